//! Where a pyramid's cut stands in for tiles not checked yet (`vkterrain --checks`): what the
//! frame checks, what it leaves to the thread that checks ahead, and the tiles it draws
//! meanwhile ([`crate::cut::stand_in`]).

use std::collections::HashMap;

use glam::DVec3;

use super::nearest_first;
use crate::camera::View;
use crate::terrain::Terrain;

/// When the tiles of a pyramid's cut are checked (`vkterrain --checks`). A base grid's tiles
/// are always checked on the frame that first needs them.
///
/// Where a tile is not checked yet, its nearest ancestor that passed is drawn over its ground
/// ([`crate::cut::stand_in`]), and the tiles between them are asked for, coarse layers first
/// and nearest first within a layer, so that the ground refines from coarse to fine.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CheckPolicy {
    /// Off the frames, on the thread that checks ahead of need: no frame waits for more than
    /// the top of the pyramid, but the detail arrives later (bench/README, "When the cut's
    /// tiles are checked"); a tile drawn already is drawn at its finest checked level until
    /// the finer one it wants passes.
    Behind,
    /// At most this many a frame, on the frame (after it is planned, for the next), the
    /// others not queued off the frame: what a frame draws depends on the frames before it
    /// alone (the tests' deterministic stand-ins). A tile drawn already is checked through a
    /// finer level on the frame that first wants it.
    PerFrame(u32),
    /// Every tile on the frame that first needs it, before anything is drawn (the default).
    OnFrame,
}

/// What a frame draws of the cut `wanted` (at `tau`; its tiles nearest first, with their
/// levels) under `policy`: the tiles, nearest first with their levels (a stand-in at the level
/// [`crate::cut::level_at`] gives it); how many tiles of the cut were stood in for; and how
/// many tiles were checked on the frame.
pub(super) fn drawn_cut(
    terrain: &Terrain,
    view: &View,
    camera: DVec3,
    tau: f64,
    wanted: &[(usize, u32)],
    policy: CheckPolicy,
) -> (Vec<(usize, u32)>, usize, u64) {
    // On the frame, every tile first, on every core, through the level it is drawn at.
    let mut checked = 0;
    if policy == CheckPolicy::OnFrame {
        let unchecked: Vec<(usize, u32)> = wanted
            .iter()
            .copied()
            .filter(|&(i, _)| terrain.tiles[i].usable().is_none())
            .collect();
        terrain.check_all_through(&unchecked);
        checked = unchecked.len() as u64;
    }
    let level: HashMap<usize, u32> = wanted.iter().copied().collect();
    let mut checks = FrameChecks {
        terrain,
        level: &level,
        later: Vec::new(),
        checked,
    };
    let nodes: Vec<crate::cut::Node> = wanted
        .iter()
        .map(|&(tile, level)| crate::cut::Node {
            layer: terrain.tiles[tile].layer,
            tile,
            level,
        })
        .collect();
    let balance = crate::fault::Fault::of_process() != Some(crate::fault::Fault::NoStandInBalance);
    let drawn = crate::cut::stand_in(terrain, &nodes, &mut checks, balance);
    // The tiles still to check, coarse layers first, nearest first within a layer: each one
    // checked refines the ground drawn by the one over it.
    let mut later = checks.later;
    let mut seen = std::collections::HashSet::new();
    later.retain(|&i| seen.insert(i) && terrain.tiles[i].usable().is_none());
    later.sort_by_key(|&i| std::cmp::Reverse(terrain.tiles[i].layer));
    // An ancestor is checked through level 0 to stand in; the frame checks it further where
    // it is drawn finer.
    let later: Vec<(usize, u32)> = later
        .into_iter()
        .map(|i| (i, level.get(&i).copied().unwrap_or(0)))
        .collect();
    match policy {
        CheckPolicy::Behind => terrain.check_first(&later),
        CheckPolicy::PerFrame(n) => {
            let now = &later[..later.len().min(n as usize)];
            terrain.check_all_through(now);
            checks.checked += now.len() as u64;
        }
        CheckPolicy::OnFrame => {}
    }
    let tiles = drawn
        .tiles
        .iter()
        .map(|&i| {
            let l = level
                .get(&i)
                .copied()
                .unwrap_or_else(|| crate::cut::level_at(terrain, view, camera, tau, i));
            (i, l)
        })
        .collect();
    (
        nearest_first(terrain, camera, tiles),
        drawn.stood_in,
        checks.checked,
    )
}

/// The frame's side of [`crate::cut::Checks`]: the tiles to check later are listed, for the
/// policy to check off the frame or on the next ones.
struct FrameChecks<'a> {
    terrain: &'a Terrain,
    /// The level each tile of the cut is drawn at (what it is checked through).
    level: &'a HashMap<usize, u32>,
    later: Vec<usize>,
    checked: u64,
}

impl crate::cut::Checks for FrameChecks<'_> {
    fn state(&self, i: usize) -> Option<bool> {
        self.terrain.tiles[i].usable()
    }

    fn later(&mut self, i: usize) {
        self.later.push(i);
    }

    fn now(&mut self, i: usize) -> bool {
        self.checked += 1;
        let level = self.level.get(&i).copied().unwrap_or(0);
        self.terrain.check_through(i, level).is_ok()
    }
}
