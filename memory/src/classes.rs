//! Size classes of the chunk pool, and how many chunks of each the pool is carved into.
//!
//! Classes grow exponentially (by `ratio`, default 2) from 32 KiB until one holds the largest
//! tile at its finest level. The count of each class follows the tile set's size histogram:
//! every (tile, level) pair votes for the tightest class that holds the tile up to that level
//! (so each level is assumed equally likely to be wanted, which is what a flight over the whole
//! set averages to). When the budget holds one chunk per vote, that is the pool: no request can
//! ever find the pool full. Otherwise every tile first gets one chunk of the class that holds
//! its level 0 (while that takes at most half the budget), so any set of visible tiles can be
//! drawn at least coarsely; the rest is apportioned by the D'Hondt rule: chunks are handed out
//! one at a time to the class with the largest `votes / (chunks + 1)` among those still
//! fitting in what is left, so counts stay proportional to the histogram as the budget grows,
//! and a small budget goes to the classes most tiles need rather than being rounded away.

use crate::cost::align;

/// Chunk offsets and sizes are multiples of this (index and vertex offsets divide evenly).
pub const CHUNK_ALIGN: u64 = 256;

/// The smallest chunk.
pub const MIN_CLASS: u64 = 32 << 10;

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ClassPlan {
    /// Chunk size of each class, ascending.
    pub sizes: Vec<u64>,
    /// Chunks of each class.
    pub counts: Vec<u32>,
    /// The histogram: (tile, level) pairs whose tightest class is this one.
    pub votes: Vec<u64>,
}

impl ClassPlan {
    /// Plans classes for tiles that need `needs[t][l]` bytes to hold levels `0..=l`, within
    /// `budget` bytes.
    pub fn new<N: AsRef<[u64]>>(needs: &[N], budget: u64, ratio: f64) -> ClassPlan {
        ClassPlan::weighted(needs, 1, budget, ratio)
    }

    /// [`ClassPlan::new`] for a sample of a set's tiles, each standing for `weight` tiles: its
    /// votes, and its tiles' level-0 chunks, count `weight` times (with a weight of 1, the
    /// plan of exactly these tiles).
    pub fn weighted<N: AsRef<[u64]>>(
        needs: &[N],
        weight: u64,
        budget: u64,
        ratio: f64,
    ) -> ClassPlan {
        let all = || needs.iter().flat_map(|t| t.as_ref().iter().copied());
        let largest = all().max().unwrap_or(0);
        let ratio = ratio.max(1.1);
        let mut sizes = vec![MIN_CLASS];
        while sizes[sizes.len() - 1] < largest {
            let last = sizes[sizes.len() - 1];
            let next = align((last as f64 * ratio).ceil() as u64, CHUNK_ALIGN).max(last + 1);
            sizes.push(next);
        }
        let mut votes = vec![0u64; sizes.len()];
        for need in all() {
            votes[class_for(&sizes, need).unwrap_or(sizes.len() - 1)] += weight;
        }
        let everything: u64 = votes.iter().zip(&sizes).map(|(v, s)| v * s).sum();
        let counts = if budget >= everything {
            votes.iter().map(|&v| v as u32).collect()
        } else {
            let mut counts = vec![0u32; sizes.len()];
            let mut reserved = 0;
            'presence: for t in needs {
                let Some(c) = t.as_ref().first().and_then(|&n| class_for(&sizes, n)) else {
                    continue;
                };
                for _ in 0..weight {
                    if reserved + sizes[c] > budget / 2 {
                        break 'presence;
                    }
                    counts[c] += 1;
                    reserved += sizes[c];
                }
            }
            dhondt(&sizes, &votes, counts, budget - reserved)
        };
        ClassPlan {
            sizes,
            counts,
            votes,
        }
    }

    /// Bytes of the whole pool.
    pub fn bytes(&self) -> u64 {
        self.sizes
            .iter()
            .zip(&self.counts)
            .map(|(s, &c)| s * u64::from(c))
            .sum()
    }

    /// The tightest class holding `bytes`.
    pub fn class_for(&self, bytes: u64) -> Option<usize> {
        class_for(&self.sizes, bytes)
    }
}

fn class_for(sizes: &[u64], bytes: u64) -> Option<usize> {
    sizes.iter().position(|&s| s >= bytes)
}

fn dhondt(sizes: &[u64], votes: &[u64], mut counts: Vec<u32>, budget: u64) -> Vec<u32> {
    let mut left = budget;
    loop {
        let best = (0..sizes.len())
            .filter(|&c| votes[c] > 0 && sizes[c] <= left)
            .max_by(|&a, &b| {
                // votes_a / (n_a + 1) vs votes_b / (n_b + 1), exactly; ties go to the smaller.
                let qa = u128::from(votes[a]) * u128::from(counts[b] + 1);
                let qb = u128::from(votes[b]) * u128::from(counts[a] + 1);
                qa.cmp(&qb).then(b.cmp(&a))
            });
        let Some(c) = best else { break };
        counts[c] += 1;
        left -= sizes[c];
    }
    counts
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cost::tests::tile;
    use crate::cost::TileCost;

    fn needs(tiles: &[TileCost]) -> Vec<Vec<u64>> {
        tiles
            .iter()
            .map(|t| (0..=t.finest()).map(|l| t.need(l)).collect())
            .collect()
    }

    #[test]
    fn classes_cover_the_largest_tile_and_grow_by_the_ratio() {
        let tiles: Vec<TileCost> = (1..6).map(|s| tile(9, s * 40)).collect();
        let plan = ClassPlan::new(&needs(&tiles), 64 << 20, 2.0);
        let largest = tiles.iter().map(|t| t.need(8)).max().unwrap();
        assert_eq!(plan.sizes[0], MIN_CLASS);
        assert!(*plan.sizes.last().unwrap() >= largest);
        assert!(plan.sizes[plan.sizes.len() - 2] < largest);
        for w in plan.sizes.windows(2) {
            assert_eq!(w[1], 2 * w[0]);
        }
        assert_eq!(plan.votes.iter().sum::<u64>(), 5 * 9);
    }

    #[test]
    fn a_large_budget_gives_one_chunk_per_vote_and_a_small_one_stays_within_it() {
        let tiles: Vec<TileCost> = (1..6).map(|s| tile(9, s * 40)).collect();
        let big = ClassPlan::new(&needs(&tiles), 1 << 40, 2.0);
        assert_eq!(
            big.counts.iter().map(|&c| u64::from(c)).collect::<Vec<_>>(),
            big.votes
        );
        for budget in [1 << 20, 3 << 20, 10 << 20] {
            let small = ClassPlan::new(&needs(&tiles), budget, 2.0);
            assert!(small.bytes() <= budget);
            // D'Hondt fills the budget down to less than the smallest class.
            assert!(budget - small.bytes() < MIN_CLASS);
            assert!(small.counts[0] > 0);
            // Every tile can hold its level 0 at once.
            let presence: u32 = (0..small.sizes.len())
                .filter(|&c| small.sizes[c] >= tiles.iter().map(|t| t.need(0)).max().unwrap())
                .map(|c| small.counts[c])
                .sum();
            assert!(presence >= 5, "{small:?}");
        }
    }

    /// A sample whose tiles each stand for `weight` tiles plans as the tiles repeated that
    /// many times would: the same classes, votes and counts, at every budget.
    #[test]
    fn a_weighted_sample_plans_as_its_tiles_repeated() {
        let tiles: Vec<TileCost> = (1..8).map(|s| tile(9, s * 30)).collect();
        let repeated: Vec<TileCost> = tiles
            .iter()
            .flat_map(|t| std::iter::repeat_n(t.clone(), 3))
            .collect();
        for budget in [1 << 20, 5 << 20, 20 << 20, 1 << 40] {
            let weighted = ClassPlan::weighted(&needs(&tiles), 3, budget, 2.0);
            assert_eq!(
                weighted,
                ClassPlan::new(&needs(&repeated), budget, 2.0),
                "{budget}"
            );
            // The control: unweighted, a third of the votes.
            let plain = ClassPlan::new(&needs(&tiles), budget, 2.0);
            assert_eq!(
                3 * plain.votes.iter().sum::<u64>(),
                weighted.votes.iter().sum::<u64>()
            );
        }
    }
}
