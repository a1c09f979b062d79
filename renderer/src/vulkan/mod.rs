//! The thin Vulkan layer: one file per kind of object, each creating and destroying its kind.
//! Nothing above this module calls raw `ash` to make resources.

pub mod buffer;
pub mod compute;
pub mod context;
pub mod decode;
pub mod image;
pub mod indices;
pub mod morph_pass;
pub mod pipeline;
pub mod pool;
pub mod sets;
pub mod swapchain;
pub mod sync;
pub mod texture;
pub mod timestamps;

pub use buffer::Buffer;
pub use context::{Gpu, GpuOptions};
pub use image::Image;

use ash::vk;

/// What can go wrong talking to the driver, mapped once from `vk::Result`.
#[derive(Debug, thiserror::Error)]
pub enum VkError {
    #[error("out of GPU memory")]
    OutOfMemory,
    #[error("the GPU device was lost")]
    DeviceLost,
    #[error("Vulkan call failed: {0}")]
    Unexpected(vk::Result),
    #[error("GPU memory allocation failed: {0}")]
    Allocation(#[from] gpu_allocator::AllocationError),
    /// The machine cannot run the renderer (no device, missing feature or layer).
    #[error("{0}")]
    Unsupported(String),
    /// The GPU found the tile data inconsistent (an index array built from a tile's vertices
    /// does not come out as the file says).
    #[error("{0}")]
    InvalidData(String),
}

impl From<vk::Result> for VkError {
    fn from(r: vk::Result) -> Self {
        match r {
            vk::Result::ERROR_OUT_OF_DEVICE_MEMORY | vk::Result::ERROR_OUT_OF_HOST_MEMORY => {
                VkError::OutOfMemory
            }
            vk::Result::ERROR_DEVICE_LOST => VkError::DeviceLost,
            other => VkError::Unexpected(other),
        }
    }
}

pub type VkResult<T> = Result<T, VkError>;
