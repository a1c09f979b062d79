//! The morph units of a set with shared sides come from the input's scan alone
//! (`tiles::units`), so that every shard of a distributed build seals its tiles at the set's
//! units; where a tile's deviation passes the scan's bound, the merge seals it again.

mod common;

use std::path::{Path, PathBuf};

use common::hgt_crop;
use tiles::shard::{build_shard, merge, tile_ranges, MergeSummary, Scans, Shard};
use tiles::units::deviation_bounds;
use tiles::{build_tileset, BuildParams, Grid, TileSet, TileSetMeta};

/// 3 x 3 tiles of the SRTM3 tile N43E007 (the Alps: rough ground, where a coarse level's
/// spacing rule leaves triangles far over its error).
const SIZE: (usize, usize) = (769, 769);
/// A crop (from the tile's north-west corner) whose last tiles' data end on an odd column and
/// row (255 and 247), so that they are meshed one column and row further, copies of the last.
/// Its edges are steep enough that, were those copies not held within each level's error,
/// finer vertices on them would pass the bounds of levels 2-7.
const PADDED: ((usize, usize), (usize, usize)) = ((0, 0), (768, 760));
const SPACING: (f64, f64) = (67.5, 92.6);

fn alps() -> Vec<f32> {
    crop(((300, 300), SIZE))
}

fn crop((origin, size): ((usize, usize), (usize, usize))) -> Vec<f32> {
    hgt_crop("srtm/N43E007.hgt", 1201, origin, size)
}

fn grid(heights: &[f32]) -> Grid<'_> {
    sized(heights, SIZE)
}

fn sized(heights: &[f32], (width, height): (usize, usize)) -> Grid<'_> {
    Grid {
        width,
        height,
        first_row: 0,
        heights,
        spacing_x: SPACING.0,
        spacing_y: SPACING.1,
    }
}

fn params() -> BuildParams {
    BuildParams {
        levels: 9,
        base_error: 1.0,
        ..BuildParams::default()
    }
}

/// Every tile's stored morph unit per level (all tiles of a set with shared sides hold the
/// same).
fn stored_units(path: &Path) -> Vec<f32> {
    let set = TileSet::open(path).expect("open");
    let (tx, ty) = (set.header().tiles_x, set.header().tiles_y);
    let mut units: Option<Vec<f32>> = None;
    for t in 0..tx * ty {
        let tile = set.tile(t % tx, t / tx).expect("tile");
        let these: Vec<f32> = tile.levels().iter().map(|e| e.morph_unit).collect();
        match &units {
            None => units = Some(these),
            Some(u) => assert_eq!(u, &these, "tile {t}'s units differ from tile 0's"),
        }
    }
    units.expect("a tile")
}

/// Shards `0..n` of the grid built into `dir` with the scans `scans` given (as `--scans`
/// gives them), then merged; the merge's summary and the set.
fn sharded(
    grid: &Grid,
    scans: &Scans,
    n: u32,
    compact: bool,
    dir: &Path,
) -> (MergeSummary, PathBuf) {
    let meta = TileSetMeta {
        compact,
        ..TileSetMeta::default()
    };
    let parts: Vec<PathBuf> = (0..n)
        .map(|index| {
            let part = dir.join(format!("part.{index}.of.{n}"));
            let shard = Shard { index, count: n };
            build_shard(
                grid,
                &params(),
                None,
                &meta,
                (shard, 2),
                Some(scans),
                "alps",
                &part,
                &|| {},
            )
            .expect("shard");
            part
        })
        .collect();
    let out = dir.join(format!("merged.{n}.vkt"));
    let reopen = |_: &str| -> Result<_, tiles::BuildError> {
        Err(tiles::BuildError::Params(
            "the merge needs no input here".into(),
        ))
    };
    let summary = merge(&parts, &out, &reopen, &|| {}).expect("merge");
    (summary, out)
}

/// The whole grid's scan as the shards' scans give it, with its cell spans replaced.
fn scans_of(grid: &Grid, spans: Option<tiles::units::CellSpans>) -> Scans {
    let ranges = tile_ranges(grid, Shard { index: 0, count: 1 }).expect("ranges");
    let (lo, hi) = grid
        .heights
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        });
    Scans {
        lo,
        hi,
        max_range: ranges.max_range,
        max_abs: ranges.max_abs,
        spans: spans.unwrap_or(ranges.spans),
        voids: 0,
        layers: None,
    }
}

/// The set's units are its scan's bounds, to the bit: no tile's deviation raised one, on
/// both crops (the padded one's edge tiles are refined so that their copied column and row
/// hold within each level's error too). The control: with the scan's cell spans taken away
/// (bounds of `e_i` plus two steps), the same tiles' deviations raise the coarse levels'
/// units, so on this ground the units would depend on which tiles a shard holds.
#[test]
fn a_sets_morph_units_are_the_bounds_of_its_scan() {
    let dir = tempfile::tempdir().expect("temp dir");
    let spacing = SPACING.0.min(SPACING.1);
    let mut step = 0.0;
    let mut from_bounds = Vec::new();
    for (origin, size) in [PADDED, ((300, 300), SIZE)] {
        let heights = crop((origin, size));
        let grid = sized(&heights, size);
        let out = dir.path().join(format!("alps-{}.vkt", size.0));
        build_tileset(&grid, &params(), &TileSetMeta::default(), &out, &|| {}).expect("build");
        step = TileSet::open(&out).expect("open").header().height_step;
        let bounds = deviation_bounds(&params(), spacing, step, &scans_of(&grid, None).spans);
        from_bounds = bounds
            .iter()
            .map(|&b| tiles::pack::morph_unit(b, 0.0) as f32)
            .collect();
        assert_eq!(
            stored_units(&out),
            from_bounds,
            "{size:?}: a tile raised a unit past its bound"
        );
    }
    let heights = alps();
    let grid = grid(&heights);

    // The control: one shard of all the tiles, its scan without cell spans (its tiles sealed
    // at the scan's units, which the merge raises to their deviations).
    let (_, without) = sharded(
        &grid,
        &scans_of(&grid, Some([0.0; 8])),
        1,
        false,
        dir.path(),
    );
    let plain = deviation_bounds(&params(), spacing, step, &[0.0; 8]);
    let units = stored_units(&without);
    let raised: Vec<usize> = (0..units.len())
        .filter(|&k| units[k] > tiles::pack::morph_unit(plain[k], 0.0) as f32)
        .collect();
    assert!(
        !raised.is_empty() && raised.iter().all(|&k| units[k] <= from_bounds[k]),
        "without spans no tile raised a unit, or one passed the scan's bound: {units:?} against {from_bounds:?}"
    );
}

/// Where a tile's final deviation passes the bound, the units rise to it: a shard seals its
/// tiles at the scan's units (their offsets clamped) and records the deviations, and the
/// merge raises the set's units and seals every tile again, version 3 blobs and compact
/// streams alike; an unsharded build is built again at the raised bounds. All three give the
/// same bytes, which verify against the source (the offsets are not clamped). Forced here by
/// scans (and bounds) without cell spans; with the scan's spans the same shards' merge copies
/// every tile, and is the build's bytes.
#[test]
fn tiles_past_their_bounds_raise_the_units() {
    let heights = alps();
    let grid = grid(&heights);
    for compact in [false, true] {
        let dir = tempfile::tempdir().expect("temp dir");
        let forged = scans_of(&grid, Some([0.0; 8]));
        let (one, whole) = sharded(&grid, &forged, 1, compact, dir.path());
        let (three, merged) = sharded(&grid, &forged, 3, compact, dir.path());
        assert!(
            one.resealed == 9 && three.resealed == 9,
            "compact {compact}: {} and {} of 9 tiles sealed again",
            one.resealed,
            three.resealed
        );
        assert_eq!(
            std::fs::read(&merged).expect("merged"),
            std::fs::read(&whole).expect("whole"),
            "compact {compact}: sealed again, the set differs from one shard's"
        );
        let set = TileSet::open(&merged).expect("open");
        let report = tiles::verify::verify(&set, Some(&grid));
        assert!(report.ok(), "compact {compact}: {:#?}", report.problems);
        // The unsharded build at the same bounds: built again at raised ones, the same bytes.
        let step = set.header().height_step;
        let plain = deviation_bounds(&params(), SPACING.0.min(SPACING.1), step, &[0.0; 8]);
        let again = dir.path().join("again.vkt");
        let meta = TileSetMeta {
            compact,
            ..TileSetMeta::default()
        };
        tiles::build::build_tileset_at(
            &grid,
            &params(),
            (None, &meta),
            &again,
            &|| {},
            Some(plain),
        )
        .expect("build");
        assert_eq!(
            std::fs::read(&again).expect("again"),
            std::fs::read(&whole).expect("whole"),
            "compact {compact}: built again at raised bounds, the set differs from the merge's"
        );

        let real = scans_of(&grid, None);
        let sub = dir.path().join("real");
        std::fs::create_dir(&sub).expect("dir");
        let (three, merged) = sharded(&grid, &real, 3, compact, &sub);
        assert_eq!(
            three.resealed, 0,
            "compact {compact}: the scan's bounds left tiles to seal"
        );
        let built = sub.join("built.vkt");
        let meta = TileSetMeta {
            compact,
            ..TileSetMeta::default()
        };
        build_tileset(&grid, &params(), &meta, &built, &|| {}).expect("build");
        assert_eq!(
            std::fs::read(&merged).expect("merged"),
            std::fs::read(&built).expect("built"),
            "compact {compact}: the merged set differs from the build"
        );
        // The comparison can fail: the forged scans made other units.
        assert_ne!(stored_units(&merged), stored_units(&whole));
    }
}
