//! The benchmark's alternatives on the GPU: a discrete LOD chain (or the full-resolution mesh)
//! drawn as ordinary instanced indexed meshes. A compute pass culls instances against the
//! frustum and appends each to the list of the level it picks; one indirect indexed draw per
//! level then draws the listed instances.

use std::sync::Arc;

use anyhow::{Context as _, Result};
use ash::vk;
use bytemuck::{bytes_of, cast_slice};

use super::context::Device;
use super::pipelines::{compute_pipeline, draw_pipeline, Commands, Descriptors};
use super::renderer::{barrier, gpu_buffer, COLOR_FORMAT, DEPTH_FORMAT};
use super::resources::{subresource_range, Buffer, Image, Location, Pipeline};
use crate::gpu_types::GpuView;
use crate::lod_chain::LodChain;

const CHAIN_CULL_SPV: &[u8] = include_bytes!("../../shaders/chain_cull.comp.spv");
const CHAIN_VERT_SPV: &[u8] = include_bytes!("../../shaders/chain.vert.spv");
const DRAW_FRAG_SPV: &[u8] = include_bytes!("../../shaders/draw.frag.spv");

/// One frame of the alternative: what was drawn and the GPU time of each pass.
#[derive(Clone, Debug)]
pub struct ChainFrame {
    /// Instances drawn per level.
    pub instances_per_level: Vec<u32>,
    /// Triangles drawn.
    pub triangles: u64,
    /// GPU ms of the culling pass and of the raster pass (None without timestamps).
    pub times: Option<(f64, f64)>,
}

/// Buffers and pipelines of the alternative.
pub struct ChainRenderer {
    device: Arc<Device>,
    levels: Vec<(u32, u32)>,
    instance_count: u32,
    _buffers: Vec<Buffer>,
    view: Buffer,
    draws: Buffer,
    draws_readback: Buffer,
    indices: vk::Buffer,
    target: Option<(Image, Image)>,
    descriptors: Descriptors,
    cull: Pipeline,
    draw: Pipeline,
    commands: Commands,
}

impl Drop for ChainRenderer {
    fn drop(&mut self) {
        // SAFETY: waiting idle on a live device before the owners are dropped.
        unsafe {
            let _ = self.device.raw.device_wait_idle();
        }
    }
}

impl ChainRenderer {
    /// Uploads `chain` and the instance translations.
    pub fn new(device: &Arc<Device>, chain: &LodChain, instances: &[[f32; 3]]) -> Result<ChainRenderer> {
        use vk::BufferUsageFlags as U;
        let instance_count = instances.len().max(1) as u32;
        // The shared instance layout; the chain's shaders read the translation only.
        let inst: Vec<crate::gpu_types::GpuInstance> = instances
            .iter()
            .map(|t| {
                let mut i = crate::gpu_types::GpuInstance::default();
                i.model[3] = [t[0], t[1], t[2], 1.0];
                i
            })
            .collect();
        let levels: Vec<[f32; 4]> = chain.levels.iter().map(|l| [l.error, 0.0, 0.0, 0.0]).collect();
        let mut uploads = Vec::new();
        let positions = gpu_buffer(device, cast_slice(&chain.positions), U::STORAGE_BUFFER, &mut uploads)?;
        let indices = gpu_buffer(device, cast_slice(&chain.indices), U::INDEX_BUFFER, &mut uploads)?;
        let instance_buffer = gpu_buffer(device, cast_slice(&inst), U::STORAGE_BUFFER, &mut uploads)?;
        let level_buffer = gpu_buffer(device, cast_slice(&levels), U::STORAGE_BUFFER, &mut uploads)?;
        let list = Buffer::new(
            device,
            chain.levels.len() as u64 * instance_count as u64 * 4,
            U::STORAGE_BUFFER,
            Location::Gpu,
        )?;
        let dummy = Buffer::new(device, 64, U::STORAGE_BUFFER, Location::Gpu)?;
        let view = Buffer::new(device, std::mem::size_of::<GpuView>() as u64, U::UNIFORM_BUFFER, Location::Upload)?;
        let draws = Buffer::new(
            device,
            chain.levels.len() as u64 * 20,
            U::STORAGE_BUFFER | U::INDIRECT_BUFFER | U::TRANSFER_DST | U::TRANSFER_SRC,
            Location::Gpu,
        )?;
        let draws_readback = Buffer::new(device, chain.levels.len() as u64 * 20, U::TRANSFER_DST, Location::Readback)?;
        // Bindings: the fragment shader's (0 view, 1 clusters, 5 visible, 8 instances; 1 and 5
        // unused in shaded mode), then 12 positions, 13 instance lists, 14 levels, 15 draws.
        let bound: [(u32, &Buffer); 8] = [
            (0, &view),
            (1, &dummy),
            (5, &dummy),
            (8, &instance_buffer),
            (12, &positions),
            (13, &list),
            (14, &level_buffer),
            (15, &draws),
        ];
        let descriptors = Descriptors::new(device, &bound)?;
        let commands = Commands::new(device, 3)?;
        let cull = compute_pipeline(device, &descriptors.layout, CHAIN_CULL_SPV)?;
        let draw = draw_pipeline(
            device,
            &descriptors.layout,
            &[(vk::ShaderStageFlags::VERTEX, CHAIN_VERT_SPV), (vk::ShaderStageFlags::FRAGMENT, DRAW_FRAG_SPV)],
            false,
        )?;
        let index_handle = indices.raw;
        let renderer = ChainRenderer {
            device: device.clone(),
            levels: chain.levels.iter().map(|l| (l.first_index, l.index_count)).collect(),
            instance_count,
            _buffers: vec![positions, indices, instance_buffer, level_buffer, list, dummy],
            view,
            draws,
            draws_readback,
            indices: index_handle,
            target: None,
            descriptors,
            cull,
            draw,
            commands,
        };
        renderer.commands.upload(&uploads)?;
        Ok(renderer)
    }

    /// Culls, picks levels and draws one frame of `view` (flags: `FLAG_FRUSTUM_CULL`, and
    /// `FLAG_FULL_DETAIL` for the full-resolution alternative) into a `width` × `height` target.
    pub fn render(&mut self, view: &GpuView, width: u32, height: u32) -> Result<ChainFrame> {
        let mut v = *view;
        v.instance_count = self.instance_count;
        v.bin_count = self.levels.len() as u32;
        v.mode = crate::gpu_types::MODE_SHADED;
        self.view.write(bytes_of(&v))?;
        let extent = vk::Extent2D { width, height };
        if self.target.as_ref().is_none_or(|t| t.0.extent != extent) {
            self.target = None;
            let color = Image::new(
                &self.device,
                extent,
                COLOR_FORMAT,
                vk::ImageUsageFlags::COLOR_ATTACHMENT,
                vk::ImageAspectFlags::COLOR,
            )?;
            let depth = Image::new(
                &self.device,
                extent,
                DEPTH_FORMAT,
                vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT,
                vk::ImageAspectFlags::DEPTH,
            )?;
            self.target = Some((color, depth));
        }
        let (color, depth) = self.target.as_ref().context("target")?;
        let reset: Vec<u32> = self.levels.iter().flat_map(|&(first, count)| [count, 0, first, 0, 0]).collect();
        let reset: Vec<u32> =
            reset.chunks(5).enumerate().flat_map(|(l, c)| [c[0], 0, c[2], 0, l as u32 * self.instance_count]).collect();
        let groups = self.instance_count.div_ceil(64);
        self.commands.submit(|dev, cmd| {
            // SAFETY: recording into `cmd` with resources owned by `self`.
            unsafe {
                self.commands.start_timestamps(dev, cmd);
                dev.cmd_update_buffer(cmd, self.draws.raw, 0, cast_slice(&reset));
                barrier(
                    dev,
                    cmd,
                    vk::PipelineStageFlags2::COPY,
                    vk::AccessFlags2::TRANSFER_WRITE,
                    vk::PipelineStageFlags2::COMPUTE_SHADER,
                    vk::AccessFlags2::SHADER_READ | vk::AccessFlags2::SHADER_WRITE,
                );
                dev.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, self.cull.raw);
                dev.cmd_bind_descriptor_sets(
                    cmd,
                    vk::PipelineBindPoint::COMPUTE,
                    self.descriptors.layout.raw,
                    0,
                    &[self.descriptors.set],
                    &[],
                );
                dev.cmd_dispatch(cmd, groups.min(65535), groups.div_ceil(65535), 1);
                barrier(
                    dev,
                    cmd,
                    vk::PipelineStageFlags2::COMPUTE_SHADER,
                    vk::AccessFlags2::SHADER_WRITE,
                    vk::PipelineStageFlags2::DRAW_INDIRECT | vk::PipelineStageFlags2::VERTEX_SHADER,
                    vk::AccessFlags2::INDIRECT_COMMAND_READ | vk::AccessFlags2::SHADER_READ,
                );
                self.commands.timestamp(dev, cmd, 1);
                let barriers = [
                    vk::ImageMemoryBarrier2::default()
                        .src_stage_mask(vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT)
                        .dst_stage_mask(vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT)
                        .dst_access_mask(vk::AccessFlags2::COLOR_ATTACHMENT_WRITE)
                        .old_layout(vk::ImageLayout::UNDEFINED)
                        .new_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                        .image(color.raw)
                        .subresource_range(subresource_range(vk::ImageAspectFlags::COLOR)),
                    vk::ImageMemoryBarrier2::default()
                        .src_stage_mask(
                            vk::PipelineStageFlags2::EARLY_FRAGMENT_TESTS
                                | vk::PipelineStageFlags2::LATE_FRAGMENT_TESTS,
                        )
                        .dst_stage_mask(
                            vk::PipelineStageFlags2::EARLY_FRAGMENT_TESTS
                                | vk::PipelineStageFlags2::LATE_FRAGMENT_TESTS,
                        )
                        .dst_access_mask(
                            vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_READ
                                | vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_WRITE,
                        )
                        .old_layout(vk::ImageLayout::UNDEFINED)
                        .new_layout(vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL)
                        .image(depth.raw)
                        .subresource_range(subresource_range(vk::ImageAspectFlags::DEPTH)),
                ];
                dev.cmd_pipeline_barrier2(cmd, &vk::DependencyInfo::default().image_memory_barriers(&barriers));
                let color_att = [vk::RenderingAttachmentInfo::default()
                    .image_view(color.view)
                    .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                    .load_op(vk::AttachmentLoadOp::CLEAR)
                    .store_op(vk::AttachmentStoreOp::STORE)
                    .clear_value(vk::ClearValue { color: vk::ClearColorValue { float32: super::CLEAR_RGBA } })];
                let depth_att = vk::RenderingAttachmentInfo::default()
                    .image_view(depth.view)
                    .image_layout(vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL)
                    .load_op(vk::AttachmentLoadOp::CLEAR)
                    .store_op(vk::AttachmentStoreOp::DONT_CARE)
                    .clear_value(vk::ClearValue {
                        depth_stencil: vk::ClearDepthStencilValue { depth: 0.0, stencil: 0 },
                    });
                let area = vk::Rect2D { offset: vk::Offset2D { x: 0, y: 0 }, extent };
                dev.cmd_begin_rendering(
                    cmd,
                    &vk::RenderingInfo::default()
                        .render_area(area)
                        .layer_count(1)
                        .color_attachments(&color_att)
                        .depth_attachment(&depth_att),
                );
                dev.cmd_set_viewport(
                    cmd,
                    0,
                    &[vk::Viewport {
                        x: 0.0,
                        y: height as f32,
                        width: width as f32,
                        height: -(height as f32),
                        min_depth: 0.0,
                        max_depth: 1.0,
                    }],
                );
                dev.cmd_set_scissor(cmd, 0, &[area]);
                dev.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::GRAPHICS, self.draw.raw);
                dev.cmd_bind_descriptor_sets(
                    cmd,
                    vk::PipelineBindPoint::GRAPHICS,
                    self.descriptors.layout.raw,
                    0,
                    &[self.descriptors.set],
                    &[],
                );
                dev.cmd_bind_index_buffer(cmd, self.indices, 0, vk::IndexType::UINT32);
                for l in 0..self.levels.len() as u64 {
                    dev.cmd_draw_indexed_indirect(cmd, self.draws.raw, l * 20, 1, 20);
                }
                dev.cmd_end_rendering(cmd);
                self.commands.timestamp(dev, cmd, 2);
                barrier(
                    dev,
                    cmd,
                    vk::PipelineStageFlags2::DRAW_INDIRECT,
                    vk::AccessFlags2::INDIRECT_COMMAND_READ,
                    vk::PipelineStageFlags2::COPY,
                    vk::AccessFlags2::TRANSFER_READ,
                );
                dev.cmd_copy_buffer(
                    cmd,
                    self.draws.raw,
                    self.draws_readback.raw,
                    &[vk::BufferCopy { src_offset: 0, dst_offset: 0, size: self.draws.size }],
                );
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
        let draws: Vec<u32> = cast_slice::<u8, u32>(&self.draws_readback.read(self.levels.len() * 20)?).to_vec();
        let instances_per_level: Vec<u32> = draws.chunks(5).map(|c| c[1]).collect();
        let triangles =
            instances_per_level.iter().zip(&self.levels).map(|(&n, &(_, count))| n as u64 * count as u64 / 3).sum();
        let times = self.commands.read_intervals_ms()?.map(|ms| (ms[0], ms[1]));
        Ok(ChainFrame { instances_per_level, triangles, times })
    }
}
