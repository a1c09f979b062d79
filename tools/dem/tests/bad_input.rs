//! Files that must be refused with one clear line, never a panic or a huge allocation: empty,
//! truncated, wrong --size, mismatched mosaics, all-void, NaN, huge headers, missing files,
//! unknown kinds, and randomly damaged copies of valid files.

mod common;

use std::io::Cursor;
use std::path::PathBuf;

use common::{data, hgt3, patch_png_size, read_err, spacing, temp_dir, write, Samples, TiffSpec};
use dem::{Encoding, ReadOptions};
use image::{GrayImage, ImageFormat, Luma};

#[test]
fn no_input() {
    assert_eq!(
        read_err(&[], &ReadOptions::default()),
        "no input files given"
    );
}

#[test]
fn empty_files() {
    let dir = temp_dir();
    for name in [
        "N10E010.hgt",
        "e.png",
        "e.jpg",
        "e.tif",
        "e.r16",
        "e.f32",
        "e.bin",
    ] {
        let p = write(dir.path(), name, b"");
        let raw = name.ends_with(".r16") || name.ends_with(".f32");
        let opts = ReadOptions {
            size: raw.then_some((1, 1)),
            ..spacing(1.0)
        };
        let e = read_err(std::slice::from_ref(&p), &opts);
        assert_eq!(e, format!("{}: empty file", p.display()));
    }
}

#[test]
fn truncated_files() {
    let dir = temp_dir();
    let p = write(dir.path(), "N42E001.hgt", &vec![0u8; 2_000_000]);
    let e = read_err(&[p], &ReadOptions::default());
    assert!(
        e.ends_with("N42E001.hgt: size 2000000 bytes is neither 1201² nor 3601² samples (truncated or not an SRTM tile)"),
        "{e}"
    );
    for (rel, name, opts) in [
        ("puget/ps_height_1k.png", "cut.png", spacing(1.0)),
        ("puget/ps_height_4k_8bit.jpg", "cut.jpg", spacing(1.0)),
        (
            "terrainrgb/berkeley_14-2625-6369_terrain_rgb.png",
            "cut_14-2625-6369.png",
            ReadOptions {
                encoding: Some(Encoding::TerrainRgb),
                ..ReadOptions::default()
            },
        ),
    ] {
        let bytes = std::fs::read(data(rel)).unwrap();
        for len in [bytes.len() / 2, 100, 20, 3] {
            let p = write(dir.path(), name, &bytes[..len]);
            let e = read_err(&[p], &opts);
            assert!(e.contains(name), "{e}");
        }
    }
}

#[test]
fn wrong_size_for_raw_files() {
    let dir = temp_dir();
    let p = write(dir.path(), "h.r16", &[0u8; 200]);
    let opts = ReadOptions {
        size: Some((10, 11)),
        ..spacing(1.0)
    };
    let e = read_err(&[p], &opts);
    assert!(
        e.ends_with("h.r16: wrong --size 10x11: that needs 220 bytes, the file has 200"),
        "{e}"
    );
    let p = write(dir.path(), "h.f32", &[0u8; 400]);
    let opts = ReadOptions {
        size: Some((10, 11)),
        ..spacing(1.0)
    };
    let e = read_err(std::slice::from_ref(&p), &opts);
    assert!(
        e.contains("wrong --size 10x11: that needs 440 bytes"),
        "{e}"
    );
    // Sizes whose byte count overflows are just wrong, not a crash.
    let opts = ReadOptions {
        size: Some((usize::MAX, usize::MAX)),
        ..spacing(1.0)
    };
    let e = read_err(&[p], &opts);
    assert!(e.contains("wrong --size"), "{e}");
}

#[test]
fn mismatched_mosaics() {
    let dir = temp_dir();
    let a = write(dir.path(), "N41E001.hgt", &hgt3(1, |_, _| false));
    let b = write(dir.path(), "N42E001.hgt", &vec![0u8; 3601 * 3601 * 2]);
    let e = read_err(&[a.clone(), b], &ReadOptions::default());
    assert!(
        e.contains("N42E001.hgt: mismatched mosaic: it is 3601² (1\") but"),
        "{e}"
    );
    assert!(e.contains("N41E001.hgt is 1201² (3\")"), "{e}");

    // A gap: N41E001 and N41E003 without N41E002.
    let c = write(dir.path(), "N41E003.hgt", &hgt3(3, |_, _| false));
    let e = read_err(&[a.clone(), c.clone()], &ReadOptions::default());
    assert!(e.contains("mismatched mosaic: the 2 tiles do not fill the rectangle N41E001..N41E003: N41E002 is missing"), "{e}");
    // An L shape is not a rectangle either.
    let d = write(dir.path(), "N42E003.hgt", &hgt3(4, |_, _| false));
    let f = write(dir.path(), "N41E002.hgt", &hgt3(5, |_, _| false));
    let e = read_err(&[a.clone(), f, c, d], &ReadOptions::default());
    assert!(e.contains("N42E001 is missing"), "{e}");

    // The same cell twice, from two folders.
    std::fs::create_dir(dir.path().join("other")).unwrap();
    let dup = write(
        &dir.path().join("other"),
        "n41e001.HGT",
        &hgt3(1, |_, _| false),
    );
    let e = read_err(&[a.clone(), dup], &ReadOptions::default());
    assert!(
        e.contains("n41e001.HGT: mismatched mosaic: cell N41E001 is given twice"),
        "{e}"
    );

    // A tile without a usable name, and a non-SRTM file.
    let unnamed = write(dir.path(), "tile.hgt", &hgt3(1, |_, _| false));
    let e = read_err(&[a.clone(), unnamed], &ReadOptions::default());
    assert!(
        e.contains("tile.hgt: mismatched mosaic: its name does not say where it lies"),
        "{e}"
    );
    let png = write(dir.path(), "x.png", b"not really");
    let e = read_err(&[a, png.clone()], &ReadOptions::default());
    assert!(
        e.contains("x.png: mismatched mosaic: it is a PNG and ") && e.contains("of one kind"),
        "{e}"
    );
    let e = read_err(&[png.clone(), png], &ReadOptions::default());
    assert!(
        e.contains("x.png: mismatched mosaic: only SRTM .hgt tiles and GeoTIFFs can be mosaicked"),
        "{e}"
    );
}

#[test]
fn all_void() {
    let dir = temp_dir();
    let p = write(dir.path(), "S12W077.hgt", &hgt3(-32768, |_, _| false));
    let e = read_err(std::slice::from_ref(&p), &ReadOptions::default());
    assert!(
        e.ends_with("S12W077.hgt: no valid samples: every sample is void"),
        "{e}"
    );
    // A window that is all void in a file that is not: the real N48W125's northern half.
    let opts = ReadOptions {
        crop: Some("0,0,100x100".parse().unwrap()),
        ..ReadOptions::default()
    };
    let e = read_err(&[data("srtm/N48W125.hgt")], &opts);
    assert!(
        e.contains("no valid samples: every sample in crop 0,0,100x100 is void"),
        "{e}"
    );
    // All-void GeoTIFF and transparent Terrain-RGB.
    let p = dir.path().join("void.tif");
    TiffSpec::new(3, 3, Samples::I16(vec![-9999; 9]))
        .nodata("-9999")
        .write(&p);
    let e = read_err(&[p], &spacing(1.0));
    assert!(e.contains("void.tif: no valid samples"), "{e}");
}

#[test]
fn nan_in_raw_f32() {
    let dir = temp_dir();
    let mut values = [1.0f32; 12];
    values[7] = f32::NAN;
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    let p = write(dir.path(), "n.f32", &bytes);
    let opts = ReadOptions {
        size: Some((4, 3)),
        ..spacing(1.0)
    };
    let e = read_err(&[p], &opts);
    assert!(
        e.ends_with("n.f32: height NaN is not a finite number at column 3, row 1"),
        "{e}"
    );
}

#[test]
fn huge_png_header() {
    let dir = temp_dir();
    let mut png = Vec::new();
    GrayImage::from_pixel(4, 4, Luma([1]))
        .write_to(&mut Cursor::new(&mut png), ImageFormat::Png)
        .unwrap();
    for (w, h, expected) in [
        (
            100_000,
            100_000,
            "more than the limit of 2147483648 samples",
        ),
        (30_000, 30_000, "more than a file this size can hold"),
    ] {
        patch_png_size(&mut png, w, h);
        let p = write(dir.path(), "huge.png", &png);
        let e = read_err(&[p], &spacing(1.0));
        assert!(
            e.contains(&format!("huge.png: header claims {w}x{h} samples, ")),
            "{e}"
        );
        assert!(e.contains(expected), "{e}");
    }
}

#[test]
fn missing_files() {
    let dir = temp_dir();
    for name in [
        "N10E010.hgt",
        "gone.png",
        "gone.tif",
        "gone.jpg",
        "gone.f32",
        "gone",
    ] {
        let p = dir.path().join(name);
        let opts = ReadOptions {
            size: name.ends_with(".f32").then_some((2, 2)),
            ..spacing(1.0)
        };
        let e = read_err(std::slice::from_ref(&p), &opts);
        assert!(
            e.starts_with(&format!("{}: cannot read: ", p.display())),
            "{e}"
        );
    }
}

#[test]
fn unknown_kind_of_file() {
    let dir = temp_dir();
    let p = write(dir.path(), "heights.xyz", b"1 2 3\n4 5 6\n");
    let e = read_err(std::slice::from_ref(&p), &spacing(1.0));
    assert_eq!(
        e,
        format!(
            "{}: unknown kind of file: expected .hgt, .tif/.tiff, .png, .jpg/.jpeg, .r16 or .f32",
            p.display()
        )
    );
}

#[test]
fn garbage_with_a_known_extension() {
    let dir = temp_dir();
    let junk: Vec<u8> = (0..5000u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 24) as u8)
        .collect();
    for name in ["j.png", "j.jpg", "j.tif"] {
        let p = write(dir.path(), name, &junk);
        let e = read_err(&[p], &spacing(1.0));
        assert!(e.contains(&format!("{name}: not a readable")), "{e}");
    }
}

/// Randomly damaged copies of small valid files: reading may fail, but must not panic, hang or
/// return NaN heights.
#[test]
fn damaged_files_never_panic() {
    let dir = temp_dir();
    let mut png = Vec::new();
    GrayImage::from_fn(24, 17, |x, y| Luma([(x * 9 + y) as u8]))
        .write_to(&mut Cursor::new(&mut png), ImageFormat::Png)
        .unwrap();
    let mut jpg = Vec::new();
    GrayImage::from_fn(24, 17, |x, y| Luma([(x * 9 + y) as u8]))
        .write_to(&mut Cursor::new(&mut jpg), ImageFormat::Jpeg)
        .unwrap();
    let grid: Vec<f32> = (0..24 * 17).map(|i| i as f32).collect();
    let mut tiffs = Vec::new();
    for (compression, predictor, tiled) in
        [(1, 1, false), (5, 2, true), (8, 3, true), (32773, 1, false)]
    {
        let samples = if predictor == 3 {
            Samples::F32(grid.clone())
        } else {
            Samples::I16(grid.iter().map(|&v| v as i16).collect())
        };
        let mut spec = TiffSpec::new(24, 17, samples)
            .geographic(1.0, 2.0, 0.01)
            .nodata("0");
        spec.compression = compression;
        spec.predictor = predictor;
        if tiled {
            spec.layout = common::Layout::Tiles {
                width: 16,
                height: 16,
            };
        }
        tiffs.push(spec.encode());
    }
    let mut originals: Vec<(&str, Vec<u8>)> = vec![("d.png", png), ("d.jpg", jpg)];
    originals.extend(tiffs.into_iter().map(|t| ("d.tif", t)));

    let mut rng = splitmix::Rng(0x9E37_79B9_7F4A_7C15);
    let mut outcomes = (0, 0);
    for (name, original) in &originals {
        for _ in 0..150 {
            let mut bytes = original.clone();
            match rng.below(3) {
                0 => {
                    for _ in 0..1 + rng.below(4) {
                        let i = rng.below(bytes.len());
                        bytes[i] = rng.next_u64() as u8;
                    }
                }
                1 => bytes.truncate(rng.below(bytes.len())),
                _ => {
                    // Overwrite a 4-byte field with an extreme value (sizes, offsets, counts).
                    let i = rng.below(bytes.len().saturating_sub(4));
                    let v = [0u32, 1, 0xFFFF, 0xFFFF_FFFF, 0x7FFF_FFFF][rng.below(5)];
                    bytes[i..i + 4].copy_from_slice(&v.to_le_bytes());
                }
            }
            let p: PathBuf = write(dir.path(), name, &bytes);
            match dem::read(&[p], &spacing(1.0)) {
                Ok(g) => {
                    assert!(g.heights.iter().all(|h| h.is_finite()), "{name}");
                    assert_eq!(g.heights.len(), g.width * g.height);
                    outcomes.0 += 1;
                }
                Err(e) => {
                    assert!(!e.to_string().contains('\n'));
                    outcomes.1 += 1;
                }
            }
        }
    }
    // Both kinds of outcome happen, so the damage is neither always harmless nor always fatal.
    assert!(outcomes.0 > 0 && outcomes.1 > 0, "{outcomes:?}");
}

/// An SRTM name is its seven characters, then nothing or a dot: `N43E007x.hgt` says nothing
/// about where it lies; `N43E007.SRTMGL1.hgt` does.
#[test]
fn srtm_names_must_end_after_the_cell() {
    let dir = temp_dir();
    let bytes = vec![0u8; 1201 * 1201 * 2];
    let bad = write(dir.path(), "N43E007x.hgt", &bytes);
    let e = read_err(&[bad], &ReadOptions::default());
    assert!(
        e.contains("N43E007x.hgt: the name does not say where"),
        "{e}"
    );
    let good = write(dir.path(), "N43E007.SRTMGL1.hgt", &bytes);
    let g = dem::read(&[good], &ReadOptions::default()).expect("a dotted SRTM name");
    assert_eq!((g.width, g.height), (1201, 1201));
}
