//! Index arrays built on the GPU (`spirv/shaders/indices.comp`) from the vertex blocks already
//! in the tile pool: a level's index array then crosses no bus, and the upload budget pays for
//! blocks only (`memory::IndexArrays::Built`). One workgroup builds one array, with a scratch
//! lookup of its own; a frame's builds go in dispatches of as many workgroups as there are
//! lookups (at most [`MAX_BUILDS_PER_DISPATCH`]), after the frame's copies and before its draws. Each frame slot has its own
//! build list and a status word the shader raises when a built array does not have the count
//! the file gives (a tile set whose vertices do not make the mesh it claims).

use ash::vk;
use bytemuck::{Pod, Zeroable};

use super::compute::{self, PassBuffers, StoragePass, STATUS_BYTES};
use super::sync;
use super::{Buffer, Gpu, VkError, VkResult};

/// Workgroups (arrays) per dispatch at most, each with its own lookup of 257 x 257 words.
pub const MAX_BUILDS_PER_DISPATCH: u32 = 8;
const LOOKUP_BYTES: u64 = 257 * 257 * 4;

/// One array to build (the shader's `Build`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct Build {
    /// Pool word of block 0's first packed position.
    pub vertex_word: u32,
    /// Vertices of blocks `0..=level`.
    pub vertex_count: u32,
    /// Pool position of the array's first index, in indices of its width.
    pub index_at: u32,
    pub index_count: u32,
    /// 2 or 4 bytes.
    pub index_width: u32,
    /// Last column and row the tile's meshes cover.
    pub mesh_max_x: u32,
    pub mesh_max_y: u32,
    /// Reported when the build fails.
    pub tile: u32,
    /// 1: the tile is drawn part by part ([`tiles::parts`]) at `parts`, its levels 4 bits
    /// each (part `k` at bits `4 k`), with `ends[l]` the end of block `l`. 0: one level.
    pub mixed: u32,
    pub parts: [u32; 2],
    pub ends: [u32; 16],
    pub pad: u32,
}

impl Build {
    /// Makes the build draw `key` part by part; `ends` are the ends of the tile's blocks.
    pub fn part_by_part(&mut self, key: &tiles::parts::PartKey, ends: impl Iterator<Item = u32>) {
        self.mixed = 1;
        self.parts = tiles::parts::packed_levels(&key.levels);
        for (slot, end) in self.ends.iter_mut().zip(ends) {
            *slot = end;
        }
    }
}

/// A build whose array did not come out as the file says (read after its frame completed).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BuildFailure {
    pub failed: u32,
    pub tile: u32,
    /// Indices the GPU found (`u32::MAX`: a fan vertex was missing), and the file's count.
    pub got: u32,
    pub expected: u32,
}

pub struct IndexBuilder {
    pass: StoragePass,
    /// The lookups (scratch), and per frame slot the builds and the status.
    buffers: PassBuffers,
    /// Builds a slot's list holds.
    capacity: usize,
    /// Lookups in the scratch: workgroups per dispatch.
    lookups: u32,
}

impl IndexBuilder {
    /// A builder writing into `pool`, for `slots` frame slots of up to `capacity` builds each,
    /// with `lookups` (1 to [`MAX_BUILDS_PER_DISPATCH`]) arrays built at once.
    pub fn new(
        gpu: &Gpu,
        pool: &Buffer,
        slots: usize,
        capacity: usize,
        lookups: u32,
    ) -> VkResult<Self> {
        let lookups = lookups.clamp(1, MAX_BUILDS_PER_DISPATCH);
        if !gpu.storage_16bit {
            return Err(VkError::Unsupported(
                "building index arrays on the GPU needs storageBuffer16BitAccess".into(),
            ));
        }
        let (slots, capacity) = (slots.max(1), capacity.max(1));
        let sizes = (
            LOOKUP_BYTES * u64::from(lookups),
            (capacity * std::mem::size_of::<Build>()) as u64,
        );
        let buffers = PassBuffers::new(gpu, sizes, slots, "index build")?;
        let range = pool
            .size
            .min(u64::from(gpu.properties.limits.max_storage_buffer_range));
        let sets: Vec<Vec<(&Buffer, u64)>> = (0..slots)
            .map(|s| {
                vec![
                    (pool, range),
                    (pool, range),
                    (pool, range),
                    (&buffers.scratch, vk::WHOLE_SIZE),
                    (&buffers.lists[s], vk::WHOLE_SIZE),
                    (&buffers.status[s], vk::WHOLE_SIZE),
                ]
            })
            .collect();
        match StoragePass::new(gpu, (spirv::INDICES_COMP, "index build"), 8, &sets) {
            Ok(pass) => Ok(IndexBuilder {
                pass,
                buffers,
                capacity,
                lookups,
            }),
            Err(e) => {
                buffers.destroy(gpu);
                Err(e)
            }
        }
    }

    /// Builds a slot's list holds.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Bytes of GPU memory the builder holds beside the pool (lookups, lists, status).
    pub fn bytes(&self) -> u64 {
        self.buffers.bytes()
    }

    /// Writes slot `s`'s builds (its previous frame has completed); false if they do not fit.
    pub fn write(&mut self, s: usize, builds: &[Build]) -> bool {
        builds.len() <= self.capacity
            && self.buffers.lists[s].write(0, bytemuck::cast_slice(builds))
    }

    /// Who reads what the builds write: the draws' index reads and vertex shaders (which read
    /// the pool the arrays are built in: other bytes of the one buffer, which the validation
    /// layer cannot tell apart), the copies (a chunk moved) and the host (the build status).
    pub const READERS: (vk::PipelineStageFlags, vk::AccessFlags) = (
        vk::PipelineStageFlags::from_raw(
            vk::PipelineStageFlags::VERTEX_INPUT.as_raw()
                | vk::PipelineStageFlags::VERTEX_SHADER.as_raw()
                | vk::PipelineStageFlags::TRANSFER.as_raw()
                | vk::PipelineStageFlags::HOST.as_raw(),
        ),
        vk::AccessFlags::from_raw(
            vk::AccessFlags::INDEX_READ.as_raw()
                | vk::AccessFlags::SHADER_READ.as_raw()
                | vk::AccessFlags::TRANSFER_READ.as_raw()
                | vk::AccessFlags::HOST_READ.as_raw(),
        ),
    );

    /// Records slot `s`'s first `count` builds: after the frame's copies (and earlier frames'
    /// draws of the regions they rewrite), before its draws. With `pass_follows` the morph
    /// pass is recorded next, and its barriers order the builds before it and make them
    /// visible to their readers ([`crate::vulkan::morph_pass::MorphPass::record`]): one
    /// barrier between the two dispatches instead of two.
    pub fn record(
        &self,
        gpu: &Gpu,
        cmd: vk::CommandBuffer,
        (s, count): (usize, u32),
        pass_follows: bool,
    ) {
        if count == 0 {
            return;
        }
        let compute = vk::PipelineStageFlags::COMPUTE_SHADER;
        let shader = vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE;
        let earlier = vk::PipelineStageFlags::VERTEX_INPUT
            | vk::PipelineStageFlags::VERTEX_SHADER
            | vk::PipelineStageFlags::TRANSFER
            | compute;
        let written = vk::AccessFlags::TRANSFER_WRITE | vk::AccessFlags::SHADER_WRITE;
        sync::memory_barrier(gpu, cmd, (earlier, written), (compute, shader));
        self.pass.bind(gpu, cmd, s);
        let mut first = 0;
        while first < count {
            if first > 0 {
                // The next dispatch reuses the lookups.
                sync::memory_barrier(gpu, cmd, (compute, shader), (compute, shader));
            }
            let n = (count - first).min(self.lookups);
            let push = [first, u32::MAX];
            self.pass.dispatch(gpu, cmd, bytemuck::bytes_of(&push), n);
            first += n;
        }
        if pass_follows {
            return;
        }
        let (readers, reads) = Self::READERS;
        sync::memory_barrier(
            gpu,
            cmd,
            (compute, vk::AccessFlags::SHADER_WRITE),
            (readers, reads),
        );
    }

    /// After slot `s`'s frame completed: its first failed build, if any (and the status is
    /// cleared for the slot's next frame).
    pub fn take_failure(&mut self, s: usize) -> Option<BuildFailure> {
        let words = compute::take_status(&mut self.buffers.status[s])?;
        Some(BuildFailure {
            failed: words[0],
            tile: words[1],
            got: words[2],
            expected: words[3],
        })
    }

    pub fn destroy(self, gpu: &Gpu) {
        self.pass.destroy(gpu);
        self.buffers.destroy(gpu);
    }
}

/// The builder's memory as `memory::budget` sizes it before one exists: per array built at once
/// a lookup, per frame slot a build list and a status word ([`IndexBuilder::bytes`] once made).
pub fn builder_cost() -> memory::budget::BuilderCost {
    memory::budget::BuilderCost {
        lookup_bytes: LOOKUP_BYTES,
        build_bytes: std::mem::size_of::<Build>() as u64,
        status_bytes: STATUS_BYTES,
        max_lookups: MAX_BUILDS_PER_DISPATCH,
    }
}
