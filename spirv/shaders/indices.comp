#version 450
// Builds a level's index array on the GPU from the tile's vertex blocks already in the pool,
// so index arrays never cross the bus (renderer/src/vulkan/indices.rs records the dispatch).
//
// The mesh of level i is a function of its vertex set (tools/tiles/src/mesh.rs): a quadtree of
// cells over the 257 x 257 tile, each leaf drawn as one fan around its centre. Within the
// mesh's extent (mesh_max), a cell that straddles the extent's edge is always split, a cell
// past it is never drawn, and a cell inside it is split exactly when the centre of one of its
// children is a vertex (a leaf's centre is its fan's centre; a split cell's centre is a corner
// of its children's fans; no other vertex lies inside a leaf). A leaf's edge midpoint is in
// its fan exactly when it is a vertex. Fans go in P-order (the Hilbert curve over the 128 x
// 128 finest cells, as the builder sorts them), each as: centre, then the perimeter
// counter-clockwise from above starting at the north-west corner and closed by repeating it,
// then a restart (none after the last). The builder rotates each ring to start with the
// vertices a model of a vertex cache still holds; the GPU rotates it to start with the run of
// vertices it shares with the previous fan (consecutive fans are adjacent cells), so the
// arrays hold the same fans in the same order, not the same bytes.
//
// A tile drawn part by part gets one array whose 4 x 4 parts (64 x 64 cells) each come from
// a level of their own (tools/tiles/src/parts.rs, the CPU side, argues it): a point inside a
// part is a vertex when its level holds it, a point on a line between parts when the finest
// part there holds it, a point on the tile's border when the top level does; and a fan takes
// every vertex along its edges that lie on such lines, in order, so that the mesh has no
// T-junction. Those fans are not rotated.
//
// One workgroup builds one array: its invocations scatter the blocks' vertices into a
// position -> vertex lookup (a scratch slot per workgroup, never cleared: only positions this
// build wrote are read) and into a bitmap of the positions that are vertices (shared memory,
// where every test of the walk below goes), then each takes 64 consecutive finest cells along
// the curve, counts the indices of the leaves that start there, and after a prefix sum over
// the invocations writes them. A count that differs from the file's, or a fan vertex that
// is missing, is reported in `status` and nothing past the array is written.

#extension GL_EXT_shader_16bit_storage : require

layout(local_size_x = 256) in;

const uint SIDE = 257;
const uint LOOKUP_WORDS = SIDE * SIDE;
const uint CELLS_PER_INVOCATION = 64;
const uint NONE = 0xffffffffu;
// Cells per part side (a tile is 4 x 4 parts).
const uint PART = 64;

struct Build {
    // Pool word of block 0's first packed position, and the vertices of blocks 0..=level.
    uint vertex_word;
    uint vertex_count;
    // Pool position of the array's first index, in indices of its width (2 or 4 bytes).
    uint index_at;
    uint index_count;
    uint index_width;
    uint mesh_max_x;
    uint mesh_max_y;
    // Tile number, reported on failure.
    uint tile;
    // Drawn part by part (tiles/src/parts.rs): 1, with the 4 x 4 parts' levels 4 bits each
    // (part 4 j + i at bits 4 (4 j + i) of the 64) and, per level, the end of its block (the
    // vertices of blocks 0..=level). 0: one level, every vertex of blocks 0..=level.
    uint mixed;
    uint parts[2];
    uint ends[16];
    uint pad;
};

layout(std430, set = 0, binding = 0) readonly buffer Positions { uint positions[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Indices16 { uint16_t indices16[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Indices32 { uint indices32[]; };
layout(std430, set = 0, binding = 3) buffer Lookup { uint lookup[]; };
layout(std430, set = 0, binding = 4) readonly buffer Builds { Build builds[]; };
// [0] failed builds, [1] the first failing tile, [2] its GPU count, [3] its expected count.
layout(std430, set = 0, binding = 5) buffer Status { uint status[]; };

// `restart` is all ones, given at run time: a constant would be folded into a 16-bit constant,
// which SPIR-V forbids without the Int16 capability.
layout(push_constant) uniform Push { uint first_build; uint restart; } pc;

shared uint counts[256];
// Bit y * 257 + x: lattice point (x, y) is a vertex of the level.
shared uint present[(LOOKUP_WORDS + 31) / 32];

Build b;
uint lookup_base;

bool is_vertex(uint x, uint y) {
    uint i = y * SIDE + x;
    return (present[i / 32] & (1u << (i % 32))) != 0;
}

#include "parts.glsl"

// The level of part (i, j) of a mixed build.
uint part_level(uint i, uint j) {
    return packed_part_level(uvec2(b.parts[0], b.parts[1]), i, j);
}

// The level whose blocks give lattice point (x, y) of a mixed build its vertices.
uint presence_level(uint x, uint y, uint top) {
    return packed_presence_level(uvec2(b.parts[0], b.parts[1]), x, y, top);
}

// The block vertex v belongs to.
uint block_of(uint v) {
    uint k = 0;
    while (k < 15 && v >= b.ends[k]) {
        k++;
    }
    return k;
}

// The vertex at lattice point (x, y), or NONE.
uint vertex_at(uint x, uint y) {
    return is_vertex(x, y) ? lookup[lookup_base + y * SIDE + x] : NONE;
}

// Finest cell (i, j) at position d of the Hilbert curve over 128 x 128 cells (the inverse of
// the builder's hilbert_index).
uvec2 hilbert_cell(uint d) {
    uvec2 p = uvec2(0);
    uint t = d;
    for (uint s = 1; s < 128; s *= 2) {
        uint rx = 1 & (t / 2);
        uint ry = 1 & (t ^ rx);
        if (ry == 0) {
            if (rx == 1) {
                p = uvec2(s - 1) - p;
            }
            p = p.yx;
        }
        p += s * uvec2(rx, ry);
        t /= 4;
    }
    return p;
}

// Depth of the leaf covering finest cell `c`, or NONE where the mesh does not reach.
uint leaf_depth(uvec2 c) {
    for (uint d = 0; d < 7; d++) {
        uint s = 256u >> d;
        uvec2 o = (c >> (7 - d)) * s;
        if (o.x >= b.mesh_max_x || o.y >= b.mesh_max_y) {
            return NONE;
        }
        bool straddles = (b.mesh_max_x > o.x && b.mesh_max_x < o.x + s)
            || (b.mesh_max_y > o.y && b.mesh_max_y < o.y + s);
        if (!straddles) {
            uvec2 child = (c >> (6 - d)) * (s / 2) + s / 4;
            if (!is_vertex(child.x, child.y)) {
                return d;
            }
        }
    }
    uvec2 o = c * 2;
    return (o.x >= b.mesh_max_x || o.y >= b.mesh_max_y) ? NONE : 7;
}

// Lattice points of a leaf's fan in drawing order: centre, then corner 0, [mid 3], corner 3,
// [mid 2], corner 2, [mid 1], corner 1, [mid 0], corner 0 (corner k starts edge k; edges
// 0 N, 1 E, 2 S, 3 W). Returns the count (6 to 10).
uint fan(uvec2 o, uint s, out uvec2 points[10]) {
    uint h = s / 2;
    uvec2 corners[4] = uvec2[4](o, o + uvec2(s, 0), o + uvec2(s, s), o + uvec2(0, s));
    uvec2 mids[4] = uvec2[4](o + uvec2(h, 0), o + uvec2(s, h), o + uvec2(h, s), o + uvec2(0, h));
    uint n = 0;
    points[n++] = o + uvec2(h);
    points[n++] = corners[0];
    for (int k = 3; k >= 0; k--) {
        if (is_vertex(mids[k].x, mids[k].y)) {
            points[n++] = mids[k];
        }
        points[n++] = corners[k];
    }
    return n;
}

void put(uint at, uint value) {
    if (at >= b.index_count) {
        return;
    }
    if (b.index_width == 2) {
        indices16[b.index_at + at] = uint16_t(value);
    } else {
        indices32[b.index_at + at] = value;
    }
}

// Counts, or writes at `at` (when `write`), lattice point p of a fan.
void emit(uvec2 p, bool write, inout uint at, inout bool missing) {
    if (write) {
        uint v = vertex_at(p.x, p.y);
        missing = missing || v == NONE;
        put(at, v == NONE ? 0 : v);
    }
    at++;
}

// A mixed build's fan of leaf (o, s): centre, then the perimeter counter-clockwise from the
// north-west corner, closed by repeating it; along an edge on a line between parts or on the
// border every vertex, along any other the midpoint when it is one.
void mixed_fan(uvec2 o, uint s, bool write, inout uint at, inout bool missing) {
    uvec2 corners[4] = uvec2[4](o, o + uvec2(s, 0), o + uvec2(s, s), o + uvec2(0, s));
    emit(o + uvec2(s / 2), write, at, missing);
    emit(corners[0], write, at, missing);
    // Edges W (corner 0 -> 3), S (3 -> 2), E (2 -> 1), N (1 -> 0).
    const uint from[4] = uint[4](0, 3, 2, 1);
    const uint to[4] = uint[4](3, 2, 1, 0);
    for (uint e = 0; e < 4; e++) {
        ivec2 a = ivec2(corners[from[e]]);
        ivec2 c = ivec2(corners[to[e]]);
        ivec2 dir = sign(c - a);
        bool on_line = a.x == c.x ? (uint(a.x) % PART == 0) : (uint(a.y) % PART == 0);
        if (on_line) {
            for (uint t = 1; t < s; t++) {
                uvec2 p = uvec2(a + dir * int(t));
                if (is_vertex(p.x, p.y)) {
                    emit(p, write, at, missing);
                }
            }
        } else {
            uvec2 m = uvec2(a + dir * int(s / 2));
            if (is_vertex(m.x, m.y)) {
                emit(m, write, at, missing);
            }
        }
        emit(uvec2(c), write, at, missing);
    }
}

void fail(uint got) {
    if (atomicAdd(status[0], 1) == 0) {
        status[1] = b.tile;
        status[2] = got;
        status[3] = b.index_count;
    }
}

void main() {
    uint slot = gl_WorkGroupID.x;
    uint me = gl_LocalInvocationID.x;
    b = builds[pc.first_build + slot];
    lookup_base = slot * LOOKUP_WORDS;
    // A mixed build's top level, which its border takes.
    uint top = 0;
    for (uint k = 0; k < 16 && b.mixed != 0; k++) {
        top = max(top, part_level(k % 4, k / 4));
    }

    for (uint w = me; w < present.length(); w += 256) {
        present[w] = 0;
    }
    barrier();
    for (uint v = me; v < b.vertex_count; v += 256) {
        uint p = positions[b.vertex_word + v];
        uint x = p & 511;
        uint y = (p >> 9) & 511;
        if (x < SIDE && y < SIDE) {
            uint i = y * SIDE + x;
            lookup[lookup_base + i] = v;
            if (b.mixed == 0 || block_of(v) <= presence_level(x, y, top)) {
                atomicOr(present[i / 32], 1u << (i % 32));
            }
        }
    }
    memoryBarrierBuffer();
    memoryBarrierShared();
    barrier();

    // Pass 0 finds the leaves that start in this invocation's cells (skipping the rest of
    // each leaf's run of cells) and counts their indices (fan, restart); pass 1 writes them.
    uint first = me * CELLS_PER_INVOCATION;
    uint end = first + CELLS_PER_INVOCATION;
    uint starts[CELLS_PER_INVOCATION];
    uint depths[CELLS_PER_INVOCATION];
    uint leaves = 0;
    uint at = 0;
    for (uint h = first; h < end;) {
        uint d = leaf_depth(hilbert_cell(h));
        if (d == NONE) {
            h++;
            continue;
        }
        // A leaf of depth d covers 4^(7-d) consecutive positions: it is drawn at the first.
        uint run = 1u << (2 * (7 - d));
        if ((h & (run - 1)) == 0) {
            starts[leaves] = h;
            depths[leaves] = d;
            leaves++;
            uint s = 256u >> d;
            uvec2 o = (hilbert_cell(h) >> (7 - d)) * s;
            if (b.mixed != 0) {
                bool unused = false;
                mixed_fan(o, s, false, at, unused);
                at++;
            } else {
                uvec2 points[10];
                at += fan(o, s, points) + 1;
            }
        }
        h = (h | (run - 1)) + 1;
    }
    counts[me] = at;
    barrier();
    if (me == 0) {
        uint sum = 0;
        for (uint k = 0; k < 256; k++) {
            uint n = counts[k];
            counts[k] = sum;
            sum += n;
        }
        // The last fan has no restart.
        uint total = sum == 0 ? 0 : sum - 1;
        if (total != b.index_count) {
            fail(total);
        }
    }
    barrier();
    at = counts[me];
    bool missing = false;
    // The previous fan's cell (origin, size; size 0: none), for each ring's start.
    uvec2 previous = uvec2(0);
    uint previous_size = 0;
    // Before this invocation's first fan: the leaf of the cell just before it on the curve
    // (none if the mesh does not reach that cell).
    if (leaves > 0 && starts[0] > 0) {
        uvec2 c = hilbert_cell(starts[0] - 1);
        uint d = leaf_depth(c);
        if (d != NONE) {
            previous_size = 256u >> d;
            previous = (c >> (7 - d)) * previous_size;
        }
    }
    for (uint k = 0; k < leaves; k++) {
        uint d = depths[k];
        uint s = 256u >> d;
        uvec2 o = (hilbert_cell(starts[k]) >> (7 - d)) * s;
        if (b.mixed != 0) {
            mixed_fan(o, s, true, at, missing);
            put(at++, pc.restart);
            continue;
        }
        uvec2 points[10];
        uint n = fan(o, s, points);
        // The ring is points[1 .. n-1) (points[n-1] closes it): start it where the run of
        // vertices on the previous cell's boundary starts.
        uint ring = n - 2;
        uint start = 0;
        for (uint r = 0; r < ring && previous_size > 0; r++) {
            uvec2 p = points[1 + r];
            uvec2 q = points[1 + (r + ring - 1) % ring];
            uvec2 lo = previous;
            uvec2 hi = previous + previous_size;
            bool here = all(greaterThanEqual(p, lo)) && all(lessThanEqual(p, hi));
            bool before = all(greaterThanEqual(q, lo)) && all(lessThanEqual(q, hi));
            if (here && !before) {
                start = r;
                break;
            }
        }
        for (uint i = 0; i < n; i++) {
            uvec2 p = i == 0 ? points[0] : points[1 + (start + i - 1) % ring];
            uint v = vertex_at(p.x, p.y);
            missing = missing || v == NONE;
            put(at++, v == NONE ? 0 : v);
        }
        put(at++, pc.restart);
        previous = o;
        previous_size = s;
    }
    if (missing) {
        fail(NONE);
    }
}
