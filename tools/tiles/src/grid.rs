//! The source grid as the builder and the verifier see it, and its cut into tiles.

use crate::mesh::{TileSamples, TILE_CELLS, TILE_SIZE};

/// A height field in metres, row-major, row 0 = north.
#[derive(Clone, Copy, Debug)]
pub struct Grid<'a> {
    pub width: usize,
    pub height: usize,
    pub heights: &'a [f32],
    /// Metres between columns / rows.
    pub spacing_x: f64,
    pub spacing_y: f64,
}

/// The 257 x 257 samples of tile `(tx, ty)`, the last real row and column repeated past the data.
pub fn tile_samples(grid: &Grid, tx: u32, ty: u32) -> TileSamples {
    let cells = TILE_CELLS as usize;
    let (x0, y0) = (tx as usize * cells, ty as usize * cells);
    let data_max_x = (grid.width - 1 - x0).min(cells);
    let data_max_y = (grid.height - 1 - y0).min(cells);
    let mut heights = Vec::with_capacity(TILE_SIZE * TILE_SIZE);
    for y in 0..TILE_SIZE {
        let row = (y0 + y.min(data_max_y)) * grid.width;
        heights.extend((0..TILE_SIZE).map(|x| grid.heights[row + x0 + x.min(data_max_x)]));
    }
    TileSamples {
        heights,
        data_max_x: data_max_x as u32,
        data_max_y: data_max_y as u32,
    }
}
