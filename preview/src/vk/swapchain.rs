//! The window's side of Vulkan: the surface and the swapchain, each an owner type.
//!
//! Ownership: [`Surface`] holds the window (so the window outlives the surface) and an
//! `Arc<Instance>`; [`Swapchain`] holds an `Arc<Surface>` and an `Arc<Device>`, so whatever order
//! the caller drops them in, the swapchain goes first, then the surface, then the window, and
//! the instance last. The renderer draws into its own colour image and blits it into the
//! acquired swapchain image ([`super::Renderer::render_to_swapchain`]), so the window shows
//! exactly what the headless path renders.

use std::any::Any;
use std::sync::Arc;

use anyhow::{bail, Context as _, Result};
use ash::vk;
use raw_window_handle::{HasDisplayHandle, HasWindowHandle};

use super::context::{Device, Instance};
use super::resources::Semaphore;

/// Owner of a `VkSurfaceKHR` and of the window it was created for.
pub struct Surface {
    loader: ash::khr::surface::Instance,
    /// The surface handle.
    pub raw: vk::SurfaceKHR,
    // Dropped after the surface (fields drop after `Drop::drop`): the window outlives it.
    _window: Box<dyn Any + Send + Sync>,
    _instance: Arc<Instance>,
}

impl Drop for Surface {
    fn drop(&mut self) {
        // SAFETY: every swapchain of this surface holds an Arc to it, so none is alive; the
        // instance and the window are fields, dropped after this.
        unsafe { self.loader.destroy_surface(self.raw, None) };
    }
}

impl Surface {
    /// Creates a surface for `window` on `device`'s instance and checks that the device's queue
    /// can present to it. The device must have been created with
    /// [`super::ContextOptions::display`] set to this window's display.
    pub fn new<W: HasWindowHandle + HasDisplayHandle + Send + Sync + 'static>(
        device: &Arc<Device>,
        window: Arc<W>,
    ) -> Result<Arc<Surface>> {
        if !device.info.swapchain_enabled {
            bail!("the Vulkan device was created without a display (ContextOptions::display)");
        }
        let display = window.display_handle().context("window display handle")?.as_raw();
        let handle = window.window_handle().context("window handle")?.as_raw();
        let instance = &device.instance;
        let loader = ash::khr::surface::Instance::new(&instance.entry, &instance.raw);
        // SAFETY: the handles belong to `window`, which the returned owner keeps alive for the
        // surface's lifetime; the instance was created with the display's surface extensions.
        let raw = unsafe { ash_window::create_surface(&instance.entry, &instance.raw, display, handle, None) }
            .context("vkCreate*SurfaceKHR")?;
        let surface = Surface { loader, raw, _window: Box::new(window), _instance: instance.clone() };
        // SAFETY: the queue family and the physical device belong to this instance.
        let supported = unsafe {
            surface.loader.get_physical_device_surface_support(device.physical, device.queue_family, surface.raw)
        }?;
        if !supported {
            bail!("{} cannot present to this window from its graphics queue (try another --device)", device.info.name);
        }
        Ok(Arc::new(surface))
    }
}

/// A swapchain image acquired for one frame.
#[derive(Clone, Copy, Debug)]
pub struct AcquiredImage {
    /// Index into the swapchain's images.
    pub index: u32,
    /// The image (owned by the swapchain).
    pub image: vk::Image,
    /// Signalled when the image may be written: the frame's submission waits on it.
    pub acquired: vk::Semaphore,
    /// To be signalled by the frame's submission: presentation waits on it.
    pub rendered: vk::Semaphore,
}

/// Owner of a `VkSwapchainKHR` (its images belong to it) and of the semaphores of its frames.
pub struct Swapchain {
    loader: ash::khr::swapchain::Device,
    /// The swapchain handle.
    pub raw: vk::SwapchainKHR,
    /// Its images.
    images: Vec<vk::Image>,
    /// Size of every image, pixels.
    pub extent: vk::Extent2D,
    /// Format of the images.
    pub format: vk::Format,
    /// Whether the images can be copied out (screenshots).
    pub readable: bool,
    // One semaphore for acquisition (a frame waits for its submission's fence before the next
    // acquire, so one suffices) and one per image for presentation: an image's semaphore is
    // free again once that image is acquired again.
    acquired: Semaphore,
    rendered: Vec<Semaphore>,
    device: Arc<Device>,
    _surface: Arc<Surface>,
}

impl Drop for Swapchain {
    fn drop(&mut self) {
        // SAFETY: presentation may still wait on our semaphores; after the queue is idle no
        // work uses the images, which are destroyed with the swapchain. The semaphores and the
        // surface are fields, dropped after this.
        unsafe {
            let _ = self.device.raw.queue_wait_idle(self.device.queue);
            self.loader.destroy_swapchain(self.raw, None);
        }
    }
}

/// Swapchain formats the preview can blit into without changing colour values, best first: the
/// renderer writes display-ready 8-bit values (as in headless PNGs), so a UNORM format shows
/// them unchanged where an sRGB one would encode them a second time.
const PREFERRED_FORMATS: [vk::Format; 2] = [vk::Format::B8G8R8A8_UNORM, vk::Format::R8G8B8A8_UNORM];

impl Swapchain {
    /// Creates a swapchain of `width` × `height` pixels (the surface's own extent where it has
    /// one), FIFO presentation (vsync), replacing `old` if given (which the caller then drops).
    pub fn new(
        device: &Arc<Device>,
        surface: &Arc<Surface>,
        width: u32,
        height: u32,
        old: Option<&Swapchain>,
    ) -> Result<Swapchain> {
        let pd = device.physical;
        let loader = ash::khr::swapchain::Device::new(&device.instance.raw, &device.raw);
        // SAFETY: queries on a live surface and physical device of the same instance.
        let (caps, formats) = unsafe {
            (
                surface.loader.get_physical_device_surface_capabilities(pd, surface.raw)?,
                surface.loader.get_physical_device_surface_formats(pd, surface.raw)?,
            )
        };
        let format = PREFERRED_FORMATS
            .iter()
            .find_map(|f| formats.iter().find(|s| s.format == *f))
            .or(formats.first())
            .copied()
            .context("the surface reports no formats")?;
        // SAFETY: plain property query.
        let props = unsafe { device.instance.raw.get_physical_device_format_properties(pd, format.format) };
        if !props.optimal_tiling_features.contains(vk::FormatFeatureFlags::BLIT_DST) {
            bail!("swapchain format {:?} cannot be a blit destination on {}", format.format, device.info.name);
        }
        if !caps.supported_usage_flags.contains(vk::ImageUsageFlags::TRANSFER_DST) {
            bail!("the surface's images cannot be transfer destinations on {}", device.info.name);
        }
        let readable = caps.supported_usage_flags.contains(vk::ImageUsageFlags::TRANSFER_SRC);
        let extent = if caps.current_extent.width != u32::MAX {
            caps.current_extent
        } else {
            vk::Extent2D {
                width: width.clamp(caps.min_image_extent.width, caps.max_image_extent.width),
                height: height.clamp(caps.min_image_extent.height, caps.max_image_extent.height),
            }
        };
        if extent.width == 0 || extent.height == 0 {
            bail!("zero-sized swapchain (minimised window)");
        }
        let mut image_count = caps.min_image_count + 1;
        if caps.max_image_count > 0 {
            image_count = image_count.min(caps.max_image_count);
        }
        let usage = vk::ImageUsageFlags::TRANSFER_DST
            | if readable { vk::ImageUsageFlags::TRANSFER_SRC } else { vk::ImageUsageFlags::empty() };
        let alpha = [
            vk::CompositeAlphaFlagsKHR::OPAQUE,
            vk::CompositeAlphaFlagsKHR::INHERIT,
            vk::CompositeAlphaFlagsKHR::PRE_MULTIPLIED,
            vk::CompositeAlphaFlagsKHR::POST_MULTIPLIED,
        ]
        .into_iter()
        .find(|a| caps.supported_composite_alpha.contains(*a))
        .unwrap_or(vk::CompositeAlphaFlagsKHR::OPAQUE);
        let info = vk::SwapchainCreateInfoKHR::default()
            .surface(surface.raw)
            .min_image_count(image_count)
            .image_format(format.format)
            .image_color_space(format.color_space)
            .image_extent(extent)
            .image_array_layers(1)
            .image_usage(usage)
            .image_sharing_mode(vk::SharingMode::EXCLUSIVE)
            .pre_transform(caps.current_transform)
            .composite_alpha(alpha)
            // FIFO is the one mode every device has.
            .present_mode(vk::PresentModeKHR::FIFO)
            .clipped(true)
            .old_swapchain(old.map_or(vk::SwapchainKHR::null(), |o| o.raw));
        // SAFETY: valid create info on a surface this device can present to (checked when the
        // surface was made); the handle goes into the owner straight away.
        let raw = unsafe { loader.create_swapchain(&info, None) }.context("vkCreateSwapchainKHR")?;
        let mut swapchain = Swapchain {
            loader,
            raw,
            images: Vec::new(),
            extent,
            format: format.format,
            readable,
            acquired: Semaphore::new(device)?,
            rendered: Vec::new(),
            device: device.clone(),
            _surface: surface.clone(),
        };
        // SAFETY: the swapchain is live.
        swapchain.images = unsafe { swapchain.loader.get_swapchain_images(raw) }?;
        swapchain.rendered = (0..swapchain.images.len()).map(|_| Semaphore::new(device)).collect::<Result<_>>()?;
        Ok(swapchain)
    }

    /// Acquires the next image, waiting for one as long as it takes; `None` when the swapchain
    /// no longer matches the surface (recreate it). The caller must submit a frame that waits
    /// on [`AcquiredImage::acquired`] before acquiring again.
    pub fn acquire(&self) -> Result<Option<AcquiredImage>> {
        // SAFETY: the semaphore is unsignalled: the previous frame's submission waited on it,
        // and that submission's fence was waited for before this call.
        let result =
            unsafe { self.loader.acquire_next_image(self.raw, u64::MAX, self.acquired.raw, vk::Fence::null()) };
        match result {
            // A suboptimal image is still presentable; `present` reports it.
            Ok((index, _suboptimal)) => Ok(Some(AcquiredImage {
                index,
                image: self.images[index as usize],
                acquired: self.acquired.raw,
                rendered: self.rendered[index as usize].raw,
            })),
            Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => Ok(None),
            Err(e) => Err(e).context("vkAcquireNextImageKHR"),
        }
    }

    /// Presents `image` once its frame's submission has signalled [`AcquiredImage::rendered`].
    /// Returns false when the swapchain should be recreated (out of date or suboptimal).
    pub fn present(&self, image: &AcquiredImage) -> Result<bool> {
        let waits = [image.rendered];
        let swapchains = [self.raw];
        let indices = [image.index];
        let info =
            vk::PresentInfoKHR::default().wait_semaphores(&waits).swapchains(&swapchains).image_indices(&indices);
        // SAFETY: the image was acquired from this swapchain and a submission that signals
        // `rendered` (and leaves the image in PRESENT_SRC_KHR) was queued before this call.
        match unsafe { self.loader.queue_present(self.device.queue, &info) } {
            Ok(suboptimal) => Ok(!suboptimal),
            Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => Ok(false),
            Err(e) => Err(e).context("vkQueuePresentKHR"),
        }
    }
}
