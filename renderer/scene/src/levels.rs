//! Level tables: the errors per level a geomorphing vertex takes its level from
//! (the renderer's `morph` module, "The error of a blend, and `Λ`"), and the coefficients of `Λ`, the inverse
//! of their linear blend, as the vertex shader evaluates it.
//!
//! A tile's own table is its levels' measured errors (plus half a morph unit where the morph
//! reads the stored offsets, [`crate::terrain::Terrain::read_stored_offsets`]). A vertex on a side
//! takes the larger errors of the two tiles there, a corner those of the tiles around it
//! ([`crate::tile::TileInfo::tables`]): every tile holding a vertex gives it one table, and a
//! tile is drawn at the finest level any of its tables asks for where that table's part of the
//! tile is on screen. Errors are made to fall by at least
//! [`MIN_RATIO`] a level: where the spacing rule left a level's error above the next coarser
//! one's, the coarser is taken as worse than it is rather than `Λ` jumping across two levels at
//! once (a jump in a vertex's level is a pop).
//!
//! ```
//! use scene::levels::LevelTable;
//! let t = LevelTable::new(&[16.0, 8.0, 4.0, 2.0, 1.0]);
//! assert_eq!(t.level(20.0), 0.0);
//! assert!((t.level(6.0) - 1.5).abs() < 1e-5);
//! assert_eq!(t.level(0.5), 4.0);
//! ```

/// Levels a tile has at most (the tile format's maximum).
pub const MAX_LEVELS: usize = 9;

/// The least ratio of a level's error to the next finer level's in a table.
pub const MIN_RATIO: f32 = 1.25;

/// Errors per level (`E_k`) and the coefficients of `Λ(r) = Σ_k clamp(a_k - r b_k, 0, 1)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LevelTable {
    /// Coarsest first; falling by at least [`MIN_RATIO`] a level over the table's levels.
    pub errors: [f32; MAX_LEVELS],
    /// How many levels the table has.
    pub levels: usize,
    pub a: [f32; MAX_LEVELS - 1],
    pub b: [f32; MAX_LEVELS - 1],
}

impl LevelTable {
    /// The table for per-level errors `errors` (coarsest first, at most [`MAX_LEVELS`]): from
    /// the finest up, each level's error is at least [`MIN_RATIO`] times the next finer one's
    /// (never below its own), so the table falls strictly and `Λ` is continuous with a bounded
    /// slope.
    pub fn new(errors: &[f32]) -> LevelTable {
        LevelTable::over(errors, errors.len())
    }

    /// The table of a tile whose levels from `distinct` on add no vertex: copies of level
    /// `distinct - 1`'s surface (see `distinct_levels` in [`crate::terrain`]). `Λ` runs over
    /// the first `distinct` levels, which fall as in [`Self::new`]; the copies' errors are kept
    /// as given, for [`Self::max`].
    pub fn over(errors: &[f32], distinct: usize) -> LevelTable {
        let all = errors.len().clamp(1, MAX_LEVELS);
        let n = distinct.clamp(1, all);
        let own = |k: usize| match errors.get(k) {
            Some(x) if x.is_finite() => x.max(0.0),
            _ => f32::MAX / 4.0,
        };
        let mut e = [0.0f32; MAX_LEVELS];
        for (k, e) in e.iter_mut().enumerate().take(all).skip(n) {
            *e = own(k);
        }
        let mut below = 0.0f32;
        for k in (0..n).rev() {
            e[k] = if k == n - 1 {
                own(k).max(1e-6)
            } else {
                own(k).max(below * MIN_RATIO)
            };
            below = e[k];
        }
        let (mut a, mut b) = ([0.0f32; MAX_LEVELS - 1], [0.0f32; MAX_LEVELS - 1]);
        for k in 0..n - 1 {
            b[k] = 1.0 / (e[k] - e[k + 1]);
            a[k] = e[k] * b[k];
        }
        LevelTable {
            errors: e,
            levels: n,
            a,
            b,
        }
    }

    /// The table of the larger error at every level of `self` and `other`, over the levels of
    /// the longer: beyond a table's own levels, its copies' errors (the surface it draws there;
    /// with copies in neither table at a level, as two tables of that many levels were before
    /// copies were told apart).
    pub fn max(&self, other: &LevelTable) -> LevelTable {
        // A table at least the other's at every level, over at least as many levels, is the
        // answer as it stands (`over` of a table's own errors is the table, bit for bit): most
        // neighbours, at a set's open.
        let covers = |a: &LevelTable, b: &LevelTable| {
            a.levels >= b.levels && a.errors.iter().zip(&b.errors).all(|(x, y)| x >= y)
        };
        if covers(self, other) {
            return *self;
        }
        if covers(other, self) {
            return *other;
        }
        self.merged(other)
    }

    /// [`LevelTable::max`] without its quick answer: the table over the larger errors.
    fn merged(&self, other: &LevelTable) -> LevelTable {
        let errors: [f32; MAX_LEVELS] =
            std::array::from_fn(|k| self.errors[k].max(other.errors[k]));
        LevelTable::over(&errors, self.levels.max(other.levels))
    }

    /// `Λ(r)`, in f32 as the vertex shader evaluates it.
    pub fn level(&self, r: f32) -> f32 {
        self.a
            .iter()
            .zip(&self.b)
            .map(|(&a, &b)| (a - r * b).clamp(0.0, 1.0))
            .sum()
    }

    /// `Λ(r)` in f64, for the CPU's own decisions (not the shader's mirror).
    pub fn level_f64(&self, r: f64) -> f64 {
        self.a
            .iter()
            .zip(&self.b)
            .map(|(&a, &b)| (f64::from(a) - r * f64::from(b)).clamp(0.0, 1.0))
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `Λ` inverts the linear blend of the errors: `E(Λ(r)) = r` inside the table's range, 0
    /// above it, the finest level below it; continuous and non-increasing in `r`.
    #[test]
    fn the_level_inverts_the_linear_blend_of_the_errors() {
        let table = LevelTable::new(&[16.0, 8.0, 4.0, 2.0, 1.0]);
        let e = |l: f64| {
            let k = (l.floor() as usize).min(3);
            let t = l - k as f64;
            (1.0 - t) * f64::from(table.errors[k]) + t * f64::from(table.errors[k + 1])
        };
        assert_eq!(table.level(20.0), 0.0);
        assert_eq!(table.level(0.5), 4.0);
        let mut last = f32::INFINITY;
        for i in 1..400 {
            let r = f64::from(i) * 0.04 + 1.0;
            if r >= 16.0 {
                break;
            }
            let l = table.level_f64(r);
            assert!((e(l) - r).abs() < 1e-6 * r, "r = {r}: E(Λ) = {}", e(l));
            let l32 = table.level(r as f32);
            assert!(l32 <= last + 1e-6, "not monotone at {r}");
            assert!((f64::from(l32) - l).abs() < 1e-4, "f32 {l32} vs f64 {l}");
            last = l32;
        }
    }

    /// A tile whose last levels add nothing (copies, errors about the last real level's): its
    /// `Λ` ends at its last real level, which keeps its own error, where a table over all its
    /// levels (the control) inflates it by the least ratio per copy. Where it shares a side with
    /// a tile of more levels, the shared table holds the copies' errors at the finer levels.
    #[test]
    fn a_table_ends_at_the_last_level_that_adds_vertices() {
        let errors = [64.0, 32.0, 20.0, 19.5, 19.25];
        let short = LevelTable::over(&errors, 3);
        assert_eq!((short.levels, short.errors[2]), (3, 20.0), "{short:?}");
        assert_eq!(short.level(10.0), 2.0);
        let control = LevelTable::new(&errors);
        assert!(
            control.errors[2] >= 19.25 * MIN_RATIO * MIN_RATIO,
            "{control:?}"
        );
        let long = LevelTable::new(&[64.0, 32.0, 16.0, 8.0, 4.0]);
        for m in [short.max(&long), long.max(&short)] {
            assert_eq!(m.levels, 5);
            for (k, &e) in errors.iter().enumerate() {
                assert!(m.errors[k] >= e, "{k}: {m:?}");
            }
            for k in 0..4 {
                assert!(m.errors[k] >= MIN_RATIO * m.errors[k + 1] * 0.9999, "{m:?}");
            }
        }
        let other = LevelTable::over(&[60.0, 30.0, 25.0, 24.0, 23.0], 3);
        let both = short.max(&other);
        assert_eq!((both.levels, both.errors[2]), (3, 25.0), "{both:?}");
        assert_eq!(both.errors[4], 23.0, "{both:?}");
        // Tables without copies merge as they always did.
        assert_eq!(
            control.max(&long),
            LevelTable::new(&[64.0, 32.0, 20.0, 19.5, 19.25])
        );
    }

    /// A level whose error the spacing rule left above the next coarser one's is not allowed to
    /// make `Λ` jump: the table falls by the least ratio everywhere, never below a level's own
    /// error; the larger of two tables is above both.
    #[test]
    fn tables_fall_by_the_least_ratio_and_never_understate_an_error() {
        let raw = [256.0, 128.0, 143.25, 112.0, 16.0, 8.0];
        let t = LevelTable::new(&raw);
        for (k, (&e, &r)) in t.errors.iter().zip(&raw).enumerate() {
            assert!(e >= r, "{k}: {t:?}");
        }
        for k in 0..raw.len() - 1 {
            assert!(
                t.errors[k] >= MIN_RATIO * t.errors[k + 1] * 0.9999,
                "{k}: {t:?}"
            );
        }
        let other = LevelTable::new(&[100.0, 90.0, 30.0, 20.0, 30.0, 2.0]);
        let m = t.max(&other);
        for ((&e, &a), &b) in m.errors.iter().zip(&t.errors).zip(&other.errors) {
            assert!(e >= a && e >= b, "{m:?}");
        }
        // Larger errors never ask for a coarser level.
        for i in 1..200 {
            let r = f64::from(i) * 2.0;
            assert!(
                m.level_f64(r) >= t.level_f64(r) - 1e-6,
                "{r}: {} < {}\n{m:?}\n{t:?}",
                m.level_f64(r),
                t.level_f64(r)
            );
        }
    }

    /// `max` answers with one of the two tables where that table covers the other, and the
    /// answer is the merge's, bit for bit, over random tables of 1 to 9 levels with copies,
    /// equal and near-equal errors, and of each table with itself. Between two different
    /// tables both ways are taken many times: where neither covers the other, the merge is
    /// neither.
    #[test]
    fn the_larger_table_as_it_stands_is_the_merge() {
        let bits = |t: &LevelTable| {
            let floats = t.errors.iter().chain(&t.a).chain(&t.b);
            (t.levels, floats.map(|x| x.to_bits()).collect::<Vec<u32>>())
        };
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = |n: u64| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state % n
        };
        let (mut quick, mut merged) = (0, 0);
        for _ in 0..20_000 {
            let mut table = || {
                let n = 1 + next(9) as usize;
                let mut e = 4096.0f32;
                let errors: Vec<f32> = (0..n)
                    .map(|_| {
                        e *= [1.0, 0.5, 0.25, 0.9][next(4) as usize];
                        e
                    })
                    .collect();
                LevelTable::over(&errors, 1 + next(n as u64) as usize)
            };
            let (a, b) = (table(), table());
            for (x, y) in [(a, b), (b, a), (a, a)] {
                let fast = x.max(&y);
                assert_eq!(bits(&fast), bits(&x.merged(&y)), "{x:?}\n{y:?}");
                if bits(&x) == bits(&y) {
                    continue;
                }
                if bits(&fast) == bits(&x) || bits(&fast) == bits(&y) {
                    quick += 1;
                } else {
                    merged += 1;
                }
            }
        }
        assert!(quick > 5_000 && merged > 1_000, "{quick} {merged}");
    }
}
