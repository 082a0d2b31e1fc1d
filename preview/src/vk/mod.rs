//! Every `unsafe` Vulkan call of the preview lives in this module tree. Each Vulkan object has
//! a small owner type whose `Drop` destroys only its own handle; owners hold an `Arc` of the
//! device (which holds the instance), and [`Device`]'s `Drop` waits idle before destroying it,
//! so handles always go before their parents.

mod chain;
mod context;
mod pipelines;
mod renderer;
mod resources;
mod swapchain;

pub use chain::{ChainFrame, ChainRenderer};
pub use context::{validation_available, ContextOptions, Device, DeviceInfo, MessageCounts};
pub use renderer::{DrawPath, Frame, PassTimes, Renderer, RendererOptions, Selection, CLEAR_RGBA, MAX_VISIBLE};
pub use swapchain::{AcquiredImage, Surface, Swapchain};
