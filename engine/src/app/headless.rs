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
        }
        let cbs = [vk::CommandBufferSubmitInfo::default().command_buffer(self.cb)];
        gpu.submit_frame(&[vk::SubmitInfo2::default().command_buffer_infos(&cbs)], self.fence)?;
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

/// How a headless run's device, target and renderer are made (`Stage`).
#[derive(Clone)]
pub struct StageOptions {
    pub gpu: crate::gpu::GpuOptions,
    pub width: u32,
    pub height: u32,
    pub shadow_map_size: u32,
    pub aa: crate::render::renderer::AntiAliasing,
    pub render_scale: crate::render::scale::RenderScale,
    /// The upscaler's filter (None: the device kind's default).
    pub upscaler: Option<crate::render::scale::Upscaler>,
    /// Draw the debug overlay over every frame.
    pub overlay: bool,
}

/// Everything a headless run has on the device, made from one pack: the device, the offscreen
/// target, the renderer with the scene's characters, the scene and the overlay. Made again
/// whole after a device loss (`recover`).
pub struct Stage {
    pub overlay: Option<Overlay>,
    pub target: Offscreen,
    pub renderer: Renderer,
    pub scene: GpuScene,
    /// Last: the rest is made on it.
    pub gpu: Gpu,
}

/// A `Stage` without its device.
struct Parts {
    overlay: Option<Overlay>,
    target: Offscreen,
    renderer: Renderer,
    scene: GpuScene,
}

impl Parts {
    /// `mark` hears "renderer" and "scene upload" as each is made (the demo's start-up times).
    fn make(gpu: &Gpu, opts: &StageOptions, pack: &pack::Pack, mark: &mut dyn FnMut(&'static str)) -> Result<Parts> {
        let target = gpu.own(Offscreen::new(gpu, opts.width, opts.height)?);
        let mut renderer = gpu.own(Renderer::new(gpu, OFFSCREEN_FORMAT, 1)?);
        renderer.set_shadow_map_size(gpu, opts.shadow_map_size)?;
        renderer.aa = opts.aa;
        renderer.render_scale = crate::render::scale::ScaleController::new(opts.render_scale);
        if let Some(u) = opts.upscaler {
            renderer.upscaler = u;
        }
        let overlay = if opts.overlay { Some(Overlay::new(gpu, OFFSCREEN_FORMAT, 1)?) } else { None };
        mark("renderer");
        let scene = match GpuScene::upload(gpu, pack, renderer.layouts()) {
            Ok(s) => gpu.own(s),
            Err(e) => {
                if let Some(o) = overlay {
                    o.destroy(gpu);
                }
                return Err(e);
            }
        };
        match crate::anim::animated::AnimatedScene::new(gpu, pack, &scene, 1) {
            Ok(a) => renderer.animation = a,
            Err(e) => {
                if let Some(o) = overlay {
                    o.destroy(gpu);
                }
                return Err(e);
            }
        }
        mark("scene upload");
        Ok(Parts { overlay, target: target.keep(), renderer: renderer.keep(), scene: scene.keep() })
    }

    fn destroy(self, gpu: &Gpu) {
        let Parts { overlay, mut target, mut renderer, mut scene } = self;
        if let Some(o) = overlay {
            o.destroy(gpu);
        }
        scene.destroy(gpu);
        renderer.destroy(gpu);
        target.destroy(gpu);
    }
}

impl Stage {
    /// A device chosen by `opts.gpu` with `pack`'s scene on it; `mark` hears "device",
    /// "renderer" and "scene upload" as each is done.
    pub fn new(opts: &StageOptions, pack: &pack::Pack, mark: &mut dyn FnMut(&'static str)) -> Result<Stage> {
        let gpu = Gpu::new(&opts.gpu)?;
        mark("device");
        let parts = Parts::make(&gpu, opts, pack, mark)?;
        Ok(Stage::assemble(gpu, parts))
    }

    fn assemble(gpu: Gpu, p: Parts) -> Stage {
        Stage { overlay: p.overlay, target: p.target, renderer: p.renderer, scene: p.scene, gpu }
    }

    fn split(self) -> (Gpu, Parts) {
        let Stage { overlay, target, renderer, scene, gpu } = self;
        (gpu, Parts { overlay, target, renderer, scene })
    }

    /// After the device was lost: a new device with `pack`'s scene made again on it (`pack`:
    /// the one on show), carrying on from this one's state: the renderer's settings, LODs,
    /// render scale and characters, the scene's instances as the game left them, the overlay's
    /// history. What was on the lost device is retired (`recovery::retire`). On an error (the
    /// new device cannot be made or is lost too) this stage is left as it was, still lost.
    pub fn recover(&mut self, opts: &StageOptions, pack: &pack::Pack) -> Result<()> {
        let gpu = self.gpu.successor(&opts.gpu)?;
        let mut parts = Parts::make(&gpu, opts, pack, &mut |_| {})?;
        if let Err(e) = parts.renderer.set_shadow_map_size(&gpu, self.renderer.shadow.size) {
            parts.destroy(&gpu);
            return Err(e);
        }
        parts.renderer.carry_on_from(&mut self.renderer);
        parts.scene.carry_on_from(&mut self.scene);
        if let (Some(new), Some(old)) = (parts.overlay.as_mut(), self.overlay.as_mut()) {
            new.carry_on_from(old);
        }
        let old = std::mem::replace(self, Stage::assemble(gpu, parts));
        let (old_gpu, old_parts) = old.split();
        super::recovery::retire(old_gpu, old_parts, |gpu, p| p.destroy(gpu));
        Ok(())
    }

    /// Frees everything, the device last; returns the validation errors counted over the run,
    /// its teardown and every device it had included.
    pub fn destroy(self) -> usize {
        let (gpu, parts) = self.split();
        let log = gpu.validation_log();
        gpu.wait_idle();
        parts.destroy(&gpu);
        drop(gpu);
        log.error_count()
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
