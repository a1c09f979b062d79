//! Void filling by push-pull (Gortler et al., "The Lumigraph", 1996, section 3.3): *pull*
//! averages the valid samples of each 2x2 block into a half-size level, up a pyramid until a
//! level has no voids; *push* then fills every void of a level from the bilinearly interpolated
//! level above it. Total work is O(n) (the pyramid is 1/3 of the grid), and because every fill
//! value is a blend of blends, even a void covering half a tile (SRTM N48W125) comes out as a
//! smooth surface meeting the valid data, never a flat plug or a -32768 m pit. Every filled
//! value is a convex combination of valid samples, so fills stay inside the data's range.

/// One level of the pyramid; NaN marks a void.
#[derive(Clone, Debug)]
pub(crate) struct Level {
    pub(crate) width: usize,
    pub(crate) height: usize,
    pub(crate) samples: Vec<f32>,
}

/// Fills every NaN in the `width` x `height` grid `samples` and returns how many there were.
/// Returns `None`, leaving the grid as it was, when every sample is NaN.
pub fn fill_voids(samples: &mut [f32], width: usize, height: usize) -> Option<u64> {
    debug_assert_eq!(samples.len(), width * height);
    let voids = samples.iter().filter(|v| v.is_nan()).count() as u64;
    if voids == 0 {
        return Some(0);
    }
    if voids == samples.len() as u64 {
        return None;
    }

    pull_push(samples, width, height);
    Some(voids)
}

/// The push-pull of a `width` x `height` level with voids and at least one valid sample:
/// pulls coarser levels until one has no void, then pushes them down, filling every void of
/// each and of `samples`. Returns the coarser levels, filled, from the one just above up.
pub(crate) fn pull_push(samples: &mut [f32], width: usize, height: usize) -> Vec<Level> {
    // Pull: coarser levels until one has no voids. With at least one valid sample the 1x1
    // level is valid, so this ends.
    let mut pyramid: Vec<Level> = Vec::new();
    loop {
        let (fine, fw, fh) = match pyramid.last() {
            Some(l) => (&l.samples[..], l.width, l.height),
            None => (&samples[..], width, height),
        };
        let coarse = pull(fine, fw, fh);
        let done = !coarse.samples.iter().any(|v| v.is_nan());
        pyramid.push(coarse);
        if done {
            break;
        }
    }

    // Push: from the top (void-free) level down, fill each level's voids from the one above.
    for i in (1..pyramid.len()).rev() {
        let (lower, upper) = pyramid.split_at_mut(i);
        let fine = &mut lower[i - 1];
        push(&mut fine.samples, fine.width, fine.height, &upper[0]);
    }
    push(samples, width, height, &pyramid[0]);
    pyramid
}

/// Half-size level: each sample is the mean of the valid samples of its (up to) 2x2 block,
/// NaN if the block has none.
pub(crate) fn pull(fine: &[f32], width: usize, height: usize) -> Level {
    let cw = width.div_ceil(2);
    let ch = height.div_ceil(2);
    let mut samples = Vec::with_capacity(cw * ch);
    for cy in 0..ch {
        let y0 = 2 * cy;
        let y1 = (y0 + 1).min(height - 1);
        let row0 = &fine[y0 * width..(y0 + 1) * width];
        let row1 = &fine[y1 * width..(y1 + 1) * width];
        for cx in 0..cw {
            let x0 = 2 * cx;
            let x1 = (x0 + 1).min(width - 1);
            // Clamped duplicates on odd edges just count a sample twice; the mean is unchanged
            // in kind (still a convex combination of valid samples).
            let mut sum = 0.0f32;
            let mut n = 0u32;
            let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
            for v in [row0[x0], row0[x1], row1[x0], row1[x1]] {
                if !v.is_nan() {
                    sum += v;
                    n += 1;
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
            // Clamp away rounding: a mean stays within the samples it averages.
            samples.push(if n == 0 {
                f32::NAN
            } else {
                (sum / n as f32).clamp(lo, hi)
            });
        }
    }
    Level {
        width: cw,
        height: ch,
        samples,
    }
}

/// Where a fine row/column sits in the coarse level: the two coarse neighbours and the weight
/// of the second. Fine sample `i` has its centre at `i + 0.5`; coarse sample `j` covers fine
/// `2j..2j+2`, centre `2j + 1`; so in coarse index space the fine centre is at `(i - 0.5) / 2`.
fn taps(fine_len: usize, coarse_len: usize) -> Vec<(usize, usize, f32)> {
    (0..fine_len).map(|i| tap(i, coarse_len)).collect()
}

/// [`taps`] of fine row or column `i` alone.
pub(crate) fn tap(i: usize, coarse_len: usize) -> (usize, usize, f32) {
    let c = ((i as f32 - 0.5) * 0.5).clamp(0.0, (coarse_len - 1) as f32);
    let j0 = c.floor() as usize;
    let j1 = (j0 + 1).min(coarse_len - 1);
    (j0, j1, c - j0 as f32)
}

/// Fills the voids of `fine` by bilinear interpolation of the void-free `coarse` level.
fn push(fine: &mut [f32], width: usize, height: usize, coarse: &Level) {
    push_rows(fine, width, (0, height), coarse, 0);
}

/// [`push`] for rows `first..first + n` of a level `height` rows high (`rows` = `(first,
/// height)`), held in `fine`, from rows `coarse_first..` of the coarser level held in
/// `coarse` (whose `height` is the whole level's): the same taps and arithmetic, so the same
/// bits as pushing the whole level.
pub(crate) fn push_rows(
    fine: &mut [f32],
    width: usize,
    (first, height): (usize, usize),
    coarse: &Level,
    coarse_first: usize,
) {
    let xs = taps(width, coarse.width);
    let cw = coarse.width;
    for (k, row) in fine.chunks_exact_mut(width).enumerate() {
        if !row.iter().any(|v| v.is_nan()) {
            continue;
        }
        debug_assert!(first + k < height);
        let (y0, y1, ty) = tap(first + k, coarse.height);
        let (y0, y1) = (y0 - coarse_first, y1 - coarse_first);
        let r0 = &coarse.samples[y0 * cw..(y0 + 1) * cw];
        let r1 = &coarse.samples[y1 * cw..(y1 + 1) * cw];
        for (v, &(x0, x1, tx)) in row.iter_mut().zip(&xs) {
            if v.is_nan() {
                let (a, b, c, d) = (r0[x0], r0[x1], r1[x0], r1[x1]);
                let top = a + (b - a) * tx;
                let bottom = c + (d - c) * tx;
                // Clamp away rounding so a fill never exceeds its taps (keeps min/max exact).
                let lo = a.min(b).min(c.min(d));
                let hi = a.max(b).max(c.max(d));
                *v = (top + (bottom - top) * ty).clamp(lo, hi);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nothing_to_fill() {
        let mut g = vec![1.0, 2.0, 3.0, 4.0];
        assert_eq!(fill_voids(&mut g, 2, 2), Some(0));
        assert_eq!(g, vec![1.0, 2.0, 3.0, 4.0]);
    }

    #[test]
    fn all_void_is_refused() {
        let mut g = vec![f32::NAN; 6];
        assert_eq!(fill_voids(&mut g, 3, 2), None);
    }

    #[test]
    fn one_valid_sample_fills_everything() {
        let mut g = vec![f32::NAN; 7 * 5];
        g[17] = 42.0;
        assert_eq!(fill_voids(&mut g, 7, 5), Some(34));
        assert!(g.iter().all(|&v| v == 42.0));
    }

    #[test]
    fn constant_stays_constant_and_valid_samples_are_kept() {
        let (w, h) = (33, 17);
        let mut g: Vec<f32> = (0..w * h)
            .map(|i| {
                if i % 3 == 0 || (i / w > 5 && i / w < 12) {
                    f32::NAN
                } else {
                    7.5
                }
            })
            .collect();
        let voids = g.iter().filter(|v| v.is_nan()).count() as u64;
        assert_eq!(fill_voids(&mut g, w, h), Some(voids));
        assert!(g.iter().all(|&v| v == 7.5), "{g:?}");
    }

    #[test]
    fn fills_stay_in_range_and_are_smooth() {
        // A tilted plane with a big void in the middle and voids along one edge: fills must stay
        // within the valid range, follow the plane roughly, and have no jumps.
        let (w, h) = (129, 97);
        let plane = |x: usize, y: usize| 100.0 + 2.0 * x as f32 - 1.0 * y as f32;
        let mut g = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let hole = (30..90).contains(&x) && (20..70).contains(&y);
                let edge = y < 3;
                g.push(if hole || edge { f32::NAN } else { plane(x, y) });
            }
        }
        let (lo, hi) = g
            .iter()
            .filter(|v| !v.is_nan())
            .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        let orig = g.clone();
        fill_voids(&mut g, w, h).unwrap();
        for y in 0..h {
            for x in 0..w {
                let v = g[y * w + x];
                assert!(v.is_finite() && v >= lo && v <= hi);
                if !orig[y * w + x].is_nan() {
                    assert_eq!(v, orig[y * w + x]);
                } else {
                    // Push-pull biases a fill toward the valid side, but stays near the plane.
                    assert!((v - plane(x, y)).abs() < 40.0, "{x},{y}: {v}");
                }
                if x > 0 {
                    // The plane rises 2 per column: a smooth fill never jumps much more.
                    assert!((v - g[y * w + x - 1]).abs() < 8.0, "{x},{y}");
                }
            }
        }
    }

    #[test]
    fn thin_grids() {
        let mut g = vec![f32::NAN, 1.0, f32::NAN, f32::NAN, 3.0];
        assert_eq!(fill_voids(&mut g, 5, 1), Some(3));
        assert!(g.iter().all(|v| (1.0..=3.0).contains(v)));
        let mut g = vec![f32::NAN, 1.0, f32::NAN];
        assert_eq!(fill_voids(&mut g, 1, 3), Some(2));
        assert_eq!(g, vec![1.0, 1.0, 1.0]);
    }
}
