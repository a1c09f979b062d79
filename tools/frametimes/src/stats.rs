//! Summary figures of one log.
//!
//! Percentiles use linear interpolation between closest ranks (the R-7 / NumPy default):
//! `p` sits at position `p/100 * (n-1)` of the sorted times. The standard deviation is the
//! sample one (n-1). Jank is the time past the frame budget summed over frames:
//! `sum(max(0, frame_ms - budget))`.

use serde::Serialize;

use crate::log::FrameLog;

/// CPU stage columns, in frame order.
pub const CPU_STAGES: [&str; 5] = [
    "cpu_cull_ms",
    "cpu_lod_ms",
    "cpu_stitch_ms",
    "cpu_upload_ms",
    "cpu_record_ms",
];

#[derive(Clone, Debug, Serialize)]
pub struct Stats {
    pub file: String,
    pub frames: usize,
    /// Sum of frame times, seconds.
    pub duration_s: f64,
    pub mean_ms: f64,
    pub median_ms: f64,
    pub p95_ms: f64,
    pub p99_ms: f64,
    pub max_ms: f64,
    pub std_dev_ms: f64,
    pub budget_ms: f64,
    pub jank_ms: f64,
    pub frames_over_budget: usize,
    /// Million triangles (tiles plus stitches) per second of frame time, if logged.
    pub mtri_per_s: Option<f64>,
    pub upload_mb: Option<f64>,
    pub gpu_median_ms: Option<f64>,
    /// Mean milliseconds per frame of each CPU stage present in the log.
    pub cpu_stages_ms: Vec<(String, f64)>,
    pub notes: Vec<String>,
}

/// The `p`-th percentile of sorted values, linearly interpolated.
pub fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let pos = p / 100.0 * (sorted.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64)
}

pub fn median(values: &[f64]) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    percentile(&v, 50.0)
}

fn finite_sum(values: &[f64]) -> f64 {
    values.iter().filter(|v| v.is_finite()).sum()
}

impl Stats {
    pub fn of(log: &FrameLog, budget_ms: f64) -> Stats {
        let ms = log.frame_ms();
        let mut sorted = ms.to_vec();
        sorted.sort_by(f64::total_cmp);
        let n = ms.len();
        let total: f64 = ms.iter().sum();
        let mean = total / n.max(1) as f64;
        let var = if n > 1 {
            ms.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64
        } else {
            0.0
        };
        let triangles = log
            .column("triangles")
            .map(|t| finite_sum(t) + log.column("stitch_triangles").map_or(0.0, finite_sum));
        Stats {
            file: log.name(),
            frames: n,
            duration_s: total / 1000.0,
            mean_ms: mean,
            median_ms: percentile(&sorted, 50.0),
            p95_ms: percentile(&sorted, 95.0),
            p99_ms: percentile(&sorted, 99.0),
            max_ms: sorted.last().copied().unwrap_or(f64::NAN),
            std_dev_ms: var.sqrt(),
            budget_ms,
            jank_ms: ms.iter().map(|x| (x - budget_ms).max(0.0)).sum(),
            frames_over_budget: ms.iter().filter(|&&x| x > budget_ms).count(),
            mtri_per_s: triangles.map(|t| t / 1e6 / (total / 1000.0).max(1e-12)),
            upload_mb: log.column("upload_bytes").map(|b| finite_sum(b) / 1e6),
            gpu_median_ms: log.column("gpu_ms").map(median).filter(|m| m.is_finite()),
            cpu_stages_ms: CPU_STAGES
                .iter()
                .filter_map(|&c| {
                    log.column(c)
                        .map(|v| (c.to_string(), finite_sum(v) / n.max(1) as f64))
                })
                .collect(),
            notes: log.notes.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_interpolate_between_ranks() {
        let v: Vec<f64> = (1..=10).map(f64::from).collect();
        assert_eq!(percentile(&v, 50.0), 5.5);
        assert!((percentile(&v, 95.0) - 9.55).abs() < 1e-12);
        assert_eq!(percentile(&v, 100.0), 10.0);
        assert_eq!(percentile(&[4.0], 99.0), 4.0);
    }
}
