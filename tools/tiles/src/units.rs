//! The morph units of a set with shared sides, from the input's scan alone.
//!
//! A level's morph offsets are stored in its unit, `max(bound, widest) / 127` metres a step,
//! `widest` being the largest distance of a finer vertex from the level's surface in any tile
//! ([`crate::pack::morph_unit`]). The unit is the set's, not the tile's, so that a vertex of a
//! shared side gets the same bytes from both its tiles. Taken over the tiles' deviations
//! alone, the unit depended on every tile: a shard of a distributed build saw only its own,
//! and the merge sealed every tile of a part whose units were smaller again, a whole assembly
//! each (most tiles of real terrain, whose roughest tiles sit in one band).
//!
//! So `bound` is a bound on `widest` that every shard computes alike from the scan of the
//! input, which is already global ([`crate::shard`]). A finer vertex `v` of level `k` lies in
//! a leaf cell of the level's mesh, whose fan is linear between the cell's own samples, all
//! in the cell's closure (its samples, sides included). The mesher refines a leaf while one of
//! its triangles errs by more than `e_k` against the source at the samples inside it, with the
//! quantised vertex heights ([`crate::mesh`]), unless the spacing rule forbids it; and so it
//! does for the points of a padded column or row (a tile at the grid's edge whose data end on
//! an odd column is meshed one column further, that column a copy of the last), which are not
//! data and are never stored as an error, but whose vertices a finer level adds like any. So:
//!
//! - where the leaf was refined as far as `e_k` asks, `|S_k(v) - h(v)| <= e_k`, and against
//!   `v`'s quantised height, which the deviation is measured with, half a lattice step more
//!   (and the surface's rounding to `f32`, well within another step);
//! - where the spacing rule stopped it, both `S_k(v)` (a blend of quantised heights in the
//!   closure) and `v`'s quantised height lie within the closure's range of heights widened by
//!   half a step each side. Such a leaf is at most [`blocked_cell`] samples wide: a split is
//!   forbidden only below `4 e_k / spacing`. Leaves are aligned cells of the tile's quadtree,
//!   and tiles start on multiples of 256 samples, so its closure lies in the closure of an
//!   aligned cell of that size: the scan's [`CellSpans`] hold the largest range over those.
//!
//! Hence `bound_k = max(e_k, span_k) + 2 step`, with `span_k = 0` where the spacing rule
//! stops nothing (`spacing >= e_k`). So the agreement's meshes of the base grid, which
//! rasterised every level's surface only to find the deviations, need none (15% of a build of
//! the 4K mirror set). Each tile's final build still finds its deviations: were one past its
//! bound, the units would rise to it, and the set stays correct: an unsharded build is built
//! again at the raised bounds, and a sharded one's merge seals every tile again (test
//! `tiles_past_their_bounds_raise_the_units`).
//!
//! A pyramid layer's tile is built no finer than its floor, a share of its decimation error
//! ([`crate::pyramid::level_floor`]): its level `k` refines as far as `e'_k = max(e_k,
//! floor)` asks, and the floor follows the tile's data. Taken over the deviations, a layer's
//! units were a shard's own tiles', and the merge sealed again most layer tiles of a
//! distributed build (768 of the 1,365 of the 16K mirror set in 4 shards; at a hundred shards
//! it would seal nearly all of them, on one node). So a layer's floor is bounded from the
//! scans too ([`decimation_bound`]). A layer tile's decimation error is its children's plus
//! how far a sample of the layer below lies from the layer's lattice blended over it; that
//! blend and that sample both lie in the closure of the aligned cell of 2 samples of the layer
//! below that holds the sample, so the distance is at most that layer's span of size 2, and
//! the error at most their sum over the layers below. With `e'_k` from that bound the argument
//! above holds in the layer's own samples, its spans from the layer's own scan
//! ([`layer_deviation_bounds`]). As in the base grid, a tile past its bound raises the units
//! (a layer's are taken with its agreement's deviations, the same meshes as its tiles'), and
//! the set stays correct.

use rayon::prelude::*;

use crate::build::{spacing_of, BuildParams, Heights, Scanned};
use crate::grid::Grid;
use crate::mesh::TILE_CELLS;
use crate::pyramid::FLOOR_SHARE;

/// Aligned cell sizes the scan measures: 2, 4, ..., 256 samples.
pub const CELL_SIZES: usize = 8;

/// Per cell size `2^(i + 1)` samples, the largest range of heights (metres) over the closure of
/// any cell of that size aligned to the tiles' quadtrees. 0 where no sample was seen.
pub type CellSpans = [f32; CELL_SIZES];

/// The cell spans of the tiles of tile rows `rows` (which `grid` holds), `tiles_x` wide, and
/// their largest absolute height: with the largest span (a whole tile's closure, its range of
/// heights) what the height lattice's step needs ([`crate::build::tile_ranges`]).
pub fn cell_spans(grid: &Grid, tiles_x: u32, rows: std::ops::Range<u32>) -> (CellSpans, f32) {
    let tiles: Vec<(u32, u32)> = rows
        .flat_map(|ty| (0..tiles_x).map(move |tx| (tx, ty)))
        .collect();
    tiles.par_iter().map(|&t| tile_spans(grid, t)).reduce(
        || (CellSpans::default(), 0.0),
        |(a, x), (b, y)| (std::array::from_fn(|i| a[i].max(b[i])), x.max(y)),
    )
}

/// One tile's cell spans: the closures of its cells of size 2 first, row by row (a row's
/// least and largest height over each cell's three columns, then over the cell's three
/// rows), then each size from the four cells of half its size, whose closures make its own;
/// and the tile's largest absolute height.
fn tile_spans(grid: &Grid, (tx, ty): (u32, u32)) -> (CellSpans, f32) {
    let cells = TILE_CELLS as usize;
    let n = cells / 2;
    let (x0, y0) = (tx as usize * cells, ty as usize * cells);
    let (x1, y1) = (
        (x0 + cells).min(grid.width - 1),
        (y0 + cells).min(grid.height - 1),
    );
    // Cells of size 2 that hold data: columns `0..ni` and rows `0..nj`.
    let (ni, nj) = ((x1 - x0).div_ceil(2), (y1 - y0).div_ceil(2));
    let mut lo = vec![f32::INFINITY; n * n];
    let mut hi = vec![f32::NEG_INFINITY; n * n];
    let (mut row_lo, mut row_hi) = (vec![0.0f32; n], vec![0.0f32; n]);
    for y in y0..=y1 {
        let row = &grid.row(y)[x0..=x1];
        for i in 0..ni {
            let closure = &row[2 * i..(2 * i + 3).min(row.len())];
            row_lo[i] = closure.iter().copied().fold(f32::INFINITY, f32::min);
            row_hi[i] = closure.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        }
        let r = y - y0;
        // The cell below the row, and on an even row the cell above it too.
        let below = (r / 2 < nj).then_some(r / 2);
        let above = (r % 2 == 0 && r > 0).then(|| r / 2 - 1);
        for j in [below, above].into_iter().flatten() {
            let (l, h) = (&mut lo[j * n..j * n + ni], &mut hi[j * n..j * n + ni]);
            for i in 0..ni {
                l[i] = l[i].min(row_lo[i]);
                h[i] = h[i].max(row_hi[i]);
            }
        }
    }
    let mut spans = CellSpans::default();
    let mut n = n;
    for span in spans.iter_mut() {
        for c in 0..n * n {
            if lo[c] <= hi[c] {
                *span = span.max(hi[c] - lo[c]);
            }
        }
        if n == 1 {
            break;
        }
        let half = n / 2;
        for j in 0..half {
            for i in 0..half {
                let kids = [
                    2 * j * n + 2 * i,
                    2 * j * n + 2 * i + 1,
                    (2 * j + 1) * n + 2 * i,
                    (2 * j + 1) * n + 2 * i + 1,
                ];
                lo[j * half + i] = kids.iter().map(|&k| lo[k]).fold(f32::INFINITY, f32::min);
                hi[j * half + i] = kids
                    .iter()
                    .map(|&k| hi[k])
                    .fold(f32::NEG_INFINITY, f32::max);
            }
        }
        n = half;
    }
    // The last cell is the whole tile.
    (spans, lo[0].abs().max(hi[0].abs()))
}

/// The largest aligned cell (samples) that the mesher's spacing rule may leave unrefined with
/// triangles over `e` metres, at a grid spacing of `spacing` metres (the smaller of the two):
/// 0 where it leaves none. Mirrors `Mesher::may_activate` and `Mesher::may_split`: a cell of
/// size 2 is fanned in full unless `spacing < e`; one of size `s >= 4` is split unless
/// `(s / 4) spacing < e`.
pub fn blocked_cell(e: f64, spacing: f64) -> u32 {
    if spacing >= e {
        return 0;
    }
    let mut s = 2;
    while s < TILE_CELLS && f64::from(s * 2 / 4) * spacing < e {
        s *= 2;
    }
    s
}

/// Per level, a bound on the distance of any finer vertex from the level's surface in any base
/// tile (see the module's doc): the floor of the set's morph units.
pub fn deviation_bounds(
    params: &BuildParams,
    spacing: f64,
    step: f32,
    spans: &CellSpans,
) -> Vec<f64> {
    bounds_over_floor(params, spacing, step, spans, 0.0)
}

/// [`deviation_bounds`] for a pyramid layer: `spacing`, `step` and `spans` are the layer's own
/// (its samples `2^p` base samples apart, its scan's), `decimation` a bound on every one of
/// its tiles' decimation errors ([`decimation_bound`]), whose share is the floor no level is
/// built finer than.
pub fn layer_deviation_bounds(
    params: &BuildParams,
    spacing: f64,
    step: f32,
    spans: &CellSpans,
    decimation: f64,
) -> Vec<f64> {
    bounds_over_floor(params, spacing, step, spans, decimation * FLOOR_SHARE)
}

/// Per level `k`, `max(e', span) + 2 step` with `e' = max(e_k, floor)`, the error the level is
/// refined to, and `span` the span of the largest cell the spacing rule may leave over `e'`.
fn bounds_over_floor(
    params: &BuildParams,
    spacing: f64,
    step: f32,
    spans: &CellSpans,
    floor: f64,
) -> Vec<f64> {
    (0..params.levels)
        .map(|k| {
            let e = params.level_error(k).max(floor);
            let span = match blocked_cell(e, spacing) {
                0 => 0.0,
                s => f64::from(spans[s.trailing_zeros() as usize - 1]),
            };
            e.max(span) + 2.0 * f64::from(step)
        })
        .collect()
}

/// A bound on the decimation error of every tile of the layer above those whose scans found
/// `size_two_spans` (each layer's span over cells of 2 samples, `spans[0]`, the base grid's
/// first): their sum (see the module's doc), widened for the rounding of each layer's figure
/// (measured in `f32` from blends taken in `f64`, then rounded up a step) at heights of up to
/// `max_abs` metres.
pub fn decimation_bound(size_two_spans: &[f32], max_abs: f32) -> f64 {
    let sum: f64 = size_two_spans.iter().map(|&s| f64::from(s)).sum();
    let layers = size_two_spans.len() as f64;
    sum * (1.0 + 1e-5) + layers * 1e-5 * (f64::from(max_abs) + sum)
}

/// A pyramid's layers' bounds, bottom up ([`layer_deviation_bounds`]): each layer's from its
/// own scan and the spans of size 2 of the layers below it, the base grid's first
/// ([`decimation_bound`]). The build and every shard take them so, alike.
pub(crate) struct LayerBounds {
    size_two_spans: Vec<f32>,
    max_abs: f32,
}

impl LayerBounds {
    /// Above a base grid whose scan found `base`.
    pub(crate) fn above(base: &Scanned) -> LayerBounds {
        LayerBounds {
            size_two_spans: vec![base.spans[0]],
            max_abs: base.max_abs,
        }
    }

    /// The bounds of the next layer up, whose heights are `layer` and whose scan found
    /// `scanned`.
    pub(crate) fn next(
        &mut self,
        params: &BuildParams,
        layer: &dyn Heights,
        scanned: &Scanned,
    ) -> Vec<f64> {
        let decimation = decimation_bound(&self.size_two_spans, self.max_abs);
        let bounds = layer_deviation_bounds(
            params,
            spacing_of(layer),
            scanned.step,
            &scanned.spans,
            decimation,
        );
        self.size_two_spans.push(scanned.spans[0]);
        bounds
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The spans are, size by size, the largest range over every aligned cell's closure
    /// clipped to the grid, found one cell at a time: on a grid of 2 x 2 tiles whose second
    /// column and row of tiles hold 43 and 50 samples (odd and even ends), with heights that
    /// vary at every scale, the second row of tiles the roughest.
    #[test]
    fn cell_spans_are_the_ranges_of_every_cells_closure() {
        let (w, h) = (300, 307);
        let heights: Vec<f32> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let rough = if y > 256.0 {
                    (x * 1.3).sin() * 700.0
                } else {
                    0.0
                };
                (x * 0.37).sin() * 40.0
                    + (y * 0.011).cos() * 900.0
                    + ((i * 7919) % 97) as f32
                    + rough
            })
            .collect();
        let grid = Grid {
            width: w,
            height: h,
            first_row: 0,
            heights: &heights,
            spacing_x: 30.0,
            spacing_y: 30.0,
        };
        let mut want = CellSpans::default();
        for (k, span) in want.iter_mut().enumerate() {
            let s = 2usize << k;
            for y0 in (0..h - 1).step_by(s) {
                for x0 in (0..w - 1).step_by(s) {
                    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
                    for y in y0..=(y0 + s).min(h - 1) {
                        for x in x0..=(x0 + s).min(w - 1) {
                            lo = lo.min(heights[y * w + x]);
                            hi = hi.max(heights[y * w + x]);
                        }
                    }
                    *span = span.max(hi - lo);
                }
            }
        }
        let abs = heights.iter().fold(0.0f32, |m, h| m.max(h.abs()));
        assert_eq!(cell_spans(&grid, 2, 0..2), (want, abs));
        // The control: the first tile row alone misses the second's rougher cells.
        assert_ne!(cell_spans(&grid, 2, 0..1).0, want);
    }

    /// The cell the spacing rule can leave over `e`: none at a spacing of `e` or more; a
    /// finest cell just below it; and up to the largest cell whose quarter is closer than `e`.
    #[test]
    fn the_blocked_cell_follows_the_spacing_rule() {
        assert_eq!(blocked_cell(32.0, 40.0), 0);
        assert_eq!(blocked_cell(40.0, 40.0), 0);
        assert_eq!(blocked_cell(64.0, 40.0), 4);
        assert_eq!(blocked_cell(256.0, 160.0), 4);
        assert_eq!(blocked_cell(256.0, 40.0), 16);
        assert_eq!(blocked_cell(1e9, 1.0), 256);
    }
}
