//! `mutfuzz`: runs one fuzz target (or all, one after the other).
//!
//! ```text
//! mutfuzz TARGET|all [--seconds N] [--seed S]
//! ```
//!
//! Prints executions, executions per second, the slowest input and every failure (saved under
//! `fuzz/crashes/`); exits 1 if anything panicked or hung.

use std::process::ExitCode;
use std::time::Duration;

use fuzz::{fuzz, target, TARGETS};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let flag = |name: &str, default: u64| -> Result<u64, String> {
        match args.iter().position(|a| a == name) {
            None => Ok(default),
            Some(i) => args
                .get(i + 1)
                .and_then(|v| v.parse().ok())
                .ok_or_else(|| format!("{name} needs a number")),
        }
    };
    if args.first().map(String::as_str) == Some("--write-seeds") {
        return match fuzz::write_image_seeds() {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("mutfuzz: {e}");
                ExitCode::FAILURE
            }
        };
    }
    let names: Vec<&str> = match args.first().map(String::as_str) {
        Some("all") => TARGETS.iter().map(|t| t.name).collect(),
        Some(n) if !n.starts_with('-') => vec![n],
        _ => {
            let all: Vec<&str> = TARGETS.iter().map(|t| t.name).collect();
            eprintln!(
                "usage: mutfuzz TARGET|all [--seconds N] [--seed S]; targets: {}",
                all.join(", ")
            );
            return ExitCode::from(2);
        }
    };
    let (seconds, seed) = match (flag("--seconds", 60), flag("--seed", 1)) {
        (Ok(s), Ok(seed)) => (s, seed),
        (Err(e), _) | (_, Err(e)) => {
            eprintln!("mutfuzz: {e}");
            return ExitCode::from(2);
        }
    };
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let work = std::env::temp_dir().join(format!("mutfuzz-{}", std::process::id()));
    let mut failed = false;
    for name in names {
        let Some(t) = target(name) else {
            eprintln!("mutfuzz: no target {name:?}");
            return ExitCode::from(2);
        };
        match fuzz(
            t,
            Duration::from_secs(seconds),
            u64::MAX,
            seed,
            &work,
            &root.join("crashes"),
        ) {
            Ok(r) => {
                println!(
                    "{name}: {} inputs in {seconds} s ({:.0}/s), slowest {:.2} s, {} failures",
                    r.executions,
                    r.executions as f64 / seconds.max(1) as f64,
                    r.slowest.as_secs_f64(),
                    r.failures.len()
                );
                for (why, file) in &r.failures {
                    println!("  {why}: {}", file.display());
                }
                failed |= !r.failures.is_empty();
            }
            Err(e) => {
                eprintln!("mutfuzz: {name}: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    let _ = std::fs::remove_dir_all(&work);
    if failed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
