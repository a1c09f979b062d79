//! Instance, validation, device choice, the device and its queue, and the memory allocator.

use std::ffi::{c_void, CStr, CString};
use std::mem::ManuallyDrop;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};

use super::{VkError, VkResult};

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

#[derive(Clone, Debug, Default)]
pub struct GpuOptions {
    /// Enable the Khronos validation layer and count its messages (an error if it is missing).
    pub validation: bool,
    /// Pick the device whose name contains this (case-insensitive).
    pub device: Option<String>,
    /// Presenting to windows of this display: enables the surface and swapchain extensions.
    pub display: Option<raw_window_handle::RawDisplayHandle>,
}

/// The Vulkan device and everything that lives as long as it.
pub struct Gpu {
    pub entry: ash::Entry,
    pub instance: ash::Instance,
    messenger: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    debug_device: Option<ash::ext::debug_utils::Device>,
    pub physical: vk::PhysicalDevice,
    pub properties: vk::PhysicalDeviceProperties,
    pub device_name: String,
    pub device: ash::Device,
    pub queue: vk::Queue,
    pub queue_family: u32,
    allocator: ManuallyDrop<Mutex<Allocator>>,
    /// Validation warnings and errors seen so far.
    validation_messages: Arc<AtomicU64>,
    /// Raw pointer handed to the debug callback; reclaimed on drop.
    callback_counter: *const AtomicU64,
    pub wireframe_supported: bool,
    /// BC1 textures can be sampled with linear filtering and copied to (feature
    /// `textureCompressionBC`, enabled when present).
    pub bc_textures: bool,
    /// R5G6B5 textures can be sampled with linear filtering and copied to (the texture slots'
    /// format where BC1 tiles are decoded on the CPU, `--texture-format rgb565`).
    pub rgb565_textures: bool,
    /// The largest anisotropy a sampler may use (1: `samplerAnisotropy` or
    /// `shaderResourceMinLod` is missing; the terrain needs both to clamp each tile's texture
    /// level under anisotropic filtering).
    pub max_anisotropy: f32,
    /// Shaders may clamp a sample's level of detail (`shaderResourceMinLod`, enabled).
    pub min_lod: bool,
    /// Shaders may store 16-bit values in storage buffers (`storageBuffer16BitAccess`,
    /// enabled): the index arrays are built on the GPU (`vulkan::indices`).
    pub storage_16bit: bool,
    /// Vertex shaders may write storage buffers (`vertexPipelineStoresAndAtomics`, enabled):
    /// the terrain shader can write the heights it computed for a read-back
    /// (`vkterrain --read-back-heights`).
    pub vertex_stores: bool,
    /// The device counts pipeline statistics (`pipelineStatisticsQuery`, enabled): the frame
    /// log's primitives, vertex and fragment shader invocations of the terrain pass, as the
    /// GPU counted them.
    pub pipeline_statistics: bool,
    /// Every device-local memory type is also host-visible and coherent (lavapipe, most
    /// integrated GPUs): the CPU can write tile data where the GPU reads it.
    unified_memory: bool,
    /// GPU memory allocations made so far (buffers and images).
    allocations: AtomicU64,
}

unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    if severity.intersects(
        vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
            | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
    ) {
        // SAFETY: `user` is the counter the Gpu keeps alive until the messenger is destroyed.
        if let Some(counter) = unsafe { (user as *const AtomicU64).as_ref() } {
            counter.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: the layer passes a valid callback-data struct for the call's duration.
        let message = unsafe { data.as_ref() }
            .and_then(|d| (!d.p_message.is_null()).then(|| unsafe { CStr::from_ptr(d.p_message) }))
            .map(|m| m.to_string_lossy().into_owned())
            .unwrap_or_default();
        eprintln!("validation: {message}");
    }
    vk::FALSE
}

/// The instance, with the validation layer and the debug-utils messenger's extension when
/// asked for (and the surface extensions a display needs); whether debug utils are there.
fn create_instance(entry: &ash::Entry, options: &GpuOptions) -> VkResult<(ash::Instance, bool)> {
    // SAFETY: plain enumeration calls on a loaded entry.
    let layers = unsafe { entry.enumerate_instance_layer_properties() }?;
    let has_layer = layers
        .iter()
        .any(|l| l.layer_name_as_c_str().is_ok_and(|n| n == VALIDATION_LAYER));
    if options.validation && !has_layer {
        return Err(VkError::Unsupported(
            "--validation: the Khronos validation layer is not installed (Debian: vulkan-validationlayers)".into(),
        ));
    }
    // SAFETY: as above.
    let extensions = unsafe { entry.enumerate_instance_extension_properties(None) }?;
    let has_debug_utils = extensions.iter().any(|e| {
        e.extension_name_as_c_str()
            .is_ok_and(|n| n == ash::ext::debug_utils::NAME)
    });
    if options.validation && !has_debug_utils {
        // Without the messenger no message could be counted: a silent pass would lie.
        return Err(VkError::Unsupported(
            "--validation: VK_EXT_debug_utils is missing, so validation messages cannot be counted"
                .into(),
        ));
    }
    let app_name = c"vkterrain";
    let app = vk::ApplicationInfo::default()
        .application_name(app_name)
        .engine_name(app_name)
        .api_version(vk::API_VERSION_1_3);
    let layer_names: Vec<*const i8> = if options.validation {
        vec![VALIDATION_LAYER.as_ptr()]
    } else {
        vec![]
    };
    let mut ext_names: Vec<*const i8> = if has_debug_utils {
        vec![ash::ext::debug_utils::NAME.as_ptr()]
    } else {
        vec![]
    };
    if let Some(display) = options.display {
        let surface = ash_window::enumerate_required_extensions(display).map_err(|e| {
            VkError::Unsupported(format!("this display cannot present with Vulkan: {e}"))
        })?;
        ext_names.extend_from_slice(surface);
    }
    let create = vk::InstanceCreateInfo::default()
        .application_info(&app)
        .enabled_layer_names(&layer_names)
        .enabled_extension_names(&ext_names);
    // SAFETY: every pointer in `create` outlives the call.
    let instance = unsafe { entry.create_instance(&create, None) }?;
    Ok((instance, has_debug_utils))
}

/// The messenger that counts validation warnings and errors into `counter` and prints them.
fn create_messenger(
    entry: &ash::Entry,
    instance: &ash::Instance,
    counter: *const AtomicU64,
) -> VkResult<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)> {
    let loader = ash::ext::debug_utils::Instance::new(entry, instance);
    let info = vk::DebugUtilsMessengerCreateInfoEXT::default()
        .message_severity(
            vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
        )
        .message_type(
            vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
        )
        .pfn_user_callback(Some(debug_callback))
        .user_data(counter as *mut c_void);
    // SAFETY: the callback's user data lives until drop, after the messenger is destroyed.
    let m = unsafe { loader.create_debug_utils_messenger(&info, None) }?;
    Ok((loader, m))
}

/// With a display, the device must offer swapchains.
fn require_swapchain(
    instance: &ash::Instance,
    chosen: (vk::PhysicalDevice, u32, bool),
    options: &GpuOptions,
) -> VkResult<(vk::PhysicalDevice, u32, bool)> {
    if options.display.is_none() {
        return Ok(chosen);
    }
    // SAFETY: enumeration on a device of this instance.
    let exts = unsafe { instance.enumerate_device_extension_properties(chosen.0) }?;
    if exts.iter().any(|e| {
        e.extension_name_as_c_str()
            .is_ok_and(|n| n == ash::khr::swapchain::NAME)
    }) {
        Ok(chosen)
    } else {
        Err(VkError::Unsupported(
            "the device cannot present to windows (no VK_KHR_swapchain)".into(),
        ))
    }
}

/// The optional features the renderer uses, as the device offers them.
fn query_features(
    instance: &ash::Instance,
    physical: vk::PhysicalDevice,
    properties: &vk::PhysicalDeviceProperties,
) -> Features {
    // SAFETY: plain queries on this instance's device.
    let supported = unsafe { instance.get_physical_device_features(physical) };
    let bc1 = unsafe {
        instance.get_physical_device_format_properties(physical, vk::Format::BC1_RGB_UNORM_BLOCK)
    };
    let bc_textures = supported.texture_compression_bc == vk::TRUE
        && bc1.optimal_tiling_features.contains(
            vk::FormatFeatureFlags::SAMPLED_IMAGE
                | vk::FormatFeatureFlags::SAMPLED_IMAGE_FILTER_LINEAR
                | vk::FormatFeatureFlags::TRANSFER_DST,
        );
    // SAFETY: plain query on this instance's device.
    let rgb565 = unsafe {
        instance.get_physical_device_format_properties(physical, vk::Format::R5G6B5_UNORM_PACK16)
    };
    let rgb565_textures = rgb565.optimal_tiling_features.contains(
        vk::FormatFeatureFlags::SAMPLED_IMAGE
            | vk::FormatFeatureFlags::SAMPLED_IMAGE_FILTER_LINEAR
            | vk::FormatFeatureFlags::TRANSFER_DST,
    );
    let min_lod = supported.shader_resource_min_lod == vk::TRUE;
    let storage_16bit = {
        let mut v11 = vk::PhysicalDeviceVulkan11Features::default();
        let mut features = vk::PhysicalDeviceFeatures2::default().push_next(&mut v11);
        // SAFETY: plain query on this instance's device; the chain outlives the call.
        unsafe { instance.get_physical_device_features2(physical, &mut features) };
        v11.storage_buffer16_bit_access == vk::TRUE
    };
    let anisotropy = supported.sampler_anisotropy == vk::TRUE && min_lod;
    Features {
        bc_textures,
        rgb565_textures,
        min_lod,
        vertex_stores: supported.vertex_pipeline_stores_and_atomics == vk::TRUE,
        pipeline_statistics: supported.pipeline_statistics_query == vk::TRUE,
        storage_16bit,
        anisotropy,
        max_anisotropy: if anisotropy {
            properties.limits.max_sampler_anisotropy.max(1.0)
        } else {
            1.0
        },
    }
}

/// The logical device with one queue of `family` and the features the renderer uses.
fn create_device(
    instance: &ash::Instance,
    (physical, family): (vk::PhysicalDevice, u32),
    f: &Features,
    wireframe: bool,
    swapchain: bool,
) -> VkResult<ash::Device> {
    let priorities = [1.0f32];
    let queues = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(family)
        .queue_priorities(&priorities)];
    let mut v13 = vk::PhysicalDeviceVulkan13Features::default().dynamic_rendering(true);
    let mut v11 =
        vk::PhysicalDeviceVulkan11Features::default().storage_buffer16_bit_access(f.storage_16bit);
    let features = vk::PhysicalDeviceFeatures::default()
        .fill_mode_non_solid(wireframe)
        .texture_compression_bc(f.bc_textures)
        .sampler_anisotropy(f.anisotropy)
        .shader_resource_min_lod(f.min_lod)
        .vertex_pipeline_stores_and_atomics(f.vertex_stores)
        .pipeline_statistics_query(f.pipeline_statistics);
    let device_extensions: Vec<*const i8> = if swapchain {
        vec![ash::khr::swapchain::NAME.as_ptr()]
    } else {
        vec![]
    };
    let device_info = vk::DeviceCreateInfo::default()
        .queue_create_infos(&queues)
        .enabled_extension_names(&device_extensions)
        .enabled_features(&features)
        .push_next(&mut v13)
        .push_next(&mut v11);
    // SAFETY: the features were checked in open_device; pointers outlive the call.
    Ok(unsafe { instance.create_device(physical, &device_info, None) }?)
}

/// Whether every device-local memory type is also host-visible and coherent (lavapipe,
/// integrated GPUs, resizable BAR).
fn unified_memory(instance: &ash::Instance, physical: vk::PhysicalDevice) -> bool {
    // SAFETY: plain property query on this instance's device.
    let memory = unsafe { instance.get_physical_device_memory_properties(physical) };
    let types = &memory.memory_types[..memory.memory_type_count as usize];
    let host = vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
    let local: Vec<_> = types
        .iter()
        .filter(|t| {
            t.property_flags
                .contains(vk::MemoryPropertyFlags::DEVICE_LOCAL)
        })
        .collect();
    !local.is_empty() && local.iter().all(|t| t.property_flags.contains(host))
}

/// What the chosen device can do that the renderer enables or works around.
struct Features {
    bc_textures: bool,
    rgb565_textures: bool,
    min_lod: bool,
    vertex_stores: bool,
    pipeline_statistics: bool,
    storage_16bit: bool,
    anisotropy: bool,
    max_anisotropy: f32,
}

impl Gpu {
    pub fn new(options: &GpuOptions) -> VkResult<Gpu> {
        // SAFETY: loading the system Vulkan loader; failure is reported, not assumed.
        let entry = unsafe { ash::Entry::load() }.map_err(|e| {
            VkError::Unsupported(format!(
                "cannot load the Vulkan loader (install libvulkan1): {e}"
            ))
        })?;
        let (instance, has_debug_utils) = create_instance(&entry, options)?;
        let validation_messages = Arc::new(AtomicU64::new(0));
        let callback_counter = Arc::into_raw(validation_messages.clone());
        let messenger = if has_debug_utils && options.validation {
            match create_messenger(&entry, &instance, callback_counter) {
                Ok(m) => Some(m),
                Err(e) => {
                    // SAFETY: nothing else was created from the instance yet.
                    unsafe {
                        instance.destroy_instance(None);
                        drop(Arc::from_raw(callback_counter));
                    }
                    return Err(e);
                }
            }
        } else {
            None
        };
        let result = Self::open_device(&instance, options)
            .and_then(|chosen| require_swapchain(&instance, chosen, options));
        let (physical, queue_family, wireframe_supported) = match result {
            Ok(v) => v,
            Err(e) => {
                // SAFETY: nothing else was created from the instance yet.
                unsafe {
                    if let Some((loader, m)) = &messenger {
                        loader.destroy_debug_utils_messenger(*m, None);
                    }
                    instance.destroy_instance(None);
                    drop(Arc::from_raw(callback_counter));
                }
                return Err(e);
            }
        };
        // SAFETY: physical comes from this instance.
        let properties = unsafe { instance.get_physical_device_properties(physical) };
        let device_name = properties
            .device_name_as_c_str()
            .map(|c| c.to_string_lossy().into_owned())
            .unwrap_or_default();
        let features = query_features(&instance, physical, &properties);
        let device = create_device(
            &instance,
            (physical, queue_family),
            &features,
            wireframe_supported,
            options.display.is_some(),
        )?;
        // SAFETY: family and index exist (one queue requested).
        let queue = unsafe { device.get_device_queue(queue_family, 0) };
        let debug_device =
            has_debug_utils.then(|| ash::ext::debug_utils::Device::new(&instance, &device));
        let allocator = Allocator::new(&AllocatorCreateDesc {
            instance: instance.clone(),
            device: device.clone(),
            physical_device: physical,
            debug_settings: Default::default(),
            buffer_device_address: false,
            allocation_sizes: Default::default(),
        })?;
        let unified_memory = unified_memory(&instance, physical);
        let gpu = Gpu {
            entry,
            instance,
            messenger,
            debug_device,
            physical,
            properties,
            device_name,
            device,
            queue,
            queue_family,
            allocator: ManuallyDrop::new(Mutex::new(allocator)),
            validation_messages,
            callback_counter,
            wireframe_supported,
            bc_textures: features.bc_textures,
            rgb565_textures: features.rgb565_textures,
            max_anisotropy: features.max_anisotropy,
            min_lod: features.min_lod,
            storage_16bit: features.storage_16bit,
            vertex_stores: features.vertex_stores,
            pipeline_statistics: features.pipeline_statistics,
            unified_memory,
            allocations: AtomicU64::new(0),
        };
        gpu.name(gpu.queue, "graphics queue");
        Ok(gpu)
    }

    /// Chooses the device: `--device` by name, else discrete, integrated, virtual, then CPU
    /// (lavapipe). Requires Vulkan 1.3 dynamic rendering and a graphics queue.
    fn open_device(
        instance: &ash::Instance,
        options: &GpuOptions,
    ) -> VkResult<(vk::PhysicalDevice, u32, bool)> {
        // SAFETY: enumeration on a valid instance.
        let devices = unsafe { instance.enumerate_physical_devices() }?;
        let mut candidates = Vec::new();
        let mut rejected = Vec::new();
        for pd in devices {
            // SAFETY: pd comes from this instance.
            let props = unsafe { instance.get_physical_device_properties(pd) };
            let name = props
                .device_name_as_c_str()
                .map(|c| c.to_string_lossy().into_owned())
                .unwrap_or_default();
            if let Some(want) = &options.device {
                if !name.to_lowercase().contains(&want.to_lowercase()) {
                    rejected.push(format!("{name} (not named {want:?})"));
                    continue;
                }
            }
            let mut v13 = vk::PhysicalDeviceVulkan13Features::default();
            let mut features = vk::PhysicalDeviceFeatures2::default().push_next(&mut v13);
            // SAFETY: as above; the chain outlives the call.
            unsafe { instance.get_physical_device_features2(pd, &mut features) };
            let wireframe = features.features.fill_mode_non_solid == vk::TRUE;
            if props.api_version < vk::API_VERSION_1_3 || v13.dynamic_rendering != vk::TRUE {
                rejected.push(format!("{name} (lacks Vulkan 1.3 dynamic rendering)"));
                continue;
            }
            // SAFETY: as above.
            let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
            let Some(family) = families
                .iter()
                .position(|f| f.queue_flags.contains(vk::QueueFlags::GRAPHICS))
            else {
                rejected.push(format!("{name} (no graphics queue)"));
                continue;
            };
            let rank = match props.device_type {
                vk::PhysicalDeviceType::DISCRETE_GPU => 0,
                vk::PhysicalDeviceType::INTEGRATED_GPU => 1,
                vk::PhysicalDeviceType::VIRTUAL_GPU => 2,
                vk::PhysicalDeviceType::CPU => 3,
                _ => 4,
            };
            candidates.push((rank, pd, family as u32, wireframe));
        }
        candidates.sort_by_key(|c| c.0);
        candidates.first().map(|&(_, pd, family, wireframe)| (pd, family, wireframe)).ok_or_else(|| {
            VkError::Unsupported(if rejected.is_empty() {
                "no Vulkan device found (on a machine without a GPU install mesa-vulkan-drivers for lavapipe)".into()
            } else {
                format!("no usable Vulkan device: {}", rejected.join("; "))
            })
        })
    }

    /// Validation warnings and errors so far (0 without `--validation`).
    pub fn validation_messages(&self) -> u64 {
        self.validation_messages.load(Ordering::Relaxed)
    }

    pub fn unified_memory(&self) -> bool {
        self.unified_memory
    }

    /// Counts one GPU memory allocation (the log's `gpu_allocations`).
    pub fn count_allocation(&self) {
        self.allocations.fetch_add(1, Ordering::Relaxed);
    }

    /// GPU memory allocations so far.
    pub fn allocations(&self) -> u64 {
        self.allocations.load(Ordering::Relaxed)
    }

    pub fn allocator(&self) -> MutexGuard<'_, Allocator> {
        // A poisoned allocator means a panic elsewhere already; keep going with its state.
        self.allocator.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Names a Vulkan object for validation messages and debuggers.
    pub fn name<H: vk::Handle>(&self, handle: H, name: &str) {
        if let (Some(d), Ok(name)) = (&self.debug_device, CString::new(name)) {
            let info = vk::DebugUtilsObjectNameInfoEXT::default()
                .object_handle(handle)
                .object_name(&name);
            // SAFETY: the handle belongs to this device; a failed name is harmless.
            let _ = unsafe { d.set_debug_utils_object_name(&info) };
        }
    }

    pub fn wait_idle(&self) {
        // SAFETY: the device is valid; errors here mean loss, reported by the next submit.
        let _ = unsafe { self.device.device_wait_idle() };
    }
}

impl Drop for Gpu {
    fn drop(&mut self) {
        self.wait_idle();
        // SAFETY: owners of buffers, images and pipelines destroyed theirs before the Gpu
        // (they borrow it); the allocator goes before the device, the device before the
        // instance, the messenger before its user data.
        unsafe {
            ManuallyDrop::drop(&mut self.allocator);
            self.device.destroy_device(None);
            if let Some((loader, m)) = &self.messenger {
                loader.destroy_debug_utils_messenger(*m, None);
            }
            self.instance.destroy_instance(None);
            drop(Arc::from_raw(self.callback_counter));
        }
    }
}
