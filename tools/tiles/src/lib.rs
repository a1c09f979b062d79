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
