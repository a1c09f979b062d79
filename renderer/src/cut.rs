//! Choosing tiles from the tile pyramid (issue 26): a cut through it, coarse tiles far away and
//! base tiles near the camera, whose cost follows what is on screen rather than how many tiles
//! the set has. Not yet drawn: this is the selection, measured on its own (`tilebench cut`);
//! the frame still draws the base grid.
//!
//! The walk starts at the top layer and descends only into tiles whose box meets the frustum.
//! A layer tile's level errors are those against the base grid's samples under it (the
//! builder measures them, `tiles::pyramid::base_errors`; the terrain reads them in their
//! place), so a tile of layer `p >= 1` is kept when its finest level already meets `tau`
//! everywhere on screen, `e_finest <= tau / S`, with `S` the proved bound on pixels per vertical
//! metre over its box's on-screen pieces ([`lod::tolerable_error`]): every base sample under it
//! is then drawn within `tau` pixels, as a base tile's would be. Otherwise its children replace
//! it. Base tiles are kept when visible, as today. A kept tile takes the coarsest level that
//! meets `tau` ([`lod::level_for`]). A layer tile that meets `tau` is still replaced by its
//! children where their triangles, plus [`DRAW_TRIANGLES`] a draw, come to less than its own:
//! one look ahead, so the walk visits at most five tiles for each it keeps or splits.
//!
//! What the frame will need besides, and this does not do yet: stitching where tiles of two
//! layers meet (a layer tile's side spans two of the layer below), geomorphing that carries on
//! across the change from a parent to its children, and the manager and the prefetcher keyed by
//! (layer, tile).

use glam::DVec3;

use crate::camera::View;
use crate::lod::{self, Bound};
use crate::pyramid::Pyramid;

/// One tile of a cut: its layer, its index in that layer and the level it would be drawn at.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Node {
    pub layer: u32,
    pub tile: usize,
    pub level: u32,
}

/// A cut through the pyramid, and what choosing it cost.
#[derive(Clone, Debug, Default)]
pub struct Cut {
    pub nodes: Vec<Node>,
    /// Tiles looked at: those kept, those split into their children and those culled.
    pub visited: usize,
}

impl Cut {
    /// Triangles the cut's tiles have at their levels.
    pub fn triangles(&self, pyramid: &Pyramid) -> u64 {
        self.nodes
            .iter()
            .map(|n| {
                let tile = &pyramid.layers[n.layer as usize].tiles[n.tile];
                u64::from(tile.levels[n.level as usize].triangle_count)
            })
            .sum()
    }
}

/// What one more draw costs, in triangles, when a tile is weighed against its children.
pub const DRAW_TRIANGLES: u64 = 256;

/// The cut for a view: see the module header. Nodes come in no particular order.
pub fn cut(pyramid: &Pyramid, view: &View, camera: DVec3, tau: f64) -> Cut {
    cut_with(pyramid, view, camera, tau, true)
}

/// [`cut`], where `weigh_children` false keeps every layer tile that meets tau (the rule
/// without the look ahead, kept to measure what it costs).
pub fn cut_with(
    pyramid: &Pyramid,
    view: &View,
    camera: DVec3,
    tau: f64,
    weigh_children: bool,
) -> Cut {
    let planes = view.frustum();
    let top = pyramid.top();
    let mut stack: Vec<(u32, usize)> = (0..pyramid.layers[top as usize].tiles.len())
        .map(|i| (top, i))
        .collect();
    let mut out = Cut::default();
    // A tile's level, and its triangles there, if it is on screen and meets tau (None: it
    // needs its children; Some(None): off screen).
    let choose = |p: u32, i: usize, visited: &mut usize| -> Option<Option<(u32, u64)>> {
        *visited += 1;
        let tile = &pyramid.layers[p as usize].tiles[i];
        let (lo, hi) = lod::tile_box(tile);
        if crate::cull::box_outside(&planes, lo - camera, hi - camera) {
            return Some(None);
        }
        let r = lod::tolerable_error(view, camera, tile, tau, Bound::Guaranteed);
        let finest = tile.levels.last().map_or(0.0, |l| f64::from(l.max_error));
        if p > 0 && finest > r {
            return None;
        }
        let level = lod::level_for(tile, r);
        Some(Some((
            level,
            u64::from(tile.levels[level as usize].triangle_count),
        )))
    };
    while let Some((p, i)) = stack.pop() {
        let chosen = match choose(p, i, &mut out.visited) {
            None => {
                stack.extend(pyramid.children(p, i).map(|c| (p - 1, c)));
                continue;
            }
            Some(None) => continue,
            Some(Some(chosen)) => chosen,
        };
        // A layer tile that meets tau is still replaced by its children where they cost less:
        // a big tile takes the level its nearest point needs all over, its children each their
        // own.
        if p > 0 && weigh_children {
            let mut children = 0u64;
            for c in pyramid.children(p, i) {
                match choose(p - 1, c, &mut out.visited) {
                    Some(Some((_, t))) => children += t + DRAW_TRIANGLES,
                    Some(None) => {}
                    None => {
                        children = u64::MAX;
                        break;
                    }
                }
            }
            if children < chosen.1 + DRAW_TRIANGLES {
                stack.extend(pyramid.children(p, i).map(|c| (p - 1, c)));
                continue;
            }
        }
        out.nodes.push(Node {
            layer: p,
            tile: i,
            level: chosen.0,
        });
    }
    out
}
