//! Owners of buffers, images and the small pipeline objects. Each `Drop` destroys only its own
//! handle; each holds an `Arc<Device>` so the device outlives it.

use std::sync::Arc;

use anyhow::{bail, Context as _, Result};
use ash::vk;

use super::context::Device;

/// Where a buffer's memory lives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Location {
    /// Device-local; filled by a copy (or directly, where device memory is host-visible).
    Gpu,
    /// Host-visible and coherent, written by the CPU each frame.
    Upload,
    /// Host-visible and coherent, preferably cached, read by the CPU after a fence.
    Readback,
}

/// Owner of a `VkBuffer` and its dedicated memory (mapped when host-visible).
pub struct Buffer {
    device: Arc<Device>,
    /// The buffer handle.
    pub raw: vk::Buffer,
    memory: vk::DeviceMemory,
    /// Size in bytes.
    pub size: u64,
    mapped: *mut u8,
}

impl Buffer {
    /// Creates a buffer of `size` bytes (rounded up to 4, at least 4).
    pub fn new(device: &Arc<Device>, size: u64, usage: vk::BufferUsageFlags, location: Location) -> Result<Buffer> {
        let size = size.max(4).next_multiple_of(4);
        let info = vk::BufferCreateInfo::default().size(size).usage(usage).sharing_mode(vk::SharingMode::EXCLUSIVE);
        // SAFETY: valid device and create info; the handle is destroyed in Drop (or below on error).
        let raw = unsafe { device.raw.create_buffer(&info, None) }.context("vkCreateBuffer")?;
        let mut buffer = Buffer {
            device: device.clone(),
            raw,
            memory: vk::DeviceMemory::null(),
            size,
            mapped: std::ptr::null_mut(),
        };
        // SAFETY: `raw` is a live buffer of this device.
        let req = unsafe { device.raw.get_buffer_memory_requirements(raw) };
        use vk::MemoryPropertyFlags as M;
        let (required, preferred) = match location {
            Location::Gpu => (M::empty(), M::DEVICE_LOCAL),
            Location::Upload => (M::HOST_VISIBLE | M::HOST_COHERENT, M::empty()),
            Location::Readback => (M::HOST_VISIBLE | M::HOST_COHERENT, M::HOST_CACHED),
        };
        let type_index = device.memory_type(req.memory_type_bits, required, preferred)?;
        let alloc = vk::MemoryAllocateInfo::default().allocation_size(req.size).memory_type_index(type_index);
        // SAFETY: allocation of a type the buffer accepts; freed in Drop.
        buffer.memory = unsafe { device.raw.allocate_memory(&alloc, None) }
            .with_context(|| format!("vkAllocateMemory of {} bytes", req.size))?;
        // SAFETY: fresh memory of a compatible type, offset 0, not bound before.
        unsafe { device.raw.bind_buffer_memory(raw, buffer.memory, 0) }?;
        let flags = device.memory.memory_types[type_index as usize].property_flags;
        if flags.contains(M::HOST_VISIBLE | M::HOST_COHERENT) {
            // SAFETY: host-visible memory, mapped once for the buffer's lifetime.
            buffer.mapped =
                unsafe { device.raw.map_memory(buffer.memory, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty()) }?
                    as *mut u8;
        }
        Ok(buffer)
    }

    /// Whether the CPU can read and write the buffer directly.
    pub fn is_mapped(&self) -> bool {
        !self.mapped.is_null()
    }

    /// Copies `data` to the start of a mapped buffer.
    pub fn write(&self, data: &[u8]) -> Result<()> {
        if self.mapped.is_null() || data.len() as u64 > self.size {
            bail!(
                "buffer write of {} bytes into a {} buffer of {} bytes",
                data.len(),
                if self.mapped.is_null() { "unmapped" } else { "mapped" },
                self.size
            );
        }
        // SAFETY: the mapping covers `size` bytes and does not overlap `data` (a Rust slice).
        unsafe { std::ptr::copy_nonoverlapping(data.as_ptr(), self.mapped, data.len()) };
        Ok(())
    }

    /// Copies the first `len` bytes of a mapped buffer out. The caller must have waited for
    /// the GPU work that wrote them (a fence), so that they are visible (the memory is coherent).
    pub fn read(&self, len: usize) -> Result<Vec<u8>> {
        if self.mapped.is_null() || len as u64 > self.size {
            bail!("buffer read of {len} bytes from a buffer of {} bytes (mapped: {})", self.size, self.is_mapped());
        }
        let mut out = vec![0u8; len];
        // SAFETY: the mapping covers `size >= len` bytes.
        unsafe { std::ptr::copy_nonoverlapping(self.mapped, out.as_mut_ptr(), len) };
        Ok(out)
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        // SAFETY: owned handles of a live device; the GPU is no longer using them (passes wait
        // on their fence before returning, and the device waits idle before it is destroyed).
        unsafe {
            self.device.raw.destroy_buffer(self.raw, None);
            if self.memory != vk::DeviceMemory::null() {
                self.device.raw.free_memory(self.memory, None);
            }
        }
    }
}

/// Owner of a 2D `VkImage`, its dedicated memory and one view of it.
pub struct Image {
    device: Arc<Device>,
    /// The image handle.
    pub raw: vk::Image,
    memory: vk::DeviceMemory,
    /// A view of the whole image.
    pub view: vk::ImageView,
    /// Size in pixels.
    pub extent: vk::Extent2D,
}

impl Image {
    /// Creates a device-local 2D image with one mip level and a view of it.
    pub fn new(
        device: &Arc<Device>,
        extent: vk::Extent2D,
        format: vk::Format,
        usage: vk::ImageUsageFlags,
        aspect: vk::ImageAspectFlags,
    ) -> Result<Image> {
        let info = vk::ImageCreateInfo::default()
            .image_type(vk::ImageType::TYPE_2D)
            .format(format)
            .extent(vk::Extent3D { width: extent.width, height: extent.height, depth: 1 })
            .mip_levels(1)
            .array_layers(1)
            .samples(vk::SampleCountFlags::TYPE_1)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(usage)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        // SAFETY: valid create info; destroyed in Drop.
        let raw = unsafe { device.raw.create_image(&info, None) }.context("vkCreateImage")?;
        let mut image = Image {
            device: device.clone(),
            raw,
            memory: vk::DeviceMemory::null(),
            view: vk::ImageView::null(),
            extent,
        };
        // SAFETY: `raw` is a live image of this device.
        let req = unsafe { device.raw.get_image_memory_requirements(raw) };
        let type_index = device.memory_type(
            req.memory_type_bits,
            vk::MemoryPropertyFlags::empty(),
            vk::MemoryPropertyFlags::DEVICE_LOCAL,
        )?;
        let alloc = vk::MemoryAllocateInfo::default().allocation_size(req.size).memory_type_index(type_index);
        // SAFETY: as for buffers; freed in Drop.
        image.memory = unsafe { device.raw.allocate_memory(&alloc, None) }?;
        // SAFETY: fresh memory of a compatible type.
        unsafe { device.raw.bind_image_memory(raw, image.memory, 0) }?;
        let view_info = vk::ImageViewCreateInfo::default()
            .image(raw)
            .view_type(vk::ImageViewType::TYPE_2D)
            .format(format)
            .subresource_range(subresource_range(aspect));
        // SAFETY: the image is bound to memory; the view is destroyed before it in Drop.
        image.view = unsafe { device.raw.create_image_view(&view_info, None) }?;
        Ok(image)
    }
}

/// The single mip level and layer of an image with `aspect`.
pub fn subresource_range(aspect: vk::ImageAspectFlags) -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange {
        aspect_mask: aspect,
        base_mip_level: 0,
        level_count: 1,
        base_array_layer: 0,
        layer_count: 1,
    }
}

impl Drop for Image {
    fn drop(&mut self) {
        // SAFETY: owned handles, no longer in use by the GPU (see Buffer's Drop).
        unsafe {
            if self.view != vk::ImageView::null() {
                self.device.raw.destroy_image_view(self.view, None);
            }
            self.device.raw.destroy_image(self.raw, None);
            if self.memory != vk::DeviceMemory::null() {
                self.device.raw.free_memory(self.memory, None);
            }
        }
    }
}

/// Declares an owner type for a handle destroyed by one `ash::Device` method.
macro_rules! owner {
    ($(#[$doc:meta])* $name:ident, $handle:ty, $destroy:ident) => {
        $(#[$doc])*
        pub struct $name {
            device: Arc<Device>,
            /// The handle.
            pub raw: $handle,
        }

        impl $name {
            /// Takes ownership of `raw`, created from `device`.
            ///
            /// # Safety
            /// `raw` must be a valid handle created from `device` and owned by nobody else.
            pub unsafe fn from_raw(device: &Arc<Device>, raw: $handle) -> $name {
                $name { device: device.clone(), raw }
            }
        }

        impl Drop for $name {
            fn drop(&mut self) {
                // SAFETY: `from_raw`'s contract: we own the handle; it is no longer in use by
                // the GPU (work is waited for before owners are dropped).
                unsafe { self.device.raw.$destroy(self.raw, None) };
            }
        }
    };
}

owner!(
    /// Owner of a `VkShaderModule`.
    ShaderModule, vk::ShaderModule, destroy_shader_module);
owner!(
    /// Owner of a `VkDescriptorSetLayout`.
    DescriptorSetLayout, vk::DescriptorSetLayout, destroy_descriptor_set_layout);
owner!(
    /// Owner of a `VkPipelineLayout`.
    PipelineLayout, vk::PipelineLayout, destroy_pipeline_layout);
owner!(
    /// Owner of a `VkPipeline`.
    Pipeline, vk::Pipeline, destroy_pipeline);
owner!(
    /// Owner of a `VkDescriptorPool` (its sets are freed with it).
    DescriptorPool, vk::DescriptorPool, destroy_descriptor_pool);
owner!(
    /// Owner of a `VkCommandPool` (its command buffers are freed with it).
    CommandPool, vk::CommandPool, destroy_command_pool);
owner!(
    /// Owner of a `VkFence`.
    Fence, vk::Fence, destroy_fence);
owner!(
    /// Owner of a `VkQueryPool`.
    QueryPool, vk::QueryPool, destroy_query_pool);
owner!(
    /// Owner of a binary `VkSemaphore`.
    Semaphore, vk::Semaphore, destroy_semaphore);

impl Semaphore {
    /// Creates an unsignalled binary semaphore.
    pub fn new(device: &Arc<Device>) -> Result<Semaphore> {
        // SAFETY: default create info; the handle goes straight into its owner.
        unsafe {
            let raw =
                device.raw.create_semaphore(&vk::SemaphoreCreateInfo::default(), None).context("vkCreateSemaphore")?;
            Ok(Semaphore::from_raw(device, raw))
        }
    }
}

impl ShaderModule {
    /// Creates a shader module from SPIR-V bytes (any alignment).
    pub fn new(device: &Arc<Device>, spirv: &[u8]) -> Result<ShaderModule> {
        let words = ash::util::read_spv(&mut std::io::Cursor::new(spirv)).context("invalid SPIR-V")?;
        let info = vk::ShaderModuleCreateInfo::default().code(&words);
        // SAFETY: valid SPIR-V words; the module is owned by the returned value.
        unsafe {
            let raw = device.raw.create_shader_module(&info, None)?;
            Ok(ShaderModule::from_raw(device, raw))
        }
    }
}
