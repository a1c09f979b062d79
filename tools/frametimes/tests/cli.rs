//! `frametimes` on real logs written by `vkterrain` (Puget sample, orbit path, 512 x 384 on
//! lavapipe: tau 1, tau 4 and brute force; `short.csv` is the first five frames of the tau 1
//! log; `interrupted.csv` the tau 4 log cut mid-line).

use std::path::PathBuf;
use std::process::{Command, Output};

fn log(name: &str) -> PathBuf {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/logs")).join(name);
    assert!(p.exists(), "test log missing: {}", p.display());
    p
}

fn frametimes(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_frametimes"))
        .args(args)
        .output()
        .expect("frametimes runs")
}

fn s(p: &std::path::Path) -> &str {
    p.to_str().expect("utf-8 path")
}

fn json(o: &Output) -> serde_json::Value {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).expect("json")
}

fn close(v: &serde_json::Value, want: f64) {
    let got = v.as_f64().unwrap_or(f64::NAN);
    assert!(
        (got - want).abs() <= 1e-6 * want.abs().max(1.0),
        "got {got}, want {want}"
    );
}

#[test]
fn summary_matches_hand_computed_figures() {
    // frame_ms = 182.8516, 40.1660, 32.4594, 26.4355, 29.6984.
    // Sorted: 26.4355 29.6984 32.4594 40.1660 182.8516. Mean 311.6109 / 5 = 62.32218.
    // p95 sits at 0.95 * 4 = 3.8: 40.1660 + 0.8 * (182.8516 - 40.1660) = 154.31448.
    // p99 at 3.96: 40.1660 + 0.96 * 142.6856 = 177.144176.
    // Jank at 1000/60 ms: 166.18493 + 23.49933 + 15.79273 + 9.76883 + 13.03173 = 228.27757.
    let o = frametimes(&["summary", s(&log("short.csv")), "--json"]);
    let v = json(&o);
    assert_eq!(v["frames"], 5);
    close(&v["mean_ms"], 62.32218);
    close(&v["median_ms"], 32.4594);
    close(&v["p95_ms"], 154.31448);
    close(&v["p99_ms"], 177.144176);
    close(&v["max_ms"], 182.8516);
    close(&v["jank_ms"], 228.277_566_666_7);
    assert_eq!(v["frames_over_budget"], 5);
    close(&v["duration_s"], 0.3116109);
    // With a 35 ms budget only two frames are over: 5.166 + 147.8516.
    let v = json(&frametimes(&[
        "summary",
        s(&log("short.csv")),
        "--json",
        "--budget-ms",
        "35",
    ]));
    assert_eq!(v["frames_over_budget"], 2);
    close(&v["jank_ms"], 153.0176);
    // The text table says the same.
    let o = frametimes(&["summary", s(&log("short.csv"))]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("32.459") && text.contains("154.314"),
        "{text}"
    );
}

#[test]
fn compare_says_what_is_beyond_noise_and_plots() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (png, svg) = (dir.path().join("cmp.png"), dir.path().join("cmp.svg"));
    let (a, b, c) = (
        log("orbit_tau1.csv"),
        log("orbit_tau4.csv"),
        log("orbit_brute.csv"),
    );
    let o = frametimes(&["compare", s(&a), s(&b), s(&c), "--plot", s(&png)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("orbit_tau4.csv vs orbit_tau1.csv") && text.contains("faster, beyond noise"),
        "{text}"
    );
    assert!(
        text.contains("orbit_brute.csv vs orbit_tau1.csv") && text.contains("slower, beyond noise"),
        "{text}"
    );
    let bytes = std::fs::read(&png).expect("png");
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    assert!(
        bytes.len() > 20_000,
        "a plot, not an empty image ({} bytes)",
        bytes.len()
    );
    let o = frametimes(&["compare", s(&a), s(&b), "--plot", s(&svg)]);
    assert!(o.status.success());
    let svg_text = std::fs::read_to_string(&svg).expect("svg");
    assert!(
        svg_text.contains("<svg")
            && svg_text.contains("orbit_tau4.csv")
            && svg_text.contains("frame time (ms)")
    );
    // A log against itself: no difference.
    let v = json(&frametimes(&["compare", s(&a), s(&a), "--json"]));
    assert_eq!(v["comparisons"][0]["beyond_noise"], false);
    close(&v["comparisons"][0]["median_ratio"], 1.0);
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .expect("dir")
        .map(|e| e.expect("entry").file_name())
        .collect();
    assert_eq!(leftovers.len(), 2, "{leftovers:?}");
}

#[test]
fn fail_if_slower_gates_both_ways() {
    let (fast, slow) = (log("orbit_tau1.csv"), log("orbit_brute.csv"));
    // The brute-force run is ~10x slower: a regression.
    let o = frametimes(&["compare", s(&fast), s(&slow), "--fail-if-slower", "10"]);
    assert_eq!(
        o.status.code(),
        Some(3),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("slower than orbit_tau1.csv by more than 10%")
    );
    // The other way round it is an improvement: no failure.
    let o = frametimes(&["compare", s(&slow), s(&fast), "--fail-if-slower", "10"]);
    assert_eq!(o.status.code(), Some(0));
    // Same run: within noise, passes even with a 0% threshold.
    let o = frametimes(&["compare", s(&fast), s(&fast), "--fail-if-slower", "0"]);
    assert_eq!(o.status.code(), Some(0));
    // tau 4 is faster than tau 1, so tau 1 against tau 4 is slower by far more than 20%.
    let o = frametimes(&[
        "compare",
        s(&log("orbit_tau4.csv")),
        s(&fast),
        "--fail-if-slower",
        "20",
    ]);
    assert_eq!(o.status.code(), Some(3));
}

#[test]
fn odd_logs_get_notes_and_other_files_an_error() {
    let dir = tempfile::tempdir().expect("temp dir");
    // Interrupted mid-line, and a different frame count from the full log.
    let o = frametimes(&[
        "compare",
        s(&log("orbit_tau4.csv")),
        s(&log("interrupted.csv")),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("interrupted.csv") && err.contains("incomplete"),
        "{err}"
    );
    assert!(err.contains("different frame counts"), "{err}");
    // Missing columns: only frame and frame_ms.
    let minimal = dir.path().join("minimal.csv");
    std::fs::write(&minimal, "frame,frame_ms\n0,10\n1,12\n2,11\n").expect("write");
    let v = json(&frametimes(&["summary", s(&minimal), "--json"]));
    close(&v["median_ms"], 11.0);
    assert!(v["mtri_per_s"].is_null());
    // Not a log at all.
    let other = dir.path().join("other.csv");
    std::fs::write(&other, "time_s,x_m,y_m\n0,1,2\n").expect("write");
    let o = frametimes(&["summary", s(&other)]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        err.contains("other.csv")
            && err.contains("not a vkterrain frame log")
            && !err.contains("panicked"),
        "{err}"
    );
    let o = frametimes(&["summary", s(&dir.path().join("missing.csv"))]);
    assert_eq!(o.status.code(), Some(1));
    let o = frametimes(&[
        "compare",
        s(&minimal),
        s(&minimal),
        "--plot",
        s(&dir.path().join("x.gif")),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains(".png or .svg"));
}

/// Exit codes of the README's table (3, a regression, is checked above): 0, 1 for a file
/// that is no log (a FIFO, /dev/zero, negative frame times only), 2 for usage.
#[test]
fn exit_codes_follow_the_table() {
    let dir = tempfile::tempdir().expect("temp dir");
    assert_eq!(
        frametimes(&["summary", s(&log("short.csv"))]).status.code(),
        Some(0)
    );
    assert_eq!(
        frametimes(&["summary", "--no-such-flag"]).status.code(),
        Some(2)
    );
    assert_eq!(frametimes(&["summary", "/dev/zero"]).status.code(), Some(1));
    let fifo = dir.path().join("pipe.csv");
    let made = Command::new("mkfifo").arg(&fifo).status().expect("mkfifo");
    assert!(made.success());
    let o = frametimes(&["summary", s(&fifo)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("not a regular file"));
    let negative = dir.path().join("negative.csv");
    std::fs::write(&negative, "frame,frame_ms\n0,-5\n1,-1\n").expect("write");
    assert_eq!(
        frametimes(&["summary", s(&negative)]).status.code(),
        Some(1)
    );
}
