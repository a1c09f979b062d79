//! One tile as the renderer keeps it in memory, and the four sides it shares with its
//! neighbours: which tile lies across a side, and how a vertex on a side moves into the
//! neighbour's frame. Terrain (the whole set), stitching and the level tables all speak of sides
//! in these terms.

use glam::DVec3;
use tiles::format::{LevelEntry, TileHeader};
use tiles::pack::{pack, unpack};

use crate::levels::LevelTable;

/// Cells per side of each tile's coarse height map (for ground-following paths).
pub(crate) const HEIGHT_CELLS: usize = 8;

pub struct TileInfo {
    pub tx: u32,
    pub ty: u32,
    pub header: TileHeader,
    pub levels: Vec<LevelEntry>,
    /// World box over all levels: x east, y north, z up (metres).
    pub min: DVec3,
    pub max: DVec3,
    /// Per level, per [`Side`] (N, E, S, W): the packed border vertices in order along the side.
    pub borders: Vec<[Vec<u32>; 4]>,
    /// The same vertices as indices into the tile's vertex array (blocks 0.. in order).
    pub border_indices: Vec<[Vec<u32>; 4]>,
    pub(crate) heights: [f32; HEIGHT_CELLS * HEIGHT_CELLS],
    /// Per texture mip, finest first: its BC1 blocks' place in the tile's texture blob
    /// (validated at open; empty when the set has no textures).
    pub(crate) texture_mips: Vec<std::ops::Range<usize>>,
    /// The level tables geomorphing takes its vertices' levels from ([`crate::levels`]):
    /// inside the tile (its own errors), on its N, E, S, W sides (the larger errors of it and
    /// that neighbour), at its NW, NE, SW, SE corners (the largest of the tiles there).
    pub tables: [LevelTable; 9],
    /// The largest of the nine: covers every vertex's table, for the quick test that the whole
    /// tile may be drawn at level 0 (the drawn level itself takes each part's table over that
    /// part, `renderer::lod::morph_level`).
    pub drawn_table: LevelTable,
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
