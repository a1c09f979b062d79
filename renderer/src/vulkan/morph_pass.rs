//! The morph pass's Vulkan side: its compute pipeline over the terrain set layout and the
//! dispatch a frame records before its draws. What the pass computes is `morph.comp`'s header
//! and `crate::morph`; how much memory it gets is `memory::budget`'s decision.

use ash::vk;

use super::pipeline::compute_pipeline;
use super::{Gpu, VkResult};
use crate::interface::{FrameConstants, PUSH_CONSTANT_BYTES};

/// Workgroups of the morph pass at most: each places one tile at a time in a scratch region of
/// its own (`memory::budget` decides how many the budget holds).
pub const MORPH_GROUPS: u32 = 16;
/// Bytes of one workgroup's scratch region: a grid of 257 x 257 points of three words (own and
/// morphed height, the level passed to children), then its lists of vertices by scale, 66,045
/// words at most (`REGION` in `morph.comp`): 1,056,768 bytes, the budget's share of regions
/// as before the passed level (two-word points and entries, 1,056,784).
pub const MORPH_REGION_BYTES: u64 = (3 * 257 * 257 + 66_045) * 4;

/// The pass's pipeline and its layout: the terrain set layout, the frame's push constants for
/// the compute stage.
pub struct MorphPass {
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
}

impl MorphPass {
    pub fn new(gpu: &Gpu, set_layout: vk::DescriptorSetLayout) -> VkResult<MorphPass> {
        let ranges = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::COMPUTE)
            .size(PUSH_CONSTANT_BYTES)];
        let set_layouts = [set_layout];
        let layout_info = vk::PipelineLayoutCreateInfo::default()
            .set_layouts(&set_layouts)
            .push_constant_ranges(&ranges);
        // SAFETY: valid create info.
        let layout = unsafe { gpu.device.create_pipeline_layout(&layout_info, None) }?;
        gpu.name(layout, "morph pass pipeline layout");
        match compute_pipeline(gpu, spirv::MORPH_COMP, layout, "morph pass") {
            Ok(pipeline) => Ok(MorphPass { layout, pipeline }),
            Err(e) => {
                // SAFETY: unused.
                unsafe { gpu.device.destroy_pipeline_layout(layout, None) };
                Err(e)
            }
        }
    }

    /// Whether [`MorphPass::record`] records anything for a frame of `constants` with
    /// `groups` workgroups (a frame drawn unmorphed, or with no draws, has no pass).
    pub fn records(constants: &FrameConstants, groups: u32) -> bool {
        constants.draws > 0 && groups > 0
    }

    /// Records the pass over the frame's `constants.draws` records, with `set` (its records,
    /// morphed heights and the scratch) and at most `groups` workgroups: after the frame's
    /// copies and index builds (and the previous frames' passes, which share the scratch),
    /// before its draws. Its last barrier also makes the frame's index builds visible to the
    /// draws' index reads, the copies and the host, so a builder followed by the pass leaves
    /// out its own ([`super::indices::IndexBuilder::record`]).
    pub fn record(
        &self,
        gpu: &Gpu,
        cmd: vk::CommandBuffer,
        (set, groups): (vk::DescriptorSet, u32),
        constants: &FrameConstants,
    ) {
        if !Self::records(constants, groups) {
            return;
        }
        let compute = vk::PipelineStageFlags::COMPUTE_SHADER;
        let earlier = vk::PipelineStageFlags::TRANSFER | compute;
        let written = vk::AccessFlags::TRANSFER_WRITE | vk::AccessFlags::SHADER_WRITE;
        let shader = vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE;
        super::sync::memory_barrier(gpu, cmd, (earlier, written), (compute, shader));
        // The set's Tile binding (dynamic) at the first record; the pass reads none.
        let offsets = [crate::interface::tile_binding_offset(0)];
        super::sync::bind_compute(gpu, cmd, (self.pipeline, self.layout), set, &offsets);
        // SAFETY: recording outside rendering; the pipeline and its set are bound.
        unsafe {
            gpu.device.cmd_push_constants(
                cmd,
                self.layout,
                vk::ShaderStageFlags::COMPUTE,
                0,
                bytemuck::bytes_of(constants),
            );
            gpu.device
                .cmd_dispatch(cmd, constants.draws.min(groups), 1, 1);
        }
        // Every compute write so far (the pass's, and the index builder's before it) to the
        // vertex shader's reads, and to the index builder's readers.
        let (readers, reads) = super::indices::IndexBuilder::READERS;
        super::sync::memory_barrier(
            gpu,
            cmd,
            (compute, vk::AccessFlags::SHADER_WRITE),
            (
                vk::PipelineStageFlags::VERTEX_SHADER | readers,
                vk::AccessFlags::SHADER_READ | reads,
            ),
        );
    }

    pub fn destroy(self, gpu: &Gpu) {
        // SAFETY: no command buffer in flight uses them.
        unsafe {
            gpu.device.destroy_pipeline(self.pipeline, None);
            gpu.device.destroy_pipeline_layout(self.layout, None);
        }
    }
}
