//! The offscreen render target of headless runs: a colour and a depth image, and a readback
//! buffer for screenshots.

use ash::vk;

use crate::vulkan::buffer::BufferDesc;
use crate::vulkan::{sync, Buffer, Gpu, Image, VkResult};

pub const COLOR_FORMAT: vk::Format = vk::Format::R8G8B8A8_UNORM;
pub const DEPTH_FORMAT: vk::Format = vk::Format::D32_SFLOAT;

/// The colour image after rendering.
const RENDERED: sync::Layout = (
    vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
    vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
);

/// A colour image's one mip and one layer.
fn colour() -> vk::ImageSubresourceRange {
    sync::subresources(vk::ImageAspectFlags::COLOR, (0, 1), (0, 1))
}

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

    /// Clears the target and begins dynamic rendering into it, viewport and scissor set. The
    /// target was last used by its slot's previous frame, whose fence was waited on.
    pub fn begin_rendering(&self, gpu: &Gpu, cmd: vk::CommandBuffer, sky: [f32; 3]) {
        let unused = (vk::ImageLayout::UNDEFINED, vk::AccessFlags::empty());
        let depth_attachment_rw = (
            // DEPTH_STENCIL_ATTACHMENT_OPTIMAL: the depth-only layouts need the
            // separateDepthStencilLayouts feature, which is not enabled.
            vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL,
            vk::AccessFlags::DEPTH_STENCIL_ATTACHMENT_WRITE
                | vk::AccessFlags::DEPTH_STENCIL_ATTACHMENT_READ,
        );
        let depth_range = sync::subresources(vk::ImageAspectFlags::DEPTH, (0, 1), (0, 1));
        // From UNDEFINED: the previous contents are not needed. The colour image's previous
        // reads (read-back, blit) were by this slot's earlier frame, finished before this one
        // was recorded.
        sync::layout_barrier(
            gpu,
            cmd,
            vk::PipelineStageFlags::TOP_OF_PIPE,
            vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT
                | vk::PipelineStageFlags::EARLY_FRAGMENT_TESTS
                | vk::PipelineStageFlags::LATE_FRAGMENT_TESTS,
            &[
                sync::transition(self.color.raw, colour(), unused, RENDERED),
                sync::transition(self.depth.raw, depth_range, unused, depth_attachment_rw),
            ],
        );
        let extent = self.extent();
        let colour_attachment = [vk::RenderingAttachmentInfo::default()
            .image_view(self.color.view)
            .image_layout(RENDERED.0)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::STORE)
            .clear_value(vk::ClearValue {
                color: vk::ClearColorValue {
                    float32: [sky[0], sky[1], sky[2], 1.0],
                },
            })];
        // Reversed Z: clear to 0 (infinitely far).
        let depth_attachment = vk::RenderingAttachmentInfo::default()
            .image_view(self.depth.view)
            .image_layout(depth_attachment_rw.0)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::DONT_CARE)
            .clear_value(vk::ClearValue {
                depth_stencil: vk::ClearDepthStencilValue {
                    depth: 0.0,
                    stencil: 0,
                },
            });
        let area = vk::Rect2D {
            offset: vk::Offset2D::default(),
            extent,
        };
        let info = vk::RenderingInfo::default()
            .render_area(area)
            .layer_count(1)
            .color_attachments(&colour_attachment)
            .depth_attachment(&depth_attachment);
        let viewport = vk::Viewport {
            x: 0.0,
            y: 0.0,
            width: extent.width as f32,
            height: extent.height as f32,
            min_depth: 0.0,
            max_depth: 1.0,
        };
        // SAFETY: recording outside rendering; the images are in the attachment layouts.
        unsafe {
            gpu.device.cmd_begin_rendering(cmd, &info);
            gpu.device.cmd_set_viewport(cmd, 0, &[viewport]);
            gpu.device.cmd_set_scissor(cmd, 0, &[area]);
        }
    }

    /// Records the copy of the rendered colour image into the readback buffer (the image is in
    /// COLOR_ATTACHMENT_OPTIMAL after rendering).
    pub fn record_readback(&self, gpu: &Gpu, cmd: vk::CommandBuffer) {
        let to_src = sync::transition(
            self.color.raw,
            colour(),
            RENDERED,
            (
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                vk::AccessFlags::TRANSFER_READ,
            ),
        );
        sync::layout_barrier(
            gpu,
            cmd,
            vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
            vk::PipelineStageFlags::TRANSFER,
            &[to_src],
        );
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
        // SAFETY: cmd is recording outside a render pass; image and buffer are ours.
        unsafe {
            gpu.device.cmd_copy_image_to_buffer(
                cmd,
                self.color.raw,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                self.readback.raw,
                &[region],
            );
        }
        sync::host_read_barrier(gpu, cmd);
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
        let read = (
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            vk::AccessFlags::TRANSFER_READ,
        );
        let written = (
            vk::ImageLayout::TRANSFER_DST_OPTIMAL,
            vk::AccessFlags::TRANSFER_WRITE,
        );
        let unused = (vk::ImageLayout::UNDEFINED, vk::AccessFlags::empty());
        let before = [
            sync::transition(
                self.color.raw,
                colour(),
                if after_readback { read } else { RENDERED },
                read,
            ),
            sync::transition(dst, colour(), unused, written),
        ];
        let presented = (vk::ImageLayout::PRESENT_SRC_KHR, vk::AccessFlags::empty());
        let after = [sync::transition(dst, colour(), written, presented)];
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
        sync::layout_barrier(
            gpu,
            cmd,
            vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT | vk::PipelineStageFlags::TRANSFER,
            vk::PipelineStageFlags::TRANSFER,
            &before,
        );
        // SAFETY: recording outside rendering; both images are live for the frame.
        unsafe {
            gpu.device.cmd_blit_image(
                cmd,
                self.color.raw,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                dst,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &[blit],
                vk::Filter::NEAREST,
            );
        }
        sync::layout_barrier(
            gpu,
            cmd,
            vk::PipelineStageFlags::TRANSFER,
            vk::PipelineStageFlags::BOTTOM_OF_PIPE,
            &after,
        );
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
