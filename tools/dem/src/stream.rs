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

use crate::banded::{Plan, Pulled, Scanner, STORED};
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
    match laid_out(paths, opts)? {
        Opened::Whole(stream) => Ok(stream),
        Opened::Banded(layout) => layout.scanned(opts),
    }
}

/// Opens `paths` without reading their rows: for a caller that learnt what the whole grid's
/// read would say from elsewhere (a sharded build's scans, which each read a band:
/// `tiletool build --scan-only`). [`Stream::rows`] then reads the rows as stored, a grid
/// known to hold no void, until [`Stream::with_plan`] gives it the fill's plan. `min_max` is
/// as given. Formats read whole ([`BAND_FORMATS`] are not) are opened as [`open`] does.
pub fn open_unscanned(
    paths: &[PathBuf],
    opts: &ReadOptions,
    min_max: (f32, f32),
) -> Result<Stream, DemError> {
    match laid_out(paths, opts)? {
        Opened::Whole(stream) => Ok(stream),
        Opened::Banded(l) => Ok(Stream {
            width: l.width,
            height: l.height,
            spacing_x: l.spacing_x,
            spacing_y: l.spacing_y,
            voids_filled: 0,
            description: l.description(opts),
            placement: l.placement.map(|p| p.window(l.x0, l.y0)),
            min_max,
            source: Source::Bands {
                plan: Plan::no_voids(l.width, l.height, STORED),
                rows: Box::new(l.rows),
                x0: l.x0,
                y0: l.y0,
            },
        }),
    }
}

/// What a read of some rows finds: their range of heights (voids aside) and their voids,
/// and the fill's share of the pass over the rows asked to be pulled ([`Plan::join`]; `None`
/// for formats read whole).
#[derive(Clone, Debug, PartialEq)]
pub struct RowsScan {
    pub lo: f32,
    pub hi: f32,
    pub voids: u64,
    pub pulled: Option<Pulled>,
}

/// A DEM opened for reading in bands, its rows not yet read.
struct Layout {
    rows: Rows,
    file: String,
    x0: usize,
    y0: usize,
    width: usize,
    height: usize,
    spacing_x: f64,
    spacing_y: f64,
    placement: Option<Placement>,
    description: String,
}

enum Opened {
    /// A picture, decoded whole.
    Whole(Stream),
    Banded(Layout),
}

/// The checks and layout of [`open`], before any row is read.
fn laid_out(paths: &[PathBuf], opts: &ReadOptions) -> Result<Opened, DemError> {
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
            return Ok(Opened::Whole(Stream {
                width: grid.width,
                height: grid.height,
                spacing_x: grid.spacing_x,
                spacing_y: grid.spacing_y,
                voids_filled: grid.voids_filled,
                description: grid.description,
                placement: grid.placement,
                min_max,
                source: Source::Whole(grid.heights),
            }));
        }
    };
    let (x0, y0, width, height) = window(&file, opts, rows.width(), rows.height())?;
    let (spacing_x, spacing_y) = spacing(&file, opts, georef, y0, height)?;
    Ok(Opened::Banded(Layout {
        rows,
        file,
        x0,
        y0,
        width,
        height,
        spacing_x,
        spacing_y,
        placement,
        description,
    }))
}

impl Layout {
    fn description(&self, opts: &ReadOptions) -> String {
        match opts.crop {
            Some(c) => format!("{}, crop {c}", self.description),
            None => self.description.clone(),
        }
    }

    /// Rows `first..first + n` of the window, as stored, checked: every valid height within
    /// ±[`MAX_HEIGHT`]. Each row goes to `each` with its range folded into `range`.
    fn checked_rows(
        &self,
        first: usize,
        n: usize,
        range: &mut (f32, f32),
        each: &mut dyn FnMut(&[f32]),
    ) -> Result<(), DemError> {
        let full_width = self.rows.width();
        let band = self.rows.read(self.y0 + first, self.y0 + first + n)?;
        for (r, row) in band.chunks_exact(full_width).enumerate() {
            let row = &row[self.x0..self.x0 + self.width];
            for (x, &h) in row.iter().enumerate() {
                if h.is_nan() {
                    continue;
                }
                // A fill blends valid samples, so checking those checks the filled grid.
                if !(h.is_finite() && f64::from(h.abs()) <= MAX_HEIGHT) {
                    return Err(DemError::Malformed {
                        file: self.file.clone(),
                        problem: format!(
                            "height {h:.3e} m at column {x}, row {} is beyond ±{MAX_HEIGHT} m (an undeclared nodata value?)",
                            first + r
                        ),
                    });
                }
                range.0 = range.0.min(h);
                range.1 = range.1.max(h);
            }
            each(row);
        }
        Ok(())
    }

    /// [`open`]'s pass over the window: checks, range, voids, the fill's plan.
    fn scanned(self, opts: &ReadOptions) -> Result<Stream, DemError> {
        let mut scan = Scanner::new(self.width, self.height, STORED);
        let mut range = (f32::INFINITY, f32::NEG_INFINITY);
        for first in (0..self.height).step_by(SCAN_ROWS) {
            let n = SCAN_ROWS.min(self.height - first);
            self.checked_rows(first, n, &mut range, &mut |row| scan.row(row))?;
        }
        let plan = scan.finish().ok_or_else(|| DemError::NoValidSamples {
            file: self.file.clone(),
            window: opts
                .crop
                .map_or_else(String::new, |c| format!(" in crop {c}")),
        })?;
        Ok(Stream {
            width: self.width,
            height: self.height,
            spacing_x: self.spacing_x,
            spacing_y: self.spacing_y,
            voids_filled: plan.voids,
            description: self.description(opts),
            placement: self.placement.map(|p| p.window(self.x0, self.y0)),
            min_max: range,
            source: Source::Bands {
                rows: Box::new(self.rows),
                x0: self.x0,
                y0: self.y0,
                plan,
            },
        })
    }
}

/// Rows `rows` of `paths`' grid read and checked as [`open`] checks every row, without
/// reading the others: their range and voids, and the fill's share of the pass over rows
/// `pull` (within `rows`, from a row of the fill's top pulled level, every 64 rows at most, to
/// another or to the grid's end: [`Pulled`]). One
/// shard's share of a scan (`tiletool build --shard K/N --scan-only`); formats read whole are
/// decoded whole.
pub fn scan_rows(
    paths: &[PathBuf],
    opts: &ReadOptions,
    rows: std::ops::Range<usize>,
    pull: std::ops::Range<usize>,
) -> Result<RowsScan, DemError> {
    let mut out = RowsScan {
        lo: f32::INFINITY,
        hi: f32::NEG_INFINITY,
        voids: 0,
        pulled: None,
    };
    match laid_out(paths, opts)? {
        Opened::Whole(stream) => {
            // Decoded and filled whole: its voids are the whole grid's (`voids_filled`), which
            // tells a sharded build that the scans cannot stand for the whole read.
            let heights = stream.rows(rows.start, rows.end.min(stream.height))?;
            for &h in heights.iter() {
                out.lo = out.lo.min(h);
                out.hi = out.hi.max(h);
            }
            out.voids = stream.voids_filled;
        }
        Opened::Banded(l) => {
            let end = rows.end.min(l.height);
            assert!(rows.start <= pull.start && pull.end <= end.max(pull.start));
            let mut range = (f32::INFINITY, f32::NEG_INFINITY);
            let mut voids = 0u64;
            let mut scan = Scanner::new(l.width, l.height, STORED);
            let mut y = rows.start;
            for first in (rows.start..end).step_by(SCAN_ROWS) {
                let n = SCAN_ROWS.min(end - first);
                l.checked_rows(first, n, &mut range, &mut |row| {
                    voids += row.iter().filter(|h| h.is_nan()).count() as u64;
                    if pull.contains(&y) {
                        scan.row(row);
                    }
                    y += 1;
                })?;
            }
            (out.lo, out.hi, out.voids) = (range.0, range.1, voids);
            out.pulled = Some(scan.part(pull.start));
        }
    }
    Ok(out)
}

impl Stream {
    /// This stream (opened by [`open_unscanned`]) filling its rows with `plan` (the shares'
    /// pulled rows joined, [`Plan::join`]) as [`open`]'s stream does. A stream held whole was
    /// filled when it was decoded, and stays as it is.
    pub fn with_plan(mut self, plan: Plan) -> Stream {
        if let Source::Bands { plan: ours, .. } = &mut self.source {
            self.voids_filled = plan.voids;
            *ours = plan;
        }
        self
    }

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

    /// True when a read of a few rows costs about their share of a read of many: the grid held
    /// whole, or read from raw or SRTM files with no void to fill. Then a reader that wants
    /// every `k`-th row (a pyramid layer's) reads those alone. A GeoTIFF decodes whole strips
    /// or tiles, and a fill reads the rows around the ones asked, so they are read in runs.
    pub fn reads_rows_singly(&self) -> bool {
        match &self.source {
            Source::Whole(_) => true,
            Source::Bands { rows, plan, .. } => {
                matches!(**rows, Rows::Raw(_) | Rows::Srtm(_)) && plan.fills_nothing()
            }
        }
    }

    /// True when the grid is read from its files a band at a time, false when it is held whole.
    pub fn is_banded(&self) -> bool {
        matches!(self.source, Source::Bands { .. })
    }
}
