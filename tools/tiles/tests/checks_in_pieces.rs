//! A tile's semantic checks made level by level (`tiles::verify::tile_problems_in`, what the
//! renderer runs as a tile's levels are first needed) find what one pass over every level
//! finds: on real data (an SRTM3 crop of the Alps), a tile with a broken fan at level `k` is
//! reported in the piece that holds level `k`, with the same line as the whole check, and in no
//! piece before it. So is a finer block's morph offset that misses a coarser level's surface,
//! and a vertex of block `k` outside the mesh extent (a structure check, which a reader makes
//! piece by piece as well: `TileSet::tile_levels`). The control: the sound tile passes in
//! every split.

mod common;

use tiles::verify::{tile_problems, tile_problems_in};
use tiles::TileSet;

/// The problems of tile 0,0 checked in the pieces that `cuts` splits its levels into, as a
/// renderer checks them: each piece's structure, then its semantic checks.
fn in_pieces(set: &TileSet, cuts: &[u32]) -> Vec<Vec<String>> {
    let levels = set.header().levels;
    let mut bounds = vec![0];
    bounds.extend(cuts.iter().copied().filter(|&c| c > 0 && c < levels));
    bounds.push(levels);
    bounds
        .windows(2)
        .map(|w| match set.tile_levels(0, 0, w[0]..w[1]) {
            Ok(tile) => tile_problems_in(set, &tile, w[0]..w[1]),
            Err(e) => vec![e.to_string()],
        })
        .collect()
}

/// The whole check's first problem with tile 0,0: its structure, then its semantic checks.
fn whole(set: &TileSet) -> Option<String> {
    match set.tile(0, 0) {
        Ok(tile) => tile_problems(set, &tile).into_iter().next(),
        Err(e) => Some(e.to_string()),
    }
}

/// `bytes` with their checksums recomputed, written to `dir/name` and opened.
fn resealed(dir: &std::path::Path, mut bytes: Vec<u8>, name: &str) -> TileSet {
    tiles::format::reseal(&mut bytes).expect("reseal");
    let path = dir.join(name);
    std::fs::write(&path, &bytes).expect("write");
    TileSet::open(&path).expect("open")
}

/// Asserts that the whole check's first problem names every one of `names`, and that the
/// damage at level `k` is found first in the piece holding level `k` of every split, with
/// that line, and in no piece before.
fn found_where_it_is(set: &TileSet, k: u32, splits: &[&[u32]], names: &[&str]) {
    let whole = whole(set);
    assert!(
        whole
            .as_ref()
            .is_some_and(|p| names.iter().all(|n| p.contains(n))),
        "level {k}, {names:?}: {whole:?}"
    );
    for &cuts in splits {
        let pieces = in_pieces(set, cuts);
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
                assert_eq!(found.first(), whole.as_ref(), "level {k}, {cuts:?}");
            }
        }
    }
}

#[test]
fn checks_in_pieces_find_what_one_pass_finds() {
    let dir = tempfile::tempdir().expect("temp dir");
    // One full tile and a partial one.
    let file = common::relief_set(dir.path(), (256 + 1 + 90, 257));
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
        let set = resealed(dir.path(), broken, &format!("broken{k}.vkt"));
        let what = format!("tile 0,0 level {k}: fan 0");
        found_where_it_is(&set, k, &splits, &[&what]);
    }
    // Block k's first vertex: its offset onto level 0 off by 40 units, then its column moved
    // past the mesh extent (9 bits hold up to 511).
    for (k, e) in tables.iter().enumerate().skip(1) {
        let k = k as u32;
        if e.block_len == 0 {
            continue;
        }
        let morph = entry.offset as usize + e.morph_offset as usize;
        let positions = entry.offset as usize + e.positions_offset as usize;
        let mut off_surface = bytes.clone();
        off_surface[morph] = (off_surface[morph] as i8).wrapping_add(40) as u8;
        let mut outside = bytes.clone();
        let word = u32::from_le_bytes(outside[positions..positions + 4].try_into().unwrap());
        outside[positions..positions + 4].copy_from_slice(&(word | 0x1ff).to_le_bytes());
        let cases = [
            (off_surface, "morph offsets onto level 0 miss its surface"),
            (outside, "outside the mesh extent"),
        ];
        for (n, (broken, what)) in cases.into_iter().enumerate() {
            let set = resealed(dir.path(), broken, &format!("block{k}.{n}.vkt"));
            found_where_it_is(&set, k, &splits, &[&format!("level {k}"), what]);
        }
    }
}
