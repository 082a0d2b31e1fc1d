//! Instance, validation messenger and device: the owners every other Vulkan object hangs off.
//!
//! Ownership: every resource holds an `Arc<Device>`, the device holds the messenger and an
//! `Arc<Instance>`, so handles are destroyed children first whatever order the caller drops
//! them in; [`Device`]'s `Drop` waits for the GPU to go idle before destroying the device.

use std::ffi::{c_void, CStr, CString};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};

use anyhow::{anyhow, bail, Context as _, Result};
use ash::vk;

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// Whether the Vulkan loader can be loaded and lists `VK_LAYER_KHRONOS_validation`.
pub fn validation_available() -> bool {
    // SAFETY: loading the system's Vulkan loader (see `Device::new`); the entry is dropped
    // (unloaded) at the end, and nothing created from it outlives it.
    unsafe {
        let Ok(entry) = ash::Entry::load() else { return false };
        entry
            .enumerate_instance_layer_properties()
            .map(|layers| layers.iter().any(|l| l.layer_name_as_c_str().ok() == Some(VALIDATION_LAYER)))
            .unwrap_or(false)
    }
}

/// How to create the Vulkan context.
#[derive(Clone, Debug, Default)]
pub struct ContextOptions {
    /// Enable `VK_LAYER_KHRONOS_validation` (with synchronization validation) and count its
    /// messages; fails if the layer is not installed.
    pub validation: bool,
    /// Pick the first physical device whose name contains this (case-insensitive).
    pub device_name: Option<String>,
    /// Use `VK_EXT_mesh_shader` when the device has it.
    pub allow_mesh_shaders: bool,
    /// The display a window will be shown on: enables its surface extensions on the instance
    /// and `VK_KHR_swapchain` on the device (devices without it are skipped). `None`: headless.
    pub display: Option<raw_window_handle::RawDisplayHandle>,
}

/// Warnings and errors reported by the validation layer, counted by the debug messenger.
#[derive(Debug, Default)]
pub struct MessageCounts {
    warnings: AtomicU32,
    errors: AtomicU32,
    first: Mutex<Vec<String>>,
}

impl MessageCounts {
    /// Number of warning-severity messages so far.
    pub fn warnings(&self) -> u32 {
        self.warnings.load(Ordering::Relaxed)
    }
    /// Number of error-severity messages so far.
    pub fn errors(&self) -> u32 {
        self.errors.load(Ordering::Relaxed)
    }
    /// The first few messages (at most 20), for reports.
    pub fn first_messages(&self) -> Vec<String> {
        self.first.lock().map(|m| m.clone()).unwrap_or_default()
    }
}

/// Owner of the loader and the `VkInstance`.
pub struct Instance {
    /// The dlopened loader (`ash` feature `loaded`).
    pub entry: ash::Entry,
    /// The instance function table.
    pub raw: ash::Instance,
    /// Whether the validation layer is enabled.
    pub validation: bool,
}

impl Drop for Instance {
    fn drop(&mut self) {
        // SAFETY: every child (device, messenger) holds an Arc to this instance, so none is alive.
        unsafe { self.raw.destroy_instance(None) };
    }
}

/// Owner of a `VkDebugUtilsMessengerEXT` that counts validation warnings and errors.
pub struct DebugMessenger {
    loader: ash::ext::debug_utils::Instance,
    raw: vk::DebugUtilsMessengerEXT,
    // Kept alive for the callback, which receives a raw pointer to it.
    _counts: Arc<MessageCounts>,
    _instance: Arc<Instance>,
}

impl Drop for DebugMessenger {
    fn drop(&mut self) {
        // SAFETY: the messenger was created from this loader's instance, which `_instance` keeps.
        unsafe { self.loader.destroy_debug_utils_messenger(self.raw, None) };
    }
}

unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: `user` is the `MessageCounts` the messenger owns (an Arc kept for its lifetime);
    // `data` is valid for the duration of the callback per the Vulkan spec.
    let counts = unsafe { &*(user as *const MessageCounts) };
    let message = unsafe {
        if data.is_null() || (*data).p_message.is_null() {
            String::from("(no message)")
        } else {
            CStr::from_ptr((*data).p_message).to_string_lossy().into_owned()
        }
    };
    let label = if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::ERROR) {
        counts.errors.fetch_add(1, Ordering::Relaxed);
        "error"
    } else {
        counts.warnings.fetch_add(1, Ordering::Relaxed);
        "warning"
    };
    eprintln!("vulkan validation {label}: {message}");
    if let Ok(mut first) = counts.first.lock() {
        if first.len() < 20 {
            first.push(format!("{label}: {message}"));
        }
    }
    vk::FALSE
}

/// What the chosen device can do, as far as the preview cares.
#[derive(Clone, Debug)]
pub struct DeviceInfo {
    /// `VkPhysicalDeviceProperties::deviceName`.
    pub name: String,
    /// Driver name and info (`VkPhysicalDeviceDriverProperties`).
    pub driver: String,
    /// Vulkan version the device reports, as "1.3.230".
    pub api_version: String,
    /// `maxComputeWorkGroupCount[0]`.
    pub max_compute_groups_x: u32,
    /// `maxStorageBufferRange` in bytes.
    pub max_storage_buffer_range: u32,
    /// Nanoseconds per timestamp tick (`timestampPeriod`).
    pub timestamp_period_ns: f32,
    /// Whether the queue family writes timestamps (`timestampValidBits > 0`).
    pub timestamps: bool,
    /// Subgroup size reported by `VkPhysicalDeviceSubgroupProperties` (informative only: the
    /// shaders never assume one).
    pub subgroup_size: u32,
    /// Whether `VK_EXT_mesh_shader` (with the `meshShader` and `taskShader` features) is present
    /// on the device.
    pub mesh_shader_available: bool,
    /// Whether the device was created with `VK_EXT_mesh_shader` enabled.
    pub mesh_shader_enabled: bool,
    /// Whether the device was created with `VK_KHR_swapchain` (for a window) enabled.
    pub swapchain_enabled: bool,
    /// `maxTaskWorkGroupCount[0]` when mesh shaders are available.
    pub max_task_groups_x: u32,
    /// `maxTaskWorkGroupTotalCount` when mesh shaders are available.
    pub max_task_groups_total: u32,
}

impl DeviceInfo {
    /// One line for logs: name, driver, Vulkan version, subgroup size, mesh shaders.
    pub fn summary(&self) -> String {
        format!(
            "{} ({}; Vulkan {}; subgroup {}; mesh shaders {})",
            self.name,
            self.driver,
            self.api_version,
            self.subgroup_size,
            if self.mesh_shader_available { "available" } else { "not available" }
        )
    }
}

/// Owner of the `VkDevice` (and its one queue).
pub struct Device {
    /// The device function table.
    pub raw: ash::Device,
    /// The physical device it was created from.
    pub physical: vk::PhysicalDevice,
    /// The queue used for everything (graphics + compute).
    pub queue: vk::Queue,
    /// Its family.
    pub queue_family: u32,
    /// Memory types and heaps.
    pub memory: vk::PhysicalDeviceMemoryProperties,
    /// Capabilities.
    pub info: DeviceInfo,
    /// `VK_EXT_mesh_shader` device functions when enabled.
    pub mesh: Option<ash::ext::mesh_shader::Device>,
    /// Validation message counts (all zero without validation).
    pub counts: Arc<MessageCounts>,
    // Dropped after the device itself (fields drop after `Drop::drop`), in this order.
    _messenger: Option<DebugMessenger>,
    /// The instance, kept alive as long as the device.
    pub instance: Arc<Instance>,
}

impl Drop for Device {
    fn drop(&mut self) {
        // SAFETY: every object created from the device holds an Arc to it, so none is alive;
        // waiting idle first makes sure no submitted work still uses the queue.
        unsafe {
            let _ = self.raw.device_wait_idle();
            self.raw.destroy_device(None);
        }
    }
}

impl Device {
    /// Loads Vulkan, creates an instance (with validation if asked) and a device on the best
    /// physical device that has Vulkan 1.3, a graphics+compute queue, `shaderFloat64` (for the
    /// exact selection arithmetic), `dynamicRendering` and `synchronization2`.
    pub fn new(options: &ContextOptions) -> Result<Arc<Device>> {
        // SAFETY: loading the system's Vulkan loader runs its initialisation code; it is the
        // library Vulkan applications are meant to load.
        let entry = unsafe { ash::Entry::load() }.context("cannot load the Vulkan loader (libvulkan.so.1)")?;
        // SAFETY: plain enumeration calls on a valid entry.
        let layers = unsafe { entry.enumerate_instance_layer_properties() }?;
        let has_validation = layers.iter().any(|l| l.layer_name_as_c_str().ok() == Some(VALIDATION_LAYER));
        if options.validation && !has_validation {
            bail!("--validate: VK_LAYER_KHRONOS_validation is not installed (Debian: vulkan-validationlayers)");
        }
        let validation = options.validation;
        let app_name = CString::new("mres-preview")?;
        let app = vk::ApplicationInfo::default().application_name(&app_name).api_version(vk::API_VERSION_1_3);
        let layer_ptrs = if validation { vec![VALIDATION_LAYER.as_ptr()] } else { vec![] };
        let mut ext_ptrs = if validation { vec![ash::ext::debug_utils::NAME.as_ptr()] } else { vec![] };
        if let Some(display) = options.display {
            ext_ptrs.extend_from_slice(
                ash_window::enumerate_required_extensions(display)
                    .context("this display has no Vulkan surface extension")?,
            );
        }
        let enabled_validation = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
        let mut validation_features =
            vk::ValidationFeaturesEXT::default().enabled_validation_features(&enabled_validation);
        let mut create = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_layer_names(&layer_ptrs)
            .enabled_extension_names(&ext_ptrs);
        if validation {
            create = create.push_next(&mut validation_features);
        }
        // SAFETY: the create info and everything it points to live until the call returns.
        let raw = unsafe { entry.create_instance(&create, None) }.context("vkCreateInstance")?;
        let instance = Arc::new(Instance { entry, raw, validation });

        let counts = Arc::new(MessageCounts::default());
        let messenger = if validation {
            let loader = ash::ext::debug_utils::Instance::new(&instance.entry, &instance.raw);
            let info = vk::DebugUtilsMessengerCreateInfoEXT::default()
                .message_severity(
                    vk::DebugUtilsMessageSeverityFlagsEXT::WARNING | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
                )
                .message_type(
                    vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                        | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                        | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
                )
                .pfn_user_callback(Some(debug_callback))
                .user_data(Arc::as_ptr(&counts) as *mut c_void);
            // SAFETY: `counts` outlives the messenger (the messenger holds a clone).
            let raw = unsafe { loader.create_debug_utils_messenger(&info, None) }?;
            Some(DebugMessenger { loader, raw, _counts: counts.clone(), _instance: instance.clone() })
        } else {
            None
        };

        let (physical, queue_family, info) = pick_physical_device(&instance, options)?;
        // SAFETY: `physical` was enumerated from this instance.
        let memory = unsafe { instance.raw.get_physical_device_memory_properties(physical) };

        let priorities = [1.0f32];
        let queues =
            [vk::DeviceQueueCreateInfo::default().queue_family_index(queue_family).queue_priorities(&priorities)];
        let features10 = vk::PhysicalDeviceFeatures::default().shader_float64(true);
        let mut features13 = vk::PhysicalDeviceVulkan13Features::default()
            .dynamic_rendering(true)
            .synchronization2(true)
            // glslang's SPIR-V 1.6 uses LocalSizeId, which needs maintenance4 (required in 1.3).
            .maintenance4(true);
        let mut mesh_features = vk::PhysicalDeviceMeshShaderFeaturesEXT::default().mesh_shader(true).task_shader(true);
        let mesh_enabled = options.allow_mesh_shaders && info.mesh_shader_available;
        let mut extensions = vec![];
        if mesh_enabled {
            extensions.push(ash::ext::mesh_shader::NAME.as_ptr());
        }
        let swapchain_enabled = options.display.is_some();
        if swapchain_enabled {
            extensions.push(ash::khr::swapchain::NAME.as_ptr());
        }
        let mut features2 = vk::PhysicalDeviceFeatures2::default().features(features10);
        let mut create = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queues)
            .enabled_extension_names(&extensions)
            .push_next(&mut features2)
            .push_next(&mut features13);
        if mesh_enabled {
            create = create.push_next(&mut mesh_features);
        }
        // SAFETY: the create info chain lives until the call returns; features were checked.
        let raw = unsafe { instance.raw.create_device(physical, &create, None) }.context("vkCreateDevice")?;
        // SAFETY: family `queue_family` was requested with one queue.
        let queue = unsafe { raw.get_device_queue(queue_family, 0) };
        let mesh = mesh_enabled.then(|| ash::ext::mesh_shader::Device::new(&instance.raw, &raw));
        let info = DeviceInfo { mesh_shader_enabled: mesh_enabled, swapchain_enabled, ..info };
        Ok(Arc::new(Device {
            raw,
            physical,
            queue,
            queue_family,
            memory,
            info,
            mesh,
            counts,
            _messenger: messenger,
            instance,
        }))
    }

    /// Index of a memory type allowed by `type_bits` that has all of `required`, preferring one
    /// that also has `preferred`.
    pub fn memory_type(
        &self,
        type_bits: u32,
        required: vk::MemoryPropertyFlags,
        preferred: vk::MemoryPropertyFlags,
    ) -> Result<u32> {
        let types = &self.memory.memory_types[..self.memory.memory_type_count as usize];
        let fits = |i: usize, flags: vk::MemoryPropertyFlags| {
            type_bits & (1 << i) != 0 && types[i].property_flags.contains(flags)
        };
        (0..types.len())
            .find(|&i| fits(i, required | preferred))
            .or_else(|| (0..types.len()).find(|&i| fits(i, required)))
            .map(|i| i as u32)
            .ok_or_else(|| anyhow!("no memory type with {required:?}"))
    }
}

fn pick_physical_device(
    instance: &Instance,
    options: &ContextOptions,
) -> Result<(vk::PhysicalDevice, u32, DeviceInfo)> {
    // SAFETY: enumeration and property queries on a valid instance; the chained structs live
    // on the stack for the duration of each call.
    unsafe {
        let devices = instance.raw.enumerate_physical_devices()?;
        let mut candidates = Vec::new();
        let mut rejected = Vec::new();
        for pd in devices {
            let mut driver = vk::PhysicalDeviceDriverProperties::default();
            let mut subgroup = vk::PhysicalDeviceSubgroupProperties::default();
            let mut mesh_props = vk::PhysicalDeviceMeshShaderPropertiesEXT::default();
            let exts = instance.raw.enumerate_device_extension_properties(pd)?;
            let has_mesh_ext =
                exts.iter().any(|e| e.extension_name_as_c_str().ok() == Some(ash::ext::mesh_shader::NAME));
            let has_swapchain =
                exts.iter().any(|e| e.extension_name_as_c_str().ok() == Some(ash::khr::swapchain::NAME));
            let mut props2 = vk::PhysicalDeviceProperties2::default().push_next(&mut driver).push_next(&mut subgroup);
            if has_mesh_ext {
                props2 = props2.push_next(&mut mesh_props);
            }
            instance.raw.get_physical_device_properties2(pd, &mut props2);
            let props = props2.properties;
            let name = props.device_name_as_c_str().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            let mut f13 = vk::PhysicalDeviceVulkan13Features::default();
            let mut fmesh = vk::PhysicalDeviceMeshShaderFeaturesEXT::default();
            let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut f13);
            if has_mesh_ext {
                f2 = f2.push_next(&mut fmesh);
            }
            instance.raw.get_physical_device_features2(pd, &mut f2);
            let f10 = f2.features;
            let families = instance.raw.get_physical_device_queue_family_properties(pd);
            let family = families
                .iter()
                .position(|q| q.queue_flags.contains(vk::QueueFlags::GRAPHICS | vk::QueueFlags::COMPUTE));
            let v = props.api_version;
            let api = format!("{}.{}.{}", vk::api_version_major(v), vk::api_version_minor(v), vk::api_version_patch(v));
            let missing: Vec<&str> = [
                (v < vk::API_VERSION_1_3, "Vulkan 1.3"),
                (family.is_none(), "a graphics+compute queue"),
                (f10.shader_float64 == 0, "shaderFloat64"),
                (f13.dynamic_rendering == 0, "dynamicRendering"),
                (f13.synchronization2 == 0, "synchronization2"),
                (f13.maintenance4 == 0, "maintenance4"),
                (options.display.is_some() && !has_swapchain, "VK_KHR_swapchain"),
            ]
            .iter()
            .filter(|(bad, _)| *bad)
            .map(|(_, what)| *what)
            .collect();
            if let Some(want) = &options.device_name {
                if !name.to_lowercase().contains(&want.to_lowercase()) {
                    rejected.push(format!("{name}: not named {want}"));
                    continue;
                }
            }
            if !missing.is_empty() {
                rejected.push(format!("{name}: lacks {}", missing.join(", ")));
                continue;
            }
            let rank = match props.device_type {
                vk::PhysicalDeviceType::DISCRETE_GPU => 0,
                vk::PhysicalDeviceType::INTEGRATED_GPU => 1,
                vk::PhysicalDeviceType::VIRTUAL_GPU => 2,
                vk::PhysicalDeviceType::CPU => 3,
                _ => 4,
            };
            let cstr = |s: &[std::ffi::c_char]| CStr::from_ptr(s.as_ptr()).to_string_lossy().into_owned();
            let mesh_ok = has_mesh_ext && fmesh.mesh_shader != 0 && fmesh.task_shader != 0;
            let info = DeviceInfo {
                name,
                driver: format!("{} {}", cstr(&driver.driver_name), cstr(&driver.driver_info)),
                api_version: api,
                max_compute_groups_x: props.limits.max_compute_work_group_count[0],
                max_storage_buffer_range: props.limits.max_storage_buffer_range,
                timestamp_period_ns: props.limits.timestamp_period,
                timestamps: family.is_some_and(|f| families[f].timestamp_valid_bits > 0),
                subgroup_size: subgroup.subgroup_size,
                mesh_shader_available: mesh_ok,
                mesh_shader_enabled: false,
                swapchain_enabled: false,
                max_task_groups_x: if mesh_ok { mesh_props.max_task_work_group_count[0] } else { 0 },
                max_task_groups_total: if mesh_ok { mesh_props.max_task_work_group_total_count } else { 0 },
            };
            candidates.push((rank, pd, family.unwrap_or(0) as u32, info));
        }
        candidates.sort_by_key(|c| c.0);
        let (_, pd, family, info) = candidates.into_iter().next().ok_or_else(|| {
            anyhow!(
                "no usable Vulkan device ({})",
                if rejected.is_empty() { "none found".into() } else { rejected.join("; ") }
            )
        })?;
        Ok((pd, family, info))
    }
}
