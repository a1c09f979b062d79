//! The run's JSON summary: what the run was ([`RunInfo`]) and what its frames measured, as
//! medians, percentiles, sums and maxima over the log's records ([`Summary::of`]).

use frametimes::stats::percentile;
use serde::Serialize;

use super::FrameRecord;

/// What a run was: the device and the settings that shape its numbers.
#[derive(Clone, Debug, Default)]
pub struct RunInfo {
    pub device: String,
    pub size: (u32, u32),
    pub tau: f64,
    pub brute_force: bool,
    pub validation_messages: u64,
    pub pool_bytes: u64,
    pub upload_budget: u64,
    pub frames_in_flight: usize,
    /// Uploads went through the staging ring (not written in place).
    pub staging: bool,
    /// How levels travel: "progressive", "per-level" or "whole-tile".
    pub upload_scheme: &'static str,
    /// Where index arrays came from: "built" on the GPU or "sent" from the file.
    pub index_arrays: &'static str,
    /// Where a compact set's levels were decoded: "gpu" (sent as their streams) or "cpu"
    /// (sent as the positions the CPU rebuilt); "none" for other sets.
    pub levels_decoded_on: &'static str,
    /// Who made the built index arrays: "gpu" (the builder's compute pass) or "cpu" (made
    /// from the tiles' checked levels and copied into place, as far as the staging memory
    /// held them; the log's `index_arrays_made`); "none" where they were sent.
    pub index_builder: &'static str,
    /// Geomorphing tiles drawn part by part (chosen, or the device's default; arrays built).
    pub part_by_part: bool,
    /// Device memory of the texture slots (0: none).
    pub texture_bytes: u64,
    /// The tile set's mapping resident in the process when the flight ended (None: unknown).
    pub file_mapped_bytes: Option<u64>,
    /// Of the mapping, what opening the set had paged in and `--file-cache-mb` gave back
    /// before the flight.
    pub file_released_at_open_bytes: u64,
    /// Drawing the first view once before the timed flight (ms; None: not primed).
    pub prime_ms: Option<f64>,
    /// Opening the tile set (its header and directory), and checking the tiles of the
    /// first view before the first frame (ms).
    pub open_ms: f64,
    pub first_view_check_ms: f64,
    /// Tiles that failed their checks (never drawn; exit code 4).
    pub tiles_failed: u64,
    /// Tile outlines (header and level table) read over the run: each tile is read when
    /// first asked for, with its neighbours' (`scene::store`), not at open.
    pub outlines_read: u64,
    /// Tiles in the set as opened (every pyramid layer's with `--pyramid`).
    pub tiles: u64,
    /// Tiles whose tables the GPU pool was planned from (`--plan-sample`).
    pub pool_planned_from: u64,
}

#[derive(Serialize, Debug)]
pub struct Summary {
    pub frames: usize,
    pub device: String,
    pub width: u32,
    pub height: u32,
    pub tau: f64,
    pub brute_force: bool,
    pub frame_ms_mean: f64,
    pub frame_ms_median: f64,
    pub frame_ms_p95: f64,
    pub frame_ms_p99: f64,
    pub frame_ms_max: f64,
    /// The first frame against the median: what a cold start costs.
    pub first_frame_ratio: f64,
    /// The slowest of the first three frames against the median.
    pub first_frames_ratio: f64,
    /// Drawing the first view once, untimed, before the flight (ms; None: not primed).
    pub prime_ms: Option<f64>,
    /// Opening the tile set and checking the first view's tiles (ms), and the checks of tiles
    /// that came into view unchecked during the flight (in the frames' CPU time).
    pub open_ms: f64,
    pub first_view_check_ms: f64,
    pub tiles_checked_in_frames: u64,
    pub check_ms_in_frames: f64,
    /// Tiles that failed their checks and were not drawn.
    pub tiles_failed: u64,
    /// Tile outlines read over the run, of the tiles in the set as opened.
    pub outlines_read: u64,
    pub tiles: u64,
    pub pool_planned_from: u64,
    pub gpu_ms_median: Option<f64>,
    pub gpu_draw_ms_median: Option<f64>,
    pub cpu_ms_median: f64,
    /// Per-frame CPU overhead (cull + LOD + residency + stitch + record) as a share of the
    /// frame time.
    pub cpu_share: f64,
    /// CPU time writing uploads as a share of the frame time.
    pub upload_share: f64,
    pub triangles_per_frame_mean: f64,
    pub mtri_per_s: f64,
    pub upload_mb: f64,
    pub upload_mb_blocks: f64,
    pub upload_mb_indices: f64,
    pub upload_mb_coarser: f64,
    /// With `--measure-error`: the largest `max_error_px` of the flight, and how many frames
    /// were measured.
    pub max_error_px: Option<f64>,
    pub frames_measured: usize,
    /// The largest `pop_px` of the flight.
    pub pop_px: Option<f64>,
    pub staged_mb: f64,
    pub upload_bytes_p99: f64,
    pub upload_overshoot_mb: f64,
    pub pool_mb: f64,
    /// None: unlimited (the baselines).
    pub upload_budget_mb: Option<f64>,
    pub frames_in_flight: usize,
    pub staging: bool,
    pub upload_scheme: &'static str,
    pub index_arrays: &'static str,
    pub levels_decoded_on: &'static str,
    pub index_builder: &'static str,
    pub part_by_part: bool,
    /// Index arrays built on the GPU, and their megabytes (written in GPU memory, not sent).
    pub index_builds: u64,
    pub index_build_mb: f64,
    /// With `--read-back-heights`: vertices compared over the flight, and the largest
    /// difference between the GPU's height and the CPU mirror's (m).
    pub heights_read_back: u64,
    pub heights_max_diff_m: Option<f64>,
    /// GPU allocations after the first frame (the pool is allocated once: 0).
    pub gpu_allocations_after_first_frame: u64,
    /// Frames drawn unmorphed while morphing: their draws needed more morphed heights than
    /// the morph pass's share of the budget holds (`tiles_unmorphed`).
    pub frames_unmorphed: u64,
    pub hits: u64,
    pub misses: u64,
    pub evictions: u64,
    pub chunk_moves: u64,
    /// Tile-frames drawn below the wanted level.
    pub tiles_coarser: u64,
    /// Tile-frames with a visible tile not drawn.
    pub tiles_missing: u64,
    /// The cold start: frames before the first that draws every visible tile at its wanted
    /// level (nothing to predict from yet).
    pub warmup_frames: u64,
    /// Of `tiles_coarser`: those after the cold start.
    pub tiles_coarser_warm: u64,
    pub prefetch_mb: f64,
    pub prefetch_hits: u64,
    pub prefetch_wasted_mb: f64,
    /// The shortest horizon's prediction error, metres: median and largest.
    pub prediction_error_m_median: Option<f64>,
    pub prediction_error_m_max: Option<f64>,
    pub cpu_prefetch_ms_median: f64,
    /// The file side (`--file-cache-mb`): the mapping given back after opening the set, the
    /// tiles advised `DONTNEED` during the flight, and how much of the mapping the process
    /// held when the flight ended.
    pub file_released_at_open_mb: f64,
    pub file_released_mb: f64,
    pub file_mapped_mb_end: Option<f64>,
    /// The texture slots' memory, the texture bytes sent, and the tile-frames whose texture
    /// was coarser than wanted or missing.
    pub texture_mb: f64,
    pub upload_mb_textures: f64,
    pub tiles_texture_coarser: u64,
    pub validation_messages: u64,
}

/// The largest of a per-frame measure over the frames that measured it (None: none did).
fn max_measured(records: &[FrameRecord], f: fn(&FrameRecord) -> f64) -> Option<f64> {
    records
        .iter()
        .map(f)
        .filter(|e| !e.is_nan())
        .reduce(f64::max)
}

/// A per-frame measure over the frames that measured it, in increasing order.
/// The frames a flight took to warm up, and the tile-frames drawn coarser after them
/// (`memory::sim::cold_start`).
fn cold_start(records: &[FrameRecord]) -> (u64, u64) {
    let per_frame: Vec<(u64, u64)> = records
        .iter()
        .map(|r| (r.tiles_coarser, r.tiles_missing))
        .collect();
    memory::sim::cold_start(&per_frame)
}

fn sorted_by(records: &[FrameRecord], f: fn(&FrameRecord) -> f64) -> Vec<f64> {
    let mut v: Vec<f64> = records.iter().map(f).filter(|x| !x.is_nan()).collect();
    v.sort_by(f64::total_cmp);
    v
}

impl Summary {
    pub fn of(records: &[FrameRecord], run: &RunInfo) -> Summary {
        let ms = sorted_by(records, |r| r.frame_ms);
        let gpu = sorted_by(records, |r| r.gpu_ms);
        let draw = sorted_by(records, |r| r.gpu_draw_ms);
        let cpu = sorted_by(records, FrameRecord::cpu_ms);
        let uploads = sorted_by(records, |r| r.upload_bytes as f64);
        let predicted = sorted_by(records, |r| r.prediction_error_m);
        let total_ms: f64 = ms.iter().sum();
        let tris: u64 = records
            .iter()
            .map(|r| r.triangles + r.stitch_triangles)
            .sum();
        let sum = |f: fn(&FrameRecord) -> u64| records.iter().map(f).sum::<u64>();
        let median = percentile(&ms, 50.0);
        let (warmup_frames, tiles_coarser_warm) = cold_start(records);
        Summary {
            frames: records.len(),
            device: run.device.clone(),
            width: run.size.0,
            height: run.size.1,
            tau: run.tau,
            brute_force: run.brute_force,
            frame_ms_mean: total_ms / records.len().max(1) as f64,
            frame_ms_median: median,
            frame_ms_p95: percentile(&ms, 95.0),
            frame_ms_p99: percentile(&ms, 99.0),
            frame_ms_max: ms.last().copied().unwrap_or(f64::NAN),
            first_frame_ratio: records.first().map_or(f64::NAN, |r| r.frame_ms / median),
            first_frames_ratio: max_measured(&records[..records.len().min(3)], |r| r.frame_ms)
                .map_or(f64::NAN, |first| first / median),
            prime_ms: run.prime_ms,
            open_ms: run.open_ms,
            first_view_check_ms: run.first_view_check_ms,
            tiles_checked_in_frames: sum(|r| r.tiles_checked),
            check_ms_in_frames: records.iter().map(|r| r.cpu_check_ms).sum(),
            tiles_failed: run.tiles_failed,
            outlines_read: run.outlines_read,
            tiles: run.tiles,
            pool_planned_from: run.pool_planned_from,
            gpu_ms_median: (!gpu.is_empty()).then(|| percentile(&gpu, 50.0)),
            gpu_draw_ms_median: (!draw.is_empty()).then(|| percentile(&draw, 50.0)),
            cpu_ms_median: percentile(&cpu, 50.0),
            cpu_share: records.iter().map(FrameRecord::overhead_ms).sum::<f64>()
                / total_ms.max(1e-9),
            upload_share: records.iter().map(|r| r.cpu_upload_ms).sum::<f64>() / total_ms.max(1e-9),
            triangles_per_frame_mean: tris as f64 / records.len().max(1) as f64,
            mtri_per_s: tris as f64 / (total_ms / 1000.0).max(1e-9) / 1e6,
            upload_mb: sum(|r| r.upload_bytes) as f64 / 1e6,
            upload_mb_blocks: sum(|r| r.upload_bytes_blocks) as f64 / 1e6,
            upload_mb_indices: sum(|r| r.upload_bytes_indices) as f64 / 1e6,
            upload_mb_coarser: sum(|r| r.upload_bytes_coarser) as f64 / 1e6,
            max_error_px: max_measured(records, |r| r.max_error_px),
            frames_measured: records.iter().filter(|r| !r.max_error_px.is_nan()).count(),
            pop_px: max_measured(records, |r| r.pop_px),
            staged_mb: sum(|r| r.staged_bytes) as f64 / 1e6,
            upload_bytes_p99: percentile(&uploads, 99.0),
            upload_overshoot_mb: sum(|r| r.upload_overshoot_bytes) as f64 / 1e6,
            pool_mb: run.pool_bytes as f64 / 1e6,
            upload_budget_mb: (run.upload_budget != u64::MAX)
                .then(|| run.upload_budget as f64 / 1e6),
            frames_in_flight: run.frames_in_flight,
            staging: run.staging,
            upload_scheme: run.upload_scheme,
            index_arrays: run.index_arrays,
            levels_decoded_on: run.levels_decoded_on,
            index_builder: run.index_builder,
            part_by_part: run.part_by_part,
            index_builds: sum(|r| r.index_builds),
            index_build_mb: sum(|r| r.index_build_bytes) as f64 / 1e6,
            heights_read_back: sum(|r| r.heights_read_back),
            heights_max_diff_m: max_measured(records, |r| r.heights_max_diff_m),
            gpu_allocations_after_first_frame: sum(|r| r.gpu_allocations)
                - records.first().map_or(0, |r| r.gpu_allocations),
            frames_unmorphed: records.iter().filter(|r| r.tiles_unmorphed > 0).count() as u64,
            hits: sum(|r| r.hits),
            misses: sum(|r| r.misses),
            evictions: sum(|r| r.evictions),
            chunk_moves: sum(|r| r.chunk_moves),
            tiles_coarser: sum(|r| r.tiles_coarser),
            tiles_missing: sum(|r| r.tiles_missing),
            warmup_frames,
            tiles_coarser_warm,
            prefetch_mb: sum(|r| r.prefetch_bytes) as f64 / 1e6,
            prefetch_hits: sum(|r| r.prefetch_hits),
            prefetch_wasted_mb: sum(|r| r.prefetch_wasted_bytes) as f64 / 1e6,
            prediction_error_m_median: (!predicted.is_empty())
                .then(|| percentile(&predicted, 50.0)),
            prediction_error_m_max: predicted.last().copied(),
            cpu_prefetch_ms_median: percentile(&sorted_by(records, |r| r.cpu_prefetch_ms), 50.0),
            file_released_at_open_mb: run.file_released_at_open_bytes as f64 / 1e6,
            file_released_mb: sum(|r| r.file_released_bytes) as f64 / 1e6,
            file_mapped_mb_end: run.file_mapped_bytes.map(|b| b as f64 / 1e6),
            texture_mb: run.texture_bytes as f64 / 1e6,
            upload_mb_textures: sum(|r| r.upload_bytes_textures) as f64 / 1e6,
            tiles_texture_coarser: sum(|r| r.tiles_texture_coarser),
            validation_messages: run.validation_messages,
        }
    }
}
