//! A compact tile set (format version 5) flown with its levels sent as their compact streams
//! and decoded on the GPU (`--decode gpu`, the default for such sets), against the same set
//! with the positions the CPU rebuilt sent instead (`--decode cpu`): every frame the same
//! pixels and triangles, at about a third of the block bytes on the bus (lavapipe, validation
//! on); the same with the file's index arrays. Controls: streams sent but never decoded
//! (`decode-skip`) stop the flight where arrays are built from the blocks, and draw other
//! frames with the file's arrays; a decode the GPU refuses (`decode-count`) stops the flight
//! with one line naming the tile and level.

use std::path::{Path, PathBuf};

use tiles::{build_tileset, BuildParams, TileSetMeta};

mod common;

/// The Puget sample built with compact levels.
fn compact_puget(dir: &Path) -> PathBuf {
    let grid = dem::read(&[common::sample()], &common::puget_options()).expect("sample");
    let out = dir.join("compact.vkt");
    let meta = TileSetMeta {
        compact: true,
        ..TileSetMeta::default()
    };
    let view = common::grid_view(&grid);
    build_tileset(&view, &BuildParams::default(), &meta, &out, &|| {}).expect("build");
    out
}

/// Three frames over `set`, its levels decoded on the GPU and its index arrays built there,
/// with `fault` injected: the exit code and stderr.
fn three_frames(set: &Path, fault: &str) -> (Option<i32>, String) {
    let args = [
        common::s(set),
        "--headless",
        "--frames",
        "3",
        "--size",
        "256x192",
        "--decode",
        "gpu",
        // The GPU's builder reads the decoded blocks (the CPU makes arrays from the positions
        // it rebuilt, which a skipped decode does not touch).
        "--index-builder",
        "gpu",
    ];
    let o = common::vkterrain_with_env(&args, ("VKTERRAIN_FAULT", fault));
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn column_sum(out: &Path, name: &str) -> f64 {
    common::log_column(&out.join("frames.csv"), name)
        .iter()
        .sum()
}

#[test]
fn levels_decoded_on_the_gpu_draw_the_frames_their_positions_draw() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = compact_puget(dir.path());
    let run = |name: &str, extra: &[&str], fault: Option<&str>| {
        let out = dir.path().join(name);
        std::fs::create_dir_all(&out).expect("dir");
        let mut args = vec!["--tau", "1"];
        args.extend(extra);
        let frames = common::flight_with_fault(&set, &out, "flyover", 30, &args, fault);
        (out, frames)
    };
    let (gpu_out, gpu) = run("gpu", &["--decode", "gpu"], None);
    let (cpu_out, cpu) = run("cpu", &["--decode", "cpu"], None);
    let same = |a: &[image::RgbaImage], b: &[image::RgbaImage], what: &str| {
        for (k, (x, y)) in a.iter().zip(b).enumerate() {
            assert!(x == y, "frame {k}: {what}, the frame differs");
        }
    };
    same(&gpu, &cpu, "decoded on the GPU");
    // Where the user does not choose, the device does: the CPU's decoder on a software
    // rasteriser, whose compute runs on the same cores (settings::decode_pays_on).
    let (auto_out, auto) = run("auto", &[], None);
    same(&auto, &cpu, "decoded where the device decides");
    // The version 3 build of the same sample draws the same frames: a compact tile rebuilt
    // only through the levels its checks read, with its sides and part tables grown level by
    // level, is drawn as the whole tile is.
    let whole = common::puget(dir.path());
    let out = dir.path().join("version3");
    std::fs::create_dir_all(&out).expect("dir");
    let v3 = common::flight_with_fault(&whole, &out, "flyover", 30, &["--tau", "1"], None);
    same(&v3, &cpu, "drawn from the version 3 build");
    let summary = |out: &Path| -> serde_json::Value {
        let json = std::fs::read(out.join("frames.json")).expect("summary");
        serde_json::from_slice(&json).expect("summary parses")
    };
    let software = summary(&auto_out)["device"]
        .as_str()
        .is_some_and(|d| d.contains("llvmpipe"));
    let chosen = if software { "cpu" } else { "gpu" };
    assert_eq!(summary(&auto_out)["levels_decoded_on"], chosen);
    assert_eq!(summary(&gpu_out)["levels_decoded_on"], "gpu");
    assert_eq!(summary(&cpu_out)["levels_decoded_on"], "cpu");
    let triangles = |out: &Path| common::log_column(&out.join("frames.csv"), "triangles");
    assert_eq!(triangles(&gpu_out), triangles(&cpu_out));
    let (sent, rebuilt) = (
        column_sum(&gpu_out, "upload_bytes_blocks"),
        column_sum(&cpu_out, "upload_bytes_blocks"),
    );
    eprintln!("block bytes: {sent} as streams, {rebuilt} as positions");
    assert!(
        sent > 0.0 && sent < 0.4 * rebuilt,
        "{sent} bytes as streams against {rebuilt} as positions"
    );
    // The file's own index arrays (the fallback without 16-bit storage) address the decoded
    // blocks too: the file numbers their vertices in decoding order.
    // (They draw whole levels, not part by part: other frames than the built arrays'.)
    let sent_arrays = ["--decode", "gpu", "--index-arrays", "sent"];
    let (_, arrays) = run("arrays", &sent_arrays, None);
    let (_, arrays_cpu) = run(
        "arrays-cpu",
        &["--decode", "cpu", "--index-arrays", "sent"],
        None,
    );
    same(&arrays, &arrays_cpu, "with the file's index arrays");

    // The control: streams sent and never decoded leave the blocks' places unwritten. With
    // arrays built on the GPU, the builder finds vertices missing and the flight stops; with
    // the file's arrays nothing checks, and the frames differ.
    let (code, err) = three_frames(&set, "decode-skip");
    assert!(
        code == Some(1) && err.contains("the index array built from its vertices"),
        "{err}"
    );
    let (_, skipped) = run("skip", &sent_arrays, Some("decode-skip"));
    let differing = skipped.iter().zip(&arrays).filter(|(s, g)| s != g).count();
    assert!(differing > 0, "undecoded streams drew the same frames");

    // A decode the GPU refuses stops the flight with one line naming the tile and level.
    let (code, err) = three_frames(&set, "decode-count");
    assert_eq!(code, Some(1), "{err}");
    let line = err
        .lines()
        .find(|l| l.contains("refused its compact stream"))
        .unwrap_or_else(|| panic!("no refusal line: {err}"));
    assert!(
        line.contains("tile #") && line.contains("level 0"),
        "{line}"
    );
}

/// A compact tile is rebuilt and checked through the levels a frame wants, as a version 3 tile
/// is checked: a byte of tile 1,2's level 2 stream changed, the file resealed (so that only the
/// decoder can tell), leaves the frames that draw the tile coarser as the sound file's; the
/// frame that first wants level 2 or finer finds it, with one line naming the file and the
/// tile, and the flight goes on without the tile and exits 4. The control: the sound file
/// draws every visible tile and exits 0, and asks for tile 1,2 coarser than level 2 first
/// (were the whole tile rebuilt at its first check, the damage would stop it at once).
#[test]
fn a_damaged_compact_level_is_found_when_it_is_first_needed() {
    use tiles::format::{LevelEntry, TileHeader};
    let dir = tempfile::tempdir().expect("temp dir");
    let set = compact_puget(dir.path());
    let level = 2usize;
    let ts = tiles::TileSet::open(&set).expect("open");
    let (_, entries, lengths) = ts.tile_table_and_streams(1, 2).expect("table");
    let at = ts.dir_entry(1, 2).expect("entry").offset as usize
        + size_of::<TileHeader>()
        + entries.len() * size_of::<LevelEntry>()
        + 4
        + 4 * lengths.len()
        + lengths[..level].iter().sum::<u32>() as usize;
    assert!(lengths[level] > 0, "level {level} has a stream");
    drop(ts);
    // Tile 1,2 is index 2 * 4 + 1.
    let fly = |p: &Path, name: &str| common::four_traced_frames(dir.path(), p, name, 9);
    let ((_, [visible, drawn, _], asked), finer) =
        common::sound_flight(dir.path(), &set, level as u32);

    let mut bytes = std::fs::read(&set).expect("read");
    bytes[at] ^= 0x01;
    tiles::format::reseal(&mut bytes).expect("reseal");
    let damaged = dir.path().join("damaged.vkt");
    std::fs::write(&damaged, &bytes).expect("write");
    let (o, [v, d, _], asked_damaged) = fly(&damaged, "damaged");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(4), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("damaged.vkt") && err.contains("tile 1,2") && err.contains("not drawn"),
        "{err}"
    );
    assert_eq!(v, visible);
    assert_eq!(asked_damaged[..finer], asked[..finer]);
    assert_eq!(
        d[..finer],
        drawn[..finer],
        "drawn coarse as the sound file's"
    );
    assert!(
        asked_damaged[finer..].iter().all(Option::is_none),
        "tile 1,2 was asked for after it failed: {asked_damaged:?}"
    );
}
