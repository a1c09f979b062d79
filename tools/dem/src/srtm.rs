//! SRTM `.hgt` tiles: headerless big-endian i16, 1201² (3", SRTM3) or 3601² (1", SRTM1)
//! samples, -32768 = void. The name (N42E001) is the south-west corner of the 1°x1° cell;
//! several tiles given together are mosaicked by their names, sharing edge rows/columns.

use std::path::{Path, PathBuf};

use crate::error::label;
use crate::placement::{Crs, Placement};
use crate::raster::{Georef, Raster};
use crate::{DemError, ReadOptions};

const VOID: i16 = -32768;

/// The 1°x1° cell a tile covers, by its south-west corner in whole degrees (S, W negative).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
struct Cell {
    lat: i32,
    lon: i32,
}

impl Cell {
    /// `N42E001`, `s12w077.hgt`, `N42E001.SRTMGL1.hgt`: the first seven characters of the file
    /// name, any case, any directory.
    fn from_path(path: &Path) -> Option<Cell> {
        let full = path.file_name()?.to_str()?;
        // The seven characters end the name or are followed by a dot (`N42E001x.hgt` is not).
        if !matches!(full.as_bytes().get(7), None | Some(b'.')) {
            return None;
        }
        let name = full.get(..7)?.to_ascii_uppercase();
        let b = name.as_bytes();
        let lat: i32 = name.get(1..3)?.parse().ok()?;
        let lon: i32 = name.get(4..7)?.parse().ok()?;
        if !b[1..3].iter().chain(&b[4..7]).all(u8::is_ascii_digit) {
            return None; // "+1" parses as an i32 but is no tile name
        }
        let lat = match b[0] {
            b'N' if lat <= 89 => lat,
            b'S' if (1..=90).contains(&lat) => -lat,
            _ => return None,
        };
        let lon = match b[3] {
            b'E' if lon <= 179 => lon,
            b'W' if (1..=180).contains(&lon) => -lon,
            _ => return None,
        };
        Some(Cell { lat, lon })
    }

    fn name(self) -> String {
        let ns = if self.lat < 0 { 'S' } else { 'N' };
        let ew = if self.lon < 0 { 'W' } else { 'E' };
        format!("{ns}{:02}{ew}{:03}", self.lat.abs(), self.lon.abs())
    }
}

/// Samples per side from the file length: the only thing that tells SRTM1 from SRTM3.
fn side_from_len(file: &str, len: u64) -> Result<usize, DemError> {
    match len {
        0 => Err(DemError::Empty {
            file: file.to_string(),
        }),
        2_884_802 => Ok(1201),
        25_934_402 => Ok(3601),
        _ => Err(DemError::Malformed {
            file: file.to_string(),
            problem: format!(
                "size {len} bytes is neither 1201² nor 3601² samples (truncated or not an SRTM tile)"
            ),
        }),
    }
}

/// Reads one tile, or mosaics several.
pub fn read(paths: &[PathBuf], opts: &ReadOptions) -> Result<Raster, DemError> {
    let mosaic = layout(paths, opts)?;
    let samples = mosaic.rows(0, mosaic.height)?;
    Ok(Raster {
        width: mosaic.width,
        height: mosaic.height,
        samples,
        georef: mosaic.georef,
        placement: mosaic.placement,
        description: mosaic.description,
    })
}

/// One tile or a mosaic of several, laid out from the files' names and sizes, read a band of
/// rows at a time ([`Mosaic::rows`]).
#[derive(Clone, Debug)]
pub struct Mosaic {
    pub width: usize,
    pub height: usize,
    pub georef: Georef,
    pub placement: Option<Placement>,
    pub description: String,
    /// Samples per tile side.
    side: usize,
    /// North to south, then west to east: first row, first column, path, label.
    cells: Vec<(usize, usize, PathBuf, String)>,
    scale: f64,
}

/// Lays out one tile, or a mosaic of several, without reading their samples.
pub fn layout(paths: &[PathBuf], opts: &ReadOptions) -> Result<Mosaic, DemError> {
    // Sizes and names first, so a bad mosaic is refused before any tile is read.
    let mut tiles = Vec::with_capacity(paths.len());
    for path in paths {
        let file = label(path);
        let len = std::fs::metadata(path)
            .map_err(|source| DemError::Io {
                file: file.clone(),
                source,
            })?
            .len();
        let side = side_from_len(&file, len)?;
        tiles.push((path, file, side, Cell::from_path(path)));
    }

    let [(path, file, side, cell)] = &tiles[..] else {
        return layout_mosaic(&tiles, opts);
    };
    let side = *side;
    let arc = if side == 1201 { 3 } else { 1 };
    let (georef, description) = match cell {
        Some(cell) => (
            georef(cell.lat + 1, side),
            format!("SRTM{arc} {}", cell.name()),
        ),
        None if opts.spacing.is_some() => (Georef::None, format!("SRTM{arc} (unnamed tile)")),
        None => {
            return Err(DemError::Option {
                file: file.clone(),
                problem: "the name does not say where the tile lies (expected like N42E001.hgt): \
                          rename it or pass --spacing"
                    .to_string(),
            })
        }
    };
    Ok(Mosaic {
        width: side,
        height: side,
        georef,
        placement: cell.map(|c| placement(c.lat + 1, c.lon, side)),
        description,
        side,
        cells: vec![(0, 0, (*path).clone(), file.clone())],
        scale: opts.vertical_scale(),
    })
}

impl Mosaic {
    /// Rows `y0..y1` of the mosaic, voids as NaN, heights times the vertical scale. Where
    /// tiles share a row or column, a valid sample wins over a void, and of two valid ones the
    /// later tile's (north to south, west to east).
    pub fn rows(&self, y0: usize, y1: usize) -> Result<Vec<f32>, DemError> {
        use std::os::unix::fs::FileExt;
        let (width, side) = (self.width, self.side);
        let mut out = vec![f32::NAN; (y1 - y0) * width];
        let mut bytes = Vec::new();
        for (row0, col0, path, file) in &self.cells {
            let (a, b) = (y0.max(*row0), y1.min(row0 + side));
            if a >= b {
                continue;
            }
            let io = |source| DemError::Io {
                file: file.clone(),
                source,
            };
            let f = std::fs::File::open(path).map_err(io)?;
            // The file may have changed since its length was checked.
            let len = f.metadata().map_err(io)?.len();
            if len != (side * side * 2) as u64 {
                return Err(DemError::Malformed {
                    file: file.clone(),
                    problem: format!("size changed while reading (now {len} bytes)"),
                });
            }
            bytes.resize((b - a) * side * 2, 0);
            f.read_exact_at(&mut bytes, ((a - row0) * side * 2) as u64)
                .map_err(io)?;
            for (r, src) in bytes.chunks_exact(side * 2).enumerate() {
                let dst = &mut out[(a - y0 + r) * width + col0..][..side];
                for (d, s) in dst.iter_mut().zip(src.chunks_exact(2)) {
                    let v = i16::from_be_bytes([s[0], s[1]]);
                    // On shared edges keep a valid sample over a void (the neighbour may have it).
                    if v != VOID {
                        *d = (f64::from(v) * self.scale) as f32;
                    }
                }
            }
        }
        Ok(out)
    }
}

/// Sample (0, 0) of a tile or mosaic is the north-west corner of its top-left cell: SRTM
/// samples are points on whole degrees (and fractions), WGS 84.
fn placement(lat_north: i32, lon_west: i32, side: usize) -> Placement {
    let step = 1.0 / (side - 1) as f64;
    Placement {
        crs: Crs::Geographic { code: Some(4326) },
        x0: f64::from(lon_west),
        y0: f64::from(lat_north),
        dx: step,
        dy: step,
    }
}

/// Row 0 of a tile or mosaic lies on the northern edge of its top cells.
fn georef(lat_north: i32, side: usize) -> Georef {
    let step = 1.0 / (side - 1) as f64;
    Georef::Degrees {
        step_lon: step,
        step_lat: step,
        lat_row0: f64::from(lat_north),
    }
}

type Tile<'a> = (&'a PathBuf, String, usize, Option<Cell>);

fn layout_mosaic(tiles: &[Tile<'_>], opts: &ReadOptions) -> Result<Mosaic, DemError> {
    let mosaic_error = |file: &str, problem: String| DemError::Mosaic {
        file: file.to_string(),
        problem,
    };
    let Some((_, first_file, side, _)) = tiles.first() else {
        return Err(DemError::NoInput);
    };
    let side = *side;
    let arc = |s: usize| {
        if s == 1201 {
            "1201² (3\")"
        } else {
            "3601² (1\")"
        }
    };
    let mut cells: Vec<(Cell, &Tile<'_>)> = Vec::with_capacity(tiles.len());
    for tile in tiles {
        let (_, file, tile_side, cell) = tile;
        if *tile_side != side {
            return Err(mosaic_error(
                file,
                format!(
                    "it is {} but {first_file} is {}",
                    arc(*tile_side),
                    arc(side)
                ),
            ));
        }
        let Some(cell) = cell else {
            return Err(mosaic_error(
                file,
                "its name does not say where it lies (expected like N42E001.hgt)".to_string(),
            ));
        };
        if let Some((_, other)) = cells.iter().find(|(c, _)| c == cell) {
            return Err(mosaic_error(
                file,
                format!("cell {} is given twice (also {})", cell.name(), other.1),
            ));
        }
        cells.push((*cell, tile));
    }

    let lat_min = cells.iter().map(|(c, _)| c.lat).min().unwrap_or(0);
    let lat_max = cells.iter().map(|(c, _)| c.lat).max().unwrap_or(0);
    let lon_min = cells.iter().map(|(c, _)| c.lon).min().unwrap_or(0);
    let lon_max = cells.iter().map(|(c, _)| c.lon).max().unwrap_or(0);
    let rows = (lat_max - lat_min + 1) as usize;
    let cols = (lon_max - lon_min + 1) as usize;
    if rows * cols != cells.len() {
        // Name the first hole so the user knows which tile to add.
        let missing = (lat_min..=lat_max)
            .rev()
            .flat_map(|lat| (lon_min..=lon_max).map(move |lon| Cell { lat, lon }))
            .find(|c| !cells.iter().any(|(d, _)| d == c));
        let sw = Cell {
            lat: lat_min,
            lon: lon_min,
        };
        let ne = Cell {
            lat: lat_max,
            lon: lon_max,
        };
        return Err(mosaic_error(
            first_file,
            format!(
                "the {} tiles do not fill the rectangle {}..{}: {} is missing",
                cells.len(),
                sw.name(),
                ne.name(),
                missing.map_or_else(|| "a tile".to_string(), Cell::name)
            ),
        ));
    }

    // Tiles overlap by one row/column; rows * cols == number of files, so this is bounded by
    // the files' own sizes.
    let step = side - 1;
    let width = cols * step + 1;
    let height = rows * step + 1;
    cells.sort_by_key(|(c, _)| (std::cmp::Reverse(c.lat), c.lon));
    let sw = Cell {
        lat: lat_min,
        lon: lon_min,
    };
    let ne = Cell {
        lat: lat_max,
        lon: lon_max,
    };
    let arc = if side == 1201 { 3 } else { 1 };
    Ok(Mosaic {
        width,
        height,
        georef: georef(lat_max + 1, side),
        placement: Some(placement(lat_max + 1, lon_min, side)),
        description: format!(
            "SRTM{arc} mosaic {}..{} ({} files)",
            sw.name(),
            ne.name(),
            cells.len()
        ),
        side,
        cells: cells
            .iter()
            .map(|(cell, (path, file, _, _))| {
                let row0 = (lat_max - cell.lat) as usize * step;
                let col0 = (cell.lon - lon_min) as usize * step;
                (row0, col0, (*path).clone(), file.clone())
            })
            .collect(),
        scale: opts.vertical_scale(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_from_names() {
        let c = |s: &str| Cell::from_path(Path::new(s));
        assert_eq!(c("N42E001.hgt"), Some(Cell { lat: 42, lon: 1 }));
        assert_eq!(c("/x/y/s12w077.HGT"), Some(Cell { lat: -12, lon: -77 }));
        assert_eq!(c("N42E001.SRTMGL1.hgt"), Some(Cell { lat: 42, lon: 1 }));
        assert_eq!(
            c("S90W180.hgt"),
            Some(Cell {
                lat: -90,
                lon: -180
            })
        );
        assert_eq!(c("N90E000.hgt"), None);
        assert_eq!(c("N42E180.hgt"), None);
        assert_eq!(c("N+1E001.hgt"), None);
        assert_eq!(c("tile.hgt"), None);
        assert_eq!(c("N4"), None);
        assert_eq!(Cell { lat: -12, lon: -77 }.name(), "S12W077");
        assert_eq!(Cell { lat: 0, lon: 0 }.name(), "N00E000");
    }
}
