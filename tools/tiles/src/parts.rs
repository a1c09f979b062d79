//! A tile drawn part by part: each of its 4 x 4 parts (64 x 64 cells) at a level of its own, in
//! one conforming mesh. This is the CPU side of what the renderer's index builder
//! (`spirv/shaders/indices.comp`) makes on the GPU, so that the two can be compared and the
//! renderer knows an array's length before the GPU writes it.
//!
//! # The mesh
//!
//! A level's mesh is a function of its vertex set (the quadtree of fans, see the shader's
//! header): a cell is split exactly when the centre of one of its children is a vertex, a leaf
//! is drawn as one fan around its centre, and a leaf's edge midpoint is in the fan exactly when
//! it is a vertex. Levels are nested, and block `j` of a tile holds the vertices level `j` adds,
//! so "vertex of level `L`" is "vertex of a block `<= L`".
//!
//! The mixed mesh takes its vertex set point by point:
//! - a point inside part `q` is a vertex when its block is `<= L_q`;
//! - a point on a line between parts, when its block is `<=` the largest level of the parts
//!   that meet there;
//! - a point on the tile's outer border, when its block is `<= G`, the largest level of all.
//!   The border is then the one level `G` draws, so stitching to the neighbours is as for a
//!   tile drawn at `G`.
//!
//! Every cell split is decided by a child's centre, which lies inside one part (never on a
//! line), so inside each part the leaves are those of its own level `L_q`, provided every
//! leaf lies in one part: each part's centre must be a vertex of its level (then its ancestors
//! are split). [`Centres::key`] ensures it by raising a part to the level that adds its centre,
//! or by making the four parts of a quadrant one level where a centre never appears, or a
//! quadrant one leaf. A leaf's edges that lie on a line between parts or on the border may
//! hold more vertices than the midpoint (a finer neighbour's): the fan takes every vertex
//! along such an edge, in order. So no vertex lies inside an edge of a fan it is not in, and
//! the mesh has no T-junction and no crack whatever the heights of its vertices: the parts
//! need no stitching between them.
//!
//! With every part at one level the mixed mesh is that level's mesh, fan for fan.

use crate::mesh::TILE_SIZE;
use crate::pack::unpack;

/// Parts per tile side, and cells per part side.
pub const PARTS: usize = 4;
pub const PART_CELLS: u32 = 64;

/// Lattice points per tile.
const POINTS: usize = TILE_SIZE * TILE_SIZE;
/// Block of a point that no level holds.
const NEVER: u8 = u8::MAX;
/// Restart index in the arrays this module makes.
pub const RESTART: u32 = u32::MAX;

/// The level of each part, row by row from the tile's first row (part `(i, j)` covers cells
/// `64 i .. 64 (i + 1)` across and `64 j .. 64 (j + 1)` down, at index `4 j + i`).
pub type PartLevels = [u8; PARTS * PARTS];

/// The levels a tile's parts are drawn at, made such that every leaf lies in one part.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PartKey {
    pub levels: PartLevels,
}

/// Where each lattice point of a tile first appears: its block, and its vertex index.
pub struct Blocks {
    /// Per vertex in index order, its lattice point.
    points: Vec<(u32, u32)>,
    /// How many blocks there are.
    levels: usize,
    block: Vec<u8>,
    vertex: Vec<u32>,
    mesh_max: (u32, u32),
    centres: Centres,
}

/// What deciding a tile's [`PartKey`] needs of its vertices (20 bytes, where [`Blocks`] holds
/// 5 bytes a lattice point): the blocks that add the centres of its parts and quadrants.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Centres {
    /// Per part, the block that adds its centre ([`NEVER`]: none does).
    parts: PartLevels,
    /// Per quadrant (2 x 2 parts), the block that adds its centre.
    quadrants: [u8; 4],
    /// Per corner of the parts' grid (5 x 5, row by row), the block that adds it.
    corners: [u8; (PARTS + 1) * (PARTS + 1)],
    /// The last column and row the mesh covers (a partial tile's cells across its edge are
    /// split whatever their vertices, and cells past it are not drawn).
    mesh_max: (u32, u32),
}

impl Blocks {
    /// From the packed positions of blocks `0..`, block by block, and the last column and row
    /// the tile's meshes cover.
    pub fn new<'a>(blocks: impl IntoIterator<Item = &'a [u32]>, mesh_max: (u32, u32)) -> Blocks {
        let mut block = vec![NEVER; POINTS];
        let mut vertex = vec![u32::MAX; POINTS];
        let mut index = 0u32;
        let mut points = Vec::new();
        let mut blocks_read = 0;
        for (j, positions) in blocks.into_iter().enumerate() {
            blocks_read = j + 1;
            for &p in positions {
                let (x, y, _) = unpack(p);
                points.push((x, y));
                if (x as usize) < TILE_SIZE && (y as usize) < TILE_SIZE {
                    let i = y as usize * TILE_SIZE + x as usize;
                    block[i] = j.min(usize::from(NEVER - 1)) as u8;
                    vertex[i] = index;
                }
                index += 1;
            }
        }
        let centres = Centres::of(&block, mesh_max);
        Blocks {
            points,
            levels: blocks_read,
            block,
            vertex,
            mesh_max,
            centres,
        }
    }

    pub fn centres(&self) -> Centres {
        self.centres
    }

    /// [`Centres::key`].
    pub fn key(&self, wanted: &PartLevels, top: u32) -> Option<PartKey> {
        self.centres.key(wanted, top)
    }

    /// The length of [`Blocks::indices`]'s array.
    pub fn count(&self, key: &PartKey) -> Option<u32> {
        self.indices(key).map(|i| i.len() as u32)
    }

    /// Whether lattice point `(x, y)` is a vertex of the mixed mesh of `key`.
    fn is_vertex(&self, key: &PartKey, x: u32, y: u32) -> bool {
        let b = self.block[y as usize * TILE_SIZE + x as usize];
        b != NEVER && b <= presence_level(key, x, y)
    }

    /// The mixed mesh of `key` as an index array (fans in the order of the finest cells along
    /// the Hilbert curve, each ring from the leaf's north-west corner, [`RESTART`] between
    /// fans), into the vertices of blocks `0..` in order. None if a fan vertex is missing (the
    /// blocks do not make a mesh).
    pub fn indices(&self, key: &PartKey) -> Option<Vec<u32>> {
        let mut out = Vec::new();
        let mut ring = Vec::with_capacity(16);
        let mut h = 0u32;
        while h < CELLS {
            let c = hilbert_cell(h);
            let Some(d) = self.leaf_depth(key, c) else {
                h += 1;
                continue;
            };
            let run = 1u32 << (2 * (7 - d));
            if h & (run - 1) == 0 {
                let s = 256u32 >> d;
                let o = ((c.0 >> (7 - d)) * s, (c.1 >> (7 - d)) * s);
                self.fan(key, o, s, &mut ring);
                if !out.is_empty() {
                    out.push(RESTART);
                }
                for &(x, y) in &ring {
                    let v = self.vertex[y as usize * TILE_SIZE + x as usize];
                    if v == u32::MAX || !self.is_vertex(key, x, y) {
                        return None;
                    }
                    out.push(v);
                }
            }
            h = (h | (run - 1)) + 1;
        }
        Some(out)
    }

    /// Depth of the leaf covering finest cell `c`, or None where the mesh does not reach (the
    /// shader's `leaf_depth`).
    fn leaf_depth(&self, key: &PartKey, c: (u32, u32)) -> Option<u32> {
        let (mx, my) = self.mesh_max;
        for d in 0..7u32 {
            let s = 256u32 >> d;
            let o = ((c.0 >> (7 - d)) * s, (c.1 >> (7 - d)) * s);
            if o.0 >= mx || o.1 >= my {
                return None;
            }
            let straddles = (mx > o.0 && mx < o.0 + s) || (my > o.1 && my < o.1 + s);
            if !straddles {
                let child = (
                    (c.0 >> (6 - d)) * (s / 2) + s / 4,
                    (c.1 >> (6 - d)) * (s / 2) + s / 4,
                );
                if !self.is_vertex(key, child.0, child.1) {
                    return Some(d);
                }
            }
        }
        let o = (c.0 * 2, c.1 * 2);
        (o.0 < mx && o.1 < my).then_some(7)
    }

    /// The lattice points of leaf `(o, s)`'s fan: centre, then the perimeter counter-clockwise
    /// from the north-west corner, closed by repeating it. Along an edge on a line between
    /// parts or on the border, every vertex; along any other, the midpoint when it is one.
    fn fan(&self, key: &PartKey, o: (u32, u32), s: u32, ring: &mut Vec<(u32, u32)>) {
        ring.clear();
        ring.push((o.0 + s / 2, o.1 + s / 2));
        let corners = [
            (o.0, o.1),
            (o.0 + s, o.1),
            (o.0 + s, o.1 + s),
            (o.0, o.1 + s),
        ];
        ring.push(corners[0]);
        // Edges W (corner 0 -> 3), S (3 -> 2), E (2 -> 1), N (1 -> 0).
        for (from, to) in [(0, 3), (3, 2), (2, 1), (1, 0)] {
            let (a, b) = (corners[from], corners[to]);
            let on_line = if a.0 == b.0 {
                a.0.is_multiple_of(PART_CELLS)
            } else {
                a.1.is_multiple_of(PART_CELLS)
            };
            let step = |t: u32| (toward(a.0, b.0, t), toward(a.1, b.1, t));
            if on_line {
                for t in 1..s {
                    let p = step(t);
                    if self.is_vertex(key, p.0, p.1) {
                        ring.push(p);
                    }
                }
            } else {
                let m = step(s / 2);
                if self.is_vertex(key, m.0, m.1) {
                    ring.push(m);
                }
            }
            ring.push(b);
        }
    }
}

/// Per lattice point, the last of blocks `0..` (their packed positions) that holds it
/// ([`NEVER`]: none), and how many blocks there are: what [`Blocks`] holds, less each vertex's
/// index and point.
fn lattice_blocks<'a>(blocks: impl IntoIterator<Item = &'a [u32]>) -> (Vec<u8>, usize) {
    let mut block = vec![NEVER; POINTS];
    let mut count = 0;
    for (j, positions) in blocks.into_iter().enumerate() {
        count = j + 1;
        let j = j.min(usize::from(NEVER - 1)) as u8;
        for &p in positions {
            let (x, y, _) = unpack(p);
            if (x as usize) < TILE_SIZE && (y as usize) < TILE_SIZE {
                block[y as usize * TILE_SIZE + x as usize] = j;
            }
        }
    }
    (block, count)
}

impl Centres {
    /// From each lattice point's block ([`lattice_blocks`]).
    fn of(block: &[u8], mesh_max: (u32, u32)) -> Centres {
        let at = |x: u32, y: u32| block[y as usize * TILE_SIZE + x as usize];
        let half = PART_CELLS / 2;
        Centres {
            parts: std::array::from_fn(|q| {
                let (i, j) = ((q % PARTS) as u32, (q / PARTS) as u32);
                at(i * PART_CELLS + half, j * PART_CELLS + half)
            }),
            quadrants: std::array::from_fn(|k| {
                let (i, j) = ((k % 2) as u32, (k / 2) as u32);
                at(
                    2 * PART_CELLS * i + PART_CELLS,
                    2 * PART_CELLS * j + PART_CELLS,
                )
            }),
            corners: std::array::from_fn(|c| {
                let (i, j) = ((c % (PARTS + 1)) as u32, (c / (PARTS + 1)) as u32);
                at(i * PART_CELLS, j * PART_CELLS)
            }),
            mesh_max,
        }
    }

    /// The key that draws part `q` at `wanted[q]` or finer, with every part at most `top` (the
    /// level whose blocks are resident). None: the parts cannot be drawn apart at `top` (the
    /// tile is drawn at `top` as one level).
    pub fn key(&self, wanted: &PartLevels, top: u32) -> Option<PartKey> {
        let top = u8::try_from(top).ok()?;
        let mut levels = wanted.map(|l| l.min(top));
        // A part whose centre is a vertex of some level: at least that level.
        for (l, &c) in levels.iter_mut().zip(&self.parts) {
            if c != NEVER {
                *l = (*l).max(c);
            }
        }
        // Quadrant by quadrant: parts whose centre its level lacks make the quadrant one level.
        for k in 0..4 {
            let parts = quadrant_parts(k);
            if parts.iter().all(|&q| self.parts[q] <= levels[q]) {
                continue;
            }
            let m = parts.iter().map(|&q| levels[q]).max().unwrap_or(0);
            for q in parts {
                levels[q] = m;
            }
        }
        if levels.iter().any(|&l| l > top) {
            return None;
        }
        // A quadrant none of whose parts' centres is a vertex of its level is one leaf (all its
        // parts at one level, above): its own centre must then be a vertex of that level.
        for k in 0..4 {
            if !self.is_leaf(&levels, k) {
                continue;
            }
            let parts = quadrant_parts(k);
            let m = levels[parts[0]].max(self.quadrants[k]);
            if m > top {
                return None;
            }
            for q in parts {
                levels[q] = m;
            }
        }
        // The root must be split: some quadrant's centre is a vertex (it lies where the
        // quadrant's four parts meet, so its level is theirs).
        let (mx, my) = self.mesh_max;
        let straddles = mx < 256 || my < 256;
        let root_split = straddles
            || (0..4).any(|k| {
                let c = self.quadrants[k];
                c != NEVER
                    && c <= quadrant_parts(k)
                        .iter()
                        .map(|&q| levels[q])
                        .max()
                        .unwrap_or(0)
            });
        root_split.then_some(PartKey { levels })
    }
}

impl Centres {
    /// Whether quadrant `k` is one leaf at `levels`: it lies inside the mesh (one across the
    /// mesh's edge is split, one past it not drawn) and none of its parts' centres is a vertex.
    fn is_leaf(&self, levels: &PartLevels, k: usize) -> bool {
        let side = 2 * PART_CELLS;
        let (i, j) = ((k % 2) as u32, (k / 2) as u32);
        (i + 1) * side <= self.mesh_max.0
            && (j + 1) * side <= self.mesh_max.1
            && quadrant_parts(k).iter().all(|&q| self.parts[q] > levels[q])
    }
}

/// Lines between parts and along the border, cut at the parts' corners: 5 vertical lines
/// (x = 0, 64, .., 256) by 4 part rows, then 5 horizontal lines by 4 part columns.
const SEGMENTS: usize = 2 * (PARTS + 1) * PARTS;

/// A tile's array lengths for every key, from tables (about 2.5 KB a tile): what
/// [`Blocks::indices`] makes, counted without making it.
///
/// Inside part `q` the mixed mesh has the leaves of level `L_q`, so its fans are level
/// `L_q`'s fans centred in the part, as stored, except along the lines: a leaf edge on a line
/// holds every vertex of the line's level `P` strictly inside it, where level `L_q` held at
/// most its midpoint. The edges of part `q`'s leaves along a segment cover it, so the segment
/// adds `V(P) - V(L_q)` to that side, `V(X)` the vertices of level `X` strictly inside the
/// segment.
#[derive(Clone)]
pub struct Counts {
    /// Per level and part: indices of the level's fans centred in the part, and the fans (of
    /// the levels counted).
    indices: Vec<[u32; PARTS * PARTS]>,
    fans: Vec<[u32; PARTS * PARTS]>,
    /// Per level and segment: the level's vertices strictly inside the segment (of every
    /// level the blocks have: they come from the blocks, which are read whole).
    inside: Vec<[u32; SEGMENTS]>,
    /// Parts the mesh reaches.
    reached: [bool; PARTS * PARTS],
    centres: Centres,
}

/// The segment lattice point `(x, y)` lies inside, if any (not at a part's corner).
fn segment(x: u32, y: u32) -> Option<usize> {
    let (on_x, on_y) = (x.is_multiple_of(PART_CELLS), y.is_multiple_of(PART_CELLS));
    let (a, b) = ((x / PART_CELLS) as usize, (y / PART_CELLS) as usize);
    match (on_x, on_y) {
        (true, false) if b < PARTS => Some(a * PARTS + b),
        (false, true) if a < PARTS => Some((PARTS + 1) * PARTS + b * PARTS + a),
        _ => None,
    }
}

impl Counts {
    /// From the tile's blocks and each level's stored index array (vertex indices, `None`
    /// between fans).
    pub fn new<L, I>(blocks: &Blocks, levels: L) -> Counts
    where
        L: IntoIterator<Item = I>,
        I: IntoIterator<Item = Option<u32>>,
    {
        let mut counts = Counts::empty(&blocks.block, blocks.levels, blocks.centres);
        let at = |v: u32| blocks.points.get(v as usize).copied();
        for level in levels {
            counts.push_level(&at, level);
        }
        counts
    }

    /// No level counted yet: each level's vertices on the segments, from each lattice point's
    /// block (of `n` blocks, [`lattice_blocks`]).
    fn empty(block: &[u8], n: usize, centres: Centres) -> Counts {
        let mut inside = vec![[0u32; SEGMENTS]; n];
        // The points on the lines between parts (the others lie on no segment).
        let line = (0..=PARTS as u32).map(|k| k * PART_CELLS);
        let along = 0..TILE_SIZE as u32;
        let on_lines = line
            .clone()
            .flat_map(|x| along.clone().map(move |y| (x, y)))
            .chain(line.flat_map(|y| along.clone().map(move |x| (x, y))));
        for (x, y) in on_lines {
            let b = usize::from(block[y as usize * TILE_SIZE + x as usize]);
            if let (Some(seg), true) = (segment(x, y), b < n) {
                for level in &mut inside[b..] {
                    level[seg] += 1;
                }
            }
        }
        let (mx, my) = centres.mesh_max;
        let reached = std::array::from_fn(|q| {
            ((q % PARTS) as u32 * PART_CELLS) < mx && ((q / PARTS) as u32 * PART_CELLS) < my
        });
        Counts {
            indices: Vec::new(),
            fans: Vec::new(),
            inside,
            reached,
            centres,
        }
    }

    /// Counts the next level's fans: `level` its stored index array, `at` a vertex's lattice
    /// point.
    fn push_level(
        &mut self,
        at: &dyn Fn(u32) -> Option<(u32, u32)>,
        level: impl IntoIterator<Item = Option<u32>>,
    ) {
        let (mut lengths, mut counts) = ([0u32; PARTS * PARTS], [0u32; PARTS * PARTS]);
        let mut fan = |centre: Option<u32>, length: u32| {
            let Some((x, y)) = centre.and_then(at) else {
                return;
            };
            if !x.is_multiple_of(PART_CELLS) && !y.is_multiple_of(PART_CELLS) {
                let q = (y / PART_CELLS) as usize * PARTS + (x / PART_CELLS) as usize;
                lengths[q] += length;
                counts[q] += 1;
            }
        };
        let (mut centre, mut length) = (None, 0u32);
        for i in level {
            match i {
                Some(v) => {
                    if length == 0 {
                        centre = Some(v);
                    }
                    length += 1;
                }
                None => {
                    fan(centre, length);
                    length = 0;
                }
            }
        }
        if length > 0 {
            fan(centre, length);
        }
        self.indices.push(lengths);
        self.fans.push(counts);
    }

    /// How many levels are counted.
    pub fn levels(&self) -> u32 {
        self.indices.len() as u32
    }

    /// The length of `key`'s array and its triangles, for a key [`Centres::key`] made (every
    /// leaf in one part). None for a level the tile does not have.
    pub fn count(&self, key: &PartKey) -> Option<(u32, u32)> {
        let level = |q: usize| usize::from(key.levels[q]);
        let top = key.levels.iter().copied().max().map(usize::from)?;
        let leaf: [bool; 4] = std::array::from_fn(|k| self.centres.is_leaf(&key.levels, k));
        let in_leaf = |q: usize| leaf[(q / PARTS / 2) * 2 + (q % PARTS) / 2];
        let (mut length, mut fans) = (0u32, 0u32);
        for q in 0..PARTS * PARTS {
            length += self.indices.get(level(q))?[q];
            fans += self.fans[level(q)][q];
        }
        let part = |i: usize, j: usize| j * PARTS + i;
        // The parts on either side of a segment (None past the border).
        let sides = |seg: usize| {
            if seg < (PARTS + 1) * PARTS {
                let (line, row) = (seg / PARTS, seg % PARTS);
                (
                    (line > 0).then(|| part(line - 1, row)),
                    (line < PARTS).then(|| part(line, row)),
                )
            } else {
                let s = seg - (PARTS + 1) * PARTS;
                let (line, column) = (s / PARTS, s % PARTS);
                (
                    (line > 0).then(|| part(column, line - 1)),
                    (line < PARTS).then(|| part(column, line)),
                )
            }
        };
        let presence = |seg: usize| match sides(seg) {
            (Some(a), Some(b)) => level(a).max(level(b)),
            _ => top,
        };
        for seg in 0..SEGMENTS {
            let (a, b) = sides(seg);
            let p = presence(seg);
            for q in [a, b].into_iter().flatten() {
                // A leaf quadrant's fan takes its edges whole (below).
                if self.reached[q] && !in_leaf(q) {
                    length += self.inside[p][seg] - self.inside[level(q)][seg];
                }
            }
        }
        // A leaf quadrant: its centre, its four corners, the ring's closing repeat, and along
        // each edge (two segments, on lines) every vertex of their levels, with the edge's
        // midpoint, a corner of the parts' grid, where it is one.
        for k in (0..4).filter(|&k| leaf[k]) {
            let (a, b) = (2 * (k % 2), 2 * (k / 2));
            let vertical = |line: usize, row: usize| line * PARTS + row;
            let horizontal =
                |line: usize, column: usize| (PARTS + 1) * PARTS + line * PARTS + column;
            let edges = [
                ([vertical(a, b), vertical(a, b + 1)], (a, b + 1)),
                ([vertical(a + 2, b), vertical(a + 2, b + 1)], (a + 2, b + 1)),
                ([horizontal(b, a), horizontal(b, a + 1)], (a + 1, b)),
                (
                    [horizontal(b + 2, a), horizontal(b + 2, a + 1)],
                    (a + 1, b + 2),
                ),
            ];
            length += 6;
            fans += 1;
            for (segments, (i, j)) in edges {
                for seg in segments {
                    length += self.inside[presence(seg)][seg];
                }
                let at = if i == 0 || j == 0 || i == PARTS || j == PARTS {
                    top
                } else {
                    level(part(i - 1, j - 1))
                        .max(level(part(i, j - 1)))
                        .max(level(part(i - 1, j)))
                        .max(level(part(i, j)))
                };
                let c = self.centres.corners[j * (PARTS + 1) + i];
                length += u32::from(c != NEVER && usize::from(c) <= at);
            }
        }
        let restarts = fans.saturating_sub(1);
        Some((length + restarts, length - 2 * fans))
    }
}

/// What drawing `tile` part by part needs of its data, from its positions and stored arrays
/// (its [`Centres`] and [`Counts`], about 2.5 KB).
pub fn tables(tile: &crate::format::Tile) -> (Centres, Counts) {
    tables_through(tile, tile.levels().len() as u32)
}

/// [`tables`] for the tile's first `levels` levels alone (their counts; the centres are the
/// blocks'), for a reader that has checked only those: their index arrays are the only ones
/// read.
pub fn tables_through(tile: &crate::format::Tile, levels: u32) -> (Centres, Counts) {
    let all = tile.levels().len() as u32;
    let (block, n) = lattice_blocks((0..all).filter_map(|j| tile.level(j).map(|l| l.positions)));
    let centres = Centres::of(&block, (tile.header.mesh_max_x, tile.header.mesh_max_y));
    let counts = counts_through(tile, &Counts::empty(&block, n, centres), levels);
    (centres, counts)
}

/// `counts` (a tile's part tables through some level) with the tile's levels up to `levels`
/// counted as well: what [`tables_through`] gives, reading the new levels' index arrays alone.
pub fn counts_through(tile: &crate::format::Tile, counts: &Counts, levels: u32) -> Counts {
    let all = tile.levels().len() as u32;
    let blocks: Vec<(u32, &[u32])> = (0..all)
        .filter_map(|j| tile.level(j))
        .map(|l| (l.entry.block_start, l.positions))
        .collect();
    let at = |v: u32| -> Option<(u32, u32)> {
        let j = blocks
            .partition_point(|&(start, _)| start <= v)
            .checked_sub(1)?;
        let (start, positions) = blocks[j];
        let (x, y, _) = unpack(*positions.get((v - start) as usize)?);
        Some((x, y))
    };
    let mut out = counts.clone();
    for j in counts.levels()..levels.min(all) {
        if let Some(l) = tile.level(j) {
            out.push_level(&at, l.indices.iter());
        }
    }
    out
}

/// `t` steps from `a` towards `b` (`a` itself when they are equal).
fn toward(a: u32, b: u32, t: u32) -> u32 {
    match b.cmp(&a) {
        std::cmp::Ordering::Greater => a + t,
        std::cmp::Ordering::Less => a - t,
        std::cmp::Ordering::Equal => a,
    }
}

/// The parts' levels as the shaders read them: 4 bits each, part `k` at bits `4 (k % 8)` of
/// word `k / 8` (`indices.comp`'s build, the terrain records' `parts_lo`, `parts_hi`).
pub fn packed_levels(levels: &PartLevels) -> [u32; 2] {
    let mut words = [0u32; 2];
    for (k, &l) in levels.iter().enumerate() {
        words[k / 8] |= u32::from(l & 15) << (4 * (k % 8));
    }
    words
}

/// The level a lattice point of the mixed mesh takes (module header): the finest of the parts
/// whose closed box holds it, the tile's (the finest part's) on its border.
pub fn presence_level(key: &PartKey, x: u32, y: u32) -> u8 {
    holding_parts(key, x, y).map_or(top_level(key), |levels| {
        levels.into_iter().max().unwrap_or(0)
    })
}

/// The coarsest of the parts whose closed box holds a lattice point, the tile's (the finest
/// part's) on its border: the most the morph pass lets a vertex there take from its parents
/// (`renderer::morph`, "Within a block"; `packed_coarsest_level` in `parts.glsl`).
pub fn coarsest_level(key: &PartKey, x: u32, y: u32) -> u8 {
    holding_parts(key, x, y).map_or(top_level(key), |levels| {
        levels.into_iter().min().unwrap_or(0)
    })
}

/// The tile's level: its finest part's.
fn top_level(key: &PartKey) -> u8 {
    key.levels.iter().copied().max().unwrap_or(0)
}

/// The levels of the four parts (some the same) whose closed boxes hold lattice point `(x,
/// y)` inside the tile; None on its border.
fn holding_parts(key: &PartKey, x: u32, y: u32) -> Option<[u8; 4]> {
    let edge = TILE_SIZE as u32 - 1;
    if x == 0 || y == 0 || x >= edge || y >= edge {
        return None;
    }
    let span = |v: u32| {
        let hi = (v / PART_CELLS) as usize;
        if v.is_multiple_of(PART_CELLS) {
            (hi - 1, hi)
        } else {
            (hi, hi)
        }
    };
    let ((i0, i1), (j0, j1)) = (span(x), span(y));
    let at = |i: usize, j: usize| key.levels[j * PARTS + i];
    Some([at(i0, j0), at(i1, j0), at(i0, j1), at(i1, j1)])
}

/// The parts of quadrant `k` (row by row: NW, NE, SW, SE of the tile's 2 x 2 quadrants).
fn quadrant_parts(k: usize) -> [usize; 4] {
    let (i, j) = (2 * (k % 2), 2 * (k / 2));
    [
        j * PARTS + i,
        j * PARTS + i + 1,
        (j + 1) * PARTS + i,
        (j + 1) * PARTS + i + 1,
    ]
}

/// Finest cells per tile (128 x 128).
const CELLS: u32 = 128 * 128;

/// Finest cell at position `d` of the Hilbert curve over 128 x 128 cells (the shader's
/// `hilbert_cell`).
fn hilbert_cell(d: u32) -> (u32, u32) {
    let (mut x, mut y) = (0u32, 0u32);
    let mut t = d;
    let mut s = 1u32;
    while s < 128 {
        let rx = 1 & (t / 2);
        let ry = 1 & (t ^ rx);
        if ry == 0 {
            if rx == 1 {
                x = s - 1 - x;
                y = s - 1 - y;
            }
            std::mem::swap(&mut x, &mut y);
        }
        x += s * rx;
        y += s * ry;
        t /= 4;
        s *= 2;
    }
    (x, y)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presence_is_the_finest_holding_part_coarsest_the_coarsest_and_the_border_both_the_top() {
        let mut levels = [2u8; 16];
        levels[5] = 6; // part (1, 1)
        let key = PartKey { levels };
        // (x, y, presence, coarsest, where): on a line or a corner the finest and the coarsest
        // holding part differ; inside a part and on the border they are the same.
        for (x, y, finest, coarsest, at) in [
            (100, 100, 6, 6, "inside part 5"),
            (64, 100, 6, 2, "line between parts 4 and 5"),
            (64, 64, 6, 2, "corner of parts 0, 1, 4, 5"),
            (10, 10, 2, 2, "inside part 0"),
            (200, 0, 6, 6, "the border takes the top level"),
            (192, 150, 2, 2, "line between parts 10 and 11"),
        ] {
            assert_eq!(presence_level(&key, x, y), finest, "{at}");
            assert_eq!(coarsest_level(&key, x, y), coarsest, "{at}");
        }
    }

    #[test]
    fn the_curve_visits_every_cell_once_quadrant_by_quadrant() {
        let mut seen = vec![false; CELLS as usize];
        for d in 0..CELLS {
            let (x, y) = hilbert_cell(d);
            assert!(!std::mem::replace(&mut seen[(y * 128 + x) as usize], true));
            // Each run of 1024 positions is one part (32 x 32 finest cells).
            let part = (x / 32, y / 32);
            let first = hilbert_cell(d & !1023);
            assert_eq!(part, (first.0 / 32, first.1 / 32));
        }
    }
}
