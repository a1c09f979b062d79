//! The offscreen render target of headless runs: a colour and a depth image, and a readback
//! buffer for screenshots.

use ash::vk;

use crate::vulkan::buffer::BufferDesc;
use crate::vulkan::{Buffer, Gpu, Image, VkResult};

pub const COLOR_FORMAT: vk::Format = vk::Format::R8G8B8A8_UNORM;
pub const DEPTH_FORMAT: vk::Format = vk::Format::D32_SFLOAT;

pub struct Target {
    pub color: Image,
    pub depth: Image,
    readback: Buffer,
}

impl Target {
    pub fn new(gpu: &Gpu, width: u32, height: u32) -> VkResult<Target> {
        let extent = vk::Extent2D { width, height };
        let color = Image::new_2d(
            gpu,
            extent,
            COLOR_FORMAT,
            vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC,
            vk::ImageAspectFlags::COLOR,
            "offscreen colour",
        )?;
        let depth = Image::new_2d(
            gpu,
            extent,
            DEPTH_FORMAT,
            vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT,
            vk::ImageAspectFlags::DEPTH,
            "offscreen depth",
        )?;
        let readback = Buffer::new(
            gpu,
            BufferDesc::readback(u64::from(width) * u64::from(height) * 4),
            "screenshot readback",
        )?;
        Ok(Target {
            color,
            depth,
            readback,
        })
    }

    pub fn extent(&self) -> vk::Extent2D {
        self.color.extent
    }

    /// Records the copy of the rendered colour image into the readback buffer (the image is in
    /// COLOR_ATTACHMENT_OPTIMAL after rendering).
    pub fn record_readback(&self, gpu: &Gpu, cmd: vk::CommandBuffer) {
        let range = vk::ImageSubresourceRange::default()
            .aspect_mask(vk::ImageAspectFlags::COLOR)
            .level_count(1)
            .layer_count(1);
        let to_src = vk::ImageMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
            .dst_access_mask(vk::AccessFlags::TRANSFER_READ)
            .old_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
            .new_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .image(self.color.raw)
            .subresource_range(range);
        let extent = self.extent();
        let region = vk::BufferImageCopy::default()
            .image_subresource(
                vk::ImageSubresourceLayers::default()
                    .aspect_mask(vk::ImageAspectFlags::COLOR)
                    .layer_count(1),
            )
            .image_extent(vk::Extent3D {
                width: extent.width,
                height: extent.height,
                depth: 1,
            });
        let to_host = vk::BufferMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .buffer(self.readback.raw)
            .size(vk::WHOLE_SIZE);
        // SAFETY: cmd is recording outside a render pass; image and buffer are ours.
        unsafe {
            gpu.device.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[to_src],
            );
            gpu.device.cmd_copy_image_to_buffer(
                cmd,
                self.color.raw,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                self.readback.raw,
                &[region],
            );
            gpu.device.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::HOST,
                vk::DependencyFlags::empty(),
                &[],
                &[to_host],
                &[],
            );
        }
    }

    /// Records a copy of the rendered image into a swapchain image and leaves that ready to
    /// present. `after_readback`: the colour image is already in TRANSFER_SRC_OPTIMAL.
    pub fn record_blit(
        &self,
        gpu: &Gpu,
        cmd: vk::CommandBuffer,
        dst: vk::Image,
        dst_extent: vk::Extent2D,
        after_readback: bool,
    ) {
        let range = vk::ImageSubresourceRange::default()
            .aspect_mask(vk::ImageAspectFlags::COLOR)
            .level_count(1)
            .layer_count(1);
        let barrier = |image, old, new, src, dst_access| {
            vk::ImageMemoryBarrier::default()
                .src_access_mask(src)
                .dst_access_mask(dst_access)
                .old_layout(old)
                .new_layout(new)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .image(image)
                .subresource_range(range)
        };
        let (src_old, src_access) = if after_readback {
            (
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                vk::AccessFlags::TRANSFER_READ,
            )
        } else {
            (
                vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
                vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
            )
        };
        let before = [
            barrier(
                self.color.raw,
                src_old,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                src_access,
                vk::AccessFlags::TRANSFER_READ,
            ),
            barrier(
                dst,
                vk::ImageLayout::UNDEFINED,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                vk::AccessFlags::empty(),
                vk::AccessFlags::TRANSFER_WRITE,
            ),
        ];
        let after = [barrier(
            dst,
            vk::ImageLayout::TRANSFER_DST_OPTIMAL,
            vk::ImageLayout::PRESENT_SRC_KHR,
            vk::AccessFlags::TRANSFER_WRITE,
            vk::AccessFlags::empty(),
        )];
        let layers = vk::ImageSubresourceLayers::default()
            .aspect_mask(vk::ImageAspectFlags::COLOR)
            .layer_count(1);
        let e = self.extent();
        let corner = |w: u32, h: u32| {
            [
                vk::Offset3D::default(),
                vk::Offset3D {
                    x: w as i32,
                    y: h as i32,
                    z: 1,
                },
            ]
        };
        let blit = vk::ImageBlit::default()
            .src_subresource(layers)
            .src_offsets(corner(e.width, e.height))
            .dst_subresource(layers)
            .dst_offsets(corner(dst_extent.width, dst_extent.height));
        // SAFETY: recording outside rendering; both images are live for the frame.
        unsafe {
            gpu.device.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT | vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &before,
            );
            gpu.device.cmd_blit_image(
                cmd,
                self.color.raw,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                dst,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &[blit],
                vk::Filter::NEAREST,
            );
            gpu.device.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::BOTTOM_OF_PIPE,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &after,
            );
        }
    }

    /// The last read-back image as RGBA8 rows (after the frame's fence).
    pub fn pixels(&mut self) -> Option<Vec<u8>> {
        self.readback.mapped().map(|m| m.to_vec())
    }

    pub fn destroy(self, gpu: &Gpu) {
        self.color.destroy(gpu);
        self.depth.destroy(gpu);
        self.readback.destroy(gpu);
    }
}
