//! Frustum culling of tile bounding boxes, relative to the camera.

use glam::{DVec3, Vec4};

use crate::tile::TileInfo;

/// Whether the tile's box touches the frustum (planes from [`crate::camera::View::frustum`]).
pub fn visible(planes: &[Vec4; 5], camera: DVec3, tile: &TileInfo) -> bool {
    !box_outside(planes, tile.min - camera, tile.max - camera)
}

/// Whether the box `lo..hi` (relative to the camera) lies wholly outside one of the planes
/// (conservative: a box reported inside may still miss the frustum; one within rounding of a
/// plane, the planes being f32, counts as inside).
pub fn box_outside(planes: &[Vec4; 5], lo: DVec3, hi: DVec3) -> bool {
    let (lo, hi) = (lo.as_vec3(), hi.as_vec3());
    !planes.iter().all(|p| {
        // The box corner furthest along the plane normal.
        let corner = glam::Vec3::new(
            if p.x >= 0.0 { hi.x } else { lo.x },
            if p.y >= 0.0 { hi.y } else { lo.y },
            if p.z >= 0.0 { hi.z } else { lo.z },
        );
        let n = p.truncate();
        let slack = 1e-5 * (n.abs().dot(corner.abs()) + p.w.abs());
        n.dot(corner) + p.w >= -slack
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use crate::test_rng::Rng;

    /// Random cameras and boxes around them: a box culled has no point of a 9 x 9 x 9 lattice
    /// on screen (culling never drops what is visible); every box wholly behind the camera is
    /// culled, and so is most of what lies off screen (culling does cull).
    #[test]
    fn culled_boxes_have_nothing_on_screen() {
        let mut rng = Rng(0xc011_5eed_0bad_f00d);
        let (w, h) = (640u32, 480u32);
        let (mut culled, mut behind, mut behind_culled, mut seen_kept) = (0, 0, 0, 0);
        for _ in 0..3000 {
            let camera = Camera {
                position: DVec3::ZERO,
                yaw: rng.range(-3.0, 3.0),
                pitch: rng.range(-1.4, 1.0),
                fov_y: rng.range(0.3, 1.6),
            };
            let view = camera.view(w, h);
            let planes = view.frustum();
            let centre = DVec3::new(
                rng.range(-2000.0, 2000.0),
                rng.range(-2000.0, 2000.0),
                rng.range(-800.0, 800.0),
            );
            let size = DVec3::new(
                rng.range(1.0, 600.0),
                rng.range(1.0, 600.0),
                rng.range(1.0, 300.0),
            );
            let (lo, hi) = (centre - size * 0.5, centre + size * 0.5);
            let outside = box_outside(&planes, lo, hi);
            let lattice = (0..9 * 9 * 9).map(|k| {
                let t = DVec3::new(f64::from(k % 9), f64::from(k / 9 % 9), f64::from(k / 81)) / 8.0;
                lo + (hi - lo) * t
            });
            let mut on_screen = false;
            let mut all_behind = true;
            for p in lattice {
                all_behind &= view.to_view(p).z > 0.0;
                if let Some((x, y)) = view.project(p) {
                    on_screen |=
                        (0.0..=f64::from(w)).contains(&x) && (0.0..=f64::from(h)).contains(&y);
                }
            }
            assert!(
                !(outside && on_screen),
                "culled a box with a point on screen"
            );
            culled += u32::from(outside);
            seen_kept += u32::from(on_screen);
            if all_behind {
                behind += 1;
                behind_culled += u32::from(outside);
            }
        }
        assert!(
            behind > 100 && behind_culled == behind,
            "{behind_culled} of {behind}"
        );
        // Most random boxes are off screen; culling keeps the visible ones and drops most.
        assert!(seen_kept > 100, "{seen_kept} boxes on screen");
        assert!(culled > 3000 / 2, "only {culled} of 3000 culled");
    }
}
