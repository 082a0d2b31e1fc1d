//! The GPU side of the preview: buffers of one file, the pipelines, and the two passes
//! (selection; selection + expansion + draw), recorded by [`record`]. Public methods are safe:
//! each records one command buffer, submits it and waits for its fence before returning.

mod record;

use std::sync::Arc;

use anyhow::{bail, Context as _, Result};
use ash::vk;
use bytemuck::{bytes_of, cast_slice};

use super::context::Device;
pub use super::pipelines::COLOR_FORMAT;
pub(crate) use super::pipelines::DEPTH_FORMAT;
use super::pipelines::{compute_pipeline, draw_pipeline, Commands, Descriptors};
use super::resources::{Buffer, Image, Location, Pipeline};
use super::swapchain::{AcquiredImage, Swapchain};
use crate::gpu_types::{GpuCounters, GpuInstance, GpuView};
use crate::scene::SceneData;

const CULL_SPV: &[u8] = include_bytes!("../../shaders/cull.comp.spv");
const SELECT_SPV: &[u8] = include_bytes!("../../shaders/select.comp.spv");
const SELECT_NAIVE_SPV: &[u8] = include_bytes!("../../shaders/select_naive.comp.spv");
const EXPAND_SPV: &[u8] = include_bytes!("../../shaders/expand.comp.spv");
const DRAW_VERT_SPV: &[u8] = include_bytes!("../../shaders/draw.vert.spv");
const DRAW_FRAG_SPV: &[u8] = include_bytes!("../../shaders/draw.frag.spv");
const DRAW_TASK_SPV: &[u8] = include_bytes!("../../shaders/draw.task.spv");
const DRAW_MESH_SPV: &[u8] = include_bytes!("../../shaders/draw.mesh.spv");

/// Background colour (never pure red).
pub const CLEAR_RGBA: [f32; 4] = [0.16, 0.18, 0.22, 1.0];
const CULL_GROUP_SIZE: u32 = 64;
/// Largest visible list: a fallback index carries the visible slot in its upper 24 bits.
pub const MAX_VISIBLE: u32 = 1 << 24;
/// Default cap of the fallback index buffer (entries; 4 bytes each).
const DEFAULT_INDEX_CAP: u64 = 1 << 26;
const TIMESTAMPS: u32 = 4;

/// The result of a selection pass.
#[derive(Clone, Debug, Default)]
pub struct Selection {
    /// Visible clusters, in the order the GPU appended them.
    pub visible: Vec<u32>,
    /// The instance of each visible cluster.
    pub instances: Vec<u32>,
    /// (own, parent) projected errors of every cluster, when asked for.
    pub projected: Vec<[f32; 2]>,
}

/// GPU time of each pass of one frame, in milliseconds (absent without timestamp support).
#[derive(Clone, Copy, Debug, Default)]
pub struct PassTimes {
    /// Cluster selection.
    pub select_ms: f64,
    /// Index expansion (0 on the mesh-shader path).
    pub expand_ms: f64,
    /// Rasterization (both draws; on the mesh path this includes the task and mesh shaders).
    pub draw_ms: f64,
}

/// One rendered frame, read back.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// RGBA8 pixels, row by row from the top.
    pub rgba: Vec<u8>,
    /// Clusters drawn.
    pub clusters: u32,
    /// Triangles drawn.
    pub triangles: u64,
    /// Clusters selected but not drawn because the visible list or index buffer was full.
    pub dropped: u32,
    /// Reverse-Z depth (`z_near / view depth`, 0 = background), row by row from the top, when asked for.
    pub depth: Option<Vec<f32>>,
    /// GPU pass times, where the queue has timestamps.
    pub times: Option<PassTimes>,
}

/// Where a frame for the window goes (see [`Renderer::render_to_swapchain`]).
struct PresentTarget {
    image: AcquiredImage,
    extent: vk::Extent2D,
    format: vk::Format,
    screenshot: bool,
}

struct RenderTarget {
    color: Image,
    depth: Image,
    readback: Buffer,
    depth_readback: Buffer,
}

/// How the selected clusters are drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DrawPath {
    /// Mesh shaders where the device was created with them, else the fallback.
    #[default]
    Auto,
    /// `VK_EXT_mesh_shader`: a task workgroup per 32 visible clusters, a mesh workgroup per cluster.
    Mesh,
    /// Compute-expanded index buffer + indirect indexed draw (any Vulkan 1.3 device).
    Fallback,
}

/// Choices made when a [`Renderer`] is built.
#[derive(Clone, Debug, Default)]
pub struct RendererOptions {
    /// Diagnostic: select with the driver's own f32 division and sqrt instead of the exact
    /// (f64-corrected) ones, to measure how far a device is from FORMAT.md §6.
    pub naive_arithmetic: bool,
    /// Draw path; `Mesh` fails where the device was created without mesh shaders.
    pub path: DrawPath,
    /// The instances (`crate::instances`); empty means one identity instance of the scene's
    /// first mesh.
    pub instances: Vec<GpuInstance>,
    /// Visible-list entries (default: every cluster of every instance, at most [`MAX_VISIBLE`]).
    pub visible_capacity: Option<u32>,
    /// Fallback index-buffer entries (default: every cluster's indices, at most 2^26 with
    /// several instances).
    pub index_capacity: Option<u64>,
}

/// A file's GPU buffers plus the pipelines that select and draw it.
pub struct Renderer {
    device: Arc<Device>,
    cluster_count: u32,
    instance_count: u32,
    bin_count: u32,
    model: ([f32; 3], f32, f32),
    visible_capacity: u32,
    index_capacity: u32,
    mesh_path: bool,
    max_groups: u32,
    no_readback: bool,
    _clusters: Buffer,
    _page_bases: Buffer,
    _pages: Buffer,
    _instances: Buffer,
    _bins: Buffer,
    _work: Buffer,
    _level_order: Buffer,
    view: Buffer,
    counters: Buffer,
    visible: Buffer,
    indices: Buffer,
    projected: Buffer,
    readback_counters: Buffer,
    readback_visible: Buffer,
    readback_projected: Buffer,
    target: Option<RenderTarget>,
    /// Host copy of a presented swapchain image (screenshots from the window).
    present_readback: Option<Buffer>,
    descriptors: Descriptors,
    cull: Pipeline,
    select: Pipeline,
    expand: Pipeline,
    draw_front: Pipeline,
    draw_back: Pipeline,
    mesh_front: Option<Pipeline>,
    mesh_back: Option<Pipeline>,
    commands: Commands,
}

impl Drop for Renderer {
    fn drop(&mut self) {
        // SAFETY: waiting idle on a live device; afterwards no GPU work uses the owners, which
        // then drop (in field order) before the last Arc of the device can.
        unsafe {
            let _ = self.device.raw.device_wait_idle();
        }
    }
}

impl Renderer {
    /// Uploads `scene` and builds the pipelines.
    pub fn new(device: &Arc<Device>, scene: &SceneData, options: RendererOptions) -> Result<Renderer> {
        use vk::BufferUsageFlags as U;
        let limit = device.info.max_storage_buffer_range as u64;
        let too_big = |what: &str, bytes: u64| -> Result<()> {
            if bytes > limit {
                bail!("{what}: {bytes} bytes exceed this device's maxStorageBufferRange ({limit})");
            }
            Ok(())
        };
        let mesh_path = match options.path {
            DrawPath::Auto => device.mesh.is_some(),
            DrawPath::Mesh if device.mesh.is_none() => {
                bail!(
                    "the mesh-shader path needs VK_EXT_mesh_shader with task and mesh shaders, which {} lacks",
                    device.info.name
                )
            }
            DrawPath::Mesh => true,
            DrawPath::Fallback => false,
        };
        let instances: Vec<GpuInstance> = if options.instances.is_empty() {
            vec![crate::instances::translated(scene, 0, [0.0; 3])]
        } else {
            options.instances.clone()
        };
        if let Some(bad) = instances.iter().find(|i| i.mesh as usize >= scene.parts.len()) {
            bail!("an instance places mesh {}, the scene has {}", bad.mesh, scene.parts.len());
        }
        let instance_count = u32::try_from(instances.len()).context("too many instances")?;
        let cluster_count = scene.clusters.len() as u32;
        let n = cluster_count.max(1) as u64;
        let visible_capacity = options
            .visible_capacity
            .unwrap_or_else(|| (n * instance_count as u64).min(MAX_VISIBLE as u64) as u32)
            .clamp(1, MAX_VISIBLE)
            .min((limit / 8) as u32);
        let index_capacity = options
            .index_capacity
            .unwrap_or(if instance_count == 1 {
                scene.index_capacity
            } else {
                (scene.index_capacity * instance_count as u64).min(DEFAULT_INDEX_CAP)
            })
            .clamp(3, u32::MAX as u64 / 4)
            .min(limit / 4) as u32;
        too_big("decompressed pages", scene.pages.len() as u64)?;
        too_big("index buffer", index_capacity as u64 * 4)?;
        too_big("cluster records", scene.clusters.len() as u64 * 64)?;
        too_big("visible list", visible_capacity as u64 * 8)?;
        let mut max_groups = device.info.max_compute_groups_x.min(65535);
        if mesh_path {
            max_groups = max_groups.min(device.info.max_task_groups_x);
            let tasks = (visible_capacity as u64).div_ceil(32);
            if tasks > device.info.max_task_groups_total as u64 {
                bail!("{tasks} task workgroups exceed this device's maxTaskWorkGroupTotalCount");
            }
        }

        let mut uploads = Vec::new();
        let clusters = gpu_buffer(device, cast_slice(&scene.clusters), U::STORAGE_BUFFER, &mut uploads)?;
        let page_bases = gpu_buffer(device, cast_slice(&scene.page_bases), U::STORAGE_BUFFER, &mut uploads)?;
        let pages = gpu_buffer(device, &scene.pages, U::STORAGE_BUFFER, &mut uploads)?;
        let instance_buffer = gpu_buffer(device, cast_slice(&instances), U::STORAGE_BUFFER, &mut uploads)?;
        let bins = gpu_buffer(device, cast_slice(&scene.bins), U::STORAGE_BUFFER, &mut uploads)?;
        let level_order = gpu_buffer(device, cast_slice(&scene.level_order), U::STORAGE_BUFFER, &mut uploads)?;
        let work = Buffer::new(device, instance_count as u64 * 16, U::STORAGE_BUFFER, Location::Gpu)?;
        let view = Buffer::new(device, std::mem::size_of::<GpuView>() as u64, U::UNIFORM_BUFFER, Location::Upload)?;
        let counters = Buffer::new(
            device,
            std::mem::size_of::<GpuCounters>() as u64,
            U::STORAGE_BUFFER | U::INDIRECT_BUFFER | U::TRANSFER_DST | U::TRANSFER_SRC,
            Location::Gpu,
        )?;
        let visible =
            Buffer::new(device, visible_capacity as u64 * 8, U::STORAGE_BUFFER | U::TRANSFER_SRC, Location::Gpu)?;
        // The mesh path draws from the visible list alone.
        let index_entries = if mesh_path { 1 } else { index_capacity as u64 };
        let indices = Buffer::new(device, index_entries * 4, U::STORAGE_BUFFER | U::INDEX_BUFFER, Location::Gpu)?;
        let projected = Buffer::new(device, n * 8, U::STORAGE_BUFFER | U::TRANSFER_SRC, Location::Gpu)?;
        let readback_counters =
            Buffer::new(device, std::mem::size_of::<GpuCounters>() as u64, U::TRANSFER_DST, Location::Readback)?;
        let readback_visible = Buffer::new(device, visible_capacity as u64 * 8, U::TRANSFER_DST, Location::Readback)?;
        let readback_projected = Buffer::new(device, n * 8, U::TRANSFER_DST, Location::Readback)?;

        // Descriptor set: 0 view (uniform), 1 clusters, 2 page bases, 3 pages, 4 counters,
        // 5 visible, 6 indices, 7 projected, 8 instances, 9 level bins, 10 work items, 11 level
        // order (storage); the same for every pipeline (shaders/common.glsl and each stage).
        let storage = [
            &clusters,
            &page_bases,
            &pages,
            &counters,
            &visible,
            &indices,
            &projected,
            &instance_buffer,
            &bins,
            &work,
            &level_order,
        ];
        let bound: Vec<(u32, &Buffer)> =
            std::iter::once(&view).chain(storage).enumerate().map(|(i, b)| (i as u32, b)).collect();
        let descriptors = Descriptors::new(device, &bound)?;
        let commands = Commands::new(device, TIMESTAMPS)?;

        let pipeline_layout = &descriptors.layout;
        let cull = compute_pipeline(device, pipeline_layout, CULL_SPV)?;
        let select = compute_pipeline(
            device,
            pipeline_layout,
            if options.naive_arithmetic { SELECT_NAIVE_SPV } else { SELECT_SPV },
        )?;
        let expand = compute_pipeline(device, pipeline_layout, EXPAND_SPV)?;
        // The fallback: no vertex input, the vertex shader decodes positions from the pages.
        let vertex_stages =
            [(vk::ShaderStageFlags::VERTEX, DRAW_VERT_SPV), (vk::ShaderStageFlags::FRAGMENT, DRAW_FRAG_SPV)];
        let draw_front = draw_pipeline(device, pipeline_layout, &vertex_stages, false)?;
        let draw_back = draw_pipeline(device, pipeline_layout, &vertex_stages, true)?;
        let mesh_stages = [
            (vk::ShaderStageFlags::TASK_EXT, DRAW_TASK_SPV),
            (vk::ShaderStageFlags::MESH_EXT, DRAW_MESH_SPV),
            (vk::ShaderStageFlags::FRAGMENT, DRAW_FRAG_SPV),
        ];
        let (mesh_front, mesh_back) = if mesh_path {
            (
                Some(draw_pipeline(device, pipeline_layout, &mesh_stages, false)?),
                Some(draw_pipeline(device, pipeline_layout, &mesh_stages, true)?),
            )
        } else {
            (None, None)
        };

        let renderer = Renderer {
            device: device.clone(),
            cluster_count,
            instance_count,
            bin_count: scene.bins.len() as u32,
            model: (scene.bounds.center, scene.model_far, scene.model_near),
            visible_capacity,
            index_capacity,
            mesh_path,
            max_groups,
            no_readback: false,
            _clusters: clusters,
            _page_bases: page_bases,
            _pages: pages,
            _instances: instance_buffer,
            _bins: bins,
            _work: work,
            _level_order: level_order,
            view,
            counters,
            visible,
            indices,
            projected,
            readback_counters,
            readback_visible,
            readback_projected,
            target: None,
            present_readback: None,
            descriptors,
            cull,
            select,
            expand,
            draw_front,
            draw_back,
            mesh_front,
            mesh_back,
            commands,
        };
        // Copy the staged data into the device-local buffers.
        renderer.commands.upload(&uploads)?;
        drop(uploads);
        Ok(renderer)
    }

    /// The device this renderer runs on.
    pub fn device(&self) -> &Arc<Device> {
        &self.device
    }

    /// Whether draws use the mesh-shader path.
    pub fn mesh_path(&self) -> bool {
        self.mesh_path
    }

    /// A one-line description of the draw path.
    pub fn path_name(&self) -> &'static str {
        if self.mesh_path {
            "mesh shaders (task workgroup per 32 visible clusters, mesh workgroup per cluster)"
        } else {
            "fallback (compute-expanded index buffer + indirect indexed draw)"
        }
    }

    /// Runs the selection pass for `view` and reads back the visible list (and, with
    /// `FLAG_WRITE_PROJECTED` in `view.flags`, every cluster's projected errors).
    pub fn select(&mut self, view: &GpuView) -> Result<Selection> {
        let view = self.prepare_view(view)?;
        let want_projected = view.flags & crate::gpu_types::FLAG_WRITE_PROJECTED != 0;
        let n = self.cluster_count.max(1) as u64;
        self.commands.submit(|dev, cmd| {
            // SAFETY: recording into `cmd` with buffers owned by `self`.
            unsafe {
                self.record_select(dev, cmd);
                barrier(
                    dev,
                    cmd,
                    vk::PipelineStageFlags2::COMPUTE_SHADER,
                    vk::AccessFlags2::SHADER_WRITE,
                    vk::PipelineStageFlags2::COPY,
                    vk::AccessFlags2::TRANSFER_READ,
                );
                self.copy_counters(dev, cmd);
                dev.cmd_copy_buffer(
                    cmd,
                    self.visible.raw,
                    self.readback_visible.raw,
                    &[vk::BufferCopy { src_offset: 0, dst_offset: 0, size: self.visible_capacity as u64 * 8 }],
                );
                if want_projected {
                    dev.cmd_copy_buffer(
                        cmd,
                        self.projected.raw,
                        self.readback_projected.raw,
                        &[vk::BufferCopy { src_offset: 0, dst_offset: 0, size: n * 8 }],
                    );
                }
                barrier(
                    dev,
                    cmd,
                    vk::PipelineStageFlags2::COPY,
                    vk::AccessFlags2::TRANSFER_WRITE,
                    vk::PipelineStageFlags2::HOST,
                    vk::AccessFlags2::HOST_READ,
                );
            }
        })?;
        let counters = self.read_counters()?;
        if counters.dropped > 0 || counters.visible_count > self.visible_capacity {
            bail!(
                "the visible list ({} entries) overflowed: {} clusters selected",
                self.visible_capacity,
                counters.visible_count
            );
        }
        let entries = self.readback_visible.read(counters.visible_count as usize * 8)?;
        let entries = cast_slice::<u8, [u32; 2]>(&entries);
        let visible: Vec<u32> = entries.iter().map(|e| e[0]).collect();
        let instances: Vec<u32> = entries.iter().map(|e| e[1]).collect();
        let projected = if want_projected {
            cast_slice::<u8, [f32; 2]>(&self.readback_projected.read(self.cluster_count as usize * 8)?).to_vec()
        } else {
            Vec::new()
        };
        Ok(Selection { visible, instances, projected })
    }

    /// Selects, expands and draws the clusters for `view` into a `width` × `height` image and
    /// reads it back. Front faces are shaded, back faces pure red (the crack test's flag).
    pub fn render(&mut self, view: &GpuView, width: u32, height: u32) -> Result<Frame> {
        self.render_frame(view, width, height, false, None)
    }

    /// Renders `view` exactly as [`Renderer::render_without_readback`] does, at the swapchain's
    /// size, then blits the image into `image` (acquired from `swapchain`) and leaves it ready
    /// to present: the submission waits on [`AcquiredImage::acquired`] and signals
    /// [`AcquiredImage::rendered`]. With `screenshot`, [`Frame::rgba`] holds the swapchain
    /// image as presented (converted to RGBA), which needs [`Swapchain::readable`].
    pub fn render_to_swapchain(
        &mut self,
        view: &GpuView,
        swapchain: &Swapchain,
        image: &AcquiredImage,
        screenshot: bool,
    ) -> Result<Frame> {
        if screenshot && !swapchain.readable {
            bail!("this surface's images cannot be read back (no TRANSFER_SRC usage)");
        }
        if screenshot && !matches!(swapchain.format, vk::Format::B8G8R8A8_UNORM | vk::Format::R8G8B8A8_UNORM) {
            bail!("screenshots need an 8-bit UNORM swapchain, not {:?}", swapchain.format);
        }
        let present = PresentTarget { image: *image, extent: swapchain.extent, format: swapchain.format, screenshot };
        self.no_readback = true;
        let frame = self.render_frame(view, swapchain.extent.width, swapchain.extent.height, false, Some(&present));
        self.no_readback = false;
        frame
    }

    /// [`Renderer::render`] without reading the image back (counts and times only).
    pub fn render_without_readback(&mut self, view: &GpuView, width: u32, height: u32) -> Result<Frame> {
        self.no_readback = true;
        let frame = self.render_frame(view, width, height, false, None);
        self.no_readback = false;
        frame
    }

    /// [`Renderer::render`], also reading back the depth buffer.
    pub fn render_with_depth(&mut self, view: &GpuView, width: u32, height: u32) -> Result<Frame> {
        self.render_frame(view, width, height, true, None)
    }

    fn render_frame(
        &mut self,
        view: &GpuView,
        width: u32,
        height: u32,
        want_depth: bool,
        present: Option<&PresentTarget>,
    ) -> Result<Frame> {
        self.prepare_view(view)?;
        self.ensure_target(width, height)?;
        if let Some(p) = present {
            self.ensure_present_readback(p)?;
        }
        let target = self.target.as_ref().context("render target")?;
        // Presentation: wait for the image to be acquired before the blit writes it (the
        // barrier in `record_present` chains to this stage), signal presentation when
        // everything is done.
        let waits: Vec<vk::SemaphoreSubmitInfo> = present
            .map(|p| {
                vk::SemaphoreSubmitInfo::default().semaphore(p.image.acquired).stage_mask(vk::PipelineStageFlags2::BLIT)
            })
            .into_iter()
            .collect();
        let signals: Vec<vk::SemaphoreSubmitInfo> = present
            .map(|p| {
                vk::SemaphoreSubmitInfo::default()
                    .semaphore(p.image.rendered)
                    .stage_mask(vk::PipelineStageFlags2::ALL_COMMANDS)
            })
            .into_iter()
            .collect();
        self.commands.submit_with(&waits, &signals, |dev, cmd| {
            // SAFETY: recording into `cmd` with resources owned by `self`; layouts are
            // transitioned from UNDEFINED each frame (contents are cleared anyway).
            unsafe {
                self.commands.start_timestamps(dev, cmd);
                self.record_select(dev, cmd);
                self.record_expand(dev, cmd);
                self.record_draw(dev, cmd, target, want_depth);
                self.record_readback(dev, cmd, (target, present), want_depth);
            }
        })?;
        self.read_frame(target, present, want_depth)
    }

    /// The frame just rendered into `target`: counters, pixels (the presented image's where a
    /// screenshot was asked for), depth if wanted, pass times.
    fn read_frame(&self, target: &RenderTarget, present: Option<&PresentTarget>, want_depth: bool) -> Result<Frame> {
        let extent = target.color.extent;
        let counters = self.read_counters()?;
        let pixels = extent.width as usize * extent.height as usize;
        let rgba = match (present, &self.present_readback) {
            (Some(p), Some(buffer)) if p.screenshot => {
                let mut bytes = buffer.read(pixels * 4)?;
                if p.format == vk::Format::B8G8R8A8_UNORM {
                    bytes.chunks_exact_mut(4).for_each(|px| px.swap(0, 2));
                }
                bytes
            }
            _ if self.no_readback => Vec::new(),
            _ => target.readback.read(pixels * 4)?,
        };
        let depth = if want_depth {
            Some(cast_slice::<u8, f32>(&target.depth_readback.read(pixels * 4)?).to_vec())
        } else {
            None
        };
        let times = self.read_times()?;
        let clusters = counters.visible_count.min(self.visible_capacity);
        Ok(Frame {
            width: extent.width,
            height: extent.height,
            rgba,
            clusters,
            triangles: if self.mesh_path { counters.triangles as u64 } else { counters.index_count as u64 / 3 },
            dropped: counters.dropped,
            depth,
            times,
        })
    }

    fn prepare_view(&self, view: &GpuView) -> Result<GpuView> {
        let mut view = *view;
        view.cluster_count = self.cluster_count;
        view.max_groups = self.max_groups;
        view.instance_count = self.instance_count;
        view.bin_count = self.bin_count;
        (view.model_center, view.model_far, view.model_near) = self.model;
        view.visible_capacity = self.visible_capacity;
        view.index_capacity = self.index_capacity;
        self.view.write(bytes_of(&view))?;
        Ok(view)
    }

    fn read_counters(&self) -> Result<GpuCounters> {
        let bytes = self.readback_counters.read(std::mem::size_of::<GpuCounters>())?;
        Ok(bytemuck::pod_read_unaligned(&bytes))
    }

    fn read_times(&self) -> Result<Option<PassTimes>> {
        Ok(self.commands.read_intervals_ms()?.map(|ms| PassTimes {
            select_ms: ms[0],
            expand_ms: ms[1],
            draw_ms: ms[2],
        }))
    }

    fn ensure_target(&mut self, width: u32, height: u32) -> Result<()> {
        let extent = vk::Extent2D { width, height };
        if self.target.as_ref().is_some_and(|t| t.color.extent == extent) {
            return Ok(());
        }
        if width == 0 || height == 0 || width > 16384 || height > 16384 {
            bail!("image size {width}x{height} out of range (1..=16384)");
        }
        self.target = None;
        let color = Image::new(
            &self.device,
            extent,
            COLOR_FORMAT,
            vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC,
            vk::ImageAspectFlags::COLOR,
        )?;
        let depth = Image::new(
            &self.device,
            extent,
            DEPTH_FORMAT,
            vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC,
            vk::ImageAspectFlags::DEPTH,
        )?;
        let readback = Buffer::new(
            &self.device,
            width as u64 * height as u64 * 4,
            vk::BufferUsageFlags::TRANSFER_DST,
            Location::Readback,
        )?;
        let depth_readback = Buffer::new(
            &self.device,
            width as u64 * height as u64 * 4,
            vk::BufferUsageFlags::TRANSFER_DST,
            Location::Readback,
        )?;
        self.target = Some(RenderTarget { color, depth, readback, depth_readback });
        Ok(())
    }

    fn ensure_present_readback(&mut self, present: &PresentTarget) -> Result<()> {
        let bytes = present.extent.width as u64 * present.extent.height as u64 * 4;
        if present.screenshot && self.present_readback.as_ref().is_none_or(|b| b.size < bytes) {
            self.present_readback = None;
            self.present_readback =
                Some(Buffer::new(&self.device, bytes, vk::BufferUsageFlags::TRANSFER_DST, Location::Readback)?);
        }
        Ok(())
    }
}

/// A global memory barrier.
///
/// # Safety
/// `cmd` must be recording, on `dev`.
pub(crate) unsafe fn barrier(
    dev: &ash::Device,
    cmd: vk::CommandBuffer,
    src_stage: vk::PipelineStageFlags2,
    src_access: vk::AccessFlags2,
    dst_stage: vk::PipelineStageFlags2,
    dst_access: vk::AccessFlags2,
) {
    let b = [vk::MemoryBarrier2::default()
        .src_stage_mask(src_stage)
        .src_access_mask(src_access)
        .dst_stage_mask(dst_stage)
        .dst_access_mask(dst_access)];
    // SAFETY: per this function's contract.
    unsafe { dev.cmd_pipeline_barrier2(cmd, &vk::DependencyInfo::default().memory_barriers(&b)) };
}

/// A device-local buffer holding `data`: written directly where device memory is mapped,
/// otherwise through a staging buffer pushed onto `uploads` (copied by the caller).
pub(crate) fn gpu_buffer(
    device: &Arc<Device>,
    data: &[u8],
    usage: vk::BufferUsageFlags,
    uploads: &mut Vec<(Buffer, vk::Buffer)>,
) -> Result<Buffer> {
    let buffer = Buffer::new(device, data.len() as u64, usage | vk::BufferUsageFlags::TRANSFER_DST, Location::Gpu)?;
    if buffer.is_mapped() {
        buffer.write(data)?;
    } else if !data.is_empty() {
        let staging = Buffer::new(device, data.len() as u64, vk::BufferUsageFlags::TRANSFER_SRC, Location::Upload)?;
        staging.write(data)?;
        uploads.push((staging, buffer.raw));
    }
    Ok(buffer)
}
