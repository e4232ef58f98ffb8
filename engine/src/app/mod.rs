//! The windowed front end a game runs in: a winit window, the Vulkan surface and swapchain
//! (`swapchain`), frames in flight, the renderer and its scene, and the debug overlay (egui-winit
//! feeds it input; F1 shows or hides it). What the keys and the mouse do, the camera and the
//! world are the game's (`game::Game`; the demo's is `src/bin/demo/game.rs`).

pub mod game;
pub mod headless;
pub mod recovery;
pub(crate) mod swapchain;

pub use game::{Cx, Game, Input};

use crate::gpu::{Gpu, GpuOptions};
use recovery::LossPolicy;
use crate::ui::{FrameStats, Overlay};
use crate::render::graph::{Access, Pass, OUTPUT};
use crate::render::renderer::{FrameTarget, Renderer};
use crate::scene::GpuScene;
use anyhow::{anyhow, Context, Result};
use ash::vk;
use raw_window_handle::{HasDisplayHandle, HasWindowHandle};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;
use swapchain::{Frames, Swapchain};
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, MouseButton, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

pub const FRAMES_IN_FLIGHT: usize = 2;
/// How long a frame waits for a swapchain image before it is skipped.
const ACQUIRE_TIMEOUT_NS: u64 = 1_000_000_000;

pub struct WindowOptions {
    pub gpu: GpuOptions,
    pub width: u32,
    pub height: u32,
    /// Close after this many presented frames (for tests); run until closed when `None`.
    pub max_frames: Option<u64>,
    /// Texels per side of the sun's shadow map.
    pub shadow_map_size: u32,
    /// Anti-aliasing from the first frame (the overlay switches it).
    pub aa: crate::render::renderer::AntiAliasing,
    /// How the 3D passes' resolution is chosen (the overlay shows the scale).
    pub render_scale: crate::render::scale::RenderScale,
    /// The upscaler's filter (None: the device kind's default).
    pub upscaler: Option<crate::render::scale::Upscaler>,
    pub title: String,
    /// Show the debug overlay from the first frame (F1 toggles it either way).
    pub overlay: bool,
}

/// What a finished windowed run reports.
pub struct WindowRun {
    pub frames: u64,
    pub validation_errors: usize,
    pub device_name: String,
}

/// Open a window showing `first` and run `game` in it until the window is closed (Esc, the
/// close button, Ctrl-C) or `max_frames` were presented.
pub fn run(first: &pack::Pack, opts: WindowOptions, game: &mut dyn Game) -> Result<WindowRun> {
    // Ctrl-C / SIGTERM close the window like the close button does, so the run still ends with
    // its summary and a clean Vulkan teardown.
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    if let Err(e) = ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst)) {
        eprintln!("demo: cannot install the Ctrl-C handler ({e}); closing the window still works");
    }
    let event_loop = EventLoop::new().map_err(|e| anyhow!("cannot open a window: {e}"))?;
    let mut app = App { first, opts, game, state: None, error: None, result: None, stop };
    event_loop.run_app(&mut app).map_err(|e| anyhow!("event loop: {e}"))?;
    if let Some(e) = app.error {
        return Err(e);
    }
    app.result.ok_or_else(|| anyhow!("the window closed before the first frame"))
}

struct App<'a> {
    first: &'a pack::Pack,
    opts: WindowOptions,
    game: &'a mut dyn Game,
    state: Option<State>,
    error: Option<anyhow::Error>,
    result: Option<WindowRun>,
    stop: Arc<AtomicBool>,
}

/// Everything that exists while the window is open. Field order is destruction order.
struct State {
    /// Taken by `destroy`; dropped before `gpu` in any case (field order).
    overlay: Option<Overlay>,
    egui: egui_winit::State,
    swapchain: Swapchain,
    renderer: Renderer,
    scene: GpuScene,
    frames: Frames,
    window: Arc<Window>,
    gpu: Gpu,
    input: Input,
    looking: bool,
    last_cursor: Option<(f64, f64)>,
    last_frame: Instant,
    presented: u64,
    /// The last change a key made and the first frame recorded with it, until the frames in
    /// flight after it have been presented (then it is logged as shown).
    announcing: Option<(String, u64)>,
    needs_resize: bool,
    /// Frames skipped because no swapchain image came back in time (reported once).
    skipped_acquires: u64,
    /// The device's options (with the window's surface extensions): a lost device's successor
    /// is made with them.
    gpu_opts: GpuOptions,
    /// Which device losses are survived (`recovery`).
    losses: LossPolicy,
}

impl ApplicationHandler for App<'_> {
    fn resumed(&mut self, el: &ActiveEventLoop) {
        if self.state.is_some() {
            return;
        }
        match State::new(el, self.first, &self.opts).and_then(|mut s| {
            self.game.start(&mut s.cx(), self.first)?;
            Ok(s)
        }) {
            Ok(s) => {
                println!("window: {}x{} on {}", s.swapchain.extent.width, s.swapchain.extent.height, s.gpu.caps.device_name);
                self.state = Some(s);
            }
            Err(e) => {
                self.error = Some(e);
                el.exit();
            }
        }
    }

    fn window_event(&mut self, el: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        let Some(s) = self.state.as_mut() else { return };
        // egui sees every event (it tracks the pointer and focus even while hidden); `consumed`
        // means the overlay is using it, so the game must not.
        let consumed = s.egui.on_window_event(&s.window, &event).consumed && s.overlay.as_ref().is_some_and(|o| o.visible);
        match event {
            WindowEvent::CloseRequested => el.exit(),
            WindowEvent::Resized(_) => s.needs_resize = true,
            WindowEvent::KeyboardInput { event, is_synthetic, .. } => {
                let PhysicalKey::Code(code) = event.physical_key else { return };
                if event.state != ElementState::Pressed {
                    // Releases always count, so no key sticks down.
                    s.input.keys.remove(&code);
                    return;
                }
                // winit makes up a press for every key held down when the window gains the
                // focus: the key is down (movement keys keep working), but nobody pressed it
                // here, so it switches nothing. Two fresh-clone test runs saw one F5 from
                // xdotool switch the lightmaps off and at once on again.
                if is_synthetic {
                    if !consumed {
                        s.input.keys.insert(code);
                    }
                    return;
                }
                if code == KeyCode::Escape {
                    el.exit();
                }
                if code == KeyCode::F1 && !event.repeat {
                    if let Some(o) = s.overlay.as_mut() {
                        o.visible = !o.visible;
                    }
                }
                if !event.repeat {
                    match self.game.key(&mut s.cx(), code) {
                        Ok(Some(what)) => {
                            println!("window: {what}");
                            s.announcing = Some((what, s.presented));
                        }
                        Ok(None) => {}
                        Err(e) => {
                            self.error = Some(e);
                            el.exit();
                            return;
                        }
                    }
                }
                if !consumed {
                    s.input.keys.insert(code);
                }
            }
            WindowEvent::MouseInput { state, button: MouseButton::Left | MouseButton::Right, .. } => {
                // A drag that starts on the overlay works the overlay.
                s.looking = state == ElementState::Pressed && !consumed;
                s.last_cursor = None;
            }
            WindowEvent::CursorMoved { position, .. } if s.looking => {
                if let Some((x, y)) = s.last_cursor {
                    s.input.look.0 += position.x - x;
                    s.input.look.1 += position.y - y;
                }
                s.last_cursor = Some((position.x, position.y));
            }
            WindowEvent::RedrawRequested => {
                let presented = s.presented;
                if let Err(e) = s.frame(&mut *self.game) {
                    // A lost device is made again from the pack on show (`recovery`); the next
                    // redraw draws the frame again, from the same game state.
                    let what = format!("{e:#}");
                    let start = Instant::now();
                    let pack = self.game.pack().unwrap_or(self.first);
                    if let Err(e) = s.losses.survive(e).and_then(|()| s.recover(pack)) {
                        self.error = Some(e);
                        el.exit();
                        return;
                    }
                    s.losses.recovered();
                    println!("window: device lost at frame {} ({what}); made again from the pack in {:.0} ms", s.presented, start.elapsed().as_secs_f64() * 1e3);
                    s.announcing = Some(("device made again".into(), s.presented));
                    return;
                }
                if s.presented > presented {
                    s.losses.frame_shown();
                }
                if s.presented == 10 {
                    println!("window: presented 10 frames");
                }
                // A change is on screen once the frame after the first one recorded with it has
                // been presented too (frames in flight are presented in order): scripts wait for
                // this line, not for a time, before they look at the screen.
                if let Some((what, frame)) = s.announcing.take_if(|(_, f)| s.presented >= *f + FRAMES_IN_FLIGHT as u64) {
                    println!("window: {what} shown (frame {frame})");
                }
                if self.opts.max_frames.is_some_and(|m| s.presented >= m) {
                    el.exit();
                }
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, el: &ActiveEventLoop) {
        if self.stop.load(Ordering::SeqCst) {
            el.exit();
            return;
        }
        if let Some(s) = &self.state {
            s.window.request_redraw();
        }
    }

    fn exiting(&mut self, _el: &ActiveEventLoop) {
        if let Some(mut s) = self.state.take() {
            s.gpu.wait_idle();
            self.result = Some(WindowRun { frames: s.presented, validation_errors: s.gpu.validation().error_count(), device_name: s.gpu.caps.device_name.clone() });
            s.destroy();
        }
    }
}

/// What the window has on `gpu`: a surface and swapchain for `window`, a renderer writing its
/// format with `pack`'s scene, the frames in flight and the overlay (hidden). On an error
/// nothing made is left behind. At start-up and after a device loss alike.
fn on_device(gpu: &Gpu, window: &Window, pack: &pack::Pack, shadow_map_size: u32) -> Result<(Swapchain, Renderer, GpuScene, Frames, Overlay)> {
    let display = window.display_handle().map_err(|e| anyhow!("display handle: {e}"))?.as_raw();
    let handle = window.window_handle().map_err(|e| anyhow!("window handle: {e}"))?.as_raw();
    let surface = unsafe { ash_window::create_surface(&gpu.entry, &gpu.instance, display, handle, None)? };
    let swapchain = gpu.own(Swapchain::new(gpu, surface, window.inner_size())?);
    let (renderer, scene) = recovery::renderer_and_scene(gpu, pack, swapchain.format, FRAMES_IN_FLIGHT, shadow_map_size)?;
    let (renderer, scene) = (gpu.own(renderer), gpu.own(scene));
    let frames = gpu.own(Frames::new(gpu)?);
    let overlay = Overlay::new(gpu, swapchain.format, FRAMES_IN_FLIGHT)?;
    Ok((swapchain.keep(), renderer.keep(), scene.keep(), frames.keep(), overlay))
}

impl State {
    fn new(el: &ActiveEventLoop, pack: &pack::Pack, opts: &WindowOptions) -> Result<State> {
        let attrs = Window::default_attributes().with_title(opts.title.clone()).with_inner_size(PhysicalSize::new(opts.width, opts.height));
        let window = Arc::new(el.create_window(attrs).context("creating the window")?);
        let display = window.display_handle().map_err(|e| anyhow!("display handle: {e}"))?.as_raw();
        let mut gpu_opts = opts.gpu.clone();
        gpu_opts.surface_extensions = ash_window::enumerate_required_extensions(display)?.to_vec();
        gpu_opts.surface_extensions.push(ash::khr::surface::NAME.as_ptr());
        gpu_opts.surface_extensions.dedup();
        let gpu = Gpu::new(&gpu_opts)?;
        if !gpu.swapchain_capable {
            return Err(anyhow!("{} cannot present to a window (no VK_KHR_swapchain)", gpu.caps.device_name));
        }
        let (swapchain, mut renderer, scene, frames, mut overlay) = on_device(&gpu, &window, pack, opts.shadow_map_size)?;
        renderer.aa = opts.aa;
        renderer.render_scale = crate::render::scale::ScaleController::new(opts.render_scale);
        if let Some(u) = opts.upscaler {
            renderer.upscaler = u;
        }
        overlay.visible = opts.overlay;
        let egui = egui_winit::State::new(overlay.context().clone(), egui::ViewportId::ROOT, &*window, Some(window.scale_factor() as f32), None, None);
        Ok(State {
            overlay: Some(overlay),
            egui,
            swapchain,
            renderer,
            scene,
            frames,
            window,
            gpu,
            gpu_opts,
            input: Input::default(),
            looking: false,
            last_cursor: None,
            last_frame: Instant::now(),
            presented: 0,
            announcing: None,
            needs_resize: false,
            skipped_acquires: 0,
            losses: LossPolicy::default(),
        })
    }

    /// After the device was lost (`recovery`): a new device, surface and swapchain for the same
    /// window, and `pack`'s scene made again on it, carrying on from this state (the renderer's
    /// settings, LODs, render scale and characters, the scene's instances, the overlay). The
    /// window's surface can have one swapchain: the lost device's goes first (a hung device's
    /// cannot; making the new one may then fail). On an error the old state stays, to be torn
    /// down.
    fn recover(&mut self, pack: &pack::Pack) -> Result<()> {
        let gpu = self.gpu.successor(&self.gpu_opts)?;
        if !self.gpu.hung() {
            self.gpu.wait_idle();
            self.swapchain.destroy(&self.gpu);
        }
        let (swapchain, mut renderer, mut scene, frames, mut overlay) = on_device(&gpu, &self.window, pack, self.renderer.shadow.size)?;
        renderer.carry_on_from(&mut self.renderer);
        scene.carry_on_from(&mut self.scene);
        if let Some(old) = self.overlay.as_mut() {
            overlay.carry_on_from(old);
        }
        self.egui = egui_winit::State::new(overlay.context().clone(), egui::ViewportId::ROOT, &*self.window, Some(self.window.scale_factor() as f32), None, None);
        let old = (
            std::mem::replace(&mut self.overlay, Some(overlay)),
            std::mem::replace(&mut self.frames, frames),
            std::mem::replace(&mut self.scene, scene),
            std::mem::replace(&mut self.renderer, renderer),
            std::mem::replace(&mut self.swapchain, swapchain),
        );
        let old_gpu = std::mem::replace(&mut self.gpu, gpu);
        recovery::retire(old_gpu, old, |gpu, (overlay, mut frames, mut scene, mut renderer, mut swapchain)| {
            if let Some(o) = overlay {
                o.destroy(gpu);
            }
            frames.destroy(gpu);
            scene.destroy(gpu);
            renderer.destroy(gpu);
            swapchain.destroy(gpu);
        });
        self.needs_resize = false;
        Ok(())
    }

    fn cx(&mut self) -> Cx<'_> {
        Cx { gpu: &self.gpu, renderer: &mut self.renderer, scene: &mut self.scene, frames_in_flight: FRAMES_IN_FLIGHT }
    }

    fn frame(&mut self, game: &mut dyn Game) -> Result<()> {
        self.gpu.alive("a frame")?;
        let now = Instant::now();
        let frame_ms = (now - self.last_frame).as_secs_f64() * 1e3;
        let dt = (now - self.last_frame).as_secs_f32().min(0.1);
        self.last_frame = now;
        let mut cx = Cx { gpu: &self.gpu, renderer: &mut self.renderer, scene: &mut self.scene, frames_in_flight: FRAMES_IN_FLIGHT };
        game.update(&mut cx, &self.input, dt);
        self.input.look = (0.0, 0.0);
        self.renderer.animate(&mut self.scene, dt);
        if self.needs_resize {
            self.swapchain.recreate(&self.gpu, self.window.inner_size())?;
            self.needs_resize = false;
            let what = format!("swapchain rebuilt at {}x{}", self.swapchain.extent.width, self.swapchain.extent.height);
            println!("window: {what}");
            // Scripts wait for "... shown" before they look at the new size.
            self.announcing = Some((what, self.presented));
        }
        if self.swapchain.extent.width == 0 || self.swapchain.extent.height == 0 {
            return Ok(()); // minimised
        }
        let d = &self.gpu.device;
        let slot = (self.presented % FRAMES_IN_FLIGHT as u64) as usize;
        let (cb, fence, acquired) = (self.frames.cbs[slot], self.frames.fences[slot], self.frames.acquired[slot]);
        self.gpu.wait_fence(fence, "a frame")?;
        // The frame this slot last held is finished: its GPU measurements are readable (before
        // the slot's first use there is nothing to read).
        if let Some(o) = self.overlay.as_mut().filter(|_| self.presented >= FRAMES_IN_FLIGHT as u64) {
            o.push_frame(frame_ms, None, FrameStats::read(&self.gpu, &self.renderer, slot));
        }
        // Bounded: a present engine that holds every image (a hidden window under some
        // compositors, a stalled one) skips this frame and keeps the event loop answering,
        // instead of blocking it until the image comes back; the next redraw tries again.
        let image_index = match unsafe { self.swapchain.loader.acquire_next_image(self.swapchain.swapchain, ACQUIRE_TIMEOUT_NS, acquired, vk::Fence::null()) } {
            Ok((i, _)) => i,
            Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => {
                self.needs_resize = true;
                return Ok(());
            }
            Err(vk::Result::TIMEOUT | vk::Result::NOT_READY) => {
                self.skipped_acquires += 1;
                if self.skipped_acquires == 1 {
                    println!("window: no swapchain image within {} ms; skipping frames until one is free", ACQUIRE_TIMEOUT_NS / 1_000_000);
                }
                return Ok(());
            }
            Err(e) => return Err(anyhow!("acquiring a swapchain image: {e}")),
        };
        let i = image_index as usize;
        let target = FrameTarget { color_image: self.swapchain.images[i], color_view: self.swapchain.views[i], extent: self.swapchain.extent };
        unsafe {
            d.reset_fences(&[fence])?;
            d.reset_command_buffer(cb, vk::CommandBufferResetFlags::empty())?;
            d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT))?;
        }
        self.renderer.prepare(&self.gpu, slot, &self.scene, &game.camera(), &game.lighting(), target.extent)?;
        // Taken every frame, shown or not, so input does not pile up while the overlay is hidden.
        let input = self.egui.take_egui_input(&self.window);
        let mut extra: Vec<&mut dyn Pass> = Vec::new();
        if let Some(o) = self.overlay.as_mut().filter(|o| o.visible) {
            // Slider edits land in the game now and take effect from its next step.
            let (renderer, mut input) = (&mut self.renderer, Some(input));
            let mut platform = None;
            game.panels(&mut |panels| platform = input.take().map(|i| o.build(i, renderer, panels)));
            if let Some(platform) = platform {
                self.egui.handle_platform_output(&self.window, platform);
            }
            extra.push(o);
        }
        self.renderer.record_prepared(&self.gpu, cb, slot, &self.scene, &target, &mut extra, &[(OUTPUT, Access::Present)])?;
        let rendered = self.swapchain.rendered[i];
        unsafe {
            d.end_command_buffer(cb)?;
            let waits = [vk::SemaphoreSubmitInfo::default().semaphore(acquired).stage_mask(vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT)];
            let signals = [vk::SemaphoreSubmitInfo::default().semaphore(rendered).stage_mask(vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT)];
            let cbs = [vk::CommandBufferSubmitInfo::default().command_buffer(cb)];
            let submit = [vk::SubmitInfo2::default().wait_semaphore_infos(&waits).command_buffer_infos(&cbs).signal_semaphore_infos(&signals)];
            self.gpu.submit_frame(&submit, fence)?;
            let swapchains = [self.swapchain.swapchain];
            let indices = [image_index];
            let wait = [rendered];
            let present = vk::PresentInfoKHR::default().wait_semaphores(&wait).swapchains(&swapchains).image_indices(&indices);
            match self.swapchain.loader.queue_present(self.gpu.queue, &present) {
                Ok(false) => {}
                Ok(true) | Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => self.needs_resize = true,
                Err(e) => return Err(anyhow!("presenting: {e}")),
            }
        }
        self.presented += 1;
        Ok(())
    }

    fn destroy(&mut self) {
        self.gpu.wait_idle();
        if let Some(o) = self.overlay.take() {
            o.destroy(&self.gpu);
        }
        self.frames.destroy(&self.gpu);
        self.scene.destroy(&self.gpu);
        self.renderer.destroy(&self.gpu);
        self.swapchain.destroy(&self.gpu);
    }
}
