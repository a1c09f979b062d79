//! Distributed builds (issue 29): [`build_shard`] builds a share of a set's tiles into a
//! part file, and [`merge`] joins the parts into the set that [`crate::build`] makes of the
//! same input and options, byte for byte.
//!
//! # What is global, and how each piece of it is settled
//!
//! A tile's bytes depend on more than its own samples:
//!
//! - **The height range, the height lattice's step and the cell spans** (the morph units'
//!   bounds, below), from a scan of the whole grid. A shard scans the whole input, as the
//!   build does, unless it is given every shard's scan ([`ShardScan`], `tiletool build
//!   --shard K/N --scan-only`, which reads only shard K's rows): their extremes are the whole
//!   grid's, so the step and the spans are the same.
//! - **The void fill**, which is global (`dem::banded`): the reader's open plans it, as for a
//!   build. With scans, each scan carries its rows' share of the plan's pass ([`pull_rows`]),
//!   and the shares join into the pass's plan. A fill changes the tiles' ranges, so a grid
//!   with voids takes a second stage ([`ShardRanges`], `--ranges-only`): each shard fills its
//!   rows with the joined plan and ranges their tiles. The build then reads only its rows,
//!   with the margin their fill needs.
//! - **The shared sides.** The build's agreement ([`crate::build`]) settles the least fixed
//!   point of "a tile's sides are those of its mesh with its own and its neighbours' sides
//!   forced": meshing is monotone in what is forced, and the passes climb to that point from
//!   nothing. A shard runs the same passes over its tile rows and `halo` rows either side,
//!   the tiles beyond taken as absent. With fewer neighbours it forces less, so its state is
//!   below the global fixed point (Knaster-Tarski: the global point, restricted to the
//!   window, is a pre-fixed point of the shard's operator, and the shard's least fixed point
//!   lies below every pre-fixed point). The merge puts the owners' states together and checks
//!   that every tile was meshed with the sides its neighbours now hold. Where that holds
//!   everywhere, the state is a fixed point below the least one, so it is the least one: the
//!   build's. Where it does not (a cascade longer than the halo), the merge resumes the passes
//!   from that state, reading the input again, and climbs to the same point
//!   ([`crate::build::settle`]); the tiles whose forced sides changed are built again there.
//! - **The morph units**: per level, a bound from the scan ([`crate::units`]), the same in
//!   every shard, raised where a tile's final build finds a deviation past it. A shard seals
//!   its tiles at the bounds' units (offsets clamped where a deviation passes them) and
//!   records its tiles' final deviations, the bounds and the units; where the set's units
//!   come out larger, the merge seals those tiles again from their own vertices
//!   ([`crate::build::rebuild_tile`], which makes the build's bytes from a tile's vertex
//!   sets; a compact tile keeps its stream, [`reseal_compact_tile`]).
//!
//! The tile pyramid (`--pyramid`) is built on the shards, each its rows of every layer
//! ([`Shard::rows`] of the layer's tile rows), the same way: a layer's shared sides and
//! morph units are settled as the base grid's are (the units from a bound every shard finds
//! from the scans, [`crate::units::layer_deviation_bounds`], raised where a tile passes it), and
//! what else a layer tile depends on beyond its samples (the layer's range and step, its
//! decimation error from its children's, its errors against the base grid) each shard
//! finds for itself (`ShardLayers::build` says how). The merge then copies the layers as it
//! does the base grid.
//!
//! # The part file
//!
//! Little-endian: `PART_MAGIC`, the part format's version, the shard's index and count and
//! its halo, the recipe (the inputs and options, as text: parts of one set must hold the
//! same), the set's header as the writer is given it, the owned tile rows, the units its
//! blobs were sealed with and the bounds under them (from the scan, [`crate::units`]), the
//! agreement's passes and meshes, then per owned tile (row-major)
//! its forced sides and sides (bitmaps), its final build's deviations, its blob (with compact levels, the
//! bytes the set stores, [`compact_tile`]: compacted on the shard, copied by the merge) and
//! its texture; then the number of pyramid layers (0 without a pyramid) and per layer its
//! index, owned rows (possibly none) and tile counts, its scan's lattice step and range, its
//! units and the bounds under them, passes and meshes, and per owned tile the same record with its agreement's
//! deviations, its decimation error and its levels' errors against the base grid before the
//! blob; last, the crc32 of everything before it and `END_MAGIC`. It is written to a
//! temporary file and renamed when complete, so a shard killed at any point leaves no part
//! that reads as whole. Version 5; version 4 parts held no layer bounds (a layer's units
//! followed its tiles' deviations), version 3 no layers (the merge built them), version 2 no
//! bounds and version 1 version 3 blobs, and all are refused.

use std::io::{BufWriter, Write};
use std::ops::Range;
use std::path::{Path, PathBuf};

use crate::build::{
    build_tiles, forced_sides, scan, set_header, settle, units_of, validate, Bands, BuildParams,
    BuiltTile, CompactSides, Heights, Layer, LevelStats, Remesh, Scanned, SideBits, Start,
    TileSetMeta,
};
use crate::format::{
    compact_tile, layer_layout, reseal_compact_tile, stored_tile_table, temp_path, tile_count,
    FileHeader, LayerHeader, Tile, TileSetWriter, FLAG_COMPACT_LEVELS, FLAG_SHARED_SIDES,
};
use crate::pyramid::{decimation_errors, Decimated};
use crate::texture::{self, Prepared, Texturing};
use crate::units::{cell_spans, deviation_bounds, CellSpans, LayerBounds, CELL_SIZES};
use crate::BuildError;

/// The first bytes of a part file.
pub const PART_MAGIC: [u8; 8] = *b"VKTPART\0";
/// Its last bytes, after the checksum.
const END_MAGIC: [u8; 8] = *b"VKTPEND\0";
/// Where a part's blobs start: a multiple of this many bytes from the file's start.
const ALIGN: usize = 16;
/// The part format's version.
pub const PART_VERSION: u32 = 5;
/// Tile rows beyond its own that a shard settles the sides over, by default. On the sets
/// measured (bench/README.md, "Distributed builds") one row already left no seam to settle
/// again in the merge; two give margin for longer cascades at the cost of about `4 / rows`
/// more agreement meshes per shard.
pub const DEFAULT_HALO: u32 = 2;

/// Shard `index` of `count`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: u32,
    pub count: u32,
}

impl std::str::FromStr for Shard {
    type Err = String;

    /// `K/N`, with `0 <= K < N`.
    fn from_str(s: &str) -> Result<Shard, String> {
        let bad = || format!("--shard {s}: expected K/N with 0 <= K < N, e.g. 3/8");
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count) = (
            k.trim().parse().map_err(|_| bad())?,
            n.trim().parse().map_err(|_| bad())?,
        );
        if index >= count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl Shard {
    /// The tile rows this shard builds: `N` bands of whole tile rows, as even as rows allow.
    pub fn rows(&self, tiles_y: u32) -> Range<u32> {
        let at = |k: u32| (u64::from(tiles_y) * u64::from(k) / u64::from(self.count)) as u32;
        at(self.index)..at(self.index + 1)
    }

    /// [`rows`](Self::rows), refused when the set has fewer tile rows than shards (some would
    /// have none).
    pub fn rows_of(&self, tiles_y: u32) -> Result<Range<u32>, BuildError> {
        if self.count > tiles_y {
            return Err(BuildError::Params(format!(
                "--shard {self}: the set has {tiles_y} tile rows, so at most {tiles_y} shards"
            )));
        }
        Ok(self.rows(tiles_y))
    }
}

/// What a shard built.
#[derive(Clone, Debug, Default)]
pub struct ShardSummary {
    /// The tile rows it built, and those its agreement covered.
    pub rows: Range<u32>,
    pub window: Range<u32>,
    pub tiles_x: u32,
    pub tiles: u64,
    pub levels: Vec<LevelStats>,
    pub agreement_passes: u32,
    pub agreement_meshes: u64,
    /// Tiles of the pyramid's layers it built.
    pub pyramid_tiles: u64,
    pub part_bytes: u64,
}

/// Builds shard `shard`'s tiles of the set that [`crate::build::build_tileset_from`] would
/// build of `heights`, into the part file `out`. `recipe` names the inputs and options (the
/// merge refuses parts whose recipes differ). `known`: the whole grid's range and lattice
/// step from every shard's scan ([`ShardScan`]), so that the shard reads only its rows; the
/// caller checked that the grid holds no void. Without it the shard reads the whole grid.
#[allow(clippy::too_many_arguments)]
pub fn build_shard(
    heights: &dyn Heights,
    params: &BuildParams,
    texturing: Option<&Texturing>,
    meta: &TileSetMeta,
    (shard, halo): (Shard, u32),
    known: Option<&Scans>,
    recipe: &str,
    out: &Path,
    progress: &(dyn Fn() + Sync),
) -> Result<ShardSummary, BuildError> {
    validate(params, texturing)?;
    let shape = heights.shape();
    let (tiles_x, tiles_y) = tile_count(shape.width, shape.height).map_err(BuildError::Params)?;
    let rows = shard.rows_of(tiles_y)?;
    // The whole grid's range and lattice step: from the shards' scans, or read here.
    let scanned = match known {
        Some(scans) => scans.scanned(),
        None => scan(&Bands::new(heights, (tiles_x, tiles_y)))?,
    };
    let header = set_header(&shape, params, texturing, meta, &scanned)?;
    let spacing = shape.spacing_x.min(shape.spacing_y);
    let bounds = deviation_bounds(params, spacing, scanned.step, &scanned.spans);
    let window = rows.start.saturating_sub(halo)..(rows.end + halo).min(tiles_y);
    // The agreement reads the window's rows, the build the shard's own: no band holds more.
    let (around, own) = (
        Bands::within(heights, (tiles_x, tiles_y), window.clone()),
        Bands::within(heights, (tiles_x, tiles_y), rows.clone()),
    );
    let agreed = if params.shared_sides {
        let mut agreed = settle(
            &around,
            params,
            scanned.step,
            None,
            Remesh::Changed,
            window.clone(),
            None,
        )?;
        // Sealed at the scan's bounds' units (the agreement's meshes of the base grid find no
        // deviations): the merge seals again where a tile's final build passed them.
        let own = (rows.start - window.start) as usize * tiles_x as usize;
        let count = rows.len() * tiles_x as usize;
        agreed.units = units_of(&bounds, &agreed.deviation[own..own + count]);
        Some(agreed)
    } else {
        None
    };
    let prepared =
        texturing.map(|t| (Prepared::new((scanned.lo, scanned.hi), &t.source), t.layout));
    drop(around);
    let layer = Layer {
        index: 0,
        bands: &own,
        step: scanned.step,
        bounds: bounds.clone(),
        decimation: None,
        prepared: prepared.as_ref().map(|(p, l)| (p.for_layer(0), *l)),
        base: None,
    };
    let mut part = PartWriter::create(out)?;
    part.put(&PART_MAGIC)?;
    for v in [PART_VERSION, shard.index, shard.count, halo] {
        part.u32(v)?;
    }
    part.u32(recipe.len() as u32)?;
    part.put(recipe.as_bytes())?;
    part.put(bytemuck::bytes_of(&header))?;
    for v in [rows.start, rows.end, tiles_x, params.levels] {
        part.u32(v)?;
    }
    let units = agreed.as_ref().map(|a| a.units.clone()).unwrap_or_default();
    for level in 0..params.levels as usize {
        part.f64(units.get(level).copied().unwrap_or(0.0))?;
    }
    for &b in &bounds {
        part.f64(b)?;
    }
    part.u32(agreed.as_ref().map_or(0, |a| a.passes))?;
    part.u64(agreed.as_ref().map_or(0, |a| a.meshes))?;
    let mut summary = ShardSummary {
        rows: rows.clone(),
        window,
        tiles_x,
        levels: vec![LevelStats::default(); params.levels as usize],
        agreement_passes: agreed.as_ref().map_or(0, |a| a.passes),
        agreement_meshes: agreed.as_ref().map_or(0, |a| a.meshes),
        ..ShardSummary::default()
    };
    let none = vec![[[0u64; 5]; 4]; params.levels as usize];
    let compact = header.flags & FLAG_COMPACT_LEVELS != 0;
    build_tiles(
        &layer,
        params,
        agreed.as_ref(),
        rows,
        &mut |t, (built, texture), _| {
            let (forced, sides) = match &agreed {
                Some(a) => (&a.forced[t - a.first], &a.sides[t - a.first]),
                None => (&none, &none),
            };
            // The final build's deviations (the agreement's meshes find none: the units
            // come from the scan): the merge raises the set's units where one passes them.
            part.sides_and_deviation(forced, sides, &built.deviation)?;
            let xy = (0, built.tx, built.ty);
            let compact = compact.then_some((params.levels, scanned.step));
            let tex = texture.map(|(blob, _, _)| blob).unwrap_or_default();
            part.blobs(&built.blob, xy, compact, &tex)?;
            summary.tiles += 1;
            for (sum, l) in summary.levels.iter_mut().zip(&built.levels) {
                sum.vertices += l.vertices;
                sum.triangles += l.triangles;
                sum.bytes += l.bytes;
                sum.max_error = sum.max_error.max(l.max_error);
                sum.limited_triangles += l.limited_triangles;
                sum.limited_excess = sum.limited_excess.max(l.limited_excess);
            }
            progress();
            Ok(())
        },
    )?;
    // The pyramid's layers (none without one).
    let layers = layers_of(&header).map_err(BuildError::Internal)?;
    let mut into = ShardLayers {
        part: &mut part,
        summary: &mut summary,
        progress,
    };
    let prepared = prepared.as_ref();
    into.build(
        heights,
        params,
        (&header, &scanned),
        &layers,
        (prepared, known),
        (shard, halo),
    )?;
    summary.part_bytes = part.finish()?;
    Ok(summary)
}

/// Where a shard writes its share of the pyramid's layers.
struct ShardLayers<'a, 'p> {
    part: &'a mut PartWriter,
    summary: &'a mut ShardSummary,
    progress: &'p (dyn Fn() + Sync),
}

/// The pyramid's layers of the set whose header (as the writer is given it, its version not
/// set yet) is `header`.
fn layers_of(header: &FileHeader) -> Result<Vec<LayerHeader>, String> {
    let versioned = FileHeader {
        version: crate::format::VERSION,
        ..*header
    };
    Ok(layer_layout(&versioned)?.0)
}

/// The hull of two tile row ranges, an empty one adding nothing.
fn hull(a: &Range<u32>, b: &Range<u32>) -> Range<u32> {
    match (a.is_empty(), b.is_empty()) {
        (true, _) => b.clone(),
        (_, true) => a.clone(),
        _ => a.start.min(b.start)..a.end.max(b.end),
    }
}

impl ShardLayers<'_, '_> {
    /// Builds the shard's tile rows of each pyramid layer into the part, after its base tiles:
    /// in layer `p` of `T` tile rows, the rows that [`Shard::rows`] gives it of `T` (none
    /// where `T` is below the shard count), so that every shard builds about its share of
    /// each layer. What a layer tile depends on beyond its own samples, and where it comes
    /// from:
    ///
    /// - **The layer's range and lattice step**: from every shard's scan of its rows of the
    ///   layer ([`layer_scans`]) where they are given (`known`) and the grid has no void;
    ///   else a scan of the whole layer, as the build's (every `2^p`-th row of the input,
    ///   read alone where the source reads rows singly, else in runs of every row:
    ///   [`Decimated`]).
    /// - **Its decimation error**, from its children's in the layer below
    ///   ([`decimation_errors`]): measured here for the rows the shard's own and those of
    ///   its layers above need, from the bottom up, so it reads only the rows under them.
    /// - **Its shared sides**: settled over its rows and `halo` more either side, as the base
    ///   grid's; the merge checks for the fixed point and resumes where a halo fell short.
    /// - **Its morph units**: from the layer's bounds, which follow from the scans of the layers
    ///   below and its own ([`crate::units::layer_deviation_bounds`]), the same on every shard;
    ///   the part records them, each tile's deviations and the units it sealed with, and the
    ///   merge seals again only where a tile's deviation passed the bounds.
    /// - **Its errors against the base grid** ([`crate::pyramid::base_errors`]): the base
    ///   rows under its own tile row.
    fn build(
        &mut self,
        heights: &dyn Heights,
        params: &BuildParams,
        (header, base): (&FileHeader, &Scanned),
        layers: &[LayerHeader],
        (prepared, known): (Option<&(Prepared, texture::Layout)>, Option<&Scans>),
        (shard, halo): (Shard, u32),
    ) -> Result<(), BuildError> {
        self.part.u32(layers.len() as u32)?;
        let own = |l: &LayerHeader| shard.rows(l.tiles_y);
        let windows: Vec<Range<u32>> = layers
            .iter()
            .map(|l| match own(l) {
                rows if rows.is_empty() || !params.shared_sides => rows,
                rows => rows.start.saturating_sub(halo)..(rows.end + halo).min(l.tiles_y),
            })
            .collect();
        // The rows whose decimation errors are needed: each layer's window, and the children
        // of those needed in the layer above.
        let mut needed = windows.clone();
        for i in (0..layers.len().saturating_sub(1)).rev() {
            let (above, rows) = (&needed[i + 1], layers[i].tiles_y);
            let children = (2 * above.start).min(rows)..(2 * above.end).min(rows);
            needed[i] = hull(&needed[i], &children);
        }
        let mut below = vec![0.0f32; (header.tiles_x * header.tiles_y) as usize];
        let mut below_tiles_x = header.tiles_x;
        let mut layer_bounds = LayerBounds::above(base);
        for (i, l) in layers.iter().enumerate() {
            let p = i as u32 + 1;
            let tiles = (l.tiles_x, l.tiles_y);
            let layer_heights = Decimated::new(heights, p);
            let finer_layer = Decimated::new(heights, p - 1);
            let finer: &dyn Heights = if p == 1 { heights } else { &finer_layer };
            let decimation =
                decimation_errors(finer, &below, below_tiles_x, tiles, needed[i].clone())?;
            let scanned = match known.and_then(|k| k.layer_scanned(p)) {
                Some(scanned) => scanned,
                None => scan(&Bands::new(&layer_heights, tiles))?,
            };
            let rows = own(l);
            let bounds = layer_bounds.next(params, &layer_heights, &scanned);
            let agreed = match params.shared_sides && !rows.is_empty() {
                true => {
                    let window = windows[i].clone();
                    let around = Bands::within(&layer_heights, tiles, window.clone());
                    let (step, floors) = (scanned.step, Some(&decimation[..]));
                    let mut agreed =
                        settle(&around, params, step, floors, Remesh::Changed, window, None)?;
                    let from = (rows.start - windows[i].start) as usize * l.tiles_x as usize;
                    let count = rows.len() * l.tiles_x as usize;
                    agreed.units = units_of(&bounds, &agreed.deviation[from..from + count]);
                    Some(agreed)
                }
                false => None,
            };
            for v in [p, rows.start, rows.end, l.tiles_x, l.tiles_y] {
                self.part.u32(v)?;
            }
            for v in [scanned.step, scanned.lo, scanned.hi] {
                self.part.f32(v)?;
            }
            let units = agreed.as_ref().map(|a| a.units.clone()).unwrap_or_default();
            for level in 0..params.levels as usize {
                self.part.f64(units.get(level).copied().unwrap_or(0.0))?;
            }
            for &b in &bounds {
                self.part.f64(b)?;
            }
            self.part.u32(agreed.as_ref().map_or(0, |a| a.passes))?;
            self.part.u64(agreed.as_ref().map_or(0, |a| a.meshes))?;
            let layer = Layer {
                index: p,
                bands: &Bands::within(&layer_heights, tiles, rows.clone()),
                step: scanned.step,
                bounds,
                decimation: Some(&decimation),
                prepared: prepared.map(|(s, l)| (s.for_layer(p), *l)),
                base: Some(heights),
            };
            let compact = header.flags & FLAG_COMPACT_LEVELS != 0;
            let none = vec![[[0u64; 5]; 4]; params.levels as usize];
            let (part, summary, progress) = (&mut *self.part, &mut *self.summary, self.progress);
            build_tiles(
                &layer,
                params,
                agreed.as_ref(),
                rows,
                &mut |t, (built, texture), errors| {
                    // The agreement's deviations: the layer's units are the set's largest.
                    let (forced, sides, deviation) = match &agreed {
                        Some(a) => {
                            let k = t - a.first;
                            (&a.forced[k], &a.sides[k], &a.deviation[k])
                        }
                        None => (&none, &none, &built.deviation),
                    };
                    part.sides_and_deviation(forced, sides, deviation)?;
                    part.f32(decimation[t])?;
                    for &e in errors {
                        part.f32(e)?;
                    }
                    let xy = (p, built.tx, built.ty);
                    let compact = compact.then_some((params.levels, scanned.step));
                    let tex = texture.map(|(blob, _, _)| blob).unwrap_or_default();
                    part.blobs(&built.blob, xy, compact, &tex)?;
                    summary.pyramid_tiles += 1;
                    progress();
                    Ok(())
                },
            )?;
            (below, below_tiles_x) = (decimation, l.tiles_x);
        }
        Ok(())
    }
}

/// What a shard's scan found of its tile rows (`tiletool build --shard K/N --scan-only`): the range of
/// heights, what the lattice step depends on ([`crate::quantise::lattice_step`]: the
/// largest tile range and absolute height) and the voids, and the void fill's share of the
/// pass over the grid (`fill`: `dem::Pulled` as a line of text, from the rows
/// [`pull_rows`]; `None` for inputs decoded whole). Every shard's together stand for the
/// build's pass over the whole grid: with no void, for all of it; with voids, their ranges
/// are those of the grid before its fill, so a second stage reads them again filled
/// ([`ShardRanges`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ShardScan {
    pub lo: f32,
    pub hi: f32,
    pub max_range: f32,
    pub max_abs: f32,
    /// The cell spans of its tile rows ([`crate::units`]).
    pub spans: CellSpans,
    pub voids: u64,
    pub fill: Option<String>,
    /// Its rows of each pyramid layer the grid would have ([`layer_scans`]); `None` for a
    /// grid with voids, whose layers' figures are those of the grid filled.
    pub layers: Option<Vec<LayerScan>>,
}

/// What a shard's scan found of its tile rows of one pyramid layer ([`Shard::rows`] of the
/// layer's): its range of heights, its largest absolute height and its cell spans, which
/// give the layer's lattice step once every shard's are joined.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LayerScan {
    pub lo: f32,
    pub hi: f32,
    pub max_abs: f32,
    pub spans: CellSpans,
}

/// The first line of a scan file, with its version; its first bytes are [`SCAN_MAGIC`].
/// Version 1 held no fill, version 2 no cell spans, version 3 no layers.
const SCAN_HEAD: &str = "VKTSCAN1 vkterrain shard scan, version 4";
/// The first bytes of a scan file.
pub const SCAN_MAGIC: [u8; 8] = *b"VKTSCAN1";

/// What a shard's tile rows hold once the grid's voids are filled (`tiletool build --shard
/// K/N --scans DIR --ranges-only`): the largest tile range and absolute height, which every
/// shard's scan gives for a grid with no void. The second stage of a scanned build of an
/// input with voids.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShardRanges {
    pub max_range: f32,
    pub max_abs: f32,
    pub spans: CellSpans,
}

/// The first line of a ranges file; its first bytes are [`RANGES_MAGIC`].
/// Version 1 held no cell spans.
const RANGES_HEAD: &str = "VKTRANGE vkterrain shard ranges, version 2";
/// The first bytes of a ranges file.
pub const RANGES_MAGIC: [u8; 8] = *b"VKTRANGE";

/// A scan or ranges file: its first line, the shard, `name value` fields, then the input's
/// recipe; a crc32 line guards them all.
fn record_text(head: &str, shard: Shard, fields: &[(&str, String)], recipe: &str) -> String {
    let mut body = format!("{head}\nshard {shard}\n");
    for (name, value) in fields {
        body.push_str(&format!("{name} {value}\n"));
    }
    body.push_str(recipe);
    body.push('\n');
    format!("{body}crc {:08x}\n", crc32fast::hash(body.as_bytes()))
}

/// [`record_text`] read back, its fields `names` in order: the shard, their values, the recipe.
fn record_fields(
    text: &str,
    head: &str,
    names: &[&str],
) -> Result<(Shard, Vec<String>, String), String> {
    let (body, crc) = text
        .trim_end_matches('\n')
        .rsplit_once("\ncrc ")
        .ok_or("not a shard record (no crc line)")?;
    let body = format!("{body}\n");
    let stored = u32::from_str_radix(crc.trim(), 16).map_err(|_| "a bad crc line")?;
    if crc32fast::hash(body.as_bytes()) != stored {
        return Err("damaged: its checksum does not match".into());
    }
    let mut lines = body.lines();
    if lines.next() != Some(head) {
        return Err(format!("not a file of this version ({head})"));
    }
    let mut field = |name: &str| -> Result<String, String> {
        let line = lines.next().unwrap_or_default();
        line.strip_prefix(name)
            .and_then(|v| v.strip_prefix(' '))
            .map(str::to_string)
            .ok_or_else(|| {
                let start: String = line.chars().take(40).collect();
                format!("expected `{name}`, found `{start}`")
            })
    };
    let shard: Shard = field("shard")?.parse()?;
    let values = names
        .iter()
        .map(|n| field(n))
        .collect::<Result<Vec<_>, _>>()?;
    let recipe: Vec<&str> = lines.collect();
    Ok((shard, values, recipe.join("\n")))
}

/// A height as the 8 hex digits of its bits, so that it reads back exact.
fn height_text(h: f32) -> String {
    format!("{:08x}", h.to_bits())
}

fn height_of(v: &str) -> Result<f32, String> {
    u32::from_str_radix(v, 16)
        .map(f32::from_bits)
        .map_err(|_| format!("a bad height `{v}`"))
}

/// Layer scans as `lo/hi/max-abs/spans` joined by `;` (`-` for none; empty for a grid with no
/// layer above it).
fn layers_text(layers: Option<&[LayerScan]>) -> String {
    let Some(layers) = layers else {
        return "-".into();
    };
    let one = |l: &LayerScan| {
        let figures = [l.lo, l.hi, l.max_abs].map(height_text).join("/");
        format!("{figures}/{}", spans_text(&l.spans))
    };
    layers.iter().map(one).collect::<Vec<_>>().join(";")
}

fn layers_of_text(v: &str) -> Result<Option<Vec<LayerScan>>, String> {
    if v == "-" {
        return Ok(None);
    }
    if v.is_empty() {
        return Ok(Some(Vec::new()));
    }
    let one = |l: &str| -> Result<LayerScan, String> {
        let f: Vec<&str> = l.split('/').collect();
        let [lo, hi, max_abs, spans] = f[..] else {
            return Err(format!("a bad layer scan `{l}`"));
        };
        Ok(LayerScan {
            lo: height_of(lo)?,
            hi: height_of(hi)?,
            max_abs: height_of(max_abs)?,
            spans: spans_of(spans)?,
        })
    };
    v.split(';').map(one).collect::<Result<_, _>>().map(Some)
}

/// Cell spans as heights ([`height_text`]) joined by commas.
fn spans_text(spans: &CellSpans) -> String {
    spans.map(height_text).join(",")
}

fn spans_of(v: &str) -> Result<CellSpans, String> {
    let spans: Vec<f32> = v.split(',').map(height_of).collect::<Result<_, _>>()?;
    spans
        .try_into()
        .map_err(|_| format!("not {CELL_SIZES} cell spans"))
}

impl ShardScan {
    /// The scan file: its figures, the fill's share (`-` for none), the input's recipe.
    pub fn to_text(&self, shard: Shard, recipe: &str) -> String {
        let fields = [
            ("lo", height_text(self.lo)),
            ("hi", height_text(self.hi)),
            ("max-range", height_text(self.max_range)),
            ("max-abs", height_text(self.max_abs)),
            ("spans", spans_text(&self.spans)),
            ("voids", self.voids.to_string()),
            ("fill", self.fill.clone().unwrap_or_else(|| "-".into())),
            ("layers", layers_text(self.layers.as_deref())),
        ];
        record_text(SCAN_HEAD, shard, &fields, recipe)
    }

    /// A scan file read back: its shard, figures and recipe.
    pub fn from_text(text: &str) -> Result<(Shard, ShardScan, String), String> {
        let names = [
            "lo",
            "hi",
            "max-range",
            "max-abs",
            "spans",
            "voids",
            "fill",
            "layers",
        ];
        let (shard, v, recipe) = record_fields(text, SCAN_HEAD, &names)?;
        let scan = ShardScan {
            lo: height_of(&v[0])?,
            hi: height_of(&v[1])?,
            max_range: height_of(&v[2])?,
            max_abs: height_of(&v[3])?,
            spans: spans_of(&v[4])?,
            voids: v[5].parse().map_err(|_| "a bad void count")?,
            fill: (v[6] != "-").then(|| v[6].clone()),
            layers: layers_of_text(&v[7])?,
        };
        Ok((shard, scan, recipe))
    }
}

impl ShardRanges {
    /// The ranges file: the figures, then the input's recipe.
    pub fn to_text(&self, shard: Shard, recipe: &str) -> String {
        let fields = [
            ("max-range", height_text(self.max_range)),
            ("max-abs", height_text(self.max_abs)),
            ("spans", spans_text(&self.spans)),
        ];
        record_text(RANGES_HEAD, shard, &fields, recipe)
    }

    /// A ranges file read back: its shard, figures and recipe.
    pub fn from_text(text: &str) -> Result<(Shard, ShardRanges, String), String> {
        let names = ["max-range", "max-abs", "spans"];
        let (shard, v, recipe) = record_fields(text, RANGES_HEAD, &names)?;
        let ranges = ShardRanges {
            max_range: height_of(&v[0])?,
            max_abs: height_of(&v[1])?,
            spans: spans_of(&v[2])?,
        };
        Ok((shard, ranges, recipe))
    }
}

/// Every shard's scan of one input, put together.
#[derive(Clone, Debug, PartialEq)]
pub struct Scans {
    pub lo: f32,
    pub hi: f32,
    pub max_range: f32,
    pub max_abs: f32,
    pub spans: CellSpans,
    pub voids: u64,
    /// Each pyramid layer's figures, where every shard's scan holds them.
    pub layers: Option<Vec<LayerScan>>,
}

impl Scans {
    /// The scans of shards `0..N`, in any order; `None` for none.
    pub fn join(scans: &[ShardScan]) -> Option<Scans> {
        let first = scans.first()?;
        let layers = first.layers.as_ref().and_then(|l| {
            let joined = |a: LayerScan, b: &LayerScan| LayerScan {
                lo: a.lo.min(b.lo),
                hi: a.hi.max(b.hi),
                max_abs: a.max_abs.max(b.max_abs),
                spans: widest(&a.spans, &b.spans),
            };
            scans.iter().try_fold(l.clone(), |a, s| match &s.layers {
                Some(b) if b.len() == a.len() => {
                    Some(a.into_iter().zip(b).map(|(a, b)| joined(a, b)).collect())
                }
                _ => None,
            })
        });
        Some(scans.iter().fold(
            Scans {
                lo: first.lo,
                hi: first.hi,
                max_range: 0.0,
                max_abs: 0.0,
                spans: CellSpans::default(),
                voids: 0,
                layers,
            },
            |a, s| Scans {
                lo: a.lo.min(s.lo),
                hi: a.hi.max(s.hi),
                max_range: a.max_range.max(s.max_range),
                max_abs: a.max_abs.max(s.max_abs),
                spans: widest(&a.spans, &s.spans),
                voids: a.voids + s.voids,
                layers: a.layers,
            },
        ))
    }

    /// The scans with the tile ranges of the filled grid: every shard's [`ShardRanges`].
    pub fn filled(self, ranges: &[ShardRanges]) -> Scans {
        Scans {
            max_range: ranges.iter().fold(0.0, |m, r| m.max(r.max_range)),
            max_abs: ranges.iter().fold(0.0, |m, r| m.max(r.max_abs)),
            spans: ranges
                .iter()
                .fold(CellSpans::default(), |m, r| widest(&m, &r.spans)),
            // The layers' figures were of the grid before its fill.
            layers: None,
            ..self
        }
    }

    /// What a scan of the whole of pyramid layer `p` (>= 1) finds, where the shards' scans
    /// hold it.
    fn layer_scanned(&self, p: u32) -> Option<crate::build::Scanned> {
        let l = self.layers.as_ref()?.get(p as usize - 1)?;
        Some(crate::build::Scanned {
            lo: l.lo,
            hi: l.hi,
            max_abs: l.max_abs,
            step: crate::quantise::lattice_step(l.spans[CELL_SIZES - 1], l.max_abs),
            spans: l.spans,
        })
    }

    /// What the build's pass over the whole grid finds: the same range, the same step.
    fn scanned(&self) -> crate::build::Scanned {
        crate::build::Scanned {
            lo: self.lo,
            hi: self.hi,
            max_abs: self.max_abs,
            step: crate::quantise::lattice_step(self.max_range, self.max_abs),
            spans: self.spans,
        }
    }
}

/// The larger of two cell spans, size by size.
fn widest(a: &CellSpans, b: &CellSpans) -> CellSpans {
    std::array::from_fn(|i| a[i].max(b[i]))
}

/// Grid rows whose share of the void fill's pass a shard's scan pulls: its tile rows' samples
/// but the row its last tile row shares with the next shard's, so that the shards' shares
/// cover the grid's rows once. Each starts on a multiple of 256 rows (a tile row), which is a
/// multiple of the rows a row of the fill's top pulled level stands for (at most 64,
/// `dem::Pulled`).
pub fn pull_rows(
    shard: Shard,
    (width, height): (usize, usize),
) -> Result<Range<usize>, BuildError> {
    let (rows, last) = grid_rows(shard, (width, height))?;
    Ok(rows.start..if last { height } else { rows.end - 1 })
}

/// Grid rows a shard's scan reads: its tile rows' samples, up to and with the row its last
/// tile row shares with the next shard's.
pub fn scan_rows(
    shard: Shard,
    (width, height): (usize, usize),
) -> Result<Range<usize>, BuildError> {
    Ok(grid_rows(shard, (width, height))?.0)
}

/// The grid rows of a shard's tile rows (with the row the last shares with the next tile row),
/// and whether they end the grid.
fn grid_rows(
    shard: Shard,
    (width, height): (usize, usize),
) -> Result<(Range<usize>, bool), BuildError> {
    let (_, tiles_y) = tile_count(width, height).map_err(BuildError::Params)?;
    let rows = shard.rows_of(tiles_y)?;
    let cells = crate::mesh::TILE_CELLS as usize;
    let grid = rows.start as usize * cells..(rows.end as usize * cells + 1).min(height);
    Ok((grid, rows.end == tiles_y))
}

/// Shard `shard`'s rows ([`Shard::rows`]) of each pyramid layer a set of `heights` has with
/// `--pyramid`, scanned as a build scans a whole layer (as stored: meaningful when the grid
/// holds no void). Every shard's together make the layers' scans, so that a shard given them
/// reads no layer whole.
pub fn layer_scans(heights: &dyn Heights, shard: Shard) -> Result<Vec<LayerScan>, BuildError> {
    let shape = heights.shape();
    let layers = crate::format::pyramid_layers(shape.width, shape.height);
    (1..=layers)
        .map(|p| {
            let layer = Decimated::new(heights, p);
            let grid = layer.shape();
            let tiles = tile_count(grid.width, grid.height).map_err(BuildError::Params)?;
            let found = scan(&Bands::within(&layer, tiles, shard.rows(tiles.1)))?;
            Ok(LayerScan {
                lo: found.lo,
                hi: found.hi,
                max_abs: found.max_abs,
                spans: found.spans,
            })
        })
        .collect()
}

/// The largest tile range and absolute height, and the cell spans ([`crate::units`]), over
/// shard `shard`'s tile rows, reading only their rows of `heights` (as stored: meaningful when
/// they hold no void).
pub fn tile_ranges(heights: &dyn Heights, shard: Shard) -> Result<ShardRanges, BuildError> {
    let shape = heights.shape();
    let tiles = tile_count(shape.width, shape.height).map_err(BuildError::Params)?;
    let rows = shard.rows(tiles.1);
    let bands = Bands::within(heights, tiles, rows);
    let mut found = ShardRanges {
        max_range: 0.0,
        max_abs: 0.0,
        spans: CellSpans::default(),
    };
    for b in 0..bands.count() {
        let band = bands.load(b, 0)?;
        let grid = band.grid(&shape);
        let (spans, abs) = cell_spans(&grid, tiles.0, band.tile_rows.clone());
        found.spans = widest(&found.spans, &spans);
        found.max_range = found.spans[CELL_SIZES - 1];
        found.max_abs = found.max_abs.max(abs);
    }
    Ok(found)
}

/// A part file being written: to its temporary name, checksummed as it goes, renamed when
/// finished (dropped unfinished, the temporary file is removed).
struct PartWriter {
    path: PathBuf,
    tmp: PathBuf,
    file: Option<BufWriter<std::fs::File>>,
    crc: crc32fast::Hasher,
    len: u64,
}

impl PartWriter {
    fn create(path: &Path) -> Result<PartWriter, BuildError> {
        let tmp = temp_path(path)?;
        // A shard killed with SIGKILL could not remove its temporary file: its rerun does.
        crate::format::remove_stale_temporaries(path);
        let file = std::fs::File::create(&tmp).map_err(|e| io_error(&tmp, e))?;
        Ok(PartWriter {
            path: path.to_path_buf(),
            tmp,
            file: Some(BufWriter::with_capacity(1 << 20, file)),
            crc: crc32fast::Hasher::new(),
            len: 0,
        })
    }

    fn put(&mut self, bytes: &[u8]) -> Result<(), BuildError> {
        self.crc.update(bytes);
        self.len += bytes.len() as u64;
        let file = self.file.as_mut().expect("open until finished");
        file.write_all(bytes).map_err(|e| io_error(&self.path, e))
    }

    fn u32(&mut self, v: u32) -> Result<(), BuildError> {
        self.put(&v.to_le_bytes())
    }

    /// Zeros up to the next multiple of [`ALIGN`] bytes: blobs lie aligned in the map, as
    /// their readers need.
    fn align(&mut self) -> Result<(), BuildError> {
        let pad = self.len.next_multiple_of(ALIGN as u64) - self.len;
        self.put(&[0u8; ALIGN][..pad as usize])
    }

    fn u64(&mut self, v: u64) -> Result<(), BuildError> {
        self.put(&v.to_le_bytes())
    }

    fn f64(&mut self, v: f64) -> Result<(), BuildError> {
        self.put(&v.to_le_bytes())
    }

    fn f32(&mut self, v: f32) -> Result<(), BuildError> {
        self.put(&v.to_le_bytes())
    }

    fn sides(&mut self, sides: &CompactSides) -> Result<(), BuildError> {
        for level in sides {
            for side in level {
                for &word in side {
                    self.u64(word)?;
                }
            }
        }
        Ok(())
    }

    /// A tile record's first fields: its forced sides, its sides and its deviations.
    fn sides_and_deviation(
        &mut self,
        forced: &CompactSides,
        sides: &CompactSides,
        deviation: &[f64],
    ) -> Result<(), BuildError> {
        self.sides(forced)?;
        self.sides(sides)?;
        deviation.iter().try_for_each(|&d| self.f64(d))
    }

    /// A tile record's last fields: tile `(tx, ty)` of layer `layer`'s version 3 blob, or with
    /// compact levels (`compact`: the levels and the layer's lattice step) what the set stores
    /// (compacted here, on the shard: the merge copies it), then its texture, each after its
    /// length and aligned.
    fn blobs(
        &mut self,
        blob: &[u8],
        (layer, tx, ty): (u32, u32, u32),
        compact: Option<(u32, f32)>,
        texture: &[u8],
    ) -> Result<(), BuildError> {
        let compacted;
        let blob = match compact {
            Some(shape) => {
                compacted = compact_tile(blob, (tx, ty), shape).map_err(|what| {
                    BuildError::Internal(format!("layer {layer} tile {tx},{ty}: {what}"))
                })?;
                &compacted[..]
            }
            None => blob,
        };
        self.u64(blob.len() as u64)?;
        self.align()?;
        self.put(blob)?;
        self.u64(texture.len() as u64)?;
        self.align()?;
        self.put(texture)
    }

    /// The checksum and end mark, then sync and rename into place. Returns the part's size.
    fn finish(mut self) -> Result<u64, BuildError> {
        let crc = self.crc.clone().finalize();
        let mut file = self.file.take().expect("open until finished");
        let tail = [&crc.to_le_bytes()[..], &END_MAGIC].concat();
        let error = |e| io_error(&self.path, e);
        file.write_all(&tail).map_err(error)?;
        let file = file.into_inner().map_err(|e| error(e.into_error()))?;
        file.sync_all().map_err(error)?;
        std::fs::rename(&self.tmp, &self.path).map_err(error)?;
        Ok(self.len + tail.len() as u64)
    }
}

impl Drop for PartWriter {
    fn drop(&mut self) {
        if self.file.is_some() {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Seals a part's bytes again after they were changed: the crc32 of everything before the
/// checksum, written where the checksum is (the fuzzer's mutations then meet the merge's
/// checks beyond the checksum). Bytes that do not end in the end mark are left as they are.
pub fn reseal_part(bytes: &mut [u8]) -> Result<(), String> {
    let n = bytes.len();
    if n < 12 || bytes[n - 8..] != END_MAGIC {
        return Err("no end mark".into());
    }
    let crc = crc32fast::hash(&bytes[..n - 12]);
    bytes[n - 12..n - 8].copy_from_slice(&crc.to_le_bytes());
    Ok(())
}

fn io_error(path: &Path, e: std::io::Error) -> BuildError {
    BuildError::Input(format!("{}: {e}", path.display()))
}

/// One part file, mapped and checked: its preamble read, its tiles indexed.
pub struct Part {
    pub path: PathBuf,
    pub shard: Shard,
    pub halo: u32,
    pub recipe: String,
    pub header: FileHeader,
    pub rows: Range<u32>,
    pub tiles_x: u32,
    pub levels: u32,
    /// The units its blobs were sealed with (0s with independent sides).
    pub units: Vec<f64>,
    /// Per level, the floor of the set's morph units from the input's scan ([`crate::units`]).
    pub bounds: Vec<f64>,
    pub agreement_passes: u32,
    pub agreement_meshes: u64,
    /// Its share of each pyramid layer, from layer 1 up.
    pub layers: Vec<PartLayer>,
    map: memmap2::Mmap,
    /// Per owned tile: where its record starts.
    tiles: Vec<usize>,
}

/// A part's tile rows of one pyramid layer.
pub struct PartLayer {
    pub rows: Range<u32>,
    pub tiles_x: u32,
    pub tiles_y: u32,
    /// The layer's lattice step and range of heights, from the shard's scan of the layer.
    pub step: f32,
    pub lo: f32,
    pub hi: f32,
    /// The units its tiles were sealed with (0s with independent sides, or no rows).
    pub units: Vec<f64>,
    /// Per level, the floor of the layer's morph units from the scans ([`crate::units`]).
    pub bounds: Vec<f64>,
    pub agreement_passes: u32,
    pub agreement_meshes: u64,
    /// Per owned tile: where its record starts.
    tiles: Vec<usize>,
}

/// A part's fields before its tiles, and where its tiles start.
struct Preamble {
    shard: Shard,
    halo: u32,
    recipe: String,
    header: FileHeader,
    rows: Range<u32>,
    tiles_x: u32,
    levels: u32,
    units: Vec<f64>,
    bounds: Vec<f64>,
    passes: u32,
    meshes: u64,
    tiles: Vec<usize>,
    layers: Vec<PartLayer>,
}

/// One tile of a part, as recorded.
pub struct PartTile<'a> {
    pub forced: CompactSides,
    pub sides: CompactSides,
    pub deviation: Vec<f64>,
    /// A layer tile's decimation error and its levels' errors against the base grid (0 and
    /// none in the base grid).
    pub decimation: f32,
    pub errors: Vec<f32>,
    pub blob: &'a [u8],
    pub texture: &'a [u8],
}

/// Reads a part's fields in order, refusing to run past its end.
struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or("ends early")?;
        let out = &self.bytes[self.at..end];
        self.at = end;
        Ok(out)
    }

    fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }

    /// The bytes of `len` that follow the padding to the next multiple of [`ALIGN`].
    fn aligned(&mut self, len: usize) -> Result<&'a [u8], String> {
        self.take(self.at.next_multiple_of(ALIGN) - self.at)?;
        self.take(len)
    }

    fn u64(&mut self) -> Result<u64, String> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }

    fn f64(&mut self) -> Result<f64, String> {
        Ok(f64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }

    fn f32(&mut self) -> Result<f32, String> {
        Ok(f32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }

    /// A tile record's blob and texture, after its fixed fields; their offsets are checked.
    fn blobs(&mut self) -> Result<(), String> {
        let blob = self.len()?;
        self.aligned(blob)?;
        let texture = self.len()?;
        self.aligned(texture)?;
        Ok(())
    }

    fn len(&mut self) -> Result<usize, String> {
        usize::try_from(self.u64()?).map_err(|_| "a length out of range".to_string())
    }

    fn sides(&mut self, levels: u32) -> Result<CompactSides, String> {
        (0..levels)
            .map(|_| {
                let mut level = [[0u64; 5]; 4];
                for side in &mut level {
                    for word in side.iter_mut() {
                        *word = self.u64()?;
                    }
                }
                Ok(level)
            })
            .collect()
    }
}

/// Bytes of a part summed before they are dropped from memory when it is opened (a multiple of
/// the page size).
const CHECKSUM_WINDOW: usize = 64 << 20;

/// Bytes of a tile record's sides and deviations at `levels` levels.
fn fixed_record_len(levels: u32) -> usize {
    levels as usize * (2 * 4 * size_of::<SideBits>() + 8)
}

/// Bytes of a layer tile record's fixed fields: a base tile's, its decimation error and its
/// levels' errors against the base grid.
fn fixed_layer_record_len(levels: u32) -> usize {
    fixed_record_len(levels) + 4 + 4 * levels as usize
}

impl Part {
    /// Maps and checks `path`: magic, version, checksum, and a structure that adds up.
    pub fn open(path: &Path) -> Result<Part, BuildError> {
        let refuse = |what: String| BuildError::Input(format!("{}: {what}", path.display()));
        let file = std::fs::File::open(path).map_err(|e| refuse(e.to_string()))?;
        let meta = file.metadata().map_err(|e| refuse(e.to_string()))?;
        if !meta.is_file() {
            return Err(refuse("not a regular file".into()));
        }
        // SAFETY: the map is read-only; a part is written once to a temporary name and renamed,
        // so no writer holds the file a merge reads.
        let map = unsafe { memmap2::Mmap::map(&file) }.map_err(|e| refuse(e.to_string()))?;
        if map.len() < PART_MAGIC.len() || map[..PART_MAGIC.len()] != PART_MAGIC {
            return Err(refuse("not a vkterrain part file (no VKTPART mark)".into()));
        }
        let tail = PART_MAGIC.len() + 4 + END_MAGIC.len();
        if map.len() < tail || map[map.len() - END_MAGIC.len()..] != END_MAGIC {
            return Err(refuse(
                "incomplete: it does not end with the part's end mark (a shard cut short?)".into(),
            ));
        }
        let body = map.len() - 4 - END_MAGIC.len();
        let stored = u32::from_le_bytes(map[body..body + 4].try_into().expect("4 bytes"));
        // The checksum reads every page: each window's pages go out of this process's memory
        // as soon as they are summed, until the copy needs them (see `release`). Dropped only
        // at the end, a part's every page was resident at once: a merge's peak was its
        // largest part (7 GB for a 16K pyramid set in one shard).
        let mut crc = crc32fast::Hasher::new();
        for start in (0..body).step_by(CHECKSUM_WINDOW) {
            let end = (start + CHECKSUM_WINDOW).min(body);
            crc.update(&map[start..end]);
            // SAFETY: as in `release`: a read-only file mapping, no slice of it held yet.
            let _ = unsafe {
                map.unchecked_advise_range(memmap2::UncheckedAdvice::DontNeed, start, end - start)
            };
        }
        if crc.finalize() != stored {
            return Err(refuse("damaged: its checksum does not match".into()));
        }
        let p = Self::parse(&map[..body]).map_err(refuse)?;
        Ok(Part {
            path: path.to_path_buf(),
            shard: p.shard,
            halo: p.halo,
            recipe: p.recipe,
            header: p.header,
            rows: p.rows,
            tiles_x: p.tiles_x,
            levels: p.levels,
            units: p.units,
            bounds: p.bounds,
            agreement_passes: p.passes,
            agreement_meshes: p.meshes,
            layers: p.layers,
            map,
            tiles: p.tiles,
        })
    }

    fn parse(bytes: &[u8]) -> Result<Preamble, String> {
        let mut c = Cursor {
            bytes,
            at: PART_MAGIC.len(),
        };
        let version = c.u32()?;
        if version != PART_VERSION {
            return Err(format!(
                "part format version {version}; this tiletool reads version {PART_VERSION}"
            ));
        }
        let (index, count, halo) = (c.u32()?, c.u32()?, c.u32()?);
        if index >= count {
            return Err(format!("shard {index} of {count}"));
        }
        let recipe_len = c.u32()? as usize;
        let recipe = std::str::from_utf8(c.take(recipe_len)?)
            .map_err(|_| "its recipe is not text")?
            .to_string();
        let header: FileHeader = bytemuck::pod_read_unaligned(c.take(size_of::<FileHeader>())?);
        let (r0, r1, tiles_x, levels) = (c.u32()?, c.u32()?, c.u32()?, c.u32()?);
        let expected = tile_count(header.grid_width as usize, header.grid_height as usize)?;
        let shard = Shard { index, count };
        if (tiles_x, levels) != (header.tiles_x, header.levels)
            || expected != (header.tiles_x, header.tiles_y)
            || (r0..r1) != shard.rows(header.tiles_y)
            || count > header.tiles_y
            || levels == 0
            || levels > crate::format::MAX_LEVELS
        {
            return Err(format!(
                "its tile rows {r0}..{r1} of {tiles_x} x {} tiles at {levels} levels do not add up",
                header.tiles_y
            ));
        }
        let units = (0..levels).map(|_| c.f64()).collect::<Result<_, _>>()?;
        let bounds = (0..levels).map(|_| c.f64()).collect::<Result<_, _>>()?;
        let (passes, meshes) = (c.u32()?, c.u64()?);
        let mut tiles = Vec::new();
        for _ in 0..(r1 - r0) as usize * tiles_x as usize {
            tiles.push(c.at);
            c.take(fixed_record_len(levels))?;
            c.blobs()?;
        }
        let layers = Self::parse_layers(&mut c, &header, shard)?;
        if c.at != bytes.len() {
            return Err(format!("{} bytes after its last tile", bytes.len() - c.at));
        }
        Ok(Preamble {
            shard,
            halo,
            recipe,
            header,
            rows: r0..r1,
            tiles_x,
            levels,
            units,
            bounds,
            passes,
            meshes,
            tiles,
            layers,
        })
    }

    /// The part's share of each pyramid layer, after its base tiles.
    fn parse_layers(
        c: &mut Cursor,
        header: &FileHeader,
        shard: Shard,
    ) -> Result<Vec<PartLayer>, String> {
        let expected = layers_of(header)?;
        let count = c.u32()? as usize;
        if count != expected.len() {
            return Err(format!(
                "it holds {count} pyramid layers, and its set {}",
                expected.len()
            ));
        }
        let levels = header.levels;
        let mut layers = Vec::with_capacity(count);
        for (i, l) in expected.iter().enumerate() {
            let fields = [c.u32()?, c.u32()?, c.u32()?, c.u32()?, c.u32()?];
            let [p, r0, r1, tiles_x, tiles_y] = fields;
            if p as usize != i + 1
                || (tiles_x, tiles_y) != (l.tiles_x, l.tiles_y)
                || (r0..r1) != shard.rows(tiles_y)
            {
                return Err(format!(
                    "its pyramid layer {} (rows {r0}..{r1} of {tiles_x} x {tiles_y} tiles) \
                     does not add up",
                    i + 1
                ));
            }
            let (step, lo, hi) = (c.f32()?, c.f32()?, c.f32()?);
            let units = (0..levels).map(|_| c.f64()).collect::<Result<_, _>>()?;
            let bounds = (0..levels).map(|_| c.f64()).collect::<Result<_, _>>()?;
            let (passes, meshes) = (c.u32()?, c.u64()?);
            let mut tiles = Vec::new();
            for _ in 0..(r1 - r0) as usize * tiles_x as usize {
                tiles.push(c.at);
                c.take(fixed_layer_record_len(levels))?;
                c.blobs()?;
            }
            layers.push(PartLayer {
                rows: r0..r1,
                tiles_x,
                tiles_y,
                step,
                lo,
                hi,
                units,
                bounds,
                agreement_passes: passes,
                agreement_meshes: meshes,
                tiles,
            });
        }
        Ok(layers)
    }

    /// Its tile rows of grid `p` (0: the base grid, else pyramid layer `p`).
    fn grid_rows(&self, p: u32) -> Range<u32> {
        match p {
            0 => self.rows.clone(),
            p => self.layers[p as usize - 1].rows.clone(),
        }
    }

    /// The units it sealed grid `p`'s tiles with.
    fn grid_units(&self, p: u32) -> &[f64] {
        match p {
            0 => &self.units,
            p => &self.layers[p as usize - 1].units,
        }
    }

    /// Where grid `p`'s records start, and the index in the grid of the first.
    fn grid_records(&self, p: u32) -> (&[usize], usize) {
        match p {
            0 => (
                &self.tiles,
                self.rows.start as usize * self.tiles_x as usize,
            ),
            p => {
                let l = &self.layers[p as usize - 1];
                (&l.tiles, l.rows.start as usize * l.tiles_x as usize)
            }
        }
    }

    /// Tile `t` (row-major) of grid `p`, which this part must own.
    fn grid_tile(&self, p: u32, t: usize) -> PartTile<'_> {
        let (records, first) = self.grid_records(p);
        self.record(records[t - first], p > 0)
    }

    /// Drops tile `t` of grid `p`'s record from this process's memory once it is copied: the
    /// merge maps parts as large as the set, and would otherwise hold them all (its pages stay
    /// in the kernel's cache, and are read again from the file if touched).
    fn release_grid_tile(&self, p: u32, t: usize) {
        let (records, first) = self.grid_records(p);
        self.release_record(records, t - first);
    }

    /// Drops record `k` of `records` (offsets into the map) from memory.
    fn release_record(&self, records: &[usize], k: usize) {
        let start = records[k];
        let end = records.get(k + 1).copied().unwrap_or(self.map.len());
        let page = 4096;
        let (start, end) = (start.next_multiple_of(page), end / page * page);
        if start < end {
            // SAFETY: a read-only mapping of a file that is not written while merged: dropped
            // pages lose nothing, and a slice into them reads the same bytes again.
            let _ = unsafe {
                self.map.unchecked_advise_range(
                    memmap2::UncheckedAdvice::DontNeed,
                    start,
                    end - start,
                )
            };
        }
    }

    /// The tile record at `at`: a layer tile's (`layer`) or a base tile's.
    fn record(&self, at: usize, layer: bool) -> PartTile<'_> {
        let mut c = Cursor {
            bytes: &self.map,
            at,
        };
        // The structure was checked when the part was opened.
        let mut read = || -> Result<PartTile<'_>, String> {
            let forced = c.sides(self.levels)?;
            let sides = c.sides(self.levels)?;
            let deviation = (0..self.levels)
                .map(|_| c.f64())
                .collect::<Result<_, _>>()?;
            let (decimation, errors) = match layer {
                true => (
                    c.f32()?,
                    (0..self.levels)
                        .map(|_| c.f32())
                        .collect::<Result<_, _>>()?,
                ),
                false => (0.0, Vec::new()),
            };
            let blob = c.len()?;
            let blob = c.aligned(blob)?;
            let texture = c.len()?;
            let texture = c.aligned(texture)?;
            Ok(PartTile {
                forced,
                sides,
                deviation,
                decimation,
                errors,
                blob,
                texture,
            })
        };
        read().expect("checked at open")
    }
}

/// Opens the input that a part's recipe names, and its texturing (for [`merge`]).
pub type Reopen = dyn Fn(&str) -> Result<(Box<dyn Heights>, Option<Texturing>), BuildError>;

/// What a merge did.
#[derive(Clone, Debug, Default)]
pub struct MergeSummary {
    pub parts: u32,
    pub tiles: u64,
    /// Tiles whose forced sides the parts had not settled: meshed again by resuming the
    /// agreement (`remeshed`, all meshes), of which `rebuilt` had their sides changed and
    /// were built again from the input.
    pub unsettled: u64,
    pub remeshed: u64,
    pub rebuilt: u64,
    /// Tiles sealed again at the set's morph units.
    pub resealed: u64,
    pub file_bytes: u64,
    /// Per level, over the set's tiles: vertices, triangles and the largest measured error
    /// (the other figures of a build's summary are not kept in the parts).
    pub levels: Vec<LevelStats>,
    /// Tiles of the pyramid's layers (0 without a pyramid), as the shards built them; of
    /// them, as for the base grid's above: unsettled, meshes to settle them, built again,
    /// sealed again.
    pub pyramid_tiles: u64,
    pub pyramid_unsettled: u64,
    pub pyramid_remeshed: u64,
    pub pyramid_rebuilt: u64,
    pub pyramid_resealed: u64,
}

/// Checks that `paths` are the parts of one set, every shard exactly once, and writes the set
/// to `out` (temporary file, then rename). `reopen` opens the input a part's recipe names,
/// for the rare seam that the shards' halos did not settle.
pub fn merge(
    paths: &[PathBuf],
    out: &Path,
    reopen: &Reopen,
    progress: &(dyn Fn() + Sync),
) -> Result<MergeSummary, BuildError> {
    let parts = paths
        .iter()
        .map(|p| Part::open(p))
        .collect::<Result<Vec<_>, _>>()?;
    let Some(first) = parts.first() else {
        return Err(BuildError::Params("no parts to merge".into()));
    };
    let count = first.shard.count;
    let mut by_index: Vec<Option<&Part>> = vec![None; count as usize];
    for part in &parts {
        let refuse = |what: String| BuildError::Params(format!("{}: {what}", part.path.display()));
        if part.recipe != first.recipe {
            let differs = part
                .recipe
                .lines()
                .zip(first.recipe.lines())
                .find(|(a, b)| a != b)
                .map_or_else(
                    || "its inputs or options".to_string(),
                    |(a, _)| format!("`{a}`"),
                );
            return Err(refuse(format!(
                "built from other inputs or options than {} ({differs} differs)",
                first.path.display()
            )));
        }
        if part.shard.count != count {
            return Err(refuse(format!(
                "is shard {} of a build in {} shards, and {} is of {count}",
                part.shard,
                part.shard.count,
                first.path.display()
            )));
        }
        if bytemuck::bytes_of(&part.header) != bytemuck::bytes_of(&first.header) {
            return Err(refuse(format!(
                "its set header differs from {}'s (the input changed between shards?)",
                first.path.display()
            )));
        }
        if part.bounds != first.bounds {
            return Err(refuse(format!(
                "its scan's morph unit bounds differ from {}'s (the input changed between shards?)",
                first.path.display()
            )));
        }
        let slot = &mut by_index[part.shard.index as usize];
        if let Some(other) = slot {
            return Err(refuse(format!(
                "shard {} is given twice (also {})",
                part.shard,
                other.path.display()
            )));
        }
        *slot = Some(part);
    }
    if let Some(k) = by_index.iter().position(Option::is_none) {
        return Err(BuildError::Params(format!(
            "shard {k}/{count} is missing: merge needs all {count} parts"
        )));
    }
    let by_index: Vec<&Part> = by_index.into_iter().flatten().collect();
    let header = first.header;
    let params = BuildParams {
        levels: header.levels,
        base_error: header.base_error,
        shared_sides: header.flags & FLAG_SHARED_SIDES != 0,
        pyramid: header.pyramid_layers > 0,
    };
    let mut summary = MergeSummary {
        parts: by_index.len() as u32,
        levels: vec![LevelStats::default(); header.levels as usize],
        ..MergeSummary::default()
    };
    // The base grid, then each layer above it, as the build writes them.
    let mut writer = TileSetWriter::create(out, header)?;
    let base = PartsGrid::of(&by_index, 0)?;
    let run = (&params, reopen, progress);
    let m = merge_grid(&mut writer, &base, run, Some(&mut summary.levels))?;
    summary.tiles = m.tiles;
    (summary.unsettled, summary.remeshed) = (m.unsettled, m.remeshed);
    (summary.rebuilt, summary.resealed) = (m.rebuilt, m.resealed);
    for p in 1..=header.pyramid_layers {
        let layer = PartsGrid::of(&by_index, p)?;
        let l = &first.layers[p as usize - 1];
        writer.set_layer_heights(p, l.step, l.lo, l.hi);
        let m = merge_grid(&mut writer, &layer, run, None)?;
        summary.pyramid_tiles += m.tiles;
        summary.pyramid_unsettled += m.unsettled;
        summary.pyramid_remeshed += m.remeshed;
        summary.pyramid_rebuilt += m.rebuilt;
        summary.pyramid_resealed += m.resealed;
    }
    writer.finish()?;
    summary.file_bytes = std::fs::metadata(out).map(|m| m.len()).unwrap_or(0);
    Ok(summary)
}

/// One grid of the set that the parts hold, as the merge reads it: the base grid (`p` 0) or
/// pyramid layer `p`, each tile row from the part that built it.
struct PartsGrid<'a> {
    p: u32,
    tiles: (u32, u32),
    /// Its height lattice's step.
    step: f32,
    /// Per level, the floor of its morph units ([`crate::units`]).
    bounds: Vec<f64>,
    /// Each tile row's part.
    row_owner: Vec<&'a Part>,
}

impl<'a> PartsGrid<'a> {
    /// Grid `p` of `parts` (by shard index, every shard present; the base grid's header and
    /// bounds checked alike in each). A layer's scan and bounds must be the same in every part.
    fn of(parts: &[&'a Part], p: u32) -> Result<PartsGrid<'a>, BuildError> {
        let first = parts[0];
        let (tiles, step, bounds) = match p {
            0 => {
                let h = &first.header;
                ((h.tiles_x, h.tiles_y), h.height_step, first.bounds.clone())
            }
            _ => {
                let l = &first.layers[p as usize - 1];
                for part in parts {
                    let o = &part.layers[p as usize - 1];
                    if (o.step, o.lo, o.hi, &o.bounds) != (l.step, l.lo, l.hi, &l.bounds) {
                        return Err(BuildError::Params(format!(
                            "{}: its scan of pyramid layer {p} differs from {}'s (the input \
                             changed between shards?)",
                            part.path.display(),
                            first.path.display()
                        )));
                    }
                }
                ((l.tiles_x, l.tiles_y), l.step, l.bounds.clone())
            }
        };
        // The shards' rows cover each grid (checked when each part was opened).
        let row_owner: Vec<&Part> = parts
            .iter()
            .flat_map(|part| part.grid_rows(p).map(move |_| *part))
            .collect();
        if row_owner.len() != tiles.1 as usize {
            let grid = match p {
                0 => "the set".to_string(),
                p => format!("pyramid layer {p}"),
            };
            return Err(BuildError::Internal(format!(
                "the shards' rows do not cover {grid}"
            )));
        }
        Ok(PartsGrid {
            p,
            tiles,
            step,
            bounds,
            row_owner,
        })
    }

    /// The part that built tile `t` (row-major).
    fn owner(&self, t: usize) -> &'a Part {
        self.row_owner[t / self.tiles.0 as usize]
    }

    /// Tile `t` as its part recorded it.
    fn tile(&self, t: usize) -> PartTile<'a> {
        self.owner(t).grid_tile(self.p, t)
    }

    /// How problems name tile `(tx, ty)`.
    fn tile_name(&self, (tx, ty): (u32, u32)) -> String {
        match self.p {
            0 => format!("tile {tx},{ty}"),
            p => format!("pyramid layer {p} tile {tx},{ty}"),
        }
    }
}

/// What [`merge_grid`] did with one grid's tiles (see [`MergeSummary`]).
#[derive(Default)]
struct GridMerged {
    tiles: u64,
    unsettled: u64,
    remeshed: u64,
    rebuilt: u64,
    resealed: u64,
}

/// Writes `grid` of the set from the parts' shares of it, after the grids below it: its shared
/// sides checked for the fixed point and resumed from the input where a halo fell short (those
/// tiles built again), its morph units from its bounds and every tile's deviations, and each
/// tile copied, or sealed again where its part's units were smaller. `(params, reopen,
/// progress)` as [`merge`] has them; `levels`: the per-level figures to add each tile's to
/// (the base grid's).
fn merge_grid(
    writer: &mut TileSetWriter,
    grid: &PartsGrid,
    (params, reopen, progress): (&BuildParams, &Reopen, &(dyn Fn() + Sync)),
    mut levels: Option<&mut Vec<LevelStats>>,
) -> Result<GridMerged, BuildError> {
    let p = grid.p;
    let (tiles_x, tiles_y) = grid.tiles;
    let count = tiles_x as usize * tiles_y as usize;
    let mut merged = GridMerged::default();
    // Each layer tile's decimation error, its floor (none in the base grid).
    let decimation: Vec<f32> = match p {
        0 => Vec::new(),
        _ => (0..count).map(|t| grid.tile(t).decimation).collect(),
    };
    let floors = (p > 0).then_some(&decimation[..]);
    // Tiles built again where the agreement moved their sides: blob, and above the base
    // grid, its levels' errors against it.
    let mut rebuilt: std::collections::HashMap<usize, (Vec<u8>, Vec<f32>)> = Default::default();
    let mut units = Vec::new();
    if params.shared_sides {
        let start = recorded_start(count, |t| grid.tile(t));
        let recorded = start.forced.clone();
        let unsettled = unsettled_tiles(&start, tiles_x, params.levels);
        merged.unsettled = unsettled as u64;
        // Each tile's deviations as its part recorded them: the final build's in the base
        // grid, the agreement's (the same meshes) in a layer.
        let mut deviation = start.deviation.clone();
        if unsettled > 0 {
            let (heights, _) = reopen(&grid.row_owner[0].recipe)?;
            let decimated;
            let grid_heights: &dyn Heights = match p {
                0 => heights.as_ref(),
                _ => {
                    decimated = Decimated::new(heights.as_ref(), p);
                    &decimated
                }
            };
            let bands = Bands::new(grid_heights, (tiles_x, tiles_y));
            let all = 0..tiles_y;
            let (changes, step) = (Remesh::Changed, grid.step);
            let mut agreed = settle(&bands, params, step, floors, changes, all, Some(start))?;
            merged.remeshed = agreed.meshes;
            // A layer's agreement measures its meshes' deviations; the base grid's finds none,
            // and the recorded ones stand.
            if p > 0 {
                deviation = agreed.deviation.clone();
            }
            agreed.units = units_of(&grid.bounds, &deviation);
            let changed: Vec<usize> = (0..count)
                .filter(|&t| agreed.forced[t] != recorded[t])
                .collect();
            merged.rebuilt = changed.len() as u64;
            let layer = Layer {
                index: p,
                bands: &bands,
                step,
                bounds: grid.bounds.clone(),
                decimation: floors,
                prepared: None,
                base: (p > 0).then_some(heights.as_ref()),
            };
            // Whole tile rows are built; the changed tiles of each are kept.
            let mut rows: Vec<u32> = changed
                .iter()
                .map(|&t| (t / tiles_x as usize) as u32)
                .collect();
            rows.dedup();
            for row in rows {
                let mut keep = |t: usize, (b, _): (BuiltTile, _), errors: &[f32]| {
                    if changed.binary_search(&t).is_ok() {
                        if p == 0 {
                            deviation[t] = b.deviation;
                        }
                        rebuilt.insert(t, (b.blob, errors.to_vec()));
                    }
                    Ok(())
                };
                build_tiles(&layer, params, Some(&agreed), row..row + 1, &mut keep)?;
            }
            if units_of(&grid.bounds, &deviation) != agreed.units {
                return Err(BuildError::Internal(
                    "a tile built again at the seams passed the set's morph units".into(),
                ));
            }
        }
        units = units_of(&grid.bounds, &deviation);
    }
    // Each tile's blob as the set holds it: rebuilt above, sealed again at the grid's units
    // (on every core: it is most of a merge's work when the units differ), or as the part has
    // it. Written in row-major order, as the build writes them. With compact levels a part
    // holds each tile as the set stores it: one sealed again keeps its stream under a new
    // table and checksum, and the rest are copied once their streams decode as their tables
    // say.
    let compact = grid.row_owner[0].header.flags & FLAG_COMPACT_LEVELS != 0;
    let shape = (params.levels, grid.step);
    let xy = |t: usize| ((t % tiles_x as usize) as u32, (t / tiles_x as usize) as u32);
    let make = |t: usize| -> Result<Made, BuildError> {
        let part = grid.owner(t);
        let failed = |what: String| {
            let (path, name) = (part.path.display(), grid.tile_name(xy(t)));
            BuildError::Input(format!("{path}: {name}: {what}"))
        };
        if rebuilt.contains_key(&t) {
            return Ok(Made::Rebuilt);
        }
        let stored = grid.tile(t).blob;
        if !params.shared_sides || part.grid_units(p) == &units[..] {
            let entries = stored_tile_table(stored, xy(t), shape, compact).map_err(failed)?;
            return Ok(Made::Copied(entries));
        }
        let out = match compact {
            true => reseal_compact_tile(stored, xy(t), shape, &units),
            false => reseal(stored, xy(t), params.levels, grid.step, &units),
        };
        let out = out.map_err(failed)?;
        let entries = stored_tile_table(&out, xy(t), shape, compact).map_err(failed)?;
        Ok(Made::Resealed(out, entries))
    };
    let in_flight = 2 * rayon::current_num_threads();
    crate::ordered::in_order(count, in_flight, make, |t, made| {
        let tile = grid.tile(t);
        let (tx, ty) = xy(t);
        let d = tile.decimation;
        let entries = match made? {
            Made::Rebuilt => {
                let (blob, errors) = &rebuilt[&t];
                writer.add_layer_tile(p, tx, ty, blob, d, errors)?;
                match levels {
                    Some(_) => Tile::parse(blob, tx, ty, params.levels, grid.step)
                        .map_err(|what| {
                            BuildError::Internal(format!(
                                "tile {tx},{ty} of the merged set: {what}"
                            ))
                        })?
                        .levels()
                        .to_vec(),
                    None => Vec::new(),
                }
            }
            Made::Resealed(stored, entries) => {
                merged.resealed += 1;
                writer.add_stored_layer_tile(p, (tx, ty), &stored, d, &tile.errors)?;
                entries
            }
            Made::Copied(entries) => {
                writer.add_stored_layer_tile(p, (tx, ty), tile.blob, d, &tile.errors)?;
                entries
            }
        };
        if let Some(levels) = levels.as_deref_mut() {
            for (sum, e) in levels.iter_mut().zip(&entries) {
                sum.vertices += u64::from(e.vertex_count());
                sum.triangles += u64::from(e.triangle_count);
                sum.max_error = sum.max_error.max(f64::from(e.max_error));
            }
        }
        if !tile.texture.is_empty() {
            writer.add_layer_texture(p, tx, ty, tile.texture)?;
        }
        grid.owner(t).release_grid_tile(p, t);
        merged.tiles += 1;
        progress();
        Ok::<(), BuildError>(())
    })?;
    Ok(merged)
}

/// What the merge makes of a part's tile before it is written, with its level table.
enum Made {
    /// Built again from the input (the agreement moved its sides): written as built.
    Rebuilt,
    /// Sealed again at the set's morph units: the bytes to store.
    Resealed(Vec<u8>, Vec<crate::format::LevelEntry>),
    /// Copied as the part stores it.
    Copied(Vec<crate::format::LevelEntry>),
}

/// The agreement's state as the parts recorded it, for tiles `0..count` of a layer (`tile`
/// reads each from its owner): where the merge checks for the fixed point, and resumes from.
fn recorded_start<'p>(count: usize, tile: impl Fn(usize) -> PartTile<'p>) -> Start {
    let mut start = Start {
        sides: Vec::with_capacity(count),
        forced: Vec::with_capacity(count),
        deviation: Vec::with_capacity(count),
    };
    for t in 0..count {
        let tile = tile(t);
        start.sides.push(tile.sides);
        start.forced.push(tile.forced);
        start.deviation.push(tile.deviation);
    }
    start
}

/// Tiles whose recorded forced sides are not what their own and their neighbours' recorded
/// sides force: where the shards' states do not make a fixed point.
fn unsettled_tiles(start: &Start, tiles_x: u32, levels: u32) -> usize {
    let tiles = (tiles_x, (start.sides.len() / tiles_x as usize) as u32);
    (0..start.sides.len())
        .filter(|&t| forced_sides(t, &start.sides, levels as usize, tiles) != start.forced[t])
        .count()
}

/// A version 3 tile blob sealed again with the morph units `units`: its vertex sets and
/// height codes read back, and the build's assembly run over them
/// ([`crate::build::rebuild_tile`]), so the bytes are those a build at `units` makes.
fn reseal(
    blob: &[u8],
    (tx, ty): (u32, u32),
    levels: u32,
    step: f32,
    units: &[f64],
) -> Result<Vec<u8>, String> {
    let tile = Tile::parse(blob, tx, ty, levels, step)?;
    let sets: Vec<Vec<(u32, u32, u16)>> = (0..levels)
        .map(|j| {
            let level = tile.level(j).ok_or("a level is missing")?;
            Ok(level
                .positions
                .iter()
                .map(|&p| crate::pack::unpack(p))
                .collect())
        })
        .collect::<Result<_, String>>()?;
    let mut entries = tile.levels().to_vec();
    for (e, &u) in entries.iter_mut().zip(units) {
        e.morph_unit = u as f32;
    }
    let numbering = crate::build::Numbering::Decode;
    Ok(crate::build::rebuild_tile(
        &tile.header,
        &entries,
        &sets,
        numbering,
    ))
}
