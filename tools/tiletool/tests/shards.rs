//! Distributed builds end to end (issue 29): `tiletool build --shard K/N` on real data, the
//! parts merged into the same bytes as a build without shards (seams settled by the halos,
//! and resumed from the input where a halo of 0 leaves them unsettled), and every part that
//! does not belong refused with one line, leaving no output behind.

mod common;

use std::path::{Path, PathBuf};
use std::process::Output;

use common::{s, stderr, tiletool};
use testdata::data;

/// SRTM3 N55W003 (1201 x 1201: 5 x 5 tiles), rugged, no voids.
fn srtm3() -> PathBuf {
    data("srtm/N55W003.hgt")
}

fn build(input: &Path, out: &Path, extra: &[&str]) {
    let mut args = vec!["build", s(input), "-o", s(out), "--quiet"];
    args.extend(extra);
    let o = tiletool(&args);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// The parts of an `n`-shard build of `input` in `dir`, named `part-K-of-N`.
fn shards(input: &Path, dir: &Path, n: u32, extra: &[&str]) -> Vec<PathBuf> {
    (0..n)
        .map(|k| {
            let part = dir.join(format!("part-{k}-of-{n}"));
            let shard = format!("{k}/{n}");
            let mut args = vec!["--shard", &shard];
            args.extend(extra);
            build(input, &part, &args);
            part
        })
        .collect()
}

fn merge(parts: &[PathBuf], out: &Path) -> Output {
    let mut args = vec!["merge", "-o", s(out)];
    args.extend(parts.iter().map(|p| s(p)));
    tiletool(&args)
}

fn same_bytes(a: &Path, b: &Path) -> bool {
    std::fs::read(a).expect("read") == std::fs::read(b).expect("read")
}

/// Merged parts are the build's bytes: at 2 and 5 shards with the default halo, with a halo
/// of 0 (the seams left for the merge to settle from the input, the pyramid's layers' as
/// well as the base grid's: it must say so), with independent sides, with compact levels and
/// a tinted relief, and with a pyramid (whose layers the shards build, each its rows of
/// every layer: 3 x 3, 2 x 2 and 1 x 1 tiles here, so some shards own no row of the upper
/// layers), compact and not, and under a photo. The control: a set built
/// with other options differs from the merged one, so the comparison can fail.
#[test]
fn merged_parts_are_the_builds_bytes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let input = srtm3();
    for (case, (n, extra)) in [
        (2, &[][..]),
        (5, &[][..]),
        (3, &["--independent-sides", "--no-texture"][..]),
        (3, &["--compact", "--tint"][..]),
        (2, &["--pyramid"][..]),
        (4, &["--pyramid", "--compact", "--tint"][..]),
    ]
    .into_iter()
    .enumerate()
    {
        let whole = dir.path().join(format!("whole-{case}.vkt"));
        build(&input, &whole, extra);
        let sub = dir.path().join(format!("case-{case}"));
        std::fs::create_dir(&sub).expect("dir");
        let parts = shards(&input, &sub, n, extra);
        let merged = sub.join("merged.vkt");
        let o = merge(&parts, &merged);
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(
            same_bytes(&merged, &whole),
            "{n} shards {extra:?}: the merged set differs from the build"
        );
    }
    // Compact levels on rough ground (SRTM1 N43E007 in 3 shards), whose shards' morph units
    // differed from the set's while the units followed the tiles' deviations (the merge then
    // sealed most tiles again): the units now come from the scan's bounds, the same in every
    // shard, so the merge copies every tile, and the bytes are the build's. The merge's
    // sealing again, for tiles past their bounds, is tested in tools/tiles/tests/units.rs.
    let input_units = data("srtm/N43E007.hgt");
    let whole = dir.path().join("whole-units.vkt");
    build(&input_units, &whole, &["--compact"]);
    let sub = dir.path().join("units");
    std::fs::create_dir(&sub).expect("dir");
    let parts = shards(&input_units, &sub, 3, &["--compact"]);
    let merged = sub.join("merged.vkt");
    let o = merge(&parts, &merged);
    assert!(o.status.success(), "{}", stderr(&o));
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        !said.contains("sealed again at the set's morph units"),
        "tiles were sealed again: a shard's units were not the set's: {said}"
    );
    assert!(
        same_bytes(&merged, &whole),
        "compact, rough ground: differs from the build"
    );
    // The parts hold the compact bytes, not version 3 blobs: together about the set's size.
    // The control: the same shards without --compact weigh several times more.
    let weight = |parts: &[PathBuf]| -> u64 {
        parts
            .iter()
            .map(|p| std::fs::metadata(p).expect("part").len())
            .sum()
    };
    let set_bytes = std::fs::metadata(&whole).expect("set").len();
    assert!(
        weight(&parts) < set_bytes * 11 / 10,
        "compact parts weigh {} bytes, the set {set_bytes}",
        weight(&parts)
    );
    let sub = dir.path().join("units-v3");
    std::fs::create_dir(&sub).expect("dir");
    let v3_parts = shards(&input_units, &sub, 3, &[]);
    assert!(
        weight(&v3_parts) > 2 * weight(&parts),
        "the control: version 3 parts are not heavier"
    );
    // A photo over a pyramid: the shards texture the layers' tiles too.
    let puget = data("puget/ps_height_1k.png");
    let photo = data("puget/ps_texture_1k.png");
    let photo_args = [
        "--pyramid",
        "--spacing",
        "160",
        "--vertical-scale",
        "0.1",
        "--texture",
        s(&photo),
    ];
    let whole = dir.path().join("whole-photo.vkt");
    build(&puget, &whole, &photo_args);
    let sub = dir.path().join("photo");
    std::fs::create_dir(&sub).expect("dir");
    let parts = shards(&puget, &sub, 3, &photo_args);
    let merged = sub.join("merged.vkt");
    let o = merge(&parts, &merged);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        same_bytes(&merged, &whole),
        "a photo over a pyramid: differs from the build"
    );
    // A halo of 0: the shards see no neighbour across their seams, so the merge must resume
    // the agreement there and build those tiles again, in the base grid and in the layers.
    let whole = dir.path().join("whole-halo0.vkt");
    build(&input, &whole, &["--pyramid"]);
    let sub = dir.path().join("halo0");
    std::fs::create_dir(&sub).expect("dir");
    let parts = shards(&input, &sub, 3, &["--halo", "0", "--pyramid"]);
    let merged = sub.join("merged.vkt");
    let o = tiletool(&[
        "merge",
        s(&parts[0]),
        s(&parts[1]),
        s(&parts[2]),
        "-o",
        s(&merged),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        said.contains(" tiles unsettled") && said.contains(" tiles built again from the input"),
        "the merge did not settle the seams itself: {said}"
    );
    assert!(
        said.contains("layer tiles unsettled") && said.contains("layer tiles built again"),
        "the merge did not settle the layers' seams itself: {said}"
    );
    assert!(
        same_bytes(&merged, &whole),
        "halo 0: differs from the build"
    );
    // The control: other options, other bytes.
    let other = dir.path().join("other.vkt");
    build(&input, &other, &["--levels", "8"]);
    assert!(!same_bytes(&merged, &other), "the comparison cannot fail");
}

/// Every shard's scan of `input` (`--scan-only`, no texture) into `dir`, as `--scans` reads
/// them.
fn scan_all(input: &Path, dir: &Path, n: u32) {
    for k in 0..n {
        let out = dir.join(format!("scan-{k}-of-{n}.vktscan"));
        let shard = format!("{k}/{n}");
        let o = tiletool(&[
            "build",
            s(input),
            "--no-texture",
            "--shard",
            &shard,
            "--scan-only",
            "-o",
            s(&out),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
}

/// With every shard's scan (`tiletool build --shard K/N --scan-only`), a shard reads only its
/// own rows and the merged set is still the build's bytes. N55W003 (void-free) in 5 shards of
/// one tile row, halo 0 so that a shard's window is its row (the merge settles the seams): a
/// shard says how much it read, under 0.6 of the file with scans (its row twice, and the
/// inputs' fingerprints), and over twice the
/// file without them (the control: it reads the whole input twice to scan it). With a
/// pyramid, the scans carry the layers' figures too (below). A scan of other inputs is
/// refused.
#[test]
fn with_scans_a_shard_reads_only_its_rows_and_the_set_is_the_same() {
    let dir = tempfile::tempdir().expect("temp dir");
    let input = srtm3();
    let whole = dir.path().join("whole.vkt");
    build(&input, &whole, &["--no-texture"]);
    let scans = dir.path().join("scans");
    std::fs::create_dir(&scans).expect("dir");
    let n = 5;
    scan_all(&input, &scans, n);
    let shard_args = |k: u32, part: &Path, with_scans: bool| -> Output {
        let given = with_scans.then_some(scans.as_path());
        let o = halo_0_shard(&input, (k, n), part, (given, &[]));
        assert!(o.status.success(), "{}", stderr(&o));
        o
    };
    let (parts, with) = shard_all(dir.path(), "part", n, |k, part| shard_args(k, part, true));
    let merged = dir.path().join("merged.vkt");
    let o = merge(&parts, &merged);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        same_bytes(&merged, &whole),
        "with scans: differs from the build"
    );
    let without = input_read(&shard_args(2, &dir.path().join("alone"), false));
    let file = std::fs::metadata(&input).expect("input").len() as f64 / 1e6;
    assert!(
        with[2] < 0.6 * file && without > 2.0 * file,
        "shard 2/{n} read {} MB with scans and {without} MB without, of a {file} MB input",
        with[2]
    );
    // With a pyramid: the scans hold each shard's rows of every layer, so a shard scans no
    // layer whole, and the set is the build's. The control: the same scans without their
    // layers (`layers -`, resealed) make the shard scan each layer itself, about 0.9 of the
    // file more (every second, fourth and eighth row), for the same part.
    let whole = dir.path().join("whole-pyramid.vkt");
    build(&input, &whole, &["--no-texture", "--pyramid"]);
    let pyramid_shard = |k: u32, part: &Path, scans: &Path| -> Output {
        let o = halo_0_shard(&input, (k, n), part, (Some(scans), &["--pyramid"]));
        assert!(o.status.success(), "{}", stderr(&o));
        o
    };
    let (parts, with) = shard_all(dir.path(), "pyramid", n, |k, part| {
        pyramid_shard(k, part, &scans)
    });
    let merged = dir.path().join("merged-pyramid.vkt");
    let o = merge(&parts, &merged);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        same_bytes(&merged, &whole),
        "a pyramid with scans: differs from the build"
    );
    let bare = dir.path().join("scans-without-layers");
    std::fs::create_dir(&bare).expect("dir");
    for k in 0..n {
        let name = format!("scan-{k}-of-{n}.vktscan");
        let text = std::fs::read_to_string(scans.join(&name)).expect("scan");
        let (body, _) = text.trim_end().rsplit_once("\ncrc ").expect("crc line");
        let body: String = body
            .lines()
            .map(|l| match l.starts_with("layers ") {
                true => "layers -\n".to_string(),
                false => format!("{l}\n"),
            })
            .collect();
        let crc = crc32fast::hash(body.as_bytes());
        std::fs::write(bare.join(&name), format!("{body}crc {crc:08x}\n")).expect("write");
    }
    let alone = dir.path().join("pyramid-alone");
    let without = input_read(&pyramid_shard(2, &alone, &bare));
    assert!(
        same_bytes(&alone, &parts[2]),
        "without the layers' scans: another part"
    );
    assert!(
        without > with[2] + 0.5 * file,
        "shard 2/{n} of a pyramid read {} MB with the layers' scans and {without} MB without, \
         of a {file} MB input",
        with[2]
    );
    // A scan of another input: refused, naming the scan.
    let other = data("srtm/N41E001.hgt");
    let o = tiletool(&[
        "build",
        s(&other),
        "--no-texture",
        "--shard",
        "0/5",
        "--scans",
        s(&scans),
        "-o",
        s(&dir.path().join("x")),
    ]);
    assert!(!o.status.success(), "a scan of another input was taken");
    assert!(stderr(&o).contains("scan-0-of-5.vktscan"), "{}", stderr(&o));
}

/// Shard `k` of `n` of `input`, untextured, with a halo of 0 (a shard's window is its rows;
/// the merge settles the seams), into `part`, given every shard's scans (and ranges) in
/// `scans` when there are some.
fn halo_0_shard(
    input: &Path,
    (k, n): (u32, u32),
    part: &Path,
    (scans, extra): (Option<&Path>, &[&str]),
) -> Output {
    let shard = format!("{k}/{n}");
    let mut args = vec![
        "build",
        s(input),
        "--no-texture",
        "--halo",
        "0",
        "--shard",
        &shard,
        "-o",
        s(part),
    ];
    if let Some(dir) = scans {
        args.extend(["--scans", s(dir)]);
    }
    args.extend(extra);
    tiletool(&args)
}

/// Shards `0..n` built by `shard` (given the index and the part's path) into `dir`, their
/// parts named `{name}-{k}-of-{n}`: the parts, and what each read of its input (MB).
fn shard_all(
    dir: &Path,
    name: &str,
    n: u32,
    shard: impl Fn(u32, &Path) -> Output,
) -> (Vec<PathBuf>, Vec<f64>) {
    (0..n)
        .map(|k| {
            let part = dir.join(format!("{name}-{k}-of-{n}"));
            let read = input_read(&shard(k, &part));
            (part, read)
        })
        .unzip()
}

/// The figure a shard prints of what it read of its input, MB.
fn input_read(o: &Output) -> f64 {
    let said = String::from_utf8_lossy(&o.stdout);
    let line = said
        .lines()
        .find(|l| l.contains("input read"))
        .unwrap_or_else(|| panic!("no input-read figure: {said}"));
    let mb = line.split("input read ").nth(1).expect("figure");
    mb.split_whitespace()
        .next()
        .expect("MB")
        .parse()
        .expect("number")
}

/// An input with voids (SRTM1 N48W125, half of it sea) in three stages: every shard's scan
/// pulls its rows' share of the void fill's pass, every shard's ranges fill its rows with the
/// plan joined from all the scans, then each shard reads only its rows with the margin their
/// fill needs. The merged set is the build's bytes, and each of 5 shards (halo 0) reads under
/// 1.3x the file where the control, the same shard without scans, reads over 3x (the whole
/// input to scan it and again to range its tiles). A shard without the ranges is refused with
/// one line naming the missing file, and ranges from other scans are refused.
#[test]
fn with_scans_and_ranges_a_shard_fills_its_voids_from_its_rows() {
    let dir = tempfile::tempdir().expect("temp dir");
    let voids = data("srtm/N48W125.hgt");
    let whole = dir.path().join("n48.vkt");
    build(&voids, &whole, &["--no-texture"]);
    let scans = dir.path().join("n48-scans");
    std::fs::create_dir(&scans).expect("dir");
    let n = 5;
    scan_all(&voids, &scans, n);
    let shard_build = |k: u32, part: &Path, with_scans: bool| -> Output {
        halo_0_shard(
            &voids,
            (k, n),
            part,
            (with_scans.then_some(scans.as_path()), &[]),
        )
    };
    // Without the second stage: refused, naming the ranges file.
    let o = shard_build(0, &dir.path().join("early"), true);
    assert!(!o.status.success(), "built without the ranges");
    assert!(
        stderr(&o).contains("ranges-0-of-5.vktranges") && stderr(&o).lines().count() == 1,
        "{}",
        stderr(&o)
    );
    let ranges = |k: u32| -> Output {
        let shard = format!("{k}/{n}");
        let out = scans.join(format!("ranges-{k}-of-{n}.vktranges"));
        let args = [
            "build",
            s(&voids),
            "--no-texture",
            "--shard",
            &shard,
            "--scans",
            s(&scans),
            "--ranges-only",
            "-o",
            s(&out),
        ];
        tiletool(&args)
    };
    for k in 0..n {
        let o = ranges(k);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let file = std::fs::metadata(&voids).expect("input").len() as f64 / 1e6;
    let mut parts = Vec::new();
    for k in 0..n {
        let part = dir.path().join(format!("n48-{k}"));
        let o = shard_build(k, &part, true);
        assert!(o.status.success(), "{}", stderr(&o));
        let read = input_read(&o);
        assert!(
            read < 1.3 * file,
            "shard {k}/{n} read {read} MB of a {file} MB input"
        );
        parts.push(part);
    }
    let merged = dir.path().join("n48-merged.vkt");
    let o = merge(&parts, &merged);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        same_bytes(&merged, &whole),
        "N48W125 in 5 scanned shards: differs from the build"
    );
    let o = shard_build(2, &dir.path().join("alone"), false);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        input_read(&o) > 3.0 * file,
        "the control read {} MB",
        input_read(&o)
    );
    // Ranges from the scans of another input: refused, naming them.
    let other = dir.path().join("other-scans");
    std::fs::create_dir(&other).expect("dir");
    let input = data("srtm/N42E001.hgt");
    scan_all(&input, &other, n);
    let theirs = other.join("ranges-1-of-5.vktranges");
    let args = [
        "build",
        s(&input),
        "--no-texture",
        "--shard",
        "1/5",
        "--scans",
        s(&other),
        "--ranges-only",
        "-o",
        s(&theirs),
    ];
    let o = tiletool(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::copy(&theirs, scans.join("ranges-1-of-5.vktranges")).expect("copy");
    let o = shard_build(0, &dir.path().join("foreign"), true);
    assert!(!o.status.success(), "built with foreign ranges");
    assert!(
        stderr(&o).contains("ranges-1-of-5.vktranges"),
        "{}",
        stderr(&o)
    );
}

/// Parts that do not make one set are refused with one line naming the part, and nothing is
/// written: a shard missing, one given twice, a part of other options, one of a build in
/// other shards, one cut short (as a killed shard cannot leave: it writes a temporary
/// file), a flipped byte, and a file that is no part. Bad `--shard` values are refused
/// before any work.
/// Where a part's fields lie (tools/tiles/src/shard.rs, "The part file"): the offset of its
/// owned tile rows, its levels, and where its first tile's record starts.
fn part_layout(bytes: &[u8]) -> (usize, u32, usize) {
    let recipe_len = u32::from_le_bytes(bytes[24..28].try_into().expect("4 bytes")) as usize;
    let rows_at = 28 + recipe_len + size_of::<tiles::format::FileHeader>();
    let levels = u32::from_le_bytes(bytes[rows_at + 12..rows_at + 16].try_into().expect("4"));
    // The rows, tiles across and levels; the units and the bounds, 8 bytes a level each; the
    // agreement's passes and meshes.
    (rows_at, levels, rows_at + 16 + 16 * levels as usize + 12)
}

/// A part's bytes before its checksum, sealed as the writer seals them: the crc32 of
/// everything before it, then the end mark.
fn sealed(mut body: Vec<u8>) -> Vec<u8> {
    let crc = crc32fast::hash(&body);
    body.extend(crc.to_le_bytes());
    body.extend(b"VKTPEND\0");
    body
}

#[test]
fn parts_that_do_not_belong_are_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let input = srtm3();
    let parts = shards(&input, dir.path(), 3, &["--no-texture"]);
    let out = dir.path().join("set.vkt");
    let refused = |parts: &[PathBuf], names: &Path, what: &str| {
        let o = merge(parts, &out);
        let err = stderr(&o);
        assert!(!o.status.success(), "{what}: merged");
        assert_eq!(err.lines().count(), 1, "{what}: not one line: {err}");
        assert!(
            err.contains(s(names)) || err.contains(what),
            "{what}: {err}"
        );
        assert!(!err.contains("panicked"), "{what}: {err}");
        assert!(!out.exists(), "{what}: an output was left");
        let leftovers: Vec<_> = std::fs::read_dir(dir.path())
            .expect("dir")
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().contains(".tmp."))
            .collect();
        assert!(leftovers.is_empty(), "{what}: {leftovers:?}");
        err
    };
    let err = refused(&parts[..2], &parts[0], "shard 2/3 is missing");
    assert!(err.contains("shard 2/3 is missing"), "{err}");
    let twice = [parts[0].clone(), parts[1].clone(), parts[1].clone()];
    let err = refused(&twice, &parts[1], "given twice");
    assert!(err.contains("given twice"), "{err}");
    let foreign = dir.path().join("foreign");
    build(
        &input,
        &foreign,
        &["--shard", "2/3", "--no-texture", "--levels", "8"],
    );
    let mixed = [parts[0].clone(), parts[1].clone(), foreign.clone()];
    let err = refused(&mixed, &foreign, "other inputs or options");
    assert!(
        err.contains("levels"),
        "the differing option is not named: {err}"
    );
    let four = dir.path().join("four");
    build(&input, &four, &["--shard", "3/4", "--no-texture"]);
    let mixed = [
        parts[0].clone(),
        parts[1].clone(),
        parts[2].clone(),
        four.clone(),
    ];
    refused(&mixed, &four, "shards");
    let bytes = std::fs::read(&parts[1]).expect("read");
    let cut = dir.path().join("cut");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).expect("write");
    let err = refused(
        &[parts[0].clone(), cut.clone(), parts[2].clone()],
        &cut,
        "incomplete",
    );
    assert!(err.contains("incomplete"), "{err}");
    let mut flipped = bytes.clone();
    flipped[bytes.len() / 2] ^= 0x10;
    let damaged = dir.path().join("damaged");
    std::fs::write(&damaged, &flipped).expect("write");
    let err = refused(
        &[parts[0].clone(), damaged.clone(), parts[2].clone()],
        &damaged,
        "damaged",
    );
    assert!(err.contains("checksum"), "{err}");
    // A part forged and resealed (its checksum made to match): shard 0 of 2^32 - 1, owning
    // no tile row, so that only the shard count is wrong. Refused for it, not trusted into
    // an allocation of that many shards.
    let (rows_at, _, tiles_at) = part_layout(&bytes);
    let mut forged = bytes[..tiles_at].to_vec();
    forged[12..16].copy_from_slice(&0u32.to_le_bytes());
    forged[16..20].copy_from_slice(&u32::MAX.to_le_bytes());
    forged[rows_at..rows_at + 8].fill(0);
    let forged = sealed(forged);
    let resealed = dir.path().join("resealed");
    std::fs::write(&resealed, &forged).expect("write");
    let err = refused(
        &[resealed.clone(), parts[1].clone()],
        &resealed,
        "do not add up",
    );
    assert!(err.contains("do not add up"), "{err}");
    // A part whose scan's bounds on the morph units (after its units, 8 bytes a level) differ
    // from the others', resealed: its tiles were sealed at other units, so it is refused.
    let (rows_at, levels, _) = part_layout(&bytes);
    let at = rows_at + 16 + 8 * levels as usize;
    let mut forged = bytes[..bytes.len() - 12].to_vec();
    let bound = f64::from_le_bytes(forged[at..at + 8].try_into().expect("8"));
    forged[at..at + 8].copy_from_slice(&(bound * 2.0).to_le_bytes());
    let forged = sealed(forged);
    let bounded = dir.path().join("bounded");
    std::fs::write(&bounded, &forged).expect("write");
    let err = refused(
        &[parts[0].clone(), bounded.clone(), parts[2].clone()],
        &bounded,
        "bounds differ",
    );
    assert!(err.contains("bounds differ"), "{err}");
    // A compact part whose first tile's stored level length is wrong, the part's checksum made
    // to match: the merge checks what it copies (decoded against the tile's table and
    // lengths), so it is refused, naming the part and the tile. The control: the same part
    // unchanged merges.
    let compact_dir = dir.path().join("compact");
    std::fs::create_dir(&compact_dir).expect("dir");
    let compact = shards(&input, &compact_dir, 3, &["--no-texture", "--compact"]);
    let bytes = std::fs::read(&compact[1]).expect("read");
    let (_, levels, tiles_at) = part_layout(&bytes);
    // Forced sides and sides (4 sides of 5 words a level, each), deviations, the blob's length.
    let blob_len_at = tiles_at + levels as usize * (2 * 4 * 40 + 8);
    let blob_at = (blob_len_at + 8).next_multiple_of(16);
    let table = size_of::<tiles::format::TileHeader>()
        + levels as usize * size_of::<tiles::format::LevelEntry>();
    let first_length = blob_at + table + 4;
    let mut forged = bytes[..bytes.len() - 12].to_vec();
    let n = u32::from_le_bytes(
        forged[first_length..first_length + 4]
            .try_into()
            .expect("4"),
    );
    forged[first_length..first_length + 4].copy_from_slice(&(n + 1).to_le_bytes());
    let forged = sealed(forged);
    let forged_part = compact_dir.join("forged");
    std::fs::write(&forged_part, &forged).expect("write");
    let err = refused(
        &[compact[0].clone(), forged_part.clone(), compact[2].clone()],
        &forged_part,
        "its length says",
    );
    assert!(
        err.contains("its length says") && err.contains("tile 0,"),
        "the damaged tile is not named: {err}"
    );
    let o = merge(&compact, &out);
    assert!(o.status.success(), "the control: {}", stderr(&o));
    std::fs::remove_file(&out).expect("rm");
    let set = dir.path().join("a-set");
    build(&input, &set, &["--no-texture"]);
    refused(
        &[parts[0].clone(), set.clone(), parts[2].clone()],
        &set,
        "not a vkterrain part file",
    );
    // The parts, all present, still merge: the refusals above were about the parts given.
    let o = merge(&parts, &out);
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::remove_file(&out).expect("rm");
    for (shard, why) in [
        ("3/3", "expected K/N"),
        ("x/3", "expected K/N"),
        ("7/9", "at most 5 shards"),
    ] {
        let part = dir.path().join("bad-shard");
        let o = tiletool(&[
            "build",
            s(&input),
            "--shard",
            shard,
            "-o",
            s(&part),
            "--quiet",
        ]);
        let err = stderr(&o);
        assert!(
            !o.status.success() && err.contains(why),
            "--shard {shard}: {err}"
        );
        assert!(!part.exists(), "--shard {shard}: a part was written");
    }
}
