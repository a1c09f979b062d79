//! The frame plan (README, "How a frame is made", steps 2-5), in plain Rust: cull tiles against the
//! frustum and sort them front to back, choose the level each one wants, let the memory manager
//! grant levels and schedule uploads within the budget, and stitch neighbours at the levels
//! *granted* (a tile whose wanted level is not resident yet is drawn, and stitched, at the level it
//! has). The recorder in [`crate::frame`] turns the plan into commands.

use std::collections::HashMap;
use std::time::Instant;

use glam::DVec3;
use memory::{Manager, Request, Stats};

use crate::camera::{Camera, View};
use crate::log::ms;
use crate::stitch::{stitch_across, stitch_side, DrawnSide, Stitch};
use crate::terrain::Terrain;
use crate::tile::Side;
use crate::{cull, lod};

mod stand_in;

use stand_in::drawn_cut;
pub use stand_in::CheckPolicy;

/// How levels are chosen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LevelRule {
    /// The coarsest level whose measured error projects to at most `tau` pixels, by `Bound`.
    Tau(f64, lod::Bound),
    /// Every visible tile at this level (clamped to the finest).
    Forced(u32),
    /// Every visible tile at its finest level (the baseline).
    Finest,
    /// Geomorphing (paper, section 5): each vertex blends the levels at a continuous level of
    /// its own, from its position and the camera ([`crate::morph`]); each tile is drawn at the
    /// coarsest level that covers its on-screen vertices' levels ([`lod::morph_level`]). With
    /// `true`, part by part: each of a tile's 4 x 4 parts gets its own level
    /// ([`lod::morph_parts`]) and the tile wants the largest ([`crate::parts`] draws them).
    Morph(f64, lod::Bound, bool),
}

/// One tile to draw, where its data sits in the pool.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Draw {
    pub tile: usize,
    pub wanted: u32,
    pub level: u32,
    /// Pool byte offsets of block 0's positions, of block 0's morph rows and of the level's
    /// index array.
    pub vertex_offset: u64,
    pub morph_offset: u64,
    pub index_offset: u64,
    /// 2 or 4 bytes.
    pub index_width: u32,
    pub index_count: u32,
    pub triangle_count: u32,
    /// Part by part: the level each part wants ([`lod::morph_parts`]), and once
    /// [`crate::parts::PartDraws::assign`] has found one, the key the tile is drawn at (None:
    /// at `level` throughout).
    pub parts: Option<tiles::parts::PartLevels>,
    pub key: Option<tiles::parts::PartKey>,
}

/// Everything one frame does, decided before any command is recorded.
pub struct Plan {
    pub view: View,
    /// Front to back.
    pub draws: Vec<Draw>,
    /// Stitch geometry, each in the frame of the draw it indexes.
    pub stitches: Vec<(usize, Stitch)>,
    pub uploads: Vec<memory::Upload>,
    pub moves: Vec<memory::Move>,
    /// Visible tiles front to back with the level each wanted (a trace's rows).
    pub requests: Vec<Request>,
    pub stats: Stats,
    pub tiles_visible: u64,
    pub cpu_cull_ms: f64,
    pub cpu_lod_ms: f64,
    pub cpu_residency_ms: f64,
    /// The manager's prefetch step (not in `cpu_residency_ms`).
    pub cpu_prefetch_ms: f64,
    pub cpu_stitch_ms: f64,
    /// Checking tiles that came into view unchecked (the prefetcher's tiles are checked ahead,
    /// off the frame), and how many.
    pub cpu_check_ms: f64,
    pub tiles_checked: u64,
    /// Tiles that have failed their checks so far (never drawn).
    pub tiles_failed: u64,
    /// Tiles of the pyramid's cut drawn by an ancestor: not checked yet, failed, or beside a
    /// tile two layers coarser ([`crate::cut::stand_in`]); or held at a coarser level of their
    /// own than they want until the finer one passes its check (`--checks behind`).
    pub tiles_stood_in: u64,
}

/// A tile set whose neighbouring tiles do not share their border.
#[derive(Debug, thiserror::Error)]
#[error("tiles {a:?} and {b:?} do not share their border (corrupted tile set?)")]
pub struct BorderMismatch {
    pub a: (u32, u32),
    pub b: (u32, u32),
}

/// The memory manager's side of one frame.
#[derive(Clone, Copy, Debug)]
pub struct Residency<'a> {
    /// The frame's number (the manager's clock).
    pub frame: u64,
    /// The newest frame the GPU has finished.
    pub completed: Option<u64>,
    /// False: draw what is resident only (pre-recorded frames).
    pub allow_uploads: bool,
    /// Tiles predicted to become visible, soonest first, to upload with what the frame leaves
    /// of its budget (empty: no prefetching).
    pub prefetch: &'a [Request],
    /// The end of the frame's CPU time for prefetching (`--prefetch-ms`, counted from the
    /// prediction's start): the manager takes no candidate after it. None: no deadline.
    pub prefetch_until: Option<Instant>,
}

/// Plans one frame of `camera` at `extent` pixels.
pub fn plan(
    terrain: &Terrain,
    manager: &mut Manager,
    camera: &Camera,
    extent: (u32, u32),
    (rule, checks): (LevelRule, CheckPolicy),
    residency: Residency,
) -> Result<Plan, BorderMismatch> {
    let Residency {
        frame,
        completed,
        allow_uploads,
        prefetch,
        prefetch_until,
    } = residency;
    let view = camera.view(extent.0, extent.1);

    let t = Instant::now();
    let cut = cut_tiles(terrain, &view, camera.position, rule);
    let mut visible = match &cut {
        Some(_) => Vec::new(),
        None => visible_tiles(terrain, &view, camera.position),
    };
    let cpu_cull_ms = ms(t);
    let tiles_visible = cut.as_ref().map_or(visible.len(), |(_, c)| c.len()) as u64;

    // A tile's levels are checked before their first upload; a tile that fails is never
    // drawn. Over a pyramid, ancestors stand in for the cut's tiles not checked yet.
    let t = Instant::now();
    let mut stood_in = 0;
    let mut stand_in_checks = 0;
    let cut = cut.map(|(tau, wanted)| {
        let (drawn, s, c) = drawn_cut(terrain, &view, camera.position, tau, &wanted, checks);
        (stood_in, stand_in_checks) = (s, c);
        visible = drawn.iter().map(|&(i, _)| i).collect();
        drawn
    });
    let mut cpu_check_ms = ms(t);

    let t = Instant::now();
    let morphing = matches!(rule, LevelRule::Morph(..));
    // A cut's tiles take the cut's levels, or morphing, the morph rule's (as any tile's).
    let (mut requests, mut parts) = match &cut {
        Some(cut) if !morphing => (cut_requests(cut, &visible), Vec::new()),
        _ => wanted(terrain, &view, camera.position, &visible, rule),
    };
    let cpu_lod_ms = ms(t);

    let t = Instant::now();
    // A base grid's tiles are checked on the frame; a whole tile is uploaded at once.
    let policy = cut.as_ref().map_or(CheckPolicy::OnFrame, |_| checks);
    let whole = manager.config().scheme == memory::Scheme::WholeTile;
    let requested = (&mut requests, &mut parts);
    let (prefetch, checked, held) = check_requests(terrain, requested, prefetch, (policy, whole));
    let tiles_checked = checked + stand_in_checks;
    cpu_check_ms += ms(t);
    let parts: HashMap<u32, tiles::parts::PartLevels> =
        requests.iter().map(|r| r.tile).zip(parts).collect();

    let t = Instant::now();
    let mut residency = manager.plan_frame(frame, completed, &requests, allow_uploads);
    let t_prefetch = Instant::now();
    if allow_uploads {
        let in_time = || prefetch_until.is_none_or(|end| Instant::now() < end);
        manager.prefetch_while(&mut residency, &prefetch, in_time);
    }
    let cpu_prefetch_ms = ms(t_prefetch);
    let draws: Vec<Draw> = residency
        .grants
        .iter()
        .filter_map(|g| draw_of(terrain, g, parts.get(&g.tile).copied()))
        .collect();
    // The prefetch step is counted with the prediction (`--prefetch-ms` bounds the two).
    let cpu_residency_ms = ms(t) - cpu_prefetch_ms;

    let t = Instant::now();
    let stitches = stitch_granted(terrain, &draws, morphing)?;
    let cpu_stitch_ms = ms(t);

    Ok(Plan {
        view,
        draws,
        stitches,
        uploads: residency.uploads,
        moves: residency.moves,
        requests,
        stats: residency.stats,
        tiles_visible,
        cpu_cull_ms,
        cpu_lod_ms,
        cpu_residency_ms,
        cpu_prefetch_ms,
        cpu_stitch_ms,
        cpu_check_ms,
        tiles_checked,
        tiles_failed: terrain.failed_count() as u64,
        tiles_stood_in: (stood_in + held) as u64,
    })
}

/// Checks each request's tile through the level it wants (every level with `every_level`:
/// the manager then uploads whole tiles) before its first upload there, and keeps the
/// requests that may be drawn, with their part levels (`parts`: one per request, or none).
/// Under [`CheckPolicy::Behind`] a tile whose first levels passed but not yet the wanted one
/// is drawn at its finest checked level meanwhile, and the rest is checked off the frame.
/// Of the `prefetch` requests, keeps those checked through their levels and queues the
/// others for a check off the frame. Returns the prefetch requests kept, how many tiles were
/// checked on the frame and how many are held at a coarser level than they want.
fn check_requests(
    terrain: &Terrain,
    (requests, parts): (&mut Vec<Request>, &mut Vec<tiles::parts::PartLevels>),
    prefetch: &[Request],
    (policy, every_level): (CheckPolicy, bool),
) -> (Vec<Request>, u64, usize) {
    let through = |r: &Request| if every_level { u32::MAX } else { r.wanted };
    let due: Vec<(usize, u32)> = requests
        .iter()
        .filter(|r| {
            terrain.tiles[r.tile as usize]
                .usable_at(through(r))
                .is_none()
        })
        .map(|r| (r.tile as usize, through(r)))
        .collect();
    let checked = match policy {
        CheckPolicy::Behind => {
            terrain.check_first(&due);
            0
        }
        CheckPolicy::OnFrame | CheckPolicy::PerFrame(_) => {
            terrain.check_all_through(&due);
            due.len() as u64
        }
    };
    let has_parts = parts.len() == requests.len();
    let mut kept = Vec::with_capacity(requests.len());
    let mut kept_parts = Vec::with_capacity(parts.len());
    let mut held = 0;
    for (k, mut r) in requests.iter().copied().enumerate() {
        let tile = &terrain.tiles[r.tile as usize];
        let drawn_at = match tile.usable_at(through(&r)) {
            Some(true) => r.wanted,
            Some(false) => continue,
            // Its own check passed at a coarser level (checked behind): that level for now.
            None => match (tile.usable(), tile.checked_levels().checked_sub(1)) {
                (Some(true), Some(checked)) if !every_level => {
                    held += 1;
                    checked
                }
                _ => continue,
            },
        };
        r.wanted = r.wanted.min(drawn_at);
        kept.push(r);
        if has_parts {
            kept_parts.push(parts[k].map(|l| l.min(r.wanted as u8)));
        }
    }
    *requests = kept;
    *parts = kept_parts;
    let prefetch = prefetch
        .iter()
        .copied()
        .filter(
            |r| match terrain.tiles[r.tile as usize].usable_at(through(r)) {
                Some(usable) => usable,
                None => {
                    terrain.check_soon(r.tile as usize, through(r));
                    false
                }
            },
        )
        .collect();
    (prefetch, checked, held)
}

/// The draw of a granted tile (None: nothing of it resident).
fn draw_of(
    terrain: &Terrain,
    g: &memory::Grant,
    parts: Option<tiles::parts::PartLevels>,
) -> Option<Draw> {
    let level = g.level?;
    let stored = &terrain.tiles[g.tile as usize].levels[level as usize];
    Some(Draw {
        tile: g.tile as usize,
        wanted: g.wanted,
        level,
        vertex_offset: g.vertex_offset,
        morph_offset: g.morph_offset,
        index_offset: g.index_offset,
        index_width: g.index_width,
        index_count: stored.index_count,
        triangle_count: stored.triangle_count,
        parts,
        key: None,
    })
}

/// Checks the tiles `camera` sees at `extent` pixels under `rule`, on every core
/// ([`Terrain::check`]): the part of opening a tile set that its first view needs, before the
/// first frame. Over a pyramid, the tiles of the cut.
pub fn check_view(
    terrain: &Terrain,
    camera: &Camera,
    extent: (u32, u32),
    (rule, checks): (LevelRule, CheckPolicy),
) {
    let view = camera.view(extent.0, extent.1);
    if checks != CheckPolicy::OnFrame {
        // What the first frame will check, and behind, the rest queued.
        if let Some((tau, wanted)) = cut_tiles(terrain, &view, camera.position, rule) {
            drawn_cut(terrain, &view, camera.position, tau, &wanted, checks);
            return;
        }
    }
    terrain.check_all_through(
        &requests_for(terrain, &view, camera.position, rule)
            .iter()
            .map(|r| (r.tile as usize, r.wanted))
            .collect::<Vec<_>>(),
    );
}

/// Whether frames over `terrain` under `rule` draw a cut through its pyramid: the terrain
/// holds layers above its base grid ([`Terrain::open_pyramid`]) and levels follow tau, with
/// or without geomorphing.
pub fn draws_cut(terrain: &Terrain, rule: LevelRule) -> bool {
    terrain.top() > 0 && matches!(rule, LevelRule::Tau(..) | LevelRule::Morph(..))
}

/// Where frames draw a cut ([`draws_cut`]): its tau, and its tiles nearest first, each with the
/// level it is drawn at ([`crate::cut`]: culled and levelled in one walk).
fn cut_tiles(
    terrain: &Terrain,
    view: &View,
    camera: DVec3,
    rule: LevelRule,
) -> Option<(f64, Vec<(usize, u32)>)> {
    let (LevelRule::Tau(tau, _) | LevelRule::Morph(tau, _, _)) = rule else {
        return None;
    };
    if !draws_cut(terrain, rule) {
        return None;
    }
    let rules = crate::cut::Rules {
        morph: matches!(rule, LevelRule::Morph(..)),
        ..crate::cut::Rules::ALL
    };
    let cut = crate::cut::cut_with(terrain, view, camera, tau, rules);
    let nodes = cut.nodes.iter().map(|n| (n.tile, n.level)).collect();
    Some((tau, nearest_first(terrain, camera, nodes)))
}

/// Tiles with their levels, sorted by the distance from `camera` to each tile's box, then by
/// index.
fn nearest_first(terrain: &Terrain, camera: DVec3, tiles: Vec<(usize, u32)>) -> Vec<(usize, u32)> {
    let mut keyed: Vec<(f64, usize, u32)> = tiles
        .into_iter()
        .map(|(i, l)| {
            let t = &terrain.tiles[i];
            (camera.clamp(t.min, t.max).distance_squared(camera), i, l)
        })
        .collect();
    keyed.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    keyed.into_iter().map(|(_, i, l)| (i, l)).collect()
}

/// The requests of a cut's tiles that are in `visible` (those that passed their checks).
fn cut_requests(cut: &[(usize, u32)], visible: &[usize]) -> Vec<Request> {
    let level: HashMap<usize, u32> = cut.iter().copied().collect();
    visible
        .iter()
        .map(|&i| Request {
            tile: i as u32,
            wanted: level[&i],
        })
        .collect()
}

/// The tiles a view draws nearest first, with the level each wants under `rule`: the visible
/// base tiles ([`visible_tiles`], [`wanted_levels`]), or the cut through a pyramid
/// ([`draws_cut`]). The prefetcher asks it for predicted cameras, so a prediction wants what
/// the frame will.
pub fn requests_for(
    terrain: &Terrain,
    view: &View,
    camera: DVec3,
    rule: LevelRule,
) -> Vec<Request> {
    match cut_tiles(terrain, view, camera, rule) {
        Some((_, cut)) => {
            let tiles: Vec<usize> = cut.iter().map(|&(i, _)| i).collect();
            if matches!(rule, LevelRule::Morph(..)) {
                return wanted_levels(terrain, view, camera, &tiles, rule);
            }
            cut_requests(&cut, &tiles)
        }
        None => {
            let visible = visible_tiles(terrain, view, camera);
            wanted_levels(terrain, view, camera, &visible, rule)
        }
    }
}

/// Base tiles whose box touches the frustum, nearest first (by the box point closest to the
/// camera).
pub fn visible_tiles(terrain: &Terrain, view: &View, camera: DVec3) -> Vec<usize> {
    let planes = view.frustum();
    let mut visible: Vec<(f64, usize)> = terrain
        .base()
        .enumerate()
        .filter(|(_, tile)| cull::visible(&planes, camera, tile))
        .map(|(i, tile)| {
            let d = camera.clamp(tile.min, tile.max).distance_squared(camera);
            (d, i)
        })
        .collect();
    visible.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    visible.into_iter().map(|(_, i)| i).collect()
}

/// The level each of `visible` (front to back) wants from `camera`, as requests in the same
/// order. Used for the frame and for predicted cameras alike, so a prediction wants what the
/// frame will.
pub fn wanted_levels(
    terrain: &Terrain,
    view: &View,
    camera: DVec3,
    visible: &[usize],
    rule: LevelRule,
) -> Vec<Request> {
    wanted(terrain, view, camera, visible, rule).0
}

/// [`wanted_levels`], and part by part, each tile's part levels (empty otherwise).
fn wanted(
    terrain: &Terrain,
    view: &View,
    camera: DVec3,
    visible: &[usize],
    rule: LevelRule,
) -> (Vec<Request>, Vec<tiles::parts::PartLevels>) {
    let finest = terrain.levels - 1;
    let mut parts = Vec::new();
    let requests = visible
        .iter()
        .map(|&i| {
            let tile = &terrain.tiles[i];
            let wanted = match rule {
                LevelRule::Finest => finest,
                LevelRule::Forced(l) => l.min(finest),
                LevelRule::Tau(tau, bound) => lod::level(view, camera, tile, tau, bound),
                LevelRule::Morph(tau, bound, false) => {
                    lod::morph_level(view, camera, tile, tau, bound)
                }
                LevelRule::Morph(tau, bound, true) => {
                    let levels = lod::morph_parts(view, camera, tile, tau, bound);
                    parts.push(levels);
                    u32::from(levels.iter().copied().max().unwrap_or(0))
                }
            };
            Request {
                tile: i as u32,
                wanted: wanted.min(finest),
            }
        })
        .collect();
    (requests, parts)
}

/// Stitches between drawn neighbours at their granted levels, each pair once (from the tile
/// west or north of the seam), for frames that geomorph or not. A draw's record is its index.
pub fn stitch_granted(
    terrain: &Terrain,
    draws: &[Draw],
    morphing: bool,
) -> Result<Vec<(usize, Stitch)>, BorderMismatch> {
    // Two morphed copies of a shared side vertex coincide only where the sides are shared
    // (`slivers` as in [`stitch_side`]); across layers, never.
    let slivers = morphing && !terrain.shared_sides;
    let level_of: HashMap<usize, (u32, u32)> = draws
        .iter()
        .enumerate()
        .map(|(k, d)| (d.tile, (d.level, k as u32)))
        .collect();
    let mut stitches = Vec::new();
    let across = crate::fault::Fault::of_process() != Some(crate::fault::Fault::NoStitchAcross);
    for (k, d) in draws.iter().enumerate() {
        let a = &terrain.tiles[d.tile];
        let mut s = Stitch::default();
        for side in Side::FORWARD {
            let Some(j) = terrain.neighbour(a, side) else {
                continue;
            };
            let Some(&(level_b, record_b)) = level_of.get(&j) else {
                continue;
            };
            let b = &terrain.tiles[j];
            let mine = DrawnSide {
                tile: a,
                level: d.level,
                record: k as u32,
            };
            let theirs = DrawnSide {
                tile: b,
                level: level_b,
                record: record_b,
            };
            if !stitch_side(&mut s, mine, theirs, side, slivers) {
                return Err(BorderMismatch {
                    a: (a.tx, a.ty),
                    b: (b.tx, b.ty),
                });
            }
        }
        // Across layers, from the coarser tile: where its neighbour in its own layer is not
        // drawn, the neighbour's children along the side may be.
        for side in Side::ALL.into_iter().filter(|_| a.layer > 0 && across) {
            let Some(j) = terrain.neighbour(a, side) else {
                continue;
            };
            if level_of.contains_key(&j) {
                continue;
            }
            let children = along_side(terrain, j, side.opposite()).map(|c| {
                let &(level, record) = level_of.get(&c?)?;
                Some(DrawnSide {
                    tile: &terrain.tiles[c?],
                    level,
                    record,
                })
            });
            let Some(first) = children.iter().flatten().next() else {
                continue;
            };
            let steps = (
                terrain.height_step_of(a),
                terrain.height_step_of(first.tile),
            );
            let mine = DrawnSide {
                tile: a,
                level: d.level,
                record: k as u32,
            };
            if !stitch_across(&mut s, mine, children, side, (steps, morphing)) {
                return Err(BorderMismatch {
                    a: (a.tx, a.ty),
                    b: (first.tile.tx, first.tile.ty),
                });
            }
        }
        if s.triangles > 0 {
            stitches.push((k, s));
        }
    }
    Ok(stitches)
}

/// The two children of tile `j` (of a layer above the base) along its side `side`, north or
/// west first (None where the layer below has none there).
fn along_side(terrain: &Terrain, j: usize, side: Side) -> [Option<usize>; 2] {
    let t = &terrain.tiles[j];
    let (x, y) = (2 * t.tx, 2 * t.ty);
    let cells = match side {
        Side::North => [(x, y), (x + 1, y)],
        Side::South => [(x, y + 1), (x + 1, y + 1)],
        Side::West => [(x, y), (x, y + 1)],
        Side::East => [(x + 1, y), (x + 1, y + 1)],
    };
    cells.map(|(cx, cy)| terrain.tile_in(t.layer - 1, cx, cy))
}
