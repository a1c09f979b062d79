//! The frame-timing log: CSV with a header row, one row per frame, and a JSON summary.
//!
//! Columns (later versions add columns, never rename; see the README):
//! `frame, time_s, frame_ms, cpu_cull_ms, cpu_lod_ms, cpu_stitch_ms, cpu_upload_ms,
//! cpu_record_ms, gpu_ms, tiles_visible, tiles_drawn, triangles, vertices, stitch_triangles,
//! upload_bytes, resident_bytes, evictions`, then the memory manager's
//! `gpu_allocations, upload_bytes_blocks, upload_bytes_indices, uploads_deferred_bytes,
//! upload_overshoot_bytes, staged_bytes, tiles_coarser, tiles_missing, chunks_free,
//! chunk_moves, chunk_move_bytes, hits, misses, used_bytes, cpu_residency_ms, gpu_draw_ms,
//! upload_bytes_coarser, max_error_px, pop_px`, then prefetching's
//! `prefetch_bytes, prefetch_hits, prefetch_wasted_bytes, prediction_error_m, cpu_prefetch_ms,
//! file_advised_bytes, file_released_bytes`, then the textures'
//! `upload_bytes_textures, texture_slots_free, tiles_texture_coarser`, then the index arrays
//! built on the GPU `index_builds, index_build_bytes`, the heights read back from the vertex
//! shader `heights_read_back, heights_max_diff_m`, the tiles' checks when first needed
//! `cpu_check_ms, tiles_checked, tiles_failed`, drawing part by part
//! `tiles_part_by_part, part_builds`, the morph pass's `tiles_unmorphed`,
//! and last `tiles_level_0 .. tiles_level_{n-1}`.

use std::path::Path;

use frametimes::stats::percentile;
use serde::Serialize;

#[derive(Clone, Debug, Default)]
pub struct FrameRecord {
    pub frame: u64,
    pub time_s: f64,
    pub frame_ms: f64,
    pub cpu_cull_ms: f64,
    pub cpu_lod_ms: f64,
    pub cpu_stitch_ms: f64,
    /// Writing this frame's uploads (into the pool or the staging ring).
    pub cpu_upload_ms: f64,
    pub cpu_record_ms: f64,
    /// The memory manager's decisions.
    pub cpu_residency_ms: f64,
    /// The whole command buffer: transfers, terrain pass, read-back, blit. NaN when the queue
    /// has no timestamps.
    pub gpu_ms: f64,
    /// The terrain pass alone (tile and stitch draws).
    pub gpu_draw_ms: f64,
    pub tiles_visible: u64,
    pub tiles_drawn: u64,
    pub triangles: u64,
    pub vertices: u64,
    pub stitch_triangles: u64,
    /// Tile data sent this frame (blocks + index arrays).
    pub upload_bytes: u64,
    /// Bytes of chunks owned by tiles.
    pub resident_bytes: u64,
    pub evictions: u64,
    /// GPU memory allocations made during the frame (0 after the first: the pool is fixed).
    pub gpu_allocations: u64,
    pub upload_bytes_blocks: u64,
    pub upload_bytes_indices: u64,
    /// Index arrays built on the GPU this frame, and their bytes (not sent: not in
    /// `upload_bytes`).
    pub index_builds: u64,
    pub index_build_bytes: u64,
    /// With `--read-back-heights`: drawn vertices whose height the vertex shader wrote and the
    /// CPU mirror recomputed, and the largest difference between the two (m; NaN: none).
    pub heights_read_back: u64,
    pub heights_max_diff_m: f64,
    /// Of `upload_bytes_indices`: coarser index arrays for tiles whose wanted level dropped.
    pub upload_bytes_coarser: u64,
    /// With `--measure-error`: the largest screen distance, pixels, between the drawn surface
    /// and a source sample (NaN when not measured this frame).
    pub max_error_px: f64,
    /// With `--measure-error`: the largest screen jump of a surface point from the previous
    /// measured frame's levels to this frame's, under this frame's camera (NaN when not
    /// measured, and on the first measured frame).
    pub pop_px: f64,
    /// Bytes still needed to draw every visible tile at its wanted level.
    pub uploads_deferred_bytes: u64,
    /// Bytes sent beyond the upload budget (new tiles' level 0, or one step larger than it).
    pub upload_overshoot_bytes: u64,
    /// Bytes that went through the staging ring (the rest was written in place).
    pub staged_bytes: u64,
    /// Visible tiles drawn below the level they wanted.
    pub tiles_coarser: u64,
    /// Visible tiles with nothing resident (not drawn).
    pub tiles_missing: u64,
    pub chunks_free: u64,
    pub chunk_moves: u64,
    pub chunk_move_bytes: u64,
    /// Visible tiles drawn at their wanted level with no upload.
    pub hits: u64,
    pub misses: u64,
    /// Bytes of tile data in the owned chunks.
    pub used_bytes: u64,
    /// Of `upload_bytes`: sent for tiles predicted to become visible.
    pub prefetch_bytes: u64,
    /// Tiles drawn this frame from data prefetched for them (each prefetch counted once).
    pub prefetch_hits: u64,
    /// Prefetched bytes evicted this frame before anything drew them.
    pub prefetch_wasted_bytes: u64,
    /// The distance, metres, between where the shortest horizon (0.25 s or one frame, the
    /// longer) predicted the camera and where it was when that time came (NaN when no
    /// prediction fell due this frame).
    pub prediction_error_m: f64,
    /// Predicting the camera, culling and choosing levels for it, and advising the kernel.
    pub cpu_prefetch_ms: f64,
    /// Bytes of the tile set newly advised `WILLNEED` (read ahead) and `DONTNEED` (released).
    pub file_advised_bytes: u64,
    pub file_released_bytes: u64,
    /// Texture mips sent this frame (not counted in `upload_bytes`, which is geometry).
    pub upload_bytes_textures: u64,
    /// Texture slots holding no tile.
    pub texture_slots_free: u64,
    /// Drawn tiles whose texture is coarser than their footprint wants, or missing (no slot).
    pub tiles_texture_coarser: u64,
    /// Checking tiles that came into view unchecked, before their first upload, and how
    /// many; tiles that have failed their checks so far (never drawn).
    pub cpu_check_ms: f64,
    pub tiles_checked: u64,
    pub tiles_failed: u64,
    /// Tiles drawn part by part (`crate::parts`), and the arrays built for them this frame
    /// besides the manager's (`index_builds`).
    pub tiles_part_by_part: u64,
    pub part_builds: u64,
    /// Morphing tiles the morph pass skipped, drawn at their own heights: the frame's morphed
    /// heights (a share of the GPU budget) could not hold its vertices, so none was morphed.
    pub tiles_unmorphed: u64,
    pub tiles_per_level: Vec<u64>,
}

pub const BASE_COLUMNS: [&str; 56] = [
    "frame",
    "time_s",
    "frame_ms",
    "cpu_cull_ms",
    "cpu_lod_ms",
    "cpu_stitch_ms",
    "cpu_upload_ms",
    "cpu_record_ms",
    "gpu_ms",
    "tiles_visible",
    "tiles_drawn",
    "triangles",
    "vertices",
    "stitch_triangles",
    "upload_bytes",
    "resident_bytes",
    "evictions",
    "gpu_allocations",
    "upload_bytes_blocks",
    "upload_bytes_indices",
    "uploads_deferred_bytes",
    "upload_overshoot_bytes",
    "staged_bytes",
    "tiles_coarser",
    "tiles_missing",
    "chunks_free",
    "chunk_moves",
    "chunk_move_bytes",
    "hits",
    "misses",
    "used_bytes",
    "cpu_residency_ms",
    "gpu_draw_ms",
    "upload_bytes_coarser",
    "max_error_px",
    "pop_px",
    "prefetch_bytes",
    "prefetch_hits",
    "prefetch_wasted_bytes",
    "prediction_error_m",
    "cpu_prefetch_ms",
    "file_advised_bytes",
    "file_released_bytes",
    "upload_bytes_textures",
    "texture_slots_free",
    "tiles_texture_coarser",
    "index_builds",
    "index_build_bytes",
    "heights_read_back",
    "heights_max_diff_m",
    "cpu_check_ms",
    "tiles_checked",
    "tiles_failed",
    "tiles_part_by_part",
    "part_builds",
    "tiles_unmorphed",
];

pub fn header(levels: u32) -> String {
    let mut cols: Vec<String> = BASE_COLUMNS.iter().map(|s| s.to_string()).collect();
    cols.extend((0..levels).map(|l| format!("tiles_level_{l}")));
    cols.join(",")
}

/// A time in ms with four decimals, empty when unknown.
/// Milliseconds since `t` (the log's unit of time).
pub fn ms(t: std::time::Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1000.0
}

fn ms_cell(v: f64) -> String {
    if v.is_nan() {
        String::new()
    } else {
        format!("{v:.4}")
    }
}

impl FrameRecord {
    pub fn csv_row(&self) -> String {
        let n = |v: u64| v.to_string();
        // In the header's order.
        let cells = [
            n(self.frame),
            ms_cell(self.time_s),
            ms_cell(self.frame_ms),
            ms_cell(self.cpu_cull_ms),
            ms_cell(self.cpu_lod_ms),
            ms_cell(self.cpu_stitch_ms),
            ms_cell(self.cpu_upload_ms),
            ms_cell(self.cpu_record_ms),
            ms_cell(self.gpu_ms),
            n(self.tiles_visible),
            n(self.tiles_drawn),
            n(self.triangles),
            n(self.vertices),
            n(self.stitch_triangles),
            n(self.upload_bytes),
            n(self.resident_bytes),
            n(self.evictions),
            n(self.gpu_allocations),
            n(self.upload_bytes_blocks),
            n(self.upload_bytes_indices),
            n(self.uploads_deferred_bytes),
            n(self.upload_overshoot_bytes),
            n(self.staged_bytes),
            n(self.tiles_coarser),
            n(self.tiles_missing),
            n(self.chunks_free),
            n(self.chunk_moves),
            n(self.chunk_move_bytes),
            n(self.hits),
            n(self.misses),
            n(self.used_bytes),
            ms_cell(self.cpu_residency_ms),
            ms_cell(self.gpu_draw_ms),
            n(self.upload_bytes_coarser),
            ms_cell(self.max_error_px),
            ms_cell(self.pop_px),
            n(self.prefetch_bytes),
            n(self.prefetch_hits),
            n(self.prefetch_wasted_bytes),
            ms_cell(self.prediction_error_m),
            ms_cell(self.cpu_prefetch_ms),
            n(self.file_advised_bytes),
            n(self.file_released_bytes),
            n(self.upload_bytes_textures),
            n(self.texture_slots_free),
            n(self.tiles_texture_coarser),
            n(self.index_builds),
            n(self.index_build_bytes),
            n(self.heights_read_back),
            if self.heights_max_diff_m.is_nan() {
                String::new()
            } else {
                format!("{:.3e}", self.heights_max_diff_m)
            },
            ms_cell(self.cpu_check_ms),
            n(self.tiles_checked),
            n(self.tiles_failed),
            n(self.tiles_part_by_part),
            n(self.part_builds),
            n(self.tiles_unmorphed),
        ];
        let levels = self.tiles_per_level.iter().map(|&v| n(v));
        cells
            .into_iter()
            .chain(levels)
            .collect::<Vec<_>>()
            .join(",")
    }

    /// All the frame's CPU work: its decisions, its uploads and the checks of tiles that came
    /// into view unchecked.
    pub fn cpu_ms(&self) -> f64 {
        self.overhead_ms() + self.cpu_upload_ms + self.cpu_check_ms
    }

    /// The per-frame decision and recording work: cull + LOD + residency + stitch + record
    /// (writing uploads, which depends on what became visible, is counted apart).
    pub fn overhead_ms(&self) -> f64 {
        self.cpu_prefetch_ms
            + self.cpu_cull_ms
            + self.cpu_lod_ms
            + self.cpu_residency_ms
            + self.cpu_stitch_ms
            + self.cpu_record_ms
    }
}

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
    /// Opening the tile set (header, directory, tile outlines), and checking the tiles of the
    /// first view before the first frame (ms).
    pub open_ms: f64,
    pub first_view_check_ms: f64,
    /// Tiles that failed their checks (never drawn; exit code 4).
    pub tiles_failed: u64,
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

fn sorted(values: impl Iterator<Item = f64>) -> Vec<f64> {
    let mut v: Vec<f64> = values.filter(|x| !x.is_nan()).collect();
    v.sort_by(f64::total_cmp);
    v
}

impl Summary {
    pub fn of(records: &[FrameRecord], run: &RunInfo) -> Summary {
        let ms = sorted(records.iter().map(|r| r.frame_ms));
        let gpu = sorted(records.iter().map(|r| r.gpu_ms));
        let draw = sorted(records.iter().map(|r| r.gpu_draw_ms));
        let cpu = sorted(records.iter().map(FrameRecord::cpu_ms));
        let uploads = sorted(records.iter().map(|r| r.upload_bytes as f64));
        let predicted = sorted(records.iter().map(|r| r.prediction_error_m));
        let total_ms: f64 = ms.iter().sum();
        let tris: u64 = records
            .iter()
            .map(|r| r.triangles + r.stitch_triangles)
            .sum();
        let sum = |f: fn(&FrameRecord) -> u64| records.iter().map(f).sum::<u64>();
        let median = percentile(&ms, 50.0);
        let per_frame: Vec<(u64, u64)> = records
            .iter()
            .map(|r| (r.tiles_coarser, r.tiles_missing))
            .collect();
        let (warmup_frames, tiles_coarser_warm) = memory::sim::cold_start(&per_frame);
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
            first_frames_ratio: records
                .iter()
                .take(3)
                .map(|r| r.frame_ms / median)
                .reduce(f64::max)
                .unwrap_or(f64::NAN),
            prime_ms: run.prime_ms,
            open_ms: run.open_ms,
            first_view_check_ms: run.first_view_check_ms,
            tiles_checked_in_frames: sum(|r| r.tiles_checked),
            check_ms_in_frames: records.iter().map(|r| r.cpu_check_ms).sum(),
            tiles_failed: run.tiles_failed,
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
            part_by_part: run.part_by_part,
            index_builds: sum(|r| r.index_builds),
            index_build_mb: sum(|r| r.index_build_bytes) as f64 / 1e6,
            heights_read_back: sum(|r| r.heights_read_back),
            heights_max_diff_m: max_measured(records, |r| r.heights_max_diff_m),
            gpu_allocations_after_first_frame: records
                .iter()
                .skip(1)
                .map(|r| r.gpu_allocations)
                .sum(),
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
            cpu_prefetch_ms_median: percentile(
                &sorted(records.iter().map(|r| r.cpu_prefetch_ms)),
                50.0,
            ),
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

/// Writes the log through a temporary file renamed into place, so no half-written log looks
/// complete.
pub fn write_csv(path: &Path, levels: u32, records: &[FrameRecord]) -> std::io::Result<()> {
    let mut csv = String::new();
    for row in std::iter::once(header(levels)).chain(records.iter().map(FrameRecord::csv_row)) {
        csv.push_str(&row);
        csv.push('\n');
    }
    tiles::format::write_atomically(path, csv.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_match_the_header_and_percentiles_interpolate() {
        let r = FrameRecord {
            tiles_per_level: vec![1, 2, 3],
            gpu_ms: f64::NAN,
            ..Default::default()
        };
        assert_eq!(r.csv_row().split(',').count(), header(3).split(',').count());
        let records: Vec<FrameRecord> = (1..=100)
            .map(|i| FrameRecord {
                frame_ms: f64::from(i),
                gpu_ms: f64::NAN,
                ..Default::default()
            })
            .collect();
        let s = Summary::of(&records, &RunInfo::default());
        // The same interpolating definition as `frametimes`.
        assert_eq!(s.frame_ms_median, 50.5);
        assert!((s.frame_ms_p95 - 95.05).abs() < 1e-9);
        assert_eq!(s.frame_ms_max, 100.0);
        assert!(s.gpu_ms_median.is_none());
    }
}
