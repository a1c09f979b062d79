//! Helpers shared by the renderer's integration tests: real data paths and tile sets built
//! from them.

#![allow(dead_code)] // each test file uses its own subset

use std::path::{Path, PathBuf};

use tiles::{build_tileset, BuildParams, Grid, TileSetMeta};

pub fn data(rel: &str) -> PathBuf {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data")).join(rel);
    assert!(
        p.exists(),
        "test data missing: {} (the shared data folder must sit beside the repo)",
        p.display()
    );
    p
}

pub fn sample() -> PathBuf {
    let p = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../sample/ps_height_1k.png"
    ));
    assert!(p.exists(), "bundled sample missing: {}", p.display());
    p
}

/// Builds a tile set in `dir` from a DEM.
pub fn tileset(dir: &Path, input: &Path, opts: dem::ReadOptions) -> PathBuf {
    tileset_of(dir, &[input.to_path_buf()], opts)
}

/// Builds a tile set in `dir` from DEM files read together (an SRTM mosaic).
pub fn tileset_of(dir: &Path, inputs: &[PathBuf], opts: dem::ReadOptions) -> PathBuf {
    let grid = dem::read(inputs, &opts).unwrap_or_else(|e| panic!("{e}"));
    let view = Grid {
        width: grid.width,
        height: grid.height,
        heights: &grid.heights,
        spacing_x: grid.spacing_x,
        spacing_y: grid.spacing_y,
    };
    let out = dir.join("set.vkt");
    build_tileset(
        &view,
        &BuildParams::default(),
        &TileSetMeta::default(),
        &out,
        &|| {},
    )
    .expect("build");
    out
}

pub fn puget(dir: &Path) -> PathBuf {
    tileset(
        dir,
        &sample(),
        dem::ReadOptions {
            spacing: Some(160.0),
            vertical_scale: Some(0.1),
            ..Default::default()
        },
    )
}
