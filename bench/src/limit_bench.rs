//! `tilebench limit`: the geomorphing flight table in one run. Every flight (Puget 1K flyover
//! and orbit, SRTM1 N48W125 flyover and orbit, the 4K Puget flyover; 60 frames at 1024 x 768)
//! with brute force, discrete levels at tau 1 and 3, and geomorphing at tau 1, 2, 3 and 5; each
//! row beside the static-mesh limit at its own triangle count (`vkterrain --static-grid`: the
//! same number of terrain-like fans drawn with the simplest shaders on the same device in the
//! same run). Then the paper's Table 1 on the Puget and N48W125 flyovers: error delivered and
//! pops against the source, 120 frames over the whole path (0.4 s of path a frame) and the
//! path's first 12 s at 30 frames a second.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};

use crate::{data, flight, flight_at, sibling};

/// (name, tiletool inputs and flags, error-meter flags).
struct Set {
    name: &'static str,
    build: Vec<String>,
    source: Vec<String>,
    paths: &'static [&'static str],
}

fn sets() -> Result<Vec<Set>> {
    let s = |p: PathBuf| p.to_string_lossy().into_owned();
    let puget = s(data("puget/ps_height_1k.png")?);
    let n48 = s(data("srtm/N48W125.hgt")?);
    let p4k = s(data("puget/ps_height_4k_8bit.jpg")?);
    let flags = |f: &[&str]| f.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    Ok(vec![
        Set {
            name: "Puget 1K",
            build: [
                vec![puget.clone()],
                flags(&["--spacing", "160", "--vertical-scale", "0.1"]),
            ]
            .concat(),
            source: [
                vec!["--measure-error".into(), puget],
                flags(&["--source-spacing", "160", "--source-vertical-scale", "0.1"]),
            ]
            .concat(),
            paths: &["flyover", "orbit"],
        },
        Set {
            name: "SRTM1 N48W125",
            build: vec![n48.clone()],
            source: vec!["--measure-error".into(), n48],
            paths: &["flyover", "orbit"],
        },
        Set {
            name: "Puget 4K",
            build: [
                vec![p4k],
                flags(&["--spacing", "40", "--vertical-scale", "25.7"]),
            ]
            .concat(),
            source: Vec::new(),
            paths: &["flyover"],
        },
    ])
}

/// The static-mesh limit at `triangles`: its median frame ms.
fn limit(vkterrain: &Path, triangles: f64) -> Result<f64> {
    let n = (triangles.round() as u64).max(1).to_string();
    let o = Command::new(vkterrain)
        .args([
            "-",
            "--static-grid",
            &n,
            "--frames",
            "30",
            "--size",
            "1024x768",
        ])
        .output()?;
    if !o.status.success() {
        bail!("static grid {n}: {}", String::from_utf8_lossy(&o.stderr));
    }
    let v: serde_json::Value = serde_json::from_slice(&o.stdout)?;
    Ok(v["frame_ms_median"].as_f64().unwrap_or(f64::NAN))
}

/// The first `seconds` of the keyframes `vkterrain --record` writes for `path` over `set`.
fn path_start(vkterrain: &Path, set: &Path, path: &str, seconds: f64, out: &Path) -> Result<()> {
    let full = out.with_extension("full.csv");
    let set_s = set.to_str().context("utf-8 path")?;
    let full_s = full.to_str().context("utf-8 path")?;
    let o = Command::new(vkterrain)
        .args([
            set_s,
            "--headless",
            "--path",
            path,
            "--frames",
            "1",
            "--size",
            "64x48",
        ])
        .args(["--record", full_s])
        .output()?;
    if !o.status.success() {
        bail!("recording {path}: {}", String::from_utf8_lossy(&o.stderr));
    }
    let text = std::fs::read_to_string(&full)?;
    let mut lines = text.lines();
    let mut kept = vec![lines.next().context("empty path")?.to_string()];
    for line in lines {
        let t: f64 = line.split(',').next().unwrap_or("").parse()?;
        if t <= seconds + 1e-9 {
            kept.push(line.to_string());
        }
    }
    std::fs::write(out, kept.join("\n") + "\n")?;
    Ok(())
}

/// What [`limit_table`] flies besides the flight table.
#[derive(Clone, Copy, Debug)]
pub struct Extras {
    /// The flight table (`tilebench limit` and `flights`; `tilebench table1` skips it).
    pub flights: bool,
    /// The static-mesh limit at each row's triangle count (`tilebench limit`).
    pub limit: bool,
    /// The paper's Table 1 on the sets with a source (`tilebench limit`).
    pub table1: bool,
}

/// `tilebench limit`: the flight table with the static-mesh limit and Table 1.
/// `tilebench flights`: the flight table alone (a third of the time).
/// `tilebench table1`: Table 1 alone.
pub fn limit_table(extras: Extras) -> Result<()> {
    let vkterrain = sibling("vkterrain", "renderer")?;
    let tiletool = sibling("tiletool", "tiletool")?;
    let dir = std::env::temp_dir().join(format!("tilebench-limit-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    // "geomorph" rows draw part by part on every device (the default only on software
    // rasterisers), so that the table compares the same modes on lavapipe and on a GPU.
    let modes: [(&str, &[&str]); 11] = [
        ("brute force", &["--brute-force"]),
        ("discrete, tau 1", &["--tau", "1", "--no-geomorph"]),
        ("discrete, tau 3", &["--tau", "3", "--no-geomorph"]),
        ("geomorph, tau 1", &["--tau", "1", "--part-by-part"]),
        ("geomorph, tau 2", &["--tau", "2", "--part-by-part"]),
        ("geomorph, tau 3", &["--tau", "3", "--part-by-part"]),
        ("geomorph, tau 5", &["--tau", "5", "--part-by-part"]),
        (
            "geomorph, tau 1, whole tiles",
            &["--tau", "1", "--whole-tiles"],
        ),
        (
            "geomorph, tau 3, whole tiles",
            &["--tau", "3", "--whole-tiles"],
        ),
        (
            "geomorph, tau 1, two levels (no morph pass)",
            &[
                "--tau",
                "1",
                "--part-by-part",
                "--morph-shader",
                "two-levels",
            ],
        ),
        (
            "geomorph, tau 3, two levels (no morph pass)",
            &[
                "--tau",
                "3",
                "--part-by-part",
                "--morph-shader",
                "two-levels",
            ],
        ),
    ];
    if extras.flights {
        println!("### Flights against discrete tau 1, brute force and the static-mesh limit (60 frames, 1024 x 768, one run)\n");
        println!("Frame: median frame time. GPU draw: the median of the GPU's timestamps around the draws. Limit: the static-mesh limit at the row's triangle count, median of 30 frames (`-` when not flown: `tilebench flights`). Ratios are to discrete tau 1 of the same flight.\n");
        println!("| dataset | path | mode | frame ms | GPU draw ms | triangles | frame / discrete tau 1 | triangles / discrete tau 1 | brute / this | limit ms | frame / limit |");
        println!("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    }
    let mut table1 = Vec::new();
    for set in sets()? {
        // Table 1 alone needs only the sets with a source.
        if !extras.flights && (!extras.table1 || set.source.is_empty()) {
            continue;
        }
        let file = dir.join(format!("{}.vkt", set.name.replace(' ', "_")));
        let o = Command::new(&tiletool)
            .arg("build")
            .args(&set.build)
            .args([
                "-o",
                file.to_str().context("utf-8 path")?,
                "--quiet",
                "--force",
            ])
            .output()?;
        if !o.status.success() {
            bail!(
                "building {}: {}",
                set.name,
                String::from_utf8_lossy(&o.stderr)
            );
        }
        for path in set.paths.iter().filter(|_| extras.flights) {
            let mut rows = Vec::new();
            for (mode, extra) in modes {
                let s = flight(&vkterrain, &file, path, 60, extra)?;
                let f = |k: &str| s[k].as_f64().unwrap_or(f64::NAN);
                rows.push((
                    mode,
                    f("frame_ms_median"),
                    f("triangles_per_frame_mean"),
                    f("gpu_draw_ms_median"),
                ));
            }
            let (brute, base) = (rows[0], rows[1]);
            for (mode, ms, tris, draw) in rows {
                let (l, ratio) = if extras.limit {
                    let l = limit(&vkterrain, tris)?;
                    (format!("{l:.1}"), format!("{:.2}x", ms / l))
                } else {
                    ("-".into(), "-".into())
                };
                println!(
                    "| {} | {path} | {mode} | {ms:.1} | {draw:.1} | {tris:.0} | {:.2}x | {:.2}x | {:.1}x | {l} | {ratio} |",
                    set.name,
                    ms / base.1,
                    tris / base.2,
                    brute.1 / ms,
                );
            }
        }
        if extras.table1 && !set.source.is_empty() {
            let source: Vec<&str> = set.source.iter().map(String::as_str).collect();
            let start = dir.join(format!("{}_start.csv", set.name.replace(' ', "_")));
            path_start(&vkterrain, &file, "flyover", 12.0, &start)?;
            let start_s = start.to_str().context("utf-8 path")?;
            for (mode, extra) in [
                ("discrete, tau 1", &["--tau", "1", "--no-geomorph"][..]),
                ("geomorph, tau 1", &["--tau", "1", "--part-by-part"]),
                ("geomorph, tau 2", &["--tau", "2", "--part-by-part"]),
                ("geomorph, tau 3", &["--tau", "3", "--part-by-part"]),
                ("geomorph, tau 5", &["--tau", "5", "--part-by-part"]),
            ] {
                let mut args = vec!["--warmup"];
                args.extend(extra);
                args.extend(&source);
                let whole = flight_at(&vkterrain, &file, "flyover", 120, "480x360", &args)?;
                let fine = flight_at(&vkterrain, &file, start_s, 360, "480x360", &args)?;
                let f = |s: &serde_json::Value, k: &str| s[k].as_f64().unwrap_or(f64::NAN);
                table1.push(format!(
                    "| {} | {mode} | {:.1} | {:.0} | {:.2} | {:.2} | {:.2} | {:.2} |",
                    set.name,
                    f(&whole, "frame_ms_median"),
                    f(&whole, "triangles_per_frame_mean"),
                    f(&whole, "max_error_px"),
                    f(&whole, "pop_px"),
                    f(&fine, "max_error_px"),
                    f(&fine, "pop_px"),
                ));
            }
        }
    }
    if extras.table1 {
        println!("\n### The paper's Table 1: flyovers at 480 x 360, warm, every frame measured against the source\n");
        println!("Whole path: 120 frames over the 48 s flyover (0.4 s of path a frame). First 12 s: 360 frames (30 a second).\n");
        println!("| dataset | mode | frame ms | triangles | max_error_px, whole | pop_px, whole | max_error_px, first 12 s | pop_px, first 12 s |");
        println!("|---|---|---:|---:|---:|---:|---:|---:|");
        for row in table1 {
            println!("{row}");
        }
    }
    println!();
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
