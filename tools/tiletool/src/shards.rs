//! `tiletool build --shard K/N` and `tiletool merge`: the recipe that ties a build's parts
//! together, their summaries, and the merge's reopening of the input.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{bail, Result};

use crate::{
    default_band_rows, peak_memory, About, InputArgs, Progress, ReadArgs, StreamHeights,
    TextureArgs,
};

/// The recipe's first line: its own version.
const RECIPE_HEAD: &str = "vkterrain part recipe 1";

/// Bytes read from each end of an input for its fingerprint.
const FINGERPRINT_BYTES: u64 = 1 << 16;

/// What a part was built from, as text: the inputs (each by path, size and a checksum of its
/// first and last 64 KiB), every option that changes the set's bytes, and the tool's version.
/// The parts of one set must hold the same recipe; the merge reads the inputs back from it.
/// The recipe's lines that name the input: the tool's version, each input by canonical
/// path, size and fingerprint, and the options that change how it is read. A shard's scan
/// holds them too.
pub fn input_recipe(input: &InputArgs) -> Result<String> {
    let mut lines = vec![format!("tiletool {}", env!("CARGO_PKG_VERSION"))];
    for path in &input.inputs {
        let canonical =
            std::fs::canonicalize(path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        let (size, crc) = fingerprint(&canonical)?;
        lines.push(format!("input {}\t{size}\t{crc:08x}", canonical.display()));
    }
    let r = &input.read;
    let opt = |v: Option<String>| v.unwrap_or_else(|| "-".into());
    lines.push(format!("spacing {}", opt(r.spacing.map(|v| v.to_string()))));
    lines.push(format!(
        "vertical-scale {}",
        opt(r.vertical_scale.map(|v| v.to_string()))
    ));
    lines.push(format!(
        "size {}",
        opt(r.size.map(|(w, h)| format!("{w}x{h}")))
    ));
    lines.push(format!(
        "encoding {}",
        opt(r.encoding.map(|e| e.to_string()))
    ));
    lines.push(format!("crop {}", opt(r.crop.map(|c| c.to_string()))));
    Ok(lines.join("\n"))
}

pub fn recipe(
    input: &str,
    params: &tiles::BuildParams,
    texture: &TextureArgs,
    compact: bool,
) -> Result<String> {
    let mut lines = vec![RECIPE_HEAD.to_string(), input.to_string()];
    let opt = |v: Option<String>| v.unwrap_or_else(|| "-".into());
    lines.push(format!("levels {}", params.levels));
    lines.push(format!("base-error {}", params.base_error));
    lines.push(format!(
        "sides {}",
        if params.shared_sides {
            "shared"
        } else {
            "independent"
        }
    ));
    lines.push(format!("compact {compact}"));
    let photo = match &texture.texture {
        Some(path) => {
            let canonical = std::fs::canonicalize(path)
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
            let (size, crc) = fingerprint(&canonical)?;
            format!("{}\t{size}\t{crc:08x}", canonical.display())
        }
        None => "-".into(),
    };
    lines.push(format!(
        "texture {photo} no-texture={} texels-per-sample={} sun={},{} tint={}",
        texture.no_texture,
        opt(texture.texels_per_sample.map(|v| v.to_string())),
        texture.sun_azimuth,
        texture.sun_elevation,
        texture.tint
    ));
    Ok(lines.join("\n"))
}

/// A file's size and the crc32 of its first and last [`FINGERPRINT_BYTES`].
fn fingerprint(path: &Path) -> Result<(u64, u32)> {
    use std::io::{Read, Seek, SeekFrom};
    let fail = |e: std::io::Error| anyhow::anyhow!("{}: {e}", path.display());
    let mut file = std::fs::File::open(path).map_err(fail)?;
    let size = file.metadata().map_err(fail)?.len();
    let mut crc = crc32fast::Hasher::new();
    let mut buf = vec![0u8; FINGERPRINT_BYTES.min(size) as usize];
    file.read_exact(&mut buf).map_err(fail)?;
    crc.update(&buf);
    file.seek(SeekFrom::Start(size - buf.len() as u64))
        .map_err(fail)?;
    file.read_exact(&mut buf).map_err(fail)?;
    crc.update(&buf);
    Ok((size, crc.finalize()))
}

/// The input a recipe names, opened to be read a band at a time, as the shards read it, and
/// its texturing (a relief, or none; see [`texture_args`]).
#[allow(clippy::type_complexity)]
fn reopen(
    recipe: &str,
) -> Result<
    (
        Box<dyn tiles::build::Heights>,
        Option<tiles::texture::Texturing>,
    ),
    tiles::BuildError,
> {
    let bad = |what: String| tiles::BuildError::Input(format!("the parts' recipe: {what}"));
    let mut inputs = Vec::new();
    let mut read = ReadArgs::default();
    let mut texture = None;
    let value = |v: &str| (v != "-").then(|| v.to_string());
    for line in recipe.lines() {
        let (key, rest) = line.split_once(' ').unwrap_or((line, ""));
        let parsed = match key {
            "input" => {
                let path = rest.split('\t').next().unwrap_or_default();
                inputs.push(PathBuf::from(path));
                Ok(())
            }
            "spacing" => value(rest)
                .map(|v| v.parse().map(|v| read.spacing = Some(v)))
                .unwrap_or(Ok(()))
                .map_err(|e| e.to_string()),
            "vertical-scale" => value(rest)
                .map(|v| v.parse().map(|v| read.vertical_scale = Some(v)))
                .unwrap_or(Ok(()))
                .map_err(|e| e.to_string()),
            "size" => value(rest)
                .map(|v| dem::parse_size::<usize>(&v).map(|v| read.size = Some(v)))
                .unwrap_or(Ok(()))
                .map_err(|e| e.to_string()),
            "encoding" => value(rest)
                .map(|v| v.parse().map(|v| read.encoding = Some(v)))
                .unwrap_or(Ok(()))
                .map_err(|e| format!("{e:?}")),
            "crop" => value(rest)
                .map(|v| v.parse().map(|v| read.crop = Some(v)))
                .unwrap_or(Ok(()))
                .map_err(|e| format!("{e:?}")),
            "texture" => texture_args(rest).map(|t| texture = t),
            _ => Ok(()),
        };
        parsed.map_err(|e| bad(format!("`{line}`: {e}")))?;
    }
    if inputs.is_empty() {
        return Err(bad("names no input".into()));
    }
    let texturing = match texture {
        Some(t) => t
            .texturing(None)
            .map_err(|e| bad(e.to_string()))?
            .map(|(t, _)| t),
        None => None,
    };
    let stream =
        dem::open(&inputs, &read.options()).map_err(|e| tiles::BuildError::Input(e.to_string()))?;
    let per_band = default_band_rows(stream.width, None);
    Ok((Box::new(StreamHeights { stream, per_band }), texturing))
}

/// The texture options a recipe's `texture` line holds (as [`recipe`] writes it); `None` for
/// a photo, which the merge never needs: the shards make every tile's texture, the
/// pyramid's too, and the seams' tiles are built again without their textures.
fn texture_args(line: &str) -> Result<Option<TextureArgs>, String> {
    let mut fields = line.split(' ');
    if fields.next() != Some("-") {
        return Ok(None);
    }
    let mut t = TextureArgs {
        texture: None,
        no_texture: false,
        texels_per_sample: None,
        sun_azimuth: 315.0,
        sun_elevation: 45.0,
        tint: false,
    };
    for field in fields {
        let bad = || format!("`{field}`");
        let (key, value) = field.split_once('=').ok_or_else(bad)?;
        match key {
            "no-texture" => t.no_texture = value.parse().map_err(|_| bad())?,
            "texels-per-sample" if value == "-" => {}
            "texels-per-sample" => t.texels_per_sample = Some(value.parse().map_err(|_| bad())?),
            "sun" => {
                let (a, e) = value.split_once(',').ok_or_else(bad)?;
                t.sun_azimuth = a.parse().map_err(|_| bad())?;
                t.sun_elevation = e.parse().map_err(|_| bad())?;
            }
            "tint" => t.tint = value.parse().map_err(|_| bad())?,
            _ => return Err(bad()),
        }
    }
    Ok(Some(t))
}

/// What `build --shard` prints: the share built, its agreement and the part.
pub fn print_shard(
    input: &InputArgs,
    output: &Path,
    shard: tiles::shard::Shard,
    summary: &tiles::shard::ShardSummary,
    about: &About,
    took: Duration,
) {
    let s = summary;
    println!(
        "{}  ->  {} (shard {shard})",
        input.names(),
        output.display()
    );
    println!("  source    {}", about.description);
    println!(
        "  share     tile rows {}..{} of the set's, {} tiles of {} x {} samples",
        s.rows.start, s.rows.end, s.tiles, about.width, about.height
    );
    if s.agreement_passes > 0 {
        println!(
            "  sides     agreed over tile rows {}..{}: {} passes ({} tile meshes)",
            s.window.start, s.window.end, s.agreement_passes, s.agreement_meshes
        );
    }
    if s.pyramid_tiles > 0 {
        println!(
            "  pyramid   {} tiles of its layers' rows (the same share of each layer's)",
            s.pyramid_tiles
        );
    }
    let triangles: u64 = s.levels.iter().map(|l| l.triangles).sum();
    let bytes: u64 = s.levels.iter().map(|l| l.bytes).sum();
    println!("  levels    {triangles} triangles, {bytes} bytes of geometry over all levels");
    let secs = took.as_secs_f64();
    let samples = s.tiles as f64 * 256.0 * 256.0;
    println!(
        "  part      {:.1} MB; {secs:.2} s, {:.0} M samples/min of its share{}{}",
        s.part_bytes as f64 / 1e6,
        samples / secs * 60.0 / 1e6,
        bytes_read()
            .map(|b| format!(", input read {:.1} MB", b as f64 / 1e6))
            .unwrap_or_default(),
        peak_memory()
            .map(|m| format!(", peak memory {:.0} MB", m as f64 / 1e6))
            .unwrap_or_default()
    );
}

/// Bytes this process has read with read(2) and its kin (`rchar` of /proc/self/io): the
/// input, for a shard (it maps nothing of it).
fn bytes_read() -> Option<u64> {
    let io = std::fs::read_to_string("/proc/self/io").ok()?;
    io.lines()
        .find_map(|l| l.strip_prefix("rchar:"))
        .and_then(|v| v.trim().parse().ok())
}

/// `tiletool merge`: the parts joined into the set, with a summary.
pub fn merge(parts: &[PathBuf], output: &Path, quiet: bool) -> Result<ExitCode> {
    if output.is_dir() {
        bail!("{}: is a folder, not an output file", output.display());
    }
    let start = Instant::now();
    let bar = Progress::new(
        None,
        "{elapsed_precise} [{bar:40}] {pos} tiles merged",
        quiet,
    );
    let progress = || bar.tick();
    let summary = tiles::shard::merge(parts, output, &reopen, &progress)?;
    bar.bar.finish_and_clear();
    if !quiet {
        let s = &summary;
        println!("{} parts  ->  {}", s.parts, output.display());
        println!("  tiles     {} from {} parts", s.tiles, s.parts);
        println!("  level     e_i (m)   max err (m)     vertices    triangles");
        let set = tiles::TileSet::open(output)?;
        for (i, l) in s.levels.iter().enumerate() {
            println!(
                "  {i:>5} {:>11} {:>13.3} {:>12} {:>12}",
                set.level_error(i as u32),
                l.max_error,
                l.vertices,
                l.triangles
            );
        }
        if s.unsettled == 0 {
            println!("  seams     settled by the shards' halos");
        } else {
            println!(
                "  seams     {} tiles unsettled: {} meshes to settle them, {} tiles built again from the input",
                s.unsettled, s.remeshed, s.rebuilt
            );
        }
        if s.pyramid_tiles > 0 {
            println!(
                "  pyramid   {} tiles of its layers, as the shards built them",
                s.pyramid_tiles
            );
            if s.pyramid_unsettled > 0 {
                println!(
                    "            {} layer tiles unsettled: {} meshes to settle them, {} layer tiles built again from the input",
                    s.pyramid_unsettled, s.pyramid_remeshed, s.pyramid_rebuilt
                );
            }
            if s.pyramid_resealed > 0 {
                println!(
                    "            {} layer tiles sealed again at their layer's morph units",
                    s.pyramid_resealed
                );
            }
        }
        if s.resealed > 0 {
            println!(
                "  units     {} tiles sealed again at the set's morph units",
                s.resealed
            );
        }
        println!(
            "  file      {:.1} MB; {:.2} s{}",
            s.file_bytes as f64 / 1e6,
            start.elapsed().as_secs_f64(),
            peak_memory()
                .map(|m| format!(", peak memory {:.0} MB", m as f64 / 1e6))
                .unwrap_or_default()
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// `tiletool build --shard K/N --scan-only`: shard K's rows of the input read and checked, and what the
/// build needs of them written to `output` (temporary file, then rename): their range, tile
/// ranges and voids, the void fill's share of the pass over the grid, and, with no void, its
/// rows of each pyramid layer the set would have with `--pyramid` (a shard given every scan
/// then reads no layer whole).
pub fn scan(input: &InputArgs, shard: tiles::shard::Shard, output: &Path) -> Result<ExitCode> {
    let opts = input.read.options();
    let stream = dem::open_unscanned(&input.inputs, &opts, (0.0, 0.0))?;
    let dims = (stream.width, stream.height);
    let rows = tiles::shard::scan_rows(shard, dims)?;
    let pull = tiles::shard::pull_rows(shard, dims)?;
    let read = dem::scan_rows(&input.inputs, &opts, rows, pull)?;
    let per_band = default_band_rows(stream.width, Some((shard, stream.height)));
    let heights = StreamHeights { stream, per_band };
    let ranges = tiles::shard::tile_ranges(&heights, shard)?;
    let layers = match read.voids {
        0 => Some(tiles::shard::layer_scans(&heights, shard)?),
        _ => None,
    };
    let found = tiles::shard::ShardScan {
        lo: read.lo,
        hi: read.hi,
        max_range: ranges.max_range,
        max_abs: ranges.max_abs,
        spans: ranges.spans,
        voids: read.voids,
        fill: read.pulled.map(|p| p.to_line()),
        layers,
    };
    let text = found.to_text(shard, &input_recipe(input)?);
    tiles::format::write_atomically(output, text.as_bytes())
        .map_err(|e| anyhow::anyhow!("{}: {e}", output.display()))?;
    Ok(ExitCode::SUCCESS)
}

/// `tiletool build --shard K/N --scans DIR --ranges-only`: the second stage of a scanned build
/// of an input with voids. Shard K's rows are read with the margin their voids need and
/// filled with the plan joined from every shard's scan, and the largest tile range and
/// absolute height of the filled rows go to `output` (by convention
/// DIR/ranges-K-of-N.vktranges). With no void the scan's own figures are those of the filled
/// grid, and no row is read.
pub fn ranges(
    input: &InputArgs,
    shard: tiles::shard::Shard,
    dir: &Path,
    output: &Path,
) -> Result<ExitCode> {
    let ours = input_recipe(input)?;
    let found = read_scans(&ours, shard, dir)?;
    let scans = tiles::shard::Scans::join(&found).expect("at least one shard");
    let own = &found[shard.index as usize];
    let stream = dem::open_unscanned(&input.inputs, &input.read.options(), (scans.lo, scans.hi))?;
    let figures = match fill_plan(input, &found, dir, (stream.width, stream.height))? {
        None => tiles::shard::ShardRanges {
            max_range: own.max_range,
            max_abs: own.max_abs,
            spans: own.spans,
        },
        Some(plan) => {
            let per_band = default_band_rows(stream.width, Some((shard, stream.height)));
            let stream = stream.with_plan(plan);
            let heights = StreamHeights { stream, per_band };
            tiles::shard::tile_ranges(&heights, shard)?
        }
    };
    tiles::format::write_atomically(output, figures.to_text(shard, &ours).as_bytes())
        .map_err(|e| anyhow::anyhow!("{}: {e}", output.display()))?;
    Ok(ExitCode::SUCCESS)
}

/// A shard record's text read back: its shard, the record, the input's recipe.
type ParseRecord<T> = fn(&str) -> Result<(tiles::shard::Shard, T, String), String>;

/// Every shard's record of one kind from `dir` (`{kind}-K-of-N.{ext}`, read by `parse`), in
/// shard order, each checked to be that shard's and of this input (`ours`); a missing one
/// names the command that makes it (`makes`, given K).
fn read_records<T>(
    ours: &str,
    shard: tiles::shard::Shard,
    dir: &Path,
    (kind, ext): (&str, &str),
    parse: ParseRecord<T>,
    makes: &dyn Fn(u32) -> String,
) -> Result<Vec<T>> {
    (0..shard.count)
        .map(|k| {
            let path = dir.join(format!("{kind}-{k}-of-{}.{ext}", shard.count));
            let text = std::fs::read_to_string(&path)
                .map_err(|e| anyhow::anyhow!("{}: {e} ({})", path.display(), makes(k)))?;
            let (theirs, record, recipe) =
                parse(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
            if (theirs.index, theirs.count) != (k, shard.count) {
                bail!("{}: holds the {kind} of shard {theirs}", path.display());
            }
            if recipe != ours {
                bail!(
                    "{}: the {kind} of other inputs or read options",
                    path.display()
                );
            }
            Ok(record)
        })
        .collect()
}

/// Every shard's scan from `dir` (`scan-K-of-N.vktscan`), in shard order.
fn read_scans(
    ours: &str,
    shard: tiles::shard::Shard,
    dir: &Path,
) -> Result<Vec<tiles::shard::ShardScan>> {
    let makes = |k: u32| {
        format!(
            "run `tiletool build ... --shard {k}/{} --scan-only` first",
            shard.count
        )
    };
    let parse = tiles::shard::ShardScan::from_text;
    read_records(ours, shard, dir, ("scan", "vktscan"), parse, &makes)
}

/// The void fill's plan of the `width` x `height` grid joined from every shard's share of the
/// pass (`dem::Plan::join`), or `None` when there is nothing to plan: no void, or an input
/// decoded whole (a picture), whose scans each filled the whole grid already.
fn fill_plan(
    input: &InputArgs,
    found: &[tiles::shard::ShardScan],
    dir: &Path,
    (width, height): (usize, usize),
) -> Result<Option<dem::Plan>> {
    if found.iter().all(|s| s.voids == 0) || found.iter().any(|s| s.fill.is_none()) {
        return Ok(None);
    }
    let shares = found
        .iter()
        .enumerate()
        .map(|(k, s)| {
            dem::Pulled::from_line(s.fill.as_deref().unwrap_or_default()).map_err(|e| {
                let path = dir.join(format!("scan-{k}-of-{}.vktscan", found.len()));
                anyhow::anyhow!("{}: {e}", path.display())
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let plan = dem::Plan::join(width, height, dem::STORED, &shares)
        .map_err(|e| anyhow::anyhow!("{}: the scans do not make one pass: {e}", dir.display()))?;
    match plan {
        Some(plan) => Ok(Some(plan)),
        None => bail!(
            "{}: every sample of the input is a void",
            input.inputs[0].display()
        ),
    }
}

/// The grid as a shard given every shard's scan in `dir` reads it (its rows, with the margin
/// their voids need, filled as the whole grid is), and the whole grid's figures. An input with
/// voids needs every shard's ranges too (`--ranges-only`, [`ranges`]).
pub fn scanned_stream(
    input: &InputArgs,
    ours: &str,
    shard: tiles::shard::Shard,
    dir: &Path,
) -> Result<(dem::Stream, tiles::shard::Scans)> {
    let found = read_scans(ours, shard, dir)?;
    let scans = tiles::shard::Scans::join(&found).expect("at least one shard");
    let stream = dem::open_unscanned(&input.inputs, &input.read.options(), (scans.lo, scans.hi))?;
    let Some(plan) = fill_plan(input, &found, dir, (stream.width, stream.height))? else {
        return Ok((stream, scans));
    };
    let makes = |k: u32| {
        format!(
            "the input has voids: run `tiletool build ... --shard {k}/{} --scans {} --ranges-only` first",
            shard.count,
            dir.display()
        )
    };
    let parse = tiles::shard::ShardRanges::from_text;
    let ranges = read_records(ours, shard, dir, ("ranges", "vktranges"), parse, &makes)?;
    Ok((stream.with_plan(plan), scans.filled(&ranges)))
}
