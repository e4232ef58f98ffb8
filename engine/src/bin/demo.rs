//! `demo`: render a cooked pack. In a window with a fly camera and the debug overlay (F1, or
//! `--overlay` from the start) when there is a display; headless (offscreen frames, screenshots,
//! frame times) with `--headless` or when there is none, the overlay drawn into the frames with
//! `--overlay`.
//!
//! Exit status: 0 ok, 1 runtime failure, 2 bad arguments or a bad pack, 3 validation errors.

use std::time::Instant;
use engine::scene::camera::Camera;
use engine::gpu::{DeviceLost, DevicePreference, GpuOptions};
use engine::app::headless::{Stage, StageOptions};
use engine::app::recovery::LossPolicy;
use engine::ui::{self, FrameStats};
use engine::render::renderer::Lighting;
use engine::render::scale::{RenderScale, Upscaler};
use engine::stats::{median, percentile};
use engine::app::{self, WindowOptions};
use game::DemoGame;

#[path = "demo/flight.rs"]
mod flight;
#[path = "demo/game.rs"]
mod game;
use engine::assets::reload::{reload_shaders, PackInfo, PackWatch, ShaderReload};
use engine::render::shaders::SourceWatch;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::process::ExitCode;

const USAGE: &str = "usage: demo [PACK...] [--headless] [--frames N] [--width W] [--height H]
            [--screenshot PATH] [--screenshot-every K] [--screens T,T,...] [--flight SECONDS]
            [--overlay] [--watch] [--device auto|cpu|gpu|NAME]
            [--validation] [--shadow-map-size N] [--aa off|msaa|fxaa]
            [--render-scale S | --target-ms T] [--upscaler easu|cubic]
       demo --dump-pose PACK --clip NAME --time T

  PACK                 cooked pack to show (default: build/temple.pack, made by `make cook`);
                       in the window, Tab switches between several; headless shows the first
  --headless           render offscreen even if a display is available
  --frames N           headless: frames to render (default 100); window: close after N frames
  --width/--height     image or window size in pixels (default 1280x720)
  --screenshot PATH    headless: write the last frame here (default build/screenshots/demo.png)
  --screenshot-every K headless: also write every K-th frame next to it as frame_NNNNN.png
  --screens T,T,...    headless: also write the frames at these times (seconds of the flight,
                       each frame 1/60 s) as t<T>s.png in --screens-dir (default build/screens)
  --rss-at N,N,...     headless: print the memory after these frames: allocated on the heap and
                       on the device (what the soak test, `make soak`, compares), and resident
  --flight SECONDS     headless: the camera flies a loop of this length over the level (from the
                       player's view, in at eye height, up and around above the roofs, back down;
                       default 24); 0 keeps it at the player's view
  --overlay            show the debug overlay (frame-time graph, counters, switches) from the
                       start; headless, it is drawn into the frames, so screenshots show it
  --watch              reload the (first) pack whenever its file is replaced (`cook --watch`
                       rewrites it): the scene, its lightmaps and probes, keeping the camera; a
                       pack that cannot be read or loaded keeps the last good one on screen, its
                       error on stderr and in the overlay's \"pack\" section (which also shows
                       when the pack was cooked and its bake's samples per texel). With the
                       shader sources present (the project's shaders/, or ENGINE_SHADERS), an
                       edited shader is compiled again (glslc) and the pipelines made from it;
                       one that does not compile keeps the old ones. Headless, it
                       renders until Ctrl-C (or --frames), prints `reloaded PACK` and writes
                       --screenshot again from the first frame after each reload
  --device D           pick the Vulkan device (also ENGINE_DEVICE); lavapipe is `cpu`
  --validation         enable the Vulkan validation layer (also ENGINE_VALIDATION=1);
                       any validation error makes the exit status 3
  --shadow-map-size N  texels per side of the sun's shadow map for dynamic objects (default 2048)
  --aa MODE            anti-aliasing: off (default); msaa (4 samples a pixel, alpha-to-coverage
                       for alpha-tested materials, resolved before the tone map); or fxaa (a
                       post-process pass after the tone map, cheaper)
  --target-ms T        the frame budget in GPU milliseconds the render scale adapts to hold
                       (default 16.7: 60 fps): the 3D passes draw at 0.5 to 1 of the output's
                       size, and an edge-adaptive upscaler (FSR 1 EASU) brings the frame back
  --render-scale S     draw the 3D passes at this fixed scale instead (0.5..1; 1 = off: every
                       pass at the output's size)
  --upscaler U         below the output's size: easu (FSR 1's edge-adaptive upsampler, the
                       default on GPUs) or cubic (Catmull-Rom, the default on CPU devices)
  --dump-pose PACK     print clip NAME's pose at T seconds (clamped to the clip) as JSON: node
                       world matrices, joint matrices, morph weights, skinned LOD 0 vertices

The debug overlay (F1; hidden at start unless --overlay): frame-time graph (CPU frame and GPU
ms, median and p99), culling/LOD counters, shader invocations and GPU ms per pass, and switches
for the depth pre-pass, frustum culling, LOD selection and freezing, fragment counting,
anti-aliasing (off, MSAA, FXAA) and the LOD pixel error; its \"simulation\" section has sliders for every flock's and particle
emitter's parameters, applied to the running simulation at once. While the pointer is over the
overlay, the mouse works it, not the camera.";

fn usage() -> String {
    format!("{USAGE}\n\nIn the window: {}", game::KEYS)
}

const DEFAULT_PACK: &str = "build/temple.pack";

/// Frames a watching headless run's summary (medians, pass times) covers: its last minute.
const WATCH_SUMMARY_FRAMES: u64 = 3600;

struct Args {
    pack: Option<PathBuf>,
    /// More packs for the window's Tab.
    more: Vec<PathBuf>,
    headless: bool,
    frames: Option<u64>,
    width: u32,
    height: u32,
    screenshot: PathBuf,
    screenshot_every: Option<u64>,
    /// Frame numbers (from 0) to write to build/screens/, with the time they show.
    screens: Vec<(u64, f64)>,
    flight: f32,
    screens_dir: PathBuf,
    rss_at: Vec<u64>,
    overlay: bool,
    /// Reload the first pack when its file is replaced.
    watch: bool,
    device: DevicePreference,
    validation: bool,
    shadow_map_size: u32,
    aa: engine::render::renderer::AntiAliasing,
    render_scale: RenderScale,
    upscaler: Option<Upscaler>,
    /// `--dump-pose PACK --clip NAME --time T`.
    dump_pose: Option<(PathBuf, Option<String>, Option<f32>)>,
}

fn parse_args() -> Result<Args, String> {
    let mut a = Args {
        pack: None,
        more: Vec::new(),
        headless: false,
        frames: None,
        width: 1280,
        height: 720,
        screenshot: PathBuf::from("build/screenshots/demo.png"),
        screenshot_every: None,
        screens: Vec::new(),
        flight: flight::DEFAULT_SECONDS,
        screens_dir: PathBuf::from("build/screens"),
        rss_at: Vec::new(),
        overlay: false,
        watch: false,
        device: DevicePreference::from_env(),
        validation: GpuOptions::validation_from_env(),
        shadow_map_size: engine::render::shadow::DEFAULT_SHADOW_MAP_SIZE,
        aa: Default::default(),
        render_scale: RenderScale::default(),
        upscaler: None,
        dump_pose: None,
    };
    let (mut render_scale, mut target_ms) = (None, None);
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        let mut value = |name: &str| it.next().ok_or_else(|| format!("{name} needs a value"));
        fn number<T: std::str::FromStr>(name: &str, v: String) -> Result<T, String> {
            v.parse().map_err(|_| format!("{name}: '{v}' is not a valid number"))
        }
        match arg.as_str() {
            "-h" | "--help" => {
                println!("{}", usage());
                std::process::exit(0);
            }
            "--headless" => a.headless = true,
            "--validation" => a.validation = true,
            "--overlay" => a.overlay = true,
            "--watch" => a.watch = true,
            "--frames" => a.frames = Some(number("--frames", value("--frames")?)?),
            "--width" => a.width = number("--width", value("--width")?)?,
            "--height" => a.height = number("--height", value("--height")?)?,
            "--screenshot" => a.screenshot = PathBuf::from(value("--screenshot")?),
            "--screenshot-every" => a.screenshot_every = Some(number("--screenshot-every", value("--screenshot-every")?)?),
            "--screens" => {
                for t in value("--screens")?.split(',') {
                    let secs: f64 = t.trim().parse().ok().filter(|s: &f64| s.is_finite() && *s >= 0.0).ok_or(format!("--screens: '{t}' is not a time in seconds"))?;
                    a.screens.push(((secs * 60.0).round() as u64, secs));
                }
            }
            "--screens-dir" => a.screens_dir = PathBuf::from(value("--screens-dir")?),
            "--rss-at" => {
                for n in value("--rss-at")?.split(',') {
                    a.rss_at.push(n.trim().parse().ok().filter(|&n: &u64| n > 0).ok_or(format!("--rss-at: '{n}' is not a frame count"))?);
                }
            }
            "--flight" => {
                let v = value("--flight")?;
                a.flight = v.parse().ok().filter(|s: &f32| s.is_finite() && *s >= 0.0).ok_or(format!("--flight: '{v}' is not a length in seconds"))?;
            }
            "--device" => a.device = DevicePreference::parse(&value("--device")?),
            "--shadow-map-size" => a.shadow_map_size = number("--shadow-map-size", value("--shadow-map-size")?)?,
            "--aa" => a.aa = value("--aa")?.parse().map_err(|e| format!("--aa: {e}"))?,
            "--render-scale" => render_scale = Some(value("--render-scale")?),
            "--target-ms" => target_ms = Some(value("--target-ms")?),
            "--upscaler" => a.upscaler = Some(value("--upscaler")?.parse().map_err(|e| format!("--upscaler: {e}"))?),
            "--dump-pose" => a.dump_pose = Some((PathBuf::from(value("--dump-pose")?), None, None)),
            "--clip" => a.dump_pose.as_mut().ok_or("--clip goes with --dump-pose")?.1 = Some(value("--clip")?),
            "--time" => a.dump_pose.as_mut().ok_or("--time goes with --dump-pose")?.2 = Some(number("--time", value("--time")?)?),
            s if s.starts_with('-') => return Err(format!("unknown option '{s}'")),
            s if a.pack.is_none() => a.pack = Some(PathBuf::from(s)),
            s => a.more.push(PathBuf::from(s)),
        }
    }
    a.render_scale = RenderScale::from_args(render_scale.as_deref(), target_ms.as_deref())?;
    if let Some((_, clip, time)) = &a.dump_pose {
        if clip.is_none() || !time.is_some_and(f32::is_finite) {
            return Err("--dump-pose needs --clip NAME and a finite --time T".into());
        }
    }
    if a.width == 0 || a.height == 0 || a.width > 16384 || a.height > 16384 {
        return Err(format!("image size {}x{} is out of range (1..16384)", a.width, a.height));
    }
    if !(16..=16384).contains(&a.shadow_map_size) {
        return Err(format!("--shadow-map-size {} is out of range (16..16384)", a.shadow_map_size));
    }
    if a.frames == Some(0) || a.screenshot_every == Some(0) {
        return Err("--frames and --screenshot-every must be at least 1".into());
    }
    Ok(a)
}

/// The pack given, or the project's own content: relative to the working directory first, then
/// to the repository the binary was built in (target/release/demo -> ../../build/temple.pack).
fn resolve_pack(arg: Option<PathBuf>) -> PathBuf {
    if let Some(p) = arg {
        return p;
    }
    let local = PathBuf::from(DEFAULT_PACK);
    if local.exists() {
        return local;
    }
    std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent()?.parent()?.parent().map(|root| root.join(DEFAULT_PACK)))
        .filter(|p| p.exists())
        .unwrap_or(local)
}

fn has_display() -> bool {
    ["DISPLAY", "WAYLAND_DISPLAY"].iter().any(|v| std::env::var_os(v).is_some_and(|s| !s.is_empty()))
}

/// Where the time from launch to the first frame went, stage by stage (printed headless as
/// "start-up: ..."; `tools/startup.py` reads it).
struct Startup {
    launch: Instant,
    last: Instant,
    stages: Vec<(&'static str, f64)>,
}

impl Startup {
    fn new() -> Startup {
        let now = Instant::now();
        Startup { launch: now, last: now, stages: Vec::new() }
    }

    /// The time since the previous mark was spent on `what`.
    fn mark(&mut self, what: &'static str) {
        let now = Instant::now();
        self.stages.push((what, (now - self.last).as_secs_f64() * 1e3));
        self.last = now;
    }

    fn line(&self) -> String {
        let parts: Vec<String> = self.stages.iter().map(|(what, ms)| format!("{what} {ms:.1} ms")).collect();
        format!("start-up: {}; launch to first frame {:.1} ms", parts.join(", "), (self.last - self.launch).as_secs_f64() * 1e3)
    }
}

fn main() -> ExitCode {
    let mut startup = Startup::new();
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("demo: error: {e}\n{}", usage());
            return ExitCode::from(2);
        }
    };
    if let Some((model, Some(clip), Some(time))) = &args.dump_pose {
        return engine::anim::dump::run(model, clip, *time);
    }
    let pack_path = resolve_pack(args.pack.clone());
    let mut packs = Vec::new();
    for path in std::iter::once(&pack_path).chain(&args.more) {
        match pack::Pack::read_file(path) {
            Ok(p) => packs.push(p),
            Err(e) => {
                // Missing or from an older cooker: say how to make it, since that is the fix.
                let hint = match (&e, args.pack.is_none()) {
                    (pack::PackError::Io(_) | pack::PackError::WrongVersion { .. }, true) => " (run `make cook` to cook the project's content)",
                    (pack::PackError::Io(_) | pack::PackError::WrongVersion { .. }, false) => " (cook one with `.venv/bin/cook LEVEL.toml|MODEL.gltf -o PACK`)",
                    _ => "",
                };
                eprintln!("demo: error: {}: {e}{hint}", path.display());
                return ExitCode::from(2);
            }
        }
    }
    let pack = &packs[0];
    startup.mark("read packs");
    let gpu_opts = GpuOptions { validation: args.validation, device: args.device.clone(), surface_extensions: vec![], pipeline_cache: GpuOptions::default_pipeline_cache() };

    if !args.headless && has_display() {
        let opts = WindowOptions {
            gpu: gpu_opts.clone(),
            width: args.width,
            height: args.height,
            max_frames: args.frames,
            shadow_map_size: args.shadow_map_size,
            aa: args.aa,
            render_scale: args.render_scale,
            upscaler: args.upscaler,
            title: format!("demo - {}", pack_path.display()),
            overlay: args.overlay,
        };
        let game = DemoGame::new(&packs);
        let mut game = if args.watch { game.watching(&pack_path) } else { game };
        match app::run(&packs[0], opts, &mut game) {
            Ok(run) => {
                println!("window closed after {} frames on {}", run.frames, run.device_name);
                return validation_verdict(args.validation, run.validation_errors);
            }
            Err(e) if e.is::<DeviceLost>() => exit_device_lost(&e),
            Err(e) => eprintln!("demo: cannot use a window ({e:#}); rendering headless instead"),
        }
    }
    match headless(&args, &pack_path, pack, &gpu_opts, startup) {
        Ok(code) => code,
        Err(e) if e.is::<DeviceLost>() => exit_device_lost(&e),
        Err(e) => {
            eprintln!("demo: error: {e:#}");
            ExitCode::from(1)
        }
    }
}

/// Leaves at once, status 1, after the GPU hung or was lost. The device's threads may still be
/// running the hung work: exit handlers and library destructors would then free memory under
/// them (a fresh-clone CI run of `test_a_hung_gpu_is_a_clear_error_not_a_wait_forever` saw a
/// segfault on the way out), so none of them run.
fn exit_device_lost(e: &anyhow::Error) -> ! {
    eprintln!("demo: error: {e:#}; restart the program (on a real GPU, update or reset the driver)");
    let _ = std::io::Write::flush(&mut std::io::stdout());
    let _ = std::io::Write::flush(&mut std::io::stderr());
    // SAFETY: _exit ends the process; nothing after it runs, nothing before it is left half done
    // that the OS does not reclaim.
    unsafe { libc::_exit(1) }
}

/// The process's resident set size (Linux: /proc/self/statm, in pages of 4 KiB).
fn resident_kib() -> Option<u64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * 4)
}

/// Host memory for `--rss-at`, in KiB: the bytes allocated on the heap and not yet freed (glibc's
/// count over all its arenas and the blocks it maps apart), and the resident memory.
///
/// The first is what a host leak grows, and the soak judges it (with the device memory). The resident memory is also a
/// high-water mark: lavapipe allocates and frees ~6 MB of scratch in every frame, and where two
/// frames' scratch overlap, glibc keeps the larger, fragmented heap it grew. Under heaptrack, over
/// 3,000 frames, the live heap's low point between frames stayed within 10 KB while the resident
/// memory rose in one 3 MiB step, at the moment the live heap reached a new peak.
fn memory_kib() -> (u64, u64) {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallinfo2 only reads glibc's counters.
    let heap = unsafe {
        let m = libc::mallinfo2();
        (m.uordblks + m.hblkhd) as u64 / 1024
    };
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    let heap = 0;
    (heap, resident_kib().unwrap_or(0))
}

fn validation_verdict(enabled: bool, errors: usize) -> ExitCode {
    if enabled {
        println!("validation errors: {errors}");
    }
    if errors > 0 {
        ExitCode::from(3)
    } else {
        ExitCode::SUCCESS
    }
}

fn headless(args: &Args, pack_path: &Path, pack: &pack::Pack, gpu_opts: &GpuOptions, mut startup: Startup) -> anyhow::Result<ExitCode> {
    let stage_opts = StageOptions {
        gpu: gpu_opts.clone(),
        width: args.width,
        height: args.height,
        shadow_map_size: args.shadow_map_size,
        aa: args.aa,
        render_scale: args.render_scale,
        upscaler: args.upscaler,
        overlay: args.overlay,
    };
    let mut stage = Stage::new(&stage_opts, pack, &mut |what| {
        startup.mark(what);
    })?;
    println!("device: {} ({:?})", stage.gpu.caps.device_name, stage.gpu.caps.device_type);
    let scene = &stage.scene;
    println!("scene upload: {} bytes in {} submits", scene.upload.bytes, scene.upload.submits);
    let (min, max) = scene.bounds();
    let still = Camera::for_pack(&pack.manifest, min, max);
    let flight = (args.flight > 0.0).then(|| flight::Flight::for_pack(&pack.manifest, min, max, args.flight));
    let mut lighting = Lighting::for_pack(&pack.manifest);
    // --watch: the pack's file, and Ctrl-C / SIGTERM to end the run with its summary and a
    // clean teardown (a watching run has no last frame of its own).
    let mut watch = args.watch.then(|| (PackWatch::new(pack_path), PackInfo::new(pack_path, pack)));
    // And the shader sources, where they are (the project's ../shaders or ENGINE_SHADERS).
    let mut shader_watch = if args.watch { engine::render::shaders::sources().map(|d| SourceWatch::new(&d)) } else { None };
    let stop = Arc::new(AtomicBool::new(false));
    if args.watch {
        let flag = stop.clone();
        if let Err(e) = ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst)) {
            eprintln!("demo: cannot install the Ctrl-C handler ({e})");
        }
    }
    if !args.screens.is_empty() {
        std::fs::create_dir_all(&args.screens_dir).map_err(|e| anyhow::anyhow!("creating {}: {e}", args.screens_dir.display()))?;
    }
    let mut world = engine::sim::level::world_from_spawns(&pack.manifest.spawns, &pack.manifest.pillars, min, max);
    engine::sim::level::warm_up(&mut world);
    startup.mark("simulation warm-up");
    // Long enough for every requested screen unless the frame count was given.
    let frames = match (args.frames, args.watch) {
        (Some(n), _) => n,
        (None, true) => u64::MAX,
        (None, false) => args.screens.iter().map(|&(k, _)| k + 1).max().unwrap_or(0).max(100),
    };
    if let Some(&(_, secs)) = args.screens.iter().find(|&&(k, _)| k >= frames) {
        anyhow::bail!("--screens {secs}: past the last frame ({frames} frames are {:.2} s)", frames as f64 / 60.0);
    }
    // The per-frame records are allocated and written once up front, so their memory is resident
    // before the first frame: `--rss-at` (the soak) compares resident memory between frames, and
    // records that grew as frames passed (by pages, and by doubling) would read as a leak.
    // A watching run has no last frame: its summary covers its last minute of frames.
    let window = if args.watch { frames.min(WATCH_SUMMARY_FRAMES) } else { frames };
    let record = || {
        let mut v = vec![0.0f64; window as usize];
        v.fill(1.0);
        v.clear();
        v
    };
    let mut frame_ms = record();
    let mut gpu_ms = record();
    // Every pass of the renderer, in frame order, with its GPU ms per frame (0 when it did not run).
    let pass_names: Vec<&'static str> = stage.renderer.pass_names().collect();
    let mut pass_ms: Vec<Vec<f64>> = pass_names.iter().map(|_| record()).collect();
    let mut skin_ms = record();
    // Frames drawn at each render scale (in hundredths).
    let mut scales: std::collections::BTreeMap<u32, u64> = Default::default();
    let (mut reloaded, mut rendered) = (false, 0u64);
    let mut next_frame = Instant::now();
    // The pack on show when it is not `pack` (a reload under --watch): what a lost device is
    // made again from.
    let mut on_show: Option<pack::Pack> = None;
    let mut losses = LossPolicy::default();
    for f in 0..frames {
        if args.watch {
            // Watching, frames keep real time (at most 60 a second) instead of running flat out
            // beside the cook that rewrites the pack.
            next_frame += std::time::Duration::from_secs_f64(1.0 / 60.0);
            let now = Instant::now();
            match next_frame.checked_duration_since(now) {
                Some(wait) => std::thread::sleep(wait),
                None => next_frame = now,
            }
        }
        if stop.load(Ordering::SeqCst) {
            break;
        }
        if frame_ms.len() as u64 >= window {
            for v in std::iter::once(&mut frame_ms).chain([&mut gpu_ms, &mut skin_ms]).chain(pass_ms.iter_mut()) {
                v.clear();
            }
        }
        let replaced = watch.as_mut().is_some_and(|(w, _)| w.changed());
        if let Some((w, info)) = watch.as_mut().filter(|_| replaced) {
            let path = w.path();
            let fresh = pack::Pack::read_file(path).map_err(anyhow::Error::from);
            match fresh.and_then(|p| engine::assets::reload::replace_scene(&stage.gpu, &mut stage.renderer, &mut stage.scene, &p, 1).map(|()| p)) {
                Ok(p) => {
                    // The camera and the world go on; the light is the new pack's.
                    lighting = Lighting::for_pack(&p.manifest);
                    info.shown(&p);
                    info.reloads += 1;
                    println!("reloaded {}", path.display());
                    reloaded = true;
                    on_show = Some(p);
                }
                Err(e) if e.is::<DeviceLost>() => return Err(e),
                Err(e) => {
                    eprintln!("demo: error: {}: {e:#}; still showing the last good pack", path.display());
                    info.error = Some(format!("{e:#}"));
                }
            }
        }
        if let (Some(sw), Some((_, info))) = (shader_watch.as_mut(), watch.as_mut()) {
            match reload_shaders(sw, &stage.gpu, &mut stage.renderer, 1)? {
                ShaderReload::Unchanged => {}
                ShaderReload::Reloaded(changed) => {
                    println!("reloaded shaders ({} modules changed: {})", changed.len(), changed.join(", "));
                    info.shader_reloads += 1;
                    info.shader_error = None;
                    reloaded = true;
                }
                ShaderReload::Refused(messages) => {
                    eprintln!("demo: shader error: {messages}\ndemo: the pipelines are as they were");
                    info.shader_error = messages.lines().next().map(str::to_string);
                }
            }
        }
        // Headless frames advance a fixed 1/60 s of animation, so runs are reproducible.
        stage.renderer.animate(&mut stage.scene, 1.0 / 60.0);
        rendered += 1;
        let last = f + 1 == frames;
        let every = args.screenshot_every.is_some_and(|k| (f + 1) % k == 0);
        // Headless frames advance the simulation by a fixed 1/60 s: the same frames give the
        // same image whatever the machine's speed.
        world.update(1.0 / 60.0);
        // Frame f shows the flight at f/60 s (frame 0: the player's view).
        let camera = flight.as_ref().map_or(still, |fl| fl.camera(f as f32 / 60.0));
        let screen = args.screens.iter().find(|(k, _)| *k == f).map(|&(_, secs)| secs);
        engine::sim::level::prepare_frame(&world, &mut stage.renderer, &stage.scene, &camera);
        // The first frame of a watching run, and the first after each reload, are written too.
        let shown = watch.is_some() && (f == 0 || std::mem::take(&mut reloaded));
        let capture = last || every || screen.is_some() || shown;
        // A lost device is made again from the pack on show and the frame drawn again
        // (`app::recovery`): the world, the camera and the renderer's state carry on.
        let t = loop {
            let drawn = match stage.overlay.as_mut() {
                Some(o) => stage.target.render_with(&stage.gpu, &mut stage.renderer, &stage.scene, &camera, &lighting, capture, o, |o, renderer| {
                    // A fixed 60 Hz clock: the same frames give the same pictures.
                    let mut sim = ui::SimPanel::new(&mut world);
                    let input = ui::headless_input(args.width, args.height, f as f64 / 60.0, Vec::new());
                    match &watch {
                        Some((_, info)) => o.build(input, renderer, &mut [&mut ui::PackPanel { info }, &mut sim]),
                        None => o.build(input, renderer, &mut [&mut sim]),
                    };
                }),
                None => stage.target.render(&stage.gpu, &mut stage.renderer, &stage.scene, &camera, &lighting, capture),
            };
            let e = match drawn {
                Ok(t) => break t,
                Err(e) => e,
            };
            let what = format!("{e:#}");
            losses.survive(e)?;
            let start = Instant::now();
            stage.recover(&stage_opts, on_show.as_ref().unwrap_or(pack)).map_err(|e| e.context(format!("making the device again after it was lost at frame {f}")))?;
            losses.recovered();
            println!("device lost at frame {f} ({what}); made again from the pack in {:.0} ms, drawing frame {f} again", start.elapsed().as_secs_f64() * 1e3);
        };
        losses.frame_shown();
        if let Some(o) = stage.overlay.as_mut() {
            o.push_frame(t.frame_ms, t.gpu_ms, FrameStats::read(&stage.gpu, &stage.renderer, 0));
        }
        if f == 0 {
            startup.mark("first frame");
            println!("{}", startup.line());
        }
        frame_ms.push(t.frame_ms);
        gpu_ms.extend(t.gpu_ms);
        *scales.entry((stage.renderer.frame_scale() * 100.0).round() as u32).or_default() += 1;
        if let Some(p) = stage.renderer.profile(&stage.gpu, 0) {
            for (v, name) in pass_ms.iter_mut().zip(&pass_names) {
                v.push(p.ms(name));
            }
            skin_ms.push(p.ms("skinning"));
        }
        if every {
            let dir = args.screenshot.parent().unwrap_or(Path::new("."));
            stage.target.save_png(&dir.join(format!("frame_{:05}.png", f + 1)))?;
        }
        if args.rss_at.contains(&(f + 1)) {
            let (heap, resident) = memory_kib();
            let (device, blocks) = stage.gpu.device_memory();
            println!(
                "memory after frame {}: heap {heap} KiB allocated, device {} KiB allocated (of {} KiB in blocks), {resident} KiB resident",
                f + 1,
                device / 1024,
                blocks / 1024
            );
        }
        if shown && !last {
            stage.target.save_png(&args.screenshot)?;
            println!("wrote {}", args.screenshot.display());
            if f == 0 {
                match &shader_watch {
                    Some(sw) => println!("watching {} and the shaders in {}", pack_path.display(), sw.dir().display()),
                    None => println!("watching {}", pack_path.display()),
                }
            }
        }
        if let Some(secs) = screen {
            let path = args.screens_dir.join(format!("t{secs}s.png"));
            stage.target.save_png(&path)?;
            println!("wrote {} (render scale {:.2})", path.display(), stage.renderer.frame_scale());
        }
    }
    stage.target.save_png(&args.screenshot)?;
    println!("wrote {}", args.screenshot.display());
    let c = stage.renderer.visibility.counts;
    // The cull counts include the boids (culled with the scene); reported apart here.
    let boids = stage.renderer.boids.boids.len() as u32;
    println!(
        "frames: {rendered} at {}x{}, {} instances ({} culled, {} drawn), {} boids ({} drawn), {} triangles drawn of {} at full detail in {} draw calls, LOD histogram {:?}",
        args.width,
        args.height,
        stage.scene.instances.len(),
        c.cull.culled - (boids - c.boids),
        c.cull.visible - c.boids,
        boids,
        c.boids,
        c.triangles,
        stage.scene.triangle_count(),
        stage.renderer.draw_calls,
        c.lod_histogram
    );
    println!(
        "frame_ms: median {:.3} p95 {:.3}",
        median(&frame_ms).unwrap_or(0.0),
        percentile(&frame_ms, 95.0).unwrap_or(0.0)
    );
    if let Some(m) = median(&gpu_ms) {
        println!("gpu_ms: median {m:.3}");
    }
    let at: Vec<String> = scales.iter().map(|(s, n)| format!("{:.2}: {n}", *s as f32 / 100.0)).collect();
    println!("render scale {}: frames at each {{{}}}", stage.renderer.render_scale.mode.describe(), at.join(", "));
    // The passes that ran in some frame, as the overlay lists them.
    let ran: Vec<String> = pass_names
        .iter()
        .zip(&pass_ms)
        .filter_map(|(name, ms)| median(ms).filter(|_| ms.iter().any(|&m| m > 0.0)).map(|m| format!("{name} {m:.3}")))
        .collect();
    if !ran.is_empty() {
        println!("pass gpu_ms (median): {} ({} shadow casters, {} billboards)", ran.join(", "), stage.renderer.shadow_casters, stage.renderer.visibility.counts.particles);
    }
    if let Some(a) = &stage.renderer.animation {
        println!(
            "animation: {} animated instances, {} skinning jobs in {} dispatch(es) ({} vertices) last frame, skinning gpu_ms median {:.3}, animation cpu_ms last frame {:.3}",
            a.instances.len(),
            a.jobs,
            a.dispatches,
            a.skinned_vertices,
            median(&skin_ms).unwrap_or(0.0),
            a.cpu_ms
        );
    }
    if losses.recoveries > 0 {
        println!("device recoveries: {}", losses.recoveries);
    }
    let errors = stage.destroy();
    Ok(validation_verdict(gpu_opts.validation, errors))
}
