//! `vkterrain`: fly over a tile set with Vulkan.
//!
//! ```text
//! vkterrain puget.vkt --headless --path flyover --frames 300 --size 1024x768 --tau 1 \
//!     --log frames.csv --out shots --screenshot-every 50
//! ```

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use clap::Parser;
use renderer::frame::Settings;
use renderer::headless::{fly, Flight};
use renderer::log::{write_csv, FrameRecord, Summary};
use renderer::path::CameraPath;
use renderer::terrain::Terrain;
use renderer::vulkan::{Gpu, GpuOptions};
use renderer::window::{self, WindowOptions};

#[derive(Parser)]
#[command(
    name = "vkterrain",
    version,
    about = "Fly over a vkterrain tile set with Vulkan"
)]
struct Cli {
    /// Tile set built by `tiletool build`.
    tileset: PathBuf,
    /// Render offscreen (the default when there is no display).
    #[arg(long, conflicts_with = "window")]
    headless: bool,
    /// Open a window and fly with WASD/QE and the mouse (the default with a display).
    #[arg(long)]
    window: bool,
    /// Window mode, for tests: ask for a new window size at a frame, FRAME=WxH.
    #[arg(long, hide = true, value_parser = parse_resize)]
    resize_at: Option<(u64, (u32, u32))>,
    /// Camera path: a CSV keyframe file, or `orbit` / `flyover` generated from the tile set.
    #[arg(long, default_value = "flyover")]
    path: String,
    /// Frames to render; frame k shows the path at k * duration / frames. In a window: close
    /// after this many frames (default: run until closed).
    #[arg(long)]
    frames: Option<u64>,
    #[arg(long, default_value = "1024x768", value_parser = parse_size)]
    size: (u32, u32),
    /// Pixel tolerance of the level of detail.
    #[arg(long, default_value_t = 1.0)]
    tau: f64,
    /// Draw every visible tile at this level.
    #[arg(long)]
    level: Option<u32>,
    /// Draw every visible tile at its finest level (the baseline of the benchmarks).
    #[arg(long)]
    brute_force: bool,
    /// Frame-timing log (CSV); a JSON summary goes next to it (same name, .json).
    #[arg(long)]
    log: Option<PathBuf>,
    /// Folder for screenshots (frame_000010.png).
    #[arg(long)]
    out: Option<PathBuf>,
    #[arg(long, default_value_t = 0)]
    screenshot_every: u64,
    /// Clear colour, 0..1 each.
    #[arg(long, default_value = "0.55,0.70,0.90", value_parser = parse_rgb)]
    sky: [f32; 3],
    /// GPU memory for tile data, MB.
    #[arg(long, default_value_t = 1024)]
    gpu_budget_mb: u64,
    /// Enable the Khronos validation layer; any message makes the exit code 2.
    #[arg(long)]
    validation: bool,
    /// Use the device whose name contains this.
    #[arg(long)]
    device: Option<String>,
    /// Colour tiles by their level.
    #[arg(long)]
    level_colours: bool,
    #[arg(long)]
    wireframe: bool,
    /// Benchmark: time only the replay of pre-recorded frames over pre-resident tiles (the
    /// draw-only limit of the same flight).
    #[arg(long)]
    draw_only: bool,
    /// Benchmark: fly the path once untimed first, so the timed flight starts warm.
    #[arg(long)]
    warmup: bool,
    /// Diagnostic: do not draw the stitching triangles (shows the cracks they close).
    #[arg(long)]
    no_stitch: bool,
    /// Write the path flown (CSV keyframes) here.
    #[arg(long)]
    record: Option<PathBuf>,
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s.split_once(['x', 'X']).ok_or("expected WxH")?;
    let (w, h): (u32, u32) = (
        w.parse().map_err(|_| "expected WxH")?,
        h.parse().map_err(|_| "expected WxH")?,
    );
    if !(16..=16384).contains(&w) || !(16..=16384).contains(&h) {
        return Err("each side must be 16..=16384 pixels".into());
    }
    Ok((w, h))
}

fn parse_resize(s: &str) -> Result<(u64, (u32, u32)), String> {
    let (frame, size) = s.split_once('=').ok_or("expected FRAME=WxH")?;
    Ok((
        frame.parse().map_err(|_| "expected FRAME=WxH")?,
        parse_size(size)?,
    ))
}

fn parse_rgb(s: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|t| t.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| "expected R,G,B")?;
    match v[..] {
        [r, g, b] if v.iter().all(|c| (0.0..=1.0).contains(c)) => Ok([r, g, b]),
        _ => Err("expected R,G,B with each in 0..1".into()),
    }
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("vkterrain: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<ExitCode> {
    let terrain = Terrain::open(&cli.tileset)?;
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
    let settings = Settings {
        tau: cli.tau,
        forced_level: cli.level,
        brute_force: cli.brute_force,
        level_colours: cli.level_colours,
        wireframe: cli.wireframe,
        sky: cli.sky,
        no_stitch: cli.no_stitch,
    };
    let gpu_options = GpuOptions {
        validation: cli.validation,
        device: cli.device.clone(),
        display: None,
    };
    if windowed {
        let options = WindowOptions {
            gpu: gpu_options,
            size: cli.size,
            settings,
            gpu_budget_bytes: cli.gpu_budget_mb << 20,
            frames: cli.frames,
            resize_at: cli.resize_at,
            screenshot_dir: cli.out.clone().unwrap_or_else(|| PathBuf::from(".")),
            record: cli.record.clone(),
            start: path.at(path.keys[0].time),
        };
        let (records, validation) = window::run(&terrain, options).map_err(anyhow::Error::msg)?;
        return finish(&cli, &terrain, &records, "window", validation);
    }
    if let Some(record) = &cli.record {
        std::fs::write(record, path.to_csv())
            .with_context(|| format!("{}: cannot write", record.display()))?;
    }
    let gpu = Gpu::new(&gpu_options)?;
    let flight = Flight {
        terrain: &terrain,
        path: &path,
        frames: cli.frames.unwrap_or(120),
        size: cli.size,
        settings,
        gpu_budget_bytes: cli.gpu_budget_mb << 20,
        out: cli.out.clone(),
        screenshot_every: cli.screenshot_every,
        draw_only: cli.draw_only,
        warmup: cli.warmup,
    };
    let records = fly(&gpu, &flight)?;
    let validation = gpu.validation_messages();
    let device = gpu.device_name.clone();
    drop(gpu);
    finish(&cli, &terrain, &records, &device, validation)
}

/// Writes the log and its summary, prints the summary, and turns validation messages into
/// the exit code.
fn finish(
    cli: &Cli,
    terrain: &Terrain,
    records: &[FrameRecord],
    device: &str,
    validation: u64,
) -> Result<ExitCode> {
    let summary = Summary::of(
        records,
        device,
        cli.size,
        cli.tau,
        cli.brute_force,
        validation,
    );
    let json = serde_json::to_string_pretty(&summary)?;
    if let Some(log) = &cli.log {
        write_csv(log, terrain.levels, records)
            .with_context(|| format!("{}: cannot write", log.display()))?;
        let json_path = log.with_extension("json");
        std::fs::write(&json_path, &json)
            .with_context(|| format!("{}: cannot write", json_path.display()))?;
    }
    println!("{json}");
    if validation > 0 {
        eprintln!("vkterrain: {validation} validation messages");
        return Ok(ExitCode::from(2));
    }
    Ok(ExitCode::SUCCESS)
}
