//! Frames recorded once over what is resident and replayed without any per-frame work: the
//! draw-only limit (`vkterrain --draw-only`). Nothing is uploaded or evicted, so frames
//! recorded earlier stay valid.

use ash::vk;

use super::pass::{self, pass_constants, Bindings, DrawCounts, Scene};
use super::records::{self, frame_record};
use super::ring;
use super::Renderer;
use crate::camera::Camera;
use crate::error::FrameError;
use crate::interface::{RECORDS_OFFSET, RECORD_BYTES};
use crate::log::FrameRecord;
use crate::plan::{self, Plan};
use crate::settings::Settings;
use crate::terrain::Terrain;
use crate::textures::TexturePlan;
use crate::vulkan::buffer::BufferDesc;
use crate::vulkan::sets::{SetBuffers, TerrainSets};
use crate::vulkan::sync;
use crate::vulkan::{Buffer, Gpu, VkResult};

/// A frame recorded once and replayed (see [`Renderer::record_static`]).
pub struct StaticFrame {
    cmd: vk::CommandBuffer,
    stitch: Option<Buffer>,
    records: Option<Buffer>,
    /// Nothing reads heights back from a replayed frame: a placeholder for the set.
    heights: Option<Buffer>,
    /// The morph pass's heights for its draws (a placeholder when it does not morph).
    morphed: Option<Buffer>,
    sets: Option<TerrainSets>,
    record: FrameRecord,
}

impl Renderer {
    /// Records a frame into its own command buffer over what is resident now, for replay
    /// without any per-frame work (the draw-only limit). Tiles not resident are drawn coarser or
    /// not at all (fly the path once first).
    pub fn record_static(
        &mut self,
        gpu: &Gpu,
        terrain: &Terrain,
        camera: &Camera,
        settings: &Settings,
    ) -> Result<StaticFrame, FrameError> {
        self.finish_all(gpu)?;
        let extent = self.extent();
        let plan = plan::plan(
            terrain,
            &mut self.manager,
            camera,
            extent,
            settings.planning(),
            plan::Residency {
                frame: self.frame,
                completed: self.frame.checked_sub(1),
                allow_uploads: false,
                prefetch: &[],
                prefetch_until: None,
            },
        )?;
        let textures = self.plan_textures(terrain, &plan, camera, settings, None);
        self.frame += 1;
        let mut frame = StaticFrame {
            cmd: vk::CommandBuffer::null(),
            stitch: None,
            records: None,
            heights: None,
            morphed: None,
            sets: None,
            record: FrameRecord::default(),
        };
        let view = (terrain, camera, settings);
        match self.record_into(gpu, &mut frame, view, (&plan, &textures)) {
            Ok(counts) => {
                frame.record = frame_record(&plan, &textures, counts, terrain.levels);
                Ok(frame)
            }
            Err(e) => {
                self.destroy_static(gpu, frame);
                Err(e)
            }
        }
    }

    /// Allocates `frame`'s own buffers and set, writes its stitches and records, and records
    /// its command buffer (the caller destroys what was made when this fails).
    fn record_into(
        &self,
        gpu: &Gpu,
        frame: &mut StaticFrame,
        (terrain, camera, settings): (&Terrain, &Camera, &Settings),
        (plan, textures): (&Plan, &TexturePlan),
    ) -> Result<DrawCounts, FrameError> {
        let bytes: u64 = plan
            .stitches
            .iter()
            .map(|(_, s)| 4 * s.indices.len() as u64)
            .sum();
        let usage = vk::BufferUsageFlags::INDEX_BUFFER;
        let desc = BufferDesc::upload(bytes.max(4), usage);
        let stitch = frame
            .stitch
            .insert(Buffer::new(gpu, desc, "static stitches")?);
        let ranges = records::write_stitches(stitch, &plan.stitches)?;
        let stitch = stitch.raw;
        let record_bytes = RECORDS_OFFSET + RECORD_BYTES * plan.draws.len().max(1) as u64;
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::UNIFORM_BUFFER;
        let desc = BufferDesc::upload(record_bytes, usage);
        let records = frame
            .records
            .insert(Buffer::new(gpu, desc, "static tile records")?);
        let textured = self.texture_slots.is_some();
        let (constants, morph) = pass_constants(terrain, camera, plan, settings, textured);
        let morph = morph.as_ref().map(|m| (m, &constants));
        records::write_records(
            records,
            terrain,
            camera,
            (plan, textures),
            morph,
            None,
            // Its own morphed heights hold every draw (none without the pass's regions).
            (
                false,
                if self.morph_groups() > 0 {
                    usize::MAX
                } else {
                    0
                },
            ),
        )?;
        let desc = BufferDesc::readback_storage(16);
        let heights =
            frame
                .heights
                .insert(Buffer::new(gpu, desc, "static frame heights (unused)")?);
        let size = 4 * records::drawn_vertices(terrain, plan).max(1) as u64;
        let morphed = frame.morphed.insert(ring::morphed_buffer(
            gpu,
            size,
            "static frame morphed heights",
        )?);
        let sets = frame.sets.insert(TerrainSets::new(
            gpu,
            &self.pipeline,
            (&self.pool.buffer, &self.morph_scratch),
            &[SetBuffers {
                records,
                heights,
                morphed,
            }],
            &self.textures,
            "static frame descriptor set",
        )?);
        let set = sets.sets[0];
        frame.cmd = self.commands.allocate(gpu, "static frame")?;
        let cmd = frame.cmd;
        let slot = &self.slots[0];
        sync::begin(gpu, cmd, false)?;
        slot.timestamps.begin(gpu, cmd);
        self.pipeline
            .morph
            .record(gpu, cmd, (set, self.morph_groups()), &constants);
        let at = Bindings {
            target: &slot.target,
            timestamps: &slot.timestamps,
            set,
            stitch,
        };
        let scene = Scene {
            terrain,
            settings,
            plan,
            constants: &constants,
            stitch_ranges: &ranges,
            read_back: false,
            cull: pass::tiles_cull_mode(settings, self.fault),
            textures: &[],
        };
        let counts = self.record_pass(gpu, cmd, at, scene);
        slot.timestamps.end(gpu, cmd);
        sync::end(gpu, cmd)?;
        Ok(counts)
    }

    /// Runs a recorded frame and waits for it; returns its record with the GPU times.
    pub fn replay(&mut self, gpu: &Gpu, frame: &StaticFrame) -> VkResult<FrameRecord> {
        let slot = &self.slots[0];
        sync::submit(gpu, frame.cmd, slot.fence, None, None)?;
        sync::wait_and_reset(gpu, slot.fence)?;
        let mut record = frame.record.clone();
        (record.gpu_ms, record.gpu_draw_ms) =
            slot.timestamps.read_ms(gpu).unwrap_or((f64::NAN, f64::NAN));
        Ok(record)
    }

    pub fn destroy_static(&self, gpu: &Gpu, frame: StaticFrame) {
        gpu.wait_idle();
        if frame.cmd != vk::CommandBuffer::null() {
            self.commands.free(gpu, frame.cmd);
        }
        for b in [frame.stitch, frame.records, frame.heights, frame.morphed]
            .into_iter()
            .flatten()
        {
            b.destroy(gpu);
        }
        if let Some(s) = frame.sets {
            s.destroy(gpu);
        }
    }
}
