//! The terrain pass, recorded the same way for a live frame and a replayed one: the push
//! constants, one indexed fan draw per tile from the pool and the stitches, between the
//! pass's timestamps; and a live frame's whole command buffer around it.

use ash::vk;

use super::records::{self, DrawnTile};
use super::uploads::Uploads;
use super::{FrameInput, Renderer};
use crate::camera::{Camera, View};
use crate::error::FrameError;
use crate::fault::Fault;
use crate::interface::{
    tile_binding_offset, FrameConstants, MorphFrame, FLAG_GEOMORPH, FLAG_LEVEL_COLOURS,
    FLAG_RELIEF, FLAG_TEXTURE, FLAG_TILES,
};
use crate::morph;
use crate::plan::{LevelRule, Plan};
use crate::settings::{MorphShader, Settings, Shading};
use crate::stitch::pulled;
use crate::target::Target;
use crate::terrain::Terrain;
use crate::textures::{TextureDraw, TexturePlan};
use crate::vulkan::decode::Decoder;
use crate::vulkan::morph_pass::MorphPass;
use crate::vulkan::pipeline::{Pair, TerrainPipeline};
use crate::vulkan::pool;
use crate::vulkan::sync;
use crate::vulkan::texture;
use crate::vulkan::timestamps::Timestamps;
use crate::vulkan::Gpu;

/// What a live frame wrote for its pass.
pub(super) struct PassInputs {
    pub constants: FrameConstants,
    pub drawn: Vec<DrawnTile>,
    pub stitch_ranges: Vec<(u32, u32)>,
    /// Draws the morph pass skipped: its heights held no more vertices.
    pub unmorphed: u64,
}

impl Renderer {
    /// Writes slot `s`'s stitches and tile records for the frame; returns them with the push
    /// constants.
    pub(super) fn write_pass_inputs(
        &mut self,
        terrain: &Terrain,
        settings: &Settings,
        camera: &Camera,
        (plan, textures): (&Plan, &TexturePlan),
        s: usize,
    ) -> Result<PassInputs, FrameError> {
        let slot = &mut self.slots[s];
        let stitch_ranges = records::write_stitches(&mut slot.stitch, &plan.stitches)?;
        let textured = self.texture_slots.is_some();
        let (constants, morph) = pass_constants(terrain, camera, plan, settings, textured);
        // The meter and the read-back need each draw's morph inputs; nothing else does.
        let describe = self.meter.is_some() || self.options.read_back_heights;
        let capacity = (slot.morphed.size / 4) as usize;
        let (drawn, unmorphed) = records::write_records(
            &mut slot.records,
            terrain,
            camera,
            (plan, textures),
            morph.as_ref().map(|m| (m, &constants)),
            self.fault,
            (describe, capacity),
        )?;
        Ok(PassInputs {
            constants,
            unmorphed,
            drawn,
            stitch_ranges,
        })
    }

    /// Records slot `s`'s command buffer: the frame's copies and index builds, the pass, the
    /// screenshot's read-back and the window's blit, between the frame's timestamps.
    pub(super) fn record_live(
        &self,
        gpu: &Gpu,
        s: usize,
        input: &FrameInput<'_>,
        scene: Scene<'_>,
        uploads: &Uploads,
    ) -> Result<DrawCounts, FrameError> {
        let slot = &self.slots[s];
        let cmd = slot.cmd;
        sync::begin(gpu, cmd, true)?;
        slot.timestamps.begin(gpu, cmd);
        let staging = &slot.staging;
        pool::record_transfers(
            gpu,
            cmd,
            &self.pool,
            staging,
            &uploads.moves,
            &uploads.staged,
        );
        let copies = &uploads.texture_copies;
        texture::record_uploads(gpu, cmd, &self.textures, staging.raw(), copies);
        if let Some(d) = self
            .decoder
            .as_ref()
            .filter(|_| self.fault != Some(Fault::DecodeSkip))
        {
            d.record(gpu, cmd, (s, &uploads.decode_waves), Decoder::READERS);
        }
        if self.fault != Some(Fault::MadeSkip) {
            pool::record_made(gpu, cmd, &self.pool, staging, &uploads.made);
        }
        let groups = self.morph_groups();
        if let Some(b) = &self.builder {
            let pass_follows = MorphPass::records(scene.constants, groups);
            b.record(gpu, cmd, (s, uploads.on_gpu), pass_follows);
        }
        let set = self
            .sets
            .as_ref()
            .map_or(vk::DescriptorSet::null(), |t| t.sets[s]);
        self.pipeline
            .morph
            .record(gpu, cmd, (set, groups), scene.constants);
        if self.fault == Some(Fault::Validation) && self.frame == 0 {
            // SAFETY: deliberately invalid (offset 1 for 16-bit indices), for the tests of
            // the validation path; the pass rebinds a valid index buffer before any draw.
            unsafe {
                let pool = self.pool.buffer.raw;
                gpu.device
                    .cmd_bind_index_buffer(cmd, pool, 1, vk::IndexType::UINT16);
            }
        }
        if self.fault == Some(Fault::Unsynchronised) && self.frame == 0 {
            // SAFETY: valid, but unordered on purpose: a transfer rewrites the first morphed
            // height after the pass wrote it and before the draws read it, with no barrier
            // (a hazard only synchronisation validation reports; one vertex of the first
            // frame is misplaced).
            unsafe {
                gpu.device.cmd_fill_buffer(cmd, slot.morphed.raw, 0, 4, 0);
            }
        }
        let at = Bindings {
            target: &slot.target,
            timestamps: &slot.timestamps,
            set,
            stitch: slot.stitch.raw,
        };
        let counts = self.record_pass(gpu, cmd, at, scene);
        if input.screenshot {
            slot.target.record_readback(gpu, cmd);
        }
        if let Some(p) = &input.present {
            slot.target
                .record_blit(gpu, cmd, p.image, p.extent, input.screenshot);
        }
        slot.timestamps.end(gpu, cmd);
        sync::end(gpu, cmd)?;
        Ok(counts)
    }

    /// Records the terrain pass between the pass's timestamps (and, with read-back, the barrier
    /// that makes the vertex shader's heights visible to the host).
    pub(super) fn record_pass(
        &self,
        gpu: &Gpu,
        cmd: vk::CommandBuffer,
        at: Bindings<'_>,
        scene: Scene<'_>,
    ) -> DrawCounts {
        let read_back = scene.read_back;
        let timestamps = at.timestamps;
        timestamps.pass_begin(gpu, cmd);
        let counts = Pass {
            gpu,
            cmd,
            pipeline: &self.pipeline,
            pool: self.pool.buffer.raw,
            at,
            scene,
        }
        .record();
        if read_back {
            sync::vertex_to_host_barrier(gpu, cmd);
        }
        timestamps.pass_end(gpu, cmd);
        counts
    }
}

/// What the terrain pass drew.
#[derive(Clone, Copy, Default)]
pub(super) struct DrawCounts {
    pub triangles: u64,
    pub vertices: u64,
    pub stitch_triangles: u64,
    /// Draws by the photo pipeline.
    pub photo: u64,
}

/// What a pass draws: the same for a live frame and a replayed one.
pub(super) struct Scene<'a> {
    pub terrain: &'a Terrain,
    pub settings: &'a Settings,
    pub plan: &'a Plan,
    pub constants: &'a FrameConstants,
    /// Per stitch, its indices in the stitch buffer (first, count).
    pub stitch_ranges: &'a [(u32, u32)],
    /// Draw with the pipeline that writes every vertex's height.
    pub read_back: bool,
    /// The tiles' cull mode ([`tiles_cull_mode`]).
    pub cull: vk::CullModeFlags,
    /// Per draw, its texture slot this frame (empty: none has one): with the frame's texture
    /// flag, the draws the photo pipeline may draw (the fragment shader's own test).
    pub textures: &'a [Option<TextureDraw>],
}

/// The cull mode of the tiles' draws: back faces unless `--no-cull` or the wireframe (the
/// `cull-front` fault culls the front faces instead).
pub(super) fn tiles_cull_mode(settings: &Settings, fault: Option<Fault>) -> vk::CullModeFlags {
    match (settings.cull_back_faces && !settings.wireframe, fault) {
        (false, _) => vk::CullModeFlags::NONE,
        (true, Some(Fault::CullFront)) => vk::CullModeFlags::FRONT,
        (true, _) => vk::CullModeFlags::BACK,
    }
}

/// Where a pass draws from and to: a frame slot's objects, or a static frame's.
pub(super) struct Bindings<'a> {
    pub target: &'a Target,
    pub timestamps: &'a Timestamps,
    /// The pool and the frame's records.
    pub set: vk::DescriptorSet,
    pub stitch: vk::Buffer,
}

/// The terrain pass of one frame: clear, one indexed fan draw per tile from the pool, then
/// the stitches from the stitch buffer; every vertex pulled by the shader with its tile's
/// record.
struct Pass<'a> {
    gpu: &'a Gpu,
    cmd: vk::CommandBuffer,
    pipeline: &'a TerrainPipeline,
    pool: vk::Buffer,
    at: Bindings<'a>,
    scene: Scene<'a>,
}

impl Pass<'_> {
    /// The pipelines the settings draw with.
    fn pair(&self) -> Pair {
        let p = self.pipeline;
        match (
            self.scene.settings.wireframe,
            self.scene.settings.morph_shader,
        ) {
            (true, _) => p.wireframe.unwrap_or(p.fill),
            (false, _) if self.scene.read_back => p.read_back.unwrap_or(p.fill),
            (false, MorphShader::ForwardDifferences) => p.all_rows,
            (false, MorphShader::TwoLevels) => p.two_levels,
            (false, MorphShader::Hierarchical) => p.fill,
        }
    }

    /// Binds the set, its Tile binding at record `record`.
    fn bind(&self, record: usize) {
        // SAFETY: recording; the set's buffers outlive the frame, and the offset is a
        // record's, inside the records buffer (its size counts every draw's record).
        unsafe {
            self.gpu.device.cmd_bind_descriptor_sets(
                self.cmd,
                vk::PipelineBindPoint::GRAPHICS,
                self.pipeline.layout,
                0,
                &[self.at.set],
                &[tile_binding_offset(record)],
            );
        }
    }

    fn record(&self) -> DrawCounts {
        let (gpu, cmd) = (self.gpu, self.cmd);
        self.at
            .target
            .begin_rendering(gpu, cmd, self.scene.settings.sky);
        let pipeline = self.pair();
        let constants = *self.scene.constants;
        // The textured tiles take the photo pipeline where the default one draws (it is the
        // default's with the texture path alone).
        let photo = (pipeline.tiles == self.pipeline.fill.tiles
            && constants.flags & FLAG_TEXTURE != 0
            && !self.scene.settings.one_fragment_shader)
            .then_some((self.pipeline.photo, self.pipeline.photo_whole));
        let mut counts = DrawCounts::default();
        // SAFETY: recording inside dynamic rendering; the pool and the records outlive the
        // frame, and every range drawn was written before (the manager's grants; records by
        // this frame).
        unsafe {
            let mut bound_pipeline = pipeline.tiles;
            gpu.device
                .cmd_bind_pipeline(cmd, vk::PipelineBindPoint::GRAPHICS, bound_pipeline);
            gpu.device.cmd_set_cull_mode(cmd, self.scene.cull);
            gpu.device.cmd_push_constants(
                cmd,
                self.pipeline.layout,
                vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT,
                0,
                bytemuck::bytes_of(&constants),
            );
            let mut bound: Option<u32> = None;
            for (record, d) in self.scene.plan.draws.iter().enumerate() {
                // A tile with every mip resident samples at the sampler's own level.
                let slot = self.scene.textures.get(record).copied().flatten();
                let wanted = match (photo, slot) {
                    (Some((_, whole)), Some(t)) if t.finest == 0 => whole,
                    (Some((some, _)), Some(_)) => some,
                    _ => pipeline.tiles,
                };
                if wanted != bound_pipeline {
                    // The same layout: the push constants and the set stay bound.
                    gpu.device
                        .cmd_bind_pipeline(cmd, vk::PipelineBindPoint::GRAPHICS, wanted);
                    gpu.device.cmd_set_cull_mode(cmd, self.scene.cull);
                    bound_pipeline = wanted;
                }
                counts.photo += u64::from(wanted != pipeline.tiles);
                if bound != Some(d.index_width) {
                    gpu.device
                        .cmd_bind_index_buffer(cmd, self.pool, 0, index_type(d.index_width));
                    bound = Some(d.index_width);
                }
                self.bind(record);
                // The tile's local indices plus vertexOffset: the pulled index of its record.
                gpu.device.cmd_draw_indexed(
                    cmd,
                    d.index_count,
                    1,
                    (d.index_offset / u64::from(d.index_width)) as u32,
                    pulled(record as u32, 0) as i32,
                    0,
                );
                let entry = &self.scene.terrain.tiles[d.tile].levels[d.level as usize];
                counts.triangles += u64::from(d.triangle_count);
                counts.vertices += u64::from(entry.vertex_count());
            }
        }
        if !self.scene.settings.no_stitch && !self.scene.plan.stitches.is_empty() {
            counts.stitch_triangles = self.record_stitches(pipeline.stitches);
        }
        // SAFETY: recording inside dynamic rendering.
        unsafe { gpu.device.cmd_end_rendering(cmd) };
        counts
    }

    /// The stitches from the stitch buffer with `pipeline`, never culled (they are seen edge-on
    /// from either side); their triangles.
    fn record_stitches(&self, pipeline: vk::Pipeline) -> u64 {
        let (gpu, cmd) = (self.gpu, self.cmd);
        let mut triangles = 0;
        // SAFETY: recording inside dynamic rendering, the push constants bound; the stitch
        // buffer outlives the frame and was written by it.
        unsafe {
            gpu.device
                .cmd_bind_pipeline(cmd, vk::PipelineBindPoint::GRAPHICS, pipeline);
            gpu.device.cmd_set_cull_mode(cmd, vk::CullModeFlags::NONE);
            self.bind(0);
            gpu.device
                .cmd_bind_index_buffer(cmd, self.at.stitch, 0, vk::IndexType::UINT32);
            let ranges = self.scene.stitch_ranges;
            for ((_, s), &(first, count)) in self.scene.plan.stitches.iter().zip(ranges) {
                gpu.device.cmd_draw_indexed(cmd, count, 1, first, 0, 0);
                triangles += u64::from(s.triangles);
            }
        }
        triangles
    }
}

/// The frame's push constants, and its morph constants when it morphs. `draws` counts the
/// plan's draws when the morph pass places their vertices (hierarchical morphing), 0 otherwise.
pub(super) fn pass_constants(
    terrain: &Terrain,
    camera: &Camera,
    plan: &Plan,
    settings: &Settings,
    textured: bool,
) -> (FrameConstants, Option<MorphFrame>) {
    let view = &plan.view;
    let mut constants = frame_constants(terrain, camera, view, settings, textured);
    let morphing = matches!(settings.rule(), LevelRule::Morph(..));
    if morphing && settings.morph_shader == MorphShader::Hierarchical {
        constants.draws = plan.draws.len() as u32;
    }
    let morph = morphing.then(|| morph::frame_constants(view, settings.tau));
    (constants, morph)
}

/// The frame's push constants: the camera, the spacing, the flags for `settings`.
fn frame_constants(
    terrain: &Terrain,
    camera: &Camera,
    view: &View,
    settings: &Settings,
    textured: bool,
) -> FrameConstants {
    let (sx, sy) = terrain.spacing;
    let (_, cam_rel) = terrain.camera_tile(camera.position);
    let mut flags = 0;
    if matches!(settings.rule(), LevelRule::Morph(..)) {
        flags |= FLAG_GEOMORPH;
    }
    match settings.shading {
        Shading::Photo if textured => flags |= FLAG_TEXTURE,
        Shading::Photo | Shading::Tint => {}
        Shading::Relief => flags |= FLAG_RELIEF,
        Shading::Level => flags |= FLAG_LEVEL_COLOURS,
        Shading::Tiles => flags |= FLAG_TILES,
    }
    let texture_map = match terrain.texture {
        Some(l) => {
            let size = f64::from(l.size);
            [
                (f64::from(l.gutter) / size) as f32,
                (f64::from(l.interior) / (f64::from(tiles::mesh::TILE_CELLS) * size)) as f32,
                l.size as f32,
                settings.tile_grid_offset,
            ]
        }
        None => [0.0, 0.0, 0.0, settings.tile_grid_offset],
    };
    FrameConstants {
        view_proj: view.view_proj.to_cols_array(),
        camera: [
            cam_rel.x as f32,
            cam_rel.y as f32,
            cam_rel.z as f32,
            sx as f32,
        ],
        spacing_y: sy as f32,
        height_step: terrain.height_step,
        flags,
        draws: 0,
        texture_map,
    }
}

fn index_type(width: u32) -> vk::IndexType {
    if width == 2 {
        vk::IndexType::UINT16
    } else {
        vk::IndexType::UINT32
    }
}
