//! Structured mutation fuzzing of every reader of untrusted input: the `.vkt` reader with its
//! per-tile validation (and the renderer's open), each DEM decoder, the camera-path parser, the
//! frame-log reader and the merge of a distributed build's part files.
//!
//! Each target starts from seed files (`fuzz/corpus/<target>/`, plus real data from
//! `../shared/data` where a seed would be too large to keep), mutates them with a fixed-seed
//! generator (bit flips, random and boundary bytes, boundary 32-bit integers and floats at
//! aligned offsets, truncation, deletion, duplication, splicing two inputs) and runs the reader
//! on the result. A reader may refuse any input; it may not panic, and an input that takes
//! over [`SLOW`] is reported as a hang. Tile sets and part files are resealed (checksums
//! recomputed) half of the time, so that the semantic checks, not only the checksums, meet the
//! mutations.
//!
//! `mutfuzz TARGET --seconds N [--seed S]` runs one target; failing inputs are saved under
//! `fuzz/crashes/`. A short run of every target is part of the tests (`fuzz/tests/short.rs`).

use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use splitmix::Rng;

/// An input taking longer than this is reported as a hang.
pub const SLOW: Duration = Duration::from_secs(10);

/// A fuzz target: a name, where its seeds are, and how an input is written and read.
#[derive(Clone, Copy, Debug)]
pub struct Target {
    pub name: &'static str,
    /// File name the input is written under (the extension selects the decoder).
    pub file: &'static str,
    /// Seeds: files in the corpus folder of this name, and files from `../shared/data`.
    pub corpus: &'static str,
    pub shared: &'static [&'static str],
    /// Recomputes the input's checksums (on half of the mutations).
    pub reseal: Option<fn(&mut [u8])>,
    pub run: fn(&Path),
}

pub const TARGETS: &[Target] = &[
    Target {
        name: "vkt",
        file: "input.vkt",
        corpus: "vkt",
        shared: &[],
        reseal: Some(reseal_vkt),
        run: run_vkt,
    },
    Target {
        name: "hgt",
        file: "N43E007.hgt",
        corpus: "hgt",
        shared: &["srtm/N55W003.hgt"],
        reseal: None,
        run: run_dem,
    },
    Target {
        name: "tiff",
        file: "input.tif",
        corpus: "tiff",
        shared: &["geotiff/bigtujunga.tif"],
        reseal: None,
        run: run_dem,
    },
    Target {
        name: "png",
        file: "input.png",
        corpus: "png",
        shared: &[],
        reseal: None,
        run: run_dem_spaced,
    },
    Target {
        name: "terrain-rgb",
        file: "14-2625-6369.png",
        corpus: "terrain-rgb",
        shared: &[],
        reseal: None,
        run: run_terrain_rgb,
    },
    Target {
        name: "jpeg",
        file: "input.jpg",
        corpus: "jpeg",
        shared: &[],
        reseal: None,
        run: run_dem_spaced,
    },
    Target {
        name: "raw",
        file: "input.r16",
        corpus: "raw",
        shared: &[],
        reseal: None,
        run: run_raw,
    },
    Target {
        name: "path",
        file: "path.csv",
        corpus: "path",
        shared: &[],
        reseal: None,
        run: run_path,
    },
    Target {
        name: "log",
        file: "frames.csv",
        corpus: "log",
        shared: &[],
        reseal: None,
        run: run_log,
    },
    Target {
        name: "part",
        file: "input.part",
        corpus: "part",
        shared: &[],
        reseal: Some(reseal_part),
        run: run_part,
    },
];

fn reseal_vkt(bytes: &mut [u8]) {
    let _ = tiles::format::reseal(bytes);
}

fn reseal_part(bytes: &mut [u8]) {
    let _ = tiles::shard::reseal_part(bytes);
}

fn run_vkt(p: &Path) {
    if let Ok(file) = tiles::TileSet::open(p) {
        // The base grid's tiles, then each pyramid layer's, each layer read as a tile set.
        for layer in (0..=file.pyramid_layers().min(32)).filter_map(|l| file.layer(l)) {
            let h = *layer.header();
            for ty in 0..h.tiles_y.min(64) {
                for tx in 0..h.tiles_x.min(64) {
                    let _ = layer.decimation_error(tx, ty);
                    if let Ok(tile) = layer.tile(tx, ty) {
                        let _ = tiles::verify::tile_problems(&layer, &tile);
                        let _ = tile.vertices();
                    }
                    if let Ok(Some(texture)) = layer.texture(tx, ty) {
                        for (e, blocks) in &texture.mips {
                            let _ = tiles::texture::decode_bc1(
                                blocks,
                                e.width as usize,
                                e.height as usize,
                            );
                        }
                    }
                }
            }
        }
    }
    // The renderer's own open (outlines, boxes, level tables) and each tile's check when first
    // needed (borders, texture mips), and the coarse height maps, GPU-free.
    if let Ok(terrain) = scene::terrain::Terrain::open(p) {
        let tiles: Vec<usize> = (0..terrain.tiles.len().min(64 * 64)).collect();
        terrain.check_all(&tiles);
        let _ = terrain.take_failures();
        let (lo, hi) = terrain.bounds();
        let _ = terrain.max_height_near(0.5 * (lo.x + hi.x), 0.5 * (lo.y + hi.y), 1e4);
    }
}

/// A one-shard part merged alone (the seeds are `--shard 0/1` parts, whose merge needs no input):
/// the merge refuses it or writes a set, and a refusal leaves nothing behind, neither the set
/// nor its temporary file. A set it writes is opened and verified as a user would next.
fn run_part(p: &Path) {
    let out = p.with_file_name("merged.vkt");
    let _ = std::fs::remove_file(&out);
    let inputs = |_: &str| -> Result<_, tiles::BuildError> {
        Err(tiles::BuildError::Input(
            "no input is read while fuzzing".into(),
        ))
    };
    match tiles::shard::merge(&[p.to_path_buf()], &out, &inputs, &|| {}) {
        Ok(_) => {
            if let Ok(set) = tiles::TileSet::open(&out) {
                let _ = tiles::verify::verify(&set, None);
            }
        }
        Err(_) => {
            let tmp = tiles::format::temp_path(&out).expect("a file name");
            assert!(
                !out.exists() && !tmp.exists(),
                "a refused merge left a file behind"
            );
        }
    }
}

fn run_dem(p: &Path) {
    let _ = dem::read(&[p.to_path_buf()], &dem::ReadOptions::default());
}

fn run_dem_spaced(p: &Path) {
    let opts = dem::ReadOptions {
        spacing: Some(30.0),
        ..Default::default()
    };
    let _ = dem::read(&[p.to_path_buf()], &opts);
}

fn run_terrain_rgb(p: &Path) {
    let opts = dem::ReadOptions {
        encoding: Some(dem::Encoding::TerrainRgb),
        ..Default::default()
    };
    let _ = dem::read(&[p.to_path_buf()], &opts);
}

fn run_raw(p: &Path) {
    let opts = dem::ReadOptions {
        spacing: Some(10.0),
        size: Some((16, 16)),
        ..Default::default()
    };
    let _ = dem::read(&[p.to_path_buf()], &opts);
}

fn run_path(p: &Path) {
    if let Ok(text) = std::fs::read_to_string(p) {
        if let Ok(path) = scene::path::CameraPath::parse(&text) {
            let d = path.duration();
            for k in 0..8 {
                let _ = path.at(path.keys[0].time + d * f64::from(k) / 7.0);
            }
            let _ = path.to_csv();
        }
    }
}

fn run_log(p: &Path) {
    if let Ok(log) = frametimes::log::read(p) {
        let _ = frametimes::compare::compare(&log, &log);
    }
}

const INTERESTING_U32: &[u32] = &[
    0,
    1,
    2,
    3,
    4,
    7,
    8,
    255,
    256,
    257,
    511,
    512,
    65_535,
    65_536,
    0x7fff_ffff,
    0x8000_0000,
    0xffff_fffe,
    0xffff_ffff,
];

const INTERESTING_F32: &[f32] = &[
    0.0,
    -0.0,
    -1.0,
    1e-30,
    1e30,
    3.0e38,
    -3.4e38,
    f32::NAN,
    f32::INFINITY,
    f32::NEG_INFINITY,
    f32::MIN_POSITIVE,
];

/// One mutation of `input` (with `other` for splicing).
pub fn mutate(input: &[u8], other: &[u8], rng: &mut Rng) -> Vec<u8> {
    let mut b = input.to_vec();
    let rounds = 1 + rng.below(4);
    for _ in 0..rounds {
        let n = b.len();
        match rng.below(9) {
            0 if n > 0 => {
                let i = rng.below(n);
                b[i] ^= 1 << rng.below(8);
            }
            1 if n > 0 => {
                let i = rng.below(n);
                b[i] = rng.next_u64() as u8;
            }
            2 if n > 0 => {
                let i = rng.below(n);
                b[i] = [0u8, 0x7f, 0x80, 0xff, b',', b'\n', b'-', b'.'][rng.below(8)];
            }
            3 if n >= 4 => {
                let i = rng.below(n / 4) * 4;
                let v = INTERESTING_U32[rng.below(INTERESTING_U32.len())];
                b[i..i + 4].copy_from_slice(&v.to_le_bytes());
            }
            4 if n >= 4 => {
                let i = rng.below(n / 4) * 4;
                let v = INTERESTING_F32[rng.below(INTERESTING_F32.len())];
                b[i..i + 4].copy_from_slice(&v.to_le_bytes());
            }
            5 if n > 0 => b.truncate(rng.below(n)),
            6 if n > 1 => {
                let a = rng.below(n);
                let len = rng.below((n - a).min(4096)) + 1;
                b.drain(a..a + len);
            }
            7 if n > 1 => {
                let a = rng.below(n);
                let len = (rng.below((n - a).min(4096)) + 1).min(1 << 16);
                let copy = b[a..a + len].to_vec();
                let at = rng.below(n);
                b.splice(at..at, copy);
            }
            8 if !other.is_empty() => {
                let cut = rng.below(b.len().max(1));
                let from = rng.below(other.len());
                b.truncate(cut);
                b.extend_from_slice(&other[from..]);
            }
            _ => {}
        }
    }
    b
}

/// The seeds of `target`: its corpus folder, then its files from the shared data.
pub fn seeds(target: &Target) -> Result<Vec<Vec<u8>>, String> {
    let corpus = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("corpus")
        .join(target.corpus);
    let mut out = Vec::new();
    if let Ok(entries) = std::fs::read_dir(&corpus) {
        let mut files: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
        files.sort();
        for f in files {
            out.push(std::fs::read(&f).map_err(|e| format!("{}: {e}", f.display()))?);
        }
    }
    for rel in target.shared {
        let p = testdata::try_data(rel)?;
        out.push(std::fs::read(&p).map_err(|e| format!("{}: {e}", p.display()))?);
    }
    if out.is_empty() {
        return Err(format!("{}: no seeds", corpus.display()));
    }
    Ok(out)
}

/// What a run found.
#[derive(Debug, Default)]
pub struct Report {
    pub executions: u64,
    /// Inputs that panicked or hung: (why, saved file).
    pub failures: Vec<(String, PathBuf)>,
    pub slowest: Duration,
}

/// Runs `target` for `duration` (or `max_runs` inputs) from the fixed `seed`, in `work` (a
/// scratch folder); failing inputs are copied into `crashes`.
pub fn fuzz(
    target: &Target,
    duration: Duration,
    max_runs: u64,
    seed: u64,
    work: &Path,
    crashes: &Path,
) -> Result<Report, String> {
    let seeds = seeds(target)?;
    std::fs::create_dir_all(work).map_err(|e| format!("{}: {e}", work.display()))?;
    let input = work.join(target.file);
    let mut rng = Rng(seed);
    let mut report = Report::default();
    let start = Instant::now();
    // Quiet panics while fuzzing: they are caught and reported here.
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    while start.elapsed() < duration && report.executions < max_runs {
        let a = &seeds[rng.below(seeds.len())];
        let b = &seeds[rng.below(seeds.len())];
        // Now and then the seed itself, so the reader's accepting path runs too.
        let mut bytes = if rng.below(16) == 0 {
            a.clone()
        } else {
            mutate(a, b, &mut rng)
        };
        if let Some(reseal) = target.reseal.filter(|_| rng.below(2) == 0) {
            reseal(&mut bytes);
        }
        std::fs::write(&input, &bytes).map_err(|e| format!("{}: {e}", input.display()))?;
        let t = Instant::now();
        let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| (target.run)(&input)));
        let took = t.elapsed();
        report.slowest = report.slowest.max(took);
        report.executions += 1;
        let why = match (outcome, took > SLOW) {
            (Err(_), _) => Some("panic"),
            (Ok(()), true) => Some("hang"),
            _ => None,
        };
        if let Some(why) = why {
            std::fs::create_dir_all(crashes).map_err(|e| format!("{}: {e}", crashes.display()))?;
            let saved = crashes.join(format!(
                "{}-{}-{}-{}",
                target.name, why, seed, report.executions
            ));
            std::fs::write(&saved, &bytes).map_err(|e| format!("{}: {e}", saved.display()))?;
            report.failures.push((why.to_string(), saved));
        }
    }
    std::panic::set_hook(hook);
    Ok(report)
}

pub fn target(name: &str) -> Option<&'static Target> {
    TARGETS.iter().find(|t| t.name == name)
}

/// Writes the small image seeds (`mutfuzz --write-seeds`): crops of the shared data, small
/// enough to decode thousands of times a minute.
pub fn write_image_seeds() -> Result<(), String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let open = |rel: &str| image::open(testdata::try_data(rel)?).map_err(|e| format!("{rel}: {e}"));
    let save = |img: image::DynamicImage, folder: &str, name: &str| -> Result<(), String> {
        let dir = root.join("corpus").join(folder);
        std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
        img.save(dir.join(name)).map_err(|e| format!("{name}: {e}"))
    };
    let puget = open("puget/ps_height_1k.png")?;
    save(puget.crop_imm(300, 300, 40, 40), "png", "puget-40.png")?;
    let jpeg = open("puget/ps_height_4k_8bit.jpg")?;
    save(
        image::DynamicImage::ImageLuma8(jpeg.crop_imm(1200, 1200, 48, 48).to_luma8()),
        "jpeg",
        "puget-48.jpg",
    )?;
    let rgb = open("terrainrgb/berkeley_14-2625-6369_terrain_rgb.png")?;
    save(
        image::DynamicImage::ImageRgb8(rgb.crop_imm(100, 100, 32, 32).to_rgb8()),
        "terrain-rgb",
        "berkeley-32.png",
    )?;
    Ok(())
}
