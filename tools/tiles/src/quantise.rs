//! Height quantisation: 14 bits per vertex, on one height lattice for the whole tile set.
//!
//! Every height is stored as `q` in `0..=16383` and decodes as `(base + q) * step`, where
//! `step` is one number for the whole tile set and `base` an integer per tile (its lowest
//! height in steps). Because the lattice is shared, a sample on the edge between two tiles
//! decodes to the *same* f32 in both (the integer `base + q` is the same, and so is the
//! product): the tiles' duplicated border vertices match bit for bit, which is what crack-free
//! stitching needs. `step` is the largest height range of any one tile divided by 16382 (one
//! code of slack for aligning `base`), so rounding moves a height by at most `step / 2` (0.12 m
//! when the roughest tile spans 4 km). The mesher measures every error bound against these
//! quantised heights, so quantisation counts toward `e_i` and the stored figure is what the
//! GPU will draw.

/// Largest quantised height (14 bits).
pub const HEIGHT_MAX_CODE: u16 = (1 << 14) - 1;

/// The tile set's height lattice step for tiles whose largest height range is `max_range`
/// metres and whose largest absolute height is `max_abs`. The step stays large enough that
/// `base + q` is exact in an f32 (below 2^23), so decoding is exact integer arithmetic plus
/// one rounding.
pub fn lattice_step(max_range: f32, max_abs: f32) -> f32 {
    let step = (max_range / f32::from(HEIGHT_MAX_CODE - 1)).max(max_abs / (1 << 23) as f32);
    if step > 0.0 && step.is_finite() {
        // The next power of two up keeps base * step exact for any base.
        2f32.powi(step.log2().ceil() as i32)
    } else {
        1.0
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quantiser {
    /// The tile's lowest code on the shared lattice.
    pub base: i32,
    /// The tile set's step, metres.
    pub step: f32,
}

impl Quantiser {
    /// The quantiser of a tile whose heights start at `min`, on the lattice of `step`.
    pub fn for_tile(min: f32, step: f32) -> Self {
        Quantiser {
            base: (f64::from(min) / f64::from(step)).floor() as i32,
            step,
        }
    }

    pub fn quantise(&self, h: f32) -> u16 {
        let code = round(f64::from(h) / f64::from(self.step)) - f64::from(self.base);
        code.clamp(0.0, f64::from(HEIGHT_MAX_CODE)) as u16
    }

    /// The stored height of code `q`. The renderer's vertex shader computes the same
    /// expression: `float(base + q) * step`.
    pub fn height(&self, q: u16) -> f32 {
        (self.base + i32::from(q)) as f32 * self.step
    }

    /// The lowest height the tile can represent.
    pub fn min(&self) -> f32 {
        self.height(0)
    }
}

/// `v.round()` (halves away from zero) without the library call that the baseline x86-64
/// target makes of it (no `roundsd` before SSE4.1): the truncation is one instruction, and
/// `v - trunc(v)` is exact. Past 2^52 every float is an integer already.
#[inline]
pub(crate) fn round(v: f64) -> f64 {
    if v.is_nan() || v.abs() >= (1u64 << 52) as f64 {
        return v.round();
    }
    let t = v as i64 as f64;
    let frac = v - t;
    // The sign of a zero result is the value's, as the library's.
    (t + f64::from(u8::from(frac >= 0.5)) - f64::from(u8::from(frac <= -0.5))).copysign(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rounding is `f64::round`, bit for bit: halves, their neighbours, negatives, zeros,
    /// large and non-finite values.
    #[test]
    fn rounding_is_the_librarys() {
        let mut values = vec![
            0.0,
            -0.0,
            f64::NAN,
            f64::INFINITY,
            -f64::INFINITY,
            4.5e15,
            -9e18,
        ];
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        for i in -2000..2000 {
            let half = f64::from(i) + 0.5;
            values.extend([half, half.next_up(), half.next_down(), f64::from(i)]);
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            values.push((x >> 11) as f64 / (1u64 << 30) as f64 - 4096.0);
        }
        for v in values {
            assert_eq!(round(v).to_bits(), v.round().to_bits(), "{v}");
        }
    }

    #[test]
    fn round_trip_error_is_at_most_half_a_step() {
        let step = lattice_step(4384.0, 4371.0);
        assert!(
            (4384.0 / 16382.0..2.0 * 4384.0 / 16382.0).contains(&step),
            "{step}"
        );
        let q = Quantiser::for_tile(-13.0, step);
        let mut worst = 0.0f32;
        for i in 0..100_000 {
            let h = -13.0 + 4384.0 * (i as f32 / 99_999.0);
            let code = q.quantise(h);
            assert!(code < HEIGHT_MAX_CODE || h > 4370.0);
            worst = worst.max((q.height(code) - h).abs());
        }
        assert!(worst <= step * 0.5 + 1e-4, "worst {worst}, step {step}");
    }

    #[test]
    fn neighbouring_tiles_decode_shared_heights_identically() {
        let step = lattice_step(1000.0, 3000.0);
        let (a, b) = (
            Quantiser::for_tile(1500.3, step),
            Quantiser::for_tile(1890.2, step),
        );
        for h in [1890.2f32, 2000.0, 2111.11, 2400.5] {
            assert_eq!(
                a.height(a.quantise(h)).to_bits(),
                b.height(b.quantise(h)).to_bits(),
                "{h}"
            );
        }
    }

    #[test]
    fn flat_data_decodes_to_its_height() {
        let step = lattice_step(0.0, 12.5);
        let q = Quantiser::for_tile(12.5, step);
        assert!((q.height(q.quantise(12.5)) - 12.5).abs() <= step / 2.0);
    }
}
