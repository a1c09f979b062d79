//! Index arrays made on the CPU ([`MemoryOptions::build_on_gpu`] false, the default on a
//! software rasteriser: [`crate::settings::builds_pay_on`]). Each array the frame would give
//! the GPU's builder is made here, put in the slot's staging memory after the frame's uploads,
//! and copied into its place by the frame's commands where the builder's dispatch runs: after
//! the frame's copies and after earlier frames' reads of the regions it rewrites, before the
//! draws. An array the staging memory has no room left for is built by the GPU's builder as
//! before, so the staging bound the uploads were sized by still holds.
//!
//! What is made is what the builder would build, as its header says:
//! - a level's whole array is the file's: the tile's check compared it with the level's
//!   vertices, fans, counts and borders before the tile was drawn (the GPU rotates each ring to
//!   start where the previous fan left off; the file's rings start where the builder's model of
//!   a vertex cache did: the same fans in the same order);
//! - a mix of the parts' levels is [`tiles::parts::Blocks::indices`], the CPU side of the
//!   builder's mixed walk, from the positions of the blocks the mix reads
//!   ([`crate::parts::blocks_through`]), and must be as long
//!   as the tables said when the draw was planned (the builder checks the same on the GPU).
//!
//! [`MemoryOptions::build_on_gpu`]: crate::settings::MemoryOptions::build_on_gpu

use ash::vk;
use tiles::parts::{PartKey, RESTART};

use crate::error::FrameError;
use crate::terrain::Terrain;
use crate::vulkan::indices::Build;
use crate::vulkan::pool::Staging;

/// What one build makes: level `L`'s whole array, or a mix of the parts' levels.
#[derive(Clone, Copy, Debug)]
pub(super) enum Array {
    Level(u32),
    Mix(PartKey),
}

/// Makes each of `builds` (the builder's records, with the tile and what each makes) that fits
/// in `staging` after what the frame put there, and returns the copies into the pool and the
/// builds left to the GPU's builder.
pub(super) fn make(
    terrain: &Terrain,
    builds: Vec<(Build, usize, Array)>,
    staging: &mut Staging,
) -> Result<(Vec<vk::BufferCopy>, Vec<Build>), FrameError> {
    let mut copies = Vec::with_capacity(builds.len());
    let mut left = Vec::new();
    for (build, tile, array) in builds {
        let bytes = array_bytes(terrain, &build, tile, array)?;
        match staging.push(&bytes) {
            Some(at) => copies.push(
                vk::BufferCopy::default()
                    .src_offset(at)
                    .dst_offset(u64::from(build.index_at) * u64::from(build.index_width))
                    .size(bytes.len() as u64),
            ),
            None => left.push(build),
        }
    }
    Ok((copies, left))
}

/// The bytes of one array, in the build's index width (restarts all ones).
fn array_bytes(
    terrain: &Terrain,
    build: &Build,
    tile: usize,
    array: Array,
) -> Result<Vec<u8>, FrameError> {
    let failed = |what: String| FrameError::MadeArray { tile, what };
    let want = u64::from(build.index_count) * u64::from(build.index_width);
    let indices: Vec<u32> = match array {
        Array::Level(level) => {
            let part = memory::Part::Indices(level);
            let bytes = terrain.part(tile, part).ok_or(FrameError::MissingPart {
                tile: tile as u32,
                part,
            })?;
            if bytes.len() as u64 != want {
                return Err(failed(format!(
                    "level {level}'s array is {} bytes, its build {want}",
                    bytes.len()
                )));
            }
            return Ok(bytes.to_vec());
        }
        Array::Mix(key) => {
            let levels = u32::from(key.levels.iter().copied().max().unwrap_or(0)) + 1;
            let blocks = crate::parts::blocks_through(terrain, tile, levels).ok_or_else(|| {
                failed(format!("its blocks 0..{levels} have not passed the check"))
            })?;
            blocks
                .indices(&key)
                .ok_or_else(|| failed("a fan of its mix lacks a vertex".into()))?
        }
    };
    if indices.len() as u64 != u64::from(build.index_count) {
        return Err(failed(format!(
            "its mix has {} indices, its tables said {}",
            indices.len(),
            build.index_count
        )));
    }
    Ok(match build.index_width {
        2 => indices
            .iter()
            .flat_map(|&i| {
                let narrow = if i == RESTART { u16::MAX } else { i as u16 };
                narrow.to_le_bytes()
            })
            .collect(),
        _ => indices.iter().flat_map(|&i| i.to_le_bytes()).collect(),
    })
}
