//! The previous per-vertex rule, `--morph-shader two-levels` (module header of
//! [`crate::morph`], "Where the levels agree"): each vertex blends the stored surfaces of the
//! two levels around its own level, as the vertex shader computes it, and the paper's clamped
//! forward differences it equals.

use super::MAX_LEVELS;

/// The blend weights `h'_k` for the continuous level `l` (the paper's clamped forward
/// differences): non-negative, summing to 1, one-hot at integer `l`, piecewise linear.
pub fn weights(l: f32) -> [f32; MAX_LEVELS] {
    let h: [f32; MAX_LEVELS] = std::array::from_fn(|k| (l - k as f32).clamp(0.0, 1.0));
    std::array::from_fn(|k| if k == 0 { 1.0 - h[0] } else { h[k - 1] - h[k] })
}

/// The morphed height of a vertex of block `offsets.len()` (one stored offset per coarser
/// level) with its own height `own`, the tile's morph `units` per level, at level `l`, as the
/// vertex shader computes it: only the two levels around `l` are read (`k = floor(l)` and
/// `k + 1`, clamped below the vertex's block), and from its own block on the vertex is at its
/// own height, bit for bit.
pub fn morphed_height(own: f32, offsets: &[i8], units: &[f32], l: f32) -> f32 {
    let j = offsets.len();
    if j == 0 {
        return own;
    }
    let k = ((l.max(0.0)) as usize).min(j - 1);
    let t = (l - k as f32).clamp(0.0, 1.0);
    let unit = |k: usize| units.get(k).copied().unwrap_or(0.0);
    let lower = f32::from(offsets[k]) * unit(k);
    let upper = if k + 1 < j {
        f32::from(offsets[k + 1]) * unit(k + 1)
    } else {
        0.0
    };
    own + (lower * (1.0 - t) + upper * t)
}

/// How fast [`morphed_height`] changes with the level near `l` (metres per level, the larger
/// of the two pieces around `l`): what a small difference in the level costs in height, for the
/// read-back check's tolerance.
pub fn height_slope(offsets: &[i8], units: &[f32], l: f32) -> f32 {
    let d = |m: usize| {
        if m < offsets.len() {
            f32::from(offsets[m]) * units.get(m).copied().unwrap_or(0.0)
        } else {
            0.0
        }
    };
    let k = l.max(0.0) as usize;
    let right = (d(k) - d(k + 1)).abs();
    let left = if k > 0 { (d(k - 1) - d(k)).abs() } else { 0.0 };
    right.max(left)
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
    }

    /// The two-level blend is the forward differences' dot product (the paper's formula), to
    /// rounding, at every level; from the vertex's own block on it is its own height, bit for
    /// bit; at integer levels below, the stored coarser height.
    #[test]
    fn two_levels_equal_the_forward_differences() {
        let offsets = [37i8, -100, 5, 127];
        let units = [0.8f32, 0.4, 0.2, 0.1];
        let h = 1234.5f32;
        for i in 0..=800 {
            let l = i as f32 / 100.0;
            let w = weights(l);
            let fd: f32 = (0..4)
                .map(|k| w[k] * f32::from(offsets[k]) * units[k])
                .sum();
            let two = morphed_height(h, &offsets, &units, l);
            assert!(
                (two - (h + fd)).abs() <= 1e-3,
                "l = {l}: {two} vs {}",
                h + fd
            );
        }
        for l in [4.0f32, 4.3, 5.0, 8.0] {
            let got = morphed_height(h, &offsets, &units, l);
            assert_eq!(got.to_bits(), h.to_bits(), "{l}");
        }
        for k in 0..4 {
            let want = h + f32::from(offsets[k]) * units[k];
            let got = morphed_height(h, &offsets, &units, k as f32);
            assert!((got - want).abs() <= 1e-3, "level {k}: {got} vs {want}");
        }
    }
}
