// The terrain shaders' interface with the host, defined once: the per-frame push constants,
// their flag bits and the per-draw tile records. Included by terrain.vert and terrain.frag
// (shaderc's include callback, spirv/build.rs). The host's mirror is renderer/src/interface.rs:
// its flag constants are read from this file when the spirv crate builds, and its tests check
// every field's offset against the layout compiled from this file (the SPIR-V's own Offset
// decorations), so the two cannot drift apart unnoticed.

// FrameConstants::flags. One `const uint NAME = VALUEu;` per line: spirv/build.rs reads them.
const uint FLAG_GEOMORPH = 1u;         // blend the levels (off: --no-geomorph)
const uint FLAG_LEVEL_COLOURS = 2u;    // colour by level
const uint FLAG_TEXTURE = 4u;          // sample the tile's texture
const uint FLAG_RELIEF = 8u;           // grey relief
const uint FLAG_TILES = 16u;           // a flat colour per tile

layout(push_constant) uniform FrameConstants {
    mat4 view_proj;          // camera at the origin, world axes x east, y north, z up
    vec4 camera;             // xyz: camera relative to its tile's north-west corner (m); w: metres per column
    float spacing_y;         // metres per row (rows run south)
    float height_step;       // metres per height code, one for the tile set
    uint flags;              // FLAG_*
    uint pad;
    vec4 texture_map;        // texture coordinate of tile-local sample s: x + s * y; z: texels across a layer; w: tile grid offset (samples) for the tiles shading
} frame;

#ifdef TERRAIN_VERTEX
// One drawn tile (std430).
struct TileRecord {
    ivec2 tile_offset;       // the tile's first sample relative to the camera tile's (columns, rows)
    int height_base;         // the tile's lowest code on the shared lattice
    uint positions;          // pool word of block 0's first packed vertex
    vec4 corners;            // continuous level at the NW, NE, SW, SE corners
    uvec4 starts_lo;         // first vertex of blocks 1..4 (0xffffffff past the last block)
    uvec4 starts_hi;         // first vertex of blocks 5..8
    vec4 units_lo;           // metres per morph offset unit, levels 0..3
    vec4 units_hi;           // levels 4..7
    uint level;              // the level drawn
    uint morph;              // pool byte of block 0's morph rows
    uint texture_layer;      // the tile's texture slot (0xffffffff: none)
    float texture_finest;    // its finest resident mip
    uint block_start[9];     // first vertex of each block
    uint block_len[9];       // vertices of each block
    uint morph_start[9];     // byte of each block's morph rows, from `morph`
    float texture_shift;     // samples the texture is moved by (0; a test's fault injection)
};

layout(std430, set = 0, binding = 0) readonly buffer Pool { uint words[]; } pool;
layout(std430, set = 0, binding = 1) readonly buffer Records { TileRecord tiles[]; } records;
#endif
