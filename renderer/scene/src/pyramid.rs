//! The tile pyramid as the renderer sees it: one [`Terrain`] per layer of a set built with
//! `tiletool build --pyramid` (layer 0 the base grid), and which tiles of the layer below a
//! tile covers. A layer's tiles are a terrain of their own ([`Terrain::open_layer`]): their
//! boxes, level tables and checks are worked out exactly as the base grid's, at the layer's
//! spacing, with each level's error measured against the base grid's samples under the tile
//! (`tiles::pyramid::base_errors`).

use std::path::Path;

use crate::terrain::Terrain;

pub struct Pyramid {
    /// Layer 0, the base grid, first; the last layer has the fewest tiles (one, for a set whose
    /// pyramid goes to the top).
    pub layers: Vec<Terrain>,
}

impl Pyramid {
    /// Opens every layer of the set (the base grid alone for a set without a pyramid): the
    /// file once, then each layer's view of it.
    pub fn open(path: &Path) -> Result<Pyramid, tiles::FormatError> {
        let file = tiles::TileSet::open(path)?;
        let layers = (0..=file.pyramid_layers())
            .filter_map(|p| file.layer(p))
            .map(Terrain::of_layer)
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Pyramid { layers })
    }

    /// The index of the top layer.
    pub fn top(&self) -> u32 {
        self.layers.len() as u32 - 1
    }

    /// Tiles (indices) of layer `p - 1` that tile `i` of layer `p >= 1` covers: up to 2 x 2.
    pub fn children(&self, p: u32, i: usize) -> impl Iterator<Item = usize> + '_ {
        let (upper, below) = (&self.layers[p as usize], &self.layers[p as usize - 1]);
        let (tx, ty) = (i as u32 % upper.tiles_x, i as u32 / upper.tiles_x);
        (0..4u32)
            .map(move |k| (2 * tx + k % 2, 2 * ty + k / 2))
            .filter(move |&(cx, cy)| cx < below.tiles_x && cy < below.tiles_y)
            .map(move |(cx, cy)| (cy * below.tiles_x + cx) as usize)
    }

    /// The base grid's tiles under tile `i` of layer `p`: columns and rows.
    pub fn base_tiles_under(
        &self,
        p: u32,
        i: usize,
    ) -> (std::ops::Range<u32>, std::ops::Range<u32>) {
        let layer = &self.layers[p as usize];
        let (tx, ty) = (i as u32 % layer.tiles_x, i as u32 / layer.tiles_x);
        let base = &self.layers[0];
        let f = 1u32 << p;
        (
            (tx * f).min(base.tiles_x)..((tx + 1) * f).min(base.tiles_x),
            (ty * f).min(base.tiles_y)..((ty + 1) * f).min(base.tiles_y),
        )
    }
}
