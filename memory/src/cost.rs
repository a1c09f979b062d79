//! What a tile costs in GPU memory and on the bus, level by level, and where each part sits
//! inside a chunk.
//!
//! The layout is described in the crate's header.

/// Bytes of one level of one tile, as the file stores them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LevelCost {
    /// Block `i`'s packed positions (4 bytes a vertex).
    pub positions: u64,
    /// Block `i`'s morph offsets (`i` rows of one byte a vertex).
    pub morph: u64,
    /// Level `i`'s index array.
    pub indices: u64,
    /// 2 or 4.
    pub index_width: u32,
    /// Block `i`'s positions sent as the level's compact stream of this many bytes and decoded
    /// on the GPU into its place (`None`: sent as they are). The chunk holds the positions
    /// either way.
    pub stream: Option<u64>,
}

/// Every level of one tile.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TileCost {
    pub levels: Vec<LevelCost>,
}

/// Where the parts of a tile sit inside a chunk of a given capacity (offsets from the chunk's
/// start).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    /// The finest level whose blocks and index array fit.
    pub capacity: u32,
    /// Start of block 0's morph rows (= the positions region's size).
    pub morph: u64,
    /// Start of the index region.
    pub index: u64,
    /// Bytes the layout needs.
    pub bytes: u64,
}

pub(crate) fn align(n: u64, a: u64) -> u64 {
    n.div_ceil(a) * a
}

impl TileCost {
    pub fn finest(&self) -> u32 {
        self.levels.len().saturating_sub(1) as u32
    }

    /// Bytes of block `j` in the pool: its positions and its morph rows.
    pub fn block_bytes(&self, j: u32) -> u64 {
        let l = &self.levels[j as usize];
        l.positions + l.morph
    }

    /// Bytes block `j` sends: its positions, or its stream where they are decoded on the GPU,
    /// and its morph rows.
    pub fn block_sent(&self, j: u32) -> u64 {
        let l = &self.levels[j as usize];
        l.stream.unwrap_or(l.positions) + l.morph
    }

    /// Position bytes of blocks `0..j` (where block `j`'s positions start).
    pub fn positions_before(&self, j: u32) -> u64 {
        self.levels[..j as usize].iter().map(|l| l.positions).sum()
    }

    /// Morph bytes of blocks `0..j`, each padded to 4.
    pub fn morph_before(&self, j: u32) -> u64 {
        self.levels[..j as usize]
            .iter()
            .map(|l| align(l.morph, 4))
            .sum()
    }

    /// The layout of a chunk that holds levels up to `capacity`.
    pub fn layout(&self, capacity: u32) -> Layout {
        let c = capacity.min(self.finest());
        let morph = self.positions_before(c + 1);
        let index = align(morph + self.morph_before(c + 1), 4);
        let largest_index = self.levels[..=c as usize]
            .iter()
            .map(|l| l.indices)
            .max()
            .unwrap_or(0);
        Layout {
            capacity: c,
            morph,
            index,
            bytes: index + largest_index,
        }
    }

    /// Bytes a chunk needs to hold levels up to `level`.
    pub fn need(&self, level: u32) -> u64 {
        self.layout(level).bytes
    }

    /// The finest level whose layout fits in `bytes` (None if not even level 0 does).
    pub fn capacity_in(&self, bytes: u64) -> Option<u32> {
        (0..=self.finest()).rev().find(|&l| self.need(l) <= bytes)
    }

    /// The layout of a chunk holding the whole tile (the whole-tile scheme): every block as in
    /// [`Self::layout`], then every level's index array in turn, each starting 4-aligned.
    pub fn whole_layout(&self) -> Layout {
        let l = self.layout(self.finest());
        Layout {
            bytes: l.index + self.whole_index_before(self.finest() + 1),
            ..l
        }
    }

    /// In a whole-tile chunk: where level `j`'s index array starts, from the index region.
    pub fn whole_index_before(&self, j: u32) -> u64 {
        self.levels[..j as usize]
            .iter()
            .map(|l| align(l.indices, 4))
            .sum()
    }

    /// Everything the tile stores: all blocks and all index arrays (a whole-tile upload).
    pub fn whole(&self) -> u64 {
        self.levels
            .iter()
            .map(|l| l.positions + l.morph + l.indices)
            .sum()
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A tile shaped like a real one: blocks and index arrays roughly doubling per level.
    pub fn tile(levels: u32, scale: u64) -> TileCost {
        TileCost {
            levels: (0..levels)
                .map(|i| {
                    let verts = scale << i;
                    LevelCost {
                        positions: 4 * verts,
                        morph: u64::from(i) * verts,
                        indices: 2 * 6 * (scale << (i + 1)),
                        index_width: 2,
                        stream: None,
                    }
                })
                .collect(),
        }
    }

    #[test]
    fn layout_keeps_positions_contiguous_and_regions_apart() {
        let t = tile(5, 10);
        for c in 0..5 {
            let l = t.layout(c);
            assert_eq!(
                l.morph,
                (0..=c).map(|j| t.levels[j as usize].positions).sum()
            );
            assert!(l.index >= l.morph + t.morph_before(c + 1));
            assert_eq!(l.index % 4, 0);
            assert_eq!(l.bytes, l.index + t.levels[c as usize].indices);
        }
        // Each level's chunk holds the coarser level's and the next block besides.
        for c in 0..4 {
            assert!(
                t.need(c + 1) >= t.need(c) + t.block_bytes(c + 1),
                "level {c}"
            );
        }
        // Capacity stops at the finest level.
        assert_eq!(t.need(5), t.need(4));
        assert_eq!(t.capacity_in(t.need(3)), Some(3));
        assert_eq!(t.capacity_in(t.need(3) - 1), Some(2));
        assert_eq!(t.capacity_in(0), None);
        assert_eq!(t.capacity_in(u64::MAX), Some(4));
    }
}
