//! The terrain shaders' interface as the host writes it: the per-frame push constants, their
//! flag bits and the per-draw tile records. The one definition is the GLSL include
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
    pub pad: u32,
    /// Texture coordinate of tile-local sample coordinate `s`: `x + s * y` (the texture
    /// layout's `(g + s * T / 256) / S`); `z`: `S`, texels across a layer; `w`: the tiles
    /// shading's grid offset.
    pub texture_map: [f32; 4],
}

/// Size of the push-constant block.
pub const PUSH_CONSTANT_BYTES: u32 = std::mem::size_of::<FrameConstants>() as u32;

/// One drawn tile as the vertex shader reads it (`TileRecord`, std430).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct TileRecord {
    pub tile_offset: [i32; 2],
    pub height_base: i32,
    /// Pool word of block 0's first vertex.
    pub positions: u32,
    pub corners: [f32; 4],
    /// First vertex of blocks 1..=8 (u32::MAX past the last block).
    pub starts_lo: [u32; 4],
    pub starts_hi: [u32; 4],
    /// Metres per morph offset unit of levels 0..8.
    pub units_lo: [f32; 4],
    pub units_hi: [f32; 4],
    pub level: u32,
    /// Pool byte of block 0's morph rows.
    pub morph: u32,
    /// The tile's texture layer (u32::MAX: none) and finest resident mip.
    pub texture_layer: u32,
    pub texture_finest: f32,
    pub block_start: [u32; 9],
    pub block_len: [u32; 9],
    pub morph_start: [u32; 9],
    /// Samples the texture is moved by (0; `VKTERRAIN_FAULT=texture-seam` moves every other
    /// tile's, the seam test's negative control).
    pub texture_shift: f32,
}

/// Bytes of one record.
pub const RECORD_BYTES: u64 = std::mem::size_of::<TileRecord>() as u64;

/// `(field, offset)` of a `#[repr(C)]` struct, for the layout test.
macro_rules! fields {
    ($t:ty: $($f:ident),* $(,)?) => {
        vec![$((stringify!($f), std::mem::offset_of!($t, $f) as u32)),*]
    };
}

/// `(struct, field, offset)` of the mirrors, plus each array element's `"stride"` (its size),
/// in the form of `spirv::TERRAIN_LAYOUT`.
pub fn host_layout() -> Vec<(&'static str, &'static str, u32)> {
    let frame = fields!(FrameConstants: view_proj, camera, spacing_y, height_step, flags, pad,
        texture_map);
    let record = fields!(TileRecord: tile_offset, height_base, positions, corners, starts_lo,
        starts_hi, units_lo, units_hi, level, morph, texture_layer, texture_finest, block_start,
        block_len, morph_start, texture_shift);
    let mut layout: Vec<_> = frame
        .into_iter()
        .map(|(f, o)| ("FrameConstants", f, o))
        .chain(record.into_iter().map(|(f, o)| ("TileRecord", f, o)))
        .collect();
    layout.push(("TileRecord", "stride", RECORD_BYTES as u32));
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
