//! The `vkterrain` renderer: a Vulkan (ash) frame loop over a `.vkt` tile set, with frustum
//! culling, screen-space-error LOD from the projection's Jacobian, crack-free stitching
//! between tiles, progressive residency in a fixed GPU pool (the `memory` crate), frames in
//! flight, and a frame-timing log.
//!
//! Terrain logic ([`cull`], [`lod`], [`stitch`], [`plan`], [`path`]) is plain Rust that
//! tests drive without a GPU; [`vulkan`] is the thin layer that owns every Vulkan object, and
//! [`frame`] turns one frame's plan into commands.

pub use scene::{camera, levels, path, terrain, tile};

pub mod cull;
pub mod cut;
pub mod error;
pub mod fault;
pub mod frame;
pub mod headless;
pub mod interface;
pub mod limit;
pub mod lod;
pub mod log;
pub mod measure;
pub mod morph;
pub mod parts;
pub mod plan;
pub mod prefetch;
pub mod settings;
pub mod stitch;
pub mod target;
pub mod textures;
pub mod vulkan;
pub mod window;

#[cfg(test)]
mod test_rng;
