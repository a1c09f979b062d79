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
        (
            (self.data_max_x + 1) & !1,
            (self.data_max_y + 1) & !1,
        )
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
        ((1usize << (2 * self.d)) - 1) / 3 + (self.j as usize) * (1usize << self.d) + self.i as usize
    }

    fn parent(self) -> Quad {
        Quad { d: self.d - 1, i: self.i / 2, j: self.j / 2 }
    }

    fn children(self) -> [Quad; 4] {
        let (d, i, j) = (self.d + 1, self.i * 2, self.j * 2);
        [
            Quad { d, i, j },
            Quad { d, i: i + 1, j },
            Quad { d, i, j: j + 1 },
            Quad { d, i: i + 1, j: j + 1 },
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
        Some(Quad { d: self.d, i: i?, j: j? })
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
            if t % 2 == 0 {
                [c, self.corner(k), self.midpoint(k)]
            } else {
                [c, self.midpoint(k), self.corner(k + 1)]
            }
        }
    }
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

/// Builds the nested levels of one tile, one [`Mesher::refine`] call per level.
pub struct Mesher<'a> {
    samples: &'a TileSamples,
    /// Quantised heights at every lattice point (what the mesh interpolates).
    mesh_heights: Vec<f32>,
    nodes: Vec<Node>,
    /// Midpoint presence per lattice point.
    present: Vec<bool>,
    /// Cached fan-triangle errors per cell (NaN = not computed yet).
    errors: Vec<[f32; 12]>,
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
        let mut mesher = Mesher {
            samples,
            mesh_heights,
            nodes: vec![Node::Absent; NODE_COUNT],
            present: vec![false; TILE_SIZE * TILE_SIZE],
            errors: vec![[f32::NAN; 12]; NODE_COUNT],
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
            let state = if self.outside(c) { Node::Outside } else { Node::Leaf };
            self.nodes[c.index()] = state;
            if state == Node::Leaf {
                changed.push(c);
            }
        }
    }

    fn midpoint_present(&self, q: Quad, k: usize) -> bool {
        let (x, y) = q.midpoint(k);
        self.present[lattice(x, y)]
    }

    /// Max deviation of fan triangle `t` of `q` from the source samples, cached.
    pub fn triangle_error(&mut self, q: Quad, t: usize) -> f32 {
        let cached = self.errors[q.index()][t];
        if !cached.is_nan() {
            return cached;
        }
        let e = self.measure(q.triangle(t));
        self.errors[q.index()][t] = e;
        e
    }

    /// Max |source - interpolated| over the real data samples in a triangle (edges included).
    fn measure(&self, tri: [(u32, u32); 3]) -> f32 {
        let mut worst = 0.0f32;
        raster_triangle(tri, self.samples.data_max_x, self.samples.data_max_y, |x, y, w| {
            let z = w[0] * self.mesh_heights[lattice(tri[0].0, tri[0].1)]
                + w[1] * self.mesh_heights[lattice(tri[1].0, tri[1].1)]
                + w[2] * self.mesh_heights[lattice(tri[2].0, tri[2].1)];
            worst = worst.max((self.samples.heights[lattice(x, y)] - z).abs());
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
        let e32 = e as f32;
        let mut work = self.leaves();
        'next: while let Some(q) = work.pop() {
            if self.state(q) != Node::Leaf {
                continue;
            }
            for k in 0..4 {
                if self.midpoint_present(q, k) {
                    let worst = self.triangle_error(q, 4 + 2 * k).max(self.triangle_error(q, 5 + 2 * k));
                    if worst > e32 && self.may_split(q, e) {
                        self.split(q, &mut work);
                        continue 'next;
                    }
                } else if self.triangle_error(q, k) > e32 && self.may_activate(q, e) {
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
                        Across::Finer => unreachable!("a split neighbour marks the midpoint present"),
                    }
                    continue 'next;
                }
            }
        }
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

    /// The fan triangles of leaf `q` as indices into [`Quad::triangle`].
    pub fn fan_triangles(&self, q: Quad) -> impl Iterator<Item = usize> + '_ {
        (0..4).flat_map(move |k| {
            if self.midpoint_present(q, k) {
                [Some(4 + 2 * k), Some(5 + 2 * k)]
            } else {
                [Some(k), None]
            }
            .into_iter()
            .flatten()
        })
    }
}

/// Visits every lattice point inside triangle `tri` (edges included) with `x <= max_x` and
/// `y <= max_y`, passing its barycentric weights. Integer edge functions: exact inside tests.
pub(crate) fn raster_triangle(
    tri: [(u32, u32); 3],
    max_x: u32,
    max_y: u32,
    mut visit: impl FnMut(u32, u32, [f32; 3]),
) {
    let p: [(i64, i64); 3] = tri.map(|(x, y)| (i64::from(x), i64::from(y)));
    let area = (p[1].0 - p[0].0) * (p[2].1 - p[0].1) - (p[1].1 - p[0].1) * (p[2].0 - p[0].0);
    if area == 0 {
        return;
    }
    let inv = 1.0 / area as f32;
    let x0 = p.iter().map(|v| v.0).min().unwrap_or(0);
    let x1 = p.iter().map(|v| v.0).max().unwrap_or(0).min(i64::from(max_x));
    let y0 = p.iter().map(|v| v.1).min().unwrap_or(0);
    let y1 = p.iter().map(|v| v.1).max().unwrap_or(0).min(i64::from(max_y));
    // Edge function of the edge opposite vertex a, positive on a's side (scaled by `area`'s sign).
    let edge = |a: usize, x: i64, y: i64| {
        let (b, c) = (p[(a + 1) % 3], p[(a + 2) % 3]);
        (c.0 - b.0) * (y - b.1) - (c.1 - b.1) * (x - b.0)
    };
    for y in y0..=y1 {
        for x in x0..=x1 {
            let w = [edge(0, x, y), edge(1, x, y), edge(2, x, y)];
            let inside = if area > 0 {
                w.iter().all(|&v| v >= 0)
            } else {
                w.iter().all(|&v| v <= 0)
            };
            if inside {
                visit(x as u32, y as u32, w.map(|v| v as f32 * inv));
            }
        }
    }
}
