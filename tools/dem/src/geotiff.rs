//! Single-band GeoTIFF DEMs through the `tiff` crate: integer or float samples, stripped or
//! tiled, uncompressed/LZW/Deflate/PackBits/ZSTD with any predictor it decodes. Voids come from the
//! GDAL_NODATA tag (42113); spacing from ModelPixelScale (33550) + ModelTiepoint (33922) or
//! ModelTransformation (34264), read as degrees or metres per GTModelTypeGeoKey (1024) in the
//! GeoKeyDirectory (34735). Everything else (RGB, multi-band, JPEG-in-TIFF, 1-bit) is refused
//! with one line rather than read as nonsense.

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use tiff::decoder::{ChunkType, Decoder, DecodingResult, Limits};
use tiff::tags::Tag;
use tiff::ColorType;

use crate::error::{label, one_line};
use crate::placement::{Crs, Placement};
use crate::raster::{check_dimensions, Georef, Raster, Reading, MAX_COMPRESSION_RATIO};
use crate::{DemError, ReadOptions};

// GeoKey ids and values from the GeoTIFF 1.1 spec (OGC 19-008r4), section 7.
const GT_MODEL_TYPE: u16 = 1024;
const GT_RASTER_TYPE: u16 = 1025;
const GEOGRAPHIC_TYPE: u16 = 2048;
const GEOG_ANGULAR_UNITS: u16 = 2054;
const PROJECTED_CS_TYPE: u16 = 3072;
const PROJ_LINEAR_UNITS: u16 = 3076;
const VERTICAL_UNITS: u16 = 4099;
const MODEL_PROJECTED: u16 = 1;
const MODEL_GEOGRAPHIC: u16 = 2;
const RASTER_PIXEL_IS_POINT: u16 = 2;

/// Metres per unit for the EPSG linear unit codes DEMs use.
fn linear_unit(code: u16) -> Option<(f64, &'static str)> {
    match code {
        9001 => Some((1.0, "metres")),
        9002 => Some((0.3048, "feet")),
        9003 => Some((1200.0 / 3937.0, "US survey feet")),
        _ => None,
    }
}

/// Compression methods whose decoders the `tiff` crate has built in and that are lossless.
fn compression_name(code: u16) -> Result<&'static str, String> {
    match code {
        1 => Ok("uncompressed"),
        5 => Ok("LZW"),
        8 | 32946 => Ok("Deflate"),
        32773 => Ok("PackBits"),
        6 | 7 => Err("JPEG-compressed TIFF (lossy; heights need lossless compression)".into()),
        50000 => Ok("ZSTD"),
        other => Err(format!("TIFF compression method {other}")),
    }
}

pub fn read(path: &Path, opts: &ReadOptions) -> Result<Raster, DemError> {
    let tiff = layout_for(path, opts, Reading::Whole)?;
    let samples = tiff.rows(0, tiff.height)?;
    Ok(Raster {
        width: tiff.width,
        height: tiff.height,
        samples,
        georef: tiff.georef,
        placement: tiff.placement,
        description: tiff.description,
    })
}

/// A GeoTIFF whose tags, chunk layout and byte counts were checked, read a band of rows at a
/// time by decoding the chunks (strips or tiles) that the band touches.
#[derive(Clone, Debug)]
pub struct GeoTiff {
    pub width: usize,
    pub height: usize,
    pub georef: Georef,
    pub placement: Option<Placement>,
    pub description: String,
    path: PathBuf,
    file: String,
    chunks: ChunkGrid,
    bytes_per_sample: u64,
    /// The decoder's limits: its decoding and intermediate buffers, bytes.
    limits: (usize, usize),
    nodata: Option<f64>,
    scale: f64,
}

/// Reads and checks a GeoTIFF's tags, decoding no samples, for reading in bands.
pub fn layout(path: &Path, opts: &ReadOptions) -> Result<GeoTiff, DemError> {
    layout_for(path, opts, Reading::Banded)
}

/// [`layout`], for the grid to be read as `reading` says.
pub(crate) fn layout_for(
    path: &Path,
    opts: &ReadOptions,
    reading: Reading,
) -> Result<GeoTiff, DemError> {
    let file = label(path);
    let io = |source| DemError::Io {
        file: file.clone(),
        source,
    };
    let handle = File::open(path).map_err(io)?;
    let file_len = handle.metadata().map_err(io)?.len();
    if file_len == 0 {
        return Err(DemError::Empty { file });
    }
    let malformed = |e: tiff::TiffError| DemError::Malformed {
        file: file.clone(),
        problem: format!("not a readable TIFF: {}", one_line(e)),
    };
    let unsupported = |what: String| DemError::Unsupported {
        file: file.clone(),
        problem: format!("{what}; expected one band of integer or float heights"),
    };

    let mut decoder = Decoder::new(BufReader::new(handle)).map_err(malformed)?;
    let (width, height) = decoder.dimensions().map_err(malformed)?;

    // What kind of samples, before decoding anything.
    let tag_u16 = |decoder: &mut Decoder<_>, tag, default| -> Result<u16, DemError> {
        Ok(decoder
            .find_tag_unsigned::<u16>(tag)
            .map_err(malformed)?
            .unwrap_or(default))
    };
    let compression = tag_u16(&mut decoder, Tag::Compression, 1)?;
    let compression = compression_name(compression).map_err(|what| DemError::Unsupported {
        file: file.clone(),
        problem: what,
    })?;
    let photometric = tag_u16(&mut decoder, Tag::PhotometricInterpretation, 1)?;
    let bits = match decoder.colortype() {
        Ok(ColorType::Gray(bits)) if photometric == 1 => bits,
        Ok(ColorType::Gray(_)) => {
            return Err(unsupported(
                "WhiteIsZero TIFF (inverted grey is a picture, not a DEM)".into(),
            ))
        }
        Ok(ColorType::Multiband { num_samples, .. }) => {
            return Err(unsupported(format!(
                "TIFF with {num_samples} samples per pixel"
            )))
        }
        Ok(other) => return Err(unsupported(format!("{other:?} TIFF"))),
        Err(e) => return Err(unsupported(format!("TIFF layout ({})", one_line(e)))),
    };
    // One value per sample; with one sample per pixel (checked above) the first is it.
    let sample_format = decoder
        .find_tag_unsigned_vec::<u16>(Tag::SampleFormat)
        .map_err(malformed)?
        .and_then(|v| v.first().copied())
        .unwrap_or(1);
    let sample_type = match (sample_format, bits) {
        (1, 8 | 16 | 32 | 64) => format!("u{bits}"),
        (2, 8 | 16 | 32 | 64) => format!("i{bits}"),
        (3, 16 | 32 | 64) => format!("f{bits}"),
        (1..=3, _) => return Err(unsupported(format!("{bits}-bit TIFF samples"))),
        (other, _) => return Err(unsupported(format!("TIFF sample format {other}"))),
    };

    let bytes_per_sample = u64::from(bits / 8);
    let max_bytes = if compression == "uncompressed" {
        file_len
    } else {
        file_len.saturating_mul(MAX_COMPRESSION_RATIO)
    };
    check_dimensions(
        &file,
        (width.into(), height.into()),
        bytes_per_sample,
        max_bytes,
        reading,
    )?;
    let chunks = chunk_grid(&mut decoder, width, height).map_err(|e| match e {
        ChunkError::Tiff(e) => malformed(e),
        ChunkError::Bad(problem) => DemError::Malformed {
            file: file.clone(),
            problem,
        },
    })?;
    let layout = if chunks.tiled {
        format!("tiled {}x{}", chunks.width, chunks.height)
    } else {
        "stripped".to_string()
    };

    let nodata = match decoder.find_tag(Tag::GdalNodata).map_err(malformed)? {
        None => None,
        Some(value) => {
            let text = value.into_string().map_err(malformed)?;
            Some(parse_nodata(&text).ok_or_else(|| DemError::Malformed {
                file: file.clone(),
                problem: format!("GDAL_NODATA tag {text:?} is not a number"),
            })?)
        }
    };
    let keys = geo_keys(&mut decoder).map_err(malformed)?;
    let vertical = match keys.get(VERTICAL_UNITS).and_then(linear_unit) {
        Some((factor, _)) => factor,
        None => 1.0, // absent or unknown: heights are taken as metres
    };
    // Where it lies matters only for laying a photo over it; a file that cannot say is still
    // a DEM (its spacing problems, if any, are reported next).
    let placement = placement_of(&mut decoder, &keys).ok().flatten();
    let (georef, georef_text) = if opts.spacing.is_some() {
        // The user's spacing wins; don't fail on georeferencing we would not use.
        (Georef::None, "spacing from --spacing".to_string())
    } else {
        georef(&mut decoder, &keys).map_err(|e| match e {
            GeorefError::Tiff(e) => malformed(e),
            GeorefError::Unsupported(what) => DemError::Unsupported {
                file: file.clone(),
                problem: format!("{what}: pass --spacing"),
            },
            GeorefError::Missing(what) => DemError::Option {
                file: file.clone(),
                problem: format!("{what}: pass --spacing METRES"),
            },
        })?
    };

    // One chunk at a time, so the only whole-grid buffer is the f32 output. A chunk is stored
    // whole (padding included), so the same file-size bound holds for it.
    let chunk_bytes = u64::from(chunks.width)
        .saturating_mul(u64::from(chunks.height))
        .saturating_mul(bytes_per_sample);
    if chunk_bytes > max_bytes {
        return Err(DemError::TooLarge {
            file,
            width: chunks.width.into(),
            height: chunks.height.into(),
            problem: format!("in each chunk, {chunk_bytes} bytes, more than this file can hold"),
        });
    }
    let mut limits = Limits::default();
    limits.decoding_buffer_size = usize::try_from(chunk_bytes)
        .unwrap_or(usize::MAX)
        .saturating_add(1 << 20);
    limits.intermediate_buffer_size = limits
        .intermediate_buffer_size
        .max(usize::try_from(file_len).unwrap_or(usize::MAX));
    check_byte_counts(
        &mut decoder,
        &chunks,
        compression == "uncompressed",
        bytes_per_sample,
        (width, height),
        file_len,
    )
    .map_err(|e| match e {
        ChunkError::Tiff(e) => malformed(e),
        ChunkError::Bad(problem) => DemError::Malformed {
            file: file.clone(),
            problem,
        },
    })?;
    let nodata_text = match nodata {
        Some(n) => format!(", nodata {n}"),
        None => String::new(),
    };
    Ok(GeoTiff {
        width: width as usize,
        height: height as usize,
        georef,
        placement,
        description: format!(
            "GeoTIFF {sample_type} {compression}, {layout}, {georef_text}{nodata_text}"
        ),
        path: path.to_path_buf(),
        file,
        chunks,
        bytes_per_sample,
        limits: (limits.decoding_buffer_size, limits.intermediate_buffer_size),
        nodata,
        scale: opts.vertical_scale() * vertical,
    })
}

impl GeoTiff {
    /// Rows `y0..y1`, metres, voids as NaN: the chunks that hold them decoded one at a time.
    pub fn rows(&self, y0: usize, y1: usize) -> Result<Vec<f32>, DemError> {
        let file = &self.file;
        let malformed = |e: tiff::TiffError| DemError::Malformed {
            file: file.clone(),
            problem: format!("not a readable TIFF: {}", one_line(e)),
        };
        let handle = File::open(&self.path).map_err(|source| DemError::Io {
            file: file.clone(),
            source,
        })?;
        let mut limits = Limits::default();
        (limits.decoding_buffer_size, limits.intermediate_buffer_size) = self.limits;
        let mut decoder = Decoder::new(BufReader::new(handle))
            .map_err(malformed)?
            .with_limits(limits);
        // The file may have changed since its tags were read.
        if decoder.dimensions().map_err(malformed)? != (self.width as u32, self.height as u32) {
            return Err(DemError::Malformed {
                file: file.clone(),
                problem: "size changed while reading".into(),
            });
        }
        let mut converter = Converter {
            file,
            nodata: self.nodata,
            scale: self.scale,
            width: self.width,
            first_row: y0,
            out: vec![f32::NAN; (y1 - y0) * self.width],
        };
        let chunks = &self.chunks;
        let mut buffer = DecodingResult::U8(Vec::new());
        for index in 0..chunks.count {
            let (x0, cy, w, h) = chunks.rect(index, self.width as u32, self.height as u32);
            if cy + h <= y0 || cy >= y1 {
                continue;
            }
            // Read each chunk at its full stored width: the tiff crate's row-by-row path for
            // narrower edge tiles can fail on valid LZW data ("no lzw end code found").
            let stride = chunks.width as usize;
            decoder
                .read_chunk_to_buffer(&mut buffer, index, stride * self.bytes_per_sample as usize)
                .map_err(malformed)?;
            let window = Window {
                x0,
                y0: cy,
                width: w,
                height: h,
                stride,
            };
            match &buffer {
                DecodingResult::U8(v) => converter.ints(v, &window, f64::from),
                DecodingResult::U16(v) => converter.ints(v, &window, f64::from),
                DecodingResult::U32(v) => converter.ints(v, &window, f64::from),
                DecodingResult::U64(v) => converter.ints(v, &window, |x| x as f64),
                DecodingResult::I8(v) => converter.ints(v, &window, f64::from),
                DecodingResult::I16(v) => converter.ints(v, &window, f64::from),
                DecodingResult::I32(v) => converter.ints(v, &window, f64::from),
                DecodingResult::I64(v) => converter.ints(v, &window, |x| x as f64),
                DecodingResult::F16(v) => converter.floats(v, &window, |x| f64::from(f32::from(x))),
                DecodingResult::F32(v) => converter.floats(v, &window, f64::from),
                DecodingResult::F64(v) => converter.floats(v, &window, |x| x),
            }?;
        }
        Ok(converter.out)
    }
}

/// `-32768`, `3.4e38`, `nan` (GDAL writes NaN nodata in several spellings).
fn parse_nodata(text: &str) -> Option<f64> {
    let t = text.trim_matches(|c: char| c == '\0' || c.is_whitespace());
    if t.trim_start_matches(['-', '+']).eq_ignore_ascii_case("nan") {
        return Some(f64::NAN);
    }
    t.parse().ok()
}

/// How the image is cut into chunks (strips are chunks as wide as the image).
#[derive(Clone, Debug)]
struct ChunkGrid {
    tiled: bool,
    width: u32,
    height: u32,
    across: u32,
    count: u32,
}

impl ChunkGrid {
    /// Image rectangle `(x0, y0, width, height)` of chunk `index`, edge padding excluded.
    fn rect(&self, index: u32, width: u32, height: u32) -> (usize, usize, usize, usize) {
        let x0 = (index % self.across) * self.width;
        let y0 = (index / self.across) * self.height;
        (
            x0 as usize,
            y0 as usize,
            self.width.min(width - x0) as usize,
            self.height.min(height - y0) as usize,
        )
    }
}

enum ChunkError {
    Tiff(tiff::TiffError),
    Bad(String),
}

impl From<tiff::TiffError> for ChunkError {
    fn from(e: tiff::TiffError) -> Self {
        ChunkError::Tiff(e)
    }
}

/// The chunk layout from the tags, checked against the number of chunks the file lists, so
/// that no chunk index or rectangle can fall outside the image.
fn chunk_grid<R: std::io::Read + std::io::Seek>(
    decoder: &mut Decoder<R>,
    width: u32,
    height: u32,
) -> Result<ChunkGrid, ChunkError> {
    let tiled = decoder.get_chunk_type() == ChunkType::Tile;
    let (cw, ch, count) = if tiled {
        let tw = decoder
            .find_tag_unsigned::<u32>(Tag::TileWidth)?
            .unwrap_or(0);
        let th = decoder
            .find_tag_unsigned::<u32>(Tag::TileLength)?
            .unwrap_or(0);
        (tw, th, decoder.tile_count()?)
    } else {
        let rows = decoder
            .find_tag_unsigned::<u32>(Tag::RowsPerStrip)?
            .unwrap_or(u32::MAX)
            .min(height);
        (width, rows, decoder.strip_count()?)
    };
    if cw == 0 || ch == 0 {
        return Err(ChunkError::Bad(format!("TIFF chunk size {cw}x{ch}")));
    }
    let across = width.div_ceil(cw);
    let expected = u64::from(across) * u64::from(height.div_ceil(ch));
    if u64::from(count) != expected {
        return Err(ChunkError::Bad(format!(
            "TIFF lists {count} chunks, a {width}x{height} image in {cw}x{ch} chunks needs {expected}"
        )));
    }
    Ok(ChunkGrid {
        tiled,
        width: cw,
        height: ch,
        across,
        count,
    })
}

/// Every chunk's stored bytes lie in the file and hold data: no byte count of 0, none running
/// past the end, and uncompressed chunks as long as their samples need (a decoder would
/// otherwise read past the declared count, into whatever follows).
fn check_byte_counts<R: std::io::Read + std::io::Seek>(
    decoder: &mut Decoder<R>,
    chunks: &ChunkGrid,
    uncompressed: bool,
    bytes_per_sample: u64,
    (width, height): (u32, u32),
    file_len: u64,
) -> Result<(), ChunkError> {
    let (offsets_tag, counts_tag) = if chunks.tiled {
        (Tag::TileOffsets, Tag::TileByteCounts)
    } else {
        (Tag::StripOffsets, Tag::StripByteCounts)
    };
    let offsets = decoder
        .find_tag_unsigned_vec::<u64>(offsets_tag)?
        .unwrap_or_default();
    let counts = decoder
        .find_tag_unsigned_vec::<u64>(counts_tag)?
        .unwrap_or_default();
    if offsets.len() != chunks.count as usize || counts.len() != chunks.count as usize {
        return Err(ChunkError::Bad(format!(
            "TIFF lists {} chunk offsets and {} byte counts for {} chunks",
            offsets.len(),
            counts.len(),
            chunks.count
        )));
    }
    for (k, (&offset, &count)) in offsets.iter().zip(&counts).enumerate() {
        if count == 0 {
            return Err(ChunkError::Bad(format!(
                "TIFF chunk {k} has a byte count of 0"
            )));
        }
        if offset.checked_add(count).is_none_or(|end| end > file_len) {
            return Err(ChunkError::Bad(format!(
                "TIFF chunk {k} ({count} bytes at {offset}) runs past the end of the file"
            )));
        }
        if uncompressed {
            // Tiles are stored whole; a strip holds its rows (the last one fewer).
            let (_, _, w, h) = chunks.rect(k as u32, width, height);
            let rows = if chunks.tiled {
                chunks.height as u64
            } else {
                h as u64
            };
            let cols = if chunks.tiled {
                chunks.width as u64
            } else {
                w as u64
            };
            let needed = rows * cols * bytes_per_sample;
            if count < needed {
                return Err(ChunkError::Bad(format!(
                    "TIFF chunk {k} declares {count} bytes, its samples need {needed}"
                )));
            }
        }
    }
    Ok(())
}

/// Where a decoded chunk goes: its image rectangle and its row stride in samples.
struct Window {
    x0: usize,
    y0: usize,
    width: usize,
    height: usize,
    stride: usize,
}

/// Turns decoded samples into metres, voids into NaN, placing chunks in the output grid.
struct Converter<'a> {
    file: &'a str,
    nodata: Option<f64>,
    scale: f64,
    width: usize,
    /// `out` holds rows `first_row..`; a chunk's rows outside them are skipped.
    first_row: usize,
    out: Vec<f32>,
}

impl Converter<'_> {
    /// The chunk's rows of real samples, or an error if the decoder returned too few.
    fn rows<'d, T>(
        &self,
        data: &'d [T],
        w: &Window,
    ) -> Result<impl Iterator<Item = (usize, &'d [T])> + 'd, DemError> {
        let needed = (w.height.saturating_sub(1)) * w.stride + w.width;
        if data.len() < needed || w.width > w.stride {
            return Err(DemError::Malformed {
                file: self.file.to_string(),
                problem: format!(
                    "TIFF chunk at {},{} decoded to {} samples, {needed} expected",
                    w.x0,
                    w.y0,
                    data.len()
                ),
            });
        }
        let (y0, width, height, stride) = (w.y0, w.width, w.height, w.stride);
        let (first, end) = (self.first_row, self.first_row + self.out.len() / self.width);
        Ok((0..height)
            .map(move |r| (y0 + r, &data[r * stride..][..width]))
            .filter(move |(y, _)| (first..end).contains(y)))
    }

    fn ints<T: Copy>(
        &mut self,
        data: &[T],
        w: &Window,
        to_f64: impl Fn(T) -> f64,
    ) -> Result<(), DemError> {
        // A NaN or fractional nodata matches no integer: no voids.
        let nodata = self.nodata.unwrap_or(f64::NAN);
        for (y, row) in self.rows(data, w)? {
            let out = &mut self.out[(y - self.first_row) * self.width + w.x0..][..w.width];
            for (o, &x) in out.iter_mut().zip(row) {
                let v = to_f64(x);
                *o = if v == nodata {
                    f32::NAN
                } else {
                    (v * self.scale) as f32
                };
            }
        }
        Ok(())
    }

    fn floats<T: Copy>(
        &mut self,
        data: &[T],
        w: &Window,
        to_f64: impl Fn(T) -> f64,
    ) -> Result<(), DemError> {
        // Compare in the file's own precision: GDAL writes f32 nodata as a decimal that only
        // equals the samples after rounding to f32.
        let nodata = self.nodata.map(|n| f64::from(n as f32));
        let nan_is_void = nodata.is_some_and(f64::is_nan);
        for (y, row) in self.rows(data, w)? {
            let start = (y - self.first_row) * self.width + w.x0;
            for (c, &x) in row.iter().enumerate() {
                let v = to_f64(x);
                let h = if (v.is_nan() && nan_is_void) || Some(v) == nodata {
                    f32::NAN
                } else {
                    let h = (v * self.scale) as f32;
                    if !h.is_finite() {
                        return Err(DemError::BadSample {
                            file: self.file.to_string(),
                            x: w.x0 + c,
                            y,
                            problem: format!(
                                "height {v} is not a finite number (and the nodata value is {})",
                                self.nodata
                                    .map_or_else(|| "not set".to_string(), |n| n.to_string())
                            ),
                        });
                    }
                    h
                };
                self.out[start + c] = h;
            }
        }
        Ok(())
    }
}

/// The GeoKeyDirectory's short-valued keys (the only ones we read).
struct GeoKeys(Vec<(u16, u16)>);

impl GeoKeys {
    fn get(&self, key: u16) -> Option<u16> {
        self.0.iter().find(|(k, _)| *k == key).map(|&(_, v)| v)
    }
}

fn geo_keys<R: std::io::Read + std::io::Seek>(
    decoder: &mut Decoder<R>,
) -> tiff::TiffResult<GeoKeys> {
    let Some(value) = decoder.find_tag(Tag::GeoKeyDirectoryTag)? else {
        return Ok(GeoKeys(Vec::new()));
    };
    let dir = value.into_u16_vec()?;
    // Header: version, revision, minor revision, number of keys; then 4 shorts per key:
    // id, tag holding the value (0 = the value is the 4th short), count, value.
    let count = dir.get(3).copied().unwrap_or(0) as usize;
    let keys = dir
        .get(4..)
        .unwrap_or(&[])
        .chunks_exact(4)
        .take(count)
        .filter(|e| e[1] == 0)
        .map(|e| (e[0], e[3]))
        .collect();
    Ok(GeoKeys(keys))
}

enum GeorefError {
    Tiff(tiff::TiffError),
    Unsupported(String),
    Missing(String),
}

impl From<tiff::TiffError> for GeorefError {
    fn from(e: tiff::TiffError) -> Self {
        GeorefError::Tiff(e)
    }
}

fn f64_tag<R: std::io::Read + std::io::Seek>(
    decoder: &mut Decoder<R>,
    tag: Tag,
) -> tiff::TiffResult<Option<Vec<f64>>> {
    decoder.find_tag(tag)?.map(|v| v.into_f64_vec()).transpose()
}

/// What the georeferencing tags say: the size of a pixel in model units, and one raster point
/// `(i, j)` with its model position `(x, y)` when the file gives one.
struct ModelFrame {
    sx: f64,
    sy: f64,
    origin: Option<(f64, f64, f64, f64)>,
}

/// The georeferencing tags, `None` when the file has none.
fn model_frame<R: std::io::Read + std::io::Seek>(
    decoder: &mut Decoder<R>,
) -> Result<Option<ModelFrame>, GeorefError> {
    let scale = f64_tag(decoder, Tag::ModelPixelScaleTag)?;
    let tiepoint = f64_tag(decoder, Tag::ModelTiepointTag)?;
    let transform = f64_tag(decoder, Tag::ModelTransformationTag)?;
    let (sx, sy, origin) = match (scale, tiepoint, transform) {
        (Some(s), t, _) if s.len() >= 2 => {
            let origin = t.filter(|t| t.len() >= 6).map(|t| (t[0], t[1], t[3], t[4]));
            (s[0].abs(), s[1].abs(), origin)
        }
        (_, _, Some(m)) if m.len() >= 16 => {
            if m[1] != 0.0 || m[4] != 0.0 {
                return Err(GeorefError::Unsupported(
                    "rotated or sheared ModelTransformation".into(),
                ));
            }
            (m[0].abs(), m[5].abs(), Some((0.0, 0.0, m[3], m[7])))
        }
        _ => return Ok(None),
    };
    let finite = |v: f64| v.is_finite();
    if !(finite(sx) && finite(sy) && sx > 0.0 && sy > 0.0) {
        return Err(GeorefError::Unsupported(format!("pixel scale {sx} x {sy}")));
    }
    if let Some((i, j, x, y)) = origin {
        if ![i, j, x, y].into_iter().all(finite) {
            return Err(GeorefError::Unsupported(format!(
                "tiepoint ({i}, {j}) -> ({x}, {y})"
            )));
        }
    }
    Ok(Some(ModelFrame { sx, sy, origin }))
}

/// Degrees per unit of the file's geographic angular unit.
fn angular_unit(keys: &GeoKeys) -> Result<f64, GeorefError> {
    match keys.get(GEOG_ANGULAR_UNITS).unwrap_or(9102) {
        9102 => Ok(1.0),
        9101 => Ok(180.0 / std::f64::consts::PI),
        9105 => Ok(0.9), // grad
        other => Err(GeorefError::Unsupported(format!(
            "geographic angular unit code {other}"
        ))),
    }
}

/// Metres per unit of the file's projected linear unit, and its name.
fn projected_unit(keys: &GeoKeys) -> Result<(f64, &'static str), GeorefError> {
    let unit = keys.get(PROJ_LINEAR_UNITS).unwrap_or(9001);
    linear_unit(unit)
        .ok_or_else(|| GeorefError::Unsupported(format!("projected linear unit code {unit}")))
}

/// Where the centre of pixel (0, 0) lies in raster space: (0.5, 0.5) with PixelIsArea (the
/// default: raster point (0, 0) is the first pixel's corner), (0, 0) with PixelIsPoint.
fn first_centre(keys: &GeoKeys) -> f64 {
    if keys.get(GT_RASTER_TYPE) == Some(RASTER_PIXEL_IS_POINT) {
        0.0
    } else {
        0.5
    }
}

/// An EPSG code from a GeoKey, none for "user-defined" (32767) or absent.
fn epsg(keys: &GeoKeys, key: u16) -> Option<u16> {
    keys.get(key).filter(|&c| c != 0 && c != 32767)
}

/// The file's [`Placement`], `None` when it has no georeferencing tags at all; an error when
/// it has some that cannot place it (no tiepoint, unknown model type or unit).
fn placement_of<R: std::io::Read + std::io::Seek>(
    decoder: &mut Decoder<R>,
    keys: &GeoKeys,
) -> Result<Option<Placement>, GeorefError> {
    let Some(frame) = model_frame(decoder)? else {
        return Ok(None);
    };
    let Some((i, j, x, y)) = frame.origin else {
        return Err(GeorefError::Missing(
            "no tiepoint: where it lies is unknown".into(),
        ));
    };
    let (crs, factor) = match keys.get(GT_MODEL_TYPE) {
        Some(MODEL_PROJECTED) => (
            Crs::Projected {
                code: epsg(keys, PROJECTED_CS_TYPE),
            },
            projected_unit(keys)?.0,
        ),
        Some(MODEL_GEOGRAPHIC) => (
            Crs::Geographic {
                code: epsg(keys, GEOGRAPHIC_TYPE),
            },
            angular_unit(keys)?,
        ),
        Some(other) => {
            return Err(GeorefError::Unsupported(format!(
                "GeoTIFF model type {other} (neither projected nor geographic)"
            )))
        }
        None => {
            return Err(GeorefError::Missing(
                "pixel scale without GTModelTypeGeoKey: degrees or metres is unknown".into(),
            ))
        }
    };
    let c = first_centre(keys);
    Ok(Some(Placement {
        crs,
        x0: (x + (c - i) * frame.sx) * factor,
        y0: (y - (c - j) * frame.sy) * factor,
        dx: frame.sx * factor,
        dy: frame.sy * factor,
    }))
}

/// The placement of a GeoTIFF that is not a DEM (a photo to drape over one): `None` when it
/// has no georeferencing tags, an error naming the file when it has tags that cannot place it.
pub fn read_placement(path: &Path) -> Result<Option<Placement>, DemError> {
    let file = label(path);
    let handle = File::open(path).map_err(|source| DemError::Io {
        file: file.clone(),
        source,
    })?;
    let malformed = |e: tiff::TiffError| DemError::Malformed {
        file: file.clone(),
        problem: format!("not a readable TIFF: {}", one_line(e)),
    };
    let mut decoder = Decoder::new(BufReader::new(handle)).map_err(malformed)?;
    let keys = geo_keys(&mut decoder).map_err(malformed)?;
    placement_of(&mut decoder, &keys).map_err(|e| match e {
        GeorefError::Tiff(e) => malformed(e),
        GeorefError::Unsupported(what) => DemError::Unsupported {
            file: file.clone(),
            problem: format!("georeferencing: {what}"),
        },
        GeorefError::Missing(what) => DemError::Malformed {
            file: file.clone(),
            problem: format!("georeferencing: {what}"),
        },
    })
}

/// Spacing (or what is needed to work it out after cropping) and a few words for the
/// description.
fn georef<R: std::io::Read + std::io::Seek>(
    decoder: &mut Decoder<R>,
    keys: &GeoKeys,
) -> Result<(Georef, String), GeorefError> {
    let Some(ModelFrame { sx, sy, origin }) = model_frame(decoder)? else {
        return Err(GeorefError::Missing(
            "no georeferencing (ModelPixelScale/ModelTransformation), so no spacing".into(),
        ));
    };
    match keys.get(GT_MODEL_TYPE) {
        Some(MODEL_PROJECTED) => {
            let (factor, name) = projected_unit(keys)?;
            Ok((
                Georef::Metres {
                    dx: sx * factor,
                    dy: sy * factor,
                },
                format!("projected ({name})"),
            ))
        }
        Some(MODEL_GEOGRAPHIC) => {
            let to_degrees = angular_unit(keys)?;
            let Some((_i, j, _x, y)) = origin else {
                return Err(GeorefError::Missing(
                    "geographic TIFF without a tiepoint: its latitude is unknown".into(),
                ));
            };
            let step_lat = sy * to_degrees;
            let lat_row0 = (y - (first_centre(keys) - j) * sy) * to_degrees;
            if !(-90.0..=90.0).contains(&lat_row0) {
                return Err(GeorefError::Unsupported(format!(
                    "geographic tiepoint latitude {lat_row0}"
                )));
            }
            Ok((
                Georef::Degrees {
                    step_lon: sx * to_degrees,
                    step_lat,
                    lat_row0,
                },
                "geographic".to_string(),
            ))
        }
        Some(other) => Err(GeorefError::Unsupported(format!(
            "GeoTIFF model type {other} (neither projected nor geographic)"
        ))),
        None => Err(GeorefError::Missing(
            "pixel scale without GTModelTypeGeoKey: degrees or metres is unknown".into(),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nodata_spellings() {
        assert_eq!(parse_nodata("-32768"), Some(-32768.0));
        assert_eq!(parse_nodata(" 32767\0"), Some(32767.0));
        assert!(parse_nodata("nan").is_some_and(f64::is_nan));
        assert!(parse_nodata("-NaN").is_some_and(f64::is_nan));
        assert_eq!(
            parse_nodata("-3.4028234663852886e+38"),
            Some(-3.402_823_466_385_288_6e38)
        );
        assert_eq!(parse_nodata("none"), None);
    }
}
