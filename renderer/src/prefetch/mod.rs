//! Prefetching (paper, section 6, last paragraph): the camera predicted from the poses flown
//! ([`predict`]), the tiles visible from the predicted poses with the levels they will
//! want, soonest first and nearest first, handed to the memory manager to upload with what the
//! frame leaves of its byte budget ([`memory::Manager::prefetch_while`], within `--prefetch-ms` with the prediction), and the file side: their
//! byte ranges advised `WILLNEED` so a cold page cache is read ahead, and, when the mapping
//! outgrows a budget, tiles far behind the camera advised `DONTNEED`.

pub mod predict;

use std::collections::HashMap;
use std::time::Instant;

use glam::DVec3;
use memory::Request;

use self::predict::Predictor;
use crate::camera::Camera;
use crate::log::ms;
use crate::plan::{self, LevelRule};
use crate::terrain::Terrain;

/// How prefetching runs (`vkterrain --no-prefetch`, `--prefetch-ms`, `--prefetch-free`,
/// `--no-madvise`, `--file-cache-mb`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrefetchOptions {
    /// Upload predicted tiles (GPU side).
    pub enabled: bool,
    /// Prefetch while at least this share of the pool's chunks is free.
    pub free_share: f64,
    /// CPU time for predicting, culling and choosing levels, per frame.
    pub cpu_ms: f64,
    /// Advise the kernel to read predicted tiles ahead (file side).
    pub madvise: bool,
    /// When the tile set is larger than this, tiles far behind the camera are advised
    /// `DONTNEED` until the tiles paged in by this run fit again.
    pub file_cache_bytes: Option<u64>,
}

impl Default for PrefetchOptions {
    fn default() -> Self {
        PrefetchOptions {
            enabled: true,
            free_share: memory::DEFAULT_PREFETCH_FREE,
            cpu_ms: 2.0,
            madvise: true,
            file_cache_bytes: None,
        }
    }
}

/// This frame's predictions.
#[derive(Clone, Debug, Default)]
pub struct Predicted {
    /// Tiles visible from the predicted poses, soonest first, then nearest first; a tile
    /// appears again only with a finer level.
    pub requests: Vec<Request>,
    /// Horizons looked at before the CPU budget ran out.
    pub horizons: usize,
    /// Bytes newly advised `WILLNEED` and `DONTNEED` this frame.
    pub advised_bytes: u64,
    pub released_bytes: u64,
}

/// The predictor and the file-side bookkeeping of one flight.
pub struct Prefetcher {
    pub options: PrefetchOptions,
    predictor: Predictor,
    /// Per tile: its bytes were advised or read by this run (and not released since); and
    /// those tiles, listed (with tiles released since, until the next release drops them), so
    /// that releasing looks at what was paged, not at every tile of the set.
    paged: Vec<bool>,
    paged_list: Vec<usize>,
    paged_bytes: u64,
    /// What a horizon cost in the last frame that looked at one (the slowest of its
    /// horizons), ms: a horizon starts only when one as slow still ends within the budget.
    horizon_ms: f64,
}

impl Prefetcher {
    pub fn new(options: PrefetchOptions, tiles: usize) -> Prefetcher {
        Prefetcher {
            options,
            predictor: Predictor::default(),
            paged: vec![false; tiles],
            paged_list: Vec::new(),
            paged_bytes: 0,
            horizon_ms: 0.0,
        }
    }

    /// Feeds this frame's pose; returns the error, metres, of the shortest-horizon prediction
    /// that fell due (NaN when none did).
    pub fn observe(&mut self, time: f64, camera: &Camera) -> f64 {
        self.predictor.observe(time, camera);
        let error = self.predictor.score();
        self.predictor.remember(self.predictor.horizons()[0]);
        error
    }

    /// Tiles visible from the predicted poses with their levels under `rule`, within the CPU
    /// budget; then the file side (advice) for them.
    pub fn predict(
        &mut self,
        terrain: &Terrain,
        camera: &Camera,
        extent: (u32, u32),
        rule: LevelRule,
    ) -> Predicted {
        let started = Instant::now();
        let mut out = Predicted::default();
        // Per tile listed so far, its finest level listed (a frame's few hundred tiles, not a
        // slot for each of the set's).
        let mut listed: HashMap<usize, u32> = HashMap::new();
        let mut slowest = 0.0f64;
        for h in self.predictor.horizons() {
            // A horizon starts only if one as slow as the slowest yet still ends in budget.
            if ms(started) + self.horizon_ms.max(slowest) > self.options.cpu_ms {
                break;
            }
            let t = Instant::now();
            let Some(predicted) = self.predictor.predict(h) else {
                break;
            };
            out.horizons += 1;
            let view = predicted.view(extent.0, extent.1);
            let wanted = plan::requests_for(terrain, &view, predicted.position, rule);
            for r in wanted {
                let i = r.tile as usize;
                if listed.get(&i).is_some_and(|&l| l >= r.wanted) {
                    continue;
                }
                listed.insert(i, r.wanted);
                out.requests.push(r);
            }
            slowest = slowest.max(ms(t));
        }
        // A frame that looked at none forgets half of the estimate, so one slow frame does
        // not stop prefetching for good.
        self.horizon_ms = if out.horizons > 0 {
            slowest
        } else {
            self.horizon_ms / 2.0
        };
        if self.options.madvise {
            for r in &out.requests {
                out.advised_bytes += self.page_in(terrain, r.tile as usize);
            }
        }
        if let Some(budget) = self.options.file_cache_bytes {
            if terrain.set.file_len() > budget && self.paged_bytes > budget {
                out.released_bytes = self.release_behind(terrain, camera, &listed, budget);
            }
        }
        out
    }

    /// Notes that an upload read tile `tile` from the file.
    pub fn touched(&mut self, terrain: &Terrain, tile: usize) {
        if !self.paged[tile] {
            self.paged[tile] = true;
            self.paged_list.push(tile);
            self.paged_bytes += blob_len(terrain, tile);
        }
    }

    /// Advises a tile's bytes `WILLNEED` once (until released); returns the bytes advised.
    fn page_in(&mut self, terrain: &Terrain, tile: usize) -> u64 {
        if self.paged[tile] {
            return 0;
        }
        let t = &terrain.tiles[tile];
        let Some(range) = terrain.set_of(t).blob_range(t.tx, t.ty) else {
            return 0;
        };
        // Advice only: a kernel that refuses it costs nothing but the read-ahead.
        let _ = terrain.set.will_need(range.clone());
        self.paged[tile] = true;
        self.paged_list.push(tile);
        let len = range.end - range.start;
        self.paged_bytes += len;
        len
    }

    /// Advises `DONTNEED` for tiles paged in by this run that lie behind the camera and are
    /// not predicted, farthest first, until the paged bytes are under 90% of `budget`.
    fn release_behind(
        &mut self,
        terrain: &Terrain,
        camera: &Camera,
        predicted: &HashMap<usize, u32>,
        budget: u64,
    ) -> u64 {
        let forward = camera.forward();
        // Tiles released since they were listed, or listed twice, leave the list here.
        self.paged_list.sort_unstable();
        self.paged_list.dedup();
        let paged = &self.paged;
        self.paged_list.retain(|&i| paged[i]);
        let mut behind: Vec<(f64, usize)> = self
            .paged_list
            .iter()
            .copied()
            .filter(|i| !predicted.contains_key(i))
            .filter_map(|i| {
                let t = &terrain.tiles[i];
                let centre = (t.min + t.max) * 0.5;
                let to = centre - camera.position;
                let radius = (t.max - t.min).length() * 0.5;
                // Wholly behind the camera's plane.
                (to.dot(forward) < -radius).then(|| (distance_to_box(camera.position, t), i))
            })
            .collect();
        behind.sort_by(|a, b| b.0.total_cmp(&a.0));
        let target = budget / 10 * 9;
        let mut released = 0;
        for (_, i) in behind {
            if self.paged_bytes <= target {
                break;
            }
            let t = &terrain.tiles[i];
            if let Some(range) = terrain.set_of(t).blob_range(t.tx, t.ty) {
                let _ = terrain.set.dont_need(range);
            }
            let len = blob_len(terrain, i);
            self.paged[i] = false;
            self.paged_bytes -= len;
            released += len;
        }
        released
    }
}

fn blob_len(terrain: &Terrain, tile: usize) -> u64 {
    let t = &terrain.tiles[tile];
    terrain
        .set_of(t)
        .blob_range(t.tx, t.ty)
        .map_or(0, |r| r.end - r.start)
}

fn distance_to_box(p: DVec3, t: &crate::tile::TileInfo) -> f64 {
    p.clamp(t.min, t.max).distance(p)
}
