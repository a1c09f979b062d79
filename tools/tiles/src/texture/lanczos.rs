//! Separable Lanczos resampling of RGB images (radius 2, as the paper's mipmap filter).
//!
//! Positions are in the source's index space: texel `i` has its centre at `i`. Each output
//! texel names the source position of its centre and the source texels it spans (`scale`,
//! 1 for magnification or a shift, 2 for a dyadic reduction); the kernel is widened by
//! `scale` so a reduction low-passes before it samples. Taps outside the source repeat its
//! edge texels.

/// Kernel radius in output texels.
pub const RADIUS: f64 = 2.0;

/// An RGB image of `f32` texels in 0..=255, row-major, row 0 north.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub texels: Vec<[f32; 3]>,
}

impl Image {
    pub fn new(width: usize, height: usize) -> Image {
        Image {
            width,
            height,
            texels: vec![[0.0; 3]; width * height],
        }
    }

    pub fn at(&self, x: usize, y: usize) -> [f32; 3] {
        self.texels[y * self.width + x]
    }

    /// The window `x..x+w`, `y..y+h` (which must lie inside).
    pub fn crop(&self, x: usize, y: usize, w: usize, h: usize) -> Image {
        let mut texels = Vec::with_capacity(w * h);
        for row in self.texels.chunks_exact(self.width).skip(y).take(h) {
            texels.extend_from_slice(&row[x..x + w]);
        }
        Image {
            width: w,
            height: h,
            texels,
        }
    }
}

/// `texels` as RGBA bytes into `out` (4 a texel), opaque, each channel rounded ([`byte`]):
/// what the BC1 encoder takes.
pub fn rgba8_into(texels: &[[f32; 3]], out: &mut [u8]) {
    for (o, &[r, g, b]) in out.chunks_exact_mut(4).zip(texels) {
        o.copy_from_slice(&[byte(r), byte(g), byte(b), 255]);
    }
}

/// `c.round().clamp(0.0, 255.0) as u8`, without the library call (`roundf`, or `floor` on
/// the baseline x86-64 target: with the loop around it, 9% of a build): `c + 0.5` is exact
/// in f64, and `as u8` truncates towards zero and saturates, so it is the floor of `c + 0.5`,
/// that is `c` rounded half away from zero, for `-0.5 <= c < 255.5`; below it gives 0, above
/// 255, and NaN 0, as the clamp did.
fn byte(c: f32) -> u8 {
    (f64::from(c) + 0.5) as u8
}

/// `sinc(x) sinc(x / RADIUS)` for `|x| < RADIUS`, else 0.
pub fn kernel(x: f64) -> f64 {
    if x == 0.0 {
        return 1.0;
    }
    // Exactly 0 at the other integers (sin(k pi) is not, in floating point), so sampling on
    // the texel centres copies the texels.
    if x.abs() >= RADIUS || (x - x.round()).abs() < 1e-9 {
        return 0.0;
    }
    let px = std::f64::consts::PI * x;
    RADIUS * px.sin() * (px / RADIUS).sin() / (px * px)
}

/// The source texels one output texel reads and their normalised weights.
#[derive(Clone, Debug)]
struct Taps {
    first: i64,
    weights: Vec<f32>,
}

fn taps(centre: f64, scale: f64) -> Taps {
    let scale = scale.max(1.0);
    let support = RADIUS * scale;
    let first = (centre - support).floor() as i64 + 1;
    let last = (centre + support).ceil() as i64 - 1;
    let mut weights: Vec<f64> = (first..=last)
        .map(|i| kernel((i as f64 - centre) / scale))
        .collect();
    let sum: f64 = weights.iter().sum();
    if sum.abs() < 1e-12 {
        // Cannot happen for these kernels (the centre tap is positive); be safe anyway.
        weights = vec![1.0];
        return Taps {
            first: centre.round() as i64,
            weights: weights.into_iter().map(|w| w as f32).collect(),
        };
    }
    Taps {
        first,
        weights: weights.into_iter().map(|w| (w / sum) as f32).collect(),
    }
}

/// Resamples `src` to `width x height`: output column `i` is centred on source column
/// `x0 + i * step` and spans `step` source columns (rows likewise with `y0`, `ystep`).
pub fn resample(
    src: &Image,
    width: usize,
    height: usize,
    (x0, step): (f64, f64),
    (y0, ystep): (f64, f64),
) -> Image {
    let columns: Vec<Taps> = (0..width)
        .map(|i| taps(x0 + i as f64 * step, step))
        .collect();
    let rows: Vec<Taps> = (0..height)
        .map(|j| taps(y0 + j as f64 * ystep, ystep))
        .collect();
    let clamp_x = |i: i64| i.clamp(0, src.width as i64 - 1) as usize;
    let clamp_y = |j: i64| j.clamp(0, src.height as i64 - 1) as usize;
    // Only the source rows some output row reads are filtered horizontally.
    let row_lo = rows.iter().map(|t| clamp_y(t.first)).min().unwrap_or(0);
    let row_hi = rows
        .iter()
        .map(|t| clamp_y(t.first + t.weights.len() as i64 - 1))
        .max()
        .unwrap_or(0);
    let mut across = Image::new(width, row_hi + 1 - row_lo);
    for y in row_lo..=row_hi {
        let line = &src.texels[y * src.width..(y + 1) * src.width];
        let out = &mut across.texels[(y - row_lo) * width..(y - row_lo + 1) * width];
        for (o, t) in out.iter_mut().zip(&columns) {
            let mut acc = [0.0f32; 3];
            let mut add = |w: f32, s: [f32; 3]| {
                acc[0] += w * s[0];
                acc[1] += w * s[1];
                acc[2] += w * s[2];
            };
            // Taps inside the row (most of them) read it without clamping each index.
            let inside = usize::try_from(t.first)
                .ok()
                .and_then(|first| line.get(first..first + t.weights.len()));
            match inside {
                Some(taps) => t.weights.iter().zip(taps).for_each(|(&w, &s)| add(w, s)),
                None => {
                    for (k, &w) in t.weights.iter().enumerate() {
                        add(w, line[clamp_x(t.first + k as i64)]);
                    }
                }
            }
            *o = acc;
        }
    }
    let mut out = Image::new(width, height);
    for (j, t) in rows.iter().enumerate() {
        // Channels side by side as one run of floats: the same sums, in a loop that
        // vectorises.
        let line = out.texels[j * width..(j + 1) * width].as_flattened_mut();
        for (k, &w) in t.weights.iter().enumerate() {
            let y = clamp_y(t.first + k as i64) - row_lo;
            let source = across.texels[y * width..(y + 1) * width].as_flattened();
            for (o, s) in line.iter_mut().zip(source) {
                *o += w * s;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `byte` is the rounding it replaces, on every f32 from -2 to 258 in steps of 1/1024, at
    /// the halves and their neighbours, and at NaN and the infinities.
    #[test]
    fn bytes_round_as_before() {
        let old = |c: f32| c.round().clamp(0.0, 255.0) as u8;
        let mut values: Vec<f32> = (-2048..=258 * 1024).map(|i| i as f32 / 1024.0).collect();
        for k in -2..=257 {
            let half = k as f32 + 0.5;
            values.extend([
                half,
                f32::from_bits(half.to_bits() - 1),
                f32::from_bits(half.to_bits() + 1),
            ]);
        }
        values.extend([
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -0.0,
            0.499_999_97,
        ]);
        for c in values {
            assert_eq!(byte(c), old(c), "{c:e}");
        }
    }

    fn ramp(w: usize, h: usize) -> Image {
        let mut img = Image::new(w, h);
        for y in 0..h {
            for x in 0..w {
                img.texels[y * w + x] = [x as f32 * 3.0, y as f32 * 5.0, 100.0];
            }
        }
        img
    }

    #[test]
    fn the_kernel_is_one_at_zero_and_zero_at_other_integers() {
        assert_eq!(kernel(0.0), 1.0);
        for i in 1..4 {
            assert!(kernel(i as f64).abs() < 1e-12, "{i}");
            assert!(kernel(-(i as f64)).abs() < 1e-12, "-{i}");
        }
        assert!(kernel(0.5) > 0.5 && kernel(1.5) < 0.0, "the lobes");
    }

    #[test]
    fn resampling_at_the_texel_centres_copies_the_image() {
        let src = ramp(13, 9);
        let out = resample(&src, 13, 9, (0.0, 1.0), (0.0, 1.0));
        assert_eq!(out, src);
        // A window of it, shifted by whole texels.
        let out = resample(&src, 5, 4, (3.0, 1.0), (2.0, 1.0));
        assert_eq!(out, src.crop(3, 2, 5, 4));
    }

    #[test]
    fn a_dyadic_reduction_keeps_a_linear_ramp_and_the_mean() {
        // Inside (away from clamped edges) a linear ramp stays linear: the normalised kernel
        // is symmetric, so it reproduces first-order polynomials exactly.
        let src = ramp(64, 64);
        let out = resample(&src, 32, 32, (0.5, 2.0), (0.5, 2.0));
        for y in 4..28 {
            for x in 4..28 {
                let t = out.at(x, y);
                assert!(
                    (t[0] - (2.0 * x as f32 + 0.5) * 3.0).abs() < 1e-3,
                    "{x},{y}"
                );
                assert!(
                    (t[1] - (2.0 * y as f32 + 0.5) * 5.0).abs() < 1e-3,
                    "{x},{y}"
                );
                assert!((t[2] - 100.0).abs() < 1e-3);
            }
        }
    }

    #[test]
    fn a_reduction_removes_a_pattern_finer_than_the_output_can_hold() {
        // A one-texel checkerboard becomes flat grey under a dyadic reduction (a point sample
        // would keep it at full contrast: aliasing).
        let mut src = Image::new(32, 32);
        for y in 0..32 {
            for x in 0..32 {
                let v = if (x + y) % 2 == 0 { 0.0 } else { 200.0 };
                src.texels[y * 32 + x] = [v; 3];
            }
        }
        let out = resample(&src, 16, 16, (0.5, 2.0), (0.5, 2.0));
        // Away from the edges, where clamping repeats one parity.
        for y in 2..14 {
            for x in 2..14 {
                let t = out.at(x, y);
                assert!((t[0] - 100.0).abs() < 1e-3, "{x},{y}: {t:?}");
            }
        }
    }
}
