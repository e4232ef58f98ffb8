//! Frame-time benchmarks on the real device (headless). Each scenario compares settings in the
//! same run, interleaved, and prints medians and ratios; counters are exact.
//!
//!     bench [--instances N] [--frames F] [--width W --height H] [--device auto|cpu|gpu|NAME]
//!     bench sim [--boids N,N,..] [--brute-max N] [--particles N,N,..] [--steps S]
//!
//! Scenario "instances": N cubes (default 100 000) on a square grid, a camera looking across
//! it. Reports CPU culling + LOD time per frame (median), and GPU time per frame with culling
//! and the depth pre-pass each on and off.
//!
//! Subcommand "skinned" (`bench skinned --pack build/golem.pack [--characters N] [--frames F]`):
//! N copies (default 64) of the pack's skinned character on a grid, each playing clip 0 at its
//! own phase, all in view. Reports the skinning pass's GPU time per frame (timestamps) and the
//! CPU time of advancing every animator per frame (sampling, globals, joint matrices, bounds).
//!
//! Subcommand "sim" (CPU only, no device): boid step time for each flock size, grid against
//! brute force up to --brute-max in the same run, and particle update time.

use engine::scene::camera::Camera;
use engine::gpu::{DevicePreference, Gpu, GpuOptions};
use engine::app::headless::{Offscreen, OFFSCREEN_FORMAT};
use engine::render::renderer::{Lighting, Renderer};
use engine::scene::GpuScene;
use engine::stats::median;
use glam::{Mat4, Vec3};
use pack::{IndexFormat, Material, Mesh, MeshLod, Node, Pack, PackBuilder, Submesh, Vertex};
use std::process::ExitCode;
use std::time::Instant;

struct Args {
    instances: usize,
    frames: usize,
    width: u32,
    height: u32,
    device: DevicePreference,
}

fn parse() -> Result<Args, String> {
    let mut a = Args { instances: 100_000, frames: 5, width: 640, height: 360, device: DevicePreference::from_env() };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = |name: &str| it.next().ok_or_else(|| format!("{name} needs a value"));
        let number = |name: &str, v: String| v.parse::<usize>().map_err(|_| format!("{name}: '{v}' is not a whole number"));
        match flag.as_str() {
            "--instances" => a.instances = number("--instances", value("--instances")?)?,
            "--frames" => a.frames = number("--frames", value("--frames")?)?.max(1),
            "--width" => a.width = number("--width", value("--width")?)?.max(1) as u32,
            "--height" => a.height = number("--height", value("--height")?)?.max(1) as u32,
            "--device" => a.device = DevicePreference::parse(&value("--device")?),
            "-h" | "--help" => {
                return Err(format!("usage: bench [--instances N] [--frames F] [--width W --height H] [--device auto|cpu|gpu|NAME]\n       bench sim --help (particle and boid timings, CPU only)\n       bench skinned --help (the skinning pass against the CPU reference)\n\n{}", scenarios::USAGE))
            }
            other => return Err(format!("unknown argument '{other}' (try --help)")),
        }
    }
    Ok(a)
}

/// A unit cube mesh placed `n` times on a square grid 3 m apart, heights varied.
fn instances_pack(n: usize) -> Pack {
    boxes_pack(cube_grid(n))
}

/// `n` placements on a square grid 3 m apart, heights varied (the culling scenes).
fn cube_grid(n: usize) -> impl Iterator<Item = Mat4> {
    let side = (n as f64).sqrt().ceil() as usize;
    (0..n).map(move |i| {
        let (x, z) = ((i % side) as f32 * 3.0, (i / side) as f32 * 3.0);
        Mat4::from_translation(Vec3::new(x, ((i * 7919) % 5) as f32 * 0.5, -z))
    })
}

/// A unit cube mesh, one instance per placement, in the order given (which is draw order).
fn boxes_pack(placements: impl Iterator<Item = Mat4>) -> Pack {
    boxes_builder(placements).finish()
}

/// `boxes_pack` before it is finished, for scenes that add meshes of their own.
fn boxes_builder(placements: impl Iterator<Item = Mat4>) -> PackBuilder {
    let mut b = PackBuilder::new("bench", "bench");
    let mut verts = Vec::new();
    let mut idx: Vec<u32> = Vec::new();
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let mut nrm = [0.0f32; 3];
            nrm[axis] = sign;
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let base = verts.len() as u32;
            for (a, c) in [(-1.0f32, -1.0f32), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                let mut p = [0.0f32; 3];
                p[axis] = 0.5 * sign;
                p[u] = 0.5 * a;
                p[v] = 0.5 * c * sign;
                verts.push(Vertex { position: p, normal: nrm, tangent: [1.0, 0.0, 0.0, 1.0], color: [200, 200, 200, 255], ..Default::default() });
            }
            idx.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
        }
    }
    let (vertices, uv_ranges) = b.push_vertices(&verts);
    let indices = b.push_bytes(&IndexFormat::U16.encode(&idx));
    b.manifest.materials.push(Material::default());
    b.manifest.meshes.push(Mesh {
        name: "cube".into(),
        lods: vec![MeshLod { vertices, uv_ranges, vertex_count: 24, indices, index_count: 36, index_format: IndexFormat::U16, submeshes: vec![Submesh { first_index: 0, index_count: 36, material: 0, lightmap_block: None }], error: 0.0 }],
        bounds_min: [-0.5; 3],
        bounds_max: [0.5; 3],
    });
    for (i, m) in placements.enumerate() {
        b.manifest.nodes.push(Node { name: format!("c{i}"), local: m.to_cols_array(), mesh: Some(0), ..Default::default() });
    }
    b
}

fn run(args: &Args) -> anyhow::Result<usize> {
    let gpu = Gpu::new(&GpuOptions { validation: false, device: args.device.clone(), surface_extensions: vec![], pipeline_cache: GpuOptions::default_pipeline_cache() })?;
    println!("device: {} ({:?}); {} cores", gpu.caps.device_name, gpu.caps.device_type, std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pack = instances_pack(args.instances);
    let mut target = Offscreen::new(&gpu, args.width, args.height)?;
    let mut renderer = Renderer::new(&gpu, OFFSCREEN_FORMAT, 1)?;
    let mut scene = GpuScene::upload(&gpu, &pack, renderer.layouts())?;
    // From the middle of the grid, looking along +x a little above the cubes: about a quarter
    // of them in view, most far away.
    let side = (args.instances as f64).sqrt().ceil() as f32 * 3.0;
    let camera = Camera { position: Vec3::new(0.5 * side, 6.0, -0.5 * side), yaw: -90f32.to_radians(), pitch: -8f32.to_radians(), fov_y: 60f32.to_radians(), near: 0.1 };
    let lighting = Lighting::default();

    // CPU: culling + LOD selection per frame.
    let aspect = args.width as f32 / args.height as f32;
    let mut cull_ms = Vec::new();
    for _ in 0..args.frames.max(20) {
        let t = Instant::now();
        renderer.visibility.update(&scene, camera.view_proj(aspect), camera.position, camera.fov_y, args.height as f32);
        cull_ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let c = renderer.visibility.counts;
    println!("scenario instances: {} cubes; culling tested {}, culled {}, drawn {}, triangles drawn {}", args.instances, c.cull.tested, c.cull.culled, c.cull.visible, c.triangles);
    println!("cull_ms (CPU, culling + LOD selection, median of {}): {:.3}", cull_ms.len(), median(&cull_ms).unwrap_or(0.0));

    // GPU: the four combinations, interleaved frame by frame.
    let combos = [(true, true), (true, false), (false, true), (false, false)];
    let mut gpu_ms: Vec<Vec<f64>> = vec![Vec::new(); combos.len()];
    // Per pass, for the default combination (culling and pre-pass on).
    let mut pass_ms: [Vec<f64>; 4] = Default::default();
    for _ in 0..args.frames {
        for (k, &(culling, prepass)) in combos.iter().enumerate() {
            renderer.visibility.culling = culling;
            renderer.prepass = prepass;
            let t = target.render(&gpu, &mut renderer, &scene, &camera, &lighting, false)?;
            gpu_ms[k].push(t.gpu_ms.unwrap_or(t.frame_ms));
            if let (0, Some(p)) = (k, renderer.profile(&gpu, 0)) {
                for (v, ms) in pass_ms.iter_mut().zip([p.ms_prefixed("shadow"), p.ms("prepass"), p.ms("shading"), p.ms("tonemap")]) {
                    v.push(ms);
                }
            }
        }
    }
    let med: Vec<f64> = gpu_ms.iter().map(|v| median(v).unwrap_or(0.0)).collect();
    for (k, &(culling, prepass)) in combos.iter().enumerate() {
        println!("gpu_ms culling {:<3} pre-pass {:<3}: {:9.3} (median of {})", on(culling), on(prepass), med[k], gpu_ms[k].len());
    }
    println!("ratio gpu_ms culling off / on (pre-pass on): {:.2}x", med[2] / med[0]);
    println!("ratio gpu_ms pre-pass off / on (culling on): {:.2}x", med[1] / med[0]);
    if let [Some(s), Some(a), Some(b), Some(t)] = pass_ms.each_ref().map(|v| median(v)) {
        println!("pass gpu_ms (culling on, pre-pass on, median): sun shadow {s:.3}, depth pre-pass {a:.3}, shading {b:.3}, tone map {t:.3}");
    }
    scene.destroy(&gpu);
    renderer.destroy(&gpu);
    target.destroy(&gpu);
    Ok(gpu.validation().error_count())
}

fn on(b: bool) -> &'static str {
    if b {
        "on"
    } else {
        "off"
    }
}

// The named scenarios live beside this file (a directory without main.rs is not a binary).
#[path = "bench/scenarios.rs"]
mod scenarios;
/// The demo's camera flight (demo content the flythrough scenario replays).
#[path = "demo/flight.rs"]
mod flight;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if scenarios::wanted(&args) {
        return exit_status(scenarios::parse(args), scenarios::run);
    }
    if std::env::args().nth(1).as_deref() == Some("sim") {
        return sim_bench::main(std::env::args().skip(2).collect());
    }
    if std::env::args().nth(1).as_deref() == Some("skinned") {
        return skinned_bench::main(std::env::args().skip(2).collect());
    }
    exit_status(parse(), run)
}

/// Every scenario's exit status: 0 for --help, 2 for bad arguments, 3 for validation errors, 1 for a failure.
fn exit_status<A>(args: Result<A, String>, run: impl FnOnce(&A) -> anyhow::Result<usize>) -> ExitCode {
    let args = match args {
        Ok(a) => a,
        // --help is not an error: the usage goes to stdout and the status is 0.
        Err(e) if e.starts_with("usage:") => {
            println!("{e}");
            return ExitCode::SUCCESS;
        }
        Err(e) => {
            eprintln!("bench: {e}");
            return ExitCode::from(2);
        }
    };
    match run(&args) {
        Ok(0) => ExitCode::SUCCESS,
        Ok(n) => {
            eprintln!("bench: {n} validation errors");
            ExitCode::from(3)
        }
        Err(e) => {
            eprintln!("bench: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// `bench sim`: the simulation core on the CPU (issue 8).
mod sim_bench {
    use engine::sim::boids::{BoidParams, Flock, FlockState, NeighbourSearch};
    use engine::sim::particles::{Billboard, BillboardScratch, Blend, EmitterParams, ParticleSystem, Preset};
    use engine::stats::median;
    use glam::Vec3;
    use std::process::ExitCode;
    use std::time::Instant;

    struct Args {
        boids: Vec<usize>,
        brute_max: usize,
        particles: Vec<usize>,
        steps: usize,
    }

    const USAGE: &str = "usage: bench sim [--boids N,N,..] [--brute-max N] [--particles N,N,..] [--steps S]

  --boids LIST      flock sizes to step (default 1000,10000,100000), in a ±100 m cube
  --brute-max N     also step with the O(N²) neighbour scan up to this size, interleaved with
                    the grid, and check both give the same flock (default 10000)
  --particles LIST  fountain sizes to update and turn into billboards (default 100000,1000000;
                    an empty list skips them)
  --steps S         measured steps per size (default 30)";

    fn parse(args: Vec<String>) -> Result<Args, String> {
        let mut a = Args { boids: vec![1_000, 10_000, 100_000], brute_max: 10_000, particles: vec![100_000, 1_000_000], steps: 30 };
        let list = |name: &str, v: &str| -> Result<Vec<usize>, String> {
            v.split(',').filter(|s| !s.is_empty()).map(|s| s.trim().parse::<usize>().map_err(|_| format!("{name}: '{s}' is not a whole number"))).collect()
        };
        let mut it = args.into_iter();
        while let Some(flag) = it.next() {
            let mut value = |name: &str| it.next().ok_or_else(|| format!("{name} needs a value"));
            match flag.as_str() {
                "--boids" => a.boids = list("--boids", &value("--boids")?)?,
                "--particles" => a.particles = list("--particles", &value("--particles")?)?,
                "--brute-max" => a.brute_max = list("--brute-max", &value("--brute-max")?)?.first().copied().unwrap_or(0),
                "--steps" => a.steps = list("--steps", &value("--steps")?)?.first().copied().unwrap_or(1).max(1),
                "-h" | "--help" => return Err(USAGE.into()),
                other => return Err(format!("unknown argument '{other}' (try --help)")),
            }
        }
        Ok(a)
    }

    pub fn main(args: Vec<String>) -> ExitCode {
        super::exit_status(parse(args), |args| {
            println!("sim: {} rayon threads; {} steps per measurement; h = 1/120 s", rayon::current_num_threads(), args.steps);
            for &n in &args.boids {
                boids(n, args.steps, n <= args.brute_max);
            }
            for &n in &args.particles {
                particles(n, args.steps);
            }
            Ok(0)
        })
    }

    fn ms_since(t: Instant) -> f64 {
        t.elapsed().as_secs_f64() * 1e3
    }

    /// CPU time of all this process's threads so far, in ms (Linux: the first field of each
    /// thread's schedstat, in ns). Other processes loading the machine stretch wall time but
    /// not this, so cpu_ms / threads estimates the time on an idle machine. None elsewhere.
    fn cpu_ms() -> Option<f64> {
        let mut ns = 0u64;
        for task in std::fs::read_dir("/proc/self/task").ok()? {
            let stat = std::fs::read_to_string(task.ok()?.path().join("schedstat")).ok()?;
            ns += stat.split_whitespace().next()?.parse::<u64>().ok()?;
        }
        Some(ns as f64 * 1e-6)
    }

    /// Wall ms per step (median and minimum) and CPU ms per step (mean over the run).
    struct Timing {
        wall_ms: Vec<f64>,
        cpu_ms: Option<f64>,
    }

    impl Timing {
        fn new() -> Timing {
            Timing { wall_ms: Vec::new(), cpu_ms: Some(0.0) }
        }

        fn time(&mut self, f: impl FnOnce()) {
            let (t, c) = (Instant::now(), cpu_ms());
            f();
            self.wall_ms.push(ms_since(t));
            self.cpu_ms = match (self.cpu_ms, c, cpu_ms()) {
                (Some(sum), Some(a), Some(b)) => Some(sum + (b - a)),
                _ => None,
            };
        }

        fn median(&self) -> f64 {
            median(&self.wall_ms).unwrap_or(0.0)
        }

        fn describe(&self) -> String {
            let min = self.wall_ms.iter().copied().fold(f64::INFINITY, f64::min);
            let cpu = self.cpu_ms.map_or("n/a".to_string(), |c| format!("{:.3}", c / self.wall_ms.len().max(1) as f64));
            format!("median {:9.3} min {:9.3} (of {}), cpu_ms {cpu}", self.median(), min, self.wall_ms.len())
        }
    }

    /// The CIS 565 scene (anchors §6): a ±100 m cube, rule distances 5 / 3 / 5, wandering.
    /// Grid and brute force step two copies of the same flock, interleaved step by step.
    fn boids(n: usize, steps: usize, brute: bool) {
        let h = 1.0 / 120.0;
        let start = FlockState::random(n, Vec3::splat(-100.0), Vec3::splat(100.0), 5.0, 1);
        let mut methods = vec![(NeighbourSearch::Grid, Flock::new(BoidParams::default(), start.clone()), Timing::new())];
        if brute {
            methods.push((NeighbourSearch::BruteForce, Flock::new(BoidParams::default(), start), Timing::new()));
        }
        for k in 0..steps + 2 {
            for (search, flock, timing) in methods.iter_mut() {
                if k < 2 {
                    flock.step(h, *search);
                } else {
                    timing.time(|| flock.step(h, *search));
                }
            }
        }
        let mut grid_ms = 0.0;
        for (search, flock, timing) in &methods {
            let m = timing.median();
            let c = flock.last;
            println!(
                "boids {n:>7} {:<11} step_ms {}; examined per boid {:7.1}, neighbours per boid {:5.2}",
                format!("{search:?}"),
                timing.describe(),
                c.examined as f64 / n as f64,
                c.neighbours as f64 / n as f64
            );
            if *search == NeighbourSearch::Grid {
                grid_ms = m;
            } else {
                println!("boids {n:>7} ratio brute force / grid: {:.1}x", m / grid_ms);
            }
        }
        if methods.len() == 2 {
            println!("boids {n:>7} grid and brute force flocks identical: {}", methods[0].1.state() == methods[1].1.state());
        }
    }

    /// A fountain in steady state with about `n` particles live (rate·life = n), then the
    /// update (move, kill, spawn) and the billboard fill, sorted and unsorted.
    fn particles(n: usize, steps: usize) {
        let h = 1.0 / 120.0;
        let params = EmitterParams { rate_per_s: n as f32 / 2.0, life_min_s: 1.5, life_max_s: 2.5, capacity: (n + n / 4) as u32, ..EmitterParams::preset(Preset::Fountain) };
        let mut s = ParticleSystem::new(params);
        let t = Instant::now();
        for _ in 0..(2.5 / h) as usize {
            s.step(h);
        }
        let warm_s = t.elapsed().as_secs_f64();
        let mut update = Timing::new();
        for _ in 0..steps {
            update.time(|| s.step(h));
        }
        let live = s.particles.len();
        let (mut out, mut scratch): (Vec<Billboard>, BillboardScratch) = (Vec::new(), BillboardScratch::default());
        let (camera, forward) = (Vec3::new(0.0, 2.0, 12.0), Vec3::new(0.0, -0.1, -1.0).normalize());
        let mut fill = [Timing::new(), Timing::new()];
        for k in 0..steps.min(10) + 1 {
            for (b, blend) in [Blend::Alpha, Blend::Additive].into_iter().enumerate() {
                s.params.blend = blend;
                if k == 0 {
                    s.fill_billboards(camera, forward, 0.0, &mut out, &mut scratch);
                } else {
                    fill[b].time(|| s.fill_billboards(camera, forward, 0.0, &mut out, &mut scratch));
                }
            }
        }
        let m = update.median();
        println!("particles {n:>8} live {live:>8}: update_ms {} ({:.0} M particles/s at the median); warm-up {warm_s:.1} s", update.describe(), live as f64 / m / 1e3);
        println!("particles {n:>8} billboards_ms sorted (alpha): {}", fill[0].describe());
        println!("particles {n:>8} billboards_ms unsorted (additive): {}", fill[1].describe());
    }
}

/// `bench skinned`: the skinning pass and CPU animation cost of many characters (issue 7).
mod skinned_bench {
    use super::*;
    use engine::anim::animated::AnimatedScene;

    const USAGE: &str = "usage: bench skinned --pack PACK [--characters N] [--frames F] [--width W --height H] [--device auto|cpu|gpu|NAME]";

    struct Args {
        pack: Option<std::path::PathBuf>,
        characters: usize,
        frames: usize,
        width: u32,
        height: u32,
        device: DevicePreference,
    }

    fn parse(args: Vec<String>) -> Result<Args, String> {
        let mut a = Args { pack: None, characters: 64, frames: 60, width: 640, height: 360, device: DevicePreference::from_env() };
        let mut it = args.into_iter();
        while let Some(flag) = it.next() {
            let mut value = |name: &str| it.next().ok_or_else(|| format!("{name} needs a value"));
            let number = |name: &str, v: String| v.parse::<usize>().map_err(|_| format!("{name}: '{v}' is not a whole number"));
            match flag.as_str() {
                "--pack" => a.pack = Some(value("--pack")?.into()),
                "--characters" => a.characters = number("--characters", value("--characters")?)?.max(1),
                "--frames" => a.frames = number("--frames", value("--frames")?)?.max(1),
                "--width" => a.width = number("--width", value("--width")?)?.max(1) as u32,
                "--height" => a.height = number("--height", value("--height")?)?.max(1) as u32,
                "--device" => a.device = DevicePreference::parse(&value("--device")?),
                "-h" | "--help" => return Err(USAGE.into()),
                other => return Err(format!("unknown argument '{other}' (try --help)")),
            }
        }
        if a.pack.is_none() {
            return Err(format!("--pack is required\n{USAGE}"));
        }
        Ok(a)
    }

    /// `pack` with its whole node tree copied `n` times, copy k under a root node on a grid 2 m
    /// apart; meshes, vertex data and clip keys are shared, skins, clips and node bindings are
    /// repeated with node indices moved. Clip c of copy k becomes clip c + k * clips.
    pub(super) fn replicate(pack: &Pack, n: usize) -> Pack {
        let mut out = pack.clone();
        let m = &pack.manifest;
        let (nodes, skins) = (m.nodes.len() as u32, m.animation.skins.len() as u32);
        out.manifest.nodes.clear();
        out.manifest.animation.skins.clear();
        out.manifest.animation.clips.clear();
        out.manifest.animation.nodes.clear();
        let side = (n as f32).sqrt().ceil() as usize;
        for k in 0..n as u32 {
            let base = k * (nodes + 1);
            let at = Vec3::new((k as usize % side) as f32 * 2.0, 0.0, -((k as usize / side) as f32) * 2.0);
            out.manifest.nodes.push(Node { name: format!("copy{k}"), local: Mat4::from_translation(at).to_cols_array(), ..Default::default() });
            for nd in &m.nodes {
                out.manifest.nodes.push(Node { name: format!("copy{k}/{}", nd.name), parent: Some(nd.parent.map_or(base, |p| base + 1 + p)), ..nd.clone() });
            }
            for sk in &m.animation.skins {
                out.manifest.animation.skins.push(pack::Skin { joints: sk.joints.iter().map(|j| j + base + 1).collect(), ..sk.clone() });
            }
            for c in &m.animation.clips {
                let channels = c.channels.iter().map(|ch| pack::Channel { node: ch.node + base + 1, ..ch.clone() }).collect();
                out.manifest.animation.clips.push(pack::Clip { channels, ..c.clone() });
            }
            for b in &m.animation.nodes {
                out.manifest.animation.nodes.push(pack::NodeBinding { node: b.node + base + 1, skin: b.skin.map(|s| s + k * skins), ..b.clone() });
            }
        }
        out
    }

    fn run(args: &Args) -> anyhow::Result<usize> {
        let path = args.pack.as_ref().unwrap();
        let bytes = std::fs::read(path).map_err(|e| anyhow::anyhow!("reading {}: {e}", path.display()))?;
        let single = Pack::from_bytes(&bytes).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        if single.manifest.animation.skins.is_empty() || single.manifest.animation.clips.is_empty() {
            anyhow::bail!("{} has no skin or no clip", path.display());
        }
        let pack = replicate(&single, args.characters);
        let gpu = Gpu::new(&GpuOptions { validation: false, device: args.device.clone(), surface_extensions: vec![], pipeline_cache: GpuOptions::default_pipeline_cache() })?;
        let mut target = Offscreen::new(&gpu, args.width, args.height)?;
        let mut renderer = Renderer::new(&gpu, OFFSCREEN_FORMAT, 1)?;
        let mut scene = GpuScene::upload(&gpu, &pack, renderer.layouts())?;
        let mut anim = AnimatedScene::new(&gpu, &pack, &scene, 1)?.ok_or_else(|| anyhow::anyhow!("nothing in the pack deforms"))?;
        let per_copy = single.manifest.animation.clips.len();
        for i in 0..anim.instances.len() {
            let clip = (i % args.characters) * per_copy;
            let phase = (i as f32 * 0.618_034).fract() * anim.rig.clips[clip].duration;
            anim.play(i, clip, phase, 1.0);
        }
        let animated = anim.instances.len();
        renderer.animation = Some(anim);
        // Every character at full detail, all in view: the pass skins every one each frame.
        renderer.visibility.lod_selection = false;
        // Framed on the placements, before a pose moves the bounds (as the skinned-64 scenario).
        let (lo, hi) = scene.bounds();
        renderer.animate(&mut scene, 0.0);
        let camera = Camera::framing(lo - Vec3::splat(1.0), hi + Vec3::splat(1.0));
        let (mut gpu_ms, mut cpu_ms) = (Vec::new(), Vec::new());
        for _ in 0..args.frames {
            renderer.animate(&mut scene, 1.0 / 60.0);
            target.render(&gpu, &mut renderer, &scene, &camera, &Lighting::default(), false)?;
            if let Some(t) = renderer.profile(&gpu, 0) {
                gpu_ms.push(t.ms("skinning"));
            }
            cpu_ms.push(renderer.animation.as_ref().unwrap().cpu_ms);
        }
        let wall = skinning_wall_ms(&gpu, &pack, renderer.animation.as_mut().unwrap(), args.frames)?;
        let a = renderer.animation.as_ref().unwrap();
        println!(
            "skinned: {} on {}, {} characters ({} animated instances), {} jobs in {} dispatch(es) / {} vertices skinned per frame, {} frames at {}x{}",
            path.display(),
            gpu.caps.device_name,
            args.characters,
            animated,
            a.jobs,
            a.dispatches,
            a.skinned_vertices,
            args.frames,
            args.width,
            args.height
        );
        println!("skinning pass gpu_ms per frame: median {:.3}", median(&gpu_ms).unwrap_or(f64::NAN));
        println!("skinning pass wall_ms per frame (its own fenced submit, less an empty one): median {:.3} ({:.1} M vertices/s)", wall.gpu_ms, a.skinned_vertices as f64 / wall.gpu_ms / 1e3);
        println!("CPU reference skinning (anim::skin_cpu, 1 thread), same vertices: median {:.3} ms; pass / reference = {:.2} (median of per-round ratios)", wall.cpu_ms, wall.ratio);
        println!("animation cpu_ms per frame (sample + globals + joint matrices + bounds, all characters): median {:.3}", median(&cpu_ms).unwrap_or(f64::NAN));
        scene.destroy(&gpu);
        renderer.destroy(&gpu);
        target.destroy(&gpu);
        Ok(gpu.validation().error_count())
    }

    struct WallTimes {
        gpu_ms: f64,
        cpu_ms: f64,
        ratio: f64,
    }

    /// The skinning pass timed by the wall clock: every character at LOD 0 recorded alone into
    /// a command buffer, submitted and waited for, less an empty submit; and the CPU reference
    /// skinning the same vertices with the same matrices, in the same rounds (the machine is
    /// shared: a ratio taken round by round survives noise that the absolute times do not).
    /// GPU timestamps cannot be trusted for this on lavapipe, which runs compute dispatches
    /// outside the timestamped stream (0.05 ms for 733k vertices), so the bench reports both.
    fn skinning_wall_ms(gpu: &Gpu, pack: &Pack, anim: &mut AnimatedScene, rounds: usize) -> anyhow::Result<WallTimes> {
        use engine::anim::skin_cpu::{skin_cpu, DeformData};
        let draws: Vec<engine::render::visibility::Draw> = anim.instances.iter().map(|a| engine::render::visibility::Draw { instance: a.instance, lod: 0 }).collect();
        let data: Vec<DeformData> = anim.instances.iter().map(|a| DeformData::for_node(pack, a.node as usize, 0).expect("an animated node has a mesh")).collect();
        let mut out: Vec<Vec<Vertex>> = data.iter().map(|d| vec![Vertex::default(); d.vertices.len()]).collect();
        let (mut gpu_ms, mut cpu_ms, mut ratio) = (Vec::new(), Vec::new(), Vec::new());
        for _ in 0..rounds.max(5) {
            let t = Instant::now();
            gpu.one_shot(|_| ())?;
            let empty = t.elapsed().as_secs_f64() * 1e3;
            let t = Instant::now();
            gpu.one_shot(|cb| anim.record(gpu, cb, 0, &draws, &[]))?;
            let g = (t.elapsed().as_secs_f64() * 1e3 - empty).max(0.0);
            let t = Instant::now();
            for ((a, d), o) in anim.instances.iter().zip(&data).zip(&mut out) {
                skin_cpu(d, anim.rig.node_weights(a.node as usize, &a.animator.pose), a.joint_matrices(), o);
            }
            let c = t.elapsed().as_secs_f64() * 1e3;
            std::hint::black_box(&out);
            gpu_ms.push(g);
            cpu_ms.push(c);
            ratio.push(g / c);
        }
        Ok(WallTimes { gpu_ms: median(&gpu_ms).unwrap_or(f64::NAN), cpu_ms: median(&cpu_ms).unwrap_or(f64::NAN), ratio: median(&ratio).unwrap_or(f64::NAN) })
    }

    pub fn main(args: Vec<String>) -> ExitCode {
        super::exit_status(parse(args), run)
    }
}
