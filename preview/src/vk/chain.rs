//! The benchmark's alternatives on the GPU: a discrete LOD chain (or the full-resolution mesh)
//! drawn as ordinary instanced indexed meshes. A compute pass culls instances against the
//! frustum and appends each to the list of the level it picks; one indirect indexed draw per
//! level then draws the listed instances.

use std::sync::Arc;

use anyhow::{Context as _, Result};
use ash::vk;
use bytemuck::{bytes_of, cast_slice};

use super::context::Device;
use super::renderer::{barrier, compute_pipeline, gpu_buffer, COLOR_FORMAT, DEPTH_FORMAT};
use super::resources::{
    subresource_range, Buffer, CommandPool, DescriptorPool, DescriptorSetLayout, Fence, Image, Location, Pipeline,
    PipelineLayout, QueryPool, ShaderModule,
};
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
    _set_layout: DescriptorSetLayout,
    layout: PipelineLayout,
    _pool: DescriptorPool,
    set: vk::DescriptorSet,
    cull: Pipeline,
    draw: Pipeline,
    _command_pool: CommandPool,
    cmd: vk::CommandBuffer,
    fence: Fence,
    queries: Option<QueryPool>,
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
        let inst: Vec<[f32; 4]> = instances.iter().map(|t| [t[0], t[1], t[2], 0.0]).collect();
        let levels: Vec<[f32; 4]> = chain.levels.iter().map(|l| [l.error, 0.0, 0.0, 0.0]).collect();
        let mut uploads = Vec::new();
        let positions = gpu_buffer(device, cast_slice(&chain.positions), U::STORAGE_BUFFER, &mut uploads)?;
        let indices = gpu_buffer(device, cast_slice(&chain.indices), U::INDEX_BUFFER, &mut uploads)?;
        let instance_buffer = gpu_buffer(device, cast_slice(&inst), U::STORAGE_BUFFER, &mut uploads)?;
        let level_buffer = gpu_buffer(device, cast_slice(&levels), U::STORAGE_BUFFER, &mut uploads)?;
        let list = Buffer::new(device, chain.levels.len() as u64 * instance_count as u64 * 4, U::STORAGE_BUFFER, Location::Gpu)?;
        let dummy = Buffer::new(device, 64, U::STORAGE_BUFFER, Location::Gpu)?;
        let view = Buffer::new(device, std::mem::size_of::<GpuView>() as u64, U::UNIFORM_BUFFER, Location::Upload)?;
        let draws = Buffer::new(device, chain.levels.len() as u64 * 20,
            U::STORAGE_BUFFER | U::INDIRECT_BUFFER | U::TRANSFER_DST | U::TRANSFER_SRC, Location::Gpu)?;
        let draws_readback = Buffer::new(device, chain.levels.len() as u64 * 20, U::TRANSFER_DST, Location::Readback)?;
        // Bindings: the fragment shader's (0 view, 1 clusters, 5 visible, 8 instances; 1 and 5
        // unused in shaded mode), then 12 positions, 13 instance lists, 14 levels, 15 draws.
        let bound: [(u32, &Buffer); 8] = [(0, &view), (1, &dummy), (5, &dummy), (8, &instance_buffer), (12, &positions),
            (13, &list), (14, &level_buffer), (15, &draws)];
        let bindings: Vec<vk::DescriptorSetLayoutBinding> = bound
            .iter()
            .map(|(b, _)| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(*b)
                    .descriptor_type(if *b == 0 { vk::DescriptorType::UNIFORM_BUFFER } else { vk::DescriptorType::STORAGE_BUFFER })
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::ALL)
            })
            .collect();
        // SAFETY: object creation from valid create infos; handles go straight into owners;
        // descriptor writes reference buffers owned by the returned value.
        let (set_layout, layout, pool, set, command_pool, cmd, fence, queries) = unsafe {
            let set_layout = DescriptorSetLayout::from_raw(device, device.raw.create_descriptor_set_layout(
                &vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings), None)?);
            let layouts = [set_layout.raw];
            let layout = PipelineLayout::from_raw(device, device.raw.create_pipeline_layout(
                &vk::PipelineLayoutCreateInfo::default().set_layouts(&layouts), None)?);
            let sizes = [
                vk::DescriptorPoolSize { ty: vk::DescriptorType::UNIFORM_BUFFER, descriptor_count: 1 },
                vk::DescriptorPoolSize { ty: vk::DescriptorType::STORAGE_BUFFER, descriptor_count: 7 },
            ];
            let pool = DescriptorPool::from_raw(device, device.raw.create_descriptor_pool(
                &vk::DescriptorPoolCreateInfo::default().max_sets(1).pool_sizes(&sizes), None)?);
            let set = device.raw.allocate_descriptor_sets(
                &vk::DescriptorSetAllocateInfo::default().descriptor_pool(pool.raw).set_layouts(&layouts))?[0];
            let infos: Vec<[vk::DescriptorBufferInfo; 1]> =
                bound.iter().map(|(_, b)| [vk::DescriptorBufferInfo { buffer: b.raw, offset: 0, range: vk::WHOLE_SIZE }]).collect();
            let writes: Vec<vk::WriteDescriptorSet> = bound
                .iter()
                .zip(&infos)
                .map(|((b, _), info)| {
                    vk::WriteDescriptorSet::default()
                        .dst_set(set)
                        .dst_binding(*b)
                        .descriptor_type(if *b == 0 { vk::DescriptorType::UNIFORM_BUFFER } else { vk::DescriptorType::STORAGE_BUFFER })
                        .buffer_info(info)
                })
                .collect();
            device.raw.update_descriptor_sets(&writes, &[]);
            let command_pool = CommandPool::from_raw(device, device.raw.create_command_pool(
                &vk::CommandPoolCreateInfo::default().queue_family_index(device.queue_family)
                    .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER), None)?);
            let cmd = device.raw.allocate_command_buffers(&vk::CommandBufferAllocateInfo::default()
                .command_pool(command_pool.raw).level(vk::CommandBufferLevel::PRIMARY).command_buffer_count(1))?[0];
            let fence = Fence::from_raw(device, device.raw.create_fence(&vk::FenceCreateInfo::default(), None)?);
            let queries = if device.info.timestamps {
                Some(QueryPool::from_raw(device, device.raw.create_query_pool(
                    &vk::QueryPoolCreateInfo::default().query_type(vk::QueryType::TIMESTAMP).query_count(3), None)?))
            } else {
                None
            };
            (set_layout, layout, pool, set, command_pool, cmd, fence, queries)
        };
        let cull = compute_pipeline(device, &layout, CHAIN_CULL_SPV)?;
        let draw = chain_pipeline(device, &layout)?;
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
            _set_layout: set_layout,
            layout,
            _pool: pool,
            set,
            cull,
            draw,
            _command_pool: command_pool,
            cmd,
            fence,
            queries,
        };
        if !uploads.is_empty() {
            renderer.submit(|dev, cmd| {
                for (staging, dst) in &uploads {
                    // SAFETY: both buffers live and large enough; recording in `cmd`.
                    unsafe { dev.cmd_copy_buffer(cmd, staging.raw, *dst, &[vk::BufferCopy { src_offset: 0, dst_offset: 0, size: staging.size }]) };
                }
            })?;
        }
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
            let color = Image::new(&self.device, extent, COLOR_FORMAT, vk::ImageUsageFlags::COLOR_ATTACHMENT, vk::ImageAspectFlags::COLOR)?;
            let depth = Image::new(&self.device, extent, DEPTH_FORMAT, vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT, vk::ImageAspectFlags::DEPTH)?;
            self.target = Some((color, depth));
        }
        let (color, depth) = self.target.as_ref().context("target")?;
        let reset: Vec<u32> = self.levels.iter().flat_map(|&(first, count)| [count, 0, first, 0, 0]).collect();
        let reset: Vec<u32> = reset
            .chunks(5)
            .enumerate()
            .flat_map(|(l, c)| [c[0], 0, c[2], 0, l as u32 * self.instance_count])
            .collect();
        let groups = self.instance_count.div_ceil(64);
        self.submit(|dev, cmd| {
            // SAFETY: recording into `cmd` with resources owned by `self`.
            unsafe {
                if let Some(q) = &self.queries {
                    dev.cmd_reset_query_pool(cmd, q.raw, 0, 3);
                    dev.cmd_write_timestamp2(cmd, vk::PipelineStageFlags2::TOP_OF_PIPE, q.raw, 0);
                }
                dev.cmd_update_buffer(cmd, self.draws.raw, 0, cast_slice(&reset));
                barrier(dev, cmd, vk::PipelineStageFlags2::COPY, vk::AccessFlags2::TRANSFER_WRITE,
                    vk::PipelineStageFlags2::COMPUTE_SHADER, vk::AccessFlags2::SHADER_READ | vk::AccessFlags2::SHADER_WRITE);
                dev.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, self.cull.raw);
                dev.cmd_bind_descriptor_sets(cmd, vk::PipelineBindPoint::COMPUTE, self.layout.raw, 0, &[self.set], &[]);
                dev.cmd_dispatch(cmd, groups.min(65535), groups.div_ceil(65535), 1);
                barrier(dev, cmd, vk::PipelineStageFlags2::COMPUTE_SHADER, vk::AccessFlags2::SHADER_WRITE,
                    vk::PipelineStageFlags2::DRAW_INDIRECT | vk::PipelineStageFlags2::VERTEX_SHADER,
                    vk::AccessFlags2::INDIRECT_COMMAND_READ | vk::AccessFlags2::SHADER_READ);
                if let Some(q) = &self.queries {
                    dev.cmd_write_timestamp2(cmd, vk::PipelineStageFlags2::ALL_COMMANDS, q.raw, 1);
                }
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
                        .src_stage_mask(vk::PipelineStageFlags2::EARLY_FRAGMENT_TESTS | vk::PipelineStageFlags2::LATE_FRAGMENT_TESTS)
                        .dst_stage_mask(vk::PipelineStageFlags2::EARLY_FRAGMENT_TESTS | vk::PipelineStageFlags2::LATE_FRAGMENT_TESTS)
                        .dst_access_mask(vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_READ | vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_WRITE)
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
                    .clear_value(vk::ClearValue { depth_stencil: vk::ClearDepthStencilValue { depth: 0.0, stencil: 0 } });
                let area = vk::Rect2D { offset: vk::Offset2D { x: 0, y: 0 }, extent };
                dev.cmd_begin_rendering(cmd, &vk::RenderingInfo::default().render_area(area).layer_count(1)
                    .color_attachments(&color_att).depth_attachment(&depth_att));
                dev.cmd_set_viewport(cmd, 0, &[vk::Viewport { x: 0.0, y: height as f32, width: width as f32,
                    height: -(height as f32), min_depth: 0.0, max_depth: 1.0 }]);
                dev.cmd_set_scissor(cmd, 0, &[area]);
                dev.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::GRAPHICS, self.draw.raw);
                dev.cmd_bind_descriptor_sets(cmd, vk::PipelineBindPoint::GRAPHICS, self.layout.raw, 0, &[self.set], &[]);
                dev.cmd_bind_index_buffer(cmd, self.indices, 0, vk::IndexType::UINT32);
                for l in 0..self.levels.len() as u64 {
                    dev.cmd_draw_indexed_indirect(cmd, self.draws.raw, l * 20, 1, 20);
                }
                dev.cmd_end_rendering(cmd);
                if let Some(q) = &self.queries {
                    dev.cmd_write_timestamp2(cmd, vk::PipelineStageFlags2::ALL_COMMANDS, q.raw, 2);
                }
                barrier(dev, cmd, vk::PipelineStageFlags2::DRAW_INDIRECT, vk::AccessFlags2::INDIRECT_COMMAND_READ,
                    vk::PipelineStageFlags2::COPY, vk::AccessFlags2::TRANSFER_READ);
                dev.cmd_copy_buffer(cmd, self.draws.raw, self.draws_readback.raw, &[vk::BufferCopy { src_offset: 0, dst_offset: 0, size: self.draws.size }]);
                barrier(dev, cmd, vk::PipelineStageFlags2::COPY, vk::AccessFlags2::TRANSFER_WRITE,
                    vk::PipelineStageFlags2::HOST, vk::AccessFlags2::HOST_READ);
            }
        })?;
        let draws: Vec<u32> = cast_slice::<u8, u32>(&self.draws_readback.read(self.levels.len() * 20)?).to_vec();
        let instances_per_level: Vec<u32> = draws.chunks(5).map(|c| c[1]).collect();
        let triangles = instances_per_level.iter().zip(&self.levels).map(|(&n, &(_, count))| n as u64 * count as u64 / 3).sum();
        let times = match &self.queries {
            Some(q) => {
                let mut ticks = [0u64; 3];
                // SAFETY: written by the submission just waited for.
                unsafe { self.device.raw.get_query_pool_results(q.raw, 0, &mut ticks, vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT) }?;
                let ms = |a: usize, b: usize| ticks[b].wrapping_sub(ticks[a]) as f64 * self.device.info.timestamp_period_ns as f64 * 1e-6;
                Some((ms(0, 1), ms(1, 2)))
            }
            None => None,
        };
        Ok(ChainFrame { instances_per_level, triangles, times })
    }

    fn submit(&self, record: impl FnOnce(&ash::Device, vk::CommandBuffer)) -> Result<()> {
        let dev = &self.device.raw;
        // SAFETY: as Renderer::submit: the command buffer is idle and the fence unsignalled.
        unsafe {
            dev.reset_command_buffer(self.cmd, vk::CommandBufferResetFlags::empty())?;
            dev.begin_command_buffer(self.cmd, &vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT))?;
            record(dev, self.cmd);
            dev.end_command_buffer(self.cmd)?;
            let cmds = [vk::CommandBufferSubmitInfo::default().command_buffer(self.cmd)];
            let submit = [vk::SubmitInfo2::default().command_buffer_infos(&cmds)];
            dev.queue_submit2(self.device.queue, &submit, self.fence.raw).context("vkQueueSubmit2")?;
            dev.wait_for_fences(&[self.fence.raw], true, u64::MAX).context("vkWaitForFences")?;
            dev.reset_fences(&[self.fence.raw])?;
        }
        Ok(())
    }
}

fn chain_pipeline(device: &Arc<Device>, layout: &PipelineLayout) -> Result<Pipeline> {
    let vert = ShaderModule::new(device, CHAIN_VERT_SPV)?;
    let frag = ShaderModule::new(device, DRAW_FRAG_SPV)?;
    let stages = [
        vk::PipelineShaderStageCreateInfo::default().stage(vk::ShaderStageFlags::VERTEX).module(vert.raw).name(c"main"),
        vk::PipelineShaderStageCreateInfo::default().stage(vk::ShaderStageFlags::FRAGMENT).module(frag.raw).name(c"main"),
    ];
    let vertex_input = vk::PipelineVertexInputStateCreateInfo::default();
    let assembly = vk::PipelineInputAssemblyStateCreateInfo::default().topology(vk::PrimitiveTopology::TRIANGLE_LIST);
    let viewport = vk::PipelineViewportStateCreateInfo::default().viewport_count(1).scissor_count(1);
    let raster = vk::PipelineRasterizationStateCreateInfo::default()
        .polygon_mode(vk::PolygonMode::FILL)
        .cull_mode(vk::CullModeFlags::BACK)
        .front_face(vk::FrontFace::COUNTER_CLOCKWISE)
        .line_width(1.0);
    let multisample = vk::PipelineMultisampleStateCreateInfo::default().rasterization_samples(vk::SampleCountFlags::TYPE_1);
    let depth = vk::PipelineDepthStencilStateCreateInfo::default()
        .depth_test_enable(true)
        .depth_write_enable(true)
        .depth_compare_op(vk::CompareOp::GREATER);
    let blend_attachments = [vk::PipelineColorBlendAttachmentState::default().color_write_mask(vk::ColorComponentFlags::RGBA)];
    let blend = vk::PipelineColorBlendStateCreateInfo::default().attachments(&blend_attachments);
    let dynamic_states = [vk::DynamicState::VIEWPORT, vk::DynamicState::SCISSOR];
    let dynamic = vk::PipelineDynamicStateCreateInfo::default().dynamic_states(&dynamic_states);
    let color_formats = [COLOR_FORMAT];
    let mut rendering = vk::PipelineRenderingCreateInfo::default().color_attachment_formats(&color_formats).depth_attachment_format(DEPTH_FORMAT);
    let info = [vk::GraphicsPipelineCreateInfo::default()
        .stages(&stages)
        .vertex_input_state(&vertex_input)
        .input_assembly_state(&assembly)
        .viewport_state(&viewport)
        .rasterization_state(&raster)
        .multisample_state(&multisample)
        .depth_stencil_state(&depth)
        .color_blend_state(&blend)
        .dynamic_state(&dynamic)
        .layout(layout.raw)
        .push_next(&mut rendering)];
    // SAFETY: valid state structs and modules, alive until the call returns.
    unsafe {
        let raw = device.raw.create_graphics_pipelines(vk::PipelineCache::null(), &info, None).map_err(|(_, e)| e)
            .context("vkCreateGraphicsPipelines")?[0];
        Ok(Pipeline::from_raw(device, raw))
    }
}
