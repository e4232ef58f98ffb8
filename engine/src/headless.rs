//! Rendering without a window: an offscreen colour + depth target, one frame at a time, with
//! read-back to RGBA8 and PNG, and per-frame CPU and GPU timings.

use crate::camera::Camera;
use crate::gpu::{barrier, full_range, Buffer, Gpu, Image, Transition};
use crate::renderer::{FrameTarget, Lighting, Renderer};
use crate::scene::GpuScene;
use anyhow::{Context, Result};
use ash::vk;
use gpu_allocator::MemoryLocation;
use std::path::Path;
use std::time::Instant;

/// sRGB colour: the shader writes linear values and the attachment encodes them.
pub const OFFSCREEN_FORMAT: vk::Format = vk::Format::R8G8B8A8_SRGB;

/// How long one frame took.
#[derive(Debug, Clone, Copy)]
pub struct FrameTiming {
    /// Wall time from the start of recording to the GPU finishing the frame.
    pub frame_ms: f64,
    /// GPU time between the first and last command (timestamps), when the queue supports them.
    pub gpu_ms: Option<f64>,
}

pub struct Offscreen {
    pub extent: vk::Extent2D,
    color: Image,
    depth: Image,
    readback: Buffer,
    pool: vk::CommandPool,
    cb: vk::CommandBuffer,
    fence: vk::Fence,
    timestamps: Option<vk::QueryPool>,
}

impl Offscreen {
    pub fn new(gpu: &Gpu, width: u32, height: u32) -> Result<Offscreen> {
        let extent = vk::Extent2D { width, height };
        let d = &gpu.device;
        let color = Image::new(
            gpu,
            "offscreen colour",
            OFFSCREEN_FORMAT,
            extent,
            1,
            vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC,
            vk::ImageAspectFlags::COLOR,
        )?;
        let depth = Image::new(
            gpu,
            "offscreen depth",
            gpu.caps.depth_format,
            extent,
            1,
            vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT,
            vk::ImageAspectFlags::DEPTH,
        )?;
        let readback = Buffer::new(gpu, "readback", width as u64 * height as u64 * 4, vk::BufferUsageFlags::TRANSFER_DST, MemoryLocation::GpuToCpu)?;
        let pool = unsafe {
            d.create_command_pool(
                &vk::CommandPoolCreateInfo::default()
                    .queue_family_index(gpu.queue_family)
                    .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER),
                None,
            )?
        };
        let cb = unsafe {
            d.allocate_command_buffers(&vk::CommandBufferAllocateInfo::default().command_pool(pool).command_buffer_count(1))?[0]
        };
        let fence = unsafe { d.create_fence(&vk::FenceCreateInfo::default(), None)? };
        let timestamps = if gpu.caps.timestamps {
            Some(unsafe {
                d.create_query_pool(&vk::QueryPoolCreateInfo::default().query_type(vk::QueryType::TIMESTAMP).query_count(2), None)?
            })
        } else {
            None
        };
        Ok(Offscreen { extent, color, depth, readback, pool, cb, fence, timestamps })
    }

    /// Render one frame and wait for it. With `capture`, the image is copied to the read-back
    /// buffer, ready for `pixels()`.
    pub fn render(
        &mut self,
        gpu: &Gpu,
        renderer: &mut Renderer,
        scene: &GpuScene,
        camera: &Camera,
        lighting: &Lighting,
        capture: bool,
    ) -> Result<FrameTiming> {
        self.render_with(gpu, renderer, scene, camera, lighting, capture, |_, _, _| Ok(()))
    }

    /// `render`, with `after` recording more drawing onto the finished image (the overlay)
    /// before it is captured. It gets the command buffer, the target (colour image in
    /// COLOR_ATTACHMENT_OPTIMAL, to be left so) and the renderer that just recorded.
    #[allow(clippy::too_many_arguments)]
    pub fn render_with(
        &mut self,
        gpu: &Gpu,
        renderer: &mut Renderer,
        scene: &GpuScene,
        camera: &Camera,
        lighting: &Lighting,
        capture: bool,
        after: impl FnOnce(vk::CommandBuffer, &FrameTarget, &mut Renderer) -> Result<()>,
    ) -> Result<FrameTiming> {
        gpu.alive("a frame")?;
        let d = &gpu.device;
        let start = Instant::now();
        let target = FrameTarget {
            color_image: self.color.image,
            color_view: self.color.view,
            depth_image: self.depth.image,
            depth_view: self.depth.view,
            extent: self.extent,
        };
        unsafe {
            d.reset_command_buffer(self.cb, vk::CommandBufferResetFlags::empty())?;
            d.begin_command_buffer(self.cb, &vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT))?;
            if let Some(q) = self.timestamps {
                d.cmd_reset_query_pool(self.cb, q, 0, 2);
                d.cmd_write_timestamp2(self.cb, vk::PipelineStageFlags2::TOP_OF_PIPE, q, 0);
            }
        }
        renderer.record(gpu, self.cb, 0, scene, camera, lighting, &target)?;
        after(self.cb, &target, renderer)?;
        unsafe {
            if capture {
                barrier(gpu, self.cb, self.color.image, full_range(vk::ImageAspectFlags::COLOR, 1), Transition::COLOR_ATTACHMENT_TO_TRANSFER_SRC);
                let region = vk::BufferImageCopy::default()
                    .image_subresource(vk::ImageSubresourceLayers {
                        aspect_mask: vk::ImageAspectFlags::COLOR,
                        mip_level: 0,
                        base_array_layer: 0,
                        layer_count: 1,
                    })
                    .image_extent(vk::Extent3D { width: self.extent.width, height: self.extent.height, depth: 1 });
                d.cmd_copy_image_to_buffer(self.cb, self.color.image, vk::ImageLayout::TRANSFER_SRC_OPTIMAL, self.readback.buffer, &[region]);
                let to_host = [vk::BufferMemoryBarrier2::default()
                    .buffer(self.readback.buffer)
                    .size(vk::WHOLE_SIZE)
                    .src_stage_mask(vk::PipelineStageFlags2::COPY)
                    .src_access_mask(vk::AccessFlags2::TRANSFER_WRITE)
                    .dst_stage_mask(vk::PipelineStageFlags2::HOST)
                    .dst_access_mask(vk::AccessFlags2::HOST_READ)];
                d.cmd_pipeline_barrier2(self.cb, &vk::DependencyInfo::default().buffer_memory_barriers(&to_host));
            }
            if let Some(q) = self.timestamps {
                d.cmd_write_timestamp2(self.cb, vk::PipelineStageFlags2::BOTTOM_OF_PIPE, q, 1);
            }
            d.end_command_buffer(self.cb)?;
            let cbs = [vk::CommandBufferSubmitInfo::default().command_buffer(self.cb)];
            let submit = [vk::SubmitInfo2::default().command_buffer_infos(&cbs)];
            d.queue_submit2(gpu.queue, &submit, self.fence)?;
            gpu.wait_fence(self.fence, "a frame")?;
            d.reset_fences(&[self.fence])?;
        }
        let frame_ms = start.elapsed().as_secs_f64() * 1e3;
        let gpu_ms = match self.timestamps {
            Some(q) => {
                let mut ts = [0u64; 2];
                unsafe { d.get_query_pool_results(q, 0, &mut ts, vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT)? };
                Some(ts[1].saturating_sub(ts[0]) as f64 * gpu.caps.timestamp_period_ns as f64 * 1e-6)
            }
            None => None,
        };
        Ok(FrameTiming { frame_ms, gpu_ms })
    }

    /// RGBA8 (sRGB-encoded) pixels of the last captured frame, top row first.
    pub fn pixels(&self) -> &[u8] {
        self.readback.mapped_ref()
    }

    pub fn save_png(&self, path: &Path) -> Result<()> {
        save_rgba_png(path, self.extent.width, self.extent.height, self.pixels())
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        unsafe {
            let d = &gpu.device;
            if let Some(q) = self.timestamps.take() {
                d.destroy_query_pool(q, None);
            }
            d.destroy_fence(self.fence, None);
            d.destroy_command_pool(self.pool, None);
        }
        self.readback.destroy(gpu);
        self.depth.destroy(gpu);
        self.color.destroy(gpu);
    }
}

/// Write RGBA8 pixels as a PNG, atomically (temporary file, then rename).
pub fn save_rgba_png(path: &Path, width: u32, height: u32, rgba: &[u8]) -> Result<()> {
    if let Some(dir) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let tmp = path.with_extension(format!("png.tmp-{}", std::process::id()));
    image::save_buffer_with_format(&tmp, rgba, width, height, image::ExtendedColorType::Rgba8, image::ImageFormat::Png)
        .with_context(|| format!("writing {}", path.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
