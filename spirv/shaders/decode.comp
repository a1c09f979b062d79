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
// read, and 32 columns are asked about at once (the bitmap's rows shifted by the scale give
// each point's parents). The invocations each take a run of the scale's rows, count the
// questions in it, and after a prefix sum count the ones among their bits; a second prefix
// sum over those gives each its place in the block, and each reads its answers. The
// residuals' codes are of varying length, so invocation 0 reads them in order, each vertex's
// parents decoded before it (the stream through two words kept in registers).
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

// Bits of grid row y for columns x .. x + 31 (x >= -32), least significant first; 0 outside
// the grid.
uint row_bits(int y, int x) {
    if (y < 0 || y >= int(SIDE) || x <= -32) {
        return 0u;
    }
    uint v;
    if (x < 0) {
        // Columns x .. -1 are outside: the row's first 32 + x columns, moved up.
        v = bits_at_known(uint(y) * SIDE, uint(32 + x)) << uint(-x);
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

// The bits b of the word of columns x0 .. x0 + 31 (x0 a multiple of 32) whose column is
// `offset` modulo `period` (a power of two).
uint columns(uint period, uint offset, uint x0) {
    if (period > 32u) {
        uint first = (offset + period - x0 % period) % period;
        return first < 32u ? 1u << first : 0u;
    }
    uint m = 1u << offset;
    for (uint p = period; p < 32u; p *= 2u) {
        m |= m << p;
    }
    return m;
}

// The walk's questions of scale s = 2^k in grid row y (a multiple of s), columns x0 .. x0 + 31
// (x0 a multiple of 32): the points of that scale not known whose two
// parents are (tools/tiles/src/compact.rs, `parents`): an edge's midpoint has the edge's ends;
// a cell's centre (x, y) the diagonal through (x - s, y - s) and (x + s, y + s) where x and y
// are alike modulo 4 s (both s or both 3 s), the other diagonal otherwise (at s = 128 the one
// cell centre, (128, 128), is alike).
uint questions_in(uint y, uint x0, uint k) {
    int s = 1 << k;
    int yi = int(y);
    int xi = int(x0);
    uint odd_columns = columns(2u << k, 1u << k, x0);
    uint c;
    if (((y >> k) & 1u) == 0u) {
        // A row of even multiples of s: its odd multiples are horizontal edges' midpoints.
        c = row_bits(yi, xi - s) & row_bits(yi, xi + s) & odd_columns;
    } else {
        uint even_columns = columns(2u << k, 0u, x0);
        uint vertical = row_bits(yi - s, xi) & row_bits(yi + s, xi) & even_columns;
        uint main_diagonal = row_bits(yi - s, xi - s) & row_bits(yi + s, xi + s);
        uint other_diagonal = row_bits(yi - s, xi + s) & row_bits(yi + s, xi - s);
        // Columns s and 3 s modulo 4 s.
        uint first = columns(4u << k, 1u << k, x0);
        uint third = columns(4u << k, 3u << k, x0);
        bool first_row = (y & ((4u << k) - 1u)) == (1u << k);
        c = vertical | (main_diagonal & (first_row ? first : third))
            | (other_diagonal & (first_row ? third : first));
    }
    c &= ~row_bits(yi, xi);
    int past = xi + 32 - int(SIDE);
    if (past > 0) {
        c &= past >= 32 ? 0u : (0xffffffffu >> uint(past));
    }
    return c;
}

// The walk over scale 2^k, 32 columns at a time, row-major: each invocation takes a run of
// the scale's rows (m a side). No point of a scale is a parent of another, so the questions
// are known before any answer: each invocation counts its own, a prefix sum gives it its
// first bit, the ones among its bits (counted from the stream) and a second prefix sum its
// first place in the block, then it reads its answers.
void walk_words(Decode d, uint k, uint lane) {
    uint m = (256u >> k) + 1u;
    uint rows = (m + LANES - 1u) / LANES;
    uint first = min(lane * rows, m);
    uint last = min(first + rows, m);
    uint questions = 0u;
    for (uint cj = first; cj < last; cj++) {
        for (uint x0 = 0u; x0 < SIDE; x0 += 32u) {
            questions += uint(bitCount(questions_in(cj << k, x0, k)));
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
            uint y = cj << k;
            for (uint x0 = 0u; x0 < SIDE; x0 += 32u) {
                uint c = questions_in(y, x0, k);
                while (c != 0u) {
                    uint b = uint(findLSB(c));
                    c &= c - 1u;
                    if (bits(at, 1u) == 1u) {
                        uint i = y * SIDE + x0 + b;
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

// Invocation 0's reader of the residuals, which it reads in order: the stream's words
// `window_word` and the next, kept in registers (a storage read is slow on some devices).
uint window_word = 0xfffffffeu;  // none yet (one past it is no word either)
uint window_lo;
uint window_hi;

// `width` (at most 32) bits from bit `at`, through the window.
uint next_bits(uint at, uint width) {
    uint w = at >> 5u;
    if (w != window_word) {
        window_lo = w == window_word + 1u ? window_hi : word(w);
        window_hi = word(w + 1u);
        window_word = w;
    }
    uint o = at & 31u;
    uint v = window_lo >> o;
    if (o != 0u) {
        v |= window_hi << (32u - o);
    }
    return width == 32u ? v : v & ((1u << width) - 1u);
}

// Invocation 0: the heights of the vertices the walk placed, in the block's order.
void read_heights(Decode d, uint raw) {
    uint at = bit_at;
    if (at + 5u > d.end_bit) {
        fail(ENDS_EARLY);
        return;
    }
    uint k = next_bits(at, 5u);
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
        uint ones = uint(findLSB(~next_bits(at, ESCAPE)));
        uint z;
        uint len;
        if (ones >= ESCAPE) {
            len = ESCAPE + 17u;
            z = next_bits(at + ESCAPE, 17u);
        } else {
            len = ones + 1u + k;
            z = (ones << k) | next_bits(at + ones + 1u, k);
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
    for (int k = 7; k >= 0; --k) {
        walk_words(d, uint(k), lane);
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
