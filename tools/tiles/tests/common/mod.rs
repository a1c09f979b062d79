//! Helpers shared by the tile model's integration tests.

use testdata::data;

/// A crop of the `n x n` SRTM tile `name` (of the shared data) in metres, as stored (a void
/// reads -32768). Reads the `.hgt` bytes directly (no DEM crate), so that the tile model is
/// tested on its own.
pub fn hgt_crop(
    name: &str,
    n: usize,
    (x0, y0): (usize, usize),
    (w, h): (usize, usize),
) -> Vec<f32> {
    let bytes = std::fs::read(data(name)).expect("readable hgt");
    let mut out = Vec::with_capacity(w * h);
    for y in y0..y0 + h {
        for x in x0..x0 + w {
            let i = 2 * (y * n + x);
            out.push(f32::from(i16::from_be_bytes([bytes[i], bytes[i + 1]])));
        }
    }
    out
}

/// A `w x h` grid of `heights` at SRTM3's spacing near 55 N (N55W003's crops).
#[allow(dead_code)]
pub fn srtm3_grid(heights: &[f32], (w, h): (usize, usize)) -> tiles::Grid<'_> {
    tiles::Grid {
        width: w,
        height: h,
        first_row: 0,
        heights,
        spacing_x: 53.2,
        spacing_y: 92.6,
    }
}

/// A `w x h` crop of the SRTM3 tile N41E001 from column 0, row 416 (inland Catalonia north of
/// Tarragona, 278-1,017 m, no voids; rough ground, every level distinct), built as
/// `dir/relief.vkt`: 67.5 x 92.6 m spacing, 9 levels, base error 1 m, shared sides. (Until
/// 2026-12-08 a crop of N43E007 whose roughness was 18 voids read as -32768 m.)
#[allow(dead_code)]
pub fn relief_set(dir: &std::path::Path, (w, h): (usize, usize)) -> std::path::PathBuf {
    let heights = hgt_crop("srtm/N41E001.hgt", 1201, (0, 416), (w, h));
    let grid = tiles::Grid {
        width: w,
        height: h,
        first_row: 0,
        heights: &heights,
        spacing_x: 67.5,
        spacing_y: 92.6,
    };
    let out = dir.join("relief.vkt");
    let params = tiles::BuildParams {
        levels: 9,
        base_error: 1.0,
        ..tiles::BuildParams::default()
    };
    let meta = tiles::TileSetMeta::default();
    tiles::build_tileset(&grid, &params, &meta, &out, &|| {}).expect("build");
    out
}
