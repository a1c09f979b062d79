//! Residency policies replayed on recorded traces (`memsim`, and `tilebench memory`).

use std::time::Instant;

use memory::sim::{replay, tile_set_bytes, Outcome};
use memory::trace::Trace;
use memory::{Config, Manager, Scheme, TileCost, Victim};

/// The policies compared: the manager over a sweep of its weight, its two pure ingredients,
/// the two naive schemes, and Belady's rule as the reference.
pub fn policies(pool: u64, upload_budget: u64) -> Vec<(String, Config)> {
    let base = Config {
        pool_bytes: pool,
        upload_budget,
        ..Config::default()
    };
    let mut out = Vec::new();
    for w in [0.0, 0.5, 1.0, 2.0, 4.0] {
        out.push((
            format!("mixture, weight {w}"),
            Config {
                weight: w,
                victim: Victim::Mixture,
                ..base
            },
        ));
    }
    out.push((
        "pure LRU".into(),
        Config {
            victim: Victim::Lru,
            ..base
        },
    ));
    out.push((
        "pure tightest fit".into(),
        Config {
            victim: Victim::TightestFit,
            ..base
        },
    ));
    out.push((
        "whole tiles (old scheme), LRU".into(),
        Config {
            victim: Victim::Lru,
            scheme: Scheme::WholeTile,
            ..base
        },
    ));
    out.push((
        "per level from scratch".into(),
        Config {
            scheme: Scheme::PerLevel,
            ..base
        },
    ));
    out.push((
        "Belady (knows the future)".into(),
        Config {
            victim: Victim::Belady,
            ..base
        },
    ));
    out
}

/// Every policy replayed on `trace` with a pool of `pool` bytes, Belady's rule last.
pub fn policy_runs(trace: &Trace, pool: u64, upload_budget: u64) -> Vec<(String, Outcome)> {
    policies(pool, upload_budget)
        .into_iter()
        .map(|(name, c)| (name, replay(trace, c, 2)))
        .collect()
}

/// The name of the manager's default policy in [`policies`].
pub fn default_policy() -> String {
    format!("mixture, weight {}", memory::DEFAULT_WEIGHT)
}

/// `name`'s (misses, bytes) over Belady's (the last run).
pub fn against_belady(runs: &[(String, Outcome)], name: &str) -> (f64, f64) {
    let ratio = |a: u64, b: u64| a as f64 / (b as f64).max(1.0);
    let belady = runs.last().map(|r| r.1).unwrap_or_default();
    runs.iter()
        .find(|(n, _)| n == name)
        .map_or((f64::NAN, f64::NAN), |(_, o)| {
            (
                ratio(o.misses, belady.misses),
                ratio(o.bytes(), belady.bytes()),
            )
        })
}

/// A markdown table of the runs, with ratios against Belady's rule.
pub fn policy_table(runs: &[(String, Outcome)]) -> String {
    let mut t = String::from(
        "| policy | hits | misses | misses / Belady | coarser tile-frames | missing tile-frames | MB uploaded | MB / Belady | of which indices | evictions | chunk moves |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for (name, o) in runs {
        let (rm, rb) = against_belady(runs, name);
        t += &format!(
            "| {name} | {} | {} | {rm:.2}x | {} | {} | {:.1} | {rb:.2}x | {:.0}% | {} | {} |\n",
            o.hits,
            o.misses,
            o.coarser,
            o.missing,
            o.bytes() as f64 / 1e6,
            100.0 * o.bytes_indices as f64 / (o.bytes() as f64).max(1.0),
            o.evictions,
            o.moves,
        );
    }
    t
}

/// Bytes moved over the flight by the three transfer schemes with room for everything.
pub fn bytes_by_scheme(trace: &Trace) -> [Outcome; 3] {
    [Scheme::WholeTile, Scheme::PerLevel, Scheme::Progressive].map(|scheme| {
        let c = Config {
            pool_bytes: u64::MAX / 4,
            upload_budget: u64::MAX / 4,
            scheme,
            victim: Victim::Lru,
            ..Config::default()
        };
        replay(trace, c, 2)
    })
}

/// The tile set's own figures: refining every tile from its second-finest level to the finest
/// (one block and one index array), sending the finest from scratch, and the whole set.
pub fn tile_set_figures(trace: &Trace) -> (u64, u64, u64) {
    let (mut refine, mut scratch) = (0, 0);
    for c in &trace.costs {
        let f = c.finest();
        let last = &c.levels[f as usize];
        refine += c.block_bytes(f) + last.indices;
        scratch += (0..=f).map(|j| c.block_bytes(j)).sum::<u64>() + last.indices;
    }
    (refine, scratch, tile_set_bytes(trace))
}

/// Times the manager's `plan_frame` on [`memory::sim::synthetic`]: 1280 tiles (`costs`
/// repeated), 1000 visible, 400 frames, a pool of a quarter of the set, two frames in flight.
/// Returns the frame count, the sorted times (ms) and the evictions.
pub fn time_manager(costs: &[TileCost]) -> (usize, Vec<f64>, u64) {
    let trace = memory::sim::synthetic(costs, 1280, 1000, 400);
    let total: u64 = trace.costs.iter().map(|c| c.whole()).sum();
    let config = Config {
        pool_bytes: total / 4,
        ..Config::default()
    };
    let mut m = Manager::new(trace.costs.clone(), config);
    let mut times = Vec::with_capacity(trace.frames.len());
    let mut evictions = 0;
    for (f, requests) in trace.frames.iter().enumerate() {
        let f = f as u64;
        let start = Instant::now();
        let plan = m.plan_frame(f, f.checked_sub(2), requests, true);
        times.push(start.elapsed().as_secs_f64() * 1000.0);
        evictions += plan.stats.evictions;
    }
    times.sort_by(f64::total_cmp);
    (trace.frames.len(), times, evictions)
}

/// Replays `trace` without prefetching, with the predictions it recorded, and with a perfect
/// predictor (the next `ahead` frames' requests): tile-frames drawn coarser than wanted,
/// missing, bytes prefetched, hits and waste, as a Markdown table.
pub fn prefetch_table(
    trace: &Trace,
    pool: u64,
    upload: u64,
    ahead: usize,
    index_arrays: memory::IndexArrays,
) -> String {
    use memory::sim::{replay_prefetching, Prefetching};
    let c = memory::Config {
        pool_bytes: pool,
        upload_budget: upload,
        index_arrays,
        ..memory::Config::default()
    };
    let runs = [
        ("no prefetching", Prefetching::Off),
        ("recorded predictions (ours)", Prefetching::Recorded),
        (
            "perfect predictor (upper bound)",
            Prefetching::Perfect { frames: ahead },
        ),
    ];
    let off = replay_prefetching(trace, c, 2, Prefetching::Off);
    let mut out = String::from("| prefetching | tile-frames coarser | vs none | after the cold start | vs none | cold-start frames | missing | uploaded MB | prefetched MB | hits | wasted MB |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    let ratio = |a: u64, b: u64| {
        if b == 0 {
            "-".to_string()
        } else {
            format!("{:.2}", a as f64 / b as f64)
        }
    };
    for (name, p) in runs {
        let o = replay_prefetching(trace, c, 2, p);
        out += &format!(
            "| {name} | {} | {} | {} | {} | {} | {} | {:.2} | {:.2} | {} | {:.2} |\n",
            o.coarser,
            ratio(o.coarser, off.coarser),
            o.coarser_warm,
            ratio(o.coarser_warm, off.coarser_warm),
            o.warmup_frames,
            o.missing,
            o.bytes() as f64 / 1e6,
            o.prefetch_bytes as f64 / 1e6,
            o.prefetch_hits,
            o.prefetch_wasted_bytes as f64 / 1e6
        );
    }
    out
}
