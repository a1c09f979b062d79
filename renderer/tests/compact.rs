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

/// Three frames over `set` with `fault` injected: the exit code and stderr.
fn three_frames(set: &Path, fault: &str) -> (Option<i32>, String) {
    let args = [
        common::s(set),
        "--headless",
        "--frames",
        "3",
        "--size",
        "256x192",
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
