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

use std::collections::HashMap;

use tiles::parts::{Blocks, PartKey};

use crate::plan::Plan;
use crate::terrain::Terrain;

/// What part-by-part drawing remembers between frames.
#[derive(Default)]
pub struct PartDraws {
    /// Per tile: where this module last built a mix for it, and the mix's key.
    held: HashMap<usize, (u64, PartKey)>,
}

/// One array to build this frame: the draw's index in the plan.
pub type Rebuild = usize;

impl PartDraws {
    /// Gives each draw that has part levels the key it is drawn at (at most its granted
    /// level) and its array's length. A draw whose parts cannot be drawn apart at that level
    /// keeps its level throughout.
    pub fn assign(&mut self, terrain: &Terrain, plan: &mut Plan) {
        for d in &mut plan.draws {
            d.key = None;
            let Some(wanted) = d.parts else { continue };
            // Read with the tile's check (drawn tiles passed it).
            let Some((centres, counts)) = terrain.tiles[d.tile].paged().map(|p| &p.parts) else {
                continue;
            };
            let Some(key) = centres.key(&wanted, d.level) else {
                continue;
            };
            if key.levels.iter().all(|&l| u32::from(l) == d.level) {
                continue;
            }
            // The key the region holds, while it covers this one closely enough: finer parts
            // are within tau, and keeping it saves a build.
            let key = match self.held.get(&d.tile) {
                Some(&(at, held)) if at == d.index_offset && keeps(&held, &key, d.level) => held,
                _ => key,
            };
            // The room is level G's array: a longer one (never seen) is drawn at G.
            if let Some((length, triangles)) = counts.count(&key) {
                if length <= d.index_count {
                    d.key = Some(key);
                    d.index_count = length;
                    d.triangle_count = triangles;
                }
            }
        }
    }

    /// The draws whose arrays this module builds this frame. This module remembers the regions
    /// it wrote a mix into; any other region holds what the manager built there (a level). A
    /// draw at a key is built unless its region holds that key; a draw at one level is built
    /// only where this module wrote a mix into the tile's regions since the manager last built
    /// there, so that drawing whole tiles (discrete levels, `--whole-tiles`) builds nothing
    /// more than the manager asks. A build of the manager's where a draw at a key draws from
    /// is replaced by the draw's (one build writes there). Call after [`PartDraws::assign`].
    pub fn rebuilds(&mut self, plan: &Plan) -> Vec<Rebuild> {
        let built = |tile: usize, at: u64| {
            plan.uploads
                .iter()
                .any(|u| u.built && u.tile as usize == tile && u.dst == at)
        };
        // A level the manager builds over a mix replaces it.
        self.held.retain(|&tile, &mut (at, _)| !built(tile, at));
        let mut out = Vec::new();
        for (k, d) in plan.draws.iter().enumerate() {
            match (d.key, self.held.get(&d.tile)) {
                (Some(key), held) if held == Some(&(d.index_offset, key)) => {}
                (Some(key), _) => {
                    self.held.insert(d.tile, (d.index_offset, key));
                    out.push(k);
                }
                (None, None) => {}
                (None, Some(_)) => {
                    self.held.remove(&d.tile);
                    if !built(d.tile, d.index_offset) {
                        out.push(k);
                    }
                }
            }
        }
        out
    }
}

/// Levels finer than wanted a part may stay drawn at rather than its array be built again.
pub const SLACK: u8 = 1;

/// Whether a tile drawn at `held` may stay so where it wants `key`, at level `top`: every part
/// at least as fine as wanted and at most [`SLACK`] finer, and the border still `top`'s.
fn keeps(held: &PartKey, key: &PartKey, top: u32) -> bool {
    held.levels.iter().copied().max().map(u32::from) == Some(top)
        && held
            .levels
            .iter()
            .zip(&key.levels)
            .all(|(&h, &k)| h >= k && h <= k.saturating_add(SLACK))
}

/// Where each lattice point of `tile` first appears (the tile passed its check to be drawn).
pub fn blocks(terrain: &Terrain, tile: usize) -> Blocks {
    let info = &terrain.tiles[tile];
    let mesh_max = (info.header.mesh_max_x, info.header.mesh_max_y);
    match terrain.set.tile(info.tx, info.ty) {
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
