//! Several GeoTIFFs laid side by side by their georeferencing into one grid (`tiletool build
//! dir/*.tif`), as elevation products are distributed: one file per degree or per map sheet.
//! The files must be in one coordinate system with the same sample spacing, on one lattice
//! (each file's first sample a whole number of samples from the others'), and together cover
//! a rectangle. Where files overlap (a shared edge row or column, as SRTM and Copernicus
//! tiles have), a valid sample wins over a void, and of two valid ones the later file's,
//! north to south, then west to east. Rows are read a band at a time, from the files the band
//! touches.

use std::path::PathBuf;

use crate::error::label;
use crate::geotiff::{self, GeoTiff};
use crate::placement::Placement;
use crate::raster::{Georef, Reading};
use crate::{DemError, ReadOptions};

/// How far from a whole number of samples a file's offset may be (rounding in the tags).
const LATTICE_TOLERANCE: f64 = 1e-3;

/// GeoTIFFs laid out as one grid.
#[derive(Clone, Debug)]
pub struct TiffMosaic {
    pub width: usize,
    pub height: usize,
    pub georef: Georef,
    pub placement: Option<Placement>,
    pub description: String,
    /// North to south, then west to east: first column, first row, the file.
    files: Vec<(usize, usize, GeoTiff)>,
}

/// Lays out the GeoTIFFs `paths` as one grid, reading no samples, for reading in bands.
pub fn layout(paths: &[PathBuf], opts: &ReadOptions) -> Result<TiffMosaic, DemError> {
    layout_for(paths, opts, Reading::Banded)
}

/// [`layout`], for the grid to be read as `reading` says.
pub(crate) fn layout_for(
    paths: &[PathBuf],
    opts: &ReadOptions,
    reading: Reading,
) -> Result<TiffMosaic, DemError> {
    let refuse = |path: &PathBuf, problem: String| DemError::Mosaic {
        file: label(path),
        problem,
    };
    let mut files = Vec::with_capacity(paths.len());
    for path in paths {
        let tiff = geotiff::layout(path, opts)?;
        let Some(placement) = tiff.placement else {
            return Err(refuse(
                path,
                "its georeferencing does not say where it lies, so it cannot be placed beside the others".into(),
            ));
        };
        files.push((path, tiff, placement));
    }
    let (first_path, first, base) = (files[0].0, &files[0].1, files[0].2);
    let mut placed = Vec::with_capacity(files.len());
    for (path, tiff, placement) in &files {
        let map = placement
            .in_grid_of(&base)
            .map_err(|e| refuse(path, format!("{e} ({})", label(first_path))))?;
        let same_step = |s: f64| (s - 1.0).abs() <= 1e-9;
        if !(same_step(map.step.0) && same_step(map.step.1)) {
            return Err(refuse(
                path,
                format!(
                    "its samples are {} x {} apart, those of {} {} x {}: resample one onto the other",
                    placement.dx,
                    placement.dy,
                    label(first_path),
                    base.dx,
                    base.dy
                ),
            ));
        }
        let whole = |v: f64| (v - v.round()).abs() <= LATTICE_TOLERANCE;
        if !(whole(map.origin.0) && whole(map.origin.1)) {
            return Err(refuse(
                path,
                format!(
                    "its first sample lies {:.4}, {:.4} samples from that of {}, not a whole number: the grids are not aligned",
                    map.origin.0,
                    map.origin.1,
                    label(first_path)
                ),
            ));
        }
        placed.push((
            map.origin.0.round() as i64,
            map.origin.1.round() as i64,
            tiff.clone(),
            *path,
        ));
    }
    let col_min = placed.iter().map(|p| p.0).min().unwrap_or(0);
    let row_min = placed.iter().map(|p| p.1).min().unwrap_or(0);
    let col_max = placed
        .iter()
        .map(|p| p.0 + p.2.width as i64)
        .max()
        .unwrap_or(0);
    let row_max = placed
        .iter()
        .map(|p| p.1 + p.2.height as i64)
        .max()
        .unwrap_or(0);
    let (width, height) = ((col_max - col_min) as usize, (row_max - row_min) as usize);
    let limit = reading.limit();
    if (width as u64).saturating_mul(height as u64) > limit {
        return Err(refuse(
            first_path,
            format!("together {width}x{height} samples, more than the limit of {limit}"),
        ));
    }
    let mut files: Vec<(usize, usize, GeoTiff, &PathBuf)> = placed
        .into_iter()
        .map(|(c, r, t, p)| ((c - col_min) as usize, (r - row_min) as usize, t, p))
        .collect();
    files.sort_by_key(|f| (f.1, f.0));
    for pair in files.windows(2) {
        if (pair[0].0, pair[0].1) == (pair[1].0, pair[1].1) {
            return Err(refuse(
                pair[1].3,
                format!("it lies where {} lies", label(pair[0].3)),
            ));
        }
    }
    // Every row covered from the first column to the last: a hole would be filled as a void,
    // a made-up surface where a file is missing.
    let mut rows: Vec<usize> = files.iter().flat_map(|f| [f.1, f.1 + f.2.height]).collect();
    rows.push(0);
    rows.sort_unstable();
    rows.dedup();
    for &y in rows.iter().filter(|&&y| y < height) {
        let mut spans: Vec<(usize, usize)> = files
            .iter()
            .filter(|f| (f.1..f.1 + f.2.height).contains(&y))
            .map(|f| (f.0, f.0 + f.2.width))
            .collect();
        spans.sort_unstable();
        let mut reach = 0;
        for (a, b) in spans {
            if a > reach {
                break;
            }
            reach = reach.max(b);
        }
        if reach < width {
            return Err(refuse(
                first_path,
                format!(
                    "the {} files do not cover their {width}x{height} rectangle: nothing at column {reach}, row {y}",
                    files.len()
                ),
            ));
        }
    }
    // Where the first file landed: the mosaic's georeferencing is its, moved there.
    let (c0, r0) = ((-col_min) as usize, (-row_min) as usize);
    let georef = match first.georef {
        Georef::Degrees {
            step_lon,
            step_lat,
            lat_row0,
        } => Georef::Degrees {
            step_lon,
            step_lat,
            lat_row0: lat_row0 + r0 as f64 * step_lat,
        },
        other => other,
    };
    let placement = Placement {
        x0: base.x0 - c0 as f64 * base.dx,
        y0: base.y0 + r0 as f64 * base.dy,
        ..base
    };
    Ok(TiffMosaic {
        width,
        height,
        georef,
        placement: Some(placement),
        description: format!(
            "GeoTIFF mosaic of {} files, {}",
            files.len(),
            first.description
        ),
        files: files.into_iter().map(|(c, r, t, _)| (c, r, t)).collect(),
    })
}

impl TiffMosaic {
    /// Rows `y0..y1` of the mosaic, voids as NaN.
    pub fn rows(&self, y0: usize, y1: usize) -> Result<Vec<f32>, DemError> {
        let width = self.width;
        let mut out = vec![f32::NAN; (y1 - y0) * width];
        for (col, row, tiff) in &self.files {
            let (a, b) = (y0.max(*row), y1.min(row + tiff.height));
            if a >= b {
                continue;
            }
            let rows = tiff.rows(a - row, b - row)?;
            for (r, src) in rows.chunks_exact(tiff.width).enumerate() {
                let dst = &mut out[(a - y0 + r) * width + col..][..tiff.width];
                for (d, &s) in dst.iter_mut().zip(src) {
                    if !s.is_nan() {
                        *d = s;
                    }
                }
            }
        }
        Ok(out)
    }
}
