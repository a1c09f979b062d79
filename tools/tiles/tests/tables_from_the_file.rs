//! A tile's header and level table read from the file (`TileSet::tile_table`, what the
//! renderer reads of every tile at open) are what the tile's outline read through the mapping
//! holds, and a table whose sections do not lie inside the tile is refused by both with the
//! same line: on real data (an SRTM3 crop of the Alps), every tile of the set, then tile 0,0
//! with one level's section moved past the tile's end or off its alignment, or its border
//! lists made too long. The control: the sound set's tables read the same both ways.

mod common;

use tiles::format::{LevelEntry, TileHeader};
use tiles::TileSet;

/// A change to one level's entry, given the tile's length.
type Damage = fn(&mut LevelEntry, u32);

#[test]
fn tables_read_from_the_file_are_the_outlines() {
    let dir = tempfile::tempdir().expect("temp dir");
    let file = common::relief_set(dir.path(), (2 * 256 + 1, 256 + 1));
    let sound = TileSet::open(&file).expect("open");
    let h = *sound.header();
    for ty in 0..h.tiles_y {
        for tx in 0..h.tiles_x {
            let (header, levels) = sound.tile_table(tx, ty).expect("the table reads");
            let outline = sound.tile_outline(tx, ty).expect("the outline reads");
            assert_eq!(
                bytemuck::bytes_of(&header),
                bytemuck::bytes_of(&outline.header)
            );
            assert_eq!(
                bytemuck::cast_slice::<LevelEntry, u8>(&levels),
                bytemuck::cast_slice::<LevelEntry, u8>(outline.levels())
            );
        }
    }
    let entry = sound.dir_entry(0, 0).expect("entry");
    let bytes = std::fs::read(&file).expect("read");
    let table =
        |k: usize| entry.offset as usize + size_of::<TileHeader>() + k * size_of::<LevelEntry>();
    let damage: [(&str, Damage); 4] = [
        ("indices past the end", |e, len| e.index_offset = len),
        ("positions misaligned", |e, _| e.positions_offset += 2),
        ("morph offsets past the end", |e, len| {
            e.morph_offset = len - 1
        }),
        ("border lists too long", |e, _| e.border_len[2] = 1 << 30),
    ];
    for k in [1usize, 5, 8] {
        for (n, (what, damage)) in damage.iter().enumerate() {
            let mut broken = bytes.clone();
            let at = table(k);
            let mut e: LevelEntry =
                bytemuck::pod_read_unaligned(&broken[at..at + size_of::<LevelEntry>()]);
            damage(&mut e, entry.len as u32);
            broken[at..at + size_of::<LevelEntry>()].copy_from_slice(bytemuck::bytes_of(&e));
            tiles::format::reseal(&mut broken).expect("reseal");
            let path = dir.path().join(format!("broken{k}.{n}.vkt"));
            std::fs::write(&path, &broken).expect("write");
            let set = TileSet::open(&path).expect("open");
            let read = set.tile_table(0, 0).map(|_| ()).map_err(|e| e.to_string());
            let mapped = set
                .tile_outline(0, 0)
                .map(|_| ())
                .map_err(|e| e.to_string());
            assert!(read.is_err(), "level {k}, {what}: read");
            assert_eq!(read, mapped, "level {k}, {what}");
            assert!(
                set.tile_table(1, 0).is_ok(),
                "level {k}, {what}: its neighbour"
            );
        }
    }
}
