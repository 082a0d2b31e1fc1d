//! What the selection renderer ([`super::renderer`]) and the LOD-chain renderer
//! ([`super::chain`]) set up alike: the one descriptor set of buffers, the compute and draw
//! pipelines over it, and the command buffer that each public call records, submits and waits
//! for (with its timestamp queries).

use std::sync::Arc;

use anyhow::{Context as _, Result};
use ash::vk;

use super::context::Device;
use super::resources::{
    Buffer, CommandPool, DescriptorPool, DescriptorSetLayout, Fence, Pipeline, PipelineLayout, QueryPool, ShaderModule,
};

/// Colour attachment format; the read-back bytes are RGBA8.
pub const COLOR_FORMAT: vk::Format = vk::Format::R8G8B8A8_UNORM;
pub(crate) const DEPTH_FORMAT: vk::Format = vk::Format::D32_SFLOAT;

/// One descriptor set of whole buffers, visible to every stage, and the pipeline layout made of
/// it. Binding 0 is the view (a uniform buffer, shaders/common.glsl), every other one a storage
/// buffer. Fields drop in declaration order.
pub(crate) struct Descriptors {
    _set_layout: DescriptorSetLayout,
    /// The layout of every pipeline that uses the set.
    pub layout: PipelineLayout,
    _pool: DescriptorPool,
    /// The set, written once; lives as long as the pool.
    pub set: vk::DescriptorSet,
}

fn descriptor_type(binding: u32) -> vk::DescriptorType {
    if binding == 0 {
        vk::DescriptorType::UNIFORM_BUFFER
    } else {
        vk::DescriptorType::STORAGE_BUFFER
    }
}

impl Descriptors {
    /// Binds each `(binding, buffer)` (whole buffer); `bound` must hold binding 0 and no binding
    /// twice. The buffers must outlive every use of the set.
    pub fn new(device: &Arc<Device>, bound: &[(u32, &Buffer)]) -> Result<Descriptors> {
        let bindings: Vec<vk::DescriptorSetLayoutBinding> = bound
            .iter()
            .map(|&(b, _)| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b)
                    .descriptor_type(descriptor_type(b))
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::ALL)
            })
            .collect();
        let storage = bound.iter().filter(|&&(b, _)| b != 0).count() as u32;
        // SAFETY: object creation from valid create infos; each handle goes straight into its
        // owner. The descriptor writes reference live buffers (the caller keeps them alive).
        unsafe {
            let set_layout = DescriptorSetLayout::from_raw(
                device,
                device.raw.create_descriptor_set_layout(
                    &vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings),
                    None,
                )?,
            );
            let layouts = [set_layout.raw];
            let layout = PipelineLayout::from_raw(
                device,
                device
                    .raw
                    .create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default().set_layouts(&layouts), None)?,
            );
            let sizes = [
                vk::DescriptorPoolSize { ty: vk::DescriptorType::UNIFORM_BUFFER, descriptor_count: 1 },
                vk::DescriptorPoolSize { ty: vk::DescriptorType::STORAGE_BUFFER, descriptor_count: storage },
            ];
            let pool = DescriptorPool::from_raw(
                device,
                device.raw.create_descriptor_pool(
                    &vk::DescriptorPoolCreateInfo::default().max_sets(1).pool_sizes(&sizes),
                    None,
                )?,
            );
            let set = device.raw.allocate_descriptor_sets(
                &vk::DescriptorSetAllocateInfo::default().descriptor_pool(pool.raw).set_layouts(&layouts),
            )?[0];
            let infos: Vec<[vk::DescriptorBufferInfo; 1]> = bound
                .iter()
                .map(|(_, b)| [vk::DescriptorBufferInfo { buffer: b.raw, offset: 0, range: vk::WHOLE_SIZE }])
                .collect();
            let writes: Vec<vk::WriteDescriptorSet> = bound
                .iter()
                .zip(&infos)
                .map(|(&(b, _), info)| {
                    vk::WriteDescriptorSet::default()
                        .dst_set(set)
                        .dst_binding(b)
                        .descriptor_type(descriptor_type(b))
                        .buffer_info(info)
                })
                .collect();
            device.raw.update_descriptor_sets(&writes, &[]);
            Ok(Descriptors { _set_layout: set_layout, layout, _pool: pool, set })
        }
    }
}

/// The command buffer of a renderer: each call records it, submits it and waits for its fence,
/// so it is never in use between calls. Optionally `timestamps` timestamp queries.
pub(crate) struct Commands {
    device: Arc<Device>,
    _pool: CommandPool,
    cmd: vk::CommandBuffer,
    fence: Fence,
    queries: Option<QueryPool>,
    timestamps: u32,
}

impl Commands {
    /// A command pool with one primary buffer, a fence, and `timestamps` queries where the
    /// device's queue has timestamps.
    pub fn new(device: &Arc<Device>, timestamps: u32) -> Result<Commands> {
        // SAFETY: object creation from valid create infos; each handle goes straight into its owner.
        unsafe {
            let pool = CommandPool::from_raw(
                device,
                device.raw.create_command_pool(
                    &vk::CommandPoolCreateInfo::default()
                        .queue_family_index(device.queue_family)
                        .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER),
                    None,
                )?,
            );
            let cmd = device.raw.allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(pool.raw)
                    .level(vk::CommandBufferLevel::PRIMARY)
                    .command_buffer_count(1),
            )?[0];
            let fence = Fence::from_raw(device, device.raw.create_fence(&vk::FenceCreateInfo::default(), None)?);
            let queries = if device.info.timestamps {
                Some(QueryPool::from_raw(
                    device,
                    device.raw.create_query_pool(
                        &vk::QueryPoolCreateInfo::default()
                            .query_type(vk::QueryType::TIMESTAMP)
                            .query_count(timestamps),
                        None,
                    )?,
                ))
            } else {
                None
            };
            Ok(Commands { device: device.clone(), _pool: pool, cmd, fence, queries, timestamps })
        }
    }

    /// Records `record` into the command buffer, submits it and waits for it to finish.
    pub fn submit(&self, record: impl FnOnce(&ash::Device, vk::CommandBuffer)) -> Result<()> {
        self.submit_with(&[], &[], record)
    }

    /// [`Commands::submit`], waiting on and signalling the given semaphores.
    pub fn submit_with(
        &self,
        waits: &[vk::SemaphoreSubmitInfo],
        signals: &[vk::SemaphoreSubmitInfo],
        record: impl FnOnce(&ash::Device, vk::CommandBuffer),
    ) -> Result<()> {
        let dev = &self.device.raw;
        // SAFETY: the command buffer is not in use (every submission is waited for before
        // this returns); the fence is unsignalled (reset after each wait).
        unsafe {
            dev.reset_command_buffer(self.cmd, vk::CommandBufferResetFlags::empty())?;
            dev.begin_command_buffer(
                self.cmd,
                &vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
            )?;
            record(dev, self.cmd);
            dev.end_command_buffer(self.cmd)?;
            let cmds = [vk::CommandBufferSubmitInfo::default().command_buffer(self.cmd)];
            let submit = [vk::SubmitInfo2::default()
                .wait_semaphore_infos(waits)
                .command_buffer_infos(&cmds)
                .signal_semaphore_infos(signals)];
            dev.queue_submit2(self.device.queue, &submit, self.fence.raw).context("vkQueueSubmit2")?;
            dev.wait_for_fences(&[self.fence.raw], true, u64::MAX).context("vkWaitForFences")?;
            dev.reset_fences(&[self.fence.raw])?;
        }
        Ok(())
    }

    /// Copies each staging buffer of `uploads` (from [`super::renderer::gpu_buffer`]) into its
    /// device-local buffer, and waits.
    pub fn upload(&self, uploads: &[(Buffer, vk::Buffer)]) -> Result<()> {
        if uploads.is_empty() {
            return Ok(());
        }
        self.submit(|dev, cmd| {
            for (staging, dst) in uploads {
                let region = [vk::BufferCopy { src_offset: 0, dst_offset: 0, size: staging.size }];
                // SAFETY: both buffers are live and large enough; recording in `cmd`.
                unsafe { dev.cmd_copy_buffer(cmd, staging.raw, *dst, &region) };
            }
        })
    }

    /// Resets the queries and writes timestamp 0 at the top of the pipe (nothing without
    /// timestamps).
    ///
    /// # Safety
    /// `cmd` must be this value's command buffer, recording, outside a render pass.
    pub unsafe fn start_timestamps(&self, dev: &ash::Device, cmd: vk::CommandBuffer) {
        if let Some(q) = &self.queries {
            // SAFETY: per this function's contract.
            unsafe {
                dev.cmd_reset_query_pool(cmd, q.raw, 0, self.timestamps);
                dev.cmd_write_timestamp2(cmd, vk::PipelineStageFlags2::TOP_OF_PIPE, q.raw, 0);
            }
        }
    }

    /// Writes timestamp `index` (1 ..= timestamps - 1) once all earlier commands are done.
    ///
    /// # Safety
    /// As [`Commands::start_timestamps`], which must have been recorded first.
    pub unsafe fn timestamp(&self, dev: &ash::Device, cmd: vk::CommandBuffer, index: u32) {
        if let Some(q) = &self.queries {
            // SAFETY: per this function's contract.
            unsafe { dev.cmd_write_timestamp2(cmd, vk::PipelineStageFlags2::ALL_COMMANDS, q.raw, index) };
        }
    }

    /// Milliseconds between consecutive timestamps of the last submission (timestamps - 1
    /// values), or None without timestamps.
    pub fn read_intervals_ms(&self) -> Result<Option<Vec<f64>>> {
        let Some(q) = &self.queries else { return Ok(None) };
        let mut ticks = vec![0u64; self.timestamps as usize];
        // SAFETY: the queries were written by the submission this call follows (fence waited).
        unsafe {
            self.device.raw.get_query_pool_results(
                q.raw,
                0,
                &mut ticks,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
        }?;
        let period_ms = self.device.info.timestamp_period_ns as f64 * 1e-6;
        Ok(Some(ticks.windows(2).map(|t| t[1].wrapping_sub(t[0]) as f64 * period_ms).collect()))
    }
}

/// A compute pipeline of the SPIR-V `spirv` (entry point `main`).
pub(crate) fn compute_pipeline(device: &Arc<Device>, layout: &PipelineLayout, spirv: &[u8]) -> Result<Pipeline> {
    let module = ShaderModule::new(device, spirv)?;
    let stage = vk::PipelineShaderStageCreateInfo::default()
        .stage(vk::ShaderStageFlags::COMPUTE)
        .module(module.raw)
        .name(c"main");
    let info = [vk::ComputePipelineCreateInfo::default().stage(stage).layout(layout.raw)];
    // SAFETY: valid module and layout; the pipeline goes into its owner.
    unsafe {
        let raw = device
            .raw
            .create_compute_pipelines(vk::PipelineCache::null(), &info, None)
            .map_err(|(_, e)| e)
            .context("vkCreateComputePipelines")?[0];
        Ok(Pipeline::from_raw(device, raw))
    }
}

/// A draw pipeline into [`COLOR_FORMAT`] + [`DEPTH_FORMAT`] of the SPIR-V `stages` (entry points
/// `main`): without a vertex stage, task + mesh shaders; with one, a triangle list without
/// vertex input (the vertex shader reads its buffers). Reverse-Z depth test, dynamic viewport
/// and scissor. `back_faces` draws only back faces, pushed slightly away (depth bias) so that
/// front faces win every tie along silhouettes; otherwise only front faces.
pub(crate) fn draw_pipeline(
    device: &Arc<Device>,
    layout: &PipelineLayout,
    stages: &[(vk::ShaderStageFlags, &[u8])],
    back_faces: bool,
) -> Result<Pipeline> {
    let modules = stages
        .iter()
        .map(|&(stage, spirv)| Ok((stage, ShaderModule::new(device, spirv)?)))
        .collect::<Result<Vec<_>>>()?;
    let stages: Vec<vk::PipelineShaderStageCreateInfo> = modules
        .iter()
        .map(|(stage, m)| vk::PipelineShaderStageCreateInfo::default().stage(*stage).module(m.raw).name(c"main"))
        .collect();
    let vertex_stage = modules.iter().any(|(stage, _)| *stage == vk::ShaderStageFlags::VERTEX);
    let vertex_input = vk::PipelineVertexInputStateCreateInfo::default();
    let assembly = vk::PipelineInputAssemblyStateCreateInfo::default().topology(vk::PrimitiveTopology::TRIANGLE_LIST);
    let viewport = vk::PipelineViewportStateCreateInfo::default().viewport_count(1).scissor_count(1);
    let raster = vk::PipelineRasterizationStateCreateInfo::default()
        .polygon_mode(vk::PolygonMode::FILL)
        .cull_mode(if back_faces { vk::CullModeFlags::FRONT } else { vk::CullModeFlags::BACK })
        .front_face(vk::FrontFace::COUNTER_CLOCKWISE)
        .depth_bias_enable(back_faces)
        .depth_bias_constant_factor(if back_faces { -16.0 } else { 0.0 })
        .depth_bias_slope_factor(if back_faces { -2.0 } else { 0.0 })
        .line_width(1.0);
    let multisample =
        vk::PipelineMultisampleStateCreateInfo::default().rasterization_samples(vk::SampleCountFlags::TYPE_1);
    let depth = vk::PipelineDepthStencilStateCreateInfo::default()
        .depth_test_enable(true)
        .depth_write_enable(true)
        .depth_compare_op(vk::CompareOp::GREATER);
    let blend_attachments =
        [vk::PipelineColorBlendAttachmentState::default().color_write_mask(vk::ColorComponentFlags::RGBA)];
    let blend = vk::PipelineColorBlendStateCreateInfo::default().attachments(&blend_attachments);
    let dynamic_states = [vk::DynamicState::VIEWPORT, vk::DynamicState::SCISSOR];
    let dynamic = vk::PipelineDynamicStateCreateInfo::default().dynamic_states(&dynamic_states);
    let color_formats = [COLOR_FORMAT];
    let mut rendering = vk::PipelineRenderingCreateInfo::default()
        .color_attachment_formats(&color_formats)
        .depth_attachment_format(DEPTH_FORMAT);
    let mut info = vk::GraphicsPipelineCreateInfo::default().stages(&stages);
    if vertex_stage {
        info = info.vertex_input_state(&vertex_input).input_assembly_state(&assembly);
    }
    let info = [info
        .viewport_state(&viewport)
        .rasterization_state(&raster)
        .multisample_state(&multisample)
        .depth_stencil_state(&depth)
        .color_blend_state(&blend)
        .dynamic_state(&dynamic)
        .layout(layout.raw)
        .push_next(&mut rendering)];
    // SAFETY: valid state structs and modules (alive until the call returns).
    unsafe {
        let raw = device
            .raw
            .create_graphics_pipelines(vk::PipelineCache::null(), &info, None)
            .map_err(|(_, e)| e)
            .context("vkCreateGraphicsPipelines")?[0];
        Ok(Pipeline::from_raw(device, raw))
    }
}
