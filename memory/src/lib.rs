//! GPU memory manager for tile data (paper, section 6, "explicit memory management"): one pool
//! of device memory allocated at start and carved into chunks of exponentially growing size
//! classes ([`classes`]), a least-recently-used list per class with victims chosen by a mixture
//! of age and tightness of fit, and progressive level uploads within a per-frame byte budget.
//!
//! The crate decides; it does not touch the GPU. Each frame the renderer passes the visible
//! tiles (front to back, with the level LOD wants for each) to [`Manager::plan_frame`] and gets
//! back the level to draw for each, where its data sits in the pool, the uploads and in-pool
//! moves to record, and the frame's counters. A tile's chunk holds its blocks `0..=L`
//! (positions and morph rows) and the index array of the level drawn; the layout is in
//! [`cost`]. Chunks a frame still in flight may read are never reused before that frame
//! completes (the caller says which frames have).
//!
//! ```
//! use memory::{Config, LevelCost, Manager, Request, TileCost};
//!
//! // One tile of two levels: 100 then 300 vertices, u16 indices.
//! let tile = TileCost {
//!     levels: vec![
//!         LevelCost { positions: 400, morph: 0, indices: 700, index_width: 2 },
//!         LevelCost { positions: 800, morph: 200, indices: 2_000, index_width: 2 },
//!     ],
//! };
//! let mut manager = Manager::new(vec![tile], Config::default());
//! let plan = manager.plan_frame(0, None, &[Request { tile: 0, wanted: 1 }], true);
//! assert_eq!(plan.grants[0].level, Some(1));
//! // Level 0 (block 0, index array 0), then block 1 with its morph rows and index array 1.
//! assert_eq!(plan.stats.upload_bytes_blocks, 400 + 800 + 200);
//! assert_eq!(plan.stats.upload_bytes_indices, 700 + 2_000);
//! // The next frame finds it resident.
//! let plan = manager.plan_frame(1, Some(0), &[Request { tile: 0, wanted: 1 }], true);
//! assert_eq!((plan.stats.hits, plan.uploads.len()), (1, 0));
//! ```

pub mod classes;
pub mod cost;
mod lru;
pub mod manager;
pub mod sim;
pub mod trace;

pub use classes::ClassPlan;
pub use cost::{Layout, LevelCost, TileCost};
pub use manager::{
    Config, FramePlan, Grant, Manager, Move, Part, Request, Scheme, Stats, TileId, Upload, Victim,
    DEFAULT_DOWNGRADE_SLACK, DEFAULT_UPLOAD_BUDGET, DEFAULT_WEIGHT,
};

#[cfg(test)]
mod tests;
