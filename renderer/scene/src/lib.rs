//! What `vkterrain` flies over and how, in plain Rust with no Vulkan: the tile set as opened and
//! checked ([`terrain`]), each tile and the sides it shares ([`tile`]), the level tables
//! geomorphing takes its vertices' levels from ([`levels`]), the camera ([`camera`]) and camera
//! paths ([`path`]). The renderer re-exports these modules under the same names; the fuzzer
//! opens tile sets and parses paths through this crate alone, without linking a GPU stack.

pub mod camera;
pub mod levels;
pub mod path;
pub mod store;
pub mod terrain;
pub mod tile;
