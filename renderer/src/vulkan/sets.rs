//! Descriptor sets of the terrain pipeline's layout ([`TerrainPipeline::set_layout`]): one for
//! each [`SetBuffers`] given, each pointing at the tile pool, its own records, read-back heights
//! and morphed heights, the morph pass's scratch and the texture array.

use ash::vk;

use super::pipeline::{TerrainPipeline, BINDINGS};
use super::{Gpu, VkResult};
use crate::interface::{MorphFrame, RECORDS_OFFSET, RECORD_BYTES};

/// What one terrain set points at beside the pool, the textures and the morph scratch: its
/// frame's records, read-back heights and morphed heights.
#[derive(Clone, Copy)]
pub struct SetBuffers<'a> {
    pub records: &'a super::Buffer,
    pub heights: &'a super::Buffer,
    pub morphed: &'a super::Buffer,
}

/// Descriptor sets of the terrain pipeline's layout, from a pool of their own.
pub struct TerrainSets {
    pool: vk::DescriptorPool,
    pub sets: Vec<vk::DescriptorSet>,
}

impl TerrainSets {
    /// A set for each of `buffers`, pointing at the tile pool, at its own records, heights and
    /// morphed heights, at the morph pass's `scratch` and at the texture array.
    pub fn new(
        gpu: &Gpu,
        pipeline: &TerrainPipeline,
        (tile_pool, scratch): (&super::Buffer, &super::Buffer),
        buffers: &[SetBuffers<'_>],
        textures: &super::texture::TextureArray,
        name: &str,
    ) -> VkResult<TerrainSets> {
        let records = buffers;
        let count = records.len().max(1) as u32;
        // Per descriptor kind, its bindings' count in every set.
        let mut sizes: Vec<vk::DescriptorPoolSize> = Vec::new();
        for (_, ty, _) in BINDINGS {
            match sizes.iter_mut().find(|s| s.ty == ty) {
                Some(s) => s.descriptor_count += count,
                None => sizes.push(
                    vk::DescriptorPoolSize::default()
                        .ty(ty)
                        .descriptor_count(count),
                ),
            }
        }
        let info = vk::DescriptorPoolCreateInfo::default()
            .max_sets(count)
            .pool_sizes(&sizes);
        // SAFETY: valid create info.
        let pool = unsafe { gpu.device.create_descriptor_pool(&info, None) }?;
        gpu.name(pool, name);
        let layouts = vec![pipeline.set_layout; records.len()];
        let alloc = vk::DescriptorSetAllocateInfo::default()
            .descriptor_pool(pool)
            .set_layouts(&layouts);
        // SAFETY: the pool has room for these sets.
        let sets = match unsafe { gpu.device.allocate_descriptor_sets(&alloc) } {
            Ok(s) => s,
            Err(e) => {
                // SAFETY: nothing allocated from it.
                unsafe { gpu.device.destroy_descriptor_pool(pool, None) };
                return Err(e.into());
            }
        };
        let range = tile_pool
            .size
            .min(u64::from(gpu.properties.limits.max_storage_buffer_range));
        for (&set, b) in sets.iter().zip(records) {
            let (r, heights) = (b.records, b.heights);
            let pool_info = [vk::DescriptorBufferInfo::default()
                .buffer(tile_pool.raw)
                .range(range)];
            let record_info = [vk::DescriptorBufferInfo::default()
                .buffer(r.raw)
                .range(vk::WHOLE_SIZE)];
            let tile_info = [vk::DescriptorBufferInfo::default()
                .buffer(r.raw)
                .offset(RECORDS_OFFSET)
                .range(RECORD_BYTES)];
            let morph_info = [vk::DescriptorBufferInfo::default()
                .buffer(r.raw)
                .range(std::mem::size_of::<MorphFrame>() as u64)];
            let heights_info = [vk::DescriptorBufferInfo::default()
                .buffer(heights.raw)
                .range(vk::WHOLE_SIZE)];
            let morphed_info = [vk::DescriptorBufferInfo::default()
                .buffer(b.morphed.raw)
                .range(vk::WHOLE_SIZE)];
            let scratch_info = [vk::DescriptorBufferInfo::default()
                .buffer(scratch.raw)
                .range(vk::WHOLE_SIZE)];
            let texture_info = [vk::DescriptorImageInfo::default()
                .sampler(textures.sampler)
                .image_view(textures.view)
                .image_layout(vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL)];
            let write = |b: u32| {
                vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(b)
                    .descriptor_type(BINDINGS[b as usize].1)
            };
            let writes = [
                write(0).buffer_info(&pool_info),
                write(1).buffer_info(&record_info),
                write(2).image_info(&texture_info),
                write(3).buffer_info(&heights_info),
                write(4).buffer_info(&tile_info),
                write(5).buffer_info(&morph_info),
                write(6).buffer_info(&morphed_info),
                write(7).buffer_info(&scratch_info),
            ];
            // SAFETY: the set is not in use; the buffers, view and sampler are live.
            unsafe { gpu.device.update_descriptor_sets(&writes, &[]) };
        }
        Ok(TerrainSets { pool, sets })
    }

    pub fn destroy(self, gpu: &Gpu) {
        // SAFETY: no command buffer in flight uses the sets.
        unsafe { gpu.device.destroy_descriptor_pool(self.pool, None) };
    }
}
