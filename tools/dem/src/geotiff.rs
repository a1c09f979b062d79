//! Single-band GeoTIFF DEMs through the `tiff` crate: integer or float samples, stripped or
//! tiled, uncompressed/LZW/Deflate/PackBits with any predictor it decodes. Voids come from the
//! GDAL_NODATA tag (42113); spacing from ModelPixelScale (33550) + ModelTiepoint (33922) or
//! ModelTransformation (34264), read as degrees or metres per GTModelTypeGeoKey (1024) in the
//! GeoKeyDirectory (34735). Everything else (RGB, multi-band, JPEG-in-TIFF, 1-bit) is refused
//! with one line rather than read as nonsense.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::tags::Tag;
use tiff::ColorType;

use crate::error::{label, one_line};
use crate::raster::{check_dimensions, Georef, Raster, MAX_COMPRESSION_RATIO};
use crate::{DemError, ReadOptions};

// GeoKey ids and values from the GeoTIFF 1.1 spec (OGC 19-008r4), section 7.
const GT_MODEL_TYPE: u16 = 1024;
const GT_RASTER_TYPE: u16 = 1025;
const GEOG_ANGULAR_UNITS: u16 = 2054;
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
        50000 => Err("ZSTD-compressed TIFF (recompress with LZW or Deflate)".into()),
        other => Err(format!("TIFF compression method {other}")),
    }
}

pub fn read(path: &Path, opts: &ReadOptions) -> Result<Raster, DemError> {
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
    let sample_format = tag_u16(&mut decoder, Tag::SampleFormat, 1)?;
    let bits = match decoder.colortype() {
        Ok(ColorType::Gray(bits)) if photometric == 1 => bits,
        Ok(ColorType::Gray(_)) => {
            return Err(unsupported(
                "WhiteIsZero TIFF (inverted grey is a picture, not a DEM)".into(),
            ))
        }
        Ok(ColorType::Multiband { num_samples, .. }) => {
            return Err(unsupported(format!("TIFF with {num_samples} samples per pixel")))
        }
        Ok(other) => return Err(unsupported(format!("{other:?} TIFF"))),
        Err(e) => return Err(unsupported(format!("TIFF layout ({})", one_line(e)))),
    };
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
    let samples = check_dimensions(
        &file,
        width.into(),
        height.into(),
        bytes_per_sample,
        max_bytes,
    )?;
    let layout = match decoder.get_chunk_type() {
        tiff::decoder::ChunkType::Tile => {
            let (tw, th) = decoder.chunk_dimensions();
            format!("tiled {tw}x{th}")
        }
        tiff::decoder::ChunkType::Strip => "stripped".to_string(),
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

    let mut limits = Limits::default();
    limits.decoding_buffer_size = samples * bytes_per_sample as usize + (1 << 20);
    limits.intermediate_buffer_size = limits
        .intermediate_buffer_size
        .max(usize::try_from(file_len).unwrap_or(usize::MAX));
    let mut decoder = decoder.with_limits(limits);
    let data = decoder.read_image().map_err(malformed)?;

    let scale = opts.vertical_scale() * vertical;
    let mut converter = Converter {
        file: &file,
        width: width as usize,
        nodata,
        scale,
        out: Vec::with_capacity(samples),
    };
    match data {
        DecodingResult::U8(v) => converter.ints(&v, f64::from),
        DecodingResult::U16(v) => converter.ints(&v, f64::from),
        DecodingResult::U32(v) => converter.ints(&v, f64::from),
        DecodingResult::U64(v) => converter.ints(&v, |x| x as f64),
        DecodingResult::I8(v) => converter.ints(&v, f64::from),
        DecodingResult::I16(v) => converter.ints(&v, f64::from),
        DecodingResult::I32(v) => converter.ints(&v, f64::from),
        DecodingResult::I64(v) => converter.ints(&v, |x| x as f64),
        DecodingResult::F16(v) => converter.floats(&v, |x| f64::from(f32::from(x)))?,
        DecodingResult::F32(v) => converter.floats(&v, f64::from)?,
        DecodingResult::F64(v) => converter.floats(&v, |x| x)?,
    }
    let out = converter.out;
    if out.len() != samples {
        return Err(DemError::Malformed {
            file,
            problem: format!(
                "decoded {} samples for a {width}x{height} image",
                out.len()
            ),
        });
    }
    let nodata_text = match nodata {
        Some(n) => format!(", nodata {n}"),
        None => String::new(),
    };
    Ok(Raster {
        width: width as usize,
        height: height as usize,
        samples: out,
        georef,
        description: format!(
            "GeoTIFF {sample_type} {compression}, {layout}, {georef_text}{nodata_text}"
        ),
    })
}

/// `-32768`, `3.4e38`, `nan` (GDAL writes NaN nodata in several spellings).
fn parse_nodata(text: &str) -> Option<f64> {
    let t = text.trim_matches(|c: char| c == '\0' || c.is_whitespace());
    if t.trim_start_matches(['-', '+']).eq_ignore_ascii_case("nan") {
        return Some(f64::NAN);
    }
    t.parse().ok()
}

/// Turns decoded samples into metres, voids into NaN.
struct Converter<'a> {
    file: &'a str,
    width: usize,
    nodata: Option<f64>,
    scale: f64,
    out: Vec<f32>,
}

impl Converter<'_> {
    fn ints<T: Copy>(&mut self, data: &[T], to_f64: impl Fn(T) -> f64) {
        // A NaN or fractional nodata matches no integer: no voids.
        let nodata = self.nodata.unwrap_or(f64::NAN);
        self.out.extend(data.iter().map(|&x| {
            let v = to_f64(x);
            if v == nodata {
                f32::NAN
            } else {
                (v * self.scale) as f32
            }
        }));
    }

    fn floats<T: Copy>(&mut self, data: &[T], to_f64: impl Fn(T) -> f64) -> Result<(), DemError> {
        // Compare in the file's own precision: GDAL writes f32 nodata as a decimal that only
        // equals the samples after rounding to f32.
        let nodata = self.nodata.map(|n| f64::from(n as f32));
        let nan_is_void = nodata.is_some_and(f64::is_nan);
        for (i, &x) in data.iter().enumerate() {
            let v = to_f64(x);
            let h = if (v.is_nan() && nan_is_void) || Some(v) == nodata {
                f32::NAN
            } else {
                let h = (v * self.scale) as f32;
                if !h.is_finite() {
                    return Err(DemError::BadSample {
                        file: self.file.to_string(),
                        x: i % self.width.max(1),
                        y: i / self.width.max(1),
                        problem: format!(
                            "height {v} is not a finite number (and the nodata value is {})",
                            self.nodata
                                .map_or_else(|| "not set".to_string(), |n| n.to_string())
                        ),
                    });
                }
                h
            };
            self.out.push(h);
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

/// Spacing (or what is needed to work it out after cropping) and a few words for the
/// description.
fn georef<R: std::io::Read + std::io::Seek>(
    decoder: &mut Decoder<R>,
    keys: &GeoKeys,
) -> Result<(Georef, String), GeorefError> {
    let scale = f64_tag(decoder, Tag::ModelPixelScaleTag)?;
    let tiepoint = f64_tag(decoder, Tag::ModelTiepointTag)?;
    let transform = f64_tag(decoder, Tag::ModelTransformationTag)?;

    // (size of a pixel in x and y, and a raster point (i, j) with its model position (x, y)).
    type Origin = Option<(f64, f64, f64, f64)>;
    let (sx, sy, origin): (f64, f64, Origin) = match (scale, tiepoint, transform) {
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
        _ => {
            return Err(GeorefError::Missing(
                "no georeferencing (ModelPixelScale/ModelTransformation), so no spacing".into(),
            ))
        }
    };
    if !(sx.is_finite() && sy.is_finite() && sx > 0.0 && sy > 0.0) {
        return Err(GeorefError::Unsupported(format!(
            "pixel scale {sx} x {sy}"
        )));
    }

    match keys.get(GT_MODEL_TYPE) {
        Some(MODEL_PROJECTED) => {
            let unit = keys.get(PROJ_LINEAR_UNITS).unwrap_or(9001);
            let (factor, name) = linear_unit(unit).ok_or_else(|| {
                GeorefError::Unsupported(format!("projected linear unit code {unit}"))
            })?;
            Ok((
                Georef::Metres {
                    dx: sx * factor,
                    dy: sy * factor,
                },
                format!("projected ({name})"),
            ))
        }
        Some(MODEL_GEOGRAPHIC) => {
            let to_degrees = match keys.get(GEOG_ANGULAR_UNITS).unwrap_or(9102) {
                9102 => 1.0,
                9101 => 180.0 / std::f64::consts::PI,
                9105 => 0.9, // grad
                other => {
                    return Err(GeorefError::Unsupported(format!(
                        "geographic angular unit code {other}"
                    )))
                }
            };
            let Some((_i, j, _x, y)) = origin else {
                return Err(GeorefError::Missing(
                    "geographic TIFF without a tiepoint: its latitude is unknown".into(),
                ));
            };
            // With PixelIsArea (the default) raster point (0, 0) is the corner of the first
            // pixel, whose centre is half a pixel in.
            let centre = if keys.get(GT_RASTER_TYPE) == Some(RASTER_PIXEL_IS_POINT) {
                0.0
            } else {
                0.5
            };
            let step_lat = sy * to_degrees;
            let lat_row0 = y * to_degrees - (centre - j) * step_lat;
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
