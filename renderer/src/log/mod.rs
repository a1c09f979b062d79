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
//! `tiles_part_by_part, part_builds`, the morph pass's `tiles_unmorphed`, the tiles drawn from
//! the pyramid's layers above the base grid `tiles_above_base` and the tiles of its cut an
//! ancestor (or a coarser checked level) stood in for `tiles_stood_in` (`--pyramid`), the index
//! arrays made on the CPU rather than built on the GPU `index_arrays_made`, the tiles drawn by
//! the pipeline whose fragment shader has the texture's path alone `tiles_photo`, the terrain
//! pass as the GPU counted it (pipeline statistics, empty where the device does not count
//! them) `gpu_primitives, gpu_primitives_after_clipping, gpu_vertex_invocations,
//! gpu_fragment_invocations`, and last `tiles_level_0 .. tiles_level_{n-1}`.

use std::path::Path;

mod summary;

pub use summary::{RunInfo, Summary};

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
    /// Drawn tiles of the pyramid's layers above the base grid (`--pyramid`; 0 otherwise).
    pub tiles_above_base: u64,
    /// Tiles of the pyramid's cut drawn by an ancestor: not checked yet (`--checks`), failed,
    /// or beside a tile two layers coarser; or held at a coarser level of their own until the
    /// finer one passes its check (`--checks behind`) (`--pyramid`; 0 otherwise).
    pub tiles_stood_in: u64,
    /// Of the frame's index arrays (`index_builds` and `part_builds`), those made on the CPU
    /// and copied into place rather than built on the GPU (`--index-builder`).
    pub index_arrays_made: u64,
    /// Tiles drawn by the pipeline whose fragment shader has the texture's path alone (shaded
    /// by their texture this frame, `--one-fragment-shader` off).
    pub tiles_photo: u64,
    /// The terrain pass as the GPU counted it, where the device counts pipeline statistics.
    pub pass_statistics: Option<crate::vulkan::timestamps::PassStatistics>,
    pub tiles_per_level: Vec<u64>,
}

pub const BASE_COLUMNS: [&str; 64] = [
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
    "tiles_above_base",
    "tiles_stood_in",
    "index_arrays_made",
    "tiles_photo",
    "gpu_primitives",
    "gpu_primitives_after_clipping",
    "gpu_vertex_invocations",
    "gpu_fragment_invocations",
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
            n(self.tiles_above_base),
            n(self.tiles_stood_in),
            n(self.index_arrays_made),
            n(self.tiles_photo),
        ];
        let counted = self.pass_statistics.map(|s| {
            [
                s.primitives,
                s.clipped_primitives,
                s.vertex_invocations,
                s.fragment_invocations,
            ]
        });
        let cells = cells
            .into_iter()
            .chain((0..4).map(|k| counted.map_or_else(String::new, |c| c[k].to_string())));
        let levels = self.tiles_per_level.iter().map(|&v| n(v));
        cells.chain(levels).collect::<Vec<_>>().join(",")
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
