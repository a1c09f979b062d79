//! Height quantisation: 14 bits per vertex, per tile.
//!
//! A tile's heights are stored as `q` in `0..=16383` with `height = min + q * step`, where
//! `min` and `step = (max - min) / 16383` come from the tile's own samples, so the rounding
//! error is at most `step / 2` (0.12 m for a tile spanning 4 km of relief). The mesher measures
//! every error bound against these quantised heights, never against the exact ones, so the
//! quantisation counts toward `e_i` and the stored figure is what the GPU will draw.

/// Largest quantised height (14 bits).
pub const HEIGHT_MAX_CODE: u16 = (1 << 14) - 1;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quantiser {
    pub min: f32,
    pub step: f32,
}

impl Quantiser {
    /// The quantiser that spans `min..=max` with 14 bits.
    pub fn spanning(min: f32, max: f32) -> Self {
        let range = max - min;
        // A flat tile still needs a positive step so heights decode to `min`.
        let step = if range > 0.0 {
            range / f32::from(HEIGHT_MAX_CODE)
        } else {
            1.0
        };
        Quantiser { min, step }
    }

    pub fn quantise(&self, h: f32) -> u16 {
        let q = ((h - self.min) / self.step).round();
        q.clamp(0.0, f32::from(HEIGHT_MAX_CODE)) as u16
    }

    /// The stored height of code `q`. The renderer's vertex shader computes the same expression.
    pub fn height(&self, q: u16) -> f32 {
        self.min + f32::from(q) * self.step
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_error_is_at_most_half_a_step() {
        let q = Quantiser::spanning(-13.0, 4371.0);
        let mut worst = 0.0f32;
        for i in 0..100_000 {
            let h = -13.0 + 4384.0 * (i as f32 / 99_999.0);
            worst = worst.max((q.height(q.quantise(h)) - h).abs());
        }
        assert!(
            worst <= q.step * 0.5 + 1e-3,
            "worst {worst}, step {}",
            q.step
        );
        assert_eq!(q.quantise(4371.0), HEIGHT_MAX_CODE);
        assert_eq!(q.quantise(-13.0), 0);
    }

    #[test]
    fn flat_tile_decodes_to_its_height() {
        let q = Quantiser::spanning(12.5, 12.5);
        assert_eq!(q.height(q.quantise(12.5)), 12.5);
    }
}
