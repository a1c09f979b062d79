//! Every real DEM in `../shared/data` goes through the whole preprocessing path (dem reader,
//! tile builder, file writer, mmap reader) and passes the independent verifier against its
//! source: structure, nesting, fans, morph offsets and every level's recomputed error.

use std::path::PathBuf;
use testdata::data;

use dem::{Encoding, ReadOptions};
use tiles::{build_tileset, verify::verify, BuildParams, Grid, TileSet, TileSetMeta};

fn build_and_verify(files: &[&str], opts: ReadOptions, params: BuildParams) {
    let paths: Vec<PathBuf> = files.iter().map(|f| data(f)).collect();
    let grid = dem::read(&paths, &opts).unwrap_or_else(|e| panic!("{e}"));
    let view = Grid {
        width: grid.width,
        height: grid.height,
        first_row: 0,
        heights: &grid.heights,
        spacing_x: grid.spacing_x,
        spacing_y: grid.spacing_y,
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("set.vkt");
    let meta = TileSetMeta {
        description: grid.description.clone(),
        voids_filled: grid.voids_filled,
        compact: false,
    };
    let summary = build_tileset(&view, &params, &meta, &out, &|| {})
        .unwrap_or_else(|e| panic!("{files:?}: {e}"));
    let set = TileSet::open(&out).expect("open");
    let report = verify(&set, Some(&view));
    assert!(
        report.ok(),
        "{files:?}: {:#?}",
        &report.problems[..report.problems.len().min(20)]
    );
    // Where the spacing rule did not stop refinement, every level is within its bound.
    for (i, l) in summary.levels.iter().enumerate() {
        let e = params.level_error(i as u32);
        if l.limited_triangles == 0 {
            assert!(
                l.max_error <= e,
                "{files:?} level {i}: {} > {e}",
                l.max_error
            );
        }
    }
    // The finest level follows the source closely: within its bound or the quantisation.
    let finest = report
        .recomputed_max_error
        .last()
        .copied()
        .unwrap_or(f64::INFINITY);
    assert!(
        finest <= params.base_error.max(1e-3) + 1e-6
            || summary
                .levels
                .last()
                .is_some_and(|l| l.limited_triangles > 0)
    );
}

fn spacing(metres: f64, scale: f64) -> ReadOptions {
    ReadOptions {
        spacing: Some(metres),
        vertical_scale: Some(scale),
        ..Default::default()
    }
}

#[test]
fn puget_1k_png() {
    build_and_verify(
        &["puget/ps_height_1k.png"],
        spacing(160.0, 0.1),
        BuildParams::default(),
    );
}

#[test]
fn puget_4k_jpeg() {
    // 8-bit heights of about 25.7 m a step on a 40 m grid (coarse: a scale test).
    build_and_verify(
        &["puget/ps_height_4k_8bit.jpg"],
        spacing(40.0, 25.7),
        BuildParams {
            levels: 9,
            base_error: 4.0,
            ..BuildParams::default()
        },
    );
}

#[test]
fn srtm3_tiles_and_mosaic() {
    for f in ["srtm/N43E007.hgt", "srtm/N55W003.hgt"] {
        build_and_verify(&[f], ReadOptions::default(), BuildParams::default());
    }
    build_and_verify(
        &["srtm/N41E001.hgt", "srtm/N42E001.hgt"],
        ReadOptions::default(),
        BuildParams::default(),
    );
}

#[test]
fn srtm1_half_void() {
    build_and_verify(
        &["srtm/N48W125.hgt"],
        ReadOptions::default(),
        BuildParams::default(),
    );
}

#[test]
fn geotiffs() {
    for f in [
        "geotiff/mt_rainier_90m.tif",
        "geotiff/mt_fuji_90m.tif",
        "geotiff/bigtujunga.tif",
    ] {
        build_and_verify(&[f], ReadOptions::default(), BuildParams::default());
    }
}

#[test]
fn terrain_rgb_tiles() {
    let rgb = |spacing| ReadOptions {
        encoding: Some(Encoding::TerrainRgb),
        spacing,
        ..Default::default()
    };
    // Fuji's tile has no z-x-y in its name: the spacing must be given.
    build_and_verify(
        &["terrainrgb/fuji_terrain_rgb.png"],
        rgb(Some(30.0)),
        BuildParams {
            levels: 8,
            base_error: 0.5,
            ..BuildParams::default()
        },
    );
    build_and_verify(
        &["terrainrgb/berkeley_14-2625-6369_terrain_rgb.png"],
        rgb(None),
        BuildParams {
            levels: 8,
            base_error: 0.25,
            ..BuildParams::default()
        },
    );
}
