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
use renderer::frame::{MemoryOptions, MorphShader, Settings, Shading};
use renderer::headless::{fly, Flight, FlightResult};
use renderer::log::{write_csv, RunInfo, Summary};
use renderer::measure::ErrorMeter;
use renderer::path::CameraPath;
use renderer::prefetch::PrefetchOptions;
use renderer::terrain::Terrain;
use renderer::vulkan::{Gpu, GpuOptions};
use renderer::window::{self, WindowOptions};

/// Exit codes (README, "Exit codes"): 0 success, 1 bad input or a failure (one line on
/// stderr), 2 usage (clap), 3 the run completed but the validation layer spoke.
const EXIT_VALIDATION: u8 = 3;

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
    /// Window mode, for tests: ask for a new window size at a frame, FRAME=WxH (repeatable:
    /// a resize storm).
    #[arg(long, hide = true, value_parser = parse_resize, num_args = 1..)]
    resize_at: Vec<(u64, (u32, u32))>,
    /// Camera path: a CSV keyframe file, or `orbit` / `flyover` generated from the tile set.
    #[arg(long, default_value = "flyover")]
    path: String,
    /// Frames to render; frame k shows the path at k * duration / frames. In a window: close
    /// after this many frames (default: run until closed). At most 10 million.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=10_000_000))]
    frames: Option<u64>,
    /// Image size in pixels, WxH (the window's initial size in window mode).
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
    /// Save every K-th frame as a PNG into --out (0: none).
    #[arg(long, default_value_t = 0, value_name = "K")]
    screenshot_every: u64,
    /// Sky (clear) colour: R,G,B as 0..1 floats or 0..255 integers, or #rrggbb.
    #[arg(long, default_value = "0.55,0.70,0.90", value_parser = parse_rgb)]
    sky: [f32; 3],
    /// GPU memory for tile data, MB: one pool allocated at start (smaller when the tile set
    /// needs less); tiles that do not fit are drawn coarser.
    #[arg(long, default_value_t = 1024)]
    gpu_budget_mb: u64,
    /// Tile data uploaded per frame at most, MB (new tiles' coarsest level may exceed it).
    /// Default 4; unlimited with --brute-force and --level, which are baselines.
    #[arg(long)]
    upload_budget_mb: Option<f64>,
    /// Frames the CPU may run ahead of the GPU.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=4))]
    frames_in_flight: u32,
    /// Send every upload through the staging ring, even where GPU memory is host-visible.
    #[arg(long)]
    force_staging: bool,
    /// Eviction: how much one doubling of wasted chunk space weighs against age (0: pure LRU).
    #[arg(long, default_value_t = memory::DEFAULT_WEIGHT)]
    evict_weight: f64,
    /// Levels finer than LOD wants a tile may stay drawn (within tau) rather than re-sending
    /// a coarser index array.
    #[arg(long, default_value_t = memory::DEFAULT_DOWNGRADE_SLACK)]
    downgrade_slack: u32,
    /// How a tile's level is chosen for --tau: from a bound on the projection's vertical
    /// Jacobian proved to cover every on-screen point of the tile (guaranteed), or from the
    /// Jacobian sampled at the box's corners and nearest point (sampled; can exceed tau).
    #[arg(long, value_enum, default_value_t = LodBound::Guaranteed)]
    lod_bound: LodBound,
    /// Discrete levels: no geomorphing (each tile at one level, heights unblended; levels
    /// change in one frame, which pops).
    #[arg(long)]
    no_geomorph: bool,
    /// The vertex shader that blends levels: two-levels (reads the two levels around each
    /// vertex's level) or forward-differences (the paper's clamped forward differences as dot
    /// products over every level; the reference).
    #[arg(long, value_enum, default_value_t = MorphShaderArg::TwoLevels)]
    morph_shader: MorphShaderArg,
    /// Diagnostic (headless): the vertex shader writes every drawn vertex's height to a buffer
    /// that is read back and compared with the CPU mirror the error meter uses (log columns
    /// heights_read_back, heights_max_diff_m); a difference beyond float rounding stops the
    /// flight with one line naming the tile and vertex.
    #[arg(long)]
    read_back_heights: bool,
    /// How tile levels travel: progressive (new blocks and one index array per refinement),
    /// per-level (each level from scratch) or whole-tile (every level at once, the old scheme).
    /// --draw-only uses whole-tile, so that every pre-recorded frame finds its levels.
    #[arg(long, value_enum, default_value_t = UploadScheme::Progressive)]
    upload_scheme: UploadScheme,
    /// Where index arrays come from: built on the GPU from the tile's resident vertex blocks
    /// (they then cost no upload budget; needs storageBuffer16BitAccess, else sent), or sent
    /// from the file like the blocks (the comparison).
    #[arg(long, value_enum, default_value_t = IndexArraysArg::Built)]
    index_arrays: IndexArraysArg,
    /// Measure each frame's screen-space error against this DEM (the one the tile set was
    /// built from; with --source-spacing / --source-vertical-scale as given to tiletool):
    /// log column max_error_px. Slow (every sample of the drawn tiles, on the CPU); headless.
    #[arg(long, value_name = "DEM", num_args = 1..)]
    measure_error: Vec<PathBuf>,
    /// Metres between the source's samples, for formats that do not say.
    #[arg(long, value_name = "M")]
    source_spacing: Option<f64>,
    /// Metres per unit of the source's stored values (grey images).
    #[arg(long, value_name = "S")]
    source_vertical_scale: Option<f64>,
    /// Measure every K-th frame only.
    #[arg(long, default_value_t = 1, value_name = "K", value_parser = clap::value_parser!(u64).range(1..))]
    measure_every: u64,
    /// Write every frame's visible tiles and wanted levels here (for `memsim`).
    #[arg(long, value_name = "FILE")]
    trace: Option<PathBuf>,
    /// Enable the Khronos validation layer; any message makes the exit code 3.
    #[arg(long)]
    validation: bool,
    /// Use the device whose name contains this.
    #[arg(long)]
    device: Option<String>,
    /// How to colour the terrain: photo (the tile set's texture tiles: a photo, or the shaded
    /// relief tiletool bakes without one), relief (grey, lit by each triangle), tint (a
    /// hypsometric tint lit by each triangle), level (level colours) or tiles (a flat colour per
    /// tile, to see their borders). Default: photo when the tile set has textures, else tint.
    /// The window cycles them with T.
    #[arg(long, value_enum)]
    shading: Option<ShadingArg>,
    /// With --shading tiles: move the grid by this many samples (tests: lines that are not
    /// tile borders).
    #[arg(long, hide = true, default_value_t = 0.0)]
    tile_grid_offset: f32,
    /// Colour tiles by their level (the same as --shading level).
    #[arg(long, conflicts_with = "shading")]
    level_colours: bool,
    /// Anisotropic texture filtering, up to N samples (1: off; clamped to the device's limit).
    #[arg(long, default_value_t = 16, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=64))]
    anisotropy: u32,
    /// The share (0..1) of --gpu-budget-mb that texture slots may take; the tile pool gets
    /// the rest.
    #[arg(long, default_value_t = renderer::frame::DEFAULT_TEXTURE_SHARE, value_name = "SHARE")]
    texture_share: f64,
    /// Draw triangle edges only (where the device supports it).
    #[arg(long)]
    wireframe: bool,
    /// Benchmark: time only the replay of pre-recorded frames over pre-resident tiles (the
    /// draw-only limit of the same flight).
    #[arg(long)]
    draw_only: bool,
    /// Benchmark: instead of flying, draw a static grid of terrain-like fans with at least
    /// this many triangles with the simplest shaders, --frames times at --size, and print the
    /// frame times (the static-mesh limit; the tile set is not read).
    #[arg(long, value_name = "TRIANGLES", value_parser = clap::value_parser!(u64).range(1..=100_000_000))]
    static_grid: Option<u64>,
    /// Draw the first view once, untimed, before the timed flight: the driver compiles its
    /// shader variants and the first view's tiles arrive then (reported as prime_ms), as behind
    /// a loading screen, not in the first frames. (The primed frame counts in --trace and in the
    /// frame numbers of VKTERRAIN_FAULT.)
    #[arg(long, conflicts_with_all = ["warmup", "warmup_driver"])]
    prime: bool,
    /// Benchmark: fly the path once untimed first, so the timed flight starts warm.
    #[arg(long)]
    warmup: bool,
    /// Benchmark: fly the path once untimed, then empty the GPU pool, so the timed flight
    /// streams every tile from cold with the driver warm (a software rasteriser such as
    /// lavapipe grows its working memory over the first frames it draws).
    #[arg(long, conflicts_with = "warmup")]
    warmup_driver: bool,
    /// Diagnostic: do not draw the stitching triangles (shows the cracks they close).
    #[arg(long)]
    no_stitch: bool,
    /// Diagnostic: geomorph a tile set built with `--independent-sides` without the sliver
    /// triangles that join the two tiles' differently morphed copies of a shared side vertex
    /// (shows the cracks they close; sets built with shared sides need none).
    #[arg(long)]
    no_slivers: bool,
    /// Write the path flown (CSV keyframes) here.
    #[arg(long)]
    record: Option<PathBuf>,
    /// Do not upload tiles predicted to become visible (the camera is predicted from the
    /// poses flown, at least 0.25 to 2 s and 1 to 8 frames ahead); nor read them ahead from
    /// the file.
    #[arg(long)]
    no_prefetch: bool,
    /// CPU time per frame for predicting the camera and culling and choosing levels for it.
    #[arg(long, default_value_t = 2.0, value_name = "MS")]
    prefetch_ms: f64,
    /// Prefetch only while at least this share (0..1) of the GPU pool's chunks is free, and
    /// never take it below that.
    #[arg(long, default_value_t = memory::DEFAULT_PREFETCH_FREE, value_name = "SHARE")]
    prefetch_free: f64,
    /// Do not advise the kernel to read predicted tiles ahead of use (madvise WILLNEED).
    #[arg(long)]
    no_madvise: bool,
    /// When the tile set file is larger than this, give back the pages that opening it read,
    /// and let the kernel drop tiles far behind the camera from this process's memory (madvise
    /// DONTNEED) once the flight has paged in more than this.
    #[arg(long, value_name = "MB")]
    file_cache_mb: Option<u64>,
    /// Benchmark: drop the tile set from the page cache after opening it (which reads it
    /// whole, to validate it), so the flight reads tiles from disk as a first run would.
    #[arg(long)]
    cold_file_cache: bool,
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

/// `R,G,B` as 0..1 floats or 0..255 integers (any component above 1 means integers), or
/// `#rrggbb`.
fn parse_rgb(s: &str) -> Result<[f32; 3], String> {
    let s = s.trim();
    if let Some(hex) = s.strip_prefix('#') {
        let byte = |i: usize| {
            hex.get(i..i + 2)
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .map(|b| f32::from(b) / 255.0)
        };
        return match (hex.len(), byte(0), byte(2), byte(4)) {
            (6, Some(r), Some(g), Some(b)) => Ok([r, g, b]),
            _ => Err("expected #rrggbb".into()),
        };
    }
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let v: Vec<f32> = parts
        .iter()
        .map(|t| t.parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| "expected R,G,B or #rrggbb")?;
    let [r, g, b] = v[..] else {
        return Err("expected R,G,B or #rrggbb".into());
    };
    let integers = parts.iter().all(|t| !t.contains('.'));
    if v.iter().any(|c| !c.is_finite() || *c < 0.0) {
        return Err("colour components must not be negative".into());
    }
    // All within 0..1: fractions (so `1,0,1` is magenta); otherwise 0..255 integers.
    if v.iter().all(|&c| c <= 1.0) {
        return Ok([r, g, b]);
    }
    if integers && v.iter().all(|&c| c <= 255.0) {
        return Ok([r / 255.0, g / 255.0, b / 255.0]);
    }
    Err("expected R,G,B with each in 0..1 (or 0..255 integers)".into())
}

/// Reads the source DEM for --measure-error and cuts it into the tile set's tiles.
fn error_meter(cli: &Cli, terrain: &Terrain, sources: &[PathBuf]) -> Result<ErrorMeter> {
    let name = sources[0].display();
    let options = dem::ReadOptions {
        spacing: cli.source_spacing,
        vertical_scale: cli.source_vertical_scale,
        ..Default::default()
    };
    let grid = dem::read(sources, &options).map_err(|e| anyhow::anyhow!("{e}"))?;
    let view = tiles::Grid {
        width: grid.width,
        height: grid.height,
        heights: &grid.heights,
        spacing_x: grid.spacing_x,
        spacing_y: grid.spacing_y,
    };
    ErrorMeter::new(terrain, &view).map_err(|e| anyhow::anyhow!("{name}: {e}"))
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum ShadingArg {
    Photo,
    Relief,
    Tint,
    Level,
    Tiles,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum MorphShaderArg {
    TwoLevels,
    ForwardDifferences,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum LodBound {
    Guaranteed,
    Sampled,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum UploadScheme {
    Progressive,
    PerLevel,
    WholeTile,
}

impl From<UploadScheme> for memory::Scheme {
    fn from(s: UploadScheme) -> memory::Scheme {
        match s {
            UploadScheme::Progressive => memory::Scheme::Progressive,
            UploadScheme::PerLevel => memory::Scheme::PerLevel,
            UploadScheme::WholeTile => memory::Scheme::WholeTile,
        }
    }
}

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum IndexArraysArg {
    Built,
    Sent,
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

/// `--static-grid N`: the static-mesh limit's frame times, as a JSON summary on stdout.
fn static_limit(cli: &Cli, triangles: u64) -> Result<ExitCode> {
    let gpu = Gpu::new(&GpuOptions {
        validation: cli.validation,
        device: cli.device.clone(),
        display: None,
    })?;
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
    let mut terrain = Terrain::open(&cli.tileset)?;
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
    let shading = match (cli.shading, cli.level_colours) {
        (_, true) | (Some(ShadingArg::Level), _) => Shading::Level,
        (Some(ShadingArg::Photo), _) if terrain.texture.is_none() => bail!(
            "{}: --shading photo: the tile set has no texture tiles (build it with tiletool's --texture, or without --no-texture)",
            cli.tileset.display()
        ),
        (Some(ShadingArg::Photo), _) => Shading::Photo,
        (Some(ShadingArg::Relief), _) => Shading::Relief,
        (Some(ShadingArg::Tint), _) => Shading::Tint,
        (Some(ShadingArg::Tiles), _) => Shading::Tiles,
        (None, false) if terrain.texture.is_some() => Shading::Photo,
        (None, false) => Shading::Tint,
    };
    if !(0.0..=1.0).contains(&cli.texture_share) {
        bail!("--texture-share must be a share between 0 and 1");
    }
    let settings = Settings {
        tau: cli.tau,
        forced_level: cli.level,
        brute_force: cli.brute_force,
        shading,
        tile_grid_offset: cli.tile_grid_offset,
        wireframe: cli.wireframe,
        sky: cli.sky,
        no_stitch: cli.no_stitch,
        bound: match cli.lod_bound {
            LodBound::Guaranteed => renderer::lod::Bound::Guaranteed,
            LodBound::Sampled => renderer::lod::Bound::Sampled,
        },
        geomorph: !cli.no_geomorph,
        morph_shader: match cli.morph_shader {
            MorphShaderArg::TwoLevels => MorphShader::TwoLevels,
            MorphShaderArg::ForwardDifferences => MorphShader::ForwardDifferences,
        },
    };
    if !(cli.tau.is_finite() && cli.tau > 0.0) {
        bail!("--tau must be a positive number of pixels");
    }
    let upload_budget = match cli.upload_budget_mb {
        Some(mb) if mb.is_finite() && mb > 0.0 => (mb * f64::from(1 << 20)) as u64,
        Some(_) => bail!("--upload-budget-mb must be a positive number of megabytes"),
        // A baseline draws what it says: nothing deferred.
        None if cli.brute_force || cli.level.is_some() => u64::MAX,
        None => memory::DEFAULT_UPLOAD_BUDGET,
    };
    if !(cli.evict_weight.is_finite() && cli.evict_weight >= 0.0) {
        bail!("--evict-weight must be zero or positive");
    }
    if !(cli.prefetch_ms.is_finite() && cli.prefetch_ms >= 0.0) {
        bail!("--prefetch-ms must be zero or a positive number of milliseconds");
    }
    if !(0.0..=1.0).contains(&cli.prefetch_free) {
        bail!("--prefetch-free must be a share between 0 and 1");
    }
    let prefetch = PrefetchOptions {
        enabled: !cli.no_prefetch,
        free_share: cli.prefetch_free,
        cpu_ms: cli.prefetch_ms,
        madvise: !cli.no_prefetch && !cli.no_madvise,
        file_cache_bytes: cli.file_cache_mb.map(|mb| mb.saturating_mul(1 << 20)),
    };
    // Opening read every tile's positions (borders, height bounds): with a file cache budget
    // smaller than the set, the process gives those pages back before flying, and holds what
    // the flight pages in (advice only: a kernel that ignores it costs the budget, not the run).
    let mut released_at_open = 0;
    if let Some(budget) = prefetch.file_cache_bytes {
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
    let memory = MemoryOptions {
        gpu_budget_bytes: cli
            .gpu_budget_mb
            .checked_mul(1 << 20)
            .filter(|&b| b > 0)
            .context("--gpu-budget-mb must be between 1 and 2^44")?,
        upload_budget,
        weight: cli.evict_weight,
        frames_in_flight: cli.frames_in_flight as usize,
        force_staging: cli.force_staging,
        downgrade_slack: cli.downgrade_slack,
        scheme: if cli.draw_only {
            memory::Scheme::WholeTile
        } else {
            cli.upload_scheme.into()
        },
        prefetch,
        // A window can switch to the textures at any time; a headless flight only if it uses
        // them.
        textures: shading == Shading::Photo || windowed,
        texture_share: cli.texture_share,
        anisotropy: cli.anisotropy as f32,
        index_arrays: match cli.index_arrays {
            IndexArraysArg::Built => memory::IndexArrays::Built,
            IndexArraysArg::Sent => memory::IndexArrays::Sent,
        },
        read_back_heights: cli.read_back_heights,
    };
    let gpu_options = GpuOptions {
        validation: cli.validation,
        device: cli.device.clone(),
        display: None,
    };
    if windowed && !cli.measure_error.is_empty() {
        bail!("--measure-error runs headless (add --headless)");
    }
    let (result, device, validation) = if windowed {
        let options = WindowOptions {
            gpu: gpu_options,
            size: cli.size,
            settings,
            memory,
            trace: cli.trace.is_some(),
            frames: cli.frames,
            resize_at: cli.resize_at.clone(),
            screenshot_dir: cli.out.clone().unwrap_or_else(|| PathBuf::from(".")),
            record: cli.record.clone(),
            start: path.at(path.keys[0].time),
        };
        window::run(&terrain, options).map_err(anyhow::Error::msg)?
    } else {
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
            sources => Some((error_meter(&cli, &terrain, sources)?, cli.measure_every)),
        };
        let result = fly(&gpu, &flight, meter)?;
        let (validation, device) = (gpu.validation_messages(), gpu.device_name.clone());
        drop(gpu);
        (result, device, validation)
    };
    // A window fails through `window::run`; a headless flight may stop early with its log kept.
    let code = finish(
        &cli,
        &terrain,
        &result,
        &memory,
        &device,
        validation,
        released_at_open,
    )?;
    match &result.error {
        // The log of the frames before the failure is written; the failure is the one line.
        Some(e) => bail!(
            "{e} (the log keeps the {} frames completed before)",
            result.records.len()
        ),
        None => Ok(code),
    }
}

/// Writes the log, its summary and the trace, prints the summary, and turns validation
/// messages into the exit code.
fn finish(
    cli: &Cli,
    terrain: &Terrain,
    result: &FlightResult,
    memory: &MemoryOptions,
    device: &str,
    validation: u64,
    released_at_open: u64,
) -> Result<ExitCode> {
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
        index_arrays: if result.built_indices {
            "built"
        } else {
            "sent"
        },
    };
    let records = &result.records;
    let summary = Summary::of(records, &run);
    let json = serde_json::to_string_pretty(&summary)?;
    if let Some(log) = &cli.log {
        write_csv(log, terrain.levels, records)
            .with_context(|| format!("{}: cannot write", log.display()))?;
        let json_path = log.with_extension("json");
        write_atomically(&json_path, json.as_bytes())?;
    }
    if let (Some(path), Some(trace)) = (&cli.trace, &result.trace) {
        write_atomically(path, trace.as_bytes())?;
    }
    println!("{json}");
    if validation > 0 {
        eprintln!("vkterrain: {validation} validation messages");
        return Ok(ExitCode::from(EXIT_VALIDATION));
    }
    Ok(ExitCode::SUCCESS)
}

/// Writes through a temporary file renamed into place, so no half-written file looks valid.
fn write_atomically(path: &std::path::Path, bytes: &[u8]) -> Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, bytes)
        .and_then(|()| std::fs::rename(&tmp, path))
        .with_context(|| format!("{}: cannot write", path.display()))
}
