//! Named frame-time scenarios (issue 9): `bench --scenario NAME[,NAME] | --all`.
//!
//! Every scenario renders headless at one resolution (default 1280x720) for a fixed number of
//! warm-up frames, then a fixed number of measured frames. Each frame advances the simulation
//! and animation by a fixed `FRAME_S` and the camera is a function of the frame number only, so
//! every run does the same work and the counters of frame k are exact (the tests pin them).
//!
//! The CPU frame time is the wall time of a whole frame: simulation and animation update,
//! culling and recording, submit, and the wait for the GPU's fence. On lavapipe the GPU is the
//! CPU, so this is the number that matters; its GPU timestamps also miss compute work (the
//! skinning pass), so the per-pass GPU times are reported beside it but never instead of it.
//!
//! A floor is measured in the same run: clear an image of the same size and wait for it. Each
//! scenario's percentiles are also given as multiples of the floor's.

use super::{boxes_builder, boxes_pack, cube_grid, skinned_bench};
use engine::anim::animated::AnimatedScene;
use engine::scene::camera::Camera;
use crate::flight::{self, Flight};
use engine::gpu::{barrier, full_range, DevicePreference, Gpu, GpuOptions, Image, Transition};
use engine::app::headless::{Offscreen, OFFSCREEN_FORMAT};
use engine::render::graph::FrameProfile;
use engine::render::renderer::{AntiAliasing, Lighting, Renderer};
use engine::render::scale::{RenderScale, ScaleController};
use engine::scene::GpuScene;
use engine::sim::boids::{Aabb, BoidParams, Flock, FlockState};
use engine::sim::clock::{ClockParams, FixedClock};
use engine::sim::particles::{EmitterParams, ParticleSystem, Preset};
use engine::sim::World;
use engine::sim::level;
use engine::stats::percentile;
use glam::{Mat4, Vec3};
use pack::{Pack, PackBuilder};
use serde_json::{json, Map, Value};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What each scenario renders (its scene, world, camera path and switches).
#[path = "setups.rs"]
mod setups;

#[path = "bird.rs"]
mod bird;
use setups::setup;

/// Simulated time per frame: a 60 Hz display's frame, whatever the machine's speed.
pub const FRAME_S: f64 = 1.0 / 60.0;

pub const NAMES: [&str; 6] = ["demo-flythrough", "culling-100k", "boids-10k", "particles-100k", "skinned-64", "prepass-overdraw"];

pub const USAGE: &str = "usage: bench --scenario NAME[,NAME..] | --all  [--frames N] [--warmup N] [--width W] [--height H]
             [--json-dir DIR] [--level PACK] [--character PACK] [--device auto|cpu|gpu|NAME] [--quiet]
             [--render-scale S | --target-ms T]
       bench --list

  --scenario LIST   comma-separated scenario names (see --list)
  --all             every scenario, in the order --list gives
  --frames N        measured frames per scenario (default 60)
  --warmup N        frames rendered first and not measured (default 5); they advance the
                    simulation and the camera like any frame, so frame k is the same in every run
  --width/--height  image size in pixels (default 1280x720)
  --json-dir DIR    where <scenario>.json goes (default build/bench)
  --level PACK      the cooked demo level for demo-flythrough (default build/temple.pack, `make cook`)
  --character PACK  the skinned character for skinned-64 (default build/golem.pack, `make cook`)
  --device D        pick the Vulkan device (also ENGINE_DEVICE); lavapipe is `cpu`
  --quiet           only the one-line summary per scenario
  --no-variants     measure each scenario's default only (no variant frames in between): for
                    comparing with a build that has fewer or no variants
  --target-ms T     the GPU frame time the render scale adapts to hold (default 16.7); each
                    series (the default, each variant) adapts on its own frames
  --render-scale S  a fixed render scale instead (0.5..1; 1: every pass at the image's size)

Scenarios:
  demo-flythrough   the demo level on a scripted camera orbit, its characters, boids and particles
                    animating at a fixed step; frames cycle through the default (no anti-aliasing)
                    and the variants aa_msaa, aa_fxaa, sky_off, material_maps_off, specular_off,
                    transparency_off, lightmaps_bicubic, reflections_off
  culling-100k      100 000 cubes on a grid, a quarter in view: frustum culling and LOD selection;
                    frames alternate with instancing on (the scenario's times) and off, one draw
                    call per cube (its `variants.instancing_off`)
  boids-10k         a flock of 10 000 boids stepped and drawn
  particles-100k    a fountain holding about 100 000 live particles, stepped, sorted and drawn
  skinned-64        64 skinned characters (the --character pack) all in view, skinned every frame
                    at the LODs their size on screen picks; frames alternate with LOD selection
                    off, every one at full detail (its `variants.lod_off`)
  prepass-overdraw  16 overlapping opaque layers drawn back to front; frames alternate with the
                    depth pre-pass on (the scenario's times) and off (its `variants.prepass_off`)

Each scenario writes DIR/<scenario>.json: CPU frame time (wall time of the whole frame, fence
wait included) and its parts (update, prepare and record, fence wait), per-pass GPU time (p50/p95/p99/max), the floor (clear and wait for an empty
frame of the same size) and each percentile as a multiple of it, and the last frame's counters;
its `variants` hold the same for each variant.
Exit status: 0 ok, 1 a scenario failed, 2 bad arguments, 3 Vulkan validation errors.";

pub struct Options {
    pub scenarios: Vec<&'static str>,
    pub frames: usize,
    pub warmup: usize,
    pub width: u32,
    pub height: u32,
    pub json_dir: PathBuf,
    pub level: PathBuf,
    pub character: PathBuf,
    pub device: DevicePreference,
    pub quiet: bool,
    /// Skip the scenarios' variants.
    pub no_variants: bool,
    /// How the 3D passes' resolution is chosen (adaptive at 16.7 ms unless told).
    pub render_scale: RenderScale,
}

/// Whether the command line asks for named scenarios (the other forms are the older benches).
pub fn wanted(args: &[String]) -> bool {
    args.iter().any(|a| matches!(a.as_str(), "--scenario" | "--all" | "--list"))
}

pub fn parse(args: Vec<String>) -> Result<Options, String> {
    let mut o = Options {
        scenarios: Vec::new(),
        frames: 60,
        warmup: 5,
        width: 1280,
        height: 720,
        json_dir: PathBuf::from("build/bench"),
        level: PathBuf::from("build/temple.pack"),
        character: PathBuf::from("build/golem.pack"),
        device: DevicePreference::from_env(),
        quiet: false,
        no_variants: false,
        render_scale: RenderScale::default(),
    };
    let (mut render_scale, mut target_ms) = (None, None);
    let mut it = args.into_iter();
    while let Some(flag) = it.next() {
        let mut value = |name: &str| it.next().ok_or_else(|| format!("{name} needs a value"));
        let number = |name: &str, v: String| v.parse::<usize>().map_err(|_| format!("{name}: '{v}' is not a whole number"));
        match flag.as_str() {
            "--scenario" => o.scenarios.extend(scenario_list(&value("--scenario")?)?),
            "--all" => o.scenarios.extend(NAMES),
            "--list" => {
                println!("{}", NAMES.join("\n"));
                std::process::exit(0);
            }
            "--frames" => o.frames = number("--frames", value("--frames")?)?,
            "--warmup" => o.warmup = number("--warmup", value("--warmup")?)?,
            "--width" => o.width = number("--width", value("--width")?)? as u32,
            "--height" => o.height = number("--height", value("--height")?)? as u32,
            "--json-dir" => o.json_dir = value("--json-dir")?.into(),
            "--level" => o.level = value("--level")?.into(),
            "--character" => o.character = value("--character")?.into(),
            "--device" => o.device = DevicePreference::parse(&value("--device")?),
            "--quiet" => o.quiet = true,
            "--no-variants" => o.no_variants = true,
            "--render-scale" => render_scale = Some(value("--render-scale")?),
            "--target-ms" => target_ms = Some(value("--target-ms")?),
            "-h" | "--help" => return Err(USAGE.into()),
            other => return Err(format!("unknown argument '{other}' (try --help)")),
        }
    }
    o.render_scale = RenderScale::from_args(render_scale.as_deref(), target_ms.as_deref())?;
    if o.frames == 0 {
        return Err("--frames must be at least 1".into());
    }
    if !(1..=16384).contains(&o.width) || !(1..=16384).contains(&o.height) {
        return Err(format!("image size {}x{} is out of range (1..16384)", o.width, o.height));
    }
    // Each once, in the order asked.
    let mut seen = Vec::new();
    o.scenarios.retain(|s| {
        if seen.contains(s) {
            false
        } else {
            seen.push(*s);
            true
        }
    });
    Ok(o)
}

fn scenario_list(v: &str) -> Result<Vec<&'static str>, String> {
    let names: Vec<&str> = v.split(',').map(str::trim).filter(|s| !s.is_empty()).collect();
    if names.is_empty() {
        return Err("--scenario needs at least one name (see --list)".into());
    }
    names
        .into_iter()
        .map(|n| NAMES.iter().copied().find(|k| *k == n).ok_or_else(|| format!("unknown scenario '{n}' (known: {})", NAMES.join(", "))))
        .collect()
}

/// What one scenario renders and how its frames change.
struct Setup {
    scene: GpuScene,
    /// Particles and flocks, stepped by `FRAME_S` each frame (empty for most scenarios).
    world: World,
    /// The camera of frame k (warm-up frames included).
    camera: Box<dyn Fn(usize) -> Camera>,
    lighting: Lighting,
    /// Renderer switches measured against the scenario's default: frames cycle through the
    /// default and each variant (demo-flythrough, prepass-overdraw, culling-100k).
    variants: Vec<Switch>,
    /// Facts about the scenario's content for the JSON (counts it was built with).
    content: Map<String, Value>,
}

/// A renderer setting a scenario measures against its default: frames cycle through the
/// default and the variants, so all see the same content on the same machine at the same moment.
#[derive(Debug, Clone, Copy)]
enum Switch {
    PrepassOff,
    InstancingOff,
    Msaa,
    Fxaa,
    SkyOff,
    MaterialMapsOff,
    SpecularOff,
    TransparencyOff,
    BicubicLightmaps,
    ReflectionsOff,
    LodOff,
}

impl Switch {
    /// The variant's JSON key.
    fn key(self) -> &'static str {
        match self {
            Switch::PrepassOff => "prepass_off",
            Switch::InstancingOff => "instancing_off",
            Switch::Msaa => "aa_msaa",
            Switch::Fxaa => "aa_fxaa",
            Switch::SkyOff => "sky_off",
            Switch::MaterialMapsOff => "material_maps_off",
            Switch::SpecularOff => "specular_off",
            Switch::TransparencyOff => "transparency_off",
            Switch::BicubicLightmaps => "lightmaps_bicubic",
            Switch::ReflectionsOff => "reflections_off",
            Switch::LodOff => "lod_off",
        }
    }

    fn label(self) -> &'static str {
        match self {
            Switch::PrepassOff => "pre-pass off",
            Switch::InstancingOff => "instancing off",
            Switch::Msaa => "MSAA 4x",
            Switch::Fxaa => "FXAA",
            Switch::SkyOff => "sky off",
            Switch::MaterialMapsOff => "material maps off",
            Switch::SpecularOff => "specular off",
            Switch::TransparencyOff => "transparency off",
            Switch::BicubicLightmaps => "bicubic lightmaps",
            Switch::ReflectionsOff => "reflection probes off",
            Switch::LodOff => "LOD selection off",
        }
    }

    /// Set the renderer as the variant has it (`on`) or as the default has it.
    fn set(self, r: &mut Renderer, on: bool) {
        match self {
            Switch::PrepassOff => r.prepass = !on,
            Switch::InstancingOff => r.instancing = !on,
            Switch::Msaa => r.aa = if on { AntiAliasing::Msaa } else { AntiAliasing::Off },
            Switch::Fxaa => r.aa = if on { AntiAliasing::Fxaa } else { AntiAliasing::Off },
            Switch::SkyOff => r.sky = !on,
            Switch::MaterialMapsOff => r.material_maps = !on,
            Switch::SpecularOff => r.specular = !on,
            Switch::TransparencyOff => r.transparency = !on,
            Switch::BicubicLightmaps => r.bicubic_lightmaps = on,
            Switch::ReflectionsOff => r.reflections = !on,
            Switch::LodOff => r.visibility.lod_selection = !on,
        }
    }
}

/// Put the renderer in series `index`'s setting: 0 the default, i the variant i - 1.
fn select(r: &mut Renderer, variants: &[Switch], index: usize) {
    for v in variants {
        v.set(r, false);
    }
    if index > 0 {
        variants[index - 1].set(r, true);
    }
}

/// Samples of one series of frames.
#[derive(Default)]
struct Series {
    cpu_ms: Vec<f64>,
    /// The CPU frame's parts: simulation and animation update, preparing and recording the
    /// frame up to the submit, and the wait for its fence (`FrameTiming`).
    update_ms: Vec<f64>,
    record_ms: Vec<f64>,
    wait_ms: Vec<f64>,
    gpu_ms: Vec<f64>,
    /// The render scale each frame was drawn at.
    scales: Vec<f64>,
    /// Culling's counts summed over the measured frames (instances culled by the frustum, tested
    /// and culled by occlusion, drawn; triangles): what culling did along the whole camera path.
    totals: [u64; 5],
    passes: Vec<FrameProfile>,
    counters: Map<String, Value>,
}

pub fn run(o: &Options) -> anyhow::Result<usize> {
    if o.scenarios.is_empty() {
        anyhow::bail!("no scenario named: use --scenario NAME[,NAME..] or --all (see --list)");
    }
    let gpu = Gpu::new(&GpuOptions {
        validation: engine::gpu::GpuOptions::validation_from_env(),
        device: o.device.clone(),
        surface_extensions: vec![],
        pipeline_cache: GpuOptions::default_pipeline_cache(),
    })?;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "bench: {} ({:?}), {cores} cores, {}x{}, {} warm-up + {} measured frames, {:.4} s simulated per frame",
        gpu.caps.device_name, gpu.caps.device_type, o.width, o.height, o.warmup, o.frames, FRAME_S
    );
    let floor = floor_ms(&gpu, o)?;
    let floor_stats = summary(&floor);
    println!(
        "floor (clear + wait, empty frame): p50 {:.3} ms, p95 {:.3} ms",
        floor_stats["p50"].as_f64().unwrap_or(0.0),
        floor_stats["p95"].as_f64().unwrap_or(0.0)
    );
    std::fs::create_dir_all(&o.json_dir).map_err(|e| anyhow::anyhow!("creating {}: {e}", o.json_dir.display()))?;
    let mut failed = Vec::new();
    for name in &o.scenarios {
        match run_one(&gpu, o, name, &floor_stats) {
            Ok(path) => println!("  wrote {}", path.display()),
            Err(e) => {
                eprintln!("bench: scenario {name} failed: {e:#}");
                failed.push(*name);
            }
        }
    }
    if !failed.is_empty() {
        anyhow::bail!("{} of {} scenarios failed: {}", failed.len(), o.scenarios.len(), failed.join(", "));
    }
    Ok(gpu.validation().error_count())
}

/// The floor: record a clear of a colour image of the frame's size, submit, wait. The command
/// buffer and fence are made per frame by `one_shot` (microseconds), which errs on the high side.
fn floor_ms(gpu: &Gpu, o: &Options) -> anyhow::Result<Vec<f64>> {
    let extent = ash::vk::Extent2D { width: o.width, height: o.height };
    let usage = ash::vk::ImageUsageFlags::COLOR_ATTACHMENT | ash::vk::ImageUsageFlags::TRANSFER_DST;
    let mut image = Image::new(gpu, "bench floor", OFFSCREEN_FORMAT, extent, 1, usage, ash::vk::ImageAspectFlags::COLOR)?;
    let range = full_range(ash::vk::ImageAspectFlags::COLOR, 1);
    // At least 200 samples whatever --frames says: each takes well under a millisecond, and on a
    // shared machine a few dozen give a p95 that is mostly scheduling noise.
    let samples = o.frames.max(200);
    let mut ms = Vec::with_capacity(samples);
    for k in 0..o.warmup + samples {
        let t = Instant::now();
        gpu.one_shot(|cb| unsafe {
            barrier(gpu, cb, image.image, range, Transition::UNDEFINED_TO_TRANSFER_DST);
            let clear = ash::vk::ClearColorValue { float32: [0.1, 0.1, 0.1, 1.0] };
            gpu.device.cmd_clear_color_image(cb, image.image, ash::vk::ImageLayout::TRANSFER_DST_OPTIMAL, &clear, &[range]);
        })?;
        if k >= o.warmup {
            ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
    }
    image.destroy(gpu);
    Ok(ms)
}

fn run_one(gpu: &Gpu, o: &Options, name: &str, floor: &Value) -> anyhow::Result<PathBuf> {
    let mut renderer = Renderer::new(gpu, OFFSCREEN_FORMAT, 1)?;
    // `measure` feeds each series' controller its own frames.
    renderer.scale_feedback = false;
    let mut target = Offscreen::new(gpu, o.width, o.height)?;
    let result = setup(gpu, o, name, &mut renderer).and_then(|mut s| {
        if o.no_variants {
            s.variants.clear();
        }
        let r = measure(gpu, o, &mut renderer, &mut target, &mut s);
        s.scene.destroy(gpu);
        r.map(|series| (series, s.content, s.variants))
    });
    let pass_names: Vec<&'static str> = renderer.pass_names().collect();
    renderer.destroy(gpu);
    target.destroy(gpu);
    let (series, content, variants) = result?;
    let main = &series[0];
    let mut doc = json!({
        "scenario": name,
        "schema": 1,
        "device": gpu.caps.device_name,
        "cores": std::thread::available_parallelism().map_or(1, |n| n.get()),
        "width": o.width,
        "height": o.height,
        "warmup_frames": o.warmup,
        "frames": o.frames,
        "frame_s": FRAME_S,
        "content": content,
        "floor_ms": floor,
        "note": "cpu_frame_ms is the wall time of a whole frame including the wait for the GPU fence; GPU timestamps on lavapipe do not capture compute work reliably (skinning_ms understates the skinning pass)",
    });
    let fields = doc.as_object_mut().expect("an object");
    fields.extend(series_json(main, floor, &pass_names));
    if !variants.is_empty() {
        let mut all = Map::new();
        for (switch, v) in variants.iter().zip(&series[1..]) {
            let mut variant = series_json(v, floor, &pass_names);
            variant.insert("label".into(), json!(switch.label()));
            all.insert(switch.key().into(), Value::Object(variant));
        }
        doc["variants"] = Value::Object(all);
    }
    print_summary(o, name, &doc, &variants);
    let path = o.json_dir.join(format!("{name}.json"));
    write_atomic(&path, &serde_json::to_vec_pretty(&doc)?)?;
    Ok(path)
}

/// One series' times (with the floor's ratios), per-pass GPU ms, counters and samples.
fn series_json(s: &Series, floor: &Value, pass_names: &[&'static str]) -> Map<String, Value> {
    let doc = json!({
        "cpu_frame_ms": summary(&s.cpu_ms),
        // Where the CPU frame goes: update + record + fence wait = the frame (to rounding).
        "cpu_update_ms": summary(&s.update_ms),
        "cpu_record_ms": summary(&s.record_ms),
        "fence_wait_ms": summary(&s.wait_ms),
        "floor_ratio": ratios(&s.cpu_ms, floor),
        "gpu_frame_ms": summary(&s.gpu_ms),
        "pass_gpu_ms": pass_summary(&s.passes, pass_names),
        "render_scale": scale_summary(&s.scales),
        "counter_totals": {
            "frustum_culled": s.totals[0],
            "occlusion_tested": s.totals[1],
            "occlusion_culled": s.totals[2],
            "drawn": s.totals[3],
            "triangles": s.totals[4],
        },
        "counters": s.counters,
        "samples": { "cpu_frame_ms": s.cpu_ms, "gpu_frame_ms": s.gpu_ms, "render_scale": s.scales },
    });
    match doc {
        Value::Object(m) => m,
        _ => unreachable!("json! of an object"),
    }
}

/// The render scales of a series: median, range and how many frames ran at each.
fn scale_summary(scales: &[f64]) -> Value {
    let mut counts: std::collections::BTreeMap<String, usize> = Default::default();
    for s in scales {
        *counts.entry(format!("{s:.2}")).or_default() += 1;
    }
    let mut sorted = scales.to_vec();
    sorted.sort_by(f64::total_cmp);
    json!({
        "p50": sorted.get(sorted.len() / 2),
        "min": sorted.first(),
        "max": sorted.last(),
        "frames_at": counts,
    })
}

fn print_summary(o: &Options, name: &str, doc: &Value, variants: &[Switch]) {
    let f = |v: &Value| v.as_f64().unwrap_or(f64::NAN);
    let cpu = &doc["cpu_frame_ms"];
    let ratio = &doc["floor_ratio"];
    println!(
        "{name:<17} cpu_frame_ms p50 {:8.3} p95 {:8.3} p99 {:8.3} max {:8.3}  (x floor: p50 {:6.1}, p95 {:6.1})",
        f(&cpu["p50"]),
        f(&cpu["p95"]),
        f(&cpu["p99"]),
        f(&cpu["max"]),
        f(&ratio["p50"]),
        f(&ratio["p95"])
    );
    println!(
        "{:<17} of it (p50): update {:.3} ms, prepare and record {:.3} ms, fence wait {:.3} ms",
        "",
        f(&doc["cpu_update_ms"]["p50"]),
        f(&doc["cpu_record_ms"]["p50"]),
        f(&doc["fence_wait_ms"]["p50"])
    );
    println!("{:<17} render scale {} (frames at each: {})", "", o.render_scale.describe(), doc["render_scale"]["frames_at"]);
    for switch in variants {
        let c = &doc["variants"][switch.key()]["cpu_frame_ms"];
        let ratio = f(&c["p50"]) / f(&cpu["p50"]);
        println!("{:<17} cpu_frame_ms p50 {:8.3} p95 {:8.3} ({}: p50 x{ratio:.2} of the default)", "", f(&c["p50"]), f(&c["p95"]), switch.label());
    }
    if !o.quiet {
        println!("{:<17} counters {}", "", doc["counters"]);
    }
}

/// Write through a temporary file and rename, so a reader never sees half a file.
fn write_atomic(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    let tmp = path.with_extension(format!("json.tmp-{}", std::process::id()));
    std::fs::write(&tmp, bytes).map_err(|e| anyhow::anyhow!("writing {}: {e}", tmp.display()))?;
    std::fs::rename(&tmp, path).map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))?;
    Ok(())
}

/// Warm-up frames, then measured ones; series i > 0 holds variant i - 1's frames.
fn measure(gpu: &Gpu, o: &Options, renderer: &mut Renderer, target: &mut Offscreen, s: &mut Setup) -> anyhow::Result<Vec<Series>> {
    let mut series: Vec<Series> = (0..1 + s.variants.len()).map(|_| Series::default()).collect();
    let per_frame = series.len();
    // Each series adapts its render scale to its own frames (a variant's cost is its own).
    let mut scalers = vec![ScaleController::new(o.render_scale); per_frame];
    for k in 0..(o.warmup + o.frames) * per_frame {
        // A frame's variants share its simulation step, so all see the same content.
        let (frame, variant) = (k / per_frame, k % per_frame);
        select(renderer, &s.variants, variant);
        std::mem::swap(&mut renderer.render_scale, &mut scalers[variant]);
        let t = Instant::now();
        if variant == 0 {
            renderer.animate(&mut s.scene, FRAME_S as f32);
            s.world.update(FRAME_S);
        }
        let camera = (s.camera)(frame);
        level::prepare_frame(&s.world, renderer, &s.scene, &camera);
        let update_ms = t.elapsed().as_secs_f64() * 1e3;
        let timing = target.render(gpu, renderer, &s.scene, &camera, &s.lighting, false)?;
        let cpu_ms = t.elapsed().as_secs_f64() * 1e3;
        // The frame's GPU time moves its series' scale for that series' next frame.
        let scale = renderer.frame_scale();
        renderer.render_scale.observe(scale, timing.gpu_ms.unwrap_or(cpu_ms) as f32);
        std::mem::swap(&mut renderer.render_scale, &mut scalers[variant]);
        if frame < o.warmup {
            continue;
        }
        let out = &mut series[variant];
        out.cpu_ms.push(cpu_ms);
        out.update_ms.push(update_ms);
        out.record_ms.push(timing.record_ms);
        out.wait_ms.push(timing.wait_ms);
        out.gpu_ms.extend(timing.gpu_ms);
        out.scales.push(scale as f64);
        out.passes.extend(renderer.profile(gpu, 0));
        out.counters = counters(gpu, renderer, &s.scene, &s.world);
        let c = renderer.visibility.counts;
        let frame_counts = [(c.cull.culled - c.cull.occlusion_culled) as u64, c.cull.occlusion_tested as u64, c.cull.occlusion_culled as u64, c.cull.visible as u64, c.triangles];
        for (t, n) in out.totals.iter_mut().zip(frame_counts) {
            *t += n;
        }
    }
    for (variant, out) in series.iter_mut().enumerate() {
        let scale = out.scales.last().copied().unwrap_or(1.0) as f32;
        let shaded = fragments_shaded(gpu, renderer, target, s, o.warmup + o.frames - 1, variant, scale)?;
        out.counters.insert("fragments_shaded".into(), json!(shaded));
    }
    Ok(series)
}

/// Fragments the shading pass shades in the last frame (same camera and render scale `scale`, no
/// simulation step), from one more frame, not timed, with the shader's fragment counter on: the
/// counter costs an atomic per fragment, and lavapipe's pipeline statistics count fragments the
/// depth test then rejects, so they cannot show what the pre-pass saves.
fn fragments_shaded(gpu: &Gpu, renderer: &mut Renderer, target: &mut Offscreen, s: &Setup, last: usize, variant: usize, scale: f32) -> anyhow::Result<Option<u32>> {
    let camera = (s.camera)(last);
    select(renderer, &s.variants, variant);
    renderer.count_fragments = true;
    // The series' scale, not the renderer's own controller (the measured frames swapped theirs in).
    let own = std::mem::replace(&mut renderer.render_scale, ScaleController::new(RenderScale::Fixed(scale)));
    level::prepare_frame(&s.world, renderer, &s.scene, &camera);
    let frame = target.render(gpu, renderer, &s.scene, &camera, &s.lighting, false);
    let shaded = renderer.fragment_count(0);
    renderer.render_scale = own;
    renderer.count_fragments = false;
    select(renderer, &s.variants, 0);
    frame?;
    Ok(shaded)
}

/// The frame's exact counters (the last measured frame's end up in the JSON).
fn counters(gpu: &Gpu, r: &Renderer, scene: &GpuScene, world: &World) -> Map<String, Value> {
    let c = r.visibility.counts;
    let mut m = Map::new();
    let mut put = |k: &str, v: Value| {
        m.insert(k.into(), v);
    };
    put("instances", json!(scene.instances.len()));
    // The cull counts include the boids (culled with the scene), as in the overlay.
    put("cull_tested", json!(c.cull.tested));
    put("culled", json!(c.cull.culled));
    put("drawn", json!(c.cull.visible));
    // Of the culled, those occlusion culling hid (`drawn` is after both).
    put("occlusion_tested", json!(c.cull.occlusion_tested));
    put("occlusion_culled", json!(c.cull.occlusion_culled));
    put("occluders", json!(r.visibility.occlusion_culler.stats.occluders));
    put("triangles", json!(c.triangles));
    put("draw_calls", json!(r.draw_calls));
    put("lod_histogram", json!(c.lod_histogram));
    put("particles", json!(c.particles));
    put("particles_live", json!(world.emitters.iter().map(|e| e.particles.len()).sum::<usize>()));
    put("boids", json!(r.boids.boids.len()));
    put("boids_drawn", json!(c.boids));
    put("shadow_casters", json!(r.shadow_casters));
    put("sim_steps", json!(world.clock.steps));
    if let Some(a) = &r.animation {
        put("animated_instances", json!(a.instances.len()));
        put("skinning_jobs", json!(a.jobs));
        put("skinning_dispatches", json!(a.dispatches));
        put("skinned_vertices", json!(a.skinned_vertices));
    }
    if let Some(p) = r.profile(gpu, 0) {
        put("prepass_fragment_invocations", json!(p.invocations("prepass").map(|p| p.fragment)));
        put("shading_vertex_invocations", json!(p.invocations("shading").map(|s| s.vertex)));
        put("shading_fragment_invocations", json!(p.invocations("shading").map(|s| s.fragment)));
    }
    m
}

/// p50/p95/p99/max/mean of samples (nearest rank, as everywhere in the engine); nulls when empty.
fn summary(v: &[f64]) -> Value {
    let p = |q: f64| percentile(v, q);
    let max = v.iter().copied().reduce(f64::max);
    let mean = (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
    json!({ "p50": p(50.0), "p95": p(95.0), "p99": p(99.0), "max": max, "mean": mean, "count": v.len() })
}

/// The scenario's percentiles as multiples of the floor's.
fn ratios(v: &[f64], floor: &Value) -> Value {
    let s = summary(v);
    let r = |k: &str| match (s[k].as_f64(), floor[k].as_f64()) {
        (Some(a), Some(b)) if b > 0.0 => json!(a / b),
        _ => Value::Null,
    };
    json!({ "p50": r("p50"), "p95": r("p95"), "p99": r("p99") })
}

/// Percentiles of every pass's GPU ms (0 in frames it did not run), by pass name: each of the
/// renderer's `names` (whether or not it ran) and any other pass a frame ran. The graph times
/// every pass, so a new one appears here without code.
fn pass_summary(p: &[FrameProfile], names: &[&'static str]) -> Value {
    let mut names = names.to_vec();
    for f in p {
        for pass in &f.passes {
            if !names.contains(&pass.name) {
                names.push(pass.name);
            }
        }
    }
    let m: Map<String, Value> = names.iter().map(|&n| (n.to_string(), summary(&p.iter().map(|f| f.ms(n)).collect::<Vec<_>>()))).collect();
    Value::Object(m)
}
