//! The debug overlay: egui drawn by egui-ash-renderer onto the final display image, as the
//! frame graph's last drawing pass (before present or read-back). It shows the frame-time graph and the
//! renderer's counters and flips its switches (`panels`); callers add their own panels per frame.
//!
//! Per frame: `build` (egui layout for this frame's input), the pass (texture uploads, then one
//! dynamic-rendering pass that loads the image and draws the UI over it), and once the frame's
//! fence has signalled, `push_frame` with what the GPU measured.

pub mod history;
pub mod panels;
pub mod sim_panel;

pub use history::{FrameHistory, Ring, HISTORY_FRAMES};
pub use panels::{ControlRects, PackPanel, Panel, PassesPanel, RendererPanel};
pub use sim_panel::SimPanel;

use crate::gpu::Gpu;
use crate::render::frame::FrameCx;
use crate::render::graph::{Access, FrameProfile, Io, Pass, Rec, Rendering, OUTPUT};
use crate::render::renderer::Renderer;
use anyhow::{anyhow, Result};
use ash::vk;
use egui_ash_renderer::allocator::GpuAllocator;
use egui_ash_renderer::{DynamicRendering, Options, RenderMode};

/// What the GPU measured for one finished frame (read after its fence).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameStats {
    /// GPU ms and shader invocations of each pass the frame ran.
    pub passes: Option<FrameProfile>,
    /// Fragments the shading pass shaded, when `Renderer::count_fragments` was on.
    pub fragments_shaded: Option<u32>,
}

impl FrameStats {
    /// Read what the frame last recorded in `slot` measured; its fence must have signalled.
    pub fn read(gpu: &Gpu, renderer: &Renderer, slot: usize) -> FrameStats {
        FrameStats {
            passes: renderer.profile(gpu, slot),
            fragments_shaded: renderer.fragment_count(slot),
        }
    }

    /// GPU time of the renderer's passes, when timestamps exist.
    pub fn gpu_ms(&self) -> Option<f64> {
        self.passes.as_ref().filter(|p| p.passes.iter().any(|p| p.gpu_ms.is_some())).map(FrameProfile::total_ms)
    }
}

/// A frame's UI, laid out and tessellated, waiting to be recorded.
struct Prepared {
    primitives: Vec<egui::ClippedPrimitive>,
    textures: egui::TexturesDelta,
    pixels_per_point: f32,
}

pub struct Overlay {
    ctx: egui::Context,
    painter: egui_ash_renderer::Renderer<GpuAllocator>,
    /// For egui-ash-renderer's texture uploads (it submits and waits on its own).
    upload_pool: vk::CommandPool,
    /// F1 in the window; `--overlay` headless. Hidden: nothing is built or drawn.
    pub visible: bool,
    pub history: FrameHistory,
    /// The last finished frame's measurements.
    pub last: FrameStats,
    prepared: Option<Prepared>,
    /// Textures egui released, freed once no frame in flight can sample them.
    pending_free: Vec<egui::TextureId>,
    window_rect: Option<egui::Rect>,
    controls: ControlRects,
}

impl Overlay {
    /// An overlay drawing onto `color_format` images, with `frames_in_flight` frames recorded
    /// before the oldest is waited for.
    pub fn new(gpu: &Gpu, color_format: vk::Format, frames_in_flight: usize) -> Result<Overlay> {
        let srgb = matches!(color_format, vk::Format::R8G8B8A8_SRGB | vk::Format::B8G8R8A8_SRGB | vk::Format::A8B8G8R8_SRGB_PACK32);
        let mode = RenderMode::DynamicRendering(DynamicRendering {
            color_attachment_format: color_format,
            depth_attachment_format: None,
            stencil_attachment_format: None,
        });
        let options = Options {
            in_flight_frames: frames_in_flight,
            enable_depth_test: false,
            enable_depth_write: false,
            srgb_framebuffer: srgb,
        };
        let painter = egui_ash_renderer::Renderer::with_gpu_allocator((*gpu.allocator).clone(), gpu.device.clone(), mode, options).map_err(|e| anyhow!("creating the overlay renderer: {e}"))?;
        let upload_pool = unsafe {
            gpu.device.create_command_pool(
                &vk::CommandPoolCreateInfo::default()
                    .queue_family_index(gpu.queue_family)
                    .flags(vk::CommandPoolCreateFlags::TRANSIENT | vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER),
                None,
            )?
        };
        let ctx = egui::Context::default();
        ctx.set_theme(egui::Theme::Dark);
        ctx.set_visuals_of(egui::Theme::Dark, overlay_visuals());
        ctx.all_styles_mut(|s| {
            s.animation_time = 0.0;
            // Text never wraps: wrapping depends on last frame's column widths, so rows could
            // change height from frame to frame and move the controls under the pointer.
            s.wrap_mode = Some(egui::TextWrapMode::Extend);
        });
        Ok(Overlay {
            ctx,
            painter,
            upload_pool,
            visible: true,
            history: FrameHistory::default(),
            last: FrameStats::default(),
            prepared: None,
            pending_free: Vec::new(),
            window_rect: None,
            controls: Vec::new(),
        })
    }

    pub fn context(&self) -> &egui::Context {
        &self.ctx
    }

    /// Record a finished frame: its CPU frame time and what the GPU measured.
    pub fn push_frame(&mut self, cpu_ms: f64, gpu_ms: Option<f64>, stats: FrameStats) {
        self.history.cpu_ms.push(cpu_ms);
        if let Some(g) = gpu_ms.or(stats.gpu_ms()) {
            self.history.gpu_ms.push(g);
        }
        self.last = stats;
    }

    /// Lay out this frame's UI for `input`: the renderer's panel, then `extra` panels. Call after
    /// `Renderer::record`, so the counters are this frame's; switches flipped here take effect
    /// from the next frame. Returns what egui asks of the platform (cursor, clipboard).
    pub fn build(&mut self, input: egui::RawInput, renderer: &mut Renderer, extra: &mut [&mut dyn Panel]) -> egui::PlatformOutput {
        if !self.visible {
            // Nothing to draw; texture changes not yet recorded still go up with the next record.
            if let Some(p) = self.prepared.as_mut() {
                p.primitives.clear();
            }
            return egui::PlatformOutput::default();
        }
        self.controls.clear();
        let mut window_rect = None;
        let (history, last, controls) = (&self.history, &self.last, &mut self.controls);
        let output = self.ctx.run_ui(input, |ui| {
            // A discarded pass starts over: keep only the rects of the pass that is drawn.
            controls.clear();
            let ctx = ui.ctx().clone();
            // Never taller than the frame: the panels scroll inside it (the title bar and margins
            // take the rest).
            let max_height = (ui.available_rect_before_wrap().height() - 48.0).max(100.0);
            let shown = egui::Window::new("engine").default_pos([8.0, 8.0]).default_width(330.0).resizable(false).show(&ctx, |ui| {
                egui::ScrollArea::vertical().max_height(max_height).show(ui, |ui| {
                    let mut own = RendererPanel {
                        renderer: &mut *renderer,
                        history,
                        last,
                        controls: &mut *controls,
                    };
                    show_panel(ui, &mut own, true);
                    show_panel(ui, &mut PassesPanel { renderer: &*renderer, last }, false);
                    for panel in extra.iter_mut() {
                        show_panel(ui, &mut **panel, false);
                    }
                });
            });
            window_rect = shown.map(|s| s.response.rect);
        });
        self.window_rect = window_rect;
        let primitives = self.ctx.tessellate(output.shapes, output.pixels_per_point);
        // Deltas of a frame that was built but never recorded still have to reach the GPU.
        let mut textures = self.prepared.take().map(|p| p.textures).unwrap_or_default();
        textures.append(output.textures_delta);
        self.prepared = Some(Prepared {
            primitives,
            textures,
            pixels_per_point: output.pixels_per_point,
        });
        output.platform_output
    }

    /// Upload texture changes, with the device idle: egui-ash-renderer writes them without
    /// waiting for frames in flight.
    fn upload_textures(&mut self, gpu: &Gpu, textures: &mut egui::TexturesDelta) -> Result<()> {
        if !textures.set.is_empty() || !self.pending_free.is_empty() {
            gpu.wait_idle();
            for id in self.pending_free.drain(..) {
                self.painter.free_texture(id).map_err(|e| anyhow!("overlay: freeing a texture: {e}"))?;
            }
            for (id, deltas) in textures.set.drain() {
                for delta in deltas {
                    self.painter.set_texture(gpu.queue, self.upload_pool, id, &delta).map_err(|e| anyhow!("overlay: uploading a texture: {e}"))?;
                }
            }
        }
        self.pending_free.extend(textures.free.drain());
        Ok(())
    }

    /// The overlay window's rectangle in pixels (left, top, right, bottom; may reach past the
    /// image) as last built; None when hidden.
    pub fn window_rect_px(&self) -> Option<[f32; 4]> {
        let ppp = self.ctx.pixels_per_point();
        self.window_rect.filter(|_| self.visible).map(|r| [r.min.x * ppp, r.min.y * ppp, r.max.x * ppp, r.max.y * ppp])
    }

    /// The centre of the control labelled `name` (see `RendererPanel`), in points, as last built.
    pub fn control_centre(&self, name: &str) -> Option<egui::Pos2> {
        self.controls.iter().find(|(n, _)| *n == name).map(|(_, r)| r.center())
    }

    /// What the overlay of a lost device showed: whether it is shown and its frame history.
    pub fn carry_on_from(&mut self, old: &mut Overlay) {
        self.visible = old.visible;
        std::mem::swap(&mut self.history, &mut old.history);
        std::mem::swap(&mut self.last, &mut old.last);
    }

    /// Destroy the GPU objects; the device must be idle. Consumes the overlay, so its clone of the
    /// allocator is gone before the `Gpu` drops.
    pub fn destroy(self, gpu: &Gpu) {
        let Overlay { painter, upload_pool, .. } = self;
        // egui-ash-renderer frees its buffers, textures and pipeline on drop.
        drop(painter);
        unsafe { gpu.device.destroy_command_pool(upload_pool, None) };
    }
}

/// Input for one headless frame: a `width` x `height` pixel screen at 1 pixel per point, at
/// `time_s` (a fixed step keeps frames reproducible), with scripted `events`.
pub fn headless_input(width: u32, height: u32, time_s: f64, events: Vec<egui::Event>) -> egui::RawInput {
    egui::RawInput {
        screen_rect: Some(egui::Rect::from_min_size(egui::Pos2::ZERO, egui::vec2(width as f32, height as f32))),
        time: Some(time_s),
        events,
        ..Default::default()
    }
}

fn show_panel(ui: &mut egui::Ui, panel: &mut dyn Panel, open: bool) {
    let title = panel.title().to_string();
    egui::CollapsingHeader::new(title).default_open(open || panel.default_open()).show(ui, |ui| panel.ui(ui));
}

/// Dark and without shadows, so nothing is drawn outside the window's rectangle.
fn overlay_visuals() -> egui::Visuals {
    let mut v = egui::Visuals::dark();
    v.window_shadow = egui::Shadow::NONE;
    v.popup_shadow = egui::Shadow::NONE;
    // Nearly opaque and light text: blending happens in linear light on the sRGB targets, which
    // makes a translucent dark fill look much thinner than egui's gamma-space design intends.
    v.window_fill = egui::Color32::from_rgba_unmultiplied(16, 18, 22, 242);
    v.override_text_color = Some(egui::Color32::from_gray(225));
    // An unchecked box must stand out from the fill.
    v.widgets.inactive.bg_stroke = egui::Stroke::new(1.0, egui::Color32::from_gray(150));
    v
}

/// The overlay is the frame's last drawing pass (the caller adds it to `Renderer::record_prepared`):
/// it loads the output and draws the built UI over it.
impl Pass for Overlay {
    fn name(&self) -> &'static str {
        "overlay"
    }

    fn declare(&mut self, _cx: &FrameCx, io: &mut Io) {
        if let Some(p) = &self.prepared {
            // Texture uploads happen even in a frame with nothing to draw.
            io.side_effects();
            if !p.primitives.is_empty() {
                io.uses(OUTPUT, Access::ColorBlend);
            }
        }
    }

    fn record(&mut self, _cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        let Some(mut p) = self.prepared.take() else { return Ok(()) };
        self.upload_textures(rec.gpu, &mut p.textures)?;
        if p.primitives.is_empty() {
            return Ok(());
        }
        let cb = rec.cb;
        let target = rec.image(OUTPUT);
        rec.begin_rendering(&Rendering::color(target, None));
        let drawn = self.painter.cmd_draw(cb, target.extent, p.pixels_per_point, &p.primitives);
        rec.end_rendering();
        drawn.map_err(|e| anyhow!("overlay: recording the UI: {e}"))
    }
}
