//! `mres-preview`: renders `.mres` files through the GPU selection path an engine would use
//! (docs/ARCHITECTURE.md, "preview").
//!
//! - [`scene`] flattens a file into GPU inputs: one [`gpu_types::GpuCluster`] per cluster and
//!   the decompressed pages as is, with a page base table; several files merge into one.
//! - [`instances`] places meshes by transforms ([`gpu_types::GpuInstance`]), with the CPU twin
//!   of the selection under a transform, and loads scene files.
//! - [`vk`] holds every `unsafe` Vulkan call: the context, the owners of each object, and the
//!   [`vk::Renderer`] that runs the selection compute pass and the fallback draw
//!   (compute-expanded index buffer + indirect indexed draw).
//! - [`viewer`] is the windowed viewer (winit): a [`fly`] camera, keys for τ and the modes,
//!   frames drawn by the same renderer and blitted into a swapchain.
//! - [`coverage`] counts the pixels coarse cuts cover against full detail.
//! - [`verify`] proves a file: GPU selection equals the CPU reference for many cameras, and the
//!   drawn cut of a closed mesh shows no back face from outside.
#![deny(missing_docs)]

pub mod bench;
pub mod camera;
pub mod coverage;
pub mod exposed;
pub mod fly;
pub mod gpu_types;
pub mod image;
pub mod instances;
pub use mres_check::lod_chain;
pub mod scene;
pub mod verify;
pub mod viewer;
pub mod vk;
