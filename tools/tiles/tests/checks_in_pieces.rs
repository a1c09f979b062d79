//! A tile's semantic checks made level by level (`tiles::verify::tile_problems_in`, what the
//! renderer runs as a tile's levels are first needed) find what one pass over every level
//! finds: on real data (an SRTM3 crop of the Alps), a tile with a broken fan at level `k` is
//! reported in the piece that holds level `k`, with the same line as the whole check, and in no
//! piece before it. The control: the sound tile passes in every split.

mod common;

use tiles::verify::{tile_problems, tile_problems_in};
use tiles::TileSet;

/// The problems of tile 0,0 checked in the pieces that `cuts` splits its levels into.
fn in_pieces(set: &TileSet, cuts: &[u32]) -> Vec<Vec<String>> {
    let tile = set.tile(0, 0).expect("tile");
    let levels = tile.header.levels;
    let mut bounds = vec![0];
    bounds.extend(cuts.iter().copied().filter(|&c| c > 0 && c < levels));
    bounds.push(levels);
    bounds
        .windows(2)
        .map(|w| tile_problems_in(set, &tile, w[0]..w[1]))
        .collect()
}

#[test]
fn checks_in_pieces_find_what_one_pass_finds() {
    let dir = tempfile::tempdir().expect("temp dir");
    // One full tile and a partial one.
    let file = common::alps_set(dir.path(), (256 + 1 + 90, 257));
    let splits: [&[u32]; 4] = [&[], &[3], &[1, 5], &[1, 2, 3, 4, 5, 6, 7, 8]];
    let sound = TileSet::open(&file).expect("open");
    for cuts in splits {
        assert!(
            in_pieces(&sound, cuts).iter().all(Vec::is_empty),
            "the sound tile, split at {cuts:?}"
        );
    }
    let entry = sound.dir_entry(0, 0).expect("entry");
    let tile = sound.tile(0, 0).expect("tile");
    let levels = tile.header.levels;
    let tables: Vec<_> = (0..levels)
        .map(|k| tile.level(k).expect("level").entry)
        .collect();
    let bytes = std::fs::read(&file).expect("read");
    for (k, e) in tables.iter().enumerate() {
        let k = k as u32;
        // Swap the first fan's second and third ring entries: the ring no longer walks its cell.
        let mut broken = bytes.clone();
        let w = e.index_width as usize;
        let at = entry.offset as usize + e.index_offset as usize;
        broken[at + 2 * w..at + 4 * w].rotate_left(w);
        tiles::format::reseal(&mut broken).expect("reseal");
        let path = dir.path().join(format!("broken{k}.vkt"));
        std::fs::write(&path, &broken).expect("write");
        let set = TileSet::open(&path).expect("open");
        let whole = tile_problems(&set, &set.tile(0, 0).expect("tile"));
        assert!(
            whole
                .first()
                .is_some_and(|p| p.contains(&format!("tile 0,0 level {k}: fan 0"))),
            "level {k}: {whole:?}"
        );
        for cuts in splits {
            let pieces = in_pieces(&set, cuts);
            let starts: Vec<u32> = std::iter::once(0).chain(cuts.iter().copied()).collect();
            // The piece holding level k: the last that starts at or before it.
            let holder = starts.iter().rposition(|&s| s <= k).expect("a piece");
            for (i, found) in pieces.iter().enumerate() {
                if i < holder {
                    assert!(
                        found.is_empty(),
                        "level {k}, {cuts:?}, piece {i}: {found:?}"
                    );
                } else if i == holder {
                    assert_eq!(found.first(), whole.first(), "level {k}, {cuts:?}");
                }
            }
        }
    }
}
