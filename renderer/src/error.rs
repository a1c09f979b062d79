//! Why a frame could not be made. Each way names what went wrong, with the numbers a user or a
//! bug report needs; none of them panics, and the caller ends the flight with the message.

use std::path::PathBuf;

use crate::plan::BorderMismatch;
use crate::vulkan::VkError;

#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    #[error(transparent)]
    Gpu(#[from] VkError),
    #[error(transparent)]
    TileSet(#[from] BorderMismatch),
    /// Reading a mapped file that shrank would fault (SIGBUS), so every frame that reads the
    /// file checks its length first.
    #[error("{}: the tile set changed on disk while in use ({now} bytes, was {was})", path.display())]
    FileChanged {
        path: PathBuf,
        /// The length now, or why it could not be read.
        now: String,
        was: u64,
    },
    /// The plan asked for a part the tile set does not hold.
    #[error("tile {tile} has no {part:?}")]
    MissingPart { tile: u32, part: memory::Part },
    #[error("tile {tile} has no texture mip {mip}")]
    MissingTextureMip { tile: u32, mip: u32 },
    /// More bytes to stage than the bound the slot's staging memory was sized by.
    #[error("staging ring full ({used} bytes) uploading tile {tile}{what}")]
    StagingFull {
        used: u64,
        tile: u32,
        /// What of the tile ("" for geometry, "'s texture").
        what: &'static str,
    },
    /// An upload marked as built on the GPU that is not an index array.
    #[error("tile {tile}: {part:?} built")]
    BuiltNotIndices { tile: u32, part: memory::Part },
    /// The index builder addresses the pool in 32-bit words.
    #[error("pool offset {bytes} past 32-bit indexing")]
    PastIndexing { bytes: u64 },
    /// An index array made on the CPU did not come out as the tile's tables say.
    #[error("tile #{tile}: the index array made from its checked levels: {what}")]
    MadeArray { tile: usize, what: String },
    #[error("{builds} index builds in one frame (room for {capacity})")]
    TooManyBuilds { builds: usize, capacity: usize },
    #[error("{decodes} compact levels to decode in one frame (room for {capacity})")]
    TooManyDecodes { decodes: usize, capacity: usize },
    #[error("stitch geometry ({bytes} bytes) does not fit its buffer ({capacity} bytes)")]
    StitchesOverflow { bytes: u64, capacity: u64 },
    #[error("{tiles} tiles in view; at most {max} can be drawn in one frame")]
    TooManyTiles { tiles: usize, max: usize },
    #[error("{records} tile records do not fit their buffer ({capacity} bytes)")]
    RecordsOverflow { records: usize, capacity: u64 },
}
