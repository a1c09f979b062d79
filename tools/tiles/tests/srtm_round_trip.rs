//! Builds real SRTM data into a tile set and checks it with the independent verifier.
//! Reads the `.hgt` bytes directly (no DEM crate) so the tile model is tested on its own.

use std::mem::size_of;

mod common;

use common::hgt_crop;
use tiles::{build_tileset, verify::verify, BuildParams, Grid, TileSet, TileSetMeta};

/// A crop of an SRTM3 tile in metres (N55W003 has no voids).
fn srtm_crop(x0: usize, y0: usize, w: usize, h: usize) -> Vec<f32> {
    hgt_crop("srtm/N55W003.hgt", 1201, (x0, y0), (w, h))
}

#[test]
fn odd_sized_crop_builds_and_verifies_against_its_source() {
    // 300 x 190: two tiles across (the second 43 samples wide, odd), one down, partial.
    let (w, h) = (300, 190);
    let heights = srtm_crop(100, 200, w, h);
    let grid = common::srtm3_grid(&heights, (w, h));
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

/// Each level records its error near each side (over its triangles that touch the side, a
/// bound for side level tables), and `verify` recomputes it: never below
/// what it is, at most a code step above. Where coast meets sea (SRTM1 N48W125, no voids in
/// this crop), many sides' errors are well below their tile's, which is what the codes are
/// for; on ground rugged all over they are close to it. The controls: a code
/// lowered (understating the side) and one raised to the whole level's error are both caught;
/// code 0, what files from before the codes hold, reads as the whole level's error and passes.
#[test]
fn errors_near_each_side_are_recorded_and_verified() {
    use tiles::format::{reseal, side_error_of, LevelEntry, TileHeader};
    let (w, h) = (513, 513);
    let heights = hgt_crop("srtm/N48W125.hgt", 3601, (2400, 2400), (w, h));
    assert!(heights.iter().all(|&z| z > -1000.0), "a void in the crop");
    let grid = Grid {
        width: w,
        height: h,
        first_row: 0,
        heights: &heights,
        spacing_x: 20.6,
        spacing_y: 30.9,
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("sides.vkt");
    let params = BuildParams {
        levels: 7,
        base_error: 1.0,
        ..BuildParams::default()
    };
    build_tileset(&grid, &params, &TileSetMeta::default(), &out, &|| {}).expect("build");
    let set = TileSet::open(&out).expect("open");
    let report = verify(&set, Some(&grid));
    assert!(report.ok(), "{:#?}", report.problems);

    // Every code recorded, every side's error at most the level's; many well below it.
    let (mut sides, mut below_half) = (0, 0);
    let mut target = None;
    for ty in 0..2 {
        for tx in 0..2 {
            let tile = set.tile(tx, ty).expect("tile");
            for (k, l) in tile.levels().iter().enumerate() {
                for s in 0..4 {
                    assert_ne!(l.side_errors[s], 0, "tile {tx},{ty} level {k} side {s}");
                    assert!(l.side_error(s) <= l.max_error);
                    sides += 1;
                    below_half += usize::from(l.side_error(s) < 0.5 * l.max_error);
                    // The controls' side: room for two codes below and many above, on a
                    // level whose code step is well over verify's tolerance.
                    let code = l.side_errors[s];
                    if (3..=200).contains(&code) && l.max_error > 4.0 && target.is_none() {
                        target = Some((tx, ty, k, s, code));
                    }
                }
            }
        }
    }
    eprintln!("{below_half} of {sides} side errors under half their level's");
    assert!(
        below_half * 5 >= sides,
        "only {below_half} of {sides} side errors are under half their level's"
    );
    let (tx, ty, k, s, code) = target.expect("a side error well under its level's");
    eprintln!("controls on tile {tx},{ty} level {k} side {s}, code {code}");
    let max_error = set.tile(tx, ty).expect("tile").levels()[k].max_error;
    let at = set.dir_entry(tx, ty).expect("entry").offset as usize
        + size_of::<TileHeader>()
        + k * size_of::<LevelEntry>()
        + std::mem::offset_of!(LevelEntry, side_errors)
        + s;
    drop(set);
    let bytes = std::fs::read(&out).expect("read");
    let with_code = |c: u8| {
        let mut b = bytes.clone();
        b[at] = c;
        reseal(&mut b).expect("reseal");
        let path = dir.path().join(format!("code{c}.vkt"));
        std::fs::write(&path, b).expect("write");
        let set = TileSet::open(&path).expect("open");
        verify(&set, Some(&grid))
    };
    // Understated by two code steps: a side table built from it would refine too little.
    let lowered = with_code(code - 2);
    assert!(
        lowered.problems.iter().any(|p| p.contains("near side")),
        "code {} for {} m not caught: {:#?}",
        code - 2,
        side_error_of(max_error, code - 2),
        lowered.problems
    );
    let raised = with_code(255);
    assert!(
        raised.problems.iter().any(|p| p.contains("near side")),
        "{:#?}",
        raised.problems
    );
    let unrecorded = with_code(0);
    assert!(unrecorded.ok(), "{:#?}", unrecorded.problems);
}
