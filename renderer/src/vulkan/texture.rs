//! The texture array: one image with a layer per texture slot (paper, section 6: a fixed set
//! of textures allocated at start), every layer the same BC1 mip chain, sampled trilinearly
//! (anisotropically where the device can) through one combined image sampler.
//!
//! Every mip of every layer is in the SHADER_READ_ONLY_OPTIMAL layout from creation on, except
//! while a frame copies into it: [`record_uploads`] moves just the mips it writes to
//! TRANSFER_DST_OPTIMAL (discarding what they held), copies, and moves them back, so a frame
//! can add mips to some layers while earlier frames in flight sample others. The memory
//! manager's texture slots never let a frame write a mip that a frame in flight may sample (a
//! layer's resident mips only grow until every frame that sampled it has finished).

use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

use super::{sync, Gpu, VkResult};

/// What to allocate.
#[derive(Clone, Copy, Debug)]
pub struct TextureDesc {
    pub format: vk::Format,
    /// Texels across mip 0.
    pub size: u32,
    pub mips: u32,
    pub layers: u32,
    /// 1: no anisotropic filtering.
    pub anisotropy: f32,
}

pub struct TextureArray {
    pub raw: vk::Image,
    pub view: vk::ImageView,
    pub sampler: vk::Sampler,
    pub desc: TextureDesc,
    allocation: Option<Allocation>,
}

impl TextureArray {
    pub fn new(gpu: &Gpu, desc: TextureDesc, name: &str) -> VkResult<TextureArray> {
        let info = vk::ImageCreateInfo::default()
            .image_type(vk::ImageType::TYPE_2D)
            .format(desc.format)
            .extent(vk::Extent3D {
                width: desc.size,
                height: desc.size,
                depth: 1,
            })
            .mip_levels(desc.mips)
            .array_layers(desc.layers)
            .samples(vk::SampleCountFlags::TYPE_1)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(vk::ImageUsageFlags::SAMPLED | vk::ImageUsageFlags::TRANSFER_DST)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        // SAFETY: valid create info on a live device.
        let raw = unsafe { gpu.device.create_image(&info, None) }?;
        let mut array = TextureArray {
            raw,
            view: vk::ImageView::null(),
            sampler: vk::Sampler::null(),
            desc,
            allocation: None,
        };
        match array.finish(gpu, name) {
            Ok(()) => Ok(array),
            Err(e) => {
                array.destroy(gpu);
                Err(e)
            }
        }
    }

    /// A one-texel array bound where a tile set has no textures (the shader never samples it).
    pub fn placeholder(gpu: &Gpu) -> VkResult<TextureArray> {
        let desc = TextureDesc {
            format: vk::Format::R8G8B8A8_UNORM,
            size: 1,
            mips: 1,
            layers: 1,
            anisotropy: 1.0,
        };
        TextureArray::new(gpu, desc, "no texture tiles (placeholder)")
    }

    /// Memory, view, sampler, and the move to the GENERAL layout.
    fn finish(&mut self, gpu: &Gpu, name: &str) -> VkResult<()> {
        let desc = self.desc;
        // SAFETY: raw belongs to this device.
        let requirements = unsafe { gpu.device.get_image_memory_requirements(self.raw) };
        let allocation =
            self.allocation
                .insert(gpu.allocator().allocate(&AllocationCreateDesc {
                    name,
                    requirements,
                    location: MemoryLocation::GpuOnly,
                    linear: false,
                    allocation_scheme: AllocationScheme::GpuAllocatorManaged,
                })?);
        gpu.count_allocation();
        // SAFETY: memory from the allocator for these requirements.
        unsafe {
            gpu.device
                .bind_image_memory(self.raw, allocation.memory(), allocation.offset())
        }?;
        let range = vk::ImageSubresourceRange::default()
            .aspect_mask(vk::ImageAspectFlags::COLOR)
            .level_count(desc.mips)
            .layer_count(desc.layers);
        let view_info = vk::ImageViewCreateInfo::default()
            .image(self.raw)
            .view_type(vk::ImageViewType::TYPE_2D_ARRAY)
            .format(desc.format)
            .subresource_range(range);
        // SAFETY: the image is bound and the view matches it.
        self.view = unsafe { gpu.device.create_image_view(&view_info, None) }?;
        let anisotropic = desc.anisotropy > 1.0;
        let sampler_info = vk::SamplerCreateInfo::default()
            .mag_filter(vk::Filter::LINEAR)
            .min_filter(vk::Filter::LINEAR)
            .mipmap_mode(vk::SamplerMipmapMode::LINEAR)
            .address_mode_u(vk::SamplerAddressMode::CLAMP_TO_EDGE)
            .address_mode_v(vk::SamplerAddressMode::CLAMP_TO_EDGE)
            .address_mode_w(vk::SamplerAddressMode::CLAMP_TO_EDGE)
            .anisotropy_enable(anisotropic)
            .max_anisotropy(if anisotropic { desc.anisotropy } else { 1.0 })
            .min_lod(0.0)
            .max_lod(vk::LOD_CLAMP_NONE);
        // SAFETY: valid create info; anisotropy only when the feature was enabled (the caller
        // clamps it to the device's limit, which is 1 without the feature).
        self.sampler = unsafe { gpu.device.create_sampler(&sampler_info, None) }?;
        gpu.name(self.raw, name);
        gpu.name(self.view, name);
        gpu.name(self.sampler, name);
        // The image is new and unused.
        let barrier = sync::transition(
            self.raw,
            range,
            (vk::ImageLayout::UNDEFINED, vk::AccessFlags::empty()),
            (
                vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
                vk::AccessFlags::SHADER_READ,
            ),
        );
        sync::run_once(gpu, "texture array layout", |cmd| {
            sync::layout_barrier(
                gpu,
                cmd,
                vk::PipelineStageFlags::TOP_OF_PIPE,
                vk::PipelineStageFlags::FRAGMENT_SHADER,
                &[barrier],
            );
        })
    }

    /// Bytes of device memory the array holds.
    pub fn bytes(&self) -> u64 {
        self.allocation.as_ref().map_or(0, |a| a.size())
    }

    pub fn destroy(mut self, gpu: &Gpu) {
        // SAFETY: the owner guarantees the GPU is done with the image; null handles are
        // ignored by the driver.
        unsafe {
            gpu.device.destroy_sampler(self.sampler, None);
            gpu.device.destroy_image_view(self.view, None);
            gpu.device.destroy_image(self.raw, None);
        }
        if let Some(a) = self.allocation.take() {
            let _ = gpu.allocator().free(a);
        }
    }
}

/// One mip of one layer copied from the staging buffer at `offset` (tightly packed blocks).
pub fn copy_region(offset: u64, layer: u32, mip: u32, texels: u32) -> vk::BufferImageCopy {
    vk::BufferImageCopy::default()
        .buffer_offset(offset)
        .image_subresource(
            vk::ImageSubresourceLayers::default()
                .aspect_mask(vk::ImageAspectFlags::COLOR)
                .mip_level(mip)
                .base_array_layer(layer)
                .layer_count(1),
        )
        .image_extent(vk::Extent3D {
            width: texels,
            height: texels,
            depth: 1,
        })
}

/// Records this frame's texture copies: each written mip goes to TRANSFER_DST_OPTIMAL after
/// earlier frames' sampling of the image, is copied, and returns to SHADER_READ_ONLY_OPTIMAL
/// before this frame's sampling.
pub fn record_uploads(
    gpu: &Gpu,
    cmd: vk::CommandBuffer,
    array: &TextureArray,
    staging: vk::Buffer,
    copies: &[vk::BufferImageCopy],
) {
    if copies.is_empty() {
        return;
    }
    // The mip's old contents (another tile's, or nothing) are not needed.
    let unused = (vk::ImageLayout::UNDEFINED, vk::AccessFlags::empty());
    let written = (
        vk::ImageLayout::TRANSFER_DST_OPTIMAL,
        vk::AccessFlags::TRANSFER_WRITE,
    );
    let sampled = (
        vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
        vk::AccessFlags::SHADER_READ,
    );
    let mip = |c: &vk::BufferImageCopy| {
        let s = c.image_subresource;
        sync::subresources(
            vk::ImageAspectFlags::COLOR,
            (s.mip_level, 1),
            (s.base_array_layer, 1),
        )
    };
    let barriers = |from, to| -> Vec<_> {
        let t = |c| sync::transition(array.raw, mip(c), from, to);
        copies.iter().map(t).collect()
    };
    sync::layout_barrier(
        gpu,
        cmd,
        vk::PipelineStageFlags::FRAGMENT_SHADER,
        vk::PipelineStageFlags::TRANSFER,
        &barriers(unused, written),
    );
    // SAFETY: recording outside rendering; every region lies in the staging buffer and in the
    // array, each (layer, mip) written once, and no frame in flight samples those mips.
    unsafe {
        gpu.device.cmd_copy_buffer_to_image(
            cmd,
            staging,
            array.raw,
            vk::ImageLayout::TRANSFER_DST_OPTIMAL,
            copies,
        );
    }
    sync::layout_barrier(
        gpu,
        cmd,
        vk::PipelineStageFlags::TRANSFER,
        vk::PipelineStageFlags::FRAGMENT_SHADER,
        &barriers(written, sampled),
    );
}
