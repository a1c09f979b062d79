//! Vertex packing: one vertex in 32 bits, plus one morph byte per coarser level.
//!
//! `packed = x | y << 9 | q << 18`: x and y are the vertex's column and row inside its tile
//! (0..=256, 9 bits each) and q its quantised height (14 bits, see [`crate::quantise`]). On the
//! GPU the word is read as two 16-bit components (`R16G16_UINT`, low half first) and recombined
//! as `lo | hi << 16`, as the paper stores "all three values in two 16 bit vertex attribute
//! components".
//!
//! Morph offsets (for geomorphing): a vertex introduced at level `j` is not part of the coarser
//! meshes `k < j`, so for each of them it stores where that mesh's surface lies at its position:
//! `height_on_k = height + offset_k * unit_k`, with `offset_k` an `i8` and `unit_k` the
//! `morph_unit` of level `k`'s [`LevelEntry`](crate::format::LevelEntry). The unit is
//! `max(b_k, d_k) / 127`, where `d_k` is the largest distance of any finer vertex from level
//! `k`'s surface, measured by the builder, and `b_k` (with shared sides) a bound on it from
//! the input's scan ([`crate::units`]: `e_k` plus two lattice steps, or where the spacing rule
//! stops refinement the heights' range over the cells it leaves), so that every shard of a
//! distributed build finds the same unit; every offset fits in `-127..=127`. The offset's own
//! rounding (half a unit) only touches heights mid-morph under the rules that read the
//! offsets, never the stored level meshes, whose error is measured exactly.

pub const COORD_BITS: u32 = 9;
pub const HEIGHT_BITS: u32 = 14;

pub fn pack(x: u32, y: u32, q: u16) -> u32 {
    debug_assert!(x < 1 << COORD_BITS && y < 1 << COORD_BITS && u32::from(q) < 1 << HEIGHT_BITS);
    x | y << COORD_BITS | u32::from(q) << (2 * COORD_BITS)
}

pub fn unpack(p: u32) -> (u32, u32, u16) {
    let mask = (1 << COORD_BITS) - 1;
    (
        p & mask,
        (p >> COORD_BITS) & mask,
        (p >> (2 * COORD_BITS)) as u16,
    )
}

/// The morph unit of a level (metres per offset step): `max_deviation` is the largest
/// distance of a finer vertex from the level's surface.
pub fn morph_unit(error_bound: f64, max_deviation: f64) -> f64 {
    error_bound.max(max_deviation) / 127.0
}

/// The morph offset that moves a vertex of height `h` to `target`.
pub fn morph_offset(h: f32, target: f32, unit: f64) -> i8 {
    crate::quantise::round((f64::from(target) - f64::from(h)) / unit).clamp(-127.0, 127.0) as i8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pack_round_trips_the_extremes() {
        for (x, y, q) in [(0, 0, 0), (256, 256, 16383), (256, 0, 1), (3, 255, 8191)] {
            assert_eq!(unpack(pack(x, y, q)), (x, y, q));
        }
    }

    #[test]
    fn offsets_within_the_unit_range_round_trip() {
        let unit = morph_unit(4.0, 3.2);
        assert!((unit - 4.0 / 127.0).abs() < 1e-12);
        let o = morph_offset(100.0, 103.9, unit);
        assert!((f64::from(o) * unit - 3.9).abs() <= unit / 2.0 + 1e-9);
        // A level that exceeded its bound widens its unit, so its offsets still fit.
        let wide = morph_unit(4.0, 9.0);
        assert_eq!(morph_offset(0.0, -9.1, wide), -127);
    }
}
