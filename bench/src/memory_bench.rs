//! `tilebench memory`: the memory manager on real flights. Traces recorded by `vkterrain
//! --trace` are replayed through every policy (bytes by transfer scheme, misses and bytes
//! against Belady's rule); the cold start and the upload budget are read from real flights'
//! logs; the manager's CPU time is timed on a synthetic frame of 1000 visible tiles.

use std::path::Path;

use anyhow::{Context, Result};
use bench::residency::{
    against_belady, bytes_by_scheme, default_policy, policy_runs, policy_table, tile_set_figures,
    time_manager,
};
use dem::ReadOptions;
use memory::sim::tile_set_bytes;
use memory::trace::Trace;
use memory::TileCost;
use tiles::BuildParams;

use crate::{build, data, flight, sibling};

const FRAMES: u32 = 120;

pub fn memory() -> Result<()> {
    let vkterrain = sibling("vkterrain", "renderer")?;
    let dir = std::env::temp_dir().join(format!("tilebench-memory-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let params = BuildParams::default();
    let sets = [
        (
            "Puget 1K",
            "puget.vkt",
            dem::read(
                &[data("puget/ps_height_1k.png")?],
                &ReadOptions {
                    spacing: Some(160.0),
                    vertical_scale: Some(0.1),
                    ..Default::default()
                },
            )?,
        ),
        (
            "SRTM1 N48W125",
            "n48.vkt",
            dem::read(&[data("srtm/N48W125.hgt")?], &ReadOptions::default())?,
        ),
        (
            "Puget 4K (8-bit)",
            "p4k.vkt",
            dem::read(
                &[data("puget/ps_height_4k_8bit.jpg")?],
                &ReadOptions {
                    spacing: Some(40.0),
                    vertical_scale: Some(25.7),
                    ..Default::default()
                },
            )?,
        ),
    ];
    let mut traces: Vec<(String, Trace)> = Vec::new();
    for (name, file, grid) in &sets {
        let set = dir.join(file);
        build(grid, &params, &set)?;
        for path in ["orbit", "flyover"] {
            let trace = dir.join(format!("{file}.{path}.trace"));
            let t = trace.to_str().context("utf-8 path")?;
            flight(
                &vkterrain,
                &set,
                path,
                FRAMES,
                &["--tau", "1", "--trace", t],
            )?;
            let text = std::fs::read_to_string(&trace)?;
            let parsed = Trace::parse(&text).map_err(anyhow::Error::msg)?;
            traces.push((format!("{name} {path}"), parsed));
        }
    }

    println!(
        "### Bytes over real flights ({FRAMES} frames, 1024 x 768, tau 1), room for everything\n"
    );
    println!("Traces from `vkterrain --trace`, replayed with a pool and an upload budget large enough that nothing is evicted or deferred: what each transfer scheme sends.\n");
    println!("| flight | tile set MB | finest: refine / scratch MB | whole tiles MB | per level from scratch MB | progressive MB | progressive / whole | progressive / per level | indices in progressive | of which coarser arrays | progressive, slack 1 / whole |");
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for (name, t) in &traces {
        let (refine, scratch, whole_set) = tile_set_figures(t);
        let [w, p, g] = bytes_by_scheme(t);
        let slack = memory::sim::replay(
            t,
            memory::Config {
                pool_bytes: u64::MAX / 4,
                upload_budget: u64::MAX / 4,
                downgrade_slack: 1,
                ..memory::Config::default()
            },
            2,
        );
        let mb = |b: u64| b as f64 / 1e6;
        println!(
            "| {name} | {:.1} | {:.1} / {:.1} | {:.1} | {:.1} | {:.1} | {:.2} | {:.2} | {:.0}% | {:.0}% | {:.2} |",
            mb(whole_set),
            mb(refine),
            mb(scratch),
            mb(w.bytes()),
            mb(p.bytes()),
            mb(g.bytes()),
            g.bytes() as f64 / w.bytes().max(1) as f64,
            g.bytes() as f64 / p.bytes().max(1) as f64,
            100.0 * g.bytes_indices as f64 / g.bytes().max(1) as f64,
            100.0 * g.bytes_coarser as f64 / g.bytes().max(1) as f64,
            slack.bytes() as f64 / w.bytes().max(1) as f64,
        );
    }

    println!(
        "\n### Against Belady's rule (pools of 5% to 50% of the tile set, default upload budget)\n"
    );
    println!("Every policy replayed on each trace; Belady's rule evicts the tile whose next request is farthest away (knowing the future). At 25% and 50% most flights never need to evict: all policies tie. Smaller pools show where they part.\n");
    println!("| flight | pool | pool MB | evictions (default) | default misses / Belady | default bytes / Belady | LRU bytes / Belady | tightest fit bytes / Belady | whole tiles bytes / Belady |");
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    let mut tables = Vec::new();
    for (name, t) in &traces {
        for share in [0.05, 0.1, 0.25, 0.5] {
            let pool = (tile_set_bytes(t) as f64 * share) as u64;
            let runs = policy_runs(t, pool, memory::DEFAULT_UPLOAD_BUDGET);
            let default = default_policy();
            let evictions = runs
                .iter()
                .find(|(n, _)| *n == default)
                .map_or(0, |(_, o)| o.evictions);
            let (misses, bytes) = against_belady(&runs, &default);
            let b = |n: &str| against_belady(&runs, n).1;
            println!(
                "| {name} | {:.0}% | {:.1} | {evictions} | {misses:.2}x | {bytes:.2}x | {:.2}x | {:.2}x | {:.2}x |",
                share * 100.0,
                pool as f64 / 1e6,
                b("pure LRU"),
                b("pure tightest fit"),
                b("whole tiles (old scheme), LRU"),
            );
            if share == 0.1 || share == 0.25 {
                tables.push((
                    format!("{name}, pool {:.0}%", share * 100.0),
                    policy_table(&runs),
                ));
            }
        }
    }
    // A flight that comes back: the synthetic one the manager is timed on (a window of 1000
    // of 1280 tiles sliding by 8 a frame, so each tile returns after 160 frames).
    if let Some((_, t)) = traces.iter().find(|(n, _)| n.starts_with("Puget 4K")) {
        let synthetic = memory::sim::synthetic(&t.costs, 1280, 1000, 400);
        for share in [0.1, 0.25] {
            let pool = (tile_set_bytes(&synthetic) as f64 * share) as u64;
            let runs = policy_runs(&synthetic, pool, memory::DEFAULT_UPLOAD_BUDGET);
            let default = default_policy();
            let evictions = runs
                .iter()
                .find(|(n, _)| *n == default)
                .map_or(0, |(_, o)| o.evictions);
            let (misses, bytes) = against_belady(&runs, &default);
            let b = |n: &str| against_belady(&runs, n).1;
            println!(
                "| synthetic, tiles return (`memory::sim::synthetic`) | {:.0}% | {:.1} | {evictions} | {misses:.2}x | {bytes:.2}x | {:.2}x | {:.2}x | {:.2}x |",
                share * 100.0,
                pool as f64 / 1e6,
                b("pure LRU"),
                b("pure tightest fit"),
                b("whole tiles (old scheme), LRU"),
            );
            tables.push((
                format!(
                    "synthetic (1280 tiles, 1000 visible), pool {:.0}%",
                    share * 100.0
                ),
                policy_table(&runs),
            ));
        }
    }
    println!();
    for (title, table) in tables {
        println!("**{title}**\n\n{table}");
    }

    cold_start(&vkterrain, &dir.join("puget.vkt"), &dir)?;
    frames_in_flight(&vkterrain, &dir.join("puget.vkt"))?;
    if let Some((_, t)) = traces.iter().find(|(n, _)| n.starts_with("Puget 4K")) {
        manager_time(&t.costs)?;
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

/// The cold demo flight: first frames against the median, and the upload bytes per frame.
fn cold_start(vkterrain: &Path, set: &Path, dir: &Path) -> Result<()> {
    println!(
        "### Cold start: the demo flight (Puget 1K flyover, {FRAMES} frames, 1024 x 768, tau 1)\n"
    );
    println!("| upload budget | frame 0 / median | frames 0-2 worst / median | median ms | p99 upload bytes | max upload bytes | frames with deferred tiles |");
    println!("|---|---:|---:|---:|---:|---:|---:|");
    let configs = [
        ("4 MiB (default)", vec![]),
        ("1 MiB", vec!["--upload-budget-mb", "1"]),
        ("unlimited", vec!["--upload-budget-mb", "100000"]),
        (
            "4 MiB, driver warmed first (`--warmup-driver`)",
            vec!["--warmup-driver"],
        ),
    ];
    // Two rounds, alternating: each row is one run (ratios inside the run).
    for round in 1..=2 {
        for (label, extra) in &configs {
            let log = dir.join("cold.csv");
            let mut args = vec!["--tau", "1", "--log", log.to_str().context("utf-8")?];
            args.extend(extra);
            let s = flight(vkterrain, set, "flyover", FRAMES, &args)?;
            let frames = frametimes::log::read(&log)?;
            let col = |name: &str| -> Result<Vec<f64>> {
                frames
                    .column(name)
                    .map(<[f64]>::to_vec)
                    .with_context(|| format!("{}: no column {name}", log.display()))
            };
            let ms = col("frame_ms")?;
            let median = s["frame_ms_median"].as_f64().unwrap_or(f64::NAN);
            let first3 = ms.iter().take(3).copied().fold(0.0, f64::max);
            let up = col("upload_bytes")?;
            let deferred = col("uploads_deferred_bytes")?
                .iter()
                .filter(|&&b| b > 0.0)
                .count();
            println!(
                "| {label}, run {round} | {:.2}x | {:.2}x | {median:.1} | {:.0} | {:.0} | {deferred} |",
                ms[0] / median,
                first3 / median,
                s["upload_bytes_p99"].as_f64().unwrap_or(f64::NAN),
                up.iter().copied().fold(0.0, f64::max),
            );
        }
    }
    println!();
    Ok(())
}

/// Median frame with one and two frames in flight, alternating runs.
fn frames_in_flight(vkterrain: &Path, set: &Path) -> Result<()> {
    println!("### Frames in flight (Puget 1K, {FRAMES} frames, 1024 x 768, tau 1; two rounds, alternating)\n");
    println!("| path | 1 in flight: median ms | 2 in flight: median ms | 1 / 2 |");
    println!("|---|---:|---:|---:|");
    for path in ["flyover", "orbit"] {
        let mut med = [Vec::new(), Vec::new()];
        for _round in 0..2 {
            for (k, n) in ["1", "2"].into_iter().enumerate() {
                let s = flight(vkterrain, set, path, FRAMES, &["--frames-in-flight", n])?;
                med[k].push(s["frame_ms_median"].as_f64().unwrap_or(f64::NAN));
            }
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let (one, two) = (mean(&med[0]), mean(&med[1]));
        println!("| {path} | {one:.1} | {two:.1} | {:.2} |", one / two);
    }
    println!();
    Ok(())
}

/// The manager's CPU time per frame with 1000 visible tiles: a 1280-tile set (the 4K set's
/// tiles, five times over), a window of 1000 tiles sliding by 8 a frame, wanted levels in a
/// random walk, a pool of a quarter of the set.
fn manager_time(costs: &[TileCost]) -> Result<()> {
    let (frames, times, evictions) = time_manager(costs);
    println!(
        "### Manager CPU time per frame (1000 visible tiles, 1280 tiles, pool 25%, {frames} frames)\n"
    );
    println!("| median ms | p95 ms | max ms | evictions |");
    println!("|---:|---:|---:|---:|");
    let p = |q: f64| frametimes::stats::percentile(&times, q);
    println!(
        "| {:.3} | {:.3} | {:.3} | {evictions} |\n",
        p(50.0),
        p(95.0),
        times.last().copied().unwrap_or(f64::NAN)
    );
    Ok(())
}
