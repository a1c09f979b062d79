//! Issue 28's compact levels: a tile's levels kept as which vertices each level adds and their
//! heights, everything else rebuilt ([`crate::build::rebuild_tile`]).
//!
//! Per level, in one bit stream (least significant bit first), each level starting on a byte:
//!
//! - the level's vertices that have no parents known yet (the tile's corners, and where the
//!   data's edge cuts cells): a count (16 bits), then each as `x` (9 bits), `y` (9 bits) and
//!   its height code (14 bits);
//! - **where the others are**: a walk over the grid points of scale 128 down to 1, each scale
//!   in row-major order, with one bit for every point not known yet whose two parents
//!   (`parents` below: the morph's hierarchy) are: 1 if the level adds it. A decoder repeats
//!   the walk, so the bits say which points and nothing else;
//! - **their heights**: in the walk's order, each vertex's residual, its height code minus the
//!   mean (rounded down) of its parents' codes (which the walk has decoded before it),
//!   zigzagged to `z` and Rice-coded with the level's parameter `k` (5 bits, the `k` that
//!   makes the level shortest): `z >> k` in unary (that many 1s, then a 0), then the low `k`
//!   bits; a quotient of [`ESCAPE`] or more is sent as `ESCAPE` 1s and `z` in 17 bits.
//!   Residuals lie near 0 and fall off about exponentially, where a Rice code comes within a
//!   few percent of their entropy (`tilebench compact` measures it).
//!
//! The tile's header and level entries stay as they are (their measured errors and morph
//! units need the source). `tilebench compact` weighs this against today's blobs and against
//! entropy coding.

use crate::format::{LevelEntry, Tile, TileHeader};
use crate::mesh::TILE_SIZE;
use crate::quantise::HEIGHT_MAX_CODE;

/// The scale of tile-local grid point `(x, y)`: the largest power of two dividing both (512 at
/// the origin, which has no parents; the tile's other corners have 256 and none either).
pub fn scale_of(x: u32, y: u32) -> u32 {
    let m = x | y;
    if m == 0 {
        512
    } else {
        1 << m.trailing_zeros()
    }
}

/// The two parents of tile-local grid point `(x, y)`: an edge's midpoint has the edge's ends,
/// a cell's centre the diagonal through its parent cell's centre (the tile's centre, whose
/// cell has no parent, the north-west to south-east one); the tile's corners have none. The
/// renderer's morph pass places each vertex from these two (`renderer::morph`, "The morph";
/// `morph.comp` computes them the same way), and the compact levels predict its height from
/// them.
pub fn parents(x: u32, y: u32) -> Option<[(u32, u32); 2]> {
    let s = scale_of(x, y);
    if s >= 256 {
        return None;
    }
    let odd = |c: u32| (c / s) & 1 == 1;
    match (odd(x), odd(y)) {
        (true, true) => {
            let toward = |c: u32| s == 128 || ((c + s) / (2 * s)) & 1 == 1;
            let (dx, dy) = (toward(x), toward(y));
            let near = |c: u32, d: bool| if d { c + s } else { c - s };
            let far = |c: u32, d: bool| if d { c - s } else { c + s };
            Some([(near(x, dx), near(y, dy)), (far(x, dx), far(y, dy))])
        }
        (true, false) => Some([(x - s, y), (x + s, y)]),
        (false, true) => Some([(x, y - s), (x, y + s)]),
        (false, false) => None,
    }
}

/// Each level's new vertices, `(x, y, height code)`.
pub type LevelSets = Vec<Vec<(u32, u32, u16)>>;

/// A vertex the walk adds, with its two parents (flat grid indices).
type Walked = (usize, usize, usize);

fn at((x, y): (u32, u32)) -> usize {
    y as usize * TILE_SIZE + x as usize
}

/// Grid points of scale `s` in the walk's order.
fn points_of_scale(s: u32) -> impl Iterator<Item = (u32, u32)> {
    let side = TILE_SIZE as u32;
    (0..side)
        .step_by(s as usize)
        .flat_map(move |y| (0..side).step_by(s as usize).map(move |x| (x, y)))
        .filter(move |&(x, y)| scale_of(x, y) == s)
}

/// The walk's order (scales 128 down to 1, each row-major) as flat grid indices: each point
/// but the tile's corners with its two parents, `[point, parent, parent]`. Made once: the
/// walk runs once a level of every tile coded or decoded, and finding each point's scale and
/// parents again every time was most of a decode.
fn walk() -> &'static [[u32; 3]] {
    static WALK: std::sync::OnceLock<Vec<[u32; 3]>> = std::sync::OnceLock::new();
    WALK.get_or_init(|| {
        (0..8)
            .rev()
            .flat_map(|k| points_of_scale(1 << k))
            .filter_map(|p| {
                let [a, b] = parents(p.0, p.1)?;
                Some([at(p), at(a), at(b)].map(|i| i as u32))
            })
            .collect()
    })
}

/// Where each grid point is in the walk ([`NOT_WALKED`]: a corner), and the walk's entries
/// each point is a parent of (`children[child_start[p]..child_start[p + 1]]`, as indices in
/// the walk): what a decoder follows to ask about the points whose parents it has just met,
/// instead of going through the whole walk once a level.
struct WalkIndex {
    index_of: Vec<u32>,
    child_start: Vec<u32>,
    children: Vec<u32>,
}

const NOT_WALKED: u32 = u32::MAX;

fn walk_index() -> &'static WalkIndex {
    static INDEX: std::sync::OnceLock<WalkIndex> = std::sync::OnceLock::new();
    INDEX.get_or_init(|| {
        let table = walk();
        let mut index_of = vec![NOT_WALKED; TILE_SIZE * TILE_SIZE];
        let mut count = vec![0u32; TILE_SIZE * TILE_SIZE + 1];
        for (i, &[p, a, b]) in table.iter().enumerate() {
            index_of[p as usize] = i as u32;
            count[a as usize + 1] += 1;
            count[b as usize + 1] += 1;
        }
        for k in 1..count.len() {
            count[k] += count[k - 1];
        }
        let mut next = count.clone();
        let mut children = vec![0u32; 2 * table.len()];
        for (i, &[_, a, b]) in table.iter().enumerate() {
            for parent in [a, b] {
                children[next[parent as usize] as usize] = i as u32;
                next[parent as usize] += 1;
            }
        }
        WalkIndex {
            index_of,
            child_start: count,
            children,
        }
    })
}

/// A decoder's grid as it learns a tile's vertices: which points are known, and which walk
/// entries are asked about (their point not known, both parents known), as a bitmap over the
/// walk; an entry not added stays asked about at the next level.
struct Learnt {
    known: Vec<bool>,
    asked: Vec<u64>,
    table: &'static [[u32; 3]],
    index: &'static WalkIndex,
}

impl Learnt {
    fn new() -> Learnt {
        Learnt {
            known: vec![false; TILE_SIZE * TILE_SIZE],
            asked: vec![0; walk().len().div_ceil(64)],
            table: walk(),
            index: walk_index(),
        }
    }

    /// Point `p` is a vertex from now on: it is asked about no more, and each point it is a
    /// parent of whose other parent is known is asked about.
    fn learn(&mut self, p: usize) {
        let (table, index) = (self.table, self.index);
        self.known[p] = true;
        let i = index.index_of[p];
        if i != NOT_WALKED {
            self.asked[i as usize / 64] &= !(1 << (i % 64));
        }
        let children = index.child_start[p] as usize..index.child_start[p + 1] as usize;
        for &i in &index.children[children] {
            let [c, a, b] = table[i as usize].map(|v| v as usize);
            if !self.known[c] && self.known[a] && self.known[b] {
                self.asked[i as usize / 64] |= 1 << (i % 64);
            }
        }
    }

    /// One level's walk, over the entries asked about alone, in the walk's order: `adds` says
    /// whether the level adds each entry's point, which is then learnt (and asks about entries
    /// after it: its children are of finer scales). The points added, with their parents.
    fn walk<E>(
        &mut self,
        mut adds: impl FnMut(usize) -> Result<bool, E>,
    ) -> Result<Vec<Walked>, E> {
        let mut added = Vec::new();
        for word in 0..self.asked.len() {
            let mut asked = self.asked[word];
            while asked != 0 {
                let bit = asked.trailing_zeros();
                let [p, a, b] = self.table[word * 64 + bit as usize].map(|v| v as usize);
                if adds(p)? {
                    self.learn(p);
                    added.push((p, a, b));
                }
                asked = self.asked[word] & (!0u64).checked_shl(bit + 1).unwrap_or(0);
            }
        }
        Ok(added)
    }
}

/// The grid point at flat index `i`.
fn point(i: u32) -> (u32, u32) {
    (i % TILE_SIZE as u32, i / TILE_SIZE as u32)
}

/// The unary quotients from which a residual is sent whole (17 bits after `ESCAPE` 1s).
const ESCAPE: u32 = 24;

/// Bits of zigzagged residual `z` Rice-coded with parameter `k`.
fn rice_bits(z: u32, k: u32) -> u64 {
    let q = z >> k;
    if q >= ESCAPE {
        u64::from(ESCAPE + 17)
    } else {
        u64::from(q + 1 + k)
    }
}

/// The mean of two codes, rounded down: what a vertex's residual is taken against.
fn predicted(a: u16, b: u16) -> i32 {
    (i32::from(a) + i32::from(b)).div_euclid(2)
}

struct Bits {
    bytes: Vec<u8>,
    len: usize,
}

impl Bits {
    /// Appends the low `width` bits of `value` (at most 32), least significant first: at most
    /// five bytes are touched, the first of them shared with the bits before.
    fn push(&mut self, value: u32, width: u32) {
        if width == 0 {
            return;
        }
        let value = u64::from(value) & ((1u64 << width) - 1);
        let (first, skip) = (self.len / 8, self.len % 8);
        self.len += width as usize;
        self.bytes.resize(self.len.div_ceil(8), 0);
        let shifted = (value << skip).to_le_bytes();
        for (byte, &b) in self.bytes[first..].iter_mut().zip(&shifted) {
            *byte |= b;
        }
    }

    fn align(&mut self) {
        self.len = self.len.next_multiple_of(8);
    }
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    /// The next `width` bits (at most 32), least significant first.
    fn read(&mut self, width: u32) -> Result<u32, String> {
        let end = self.at + width as usize;
        if end > 8 * self.bytes.len() {
            return Err("the compact levels end early".into());
        }
        if width == 0 {
            return Ok(0);
        }
        // The 8 bytes from the one holding the first bit: at most 7 + 32 bits are needed.
        let first = self.at / 8;
        let mut window = [0u8; 8];
        let n = (self.bytes.len() - first).min(8);
        window[..n].copy_from_slice(&self.bytes[first..first + n]);
        let value = u64::from_le_bytes(window) >> (self.at % 8);
        self.at = end;
        Ok((value & ((1u64 << width) - 1)) as u32)
    }

    /// The next bit.
    fn bit(&mut self) -> Result<bool, String> {
        let byte = self
            .bytes
            .get(self.at / 8)
            .ok_or("the compact levels end early")?;
        let bit = (byte >> (self.at % 8)) & 1 == 1;
        self.at += 1;
        Ok(bit)
    }

    fn align(&mut self) {
        self.at = self.at.next_multiple_of(8);
    }
}

/// A tile's levels as the compact bit stream (module header).
pub fn encode(tile: &Tile) -> Vec<u8> {
    encode_levels(tile).0
}

/// [`encode`], with each level's bytes in the stream (levels start on bytes, in order).
pub fn encode_levels(tile: &Tile) -> (Vec<u8>, Vec<u32>) {
    let mut lengths = Vec::with_capacity(tile.header.levels as usize);
    let mut bits = Bits {
        bytes: Vec::new(),
        len: 0,
    };
    let mut code = vec![0u16; TILE_SIZE * TILE_SIZE];
    let mut block = vec![u32::MAX; TILE_SIZE * TILE_SIZE];
    let levels: Vec<_> = (0..tile.header.levels)
        .map_while(|j| tile.level(j))
        .collect();
    for (j, level) in levels.iter().enumerate() {
        for &p in level.positions {
            let (x, y, c) = crate::pack::unpack(p);
            code[at((x, y))] = c;
            block[at((x, y))] = j as u32;
        }
    }
    // The decoder's walk (`decode_levels`), over the entries asked about alone.
    let mut learnt = Learnt::new();
    for (j, level) in levels.iter().enumerate() {
        let j = j as u32;
        // Sent as they are: the vertices without both parents in this level (the walk meets
        // every other one, after its parents, which are coarser).
        let raw: Vec<(u32, u32)> = level
            .positions
            .iter()
            .map(|&p| {
                let (x, y, _) = crate::pack::unpack(p);
                (x, y)
            })
            .filter(|&(x, y)| {
                parents(x, y).is_none_or(|[a, b]| block[at(a)] > j || block[at(b)] > j)
            })
            .collect();
        bits.push(raw.len() as u32, 16);
        for &(x, y) in &raw {
            bits.push(x, 9);
            bits.push(y, 9);
            bits.push(u32::from(code[at((x, y))]), 14);
            learnt.learn(at((x, y)));
        }
        let added = learnt
            .walk(|p| {
                let adds = block[p] == j;
                bits.push(u32::from(adds), 1);
                Ok::<_, std::convert::Infallible>(adds)
            })
            .unwrap_or_else(|never| match never {});
        let residual = |&(p, a, b): &Walked| {
            let r = i32::from(code[p]) - predicted(code[a], code[b]);
            ((r << 1) ^ (r >> 31)) as u32
        };
        let zs: Vec<u32> = added.iter().map(residual).collect();
        let k = (0..17u32)
            .min_by_key(|&k| zs.iter().map(|&z| rice_bits(z, k)).sum::<u64>())
            .expect("a parameter");
        bits.push(k, 5);
        for &z in &zs {
            let q = z >> k;
            if q >= ESCAPE {
                bits.push((1 << ESCAPE) - 1, ESCAPE);
                bits.push(z, 17);
            } else {
                // q ones (at most 23, so within a u32), then a zero.
                bits.push((1 << q) - 1, q + 1);
                bits.push(z & ((1 << k) - 1), k);
            }
        }
        bits.align();
        lengths.push((bits.len / 8) as u32 - lengths.iter().sum::<u32>());
    }
    (bits.bytes, lengths)
}

/// Each level's new vertices `(x, y, code)` from the compact bit stream of a tile with
/// `levels` levels, or why the stream is not one: it ends early, a vertex is out of the grid
/// or sent twice, or a height comes out of the code range.
pub fn decode(bytes: &[u8], levels: u32) -> Result<LevelSets, String> {
    decode_levels(bytes, levels).map(|(sets, _)| sets)
}

/// [`decode`], with each level's bytes in the stream: what a decoder of one level (the GPU's,
/// `renderer::vulkan::decode`) is handed. Each set is in the order a level's vertices are
/// decoded: the raw ones as sent, then the walk's in the walk's order.
pub fn decode_levels(
    bytes: &[u8],
    levels: u32,
) -> Result<(LevelSets, Vec<std::ops::Range<usize>>), String> {
    let mut reader = Reader { bytes, at: 0 };
    let mut ranges = Vec::with_capacity(levels as usize);
    let mut code = vec![0u16; TILE_SIZE * TILE_SIZE];
    let mut learnt = Learnt::new();
    let mut sets = Vec::with_capacity(levels as usize);
    for j in 0..levels {
        let start = reader.at / 8;
        let mut set = Vec::new();
        let raw = reader.read(16)?;
        for _ in 0..raw {
            let (x, y) = (reader.read(9)?, reader.read(9)?);
            let c = reader.read(14)? as u16;
            if x >= TILE_SIZE as u32 || y >= TILE_SIZE as u32 || learnt.known[at((x, y))] {
                return Err(format!(
                    "level {j}: vertex ({x}, {y}) outside the tile or twice"
                ));
            }
            learnt.learn(at((x, y)));
            code[at((x, y))] = c;
            set.push((x, y, c));
        }
        let added = learnt.walk(|_| reader.bit())?;
        let k = reader.read(5)?;
        if k > 16 {
            return Err(format!("level {j}: Rice parameter {k}"));
        }
        for (p, a, b) in added {
            let mut q = 0;
            while q < ESCAPE && reader.bit()? {
                q += 1;
            }
            let z = if q == ESCAPE {
                reader.read(17)?
            } else {
                (q << k) | reader.read(k)?
            };
            let r = (z >> 1) as i32 ^ -((z & 1) as i32);
            let c = predicted(code[a], code[b]) + r;
            let (x, y) = point(p as u32);
            if !(0..=i32::from(HEIGHT_MAX_CODE)).contains(&c) {
                return Err(format!(
                    "level {j}: vertex {:?} has height code {c}, out of range",
                    (x, y)
                ));
            }
            code[p] = c as u16;
            set.push((x, y, c as u16));
        }
        reader.align();
        sets.push(set);
        ranges.push(start..reader.at / 8);
    }
    if reader.at / 8 != bytes.len() {
        return Err(format!(
            "{} bytes after the compact levels",
            bytes.len() - reader.at / 8
        ));
    }
    Ok((sets, ranges))
}

/// A tile's blob from its header, its level entries and its compact levels, its blocks numbered
/// as `numbering` says: [`decode`], then [`crate::build::rebuild_tile`].
pub fn rebuild(
    header: &TileHeader,
    entries: &[LevelEntry],
    bytes: &[u8],
    numbering: crate::build::Numbering,
) -> Result<Vec<u8>, String> {
    rebuild_levels(header, entries, bytes, header.levels, numbering).map(|(blob, _)| blob)
}

/// [`rebuild`] of the tile's first `count` levels, `bytes` holding their streams alone (all of
/// them with `count` the tile's level count), with each level's bytes in the stream. With
/// fewer levels the blob is the full blob's first bytes ([`crate::build::rebuild_tile`]).
pub fn rebuild_levels(
    header: &TileHeader,
    entries: &[LevelEntry],
    bytes: &[u8],
    count: u32,
    numbering: crate::build::Numbering,
) -> Result<(Vec<u8>, Vec<std::ops::Range<usize>>), String> {
    let (sets, ranges) = decode_levels(bytes, count)?;
    let blob = crate::build::rebuild_tile(header, entries, &sets, numbering);
    Ok((blob, ranges))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bits_read_back_as_written_and_refuse_to_run_past_the_end() {
        let mut bits = Bits {
            bytes: Vec::new(),
            len: 0,
        };
        let values = [(5u32, 3u32), (0, 0), (16383, 14), (1, 1), (300, 9)];
        for &(v, w) in &values {
            bits.push(v, w);
        }
        bits.align();
        let mut reader = Reader {
            bytes: &bits.bytes,
            at: 0,
        };
        for &(v, w) in &values {
            assert_eq!(reader.read(w), Ok(v));
        }
        reader.align();
        assert!(reader.read(1).is_err());
    }

    /// The word-wise writer lays down what one bit at a time does, masking the bits of a value
    /// above its width (the escape and unary codes rely on it).
    #[test]
    fn pushes_lay_down_the_bits_one_at_a_time_would() {
        let (mut bits, mut reference) = (
            Bits {
                bytes: Vec::new(),
                len: 0,
            },
            (Vec::<u8>::new(), 0usize),
        );
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..5000 {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            let (value, width) = ((state >> 11) as u32, ((state >> 45) % 33) as u32);
            bits.push(value, width);
            for i in 0..width {
                if reference.1 % 8 == 0 {
                    reference.0.push(0);
                }
                if (value >> i) & 1 == 1 {
                    reference.0[reference.1 / 8] |= 1 << (reference.1 % 8);
                }
                reference.1 += 1;
            }
            assert_eq!((&bits.bytes, bits.len), (&reference.0, reference.1));
        }
    }

    /// Every point but the tile's corners has parents of a coarser scale, and the walk visits
    /// every scale's points once.
    #[test]
    fn parents_are_coarser_and_the_walk_covers_the_grid() {
        let mut visited = 0;
        for s in (0..8).rev().map(|k| 1u32 << k) {
            for (x, y) in points_of_scale(s) {
                visited += 1;
                let [a, b] = parents(x, y).expect("parents");
                assert!(
                    scale_of(a.0, a.1) > s && scale_of(b.0, b.1) > s,
                    "({x}, {y})"
                );
            }
        }
        assert_eq!(visited, TILE_SIZE * TILE_SIZE - 4);
        // The table the coder and decoder walk is that walk.
        let walked: Vec<[(u32, u32); 3]> = (0..8)
            .rev()
            .flat_map(|k| points_of_scale(1 << k))
            .map(|(x, y)| {
                let [a, b] = parents(x, y).expect("parents");
                [(x, y), a, b]
            })
            .collect();
        let table: Vec<[(u32, u32); 3]> = walk().iter().map(|w| w.map(point)).collect();
        assert_eq!(table, walked);
    }

    /// The reader's window reads what a bit at a time reads, at every offset and width, and
    /// refuses a read one bit past the end.
    #[test]
    fn windowed_reads_are_bit_by_bit_reads() {
        let bytes: Vec<u8> = (0..23u32).map(|i| (i * 151 + 7) as u8).collect();
        let bit = |i: usize| u32::from((bytes[i / 8] >> (i % 8)) & 1);
        for at in 0..8 * bytes.len() {
            for width in 0..=32u32 {
                let mut reader = Reader { bytes: &bytes, at };
                let end = at + width as usize;
                if end > 8 * bytes.len() {
                    assert!(reader.read(width).is_err(), "{at} + {width}");
                    continue;
                }
                let want = (0..width as usize).fold(0u32, |v, i| v | bit(at + i) << i);
                assert_eq!(reader.read(width), Ok(want), "{at} + {width}");
                assert_eq!(reader.at, end);
            }
        }
    }
}
