//! From a height grid to tile blobs: cutting, per-tile level construction, fan emission in
//! P-order, vertex blocks, morph offsets, and the parallel, streaming tile-set build.

use std::path::Path;
use std::sync::mpsc::sync_channel;

use rayon::prelude::*;

use crate::format::{FileHeader, LevelEntry, TileHeader, TileSetWriter, MAX_LEVELS, TILE_MAGIC};
use crate::mesh::{lattice, plane, triangle_spans, Mesher, TileSamples, TILE_CELLS, TILE_SIZE};
use crate::pack::{morph_offset, morph_unit, pack};
use crate::quantise::Quantiser;
use crate::BuildError;

/// A height field in metres, row-major, row 0 = north.
#[derive(Clone, Copy, Debug)]
pub struct Grid<'a> {
    pub width: usize,
    pub height: usize,
    pub heights: &'a [f32],
    /// Metres between columns / rows.
    pub spacing_x: f64,
    pub spacing_y: f64,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BuildParams {
    pub levels: u32,
    /// `e_{levels-1}`, the finest level's bound, metres.
    pub base_error: f64,
}

impl Default for BuildParams {
    fn default() -> Self {
        BuildParams {
            levels: 9,
            base_error: 1.0,
        }
    }
}

impl BuildParams {
    pub fn validate(&self) -> Result<(), BuildError> {
        if self.levels == 0 || self.levels > MAX_LEVELS {
            return Err(BuildError::Params(format!(
                "--levels {} is outside 1..={MAX_LEVELS}",
                self.levels
            )));
        }
        if !(self.base_error > 0.0 && self.base_error.is_finite()) {
            return Err(BuildError::Params(format!(
                "--base-error {} must be a positive number of metres",
                self.base_error
            )));
        }
        Ok(())
    }

    pub fn level_error(&self, level: u32) -> f64 {
        level_error(self.base_error, self.levels, level)
    }
}

/// `e_i = base * 2^(n-1-i)`.
pub fn level_error(base: f64, levels: u32, level: u32) -> f64 {
    base * f64::powi(2.0, levels as i32 - 1 - level as i32)
}

/// Tiles across and down for a grid: tiles of 257 samples overlapping by one.
pub fn tile_count(width: usize, height: usize) -> Result<(u32, u32), String> {
    if width < 2 || height < 2 {
        return Err("a grid needs at least 2 x 2 samples".into());
    }
    let cells = TILE_CELLS as usize;
    let (tx, ty) = ((width - 1).div_ceil(cells), (height - 1).div_ceil(cells));
    if tx > u32::MAX as usize / 2
        || ty > u32::MAX as usize / 2
        || (width as u64) * (height as u64) > 1 << 40
    {
        return Err("too many samples".into());
    }
    Ok((tx as u32, ty as u32))
}

/// The 257 x 257 samples of tile `(tx, ty)`, the last real row and column repeated past the data.
pub fn tile_samples(grid: &Grid, tx: u32, ty: u32) -> TileSamples {
    let cells = TILE_CELLS as usize;
    let (x0, y0) = (tx as usize * cells, ty as usize * cells);
    let data_max_x = (grid.width - 1 - x0).min(cells);
    let data_max_y = (grid.height - 1 - y0).min(cells);
    let mut heights = Vec::with_capacity(TILE_SIZE * TILE_SIZE);
    for y in 0..TILE_SIZE {
        let row = (y0 + y.min(data_max_y)) * grid.width;
        heights.extend((0..TILE_SIZE).map(|x| grid.heights[row + x0 + x.min(data_max_x)]));
    }
    TileSamples {
        heights,
        data_max_x: data_max_x as u32,
        data_max_y: data_max_y as u32,
    }
}

/// Per-level figures of a built tile, for summaries.
#[derive(Clone, Copy, Debug, Default)]
pub struct LevelStats {
    pub vertices: u64,
    pub triangles: u64,
    pub bytes: u64,
    pub max_error: f64,
    pub limited_triangles: u64,
    pub limited_excess: f64,
}

pub struct BuiltTile {
    pub tx: u32,
    pub ty: u32,
    pub blob: Vec<u8>,
    pub levels: Vec<LevelStats>,
}

/// Position of a cell along the Hilbert curve over `n x n` cells (`n` a power of two).
/// Leaves sorted by it are visited depth-first with every step to an adjacent cell: the
/// P-order traversal of the paper, figure 3.
fn hilbert_index(n: u32, mut x: u32, mut y: u32) -> u32 {
    let mut d = 0;
    let mut s = n / 2;
    while s > 0 {
        let rx = u32::from(x & s > 0);
        let ry = u32::from(y & s > 0);
        d += s * s * ((3 * rx) ^ ry);
        if ry == 0 {
            if rx == 1 {
                x = s - 1 - (x & (s - 1));
                y = s - 1 - (y & (s - 1));
            }
            std::mem::swap(&mut x, &mut y);
        }
        x &= s - 1;
        y &= s - 1;
        s /= 2;
    }
    d
}

const NO_VERTEX: u32 = u32::MAX;

/// A model of a GPU's post-transform vertex cache (first in, first out, 16 entries, the size
/// vertex-cache analyses use) over lattice points, to order each fan's ring.
struct FifoCache {
    /// 1 + the miss count at which each point entered the cache (0 = never).
    entered: Vec<u32>,
    misses: u32,
}

impl FifoCache {
    const SIZE: u32 = 16;

    fn new(points: usize) -> Self {
        FifoCache {
            entered: vec![0; points],
            misses: 0,
        }
    }

    fn holds(&self, p: usize) -> bool {
        let e = self.entered[p];
        e > 0 && self.misses - (e - 1) < Self::SIZE
    }

    fn touch(&mut self, p: usize) {
        if !self.holds(p) {
            self.misses += 1;
            self.entered[p] = self.misses;
        }
    }

    fn clear(&mut self) {
        self.entered.fill(0);
        self.misses = 0;
    }
}

/// Rotates a closed fan (centre, ring..., first ring vertex again) so the ring starts with the
/// longest run of vertices still in the cache. A FIFO cache then meets those shared vertices
/// before this fan's new ones push them out (the fan stays the same triangles, same winding).
fn rotate_ring(fan: &mut Vec<(u32, u32)>, recent: impl Fn((u32, u32)) -> bool) {
    let ring = fan.len() - 2;
    let seen: Vec<bool> = fan[1..=ring].iter().map(|&p| recent(p)).collect();
    let run = |s: usize| (0..ring).take_while(|&i| seen[(s + i) % ring]).count();
    let Some(start) = (0..ring).max_by_key(|&s| (run(s), std::cmp::Reverse(s))) else {
        return;
    };
    if start == 0 || run(start) == 0 {
        return;
    }
    fan[1..=ring].rotate_left(start);
    fan[ring + 1] = fan[1];
}

struct LevelOut {
    entry: LevelEntry,
    block: Vec<u32>,
    indices: Vec<u32>,
    border: [Vec<u32>; 4],
}

/// Builds every level of tile `(tx, ty)` and serialises it.
pub fn build_tile(
    grid: &Grid,
    tx: u32,
    ty: u32,
    params: &BuildParams,
) -> Result<BuiltTile, BuildError> {
    let samples = tile_samples(grid, tx, ty);
    let (lo, hi) = samples
        .heights
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &h| {
            (lo.min(h), hi.max(h))
        });
    let quantiser = Quantiser::spanning(lo, hi);
    let mut mesher = Mesher::new(&samples, &quantiser, grid.spacing_x.min(grid.spacing_y));
    let (mesh_max_x, mesh_max_y) = samples.mesh_max();

    let n = params.levels as usize;
    // Global vertex index of each lattice point, and the level that introduced it.
    let mut vertex_of = vec![NO_VERTEX; TILE_SIZE * TILE_SIZE];
    let mut lattice_of: Vec<u32> = Vec::new();
    let mut vertex_level: Vec<u8> = Vec::new();
    let mut levels: Vec<LevelOut> = Vec::with_capacity(n);
    // Each level's surface at every lattice point.
    let mut surfaces: Vec<Vec<f32>> = Vec::with_capacity(n);
    let mut fan = Vec::with_capacity(10);
    let mut cache = FifoCache::new(TILE_SIZE * TILE_SIZE);

    for level in 0..n {
        let e = params.level_error(level as u32);
        mesher.refine(e);
        let mut keyed: Vec<(u32, _)> = mesher
            .leaves()
            .into_iter()
            .map(|q| {
                let (x, y) = q.origin();
                (hilbert_index(TILE_CELLS / 2, x / 2, y / 2), q)
            })
            .collect();
        keyed.sort_unstable_by_key(|&(key, _)| key);
        let leaves: Vec<_> = keyed.into_iter().map(|(_, q)| q).collect();

        let block_start = lattice_of.len() as u32;
        let mut indices = Vec::with_capacity(leaves.len() * 10);
        let mut triangles = 0u32;
        for &q in &leaves {
            fan.clear();
            mesher.fan(q, &mut fan);
            triangles += fan.len() as u32 - 2;
            rotate_ring(&mut fan, |(x, y)| cache.holds(lattice(x, y)));
            for &(x, y) in &fan {
                cache.touch(lattice(x, y));
                let l = lattice(x, y);
                if vertex_of[l] == NO_VERTEX {
                    vertex_of[l] = lattice_of.len() as u32;
                    lattice_of.push(l as u32);
                    vertex_level.push(level as u8);
                }
                indices.push(vertex_of[l]);
            }
            indices.push(NO_VERTEX);
        }
        indices.pop();
        cache.clear();

        // Measured error, and the places where refinement was not allowed.
        let mut max_error = 0.0f64;
        let mut limited_excess = 0.0f64;
        let mut limited_triangles = 0u32;
        for &q in &leaves {
            for &t in mesher.fan_triangles(q).as_slice() {
                let err = mesher.triangle_error(q, t);
                max_error = max_error.max(err);
                if err > e {
                    if !mesher.refinement_forbidden(q, t, e) {
                        return Err(BuildError::Internal(format!(
                            "tile {tx},{ty} level {level}: a triangle of cell {q:?} exceeds {e} m by {} m",
                            err - e
                        )));
                    }
                    limited_triangles += 1;
                    limited_excess = limited_excess.max(err - e);
                }
            }
        }
        // The level's surface at every lattice point, for the morph offsets of the vertices
        // finer levels introduce.
        let heights = mesher.quantised_heights();
        let mut surface = vec![f32::NAN; TILE_SIZE * TILE_SIZE];
        // The finest level has no finer vertices to morph.
        let leaves_to_draw = if level + 1 < n { &leaves[..] } else { &[] };
        for &q in leaves_to_draw {
            for &t in mesher.fan_triangles(q).as_slice() {
                let tri = q.triangle(t);
                let (a, b, c) = plane(tri, tri.map(|(x, y)| f64::from(heights[lattice(x, y)])));
                triangle_spans(q, t, mesh_max_x, mesh_max_y, |y, lo, hi| {
                    let z0 = a + c * f64::from(y);
                    for (x, z) in (lo..=hi).zip(&mut surface[lattice(lo, y)..=lattice(hi, y)]) {
                        *z = (z0 + b * f64::from(x)) as f32;
                    }
                });
            }
        }
        surfaces.push(surface);
        let block: Vec<u32> = lattice_of[block_start as usize..]
            .iter()
            .map(|&l| {
                let (x, y) = (l % TILE_SIZE as u32, l / TILE_SIZE as u32);
                pack(x, y, quantiser.quantise(samples.heights[l as usize]))
            })
            .collect();
        let vertex_count = lattice_of.len() as u32;
        let (mut z_min, mut z_max) = (f32::INFINITY, f32::NEG_INFINITY);
        let mut border: [Vec<(u32, u32)>; 4] = Default::default();
        for &l in &lattice_of {
            let (x, y) = (l % TILE_SIZE as u32, l / TILE_SIZE as u32);
            let h = heights[l as usize];
            z_min = z_min.min(h);
            z_max = z_max.max(h);
            let v = vertex_of[l as usize];
            if y == 0 {
                border[0].push((x, v));
            }
            if x == mesh_max_x {
                border[1].push((y, v));
            }
            if y == mesh_max_y {
                border[2].push((x, v));
            }
            if x == 0 {
                border[3].push((y, v));
            }
        }
        let border = border.map(|mut side| {
            side.sort_unstable();
            side.into_iter().map(|(_, v)| v).collect::<Vec<u32>>()
        });
        let entry = LevelEntry {
            error_bound: e as f32,
            // Rounded up so the stored figure is never below the measured one.
            max_error: round_up_f32(max_error),
            limited_excess: round_up_f32(limited_excess),
            limited_triangles,
            z_min,
            z_max,
            block_start,
            block_len: vertex_count - block_start,
            index_count: indices.len() as u32,
            index_width: if vertex_count <= u32::from(u16::MAX) {
                2
            } else {
                4
            },
            triangle_count: triangles,
            fan_count: leaves.len() as u32,
            border_len: [0, 1, 2, 3].map(|k| border[k].len() as u32),
            ..LevelEntry::default()
        };
        levels.push(LevelOut {
            entry,
            block,
            indices,
            border,
        });
    }

    // Morph offsets: each vertex of block j, on every coarser level k < j, in units sized so
    // the largest deviation from level k's surface fits.
    for k in 0..n {
        let start = levels[k].entry.vertex_count() as usize;
        let deviation = lattice_of[start..]
            .iter()
            .map(|&l| {
                (f64::from(surfaces[k][l as usize])
                    - f64::from(mesher.quantised_heights()[l as usize]))
                .abs()
            })
            .fold(0.0, f64::max);
        levels[k].entry.morph_unit =
            morph_unit(levels[k].entry.error_bound.into(), deviation) as f32;
    }
    let mut morph: Vec<Vec<i8>> = Vec::with_capacity(n);
    for (j, out) in levels.iter().enumerate() {
        let start = out.entry.block_start as usize;
        let mut rows = Vec::with_capacity(j * out.block.len());
        for (k, coarse) in levels.iter().enumerate().take(j) {
            let unit = f64::from(coarse.entry.morph_unit);
            rows.extend(lattice_of[start..start + out.block.len()].iter().map(|&l| {
                let h = mesher.quantised_heights()[l as usize];
                morph_offset(h, surfaces[k][l as usize], unit)
            }));
        }
        debug_assert!(vertex_level[start..start + out.block.len()]
            .iter()
            .all(|&v| v as usize == j));
        morph.push(rows);
    }

    let header = TileHeader {
        magic: TILE_MAGIC,
        tx,
        ty,
        levels: params.levels,
        data_max_x: samples.data_max_x,
        data_max_y: samples.data_max_y,
        mesh_max_x,
        mesh_max_y,
        height_min: quantiser.min,
        height_step: quantiser.step,
        vertex_count: lattice_of.len() as u32,
        reserved: 0,
    };
    let (blob, stats) = serialise(&header, &mut levels, &morph);
    Ok(BuiltTile {
        tx,
        ty,
        blob,
        levels: stats,
    })
}

fn round_up_f32(v: f64) -> f32 {
    let f = v as f32;
    if f64::from(f) < v {
        f.next_up()
    } else {
        f
    }
}

fn pad4(blob: &mut Vec<u8>) {
    while !blob.len().is_multiple_of(4) {
        blob.push(0);
    }
}

fn serialise(
    header: &TileHeader,
    levels: &mut [LevelOut],
    morph: &[Vec<i8>],
) -> (Vec<u8>, Vec<LevelStats>) {
    let table =
        std::mem::size_of::<TileHeader>() + levels.len() * std::mem::size_of::<LevelEntry>();
    let mut blob = vec![0u8; table];
    let mut stats = Vec::with_capacity(levels.len());
    let mut block_bytes = 0u64;
    for (i, out) in levels.iter_mut().enumerate() {
        let e = &mut out.entry;
        e.positions_offset = blob.len() as u32;
        blob.extend_from_slice(bytemuck::cast_slice(&out.block));
        e.morph_offset = blob.len() as u32;
        blob.extend_from_slice(bytemuck::cast_slice(&morph[i]));
        pad4(&mut blob);
        block_bytes += (out.block.len() * 4 + morph[i].len()) as u64;
        e.index_offset = blob.len() as u32;
        if e.index_width == 2 {
            let narrow: Vec<u16> = out.indices.iter().map(|&v| v as u16).collect();
            blob.extend_from_slice(bytemuck::cast_slice(&narrow));
        } else {
            blob.extend_from_slice(bytemuck::cast_slice(&out.indices));
        }
        pad4(&mut blob);
        e.border_offset = blob.len() as u32;
        for side in &out.border {
            blob.extend_from_slice(bytemuck::cast_slice(side));
        }
        stats.push(LevelStats {
            vertices: u64::from(e.vertex_count()),
            triangles: u64::from(e.triangle_count),
            bytes: block_bytes + u64::from(e.index_count) * u64::from(e.index_width),
            max_error: f64::from(e.max_error),
            limited_triangles: u64::from(e.limited_triangles),
            limited_excess: f64::from(e.limited_excess),
        });
    }
    blob[..std::mem::size_of::<TileHeader>()].copy_from_slice(bytemuck::bytes_of(header));
    let entries: Vec<LevelEntry> = levels.iter().map(|l| l.entry).collect();
    blob[std::mem::size_of::<TileHeader>()..table].copy_from_slice(bytemuck::cast_slice(&entries));
    (blob, stats)
}

/// Everything about a tile set that is not in its tiles.
#[derive(Clone, Debug, Default)]
pub struct TileSetMeta {
    pub description: String,
    pub voids_filled: u64,
}

/// Totals of a finished build.
#[derive(Clone, Debug, Default)]
pub struct BuildSummary {
    pub tiles: u64,
    /// Per level, summed over tiles.
    pub levels: Vec<LevelStats>,
    pub file_bytes: u64,
}

/// Builds all tiles in parallel and streams them into `out` (temporary file, then rename).
/// At most a few tiles per worker are in flight, so memory does not grow with the tile count.
/// `progress` is called once per finished tile.
pub fn build_tileset(
    grid: &Grid,
    params: &BuildParams,
    meta: &TileSetMeta,
    out: &Path,
    progress: &(dyn Fn() + Sync),
) -> Result<BuildSummary, BuildError> {
    params.validate()?;
    let (tiles_x, tiles_y) = tile_count(grid.width, grid.height).map_err(BuildError::Params)?;
    if grid.heights.len() != grid.width * grid.height {
        return Err(BuildError::Params(
            "height grid length does not match its size".into(),
        ));
    }
    if let Some(bad) = grid.heights.iter().find(|h| !h.is_finite()) {
        return Err(BuildError::Params(format!(
            "height grid holds a non-finite value ({bad})"
        )));
    }
    let (lo, hi) = grid
        .heights
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &h| {
            (lo.min(h), hi.max(h))
        });
    let mut description = [0u8; 128];
    let text = meta.description.as_bytes();
    let mut cut = text.len().min(description.len());
    while !meta.description.is_char_boundary(cut) {
        cut -= 1;
    }
    description[..cut].copy_from_slice(&text[..cut]);
    let header = FileHeader {
        grid_width: grid.width as u32,
        grid_height: grid.height as u32,
        tiles_x,
        tiles_y,
        tile_size: TILE_SIZE as u32,
        levels: params.levels,
        spacing_x: grid.spacing_x,
        spacing_y: grid.spacing_y,
        base_error: params.base_error,
        height_min: lo,
        height_max: hi,
        voids_filled: meta.voids_filled,
        description,
        ..bytemuck::Zeroable::zeroed()
    };
    let mut writer = TileSetWriter::create(out, header)?;
    let mut summary = BuildSummary {
        levels: vec![LevelStats::default(); params.levels as usize],
        ..Default::default()
    };
    let jobs: Vec<(u32, u32)> = (0..tiles_y)
        .flat_map(|ty| (0..tiles_x).map(move |tx| (tx, ty)))
        .collect();
    let in_flight = 2 * rayon::current_num_threads();
    let (send, receive) = sync_channel::<Result<BuiltTile, BuildError>>(in_flight);
    std::thread::scope(|scope| -> Result<(), BuildError> {
        scope.spawn(move || {
            // A failed send means the writer stopped (an error): stop building too.
            let _ = jobs.par_iter().try_for_each_with(send, |send, &(tx, ty)| {
                send.send(build_tile(grid, tx, ty, params)).map_err(|_| ())
            });
        });
        for built in receive {
            let built = built?;
            writer.add_tile(built.tx, built.ty, &built.blob)?;
            summary.tiles += 1;
            for (sum, l) in summary.levels.iter_mut().zip(&built.levels) {
                sum.vertices += l.vertices;
                sum.triangles += l.triangles;
                sum.bytes += l.bytes;
                sum.max_error = sum.max_error.max(l.max_error);
                sum.limited_triangles += l.limited_triangles;
                sum.limited_excess = sum.limited_excess.max(l.limited_excess);
            }
            progress();
        }
        Ok(())
    })?;
    writer.finish()?;
    summary.file_bytes = std::fs::metadata(out).map(|m| m.len()).unwrap_or(0);
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hilbert_steps_are_adjacent() {
        let n = 16;
        let mut cells: Vec<(u32, u32)> = (0..n * n).map(|i| (i % n, i / n)).collect();
        cells.sort_by_key(|&(x, y)| hilbert_index(n, x, y));
        for w in cells.windows(2) {
            let d = w[0].0.abs_diff(w[1].0) + w[0].1.abs_diff(w[1].1);
            assert_eq!(d, 1, "{:?} -> {:?}", w[0], w[1]);
        }
    }

    #[test]
    fn tile_count_covers_any_grid() {
        assert_eq!(tile_count(257, 257), Ok((1, 1)));
        assert_eq!(tile_count(258, 2), Ok((2, 1)));
        assert_eq!(tile_count(1201, 2401), Ok((5, 10)));
        assert_eq!(tile_count(3601, 3601), Ok((15, 15)));
        assert!(tile_count(1, 5).is_err());
    }

    #[test]
    fn level_errors_halve_per_level() {
        let p = BuildParams {
            levels: 9,
            base_error: 1.0,
        };
        assert_eq!(p.level_error(0), 256.0);
        assert_eq!(p.level_error(8), 1.0);
    }
}
