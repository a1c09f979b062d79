#version 450
// The terrain's vertex shader: pulls its vertex from the tile pool and geomorphs it (paper,
// section 5, figure 6).
//
// Vertices are pulled, not fed: gl_VertexIndex is (draw record << 17) | the vertex's index in
// its tile (blocks 0.. in order). A tile's draw sets vertexOffset = record << 17 and indexes
// its fans with tile-local indices; a stitch indexes vertices of two tiles directly with such
// encoded indices, so every vertex of a stitch is computed from its own tile's record, bit
// for bit as that tile's draw computes it.
//
// Positions are computed relative to the camera from integers wherever possible, so a grid
// point shared by two tiles lands on the same f32 position in every draw: its sample
// column/row relative to the camera's tile is the same integer, and its height the same
// integer code on the tile set's height lattice.
//
// Geomorphing: the vertex's continuous level l(v) is the bilinear interpolation of the tile's
// corner levels (exact on the tile's edges, where it depends on the edge's two corners alone,
// which neighbouring tiles share). Its height blends the nested levels' heights H_k with the
// clamped forward differences h = clamp(l - (0, 1, 2, ...), 0, 1), h'_0 = 1 - h_0,
// h'_k = h_{k-1} - h_k: H(l) = sum h'_k H_k, as dot products without branches. For a vertex of
// block j, H_k = own height + offset_k * unit_k for k < j (one stored byte per coarser level)
// and H_k = own height for k >= j. renderer/src/morph.rs is the CPU mirror of this arithmetic.
//
// MORPH_BRANCHES (a second build of this file) finds the two levels to blend with branches
// instead, the reference the paper measured forward differences against.

#define TERRAIN_VERTEX
#include "interface.glsl"

layout(location = 0) out vec3 relative;   // position relative to the camera (m)
layout(location = 1) out float height;    // absolute height (m)
layout(location = 2) out float level;     // the vertex's continuous level
layout(location = 3) flat out uint flags;
// Texturing: the sample position relative to the camera's tile (columns, rows), and the
// provoking vertex's tile: its first sample there, its texture layer (-1: none) and finest
// resident mip. Stitch triangles join two tiles; the fragment shader takes texture
// coordinates relative to the provoking vertex's tile, so they sample one layer consistently.
layout(location = 4) out vec2 sample_xy;
layout(location = 5) flat out vec4 texture_tile;

// Signed byte `byte` of the pool.
float pool_byte(uint byte) {
    return float(bitfieldExtract(int(pool.words[byte >> 2]), int((byte & 3u) * 8u), 8));
}

// Bilinear in the corners; t in {0, 1} gives the end values exactly.
float vertex_level(vec4 c, uint x, uint y) {
    float fx = float(x) / 256.0;
    float fy = float(y) / 256.0;
    float top = c.x * (1.0 - fx) + c.y * fx;
    float bottom = c.z * (1.0 - fx) + c.w * fx;
    return top * (1.0 - fy) + bottom * fy;
}

void main() {
    uint id = uint(gl_VertexIndex);
    uint r = id >> 17;
    uint local = id & 0x1ffffu;
    uint v = pool.words[records.tiles[r].positions + local];
    uint x = v & 511u;
    uint y = (v >> 9) & 511u;
    uint code = v >> 18;
    ivec2 sample_pos = records.tiles[r].tile_offset + ivec2(int(x), int(y));
    float own = float(records.tiles[r].height_base + int(code)) * frame.height_step;

    float l = float(records.tiles[r].level);
    if ((frame.flags & FLAG_GEOMORPH) != 0u) {
        l = vertex_level(records.tiles[r].corners, x, y);
    }
    // The vertex's block j: how many block starts it has passed.
    uvec4 passed_lo = uvec4(greaterThanEqual(uvec4(local), records.tiles[r].starts_lo));
    uvec4 passed_hi = uvec4(greaterThanEqual(uvec4(local), records.tiles[r].starts_hi));
    uvec4 sum = passed_lo + passed_hi;
    uint j = sum.x + sum.y + sum.z + sum.w;
    uint in_block = local - records.tiles[r].block_start[j];
    uint rows = records.tiles[r].morph + records.tiles[r].morph_start[j] + in_block;
    uint len = records.tiles[r].block_len[j];
    // Row k of the block for k < j; rows past the block's last read its last row, masked to 0.
    uint last = max(j, 1u) - 1u;
    vec4 o_lo, o_hi;
    for (uint k = 0u; k < 4u; ++k) {
        o_lo[k] = pool_byte(rows + min(k, last) * len) * float(k < j);
        o_hi[k] = pool_byte(rows + min(k + 4u, last) * len) * float(k + 4u < j);
    }
    vec4 d_lo = o_lo * records.tiles[r].units_lo;
    vec4 d_hi = o_hi * records.tiles[r].units_hi;

#ifdef MORPH_BRANCHES
    // The two levels around l, found by branching.
    float shift = 0.0;
    if (l < float(j)) {
        float lower = floor(l);
        uint k = uint(lower);
        float f = l - lower;
        float dk = k < 4u ? d_lo[k] : d_hi[k - 4u];
        float dk1 = 0.0;
        if (k + 1u < j) {
            dk1 = k + 1u < 4u ? d_lo[k + 1u] : d_hi[k - 3u];
        }
        shift = dk * (1.0 - f) + dk1 * f;
    }
#else
    vec4 h_lo = clamp(vec4(l) - vec4(0.0, 1.0, 2.0, 3.0), 0.0, 1.0);
    vec4 h_hi = clamp(vec4(l) - vec4(4.0, 5.0, 6.0, 7.0), 0.0, 1.0);
    vec4 w_lo = vec4(1.0, h_lo.xyz) - h_lo;
    vec4 w_hi = vec4(h_lo.w, h_hi.xyz) - h_hi;
    float shift = dot(w_lo, d_lo) + dot(w_hi, d_hi);
#endif

    height = own + shift;
    relative = vec3(float(sample_pos.x) * frame.camera.w, -float(sample_pos.y) * frame.spacing_y, height) - frame.camera.xyz;
    level = l;
    flags = frame.flags;
    sample_xy = vec2(sample_pos);
    uint layer = records.tiles[r].texture_layer;
    texture_tile = vec4(vec2(records.tiles[r].tile_offset) + records.tiles[r].texture_shift,
                        layer == 0xffffffffu ? -1.0 : float(layer),
                        records.tiles[r].texture_finest);
    gl_Position = frame.view_proj * vec4(relative, 1.0);
}
