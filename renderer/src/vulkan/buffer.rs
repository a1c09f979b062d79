//! Buffers: a `vk::Buffer` with its gpu-allocator allocation, created and destroyed here.

use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

use super::{Gpu, VkResult};

/// What a buffer is for and where it lives.
#[derive(Clone, Copy, Debug)]
pub struct BufferDesc {
    pub size: u64,
    pub usage: vk::BufferUsageFlags,
    pub location: MemoryLocation,
}

impl BufferDesc {
    /// Device memory the GPU reads (filled by copies from a staging buffer).
    pub fn gpu_only(size: u64, usage: vk::BufferUsageFlags) -> Self {
        BufferDesc {
            size,
            usage: usage | vk::BufferUsageFlags::TRANSFER_DST,
            location: MemoryLocation::GpuOnly,
        }
    }

    /// Host-visible memory the CPU writes: staging, and per-frame geometry.
    pub fn upload(size: u64, usage: vk::BufferUsageFlags) -> Self {
        BufferDesc {
            size,
            usage,
            location: MemoryLocation::CpuToGpu,
        }
    }

    /// Host-visible memory shaders write and the CPU reads back.
    pub fn readback_storage(size: u64) -> Self {
        BufferDesc {
            size,
            usage: vk::BufferUsageFlags::STORAGE_BUFFER,
            location: MemoryLocation::GpuToCpu,
        }
    }

    /// Host-visible memory the CPU reads back.
    pub fn readback(size: u64) -> Self {
        BufferDesc {
            size,
            usage: vk::BufferUsageFlags::TRANSFER_DST,
            location: MemoryLocation::GpuToCpu,
        }
    }
}

pub struct Buffer {
    pub raw: vk::Buffer,
    pub size: u64,
    allocation: Option<Allocation>,
}

impl Buffer {
    pub fn new(gpu: &Gpu, desc: BufferDesc, name: &str) -> VkResult<Buffer> {
        let info = vk::BufferCreateInfo::default()
            .size(desc.size.max(4))
            .usage(desc.usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        // SAFETY: valid create info on a live device.
        let raw = unsafe { gpu.device.create_buffer(&info, None) }?;
        // SAFETY: raw was just created on this device.
        let requirements = unsafe { gpu.device.get_buffer_memory_requirements(raw) };
        let allocation = gpu.allocator().allocate(&AllocationCreateDesc {
            name,
            requirements,
            location: desc.location,
            linear: true,
            allocation_scheme: AllocationScheme::GpuAllocatorManaged,
        });
        let allocation = match allocation {
            Ok(a) => a,
            Err(e) => {
                // SAFETY: not bound, not in use.
                unsafe { gpu.device.destroy_buffer(raw, None) };
                return Err(e.into());
            }
        };
        // SAFETY: memory and offset come from the allocator for these requirements.
        if let Err(e) = unsafe {
            gpu.device
                .bind_buffer_memory(raw, allocation.memory(), allocation.offset())
        } {
            let _ = gpu.allocator().free(allocation);
            // SAFETY: not in use.
            unsafe { gpu.device.destroy_buffer(raw, None) };
            return Err(e.into());
        }
        gpu.name(raw, name);
        gpu.count_allocation();
        Ok(Buffer {
            raw,
            size: desc.size,
            allocation: Some(allocation),
        })
    }

    /// The CPU view of a host-visible buffer.
    pub fn mapped(&mut self) -> Option<&mut [u8]> {
        let size = self.size as usize;
        self.allocation
            .as_mut()?
            .mapped_slice_mut()
            .map(|s| &mut s[..size])
    }

    /// Host writes need no flush (HOST_COHERENT memory).
    pub fn is_coherent(&self) -> bool {
        self.allocation.as_ref().is_some_and(|a| {
            a.memory_properties()
                .contains(vk::MemoryPropertyFlags::HOST_COHERENT)
        })
    }

    pub fn write(&mut self, offset: usize, bytes: &[u8]) -> bool {
        match self.mapped() {
            Some(m) if offset + bytes.len() <= m.len() => {
                m[offset..offset + bytes.len()].copy_from_slice(bytes);
                true
            }
            _ => false,
        }
    }

    /// Frees the memory and the buffer; the GPU must be done with it.
    pub fn destroy(mut self, gpu: &Gpu) {
        if let Some(a) = self.allocation.take() {
            let _ = gpu.allocator().free(a);
        }
        // SAFETY: the owner guarantees the GPU no longer uses it.
        unsafe { gpu.device.destroy_buffer(self.raw, None) };
    }
}
