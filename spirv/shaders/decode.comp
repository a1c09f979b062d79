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
// read. The invocations each take a run of the scale's rows, count the questions in it, and
// after a prefix sum count the ones among their bits; a second prefix sum over those gives
// each its place in the block, and each reads its answers. The residuals' codes are of varying length, so
// invocation 0 reads them in order, each vertex's parents decoded before it.
//
// A stream that is not a level of this tile (it ends early or runs past its level's end, a
// raw vertex is outside the grid or known, more vertices than the block holds or fewer, a
// Rice parameter over 16, a code out of range), or coarser blocks that hold a point outside
// the grid, are reported in `status` with a reason; the positions written are then not to be
// drawn.

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
const uint COARSER_BLOCKS = 8u;

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

// `width` (at most 32) bits of the known bitmap from bit `at`.
uint bits_at_known(uint at, uint width) {
    uint w = at >> 5u;
    uint o = at & 31u;
    uint v = known[w] >> o;
    if (o != 0u && w + 1u < known.length()) {
        v |= known[w + 1u] << (32u - o);
    }
    return width == 32u ? v : v & ((1u << width) - 1u);
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

// Whether the walk asks about grid point (x, y) of scale 2^k, with its grid index: a point not
// known yet whose parents are.
bool asked(uint x, uint y, uint k, out uint i) {
    i = y * SIDE + x;
    if (is_known(i)) {
        return false;
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

// The ones among `count` bits from bit `at`.
uint ones_in(uint at, uint count) {
    uint n = 0u;
    for (uint done = 0u; done < count; done += 32u) {
        n += uint(bitCount(bits(at + done, min(32u, count - done))));
    }
    return n;
}

// The walk over the points of scale 2^k, row-major: each invocation takes a run of the
// scale's lattice rows (m a side), in a row of even index its odd columns (the even ones are
// coarser points), in an odd row every column. No point of a scale is a parent of another,
// so the questions are known before any answer; the answers are counted from the stream.
void walk_scale(Decode d, uint k, uint lane) {
    uint m = (256u >> k) + 1u;
    uint rows = (m + LANES - 1u) / LANES;
    uint first = min(lane * rows, m);
    uint last = min(first + rows, m);
    uint i;
    uint questions = 0u;
    for (uint cj = first; cj < last; cj++) {
        uint step = 2u - (cj & 1u);
        for (uint ci = step - 1u; ci < m; ci += step) {
            questions += asked(ci << k, cj << k, k, i) ? 1u : 0u;
        }
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
    runs[1][lane] = failure == 0u ? ones_in(runs[0][lane], questions) : 0u;
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
        for (uint cj = first; cj < last; cj++) {
            uint step = 2u - (cj & 1u);
            for (uint ci = step - 1u; ci < m; ci += step) {
                if (asked(ci << k, cj << k, k, i)) {
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
    }
    memoryBarrierBuffer();
    barrier();
}

// Bits of grid row y for columns x0 - 1 + shift .. + 32 (shift 0, 1 or 2: the columns left of,
// at and right of x0), least significant first; 0 outside the grid.
uint row_bits(int y, int x) {
    if (y < 0 || y >= int(SIDE)) {
        return 0u;
    }
    uint v;
    if (x < 0) {
        // Only x = -1: column -1 is outside, columns 0..30 are the window's bits 1..31.
        v = bits_at_known(uint(y) * SIDE, 31u) << 1u;
    } else {
        v = bits_at_known(uint(y) * SIDE + uint(x), 32u);
    }
    // Columns past the row's end are the next row's.
    int past = x + 32 - int(SIDE);
    if (past > 0) {
        v &= past >= 32 ? 0u : (0xffffffffu >> uint(past));
    }
    return v;
}

// The candidates of scale 1 in grid row y, columns x0 .. x0 + 31: points not known whose two
// parents are (tools/tiles/src/compact.rs, `parents`, at scale 1: an edge's midpoint has the
// edge's ends; a cell's centre (x, y) the diagonal through (x - 1, y - 1) and (x + 1, y + 1)
// when x and y are alike modulo 4, the other one otherwise).
uint finest_candidates(uint y, uint x0) {
    int yi = int(y);
    int xi = int(x0);
    uint own = ~row_bits(yi, xi);
    uint c;
    if ((y & 1u) == 0u) {
        // Odd columns: the midpoints of horizontal edges.
        c = row_bits(yi, xi - 1) & row_bits(yi, xi + 1) & 0xaaaaaaaau;
    } else {
        uint vertical = row_bits(yi - 1, xi) & row_bits(yi + 1, xi) & 0x55555555u;
        uint main_diagonal = row_bits(yi - 1, xi - 1) & row_bits(yi + 1, xi + 1);
        uint other_diagonal = row_bits(yi - 1, xi + 1) & row_bits(yi + 1, xi - 1);
        // Columns 1 mod 4 (bits 1, 5, ...) and 3 mod 4.
        uint main_columns = (y & 3u) == 1u ? 0x22222222u : 0x88888888u;
        uint other_columns = (y & 3u) == 1u ? 0x88888888u : 0x22222222u;
        c = vertical | (main_diagonal & main_columns) | (other_diagonal & other_columns);
    }
    c &= own;
    int past = xi + 32 - int(SIDE);
    if (past > 0) {
        c &= past >= 32 ? 0u : (0xffffffffu >> uint(past));
    }
    return c;
}

// The walk over scale 1, 32 columns at a time (the finest scale holds three quarters of the
// grid's points): as walk_scale, each invocation a run of rows.
void walk_finest(Decode d, uint lane) {
    uint rows = (SIDE + LANES - 1u) / LANES;
    uint first = min(lane * rows, SIDE);
    uint last = min(first + rows, SIDE);
    uint questions = 0u;
    for (uint y = first; y < last; y++) {
        for (uint x0 = 0u; x0 < SIDE; x0 += 32u) {
            questions += uint(bitCount(finest_candidates(y, x0)));
        }
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
    runs[1][lane] = failure == 0u ? ones_in(runs[0][lane], questions) : 0u;
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
        for (uint y = first; y < last; y++) {
            for (uint x0 = 0u; x0 < SIDE; x0 += 32u) {
                uint c = finest_candidates(y, x0);
                while (c != 0u) {
                    uint b = uint(findLSB(c));
                    c &= c - 1u;
                    if (bits(at, 1u) == 1u) {
                        uint i = y * SIDE + x0 + b;
                        atomicOr(known[i / 32u], 1u << (i % 32u));
                        positions[d.out_word + slot] = i;
                        slot++;
                    }
                    at++;
                }
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
        uint x = packed & 511u;
        uint y = (packed >> 9u) & 511u;
        if (x >= SIDE || y >= SIDE) {
            // Not a position: the pool does not hold the tile's coarser blocks there.
            failure = COARSER_BLOCKS;
            continue;
        }
        uint i = y * SIDE + x;
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
    for (int k = 7; k >= 1; --k) {
        walk_scale(d, uint(k), lane);
    }
    walk_finest(d, lane);
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
