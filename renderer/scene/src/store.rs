//! A terrain's tiles, each read from its outline (its header and level table, a page of the
//! file) the first time anything asks for it. Opening a set then costs the same whatever its
//! number of tiles, and a flight reads the outlines of the tiles its cut reaches and of their
//! neighbours (whose level tables a tile's side and corner tables take in), not the set's.
//!
//! A tile whose outline does not read (a damaged header or level table) is still a tile: it
//! covers its place in the grid, and its check fails with the outline's problem the first
//! time it is made, so it is never drawn and the flight names it (see [`TileInfo::broken`]).

use std::ops::Index;
use std::sync::atomic::{AtomicU32, AtomicUsize, Ordering};
use std::sync::{Mutex, OnceLock};

use glam::DVec3;
use tiles::format::{LevelEntry, TileHeader, TileSet};
use tiles::mesh::TILE_CELLS;

use crate::levels::LevelTable;
use crate::tile::{Side, TileInfo};

/// One layer of the tiles a terrain holds.
#[derive(Clone)]
pub struct Layer {
    /// Its first tile's index in [`crate::terrain::Terrain::tiles`]; its tiles follow,
    /// row-major.
    pub first: usize,
    pub tiles_x: u32,
    pub tiles_y: u32,
    /// The layer's view of the file (its directory, spacing and height lattice).
    pub set: TileSet,
}

impl Layer {
    pub fn len(&self) -> usize {
        (self.tiles_x * self.tiles_y) as usize
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// What a tile's outline says, read once: its header, level table, box and own level table;
/// for a tile whose outline does not read, why, with a stand-in that holds its place (its
/// box in the grid, levels that hold nothing).
pub struct Outline {
    pub header: TileHeader,
    pub levels: Vec<LevelEntry>,
    /// Per level, the bytes of its compact stream (version 5 compact sets; empty otherwise).
    pub streams: Vec<u32>,
    pub min: DVec3,
    pub max: DVec3,
    table: LevelTable,
    pub broken: Option<String>,
}

/// The tiles of every layer opened, in one index space (the base grid's first, row-major, then
/// each pyramid layer's), read as they are first asked for.
pub struct Tiles {
    layers: Vec<Layer>,
    infos: Box<[OnceLock<Box<TileInfo>>]>,
    /// Outlines read so far, kept: a tile's neighbours' level tables go into its side tables,
    /// so most outlines are asked for by up to nine tiles.
    outlines: Box<[OnceLock<Box<Outline>>]>,
    read: AtomicUsize,
    /// Whether the level tables hold half a morph unit over the measured errors: the rounding
    /// of the stored offsets, for the morph rules that read them
    /// ([`crate::terrain::Terrain::read_stored_offsets`]).
    rounding: bool,
}

impl Tiles {
    pub(crate) fn new(layers: Vec<Layer>) -> Tiles {
        let n = layers.iter().map(Layer::len).sum();
        Tiles {
            layers,
            infos: (0..n).map(|_| OnceLock::new()).collect(),
            outlines: (0..n).map(|_| OnceLock::new()).collect(),
            read: AtomicUsize::new(0),
            rounding: false,
        }
    }

    /// The level tables made for a morph that reads the stored offsets (see `rounding`);
    /// before any outline is read.
    pub(crate) fn set_rounding(&mut self, rounding: bool) {
        debug_assert_eq!(
            self.outlines_read(),
            0,
            "outlines read before the tables' rule"
        );
        self.rounding = rounding;
    }

    pub fn len(&self) -> usize {
        self.infos.len()
    }

    pub fn is_empty(&self) -> bool {
        self.infos.is_empty()
    }

    /// Tile `i`, read from its outline if nothing asked for it before.
    pub fn get(&self, i: usize) -> Option<&TileInfo> {
        let slot = self.infos.get(i)?;
        Some(slot.get_or_init(|| Box::new(self.info(i))))
    }

    /// Tile `i` if something has asked for it already (no read).
    pub fn known(&self, i: usize) -> Option<&TileInfo> {
        self.infos.get(i)?.get().map(|b| &**b)
    }

    /// Every tile in index order, each read as the iteration reaches it: a sweep of the whole
    /// set, for tools and tests, never for a frame.
    pub fn iter(&self) -> impl ExactSizeIterator<Item = &TileInfo> + '_ {
        (0..self.len()).map(move |i| &self[i])
    }

    /// How many outlines have been read so far.
    pub fn outlines_read(&self) -> usize {
        self.read.load(Ordering::Relaxed)
    }

    /// The layer holding tile `i`, and the tile's column and row in it.
    pub fn place(&self, i: usize) -> (u32, u32, u32) {
        let p = self
            .layers
            .iter()
            .rposition(|g| g.first <= i)
            .expect("layer 0 starts at 0");
        let g = &self.layers[p];
        let k = (i - g.first) as u32;
        (p as u32, k % g.tiles_x, k / g.tiles_x)
    }

    /// The index of layer `p`'s tile at column `tx + dx`, row `ty + dy`, if there is one.
    pub fn at(&self, p: u32, tx: u32, ty: u32, (dx, dy): (i64, i64)) -> Option<usize> {
        let g = &self.layers[p as usize];
        let x = u32::try_from(i64::from(tx) + dx).ok()?;
        let y = u32::try_from(i64::from(ty) + dy).ok()?;
        (x < g.tiles_x && y < g.tiles_y).then(|| g.first + (y * g.tiles_x + x) as usize)
    }

    /// Tile `i`'s outline alone, read if nothing asked for it before (its neighbours' are
    /// not): what its costs and its box need.
    pub fn outline(&self, i: usize) -> &Outline {
        self.outlines[i].get_or_init(|| {
            self.read.fetch_add(1, Ordering::Relaxed);
            let (p, tx, ty) = self.place(i);
            let set = &self.layers[p as usize].set;
            Box::new(
                read_outline(set, (tx, ty), self.rounding)
                    .unwrap_or_else(|e| placeholder(set, tx, ty, e)),
            )
        })
    }

    /// Tile `i` from its outline, with its side and corner tables: the larger errors of the
    /// tiles that hold the side or corner (their own tables, from their outlines), the same
    /// table in each of them. A neighbour whose outline does not read is never drawn, so no
    /// side or corner is shared with it, and it adds nothing.
    fn info(&self, i: usize) -> TileInfo {
        let (p, tx, ty) = self.place(i);
        let outline = self.outline(i);
        let own = outline.table;
        let around = |cells: &[(i64, i64)]| {
            cells
                .iter()
                .filter_map(|&d| self.at(p, tx, ty, d))
                .map(|j| self.outline(j))
                .filter(|o| o.broken.is_none())
                .fold(own, |a, b| a.max(&b.table))
        };
        let tables = [
            own,
            around(&[Side::North.step()]),
            around(&[Side::East.step()]),
            around(&[Side::South.step()]),
            around(&[Side::West.step()]),
            around(&[(-1, -1), (0, -1), (-1, 0)]),
            around(&[(1, -1), (0, -1), (1, 0)]),
            around(&[(-1, 1), (0, 1), (-1, 0)]),
            around(&[(1, 1), (0, 1), (1, 0)]),
        ];
        TileInfo {
            tx,
            ty,
            layer: p,
            header: outline.header,
            levels: outline.levels.clone(),
            streams: outline.streams.clone(),
            min: outline.min,
            max: outline.max,
            drawn_table: tables[1..].iter().fold(tables[0], |a, b| a.max(b)),
            tables,
            broken: outline.broken.clone(),
            own: OnceLock::new(),
            usable: OnceLock::new(),
            checked: AtomicU32::new(0),
            late: OnceLock::new(),
            extending: Mutex::new(()),
            heights: OnceLock::new(),
        }
    }
}

impl Index<usize> for Tiles {
    type Output = TileInfo;

    fn index(&self, i: usize) -> &TileInfo {
        match self.get(i) {
            Some(t) => t,
            None => panic!("tile {i} of {}", self.len()),
        }
    }
}

/// One tile's header, level table, box and own level table, from its outline (no checksum:
/// the tile's check comes when it is first needed). The problem as one line naming the file
/// and the tile when the outline does not read.
fn read_outline(set: &TileSet, (tx, ty): (u32, u32), rounding: bool) -> Result<Outline, String> {
    let h = *set.header();
    let (sx, sy) = (h.spacing_x, h.spacing_y);
    let (th, mut levels, streams) = set
        .tile_table_and_streams(tx, ty)
        .map_err(|e| e.to_string())?;
    // A pyramid layer's tile: its levels' errors against the base grid's samples under it,
    // not its own subsampled grid's, so that it is chosen by the ground it stands for.
    if let Some(errors) = set.base_errors(tx, ty) {
        for (l, e) in levels.iter_mut().zip(errors) {
            l.max_error = e;
        }
    }
    let z_min = levels.iter().map(|l| l.z_min).fold(f32::INFINITY, f32::min);
    let z_max = levels
        .iter()
        .map(|l| l.z_max)
        .fold(f32::NEG_INFINITY, f32::max);
    let (c0, r0) = (f64::from(tx * TILE_CELLS), f64::from(ty * TILE_CELLS));
    let min = DVec3::new(
        c0 * sx,
        -(r0 + f64::from(th.mesh_max_y)) * sy,
        f64::from(z_min),
    );
    let max = DVec3::new(
        (c0 + f64::from(th.mesh_max_x)) * sx,
        -r0 * sy,
        f64::from(z_max),
    );
    // Its levels' errors as the morph sees them: measured, plus half a morph unit where the
    // morph reads the stored offsets, which are rounded to whole units. The morph pass reads
    // none (it blends the levels' own surfaces), so its tables are the measured errors.
    let rounding = if rounding { 0.5 } else { 0.0 };
    let errors: Vec<f32> = levels
        .iter()
        .map(|l| l.max_error.max(0.0) + rounding * l.morph_unit.max(0.0))
        .collect();
    let table = LevelTable::over(&errors, distinct_levels(&levels));
    Ok(Outline {
        header: th,
        levels,
        streams,
        min,
        max,
        table,
        broken: None,
    })
}

/// What stands for a tile whose outline does not read (`problem`): its place in the grid, the
/// set's height range, levels that hold nothing. It is never drawn (its check fails first).
fn placeholder(set: &TileSet, tx: u32, ty: u32, problem: String) -> Outline {
    let h = *set.header();
    let (sx, sy) = (h.spacing_x, h.spacing_y);
    let cells = |grid: u32, t: u32| grid.saturating_sub(1 + t * TILE_CELLS).min(TILE_CELLS);
    let (w, hh) = (cells(h.grid_width, tx), cells(h.grid_height, ty));
    let (c0, r0) = (f64::from(tx * TILE_CELLS), f64::from(ty * TILE_CELLS));
    let levels = vec![
        LevelEntry {
            index_width: 2,
            ..LevelEntry::default()
        };
        h.levels as usize
    ];
    Outline {
        header: TileHeader::default(),
        table: LevelTable::over(&vec![0.0; levels.len()], 1),
        levels,
        streams: Vec::new(),
        min: DVec3::new(c0 * sx, -(r0 + f64::from(hh)) * sy, f64::from(h.height_min)),
        max: DVec3::new((c0 + f64::from(w)) * sx, -r0 * sy, f64::from(h.height_max)),
        broken: Some(problem),
    }
}

/// How many of a tile's levels draw surfaces of their own: a level that adds no vertex to the
/// one before draws the same triangles, so it is the same surface with the same error. A
/// pyramid layer's tile is built no finer than a floor ([`tiles::pyramid::level_floor`]), and
/// its levels past that floor are such copies: up to 7 of 9 in the mirror sets' top layers.
/// A level table over them would fall by the least ratio across copies of one surface, and
/// make the tile's real levels look up to `MIN_RATIO^6` times worse than they are; the table
/// stops at the last level of its own instead. Levels past it draw the same triangles, and
/// the same surface, as that level.
fn distinct_levels(levels: &[LevelEntry]) -> usize {
    let adds = |k: usize| {
        levels[k].block_len > 0 || levels[k].triangle_count != levels[k - 1].triangle_count
    };
    1 + (1..levels.len()).rev().find(|&k| adds(k)).unwrap_or(0)
}
