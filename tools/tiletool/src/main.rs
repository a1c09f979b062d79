//! `tiletool`: turns real DEMs into vkterrain tile sets and inspects them.
//!
//! ```text
//! tiletool build N41E001.hgt N42E001.hgt -o catalonia.vkt
//! tiletool info catalonia.vkt [--json]
//! tiletool verify catalonia.vkt --source N41E001.hgt N42E001.hgt
//! tiletool export catalonia.vkt --tile 2,3 --level 5 -o mesh.obj
//! ```
//!
//! Every failure is one line naming the file and the problem, and a non-zero exit.

mod export;
mod info;
mod photo;
mod shards;

use shards::{input_recipe, merge, print_shard, ranges, recipe, scan, scanned_stream};

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

#[derive(Parser)]
#[command(
    name = "tiletool",
    version,
    about = "Preprocess DEMs into vkterrain tile sets"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Build a tile set from one DEM (or several adjacent SRTM .hgt tiles).
    Build {
        #[command(flatten)]
        input: InputArgs,
        /// Output tile set (.vkt).
        #[arg(short, long)]
        output: PathBuf,
        /// Levels of detail per tile; level 0 is the coarsest.
        #[arg(long, default_value_t = 9)]
        levels: u32,
        /// Error bound of the finest level in metres; level i gets base * 2^(levels-1-i).
        #[arg(long, default_value_t = 1.0)]
        base_error: f64,
        /// Build every tile on its own instead of making neighbours agree on the vertices of
        /// their shared sides. Faster and slightly smaller, but a geomorphing renderer must
        /// then close the seams with sliver triangles; kept for comparisons.
        #[arg(long)]
        independent_sides: bool,
        /// Also build the tile pyramid: coarser tiles over 2 x 2 tiles of the layer below, up
        /// to one tile, for views that see much of the set (format version 3; see the README,
        /// "The tile pyramid").
        #[arg(long)]
        pyramid: bool,
        /// Store each tile's levels compact: which vertices each level adds and their heights,
        /// the fans, vertex order and morph offsets rebuilt when read (format version 5, about
        /// 1 byte a sample on rough terrain instead of 18-32; see the README, "Compact levels").
        /// Readers rebuild a tile's levels on the CPU as far as they first read them;
        /// `vkterrain` decodes the levels it draws on the GPU.
        #[arg(long)]
        compact: bool,
        /// No progress bar or summary.
        #[arg(long)]
        quiet: bool,
        /// Replace the output even if it exists and is not a tile set.
        #[arg(long)]
        force: bool,
        /// Tile rows (256 grid rows each) held at a time when reading SRTM and raw inputs,
        /// which are read a band at a time; other inputs are held whole
        /// [default: about 64 M samples a band; for a shard, at most a quarter of its rows]
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
        band_rows: Option<u32>,
        #[command(flatten)]
        texture: TextureArgs,
        /// Build only shard K of N (0 <= K < N): the K-th of N bands of tile rows, into a part
        /// file (OUTPUT), for `tiletool merge` to join into the set that a build without
        /// --shard makes, byte for byte. Each shard meshes only its band, and reads the whole
        /// input to scan it unless given --scans (see the README, "Distributed builds").
        #[arg(long, value_name = "K/N")]
        shard: Option<tiles::shard::Shard>,
        /// Tile rows beyond its band over which a shard settles the shared sides with its
        /// neighbours, so that the merge finds the seams settled.
        #[arg(long, requires = "shard", default_value_t = tiles::shard::DEFAULT_HALO)]
        halo: u32,
        /// A folder holding every shard's scan (`build ... --shard K/N --scan-only -o
        /// DIR/scan-K-of-N.vktscan`): the shard then reads only its rows of the input (with
        /// the margin their voids' fill needs), not the whole of it. An input with voids needs
        /// every shard's ranges in DIR too (`--ranges-only`).
        #[arg(long, requires = "shard", value_name = "DIR")]
        scans: Option<PathBuf>,
        /// Only scan shard K/N's rows of the input (their range of heights, tile ranges, cell
        /// spans and voids, and the void fill's share of the pass, reading only those rows) into
        /// OUTPUT, by convention DIR/scan-K-of-N.vktscan, for the shards' `--scans DIR`.
        #[arg(long, requires = "shard", conflicts_with = "scans")]
        scan_only: bool,
        /// With --scans: only fill shard K/N's rows as the scans plan and write their tile
        /// ranges and cell spans into OUTPUT, by convention DIR/ranges-K-of-N.vktranges (the second stage of
        /// a scanned build, which an input with voids needs).
        #[arg(long, requires = "scans", conflicts_with = "scan_only")]
        ranges_only: bool,
    },

    /// Join the part files of a sharded build (`build --shard K/N`) into the tile set.
    Merge {
        /// Every part of the build, each shard exactly once.
        #[arg(required = true)]
        parts: Vec<PathBuf>,
        /// Output tile set (.vkt).
        #[arg(short, long)]
        output: PathBuf,
        /// No progress bar or summary.
        #[arg(long)]
        quiet: bool,
        /// Replace the output even if it exists and is not a tile set.
        #[arg(long)]
        force: bool,
    },
    /// Print a tile set's grid, levels and measured errors.
    Info {
        file: PathBuf,
        #[arg(long)]
        json: bool,
    },
    /// Check a tile set's structure, and with --source its errors against the DEM.
    Verify {
        file: PathBuf,
        /// The DEM the set was built from (same flags as build).
        #[arg(long, num_args = 1..)]
        source: Vec<PathBuf>,
        /// Another tile set of the same input (e.g. the version 3 build of a `--compact` set):
        /// every tile of every layer must read back the same, byte for byte.
        #[arg(long)]
        against: Option<PathBuf>,
        /// No progress bar (it appears on a terminal for a verify that takes over a second).
        #[arg(long)]
        quiet: bool,
        #[command(flatten)]
        read: ReadArgs,
    },
    /// Write one level of one tile as a Wavefront OBJ mesh, or one mip of its texture as PNG.
    Export {
        file: PathBuf,
        /// Tile column and row, e.g. 2,3.
        #[arg(long, value_parser = parse_pair)]
        tile: (u32, u32),
        /// Level of detail to write as OBJ.
        #[arg(
            long,
            required_unless_present = "texture_mip",
            conflicts_with = "texture_mip"
        )]
        level: Option<u32>,
        /// Texture mip to write as PNG instead (the decoded BC1 layer, gutter included).
        #[arg(long)]
        texture_mip: Option<u32>,
        #[arg(short, long)]
        output: PathBuf,
    },
}

/// What the terrain is textured with (default: a pre-lit shaded relief of the heights).
#[derive(Args, Clone)]
struct TextureArgs {
    /// Photo texture draped over the heights: PNG, JPEG or RGB GeoTIFF of any resolution.
    /// A GeoTIFF over georeferenced heights (GeoTIFF, SRTM, named Terrain-RGB tile) is aligned
    /// by both files' georeferencing (same coordinate system; grey where it does not reach);
    /// otherwise it is taken to span the height grid exactly (first to last column and row).
    #[arg(long, conflicts_with = "no_texture")]
    texture: Option<PathBuf>,
    /// No texture tiles: the renderer lights the terrain itself (as before format v2).
    #[arg(long)]
    no_texture: bool,
    /// Texels per grid cell along each axis, rounded per tile to a power of two
    /// [default: the photo's own density; 2 for the relief, i.e. 4 per sample as in the paper]
    #[arg(long)]
    texels_per_sample: Option<f64>,
    /// Sun of the shaded relief: degrees clockwise from north.
    #[arg(long, default_value_t = 315.0, allow_negative_numbers = true)]
    sun_azimuth: f64,
    /// Sun of the shaded relief: degrees above the horizon.
    #[arg(long, default_value_t = 45.0, allow_negative_numbers = true)]
    sun_elevation: f64,
    /// Colour the shaded relief by height (hypsometric tint).
    #[arg(long, conflicts_with = "texture")]
    tint: bool,
}

impl TextureArgs {
    /// The texturing to build with, reading the photo if there is one, and how the photo lies
    /// on the heights.
    fn texturing(
        &self,
        grid: Option<&dem::HeightGrid>,
    ) -> Result<Option<(tiles::texture::Texturing, Option<photo::Laid>)>> {
        use tiles::texture::{interior_for, Layout, Source, Texturing};
        if self.no_texture {
            return Ok(None);
        }
        if let Some(t) = self.texels_per_sample {
            if !(t.is_finite() && t > 0.0) {
                bail!("--texels-per-sample {t} must be a positive number");
            }
        }
        let (source, density, laid) = match &self.texture {
            Some(path) => {
                let grid = grid.ok_or_else(|| {
                    anyhow::anyhow!("{}: a photo is laid on a grid read whole", path.display())
                })?;
                let picture = photo::read(path)?;
                let (photo, laid) = photo::lay(picture, path, grid, &view(grid))?;
                let density = photo.pixels_per_cell();
                (Source::Photo(photo), density, Some(laid))
            }
            None => {
                let relief = tiles::texture::relief::Relief {
                    azimuth_deg: self.sun_azimuth,
                    elevation_deg: self.sun_elevation,
                    tint: self.tint,
                };
                relief.validate().map_err(|e| anyhow::anyhow!(e))?;
                (Source::Relief(relief), 2.0, None)
            }
        };
        let layout = Layout::new(interior_for(self.texels_per_sample.unwrap_or(density)))
            .map_err(|e| anyhow::anyhow!(e))?;
        Ok(Some((Texturing { source, layout }, laid)))
    }
}

#[derive(Args)]
struct InputArgs {
    /// DEM file(s): 16/8-bit grey PNG or JPEG, SRTM .hgt, GeoTIFF, Terrain-RGB/Terrarium PNG, raw .r16/.f32.
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    #[command(flatten)]
    read: ReadArgs,
}

impl InputArgs {
    /// The inputs as a summary names them: their paths, space-separated.
    fn names(&self) -> String {
        let names: Vec<_> = self
            .inputs
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        names.join(" ")
    }
}

#[derive(Args, Clone, Default)]
struct ReadArgs {
    /// Metres between samples, for formats that do not say (overrides the file).
    #[arg(long)]
    spacing: Option<f64>,
    /// Metres per unit of the stored values (grey images, .r16).
    #[arg(long)]
    vertical_scale: Option<f64>,
    /// Grid size of raw .r16/.f32 files, e.g. 1025x1025.
    #[arg(long, value_parser = dem::parse_size::<usize>)]
    size: Option<(usize, usize)>,
    /// How RGB PNGs encode height: terrain-rgb or terrarium.
    #[arg(long)]
    encoding: Option<dem::Encoding>,
    /// Use only a window of the grid: X,Y,WxH (columns and rows from the north-west corner).
    #[arg(long)]
    crop: Option<dem::Crop>,
}

fn parse_pair(s: &str) -> Result<(u32, u32), String> {
    let (a, b) = s.split_once(',').ok_or("expected X,Y")?;
    Ok((
        a.trim().parse().map_err(|_| "expected X,Y")?,
        b.trim().parse().map_err(|_| "expected X,Y")?,
    ))
}

impl ReadArgs {
    fn options(&self) -> dem::ReadOptions {
        dem::ReadOptions {
            encoding: self.encoding,
            size: self.size,
            spacing: self.spacing,
            vertical_scale: self.vertical_scale,
            crop: self.crop,
        }
    }
}

/// The temporary file of the build in progress, for the signal handler (a leaked C string,
/// set once before the build starts).
static TEMP_FILE: std::sync::atomic::AtomicPtr<libc::c_char> =
    std::sync::atomic::AtomicPtr::new(std::ptr::null_mut());

/// On SIGINT, SIGTERM or SIGHUP: unlink the build's temporary file and exit with 128 + the
/// signal, as the shell would report it. Only async-signal-safe calls.
extern "C" fn on_signal(signal: libc::c_int) {
    let path = TEMP_FILE.load(std::sync::atomic::Ordering::SeqCst);
    // SAFETY: `path` is null or a NUL-terminated string leaked for the process's lifetime;
    // unlink and _exit are async-signal-safe.
    unsafe {
        if !path.is_null() {
            libc::unlink(path);
        }
        libc::_exit(128 + signal);
    }
}

/// Makes an interrupted build remove its temporary file (a SIGKILLed one cannot: the next
/// build into the same folder removes it, see `tiles::format::TileSetWriter::create`).
fn remove_on_signal(output: &Path) -> Result<()> {
    use std::os::unix::ffi::OsStrExt;
    let tmp = tiles::format::temp_path(output)?;
    let c = std::ffi::CString::new(tmp.as_os_str().as_bytes())
        .map_err(|_| anyhow::anyhow!("{}: a NUL byte in the path", output.display()))?;
    TEMP_FILE.store(c.into_raw(), std::sync::atomic::Ordering::SeqCst);
    for signal in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
        // SAFETY: installs a handler that only makes async-signal-safe calls.
        let previous =
            unsafe { libc::signal(signal, on_signal as *const () as libc::sighandler_t) };
        if previous == libc::SIG_ERR {
            bail!("cannot install a signal handler");
        }
    }
    Ok(())
}

fn main() -> ExitCode {
    tiles::hold_freed_memory();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Build {
            input,
            output,
            levels,
            base_error,
            independent_sides,
            pyramid,
            compact,
            quiet,
            force,
            band_rows,
            texture,
            shard,
            halo,
            scans,
            scan_only,
            ranges_only,
        } => {
            // A shard's output is a part file (or a scan, or ranges), which a retried shard
            // replaces.
            let replaces = match (shard, scan_only, ranges_only) {
                (Some(_), true, _) => tiles::shard::SCAN_MAGIC,
                (Some(_), _, true) => tiles::shard::RANGES_MAGIC,
                (Some(_), false, false) => tiles::shard::PART_MAGIC,
                (None, _, _) => tiles::format::MAGIC,
            };
            check_output(&output, &input.inputs, force, replaces).and_then(|()| {
                if let (Some(shard), true) = (shard, scan_only) {
                    return scan(&input, shard, &output);
                }
                if let (Some(shard), Some(dir), true) = (shard, &scans, ranges_only) {
                    return ranges(&input, shard, dir, &output);
                }
                remove_on_signal(&output)?;
                build(
                    &input,
                    &output,
                    tiles::BuildParams {
                        levels,
                        base_error,
                        shared_sides: !independent_sides,
                        pyramid,
                    },
                    &texture,
                    band_rows,
                    (quiet, compact),
                    shard.map(|s| (s, halo, scans)),
                )
            })
        }

        Command::Merge {
            parts,
            output,
            quiet,
            force,
        } => check_output(&output, &parts, force, tiles::format::MAGIC).and_then(|()| {
            remove_on_signal(&output)?;
            merge(&parts, &output, quiet)
        }),
        Command::Info { file, json } => info::run(&file, json),
        Command::Verify {
            file,
            source,
            against,
            read,
            quiet,
        } => verify(&file, &source, against.as_deref(), &read, quiet),
        Command::Export {
            file,
            tile,
            level,
            texture_mip,
            output,
        } => match (level, texture_mip) {
            (Some(level), _) => export::run(&file, tile, level, &output),
            (None, Some(mip)) => export::texture(&file, tile, mip, &output),
            (None, None) => Err(anyhow::anyhow!("give --level or --texture-mip")),
        },
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("tiletool: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// The tile builder's view of a decoded height grid.
fn view(grid: &dem::HeightGrid) -> tiles::Grid<'_> {
    tiles::Grid {
        width: grid.width,
        height: grid.height,
        first_row: 0,
        heights: &grid.heights,
        spacing_x: grid.spacing_x,
        spacing_y: grid.spacing_y,
    }
}

/// A build's heights: held whole, or read a band at a time.
enum Dem {
    Whole(dem::HeightGrid),
    Bands(StreamHeights),
}

/// What a build's summary says of its heights.
struct About {
    width: usize,
    height: usize,
    spacing_x: f64,
    spacing_y: f64,
    min_max: (f32, f32),
    voids_filled: u64,
    description: String,
}

impl Dem {
    fn about(&self) -> About {
        match self {
            Dem::Whole(g) => About {
                width: g.width,
                height: g.height,
                spacing_x: g.spacing_x,
                spacing_y: g.spacing_y,
                min_max: g.min_max(),
                voids_filled: g.voids_filled,
                description: g.description.clone(),
            },
            Dem::Bands(StreamHeights { stream: s, .. }) => About {
                width: s.width,
                height: s.height,
                spacing_x: s.spacing_x,
                spacing_y: s.spacing_y,
                min_max: s.min_max,
                voids_filled: s.voids_filled,
                description: s.description.clone(),
            },
        }
    }
}

/// A progress bar on stderr that appears only for work that takes over a second, and never
/// with `--quiet`.
struct Progress {
    bar: ProgressBar,
    start: Instant,
    quiet: bool,
}

impl Progress {
    fn new(len: Option<u64>, template: &str, quiet: bool) -> Progress {
        let bar = ProgressBar::with_draw_target(len, ProgressDrawTarget::hidden());
        bar.set_style(
            ProgressStyle::with_template(template)
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        Progress {
            bar,
            start: Instant::now(),
            quiet,
        }
    }

    /// One more item done.
    fn tick(&self) {
        self.bar.inc(1);
        if !self.quiet && self.bar.is_hidden() && self.start.elapsed() > Duration::from_secs(1) {
            self.bar.set_draw_target(ProgressDrawTarget::stderr());
        }
    }
}

/// Samples a band holds by default: 256 MB of heights.
const BAND_SAMPLES: usize = 1 << 26;

/// Tile rows per band for a grid `width` samples wide: about [`BAND_SAMPLES`], at least one.
/// For shard `shard` of a grid `height` samples high, at most a quarter of the shard's tile
/// rows (at least one): its memory then follows its share of the grid, about 1/N of the whole
/// build's plus a band, as a distributed build wants of it.
fn default_band_rows(width: usize, shard: Option<(tiles::shard::Shard, usize)>) -> u32 {
    let whole = (BAND_SAMPLES / (257 * width.max(1))).clamp(1, u32::MAX as usize) as u32;
    let share = shard.and_then(|(s, height)| {
        let (_, tiles_y) = tiles::format::tile_count(width, height).ok()?;
        Some(s.rows(tiles_y).len() as u32)
    });
    match share {
        Some(rows) => whole.min(rows.div_ceil(4).max(1)),
        None => whole,
    }
}

/// A DEM stream as the tile builder reads it.
struct StreamHeights {
    stream: dem::Stream,
    per_band: u32,
}

impl tiles::build::Heights for StreamHeights {
    fn shape(&self) -> tiles::Grid<'_> {
        let s = &self.stream;
        tiles::Grid {
            width: s.width,
            height: s.height,
            first_row: 0,
            heights: &[],
            spacing_x: s.spacing_x,
            spacing_y: s.spacing_y,
        }
    }

    fn rows(&self, y0: usize, y1: usize) -> Result<std::borrow::Cow<'_, [f32]>, tiles::BuildError> {
        self.stream
            .rows(y0, y1)
            .map_err(|e| tiles::BuildError::Input(e.to_string()))
    }

    fn reads_rows_singly(&self) -> bool {
        self.stream.reads_rows_singly()
    }

    fn band_tile_rows(&self) -> u32 {
        if self.stream.is_banded() {
            self.per_band
        } else {
            u32::MAX
        }
    }
}

fn read_dem(inputs: &[PathBuf], read: &ReadArgs) -> Result<dem::HeightGrid> {
    Ok(dem::read(inputs, &read.options())?)
}

/// Refuses an output that would destroy data: one of the inputs, anything but a regular file
/// (a FIFO or device would be replaced by the rename), or an existing file that is not a tile
/// set (unless `force`).
fn check_output(output: &Path, inputs: &[PathBuf], force: bool, replaces: [u8; 8]) -> Result<()> {
    use std::os::unix::fs::MetadataExt;
    let Ok(meta) = std::fs::symlink_metadata(output) else {
        return Ok(()); // nothing there yet
    };
    let target = std::fs::metadata(output).unwrap_or(meta);
    let name = output.display();
    if target.is_dir() {
        bail!("{name}: is a folder, not an output file");
    }
    if !target.is_file() {
        bail!("{name}: not a regular file; refusing to replace it");
    }
    for input in inputs {
        if let Ok(m) = std::fs::metadata(input) {
            if (m.dev(), m.ino()) == (target.dev(), target.ino()) {
                bail!(
                    "{name}: is the input {}; choose another output",
                    input.display()
                );
            }
        }
    }
    if !force {
        let mut magic = [0u8; 8];
        let is_ours = std::fs::File::open(output)
            .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut magic))
            .is_ok()
            && magic == replaces;
        if !is_ours {
            let what = if replaces == tiles::format::MAGIC {
                "a tile set"
            } else {
                "a part file"
            };
            bail!("{name}: exists and is not {what}; add --force to replace it");
        }
    }
    Ok(())
}

fn build(
    input: &InputArgs,
    output: &Path,
    params: tiles::BuildParams,
    texture: &TextureArgs,
    band_rows: Option<u32>,
    (quiet, compact): (bool, bool),
    shard: Option<(tiles::shard::Shard, u32, Option<PathBuf>)>,
) -> Result<ExitCode> {
    params.validate()?;
    if output.is_dir() {
        bail!("{}: is a folder, not an output file", output.display());
    }
    let start = Instant::now();
    // A photo is laid on the grid by its georeferencing, which needs the grid whole; otherwise
    // SRTM and raw inputs are read a band at a time (dem::open), the others held whole.
    // A shard with every shard's scans reads only its own rows (and the margin their voids'
    // fill needs). What the input is, for a shard's recipe and its scans: its files read once
    // for it.
    let inputs = shard.as_ref().map(|_| input_recipe(input)).transpose()?;
    let scanned = match (&shard, &inputs) {
        (Some((s, _, Some(dir))), Some(ours)) if texture.texture.is_none() => {
            Some(scanned_stream(input, ours, *s, dir)?)
        }
        _ => None,
    };
    let ours = shard.as_ref().map(|(s, _, _)| *s);
    let mut scans = None;
    let dem = if texture.texture.is_some() {
        Dem::Whole(read_dem(&input.inputs, &input.read)?)
    } else if let Some((stream, found)) = scanned {
        scans = Some(found);
        let per_band = band_rows
            .unwrap_or_else(|| default_band_rows(stream.width, ours.map(|s| (s, stream.height))));
        Dem::Bands(StreamHeights { stream, per_band })
    } else {
        let stream = dem::open(&input.inputs, &input.read.options())?;
        let per_band = band_rows
            .unwrap_or_else(|| default_band_rows(stream.width, ours.map(|s| (s, stream.height))));
        Dem::Bands(StreamHeights { stream, per_band })
    };
    let (texturing, laid) = texture
        .texturing(match &dem {
            Dem::Whole(grid) => Some(grid),
            Dem::Bands(_) => None,
        })?
        .unzip();
    let laid = laid.flatten();
    let decoded = start.elapsed();
    let about = dem.about();
    let (tiles_x, tiles_y) = tiles::format::tile_count(about.width, about.height)
        .map_err(|e| anyhow::anyhow!("{}: {e}", input.inputs[0].display()))?;
    // The pyramid's layers' tiles count too.
    let layers = if params.pyramid {
        tiles::format::pyramid_layers(about.width, about.height)
    } else {
        0
    };
    let all_tiles: u64 = (0..=layers)
        .map(|p| {
            let (w, h, _) = tiles::format::layer_grid(about.width, about.height, p);
            tiles::format::tile_count(w, h).map_or(0, |(x, y)| u64::from(x) * u64::from(y))
        })
        .sum();
    let bar = Progress::new(
        Some(all_tiles),
        "{elapsed_precise} [{bar:40}] {pos}/{len} tiles ({eta} left)",
        quiet,
    );
    let progress = || bar.tick();
    let meta = tiles::TileSetMeta {
        description: about.description.clone(),
        voids_filled: about.voids_filled,
        compact,
    };
    let whole;
    let heights: &dyn tiles::build::Heights = match &dem {
        Dem::Whole(grid) => {
            whole = view(grid);
            &whole
        }
        Dem::Bands(heights) => heights,
    };
    if let Some((shard, halo, _)) = shard {
        let shard = (shard, halo);
        let recipe = recipe(
            inputs.as_deref().unwrap_or_default(),
            &params,
            texture,
            compact,
        )?;
        let (tiles_x, _) = (tiles_x, tiles_y);
        let bar_len = u64::from(shard.0.rows(tiles_y).len() as u32) * u64::from(tiles_x);
        bar.bar.set_length(bar_len);
        let summary = tiles::shard::build_shard(
            heights,
            &params,
            texturing.as_ref(),
            &meta,
            shard,
            scans.as_ref(),
            &recipe,
            output,
            &progress,
        )?;
        bar.bar.finish_and_clear();
        if !quiet {
            print_shard(input, output, shard.0, &summary, &about, start.elapsed());
        }
        return Ok(ExitCode::SUCCESS);
    }
    let summary = tiles::build::build_tileset_from(
        heights,
        &params,
        texturing.as_ref(),
        &meta,
        output,
        &progress,
    )?;
    bar.bar.finish_and_clear();
    let total = start.elapsed();
    if !quiet {
        let grid = &about;
        let samples = (grid.width * grid.height) as f64;
        let (lo, hi) = grid.min_max;
        println!("{}  ->  {}", input.names(), output.display());
        println!("  source    {}", grid.description);
        println!(
            "  grid      {} x {} samples, spacing {:.2} x {:.2} m, heights {:.1}..{:.1} m, {} voids filled",
            grid.width, grid.height, grid.spacing_x, grid.spacing_y, lo, hi, grid.voids_filled
        );
        println!(
            "  tiles     {tiles_x} x {tiles_y} of 257 x 257, {} levels, base error {} m",
            params.levels, params.base_error
        );
        if params.shared_sides {
            println!(
                "  sides     shared: neighbours agreed after {} passes ({} tile meshes, {} from \
                 the tile's last)",
                summary.agreement_passes, summary.agreement_meshes, summary.agreement_resumed
            );
        } else {
            println!("  sides     independent");
        }
        println!(
            "  level     e_i (m)   max err (m)     vertices    triangles        bytes   limited"
        );
        for (i, l) in summary.levels.iter().enumerate() {
            let limited = if l.limited_triangles > 0 {
                format!("{} by <= {:.2} m", l.limited_triangles, l.limited_excess)
            } else {
                "-".into()
            };
            println!(
                "  {i:>5} {:>11} {:>13.3} {:>12} {:>12} {:>12}   {limited}",
                params.level_error(i as u32),
                l.max_error,
                l.vertices,
                l.triangles,
                l.bytes
            );
        }
        if let Some(t) = &texturing {
            print_texture(t, laid.as_ref(), &summary, tiles_x * tiles_y);
        }
        if !summary.pyramid.is_empty() {
            println!("  pyramid   layer  tiles    triangles        bytes  texture bytes  decimation error (m)  finest, coarsest level's error (m)");
        }
        for (p, l) in summary.pyramid.iter().enumerate() {
            println!(
                "  {:>13} {:>6} {:>12} {:>12} {:>14} {:>21.3}  {:.3}, {:.3}",
                p + 1,
                l.tiles,
                l.triangles,
                l.bytes,
                l.texture_bytes,
                l.decimation_error,
                l.base_errors.last().copied().unwrap_or(0.0),
                l.base_errors.first().copied().unwrap_or(0.0)
            );
        }
        let secs = total.as_secs_f64();
        println!(
            "  file      {:.1} MB; {:.2} s (decode {:.2} s), {:.0} M samples/min{}",
            summary.file_bytes as f64 / 1e6,
            secs,
            decoded.as_secs_f64(),
            samples / secs * 60.0 / 1e6,
            peak_memory()
                .map(|m| format!(", peak memory {:.0} MB", m as f64 / 1e6))
                .unwrap_or_default()
        );
    }
    Ok(ExitCode::SUCCESS)
}

fn print_texture(
    t: &tiles::texture::Texturing,
    laid: Option<&photo::Laid>,
    summary: &tiles::BuildSummary,
    tiles: u32,
) {
    use tiles::texture::Source;
    let l = &t.layout;
    let what = match (&t.source, laid) {
        (Source::Photo(p), Some(laid)) => format!("photo {}x{} px, {laid}", p.width, p.height),
        (Source::Photo(p), None) => format!("photo {}x{} px", p.width, p.height),
        (Source::Relief(r), _) => format!(
            "shaded relief{}, sun at azimuth {} and elevation {} degrees",
            if r.tint { " with hypsometric tint" } else { "" },
            r.azimuth_deg,
            r.elevation_deg
        ),
    };
    println!("  texture   {what}");
    println!(
        "            BC1, {} texels per tile + {}-texel gutters = {} per layer, {} mips ({} aligned with the tiles)",
        l.interior,
        l.gutter,
        l.size,
        l.mips,
        l.aligned_mips()
    );
    println!("    mip      texels   PSNR (dB)        bytes");
    for (m, s) in summary.texture_mips.iter().enumerate() {
        println!(
            "  {m:>5} {:>11} {:>11.2} {:>12}",
            format!("{0}x{0}", s.size),
            s.psnr(),
            s.bytes
        );
    }
    // Source texels: the photo's pixels, or the relief texels the tiles' interiors hold.
    let source_texels = match &t.source {
        Source::Photo(p) => (p.width * p.height) as f64,
        Source::Relief(_) => f64::from(tiles) * f64::from(l.interior).powi(2),
    };
    let made = f64::from(tiles) * f64::from(l.interior).powi(2);
    let per_core = |texels: f64| texels / summary.texture_seconds.max(1e-9) * 60.0 / 1e6;
    println!(
        "            {:.1} s of thread time: {:.0} M source texels per minute per core ({:.0} M tile texels made)",
        summary.texture_seconds,
        per_core(source_texels),
        per_core(made)
    );
}

/// Peak resident memory of this process (Linux), bytes.
fn peak_memory() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

fn verify(
    file: &Path,
    source: &[PathBuf],
    against: Option<&Path>,
    read: &ReadArgs,
    quiet: bool,
) -> Result<ExitCode> {
    let set = tiles::TileSet::open(file)?;
    let other = against.map(tiles::TileSet::open).transpose()?;
    let grid = if source.is_empty() {
        None
    } else {
        Some(read_dem(source, read)?)
    };
    let view = grid.as_ref().map(view);
    let all_tiles: u64 = (0..=set.pyramid_layers())
        .filter_map(|p| set.layer(p))
        .map(|l| u64::from(l.header().tiles_x) * u64::from(l.header().tiles_y))
        .sum();
    let bar = Progress::new(
        Some(all_tiles),
        "{elapsed_precise} [{bar:40}] {pos}/{len} tiles checked ({eta} left)",
        quiet,
    );
    let mut report =
        tiles::verify::verify_in_runs(&set, view.as_ref(), tiles::verify::TILES_A_RUN, &|| {
            bar.tick()
        });
    bar.bar.finish_and_clear();
    if let Some(other) = &other {
        report
            .problems
            .extend(tiles::verify::same_tiles(&set, other));
    }
    for p in report.problems.iter().take(50) {
        eprintln!("{p}");
    }
    if report.problems.len() > 50 {
        eprintln!("... and {} more problems", report.problems.len() - 50);
    }
    let what = match (grid.is_some(), &other) {
        (true, None) => "structure and errors against the source".to_string(),
        (false, None) => "structure".to_string(),
        (g, Some(o)) => format!(
            "structure{}, every tile the same as {}'s",
            if g { ", errors against the source" } else { "" },
            o.path().display()
        ),
    };
    if report.ok() {
        println!(
            "{}: OK ({what}): {} tiles, {} tile levels checked",
            file.display(),
            report.tiles,
            report.levels_checked
        );
        if let Some(g) = &grid {
            let errs: Vec<String> = report
                .recomputed_max_error
                .iter()
                .map(|e| format!("{e:.3}"))
                .collect();
            println!("  recomputed max error per level (m): {}", errs.join(" "));
            if g.voids_filled > 0 {
                println!("  (source voids filled: {})", g.voids_filled);
            }
        }
        if !report.limited.is_empty() {
            println!(
                "  {} tile levels exceed e_i where the spacing rule stopped refinement (see `tiletool info`)",
                report.limited.len()
            );
        }
        Ok(ExitCode::SUCCESS)
    } else {
        eprintln!(
            "{}: FAILED: {} problems",
            file.display(),
            report.problems.len()
        );
        Ok(ExitCode::FAILURE)
    }
}
