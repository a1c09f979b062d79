//! Images with one view: the render targets.

use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

use super::{Gpu, VkResult};

pub struct Image {
    pub raw: vk::Image,
    pub view: vk::ImageView,
    pub format: vk::Format,
    pub extent: vk::Extent2D,
    allocation: Option<Allocation>,
}

impl Image {
    pub fn new_2d(
        gpu: &Gpu,
        extent: vk::Extent2D,
        format: vk::Format,
        usage: vk::ImageUsageFlags,
        aspect: vk::ImageAspectFlags,
        name: &str,
    ) -> VkResult<Image> {
        let info = vk::ImageCreateInfo::default()
            .image_type(vk::ImageType::TYPE_2D)
            .format(format)
            .extent(vk::Extent3D {
                width: extent.width,
                height: extent.height,
                depth: 1,
            })
            .mip_levels(1)
            .array_layers(1)
            .samples(vk::SampleCountFlags::TYPE_1)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(usage)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        // SAFETY: valid create info on a live device.
        let raw = unsafe { gpu.device.create_image(&info, None) }?;
        // SAFETY: raw belongs to this device.
        let requirements = unsafe { gpu.device.get_image_memory_requirements(raw) };
        let allocation = match gpu.allocator().allocate(&AllocationCreateDesc {
            name,
            requirements,
            location: MemoryLocation::GpuOnly,
            linear: false,
            allocation_scheme: AllocationScheme::GpuAllocatorManaged,
        }) {
            Ok(a) => a,
            Err(e) => {
                // SAFETY: not bound or used.
                unsafe { gpu.device.destroy_image(raw, None) };
                return Err(e.into());
            }
        };
        // SAFETY: memory from the allocator for these requirements.
        unsafe {
            gpu.device
                .bind_image_memory(raw, allocation.memory(), allocation.offset())
        }?;
        let view_info = vk::ImageViewCreateInfo::default()
            .image(raw)
            .view_type(vk::ImageViewType::TYPE_2D)
            .format(format)
            .subresource_range(
                vk::ImageSubresourceRange::default()
                    .aspect_mask(aspect)
                    .level_count(1)
                    .layer_count(1),
            );
        // SAFETY: the image is bound and the view matches it.
        let view = unsafe { gpu.device.create_image_view(&view_info, None) }?;
        gpu.name(raw, name);
        gpu.name(view, name);
        gpu.count_allocation();
        Ok(Image {
            raw,
            view,
            format,
            extent,
            allocation: Some(allocation),
        })
    }

    pub fn destroy(mut self, gpu: &Gpu) {
        // SAFETY: the owner guarantees the GPU is done with the image.
        unsafe {
            gpu.device.destroy_image_view(self.view, None);
            gpu.device.destroy_image(self.raw, None);
        }
        if let Some(a) = self.allocation.take() {
            let _ = gpu.allocator().free(a);
        }
    }
}
