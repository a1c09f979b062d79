//! The frame loop's mechanism (DESIGN.md, "The frame"): [`crate::plan`] decides what a frame
//! draws and uploads; this module writes the uploads (into the pool, or the staging ring),
//! records the transfers, the terrain pass (one indexed fan draw per tile straight from the
//! pool, then the stitches), the read-back and the window blit, and submits.
//!
//! Textures: when the tile set has texture tiles, a fixed array of texture slots (one layer
//! each) is allocated beside the pool; each frame the drawn tiles ask for the mips their
//! footprint needs, the memory manager's [`TextureSlots`] grants layers and schedules mips
//! with the bytes the geometry left in the frame's budget, and the copies go through the
//! staging ring before the pass.
//!
//! Frames in flight: each of `frames_in_flight` slots owns a command buffer, a fence,
//! timestamp queries, a stitch buffer, a staging slot, a render target and the semaphore a
//! window image is acquired with. Starting a frame waits only for its slot's previous frame;
//! the frame just submitted is never waited for. Results (GPU times, screenshots) come back as
//! [`Finished`] frames when their slot's fence has signalled. Every GPU allocation happens in
//! [`Renderer::new`] (and on a window resize): the log's `gpu_allocations` proves it.

use std::time::Instant;

use ash::vk;
use bytemuck::Zeroable;
use memory::textures::{TextureConfig, TextureSlots};
use memory::{Config, IndexArrays, Manager, Scheme, Victim};

use crate::camera::Camera;
use crate::interface::{
    FrameConstants, MorphFrame, TileRecord, FLAG_GEOMORPH, FLAG_LEVEL_COLOURS, FLAG_RELIEF,
    FLAG_TEXTURE, FLAG_TILES, RECORDS_OFFSET, RECORD_BYTES,
};
use crate::log::FrameRecord;
use crate::measure::State;
use crate::morph::{self, TileMorph, MAX_LEVELS};
use crate::plan::{self, BorderMismatch, LevelRule, Plan, TexturePlan};
use crate::prefetch::{Predicted, PrefetchOptions, Prefetcher};
use crate::stitch::{pulled, Stitch, MAX_RECORDS};
use crate::target::{Target, COLOR_FORMAT, DEPTH_FORMAT};
use crate::terrain::Terrain;
use crate::vulkan::buffer::BufferDesc;
use crate::vulkan::indices::{self, IndexBuilder};
use crate::vulkan::pipeline::{TerrainPipeline, TerrainSets};
use crate::vulkan::pool::{self, Staging, TilePool};
use crate::vulkan::sync::{self, Commands};
use crate::vulkan::texture::{self, TextureArray, TextureDesc};
use crate::vulkan::timestamps::Timestamps;
use crate::vulkan::{Buffer, Gpu, VkError, VkResult};

/// How to draw.
#[derive(Clone, Debug)]
pub struct Settings {
    /// Pixel tolerance.
    pub tau: f64,
    /// Draw every visible tile at this level.
    pub forced_level: Option<u32>,
    /// Draw every visible tile at its finest level (the baseline).
    pub brute_force: bool,
    pub shading: Shading,
    /// Samples the `Tiles` shading's grid is moved by (0: the tiles; tests use other lines).
    pub tile_grid_offset: f32,
    pub wireframe: bool,
    pub sky: [f32; 3],
    /// Diagnostic: leave the seams open, to see (and test) what stitching closes.
    pub no_stitch: bool,
    /// How the level for tau is chosen (the guaranteed bound, or the old sampling).
    pub bound: crate::lod::Bound,
    /// Continuous levels, heights blended between levels (off: `--no-geomorph`).
    pub geomorph: bool,
    pub morph_shader: MorphShader,
}

/// How the terrain is coloured.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Shading {
    /// The tile set's texture tiles: a photo, or the shaded relief tiletool bakes without
    /// one (tiles without a texture slot fall back to `Tint`).
    Photo,
    /// Grey, lit by each triangle's own normal: the mesh as the level of detail made it.
    Relief,
    /// A hypsometric tint lit by each triangle's normal (the shading without textures).
    #[default]
    Tint,
    /// Level colours (coarse blue to fine red) over the tint.
    Level,
    /// One flat colour per tile, neighbours always different (a diagnostic: where the tile
    /// borders fall on screen). The grid may be moved by `Settings::tile_grid_offset`.
    Tiles,
}

impl Shading {
    pub const ALL: [Shading; 5] = [
        Shading::Photo,
        Shading::Relief,
        Shading::Tint,
        Shading::Level,
        Shading::Tiles,
    ];

    /// The next mode in [`Shading::ALL`] (the window's key).
    pub fn next(self) -> Shading {
        let i = Shading::ALL.iter().position(|&s| s == self).unwrap_or(0);
        Shading::ALL[(i + 1) % Shading::ALL.len()]
    }
}

/// Which vertex shader blends the levels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MorphShader {
    /// The two levels around each vertex's level, two bytes read (the default).
    #[default]
    TwoLevels,
    /// The paper's clamped forward differences as dot products over every stored level (the
    /// reference, `--morph-shader forward-differences`).
    ForwardDifferences,
}

impl Settings {
    pub fn rule(&self) -> LevelRule {
        if self.brute_force {
            LevelRule::Finest
        } else if let Some(l) = self.forced_level {
            LevelRule::Forced(l)
        } else if self.geomorph {
            LevelRule::Morph(self.tau, self.bound)
        } else {
            LevelRule::Tau(self.tau, self.bound)
        }
    }
}

/// GPU memory and transfer settings.
#[derive(Clone, Copy, Debug)]
pub struct MemoryOptions {
    /// Device memory for tile data (the pool is at most this).
    pub gpu_budget_bytes: u64,
    /// Tile data sent per frame at most (see `memory::Manager::plan_frame` for the exceptions).
    pub upload_budget: u64,
    /// The eviction mixture's weight.
    pub weight: f64,
    pub frames_in_flight: usize,
    /// Send every upload through the staging ring, even where the pool is host-visible.
    pub force_staging: bool,
    /// Levels finer than wanted a tile may stay drawn rather than re-sending an index array.
    pub downgrade_slack: u32,
    /// How levels travel (progressive; the others are for comparison and the draw-only limit).
    pub scheme: Scheme,
    pub prefetch: PrefetchOptions,
    /// Allocate texture slots when the tile set has textures (false: geometry only).
    pub textures: bool,
    /// The share of `gpu_budget_bytes` the texture slots may take.
    pub texture_share: f64,
    /// Anisotropic filtering of the textures, up to the device's limit (1: off).
    pub anisotropy: f32,
    /// Build index arrays on the GPU from the resident blocks (the default; sent from the
    /// file instead when the device cannot store 16-bit values from a shader).
    pub index_arrays: IndexArrays,
    /// Read every drawn vertex's height back from the vertex shader (a buffer per frame slot),
    /// for the check against the CPU mirror (`vkterrain --read-back-heights`).
    pub read_back_heights: bool,
}

impl Default for MemoryOptions {
    fn default() -> Self {
        MemoryOptions {
            gpu_budget_bytes: 1 << 30,
            upload_budget: memory::DEFAULT_UPLOAD_BUDGET,
            weight: memory::DEFAULT_WEIGHT,
            frames_in_flight: 2,
            force_staging: false,
            downgrade_slack: memory::DEFAULT_DOWNGRADE_SLACK,
            scheme: Scheme::Progressive,
            prefetch: PrefetchOptions::default(),
            textures: true,
            texture_share: DEFAULT_TEXTURE_SHARE,
            anisotropy: 16.0,
            index_arrays: IndexArrays::Built,
            read_back_heights: false,
        }
    }
}

/// The share of the GPU budget texture slots take by default.
pub const DEFAULT_TEXTURE_SHARE: f64 = 0.25;

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

#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    #[error(transparent)]
    Gpu(#[from] VkError),
    #[error(transparent)]
    TileSet(#[from] BorderMismatch),
    #[error("{0}")]
    Internal(String),
}

/// A frame submitted from a slot and not yet collected.
struct Pending {
    record: FrameRecord,
    screenshot: bool,
    /// With read-back: the draws whose heights the slot's buffer receives, and how many
    /// heights they write.
    read_back: Option<(Vec<DrawnTile>, usize)>,
    started: Instant,
    submitted: Instant,
    /// When the next frame started (the end of this frame's CPU interval).
    ended: Option<Instant>,
}

struct Slot {
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    acquired: vk::Semaphore,
    timestamps: Timestamps,
    stitch: Buffer,
    records: Buffer,
    /// The vertex shader's heights (read-back; 16 bytes unused otherwise).
    heights: Buffer,
    staging: Staging,
    target: Target,
    pending: Option<Pending>,
}

impl Slot {
    fn new(gpu: &Gpu, commands: &Commands, i: usize, sizes: SlotSizes) -> VkResult<Slot> {
        Ok(Slot {
            cmd: commands.allocate(gpu, &format!("frame slot {i} commands"))?,
            fence: sync::fence(gpu, false, &format!("frame slot {i} fence"))?,
            acquired: sync::semaphore(gpu, &format!("frame slot {i} image acquired"))?,
            timestamps: Timestamps::new(gpu, &format!("frame slot {i} timestamps"))?,
            stitch: Buffer::new(
                gpu,
                BufferDesc::upload(sizes.stitch, vk::BufferUsageFlags::INDEX_BUFFER),
                &format!("frame slot {i} stitch geometry"),
            )?,
            records: Buffer::new(
                gpu,
                BufferDesc::upload(sizes.records, vk::BufferUsageFlags::STORAGE_BUFFER),
                &format!("frame slot {i} tile records"),
            )?,
            heights: Buffer::new(
                gpu,
                BufferDesc::readback_storage(sizes.heights),
                &format!("frame slot {i} heights read back"),
            )?,
            staging: Staging::new(gpu, sizes.staging, &format!("frame slot {i} staging"))?,
            target: Target::new(gpu, sizes.extent.0, sizes.extent.1)?,
            pending: None,
        })
    }

    fn destroy(self, gpu: &Gpu) {
        sync::destroy_fence(gpu, self.fence);
        sync::destroy_semaphore(gpu, self.acquired);
        self.timestamps.destroy(gpu);
        self.stitch.destroy(gpu);
        self.records.destroy(gpu);
        self.heights.destroy(gpu);
        self.staging.destroy(gpu);
        self.target.destroy(gpu);
    }
}

#[derive(Clone, Copy)]
struct SlotSizes {
    stitch: u64,
    records: u64,
    heights: u64,
    staging: u64,
    extent: (u32, u32),
}

pub struct Renderer {
    pipeline: TerrainPipeline,
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
    meter: Option<(crate::measure::ErrorMeter, u64)>,
    /// Fault injection for tests (`VKTERRAIN_FAULT`, see [`Fault`]).
    fault: Option<Fault>,
    /// Frames collected by a frame that then failed; [`Renderer::finish_all`] returns them.
    collected: Vec<Finished>,
    /// The camera predictor and the file side of prefetching.
    prefetcher: Prefetcher,
    /// Builds index arrays on the GPU (None: they are sent from the file).
    builder: Option<IndexBuilder>,
}

/// Faults the tests inject through the `VKTERRAIN_FAULT` environment variable, to check the
/// paths that real faults take.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    /// `validation`: the first frame binds an index buffer at an offset that is not a multiple
    /// of the index size, which the validation layer reports.
    Validation,
    /// `device-lost-at-N`: frame N fails as if the device were lost.
    DeviceLostAt(u64),
    /// `oom-above-MB`: allocating a tile pool larger than MB megabytes fails as if device
    /// memory ran out.
    OomAbove(u64),
    /// `truncate-at-N`: before frame N the tile set file is cut to half its length, as another
    /// process rewriting it would.
    TruncateAt(u64),
    /// `texture-seam`: every other tile (by tile column plus row) samples its texture moved by
    /// 4 samples, a misregistration that shows at tile borders (the seam test's control).
    TextureSeam,
    /// `texture-no-clamp`: the shader is told every tile has all its mips, so tiles whose fine
    /// mips are not resident sample memory nothing was copied to (the clamp test's control).
    TextureNoClamp,
    /// `mirror-bias`: the CPU mirror the read-back heights are checked against adds one unit
    /// to every stored morph offset (the read-back test's control).
    MirrorBias,
}

impl Fault {
    pub fn from_env() -> Option<Fault> {
        let v = std::env::var("VKTERRAIN_FAULT").ok()?;
        match v.as_str() {
            "validation" => Some(Fault::Validation),
            "texture-seam" => Some(Fault::TextureSeam),
            "texture-no-clamp" => Some(Fault::TextureNoClamp),
            "mirror-bias" => Some(Fault::MirrorBias),
            _ => {
                let number = |prefix: &str| v.strip_prefix(prefix).and_then(|n| n.parse().ok());
                number("device-lost-at-")
                    .map(Fault::DeviceLostAt)
                    .or_else(|| number("truncate-at-").map(Fault::TruncateAt))
                    .or_else(|| number("oom-above-").map(|mb: u64| Fault::OomAbove(mb << 20)))
            }
        }
    }
}

/// A frame recorded once and replayed (see [`Renderer::record_static`]).
pub struct StaticFrame {
    cmd: vk::CommandBuffer,
    stitch: Option<Buffer>,
    records: Option<Buffer>,
    /// Nothing reads heights back from a replayed frame: a placeholder for the set.
    heights: Option<Buffer>,
    sets: Option<TerrainSets>,
    record: FrameRecord,
}

impl Renderer {
    /// Plans the pool for `terrain` and allocates everything the loop will use.
    pub fn new(
        gpu: &Gpu,
        terrain: &Terrain,
        extent: (u32, u32),
        options: MemoryOptions,
    ) -> VkResult<Renderer> {
        // The shader reads the pool as one storage buffer.
        let readable = u64::from(gpu.properties.limits.max_storage_buffer_range);
        let slot_config = texture_config(gpu, terrain, &options);
        let texture_bytes = slot_config
            .as_ref()
            .map_or(0, |c| c.slots as u64 * c.slot_bytes());
        let slot_count = options.frames_in_flight.max(1);
        let builds_per_frame = builds_per_frame(terrain);
        // The index builder takes at most an eighth of the GPU budget: as many lookups (arrays
        // built at once) as fit, up to eight (2.1 MB); under about 2.5 MB not even one fits,
        // and index arrays are sent.
        // (lookups, bytes) of the builder, when arrays are built.
        let builder_size = [8, 4, 2, 1]
            .into_iter()
            .map(|n| (n, IndexBuilder::bytes_for(slot_count, builds_per_frame, n)))
            .find(|&(_, bytes)| bytes <= options.gpu_budget_bytes / 8)
            .filter(|_| gpu.storage_16bit && options.index_arrays == IndexArrays::Built);
        let index_arrays = match builder_size {
            Some(_) => IndexArrays::Built,
            None => IndexArrays::Sent,
        };
        let builder_bytes = builder_size.map_or(0, |(_, bytes)| bytes);
        let config = Config {
            pool_bytes: options
                .gpu_budget_bytes
                .saturating_sub(texture_bytes + builder_bytes)
                .min(readable),
            upload_budget: options.upload_budget,
            weight: options.weight,
            class_ratio: 2.0,
            scheme: options.scheme,
            victim: Victim::Mixture,
            downgrade_slack: options.downgrade_slack,
            prefetch_free: options.prefetch.free_share,
            index_arrays,
        };
        let fault = Fault::from_env();
        let (manager, pool) = allocate_pool(gpu, terrain, config, options.force_staging, fault)?;
        let textures = match (&slot_config, terrain.texture) {
            (Some(c), Some(layout)) => TextureArray::new(
                gpu,
                TextureDesc {
                    format: vk::Format::BC1_RGB_UNORM_BLOCK,
                    size: layout.size,
                    mips: layout.mips,
                    layers: c.slots as u32,
                    anisotropy: options.anisotropy.clamp(1.0, gpu.max_anisotropy),
                },
                "texture slots",
            ),
            _ => TextureArray::placeholder(gpu),
        };
        let textures = match textures {
            Ok(t) => t,
            Err(e) => {
                pool.destroy(gpu);
                return Err(e);
            }
        };
        let sizes = SlotSizes {
            stitch: stitch_bound(terrain),
            records: RECORDS_OFFSET
                + RECORD_BYTES * terrain.tiles.len().clamp(1, MAX_RECORDS) as u64,
            // Every tile at most once a frame, at its finest level at most.
            heights: if options.read_back_heights {
                4 * terrain
                    .tiles
                    .iter()
                    .filter_map(|t| t.levels.last())
                    .map(|l| u64::from(l.vertex_count()))
                    .sum::<u64>()
                    .max(4)
            } else {
                16
            },
            staging: staging_bound(&manager, options.upload_budget)
                + slot_config
                    .as_ref()
                    .map_or(0, |c| texture_staging_bound(c, options.upload_budget)),
            extent,
        };
        let commands = match Commands::new(gpu, "frame commands") {
            Ok(c) => c,
            Err(e) => {
                pool.destroy(gpu);
                textures.destroy(gpu);
                return Err(e);
            }
        };
        let read_back = options.read_back_heights;
        let pipeline = if read_back && !gpu.vertex_stores {
            Err(VkError::Unsupported(
                "reading heights back needs vertexPipelineStoresAndAtomics, which this device \
                 lacks"
                    .into(),
            ))
        } else {
            TerrainPipeline::new(gpu, COLOR_FORMAT, DEPTH_FORMAT, read_back)
        };
        let mut slots = Vec::new();
        let mut failure = pipeline.as_ref().err().map(|e| e.to_string());
        for i in 0..slot_count {
            if failure.is_some() {
                break;
            }
            match Slot::new(gpu, &commands, i, sizes) {
                Ok(s) => slots.push(s),
                Err(e) => failure = Some(e.to_string()),
            }
        }
        let mut builder = None;
        if let (Some((lookups, _)), None) = (builder_size, &failure) {
            match IndexBuilder::new(gpu, &pool.buffer, slot_count, builds_per_frame, lookups) {
                Ok(b) => builder = Some(b),
                Err(e) => failure = Some(e.to_string()),
            }
        }
        let mut sets = None;
        if let (Ok(p), None) = (&pipeline, &failure) {
            let records: Vec<(&Buffer, &Buffer)> =
                slots.iter().map(|s| (&s.records, &s.heights)).collect();
            match TerrainSets::new(
                gpu,
                p,
                &pool.buffer,
                &records,
                &textures,
                "frame descriptor sets",
            ) {
                Ok(s) => sets = Some(s),
                Err(e) => failure = Some(e.to_string()),
            }
        }
        match (pipeline, failure) {
            (Ok(pipeline), None) => Ok(Renderer {
                pipeline,
                sets,
                commands,
                slots,
                pool,
                manager,
                textures,
                texture_slots: slot_config.map(TextureSlots::new),
                options,
                frame: 0,
                slot_ready: None,
                trace: None,
                last_end: None,
                meter: None,
                fault,
                collected: Vec::new(),
                prefetcher: Prefetcher::new(options.prefetch, terrain.tiles.len()),
                builder,
            }),
            (pipeline, failure) => {
                gpu.wait_idle();
                if let Some(b) = builder {
                    b.destroy(gpu);
                }
                for s in slots {
                    s.destroy(gpu);
                }
                if let Ok(p) = pipeline {
                    p.destroy(gpu);
                }
                commands.destroy(gpu);
                pool.destroy(gpu);
                textures.destroy(gpu);
                Err(VkError::Unsupported(failure.unwrap_or_default()))
            }
        }
    }

    /// Whether index arrays are built on the GPU (else sent from the file).
    pub fn builds_indices(&self) -> bool {
        self.builder.is_some()
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
        self.trace = Some(memory::trace::header(&terrain_costs(&self.manager)));
    }

    /// Measures every `every`-th frame's error in pixels against the source (see
    /// [`crate::measure`]); the log's `max_error_px`.
    pub fn measure_error(&mut self, meter: crate::measure::ErrorMeter, every: u64) {
        self.meter = Some((meter, every.max(1)));
    }

    /// Stops measuring; returns the meter (and its period) to resume with later.
    pub fn take_meter(&mut self) -> Option<(crate::measure::ErrorMeter, u64)> {
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

    /// Makes the next frame's slot free (waiting for the frame that last used it, and
    /// collecting any older frames already done); returns the semaphore a window image must be
    /// acquired with, and the frames finished meanwhile.
    pub fn begin_frame(&mut self, gpu: &Gpu) -> VkResult<(vk::Semaphore, Vec<Finished>)> {
        let n = self.slots.len() as u64;
        let slot = (self.frame % n) as usize;
        if self.slot_ready.is_some() {
            return Ok((self.slots[slot].acquired, Vec::new()));
        }
        let now = Instant::now();
        if let Some(prev) = self.frame.checked_sub(1) {
            if let Some(p) = self.slots[(prev % n) as usize].pending.as_mut() {
                p.ended.get_or_insert(now);
            }
        }
        // Oldest first: the slot's own frame (frame - n) must finish; later ones only if done.
        let mut finished = Vec::new();
        for f in self.frame.saturating_sub(n)..self.frame {
            let s = (f % n) as usize;
            if self.slots[s].pending.is_none() {
                continue;
            }
            if s != slot && !sync::is_signalled(gpu, self.slots[s].fence)? {
                break;
            }
            finished.push(self.collect(gpu, s)?);
        }
        self.slot_ready = Some(now);
        Ok((self.slots[slot].acquired, finished))
    }

    /// The newest frame after which every frame has finished.
    fn completed(&self) -> Option<u64> {
        let n = self.slots.len() as u64;
        let oldest_pending = (self.frame.saturating_sub(n)..self.frame)
            .find(|f| self.slots[(f % n) as usize].pending.is_some());
        match oldest_pending {
            Some(f) => f.checked_sub(1),
            None => self.frame.checked_sub(1),
        }
    }

    /// Waits for the slot's frame and completes its record.
    fn collect(&mut self, gpu: &Gpu, s: usize) -> VkResult<Finished> {
        let slot = &mut self.slots[s];
        let Some(p) = slot.pending.take() else {
            return Err(VkError::Unsupported("no frame pending".into()));
        };
        sync::wait_and_reset(gpu, slot.fence)?;
        if let Some(f) = self.builder.as_mut().and_then(|b| b.take_failure(s)) {
            return Err(VkError::InvalidData(build_failure(f)));
        }
        let slot = &mut self.slots[s];
        let mut record = p.record;
        // frame_ms: the interval between this frame's and the previous frame's completion on
        // the GPU (the cadence a display sees, whatever runs ahead); the first frame costs its
        // CPU time to submission plus its GPU time. Without timestamps: the CPU interval.
        match slot.timestamps.read_ticks(gpu) {
            Some(t) => {
                record.gpu_ms = slot.timestamps.ms_between(t[0], t[3]);
                record.gpu_draw_ms = slot.timestamps.ms_between(t[1], t[2]);
                record.frame_ms = match self.last_end {
                    Some(prev) => slot.timestamps.ms_between(prev, t[3]),
                    None => (p.submitted - p.started).as_secs_f64() * 1000.0 + record.gpu_ms,
                };
                self.last_end = Some(t[3]);
            }
            None => {
                (record.gpu_ms, record.gpu_draw_ms) = (f64::NAN, f64::NAN);
                let end = p.ended.unwrap_or_else(Instant::now);
                record.frame_ms = (end - p.started).as_secs_f64() * 1000.0;
            }
        }
        let pixels = if p.screenshot {
            slot.target.pixels()
        } else {
            None
        };
        let heights = p.read_back.map(|(draws, n)| {
            let values = slot.heights.mapped().map_or_else(Vec::new, |m| {
                bytemuck::cast_slice::<u8, f32>(&m[..(4 * n).min(m.len()) / 4 * 4]).to_vec()
            });
            ReadBack { draws, values }
        });
        let e = slot.target.extent();
        Ok(Finished {
            record,
            pixels,
            extent: (e.width, e.height),
            heights,
        })
    }

    /// Waits for every frame in flight; returns them, oldest first.
    pub fn finish_all(&mut self, gpu: &Gpu) -> VkResult<Vec<Finished>> {
        let n = self.slots.len() as u64;
        let mut finished = std::mem::take(&mut self.collected);
        for f in self.frame.saturating_sub(n)..self.frame {
            let s = (f % n) as usize;
            if self.slots[s].pending.is_some() {
                finished.push(self.collect(gpu, s)?);
            }
        }
        // The GPU idles from here until the next submission: the next frame's interval starts
        // afresh (its CPU time plus its GPU time, as the first frame's).
        self.last_end = None;
        Ok(finished)
    }

    /// Waits for every frame in flight, then forgets every tile: the pool is empty, as at
    /// start, while the driver keeps whatever it warmed up (`vkterrain --warmup-driver`).
    pub fn forget_tiles(&mut self, gpu: &Gpu) -> VkResult<()> {
        self.finish_all(gpu)?;
        let config = *self.manager.config();
        self.manager = Manager::new(terrain_costs(&self.manager), config);
        if let Some(slots) = &mut self.texture_slots {
            *slots = TextureSlots::new(slots.config().clone());
        }
        Ok(())
    }

    /// New render targets for a new window size (after every frame in flight finished).
    pub fn resize(&mut self, gpu: &Gpu, extent: (u32, u32)) -> VkResult<Vec<Finished>> {
        let finished = self.finish_all(gpu)?;
        gpu.wait_idle();
        for slot in &mut self.slots {
            let target = Target::new(gpu, extent.0, extent.1)?;
            std::mem::replace(&mut slot.target, target).destroy(gpu);
        }
        Ok(finished)
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
        let cpu_prefetch_ms = ms(t);
        let prefetch = if self.prefetcher.options.enabled {
            predicted.requests.as_slice()
        } else {
            &[]
        };
        let plan = plan::plan(
            terrain,
            &mut self.manager,
            input.camera,
            extent,
            settings.rule(),
            plan::Residency {
                frame: self.frame,
                completed,
                allow_uploads: true,
                prefetch,
            },
        )?;
        self.write_trace(&plan, &predicted.requests);
        let s = (self.frame % self.slots.len() as u64) as usize;
        let geometry_bytes = plan.stats.upload_bytes_blocks + plan.stats.upload_bytes_indices;
        let textures = self.plan_textures(
            terrain,
            &plan,
            input.camera,
            settings,
            Some(self.options.upload_budget.saturating_sub(geometry_bytes)),
        );

        let t = Instant::now();
        self.slots[s].staging.reset();
        let (moves, staged, builds) = self.write_uploads(terrain, &plan, s)?;
        let staged_geometry = self.slots[s].staging.sent();
        let texture_copies = self.write_texture_uploads(terrain, &textures, s)?;
        let cpu_upload_ms = ms(t);

        let t = Instant::now();
        let slot = &mut self.slots[s];
        let stitch_ranges = write_stitches(&mut slot.stitch, &plan.stitches)?;
        let textured = self.texture_slots.is_some();
        let (constants, morph) =
            pass_constants(terrain, input.camera, &plan.view, settings, textured);
        // The meter and the read-back need each draw's morph inputs; nothing else does.
        let describe = self.meter.is_some() || self.options.read_back_heights;
        let drawn = write_records(
            &mut slot.records,
            terrain,
            input.camera,
            (&plan, &textures),
            morph.as_ref().map(|m| (m, &constants)),
            self.fault,
            describe,
        )?;
        let set = self
            .sets
            .as_ref()
            .map_or(vk::DescriptorSet::null(), |t| t.sets[s]);
        let cmd = slot.cmd;
        sync::begin(gpu, cmd, true)?;
        slot.timestamps.begin(gpu, cmd);
        pool::record_transfers(gpu, cmd, &self.pool, &slot.staging, &moves, &staged);
        texture::record_uploads(
            gpu,
            cmd,
            &self.textures,
            slot.staging.raw(),
            &texture_copies,
        );
        if let Some(b) = &self.builder {
            b.record(gpu, cmd, s, builds);
        }
        slot.timestamps.pass_begin(gpu, cmd);
        let pass = Pass {
            gpu,
            cmd,
            pipeline: &self.pipeline,
            target: &slot.target,
            pool: self.pool.buffer.raw,
            stitch: slot.stitch.raw,
            set,
            terrain,
            settings,
            constants: &constants,
            read_back: self.options.read_back_heights,
            plan: &plan,
            stitch_ranges: &stitch_ranges,
        };
        if self.fault == Some(Fault::Validation) && self.frame == 0 {
            // SAFETY: deliberately invalid (offset 1 for 16-bit indices), for the tests of
            // the validation path; the pass rebinds a valid index buffer before any draw.
            unsafe {
                gpu.device.cmd_bind_index_buffer(
                    cmd,
                    self.pool.buffer.raw,
                    1,
                    vk::IndexType::UINT16,
                );
            }
        }
        let counts = pass.record();
        if self.options.read_back_heights {
            sync::vertex_to_host_barrier(gpu, cmd);
        }
        slot.timestamps.pass_end(gpu, cmd);
        if input.screenshot {
            slot.target.record_readback(gpu, cmd);
        }
        if let Some(p) = &input.present {
            slot.target
                .record_blit(gpu, cmd, p.image, p.extent, input.screenshot);
        }
        slot.timestamps.end(gpu, cmd);
        sync::end(gpu, cmd)?;
        let cpu_record_ms = ms(t);

        sync::submit(
            gpu,
            cmd,
            slot.fence,
            input.present.map(|p| p.acquired),
            input.present.map(|p| p.done),
        )?;
        let mut record = frame_record(&plan, &textures, counts, terrain.levels);
        if let Some((meter, every)) = &mut self.meter {
            if input.label.is_multiple_of(*every) {
                let draws: Vec<(usize, State)> = drawn
                    .iter()
                    .map(|&(tile, level, _, morph)| (tile, State { level, morph }))
                    .collect();
                let m = meter.frame(terrain, input.camera, extent, &draws);
                (record.max_error_px, record.pop_px) = (m.max_error_px, m.pop_px);
            }
        }
        record.frame = input.label;
        record.time_s = input.time_s;
        record.cpu_upload_ms = cpu_upload_ms;
        record.cpu_record_ms = cpu_record_ms;
        record.staged_bytes = staged_geometry;
        record.gpu_allocations = gpu.allocations() - allocations;
        record.prediction_error_m = prediction_error_m;
        record.cpu_prefetch_ms = cpu_prefetch_ms;
        record.file_advised_bytes = predicted.advised_bytes;
        record.file_released_bytes = predicted.released_bytes;
        slot.pending = Some(Pending {
            record,
            screenshot: input.screenshot,
            read_back: self.options.read_back_heights.then(|| {
                let n = drawn.last().map_or(0, |&(tile, level, start, _)| {
                    start + terrain.tiles[tile].levels[level as usize].vertex_count() as usize
                });
                (drawn, n)
            }),
            started,
            submitted: Instant::now(),
            ended: None,
        });
        self.frame += 1;
        self.slot_ready = None;
        Ok(())
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
                plan::plan_textures(terrain, slots, plan, camera.position, residency, budget)
            }
            _ => TexturePlan {
                draws: vec![None; plan.draws.len()],
                ..TexturePlan::default()
            },
        }
    }

    /// Writes the frame's texture mips into the slot's staging memory; returns the copies.
    fn write_texture_uploads(
        &mut self,
        terrain: &Terrain,
        textures: &TexturePlan,
        s: usize,
    ) -> Result<Vec<vk::BufferImageCopy>, FrameError> {
        let mut copies = Vec::with_capacity(textures.uploads.len());
        for u in &textures.uploads {
            let bytes = terrain.texture_mip(u.tile as usize, u.mip).ok_or_else(|| {
                FrameError::Internal(format!("tile {} has no texture mip {}", u.tile, u.mip))
            })?;
            let staging = &mut self.slots[s].staging;
            let at = staging.push_aligned(bytes, TEXTURE_ALIGN).ok_or_else(|| {
                FrameError::Internal(format!(
                    "staging ring full ({} bytes) uploading tile {}'s texture",
                    staging.used(),
                    u.tile
                ))
            })?;
            let texels = self.textures.desc.size >> u.mip;
            copies.push(texture::copy_region(at, u.slot, u.mip, texels.max(1)));
        }
        Ok(copies)
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

    /// Writes the plan's uploads: straight into the pool where that is safe, else into the
    /// slot's staging memory; returns the moves and staged copies to record.
    fn write_uploads(
        &mut self,
        terrain: &Terrain,
        plan: &Plan,
        s: usize,
    ) -> Result<(Vec<vk::BufferCopy>, Vec<vk::BufferCopy>, u32), FrameError> {
        let moves = plan
            .moves
            .iter()
            .map(|m| {
                vk::BufferCopy::default()
                    .src_offset(m.src)
                    .dst_offset(m.dst)
                    .size(m.bytes)
            })
            .collect();
        if self.fault == Some(Fault::TruncateAt(self.frame)) {
            let path = terrain.set.path();
            let half = terrain.set.file_len() / 2;
            let _ = std::fs::OpenOptions::new()
                .write(true)
                .open(path)
                .and_then(|f| f.set_len(half));
        }
        if !plan.uploads.is_empty() {
            // Reading a mapped file that shrank would fault (SIGBUS): check its length before
            // the frame's reads. (A file cut between this check and the copies can still fault;
            // tile sets are meant to be replaced by rename, as tiletool writes them.)
            let now = std::fs::metadata(terrain.set.path()).map(|m| m.len());
            if now
                .as_ref()
                .map_or(true, |&len| len < terrain.set.file_len())
            {
                return Err(FrameError::Internal(format!(
                    "{}: the tile set changed on disk while in use ({} bytes, was {})",
                    terrain.set.path().display(),
                    now.map_or_else(|e| e.to_string(), |l| l.to_string()),
                    terrain.set.file_len()
                )));
            }
        }
        let mut staged = Vec::new();
        let builds = self.write_builds(terrain, plan, s)?;
        for u in plan.uploads.iter().filter(|u| !u.built) {
            self.prefetcher.touched(terrain, u.tile as usize);
            let bytes = terrain.part(u.tile as usize, u.part).ok_or_else(|| {
                FrameError::Internal(format!("tile {} has no {:?}", u.tile, u.part))
            })?;
            if bytes.is_empty() {
                continue;
            }
            if !u.in_flight && self.pool.write(u.dst, bytes) {
                continue;
            }
            let at = self.slots[s].staging.push(bytes).ok_or_else(|| {
                FrameError::Internal(format!(
                    "staging ring full ({} bytes) uploading tile {}",
                    self.slots[s].staging.used(),
                    u.tile
                ))
            })?;
            staged.push(
                vk::BufferCopy::default()
                    .src_offset(at)
                    .dst_offset(u.dst)
                    .size(bytes.len() as u64),
            );
        }
        Ok((moves, staged, builds))
    }

    /// Writes the plan's index array builds ([`memory::gpu_builds`]: a build overlapped by a
    /// later one is left out) into slot `s`'s list; returns how many.
    fn write_builds(
        &mut self,
        terrain: &Terrain,
        plan: &Plan,
        s: usize,
    ) -> Result<u32, FrameError> {
        let Some(builder) = self.builder.as_mut() else {
            return Ok(0);
        };
        let kept = memory::gpu_builds(&plan.uploads);
        let mut builds = Vec::with_capacity(kept.len());
        for u in kept {
            let memory::Part::Indices(level) = u.part else {
                return Err(FrameError::Internal(format!(
                    "tile {}: {:?} built",
                    u.tile, u.part
                )));
            };
            let tile = &terrain.tiles[u.tile as usize];
            let l = &tile.levels[level as usize];
            let word = |bytes: u64, width: u64| {
                u32::try_from(bytes / width).map_err(|_| {
                    FrameError::Internal(format!("pool offset {bytes} past 32-bit indexing"))
                })
            };
            builds.push(indices::Build {
                vertex_word: word(u.chunk, 4)?,
                vertex_count: l.vertex_count(),
                index_at: word(u.dst, u64::from(l.index_width))?,
                index_count: l.index_count,
                index_width: l.index_width,
                mesh_max_x: tile.header.mesh_max_x,
                mesh_max_y: tile.header.mesh_max_y,
                tile: u.tile,
            });
        }
        if !builder.write(s, &builds) {
            return Err(FrameError::Internal(format!(
                "{} index builds in one frame (room for {})",
                builds.len(),
                builder.capacity()
            )));
        }
        Ok(builds.len() as u32)
    }

    /// Records a frame into its own command buffer over what is resident now, for replay
    /// without any per-frame work (the draw-only limit). Nothing is uploaded or evicted, so
    /// frames recorded earlier stay valid; tiles not resident are drawn coarser or not at all
    /// (fly the path once first).
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
            settings.rule(),
            plan::Residency {
                frame: self.frame,
                completed: self.frame.checked_sub(1),
                allow_uploads: false,
                prefetch: &[],
            },
        )?;
        let textures = self.plan_textures(terrain, &plan, camera, settings, None);
        self.frame += 1;
        let bytes: u64 = plan
            .stitches
            .iter()
            .map(|(_, s)| 4 * s.indices.len() as u64)
            .sum();
        let mut frame = StaticFrame {
            cmd: vk::CommandBuffer::null(),
            stitch: None,
            records: None,
            heights: None,
            sets: None,
            record: FrameRecord::default(),
        };
        let result = (|| {
            let usage = vk::BufferUsageFlags::INDEX_BUFFER;
            let stitch = frame.stitch.insert(Buffer::new(
                gpu,
                BufferDesc::upload(bytes.max(4), usage),
                "static stitches",
            )?);
            let ranges = write_stitches(stitch, &plan.stitches)?;
            let record_bytes = RECORDS_OFFSET + RECORD_BYTES * plan.draws.len().max(1) as u64;
            let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
            let records = frame.records.insert(Buffer::new(
                gpu,
                BufferDesc::upload(record_bytes, usage),
                "static tile records",
            )?);
            let textured = self.texture_slots.is_some();
            let (constants, morph) =
                pass_constants(terrain, camera, &plan.view, settings, textured);
            write_records(
                records,
                terrain,
                camera,
                (&plan, &textures),
                morph.as_ref().map(|m| (m, &constants)),
                None,
                false,
            )?;
            let heights = frame.heights.insert(Buffer::new(
                gpu,
                BufferDesc::readback_storage(16),
                "static frame heights (unused)",
            )?);
            let sets = frame.sets.insert(TerrainSets::new(
                gpu,
                &self.pipeline,
                &self.pool.buffer,
                &[(&*records, &*heights)],
                &self.textures,
                "static frame descriptor set",
            )?);
            let set = sets.sets[0];
            let stitch = frame.stitch.as_ref().map_or(vk::Buffer::null(), |b| b.raw);
            frame.cmd = self.commands.allocate(gpu, "static frame")?;
            let cmd = frame.cmd;
            let slot = &self.slots[0];
            sync::begin(gpu, cmd, false)?;
            slot.timestamps.begin(gpu, cmd);
            slot.timestamps.pass_begin(gpu, cmd);
            let counts = Pass {
                gpu,
                cmd,
                pipeline: &self.pipeline,
                target: &slot.target,
                pool: self.pool.buffer.raw,
                stitch,
                set,
                terrain,
                settings,
                constants: &constants,
                read_back: false,
                plan: &plan,
                stitch_ranges: &ranges,
            }
            .record();
            slot.timestamps.pass_end(gpu, cmd);
            slot.timestamps.end(gpu, cmd);
            sync::end(gpu, cmd)?;
            Ok::<_, FrameError>(counts)
        })();
        match result {
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
        if let Some(b) = frame.stitch {
            b.destroy(gpu);
        }
        if let Some(b) = frame.records {
            b.destroy(gpu);
        }
        if let Some(b) = frame.heights {
            b.destroy(gpu);
        }
        if let Some(s) = frame.sets {
            s.destroy(gpu);
        }
    }

    pub fn destroy(self, gpu: &Gpu) {
        gpu.wait_idle();
        if let Some(s) = self.sets {
            s.destroy(gpu);
        }
        for s in self.slots {
            s.destroy(gpu);
        }
        self.pool.destroy(gpu);
        if let Some(b) = self.builder {
            b.destroy(gpu);
        }
        self.textures.destroy(gpu);
        self.pipeline.destroy(gpu);
        self.commands.destroy(gpu);
    }
}

/// The error for a build whose array did not come out as the file says.
fn build_failure(f: indices::BuildFailure) -> String {
    let got = if f.got == u32::MAX {
        "lacks a vertex its fans need".to_string()
    } else {
        format!("has {} indices", f.got)
    };
    format!(
        "tile #{}: the index array built from its vertices {got} where the tile set says {} ({} such builds in the frame): the file's vertices do not make the mesh it claims",
        f.tile, f.expected, f.failed
    )
}

/// Index arrays a frame may build at most: each visible tile's presence, refinement and
/// prefetched spare, and a few prefetched tiles not visible yet.
fn builds_per_frame(terrain: &Terrain) -> usize {
    3 * terrain.tiles.len() + 8
}

/// The smallest pool worth trying when device memory runs short.
const MIN_POOL: u64 = 1 << 20;

/// Plans and allocates the tile pool; when device memory runs out, halves the budget and tries
/// again (down to [`MIN_POOL`]), saying so once on stderr: a smaller pool only means coarser
/// tiles.
fn allocate_pool(
    gpu: &Gpu,
    terrain: &Terrain,
    mut config: Config,
    force_staging: bool,
    fault: Option<Fault>,
) -> VkResult<(Manager, TilePool)> {
    let mut first = None;
    loop {
        let manager = Manager::new(terrain.costs(), config);
        let bytes = manager.pool_bytes();
        let wanted = *first.get_or_insert(bytes);
        let result = match fault {
            Some(Fault::OomAbove(limit)) if bytes > limit => Err(VkError::OutOfMemory),
            _ => TilePool::new(gpu, bytes, force_staging),
        };
        match result {
            Ok(pool) => {
                if bytes < wanted {
                    eprintln!(
                        "vkterrain: note: out of GPU memory for a {:.1} MB tile pool; flying with {:.1} MB (tiles may be drawn coarser)",
                        wanted as f64 / 1e6,
                        bytes as f64 / 1e6
                    );
                }
                return Ok((manager, pool));
            }
            Err(VkError::OutOfMemory | VkError::Allocation(_)) if bytes / 2 >= MIN_POOL => {
                config.pool_bytes = bytes / 2;
            }
            Err(e) => return Err(e),
        }
    }
}

fn terrain_costs(manager: &Manager) -> Vec<memory::TileCost> {
    (0..manager.tile_count())
        .map(|t| manager.tile_cost(t as u32).clone())
        .collect()
}

/// Bytes of stitch geometry a frame can need at most: every pair of neighbouring tiles, each
/// side at its longest border (a 4-index fan per triangle, fewer triangles than vertices).
fn stitch_bound(terrain: &Terrain) -> u64 {
    let longest = |t: usize, side: usize| {
        terrain.tiles[t]
            .borders
            .iter()
            .map(|b| b[side].len() as u64)
            .max()
            .unwrap_or(0)
    };
    let mut bytes = 0;
    for (i, a) in terrain.tiles.iter().enumerate() {
        for (side, (dx, dy)) in [(1usize, (1u32, 0u32)), (2, (0, 1))] {
            if let Some(j) = terrain.tile_index(a.tx + dx, a.ty + dy) {
                let v = longest(i, side) + longest(j, (side + 2) % 4);
                bytes += 16 * v;
            }
        }
    }
    bytes.max(4)
}

/// Bytes a frame can send at most: the budget, every tile's level 0 (presence may overshoot
/// the budget), and the largest single step (taken alone when larger than the budget).
fn staging_bound(manager: &Manager, upload_budget: u64) -> u64 {
    let n = manager.tile_count();
    let costs = (0..n).map(|t| manager.tile_cost(t as u32));
    let presence: u64 = costs
        .clone()
        .map(|c| c.block_bytes(0) + c.levels[0].indices)
        .sum();
    let step = costs.clone().map(|c| c.need(c.finest())).max().unwrap_or(0);
    // No frame sends more than the whole tile set (an unlimited budget is capped there).
    let everything: u64 = costs.map(|c| c.whole()).sum();
    let padding = 4 * 8 * (n as u64 + 1);
    upload_budget.min(everything) + presence + step + padding
}

/// The texture slots `terrain` gets under `options`: as many layers of its texture layout as
/// the budget's texture share holds, at most one per tile and the device's layer limit. None
/// when the set has no textures, they are not wanted, or the device cannot sample BC1.
fn texture_config(gpu: &Gpu, terrain: &Terrain, options: &MemoryOptions) -> Option<TextureConfig> {
    let layout = terrain.texture?;
    if !options.textures {
        return None;
    }
    if !gpu.bc_textures {
        eprintln!("vkterrain: note: the device cannot sample BC1 textures; drawing without the tile set's textures");
        return None;
    }
    let slot_bytes = layout.bytes() as u64;
    let share = (options.gpu_budget_bytes as f64 * options.texture_share.clamp(0.0, 1.0)) as u64;
    let slots = (share / slot_bytes)
        .min(terrain.tiles.len() as u64)
        .min(u64::from(gpu.properties.limits.max_image_array_layers));
    if slots == 0 {
        eprintln!(
            "vkterrain: note: {:.1} MB of the GPU budget holds no {:.2} MB texture slot; drawing without textures",
            share as f64 / 1e6,
            slot_bytes as f64 / 1e6
        );
        return None;
    }
    Some(TextureConfig {
        slots: slots as usize,
        mip_bytes: (0..layout.mips)
            .map(|m| layout.mip_bytes(m) as u64)
            .collect(),
        mip_texels: (0..layout.mips).map(|m| layout.mip_size(m)).collect(),
    })
}

/// Staging bytes the textures of one frame can need: the budget (what geometry leaves of it,
/// never more than every slot's whole chain), every slot's base mips (sent over the budget),
/// and the copies' alignment.
fn texture_staging_bound(config: &TextureConfig, upload_budget: u64) -> u64 {
    let slots = config.slots as u64;
    let base: u64 = config.mip_bytes[config.base() as usize..].iter().sum();
    let padding = TEXTURE_ALIGN * slots * u64::from(config.mips());
    upload_budget.min(slots * config.slot_bytes()) + slots * base + padding
}

/// Alignment of texture copies in the staging buffer (a multiple of the BC1 block's 8 bytes
/// and of 4).
const TEXTURE_ALIGN: u64 = 16;

/// Writes this frame's stitches (their pulled indices) into `buffer`; returns per stitch
/// (first index, index count).
fn write_stitches(
    buffer: &mut Buffer,
    stitches: &[(usize, Stitch)],
) -> Result<Vec<(u32, u32)>, FrameError> {
    let mut ranges = Vec::with_capacity(stitches.len());
    let mut indices: Vec<u32> = Vec::new();
    for (_, s) in stitches {
        ranges.push((indices.len() as u32, s.indices.len() as u32));
        indices.extend(s.gpu_indices());
    }
    if !indices.is_empty() && !buffer.write(0, bytemuck::cast_slice(&indices)) {
        return Err(FrameError::Internal(format!(
            "stitch geometry ({} bytes) does not fit its buffer ({} bytes)",
            4 * indices.len(),
            buffer.size
        )));
    }
    Ok(ranges)
}

/// One draw as its record describes it: the tile, its level, where its vertices' heights go
/// in the read-back buffer, and how it morphs (None: discrete).
pub type DrawnTile = (usize, u32, usize, Option<TileMorph>);

/// The frame's push constants, and its morph constants when it morphs.
fn pass_constants(
    terrain: &Terrain,
    camera: &Camera,
    view: &crate::camera::View,
    settings: &Settings,
    textured: bool,
) -> (FrameConstants, Option<MorphFrame>) {
    let constants = frame_constants(terrain, camera, view, settings, textured);
    let morph = matches!(settings.rule(), LevelRule::Morph(..))
        .then(|| morph::frame_constants(view, settings.tau));
    (constants, morph)
}

/// Writes the frame's morph constants and tile records, one per draw in order (a draw's record
/// is its index); returns each draw as written, with how it morphs only when `describe` (for
/// the error meter and the read-back).
fn write_records(
    buffer: &mut Buffer,
    terrain: &Terrain,
    camera: &Camera,
    (plan, textures): (&Plan, &TexturePlan),
    morph: Option<(&MorphFrame, &FrameConstants)>,
    fault: Option<Fault>,
    describe: bool,
) -> Result<Vec<DrawnTile>, FrameError> {
    if plan.draws.len() > MAX_RECORDS {
        return Err(FrameError::Internal(format!(
            "{} tiles in view; at most {MAX_RECORDS} can be drawn in one frame",
            plan.draws.len()
        )));
    }
    let (cam_tile, _) = terrain.camera_tile(camera.position);
    let mut drawn = Vec::with_capacity(plan.draws.len());
    let mut heights = 0usize;
    let records: Vec<TileRecord> = plan
        .draws
        .iter()
        .zip(&textures.draws)
        .map(|(d, texture)| {
            let info = &terrain.tiles[d.tile];
            let mut r = TileRecord::zeroed();
            (r.texture_layer, r.texture_finest) = match texture {
                Some(t) => (t.layer, t.finest as f32),
                None => (u32::MAX, 0.0),
            };
            match fault {
                Some(Fault::TextureSeam) if (info.tx + info.ty) % 2 == 1 => r.texture_shift = 4.0,
                Some(Fault::TextureNoClamp) => r.texture_finest = 0.0,
                _ => {}
            }
            r.tile_offset = Terrain::tile_offset(cam_tile, info);
            r.height_base = info.header.height_base;
            r.positions = (d.vertex_offset / 4) as u32;
            r.level = d.level;
            r.cap = d.level as f32;
            r.heights = heights as u32;
            let mut starts = [u32::MAX; 8];
            let (mut start, mut rows) = (0u32, d.morph_offset as u32);
            for (j, l) in info.levels.iter().enumerate().take(MAX_LEVELS) {
                r.blocks[j] = [start, l.block_len, rows, 0];
                if j > 0 {
                    starts[j - 1] = start;
                }
                if j < 8 {
                    r.units[j] = l.morph_unit;
                }
                start += l.block_len;
                rows += (j as u32 * l.block_len).div_ceil(4) * 4;
            }
            (r.starts_lo, r.starts_hi) = split(starts);
            if morph.is_some() {
                r.tables = info.tables.map(|t| t.coefficients());
            }
            let tile_morph = morph.filter(|_| describe).map(|(frame, c)| TileMorph {
                view_proj: glam::Mat4::from_cols_array(&c.view_proj),
                camera: glam::Vec4::from_array(c.camera),
                spacing_y: c.spacing_y,
                height_step: c.height_step,
                frame: *frame,
                tile_offset: r.tile_offset,
                cap: r.cap,
                tables: r.tables,
            });
            drawn.push((d.tile, d.level, heights, tile_morph));
            heights += info.levels[d.level as usize].vertex_count() as usize;
            r
        })
        .collect();
    let frame = morph.map_or_else(MorphFrame::zeroed, |(m, _)| *m);
    let written = buffer.write(0, bytemuck::bytes_of(&frame))
        && (records.is_empty()
            || buffer.write(RECORDS_OFFSET as usize, bytemuck::cast_slice(&records)));
    if !written {
        return Err(FrameError::Internal(format!(
            "{} tile records do not fit their buffer ({} bytes)",
            records.len(),
            buffer.size
        )));
    }
    Ok(drawn)
}

/// The halves of an eight-element array (a record's `_lo` and `_hi` vectors).
fn split<T: Copy + Default>(a: [T; 8]) -> ([T; 4], [T; 4]) {
    (
        std::array::from_fn(|i| a[i]),
        std::array::from_fn(|i| a[i + 4]),
    )
}

/// What the terrain pass drew.
#[derive(Clone, Copy, Default)]
struct DrawCounts {
    triangles: u64,
    vertices: u64,
    stitch_triangles: u64,
}

/// The frame's record from its plan (times and GPU results are added later).
fn frame_record(
    plan: &Plan,
    textures: &TexturePlan,
    counts: DrawCounts,
    levels: u32,
) -> FrameRecord {
    let st = &plan.stats;
    let mut tiles_per_level = vec![0; levels as usize];
    for d in &plan.draws {
        tiles_per_level[d.level as usize] += 1;
    }
    FrameRecord {
        cpu_cull_ms: plan.cpu_cull_ms,
        cpu_lod_ms: plan.cpu_lod_ms,
        cpu_stitch_ms: plan.cpu_stitch_ms,
        cpu_residency_ms: plan.cpu_residency_ms,
        gpu_ms: f64::NAN,
        gpu_draw_ms: f64::NAN,
        tiles_visible: plan.tiles_visible,
        tiles_drawn: plan.draws.len() as u64,
        triangles: counts.triangles,
        vertices: counts.vertices,
        stitch_triangles: counts.stitch_triangles,
        upload_bytes: st.upload_bytes_blocks + st.upload_bytes_indices,
        resident_bytes: st.resident_bytes,
        evictions: st.evictions,
        upload_bytes_blocks: st.upload_bytes_blocks,
        upload_bytes_indices: st.upload_bytes_indices,
        index_builds: st.index_builds,
        index_build_bytes: st.index_build_bytes,
        upload_bytes_coarser: st.upload_bytes_coarser,
        uploads_deferred_bytes: st.uploads_deferred_bytes,
        upload_overshoot_bytes: st.upload_overshoot_bytes,
        tiles_coarser: st.tiles_coarser,
        tiles_missing: st.tiles_missing,
        chunks_free: st.chunks_free,
        chunk_moves: st.chunk_moves,
        chunk_move_bytes: st.chunk_move_bytes,
        hits: st.hits,
        misses: st.misses,
        used_bytes: st.used_bytes,
        prefetch_bytes: st.prefetch_bytes,
        prefetch_hits: st.prefetch_hits,
        prefetch_wasted_bytes: st.prefetch_wasted_bytes,
        upload_bytes_textures: textures.stats.upload_bytes,
        texture_slots_free: u64::from(textures.stats.slots_free),
        tiles_texture_coarser: u64::from(textures.stats.coarser + textures.stats.without_slot),
        tiles_per_level,
        max_error_px: f64::NAN,
        pop_px: f64::NAN,
        prediction_error_m: f64::NAN,
        heights_max_diff_m: f64::NAN,
        ..Default::default()
    }
}

/// The terrain pass of one frame: clear, one indexed fan draw per tile from the pool, then
/// the stitches from the slot's stitch buffer; every vertex pulled by the shader with its
/// tile's record.
struct Pass<'a> {
    gpu: &'a Gpu,
    cmd: vk::CommandBuffer,
    pipeline: &'a TerrainPipeline,
    target: &'a Target,
    pool: vk::Buffer,
    stitch: vk::Buffer,
    /// The pool and this frame's records.
    set: vk::DescriptorSet,
    terrain: &'a Terrain,
    settings: &'a Settings,
    constants: &'a FrameConstants,
    /// Draw with the pipeline that writes every vertex's height.
    read_back: bool,
    plan: &'a Plan,
    stitch_ranges: &'a [(u32, u32)],
}

impl Pass<'_> {
    fn record(&self) -> DrawCounts {
        let (gpu, cmd) = (self.gpu, self.cmd);
        self.target
            .begin_rendering(self.gpu, self.cmd, self.settings.sky);
        let pipeline = match (self.settings.wireframe, self.settings.morph_shader) {
            (true, _) => self.pipeline.wireframe.unwrap_or(self.pipeline.fill),
            (false, _) if self.read_back => self.pipeline.read_back.unwrap_or(self.pipeline.fill),
            (false, MorphShader::ForwardDifferences) => self.pipeline.all_rows,
            (false, MorphShader::TwoLevels) => self.pipeline.fill,
        };
        let constants = *self.constants;
        let mut counts = DrawCounts::default();
        // SAFETY: recording inside dynamic rendering; the pool, the records and the stitch
        // buffer outlive the frame, and every range drawn was written before (the manager's
        // grants; records and stitches by this frame).
        unsafe {
            gpu.device
                .cmd_bind_pipeline(cmd, vk::PipelineBindPoint::GRAPHICS, pipeline);
            gpu.device.cmd_bind_descriptor_sets(
                cmd,
                vk::PipelineBindPoint::GRAPHICS,
                self.pipeline.layout,
                0,
                &[self.set],
                &[],
            );
            gpu.device.cmd_push_constants(
                cmd,
                self.pipeline.layout,
                vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT,
                0,
                bytemuck::bytes_of(&constants),
            );
            let mut bound: Option<u32> = None;
            for (record, d) in self.plan.draws.iter().enumerate() {
                if bound != Some(d.index_width) {
                    gpu.device
                        .cmd_bind_index_buffer(cmd, self.pool, 0, index_type(d.index_width));
                    bound = Some(d.index_width);
                }
                // The tile's local indices plus vertexOffset: the pulled index of its record.
                gpu.device.cmd_draw_indexed(
                    cmd,
                    d.index_count,
                    1,
                    (d.index_offset / u64::from(d.index_width)) as u32,
                    pulled(record as u32, 0) as i32,
                    0,
                );
                let entry = &self.terrain.tiles[d.tile].levels[d.level as usize];
                counts.triangles += u64::from(entry.triangle_count);
                counts.vertices += u64::from(entry.vertex_count());
            }
            if !self.settings.no_stitch && !self.plan.stitches.is_empty() {
                gpu.device
                    .cmd_bind_index_buffer(cmd, self.stitch, 0, vk::IndexType::UINT32);
                for ((_, s), &(first, count)) in self.plan.stitches.iter().zip(self.stitch_ranges) {
                    gpu.device.cmd_draw_indexed(cmd, count, 1, first, 0, 0);
                    counts.stitch_triangles += u64::from(s.triangles);
                }
            }
            gpu.device.cmd_end_rendering(cmd);
        }
        counts
    }
}

/// The frame's push constants: the camera, the spacing, the flags for `settings`.
fn frame_constants(
    terrain: &Terrain,
    camera: &Camera,
    view: &crate::camera::View,
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
        pad: 0,
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

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1000.0
}
