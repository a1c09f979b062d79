//! `tilebench compact SET.vkt...`: what issue 28's compact level encoding would weigh, measured
//! on built sets before any of it is written. Each base tile's levels are re-encoded as the
//! issue describes, without the parts that can be derived:
//!
//! - **Where the new vertices are**: per level, coarse scales first, one bit for every grid
//!   point not yet present whose two parents (`renderer::morph::parents`) are: it is added or
//!   not. A decoder repeats the same walk, so the bits are the whole positional code (fans and
//!   x, y follow; the corners that have no parents are sent raw, 18 bits each).
//! - **Their heights**: a residual against the mean of the parents' height codes (the surface
//!   the coarser level draws there, as the morph pass places a vertex with no share), either
//!   packed per block at the width of its largest zigzagged residual (one byte for the width),
//!   or entropy-coded with one table per level for the set (the bits its empirical entropy
//!   gives; a real coder adds its table and a little).
//!
//! Every tile's blob is rebuilt from its vertex sets and height codes, with its header and
//! its levels' measured figures (`tiles::build::rebuild_tile`), and compared with the stored
//! one byte for byte: the encoding above would not hold the rest, so it must follow.
//!
//! Against that, what each base tile's blob holds today, by kind. Only the base grid is
//! counted (a pyramid's layers would add in proportion); textures are not geometry.

use std::collections::HashMap;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use tiles::build::Numbering;
use tiles::compact::{parents, scale_of};
use tiles::TileSet;

const SIDE: usize = 257;
const DECODE: Numbering = Numbering::Decode;
const FIRST_USE: Numbering = Numbering::FirstUse;

/// Byte counts and bit counts summed over a set's base tiles.
#[derive(Default)]
struct Weights {
    tiles: u64,
    vertices: u64,
    blob: u64,
    positions: u64,
    morph: u64,
    indices: u64,
    tree_bits: u64,
    /// Per level and scale index: candidates, and how many of them were added.
    tree: Vec<[(u64, u64); 8]>,
    raw_bits: u64,
    packed_bytes: u64,
    /// CPU time of rebuilding the tiles' blobs from the vertex sets and heights.
    rebuild_seconds: f64,
    /// `tiles::compact`'s bit streams, and the headers and level entries kept beside them.
    encoded: u64,
    tables: u64,
    /// Per level, how often each residual occurs (for the entropy).
    residuals: Vec<HashMap<i32, u64>>,
}

pub fn compact() -> Result<()> {
    let sets: Vec<PathBuf> = std::env::args().skip(2).map(PathBuf::from).collect();
    if sets.is_empty() {
        bail!("usage: tilebench compact SET.vkt...");
    }
    println!(
        "| set | samples | vertices | today B/sample (positions, morph, indices, other) | \
         tree bits/vertex, plain | entropy | residual bits/vertex, packed | entropy | compact \
         B/sample, plain and packed | both entropy-coded | `tiles::compact`, B/sample: levels + \
         header and entries | rebuilt on the CPU, ms a tile |"
    );
    println!("|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for set in &sets {
        let ts = TileSet::open(set).with_context(|| set.display().to_string())?;
        let file = std::fs::read(set).with_context(|| set.display().to_string())?;
        let w = weigh(&ts, &file).with_context(|| set.display().to_string())?;
        let h = ts.header();
        let samples = f64::from(h.grid_width) * f64::from(h.grid_height);
        let per = |bytes: f64| bytes / samples;
        let entropy_bits: f64 = w.residuals.iter().map(entropy_bits).sum();
        let vertices = w.vertices as f64;
        let residual_packed = w.packed_bytes as f64 * 8.0;
        let fixed = (w.tree_bits + w.raw_bits) as f64;
        let tree_entropy = tree_entropy_bits(&w.tree);
        println!(
            "| {} | {:.2} M | {:.2} M | **{:.2}** ({:.2}, {:.2}, {:.2}, {:.2}) | {:.2} | {:.2} | \
             {:.2} | {:.2} | **{:.3}** | **{:.3}** | **{:.3}** + {:.3} | {:.1} |",
            set.file_name().and_then(|n| n.to_str()).unwrap_or("?"),
            samples / 1e6,
            vertices / 1e6,
            per(w.blob as f64),
            per(w.positions as f64),
            per(w.morph as f64),
            per(w.indices as f64),
            per((w.blob - w.positions - w.morph - w.indices) as f64),
            w.tree_bits as f64 / vertices,
            tree_entropy / vertices,
            residual_packed / vertices,
            entropy_bits / vertices,
            per((fixed + residual_packed) / 8.0),
            per((tree_entropy + w.raw_bits as f64 + entropy_bits) / 8.0),
            per(w.encoded as f64),
            per(w.tables as f64),
            w.rebuild_seconds * 1e3 / w.tiles as f64,
        );
    }
    Ok(())
}

/// The bits an ideal binary coder spends on the tree's bits with one probability per level and
/// scale.
fn tree_entropy_bits(tree: &[[(u64, u64); 8]]) -> f64 {
    tree.iter()
        .flatten()
        .map(|&(c, a)| {
            let (c, a) = (c as f64, a as f64);
            let h = |n: f64| if n > 0.0 { -n * (n / c).log2() } else { 0.0 };
            h(a) + h(c - a)
        })
        .sum()
}

/// The bits an ideal coder with one static table spends on `counts`.
fn entropy_bits(counts: &HashMap<i32, u64>) -> f64 {
    let n: u64 = counts.values().sum();
    counts
        .values()
        .map(|&c| {
            let p = c as f64 / n as f64;
            -(c as f64) * p.log2()
        })
        .sum()
}

fn weigh(ts: &TileSet, file: &[u8]) -> Result<Weights> {
    let h = ts.header();
    let mut w = Weights {
        residuals: vec![HashMap::new(); h.levels as usize],
        tree: vec![[(0, 0); 8]; h.levels as usize],
        ..Weights::default()
    };
    for ty in 0..h.tiles_y {
        for tx in 0..h.tiles_x {
            let tile = ts.tile(tx, ty).with_context(|| format!("tile {tx},{ty}"))?;
            let e = ts.dir_entry(tx, ty).context("directory")?;
            let blob = &file[e.offset as usize..(e.offset + e.len) as usize];
            weigh_tile(&tile, blob, &mut w).with_context(|| format!("tile {tx},{ty}"))?;
        }
    }
    Ok(w)
}

fn weigh_tile(tile: &tiles::format::Tile, blob: &[u8], w: &mut Weights) -> Result<()> {
    w.tiles += 1;
    w.blob += tile.blob_len() as u64;
    // Per grid point: its height code and the block that brings it (MAX: none).
    let mut code = vec![0i32; SIDE * SIDE];
    let mut block = vec![usize::MAX; SIDE * SIDE];
    let mut blocks = Vec::new();
    for j in 0..tile.header.levels {
        let Some(level) = tile.level(j) else { break };
        let n = level.positions.len() as u64;
        w.positions += 4 * n;
        w.morph += (u64::from(j) * n).div_ceil(4) * 4;
        w.indices += level.indices.len() as u64 * u64::from(level.entry.index_width);
        let mut points = Vec::with_capacity(level.positions.len());
        for &p in level.positions {
            let (x, y, c) = tiles::pack::unpack(p);
            let at = y as usize * SIDE + x as usize;
            code[at] = c as i32;
            block[at] = j as usize;
            points.push((x, y));
        }
        w.vertices += n;
        blocks.push(points);
    }
    // The rest of the tile must follow from the vertex sets and their heights (issue 28), as
    // `tiles`' test shows on SRTM3 crops: checked here on every tile weighed, byte for byte.
    let coded: Vec<Vec<(u32, u32, u16)>> = (0..blocks.len() as u32)
        .map(|j| {
            let level = tile.level(j).expect("read above");
            level
                .positions
                .iter()
                .map(|&p| tiles::pack::unpack(p))
                .collect()
        })
        .collect();
    let started = std::time::Instant::now();
    let rebuilt = tiles::build::rebuild_tile(&tile.header, tile.levels(), &coded, DECODE);
    w.rebuild_seconds += started.elapsed().as_secs_f64();
    // Sets written before the decoding order numbered blocks by first use.
    let numbering = if rebuilt == blob {
        DECODE
    } else if tiles::build::rebuild_tile(&tile.header, tile.levels(), &coded, FIRST_USE) == blob {
        FIRST_USE
    } else {
        bail!("its blob does not follow from its vertices and heights");
    };
    // And the bit stream itself: its bytes, and the same blob from them.
    let stream = tiles::compact::encode(tile);
    w.encoded += stream.len() as u64;
    w.tables += (std::mem::size_of::<tiles::format::TileHeader>()
        + blocks.len() * std::mem::size_of::<tiles::format::LevelEntry>()) as u64;
    if tiles::compact::rebuild(&tile.header, tile.levels(), &stream, numbering).as_deref()
        != Ok(blob)
    {
        bail!("its compact bit stream does not rebuild its blob");
    }
    let present = |at: usize, j: usize| block[at] <= j;
    // What a decoder knows so far: the points of the levels decoded.
    let mut known = vec![false; SIDE * SIDE];
    let index = |(x, y): (u32, u32)| y as usize * SIDE + x as usize;
    for (j, points) in blocks.iter().enumerate() {
        // Residuals, packed at the block's width, and counted for the level's table.
        let mut widest = 0u32;
        let mut coded = 0u64;
        for &(x, y) in points {
            let at = index((x, y));
            match parents(x, y).filter(|[p, q]| present(index(*p), j) && present(index(*q), j)) {
                Some([p, q]) => {
                    let r = code[at] - (code[index(p)] + code[index(q)]).div_euclid(2);
                    let zigzag = ((r << 1) ^ (r >> 31)) as u32;
                    widest = widest.max(32 - zigzag.leading_zeros());
                    *w.residuals[j].entry(r).or_default() += 1;
                    coded += 1;
                }
                None => w.raw_bits += 18 + 14,
            }
        }
        w.packed_bytes += (coded * u64::from(widest)).div_ceil(8) + 1;
        // Where the block's vertices are, walked as a decoder would: the vertices sent raw
        // first, then one bit per candidate (a point not known yet whose parents are), coarse
        // scales first. Every vertex of the block must end up known, else the code could not
        // say it is there.
        for &(x, y) in points {
            let raw =
                parents(x, y).is_none_or(|[p, q]| !present(index(p), j) || !present(index(q), j));
            known[index((x, y))] |= raw;
        }
        for k in (0..8).rev() {
            let s = 1u32 << k;
            for y in (0..SIDE as u32).step_by(s as usize) {
                for x in (0..SIDE as u32).step_by(s as usize) {
                    let at = index((x, y));
                    if scale_of(x, y) != s || known[at] {
                        continue;
                    }
                    let Some([p, q]) = parents(x, y) else {
                        continue;
                    };
                    if known[index(p)] && known[index(q)] {
                        w.tree_bits += 1;
                        let (candidates, added) = &mut w.tree[j][k];
                        *candidates += 1;
                        *added += u64::from(block[at] == j);
                        known[at] = block[at] == j;
                    }
                }
            }
        }
        let missed = points.iter().filter(|&&p| !known[index(p)]).count();
        if missed > 0 {
            bail!(
                "block {j}: {missed} of its {} vertices are neither met by the walk nor sent raw",
                points.len()
            );
        }
    }
    Ok(())
}
