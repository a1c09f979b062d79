//! Headerless little-endian grids as game engines and World Machine export them: `.r16`
//! (u16 units, times `--vertical-scale`) and `.f32` (f32 metres). Nothing in the file says its
//! size or spacing, so `--size` and `--spacing` are required, and the length must match the
//! size exactly: a wrong `--size` would otherwise silently shear the terrain.

use std::path::{Path, PathBuf};

use crate::error::label;
use crate::raster::{check_dimensions, Georef, Raster, Reading};
use crate::{DemError, ReadOptions};

/// Sample type of a raw file, from its extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RawKind {
    U16,
    F32,
}

impl RawKind {
    fn bytes(self) -> u64 {
        match self {
            RawKind::U16 => 2,
            RawKind::F32 => 4,
        }
    }
}

pub fn read(path: &Path, kind: RawKind, opts: &ReadOptions) -> Result<Raster, DemError> {
    let raw = layout_for(path, kind, opts, Reading::Whole)?;
    let samples = raw.rows(0, raw.height)?;
    Ok(Raster {
        width: raw.width,
        height: raw.height,
        samples,
        georef: Georef::None,
        placement: None,
        description: raw.description.clone(),
    })
}

/// A raw file whose length matched its `--size`, read a band of rows at a time.
#[derive(Clone, Debug)]
pub struct RawRows {
    pub width: usize,
    pub height: usize,
    pub description: String,
    path: PathBuf,
    file: String,
    kind: RawKind,
    scale: f64,
}

/// Checks a raw file's size against `--size`, reading nothing, for reading in bands.
pub fn layout(path: &Path, kind: RawKind, opts: &ReadOptions) -> Result<RawRows, DemError> {
    layout_for(path, kind, opts, Reading::Banded)
}

/// [`layout`], for the grid to be read as `reading` says.
fn layout_for(
    path: &Path,
    kind: RawKind,
    opts: &ReadOptions,
    reading: Reading,
) -> Result<RawRows, DemError> {
    let file = label(path);
    let ext = match kind {
        RawKind::U16 => ".r16",
        RawKind::F32 => ".f32",
    };
    let Some((width, height)) = opts.size else {
        return Err(DemError::Option {
            file,
            problem: format!("a raw {ext} file does not say its size: pass --size WxH"),
        });
    };
    let actual = std::fs::metadata(path)
        .map_err(|source| DemError::Io {
            file: file.clone(),
            source,
        })?
        .len();
    if actual == 0 {
        return Err(DemError::Empty { file });
    }
    let expected = (width as u64)
        .saturating_mul(height as u64)
        .saturating_mul(kind.bytes());
    if expected != actual {
        return Err(DemError::WrongSize {
            file,
            width,
            height,
            expected,
            actual,
        });
    }
    // The length matched, so this only enforces the sample limit.
    check_dimensions(
        &file,
        (width as u64, height as u64),
        kind.bytes(),
        actual,
        reading,
    )?;
    let kind_name = match kind {
        RawKind::U16 => "raw u16 (.r16)",
        RawKind::F32 => "raw f32 (.f32)",
    };
    Ok(RawRows {
        width,
        height,
        description: format!("{kind_name} {width}x{height}"),
        path: path.to_path_buf(),
        file,
        kind,
        scale: opts.vertical_scale(),
    })
}

impl RawRows {
    /// Rows `y0..y1`, metres.
    pub fn rows(&self, y0: usize, y1: usize) -> Result<Vec<f32>, DemError> {
        use std::os::unix::fs::FileExt;
        let file = &self.file;
        let io = |source| DemError::Io {
            file: file.clone(),
            source,
        };
        let f = std::fs::File::open(&self.path).map_err(io)?;
        let b = self.kind.bytes() as usize;
        let expected = (self.width * self.height * b) as u64;
        let len = f.metadata().map_err(io)?.len();
        if len != expected {
            return Err(DemError::Malformed {
                file: file.clone(),
                problem: format!("size changed while reading (now {len} bytes)"),
            });
        }
        let mut bytes = vec![0u8; (y1 - y0) * self.width * b];
        f.read_exact_at(&mut bytes, (y0 * self.width * b) as u64)
            .map_err(io)?;
        let scale = self.scale;
        Ok(match self.kind {
            RawKind::U16 => bytes
                .chunks_exact(2)
                .map(|b| (f64::from(u16::from_le_bytes([b[0], b[1]])) * scale) as f32)
                .collect(),
            RawKind::F32 => {
                let mut samples = Vec::with_capacity(bytes.len() / 4);
                for (i, b) in bytes.chunks_exact(4).enumerate() {
                    let v = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                    // Raw files have no nodata convention: NaN is damage, not a void.
                    let scaled = (f64::from(v) * scale) as f32;
                    if !scaled.is_finite() {
                        return Err(DemError::BadSample {
                            file: file.clone(),
                            x: i % self.width,
                            y: y0 + i / self.width,
                            problem: format!("height {v} is not a finite number"),
                        });
                    }
                    samples.push(scaled);
                }
                samples
            }
        })
    }
}
