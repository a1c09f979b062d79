//! What the tiletool tests share: running the binary and reading what it says.

use std::path::{Path, PathBuf};

use std::process::{Command, Output};
use testdata::sample;

pub fn tiletool(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tiletool"))
        .args(args)
        .output()
        .expect("tiletool runs")
}

pub fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Builds the sample into `dir/name` with `extra` flags; returns the file and `info --json`.
#[allow(dead_code)] // each test file compiles this module; not all of them build the sample
pub fn build_sample(dir: &Path, name: &str, extra: &[&str]) -> (PathBuf, serde_json::Value) {
    let out = dir.join(name);
    let src = sample();
    let mut args = vec![
        "build",
        s(&src),
        "-o",
        s(&out),
        "--spacing",
        "160",
        "--vertical-scale",
        "0.1",
        "--quiet",
    ];
    args.extend(extra);
    let o = tiletool(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = tiletool(&["info", s(&out), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    (out, serde_json::from_slice(&o.stdout).expect("json"))
}
