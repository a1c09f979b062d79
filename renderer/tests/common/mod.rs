//! Helpers shared by the renderer's integration tests: real data paths and tile sets built
//! from them.

#![allow(dead_code)] // each test file uses its own subset

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::{Arc, Mutex, OnceLock};

use tiles::{build_tileset, BuildParams, Grid, TileSetMeta};

// Each test file uses its own subset.
#[allow(unused_imports)]
pub use testdata::{data, sample};

/// Builds a tile set in `dir` from a DEM.
pub fn tileset(dir: &Path, input: &Path, opts: dem::ReadOptions) -> PathBuf {
    tileset_of(dir, &[input.to_path_buf()], opts)
}

/// Builds a tile set in `dir` from DEM files read together (an SRTM mosaic).
pub fn tileset_of(dir: &Path, inputs: &[PathBuf], opts: dem::ReadOptions) -> PathBuf {
    tileset_with(dir, inputs, opts, &BuildParams::default())
}

/// [`tileset_of`] with build parameters.
pub fn tileset_with(
    dir: &Path,
    inputs: &[PathBuf],
    opts: dem::ReadOptions,
    params: &BuildParams,
) -> PathBuf {
    let key = format!("{inputs:?} {opts:?} {params:?}");
    built_once(key, dir, "set.vkt", |out| {
        let grid = dem::read(inputs, &opts).unwrap_or_else(|e| panic!("{e}"));
        let view = grid_view(&grid);
        build_tileset(&view, params, &TileSetMeta::default(), out, &|| {}).expect("build");
    })
}

/// `dir/name`: a copy of the tile set `build` makes, built once per test process for each
/// `key` (what the set is built from). A build of the same input with the same options is the
/// same bytes (`tiletool`'s test `builds_are_reproducible_byte_for_byte`), and most tests fly
/// the Puget sample: a process built it up to 24 times. Each test gets a copy of its own, as
/// it did its own build: a test may damage its set, or cut it while it is flown.
pub fn built_once(key: String, dir: &Path, name: &str, build: impl FnOnce(&Path)) -> PathBuf {
    // Per key: its number (its folder) and the set once built.
    type Slots = HashMap<String, Arc<(usize, OnceLock<PathBuf>)>>;
    static BUILT: OnceLock<Mutex<Slots>> = OnceLock::new();
    let slot = {
        let mut built = BUILT
            .get_or_init(Default::default)
            .lock()
            .unwrap_or_else(|p| p.into_inner());
        let n = built.len();
        Arc::clone(
            built
                .entry(key)
                .or_insert_with(|| Arc::new((n, OnceLock::new()))),
        )
    };
    let cached = slot.1.get_or_init(|| {
        let dir = cache_dir().join(slot.0.to_string());
        std::fs::create_dir_all(&dir).expect("cache dir");
        let out = dir.join(name);
        build(&out);
        out
    });
    // Copied beside, then renamed over `name`, as a build writes: a set already there that a
    // test still has open keeps its bytes.
    let out = dir.join(name);
    let copy = dir.join(format!(".{name}.copy"));
    std::fs::copy(cached, &copy).unwrap_or_else(|e| panic!("{}: {e}", cached.display()));
    std::fs::rename(&copy, &out).unwrap_or_else(|e| panic!("{}: {e}", out.display()));
    out
}

/// This process's folder of built sets, under the target folder's scratch space (the sets of
/// test processes that have ended are removed first: a process cannot remove its own at exit).
fn cache_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let root = Path::new(env!("CARGO_TARGET_TMPDIR")).join("test-sets");
        for entry in std::fs::read_dir(&root).into_iter().flatten().flatten() {
            let pid = entry.file_name().to_string_lossy().parse::<u32>();
            if pid.is_ok_and(|pid| !Path::new(&format!("/proc/{pid}")).exists()) {
                let _ = std::fs::remove_dir_all(entry.path());
            }
        }
        let dir = root.join(std::process::id().to_string());
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("test-sets dir");
        dir
    })
}

/// The builder's view of a DEM read by `dem`.
pub fn grid_view(grid: &dem::HeightGrid) -> Grid<'_> {
    Grid {
        width: grid.width,
        height: grid.height,
        first_row: 0,
        heights: &grid.heights,
        spacing_x: grid.spacing_x,
        spacing_y: grid.spacing_y,
    }
}

/// GENERATED test data, not a real place: a `size` x `size` mirror tiling of the real SRTM3
/// tile N55W003, the same grid `bench/mirror.py` writes for the scale benchmarks (reflected at
/// every edge, voids and heights below 0 as 0, 90 m spacing), built with the default
/// parameters into `dir/mirror-SIZE.vkt`.
pub fn mirror(dir: &Path, size: usize) -> PathBuf {
    mirror_with(dir, size, &BuildParams::default())
}

/// Build options with the tile pyramid (`tiletool build --pyramid`).
pub fn with_pyramid() -> BuildParams {
    BuildParams {
        pyramid: true,
        ..BuildParams::default()
    }
}

/// The heights of [`mirror`]'s grid of `size` x `size` samples (metres, row-major, north
/// first): SRTM3 N55W003 mirrored at its edges, voids as 0.
pub fn mirror_heights(size: usize) -> Vec<f32> {
    let path = data("srtm/N55W003.hgt");
    let raw = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let side = ((raw.len() / 2) as f64).sqrt().round() as usize;
    assert_eq!(
        side * side * 2,
        raw.len(),
        "{}: not a square .hgt",
        path.display()
    );
    let source = |x: usize, y: usize| -> f32 {
        let at = 2 * (y * side + x);
        f32::from(i16::from_be_bytes([raw[at], raw[at + 1]]).max(0))
    };
    let mirrored = |i: usize| {
        let j = i % (2 * (side - 1));
        if j < side {
            j
        } else {
            2 * (side - 1) - j
        }
    };
    (0..size * size)
        .map(|i| source(mirrored(i % size), mirrored(i / size)))
        .collect()
}

/// [`mirror`] built with `params`.
pub fn mirror_with(dir: &Path, size: usize, params: &BuildParams) -> PathBuf {
    let heights = mirror_heights(size);
    let grid = Grid {
        width: size,
        height: size,
        first_row: 0,
        heights: &heights,
        spacing_x: 90.0,
        spacing_y: 90.0,
    };
    let out = dir.join(format!("mirror-{size}.vkt"));
    build_tileset(&grid, params, &TileSetMeta::default(), &out, &|| {}).expect("build");
    out
}

/// Opens a tile set and checks every tile, as a flight checks them when first needed
/// (`part` gives a tile's data only after its check); fails the test if any tile fails.
pub fn open_checked(set: &Path) -> renderer::terrain::Terrain {
    let terrain =
        renderer::terrain::Terrain::open(set).unwrap_or_else(|e| panic!("{}: {e}", set.display()));
    let all: Vec<usize> = (0..terrain.tiles.len()).collect();
    terrain.check_all(&all);
    assert_eq!(terrain.failed_count(), 0, "{:?}", terrain.take_failures());
    terrain
}

/// How the tests read the bundled Puget Sound sample.
pub fn puget_options() -> dem::ReadOptions {
    dem::ReadOptions {
        spacing: Some(160.0),
        vertical_scale: Some(0.1),
        ..Default::default()
    }
}

/// The 4K Puget Sound heights (`puget/ps_height_4k_8bit.jpg` of the shared data) and how the
/// tests read them: 40 m a sample, the 8-bit codes scaled to metres.
pub fn puget_4k() -> (PathBuf, dem::ReadOptions) {
    let options = dem::ReadOptions {
        spacing: Some(40.0),
        vertical_scale: Some(25.7),
        ..Default::default()
    };
    (data("puget/ps_height_4k_8bit.jpg"), options)
}

pub fn puget(dir: &Path) -> PathBuf {
    tileset(dir, &sample(), puget_options())
}

/// The Puget sample with texture tiles: its photo (`sample/ps_texture_1k.png`, one texel per
/// cell) or, with `photo` false, the shaded relief tiletool bakes (two texels per cell).
pub fn puget_textured(dir: &Path, photo: bool) -> PathBuf {
    built_once(
        format!("puget textured, photo {photo}"),
        dir,
        "textured.vkt",
        |out| build_textured(out, photo),
    )
}

fn build_textured(out: &Path, photo: bool) {
    use tiles::texture::{interior_for, relief::Relief, Layout, Photo, Source, Texturing};
    let grid = dem::read(&[sample()], &puget_options()).unwrap_or_else(|e| panic!("{e}"));
    let view = grid_view(&grid);
    let (source, density) = if photo {
        let path = testdata::sample_texture();
        let rgb = image::open(&path)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
            .to_rgb8();
        let (width, height) = (rgb.width() as usize, rgb.height() as usize);
        let photo = Photo::spanning(width, height, rgb.into_raw(), &view);
        let density = photo.pixels_per_cell();
        (Source::Photo(photo), density)
    } else {
        let relief = Relief {
            azimuth_deg: 315.0,
            elevation_deg: 45.0,
            tint: false,
        };
        (Source::Relief(relief), 2.0)
    };
    let texturing = Texturing {
        source,
        layout: Layout::new(interior_for(density)).expect("layout"),
    };
    tiles::build_tileset_textured(
        &view,
        &BuildParams::default(),
        Some(&texturing),
        &TileSetMeta::default(),
        out,
        &|| {},
    )
    .expect("build");
}

/// The Puget sample built with its tiles' sides independent (no agreement between neighbours).
pub fn puget_independent(dir: &Path) -> PathBuf {
    let params = BuildParams {
        shared_sides: false,
        ..BuildParams::default()
    };
    tileset_with(dir, &[sample()], puget_options(), &params)
}

pub const SKY: [u8; 3] = [255, 0, 255];

pub fn vkterrain(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vkterrain"))
        .args(args)
        .output()
        .expect("vkterrain runs")
}

/// Runs vkterrain with one environment variable set (a fault to inject).
pub fn vkterrain_with_env(args: &[&str], (key, value): (&str, &str)) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vkterrain"))
        .args(args)
        .env(key, value)
        .output()
        .expect("vkterrain runs")
}

/// Runs vkterrain, which must succeed with no validation message, and returns its summary.
pub fn summary(args: &[&str]) -> serde_json::Value {
    let o = vkterrain(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(!err.contains("validation"), "validation messages: {err}");
    serde_json::from_slice(&o.stdout).expect("summary")
}

pub fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// Runs a headless flight with validation and a magenta sky; returns the screenshots' pixels.
pub fn flight(
    set: &Path,
    out: &Path,
    path: &str,
    frames: u32,
    extra: &[&str],
) -> Vec<image::RgbaImage> {
    flight_with_fault(set, out, path, frames, extra, None)
}

/// [`flight`] with a fault injected (`VKTERRAIN_FAULT`, see `renderer::fault::Fault`).
pub fn flight_with_fault(
    set: &Path,
    out: &Path,
    path: &str,
    frames: u32,
    extra: &[&str],
    fault: Option<&str>,
) -> Vec<image::RgbaImage> {
    flight_exiting(set, out, path, frames, extra, fault, 0)
}

/// [`flight_with_fault`], the flight ending with exit code `code` (4: a tile failed its
/// check).
pub fn flight_exiting(
    set: &Path,
    out: &Path,
    path: &str,
    frames: u32,
    extra: &[&str],
    fault: Option<&str>,
    code: i32,
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
    let mut command = Command::new(env!("CARGO_BIN_EXE_vkterrain"));
    if let Some(f) = fault {
        command.env("VKTERRAIN_FAULT", f);
    }
    let o = command.args(&args).output().expect("vkterrain runs");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(
        o.status.code(),
        Some(code),
        "vkterrain exited {:?}: {err}",
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

/// Column `name` of the frame log at `path`, one value per frame, read by the reader
/// `frametimes` uses. Panics when the log does not read, the reader dropped a row, the column
/// is missing, or a cell is empty (every column a test reads is written on every frame).
pub fn log_column(path: &Path, name: &str) -> Vec<f64> {
    let log = frametimes::log::read(path).unwrap_or_else(|e| panic!("{e}"));
    assert!(log.notes.is_empty(), "{}: {:?}", path.display(), log.notes);
    let values = log
        .column(name)
        .unwrap_or_else(|| panic!("{}: no column {name}", path.display()));
    if let Some(k) = values.iter().position(|v| v.is_nan()) {
        panic!("{}: frame {k} has no {name}", path.display());
    }
    values.to_vec()
}

pub fn is_sky(p: &image::Rgba<u8>) -> bool {
    p.0[0] == SKY[0] && p.0[1] == SKY[1] && p.0[2] == SKY[2]
}

/// The fans of an index array (`width` 2 or 4 bytes): (centre, ring without its closing vertex, rotated to start at
/// its smallest index), in order. Panics on a fan that is not closed.
pub fn fans(bytes: &[u8], width: u32) -> Vec<(u32, Vec<u32>)> {
    let indices = widen(bytes, width);
    indices
        .split(|&i| i == u32::MAX)
        .map(|fan| {
            let (&centre, ring) = fan.split_first().expect("a fan has a centre");
            assert!(
                ring.len() >= 5 && ring.first() == ring.last(),
                "fan {fan:?} is not closed"
            );
            let mut ring = ring[..ring.len() - 1].to_vec();
            let start = (0..ring.len()).min_by_key(|&k| ring[k]).expect("ring");
            ring.rotate_left(start);
            (centre, ring)
        })
        .collect()
}

/// An index array's bytes (`width` 2 or 4) as u32, restarts as `u32::MAX`.
pub fn widen(bytes: &[u8], width: u32) -> Vec<u32> {
    match width {
        2 => bytes
            .chunks_exact(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]))
            .map(|i| {
                if i == u16::MAX {
                    u32::MAX
                } else {
                    u32::from(i)
                }
            })
            .collect(),
        _ => bytes
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect(),
    }
}

/// The control flight of a test that breaks tile 1,2 (index 9) at `level`: four traced
/// frames over the sound `set` exit 0 and draw every visible tile, and ask for tile 1,2 in
/// the first view coarser than `level`. Returns the flight and the first frame that asks for
/// the tile at `level` or finer.
pub fn sound_flight(dir: &Path, set: &Path, level: u32) -> (Traced, usize) {
    let (o, [visible, drawn, failed], asked) = four_traced_frames(dir, set, "control", 9);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{err}");
    assert_eq!(visible, drawn, "the control draws every visible tile");
    assert!(
        asked[0].is_some_and(|l| l < level),
        "tile 1,2 is in the first view, coarser than level {level}: {asked:?}"
    );
    let finer = asked
        .iter()
        .position(|a| a.is_some_and(|l| l >= level))
        .unwrap_or_else(|| panic!("a frame wants tile 1,2 at level {level} or finer"));
    ((o, [visible, drawn, failed], asked), finer)
}

/// What [`four_traced_frames`] reads back: the process, the log's `tiles_visible`,
/// `tiles_drawn` and `tiles_failed` per frame, and per frame the level one tile was asked for
/// at (None: not asked for).
pub type Traced = (Output, [Vec<f64>; 3], Vec<Option<u32>>);

/// Four frames over `set` at 256 x 192, validation on, logged and traced into `dir` under
/// `name`: for the tests that follow one tile (`tile`, its index in the set) through a flight.
pub fn four_traced_frames(dir: &Path, set: &Path, name: &str, tile: u32) -> Traced {
    let log = dir.join(format!("{name}.csv"));
    let trace = dir.join(format!("{name}.trace"));
    let o = vkterrain(&[
        s(set),
        "--headless",
        "--frames",
        "4",
        "--size",
        "256x192",
        "--validation",
        "--log",
        s(&log),
        "--trace",
        s(&trace),
    ]);
    let parsed = frametimes::log::read(&log).expect("the log reads");
    let column = |c: &str| parsed.column(c).expect(c).to_vec();
    let trace = std::fs::read_to_string(&trace).expect("trace");
    let trace = memory::trace::Trace::parse(&trace).expect("trace parses");
    let asked = trace
        .frames
        .iter()
        .map(|f| f.iter().find(|r| r.tile == tile).map(|r| r.wanted))
        .collect();
    let columns = ["tiles_visible", "tiles_drawn", "tiles_failed"].map(column);
    (o, columns, asked)
}
