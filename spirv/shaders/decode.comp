#version 450
// Decodes one level of a tile's compact levels (tools/tiles/src/compact.rs has the encoding
// and its CPU decoder) into the level's block of packed positions, on the GPU, so that a
// refinement crosses the bus as its bit stream: which vertices the level adds, and their
// heights as residuals (renderer/src/vulkan/decode.rs records the dispatch).
//
// A level's stream is: the vertices without known parents, raw (a 16-bit count, then x, y
// and height code in 9, 9 and 14 bits each); then a walk over the grid's scales 128 down to
// 1, each in row-major order, with one bit for every point not known yet whose two parents
// are (1: the level adds it); then a 5-bit Rice parameter k and, for each vertex the walk
// added, in the walk's order, its height code less the mean (rounded down) of its parents'
// codes, zigzagged and Rice-coded (a quotient of 24 or more: 24 ones and the value in 17
// bits). The block's vertices go out in that order: the raw ones, then the walk's.
//
// One workgroup decodes one level. Its invocations first mark the vertices of the tile's
// coarser blocks (already in the pool) in a bitmap of the grid (shared memory) and write their
// codes into a grid of its own (scratch, never cleared: only points marked are read). Invocation
// 0 reads the raw vertices. The walk goes a scale at a time: a point's parents are of coarser
// scales, so which of a scale's points are asked about is known before any of its bits is
// read. The invocations each take a run of the scale's points, count the questions in it,
// and after a prefix sum read their bits from their own offset; a second prefix sum over the
// answers gives each its place in the block. The residuals' codes are of varying length, so
// invocation 0 reads them in order, each vertex's parents decoded before it.
//
// A stream that is not a level of this tile (it ends early or runs past its level's end, a
// raw vertex is outside the grid or known, more vertices than the block holds or fewer, a
// Rice parameter over 16, a code out of range) is reported in `status` with a reason; the
// positions written are then not to be drawn.

#include "hierarchy.glsl"

layout(local_size_x = 64) in;
const uint LANES = 64u;

const uint SIDE = 257u;
const uint GRID = SIDE * SIDE;
const uint ESCAPE = 24u;
const uint HEIGHT_MAX_CODE = 16383u;

// Reasons a decode fails (DecodeFailure::reason on the host).
const uint ENDS_EARLY = 1u;
const uint RAW_VERTEX = 2u;
const uint TOO_MANY = 3u;
const uint RICE_PARAMETER = 4u;
const uint CODE_RANGE = 5u;
const uint COUNT = 6u;
const uint BITS_LEFT = 7u;

struct Decode {
    // The level's first bit in `stream`, and the bit after its last (its bytes' end).
    uint stream_bit;
    uint end_bit;
    // Pool word of block 0's first packed position, and the vertices of the coarser blocks.
    uint known_word;
    uint known_count;
    // Pool word of the level's block, and the vertices it holds (the file's count).
    uint out_word;
    uint expected;
    // Reported when the decode fails.
    uint tile;
    uint level;
};

layout(std430, set = 0, binding = 0) buffer Pool { uint positions[]; };
// The streams, each starting on a word.
layout(std430, set = 0, binding = 1) readonly buffer Streams { uint stream[]; };
layout(std430, set = 0, binding = 2) coherent buffer Scratch { uint codes[]; };
layout(std430, set = 0, binding = 3) readonly buffer Decodes { Decode decodes[]; };
// [0] failed decodes, [1] the first failing tile, [2] its level, [3] the reason.
layout(std430, set = 0, binding = 4) buffer Status { uint status[]; };

layout(push_constant) uniform Push { uint first_decode; } pc;

// Bit y * 257 + x: grid point (x, y) is a vertex of a coarser block or decoded so far.
shared uint known[(GRID + 31u) / 32u];
// Per invocation, for the scale being walked: [0] its questions, [1] its answers, each turned
// in place into its offset (the first bit it reads, the first vertex it places).
shared uint runs[2][LANES];
// The next bit to read, the vertices of the block placed so far, and the failure (0: none).
shared uint bit_at;
shared uint placed;
shared uint failure;

uint region;

bool is_known(uint i) {
    return (known[i / 32u] & (1u << (i % 32u))) != 0u;
}

// The stream's word `w`, or 0 past the buffer's end (a read looks ahead of what it takes).
uint word(uint w) {
    return w < uint(stream.length()) ? stream[w] : 0u;
}

// `width` (at most 32) bits from bit `at`, least significant first.
uint bits(uint at, uint width) {
    uint w = at >> 5u;
    uint o = at & 31u;
    uint v = word(w) >> o;
    if (o != 0u) {
        v |= word(w + 1u) << (32u - o);
    }
    return width == 32u ? v : v & ((1u << width) - 1u);
}

void fail(uint reason) {
    if (failure == 0u) {
        failure = reason;
    }
}

// Invocation 0: the raw vertices, from bit_at.
void read_raw(Decode d) {
    uint at = bit_at;
    if (at + 16u > d.end_bit) {
        fail(ENDS_EARLY);
        return;
    }
    uint raw = bits(at, 16u);
    at += 16u;
    if (raw > d.expected) {
        fail(TOO_MANY);
        return;
    }
    if (at + 32u * raw > d.end_bit) {
        fail(ENDS_EARLY);
        return;
    }
    for (uint r = 0u; r < raw; r++) {
        uint x = bits(at, 9u);
        uint y = bits(at + 9u, 9u);
        uint c = bits(at + 18u, 14u);
        at += 32u;
        uint i = y * SIDE + x;
        if (x >= SIDE || y >= SIDE || is_known(i)) {
            fail(RAW_VERTEX);
            return;
        }
        known[i / 32u] |= 1u << (i % 32u);
        codes[region + i] = c;
        positions[d.out_word + r] = x | (y << 9u) | (c << 18u);
    }
    bit_at = at;
    placed = raw;
}

// Whether the walk asks about lattice point `e` of scale 2^k (m points a side, row-major),
// with its grid index: a point of this scale not known yet whose parents are.
bool asked(uint e, uint k, uint m, out uint i) {
    uint ci = e % m;
    uint cj = e / m;
    uint x = ci << k;
    uint y = cj << k;
    i = y * SIDE + x;
    if (((ci | cj) & 1u) == 0u || is_known(i)) {
        return false;   // a coarser scale's point, or known
    }
    uvec2 p, q;
    parents_of(x, y, k, p, q);
    return is_known(p.y * SIDE + p.x) && is_known(q.y * SIDE + q.x);
}

// Invocation 0: turns runs[r] into offsets from `base`, in place; returns the end.
uint prefix(uint r, uint base) {
    uint end = base;
    for (uint l = 0u; l < LANES; l++) {
        uint n = runs[r][l];
        runs[r][l] = end;
        end += n;
    }
    return end;
}

// The walk over the points of scale 2^k: each invocation takes a run of the scale's lattice.
// No point of a scale is a parent of another, so the questions are known before any answer.
void walk_scale(Decode d, uint k, uint lane) {
    uint m = (256u >> k) + 1u;
    uint run = (m * m + LANES - 1u) / LANES;
    uint first = min(lane * run, m * m);
    uint last = min(first + run, m * m);
    uint i;
    uint questions = 0u;
    for (uint e = first; e < last; e++) {
        questions += asked(e, k, m, i) ? 1u : 0u;
    }
    runs[0][lane] = questions;
    barrier();
    if (lane == 0u) {
        bit_at = prefix(0u, bit_at);
        if (bit_at > d.end_bit) {
            fail(ENDS_EARLY);
        }
    }
    barrier();
    uint answers = 0u;
    if (failure == 0u) {
        uint at = runs[0][lane];
        for (uint e = first; e < last; e++) {
            if (asked(e, k, m, i)) {
                answers += bits(at, 1u);
                at++;
            }
        }
    }
    runs[1][lane] = answers;
    barrier();
    if (lane == 0u && failure == 0u) {
        placed = prefix(1u, placed);
        if (placed > d.expected) {
            fail(TOO_MANY);
        }
    }
    barrier();
    if (failure == 0u) {
        uint at = runs[0][lane];
        uint slot = runs[1][lane];
        for (uint e = first; e < last; e++) {
            if (asked(e, k, m, i)) {
                if (bits(at, 1u) == 1u) {
                    atomicOr(known[i / 32u], 1u << (i % 32u));
                    // The grid index for now; its packed position once its height is read.
                    positions[d.out_word + slot] = i;
                    slot++;
                }
                at++;
            }
        }
    }
    memoryBarrierBuffer();
    barrier();
}

// Invocation 0: the heights of the vertices the walk placed, in the block's order.
void read_heights(Decode d, uint raw) {
    uint at = bit_at;
    if (at + 5u > d.end_bit) {
        fail(ENDS_EARLY);
        return;
    }
    uint k = bits(at, 5u);
    at += 5u;
    if (k > 16u) {
        fail(RICE_PARAMETER);
        return;
    }
    for (uint v = raw; v < placed; v++) {
        uint i = positions[d.out_word + v];
        uint x = i % SIDE;
        uint y = i / SIDE;
        uvec2 p, q;
        parents_of(x, y, uint(findLSB(x | y)), p, q);
        // The unary quotient: the ones before the first zero, at most ESCAPE.
        uint ones = uint(findLSB(~bits(at, ESCAPE)));
        uint z;
        uint len;
        if (ones >= ESCAPE) {
            len = ESCAPE + 17u;
            z = bits(at + ESCAPE, 17u);
        } else {
            len = ones + 1u + k;
            z = (ones << k) | bits(at + ones + 1u, k);
        }
        if (at + len > d.end_bit) {
            fail(ENDS_EARLY);
            return;
        }
        at += len;
        int r = int(z >> 1u) ^ -int(z & 1u);
        int c = int((codes[region + p.y * SIDE + p.x] + codes[region + q.y * SIDE + q.x]) >> 1u) + r;
        if (c < 0 || c > int(HEIGHT_MAX_CODE)) {
            fail(CODE_RANGE);
            return;
        }
        codes[region + i] = uint(c);
        positions[d.out_word + v] = x | (y << 9u) | (uint(c) << 18u);
    }
    if (placed != d.expected) {
        fail(COUNT);
    } else if (((at + 7u) & ~7u) != d.end_bit) {
        fail(BITS_LEFT);
    }
}

void main() {
    Decode d = decodes[pc.first_decode + gl_WorkGroupID.x];
    uint lane = gl_LocalInvocationID.x;
    region = gl_WorkGroupID.x * GRID;
    for (uint w = lane; w < known.length(); w += LANES) {
        known[w] = 0u;
    }
    if (lane == 0u) {
        bit_at = d.stream_bit;
        placed = 0u;
        failure = 0u;
    }
    barrier();
    for (uint v = lane; v < d.known_count; v += LANES) {
        uint packed = positions[d.known_word + v];
        uint i = ((packed >> 9u) & 511u) * SIDE + (packed & 511u);
        atomicOr(known[i / 32u], 1u << (i % 32u));
        codes[region + i] = packed >> 18u;
    }
    memoryBarrierBuffer();
    barrier();
    if (lane == 0u) {
        read_raw(d);
    }
    memoryBarrierBuffer();
    barrier();
    uint raw = placed;
    for (int k = 7; k >= 0; --k) {
        walk_scale(d, uint(k), lane);
    }
    if (lane == 0u) {
        if (failure == 0u) {
            read_heights(d, raw);
        }
        if (failure != 0u && atomicAdd(status[0], 1u) == 0u) {
            status[1] = d.tile;
            status[2] = d.level;
            status[3] = failure;
        }
    }
}
