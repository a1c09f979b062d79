//! A DEM read band by band ([`dem::open`]) is the DEM read whole ([`dem::read`]), bit for bit,
//! on real data with voids: one SRTM1 tile, a mosaic of two SRTM3 tiles, crops, and a raw file
//! written from SRTM heights.

mod common;

use std::path::PathBuf;

use common::data;
use dem::{Crop, ReadOptions};

/// Every band of `rows` rows (and a few odd ones) of the stream equals the same rows of the
/// whole read; the metadata agree too.
fn same_in_bands(paths: &[PathBuf], opts: &ReadOptions, rows: usize) -> dem::HeightGrid {
    let whole = dem::read(paths, opts).expect("read whole");
    let stream = dem::open(paths, opts).expect("open");
    assert!(stream.is_banded(), "{}", whole.description);
    assert_eq!((stream.width, stream.height), (whole.width, whole.height));
    assert_eq!(
        (stream.spacing_x, stream.spacing_y),
        (whole.spacing_x, whole.spacing_y)
    );
    assert_eq!(stream.voids_filled, whole.voids_filled);
    assert_eq!(stream.description, whole.description);
    assert_eq!(stream.placement, whole.placement);
    assert_eq!(stream.min_max, whole.min_max());
    let w = whole.width;
    let mut bands: Vec<(usize, usize)> = (0..whole.height)
        .step_by(rows)
        .map(|y| (y, (y + rows).min(whole.height)))
        .collect();
    bands.extend([(0, 1), (whole.height - 1, whole.height), (17, 300), (0, 0)]);
    for (y0, y1) in bands {
        let got = stream.rows(y0, y1).expect("rows");
        let want = &whole.heights[y0 * w..y1 * w];
        assert!(
            got.len() == want.len()
                && got
                    .iter()
                    .zip(want)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
            "{}: rows {y0}..{y1} differ",
            whole.description
        );
    }
    whole
}

#[test]
fn srtm_tiles_and_mosaics_read_in_bands_are_read_whole() {
    let opts = ReadOptions::default();
    let one = same_in_bands(&[data("srtm/N48W125.hgt")], &opts, 257);
    // Not vacuous: the tile has voids, so the bands were filled.
    assert!(one.voids_filled > 100_000, "{}", one.voids_filled);
    let pair = [data("srtm/N41E001.hgt"), data("srtm/N42E001.hgt")];
    let mosaic = same_in_bands(&pair, &opts, 256);
    assert!(mosaic.voids_filled > 0);
    let crop = ReadOptions {
        crop: Some(Crop {
            x: 333,
            y: 1000,
            width: 700,
            height: 900,
        }),
        ..ReadOptions::default()
    };
    same_in_bands(&pair, &crop, 100);
    let void_crop = ReadOptions {
        crop: Some(Crop {
            x: 1500,
            y: 2000,
            width: 1600,
            height: 1200,
        }),
        ..ReadOptions::default()
    };
    let g = same_in_bands(&[data("srtm/N48W125.hgt")], &void_crop, 64);
    assert!(g.voids_filled > 0);
}

#[test]
fn raw_files_read_in_bands_are_read_whole() {
    let dir = tempfile::tempdir().expect("tempdir");
    let src = dem::read(&[data("srtm/N43E007.hgt")], &ReadOptions::default()).expect("read");
    let path = dir.path().join("alps.r16");
    let bytes: Vec<u8> = src
        .heights
        .iter()
        .flat_map(|h| (h.max(0.0) as u16).to_le_bytes())
        .collect();
    std::fs::write(&path, bytes).expect("write");
    let opts = ReadOptions {
        size: Some((src.width, src.height)),
        spacing: Some(90.0),
        vertical_scale: Some(0.5),
        crop: Some(Crop {
            x: 1,
            y: 2,
            width: 1000,
            height: 1100,
        }),
        ..ReadOptions::default()
    };
    same_in_bands(&[path], &opts, 300);
}

/// Formats without band reads are decoded whole and served from memory, with the same rows.
#[test]
fn other_formats_are_held_whole() {
    let path = testdata::sample();
    let opts = ReadOptions {
        spacing: Some(40.0),
        ..ReadOptions::default()
    };
    let whole = dem::read(std::slice::from_ref(&path), &opts).expect("read");
    let stream = dem::open(&[path], &opts).expect("open");
    assert!(!stream.is_banded());
    assert_eq!(
        &stream.rows(0, whole.height).expect("rows")[..],
        &whole.heights[..]
    );
}

/// GeoTIFFs are read a band at a time by decoding the strips or tiles the band touches: real
/// SRTM heights with their voids as GDAL nodata, tiled and stripped, compressed, geographic.
#[test]
fn geotiffs_read_in_bands_are_read_whole() {
    use common::{Layout, Samples, TiffSpec};
    let dir = tempfile::tempdir().expect("tempdir");
    let (w, h, samples) = n48_crop();
    let voids = samples.iter().filter(|&&v| v == -32768).count();
    assert!(voids > 1000, "{voids} voids");
    let layouts = [
        (
            Layout::Tiles {
                width: 64,
                height: 48,
            },
            5u16,
        ),
        (Layout::Strips { rows: 7 }, 8),
        (Layout::Strips { rows: 1 }, 1),
    ];
    for (k, (layout, compression)) in layouts.into_iter().enumerate() {
        let mut spec = TiffSpec::new(w as u32, h as u32, Samples::I16(samples.clone()))
            .geographic(-124.5, 47.4, 1.0 / 3600.0)
            .nodata("-32768");
        spec.layout = layout;
        spec.compression = compression;
        let path = dir.path().join(format!("n48_{k}.tif"));
        spec.write(&path);
        let g = same_in_bands(&[path], &ReadOptions::default(), 97);
        assert_eq!(g.voids_filled, voids as u64);
    }
}

/// A 900 x 700 crop of SRTM1 N48W125 across the edge of its void (the sea), voids kept.
fn n48_crop() -> (usize, usize, Vec<i16>) {
    let bytes = std::fs::read(data("srtm/N48W125.hgt")).expect("read hgt");
    let (w, h, side) = (900usize, 700usize, 3601usize);
    let mut samples = Vec::with_capacity(w * h);
    for y in 1500..1500 + h {
        for x in 2400..2400 + w {
            let i = 2 * (y * side + x);
            samples.push(i16::from_be_bytes([bytes[i], bytes[i + 1]]));
        }
    }
    (w, h, samples)
}

/// Columns `x0..x1` and rows `y0..y1` of the crop as a geographic GeoTIFF placed where they
/// lie in it.
fn n48_piece(path: &std::path::Path, (x0, x1): (usize, usize), (y0, y1): (usize, usize)) {
    use common::{Layout, Samples, TiffSpec};
    let (w, _, all) = n48_crop();
    let step = 1.0 / 3600.0;
    let samples: Vec<i16> = (y0..y1)
        .flat_map(|y| all[y * w + x0..y * w + x1].to_vec())
        .collect();
    let mut spec = TiffSpec::new((x1 - x0) as u32, (y1 - y0) as u32, Samples::I16(samples))
        .geographic(-124.5 + x0 as f64 * step, 47.4 - y0 as f64 * step, step)
        .nodata("-32768");
    spec.layout = Layout::Tiles {
        width: 32,
        height: 32,
    };
    spec.compression = 8;
    spec.write(path);
}

/// GeoTIFFs side by side (overlapping by a row and a column where they meet, as SRTM and
/// Copernicus tiles do) are the grid they were cut from, read whole and in bands; holes,
/// misaligned files and other spacings are refused with one line.
#[test]
fn geotiff_mosaics_are_the_grid_they_were_cut_from() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = |name: &str| dir.path().join(name);
    n48_piece(&p("whole.tif"), (0, 900), (0, 700));
    n48_piece(&p("nw.tif"), (0, 451), (0, 351));
    n48_piece(&p("ne.tif"), (450, 900), (0, 351));
    n48_piece(&p("sw.tif"), (0, 451), (350, 700));
    n48_piece(&p("se.tif"), (450, 900), (350, 700));
    let opts = ReadOptions::default();
    let whole = dem::read(&[p("whole.tif")], &opts).expect("read whole");
    // Given in any order.
    let pieces = [p("se.tif"), p("nw.tif"), p("sw.tif"), p("ne.tif")];
    let mosaic = same_in_bands(&pieces, &opts, 129);
    assert!(
        mosaic.description.starts_with("GeoTIFF mosaic of 4 files"),
        "{}",
        mosaic.description
    );
    assert_eq!((mosaic.width, mosaic.height), (900, 700));
    assert_eq!(mosaic.voids_filled, whole.voids_filled);
    assert!(whole.voids_filled > 1000);
    assert!(
        mosaic
            .heights
            .iter()
            .zip(&whole.heights)
            .all(|(a, b)| a.to_bits() == b.to_bits()),
        "the mosaic's heights are not the grid's"
    );
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs();
    assert!(close(mosaic.spacing_x, whole.spacing_x) && close(mosaic.spacing_y, whole.spacing_y));
    let (m, w) = (
        mosaic.placement.expect("placed"),
        whole.placement.expect("placed"),
    );
    assert!(
        (m.x0 - w.x0).abs() < 1e-9 && (m.y0 - w.y0).abs() < 1e-9,
        "{m:?} vs {w:?}"
    );

    // A hole where a file is missing.
    let e = dem::read(&pieces[..3], &opts).expect_err("a hole");
    let e = e.to_string();
    assert!(e.contains("do not cover") && !e.contains('\n'), "{e}");
    // A file half a sample off the others' lattice.
    let step = 1.0 / 3600.0;
    {
        use common::{Samples, TiffSpec};
        TiffSpec::new(4, 4, Samples::I16(vec![5; 16]))
            .geographic(-124.5 + 0.5 * step, 47.4 + 10.0 * step, step)
            .write(&p("off.tif"));
        TiffSpec::new(4, 4, Samples::I16(vec![5; 16]))
            .geographic(-124.5, 47.4 + 10.0 * step, 2.0 * step)
            .write(&p("coarse.tif"));
    }
    let e = dem::read(&[p("whole.tif"), p("off.tif")], &opts).expect_err("misaligned");
    assert!(
        e.to_string().contains("off.tif: mismatched mosaic")
            && e.to_string().contains("not aligned"),
        "{e}"
    );
    let e = dem::read(&[p("whole.tif"), p("coarse.tif")], &opts).expect_err("other spacing");
    assert!(
        e.to_string().contains("coarse.tif: mismatched mosaic") && e.to_string().contains("apart"),
        "{e}"
    );
    // Two files in one place.
    let e = dem::read(&[p("nw.tif"), p("nw.tif")], &opts).expect_err("twice");
    assert!(e.to_string().contains("lies where"), "{e}");
}

/// A grid read in bands may be far larger than one read whole: a raw 65537² file (4.3 G
/// samples, the scale issue's 64K set; sparse, so nothing is written to disk) opens as a
/// stream and reads a band, while reading it whole is refused with one line that names the
/// limit and the way round it; past the banded limit, the stream is refused too.
#[test]
fn a_grid_larger_than_one_read_whole_streams_in_bands() {
    let dir = tempfile::tempdir().expect("temp dir");
    let sparse = |name: &str, side: usize| {
        let path = dir.path().join(name);
        let file = std::fs::File::create(&path).expect("create");
        file.set_len(2 * (side * side) as u64)
            .expect("a sparse file");
        let opts = ReadOptions {
            size: Some((side, side)),
            spacing: Some(90.0),
            ..Default::default()
        };
        (vec![path], opts)
    };
    let (paths, opts) = sparse("big.r16", 65537);
    const { assert!(65537u64 * 65537 > dem::MAX_SAMPLES) };
    let stream = dem::open_unscanned(&paths, &opts, (0.0, 0.0)).expect("opens in bands");
    assert_eq!((stream.width, stream.height), (65537, 65537));
    let band = stream.rows(40_000, 40_002).expect("a band");
    assert!(band.len() == 2 * 65537 && band.iter().all(|&h| h == 0.0));
    let whole = dem::read(&paths, &opts).expect_err("too large to read whole");
    let line = whole.to_string();
    assert!(
        line.contains("big.r16")
            && line.contains("more than the limit of 2147483648 samples for a grid read whole")
            && !line.contains('\n'),
        "{line}"
    );
    // One past the banded limit's square root (2^18 = 262144 a side).
    let (paths, opts) = sparse("huge.r16", 262_145);
    let refused = dem::open_unscanned(&paths, &opts, (0.0, 0.0)).err();
    let line = refused.expect("past the banded limit").to_string();
    assert!(
        line.contains("more than the limit of 68719476736 samples"),
        "{line}"
    );
}
