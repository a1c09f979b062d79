//! GPU memory manager for tile data (paper, section 6, "explicit memory management"): one pool
//! of device memory allocated at start and carved into chunks of exponentially growing size
//! classes ([`classes`]), a least-recently-used list per class with victims chosen by a mixture
//! of age and tightness of fit, and progressive level uploads within a per-frame byte budget.
//!
//! The crate decides; it does not touch the GPU. Each frame the renderer passes the visible
//! tiles (front to back, with the level LOD wants for each) to [`Manager::plan_frame`] and gets
//! back the level to draw for each, where its data sits in the pool, the uploads and in-pool
//! moves to record, and the frame's counters. Chunks a frame still in flight may read are
//! never reused before that frame completes (the caller says which frames have). At start,
//! [`budget`] splits the GPU budget between texture slots, the GPU index builder and the pool.
//!
//! # Chunk layout
//!
//! A chunk sized for capacity level `c` is laid out as
//!
//! ```text
//! | positions: block 0 | ... | block c | morph: block 1 | ... | block c | index region .......... |
//! ^ chunk offset (256-aligned)          ^ P(c)                   ^ align4(P(c) + M(c))   chunk end ^
//! ```
//!
//! Positions of blocks `0..=c` are contiguous and in block order, so the index array of any
//! level `l <= c` addresses them with one `vertexOffset` (the chunk offset / 4). Block `j`'s
//! morph offsets (`j` rows of `block_len` bytes, one per coarser level, as in the file) follow
//! the positions, each block padded to 4 bytes. The index region runs to the chunk's end and is
//! at least as large as the largest index array of levels `0..=c`. It holds the index array of
//! the level drawn and, when prefetching has sent it and there is room, a *spare*: the array of
//! a finer level whose blocks are resident, placed apart from the drawn one (at the region's
//! end, or at its start when the drawn array sits at the end), so it is written while the other
//! is read. The frame that wants the spare's level draws it where it is and sends nothing; the
//! two alternate between the region's ends as the tile refines. A refinement without a spare
//! appends blocks and writes its index array at the region's start; nothing else moves.
//! A tile refined past its chunk's capacity moves to a larger chunk: its blocks are copied
//! inside device memory and the new level's blocks and index array are uploaded.
//!
//! The whole-tile scheme (the comparison baseline, and `vkterrain --draw-only`) lays the
//! blocks out the same way for the finest level and then every level's index array in turn,
//! each starting 4-aligned, so any level can be drawn.
//!
//! ```
//! use memory::{Config, LevelCost, Manager, Request, TileCost};
//!
//! // One tile of two levels: 100 then 300 vertices, u16 indices.
//! let tile = TileCost {
//!     levels: vec![
//!         LevelCost { positions: 400, morph: 0, indices: 700, index_width: 2, stream: None },
//!         LevelCost { positions: 800, morph: 200, indices: 2_000, index_width: 2, stream: None },
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

pub mod budget;
pub mod classes;
pub mod cost;
pub mod costs;
mod lru;
pub mod manager;
pub mod sim;
pub mod textures;
pub mod trace;

pub use classes::ClassPlan;
pub use cost::{Layout, LevelCost, TileCost};
pub use manager::{
    gpu_builds, Config, FramePlan, Grant, IndexArrays, Manager, Move, Part, Request, Scheme, Stats,
    TileId, Upload, Victim, DEFAULT_DOWNGRADE_SLACK, DEFAULT_PREFETCH_FREE, DEFAULT_UPLOAD_BUDGET,
    DEFAULT_WEIGHT,
};
pub use textures::{
    TextureConfig, TextureGrant, TextureRequest, TextureSlots, TextureStats, TextureUpload,
};

#[cfg(test)]
mod tests;
