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
// How far (samples) the star of a vertex on a tile's side reaches across the side, into both
// tiles (renderer/src/morph/mod.rs, "Over the star"; renderer/src/lod.rs covers it).
const uint SIDE_REACH = 16u;

layout(push_constant) uniform FrameConstants {
    mat4 view_proj;          // camera at the origin, world axes x east, y north, z up
    vec4 camera;             // xyz: camera relative to its tile's north-west corner (m); w: metres per column
    float spacing_y;         // metres per row (rows run south)
    float height_step;       // metres per height code, one for the tile set
    uint flags;              // FLAG_*
    uint draws;              // tile records this frame (the morph pass's count)
    vec4 texture_map;        // texture coordinate of tile-local sample s: x + s * y; z: texels across a layer; w: tile grid offset (samples) for the tiles shading
} frame;

#if defined(TERRAIN_VERTEX) || defined(MORPH_PASS)
// The frame's constants of the vertex level rule (renderer/src/morph/mod.rs): a vertex whose
// unmorphed position relative to the camera is at clip position c has |J z| =
// |jacobian.xy * c.w + jacobian.zw * c.xy| / c.w^2 pixels per vertical metre, and level
// l = sum_k clamp(a_k - r * b_k, 0, 1) for r = tau / |J z| (the finest behind `near`), with
// the coefficients of its level table.
struct MorphFrame {
    vec4 jacobian;
    float tau;               // pixels
    float near;              // the near plane's depth (m)
    float ramp;              // how deep in view (share of the half-image) a star's segment counts fully
    float pad;
};

// The coefficients of one level table: a_k and b_k for levels 0..3 and 4..7.
struct LevelCoefficients {
    vec4 a_lo;
    vec4 a_hi;
    vec4 b_lo;
    vec4 b_hi;
};

// One drawn tile (std430).
struct TileRecord {
    ivec2 tile_offset;       // the tile's first sample relative to the camera tile's (columns, rows)
    int height_base;         // the tile's lowest code on the shared lattice
    uint positions;          // pool word of block 0's first packed vertex
    uvec4 starts_lo;         // first vertex of blocks 1..4 (0xffffffff past the last block)
    uvec4 starts_hi;         // first vertex of blocks 5..8
    uvec4 blocks[9];         // per block: first vertex, vertices, pool byte of its morph rows, 0
    vec4 units[2];           // metres per morph offset unit of levels 0..3, 4..7 (vec4s: std140 = std430)
    uint level;              // the level drawn
    float cap;               // the level the vertices morph to at most
    uint heights;            // where the tile's first vertex's morphed height goes (Morphed, read-back)
    uint texture_layer;      // the tile's texture slot (0xffffffff: none)
    float texture_finest;    // its finest resident mip
    float texture_shift;     // samples the texture is moved by (0; a test's fault injection)
    uint parts_lo;           // the levels of parts 0..7 (part 4 j + i: (i, j) of 4 x 4), 4 bits each,
    uint parts_hi;           // and of parts 8..15 (drawn whole: the level in every part)
    // The level tables of the tile's vertices: its own (interior), the N, E, S, W sides (the
    // larger errors of the tile and that neighbour) and the NW, NE, SW, SE corners (of the
    // tiles there), so that every tile holding a vertex gives it the same table.
    LevelCoefficients tables[9];
    uvec4 extent;            // xy: the mesh's last column and row (256 but in a partial tile)
    uint layer;              // its pyramid layer p: vertex (x, y) at tile_offset + (x, y) << p
    float height_step;       // its layer's metres per height code
    uvec2 pad1;
    // To 1024 bytes: a record's offset in the buffer is then a multiple of any device's
    // minUniformBufferOffsetAlignment (at most 256), as the Tile binding's dynamic offset must be.
    uvec4 pad2[10];
};

layout(std430, set = 0, binding = 0) readonly buffer Pool { uint words[]; } pool;
// The frame's records buffer: its MorphFrame at byte 0 (the Morph binding below), the tile
// records from byte 256 (aligned for the Tile binding, as above).
layout(std430, set = 0, binding = 1) readonly buffer Records {
    layout(offset = 256) TileRecord tiles[];
} records;
// The records buffer's first bytes as a uniform buffer: the frame's morph constants.
layout(std140, set = 0, binding = 5) uniform Morph { MorphFrame morph; } frame_morph;
#endif

#ifdef TERRAIN_VERTEX
// The tile a draw draws, read with uniform offsets: the same records through a dynamic
// uniform buffer whose offset each tile's draw moves to its own record. A shader's reads of a
// whole draw's record are then one load for all its vertices (on lavapipe, a broadcast
// instead of a per-vertex loop over the storage buffer). Stitches join two tiles and read the
// records above by each vertex's record number.
layout(std140, set = 0, binding = 4) uniform Tile { TileRecord tile; } draw;
// Each drawn vertex's morphed height (m), at its record's `heights` plus its index in the
// tile: written by the morph pass (morph.comp) before the frame's draws.
layout(std430, set = 0, binding = 6) readonly buffer Morphed { float values[]; } morphed;
#ifdef READ_BACK
// Each drawn vertex's height (m), at its record's `heights` plus its index in the tile.
layout(std430, set = 0, binding = 3) writeonly buffer Heights { float values[]; } heights;
#endif
#endif

#if defined(TERRAIN_VERTEX) || defined(MORPH_PASS)
// Which of a record's level tables a vertex at tile-local (x, y) takes: 0 inside, 1..4 on
// the N, E, S, W sides, 5..8 at the NW, NE, SW, SE corners.
uint table_of(uint x, uint y) {
    uint column = x == 0u ? 0u : (x == 256u ? 2u : 1u);
    uint row = y == 0u ? 0u : (y == 256u ? 2u : 1u);
    const uint tables[9] = uint[](5u, 1u, 6u, 4u, 0u, 2u, 7u, 3u, 8u);
    return tables[row * 3u + column];
}

// The vertical error (m) that projects to tau pixels at clip position `clip`: 0 behind the near
// plane (the finest level). renderer/src/morph/mod.rs has the rule and its CPU mirror.
float allowed_error(vec4 clip) {
    float d = clip.w;
    MorphFrame m = frame_morph.morph;
    vec2 g = m.jacobian.xy * d + m.jacobian.zw * clip.xy;
    return d < m.near ? 0.0 : m.tau * d * d * inversesqrt(max(dot(g, g), 1e-30));
}

// The level whose error is `e` under level table `c` (Λ).
float level_for(float e, LevelCoefficients c) {
    vec4 lo = clamp(c.a_lo - e * c.b_lo, 0.0, 1.0);
    vec4 hi = clamp(c.a_hi - e * c.b_hi, 0.0, 1.0);
    return dot(lo + hi, vec4(1.0));
}

// l(v) for a vertex whose unmorphed position is at `clip`, with level table `c`.
float vertex_level(vec4 clip, LevelCoefficients c) {
    return level_for(allowed_error(clip), c);
}
#endif
