//! The window surface and its swapchain: created, recreated on resize, destroyed here.

use ash::vk;
use raw_window_handle::{RawDisplayHandle, RawWindowHandle};

use super::{sync, Gpu, VkError, VkResult};

pub struct Swapchain {
    surface_loader: ash::khr::surface::Instance,
    loader: ash::khr::swapchain::Device,
    pub surface: vk::SurfaceKHR,
    pub swapchain: vk::SwapchainKHR,
    pub images: Vec<vk::Image>,
    /// One per image, signalled when a frame's copy into the image is done; presentation
    /// waits on it. Per image, not per frame: the spec allows reusing a semaphore only after
    /// the presentation that waited on it, which is known when its image is acquired again.
    pub rendered: Vec<vk::Semaphore>,
    pub extent: vk::Extent2D,
    pub format: vk::Format,
}

impl Swapchain {
    pub fn new(
        gpu: &Gpu,
        display: RawDisplayHandle,
        window: RawWindowHandle,
        size: (u32, u32),
    ) -> VkResult<Swapchain> {
        // SAFETY: the handles come from a live winit window that outlives the swapchain.
        let surface = unsafe {
            ash_window::create_surface(&gpu.entry, &gpu.instance, display, window, None)
        }?;
        let surface_loader = ash::khr::surface::Instance::new(&gpu.entry, &gpu.instance);
        // SAFETY: surface and device belong to this instance.
        let supported = unsafe {
            surface_loader.get_physical_device_surface_support(
                gpu.physical,
                gpu.queue_family,
                surface,
            )
        }?;
        if !supported {
            // SAFETY: just created, unused.
            unsafe { surface_loader.destroy_surface(surface, None) };
            return Err(VkError::Unsupported(
                "the graphics queue cannot present to this window".into(),
            ));
        }
        let loader = ash::khr::swapchain::Device::new(&gpu.instance, &gpu.device);
        let mut chain = Swapchain {
            surface_loader,
            loader,
            surface,
            swapchain: vk::SwapchainKHR::null(),
            images: Vec::new(),
            rendered: Vec::new(),
            extent: vk::Extent2D {
                width: size.0,
                height: size.1,
            },
            format: vk::Format::B8G8R8A8_UNORM,
        };
        chain.recreate(gpu, size)?;
        Ok(chain)
    }

    /// (Re)creates the swapchain for the window's current size.
    pub fn recreate(&mut self, gpu: &Gpu, size: (u32, u32)) -> VkResult<()> {
        gpu.wait_idle();
        // SAFETY: surface and device are live.
        let caps = unsafe {
            self.surface_loader
                .get_physical_device_surface_capabilities(gpu.physical, self.surface)
        }?;
        // SAFETY: as above.
        let formats = unsafe {
            self.surface_loader
                .get_physical_device_surface_formats(gpu.physical, self.surface)
        }?;
        let format = formats
            .iter()
            .find(|f| {
                f.format == vk::Format::B8G8R8A8_UNORM || f.format == vk::Format::R8G8B8A8_UNORM
            })
            .or(formats.first())
            .copied()
            .ok_or_else(|| VkError::Unsupported("the window offers no surface format".into()))?;
        if !caps
            .supported_usage_flags
            .contains(vk::ImageUsageFlags::TRANSFER_DST)
        {
            return Err(VkError::Unsupported(
                "the window's images cannot be copied into (no TRANSFER_DST)".into(),
            ));
        }
        let extent = if caps.current_extent.width != u32::MAX {
            caps.current_extent
        } else {
            vk::Extent2D {
                width: size
                    .0
                    .clamp(caps.min_image_extent.width, caps.max_image_extent.width),
                height: size
                    .1
                    .clamp(caps.min_image_extent.height, caps.max_image_extent.height),
            }
        };
        let count = (caps.min_image_count + 1).min(if caps.max_image_count == 0 {
            u32::MAX
        } else {
            caps.max_image_count
        });
        let info = vk::SwapchainCreateInfoKHR::default()
            .surface(self.surface)
            .min_image_count(count)
            .image_format(format.format)
            .image_color_space(format.color_space)
            .image_extent(extent)
            .image_array_layers(1)
            .image_usage(vk::ImageUsageFlags::TRANSFER_DST | vk::ImageUsageFlags::COLOR_ATTACHMENT)
            .image_sharing_mode(vk::SharingMode::EXCLUSIVE)
            .pre_transform(caps.current_transform)
            .composite_alpha(vk::CompositeAlphaFlagsKHR::OPAQUE)
            .present_mode(vk::PresentModeKHR::FIFO)
            .clipped(true)
            .old_swapchain(self.swapchain);
        // SAFETY: valid info; the old swapchain is retired by this call and destroyed below.
        let swapchain = unsafe { self.loader.create_swapchain(&info, None) }?;
        if self.swapchain != vk::SwapchainKHR::null() {
            // SAFETY: the device is idle.
            unsafe { self.loader.destroy_swapchain(self.swapchain, None) };
        }
        self.swapchain = swapchain;
        // SAFETY: the swapchain was just created.
        self.images = unsafe { self.loader.get_swapchain_images(swapchain) }?;
        self.extent = extent;
        self.format = format.format;
        gpu.name(swapchain, "window swapchain");
        // The device is idle: the old semaphores have no pending operations.
        for s in self.rendered.drain(..) {
            sync::destroy_semaphore(gpu, s);
        }
        for i in 0..self.images.len() {
            self.rendered.push(sync::semaphore(
                gpu,
                &format!("swapchain image {i} rendered"),
            )?);
        }
        Ok(())
    }

    /// The next image's index and whether the swapchain is suboptimal (use the image, then
    /// recreate: the semaphore is signalled); `None` when it must be recreated first.
    pub fn acquire(&self, signal: vk::Semaphore) -> VkResult<Option<(u32, bool)>> {
        // SAFETY: the semaphore is unsignalled and owned by the caller.
        match unsafe {
            self.loader
                .acquire_next_image(self.swapchain, u64::MAX, signal, vk::Fence::null())
        } {
            Ok((index, suboptimal)) => Ok(Some((index, suboptimal))),
            Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => Ok(None),
            Err(e) => Err(e.into()),
        }
    }

    /// Presents; `false` when the swapchain is out of date.
    pub fn present(&self, gpu: &Gpu, index: u32, wait: vk::Semaphore) -> VkResult<bool> {
        let swapchains = [self.swapchain];
        let indices = [index];
        let waits = [wait];
        let info = vk::PresentInfoKHR::default()
            .wait_semaphores(&waits)
            .swapchains(&swapchains)
            .image_indices(&indices);
        // SAFETY: the image was acquired and rendered into; the semaphore is signalled by it.
        match unsafe { self.loader.queue_present(gpu.queue, &info) } {
            Ok(false) => Ok(true),
            Ok(true) | Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => Ok(false),
            Err(e) => Err(e.into()),
        }
    }

    pub fn destroy(self, gpu: &Gpu) {
        gpu.wait_idle();
        for s in self.rendered {
            sync::destroy_semaphore(gpu, s);
        }
        // SAFETY: the device is idle; the surface outlives its swapchain until here.
        unsafe {
            self.loader.destroy_swapchain(self.swapchain, None);
            self.surface_loader.destroy_surface(self.surface, None);
        }
    }
}
