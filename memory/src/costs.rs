//! Every tile's costs as the manager holds them: given whole at start, or asked for tile by
//! tile from a source the first time the manager needs one. A set of 87,381 tiles (the 64K
//! mirror set with its pyramid) is too large to read every tile's level table before the first
//! frame, and a flight needs the few hundred its cuts reach.
//!
//! The pool's size classes are planned from a sample of the tiles ([`sample`]): every tile of a
//! set of at most [`SAMPLE_TILES`] (by default), which plans exactly what the whole set does;
//! beyond that, one tile in each run of `stride` tiles through the index space (every pyramid
//! layer in proportion), each standing for its run.

use std::ops::Index;
use std::sync::OnceLock;

use crate::cost::TileCost;
use crate::manager::{Scheme, TileId};

/// The most tiles a plan reads; a larger set's plan reads a stride sample of about as many.
pub const SAMPLE_TILES: usize = 1024;

/// A tile's costs, read when the manager first needs them.
pub type CostSource = Box<dyn Fn(TileId) -> TileCost>;

/// One tile's costs and, per level, the bytes a chunk needs to hold it under the scheme.
struct Known {
    cost: TileCost,
    needs: Vec<u64>,
}

pub(crate) struct Costs {
    known: Box<[OnceLock<Known>]>,
    source: Option<CostSource>,
    scheme: Scheme,
    /// The most tiles a plan reads ([`sample`]).
    at_most: usize,
}

impl Costs {
    /// Every tile's costs, given.
    pub(crate) fn given(tiles: Vec<TileCost>, scheme: Scheme) -> Costs {
        let known = tiles
            .into_iter()
            .map(|cost| OnceLock::from(Known::new(cost, scheme)))
            .collect();
        Costs {
            known,
            source: None,
            scheme,
            at_most: usize::MAX,
        }
    }

    /// `count` tiles whose costs `source` gives when first needed, planned from a sample of
    /// at most about `at_most` of them.
    pub(crate) fn from_source(
        count: usize,
        source: CostSource,
        scheme: Scheme,
        at_most: usize,
    ) -> Costs {
        Costs {
            known: (0..count).map(|_| OnceLock::new()).collect(),
            source: Some(source),
            scheme,
            at_most,
        }
    }

    pub(crate) fn len(&self) -> usize {
        self.known.len()
    }

    fn known(&self, t: usize) -> &Known {
        self.known[t].get_or_init(|| {
            let source = self
                .source
                .as_ref()
                .expect("costs given whole are all known");
            Known::new(source(t as TileId), self.scheme)
        })
    }

    /// Tile `t`'s costs, if the set has a tile `t`.
    pub(crate) fn get(&self, t: usize) -> Option<&TileCost> {
        (t < self.len()).then(|| &self.known(t).cost)
    }

    /// Bytes a chunk needs to hold tile `t` up to each level.
    pub(crate) fn needs(&self, t: usize) -> &[u64] {
        &self.known(t).needs
    }

    /// The tiles a plan reads, and how many tiles each stands for: every tile, each for
    /// itself, where the costs were given whole; [`sample`] where they come from a source.
    pub(crate) fn sample(&self) -> (Vec<TileId>, u64) {
        match self.source {
            None => ((0..self.len() as TileId).collect(), 1),
            Some(_) => sample(self.len(), self.at_most),
        }
    }
}

/// The tiles of a set of `count` that a plan reads, and how many tiles each stands for: every
/// tile up to `at_most` ([`SAMPLE_TILES`] by default), else one tile of each run of `stride`
/// tiles, at an offset in the run drawn from a fixed hash of the run (a tile grid is often
/// periodic, a mirror tiling always, and every `stride`-th tile alone can fall on one column
/// of the period).
pub fn sample(count: usize, at_most: usize) -> (Vec<TileId>, u64) {
    let stride = count.div_ceil(at_most.max(1)).max(1);
    let tiles = (0..count)
        .step_by(stride)
        .enumerate()
        .map(|(k, start)| {
            let run = stride.min(count - start) as u64;
            (start as u64 + mix(k as u64) % run) as TileId
        })
        .collect();
    (tiles, stride as u64)
}

/// SplitMix64's finaliser: a fixed, well-spread hash.
fn mix(k: u64) -> u64 {
    let mut z = k.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

impl Known {
    fn new(cost: TileCost, scheme: Scheme) -> Known {
        Known {
            needs: needs_of(&cost, scheme),
            cost,
        }
    }
}

/// Bytes a chunk needs to hold `cost`'s tile up to each level under `scheme`.
pub(crate) fn needs_of(cost: &TileCost, scheme: Scheme) -> Vec<u64> {
    (0..=cost.finest())
        .map(|l| match scheme {
            Scheme::WholeTile => cost.whole_layout().bytes,
            _ => cost.need(l),
        })
        .collect()
}

impl Index<usize> for Costs {
    type Output = TileCost;

    fn index(&self, t: usize) -> &TileCost {
        &self.known(t).cost
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cost::tests::tile;
    use std::cell::Cell;
    use std::rc::Rc;

    #[test]
    fn a_small_set_is_sampled_whole_and_a_large_one_by_stride() {
        let (all, weight) = sample(SAMPLE_TILES, SAMPLE_TILES);
        assert_eq!((all.len(), weight), (SAMPLE_TILES, 1));
        assert_eq!(all, (0..SAMPLE_TILES as TileId).collect::<Vec<_>>());
        let n = 87_381;
        let (some, weight) = sample(n, SAMPLE_TILES);
        assert_eq!(weight, 86);
        assert!(some.len() <= SAMPLE_TILES && some.len() as u64 * weight >= n as u64);
        // One tile in each run of 86, at offsets that do not repeat with any short period.
        for (k, &t) in some.iter().enumerate() {
            assert_eq!(t as usize / 86, k, "tile {t} in run {k}");
        }
        assert!(
            *some.last().unwrap() as usize >= n - 86,
            "reaches the last layer"
        );
        let columns: std::collections::HashSet<u32> = some.iter().map(|t| t % 256).collect();
        assert!(columns.len() > 200, "{} of 256 columns", columns.len());
    }

    #[test]
    fn a_source_is_asked_once_per_tile_and_only_when_needed() {
        let asked = Rc::new(Cell::new(0));
        let counted = Rc::clone(&asked);
        let costs = Costs::from_source(
            100,
            Box::new(move |t| {
                counted.set(counted.get() + 1);
                tile(3, 10 + u64::from(t))
            }),
            Scheme::Progressive,
            SAMPLE_TILES,
        );
        assert_eq!(asked.get(), 0, "nothing read before it is needed");
        let given = Costs::given(
            (0..100).map(|t| tile(3, 10 + t)).collect(),
            Scheme::Progressive,
        );
        for t in [7, 7, 42, 7] {
            assert_eq!(costs[t], given[t]);
            assert_eq!(costs.needs(t), given.needs(t));
        }
        assert_eq!(asked.get(), 2);
    }
}
