//! Drawing a tile part by part while geomorphing: each of its 4 x 4 parts at the level the part
//! needs ([`crate::lod::morph_parts`]), in one conforming mesh ([`tiles::parts`]) that the
//! index builder makes on the GPU in the room of the tile's drawn level.
//!
//! A tile drawn at level `G` has blocks `0..=G` resident and room for level `G`'s index array;
//! the mixed array is never longer ([`tiles::parts`]'s tests). The memory manager knows levels
//! only: the mixed array is this module's business. It decides each drawn tile's key at its
//! granted level, the array's length (from the small tables the tile's check reads,
//! [`tiles::parts::tables`]; the GPU checks it on every build), and which
//! draws need their array built again this frame: those whose region does not hold their key,
//! and those at one level whose region may still hold a mix ([`PartDraws::rebuilds`]).
//!
//! A rebuilt region may be read by frames still in flight: the build is recorded in the
//! frame's command buffer after a barrier on earlier frames' index reads
//! ([`crate::vulkan::indices::IndexBuilder::record`]), as the manager's own rewrites are.

use std::collections::BTreeMap;

use tiles::parts::{Blocks, PartKey};

use crate::plan::Plan;
use crate::terrain::Terrain;

/// What part-by-part drawing remembers between frames: the mixes this module built that the
/// pool still holds, by where they start. A region's content changes only by a copy or a
/// build; the manager's (a move, an upload, a level's array built) are followed in
/// [`PartDraws::assign`], this module's own builds in [`PartDraws::rebuilds`]. A tile can
/// hold arrays in several regions at once (a level and a spare for the next, or the old and
/// the new chunk in the frame a move copies it), and a move carries a mix to its new place:
/// a draw reads whatever its own region holds.
#[derive(Default)]
pub struct PartDraws {
    mixes: BTreeMap<u64, Mix>,
    /// The longest mix in `mixes`, in bytes: the bound for finding those a range overlaps.
    longest: u64,
}

/// A mix held in the pool: whose, which key, how many bytes.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Mix {
    tile: usize,
    key: PartKey,
    bytes: u64,
}

/// One array to build this frame: the draw's index in the plan.
pub type Rebuild = usize;

impl PartDraws {
    /// Gives each draw that has part levels the key it is drawn at (at most its granted
    /// level) and its array's length, where drawing the mix pays for building it
    /// ([`BuildCost`]). A draw whose parts cannot be drawn apart at that level, or whose mix
    /// would save too little, keeps its level throughout.
    ///
    /// What the draw's region holds is kept while it covers the key (every part at least as
    /// fine as wanted: finer parts are within tau, and their extra vertices sit on the
    /// coarser surface until their own morph begins, so the image is the key's) and drawing
    /// it costs fewer extra triangles than a build. The region holds the mix this module last
    /// built there (or a move copied there), or else the manager's array of the whole level,
    /// which covers every key and is never built again for a part's sake.
    ///
    /// Call once per frame, after the manager's step: it first follows the plan's moves and
    /// uploads.
    pub fn assign(&mut self, terrain: &Terrain, plan: &mut Plan, cost: BuildCost) {
        self.follow(&plan.moves, &plan.uploads);
        let Plan { draws, .. } = plan;
        for d in draws.iter_mut() {
            d.key = None;
            let Some(wanted) = d.parts else { continue };
            // Read with the tile's check (drawn tiles passed it).
            let Some(tables) = terrain.tiles[d.tile].paged().map(|p| p.parts()) else {
                continue;
            };
            let (centres, counts) = &*tables;
            let Some(key) = centres.key(&wanted, d.level) else {
                continue;
            };
            // The room is level G's array: a longer mix (never seen) is drawn at G.
            let whole = (d.index_count, d.triangle_count);
            let fits = |k: &PartKey| counts.count(k).filter(|&(length, _)| length <= whole.0);
            let Some(exact) = fits(&key) else { continue };
            let held = self.held(d.tile, d.index_offset);
            let mix_pays = cost.pays(whole.1, exact.1, whole.1);
            let drawn = match held {
                // The held mix covers the key: keep it unless the key saves a build's worth.
                Some(held) if covers(&held, &key, d.level) => match fits(&held) {
                    Some(h) if !cost.pays(h.1, exact.1, whole.1) => Some((held, h)),
                    _ => Some((key, exact)),
                },
                // The whole level (held by the region, or built again where a held mix no
                // longer covers): the key only where it saves a build's worth over the whole
                // level, since a mix must be built again whenever a part wants more, and the
                // whole level only when the tile's level changes.
                _ if mix_pays => Some((key, exact)),
                _ => None,
            };
            if let Some((key, (length, triangles))) = drawn {
                if key.levels.iter().any(|&l| u32::from(l) != d.level) {
                    d.key = Some(key);
                    d.index_count = length;
                    d.triangle_count = triangles;
                }
            }
        }
    }

    /// The draws whose arrays this module builds this frame: a draw at a key unless its
    /// region holds that key, and a draw at one level where its region holds a mix. Any
    /// other region holds what the manager put there (a level), so drawing whole tiles
    /// (discrete levels, `--whole-tiles`) builds nothing more than the manager asks. A build
    /// of the manager's where a draw at a key draws from is replaced by the draw's (one build
    /// writes there). Call after [`PartDraws::assign`].
    pub fn rebuilds(&mut self, plan: &Plan) -> Vec<Rebuild> {
        let mut out = Vec::new();
        for (k, d) in plan.draws.iter().enumerate() {
            let held = self.held(d.tile, d.index_offset);
            match d.key {
                Some(key) if held == Some(key) => {}
                Some(key) => {
                    let bytes = u64::from(d.index_count) * u64::from(d.index_width);
                    self.built(d.tile, d.index_offset, key, bytes);
                    out.push(k);
                }
                None if held.is_some() => {
                    self.mixes.remove(&d.index_offset);
                    out.push(k);
                }
                None => {}
            }
        }
        out
    }

    /// Remembers a mix built for `tile` at `offset`.
    fn built(&mut self, tile: usize, offset: u64, key: PartKey, bytes: u64) {
        self.longest = self.longest.max(bytes);
        self.mixes.insert(offset, Mix { tile, key, bytes });
    }

    /// The key of the mix `tile`'s region at `offset` holds, if it holds one.
    fn held(&self, tile: usize, offset: u64) -> Option<PartKey> {
        self.mixes
            .get(&offset)
            .filter(|m| m.tile == tile)
            .map(|m| m.key)
    }

    /// Follows what the frame's copies and the manager's builds do to the pool, in the order
    /// the frame records them: moves (each carries the mixes it copies whole, as they were
    /// before the frame), then uploads and the manager's builds, each of which overwrites
    /// what it overlaps. A move's source keeps its mixes: draws of the frame that moves a
    /// chunk still read there.
    fn follow(&mut self, moves: &[memory::Move], uploads: &[memory::Upload]) {
        let carried: Vec<(u64, Mix)> = moves
            .iter()
            .flat_map(|m| {
                self.mixes
                    .range(m.src..m.src + m.bytes)
                    .filter(move |(&at, mix)| at + mix.bytes <= m.src + m.bytes)
                    .map(move |(&at, &mix)| (m.dst + (at - m.src), mix))
            })
            .collect();
        for m in moves {
            self.overwrite(m.dst, m.bytes);
        }
        for (at, mix) in carried {
            self.mixes.insert(at, mix);
        }
        for u in uploads {
            self.overwrite(u.dst, u.bytes);
        }
    }

    /// Forgets the mixes that `bytes` written at `dst` overlap.
    fn overwrite(&mut self, dst: u64, bytes: u64) {
        let from = dst.saturating_sub(self.longest);
        let hit: Vec<u64> = self
            .mixes
            .range(from..dst + bytes)
            .filter(|(&at, mix)| at + mix.bytes > dst)
            .map(|(&at, _)| at)
            .collect();
        for at in hit {
            self.mixes.remove(&at);
        }
    }
}

/// What building a tile's mix costs, in triangles drawn, on the device at hand: a frame builds
/// a key only where the triangles it saves each frame over what the region holds are at least
/// `fixed + share * G`, for a tile of `G` triangles at its drawn level. A build scatters every
/// vertex of the drawn level and walks the tile's cells (`indices.comp`), so its cost has a
/// fixed part and a part that grows with the tile; a mix is held for several frames, so the
/// threshold is a build's cost spread over them. `--part-build-cost` sets it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BuildCost {
    pub fixed: f32,
    pub share: f32,
}

impl BuildCost {
    /// Builds every mix that saves a triangle (the control: no cost, no hysteresis).
    pub const FREE: BuildCost = BuildCost {
        fixed: 1.0,
        share: 0.0,
    };

    /// Whether drawing `to` triangles rather than `from` saves a build's worth on a tile of
    /// `whole` triangles at its drawn level.
    pub fn pays(self, from: u32, to: u32, whole: u32) -> bool {
        let saved = from.saturating_sub(to) as f32;
        saved > 0.0 && saved >= self.fixed + self.share * whole as f32
    }
}

/// Whether a tile drawn at `held` covers `key` at level `top`: every part at least as fine as
/// wanted, and the border still `top`'s.
fn covers(held: &PartKey, key: &PartKey, top: u32) -> bool {
    held.levels.iter().copied().max().map(u32::from) == Some(top)
        && held.levels.iter().zip(&key.levels).all(|(&h, &k)| h >= k)
}

/// Where each lattice point of `tile` first appears (the tile passed its check to be drawn).
pub fn blocks(terrain: &Terrain, tile: usize) -> Blocks {
    let info = &terrain.tiles[tile];
    let mesh_max = (info.header.mesh_max_x, info.header.mesh_max_y);
    match terrain.set_of(info).tile(info.tx, info.ty) {
        Ok(t) => {
            let levels = t.levels().len() as u32;
            Blocks::new(
                (0..levels).filter_map(|j| t.level(j).map(|l| l.positions)),
                mesh_max,
            )
        }
        Err(_) => Blocks::new(std::iter::empty(), mesh_max),
    }
}

/// [`blocks`] from `tile`'s blocks `0..levels` alone, as the checks passed them
/// ([`Terrain::part`]; None where one has not passed): what a mix of parts no finer than level
/// `levels - 1` reads, without the whole tile (a compact tile is rebuilt only as far as it
/// was checked).
pub fn blocks_through(terrain: &Terrain, tile: usize, levels: u32) -> Option<Blocks> {
    let info = &terrain.tiles[tile];
    let mesh_max = (info.header.mesh_max_x, info.header.mesh_max_y);
    let positions = (0..levels)
        .map(|j| {
            let bytes = terrain.part(tile, memory::Part::Positions(j))?;
            // In place where the blob keeps them aligned (it does: 4-byte sections).
            Some(match bytemuck::try_cast_slice::<u8, u32>(bytes) {
                Ok(words) => std::borrow::Cow::Borrowed(words),
                Err(_) => std::borrow::Cow::Owned(
                    bytes
                        .chunks_exact(4)
                        .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
                        .collect(),
                ),
            })
        })
        .collect::<Option<Vec<_>>>()?;
    Some(Blocks::new(positions.iter().map(|p| &p[..]), mesh_max))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(levels: [u8; 16]) -> PartKey {
        PartKey { levels }
    }

    #[test]
    fn a_build_pays_where_it_saves_its_cost() {
        let cost = BuildCost {
            fixed: 1000.0,
            share: 0.1,
        };
        // 40,000 triangles at the level: a build's worth is 5,000.
        assert!(cost.pays(30_000, 25_000, 40_000));
        assert!(!cost.pays(30_000, 25_001, 40_000));
        // Drawing more never pays, and the free cost builds whatever saves a triangle.
        assert!(!cost.pays(25_000, 30_000, 40_000));
        assert!(BuildCost::FREE.pays(2, 1, 40_000));
        assert!(!BuildCost::FREE.pays(1, 1, 40_000));
    }

    #[test]
    fn a_mix_covers_keys_no_finer_with_the_same_border() {
        let mut held = [2u8; 16];
        held[5] = 4;
        let mut wanted = [1u8; 16];
        wanted[5] = 4;
        assert!(covers(&key(held), &key(wanted), 4));
        // A part wanting more than held, or a drawn level the mix's border is not.
        let mut more = wanted;
        more[0] = 3;
        assert!(!covers(&key(held), &key(more), 4));
        assert!(!covers(&key(held), &key(wanted), 5));
    }

    fn moved(src: u64, dst: u64, bytes: u64) -> memory::Move {
        memory::Move {
            tile: 4,
            src,
            dst,
            bytes,
        }
    }

    fn upload(dst: u64, bytes: u64) -> memory::Upload {
        memory::Upload {
            tile: 9,
            part: memory::Part::Positions(0),
            dst,
            bytes,
            in_flight: false,
            chunk: dst,
            built: false,
            stream: None,
        }
    }

    /// A move copies the mixes in its source to its destination (the source keeps them: the
    /// moving frame's draws read there); what a move or an upload overwrites holds no mix.
    #[test]
    fn mixes_follow_the_pools_copies_and_writes() {
        let (a, b) = (key([1; 16]), key([2; 16]));
        let mut parts = PartDraws::default();
        parts.built(4, 100, a, 50);
        parts.built(4, 300, b, 50);
        parts.built(7, 2000, b, 40);
        // The chunk 80..200 moves to 1000; 300 is not in it; 2000 is overwritten by a move
        // from a region without a mix.
        parts.follow(&[moved(80, 1000, 120), moved(500, 1990, 20)], &[]);
        assert_eq!(parts.held(4, 1020), Some(a));
        assert_eq!(parts.held(4, 100), Some(a));
        assert_eq!(parts.held(4, 300), Some(b));
        assert_eq!(parts.held(7, 2000), None);
        // Another tile's region, and a tile's region at another offset, are not its mix.
        assert_eq!(parts.held(5, 1020), None);
        assert_eq!(parts.held(4, 1000), None);
        // An upload that starts inside a mix clears it; one that ends where a mix starts, not.
        parts.follow(&[], &[upload(1060, 4), upload(280, 20)]);
        assert_eq!(parts.held(4, 1020), None);
        assert_eq!(parts.held(4, 300), Some(b));
        // A mix only partly in a move's source is not carried (its copy would be a torso).
        parts.follow(&[moved(320, 3000, 100)], &[]);
        assert_eq!(parts.held(4, 3000), None);
        assert_eq!(parts.held(4, 300), Some(b));
    }
}
