//! `vkterrain --measure-error`: the screen-space error a frame actually delivers, measured on
//! the CPU against the source DEM.
//!
//! For every drawn tile and every source sample the drawn level's triangles cover, the drawn
//! surface's height there (interpolated in the triangle, as the rasteriser does) and the
//! sample's are projected with the frame's camera; the distance between the two image points
//! is that sample's error in pixels. Samples where either point is behind the near plane or
//! off the image are skipped (nothing is seen there). The frame's `max_error_px` is the
//! largest over all of them.

use std::collections::HashMap;

use glam::DVec3;
use tiles::build::tile_samples;
use tiles::mesh::{TILE_CELLS, TILE_SIZE};
use tiles::verify::raster_barycentric;
use tiles::Grid;

use crate::camera::Camera;
use crate::terrain::Terrain;

type Triangle = [(u32, u32, f32); 3];

/// The source samples of every tile and the triangles of the levels drawn so far.
pub struct ErrorMeter {
    /// Per tile, 257 x 257 source heights (row 0 north), and the last real column / row.
    samples: Vec<(Vec<f32>, u32, u32)>,
    triangles: HashMap<(usize, u32), Vec<Triangle>>,
}

impl ErrorMeter {
    /// Cuts `grid` into the tile set's tiles; the grid must be the one the set was built from
    /// (same size).
    pub fn new(terrain: &Terrain, grid: &Grid) -> Result<ErrorMeter, String> {
        let h = terrain.set.header();
        if (grid.width, grid.height) != (h.grid_width as usize, h.grid_height as usize) {
            return Err(format!(
                "the source is {}x{} samples, the tile set was built from {}x{}",
                grid.width, grid.height, h.grid_width, h.grid_height
            ));
        }
        let samples = terrain
            .tiles
            .iter()
            .map(|t| {
                let s = tile_samples(grid, t.tx, t.ty);
                (s.heights, s.data_max_x, s.data_max_y)
            })
            .collect();
        Ok(ErrorMeter {
            samples,
            triangles: HashMap::new(),
        })
    }

    /// The largest error in pixels over the drawn tiles `draws` (tile, level) seen by `camera`
    /// at `extent`; 0 when nothing is seen.
    pub fn frame(
        &mut self,
        terrain: &Terrain,
        camera: &Camera,
        extent: (u32, u32),
        draws: &[(usize, u32)],
    ) -> f64 {
        let view = camera.view(extent.0, extent.1);
        let (w, h) = (f64::from(extent.0), f64::from(extent.1));
        let on_image = |p: DVec3| {
            view.project(p - camera.position)
                .filter(|&(u, v)| (0.0..=w).contains(&u) && (0.0..=h).contains(&v))
        };
        let (sx, sy) = terrain.spacing;
        let mut worst = 0.0f64;
        for &(tile, level) in draws {
            let info = &terrain.tiles[tile];
            let (c0, r0) = (
                f64::from(info.tx * TILE_CELLS),
                f64::from(info.ty * TILE_CELLS),
            );
            let triangles = self
                .triangles
                .entry((tile, level))
                .or_insert_with(|| level_triangles(terrain, tile, level));
            let (source, max_x, max_y) = &self.samples[tile];
            for &t in triangles.iter() {
                raster_barycentric(t, *max_x, *max_y, |x, y, z| {
                    let wx = (c0 + f64::from(x)) * sx;
                    let wy = -(r0 + f64::from(y)) * sy;
                    let sample = f64::from(source[y as usize * TILE_SIZE + x as usize]);
                    let (Some(a), Some(b)) = (
                        on_image(DVec3::new(wx, wy, z)),
                        on_image(DVec3::new(wx, wy, sample)),
                    ) else {
                        return;
                    };
                    worst = worst.max(((a.0 - b.0).powi(2) + (a.1 - b.1).powi(2)).sqrt());
                });
            }
        }
        worst
    }
}

/// The triangles of one level of one tile, vertices decoded to (column, row, metres).
fn level_triangles(terrain: &Terrain, tile: usize, level: u32) -> Vec<Triangle> {
    let info = &terrain.tiles[tile];
    let Ok(t) = terrain.set.tile(info.tx, info.ty) else {
        return Vec::new();
    };
    let vertices = t.vertices();
    let Some(l) = t.level(level) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for fan in l.indices.fans() {
        let v = |i: u32| vertices.get(i as usize).copied();
        let Some(c) = fan.first().and_then(|&i| v(i)) else {
            continue;
        };
        for pair in fan[1..].windows(2) {
            if let (Some(a), Some(b)) = (v(pair[0]), v(pair[1])) {
                out.push([c, a, b]);
            }
        }
    }
    out
}
