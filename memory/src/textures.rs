//! Texture slots (paper, section 6: "additionally a number of textures with a fixed resolution
//! is allocated"): a fixed set of layers of one array image, each holding one tile's texture,
//! reused least-recently-used, filled coarse mips first under the frame's byte budget.
//!
//! Like the chunk pool, this decides and does not touch the GPU. Each frame the renderer
//! passes the visible tiles front to back with the finest mip each one's footprint needs and
//! the bytes the geometry left in the frame's budget; it gets back, per tile, the slot to
//! sample and its finest resident mip (the shader clamps its level of detail there), and the
//! mips to copy into which slot. A slot a frame in flight may sample is never given to another
//! tile before that frame completes, and mips are only ever added to a slot's resident range,
//! so a frame in flight never reads a layer that is being written.
//!
//! Mips are numbered as in the file: 0 is the finest. A slot holds mips `finest..mips`, a
//! contiguous range ending at the coarsest. A newly placed tile always gets its *base*, the
//! mips smaller than [`BASE_MIP_TEXELS`] (a few hundred bytes), even over budget, so a drawn
//! tile never samples a missing texture; finer mips follow within the budget, one mip level at
//! a time across all tiles (all tiles' mip `k` before any tile's mip `k - 1`), nearest first.

use crate::manager::TileId;
use std::collections::HashMap;

/// Mips at most this many texels across are a new slot's base, sent regardless of budget.
pub const BASE_MIP_TEXELS: u32 = 32;

/// The fixed texture budget: how many slots, and each mip's size.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureConfig {
    pub slots: usize,
    /// Bytes of each mip, finest first.
    pub mip_bytes: Vec<u64>,
    /// Texels across each mip, finest first.
    pub mip_texels: Vec<u32>,
}

impl TextureConfig {
    pub fn mips(&self) -> u32 {
        self.mip_bytes.len() as u32
    }

    /// Bytes of one slot (the whole mip chain).
    pub fn slot_bytes(&self) -> u64 {
        self.mip_bytes.iter().sum()
    }

    /// The finest mip of a slot's base (the mips of at most [`BASE_MIP_TEXELS`] texels).
    pub fn base(&self) -> u32 {
        self.mip_texels
            .iter()
            .position(|&t| t <= BASE_MIP_TEXELS)
            .unwrap_or(self.mip_texels.len().saturating_sub(1)) as u32
    }
}

/// A visible tile and the finest mip its footprint on screen needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TextureRequest {
    pub tile: TileId,
    pub finest: u32,
}

/// What a tile samples this frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TextureGrant {
    pub tile: TileId,
    /// The slot (array layer), or None when every slot is taken by nearer tiles this frame or
    /// by frames in flight: the tile is drawn without its texture.
    pub slot: Option<u32>,
    /// The finest resident mip (the shader's level-of-detail clamp); `mips` with no slot.
    pub finest: u32,
}

/// One mip to copy into one slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TextureUpload {
    pub tile: TileId,
    pub slot: u32,
    pub mip: u32,
    pub bytes: u64,
}

/// A frame's texture counters (the log's columns).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TextureStats {
    pub upload_bytes: u64,
    /// Slots holding no tile after this frame's placements.
    pub slots_free: u32,
    /// Visible tiles drawn without a texture (no slot could be had).
    pub without_slot: u32,
    /// Visible tiles whose finest resident mip is coarser than their footprint needs.
    pub coarser: u32,
    /// Slots given to a new tile this frame, and of those, how many held another one.
    pub placed: u32,
    pub evicted: u32,
}

#[derive(Clone, Copy, Debug)]
struct Slot {
    tile: Option<TileId>,
    /// Finest resident mip; `mips` when none.
    finest: u32,
    /// The last frame that sampled it.
    last_used: Option<u64>,
}

/// The slots and which tile each holds.
#[derive(Clone, Debug)]
pub struct TextureSlots {
    config: TextureConfig,
    slots: Vec<Slot>,
    of_tile: HashMap<TileId, u32>,
}

impl TextureSlots {
    pub fn new(config: TextureConfig) -> TextureSlots {
        let mips = config.mips();
        TextureSlots {
            slots: vec![
                Slot {
                    tile: None,
                    finest: mips,
                    last_used: None,
                };
                config.slots
            ],
            config,
            of_tile: HashMap::new(),
        }
    }

    pub fn config(&self) -> &TextureConfig {
        &self.config
    }

    /// The slot tile `tile` holds and its finest resident mip, if any.
    pub fn resident(&self, tile: TileId) -> Option<(u32, u32)> {
        let s = *self.of_tile.get(&tile)?;
        Some((s, self.slots[s as usize].finest))
    }

    /// Plans frame `frame`: `completed` is the newest frame the GPU has finished (every frame
    /// up to it); `requests` are the visible tiles, front to back; `budget` the bytes this
    /// frame may still send. Returns one grant per request, in order, the uploads in the
    /// order to record them, and the counters.
    pub fn plan(
        &mut self,
        frame: u64,
        completed: Option<u64>,
        requests: &[TextureRequest],
        budget: u64,
    ) -> (Vec<TextureGrant>, Vec<TextureUpload>, TextureStats) {
        let mips = self.config.mips();
        let mut stats = TextureStats::default();
        // Touch what is resident first, so placing one visible tile never evicts another.
        for r in requests {
            if let Some(&s) = self.of_tile.get(&r.tile) {
                self.slots[s as usize].last_used = Some(frame);
            }
        }
        let mut uploads = Vec::new();
        let mut spent = 0u64;
        let base = self.config.base();
        for r in requests {
            if self.of_tile.contains_key(&r.tile) {
                continue;
            }
            let Some(s) = self.victim(frame, completed) else {
                continue;
            };
            let slot = &mut self.slots[s as usize];
            if let Some(old) = slot.tile.replace(r.tile) {
                self.of_tile.remove(&old);
                stats.evicted += 1;
            }
            stats.placed += 1;
            slot.last_used = Some(frame);
            slot.finest = base;
            self.of_tile.insert(r.tile, s);
            for mip in (base..mips).rev() {
                let bytes = self.config.mip_bytes[mip as usize];
                spent += bytes;
                uploads.push(TextureUpload {
                    tile: r.tile,
                    slot: s,
                    mip,
                    bytes,
                });
            }
        }
        // Finer mips: one level at a time over all tiles, nearest first, while the budget lasts.
        'levels: for mip in (0..base).rev() {
            for r in requests {
                let Some(&s) = self.of_tile.get(&r.tile) else {
                    continue;
                };
                let slot = &mut self.slots[s as usize];
                if slot.finest != mip + 1 || mip < r.finest.min(mips - 1) {
                    continue;
                }
                let bytes = self.config.mip_bytes[mip as usize];
                if spent + bytes > budget {
                    break 'levels;
                }
                spent += bytes;
                slot.finest = mip;
                uploads.push(TextureUpload {
                    tile: r.tile,
                    slot: s,
                    mip,
                    bytes,
                });
            }
        }
        let grants = requests
            .iter()
            .map(|r| match self.of_tile.get(&r.tile) {
                Some(&s) => {
                    let finest = self.slots[s as usize].finest;
                    if finest > r.finest.min(mips - 1) {
                        stats.coarser += 1;
                    }
                    TextureGrant {
                        tile: r.tile,
                        slot: Some(s),
                        finest,
                    }
                }
                None => {
                    stats.without_slot += 1;
                    TextureGrant {
                        tile: r.tile,
                        slot: None,
                        finest: mips,
                    }
                }
            })
            .collect();
        stats.upload_bytes = spent;
        stats.slots_free = self.slots.iter().filter(|s| s.tile.is_none()).count() as u32;
        (grants, uploads, stats)
    }

    /// A slot to give a new tile this frame: a free one, else the least recently used whose
    /// last use is neither this frame nor a frame in flight.
    fn victim(&self, frame: u64, completed: Option<u64>) -> Option<u32> {
        if let Some(free) = self.slots.iter().position(|s| s.tile.is_none()) {
            return Some(free as u32);
        }
        self.slots
            .iter()
            .enumerate()
            .filter(|(_, s)| {
                s.last_used
                    .is_none_or(|u| u < frame && completed.is_some_and(|c| u <= c))
            })
            .min_by_key(|(_, s)| s.last_used)
            .map(|(i, _)| i as u32)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A 544-texel layer's chain (BC1), as tiletool lays out a 512-texel interior.
    pub fn config(slots: usize) -> TextureConfig {
        let mip_texels: Vec<u32> = (0..8).map(|m| 544u32 >> m).collect();
        let mip_bytes = mip_texels
            .iter()
            .map(|&t| u64::from(t.div_ceil(4)).pow(2) * 8)
            .collect();
        TextureConfig {
            slots,
            mip_bytes,
            mip_texels,
        }
    }

    fn want(tiles: &[TileId], finest: u32) -> Vec<TextureRequest> {
        tiles
            .iter()
            .map(|&tile| TextureRequest { tile, finest })
            .collect()
    }

    #[test]
    fn a_new_tile_gets_its_base_at_once_and_finer_mips_coarse_first_within_the_budget() {
        let mut t = TextureSlots::new(config(4));
        let c = t.config().clone();
        // Base: mips 5, 6, 7 (17, 8, 4 texels); then the budget decides.
        let (grants, uploads, stats) = t.plan(0, None, &want(&[0, 1], 0), 0);
        let base: u64 = c.mip_bytes[5..].iter().sum();
        assert_eq!(
            stats.upload_bytes,
            2 * base,
            "the base goes even over budget"
        );
        assert!(grants.iter().all(|g| g.slot.is_some() && g.finest == 5));
        assert_eq!(stats.coarser, 2);
        // Coarse first: a budget for mip 4 of both tiles and mip 3 of one.
        let budget = 2 * c.mip_bytes[4] + c.mip_bytes[3];
        let (grants, uploads2, stats) = t.plan(1, Some(0), &want(&[0, 1], 0), budget);
        assert_eq!(stats.upload_bytes, budget);
        let order: Vec<(TileId, u32)> = uploads2.iter().map(|u| (u.tile, u.mip)).collect();
        assert_eq!(
            order,
            vec![(0, 4), (1, 4), (0, 3)],
            "all of mip 4 before any mip 3, nearest first"
        );
        assert_eq!((grants[0].finest, grants[1].finest), (3, 4));
        assert!(uploads.iter().all(|u| u.mip >= 5));
    }

    #[test]
    fn a_tile_needing_only_coarse_mips_gets_no_finer_ones() {
        let mut t = TextureSlots::new(config(2));
        t.plan(0, None, &want(&[0], 3), u64::MAX);
        assert_eq!(t.resident(0), Some((0, 3)));
        let (_, uploads, stats) = t.plan(1, Some(0), &want(&[0], 3), u64::MAX);
        assert!(uploads.is_empty() && stats.coarser == 0);
        // Coming closer, it asks for mip 1 and gets 2 and 1.
        let (_, uploads, _) = t.plan(2, Some(1), &want(&[0], 1), u64::MAX);
        let mips: Vec<u32> = uploads.iter().map(|u| u.mip).collect();
        assert_eq!(mips, vec![2, 1]);
    }

    #[test]
    fn slots_in_use_this_frame_or_in_flight_are_never_taken() {
        let mut t = TextureSlots::new(config(2));
        t.plan(0, None, &want(&[0, 1], 0), u64::MAX);
        // Frame 1: tiles 2 and 3 visible, frame 0 still in flight: no slot can be had.
        let (grants, uploads, stats) = t.plan(1, None, &want(&[2, 3], 0), u64::MAX);
        assert!(grants.iter().all(|g| g.slot.is_none() && g.finest == 8));
        assert!(uploads.is_empty());
        assert_eq!((stats.without_slot, stats.evicted), (2, 0));
        // Frame 2, frame 0 done (frame 1 sampled nothing): both slots go to the new tiles.
        let (grants, _, stats) = t.plan(2, Some(0), &want(&[2, 3], 0), u64::MAX);
        assert!(grants.iter().all(|g| g.slot.is_some()));
        assert_eq!(stats.evicted, 2);
        assert_eq!((t.resident(0), t.resident(1)), (None, None));
        // A visible tile keeps its slot over a newcomer even with frames done: tile 2 is
        // drawn this frame, so tile 4 takes tile 3's (older) slot, and tile 5 gets none.
        let (grants, _, _) = t.plan(3, Some(2), &want(&[2], 0), u64::MAX);
        assert!(grants[0].slot.is_some());
        let (grants, _, _) = t.plan(4, Some(3), &want(&[2, 4, 5], 0), u64::MAX);
        assert_eq!(grants[0].slot, t.resident(2).map(|r| r.0));
        assert!(grants[1].slot.is_some() && grants[2].slot.is_none());
        assert_eq!(t.resident(3), None);
    }

    #[test]
    fn the_least_recently_used_slot_goes_first() {
        let mut t = TextureSlots::new(config(3));
        t.plan(0, None, &want(&[0, 1, 2], 0), u64::MAX);
        t.plan(1, Some(0), &want(&[1], 0), u64::MAX);
        t.plan(2, Some(1), &want(&[2], 0), u64::MAX);
        // Tile 0 was last drawn at frame 0, tile 1 at 1, tile 2 at 2: tile 0 goes.
        t.plan(3, Some(2), &want(&[9], 0), u64::MAX);
        assert_eq!(t.resident(0), None);
        assert!(t.resident(1).is_some() && t.resident(2).is_some() && t.resident(9).is_some());
    }

    #[test]
    fn random_frames_keep_every_slot_rule() {
        // Random visible sets, needs and budgets, two frames in flight. Checked every frame:
        // each upload is the next finer mip of its slot (a new tile's chain starts at the
        // coarsest), the base is always resident, no two tiles share a slot, and a tile loses
        // its slot only when no frame in flight sampled it.
        let mips = config(3).mips();
        let mut t = TextureSlots::new(config(3));
        let mut cur: HashMap<TileId, (u32, u32)> = HashMap::new();
        let mut last_drawn: HashMap<TileId, u64> = HashMap::new();
        let mut state = 1u64;
        for frame in 0..500u64 {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let mut tiles: Vec<TileId> = (0..1 + (state >> 61) as usize)
                .map(|k| ((state >> (7 * k)) % 6) as TileId)
                .collect();
            tiles.sort_unstable();
            tiles.dedup();
            let finest = ((state >> 40) % 8) as u32;
            let budget = (state >> 20) % 60_000;
            let completed = frame.checked_sub(2);
            let (grants, uploads, _) = t.plan(frame, completed, &want(&tiles, finest), budget);
            for u in &uploads {
                let f = match cur.get(&u.tile) {
                    Some(&(slot, f)) if slot == u.slot => f,
                    _ => mips,
                };
                assert_eq!(
                    u.mip + 1,
                    f,
                    "frame {frame}: tile {} got mip {}",
                    u.tile,
                    u.mip
                );
                cur.insert(u.tile, (u.slot, u.mip));
            }
            let mut owners = HashMap::new();
            for k in 0..6 as TileId {
                match t.resident(k) {
                    Some(r) => {
                        assert_eq!(cur.get(&k), Some(&r), "frame {frame}: tile {k}");
                        assert!(r.1 <= 5, "the base is resident");
                        assert!(owners.insert(r.0, k).is_none(), "slot {} shared", r.0);
                    }
                    None => {
                        if cur.remove(&k).is_some() {
                            let drawn = last_drawn.get(&k).copied();
                            assert!(
                                drawn.is_none_or(|d| completed.is_some_and(|c| d <= c)),
                                "frame {frame}: tile {k} evicted while frame {drawn:?} may sample it"
                            );
                        }
                    }
                }
            }
            for g in grants.iter().filter(|g| g.slot.is_some()) {
                last_drawn.insert(g.tile, frame);
            }
        }
    }
}
