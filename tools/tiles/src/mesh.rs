//! The nested restricted-quadtree mesher for one 257 x 257 tile (paper, section 4).
//!
//! A mesh is a quadtree of square cells over the tile. Every leaf is drawn as one triangle fan
//! around its centre; its perimeter holds the four corners and, on each edge, the edge midpoint
//! when that vertex is present. A midpoint is present when the neighbour across the edge is
//! split (then it is a corner of the neighbour's children) or when it was *activated* between
//! two leaves of the same size (a bintree step that halves the two triangles beside it). The
//! quadtree is restricted: leaves that share an edge differ by at most one depth, so an edge
//! never holds more than one midpoint and no T-vertex can appear.
//!
//! Level `i+1` starts from level `i` and only adds (activations and splits), so every vertex of
//! level `i` is a vertex of level `i+1` (the nesting the progressive upload relies on). A leaf
//! is refined while one of its triangles deviates from a source sample by more than `e_{i+1}`,
//! unless the refinement would create a cell spacing below `e_{i+1}` (the paper's anti-aliasing
//! rule): a leaf of size `s` samples has its fan vertices on an `s/2` lattice, so activation in
//! it is allowed while `s/2 * spacing >= e` and a split while `s/4 * spacing >= e`.
//!
//! Triangle errors are measured against the source samples with the *quantised* vertex heights,
//! so the bound holds for what is stored. Each fan triangle's error depends only on its three
//! vertices, so it is computed once per tile and cached.

use crate::quantise::Quantiser;

/// Samples per tile side (2^8 + 1).
pub const TILE_SIZE: usize = 257;
/// Cells per tile side.
pub const TILE_CELLS: u32 = 256;
/// Depth of the finest cells (size 2: a fan needs a centre sample).
const MAX_DEPTH: u32 = 7;
const NODE_COUNT: usize = ((1usize << (2 * (MAX_DEPTH + 1))) - 1) / 3;
/// Cells whose fan errors are kept: all but the finest (size 2), which come first among the
/// indices.
const CACHED_NODES: usize = ((1usize << (2 * MAX_DEPTH)) - 1) / 3;
/// [`Mesher::fan_error`]'s mask of a cell whose fan error is not known.
const NO_FAN: u8 = u8::MAX;

/// The samples of one tile: 257 x 257 heights in metres, padded past the data by repeating the
/// last real row and column, plus where the real data ends.
#[derive(Clone, Debug)]
pub struct TileSamples {
    /// Row-major, 257 x 257, row 0 = north edge of the tile.
    pub heights: Vec<f32>,
    /// Last local column / row that holds real data (inclusive, 1..=256).
    pub data_max_x: u32,
    pub data_max_y: u32,
}

impl TileSamples {
    /// Last column / row the mesh covers: the data extent rounded up to even, because the
    /// finest cell is two samples wide. At most one padded column/row is meshed, never measured.
    pub fn mesh_max(&self) -> (u32, u32) {
        ((self.data_max_x + 1) & !1, (self.data_max_y + 1) & !1)
    }
}

/// A quadtree cell: depth `d` (0 = the whole tile), column `i`, row `j` at that depth.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Quad {
    pub d: u32,
    pub i: u32,
    pub j: u32,
}

impl Quad {
    pub const ROOT: Quad = Quad { d: 0, i: 0, j: 0 };

    pub fn size(self) -> u32 {
        TILE_CELLS >> self.d
    }

    pub fn origin(self) -> (u32, u32) {
        (self.i * self.size(), self.j * self.size())
    }

    fn index(self) -> usize {
        ((1usize << (2 * self.d)) - 1) / 3
            + (self.j as usize) * (1usize << self.d)
            + self.i as usize
    }

    /// The cell numbered `index` ([`Self::index`]'s inverse).
    fn from_index(index: usize) -> Quad {
        let mut d = 0;
        while ((1usize << (2 * (d + 1))) - 1) / 3 <= index {
            d += 1;
        }
        let at = index - ((1usize << (2 * d)) - 1) / 3;
        Quad {
            d,
            i: (at % (1usize << d)) as u32,
            j: (at >> d) as u32,
        }
    }

    fn parent(self) -> Quad {
        Quad {
            d: self.d - 1,
            i: self.i / 2,
            j: self.j / 2,
        }
    }

    fn children(self) -> [Quad; 4] {
        let (d, i, j) = (self.d + 1, self.i * 2, self.j * 2);
        [
            Quad { d, i, j },
            Quad { d, i: i + 1, j },
            Quad { d, i, j: j + 1 },
            Quad {
                d,
                i: i + 1,
                j: j + 1,
            },
        ]
    }

    /// The same-depth cell across edge `k` (0 north, 1 east, 2 south, 3 west), if inside the tile.
    fn neighbour(self, k: usize) -> Option<Quad> {
        let n = 1u32 << self.d;
        let (i, j) = match k {
            0 => (Some(self.i), self.j.checked_sub(1)),
            1 => (Some(self.i + 1).filter(|&i| i < n), Some(self.j)),
            2 => (Some(self.i), Some(self.j + 1).filter(|&j| j < n)),
            _ => (self.i.checked_sub(1), Some(self.j)),
        };
        Some(Quad {
            d: self.d,
            i: i?,
            j: j?,
        })
    }

    pub fn centre(self) -> (u32, u32) {
        let (x, y) = self.origin();
        let h = self.size() / 2;
        (x + h, y + h)
    }

    /// Corners in edge order: corner `k` starts edge `k` (NW, NE, SE, SW).
    pub fn corner(self, k: usize) -> (u32, u32) {
        let (x, y) = self.origin();
        let s = self.size();
        match k & 3 {
            0 => (x, y),
            1 => (x + s, y),
            2 => (x + s, y + s),
            _ => (x, y + s),
        }
    }

    /// Midpoint of edge `k` (0 north, 1 east, 2 south, 3 west).
    pub fn midpoint(self, k: usize) -> (u32, u32) {
        let (x, y) = self.origin();
        let (s, h) = (self.size(), self.size() / 2);
        match k {
            0 => (x + h, y),
            1 => (x + s, y + h),
            2 => (x + h, y + s),
            _ => (x, y + h),
        }
    }

    /// The fan triangle `t` of this cell: `0..4` the full triangle over edge `t`, `4..12` the
    /// two halves of edge `(t-4)/2` when its midpoint is present.
    pub fn triangle(self, t: usize) -> [(u32, u32); 3] {
        let c = self.centre();
        if t < 4 {
            [c, self.corner(t), self.corner(t + 1)]
        } else {
            let k = (t - 4) / 2;
            if t.is_multiple_of(2) {
                [c, self.corner(k), self.midpoint(k)]
            } else {
                [c, self.midpoint(k), self.corner(k + 1)]
            }
        }
    }
}

/// Position of a cell along the Hilbert curve over `n x n` cells (`n` a power of two).
/// Leaves sorted by it are visited depth-first with every step to an adjacent cell: the
/// P-order traversal of the paper, figure 3.
#[cfg(test)]
pub(crate) fn hilbert_index(n: u32, mut x: u32, mut y: u32) -> u32 {
    let mut d = 0;
    let mut s = n / 2;
    while s > 0 {
        let rx = u32::from(x & s > 0);
        let ry = u32::from(y & s > 0);
        d += s * s * ((3 * rx) ^ ry);
        if ry == 0 {
            if rx == 1 {
                x = s - 1 - (x & (s - 1));
                y = s - 1 - (y & (s - 1));
            }
            std::mem::swap(&mut x, &mut y);
        }
        x &= s - 1;
        y &= s - 1;
        s /= 2;
    }
    d
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Node {
    /// Inside a leaf ancestor.
    Absent,
    Leaf,
    Split,
    /// Entirely past the data: never split, never drawn.
    Outside,
}

/// What lies across an edge of a leaf.
enum Across {
    /// The tile border, the data border, or a leaf of the same size: a midpoint may be activated.
    Free(Option<Quad>),
    /// A leaf twice the size: it must split before the midpoint can exist.
    Coarser(Quad),
    /// A split cell: the midpoint is already present.
    Finer,
}

/// When each cell of a tile's mesh was split and each lattice point became present, level by
/// level: an earlier mesh of the tile, kept so that meshing it again with more forced side
/// vertices ([`Mesher::replay`], [`Mesher::refine_changed`]) looks only at what changes. 88 KB
/// a tile.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshHistory {
    /// Per cell: the level it was split at plus one (the data border's splits count as level
    /// 0's), or [`Self::NEVER`].
    split: Vec<u8>,
    /// Per lattice point, the same for its presence as a midpoint.
    present: Vec<u8>,
}

impl MeshHistory {
    const NEVER: u8 = u8::MAX;
    /// What one takes.
    pub const BYTES: usize = NODE_COUNT + TILE_SIZE * TILE_SIZE;

    /// A history that holds nothing yet.
    pub fn new() -> MeshHistory {
        MeshHistory {
            split: vec![Self::NEVER; NODE_COUNT],
            present: vec![Self::NEVER; TILE_SIZE * TILE_SIZE],
        }
    }

    fn tag(level: usize) -> u8 {
        u8::try_from(level + 1)
            .ok()
            .filter(|&t| t != Self::NEVER)
            .expect("levels fit a byte")
    }

    /// Whether `q` was a leaf at the level tagged `tag` with the fan `present` says (midpoint
    /// `k` present or not).
    fn had_leaf(&self, q: Quad, tag: u8, present: impl Fn(usize) -> bool) -> bool {
        let leaf =
            self.split[q.index()] > tag && (q.d == 0 || self.split[q.parent().index()] <= tag);
        leaf && (0..4).all(|k| {
            let (x, y) = q.midpoint(k);
            (self.present[lattice(x, y)] <= tag) == present(k)
        })
    }
}

impl Default for MeshHistory {
    fn default() -> Self {
        MeshHistory::new()
    }
}

/// Builds the nested levels of one tile, one [`Mesher::refine`] call per level.
pub struct Mesher<'a> {
    samples: &'a TileSamples,
    /// Quantised heights at every lattice point (what the mesh interpolates).
    mesh_heights: Vec<f32>,
    nodes: Vec<Node>,
    /// Midpoint presence per lattice point.
    present: Vec<bool>,
    /// Cached fan-triangle errors per cell but the finest (NaN = not computed yet; none made
    /// until the first is asked for).
    errors: Vec<[f64; 12]>,
    /// Per cell, the largest error of its fan as a leaf, and the fan it is of (the mask of
    /// its present midpoints, [`NO_FAN`] for none yet): what a leaf's check looks up first,
    /// 9 bytes a cell against the errors' 96, so that the checks of the leaves that need no
    /// work stay within the core's cache.
    fan_max: Vec<f64>,
    fan_mask: Vec<u8>,
    /// The bound that fan last passed refinement's check at (some of its triangles over it
    /// but not to be refined): a second call at the same bound (after forced side vertices)
    /// passes over it too.
    fan_passed: Vec<f64>,
    min_spacing: f64,
    mesh_max: (u32, u32),
}

pub(crate) fn lattice(x: u32, y: u32) -> usize {
    y as usize * TILE_SIZE + x as usize
}

impl<'a> Mesher<'a> {
    /// A mesher at the state before level 0: the root cell, split wherever the data border
    /// crosses a cell (those splits are geometry, not error, so no rule limits them).
    pub fn new(samples: &'a TileSamples, quantiser: &Quantiser, min_spacing: f64) -> Self {
        let mesh_heights = samples
            .heights
            .iter()
            .map(|&h| quantiser.height(quantiser.quantise(h)))
            .collect();
        Mesher::with_heights(samples, mesh_heights, min_spacing)
    }

    /// [`Mesher::new`] for samples that are heights on the quantiser's lattice already (a
    /// decoder's, each `quantiser.height(code)`), which quantising would give back.
    pub fn of_quantised(samples: &'a TileSamples) -> Self {
        Mesher::with_heights(samples, samples.heights.clone(), 1.0)
    }

    fn with_heights(samples: &'a TileSamples, mesh_heights: Vec<f32>, min_spacing: f64) -> Self {
        let mut mesher = Mesher {
            samples,
            mesh_heights,
            nodes: vec![Node::Absent; NODE_COUNT],
            present: vec![false; TILE_SIZE * TILE_SIZE],
            // Made on the first error asked for: a decoder's mesher asks none.
            errors: Vec::new(),
            fan_max: Vec::new(),
            fan_mask: Vec::new(),
            fan_passed: Vec::new(),
            min_spacing,
            mesh_max: samples.mesh_max(),
        };
        mesher.nodes[Quad::ROOT.index()] = Node::Leaf;
        // Splits cascade (2:1 restriction), so every leaf they create is examined again.
        let mut straddling = vec![Quad::ROOT];
        while let Some(q) = straddling.pop() {
            if mesher.nodes[q.index()] == Node::Leaf && mesher.straddles(q) {
                mesher.split(q, &mut straddling);
            }
        }
        mesher
    }

    /// The mesher whose mesh has exactly the vertices `is_vertex` says, of a level built by
    /// [`Self::refine`] and [`Self::insert_side_vertex`] (issue 28's compact levels: the fans
    /// follow from the vertex set). Every cell of such a mesh, leaf or split, has its centre
    /// as a vertex (a leaf's fan centre, or its children's shared corner), so a cell is split
    /// exactly where one of its children's centres is a vertex; and a leaf's edge midpoint is
    /// on its fan exactly where it is a vertex (split neighbours and activations both make it
    /// one). Only the topology is rebuilt: `samples` gives the data's extent (and heights for
    /// the errors, which a decoder does not ask for).
    pub fn from_vertices(
        samples: &'a TileSamples,
        quantiser: &Quantiser,
        is_vertex: impl Fn((u32, u32)) -> bool,
    ) -> Self {
        let mut mesher = Mesher::new(samples, quantiser, 1.0);
        mesher.extend_to_vertices(is_vertex);
        mesher
    }

    /// [`Self::from_vertices`] from the current mesh, whose vertices `is_vertex` must hold (a
    /// finer level's set holds a coarser one's): splits and activations only add.
    pub fn extend_to_vertices(&mut self, is_vertex: impl Fn((u32, u32)) -> bool) {
        // Until no leaf has a child centre among the vertices: every leaf is looked at, and
        // every leaf a split makes or changes (its children, and those of the 2:1 cascade).
        let mut work = self.leaves();
        while let Some(q) = work.pop() {
            if self.state(q) != Node::Leaf || q.size() < 4 {
                continue;
            }
            let wants = q
                .children()
                .into_iter()
                .any(|c| !self.outside(c) && is_vertex(c.centre()));
            if wants {
                self.split(q, &mut work);
            }
        }
        for q in self.leaves() {
            for k in 0..4 {
                let p = q.midpoint(k);
                if is_vertex(p) {
                    self.present[lattice(p.0, p.1)] = true;
                }
            }
        }
    }

    pub fn quantised_heights(&self) -> &[f32] {
        &self.mesh_heights
    }

    fn state(&self, q: Quad) -> Node {
        self.nodes[q.index()]
    }

    fn straddles(&self, q: Quad) -> bool {
        let (x, y) = q.origin();
        let s = q.size();
        let (mx, my) = self.mesh_max;
        (x < mx && mx < x + s) || (y < my && my < y + s)
    }

    fn outside(&self, q: Quad) -> bool {
        let (x, y) = q.origin();
        x >= self.mesh_max.0 || y >= self.mesh_max.1
    }

    /// The non-absent cell that covers `q`'s area (itself or an ancestor).
    fn covering(&self, mut q: Quad) -> Quad {
        while self.state(q) == Node::Absent && q.d > 0 {
            q = q.parent();
        }
        q
    }

    fn across(&self, q: Quad, k: usize) -> Across {
        let Some(n) = q.neighbour(k) else {
            return Across::Free(None);
        };
        let c = self.covering(n);
        match self.state(c) {
            Node::Outside => Across::Free(None),
            Node::Split => Across::Finer,
            Node::Leaf if c == n => Across::Free(Some(n)),
            _ => Across::Coarser(c),
        }
    }

    /// Splits leaf `q`, first splitting coarser neighbours so the 2:1 restriction holds.
    /// Every leaf whose fan changed is pushed onto `changed`.
    fn split(&mut self, q: Quad, changed: &mut Vec<Quad>) {
        debug_assert_eq!(self.state(q), Node::Leaf);
        for k in 0..4 {
            if let Across::Coarser(c) = self.across(q, k) {
                self.split(c, changed);
            }
        }
        self.nodes[q.index()] = Node::Split;
        for k in 0..4 {
            let (x, y) = q.midpoint(k);
            self.present[lattice(x, y)] = true;
            if let Some(n) = q.neighbour(k) {
                if self.state(n) == Node::Leaf {
                    changed.push(n);
                }
            }
        }
        for c in q.children() {
            let state = if self.outside(c) {
                Node::Outside
            } else {
                Node::Leaf
            };
            self.nodes[c.index()] = state;
            if state == Node::Leaf {
                changed.push(c);
            }
        }
    }

    pub fn midpoint_present(&self, q: Quad, k: usize) -> bool {
        let (x, y) = q.midpoint(k);
        self.present[lattice(x, y)]
    }

    /// Which of `q`'s edge midpoints are present, bit `k` for edge `k`: what its fan's
    /// triangles depend on besides `q`.
    fn fan_mask(&self, q: Quad) -> u8 {
        (0..4).fold(0, |m, k| m | u8::from(self.midpoint_present(q, k)) << k)
    }

    /// The largest error of leaf `q`'s fan as it is, if known ([`Self::refine`] records it).
    pub fn fan_error(&self, q: Quad) -> Option<f64> {
        let i = q.index();
        (self.fan_mask.get(i) == Some(&self.fan_mask(q))).then(|| self.fan_max[i])
    }

    /// Records leaf `q`'s fan (`mask`) as passing refinement's check at `bound`, its largest
    /// error `error`.
    fn record_fan_error(&mut self, q: Quad, mask: u8, error: f64, bound: f64) {
        if self.fan_mask.is_empty() {
            self.fan_max = vec![0.0; NODE_COUNT];
            self.fan_mask = vec![NO_FAN; NODE_COUNT];
            self.fan_passed = vec![f64::NAN; NODE_COUNT];
        }
        self.fan_max[q.index()] = error;
        self.fan_mask[q.index()] = mask;
        self.fan_passed[q.index()] = bound;
    }

    /// Max deviation of fan triangle `t` of `q` from the source samples, cached for cells
    /// above the finest (whose twelve are found again, together: [`Self::measure_finest`]).
    pub fn triangle_error(&mut self, q: Quad, t: usize) -> f64 {
        if self.errors.is_empty() {
            self.errors = vec![[f64::NAN; 12]; CACHED_NODES];
        }
        if q.size() == 2 {
            // Found again rather than kept: the finest cells are three quarters of the cells,
            // and a table with them would not stay in the core's cache.
            return self.measure_finest(q)[t];
        }
        let cached = self.errors[q.index()][t];
        if !cached.is_nan() {
            return cached;
        }
        let e = self.measure(q, t);
        self.errors[q.index()][t] = e;
        e
    }

    /// Max |source - interpolated| over the real data samples in a triangle (edges included)
    /// of a cell above the finest (a finest cell's: [`Self::measure_finest`]).
    fn measure(&self, q: Quad, t: usize) -> f64 {
        debug_assert!(
            q.size() > 2,
            "{q:?}: a finest cell's errors come from measure_finest"
        );
        let tri = q.triangle(t);
        let (a, b, c) = plane(
            tri,
            tri.map(|(x, y)| f64::from(self.mesh_heights[lattice(x, y)])),
        );
        // Four independent maxima so the loop vectorises (a single running max cannot be
        // reordered without fast-math), kept over the rows: max is exact in any order.
        let mut lanes = [0.0f64; 4];
        triangle_spans(
            q,
            t,
            self.samples.data_max_x,
            self.samples.data_max_y,
            |y, lo, hi| {
                let row = &self.samples.heights[lattice(0, y)..][lo as usize..=hi as usize];
                let z0 = a + c * f64::from(y) + b * f64::from(lo);
                // The column's offset from the integer (exact), so the lanes do not wait on
                // one another's sum.
                let mut chunks = row.chunks_exact(4);
                let mut i = 0u32;
                for chunk in &mut chunks {
                    for (j, (l, &h)) in lanes.iter_mut().zip(chunk).enumerate() {
                        let d = (f64::from(h) - (z0 + b * f64::from(i + j as u32))).abs();
                        *l = if d > *l { d } else { *l };
                    }
                    i += 4;
                }
                for &h in chunks.remainder() {
                    let d = (f64::from(h) - (z0 + b * f64::from(i))).abs();
                    lanes[0] = if d > lanes[0] { d } else { lanes[0] };
                    i += 1;
                }
            },
        );
        lanes.iter().fold(0.0f64, |w, &l| if l > w { l } else { w })
    }

    /// [`Self::measure`] of all twelve fan triangles of a finest cell `q`, in
    /// [`Quad::triangle`]'s order: the same values as `measure_smallest` of each, with
    /// each of the cell's nine points' deviations found once.
    fn measure_finest(&self, q: Quad) -> [f64; 12] {
        let (mx, my) = (self.samples.data_max_x, self.samples.data_max_y);
        let deviation = |(x, y): (u32, u32)| {
            if x <= mx && y <= my {
                let l = lattice(x, y);
                f64::from((self.samples.heights[l] - self.mesh_heights[l]).abs())
            } else {
                0.0
            }
        };
        let centre = deviation(q.centre());
        let corners = [0, 1, 2, 3].map(|k| deviation(q.corner(k)));
        let midpoints = [0, 1, 2, 3].map(|k| deviation(q.midpoint(k)));
        let mut fan = [0.0f64; 12];
        for k in 0..4 {
            let (a, b) = (q.corner(k), q.corner(k + 1));
            let near = centre.max(corners[k]).max(corners[(k + 1) % 4]);
            // The full triangle holds its long edge's midpoint, off its surface.
            let (x, y) = q.midpoint(k);
            fan[k] = if x <= mx && y <= my {
                let z = (f64::from(self.mesh_heights[lattice(a.0, a.1)])
                    + f64::from(self.mesh_heights[lattice(b.0, b.1)]))
                    * 0.5;
                near.max((f64::from(self.samples.heights[lattice(x, y)]) - z).abs())
            } else {
                near
            };
            fan[4 + 2 * k] = centre.max(corners[k]).max(midpoints[k]);
            fan[5 + 2 * k] = centre.max(midpoints[k]).max(corners[(k + 1) % 4]);
        }
        fan
    }

    /// The error of one fan triangle of a finest cell, which holds no samples but its vertices
    /// and, for a full triangle, the midpoint of its long edge: what [`Self::measure_finest`]
    /// finds for all twelve at once (the tests' reference for it).
    #[cfg(test)]
    fn measure_smallest(&self, tri: [(u32, u32); 3]) -> f64 {
        let (mx, my) = (self.samples.data_max_x, self.samples.data_max_y);
        let deviation = |(x, y): (u32, u32), z: f32| {
            if x <= mx && y <= my {
                f64::from((self.samples.heights[lattice(x, y)] - z).abs())
            } else {
                0.0
            }
        };
        let mut worst = 0.0f64;
        for &p in &tri {
            worst = worst.max(deviation(p, self.mesh_heights[lattice(p.0, p.1)]));
        }
        let (a, b) = (tri[1], tri[2]);
        if a.0.abs_diff(b.0) + a.1.abs_diff(b.1) == 2 {
            let mid = ((a.0 + b.0) / 2, (a.1 + b.1) / 2);
            let z = (f64::from(self.mesh_heights[lattice(a.0, a.1)])
                + f64::from(self.mesh_heights[lattice(b.0, b.1)]))
                * 0.5;
            if mid.0 <= mx && mid.1 <= my {
                worst =
                    worst.max((f64::from(self.samples.heights[lattice(mid.0, mid.1)]) - z).abs());
            }
        }
        worst
    }

    /// The padded column and row (`mesh_max` past the data's last, odd, column or row): meshed
    /// and drawn, their heights copies of the last data column's and row's. `None` where the
    /// data reach the mesh's extent.
    fn padding(&self) -> (Option<u32>, Option<u32>) {
        let (mx, my) = self.mesh_max;
        (
            (mx > self.samples.data_max_x).then_some(mx),
            (my > self.samples.data_max_y).then_some(my),
        )
    }

    /// Whether leaf `q`'s closure holds a point of the padded column or row.
    fn touches_padding(&self, q: Quad) -> bool {
        let ((x0, y0), s) = (q.origin(), q.size());
        let (px, py) = self.padding();
        px.is_some_and(|px| x0 <= px && px <= x0 + s)
            || py.is_some_and(|py| y0 <= py && py <= y0 + s)
    }

    /// Max |copied source - interpolated| over the padded column's and row's points in fan
    /// triangle `t` of `q`. Not an error against data, so never stored as one; refinement
    /// holds it within `e` too, so that every vertex a finer level adds, padded or not, lies
    /// within `e` of the coarser surface (what the set's morph units are bounded by,
    /// [`crate::units`]). Out of line: refinement's loop asks it of few leaves.
    #[inline(never)]
    fn padding_error(&self, q: Quad, t: usize) -> f64 {
        let (px, py) = self.padding();
        let tri = q.triangle(t);
        let (a, b, c) = plane(
            tri,
            tri.map(|(x, y)| f64::from(self.mesh_heights[lattice(x, y)])),
        );
        let deviation = |x: u32, y: u32| {
            let z = a + b * f64::from(x) + c * f64::from(y);
            (f64::from(self.samples.heights[lattice(x, y)]) - z).abs()
        };
        let mut worst = 0.0f64;
        let (mx, my) = self.mesh_max;
        triangle_spans(q, t, mx, my, |y, lo, hi| {
            if Some(y) == py {
                for x in lo..=hi {
                    worst = worst.max(deviation(x, y));
                }
            } else if let Some(px) = px.filter(|&px| lo <= px && px <= hi) {
                worst = worst.max(deviation(px, y));
            }
        });
        worst
    }

    fn may_activate(&self, q: Quad, e: f64) -> bool {
        f64::from(q.size() / 2) * self.min_spacing >= e
    }

    fn may_split(&self, q: Quad, e: f64) -> bool {
        q.size() >= 4 && f64::from(q.size() / 4) * self.min_spacing >= e
    }

    /// Refines the current mesh until every fan triangle is within `e` metres of the source,
    /// or the rule above forbids refining it further.
    pub fn refine(&mut self, e: f64) {
        let work = self.leaves();
        self.refine_from(work, e);
    }

    /// [`Self::refine`] of a level that an earlier mesh of the same tile ([`MeshHistory`])
    /// already refined at the same bound from less: the current mesh holds that mesh's level
    /// `level` ([`Self::replay`]), and only its leaves that are new or whose fan changed are
    /// looked at.
    ///
    /// Why that is the same mesh: a refined level is the least mesh that holds the level
    /// before it and the forced vertices and is closed under four rules, each monotone (once
    /// it holds, more cells and vertices keep it holding): a cell's triangle over `e` where
    /// the spacing rule allows activates its midpoint; a present midpoint whose half
    /// triangles are over `e` splits the cell; a split splits the coarser cells beside it (the
    /// 2:1 restriction); an activated midpoint needs the cell across of its size. So any
    /// order of the rules' steps reaches that least mesh (this is also why the agreement's
    /// order of meshing tiles does not matter, `crate::shard`). A leaf of the earlier mesh
    /// with the same fan passed the rules there at this bound and passes them here (they
    /// read the cell, its fan and `e` only); what changed around it (a neighbour's split) is
    /// pushed by the step that changed it.
    pub fn refine_changed(&mut self, e: f64, earlier: &MeshHistory, level: usize) {
        let tag = MeshHistory::tag(level);
        let work = self
            .leaves()
            .into_iter()
            .filter(|&q| !earlier.had_leaf(q, tag, |k| self.midpoint_present(q, k)))
            .collect();
        self.refine_from(work, e);
    }

    /// Makes the current mesh hold `earlier`'s level `level`: the cells it split and the
    /// midpoints it activated at that level (the levels before are held already).
    pub fn replay(&mut self, earlier: &MeshHistory, level: usize) {
        let tag = MeshHistory::tag(level);
        let mut changed = Vec::new();
        // Cells are numbered depth by depth, so a parent comes before its children.
        for i in 0..NODE_COUNT {
            if earlier.split[i] == tag {
                let q = Quad::from_index(i);
                if self.state(q) == Node::Leaf {
                    self.split(q, &mut changed);
                }
                debug_assert_eq!(self.state(q), Node::Split, "{q:?}");
            }
        }
        for (l, &t) in earlier.present.iter().enumerate() {
            if t == tag {
                self.present[l] = true;
            }
        }
    }

    /// Records in `history` what the current mesh split and made present since the history
    /// last recorded: the mesh of level `level`.
    pub fn record(&self, history: &mut MeshHistory, level: usize) {
        let tag = MeshHistory::tag(level);
        for (t, &node) in history.split.iter_mut().zip(&self.nodes) {
            if node == Node::Split && *t == MeshHistory::NEVER {
                *t = tag;
            }
        }
        for (t, &present) in history.present.iter_mut().zip(&self.present) {
            if present && *t == MeshHistory::NEVER {
                *t = tag;
            }
        }
    }

    /// Whether lattice point `p` is a vertex of the current mesh: present (a split's or an
    /// activated midpoint), a corner of the root, or the centre of a cell that is not absent
    /// (a leaf's fan centre; a split cell's children's corner). The last is how a side of a
    /// padded extent (the last column of data at an odd multiple of a cell's half) meets
    /// vertices: those cells straddle the extent and are split.
    pub fn is_vertex(&self, (x, y): (u32, u32)) -> bool {
        if self.present[lattice(x, y)] || (x % TILE_CELLS == 0 && y % TILE_CELLS == 0) {
            return true;
        }
        // The centre of a cell of size `2h`: both coordinates an odd multiple of `h`.
        let h = 1u32 << x.trailing_zeros().min(y.trailing_zeros());
        if (x / h).is_multiple_of(2) || (y / h).is_multiple_of(2) || h > TILE_CELLS / 2 {
            return false;
        }
        let size = 2 * h;
        let q = Quad {
            d: (TILE_CELLS / size).trailing_zeros(),
            i: x / size,
            j: y / size,
        };
        matches!(self.state(q), Node::Leaf | Node::Split)
    }

    fn refine_from(&mut self, mut work: Vec<Quad>, e: f64) {
        'next: while let Some(q) = work.pop() {
            if self.state(q) != Node::Leaf {
                continue;
            }
            let mask = self.fan_mask(q);
            let i = q.index();
            if self.fan_mask.get(i) == Some(&mask)
                && (self.fan_max[i] <= e || self.fan_passed[i] == e)
            {
                continue;
            }
            let mut fan_max = 0.0f64;
            let errors = FanErrors::of(self, q);
            let padded = self.touches_padding(q);
            let error = |mesher: &mut Self, t: usize| match padded {
                false => errors.get(mesher, t),
                true => errors.get(mesher, t).max(mesher.padding_error(q, t)),
            };
            for k in 0..4 {
                if mask & 1 << k != 0 {
                    let worst = error(self, 4 + 2 * k).max(error(self, 5 + 2 * k));
                    if worst > e && self.may_split(q, e) {
                        self.split(q, &mut work);
                        continue 'next;
                    }
                    fan_max = fan_max.max(worst);
                } else {
                    let error = error(self, k);
                    if error <= e || !self.may_activate(q, e) {
                        fan_max = fan_max.max(error);
                        continue;
                    }
                    match self.across(q, k) {
                        Across::Free(n) => {
                            let (x, y) = q.midpoint(k);
                            self.present[lattice(x, y)] = true;
                            work.push(q);
                            work.extend(n);
                        }
                        Across::Coarser(c) => {
                            self.split(c, &mut work);
                            work.push(q);
                        }
                        Across::Finer => {
                            unreachable!("a split neighbour marks the midpoint present")
                        }
                    }
                    continue 'next;
                }
            }
            self.record_fan_error(q, mask, fan_max, e);
        }
    }

    /// Makes lattice point `p` on one of the tile's sides a vertex: splits the leaves above it
    /// (with their 2:1 cascades) until `p` is a corner or a side midpoint of a leaf, and
    /// activates that midpoint. The tile set builder calls this for the vertices a neighbouring
    /// tile has on the shared side, so both tiles end up with the same side vertices per level.
    /// Refinement only adds vertices, so the level stays within its bound; call
    /// [`Self::refine`] again afterwards, because a forced split can leave finer cells over `e`.
    pub fn insert_side_vertex(&mut self, p: (u32, u32)) {
        let (mx, my) = self.mesh_max;
        debug_assert!(
            (p.0 == 0 || p.0 == mx || p.1 == 0 || p.1 == my) && p.0 <= mx && p.1 <= my,
            "{p:?} is not on a side of the mesh"
        );
        let mut changed = Vec::new();
        loop {
            let q = self.leaf_at(p);
            if (0..4).any(|k| q.corner(k) == p) {
                return;
            }
            if let Some(k) = (0..4).find(|&k| q.midpoint(k) == p) {
                if let Across::Free(_) = self.across(q, k) {
                    self.present[lattice(p.0, p.1)] = true;
                    return;
                }
            }
            self.split(q, &mut changed);
        }
    }

    /// A leaf whose cell holds `p` (inside or on its boundary; on a boundary between cells the
    /// north-western one, which is never past the data).
    fn leaf_at(&self, p: (u32, u32)) -> Quad {
        let mut q = Quad::ROOT;
        while self.state(q) == Node::Split {
            let (cx, cy) = q.centre();
            let child = usize::from(p.0 > cx) + 2 * usize::from(p.1 > cy);
            q = q.children()[child];
        }
        q
    }

    /// Whether fan triangle `t` of leaf `q` may exceed `e`: refining it is forbidden by the
    /// spacing rule, or it is already at full resolution.
    pub fn refinement_forbidden(&self, q: Quad, t: usize, e: f64) -> bool {
        if t < 4 {
            !self.may_activate(q, e)
        } else {
            !self.may_split(q, e)
        }
    }

    /// The current leaves in P-order: the order of their cells along the Hilbert curve over
    /// the tile's finest cells, the paper's figure 3. A depth-first walk that visits each
    /// split cell's children in the curve's order: a cell covers one run of the curve, so the
    /// walk meets the leaves in the order a sort by the Hilbert index of any of their cells
    /// would give (the tests' `hilbert_index`), without the keys or the sort.
    pub fn leaves_in_p_order(&self) -> Vec<Quad> {
        let mut out = Vec::new();
        // A cell with the orientation of the curve through it, as the two symmetries of the
        // square that `hilbert_index` applies to the bits below a quadrant: a swap of x and y
        // and a flip of both. They commute and each undoes itself.
        let mut stack = vec![(Quad::ROOT, false, false)];
        while let Some((q, swap, flip)) = stack.pop() {
            match self.state(q) {
                Node::Leaf => out.push(q),
                Node::Split => {
                    let children = q.children();
                    // The curve's quadrants in its order, pushed last first: (0, 0), (0, 1),
                    // (1, 1), (1, 0) in the curve's frame.
                    for (rx, ry) in [(1u32, 0u32), (1, 1), (0, 1), (0, 0)] {
                        let (mut cx, mut cy) = (rx ^ u32::from(flip), ry ^ u32::from(flip));
                        if swap {
                            std::mem::swap(&mut cx, &mut cy);
                        }
                        let turns = ry == 0;
                        stack.push((
                            children[(cx + 2 * cy) as usize],
                            swap ^ turns,
                            flip ^ (turns && rx == 1),
                        ));
                    }
                }
                _ => {}
            }
        }
        out
    }

    /// The current leaves (drawn cells), in no particular order.
    pub fn leaves(&self) -> Vec<Quad> {
        let mut out = Vec::new();
        let mut stack = vec![Quad::ROOT];
        while let Some(q) = stack.pop() {
            match self.state(q) {
                Node::Leaf => out.push(q),
                Node::Split => stack.extend(q.children()),
                _ => {}
            }
        }
        out
    }

    /// The fan of leaf `q`: centre, then the perimeter counter-clockwise seen from above
    /// (x = column east, y = row south, z up), closed by repeating the first corner.
    pub fn fan(&self, q: Quad, out: &mut Vec<(u32, u32)>) {
        out.push(q.centre());
        // Edge order 0 N, 1 E, 2 S, 3 W runs clockwise from above; walk it backwards.
        out.push(q.corner(0));
        for k in [3usize, 2, 1, 0] {
            if self.midpoint_present(q, k) {
                out.push(q.midpoint(k));
            }
            out.push(q.corner(k));
        }
    }

    /// The fan triangles of leaf `q` ([`Self::fan_triangles`]) with their errors ([`FanErrors`]).
    pub fn fan_triangle_errors(&mut self, q: Quad) -> impl Iterator<Item = (usize, f64)> {
        let fan = self.fan_triangles(q);
        let found = FanErrors::of(self, q);
        let errors: [f64; 8] = std::array::from_fn(|i| match i < fan.len {
            true => found.get(self, fan.ids[i]),
            false => 0.0,
        });
        (0..fan.len).map(move |i| (fan.ids[i], errors[i]))
    }

    /// The fan triangles of leaf `q` as indices into [`Quad::triangle`].
    pub fn fan_triangles(&self, q: Quad) -> FanTriangles {
        let mut out = FanTriangles {
            ids: [0; 8],
            len: 0,
        };
        for k in 0..4 {
            if self.midpoint_present(q, k) {
                out.ids[out.len] = 4 + 2 * k;
                out.ids[out.len + 1] = 5 + 2 * k;
                out.len += 2;
            } else {
                out.ids[out.len] = k;
                out.len += 1;
            }
        }
        out
    }
}

/// The errors of a leaf's fan triangles as [`Mesher::refine`] and
/// [`Mesher::fan_triangle_errors`] read them: a finest cell's twelve found at once
/// ([`Mesher::measure_finest`]; refinement asks for most of them), a coarser cell's one by
/// one through the cache ([`Mesher::triangle_error`]).
enum FanErrors {
    Finest([f64; 12]),
    Cached(Quad),
}

impl FanErrors {
    fn of(mesher: &Mesher<'_>, q: Quad) -> FanErrors {
        match q.size() {
            2 => FanErrors::Finest(mesher.measure_finest(q)),
            _ => FanErrors::Cached(q),
        }
    }

    /// The error of fan triangle `t` ([`Quad::triangle`]'s numbering).
    fn get(&self, mesher: &mut Mesher<'_>, t: usize) -> f64 {
        match self {
            FanErrors::Finest(all) => all[t],
            FanErrors::Cached(q) => mesher.triangle_error(*q, t),
        }
    }
}

/// The triangles of one fan (4 to 8), without borrowing the mesher.
#[derive(Clone, Copy, Debug)]
pub struct FanTriangles {
    ids: [usize; 8],
    len: usize,
}

impl FanTriangles {
    pub fn as_slice(&self) -> &[usize] {
        &self.ids[..self.len]
    }
}

/// Calls `span(y, x_lo, x_hi)` for every row of lattice points inside fan triangle `t` of
/// cell `q` (edges included), clipped to `x <= max_x`, `y <= max_y`. Every fan triangle is
/// bounded by axis-aligned and diagonal edges, so its row spans follow from the row offset
/// alone, without edge functions.
pub(crate) fn triangle_spans(
    q: Quad,
    t: usize,
    max_x: u32,
    max_y: u32,
    mut span: impl FnMut(u32, u32, u32),
) {
    let (x0, y0) = q.origin();
    let (s, h) = (q.size(), q.size() / 2);
    // (first row, last row) as offsets from y0, and the span as offsets from x0 for offset r.
    let (r0, r1): (u32, u32) = match t {
        0 | 4 | 5 | 6 | 11 => (0, h),
        1 | 3 => (0, s),
        _ => (h, s),
    };
    let last = (y0 + r1).min(max_y);
    for y in (y0 + r0)..=last {
        let r = y - y0;
        let m = r.min(s - r);
        let (lo, hi) = match t {
            0 => (r, s - r),
            1 => (s - m, s),
            2 => (s - r, r),
            3 => (0, m),
            4 => (r, h),
            5 => (h, s - r),
            6 => (s - r, s),
            7 => (r, s),
            8 => (h, r),
            9 => (s - r, h),
            10 => (0, s - r),
            _ => (0, r),
        };
        let hi = (x0 + hi).min(max_x);
        if x0 + lo <= hi {
            span(y, x0 + lo, hi);
        }
    }
}

/// The plane `z = a + b x + c y` through three lattice points with heights.
pub(crate) fn plane(tri: [(u32, u32); 3], z: [f64; 3]) -> (f64, f64, f64) {
    let [(x0, y0), (x1, y1), (x2, y2)] = tri.map(|(x, y)| (f64::from(x), f64::from(y)));
    let det = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
    let b = ((z[1] - z[0]) * (y2 - y0) - (z[2] - z[0]) * (y1 - y0)) / det;
    let c = ((x1 - x0) * (z[2] - z[0]) - (x2 - x0) * (z[1] - z[0])) / det;
    (z[0] - b * x0 - c * y0, b, c)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every cell's number gives the cell back.
    #[test]
    fn a_cells_number_gives_it_back() {
        for index in 0..NODE_COUNT {
            assert_eq!(Quad::from_index(index).index(), index);
        }
        assert_eq!(Quad::from_index(0), Quad::ROOT);
        assert_eq!(Quad::from_index(NODE_COUNT - 1).size(), 2);
    }

    /// The twelve errors of a finest cell found at once are those of each triangle alone, to
    /// the bit, over cells inside the data and past its last row and column.
    #[test]
    fn a_finest_cells_errors_at_once_are_each_triangles() {
        // A rough field (a hash of the position, metres), quantised at 0.1 m so every vertex
        // is off its sample.
        let heights: Vec<f32> = (0..TILE_SIZE * TILE_SIZE)
            .map(|l| ((l as u32).wrapping_mul(2_654_435_761) >> 20) as f32 * 0.0137)
            .collect();
        let samples = TileSamples {
            heights,
            data_max_x: 201,
            data_max_y: 256,
        };
        let mesher = Mesher::new(&samples, &Quantiser::for_tile(0.0, 0.1), 1.0);
        let mut off_surface = 0;
        for j in 0..128 {
            for i in 0..128 {
                let q = Quad { d: MAX_DEPTH, i, j };
                let fan = mesher.measure_finest(q);
                for (t, &e) in fan.iter().enumerate() {
                    let one = mesher.measure_smallest(q.triangle(t));
                    assert_eq!(e.to_bits(), one.to_bits(), "{q:?} {t}");
                    off_surface += usize::from(e > 0.05);
                }
            }
        }
        // Past the quantisation's half step: a long edge's midpoint off the surface.
        assert!(off_surface > 20_000, "{off_surface}: too smooth to test");
    }

    /// The span table visits exactly the lattice points a brute-force inside test finds, for
    /// every fan triangle of cells of several sizes, clipped or not.
    #[test]
    fn triangle_spans_match_a_brute_force_inside_test() {
        for q in [
            Quad { d: 7, i: 3, j: 5 },
            Quad { d: 5, i: 1, j: 2 },
            Quad { d: 2, i: 3, j: 0 },
            Quad::ROOT,
        ] {
            for t in 0..12 {
                for (mx, my) in [(256, 256), (q.centre().0, 256), (256, q.centre().1 + 1)] {
                    let mut spans = Vec::new();
                    triangle_spans(q, t, mx, my, |y, lo, hi| {
                        spans.extend((lo..=hi).map(|x| (x, y)))
                    });
                    let p = q.triangle(t).map(|(x, y)| (i64::from(x), i64::from(y)));
                    let cross = |a: (i64, i64), b: (i64, i64), x: i64, y: i64| {
                        (b.0 - a.0) * (y - a.1) - (b.1 - a.1) * (x - a.0)
                    };
                    let area = cross(p[0], p[1], p[2].0, p[2].1);
                    let mut brute = Vec::new();
                    for y in 0..=my {
                        for x in 0..=mx {
                            let (xi, yi) = (i64::from(x), i64::from(y));
                            let w = [
                                cross(p[1], p[2], xi, yi),
                                cross(p[2], p[0], xi, yi),
                                cross(p[0], p[1], xi, yi),
                            ];
                            if w.iter().all(|&v| v * area.signum() >= 0) {
                                brute.push((x, y));
                            }
                        }
                    }
                    spans.sort_unstable_by_key(|&(x, y)| (y, x));
                    assert_eq!(spans, brute, "cell {q:?} triangle {t} clipped to {mx},{my}");
                }
            }
        }
    }

    #[test]
    fn plane_interpolates_its_vertices() {
        let tri = [(4, 4), (0, 0), (8, 0)];
        let (a, b, c) = plane(tri, [10.0, 2.0, 6.0]);
        for ((x, y), z) in tri.iter().zip([10.0, 2.0, 6.0]) {
            assert!((a + b * f64::from(*x) + c * f64::from(*y) - z).abs() < 1e-12);
        }
    }
}
