//! Reads real elevation files into one [`HeightGrid`] in metres, for `tiletool` to cut into
//! tiles: SRTM `.hgt` (one tile or a mosaic of adjacent tiles), GeoTIFF, greyscale PNG/JPEG,
//! Terrain-RGB/Terrarium PNG tiles and raw `.r16`/`.f32`. Voids are filled (push-pull) and
//! counted; spacing comes from the file's georeferencing or from `--spacing`.
//!
//! ```no_run
//! use std::path::PathBuf;
//! let paths = [PathBuf::from("N41E001.hgt"), PathBuf::from("N42E001.hgt")];
//! let grid = dem::read(&paths, &dem::ReadOptions::default())?;
//! assert_eq!((grid.width, grid.height), (1201, 2401)); // N42 on top, one shared row
//! println!("{}: {:.1} m x {:.1} m, {} voids filled",
//!          grid.description, grid.spacing_x, grid.spacing_y, grid.voids_filled);
//! # Ok::<(), dem::DemError>(())
//! ```

mod banded;
mod error;
mod fill;
mod geo;
mod geotiff;
mod options;
mod picture;
mod placement;
mod raster;
mod raw;
mod srtm;
mod stream;
mod tiff_mosaic;

use std::path::{Path, PathBuf};

pub use banded::{Plan, Pulled, STORED};
pub use error::DemError;
pub use geo::{metres_per_degree_lat, metres_per_degree_lon};
pub use geotiff::read_placement as read_tiff_placement;
pub use options::{parse_size, Crop, Encoding, ReadOptions};
pub use placement::{Crs, Mapping, Placement};
pub use raster::{MAX_BANDED_SAMPLES, MAX_SAMPLES};
pub use stream::{open, open_unscanned, scan_rows, RowsScan, Stream, BAND_FORMATS};

use error::label;
use raster::{Georef, Raster};

/// A height field in metres, row-major, row 0 = north (first row of the file), column 0 = west.
#[derive(Clone, Debug)]
pub struct HeightGrid {
    pub width: usize,
    pub height: usize,
    /// Metres, `width * height` of them, no voids left (filled).
    pub heights: Vec<f32>,
    /// Metres between columns (east-west).
    pub spacing_x: f64,
    /// Metres between rows (north-south).
    pub spacing_y: f64,
    /// How many samples were void/nodata and got filled.
    pub voids_filled: u64,
    /// What was read, e.g. "SRTM3 mosaic N41E001..N42E001 (2 files)".
    pub description: String,
    /// Where the (cropped) grid lies, when the file says.
    pub placement: Option<Placement>,
}

impl HeightGrid {
    /// Height at column `x`, row `y`. Panics outside the grid, like slice indexing.
    pub fn get(&self, x: usize, y: usize) -> f32 {
        assert!(
            x < self.width,
            "column {x} outside a {} wide grid",
            self.width
        );
        self.heights[y * self.width + x]
    }

    /// Lowest and highest height.
    pub fn min_max(&self) -> (f32, f32) {
        self.heights
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &h| {
                (lo.min(h), hi.max(h))
            })
    }
}

/// Kind of input, from the extension or, failing that, the first bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Hgt,
    Tiff,
    Png,
    Jpeg,
    Raw(raw::RawKind),
}

impl Kind {
    fn of(path: &Path) -> Result<Kind, DemError> {
        // Only regular files: reading a FIFO could block forever, a device never ends.
        match std::fs::metadata(path) {
            Ok(m) if !m.is_file() => {
                return Err(DemError::Malformed {
                    file: label(path),
                    problem: "not a regular file".into(),
                })
            }
            Ok(_) => {}
            Err(source) => {
                return Err(DemError::Io {
                    file: label(path),
                    source,
                })
            }
        }
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("hgt") => return Ok(Kind::Hgt),
            Some("tif" | "tiff") => return Ok(Kind::Tiff),
            Some("png") => return Ok(Kind::Png),
            Some("jpg" | "jpeg") => return Ok(Kind::Jpeg),
            Some("r16") => return Ok(Kind::Raw(raw::RawKind::U16)),
            Some("f32") => return Ok(Kind::Raw(raw::RawKind::F32)),
            _ => {}
        }
        // No telling extension: the formats with a signature can still be recognised.
        let file = label(path);
        let mut magic = [0u8; 4];
        let n = {
            use std::io::Read;
            let mut f = std::fs::File::open(path).map_err(|source| DemError::Io {
                file: file.clone(),
                source,
            })?;
            let mut n = 0;
            while n < magic.len() {
                match f.read(&mut magic[n..]) {
                    Ok(0) => break,
                    Ok(k) => n += k,
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                    Err(source) => return Err(DemError::Io { file, source }),
                }
            }
            n
        };
        match &magic[..n] {
            [0x89, b'P', b'N', b'G'] => Ok(Kind::Png),
            [0xFF, 0xD8, 0xFF, _] => Ok(Kind::Jpeg),
            [b'I', b'I', 42 | 43, 0] | [b'M', b'M', 0, 42 | 43] => Ok(Kind::Tiff),
            [] => Err(DemError::Empty { file }),
            _ => Err(DemError::UnknownFormat { file }),
        }
    }

    fn name(self) -> &'static str {
        match self {
            Kind::Hgt => "an SRTM .hgt tile",
            Kind::Tiff => "a TIFF",
            Kind::Png => "a PNG",
            Kind::Jpeg => "a JPEG",
            Kind::Raw(_) => "a raw file",
        }
    }
}

/// Reads one elevation file, or several adjacent SRTM `.hgt` tiles as one mosaic, applies
/// `opts.crop`, fills voids inside the window and works out the spacing.
pub fn read(paths: &[PathBuf], opts: &ReadOptions) -> Result<HeightGrid, DemError> {
    let (kind, file) = kind_of(paths, opts)?;
    let first = &paths[0];
    let raster = match kind {
        Kind::Hgt => srtm::read(paths, opts)?,
        Kind::Tiff if paths.len() > 1 => {
            let m = tiff_mosaic::layout_for(paths, opts, raster::Reading::Whole)?;
            let samples = m.rows(0, m.height)?;
            Raster {
                width: m.width,
                height: m.height,
                samples,
                georef: m.georef,
                placement: m.placement,
                description: m.description,
            }
        }
        Kind::Tiff => geotiff::read(first, opts)?,
        Kind::Png => picture::read(first, image::ImageFormat::Png, opts)?,
        Kind::Jpeg => picture::read(first, image::ImageFormat::Jpeg, opts)?,
        Kind::Raw(raw_kind) => raw::read(first, raw_kind, opts)?,
    };
    finish(raster, &file, opts)
}

/// The kind of the input and its label for messages, once the options and the mosaic's kinds
/// are checked.
fn kind_of(paths: &[PathBuf], opts: &ReadOptions) -> Result<(Kind, String), DemError> {
    opts.validate()?;
    let Some(first) = paths.first() else {
        return Err(DemError::NoInput);
    };
    let kinds = paths
        .iter()
        .map(|p| Kind::of(p))
        .collect::<Result<Vec<_>, _>>()?;
    let kind = kinds[0];
    if paths.len() > 1 {
        if !matches!(kind, Kind::Hgt | Kind::Tiff) {
            return Err(DemError::Mosaic {
                file: label(first),
                problem: format!(
                    "only SRTM .hgt tiles and GeoTIFFs can be mosaicked, this is {}",
                    kind.name()
                ),
            });
        }
        if let Some((path, k)) = paths.iter().zip(&kinds).find(|(_, k)| **k != kind) {
            return Err(DemError::Mosaic {
                file: label(path),
                problem: format!(
                    "it is {} and {} is {}: a mosaic is of one kind",
                    k.name(),
                    label(first),
                    kind.name()
                ),
            });
        }
    }
    let file = match paths.len() {
        1 => label(first),
        n => format!("{} (+{} more)", label(first), n - 1),
    };
    if opts.size.is_some() && !matches!(kind, Kind::Raw(_)) {
        return Err(DemError::Option {
            file: label(first),
            problem: format!(
                "--size is only for raw .r16/.f32 files; {} has its own size",
                kind.name()
            ),
        });
    }
    if let (Some(e), Kind::Hgt | Kind::Tiff | Kind::Raw(_)) = (opts.encoding, kind) {
        return Err(DemError::Option {
            file: label(first),
            problem: format!("--encoding {e} is for RGB PNG tiles, not {}", kind.name()),
        });
    }
    Ok((kind, file))
}

/// Sample spacings a DEM may have, metres: from a millimetre to a thousand kilometres.
pub const MIN_SPACING: f64 = 1e-3;
pub const MAX_SPACING: f64 = 1e6;

/// Heights a DEM may hold, metres either way: ten times Olympus Mons; beyond is a broken file
/// or an undeclared nodata value (such as -3.4e38).
pub const MAX_HEIGHT: f64 = 250_000.0;

/// The window `opts.crop` keeps of a `full_width` x `full_height` grid: first column, first
/// row, width, height.
fn window(
    file: &str,
    opts: &ReadOptions,
    full_width: usize,
    full_height: usize,
) -> Result<(usize, usize, usize, usize), DemError> {
    Ok(match opts.crop {
        None => (0, 0, full_width, full_height),
        Some(c) => {
            let fits = |start: usize, len: usize, max: usize| {
                start.checked_add(len).is_some_and(|end| end <= max)
            };
            if !(fits(c.x, c.width, full_width) && fits(c.y, c.height, full_height)) {
                return Err(DemError::CropOutside {
                    file: file.to_string(),
                    crop: c,
                    width: full_width,
                    height: full_height,
                });
            }
            (c.x, c.y, c.width, c.height)
        }
    })
}

/// Metres between columns and rows of the window whose rows start at `y0` and number
/// `height`, from `--spacing` or the georeferencing, refused when implausible.
fn spacing(
    file: &str,
    opts: &ReadOptions,
    georef: Georef,
    y0: usize,
    height: usize,
) -> Result<(f64, f64), DemError> {
    let (spacing_x, spacing_y) = match (opts.spacing, georef) {
        (Some(s), _) => (s, s),
        (None, Georef::None) => {
            return Err(DemError::Option {
                file: file.to_string(),
                problem: "the spacing is not in the file: pass --spacing METRES".to_string(),
            })
        }
        (None, Georef::Metres { dx, dy }) => (dx, dy),
        (
            None,
            Georef::Degrees {
                step_lon,
                step_lat,
                lat_row0,
            },
        ) => {
            // At the window's centre row: east-west spacing shrinks with cos(latitude).
            let lat = lat_row0 - step_lat * (y0 as f64 + (height - 1) as f64 / 2.0);
            (
                step_lon * metres_per_degree_lon(lat),
                step_lat * metres_per_degree_lat(lat),
            )
        }
        (
            None,
            Georef::Mercator {
                zoom,
                tile_y,
                tile_width,
                tile_height,
            },
        ) => {
            let t = (tile_y as f64 + (y0 as f64 + height as f64 / 2.0) / tile_height as f64)
                / 2f64.powi(zoom as i32);
            let m = geo::mercator_metres_per_pixel(zoom, tile_width, geo::mercator_latitude(t));
            (m, m)
        }
    };
    let plausible = |s: f64| (MIN_SPACING..=MAX_SPACING).contains(&s);
    if (spacing_x.is_finite() && spacing_y.is_finite() && spacing_x > 0.0 && spacing_y > 0.0)
        && !(plausible(spacing_x) && plausible(spacing_y))
    {
        return Err(DemError::Option {
            file: file.to_string(),
            problem: format!(
                "the spacing works out as {spacing_x:.3e} x {spacing_y:.3e} m, outside {MIN_SPACING}..{MAX_SPACING} m: pass --spacing METRES"
            ),
        });
    }
    if !(spacing_x.is_finite() && spacing_y.is_finite() && spacing_x > 0.0 && spacing_y > 0.0) {
        return Err(DemError::Option {
            file: file.to_string(),
            problem: format!(
                "the spacing works out as {spacing_x} x {spacing_y} m (a pole?): pass --spacing METRES"
            ),
        });
    }
    Ok((spacing_x, spacing_y))
}

/// Crop, spacing, fill: the steps every format shares.
fn finish(raster: Raster, file: &str, opts: &ReadOptions) -> Result<HeightGrid, DemError> {
    let (x0, y0, width, height) = window(file, opts, raster.width, raster.height)?;
    let (spacing_x, spacing_y) = spacing(file, opts, raster.georef, y0, height)?;
    let mut heights = match opts.crop {
        None => raster.samples,
        Some(_) => raster.crop(x0, y0, width, height),
    };
    let voids_filled =
        fill::fill_voids(&mut heights, width, height).ok_or_else(|| DemError::NoValidSamples {
            file: file.to_string(),
            window: opts
                .crop
                .map_or_else(String::new, |c| format!(" in crop {c}")),
        })?;

    if let Some((k, h)) = heights
        .iter()
        .enumerate()
        .find(|(_, h)| !(h.is_finite() && f64::from(h.abs()) <= MAX_HEIGHT))
    {
        return Err(DemError::Malformed {
            file: file.to_string(),
            problem: format!(
                "height {h:.3e} m at column {}, row {} is beyond ±{MAX_HEIGHT} m (an undeclared nodata value?)",
                k % width,
                k / width
            ),
        });
    }

    let mut description = raster.description;
    if let Some(c) = opts.crop {
        description.push_str(&format!(", crop {c}"));
    }
    Ok(HeightGrid {
        width,
        height,
        heights,
        spacing_x,
        spacing_y,
        voids_filled,
        description,
        placement: raster.placement.map(|p| p.window(x0, y0)),
    })
}
