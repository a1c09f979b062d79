//! Every non-TIFF format on small files made here: grey and encoded PNGs, JPEGs, raw grids,
//! synthetic SRTM tiles and mosaics, and detection by content.

mod common;

use std::io::Cursor;
use std::path::PathBuf;

use common::{assert_close, hgt3, read, read_err, spacing, temp_dir, write};
use dem::{Encoding, ReadOptions};
use image::{GrayAlphaImage, GrayImage, ImageBuffer, ImageFormat, Luma, Rgb, RgbImage, RgbaImage};

fn png_bytes<P, C>(img: &ImageBuffer<P, C>) -> Vec<u8>
where
    P: image::Pixel + image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
    C: std::ops::Deref<Target = [P::Subpixel]>,
{
    let mut out = Vec::new();
    img.write_to(&mut Cursor::new(&mut out), ImageFormat::Png)
        .expect("encode PNG");
    out
}

#[test]
fn grey_png_8_and_16_bit() {
    let dir = temp_dir();
    let img = GrayImage::from_fn(5, 3, |x, y| Luma([(x * 10 + y) as u8]));
    let p = write(dir.path(), "g8.png", &png_bytes(&img));
    let opts = ReadOptions {
        vertical_scale: Some(2.0),
        ..spacing(10.0)
    };
    let g = read(&p, &opts);
    assert_eq!((g.width, g.height), (5, 3));
    assert_eq!(g.get(4, 2), 84.0);
    assert_eq!(g.get(0, 0), 0.0);
    assert_eq!((g.spacing_x, g.spacing_y), (10.0, 10.0));
    assert_eq!(g.description, "PNG 8-bit grey 5x3");

    let img = ImageBuffer::<Luma<u16>, Vec<u16>>::from_fn(4, 4, |x, y| {
        Luma([(x * 1000 + y) as u16 + 60000])
    });
    let p = write(dir.path(), "g16.png", &png_bytes(&img));
    let g = read(&p, &spacing(1.0));
    assert_eq!(g.get(3, 1), 63001.0);
    assert_eq!(g.min_max(), (60000.0, 63003.0));
}

#[test]
fn grey_alpha_png_zero_alpha_is_void() {
    let dir = temp_dir();
    let img = GrayAlphaImage::from_fn(8, 8, |x, y| {
        let hole = (2..5).contains(&x) && (3..6).contains(&y);
        image::LumaA([100, if hole { 0 } else { 255 }])
    });
    let p = write(dir.path(), "ga.png", &png_bytes(&img));
    let g = read(&p, &spacing(1.0));
    assert_eq!(g.voids_filled, 9);
    assert!(g.heights.iter().all(|&h| h == 100.0));
}

#[test]
fn grey_jpeg() {
    let dir = temp_dir();
    // Smooth so JPEG's error stays small.
    let img = GrayImage::from_fn(64, 48, |x, y| Luma([(x + y) as u8 + 50]));
    let p = dir.path().join("g.jpg");
    img.save(&p).expect("save JPEG");
    let g = read(&p, &spacing(30.0));
    assert_eq!((g.width, g.height), (64, 48));
    for y in 0..48 {
        for x in 0..64 {
            let expected = (x + y + 50) as f32;
            assert!((g.get(x, y) - expected).abs() <= 3.0, "{x},{y}");
        }
    }
    assert_eq!(g.description, "JPEG 8-bit grey 64x48");
}

#[test]
fn colour_jpeg_is_refused() {
    let dir = temp_dir();
    let img = RgbImage::from_fn(32, 32, |x, _| {
        if x < 16 {
            Rgb([255, 0, 0])
        } else {
            Rgb([0, 0, 255])
        }
    });
    let p = dir.path().join("c.jpg");
    img.save(&p).expect("save JPEG");
    let e = read_err(&[p], &spacing(1.0));
    assert!(e.contains("c.jpg: unsupported JPEG: colour JPEG"), "{e}");
}

#[test]
fn terrarium_png_with_tile_name() {
    let dir = temp_dir();
    // Terrarium: h = R*256 + G + B/256 - 32768.
    let heights = [-5.5f64, 0.0, 1234.25, 8848.0];
    let img = RgbImage::from_fn(2, 2, |x, y| {
        let v = heights[(y * 2 + x) as usize] + 32768.0;
        let r = (v / 256.0).floor();
        let g = (v - r * 256.0).floor();
        let b = ((v - r * 256.0 - g) * 256.0).round();
        Rgb([r as u8, g as u8, b as u8])
    });
    let p = write(dir.path(), "terrarium_10-163-395.png", &png_bytes(&img));
    let opts = ReadOptions {
        encoding: Some(Encoding::Terrarium),
        ..ReadOptions::default()
    };
    let g = read(&p, &opts);
    assert_eq!(g.heights, heights.map(|h| h as f32).to_vec());
    // Tile y 395 of 1024, centre row: web-mercator latitude, 2 px wide tile.
    let lat = (std::f64::consts::PI * (1.0 - 2.0 * 395.5 / 1024.0))
        .sinh()
        .atan();
    let expected = 40_075_016.686 * lat.cos() / (1024.0 * 2.0);
    assert_close(g.spacing_x, expected, 1e-6, "spacing");
    assert_eq!(g.description, "terrarium PNG RGB 2x2, tile z10 y395");
    // The same picture is refused without --encoding, and as grey.
    let e = read_err(std::slice::from_ref(&p), &ReadOptions::default());
    assert!(
        e.contains("pass --encoding terrain-rgb or --encoding terrarium"),
        "{e}"
    );
}

#[test]
fn terrain_rgb_rgba_transparent_is_void() {
    let dir = temp_dir();
    // Terrain-RGB 100 m = (100 + 10000) * 10 = 101000 = (1, 138, 136).
    let img = RgbaImage::from_fn(4, 4, |x, y| {
        image::Rgba([1, 138, 136, if x == 1 && y == 2 { 0 } else { 255 }])
    });
    let p = write(dir.path(), "t.png", &png_bytes(&img));
    let opts = ReadOptions {
        encoding: Some(Encoding::TerrainRgb),
        ..spacing(5.0)
    };
    let g = read(&p, &opts);
    assert_eq!(g.voids_filled, 1);
    assert!(g.heights.iter().all(|&h| (h - 100.0).abs() < 1e-3));
}

#[test]
fn option_mismatches_are_refused() {
    let dir = temp_dir();
    let grey = write(dir.path(), "g.png", &png_bytes(&GrayImage::new(2, 2)));
    let opts = ReadOptions {
        encoding: Some(Encoding::TerrainRgb),
        ..spacing(1.0)
    };
    let e = read_err(std::slice::from_ref(&grey), &opts);
    assert!(
        e.contains("--encoding terrain-rgb is for RGB pictures"),
        "{e}"
    );
    let opts = ReadOptions {
        size: Some((2, 2)),
        ..spacing(1.0)
    };
    let e = read_err(std::slice::from_ref(&grey), &opts);
    assert!(e.contains("--size is only for raw"), "{e}");
    let rgb16 = ImageBuffer::<Rgb<u16>, Vec<u16>>::new(2, 2);
    let p = write(dir.path(), "rgb16.png", &png_bytes(&rgb16));
    let opts = ReadOptions {
        encoding: Some(Encoding::TerrainRgb),
        ..spacing(1.0)
    };
    let e = read_err(&[p], &opts);
    assert!(e.contains("unsupported PNG: pixel type Rgb16"), "{e}");
    let hgt = write(dir.path(), "N10E010.hgt", &vec![0u8; 1201 * 1201 * 2]);
    let e = read_err(&[hgt], &opts);
    assert!(
        e.contains("N10E010.hgt: --encoding terrain-rgb is for RGB PNG tiles"),
        "{e}"
    );
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let e = read_err(std::slice::from_ref(&grey), &spacing(bad));
        assert!(e.starts_with("--spacing"), "{e}");
        let opts = ReadOptions {
            vertical_scale: Some(bad),
            ..spacing(1.0)
        };
        let e = read_err(std::slice::from_ref(&grey), &opts);
        assert!(e.starts_with("--vertical-scale"), "{e}");
    }
}

#[test]
fn raw_r16_and_f32() {
    let dir = temp_dir();
    let values: Vec<u16> = (0..12).map(|i| i * 1000).collect();
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    let p = write(dir.path(), "h.r16", &bytes);
    let e = read_err(std::slice::from_ref(&p), &spacing(1.0));
    assert!(e.contains("pass --size WxH"), "{e}");
    let opts = ReadOptions {
        size: Some((4, 3)),
        vertical_scale: Some(0.5),
        ..spacing(2.0)
    };
    let g = read(&p, &opts);
    assert_eq!((g.width, g.height), (4, 3));
    assert_eq!(g.get(3, 2), 5500.0);
    assert_eq!(g.description, "raw u16 (.r16) 4x3");
    // Spacing is required.
    let opts = ReadOptions {
        size: Some((4, 3)),
        ..ReadOptions::default()
    };
    let e = read_err(&[p], &opts);
    assert!(e.contains("--spacing"), "{e}");

    let values = [-10.5f32, 0.0, 8848.86, 1.0e-3, 42.0, -0.0];
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    let p = write(dir.path(), "h.F32", &bytes);
    let opts = ReadOptions {
        size: Some((3, 2)),
        ..spacing(1.0)
    };
    let g = read(&p, &opts);
    assert_eq!(g.heights, values.to_vec());
}

#[test]
fn srtm_mosaic_2x2_layout() {
    let dir = temp_dir();
    // South-west 1, south-east 2, north-west 3, north-east 4 (names in mixed case and order).
    let paths: Vec<PathBuf> = [
        ("s01w001.hgt", 1),
        ("S01E000.HGT", 2),
        ("N00W001.hgt", 3),
        ("n00e000.hgt", 4),
    ]
    .iter()
    .map(|(name, v)| write(dir.path(), name, &hgt3(*v, |_, _| false)))
    .collect();
    let g = dem::read(&paths, &ReadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((g.width, g.height), (2401, 2401));
    assert_eq!(g.description, "SRTM3 mosaic S01W001..N00E000 (4 files)");
    assert_eq!(g.get(0, 0), 3.0);
    assert_eq!(g.get(2400, 0), 4.0);
    assert_eq!(g.get(0, 2400), 1.0);
    assert_eq!(g.get(2400, 2400), 2.0);
    // At the equator 3" is ~92.8 m east-west and ~92.1 m north-south.
    assert_close(
        g.spacing_x,
        dem::metres_per_degree_lon(0.0) / 1200.0,
        1e-9,
        "dx",
    );
    assert_close(
        g.spacing_y,
        dem::metres_per_degree_lat(0.0) / 1200.0,
        1e-9,
        "dy",
    );
}

#[test]
fn srtm_shared_edge_prefers_valid_samples() {
    let dir = temp_dir();
    // The northern tile's bottom row is void; the southern tile's top row supplies it.
    let north = write(dir.path(), "N11E010.hgt", &hgt3(500, |_, y| y == 1200));
    let south = write(dir.path(), "N10E010.hgt", &hgt3(100, |_, _| false));
    let g = dem::read(&[north, south], &ReadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(g.voids_filled, 0);
    assert_eq!(g.get(7, 1200), 100.0);
    assert_eq!(g.get(7, 1199), 500.0);
}

#[test]
fn srtm_unnamed_tile_needs_spacing() {
    let dir = temp_dir();
    let p = write(dir.path(), "tile.hgt", &hgt3(7, |x, _| x == 3));
    let e = read_err(std::slice::from_ref(&p), &ReadOptions::default());
    assert!(
        e.contains("tile.hgt: the name does not say where the tile lies"),
        "{e}"
    );
    let g = read(&p, &spacing(90.0));
    assert_eq!(g.voids_filled, 1201);
    assert_eq!(g.description, "SRTM3 (unnamed tile)");
}

#[test]
fn format_from_content_when_the_extension_says_nothing() {
    let dir = temp_dir();
    let img = GrayImage::from_fn(3, 3, |x, _| Luma([x as u8]));
    let p = write(dir.path(), "heights.dat", &png_bytes(&img));
    let g = read(&p, &spacing(1.0));
    assert_eq!(g.get(2, 0), 2.0);
    let tif = common::TiffSpec::new(2, 2, common::Samples::I16(vec![1, 2, 3, 4])).encode();
    let p = write(dir.path(), "heights", &tif);
    let g = read(&p, &spacing(1.0));
    assert_eq!(g.heights, vec![1.0, 2.0, 3.0, 4.0]);
}
