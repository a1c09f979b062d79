//! Window mode under Xvfb with validation on: opens, draws frames, resizes, closes cleanly,
//! writes its log and the path flown.

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

mod common;

use common::puget;

/// An X server for one test. Tests take turns (the guard): two picking the same free display
/// number at once would share, and then kill, one server.
struct Xvfb(Child, String, #[allow(dead_code)] MutexGuard<'static, ()>);

static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
        // Killed, Xvfb leaves its lock and socket behind: remove them, or the display numbers
        // run out over many test runs.
        let n = self.1.trim_start_matches(':');
        let _ = std::fs::remove_file(format!("/tmp/.X{n}-lock"));
        let _ = std::fs::remove_file(format!("/tmp/.X11-unix/X{n}"));
    }
}

/// Whether display `n` is taken: its lock names a live process (a lock left by a killed server
/// is stale, and Xvfb replaces it).
fn display_taken(n: u32) -> bool {
    let Ok(lock) = std::fs::read_to_string(format!("/tmp/.X{n}-lock")) else {
        return Path::new(&format!("/tmp/.X11-unix/X{n}")).exists();
    };
    lock.trim()
        .parse::<u32>()
        .map_or(true, |pid| Path::new(&format!("/proc/{pid}")).exists())
}

/// Starts Xvfb on the first free display from :91 and waits for its socket.
fn xvfb() -> Xvfb {
    let turn = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    for n in 91..120 {
        if display_taken(n) {
            continue;
        }
        // A stale socket would pass for the new server's.
        let _ = std::fs::remove_file(format!("/tmp/.X11-unix/X{n}"));
        let display = format!(":{n}");
        let server = Xvfb(
            Command::new("Xvfb")
                .args([&display, "-screen", "0", "1280x1024x24", "-nolisten", "tcp"])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .unwrap_or_else(|e| {
                    panic!("cannot start Xvfb ({e}): install it (Debian: xvfb), .ci/setup does")
                }),
            display.clone(),
            turn,
        );
        let started = Instant::now();
        while started.elapsed() < Duration::from_secs(10) {
            if Path::new(&format!("/tmp/.X11-unix/X{n}")).exists() {
                return server;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        panic!("Xvfb {display} did not come up");
    }
    panic!("no free X display number");
}

#[test]
fn window_opens_draws_resizes_and_closes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = puget(dir.path());

    let x = xvfb();
    let (log, record) = (dir.path().join("win.csv"), dir.path().join("flown.csv"));
    let o = Command::new(env!("CARGO_BIN_EXE_vkterrain"))
        .args([
            set.to_str().expect("utf-8"),
            "--window",
            "--validation",
            "--frames",
            "24",
            "--size",
            "640x480",
        ])
        .args([
            "--resize-at",
            "8=400x300",
            "--log",
            log.to_str().expect("utf-8"),
            "--record",
            record.to_str().expect("utf-8"),
        ])
        .env("DISPLAY", &x.1)
        .output()
        .expect("vkterrain runs");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "exit {:?}: {err}", o.status.code());
    assert!(!err.contains("validation"), "{err}");
    assert!(
        err.contains("swapchain 400x300"),
        "the window was not resized: {err}"
    );
    let rows = std::fs::read_to_string(&log).expect("log").lines().count();
    assert_eq!(rows, 25, "header + 24 frames");
    assert!(std::fs::read_to_string(&record)
        .expect("path")
        .starts_with("time_s,"));
}

/// A resize storm: a new size asked on twelve consecutive frames (tiny, large, back and
/// forth), so swapchains go out of date while frames are in flight. The flight completes
/// with zero validation messages and every frame logged.
#[test]
fn window_survives_a_resize_storm() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = puget(dir.path());
    let x = xvfb();
    let log = dir.path().join("storm.csv");
    let sizes = [
        "300x200", "16x16", "900x700", "64x48", "640x480", "16x300", "1200x900", "320x240",
        "17x23", "800x600", "400x400", "640x480",
    ];
    let storm: Vec<String> = sizes
        .iter()
        .enumerate()
        .map(|(k, s)| format!("{}={s}", 4 + k))
        .collect();
    let o = Command::new(env!("CARGO_BIN_EXE_vkterrain"))
        .args([
            set.to_str().expect("utf-8"),
            "--window",
            "--validation",
            "--frames",
            "30",
            "--size",
            "640x480",
            "--log",
            log.to_str().expect("utf-8"),
            "--resize-at",
        ])
        .args(&storm)
        .env("DISPLAY", &x.1)
        .output()
        .expect("vkterrain runs");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "exit {:?}: {err}", o.status.code());
    assert!(!err.contains("validation"), "{err}");
    assert!(
        err.matches("swapchain").count() >= 3,
        "few resizes seen: {err}"
    );
    let rows = std::fs::read_to_string(&log).expect("log").lines().count();
    assert_eq!(rows, 31, "header + 30 frames");
}
