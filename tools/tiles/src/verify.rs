//! Independent checks of a written tile set: structure, nesting, fans, and (given the source
//! heights) every level's error, recomputed from the stored meshes alone.
//!
//! Nothing here reuses the mesher: fans are read back from the index arrays, triangles are
//! rasterised with their own barycentric code in f64, and the spacing rule is re-derived from
//! each fan's geometry. A tile set that passes is what the renderer will draw.

use crate::build::Heights;
use crate::format::{Tile, TileSet, FLAG_SHARED_SIDES};
use crate::grid::{tile_samples, Grid};
use crate::mesh::{TILE_CELLS, TILE_SIZE};
use crate::pack::unpack;
use crate::pyramid::Decimated;

/// One place where a level was allowed to exceed its bound (refinement forbidden there).
#[derive(Clone, Debug, PartialEq)]
pub struct LimitedPlace {
    pub tx: u32,
    pub ty: u32,
    pub level: u32,
    pub triangles: u64,
    pub excess: f64,
}

#[derive(Clone, Debug, Default)]
pub struct VerifyReport {
    pub tiles: u64,
    pub levels_checked: u64,
    /// With a source: the largest recomputed error per level over the base grid's tiles.
    pub recomputed_max_error: Vec<f64>,
    pub limited: Vec<LimitedPlace>,
    /// Everything that does not hold, one line each.
    pub problems: Vec<String>,
}

impl VerifyReport {
    pub fn ok(&self) -> bool {
        self.problems.is_empty()
    }
}

/// Tolerance between a stored error figure and the recomputed one (f32 storage, f32 vs f64
/// interpolation).
fn tolerance(e: f64) -> f64 {
    1e-3 + 1e-5 * e.abs()
}

/// Checks every tile, those of the pyramid's layers too; with `source`, also recomputes the
/// errors against it (a layer's against the source subsampled) and checks each layer tile's
/// decimation error against every source sample under it.
pub fn verify(set: &TileSet, source: Option<&Grid>) -> VerifyReport {
    verify_in_runs(set, source, TILES_A_RUN, &|| {})
}

/// How many tiles (whole rows of them, at least one row) [`verify`] checks of a compact set
/// before it forgets the tiles it rebuilt for them (a view keeps every tile it rebuilt; on the
/// 64K mirror set a run's tiles held 0.7 to 1.6 GB).
pub const TILES_A_RUN: u32 = 1024;

/// [`verify`], each layer's rows taken in runs of about `tiles_a_run` tiles (at least a row),
/// the view forgetting each run's rows after it, calling `progress` once a tile checked (of
/// every layer). The report does not depend on `tiles_a_run`.
pub fn verify_in_runs(
    set: &TileSet,
    source: Option<&Grid>,
    tiles_a_run: u32,
    progress: &(dyn Fn() + Sync),
) -> VerifyReport {
    let mut report = verify_layer(set, source, tiles_a_run, progress);
    if set.layer_index() != 0 || (!report.problems.is_empty() && report.tiles == 0) {
        return report;
    }
    for p in 1..=set.pyramid_layers() {
        let layer = set.layer(p).expect("a layer the set has");
        let decimated: Option<Vec<f32>> = source.map(|g| {
            let d = Decimated::new(g, p);
            let h = d.shape().height;
            d.rows(0, h).expect("a grid held whole").into_owned()
        });
        let grid = source.zip(decimated.as_ref()).map(|(g, heights)| {
            let shape = layer.header();
            Grid {
                width: shape.grid_width as usize,
                height: shape.grid_height as usize,
                first_row: 0,
                heights,
                spacing_x: g.spacing_x * f64::from(1u32 << p),
                spacing_y: g.spacing_y * f64::from(1u32 << p),
            }
        });
        let sub = verify_layer(&layer, grid.as_ref(), tiles_a_run, progress);
        report.tiles += sub.tiles;
        report.levels_checked += sub.levels_checked;
        report.problems.extend(sub.problems);
        report.limited.extend(sub.limited);
        // `recomputed_max_error` stays the base grid's: a layer's levels are built to their
        // own floors against their own samples (their errors against the base grid are
        // checked below).
        if let Some(g) = source {
            for ty in 0..layer.header().tiles_y {
                for tx in 0..layer.header().tiles_x {
                    if let Ok(tile) = layer.tile(tx, ty) {
                        check_decimation(&layer, &tile, g, &mut report);
                    }
                }
            }
        }
    }
    report
}

/// How a tile is named in problems: with its pyramid layer, when it has one.
fn tile_name(set: &TileSet, tx: u32, ty: u32) -> String {
    match set.layer_index() {
        0 => format!("tile {tx},{ty}"),
        p => format!("layer {p} tile {tx},{ty}"),
    }
}

/// A pyramid layer's tile against the base grid's samples under it: each level's stored error
/// against them ([`TileSet::base_errors`]) is what rasterising the level's fans over them gives,
/// and no more than the level's own `max_error` plus the tile's decimation error (the bound
/// [`crate::pyramid`] argues).
fn check_decimation(layer: &TileSet, tile: &Tile, base: &Grid, report: &mut VerifyReport) {
    let f = 1u32 << layer.layer_index();
    let (tx, ty) = (tile.header.tx, tile.header.ty);
    let d = f64::from(layer.decimation_error(tx, ty).unwrap_or(0.0));
    let Some(stored) = layer.base_errors(tx, ty) else {
        return;
    };
    let vertices = tile.vertices();
    let (x0, y0) = (
        (tx * TILE_CELLS * f) as usize,
        (ty * TILE_CELLS * f) as usize,
    );
    let max_x = (base.width - 1 - x0) as u32;
    let max_y = (base.height - 1 - y0) as u32;
    for level in 0..tile.header.levels {
        let Some(l) = tile.level(level) else {
            continue;
        };
        let mut worst = 0.0f64;
        for fan in l.indices.fans() {
            let v = |i: u32| {
                let (x, y, z) = vertices[i as usize];
                (x * f, y * f, z)
            };
            let c = v(fan[0]);
            for w in fan[1..].windows(2) {
                raster_barycentric([c, v(w[0]), v(w[1])], max_x, max_y, |x, y, z| {
                    let h = f64::from(base.at(x0 + x as usize, y0 + y as usize));
                    worst = worst.max((h - z).abs());
                });
            }
        }
        let name = tile_name(layer, tx, ty);
        let path = layer.path().display();
        let s = f64::from(stored[level as usize]);
        if (worst - s).abs() > tolerance(worst) {
            report.problems.push(format!(
                "{path}: {name} level {level}: recomputed error against the base grid {worst:.4} m, stored {s:.4} m"
            ));
        }
        let bound = f64::from(l.entry.max_error) + d;
        if worst > bound + tolerance(bound) {
            report.problems.push(format!(
                "{path}: {name} level {level}: a source sample lies {worst:.3} m from the level, past its error {:.3} m plus the decimation error {d:.3} m",
                l.entry.max_error
            ));
        }
    }
}

/// [`verify_layer`]'s report of tile `i` (row-major) alone.
fn verify_tile(set: &TileSet, source: Option<&Grid>, i: u32, levels: usize) -> VerifyReport {
    let tiles_x = set.header().tiles_x;
    let (tx, ty) = (i % tiles_x, i / tiles_x);
    let mut one = VerifyReport {
        tiles: 1,
        recomputed_max_error: vec![0.0; levels],
        ..Default::default()
    };
    match set.tile(tx, ty) {
        Ok(tile) => {
            check_tile(set, &tile, source, 0..tile.header.levels, &mut one);
            check_shared_edges(set, &tile, &mut one);
        }
        Err(e) => one.problems.push(e.to_string()),
    }
    // The texture: checksum, layout and every mip's size (None: the set has none).
    if let Err(e) = set.texture(tx, ty) {
        one.problems.push(e.to_string());
    }
    one
}

/// [`verify`] for one layer's tiles (the base grid's, or a pyramid layer's).
fn verify_layer(
    set: &TileSet,
    source: Option<&Grid>,
    tiles_a_run: u32,
    progress: &(dyn Fn() + Sync),
) -> VerifyReport {
    let h = set.header();
    let mut report = VerifyReport {
        recomputed_max_error: vec![0.0; h.levels as usize],
        ..Default::default()
    };
    if let Some(g) = source {
        if (g.width, g.height) != (h.grid_width as usize, h.grid_height as usize) {
            report.problems.push(format!(
                "source is {}x{} samples, the tile set was built from {}x{}",
                g.width, g.height, h.grid_width, h.grid_height
            ));
            return report;
        }
    }
    // Tile by tile on every core, each into a report of its own, joined in the tiles' order
    // (so the problems read as one pass over the rows would list them). A compact set's tiles
    // are rebuilt to be checked, and a view keeps what it rebuilt: so the rows go in runs of
    // about `tiles_a_run` tiles through one view of the layer's own, which forgets each run's
    // rows after it. The next run's first row stays: this run rebuilt it for its seams.
    use rayon::prelude::*;
    let levels = h.levels as usize;
    let rows_a_run = (tiles_a_run / h.tiles_x).max(1);
    let mut view = set.with_own_rebuilt();
    let mut each: Vec<VerifyReport> = Vec::with_capacity(h.tiles_x as usize * h.tiles_y as usize);
    for ty0 in (0..h.tiles_y).step_by(rows_a_run as usize) {
        let rows = ty0..ty0.saturating_add(rows_a_run).min(h.tiles_y);
        each.par_extend(
            (rows.start * h.tiles_x..rows.end * h.tiles_x)
                .into_par_iter()
                .map(|i| {
                    let one = verify_tile(&view, source, i, levels);
                    progress();
                    one
                }),
        );
        if !view.forget_rebuilt_rows(rows) {
            view = set.with_own_rebuilt();
        }
    }
    for one in each {
        report.tiles += one.tiles;
        report.levels_checked += one.levels_checked;
        for (all, e) in report
            .recomputed_max_error
            .iter_mut()
            .zip(one.recomputed_max_error)
        {
            *all = all.max(e);
        }
        report.limited.extend(one.limited);
        report.problems.extend(one.problems);
    }
    report
}

/// What `verify` (without a source) finds wrong with one tile: fans, coverage, nesting, blocks,
/// borders, morph offsets. Empty when the tile is sound. Renderers call it before any of the
/// tile's data leaves for the GPU.
pub fn tile_problems(set: &TileSet, tile: &Tile) -> Vec<String> {
    tile_problems_in(set, tile, 0..tile.header.levels)
}

/// [`tile_problems`] for the tile's `levels` alone, levels before them taken as checked: a
/// renderer checks the levels a tile is first drawn at, and each finer one before its first
/// upload. A level's checks cover its fans, cover, borders and box, its nesting in the level
/// before, and that its block's morph offsets onto every coarser level land on that level's
/// surface; so checking `0..a`, then `a..b`, then `b..levels` checks what one pass over every
/// level does, and reads blocks `a..b` alone for `a..b` (the structure of those levels is the
/// caller's to check first, [`crate::format::TileSet::tile_levels`]).
pub fn tile_problems_in(set: &TileSet, tile: &Tile, levels: std::ops::Range<u32>) -> Vec<String> {
    let mut report = VerifyReport {
        recomputed_max_error: vec![0.0; set.header().levels as usize],
        ..Default::default()
    };
    check_tile(set, tile, None, levels, &mut report);
    report.problems
}

/// A grid point on the edge between two tiles must decode to the same height in both (the
/// shared height lattice), or stitching could not close the seam exactly.
fn check_shared_edges(set: &TileSet, tile: &Tile, report: &mut VerifyReport) {
    let (tx, ty) = (tile.header.tx, tile.header.ty);
    // Heights (as bits) of a tile's vertices on a column (`vertical`) or row, by position along it.
    let edge = |t: &Tile, vertical: bool, at: u32| -> std::collections::HashMap<u32, u32> {
        t.vertices()
            .iter()
            .filter_map(|&(x, y, z)| {
                let (on, along) = if vertical { (x, y) } else { (y, x) };
                (on == at).then_some((along, z.to_bits()))
            })
            .collect()
    };
    // East neighbour (shared column) and south neighbour (shared row).
    for (nx, ny, vertical) in [(tx + 1, ty, true), (tx, ty + 1, false)] {
        if nx >= set.header().tiles_x || ny >= set.header().tiles_y {
            continue;
        }
        let Ok(other) = set.tile(nx, ny) else {
            continue;
        };
        let (mine, theirs) = (edge(tile, vertical, TILE_CELLS), edge(&other, vertical, 0));
        if let Some((p, _)) = mine
            .iter()
            .find(|(p, z)| theirs.get(p).is_some_and(|zb| zb != *z))
        {
            report.problems.push(format!(
                "{}: tiles {tx},{ty} and {nx},{ny} store different heights for their shared point {p} (seam cannot close)",
                set.path().display()
            ));
        }
        if set.header().flags & FLAG_SHARED_SIDES != 0 {
            if let Some(problem) = shared_side_problem(tile, &other, vertical) {
                report.problems.push(format!(
                    "{}: tiles {tx},{ty} and {nx},{ny} {problem}, although the set says they share their sides",
                    set.path().display()
                ));
            }
        }
    }
}

/// With [`FLAG_SHARED_SIDES`]: the two tiles must hold the same vertices on their shared side,
/// introduced at the same level, with the same morph offsets, and the same morph units.
fn shared_side_problem(tile: &Tile, other: &Tile, vertical: bool) -> Option<String> {
    let units =
        |t: &Tile| -> Vec<u32> { t.levels().iter().map(|e| e.morph_unit.to_bits()).collect() };
    if units(tile) != units(other) {
        return Some("use different morph units".into());
    }
    // Per position along the side: introducing level and morph offsets.
    let side = |t: &Tile, at: u32| -> std::collections::BTreeMap<u32, (u32, Vec<i8>)> {
        let mut out = std::collections::BTreeMap::new();
        for j in 0..t.header.levels {
            let Some(level) = t.level(j) else { continue };
            let n = level.entry.block_len as usize;
            for (i, &p) in level.positions.iter().enumerate() {
                let (x, y, _) = unpack(p);
                let (on, along) = if vertical { (x, y) } else { (y, x) };
                if on == at {
                    let offsets = (0..j as usize).map(|k| level.morph[k * n + i]).collect();
                    out.insert(along, (j, offsets));
                }
            }
        }
        out
    };
    let (mine, theirs) = (side(tile, TILE_CELLS), side(other, 0));
    let differing = mine
        .keys()
        .chain(theirs.keys())
        .find(|p| mine.get(p) != theirs.get(p))?;
    Some(match (mine.get(differing), theirs.get(differing)) {
        (Some((a, _)), Some((b, _))) if a != b => {
            format!("introduce their shared side vertex {differing} at levels {a} and {b}")
        }
        (Some(_), Some(_)) => {
            format!("store different morph offsets for their shared side vertex {differing}")
        }
        _ => format!("do not both hold side vertex {differing}"),
    })
}

fn check_tile(
    set: &TileSet,
    tile: &Tile,
    source: Option<&Grid>,
    levels: std::ops::Range<u32>,
    report: &mut VerifyReport,
) {
    let th = tile.header;
    let (tx, ty) = (th.tx, th.ty);
    let fh = set.header();
    let cells = TILE_CELLS as usize;
    let want_x = (fh.grid_width as usize - 1 - tx as usize * cells).min(cells) as u32;
    let want_y = (fh.grid_height as usize - 1 - ty as usize * cells).min(cells) as u32;
    // Problems found so far (a level that repeats a clean level need not be walked again).
    let found = std::cell::Cell::new(0usize);
    let mut problem = |level: Option<u32>, what: String| {
        found.set(found.get() + 1);
        let at = match level {
            Some(l) => format!("{} level {l}", tile_name(set, tx, ty)),
            None => tile_name(set, tx, ty),
        };
        report
            .problems
            .push(format!("{}: {at}: {what}", set.path().display()));
    };
    if (th.data_max_x, th.data_max_y) != (want_x, want_y) {
        problem(
            None,
            format!(
                "data extent {}x{} should be {want_x}x{want_y}",
                th.data_max_x, th.data_max_y
            ),
        );
        return;
    }
    let end = levels.end.min(th.levels);
    let vertices = tile.vertices_through(end);
    let samples = source.map(|g| tile_samples(g, tx, ty));
    // Each level's surface, for the morph offsets of the finer blocks checked here: those of
    // levels checked before by their index lists, which passed then.
    let adds = |j: u32| tile.level(j).is_some_and(|b| b.entry.block_len > 0);
    let mut surfaces: Vec<Option<Vec<f64>>> = vec![None; end as usize];
    if (levels.start.max(1)..end).any(adds) {
        for k in 0..levels.start.min(end) {
            if let Some(l) = tile.level(k) {
                let flat: Vec<u32> = l.indices.iter().map(|i| i.unwrap_or(u32::MAX)).collect();
                surfaces[k as usize] = Some(level_surface(&split_fans(&flat), &vertices));
            }
        }
    }
    // Vertices in use by the previous level (sets by bitmap below: the hash sets these
    // replace were most of verify's time).
    let mut previous: Vec<u32> = Vec::new();
    // The level before, its index list, and whether its checks found nothing (none after a
    // level cut short).
    let mut before: Option<(crate::format::Level, Vec<u32>, bool)> = None;
    // Levels before `levels` were checked by an earlier call: the last of them is where the
    // first one checked here nests, as if this pass had just checked it.
    if let Some(l) = levels.start.checked_sub(1).and_then(|k| tile.level(k)) {
        let flat: Vec<u32> = l.indices.iter().map(|i| i.unwrap_or(u32::MAX)).collect();
        previous = in_use(&flat, vertices.len()).1;
        before = Some((l, flat, true));
    }
    for level in levels.start..end {
        let found_before = found.get();
        report.levels_checked += 1;
        let Some(l) = tile.level(level) else {
            problem(Some(level), "unreadable".into());
            continue;
        };
        let e = &l.entry;
        // A pyramid layer's tile is built no finer than its floor (0 in the base grid).
        let floor = crate::pyramid::level_floor(set.decimation_error(tx, ty).unwrap_or(0.0));
        let bound = set.level_error(level).max(floor);
        if (f64::from(e.error_bound) - bound).abs() > tolerance(bound) {
            problem(
                Some(level),
                format!("error bound {} should be {bound}", e.error_bound),
            );
        }
        let flat: Vec<u32> = l.indices.iter().map(|i| i.unwrap_or(u32::MAX)).collect();
        let fans = split_fans(&flat);
        // A level that adds no vertex and stores the fans, borders and counts of a clean level
        // before it (a pyramid tile's levels past its floor, [`crate::pyramid::level_floor`]:
        // up to 7 of 9) passes the walks below as that level did, vertex for vertex: they are
        // compared, not walked again. Its errors and morph offsets are still checked.
        let repeats = before.take().is_some_and(|(b, b_flat, clean)| {
            let be = &b.entry;
            clean
                && e.block_len == 0
                && e.block_start == be.vertex_count()
                && (e.fan_count, e.triangle_count) == (be.fan_count, be.triangle_count)
                && e.z_min <= be.z_min
                && e.z_max >= be.z_max
                && l.border == b.border
                && b_flat == flat
        });
        let mut used: Vec<u32> = Vec::new();
        if repeats {
            used.clone_from(&previous);
        } else {
            if fans.len() != e.fan_count as usize {
                problem(
                    Some(level),
                    format!("{} fans, table says {}", fans.len(), e.fan_count),
                );
            }
            let (in_use, first_used) = self::in_use(&flat, vertices.len());
            used = first_used;
            let contains = |v: u32| in_use.get(v as usize).copied().unwrap_or(false);
            // Nesting: V_i ⊆ V_{i+1}, and block i holds exactly the vertices level i introduces.
            if let Some(v) = previous.iter().find(|&&v| !contains(v)) {
                problem(
                    Some(level),
                    format!(
                        "vertex {v} of level {} is missing (levels not nested)",
                        level.saturating_sub(1)
                    ),
                );
            }
            let block = e.block_start..e.vertex_count();
            if used.len() != e.vertex_count() as usize || !block.clone().all(contains) {
                problem(
                    Some(level),
                    "vertices in use differ from blocks 0..=level".into(),
                );
            }
            let mut presence = vec![false; TILE_SIZE * TILE_SIZE];
            let pos = |v: u32| vertices.get(v as usize).map(|&(x, y, _)| (x, y));
            for &v in &used {
                if let Some((x, y)) = pos(v) {
                    if x > th.mesh_max_x || y > th.mesh_max_y {
                        problem(
                            Some(level),
                            format!("vertex {v} at {x},{y} lies outside the mesh extent"),
                        );
                        return;
                    }
                    presence[y as usize * TILE_SIZE + x as usize] = true;
                }
            }
            // Fans: each a closed CCW ring on the square around its centre; together they tile the
            // mesh extent exactly once, and no level vertex sits inside a fan edge (no T-vertex).
            let mut covered = vec![false; (TILE_CELLS * TILE_CELLS) as usize];
            let mut triangles = 0u64;
            let mut bad_fan = None;
            for (f, fan) in fans.iter().enumerate() {
                match check_fan(fan, &vertices, &presence, &mut covered) {
                    Ok(t) => triangles += t,
                    Err(what) => {
                        bad_fan = Some(format!("fan {f}: {what}"));
                        break;
                    }
                }
            }
            if let Some(what) = bad_fan {
                problem(Some(level), what);
                continue;
            }
            let area = (th.mesh_max_x * th.mesh_max_y) as usize;
            let inside = covered.iter().filter(|&&c| c).count();
            let all_inside = (0..th.mesh_max_y)
                .all(|y| (0..th.mesh_max_x).all(|x| covered[(y * TILE_CELLS + x) as usize]));
            if inside != area || !all_inside {
                problem(
                    Some(level),
                    format!("fans cover {inside} of the {area} cells of the mesh extent"),
                );
            }
            if triangles != u64::from(e.triangle_count) {
                problem(
                    Some(level),
                    format!("{triangles} triangles, table says {}", e.triangle_count),
                );
            }
            // Border lists: exactly the level's vertices on each side, in order along it.
            let sides = [
                (|x: u32, y: u32, _: u32, _: u32| (y == 0).then_some(x))
                    as fn(u32, u32, u32, u32) -> Option<u32>,
                |x, y, mx, _| (x == mx).then_some(y),
                |x, y, _, my| (y == my).then_some(x),
                |x, y, _, _| (x == 0).then_some(y),
            ];
            for (k, side) in sides.iter().enumerate() {
                let mut want: Vec<(u32, u32)> = used
                    .iter()
                    .filter_map(|&v| {
                        pos(v)
                            .and_then(|(x, y)| side(x, y, th.mesh_max_x, th.mesh_max_y))
                            .map(|t| (t, v))
                    })
                    .collect();
                want.sort_unstable();
                let want: Vec<u32> = want.into_iter().map(|(_, v)| v).collect();
                if want != l.border[k] {
                    problem(
                        Some(level),
                        format!("border list {k} does not match the level's side vertices"),
                    );
                }
            }
            // Heights of the level's vertices bound the level's box.
            let (zlo, zhi) = used.iter().filter_map(|&v| vertices.get(v as usize)).fold(
                (f32::INFINITY, f32::NEG_INFINITY),
                |(lo, hi), &(_, _, z)| (lo.min(z), hi.max(z)),
            );
            if zlo < e.z_min || zhi > e.z_max {
                problem(
                    Some(level),
                    format!(
                        "vertex heights {zlo}..{zhi} leave the box {}..{}",
                        e.z_min, e.z_max
                    ),
                );
            }
        }
        if let Some(s) = &samples {
            let min_spacing = fh.spacing_x.min(fh.spacing_y);
            let (worst, limited, excess, unexplained, near_sides) = measure_level(
                &fans,
                &vertices,
                &s.heights,
                (th.data_max_x, th.data_max_y),
                (th.mesh_max_x, th.mesh_max_y),
                bound,
                min_spacing,
            );
            let slot = &mut report.recomputed_max_error[level as usize];
            *slot = slot.max(worst);
            if (worst - f64::from(e.max_error)).abs() > tolerance(worst) {
                problem(
                    Some(level),
                    format!(
                        "recomputed max error {worst:.4} m, stored {:.4} m",
                        e.max_error
                    ),
                );
            }
            if unexplained > 0.0 {
                problem(Some(level), format!(
                    "error exceeds e = {bound} m by {unexplained:.4} m where the spacing rule did not stop refinement"
                ));
            }
            // A side's error may be stored a code step (1/255 of the level's) above what it is,
            // never below it; code 0 stands for the level's whole error.
            let step = f64::from(e.max_error) / 255.0;
            for (k, &near) in near_sides.iter().enumerate() {
                let stored = f64::from(e.side_error(k));
                if e.side_errors[k] != 0
                    && (stored < near - tolerance(near) || stored > near + step + tolerance(near))
                {
                    problem(
                        Some(level),
                        format!("recomputed error near side {k} {near:.4} m, stored {stored:.4} m"),
                    );
                }
            }
            if limited as u32 != e.limited_triangles
                || (excess - f64::from(e.limited_excess)).abs() > tolerance(excess)
            {
                problem(Some(level), format!(
                    "{limited} triangles over the bound by up to {excess:.4} m; stored {} by {:.4} m",
                    e.limited_triangles, e.limited_excess
                ));
            }
            if limited > 0 {
                report.limited.push(LimitedPlace {
                    tx,
                    ty,
                    level,
                    triangles: limited,
                    excess,
                });
            }
        } else if e.limited_triangles > 0 {
            report.limited.push(LimitedPlace {
                tx,
                ty,
                level,
                triangles: u64::from(e.limited_triangles),
                excess: f64::from(e.limited_excess),
            });
        }
        check_morph(tile, level, &surfaces, &vertices, &mut problem);
        if (level + 1..end).any(adds) {
            surfaces[level as usize] = Some(level_surface(&fans, &vertices));
        }
        previous = used;
        before = Some((l, flat, found.get() == found_before));
    }
}

/// The vertices a level's flat index list (restarts as `u32::MAX`) uses, as a bitmap over the
/// tile's `count` vertices and as a list in order of first use (an index out of range is
/// listed, not marked: the checks report it).
fn in_use(flat: &[u32], count: usize) -> (Vec<bool>, Vec<u32>) {
    let (mut marked, mut used) = (vec![false; count], Vec::new());
    for &v in flat.iter().filter(|&&v| v != u32::MAX) {
        match marked.get_mut(v as usize) {
            Some(seen) if !*seen => {
                *seen = true;
                used.push(v);
            }
            Some(_) => {}
            None => used.push(v),
        }
    }
    (marked, used)
}

/// Level `k`'s surface over the tile's grid, rasterised from its fans (NaN outside them).
fn level_surface(fans: &[&[u32]], vertices: &[(u32, u32, f32)]) -> Vec<f64> {
    let mut surface = vec![f64::NAN; TILE_SIZE * TILE_SIZE];
    for fan in fans {
        let c = vertices[fan[0] as usize];
        for w in fan[1..].windows(2) {
            let tri = [c, vertices[w[0] as usize], vertices[w[1] as usize]];
            raster_plane(tri, |x, y, z| {
                surface[y as usize * TILE_SIZE + x as usize] = z
            });
        }
    }
    surface
}

/// Level `k`'s fans as slices of its flat index list (restarts as `u32::MAX`), as
/// `Indices::fans` splits them without a vector per fan: a trailing empty piece dropped.
fn split_fans(flat: &[u32]) -> Vec<&[u32]> {
    let mut fans: Vec<&[u32]> = flat.split(|&i| i == u32::MAX).collect();
    if fans.last().is_some_and(|f| f.is_empty()) {
        fans.pop();
    }
    fans
}

/// Every vertex of block `j` must morph onto each coarser level `k`'s surface: `height +
/// offset_k * unit_k` within half a unit of where level `k`'s fans put its position.
/// `surfaces[k]` is level `k`'s (None where its fans failed their checks: nothing is measured
/// against it). Checked with block `j`'s level, so a renderer checking a tile's levels as it
/// first needs them ([`tile_problems_in`]) checks the offsets it uploads with them.
fn check_morph(
    tile: &Tile,
    j: u32,
    surfaces: &[Option<Vec<f64>>],
    vertices: &[(u32, u32, f32)],
    problem: &mut impl FnMut(Option<u32>, String),
) {
    let Some(block) = tile.level(j) else { return };
    let n = block.entry.block_len as usize;
    for (k, surface) in surfaces.iter().enumerate().take(j as usize) {
        let (Some(surface), Some(coarse)) = (surface, tile.level(k as u32)) else {
            continue;
        };
        let unit = f64::from(coarse.entry.morph_unit);
        let row = &block.morph[k * n..(k + 1) * n];
        let mut worst = 0.0f64;
        for (i, &offset) in row.iter().enumerate() {
            let (x, y, h) = vertices[block.entry.block_start as usize + i];
            // (Outside the mesh extent: the level's structure check reports it.)
            let inside = x <= tile.header.mesh_max_x && y <= tile.header.mesh_max_y;
            let target = match inside {
                true => surface[y as usize * TILE_SIZE + x as usize],
                false => f64::NAN,
            };
            let miss = (f64::from(h) + f64::from(offset) * unit - target).abs();
            if miss.is_nan() || miss > unit * 0.5 + 1e-3 {
                worst = worst.max(if miss.is_nan() { f64::INFINITY } else { miss });
            }
        }
        if worst > 0.0 {
            problem(Some(j), format!("morph offsets onto level {k} miss its surface by up to {worst:.4} m (unit {unit:.4} m)"));
        }
    }
}

/// Checks one fan's shape and marks its cells; returns its triangle count.
fn check_fan(
    fan: &[u32],
    vertices: &[(u32, u32, f32)],
    presence: &[bool],
    covered: &mut [bool],
) -> Result<u64, String> {
    let at = |v: u32| {
        vertices
            .get(v as usize)
            .map(|&(x, y, _)| (i64::from(x), i64::from(y)))
            .ok_or("vertex out of range")
    };
    if fan.len() < 6 || fan.len() > 10 {
        return Err(format!(
            "{} indices (a fan has a centre and 5..=9 ring entries)",
            fan.len()
        ));
    }
    let c = at(fan[0])?;
    // At most 9 ring entries (checked above): on the stack, not a vector per fan.
    let mut stored = [(0i64, 0i64); 9];
    for (slot, &v) in stored.iter_mut().zip(&fan[1..]) {
        *slot = at(v)?;
    }
    let ring = &stored[..fan.len() - 1];
    if ring.first() != ring.last() {
        return Err("ring is not closed".into());
    }
    // The ring may start anywhere on the cell boundary (corner or midpoint): the half size is
    // its Chebyshev distance from the centre.
    let h = (ring[0].0 - c.0).abs().max((ring[0].1 - c.1).abs());
    if h == 0 || !(h as u64).is_power_of_two() {
        return Err("ring does not lie on a power-of-two cell".into());
    }
    let mut corners = 0;
    for w in ring.windows(2) {
        let (a, b) = (w[0], w[1]);
        let (ax, ay) = (a.0 - c.0, a.1 - c.1);
        if ax.abs().max(ay.abs()) != h || (ax.abs() != h && ax != 0) || (ay.abs() != h && ay != 0) {
            return Err("ring vertex off the cell's corners and midpoints".into());
        }
        if ax.abs() == h && ay.abs() == h {
            corners += 1;
        }
        // Consecutive ring vertices lie along one side, h (to or from a midpoint) or 2h (corner
        // to corner) apart, counter-clockwise seen from above: with y pointing south that is a
        // negative cross product (c->a) x (c->b) in (x, y).
        let (bx, by) = (b.0 - c.0, b.1 - c.1);
        let step = (a.0 - b.0).abs() + (a.1 - b.1).abs();
        if (a.0 != b.0 && a.1 != b.1) || (step != h && step != 2 * h) || ax * by - ay * bx >= 0 {
            return Err("ring is not a counter-clockwise walk of the cell boundary".into());
        }
        // No lattice point strictly inside this edge may be a vertex of the level.
        let (dx, dy) = ((b.0 - a.0).signum(), (b.1 - a.1).signum());
        for s in 1..h {
            let (x, y) = (a.0 + dx * s, a.1 + dy * s);
            if presence[y as usize * TILE_SIZE + x as usize] {
                return Err(format!("T-vertex at {x},{y}"));
            }
        }
    }
    if corners != 4 {
        return Err(format!("{corners} corners on the ring"));
    }
    for y in (c.1 - h)..(c.1 + h) {
        for x in (c.0 - h)..(c.0 + h) {
            let cell = &mut covered[(y * i64::from(TILE_CELLS) + x) as usize];
            if *cell {
                return Err(format!("cell {x},{y} drawn twice"));
            }
            *cell = true;
        }
    }
    Ok(ring.len() as u64 - 1)
}

/// Recomputes a level's error from its fans: (max error, triangles over `bound` where
/// refinement was forbidden, their largest excess, the largest excess where it was not).
fn measure_level(
    fans: &[&[u32]],
    vertices: &[(u32, u32, f32)],
    source: &[f32],
    (max_x, max_y): (u32, u32),
    mesh_max: (u32, u32),
    bound: f64,
    min_spacing: f64,
) -> (f64, u64, f64, f64, [f64; 4]) {
    let (mut worst, mut limited, mut excess, mut unexplained) = (0.0f64, 0u64, 0.0f64, 0.0f64);
    let mut near_sides = [0.0f64; 4];
    for fan in fans {
        let v = |i: u32| vertices[i as usize];
        let c = v(fan[0]);
        let ring: Vec<_> = fan[1..].iter().map(|&i| v(i)).collect();
        let half = c.0.abs_diff(ring[0].0).max(c.1.abs_diff(ring[0].1));
        let cell = 2 * half;
        for w in ring.windows(2) {
            let (a, b) = (w[0], w[1]);
            let err = triangle_error([c, a, b], source, max_x, max_y);
            worst = worst.max(err);
            for (x, y, _) in [c, a, b] {
                let on = [y == 0, x == mesh_max.0, y == mesh_max.1, x == 0];
                for (k, _) in on.iter().enumerate().filter(|(_, &on)| on) {
                    near_sides[k] = near_sides[k].max(err);
                }
            }
            // A micrometre of slack: the builder's and this f64 arithmetic round differently.
            if err > bound + 1e-6 {
                // A ring edge as long as the cell side can still get its midpoint (spacing
                // cell/2); a half edge only by splitting the cell (spacing cell/4).
                let full = a.0.abs_diff(b.0) + a.1.abs_diff(b.1) == cell;
                let forbidden = if full {
                    f64::from(cell / 2) * min_spacing < bound
                } else {
                    cell < 4 || f64::from(cell / 4) * min_spacing < bound
                };
                if forbidden {
                    limited += 1;
                    excess = excess.max(err - bound);
                } else {
                    unexplained = unexplained.max(err - bound);
                }
            }
        }
    }
    (worst, limited, excess, unexplained, near_sides)
}

/// Max |source - plane| over the real samples inside (or on) a triangle, in f64.
fn triangle_error(t: [(u32, u32, f32); 3], source: &[f32], max_x: u32, max_y: u32) -> f64 {
    let mut worst = 0.0f64;
    raster_barycentric(t, max_x, max_y, |x, y, z| {
        worst = worst.max((f64::from(source[y as usize * TILE_SIZE + x as usize]) - z).abs());
    });
    worst
}

/// Visits the lattice points of a triangle (edges included, clipped to `max_x`, `max_y`) with
/// the height interpolated there: row spans solved exactly on the integer lattice, heights
/// from f64 barycentric weights.
pub fn raster_barycentric(
    t: [(u32, u32, f32); 3],
    max_x: u32,
    max_y: u32,
    mut visit: impl FnMut(u32, u32, f64),
) {
    let p = t.map(|(x, y, z)| (f64::from(x), f64::from(y), f64::from(z)));
    let det = (p[1].1 - p[2].1) * (p[0].0 - p[2].0) + (p[2].0 - p[1].0) * (p[0].1 - p[2].1);
    spans(t, max_x, max_y, |y, xs| {
        let fy = f64::from(y);
        for x in xs {
            let fx = f64::from(x);
            let l0 = ((p[1].1 - p[2].1) * (fx - p[2].0) + (p[2].0 - p[1].0) * (fy - p[2].1)) / det;
            let l1 = ((p[2].1 - p[0].1) * (fx - p[2].0) + (p[0].0 - p[2].0) * (fy - p[2].1)) / det;
            let l2 = 1.0 - l0 - l1;
            visit(x, y, l0 * p[0].2 + l1 * p[1].2 + l2 * p[2].2);
        }
    });
}

/// The same points as [`raster_barycentric`] (unclipped), with the height from the triangle's
/// plane gradient: cheaper, and equal to it within float rounding (about 1e-12 m), for checks
/// with a tolerance.
fn raster_plane(t: [(u32, u32, f32); 3], mut visit: impl FnMut(u32, u32, f64)) {
    let p = t.map(|(x, y, z)| (f64::from(x), f64::from(y), f64::from(z)));
    let (ux, uy, uz) = (p[1].0 - p[0].0, p[1].1 - p[0].1, p[1].2 - p[0].2);
    let (vx, vy, vz) = (p[2].0 - p[0].0, p[2].1 - p[0].1, p[2].2 - p[0].2);
    let det = ux * vy - uy * vx;
    if det == 0.0 {
        return;
    }
    let (dzdx, dzdy) = ((uz * vy - vz * uy) / det, (vz * ux - uz * vx) / det);
    spans(t, u32::MAX, u32::MAX, |y, xs| {
        let row = p[0].2 + dzdy * (f64::from(y) - p[0].1);
        for x in xs {
            visit(x, y, row + dzdx * (f64::from(x) - p[0].0));
        }
    });
}

/// Calls `row(y, xs)` for each row of a triangle's lattice points (edges included, clipped to
/// `max_x`, `max_y`; none for a degenerate triangle), `xs` the points inside on that row.
/// Decided exactly on the integer lattice: a point is inside when its three edge functions
/// have the sign of the determinant or are zero. (For an integer edge function w, the f64
/// barycentric test w / det >= -1e-9 holds exactly when w * det >= 0, since |det| < 2^40.)
fn spans(
    t: [(u32, u32, f32); 3],
    max_x: u32,
    max_y: u32,
    mut row: impl FnMut(u32, std::ops::RangeInclusive<u32>),
) {
    let q = t.map(|(x, y, _)| (i64::from(x), i64::from(y)));
    let det = (q[1].1 - q[2].1) * (q[0].0 - q[2].0) + (q[2].0 - q[1].0) * (q[0].1 - q[2].1);
    if det == 0 {
        return;
    }
    let sign = det.signum();
    // Edge (a, b) as A x + B y + C, signed so that inside is >= 0.
    let edge = |a: (i64, i64), b: (i64, i64)| {
        let (ea, eb) = (sign * (a.1 - b.1), sign * (b.0 - a.0));
        (ea, eb, -(ea * b.0 + eb * b.1))
    };
    let edges = [edge(q[1], q[2]), edge(q[2], q[0]), edge(q[0], q[1])];
    let xs = t.map(|v| v.0);
    let ys = t.map(|v| v.1);
    let (x0, x1) = (
        xs.into_iter().min().unwrap_or(0),
        xs.into_iter().max().unwrap_or(0).min(max_x),
    );
    let (y0, y1) = (
        ys.into_iter().min().unwrap_or(0),
        ys.into_iter().max().unwrap_or(0).min(max_y),
    );
    for y in y0..=y1 {
        let (mut lo, mut hi) = (i64::from(x0), i64::from(x1));
        for &(ea, eb, ec) in &edges {
            let c = eb * i64::from(y) + ec;
            match ea.cmp(&0) {
                std::cmp::Ordering::Greater => {
                    let ceil = (-c).div_euclid(ea) + i64::from((-c).rem_euclid(ea) != 0);
                    lo = lo.max(ceil);
                }
                std::cmp::Ordering::Less => hi = hi.min(c.div_euclid(-ea)),
                std::cmp::Ordering::Equal if c < 0 => hi = lo - 1,
                std::cmp::Ordering::Equal => {}
            }
        }
        if lo <= hi {
            // lo >= x0 >= 0 and hi <= x1, both in u32.
            row(y, lo as u32..=hi as u32);
        }
    }
}

/// What differs between `set` and `other` once their tiles are read (a compact set's rebuilt,
/// [`crate::compact`]): the grid, levels, spacing, base error, height lattice, pyramid and
/// texture layout, then every tile of every layer, its blob as readers get it and its texture
/// blob; one line each (the first 50 tiles that differ, then a count). Issue 28's check that
/// a compact set holds the same tiles as a version 3 build of the same input.
pub fn same_tiles(set: &TileSet, other: &TileSet) -> Vec<String> {
    let name = |s: &TileSet| s.path().display().to_string();
    let (a, b) = (*set.header(), *other.header());
    let key = |h: &crate::format::FileHeader| {
        (
            (h.grid_width, h.grid_height, h.tiles_x, h.tiles_y, h.levels),
            (
                h.spacing_x.to_bits(),
                h.spacing_y.to_bits(),
                h.base_error.to_bits(),
            ),
            (h.height_step.to_bits(), h.pyramid_layers, h.texture_format),
            (h.texture_interior, h.texture_gutter, h.texture_mips),
        )
    };
    if key(&a) != key(&b) {
        return vec![format!(
            "{} and {}: different grids, levels, lattices, pyramids or texture layouts",
            name(set),
            name(other)
        )];
    }
    let mut problems = Vec::new();
    let mut differing = 0u64;
    for layer in 0..=set.pyramid_layers() {
        let (Some(s), Some(o)) = (set.layer(layer), other.layer(layer)) else {
            problems.push(format!("{}: no pyramid layer {layer}", name(set)));
            continue;
        };
        for ty in 0..s.header().tiles_y {
            for tx in 0..s.header().tiles_x {
                let read = |t: &TileSet| t.tile(tx, ty).map(|_| ()).map_err(|e| e.to_string());
                let problem = match (read(&s), read(&o)) {
                    (Err(e), _) | (_, Err(e)) => Some(e),
                    _ if s.blob(tx, ty) != o.blob(tx, ty) => Some("the tile differs".into()),
                    _ if s.texture_blob(tx, ty) != o.texture_blob(tx, ty) => {
                        Some("the texture differs".into())
                    }
                    _ => None,
                };
                if let Some(p) = problem {
                    differing += 1;
                    if differing <= 50 {
                        problems.push(format!(
                            "{} against {}: layer {layer} tile {tx},{ty}: {p}",
                            name(set),
                            name(other)
                        ));
                    }
                }
            }
        }
    }
    if differing > 50 {
        problems.push(format!("... {} more tiles differ", differing - 50));
    }
    problems
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The scan the spans replaced: every point of the bounding box, kept when its f64
    /// barycentric weights are all at least -1e-9.
    fn bounding_box_scan(t: [(u32, u32, f32); 3], max_x: u32, max_y: u32) -> Vec<(u32, u32, u64)> {
        let p = t.map(|(x, y, z)| (f64::from(x), f64::from(y), f64::from(z)));
        let det = (p[1].1 - p[2].1) * (p[0].0 - p[2].0) + (p[2].0 - p[1].0) * (p[0].1 - p[2].1);
        let mut out = Vec::new();
        if det == 0.0 {
            return out;
        }
        let x1 = t.iter().map(|v| v.0).max().unwrap_or(0).min(max_x);
        let y1 = t.iter().map(|v| v.1).max().unwrap_or(0).min(max_y);
        let x0 = t.iter().map(|v| v.0).min().unwrap_or(0);
        let y0 = t.iter().map(|v| v.1).min().unwrap_or(0);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (fx, fy) = (f64::from(x), f64::from(y));
                let l0 =
                    ((p[1].1 - p[2].1) * (fx - p[2].0) + (p[2].0 - p[1].0) * (fy - p[2].1)) / det;
                let l1 =
                    ((p[2].1 - p[0].1) * (fx - p[2].0) + (p[0].0 - p[2].0) * (fy - p[2].1)) / det;
                let l2 = 1.0 - l0 - l1;
                if l0 < -1e-9 || l1 < -1e-9 || l2 < -1e-9 {
                    continue;
                }
                out.push((x, y, (l0 * p[0].2 + l1 * p[1].2 + l2 * p[2].2).to_bits()));
            }
        }
        out
    }

    /// The row spans visit exactly the points the bounding-box scan kept, with the same
    /// heights bit for bit: random triangles of both windings, thin, degenerate and clipped
    /// ones, and the fan triangles the tiles are made of. The control: a span one point short
    /// on one side is caught.
    #[test]
    fn row_spans_visit_what_the_bounding_box_scan_kept() {
        let mut rng = splitmix::Rng(0x5eed);
        let mut triangles = Vec::new();
        for _ in 0..4000 {
            let span = [4, 16, 64, 257][rng.below(4)];
            let v = |rng: &mut splitmix::Rng| {
                (
                    rng.below(span) as u32,
                    rng.below(span) as u32,
                    rng.range(-500.0, 3000.0) as f32,
                )
            };
            triangles.push([v(&mut rng), v(&mut rng), v(&mut rng)]);
        }
        // A fan's triangles, centre (8, 8), half size 8, both windings.
        triangles.push([(8, 8, 1.0), (0, 0, 2.0), (8, 0, 3.0)]);
        triangles.push([(8, 8, 1.0), (8, 0, 3.0), (0, 0, 2.0)]);
        for (k, &t) in triangles.iter().enumerate() {
            let (max_x, max_y) = if k % 3 == 0 {
                (40, 30)
            } else {
                (u32::MAX, u32::MAX)
            };
            let mut spans = Vec::new();
            raster_barycentric(t, max_x, max_y, |x, y, z| spans.push((x, y, z.to_bits())));
            assert_eq!(
                spans,
                bounding_box_scan(t, max_x, max_y),
                "triangle {k}: {t:?}"
            );
            if max_x == u32::MAX {
                let mut plane = Vec::new();
                raster_plane(t, |x, y, z| plane.push((x, y, z)));
                assert_eq!(plane.len(), spans.len(), "triangle {k}");
                for (&(x, y, z), &(px, py, pz)) in spans.iter().zip(&plane) {
                    let z = f64::from_bits(z);
                    assert!((x, y) == (px, py) && (z - pz).abs() < 1e-9, "triangle {k}");
                }
            }
        }
        // The control.
        let t = [(0, 0, 0.0), (10, 0, 0.0), (0, 10, 0.0)];
        let mut spans = Vec::new();
        raster_barycentric(t, u32::MAX, u32::MAX, |x, y, z| {
            spans.push((x, y, z.to_bits()))
        });
        spans.retain(|&(x, y, _)| x + y != 10);
        assert_ne!(spans, bounding_box_scan(t, u32::MAX, u32::MAX));
    }
}
