//! Helpers shared by the renderer's integration tests: real data paths and tile sets built
//! from them.

#![allow(dead_code)] // each test file uses its own subset

use std::path::{Path, PathBuf};

use tiles::{build_tileset, BuildParams, Grid, TileSetMeta};

// Each test file uses its own subset.
#[allow(unused_imports)]
pub use testdata::{data, sample};

/// Builds a tile set in `dir` from a DEM.
pub fn tileset(dir: &Path, input: &Path, opts: dem::ReadOptions) -> PathBuf {
    tileset_of(dir, &[input.to_path_buf()], opts)
}

/// Builds a tile set in `dir` from DEM files read together (an SRTM mosaic).
pub fn tileset_of(dir: &Path, inputs: &[PathBuf], opts: dem::ReadOptions) -> PathBuf {
    tileset_with(dir, inputs, opts, &BuildParams::default())
}

/// [`tileset_of`] with build parameters.
pub fn tileset_with(
    dir: &Path,
    inputs: &[PathBuf],
    opts: dem::ReadOptions,
    params: &BuildParams,
) -> PathBuf {
    let grid = dem::read(inputs, &opts).unwrap_or_else(|e| panic!("{e}"));
    let view = Grid {
        width: grid.width,
        height: grid.height,
        heights: &grid.heights,
        spacing_x: grid.spacing_x,
        spacing_y: grid.spacing_y,
    };
    let out = dir.join("set.vkt");
    build_tileset(&view, params, &TileSetMeta::default(), &out, &|| {}).expect("build");
    out
}

/// How the tests read the bundled Puget Sound sample.
pub fn puget_options() -> dem::ReadOptions {
    dem::ReadOptions {
        spacing: Some(160.0),
        vertical_scale: Some(0.1),
        ..Default::default()
    }
}

pub fn puget(dir: &Path) -> PathBuf {
    tileset(dir, &sample(), puget_options())
}

/// The Puget sample built with its tiles' sides independent (no agreement between neighbours).
pub fn puget_independent(dir: &Path) -> PathBuf {
    let params = BuildParams {
        shared_sides: false,
        ..BuildParams::default()
    };
    tileset_with(dir, &[sample()], puget_options(), &params)
}
