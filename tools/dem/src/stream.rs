//! A DEM opened to be read a band of rows at a time ([`open`], [`Stream::rows`]), so that
//! `tiletool` can build tile sets from grids larger than memory. SRTM tiles and mosaics, raw
//! `.r16`/`.f32` files and GeoTIFFs (the strips or tiles a band touches) are read band by
//! band, straight from the files; PNG and JPEG pictures are decoded whole, as [`crate::read`]
//! does, and served from memory.
//!
//! Opening reads every row once: it checks the samples, finds the range of heights, counts the
//! voids and plans the fill ([`crate::banded`]). A band is then read again with the margin its
//! voids need and filled exactly as the whole grid would be: [`Stream::rows`] equals the same
//! rows of [`crate::read`], bit for bit.

use std::borrow::Cow;
use std::path::PathBuf;

use crate::banded::{Plan, Scanner, STORED};
use crate::placement::Placement;
use crate::raster::Georef;
use crate::{
    geotiff, kind_of, raw, spacing, srtm, tiff_mosaic, window, DemError, Kind, ReadOptions,
    MAX_HEIGHT,
};

/// The formats [`open`] reads band by band (the others are decoded whole).
pub const BAND_FORMATS: &str =
    "SRTM .hgt tiles and mosaics, GeoTIFFs and their mosaics, raw .r16 and .f32";

/// Rows read per step of the opening scan.
const SCAN_ROWS: usize = 256;

/// A DEM ready to be read in bands of rows, with what the whole grid's read would say of it.
#[derive(Debug)]
pub struct Stream {
    pub width: usize,
    pub height: usize,
    pub spacing_x: f64,
    pub spacing_y: f64,
    pub voids_filled: u64,
    pub description: String,
    pub placement: Option<Placement>,
    /// The lowest and highest height of the filled grid (a fill stays within the valid samples
    /// it blends).
    pub min_max: (f32, f32),
    source: Source,
}

#[derive(Debug)]
enum Source {
    /// Decoded and filled whole.
    Whole(Vec<f32>),
    /// Read from the files a band at a time: the window's first column and row in the file's
    /// grid, and the fill's plan.
    Bands {
        rows: Box<Rows>,
        x0: usize,
        y0: usize,
        plan: Plan,
    },
}

#[derive(Debug)]
enum Rows {
    Srtm(srtm::Mosaic),
    Raw(raw::RawRows),
    Tiff(geotiff::GeoTiff),
    TiffMosaic(tiff_mosaic::TiffMosaic),
}

impl Rows {
    fn width(&self) -> usize {
        match self {
            Rows::Srtm(m) => m.width,
            Rows::Raw(r) => r.width,
            Rows::Tiff(t) => t.width,
            Rows::TiffMosaic(m) => m.width,
        }
    }

    fn height(&self) -> usize {
        match self {
            Rows::Srtm(m) => m.height,
            Rows::Raw(r) => r.height,
            Rows::Tiff(t) => t.height,
            Rows::TiffMosaic(m) => m.height,
        }
    }

    /// Rows `y0..y1` of the file's grid, whole width, NaN for voids.
    fn read(&self, y0: usize, y1: usize) -> Result<Vec<f32>, DemError> {
        match self {
            Rows::Srtm(m) => m.rows(y0, y1),
            Rows::Raw(r) => r.rows(y0, y1),
            Rows::Tiff(t) => t.rows(y0, y1),
            Rows::TiffMosaic(m) => m.rows(y0, y1),
        }
    }
}

/// Opens `paths` as [`crate::read`] would read them, reading SRTM and raw inputs one band at a
/// time: the same checks and errors, the same grid, without holding it.
pub fn open(paths: &[PathBuf], opts: &ReadOptions) -> Result<Stream, DemError> {
    let (kind, file) = kind_of(paths, opts)?;
    let (rows, georef, placement, description) = match kind {
        Kind::Hgt => {
            let m = srtm::layout(paths, opts)?;
            let (georef, placement, description) = (m.georef, m.placement, m.description.clone());
            (Rows::Srtm(m), georef, placement, description)
        }
        Kind::Tiff if paths.len() > 1 => {
            let m = tiff_mosaic::layout(paths, opts)?;
            let (georef, placement, description) = (m.georef, m.placement, m.description.clone());
            (Rows::TiffMosaic(m), georef, placement, description)
        }
        Kind::Tiff => {
            let t = geotiff::layout(&paths[0], opts)?;
            let (georef, placement, description) = (t.georef, t.placement, t.description.clone());
            (Rows::Tiff(t), georef, placement, description)
        }
        Kind::Raw(raw_kind) => {
            let r = raw::layout(&paths[0], raw_kind, opts)?;
            let description = r.description.clone();
            (Rows::Raw(r), Georef::None, None, description)
        }
        _ => {
            let grid = crate::read(paths, opts)?;
            let min_max = grid.min_max();
            return Ok(Stream {
                width: grid.width,
                height: grid.height,
                spacing_x: grid.spacing_x,
                spacing_y: grid.spacing_y,
                voids_filled: grid.voids_filled,
                description: grid.description,
                placement: grid.placement,
                min_max,
                source: Source::Whole(grid.heights),
            });
        }
    };
    let (x0, y0, width, height) = window(&file, opts, rows.width(), rows.height())?;
    let (spacing_x, spacing_y) = spacing(&file, opts, georef, y0, height)?;

    // One pass over the window: checks, range, voids, the fill's plan.
    let mut scan = Scanner::new(width, height, STORED);
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    let full_width = rows.width();
    for first in (0..height).step_by(SCAN_ROWS) {
        let n = SCAN_ROWS.min(height - first);
        let band = rows.read(y0 + first, y0 + first + n)?;
        for (r, row) in band.chunks_exact(full_width).enumerate() {
            let row = &row[x0..x0 + width];
            for (x, &h) in row.iter().enumerate() {
                if h.is_nan() {
                    continue;
                }
                // A fill blends valid samples, so checking those checks the filled grid.
                if !(h.is_finite() && f64::from(h.abs()) <= MAX_HEIGHT) {
                    return Err(DemError::Malformed {
                        file,
                        problem: format!(
                            "height {h:.3e} m at column {x}, row {} is beyond ±{MAX_HEIGHT} m (an undeclared nodata value?)",
                            first + r
                        ),
                    });
                }
                lo = lo.min(h);
                hi = hi.max(h);
            }
            scan.row(row);
        }
    }
    let plan = scan.finish().ok_or_else(|| DemError::NoValidSamples {
        file: file.clone(),
        window: opts
            .crop
            .map_or_else(String::new, |c| format!(" in crop {c}")),
    })?;
    let mut description = description;
    if let Some(c) = opts.crop {
        description.push_str(&format!(", crop {c}"));
    }
    Ok(Stream {
        width,
        height,
        spacing_x,
        spacing_y,
        voids_filled: plan.voids,
        description,
        placement: placement.map(|p| p.window(x0, y0)),
        min_max: (lo, hi),
        source: Source::Bands {
            rows: Box::new(rows),
            x0,
            y0,
            plan,
        },
    })
}

impl Stream {
    /// Rows `y0..y1` of the filled grid (`y1 <= height`): the same bits as those rows of
    /// [`crate::read`]'s grid.
    pub fn rows(&self, y0: usize, y1: usize) -> Result<Cow<'_, [f32]>, DemError> {
        assert!(
            y0 <= y1 && y1 <= self.height,
            "rows {y0}..{y1} of {}",
            self.height
        );
        let width = self.width;
        match &self.source {
            Source::Whole(heights) => Ok(Cow::Borrowed(&heights[y0 * width..y1 * width])),
            Source::Bands {
                rows,
                x0,
                y0: top,
                plan,
            } => {
                let full = rows.width();
                let mut read = |a: usize, b: usize| -> Result<Vec<f32>, DemError> {
                    let band = rows.read(top + a, top + b)?;
                    if full == width {
                        return Ok(band);
                    }
                    let mut out = Vec::with_capacity((b - a) * width);
                    for row in band.chunks_exact(full) {
                        out.extend_from_slice(&row[*x0..x0 + width]);
                    }
                    Ok(out)
                };
                plan.fill(y0, y1, &mut read).map(Cow::Owned)
            }
        }
    }

    /// True when the grid is read from its files a band at a time, false when it is held whole.
    pub fn is_banded(&self) -> bool {
        matches!(self.source, Source::Bands { .. })
    }
}
