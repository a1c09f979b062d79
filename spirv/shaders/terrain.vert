#version 450
// The terrain's vertex shader: pulls its vertex from the tile pool and geomorphs it (paper,
// section 5, figure 6). The interface with the host is interface.glsl.
//
// Vertices are pulled, not fed: gl_VertexIndex is (draw record << 17) | the vertex's index in
// its tile (blocks 0.. in order). A tile's draw sets vertexOffset = record << 17 and indexes
// its fans with tile-local indices; a stitch indexes vertices of two tiles directly with such
// encoded indices, so every vertex of a stitch is computed from its own tile's record, bit
// for bit as that tile's draw computes it.
//
// What a vertex costs is mostly what it reads. On lavapipe a read from a storage buffer at an
// address that differs between vertices is a loop over the SIMD lanes, one scalar load each
// (about 40 of them a vertex when the record came from there); a read from a uniform buffer
// at an address the same for every vertex is one load for the whole batch. So a tile's draw
// reads its record through the Tile binding (moved to the record by the draw's dynamic
// offset) and the frame's morph constants through the Morph binding: what remains per vertex
// is the pool: its packed position, and its morphed height when it morphs.
//
// Positions are computed relative to the camera from integers wherever possible, so a grid
// point shared by two tiles lands on the same f32 position in every draw: its sample
// column/row relative to the camera's tile is the same integer, and its height the same
// integer code on the tile set's height lattice.
//
// Geomorphing (renderer/src/morph/mod.rs has the rule, its bound, and the CPU mirror of this
// arithmetic): every drawn vertex's morphed height is placed once a frame by the morph pass
// (morph.comp), coarse to fine, each vertex from its two parents' morphed heights, so that a
// vertex a finer level adds starts on the surface drawn before it. The vertex shader reads
// that height: one read beside its packed position, as a discrete vertex reads none.
//
// TWO_LEVELS (a second build, `--morph-shader two-levels`) is the previous per-vertex rule,
// kept for comparison: the vertex's own level l picks the two nested levels around it, k =
// floor(l) and k + 1, and its height blends the stored offsets o of those levels (one byte
// per coarser level) with the morph units u: H = own + (1 - t) o_k u_k + t o_(k+1) u_(k+1).
// MORPH_ALL_ROWS (a third) blends the same rule with the paper's clamped forward differences
// h = clamp(l - (0, 1, 2, ...), 0, 1), h'_0 = 1 - h_0, h'_k = h_{k-1} - h_k as dot products
// over every stored row. READ_BACK (a fourth, of the default) also writes each vertex's
// height to the Heights buffer, for the test that compares it with the CPU mirror.

#define TERRAIN_VERTEX
#include "interface.glsl"

// A tile's draw reads its record through the Tile binding, at offsets the same for every
// vertex of the draw; a stitch's vertices belong to two tiles and read theirs by record
// number. The pipelines for stitches set STITCH. Both read the same bytes, so a vertex a
// stitch shares with a tile lands where the tile's draw puts it, bit for bit.
layout(constant_id = 0) const bool STITCH = false;
#define REC(r, field) (STITCH ? records.tiles[r].field : draw.tile.field)

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
// The vertex's sample in its tile (its layer's samples): where the tile's texture is.
layout(location = 6) out vec2 tile_xy;

// Signed byte `byte` of the pool.
float pool_byte(uint byte) {
    return float(bitfieldExtract(int(pool.words[byte >> 2]), int((byte & 3u) * 8u), 8));
}

// Metres per morph offset unit of level k.
float unit_of(uint r, uint k) {
    return REC(r, units[k >> 2u])[k & 3u];
}

void main() {
    uint id = uint(gl_VertexIndex);
    uint r = id >> 17;
    uint local = id & 0x1ffffu;
    uint v = pool.words[REC(r, positions) + local];
    uint x = v & 511u;
    uint y = (v >> 9) & 511u;
    uint code = v >> 18;
    // A pyramid layer's samples are 2^layer base samples apart.
    uint layer_shift = REC(r, layer);
    ivec2 sample_pos = REC(r, tile_offset) + (ivec2(int(x), int(y)) << layer_shift);
    float own = float(REC(r, height_base) + int(code)) * REC(r, height_step);
    relative = vec3(float(sample_pos.x) * frame.camera.w, -float(sample_pos.y) * frame.spacing_y, own) - frame.camera.xyz;

    float l = float(REC(r, level));
    height = own;
    if ((frame.flags & FLAG_GEOMORPH) != 0u) {
#if defined(TWO_LEVELS) || defined(MORPH_ALL_ROWS)
        vec4 clip = frame.view_proj * vec4(relative, 1.0);
        l = min(vertex_level(clip, REC(r, tables[table_of(x, y)])), REC(r, cap));
        // The vertex's block j: how many block starts it has passed.
        uvec4 passed = uvec4(greaterThanEqual(uvec4(local), REC(r, starts_lo)))
                     + uvec4(greaterThanEqual(uvec4(local), REC(r, starts_hi)));
        uint j = passed.x + passed.y + passed.z + passed.w;
        uvec4 block = REC(r, blocks[j]);
        uint rows = block.z + (local - block.x);   // row k of the block is at rows + k * block.y
        uint last = max(j, 1u) - 1u;
#ifdef MORPH_ALL_ROWS
        vec4 o_lo, o_hi, u_lo, u_hi;
        for (uint k = 0u; k < 4u; ++k) {
            // Rows past the block's last read its last row, masked to 0.
            o_lo[k] = pool_byte(rows + min(k, last) * block.y) * float(k < j);
            o_hi[k] = pool_byte(rows + min(k + 4u, last) * block.y) * float(k + 4u < j);
            u_lo[k] = unit_of(r, k);
            u_hi[k] = unit_of(r, k + 4u);
        }
        vec4 h_lo = clamp(vec4(l) - vec4(0.0, 1.0, 2.0, 3.0), 0.0, 1.0);
        vec4 h_hi = clamp(vec4(l) - vec4(4.0, 5.0, 6.0, 7.0), 0.0, 1.0);
        vec4 w_lo = vec4(1.0, h_lo.xyz) - h_lo;
        vec4 w_hi = vec4(h_lo.w, h_hi.xyz) - h_hi;
        float shift = dot(w_lo, o_lo * u_lo) + dot(w_hi, o_hi * u_hi);
#else
        // k = floor(l) below the block (l >= j gives k = j - 1 and t = 1 on a zero offset).
        uint k = min(uint(l), last);
        float t = clamp(l - float(k), 0.0, 1.0);
        float lower = pool_byte(rows + k * block.y) * unit_of(r, k) * float(j > 0u);
        uint above = min(k + 1u, last);
        float upper = pool_byte(rows + above * block.y) * unit_of(r, above) * float(k + 1u < j);
        float shift = lower * (1.0 - t) + upper * t;
#endif
        height = own + shift;
#else
        // The morph pass placed every drawn vertex: one read (none for a tile past the frame's
        // morphed heights, drawn unmorphed).
        uint at = REC(r, heights);
        if (at != 0xffffffffu) {
            height = morphed.values[at + local];
        }
        if ((frame.flags & FLAG_LEVEL_COLOURS) != 0u) {
            vec4 clip = frame.view_proj * vec4(relative, 1.0);
            l = min(vertex_level(clip, REC(r, tables[table_of(x, y)])), REC(r, cap));
        }
#endif
        relative.z = height - frame.camera.z;
    }
#ifdef READ_BACK
    heights.values[REC(r, heights) + local] = height;
#endif
    level = l;
    flags = frame.flags;
    sample_xy = vec2(sample_pos);
    tile_xy = vec2(x, y);
    uint layer = REC(r, texture_layer);
    texture_tile = vec4(vec2(-REC(r, texture_shift)),
                        layer == 0xffffffffu ? -1.0 : float(layer),
                        REC(r, texture_finest));
    gl_Position = frame.view_proj * vec4(relative, 1.0);
}
