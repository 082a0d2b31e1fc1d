//! Recording one frame's commands (`Renderer::render_frame`): the selection, the expansion
//! (or the mesh-shader path's barrier), the draw of both sides, the read-backs and the blit to
//! a swapchain image. Each step is an `unsafe fn` with the contract of the command buffer it
//! records into; the caller submits and waits.

use ash::vk;
use bytemuck::bytes_of;

use super::super::resources::{subresource_range, Image, Pipeline};
use super::{barrier, PresentTarget, RenderTarget, Renderer, CLEAR_RGBA, CULL_GROUP_SIZE};
use crate::gpu_types::{GpuCounters, DISPATCH_ARGS_OFFSET, DRAW_ARGS_OFFSET, MESH_ARGS_OFFSET, SELECT_ARGS_OFFSET};

impl Renderer {
    /// Records what turns the selection into draws: on the mesh-shader path a barrier (the
    /// task shader reads the selection), else the expansion into an index buffer and its
    /// barrier; timestamps 1 and 2 around it.
    ///
    /// # Safety
    /// `cmd` must be recording, on `dev`, after [`Renderer::record_select`].
    pub(super) unsafe fn record_expand(&self, dev: &ash::Device, cmd: vk::CommandBuffer) {
        // SAFETY: per this function's contract; all handles are owned by `self`.
        unsafe {
            barrier(
                dev,
                cmd,
                vk::PipelineStageFlags2::COMPUTE_SHADER,
                vk::AccessFlags2::SHADER_WRITE,
                vk::PipelineStageFlags2::COMPUTE_SHADER | vk::PipelineStageFlags2::DRAW_INDIRECT,
                vk::AccessFlags2::SHADER_READ
                    | vk::AccessFlags2::SHADER_WRITE
                    | vk::AccessFlags2::INDIRECT_COMMAND_READ,
            );
            self.commands.timestamp(dev, cmd, 1);
            if self.mesh_path {
                barrier(
                    dev,
                    cmd,
                    vk::PipelineStageFlags2::COMPUTE_SHADER,
                    vk::AccessFlags2::SHADER_WRITE,
                    vk::PipelineStageFlags2::DRAW_INDIRECT
                        | vk::PipelineStageFlags2::TASK_SHADER_EXT
                        | vk::PipelineStageFlags2::MESH_SHADER_EXT
                        | vk::PipelineStageFlags2::FRAGMENT_SHADER,
                    vk::AccessFlags2::INDIRECT_COMMAND_READ | vk::AccessFlags2::SHADER_READ,
                );
            } else {
                dev.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, self.expand.raw);
                dev.cmd_dispatch_indirect(cmd, self.counters.raw, DISPATCH_ARGS_OFFSET);
                barrier(
                    dev,
                    cmd,
                    vk::PipelineStageFlags2::COMPUTE_SHADER,
                    vk::AccessFlags2::SHADER_WRITE,
                    vk::PipelineStageFlags2::DRAW_INDIRECT
                        | vk::PipelineStageFlags2::INDEX_INPUT
                        | vk::PipelineStageFlags2::VERTEX_SHADER
                        | vk::PipelineStageFlags2::FRAGMENT_SHADER,
                    vk::AccessFlags2::INDIRECT_COMMAND_READ
                        | vk::AccessFlags2::INDEX_READ
                        | vk::AccessFlags2::SHADER_READ,
                );
            }
            self.commands.timestamp(dev, cmd, 2);
        }
    }

    /// Records the draw of the selection into `target` (both sides, cleared first; depth
    /// stored if `want_depth`) and timestamp 3.
    ///
    /// # Safety
    /// `cmd` must be recording, on `dev`, after [`Renderer::record_expand`]; `target` must be
    /// this renderer's.
    pub(super) unsafe fn record_draw(
        &self,
        dev: &ash::Device,
        cmd: vk::CommandBuffer,
        target: &RenderTarget,
        want_depth: bool,
    ) {
        let extent = target.color.extent;
        // SAFETY: per this function's contract; all handles are owned by `self`.
        unsafe {
            let to_attachment = [
                image_barrier(
                    &target.color,
                    vk::ImageAspectFlags::COLOR,
                    vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT,
                    vk::AccessFlags2::COLOR_ATTACHMENT_WRITE,
                    vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
                ),
                image_barrier(
                    &target.depth,
                    vk::ImageAspectFlags::DEPTH,
                    vk::PipelineStageFlags2::EARLY_FRAGMENT_TESTS | vk::PipelineStageFlags2::LATE_FRAGMENT_TESTS,
                    vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_READ | vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_WRITE,
                    vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL,
                ),
            ];
            dev.cmd_pipeline_barrier2(cmd, &vk::DependencyInfo::default().image_memory_barriers(&to_attachment));
            let color = [vk::RenderingAttachmentInfo::default()
                .image_view(target.color.view)
                .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                .load_op(vk::AttachmentLoadOp::CLEAR)
                .store_op(vk::AttachmentStoreOp::STORE)
                .clear_value(vk::ClearValue { color: vk::ClearColorValue { float32: CLEAR_RGBA } })];
            let depth = vk::RenderingAttachmentInfo::default()
                .image_view(target.depth.view)
                .image_layout(vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL)
                .load_op(vk::AttachmentLoadOp::CLEAR)
                .store_op(if want_depth { vk::AttachmentStoreOp::STORE } else { vk::AttachmentStoreOp::DONT_CARE })
                .clear_value(vk::ClearValue { depth_stencil: vk::ClearDepthStencilValue { depth: 0.0, stencil: 0 } });
            let area = vk::Rect2D { offset: vk::Offset2D { x: 0, y: 0 }, extent };
            dev.cmd_begin_rendering(
                cmd,
                &vk::RenderingInfo::default()
                    .render_area(area)
                    .layer_count(1)
                    .color_attachments(&color)
                    .depth_attachment(&depth),
            );
            // Negative height: y up, as in the projection (Vulkan 1.1 core).
            dev.cmd_set_viewport(
                cmd,
                0,
                &[vk::Viewport {
                    x: 0.0,
                    y: extent.height as f32,
                    width: extent.width as f32,
                    height: -(extent.height as f32),
                    min_depth: 0.0,
                    max_depth: 1.0,
                }],
            );
            dev.cmd_set_scissor(cmd, 0, &[area]);
            match (&self.mesh_front, &self.mesh_back, &self.device.mesh) {
                (Some(front), Some(back), Some(mesh)) if self.mesh_path => {
                    for pipeline in [front, back] {
                        self.bind_graphics(dev, cmd, pipeline);
                        mesh.cmd_draw_mesh_tasks_indirect(cmd, self.counters.raw, MESH_ARGS_OFFSET, 1, 12);
                    }
                }
                _ => {
                    dev.cmd_bind_index_buffer(cmd, self.indices.raw, 0, vk::IndexType::UINT32);
                    for pipeline in [&self.draw_front, &self.draw_back] {
                        self.bind_graphics(dev, cmd, pipeline);
                        dev.cmd_draw_indexed_indirect(cmd, self.counters.raw, DRAW_ARGS_OFFSET, 1, 20);
                    }
                }
            }
            dev.cmd_end_rendering(cmd);
            self.commands.timestamp(dev, cmd, 3);
        }
    }

    /// Records the copies back to the host: the colour image (unless the renderer reads
    /// nothing back), the blit to the swapchain image where presenting, the depth image if
    /// `want_depth`, and the counters.
    ///
    /// # Safety
    /// `cmd` must be recording, on `dev`, after [`Renderer::record_draw`] into `target` (this
    /// renderer's); `present`'s readback must be ready (`ensure_present_readback`).
    pub(super) unsafe fn record_readback(
        &self,
        dev: &ash::Device,
        cmd: vk::CommandBuffer,
        (target, present): (&RenderTarget, Option<&PresentTarget>),
        want_depth: bool,
    ) {
        let extent = target.color.extent;
        // SAFETY: per this function's contract; all handles are owned by `self`.
        unsafe {
            let to_copy = [vk::ImageMemoryBarrier2::default()
                .src_stage_mask(vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT)
                .src_access_mask(vk::AccessFlags2::COLOR_ATTACHMENT_WRITE)
                .dst_stage_mask(vk::PipelineStageFlags2::COPY | vk::PipelineStageFlags2::BLIT)
                .dst_access_mask(vk::AccessFlags2::TRANSFER_READ)
                .old_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                .new_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL)
                .image(target.color.raw)
                .subresource_range(subresource_range(vk::ImageAspectFlags::COLOR))];
            dev.cmd_pipeline_barrier2(cmd, &vk::DependencyInfo::default().image_memory_barriers(&to_copy));
            let region = [vk::BufferImageCopy {
                buffer_offset: 0,
                buffer_row_length: 0,
                buffer_image_height: 0,
                image_subresource: vk::ImageSubresourceLayers {
                    aspect_mask: vk::ImageAspectFlags::COLOR,
                    mip_level: 0,
                    base_array_layer: 0,
                    layer_count: 1,
                },
                image_offset: vk::Offset3D { x: 0, y: 0, z: 0 },
                image_extent: vk::Extent3D { width: extent.width, height: extent.height, depth: 1 },
            }];
            if !self.no_readback {
                dev.cmd_copy_image_to_buffer(
                    cmd,
                    target.color.raw,
                    vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                    target.readback.raw,
                    &region,
                );
            }
            if let Some(p) = present {
                self.record_present(dev, cmd, &target.color, p, &region);
            }
            if want_depth {
                let to_copy = [vk::ImageMemoryBarrier2::default()
                    .src_stage_mask(vk::PipelineStageFlags2::LATE_FRAGMENT_TESTS)
                    .src_access_mask(vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_WRITE)
                    .dst_stage_mask(vk::PipelineStageFlags2::COPY)
                    .dst_access_mask(vk::AccessFlags2::TRANSFER_READ)
                    .old_layout(vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL)
                    .new_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL)
                    .image(target.depth.raw)
                    .subresource_range(subresource_range(vk::ImageAspectFlags::DEPTH))];
                dev.cmd_pipeline_barrier2(cmd, &vk::DependencyInfo::default().image_memory_barriers(&to_copy));
                let region = [vk::BufferImageCopy {
                    image_subresource: vk::ImageSubresourceLayers {
                        aspect_mask: vk::ImageAspectFlags::DEPTH,
                        mip_level: 0,
                        base_array_layer: 0,
                        layer_count: 1,
                    },
                    ..region[0]
                }];
                dev.cmd_copy_image_to_buffer(
                    cmd,
                    target.depth.raw,
                    vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                    target.depth_readback.raw,
                    &region,
                );
            }
            // The counters were last read as indirect arguments.
            barrier(
                dev,
                cmd,
                vk::PipelineStageFlags2::DRAW_INDIRECT,
                vk::AccessFlags2::INDIRECT_COMMAND_READ,
                vk::PipelineStageFlags2::COPY,
                vk::AccessFlags2::TRANSFER_READ,
            );
            self.copy_counters(dev, cmd);
            barrier(
                dev,
                cmd,
                vk::PipelineStageFlags2::COPY,
                vk::AccessFlags2::TRANSFER_WRITE,
                vk::PipelineStageFlags2::HOST,
                vk::AccessFlags2::HOST_READ,
            );
        }
    }

    /// Binds graphics `pipeline` and the renderer's descriptor set.
    ///
    /// # Safety
    /// `cmd` must be recording, on `dev`, inside a rendering pass.
    unsafe fn bind_graphics(&self, dev: &ash::Device, cmd: vk::CommandBuffer, pipeline: &Pipeline) {
        // SAFETY: per this function's contract; all handles are owned by `self`.
        unsafe {
            dev.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::GRAPHICS, pipeline.raw);
            let sets = [self.descriptors.set];
            dev.cmd_bind_descriptor_sets(
                cmd,
                vk::PipelineBindPoint::GRAPHICS,
                self.descriptors.layout.raw,
                0,
                &sets,
                &[],
            );
        }
    }

    /// Copies the counters to their host-readable buffer.
    ///
    /// # Safety
    /// `cmd` must be recording, on `dev`, after a barrier that makes the counters a transfer
    /// source.
    pub(super) unsafe fn copy_counters(&self, dev: &ash::Device, cmd: vk::CommandBuffer) {
        let size = std::mem::size_of::<GpuCounters>() as u64;
        let region = [vk::BufferCopy { src_offset: 0, dst_offset: 0, size }];
        // SAFETY: per this function's contract; all handles are owned by `self`.
        unsafe { dev.cmd_copy_buffer(cmd, self.counters.raw, self.readback_counters.raw, &region) };
    }

    /// Records the blit of the rendered colour image (in TRANSFER_SRC_OPTIMAL) into the
    /// acquired swapchain image, an optional copy of that image to the host, and its transition
    /// to PRESENT_SRC_KHR.
    ///
    /// # Safety
    /// `cmd` must be recording, on `dev`; `color` must be this renderer's colour target, of
    /// the swapchain's extent, after the barrier that makes it a transfer source.
    unsafe fn record_present(
        &self,
        dev: &ash::Device,
        cmd: vk::CommandBuffer,
        color: &Image,
        present: &PresentTarget,
        region: &[vk::BufferImageCopy; 1],
    ) {
        let range = subresource_range(vk::ImageAspectFlags::COLOR);
        // The submission waits on the acquire semaphore at BLIT: this barrier chains to it.
        let to_dst = [vk::ImageMemoryBarrier2::default()
            .src_stage_mask(vk::PipelineStageFlags2::BLIT)
            .src_access_mask(vk::AccessFlags2::NONE)
            .dst_stage_mask(vk::PipelineStageFlags2::BLIT)
            .dst_access_mask(vk::AccessFlags2::TRANSFER_WRITE)
            .old_layout(vk::ImageLayout::UNDEFINED)
            .new_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
            .image(present.image.image)
            .subresource_range(range)];
        let layers = vk::ImageSubresourceLayers {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            mip_level: 0,
            base_array_layer: 0,
            layer_count: 1,
        };
        let corner = vk::Offset3D { x: color.extent.width as i32, y: color.extent.height as i32, z: 1 };
        let blit = [vk::ImageBlit {
            src_subresource: layers,
            src_offsets: [vk::Offset3D::default(), corner],
            dst_subresource: layers,
            dst_offsets: [vk::Offset3D::default(), corner],
        }];
        // SAFETY: per this function's contract; the swapchain image was acquired for this frame.
        unsafe {
            dev.cmd_pipeline_barrier2(cmd, &vk::DependencyInfo::default().image_memory_barriers(&to_dst));
            dev.cmd_blit_image(
                cmd,
                color.raw,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                present.image.image,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &blit,
                vk::Filter::NEAREST,
            );
            let mut layout = vk::ImageLayout::TRANSFER_DST_OPTIMAL;
            let (mut stage, mut access) = (vk::PipelineStageFlags2::BLIT, vk::AccessFlags2::TRANSFER_WRITE);
            if let (true, Some(readback)) = (present.screenshot, &self.present_readback) {
                let to_src = [vk::ImageMemoryBarrier2::default()
                    .src_stage_mask(stage)
                    .src_access_mask(access)
                    .dst_stage_mask(vk::PipelineStageFlags2::COPY)
                    .dst_access_mask(vk::AccessFlags2::TRANSFER_READ)
                    .old_layout(layout)
                    .new_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL)
                    .image(present.image.image)
                    .subresource_range(range)];
                dev.cmd_pipeline_barrier2(cmd, &vk::DependencyInfo::default().image_memory_barriers(&to_src));
                dev.cmd_copy_image_to_buffer(
                    cmd,
                    present.image.image,
                    vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                    readback.raw,
                    region,
                );
                barrier(
                    dev,
                    cmd,
                    vk::PipelineStageFlags2::COPY,
                    vk::AccessFlags2::TRANSFER_WRITE,
                    vk::PipelineStageFlags2::HOST,
                    vk::AccessFlags2::HOST_READ,
                );
                layout = vk::ImageLayout::TRANSFER_SRC_OPTIMAL;
                (stage, access) = (vk::PipelineStageFlags2::COPY, vk::AccessFlags2::NONE);
            }
            // Presentation needs no access mask: the signal semaphore makes the writes visible.
            let to_present = [vk::ImageMemoryBarrier2::default()
                .src_stage_mask(stage)
                .src_access_mask(access)
                .dst_stage_mask(vk::PipelineStageFlags2::NONE)
                .dst_access_mask(vk::AccessFlags2::NONE)
                .old_layout(layout)
                .new_layout(vk::ImageLayout::PRESENT_SRC_KHR)
                .image(present.image.image)
                .subresource_range(range)];
            dev.cmd_pipeline_barrier2(cmd, &vk::DependencyInfo::default().image_memory_barriers(&to_present));
        }
    }

    /// Records the counter reset, instance culling and the (indirect) selection dispatch.
    ///
    /// # Safety
    /// `cmd` must be in the recording state and belong to `dev` (this renderer's device).
    pub(super) unsafe fn record_select(&self, dev: &ash::Device, cmd: vk::CommandBuffer) {
        let groups = self.instance_count.div_ceil(CULL_GROUP_SIZE).max(1);
        let gx = groups.min(self.device.info.max_compute_groups_x.min(65535));
        let gy = groups.div_ceil(gx);
        // SAFETY: per this function's contract; all handles are owned by `self`.
        unsafe {
            // The counters are read as indirect arguments by the previous frame's commands,
            // which completed before this submission (fence), and written below.
            dev.cmd_update_buffer(cmd, self.counters.raw, 0, bytes_of(&GpuCounters::reset()));
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
            dev.cmd_dispatch(cmd, gx, gy, 1);
            barrier(
                dev,
                cmd,
                vk::PipelineStageFlags2::COMPUTE_SHADER,
                vk::AccessFlags2::SHADER_WRITE,
                vk::PipelineStageFlags2::COMPUTE_SHADER | vk::PipelineStageFlags2::DRAW_INDIRECT,
                vk::AccessFlags2::SHADER_READ
                    | vk::AccessFlags2::SHADER_WRITE
                    | vk::AccessFlags2::INDIRECT_COMMAND_READ,
            );
            dev.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, self.select.raw);
            dev.cmd_dispatch_indirect(cmd, self.counters.raw, SELECT_ARGS_OFFSET);
        }
    }
}

/// A barrier that discards `image`'s contents and moves it to `layout` for `stage`/`access`.
fn image_barrier<'a>(
    image: &Image,
    aspect: vk::ImageAspectFlags,
    stage: vk::PipelineStageFlags2,
    access: vk::AccessFlags2,
    layout: vk::ImageLayout,
) -> vk::ImageMemoryBarrier2<'a> {
    vk::ImageMemoryBarrier2::default()
        // The previous frame's copy or blit (or attachment use) finished before this submission.
        .src_stage_mask(stage | vk::PipelineStageFlags2::COPY | vk::PipelineStageFlags2::BLIT)
        .src_access_mask(vk::AccessFlags2::NONE)
        .dst_stage_mask(stage)
        .dst_access_mask(access)
        .old_layout(vk::ImageLayout::UNDEFINED)
        .new_layout(layout)
        .image(image.raw)
        .subresource_range(subresource_range(aspect))
}
