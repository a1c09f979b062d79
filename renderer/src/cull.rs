//! Frustum culling of tile bounding boxes, relative to the camera.

use glam::{DVec3, Vec4};

use crate::terrain::TileInfo;

/// Whether the tile's box touches the frustum (planes from [`crate::camera::View::frustum`]).
pub fn visible(planes: &[Vec4; 5], camera: DVec3, tile: &TileInfo) -> bool {
    let (lo, hi) = ((tile.min - camera).as_vec3(), (tile.max - camera).as_vec3());
    planes.iter().all(|p| {
        // The box corner furthest along the plane normal.
        let corner = glam::Vec3::new(
            if p.x >= 0.0 { hi.x } else { lo.x },
            if p.y >= 0.0 { hi.y } else { lo.y },
            if p.z >= 0.0 { hi.z } else { lo.z },
        );
        p.truncate().dot(corner) + p.w >= 0.0
    })
}
