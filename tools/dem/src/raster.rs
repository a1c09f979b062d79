//! The common shape every reader returns before voids are filled: samples in metres with NaN
//! marking voids, plus what the file said about where it lies. Also the size checks every
//! reader runs on header values before it allocates anything.

use crate::placement::Placement;
use crate::DemError;

/// Largest grid read whole, in samples (8 GiB of f32 heights already): pictures, and any
/// format read into one grid (`dem::read`: the error meter's and `verify --source`'s source).
pub const MAX_SAMPLES: u64 = 1 << 31;

/// Largest grid read a band of rows at a time (`dem::stream`, what `tiletool build` reads),
/// in samples: what is held is a band, so the grid may be far larger than memory (a 65537² grid
/// is 4.3 G samples). 2^36 keeps every row, column and tile count well inside the format's
/// 32-bit fields.
pub const MAX_BANDED_SAMPLES: u64 = 1 << 36;

/// How a grid is to be read: whole, or a band of rows at a time; each has its limit on
/// samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reading {
    Whole,
    Banded,
}

impl Reading {
    /// The most samples a grid read this way may have.
    pub fn limit(self) -> u64 {
        match self {
            Reading::Whole => MAX_SAMPLES,
            Reading::Banded => MAX_BANDED_SAMPLES,
        }
    }
}

/// No lossless codec we read (deflate ~1032:1, LZW ~2700:1 at best) expands a file by more than
/// this; a header claiming more samples than `file length * ratio` can hold is lying.
pub const MAX_COMPRESSION_RATIO: u64 = 4096;

/// Where the grid lies, as far as the file says; turned into spacings after cropping, at the
/// window's centre latitude.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Georef {
    /// The file says nothing: `--spacing` is required.
    None,
    /// Projected grid, spacings in metres.
    Metres { dx: f64, dy: f64 },
    /// Geographic grid: steps in degrees, and the latitude of the centre of row 0.
    Degrees {
        step_lon: f64,
        step_lat: f64,
        lat_row0: f64,
    },
    /// A slippy-map tile `zoom`/`tile_y` (any x) spanning `tile_height` rows of `tile_width`
    /// pixels.
    Mercator {
        zoom: u32,
        tile_y: u64,
        tile_width: usize,
        tile_height: usize,
    },
}

/// A decoded grid before filling. `samples` are metres, row-major, row 0 north; NaN = void.
#[derive(Clone, Debug)]
pub struct Raster {
    pub width: usize,
    pub height: usize,
    pub samples: Vec<f32>,
    pub georef: Georef,
    /// Where the samples lie, when the file says (GeoTIFF tiepoints, SRTM names, web-mercator
    /// tile addresses).
    pub placement: Option<Placement>,
    pub description: String,
}

impl Raster {
    /// The rows `y..y+height` and columns `x..x+width`; the caller has checked they fit.
    pub fn crop(&self, x: usize, y: usize, width: usize, height: usize) -> Vec<f32> {
        let mut out = Vec::with_capacity(width * height);
        for row in self.samples.chunks_exact(self.width).skip(y).take(height) {
            out.extend_from_slice(&row[x..x + width]);
        }
        out
    }
}

/// Refuses dimensions that are zero, beyond the limit of the way the grid is read (see
/// [`Reading`]), or that need more than `max_bytes` of decoded data (what the file can hold),
/// before any buffer is sized from them. Returns the sample count.
pub fn check_dimensions(
    file: &str,
    (width, height): (u64, u64),
    bytes_per_sample: u64,
    max_bytes: u64,
    reading: Reading,
) -> Result<usize, DemError> {
    let too_large = |problem: String| DemError::TooLarge {
        file: file.to_string(),
        width,
        height,
        problem,
    };
    if width == 0 || height == 0 {
        return Err(DemError::Malformed {
            file: file.to_string(),
            problem: format!("header claims an empty {width}x{height} grid"),
        });
    }
    let samples = width.saturating_mul(height);
    let limit = reading.limit();
    if samples > limit {
        return Err(too_large(match reading {
            Reading::Whole => format!(
                "more than the limit of {limit} samples for a grid read whole (`tiletool \
                 build` without a photo texture reads one a band of rows at a time, up to \
                 {MAX_BANDED_SAMPLES})"
            ),
            Reading::Banded => format!("more than the limit of {limit} samples"),
        }));
    }
    let bytes = samples.saturating_mul(bytes_per_sample);
    if bytes > max_bytes {
        return Err(too_large(format!(
            "{bytes} bytes of data, more than a file this size can hold"
        )));
    }
    usize::try_from(samples).map_err(|_| too_large("more than this machine can address".into()))
}
