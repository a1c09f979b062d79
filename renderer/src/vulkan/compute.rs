//! What the compute passes over the tile pool share (the index builder, `indices`, and the
//! compact levels' decoder, `decode`): a pipeline whose bindings are all storage buffers, one
//! descriptor set per frame slot, and a status word per slot that the shader raises when what
//! it made is not what the file says.

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::buffer::BufferDesc;
use super::sync;
use super::{Buffer, Gpu, VkError, VkResult};

/// Bytes of a slot's status: the failures, then three words about the first one.
pub const STATUS_BYTES: u64 = 16;

/// A compute pipeline over storage buffers, with a descriptor set per frame slot.
pub struct StoragePass {
    set_layout: vk::DescriptorSetLayout,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    descriptors: vk::DescriptorPool,
    sets: Vec<vk::DescriptorSet>,
}

impl StoragePass {
    /// The pipeline of `shader` over `bindings` storage buffers and `push_bytes` of push
    /// constants, with a set per slot over the buffers `slots` gives it (one list per slot, in
    /// binding order, each buffer with the range bound).
    pub fn new(
        gpu: &Gpu,
        (shader, name): (&[u32], &str),
        push_bytes: u32,
        slots: &[Vec<(&Buffer, u64)>],
    ) -> VkResult<StoragePass> {
        let bindings = slots.first().map_or(0, Vec::len) as u32;
        let layout_bindings: Vec<_> = (0..bindings)
            .map(|b| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        let set_info = vk::DescriptorSetLayoutCreateInfo::default().bindings(&layout_bindings);
        // SAFETY: valid create info.
        let set_layout = unsafe { gpu.device.create_descriptor_set_layout(&set_info, None) }?;
        gpu.name(set_layout, &format!("{name} set layout"));
        let mut pass = StoragePass {
            set_layout,
            layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
            descriptors: vk::DescriptorPool::null(),
            sets: Vec::new(),
        };
        // On failure the partly made pass is destroyed (null handles are skipped).
        match pass.create(gpu, (shader, name), push_bytes, slots) {
            Ok(()) => Ok(pass),
            Err(e) => {
                pass.destroy(gpu);
                Err(e)
            }
        }
    }

    fn create(
        &mut self,
        gpu: &Gpu,
        (shader, name): (&[u32], &str),
        push_bytes: u32,
        slots: &[Vec<(&Buffer, u64)>],
    ) -> VkResult<()> {
        let ranges = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::COMPUTE)
            .size(push_bytes)];
        let set_layouts = [self.set_layout];
        let layout_info = vk::PipelineLayoutCreateInfo::default()
            .set_layouts(&set_layouts)
            .push_constant_ranges(&ranges);
        // SAFETY: valid create info.
        self.layout = unsafe { gpu.device.create_pipeline_layout(&layout_info, None) }?;
        gpu.name(self.layout, &format!("{name} pipeline layout"));
        self.pipeline = super::pipeline::compute_pipeline(
            gpu,
            shader,
            self.layout,
            &format!("{name} pipeline"),
        )?;
        let count: u32 = slots.iter().map(|s| s.len() as u32).sum();
        let sizes = [vk::DescriptorPoolSize::default()
            .ty(vk::DescriptorType::STORAGE_BUFFER)
            .descriptor_count(count.max(1))];
        let info = vk::DescriptorPoolCreateInfo::default()
            .max_sets(slots.len().max(1) as u32)
            .pool_sizes(&sizes);
        // SAFETY: valid create info.
        self.descriptors = unsafe { gpu.device.create_descriptor_pool(&info, None) }?;
        gpu.name(self.descriptors, &format!("{name} descriptors"));
        let layouts = vec![self.set_layout; slots.len()];
        let alloc = vk::DescriptorSetAllocateInfo::default()
            .descriptor_pool(self.descriptors)
            .set_layouts(&layouts);
        // SAFETY: the pool has room for these sets.
        self.sets = unsafe { gpu.device.allocate_descriptor_sets(&alloc) }?;
        for (&set, buffers) in self.sets.iter().zip(slots) {
            let infos: Vec<[vk::DescriptorBufferInfo; 1]> = buffers
                .iter()
                .map(|&(buffer, range)| {
                    [vk::DescriptorBufferInfo::default()
                        .buffer(buffer.raw)
                        .range(range)]
                })
                .collect();
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

    /// Binds the pipeline and slot `s`'s set.
    pub fn bind(&self, gpu: &Gpu, cmd: vk::CommandBuffer, s: usize) {
        sync::bind_compute(gpu, cmd, (self.pipeline, self.layout), self.sets[s], &[]);
    }

    /// Pushes `bytes` of push constants, then dispatches `groups` workgroups.
    pub fn dispatch(&self, gpu: &Gpu, cmd: vk::CommandBuffer, bytes: &[u8], groups: u32) {
        // SAFETY: recording outside rendering, after `bind`.
        unsafe {
            gpu.device.cmd_push_constants(
                cmd,
                self.layout,
                vk::ShaderStageFlags::COMPUTE,
                0,
                bytes,
            );
            gpu.device.cmd_dispatch(cmd, groups, 1, 1);
        }
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
    }
}

/// A slot's status word, zeroed, which the shader raises and the CPU reads after the frame.
pub fn status_buffer(gpu: &Gpu, name: &str) -> VkResult<Buffer> {
    let mut status = Buffer::new(gpu, BufferDesc::readback_storage(STATUS_BYTES), name)?;
    if !status.write(0, &[0; STATUS_BYTES as usize]) {
        status.destroy(gpu);
        return Err(VkError::Unsupported(format!("{name} is not host-visible")));
    }
    Ok(status)
}

/// The status's words once its frame completed, or None when nothing failed (and the status
/// is cleared for the slot's next frame either way).
pub fn take_status(status: &mut Buffer) -> Option<[u32; 4]> {
    let bytes = status.mapped()?;
    let words: [u32; 4] = bytemuck::pod_read_unaligned(&bytes[..STATUS_BYTES as usize]);
    bytes.fill(0);
    (words[0] > 0).then_some(words)
}

/// A pass's own buffers: a scratch region on the GPU (its workgroups' grids), and per frame
/// slot the list of work the CPU writes and a status word.
pub struct PassBuffers {
    pub scratch: Buffer,
    pub lists: Vec<Buffer>,
    pub status: Vec<Buffer>,
}

impl PassBuffers {
    /// `scratch_bytes` of scratch and `slots` lists of `list_bytes`, named after the pass;
    /// nothing is left behind on failure.
    pub fn new(
        gpu: &Gpu,
        (scratch_bytes, list_bytes): (u64, u64),
        slots: usize,
        name: &str,
    ) -> VkResult<PassBuffers> {
        let scratch = BufferDesc {
            size: scratch_bytes,
            usage: vk::BufferUsageFlags::STORAGE_BUFFER,
            location: MemoryLocation::GpuOnly,
        };
        let mut made = PassBuffers {
            scratch: Buffer::new(gpu, scratch, &format!("{name} scratch"))?,
            lists: Vec::new(),
            status: Vec::new(),
        };
        for s in 0..slots {
            let list = BufferDesc::upload(list_bytes, vk::BufferUsageFlags::STORAGE_BUFFER);
            let made_slot =
                Buffer::new(gpu, list, &format!("{name} list, slot {s}")).and_then(|list| {
                    match status_buffer(gpu, &format!("{name} status, slot {s}")) {
                        Ok(status) => Ok((list, status)),
                        Err(e) => {
                            list.destroy(gpu);
                            Err(e)
                        }
                    }
                });
            match made_slot {
                Ok((list, status)) => {
                    made.lists.push(list);
                    made.status.push(status);
                }
                Err(e) => {
                    made.destroy(gpu);
                    return Err(e);
                }
            }
        }
        Ok(made)
    }

    /// Bytes of GPU memory they hold.
    pub fn bytes(&self) -> u64 {
        self.scratch.size
            + self
                .lists
                .iter()
                .chain(&self.status)
                .map(|b| b.size)
                .sum::<u64>()
    }

    pub fn destroy(self, gpu: &Gpu) {
        for b in self.lists.into_iter().chain(self.status) {
            b.destroy(gpu);
        }
        self.scratch.destroy(gpu);
    }
}
