//! The vkterrain tile model: the nested restricted-quadtree hierarchy of Schneider &
//! Westermann (2006, section 4), its packing, and the `.vkt` file that holds it.
//!
//! `tiletool` builds tile sets with [`build::build_tileset`]; the renderer maps them with
//! [`format::TileSet`] and reads each tile's levels as GPU-ready slices:
//!
//! ```no_run
//! # fn main() -> Result<(), tiles::format::FormatError> {
//! let set = tiles::format::TileSet::open(std::path::Path::new("sample.vkt"))?;
//! let tile = set.tile(0, 0)?;
//! let level = tile.level(3).expect("the set has 9 levels");
//! println!("{} vertices, {} triangles, max error {} m",
//!     level.entry.vertex_count(), level.entry.triangle_count, level.entry.max_error);
//! # Ok(()) }
//! ```

pub mod build;
pub mod compact;
pub mod format;
pub mod grid;
pub mod mesh;
pub mod ordered;
pub mod pack;
pub mod parts;
pub mod pyramid;
pub mod quantise;
pub mod rings;
pub mod shard;
pub mod texture;
pub mod units;
pub mod verify;

pub use build::{
    build_tile, build_tileset, build_tileset_textured, BuildParams, BuildSummary, TileSetMeta,
};
pub use format::{FormatError, TileSet};
pub use grid::Grid;

/// Why a build failed.
#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    #[error("{0}")]
    Params(String),
    #[error(transparent)]
    Format(#[from] FormatError),
    /// Reading the heights of a band failed (the message names the file).
    #[error("{0}")]
    Input(String),
    /// A broken invariant of the mesher: a bug, reported rather than written.
    #[error("internal error: {0}")]
    Internal(String),
}

/// How much free memory glibc's allocator keeps at the top of each heap instead of handing it
/// back to the kernel ([`hold_freed_memory`]).
pub const HELD_FREE_BYTES: usize = 64 << 20;

/// Makes the allocator keep up to [`HELD_FREE_BYTES`] of freed memory at the top of each of
/// its heaps (glibc's `M_TOP_PAD`). `tiletool`, `tilebench` and `vkterrain` call it first thing,
/// before any thread starts.
///
/// By default glibc hands the top of a heap back to the kernel (`madvise`) as soon as a large
/// block there is freed, and the next allocation faults the same pages in again, each one
/// zeroed by the kernel. A build allocates and frees a few megabytes per tile on each thread
/// (the relief texture's images and mips above all): the GENERATED 4K mirror's build spent
/// 2.2-2.8 s of system time against 10-15 s of user time, and its threads waited on each
/// other's page faults. Lavapipe, whose compiled shaders write each frame's vertices into memory
/// it allocates and frees (perf: most page faults in its JIT code), spent 1.7-2.9 s of system
/// time on a 60-frame brute-force flight. Holding the memory
/// keeps the process at about what it touched at its peak (bench/README.md, "Freed memory
/// held"). `MALLOC_TOP_PAD_` in the environment, where set, stands instead. Elsewhere than
/// glibc this does nothing.
pub fn hold_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    if std::env::var_os("MALLOC_TOP_PAD_").is_none() {
        // SAFETY: mallopt only sets one of the allocator's tunables, under its own lock.
        unsafe { libc::mallopt(libc::M_TOP_PAD, HELD_FREE_BYTES as libc::c_int) };
    }
}
