//! One tile as the renderer keeps it in memory, and the four sides it shares with its
//! neighbours: which tile lies across a side, and how a vertex on a side moves into the
//! neighbour's frame. Terrain (the whole set), stitching and the level tables all speak of sides
//! in these terms.

use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex, OnceLock, RwLock};

use glam::DVec3;
use tiles::format::{LevelEntry, TileHeader};
use tiles::pack::{pack, unpack};

use crate::levels::LevelTable;

/// Cells per side of each tile's coarse height map (for ground-following paths).
pub(crate) const HEIGHT_CELLS: usize = 8;

/// What the renderer knows of a tile from the moment anything first asks for it
/// ([`crate::store`]): its header and level table (read without touching the tile's data,
/// [`tiles::TileSet::tile_table_and_streams`]), its box and its level tables. What needs the tile's data, its borders and texture mips, comes with its
/// check ([`Paged`]), the first time the tile is needed ([`crate::terrain::Terrain::check`]).
pub struct TileInfo {
    /// Its column and row in its layer's grid of tiles.
    pub tx: u32,
    pub ty: u32,
    /// Its pyramid layer (0: the base grid); its samples are `2^layer` base samples apart.
    pub layer: u32,
    pub header: TileHeader,
    pub levels: Vec<LevelEntry>,
    /// Per level, the bytes of its compact stream (version 5 compact sets; empty otherwise):
    /// what a refinement sends when the GPU decodes it.
    pub streams: Vec<u32>,
    /// World box over all levels: x east, y north, z up (metres).
    pub min: DVec3,
    pub max: DVec3,
    /// The level tables geomorphing takes its vertices' levels from ([`crate::levels`]):
    /// inside the tile (its own errors), on its N, E, S, W sides (the larger errors of it and
    /// that neighbour), at its NW, NE, SW, SE corners (the largest of the tiles there).
    pub tables: [LevelTable; 9],
    /// The largest of the nine: covers every vertex's table, for the quick test that the whole
    /// tile may be drawn at level 0 (the drawn level itself takes each part's table over that
    /// part, `renderer::lod::morph_level`).
    pub drawn_table: LevelTable,
    /// Why its outline does not read, where it does not (`crate::store`): the tile holds its
    /// place in the grid, and its check fails with this problem.
    pub broken: Option<String>,
    /// The tile's own check: its checksum, its structure, `tiletool verify`'s semantic checks
    /// of the levels it is first drawn at, and its texture; on success, what was read from its
    /// data.
    pub(crate) own: OnceLock<Result<Paged, String>>,
    /// The check that decides whether the tile is drawn: its own, and where the set shares
    /// sides, its sides against those of its neighbours that pass their own.
    pub(crate) usable: OnceLock<Result<(), String>>,
    /// How many of its levels, from level 0, have passed the semantic checks (their blocks
    /// and index arrays may leave for the GPU); a finer level is checked before its first
    /// upload ([`crate::terrain::Terrain::check_through`]).
    pub(crate) checked: AtomicU32,
    /// A finer level's check that failed after the tile had passed its first one: the tile
    /// is drawn no more.
    pub(crate) late: OnceLock<String>,
    /// Held while finer levels are checked, so that two threads do not check the same ones.
    pub(crate) extending: Mutex<()>,
    /// The coarse height map, read from the tile's positions the first time it is asked for.
    pub(crate) heights: OnceLock<[f32; HEIGHT_CELLS * HEIGHT_CELLS]>,
}

/// What a tile's check reads from its data, for stitching and texturing.
pub struct Paged {
    /// The tile's sides at the levels read so far: every level of a version 3 tile; those
    /// checked so far of a compact one, whose levels are rebuilt as they are first checked
    /// (each check of finer levels replaces it).
    pub(crate) sides: RwLock<Arc<Sides>>,
    /// Per texture mip, finest first: its BC1 blocks' place in the tile's texture blob (empty
    /// when the set has no textures).
    pub(crate) texture_mips: Vec<std::ops::Range<usize>>,
    /// What drawing the tile part by part needs ([`tiles::parts::tables_through`]), for the
    /// levels checked so far (each check of finer levels replaces it).
    pub(crate) parts: RwLock<Arc<PartTables>>,
}

/// A tile's part tables: its parts' centres, and its checked levels' counts.
pub type PartTables = (tiles::parts::Centres, tiles::parts::Counts);

/// A tile's sides, per level it holds, per [`Side`] (N, E, S, W).
#[derive(Default)]
pub struct Sides {
    /// The packed border vertices in order along the side.
    pub borders: Vec<[Vec<u32>; 4]>,
    /// The same vertices as indices into the tile's vertex array (blocks 0.. in order).
    pub border_indices: Vec<[Vec<u32>; 4]>,
}

impl Paged {
    /// The tile's sides, at every level drawn so far (drawn levels are checked).
    pub fn sides(&self) -> Arc<Sides> {
        Arc::clone(&self.sides.read().unwrap_or_else(|p| p.into_inner()))
    }

    /// What drawing the tile part by part needs, for the levels checked so far.
    pub fn parts(&self) -> Arc<PartTables> {
        Arc::clone(&self.parts.read().unwrap_or_else(|p| p.into_inner()))
    }
}

impl TileInfo {
    /// What the tile's check read, once the tile passed its own check (None: not checked yet,
    /// or failed).
    pub fn paged(&self) -> Option<&Paged> {
        self.own.get().and_then(|r| r.as_ref().ok())
    }

    /// Whether the tile may be drawn: None until it is checked (at any level).
    pub fn usable(&self) -> Option<bool> {
        if self.late.get().is_some() {
            return Some(false);
        }
        self.usable.get().map(Result::is_ok)
    }

    /// Whether the tile may be drawn at `level`: None until its levels up to `level` are
    /// checked.
    pub fn usable_at(&self, level: u32) -> Option<bool> {
        let level = level.min((self.levels.len() as u32).saturating_sub(1));
        match self.usable()? {
            false => Some(false),
            true => (self.checked_levels() > level).then_some(true),
        }
    }

    /// How many of its levels, from level 0, have passed their checks (0: none yet).
    pub fn checked_levels(&self) -> u32 {
        self.checked.load(Ordering::Acquire)
    }
}

/// A side of a tile, in the order the tile set stores borders.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    North,
    East,
    South,
    West,
}

impl Side {
    pub const ALL: [Side; 4] = [Side::North, Side::East, Side::South, Side::West];

    /// The sides each seam is visited from once (the tile west or north of it).
    pub const FORWARD: [Side; 2] = [Side::East, Side::South];

    /// Its place in a tile's borders.
    pub fn index(self) -> usize {
        self as usize
    }

    pub fn opposite(self) -> Side {
        Side::ALL[(self.index() + 2) % 4]
    }

    /// The step in tile columns and rows to the tile across it (rows grow southwards).
    pub fn step(self) -> (i64, i64) {
        match self {
            Side::North => (0, -1),
            Side::East => (1, 0),
            Side::South => (0, 1),
            Side::West => (-1, 0),
        }
    }

    /// Whether it runs along x (north and south) rather than along y.
    pub fn runs_along_x(self) -> bool {
        matches!(self, Side::North | Side::South)
    }
}

/// Moves a neighbour's border vertex into `to`'s frame: `from` lies across `side` of `to`, and
/// the height code is re-based onto `to`'s base (same lattice, so the same height).
pub fn rebase(p: u32, side: Side, from: &TileInfo, to: &TileInfo) -> Option<u32> {
    let (x, y, code) = unpack(p);
    let cells = i64::from(tiles::mesh::TILE_CELLS);
    let (dx, dy) = side.step();
    let (x, y) = (i64::from(x) + dx * cells, i64::from(y) + dy * cells);
    let code =
        i64::from(code) + i64::from(from.header.height_base) - i64::from(to.header.height_base);
    let ok = (0..=cells).contains(&x) && (0..=cells).contains(&y) && (0..1 << 14).contains(&code);
    ok.then(|| pack(x as u32, y as u32, code as u16))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn opposite_sides_step_back() {
        for side in Side::ALL {
            let (a, b) = (side.step(), side.opposite().step());
            assert_eq!((a.0 + b.0, a.1 + b.1), (0, 0), "{side:?}");
            assert_ne!(side, side.opposite());
            assert_eq!(side.runs_along_x(), a.0 == 0, "{side:?}");
        }
        assert_eq!(Side::ALL.map(Side::index), [0, 1, 2, 3]);
    }
}
