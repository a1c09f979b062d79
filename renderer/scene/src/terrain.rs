//! A mapped tile set as the renderer sees it: every tile validated once at open, its world
//! bounding box, measured errors and border vertices kept in memory for culling, LOD and
//! stitching; the vertex and index data stay in the mapped file until uploaded.

use std::path::Path;

use glam::DVec3;
use tiles::format::{LevelEntry, TileSet};
use tiles::mesh::TILE_CELLS;

use crate::levels::LevelTable;
use crate::tile::{rebase, Side, TileInfo, HEIGHT_CELLS};

pub struct Terrain {
    pub set: TileSet,
    pub tiles: Vec<TileInfo>,
    pub tiles_x: u32,
    pub tiles_y: u32,
    pub levels: u32,
    pub spacing: (f64, f64),
    pub height_step: f32,
    /// Neighbouring tiles have the same side vertices at every level, with the same morph
    /// offsets ([`tiles::format::FLAG_SHARED_SIDES`], checked against the borders here):
    /// geomorphing gives a shared side vertex the same height from both tiles, so stitches
    /// need no slivers between two copies of it.
    pub shared_sides: bool,
    /// The texture tiles' layout (None: the set has none) and what they show
    /// (`tiles::texture::SOURCE_*`).
    pub texture: Option<tiles::texture::Layout>,
    pub texture_source: u32,
}

impl Terrain {
    /// Opens and validates every tile (checksums, offsets, indices), so a corrupted file is
    /// refused before any GPU work.
    pub fn open(path: &Path) -> Result<Terrain, tiles::FormatError> {
        let set = TileSet::open(path)?;
        let h = *set.header();
        let (sx, sy) = (h.spacing_x, h.spacing_y);
        let mut tiles = Vec::with_capacity((h.tiles_x * h.tiles_y) as usize);
        for ty in 0..h.tiles_y {
            for tx in 0..h.tiles_x {
                tiles.push(tile_info(&set, tx, ty)?);
            }
        }
        check_tiles(&set, &tiles)?;
        let texture = set.texture_layout();
        let mut terrain = Terrain {
            set,
            tiles,
            tiles_x: h.tiles_x,
            tiles_y: h.tiles_y,
            levels: h.levels,
            spacing: (sx, sy),
            height_step: h.height_step,
            shared_sides: false,
            texture,
            texture_source: h.texture_source,
        };
        // A file that claims shared sides but whose borders differ (tampered with) is drawn as
        // one without: the seams stay closed by slivers.
        terrain.shared_sides =
            h.flags & tiles::format::FLAG_SHARED_SIDES != 0 && terrain.sides_agree();
        terrain.share_tables();
        Ok(terrain)
    }

    /// Gives every tile its side and corner level tables: the larger errors of the tiles that
    /// hold the side or corner, the same table in each of them.
    fn share_tables(&mut self) {
        let own: Vec<LevelTable> = self.tiles.iter().map(|t| t.tables[0]).collect();
        let at = |tx: i64, ty: i64| {
            (tx >= 0 && ty >= 0)
                .then(|| self.tile_index(tx as u32, ty as u32))
                .flatten()
                .map(|i| own[i])
        };
        let around = |t: &TileInfo, cells: &[(i64, i64)]| {
            cells
                .iter()
                .filter_map(|&(dx, dy)| at(i64::from(t.tx) + dx, i64::from(t.ty) + dy))
                .fold(own[self.tile_index(t.tx, t.ty).unwrap_or(0)], |a, b| {
                    a.max(&b)
                })
        };
        let tables: Vec<[LevelTable; 9]> = self
            .tiles
            .iter()
            .map(|t| {
                [
                    own[self.tile_index(t.tx, t.ty).unwrap_or(0)],
                    around(t, &[Side::North.step()]),
                    around(t, &[Side::East.step()]),
                    around(t, &[Side::South.step()]),
                    around(t, &[Side::West.step()]),
                    around(t, &[(-1, -1), (0, -1), (-1, 0)]),
                    around(t, &[(1, -1), (0, -1), (1, 0)]),
                    around(t, &[(-1, 1), (0, 1), (-1, 0)]),
                    around(t, &[(1, 1), (0, 1), (1, 0)]),
                ]
            })
            .collect();
        for (t, tables) in self.tiles.iter_mut().zip(tables) {
            t.drawn_table = tables[1..].iter().fold(tables[0], |a, b| a.max(b));
            t.tables = tables;
        }
    }

    /// Whether every two neighbouring tiles hold the same border vertices at every level, and
    /// every tile the same morph units.
    fn sides_agree(&self) -> bool {
        let units = |t: &TileInfo| -> Vec<u32> {
            t.levels.iter().map(|l| l.morph_unit.to_bits()).collect()
        };
        self.tiles.iter().all(|a| {
            units(a) == units(&self.tiles[0])
                && Side::FORWARD.iter().all(|&side| {
                    let Some(j) = self.neighbour(a, side) else {
                        return true;
                    };
                    let b = &self.tiles[j];
                    (0..self.levels as usize).all(|level| {
                        let theirs: Option<Vec<u32>> = b.borders[level][side.opposite().index()]
                            .iter()
                            .map(|&p| rebase(p, side, b, a))
                            .collect();
                        theirs.as_ref() == Some(&a.borders[level][side.index()])
                    })
                })
        })
    }

    /// The tile across `side` of `tile`, if the set has one.
    pub fn neighbour(&self, tile: &TileInfo, side: Side) -> Option<usize> {
        let (dx, dy) = side.step();
        let (x, y) = (i64::from(tile.tx) + dx, i64::from(tile.ty) + dy);
        let x = u32::try_from(x).ok()?;
        let y = u32::try_from(y).ok()?;
        self.tile_index(x, y)
    }

    /// What each tile costs in GPU memory, level by level (the memory manager's view).
    pub fn costs(&self) -> Vec<memory::TileCost> {
        self.tiles
            .iter()
            .map(|t| memory::TileCost {
                levels: t
                    .levels
                    .iter()
                    .enumerate()
                    .map(|(i, l)| memory::LevelCost {
                        positions: 4 * u64::from(l.block_len),
                        morph: i as u64 * u64::from(l.block_len),
                        indices: u64::from(l.index_count) * u64::from(l.index_width),
                        index_width: l.index_width,
                    })
                    .collect(),
            })
            .collect()
    }

    /// The stored bytes of one part of a tile (validated when the tile set was opened).
    pub fn part(&self, tile: usize, part: memory::Part) -> Option<&[u8]> {
        let info = self.tiles.get(tile)?;
        let blob = self.set.blob(info.tx, info.ty)?;
        let (offset, len) = match part {
            memory::Part::Positions(j) => {
                let l = info.levels.get(j as usize)?;
                (l.positions_offset, 4 * u64::from(l.block_len))
            }
            memory::Part::Morph(j) => {
                let l = info.levels.get(j as usize)?;
                (l.morph_offset, u64::from(j) * u64::from(l.block_len))
            }
            memory::Part::Indices(j) => {
                let l = info.levels.get(j as usize)?;
                (
                    l.index_offset,
                    u64::from(l.index_count) * u64::from(l.index_width),
                )
            }
        };
        let start = offset as usize;
        blob.get(start..start.checked_add(usize::try_from(len).ok()?)?)
    }

    /// The BC1 blocks of texture mip `mip` of `tile` (validated when the tile set was opened).
    pub fn texture_mip(&self, tile: usize, mip: u32) -> Option<&[u8]> {
        let info = self.tiles.get(tile)?;
        let range = info.texture_mips.get(mip as usize)?.clone();
        self.set.texture_blob(info.tx, info.ty)?.get(range)
    }

    /// Where the camera at `p` is for the shader: its tile (column, row of tiles) and its
    /// position relative to that tile's north-west corner. Positions are expressed relative to
    /// that tile, from integers, so a grid point shared by two tiles lands on the same f32 in
    /// both.
    pub fn camera_tile(&self, p: DVec3) -> ((f64, f64), DVec3) {
        let (sx, sy) = self.spacing;
        let cells = f64::from(TILE_CELLS);
        let tile = ((p.x / (cells * sx)).floor(), (-p.y / (cells * sy)).floor());
        let relative = DVec3::new(p.x - tile.0 * cells * sx, p.y + tile.1 * cells * sy, p.z);
        (tile, relative)
    }

    /// A tile's first sample relative to the camera's tile `camera_tile` (columns, rows): its
    /// record's `tile_offset`.
    pub fn tile_offset(camera_tile: (f64, f64), tile: &TileInfo) -> [i32; 2] {
        let cells = f64::from(TILE_CELLS);
        [
            ((f64::from(tile.tx) - camera_tile.0) * cells) as i32,
            ((f64::from(tile.ty) - camera_tile.1) * cells) as i32,
        ]
    }

    pub fn tile_index(&self, tx: u32, ty: u32) -> Option<usize> {
        (tx < self.tiles_x && ty < self.tiles_y).then(|| (ty * self.tiles_x + tx) as usize)
    }

    /// World bounds of the whole dataset.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        self.tiles
            .iter()
            .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), t| {
                (lo.min(t.min), hi.max(t.max))
            })
    }

    /// The highest ground within `radius` metres of (x, y), from each tile's coarse height map.
    pub fn max_height_near(&self, x: f64, y: f64, radius: f64) -> f64 {
        let mut best = f64::NEG_INFINITY;
        let (sx, sy) = self.spacing;
        for t in &self.tiles {
            for cy in 0..HEIGHT_CELLS {
                for cx in 0..HEIGHT_CELLS {
                    let h = t.heights[cy * HEIGHT_CELLS + cx];
                    if h == f32::NEG_INFINITY {
                        continue;
                    }
                    let cell = 257.0 / HEIGHT_CELLS as f64;
                    let x0 = t.min.x + cx as f64 * cell * sx;
                    let y1 = t.max.y - cy as f64 * cell * sy;
                    let (x1, y0) = (x0 + cell * sx, y1 - cell * sy);
                    if x1 >= x - radius && x0 <= x + radius && y1 >= y - radius && y0 <= y + radius
                    {
                        best = best.max(f64::from(h));
                    }
                }
            }
        }
        if best.is_finite() {
            best
        } else {
            self.bounds().1.z
        }
    }
}

/// One tile's bounds, borders, height cells, texture mips and own level table, read from the
/// file (its checksum and offsets checked by `TileSet::tile`).
fn tile_info(set: &TileSet, tx: u32, ty: u32) -> Result<TileInfo, tiles::FormatError> {
    let h = *set.header();
    let (sx, sy) = (h.spacing_x, h.spacing_y);
    let tile = set.tile(tx, ty)?;
    let th = tile.header;
    let levels: Vec<LevelEntry> = tile.levels().to_vec();
    let z_min = levels.iter().map(|l| l.z_min).fold(f32::INFINITY, f32::min);
    let z_max = levels
        .iter()
        .map(|l| l.z_max)
        .fold(f32::NEG_INFINITY, f32::max);
    let (c0, r0) = (f64::from(tx * TILE_CELLS), f64::from(ty * TILE_CELLS));
    let min = DVec3::new(
        c0 * sx,
        -(r0 + f64::from(th.mesh_max_y)) * sy,
        f64::from(z_min),
    );
    let max = DVec3::new(
        (c0 + f64::from(th.mesh_max_x)) * sx,
        -r0 * sy,
        f64::from(z_max),
    );
    let mut packed: Vec<u32> = Vec::with_capacity(th.vertex_count as usize);
    for i in 0..h.levels {
        if let Some(l) = tile.level(i) {
            packed.extend_from_slice(l.positions);
        }
    }
    let border_indices: Vec<[Vec<u32>; 4]> = (0..h.levels)
        .filter_map(|i| tile.level(i))
        .map(|l| l.border.map(|side| side.to_vec()))
        .collect();
    let borders = border_indices
        .iter()
        .map(|sides| {
            sides
                .clone()
                .map(|side| side.iter().map(|&v| packed[v as usize]).collect())
        })
        .collect();
    let texture_mips = match set.texture(tx, ty)? {
        Some(t) => t
            .mips
            .iter()
            .map(|(e, _)| e.offset as usize..(e.offset + e.len) as usize)
            .collect(),
        None => Vec::new(),
    };
    // Its levels' errors as the morph sees them: measured, plus half a morph unit
    // (the stored offsets are rounded to whole units).
    let errors: Vec<f32> = levels
        .iter()
        .map(|l| l.max_error.max(0.0) + 0.5 * l.morph_unit.max(0.0))
        .collect();
    let own_table = LevelTable::new(&errors);
    let q = tile.quantiser();
    let mut heights = [f32::NEG_INFINITY; HEIGHT_CELLS * HEIGHT_CELLS];
    for &p in &packed {
        let (x, y, code) = tiles::pack::unpack(p);
        let cell =
            (y as usize * HEIGHT_CELLS / 257) * HEIGHT_CELLS + x as usize * HEIGHT_CELLS / 257;
        heights[cell] = heights[cell].max(q.height(code));
    }
    Ok(TileInfo {
        tx,
        ty,
        header: th,
        levels,
        min,
        max,
        borders,
        border_indices,
        heights,
        texture_mips,
        tables: [own_table; 9],
        drawn_table: own_table,
    })
}

/// Refuses the tile set if any tile has a problem `tiletool verify` (without a source) would
/// report: fans, coverage, nesting, blocks, borders, morph offsets. Checksums catch accidents;
/// this catches a file whose checksums were recomputed over nonsense, before any of its bytes
/// reach the GPU. About 50 ms a tile, on every core.
fn check_tiles(set: &TileSet, tiles: &[TileInfo]) -> Result<(), tiles::FormatError> {
    use rayon::prelude::*;
    let problem = tiles.par_iter().find_map_first(|t| {
        let tile = match set.tile(t.tx, t.ty) {
            Ok(tile) => tile,
            Err(e) => return Some(e.to_string()),
        };
        tiles::verify::tile_problems(set, &tile).into_iter().next()
    });
    match problem {
        None => Ok(()),
        Some(what) => {
            // verify's problems start with the file's name; the error adds it back.
            let prefix = format!("{}: ", set.path().display());
            Err(tiles::FormatError::Invalid {
                path: set.path().to_path_buf(),
                what: what.strip_prefix(&prefix).unwrap_or(&what).to_string(),
            })
        }
    }
}
