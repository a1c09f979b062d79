//! The morph units of a set with shared sides come from the input's scan alone
//! (`tiles::units`), so that every shard of a distributed build seals its tiles at the set's
//! units; where a tile's deviation passes the scan's bound, the merge seals it again.

mod common;

use std::path::{Path, PathBuf};

use common::hgt_crop;
use tiles::shard::{build_shard, merge, tile_ranges, MergeSummary, Scans, Shard};
use tiles::units::deviation_bounds;
use tiles::{build_tileset, BuildParams, Grid, TileSet, TileSetMeta};

/// 3 x 3 tiles of the SRTM1 tile N48W125 (Vancouver Island's mountains, 796 m of relief, a
/// window without voids), at its own spacing: rough ground at 21 x 31 m, where a coarse level's
/// spacing rule leaves triangles far over its error. (These tests ran on a crop of N43E007
/// until 2026-12-08, whose roughness was its voids read as -32768 m.)
const SIZE: (usize, usize) = (769, 769);
/// Where the window starts in the tile.
const ORIGIN: (usize, usize) = (2368, 2368);
/// A crop of the same window whose last tiles' data end on an odd column and row (255 and
/// 247), so that they are meshed one column and row further, copies of the last. Its edges
/// are steep enough that, were those copies not held within each level's error, finer vertices
/// on them would pass the bounds of levels 4-7 (checked by leaving them out of refinement).
const PADDED: ((usize, usize), (usize, usize)) = (ORIGIN, (768, 760));
/// SRTM1's spacing at 48.5 N: 1 arc-second east and north.
const SPACING: (f64, f64) = (20.6, 30.9);

fn mountains() -> Vec<f32> {
    crop((ORIGIN, SIZE))
}

fn crop((origin, size): ((usize, usize), (usize, usize))) -> Vec<f32> {
    hgt_crop("srtm/N48W125.hgt", 3601, origin, size)
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
    set_units(&TileSet::open(path).expect("open"))
}

/// [`stored_units`] of an open set (or one of its pyramid layers).
fn set_units(set: &TileSet) -> Vec<f32> {
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

/// Shard `shard` of `grid` built into `part` with `params` and `meta`, a halo of 2, and the
/// scans `scans` given (as `--scans` gives them) or none (each shard scans for itself).
fn shard_part(
    (grid, params, meta): (&Grid, &BuildParams, &TileSetMeta),
    scans: Option<&Scans>,
    shard: Shard,
    part: &Path,
) {
    let recipe = "units test";
    build_shard(
        grid,
        params,
        None,
        meta,
        (shard, 2),
        scans,
        recipe,
        part,
        &|| {},
    )
    .expect("shard");
}

/// `parts` merged into `out`, which needs no input (their seams settled by their halos).
fn merged(parts: &[PathBuf], out: &Path) -> Result<MergeSummary, tiles::BuildError> {
    let reopen = |_: &str| -> Result<_, tiles::BuildError> {
        Err(tiles::BuildError::Params(
            "the merge needs no input here".into(),
        ))
    };
    merge(parts, out, &reopen, &|| {})
}

/// Shards `0..n` of the grid built into `dir` with the scans `scans` given, then merged; the
/// merge's summary and the set.
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
            shard_part((grid, &params(), &meta), Some(scans), shard, &part);
            part
        })
        .collect();
    let out = dir.join(format!("merged.{n}.vkt"));
    (merged(&parts, &out).expect("merge"), out)
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
    for (origin, size) in [PADDED, (ORIGIN, SIZE)] {
        let heights = crop((origin, size));
        let grid = sized(&heights, size);
        let out = dir.path().join(format!("mountains-{}.vkt", size.0));
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
    let heights = mountains();
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
    let heights = mountains();
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

/// The whole SRTM3 tile N55W003 (southern Scotland, no voids): 5 x 5 tiles, three pyramid
/// layers.
fn scotland() -> Vec<f32> {
    hgt_crop("srtm/N55W003.hgt", 1201, (0, 0), (1201, 1201))
}

/// [`scotland`]'s heights as a grid, at SRTM3's spacing there (3 arc-seconds at 55.5 N).
fn scotland_grid(heights: &[f32]) -> Grid<'_> {
    Grid {
        spacing_x: 52.5,
        spacing_y: 92.6,
        ..sized(heights, (1201, 1201))
    }
}

/// [`params`] with a tile pyramid.
fn pyramid_params() -> BuildParams {
    BuildParams {
        pyramid: true,
        ..params()
    }
}

/// A pyramid's layers take their units from bounds that every shard finds alike from the scans
/// (`tiles::units::layer_deviation_bounds`), so no layer tile's deviation raises them and a
/// sharded build's merge seals no layer tile again: N55W003 (three layers), unsharded and in
/// 3 shards, the same bytes. The control: without the decimation error's share in the bound
/// (bounds of `e_i`, as the layers' units had before), the layer tiles' stored offsets reach
/// past it, so their units followed their tiles' deviations, and a shard's would be its own
/// tiles'.
#[test]
fn a_pyramids_layer_units_are_the_bounds_of_its_scans() {
    use tiles::build::Heights;
    use tiles::pyramid::Decimated;
    use tiles::units::{cell_spans, decimation_bound, layer_deviation_bounds};

    let heights = scotland();
    let grid = scotland_grid(&heights);
    let params = pyramid_params();
    let dir = tempfile::tempdir().expect("temp dir");
    let built = dir.path().join("built.vkt");
    build_tileset(&grid, &params, &TileSetMeta::default(), &built, &|| {}).expect("build");
    let set = TileSet::open(&built).expect("open");
    assert_eq!(set.pyramid_layers(), 3);

    let max_abs = heights.iter().fold(0.0f32, |m, h| m.max(h.abs()));
    let spans_of = |g: &Grid| {
        let tiles = |n: usize| (n - 1).div_ceil(256) as u32;
        cell_spans(g, tiles(g.width), 0..tiles(g.height)).0
    };
    let mut size_two = vec![spans_of(&grid)[0]];
    let mut passed_without_floor = Vec::new();
    for p in 1..=set.pyramid_layers() {
        let layer = set.layer(p).expect("layer");
        let decimated = Decimated::new(&grid, p);
        let shape = decimated.shape();
        let rows = decimated.rows(0, shape.height).expect("rows").into_owned();
        let layer_grid = Grid {
            heights: &rows,
            ..shape
        };
        let spans = spans_of(&layer_grid);
        let spacing = layer_grid.spacing_x.min(layer_grid.spacing_y);
        let step = layer.header().height_step;
        let bounds = layer_deviation_bounds(
            &params,
            spacing,
            step,
            &spans,
            decimation_bound(&size_two, max_abs),
        );
        let want: Vec<f32> = bounds
            .iter()
            .map(|&b| tiles::pack::morph_unit(b, 0.0) as f32)
            .collect();
        assert_eq!(
            set_units(&layer),
            want,
            "layer {p}: a tile raised a unit past its bound"
        );
        // The control: the largest offset stored onto each level, against the bound without
        // the floor.
        let plain = layer_deviation_bounds(&params, spacing, step, &spans, 0.0);
        let (tx, ty) = (layer.header().tiles_x, layer.header().tiles_y);
        for t in 0..tx * ty {
            let tile = layer.tile(t % tx, t / tx).expect("tile");
            for j in 1..tile.header.levels {
                let block = tile.level(j).expect("level");
                let n = block.entry.block_len as usize;
                for k in 0..j as usize {
                    let unit = f64::from(want[k]);
                    let widest = block.morph[k * n..(k + 1) * n]
                        .iter()
                        .fold(0i32, |m, &o| m.max(i32::from(o).abs()));
                    if f64::from(widest) * unit - unit / 2.0 > plain[k] {
                        passed_without_floor.push((p, t, k));
                    }
                }
            }
        }
        size_two.push(spans[0]);
    }
    assert!(
        !passed_without_floor.is_empty(),
        "no layer tile's offset passed the bounds without the decimation error's share"
    );

    // In 3 shards, each scanning the layers itself: no layer tile sealed again, and the
    // build's bytes.
    let parts: Vec<PathBuf> = (0..3)
        .map(|index| {
            let part = dir.path().join(format!("part.{index}"));
            let shard = Shard { index, count: 3 };
            shard_part(
                (&grid, &params, &TileSetMeta::default()),
                None,
                shard,
                &part,
            );
            part
        })
        .collect();
    let set = dir.path().join("merged.vkt");
    let summary = merged(&parts, &set).expect("merge");
    assert_eq!(summary.pyramid_resealed, 0, "layer tiles sealed again");
    assert!(summary.pyramid_tiles > 0);
    assert_eq!(
        std::fs::read(&set).expect("merged"),
        std::fs::read(&built).expect("built"),
        "the merged pyramid differs from the build"
    );
}

/// Parts whose scans give other morph unit bounds belong to no one set: the merge refuses
/// them with one line naming the part, for the base grid's bounds (the second part's scan
/// forged, its cell spans doubled) and for a pyramid layer's (its layer 1 scan's cell spans
/// doubled), and leaves no set behind. The control: the same shards with the same
/// scans merge.
#[test]
fn parts_whose_scans_give_other_bounds_are_refused() {
    let heights = scotland();
    let grid = scotland_grid(&heights);
    let params = pyramid_params();
    let real = Scans {
        layers: Some(
            tiles::shard::layer_scans(&grid, Shard { index: 0, count: 1 }).expect("layers"),
        ),
        ..scans_of(&grid, None)
    };
    let mut other_base = real.clone();
    for span in other_base.spans.iter_mut() {
        *span *= 2.0;
    }
    let mut other_layer = real.clone();
    for span in other_layer.layers.as_mut().expect("layers")[0]
        .spans
        .iter_mut()
    {
        *span *= 2.0;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let part = |index: u32, scans: &Scans, name: &str| {
        let path = dir.path().join(name);
        let shard = Shard { index, count: 2 };
        shard_part(
            (&grid, &params, &TileSetMeta::default()),
            Some(scans),
            shard,
            &path,
        );
        path
    };
    let first = part(0, &real, "first");
    let out = dir.path().join("set.vkt");
    for (scans, name, what) in [
        (&other_base, "base", "morph unit bounds differ"),
        (&other_layer, "layer", "its scan of pyramid layer 1 differs"),
    ] {
        let second = part(1, scans, name);
        let refused =
            merged(&[first.clone(), second], &out).expect_err("parts of other bounds merged");
        let line = refused.to_string();
        assert!(line.contains(name) && line.contains(what), "{line}");
        assert!(!out.exists(), "a refused merge left a set");
    }
    let second = part(1, &real, "second");
    merged(&[first, second], &out).expect("the control's merge");
}
