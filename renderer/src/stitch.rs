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

use tiles::pack::{pack, unpack};

use crate::terrain::TileInfo;

/// Restart index of the stitch index arrays.
pub const RESTART: u32 = u32::MAX;

/// Stitch geometry for one tile: packed vertices in the tile's frame and fan indices.
#[derive(Default, Debug, Clone, PartialEq)]
pub struct Stitch {
    pub vertices: Vec<u32>,
    pub indices: Vec<u32>,
    pub triangles: u32,
}

/// Along-side coordinate of a packed vertex on side `k` (N/S: x, E/W: y).
fn along(p: u32, k: usize) -> u32 {
    let (x, y, _) = unpack(p);
    if k.is_multiple_of(2) {
        x
    } else {
        y
    }
}

/// Moves a neighbour's border vertex into `a`'s frame: the neighbour across side `k`, with the
/// height code re-based onto `a`'s base (same lattice, so the same height).
fn rebase(p: u32, k: usize, from: &TileInfo, to: &TileInfo) -> Option<u32> {
    let (x, y, code) = unpack(p);
    let cells = tiles::mesh::TILE_CELLS as i64;
    let (x, y) = match k {
        0 => (i64::from(x), i64::from(y) - cells),
        1 => (i64::from(x) + cells, i64::from(y)),
        2 => (i64::from(x), i64::from(y) + cells),
        _ => (i64::from(x) - cells, i64::from(y)),
    };
    let code =
        i64::from(code) + i64::from(from.header.height_base) - i64::from(to.header.height_base);
    let ok = (0..=cells).contains(&x) && (0..=cells).contains(&y) && (0..1 << 14).contains(&code);
    ok.then(|| pack(x as u32, y as u32, code as u16))
}

/// Adds the triangles between tile `a` (at `level_a`) and its neighbour `b` across side `k`
/// of `a` (at `level_b`). Returns false if the borders do not line up (a broken file).
pub fn stitch_side(
    out: &mut Stitch,
    a: &TileInfo,
    level_a: u32,
    b: &TileInfo,
    level_b: u32,
    k: usize,
) -> bool {
    let mine = &a.borders[level_a as usize][k];
    let theirs: Option<Vec<u32>> = b.borders[level_b as usize][(k + 2) % 4]
        .iter()
        .map(|&p| rebase(p, k, b, a))
        .collect();
    let Some(theirs) = theirs else { return false };
    if *mine == theirs {
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
    let q0 = base + mine.len() as u32;
    let (mut i, mut j) = (0usize, 0usize);
    let push = |out: &mut Stitch, t: [u32; 3], v: &[u32]| {
        // Two equal vertices make a triangle with no area even in 3D: skip it.
        let p = t.map(|i| v[(i - base) as usize]);
        if p[0] != p[1] && p[1] != p[2] && p[0] != p[2] {
            out.indices.extend_from_slice(&[t[0], t[1], t[2], RESTART]);
            out.triangles += 1;
        }
    };
    let all: Vec<u32> = mine.iter().chain(&theirs).copied().collect();
    while i + 1 < mine.len() || j + 1 < theirs.len() {
        let advance_theirs = j + 1 < theirs.len()
            && (i + 1 >= mine.len() || along(theirs[j + 1], k) <= along(mine[i + 1], k));
        if advance_theirs {
            push(
                out,
                [base + i as u32, q0 + j as u32, q0 + j as u32 + 1],
                &all,
            );
            j += 1;
        } else {
            push(
                out,
                [base + i as u32, base + i as u32 + 1, q0 + j as u32],
                &all,
            );
            i += 1;
        }
    }
    true
}
