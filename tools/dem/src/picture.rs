//! Heights stored as pictures: greyscale PNG (8/16-bit) and JPEG, whose values are heights in
//! some unit (`--vertical-scale`), and RGB(A) PNG tiles that pack metres into colour channels
//! (Mapbox Terrain-RGB, Terrarium; `--encoding`). Where a grey or alpha channel is present,
//! alpha 0 marks a void. Spacing is never in the file, except in a slippy-map tile's name.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use image::{DynamicImage, ImageDecoder, ImageFormat, ImageReader, Limits};

use crate::error::{label, one_line};
use crate::geo::{self, tile_address};
use crate::placement::Placement;
use crate::raster::{check_dimensions, Georef, Raster, Reading, MAX_COMPRESSION_RATIO};
use crate::{DemError, Encoding, ReadOptions};

/// JPEG decoders turn a grey picture saved as YCbCr into RGB with small chroma noise; more than
/// this much difference between channels (on average) means the picture really has colour.
const GREY_TOLERANCE: f64 = 2.0;

pub fn read(path: &Path, format: ImageFormat, opts: &ReadOptions) -> Result<Raster, DemError> {
    let file = label(path);
    let kind = if format == ImageFormat::Jpeg {
        "JPEG"
    } else {
        "PNG"
    };
    let io = |source| DemError::Io {
        file: file.clone(),
        source,
    };
    let handle = File::open(path).map_err(io)?;
    let file_len = handle.metadata().map_err(io)?.len();
    if file_len == 0 {
        return Err(DemError::Empty { file });
    }
    let malformed = |e: image::ImageError| DemError::Malformed {
        file: file.clone(),
        problem: format!("not a readable {kind}: {}", one_line(e)),
    };

    if format == ImageFormat::Jpeg {
        check_jpeg_ends(&file, &handle, file_len)?;
    }

    let mut reader = ImageReader::with_format(BufReader::new(handle), format);
    // Only the header is read until `from_decoder`; the real limit is set once we know the size.
    reader.limits(limits(64 << 20));
    let mut decoder = reader.into_decoder().map_err(malformed)?;
    let (width, height) = decoder.dimensions();
    let bytes_per_pixel = u64::from(decoder.color_type().bytes_per_pixel());
    let max_bytes = file_len.saturating_mul(MAX_COMPRESSION_RATIO);
    let pixels = check_dimensions(
        &file,
        (width.into(), height.into()),
        bytes_per_pixel,
        max_bytes,
        Reading::Whole,
    )?;
    let needed = pixels as u64 * bytes_per_pixel;
    // Room for the picture plus the decoder's own row buffers.
    decoder
        .set_limits(limits(needed.saturating_mul(2).saturating_add(64 << 20)))
        .map_err(malformed)?;
    let image = DynamicImage::from_decoder(decoder).map_err(malformed)?;
    let (width, height) = (width as usize, height as usize);
    let scale = opts.vertical_scale();

    let unsupported = |what: &str| DemError::Unsupported {
        file: file.clone(),
        problem: format!("{kind}: {what}; expected 8/16-bit grey, or RGB(A) with --encoding"),
    };
    let grey_with_encoding = |encoding: Encoding| DemError::Option {
        file: file.clone(),
        problem: format!("--encoding {encoding} is for RGB pictures, but this {kind} is grey"),
    };
    let (samples, what, georef) = match (&image, opts.encoding) {
        (DynamicImage::ImageLuma8(_) | DynamicImage::ImageLuma16(_), Some(e))
        | (DynamicImage::ImageLumaA8(_) | DynamicImage::ImageLumaA16(_), Some(e)) => {
            return Err(grey_with_encoding(e))
        }
        (DynamicImage::ImageLuma8(img), None) => (
            img.pixels()
                .map(|p| (f64::from(p.0[0]) * scale) as f32)
                .collect(),
            "8-bit grey",
            Georef::None,
        ),
        (DynamicImage::ImageLuma16(img), None) => (
            img.pixels()
                .map(|p| (f64::from(p.0[0]) * scale) as f32)
                .collect(),
            "16-bit grey",
            Georef::None,
        ),
        (DynamicImage::ImageLumaA8(img), None) => (
            img.pixels()
                .map(|p| grey_or_void(f64::from(p.0[0]), p.0[1] == 0, scale))
                .collect(),
            "8-bit grey+alpha",
            Georef::None,
        ),
        (DynamicImage::ImageLumaA16(img), None) => (
            img.pixels()
                .map(|p| grey_or_void(f64::from(p.0[0]), p.0[1] == 0, scale))
                .collect(),
            "16-bit grey+alpha",
            Georef::None,
        ),
        (DynamicImage::ImageRgb8(img), None) if format == ImageFormat::Jpeg => {
            // A grey JPEG is often stored as YCbCr (the Puget 4K file is): accept it when the
            // channels agree, and read its luma.
            let spread = img
                .pixels()
                .map(|p| {
                    let [r, g, b] = p.0.map(i32::from);
                    ((r - g).abs() + (g - b).abs() + (r - b).abs()) as f64 / 3.0
                })
                .sum::<f64>()
                / pixels as f64;
            if spread > GREY_TOLERANCE {
                return Err(unsupported("colour JPEG (heights must be grey)"));
            }
            let grey = image.to_luma8();
            (
                grey.pixels()
                    .map(|p| (f64::from(p.0[0]) * scale) as f32)
                    .collect(),
                "8-bit grey (stored as YCbCr)",
                Georef::None,
            )
        }
        (DynamicImage::ImageRgb8(_) | DynamicImage::ImageRgba8(_), Some(_))
            if format == ImageFormat::Jpeg =>
        {
            return Err(unsupported(
                "--encoding with a JPEG (lossy compression destroys encoded heights)",
            ))
        }
        (DynamicImage::ImageRgb8(_) | DynamicImage::ImageRgba8(_), None) => {
            return Err(DemError::Option {
                file,
                problem: "RGB PNG: pass --encoding terrain-rgb or --encoding terrarium to say \
                          how it encodes heights"
                    .to_string(),
            })
        }
        (DynamicImage::ImageRgb8(img), Some(e)) => (
            img.pixels()
                .map(|p| (e.decode(p.0[0], p.0[1], p.0[2]) * scale) as f32)
                .collect(),
            "RGB",
            tile_georef(path, width, height),
        ),
        (DynamicImage::ImageRgba8(img), Some(e)) => (
            img.pixels()
                .map(|p| {
                    let h = e.decode(p.0[0], p.0[1], p.0[2]);
                    grey_or_void(h, p.0[3] == 0, scale)
                })
                .collect(),
            "RGBA",
            tile_georef(path, width, height),
        ),
        (other, _) => {
            return Err(unsupported(&format!("pixel type {:?}", other.color())));
        }
    };

    let description = match opts.encoding {
        Some(e) if matches!(what, "RGB" | "RGBA") => {
            let tile = match georef {
                Georef::Mercator { zoom, tile_y, .. } => format!(", tile z{zoom} y{tile_y}"),
                _ => String::new(),
            };
            format!("{e} {kind} {what} {width}x{height}{tile}")
        }
        _ => format!("{kind} {what} {width}x{height}"),
    };
    let placement = match georef {
        Georef::Mercator { .. } => tile_placement(path, width, height),
        _ => None,
    };
    Ok(Raster {
        width,
        height,
        samples,
        georef,
        placement,
        description,
    })
}

/// The JPEG decoder fills a truncated file's missing rows with grey and reports success, which
/// would turn a cut-off download into a plausible but false terrain. A complete JPEG ends with
/// the end-of-image marker FF D9 (which cannot occur in entropy-coded data), so demand it,
/// allowing for padding some writers append (and the start-of-image marker FF D8).
fn check_jpeg_ends(file: &str, handle: &File, len: u64) -> Result<(), DemError> {
    use std::io::{Read, Seek, SeekFrom};
    let mut head = Vec::with_capacity(2);
    let tail_len = len.min(256);
    let mut tail = Vec::with_capacity(tail_len as usize);
    let mut reader = handle;
    reader
        .seek(SeekFrom::Start(0))
        .and_then(|_| reader.take(2).read_to_end(&mut head))
        .and_then(|_| reader.seek(SeekFrom::Start(len - tail_len)))
        .and_then(|_| reader.take(tail_len).read_to_end(&mut tail))
        .and_then(|_| reader.seek(SeekFrom::Start(0)))
        .map_err(|source| DemError::Io {
            file: file.to_string(),
            source,
        })?;
    if head != [0xFF, 0xD8] {
        return Err(DemError::Malformed {
            file: file.to_string(),
            problem: "not a readable JPEG: no start-of-image marker".to_string(),
        });
    }
    let end = tail
        .iter()
        .rposition(|&b| !matches!(b, 0 | b'\r' | b'\n' | b' '))
        .map_or(0, |i| i + 1);
    if tail[..end].ends_with(&[0xFF, 0xD9]) {
        Ok(())
    } else {
        Err(DemError::Malformed {
            file: file.to_string(),
            problem: "truncated JPEG (no end-of-image marker)".to_string(),
        })
    }
}

fn limits(max_alloc: u64) -> Limits {
    let mut limits = Limits::default();
    limits.max_alloc = Some(max_alloc);
    limits
}

fn grey_or_void(value: f64, transparent: bool, scale: f64) -> f32 {
    if transparent {
        f32::NAN
    } else {
        (value * scale) as f32
    }
}

/// Where a slippy-map tile's pixels lie in web-mercator metres (EPSG:3857), from its name.
fn tile_placement(path: &Path, width: usize, height: usize) -> Option<Placement> {
    let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("");
    let (zoom, x, y) = tile_address(stem)?;
    Some(geo::mercator_placement(zoom, (x, y), (width, height)))
}

/// A slippy-map tile's name (`..._14-2625-6369_...`) says where it lies.
fn tile_georef(path: &Path, width: usize, height: usize) -> Georef {
    let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("");
    match tile_address(stem) {
        Some((zoom, _x, tile_y)) => Georef::Mercator {
            zoom,
            tile_y,
            tile_width: width,
            tile_height: height,
        },
        None => Georef::None,
    }
}
