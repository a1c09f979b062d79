//! Which tiles hold GPU memory. The policy is plain Rust (unit-tested without a GPU); the
//! renderer turns its decisions into buffers. The memory issue replaces [`WholeTileLru`] with
//! chunked, progressive residency behind the same trait.

use std::collections::HashMap;

/// A residency policy: which tiles to evict so `tile` fits.
pub trait Residency {
    /// Makes `tile` (needing `bytes`) resident at `frame`; returns the tiles to evict first.
    /// Tiles for which `in_use` is true are never evicted (they are drawn this frame).
    fn admit(
        &mut self,
        tile: usize,
        bytes: u64,
        frame: u64,
        in_use: &dyn Fn(usize) -> bool,
    ) -> Vec<usize>;
    fn is_resident(&self, tile: usize) -> bool;
    fn resident_bytes(&self) -> u64;
}

/// Whole tiles, least recently used first out, within a byte budget.
#[derive(Debug)]
pub struct WholeTileLru {
    budget: u64,
    used: u64,
    tiles: HashMap<usize, (u64, u64)>,
}

impl WholeTileLru {
    pub fn new(budget: u64) -> Self {
        WholeTileLru {
            budget,
            used: 0,
            tiles: HashMap::new(),
        }
    }
}

impl Residency for WholeTileLru {
    fn admit(
        &mut self,
        tile: usize,
        bytes: u64,
        frame: u64,
        in_use: &dyn Fn(usize) -> bool,
    ) -> Vec<usize> {
        if let Some(entry) = self.tiles.get_mut(&tile) {
            entry.1 = frame;
            return Vec::new();
        }
        let mut evicted = Vec::new();
        while self.used + bytes > self.budget {
            let victim = self
                .tiles
                .iter()
                .filter(|(&t, _)| !in_use(t))
                .min_by_key(|(&t, &(_, last))| (last, t))
                .map(|(&t, _)| t);
            let Some(victim) = victim else { break };
            if let Some((b, _)) = self.tiles.remove(&victim) {
                self.used -= b;
            }
            evicted.push(victim);
        }
        // Over budget with only tiles in use: draw anyway (the frame needs them).
        self.tiles.insert(tile, (bytes, frame));
        self.used += bytes;
        evicted
    }

    fn is_resident(&self, tile: usize) -> bool {
        self.tiles.contains_key(&tile)
    }

    fn resident_bytes(&self) -> u64 {
        self.used
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn evicts_least_recently_used_tiles_not_in_use() {
        let mut lru = WholeTileLru::new(100);
        assert!(lru.admit(1, 40, 0, &|_| false).is_empty());
        assert!(lru.admit(2, 40, 1, &|_| false).is_empty());
        assert!(lru.admit(1, 40, 2, &|_| false).is_empty()); // touch 1: now 2 is older
        assert_eq!(lru.admit(3, 40, 3, &|_| false), vec![2]);
        assert_eq!(lru.resident_bytes(), 80);
        // Tile 1 is in use: nothing can go, the budget is exceeded rather than the frame broken.
        assert_eq!(
            lru.admit(4, 40, 4, &|t| t == 1 || t == 3),
            Vec::<usize>::new()
        );
        assert_eq!(lru.resident_bytes(), 120);
        assert!(lru.is_resident(4));
        assert_eq!(lru.admit(5, 10, 5, &|t| t == 4), vec![1]);
    }
}
