//! Frustum culling of tile bounding boxes, relative to the camera.

use glam::{DVec3, Vec4};

use crate::terrain::TileInfo;

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
