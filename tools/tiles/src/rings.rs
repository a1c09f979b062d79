//! The ring order of the index arrays vkterrain builds on the GPU (`spirv/shaders/indices.comp`):
//! the file's fans in the file's order, each ring rotated to start with the run of vertices
//! that lie on the previous fan's cell (consecutive fans are adjacent cells, so those are the
//! vertices a vertex cache has just seen). The builder rotates rings with a model of the cache
//! instead, which needs every earlier fan; this rule needs only the previous one, so each GPU
//! invocation can apply it. Tests compare the GPU's arrays with this index for index; the
//! vertex-cache benchmark measures it.

use crate::format::RESTART_U32;

/// `indices` (the file's array widened, restarts as `None`) with each ring rotated as the GPU
/// rotates it; restarts as [`RESTART_U32`]. `xy` gives a vertex's lattice point. (Where cells
/// past the data's edge lie between two fans on the curve, the GPU may see no previous cell
/// and keep the north-west start; the tests compare real tiles past the data's edge.)
pub fn previous_cell_rings(
    indices: impl Iterator<Item = Option<u32>>,
    xy: impl Fn(u32) -> (u32, u32),
) -> Vec<u32> {
    let all: Vec<Option<u32>> = indices.collect();
    let mut out = Vec::with_capacity(all.len());
    // The previous fan's cell: (lowest corner, highest corner).
    let mut previous: Option<((u32, u32), (u32, u32))> = None;
    for fan in all.split(|i| i.is_none()) {
        let fan: Vec<u32> = fan.iter().flatten().copied().collect();
        let (&centre, closed) = fan.split_first().expect("a fan has a centre");
        let mut ring = closed[..closed.len() - 1].to_vec();
        // The GPU's ring starts at the north-west corner, the smallest x + y.
        let nw = (0..ring.len())
            .min_by_key(|&k| {
                let (x, y) = xy(ring[k]);
                x + y
            })
            .expect("a ring");
        ring.rotate_left(nw);
        if let Some((lo, hi)) = previous {
            let on = |v: u32| {
                let (x, y) = xy(v);
                (lo.0..=hi.0).contains(&x) && (lo.1..=hi.1).contains(&y)
            };
            let m = ring.len();
            if let Some(start) = (0..m).find(|&r| on(ring[r]) && !on(ring[(r + m - 1) % m])) {
                ring.rotate_left(start);
            }
        }
        out.push(centre);
        out.extend(&ring);
        out.push(ring[0]);
        out.push(RESTART_U32);
        let points = ring.iter().map(|&v| xy(v));
        let lo = points
            .clone()
            .fold((u32::MAX, u32::MAX), |a, p| (a.0.min(p.0), a.1.min(p.1)));
        let hi = points.fold((0, 0), |a, p| (a.0.max(p.0), a.1.max(p.1)));
        previous = Some((lo, hi));
    }
    out.pop();
    out
}
