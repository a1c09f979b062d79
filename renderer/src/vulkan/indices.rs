//! Index arrays built on the GPU (`spirv/shaders/indices.comp`) from the vertex blocks already
//! in the tile pool: a level's index array then crosses no bus, and the upload budget pays for
//! blocks only (`memory::IndexArrays::Built`). One workgroup builds one array, with a scratch
//! lookup of its own; a frame's builds go in dispatches of as many workgroups as there are
//! lookups (at most [`MAX_BUILDS_PER_DISPATCH`]), after the frame's copies and before its draws. Each frame slot has its own
//! build list and a status word the shader raises when a built array does not have the count
//! the file gives (a tile set whose vertices do not make the mesh it claims).

use ash::vk;
use bytemuck::{Pod, Zeroable};
use gpu_allocator::MemoryLocation;

use super::buffer::BufferDesc;
use super::sync;
use super::{Buffer, Gpu, VkError, VkResult};

/// Workgroups (arrays) per dispatch at most, each with its own lookup of 257 x 257 words.
pub const MAX_BUILDS_PER_DISPATCH: u32 = 8;
const LOOKUP_BYTES: u64 = 257 * 257 * 4;
const STATUS_BYTES: u64 = 16;

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
    set_layout: vk::DescriptorSetLayout,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    descriptors: vk::DescriptorPool,
    /// Per frame slot.
    sets: Vec<vk::DescriptorSet>,
    builds: Vec<Buffer>,
    status: Vec<Buffer>,
    scratch: Buffer,
    /// Builds a slot's list holds.
    capacity: usize,
    /// Lookups in `scratch`: workgroups per dispatch.
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
        let bindings: Vec<_> = (0..6)
            .map(|b| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        let set_info = vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings);
        // SAFETY: valid create info.
        let set_layout = unsafe { gpu.device.create_descriptor_set_layout(&set_info, None) }?;
        gpu.name(set_layout, "index build set layout");
        let mut builder = IndexBuilder {
            set_layout,
            layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
            descriptors: vk::DescriptorPool::null(),
            sets: Vec::new(),
            builds: Vec::new(),
            status: Vec::new(),
            scratch: Buffer::new(
                gpu,
                BufferDesc {
                    size: LOOKUP_BYTES * u64::from(lookups),
                    usage: vk::BufferUsageFlags::STORAGE_BUFFER,
                    location: MemoryLocation::GpuOnly,
                },
                "index build lookup",
            )?,
            capacity: capacity.max(1),
            lookups,
        };
        // On failure the partly made builder is destroyed (null handles are skipped).
        match builder.create(gpu, pool, slots.max(1)) {
            Ok(()) => Ok(builder),
            Err(e) => {
                builder.destroy(gpu);
                Err(e)
            }
        }
    }

    /// The compute pipeline and its layout, then the sets.
    fn create(&mut self, gpu: &Gpu, pool: &Buffer, slots: usize) -> VkResult<()> {
        let ranges = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::COMPUTE)
            .size(8)];
        let set_layouts = [self.set_layout];
        let layout_info = vk::PipelineLayoutCreateInfo::default()
            .set_layouts(&set_layouts)
            .push_constant_ranges(&ranges);
        // SAFETY: valid create info.
        self.layout = unsafe { gpu.device.create_pipeline_layout(&layout_info, None) }?;
        gpu.name(self.layout, "index build pipeline layout");
        self.pipeline = super::pipeline::compute_pipeline(
            gpu,
            spirv::INDICES_COMP,
            self.layout,
            "index build pipeline",
        )?;
        self.create_sets(gpu, pool, slots)
    }

    /// The per-slot build lists and status buffers, and a descriptor set per slot over them,
    /// the pool and the lookups.
    fn create_sets(&mut self, gpu: &Gpu, pool: &Buffer, slots: usize) -> VkResult<()> {
        let sizes = [vk::DescriptorPoolSize::default()
            .ty(vk::DescriptorType::STORAGE_BUFFER)
            .descriptor_count(6 * slots as u32)];
        let info = vk::DescriptorPoolCreateInfo::default()
            .max_sets(slots as u32)
            .pool_sizes(&sizes);
        // SAFETY: valid create info.
        self.descriptors = unsafe { gpu.device.create_descriptor_pool(&info, None) }?;
        gpu.name(self.descriptors, "index build descriptors");
        let layouts = vec![self.set_layout; slots];
        let alloc = vk::DescriptorSetAllocateInfo::default()
            .descriptor_pool(self.descriptors)
            .set_layouts(&layouts);
        // SAFETY: the pool has room for these sets.
        self.sets = unsafe { gpu.device.allocate_descriptor_sets(&alloc) }?;
        let list_bytes = (self.capacity * std::mem::size_of::<Build>()) as u64;
        for s in 0..slots {
            self.builds.push(Buffer::new(
                gpu,
                BufferDesc::upload(list_bytes, vk::BufferUsageFlags::STORAGE_BUFFER),
                &format!("index builds, slot {s}"),
            )?);
            let mut status = Buffer::new(
                gpu,
                BufferDesc {
                    size: STATUS_BYTES,
                    usage: vk::BufferUsageFlags::STORAGE_BUFFER,
                    location: MemoryLocation::GpuToCpu,
                },
                &format!("index build status, slot {s}"),
            )?;
            if !status.write(0, &[0; STATUS_BYTES as usize]) {
                return Err(VkError::Unsupported(
                    "the index build status is not host-visible".into(),
                ));
            }
            self.status.push(status);
        }
        let range = pool
            .size
            .min(u64::from(gpu.properties.limits.max_storage_buffer_range));
        for (s, &set) in self.sets.iter().enumerate() {
            let whole = |buffer: &Buffer, range: u64| {
                [vk::DescriptorBufferInfo::default()
                    .buffer(buffer.raw)
                    .range(range)]
            };
            let infos = [
                whole(pool, range),
                whole(pool, range),
                whole(pool, range),
                whole(&self.scratch, vk::WHOLE_SIZE),
                whole(&self.builds[s], vk::WHOLE_SIZE),
                whole(&self.status[s], vk::WHOLE_SIZE),
            ];
            let writes: Vec<_> = infos
                .iter()
                .enumerate()
                .map(|(b, info)| {
                    vk::WriteDescriptorSet::default()
                        .dst_set(set)
                        .dst_binding(b as u32)
                        .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                        .buffer_info(info)
                })
                .collect();
            // SAFETY: the set is not in use; the buffers are live.
            unsafe { gpu.device.update_descriptor_sets(&writes, &[]) };
        }
        Ok(())
    }

    /// Builds a slot's list holds.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Bytes of GPU memory the builder holds beside the pool (lookups, lists, status).
    pub fn bytes(&self) -> u64 {
        self.scratch.size
            + self.builds.iter().map(|b| b.size).sum::<u64>()
            + self.status.iter().map(|b| b.size).sum::<u64>()
    }

    /// Writes slot `s`'s builds (its previous frame has completed); false if they do not fit.
    pub fn write(&mut self, s: usize, builds: &[Build]) -> bool {
        builds.len() <= self.capacity && self.builds[s].write(0, bytemuck::cast_slice(builds))
    }

    /// Who reads what the builds write: the draws' index reads, the copies (a chunk moved) and
    /// the host (the build status).
    pub const READERS: (vk::PipelineStageFlags, vk::AccessFlags) = (
        vk::PipelineStageFlags::from_raw(
            vk::PipelineStageFlags::VERTEX_INPUT.as_raw()
                | vk::PipelineStageFlags::TRANSFER.as_raw()
                | vk::PipelineStageFlags::HOST.as_raw(),
        ),
        vk::AccessFlags::from_raw(
            vk::AccessFlags::INDEX_READ.as_raw()
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
        sync::bind_compute(gpu, cmd, (self.pipeline, self.layout), self.sets[s], &[]);
        let mut first = 0;
        while first < count {
            if first > 0 {
                // The next dispatch reuses the lookups.
                sync::memory_barrier(gpu, cmd, (compute, shader), (compute, shader));
            }
            let n = (count - first).min(self.lookups);
            // SAFETY: as above; the pipeline and set are bound.
            unsafe {
                gpu.device.cmd_push_constants(
                    cmd,
                    self.layout,
                    vk::ShaderStageFlags::COMPUTE,
                    0,
                    bytemuck::bytes_of(&[first, u32::MAX]),
                );
                gpu.device.cmd_dispatch(cmd, n, 1, 1);
            }
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
        let status = self.status[s].mapped()?;
        let words: [u32; 4] = bytemuck::pod_read_unaligned(&status[..STATUS_BYTES as usize]);
        status.fill(0);
        (words[0] > 0).then_some(BuildFailure {
            failed: words[0],
            tile: words[1],
            got: words[2],
            expected: words[3],
        })
    }

    pub fn destroy(self, gpu: &Gpu) {
        // SAFETY: no command buffer in flight uses them; null handles are ignored.
        unsafe {
            gpu.device.destroy_pipeline(self.pipeline, None);
            gpu.device.destroy_pipeline_layout(self.layout, None);
            gpu.device.destroy_descriptor_pool(self.descriptors, None);
            gpu.device
                .destroy_descriptor_set_layout(self.set_layout, None);
        }
        for b in self.builds.into_iter().chain(self.status) {
            b.destroy(gpu);
        }
        self.scratch.destroy(gpu);
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
