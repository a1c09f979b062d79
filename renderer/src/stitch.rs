//! Stitching (paper, section 5, "Run time processing"): where two visible neighbouring tiles
//! meet, their border vertices generally differ (other levels, or the same level meshed
//! independently), leaving T-junctions. Zero-area triangles between the two border polylines
//! close every one of them. They are built on the CPU from the tiles' duplicated border
//! vertices and drawn through the same pipeline, as one-triangle fans in tile A's frame.
//!
//! Exactness: every grid point on a shared edge decodes to the same height in both tiles (the
//! tile set's shared height lattice), and the vertex shader places a vertex from integer sample
//! coordinates relative to the camera's tile, so a neighbour's vertex re-expressed in A's frame
//! lands on exactly the position the neighbour draws it at. The corner where four tiles meet
//! is a vertex of all four, at the same position, so it needs no extra triangle.
//!
//! Geomorphing: every vertex of a stitch is drawn as its own tile draws it (the shader pulls
//! it with that tile's record, see [`pulled`]). A border vertex's morphed height comes from its
//! tile's coarser levels along that border. In tile sets built with shared sides
//! ([`tiles::format::FLAG_SHARED_SIDES`]) those are the same in both tiles, and so is the
//! vertex's continuous level (it depends on the vertex's position and the camera alone), so both
//! copies of a shared vertex land on the same position, bit for bit, and stitching is as
//! without morphing. In sets built with independent sides the two copies may sit at two
//! heights; stitching with `slivers` then keeps the triangles at shared vertices: vertical
//! slivers in the plane of the edge that close the gap between the two morphed polylines
//! (zero area in plan view, as before).

use tiles::pack::unpack;

use crate::tile::{rebase, Side, TileInfo};

/// Restart index of the stitch index arrays.
pub const RESTART: u32 = u32::MAX;

/// Stitch geometry for one tile: packed vertices in the tile's frame, the same vertices as the
/// shader pulls them, and fan indices into `vertices`.
#[derive(Default, Debug, Clone, PartialEq)]
pub struct Stitch {
    pub vertices: Vec<u32>,
    /// Per vertex: `pulled(record, index)` of the tile it belongs to.
    pub pulled: Vec<u32>,
    pub indices: Vec<u32>,
    pub triangles: u32,
}

/// Bits of a pulled vertex index that hold the vertex's index in its tile (257 x 257 < 2^17).
pub const LOCAL_BITS: u32 = 17;

/// Draw records a frame may have: the record goes in the top bits of a pulled index, which
/// the tile draws set through the (signed) vertexOffset.
pub const MAX_RECORDS: usize = 1 << (31 - LOCAL_BITS);

/// The index the vertex shader decodes: the draw record and the vertex's index in its tile.
pub fn pulled(record: u32, index: u32) -> u32 {
    (record << LOCAL_BITS) | index
}

/// One side of a seam: a drawn tile, its level and its draw record.
#[derive(Clone, Copy)]
pub struct DrawnSide<'a> {
    pub tile: &'a TileInfo,
    pub level: u32,
    pub record: u32,
}

impl Stitch {
    /// The index array as the GPU draws it: each vertex replaced by its pulled index.
    pub fn gpu_indices(&self) -> impl Iterator<Item = u32> + '_ {
        self.indices.iter().map(|&i| {
            if i == RESTART {
                RESTART
            } else {
                self.pulled[i as usize]
            }
        })
    }
}

/// Along-side coordinate of a packed vertex on `side` (N/S: x, E/W: y).
fn along(p: u32, side: Side) -> u32 {
    let (x, y, _) = unpack(p);
    if side.runs_along_x() {
        x
    } else {
        y
    }
}

/// Adds the triangles between tile `a` and its neighbour `b` across `side` of `a`. With
/// `slivers`, vertices both borders share are joined too (see the module header). Returns
/// false if the borders do not line up (a broken file).
pub fn stitch_side(
    out: &mut Stitch,
    a: DrawnSide,
    b: DrawnSide,
    side: Side,
    slivers: bool,
) -> bool {
    // Drawn tiles have passed their checks, so their borders are read.
    let (Some(paged_a), Some(paged_b)) = (a.tile.paged(), b.tile.paged()) else {
        return false;
    };
    let (sides_a, sides_b) = (paged_a.sides(), paged_b.sides());
    let mine = &sides_a.borders[a.level as usize][side.index()];
    let far = side.opposite();
    let theirs: Option<Vec<u32>> = sides_b.borders[b.level as usize][far.index()]
        .iter()
        .map(|&p| rebase(p, side, b.tile, a.tile))
        .collect();
    let Some(theirs) = theirs else { return false };
    if *mine == theirs && !slivers {
        return true;
    }
    if mine.len() < 2
        || theirs.len() < 2
        || mine.first() != theirs.first()
        || mine.last() != theirs.last()
    {
        return false;
    }
    let base = out.vertices.len() as u32;
    out.vertices.extend_from_slice(mine);
    out.vertices.extend_from_slice(&theirs);
    for (drawn, sides, s) in [(a, &sides_a, side), (b, &sides_b, far)] {
        let indices = &sides.border_indices[drawn.level as usize][s.index()];
        out.pulled
            .extend(indices.iter().map(|&i| pulled(drawn.record, i)));
    }
    let all: Vec<u32> = mine.iter().chain(&theirs).copied().collect();
    let at = |line: &[u32]| line.iter().map(|&p| along(p, side)).collect::<Vec<u32>>();
    zip(&at(mine), &at(&theirs), |t| {
        // Two equal vertices make a triangle with no area even in 3D, unless morphing may
        // move the two tiles' copies apart: skip it then.
        if slivers || has_area(t.map(|i| all[i])) {
            let [i, j, l] = t.map(|i| base + i as u32);
            out.indices.extend_from_slice(&[i, j, l, RESTART]);
            out.triangles += 1;
        }
    });
    true
}

/// A triangle of three packed vertices has area (in 3D) unless two of them are the same.
fn has_area(p: [u32; 3]) -> bool {
    p[0] != p[1] && p[1] != p[2] && p[0] != p[2]
}

/// One drawn tile of a seam across layers ([`stitch_across`]): its polyline along the side,
/// as positions along it in the finer layer's samples and heights in metres, and the pulled
/// index of each vertex.
struct Line {
    along: Vec<u32>,
    height: Vec<f32>,
    pulled: Vec<u32>,
}

impl Line {
    /// `drawn`'s side `side` at its level: positions along it times `scale`, plus `offset`.
    fn of(drawn: &DrawnSide, step: f32, side: Side, scale: u32, offset: u32) -> Option<Line> {
        let sides = drawn.tile.paged()?.sides();
        let border = &sides.borders[drawn.level as usize][side.index()];
        let indices = &sides.border_indices[drawn.level as usize][side.index()];
        let base = drawn.tile.header.height_base;
        Some(Line {
            along: border
                .iter()
                .map(|&p| along(p, side) * scale + offset)
                .collect(),
            height: border
                .iter()
                .map(|&p| (base + unpack(p).2 as i32) as f32 * step)
                .collect(),
            pulled: indices.iter().map(|&i| pulled(drawn.record, i)).collect(),
        })
    }

    /// The vertices whose position is in `range`.
    fn within(&self, range: std::ops::RangeInclusive<u32>) -> Line {
        let keep: Vec<usize> = (0..self.along.len())
            .filter(|&k| range.contains(&self.along[k]))
            .collect();
        Line {
            along: keep.iter().map(|&k| self.along[k]).collect(),
            height: keep.iter().map(|&k| self.height[k]).collect(),
            pulled: keep.iter().map(|&k| self.pulled[k]).collect(),
        }
    }

    fn extend(&mut self, other: Line) {
        self.along.extend(other.along);
        self.height.extend(other.height);
        self.pulled.extend(other.pulled);
    }
}

/// Adds the triangles where tile `a` of a pyramid layer meets, across its side `side`, the
/// tiles of the layer below: `children[0]` and `children[1]`, the two halves of `a`'s side in
/// order along it (north or west first), each as drawn or None where it is not. The two
/// halves' polylines, joined, run the length of `a`'s side; a half whose tile is not drawn
/// takes `a`'s own vertices there (its triangles then have no area and are left out). Both
/// lines lie on the side's vertical plane, so the triangles are as zero-area in plan view as
/// [`stitch_side`]'s: where the two layers' heights differ at a shared point (each layer has
/// its own height lattice), they close the gap. `steps` are the two layers' metres per height
/// code (`a`'s, then the children's). With `morphing`, no triangle is left out for two
/// corners at one point with one stored height: the two layers morph their copies apart.
/// Returns false if the borders do not line up.
pub fn stitch_across(
    out: &mut Stitch,
    a: DrawnSide,
    children: [Option<DrawnSide>; 2],
    side: Side,
    (steps, morphing): ((f32, f32), bool),
) -> bool {
    let far = side.opposite();
    let Some(mine) = Line::of(&a, steps.0, side, 2, 0) else {
        return false;
    };
    if mine.along.first() != Some(&0) || mine.along.last() != Some(&512) {
        return false;
    }
    let half = |k: usize| {
        let (lo, hi) = (256 * k as u32, 256 * (k as u32 + 1));
        match &children[k] {
            Some(c) => Line::of(c, steps.1, far, 1, lo)
                .filter(|l| l.along.first() == Some(&lo) && l.along.last() == Some(&hi)),
            // The first half ends, and the second begins, where the other's tile takes over.
            None if k == 0 => Some(mine.within(0..=255)),
            None => Some(mine.within(257..=512)),
        }
    };
    let (Some(mut theirs), Some(second)) = (half(0), half(1)) else {
        return false;
    };
    if children[0].is_some() && children[1].is_some() {
        // Both halves hold the side's midpoint: once.
        theirs.along.pop();
        theirs.height.pop();
        theirs.pulled.pop();
    }
    theirs.extend(second);
    let all_along: Vec<u32> = mine.along.iter().chain(&theirs.along).copied().collect();
    let all_height: Vec<u32> = mine
        .height
        .iter()
        .chain(&theirs.height)
        .map(|h| h.to_bits())
        .collect();
    let base = out.pulled.len() as u32;
    out.pulled.extend(&mine.pulled);
    out.pulled.extend(&theirs.pulled);
    // `vertices` is indexed like `pulled`: the positions along the side stand in for the
    // packed vertices, which two layers do not share.
    out.vertices.extend(&all_along);
    zip(&mine.along, &theirs.along, |t| {
        let same = |i: usize, j: usize| {
            all_along[t[i]] == all_along[t[j]] && all_height[t[i]] == all_height[t[j]]
        };
        if morphing || !(same(0, 1) || same(1, 2) || same(0, 2)) {
            let [i, j, l] = t.map(|i| base + i as u32);
            out.indices.extend_from_slice(&[i, j, l, RESTART]);
            out.triangles += 1;
        }
    });
    true
}

/// Walks two polylines along a side that share their first and last position, given as
/// their vertices' positions along it, `mine` and `theirs`, merging them by position, and
/// emits the triangles between them: each has the next edge of one polyline and the vertex
/// the other has reached. Triangle corners index `mine` then `theirs` (offset by
/// `mine.len()`), wound as tile A draws them.
fn zip(mine: &[u32], theirs: &[u32], mut emit: impl FnMut([usize; 3])) {
    let q0 = mine.len();
    let (mut i, mut j) = (0usize, 0usize);
    while i + 1 < mine.len() || j + 1 < theirs.len() {
        let advance_theirs =
            j + 1 < theirs.len() && (i + 1 >= mine.len() || theirs[j + 1] <= mine[i + 1]);
        if advance_theirs {
            emit([i, q0 + j, q0 + j + 1]);
            j += 1;
        } else {
            emit([i, i + 1, q0 + j]);
            i += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use tiles::pack::pack;

    use super::*;
    use crate::test_rng::Rng;

    /// A border along `side` through the grid points `at` (0 and 256 included), with heights
    /// that differ between the two tiles' copies only where `code` says.
    fn border(side: Side, at: &[u32], code: impl Fn(u32) -> u16) -> Vec<u32> {
        // N: y = 0, E: x = 256, S: y = 256, W: x = 0.
        let fixed = if matches!(side, Side::East | Side::South) {
            256
        } else {
            0
        };
        at.iter()
            .map(|&a| {
                if side.runs_along_x() {
                    pack(a, fixed, code(a))
                } else {
                    pack(fixed, a, code(a))
                }
            })
            .collect()
    }

    /// Random points on a side: 0 and 256 and each other multiple of `step` with chance 1/2.
    fn points(rng: &mut Rng, step: u32) -> Vec<u32> {
        (0..=256 / step)
            .map(|i| i * step)
            .filter(|&a| a == 0 || a == 256 || rng.next() < 0.5)
            .collect()
    }

    /// The zipped triangles between `mine` and `theirs` close the seam: one triangle per
    /// segment of either polyline, each segment in exactly one, each triangle sharing an edge
    /// with the next (one strip, no gap), and the vertices the strip advances to in order
    /// along the side (the two polylines merged, so no triangle folds back over another).
    fn check(mine: &[u32], theirs: &[u32], k: Side, zipped_along: Side) -> Result<(), String> {
        let all: Vec<u32> = mine.iter().chain(theirs).copied().collect();
        let mut triangles = Vec::new();
        let at = |line: &[u32]| {
            line.iter()
                .map(|&p| along(p, zipped_along))
                .collect::<Vec<_>>()
        };
        zip(&at(mine), &at(theirs), |t| triangles.push(t));
        let segments = mine.len() + theirs.len() - 2;
        if triangles.len() != segments {
            return Err(format!(
                "{} triangles, {segments} segments",
                triangles.len()
            ));
        }
        let q0 = mine.len();
        let mut seen = vec![0u32; all.len()];
        let mut reached = 0;
        for (n, t) in triangles.iter().enumerate() {
            // The segment is the two corners on one polyline; the apex is on the other.
            let (edge, apex) = if t[0] < q0 && t[1] < q0 {
                ([t[0], t[1]], t[2])
            } else {
                ([t[1], t[2]], t[0])
            };
            let ok_edge = edge[1] == edge[0] + 1 && (edge[0] < q0) == (edge[1] < q0);
            if !ok_edge || (apex < q0) == (edge[0] < q0) {
                return Err(format!("triangle {n} {t:?} is not a segment and an apex"));
            }
            seen[edge[0]] += 1;
            let to = along(all[edge[1]], k);
            if to < reached {
                return Err(format!(
                    "triangle {n} {t:?} goes back to {to} after {reached}"
                ));
            }
            reached = to;
            if let Some(next) = triangles.get(n + 1) {
                if t.iter().filter(|v| next.contains(v)).count() != 2 {
                    return Err(format!("triangles {n} and {} share no edge", n + 1));
                }
            }
        }
        let once = (0..all.len()).all(|i| i + 1 == q0 || i + 1 == all.len() || seen[i] == 1);
        if !once {
            return Err("a segment is in no triangle or in two".into());
        }
        Ok(())
    }

    #[test]
    fn zipped_triangles_close_every_t_junction_on_every_side() {
        let mut rng = Rng(0x5717_c4ed_9e37_0001);
        for round in 0..400 {
            let k = Side::ALL[round % 4];
            let steps = [1, 2, 4, 8, 16, 32, 64, 128];
            let (sa, sb) = (steps[round % 8], steps[(round / 8) % 8]);
            let (pa, pb) = (points(&mut rng, sa), points(&mut rng, sb));
            let (mine, theirs) = (border(k, &pa, |_| 7), border(k, &pb, |_| 7));
            check(&mine, &theirs, k, k)
                .unwrap_or_else(|e| panic!("side {k:?}, {pa:?} / {pb:?}: {e}"));
        }
    }

    #[test]
    fn walking_along_the_wrong_axis_is_caught() {
        // The negative control: the same borders zipped by the other axis (constant along
        // them) walk all of one polyline before the other, folding back.
        let mut rng = Rng(0xbad_a715);
        let caught = (0..50).filter(|round| {
            let k = Side::ALL[round % 4];
            let (pa, pb) = (points(&mut rng, 8), points(&mut rng, 16));
            let (mine, theirs) = (border(k, &pa, |_| 7), border(k, &pb, |_| 7));
            check(&mine, &theirs, k, Side::ALL[(k.index() + 1) % 4]).is_err()
        });
        assert_eq!(caught.count(), 50);
    }

    #[test]
    fn identical_borders_make_only_triangles_without_area() {
        // Same vertices on both sides: every zipped triangle repeats a vertex, so without
        // slivers none is kept; different heights at a shared grid point (independent sides
        // morphing apart) give triangles with area in 3D, the slivers.
        let pa = [0, 32, 64, 160, 256];
        let mine = border(Side::North, &pa, |_| 5);
        let mut kept = 0;
        let all: Vec<u32> = mine.iter().chain(&mine).copied().collect();
        let at = |line: &[u32]| {
            line.iter()
                .map(|&p| along(p, Side::North))
                .collect::<Vec<_>>()
        };
        zip(&at(&mine), &at(&mine), |t| {
            kept += usize::from(has_area(t.map(|i| all[i])))
        });
        assert_eq!(kept, 0);
        let moved = border(Side::North, &pa, |a| if a == 64 { 6 } else { 5 });
        let all: Vec<u32> = mine.iter().chain(&moved).copied().collect();
        let mut slivers = 0;
        zip(&at(&mine), &at(&moved), |t| {
            slivers += usize::from(has_area(t.map(|i| all[i])))
        });
        assert_eq!(slivers, 2, "the two triangles at the moved vertex");
    }
}
