//! The frame-timing log: CSV with a header row, one row per frame, and a JSON summary.
//!
//! Columns (later versions add columns, never rename; see the README):
//! `frame, time_s, frame_ms, cpu_cull_ms, cpu_lod_ms, cpu_stitch_ms, cpu_upload_ms,
//! cpu_record_ms, gpu_ms, tiles_visible, tiles_drawn, triangles, vertices, stitch_triangles,
//! upload_bytes, resident_bytes, evictions, tiles_level_0 .. tiles_level_{n-1}`.

use std::io::Write;
use std::path::Path;

use serde::Serialize;

#[derive(Clone, Debug, Default)]
pub struct FrameRecord {
    pub frame: u64,
    pub time_s: f64,
    pub frame_ms: f64,
    pub cpu_cull_ms: f64,
    pub cpu_lod_ms: f64,
    pub cpu_stitch_ms: f64,
    pub cpu_upload_ms: f64,
    pub cpu_record_ms: f64,
    /// NaN when the queue has no timestamps.
    pub gpu_ms: f64,
    pub tiles_visible: u64,
    pub tiles_drawn: u64,
    pub triangles: u64,
    pub vertices: u64,
    pub stitch_triangles: u64,
    pub upload_bytes: u64,
    pub resident_bytes: u64,
    pub evictions: u64,
    pub tiles_per_level: Vec<u64>,
}

pub const BASE_COLUMNS: [&str; 17] = [
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
];

pub fn header(levels: u32) -> String {
    let mut cols: Vec<String> = BASE_COLUMNS.iter().map(|s| s.to_string()).collect();
    cols.extend((0..levels).map(|l| format!("tiles_level_{l}")));
    cols.join(",")
}

impl FrameRecord {
    pub fn csv_row(&self) -> String {
        let gpu = if self.gpu_ms.is_nan() {
            String::new()
        } else {
            format!("{:.4}", self.gpu_ms)
        };
        let mut row = format!(
            "{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{gpu},{},{},{},{},{},{},{},{}",
            self.frame,
            self.time_s,
            self.frame_ms,
            self.cpu_cull_ms,
            self.cpu_lod_ms,
            self.cpu_stitch_ms,
            self.cpu_upload_ms,
            self.cpu_record_ms,
            self.tiles_visible,
            self.tiles_drawn,
            self.triangles,
            self.vertices,
            self.stitch_triangles,
            self.upload_bytes,
            self.resident_bytes,
            self.evictions
        );
        for n in &self.tiles_per_level {
            row += &format!(",{n}");
        }
        row
    }

    pub fn cpu_ms(&self) -> f64 {
        self.overhead_ms() + self.cpu_upload_ms
    }

    /// The per-frame decision and recording work: cull + LOD + stitch + record (uploads,
    /// which depend on what became visible, are counted apart).
    pub fn overhead_ms(&self) -> f64 {
        self.cpu_cull_ms + self.cpu_lod_ms + self.cpu_stitch_ms + self.cpu_record_ms
    }
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
    pub gpu_ms_median: Option<f64>,
    pub cpu_ms_median: f64,
    /// Per-frame CPU overhead (cull + LOD + stitch + record) as a share of the frame time.
    pub cpu_share: f64,
    /// CPU time preparing uploads (staging copies, residency) as a share of the frame time.
    pub upload_share: f64,
    pub triangles_per_frame_mean: f64,
    pub mtri_per_s: f64,
    pub upload_mb: f64,
    pub validation_messages: u64,
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = (p / 100.0 * (sorted.len() - 1) as f64).round() as usize;
    sorted[rank.min(sorted.len() - 1)]
}

impl Summary {
    pub fn of(
        records: &[FrameRecord],
        device: &str,
        size: (u32, u32),
        tau: f64,
        brute_force: bool,
        validation: u64,
    ) -> Summary {
        let mut ms: Vec<f64> = records.iter().map(|r| r.frame_ms).collect();
        ms.sort_by(f64::total_cmp);
        let mut gpu: Vec<f64> = records
            .iter()
            .map(|r| r.gpu_ms)
            .filter(|g| !g.is_nan())
            .collect();
        gpu.sort_by(f64::total_cmp);
        let mut cpu: Vec<f64> = records.iter().map(FrameRecord::cpu_ms).collect();
        cpu.sort_by(f64::total_cmp);
        let total_ms: f64 = ms.iter().sum();
        let tris: u64 = records
            .iter()
            .map(|r| r.triangles + r.stitch_triangles)
            .sum();
        Summary {
            frames: records.len(),
            device: device.to_string(),
            width: size.0,
            height: size.1,
            tau,
            brute_force,
            frame_ms_mean: total_ms / records.len().max(1) as f64,
            frame_ms_median: percentile(&ms, 50.0),
            frame_ms_p95: percentile(&ms, 95.0),
            frame_ms_p99: percentile(&ms, 99.0),
            frame_ms_max: ms.last().copied().unwrap_or(f64::NAN),
            gpu_ms_median: (!gpu.is_empty()).then(|| percentile(&gpu, 50.0)),
            cpu_ms_median: percentile(&cpu, 50.0),
            cpu_share: records.iter().map(FrameRecord::overhead_ms).sum::<f64>()
                / total_ms.max(1e-9),
            upload_share: records.iter().map(|r| r.cpu_upload_ms).sum::<f64>() / total_ms.max(1e-9),
            triangles_per_frame_mean: tris as f64 / records.len().max(1) as f64,
            mtri_per_s: tris as f64 / (total_ms / 1000.0).max(1e-9) / 1e6,
            upload_mb: records.iter().map(|r| r.upload_bytes).sum::<u64>() as f64 / 1e6,
            validation_messages: validation,
        }
    }
}

/// Writes the log to a temporary file and renames it into place.
pub fn write_csv(path: &Path, levels: u32, records: &[FrameRecord]) -> std::io::Result<()> {
    let tmp = path.with_extension("csv.tmp");
    {
        let mut f = std::io::BufWriter::new(std::fs::File::create(&tmp)?);
        writeln!(f, "{}", header(levels))?;
        for r in records {
            writeln!(f, "{}", r.csv_row())?;
        }
        f.flush()?;
    }
    std::fs::rename(&tmp, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_match_the_header_and_percentiles_are_exact_on_ranks() {
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
        let s = Summary::of(&records, "test", (1, 1), 1.0, false, 0);
        assert_eq!(s.frame_ms_median, 51.0);
        assert_eq!(s.frame_ms_p95, 95.0);
        assert_eq!(s.frame_ms_max, 100.0);
        assert!(s.gpu_ms_median.is_none());
    }
}
