//! `vkterrain`: fly over a tile set with Vulkan.
//!
//! ```text
//! vkterrain puget.vkt --headless --path flyover --frames 300 --size 1024x768 --tau 1 \
//!     --log frames.csv --out shots --screenshot-every 50
//! ```

mod cli;

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use clap::Parser;
use renderer::headless::{fly, Flight, FlightResult};
use renderer::log::{write_csv, RunInfo, Summary};
use renderer::measure::ErrorMeter;
use renderer::path::CameraPath;
use renderer::settings::{MemoryOptions, Settings, Shading};
use renderer::terrain::Terrain;
use renderer::vulkan::{Gpu, GpuOptions};
use renderer::window::{self, WindowOptions};
use tiles::format::write_atomically;

use crate::cli::Cli;

/// Exit codes (README, "Exit codes"): 0 success, 1 bad input or a failure (one line on
/// stderr), 2 usage (clap), 3 the run completed but the validation layer spoke, 4 the run
/// completed without the tiles that failed their checks (one line each).
const EXIT_VALIDATION: u8 = 3;
const EXIT_BAD_TILES: u8 = 4;

/// Reads the source DEM for --measure-error and cuts it into the tile set's tiles.
fn error_meter(cli: &Cli, terrain: &Terrain, sources: &[PathBuf]) -> Result<ErrorMeter> {
    let name = sources[0].display();
    let options = dem::ReadOptions {
        spacing: cli.source_spacing,
        vertical_scale: cli.source_vertical_scale,
        size: cli.source_size.map(|(w, h)| (w as usize, h as usize)),
        ..Default::default()
    };
    let grid = dem::read(sources, &options).map_err(|e| anyhow::anyhow!("{e}"))?;
    let view = tiles::Grid {
        width: grid.width,
        height: grid.height,
        first_row: 0,
        heights: &grid.heights,
        spacing_x: grid.spacing_x,
        spacing_y: grid.spacing_y,
    };
    ErrorMeter::new(terrain, &view).map_err(|e| anyhow::anyhow!("{name}: {e}"))
}

fn main() -> ExitCode {
    tiles::hold_freed_memory();
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("vkterrain: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// `--static-grid N`: the static-mesh limit's frame times, as a JSON summary on stdout.
fn static_limit(cli: &Cli, triangles: u64) -> Result<ExitCode> {
    let gpu = Gpu::new(&gpu_options(cli))?;
    let frames = cli.frames.unwrap_or(60).min(100_000) as u32;
    let (drawn, times) = renderer::limit::static_grid(&gpu, triangles, cli.size, frames)?;
    // The first frames warm the driver up, as a flight's do; the median is over the rest.
    let warm: Vec<f64> = times.iter().skip(5.min(times.len() - 1)).copied().collect();
    let median = frametimes::stats::percentile(&warm, 50.0);
    let summary = serde_json::json!({
        "device": gpu.device_name,
        "width": cli.size.0,
        "height": cli.size.1,
        "frames": times.len(),
        "triangles": drawn,
        "frame_ms_median": median,
        "mtri_per_s": drawn as f64 / median / 1000.0,
        "validation_messages": gpu.validation_messages(),
    });
    println!("{}", serde_json::to_string_pretty(&summary)?);
    Ok(if cli.validation && gpu.validation_messages() > 0 {
        ExitCode::from(EXIT_VALIDATION)
    } else {
        ExitCode::SUCCESS
    })
}

fn run(cli: Cli) -> Result<ExitCode> {
    if let Some(n) = cli.static_grid {
        return static_limit(&cli, n);
    }
    let opening = std::time::Instant::now();
    let mut terrain = if cli.pyramid {
        Terrain::open_pyramid(&cli.tileset)?
    } else {
        Terrain::open_layer(&cli.tileset, cli.layer)?
    };
    let open_ms = opening.elapsed().as_secs_f64() * 1000.0;
    if cli.morph_shader != crate::cli::MorphShaderArg::Hierarchical {
        terrain.read_stored_offsets();
    }
    if cli.pyramid && terrain.top() == 0 {
        bail!(
            "{}: --pyramid: the tile set has no pyramid (build it with tiletool build --pyramid)",
            cli.tileset.display()
        );
    }
    terrain.shared_sides |= cli.no_slivers;
    let path = match cli.path.as_str() {
        "orbit" => CameraPath::orbit(&terrain),
        "flyover" => CameraPath::flyover(&terrain),
        file => CameraPath::read(std::path::Path::new(file)).map_err(anyhow::Error::msg)?,
    };
    if let Some(level) = cli.level {
        if level >= terrain.levels {
            bail!(
                "--level {level}: the tile set has levels 0..={}",
                terrain.levels - 1
            );
        }
    }
    if cli.frames == Some(0) {
        bail!("--frames must be at least 1");
    }
    let has_display =
        std::env::var_os("DISPLAY").is_some() || std::env::var_os("WAYLAND_DISPLAY").is_some();
    let windowed = cli.window || (!cli.headless && has_display);
    if let Some(out) = &cli.out {
        std::fs::create_dir_all(out)
            .with_context(|| format!("{}: cannot create", out.display()))?;
    }
    let settings = cli.settings(&terrain)?;
    // A window can switch to the textures at any time; a headless flight only if it uses them.
    let memory = cli.memory(settings.shading == Shading::Photo || windowed)?;
    let released_at_open = prepare_file_cache(&cli, &terrain, &memory)?;
    if windowed && !cli.measure_error.is_empty() {
        bail!("--measure-error runs headless (add --headless)");
    }
    let flown = fly_path(&cli, &terrain, &path, (settings, memory), windowed)?;
    // A window fails through `window::run`; a headless flight may stop early with its log kept.
    let code = finish(&cli, &terrain, &flown, &memory, (released_at_open, open_ms))?;
    match &flown.result.error {
        // The log of the frames before the failure is written; the failure is the one line.
        Some(e) => bail!(
            "{e} (the log keeps the {} frames completed before)",
            flown.result.records.len()
        ),
        None => Ok(code),
    }
}

/// A flight's result, and the device it ran on with the validation messages it got.
struct Flown {
    result: FlightResult,
    device: String,
    validation: u64,
    /// Geomorphing part by part, as chosen or as the device decided.
    part_by_part: bool,
}

/// Opening mapped the header and directory (each tile's table is read from the file, not
/// through the mapping): with a file cache budget smaller than the set, the process gives
/// those pages back before flying, and holds what the flight pages in (advice only: a kernel that ignores it costs the
/// budget, not the run).
/// `--cold-file-cache` drops the set from the page cache. Returns the bytes given back.
fn prepare_file_cache(cli: &Cli, terrain: &Terrain, memory: &MemoryOptions) -> Result<u64> {
    let mut released_at_open = 0;
    if let Some(budget) = memory.prefetch.file_cache_bytes {
        let len = terrain.set.file_len();
        if len > budget {
            let held = terrain.set.mapped_bytes().unwrap_or(0);
            if terrain.set.dont_need(0..len).is_ok() {
                released_at_open = held;
            }
        }
    }
    if cli.cold_file_cache {
        let left = terrain.set.drop_page_cache().with_context(|| {
            format!("{}: cannot drop from the page cache", cli.tileset.display())
        })?;
        eprintln!(
            "vkterrain: {}: {} of {} bytes still in the page cache",
            cli.tileset.display(),
            left,
            terrain.set.file_len()
        );
    }
    Ok(released_at_open)
}

fn gpu_options(cli: &Cli) -> GpuOptions {
    GpuOptions {
        validation: cli.validation,
        device: cli.device.clone(),
        display: None,
    }
}

/// Flies the path: in a window (until closed, or for `--frames`), or offscreen for `--frames`
/// frames.
fn fly_path(
    cli: &Cli,
    terrain: &Terrain,
    path: &CameraPath,
    (settings, memory): (Settings, MemoryOptions),
    windowed: bool,
) -> Result<Flown> {
    let by_device = cli.by_device();
    if windowed {
        let options = WindowOptions {
            gpu: gpu_options(cli),
            size: cli.size,
            settings,
            by_device,
            memory,
            trace: cli.trace.is_some(),
            frames: cli.frames,
            resize_at: cli.resize_at.clone(),
            screenshot_dir: cli.out.clone().unwrap_or_else(|| PathBuf::from(".")),
            record: cli.record.clone(),
            start: path.at(path.keys[0].time),
        };
        let (result, device, validation, part_by_part) =
            window::run(terrain, options).map_err(anyhow::Error::msg)?;
        return Ok(Flown {
            result,
            device,
            validation,
            part_by_part,
        });
    }
    if let Some(record) = &cli.record {
        std::fs::write(record, path.to_csv())
            .with_context(|| format!("{}: cannot write", record.display()))?;
    }
    let gpu = Gpu::new(&gpu_options(cli))?;
    let (mut settings, mut memory) = (settings, memory);
    by_device.apply(&gpu, &mut settings, &mut memory);
    let part_by_part = settings.geomorph && settings.part_by_part;
    let flight = Flight {
        terrain,
        path,
        frames: cli.frames.unwrap_or(120),
        size: cli.size,
        settings,
        memory,
        trace: cli.trace.is_some(),
        out: cli.out.clone(),
        screenshot_every: cli.screenshot_every,
        draw_only: cli.draw_only,
        warmup: cli.warmup,
        forget_after_warmup: cli.warmup_driver,
        prime: cli.prime,
    };
    let meter = match cli.measure_error.as_slice() {
        [] => None,
        sources => Some((error_meter(cli, terrain, sources)?, cli.measure_every)),
    };
    let result = fly(&gpu, &flight, meter)?;
    let (validation, device) = (gpu.validation_messages(), gpu.device_name.clone());
    drop(gpu);
    Ok(Flown {
        result,
        device,
        validation,
        part_by_part,
    })
}

/// Writes the log, its summary and the trace, prints the summary, and turns validation
/// messages into the exit code.
fn finish(
    cli: &Cli,
    terrain: &Terrain,
    flown: &Flown,
    memory: &MemoryOptions,
    (released_at_open, open_ms): (u64, f64),
) -> Result<ExitCode> {
    let Flown {
        result,
        device,
        validation,
        part_by_part,
    } = flown;
    let validation = *validation;
    let run = RunInfo {
        device: device.to_string(),
        size: cli.size,
        tau: cli.tau,
        brute_force: cli.brute_force,
        validation_messages: validation,
        pool_bytes: result.pool_bytes,
        texture_bytes: result.texture_bytes,
        upload_budget: memory.upload_budget,
        frames_in_flight: memory.frames_in_flight,
        staging: result.staging,
        upload_scheme: match memory.scheme {
            memory::Scheme::Progressive => "progressive",
            memory::Scheme::PerLevel => "per-level",
            memory::Scheme::WholeTile => "whole-tile",
        },
        // Unknown rather than a failed run where /proc is not mounted.
        file_mapped_bytes: terrain.set.mapped_bytes().ok(),
        file_released_at_open_bytes: released_at_open,
        prime_ms: result.prime_ms,
        open_ms,
        first_view_check_ms: result.first_view_check_ms,
        tiles_failed: terrain.failed_count() as u64,
        outlines_read: terrain.tiles.outlines_read() as u64,
        tiles: terrain.tiles.len() as u64,
        pool_planned_from: result.planned_from,
        part_by_part: *part_by_part && result.built_indices,
        index_arrays: if result.built_indices {
            "built"
        } else {
            "sent"
        },
        index_builder: match (result.built_indices, result.made_indices) {
            (false, _) => "none",
            (true, false) => "gpu",
            (true, true) => "cpu",
        },
        levels_decoded_on: match (terrain.has_streams(), result.decoded_levels) {
            (false, _) => "none",
            (true, true) => "gpu",
            (true, false) => "cpu",
        },
    };
    let records = &result.records;
    let summary = Summary::of(records, &run);
    let json = serde_json::to_string_pretty(&summary)?;
    if let Some(log) = &cli.log {
        write_csv(log, terrain.levels, records)
            .with_context(|| format!("{}: cannot write", log.display()))?;
        let json_path = log.with_extension("json");
        write_atomically(&json_path, json.as_bytes())
            .with_context(|| format!("{}: cannot write", json_path.display()))?;
    }
    if let (Some(path), Some(trace)) = (&cli.trace, &result.trace) {
        write_atomically(path, trace.as_bytes())
            .with_context(|| format!("{}: cannot write", path.display()))?;
    }
    println!("{json}");
    if validation > 0 {
        eprintln!("vkterrain: {validation} validation messages");
        return Ok(ExitCode::from(EXIT_VALIDATION));
    }
    // Each failed tile had its line when it failed; the summary counts them.
    if terrain.failed_count() > 0 {
        return Ok(ExitCode::from(EXIT_BAD_TILES));
    }
    Ok(ExitCode::SUCCESS)
}
