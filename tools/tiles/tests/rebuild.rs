//! Issue 28's compact levels store only which vertices each level adds and their heights: the
//! rest of a tile must follow from them. Here it does, on every tile of real SRTM3 data (shared
//! sides, so with the agreement's forced vertices; and a partial crop whose tiles end inside
//! their cells): `fans_from_vertices` gives each stored block and index array back from the
//! vertex sets, and `rebuild_tile` the whole blob, byte for byte, from the sets with their
//! height codes and the stored header and entries; and `tiles::compact`'s bit stream holds
//! exactly those sets, rebuilds the same blob, and is refused when cut short. The control: a
//! level missing one of its vertices gives other fans and another blob in every tile.

mod common;

use tiles::build::{fans_from_vertices, rebuild_tile, Numbering, RebuiltLevel};
use tiles::compact;
use tiles::mesh::TileSamples;
use tiles::{build_tileset, BuildParams, Grid, TileSet, TileSetMeta};

/// A crop of the `n x n` SRTM tile `name` in metres, voids at 0.
fn hgt_crop(name: &str, n: usize, origin: (usize, usize), size: (usize, usize)) -> Vec<f32> {
    let heights = common::hgt_crop(name, n, origin, size);
    heights.into_iter().map(|h| h.max(0.0)).collect()
}

/// Every tile of the set built from `heights` (`w x h`), level by level: the stored block
/// and index array, and what `fans_from_vertices` makes of the vertex sets (with `drop`
/// removing the last vertex of level 1's set first, for the control); and the whole blob,
/// against `rebuild_tile` of the sets with their height codes. Returns the levels compared
/// and how many differed, and the tiles whose blob differed.
fn compare(
    heights: &[f32],
    (w, h): (usize, usize),
    spacing: (f64, f64),
    drop: bool,
) -> (u32, u32, u32) {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("set.vkt");
    let grid = Grid {
        width: w,
        height: h,
        first_row: 0,
        heights,
        spacing_x: spacing.0,
        spacing_y: spacing.1,
    };
    build_tileset(
        &grid,
        &BuildParams::default(),
        &TileSetMeta::default(),
        &path,
        &|| {},
    )
    .expect("built");
    let set = TileSet::open(&path).expect("opened");
    let header = *set.header();
    let file = std::fs::read(&path).expect("read");
    let (mut levels, mut differing, mut blobs_differing) = (0, 0, 0);
    let mut compact_bytes = 0usize;
    for ty in 0..header.tiles_y {
        for tx in 0..header.tiles_x {
            let tile = set.tile(tx, ty).expect("tile");
            let samples = TileSamples {
                heights: vec![0.0; 257 * 257],
                data_max_x: tile.header.data_max_x,
                data_max_y: tile.header.data_max_y,
            };
            let stored: Vec<RebuiltLevel> = (0..header.levels)
                .map(|j| {
                    let level = tile.level(j).expect("level");
                    let block = level
                        .positions
                        .iter()
                        .map(|&p| {
                            let (x, y, _) = tiles::pack::unpack(p);
                            (x, y)
                        })
                        .collect();
                    let indices = level
                        .indices
                        .iter()
                        .map(|i| i.unwrap_or(u32::MAX))
                        .collect();
                    (block, indices)
                })
                .collect();
            let mut sets: Vec<Vec<(u32, u32)>> = stored.iter().map(|(b, _)| b.clone()).collect();
            // Any order will do: the decoder gets sets, not orders.
            for set in &mut sets {
                set.sort_unstable_by_key(|&(x, y)| (y, x));
            }
            let mut coded: Vec<Vec<(u32, u32, u16)>> = (0..header.levels)
                .map(|j| {
                    let level = tile.level(j).expect("level");
                    let mut set: Vec<_> = level
                        .positions
                        .iter()
                        .map(|&p| tiles::pack::unpack(p))
                        .collect();
                    set.sort_unstable_by_key(|&(x, y, _)| (y, x));
                    set
                })
                .collect();
            if drop {
                sets[1].pop();
                coded[1].pop();
            }
            let entry = set.dir_entry(tx, ty).expect("entry");
            let stored_blob = &file[entry.offset as usize..(entry.offset + entry.len) as usize];
            if !drop {
                // The compact bit stream holds exactly the sets, and rebuilds the blob.
                let bytes = compact::encode(&tile);
                let decoded = compact::decode(&bytes, header.levels).expect("decoded");
                let sorted = |sets: compact::LevelSets| -> compact::LevelSets {
                    sets.into_iter()
                        .map(|mut s| {
                            s.sort_unstable_by_key(|&(x, y, _)| (y, x));
                            s
                        })
                        .collect()
                };
                assert_eq!(
                    sorted(decoded),
                    coded,
                    "tile {tx},{ty}: the stream's vertices"
                );
                let from_stream =
                    compact::rebuild(&tile.header, tile.levels(), &bytes, Numbering::Decode);
                assert_eq!(from_stream.as_deref(), Ok(stored_blob), "tile {tx},{ty}");
                // Cut short, it is refused.
                let cut = compact::decode(&bytes[..bytes.len() - 1], header.levels);
                assert!(cut.is_err(), "tile {tx},{ty}: a truncated stream decoded");
                compact_bytes += bytes.len();
            }
            let rebuilt = rebuild_tile(&tile.header, tile.levels(), &coded, Numbering::Decode);
            if rebuilt != stored_blob {
                blobs_differing += 1;
                assert!(
                    drop,
                    "tile {tx},{ty}: the blob does not follow from the vertices and heights"
                );
            }
            let made = fans_from_vertices(&samples, &sets);
            for (j, (made, stored)) in made.iter().zip(&stored).enumerate() {
                levels += 1;
                if made != stored {
                    differing += 1;
                    assert!(
                        drop,
                        "tile {tx},{ty} level {j}: the fans do not follow from the vertices"
                    );
                }
            }
        }
    }
    if !drop {
        eprintln!(
            "{w} x {h}: {compact_bytes} bytes of compact levels, {:.2} B a sample",
            compact_bytes as f64 / (w * h) as f64
        );
    }
    (levels, differing, blobs_differing)
}

#[test]
fn every_tiles_blob_follows_from_its_vertex_sets_and_heights() {
    // SRTM3 N55W003 (rugged, no voids), 4 x 4 tiles.
    let side = 4 * 256 + 1;
    let srtm3 = hgt_crop("srtm/N55W003.hgt", 1201, (100, 100), (side, side));
    let (levels, differing, _) = compare(&srtm3, (side, side), (53.2, 92.6), false);
    assert_eq!((levels, differing), (16 * 9, 0));
    // SRTM3 N43E007 (the Alps by the sea), a partial crop: the last tiles end inside their
    // cells.
    let (w, h) = (600, 390);
    let alps = hgt_crop("srtm/N43E007.hgt", 1201, (300, 400), (w, h));
    let (levels, differing, _) = compare(&alps, (w, h), (67.7, 92.6), false);
    assert_eq!((levels, differing), (6 * 9, 0));
    // The control: level 1 without one of its vertices.
    let (_, differing, blobs) = compare(&srtm3, (side, side), (53.2, 92.6), true);
    assert!(
        differing >= 16,
        "a missing vertex went unnoticed in {} of 16 tiles",
        16 - differing
    );
    assert_eq!(blobs, 16, "a missing vertex left some blob as stored");
}
