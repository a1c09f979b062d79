//! `frametimes`: reads the frame-timing logs `vkterrain` writes and compares them the way
//! performance engineers do: distributions rather than averages, ratios with a statement of
//! whether a difference is beyond noise, and a plot.
//!
//! ```no_run
//! let a = frametimes::log::read(std::path::Path::new("before.csv"))?;
//! let s = frametimes::stats::Stats::of(&a, 1000.0 / 60.0);
//! println!("median {:.2} ms, p99 {:.2} ms", s.median_ms, s.p99_ms);
//! # Ok::<(), frametimes::log::LogError>(())
//! ```

pub mod compare;
pub mod log;
pub mod plot;
pub mod stats;
