//! Comparing two logs: the ratio of median frame times with a bootstrap confidence interval,
//! and a Mann-Whitney rank test on the per-frame times.
//!
//! The bootstrap resamples each log's frames with replacement (2000 times, a fixed seed so
//! runs repeat) and takes the 2.5th and 97.5th percentiles of `median(B*) / median(A*)`. A
//! difference is called *beyond noise* when that 95% interval excludes 1. The rank test
//! (two-sided, normal approximation with tie correction) is reported beside it. Frames of one
//! run are not independent samples (a slow stretch of path is slow in both runs), so both are
//! guides, not proofs; logs of the same path with the same frame count compare best.

use serde::Serialize;
use splitmix::Rng;

use crate::log::FrameLog;
use crate::stats::{percentile, Stats};

pub const RESAMPLES: usize = 2000;
const SEED: u64 = 0x5eed_f00d_cafe_1234;

#[derive(Clone, Debug, Serialize)]
pub struct Comparison {
    pub baseline: String,
    pub other: String,
    /// median(other) / median(baseline).
    pub median_ratio: f64,
    pub ci_low: f64,
    pub ci_high: f64,
    pub mann_whitney_p: f64,
    pub beyond_noise: bool,
}

impl Comparison {
    /// Whether `other` is slower than the baseline by more than `percent`, beyond noise: the
    /// whole confidence interval of the median ratio lies above `1 + percent / 100`.
    pub fn slower_by_more_than(&self, percent: f64) -> bool {
        self.ci_low > 1.0 + percent / 100.0
    }

    pub fn verdict(&self) -> String {
        let change = (self.median_ratio - 1.0) * 100.0;
        let what = if !self.beyond_noise {
            "within noise".to_string()
        } else if change > 0.0 {
            format!("{change:.1}% slower, beyond noise")
        } else {
            format!("{:.1}% faster, beyond noise", -change)
        };
        format!(
            "{} vs {}: median ratio {:.3} (95% bootstrap CI {:.3}..{:.3}), Mann-Whitney p = {:.2e}: {what}",
            self.other, self.baseline, self.median_ratio, self.ci_low, self.ci_high, self.mann_whitney_p
        )
    }
}

/// A standard normal draw (Box-Muller).
fn normal(rng: &mut Rng) -> f64 {
    let (u, v) = (rng.open_unit(), rng.open_unit());
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

/// Gamma(shape, 1) for shape >= 1 (Marsaglia and Tsang).
fn gamma(rng: &mut Rng, shape: f64) -> f64 {
    let d = shape - 1.0 / 3.0;
    let c = 1.0 / (9.0 * d).sqrt();
    loop {
        let x = normal(rng);
        let v = (1.0 + c * x).powi(3);
        if v <= 0.0 {
            continue;
        }
        if rng.open_unit().ln() < 0.5 * x * x + d - d * v + d * v.ln() {
            return d * v;
        }
    }
}

fn beta(rng: &mut Rng, a: f64, b: f64) -> f64 {
    let x = gamma(rng, a);
    x / (x + gamma(rng, b))
}

/// The median of a bootstrap resample of `sorted` (n draws with replacement), drawn without
/// drawing the resample: a resampled value is `sorted[ceil(n U) - 1]` for a uniform `U`,
/// monotone in `U`, so the resample's k-th smallest value comes from the k-th smallest of n
/// uniforms, which is Beta(k, n - k + 1); the next one above it is that plus
/// `(1 - U_k) Beta(1, n - k)`. O(1) per resample instead of sorting n values (a 4.5 M-frame
/// log took minutes).
fn resampled_median(sorted: &[f64], rng: &mut Rng) -> f64 {
    let n = sorted.len();
    if n <= 1 {
        return sorted.first().copied().unwrap_or(f64::NAN);
    }
    let at = |u: f64| sorted[((u * n as f64).ceil() as usize).clamp(1, n) - 1];
    // Percentile 50 of n values: the ((n + 1) / 2)-th for odd n, the mean of the (n / 2)-th
    // and the next for even n (1-based).
    let k = n.div_ceil(2);
    let u_k = beta(rng, k as f64, (n - k + 1) as f64);
    if n % 2 == 1 {
        return at(u_k);
    }
    let v = rng.open_unit();
    let u_next = u_k + (1.0 - u_k) * (1.0 - v.powf(1.0 / (n - k) as f64));
    0.5 * (at(u_k) + at(u_next))
}

/// The 95% bootstrap interval of median(b) / median(a).
pub fn bootstrap_median_ratio(a: &[f64], b: &[f64]) -> (f64, f64) {
    let mut rng = Rng(SEED);
    let sorted = |v: &[f64]| {
        let mut s = v.to_vec();
        s.sort_unstable_by(f64::total_cmp);
        s
    };
    let (a, b) = (sorted(a), sorted(b));
    let mut ratios: Vec<f64> = (0..RESAMPLES)
        .map(|_| {
            let ma = resampled_median(&a, &mut rng);
            let mb = resampled_median(&b, &mut rng);
            mb / ma
        })
        .collect();
    ratios.sort_unstable_by(f64::total_cmp);
    (percentile(&ratios, 2.5), percentile(&ratios, 97.5))
}

/// Two-sided Mann-Whitney U test p-value (normal approximation, tie-corrected, continuity
/// corrected).
pub fn mann_whitney_p(a: &[f64], b: &[f64]) -> f64 {
    let (na, nb) = (a.len() as f64, b.len() as f64);
    if a.is_empty() || b.is_empty() {
        return f64::NAN;
    }
    let mut all: Vec<(f64, bool)> = a
        .iter()
        .map(|&x| (x, true))
        .chain(b.iter().map(|&x| (x, false)))
        .collect();
    all.sort_by(|x, y| x.0.total_cmp(&y.0));
    let n = all.len();
    let (mut rank_sum_a, mut ties) = (0.0f64, 0.0f64);
    let mut i = 0;
    while i < n {
        let mut j = i;
        while j + 1 < n && all[j + 1].0 == all[i].0 {
            j += 1;
        }
        let rank = (i + j) as f64 / 2.0 + 1.0;
        let t = (j - i + 1) as f64;
        ties += t * t * t - t;
        rank_sum_a += all[i..=j].iter().filter(|e| e.1).count() as f64 * rank;
        i = j + 1;
    }
    let u = rank_sum_a - na * (na + 1.0) / 2.0;
    let mean = na * nb / 2.0;
    let nt = na + nb;
    let var = na * nb / 12.0 * ((nt + 1.0) - ties / (nt * (nt - 1.0)));
    if var <= 0.0 {
        return 1.0;
    }
    let z = ((u - mean).abs() - 0.5).max(0.0) / var.sqrt();
    (2.0 * (1.0 - normal_cdf(z))).clamp(0.0, 1.0)
}

/// Standard normal CDF (Abramowitz and Stegun 7.1.26 for erf, error below 1.5e-7).
fn normal_cdf(z: f64) -> f64 {
    let x = z / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    let erf = 1.0 - poly * (-x * x).exp();
    0.5 * (1.0 + if x >= 0.0 { erf } else { -erf })
}

pub fn compare(baseline: &FrameLog, other: &FrameLog) -> Comparison {
    let (a, b) = (baseline.frame_ms(), other.frame_ms());
    let (sa, sb) = (
        Stats::of(baseline, f64::INFINITY),
        Stats::of(other, f64::INFINITY),
    );
    let (ci_low, ci_high) = bootstrap_median_ratio(a, b);
    Comparison {
        baseline: baseline.name(),
        other: other.name(),
        median_ratio: sb.median_ms / sa.median_ms,
        ci_low,
        ci_high,
        mann_whitney_p: mann_whitney_p(a, b),
        beyond_noise: ci_low > 1.0 || ci_high < 1.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_cdf_matches_tables() {
        assert!((normal_cdf(0.0) - 0.5).abs() < 1e-7);
        assert!((normal_cdf(1.959_964) - 0.975).abs() < 1e-6);
        assert!((normal_cdf(-1.0) - 0.158_655_25).abs() < 1e-6);
    }

    #[test]
    fn mann_whitney_on_a_hand_computed_example() {
        // a = 1..5, b = 6..10: U_a = 0, mean 12.5, var = 25/12 * 11 = 22.9167, z = (12.5-0.5)/4.787
        // = 2.5067, p = 2 * (1 - Phi(2.5067)) = 0.01219.
        let a: Vec<f64> = (1..=5).map(f64::from).collect();
        let b: Vec<f64> = (6..=10).map(f64::from).collect();
        assert!(
            (mann_whitney_p(&a, &b) - 0.012_19).abs() < 2e-4,
            "{}",
            mann_whitney_p(&a, &b)
        );
        // Identical samples: no evidence of a difference.
        assert!(mann_whitney_p(&a, &a) > 0.9);
    }

    /// The shortcut draws resample medians from the same distribution as resampling: on odd
    /// and even sizes, quantiles of 20 000 medians each way agree to a rank.
    #[test]
    fn resampled_medians_match_explicit_resampling() {
        for n in [41usize, 40, 7, 2] {
            let sorted: Vec<f64> = (0..n).map(|i| (i * i) as f64).collect();
            let mut rng = Rng(7);
            let draws = 20_000;
            let mut fast: Vec<f64> = (0..draws)
                .map(|_| resampled_median(&sorted, &mut rng))
                .collect();
            let mut slow: Vec<f64> = (0..draws)
                .map(|_| {
                    let mut r: Vec<f64> = (0..n).map(|_| sorted[rng.below(n)]).collect();
                    r.sort_unstable_by(f64::total_cmp);
                    percentile(&r, 50.0)
                })
                .collect();
            // Means within four standard errors of each other.
            let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
            let (mf, ms) = (mean(&fast), mean(&slow));
            let var = slow.iter().map(|x| (x - ms).powi(2)).sum::<f64>() / draws as f64;
            let se = (2.0 * var / draws as f64).sqrt();
            assert!(
                (mf - ms).abs() <= 4.0 * se + 1e-9,
                "n {n}: means {mf} vs {ms} (se {se})"
            );
            fast.sort_unstable_by(f64::total_cmp);
            slow.sort_unstable_by(f64::total_cmp);
            for q in [2.5, 25.0, 50.0, 75.0, 97.5] {
                let (f, s) = (percentile(&fast, q), percentile(&slow, q));
                // Within the gap to the neighbouring values of the sorted data.
                let i = sorted.partition_point(|&v| v < s).min(n - 1);
                let gap = sorted[(i + 1).min(n - 1)] - sorted[i.saturating_sub(1)];
                assert!((f - s).abs() <= gap, "n {n} q {q}: {f} vs {s} (gap {gap})");
            }
        }
    }

    #[test]
    fn bootstrap_brackets_a_clear_shift_and_straddles_none() {
        let a: Vec<f64> = (0..400).map(|i| 10.0 + f64::from(i % 17) * 0.1).collect();
        let b: Vec<f64> = a.iter().map(|x| x * 1.3).collect();
        let (lo, hi) = bootstrap_median_ratio(&a, &b);
        assert!(lo > 1.2 && hi < 1.4 && lo <= 1.3 && hi >= 1.3, "{lo}..{hi}");
        let (lo, hi) = bootstrap_median_ratio(&a, &a.iter().rev().copied().collect::<Vec<_>>());
        assert!(lo <= 1.0 && hi >= 1.0, "{lo}..{hi}");
    }
}
