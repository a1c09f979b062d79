//! The tile pyramid's grids and its error bound.
//!
//! Layer `p` is the base grid subsampled by `f = 2^p` ([`Decimated`], see the format's "The
//! tile pyramid"): its samples are base samples, so where a layer tile and a base tile share a
//! point they hold the same height. A layer tile's levels are built against the layer's samples
//! like any tile's, so each level `i` is within its measured `e_i` of them. What a layer leaves
//! out is bounded by the tile's *decimation error* `D`:
//!
//! Let `S_p` be layer `p`'s full-lattice surface: the finest restricted-quadtree mesh of its
//! samples, every 2 x 2-cell quad fanned around its centre with all four midpoints. Every
//! level's triangles are unions of `S_p`'s (a fan's edges run along the lattice's axes and
//! through the quads' centres on its diagonals), so `M_i - S_p` is linear on each triangle of
//! `S_p` and largest at layer samples, where `S_p` is exact: `|S_p - M_i| <= e_i`. In turn
//! `S_{p-1}` refines `S_p` (a quad of `S_p` is four of `S_{p-1}`, and its eight triangles are
//! unions of their fans), so `|S_{p-1} - S_p|` is largest at layer `p-1`'s samples. By the
//! triangle inequality, at every base sample `x` of a layer-`p` tile `T`,
//!
//! ```text
//! |h(x) - M_i(x)| <= e_i + D(T),
//! D(T) = max over T's children C of D(C)  +  max over layer p-1 samples v in T of |h(v) - S_p(v)|,
//! ```
//!
//! with `D = 0` in the base grid, where `S_0` passes through every sample. [`decimation_errors`]
//! computes the second term from layer `p-1`'s samples alone, so a layer needs one pass over
//! the one below it, not over the base grid; `tiletool verify` checks the bound directly
//! against the base samples. Errors are, as everywhere in a tile set, measured at samples.
//!
//! `D` is a maximum over the whole tile: one steep spike anywhere makes every level look that
//! much worse, and a coarse level, far from most samples anyway, rarely errs by `e_i + D`. So
//! the builder also measures each level against the base samples directly ([`base_errors`]),
//! with the same fact that makes the bound: a level is linear on each full-lattice triangle, so
//! its height at a base sample is the blend of its heights at the triangle's three lattice
//! points, found once per sample for all levels. That is one pass over the base grid per
//! layer, a tile row of the layer at a time. The renderer goes by these; `D` stays in the file
//! as the bound they must keep, and `verify` checks both.

use std::borrow::Cow;

use rayon::prelude::*;

use crate::build::Heights;
use crate::format::layer_grid;
use crate::grid::Grid;
use crate::mesh::{TILE_CELLS, TILE_SIZE};
use crate::BuildError;

/// The error a pyramid layer's tile is built to at most, as a share of its decimation error
/// `D`: its level `i` is built to `max(e_i, D / 4)` against the layer's samples. Against the
/// base grid even the tile's finest level errs by what the subsampling left out (up to `D`,
/// often near it), so the renderer takes the tile only where that is tolerable; levels built
/// much finer would hold vertices it never draws (on the mirror sets the cut chose the same
/// tiles with and without the floor).
pub const FLOOR_SHARE: f64 = 0.25;

/// The error no level of a layer tile with decimation error `d` is built finer than.
pub fn level_floor(d: f32) -> f64 {
    f64::from(d) * FLOOR_SHARE
}

/// Base samples read at once when a layer reads its rows: about 64 MB of heights.
const READ_SAMPLES: usize = 1 << 24;

/// Layer `p` of a grid: every `2^p`-th sample of `source`, the last row and column clamped
/// into the grid.
pub struct Decimated<'a> {
    source: &'a dyn Heights,
    factor: usize,
    width: usize,
    height: usize,
    spacing: (f64, f64),
    /// The source's size.
    source_size: (usize, usize),
}

impl<'a> Decimated<'a> {
    pub fn new(source: &'a dyn Heights, p: u32) -> Decimated<'a> {
        let shape = source.shape();
        let (width, height, factor) = layer_grid(shape.width, shape.height, p);
        Decimated {
            source,
            factor,
            width,
            height,
            spacing: (
                shape.spacing_x * factor as f64,
                shape.spacing_y * factor as f64,
            ),
            source_size: (shape.width, shape.height),
        }
    }
}

impl Heights for Decimated<'_> {
    fn shape(&self) -> Grid<'_> {
        Grid {
            width: self.width,
            height: self.height,
            first_row: 0,
            heights: &[],
            spacing_x: self.spacing.0,
            spacing_y: self.spacing.1,
        }
    }

    fn rows(&self, y0: usize, y1: usize) -> Result<Cow<'_, [f32]>, BuildError> {
        let (sw, sh) = self.source_size;
        let f = self.factor;
        let source_row = |y: usize| (y * f).min(sh - 1);
        let mut out = Vec::with_capacity((y1 - y0) * self.width);
        // A source whose rows read singly for about their share of a run: only the rows kept.
        // (Read in runs, a layer `p` read `2^p` times the rows it keeps: most of a 16K
        // pyramid build's 25 GB read of a 537 MB input.)
        if f > 1 && self.source.reads_rows_singly() {
            for y in y0..y1 {
                let r = source_row(y);
                let row = self.source.rows(r, r + 1)?;
                out.extend((0..self.width).map(|x| row[(x * f).min(sw - 1)]));
            }
            return Ok(Cow::Owned(out));
        }
        // Source rows in runs of about READ_SAMPLES, each run read once: a source that fills
        // voids or decodes strips per read does so once per run, not once per row.
        let per_read = (READ_SAMPLES / sw).max(1);
        let mut y = y0;
        while y < y1 {
            let first = source_row(y);
            let mut end = y + 1;
            while end < y1 && source_row(end) < first + per_read {
                end += 1;
            }
            let last = source_row(end - 1);
            let rows = self.source.rows(first, last + 1)?;
            for yy in y..end {
                let row = &rows[(source_row(yy) - first) * sw..][..sw];
                out.extend((0..self.width).map(|x| row[(x * f).min(sw - 1)]));
            }
            y = end;
        }
        Ok(Cow::Owned(out))
    }

    /// A tile row a band: a layer's tiles are measured against the base grid's rows under
    /// them a tile row at a time (their surfaces held meanwhile), see [`base_errors`].
    fn band_tile_rows(&self) -> u32 {
        1
    }
}

/// The decimation error of every tile of layer `p >= 1` (row-major): the largest error of its
/// children in layer `p-1` (`below`, row-major over `below_tiles_x` columns) plus the largest
/// `|h - S_p|` over layer `p-1`'s samples in the tile. `finer` is layer `p-1`'s grid. Only the
/// tiles of tile rows `rows` are measured (a shard's; the others are left 0), and only their
/// children's errors in `below` are read.
pub fn decimation_errors(
    finer: &dyn Heights,
    below: &[f32],
    below_tiles_x: u32,
    tiles: (u32, u32),
    rows: std::ops::Range<u32>,
) -> Result<Vec<f32>, BuildError> {
    let shape = finer.shape();
    let (w, h) = (shape.width, shape.height);
    let cells = TILE_CELLS as usize;
    let below_tiles_y = below.len() as u32 / below_tiles_x.max(1);
    let mut out = vec![0.0f32; (tiles.0 * tiles.1) as usize];
    for ty in rows.start..rows.end.min(tiles.1) {
        // The tile row's samples of layer p-1: 2 * 256 rows from 2 * 256 * ty, and the layer-p
        // quads' far rows, clamped into the grid.
        let y0 = (2 * cells * ty as usize).min(h - 1);
        let y_end = (y0 + 2 * cells + 4).min(h);
        let rows = finer.rows(y0, y_end)?;
        let height = |x: usize, y: usize| rows[(y.min(h - 1) - y0) * w + x.min(w - 1)];
        let last_v = (y0 + 2 * cells).min(h - 1);
        let row_errors: Vec<f32> = (0..tiles.0)
            .into_par_iter()
            .map(|tx| {
                let x0 = (2 * cells * tx as usize).min(w - 1);
                let last_u = (x0 + 2 * cells).min(w - 1);
                // The layer-p tile's lattice point `i`: layer p-1's sample at twice it.
                let at = |i: usize| {
                    f64::from(height(x0 + 2 * (i % TILE_SIZE), y0 + 2 * (i / TILE_SIZE)))
                };
                let whole = (TILE_CELLS, TILE_CELLS);
                let mut worst = 0.0f32;
                for v in y0..=last_v {
                    for u in x0..=last_u {
                        let (a, b) = ((u - x0) as f64 / 2.0, (v - y0) as f64 / 2.0);
                        let [(i, wi), (j, wj), (k, wk)] = corners(a, b, whole);
                        let s = (wi * at(i) + wj * at(j) + wk * at(k)) as f32;
                        worst = worst.max((height(u, v) - s).abs());
                    }
                }
                let children = (0..4)
                    .map(|k| (2 * tx + k % 2, 2 * ty + k / 2))
                    .filter(|&(cx, cy)| cx < below_tiles_x && cy < below_tiles_y)
                    .map(|(cx, cy)| below[(cy * below_tiles_x + cx) as usize])
                    .fold(0.0f32, f32::max);
                // Rounded up a step so that the stored figure is never below the sum.
                let d = children + worst;
                if d > 0.0 {
                    d.next_up()
                } else {
                    d
                }
            })
            .collect();
        out[(ty * tiles.0) as usize..][..tiles.0 as usize].copy_from_slice(&row_errors);
    }
    Ok(out)
}

/// One tile of a layer row whose levels [`base_errors`] measures: its column, its levels'
/// surfaces ([`crate::build::BuiltTile::surfaces`]) and its last real column and row.
pub struct Surfaces<'a> {
    pub tx: u32,
    pub surfaces: &'a [f32],
    pub data_max: (u32, u32),
}

/// Each level's largest distance from the base grid's samples under each tile of tile row `ty`
/// of layer `p` (metres, rounded up to f32), read from `base` a run of rows at a time. A level's
/// surface is linear on each triangle of the layer's full lattice (every level's triangles are
/// unions of them), so its height at a base sample is the blend of its heights at the corners
/// of the full-lattice triangle around the sample: the same three corners and weights for every
/// level.
pub fn base_errors(
    base: &dyn Heights,
    p: u32,
    ty: u32,
    levels: usize,
    tiles: &[Surfaces],
) -> Result<Vec<Vec<f32>>, BuildError> {
    let shape = base.shape();
    let (w, h) = (shape.width, shape.height);
    let f = 1usize << p;
    let span = TILE_CELLS as usize * f;
    let y0 = (ty as usize * span).min(h - 1);
    let y_last = (y0 + span).min(h - 1);
    let mut worst = vec![vec![0.0f64; levels]; tiles.len()];
    let per_read = (READ_SAMPLES / w).max(1);
    let mut y = y0;
    while y <= y_last {
        let end = (y + per_read).min(y_last + 1);
        let rows = base.rows(y, end)?;
        // In runs of rows, each over every tile of the row, the runs in parallel: the top
        // layers' rows hold one or two tiles, over all of the base's samples, and taken a tile
        // to a core they left the other cores idle. A maximum is the same in any order.
        let runs: Vec<usize> = (y..end).step_by(ROWS_A_RUN).collect();
        let none = || vec![vec![0.0f64; levels]; tiles.len()];
        let band = runs
            .par_iter()
            .map(|&from| {
                let mut run = none();
                for (worst, t) in run.iter_mut().zip(tiles) {
                    for yy in from..(from + ROWS_A_RUN).min(end) {
                        let row = &rows[(yy - y) * w..][..w];
                        row_errors(worst, t, row, yy - y0, f, w, levels);
                    }
                }
                run
            })
            .reduce(none, |mut a, b| {
                fold_max(&mut a, &b);
                a
            });
        fold_max(&mut worst, &band);
        y = end;
    }
    Ok(worst
        .into_iter()
        .map(|w| w.into_iter().map(round_up).collect())
        .collect())
}

/// Base rows a task of [`base_errors`] measures.
const ROWS_A_RUN: usize = 16;

/// Raises each tile's and level's figure in `into` to `from`'s where that is larger.
fn fold_max(into: &mut [Vec<f64>], from: &[Vec<f64>]) {
    for (a, b) in into.iter_mut().zip(from) {
        for (a, &b) in a.iter_mut().zip(b) {
            *a = a.max(b);
        }
    }
}

/// [`base_errors`] of tile `t`'s levels over base row `row`, `dy` rows below the tile row's
/// first, into `worst`: `f` base samples to a layer sample, `w` samples to a base row.
fn row_errors(
    worst: &mut [f64],
    t: &Surfaces,
    row: &[f32],
    dy: usize,
    f: usize,
    w: usize,
    levels: usize,
) {
    let x0 = t.tx as usize * TILE_CELLS as usize * f;
    let x_last = (x0 + t.data_max.0 as usize * f).min(w - 1);
    let lattice_max = (t.data_max.0.div_ceil(2) * 2, t.data_max.1.div_ceil(2) * 2);
    let b = dy as f64 / f as f64;
    for (xx, &z) in row.iter().enumerate().take(x_last + 1).skip(x0) {
        let a = (xx - x0) as f64 / f as f64;
        let [(i, wi), (j, wj), (k, wk)] = corners(a, b, lattice_max);
        let (si, sj, sk) = (
            &t.surfaces[i * levels..][..levels],
            &t.surfaces[j * levels..][..levels],
            &t.surfaces[k * levels..][..levels],
        );
        for l in 0..levels {
            let m = wi * f64::from(si[l]) + wj * f64::from(sj[l]) + wk * f64::from(sk[l]);
            worst[l] = worst[l].max((f64::from(z) - m).abs());
        }
    }
}

/// The smallest f32 at or above `v`.
fn round_up(v: f64) -> f32 {
    let r = v as f32;
    if f64::from(r) < v {
        r.next_up()
    } else {
        r
    }
}

/// The full-lattice triangle around the point `(a, b)` of a tile (lattice units), as three
/// lattice points (index `y * 257 + x`) and their weights: the octant of the 2 x 2-cell quad
/// around it, fanned from the quad's centre. `lattice_max` is the mesh's last column and row.
/// Both the decimation error (layer `p-1`'s samples, at half steps) and the errors against
/// the base grid (at `1 / 2^p` steps) interpolate through it.
fn corners(a: f64, b: f64, (max_x, max_y): (u32, u32)) -> [(usize, f64); 3] {
    let quad = |v: f64, max: u32| ((v / 2.0).floor() * 2.0).clamp(0.0, f64::from(max.max(2) - 2));
    let (cx, cy) = (quad(a, max_x) + 1.0, quad(b, max_y) + 1.0);
    let (s, t) = (a - cx, b - cy);
    let (sx, sy) = (
        if s < 0.0 { -1.0 } else { 1.0 },
        if t < 0.0 { -1.0 } else { 1.0 },
    );
    let (u, v) = (s.abs().min(1.0), t.abs().min(1.0));
    let at = |x: f64, y: f64| y as usize * TILE_SIZE + x as usize;
    if u >= v {
        [
            (at(cx, cy), 1.0 - u),
            (at(cx + sx, cy), u - v),
            (at(cx + sx, cy + sy), v),
        ]
    } else {
        [
            (at(cx, cy), 1.0 - v),
            (at(cx, cy + sy), v - u),
            (at(cx + sx, cy + sy), u),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid held whole, as `Heights`.
    fn grid(width: usize, height: usize, f: impl Fn(usize, usize) -> f32) -> Vec<f32> {
        (0..height)
            .flat_map(|y| (0..width).map(move |x| (x, y)))
            .map(|(x, y)| f(x, y))
            .collect()
    }

    #[test]
    fn a_layer_is_every_other_sample_with_the_edge_clamped() {
        let heights = grid(6, 5, |x, y| (10 * y + x) as f32);
        let g = Grid {
            width: 6,
            height: 5,
            first_row: 0,
            heights: &heights,
            spacing_x: 30.0,
            spacing_y: 20.0,
        };
        let layer = Decimated::new(&g, 1);
        let shape = layer.shape();
        assert_eq!((shape.width, shape.height), (4, 3));
        assert_eq!((shape.spacing_x, shape.spacing_y), (60.0, 40.0));
        let rows = layer.rows(0, 3).unwrap();
        // Columns 0, 2, 4 and the last (5) clamped in; rows 0, 2, 4.
        assert_eq!(
            &rows[..],
            &[0., 2., 4., 5., 20., 22., 24., 25., 40., 42., 44., 45.]
        );
        let two = Decimated::new(&g, 2);
        assert_eq!(&two.rows(1, 2).unwrap()[..], &[40., 44., 45.]);
    }

    #[test]
    fn a_plane_decimates_without_error_and_a_bump_does_not() {
        // A plane: S_p reproduces it exactly.
        let n = 2 * 256 + 1;
        let plane = grid(n, n, |x, y| 3.0 + 0.5 * x as f32 - 0.25 * y as f32);
        let g = Grid {
            width: n,
            height: n,
            first_row: 0,
            heights: &plane,
            spacing_x: 1.0,
            spacing_y: 1.0,
        };
        let d = decimation_errors(&g, &[0.0; 4], 2, (1, 1), 0..1).unwrap();
        assert!(d[0] < 1e-3, "{d:?}");
        // The control: one odd sample raised 7 m is 7 m off S_p (its neighbours are even or
        // their fans do not reach it), and a child's error adds on.
        let mut bump = plane.clone();
        bump[101 * n + 203] += 7.0;
        let g = Grid {
            heights: &bump,
            ..g
        };
        let d = decimation_errors(&g, &[0.0, 0.5, 0.0, 0.25], 2, (1, 1), 0..1).unwrap();
        assert!((d[0] - 7.5).abs() < 1e-3, "{d:?}");
    }

    #[test]
    fn the_fan_interpolates_inside_its_octants() {
        // Heights of a layer-p quad from (0,0) to (2,2), lattice points by index y * 257 + x.
        let h = |i: usize| match (i % TILE_SIZE, i / TILE_SIZE) {
            (1, 1) => 8.0,
            (2, 1) => 4.0,
            (2, 2) => 0.0,
            _ => 2.0,
        };
        let at = |a: f64, b: f64| {
            corners(a, b, (2, 2))
                .iter()
                .map(|&(i, w)| w * h(i))
                .sum::<f64>()
        };
        // On the centre-to-midpoint edge, halfway: (8 + 4) / 2.
        assert_eq!(at(1.5, 1.0), 6.0);
        // On the diagonal to the corner (2,2), halfway: (8 + 0) / 2.
        assert_eq!(at(1.5, 1.5), 4.0);
        // On the quad's side between the midpoint (2,1) and the corner (2,2).
        assert_eq!(at(2.0, 1.5), 2.0);
        // Lattice points are themselves.
        assert_eq!(at(1.0, 1.0), 8.0);
        assert_eq!(at(0.0, 0.0), 2.0);
    }
}
