//! Headerless little-endian grids as game engines and World Machine export them: `.r16`
//! (u16 units, times `--vertical-scale`) and `.f32` (f32 metres). Nothing in the file says its
//! size or spacing, so `--size` and `--spacing` are required, and the length must match the
//! size exactly: a wrong `--size` would otherwise silently shear the terrain.

use std::path::Path;

use crate::error::label;
use crate::raster::{check_dimensions, Georef, Raster};
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
    check_dimensions(&file, width as u64, height as u64, kind.bytes(), actual)?;

    let bytes = std::fs::read(path).map_err(|source| DemError::Io {
        file: file.clone(),
        source,
    })?;
    if bytes.len() as u64 != expected {
        return Err(DemError::Malformed {
            file,
            problem: format!("size changed while reading (now {} bytes)", bytes.len()),
        });
    }
    let scale = opts.vertical_scale();
    let samples = match kind {
        RawKind::U16 => bytes
            .chunks_exact(2)
            .map(|b| (f64::from(u16::from_le_bytes([b[0], b[1]])) * scale) as f32)
            .collect(),
        RawKind::F32 => {
            let mut samples = Vec::with_capacity(width * height);
            for (i, b) in bytes.chunks_exact(4).enumerate() {
                let v = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                // Raw files have no nodata convention: NaN is damage, not a void.
                let scaled = (f64::from(v) * scale) as f32;
                if !scaled.is_finite() {
                    return Err(DemError::BadSample {
                        file,
                        x: i % width,
                        y: i / width,
                        problem: format!("height {v} is not a finite number"),
                    });
                }
                samples.push(scaled);
            }
            samples
        }
    };
    let kind_name = match kind {
        RawKind::U16 => "raw u16 (.r16)",
        RawKind::F32 => "raw f32 (.f32)",
    };
    Ok(Raster {
        width,
        height,
        samples,
        georef: Georef::None,
        placement: None,
        description: format!("{kind_name} {width}x{height}"),
    })
}
