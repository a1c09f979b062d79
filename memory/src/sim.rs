//! Replays a trace through a policy, offline: how the manager (or one of its comparison
//! schemes, or Belady's rule knowing the future) would have served a recorded flight.

use crate::cost::TileCost;
use crate::manager::{Config, Manager, Request, Victim};
use crate::trace::Trace;

/// Totals over a replayed flight.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Outcome {
    pub frames: u64,
    /// Visible tiles summed over frames.
    pub tile_frames: u64,
    pub hits: u64,
    pub misses: u64,
    /// Tile-frames drawn below the wanted level.
    pub coarser: u64,
    /// The cold start: frames before the first one that draws every tile at its wanted level.
    pub warmup_frames: u64,
    /// Of `coarser`: those after the cold start (what prefetching can help with; before the
    /// first frame there is no history to predict from).
    pub coarser_warm: u64,
    /// Tile-frames not drawn at all.
    pub missing: u64,
    pub bytes_blocks: u64,
    pub bytes_indices: u64,
    /// Of `bytes_indices`: coarser index arrays for tiles whose wanted level dropped.
    pub bytes_coarser: u64,
    pub evictions: u64,
    pub moves: u64,
    pub move_bytes: u64,
    pub overshoot: u64,
    /// The largest upload of one frame.
    pub max_frame_bytes: u64,
    pub pool_bytes: u64,
    pub prefetch_bytes: u64,
    pub prefetch_hits: u64,
    pub prefetch_wasted_bytes: u64,
}

/// Where a replay's prefetch candidates come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Prefetching {
    Off,
    /// The predictions the renderer recorded in the trace (`predicted` rows).
    Recorded,
    /// A perfect predictor: the requests of the next `frames` frames, soonest first (the
    /// upper bound of what prefetching can gain).
    Perfect {
        frames: usize,
    },
}

impl Outcome {
    pub fn bytes(&self) -> u64 {
        self.bytes_blocks + self.bytes_indices
    }
}

/// Replays `trace` with `config`, frames finishing `frames_in_flight` frames after they start.
pub fn replay(trace: &Trace, config: Config, frames_in_flight: u64) -> Outcome {
    replay_prefetching(trace, config, frames_in_flight, Prefetching::Off)
}

/// [`replay`], prefetching after each frame's plan as the renderer does.
pub fn replay_prefetching(
    trace: &Trace,
    config: Config,
    frames_in_flight: u64,
    prefetching: Prefetching,
) -> Outcome {
    let mut m = Manager::new(trace.costs.clone(), config);
    if config.victim == Victim::Belady {
        m.set_oracle(Box::new(trace.next_use()));
    }
    let mut o = Outcome {
        pool_bytes: m.pool_bytes(),
        ..Default::default()
    };
    let mut per_frame = Vec::with_capacity(trace.frames.len());
    for (f, requests) in trace.frames.iter().enumerate() {
        let f = f as u64;
        let mut p = m.plan_frame(f, f.checked_sub(frames_in_flight.max(1)), requests, true);
        let k = f as usize;
        match prefetching {
            Prefetching::Off => {}
            Prefetching::Recorded => {
                if let Some(predicted) = trace.predicted.get(k) {
                    m.prefetch(&mut p, predicted);
                }
            }
            Prefetching::Perfect { frames } => {
                let ahead: Vec<Request> = trace
                    .frames
                    .iter()
                    .skip(k + 1)
                    .take(frames)
                    .flatten()
                    .copied()
                    .collect();
                m.prefetch(&mut p, &ahead);
            }
        }
        let s = p.stats;
        o.prefetch_bytes += s.prefetch_bytes;
        o.prefetch_hits += s.prefetch_hits;
        o.prefetch_wasted_bytes += s.prefetch_wasted_bytes;
        o.frames += 1;
        o.tile_frames += requests.len() as u64;
        o.hits += s.hits;
        o.misses += s.misses;
        o.coarser += s.tiles_coarser;
        per_frame.push((s.tiles_coarser, s.tiles_missing));
        o.missing += s.tiles_missing;
        o.bytes_blocks += s.upload_bytes_blocks;
        o.bytes_indices += s.upload_bytes_indices;
        o.bytes_coarser += s.upload_bytes_coarser;
        o.evictions += s.evictions;
        o.moves += s.chunk_moves;
        o.move_bytes += s.chunk_move_bytes;
        o.overshoot += s.upload_overshoot_bytes;
        o.max_frame_bytes = o
            .max_frame_bytes
            .max(s.upload_bytes_blocks + s.upload_bytes_indices);
    }
    (o.warmup_frames, o.coarser_warm) = cold_start(&per_frame);
    o
}

/// Splits a flight's tile-frames drawn coarser than wanted at the end of its cold start, from
/// each frame's (tiles coarser, tiles missing): the number of frames before the first one
/// that draws every visible tile at its wanted level, and the tile-frames coarser after it.
pub fn cold_start(per_frame: &[(u64, u64)]) -> (u64, u64) {
    let warmup = per_frame
        .iter()
        .position(|&(coarser, missing)| coarser == 0 && missing == 0)
        .unwrap_or(per_frame.len());
    let after = per_frame[warmup..].iter().map(|&(c, _)| c).sum();
    (warmup as u64, after)
}

/// A synthetic flight for timing the manager: `tiles` tiles (the costs of `costs` repeated),
/// a window of `visible` of them sliding by 8 tiles a frame, each wanted level in a random
/// walk (steps of -1, 0, +1; a fixed seed).
pub fn synthetic(costs: &[TileCost], tiles: usize, visible: usize, frames: usize) -> Trace {
    let costs: Vec<TileCost> = costs.iter().cycle().take(tiles).cloned().collect();
    let mut wanted: Vec<u32> = (0..tiles).map(|t| (t % 9) as u32).collect();
    let mut rng = 0x2545_f491_4f6c_dd1du64;
    let frames = (0..frames)
        .map(|f| {
            (0..visible)
                .map(|k| {
                    let t = (f * 8 + k) % tiles;
                    rng ^= rng << 13;
                    rng ^= rng >> 7;
                    rng ^= rng << 17;
                    let step = (rng % 3) as i64 - 1;
                    let finest = i64::from(costs[t].finest());
                    wanted[t] = (i64::from(wanted[t]) + step).clamp(0, finest) as u32;
                    Request {
                        tile: t as u32,
                        wanted: wanted[t],
                    }
                })
                .collect()
        })
        .collect();
    Trace {
        costs,
        frames,
        predicted: Vec::new(),
    }
}

/// Bytes of the whole tile set (every block and index array of every tile).
pub fn tile_set_bytes(trace: &Trace) -> u64 {
    trace.costs.iter().map(|c| c.whole()).sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cost::tests::tile;
    use crate::manager::Scheme;

    /// A flight over 12 tiles that keeps coming back: the future matters.
    fn flight() -> Trace {
        let costs = (0..12).map(|i| tile(6, 60 + 20 * i)).collect();
        let frames = (0..120u32)
            .map(|f| {
                (0..5)
                    .map(|k| Request {
                        tile: (f / 7 + k * 3 + (f % 5)) % 12,
                        wanted: (f + k) % 6,
                    })
                    .fold(Vec::new(), |mut v: Vec<Request>, r| {
                        if !v.iter().any(|x| x.tile == r.tile) {
                            v.push(r);
                        }
                        v
                    })
            })
            .collect();
        Trace {
            costs,
            frames,
            predicted: Vec::new(),
        }
    }

    #[test]
    fn the_cold_start_ends_at_the_first_frame_with_every_tile_at_its_level() {
        // Coarser, then missing, then all there; later lateness counts after the cold start.
        assert_eq!(
            cold_start(&[(3, 0), (0, 1), (0, 0), (2, 0), (0, 0), (1, 0)]),
            (2, 3)
        );
        assert_eq!(cold_start(&[(1, 0), (4, 0)]), (2, 0));
        assert_eq!(cold_start(&[]), (0, 0));
    }

    #[test]
    fn a_perfect_predictor_under_a_tight_budget_draws_fewer_tiles_coarser() {
        // A window of 6 tiles that jumps by 3 tiles every third frame, each wanted at level 4:
        // the budget covers the average (one tile a frame) but not the jump, so without
        // prefetching the new tiles arrive over several frames.
        let costs: Vec<TileCost> = (0..80).map(|_| tile(6, 80)).collect();
        let frames = (0..60u32)
            .map(|f| {
                let start = 3 * (f / 3);
                (start..start + 6)
                    .map(|t| Request { tile: t, wanted: 4 })
                    .collect()
            })
            .collect();
        let t = Trace {
            costs,
            frames,
            predicted: Vec::new(),
        };
        let level4: u64 =
            (0..=4).map(|j| t.costs[0].block_bytes(j)).sum::<u64>() + t.costs[0].levels[4].indices;
        let c = Config {
            pool_bytes: 1 << 30,
            upload_budget: level4 * 2,
            ..Config::default()
        };
        let off = replay_prefetching(&t, c, 2, Prefetching::Off);
        let perfect = replay_prefetching(&t, c, 2, Prefetching::Perfect { frames: 3 });
        assert!(off.coarser > 20, "{off:?}");
        // Most of what is left is the cold start (six tiles at once, nothing to predict from).
        assert!(perfect.coarser * 3 < off.coarser, "{perfect:?} vs {off:?}");
        assert!(perfect.prefetch_hits > 0 && perfect.prefetch_wasted_bytes == 0);
        // Recorded predictions: none in this trace, so the same as off.
        let recorded = replay_prefetching(&t, c, 2, Prefetching::Recorded);
        assert_eq!(recorded.coarser, off.coarser);
    }

    #[test]
    fn belady_misses_no_more_than_lru_and_progressive_sends_least() {
        let t = flight();
        let budget = tile_set_bytes(&t) / 4;
        let run = |victim, scheme| {
            let c = Config {
                pool_bytes: budget,
                upload_budget: 1 << 40,
                victim,
                scheme,
                ..Config::default()
            };
            replay(&t, c, 2)
        };
        let lru = run(Victim::Lru, Scheme::Progressive);
        let belady = run(Victim::Belady, Scheme::Progressive);
        assert!(lru.evictions > 0, "{lru:?}");
        assert!(belady.evictions <= lru.evictions, "{belady:?} vs {lru:?}");
        assert_eq!(lru.tile_frames, lru.hits + lru.misses);
        let unlimited = |scheme| {
            let c = Config {
                pool_bytes: 1 << 40,
                upload_budget: 1 << 40,
                scheme,
                ..Config::default()
            };
            replay(&t, c, 2).bytes()
        };
        let (prog, per, whole) = (
            unlimited(Scheme::Progressive),
            unlimited(Scheme::PerLevel),
            unlimited(Scheme::WholeTile),
        );
        assert!(prog < per && per > 0 && whole > 0, "{prog} {per} {whole}");
        // With room for everything, whole tiles are sent once each: the tile set.
        assert_eq!(whole, tile_set_bytes(&t));
    }
}
