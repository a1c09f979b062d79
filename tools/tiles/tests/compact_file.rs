//! Tile sets written with compact levels (format version 4, `TileSetMeta::compact`): every
//! tile of every pyramid layer reads back as the version 3 build's, byte for byte; the set
//! passes `verify` against its source; it is smaller. A compact tile whose bit stream is
//! damaged (checksums resealed, so that only the decoder can tell) is refused with one line,
//! not drawn from and not a panic; its neighbours read on, and so does its level table, which
//! needs no decoding.

mod common;

use tiles::format::{reseal, COMPACT_VERSION, FLAG_COMPACT_LEVELS, VERSION};
use tiles::{build_tileset, verify::verify, BuildParams, TileSet, TileSetMeta};

/// A crop of the SRTM3 tile N55W003 in metres (no voids).
fn srtm3_crop(x0: usize, y0: usize, w: usize, h: usize) -> Vec<f32> {
    common::hgt_crop("srtm/N55W003.hgt", 1201, (x0, y0), (w, h))
}

/// `grid` built with compact levels (default parameters) into `dir/compact.vkt`.
fn compact_set(grid: &tiles::Grid, dir: &std::path::Path) -> std::path::PathBuf {
    let path = dir.join("compact.vkt");
    let meta = TileSetMeta {
        compact: true,
        ..TileSetMeta::default()
    };
    build_tileset(grid, &BuildParams::default(), &meta, &path, &|| {}).expect("compact");
    path
}

/// A 513² crop of N55W003 (2 x 2 tiles) built as version 3 into `dir/plain.vkt`, opened.
fn plain_crop(dir: &std::path::Path) -> TileSet {
    let (w, h) = (513, 513);
    let heights = srtm3_crop(300, 200, w, h);
    let grid = common::srtm3_grid(&heights, (w, h));
    let plain = dir.join("plain.vkt");
    build_tileset(
        &grid,
        &BuildParams::default(),
        &TileSetMeta::default(),
        &plain,
        &|| {},
    )
    .expect("plain");
    TileSet::open(&plain).expect("open")
}

#[test]
fn compact_sets_read_back_as_built_and_refuse_a_damaged_stream() {
    // 2 x 2 tiles and a partial third column, with the pyramid: two layers of tiles.
    let (w, h) = (600, 513);
    let heights = srtm3_crop(100, 100, w, h);
    let grid = common::srtm3_grid(&heights, (w, h));
    let params = BuildParams {
        pyramid: true,
        ..BuildParams::default()
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let (plain, compact) = (dir.path().join("plain.vkt"), dir.path().join("compact.vkt"));
    build_tileset(&grid, &params, &TileSetMeta::default(), &plain, &|| {}).expect("plain");
    let meta = TileSetMeta {
        compact: true,
        ..TileSetMeta::default()
    };
    build_tileset(&grid, &params, &meta, &compact, &|| {}).expect("compact");
    let (p, c) = (
        TileSet::open(&plain).expect("open"),
        TileSet::open(&compact).expect("open"),
    );
    assert_eq!(
        (p.header().version, c.header().version),
        (VERSION, COMPACT_VERSION)
    );
    assert!(c.compact() && !p.compact());
    assert_eq!(c.header().flags & FLAG_COMPACT_LEVELS, FLAG_COMPACT_LEVELS);
    assert!(c.pyramid_layers() > 0, "no pyramid: the layers go untested");
    let mut tiles = 0;
    for layer in 0..=c.pyramid_layers() {
        let (pl, cl) = (
            p.layer(layer).expect("layer"),
            c.layer(layer).expect("layer"),
        );
        for ty in 0..cl.header().tiles_y {
            for tx in 0..cl.header().tiles_x {
                cl.tile(tx, ty).expect("a compact tile reads");
                assert_eq!(
                    cl.blob(tx, ty),
                    pl.blob(tx, ty),
                    "layer {layer} tile {tx},{ty}"
                );
                tiles += 1;
            }
        }
    }
    assert_eq!(tiles, 6 + 2 + 1);
    let report = verify(&c, Some(&grid));
    assert!(report.ok(), "{:#?}", report.problems);
    let sizes = (
        std::fs::metadata(&plain).expect("size").len(),
        std::fs::metadata(&compact).expect("size").len(),
    );
    eprintln!("plain {} bytes, compact {}", sizes.0, sizes.1);
    assert!(
        sizes.1 * 5 < sizes.0,
        "compact {} against plain {}",
        sizes.1,
        sizes.0
    );

    // Damage one byte in the middle of tile (1, 0)'s bit stream and reseal the checksums.
    let mut bytes = std::fs::read(&compact).expect("read");
    let e = c.dir_entry(1, 0).expect("entry");
    let table = std::mem::size_of::<tiles::format::TileHeader>()
        + 9 * std::mem::size_of::<tiles::format::LevelEntry>()
        + 4;
    let at = e.offset as usize + table + (e.len as usize - table) / 2;
    bytes[at] ^= 0x5a;
    reseal(&mut bytes).expect("reseal");
    let damaged = dir.path().join("damaged.vkt");
    std::fs::write(&damaged, &bytes).expect("write");
    let d = TileSet::open(&damaged).expect("a damaged tile's stream does not stop the open");
    let error = match d.tile(1, 0) {
        Ok(_) => panic!("a damaged stream read as a tile"),
        Err(e) => e.to_string(),
    };
    eprintln!("{error}");
    assert!(
        error.contains("damaged.vkt") && error.contains("1,0"),
        "{error}"
    );
    assert!(d.blob(1, 0).is_none());
    // Its table, which readers plan with before they read the tile, reads without the stream
    // (nothing is decoded), and equals the plain build's.
    let (header, entries) = d.tile_table(1, 0).expect("the table reads");
    let plain_tile = p.tile(1, 0).expect("plain");
    assert!(bytemuck::bytes_of(&header) == bytemuck::bytes_of(&plain_tile.header));
    assert!(bytemuck::cast_slice::<_, u8>(&entries) == bytemuck::cast_slice(plain_tile.levels()));
    assert!(
        d.tile(0, 0).is_ok() && d.tile(2, 1).is_ok(),
        "its neighbours read on"
    );
    // The control: the same file undamaged (and resealed alike) reads that tile.
    let mut same = std::fs::read(&compact).expect("read");
    reseal(&mut same).expect("reseal");
    let undamaged = dir.path().join("undamaged.vkt");
    std::fs::write(&undamaged, &same).expect("write");
    assert!(TileSet::open(&undamaged).expect("open").tile(1, 0).is_ok());
}

/// Version 4 compact files, written before blocks were numbered in decoding order, still read:
/// their tiles rebuild in first-use order, which their checksums vouch for. Made here from a
/// version 5 build as the version 4 writer laid tiles out: each tile's stream straight after
/// the crc32 of its blob rebuilt in first-use order (no level lengths; the directory entry
/// shortened, the freed bytes left as a gap). The control: the same tiles under version 5 are
/// refused.
#[test]
fn version_4_compact_sets_still_read_in_first_use_order() {
    use tiles::build::Numbering;
    use tiles::format::{DirEntry, FileHeader, LevelEntry, TileHeader, FIRST_COMPACT_VERSION};

    let (w, h) = (400, 300);
    let heights = srtm3_crop(500, 300, w, h);
    let grid = common::srtm3_grid(&heights, (w, h));
    let dir = tempfile::tempdir().expect("temp dir");
    let path = compact_set(&grid, dir.path());
    let built = TileSet::open(&path).expect("open");
    assert_eq!(built.header().version, COMPACT_VERSION);
    let levels = built.header().levels as usize;
    let table = std::mem::size_of::<TileHeader>() + levels * std::mem::size_of::<LevelEntry>();
    let mut bytes = std::fs::read(&path).expect("read");
    let (tiles_x, tiles_y) = (built.header().tiles_x, built.header().tiles_y);
    let mut first_use = Vec::new();
    let mut reordered = 0;
    for ty in 0..tiles_y {
        for tx in 0..tiles_x {
            let mut e = built.dir_entry(tx, ty).expect("entry");
            let (at, len) = (e.offset as usize, e.len as usize);
            let (header, entries) = built.tile_table(tx, ty).expect("table");
            let stream = bytes[at + table + 4 + 4 * levels..at + len].to_vec();
            let blob = tiles::compact::rebuild(&header, &entries, &stream, Numbering::FirstUse)
                .expect("rebuilt");
            reordered += usize::from(Some(&blob[..]) != built.blob(tx, ty));
            let crc = crc32fast::hash(&blob).to_le_bytes();
            bytes[at + table..at + table + 4].copy_from_slice(&crc);
            bytes[at + table + 4..at + table + 4 + stream.len()].copy_from_slice(&stream);
            e.len -= 4 * levels as u64;
            let slot = std::mem::size_of::<FileHeader>()
                + (ty * tiles_x + tx) as usize * std::mem::size_of::<DirEntry>();
            bytes[slot..slot + std::mem::size_of::<DirEntry>()]
                .copy_from_slice(bytemuck::bytes_of(&e));
            first_use.push(((tx, ty), blob));
        }
    }
    assert!(
        reordered > 0,
        "no tile's order differs: the test proves nothing"
    );
    let version_at = std::mem::offset_of!(FileHeader, version);
    let write = |version: u32, name: &str| {
        let mut b = bytes.clone();
        b[version_at..version_at + 4].copy_from_slice(&version.to_le_bytes());
        reseal(&mut b).expect("reseal");
        let p = dir.path().join(name);
        std::fs::write(&p, &b).expect("write");
        TileSet::open(&p).expect("open")
    };
    let old = write(FIRST_COMPACT_VERSION, "version4.vkt");
    assert_eq!(old.header().version, FIRST_COMPACT_VERSION);
    for ((tx, ty), blob) in &first_use {
        old.tile(*tx, *ty).expect("a version 4 tile reads");
        assert_eq!(old.blob(*tx, *ty), Some(&blob[..]), "tile {tx},{ty}");
        assert_eq!(
            old.level_stream(*tx, *ty, 0),
            None,
            "version 4 has no level lengths"
        );
    }
    let report = verify(&old, Some(&grid));
    assert!(report.ok(), "{:#?}", report.problems);
    // The control: read as version 5, every tile is refused (its level lengths are not there).
    let wrong = write(COMPACT_VERSION, "version5.vkt");
    let refused = first_use
        .iter()
        .filter(|((tx, ty), _)| wrong.tile(*tx, *ty).is_err())
        .count();
    assert_eq!(refused, first_use.len());
}

/// A version 5 tile's level lengths locate each level's stream: the levels' streams, joined,
/// are the tile's, each decodes to its level's vertices; lengths that do not add up to the
/// stream are refused when the table is read.
#[test]
fn level_lengths_locate_each_levels_stream() {
    let (w, h) = (300, 300);
    let heights = srtm3_crop(200, 700, w, h);
    let grid = common::srtm3_grid(&heights, (w, h));
    let dir = tempfile::tempdir().expect("temp dir");
    let path = compact_set(&grid, dir.path());
    let set = TileSet::open(&path).expect("open");
    let levels = set.header().levels;
    let tile = set.tile(0, 0).expect("tile");
    let (stream, lengths) = tiles::compact::encode_levels(&tile);
    let (_, _, stored) = set.tile_table_and_streams(0, 0).expect("table");
    assert_eq!(stored, lengths);
    let joined: Vec<u8> = (0..levels)
        .flat_map(|j| set.level_stream(0, 0, j).expect("level").to_vec())
        .collect();
    assert_eq!(joined, stream);
    assert_eq!(set.level_stream(0, 0, levels), None);

    // A length changed (and the file resealed) is refused with the tile named.
    let mut bytes = std::fs::read(&path).expect("read");
    let e = set.dir_entry(0, 0).expect("entry");
    let at = e.offset as usize
        + std::mem::size_of::<tiles::format::TileHeader>()
        + levels as usize * std::mem::size_of::<tiles::format::LevelEntry>()
        + 4;
    bytes[at] ^= 1;
    reseal(&mut bytes).expect("reseal");
    let damaged = dir.path().join("lengths.vkt");
    std::fs::write(&damaged, &bytes).expect("write");
    let d = TileSet::open(&damaged).expect("open");
    let error = d
        .tile_table_and_streams(0, 0)
        .expect_err("refused")
        .to_string();
    assert!(
        error.contains("lengths.vkt") && error.contains("0,0"),
        "{error}"
    );
    assert!(d.tile(0, 0).is_err());
}

/// A compact tile read through its first levels is rebuilt from those alone: its blob is the
/// whole tile's first bytes, through the last of those levels' sections, and the tile holds
/// those levels (every tile of a 2 x 2 SRTM3 crop, every count of levels, each from a fresh
/// open so that nothing rebuilt from more levels serves it); its sides as decoded from those
/// levels' streams are the rebuilt tile's. A changed byte in the finest
/// level's stream (resealed) is refused when that level is read, not before: the control that
/// the first levels were rebuilt without it.
#[test]
fn a_compact_tiles_first_levels_rebuild_alone() {
    let (w, h) = (400, 380);
    let heights = srtm3_crop(400, 200, w, h);
    let grid = common::srtm3_grid(&heights, (w, h));
    let dir = tempfile::tempdir().expect("temp dir");
    let path = compact_set(&grid, dir.path());
    let whole = TileSet::open(&path).expect("open");
    let (levels, tiles_x, tiles_y) = (
        whole.header().levels,
        whole.header().tiles_x,
        whole.header().tiles_y,
    );
    assert_eq!((tiles_x, tiles_y), (2, 2));
    let mut shorter = 0;
    for (tx, ty) in (0..tiles_y).flat_map(|ty| (0..tiles_x).map(move |tx| (tx, ty))) {
        let full = whole.tile(tx, ty).expect("tile");
        let blob = whole.blob(tx, ty).expect("blob");
        for count in 1..levels {
            let set = TileSet::open(&path).expect("open");
            let tile = set.tile_levels(tx, ty, 0..count).expect("first levels");
            assert_eq!(tile.levels().len(), count as usize);
            assert!(tile.level(count).is_none());
            let last = full.levels()[count as usize - 1];
            let end =
                last.border_offset as usize + 4 * last.border_len.iter().sum::<u32>() as usize;
            let first = set.blob_through(tx, ty, count).expect("first levels' blob");
            assert_eq!(first, &blob[..end], "tile {tx},{ty}, {count} levels");
            // Its sides as decoded, without the rebuild, are the rebuilt tile's.
            let sides = set.stored_sides(tx, ty, count).expect("sides");
            assert_eq!(Some(sides), full.side_points(count), "tile {tx},{ty}");
            shorter += usize::from(end < blob.len());
        }
    }
    assert!(
        shorter > 0,
        "some tile's first levels are fewer bytes than the tile"
    );

    // The finest level's stream of tile 1,0 changed, the file resealed.
    let (_, entries, lengths) = whole.tile_table_and_streams(1, 0).expect("table");
    let finest = levels as usize - 1;
    let at = whole.dir_entry(1, 0).expect("entry").offset as usize
        + std::mem::size_of::<tiles::format::TileHeader>()
        + entries.len() * std::mem::size_of::<tiles::format::LevelEntry>()
        + 4
        + 4 * lengths.len()
        + lengths[..finest].iter().sum::<u32>() as usize;
    assert!(lengths[finest] > 0);
    let mut bytes = std::fs::read(&path).expect("read");
    bytes[at] ^= 0x01;
    reseal(&mut bytes).expect("reseal");
    let damaged = dir.path().join("finest.vkt");
    std::fs::write(&damaged, &bytes).expect("write");
    let d = TileSet::open(&damaged).expect("open");
    d.tile_levels(1, 0, 0..levels - 1)
        .expect("the first levels read without the finest");
    let error = d
        .tile_levels(1, 0, 0..levels)
        .expect_err("the finest level is refused")
        .to_string();
    assert!(
        error.contains("finest.vkt") && error.contains("1,0"),
        "{error}"
    );
    assert!(d.tile(1, 0).is_err() && d.tile(0, 0).is_ok());
}

/// The compact writer decodes every tile's stream and must get its vertices back, in order, and
/// rebuilds one tile in `FULL_CHECK_EVERY` whole against the tile built. Fed version 3 tiles
/// damaged two ways, 2 x 2 tiles of SRTM3:
/// - two vertices of a block swapped: the stream, which sends vertices in the decoder's order,
///   no longer decodes to the block, so the writer refuses the tile, with one line;
/// - a morph offset changed, which the stream does not hold: refused where the tile is rebuilt
///   (tile 0,0, in the sample), written where it is not (tile 1,0), where a reader's rebuild
///   fails the stored checksum and `verify` names the tile.
///
/// The control: the same tiles undamaged are written, and read back as built.
#[test]
fn the_compact_writer_decodes_every_stream_and_rebuilds_a_sample() {
    use tiles::format::{FileHeader, TileSetWriter, FULL_CHECK_EVERY};
    let dir = tempfile::tempdir().expect("temp dir");
    let p = plain_crop(dir.path());
    let header = FileHeader {
        flags: p.header().flags | FLAG_COMPACT_LEVELS,
        ..*p.header()
    };
    // The writer's sample (`FULL_CHECK_EVERY`): tile 0,0 is in it, tile 1,0 is not.
    let sampled = |tx: u32, ty: u32| (tx + 3 * ty).is_multiple_of(FULL_CHECK_EVERY);
    assert!(sampled(0, 0) && !sampled(1, 0));
    // Byte offsets in tile (tx, ty)'s blob of level 1's last two vertices and first morph offset.
    let offsets = |tx: u32, ty: u32| {
        let (tile, blob) = (p.tile(tx, ty).expect("tile"), p.blob(tx, ty).expect("blob"));
        let l = tile.level(1).expect("level 1");
        let at = |ptr: *const u8| ptr as usize - blob.as_ptr() as usize;
        assert!(l.positions.len() >= 2 && !l.morph.is_empty());
        let last = at(l.positions[l.positions.len() - 2..].as_ptr().cast());
        (last, at(l.morph.as_ptr().cast()))
    };
    let write =
        |name: &str, damaged: (u32, u32), swap: bool| -> Result<std::path::PathBuf, String> {
            let path = dir.path().join(name);
            let mut writer = TileSetWriter::create(&path, header).map_err(|e| e.to_string())?;
            for ty in 0..2 {
                for tx in 0..2 {
                    let mut blob = p.blob(tx, ty).expect("blob").to_vec();
                    if (tx, ty) == damaged {
                        let (last, morph) = offsets(tx, ty);
                        if swap {
                            let (a, b) = blob[last..last + 8].split_at_mut(4);
                            a.swap_with_slice(b);
                        } else {
                            blob[morph] = blob[morph].wrapping_add(1);
                        }
                    }
                    writer.add_tile(tx, ty, &blob).map_err(|e| e.to_string())?;
                }
            }
            writer.finish().map_err(|e| e.to_string())?;
            Ok(path)
        };
    let refused = |name: &str, damaged, swap, what: &str| {
        let e = write(name, damaged, swap).expect_err("a damaged tile was written");
        eprintln!("{e}");
        let tile = format!("tile {},{}", damaged.0, damaged.1);
        assert!(
            e.contains(name) && e.contains(&tile) && e.contains(what),
            "{e}"
        );
        assert!(!dir.path().join(name).exists(), "{name} left behind");
    };
    refused(
        "swapped.vkt",
        (1, 0),
        true,
        "level 1 does not decode to its vertices",
    );
    refused("morph.vkt", (0, 0), false, "rebuild");
    let unsampled = write("unsampled.vkt", (1, 0), false).expect("tile 1,0 is not rebuilt");
    let u = TileSet::open(&unsampled).expect("open");
    let error = u
        .tile(1, 0)
        .map(|_| ())
        .expect_err("a damaged morph offset read");
    assert!(error.to_string().contains("checksum"), "{error}");
    let report = verify(&u, None);
    assert!(
        report.problems.iter().any(|p| p.contains("tile 1,0")),
        "{:#?}",
        report.problems
    );
    // The control.
    let sound = write("sound.vkt", (9, 9), false).expect("sound tiles");
    let s = TileSet::open(&sound).expect("open");
    assert!(s.compact());
    for (tx, ty) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
        assert_eq!(s.blob(tx, ty), p.blob(tx, ty), "tile {tx},{ty}");
    }
    let heights = srtm3_crop(300, 200, 513, 513);
    let grid = common::srtm3_grid(&heights, (513, 513));
    assert!(verify(&s, Some(&grid)).ok());
}

/// What a merge does to a compact tile sealed at smaller morph units than the set's
/// (`reseal_compact_tile`): the stream is kept and decoded, the table takes the new units,
/// and the checksum is made anew. On the writer's sample (`FULL_CHECK_EVERY`) the tile is
/// first rebuilt at its old units and must give its stored checksum. The control: a tile in
/// the sample whose stored checksum is off is refused, and the same damage outside the
/// sample is sealed (the part's own checksum covers that case).
#[test]
fn a_compact_tile_sealed_again_keeps_its_stream_and_checks_a_sample() {
    use tiles::format::{
        compact_tile, reseal_compact_tile, stored_tile_table, LevelEntry, TileHeader,
        FULL_CHECK_EVERY,
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let p = plain_crop(dir.path());
    let shape = (p.header().levels, p.header().height_step);
    let table = size_of::<TileHeader>() + shape.0 as usize * size_of::<LevelEntry>();
    let sampled = |tx: u32, ty: u32| (tx + 3 * ty).is_multiple_of(FULL_CHECK_EVERY);
    assert!(sampled(0, 0) && !sampled(1, 0));
    for (tx, ty) in [(0, 0), (1, 0)] {
        let stored = compact_tile(p.blob(tx, ty).expect("blob"), (tx, ty), shape).expect("compact");
        let entries = stored_tile_table(&stored, (tx, ty), shape, true).expect("table");
        let units: Vec<f64> = entries
            .iter()
            .map(|e| 2.0 * f64::from(e.morph_unit))
            .collect();
        let sealed = reseal_compact_tile(&stored, (tx, ty), shape, &units).expect("sealed");
        assert_eq!(
            sealed[table + 4..],
            stored[table + 4..],
            "the stream changed"
        );
        assert_ne!(
            sealed[table..table + 4],
            stored[table..table + 4],
            "the same checksum"
        );
        let now = stored_tile_table(&sealed, (tx, ty), shape, true).expect("sealed table");
        for (e, u) in now.iter().zip(&units) {
            assert_eq!(e.morph_unit, *u as f32);
        }
        let mut damaged = stored.clone();
        damaged[table] ^= 1;
        let got = reseal_compact_tile(&damaged, (tx, ty), shape, &units);
        match sampled(tx, ty) {
            true => assert!(
                got.as_ref().is_err_and(|e| e.contains("checksum")),
                "tile {tx},{ty}: {got:?}"
            ),
            false => assert!(got.is_ok(), "tile {tx},{ty}: {got:?}"),
        }
    }
}

/// `verify` takes a compact set's rows in runs, its view forgetting what it rebuilt of each
/// run's rows after it (a view keeps every tile it rebuilt: one view over the 64K set's 65,536
/// tiles ran the machine out of memory). A run's last row checks its seams against the next
/// run's first, which stays. So a run of one row at a time must report what one run over every row reports, on
/// a set with a damaged tile in its middle row and a pyramid above it. The control that the
/// runs happened: the damaged tile is named once in each report, and the rows it checks are
/// all there (every tile of every layer counted once).
#[test]
fn verify_in_runs_of_a_row_reports_what_one_run_does() {
    use tiles::verify::verify_in_runs;
    let (w, h) = (769, 769);
    let heights = srtm3_crop(150, 120, w, h);
    let grid = common::srtm3_grid(&heights, (w, h));
    let params = BuildParams {
        pyramid: true,
        ..BuildParams::default()
    };
    let meta = TileSetMeta {
        compact: true,
        ..TileSetMeta::default()
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("compact.vkt");
    build_tileset(&grid, &params, &meta, &path, &|| {}).expect("compact");
    let sound = TileSet::open(&path).expect("open");
    assert_eq!((sound.header().tiles_x, sound.header().tiles_y), (3, 3));
    let layers = sound.pyramid_layers();
    assert!(
        layers >= 2,
        "{layers} pyramid layers: the layers' runs go untested"
    );
    let every_tile = 9 + 4 + 1;

    // Tile (1, 1)'s stream damaged in its middle, the checksums resealed.
    let mut bytes = std::fs::read(&path).expect("read");
    let e = sound.dir_entry(1, 1).expect("entry");
    let table = std::mem::size_of::<tiles::format::TileHeader>()
        + 9 * std::mem::size_of::<tiles::format::LevelEntry>()
        + 4;
    bytes[e.offset as usize + table + (e.len as usize - table) / 2] ^= 0x5a;
    reseal(&mut bytes).expect("reseal");
    let damaged = dir.path().join("damaged.vkt");
    std::fs::write(&damaged, &bytes).expect("write");
    let set = TileSet::open(&damaged).expect("open");

    for (name, set) in [("sound", &sound), ("damaged", &set)] {
        let whole = verify_in_runs(set, Some(&grid), u32::MAX, &|| {});
        let checked = std::sync::atomic::AtomicU64::new(0);
        let by_row = verify_in_runs(set, Some(&grid), 1, &|| {
            checked.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        });
        eprintln!("{name}: {:#?}", by_row.problems);
        assert_eq!(by_row.problems, whole.problems, "{name}");
        assert_eq!(
            (by_row.tiles, by_row.levels_checked),
            (whole.tiles, whole.levels_checked),
            "{name}"
        );
        assert_eq!(by_row.tiles, every_tile, "{name}");
        assert_eq!(
            checked.into_inner(),
            every_tile,
            "{name}: progress once a tile"
        );
        assert_eq!(
            by_row.recomputed_max_error, whole.recomputed_max_error,
            "{name}"
        );
        assert_eq!(by_row.limited, whole.limited, "{name}");
        let named = |r: &tiles::verify::VerifyReport| {
            r.problems
                .iter()
                .filter(|p| p.contains("damaged.vkt") && p.contains("1,1"))
                .count()
        };
        // A view forgets what it rebuilt of rows it is done with, when the rebuilt tiles are
        // its own, and reads them again after; a view whose cache another shares keeps it.
        let mut own = set.with_own_rebuilt();
        let first = own.blob(0, 0).map(<[u8]>::to_vec);
        assert!(first.is_some(), "{name}");
        let shared = own.clone();
        assert!(
            !own.forget_rebuilt_rows(0..1),
            "{name}: another view shares the cache"
        );
        drop(shared);
        assert!(own.forget_rebuilt_rows(0..1), "{name}");
        assert_eq!(own.blob(0, 0).map(<[u8]>::to_vec), first, "{name}");
        match name {
            "sound" => assert!(by_row.ok(), "{:#?}", by_row.problems),
            _ => assert_eq!(
                (named(&by_row), named(&whole)),
                (1, 1),
                "{:#?}",
                by_row.problems
            ),
        }
    }
}
