//! Level of detail per tile (paper, section 5): the coarsest level whose measured vertical
//! error cannot move any visible point of the tile by more than `tau` pixels.
//!
//! # The bound
//!
//! The stored errors are vertical: every source sample of a tile lies within `e_L` metres,
//! straight up or down, of level `L`'s surface. A vertical segment of length `e` at `p` moves
//! on screen by at most `e * sup |J z|` over the segment, where `J` is the Jacobian of the
//! projection and `z` world up. So level `L` is good enough when `e_L * S <= tau`, where `S`
//! bounds `|J z|` over every point of the tile that can be drawn or measured. [`bound`] gives
//! such an `S`, proved here.
//!
//! Let a point relative to the camera have view coordinates `(x, y, -d)` (depth `d`), let
//! `w = (w_x, w_y, w_z)` be world up in view coordinates and `f_x, f_y` the focal lengths in
//! pixels. Projection is `u = f_x x / d`, `v = f_y y / d` (plus constants), and moving the point
//! along `w` changes `x, y, d` at rates `w_x, w_y, -w_z`, so
//!
//! ```text
//! |J z| = sqrt(j_x^2 + j_y^2),   j_x = f_x (w_x / d + x w_z / d^2),   j_y likewise with y.
//! ```
//!
//! Over the tile's box `B` (below), for every point of `B` that is drawn:
//! - `d >= d0 = max(NEAR, min of d over the 8 corners)`: `d` is affine, so its minimum over the
//!   box is at a corner, and points nearer than `NEAR` are clipped;
//! - `|x| <= X`, the largest `|x|` over the corners (`|x|` is convex: its maximum over the box
//!   is at a corner), and `|x| <= t_x d` inside the frustum, with `t_x = (width / 2) / f_x`;
//!   likewise `|y| <= Y` and `|y| <= t_y d`.
//!
//! Hence `|j_x| <= f_x (|w_x| / d + |w_z| min(X / d^2, t_x / d))
//!          <= f_x (|w_x| + |w_z| min(X / d0, t_x)) / d0`, each term falling with `d`, and
//! likewise `|j_y|`; `S` is the norm of the two. The `t` terms hold for points inside the
//! frustum: a segment whose two ends are on screen is, the frustum being convex.
//!
//! The box covers what is drawn and what is measured: x and y from the tile's mesh, z from
//! the lowest to the highest vertex of any level (every level's surface interpolates its
//! vertices, so lies in that range), widened by the finest level's measured error (the source
//! samples lie within it of the finest surface, which is inside the vertex range).
//!
//! The previous rule sampled `|J z|` at the corners and at the box point nearest the camera:
//! `|J z|` can peak inside an edge or face, and the box came from vertex heights alone, so it
//! could under-estimate (`sampled_pixels_per_metre`, kept for the benchmark and the tests).

use glam::DVec3;

use crate::camera::{View, NEAR};
use crate::tile::TileInfo;

/// How the largest `|J z|` over a tile is found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Bound {
    /// The proved bound of this module's header (the default).
    #[default]
    Guaranteed,
    /// The previous rule: the 8 corners and the nearest box point of the vertex box. Can
    /// under-estimate; kept to measure what the guarantee costs.
    Sampled,
}

/// The box the bound covers, in world metres: the mesh's x and y, the vertices' z range
/// widened by the finest level's measured error (see the module header).
pub fn tile_box(tile: &TileInfo) -> (DVec3, DVec3) {
    let e = tile
        .levels
        .last()
        .map_or(0.0, |l| f64::from(l.max_error).max(0.0));
    (
        DVec3::new(tile.min.x, tile.min.y, tile.min.z - e),
        DVec3::new(tile.max.x, tile.max.y, tile.max.z + e),
    )
}

/// An upper bound on `|J z|` (pixels per vertical metre) over every point of the box
/// `lo..hi` (relative to the camera) that is on screen. Infinite for a degenerate view.
pub fn bound(view: &View, lo: DVec3, hi: DVec3) -> f64 {
    let (mut d_min, mut x_max, mut y_max) = (f64::INFINITY, 0.0f64, 0.0f64);
    for i in 0..8 {
        let corner = DVec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        );
        let v = view.to_view(corner);
        d_min = d_min.min(-v.z);
        x_max = x_max.max(v.x.abs());
        y_max = y_max.max(v.y.abs());
    }
    let d0 = d_min.max(NEAR);
    let w = DVec3::new(view.right.z, view.up.z, view.back.z).abs();
    let (fx, fy) = view.focal;
    let tx = f64::from(view.width) * 0.5 / fx;
    let ty = f64::from(view.height) * 0.5 / fy;
    let jx = fx * (w.x + w.z * (x_max / d0).min(tx)) / d0;
    let jy = fy * (w.y + w.z * (y_max / d0).min(ty)) / d0;
    let s = (jx * jx + jy * jy).sqrt();
    if s.is_finite() {
        s
    } else {
        f64::INFINITY
    }
}

/// Sub-boxes per side in [`subdivided_bound`] for tiles.
pub const SPLIT: u32 = 4;

/// [`bound`] over `n x n` sub-boxes of `lo..hi` (split in x and y), skipping those wholly
/// outside the frustum: the largest of their bounds still covers every on-screen point (each
/// is in some sub-box that is not wholly outside), and it is tighter when the box's nearest
/// corner is off screen, as for tiles under and beside the camera.
pub fn subdivided_bound(view: &View, lo: DVec3, hi: DVec3, n: u32) -> f64 {
    pieces_bound(view, &view.frustum(), lo, hi, (n, n))
}

/// [`bound`] over the `nx x ny` pieces of `lo..hi` that are not wholly outside `planes`, the
/// view's frustum: 0 when none touches it.
fn pieces_bound(
    view: &View,
    planes: &[glam::Vec4; 5],
    lo: DVec3,
    hi: DVec3,
    (nx, ny): (u32, u32),
) -> f64 {
    pieces(lo, hi, nx, ny)
        .filter(|&(a, b)| !crate::cull::box_outside(planes, a, b))
        .map(|(a, b)| bound(view, a, b))
        .fold(0.0, f64::max)
}

/// `|J z|` over a tile's on-screen part under `rule` (the guaranteed rule splits its box).
fn tile_bound(view: &View, camera: DVec3, tile: &TileInfo, rule: Bound) -> f64 {
    match rule {
        Bound::Guaranteed => {
            let (lo, hi) = tile_box(tile);
            subdivided_bound(view, lo - camera, hi - camera, SPLIT)
        }
        Bound::Sampled => sampled_pixels_per_metre(view, tile.min - camera, tile.max - camera),
    }
}

/// The vertical error that projects to `tau` pixels at `s` pixels per metre (0, the finest
/// level, for a degenerate bound).
fn error_for(s: f64, tau: f64) -> f64 {
    if s.is_finite() && s > 0.0 {
        tau / s
    } else {
        0.0
    }
}

/// The previous rule: `|J z|` at the vertex box's 8 corners and at its point nearest the
/// camera (the camera itself when inside). Not a bound.
pub fn sampled_pixels_per_metre(view: &View, lo: DVec3, hi: DVec3) -> f64 {
    let closest = DVec3::ZERO.clamp(lo, hi);
    let mut worst = view.pixels_per_vertical_metre(closest);
    for i in 0..8 {
        let corner = DVec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        );
        worst = worst.max(view.pixels_per_vertical_metre(corner));
    }
    worst
}

/// The largest vertical error, metres, that projects to at most `tau` pixels anywhere on the
/// tile (0 when the camera is in or at the tile's box: the finest level).
pub fn tolerable_error(view: &View, camera: DVec3, tile: &TileInfo, tau: f64, rule: Bound) -> f64 {
    error_for(tile_bound(view, camera, tile, rule), tau)
}

/// The level a tile is drawn at for `tau`: the coarsest whose measured error projects to at
/// most `tau` pixels under `rule`. The guaranteed rule tries the whole box first (one bound)
/// and splits it only when that could choose a coarser level than the finest-needed one, i.e.
/// unless it already allows level 0.
pub fn level(view: &View, camera: DVec3, tile: &TileInfo, tau: f64, rule: Bound) -> u32 {
    if rule == Bound::Guaranteed {
        let (lo, hi) = tile_box(tile);
        let s = bound(view, lo - camera, hi - camera);
        if level_for(tile, error_for(s, tau)) == 0 {
            return 0;
        }
    }
    level_for(tile, tolerable_error(view, camera, tile, tau, rule))
}

/// The level a tile is drawn at while geomorphing ([`crate::morph`], "The level a tile is
/// drawn at"): the coarsest that covers the level `Λ(τ / S)` of every vertex on screen whose
/// level moves it. Each vertex takes one of the tile's nine level tables
/// ([`crate::morph::table_of`]): the interior its own, a side the larger of the two tiles'. So
/// the drawn level is the largest, over the interior and the four sides, of
/// `ceil(Λ_part(τ / S_part))`, with `S_part` the proved bound over the on-screen pieces of that
/// part's box: the whole tile's box for the interior; for a side, the strip
/// [`crate::morph::SIDE_REACH`] samples deep on both sides of it, into the neighbour (the
/// tile's height range, in [`SPLIT`] pieces along the side), where the stars of the side's
/// vertices reach ([`crate::morph`], "Over the star"). A rough neighbour then makes a tile
/// finer only as far as the strip along the shared side needs, not the whole tile wherever it
/// is seen.
///
/// The four corners take no part: a tile's corners are vertices of its coarsest level (block
/// 0), which every level holds at the vertex's own height, so no level moves them and none
/// makes them appear (the shader's weights for them multiply no offset). Their level tables
/// (the largest of the four tiles around) raised a tile wherever a rougher tile touched it
/// only diagonally, for nothing. The surface near a corner is the interior's and the sides'
/// (every point there is in their boxes).
///
/// When the whole box and the strips already allow level 0 under the largest table, level 0 it
/// is.
pub fn morph_level(view: &View, camera: DVec3, tile: &TileInfo, tau: f64, rule: Bound) -> u32 {
    let finest = tile.levels.len().saturating_sub(1) as u32;
    let within =
        |table: &crate::levels::LevelTable, r: f64| (table.level_f64(r).ceil() as u32).min(finest);
    // The vertices aim at a margin below tau (crate::morph::TAU_MARGIN); so does the tile.
    let tau = tau * crate::morph::TAU_MARGIN;
    if rule == Bound::Sampled {
        return within(
            &tile.drawn_table,
            tolerable_error(view, camera, tile, tau, rule),
        );
    }
    let (lo, hi) = tile_box(tile);
    let (lo, hi) = (lo - camera, hi - camera);
    if within(
        &tile.drawn_table,
        error_for(reach_bound(view, tile, lo, hi), tau),
    ) == 0
    {
        return 0;
    }
    let planes = view.frustum();
    let interior = &tile.tables[0];
    let mut level = within(
        interior,
        error_for(pieces_bound(view, &planes, lo, hi, (SPLIT, SPLIT)), tau),
    );
    for (part, (a, b)) in strips(lo, hi, strip_depth(tile, lo, hi))
        .into_iter()
        .enumerate()
    {
        // (A side whose table is the interior's still covers the strip's outer half.)
        let table = &tile.tables[part + 1];
        if level == finest {
            continue;
        }
        // Split along the side, not across it.
        let along = |axis: usize| if part % 2 == axis { SPLIT } else { 1 };
        let s = pieces_bound(view, &planes, a, b, (along(0), along(1)));
        // 0: no piece of the part touches the frustum, so none of its vertices is on screen.
        if s > 0.0 {
            level = level.max(within(table, error_for(s, tau)));
        }
    }
    level
}

/// The levels of a tile's 4 x 4 parts while geomorphing part by part ([`tiles::parts`]): for
/// each part, [`morph_level`]'s rule over the part alone, the interior table over the part's
/// box (the whole tile's height range, in 2 x 2 pieces) and each side's table over the strip
/// across the stretch of the side that bounds the part. A part no piece of which touches the
/// frustum has no vertex on screen and gets level 0. Every on-screen vertex lies in the closed
/// box of each part whose mesh holds it (a vertex on a line between parts is in the boxes of
/// all parts there), so its level is within each of those parts' levels: the cover of
/// [`morph_level`], part by part. The tile's level, the largest of its parts', is at most
/// [`morph_level`]'s.
pub fn morph_parts(
    view: &View,
    camera: DVec3,
    tile: &TileInfo,
    tau: f64,
    rule: Bound,
) -> tiles::parts::PartLevels {
    use tiles::parts::{PARTS, PART_CELLS};
    let finest = tile.levels.len().saturating_sub(1) as u32;
    if rule == Bound::Sampled {
        return [morph_level(view, camera, tile, tau, rule) as u8; PARTS * PARTS];
    }
    let within =
        |table: &crate::levels::LevelTable, r: f64| (table.level_f64(r).ceil() as u32).min(finest);
    let tau = tau * crate::morph::TAU_MARGIN;
    let (tlo, thi) = tile_box(tile);
    let (tlo, thi) = (tlo - camera, thi - camera);
    if within(
        &tile.drawn_table,
        error_for(reach_bound(view, tile, tlo, thi), tau),
    ) == 0
    {
        return [0; PARTS * PARTS];
    }
    let planes = view.frustum();
    let interior = &tile.tables[0];
    // Parts run east with i and south with j (rows from the tile's first, northern, row), 64
    // cells each; the box's x and y span the mesh (fewer cells in a partial tile).
    let cells = (tile.header.mesh_max_x.max(1), tile.header.mesh_max_y.max(1));
    let part = cells_size(tile, tlo, thi, PART_CELLS);
    std::array::from_fn(|q| {
        let (i, j) = ((q % PARTS) as u32, (q / PARTS) as u32);
        if i * PART_CELLS >= cells.0 || j * PART_CELLS >= cells.1 {
            return 0;
        }
        // The part's stretch of the N, E, S and W sides, where it has one (decided on the
        // cells: a box's end computed in metres can miss the tile's by a rounding).
        let touches = [
            j == 0,
            (i + 1) * PART_CELLS >= cells.0,
            (j + 1) * PART_CELLS >= cells.1,
            i == 0,
        ];
        let (fi, fj) = (f64::from(i), f64::from(j));
        let lo = DVec3::new(
            tlo.x + part.0 * fi,
            if touches[2] {
                tlo.y
            } else {
                thi.y - part.1 * (fj + 1.0)
            },
            tlo.z,
        );
        let hi = DVec3::new(
            if touches[1] { thi.x } else { lo.x + part.0 },
            thi.y - part.1 * fj,
            thi.z,
        );
        let s = pieces_bound(view, &planes, lo, hi, (2, 2));
        if s == 0.0 {
            return 0;
        }
        let mut level = within(interior, error_for(s, tau));
        for (side, (a, b)) in strips(lo, hi, strip_depth(tile, tlo, thi))
            .into_iter()
            .enumerate()
        {
            let table = &tile.tables[side + 1];
            if !touches[side] || level == finest {
                continue;
            }
            let s = pieces_bound(view, &planes, a, b, (2, 2));
            if s > 0.0 {
                level = level.max(within(table, error_for(s, tau)));
            }
        }
        level as u8
    })
}

/// The size (m, east and north) of `cells` of `tile`'s grid, from the tile's box `lo..hi`
/// (fewer cells a side in a partial tile).
fn cells_size(tile: &TileInfo, lo: DVec3, hi: DVec3, cells: u32) -> (f64, f64) {
    let mesh = (tile.header.mesh_max_x.max(1), tile.header.mesh_max_y.max(1));
    (
        (hi.x - lo.x) / f64::from(mesh.0) * f64::from(cells),
        (hi.y - lo.y) / f64::from(mesh.1) * f64::from(cells),
    )
}

/// [`bound`] over the tile's box `lo..hi` and the strips along its sides ([`strips`]).
fn reach_bound(view: &View, tile: &TileInfo, lo: DVec3, hi: DVec3) -> f64 {
    let (dx, dy) = strip_depth(tile, lo, hi);
    let d = DVec3::new(dx, dy, 0.0);
    bound(view, lo - d, hi + d)
}

/// How deep the strips of [`strips`] reach on either side of a tile's side (m).
fn strip_depth(tile: &TileInfo, lo: DVec3, hi: DVec3) -> (f64, f64) {
    cells_size(tile, lo, hi, crate::morph::SIDE_REACH)
}

/// The strips along the N, E, S and W sides of the box `lo..hi` (a tile's, or a part's), `depth`
/// deep on either side of the side (into the neighbouring tile), each over the whole height:
/// where the stars of the side's vertices reach ([`crate::morph::TileMorph::reach`]).
fn strips(lo: DVec3, hi: DVec3, depth: (f64, f64)) -> [(DVec3, DVec3); 4] {
    let at = |x: f64, y: f64, z: f64| DVec3::new(x, y, z);
    let (dx, dy) = depth;
    [
        (at(lo.x, hi.y - dy, lo.z), at(hi.x, hi.y + dy, hi.z)),
        (at(hi.x - dx, lo.y, lo.z), at(hi.x + dx, hi.y, hi.z)),
        (at(lo.x, lo.y - dy, lo.z), at(hi.x, lo.y + dy, hi.z)),
        (at(lo.x - dx, lo.y, lo.z), at(lo.x + dx, hi.y, hi.z)),
    ]
}

/// The `nx x ny` pieces of `lo..hi`, split in x and y (each spans the whole height).
fn pieces(lo: DVec3, hi: DVec3, nx: u32, ny: u32) -> impl Iterator<Item = (DVec3, DVec3)> {
    let (nx, ny) = (nx.max(1), ny.max(1));
    let step = DVec3::new(
        (hi.x - lo.x) / f64::from(nx),
        (hi.y - lo.y) / f64::from(ny),
        0.0,
    );
    (0..nx * ny).map(move |i| {
        let a = lo + DVec3::new(step.x * f64::from(i % nx), step.y * f64::from(i / nx), 0.0);
        (a, DVec3::new(a.x + step.x, a.y + step.y, hi.z))
    })
}

/// The coarsest level whose measured error is within `r` metres (the finest if none is).
pub fn level_for(tile: &TileInfo, r: f64) -> u32 {
    tile.levels
        .iter()
        .position(|l| f64::from(l.max_error) <= r)
        .unwrap_or(tile.levels.len().saturating_sub(1)) as u32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_rng::Rng;

    /// Random cameras and boxes in front of them: `|J z|` at every on-screen point of a dense
    /// lattice of the box stays within the bound; the sampled rule is exceeded somewhere (it
    /// is not a bound: the negative control).
    #[test]
    fn the_bound_covers_every_on_screen_point_and_sampling_does_not() {
        let mut rng = Rng(0x5eed_1234_abcd_ef01);
        let (mut worst_bound, mut worst_sampled) = (0.0f64, 0.0f64);
        let mut on_screen = 0u64;
        for _ in 0..400 {
            let camera = rng.camera();
            let view = camera.view(640, 480);
            let centre = camera.forward() * rng.range(5.0, 3000.0)
                + DVec3::new(
                    rng.range(-500.0, 500.0),
                    rng.range(-500.0, 500.0),
                    rng.range(-300.0, 100.0),
                );
            let size = DVec3::new(
                rng.range(10.0, 2000.0),
                rng.range(10.0, 2000.0),
                rng.range(1.0, 800.0),
            );
            let (lo, hi) = (centre - size * 0.5, centre + size * 0.5);
            let s = subdivided_bound(&view, lo, hi, SPLIT);
            assert!(
                s <= bound(&view, lo, hi) * (1.0 + 1e-12),
                "subdividing loosened it"
            );
            let sampled = sampled_pixels_per_metre(&view, lo, hi);
            let n = 16;
            for k in 0..(n + 1) * (n + 1) * (n + 1) {
                let f = DVec3::new(
                    f64::from(k % (n + 1)),
                    f64::from(k / (n + 1) % (n + 1)),
                    f64::from(k / ((n + 1) * (n + 1))),
                ) / f64::from(n);
                let p = lo + (hi - lo) * f;
                let Some((u, v)) = view.project(p) else {
                    continue;
                };
                if !(0.0..=640.0).contains(&u) || !(0.0..=480.0).contains(&v) {
                    continue;
                }
                let j = view.pixels_per_vertical_metre(p);
                on_screen += 1;
                assert!(
                    j <= s * (1.0 + 1e-9),
                    "|Jz| {j} above the bound {s} at {p:?} in {lo:?}..{hi:?}"
                );
                worst_bound = worst_bound.max(j / s);
                if sampled.is_finite() {
                    worst_sampled = worst_sampled.max(j / sampled);
                }
            }
        }
        assert!(
            worst_sampled > 1.01,
            "sampling never under-estimated: {worst_sampled}"
        );
        // Not vacuous: many points checked, and somewhere the bound is nearly reached.
        assert!(on_screen > 100_000, "{on_screen} points on screen");
        assert!(
            worst_bound > 0.5,
            "the bound is loose everywhere: {worst_bound}"
        );
    }
}
