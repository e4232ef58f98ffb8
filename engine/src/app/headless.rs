//! Rendering without a window: an offscreen colour target, one frame at a time, with
//! read-back to RGBA8 and PNG, and per-frame CPU and GPU timings.

use crate::scene::camera::Camera;
use crate::gpu::{Buffer, Gpu, Image};
use crate::ui::Overlay;
use crate::render::frame::FrameCx;
use crate::render::graph::{Access, Io, Pass, Rec, ResourceId, OUTPUT};
use crate::render::renderer::{FrameTarget, Lighting, Renderer};
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
    /// Wall time from the start of recording to the GPU finishing the frame and its timestamps
    /// read back.
    pub frame_ms: f64,
    /// Of it, the CPU's part: preparing (culling, LOD, batches, uploads) and recording, up to
    /// the submit.
    pub record_ms: f64,
    /// Of it, the wait for the frame's fence after the submit (on lavapipe: the GPU work) and
    /// for its timestamps.
    pub wait_ms: f64,
    /// GPU time between the first and last command (timestamps), when the queue supports them.
    pub gpu_ms: Option<f64>,
}

pub struct Offscreen {
    pub extent: vk::Extent2D,
    color: Image,
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
        // Owned until the target is whole: an error frees what was made before it.
        let color = gpu.own(Image::new(
            gpu,
            "offscreen colour",
            OFFSCREEN_FORMAT,
            extent,
            1,
            vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC,
            vk::ImageAspectFlags::COLOR,
        )?);
        let readback = gpu.own(Buffer::new(gpu, "readback", width as u64 * height as u64 * 4, vk::BufferUsageFlags::TRANSFER_DST, MemoryLocation::GpuToCpu)?);
        let pool = gpu.own(unsafe {
            d.create_command_pool(
                &vk::CommandPoolCreateInfo::default()
                    .queue_family_index(gpu.queue_family)
                    .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER),
                None,
            )?
        });
        let cb = unsafe {
            d.allocate_command_buffers(&vk::CommandBufferAllocateInfo::default().command_pool(*pool).command_buffer_count(1))?[0]
        };
        let fence = gpu.own(unsafe { d.create_fence(&vk::FenceCreateInfo::default(), None)? });
        let timestamps = if gpu.caps.timestamps {
            Some(unsafe {
                d.create_query_pool(&vk::QueryPoolCreateInfo::default().query_type(vk::QueryType::TIMESTAMP).query_count(2), None)?
            })
        } else {
            None
        };
        Ok(Offscreen { extent, color: color.keep(), readback: readback.keep(), pool: pool.keep(), cb, fence: fence.keep(), timestamps })
    }

    /// Render one frame and wait for it. With `capture`, the image is copied to the read-back
    /// buffer, ready for `pixels()`.
    pub fn render(&mut self, gpu: &Gpu, renderer: &mut Renderer, scene: &GpuScene, camera: &Camera, lighting: &Lighting, capture: bool) -> Result<FrameTiming> {
        self.frame(gpu, renderer, scene, camera, lighting, capture, None, |_, _| {})
    }

    /// `render` with the overlay drawn over the finished image before it is captured: `build`
    /// lays it out once the renderer has prepared the frame (its counters are this frame's).
    #[allow(clippy::too_many_arguments)]
    pub fn render_with(
        &mut self,
        gpu: &Gpu,
        renderer: &mut Renderer,
        scene: &GpuScene,
        camera: &Camera,
        lighting: &Lighting,
        capture: bool,
        overlay: &mut Overlay,
        build: impl FnOnce(&mut Overlay, &mut Renderer),
    ) -> Result<FrameTiming> {
        self.frame(gpu, renderer, scene, camera, lighting, capture, Some(overlay), build)
    }

    #[allow(clippy::too_many_arguments)]
    fn frame(
        &mut self,
        gpu: &Gpu,
        renderer: &mut Renderer,
        scene: &GpuScene,
        camera: &Camera,
        lighting: &Lighting,
        capture: bool,
        mut overlay: Option<&mut Overlay>,
        build: impl FnOnce(&mut Overlay, &mut Renderer),
    ) -> Result<FrameTiming> {
        // Everything this call does is inside the frame's time, so a caller's clock around it
        // sees record_ms + wait_ms and nothing unaccounted (bench's parts add up to its frames).
        let start = Instant::now();
        gpu.alive("a frame")?;
        let d = &gpu.device;
        let target = FrameTarget { color_image: self.color.image, color_view: self.color.view, extent: self.extent };
        unsafe {
            d.reset_command_buffer(self.cb, vk::CommandBufferResetFlags::empty())?;
            d.begin_command_buffer(self.cb, &vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT))?;
            if let Some(q) = self.timestamps {
                d.cmd_reset_query_pool(self.cb, q, 0, 2);
                d.cmd_write_timestamp2(self.cb, vk::PipelineStageFlags2::TOP_OF_PIPE, q, 0);
            }
        }
        renderer.prepare(gpu, 0, scene, camera, lighting, self.extent)?;
        if let Some(o) = overlay.as_deref_mut() {
            build(o, renderer);
        }
        let mut readback = Readback { buffer: self.readback.buffer, extent: self.extent };
        let mut extra: Vec<&mut dyn Pass> = Vec::new();
        if let Some(o) = overlay {
            extra.push(o);
        }
        let finals: &[(ResourceId, Access)] = if capture {
            extra.push(&mut readback);
            &[(READBACK, Access::HostRead)]
        } else {
            &[]
        };
        renderer.record_prepared(gpu, self.cb, 0, scene, &target, &mut extra, finals)?;
        unsafe {
            if let Some(q) = self.timestamps {
                d.cmd_write_timestamp2(self.cb, vk::PipelineStageFlags2::BOTTOM_OF_PIPE, q, 1);
            }
            d.end_command_buffer(self.cb)?;
            let cbs = [vk::CommandBufferSubmitInfo::default().command_buffer(self.cb)];
            let submit = [vk::SubmitInfo2::default().command_buffer_infos(&cbs)];
            d.queue_submit2(gpu.queue, &submit, self.fence)?;
        }
        let record_ms = start.elapsed().as_secs_f64() * 1e3;
        unsafe {
            gpu.wait_fence(self.fence, "a frame")?;
            d.reset_fences(&[self.fence])?;
        }
        let gpu_ms = match self.timestamps {
            Some(q) => {
                let mut ts = [0u64; 2];
                unsafe { d.get_query_pool_results(q, 0, &mut ts, vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT)? };
                Some(ts[1].saturating_sub(ts[0]) as f64 * gpu.caps.timestamp_period_ns as f64 * 1e-6)
            }
            None => None,
        };
        let frame_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(FrameTiming { frame_ms, record_ms, wait_ms: frame_ms - record_ms, gpu_ms })
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

/// The read-back buffer, as the frame graph sees it.
const READBACK: ResourceId = ResourceId("readback");

/// The last pass of a captured frame: the output copied into the read-back buffer.
struct Readback {
    buffer: vk::Buffer,
    extent: vk::Extent2D,
}

impl Pass for Readback {
    fn name(&self) -> &'static str {
        "readback"
    }

    fn declare(&mut self, _cx: &FrameCx, io: &mut Io) {
        io.uses(OUTPUT, Access::TransferSrc).uses(READBACK, Access::BufferTransferDst);
    }

    fn record(&mut self, _cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        let layers = vk::ImageSubresourceLayers { aspect_mask: vk::ImageAspectFlags::COLOR, mip_level: 0, base_array_layer: 0, layer_count: 1 };
        let region = vk::BufferImageCopy::default().image_subresource(layers).image_extent(vk::Extent3D { width: self.extent.width, height: self.extent.height, depth: 1 });
        unsafe { rec.gpu.device.cmd_copy_image_to_buffer(rec.cb, rec.image(OUTPUT).image, vk::ImageLayout::TRANSFER_SRC_OPTIMAL, self.buffer, &[region]) };
        Ok(())
    }
}
