//! `tilebench`: the preprocessing benchmarks reported in `bench/README.md`.
//!
//! ```text
//! cargo build --release -p tiletool -p bench
//! target/release/tilebench throughput   # tiletool build end to end, samples/min, peak memory
//! target/release/tilebench economy      # vertices vs measured error, against Martini/Delatin
//! target/release/tilebench acmr         # vertex-cache miss ratio of the fan order vs meshopt
//! target/release/tilebench frames       # vkterrain flights: LOD at tau 1, 2, 4 vs brute force
//! target/release/tilebench memory       # residency: traces replayed against Belady, cold
//!                                       # start, upload budget, manager CPU, frames in flight
//! target/release/tilebench cut SET.vkt [FRAMES]  # the tile pyramid's cut vs the base grid
//! target/release/tilebench compact SET.vkt...     # issue 28's compact levels, weighed
//! target/release/tilebench all
//! ```
//!
//! Each prints Markdown tables. Ratios are measured side by side in one run.

mod compact_bench;
mod cut_bench;
mod limit_bench;
mod martini;
mod memory_bench;

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use dem::{Crop, ReadOptions};
use tiles::{build_tileset, BuildParams, Grid, TileSet, TileSetMeta};

/// A file of the shared data, or an error saying it is missing.
fn data(rel: &str) -> Result<PathBuf> {
    testdata::try_data(rel).map_err(anyhow::Error::msg)
}

fn main() -> std::process::ExitCode {
    tiles::hold_freed_memory();
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("tilebench: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

/// `tilebench limit` flies the static-mesh limit and Table 1 beside the flight table.
const ALL_EXTRAS: limit_bench::Extras = limit_bench::Extras {
    flights: true,
    limit: true,
    table1: true,
};

fn run() -> Result<()> {
    let what = std::env::args().nth(1).unwrap_or_else(|| "all".into());
    match what.as_str() {
        "throughput" => throughput(),
        "economy" => economy(),
        "acmr" => acmr(),
        "frames" => frames(),
        "memory" => memory_bench::memory(),
        "cut" => cut_bench::cut(),
        "compact" => compact_bench::compact(),
        "limit" => limit_bench::limit_table(ALL_EXTRAS),
        "flights" => limit_bench::limit_table(limit_bench::Extras {
            flights: true,
            limit: false,
            table1: false,
        }),
        "table1" => limit_bench::limit_table(limit_bench::Extras {
            flights: false,
            limit: false,
            table1: true,
        }),
        "all" => {
            throughput()?;
            economy()?;
            acmr()?;
            frames()?;
            limit_bench::limit_table(ALL_EXTRAS)?;
            memory_bench::memory()
        }
        other => {
            bail!(
                "unknown benchmark {other:?}: throughput, economy, acmr, frames, memory, limit, flights, table1, cut or all"
            )
        }
    }
}

/// A binary of the workspace next to this one (built by `cargo build --release -p package`).
fn sibling(name: &str, package: &str) -> Result<PathBuf> {
    let path = std::env::current_exe()?.with_file_name(name);
    if !path.exists() {
        bail!(
            "{} not found: cargo build --release -p {package} first",
            path.display()
        );
    }
    Ok(path)
}

/// `tiletool build` as a user runs it, decode to renamed file, three runs per dataset.
fn throughput() -> Result<()> {
    let tiletool = sibling("tiletool", "tiletool")?;
    let out_dir = std::env::temp_dir().join(format!("tilebench-{}", std::process::id()));
    std::fs::create_dir_all(&out_dir)?;
    println!(
        "### Build throughput (tiletool build, 9 levels, base error 1 m, {} threads)\n",
        std::thread::available_parallelism()?.get()
    );
    println!("| dataset | samples | runs (s) | median (s) | M samples/min | peak memory (MB) | file (MB) |");
    println!("|---|---:|---|---:|---:|---:|---:|");
    let puget = data("puget/ps_height_1k.png")?;
    let n48 = data("srtm/N48W125.hgt")?;
    let cases: [(&str, Vec<String>, f64); 2] = [
        (
            "Puget 1K (1025²)",
            vec![
                puget.display().to_string(),
                "--spacing".into(),
                "160".into(),
                "--vertical-scale".into(),
                "0.1".into(),
            ],
            1025.0 * 1025.0,
        ),
        (
            "SRTM1 N48W125 (3601²)",
            vec![n48.display().to_string()],
            3601.0 * 3601.0,
        ),
    ];
    for (name, args, samples) in cases {
        let out = out_dir.join("t.vkt");
        let mut times = Vec::new();
        let mut peak = 0.0f64;
        for _ in 0..3 {
            let start = Instant::now();
            let o = Command::new(&tiletool)
                .arg("build")
                .args(&args)
                .arg("-o")
                .arg(&out)
                .output()?;
            times.push(start.elapsed().as_secs_f64());
            if !o.status.success() {
                bail!("tiletool failed: {}", String::from_utf8_lossy(&o.stderr));
            }
            let text = String::from_utf8_lossy(&o.stdout);
            if let Some(mb) = text
                .split("peak memory ")
                .nth(1)
                .and_then(|t| t.split(' ').next())
                .and_then(|t| t.parse::<f64>().ok())
            {
                peak = peak.max(mb);
            }
        }
        let file_mb = std::fs::metadata(&out)?.len() as f64 / 1e6;
        let mut sorted = times.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted[1];
        let runs: Vec<String> = times.iter().map(|t| format!("{t:.2}")).collect();
        println!(
            "| {name} | {samples:.0} | {} | {median:.2} | {:.0} | {peak:.0} | {file_mb:.1} |",
            runs.join(", "),
            samples / median * 60.0 / 1e6
        );
    }
    let _ = std::fs::remove_dir_all(&out_dir);
    println!();
    Ok(())
}

struct Dataset {
    name: &'static str,
    grid: dem::HeightGrid,
}

/// The two grids of the mesh-economy comparison, in metres.
fn economy_grids() -> Result<Vec<Dataset>> {
    let puget = dem::read(
        &[data("puget/ps_height_1k.png")?],
        &ReadOptions {
            spacing: Some(160.0),
            vertical_scale: Some(0.1),
            ..Default::default()
        },
    )?;
    let scotland = dem::read(
        &[data("srtm/N55W003.hgt")?],
        &ReadOptions {
            crop: Some(Crop {
                x: 0,
                y: 0,
                width: 1025,
                height: 1025,
            }),
            ..Default::default()
        },
    )?;
    Ok(vec![
        Dataset {
            name: "Puget 1025²",
            grid: puget,
        },
        Dataset {
            name: "SRTM3 N55W003, first 1025²",
            grid: scotland,
        },
    ])
}

/// Our tile set of a grid, built into a temporary file.
fn build(grid: &dem::HeightGrid, params: &BuildParams, out: &Path) -> Result<TileSet> {
    let view = Grid {
        width: grid.width,
        height: grid.height,
        first_row: 0,
        heights: &grid.heights,
        spacing_x: grid.spacing_x,
        spacing_y: grid.spacing_y,
    };
    build_tileset(&view, params, &TileSetMeta::default(), out, &|| {})?;
    Ok(TileSet::open(out)?)
}

/// Per level: (measured max error, stored vertices, unique vertices, triangles).
fn level_counts(set: &TileSet) -> Result<Vec<(f64, u64, u64, u64)>> {
    let h = *set.header();
    let mut out = Vec::new();
    for level in 0..h.levels {
        let (mut err, mut stored, mut tris) = (0.0f64, 0u64, 0u64);
        let mut unique: HashSet<(u32, u32)> = HashSet::new();
        for ty in 0..h.tiles_y {
            for tx in 0..h.tiles_x {
                let tile = set.tile(tx, ty)?;
                let l = tile.level(level).context("level")?;
                err = err.max(f64::from(l.entry.max_error));
                stored += u64::from(l.entry.vertex_count());
                tris += u64::from(l.entry.triangle_count);
                for &(x, y, _) in &tile.vertices()[..l.entry.vertex_count() as usize] {
                    unique.insert((tx * 256 + x, ty * 256 + y));
                }
            }
        }
        out.push((err, stored, unique.len() as u64, tris));
    }
    Ok(out)
}

/// Delatin 0.2.0 from the data README's table: (grid, measured max error m, vertices).
const DELATIN: [(&str, f64, u64); 5] = [
    ("Puget 1025²", 4.0, 638_256),
    ("Puget 1025²", 16.0, 293_097),
    ("SRTM3 N55W003, first 1025²", 2.0, 316_099),
    ("SRTM3 N55W003, first 1025²", 8.0, 75_722),
    ("SRTM3 N55W003, first 1025²", 16.0, 30_069),
];

fn economy() -> Result<()> {
    let params = BuildParams {
        levels: 9,
        base_error: 1.0,
        ..BuildParams::default()
    };
    let dir = std::env::temp_dir().join(format!("tilebench-eco-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    println!("### Mesh economy: vertices at equal *measured* max error\n");
    println!("Ours: 9 levels, base error 1 m; vertices summed over tiles (\"stored\", what the GPU holds,");
    println!("tile borders duplicated) and as distinct grid points (\"unique\", the mesh itself). Martini:");
    println!("the reference RTIN in `bench/src/martini.rs` swept over requested errors 2^(k/8) m; for each");
    println!(
        "of our levels, the sparsest swept Martini mesh whose true max error is at most ours.\n"
    );
    let mut ratios_unique = Vec::new();
    let mut ratios_stored = Vec::new();
    let mut delatin_rows = Vec::new();
    for d in economy_grids()? {
        let set = build(&d.grid, &params, &dir.join("e.vkt"))?;
        let ours = level_counts(&set)?;
        let rtin = martini::Rtin::new(d.grid.heights.clone(), d.grid.width);
        // (requested, true max error, vertices, triangles)
        let mut sweep = Vec::new();
        for k in -16..=56 {
            let requested = 2f64.powf(f64::from(k) / 8.0) as f32;
            let (tris, verts) = rtin.mesh(requested);
            let err = martini::true_max_error(&tris, rtin.heights(), d.grid.width);
            sweep.push((requested, err, verts as u64, tris.len() as u64));
        }
        println!("**{}** (Martini check against the data README: requested 4 m → {} vertices, true error {:.2} m)\n",
            d.name,
            rtin.mesh(4.0).1,
            martini::true_max_error(&rtin.mesh(4.0).0, rtin.heights(), d.grid.width));
        println!("| e_i (m) | our max err (m) | ours stored | ours unique | our triangles | Martini vertices (its true err) | unique / Martini | stored / Martini |");
        println!("|---:|---:|---:|---:|---:|---:|---:|---:|");
        for (level, &(err, stored, unique, tris)) in ours.iter().enumerate() {
            let e = params.level_error(level as u32);
            if e > 32.0 {
                continue;
            }
            let best = sweep
                .iter()
                .filter(|s| s.1 <= err + 1e-9)
                .min_by_key(|s| s.2);
            let Some(&(_, merr, mverts, _)) = best else {
                println!("| {e} | {err:.3} | {stored} | {unique} | {tris} | (none as fine) | | |");
                continue;
            };
            let (ru, rs) = (unique as f64 / mverts as f64, stored as f64 / mverts as f64);
            ratios_unique.push(ru);
            ratios_stored.push(rs);
            println!("| {e} | {err:.3} | {stored} | {unique} | {tris} | {mverts} ({merr:.2}) | {ru:.3} | {rs:.3} |");
            for &(g, derr, dverts) in &DELATIN {
                if g == d.name && (derr - e).abs() < 1e-9 {
                    delatin_rows.push((g, e, err, unique, stored, dverts));
                }
            }
        }
        println!();
    }
    let geo = |r: &[f64]| (r.iter().map(|x| x.ln()).sum::<f64>() / r.len() as f64).exp();
    println!(
        "Geometric mean over e = 1..32 m on both grids: **unique / Martini = {:.3}**, stored / Martini = {:.3}.\n",
        geo(&ratios_unique),
        geo(&ratios_stored)
    );
    println!("Against Delatin 0.2.0 (greedy Delaunay; numbers from the data README's table, its error is a true bound):\n");
    println!("| grid | e (m) | our max err (m) | ours unique | ours stored | Delatin | unique / Delatin |");
    println!("|---|---:|---:|---:|---:|---:|---:|");
    for (g, e, err, unique, stored, dverts) in delatin_rows {
        println!(
            "| {g} | {e} | {err:.3} | {unique} | {stored} | {dverts} | {:.2} |",
            unique as f64 / dverts as f64
        );
    }
    println!();
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

fn acmr() -> Result<()> {
    let params = BuildParams {
        levels: 9,
        base_error: 1.0,
        ..BuildParams::default()
    };
    let dir = std::env::temp_dir().join(format!("tilebench-acmr-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    println!("### Vertex-cache quality of the fan order\n");
    println!(
        "ACMR (vertices transformed per triangle) from meshopt's analyzer, FIFO cache of 16 and 32"
    );
    println!(
        "entries, fans expanded to triangles in their stored order, against the same triangles"
    );
    println!(
        "reordered by meshopt's vertex-cache optimiser; summed over all tiles of the level. \"built\":"
    );
    println!(
        "the same fans with their rings as vkterrain builds them on the GPU (`tiles::rings`).\n"
    );
    println!("| grid | level | triangles | ours @16 | meshopt @16 | ratio @16 | ours @32 | meshopt @32 | ratio @32 | built @16 | ratio @16 | built @32 | ratio @32 |");
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    let mut worst: f64 = 0.0;
    let mut worst_built: f64 = 0.0;
    for d in economy_grids()? {
        let set = build(&d.grid, &params, &dir.join("a.vkt"))?;
        let h = *set.header();
        for level in 0..h.levels {
            let mut tris = 0u64;
            let mut ours = [0u64; 2];
            let mut opt = [0u64; 2];
            let mut built = [0u64; 2];
            for ty in 0..h.tiles_y {
                for tx in 0..h.tiles_x {
                    let tile = set.tile(tx, ty)?;
                    let l = tile.level(level).context("level")?;
                    let triangles = |fans: &[Vec<u32>]| -> Vec<u32> {
                        fans.iter()
                            .flat_map(|f| {
                                f[1..]
                                    .windows(2)
                                    .flat_map(|w| [f[0], w[0], w[1]])
                                    .collect::<Vec<_>>()
                            })
                            .collect()
                    };
                    let list = triangles(&l.indices.fans());
                    let mut positions = Vec::new();
                    for j in 0..=level {
                        positions.extend_from_slice(tile.level(j).context("level")?.positions);
                    }
                    let gpu = tiles::rings::previous_cell_rings(l.indices.iter(), |v| {
                        let (x, y, _) = tiles::pack::unpack(positions[v as usize]);
                        (x, y)
                    });
                    let gpu_fans: Vec<Vec<u32>> = gpu
                        .split(|&i| i == tiles::format::RESTART_U32)
                        .map(<[u32]>::to_vec)
                        .collect();
                    let gpu_list = triangles(&gpu_fans);
                    let n = l.entry.vertex_count() as usize;
                    let optimised = meshopt::optimize_vertex_cache(&list, n);
                    tris += list.len() as u64 / 3;
                    for (i, cache) in [16u32, 32].into_iter().enumerate() {
                        ours[i] += u64::from(
                            meshopt::analyze_vertex_cache(&list, n, cache, 0, 0)
                                .vertices_transformed,
                        );
                        opt[i] += u64::from(
                            meshopt::analyze_vertex_cache(&optimised, n, cache, 0, 0)
                                .vertices_transformed,
                        );
                        built[i] += u64::from(
                            meshopt::analyze_vertex_cache(&gpu_list, n, cache, 0, 0)
                                .vertices_transformed,
                        );
                    }
                }
            }
            let acmr = |v: u64| v as f64 / tris as f64;
            let r = [acmr(ours[0]) / acmr(opt[0]), acmr(ours[1]) / acmr(opt[1])];
            let b = [acmr(built[0]) / acmr(opt[0]), acmr(built[1]) / acmr(opt[1])];
            worst = worst.max(r[0]);
            worst_built = worst_built.max(b[0]);
            println!(
                "| {} | {level} | {tris} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} |",
                d.name,
                acmr(ours[0]),
                acmr(opt[0]),
                r[0],
                acmr(ours[1]),
                acmr(opt[1]),
                r[1],
                acmr(built[0]),
                b[0],
                acmr(built[1]),
                b[1]
            );
        }
    }
    println!("\nWorst ratio at 16 entries: {worst:.3} as stored, {worst_built:.3} as built on the GPU.\n");
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

/// A vkterrain flight's JSON summary, at 1024 x 768.
fn flight(
    vkterrain: &Path,
    set: &Path,
    path: &str,
    frames: u32,
    extra: &[&str],
) -> Result<serde_json::Value> {
    flight_at(vkterrain, set, path, frames, "1024x768", extra)
}

/// A vkterrain flight's JSON summary at `size` (WxH).
fn flight_at(
    vkterrain: &Path,
    set: &Path,
    path: &str,
    frames: u32,
    size: &str,
    extra: &[&str],
) -> Result<serde_json::Value> {
    let frames = frames.to_string();
    let mut args = vec![
        set.to_str().context("utf-8 path")?,
        "--headless",
        "--path",
        path,
        "--frames",
        &frames,
        "--size",
        size,
    ];
    args.extend(extra);
    let o = Command::new(vkterrain).args(&args).output()?;
    if !o.status.success() {
        bail!(
            "vkterrain {args:?} failed: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    Ok(serde_json::from_slice(&o.stdout)?)
}

/// LOD against brute force on the same path in the same run, at 1024 x 768.
fn frames() -> Result<()> {
    let vkterrain = sibling("vkterrain", "renderer")?;
    let dir = std::env::temp_dir().join(format!("tilebench-frames-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let params = BuildParams::default();
    let puget = dem::read(
        &[data("puget/ps_height_1k.png")?],
        &ReadOptions {
            spacing: Some(160.0),
            vertical_scale: Some(0.1),
            ..Default::default()
        },
    )?;
    let n48 = dem::read(&[data("srtm/N48W125.hgt")?], &ReadOptions::default())?;
    println!("### vkterrain flights, 1024 x 768, 60 frames per path, all in the same run\n");
    println!("Frame time is the interval between frames' completions on the GPU (timestamps), two frames in flight; on lavapipe the GPU is the CPU.");
    println!("CPU share: cull + LOD + residency + stitch + record over frame time (writing uploads apart, in the next column).\n");
    println!("| dataset | path | mode | median ms | p95 ms | triangles/frame | Mtri/s | CPU ms (median) | CPU share | upload share | MB uploaded | brute / this (median) |");
    println!("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    let mut limits = Vec::new();
    let mut errors = Vec::new();
    let puget_source = data("puget/ps_height_1k.png")?;
    let n48_source = data("srtm/N48W125.hgt")?;
    let sources = [
        (
            puget_source.to_str().context("utf-8 path")?,
            vec!["--source-spacing", "160", "--source-vertical-scale", "0.1"],
        ),
        (n48_source.to_str().context("utf-8 path")?, vec![]),
    ];
    for ((name, grid), (source, source_flags)) in [("Puget 1K", &puget), ("SRTM1 N48W125", &n48)]
        .into_iter()
        .zip(&sources)
    {
        let set = dir.join("f.vkt");
        build(grid, &params, &set)?;
        for path in ["flyover", "orbit"] {
            let brute = flight(&vkterrain, &set, path, 60, &["--brute-force"])?;
            let brute_ms = brute["frame_ms_median"].as_f64().unwrap_or(f64::NAN);
            let mut rows = vec![("brute force".to_string(), brute)];
            for tau in ["1", "2", "4"] {
                rows.push((
                    format!("tau {tau}"),
                    flight(&vkterrain, &set, path, 60, &["--tau", tau])?,
                ));
            }
            // The same tau-1 flight with levels from the old sampled Jacobian (not a bound).
            rows.push((
                "tau 1, sampled bound (old rule)".into(),
                flight(
                    &vkterrain,
                    &set,
                    path,
                    60,
                    &["--tau", "1", "--lod-bound", "sampled"],
                )?,
            ));
            // The same tau-1 flight sending whole tiles (the scheme before the pool).
            rows.push((
                "tau 1, whole-tile uploads".into(),
                flight(
                    &vkterrain,
                    &set,
                    path,
                    60,
                    &["--tau", "1", "--upload-scheme", "whole-tile"],
                )?,
            ));
            // The same tau-1 flight with its tiles already resident, and its draw-only limit:
            // the same frames pre-recorded and only replayed.
            let warm = flight(&vkterrain, &set, path, 60, &["--tau", "1", "--warmup"])?;
            let limit = flight(&vkterrain, &set, path, 60, &["--tau", "1", "--draw-only"])?;
            let over_limit = warm["frame_ms_median"].as_f64().unwrap_or(f64::NAN)
                / limit["frame_ms_median"].as_f64().unwrap_or(f64::NAN);
            rows.push(("tau 1, warm (flown once first)".into(), warm));
            rows.push(("tau 1, draw-only limit".into(), limit));
            // The error each bound delivers, measured against the source on every frame.
            let mut measured = Vec::new();
            for bound in ["guaranteed", "sampled"] {
                let mut args = vec![
                    "--tau",
                    "1",
                    "--lod-bound",
                    bound,
                    "--measure-error",
                    source,
                ];
                args.extend(source_flags.iter().copied());
                let m = flight(&vkterrain, &set, path, 60, &args)?;
                measured.push((
                    m["max_error_px"].as_f64().unwrap_or(f64::NAN),
                    m["triangles_per_frame_mean"].as_f64().unwrap_or(f64::NAN),
                ));
            }
            errors.push(format!(
                "| {name} | {path} | {:.3} | {:.3} | {:.0} | {:.0} | {:.2}x |",
                measured[0].0,
                measured[1].0,
                measured[0].1,
                measured[1].1,
                measured[0].1 / measured[1].1
            ));
            limits.push(format!(
                "{name}, {path}: tau-1 frame (warm) / draw-only limit = {over_limit:.2}x"
            ));
            for (mode, s) in rows {
                let f = |k: &str| s[k].as_f64().unwrap_or(f64::NAN);
                println!(
                "| {name} | {path} | {mode} | {:.1} | {:.1} | {:.0} | {:.1} | {:.2} | {:.1}% | {:.1}% | {:.1} | {:.1}x |",
                f("frame_ms_median"),
                f("frame_ms_p95"),
                f("triangles_per_frame_mean"),
                f("mtri_per_s"),
                f("cpu_ms_median"),
                100.0 * f("cpu_share"),
                100.0 * f("upload_share"),
                f("upload_mb"),
                brute_ms / f("frame_ms_median")
            );
            }
        }
    }
    println!();
    for l in limits {
        println!("- {l}");
    }
    println!("\n### The error delivered: guaranteed bound against the old sampled rule (tau 1, 60 frames, measured against the source DEM on every frame)\n");
    println!("| dataset | path | max_error_px, guaranteed | max_error_px, sampled | triangles/frame, guaranteed | triangles/frame, sampled | guaranteed / sampled |");
    println!("|---|---|---:|---:|---:|---:|---:|");
    for e in errors {
        println!("{e}");
    }
    println!();
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
