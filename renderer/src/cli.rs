//! `vkterrain`'s command line (the binary's, not the library's): the flags, their parsers, and
//! what they make of the library's settings. Every check of a value is here, so a bad one ends
//! the run with one line before anything is opened on the GPU.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Parser;
use renderer::lod::Bound;
use renderer::parts::BuildCost;
use renderer::plan::CheckPolicy;
use renderer::prefetch::PrefetchOptions;
use renderer::settings::{ByDevice, MemoryOptions, MorphShader, Settings, Shading, TextureFormat};
use renderer::terrain::Terrain;

#[derive(Parser)]
#[command(
    name = "vkterrain",
    version,
    about = "Fly over a vkterrain tile set with Vulkan"
)]
pub struct Cli {
    /// Tile set built by `tiletool build`.
    pub tileset: PathBuf,
    /// Render offscreen (the default when there is no display).
    #[arg(long, conflicts_with = "window")]
    pub headless: bool,
    /// Open a window and fly with WASD/QE and the mouse (the default with a display).
    #[arg(long)]
    pub window: bool,
    /// Window mode, for tests: ask for a new window size at a frame, FRAME=WxH (repeatable:
    /// a resize storm).
    #[arg(long, hide = true, value_parser = parse_resize, num_args = 1..)]
    pub resize_at: Vec<(u64, (u32, u32))>,
    /// Camera path: a CSV keyframe file, or `orbit` / `flyover` generated from the tile set.
    #[arg(long, default_value = "flyover")]
    pub path: String,
    /// Frames to render; frame k shows the path at k * duration / frames. In a window: close
    /// after this many frames (default: run until closed). At most 10 million.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=10_000_000))]
    pub frames: Option<u64>,
    /// Image size in pixels, WxH (the window's initial size in window mode).
    #[arg(long, default_value = "1024x768", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Pixel tolerance of the level of detail.
    #[arg(long, default_value_t = 1.0)]
    pub tau: f64,
    /// Draw every visible tile at this level.
    #[arg(long)]
    pub level: Option<u32>,
    /// Draw every visible tile at its finest level (the baseline of the benchmarks).
    #[arg(long)]
    pub brute_force: bool,
    /// Frame-timing log (CSV); a JSON summary goes next to it (same name, .json).
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Folder for screenshots (frame_000010.png).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Save every K-th frame as a PNG into --out (0: none).
    #[arg(long, default_value_t = 0, value_name = "K")]
    pub screenshot_every: u64,
    /// Sky (clear) colour: R,G,B as 0..1 floats or 0..255 integers, or #rrggbb.
    #[arg(long, default_value = "0.55,0.70,0.90", value_parser = parse_rgb)]
    pub sky: [f32; 3],
    /// GPU memory for tile data, MB: one pool allocated at start (smaller when the tile set
    /// needs less); tiles that do not fit are drawn coarser.
    #[arg(long, default_value_t = 1024)]
    pub gpu_budget_mb: u64,
    /// Tile data uploaded per frame at most, MB (new tiles' coarsest level may exceed it).
    /// Default 4; unlimited with --brute-force and --level, which are baselines.
    #[arg(long)]
    pub upload_budget_mb: Option<f64>,
    /// Frames the CPU may run ahead of the GPU.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=4))]
    pub frames_in_flight: u32,
    /// Send every upload through the staging ring, even where GPU memory is host-visible.
    #[arg(long)]
    pub force_staging: bool,
    /// Size the GPU pool's chunk classes, the staging memory and the stitch buffer from at
    /// most about this many tiles' tables: every tile of a set of up to N, else one in each
    /// run of tiles / N (a larger N reads more tables before the first frame, and plans
    /// closer to the whole set's sizes).
    #[arg(long, default_value_t = memory::costs::SAMPLE_TILES, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=(1 << 24)))]
    pub plan_sample: usize,
    /// Eviction: how much one doubling of wasted chunk space weighs against age (0: pure LRU).
    #[arg(long, default_value_t = memory::DEFAULT_WEIGHT)]
    pub evict_weight: f64,
    /// Levels finer than LOD wants a tile may stay drawn (within tau) rather than re-sending
    /// a coarser index array.
    #[arg(long, default_value_t = memory::DEFAULT_DOWNGRADE_SLACK)]
    pub downgrade_slack: u32,
    /// How a tile's level is chosen for --tau: from a bound on the projection's vertical
    /// Jacobian proved to cover every on-screen point of the tile (guaranteed), or from the
    /// Jacobian sampled at the box's corners and nearest point (sampled; can exceed tau).
    #[arg(long, value_enum, default_value_t = LodBound::Guaranteed)]
    pub lod_bound: LodBound,
    /// Discrete levels: no geomorphing (each tile at one level, heights unblended; levels
    /// change in one frame, which pops).
    #[arg(long)]
    pub no_geomorph: bool,
    /// Geomorphing: draw each tile at one level, rather than each of its 4 x 4 parts at the
    /// level the part needs (the default on GPUs, where index builds cost more than the
    /// triangles a mix saves; --draw-only draws whole tiles)
    #[arg(long, conflicts_with = "part_by_part")]
    pub whole_tiles: bool,
    /// Geomorphing: draw each of a tile's 4 x 4 parts at the level the part needs, in one
    /// index array built on the GPU per tile (the default on software rasterisers such as
    /// lavapipe, where triangles are dear)
    #[arg(long)]
    pub part_by_part: bool,
    /// Part by part: what building a tile's mixed index array costs on this device, as
    /// FIXED,SHARE: a mix is built only where it saves at least FIXED + SHARE x G triangles a
    /// frame, G being the tile's triangles at its drawn level (bench/README.md, "A build's
    /// worth", sweeps it on lavapipe; 1,0 builds every mix that saves a triangle)
    #[arg(long, value_name = "FIXED,SHARE", default_value = DEFAULT_PART_BUILD_COST, value_parser = parse_build_cost)]
    pub part_build_cost: BuildCost,
    /// How vertices morph: hierarchical (a pass places each vertex from its parents' morphed
    /// heights, coarse to fine, so that a finer level starts on the surface drawn before it),
    /// two-levels (the previous per-vertex rule: the vertex shader blends the two stored
    /// levels around each vertex's own level) or forward-differences (the same rule with the
    /// paper's clamped forward differences as dot products over every level).
    #[arg(long, value_enum, default_value_t = MorphShaderArg::Hierarchical)]
    pub morph_shader: MorphShaderArg,
    /// Diagnostic (headless): the vertex shader writes every drawn vertex's height to a buffer
    /// that is read back and compared with the CPU mirror the error meter uses (log columns
    /// heights_read_back, heights_max_diff_m); a difference beyond float rounding stops the
    /// flight with one line naming the tile and vertex. It checks the default morph (the morph
    /// pass's heights, as the vertex shader drew them), so it takes no --morph-shader.
    #[arg(long, conflicts_with = "morph_shader")]
    pub read_back_heights: bool,
    /// Send each block's morph rows (its stored offsets to the coarser levels) and hold them in
    /// the pool, although the default shaders read none: the comparison for what leaving them
    /// on disk saves. Implied by --morph-shader two-levels and forward-differences.
    #[arg(long)]
    pub morph_rows: bool,
    /// How a compact tile set's levels (tiletool build --compact, format version 5) travel:
    /// gpu (each level's compact stream, about a third of its positions' bytes, decoded by a
    /// compute pass into the pool), cpu (the positions the CPU rebuilt when it checked the
    /// tile), or auto: gpu on a GPU, cpu on a software rasteriser such as lavapipe, whose
    /// compute runs on the same cores, slower than the native decoder. Other sets send
    /// positions either way.
    #[arg(long, value_enum, default_value_t = Where::Auto)]
    pub decode: Where,
    /// How tile levels travel: progressive (new blocks and one index array per refinement),
    /// per-level (each level from scratch) or whole-tile (every level at once, the old scheme).
    /// --draw-only uses whole-tile, so that every pre-recorded frame finds its levels.
    #[arg(long, value_enum, default_value_t = UploadScheme::Progressive)]
    pub upload_scheme: UploadScheme,
    /// Where index arrays come from: built on the GPU from the tile's resident vertex blocks
    /// (they then cost no upload budget; needs storageBuffer16BitAccess, else sent), or sent
    /// from the file like the blocks (the comparison).
    #[arg(long, value_enum, default_value_t = IndexArraysArg::Built)]
    pub index_arrays: IndexArraysArg,
    /// Who builds the built index arrays: gpu (a compute pass from the resident vertex
    /// blocks), cpu (the renderer makes each from the tile's checked levels and the frame
    /// copies it into place), or auto: gpu on a GPU, cpu on a software rasteriser such as
    /// lavapipe, whose compute runs each build on one of the same cores, slower than the
    /// native code.
    #[arg(long, value_enum, default_value_t = Where::Auto)]
    pub index_builder: Where,
    /// The texture slots' format: bc1 (the file's blocks as they are), rgb565 (decoded on the
    /// CPU as they are uploaded; four times the slot memory), or auto: rgb565 on a software
    /// rasteriser such as lavapipe, which samples BC1 by decoding blocks on every fetch, and on
    /// a device that cannot sample BC1; bc1 elsewhere.
    #[arg(long, value_enum, default_value_t = TextureFormatArg::Auto)]
    pub texture_format: TextureFormatArg,
    /// Measure each frame's screen-space error against this DEM (the one the tile set was
    /// built from; with --source-spacing / --source-vertical-scale as given to tiletool):
    /// log column max_error_px. Slow (every sample of the drawn tiles, on the CPU); headless.
    #[arg(long, value_name = "DEM", num_args = 1..)]
    pub measure_error: Vec<PathBuf>,
    /// Metres between the source's samples, for formats that do not say.
    #[arg(long, value_name = "M")]
    pub source_spacing: Option<f64>,
    /// Metres per unit of the source's stored values (grey images).
    #[arg(long, value_name = "S")]
    pub source_vertical_scale: Option<f64>,
    /// The source's samples across and down, for raw `.r16`/`.f32` sources (which do not
    /// say).
    #[arg(long, value_name = "WxH", value_parser = dem::parse_size::<u32>)]
    pub source_size: Option<(u32, u32)>,
    /// Measure every K-th frame only.
    #[arg(long, default_value_t = 1, value_name = "K", value_parser = clap::value_parser!(u64).range(1..))]
    pub measure_every: u64,
    /// Write every frame's visible tiles and wanted levels here (for `memsim`).
    #[arg(long, value_name = "FILE")]
    pub trace: Option<PathBuf>,
    /// Enable the Khronos validation layer; any message makes the exit code 3.
    #[arg(long)]
    pub validation: bool,
    /// Use the device whose name contains this.
    #[arg(long)]
    pub device: Option<String>,
    /// How to colour the terrain: photo (the tile set's texture tiles: a photo, or the shaded
    /// relief tiletool bakes without one), relief (grey, lit by each triangle), tint (a
    /// hypsometric tint lit by each triangle), level (level colours) or tiles (a flat colour per
    /// tile, to see their borders). Default: photo when the tile set has textures, else tint.
    /// The window cycles them with T.
    #[arg(long, value_enum)]
    pub shading: Option<ShadingArg>,
    /// With --shading tiles: move the grid by this many samples (tests: lines that are not
    /// tile borders).
    #[arg(long, hide = true, default_value_t = 0.0)]
    pub tile_grid_offset: f32,
    /// Colour tiles by their level (the same as --shading level).
    #[arg(long, conflicts_with = "shading")]
    pub level_colours: bool,
    /// Anisotropic texture filtering, up to N samples (1: off; clamped to the device's limit).
    #[arg(long, default_value_t = 16, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=64))]
    pub anisotropy: u32,
    /// The share (0..1) of --gpu-budget-mb that texture slots may take; the tile pool gets
    /// the rest.
    #[arg(long, default_value_t = renderer::settings::DEFAULT_TEXTURE_SHARE, value_name = "SHARE")]
    pub texture_share: f64,
    /// Draw triangle edges only (where the device supports it).
    #[arg(long)]
    pub wireframe: bool,
    /// Benchmark: time only the replay of pre-recorded frames over pre-resident tiles (the
    /// draw-only limit of the same flight).
    #[arg(long)]
    pub draw_only: bool,
    /// Benchmark: instead of flying, draw a static grid of terrain-like fans with at least
    /// this many triangles with the simplest shaders, --frames times at --size, and print the
    /// frame times (the static-mesh limit; the tile set is not read).
    #[arg(long, value_name = "TRIANGLES", value_parser = clap::value_parser!(u64).range(1..=100_000_000))]
    pub static_grid: Option<u64>,
    /// Draw the first view once, untimed, before the timed flight: the driver compiles its
    /// shader variants and the first view's tiles arrive then (reported as prime_ms), as behind
    /// a loading screen, not in the first frames. (The primed frame counts in --trace and in the
    /// frame numbers of VKTERRAIN_FAULT.)
    #[arg(long, conflicts_with_all = ["warmup", "warmup_driver"])]
    pub prime: bool,
    /// Benchmark: fly the path once untimed first, so the timed flight starts warm.
    #[arg(long)]
    pub warmup: bool,
    /// Benchmark: fly the path once untimed, then empty the GPU pool, so the timed flight
    /// streams every tile from cold with the driver warm (a software rasteriser such as
    /// lavapipe grows its working memory over the first frames it draws).
    #[arg(long, conflicts_with = "warmup")]
    pub warmup_driver: bool,
    /// Diagnostic: do not draw the stitching triangles (shows the cracks they close).
    #[arg(long)]
    pub no_stitch: bool,
    /// Draw the tiles' back faces too (culled by default: hidden while the camera is above the
    /// terrain); from below it, or beside the set's edge below its heights, the underside shows.
    #[arg(long)]
    pub no_cull: bool,
    /// Diagnostic: shade every tile with the fragment shader of every shading, not textured
    /// tiles with the texture's path alone (the same frames; slower on a software rasteriser).
    #[arg(long)]
    pub one_fragment_shader: bool,
    /// Diagnostic: geomorph a tile set built with `--independent-sides` without the sliver
    /// triangles that join the two tiles' differently morphed copies of a shared side vertex
    /// (shows the cracks they close; sets built with shared sides need none).
    #[arg(long)]
    pub no_slivers: bool,
    /// Diagnostic: fly over pyramid layer N of a set built with `tiletool build --pyramid`
    /// instead of its base grid (the same ground, 2^N times the spacing).
    #[arg(
        long,
        default_value_t = 0,
        value_name = "N",
        conflicts_with = "pyramid"
    )]
    pub layer: u32,
    /// Fly the set's tile pyramid (built with `tiletool build --pyramid`): each frame draws a
    /// cut through it, base tiles near the camera and coarser layers' tiles far away, each
    /// within --tau, stitched where layers meet. Geomorphing (unless --no-geomorph) morphs each
    /// tile's levels as over the base grid; where four children replace their parent the
    /// change is discrete.
    #[arg(long, conflicts_with_all = ["brute_force", "level"])]
    pub pyramid: bool,
    /// With --pyramid, when the cut's tiles get their checks (checksum and verify's semantic
    /// checks, made before a tile's first upload): `on-frame` waits for every check on the
    /// frame that first needs the tile; `behind` checks them off the frames, coarse layers
    /// first, and draws each one's nearest checked ancestor until it passes (no frame waits
    /// for more than the top of the pyramid, but detail arrives later); a number N checks at
    /// most N a frame on the frame and stands in for the rest (deterministic, for tests). A
    /// base grid is always checked on the frame.
    #[arg(
        long,
        default_value = "on-frame",
        value_name = "on-frame|behind|N",
        value_parser = parse_checks,
        requires = "pyramid"
    )]
    pub checks: CheckPolicy,
    /// Write the path flown (CSV keyframes) here.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Do not upload tiles predicted to become visible (the camera is predicted from the
    /// poses flown, at least 0.25 to 2 s and 1 to 8 frames ahead); nor read them ahead from
    /// the file.
    #[arg(long)]
    pub no_prefetch: bool,
    /// CPU time per frame for prefetching: predicting the camera, culling and choosing levels
    /// for the predicted poses, and the memory manager's prefetch step (its deadline).
    #[arg(long, default_value_t = 2.0, value_name = "MS")]
    pub prefetch_ms: f64,
    /// Prefetch only while at least this share (0..1) of the GPU pool's chunks is free, and
    /// never take it below that.
    #[arg(long, default_value_t = memory::DEFAULT_PREFETCH_FREE, value_name = "SHARE")]
    pub prefetch_free: f64,
    /// Do not advise the kernel to read predicted tiles ahead of use (madvise WILLNEED).
    #[arg(long)]
    pub no_madvise: bool,
    /// When the tile set file is larger than this, give back the pages that opening it read
    /// (its tiles' outlines), and let the kernel drop tiles far behind the camera from this
    /// process's memory (madvise DONTNEED) once the flight has paged in more than this: the
    /// resident set follows the view, not the file
    #[arg(long, value_name = "MB", default_value_t = 1024)]
    pub file_cache_mb: u64,
    /// Benchmark: drop the tile set from the page cache after opening it, so the flight reads
    /// tiles from disk as a first run would.
    #[arg(long)]
    pub cold_file_cache: bool,
}

fn parse_checks(s: &str) -> Result<CheckPolicy, String> {
    match s {
        "behind" => Ok(CheckPolicy::Behind),
        "on-frame" => Ok(CheckPolicy::OnFrame),
        n => match n.parse() {
            Ok(0) | Err(_) => Err(format!(
                "expected on-frame, behind or a number of tiles a frame (at least 1), got {s:?}"
            )),
            Ok(n) => Ok(CheckPolicy::PerFrame(n)),
        },
    }
}

/// `--part-build-cost`'s default, measured on lavapipe (bench/README.md, "A build's worth").
const DEFAULT_PART_BUILD_COST: &str = "500,0.1";

fn parse_build_cost(s: &str) -> Result<BuildCost, String> {
    let bad = || {
        format!(
            "expected FIXED,SHARE (two numbers >= 0, e.g. {DEFAULT_PART_BUILD_COST}), got {s:?}"
        )
    };
    let (fixed, share) = s.split_once(',').ok_or_else(bad)?;
    let number = |t: &str| {
        t.trim()
            .parse::<f32>()
            .ok()
            .filter(|v| v.is_finite() && *v >= 0.0)
            .ok_or_else(bad)
    };
    Ok(BuildCost {
        fixed: number(fixed)?,
        share: number(share)?,
    })
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = dem::parse_size::<u32>(s)?;
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

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ShadingArg {
    Photo,
    Relief,
    Tint,
    Level,
    Tiles,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum MorphShaderArg {
    Hierarchical,
    TwoLevels,
    ForwardDifferences,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum LodBound {
    Guaranteed,
    Sampled,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum UploadScheme {
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
pub enum IndexArraysArg {
    Built,
    Sent,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum TextureFormatArg {
    Auto,
    Bc1,
    Rgb565,
}

/// Where a step runs: on the GPU, on the CPU, or where the device says it pays.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Where {
    Auto,
    Gpu,
    Cpu,
}

impl Cli {
    /// How to draw, checked against the tile set (photo shading needs its textures).
    pub fn settings(&self, terrain: &Terrain) -> Result<Settings> {
        let shading = match (self.shading, self.level_colours) {
            (_, true) | (Some(ShadingArg::Level), _) => Shading::Level,
            (Some(ShadingArg::Photo), _) if terrain.texture.is_none() => bail!(
                "{}: --shading photo: the tile set has no texture tiles (build it with tiletool's --texture, or without --no-texture)",
                self.tileset.display()
            ),
            (Some(ShadingArg::Photo), _) => Shading::Photo,
            (Some(ShadingArg::Relief), _) => Shading::Relief,
            (Some(ShadingArg::Tint), _) => Shading::Tint,
            (Some(ShadingArg::Tiles), _) => Shading::Tiles,
            (None, false) if terrain.texture.is_some() => Shading::Photo,
            (None, false) => Shading::Tint,
        };
        if !(0.0..=1.0).contains(&self.texture_share) {
            bail!("--texture-share must be a share between 0 and 1");
        }
        if !(self.tau.is_finite() && self.tau > 0.0) {
            bail!("--tau must be a positive number of pixels");
        }
        Ok(Settings {
            tau: self.tau,
            forced_level: self.level,
            brute_force: self.brute_force,
            shading,
            tile_grid_offset: self.tile_grid_offset,
            wireframe: self.wireframe,
            sky: self.sky,
            no_stitch: self.no_stitch,
            cull_back_faces: !self.no_cull,
            one_fragment_shader: self.one_fragment_shader,
            bound: match self.lod_bound {
                LodBound::Guaranteed => Bound::Guaranteed,
                LodBound::Sampled => Bound::Sampled,
            },
            geomorph: !self.no_geomorph,
            // Pre-recorded frames cannot follow a mix that changes from frame to frame.
            // Where the user did not choose, the device does once it is known
            // (`Cli::by_device`).
            part_by_part: !self.whole_tiles && !self.draw_only,
            part_build_cost: self.part_build_cost,
            checks: self.checks,
            morph_shader: match self.morph_shader {
                MorphShaderArg::Hierarchical => MorphShader::Hierarchical,
                MorphShaderArg::TwoLevels => MorphShader::TwoLevels,
                MorphShaderArg::ForwardDifferences => MorphShader::ForwardDifferences,
            },
        })
    }

    /// The choices left to the device ([`renderer::settings::ByDevice`]): part by part or
    /// whole tiles where the user chose neither and frames are drawn live, and each `auto`.
    pub fn by_device(&self) -> ByDevice {
        ByDevice {
            parts: !(self.whole_tiles || self.part_by_part || self.draw_only),
            decode: self.decode == Where::Auto,
            builder: self.index_builder == Where::Auto,
            texture_format: self.texture_format == TextureFormatArg::Auto,
        }
    }

    /// GPU memory, uploads and prefetching; `textures`: whether texture slots are wanted.
    pub fn memory(&self, textures: bool) -> Result<MemoryOptions> {
        let upload_budget = match self.upload_budget_mb {
            Some(mb) if mb.is_finite() && mb > 0.0 => (mb * f64::from(1 << 20)) as u64,
            Some(_) => bail!("--upload-budget-mb must be a positive number of megabytes"),
            // A baseline draws what it says: nothing deferred.
            None if self.brute_force || self.level.is_some() => u64::MAX,
            None => memory::DEFAULT_UPLOAD_BUDGET,
        };
        if !(self.evict_weight.is_finite() && self.evict_weight >= 0.0) {
            bail!("--evict-weight must be zero or positive");
        }
        Ok(MemoryOptions {
            gpu_budget_bytes: self
                .gpu_budget_mb
                .checked_mul(1 << 20)
                .filter(|&b| b > 0)
                .context("--gpu-budget-mb must be between 1 and 2^44")?,
            upload_budget,
            weight: self.evict_weight,
            frames_in_flight: self.frames_in_flight as usize,
            force_staging: self.force_staging,
            downgrade_slack: self.downgrade_slack,
            scheme: if self.draw_only {
                memory::Scheme::WholeTile
            } else {
                self.upload_scheme.into()
            },
            prefetch: self.prefetch()?,
            textures,
            texture_share: self.texture_share,
            anisotropy: self.anisotropy as f32,
            index_arrays: match self.index_arrays {
                IndexArraysArg::Built => memory::IndexArrays::Built,
                IndexArraysArg::Sent => memory::IndexArrays::Sent,
            },
            read_back_heights: self.read_back_heights,
            // Whether geomorphing is on or not: the window's key switches it.
            morph_rows: self.morph_rows || self.morph_shader != MorphShaderArg::Hierarchical,
            // Where the user did not choose (`auto`), the device does once it is known
            // (`Cli::by_device`); until then, what a GPU would get.
            decode_on_gpu: self.decode != Where::Cpu,
            build_on_gpu: self.index_builder != Where::Cpu,
            texture_format: match self.texture_format {
                TextureFormatArg::Rgb565 => TextureFormat::Rgb565,
                TextureFormatArg::Auto | TextureFormatArg::Bc1 => TextureFormat::Bc1,
            },
            plan_sample: self.plan_sample,
        })
    }

    fn prefetch(&self) -> Result<PrefetchOptions> {
        if !(self.prefetch_ms.is_finite() && self.prefetch_ms >= 0.0) {
            bail!("--prefetch-ms must be zero or a positive number of milliseconds");
        }
        if !(0.0..=1.0).contains(&self.prefetch_free) {
            bail!("--prefetch-free must be a share between 0 and 1");
        }
        Ok(PrefetchOptions {
            enabled: !self.no_prefetch,
            free_share: self.prefetch_free,
            cpu_ms: self.prefetch_ms,
            madvise: !self.no_prefetch && !self.no_madvise,
            file_cache_bytes: Some(self.file_cache_mb.saturating_mul(1 << 20)),
        })
    }
}
