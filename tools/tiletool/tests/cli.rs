//! `tiletool` end to end on real data: build, info, verify, export, and what bad input gets.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use common::{build_sample, s, stderr, tiletool};
use testdata::{data, sample};

/// A failed command: non-zero exit, exactly one line on stderr that names `file`, no panic.
fn assert_one_line_error(o: &Output, file: &str) -> String {
    let err = stderr(o);
    assert!(
        !o.status.success(),
        "expected failure, got success; stderr: {err}"
    );
    assert_eq!(o.status.code(), Some(1), "stderr: {err}");
    assert!(!err.contains("panicked"), "panic: {err}");
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "want one line, got: {err}"
    );
    assert!(err.contains(file), "error does not name {file}: {err}");
    err
}

fn dir_is_empty(dir: &Path) -> bool {
    std::fs::read_dir(dir).expect("dir").next().is_none()
}

#[test]
fn sample_builds_inspects_verifies_and_exports() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("puget.vkt");
    let src = sample();
    let flags = ["--spacing", "160", "--vertical-scale", "0.1"];
    let mut args = vec!["build", s(&src), "-o", s(&out)];
    args.extend(flags);
    let o = tiletool(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let summary = String::from_utf8_lossy(&o.stdout);
    assert!(summary.contains("4 x 4 of 257 x 257"), "{summary}");

    let o = tiletool(&["info", s(&out), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let info: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    assert_eq!(info["grid_width"], 1025);
    assert_eq!(info["tiles_x"], 4);
    let levels = info["levels"].as_array().expect("levels");
    assert_eq!(levels.len(), 9);
    // Every level below level 0 meets its bound on Puget (160 m spacing never stops refinement
    // below 128 m); level 0 is limited by the spacing rule and says so.
    for l in &levels[1..] {
        let (e, err) = (
            l["error_bound_m"].as_f64().expect("e"),
            l["max_error_m"].as_f64().expect("err"),
        );
        assert!(err <= e, "level {}: {err} > {e}", l["level"]);
        assert_eq!(l["limited_tiles"], 0);
    }
    let v: Vec<u64> = levels
        .iter()
        .map(|l| l["vertices"].as_u64().expect("v"))
        .collect();
    assert!(v.windows(2).all(|w| w[0] < w[1]), "{v:?}");

    let o = tiletool(&["info", s(&out)]);
    assert!(o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("spacing rule"),
        "info should report the limited places"
    );

    let mut args = vec!["verify", s(&out), "--source", s(&src)];
    args.extend(flags);
    let o = tiletool(&args);
    assert!(
        o.status.success(),
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        stderr(&o)
    );

    let obj = dir.path().join("t.obj");
    let o = tiletool(&[
        "export",
        s(&out),
        "--tile",
        "1,2",
        "--level",
        "3",
        "-o",
        s(&obj),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&obj).expect("obj");
    let set = tiles::TileSet::open(&out).expect("open");
    let level = set.tile(1, 2).expect("tile").level(3).expect("level");
    let verts: Vec<Vec<f64>> = text
        .lines()
        .filter(|l| l.starts_with("v "))
        .map(|l| {
            l[2..]
                .split(' ')
                .map(|t| t.parse().expect("number"))
                .collect()
        })
        .collect();
    assert_eq!(verts.len() as u32, level.entry.vertex_count());
    assert_eq!(
        text.lines().filter(|l| l.starts_with("f ")).count() as u32,
        level.entry.triangle_count
    );
    // Source columns and rows of tile (1, 2), heights in metres within Puget's range.
    assert!(verts
        .iter()
        .all(|v| (256.0..=512.0).contains(&v[0]) && (512.0..=768.0).contains(&v[1])));
    assert!(verts.iter().all(|v| (-1.0..=4400.0).contains(&v[2])));
}

#[test]
fn srtm_mosaic_builds_and_verifies() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("cat.vkt");
    let (a, b) = (data("srtm/N42E001.hgt"), data("srtm/N41E001.hgt"));
    let o = tiletool(&["build", s(&a), s(&b), "-o", s(&out), "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(o.stdout.is_empty(), "--quiet prints nothing");
    let o = tiletool(&["verify", s(&out), "--source", s(&a), s(&b)]);
    assert!(
        o.status.success(),
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        stderr(&o)
    );
    let o = tiletool(&["info", s(&out), "--json"]);
    let info: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    assert_eq!(
        (info["grid_width"].as_u64(), info["grid_height"].as_u64()),
        (Some(1201), Some(2401))
    );
    assert_eq!(info["voids_filled"], 134 + 7652);
}

/// The same input and options give the same bytes: twice on two threads, and on one. Tiles
/// are made in parallel and finish in any order (`tiles::ordered`'s tests show they do);
/// before they were written in row-major order, two builds of this mosaic differed from
/// byte 253 on. The mosaic is read whole (one band by default) and one tile row at a time.
#[test]
fn builds_are_reproducible_byte_for_byte() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (a, b) = (data("srtm/N42E001.hgt"), data("srtm/N41E001.hgt"));
    let build = |name: &str, threads: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let o = Command::new(env!("CARGO_BIN_EXE_tiletool"))
            .args(["build", s(&a), s(&b), "-o", s(&out), "--quiet"])
            .args(extra)
            .env("RAYON_NUM_THREADS", threads)
            .output()
            .expect("tiletool runs");
        assert!(o.status.success(), "{}", stderr(&o));
        std::fs::read(&out).expect("built")
    };
    let first = build("first.vkt", "2", &[]);
    assert!(first == build("second.vkt", "2", &[]), "two builds differ");
    assert!(
        first == build("one_thread.vkt", "1", &[]),
        "one thread builds other bytes"
    );
    // Read a tile row (256 grid rows) at a time: the default relief texture's filters and the
    // shared sides' agreement reach across bands, and voids are filled band by band.
    assert!(
        first == build("banded.vkt", "2", &["--band-rows", "1"]),
        "a banded build builds other bytes"
    );
}

#[test]
fn verify_against_the_wrong_source_fails() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("a.vkt");
    let o = tiletool(&[
        "build",
        s(&data("srtm/N43E007.hgt")),
        "-o",
        s(&out),
        "--quiet",
        "--levels",
        "5",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    // Same size, different terrain: the recomputed errors cannot match.
    let o = tiletool(&["verify", s(&out), "--source", s(&data("srtm/N55W003.hgt"))]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("FAILED"), "{}", stderr(&o));
}

/// `--compact` builds the same tiles as the version 3 build (`verify --against`, every tile
/// read back byte for byte, and its errors against the source), in a version 5 file a tenth
/// the size; `--against` a set of other tiles fails, naming both files.
#[test]
fn a_compact_build_verifies_against_the_plain_one() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (plain, _) = build_sample(dir.path(), "plain.vkt", &["--no-texture"]);
    let (compact, info) = build_sample(dir.path(), "compact.vkt", &["--no-texture", "--compact"]);
    assert_eq!(info["format_version"], 5, "{info}");
    let size = |p: &Path| std::fs::metadata(p).expect("size").len();
    assert!(
        size(&compact) * 10 < size(&plain),
        "{} against {}",
        size(&compact),
        size(&plain)
    );
    let o = tiletool(&[
        "verify",
        s(&compact),
        "--against",
        s(&plain),
        "--source",
        s(&sample()),
        "--spacing",
        "160",
        "--vertical-scale",
        "0.1",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(out.contains("every tile the same as"), "{out}");
    // The control: other tiles (fewer levels) are told apart.
    let (fewer, _) = build_sample(dir.path(), "fewer.vkt", &["--no-texture", "--levels", "5"]);
    let o = tiletool(&["verify", s(&compact), "--against", s(&fewer)]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("compact.vkt") && err.contains("fewer.vkt"),
        "{err}"
    );
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).expect("write");
    p
}

/// Builds `inputs` with `extra` flags into a fresh folder and checks the failure is one line
/// naming `names` and that nothing, not even a temporary file, is left behind.
fn build_fails(inputs: &[&Path], extra: &[&str], names: &str) -> String {
    let out_dir = tempfile::tempdir().expect("temp dir");
    let out = out_dir.path().join("out.vkt");
    let mut args = vec!["build"];
    args.extend(inputs.iter().map(|p| s(p)));
    args.extend(["-o", s(&out)]);
    args.extend(extra);
    let o = tiletool(&args);
    let err = assert_one_line_error(&o, names);
    assert!(
        dir_is_empty(out_dir.path()),
        "output left behind after: {err}"
    );
    err
}

#[test]
fn bad_inputs_fail_with_one_line_and_no_output() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();

    let empty = write(d, "empty.png", b"");
    build_fails(&[&empty], &["--spacing", "10"], "empty.png");

    let hgt = std::fs::read(data("srtm/N55W003.hgt")).expect("hgt");
    let truncated = write(d, "N55W003.hgt", &hgt[..hgt.len() / 2]);
    build_fails(&[&truncated], &[], "N55W003.hgt");

    let raw = write(d, "grid.r16", &vec![0u8; 100 * 100 * 2]);
    let err = build_fails(
        &[&raw],
        &["--size", "100x99", "--spacing", "10"],
        "grid.r16",
    );
    assert!(err.contains("size"), "{err}");
    // A size claiming ten billion samples is refused before anything is allocated.
    build_fails(
        &[&raw],
        &["--size", "100000x100000", "--spacing", "10"],
        "grid.r16",
    );

    // Mosaic of two resolutions.
    let sub = d.join("mix");
    std::fs::create_dir(&sub).expect("dir");
    let a = write(&sub, "N10E010.hgt", &vec![0u8; 1201 * 1201 * 2]);
    let b = write(&sub, "N11E010.hgt", &vec![0u8; 3601 * 3601 * 2]);
    let err = build_fails(&[&a, &b], &[], "N10E010.hgt");
    assert!(
        err.to_lowercase().contains("mosaic") || err.contains("resolution"),
        "{err}"
    );

    let void: Vec<u8> = std::iter::repeat_n([0x80u8, 0x00], 1201 * 1201)
        .flatten()
        .collect();
    let all_void = write(d, "N20E020.hgt", &void);
    build_fails(&[&all_void], &[], "N20E020.hgt");

    let mut f32s: Vec<u8> = (0..64 * 64)
        .flat_map(|i| (i as f32).to_le_bytes())
        .collect();
    f32s[400..404].copy_from_slice(&f32::NAN.to_le_bytes());
    let nan = write(d, "nan.f32", &f32s);
    build_fails(&[&nan], &["--size", "64x64", "--spacing", "5"], "nan.f32");

    // A TIFF with three samples per pixel (RGB) is not a DEM.
    let tiff = rgb_tiff();
    let rgb = write(d, "rgb.tif", &tiff);
    build_fails(&[&rgb], &["--spacing", "5"], "rgb.tif");

    let garbage = write(
        d,
        "garbage.tif",
        b"II*\0garbage that is not a tiff directory",
    );
    build_fails(&[&garbage], &["--spacing", "5"], "garbage.tif");

    let missing = d.join("missing.hgt");
    build_fails(&[&missing], &[], "missing.hgt");
}

/// A minimal little-endian RGB8 TIFF of 2 x 2 pixels.
fn rgb_tiff() -> Vec<u8> {
    let mut t = b"II*\0".to_vec();
    t.extend(8u32.to_le_bytes());
    let entries: [(u16, u16, u32, u32); 8] = [
        (256, 3, 1, 2),                  // width
        (257, 3, 1, 2),                  // height
        (258, 3, 1, 8),                  // bits per sample (one value for brevity)
        (259, 3, 1, 1),                  // no compression
        (262, 3, 1, 2),                  // RGB
        (273, 4, 1, 8 + 2 + 8 * 12 + 4), // strip offset: right after the directory
        (277, 3, 1, 3),                  // samples per pixel
        (279, 4, 1, 12),                 // strip byte count
    ];
    t.extend((entries.len() as u16).to_le_bytes());
    for (tag, kind, count, value) in entries {
        t.extend(tag.to_le_bytes());
        t.extend(kind.to_le_bytes());
        t.extend(count.to_le_bytes());
        t.extend(value.to_le_bytes());
    }
    t.extend(0u32.to_le_bytes());
    t.extend([200u8; 12]);
    t
}

#[test]
fn unwritable_output_fails_cleanly() {
    let dir = tempfile::tempdir().expect("temp dir");
    let src = data("srtm/N55W003.hgt");
    let out = dir.path().join("no/such/folder/out.vkt");
    let o = tiletool(&["build", s(&src), "-o", s(&out), "--levels", "3"]);
    assert_one_line_error(&o, "out.vkt");
    let o = tiletool(&["build", s(&src), "-o", s(dir.path()), "--levels", "3"]);
    assert_one_line_error(&o, s(dir.path()));
    assert!(dir_is_empty(dir.path()));
}

#[test]
fn corrupted_tile_sets_are_rejected() {
    let dir = tempfile::tempdir().expect("temp dir");
    let good = dir.path().join("good.vkt");
    let o = tiletool(&[
        "build",
        s(&data("srtm/N55W003.hgt")),
        "-o",
        s(&good),
        "--levels",
        "4",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let bytes = std::fs::read(&good).expect("read");
    let set = tiles::TileSet::open(&good).expect("open");
    let tile_at = set.dir_entry(2, 3).expect("entry").offset as usize;
    drop(set);

    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty.vkt", vec![], "too short"),
        (
            "magic.vkt",
            {
                let mut b = bytes.clone();
                b[0] = b'X';
                b
            },
            "magic",
        ),
        (
            "version.vkt",
            {
                let mut b = bytes.clone();
                b[8] = 99;
                b
            },
            "version",
        ),
        (
            "header.vkt",
            {
                let mut b = bytes.clone();
                b[16] ^= 1;
                b
            },
            "",
        ),
        (
            "truncated.vkt",
            bytes[..bytes.len() * 2 / 3].to_vec(),
            "truncated",
        ),
        (
            "tile.vkt",
            {
                let mut b = bytes.clone();
                b[tile_at + 200] ^= 0x40;
                b
            },
            "checksum",
        ),
    ];
    for (name, content, what) in cases {
        let p = write(dir.path(), name, &content);
        for cmd in ["info", "verify"] {
            let o = tiletool(&[cmd, s(&p)]);
            let err = stderr(&o);
            assert!(!o.status.success(), "{cmd} {name} succeeded");
            assert!(!err.contains("panicked"), "{cmd} {name}: {err}");
            assert!(err.contains(name), "{cmd} {name}: {err}");
            assert!(err.contains(what), "{cmd} {name}: want {what:?} in {err}");
        }
        let o = tiletool(&[
            "export",
            s(&p),
            "--tile",
            "2,3",
            "--level",
            "1",
            "-o",
            s(&dir.path().join("x.obj")),
        ]);
        assert!(
            !o.status.success() && !stderr(&o).contains("panicked"),
            "export {name}"
        );
    }
    assert!(!dir.path().join("x.obj").exists());
}

fn reseal(bytes: &mut [u8]) {
    tiles::format::reseal(bytes).expect("reseal");
}

/// A vertex decoded outside its tile, checksums recomputed: every reader refuses the file
/// with one line (info, verify, export), none panics.
#[test]
fn resealed_vertex_outside_the_tile_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let good = dir.path().join("good.vkt");
    let o = tiletool(&[
        "build",
        s(&data("srtm/N55W003.hgt")),
        "-o",
        s(&good),
        "--levels",
        "4",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let mut bytes = std::fs::read(&good).expect("read");
    let set = tiles::TileSet::open(&good).expect("open");
    let tile_at = set.dir_entry(1, 1).expect("entry").offset as usize;
    let tile = set.tile(1, 1).expect("tile");
    let finest = tile.levels()[3];
    drop(set);
    // The finest block's first vertex: x = 300 (9 bits hold it; the tile is 0..=256).
    let at = tile_at + finest.positions_offset as usize;
    let packed = u32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"));
    let moved = (packed & !0x1ff) | 300;
    bytes[at..at + 4].copy_from_slice(&moved.to_le_bytes());
    reseal(&mut bytes);
    let bad = write(dir.path(), "outside.vkt", &bytes);
    let o = tiletool(&["info", s(&bad)]);
    let err = assert_one_line_error(&o, "outside.vkt");
    assert!(err.contains("outside the mesh extent"), "info: {err}");
    // verify lists its problems, then a verdict line.
    let o = tiletool(&["verify", s(&bad)]);
    let err = stderr(&o);
    assert!(
        !o.status.success() && !err.contains("panicked"),
        "verify: {err}"
    );
    assert!(err.contains("outside the mesh extent"), "verify: {err}");
}

/// An output that would destroy data is refused: the input itself, a FIFO, a file that is not
/// a tile set (without --force); a tile set is replaced.
#[test]
fn build_never_replaces_what_it_should_not() {
    let dir = tempfile::tempdir().expect("temp dir");
    let src = dir.path().join("N55W003.hgt");
    std::fs::copy(data("srtm/N55W003.hgt"), &src).expect("copy");
    let before = std::fs::read(&src).expect("read");
    let build = |out: &Path, extra: &[&str]| {
        let mut args = vec!["build", s(&src), "-o", s(out), "--levels", "3", "--quiet"];
        args.extend(extra);
        tiletool(&args)
    };
    let o = build(&src, &[]);
    assert_one_line_error(&o, "N55W003.hgt");
    assert_eq!(
        std::fs::read(&src).expect("read"),
        before,
        "the source changed"
    );

    let notes = write(dir.path(), "notes.txt", b"keep me");
    let o = build(&notes, &[]);
    assert!(assert_one_line_error(&o, "notes.txt").contains("--force"));
    assert_eq!(std::fs::read(&notes).expect("read"), b"keep me");
    assert!(build(&notes, &["--force"]).status.success());

    let fifo = dir.path().join("pipe.vkt");
    let made = Command::new("mkfifo").arg(&fifo).status().expect("mkfifo");
    assert!(made.success());
    let o = build(&fifo, &[]);
    assert!(assert_one_line_error(&o, "pipe.vkt").contains("not a regular file"));
    for cmd in ["info", "verify"] {
        let o = tiletool(&[cmd, s(&fifo)]);
        assert!(assert_one_line_error(&o, "pipe.vkt").contains("not a regular file"));
    }

    let set = dir.path().join("set.vkt");
    assert!(build(&set, &[]).status.success());
    assert!(
        build(&set, &[]).status.success(),
        "rebuilding a tile set in place"
    );
}

/// A description with a terminal escape sequence (checksums recomputed) prints escaped.
#[test]
fn info_escapes_control_characters_in_the_description() {
    let dir = tempfile::tempdir().expect("temp dir");
    let good = dir.path().join("good.vkt");
    let o = tiletool(&[
        "build",
        s(&data("srtm/N55W003.hgt")),
        "-o",
        s(&good),
        "--levels",
        "3",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let mut bytes = std::fs::read(&good).expect("read");
    let at = std::mem::offset_of!(tiles::format::FileHeader, description);
    let evil = b"\x1b[2Jcleared\x07";
    bytes[at..at + evil.len()].copy_from_slice(evil);
    bytes[at + evil.len()] = 0;
    reseal(&mut bytes);
    let p = write(dir.path(), "evil.vkt", &bytes);
    let o = tiletool(&["info", s(&p)]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!out.contains('\x1b') && !out.contains('\x07'), "{out}");
    assert!(out.contains("\\u{1b}[2Jcleared"), "{out}");
}

/// Builds N55W003 at 3 levels into `dir` (with `extra` options) and returns the file and its
/// bytes: the starting point of the resealed-mutation tests.
fn small_srtm_set(dir: &Path, extra: &[&str]) -> (PathBuf, Vec<u8>) {
    let good = dir.join("good.vkt");
    let source = data("srtm/N55W003.hgt");
    let mut args = vec![
        "build",
        s(&source),
        "-o",
        s(&good),
        "--levels",
        "3",
        "--quiet",
    ];
    args.extend(extra);
    let o = tiletool(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let bytes = std::fs::read(&good).expect("read");
    (good, bytes)
}

/// Each case (file name, bytes, what the error must say), written into `dir`: `info` refuses
/// it with one line naming the file and saying `what`; `verify` fails without a panic, saying
/// it too.
fn refused_by_every_reader(dir: &Path, cases: Vec<(&str, Vec<u8>, &str)>) {
    for (name, content, what) in cases {
        let p = write(dir, name, &content);
        let o = tiletool(&["info", s(&p)]);
        let err = assert_one_line_error(&o, name);
        eprintln!("info {name}: {}", err.trim_end());
        assert!(err.contains(what), "info {name}: want {what:?} in {err}");
        let o = tiletool(&["verify", s(&p)]);
        let err = stderr(&o);
        assert!(
            !o.status.success() && !err.contains("panicked"),
            "verify {name}: {err}"
        );
        assert!(err.contains(what), "verify {name}: want {what:?} in {err}");
    }
}

/// Numbers that make no sense, checksums recomputed: NaN or negative spacing, a zero base
/// error, an inverted height range, a negative measured error, a NaN z range. Every reader
/// refuses them with one line naming the problem.
#[test]
fn resealed_nonsense_numbers_are_refused() {
    use tiles::format::{FileHeader, LevelEntry, TileHeader};
    let dir = tempfile::tempdir().expect("temp dir");
    let (good, bytes) = small_srtm_set(dir.path(), &[]);
    let set = tiles::TileSet::open(&good).expect("open");
    let tile_at = set.dir_entry(0, 0).expect("entry").offset as usize;
    drop(set);
    let level = |k: usize| tile_at + size_of::<TileHeader>() + k * size_of::<LevelEntry>();
    let f64_at = |at: usize, v: f64| -> Vec<u8> {
        let mut b = bytes.clone();
        b[at..at + 8].copy_from_slice(&v.to_le_bytes());
        reseal(&mut b);
        b
    };
    let f32_at = |at: usize, v: f32| -> Vec<u8> {
        let mut b = bytes.clone();
        b[at..at + 4].copy_from_slice(&v.to_le_bytes());
        reseal(&mut b);
        b
    };
    let cases = [
        (
            "nan_spacing.vkt",
            f64_at(std::mem::offset_of!(FileHeader, spacing_x), f64::NAN),
            "spacing",
        ),
        (
            "negative_spacing.vkt",
            f64_at(std::mem::offset_of!(FileHeader, spacing_y), -30.0),
            "spacing",
        ),
        (
            "huge_spacing.vkt",
            f64_at(std::mem::offset_of!(FileHeader, spacing_x), 1e300),
            "spacing",
        ),
        (
            "zero_error.vkt",
            f64_at(std::mem::offset_of!(FileHeader, base_error), 0.0),
            "base error",
        ),
        (
            "inverted.vkt",
            f32_at(std::mem::offset_of!(FileHeader, height_min), 1e6),
            "height range",
        ),
        (
            "negative_measured.vkt",
            f32_at(level(1) + std::mem::offset_of!(LevelEntry, max_error), -1.0),
            "measured error",
        ),
        (
            "nan_z.vkt",
            f32_at(level(2) + std::mem::offset_of!(LevelEntry, z_max), f32::NAN),
            "z range",
        ),
    ];
    refused_by_every_reader(dir.path(), Vec::from(cases));
}

/// Exit codes of the README's table: 0 success, 1 bad input or a failed check, 2 usage.
/// A compact set (format version 4) whose header, directory or tiles say what cannot be, with
/// every checksum resealed: `info` refuses it with one line naming the file and the problem,
/// `verify` fails without a panic. The version and the compact flag must go together; a tile
/// whose stream is cut short, or whose level table does not add up, is refused (its inner
/// checksum, or its table's checks, where the file's own checksums were resealed).
#[test]
fn resealed_compact_mutations_are_refused() {
    use tiles::format::{FileHeader, LevelEntry, TileHeader};
    let dir = tempfile::tempdir().expect("temp dir");
    let (good, bytes) = small_srtm_set(dir.path(), &["--no-texture", "--compact"]);
    let set = tiles::TileSet::open(&good).expect("open");
    assert!(set.compact());
    let entry_at =
        set.header().directory_offset as usize + 3 * size_of::<tiles::format::DirEntry>();
    let tile = set.dir_entry(3, 0).expect("entry");
    drop(set);
    let u32_at = |at: usize, v: u32| -> Vec<u8> {
        let mut b = bytes.clone();
        b[at..at + 4].copy_from_slice(&v.to_le_bytes());
        reseal(&mut b);
        b
    };
    let version = std::mem::offset_of!(FileHeader, version);
    let flags = std::mem::offset_of!(FileHeader, flags);
    let flag_bits = u32::from_le_bytes(bytes[flags..flags + 4].try_into().expect("4"));
    let len_at = entry_at + std::mem::offset_of!(tiles::format::DirEntry, len);
    let block_len = tile.offset as usize
        + size_of::<TileHeader>()
        + size_of::<LevelEntry>()
        + std::mem::offset_of!(LevelEntry, block_len);
    let cases = [
        ("v3_compact.vkt", u32_at(version, 3), "compact levels"),
        (
            "v4_plain.vkt",
            u32_at(flags, flag_bits & !tiles::format::FLAG_COMPACT_LEVELS),
            "compact levels",
        ),
        (
            "cut_stream.vkt",
            u32_at(len_at, tile.len as u32 - 1),
            "tile 3,0",
        ),
        ("bad_table.vkt", u32_at(block_len, 1_000_000), "tile 3,0"),
    ];
    refused_by_every_reader(dir.path(), Vec::from(cases));
    // The control: the good file, resealed alike, is read.
    let mut same = bytes.clone();
    reseal(&mut same);
    let p = write(dir.path(), "same.vkt", &same);
    let o = tiletool(&["verify", s(&p)]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn exit_codes_follow_the_table() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = dir.path().join("set.vkt");
    let hgt = data("srtm/N55W003.hgt");
    let build = tiletool(&["build", s(&hgt), "-o", s(&set), "--levels", "3", "--quiet"]);
    assert_eq!(build.status.code(), Some(0), "{}", stderr(&build));
    assert_eq!(tiletool(&["info", s(&set)]).status.code(), Some(0));
    assert_eq!(tiletool(&["info"]).status.code(), Some(2));
    assert_eq!(
        tiletool(&["build", "--no-such-flag"]).status.code(),
        Some(2)
    );
    let missing = dir.path().join("missing.vkt");
    assert_eq!(tiletool(&["info", s(&missing)]).status.code(), Some(1));
    // verify against the wrong source: a failed check is 1 too.
    let other = data("srtm/N43E007.hgt");
    let o = tiletool(&["verify", s(&set), "--source", s(&other)]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
}

/// An interrupted build leaves nothing behind: SIGTERM mid-build removes the temporary file
/// (exit 128 + 15), and a build finds and removes the temporary of a dead earlier build
/// (as SIGKILL leaves) while keeping a live process's.
#[test]
fn interrupted_builds_leave_no_temporary_files() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("big.vkt");
    let dead = dir.path().join(".big.vkt.tmp.999999999");
    let alive = dir
        .path()
        .join(format!(".big.vkt.tmp.{}", std::process::id()));
    std::fs::write(&dead, b"left by a SIGKILL").expect("write");
    std::fs::write(&alive, b"another build, running").expect("write");
    let mut child = Command::new(env!("CARGO_BIN_EXE_tiletool"))
        .args([
            "build",
            s(&data("puget/ps_height_4k_8bit.jpg")),
            "--spacing",
            "40",
            "--vertical-scale",
            "25.7",
            "-o",
            s(&out),
            "--quiet",
        ])
        .spawn()
        .expect("spawn");
    let own = dir.path().join(format!(".big.vkt.tmp.{}", child.id()));
    let start = std::time::Instant::now();
    // The temporary appears once the grid is read and the tiles agree on their shared sides
    // (every tile meshed several times, tools/tiles/src/build.rs): about 30 s on an idle
    // 2-core machine, over 60 s when other tests share it. The wait ends as soon as it
    // appears, so a generous limit costs nothing.
    while !own.exists() {
        assert!(
            start.elapsed().as_secs() < 300,
            "the build never started writing"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    assert!(!dead.exists(), "the dead build's temporary was kept");
    assert!(alive.exists(), "a live build's temporary was removed");
    // SAFETY: signals our own child process, which is still running (not yet waited for).
    let killed = unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
    assert_eq!(killed, 0, "kill failed");
    let status = child.wait().expect("wait");
    assert_eq!(status.code(), Some(128 + 15));
    assert!(!own.exists(), "SIGTERM left the temporary file");
    assert!(!out.exists(), "a half-written output");
}

/// Built by default, neighbouring tiles share their sides, and verify checks it; a set built
/// with `--independent-sides` whose header is forged to claim shared sides is caught (the
/// control), and has more side vertices to disagree on than zero.
#[test]
fn shared_sides_verify_and_a_forged_claim_is_caught() {
    let dir = tempfile::tempdir().expect("temp dir");
    let src = sample();
    let flags = ["--spacing", "160", "--vertical-scale", "0.1", "--quiet"];
    let (shared, alone) = (dir.path().join("shared.vkt"), dir.path().join("alone.vkt"));
    for (out, extra) in [(&shared, None), (&alone, Some("--independent-sides"))] {
        let mut args = vec!["build", s(&src), "-o", s(out)];
        args.extend(flags);
        args.extend(extra);
        let o = tiletool(&args);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let flag = |p: &Path| tiles::TileSet::open(p).expect("open").header().flags;
    assert_eq!(flag(&shared), tiles::format::FLAG_SHARED_SIDES);
    assert_eq!(flag(&alone), 0);
    let o = tiletool(&["verify", s(&shared)]);
    assert!(
        o.status.success(),
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        stderr(&o)
    );
    let o = tiletool(&["verify", s(&alone)]);
    assert!(o.status.success(), "{}", stderr(&o));

    let mut bytes = std::fs::read(&alone).expect("read");
    let at = std::mem::offset_of!(tiles::format::FileHeader, flags);
    bytes[at..at + 4].copy_from_slice(&tiles::format::FLAG_SHARED_SIDES.to_le_bytes());
    reseal(&mut bytes);
    let forged = dir.path().join("forged.vkt");
    std::fs::write(&forged, &bytes).expect("write");
    let o = tiletool(&["verify", s(&forged)]);
    assert!(
        !o.status.success(),
        "verify missed a forged shared-sides claim"
    );
    let all = format!("{}{}", String::from_utf8_lossy(&o.stdout), stderr(&o));
    assert!(
        all.contains("although the set says they share their sides"),
        "{all}"
    );
}

/// PSNR (dB) over pairs of RGB pixels.
fn psnr(pairs: impl Iterator<Item = ([u8; 3], [u8; 3])>) -> f64 {
    let (mut sum, mut n) = (0.0f64, 0u64);
    for (a, b) in pairs {
        for k in 0..3 {
            let d = f64::from(a[k]) - f64::from(b[k]);
            sum += d * d;
        }
        n += 3;
    }
    10.0 * (255.0f64.powi(2) / (sum / n as f64)).log10()
}

/// BC1 floors, documented in bench/README.md: every mip at least this PSNR against the
/// filtered mip it was compressed from, on the Puget photo and on a shaded relief.
const PSNR_FLOOR_DB: f64 = 27.0;

#[test]
fn texture_mips_meet_the_psnr_floor_on_the_photo_and_the_relief() {
    let dir = tempfile::tempdir().expect("temp dir");
    let tex = testdata::sample_texture();
    for (name, extra) in [
        ("photo.vkt", vec!["--texture", s(&tex)]),
        ("relief.vkt", vec![]),
        ("tint.vkt", vec!["--tint"]),
    ] {
        let (_, info) = build_sample(dir.path(), name, &extra);
        assert_eq!(info["format_version"], 3);
        let t = &info["texture"];
        assert_eq!(t["format"], "BC1", "{name}: {t}");
        let mips = t["mips"].as_array().expect("mips");
        assert!(mips.len() >= 7, "{name}: {} mips", mips.len());
        for m in mips {
            let db = m["psnr_db"].as_f64().expect("psnr");
            assert!(
                db >= PSNR_FLOOR_DB,
                "{name}: mip {} at {db:.2} dB",
                m["mip"]
            );
        }
        // The photo keeps its own density (1024 px over 1024 cells: 256 per tile); the relief
        // gets 2 texels per cell.
        let want = if name == "photo.vkt" { 256 } else { 512 };
        assert_eq!(t["interior_texels"], want, "{name}");
    }
}

#[test]
fn the_photo_lands_on_the_tiles_texel_for_texel() {
    // Independently of the builder's own PSNR: decode tile 1,2's mip 0 from the file and
    // compare its interior with the photo's pixels where the mapping puts them (at the
    // photo's own density, interior texel i of tile tx is photo column 256 tx + i). The
    // control: the same comparison one pixel off must be far worse, so a misplaced texture
    // cannot pass.
    let dir = tempfile::tempdir().expect("temp dir");
    let tex = testdata::sample_texture();
    let (vkt, info) = build_sample(dir.path(), "photo.vkt", &["--texture", s(&tex)]);
    let g = info["texture"]["gutter_texels"].as_u64().expect("gutter") as u32;
    let png = dir.path().join("mip0.png");
    let o = tiletool(&[
        "export",
        s(&vkt),
        "--tile",
        "1,2",
        "--texture-mip",
        "0",
        "-o",
        s(&png),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let layer = image::open(&png).expect("png").to_rgb8();
    let photo = image::open(&tex).expect("photo").to_rgb8();
    let compare = |shift: i64| {
        psnr(
            (0..256u32)
                .flat_map(|y| (0..256u32).map(move |x| (x, y)))
                .map(|(x, y)| {
                    let t = layer.get_pixel(g + x, g + y).0;
                    let px = (256 + i64::from(x) + shift).clamp(0, 1023) as u32;
                    let p = photo.get_pixel(px, 512 + y).0;
                    (t, p)
                }),
        )
    };
    let (aligned, shifted) = (compare(0), compare(1));
    assert!(aligned >= PSNR_FLOOR_DB, "aligned: {aligned:.2} dB");
    assert!(
        shifted < aligned - 3.0,
        "one pixel off is not worse: {shifted:.2} vs {aligned:.2} dB"
    );
    // The gutter holds the neighbour's texels: tile 1,2's right gutter is tile 2,2's left
    // interior, i.e. photo columns 512..512+g.
    let gutter = psnr(
        (0..256u32)
            .flat_map(|y| (0..g).map(move |k| (k, y)))
            .map(|(k, y)| {
                let t = layer.get_pixel(g + 256 + k, g + y).0;
                (t, photo.get_pixel(512 + k, 512 + y).0)
            }),
    );
    assert!(gutter >= PSNR_FLOOR_DB, "gutter: {gutter:.2} dB");
}

#[test]
fn old_versions_still_read() {
    // Files written by the version 1 builder (no textures) and the version 2 builder
    // (textured, no pyramid), kept in the fuzz corpus.
    for (name, version, textured) in [
        ("srtm-270x40.vkt", 1, false),
        ("srtm-270x40-textured.vkt", 2, true),
    ] {
        let old = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../fuzz/corpus/vkt")
            .join(name);
        let o = tiletool(&["info", s(&old), "--json"]);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        let info: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
        assert_eq!(info["format_version"], version, "{name}");
        assert_eq!(info["texture"].is_null(), !textured, "{name}");
        assert_eq!(info["pyramid"].as_array().map(Vec::len), Some(0), "{name}");
        let o = tiletool(&["verify", s(&old)]);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
    }
}

#[test]
fn bad_textures_fail_with_one_line_and_no_output() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    let src = sample();
    let flags = ["--spacing", "160"];
    let not_a_picture = write(d, "notes.png", b"this is not a picture at all");
    let mut extra = flags.to_vec();
    extra.extend(["--texture", s(&not_a_picture)]);
    build_fails(&[&src], &extra, "notes.png");
    let empty = write(d, "empty.jpg", b"");
    let mut extra = flags.to_vec();
    extra.extend(["--texture", s(&empty)]);
    build_fails(&[&src], &extra, "empty.jpg");
    let missing = d.join("missing.png");
    let mut extra = flags.to_vec();
    extra.extend(["--texture", s(&missing)]);
    build_fails(&[&src], &extra, "missing.png");
    let tiny = write(d, "tiny.png", &{
        let mut png = Vec::new();
        image::RgbImage::new(1, 1)
            .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .expect("png");
        png
    });
    let mut extra = flags.to_vec();
    extra.extend(["--texture", s(&tiny)]);
    build_fails(&[&src], &extra, "tiny.png");
    for (flag, value) in [("--texels-per-sample", "0"), ("--sun-elevation", "-5")] {
        let mut extra = flags.to_vec();
        extra.extend([flag, value]);
        build_fails(&[&src], &extra, flag);
    }
    let rgb = write(d, "rgb.tif", &rgb_tiff());
    let mut extra = flags.to_vec();
    extra.extend(["--texture", s(&rgb)]);
    let out = d.join("tiff-textured.vkt");
    let mut args = vec!["build", s(&src), "-o", s(&out), "--quiet"];
    args.extend(&extra);
    let o = tiletool(&args);
    assert!(
        o.status.success(),
        "an RGB TIFF is a texture: {}",
        stderr(&o)
    );
}

#[test]
fn a_corrupted_texture_is_caught_by_verify_and_export() {
    let dir = tempfile::tempdir().expect("temp dir");
    let tex = testdata::sample_texture();
    let (vkt, _) = build_sample(dir.path(), "photo.vkt", &["--texture", s(&tex)]);
    let mut bytes = std::fs::read(&vkt).expect("read");
    // Tile 3,3's directory entry (256-byte header, 40-byte entries, row-major) says where its
    // texture lies: offset at byte 24 of the entry, length at 32. Flip a bit in its middle.
    let entry = 256 + (3 * 4 + 3) * 40;
    let word = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes"));
    let (offset, len) = (word(entry + 24) as usize, word(entry + 32) as usize);
    assert!(len > 0 && offset + len <= bytes.len());
    bytes[offset + len / 2] ^= 0x10;
    let bad = write(dir.path(), "bad.vkt", &bytes);
    let o = tiletool(&["verify", s(&bad)]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("texture checksum"), "{}", stderr(&o));
    let png = dir.path().join("t.png");
    let o = tiletool(&[
        "export",
        s(&bad),
        "--tile",
        "3,3",
        "--texture-mip",
        "0",
        "-o",
        s(&png),
    ]);
    assert_one_line_error(&o, "bad.vkt");
}

/// Photo pixels per degree in the georeferenced tests: 1.5 per 3" cell of the SRTM heights.
const PHOTO_PX_PER_DEGREE: f64 = 1800.0;

/// The colour a test photo shows at longitude `lon`, latitude `lat`: three sinusoids of
/// 37, 29 and 53 photo pixels, so a texel taken from the wrong place shows.
fn geo_colour(lon: f64, lat: f64) -> [u8; 3] {
    let wave = |t: f64, period: f64, amplitude: f64| {
        (128.0 + amplitude * (t * PHOTO_PX_PER_DEGREE * std::f64::consts::TAU / period).sin())
            .round() as u8
    };
    [
        wave(lon, 37.0, 100.0),
        wave(lat, 29.0, 100.0),
        wave(lon + lat, 53.0, 60.0),
    ]
}

/// An RGB8 GeoTIFF photo of `geo_colour`, `w x h` pixels whose north-west corner lies at
/// `corner` in the given GeoKeys' system (`None`: no georeferencing tags at all).
fn geo_photo(path: &Path, corner: (f64, f64), (w, h): (u32, u32), keys: Option<&[u16]>) {
    use tiff::encoder::{colortype, TiffEncoder};
    use tiff::tags::Tag;
    let step = 1.0 / PHOTO_PX_PER_DEGREE;
    let rgb: Vec<u8> = (0..h)
        .flat_map(|j| (0..w).map(move |i| (i, j)))
        .flat_map(|(i, j)| {
            let lon = corner.0 + (f64::from(i) + 0.5) * step;
            let lat = corner.1 - (f64::from(j) + 0.5) * step;
            geo_colour(lon, lat)
        })
        .collect();
    let file = std::fs::File::create(path).expect("create photo");
    let mut encoder = TiffEncoder::new(file).expect("tiff");
    let mut image = encoder.new_image::<colortype::RGB8>(w, h).expect("image");
    if let Some(keys) = keys {
        let e = image.encoder();
        e.write_tag(Tag::ModelPixelScaleTag, &[step, step, 0.0][..])
            .expect("tag");
        let tie = [0.0, 0.0, 0.0, corner.0, corner.1, 0.0];
        e.write_tag(Tag::ModelTiepointTag, &tie[..]).expect("tag");
        e.write_tag(Tag::GeoKeyDirectoryTag, keys).expect("tag");
    }
    image.write_data(&rgb).expect("pixels");
}

/// GeoKeys of a geographic WGS 84 (EPSG:4326) raster of areas.
const WGS84_KEYS: [u16; 16] = [1, 1, 0, 3, 1024, 0, 1, 2, 1025, 0, 1, 1, 2048, 0, 1, 4326];

#[test]
fn a_georeferenced_photo_is_laid_by_its_georeferencing() {
    // Heights: the first 513 x 513 samples of N43E007 (2 x 2 tiles); SRTM samples are points
    // on the 3" lattice from the tile's north-west corner, 44 N 7 E (the file name says so,
    // independently of any code under test). The photo starts 0.05 degree west and 0.013
    // north of it, at 1.5 pixels per cell, and stops at 7.3 E: it covers
    // 0.3 / (512 / 1200) = 70.3% of the heights, all of them north to south.
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    let heights = data("srtm/N43E007.hgt");
    let corner = (6.95, 44.013);
    let size = (((7.3 - corner.0) * PHOTO_PX_PER_DEGREE).round() as u32, 923);
    let photo = d.join("photo.tif");
    geo_photo(&photo, corner, size, Some(&WGS84_KEYS));
    let vkt = d.join("geo.vkt");
    let build = |photo: &Path, out: &Path| {
        tiletool(&[
            "build",
            s(&heights),
            "--crop",
            "0,0,513x513",
            "-o",
            s(out),
            "--texture",
            s(photo),
        ])
    };
    let o = build(&photo, &vkt);
    assert!(o.status.success(), "{}", stderr(&o));
    let report = String::from_utf8_lossy(&o.stdout);
    assert!(
        report.contains("aligned by georeferencing (EPSG:4326), covering 70.3% of the heights"),
        "{report}"
    );
    let o = tiletool(&["info", s(&vkt), "--json"]);
    let info: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    let t = &info["texture"];
    assert!(t["placement"].as_str().unwrap().contains("georeferencing"));
    // 1.5 photo pixels per cell round to 512 texels per 256 cells.
    assert_eq!(t["interior_texels"], 512);
    let g = t["gutter_texels"].as_u64().unwrap() as u32;

    // Every interior texel of every tile against the colour the photo has at the texel's
    // own longitude and latitude (texel i of tile tx: cell 256 tx + (i + 0.5) / 2).
    let layer = |vkt: &Path, (tx, ty): (u32, u32)| {
        let png = d.join(format!("mip-{tx}-{ty}.png"));
        let tile = format!("{tx},{ty}");
        let o = tiletool(&[
            "export",
            s(vkt),
            "--tile",
            &tile,
            "--texture-mip",
            "0",
            "-o",
            s(&png),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        image::open(&png).expect("png").to_rgb8()
    };
    let texel_place = |(tx, ty): (u32, u32), (i, j): (u32, u32)| {
        let c = f64::from(256 * tx) + (f64::from(i) + 0.5) / 2.0;
        let r = f64::from(256 * ty) + (f64::from(j) + 0.5) / 2.0;
        (7.0 + c / 1200.0, 44.0 - r / 1200.0)
    };
    let photo_east = corner.0 + f64::from(size.0) / PHOTO_PX_PER_DEGREE;
    // PSNR of the texels on the photo against the photo's colours at their own place and at
    // places half a photo pixel away (a pixel-is-area/point mix-up), and the count of texels
    // beyond the photo that are not grey (BC1 stores grey 128 as 132 in its 5-bit channels,
    // hence a tolerance of 5).
    let half = 0.5 / PHOTO_PX_PER_DEGREE;
    let shifts = [
        (0.0, 0.0),
        (half, 0.0),
        (-half, 0.0),
        (0.0, half),
        (0.0, -half),
    ];
    let measure = |vkt: &Path| {
        let mut pairs = vec![Vec::new(); shifts.len()];
        let mut off_not_grey = 0;
        for tile in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            let layer = layer(vkt, tile);
            for j in 0..512 {
                for i in 0..512 {
                    let (lon, lat) = texel_place(tile, (i, j));
                    let texel = layer.get_pixel(g + i, g + j).0;
                    // A texel within two photo pixels of the photo's edge blends both sides.
                    let margin = 2.0 / PHOTO_PX_PER_DEGREE;
                    if lon < photo_east - margin {
                        for (p, (dx, dy)) in pairs.iter_mut().zip(shifts) {
                            p.push((texel, geo_colour(lon + dx, lat + dy)));
                        }
                    } else if lon > photo_east + margin
                        && texel.iter().any(|&c| c.abs_diff(128) > 5)
                    {
                        off_not_grey += 1;
                    }
                }
            }
        }
        let psnrs: Vec<f64> = pairs.into_iter().map(|p| psnr(p.into_iter())).collect();
        (psnrs, off_not_grey)
    };
    let (psnrs, off_not_grey) = measure(&vkt);
    let on = psnrs[0];
    assert!(on >= PSNR_FLOOR_DB, "aligned: {on:.2} dB");
    for (shift, db) in shifts.iter().zip(&psnrs).skip(1) {
        assert!(
            *db < on - 0.5,
            "half a photo pixel off {shift:?} is not worse: {db:.2} vs {on:.2} dB"
        );
    }
    assert_eq!(off_not_grey, 0, "texels beyond the photo that are not grey");

    // Control: the same pixels without georeferencing are stretched over the grid instead,
    // and the same measure finds them far from where they belong.
    let plain = d.join("plain.tif");
    geo_photo(&plain, corner, size, None);
    let stretched = d.join("stretched.vkt");
    let o = build(&plain, &stretched);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("span the height grid exactly"));
    let control = measure(&stretched).0[0];
    eprintln!("aligned {on:.2} dB, half a pixel off {psnrs:.2?} dB, stretched {control:.2} dB");
    assert!(
        control < on - 10.0,
        "a stretched photo measures {control:.2} dB, the aligned one {on:.2} dB"
    );
}

#[test]
fn photos_that_cannot_be_laid_on_the_heights_are_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    let heights = data("srtm/N43E007.hgt");
    let crop = ["--crop", "0,0,257x257"];
    // Three degrees east of the heights.
    let far = d.join("far.tif");
    geo_photo(&far, (10.0, 44.0), (200, 200), Some(&WGS84_KEYS));
    let mut extra = crop.to_vec();
    extra.extend(["--texture", s(&far)]);
    let err = build_fails(&[&heights], &extra, "far.tif");
    assert!(err.contains("does not overlap the heights"), "{err}");
    // A projected photo (UTM 32N, EPSG:32632) over geographic heights.
    let utm = d.join("utm.tif");
    let utm_keys = [1u16, 1, 0, 2, 1024, 0, 1, 1, 3072, 0, 1, 32632];
    geo_photo(&utm, (350_000.0, 4_870_000.0), (200, 200), Some(&utm_keys));
    let mut extra = crop.to_vec();
    extra.extend(["--texture", s(&utm)]);
    let err = build_fails(&[&heights], &extra, "utm.tif");
    assert!(
        err.contains("EPSG:32632") && err.contains("EPSG:4326"),
        "{err}"
    );
}
