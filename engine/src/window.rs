//! The windowed front end: winit window, Vulkan surface and swapchain, fly and walk camera
//! input, feature switches on the function keys, scene switching, and the debug overlay
//! (egui-winit feeds it input; F1 shows or hides it).

use crate::camera::Camera;
use crate::gpu::{full_range, Gpu, GpuOptions};
use crate::render::graph::{Access, Pass, OUTPUT};
use crate::overlay::{FrameStats, Overlay, SimPanel};
use crate::renderer::{FrameTarget, Lighting, Renderer};
use crate::sim::World;
use crate::sim_level;
use crate::scene::GpuScene;
use crate::walk::WalkMesh;
use anyhow::{anyhow, Context, Result};
use ash::vk;
use glam::Vec3;
use raw_window_handle::{HasDisplayHandle, HasWindowHandle};
use std::collections::HashSet;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, MouseButton, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

const FRAMES_IN_FLIGHT: usize = 2;
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

/// The keys, as `demo --help` and the README list them.
pub const KEYS: &str = "WASD move, Q/E down/up, Shift faster, drag with a mouse button to look, Esc quits;
F1 overlay, F2 depth pre-pass, F3 frustum culling, F4 LOD selection, F5 lightmaps (off: probes
and sun light the static geometry too), F6 walk mode (on the level's floors at eye height, up
steps, stopped by walls, at the player spawn's speed), Tab next scene (when several packs were given).";

/// Open a window and render `packs[0]` until it is closed (or `max_frames` is reached); Tab
/// switches to the next pack.
pub fn run(packs: &[pack::Pack], opts: WindowOptions) -> Result<WindowRun> {
    let pack = packs.first().ok_or_else(|| anyhow!("no pack to show"))?;
    // Ctrl-C / SIGTERM close the window like the close button does, so the run still ends with
    // its summary and a clean Vulkan teardown.
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    if let Err(e) = ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst)) {
        eprintln!("demo: cannot install the Ctrl-C handler ({e}); closing the window still works");
    }
    let event_loop = EventLoop::new().map_err(|e| anyhow!("cannot open a window: {e}"))?;
    let mut app = App { packs, current: 0, opts, state: None, error: None, result: None, stop };
    let _ = pack;
    event_loop.run_app(&mut app).map_err(|e| anyhow!("event loop: {e}"))?;
    if let Some(e) = app.error {
        return Err(e);
    }
    app.result.ok_or_else(|| anyhow!("the window closed before the first frame"))
}

struct App<'a> {
    packs: &'a [pack::Pack],
    /// The pack on screen.
    current: usize,
    opts: WindowOptions,
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
    camera: Camera,
    lighting: Lighting,
    keys: HashSet<KeyCode>,
    /// Walk mode: the eye's height above the feet (None: flying).
    walk: Option<f32>,
    /// What walking stands on and bumps into: the level's static triangles.
    walk_mesh: WalkMesh,
    /// Where the feet go where no floor is under the camera, and the walking speed: from the
    /// player spawn.
    ground: f32,
    walk_speed: f32,
    looking: bool,
    last_cursor: Option<(f64, f64)>,
    last_frame: Instant,
    /// The level's particles and flocks, stepped on the fixed clock by each frame's duration.
    world: World,
    presented: u64,
    /// The last switch (`toggle`, a scene change) and the first frame recorded with it, until the
    /// frames in flight after it have been presented (then it is logged as shown).
    announcing: Option<(String, u64)>,
    needs_resize: bool,
    /// Frames skipped because no swapchain image came back in time (reported once).
    skipped_acquires: u64,
}

impl ApplicationHandler for App<'_> {
    fn resumed(&mut self, el: &ActiveEventLoop) {
        if self.state.is_some() {
            return;
        }
        match State::new(el, &self.packs[self.current], &self.opts) {
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
        // means the overlay is using it, so the camera must not.
        let consumed = s.egui.on_window_event(&s.window, &event).consumed && s.overlay.as_ref().is_some_and(|o| o.visible);
        match event {
            WindowEvent::CloseRequested => el.exit(),
            WindowEvent::Resized(_) => s.needs_resize = true,
            WindowEvent::KeyboardInput { event, .. } => {
                if let PhysicalKey::Code(code) = event.physical_key {
                    if event.state == ElementState::Pressed {
                        if code == KeyCode::Escape {
                            el.exit();
                        }
                        if code == KeyCode::F1 && !event.repeat {
                            if let Some(o) = s.overlay.as_mut() {
                                o.visible = !o.visible;
                            }
                        }
                        if !event.repeat {
                            if let Some(what) = s.toggle(code) {
                                println!("window: {what}");
                                s.announce(what);
                            }
                        }
                        if code == KeyCode::Tab && !event.repeat && self.packs.len() > 1 {
                            self.current = (self.current + 1) % self.packs.len();
                            if let Err(e) = s.load_scene(&self.packs[self.current]) {
                                self.error = Some(e);
                                el.exit();
                                return;
                            }
                            let what = format!("scene {} of {}", self.current + 1, self.packs.len());
                            println!("window: {what}");
                            s.announce(what);
                        }
                        if !consumed {
                            s.keys.insert(code);
                        }
                    } else {
                        // Releases always count, so no key sticks down.
                        s.keys.remove(&code);
                    }
                }
            }
            WindowEvent::MouseInput { state, button: MouseButton::Left | MouseButton::Right, .. } => {
                // A drag that starts on the overlay works the overlay.
                s.looking = state == ElementState::Pressed && !consumed;
                s.last_cursor = None;
            }
            WindowEvent::CursorMoved { position, .. } => {
                if s.looking {
                    if let Some((x, y)) = s.last_cursor {
                        let sensitivity = 0.004;
                        s.camera.rotate(-(position.x - x) as f32 * sensitivity, -(position.y - y) as f32 * sensitivity);
                    }
                    s.last_cursor = Some((position.x, position.y));
                }
            }
            WindowEvent::RedrawRequested => {
                match s.frame() {
                    Ok(()) => {}
                    Err(e) => {
                        self.error = Some(e);
                        el.exit();
                        return;
                    }
                }
                if s.presented == 10 {
                    println!("window: presented 10 frames");
                }
                // A switch is on screen once the frame after the first one recorded with it has
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
            self.result = Some(WindowRun {
                frames: s.presented,
                validation_errors: s.gpu.validation().error_count(),
                device_name: s.gpu.caps.device_name.clone(),
            });
            s.destroy();
        }
    }
}

impl State {
    fn new(el: &ActiveEventLoop, pack: &pack::Pack, opts: &WindowOptions) -> Result<State> {
        let attrs = Window::default_attributes()
            .with_title(opts.title.clone())
            .with_inner_size(PhysicalSize::new(opts.width, opts.height));
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
        let surface = unsafe {
            ash_window::create_surface(
                &gpu.entry,
                &gpu.instance,
                display,
                window.window_handle().map_err(|e| anyhow!("window handle: {e}"))?.as_raw(),
                None,
            )?
        };
        let swapchain = Swapchain::new(&gpu, surface, window.inner_size())?;
        let mut renderer = Renderer::new(&gpu, swapchain.format, FRAMES_IN_FLIGHT)?;
        let scene = match renderer.set_shadow_map_size(&gpu, opts.shadow_map_size).and_then(|_| GpuScene::upload(&gpu, pack, renderer.layouts())) {
            Ok(s) => s,
            Err(e) => {
                renderer.destroy(&gpu);
                return Err(e);
            }
        };
        renderer.animation = match engine_animated(&gpu, pack, &scene) {
            Ok(a) => a,
            Err(e) => {
                renderer.destroy(&gpu);
                return Err(e);
            }
        };
        let mut overlay = Overlay::new(&gpu, swapchain.format, FRAMES_IN_FLIGHT)?;
        overlay.visible = opts.overlay;
        let egui = egui_winit::State::new(overlay.context().clone(), egui::ViewportId::ROOT, &*window, Some(window.scale_factor() as f32), None, None);
        let (min, max) = scene.bounds();
        let mut world = sim_level::world_from_spawns(&pack.manifest.spawns, &pack.manifest.pillars, min, max);
        sim_level::warm_up(&mut world);
        let frames = Frames::new(&gpu)?;
        Ok(State {
            overlay: Some(overlay),
            egui,
            swapchain,
            renderer,
            scene,
            frames,
            window,
            gpu,
            camera: Camera::for_pack(&pack.manifest, min, max),
            lighting: Lighting::for_pack(&pack.manifest),
            keys: HashSet::new(),
            walk: None,
            walk_mesh: WalkMesh::from_pack(pack),
            ground: ground_height(&pack.manifest, min),
            walk_speed: walk_speed(&pack.manifest),
            looking: false,
            last_cursor: None,
            last_frame: Instant::now(),
            world,
            presented: 0,
            announcing: None,
            needs_resize: false,
            skipped_acquires: 0,
        })
    }

    /// WASD to move, Q/E down/up, Shift to go faster; drag with a mouse button to look. Walking,
    /// the feet follow the level's floors (up steps, down drops), walls stop them, the eye stays
    /// at its height above them and Q/E do nothing.
    fn update_camera(&mut self, dt: f32) {
        let (min, max) = self.scene.bounds();
        let mut speed = if self.walk.is_some() { self.walk_speed } else { ((max - min).length() * 0.4).max(1.0) };
        if self.keys.contains(&KeyCode::ShiftLeft) || self.keys.contains(&KeyCode::ShiftRight) {
            speed *= if self.walk.is_some() { 2.0 } else { 4.0 };
        }
        let axis = |pos: KeyCode, neg: KeyCode| (self.keys.contains(&pos) as i32 - self.keys.contains(&neg) as i32) as f32;
        let local = Vec3::new(axis(KeyCode::KeyD, KeyCode::KeyA), axis(KeyCode::KeyE, KeyCode::KeyQ), axis(KeyCode::KeyW, KeyCode::KeyS));
        match self.walk {
            Some(eye) => {
                let feet = self.walk_mesh.step(self.camera.position - Vec3::Y * eye, self.camera.walk_delta(local * speed * dt));
                self.camera.position = feet + Vec3::Y * eye;
            }
            None => self.camera.translate_local(local * speed * dt),
        }
    }

    /// Log `what` as shown once it has reached the screen (see `announcing`): the next frame
    /// recorded is the first with it.
    fn announce(&mut self, what: String) {
        self.announcing = Some((what, self.presented));
    }

    /// Flip the switch on function key `code`; what it is now, for the log.
    fn toggle(&mut self, code: KeyCode) -> Option<String> {
        let on_off = |b: bool| if b { "on" } else { "off" };
        let r = &mut self.renderer;
        Some(match code {
            KeyCode::F2 => {
                r.prepass = !r.prepass;
                format!("depth pre-pass {}", on_off(r.prepass))
            }
            KeyCode::F3 => {
                r.visibility.culling = !r.visibility.culling;
                format!("frustum culling {}", on_off(r.visibility.culling))
            }
            KeyCode::F4 => {
                r.visibility.lod_selection = !r.visibility.lod_selection;
                format!("LOD selection {}", on_off(r.visibility.lod_selection))
            }
            KeyCode::F5 => {
                r.lightmaps = !r.lightmaps;
                format!("lightmaps {}", on_off(r.lightmaps))
            }
            KeyCode::F6 => {
                self.walk = match self.walk {
                    Some(_) => None,
                    None => Some(crate::camera::EYE_HEIGHT_M),
                };
                self.land();
                format!("walk mode {}", on_off(self.walk.is_some()))
            }
            _ => return None,
        })
    }

    /// Replace the scene with `pack`'s: its meshes, characters, particles and flocks, and a
    /// camera at its player spawn. The switches and the overlay stay as they are.
    fn load_scene(&mut self, pack: &pack::Pack) -> Result<()> {
        self.gpu.wait_idle();
        if let Some(mut a) = self.renderer.animation.take() {
            a.destroy(&self.gpu);
        }
        let scene = GpuScene::upload(&self.gpu, pack, self.renderer.layouts())?;
        self.scene.destroy(&self.gpu);
        self.scene = scene;
        self.renderer.animation = engine_animated(&self.gpu, pack, &self.scene)?;
        let (min, max) = self.scene.bounds();
        self.world = sim_level::world_from_spawns(&pack.manifest.spawns, &pack.manifest.pillars, min, max);
        sim_level::warm_up(&mut self.world);
        self.camera = Camera::for_pack(&pack.manifest, min, max);
        self.lighting = Lighting::for_pack(&pack.manifest);
        self.walk_mesh = WalkMesh::from_pack(pack);
        self.ground = ground_height(&pack.manifest, min);
        self.walk_speed = walk_speed(&pack.manifest);
        self.land();
        Ok(())
    }

    /// Walking, put the feet on the floor under the camera (the spawn's height where there is
    /// none) and the eye above them.
    fn land(&mut self) {
        if let Some(eye) = self.walk {
            let p = self.camera.position;
            let floor = self.walk_mesh.floor(glam::Vec2::new(p.x, p.z), p.y).unwrap_or(self.ground);
            self.camera.position.y = floor + eye;
        }
    }

    fn frame(&mut self) -> Result<()> {
        self.gpu.alive("a frame")?;
        let now = Instant::now();
        let frame_ms = (now - self.last_frame).as_secs_f64() * 1e3;
        let dt = (now - self.last_frame).as_secs_f32().min(0.1);
        self.last_frame = now;
        self.update_camera(dt);
        self.renderer.animate(&mut self.scene, dt);
        self.world.update(dt as f64);
        if self.needs_resize {
            self.swapchain.recreate(&self.gpu, self.window.inner_size())?;
            self.needs_resize = false;
            println!("window: swapchain rebuilt at {}x{}", self.swapchain.extent.width, self.swapchain.extent.height);
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
        let image_index = match unsafe {
            self.swapchain.loader.acquire_next_image(self.swapchain.swapchain, ACQUIRE_TIMEOUT_NS, acquired, vk::Fence::null())
        } {
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
        let target = FrameTarget {
            color_image: self.swapchain.images[i],
            color_view: self.swapchain.views[i],
            extent: self.swapchain.extent,
        };
        unsafe {
            d.reset_fences(&[fence])?;
            d.reset_command_buffer(cb, vk::CommandBufferResetFlags::empty())?;
            d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT))?;
        }
        sim_level::prepare_frame(&self.world, &mut self.renderer, &self.camera);
        self.renderer.prepare(&self.gpu, slot, &self.scene, &self.camera, &self.lighting, target.extent)?;
        // Taken every frame, shown or not, so input does not pile up while the overlay is hidden.
        let input = self.egui.take_egui_input(&self.window);
        let mut extra: Vec<&mut dyn Pass> = Vec::new();
        if let Some(o) = self.overlay.as_mut().filter(|o| o.visible) {
            // Slider edits land in the world now and take effect from its next step.
            let platform = o.build(input, &mut self.renderer, &mut [&mut SimPanel::new(&mut self.world)]);
            self.egui.handle_platform_output(&self.window, platform);
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
            d.queue_submit2(self.gpu.queue, &submit, fence)?;
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

/// Per-frame-in-flight command buffers and synchronisation.
struct Frames {
    pool: vk::CommandPool,
    cbs: Vec<vk::CommandBuffer>,
    fences: Vec<vk::Fence>,
    acquired: Vec<vk::Semaphore>,
}

impl Frames {
    fn new(gpu: &Gpu) -> Result<Frames> {
        let d = &gpu.device;
        unsafe {
            let pool = d.create_command_pool(
                &vk::CommandPoolCreateInfo::default()
                    .queue_family_index(gpu.queue_family)
                    .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER),
                None,
            )?;
            let cbs = d.allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default().command_pool(pool).command_buffer_count(FRAMES_IN_FLIGHT as u32),
            )?;
            let mut fences = Vec::new();
            let mut acquired = Vec::new();
            for _ in 0..FRAMES_IN_FLIGHT {
                fences.push(d.create_fence(&vk::FenceCreateInfo::default().flags(vk::FenceCreateFlags::SIGNALED), None)?);
                acquired.push(d.create_semaphore(&vk::SemaphoreCreateInfo::default(), None)?);
            }
            Ok(Frames { pool, cbs, fences, acquired })
        }
    }

    fn destroy(&mut self, gpu: &Gpu) {
        unsafe {
            for &f in &self.fences {
                gpu.device.destroy_fence(f, None);
            }
            for &s in &self.acquired {
                gpu.device.destroy_semaphore(s, None);
            }
            gpu.device.destroy_command_pool(self.pool, None);
        }
    }
}

struct Swapchain {
    surface_loader: ash::khr::surface::Instance,
    loader: ash::khr::swapchain::Device,
    surface: vk::SurfaceKHR,
    swapchain: vk::SwapchainKHR,
    format: vk::Format,
    color_space: vk::ColorSpaceKHR,
    extent: vk::Extent2D,
    images: Vec<vk::Image>,
    views: Vec<vk::ImageView>,
    /// One "rendering finished" semaphore per swapchain image: presentation holds it until that
    /// image is acquired again, so it cannot be shared across frames in flight.
    rendered: Vec<vk::Semaphore>,
}

impl Swapchain {
    fn new(gpu: &Gpu, surface: vk::SurfaceKHR, size: PhysicalSize<u32>) -> Result<Swapchain> {
        let surface_loader = ash::khr::surface::Instance::new(&gpu.entry, &gpu.instance);
        let supported = unsafe { surface_loader.get_physical_device_surface_support(gpu.physical_device, gpu.queue_family, surface)? };
        if !supported {
            return Err(anyhow!("{} cannot present to this window's surface", gpu.caps.device_name));
        }
        let formats = unsafe { surface_loader.get_physical_device_surface_formats(gpu.physical_device, surface)? };
        let format = formats
            .iter()
            .find(|f| {
                matches!(f.format, vk::Format::B8G8R8A8_SRGB | vk::Format::R8G8B8A8_SRGB)
                    && f.color_space == vk::ColorSpaceKHR::SRGB_NONLINEAR
            })
            .or(formats.first())
            .copied()
            .ok_or_else(|| anyhow!("the surface offers no formats"))?;
        let loader = ash::khr::swapchain::Device::new(&gpu.instance, &gpu.device);
        let mut sc = Swapchain {
            surface_loader,
            loader,
            surface,
            swapchain: vk::SwapchainKHR::null(),
            format: format.format,
            color_space: format.color_space,
            extent: vk::Extent2D::default(),
            images: vec![],
            views: vec![],
            rendered: vec![],
        };
        sc.build(gpu, size)?;
        Ok(sc)
    }

    fn build(&mut self, gpu: &Gpu, size: PhysicalSize<u32>) -> Result<()> {
        let caps = unsafe { self.surface_loader.get_physical_device_surface_capabilities(gpu.physical_device, self.surface)? };
        self.extent = if caps.current_extent.width != u32::MAX {
            caps.current_extent
        } else {
            vk::Extent2D {
                width: size.width.clamp(caps.min_image_extent.width, caps.max_image_extent.width),
                height: size.height.clamp(caps.min_image_extent.height, caps.max_image_extent.height),
            }
        };
        if self.extent.width == 0 || self.extent.height == 0 {
            return Ok(());
        }
        let mut count = caps.min_image_count + 1;
        if caps.max_image_count > 0 {
            count = count.min(caps.max_image_count);
        }
        let old = self.swapchain;
        let info = vk::SwapchainCreateInfoKHR::default()
            .surface(self.surface)
            .min_image_count(count)
            .image_format(self.format)
            .image_color_space(self.color_space)
            .image_extent(self.extent)
            .image_array_layers(1)
            .image_usage(vk::ImageUsageFlags::COLOR_ATTACHMENT)
            .image_sharing_mode(vk::SharingMode::EXCLUSIVE)
            .pre_transform(caps.current_transform)
            .composite_alpha(vk::CompositeAlphaFlagsKHR::OPAQUE)
            .present_mode(vk::PresentModeKHR::FIFO)
            .clipped(true)
            .old_swapchain(old);
        self.swapchain = unsafe { self.loader.create_swapchain(&info, None)? };
        self.destroy_images(gpu);
        if old != vk::SwapchainKHR::null() {
            unsafe { self.loader.destroy_swapchain(old, None) };
        }
        self.images = unsafe { self.loader.get_swapchain_images(self.swapchain)? };
        for &image in &self.images {
            let view = unsafe {
                gpu.device.create_image_view(
                    &vk::ImageViewCreateInfo::default()
                        .image(image)
                        .view_type(vk::ImageViewType::TYPE_2D)
                        .format(self.format)
                        .subresource_range(full_range(vk::ImageAspectFlags::COLOR, 1)),
                    None,
                )?
            };
            self.views.push(view);
            self.rendered.push(unsafe { gpu.device.create_semaphore(&vk::SemaphoreCreateInfo::default(), None)? });
        }
        Ok(())
    }

    fn recreate(&mut self, gpu: &Gpu, size: PhysicalSize<u32>) -> Result<()> {
        gpu.wait_idle();
        self.build(gpu, size)
    }

    fn destroy_images(&mut self, gpu: &Gpu) {
        unsafe {
            for v in self.views.drain(..) {
                gpu.device.destroy_image_view(v, None);
            }
            for s in self.rendered.drain(..) {
                gpu.device.destroy_semaphore(s, None);
            }
        }
        self.images.clear();
    }

    fn destroy(&mut self, gpu: &Gpu) {
        self.destroy_images(gpu);
        unsafe {
            self.loader.destroy_swapchain(self.swapchain, None);
            self.surface_loader.destroy_surface(self.surface, None);
        }
    }
}

/// Where walking puts the feet when no floor is under the camera: the player spawn's height (it
/// stands on the floor), else the bottom of the scene.
fn ground_height(manifest: &pack::Manifest, min: Vec3) -> f32 {
    manifest.spawns.iter().find(|s| s.kind == "player").map_or(min.y, |s| s.position[1])
}

/// Metres per second walking: the player spawn's `speed`, else a brisk walk.
fn walk_speed(manifest: &pack::Manifest) -> f32 {
    let spawn = manifest.spawns.iter().find(|s| s.kind == "player");
    spawn.and_then(|s| s.params.get("speed")).and_then(|v| v.as_f64()).map_or(1.5, |v| v as f32)
}

/// The scene's animated instances, one skinning job per frame in flight.
fn engine_animated(gpu: &Gpu, pack: &pack::Pack, scene: &GpuScene) -> Result<Option<crate::animated::AnimatedScene>> {
    crate::animated::AnimatedScene::new(gpu, pack, scene, FRAMES_IN_FLIGHT)
}
