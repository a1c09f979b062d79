//! Level of detail per tile (paper, section 5): project the pixel tolerance `tau` into object
//! space with the Jacobian of the current projection at the tile's bounding-box corners, and
//! draw the tile at the finest level any corner asks for.
//!
//! The Jacobian is applied to world up, because the stored errors are vertical deviations:
//! `r = tau / |J z|` is the vertical error that moves `tau` pixels on screen at that point.
//! The level chosen is the coarsest whose *measured* max error (from the tile file) is at most
//! the smallest `r`. Corners alone miss the nearest part of a box the camera is over or inside,
//! so the box point closest to the camera is evaluated too; inside the box it is the camera
//! itself, which asks for the finest level.

use glam::DVec3;

use crate::camera::View;
use crate::terrain::TileInfo;

/// The smallest object-space vertical error, metres, that projects to `tau` pixels anywhere
/// on the tile's box.
pub fn tolerable_error(view: &View, camera: DVec3, tile: &TileInfo, tau: f64) -> f64 {
    let (lo, hi) = (tile.min - camera, tile.max - camera);
    let closest = DVec3::ZERO.clamp(lo, hi);
    let mut worst = view.pixels_per_vertical_metre(closest);
    for i in 0..8 {
        let corner = DVec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        );
        worst = worst.max(view.pixels_per_vertical_metre(corner));
    }
    tau / worst
}

/// The coarsest level whose measured error is within `r` metres (the finest if none is).
pub fn level_for(tile: &TileInfo, r: f64) -> u32 {
    tile.levels
        .iter()
        .position(|l| f64::from(l.max_error) <= r)
        .unwrap_or(tile.levels.len().saturating_sub(1)) as u32
}
