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
//! vertex's continuous level (it depends on the edge's two shared corners alone), so both
//! copies of a shared vertex land on the same position, bit for bit, and stitching is as
//! without morphing. In sets built with independent sides the two copies may sit at two
//! heights; stitching with `slivers` then keeps the triangles at shared vertices: vertical
//! slivers in the plane of the edge that close the gap between the two morphed polylines
//! (zero area in plan view, as before).

use tiles::pack::{pack, unpack};

use crate::terrain::TileInfo;

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
pub struct Side<'a> {
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
pub(crate) fn rebase(p: u32, k: usize, from: &TileInfo, to: &TileInfo) -> Option<u32> {
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

/// Adds the triangles between tile `a` and its neighbour `b` across side `k` of `a`. With
/// `slivers`, vertices both borders share are joined too (see the module header). Returns
/// false if the borders do not line up (a broken file).
pub fn stitch_side(out: &mut Stitch, a: Side, b: Side, k: usize, slivers: bool) -> bool {
    let mine = &a.tile.borders[a.level as usize][k];
    let far = (k + 2) % 4;
    let theirs: Option<Vec<u32>> = b.tile.borders[b.level as usize][far]
        .iter()
        .map(|&p| rebase(p, k, b.tile, a.tile))
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
    for (side, s) in [(a, k), (b, far)] {
        let indices = &side.tile.border_indices[side.level as usize][s];
        out.pulled
            .extend(indices.iter().map(|&i| pulled(side.record, i)));
    }
    let q0 = base + mine.len() as u32;
    let (mut i, mut j) = (0usize, 0usize);
    let push = |out: &mut Stitch, t: [u32; 3], v: &[u32]| {
        // Two equal vertices make a triangle with no area even in 3D, unless morphing may
        // move the two tiles' copies apart: skip it then.
        let p = t.map(|i| v[(i - base) as usize]);
        if slivers || (p[0] != p[1] && p[1] != p[2] && p[0] != p[2]) {
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
