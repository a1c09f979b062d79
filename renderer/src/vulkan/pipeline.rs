//! The terrain pipeline: packed 2 x u16 vertices, triangle fans with primitive restart, one
//! push-constant block per draw, reversed-Z depth, dynamic rendering.

use std::ffi::CStr;

use ash::vk;

use super::{Gpu, VkResult};

/// Size of the per-draw push constants (the guaranteed minimum limit).
pub const PUSH_CONSTANT_BYTES: u32 = 128;

pub struct TerrainPipeline {
    pub layout: vk::PipelineLayout,
    pub fill: vk::Pipeline,
    /// Present when the device supports `fillModeNonSolid`.
    pub wireframe: Option<vk::Pipeline>,
}

fn shader(gpu: &Gpu, words: &[u32], name: &str) -> VkResult<vk::ShaderModule> {
    let info = vk::ShaderModuleCreateInfo::default().code(words);
    // SAFETY: words are SPIR-V compiled at build time.
    let module = unsafe { gpu.device.create_shader_module(&info, None) }?;
    gpu.name(module, name);
    Ok(module)
}

impl TerrainPipeline {
    pub fn new(gpu: &Gpu, color: vk::Format, depth: vk::Format) -> VkResult<TerrainPipeline> {
        let ranges = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT)
            .size(PUSH_CONSTANT_BYTES)];
        let layout_info = vk::PipelineLayoutCreateInfo::default().push_constant_ranges(&ranges);
        // SAFETY: valid create info.
        let layout = unsafe { gpu.device.create_pipeline_layout(&layout_info, None) }?;
        gpu.name(layout, "terrain pipeline layout");
        let vert = shader(gpu, spirv::TERRAIN_VERT, "terrain.vert")?;
        let frag = shader(gpu, spirv::TERRAIN_FRAG, "terrain.frag")?;
        let fill = Self::build(
            gpu,
            layout,
            vert,
            frag,
            color,
            depth,
            vk::PolygonMode::FILL,
            "terrain (fill)",
        );
        let wireframe = if gpu.wireframe_supported {
            Some(Self::build(
                gpu,
                layout,
                vert,
                frag,
                color,
                depth,
                vk::PolygonMode::LINE,
                "terrain (wireframe)",
            ))
        } else {
            None
        };
        // SAFETY: modules are only needed during pipeline creation.
        unsafe {
            gpu.device.destroy_shader_module(vert, None);
            gpu.device.destroy_shader_module(frag, None);
        }
        let fill = fill?;
        let wireframe = wireframe.transpose()?;
        Ok(TerrainPipeline {
            layout,
            fill,
            wireframe,
        })
    }

    #[allow(clippy::too_many_arguments)]
    fn build(
        gpu: &Gpu,
        layout: vk::PipelineLayout,
        vert: vk::ShaderModule,
        frag: vk::ShaderModule,
        color: vk::Format,
        depth: vk::Format,
        polygon: vk::PolygonMode,
        name: &str,
    ) -> VkResult<vk::Pipeline> {
        let entry: &CStr = c"main";
        let stages = [
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::VERTEX)
                .module(vert)
                .name(entry),
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::FRAGMENT)
                .module(frag)
                .name(entry),
        ];
        let bindings = [vk::VertexInputBindingDescription::default()
            .binding(0)
            .stride(4)
            .input_rate(vk::VertexInputRate::VERTEX)];
        let attributes = [vk::VertexInputAttributeDescription::default()
            .location(0)
            .binding(0)
            .format(vk::Format::R16G16_UINT)
            .offset(0)];
        let vertex_input = vk::PipelineVertexInputStateCreateInfo::default()
            .vertex_binding_descriptions(&bindings)
            .vertex_attribute_descriptions(&attributes);
        // Paper, section 4: recursive fans joined by primitive restart, one draw per tile.
        let assembly = vk::PipelineInputAssemblyStateCreateInfo::default()
            .topology(vk::PrimitiveTopology::TRIANGLE_FAN)
            .primitive_restart_enable(true);
        let viewport = vk::PipelineViewportStateCreateInfo::default()
            .viewport_count(1)
            .scissor_count(1);
        // No culling: stitching triangles are seen edge-on from either side.
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
        let dynamic = [vk::DynamicState::VIEWPORT, vk::DynamicState::SCISSOR];
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
        // SAFETY: no command buffer in flight uses them.
        unsafe {
            gpu.device.destroy_pipeline(self.fill, None);
            if let Some(w) = self.wireframe {
                gpu.device.destroy_pipeline(w, None);
            }
            gpu.device.destroy_pipeline_layout(self.layout, None);
        }
    }
}
