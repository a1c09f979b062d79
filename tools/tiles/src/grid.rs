//! The source grid as the builder and the verifier see it, and its cut into tiles.

use crate::mesh::{TileSamples, TILE_CELLS, TILE_SIZE};

/// A height field in metres, row-major, row 0 = north: the whole grid, or a band of its rows
/// (banded builds read a grid larger than memory a band at a time).
#[derive(Clone, Copy, Debug)]
pub struct Grid<'a> {
    /// Columns and rows of the whole grid.
    pub width: usize,
    pub height: usize,
    /// The row `heights` starts at: it holds rows `first_row..first_row + heights.len() /
    /// width` (0 and all of them when the grid is whole).
    pub first_row: usize,
    pub heights: &'a [f32],
    /// Metres between columns / rows.
    pub spacing_x: f64,
    pub spacing_y: f64,
}

impl Grid<'_> {
    /// The height at column `x`, row `y` of the whole grid. Panics outside the rows held.
    pub fn at(&self, x: usize, y: usize) -> f32 {
        self.heights[(y - self.first_row) * self.width + x]
    }

    /// Row `y` of the whole grid. Panics outside the rows held.
    pub fn row(&self, y: usize) -> &[f32] {
        let start = (y - self.first_row) * self.width;
        &self.heights[start..start + self.width]
    }

    /// The rows held, `first_row..end`.
    pub fn rows(&self) -> std::ops::Range<usize> {
        self.first_row..self.first_row + self.heights.len() / self.width.max(1)
    }
}

/// The 257 x 257 samples of tile `(tx, ty)`, the last real row and column repeated past the data.
pub fn tile_samples(grid: &Grid, tx: u32, ty: u32) -> TileSamples {
    let cells = TILE_CELLS as usize;
    let (x0, y0) = (tx as usize * cells, ty as usize * cells);
    let data_max_x = (grid.width - 1 - x0).min(cells);
    let data_max_y = (grid.height - 1 - y0).min(cells);
    let mut heights = Vec::with_capacity(TILE_SIZE * TILE_SIZE);
    for y in 0..TILE_SIZE {
        let row = grid.row(y0 + y.min(data_max_y));
        heights.extend((0..TILE_SIZE).map(|x| row[x0 + x.min(data_max_x)]));
    }
    TileSamples {
        heights,
        data_max_x: data_max_x as u32,
        data_max_y: data_max_y as u32,
    }
}
