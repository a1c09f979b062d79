#version 450
// The morph pass: places every vertex a frame draws at its morphed height, once a frame,
// before the draws (renderer/src/morph/mod.rs has the rule, its error bound and the CPU mirror of
// this arithmetic; renderer/src/vulkan/morph_pass.rs records the dispatch).
//
// The vertices of a tile's meshes form a hierarchy: every vertex but the tile's corners lies
// midway between two parents of a coarser scale (an edge's midpoint between the edge's ends,
// a cell's centre between its parent cell's centre and the parent's corner it faces), and a
// mesh that lacks the vertex has the segment between its parents as an edge, so its surface
// there is the parents' mean. A vertex of block j with level l is placed at
//
//     m(v) = (m(p) + m(q)) / 2 + w (own(v) - (own(p) + own(q)) / 2),   w = clamp(l - j + 1, 0, 1),
//
// its parents' mean plus its share w of its own detail; block 0 is always at its own height.
// Its level l is the one its position and the camera give it, raised towards the levels on the
// segments in view from it to the corners of its star's box (star_error below), and to at
// least what its parents of its own block pass on (a grid point's third value, below).
// Where every vertex is at w = 1 that is the level's surface; where a vertex has w = 0 it lies
// on the surface drawn without it, so a finer level arriving moves nothing at first.
//
// One workgroup places one tile at a time (the records r = g, g + groups, ...), in a scratch
// region of its own (never cleared: every parent is a vertex of the tile's drawn blocks, so
// only what was written for this tile is read). First each invocation takes vertices of the
// tile, writes their own heights into the region's 257 x 257 grid, places block 0 (level 0 to
// pass on), and lists every other vertex under its scale (a list per scale, at a fixed place,
// as long as the grid has points of that scale). Then, from the coarsest scale (128 samples)
// to the finest (1), the invocations place the vertices of one list each round from the grid,
// with a barrier between scales: a vertex is placed once (its pool word read again then, as
// the lists hold only its index).

#define MORPH_PASS
#include "interface.glsl"

layout(local_size_x = 32) in;
const uint LANES = 32u;

const uint SIDE = 257;
const uint GRID = SIDE * SIDE;
// A workgroup's region, in words: the grid, three a point (its own and morphed height and the
// level it passes to its children, as floats' bits), then the lists of vertices (their indices
// in the draw) by scale: 1,056,768 bytes, no more than the two-word grid and two-word entries
// it had before the passed level (renderer/src/vulkan/morph_pass.rs, MORPH_REGION_BYTES).
const uint LIST_ENTRIES = 66045u;
const uint REGION = 3u * GRID + LIST_ENTRIES;

layout(std430, set = 0, binding = 7) coherent buffer Scratch { uint words[]; } scratch;
layout(std430, set = 0, binding = 6) writeonly buffer Morphed { float values[]; } morphed;

// The level whose blocks the draw's mesh takes at a point (the index builder's rule).
#include "parts.glsl"
#include "hierarchy.glsl"

// A grid point's third value, the level it passes to its children, is a placed vertex's level
// held to its block, clamp(l, j - 1, j), so that a child of its block takes at least its
// weight and a child of a finer block nothing (renderer/src/morph/mod.rs, "Within a block";
// morph::hierarchy mirrors it); 0 for block 0 and the tile's corners.

// Grid point (x, y)'s first word in a region.
uint point_at(uint region, uint x, uint y) {
    return region + 3u * (y * SIDE + x);
}

// A grid point's (own, morphed, passed) values.
vec3 point_values(uint at) {
    return uintBitsToFloat(uvec3(scratch.words[at], scratch.words[at + 1u],
                                 scratch.words[at + 2u]));
}

// Vertices listed per scale index (scale 2^k at k) for the tile being placed.
shared uint listed[8];

// Where the list of scale index k starts (in list entries): after the lists of the coarser
// scales, each as long as the grid's points of its scale, (256/s + 1)^2 - (128/s + 1)^2 for
// s = 2^k < 256 (the first of which, s = 128, has 5: the tile's centre and edge midpoints;
// the last, s = 1, ends at LIST_ENTRIES), after the grid's 3 GRID words.
const uint LIST_START[8] = uint[](16637u, 4221u, 1085u, 285u, 77u, 21u, 5u, 0u);

// The scale index of tile-local grid point (x, y): log2 of the largest power of two dividing
// both (8 or more for the tile's corners, which have no parents and stay at their own height).
uint scale_index(uint x, uint y) {
    uint m = x | y;
    return m == 0u ? 9u : uint(findLSB(m));
}

// The part of the segment from clip position `a` to `b` that is in view (inside the image and
// at least twice the near plane's depth away), as (lo, hi) along it: empty where lo > hi.
vec2 in_view(vec4 a, vec4 b) {
    float near = 2.0 * frame_morph.morph.near;
    float fa[5] = float[](a.w - a.x, a.w + a.x, a.w - a.y, a.w + a.y, a.w - near);
    float fb[5] = float[](b.w - b.x, b.w + b.x, b.w - b.y, b.w + b.y, b.w - near);
    float lo = 0.0;
    float hi = 1.0;
    for (int i = 0; i < 5; ++i) {
        float d = fb[i] - fa[i];
        if (d > 0.0) {
            lo = max(lo, -fa[i] / d);
        } else if (d < 0.0) {
            hi = min(hi, -fa[i] / d);
        } else if (fa[i] < 0.0) {
            hi = -1.0;
        }
    }
    return vec2(lo, hi);
}

// How far inside the view clip position `p` is, as a share of the half-image: its distance to
// the image's nearest edge, and less within four near planes' depth (0 at twice the near
// plane's depth and nearer, as off the image).
float depth_in_view(vec4 p) {
    float near = 2.0 * frame_morph.morph.near;
    if (p.w <= near) {
        return 0.0;
    }
    float m = min(min(p.w - abs(p.x), p.w - abs(p.y)), p.w - near);
    return max(m / p.w, 0.0);
}

// How fully the segment from clip position `a` (a vertex, `depth_a` its depth_in_view) to `b`
// (a corner of its star) counts towards the vertex's level: how far inside the view the deepest
// of its ends and midpoint is, over the ramp.
float star_weight(float depth_a, vec4 a, vec4 b) {
    float inside = max(max(depth_a, depth_in_view(b)), depth_in_view(0.5 * (a + b)));
    return clamp(inside / frame_morph.morph.ramp, 0.0, 1.0);
}

// The error allowed at a vertex whose own allowed error is `e`, lowered towards that at the
// farthest point in view on the segment to each corner of its star's box (x +- reach.x,
// y +- reach.y at its height), weighted by how deep in view the segment reaches
// (renderer/src/morph/mod.rs, "Over the star").
float star_error(vec4 clip, float e, vec2 reach) {
    vec4 east = frame.view_proj[0] * (reach.x * frame.camera.w);
    vec4 south = frame.view_proj[1] * (-reach.y * frame.spacing_y);
    float depth = depth_in_view(clip);
    float lift = 0.0;
    for (int k = 0; k < 4; ++k) {
        vec4 q = (clip + ((k & 1) == 0 ? -east : east)) + ((k & 2) == 0 ? -south : south);
        vec2 span = in_view(clip, q);
        if (span.x <= span.y) {
            float weight = star_weight(depth, clip, q);
            vec4 p = clip + (q - clip) * span.y;
            lift = max(lift, weight * (e - allowed_error(p)));
        }
    }
    return e - lift;
}

void main() {
    uint g = gl_WorkGroupID.x;
    uint groups = gl_NumWorkGroups.x;
    uint lane = gl_LocalInvocationID.x;
    uint region = g * REGION;
    for (uint r = g; r < frame.draws; r += groups) {
        uint positions = records.tiles[r].positions;
        uint level = records.tiles[r].level;
        uint out_at = records.tiles[r].heights;
        if (out_at == 0xffffffffu) {
            continue;   // past the frame's morphed heights: drawn unmorphed (the same for the group)
        }
        int height_base = records.tiles[r].height_base;
        ivec2 tile_offset = records.tiles[r].tile_offset;
        uint layer_shift = records.tiles[r].layer;
        float height_step = records.tiles[r].height_step;
        float cap = records.tiles[r].cap;
        uvec4 starts_lo = records.tiles[r].starts_lo;
        uvec4 starts_hi = records.tiles[r].starts_hi;
        // The interior's level table, which most vertices take, read once for the tile.
        LevelCoefficients interior = records.tiles[r].tables[0];
        uvec2 extent = records.tiles[r].extent.xy;
        uvec2 parts = uvec2(records.tiles[r].parts_lo, records.tiles[r].parts_hi);
        uvec4 last = records.tiles[r].blocks[min(level, 8u)];
        uint count = last.x + last.y;
        if (level == 0u) {
            // Block 0 alone, every vertex at its own height: no grid, no lists, no barrier
            // (the same for the whole group). Most far tiles of a view are drawn so.
            for (uint i = lane; i < count; i += LANES) {
                uint v = pool.words[positions + i];
                morphed.values[out_at + i] = float(height_base + int(v >> 18)) * height_step;
            }
            continue;
        }
        if (lane < 8u) {
            listed[lane] = 0u;
        }
        barrier();
        // Own heights into the grid; block 0 placed; the others listed by scale.
        for (uint i = lane; i < count; i += LANES) {
            uint v = pool.words[positions + i];
            uint x = v & 511u;
            uint y = (v >> 9) & 511u;
            float own = float(height_base + int(v >> 18)) * height_step;
            uint at = point_at(region, x, y);
            scratch.words[at] = floatBitsToUint(own);
            scratch.words[at + 1u] = floatBitsToUint(own);
            scratch.words[at + 2u] = 0u;
            uint k = scale_index(x, y);
            uvec4 passed = uvec4(greaterThanEqual(uvec4(i), starts_lo))
                         + uvec4(greaterThanEqual(uvec4(i), starts_hi));
            uint j = passed.x + passed.y + passed.z + passed.w;
            if (i < starts_lo.x || k > 7u) {
                morphed.values[out_at + i] = own;
            } else if (j <= packed_presence_level(parts, x, y, level)) {
                // (A vertex the mesh does not hold is neither placed nor drawn.)
                uint slot = atomicAdd(listed[k], 1u);
                scratch.words[region + 3u * GRID + LIST_START[k] + slot] = i;
            }
        }
        memoryBarrierBuffer();
        barrier();
        for (int k = 7; k >= 0; --k) {
            uint s = 1u << uint(k);
            uint start = LIST_START[k];
            uint n = listed[k];
            if (n == 0u) {
                continue;   // the same for the whole workgroup: no barrier is skipped by part
            }
            for (uint e = lane; e < n; e += LANES) {
                uint i = scratch.words[region + 3u * GRID + start + e];
                uint v = pool.words[positions + i];
                uint x = v & 511u;
                uint y = (v >> 9) & 511u;
                uvec2 p, q;
                parents_of(x, y, uint(k), p, q);
                // Each parent's own and placed heights, and the level it passes on.
                vec3 a = point_values(point_at(region, p.x, p.y));
                vec3 b = point_values(point_at(region, q.x, q.y));
                float own = float(height_base + int(v >> 18)) * height_step;
                ivec2 sample_pos = tile_offset + (ivec2(int(x), int(y)) << layer_shift);
                vec3 relative = vec3(float(sample_pos.x) * frame.camera.w,
                                     -float(sample_pos.y) * frame.spacing_y, own)
                              - frame.camera.xyz;
                vec4 clip = frame.view_proj * vec4(relative, 1.0);
                uint t = table_of(x, y);
                LevelCoefficients c;
                if (t == 0u) {
                    c = interior;
                } else {
                    c = records.tiles[r].tables[t];
                }
                // The star's reach (TileMorph::reach): none across a line between parts or
                // past the mesh's last column or row; along a tile's side its scale, across
                // the side at most SIDE_REACH.
                // (In base samples: a pyramid layer's are 2^layer apart.)
                bool side_x = x == 0u || x == 256u;
                bool side_y = y == 0u || y == 256u;
                vec2 reach = float(s << layer_shift)
                           * vec2(bvec2((side_y || (x & 63u) != 0u) && x + s <= extent.x,
                                        (side_x || (y & 63u) != 0u) && y + s <= extent.y));
                if (side_x) {
                    reach.x = float(min(s, SIDE_REACH) << layer_shift);
                }
                if (side_y) {
                    reach.y = float(min(s, SIDE_REACH) << layer_shift);
                }
                if (side_x && side_y) {
                    reach = vec2(0.0);
                }
                float allowed = allowed_error(clip);
                if (reach != vec2(0.0)) {
                    allowed = star_error(clip, allowed, reach);
                }
                // At least the levels its parents pass on ("Within a block").
                // (No further than the coarsest part holding it draws: a part's fans hold
                // no vertex of a finer block than its own away from weight 0.)
                float inherited = min(max(a.z, b.z),
                                      float(packed_coarsest_level(parts, x, y, level)));
                float l = max(min(level_for(allowed, c), cap), inherited);
                uvec4 passed = uvec4(greaterThanEqual(uvec4(i), starts_lo))
                             + uvec4(greaterThanEqual(uvec4(i), starts_hi));
                uint j = passed.x + passed.y + passed.z + passed.w;
                float w = clamp(l - float(j) + 1.0, 0.0, 1.0);
                float m = 0.5 * (a.y + b.y) + w * (own - 0.5 * (a.x + b.x));
                float held = clamp(l, float(j) - 1.0, float(j));
                uint at = point_at(region, x, y);
                scratch.words[at + 1u] = floatBitsToUint(m);
                scratch.words[at + 2u] = floatBitsToUint(held);
                morphed.values[out_at + i] = m;
            }
            memoryBarrierBuffer();
            barrier();
        }
        // Every invocation is done with this tile's counts before the next resets them (the
        // scales skipped above skipped their barriers too).
        barrier();
    }
}
