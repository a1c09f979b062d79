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

use std::collections::{HashMap, HashSet};

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
    /// level) and its array's length, where drawing the mix pays for building it
    /// ([`BuildCost`]). A draw whose parts cannot be drawn apart at that level, or whose mix
    /// would save too little, keeps its level throughout.
    ///
    /// What the draw's region holds is kept while it covers the key (every part at least as
    /// fine as wanted: finer parts are within tau, and their extra vertices sit on the
    /// coarser surface until their own morph begins, so the image is the key's) and drawing
    /// it costs fewer extra triangles than a build. The region holds the mix this module last
    /// built there, or else the manager's array of the whole level, which covers every key
    /// and is never built again for a part's sake.
    pub fn assign(&mut self, terrain: &Terrain, plan: &mut Plan, cost: BuildCost) {
        let Plan { draws, uploads, .. } = plan;
        let built = manager_builds(uploads);
        for d in draws.iter_mut() {
            d.key = None;
            let Some(wanted) = d.parts else { continue };
            // Read with the tile's check (drawn tiles passed it).
            let Some((centres, counts)) = terrain.tiles[d.tile].paged().map(|p| &p.parts) else {
                continue;
            };
            let Some(key) = centres.key(&wanted, d.level) else {
                continue;
            };
            // The room is level G's array: a longer mix (never seen) is drawn at G.
            let whole = (d.index_count, d.triangle_count);
            let fits = |k: &PartKey| counts.count(k).filter(|&(length, _)| length <= whole.0);
            let Some(exact) = fits(&key) else { continue };
            // A region the manager builds this frame holds the whole level.
            let rebuilt = built.contains(&(d.tile, d.index_offset));
            let held = match self.held.get(&d.tile) {
                Some(&(at, held)) if at == d.index_offset && !rebuilt => Some(held),
                _ => None,
            };
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

    /// The draws whose arrays this module builds this frame. This module remembers the regions
    /// it wrote a mix into; any other region holds what the manager built there (a level). A
    /// draw at a key is built unless its region holds that key; a draw at one level is built
    /// only where this module wrote a mix into the tile's regions since the manager last built
    /// there, so that drawing whole tiles (discrete levels, `--whole-tiles`) builds nothing
    /// more than the manager asks. A build of the manager's where a draw at a key draws from
    /// is replaced by the draw's (one build writes there). Call after [`PartDraws::assign`].
    pub fn rebuilds(&mut self, plan: &Plan) -> Vec<Rebuild> {
        let manager = manager_builds(&plan.uploads);
        let built = |tile: usize, at: u64| manager.contains(&(tile, at));
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

/// The regions the manager builds a level's array into this frame, by tile and pool offset
/// (a set, so that a frame's cost follows its draws and uploads, not their product).
fn manager_builds(uploads: &[memory::Upload]) -> HashSet<(usize, u64)> {
    uploads
        .iter()
        .filter(|u| u.built)
        .map(|u| (u.tile as usize, u.dst))
        .collect()
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
}
