//! `tilebench cut SET.vkt [FRAMES]`: the tile pyramid's cut (`renderer::cut`) against the base
//! grid alone, on the orbit and the flyover over a set built with `tiletool build --pyramid`,
//! at 1024 x 768 and tau 1. Per frame: tiles chosen, tiles looked at, their triangles at the
//! levels chosen, and the CPU time of choosing, for the base grid alone (the cut of a pyramid
//! of one layer: the same rule, every visible base tile) and for the whole pyramid. CPU only:
//! nothing is drawn.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use renderer::cut::Cut;
use renderer::path::CameraPath;
use renderer::terrain::Terrain;

const TAU: f64 = 1.0;

/// One frame's cut: tiles chosen, tiles looked at, triangles, CPU ms, coarsest layer.
type Row = (usize, usize, u64, f64, u32);
const SIZE: (u32, u32) = (1024, 768);

pub fn cut() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(2).collect();
    let Some(set) = args.first().map(PathBuf::from) else {
        bail!("usage: tilebench cut SET.vkt [FRAMES]");
    };
    let frames: u64 = match args.get(1) {
        Some(n) => n.parse().context("FRAMES")?,
        None => 60,
    };
    let opened = Instant::now();
    let pyramid = Terrain::open_pyramid(&set).with_context(|| set.display().to_string())?;
    let open_ms = opened.elapsed().as_secs_f64() * 1e3;
    if pyramid.top() == 0 {
        bail!("{}: no pyramid (build it with --pyramid)", set.display());
    }
    let tiles = pyramid.tiles.len();
    println!(
        "{}: {} base tiles, {} layers above, {tiles} tiles in all; opened (every layer's outlines) in {open_ms:.0} ms\n",
        set.display(),
        pyramid.base().len(),
        pyramid.top()
    );
    let base = Terrain::open(&set)?;
    println!(
        "| flight | selection | tiles chosen | looked at | triangles | CPU ms | coarsest layer |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|");
    for (name, path) in [
        ("orbit", CameraPath::orbit(&pyramid)),
        ("flyover", CameraPath::flyover(&pyramid)),
    ] {
        for (what, p) in [("base grid", &base), ("pyramid", &pyramid)] {
            let mut rows: Vec<Row> = Vec::new();
            for k in 0..frames {
                let t = k as f64 * path.duration() / frames as f64;
                let camera = path.at(path.keys[0].time + t);
                let view = camera.view(SIZE.0, SIZE.1);
                let start = Instant::now();
                let c: Cut = renderer::cut::cut(p, &view, camera.position, TAU);
                let ms = start.elapsed().as_secs_f64() * 1e3;
                let coarsest = c.nodes.iter().map(|n| n.layer).max().unwrap_or(0);
                rows.push((c.nodes.len(), c.visited, c.triangles(p), ms, coarsest));
            }
            let median = |f: &dyn Fn(&Row) -> f64| {
                let mut v: Vec<f64> = rows.iter().map(f).collect();
                v.sort_by(f64::total_cmp);
                v[v.len() / 2]
            };
            println!(
                "| {name} | {what} | {:.0} | {:.0} | {:.0} | {:.2} | {:.0} |",
                median(&|r| r.0 as f64),
                median(&|r| r.1 as f64),
                median(&|r| r.2 as f64),
                median(&|r| r.3),
                median(&|r| f64::from(r.4)),
            );
        }
    }
    println!(
        "\nMedians over {frames} frames at {}x{}, tau {TAU}.",
        SIZE.0, SIZE.1
    );
    first_views(&set)
}

/// What the first frame of each flight must check before it can draw (each chosen tile's
/// checksum and `tiletool verify`'s per-tile checks, on every core, as `vkterrain` does before
/// its first frame), for the base grid's choice and the pyramid's. Each on a terrain opened
/// afresh, so no check is cached; the file is in the page cache (warm).
fn first_views(set: &std::path::Path) -> Result<()> {
    println!("\n| flight | selection | first view's tiles | checked in | per tile |");
    println!("|---|---|---:|---:|---:|");
    for name in ["orbit", "flyover"] {
        for what in ["base grid", "pyramid"] {
            let p = if what == "base grid" {
                Terrain::open(set)?
            } else {
                Terrain::open_pyramid(set)?
            };
            let path = if name == "orbit" {
                CameraPath::orbit(&p)
            } else {
                CameraPath::flyover(&p)
            };
            let camera = path.at(path.keys[0].time);
            let view = camera.view(SIZE.0, SIZE.1);
            let c = renderer::cut::cut(&p, &view, camera.position, TAU);
            let start = Instant::now();
            let tiles: Vec<usize> = c.nodes.iter().map(|n| n.tile).collect();
            p.check_all(&tiles);
            if p.failed_count() > 0 {
                bail!("{}: tiles failed their checks", set.display());
            }
            let s = start.elapsed().as_secs_f64();
            println!(
                "| {name} | {what} | {} | {s:.2} s | {:.0} ms |",
                c.nodes.len(),
                s * 1e3 / c.nodes.len().max(1) as f64
            );
        }
    }
    println!("\nOne run; the first frame of each flight; both cores.");
    Ok(())
}
