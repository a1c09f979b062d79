//! Residency traces: what each frame of a flight asked of the manager, to replay offline.
//!
//! Format (CSV, written by `vkterrain --trace FILE`, read by `memsim`):
//!
//! ```text
//! # vkterrain trace v1
//! frame,tile,wanted,bytes
//! 0,5,3,48812
//! ```
//!
//! One row per visible tile per frame, in the frame's front-to-back order. `tile` is the tile's
//! index in the tile set (row-major), `wanted` the level LOD chose, `bytes` what drawing that
//! level costs from scratch (blocks `0..=wanted` with their morph rows, and the index array).
//! A frame with no visible tile has no row.

use std::collections::HashMap;
use std::fmt::Write as _;

use crate::manager::{Request, TileId};

pub const HEADER: &str = "# vkterrain trace v1\nframe,tile,wanted,bytes\n";

/// A flight's requests, frame by frame.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Trace {
    pub frames: Vec<Vec<Request>>,
}

/// Appends one frame's rows to `out`.
pub fn write_frame(out: &mut String, frame: u64, requests: &[(Request, u64)]) {
    for (r, bytes) in requests {
        let _ = writeln!(out, "{frame},{},{},{bytes}", r.tile, r.wanted);
    }
}

impl Trace {
    /// Parses a trace; `frames` is at least one past the last frame with a row.
    pub fn parse(text: &str) -> Result<Trace, String> {
        let mut lines = text.lines().enumerate();
        match lines.next() {
            Some((_, l)) if l.trim() == "# vkterrain trace v1" => {}
            _ => {
                return Err(
                    "not a vkterrain trace (first line must be `# vkterrain trace v1`)".into(),
                )
            }
        }
        match lines.next() {
            Some((_, l)) if l.trim() == "frame,tile,wanted,bytes" => {}
            _ => return Err("line 2: expected the header `frame,tile,wanted,bytes`".into()),
        }
        let mut frames: Vec<Vec<Request>> = Vec::new();
        for (n, line) in lines {
            if line.trim().is_empty() {
                continue;
            }
            let bad = || format!("line {}: expected frame,tile,wanted,bytes", n + 1);
            let f: Vec<u64> = line
                .split(',')
                .map(|s| s.trim().parse::<u64>())
                .collect::<Result<_, _>>()
                .map_err(|_| bad())?;
            let [frame, tile, wanted, _bytes] = f[..] else {
                return Err(bad());
            };
            let frame = usize::try_from(frame).map_err(|_| bad())?;
            if frame + 1 < frames.len() {
                return Err(format!("line {}: frames must not go back", n + 1));
            }
            if frame > 10_000_000 {
                return Err(format!(
                    "line {}: frame {frame} is implausibly large",
                    n + 1
                ));
            }
            frames.resize_with(frames.len().max(frame + 1), Vec::new);
            frames[frame].push(Request {
                tile: u32::try_from(tile).map_err(|_| bad())?,
                wanted: u32::try_from(wanted).map_err(|_| bad())?,
            });
        }
        Ok(Trace { frames })
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

    #[test]
    fn round_trip_and_next_use() {
        let mut text = HEADER.to_string();
        let r = |tile, wanted| Request { tile, wanted };
        write_frame(&mut text, 0, &[(r(5, 3), 100), (r(2, 0), 10)]);
        write_frame(&mut text, 2, &[(r(5, 4), 200)]);
        let t = Trace::parse(&text).unwrap();
        assert_eq!(
            t.frames,
            vec![vec![r(5, 3), r(2, 0)], vec![], vec![r(5, 4)]]
        );
        let next = t.next_use();
        assert_eq!(next(5, 0), 2);
        assert_eq!(next(2, 0), u64::MAX);
        assert!(Trace::parse("frame,tile\n").is_err());
        let mut back = HEADER.to_string();
        write_frame(&mut back, 3, &[(r(1, 1), 1)]);
        write_frame(&mut back, 1, &[(r(1, 1), 1)]);
        assert!(Trace::parse(&back).unwrap_err().contains("line 4"));
    }
}
