//! GeoTIFF variants made here: every sample type x layout x compression x predictor x byte
//! order we claim to read, nodata handling, the georeferencing cases, files written by the
//! `tiff` crate's own encoder, and the variants we refuse.

mod common;

use common::{assert_close, read, read_err, temp_dir, write, Layout, Samples, TagValue, TiffSpec};
use dem::{metres_per_degree_lat, metres_per_degree_lon, ReadOptions};

const W: u32 = 37;
const H: u32 = 23;

/// A test height for sample (x, y): varied in sign and magnitude, every 11th sample void.
fn height(x: u32, y: u32) -> Option<f64> {
    let i = y * W + x;
    if i % 11 == 5 {
        None
    } else {
        Some(f64::from(x) * 3.0 - f64::from(y) * 2.0 + 5.0) // -39..113
    }
}

fn grid<T>(void: T, f: impl Fn(f64) -> T) -> Vec<T>
where
    T: Copy,
{
    (0..H)
        .flat_map(|y| (0..W).map(move |x| (x, y)))
        .map(|(x, y)| height(x, y).map_or(void, &f))
        .collect()
}

fn voids() -> u64 {
    (0..W * H).filter(|i| i % 11 == 5).count() as u64
}

/// Valid samples must come back exactly (they are small integers in every type).
fn check_values(g: &dem::HeightGrid, what: &str) {
    assert_eq!((g.width, g.height), (W as usize, H as usize), "{what}");
    assert_eq!(g.voids_filled, voids(), "{what}");
    for y in 0..H {
        for x in 0..W {
            if let Some(h) = height(x, y) {
                assert_eq!(g.get(x as usize, y as usize), h as f32, "{what} at {x},{y}");
            }
        }
    }
}

#[test]
fn every_sample_type_layout_compression_and_predictor() {
    let dir = temp_dir();
    let types: Vec<(&str, Samples, &str, bool)> = vec![
        (
            "i16",
            Samples::I16(grid(-32768, |h| h as i16)),
            "-32768",
            false,
        ),
        (
            "u16",
            Samples::U16(grid(65535, |h| (h + 100.0) as u16)),
            "65535",
            false,
        ),
        (
            "u8",
            Samples::U8(grid(0, |h| (h + 100.0) as u8)),
            "0",
            false,
        ),
        (
            "i32",
            Samples::I32(grid(-9999, |h| h as i32)),
            "-9999",
            false,
        ),
        (
            "f32",
            Samples::F32(grid(-3.402_823_5e38, |h| h as f32)),
            "-3.4028234663852886e+38",
            true,
        ),
        (
            "f32nan",
            Samples::F32(grid(f32::NAN, |h| h as f32)),
            "nan",
            true,
        ),
        ("f64", Samples::F64(grid(-9999.0, |h| h)), "-9999", true),
    ];
    let layouts = [
        Layout::Strips { rows: 5 },
        Layout::Strips { rows: H },
        Layout::Tiles {
            width: 16,
            height: 16,
        },
    ];
    let mut count = 0;
    for (name, samples, nodata, float) in &types {
        for layout in layouts {
            for compression in [1u16, 5, 8, 32773, 50000] {
                for predictor in [1u16, if *float { 3 } else { 2 }] {
                    for big_endian in [false, true] {
                        let mut spec = TiffSpec::new(W, H, samples.clone())
                            .geographic(10.0, 50.0, 1.0 / 1200.0)
                            .nodata(nodata);
                        spec.layout = layout;
                        spec.compression = compression;
                        spec.predictor = predictor;
                        spec.big_endian = big_endian;
                        let what = format!(
                            "{name} {layout:?} compression {compression} predictor {predictor} big-endian {big_endian}"
                        );
                        let path = dir.path().join(format!("v{count}.tif"));
                        spec.write(&path);
                        let g = read(&path, &ReadOptions::default());
                        // The u16/u8 grids were offset by +100 to stay unsigned.
                        let g = if matches!(samples, Samples::U16(_) | Samples::U8(_)) {
                            dem::HeightGrid {
                                heights: g.heights.iter().map(|h| h - 100.0).collect(),
                                ..g
                            }
                        } else {
                            g
                        };
                        check_values(&g, &what);
                        count += 1;
                    }
                }
            }
        }
    }
    assert_eq!(count, 7 * 3 * 5 * 2 * 2);
}

#[test]
fn description_names_the_variant() {
    let dir = temp_dir();
    let mut spec = TiffSpec::new(W, H, Samples::I16(grid(-32768, |h| h as i16)))
        .geographic(10.0, 50.0, 1.0 / 1200.0)
        .nodata("-32768");
    spec.compression = 5;
    spec.layout = Layout::Tiles {
        width: 16,
        height: 16,
    };
    let p = write(dir.path(), "d.tif", &spec.encode());
    let g = read(&p, &ReadOptions::default());
    assert_eq!(
        g.description,
        "GeoTIFF i16 LZW, tiled 16x16, geographic, nodata -32768"
    );
}

#[test]
fn written_by_the_tiff_crate_encoder() {
    use tiff::encoder::{colortype, Compression, DeflateLevel, Predictor, TiffEncoder};
    use tiff::tags::Tag;
    let dir = temp_dir();
    let heights = grid(-32768i16, |h| h as i16);
    let floats = grid(f32::NAN, |h| h as f32);
    for (i, compression) in [
        Compression::Uncompressed,
        Compression::Lzw,
        Compression::Deflate(DeflateLevel::Balanced),
        Compression::Packbits,
    ]
    .into_iter()
    .enumerate()
    {
        for predictor in [Predictor::None, Predictor::Horizontal] {
            for float in [false, true] {
                if float && predictor == Predictor::Horizontal {
                    continue; // the encoder refuses it (floats want predictor 3)
                }
                let path = dir.path().join(format!("enc{i}{predictor:?}{float}.tif"));
                let file = std::fs::File::create(&path).unwrap();
                let mut enc = TiffEncoder::new(file)
                    .unwrap()
                    .with_compression(compression)
                    .with_predictor(predictor);
                macro_rules! write_image {
                    ($ct:ty, $data:expr, $nodata:expr) => {{
                        let mut image = enc.new_image::<$ct>(W, H).unwrap();
                        image.rows_per_strip(4).unwrap();
                        let e = image.encoder();
                        e.write_tag(Tag::ModelPixelScaleTag, &[30.0f64, 30.0, 0.0][..])
                            .unwrap();
                        e.write_tag(
                            Tag::ModelTiepointTag,
                            &[0.0f64, 0.0, 0.0, 400000.0, 3800000.0, 0.0][..],
                        )
                        .unwrap();
                        e.write_tag(
                            Tag::GeoKeyDirectoryTag,
                            &[1u16, 1, 0, 2, 1024, 0, 1, 1, 3076, 0, 1, 9001][..],
                        )
                        .unwrap();
                        e.write_tag(Tag::GdalNodata, $nodata).unwrap();
                        image.write_data($data).unwrap();
                    }};
                }
                if float {
                    write_image!(colortype::Gray32Float, &floats, "nan");
                } else {
                    write_image!(colortype::GrayI16, &heights, "-32768");
                }
                let g = read(&path, &ReadOptions::default());
                check_values(&g, &path.display().to_string());
                assert_eq!((g.spacing_x, g.spacing_y), (30.0, 30.0));
                assert!(g.description.contains("stripped, projected (metres)"));
            }
        }
    }
}

#[test]
fn nan_samples() {
    let dir = temp_dir();
    let mut samples = grid(-9999.0f32, |h| h as f32);
    samples[40] = f32::NAN;
    // NaN with a numeric nodata is damage, not a void.
    let p = dir.path().join("nan_numeric.tif");
    TiffSpec::new(W, H, Samples::F32(samples.clone()))
        .geographic(0.0, 1.0, 0.001)
        .nodata("-9999")
        .write(&p);
    let e = read_err(&[p], &ReadOptions::default());
    assert!(
        e.contains("nan_numeric.tif: height NaN is not a finite number"),
        "{e}"
    );
    assert!(e.contains("at column 3, row 1"), "{e}");
    // ... and without any nodata.
    let p = dir.path().join("nan_none.tif");
    TiffSpec::new(W, H, Samples::F32(samples.clone()))
        .geographic(0.0, 1.0, 0.001)
        .write(&p);
    let e = read_err(&[p], &ReadOptions::default());
    assert!(e.contains("nodata value is not set"), "{e}");
    // With nodata "nan" NaNs are voids (and -9999 is then a height).
    let p = dir.path().join("nan_void.tif");
    TiffSpec::new(W, H, Samples::F32(samples))
        .geographic(0.0, 1.0, 0.001)
        .nodata("NaN")
        .write(&p);
    let g = read(&p, &ReadOptions::default());
    assert_eq!(g.voids_filled, 1);
    assert_eq!(g.min_max().0, -9999.0);
}

#[test]
fn spacing_from_georeferencing() {
    let dir = temp_dir();
    let data = || Samples::I16(grid(-32768, |h| h as i16));

    // Geographic 1", top edge at 45 N: W x H cells, centre row 11 of 23 at 45 - 11.5/3600.
    let p = dir.path().join("geo.tif");
    TiffSpec::new(W, H, data())
        .geographic(7.0, 45.0, 1.0 / 3600.0)
        .write(&p);
    let g = read(&p, &ReadOptions::default());
    let lat = 45.0 - 11.5 / 3600.0;
    assert_close(g.spacing_x, metres_per_degree_lon(lat) / 3600.0, 1e-9, "dx");
    assert_close(g.spacing_y, metres_per_degree_lat(lat) / 3600.0, 1e-9, "dy");

    // Projected metres and feet.
    let p = dir.path().join("m.tif");
    TiffSpec::new(W, H, data()).projected(10.0, 9001).write(&p);
    let g = read(&p, &ReadOptions::default());
    assert_eq!((g.spacing_x, g.spacing_y), (10.0, 10.0));
    let p = dir.path().join("ft.tif");
    TiffSpec::new(W, H, data()).projected(10.0, 9002).write(&p);
    let g = read(&p, &ReadOptions::default());
    assert_close(g.spacing_x, 3.048, 1e-12, "feet");
    assert!(g.description.contains("projected (feet)"));
    // An unknown linear unit is refused unless --spacing is given.
    let p = dir.path().join("unit.tif");
    TiffSpec::new(W, H, data()).projected(10.0, 9036).write(&p);
    let e = read_err(std::slice::from_ref(&p), &ReadOptions::default());
    assert!(
        e.contains("unsupported projected linear unit code 9036: pass --spacing"),
        "{e}"
    );
    let g = read(
        &p,
        &ReadOptions {
            spacing: Some(12.0),
            ..ReadOptions::default()
        },
    );
    assert_eq!((g.spacing_x, g.spacing_y), (12.0, 12.0));

    // ModelTransformation instead of scale + tiepoint.
    let p = dir.path().join("matrix.tif");
    let mut spec = TiffSpec::new(W, H, data());
    spec.extra_tags = vec![
        (
            34264,
            TagValue::Double(vec![
                25.0, 0.0, 0.0, 300000.0, 0.0, -25.0, 0.0, 5000000.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                0.0, 1.0,
            ]),
        ),
        (34735, TagValue::Short(vec![1, 1, 0, 1, 1024, 0, 1, 1])),
    ];
    spec.write(&p);
    let g = read(&p, &ReadOptions::default());
    assert_eq!((g.spacing_x, g.spacing_y), (25.0, 25.0));

    // No georeferencing at all: --spacing needed.
    let p = dir.path().join("plain.tif");
    TiffSpec::new(W, H, data()).write(&p);
    let e = read_err(std::slice::from_ref(&p), &ReadOptions::default());
    assert!(
        e.contains("plain.tif: no georeferencing") && e.contains("pass --spacing"),
        "{e}"
    );
    // A pixel scale without a model type is ambiguous.
    let p = dir.path().join("nomodel.tif");
    let mut spec = TiffSpec::new(W, H, data());
    spec.extra_tags = vec![(33550, TagValue::Double(vec![1.0, 1.0, 0.0]))];
    spec.write(&p);
    let e = read_err(&[p], &ReadOptions::default());
    assert!(e.contains("degrees or metres is unknown"), "{e}");
}

#[test]
fn vertical_units_in_feet_become_metres() {
    let dir = temp_dir();
    let p = dir.path().join("vft.tif");
    let mut spec = TiffSpec::new(2, 1, Samples::I16(vec![100, 1000]));
    spec.extra_tags = vec![
        (33550, TagValue::Double(vec![10.0, 10.0, 0.0])),
        (
            34735,
            TagValue::Short(vec![1, 1, 0, 2, 1024, 0, 1, 1, 4099, 0, 1, 9002]),
        ),
    ];
    spec.write(&p);
    let g = read(&p, &ReadOptions::default());
    assert_eq!(g.heights, vec![30.48, 304.8]);
}

#[test]
fn unsupported_variants_are_refused_with_one_line() {
    let dir = temp_dir();
    let cases: Vec<(&str, TiffSpec, &str)> = vec![
        (
            "rgb",
            {
                let mut s = TiffSpec::new(4, 4, Samples::U8(vec![9; 48]));
                s.samples_per_pixel = 3;
                s.photometric = 2;
                s
            },
            "unsupported RGB(8) TIFF",
        ),
        (
            "two_bands",
            {
                let mut s = TiffSpec::new(4, 4, Samples::I16(vec![9; 32]));
                s.samples_per_pixel = 2;
                s
            },
            "unsupported TIFF with 2 samples per pixel",
        ),
        (
            "jpeg",
            {
                let mut s = TiffSpec::new(4, 4, Samples::U8(vec![9; 16]));
                s.compression = 7;
                s
            },
            "unsupported JPEG-compressed TIFF",
        ),
        (
            "white_is_zero",
            {
                let mut s = TiffSpec::new(4, 4, Samples::U8(vec![9; 16]));
                s.photometric = 0;
                s
            },
            "unsupported WhiteIsZero TIFF",
        ),
        (
            "lerc",
            {
                let mut s = TiffSpec::new(4, 4, Samples::U8(vec![9; 16]));
                s.compression = 34887;
                s
            },
            "unsupported TIFF compression method 34887",
        ),
        (
            "complex",
            TiffSpec::new(4, 4, Samples::I32(vec![9; 16])),
            "unsupported TIFF sample format 5",
        ),
    ];
    for (name, spec, expected) in cases {
        let mut bytes = spec.encode();
        if name == "complex" {
            patch_short_tag(&mut bytes, 339, 5); // SampleFormat 5 = complex integer
        }
        let p = write(dir.path(), &format!("{name}.tif"), &bytes);
        let e = read_err(
            &[p],
            &ReadOptions {
                spacing: Some(1.0),
                ..ReadOptions::default()
            },
        );
        assert!(
            e.contains(&format!("{name}.tif: {expected}")),
            "{name}: {e}"
        );
    }
}

/// Sets the value of a SHORT tag in a little-endian classic TIFF.
fn patch_short_tag(bytes: &mut [u8], tag: u16, value: u16) {
    let ifd = u32::from_le_bytes(bytes[4..8].try_into().unwrap()) as usize;
    let n = u16::from_le_bytes([bytes[ifd], bytes[ifd + 1]]) as usize;
    for e in 0..n {
        let at = ifd + 2 + 12 * e;
        if u16::from_le_bytes([bytes[at], bytes[at + 1]]) == tag {
            bytes[at + 8..at + 10].copy_from_slice(&value.to_le_bytes());
            return;
        }
    }
    panic!("tag {tag} not found");
}

#[test]
fn huge_dimensions_are_refused_before_allocating() {
    let dir = temp_dir();
    for (w, h, expected) in [
        (
            100_000u32,
            100_000u32,
            "more than the limit of 2147483648 samples",
        ),
        (20_000, 20_000, "more than a file this size can hold"),
    ] {
        let mut spec = TiffSpec::new(4, 4, Samples::I16(vec![1; 16]));
        spec.layout = Layout::Strips { rows: 4 };
        let mut bytes = spec.encode();
        patch_long_tag(&mut bytes, 256, w);
        patch_long_tag(&mut bytes, 257, h);
        patch_long_tag(&mut bytes, 278, h);
        let p = write(dir.path(), "huge.tif", &bytes);
        let e = read_err(
            &[p],
            &ReadOptions {
                spacing: Some(1.0),
                ..ReadOptions::default()
            },
        );
        assert!(
            e.contains(&format!("huge.tif: header claims {w}x{h} samples, ")),
            "{e}"
        );
        assert!(e.contains(expected), "{e}");
    }
}

#[test]
fn huge_tiles_are_refused_before_allocating() {
    let dir = temp_dir();
    let mut spec = TiffSpec::new(4, 4, Samples::I16(vec![1; 16]));
    spec.layout = Layout::Tiles {
        width: 16,
        height: 16,
    };
    let mut bytes = spec.encode();
    // Still one tile for a 4x4 image, but 4 GiB samples of it.
    patch_long_tag(&mut bytes, 322, 65536);
    patch_long_tag(&mut bytes, 323, 65536);
    let p = write(dir.path(), "bigtile.tif", &bytes);
    let e = read_err(
        &[p],
        &ReadOptions {
            spacing: Some(1.0),
            ..ReadOptions::default()
        },
    );
    assert!(
        e.contains("bigtile.tif: header claims 65536x65536 samples, in each chunk"),
        "{e}"
    );
}

fn patch_long_tag(bytes: &mut [u8], tag: u16, value: u32) {
    let ifd = u32::from_le_bytes(bytes[4..8].try_into().unwrap()) as usize;
    let n = u16::from_le_bytes([bytes[ifd], bytes[ifd + 1]]) as usize;
    for e in 0..n {
        let at = ifd + 2 + 12 * e;
        if u16::from_le_bytes([bytes[at], bytes[at + 1]]) == tag {
            bytes[at + 8..at + 12].copy_from_slice(&value.to_le_bytes());
            return;
        }
    }
    panic!("tag {tag} not found");
}

#[test]
fn truncated_real_geotiff() {
    let dir = temp_dir();
    let bytes = std::fs::read(common::data("geotiff/mt_fuji_90m.tif")).unwrap();
    // The IFD comes first in this file, so the header survives and the tiles are cut.
    for len in [bytes.len() / 2, 600, 100, 9] {
        let p = write(dir.path(), "cut.tif", &bytes[..len]);
        let e = read_err(&[p], &ReadOptions::default());
        assert!(
            e.starts_with(&format!("{}: ", dir.path().join("cut.tif").display())),
            "{e}"
        );
    }
}

/// Hostile numbers in otherwise valid TIFFs: zero or short strip byte counts (a decoder would
/// read past them), absurd pixel scales, heights no planet has. Each is one line, no grid.
#[test]
fn hostile_byte_counts_scales_and_heights_are_refused() {
    let dir = temp_dir();
    let metres = |scale: f64| {
        vec![
            (33550, TagValue::Double(vec![scale, scale, 0.0])),
            (34735, TagValue::Short(vec![1, 1, 0, 1, 1024, 0, 1, 1])),
        ]
    };
    let plain = TiffSpec::new(4, 4, Samples::I16(vec![7; 16]));
    for (name, count, want) in [
        ("zero.tif", 0, "byte count of 0"),
        ("short.tif", 10, "declares 10 bytes"),
    ] {
        let mut bytes = plain.encode();
        patch_long_tag(&mut bytes, 279, count);
        let p = write(dir.path(), name, &bytes);
        let opts = ReadOptions {
            spacing: Some(1.0),
            ..ReadOptions::default()
        };
        let e = read_err(&[p], &opts);
        assert!(e.contains(name) && e.contains(want), "{e}");
    }
    for scale in [1e300, 1e-300] {
        let mut spec = plain.clone();
        spec.extra_tags = metres(scale);
        let p = dir.path().join("scale.tif");
        spec.write(&p);
        let e = read_err(&[p], &ReadOptions::default());
        assert!(
            e.contains("scale.tif") && e.contains("spacing"),
            "{scale}: {e}"
        );
    }
    for h in [3e38f32, -3.4e38, 1e6] {
        let mut spec = TiffSpec::new(2, 2, Samples::F32(vec![1.0, 2.0, h, 3.0]));
        spec.extra_tags = metres(30.0);
        let p = dir.path().join("heights.tif");
        spec.write(&p);
        let e = read_err(&[p], &ReadOptions::default());
        assert!(
            e.contains("heights.tif") && e.contains("column 0, row 1"),
            "{h}: {e}"
        );
    }
}
