//! The terrain shaders' interface as the host writes it: the per-frame push constants, their
//! flag bits, the frame's constants of the morph level rule and the per-draw tile records. The one definition is the GLSL include
//! `spirv/shaders/interface.glsl`; the flag values here are the ones the spirv crate read out of
//! it at build time, and the structs below are `#[repr(C)]` mirrors whose every field offset a
//! test compares with the layout the compiler gave the GLSL (the SPIR-V's `Offset`
//! decorations, `spirv::TERRAIN_LAYOUT`), field names included.
//!
//! ```
//! use renderer::interface::{FrameConstants, FLAG_GEOMORPH};
//! let mut c: FrameConstants = bytemuck::Zeroable::zeroed();
//! c.flags |= FLAG_GEOMORPH;
//! assert_eq!(bytemuck::bytes_of(&c).len(), renderer::interface::PUSH_CONSTANT_BYTES as usize);
//! ```

use bytemuck::{Pod, Zeroable};

pub use spirv::flags::{FLAG_GEOMORPH, FLAG_LEVEL_COLOURS, FLAG_RELIEF, FLAG_TEXTURE, FLAG_TILES};

/// Per-frame constants (`FrameConstants`, the push-constant block).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct FrameConstants {
    pub view_proj: [f32; 16],
    /// xyz: the camera relative to its tile's north-west corner (m); w: metres per column.
    pub camera: [f32; 4],
    pub spacing_y: f32,
    pub height_step: f32,
    /// `FLAG_*`.
    pub flags: u32,
    /// Tile records this frame (the morph pass's count).
    pub draws: u32,
    /// Texture coordinate of tile-local sample coordinate `s`: `x + s * y` (the texture
    /// layout's `(g + s * T / 256) / S`); `z`: `S`, texels across a layer; `w`: the tiles
    /// shading's grid offset.
    pub texture_map: [f32; 4],
}

/// Size of the push-constant block.
pub const PUSH_CONSTANT_BYTES: u32 = std::mem::size_of::<FrameConstants>() as u32;

/// The frame's constants of the vertex level rule (`MorphFrame`, at the start of the records
/// buffer; [`crate::morph::frame_constants`] makes them).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct MorphFrame {
    /// `|J z| = |xy * d + zw * clip.xy| / d²` at a clip position of depth `d`.
    pub jacobian: [f32; 4],
    pub tau: f32,
    pub near: f32,
    /// How deep in view (a share of the half-image) the segment from a vertex to a corner of
    /// its star must reach for the corner to count fully ([`crate::morph::STAR_RAMP`]).
    pub ramp: f32,
    pub pad: f32,
}

/// One level table's coefficients (`LevelCoefficients`): `Λ(r) = Σ_k clamp(a_k - r b_k, 0, 1)`,
/// levels 0..3 and 4..7 ([`crate::morph::LevelTable`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct LevelCoefficients {
    pub a_lo: [f32; 4],
    pub a_hi: [f32; 4],
    pub b_lo: [f32; 4],
    pub b_hi: [f32; 4],
}

impl LevelCoefficients {
    /// A level table's coefficients as the shader reads them.
    pub fn of(table: &crate::levels::LevelTable) -> LevelCoefficients {
        LevelCoefficients {
            a_lo: std::array::from_fn(|k| table.a[k]),
            a_hi: std::array::from_fn(|k| table.a[k + 4]),
            b_lo: std::array::from_fn(|k| table.b[k]),
            b_hi: std::array::from_fn(|k| table.b[k + 4]),
        }
    }
}

/// One drawn tile as the vertex shader reads it (`TileRecord`): std430 in the records buffer,
/// and the same bytes as std140 through the `Tile` binding (every member 16-byte aligned or
/// packed so that the two layouts agree; the layout test sees both copies).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct TileRecord {
    pub tile_offset: [i32; 2],
    pub height_base: i32,
    /// Pool word of block 0's first vertex.
    pub positions: u32,
    /// First vertex of blocks 1..=8 (u32::MAX past the last block).
    pub starts_lo: [u32; 4],
    pub starts_hi: [u32; 4],
    /// Per block: its first vertex, its vertices, the pool byte of its morph rows (where the
    /// rows are sent: only the two-levels shaders read them, `MemoryOptions::morph_rows`), 0.
    pub blocks: [[u32; 4]; 9],
    /// Metres per morph offset unit of levels 0..8.
    pub units: [f32; 8],
    pub level: u32,
    /// The level the draw's vertices morph to at most.
    pub cap: f32,
    /// Where the tile's vertex 0 goes in the morphed heights (and, with
    /// `--read-back-heights`, in the heights read back).
    pub heights: u32,
    /// The tile's texture layer (u32::MAX: none) and finest resident mip.
    pub texture_layer: u32,
    pub texture_finest: f32,
    /// Samples the texture is moved by (0; `VKTERRAIN_FAULT=texture-seam` moves every other
    /// tile's, the seam test's negative control).
    pub texture_shift: f32,
    /// The levels of the tile's 4 x 4 parts, 4 bits each (part `4 j + i` at bits `4 (k % 8)`
    /// of word `k / 8`); drawn whole, the level in every part. The morph pass places the
    /// vertices the draw's mesh holds ([`tiles::parts::presence_level`]).
    pub parts_lo: u32,
    pub parts_hi: u32,
    /// The level tables of the tile's vertices: inside, the N, E, S, W sides, the NW, NE, SW,
    /// SE corners ([`crate::tile::TileInfo::tables`]).
    pub tables: [LevelCoefficients; 9],
    /// `[x, y, _, _]`: the mesh's last column and row (256 but in a partial tile).
    pub extent: [u32; 4],
    /// The tile's pyramid layer `p` (its samples are `2^p` base samples apart, its vertex
    /// `(x, y)` at `tile_offset + (x, y) << p`) and its layer's metres per height code (each
    /// layer has its own lattice).
    pub layer: u32,
    pub height_step: f32,
    pub pad1: [u32; 2],
    /// To [`RECORD_ALIGNMENT`] and beyond.
    pub pad2: [[u32; 4]; 10],
}

/// Bytes of one record.
pub const RECORD_BYTES: u64 = std::mem::size_of::<TileRecord>() as u64;

/// What a record's place in the records buffer is a multiple of: the largest
/// `minUniformBufferOffsetAlignment` Vulkan allows, so that the `Tile` binding's dynamic
/// offset may point at any record on any device.
pub const RECORD_ALIGNMENT: u64 = 256;

/// Where the records start in the records buffer, after the frame's [`MorphFrame`].
pub const RECORDS_OFFSET: u64 = RECORD_ALIGNMENT;

const _: () = assert!(RECORD_BYTES.is_multiple_of(RECORD_ALIGNMENT));
const _: () = assert!(std::mem::size_of::<MorphFrame>() as u64 <= RECORDS_OFFSET);

/// The dynamic offset of the `Tile` binding for record `i`: its bytes from [`RECORDS_OFFSET`].
pub fn tile_binding_offset(i: usize) -> u32 {
    (RECORD_BYTES * i as u64) as u32
}

/// `(field, offset)` of a `#[repr(C)]` struct, for the layout test.
macro_rules! fields {
    ($t:ty: $($f:ident),* $(,)?) => {
        vec![$((stringify!($f), std::mem::offset_of!($t, $f) as u32)),*]
    };
}

/// `(struct, field, offset)` of the mirrors, plus each array element's `"stride"` (its size),
/// in the form of `spirv::TERRAIN_LAYOUT`.
pub fn host_layout() -> Vec<(&'static str, &'static str, u32)> {
    let frame = fields!(FrameConstants: view_proj, camera, spacing_y, height_step, flags, draws,
        texture_map);
    let morph = fields!(MorphFrame: jacobian, tau, near, ramp, pad);
    let coefficients = fields!(LevelCoefficients: a_lo, a_hi, b_lo, b_hi);
    let record = fields!(TileRecord: tile_offset, height_base, positions, starts_lo, starts_hi,
        blocks, units, level, cap, heights, texture_layer, texture_finest, texture_shift,
        parts_lo, parts_hi, tables, extent, layer, height_step, pad1, pad2);
    let named = |name: &'static str, fields: Vec<(&'static str, u32)>| {
        fields.into_iter().map(move |(f, o)| (name, f, o))
    };
    let mut layout: Vec<_> = named("FrameConstants", frame)
        .chain(named("MorphFrame", morph))
        .chain(named("LevelCoefficients", coefficients))
        .chain(named("TileRecord", record))
        .collect();
    layout.push(("TileRecord", "stride", RECORD_BYTES as u32));
    let stride = std::mem::size_of::<LevelCoefficients>() as u32;
    layout.push(("LevelCoefficients", "stride", stride));
    layout.push(("Records", "tiles", RECORDS_OFFSET as u32));
    layout.sort();
    layout
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every member the shader has, at the offset the compiler gave it, and nothing more.
    #[test]
    fn the_host_structs_have_the_shaders_layout() {
        let mut shader: Vec<(&str, &str, u32)> = spirv::TERRAIN_LAYOUT.to_vec();
        shader.sort();
        let host = host_layout();
        for entry in &shader {
            assert!(
                host.contains(entry),
                "the shader has {entry:?}, the host does not"
            );
        }
        for entry in &host {
            assert!(
                shader.contains(entry),
                "the host has {entry:?}, the shader does not"
            );
        }
    }

    /// The comparison can fail: a layout with one member moved by four bytes differs.
    #[test]
    fn a_moved_member_is_seen() {
        let mut host = host_layout();
        let i = host
            .iter()
            .position(|e| e.1 == "level")
            .expect("the record has a level");
        host[i].2 += 4;
        let shader = spirv::TERRAIN_LAYOUT.to_vec();
        assert!(host.iter().any(|e| !shader.contains(e)));
    }
}
