//! Choosing tiles from the tile pyramid (issue 26): a cut through it, coarse tiles far away and
//! base tiles near the camera, whose cost follows what is on screen rather than how many tiles
//! the set has. `vkterrain --pyramid` draws it ([`crate::plan`]; each tile at the cut's
//! level, or geomorphing, at the morph rule's); `tilebench cut` measures the choice on its own.
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
//! one look ahead, whose choices for the children are kept for when they are walked, so no
//! tile is looked at twice.
//!
//! Last, the cut is balanced: a kept tile beside ground that was split two layers finer is
//! split as well, until every two neighbours are at most one layer apart, so that a tile's
//! side meets one tile of its own layer or two of the layer below, never more.
//!
//! The frame stitches where tiles of two layers meet (a layer tile's side spans two of the
//! layer below, [`crate::stitch::stitch_across`]); the memory manager and the prefetcher see
//! a layer's tiles as any others (one index space, [`Terrain::tiles`]). Geomorphing morphs each
//! tile's own levels, a layer tile's as a base tile's; not done yet: geomorphing that carries
//! on across the change from a parent to its children, which stays discrete (a pop).

use std::collections::HashSet;

use glam::DVec3;

use crate::camera::View;
use crate::lod::{self, Bound};
use crate::terrain::Terrain;

/// One tile of a cut: its layer, its index in [`Terrain::tiles`] and the level it is drawn at.
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
    pub fn triangles(&self, terrain: &Terrain) -> u64 {
        self.nodes
            .iter()
            .map(|n| {
                let tile = &terrain.tiles[n.tile];
                u64::from(tile.levels[n.level as usize].triangle_count)
            })
            .sum()
    }
}

/// What one more draw costs, in triangles, when a tile is weighed against its children.
pub const DRAW_TRIANGLES: u64 = 256;

/// The cut for a view: see the module header. Nodes come in no particular order.
pub fn cut(terrain: &Terrain, view: &View, camera: DVec3, tau: f64) -> Cut {
    cut_with(terrain, view, camera, tau, Rules::ALL)
}

/// Which of the cut's rules apply beyond meeting tau: each can be turned off to measure what
/// it does.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rules {
    /// Replace a layer tile that meets tau by its children where they cost less.
    pub weigh_children: bool,
    /// Split tiles until every two neighbours are at most a layer apart.
    pub balance: bool,
    /// Weigh and level tiles as geomorphing draws them ([`lod::morph_level`]: a level with
    /// the blend's margin) rather than at [`lod::level_for`]'s.
    pub morph: bool,
}

impl Rules {
    pub const ALL: Rules = Rules {
        weigh_children: true,
        balance: true,
        morph: false,
    };
}

/// [`cut`] under `rules`.
pub fn cut_with(terrain: &Terrain, view: &View, camera: DVec3, tau: f64, rules: Rules) -> Cut {
    let weigh_children = rules.weigh_children;
    let walk = Walk {
        terrain,
        view,
        planes: view.frustum(),
        camera,
        tau,
        weigh_children,
        morph: rules.morph,
    };
    let top = terrain.top();
    let mut stack: Vec<Pending> = (0..terrain.layers[top as usize].len())
        .map(|i| (terrain.index_in(top, i), None))
        .collect();
    let mut out = Cut::default();
    let mut split = HashSet::new();
    walk.run(&mut stack, &mut out, &mut split);
    if !rules.balance {
        return out;
    }
    // Balance: a tile beside ground drawn two or more layers finer is split too, until every
    // two neighbours are at most a layer apart. Splitting only goes down, so it ends.
    loop {
        let mut balance: Vec<usize> = (0..out.nodes.len())
            .filter(|&k| {
                let n = out.nodes[k];
                n.layer >= 2 && finer_beside(terrain, &split, n.tile)
            })
            .collect();
        if balance.is_empty() {
            break;
        }
        balance.sort_unstable();
        for k in balance.into_iter().rev() {
            let n = out.nodes.swap_remove(k);
            split.insert(n.tile);
            stack.extend(terrain.children(n.tile).map(|c| (c, None)));
        }
        walk.run(&mut stack, &mut out, &mut split);
    }
    out
}

/// Whether tile `i` (of layer `p >= 1`) has, across one of its sides, ground drawn two or
/// more layers finer: its neighbour in layer `p` was split, and so was one of that
/// neighbour's children along the shared side (conservative: those children's own children
/// might all be culled).
fn finer_beside(terrain: &Terrain, split: &HashSet<usize>, i: usize) -> bool {
    let t = &terrain.tiles[i];
    let p = t.layer;
    let (tx, ty) = (i64::from(t.tx), i64::from(t.ty));
    let at = |p: u32, x: i64, y: i64| {
        (x >= 0 && y >= 0)
            .then(|| terrain.tile_in(p, x as u32, y as u32))
            .flatten()
    };
    [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)]
        .iter()
        .any(|&(dx, dy)| {
            let (nx, ny) = (tx + dx, ty + dy);
            if !at(p, nx, ny).is_some_and(|n| split.contains(&n)) {
                return false;
            }
            // The neighbour's two children that touch this tile.
            let along: [(i64, i64); 2] = match (dx, dy) {
                (1, _) => [(2 * nx, 2 * ny), (2 * nx, 2 * ny + 1)],
                (-1, _) => [(2 * nx + 1, 2 * ny), (2 * nx + 1, 2 * ny + 1)],
                (_, 1) => [(2 * nx, 2 * ny), (2 * nx + 1, 2 * ny)],
                _ => [(2 * nx, 2 * ny + 1), (2 * nx + 1, 2 * ny + 1)],
            };
            along
                .iter()
                .any(|&(cx, cy)| at(p - 1, cx, cy).is_some_and(|c| split.contains(&c)))
        })
}

/// A tile to walk (its index in [`Terrain::tiles`]), and its choice when already made
/// ([`Walk::choose`]'s answer).
type Pending = (usize, Option<Choice>);

/// A tile's level and its triangles there, if it is on screen and meets tau (None: it needs
/// its children; Some(None): off screen).
type Choice = Option<Option<(u32, u64)>>;

/// One view's walk down the pyramid.
struct Walk<'a> {
    terrain: &'a Terrain,
    view: &'a View,
    planes: [glam::Vec4; 5],
    camera: DVec3,
    tau: f64,
    weigh_children: bool,
    morph: bool,
}

impl Walk<'_> {
    /// The tile's [`Choice`].
    fn choose(&self, i: usize, visited: &mut usize) -> Choice {
        *visited += 1;
        let tile = &self.terrain.tiles[i];
        let p = tile.layer;
        let (lo, hi) = lod::tile_box(tile);
        if crate::cull::box_outside(&self.planes, lo - self.camera, hi - self.camera) {
            return Some(None);
        }
        let r = lod::tolerable_error(self.view, self.camera, tile, self.tau, Bound::Guaranteed);
        let finest = tile.levels.last().map_or(0.0, |l| f64::from(l.max_error));
        if p > 0 && finest > r {
            return None;
        }
        let level = if self.morph {
            lod::morph_level(self.view, self.camera, tile, self.tau, Bound::Guaranteed)
        } else {
            lod::level_for(tile, r)
        };
        Some(Some((
            level,
            u64::from(tile.levels[level as usize].triangle_count),
        )))
    }

    /// Walks the tiles on `stack` and all they split into, keeping tiles into `out` and
    /// noting the tiles split. A tile on the stack may come with its choice already made (by
    /// its parent's look ahead), so that no tile is weighed twice.
    fn run(&self, stack: &mut Vec<Pending>, out: &mut Cut, split: &mut HashSet<usize>) {
        let terrain = self.terrain;
        while let Some((i, known)) = stack.pop() {
            let p = terrain.tiles[i].layer;
            let chosen = match known.unwrap_or_else(|| self.choose(i, &mut out.visited)) {
                None => {
                    split.insert(i);
                    stack.extend(terrain.children(i).map(|c| (c, None)));
                    continue;
                }
                Some(None) => continue,
                Some(Some(chosen)) => chosen,
            };
            // A layer tile that meets tau is still replaced by its children where they cost
            // less: a big tile takes the level its nearest point needs all over, its children
            // each their own.
            if p > 0 && self.weigh_children {
                let mut children = 0u64;
                let mut weighed = Vec::with_capacity(4);
                for c in terrain.children(i) {
                    let choice = self.choose(c, &mut out.visited);
                    weighed.push((c, Some(choice)));
                    match choice {
                        Some(Some((_, t))) => children += t + DRAW_TRIANGLES,
                        Some(None) => {}
                        None => {
                            children = u64::MAX;
                            break;
                        }
                    }
                }
                if children < chosen.1 + DRAW_TRIANGLES {
                    split.insert(i);
                    stack.extend(weighed);
                    continue;
                }
            }
            out.nodes.push(Node {
                layer: p,
                tile: i,
                level: chosen.0,
            });
        }
    }
}

/// The level tile `i` is drawn at when it stands in for tiles of its cut
/// ([`stand_in`]): the coarsest that meets tau on screen, or its finest.
pub fn level_at(terrain: &Terrain, view: &View, camera: DVec3, tau: f64, i: usize) -> u32 {
    let tile = &terrain.tiles[i];
    lod::level_for(
        tile,
        lod::tolerable_error(view, camera, tile, tau, Bound::Guaranteed),
    )
}

/// Where a cut's tiles stand in their checks: the frame asks, and the answer is its policy
/// (`vkterrain --checks`).
pub trait Checks {
    /// Whether tile `i` may be drawn: Some(true) it passed its check, Some(false) it failed
    /// (never drawn), None not checked yet.
    fn state(&self, i: usize) -> Option<bool>;
    /// Tile `i`, not checked yet, is wanted or would stand in for a wanted tile: to be
    /// checked later.
    fn later(&mut self, i: usize);
    /// Nothing over tile `i` can be drawn: check it now, whatever the policy; true if it
    /// passed.
    fn now(&mut self, i: usize) -> bool;
}

/// What a frame draws of a cut.
#[derive(Clone, Debug, Default)]
pub struct Drawn {
    /// Its tiles (indices in [`Terrain::tiles`]), in no particular order.
    pub tiles: Vec<usize>,
    /// Tiles of the cut not drawn themselves: an ancestor is drawn over their ground.
    pub stood_in: usize,
}

/// The tiles a frame draws for `cut` while some of its tiles cannot be drawn: not checked yet
/// (their checks run off the frame, `checks` decides) or failed. Each such tile's nearest
/// ancestor that passed its check is drawn in its place, the ground of every other tile under
/// that ancestor with it. Where nothing over a tile has passed, the coarsest unchecked one is
/// checked on the frame (the first frame checks the top of each chain this way, one tile for
/// many). A tile that failed, with every ancestor, leaves its ground undrawn, as in a base
/// grid.
///
/// Then the drawn tiles are balanced as [`cut_with`] balances the cut, but upwards: a tile
/// beside a drawn tile two or more layers coarser is replaced by its ancestor one layer below
/// that one (or that ancestor's own stand-in), until every two neighbours are at most a layer
/// apart, which is what the stitches across layers join ([`crate::stitch::stitch_across`]).
/// Tiles only ever rise towards the top layer, so it ends. With `balance` false (the tests'
/// controls; the fault `no-stand-in-balance`) tiles two layers apart may meet, where no stitch
/// joins them. Checked coarse layers first (as the frames ask, [`Checks::later`]), the
/// stand-ins seldom need the balance: none of the orbits and flyovers over the 1K, 4K and 16K
/// mirror sets did (12 frames each, two checks a frame or checked behind); a tile that fails
/// while its neighbours pass does.
pub fn stand_in(terrain: &Terrain, cut: &[Node], checks: &mut impl Checks, balance: bool) -> Drawn {
    let mut drawn: HashSet<usize> = HashSet::with_capacity(cut.len());
    for n in cut {
        if let Some(a) = drawable(terrain, n.tile, checks) {
            drawn.insert(a);
        }
    }
    loop {
        // A tile under another drawn tile is drawn by it.
        let over: Vec<usize> = drawn
            .iter()
            .copied()
            .filter(|&t| ancestors(terrain, t).any(|a| drawn.contains(&a)))
            .collect();
        for t in over {
            drawn.remove(&t);
        }
        if !balance {
            break;
        }
        let mut rise: Vec<(usize, u32)> = drawn
            .iter()
            .filter_map(|&t| coarse_beside(terrain, &drawn, t).map(|r| (t, r)))
            .collect();
        if rise.is_empty() {
            break;
        }

        rise.sort_unstable();
        for (t, r) in rise {
            let a = ancestors(terrain, t)
                .find(|&a| terrain.tiles[a].layer == r)
                .expect("a tile beside a coarser one has ancestors up to its layer");
            drawn.remove(&t);
            if let Some(b) = drawable(terrain, a, checks) {
                drawn.insert(b);
            }
        }
    }
    let stood_in = cut.iter().filter(|n| !drawn.contains(&n.tile)).count();
    Drawn {
        tiles: drawn.into_iter().collect(),
        stood_in,
    }
}

/// Tile `i`'s ancestors, nearest first.
fn ancestors(terrain: &Terrain, i: usize) -> impl Iterator<Item = usize> + '_ {
    std::iter::successors(terrain.parent(i), |&a| terrain.parent(a))
}

/// What can be drawn over tile `i`'s ground: the tile itself if it passed its check, else its
/// nearest ancestor that passed; else, checked on the frame, the coarsest over it that passes.
/// None: the tile and every ancestor failed. The unchecked tiles between the one drawn and `i`
/// are asked for [`Checks::later`], so that the ground refines from coarse to fine.
fn drawable(terrain: &Terrain, i: usize, checks: &mut impl Checks) -> Option<usize> {
    let chain: Vec<usize> = std::iter::once(i).chain(ancestors(terrain, i)).collect();
    for &a in &chain {
        match checks.state(a) {
            Some(true) => return Some(a),
            None => checks.later(a),
            Some(false) => {}
        }
    }
    chain
        .iter()
        .rev()
        .copied()
        .find(|&a| checks.state(a).is_none() && checks.now(a))
}

/// The layer tile `t` must rise to: one below the coarsest drawn tile beside it, where that
/// one is two or more layers above `t`'s (None: no such neighbour).
fn coarse_beside(terrain: &Terrain, drawn: &HashSet<usize>, t: usize) -> Option<u32> {
    let tile = &terrain.tiles[t];
    let q = tile.layer;
    let (tx, ty) = (i64::from(tile.tx), i64::from(tile.ty));
    [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)]
        .iter()
        .filter_map(|&(dx, dy)| {
            let (nx, ny) = (tx + dx, ty + dy);
            if nx < 0 || ny < 0 {
                return None;
            }
            // The drawn tile over the neighbouring cell, if any is at or above layer q.
            (q..terrain.layers.len() as u32).find_map(|r| {
                let k = r - q;
                let j = terrain.tile_in(r, (nx >> k) as u32, (ny >> k) as u32)?;
                drawn.contains(&j).then_some(r)
            })
        })
        .filter(|&r| r >= q + 2)
        .max()
        .map(|r| r - 1)
}
