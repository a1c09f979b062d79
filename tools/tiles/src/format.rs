//! The `.vkt` tile-set file: one memory-mappable file per dataset.
//!
//! Layout (all integers and floats little-endian, every section 4-byte aligned, tiles 16-byte
//! aligned):
//!
//! ```text
//! FileHeader      256 bytes   magic "VKTILES\0", version, grid, spacing, levels, pyramid layers,
//!                             crc of header and every directory
//! DirEntry * T    40 bytes    per tile (row-major by tile): offset, length, crc32 of the tile blob,
//!                             the tile's decimation error (0 for the base grid), offset and
//!                             length of the tile's texture blob (0 = none)
//! LayerHeader * P 64 bytes    version 3: per pyramid layer p = 1..=P above the base grid (see
//!                             "The tile pyramid" below)
//! DirEntry * T_p  40 bytes    per tile of layer p, p = 1..=P, as the base's
//! f32 * T_p * L   4 bytes     per tile of layer p and level, the level's error against the base
//!                             grid's samples under the tile
//! tile blobs      ...         TileHeader, LevelEntry * levels, then per level i:
//!                               block i positions   block_len * u32 (packed vertex, see `pack`)
//!                               block i morph       i * block_len * i8, level-major (see `pack`)
//!                               level i indices     index_count * u16|u32, restart = all ones
//!                               level i border      4 lists of u32 vertex indices (N, E, S, W)
//! texture blobs   ...         version 2, when `texture_format` is BC1: per tile a
//!                             `TextureHeader`, `MipEntry * mips`, each mip's BC1 blocks
//!                             (see [`crate::texture`] for the layout and the texel mapping)
//! ```
//!
//! Version 5 ([`FLAG_COMPACT_LEVELS`]) keeps each tile's header and level table, then the
//! crc32 of the version 3 blob, each level's bytes in the stream (u32 each, so that one level's
//! stream can be handed to a decoder alone: a refinement on the bus) and the levels as
//! [`crate::compact`]'s bit stream, from which a reader rebuilds the version 3 blob;
//! everything else is as in version 3. Its blocks number
//! their vertices in the order the stream decodes them ([`Numbering::Decode`], as version 3
//! files are written since); version 4, read still, is the same with each block in the order
//! its fans first use its vertices ([`Numbering::FirstUse`]), which only a rebuild of the
//! whole tile on the CPU can give, and without the level lengths.
//!
//! Version 1 files (no texture fields) are still read, as tile sets without textures; version 2
//! files (no pyramid: the field was reserved and zero) as tile sets without a pyramid.
//!
//! # The tile pyramid (version 3)
//!
//! Above the base grid's tiles, layer `p` holds tiles of the grid subsampled by `f = 2^p`: its
//! sample `(x, y)` is the base sample `(min(f x, W-1), min(f y, H-1))`, so a layer has
//! `ceil((W-1)/f) + 1` columns and each of its tiles covers 2 x 2 tiles of layer `p-1`, up to
//! the last layer, one tile. Where `W-1` is not a multiple of `f` the last column repeats the
//! base's last one, `< f` base columns beyond the data (and the same for rows). A layer's tiles
//! are ordinary tiles of that grid, with their own nested levels, shared sides and textures, so
//! [`TileSet::layer`] hands a layer out as a tile set of its own.
//!
//! A level's `max_error` (and the rest of its entry) is measured against the layer's samples,
//! as in any tile. What a renderer chooses a layer tile by is its error against the ground it
//! stands for: the layer's error table holds, per tile and level, the largest distance of the
//! base grid's samples under the tile from the level ([`TileSet::base_errors`]). It is at most
//! `max_error + D`, where `D` is the tile's decimation error, stored in its directory entry: a
//! bound on how far any base sample lies from the layer's finest surface, which grows with the
//! worst sample of the tile and is far looser at coarse levels than the measured table. Both
//! are argued and computed in [`crate::pyramid`]; `tiletool verify --source` recomputes the
//! table and checks the bound. A layer tile's level `i` is built to `max(e_i, D / 4)`
//! ([`crate::pyramid::level_floor`]), its `error_bound`; verify holds it to that.
//! `LevelEntry::side_errors` (each level's error near each side) took the entry's last,
//! formerly reserved and zero, four bytes within version 2: a zero code reads as the whole
//! level's error, so files from before it read as they did, and readers from before it ignore
//! the codes.
//!
//! Writing goes to a hidden temporary file in the destination folder which is renamed over the
//! destination only after everything, header last, is written and synced: an interrupted build
//! never leaves a file that looks valid. Reading validates the header, the directory, each
//! tile's checksum and every count, offset and index before handing out slices, so a corrupted
//! or hostile file gives a [`FormatError`], never a panic or an out-of-bounds read.

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::mem::size_of;
use std::path::{Path, PathBuf};

use bytemuck::{Pod, Zeroable};

use crate::build::Numbering;
use crate::mesh::TILE_CELLS;
use crate::quantise::Quantiser;
use crate::texture;

pub const MAGIC: [u8; 8] = *b"VKTILES\0";
pub const TILE_MAGIC: [u8; 4] = *b"TILE";
pub const VERSION: u32 = 3;
/// The version of files whose tiles hold compact levels ([`FLAG_COMPACT_LEVELS`]); other files
/// are still written as [`VERSION`], which readers of version 3 read.
pub const COMPACT_VERSION: u32 = 5;
/// The first compact version, read still: its blocks in [`Numbering::FirstUse`] order.
pub const FIRST_COMPACT_VERSION: u32 = 4;
/// The writer of a compact file rebuilds one tile in this many and compares it with the tile
/// built (the tiles with `(tx + 3 ty) % FULL_CHECK_EVERY == 0`: some in every row and column).
pub const FULL_CHECK_EVERY: u32 = 8;

/// How a compact file of `version` numbers its blocks' vertices.
pub fn numbering(version: u32) -> Numbering {
    if version == FIRST_COMPACT_VERSION {
        Numbering::FirstUse
    } else {
        Numbering::Decode
    }
}
/// The oldest version this reader reads: version 1 had no textures and zeros in their fields.
pub const OLDEST_VERSION: u32 = 1;

/// `FileHeader::flags`: every two neighbouring tiles have the same vertices on their shared
/// side at every level, with the same heights and the same morph offsets (every tile uses the
/// same morph unit per level). Geomorphing then gives a side vertex the same height from both
/// tiles, bit for bit. Files without it (built with `--independent-sides`, or by older
/// builders) are read the same way; the renderer closes their morphing seams with slivers.
pub const FLAG_SHARED_SIDES: u32 = 1;
/// `FileHeader::flags` (versions 4 and 5, and only there): each tile's blob holds its header and level
/// table as version 3 does, the crc32 of its version 3 blob, then its levels as
/// [`crate::compact`]'s bit stream in place of the sections; a reader rebuilds the version 3
/// blob from them ([`crate::compact::rebuild`], once per tile, kept), checks it against that
/// crc, and reads it.
pub const FLAG_COMPACT_LEVELS: u32 = 2;
/// The most levels a tile set may have (one morph byte per coarser level per vertex).
pub const MAX_LEVELS: u32 = 16;
/// Index value that restarts a fan (all ones at the index width).
pub const RESTART_U16: u16 = u16::MAX;
pub const RESTART_U32: u32 = u32::MAX;

/// The level table after a tile's header in `stored` (which holds it).
fn stored_entries(stored: &[u8], levels: u32) -> Vec<LevelEntry> {
    (0..levels as usize)
        .map(|i| {
            let at = size_of::<TileHeader>() + i * size_of::<LevelEntry>();
            bytemuck::pod_read_unaligned(&stored[at..at + size_of::<LevelEntry>()])
        })
        .collect()
}

/// Bytes of a tile's header and level table.
fn table_len(levels: u32) -> usize {
    size_of::<TileHeader>() + levels as usize * size_of::<LevelEntry>()
}

/// Where a compact tile's bit stream starts in its stored bytes: after its header and level
/// table, the crc32 of its version 3 blob and (version 5) each level's bytes in the stream.
fn stream_start(levels: u32, version: u32) -> usize {
    let lengths = if version == FIRST_COMPACT_VERSION {
        0
    } else {
        4 * levels as usize
    };
    table_len(levels) + 4 + lengths
}

/// A version 5 compact tile's stored level lengths (`stored` holds them).
fn stored_lengths(stored: &[u8], levels: u32) -> Vec<u32> {
    let at = table_len(levels) + 4;
    stored[at..at + 4 * levels as usize]
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")))
        .collect()
}

/// A version 3 tile blob as a compact one: its header and level table, then its levels'
/// bit stream. The stream is decoded here and must give back every level's vertices and
/// height codes, in order, so that a file never holds a stream that does not decode to the
/// tile built. What a reader makes of those vertices (fans, order, borders, morph offsets)
/// is the build's own assembly run again ([`crate::build::rebuild_tile`]); it is rebuilt
/// and compared byte for byte here on one tile in [`FULL_CHECK_EVERY`] (a deterministic
/// sample, every layer's first tile among them), on every tile by `tiletool verify`, and
/// against the stored checksum wherever a tile is read. Rebuilding every tile here cost
/// 11% of a build (N48W125, perf). A shard of a compact build stores its tiles so, and the
/// merge copies them.
pub fn compact_tile(
    blob: &[u8],
    (tx, ty): (u32, u32),
    (levels, step): (u32, f32),
) -> Result<Vec<u8>, String> {
    let tile = Tile::parse(blob, tx, ty, levels, step)?;
    let table = table_len(levels);
    let mut out = blob[..table].to_vec();
    out.extend(crc32fast::hash(blob).to_le_bytes());
    let (stream, lengths) = crate::compact::encode_levels(&tile);
    let (sets, _) = crate::compact::decode_levels(&stream, levels)?;
    for (j, set) in sets.iter().enumerate() {
        let built = tile
            .level(j as u32)
            .map(|l| l.positions)
            .unwrap_or_default();
        let decoded = set.iter().map(|&(x, y, c)| crate::pack::pack(x, y, c));
        if built.len() != set.len() || !decoded.eq(built.iter().copied()) {
            return Err(format!(
                "its compact level {j} does not decode to its vertices"
            ));
        }
    }
    out.extend(bytemuck::cast_slice(&lengths));
    out.extend(stream);
    if (tx + 3 * ty).is_multiple_of(FULL_CHECK_EVERY) {
        let made = rebuilt(&out, (tx, ty), (levels, step), COMPACT_VERSION, levels)?;
        if made != blob {
            return Err("its compact levels do not rebuild it".into());
        }
    }
    Ok(out)
}

/// Compact (version 5) tile `(tx, ty)`'s stored bytes with its levels' morph units set to
/// `units`: what a merge stores for a part's tile sealed at smaller units than the set's. Its
/// stream is decoded (checked as [`stored_tile_table`] checks it) and is kept as it is: the
/// vertices and height codes do not depend on the units. The table takes the units, and the
/// checksum is that of the version 3 blob the build's assembly makes of those vertices at
/// them ([`crate::build::rebuild_tile`]). The same bytes as [`compact_tile`] of the tile
/// sealed at `units`, with one assembly instead of an expansion, a seal and an encoding.
///
/// The new checksum is made, not checked, so a stream that decodes but is not the one the
/// shard encoded would be sealed as if it were. The part's own checksum covers its bytes
/// between the shard and the merge, and the tiles [`compact_tile`] rebuilds in full (one in
/// [`FULL_CHECK_EVERY`]) are rebuilt here at their old units too and must give their stored
/// checksum.
pub fn reseal_compact_tile(
    stored: &[u8],
    (tx, ty): (u32, u32),
    shape: (u32, f32),
    units: &[f64],
) -> Result<Vec<u8>, String> {
    let (header, mut entries, sets) = compact_levels(stored, (tx, ty), shape)?;
    let numbering = numbering(COMPACT_VERSION);
    let table = table_len(shape.0);
    if (tx + 3 * ty).is_multiple_of(FULL_CHECK_EVERY) {
        let old = crate::build::rebuild_tile(&header, &entries, &sets, numbering);
        if crc32fast::hash(&old).to_le_bytes()[..] != stored[table..table + 4] {
            return Err("its compact levels rebuild a tile that fails its checksum".into());
        }
    }
    for (e, &u) in entries.iter_mut().zip(units) {
        e.morph_unit = u as f32;
    }
    let blob = crate::build::rebuild_tile(&header, &entries, &sets, numbering);
    let mut out = blob[..table].to_vec();
    out.extend(crc32fast::hash(&blob).to_le_bytes());
    out.extend(&stored[table + 4..]);
    Ok(out)
}

/// The level table of tile `(tx, ty)`'s stored bytes, checked as far as a copy needs, without
/// a rebuild: a version 3 blob parsed whole ([`Tile::parse`]); a compact (version 5) tile's
/// header and table, and its stream decoded to as many vertices a level as the table says,
/// each level ending where its length says. What only a rebuild shows (the checksum of the
/// version 3 blob) is checked by every reader and by `tiletool verify`.
pub fn stored_tile_table(
    stored: &[u8],
    (tx, ty): (u32, u32),
    (levels, step): (u32, f32),
    compact: bool,
) -> Result<Vec<LevelEntry>, String> {
    match compact {
        true => Ok(compact_levels(stored, (tx, ty), (levels, step))?.1),
        false => Ok(Tile::parse(stored, tx, ty, levels, step)?.levels().to_vec()),
    }
}

/// A compact tile's header and level table from its stored bytes, checked as [`Tile::parse`]
/// checks them; the bytes must reach `start`, where its stream begins.
fn stored_table(
    stored: &[u8],
    (tx, ty): (u32, u32),
    (levels, step): (u32, f32),
    start: usize,
) -> Result<(TileHeader, Vec<LevelEntry>), String> {
    if stored.len() < start {
        return Err(format!(
            "{} bytes is too short for a tile's table",
            stored.len()
        ));
    }
    let header: TileHeader = bytemuck::pod_read_unaligned(&stored[..size_of::<TileHeader>()]);
    check_tile_header(&header, tx, ty, levels, step)?;
    let entries = stored_entries(stored, levels);
    check_table(&header, &entries)?;
    Ok((header, entries))
}

/// A compact (version 5) tile's header, level table and decoded levels, checked: the header
/// and table as [`Tile::parse`] checks them, each level decoded to as many vertices as its
/// entry says and ending where its stored length says.
fn compact_levels(
    stored: &[u8],
    (tx, ty): (u32, u32),
    (levels, step): (u32, f32),
) -> Result<(TileHeader, Vec<LevelEntry>, crate::compact::LevelSets), String> {
    let start = stream_start(levels, COMPACT_VERSION);
    let (header, entries) = stored_table(stored, (tx, ty), (levels, step), start)?;
    let (sets, ranges) = crate::compact::decode_levels(&stored[start..], levels)?;
    let lengths = stored_lengths(stored, levels);
    for (j, ((set, range), e)) in sets.iter().zip(&ranges).zip(&entries).enumerate() {
        if set.len() != e.block_len as usize {
            return Err(format!(
                "its compact level {j} decodes to {} vertices, its table says {}",
                set.len(),
                e.block_len
            ));
        }
        if range.len() != lengths[j] as usize {
            return Err(format!(
                "level {j}'s stream is {} bytes, its length says {}",
                range.len(),
                lengths[j]
            ));
        }
    }
    Ok((header, entries, sets))
}

/// The version 3 blob of a compact tile's stored bytes (its header and level table, the crc32
/// of the version 3 blob, in version 5 each level's bytes in the stream, then its levels' bit
/// stream), or what is wrong with them: the header as [`Tile::parse`] checks it, the stream as
/// [`crate::compact::decode`] does, each level ending where its length says, and the blob
/// rebuilt must have the stored table and checksum (the file's own checksum covers the stored
/// bytes; this one, what a decoder made of them).
///
/// With `count` below the tile's level count (version 5: the levels' lengths say where the
/// first levels' streams end), the blob of its first `count` levels alone: the full blob's
/// first bytes, through those levels' sections, under the stored table. Their rebuilt entries
/// must be the stored ones; the checksum, which covers every level, waits for the whole tile.
fn rebuilt(
    stored: &[u8],
    (tx, ty): (u32, u32),
    (levels, step): (u32, f32),
    version: u32,
    count: u32,
) -> Result<Vec<u8>, String> {
    let table = table_len(levels);
    let start = stream_start(levels, version);
    let (header, entries) = stored_table(stored, (tx, ty), (levels, step), start)?;
    let crc = u32::from_le_bytes(stored[table..table + 4].try_into().expect("4 bytes"));
    let lengths = match version {
        FIRST_COMPACT_VERSION => Vec::new(),
        _ => stored_lengths(stored, levels),
    };
    let count = match lengths.is_empty() {
        true => levels,
        false => count.clamp(1, levels),
    };
    let end = match count < levels {
        true => {
            start as u64
                + lengths[..count as usize]
                    .iter()
                    .map(|&n| u64::from(n))
                    .sum::<u64>()
        }
        false => stored.len() as u64,
    };
    let streams = usize::try_from(end)
        .ok()
        .and_then(|end| stored.get(start..end))
        .ok_or("its levels' lengths run past its stream")?;
    let (mut blob, ranges) =
        crate::compact::rebuild_levels(&header, &entries, streams, count, numbering(version))?;
    if let Some(j) = ranges
        .iter()
        .zip(&lengths)
        .position(|(r, &n)| r.len() != n as usize)
    {
        return Err(format!(
            "level {j}'s stream is {} bytes, its length says {}",
            ranges[j].len(),
            lengths[j]
        ));
    }
    if count < levels {
        let given = table_len(count);
        if blob.get(..given) != Some(&stored[..given]) {
            return Err("its compact levels do not rebuild its level table".into());
        }
        blob[..table].copy_from_slice(&stored[..table]);
        return Ok(blob);
    }
    if blob.get(..table) != Some(&stored[..table]) {
        return Err("its compact levels do not rebuild its level table".into());
    }
    if crc32fast::hash(&blob) != crc {
        return Err("its compact levels rebuild a tile that fails its checksum".into());
    }
    Ok(blob)
}

#[cfg(target_endian = "big")]
compile_error!("the .vkt reader casts little-endian sections in place");

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct FileHeader {
    pub magic: [u8; 8],
    pub version: u32,
    pub header_len: u32,
    pub grid_width: u32,
    pub grid_height: u32,
    pub tiles_x: u32,
    pub tiles_y: u32,
    pub tile_size: u32,
    pub levels: u32,
    /// Metres between columns (east-west) and rows (north-south).
    pub spacing_x: f64,
    pub spacing_y: f64,
    /// `e_{levels-1}` in metres; `e_i = base_error * 2^(levels-1-i)`.
    pub base_error: f64,
    pub height_min: f32,
    pub height_max: f32,
    pub voids_filled: u64,
    pub directory_offset: u64,
    pub directory_entry_len: u32,
    /// [`texture::FORMAT_NONE`] or [`texture::FORMAT_BC1`] (version 2).
    pub texture_format: u32,
    /// Where the heights came from, UTF-8, zero-padded.
    pub description: [u8; 128],
    /// Metres per height code, the same for every tile (see `quantise`).
    pub height_step: f32,
    /// [`FLAG_SHARED_SIDES`], or 0.
    pub flags: u32,
    /// Texture layout: texels across a tile's interior (the gutter and mips follow from it,
    /// see [`texture::Layout`]) and what the texture shows (`texture::SOURCE_*`). Version 2.
    pub texture_interior: u32,
    pub texture_gutter: u32,
    pub texture_mips: u32,
    pub texture_source: u32,
    /// Layers of the tile pyramid above the base grid (version 3; reserved and zero before).
    pub pyramid_layers: u32,
    /// crc32 of this header (with this field zero) followed by the directory, then (version 3)
    /// the layer headers and the layers' directories.
    pub header_crc: u32,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct DirEntry {
    pub offset: u64,
    pub len: u64,
    pub crc: u32,
    /// Metres: how far a base sample may lie from this tile's finest surface (0 in the base
    /// grid; a reserved, zero field before version 3).
    pub decimation_error: f32,
    pub texture_offset: u64,
    pub texture_len: u64,
}

/// One layer of the tile pyramid (version 3), after the base directory.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct LayerHeader {
    pub grid_width: u32,
    pub grid_height: u32,
    pub tiles_x: u32,
    pub tiles_y: u32,
    /// Base samples per layer sample, `2^p`.
    pub factor: u32,
    /// The layer's own height lattice step: its tiles span more ground than the base's.
    pub height_step: f32,
    pub spacing_x: f64,
    pub spacing_y: f64,
    pub directory_offset: u64,
    pub height_min: f32,
    pub height_max: f32,
    /// Where the layer's error table starts: per tile (row-major), per level, the level's
    /// largest distance from the base grid's samples under the tile (f32 metres).
    pub errors_offset: u64,
}

/// The most pyramid layers a file may declare: enough for grids of `256 * 2^32` samples a side.
pub const MAX_PYRAMID_LAYERS: u32 = 32;

/// The grid of pyramid layer `p` above a base grid of `width x height` samples: its size and
/// the base samples per layer sample.
pub fn layer_grid(width: usize, height: usize, p: u32) -> (usize, usize, usize) {
    let f = 1usize << p;
    ((width - 1).div_ceil(f) + 1, (height - 1).div_ceil(f) + 1, f)
}

/// Pyramid layers a grid of `width x height` samples gets above its base: until one tile.
pub fn pyramid_layers(width: usize, height: usize) -> u32 {
    let mut p = 0;
    while let Ok((tx, ty)) = {
        let (w, h, _) = layer_grid(width, height, p);
        tile_count(w, h)
    } {
        if (tx, ty) == (1, 1) || p >= MAX_PYRAMID_LAYERS {
            break;
        }
        p += 1;
    }
    p
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct TileHeader {
    pub magic: [u8; 4],
    pub tx: u32,
    pub ty: u32,
    pub levels: u32,
    /// Last local column / row of real data (inclusive).
    pub data_max_x: u32,
    pub data_max_y: u32,
    /// Last local column / row the meshes cover (data extent rounded up to even).
    pub mesh_max_x: u32,
    pub mesh_max_y: u32,
    /// `height_base * height_step`, the lowest height the tile can hold (for reading only).
    pub height_min: f32,
    pub height_step: f32,
    pub vertex_count: u32,
    /// The tile's lowest code on the tile set's height lattice: heights decode as
    /// `(height_base + q) * height_step`.
    pub height_base: i32,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct LevelEntry {
    /// `e_i`, metres.
    pub error_bound: f32,
    /// Measured max |source - mesh| over the tile's real samples, after quantisation, metres.
    pub max_error: f32,
    /// Where the spacing rule (or full resolution) stopped refinement above `e_i`: the largest
    /// excess over `e_i` in metres, and how many fan triangles exceed.
    pub limited_excess: f32,
    pub limited_triangles: u32,
    pub z_min: f32,
    pub z_max: f32,
    /// Metres per unit of this level's morph offsets (stored in finer blocks).
    pub morph_unit: f32,
    /// First vertex of block i; blocks are consecutive, so this is also the number of
    /// vertices in blocks `0..i`.
    pub block_start: u32,
    pub block_len: u32,
    pub positions_offset: u32,
    pub morph_offset: u32,
    pub index_offset: u32,
    pub index_count: u32,
    /// 2 or 4 bytes.
    pub index_width: u32,
    pub triangle_count: u32,
    pub fan_count: u32,
    pub border_offset: u32,
    /// Vertices on the N, E, S, W tile sides at this level.
    pub border_len: [u32; 4],
    /// The level's error near each side (N, E, S, W), as a share of `max_error`: see
    /// [`LevelEntry::side_error`]. 0 where no builder recorded it (a reserved, zero field in
    /// files from before it), which reads as `max_error`.
    pub side_errors: [u8; 4],
}

impl LevelEntry {
    /// Vertices the level draws: blocks `0..=i`.
    pub fn vertex_count(&self) -> u32 {
        self.block_start + self.block_len
    }

    /// The max error of this level over its triangles that touch side `side` (0..4: N, E, S,
    /// W; a triangle touches a side where one of its corners lies on it), after quantisation,
    /// never below the measured figure: `max_error · c / 255` for the stored code `c` in
    /// 1..=255, and `max_error` itself where the code is 0 (not recorded). A vertex on a side
    /// lies in no triangle of any level that misses the side, so this bounds every level's
    /// error wherever its triangles around that vertex reach. The renderer's side level tables
    /// do not use it yet: taken alone it let the error between a triangle's vertices pass tau
    /// (bench/README.md, "Geomorphing").
    pub fn side_error(&self, side: usize) -> f32 {
        side_error_of(self.max_error, self.side_errors[side])
    }
}

/// What code `c` of [`LevelEntry::side_errors`] stands for, for a level whose max error is
/// `max_error`.
pub fn side_error_of(max_error: f32, c: u8) -> f32 {
    match c {
        0 | 255 => max_error,
        c => max_error * (f32::from(c) / 255.0),
    }
}

/// The least code in 1..=255 that [`side_error_of`] reads as at least `measured` metres (the
/// side's measured max error, at most `max_error`); 0, read as `max_error`, if none does.
pub fn side_error_code(max_error: f32, measured: f64) -> u8 {
    (1..=255u8)
        .find(|&c| f64::from(side_error_of(max_error, c)) >= measured)
        .unwrap_or(0)
}

/// What went wrong reading or writing a `.vkt` file; shows as one line naming the file.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// The io error is part of the one-line message, not a separate cause, so that error
    /// chains do not print it twice.
    #[error("{}: {error}", path.display())]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{}: {what}", path.display())]
    Invalid { path: PathBuf, what: String },
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> FormatError + '_ {
    move |error| FormatError::Io {
        path: path.to_path_buf(),
        error,
    }
}

fn align_up(n: u64, a: u64) -> u64 {
    n.div_ceil(a) * a
}

/// The hidden temporary file a build of `path` writes before renaming it into place:
/// `.NAME.tmp.PID` beside it (the PID of this process).
pub fn temp_path(path: &Path) -> Result<PathBuf, FormatError> {
    temp_beside(path).ok_or_else(|| FormatError::Invalid {
        path: path.to_path_buf(),
        what: "not a file name".into(),
    })
}

/// `.NAME.tmp.PID` in `path`'s folder, or `None` when `path` names no file (`/`, `..`).
fn temp_beside(path: &Path) -> Option<PathBuf> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let name = path.file_name()?;
    Some(dir.join(format!(
        ".{}.tmp.{}",
        name.to_string_lossy(),
        std::process::id()
    )))
}

/// Writes `bytes` to `path` through its [`temp_path`], renamed into place, so that no reader
/// (and no later run) ever finds a half-written file under the name; the temporary is removed
/// when writing or renaming fails. For the small outputs of `tiletool export` and `vkterrain`
/// (summaries, traces); a tile set streams through [`TileSetWriter`] instead. The error is the
/// bare io error: callers say which file they could not write.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = temp_beside(path)
        .ok_or_else(|| std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a file name"))?;
    let written = std::fs::write(&tmp, bytes).and_then(|()| std::fs::rename(&tmp, path));
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// Removes temporaries of earlier builds of `path` whose process is provably gone (a build
/// killed with SIGKILL cannot clean up after itself): `.NAME.tmp.PID` with no `/proc/PID`.
/// A live process's file, or one that cannot be checked, is left alone.
pub(crate) fn remove_stale_temporaries(path: &Path) {
    let (Some(dir), Some(name)) = (path.parent(), path.file_name()) else {
        return;
    };
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    if !Path::new("/proc/self").exists() {
        return; // no way to prove a process dead
    }
    let prefix = format!(".{}.tmp.", name.to_string_lossy());
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let file = entry.file_name();
        let Some(pid) = file
            .to_str()
            .and_then(|f| f.strip_prefix(&prefix))
            .and_then(|p| p.parse::<u32>().ok())
        else {
            continue;
        };
        let alive = Path::new(&format!("/proc/{pid}")).exists();
        if pid != std::process::id() && !alive {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

/// The layer headers a header's grid and `pyramid_layers` imply (their height fields zero),
/// laid out after the base directory, and where the last directory ends.
pub fn layer_layout(h: &FileHeader) -> Result<(Vec<LayerHeader>, u64), String> {
    let (w, hh) = (h.grid_width as usize, h.grid_height as usize);
    let (tx, ty) = tile_count(w, hh)?;
    let layers = if h.version >= 3 { h.pyramid_layers } else { 0 };
    if layers > MAX_PYRAMID_LAYERS || layers > pyramid_layers(w, hh) {
        return Err(format!(
            "{layers} pyramid layers, but a {w}x{hh} grid has {} at most",
            pyramid_layers(w, hh)
        ));
    }
    let entry = size_of::<DirEntry>() as u64;
    let mut at = size_of::<FileHeader>() as u64 + u64::from(tx) * u64::from(ty) * entry;
    at += u64::from(layers) * size_of::<LayerHeader>() as u64;
    let mut out = Vec::with_capacity(layers as usize);
    for p in 1..=layers {
        let (lw, lh, f) = layer_grid(w, hh, p);
        let (ltx, lty) = tile_count(lw, lh)?;
        out.push(LayerHeader {
            grid_width: lw as u32,
            grid_height: lh as u32,
            tiles_x: ltx,
            tiles_y: lty,
            factor: f as u32,
            spacing_x: h.spacing_x * f as f64,
            spacing_y: h.spacing_y * f as f64,
            directory_offset: at,
            ..LayerHeader::default()
        });
        at += u64::from(ltx) * u64::from(lty) * entry;
    }
    // The layers' error tables, after the directories.
    for l in &mut out {
        l.errors_offset = at;
        at += u64::from(l.tiles_x) * u64::from(l.tiles_y) * u64::from(h.levels) * 4;
    }
    Ok((out, at))
}

/// Writes a tile set to a temporary file and renames it into place on [`finish`](Self::finish).
/// Dropped unfinished, it deletes the temporary file. Tiles of every pyramid layer go into the
/// one file; `header.pyramid_layers` says how many layers there are.
pub struct TileSetWriter {
    path: PathBuf,
    tmp_path: PathBuf,
    file: Option<BufWriter<File>>,
    header: FileHeader,
    layers: Vec<LayerHeader>,
    /// Per layer (0: the base), its directory and which tiles were written.
    directories: Vec<Vec<DirEntry>>,
    /// Per layer above the base, its error table (tiles x levels).
    errors: Vec<Vec<f32>>,
    written: Vec<Vec<bool>>,
    pos: u64,
}

impl TileSetWriter {
    pub fn create(path: &Path, header: FileHeader) -> Result<Self, FormatError> {
        let header = FileHeader {
            version: if header.flags & FLAG_COMPACT_LEVELS != 0 {
                COMPACT_VERSION
            } else {
                VERSION
            },
            ..header
        };
        let (layers, dir_end) = layer_layout(&header).map_err(|what| FormatError::Invalid {
            path: path.to_path_buf(),
            what: format!("internal: {what}"),
        })?;
        let tmp_path = temp_path(path)?;
        remove_stale_temporaries(path);
        let file = File::create(&tmp_path).map_err(io_err(path))?;
        let counts = std::iter::once(header.tiles_x as usize * header.tiles_y as usize).chain(
            layers
                .iter()
                .map(|l| l.tiles_x as usize * l.tiles_y as usize),
        );
        let pos = align_up(dir_end, 16);
        let mut writer = TileSetWriter {
            path: path.to_path_buf(),
            tmp_path,
            file: Some(BufWriter::with_capacity(1 << 20, file)),
            header,
            directories: counts
                .clone()
                .map(|n| vec![DirEntry::default(); n])
                .collect(),
            written: counts.map(|n| vec![false; n]).collect(),
            errors: layers
                .iter()
                .map(|l| vec![0.0; (l.tiles_x * l.tiles_y * header.levels) as usize])
                .collect(),
            layers,
            pos,
        };
        writer.seek(pos)?;
        Ok(writer)
    }

    /// The pyramid layers above the base, as they will be written (height fields as set).
    pub fn layers(&self) -> &[LayerHeader] {
        &self.layers
    }

    /// Layer `p`'s (>= 1) height lattice step and height range.
    pub fn set_layer_heights(&mut self, p: u32, step: f32, lo: f32, hi: f32) {
        let l = &mut self.layers[p as usize - 1];
        (l.height_step, l.height_min, l.height_max) = (step, lo, hi);
    }

    fn file(&mut self) -> &mut BufWriter<File> {
        self.file
            .as_mut()
            .expect("the file lives until finish or drop")
    }

    fn seek(&mut self, pos: u64) -> Result<(), FormatError> {
        let path = self.path.clone();
        self.file()
            .seek(SeekFrom::Start(pos))
            .map_err(io_err(&path))?;
        Ok(())
    }

    fn write(&mut self, bytes: &[u8]) -> Result<(), FormatError> {
        let path = self.path.clone();
        self.file().write_all(bytes).map_err(io_err(&path))
    }

    fn slot(&self, layer: u32, tx: u32, ty: u32) -> usize {
        let tiles_x = match layer {
            0 => self.header.tiles_x,
            p => self.layers[p as usize - 1].tiles_x,
        };
        ty as usize * tiles_x as usize + tx as usize
    }

    /// Appends tile `(tx, ty)`'s blob (tiles may arrive in any order).
    pub fn add_tile(&mut self, tx: u32, ty: u32, blob: &[u8]) -> Result<(), FormatError> {
        self.add_layer_tile(0, tx, ty, blob, 0.0, &[])
    }

    /// Appends tile `(tx, ty)` of pyramid layer `layer` (0: the base grid) with its decimation
    /// error and, above the base, each level's error against the base grid's samples.
    pub fn add_layer_tile(
        &mut self,
        layer: u32,
        tx: u32,
        ty: u32,
        blob: &[u8],
        decimation_error: f32,
        base_errors: &[f32],
    ) -> Result<(), FormatError> {
        let compacted;
        let blob = if self.header.flags & FLAG_COMPACT_LEVELS != 0 {
            compacted = self.compacted(layer, tx, ty, blob)?;
            &compacted[..]
        } else {
            blob
        };
        self.put_layer_tile(layer, (tx, ty), blob, decimation_error, base_errors)
    }

    /// Appends base tile `(tx, ty)`'s bytes as the file stores them: with compact levels, what
    /// [`compact_tile`] made of its version 3 blob (a merge copies a part's tiles so), else
    /// the blob itself.
    pub fn add_stored_tile(&mut self, tx: u32, ty: u32, stored: &[u8]) -> Result<(), FormatError> {
        self.put_layer_tile(0, (tx, ty), stored, 0.0, &[])
    }

    /// [`add_stored_tile`](Self::add_stored_tile) for a tile of pyramid layer `layer`, with its
    /// decimation error and its levels' errors against the base grid (a merge copies the
    /// layers' tiles that the shards built).
    pub fn add_stored_layer_tile(
        &mut self,
        layer: u32,
        (tx, ty): (u32, u32),
        stored: &[u8],
        decimation_error: f32,
        base_errors: &[f32],
    ) -> Result<(), FormatError> {
        self.put_layer_tile(layer, (tx, ty), stored, decimation_error, base_errors)
    }

    fn put_layer_tile(
        &mut self,
        layer: u32,
        (tx, ty): (u32, u32),
        blob: &[u8],
        decimation_error: f32,
        base_errors: &[f32],
    ) -> Result<(), FormatError> {
        let slot = self.slot(layer, tx, ty);
        if layer > 0 {
            let n = self.header.levels as usize;
            if base_errors.len() != n {
                return Err(FormatError::Invalid {
                    path: self.path.clone(),
                    what: format!("internal: {} errors for {n} levels", base_errors.len()),
                });
            }
            self.errors[layer as usize - 1][slot * n..][..n].copy_from_slice(base_errors);
        }
        let pad = align_up(self.pos, 16) - self.pos;
        self.write(&[0u8; 16][..pad as usize])?;
        self.pos += pad;
        self.directories[layer as usize][slot] = DirEntry {
            offset: self.pos,
            len: blob.len() as u64,
            crc: crc32fast::hash(blob),
            decimation_error,
            ..DirEntry::default()
        };
        self.written[layer as usize][slot] = true;
        self.write(blob)?;
        self.pos += blob.len() as u64;
        Ok(())
    }

    /// [`compact_tile`] for tile `(tx, ty)` of pyramid layer `layer`, at that layer's step.
    fn compacted(&self, layer: u32, tx: u32, ty: u32, blob: &[u8]) -> Result<Vec<u8>, FormatError> {
        let step = match layer {
            0 => self.header.height_step,
            p => self.layers[p as usize - 1].height_step,
        };
        compact_tile(blob, (tx, ty), (self.header.levels, step)).map_err(|what| {
            FormatError::Invalid {
                path: self.path.clone(),
                what: format!("internal: tile {tx},{ty} of layer {layer}: {what}"),
            }
        })
    }

    /// Appends tile `(tx, ty)`'s texture blob (after its tile, in any order).
    pub fn add_texture(&mut self, tx: u32, ty: u32, blob: &[u8]) -> Result<(), FormatError> {
        self.add_layer_texture(0, tx, ty, blob)
    }

    /// [`add_texture`](Self::add_texture) for a tile of pyramid layer `layer`.
    pub fn add_layer_texture(
        &mut self,
        layer: u32,
        tx: u32,
        ty: u32,
        blob: &[u8],
    ) -> Result<(), FormatError> {
        let slot = self.slot(layer, tx, ty);
        let pad = align_up(self.pos, 16) - self.pos;
        self.write(&[0u8; 16][..pad as usize])?;
        self.pos += pad;
        let e = &mut self.directories[layer as usize][slot];
        e.texture_offset = self.pos;
        e.texture_len = blob.len() as u64;
        self.write(blob)?;
        self.pos += blob.len() as u64;
        Ok(())
    }

    /// Writes the directories and the header, syncs, and renames the file into place.
    pub fn finish(mut self) -> Result<(), FormatError> {
        for (p, written) in self.written.iter().enumerate() {
            if let Some(missing) = written.iter().position(|w| !w) {
                return Err(FormatError::Invalid {
                    path: self.path.clone(),
                    what: format!("internal: tile {missing} of layer {p} was never written"),
                });
            }
        }
        let mut header = self.header;
        header.magic = MAGIC;
        header.header_len = size_of::<FileHeader>() as u32;
        header.directory_offset = size_of::<FileHeader>() as u64;
        header.directory_entry_len = size_of::<DirEntry>() as u32;
        let mut directory: Vec<u8> = bytemuck::cast_slice(&self.directories[0]).to_vec();
        directory.extend_from_slice(bytemuck::cast_slice(&self.layers));
        for d in &self.directories[1..] {
            directory.extend_from_slice(bytemuck::cast_slice(d));
        }
        for e in &self.errors {
            directory.extend_from_slice(bytemuck::cast_slice(e));
        }
        header.header_crc = 0;
        header.header_crc = header_crc(&header, &directory);
        self.seek(0)?;
        self.write(bytemuck::bytes_of(&header))?;
        self.write(&directory)?;
        let path = self.path.clone();
        let file = self.file.take().expect("the file lives until finish");
        let file = file.into_inner().map_err(|e| FormatError::Io {
            path: path.clone(),
            error: e.into_error(),
        })?;
        file.sync_all().map_err(io_err(&path))?;
        drop(file);
        std::fs::rename(&self.tmp_path, &self.path).map_err(io_err(&path))?;
        Ok(())
    }
}

impl Drop for TileSetWriter {
    fn drop(&mut self) {
        if self.file.take().is_some() {
            let _ = std::fs::remove_file(&self.tmp_path);
        }
    }
}

/// Largest |height| and spacing a tile set may declare, metres: far beyond any planet's relief
/// and any useful grid, well inside what f32 arithmetic handles.
const MAX_METRES: f64 = 1e7;

/// What is wrong with the header's numbers, if anything: every one finite, spacings and the
/// base error positive, the height range ordered, all within [`MAX_METRES`].
fn header_numbers(h: &FileHeader) -> Option<String> {
    let positive = |v: f64| v.is_finite() && v > 0.0 && v <= MAX_METRES;
    if !positive(h.spacing_x) || !positive(h.spacing_y) {
        return Some(format!(
            "spacing {} x {} m is not a positive size up to {MAX_METRES} m",
            h.spacing_x, h.spacing_y
        ));
    }
    if !positive(h.base_error) {
        return Some(format!("base error {} m is not positive", h.base_error));
    }
    let (lo, hi) = (f64::from(h.height_min), f64::from(h.height_max));
    if !(lo.is_finite() && hi.is_finite() && lo <= hi && lo.abs().max(hi.abs()) <= MAX_METRES) {
        return Some(format!(
            "height range {lo}..{hi} m is not an ordered, finite range"
        ));
    }
    None
}

/// What is wrong with a level's numbers, if anything: bound positive, errors and morph unit
/// finite and not negative, z range ordered and finite.
fn level_numbers(e: &LevelEntry) -> Option<String> {
    let non_negative = |v: f32| v.is_finite() && v >= 0.0 && f64::from(v) <= MAX_METRES;
    if !(non_negative(e.error_bound) && e.error_bound > 0.0) {
        return Some(format!("error bound {} m is not positive", e.error_bound));
    }
    if !non_negative(e.max_error) || !non_negative(e.limited_excess) {
        return Some(format!(
            "measured error {} m (excess {} m) is not a finite, non-negative number",
            e.max_error, e.limited_excess
        ));
    }
    if !non_negative(e.morph_unit) {
        return Some(format!(
            "morph unit {} m is not finite and non-negative",
            e.morph_unit
        ));
    }
    let (lo, hi) = (f64::from(e.z_min), f64::from(e.z_max));
    if !(lo.is_finite() && hi.is_finite() && lo <= hi && lo.abs().max(hi.abs()) <= MAX_METRES) {
        return Some(format!(
            "z range {lo}..{hi} m is not an ordered, finite range"
        ));
    }
    if e.index_count == 0 || e.triangle_count == 0 || e.fan_count == 0 {
        return Some("no triangles".into());
    }
    None
}

/// Recomputes every tile's checksum and the header's in a tile set's bytes, so that only the
/// semantic checks can reject what was changed: for tests and fuzzing, which mutate files as
/// a hostile user would. Fails on bytes whose header or directory does not fit.
pub fn reseal(bytes: &mut [u8]) -> Result<(), String> {
    if bytes.len() < size_of::<FileHeader>() {
        return Err("shorter than a header".into());
    }
    let mut h: FileHeader = bytemuck::pod_read_unaligned(&bytes[..size_of::<FileHeader>()]);
    let n = h.tiles_x as usize * h.tiles_y as usize;
    let dir_at = h.directory_offset as usize;
    let entry_len = size_of::<DirEntry>();
    let base_end = n
        .checked_mul(entry_len)
        .and_then(|l| l.checked_add(dir_at))
        .filter(|&end| end <= bytes.len())
        .ok_or("directory outside the file")?;
    // The layers' directories, where the header's grid implies a layout that fits.
    let mut directories = vec![(dir_at, n)];
    let mut dir_end = base_end;
    if let Ok((layers, end)) = layer_layout(&h) {
        if end as usize <= bytes.len() && dir_at == size_of::<FileHeader>() {
            directories.extend(layers.iter().map(|l| {
                (
                    l.directory_offset as usize,
                    (l.tiles_x * l.tiles_y) as usize,
                )
            }));
            dir_end = end as usize;
        }
    }
    for (at0, count) in directories {
        for k in 0..count {
            let at = at0 + k * entry_len;
            let mut e: DirEntry = bytemuck::pod_read_unaligned(&bytes[at..at + entry_len]);
            let (start, end) = (e.offset as usize, e.offset.saturating_add(e.len) as usize);
            if start <= end && end <= bytes.len() {
                e.crc = crc32fast::hash(&bytes[start..end]);
                bytes[at..at + entry_len].copy_from_slice(bytemuck::bytes_of(&e));
            }
        }
    }
    h.header_crc = 0;
    h.header_crc = header_crc(&h, &bytes[dir_at..dir_end]);
    bytes[..size_of::<FileHeader>()].copy_from_slice(bytemuck::bytes_of(&h));
    Ok(())
}

fn header_crc(header: &FileHeader, directory: &[u8]) -> u32 {
    let mut h = *header;
    h.header_crc = 0;
    let mut hasher = crc32fast::Hasher::new();
    hasher.update(bytemuck::bytes_of(&h));
    hasher.update(directory);
    hasher.finalize()
}

/// `e_i = base * 2^(n-1-i)`.
pub fn level_error(base: f64, levels: u32, level: u32) -> f64 {
    base * f64::powi(2.0, levels as i32 - 1 - level as i32)
}

/// Tiles across and down for a grid: tiles of 257 samples overlapping by one.
pub fn tile_count(width: usize, height: usize) -> Result<(u32, u32), String> {
    if width < 2 || height < 2 {
        return Err("a grid needs at least 2 x 2 samples".into());
    }
    let cells = TILE_CELLS as usize;
    let (tx, ty) = ((width - 1).div_ceil(cells), (height - 1).div_ceil(cells));
    if tx > u32::MAX as usize / 2
        || ty > u32::MAX as usize / 2
        || (width as u64) * (height as u64) > 1 << 40
    {
        return Err("too many samples".into());
    }
    Ok((tx as u32, ty as u32))
}

/// A memory-mapped, validated tile set. A clone is another view of the same mapping (and of
/// the same rebuilt tiles).
#[derive(Clone)]
pub struct TileSet {
    path: PathBuf,
    map: std::sync::Arc<memmap2::Mmap>,
    /// The file mapped, for reads that should not page the mapping in: each tile's table at a
    /// reader's open ([`TileSet::tile_table`]) and the checksum of a tile read in part.
    file: std::sync::Arc<File>,
    /// The file's header; in a layer's view ([`TileSet::layer`]), the layer's grid, spacing,
    /// height lattice and directory in place of the base's.
    header: FileHeader,
    /// Every tile's texture layout, when the set has textures.
    texture: Option<texture::Layout>,
    /// Which pyramid layer this is (0: the base grid), and the file's layers above the base.
    layer: u32,
    layers: std::sync::Arc<Vec<LayerHeader>>,
    /// With compact levels ([`FLAG_COMPACT_LEVELS`]): each of this view's tiles' version 3
    /// blob, rebuilt through the levels first read, and again through more as more are read,
    /// each kept (or why it could not be).
    rebuilt: std::sync::Arc<RebuiltTiles>,
}

/// Per tile of a view, once it is first read: per count of levels `1..=levels`, the blob
/// rebuilt from its first levels (see [`rebuilt`]) or why there is none, once asked for. A
/// reader asks for the levels it checks, so a tile first drawn coarse rebuilds its coarse
/// levels alone; every blob made stays while the view does (readers hold slices of them), or
/// until a reader done with its rows has the view forget them ([`TileSet::forget_rebuilt_rows`]).
type RebuiltTiles = Vec<std::sync::OnceLock<Box<[Rebuilt]>>>;

/// One tile's blob rebuilt from some count of its levels, or why it could not be.
type Rebuilt = std::sync::OnceLock<Result<Box<[u8]>, String>>;

/// The cache of rebuilt tiles for a view of `tiles` tiles (empty without compact levels).
fn rebuilt_cache(header: &FileHeader, tiles: u64) -> std::sync::Arc<RebuiltTiles> {
    let n = if header.flags & FLAG_COMPACT_LEVELS != 0 {
        tiles as usize
    } else {
        0
    };
    std::sync::Arc::new((0..n).map(|_| std::sync::OnceLock::new()).collect())
}

/// The texture layout a header declares (None: no textures); what is wrong with it, if
/// anything. Version 1 had no textures, whatever its (then reserved) fields hold.
fn texture_layout(h: &FileHeader) -> Result<Option<texture::Layout>, String> {
    if h.version < 2 || h.texture_format == texture::FORMAT_NONE {
        return Ok(None);
    }
    if h.texture_format != texture::FORMAT_BC1 {
        return Err(format!("texture format {} is not known", h.texture_format));
    }
    let layout = texture::Layout::new(h.texture_interior).map_err(|e| format!("texture: {e}"))?;
    if (layout.gutter, layout.mips) != (h.texture_gutter, h.texture_mips) {
        return Err(format!(
            "texture gutter {} and {} mips do not match its {}-texel interior",
            h.texture_gutter, h.texture_mips, h.texture_interior
        ));
    }
    if !(texture::SOURCE_PHOTO..=texture::SOURCE_GEOREFERENCED_PHOTO).contains(&h.texture_source) {
        return Err(format!("texture source {} is not known", h.texture_source));
    }
    Ok(Some(layout))
}

impl std::fmt::Debug for TileSet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TileSet")
            .field("path", &self.path)
            .field("header", &self.header)
            .finish()
    }
}

impl TileSet {
    /// Maps `path` and validates its header and directory (not yet the tiles).
    pub fn open(path: &Path) -> Result<TileSet, FormatError> {
        // Only regular files: opening a FIFO would block forever, a device is no tile set.
        let meta = std::fs::metadata(path).map_err(io_err(path))?;
        if !meta.is_file() {
            return Err(FormatError::Invalid {
                path: path.to_path_buf(),
                what: "not a regular file".into(),
            });
        }
        let file = File::open(path).map_err(io_err(path))?;
        // SAFETY: the map is read-only; a tile set that another process truncates while mapped
        // could fault, which is the documented memmap2 caveat every mmap reader accepts.
        let map = unsafe { memmap2::Mmap::map(&file) }.map_err(io_err(path))?;
        let invalid = |what: String| FormatError::Invalid {
            path: path.to_path_buf(),
            what,
        };
        if map.len() < size_of::<FileHeader>() {
            return Err(invalid(format!(
                "{} bytes is too short for a tile set header",
                map.len()
            )));
        }
        let header: FileHeader = bytemuck::pod_read_unaligned(&map[..size_of::<FileHeader>()]);
        if header.magic != MAGIC {
            return Err(invalid("not a vkterrain tile set (bad magic)".into()));
        }
        if !(OLDEST_VERSION..=COMPACT_VERSION).contains(&header.version) {
            return Err(invalid(format!(
                "format version {} is not supported (this reader reads {OLDEST_VERSION}..={COMPACT_VERSION})",
                header.version
            )));
        }
        let compact_version = header.version >= FIRST_COMPACT_VERSION;
        if compact_version != (header.flags & FLAG_COMPACT_LEVELS != 0) {
            return Err(invalid(format!(
                "format version {} with flags {:#x}: compact levels are versions {FIRST_COMPACT_VERSION} and {COMPACT_VERSION}'s alone",
                header.version, header.flags
            )));
        }
        if header.header_len as usize != size_of::<FileHeader>()
            || header.directory_entry_len as usize != size_of::<DirEntry>()
            || header.directory_offset != size_of::<FileHeader>() as u64
        {
            return Err(invalid(
                "header or directory layout does not match this version".into(),
            ));
        }
        if header.tile_size != TILE_CELLS + 1 {
            return Err(invalid(format!(
                "tile size {} (expected {})",
                header.tile_size,
                TILE_CELLS + 1
            )));
        }
        if !(header.height_step.is_finite() && header.height_step > 0.0) {
            return Err(invalid(format!(
                "height step {} is not a positive number",
                header.height_step
            )));
        }
        if let Some(problem) = header_numbers(&header) {
            return Err(invalid(problem));
        }
        if header.levels == 0 || header.levels > MAX_LEVELS {
            return Err(invalid(format!(
                "{} levels (expected 1..={MAX_LEVELS})",
                header.levels
            )));
        }
        let (tx, ty) = tile_count(header.grid_width as usize, header.grid_height as usize)
            .map_err(|e| {
                invalid(format!(
                    "grid {}x{}: {e}",
                    header.grid_width, header.grid_height
                ))
            })?;
        if (tx, ty) != (header.tiles_x, header.tiles_y) {
            return Err(invalid(format!(
                "{}x{} tiles does not match the {}x{} grid",
                header.tiles_x, header.tiles_y, header.grid_width, header.grid_height
            )));
        }
        let (expected, dir_end) = layer_layout(&header).map_err(invalid)?;
        if dir_end > map.len() as u64 {
            return Err(invalid(format!(
                "directory of {} tiles and {} pyramid layers runs past the end of the file (truncated?)",
                tx * ty,
                expected.len()
            )));
        }
        let directory = &map[header.directory_offset as usize..dir_end as usize];
        if header_crc(&header, directory) != header.header_crc {
            return Err(invalid("header checksum mismatch (corrupted file)".into()));
        }
        let layers_at =
            header.directory_offset as usize + (tx * ty) as usize * size_of::<DirEntry>();
        let mut layers = Vec::with_capacity(expected.len());
        for (i, want) in expected.iter().enumerate() {
            let at = layers_at + i * size_of::<LayerHeader>();
            let l: LayerHeader =
                bytemuck::pod_read_unaligned(&map[at..at + size_of::<LayerHeader>()]);
            let heights = LayerHeader {
                height_step: l.height_step,
                height_min: l.height_min,
                height_max: l.height_max,
                ..*want
            };
            if l != heights {
                return Err(invalid(format!(
                    "pyramid layer {} does not match the {}x{} grid",
                    i + 1,
                    header.grid_width,
                    header.grid_height
                )));
            }
            let finite = [l.height_step, l.height_min, l.height_max]
                .iter()
                .all(|v| v.is_finite());
            if !finite || l.height_step <= 0.0 || l.height_min > l.height_max {
                return Err(invalid(format!(
                    "pyramid layer {}: height step {} or range {}..{} is not valid",
                    i + 1,
                    l.height_step,
                    l.height_min,
                    l.height_max
                )));
            }
            layers.push(l);
        }
        let texture = texture_layout(&header).map_err(invalid)?;
        let set = TileSet {
            path: path.to_path_buf(),
            map: std::sync::Arc::new(map),
            file: std::sync::Arc::new(file),
            header,
            texture,
            layer: 0,
            layers: std::sync::Arc::new(layers),
            rebuilt: rebuilt_cache(
                &header,
                u64::from(header.tiles_x) * u64::from(header.tiles_y),
            ),
        };
        set.check_entries(dir_end)?;
        for p in 1..=set.pyramid_layers() {
            set.layer(p)
                .expect("a layer it has")
                .check_entries(dir_end)?;
        }
        Ok(set)
    }

    /// Every directory entry's tile and texture lie inside the file, after the directories.
    fn check_entries(&self, dir_end: u64) -> Result<(), FormatError> {
        let (tx, ty) = (self.header.tiles_x, self.header.tiles_y);
        let invalid = |what: String| FormatError::Invalid {
            path: self.path.clone(),
            what: match self.layer {
                0 => what,
                p => format!("pyramid layer {p}: {what}"),
            },
        };
        for i in 0..(tx * ty) as usize {
            let e = self.entry(i);
            if let Some(layout) = &self.texture {
                if !e.texture_offset.is_multiple_of(16)
                    || e.texture_offset < dir_end
                    || (e.texture_len as usize) < layout.bytes()
                    || e.texture_offset
                        .checked_add(e.texture_len)
                        .is_none_or(|end| end > self.map.len() as u64)
                {
                    return Err(invalid(format!(
                        "texture of tile {},{} lies outside the file (offset {}, length {}; truncated?)",
                        i as u32 % tx,
                        i as u32 / tx,
                        e.texture_offset,
                        e.texture_len
                    )));
                }
            }
            if !e.offset.is_multiple_of(16)
                || e.offset < dir_end
                || e.offset
                    .checked_add(e.len)
                    .is_none_or(|end| end > self.map.len() as u64)
            {
                return Err(invalid(format!(
                    "tile {},{} lies outside the file (offset {}, length {}; truncated?)",
                    i as u32 % tx,
                    i as u32 / tx,
                    e.offset,
                    e.len
                )));
            }
            let d = e.decimation_error;
            if !(d.is_finite() && (0.0..=MAX_METRES as f32).contains(&d)) {
                return Err(invalid(format!(
                    "tile {},{}: decimation error {d} is not a distance",
                    i as u32 % tx,
                    i as u32 / tx
                )));
            }
        }
        Ok(())
    }

    /// Layers of the tile pyramid above the base grid (0: none; always 0 before version 3).
    pub fn pyramid_layers(&self) -> u32 {
        self.layers.len() as u32
    }

    /// Which pyramid layer this is (0: the base grid).
    pub fn layer_index(&self) -> u32 {
        self.layer
    }

    /// Pyramid layer `p` (0: the base grid) as a tile set of its own: its grid, spacing, height
    /// lattice and directory, over the same mapping; levels, base error, flags and texture
    /// layout as the file's. None past the last layer.
    pub fn layer(&self, p: u32) -> Option<TileSet> {
        let base = FileHeader {
            pyramid_layers: self.layers.len() as u32,
            ..self.header
        };
        let header = match p {
            0 if self.layer == 0 => base,
            0 => return None,
            p => {
                let l = self.layers.get(p as usize - 1)?;
                FileHeader {
                    grid_width: l.grid_width,
                    grid_height: l.grid_height,
                    tiles_x: l.tiles_x,
                    tiles_y: l.tiles_y,
                    spacing_x: l.spacing_x,
                    spacing_y: l.spacing_y,
                    height_step: l.height_step,
                    height_min: l.height_min,
                    height_max: l.height_max,
                    directory_offset: l.directory_offset,
                    ..base
                }
            }
        };
        (self.layer == 0).then(|| TileSet {
            path: self.path.clone(),
            map: self.map.clone(),
            file: self.file.clone(),
            header,
            texture: self.texture,
            layer: p,
            layers: self.layers.clone(),
            rebuilt: if p == 0 {
                self.rebuilt.clone()
            } else {
                rebuilt_cache(
                    &header,
                    u64::from(header.tiles_x) * u64::from(header.tiles_y),
                )
            },
        })
    }

    /// Tile `(tx, ty)`'s decimation error, metres (0 in the base grid): base samples lie at
    /// most this far from its finest surface, so level `i` is within `max_error + D` of them.
    pub fn decimation_error(&self, tx: u32, ty: u32) -> Option<f32> {
        self.dir_entry(tx, ty).map(|e| e.decimation_error)
    }

    /// In a pyramid layer, tile `(tx, ty)`'s levels' errors against the base grid's samples
    /// under it, metres, one per level (None in the base grid, whose `max_error`s are these).
    pub fn base_errors(&self, tx: u32, ty: u32) -> Option<Vec<f32>> {
        let l = self.layers.get((self.layer as usize).checked_sub(1)?)?;
        if tx >= l.tiles_x || ty >= l.tiles_y {
            return None;
        }
        let n = self.header.levels as usize;
        let at = l.errors_offset as usize + ((ty * l.tiles_x + tx) as usize) * n * 4;
        let bytes = self.map.get(at..at + n * 4)?;
        Some(
            bytes
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect(),
        )
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn header(&self) -> &FileHeader {
        &self.header
    }

    pub fn file_len(&self) -> u64 {
        self.map.len() as u64
    }

    /// The source description stored at build time, safe to print: control characters
    /// (terminal escape sequences included) are shown escaped, as `\u{1b}`.
    pub fn description(&self) -> String {
        let d = &self.header.description;
        let end = d.iter().position(|&b| b == 0).unwrap_or(d.len());
        String::from_utf8_lossy(&d[..end])
            .chars()
            .flat_map(|c| {
                let escaped: Vec<char> = if c.is_control() {
                    c.escape_unicode().collect()
                } else {
                    vec![c]
                };
                escaped
            })
            .collect()
    }

    /// `e_i` in metres.
    pub fn level_error(&self, level: u32) -> f64 {
        level_error(self.header.base_error, self.header.levels, level)
    }

    fn entry(&self, i: usize) -> DirEntry {
        let at = self.header.directory_offset as usize + i * size_of::<DirEntry>();
        bytemuck::pod_read_unaligned(&self.map[at..at + size_of::<DirEntry>()])
    }

    pub fn dir_entry(&self, tx: u32, ty: u32) -> Option<DirEntry> {
        (tx < self.header.tiles_x && ty < self.header.tiles_y)
            .then(|| self.entry(ty as usize * self.header.tiles_x as usize + tx as usize))
    }

    /// Byte range of tile `(tx, ty)` in the file.
    pub fn blob_range(&self, tx: u32, ty: u32) -> Option<std::ops::Range<u64>> {
        let e = self.dir_entry(tx, ty)?;
        Some(e.offset..e.offset.checked_add(e.len)?)
    }

    /// Asks the kernel to read `range` of the file ahead (`madvise(MADV_WILLNEED)`), so a
    /// later read does not wait for the disk. Returns at once; the read goes on meanwhile.
    pub fn will_need(&self, range: std::ops::Range<u64>) -> std::io::Result<()> {
        let (offset, len) = self.clamp(range);
        if len == 0 {
            return Ok(());
        }
        self.map
            .advise_range(memmap2::Advice::WillNeed, offset, len)
    }

    /// Lets the kernel drop `range` of the mapping from this process
    /// (`madvise(MADV_DONTNEED)`); the next read pages it in again from the file.
    pub fn dont_need(&self, range: std::ops::Range<u64>) -> std::io::Result<()> {
        let (offset, len) = self.clamp(range);
        if len == 0 {
            return Ok(());
        }
        // SAFETY: the map is a read-only, shared mapping of a file: dropping its pages loses
        // nothing (they are read again from the file), and no slice of the range is held across
        // this call by the renderer (uploads copy out of the map within a frame).
        unsafe {
            self.map
                .unchecked_advise_range(memmap2::UncheckedAdvice::DontNeed, offset, len)
        }
    }

    /// Drops the whole file from the page cache (this mapping's pages, then the kernel's
    /// cached copy, `posix_fadvise(POSIX_FADV_DONTNEED)`): for measuring a first flight from
    /// disk. Returns the bytes still cached afterwards.
    pub fn drop_page_cache(&self) -> std::io::Result<u64> {
        self.dont_need(0..self.file_len())?;
        let file = File::open(&self.path)?;
        use std::os::fd::AsRawFd;
        // SAFETY: a plain system call on an open descriptor; it only advises the kernel.
        let r = unsafe { libc::posix_fadvise(file.as_raw_fd(), 0, 0, libc::POSIX_FADV_DONTNEED) };
        if r != 0 {
            return Err(std::io::Error::from_raw_os_error(r));
        }
        self.cached_bytes()
    }

    /// Bytes of the file in the page cache now (`mincore` over the mapping).
    pub fn cached_bytes(&self) -> std::io::Result<u64> {
        let len = self.map.len();
        if len == 0 {
            return Ok(0);
        }
        // SAFETY: sysconf has no preconditions.
        let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) }.max(1) as usize;
        let mut pages = vec![0u8; len.div_ceil(page)];
        // SAFETY: the address and length are this live mapping's (page-aligned start), and
        // `pages` has one byte per page of it, as mincore requires.
        let r = unsafe {
            libc::mincore(
                self.map.as_ptr() as *mut libc::c_void,
                len,
                pages.as_mut_ptr(),
            )
        };
        if r != 0 {
            return Err(std::io::Error::last_os_error());
        }
        let resident = pages.iter().filter(|&&p| p & 1 != 0).count();
        Ok((resident * page).min(len) as u64)
    }

    /// Bytes of the mapping resident in this process (the `Rss` of its areas in
    /// `/proc/self/smaps`): what [`TileSet::dont_need`] gives back. The page cache may keep the
    /// pages after that ([`TileSet::cached_bytes`] counts those).
    pub fn mapped_bytes(&self) -> std::io::Result<u64> {
        if self.map.is_empty() {
            return Ok(0);
        }
        let start = self.map.as_ptr() as u64;
        let end = start + self.map.len() as u64;
        let smaps = std::fs::read_to_string("/proc/self/smaps")?;
        let (mut inside, mut kib) = (false, 0u64);
        // The file is read in pieces: an area that changed meanwhile may be listed twice.
        let mut seen = std::collections::HashSet::new();
        for line in smaps.lines() {
            let first = line.split_whitespace().next().unwrap_or("");
            // An area's header: "start-end perms offset dev inode path".
            let area = first
                .split_once('-')
                .and_then(|(a, _)| u64::from_str_radix(a, 16).ok());
            if let Some(a) = area {
                inside = (start..end).contains(&a) && seen.insert(a);
            } else if inside && first == "Rss:" {
                let value = line.split_whitespace().nth(1).unwrap_or("");
                kib += value.parse::<u64>().map_err(|_| {
                    std::io::Error::new(
                        std::io::ErrorKind::InvalidData,
                        format!("/proc/self/smaps: unreadable line {line:?}"),
                    )
                })?;
            }
        }
        Ok(kib * 1024)
    }

    fn clamp(&self, range: std::ops::Range<u64>) -> (usize, usize) {
        let len = self.map.len() as u64;
        let start = range.start.min(len);
        let end = range.end.clamp(start, len);
        (start as usize, (end - start) as usize)
    }

    /// A problem with tile `(tx, ty)` of this view, as one line naming the file and the tile.
    pub fn tile_error(&self, tx: u32, ty: u32, what: String) -> FormatError {
        FormatError::Invalid {
            path: self.path.clone(),
            what: match self.layer {
                0 => format!("tile {tx},{ty}: {what}"),
                p => format!("pyramid layer {p} tile {tx},{ty}: {what}"),
            },
        }
    }

    /// Tile `(tx, ty)`'s directory entry, or an error when the tile is outside the set.
    fn checked_entry(&self, tx: u32, ty: u32) -> Result<DirEntry, FormatError> {
        self.dir_entry(tx, ty).ok_or_else(|| {
            self.tile_error(
                tx,
                ty,
                format!(
                    "outside the {}x{} tiles",
                    self.header.tiles_x, self.header.tiles_y
                ),
            )
        })
    }

    /// The layout every tile's texture has, when the set has textures.
    pub fn texture_layout(&self) -> Option<texture::Layout> {
        self.texture
    }

    /// Tile `(tx, ty)`'s texture, checksum and structure validated (None: the set has none).
    pub fn texture(
        &self,
        tx: u32,
        ty: u32,
    ) -> Result<Option<texture::TileTexture<'_>>, FormatError> {
        let Some(layout) = &self.texture else {
            return Ok(None);
        };
        let invalid = |what: String| self.tile_error(tx, ty, what);
        let e = self.checked_entry(tx, ty)?;
        let blob =
            &self.map[e.texture_offset as usize..(e.texture_offset + e.texture_len) as usize];
        texture::parse_blob(blob, layout, (tx, ty))
            .map(Some)
            .map_err(invalid)
    }

    /// Tile `(tx, ty)`'s stored bytes, not re-checked: for readers that validated the tile once
    /// with [`tile`](Self::tile) and then fetch parts of it often (the renderer's uploads).
    pub fn blob(&self, tx: u32, ty: u32) -> Option<&[u8]> {
        self.blob_through(tx, ty, self.header.levels)
    }

    /// [`blob`](Self::blob), holding at least the sections of the tile's first `count` levels
    /// (with compact levels, the blob rebuilt from those: see
    /// [`tile_levels`](Self::tile_levels); otherwise the whole stored blob).
    pub fn blob_through(&self, tx: u32, ty: u32, count: u32) -> Option<&[u8]> {
        if self.compact() {
            return self.rebuilt_blob(tx, ty, true, count).ok();
        }
        let e = self.dir_entry(tx, ty)?;
        self.bytes_at(e.offset, e.len)
    }

    /// `len` bytes of the file from `offset`, if the file holds them.
    fn bytes_at(&self, offset: u64, len: u64) -> Option<&[u8]> {
        self.map
            .get(usize::try_from(offset).ok()?..usize::try_from(offset.checked_add(len)?).ok()?)
    }

    /// Tile `(tx, ty)`'s stored texture bytes, unchecked (see [`TileSet::texture`]); mip
    /// entries' offsets count from its start.
    pub fn texture_blob(&self, tx: u32, ty: u32) -> Option<&[u8]> {
        let e = self.dir_entry(tx, ty)?;
        self.bytes_at(e.texture_offset, e.texture_len)
    }

    /// Tile `(tx, ty)`'s header and level table, checked for the counts and offsets that make
    /// its sections lie inside it, without reading the sections: no checksum, no vertex or index
    /// values. One page of the file per tile, for a reader that learns every tile's box and
    /// errors at open and validates a tile fully ([`tile`](Self::tile)) only when it needs the
    /// tile's data. The level data it hands out may be nonsense (in range, but unchecked).
    ///
    /// With compact levels the outline is the tile rebuilt (checksum first: the bit stream is
    /// decoded), and costs what [`tile`](Self::tile) does.
    pub fn tile_outline(&self, tx: u32, ty: u32) -> Result<Tile<'_>, FormatError> {
        self.tile_outline_through(tx, ty, self.header.levels)
    }

    /// Every vertex of tile `(tx, ty)` as `(x, y, height in metres)`, unchecked beyond what
    /// reading them needs (for readers that only place things over the ground, such as
    /// cameras): with compact levels, decoded from the tile's stream without rebuilding it.
    pub fn tile_points(&self, tx: u32, ty: u32) -> Result<Vec<(u32, u32, f32)>, FormatError> {
        if !self.compact() {
            return self.tile_outline(tx, ty).map(|t| t.vertices());
        }
        let invalid = |what: String| self.tile_error(tx, ty, what);
        let (header, _) = self.tile_table(tx, ty)?;
        let e = self.checked_entry(tx, ty)?;
        let stream = self
            .bytes_at(e.offset, e.len)
            .and_then(|stored| stored.get(stream_start(header.levels, self.header.version)..))
            .ok_or_else(|| invalid("the tile runs past the end of the file".into()))?;
        let sets = crate::compact::decode(stream, header.levels).map_err(invalid)?;
        let q = Quantiser {
            base: header.height_base,
            step: header.height_step,
        };
        Ok(sets
            .iter()
            .flatten()
            .map(|&(x, y, c)| (x, y, q.height(c)))
            .collect())
    }

    /// Tile `(tx, ty)`'s sides at each of its first `count` levels, as stored and unchecked
    /// ([`Tile::side_points`] of its outline): for a reader that compares them with a
    /// neighbour's before, or without, checking the tile. A compact tile's come from its first
    /// levels' streams decoded, without rebuilding the tile: a level's side holds every vertex
    /// of it and the coarser levels on that side of the mesh, in order along it.
    pub fn stored_sides(
        &self,
        tx: u32,
        ty: u32,
        count: u32,
    ) -> Result<Vec<[Vec<u32>; 4]>, FormatError> {
        let invalid = |what: String| self.tile_error(tx, ty, what);
        let unreadable = || invalid("a side names a vertex no block holds".into());
        if !self.compact() || self.header.version == FIRST_COMPACT_VERSION {
            let tile = self.tile_outline_through(tx, ty, count)?;
            return tile.side_points(count).ok_or_else(unreadable);
        }
        let (header, _, lengths) = self.tile_table_and_streams(tx, ty)?;
        let count = count.clamp(1, header.levels);
        let e = self.checked_entry(tx, ty)?;
        let start = stream_start(header.levels, self.header.version);
        let end = start + lengths[..count as usize].iter().sum::<u32>() as usize;
        let stream = self
            .bytes_at(e.offset, e.len)
            .and_then(|stored| stored.get(start..end))
            .ok_or_else(|| invalid("the tile runs past the end of the file".into()))?;
        let (sets, _) = crate::compact::decode_levels(stream, count).map_err(invalid)?;
        let mesh_max = (header.mesh_max_x, header.mesh_max_y);
        let mut along: [Vec<(u32, u32)>; 4] = Default::default();
        Ok(sets
            .iter()
            .map(|set| {
                for &(x, y, c) in set {
                    let on = [y == 0, x == mesh_max.0, y == mesh_max.1, x == 0];
                    for k in (0..4).filter(|&k| on[k]) {
                        let at = if k % 2 == 0 { x } else { y };
                        along[k].push((at, crate::pack::pack(x, y, c)));
                    }
                }
                std::array::from_fn(|k| {
                    along[k].sort_unstable();
                    along[k].iter().map(|&(_, p)| p).collect()
                })
            })
            .collect())
    }

    /// [`tile_outline`](Self::tile_outline) for a reader of the tile's first `count` levels:
    /// with compact levels, a tile of those levels alone ([`tile_levels`](Self::tile_levels)),
    /// rebuilt from their streams; otherwise every level's outline, as `tile_outline` reads it.
    pub fn tile_outline_through(
        &self,
        tx: u32,
        ty: u32,
        count: u32,
    ) -> Result<Tile<'_>, FormatError> {
        let invalid = |what: String| self.tile_error(tx, ty, what);
        let e = self.checked_entry(tx, ty)?;
        let (levels, step) = (self.header.levels, self.header.height_step);
        if self.compact() {
            let blob = self.rebuilt_blob(tx, ty, true, count).map_err(invalid)?;
            return Tile::outline_through(blob, (tx, ty), (levels, step), count).map_err(invalid);
        }
        let blob = &self.map[e.offset as usize..(e.offset + e.len) as usize];
        Tile::outline(blob, tx, ty, levels, step).map_err(invalid)
    }

    /// Tile `(tx, ty)`'s header and level table, checked as [`tile_outline`](Self::tile_outline)
    /// checks them (with compact levels, without the sections, which are not there until the
    /// tile is rebuilt): what a reader plans with before it reads the tile, in either version.
    ///
    /// Read from the file, not through the mapping: a page fault maps the pages around it as
    /// well (the kernel's fault-around, 64 KiB), so reading every tile's table at open through
    /// the map left 16 pages a tile in the process, 360 MB of a 16K set, for a few hundred
    /// bytes each.
    pub fn tile_table(
        &self,
        tx: u32,
        ty: u32,
    ) -> Result<(TileHeader, Vec<LevelEntry>), FormatError> {
        self.tile_table_and_streams(tx, ty)
            .map(|(header, entries, _)| (header, entries))
    }

    /// [`tile_table`](Self::tile_table), with a compact version 5 tile's level lengths (each
    /// level's bytes in its bit stream, which a decoder of one level is handed: what a
    /// refinement sends), read in the same call; empty for other files. They must add up to
    /// the tile's stream.
    pub fn tile_table_and_streams(
        &self,
        tx: u32,
        ty: u32,
    ) -> Result<(TileHeader, Vec<LevelEntry>, Vec<u32>), FormatError> {
        use std::os::unix::fs::FileExt;
        let invalid = |what: String| self.tile_error(tx, ty, what);
        let e = self.checked_entry(tx, ty)?;
        let levels = self.header.levels;
        let (header_len, table) = (size_of::<TileHeader>(), table_len(levels));
        let streams = self.has_level_streams();
        let read = match streams {
            true => stream_start(levels, self.header.version),
            false => table,
        };
        if (e.len as usize) < table {
            let (what, count, at) = match (e.len as usize) < header_len {
                true => ("tile header", 1, 0),
                false => ("level table", levels, header_len),
            };
            return Err(invalid(match self.compact() {
                true => format!("{} bytes is too short for a tile's table", e.len),
                false => format!("{what} ({count} items at {at}) runs past the tile"),
            }));
        }
        if (e.len as usize) < read {
            return Err(invalid(format!(
                "{} bytes is too short for a tile's table",
                e.len
            )));
        }
        let mut stored = vec![0u8; read];
        self.file
            .read_exact_at(&mut stored, e.offset)
            .map_err(|err| invalid(format!("its table cannot be read: {err}")))?;
        let header: TileHeader = bytemuck::pod_read_unaligned(&stored[..header_len]);
        check_tile_header(&header, tx, ty, levels, self.header.height_step).map_err(invalid)?;
        let entries = stored_entries(&stored, levels);
        check_table(&header, &entries).map_err(invalid)?;
        if !self.compact() {
            check_sections(&entries, e.len).map_err(invalid)?;
        }
        let lengths = match streams {
            true => stored_lengths(&stored, levels),
            false => Vec::new(),
        };
        let stream = lengths.iter().map(|&n| u64::from(n)).sum::<u64>();
        if streams && stream != e.len - read as u64 {
            return Err(invalid(format!(
                "its levels' lengths add up to {stream} bytes, its stream has {}",
                e.len - read as u64
            )));
        }
        Ok((header, entries, lengths))
    }

    /// Level `j`'s bytes of compact tile `(tx, ty)`'s bit stream (version 5 files; None
    /// otherwise), unchecked: a reader hands them to a decoder once the tile has passed its
    /// check, which decodes every level and compares its end with its length.
    pub fn level_stream(&self, tx: u32, ty: u32, j: u32) -> Option<&[u8]> {
        if !self.compact() || self.header.version == FIRST_COMPACT_VERSION {
            return None;
        }
        let e = self.dir_entry(tx, ty)?;
        let stored = self.bytes_at(e.offset, e.len)?;
        let start = stream_start(self.header.levels, self.header.version);
        let lengths = stored_lengths(stored.get(..start)?, self.header.levels);
        let from = start + lengths.get(..j as usize)?.iter().sum::<u32>() as usize;
        stored.get(from..from + *lengths.get(j as usize)? as usize)
    }

    /// Tile `(tx, ty)`, checksum and structure validated (with compact levels, the checksum of
    /// the stored bytes, and the structure of the blob rebuilt from them).
    pub fn tile(&self, tx: u32, ty: u32) -> Result<Tile<'_>, FormatError> {
        self.tile_levels(tx, ty, 0..self.header.levels)
    }

    /// [`tile`](Self::tile) with the structure of levels `levels` alone checked (the checksum
    /// covers every level): a reader that reads a tile's finer levels later checks each first
    /// ([`Tile::check_levels`]).
    ///
    /// With compact levels (version 5) the tile is rebuilt from its levels through
    /// `levels.end` alone and holds those alone ([`Tile::level`] is None past them): a tile
    /// first drawn coarse is decoded and assembled only as far as it is drawn, and each
    /// rebuilt level's entry must be the stored one. The checksum of the whole tile rebuilt is
    /// compared when every level is asked for.
    pub fn tile_levels(
        &self,
        tx: u32,
        ty: u32,
        levels: std::ops::Range<u32>,
    ) -> Result<Tile<'_>, FormatError> {
        let invalid = |what: String| self.tile_error(tx, ty, what);
        let e = self.checked_entry(tx, ty)?;
        let blob = &self.map[e.offset as usize..(e.offset + e.len) as usize];
        let crc = self
            .crc_read(e.offset, e.len)
            .map_err(|err| invalid(format!("cannot be read: {err}")))?;
        if crc != e.crc {
            return Err(invalid("checksum mismatch (corrupted file)".into()));
        }
        let (all, step) = (self.header.levels, self.header.height_step);
        let tile = if self.compact() {
            let blob = self
                .rebuilt_blob(tx, ty, false, levels.end)
                .map_err(invalid)?;
            Tile::outline_through(blob, (tx, ty), (all, step), levels.end)
        } else {
            Tile::outline(blob, tx, ty, all, step)
        }
        .map_err(invalid)?;
        tile.check_levels(levels).map_err(invalid)?;
        Ok(tile)
    }

    /// The crc32 of `len` bytes of the file at `offset`, read from the file rather than through
    /// the mapping: a tile's checksum covers every level, and a reader that draws its first
    /// levels only would otherwise hold the pages of all of them mapped (most of a tile's
    /// bytes are its finest levels'), which the process's resident set would count.
    fn crc_read(&self, offset: u64, len: u64) -> std::io::Result<u32> {
        use std::os::unix::fs::FileExt;
        const CHUNK: u64 = 1 << 20;
        let mut hasher = crc32fast::Hasher::new();
        let mut buf = vec![0u8; CHUNK.min(len) as usize];
        let mut at = 0;
        while at < len {
            let n = CHUNK.min(len - at) as usize;
            self.file.read_exact_at(&mut buf[..n], offset + at)?;
            hasher.update(&buf[..n]);
            at += n as u64;
        }
        Ok(hasher.finalize())
    }

    /// Whether the tiles hold compact levels ([`FLAG_COMPACT_LEVELS`]).
    pub fn compact(&self) -> bool {
        self.header.flags & FLAG_COMPACT_LEVELS != 0
    }

    /// Whether each tile's levels are stored as separate compact streams, which a reader may
    /// send as they are ([`TileSet::level_stream`]; compact sets after version 4).
    pub fn has_level_streams(&self) -> bool {
        self.compact() && self.header.version != FIRST_COMPACT_VERSION
    }

    /// Another view of the same mapping, with a cache of rebuilt tiles of its own: a reader
    /// that goes over a compact set once has it forget the rows it is done with
    /// ([`Self::forget_rebuilt_rows`]), so that the tiles it rebuilt do not all stay (a 64K
    /// set's are tens of gigabytes).
    pub fn with_own_rebuilt(&self) -> TileSet {
        let tiles = u64::from(self.header.tiles_x) * u64::from(self.header.tiles_y);
        TileSet {
            rebuilt: rebuilt_cache(&self.header, tiles),
            ..self.clone()
        }
    }

    /// Drops what this view rebuilt of tile rows `rows` (a reader done with them), if the view's
    /// rebuilt tiles are its own ([`Self::with_own_rebuilt`], no clone since); otherwise keeps
    /// everything and says false. No tile read from the view can outlive this (`&mut self`).
    pub fn forget_rebuilt_rows(&mut self, rows: std::ops::Range<u32>) -> bool {
        let tiles_x = self.header.tiles_x as usize;
        let Some(cache) = std::sync::Arc::get_mut(&mut self.rebuilt) else {
            return false;
        };
        let end = (rows.end as usize * tiles_x).min(cache.len());
        for slot in cache
            .iter_mut()
            .take(end)
            .skip(rows.start as usize * tiles_x)
        {
            slot.take();
        }
        true
    }

    /// A compact tile's version 3 blob, rebuilt from its first `count` levels (all of them in
    /// version 4) once and kept (see [`rebuilt`]): a blob already made from as many levels or
    /// more serves too. `check` first compares the stored bytes with their checksum (a decoder
    /// is not handed bytes nothing vouches for).
    fn rebuilt_blob(&self, tx: u32, ty: u32, check: bool, count: u32) -> Result<&[u8], String> {
        let e = self.dir_entry(tx, ty).ok_or("outside the tile set")?;
        let slot = ty as usize * self.header.tiles_x as usize + tx as usize;
        let levels = self.header.levels;
        let count = match self.header.version {
            FIRST_COMPACT_VERSION => levels,
            _ => count.clamp(1, levels),
        };
        let cells = self
            .rebuilt
            .get(slot)
            .ok_or("outside the tile set")?
            .get_or_init(|| (0..levels).map(|_| Rebuilt::new()).collect());
        let made = (count..=levels)
            .filter_map(|c| cells[c as usize - 1].get())
            .find(|made| made.is_ok());
        let made = made.unwrap_or_else(|| {
            cells[count as usize - 1].get_or_init(|| {
                let stored = self
                    .bytes_at(e.offset, e.len)
                    .ok_or("the tile runs past the end of the file")?;
                if check && crc32fast::hash(stored) != e.crc {
                    return Err("checksum mismatch (corrupted file)".into());
                }
                rebuilt(
                    stored,
                    (tx, ty),
                    (levels, self.header.height_step),
                    self.header.version,
                    count,
                )
                .map(Vec::into_boxed_slice)
            })
        });
        made.as_deref().map_err(Clone::clone)
    }
}

/// Index array of one level.
#[derive(Clone, Copy, Debug)]
pub enum Indices<'a> {
    U16(&'a [u16]),
    U32(&'a [u32]),
}

impl<'a> Indices<'a> {
    pub fn len(&self) -> usize {
        match self {
            Indices::U16(s) => s.len(),
            Indices::U32(s) => s.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn bytes(&self) -> &[u8] {
        match self {
            Indices::U16(s) => bytemuck::cast_slice(s),
            Indices::U32(s) => bytemuck::cast_slice(s),
        }
    }

    /// Indices widened to u32, restarts as `None`.
    pub fn iter(&self) -> IndexIter<'a> {
        match *self {
            Indices::U16(s) => IndexIter::U16(s.iter()),
            Indices::U32(s) => IndexIter::U32(s.iter()),
        }
    }

    /// The fans: each a slice of vertex indices, centre first, closed perimeter after.
    pub fn fans(&self) -> Vec<Vec<u32>> {
        let mut fans = Vec::new();
        let mut cur = Vec::new();
        for i in self.iter() {
            match i {
                Some(v) => cur.push(v),
                None => fans.push(std::mem::take(&mut cur)),
            }
        }
        if !cur.is_empty() {
            fans.push(cur);
        }
        fans
    }
}

/// One tile of a mapped tile set.
#[derive(Clone, Copy, Debug)]
pub struct Tile<'a> {
    blob: &'a [u8],
    pub header: TileHeader,
    levels: &'a [LevelEntry],
}

/// [`Indices::iter`]: one width chosen once, not a chain of both (the tile checks and the
/// part tables walk every index of every level this way).
#[derive(Clone, Debug)]
pub enum IndexIter<'a> {
    U16(std::slice::Iter<'a, u16>),
    U32(std::slice::Iter<'a, u32>),
}

impl Iterator for IndexIter<'_> {
    type Item = Option<u32>;

    #[inline]
    fn next(&mut self) -> Option<Option<u32>> {
        match self {
            IndexIter::U16(it) => it
                .next()
                .map(|&i| (i != RESTART_U16).then_some(u32::from(i))),
            IndexIter::U32(it) => it.next().map(|&i| (i != RESTART_U32).then_some(i)),
        }
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        match self {
            IndexIter::U16(it) => it.size_hint(),
            IndexIter::U32(it) => it.size_hint(),
        }
    }
}

impl ExactSizeIterator for IndexIter<'_> {}

/// The data of one level of one tile, as stored.
#[derive(Clone, Copy, Debug)]
pub struct Level<'a> {
    pub entry: LevelEntry,
    /// Block i's packed vertices.
    pub positions: &'a [u32],
    /// Block i's morph offsets: `i` rows of `block_len` bytes, row k for coarser level k.
    pub morph: &'a [i8],
    pub indices: Indices<'a>,
    /// Vertex indices on the N, E, S, W sides.
    pub border: [&'a [u32]; 4],
}

fn section<'a, T: Pod>(
    blob: &'a [u8],
    offset: u32,
    count: u64,
    what: &str,
) -> Result<&'a [T], String> {
    let bytes = count
        .checked_mul(size_of::<T>() as u64)
        .filter(|&b| {
            (offset as u64)
                .checked_add(b)
                .is_some_and(|end| end <= blob.len() as u64)
        })
        .ok_or_else(|| format!("{what} ({count} items at {offset}) runs past the tile"))?;
    let s = &blob[offset as usize..offset as usize + bytes as usize];
    bytemuck::try_cast_slice(s).map_err(|_| format!("{what} at {offset} is misaligned"))
}

/// Where [`Tile::outline`] finds each level's sections, checked as it checks them ([`section`]'s
/// bounds and alignment, for a blob of `len` bytes at a 16-byte aligned offset) without the
/// blob at hand.
fn check_sections(entries: &[LevelEntry], len: u64) -> Result<(), String> {
    let span = |offset: u32, count: u64, size: u64, what: &str| {
        let fits = count
            .checked_mul(size)
            .and_then(|b| u64::from(offset).checked_add(b))
            .is_some_and(|end| end <= len);
        if !fits {
            return Err(format!(
                "{what} ({count} items at {offset}) runs past the tile"
            ));
        }
        match u64::from(offset).is_multiple_of(size) {
            true => Ok(()),
            false => Err(format!("{what} at {offset} is misaligned")),
        }
    };
    for (i, e) in entries.iter().enumerate() {
        let err = |what: String| format!("level {i}: {what}");
        let n = u64::from(e.block_len);
        span(e.positions_offset, n, 4, "positions").map_err(err)?;
        span(e.morph_offset, n * i as u64, 1, "morph offsets").map_err(err)?;
        let width = if e.index_width == 2 { 2 } else { 4 };
        span(e.index_offset, u64::from(e.index_count), width, "indices").map_err(err)?;
        let total: u64 = e.border_len.iter().map(|&l| u64::from(l)).sum();
        span(e.border_offset, total, 4, "border").map_err(err)?;
    }
    Ok(())
}

/// A level table's own checks: each block following the previous one, index widths that
/// address the blocks, sane numbers, and the blocks adding up to the header's vertex count
/// (not where the sections lie).
fn check_table(header: &TileHeader, entries: &[LevelEntry]) -> Result<(), String> {
    let mut start = 0u32;
    for (i, e) in entries.iter().enumerate() {
        let err = |what: String| format!("level {i}: {what}");
        if e.block_start != start {
            return Err(err(format!(
                "block starts at vertex {} instead of {start}",
                e.block_start
            )));
        }
        start = start
            .checked_add(e.block_len)
            .ok_or_else(|| err("vertex count overflows".into()))?;
        if e.index_width == 2 && start > u32::from(RESTART_U16) {
            return Err(err(format!(
                "{start} vertices cannot be addressed with 16-bit indices"
            )));
        }
        if e.index_width != 2 && e.index_width != 4 {
            return Err(err(format!("index width {}", e.index_width)));
        }
        if let Some(problem) = level_numbers(e) {
            return Err(err(problem));
        }
    }
    if start != header.vertex_count {
        return Err(format!(
            "blocks hold {start} vertices, header says {}",
            header.vertex_count
        ));
    }
    Ok(())
}

/// A tile header's own checks: magic, place, level count, extents and height step.
fn check_tile_header(
    header: &TileHeader,
    tx: u32,
    ty: u32,
    levels: u32,
    step: f32,
) -> Result<(), String> {
    if header.magic != TILE_MAGIC {
        return Err("bad tile magic".into());
    }
    if (header.tx, header.ty) != (tx, ty) {
        return Err(format!(
            "directory points at tile {},{}",
            header.tx, header.ty
        ));
    }
    if header.levels != levels {
        return Err(format!("{} levels (the file says {levels})", header.levels));
    }
    let (dx, dy, mx, my) = (
        header.data_max_x,
        header.data_max_y,
        header.mesh_max_x,
        header.mesh_max_y,
    );
    if !(1..=TILE_CELLS).contains(&dx)
        || !(1..=TILE_CELLS).contains(&dy)
        || mx != (dx + 1) & !1
        || my != (dy + 1) & !1
    {
        return Err(format!("bad data extent {dx}x{dy} / mesh extent {mx}x{my}"));
    }
    if header.height_step.to_bits() != step.to_bits() {
        return Err(format!(
            "height step {} differs from the tile set's {step}",
            header.height_step
        ));
    }
    Ok(())
}

impl<'a> Tile<'a> {
    /// The header and level table, and every section's place inside the blob.
    fn outline(
        blob: &'a [u8],
        tx: u32,
        ty: u32,
        levels: u32,
        step: f32,
    ) -> Result<Tile<'a>, String> {
        Tile::outline_through(blob, (tx, ty), (levels, step), levels)
    }

    /// [`outline`](Self::outline) of a blob that may hold the sections of the first `count`
    /// levels alone (a compact tile rebuilt that far): the whole table is checked, and the
    /// tile holds those levels alone.
    fn outline_through(
        blob: &'a [u8],
        (tx, ty): (u32, u32),
        (levels, step): (u32, f32),
        count: u32,
    ) -> Result<Tile<'a>, String> {
        let header: TileHeader = *section::<TileHeader>(blob, 0, 1, "tile header")?
            .first()
            .ok_or("empty tile")?;
        check_tile_header(&header, tx, ty, levels, step)?;
        let entries = section::<LevelEntry>(
            blob,
            size_of::<TileHeader>() as u32,
            levels as u64,
            "level table",
        )?;
        check_table(&header, entries)?;
        let tile = Tile {
            blob,
            header,
            levels: &entries[..count.clamp(1, levels) as usize],
        };
        for i in 0..tile.levels.len() {
            let err = |what: String| format!("level {i}: {what}");
            tile.level_unchecked(i as u32).map_err(err)?;
        }
        Ok(tile)
    }

    /// [`outline`](Self::outline), then every vertex, index and border entry in range.
    pub(crate) fn parse(
        blob: &'a [u8],
        tx: u32,
        ty: u32,
        levels: u32,
        step: f32,
    ) -> Result<Tile<'a>, String> {
        let tile = Tile::outline(blob, tx, ty, levels, step)?;
        tile.check_levels(0..levels)?;
        Ok(tile)
    }

    /// The structure [`TileSet::tile`] checks, for levels `levels` of a tile read by its
    /// outline: every vertex of their blocks inside the mesh extent, every index and border
    /// entry inside blocks `0..=level`. Levels outside the range keep their sections' bounds
    /// (the outline's) and nothing more: a reader checks a level before it reads its values.
    pub fn check_levels(&self, levels: std::ops::Range<u32>) -> Result<(), String> {
        let header = self.header;
        let end = (levels.end as usize).min(self.levels.len());
        for (i, e) in self
            .levels
            .iter()
            .enumerate()
            .take(end)
            .skip(levels.start as usize)
        {
            let err = |what: String| format!("level {i}: {what}");
            let start = e.block_start + e.block_len;
            let level = self.level_unchecked(i as u32).map_err(err)?;
            // Decoded positions inside the tile's mesh extent (readers index by them).
            let (mx, my) = (header.mesh_max_x, header.mesh_max_y);
            if let Some((k, (x, y, _))) = level
                .positions
                .iter()
                .map(|&p| crate::pack::unpack(p))
                .enumerate()
                .find(|&(_, (x, y, _))| x > mx || y > my)
            {
                return Err(err(format!(
                    "vertex {} at ({x}, {y}) outside the mesh extent {mx}x{my}",
                    e.block_start as usize + k
                )));
            }
            let out_of_range = level.indices.iter().flatten().find(|&v| v >= start);
            if let Some(v) = out_of_range {
                return Err(err(format!(
                    "index {v} outside blocks 0..={i} ({start} vertices)"
                )));
            }
            if let Some(v) = level
                .border
                .iter()
                .flat_map(|b| b.iter())
                .find(|&&v| v >= start)
            {
                return Err(err(format!("border vertex {v} outside blocks 0..={i}")));
            }
        }
        Ok(())
    }

    pub fn levels(&self) -> &'a [LevelEntry] {
        self.levels
    }

    pub fn quantiser(&self) -> Quantiser {
        Quantiser {
            base: self.header.height_base,
            step: self.header.height_step,
        }
    }

    pub fn blob_len(&self) -> usize {
        self.blob.len()
    }

    /// Level `i` (validated when the tile was parsed).
    pub fn level(&self, i: u32) -> Option<Level<'a>> {
        self.level_unchecked(i).ok()
    }

    fn level_unchecked(&self, i: u32) -> Result<Level<'a>, String> {
        let e = *self
            .levels
            .get(i as usize)
            .ok_or_else(|| format!("no level {i}"))?;
        let n = u64::from(e.block_len);
        let positions = section::<u32>(self.blob, e.positions_offset, n, "positions")?;
        let morph = section::<i8>(self.blob, e.morph_offset, n * u64::from(i), "morph offsets")?;
        let count = u64::from(e.index_count);
        let indices = match e.index_width {
            2 => Indices::U16(section::<u16>(self.blob, e.index_offset, count, "indices")?),
            _ => Indices::U32(section::<u32>(self.blob, e.index_offset, count, "indices")?),
        };
        let total: u64 = e.border_len.iter().map(|&l| u64::from(l)).sum();
        let all = section::<u32>(self.blob, e.border_offset, total, "border")?;
        let (n0, n1, n2) = (
            e.border_len[0] as usize,
            e.border_len[1] as usize,
            e.border_len[2] as usize,
        );
        let border = [
            &all[..n0],
            &all[n0..n0 + n1],
            &all[n0 + n1..n0 + n1 + n2],
            &all[n0 + n1 + n2..],
        ];
        Ok(Level {
            entry: e,
            positions,
            morph,
            indices,
            border,
        })
    }

    /// Every vertex of the tile, decoded: (x, y, height in metres), in index order.
    pub fn vertices(&self) -> Vec<(u32, u32, f32)> {
        self.vertices_through(self.header.levels)
    }

    /// The tile's sides at each of its first `levels` levels as packed vertices (per side, N,
    /// E, S, W, in order along it), each looked up in the block that holds it; None where a
    /// side names a vertex no block holds, or a level the tile does not hold (data not
    /// checked).
    pub fn side_points(&self, levels: u32) -> Option<Vec<[Vec<u32>; 4]>> {
        let blocks: Vec<(u32, &[u32])> = (0..levels)
            .filter_map(|j| self.level(j))
            .map(|l| (l.entry.block_start, l.positions))
            .collect();
        let at = |v: u32| -> Option<u32> {
            let j = blocks
                .partition_point(|&(start, _)| start <= v)
                .checked_sub(1)?;
            let (start, positions) = blocks[j];
            positions.get((v - start) as usize).copied()
        };
        (0..levels)
            .map(|i| {
                let l = self.level(i)?;
                let mut sides: [Vec<u32>; 4] = Default::default();
                for (side, stored) in sides.iter_mut().zip(l.border) {
                    *side = stored.iter().map(|&v| at(v)).collect::<Option<_>>()?;
                }
                Some(sides)
            })
            .collect()
    }

    /// The vertices of blocks `0..levels`, decoded as [`vertices`](Self::vertices) decodes them.
    pub fn vertices_through(&self, levels: u32) -> Vec<(u32, u32, f32)> {
        let q = self.quantiser();
        let blocks: Vec<Level> = (0..levels.min(self.header.levels))
            .filter_map(|i| self.level(i))
            .collect();
        let mut out = Vec::with_capacity(blocks.iter().map(|l| l.positions.len()).sum());
        for l in &blocks {
            out.extend(l.positions.iter().map(|&p| {
                let (x, y, h) = crate::pack::unpack(p);
                (x, y, q.height(h))
            }));
        }
        out
    }
}
