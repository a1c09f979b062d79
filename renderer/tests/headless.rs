//! `vkterrain` headless on lavapipe with the validation layer on: real tile sets (the bundled
//! Puget sample and SRTM), renders that are terrain, no cracks against brute force, a
//! silhouette within tau + 1 pixels, and clear errors for broken tile sets.

use std::path::Path;
use std::process::{Command, Output};

mod common;

use common::{data, puget, tileset};

const SKY: [u8; 3] = [255, 0, 255];

fn vkterrain(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vkterrain"))
        .args(args)
        .output()
        .expect("vkterrain runs")
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// Runs a headless flight with validation and a magenta sky; returns the screenshots' pixels.
fn flight(
    set: &Path,
    out: &Path,
    path: &str,
    frames: u32,
    extra: &[&str],
) -> Vec<image::RgbaImage> {
    let log = out.join("frames.csv");
    let frames_s = frames.to_string();
    let mut args = vec![
        s(set),
        "--headless",
        "--validation",
        "--path",
        path,
        "--frames",
        &frames_s,
        "--sky",
        "1,0,1",
        "--log",
        s(&log),
        "--out",
        s(out),
        "--screenshot-every",
        "1",
    ];
    if !extra.contains(&"--size") {
        args.extend(["--size", "256x192"]);
    }
    args.extend(extra);
    let o = vkterrain(&args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        o.status.success(),
        "vkterrain failed ({:?}): {err}",
        o.status.code()
    );
    assert!(!err.contains("validation"), "validation messages: {err}");
    (0..frames)
        .map(|k| {
            image::open(out.join(format!("frame_{k:06}.png")))
                .expect("screenshot")
                .to_rgba8()
        })
        .collect()
}

fn is_sky(p: &image::Rgba<u8>) -> bool {
    p.0[0] == SKY[0] && p.0[1] == SKY[1] && p.0[2] == SKY[2]
}

/// Sky pixels with terrain on both sides (horizontally or vertically) in `lod`, where the
/// brute-force image has terrain all around: holes in the surface.
fn cracks(lod: &image::RgbaImage, brute: &image::RgbaImage) -> Vec<(u32, u32)> {
    let (w, h) = lod.dimensions();
    let deep_terrain = |x: u32, y: u32| {
        (x.saturating_sub(3)..=(x + 3).min(w - 1)).all(|i| {
            (y.saturating_sub(3)..=(y + 3).min(h - 1)).all(|j| !is_sky(brute.get_pixel(i, j)))
        })
    };
    let mut found = Vec::new();
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            if !is_sky(lod.get_pixel(x, y)) {
                continue;
            }
            let flanked_h = !is_sky(lod.get_pixel(x - 1, y)) && !is_sky(lod.get_pixel(x + 1, y));
            let flanked_v = !is_sky(lod.get_pixel(x, y - 1)) && !is_sky(lod.get_pixel(x, y + 1));
            if (flanked_h || flanked_v) && deep_terrain(x, y) {
                found.push((x, y));
            }
        }
    }
    found
}

/// Per column, the first terrain row from the top (the horizon), where there is one.
fn horizon(img: &image::RgbaImage) -> Vec<Option<u32>> {
    let (w, h) = img.dimensions();
    (0..w)
        .map(|x| (0..h).find(|&y| !is_sky(img.get_pixel(x, y))))
        .collect()
}

/// The crack detector finds the seams when stitching is switched off (so a pass means
/// something), and none with it.
#[test]
fn without_stitching_the_seams_show() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = puget(dir.path());
    let (a, b) = (dir.path().join("open"), dir.path().join("brute"));
    let open = flight(
        &set,
        &a,
        "flyover",
        6,
        &["--no-stitch", "--size", "512x384"],
    );
    let brute = flight(
        &set,
        &b,
        "flyover",
        6,
        &["--brute-force", "--size", "512x384"],
    );
    let total: usize = open
        .iter()
        .zip(&brute)
        .map(|(o, b)| cracks(o, b).len())
        .sum();
    assert!(
        total > 0,
        "no crack pixels found with stitching off: the detector is blind"
    );
}

fn compare_with_brute_force(set: &Path, path: &str, frames: u32, tau: f64) {
    let dir = tempfile::tempdir().expect("temp dir");
    let (a, b) = (dir.path().join("lod"), dir.path().join("brute"));
    let tau_s = tau.to_string();
    let lod = flight(set, &a, path, frames, &["--tau", &tau_s]);
    let brute = flight(set, &b, path, frames, &["--brute-force"]);
    let mut terrain_seen = false;
    for (k, (l, b)) in lod.iter().zip(&brute).enumerate() {
        let c = cracks(l, b);
        assert!(
            c.is_empty(),
            "{path} frame {k}: {} crack pixels, first at {:?}",
            c.len(),
            &c[..c.len().min(5)]
        );
        let (hl, hb) = (horizon(l), horizon(b));
        let worst = hl
            .iter()
            .zip(&hb)
            .filter_map(|(x, y)| Some(x.as_ref()?.abs_diff(*y.as_ref()?)))
            .max()
            .unwrap_or(0);
        assert!(
            f64::from(worst) <= tau + 1.0,
            "{path} frame {k}: silhouette off by {worst} px (tau {tau})"
        );
        terrain_seen |= hl.iter().any(Option::is_some);
    }
    assert!(terrain_seen, "{path}: no frame showed terrain");
}

#[test]
fn puget_renders_terrain_with_a_log_and_no_validation_messages() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = puget(dir.path());
    let out = dir.path().join("shots");
    let shots = flight(&set, &out, "orbit", 4, &[]);
    for (k, img) in shots.iter().enumerate() {
        let total = img.pixels().count() as f64;
        let terrain: Vec<&image::Rgba<u8>> = img.pixels().filter(|p| !is_sky(p)).collect();
        assert!(
            terrain.len() as f64 > 0.2 * total,
            "frame {k}: only {} terrain pixels",
            terrain.len()
        );
        // Shaded terrain, not one flat colour: many distinct colours.
        let mut colours: Vec<[u8; 3]> = terrain.iter().map(|p| [p.0[0], p.0[1], p.0[2]]).collect();
        colours.sort_unstable();
        colours.dedup();
        assert!(colours.len() > 200, "frame {k}: {} colours", colours.len());
    }
    let csv = std::fs::read_to_string(out.join("frames.csv")).expect("log");
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    for col in [
        "frame",
        "time_s",
        "frame_ms",
        "cpu_cull_ms",
        "gpu_ms",
        "tiles_visible",
        "triangles",
        "stitch_triangles",
        "upload_bytes",
        "resident_bytes",
        "evictions",
        "tiles_level_0",
    ] {
        assert!(header.contains(&col), "missing column {col}");
    }
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 4);
    assert!(rows.iter().all(|r| r.len() == header.len()));
    let tri = header.iter().position(|c| *c == "triangles").expect("col");
    assert!(rows
        .iter()
        .all(|r| r[tri].parse::<u64>().expect("number") > 0));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("frames.json")).expect("summary"))
            .expect("json");
    assert_eq!(summary["frames"], 4);
    assert_eq!(summary["validation_messages"], 0);
}

#[test]
fn puget_lod_has_no_cracks_and_keeps_the_silhouette() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = puget(dir.path());
    compare_with_brute_force(&set, "flyover", 6, 1.0);
    compare_with_brute_force(&set, "orbit", 3, 1.0);
}

#[test]
fn srtm_grazing_flight_has_no_cracks() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = tileset(
        dir.path(),
        &data("srtm/N43E007.hgt"),
        dem::ReadOptions::default(),
    );
    compare_with_brute_force(&set, "flyover", 6, 1.0);
}

#[test]
fn broken_tile_sets_give_one_clear_line() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = puget(dir.path());
    let mut bytes = std::fs::read(&set).expect("read");
    let n = bytes.len();
    bytes[n / 2] ^= 0x5a;
    let bad = dir.path().join("corrupt.vkt");
    std::fs::write(&bad, &bytes).expect("write");
    let truncated = dir.path().join("truncated.vkt");
    std::fs::write(&truncated, &bytes[..n / 3]).expect("write");
    for (file, name) in [(&bad, "corrupt.vkt"), (&truncated, "truncated.vkt")] {
        let o = vkterrain(&[s(file), "--headless", "--frames", "2", "--size", "64x64"]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(err.contains(name) && !err.contains("panicked"), "{err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    }
}
