//! Command pools and buffers, fences and semaphores: created, used and destroyed here.

use ash::vk;

use super::{Gpu, VkResult};

/// A command pool (resettable buffers) and the buffers allocated from it.
pub struct Commands {
    pool: vk::CommandPool,
}

impl Commands {
    pub fn new(gpu: &Gpu, name: &str) -> VkResult<Commands> {
        let info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(gpu.queue_family)
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        // SAFETY: valid create info on a live device; destroyed in `destroy`.
        let pool = unsafe { gpu.device.create_command_pool(&info, None) }?;
        gpu.name(pool, name);
        Ok(Commands { pool })
    }

    pub fn allocate(&self, gpu: &Gpu, name: &str) -> VkResult<vk::CommandBuffer> {
        let info = vk::CommandBufferAllocateInfo::default()
            .command_pool(self.pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: allocation from our pool; freed with it or by `free`.
        let cmd = unsafe { gpu.device.allocate_command_buffers(&info) }?[0];
        gpu.name(cmd, name);
        Ok(cmd)
    }

    /// Frees a buffer the GPU no longer uses.
    pub fn free(&self, gpu: &Gpu, cmd: vk::CommandBuffer) {
        // SAFETY: the caller waited for the buffer's last submission.
        unsafe { gpu.device.free_command_buffers(self.pool, &[cmd]) };
    }

    /// The device must be idle (or every buffer of the pool finished).
    pub fn destroy(self, gpu: &Gpu) {
        // SAFETY: as documented; destroying the pool frees its buffers.
        unsafe { gpu.device.destroy_command_pool(self.pool, None) };
    }
}

/// Resets `cmd` and begins recording.
pub fn begin(gpu: &Gpu, cmd: vk::CommandBuffer, one_time: bool) -> VkResult<()> {
    let flags = if one_time {
        vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT
    } else {
        vk::CommandBufferUsageFlags::empty()
    };
    // SAFETY: the caller waited for the buffer's last submission (its slot's fence).
    unsafe {
        gpu.device
            .reset_command_buffer(cmd, vk::CommandBufferResetFlags::empty())?;
        gpu.device
            .begin_command_buffer(cmd, &vk::CommandBufferBeginInfo::default().flags(flags))?;
    }
    Ok(())
}

pub fn end(gpu: &Gpu, cmd: vk::CommandBuffer) -> VkResult<()> {
    // SAFETY: recording began with `begin`.
    unsafe { gpu.device.end_command_buffer(cmd) }?;
    Ok(())
}

/// Submits `cmd`, signalling `fence` when done; waits on `wait` (at the transfer stage, where
/// a frame first touches the swapchain image) and signals `signal`.
pub fn submit(
    gpu: &Gpu,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    wait: Option<vk::Semaphore>,
    signal: Option<vk::Semaphore>,
) -> VkResult<()> {
    let cmds = [cmd];
    let waits: Vec<vk::Semaphore> = wait.into_iter().collect();
    let stages = vec![vk::PipelineStageFlags::TRANSFER; waits.len()];
    let signals: Vec<vk::Semaphore> = signal.into_iter().collect();
    let info = vk::SubmitInfo::default()
        .command_buffers(&cmds)
        .wait_semaphores(&waits)
        .wait_dst_stage_mask(&stages)
        .signal_semaphores(&signals);
    // SAFETY: the command buffer is complete; the fence is unsignalled (reset by the caller).
    unsafe { gpu.device.queue_submit(gpu.queue, &[info], fence) }?;
    Ok(())
}

pub fn fence(gpu: &Gpu, signalled: bool, name: &str) -> VkResult<vk::Fence> {
    let flags = if signalled {
        vk::FenceCreateFlags::SIGNALED
    } else {
        vk::FenceCreateFlags::empty()
    };
    // SAFETY: plain creation; destroyed by `destroy_fence`.
    let f = unsafe {
        gpu.device
            .create_fence(&vk::FenceCreateInfo::default().flags(flags), None)
    }?;
    gpu.name(f, name);
    Ok(f)
}

/// Waits for `fence` and resets it.
pub fn wait_and_reset(gpu: &Gpu, fence: vk::Fence) -> VkResult<()> {
    // SAFETY: the fence belongs to this device.
    unsafe {
        gpu.device.wait_for_fences(&[fence], true, u64::MAX)?;
        gpu.device.reset_fences(&[fence])?;
    }
    Ok(())
}

/// Whether `fence` is signalled, without waiting.
pub fn is_signalled(gpu: &Gpu, fence: vk::Fence) -> VkResult<bool> {
    // SAFETY: the fence belongs to this device.
    Ok(unsafe { gpu.device.get_fence_status(fence) }?)
}

pub fn destroy_fence(gpu: &Gpu, fence: vk::Fence) {
    // SAFETY: the caller guarantees no pending submission signals it.
    unsafe { gpu.device.destroy_fence(fence, None) };
}

pub fn semaphore(gpu: &Gpu, name: &str) -> VkResult<vk::Semaphore> {
    // SAFETY: plain creation; destroyed by `destroy_semaphore`.
    let s = unsafe {
        gpu.device
            .create_semaphore(&vk::SemaphoreCreateInfo::default(), None)
    }?;
    gpu.name(s, name);
    Ok(s)
}

pub fn destroy_semaphore(gpu: &Gpu, semaphore: vk::Semaphore) {
    // SAFETY: the caller guarantees no pending operation uses it (device idle).
    unsafe { gpu.device.destroy_semaphore(semaphore, None) };
}

/// Records commands with `record` into a command buffer of their own, submits them and waits
/// for them (set-up and diagnostics only: never on a frame's path).
pub fn run_once(gpu: &Gpu, name: &str, record: impl FnOnce(vk::CommandBuffer)) -> VkResult<()> {
    let commands = Commands::new(gpu, name)?;
    let result = (|| {
        let cmd = commands.allocate(gpu, name)?;
        begin(gpu, cmd, true)?;
        record(cmd);
        end(gpu, cmd)?;
        let fence = fence(gpu, false, name)?;
        let done = submit(gpu, cmd, fence, None, None).and_then(|()| wait_and_reset(gpu, fence));
        destroy_fence(gpu, fence);
        done
    })();
    commands.destroy(gpu);
    result
}

/// A stage and the memory accesses in it: one side of a barrier.
pub type Scope = (vk::PipelineStageFlags, vk::AccessFlags);

/// Records a global memory barrier: `before`'s accesses happen before `after`'s (buffers only;
/// images need their layout barriers). Must be recorded outside rendering.
pub fn memory_barrier(gpu: &Gpu, cmd: vk::CommandBuffer, before: Scope, after: Scope) {
    let barrier = vk::MemoryBarrier::default()
        .src_access_mask(before.1)
        .dst_access_mask(after.1);
    // SAFETY: a recording command buffer; a global barrier names no resource.
    unsafe {
        gpu.device.cmd_pipeline_barrier(
            cmd,
            before.0,
            after.0,
            vk::DependencyFlags::empty(),
            &[barrier],
            &[],
            &[],
        );
    }
}

/// Makes transfer writes visible to host reads after the command buffer's fence (read-backs).
pub fn host_read_barrier(gpu: &Gpu, cmd: vk::CommandBuffer) {
    memory_barrier(
        gpu,
        cmd,
        (
            vk::PipelineStageFlags::TRANSFER,
            vk::AccessFlags::TRANSFER_WRITE,
        ),
        (vk::PipelineStageFlags::HOST, vk::AccessFlags::HOST_READ),
    );
}

/// Makes vertex-shader writes visible to host reads after the command buffer's fence (the
/// heights read back).
pub fn vertex_to_host_barrier(gpu: &Gpu, cmd: vk::CommandBuffer) {
    memory_barrier(
        gpu,
        cmd,
        (
            vk::PipelineStageFlags::VERTEX_SHADER,
            vk::AccessFlags::SHADER_WRITE,
        ),
        (vk::PipelineStageFlags::HOST, vk::AccessFlags::HOST_READ),
    );
}

/// A change of an image's layout, one side of it: the layout and the accesses before or after.
pub type Layout = (vk::ImageLayout, vk::AccessFlags);

/// The subresources of one aspect of an image: `mips` levels from `mip`, `layers` from `layer`.
pub fn subresources(
    aspect: vk::ImageAspectFlags,
    (mip, mips): (u32, u32),
    (layer, layers): (u32, u32),
) -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange::default()
        .aspect_mask(aspect)
        .base_mip_level(mip)
        .level_count(mips)
        .base_array_layer(layer)
        .layer_count(layers)
}

/// One image layout transition for [`layout_barrier`]: `range` of `image` goes from `from` to
/// `to` (from UNDEFINED, the old contents are dropped).
pub fn transition(
    image: vk::Image,
    range: vk::ImageSubresourceRange,
    from: Layout,
    to: Layout,
) -> vk::ImageMemoryBarrier<'static> {
    vk::ImageMemoryBarrier::default()
        .src_access_mask(from.1)
        .dst_access_mask(to.1)
        .old_layout(from.0)
        .new_layout(to.0)
        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .image(image)
        .subresource_range(range)
}

/// Records image layout transitions between the stages `before` and `after`. Must be recorded
/// outside rendering, with every image live until the command buffer completes.
pub fn layout_barrier(
    gpu: &Gpu,
    cmd: vk::CommandBuffer,
    before: vk::PipelineStageFlags,
    after: vk::PipelineStageFlags,
    transitions: &[vk::ImageMemoryBarrier],
) {
    // SAFETY: a recording command buffer; the images are the caller's, live (as documented).
    unsafe {
        gpu.device.cmd_pipeline_barrier(
            cmd,
            before,
            after,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            transitions,
        );
    }
}

/// Binds a compute pipeline and its set 0 (with `dynamic_offsets` for its dynamic bindings).
pub fn bind_compute(
    gpu: &Gpu,
    cmd: vk::CommandBuffer,
    (pipeline, layout): (vk::Pipeline, vk::PipelineLayout),
    set: vk::DescriptorSet,
    dynamic_offsets: &[u32],
) {
    // SAFETY: recording outside rendering; the caller keeps the set's buffers alive for the
    // command buffer.
    unsafe {
        gpu.device
            .cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, pipeline);
        gpu.device.cmd_bind_descriptor_sets(
            cmd,
            vk::PipelineBindPoint::COMPUTE,
            layout,
            0,
            &[set],
            dynamic_offsets,
        );
    }
}
