//! Residency traces: what each frame of a flight asked of the manager, to replay offline.
//!
//! Format (written by `vkterrain --trace FILE`, read by `memsim`): a first line, then two CSV
//! tables, each after its header line.
//!
//! ```text
//! # vkterrain trace v2
//! tile,level,positions,morph,indices,index_width
//! 0,0,1160,0,1708,2
//! ...
//! frame,tile,wanted,bytes,predicted
//! 0,5,3,48812,0
//! 0,6,2,30210,1
//! ```
//!
//! The first table is what every level of every tile costs (bytes of the level's block
//! positions and morph rows, of its index array, and the index width), so a trace replays
//! without the tile set. The second has one row per visible tile per frame, in the frame's
//! front-to-back order: `tile` is the tile's index in the tile set (row-major), `wanted` the
//! level LOD chose, `bytes` what drawing that level costs from scratch (blocks `0..=wanted`
//! with their morph rows, and the index array). A frame with no visible tile has no row.
//! `predicted` is 0 for those rows; rows with 1 follow a frame's requests and list what the
//! camera predictor expected to become visible (soonest first, nearest first, with the level
//! it would want), whether or not prefetching was on, so the simulator can replay prefetching.
//! Version 1 traces (no `predicted` column) still read. Compact streams decoded on the GPU
//! ([`LevelCost::stream`]) are not recorded: a trace replays blocks sent as positions.

use std::collections::HashMap;
use std::fmt::Write as _;

use crate::cost::{LevelCost, TileCost};
use crate::manager::{Request, TileId};

const FIRST: &str = "# vkterrain trace v2";
const FIRST_V1: &str = "# vkterrain trace v1";
const COSTS: &str = "tile,level,positions,morph,indices,index_width";
const FRAMES: &str = "frame,tile,wanted,bytes,predicted";
const FRAMES_V1: &str = "frame,tile,wanted,bytes";

/// The start of a trace: the first line and the cost table, up to the frames' header.
pub fn header(costs: &[TileCost]) -> String {
    let mut out = format!("{FIRST}\n{COSTS}\n");
    for (t, c) in costs.iter().enumerate() {
        for (l, lc) in c.levels.iter().enumerate() {
            let _ = writeln!(
                out,
                "{t},{l},{},{},{},{}",
                lc.positions, lc.morph, lc.indices, lc.index_width
            );
        }
    }
    out + FRAMES + "\n"
}

/// A flight's requests, frame by frame, what the predictor expected at each frame, and what
/// its tiles cost.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Trace {
    pub costs: Vec<TileCost>,
    pub frames: Vec<Vec<Request>>,
    /// Per frame: the predicted requests (empty in version 1 traces).
    pub predicted: Vec<Vec<Request>>,
}

/// Appends one frame's requests to `out`.
pub fn write_frame(out: &mut String, frame: u64, requests: &[(Request, u64)]) {
    for (r, bytes) in requests {
        let _ = writeln!(out, "{frame},{},{},{bytes},0", r.tile, r.wanted);
    }
}

/// Appends one frame's predicted requests to `out` (after its requests).
pub fn write_predicted(out: &mut String, frame: u64, predicted: &[(Request, u64)]) {
    for (r, bytes) in predicted {
        let _ = writeln!(out, "{frame},{},{},{bytes},1", r.tile, r.wanted);
    }
}

impl Trace {
    /// Parses a trace; `frames` is at least one past the last frame with a row.
    pub fn parse(text: &str) -> Result<Trace, String> {
        let mut lines = text.lines().enumerate();
        let v1 = match lines.next() {
            Some((_, l)) if l.trim() == FIRST => false,
            Some((_, l)) if l.trim() == FIRST_V1 => true,
            _ => {
                return Err(format!(
                    "not a vkterrain trace (first line must be `{FIRST}`)"
                ))
            }
        };
        let frames_header = if v1 { FRAMES_V1 } else { FRAMES };
        match lines.next() {
            Some((_, l)) if l.trim() == COSTS => {}
            _ => return Err(format!("line 2: expected the header `{COSTS}`")),
        }
        let numbers = |n: usize, line: &str, want: &str| -> Result<Vec<u64>, String> {
            let v: Vec<u64> = line
                .split(',')
                .map(|s| s.trim().parse::<u64>())
                .collect::<Result<_, _>>()
                .map_err(|_| format!("line {}: expected {want}", n + 1))?;
            if v.len() == want.split(',').count() {
                Ok(v)
            } else {
                Err(format!("line {}: expected {want}", n + 1))
            }
        };
        let mut costs: Vec<TileCost> = Vec::new();
        let mut in_frames = false;
        let mut frames: Vec<Vec<Request>> = Vec::new();
        let mut predicted: Vec<Vec<Request>> = Vec::new();
        for (n, line) in lines {
            let line = line.trim();
            if line.is_empty() {
                continue;
            }
            if !in_frames {
                if line == frames_header {
                    in_frames = true;
                    continue;
                }
                let v = numbers(n, line, COSTS)?;
                let (t, l) = (v[0] as usize, v[1] as usize);
                if t > costs.len() || (t == costs.len()) != (l == 0) || t + 1 < costs.len() {
                    return Err(format!(
                        "line {}: costs must list tiles and levels in order",
                        n + 1
                    ));
                }
                if t == costs.len() {
                    costs.push(TileCost::default());
                }
                if costs[t].levels.len() != l || !matches!(v[5], 2 | 4) {
                    return Err(format!("line {}: bad level or index width", n + 1));
                }
                costs[t].levels.push(LevelCost {
                    positions: v[2],
                    morph: v[3],
                    indices: v[4],
                    index_width: v[5] as u32,
                    stream: None,
                });
                continue;
            }
            let v = numbers(n, line, frames_header)?;
            let (frame, tile, wanted, is_predicted) = match v[..] {
                [frame, tile, wanted, _bytes] => (frame, tile, wanted, 0),
                [frame, tile, wanted, _bytes, p] => (frame, tile, wanted, p),
                _ => unreachable!("numbers() checked the count"),
            };
            if is_predicted > 1 {
                return Err(format!("line {}: predicted must be 0 or 1", n + 1));
            }
            let frame = usize::try_from(frame).map_err(|_| format!("line {}: bad frame", n + 1))?;
            if frame + 1 < frames.len() {
                return Err(format!("line {}: frames must not go back", n + 1));
            }
            if frame > 10_000_000 {
                return Err(format!(
                    "line {}: frame {frame} is implausibly large",
                    n + 1
                ));
            }
            let tile = tile as usize;
            if tile >= costs.len() || wanted as usize >= costs[tile].levels.len() {
                return Err(format!(
                    "line {}: tile {tile} level {wanted} not in the costs",
                    n + 1
                ));
            }
            frames.resize_with(frames.len().max(frame + 1), Vec::new);
            predicted.resize_with(frames.len(), Vec::new);
            let r = Request {
                tile: tile as u32,
                wanted: wanted as u32,
            };
            if is_predicted == 1 {
                predicted[frame].push(r);
            } else {
                frames[frame].push(r);
            }
        }
        if !in_frames {
            return Err(format!(
                "no `{frames_header}` header: the trace is truncated"
            ));
        }
        Ok(Trace {
            costs,
            frames,
            predicted,
        })
    }

    /// For Belady's rule: `next(tile, frame)` is the first frame after `frame` requesting
    /// `tile`, u64::MAX if none.
    pub fn next_use(&self) -> impl Fn(TileId, u64) -> u64 + 'static {
        let mut uses: HashMap<TileId, Vec<u64>> = HashMap::new();
        for (f, frame) in self.frames.iter().enumerate() {
            for r in frame {
                uses.entry(r.tile).or_default().push(f as u64);
            }
        }
        move |tile, frame| {
            uses.get(&tile)
                .and_then(|v| {
                    let i = v.partition_point(|&f| f <= frame);
                    v.get(i).copied()
                })
                .unwrap_or(u64::MAX)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn costs() -> Vec<TileCost> {
        let level = |i: u64| LevelCost {
            positions: 40 * (i + 1),
            morph: 10 * i,
            indices: 100 * (i + 1),
            index_width: 2,
            stream: None,
        };
        (0..6)
            .map(|_| TileCost {
                levels: (0..5).map(level).collect(),
            })
            .collect()
    }

    #[test]
    fn round_trip_and_next_use() {
        let mut text = header(&costs());
        let r = |tile, wanted| Request { tile, wanted };
        write_frame(&mut text, 0, &[(r(5, 3), 100), (r(2, 0), 10)]);
        write_predicted(&mut text, 0, &[(r(1, 2), 50)]);
        write_frame(&mut text, 2, &[(r(5, 4), 200)]);
        let t = Trace::parse(&text).unwrap();
        assert_eq!(
            t.frames,
            vec![vec![r(5, 3), r(2, 0)], vec![], vec![r(5, 4)]]
        );
        assert_eq!(t.predicted, vec![vec![r(1, 2)], vec![], vec![]]);
        // Version 1: no predicted column.
        let v1 = text
            .replace(FIRST, FIRST_V1)
            .replace(FRAMES, FRAMES_V1)
            .lines()
            .filter_map(|l| match (l.split(',').count(), l.rsplit_once(',')) {
                // Frame rows: drop predicted ones, and the column.
                (5, Some((_, "1"))) => None,
                (5, Some((row, _))) => Some(row.to_string() + "\n"),
                _ => Some(l.to_string() + "\n"),
            })
            .collect::<String>();
        let t1 = Trace::parse(&v1).unwrap();
        assert_eq!(t1.frames, t.frames);
        let next = t.next_use();
        assert_eq!(next(5, 0), 2);
        assert_eq!(next(2, 0), u64::MAX);
        assert!(Trace::parse("frame,tile\n").is_err());
        let lines = 2 + 6 * 5 + 1;
        let mut back = header(&costs());
        write_frame(&mut back, 3, &[(r(1, 1), 1)]);
        write_frame(&mut back, 1, &[(r(1, 1), 1)]);
        let e = Trace::parse(&back).unwrap_err();
        assert!(e.contains(&format!("line {}", lines + 2)), "{e}");
        let mut unknown = header(&costs());
        write_frame(&mut unknown, 0, &[(r(9, 1), 1)]);
        assert!(Trace::parse(&unknown)
            .unwrap_err()
            .contains("not in the costs"));
        assert!(Trace::parse(&header(&costs())[..40]).is_err(), "truncated");
    }
}
