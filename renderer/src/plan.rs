//! The frame plan (DESIGN.md, "The frame", steps 2-5), in plain Rust: cull tiles against the
//! frustum and sort them front to back, choose the level each one wants, let the memory
//! manager grant levels and schedule uploads within the budget, and stitch neighbours at the
//! levels *granted* (a tile whose wanted level is not resident yet is drawn, and stitched, at
//! the level it has). The recorder in [`crate::frame`] turns the plan into commands.

use std::collections::HashMap;
use std::time::Instant;

use glam::DVec3;
use memory::textures::{TextureRequest, TextureSlots, TextureStats, TextureUpload};
use memory::{Manager, Request, Stats};

use crate::camera::{Camera, View};
use crate::stitch::{stitch_side, Side, Stitch};
use crate::terrain::Terrain;
use crate::{cull, lod};

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
    /// coarsest level that covers its on-screen vertices' levels ([`lod::morph_level`]).
    Morph(f64, lod::Bound),
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
    pub cpu_stitch_ms: f64,
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
}

/// Plans one frame of `camera` at `extent` pixels.
pub fn plan(
    terrain: &Terrain,
    manager: &mut Manager,
    camera: &Camera,
    extent: (u32, u32),
    rule: LevelRule,
    residency: Residency,
) -> Result<Plan, BorderMismatch> {
    let Residency {
        frame,
        completed,
        allow_uploads,
        prefetch,
    } = residency;
    let view = camera.view(extent.0, extent.1);

    let t = Instant::now();
    let visible = visible_tiles(terrain, &view, camera.position);
    let cpu_cull_ms = ms(t);

    let t = Instant::now();
    let morphing = matches!(rule, LevelRule::Morph(..));
    let requests = wanted_levels(terrain, &view, camera.position, &visible, rule);
    let cpu_lod_ms = ms(t);

    let t = Instant::now();
    let mut residency = manager.plan_frame(frame, completed, &requests, allow_uploads);
    if allow_uploads {
        manager.prefetch(&mut residency, prefetch);
    }
    let draws: Vec<Draw> = residency
        .grants
        .iter()
        .filter_map(|g| {
            let level = g.level?;
            Some(Draw {
                tile: g.tile as usize,
                wanted: g.wanted,
                level,
                vertex_offset: g.vertex_offset,
                morph_offset: g.morph_offset,
                index_offset: g.index_offset,
                index_width: g.index_width,
                index_count: terrain.tiles[g.tile as usize].levels[level as usize].index_count,
            })
        })
        .collect();
    let cpu_residency_ms = ms(t);

    let t = Instant::now();
    // Two morphed copies of a shared side vertex coincide only where the sides are shared.
    let stitches = stitch_granted(terrain, &draws, morphing && !terrain.shared_sides)?;
    let cpu_stitch_ms = ms(t);

    Ok(Plan {
        view,
        draws,
        stitches,
        uploads: residency.uploads,
        moves: residency.moves,
        requests,
        stats: residency.stats,
        tiles_visible: visible.len() as u64,
        cpu_cull_ms,
        cpu_lod_ms,
        cpu_residency_ms,
        cpu_stitch_ms,
    })
}

/// Tiles whose box touches the frustum, nearest first (by the box point closest to the camera).
pub fn visible_tiles(terrain: &Terrain, view: &View, camera: DVec3) -> Vec<usize> {
    let planes = view.frustum();
    let mut visible: Vec<(f64, usize)> = terrain
        .tiles
        .iter()
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
    let finest = terrain.levels - 1;
    visible
        .iter()
        .map(|&i| {
            let tile = &terrain.tiles[i];
            let wanted = match rule {
                LevelRule::Finest => finest,
                LevelRule::Forced(l) => l.min(finest),
                LevelRule::Tau(tau, bound) => lod::level(view, camera, tile, tau, bound),
                LevelRule::Morph(tau, bound) => lod::morph_level(view, camera, tile, tau, bound),
            };
            Request {
                tile: i as u32,
                wanted: wanted.min(finest),
            }
        })
        .collect()
}

/// Stitches between drawn neighbours at their granted levels, each pair once (from the tile
/// west or north of the seam); `slivers` as in [`stitch_side`]. A draw's record is its index.
pub fn stitch_granted(
    terrain: &Terrain,
    draws: &[Draw],
    slivers: bool,
) -> Result<Vec<(usize, Stitch)>, BorderMismatch> {
    let level_of: HashMap<usize, (u32, u32)> = draws
        .iter()
        .enumerate()
        .map(|(k, d)| (d.tile, (d.level, k as u32)))
        .collect();
    let mut stitches = Vec::new();
    for (k, d) in draws.iter().enumerate() {
        let a = &terrain.tiles[d.tile];
        let mut s = Stitch::default();
        for (side, (dx, dy)) in [(1usize, (1u32, 0u32)), (2, (0, 1))] {
            let Some(j) = terrain.tile_index(a.tx + dx, a.ty + dy) else {
                continue;
            };
            let Some(&(level_b, record_b)) = level_of.get(&j) else {
                continue;
            };
            let b = &terrain.tiles[j];
            let mine = Side {
                tile: a,
                level: d.level,
                record: k as u32,
            };
            let theirs = Side {
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
        if s.triangles > 0 {
            stitches.push((k, s));
        }
    }
    Ok(stitches)
}

/// A drawn tile's texture: the array layer (its slot) and the finest mip resident there,
/// where the shader clamps its level of detail.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TextureDraw {
    pub layer: u32,
    pub finest: u32,
}

/// The texture side of a frame.
#[derive(Clone, Debug, Default)]
pub struct TexturePlan {
    /// Per draw, in the plan's order (None: drawn without its texture, shaded by height).
    pub draws: Vec<Option<TextureDraw>>,
    pub uploads: Vec<TextureUpload>,
    pub stats: TextureStats,
}

/// The finest texture mip tile `tile` can show from `camera`: [`mip_for_distance`] at the
/// tile box's nearest point, for mip-0 texels `256 * spacing / T` metres across.
pub fn texture_mip_wanted(
    terrain: &Terrain,
    layout: &tiles::texture::Layout,
    view: &View,
    camera: DVec3,
    tile: usize,
) -> u32 {
    let t = &terrain.tiles[tile];
    let r = camera.clamp(t.min, t.max).distance(camera);
    let (sx, sy) = terrain.spacing;
    let texel = f64::from(tiles::mesh::TILE_CELLS) * sx.min(sy) / f64::from(layout.interior);
    mip_for_distance(r, texel, view, layout.mips)
}

/// The mip to sample for surface `distance` metres or more from the camera, with mip-0 texels
/// `texel` metres across and `mips` mips: the coarsest whose texels still project to at most
/// a pixel anywhere in the view (a point at distance `r` is at least `r * cos(half
/// diagonal)` deep, where a metre covers at most `focal / depth` pixels). Finer mips would
/// only be minified; the next coarser one would be magnified somewhere.
pub fn mip_for_distance(distance: f64, texel: f64, view: &View, mips: u32) -> u32 {
    let focal = view.focal.0.max(view.focal.1);
    let (hx, hy) = (
        f64::from(view.width) * 0.5 / view.focal.0,
        f64::from(view.height) * 0.5 / view.focal.1,
    );
    let depth = distance / (1.0 + hx * hx + hy * hy).sqrt();
    let ratio = depth / (texel * focal);
    if ratio <= 1.0 || !ratio.is_finite() {
        return 0;
    }
    (ratio.log2().floor() as u32).min(mips.saturating_sub(1))
}

/// Textures for the plan's draws: each drawn tile asks for the finest mip its footprint
/// needs, nearest first, and `slots` grants layers and schedules mips within `budget` bytes.
/// With no budget (pre-recorded frames) nothing is placed or uploaded: tiles sample what is
/// resident.
pub fn plan_textures(
    terrain: &Terrain,
    slots: &mut TextureSlots,
    plan: &Plan,
    camera: DVec3,
    residency: (u64, Option<u64>),
    budget: Option<u64>,
) -> TexturePlan {
    let Some(layout) = terrain.texture else {
        return TexturePlan {
            draws: vec![None; plan.draws.len()],
            ..TexturePlan::default()
        };
    };
    let Some(budget) = budget else {
        let draws = plan
            .draws
            .iter()
            .map(|d| {
                slots
                    .resident(d.tile as u32)
                    .map(|(layer, finest)| TextureDraw { layer, finest })
            })
            .collect();
        return TexturePlan {
            draws,
            ..TexturePlan::default()
        };
    };
    let requests: Vec<TextureRequest> = plan
        .draws
        .iter()
        .map(|d| TextureRequest {
            tile: d.tile as u32,
            finest: texture_mip_wanted(terrain, &layout, &plan.view, camera, d.tile),
        })
        .collect();
    let (frame, completed) = residency;
    let (grants, uploads, stats) = slots.plan(frame, completed, &requests, budget);
    let draws = grants
        .iter()
        .map(|g| {
            g.slot.map(|layer| TextureDraw {
                layer,
                finest: g.finest,
            })
        })
        .collect();
    TexturePlan {
        draws,
        uploads,
        stats,
    }
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1000.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;

    #[test]
    fn the_texture_mip_follows_the_pixel_footprint() {
        let camera = Camera {
            position: DVec3::ZERO,
            yaw: 0.3,
            pitch: -0.2,
            fov_y: 60f64.to_radians(),
        };
        let view = camera.view(1024, 768);
        let (texel, mips) = (40.0, 10);
        // The direction of the image's corner: there a point at distance r is shallowest, so
        // its texels look largest.
        let (hx, hy) = (512.0 / view.focal.0, 384.0 / view.focal.1);
        let corner = (-view.back + hx * view.right + hy * view.up).normalize();
        let corner_pixel = view.project(corner * 100.0).expect("in front");
        assert!((corner_pixel.0 - 1024.0).abs() < 1e-6 && corner_pixel.1.abs() < 1e-6);
        // Pixels spanned on screen by a segment of `size` metres at `p`, across the view.
        let pixels = |p: DVec3, size: f64| {
            let a = view.project(p).expect("in front");
            let b = view.project(p + view.right * size).expect("in front");
            (b.0 - a.0).hypot(b.1 - a.1)
        };
        let mut last = 0;
        for k in 0..400 {
            let r = 10.0 * 1.05f64.powi(k);
            let m = mip_for_distance(r, texel, &view, mips);
            assert!(m >= last, "farther asks for a finer mip at {r} m");
            last = m;
            let size = |m: u32| texel * f64::from(1u32 << m);
            let here = pixels(corner * r, size(m));
            assert!(m == 0 || here <= 1.0 + 1e-9, "mip {m} at {r} m: {here} px");
            if m + 1 < mips {
                let coarser = pixels(corner * r, size(m + 1));
                assert!(coarser > 1.0, "mip {} at {r} m: {coarser} px", m + 1);
            }
        }
        assert_eq!(last, mips - 1, "far away reaches the coarsest mip");
        // Inside the tile's box, or nonsense distances: the finest mip.
        assert_eq!(mip_for_distance(0.0, texel, &view, mips), 0);
        assert_eq!(mip_for_distance(f64::NAN, texel, &view, mips), 0);
        assert_eq!(mip_for_distance(f64::INFINITY, texel, &view, mips), 0);
    }
}
