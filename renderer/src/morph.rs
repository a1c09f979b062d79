//! Geomorphing arithmetic (paper, section 5, figure 6), in plain Rust: the CPU mirror of what
//! the vertex shader will compute, so that tests and the error meter can check it.
//!
//! A tile is given a continuous LOD value `l` at each of its four corners; a vertex at `(x, y)`
//! gets `l(v)` by bilinear interpolation. Its height blends the nested levels' heights `H_k`
//! with the clamped forward differences
//!
//! ```text
//! h = clamp((l, l, ..., l) - (0, 1, ..., n-1), 0, 1)
//! h'_0 = 1 - h_0,   h'_k = h_{k-1} - h_k
//! H(l) = sum_k h'_k H_k
//! ```
//!
//! For a vertex of block `j`, `H_k = height + offset_k * unit_k` for the coarser levels
//! `k < j` (the stored offsets) and `H_k = height` for `k >= j`, so `H(l) = height + sum_{k<j}
//! h'_k offset_k unit_k`: at `l >= j` every `h'_k` with `k < j` is exactly 0 and the vertex sits
//! at its own height, bit for bit.
//!
//! Continuity across tiles: on an edge, the bilinear `l(v)` depends only on the edge's two
//! corner values, and a grid corner's value is one number shared by every tile that touches it
//! ([`corner_levels`]), so both tiles compute the same `l(v)` for a shared edge vertex.

/// Levels the weights cover (the tile format's maximum).
pub const MAX_LEVELS: usize = 9;

/// The basis weights `h'_k` for the continuous level `l`: non-negative, summing to 1, the
/// `k`-th one-hot at integer `l = k`, piecewise linear and continuous in `l`.
pub fn weights(l: f32) -> [f32; MAX_LEVELS] {
    let h: [f32; MAX_LEVELS] = std::array::from_fn(|k| (l - k as f32).clamp(0.0, 1.0));
    std::array::from_fn(|k| if k == 0 { 1.0 - h[0] } else { h[k - 1] - h[k] })
}

/// The morphed height of a vertex of block `offsets.len()` (one stored offset per coarser
/// level) with its own `height`, the tile's morph `units` per level, at continuous level `l`.
pub fn morphed_height(height: f32, offsets: &[i8], units: &[f32], l: f32) -> f32 {
    let w = weights(l);
    let shift: f32 = offsets
        .iter()
        .zip(units)
        .zip(w)
        .map(|((&o, &u), w)| w * (f32::from(o) * u))
        .sum();
    height + shift
}

/// The bilinear `l(v)` at tile-local sample `(x, y)` (0..=256) from the corner values
/// `[north-west, north-east, south-west, south-east]`. On an edge it depends only on that
/// edge's two corners, evaluated the same way from either side.
pub fn vertex_level(corners: [f32; 4], x: u32, y: u32) -> f32 {
    let cells = tiles::mesh::TILE_CELLS as f32;
    let (fx, fy) = (x as f32 / cells, y as f32 / cells);
    // Exact at both ends (t = 0 gives a, t = 1 gives b, bit for bit), so a corner reads the
    // same whichever edge of whichever tile reaches it.
    let lerp = |a: f32, b: f32, t: f32| a * (1.0 - t) + b * t;
    match (y, x) {
        // The edges use their two corners alone (the same expression from both tiles).
        (0, _) => lerp(corners[0], corners[1], fx),
        (256, _) => lerp(corners[2], corners[3], fx),
        (_, 0) => lerp(corners[0], corners[2], fy),
        (_, 256) => lerp(corners[1], corners[3], fy),
        _ => lerp(
            lerp(corners[0], corners[1], fx),
            lerp(corners[2], corners[3], fx),
            fy,
        ),
    }
}

/// The vertices of a tile's blocks `0..=level`, decoded: `(x, y, height)` in index order,
/// each height geomorphed at the vertex's continuous level when `corners` are given (the
/// tile's corner levels), as the vertex shader places it.
pub fn tile_vertices(
    tile: &tiles::format::Tile,
    level: u32,
    corners: Option<[f32; 4]>,
) -> Vec<(u32, u32, f32)> {
    let mut vertices = tile.vertices();
    let blocks = (0..=level).map_while(|j| tile.level(j));
    let end = blocks.clone().map(|b| b.positions.len()).sum::<usize>();
    vertices.truncate(end);
    let Some(corners) = corners else {
        return vertices;
    };
    let units: Vec<f32> = tile.levels().iter().map(|l| l.morph_unit).collect();
    let mut offsets = Vec::with_capacity(MAX_LEVELS);
    let mut start = 0usize;
    for (j, block) in blocks.enumerate() {
        let n = block.positions.len();
        for (i, v) in vertices[start..start + n].iter_mut().enumerate() {
            offsets.clear();
            offsets.extend((0..j).map(|k| block.morph[k * n + i]));
            v.2 = morphed_height(v.2, &offsets, &units, vertex_level(corners, v.0, v.1));
        }
        start += n;
    }
    vertices
}

/// The continuous level at which a tile's error, interpolated linearly between its levels'
/// measured errors `errors` (coarsest first), equals `r` metres: 0 when even level 0 is within
/// `r`, the finest level when none is. Non-increasing in `r`.
pub fn continuous_level(errors: &[f32], r: f64) -> f64 {
    let Some(first) = errors.first() else {
        return 0.0;
    };
    if f64::from(*first) <= r {
        return 0.0;
    }
    for (k, pair) in errors.windows(2).enumerate() {
        let (a, b) = (f64::from(pair[0]), f64::from(pair[1]));
        if b <= r {
            // a > r >= b: the crossing inside [k, k + 1] (a == b cannot happen here).
            return k as f64 + (a - r) / (a - b);
        }
    }
    (errors.len() - 1) as f64
}

/// Corner values of a grid of tiles: each grid corner `(i, j)` (0..=tiles_x, 0..=tiles_y) takes
/// the largest level of the tiles touching it, so every tile's corners are at least its own
/// level and two tiles sharing a corner read the same value. `level(tx, ty)` is a tile's
/// continuous level (None for tiles not considered). Returns the corner grid, row-major.
pub fn corner_levels(
    tiles_x: u32,
    tiles_y: u32,
    level: impl Fn(u32, u32) -> Option<f32>,
) -> Vec<f32> {
    let (w, h) = (tiles_x as usize + 1, tiles_y as usize + 1);
    let mut corners = vec![0.0f32; w * h];
    for ty in 0..tiles_y {
        for tx in 0..tiles_x {
            let Some(l) = level(tx, ty) else { continue };
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let c = &mut corners[(ty + dy) as usize * w + (tx + dx) as usize];
                *c = c.max(l);
            }
        }
    }
    corners
}

/// A tile's four corner values `[NW, NE, SW, SE]` from [`corner_levels`]' grid.
pub fn tile_corners(corners: &[f32], tiles_x: u32, tx: u32, ty: u32) -> [f32; 4] {
    let w = tiles_x as usize + 1;
    let at = |i: u32, j: u32| corners[j as usize * w + i as usize];
    [
        at(tx, ty),
        at(tx + 1, ty),
        at(tx, ty + 1),
        at(tx + 1, ty + 1),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_are_a_partition_of_unity_one_hot_at_integers() {
        for i in 0..=800 {
            let l = i as f32 / 100.0;
            let w = weights(l);
            assert!(w.iter().all(|&x| x >= 0.0), "{l}: {w:?}");
            assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-6, "{l}: {w:?}");
        }
        for d in 0..MAX_LEVELS {
            let w = weights(d as f32);
            for (k, &x) in w.iter().enumerate() {
                assert_eq!(x, if k == d { 1.0 } else { 0.0 }, "l = {d}: {w:?}");
            }
        }
        // Continuous: a small step in l moves every weight by at most that step.
        for i in 0..800 {
            let (a, b) = (weights(i as f32 / 100.0), weights((i + 1) as f32 / 100.0));
            assert!(a.iter().zip(&b).all(|(x, y)| (x - y).abs() <= 0.0101));
        }
    }

    #[test]
    fn a_vertex_sits_at_its_own_height_from_its_level_on_and_at_a_coarser_level_below() {
        let offsets = [37i8, -100, 5, 127];
        let units = [0.8f32, 0.4, 0.2, 0.1];
        let h = 1234.5f32;
        for l in [4.0f32, 4.3, 5.0, 8.0] {
            assert_eq!(
                morphed_height(h, &offsets, &units, l).to_bits(),
                h.to_bits(),
                "{l}"
            );
        }
        for k in 0..4 {
            let want = h + f32::from(offsets[k]) * units[k];
            let got = morphed_height(h, &offsets, &units, k as f32);
            assert!((got - want).abs() <= 1e-3, "level {k}: {got} vs {want}");
        }
        // Half way between levels 1 and 2: the mean of the two heights.
        let mid = morphed_height(h, &offsets, &units, 1.5);
        let (h1, h2) = (h + -100.0 * 0.4, h + 5.0 * 0.2);
        assert!((mid - 0.5 * (h1 + h2)).abs() <= 1e-3, "{mid}");
    }

    /// Two tiles sharing an edge list its corners in different slots (east edge of one, west
    /// edge of the other); a vertex on it gets bit-identical l(v) from both, hence the same
    /// weights and, for equal stored heights, the same morphed height.
    #[test]
    fn shared_edge_vertices_get_bit_identical_levels_from_both_tiles() {
        let mut seed = 0x1234_5678_9abc_def0u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32 * 8.0
        };
        for _ in 0..500 {
            let grid: Vec<f32> = (0..9).map(|_| next()).collect(); // 2 x 2 tiles, 3 x 3 corners
            let west = tile_corners(&grid, 2, 0, 0);
            let east = tile_corners(&grid, 2, 1, 0);
            let south = tile_corners(&grid, 2, 0, 1);
            for t in 0..=256u32 {
                let a = vertex_level(west, 256, t);
                let b = vertex_level(east, 0, t);
                assert_eq!(a.to_bits(), b.to_bits(), "east-west edge at {t}");
                let c = vertex_level(west, t, 256);
                let d = vertex_level(south, t, 0);
                assert_eq!(c.to_bits(), d.to_bits(), "north-south edge at {t}");
            }
        }
    }

    #[test]
    fn corner_values_cover_every_tile_and_are_shared() {
        let levels = [[1.5f32, 3.0, 0.0], [2.2, 0.5, 7.9]];
        let grid = corner_levels(3, 2, |tx, ty| Some(levels[ty as usize][tx as usize]));
        for (ty, row) in levels.iter().enumerate() {
            for (tx, &l) in row.iter().enumerate() {
                let c = tile_corners(&grid, 3, tx as u32, ty as u32);
                assert!(c.iter().all(|&v| v >= l), "tile {tx},{ty}: {c:?} below {l}");
                // Bilinear interpolation of values >= l stays >= l inside the tile.
                for (x, y) in [(0, 0), (128, 77), (256, 256), (3, 250)] {
                    assert!(vertex_level(c, x, y) >= l - 1e-6);
                }
            }
        }
        assert_eq!(
            grid[1], 3.0,
            "the corner between tiles 0,0 and 1,0 takes the larger"
        );
    }

    #[test]
    fn continuous_level_interpolates_the_measured_errors() {
        let errors = [16.0f32, 8.0, 4.0, 2.0, 1.0];
        assert_eq!(continuous_level(&errors, 20.0), 0.0);
        assert_eq!(continuous_level(&errors, 8.0), 1.0);
        assert!((continuous_level(&errors, 6.0) - 1.5).abs() < 1e-12);
        assert_eq!(continuous_level(&errors, 0.5), 4.0);
        let mut last = f64::INFINITY;
        for i in 0..400 {
            let l = continuous_level(&errors, f64::from(i) * 0.05);
            assert!(l <= last, "not monotone at r = {}", f64::from(i) * 0.05);
            last = l;
        }
    }
}
