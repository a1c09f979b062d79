//! A short fuzz run of every target (fixed seed, a fixed number of inputs) as part of the test
//! command, and a control showing the runner does catch a reader that panics. The long runs
//! are `mutfuzz all --seconds 3600` (README).

use std::time::Duration;

use fuzz::{fuzz, Target, TARGETS};

fn run(target: &Target, inputs: u64, seed: u64) -> fuzz::Report {
    let work = tempfile::tempdir().expect("temp dir");
    let crashes = work.path().join("crashes");
    fuzz(
        target,
        Duration::from_secs(120),
        inputs,
        seed,
        &work.path().join("work"),
        &crashes,
    )
    .unwrap_or_else(|e| panic!("{}: {e}", target.name))
}

#[test]
fn every_target_survives_a_short_run() {
    for target in TARGETS {
        // The SRTM and GeoTIFF seeds are megabytes: fewer inputs.
        let inputs = match target.name {
            "hgt" | "tiff" | "part" => 300,
            "vkt" => 1500,
            _ => 3000,
        };
        let report = run(target, inputs, 0x5eed);
        assert_eq!(report.executions, inputs, "{}", target.name);
        assert!(
            report.failures.is_empty(),
            "{}: {:?}",
            target.name,
            report.failures
        );
    }
}

fn panics_on_a_bang(p: &std::path::Path) {
    let bytes = std::fs::read(p).expect("input");
    assert!(!bytes.contains(&b'!'), "a reader that panics on '!'");
}

/// The negative control: a reader that panics on some inputs is caught, and the input saved.
#[test]
fn the_runner_catches_a_panicking_reader() {
    let target = Target {
        name: "control",
        file: "input.csv",
        corpus: "path",
        shared: &[],
        reseal: None,
        run: panics_on_a_bang,
    };
    let report = run(&target, 3000, 1);
    assert!(!report.failures.is_empty(), "no panic found in 3000 inputs");
    assert!(report.failures.iter().all(|(why, _)| why == "panic"));
}
