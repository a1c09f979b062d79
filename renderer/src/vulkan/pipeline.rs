//! The terrain pipeline: vertices pulled from the tile pool (a storage buffer) with each draw's
//! tile record (another), triangle fans with primitive restart, one push-constant block per
//! frame, reversed-Z depth, dynamic rendering. Vertex shaders: geomorphing from the heights the
//! morph pass placed (the default; the pass is a compute pipeline of the same set layout), the
//! previous per-vertex rule from the two levels around each vertex's level and from the
//! paper's forward differences over every level (the comparisons), and, for
//! `--read-back-heights`, the default writing every vertex's height to a buffer. The fragment
//! shader samples the texture array (one layer per texture slot).

use std::ffi::CStr;

use ash::vk;

use super::morph_pass::MorphPass;
use super::{Gpu, VkError, VkResult};

use crate::interface::PUSH_CONSTANT_BYTES;

pub struct TerrainPipeline {
    /// Binding 0: the tile pool; binding 1: the frame's tile records (both storage buffers);
    /// binding 2: the texture array and its sampler; binding 3: the heights read back;
    /// binding 4: the drawn tile's record (a dynamic uniform buffer over binding 1, moved to
    /// each draw's record); binding 5: the frame's morph constants (the records buffer's first
    /// bytes, a uniform buffer); binding 6: the frame's morphed heights (written by the morph
    /// pass, read by the vertex shader); binding 7: the morph pass's scratch grids.
    pub set_layout: vk::DescriptorSetLayout,
    pub layout: vk::PipelineLayout,
    pub fill: Pair,
    /// `fill`'s tiles pipeline with the fragment shader's texture path alone (`PHOTO`), for
    /// the tiles drawn with their texture this frame.
    pub photo: vk::Pipeline,
    /// `photo` for tiles whose every mip is resident (`WHOLE_MIPS`): the sampler's own level.
    pub photo_whole: vk::Pipeline,
    /// The previous per-vertex rule (`--morph-shader two-levels`).
    pub two_levels: Pair,
    /// The same rule with the paper's forward differences (`--morph-shader forward-differences`).
    pub all_rows: Pair,
    /// The morph pass (`morph.comp`) over the set layout above.
    pub morph: MorphPass,
    /// The default writing each vertex's height (`--read-back-heights`; needs
    /// `vertexPipelineStoresAndAtomics`).
    pub read_back: Option<Pair>,
    /// Present when the device supports `fillModeNonSolid`.
    pub wireframe: Option<Pair>,
}

/// The terrain set's bindings (as [`TerrainPipeline::set_layout`] describes them): number,
/// kind and stages, the one list the layout, the pool's sizes and the writes take them from.
pub(super) const BINDINGS: [(u32, vk::DescriptorType, vk::ShaderStageFlags); 8] = [
    (0, vk::DescriptorType::STORAGE_BUFFER, VERTEX_AND_MORPH),
    (1, vk::DescriptorType::STORAGE_BUFFER, VERTEX_AND_MORPH),
    (
        2,
        vk::DescriptorType::COMBINED_IMAGE_SAMPLER,
        vk::ShaderStageFlags::FRAGMENT,
    ),
    (
        3,
        vk::DescriptorType::STORAGE_BUFFER,
        vk::ShaderStageFlags::VERTEX,
    ),
    (
        4,
        vk::DescriptorType::UNIFORM_BUFFER_DYNAMIC,
        vk::ShaderStageFlags::VERTEX,
    ),
    (5, vk::DescriptorType::UNIFORM_BUFFER, VERTEX_AND_MORPH),
    (6, vk::DescriptorType::STORAGE_BUFFER, VERTEX_AND_MORPH),
    (
        7,
        vk::DescriptorType::STORAGE_BUFFER,
        vk::ShaderStageFlags::COMPUTE,
    ),
];

/// The stages of the bindings both the vertex shader and the morph pass read.
const VERTEX_AND_MORPH: vk::ShaderStageFlags = vk::ShaderStageFlags::from_raw(
    vk::ShaderStageFlags::VERTEX.as_raw() | vk::ShaderStageFlags::COMPUTE.as_raw(),
);

/// One vertex shader's two pipelines: for tiles, which read their record through the Tile
/// binding, and for stitches, whose vertices read theirs by record number (`STITCH`).
#[derive(Clone, Copy, Debug)]
pub struct Pair {
    pub tiles: vk::Pipeline,
    pub stitches: vk::Pipeline,
}

impl Pair {
    fn destroy(self, gpu: &Gpu) {
        // SAFETY: no command buffer in flight uses them.
        unsafe {
            gpu.device.destroy_pipeline(self.tiles, None);
            gpu.device.destroy_pipeline(self.stitches, None);
        }
    }
}

/// The terrain set layout ([`BINDINGS`]) and the pipeline layout of the draws: that set and the
/// frame's push constants for the vertex and fragment stages.
fn layouts(gpu: &Gpu) -> VkResult<(vk::DescriptorSetLayout, vk::PipelineLayout)> {
    let ranges = [vk::PushConstantRange::default()
        .stage_flags(vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT)
        .size(PUSH_CONSTANT_BYTES)];
    let bindings = BINDINGS.map(|(b, ty, stage)| {
        vk::DescriptorSetLayoutBinding::default()
            .binding(b)
            .descriptor_type(ty)
            .descriptor_count(1)
            .stage_flags(stage)
    });
    let set_info = vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings);
    // SAFETY: valid create info.
    let set_layout = unsafe { gpu.device.create_descriptor_set_layout(&set_info, None) }?;
    gpu.name(set_layout, "terrain descriptor set layout");
    let set_layouts = [set_layout];
    let layout_info = vk::PipelineLayoutCreateInfo::default()
        .set_layouts(&set_layouts)
        .push_constant_ranges(&ranges);
    // SAFETY: valid create info.
    match unsafe { gpu.device.create_pipeline_layout(&layout_info, None) } {
        Ok(layout) => {
            gpu.name(layout, "terrain pipeline layout");
            Ok((set_layout, layout))
        }
        Err(e) => {
            // SAFETY: unused.
            unsafe { gpu.device.destroy_descriptor_set_layout(set_layout, None) };
            Err(e.into())
        }
    }
}

fn shader(gpu: &Gpu, words: &[u32], name: &str) -> VkResult<vk::ShaderModule> {
    let info = vk::ShaderModuleCreateInfo::default().code(words);
    // SAFETY: words are SPIR-V compiled at build time.
    let module = unsafe { gpu.device.create_shader_module(&info, None) }?;
    gpu.name(module, name);
    Ok(module)
}

impl TerrainPipeline {
    /// The pipelines, with the read-back one when `read_back` (the device must support
    /// vertex stores, [`Gpu::vertex_stores`]).
    pub fn new(
        gpu: &Gpu,
        color: vk::Format,
        depth: vk::Format,
        read_back: bool,
    ) -> VkResult<TerrainPipeline> {
        let (set_layout, layout) = layouts(gpu)?;
        let vert = shader(gpu, spirv::TERRAIN_VERT, "terrain.vert")?;
        let vert_all_rows = shader(gpu, spirv::TERRAIN_VERT_ALL_ROWS, "terrain.vert (all rows)")?;
        let vert_two_levels = shader(
            gpu,
            spirv::TERRAIN_VERT_TWO_LEVELS,
            "terrain.vert (two levels)",
        )?;
        let vert_read_back = shader(
            gpu,
            spirv::TERRAIN_VERT_READ_BACK,
            "terrain.vert (read-back)",
        )?;
        let frag = if gpu.min_lod {
            shader(gpu, spirv::TERRAIN_FRAG_MIN_LOD, "terrain.frag (MinLod)")?
        } else {
            shader(gpu, spirv::TERRAIN_FRAG, "terrain.frag")?
        };
        let pair = |vert, mode, name: &str| {
            Self::pair(gpu, layout, (vert, frag), (color, depth), mode, name)
        };
        let fill = pair(vert, vk::PolygonMode::FILL, "terrain (fill)");
        let photo = |whole: bool, name: &str| {
            Self::specialised(
                gpu,
                layout,
                (vert, false),
                (frag, Some(whole)),
                (color, depth),
                vk::PolygonMode::FILL,
                name,
            )
        };
        let (photo, photo_whole) = (
            photo(false, "terrain (fill, photo)"),
            photo(true, "terrain (fill, photo, every mip)"),
        );
        let two_levels = pair(
            vert_two_levels,
            vk::PolygonMode::FILL,
            "terrain (fill, two levels)",
        );
        let all_rows = pair(
            vert_all_rows,
            vk::PolygonMode::FILL,
            "terrain (fill, forward differences over all rows)",
        );
        let read_back = read_back.then(|| {
            pair(
                vert_read_back,
                vk::PolygonMode::FILL,
                "terrain (fill, heights read back)",
            )
        });
        let wireframe = gpu
            .wireframe_supported
            .then(|| pair(vert, vk::PolygonMode::LINE, "terrain (wireframe)"));
        // SAFETY: modules are only needed during pipeline creation.
        unsafe {
            for module in [vert, vert_all_rows, vert_two_levels, vert_read_back, frag] {
                gpu.device.destroy_shader_module(module, None);
            }
        }
        Ok(TerrainPipeline {
            set_layout,
            layout,
            fill: fill?,
            photo: photo?,
            photo_whole: photo_whole?,
            two_levels: two_levels?,
            all_rows: all_rows?,
            morph: MorphPass::new(gpu, set_layout)?,
            read_back: read_back.transpose()?,
            wireframe: wireframe.transpose()?,
        })
    }

    /// One vertex shader's pair of pipelines (tiles, stitches) with `frag`.
    fn pair(
        gpu: &Gpu,
        layout: vk::PipelineLayout,
        (vert, frag): (vk::ShaderModule, vk::ShaderModule),
        formats: (vk::Format, vk::Format),
        mode: vk::PolygonMode,
        name: &str,
    ) -> VkResult<Pair> {
        let build = |stitch: bool, name: &str| {
            Self::specialised(
                gpu,
                layout,
                (vert, stitch),
                (frag, None),
                formats,
                mode,
                name,
            )
        };
        Ok(Pair {
            tiles: build(false, name)?,
            stitches: build(true, &format!("{name}, stitches"))?,
        })
    }

    /// A pipeline of `vert` and `frag` specialised: the vertex shader's `STITCH` (constant 0)
    /// and, for the photo pipelines (`photo` Some), the fragment shader's `PHOTO` (constant 1)
    /// and `WHOLE_MIPS` (constant 2) as `photo` says.
    fn specialised(
        gpu: &Gpu,
        layout: vk::PipelineLayout,
        (vert, stitch): (vk::ShaderModule, bool),
        (frag, photo): (vk::ShaderModule, Option<bool>),
        (color, depth): (vk::Format, vk::Format),
        mode: vk::PolygonMode,
        name: &str,
    ) -> VkResult<vk::Pipeline> {
        let constant = |id: u32, offset: u32| {
            vk::SpecializationMapEntry::default()
                .constant_id(id)
                .offset(offset)
                .size(4)
        };
        let vertex_entries = [constant(0, 0)];
        let fragment_entries = [constant(1, 0), constant(2, 4)];
        let stitch = u32::from(stitch).to_ne_bytes();
        let mut photo_data = [0u8; 8];
        photo_data[..4].copy_from_slice(&u32::from(photo.is_some()).to_ne_bytes());
        photo_data[4..].copy_from_slice(&u32::from(photo == Some(true)).to_ne_bytes());
        let vertex = vk::SpecializationInfo::default()
            .map_entries(&vertex_entries)
            .data(&stitch);
        let fragment = vk::SpecializationInfo::default()
            .map_entries(&fragment_entries)
            .data(&photo_data);
        Self::build(
            gpu,
            layout,
            (vert, Some(&vertex)),
            (frag, Some(&fragment)),
            color,
            depth,
            mode,
            name,
        )
    }

    #[allow(clippy::too_many_arguments)]
    pub(crate) fn build(
        gpu: &Gpu,
        layout: vk::PipelineLayout,
        (vert, specialization): (vk::ShaderModule, Option<&vk::SpecializationInfo>),
        (frag, frag_specialization): (vk::ShaderModule, Option<&vk::SpecializationInfo>),
        color: vk::Format,
        depth: vk::Format,
        polygon: vk::PolygonMode,
        name: &str,
    ) -> VkResult<vk::Pipeline> {
        let entry: &CStr = c"main";
        let mut vertex_stage = vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::VERTEX)
            .module(vert)
            .name(entry);
        if let Some(s) = specialization {
            vertex_stage = vertex_stage.specialization_info(s);
        }
        let mut fragment_stage = vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::FRAGMENT)
            .module(frag)
            .name(entry);
        if let Some(s) = frag_specialization {
            fragment_stage = fragment_stage.specialization_info(s);
        }
        let stages = [vertex_stage, fragment_stage];
        // No vertex input: the shader pulls its vertices from the pool.
        let vertex_input = vk::PipelineVertexInputStateCreateInfo::default();
        // Paper, section 4: recursive fans joined by primitive restart, one draw per tile.
        let assembly = vk::PipelineInputAssemblyStateCreateInfo::default()
            .topology(vk::PrimitiveTopology::TRIANGLE_FAN)
            .primitive_restart_enable(true);
        let viewport = vk::PipelineViewportStateCreateInfo::default()
            .viewport_count(1)
            .scissor_count(1);
        // The cull mode is dynamic state (above).
        let raster = vk::PipelineRasterizationStateCreateInfo::default()
            .polygon_mode(polygon)
            .cull_mode(vk::CullModeFlags::NONE)
            .front_face(vk::FrontFace::COUNTER_CLOCKWISE)
            .line_width(1.0);
        let multisample = vk::PipelineMultisampleStateCreateInfo::default()
            .rasterization_samples(vk::SampleCountFlags::TYPE_1);
        // Reversed Z with an infinite far plane: depth 1 at the near plane, 0 at infinity.
        let depth_state = vk::PipelineDepthStencilStateCreateInfo::default()
            .depth_test_enable(true)
            .depth_write_enable(true)
            .depth_compare_op(vk::CompareOp::GREATER_OR_EQUAL);
        let blend_attachments = [vk::PipelineColorBlendAttachmentState::default()
            .color_write_mask(vk::ColorComponentFlags::RGBA)];
        let blend =
            vk::PipelineColorBlendStateCreateInfo::default().attachments(&blend_attachments);
        // The cull mode is set with each pipeline bound: the tiles' back faces are culled
        // unless `--no-cull`, stitches' never (core in Vulkan 1.3).
        let dynamic = [
            vk::DynamicState::VIEWPORT,
            vk::DynamicState::SCISSOR,
            vk::DynamicState::CULL_MODE,
        ];
        let dynamic_state = vk::PipelineDynamicStateCreateInfo::default().dynamic_states(&dynamic);
        let color_formats = [color];
        let mut rendering = vk::PipelineRenderingCreateInfo::default()
            .color_attachment_formats(&color_formats)
            .depth_attachment_format(depth);
        let info = vk::GraphicsPipelineCreateInfo::default()
            .stages(&stages)
            .vertex_input_state(&vertex_input)
            .input_assembly_state(&assembly)
            .viewport_state(&viewport)
            .rasterization_state(&raster)
            .multisample_state(&multisample)
            .depth_stencil_state(&depth_state)
            .color_blend_state(&blend)
            .dynamic_state(&dynamic_state)
            .layout(layout)
            .push_next(&mut rendering);
        // SAFETY: every pointer in `info` outlives the call.
        let pipelines = unsafe {
            gpu.device
                .create_graphics_pipelines(vk::PipelineCache::null(), &[info], None)
        }
        .map_err(|(_, e)| e)?;
        let pipeline = pipelines[0];
        gpu.name(pipeline, name);
        Ok(pipeline)
    }

    pub fn destroy(self, gpu: &Gpu) {
        self.morph.destroy(gpu);
        // SAFETY: no command buffer in flight uses them.
        unsafe {
            let pairs = [
                Some(self.fill),
                Some(self.two_levels),
                Some(self.all_rows),
                self.read_back,
                self.wireframe,
            ];
            for p in pairs.into_iter().flatten() {
                p.destroy(gpu);
            }
            gpu.device.destroy_pipeline(self.photo, None);
            gpu.device.destroy_pipeline(self.photo_whole, None);
            gpu.device.destroy_pipeline_layout(self.layout, None);
            gpu.device
                .destroy_descriptor_set_layout(self.set_layout, None);
        }
    }
}

/// The static-mesh limit's pipeline (`crate::limit`): the terrain's fixed-function state
/// (fans with primitive restart, reversed-Z depth, the same attachments) with the simplest
/// shaders: grid positions from the vertex index, one colour.
pub struct LimitPipeline {
    pub layout: vk::PipelineLayout,
    pub pipeline: vk::Pipeline,
}

/// Size of the limit's push constants: a matrix, the grid's side and its spacing.
pub const LIMIT_PUSH_BYTES: u32 = 64 + 8;

impl LimitPipeline {
    pub fn new(gpu: &Gpu, color: vk::Format, depth: vk::Format) -> VkResult<LimitPipeline> {
        let ranges = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::VERTEX)
            .size(LIMIT_PUSH_BYTES)];
        let layout_info = vk::PipelineLayoutCreateInfo::default().push_constant_ranges(&ranges);
        // SAFETY: valid create info.
        let layout = unsafe { gpu.device.create_pipeline_layout(&layout_info, None) }?;
        gpu.name(layout, "static-mesh limit pipeline layout");
        let modules = shader(gpu, spirv::LIMIT_VERT, "limit.vert")
            .and_then(|v| shader(gpu, spirv::LIMIT_FRAG, "limit.frag").map(|f| (v, f)));
        let pipeline = modules.and_then(|(vert, frag)| {
            let p = TerrainPipeline::build(
                gpu,
                layout,
                (vert, None),
                (frag, None),
                color,
                depth,
                vk::PolygonMode::FILL,
                "static-mesh limit",
            );
            // SAFETY: modules are only needed during pipeline creation.
            unsafe {
                gpu.device.destroy_shader_module(vert, None);
                gpu.device.destroy_shader_module(frag, None);
            }
            p
        });
        match pipeline {
            Ok(pipeline) => Ok(LimitPipeline { layout, pipeline }),
            Err(e) => {
                // SAFETY: unused.
                unsafe { gpu.device.destroy_pipeline_layout(layout, None) };
                Err(e)
            }
        }
    }

    pub fn destroy(self, gpu: &Gpu) {
        // SAFETY: no command buffer in flight uses them.
        unsafe {
            gpu.device.destroy_pipeline(self.pipeline, None);
            gpu.device.destroy_pipeline_layout(self.layout, None);
        }
    }
}

/// A compute pipeline of `words` (SPIR-V compiled at build time) with `layout`, named `name`.
pub(crate) fn compute_pipeline(
    gpu: &Gpu,
    words: &[u32],
    layout: vk::PipelineLayout,
    name: &str,
) -> VkResult<vk::Pipeline> {
    let module = shader(gpu, words, name)?;
    let stage = vk::PipelineShaderStageCreateInfo::default()
        .stage(vk::ShaderStageFlags::COMPUTE)
        .module(module)
        .name(c"main");
    let info = [vk::ComputePipelineCreateInfo::default()
        .stage(stage)
        .layout(layout)];
    // SAFETY: valid create info; the module is destroyed once the pipeline exists.
    let pipelines = unsafe {
        gpu.device
            .create_compute_pipelines(vk::PipelineCache::null(), &info, None)
    };
    // SAFETY: no longer needed either way.
    unsafe { gpu.device.destroy_shader_module(module, None) };
    let pipeline = pipelines.map_err(|(_, e)| VkError::from(e))?[0];
    gpu.name(pipeline, name);
    Ok(pipeline)
}
