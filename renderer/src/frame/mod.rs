//! The frame loop's mechanism (README, "How a frame is made"): [`crate::plan`] decides what a
//! frame draws and uploads; this module writes the uploads (into the pool, or the staging
//! ring), records the transfers, the terrain pass (one indexed fan draw per tile straight from
//! the pool, then the stitches), the read-back and the window blit, and submits.
//!
//! - `ring`: the frames in flight. Each of `frames_in_flight` slots owns a command buffer, a
//!   fence, timestamp queries, a stitch buffer, a staging slot, a render target and the
//!   semaphore a window image is acquired with. Starting a frame waits only for its slot's
//!   previous frame; the frame just submitted is never waited for. Results (GPU times,
//!   screenshots) come back as [`Finished`] frames when their slot's fence has signalled.
//! - `create`: every GPU allocation, made in [`Renderer::new`] (and on a window resize) as
//!   `memory::budget` splits the budget; the log's `gpu_allocations` proves none happens later.
//! - `uploads`: the plan's blocks, index arrays (sent, or built on the GPU) and texture mips,
//!   written where the GPU will read them.
//! - `records` and `pass`: what the shaders read for each draw, and the pass itself, shared
//!   by live frames and replayed ones (`replay`).
//!
//! Textures: when the tile set has texture tiles, a fixed array of texture slots (one layer
//! each) is allocated beside the pool; each frame the drawn tiles ask for the mips their
//! footprint needs, the memory manager's [`TextureSlots`] grants layers and schedules mips with
//! the bytes the geometry left in the frame's budget, and the copies go through the staging
//! ring before the pass.

mod create;
mod made;
mod pass;
mod records;
mod replay;
mod ring;
mod uploads;

use std::time::Instant;

use ash::vk;
use memory::textures::TextureSlots;
use memory::Manager;

use self::pass::Scene;
pub use self::records::DrawnTile;
pub use self::replay::StaticFrame;
use self::ring::Slot;
use crate::camera::Camera;
use crate::error::FrameError;
use crate::fault::Fault;
use crate::log::{ms, FrameRecord};
use crate::measure::ErrorMeter;
use crate::parts::PartDraws;
use crate::plan::{self, Plan};
use crate::prefetch::{Predicted, Prefetcher};
use crate::settings::{MemoryOptions, Settings, Shading};
use crate::terrain::Terrain;
use crate::textures::{self, TexturePlan};
use crate::vulkan::decode::Decoder;
use crate::vulkan::indices::IndexBuilder;
use crate::vulkan::pipeline::TerrainPipeline;
use crate::vulkan::pool::TilePool;
use crate::vulkan::sets::TerrainSets;
use crate::vulkan::sync::{self, Commands};
use crate::vulkan::texture::TextureArray;
use crate::vulkan::{Buffer, Gpu, VkError};

/// Where a windowed frame goes: the acquired swapchain image, copied into after rendering.
#[derive(Clone, Copy, Debug)]
pub struct Present {
    pub image: vk::Image,
    pub extent: vk::Extent2D,
    /// Signalled when the image is acquired (the slot's, from [`Renderer::begin_frame`]).
    pub acquired: vk::Semaphore,
    /// Signalled when the copy is done; presentation waits for it.
    pub done: vk::Semaphore,
}

/// One frame to render.
pub struct FrameInput<'a> {
    pub camera: &'a Camera,
    /// Path or wall-clock time, and the frame's number in the log.
    pub time_s: f64,
    pub label: u64,
    pub screenshot: bool,
    pub present: Option<Present>,
}

/// A frame the GPU has finished: its complete record, and its pixels if asked for.
pub struct Finished {
    pub record: FrameRecord,
    pub pixels: Option<Vec<u8>>,
    pub extent: (u32, u32),
    /// With `read_back_heights`: what the vertex shader computed for every drawn vertex.
    pub heights: Option<ReadBack>,
}

/// The heights the vertex shader wrote in one frame, and what each draw was.
pub struct ReadBack {
    /// Per draw: the tile, its level, where its vertices start in `values`, and how it morphed
    /// (None: discrete).
    pub draws: Vec<DrawnTile>,
    pub values: Vec<f32>,
}

pub struct Renderer {
    pipeline: TerrainPipeline,
    /// The morph pass's scratch grids (shared by the slots: the pass waits for earlier ones).
    morph_scratch: Buffer,
    /// One descriptor set per slot: the pool and the slot's records.
    sets: Option<TerrainSets>,
    commands: Commands,
    slots: Vec<Slot>,
    pool: TilePool,
    manager: Manager,
    /// One layer per texture slot (a one-texel placeholder when there are none).
    textures: TextureArray,
    /// Which tile each layer holds (None: the frames draw without textures).
    texture_slots: Option<TextureSlots>,
    options: MemoryOptions,
    /// The next frame's number (the manager's clock).
    frame: u64,
    /// The slot of the next frame is free and its semaphore unsignalled; the frame's interval
    /// started then (before waiting for the slot).
    slot_ready: Option<Instant>,
    /// `vkterrain --trace`: the requests of every frame so far.
    trace: Option<String>,
    /// The GPU end stamp of the last frame collected (ticks).
    last_end: Option<u64>,
    /// `vkterrain --measure-error`: the meter and every how many frames it runs.
    meter: Option<(ErrorMeter, u64)>,
    /// Fault injection for tests (`VKTERRAIN_FAULT`, see [`Fault`]).
    fault: Option<Fault>,
    /// Frames collected by a frame that then failed; [`Renderer::finish_all`] returns them.
    collected: Vec<Finished>,
    /// The camera predictor and the file side of prefetching.
    prefetcher: Prefetcher,
    /// Builds index arrays on the GPU (None: they are sent from the file).
    builder: Option<IndexBuilder>,
    /// Decodes a compact set's levels on the GPU (None: positions are sent).
    decoder: Option<Decoder>,
    /// What drawing tiles part by part remembers between frames (with the builder only).
    parts: PartDraws,
}

/// What the CPU did for a frame before recording it, for its log record.
struct Prepared {
    plan: Plan,
    predicted: Predicted,
    prediction_error_m: f64,
    cpu_prefetch_ms: f64,
}

impl Renderer {
    /// The morph pass's workgroups: one per scratch region the budget gave it (0: none, and
    /// frames are drawn unmorphed).
    pub(super) fn morph_groups(&self) -> u32 {
        (self.morph_scratch.size / crate::vulkan::morph_pass::MORPH_REGION_BYTES) as u32
    }

    /// Whether index arrays are built on the GPU (else sent from the file).
    pub fn builds_indices(&self) -> bool {
        self.builder.is_some()
    }

    /// Whether built index arrays are made on the CPU and copied into place
    /// (`MemoryOptions::build_on_gpu` false) rather than built by the GPU's builder.
    pub fn makes_indices(&self) -> bool {
        self.builder.is_some() && !self.options.build_on_gpu
    }

    /// Whether a compact set's levels are sent as their streams and decoded on the GPU.
    pub fn decodes_levels(&self) -> bool {
        self.decoder.is_some()
    }

    pub fn manager(&self) -> &Manager {
        &self.manager
    }

    pub fn pool(&self) -> &TilePool {
        &self.pool
    }

    /// The texture slots (None: the frames draw without textures).
    pub fn texture_slots(&self) -> Option<&TextureSlots> {
        self.texture_slots.as_ref()
    }

    /// Device memory of the texture slots' array.
    pub fn texture_bytes(&self) -> u64 {
        self.texture_slots
            .as_ref()
            .map_or(0, |_| self.textures.bytes())
    }

    pub fn options(&self) -> &MemoryOptions {
        &self.options
    }

    /// Starts collecting a trace of every frame's requests (see `memory::trace`).
    pub fn enable_trace(&mut self) {
        self.trace = Some(memory::trace::header(&create::tile_costs(&self.manager)));
    }

    /// Measures every `every`-th frame's error in pixels against the source (see
    /// [`crate::measure`]); the log's `max_error_px`.
    pub fn measure_error(&mut self, meter: ErrorMeter, every: u64) {
        self.meter = Some((meter, every.max(1)));
    }

    /// Stops measuring; returns the meter (and its period) to resume with later.
    pub fn take_meter(&mut self) -> Option<(ErrorMeter, u64)> {
        self.meter.take()
    }

    pub fn take_trace(&mut self) -> Option<String> {
        self.trace.take()
    }

    /// The extent of the render targets.
    pub fn extent(&self) -> (u32, u32) {
        let e = self.slots[0].target.extent();
        (e.width, e.height)
    }

    /// Plans, records and submits one frame; returns the frames that finished meanwhile.
    pub fn render(
        &mut self,
        gpu: &Gpu,
        terrain: &Terrain,
        settings: &Settings,
        input: FrameInput<'_>,
    ) -> Result<Vec<Finished>, FrameError> {
        let allocations = gpu.allocations();
        if self.fault == Some(Fault::DeviceLostAt(self.frame)) {
            return Err(FrameError::Gpu(VkError::DeviceLost));
        }
        let (_, finished) = self.begin_frame(gpu)?;
        match self.render_begun(gpu, terrain, settings, input, allocations) {
            Ok(()) => Ok(finished),
            Err(e) => {
                // Frames that finished before the failure are not lost: finish_all returns them.
                self.collected.extend(finished);
                Err(e)
            }
        }
    }

    /// The frame after its slot is free: plan, uploads, record, submit.
    fn render_begun(
        &mut self,
        gpu: &Gpu,
        terrain: &Terrain,
        settings: &Settings,
        input: FrameInput<'_>,
        allocations: u64,
    ) -> Result<(), FrameError> {
        let started = self.slot_ready.unwrap_or_else(Instant::now);
        let prepared = self.prepare(terrain, settings, &input)?;
        let plan = &prepared.plan;
        let s = self.slot_index();
        let geometry_bytes = plan.stats.upload_bytes_blocks + plan.stats.upload_bytes_indices;
        let budget = self.options.upload_budget.saturating_sub(geometry_bytes);
        let textures = self.plan_textures(terrain, plan, input.camera, settings, Some(budget));

        let t = Instant::now();
        let uploads = self.write_uploads(terrain, plan, &textures, s)?;
        let cpu_upload_ms = ms(t);

        let t = Instant::now();
        let written =
            self.write_pass_inputs(terrain, settings, input.camera, (plan, &textures), s)?;
        let scene = Scene {
            terrain,
            settings,
            plan,
            constants: &written.constants,
            stitch_ranges: &written.stitch_ranges,
            read_back: self.options.read_back_heights,
            cull: pass::tiles_cull_mode(settings, self.fault),
            textures: &textures.draws,
        };
        let counts = self.record_live(gpu, s, &input, scene, &uploads)?;
        let cpu_record_ms = ms(t);
        let slot = &self.slots[s];
        let present = input.present;
        sync::submit(
            gpu,
            slot.cmd,
            slot.fence,
            present.map(|p| p.acquired),
            present.map(|p| p.done),
        )?;

        let mut record = records::frame_record(plan, &textures, counts, terrain.levels);
        let extent = self.extent();
        if let Some((meter, every)) = &mut self.meter {
            if input.label.is_multiple_of(*every) {
                let m = meter.frame_drawn(terrain, input.camera, extent, &written.drawn);
                (record.max_error_px, record.pop_px) = (m.max_error_px, m.pop_px);
            }
        }
        record.frame = input.label;
        record.time_s = input.time_s;
        record.cpu_upload_ms = cpu_upload_ms;
        record.cpu_record_ms = cpu_record_ms;
        record.staged_bytes = uploads.staged_geometry;
        record.part_builds = u64::from(uploads.part_builds);
        record.index_arrays_made = uploads.made.len() as u64;
        record.tiles_part_by_part = plan.draws.iter().filter(|d| d.key.is_some()).count() as u64;
        record.tiles_unmorphed = written.unmorphed;
        record.tiles_above_base = plan
            .draws
            .iter()
            .filter(|d| terrain.tiles[d.tile].layer > 0)
            .count() as u64;
        record.tiles_stood_in = plan.tiles_stood_in;
        record.gpu_allocations = gpu.allocations() - allocations;
        record.prediction_error_m = prepared.prediction_error_m;
        record.cpu_prefetch_ms = prepared.cpu_prefetch_ms;
        record.file_advised_bytes = prepared.predicted.advised_bytes;
        record.file_released_bytes = prepared.predicted.released_bytes;
        let read_back = self
            .options
            .read_back_heights
            .then(|| records::read_back_draws(terrain, written.drawn));
        self.slots[s].submitted(record, input.screenshot, read_back, started);
        self.frame += 1;
        self.slot_ready = None;
        Ok(())
    }

    /// The slot of the next frame.
    fn slot_index(&self) -> usize {
        (self.frame % self.slots.len() as u64) as usize
    }

    /// The camera's prediction and the frame's plan (the prefetch requests with it), with the
    /// frame's requests appended to the trace.
    fn prepare(
        &mut self,
        terrain: &Terrain,
        settings: &Settings,
        input: &FrameInput<'_>,
    ) -> Result<Prepared, FrameError> {
        let completed = self.completed();
        let extent = self.extent();
        let t = Instant::now();
        let prediction_error_m = self.prefetcher.observe(input.time_s, input.camera);
        let predicted = if self.prefetcher.options.enabled || self.trace.is_some() {
            self.prefetcher
                .predict(terrain, input.camera, extent, settings.rule())
        } else {
            Predicted::default()
        };
        let cpu_predict_ms = ms(t);
        let (prefetch, prefetch_until) = if self.prefetcher.options.enabled {
            let budget =
                std::time::Duration::try_from_secs_f64(self.prefetcher.options.cpu_ms / 1e3);
            let until = budget.ok().and_then(|b| t.checked_add(b));
            (predicted.requests.as_slice(), until)
        } else {
            (&[][..], None)
        };
        let mut plan = plan::plan(
            terrain,
            &mut self.manager,
            input.camera,
            extent,
            settings.planning(),
            plan::Residency {
                frame: self.frame,
                completed,
                allow_uploads: true,
                prefetch,
                prefetch_until,
            },
        )?;
        // Part by part, where the builder makes the arrays (sent ones are whole levels).
        let t_parts = Instant::now();
        if self.builder.is_some() {
            self.parts
                .assign(terrain, &mut plan, settings.part_build_cost);
        }
        plan.cpu_lod_ms += ms(t_parts);
        // One line per tile that failed its check (here, or on the thread checking ahead).
        for (_, problem) in terrain.take_failures() {
            eprintln!("vkterrain: {problem}; the tile is not drawn");
        }
        // The prediction and the manager's step: what `--prefetch-ms` bounds.
        let cpu_prefetch_ms = cpu_predict_ms + plan.cpu_prefetch_ms;
        self.write_trace(&plan, &predicted.requests);
        Ok(Prepared {
            plan,
            predicted,
            prediction_error_m,
            cpu_prefetch_ms,
        })
    }

    /// The frame's textures: placed and uploaded within `budget` (None: what is resident).
    /// Nothing when there are no slots or the shading does not sample them.
    fn plan_textures(
        &mut self,
        terrain: &Terrain,
        plan: &Plan,
        camera: &Camera,
        settings: &Settings,
        budget: Option<u64>,
    ) -> TexturePlan {
        let residency = (self.frame, self.completed());
        match &mut self.texture_slots {
            Some(slots) if settings.shading == Shading::Photo => {
                textures::plan_textures(terrain, slots, plan, camera.position, residency, budget)
            }
            _ => TexturePlan {
                draws: vec![None; plan.draws.len()],
                ..TexturePlan::default()
            },
        }
    }

    /// Appends the frame's requests and predictions to the trace.
    fn write_trace(&mut self, plan: &Plan, predicted: &[memory::Request]) {
        let Some(trace) = self.trace.as_mut() else {
            return;
        };
        let rows = |requests: &[memory::Request]| -> Vec<(memory::Request, u64)> {
            requests
                .iter()
                .map(|r| {
                    let t = self.manager.tile_cost(r.tile);
                    let bytes = (0..=r.wanted).map(|j| t.block_bytes(j)).sum::<u64>()
                        + t.levels[r.wanted as usize].indices;
                    (*r, bytes)
                })
                .collect()
        };
        memory::trace::write_frame(trace, self.frame, &rows(&plan.requests));
        memory::trace::write_predicted(trace, self.frame, &rows(predicted));
    }
}
