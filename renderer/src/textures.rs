//! Texture streaming, the renderer's side (paper, section 6, textures as tiles): which mip each
//! drawn tile needs for its footprint on screen, asked of the memory manager's texture slots
//! ([`memory::textures`], which grants layers and schedules mips within the frame's bytes).
//! The copies are written in `frame/uploads.rs`, the texture array lives in `vulkan/texture.rs`,
//! and the shader clamps its level of detail to the finest mip resident.

use glam::DVec3;
use memory::textures::{TextureRequest, TextureSlots, TextureStats, TextureUpload};

use crate::camera::View;
use crate::plan::Plan;
use crate::terrain::Terrain;

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

/// A BC1 mip `texels` across (its blocks as the tile set stores them) decoded to R5G6B5, two
/// bytes a texel, row by row: the texture slots' format where sampling BC1 would decode blocks
/// on every fetch (`settings::TextureFormat::Rgb565`). A block's two end colours are R5G6B5
/// already; the two between them (or the midpoint and black, where the first end is not the
/// larger) are made from the ends widened to 8 bits, as BC1 defines them, and rounded to the
/// nearest 5- or 6-bit step: within half a step of BC1's own decode. Each block's four colours
/// are made once and its sixteen texels look them up.
pub fn rgb565_of_bc1(blocks: &[u8], texels: u32) -> Vec<u8> {
    let n = texels as usize;
    let across = n.div_ceil(4);
    let mut out = vec![0u8; n * n * 2];
    for (b, block) in blocks.chunks_exact(8).enumerate().take(across * across) {
        let (bx, by) = (b % across * 4, b / across * 4);
        let c0 = u16::from_le_bytes([block[0], block[1]]);
        let c1 = u16::from_le_bytes([block[2], block[3]]);
        let palette = bc1_palette(c0, c1);
        let bits = u32::from_le_bytes([block[4], block[5], block[6], block[7]]);
        for i in 0..16 {
            let (x, y) = (bx + i % 4, by + i / 4);
            if x < n && y < n {
                let colour = palette[(bits >> (2 * i) & 3) as usize];
                out[2 * (y * n + x)..2 * (y * n + x) + 2].copy_from_slice(&colour.to_le_bytes());
            }
        }
    }
    out
}

/// A BC1 block's four colours as R5G6B5, from its two end colours.
fn bc1_palette(c0: u16, c1: u16) -> [u16; 4] {
    let widen = |c: u16| {
        let (r, g, b) = (
            u32::from(c >> 11),
            u32::from(c >> 5 & 63),
            u32::from(c & 31),
        );
        [r << 3 | r >> 2, g << 2 | g >> 4, b << 3 | b >> 2]
    };
    let pack = |rgb: [u32; 3]| {
        let to = |v: u32, max: u32| (v * max + 127) / 255;
        (to(rgb[0], 31) << 11 | to(rgb[1], 63) << 5 | to(rgb[2], 31)) as u16
    };
    let (a, b) = (widen(c0), widen(c1));
    let mix = |wa: u32, wb: u32| pack([0, 1, 2].map(|k| (wa * a[k] + wb * b[k]) / (wa + wb)));
    if c0 > c1 {
        [c0, c1, mix(2, 1), mix(1, 2)]
    } else {
        [c0, c1, mix(1, 1), 0]
    }
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

    /// Every texel of a BC1 mip of an odd size (partial blocks at its edges), decoded straight
    /// to R5G6B5, is within one 5- or 6-bit step of the reference decoder's colour (texpresso,
    /// which `tiletool` uses), in both of BC1's modes.
    #[test]
    fn bc1_decodes_straight_to_rgb565_as_the_reference_decoder_does() {
        let texels = 17u32;
        let blocks_across = texels.div_ceil(4) as usize;
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let blocks: Vec<u8> = (0..blocks_across * blocks_across)
            .flat_map(|_| next().to_le_bytes())
            .collect();
        let modes = blocks.chunks_exact(8).map(|b| b[0..2] > b[2..4]);
        let both = modes.clone().any(|m| m) && modes.clone().any(|m| !m);
        assert!(both, "the blocks hold one mode only");
        let ours = rgb565_of_bc1(&blocks, texels);
        let n = texels as usize;
        let reference = tiles::texture::decode_bc1(&blocks, n, n);
        for (i, (mine, theirs)) in ours
            .chunks_exact(2)
            .zip(reference.chunks_exact(4))
            .enumerate()
        {
            let c = u16::from_le_bytes([mine[0], mine[1]]);
            let got = [
                u32::from(c >> 11) * 255 / 31,
                u32::from(c >> 5 & 63) * 255 / 63,
                u32::from(c & 31) * 255 / 31,
            ];
            for k in 0..3 {
                let step = if k == 1 { 255 / 63 + 1 } else { 255 / 31 + 1 };
                let d = got[k].abs_diff(u32::from(theirs[k]));
                assert!(
                    d <= step,
                    "texel {i} channel {k}: {} against {}",
                    got[k],
                    theirs[k]
                );
            }
        }
    }
}
