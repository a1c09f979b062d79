//! `vkterrain --measure-error`: the screen-space error and the pops a flight actually shows,
//! measured on the CPU against the source DEM.
//!
//! Each drawn tile is rasterised into a grid of the heights its triangles give at the tile's
//! source samples (interpolated in each triangle, as the rasteriser does), with its vertices
//! geomorphed as the vertex shader does ([`crate::morph`], the shader's CPU mirror) when the
//! frame morphs. Unmorphed levels are rasterised once and kept.
//! - `max_error_px`: for every sample of every drawn tile, the drawn surface point and the
//!   source sample are projected with the frame's camera; their distance on the image is that
//!   sample's error. The frame's value is the largest.
//! - `pop_px`: at every base sample drawn in this frame and the previous one by a different
//!   tile or LOD state (level, or the camera its vertices took their levels from when
//!   morphing), the surface point as the previous frame drew it and as this one does, both
//!   projected with the *current* camera (so camera motion is factored out): the largest
//!   distance is the frame's pop. Ground newly in view has no previous surface: no pop.
//!
//! Samples where either point is behind the near plane or off the image are skipped (nothing
//! is seen there).
//!
//! Over a pyramid's cut (`--pyramid`), a tile of layer `p` is rasterised at the base grid's
//! samples under it (its vertex `(x, y)` at `(x, y) << p` base samples from its corner) and
//! measured against every one of them, as the cut promises ([`crate::cut`]): so a layer tile's
//! surface is a grid of `(256 << p) + 1` samples a side, and the meter measures pyramids of at
//! most [`MAX_LAYER`] layers. Pops are measured on the ground, so where children replace their
//! parent (or the reverse) the jump between the two tiles' surfaces counts.

use std::collections::HashMap;

use rayon::prelude::*;

use glam::DVec3;
use tiles::grid::tile_samples;
use tiles::mesh::{TILE_CELLS, TILE_SIZE};
use tiles::verify::raster_barycentric;
use tiles::Grid;

use crate::camera::Camera;
use crate::frame::{DrawnTile, ReadBack};
use crate::morph;
use crate::terrain::Terrain;

/// The highest pyramid layer the meter measures: a layer-4 tile's surface is 4097² samples
/// (67 MB a level kept).
pub const MAX_LAYER: u32 = 4;

/// The measures of one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measured {
    pub max_error_px: f64,
    /// NaN on the first measured frame (nothing to compare with).
    pub pop_px: f64,
}

/// The source samples of every tile, the height grids of the levels drawn so far, and the
/// levels of the previous measured frame.
pub struct ErrorMeter {
    /// Per base tile, 257 x 257 source heights (row 0 north), and the last real column / row.
    samples: Vec<(Vec<f32>, u32, u32)>,
    /// Per (tile, level), unmorphed: the drawn surface's height at each sample (NaN where no
    /// triangle covers it).
    surfaces: HashMap<(usize, u32), Vec<f32>>,
    /// The previous measured frame's state of each tile, and its surface when morphed.
    previous: Option<HashMap<usize, Drawn>>,
    /// The previous measured frame's tile over each base tile it drew.
    previous_cover: HashMap<usize, usize>,
}

/// A tile's state in a measured frame, and its surface when morphed (not cached).
type Drawn = (State, Option<Vec<f32>>);

/// What a tile's drawn surface depends on: its level, and how it morphs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct State {
    pub level: u32,
    pub morph: Option<morph::TileMorph>,
    /// Drawn part by part at these levels ([`crate::parts`]); None: at `level` throughout.
    pub parts: Option<tiles::parts::PartKey>,
}

impl ErrorMeter {
    /// Cuts `grid` into the tile set's base tiles; the grid must be the one the set was built
    /// from (same size), and the terrain's pyramid at most [`MAX_LAYER`] layers high.
    pub fn new(terrain: &Terrain, grid: &Grid) -> Result<ErrorMeter, String> {
        let h = terrain.set.header();
        if (grid.width, grid.height) != (h.grid_width as usize, h.grid_height as usize) {
            return Err(format!(
                "the source is {}x{} samples, the tile set was built from {}x{}",
                grid.width, grid.height, h.grid_width, h.grid_height
            ));
        }
        if terrain.top() > MAX_LAYER {
            return Err(format!(
                "the error meter measures pyramids of at most {MAX_LAYER} layers above the \
                 base grid; this one has {}",
                terrain.top()
            ));
        }
        let samples = terrain
            .base()
            .map(|t| {
                let s = tile_samples(grid, t.tx, t.ty);
                (s.heights, s.data_max_x, s.data_max_y)
            })
            .collect();
        Ok(ErrorMeter {
            samples,
            surfaces: HashMap::new(),
            previous: None,
            previous_cover: HashMap::new(),
        })
    }

    /// [`ErrorMeter::frame`] for the draws as the frame loop wrote them.
    pub fn frame_drawn(
        &mut self,
        terrain: &Terrain,
        camera: &Camera,
        extent: (u32, u32),
        drawn: &[DrawnTile],
    ) -> Measured {
        let draws: Vec<(usize, State)> = drawn
            .iter()
            .map(|&(tile, level, _, morph, parts)| {
                (
                    tile,
                    State {
                        level,
                        morph,
                        parts,
                    },
                )
            })
            .collect();
        self.frame(terrain, camera, extent, &draws)
    }

    /// Rasterises and keeps the unmorphed (tile, level) surfaces of `needed` not kept yet, in
    /// parallel.
    fn rasterise(&mut self, terrain: &Terrain, needed: impl Iterator<Item = (usize, u32)>) {
        let mut needed: Vec<(usize, u32)> =
            needed.filter(|k| !self.surfaces.contains_key(k)).collect();
        needed.sort_unstable();
        needed.dedup();
        let made: Vec<_> = needed
            .into_par_iter()
            .map(|(tile, level)| {
                let state = State {
                    level,
                    morph: None,
                    parts: None,
                };
                ((tile, level), surface(terrain, tile, state))
            })
            .collect();
        self.surfaces.extend(made);
    }

    /// Measures a frame that drew `draws` (tile, state) seen by `camera` at `extent`; the
    /// previous call's draws are the previous frame's (call it on consecutive frames for
    /// `pop_px` to mean what it says). Tiles are measured in parallel: the frame's value is
    /// the largest of theirs, whatever the order.
    pub fn frame(
        &mut self,
        terrain: &Terrain,
        camera: &Camera,
        extent: (u32, u32),
        draws: &[(usize, State)],
    ) -> Measured {
        let had_previous = self.previous.is_some();
        let previous = self.previous.take().unwrap_or_default();
        let cover = std::mem::take(&mut self.previous_cover);
        let unmorphed = |s: &State| s.morph.is_none() && s.parts.is_none();
        // Unmorphed levels are rasterised once and kept (the previous frame's are already).
        let needed = draws
            .iter()
            .filter(|(_, s)| unmorphed(s))
            .map(|&(tile, s)| (tile, s.level));
        self.rasterise(terrain, needed);
        let (surfaces, samples) = (&self.surfaces, &self.samples);
        // What the previous frame drew over base tile `b`, where it was another tile or another
        // state than `(tile, state)`: that tile's surface and where it lies.
        let before = |b: usize, tile: usize, state: State| {
            let &was = cover.get(&b)?;
            let (s, grid) = previous.get(&was)?;
            if was == tile && *s == state {
                return None;
            }
            let grid = if unmorphed(s) {
                surfaces.get(&(was, s.level))?
            } else {
                grid.as_ref()?
            };
            Some((grid.as_slice(), footprint(terrain, was)))
        };
        let sight = Sight {
            view: camera.view(extent.0, extent.1),
            eye: camera.position,
        };
        let measured: Vec<(usize, Drawn, f64, f64)> = draws
            .par_iter()
            .map(|&(tile, state)| {
                let morphed_now = (!unmorphed(&state)).then(|| surface(terrain, tile, state));
                let now = morphed_now
                    .as_ref()
                    .unwrap_or_else(|| &surfaces[&(tile, state.level)]);
                let then = |b: usize| before(b, tile, state);
                let (error, pop) = compare(terrain, tile, samples, now, &then, &sight);
                (tile, (state, morphed_now), error, pop)
            })
            .collect();
        let mut current = HashMap::new();
        let (mut error, mut pop) = (0.0f64, 0.0f64);
        for (tile, drawn, e, p) in measured {
            error = error.max(e);
            pop = pop.max(p);
            let (columns, rows) = terrain.base_tiles_under(tile);
            for by in rows {
                for bx in columns.clone() {
                    self.previous_cover
                        .insert((by * terrain.tiles_x + bx) as usize, tile);
                }
            }
            current.insert(tile, drawn);
        }
        self.previous = Some(current);
        Measured {
            max_error_px: error,
            pop_px: if had_previous { pop } else { f64::NAN },
        }
    }
}

/// Where a frame's camera shows points on its image.
struct Sight {
    view: crate::camera::View,
    eye: DVec3,
}

impl Sight {
    /// The points above and below world `(x, y)`, in pixels where they are on the image: a
    /// sample's drawn, true and previous heights share the horizontal part of the projection.
    fn vertical(&self, x: f64, y: f64) -> impl Fn(f32) -> Option<(f64, f64)> + '_ {
        let line = self.view.vertical(x - self.eye.x, y - self.eye.y);
        let (w, h) = (f64::from(self.view.width), f64::from(self.view.height));
        move |z| {
            line.project(f64::from(z) - self.eye.z)
                .filter(|&(u, v)| (0.0..=w).contains(&u) && (0.0..=h).contains(&v))
        }
    }
}

/// What the previous frame drew over a base tile, where it differs: a tile's surface and its
/// [`footprint`].
type Before<'a> = Option<(&'a [f32], (u32, u32, usize))>;

/// The largest distance on the image (pixels) between where `now` draws the base samples under
/// the tile and where the source has them (the error), and where the previous frame drew them
/// (the pop: `then` of each base tile's index); samples off the image, or not drawn, count for
/// neither.
fn compare<'a>(
    terrain: &Terrain,
    tile: usize,
    samples: &[(Vec<f32>, u32, u32)],
    now: &[f32],
    then: &impl Fn(usize) -> Before<'a>,
    sight: &Sight,
) -> (f64, f64) {
    let (c0, r0, side) = footprint(terrain, tile);
    let (sx, sy) = terrain.spacing;
    let distance =
        |a: (f64, f64), b: (f64, f64)| ((a.0 - b.0).powi(2) + (a.1 - b.1).powi(2)).sqrt();
    let (mut error, mut pop) = (0.0f64, 0.0f64);
    let (columns, rows) = terrain.base_tiles_under(tile);
    for by in rows {
        for bx in columns.clone() {
            let b = (by * terrain.tiles_x + bx) as usize;
            let (source, max_x, max_y) = &samples[b];
            // The base tile's first sample, in the base grid and in the tile's surface.
            let (bc, br) = (bx * TILE_CELLS, by * TILE_CELLS);
            let (ox, oy) = ((bc - c0) as usize, (br - r0) as usize);
            // And in the surface the previous frame drew there.
            let was = then(b)
                .map(|(grid, (pc, pr, side))| (grid, (bc - pc) as usize, (br - pr) as usize, side));
            for y in 0..=*max_y as usize {
                for x in 0..=*max_x as usize {
                    let k = (oy + y) * side + ox + x;
                    let z = now[k];
                    if z.is_nan() {
                        continue;
                    }
                    let at = sight.vertical(
                        (f64::from(bc) + x as f64) * sx,
                        -(f64::from(br) + y as f64) * sy,
                    );
                    let Some(drawn) = at(z) else { continue };
                    if let Some(truth) = at(source[y * TILE_SIZE + x]) {
                        error = error.max(distance(drawn, truth));
                    }
                    let old = was.map(|(grid, px, py, side)| grid[(py + y) * side + px + x]);
                    if let Some(old) = old.filter(|z| !z.is_nan()).and_then(at) {
                        pop = pop.max(distance(drawn, old));
                    }
                }
            }
        }
    }
    (error, pop)
}

/// Where tile `i`'s surface grid lies over the base grid: its first base sample (column, row)
/// and its side in samples (257 for a base tile, `(256 << p) + 1` for one of layer `p`).
fn footprint(terrain: &Terrain, i: usize) -> (u32, u32, usize) {
    let t = &terrain.tiles[i];
    let cells = TILE_CELLS << t.layer;
    (t.tx * cells, t.ty * cells, cells as usize + 1)
}

/// The heights one tile draws at the base samples under it in `state` (NaN where none; a grid
/// of [`footprint`]'s side): the level's triangles over its vertices, geomorphed when `state`
/// has corner levels.
fn surface(terrain: &Terrain, tile: usize, state: State) -> Vec<f32> {
    let (_, _, side) = footprint(terrain, tile);
    let mut grid = vec![f32::NAN; side * side];
    let info = &terrain.tiles[tile];
    // The renderer checked the levels it drew (and a tile that failed is not drawn): read the
    // tile as it does, without checking every level of it again for every frame it is drawn in.
    let Ok(t) = terrain.set_of(info).tile_outline(info.tx, info.ty) else {
        return grid;
    };
    let p = info.layer;
    let vertices: Vec<(u32, u32, f32)> =
        morph::tile_vertices(&t, state.level, state.morph.as_ref())
            .into_iter()
            .map(|(x, y, z)| (x << p, y << p, z))
            .collect();
    let Some(l) = t.level(state.level) else {
        return grid;
    };
    let (mx, my) = (info.header.mesh_max_x << p, info.header.mesh_max_y << p);
    let fans = match &state.parts {
        Some(key) => {
            let made = crate::parts::blocks(terrain, tile).indices(key);
            made.map_or_else(Vec::new, |i| {
                i.split(|&v| v == tiles::parts::RESTART)
                    .map(<[u32]>::to_vec)
                    .collect()
            })
        }
        None => l.indices.fans(),
    };
    for fan in fans {
        let v = |i: u32| vertices.get(i as usize).copied();
        let Some(c) = fan.first().and_then(|&i| v(i)) else {
            continue;
        };
        for pair in fan[1..].windows(2) {
            if let (Some(a), Some(b)) = (v(pair[0]), v(pair[1])) {
                raster_barycentric([c, a, b], mx, my, |x, y, z| {
                    grid[y as usize * side + x as usize] = z as f32;
                });
            }
        }
    }
    grid
}

/// The comparison of the heights the vertex shader wrote with the CPU mirror's.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HeightCheck {
    /// Vertices compared.
    pub vertices: u64,
    /// The largest difference (m) and where: (tile column, row, vertex index).
    pub max_diff_m: f64,
    pub worst: Option<(u32, u32, usize)>,
    /// Vertices further apart than [`height_tolerance`].
    pub over: u64,
}

/// How far the GPU's vertex level may be from the mirror's, in levels: the shader's
/// `inversesqrt` is within 2 ulp, and `a_k - r b_k` cancels by up to the table's ratio of an
/// error to its step (2 where errors double; at most `1 / (1 - 1 / MIN_RATIO)` = 5, since
/// every table falls by at least [`crate::levels::MIN_RATIO`] a level), so a few 1e-6 of a
/// level; this allows far more.
pub const LEVEL_TOLERANCE: f64 = 1e-4;

/// How far a GPU height may be from the mirror's: four float steps at its magnitude (the two
/// round their products and sums in different orders), the height a level difference of
/// [`LEVEL_TOLERANCE`] makes at the vertex's `slope` (metres per level), and a micrometre.
pub fn height_tolerance(h: f32, slope: f32) -> f64 {
    4.0 * f64::from(f32::EPSILON) * f64::from(h.abs())
        + LEVEL_TOLERANCE * f64::from(slope.abs())
        + 1e-6
}

/// Compares every read-back height of a frame with [`morph::tile_vertices`] for the same draw;
/// `bias` is added to every stored morph offset of the mirror (0; the check's control uses 1).
pub fn check_heights(terrain: &Terrain, read_back: &ReadBack, bias: i8) -> HeightCheck {
    let mut check = HeightCheck::default();
    for &(tile, level, start, morph, parts) in &read_back.draws {
        let info = &terrain.tiles[tile];
        // Levels the renderer checked before it drew them (as in `surface`).
        let Ok(t) = terrain.set_of(info).tile_outline(info.tx, info.ty) else {
            continue;
        };
        let mirror = morph::tile_heights(&t, level, morph.as_ref(), bias);
        let gpu = read_back
            .values
            .get(start..start + mirror.len())
            .unwrap_or(&[]);
        // Drawn part by part, a vertex that no fan of the mix takes is not shaded: only the
        // mix's vertices have a height to compare.
        let drawn: Option<Vec<bool>> = parts.map(|key| {
            let mut used = vec![false; mirror.len()];
            let made = crate::parts::blocks(terrain, tile).indices(&key);
            for &v in made.iter().flatten() {
                if let Some(u) = used.get_mut(v as usize) {
                    *u = true;
                }
            }
            used
        });
        for (i, (&g, &(_, _, h, slope))) in gpu.iter().zip(&mirror).enumerate() {
            if drawn.as_ref().is_some_and(|d| !d[i]) {
                continue;
            }
            let d = (f64::from(g) - f64::from(h)).abs();
            check.vertices += 1;
            if d.is_nan() || d > height_tolerance(h, slope) {
                check.over += 1;
            }
            if d.is_nan() || d > check.max_diff_m {
                check.max_diff_m = d;
                check.worst = Some((info.tx, info.ty, i));
            }
        }
    }
    check
}
