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
use renderer::log::{write_csv, Summary};
use renderer::path::CameraPath;
use renderer::terrain::Terrain;
use renderer::vulkan::{Gpu, GpuOptions};

#[derive(Parser)]
#[command(
    name = "vkterrain",
    version,
    about = "Fly over a vkterrain tile set with Vulkan"
)]
struct Cli {
    /// Tile set built by `tiletool build`.
    tileset: PathBuf,
    /// Render offscreen (the only mode of this build).
    #[arg(long)]
    headless: bool,
    /// Camera path: a CSV keyframe file, or `orbit` / `flyover` generated from the tile set.
    #[arg(long, default_value = "flyover")]
    path: String,
    /// Frames to render; frame k shows the path at k * duration / frames.
    #[arg(long, default_value_t = 120)]
    frames: u64,
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
    // Offscreen is the only mode of this build, so --headless is accepted and implied.
    let _ = cli.headless;
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
    if cli.frames == 0 {
        bail!("--frames must be at least 1");
    }
    if let Some(out) = &cli.out {
        std::fs::create_dir_all(out)
            .with_context(|| format!("{}: cannot create", out.display()))?;
    }
    if let Some(record) = &cli.record {
        std::fs::write(record, path.to_csv())
            .with_context(|| format!("{}: cannot write", record.display()))?;
    }
    let gpu = Gpu::new(&GpuOptions {
        validation: cli.validation,
        device: cli.device.clone(),
    })?;
    let settings = Settings {
        tau: cli.tau,
        forced_level: cli.level,
        brute_force: cli.brute_force,
        level_colours: cli.level_colours,
        wireframe: cli.wireframe,
        sky: cli.sky,
        no_stitch: cli.no_stitch,
    };
    let flight = Flight {
        terrain: &terrain,
        path: &path,
        frames: cli.frames,
        size: cli.size,
        settings,
        gpu_budget_bytes: cli.gpu_budget_mb << 20,
        out: cli.out.clone(),
        screenshot_every: cli.screenshot_every,
    };
    let records = fly(&gpu, &flight)?;
    let validation = gpu.validation_messages();
    let summary = Summary::of(
        &records,
        &gpu.device_name,
        cli.size,
        cli.tau,
        cli.brute_force,
        validation,
    );
    let json = serde_json::to_string_pretty(&summary)?;
    if let Some(log) = &cli.log {
        write_csv(log, terrain.levels, &records)
            .with_context(|| format!("{}: cannot write", log.display()))?;
        let json_path = log.with_extension("json");
        std::fs::write(&json_path, &json)
            .with_context(|| format!("{}: cannot write", json_path.display()))?;
    }
    println!("{json}");
    drop(gpu);
    if validation > 0 {
        eprintln!("vkterrain: {validation} validation messages");
        return Ok(ExitCode::from(2));
    }
    Ok(ExitCode::SUCCESS)
}
