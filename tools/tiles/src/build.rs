//! From a height grid to tile blobs: cutting, per-tile level construction, fan emission in
//! P-order, vertex blocks, morph offsets, and the parallel, streaming tile-set build, whose
//! tiles are written in row-major order so that a build is reproducible byte for byte.

use std::borrow::Cow;
use std::path::Path;
use std::sync::{Arc, Mutex};

use rayon::prelude::*;

use crate::format::{
    level_error, pyramid_layers, side_error_code, tile_count, FileHeader, LevelEntry, TileHeader,
    TileSetWriter, FLAG_SHARED_SIDES, MAX_LEVELS, TILE_MAGIC,
};
use crate::grid::{tile_samples, Grid};
#[cfg(test)]
use crate::mesh::hilbert_index;
use crate::mesh::{
    lattice, plane, triangle_spans, MeshHistory, Mesher, Quad, TileSamples, TILE_CELLS, TILE_SIZE,
};
use crate::pack::{morph_offset, morph_unit, pack};
use crate::pyramid::{base_errors, decimation_errors, level_floor, Decimated, Surfaces};
use crate::quantise::{lattice_step, Quantiser};
use crate::texture::{self, Prepared, Source, Texturing};
use crate::units::{cell_spans, deviation_bounds, CellSpans, LayerBounds, CELL_SIZES};
use crate::BuildError;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BuildParams {
    pub levels: u32,
    /// `e_{levels-1}`, the finest level's bound, metres.
    pub base_error: f64,
    /// Make neighbouring tiles agree on their shared sides ([`FLAG_SHARED_SIDES`]): the same
    /// side vertices at every level and the same morph offsets for them. Off builds every
    /// tile on its own (one pass, fewer vertices; geomorphing then needs sliver triangles).
    pub shared_sides: bool,
    /// Build the tile pyramid above the base grid (format version 3): coarser tiles, each
    /// over 2 x 2 tiles of the layer below, up to one tile (see [`crate::pyramid`]).
    pub pyramid: bool,
}

impl Default for BuildParams {
    fn default() -> Self {
        BuildParams {
            levels: 9,
            base_error: 1.0,
            shared_sides: true,
            pyramid: false,
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

/// The height lattice step for a grid: fits the roughest tile's range in 14 bits.
pub fn height_step(grid: &Grid) -> Result<f32, String> {
    let (tiles_x, tiles_y) = tile_count(grid.width, grid.height)?;
    let (max_range, max_abs) = tile_ranges(grid, tiles_x, 0..tiles_y);
    Ok(lattice_step(max_range, max_abs))
}

/// The largest height range of one tile and the largest absolute height, over the tiles of
/// tile rows `rows` (which `grid` holds): the largest cell span is a whole tile's.
pub(crate) fn tile_ranges(grid: &Grid, tiles_x: u32, rows: std::ops::Range<u32>) -> (f32, f32) {
    let (spans, max_abs) = cell_spans(grid, tiles_x, rows);
    (spans[CELL_SIZES - 1], max_abs)
}

/// Where a build reads its heights: a grid held whole ([`Grid`]), or a grid read a band of
/// tile rows at a time, so that its size is not bounded by memory (`tiletool` reads SRTM and
/// raw inputs so). Builds from either are the same bytes.
pub trait Heights: Sync {
    /// The whole grid's width, height and spacing (its `heights` empty).
    fn shape(&self) -> Grid<'_>;
    /// Rows `y0..y1` of the grid, metres.
    fn rows(&self, y0: usize, y1: usize) -> Result<Cow<'_, [f32]>, BuildError>;
    /// Tile rows a band holds: `u32::MAX` reads the grid as one band.
    fn band_tile_rows(&self) -> u32 {
        u32::MAX
    }
    /// True when reading rows one at a time costs about what reading them in one run does (a
    /// pyramid layer then reads only the rows it keeps, [`Decimated`]).
    fn reads_rows_singly(&self) -> bool {
        false
    }
}

impl Heights for Grid<'_> {
    fn shape(&self) -> Grid<'_> {
        Grid {
            heights: &[],
            first_row: 0,
            ..*self
        }
    }

    fn rows(&self, y0: usize, y1: usize) -> Result<Cow<'_, [f32]>, BuildError> {
        let held = self.rows();
        if !(held.start <= y0 && y0 <= y1 && y1 <= held.end) {
            return Err(BuildError::Internal(format!(
                "rows {y0}..{y1} asked of a grid holding {held:?}"
            )));
        }
        let w = self.width;
        Ok(Cow::Borrowed(
            &self.heights[(y0 - held.start) * w..(y1 - held.start) * w],
        ))
    }

    /// Rows held in memory: any are a slice.
    fn reads_rows_singly(&self) -> bool {
        true
    }
}

/// A grid cut into bands of whole tile rows, each read when a step of the build needs it.
pub(crate) struct Bands<'a> {
    source: &'a dyn Heights,
    shape: Grid<'a>,
    tiles: (u32, u32),
    /// The tile rows the bands cover: all of them, or a shard's.
    rows: std::ops::Range<u32>,
    per_band: u32,
    /// The rows read last, kept for a read of the same rows (a grid read as one band is read
    /// once) and dropped before any other read (one band in memory, not two).
    last: Mutex<Option<HeldRows<'a>>>,
}

/// Rows `range` of the grid, shared by the band that read them and the cache.
type HeldRows<'a> = (std::ops::Range<usize>, Arc<Cow<'a, [f32]>>);

/// One band's rows, and the grid they make.
pub(crate) struct Band<'a> {
    rows: Arc<Cow<'a, [f32]>>,
    first_row: usize,
    pub tile_rows: std::ops::Range<u32>,
}

impl<'a> Bands<'a> {
    pub(crate) fn new(source: &'a dyn Heights, tiles: (u32, u32)) -> Bands<'a> {
        Bands {
            source,
            shape: source.shape(),
            tiles,
            rows: 0..tiles.1,
            per_band: source.band_tile_rows().clamp(1, tiles.1.max(1)),
            last: Mutex::new(None),
        }
    }

    /// The same grid's bands over tile rows `rows` only (a shard's): a band holds no row
    /// the shard does not need.
    pub(crate) fn within(
        source: &'a dyn Heights,
        tiles: (u32, u32),
        rows: std::ops::Range<u32>,
    ) -> Bands<'a> {
        Bands {
            rows,
            ..Bands::new(source, tiles)
        }
    }

    pub(crate) fn count(&self) -> u32 {
        (self.rows.len() as u32).div_ceil(self.per_band)
    }

    fn tile_rows(&self, b: u32) -> std::ops::Range<u32> {
        let start = self.rows.start + b * self.per_band;
        start..(start + self.per_band).min(self.rows.end)
    }

    /// Band `b`: the samples of its tile rows and `margin` more rows either side (within the
    /// grid).
    pub(crate) fn load(&self, b: u32, margin: usize) -> Result<Band<'a>, BuildError> {
        let rows = self.tile_rows(b);
        let cells = TILE_CELLS as usize;
        let y0 = (rows.start as usize * cells).saturating_sub(margin);
        let y1 = (rows.end as usize * cells + 1 + margin).min(self.shape.height);
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        let heights = match last.take() {
            Some((held, heights)) if held == (y0..y1) => heights,
            _ => Arc::new(self.source.rows(y0, y1)?),
        };
        *last = Some((y0..y1, heights.clone()));
        Ok(Band {
            rows: heights,
            first_row: y0,
            tile_rows: rows,
        })
    }
}

impl Band<'_> {
    pub(crate) fn grid<'g>(&'g self, shape: &Grid) -> Grid<'g> {
        Grid {
            width: shape.width,
            height: shape.height,
            first_row: self.first_row,
            heights: &self.rows,
            spacing_x: shape.spacing_x,
            spacing_y: shape.spacing_y,
        }
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
    /// Where the tile's side vertices are, per level.
    pub sides: Sides,
    /// Per level, the largest distance of a finer vertex from the level's surface (metres;
    /// 0 for the finest level).
    pub deviation: Vec<f64>,
    /// A pyramid layer's tile (built with `Output::LayerTile`): every level's surface at every lattice
    /// point of the mesh extent, interleaved (`[point * levels + level]`); empty otherwise.
    pub surfaces: Vec<f32>,
    /// The last column and row of real data.
    pub data_max: (u32, u32),
    /// The agreement's meshes ([`Output::Sides`], [`Output::SidesBare`]): when each cell and
    /// vertex came, for meshing the tile again with more forced; `None` for a built tile.
    pub history: Option<MeshHistory>,
}

/// The side vertices of a tile, per level and side (north, east, south, west): each vertex's
/// column (north and south sides) or row (east and west), ascending.
pub type Sides = Vec<[Vec<u16>; 4]>;

/// What a tile is built to agree on with its neighbours (empty: nothing, the tile on its own).
#[derive(Clone, Debug, Default)]
pub struct Agreement {
    /// Per level and side, positions that must be vertices of that level on that side.
    pub forced: Sides,
    /// Per level, the morph unit every tile of the set uses (None: the tile's own units).
    pub units: Option<Vec<f64>>,
    /// Metres no level is built finer than (0 in the base grid; a pyramid layer's tile is
    /// built to `max(e_i, floor)`, see [`crate::pyramid::level_floor`]).
    pub floor: f64,
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

    /// Empties the cache: every point held entered at least `SIZE` misses ago, as though
    /// `SIZE` misses had passed, without writing the table again (a tile's levels each start
    /// empty; the table is 264 KB).
    fn clear(&mut self) {
        self.misses += Self::SIZE;
    }
}

/// Rotates a closed fan (centre, ring..., first ring vertex again) so the ring starts with the
/// longest run of vertices still in the cache. A FIFO cache then meets those shared vertices
/// before this fan's new ones push them out (the fan stays the same triangles, same winding).
fn rotate_ring(fan: &mut [(u32, u32)], recent: impl Fn((u32, u32)) -> bool) {
    let ring = fan.len() - 2;
    let Some(start) = longest_run_start(ring, |i| recent(fan[1 + i])) else {
        return;
    };
    fan[1..=ring].rotate_left(start);
    fan[ring + 1] = fan[1];
}

/// Where the ring of `ring` (at most 8) vertices starts its longest run of vertices `seen`,
/// going round; the first such start, and none where that is 0 or nothing is seen. As a bit
/// mask turned once per start: a fan's ring is asked this once per fan of every level.
fn longest_run_start(ring: usize, seen: impl Fn(usize) -> bool) -> Option<usize> {
    let full = (1u32 << ring) - 1;
    let mask = (0..ring).fold(0u32, |m, i| m | u32::from(seen(i)) << i);
    if mask == 0 || mask == full {
        // Every start has the same run: the first, 0.
        return None;
    }
    let mut best = (0, 0);
    for s in 1..ring {
        let turned = ((mask >> s) | (mask << (ring - s))) & full;
        let run = turned.trailing_ones();
        if run > best.0 {
            best = (run, s);
        }
    }
    // Start 0 wins its ties, and keeps the ring as it is.
    (best.0 > mask.trailing_ones()).then_some(best.1)
}

struct LevelOut {
    entry: LevelEntry,
    block: Vec<u32>,
    indices: Vec<u32>,
    border: [Vec<u32>; 4],
}

/// How the vertices a level adds are numbered within its block.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Numbering {
    /// In the order the level's fans first use them (files written before the compact levels'
    /// version 5: version 3 sets and version 4 compact sets).
    FirstUse,
    /// In the order the level's compact stream decodes them ([`crate::compact`]): first the
    /// vertices without both parents among the levels so far, row-major, then the others by
    /// scale, coarsest first, each scale row-major. A GPU decoding the stream then writes the
    /// block the file describes, with no permutation sent beside it.
    Decode,
}

/// The tile's vertices in index order: blocks by introducing level, each in the order its
/// [`Numbering`] gives.
struct VertexOrder {
    /// Global vertex index of each lattice point (`NO_VERTEX` if not a vertex yet).
    index_of: Vec<u32>,
    /// Lattice point of each vertex.
    lattice_of: Vec<u32>,
}

impl VertexOrder {
    fn new() -> Self {
        VertexOrder {
            index_of: vec![NO_VERTEX; TILE_SIZE * TILE_SIZE],
            lattice_of: Vec::new(),
        }
    }

    fn index(&mut self, l: usize) -> u32 {
        if self.index_of[l] == NO_VERTEX {
            self.index_of[l] = self.lattice_of.len() as u32;
            self.lattice_of.push(l as u32);
        }
        self.index_of[l]
    }

    /// Numbers the vertices a level adds in [`Numbering::Decode`]'s order where they are
    /// known, `set` (a rebuild's decoded level), before its fans are emitted: the same numbers
    /// where the fans use exactly the set's points and the coarser levels', as a sound level's
    /// do (where they do not, the fans number the points they meet after these, and the
    /// rebuilt tile fails its checksum).
    fn number_set_for_decoding(&mut self, set: &[(u32, u32, u16)]) {
        let mut new = Vec::with_capacity(set.len());
        for &(x, y, _) in set {
            self.meet(lattice(x, y), &mut new);
        }
        self.number_met(new);
    }

    /// Marks lattice point `l` as met, into `new`, if it has no number yet.
    fn meet(&mut self, l: usize, new: &mut Vec<u32>) {
        if self.index_of[l] == NO_VERTEX {
            // Marked as met (not a vertex index: no block is that long).
            self.index_of[l] = NO_VERTEX - 1;
            new.push(l as u32);
        }
    }

    /// Numbers the points met, `new`, in [`Numbering::Decode`]'s order: those without both
    /// parents among the vertices so far (these included) first, row-major, then the others by
    /// scale, coarsest first, each scale row-major.
    fn number_met(&mut self, new: Vec<u32>) {
        let is_vertex = |index_of: &[u32], (x, y): (u32, u32)| index_of[lattice(x, y)] != NO_VERTEX;
        // The key (class, scale, lattice point) packed in one word, in the same order: a point
        // takes 17 bits (257² < 2^17), a scale 4.
        const POINT_BITS: u32 = 17;
        const _: () = assert!(TILE_SIZE * TILE_SIZE <= 1 << POINT_BITS);
        let mut keyed: Vec<u32> = new
            .iter()
            .map(|&l| {
                let (x, y) = xy(l);
                match crate::compact::parents(x, y) {
                    Some([a, b])
                        if is_vertex(&self.index_of, a) && is_vertex(&self.index_of, b) =>
                    {
                        let scale = 8 - crate::compact::scale_of(x, y).trailing_zeros();
                        1 << (POINT_BITS + 4) | scale << POINT_BITS | l
                    }
                    _ => l,
                }
            })
            .collect();
        keyed.sort_unstable();
        for &l in &new {
            self.index_of[l as usize] = NO_VERTEX;
        }
        for key in keyed {
            self.index((key & ((1 << POINT_BITS) - 1)) as usize);
        }
    }
}

fn xy(l: u32) -> (u32, u32) {
    (l % TILE_SIZE as u32, l / TILE_SIZE as u32)
}

/// The level's index array (fans joined by restarts) and its triangle count; new vertices get
/// the next indices, which makes them this level's block: in the order the fans first use
/// them, or with `decode` in [`Numbering::Decode`]'s (the fans are walked once, their lattice
/// points written and then mapped to the numbers the level's new points get).
fn emit_fans(
    mesher: &Mesher,
    leaves: &[Quad],
    vertices: &mut VertexOrder,
    cache: &mut FifoCache,
    decode: bool,
) -> (Vec<u32>, u32) {
    let mut indices = Vec::with_capacity(leaves.len() * 10);
    let mut triangles = 0u32;
    let mut fan = Vec::with_capacity(10);
    let mut new = Vec::new();
    cache.clear();
    for &q in leaves {
        fan.clear();
        mesher.fan(q, &mut fan);
        triangles += fan.len() as u32 - 2;
        rotate_ring(&mut fan, |(x, y)| cache.holds(lattice(x, y)));
        for &(x, y) in &fan {
            let l = lattice(x, y);
            cache.touch(l);
            if decode {
                vertices.meet(l, &mut new);
                indices.push(l as u32);
            } else {
                indices.push(vertices.index(l));
            }
        }
        indices.push(NO_VERTEX);
    }
    indices.pop();
    if decode {
        // Numbered by the set the fans met, whatever order they met it in.
        vertices.number_met(new);
        for i in &mut indices {
            if *i != NO_VERTEX {
                *i = vertices.index_of[*i as usize];
            }
        }
    }
    (indices, triangles)
}

/// One level rebuilt by [`fans_from_vertices`]: its block (its new vertices, `(x, y)` in
/// [`Numbering::Decode`]'s order) and its index array (fans joined by `u32::MAX` restarts).
pub type RebuiltLevel = (Vec<(u32, u32)>, Vec<u32>);

/// Each level's block (its new vertices, `(x, y)` in decoding order) and index array, from
/// the levels' vertex sets alone (`sets[j]`: the vertices level `j` adds, in any order), as
/// [`build_tile`] emits them: the decoding half of issue 28's compact levels, where the fans
/// and the vertices' order are not stored but follow from which vertices each level has
/// ([`Mesher::from_vertices`]). `samples` gives the tile's data extent.
pub fn fans_from_vertices(samples: &TileSamples, sets: &[Vec<(u32, u32)>]) -> Vec<RebuiltLevel> {
    let quantiser = Quantiser::for_tile(0.0, 1.0);
    let mut vertex = vec![false; TILE_SIZE * TILE_SIZE];
    let mut vertices = VertexOrder::new();
    let mut cache = FifoCache::new(TILE_SIZE * TILE_SIZE);
    // One mesher for all levels: a finer level's set holds a coarser one's, so each level only
    // adds splits and activations to the last (as rebuild_tile does).
    let mut mesher = Mesher::new(samples, &quantiser, 1.0);
    sets.iter()
        .map(|set| {
            for &(x, y) in set {
                vertex[lattice(x, y)] = true;
            }
            mesher.extend_to_vertices(|(x, y)| vertex[lattice(x, y)]);
            let leaves = mesher.leaves_in_p_order();
            let start = vertices.lattice_of.len();
            let (indices, _) = emit_fans(&mesher, &leaves, &mut vertices, &mut cache, true);
            let block = vertices.lattice_of[start..]
                .iter()
                .map(|&l| xy(l))
                .collect();
            (block, indices)
        })
        .collect()
}

/// The decoding half of issue 28's compact levels: a tile's blob rebuilt from what that
/// encoding keeps, as [`build_tile`] made it, byte for byte: each level's new vertices with
/// their height codes (`(x, y, code)`, in any order), and the stored header and level entries
/// (for their measured figures and morph units, which need the source to compute). The fans,
/// the vertices' order, the border lists, the height ranges and the morph offsets follow
/// ([`Mesher::from_vertices`], and the same assembly as the build's).
///
/// With fewer `sets` than `entries` (the first levels only), the blob is the full blob's first
/// bytes, through the last of those levels' sections: a level's sections, and its entry, follow
/// from its own and the coarser levels' vertices alone, and the blob lays the levels out in
/// order after a table with room for every entry. The table's entries past the given levels are
/// left zero. So a reader that draws a tile's coarse levels rebuilds those alone.
pub fn rebuild_tile(
    header: &TileHeader,
    entries: &[LevelEntry],
    sets: &[Vec<(u32, u32, u16)>],
    numbering: Numbering,
) -> Vec<u8> {
    let quantiser = Quantiser {
        base: header.height_base,
        step: header.height_step,
    };
    let mut samples = TileSamples {
        heights: vec![quantiser.min(); TILE_SIZE * TILE_SIZE],
        data_max_x: header.data_max_x,
        data_max_y: header.data_max_y,
    };
    let mut code = vec![0u16; TILE_SIZE * TILE_SIZE];
    for &(x, y, c) in sets.iter().flatten() {
        samples.heights[lattice(x, y)] = quantiser.height(c);
        code[lattice(x, y)] = c;
    }
    let mut mesher = Mesher::of_quantised(&samples);
    let mut assembly = Assembly::new(sets.len(), samples.mesh_max(), Output::Tile, numbering);
    let mut vertex = vec![false; TILE_SIZE * TILE_SIZE];
    for (set, stored) in sets.iter().zip(entries) {
        for &(x, y, _) in set {
            vertex[lattice(x, y)] = true;
        }
        mesher.extend_to_vertices(|(x, y)| vertex[lattice(x, y)]);
        let leaves = mesher.leaves_in_p_order();
        let errors = LevelEntry {
            error_bound: stored.error_bound,
            max_error: stored.max_error,
            side_errors: stored.side_errors,
            limited_excess: stored.limited_excess,
            limited_triangles: stored.limited_triangles,
            ..LevelEntry::default()
        };
        assembly.add_level(&mesher, &leaves, errors, &|l| code[l], Some(set));
    }
    let units: Vec<f64> = entries.iter().map(|e| f64::from(e.morph_unit)).collect();
    let (blob, _) = assembly.seal(header, mesher.quantised_heights(), &units, entries.len());
    blob
}

/// A level's entry as far as its measured errors fill it ([`measure_level`]), under the
/// bound `e`; the cell of a triangle over `e` that could have been refined (a mesher bug).
fn level_errors(
    mesher: &mut Mesher,
    leaves: &[Quad],
    e: f64,
    mesh_max: (u32, u32),
) -> Result<LevelEntry, Quad> {
    let measured = measure_level(mesher, leaves, e, mesh_max)?;
    let max_error = round_up_f32(measured.max_error);
    Ok(LevelEntry {
        error_bound: e as f32,
        // Rounded up so the stored figures are never below the measured ones.
        max_error,
        side_errors: measured
            .side_errors
            .map(|side| side_error_code(max_error, side)),
        limited_excess: round_up_f32(measured.limited_excess),
        limited_triangles: measured.limited_triangles,
        ..LevelEntry::default()
    })
}

/// What [`measure_level`] finds of a level.
struct Measured {
    max_error: f64,
    /// The largest error over the triangles touching each side (N, E, S, W).
    side_errors: [f64; 4],
    limited_triangles: u32,
    limited_excess: f64,
}

/// The level's measured max error, overall and over the triangles that touch each side of the
/// mesh extent (`mesh_max`: its last column and row), and, where refinement was forbidden, how
/// many triangles exceed `e` and by how much at most. A triangle touches a side where one of
/// its corners is on it: the extent is convex. A triangle over `e` that could have been refined
/// is a mesher bug, returned as the offending cell.
fn measure_level(
    mesher: &mut Mesher,
    leaves: &[Quad],
    e: f64,
    mesh_max: (u32, u32),
) -> Result<Measured, Quad> {
    let mut m = Measured {
        max_error: 0.0,
        side_errors: [0.0; 4],
        limited_triangles: 0,
        limited_excess: 0.0,
    };
    for &q in leaves {
        // A leaf away from the sides whose fan refinement found within `e` adds its largest
        // error alone.
        let ((x0, y0), s) = (q.origin(), q.size());
        let inside = x0 > 0 && y0 > 0 && x0 + s < mesh_max.0 && y0 + s < mesh_max.1;
        match mesher.fan_error(q) {
            Some(fan) if inside && fan <= e => {
                m.max_error = m.max_error.max(fan);
                continue;
            }
            _ => {}
        }
        for (t, err) in mesher.fan_triangle_errors(q) {
            m.max_error = m.max_error.max(err);
            for &p in &q.triangle(t) {
                for (k, on) in on_sides(p, mesh_max).into_iter().enumerate() {
                    if on {
                        m.side_errors[k] = m.side_errors[k].max(err);
                    }
                }
            }
            if err > e {
                if !mesher.refinement_forbidden(q, t, e) {
                    return Err(q);
                }
                m.limited_triangles += 1;
                m.limited_excess = m.limited_excess.max(err - e);
            }
        }
    }
    Ok(m)
}

/// The level's surface at every lattice point of the mesh extent.
fn rasterise_surface(mesher: &Mesher, leaves: &[Quad], (max_x, max_y): (u32, u32)) -> Vec<f32> {
    let heights = mesher.quantised_heights();
    let mut surface = vec![f32::NAN; TILE_SIZE * TILE_SIZE];
    for &q in leaves {
        if q.size() == 2 {
            // The finest cells hold only their fan's ring and centre: vertices keep their
            // height, an absent midpoint lies halfway along its edge.
            let (x0, y0) = q.origin();
            for (dx, dy) in [(0, 0), (2, 0), (0, 2), (2, 2), (1, 1)] {
                let l = lattice(x0 + dx, y0 + dy);
                surface[l] = heights[l];
            }
            for k in 0..4 {
                let (a, b, (mx, my)) = (q.corner(k), q.corner(k + 1), q.midpoint(k));
                let l = lattice(mx, my);
                surface[l] = if mesher.midpoint_present(q, k) {
                    heights[l]
                } else {
                    (heights[lattice(a.0, a.1)] + heights[lattice(b.0, b.1)]) * 0.5
                };
            }
            continue;
        }
        for &t in mesher.fan_triangles(q).as_slice() {
            let tri = q.triangle(t);
            let (a, b, c) = plane(tri, tri.map(|(x, y)| f64::from(heights[lattice(x, y)])));
            triangle_spans(q, t, max_x, max_y, |y, lo, hi| {
                let z0 = a + c * f64::from(y);
                // Counted over the slice, not over an inclusive range of columns, so the
                // loop vectorises (the same arithmetic, the same values).
                let row = &mut surface[lattice(lo, y)..=lattice(hi, y)];
                for (i, z) in row.iter_mut().enumerate() {
                    *z = (z0 + b * f64::from(lo + i as u32)) as f32;
                }
            });
        }
    }
    surface
}

/// Builds every level of tile `(tx, ty)` and serialises it. `step` is the tile set's height
/// lattice step, [`height_step`] of the grid.
pub fn build_tile(
    grid: &Grid,
    tx: u32,
    ty: u32,
    params: &BuildParams,
    step: f32,
    agreement: &Agreement,
) -> Result<BuiltTile, BuildError> {
    mesh_tile(
        grid,
        (tx, ty),
        params,
        step,
        agreement,
        (Output::Tile, None),
    )
}

/// What [`mesh_tile`] makes: the whole tile, or only what the shared-sides agreement reads of
/// it (its sides and deviations; no fan order, index arrays, morph offsets or blob).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Output {
    Tile,
    /// The whole tile and every level's surface.
    LayerTile,
    Sides,
    /// [`Output::Sides`] without the deviations (all 0), so without the levels' surfaces: the
    /// base grid's agreement, whose morph units come from the scan ([`crate::units`]); each
    /// tile's deviations come from its final build.
    SidesBare,
}

/// [`build_tile`], or with `Output::Sides` the same meshes with only `sides`, `deviation`
/// and `history` of the result filled in: they depend on each level's set of vertices, not on
/// their order. `earlier`: the history of a mesh of the same tile at the same bounds with
/// forced sides that this `agreement`'s hold (the agreement's last mesh of it), so that only
/// what the new forced vertices change is refined ([`Mesher::refine_changed`]).
fn mesh_tile(
    grid: &Grid,
    (tx, ty): (u32, u32),
    params: &BuildParams,
    step: f32,
    agreement: &Agreement,
    (output, earlier): (Output, Option<&MeshHistory>),
) -> Result<BuiltTile, BuildError> {
    let samples = tile_samples(grid, tx, ty);
    let lo = samples
        .heights
        .iter()
        .fold(f32::INFINITY, |lo, &h| lo.min(h));
    let quantiser = Quantiser::for_tile(lo, step);
    let mut mesher = Mesher::new(&samples, &quantiser, grid.spacing_x.min(grid.spacing_y));
    let mesh_max = samples.mesh_max();
    let n = params.levels as usize;
    let mut assembly = Assembly::new(n, mesh_max, output, Numbering::Decode);
    let code_of = |l: usize| quantiser.quantise(samples.heights[l]);
    let agreeing = matches!(output, Output::Sides | Output::SidesBare);
    let mut history = agreeing.then(MeshHistory::new);
    let mut bare_sides = Sides::new();
    for level in 0..n {
        let e = params.level_error(level as u32).max(agreement.floor);
        if let Some(earlier) = earlier {
            mesher.replay(earlier, level);
        }
        // Forced first, then refined once: the level is the least mesh closed under
        // refinement's rules that holds both (see `Mesher::refine_changed`), whatever the order.
        if let Some(forced) = agreement.forced.get(level) {
            for (k, side) in forced.iter().enumerate() {
                for &at in side {
                    mesher.insert_side_vertex(side_point(k, at, mesh_max));
                }
            }
        }
        match earlier {
            Some(earlier) => mesher.refine_changed(e, earlier, level),
            None => mesher.refine(e),
        }
        if let Some(history) = &mut history {
            mesher.record(history, level);
        }
        if output == Output::SidesBare {
            // Only the sides are read: no leaves, fans or vertex numbers.
            bare_sides.push(std::array::from_fn(|k| {
                let end = if k % 2 == 0 { mesh_max.0 } else { mesh_max.1 };
                (0..=end as u16)
                    .filter(|&at| mesher.is_vertex(side_point(k, at, mesh_max)))
                    .collect()
            }));
            continue;
        }
        // In P-order either way: the surfaces below are written leaf by leaf, and points on
        // shared edges take the last leaf's rounding.
        let leaves = mesher.leaves_in_p_order();
        // What the agreement reads (sides, deviations) does not depend on the measured
        // errors, and its last mesh of each tile is the mesh the build measures (a tile is
        // built with the forced sides it was last meshed with): the agreement's meshes skip
        // the walk over every triangle of every level.
        let errors = if agreeing {
            LevelEntry::default()
        } else {
            level_errors(&mut mesher, &leaves, e, mesh_max).map_err(|q| {
                BuildError::Internal(format!(
                    "tile {tx},{ty} level {level}: a triangle of cell {q:?} exceeds {e} m"
                ))
            })?
        };
        assembly.add_level(&mesher, &leaves, errors, &code_of, None);
    }

    let heights = mesher.quantised_heights();
    let deviation = match output {
        Output::SidesBare => vec![0.0; n],
        _ => deviations(
            &assembly.levels,
            &assembly.surfaces,
            &assembly.vertices.lattice_of,
            heights,
        ),
    };
    if agreeing {
        return Ok(BuiltTile {
            tx,
            ty,
            blob: Vec::new(),
            levels: Vec::new(),
            sides: match output {
                Output::SidesBare => bare_sides,
                _ => assembly.positions,
            },
            deviation,
            surfaces: Vec::new(),
            data_max: (samples.data_max_x, samples.data_max_y),
            history,
        });
    }
    // A tile whose deviation passes the set's units (past the scan's bounds, which no input
    // here reaches) is sealed with its offsets clamped: its caller sees the deviation, raises
    // the units and seals it again ([`build_layer`], the merge).
    let units: Vec<f64> = match &agreement.units {
        Some(units) => units.clone(),
        None => (0..n)
            .map(|k| morph_unit(assembly.levels[k].entry.error_bound.into(), deviation[k]))
            .collect(),
    };
    let header = TileHeader {
        magic: TILE_MAGIC,
        tx,
        ty,
        levels: params.levels,
        data_max_x: samples.data_max_x,
        data_max_y: samples.data_max_y,
        mesh_max_x: mesh_max.0,
        mesh_max_y: mesh_max.1,
        height_min: quantiser.min(),
        height_step: quantiser.step,
        vertex_count: assembly.vertices.lattice_of.len() as u32,
        height_base: quantiser.base,
    };
    let surfaces = assembly.interleaved_surfaces();
    let (blob, stats) = assembly.seal(&header, heights, &units, n);
    Ok(BuiltTile {
        tx,
        ty,
        blob,
        levels: stats,
        sides: assembly.positions,
        deviation,
        surfaces,
        data_max: (samples.data_max_x, samples.data_max_y),
        history: None,
    })
}

/// A tile's levels assembled one after another from a mesher's mesh of each: the vertex order,
/// each level's block, index array, border lists and entry, and the surfaces the coarser
/// levels draw (for the morph offsets). The build drives it from a mesher it refines; the
/// compact levels' decoder ([`rebuild_tile`]) from a mesher rebuilt from each level's vertex
/// set, so that the two make the same bytes by construction.
struct Assembly {
    output: Output,
    numbering: Numbering,
    levels_wanted: usize,
    mesh_max: (u32, u32),
    vertices: VertexOrder,
    levels: Vec<LevelOut>,
    /// Each level's surface at every lattice point (none for the finest: nothing morphs to
    /// it), and the finest's where a layer tile keeps it.
    surfaces: Vec<Vec<f32>>,
    finest_surface: Vec<f32>,
    cache: FifoCache,
    /// Border lists and height range grow with each block.
    sides: [Vec<(u32, u32)>; 4],
    z: (f32, f32),
    positions: Sides,
}

impl Assembly {
    fn new(levels: usize, mesh_max: (u32, u32), output: Output, numbering: Numbering) -> Self {
        Assembly {
            output,
            numbering,
            levels_wanted: levels,
            mesh_max,
            vertices: VertexOrder::new(),
            levels: Vec::with_capacity(levels),
            surfaces: Vec::with_capacity(levels),
            finest_surface: Vec::new(),
            cache: FifoCache::new(TILE_SIZE * TILE_SIZE),
            sides: Default::default(),
            z: (f32::INFINITY, f32::NEG_INFINITY),
            positions: Vec::with_capacity(levels),
        }
    }

    /// Adds the mesher's mesh as the next level: `leaves` its leaves in P-order, `errors` the
    /// entry's measured figures (the rest of the entry is filled here), `code_of` the height
    /// code of a lattice point, `set` the vertices the level adds where the caller knows them
    /// (a rebuild: [`Numbering::Decode`] then numbers them without walking the fans).
    fn add_level(
        &mut self,
        mesher: &Mesher,
        leaves: &[Quad],
        errors: LevelEntry,
        code_of: &dyn Fn(usize) -> u16,
        set: Option<&[(u32, u32, u16)]>,
    ) {
        let full = !matches!(self.output, Output::Sides | Output::SidesBare);
        let (level, n, mesh_max) = (self.levels.len(), self.levels_wanted, self.mesh_max);
        let vertices = &mut self.vertices;
        let block_start = vertices.lattice_of.len();
        let (indices, triangles) = if full {
            let decode = match (self.numbering, set) {
                (Numbering::Decode, Some(set)) => {
                    vertices.number_set_for_decoding(set);
                    false
                }
                (Numbering::Decode, None) => true,
                (Numbering::FirstUse, _) => false,
            };
            emit_fans(mesher, leaves, vertices, &mut self.cache, decode)
        } else {
            let mut fan = Vec::with_capacity(10);
            for &q in leaves {
                fan.clear();
                mesher.fan(q, &mut fan);
                for &(x, y) in &fan {
                    vertices.index(lattice(x, y));
                }
            }
            (Vec::new(), 0)
        };
        let heights = mesher.quantised_heights();
        let new = &vertices.lattice_of[block_start..];
        let block: Vec<u32> = if full {
            new.iter()
                .map(|&l| {
                    let (x, y) = xy(l);
                    pack(x, y, code_of(l as usize))
                })
                .collect()
        } else {
            Vec::new()
        };
        let sides = &mut self.sides;
        for (i, &l) in new.iter().enumerate() {
            let (x, y) = xy(l);
            let v = (block_start + i) as u32;
            self.z.0 = self.z.0.min(heights[l as usize]);
            self.z.1 = self.z.1.max(heights[l as usize]);
            for (k, on) in on_sides((x, y), mesh_max).into_iter().enumerate() {
                if on {
                    sides[k].push((if k % 2 == 0 { x } else { y }, v));
                }
            }
        }
        let border = [0, 1, 2, 3].map(|k| {
            sides[k].sort_unstable();
            sides[k].iter().map(|&(_, v)| v).collect::<Vec<u32>>()
        });
        self.positions
            .push([0, 1, 2, 3].map(|k| sides[k].iter().map(|&(at, _)| at as u16).collect()));
        // The agreement's meshes of the base grid want no surface: they are for the deviations.
        if (level + 1 < n && self.output != Output::SidesBare) || self.output == Output::LayerTile {
            let mut surface = rasterise_surface(mesher, leaves, mesh_max);
            along_sides(&mut surface, &self.positions[level], heights, mesh_max);
            if level + 1 < n {
                self.surfaces.push(surface);
            } else {
                self.finest_surface = surface;
            }
        }
        let vertex_count = vertices.lattice_of.len() as u32;
        let entry = LevelEntry {
            z_min: self.z.0,
            z_max: self.z.1,
            block_start: block_start as u32,
            block_len: vertex_count - block_start as u32,
            index_count: indices.len() as u32,
            index_width: if vertex_count <= u32::from(u16::MAX) {
                2
            } else {
                4
            },
            triangle_count: triangles,
            fan_count: leaves.len() as u32,
            border_len: [0, 1, 2, 3].map(|k| border[k].len() as u32),
            ..errors
        };
        self.levels.push(LevelOut {
            entry,
            block,
            indices,
            border,
        });
    }

    /// A layer tile's surfaces, interleaved by level (a lattice point's levels side by side);
    /// empty for other tiles.
    fn interleaved_surfaces(&mut self) -> Vec<f32> {
        if self.output != Output::LayerTile {
            return Vec::new();
        }
        let n = self.levels_wanted;
        let mut all = vec![f32::NAN; TILE_SIZE * TILE_SIZE * n];
        let finest = std::mem::take(&mut self.finest_surface);
        for (k, surface) in self.surfaces.iter().chain([&finest]).enumerate() {
            for (l, &z) in surface.iter().enumerate() {
                all[l * n + k] = z;
            }
        }
        all
    }

    /// The morph offsets at `units` metres a step and the tile's blob under `header`.
    fn seal(
        &mut self,
        header: &TileHeader,
        heights: &[f32],
        units: &[f64],
        table_levels: usize,
    ) -> (Vec<u8>, Vec<LevelStats>) {
        let morph = morph_offsets(
            &mut self.levels,
            &self.surfaces,
            &self.vertices.lattice_of,
            heights,
            units,
        );
        serialise(header, &mut self.levels, &morph, table_levels)
    }
}

/// Whether lattice point `(x, y)` lies on the N, E, S and W sides of a mesh extent whose last
/// column and row are `max_x`, `max_y`.
fn on_sides((x, y): (u32, u32), (max_x, max_y): (u32, u32)) -> [bool; 4] {
    [y == 0, x == max_x, y == max_y, x == 0]
}

/// The lattice point at `at` along side `k` (north, east, south, west) of a mesh.
fn side_point(k: usize, at: u16, (max_x, max_y): (u32, u32)) -> (u32, u32) {
    let at = u32::from(at);
    match k {
        0 => (at, 0),
        1 => (max_x, at),
        2 => (at, max_y),
        _ => (0, at),
    }
}

/// Rewrites a level's surface along the mesh's sides as the interpolation between that side's
/// vertices, computed from the side alone. The rasterised value is the same number in exact
/// arithmetic, but it comes from whichever triangle holds the point, and the neighbouring tile
/// has a different one; computed this way, two tiles with the same side vertices and heights
/// get the same f32, hence the same morph offsets.
fn along_sides(surface: &mut [f32], sides: &[Vec<u16>; 4], heights: &[f32], mesh_max: (u32, u32)) {
    for (k, side) in sides.iter().enumerate() {
        for pair in side.windows(2) {
            let (a, b) = (
                side_point(k, pair[0], mesh_max),
                side_point(k, pair[1], mesh_max),
            );
            let (ha, hb) = (
                f64::from(heights[lattice(a.0, a.1)]),
                f64::from(heights[lattice(b.0, b.1)]),
            );
            let span = f64::from(pair[1] - pair[0]);
            for at in pair[0]..=pair[1] {
                let t = f64::from(at - pair[0]) / span;
                let (x, y) = side_point(k, at, mesh_max);
                surface[lattice(x, y)] = (ha + (hb - ha) * t) as f32;
            }
        }
    }
}

/// Per level `k`, the largest distance of a finer vertex (one introduced after `k`) from level
/// `k`'s surface; 0 for the finest level, which nothing morphs to.
fn deviations(
    levels: &[LevelOut],
    surfaces: &[Vec<f32>],
    lattice_of: &[u32],
    heights: &[f32],
) -> Vec<f64> {
    let mut deviation = vec![0.0; levels.len()];
    for (k, surface) in surfaces.iter().enumerate() {
        let start = levels[k].entry.vertex_count() as usize;
        deviation[k] = lattice_of[start..]
            .iter()
            .map(|&l| (f64::from(surface[l as usize]) - f64::from(heights[l as usize])).abs())
            .fold(0.0, f64::max);
    }
    deviation
}

/// Morph offsets of each block `j` toward every coarser level `k < j` (row-major by `k`), in
/// `units` (metres per offset step, one per level); stores each level's unit in its entry.
fn morph_offsets(
    levels: &mut [LevelOut],
    surfaces: &[Vec<f32>],
    lattice_of: &[u32],
    heights: &[f32],
    units: &[f64],
) -> Vec<Vec<i8>> {
    for (out, &unit) in levels.iter_mut().zip(units) {
        out.entry.morph_unit = unit as f32;
    }
    levels
        .iter()
        .enumerate()
        .map(|(j, out)| {
            let block =
                &lattice_of[out.entry.block_start as usize..out.entry.vertex_count() as usize];
            let mut rows = Vec::with_capacity(j * block.len());
            for (k, surface) in surfaces.iter().enumerate().take(j) {
                let unit = f64::from(levels[k].entry.morph_unit);
                rows.extend(
                    block
                        .iter()
                        .map(|&l| morph_offset(heights[l as usize], surface[l as usize], unit)),
                );
            }
            rows
        })
        .collect()
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
    table_levels: usize,
) -> (Vec<u8>, Vec<LevelStats>) {
    debug_assert!(table_levels >= levels.len());
    let table =
        std::mem::size_of::<TileHeader>() + table_levels * std::mem::size_of::<LevelEntry>();
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
    let given = std::mem::size_of::<TileHeader>() + std::mem::size_of_val(&entries[..]);
    blob[std::mem::size_of::<TileHeader>()..given].copy_from_slice(bytemuck::cast_slice(&entries));
    (blob, stats)
}

/// Everything about a tile set that is not in its tiles.
#[derive(Clone, Debug, Default)]
pub struct TileSetMeta {
    pub description: String,
    pub voids_filled: u64,
    /// Write the tiles' levels compact (format version 4, [`crate::compact`]): each rebuilt
    /// as built before it is written.
    pub compact: bool,
}

/// Totals of a finished build.
#[derive(Clone, Debug, Default)]
pub struct BuildSummary {
    pub tiles: u64,
    /// Per level, summed over tiles.
    pub levels: Vec<LevelStats>,
    pub file_bytes: u64,
    /// Passes over the tiles until neighbours agreed on their sides, and the tiles meshed in
    /// them (0 and 0 with independent sides); the written tiles are one more pass.
    pub agreement_passes: u32,
    pub agreement_meshes: u64,
    /// Of those, the meshes that started from the tile's last (kept within a budget).
    pub agreement_resumed: u64,
    /// Per texture mip, summed over tiles (empty without textures).
    pub texture_mips: Vec<MipStats>,
    /// Thread-seconds spent making textures (filtering, compressing), over all workers.
    pub texture_seconds: f64,
    /// The tile pyramid's layers above the base, from layer 1 (empty without a pyramid). The
    /// figures above are the base grid's.
    pub pyramid: Vec<PyramidLayerSummary>,
}

/// Totals of one pyramid layer of a build.
#[derive(Clone, Debug, Default)]
pub struct PyramidLayerSummary {
    pub tiles: u64,
    /// Over all levels of all tiles.
    pub triangles: u64,
    pub bytes: u64,
    pub texture_bytes: u64,
    /// The largest decimation error of the layer's tiles, metres.
    pub decimation_error: f32,
    /// Per level, the largest error against the base grid's samples over the layer's tiles.
    pub base_errors: Vec<f64>,
    pub agreement_passes: u32,
}

/// One texture mip's totals over the tiles of a build.
#[derive(Clone, Copy, Debug, Default)]
pub struct MipStats {
    pub size: u32,
    pub bytes: u64,
    pub squared_error: f64,
    pub texels: u64,
}

impl MipStats {
    /// PSNR of the BC1 mips against the filtered ones, dB.
    pub fn psnr(&self) -> f64 {
        texture::psnr(self.squared_error, self.texels)
    }
}

/// Builds all tiles in parallel and streams them into `out` (temporary file, then rename).
/// At most a few tiles per worker are in flight, so memory does not grow with the tile count.
/// `progress` is called once per finished tile. No textures: see [`build_tileset_textured`].
pub fn build_tileset(
    grid: &Grid,
    params: &BuildParams,
    meta: &TileSetMeta,
    out: &Path,
    progress: &(dyn Fn() + Sync),
) -> Result<BuildSummary, BuildError> {
    build_tileset_textured(grid, params, None, meta, out, progress)
}

/// [`build_tileset`], with a texture tile beside each geometry tile when `texturing` says so.
pub fn build_tileset_textured(
    grid: &Grid,
    params: &BuildParams,
    texturing: Option<&Texturing>,
    meta: &TileSetMeta,
    out: &Path,
    progress: &(dyn Fn() + Sync),
) -> Result<BuildSummary, BuildError> {
    if grid.first_row != 0 || grid.heights.len() != grid.width * grid.height {
        return Err(BuildError::Params(
            "height grid length does not match its size".into(),
        ));
    }
    build_tileset_from(grid, params, texturing, meta, out, progress)
}

/// What a first pass over the heights finds: the range, the height lattice's step, and the
/// cell spans that bound the set's morph units ([`crate::units`]).
pub(crate) struct Scanned {
    pub lo: f32,
    pub hi: f32,
    /// The largest absolute height (with the largest span, what the step follows from).
    pub max_abs: f32,
    pub step: f32,
    pub spans: CellSpans,
}

/// One pass over the grid, band by band: refuses a non-finite height and finds the range of
/// heights and the lattice step ([`height_step`]'s, over the bands' tiles).
pub(crate) fn scan(bands: &Bands) -> Result<Scanned, BuildError> {
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    let mut max_abs = 0.0f32;
    let mut spans = CellSpans::default();
    for b in 0..bands.count() {
        let band = bands.load(b, 0)?;
        if let Some(bad) = band.rows.iter().find(|h| !h.is_finite()) {
            return Err(BuildError::Params(format!(
                "height grid holds a non-finite value ({bad})"
            )));
        }
        for &h in band.rows.iter() {
            lo = lo.min(h);
            hi = hi.max(h);
        }
        let grid = band.grid(&bands.shape);
        let (found, abs) = cell_spans(&grid, bands.tiles.0, band.tile_rows.clone());
        for (s, f) in spans.iter_mut().zip(found) {
            *s = s.max(f);
        }
        max_abs = max_abs.max(abs);
    }
    Ok(Scanned {
        lo,
        hi,
        max_abs,
        step: lattice_step(spans[CELL_SIZES - 1], max_abs),
        spans,
    })
}

/// A build's options checked before any work: the levels and, for a relief, its sun.
pub(crate) fn validate(
    params: &BuildParams,
    texturing: Option<&Texturing>,
) -> Result<(), BuildError> {
    params.validate()?;
    if let Some(Texturing {
        source: Source::Relief(r),
        ..
    }) = texturing
    {
        r.validate().map_err(BuildError::Params)?;
    }
    Ok(())
}

/// The set's header, as the writer is given it: the grid, the options and what the scan found.
pub(crate) fn set_header(
    shape: &Grid,
    params: &BuildParams,
    texturing: Option<&Texturing>,
    meta: &TileSetMeta,
    &Scanned { lo, hi, step, .. }: &Scanned,
) -> Result<FileHeader, BuildError> {
    let (tiles_x, tiles_y) = tile_count(shape.width, shape.height).map_err(BuildError::Params)?;
    let mut description = [0u8; 128];
    let text = meta.description.as_bytes();
    let mut cut = text.len().min(description.len());
    while !meta.description.is_char_boundary(cut) {
        cut -= 1;
    }
    description[..cut].copy_from_slice(&text[..cut]);
    let header = FileHeader {
        grid_width: shape.width as u32,
        grid_height: shape.height as u32,
        tiles_x,
        tiles_y,
        tile_size: TILE_SIZE as u32,
        levels: params.levels,
        spacing_x: shape.spacing_x,
        spacing_y: shape.spacing_y,
        base_error: params.base_error,
        height_min: lo,
        height_max: hi,
        voids_filled: meta.voids_filled,
        description,
        height_step: step,
        ..bytemuck::Zeroable::zeroed()
    };
    let header = FileHeader {
        flags: if params.shared_sides {
            FLAG_SHARED_SIDES
        } else {
            0
        } | if meta.compact {
            crate::format::FLAG_COMPACT_LEVELS
        } else {
            0
        },
        pyramid_layers: if params.pyramid {
            pyramid_layers(shape.width, shape.height)
        } else {
            0
        },
        ..header
    };
    let header = match texturing {
        Some(t) => FileHeader {
            texture_format: texture::FORMAT_BC1,
            texture_interior: t.layout.interior,
            texture_gutter: t.layout.gutter,
            texture_mips: t.layout.mips,
            texture_source: t.source_code(),
            ..header
        },
        None => header,
    };
    Ok(header)
}

/// [`build_tileset_textured`] from any [`Heights`]: a grid held whole is one band; a grid
/// read in bands is read once to scan it, once per agreement pass for the bands with tiles to
/// mesh again, and once to build, a band at a time, so that memory holds one band (and its
/// texture margin), not the grid. The bytes are the same either way.
pub fn build_tileset_from(
    heights: &dyn Heights,
    params: &BuildParams,
    texturing: Option<&Texturing>,
    meta: &TileSetMeta,
    out: &Path,
    progress: &(dyn Fn() + Sync),
) -> Result<BuildSummary, BuildError> {
    build_tileset_at(heights, params, (texturing, meta), out, progress, None)
}

/// [`build_tileset_from`] with the base grid's morph unit bounds given (`None`: from the
/// scan, [`crate::units`]): for the tests of a tile that passes its bound, which no input
/// here reaches.
#[doc(hidden)]
pub fn build_tileset_at(
    heights: &dyn Heights,
    params: &BuildParams,
    (texturing, meta): (Option<&Texturing>, &TileSetMeta),
    out: &Path,
    progress: &(dyn Fn() + Sync),
    bounds: Option<Vec<f64>>,
) -> Result<BuildSummary, BuildError> {
    validate(params, texturing)?;
    let shape = heights.shape();
    let (tiles_x, tiles_y) = tile_count(shape.width, shape.height).map_err(BuildError::Params)?;
    let bands = Bands::new(heights, (tiles_x, tiles_y));
    let scanned = scan(&bands)?;
    let Scanned { lo, hi, step, .. } = scanned;
    let header = set_header(&shape, params, texturing, meta, &scanned)?;
    // The relief's tint spans the base grid's heights in every layer, so that colours match.
    let prepared = texturing.map(|t| (Prepared::new((lo, hi), &t.source), t.layout));
    let fresh = || BuildSummary {
        levels: vec![LevelStats::default(); params.levels as usize],
        texture_mips: texturing
            .map(|t| {
                (0..t.layout.mips)
                    .map(|m| MipStats {
                        size: t.layout.mip_size(m),
                        ..MipStats::default()
                    })
                    .collect()
            })
            .unwrap_or_default(),
        ..Default::default()
    };
    let spacing = shape.spacing_x.min(shape.spacing_y);
    let mut bounds =
        bounds.unwrap_or_else(|| deviation_bounds(params, spacing, step, &scanned.spans));
    let (mut writer, mut summary) = loop {
        let (mut writer, mut summary) = (TileSetWriter::create(out, header)?, fresh());
        let base = Layer {
            index: 0,
            bands: &bands,
            step,
            bounds: bounds.clone(),
            decimation: None,
            prepared: prepared.as_ref().map(|(p, l)| (p.for_layer(0), *l)),
            base: None,
        };
        match build_layer(&mut writer, &base, params, progress, &mut summary)? {
            None => break (writer, summary),
            // A tile passed the scan's bounds: the units rise to hold it, and the
            // base grid is built again at them, the same meshes sealed again.
            Some(raised) if raised != bounds => bounds = raised,
            Some(_) => {
                let what = "the morph units did not hold at bounds raised to the deviations";
                return Err(BuildError::Internal(what.into()));
            }
        }
    };
    build_pyramid(
        &mut writer,
        heights,
        params,
        (&header, &scanned),
        prepared.as_ref(),
        progress,
        &mut summary,
    )?;
    writer.finish()?;
    summary.file_bytes = std::fs::metadata(out).map(|m| m.len()).unwrap_or(0);
    Ok(summary)
}

/// The pyramid's layers above a base grid already written: each layer from the grid
/// subsampled, its error bound from the layer below, its tiles measured against the base
/// grid (a build's last step, and a sharded build's merge's).
pub(crate) fn build_pyramid(
    writer: &mut TileSetWriter,
    heights: &dyn Heights,
    params: &BuildParams,
    (header, base): (&FileHeader, &Scanned),
    prepared: Option<&(Prepared, texture::Layout)>,
    progress: &(dyn Fn() + Sync),
    summary: &mut BuildSummary,
) -> Result<(), BuildError> {
    let (tiles_x, tiles_y) = (header.tiles_x, header.tiles_y);
    // The pyramid: each layer from the grid subsampled, its error bound from the layer below.
    let mut below = vec![0.0f32; (tiles_x * tiles_y) as usize];
    let mut below_tiles_x = tiles_x;
    let mut bounds = LayerBounds::above(base);
    for p in 1..=header.pyramid_layers {
        let layer_heights = Decimated::new(heights, p);
        let finer = Decimated::new(heights, p - 1);
        let finer: &dyn Heights = if p == 1 { heights } else { &finer };
        let l = writer.layers()[p as usize - 1];
        let decimation = decimation_errors(
            finer,
            &below,
            below_tiles_x,
            (l.tiles_x, l.tiles_y),
            0..l.tiles_y,
        )?;
        let layer_bands = Bands::new(&layer_heights, (l.tiles_x, l.tiles_y));
        let scanned = scan(&layer_bands)?;
        writer.set_layer_heights(p, scanned.step, scanned.lo, scanned.hi);
        let mut layer_summary = BuildSummary {
            levels: vec![LevelStats::default(); params.levels as usize],
            texture_mips: summary
                .texture_mips
                .iter()
                .map(|m| MipStats {
                    bytes: 0,
                    squared_error: 0.0,
                    texels: 0,
                    ..*m
                })
                .collect(),
            ..Default::default()
        };
        let layer = Layer {
            index: p,
            bands: &layer_bands,
            step: scanned.step,
            bounds: bounds.next(params, &layer_heights, &scanned),
            decimation: Some(&decimation),
            prepared: prepared.map(|(s, l)| (s.for_layer(p), *l)),
            base: Some(heights),
        };
        if build_layer(writer, &layer, params, progress, &mut layer_summary)?.is_some() {
            // Its units follow its tiles' deviations, found by the same meshes as its build.
            return Err(BuildError::Internal(format!(
                "pyramid layer {p}: a tile passed the layer's morph units"
            )));
        }
        summary.pyramid.push(PyramidLayerSummary {
            tiles: layer_summary.tiles,
            triangles: layer_summary.levels.iter().map(|l| l.triangles).sum(),
            bytes: layer_summary.levels.iter().map(|l| l.bytes).sum(),
            texture_bytes: layer_summary.texture_mips.iter().map(|m| m.bytes).sum(),
            decimation_error: decimation.iter().fold(0.0f32, |a, &d| a.max(d)),
            base_errors: layer_summary.levels.iter().map(|l| l.max_error).collect(),
            agreement_passes: layer_summary.agreement_passes,
        });
        summary.texture_seconds += layer_summary.texture_seconds;
        (below, below_tiles_x) = (decimation, l.tiles_x);
    }
    Ok(())
}

/// The spacing a layer's mesher holds its spacing rule to: the smaller of its two.
pub(crate) fn spacing_of(heights: &dyn Heights) -> f64 {
    let shape = heights.shape();
    shape.spacing_x.min(shape.spacing_y)
}

/// One layer of a build: the base grid (`index` 0) or a pyramid layer, read in bands.
pub(crate) struct Layer<'a> {
    pub index: u32,
    pub bands: &'a Bands<'a>,
    /// The layer's height lattice step.
    pub step: f32,
    /// Per level, the floor of its morph units ([`crate::units`]).
    pub bounds: Vec<f64>,
    /// Per tile (row-major), its decimation error (None: the base grid, all 0).
    pub decimation: Option<&'a [f32]>,
    pub prepared: Option<(Prepared<'a>, texture::Layout)>,
    /// Above the base: the base grid, which the layer's levels are measured against.
    pub base: Option<&'a dyn Heights>,
}

/// Builds one layer's tiles, shared sides agreed first where the build asks for them, and
/// writes them (with their textures) in row-major order, whatever order they finish in, so
/// that the same input and options give the same bytes. With shared sides, the bounds the
/// layer's units must rise to where a tile's final build found a deviation past them (then
/// its tiles were sealed with offsets clamped, and the layer is to be built again at those
/// bounds: [`build_tileset_from`]); `None` where the units held.
fn build_layer(
    writer: &mut TileSetWriter,
    layer: &Layer,
    params: &BuildParams,
    progress: &(dyn Fn() + Sync),
    summary: &mut BuildSummary,
) -> Result<Option<Vec<f64>>, BuildError> {
    let agreements = if params.shared_sides {
        let agreed = agree_sides(
            layer.bands,
            params,
            (layer.step, &layer.bounds),
            layer.decimation,
            Remesh::Changed,
        )?;
        summary.agreement_passes = agreed.passes;
        summary.agreement_meshes = agreed.meshes;
        summary.agreement_resumed = agreed.resumed;
        Some(agreed)
    } else {
        None
    };
    let rows = 0..layer.bands.tiles.1;
    let mut widest = vec![0.0f64; params.levels as usize];
    build_tiles(
        layer,
        params,
        agreements.as_ref(),
        rows,
        &mut |t, made, errors| {
            for (w, &d) in widest.iter_mut().zip(&made.0.deviation) {
                *w = w.max(d);
            }
            write_tile(writer, layer, summary, t, made, errors, progress)
        },
    )?;
    Ok(agreements.and_then(|a| {
        let held = units_of(&layer.bounds, [&widest]) == a.units;
        (!held).then(|| {
            layer
                .bounds
                .iter()
                .zip(&widest)
                .map(|(b, w)| b.max(*w))
                .collect()
        })
    }))
}

/// Where [`build_tiles`] hands each tile: its index in the layer (row-major), the tile and
/// its texture, and above the base its levels' errors against the base grid.
pub(crate) type TileSink<'s> =
    dyn FnMut(usize, (BuiltTile, Option<MadeTexture>), &[f32]) -> Result<(), BuildError> + 's;

/// Builds the tiles of tile rows `rows` of a layer, with the agreement settled for them (its
/// window holds `rows`) or on their own, and hands them to `sink` in row-major order.
pub(crate) fn build_tiles(
    layer: &Layer,
    params: &BuildParams,
    agreements: Option<&Agreed>,
    rows: std::ops::Range<u32>,
    sink: &mut TileSink,
) -> Result<(), BuildError> {
    let bands = layer.bands;
    let (tiles_x, step) = (bands.tiles.0, layer.step);

    let margin = layer
        .prepared
        .as_ref()
        .map_or(0, |(_, l)| l.rows_beyond_tile());
    // At most a few tiles per worker are in flight, so memory does not grow with the tiles.
    let in_flight = 2 * rayon::current_num_threads();
    let floor = |t: usize| layer.decimation.map_or(0.0, |d| level_floor(d[t]));
    for b in 0..bands.count() {
        let band_rows = bands.tile_rows(b);
        let (r0, r1) = (band_rows.start.max(rows.start), band_rows.end.min(rows.end));
        if r0 >= r1 {
            continue;
        }
        let band = bands.load(b, margin)?;
        let grid = band.grid(&bands.shape);
        let first = (r0 * tiles_x) as usize;
        let count = ((r1 - r0) * tiles_x) as usize;
        let layer_tile = layer.base.is_some();
        let make = |i: usize| {
            let t = first + i;
            let (tx, ty) = (t as u32 % tiles_x, t as u32 / tiles_x);
            // A layer's tiles keep their levels' surfaces, to be measured against the base.
            let output = if layer_tile {
                Output::LayerTile
            } else {
                Output::Tile
            };
            let mesh = |agreement: &Agreement| {
                mesh_tile(&grid, (tx, ty), params, step, agreement, (output, None))
            };
            let built = match agreements {
                Some(a) => {
                    let agreement = Agreement {
                        forced: expand(&a.forced[t - a.first]),
                        units: Some(a.units.clone()),
                        floor: floor(t),
                    };
                    mesh(&agreement).and_then(|b| {
                        if compact(&b.sides) == a.sides[t - a.first] {
                            Ok(b)
                        } else {
                            Err(BuildError::Internal(format!(
                                "tile {tx},{ty}: its sides changed after agreement"
                            )))
                        }
                    })
                }
                None => mesh(&Agreement {
                    floor: floor(t),
                    ..Agreement::default()
                }),
            };
            built.map(|b| {
                let texture = layer.prepared.as_ref().map(|(source, layout)| {
                    let start = std::time::Instant::now();
                    let (blob, mips) = texture::build_blob(&grid, source, layout, (tx, ty));
                    (blob, mips, start.elapsed().as_secs_f64())
                });
                (b, texture)
            })
        };
        // A layer's tiles wait for the band (one tile row) to be measured against the base
        // grid; the base grid's are written as they come.
        let mut held = Vec::new();
        let mut write = |i: usize, made, errors: &[f32]| sink(first + i, made, errors);
        crate::ordered::in_order(count, in_flight, make, |i, built| {
            let (built, texture) = built?;
            if layer_tile {
                held.push((i, built, texture));
                Ok(())
            } else {
                write(i, (built, texture), &[])
            }
        })?;
        if let Some(base) = layer.base {
            let levels = params.levels as usize;
            let surfaces: Vec<Surfaces> = held
                .iter()
                .map(|(_, b, _)| Surfaces {
                    tx: b.tx,
                    surfaces: &b.surfaces,
                    data_max: b.data_max,
                })
                .collect();
            let errors = match held.first() {
                Some((_, b, _)) => base_errors(base, layer.index, b.ty, levels, &surfaces)?,
                None => Vec::new(),
            };
            drop(surfaces);
            for ((i, built, texture), errors) in held.drain(..).zip(errors) {
                write(i, (built, texture), &errors)?;
            }
        }
    }
    Ok(())
}

/// A tile's texture blob, its mips' figures and the thread-seconds it took.
pub(crate) type MadeTexture = (Vec<u8>, Vec<texture::MipEntry>, f64);

/// A built tile (of `layer`, directory slot `t`) and its texture into the file and the summary.
fn write_tile(
    writer: &mut TileSetWriter,
    layer: &Layer,
    summary: &mut BuildSummary,
    t: usize,
    (built, texture): (BuiltTile, Option<MadeTexture>),
    base_errors: &[f32],
    progress: &(dyn Fn() + Sync),
) -> Result<(), BuildError> {
    let d = layer.decimation.map_or(0.0, |d| d[t]);
    writer.add_layer_tile(layer.index, built.tx, built.ty, &built.blob, d, base_errors)?;
    if let Some((blob, mips, seconds)) = texture {
        writer.add_layer_texture(layer.index, built.tx, built.ty, &blob)?;
        summary.texture_seconds += seconds;
        for (sum, m) in summary.texture_mips.iter_mut().zip(&mips) {
            sum.bytes += u64::from(m.len);
            sum.squared_error += m.squared_error;
            sum.texels += m.texels;
        }
    }
    summary.tiles += 1;
    for (k, (sum, l)) in summary.levels.iter_mut().zip(&built.levels).enumerate() {
        sum.vertices += l.vertices;
        sum.triangles += l.triangles;
        sum.bytes += l.bytes;
        // A layer's errors against the base grid: what the renderer goes by.
        let e = base_errors.get(k).map_or(l.max_error, |&e| f64::from(e));
        sum.max_error = sum.max_error.max(e);
        sum.limited_triangles += l.limited_triangles;
        sum.limited_excess = sum.limited_excess.max(l.limited_excess);
    }
    progress();
    Ok(())
}

/// Passes over the tile set until every pair of neighbours agrees on their shared side: the
/// same vertices at every level. Returns, per tile (row-major), the agreement to build it with
/// and the sides it will then have, with the number of passes and of tiles meshed.
///
/// A tile is built forcing, on each shared side, the union of its own side vertices and its
/// neighbour's from the last pass. Forced vertices can cascade into more side vertices (2:1
/// splits), so the sets only grow, and the passes stop when a pass changes none: then each
/// tile holds its neighbour's set and the neighbour holds its, so the two are equal. A tile
/// is meshed again only when its forced sides changed, since a mesh is a function of them
/// (the rule before meshed every tile next to a change: a third more meshes, the same
/// result). The morph units are then the set's, the same for every tile ([`units_of`]), so a
/// side vertex's offsets (same surface, same height) are the same bytes in both tiles.
///
/// The sides settled are the least fixed point of "a tile's sides are those of its mesh with
/// its own and its neighbours' sides forced": the passes climb to it from nothing, and reach
/// the same point from any state below it ([`settle`], which a distributed build's merge
/// resumes from its shards' states; `crate::shard` argues it).
fn agree_sides(
    bands: &Bands,
    params: &BuildParams,
    (step, bounds): (f32, &[f64]),
    floors: Option<&[f32]>,
    remesh: Remesh,
) -> Result<Agreed, BuildError> {
    let mut agreed = settle(bands, params, step, floors, remesh, 0..bands.tiles.1, None)?;
    agreed.units = units_of(bounds, &agreed.deviation);
    Ok(agreed)
}

/// Per level, the morph unit of a set whose tiles' deviations are `deviation` (per tile, per
/// level): the largest any tile needs, and at least the layer's bound (`bounds`,
/// [`crate::units`]), so that a shared vertex's offsets are the same bytes in both its tiles
/// and a shard, seeing some of the tiles, finds the set's units.
pub(crate) fn units_of<'d>(
    bounds: &[f64],
    deviation: impl IntoIterator<Item = &'d Vec<f64>> + Clone,
) -> Vec<f64> {
    (0..bounds.len())
        .map(|k| {
            let widest = deviation
                .clone()
                .into_iter()
                .map(|d| d[k])
                .fold(0.0, f64::max);
            morph_unit(bounds[k], widest)
        })
        .collect()
}

/// Where [`settle`] starts from: each tile's sides, the forced sides it was last meshed with
/// and that mesh's deviations (a shard's state, or the tiles meshed by several shards; in the
/// base grid, whose agreement finds none, the final builds' that the parts recorded).
pub(crate) struct Start {
    pub sides: Vec<CompactSides>,
    pub forced: Vec<CompactSides>,
    pub deviation: Vec<Vec<f64>>,
}

/// The agreement's passes over tile rows `rows` of the layer, tiles beyond them taken as
/// absent (a shard's window; the whole layer for a build). From nothing, or from `start`
/// (one entry per tile of `rows`, row-major): then only the tiles whose forced sides are not
/// what they were last meshed with are meshed first. `units` is left empty.
pub(crate) fn settle(
    bands: &Bands,
    params: &BuildParams,
    step: f32,
    floors: Option<&[f32]>,
    remesh: Remesh,
    rows: std::ops::Range<u32>,
    start: Option<Start>,
) -> Result<Agreed, BuildError> {
    let tiles_x = bands.tiles.0;
    let first = rows.start as usize * tiles_x as usize;
    /// Far more than any data needs (a change spreads one tile per pass).
    const MAX_PASSES: u32 = 1000;
    let count = (rows.len() as u32 * tiles_x) as usize;
    let levels = params.levels as usize;
    // Tiles are numbered from the window's first: `t` is tile `first + t` of the layer.
    let window = (tiles_x, rows.len() as u32);
    let neighbour = |t: usize, k: usize| neighbour_of(t, k, window);
    let forced = |t: usize, sides: &[CompactSides]| forced_sides(t, sides, levels, window);
    // A pyramid layer's units follow its tiles' deviations; the base grid's come from the
    // scan, so its meshes here find none (each tile's final build does).
    let output = match floors {
        Some(_) => Output::Sides,
        None => Output::SidesBare,
    };
    // The state is per tile, so it grows with the set: side vertices are held as bitmaps
    // (1.4 KB a tile and copy at 9 levels; lists of u16 took about 40 KB a tile in all).
    // `meshed_with` is what each tile was last meshed with: a build is a function of its
    // forced sides, so a tile whose forced sides are what they were needs no new mesh.
    let (mut sides, mut meshed_with, mut deviation) = match start {
        Some(s) => (
            s.sides,
            s.forced.into_iter().map(Some).collect(),
            s.deviation,
        ),
        None => (
            vec![Vec::new(); count],
            vec![None; count],
            vec![vec![0.0f64; levels]; count],
        ),
    };
    if sides.len() != count || meshed_with.len() != count || deviation.len() != count {
        return Err(BuildError::Internal(format!(
            "the agreement's start holds {} tiles, not {count}",
            sides.len()
        )));
    }
    // The tiles to mesh in the next pass: every tile not meshed with its forced sides as they
    // are (all of them from nothing).
    let stale = |t: usize, sides: &[CompactSides], meshed_with: &[Option<CompactSides>]| {
        meshed_with[t].as_ref() != Some(&forced(t, sides))
    };
    let mut dirty: Vec<usize> = (0..count)
        .filter(|&t| stale(t, &sides, &meshed_with))
        .collect();
    let (mut passes, mut rebuilt, mut resumed) = (0u32, 0u64, 0u64);
    // Each tile's last mesh, kept while they fit a budget (a start's tiles have none: their
    // first mesh here is from nothing).
    let budget = match remesh {
        Remesh::KeepingAtMost(tiles) => tiles * MeshHistory::BYTES,
        _ => HISTORY_BUDGET,
    };
    let mut histories = Histories::new(count, budget);
    while !dirty.is_empty() {
        passes += 1;
        if passes > MAX_PASSES {
            return Err(BuildError::Internal(format!(
                "tile sides still changing after {MAX_PASSES} passes"
            )));
        }
        let mut next = vec![false; count];
        // Band by band, in row-major order: each band read only when one of its tiles is to
        // be meshed again (dirty when the pass began, or next to a change made since). Within a band, the tiles of one colour of a
        // checkerboard, then the other's with the first colour's new sides forced: no tile
        // has a neighbour of its own colour, so each colour's tiles mesh in parallel, and the
        // second waits for nothing it could have had. Meshing is monotone in what is
        // forced, so any order of the updates climbs to the same least fixed point (see
        // `crate::shard`); this one meshes each tile fewer times than passes that mesh every
        // tile from the state before the pass.
        let mut pending = vec![false; count];
        for &t in &dirty {
            pending[t] = true;
        }
        // The tests' reference order: every tile of the pass from the state before it.
        let jacobi = remesh == Remesh::FromThePassBefore;
        let before = jacobi.then(|| sides.clone());
        let phases: &[Option<usize>] = if jacobi { &[None] } else { &[Some(0), Some(1)] };
        for b in 0..bands.count() {
            // The band's tiles of the window, and of them those to look at: dirty when the
            // pass began, or next to a change made since.
            let band_rows = bands.tile_rows(b);
            let (r0, r1) = (band_rows.start.max(rows.start), band_rows.end.min(rows.end));
            if r0 >= r1 {
                continue;
            }
            let span =
                (r0 as usize * tiles_x as usize - first)..(r1 as usize * tiles_x as usize - first);
            let looked_at = |t: usize, next: &[bool]| pending[t] || (!jacobi && next[t]);
            if !span.clone().any(|t| looked_at(t, &next)) {
                continue;
            }
            let band = bands.load(b, 0)?;
            let grid = band.grid(&bands.shape);
            for &colour in phases {
                let state = before.as_deref().unwrap_or(&sides);
                let batch: Vec<(usize, CompactSides)> = span
                    .clone()
                    .filter(|&t| looked_at(t, &next))
                    .filter(|&t| {
                        let g = first + t;
                        colour
                            .is_none_or(|c| (g % tiles_x as usize + g / tiles_x as usize) % 2 == c)
                    })
                    .map(|t| (t, forced(t, state)))
                    .filter(|(t, f)| {
                        remesh == Remesh::NextToChange || meshed_with[*t].as_ref() != Some(f)
                    })
                    .collect();
                rebuilt += batch.len() as u64;
                resumed += batch
                    .iter()
                    .filter(|(t, _)| histories.get(*t).is_some())
                    .count() as u64;
                let meshed: Vec<Meshed> = batch
                    .par_iter()
                    .map(|(t, forced)| {
                        let g = first + *t;
                        let (tx, ty) = (g as u32 % tiles_x, g as u32 / tiles_x);
                        let agreement = Agreement {
                            forced: expand(forced),
                            units: None,
                            floor: floors.map_or(0.0, |d| level_floor(d[g])),
                        };
                        // Forced sides only grow, so the tile's last mesh (if kept) holds
                        // less than this one: it is where this mesh starts.
                        let earlier = histories.get(*t);
                        mesh_tile(&grid, (tx, ty), params, step, &agreement, (output, earlier))
                            .map(|b| (*t, compact(&b.sides), b.deviation, b.history))
                    })
                    .collect::<Result<_, _>>()?;
                for ((t, new, d, history), (_, used)) in meshed.into_iter().zip(batch) {
                    if let Some(history) = history {
                        histories.put(t, history);
                    }
                    deviation[t] = d;
                    meshed_with[t] = Some(used);
                    if new != sides[t] {
                        sides[t] = new;
                        next[t] = true;
                        for k in 0..4 {
                            if let Some(n) = neighbour(t, k) {
                                next[n] = true;
                            }
                        }
                    }
                }
            }
        }
        // Of the tiles next to a change, those whose forced sides changed since their mesh.
        dirty = (0..count)
            .filter(|&t| next[t])
            .filter(|&t| remesh == Remesh::NextToChange || stale(t, &sides, &meshed_with))
            .collect();
    }
    // Each tile now holds its neighbour's side and the neighbour holds its: they are equal.
    for t in 0..count {
        for k in [1, 2] {
            let Some(n) = neighbour(t, k) else { continue };
            if (0..levels).any(|l| sides[t][l][k] != sides[n][l][(k + 2) % 4]) {
                return Err(BuildError::Internal(format!(
                    "tiles {} and {} still disagree on their side after {passes} passes",
                    first + t,
                    first + n
                )));
            }
        }
    }
    // Every tile was last meshed with its forced sides as they are now: a tile whose forced
    // sides changed after its last mesh would be in `dirty`. So those are its agreement, and
    // no further copy of the sides is made (the state is per tile: it grows with the set).
    let forced = meshed_with
        .into_iter()
        .enumerate()
        .map(|(t, f)| {
            f.ok_or_else(|| BuildError::Internal(format!("tile {} was never meshed", first + t)))
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Agreed {
        first,
        forced,
        sides,
        deviation,
        units: Vec::new(),
        passes,
        meshes: rebuilt,
        resumed,
    })
}

/// A tile meshed by the agreement: its number, sides, deviations and mesh history.
type Meshed = (usize, CompactSides, Vec<f64>, Option<MeshHistory>);

/// Bytes of mesh histories the agreement keeps: every tile of a 16K set (4,096 tiles, 88 KB
/// each); a larger set's tiles past it are meshed again from nothing, as before histories.
const HISTORY_BUDGET: usize = 400 << 20;

/// The agreement's last mesh of each tile, as many as fit a budget; when full, the oldest
/// kept makes room (a pass sweeps the bands in order, so the oldest is the furthest from the
/// tiles being meshed).
struct Histories {
    kept: Vec<Option<MeshHistory>>,
    order: std::collections::VecDeque<usize>,
    room: usize,
}

impl Histories {
    fn new(tiles: usize, budget: usize) -> Histories {
        Histories {
            kept: vec![None; tiles],
            order: std::collections::VecDeque::new(),
            room: budget / MeshHistory::BYTES,
        }
    }

    fn get(&self, t: usize) -> Option<&MeshHistory> {
        self.kept[t].as_ref()
    }

    fn put(&mut self, t: usize, history: MeshHistory) {
        if self.kept[t].replace(history).is_none() {
            self.order.push_back(t);
        }
        while self.order.len() > self.room {
            if let Some(oldest) = self.order.pop_front() {
                self.kept[oldest] = None;
            }
        }
    }
}

/// Tile `t`'s neighbour across side `k` (north, east, south, west) among `tiles_x` x
/// `tiles_y` tiles numbered row-major; none past the edge.
fn neighbour_of(t: usize, k: usize, (tiles_x, tiles_y): (u32, u32)) -> Option<usize> {
    let (tx, ty) = ((t as u32 % tiles_x) as i64, (t as u32 / tiles_x) as i64);
    let (nx, ny) = match k {
        0 => (tx, ty - 1),
        1 => (tx + 1, ty),
        2 => (tx, ty + 1),
        _ => (tx - 1, ty),
    };
    ((0..i64::from(tiles_x)).contains(&nx) && (0..i64::from(tiles_y)).contains(&ny))
        .then(|| (ny * i64::from(tiles_x) + nx) as usize)
}

/// The agreement's rule: what tile `t` is meshed with, on each side and level its own side
/// vertices and its neighbour's (`sides` per tile of `tiles`, row-major).
pub(crate) fn forced_sides(
    t: usize,
    sides: &[CompactSides],
    levels: usize,
    tiles: (u32, u32),
) -> CompactSides {
    (0..levels)
        .map(|level| {
            std::array::from_fn(|k| {
                let Some(n) = neighbour_of(t, k, tiles) else {
                    return NO_SIDE;
                };
                let theirs = sides[n].get(level).map_or(NO_SIDE, |s| s[(k + 2) % 4]);
                let ours = sides[t].get(level).map_or(NO_SIDE, |s| s[k]);
                std::array::from_fn(|w| ours[w] | theirs[w])
            })
        })
        .collect()
}

/// Which tiles a pass of [`agree_sides`] meshes again.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Remesh {
    /// Those next to a change whose forced sides changed (the build's).
    Changed,
    /// Every tile next to a change (the rule before; the tests' reference).
    #[cfg_attr(not(test), allow(dead_code))]
    NextToChange,
    /// Those whose forced sides changed, every tile of a pass meshed from the state before
    /// the pass rather than in the checkerboard's order (the order before; the tests'
    /// reference for it).
    #[cfg_attr(not(test), allow(dead_code))]
    FromThePassBefore,
    /// [`Remesh::Changed`] keeping the last meshes of at most this many tiles, not the
    /// budget's (0: every mesh from nothing, the rule before mesh histories; the tests'
    /// reference for them, and for a budget that drops some).
    #[cfg_attr(not(test), allow(dead_code))]
    KeepingAtMost(usize),
}

/// One side's vertices at one level: bit `i` for position `i` (0..=256).
pub(crate) type SideBits = [u64; 5];

const NO_SIDE: SideBits = [0; 5];

/// A tile's side vertices per level and side (north, east, south, west), as bitmaps: the
/// agreement's state, a [`Sides`] in 40 bytes a side and level.
pub(crate) type CompactSides = Vec<[SideBits; 4]>;

fn compact(sides: &Sides) -> CompactSides {
    sides
        .iter()
        .map(|level| {
            level.each_ref().map(|side| {
                let mut bits = NO_SIDE;
                for &at in side {
                    bits[usize::from(at) / 64] |= 1 << (at % 64);
                }
                bits
            })
        })
        .collect()
}

/// The positions of a [`CompactSides`], ascending.
fn expand(sides: &CompactSides) -> Sides {
    sides
        .iter()
        .map(|level| {
            level.each_ref().map(|bits| {
                (0..TILE_SIZE as u16)
                    .filter(|&at| bits[usize::from(at) / 64] & (1 << (at % 64)) != 0)
                    .collect()
            })
        })
        .collect()
}

/// What [`agree_sides`] or [`settle`] settled.
pub(crate) struct Agreed {
    /// The layer's index of the first tile below (0 but for a shard's window).
    pub first: usize,
    /// Per tile (row-major from `first`): the side vertices to build it with (its
    /// [`Agreement::forced`]), the sides it will then have, and its deviations per level
    /// (pyramid layers'; the base grid's meshes here find none, [`Output::SidesBare`]).
    pub forced: Vec<CompactSides>,
    pub sides: Vec<CompactSides>,
    pub deviation: Vec<Vec<f64>>,
    /// Per level, the morph unit of every tile (empty until the caller sets it).
    pub units: Vec<f64>,
    pub passes: u32,
    /// Tiles meshed over all passes.
    pub meshes: u64,
    /// Of those, the meshes that started from the tile's last ([`Mesher::refine_changed`]).
    pub resumed: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What the agreement reads of a tile (`Output::Sides`: no fan order, arrays or blob) is
    /// what the whole build makes of it, with and without forced sides.
    #[test]
    fn a_mesh_for_the_agreement_has_the_whole_builds_sides_and_deviations() {
        let heights = srtm3_crop(2 * 256 + 1);
        let grid = square(&heights);
        agreement_meshes_of(&grid);
        // A tile whose data end on an odd column and row (272 x 300 samples: tile (1, 1)
        // holds 16 x 44 of them, meshed to 16 x 44 with a copied column): its east and south
        // sides meet vertices at the centres of the cells the extent crosses.
        let (width, height) = (256 + 16, 256 + 44);
        let cropped: Vec<f32> = (0..width * height)
            .map(|i| heights[(i / width) * grid.width + i % width])
            .collect();
        agreement_meshes_of(&Grid {
            width,
            height,
            heights: &cropped,
            ..square(&heights)
        });
    }

    fn agreement_meshes_of(grid: &Grid) {
        let params = BuildParams::default();
        let step = height_step(grid).expect("step");
        let alone = Agreement::default();
        let first = mesh_tile(grid, (1, 1), &params, step, &alone, (Output::Tile, None));
        let first = first.expect("built");
        // Force the west side to hold every vertex the tile has on its east side.
        let forced: Sides = first
            .sides
            .iter()
            .map(|s| [vec![], vec![], vec![], s[1].clone()])
            .collect();
        let mut seen = Vec::new();
        let forced = Agreement {
            forced,
            units: None,
            floor: 0.0,
        };
        let mesh = |agreement: &Agreement, output, earlier: Option<&MeshHistory>| {
            mesh_tile(grid, (1, 1), &params, step, agreement, (output, earlier)).expect("meshed")
        };
        for agreement in [&alone, &forced] {
            let whole = mesh(agreement, Output::Tile, None);
            let sides = mesh(agreement, Output::Sides, None);
            let bare = mesh(agreement, Output::SidesBare, None);
            assert!(sides.blob.is_empty() && !whole.blob.is_empty());
            assert_eq!(sides.sides, whole.sides);
            assert_eq!(sides.deviation, whole.deviation);
            assert_eq!(bare.sides, whole.sides, "sides read from the mesh");
            assert_eq!(bare.deviation, vec![0.0; params.levels as usize]);
            assert_eq!(bare.history, sides.history);
            seen.push(whole.sides);
        }
        assert_ne!(
            seen[0], seen[1],
            "forcing the west side changed nothing: no test"
        );
        // Meshed again from the mesh without forced sides: the same as meshed afresh.
        for output in [Output::Sides, Output::SidesBare] {
            let before = mesh(&alone, output, None);
            let fresh = mesh(&forced, output, None);
            let again = mesh(&forced, output, before.history.as_ref());
            assert_eq!(again.sides, fresh.sides, "{output:?}");
            assert_eq!(again.deviation, fresh.deviation, "{output:?}");
            assert_eq!(again.history, fresh.history, "{output:?}");
            // The control: from a mesh that held more than the agreement forces, the forced
            // vertices stay, and the result is not the mesh without them.
            let wrong = mesh(&alone, output, fresh.history.as_ref());
            assert_ne!(
                wrong.sides, before.sides,
                "{output:?}: the history was not read"
            );
        }
    }

    /// `side * side` heights of the SRTM3 tile N55W003 (no voids), from (100, 100).
    /// A square grid of `heights` at SRTM3's spacing near 55 N.
    fn square(heights: &[f32]) -> Grid<'_> {
        let side = heights.len().isqrt();
        Grid {
            width: side,
            height: side,
            first_row: 0,
            heights,
            spacing_x: 53.2,
            spacing_y: 92.6,
        }
    }

    fn srtm3_crop(side: usize) -> Vec<f32> {
        let n = 1201;
        let bytes = std::fs::read(testdata::data("srtm/N55W003.hgt")).expect("readable hgt");
        (0..side * side)
            .map(|i| {
                let (x, y) = (i % side, i / side);
                let at = 2 * ((y + 100) * n + x + 100);
                f32::from(i16::from_be_bytes([bytes[at], bytes[at + 1]]))
            })
            .collect()
    }

    /// Meshing again only the tiles whose forced sides changed settles on the same sides
    /// and agreements as meshing every tile next to a change, with fewer meshes; and so does
    /// meshing each pass's tiles from the state before the pass, the order before the
    /// checkerboard, with more; and meshing every tile from nothing rather than from its last
    /// mesh, or from the last meshes a small budget still holds, with as many (real SRTM3
    /// heights, 4 x 4 tiles).
    #[test]
    fn agreement_remeshes_only_what_changed_and_settles_the_same() {
        let side = 4 * 256 + 1;
        let heights = srtm3_crop(side);
        let grid = square(&heights);
        let params = BuildParams::default();
        let step = height_step(&grid).expect("step");
        let bands = Bands::new(&grid, (4, 4));
        let bounds: Vec<f64> = (0..params.levels).map(|k| params.level_error(k)).collect();
        let agree =
            |remesh| agree_sides(&bands, &params, (step, &bounds), None, remesh).expect("agreed");
        let (fewer, every) = (agree(Remesh::Changed), agree(Remesh::NextToChange));
        let jacobi = agree(Remesh::FromThePassBefore);
        let afresh = agree(Remesh::KeepingAtMost(0));
        // Twelve of the sixteen tiles' last meshes kept: the oldest are dropped as the passes
        // go, and some tiles are meshed again from nothing.
        let dropping = agree(Remesh::KeepingAtMost(12));
        assert_eq!(fewer.meshes, afresh.meshes);
        assert_eq!(fewer.meshes, dropping.meshes);
        assert!(
            afresh.resumed == 0 && 0 < dropping.resumed && dropping.resumed < fewer.resumed,
            "{} {} {}",
            afresh.resumed,
            dropping.resumed,
            fewer.resumed
        );
        assert!(fewer.passes > 1, "the sides did not need agreeing: no test");
        assert!(
            fewer.meshes < every.meshes,
            "{} >= {}",
            fewer.meshes,
            every.meshes
        );
        // The checkerboard's order: the same point in fewer meshes than passes from the
        // state before each.
        assert!(
            fewer.meshes < jacobi.meshes,
            "{} >= {}",
            fewer.meshes,
            jacobi.meshes
        );
        for other in [&every, &jacobi, &afresh, &dropping] {
            assert_eq!(fewer.units, other.units, "morph units");
            assert_eq!(fewer.forced.len(), other.forced.len());
            for t in 0..fewer.forced.len() {
                assert_eq!(fewer.forced[t], other.forced[t], "tile {t}: forced sides");
                assert_eq!(fewer.sides[t], other.sides[t], "tile {t}: sides");
            }
        }
    }

    /// The agreement's bitmaps hold exactly the side lists: every position 0..=256 of every
    /// side and level, in and out, round-trips; a list with a repeat does not (the control:
    /// the bitmaps are sets).
    #[test]
    fn side_bitmaps_hold_the_side_lists() {
        let mut rng = splitmix::Rng(0x51de_b175);
        for _ in 0..50 {
            let sides: Sides = (0..9)
                .map(|_| {
                    std::array::from_fn(|_| {
                        (0..TILE_SIZE as u16)
                            .filter(|_| rng.below(3) == 0)
                            .collect()
                    })
                })
                .collect();
            assert_eq!(expand(&compact(&sides)), sides);
        }
        let all: Sides = vec![std::array::from_fn(|_| (0..TILE_SIZE as u16).collect())];
        assert_eq!(expand(&compact(&all)), all);
        let repeat: Sides = vec![[vec![3, 3], vec![], vec![256], vec![0]]];
        assert_ne!(expand(&compact(&repeat)), repeat);
    }

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

    /// The walk in P-order meets a mesh's leaves in the order a sort by their cells' Hilbert
    /// index gives (the sort it replaced), at every level of a real tile.
    #[test]
    fn leaves_in_p_order_are_the_leaves_sorted_along_the_curve() {
        let heights = srtm3_crop(257);
        let grid = square(&heights);
        let samples = tile_samples(&grid, 0, 0);
        let lo = samples
            .heights
            .iter()
            .fold(f32::INFINITY, |lo, &h| lo.min(h));
        let quantiser = Quantiser::for_tile(lo, height_step(&grid).expect("step"));
        let mut mesher = Mesher::new(&samples, &quantiser, grid.spacing_x.min(grid.spacing_y));
        let params = BuildParams::default();
        let mut counts = Vec::new();
        for level in 0..params.levels {
            mesher.refine(params.level_error(level));
            let mut sorted = mesher.leaves();
            sorted.sort_by_key(|q| {
                let (x, y) = q.origin();
                hilbert_index(TILE_CELLS / 2, x / 2, y / 2)
            });
            assert_eq!(mesher.leaves_in_p_order(), sorted, "level {level}");
            counts.push(sorted.len());
        }
        // Coarse and fine leaves side by side, not a uniform grid the sort could not misplace.
        assert!(counts[1] >= 16 && counts[8] > 4 * counts[1], "{counts:?}");
    }

    /// The ring's longest run found by bit masks starts where the count from every start that
    /// it replaced says, for every ring of 3 to 8 vertices and every set of them seen.
    #[test]
    fn a_rings_longest_run_starts_where_counting_finds_it() {
        let mut turned = 0;
        for ring in 3..=8usize {
            for mask in 0u32..1 << ring {
                let seen = |i: usize| mask >> (i % ring) & 1 == 1;
                let run = |s: usize| (0..ring).take_while(|&i| seen(s + i)).count();
                let counted = (0..ring)
                    .max_by_key(|&s| (run(s), std::cmp::Reverse(s)))
                    .filter(|&s| s != 0 && run(s) != 0);
                assert_eq!(longest_run_start(ring, seen), counted, "{ring} {mask:b}");
                turned += usize::from(counted.is_some());
            }
        }
        assert!(turned > 200, "{turned}");
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
            ..BuildParams::default()
        };
        assert_eq!(p.level_error(0), 256.0);
        assert_eq!(p.level_error(8), 1.0);
    }
}
