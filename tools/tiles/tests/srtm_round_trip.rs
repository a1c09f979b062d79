//! Builds real SRTM data into a tile set and checks it with the independent verifier.
//! Reads the `.hgt` bytes directly (no DEM crate) so the tile model is tested on its own.

use testdata::data;

use tiles::{build_tileset, verify::verify, BuildParams, Grid, TileSet, TileSetMeta};

/// A crop of an SRTM3 tile in metres (N55W003 has no voids).
fn srtm_crop(x0: usize, y0: usize, w: usize, h: usize) -> Vec<f32> {
    let bytes = std::fs::read(data("srtm/N55W003.hgt")).expect("readable hgt");
    let mut out = Vec::with_capacity(w * h);
    for y in y0..y0 + h {
        for x in x0..x0 + w {
            let i = 2 * (y * 1201 + x);
            out.push(f32::from(i16::from_be_bytes([bytes[i], bytes[i + 1]])));
        }
    }
    out
}

#[test]
fn odd_sized_crop_builds_and_verifies_against_its_source() {
    // 300 x 190: two tiles across (the second 43 samples wide, odd), one down, partial.
    let (w, h) = (300, 190);
    let heights = srtm_crop(100, 200, w, h);
    let grid = Grid {
        width: w,
        height: h,
        heights: &heights,
        spacing_x: 53.2,
        spacing_y: 92.6,
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("crop.vkt");
    let params = BuildParams {
        levels: 7,
        base_error: 1.0,
        ..BuildParams::default()
    };
    let summary =
        build_tileset(&grid, &params, &TileSetMeta::default(), &out, &|| {}).expect("build");
    assert_eq!(summary.tiles, 2);
    let set = TileSet::open(&out).expect("open");
    let report = verify(&set, Some(&grid));
    assert!(report.ok(), "{:#?}", report.problems);
    for (i, &e) in report.recomputed_max_error.iter().enumerate() {
        let bound = params.level_error(i as u32);
        assert!(e <= bound, "level {i}: {e} > {bound}");
        assert!(e > 0.0);
    }
    // Finer levels hold more vertices.
    let tile = set.tile(0, 0).expect("tile");
    let counts: Vec<u32> = tile.levels().iter().map(|l| l.vertex_count()).collect();
    assert!(counts.windows(2).all(|w| w[0] < w[1]), "{counts:?}");
    // No temporary file left behind.
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .expect("dir")
        .map(|e| e.expect("entry").file_name())
        .collect();
    assert_eq!(names.len(), 1, "{names:?}");
}
