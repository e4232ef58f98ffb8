//! Frame-time benchmarks on the real device (headless). Each scenario compares settings in the
//! same run, interleaved, and prints medians and ratios; counters are exact.
//!
//!     bench [--instances N] [--frames F] [--width W --height H] [--device auto|cpu|gpu|NAME]
//!
//! Scenario "instances": N cubes (default 100 000) on a square grid, a camera looking across
//! it. Reports CPU culling + LOD time per frame (median), and GPU time per frame with culling
//! and the depth pre-pass each on and off.

use engine::camera::Camera;
use engine::gpu::{DevicePreference, Gpu, GpuOptions};
use engine::headless::{Offscreen, OFFSCREEN_FORMAT};
use engine::renderer::{Lighting, Renderer};
use engine::scene::GpuScene;
use engine::stats::median;
use glam::{Mat4, Vec3};
use pack::{Material, Mesh, MeshLod, Node, Pack, PackBuilder, Submesh, Vertex};
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
            "-h" | "--help" => return Err("usage: bench [--instances N] [--frames F] [--width W --height H] [--device auto|cpu|gpu|NAME]".into()),
            other => return Err(format!("unknown argument '{other}' (try --help)")),
        }
    }
    Ok(a)
}

/// A unit cube mesh placed `n` times on a square grid 3 m apart, heights varied.
fn instances_pack(n: usize) -> Pack {
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
    let vertices = b.push_bytes(Vertex::slice_as_bytes(&verts));
    let bytes: Vec<u8> = idx.iter().flat_map(|i| i.to_le_bytes()).collect();
    let indices = b.push_bytes(&bytes);
    b.manifest.materials.push(Material::default());
    b.manifest.meshes.push(Mesh {
        name: "cube".into(),
        lods: vec![MeshLod { vertices, vertex_count: 24, indices, index_count: 36, submeshes: vec![Submesh { first_index: 0, index_count: 36, material: 0, lightmap_page: None }], error: 0.0 }],
        bounds_min: [-0.5; 3],
        bounds_max: [0.5; 3],
        is_static: false,
    });
    let side = (n as f64).sqrt().ceil() as usize;
    for i in 0..n {
        let (x, z) = ((i % side) as f32 * 3.0, (i / side) as f32 * 3.0);
        let m = Mat4::from_translation(Vec3::new(x, ((i * 7919) % 5) as f32 * 0.5, -z));
        b.manifest.nodes.push(Node { name: format!("c{i}"), parent: None, local: m.to_cols_array(), mesh: Some(0) });
    }
    b.finish()
}

fn run(args: &Args) -> anyhow::Result<usize> {
    let gpu = Gpu::new(&GpuOptions { validation: false, device: args.device.clone(), surface_extensions: vec![] })?;
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
    println!(
        "scenario instances: {} cubes; culling tested {}, culled {}, drawn {}, triangles drawn {}",
        args.instances, c.cull.tested, c.cull.culled, c.cull.visible, c.triangles
    );
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
            if let (0, Some(p)) = (k, renderer.pass_times_ms(&gpu, 0)) {
                for (v, ms) in pass_ms.iter_mut().zip([p.shadow_ms, p.prepass_ms, p.shading_ms, p.tonemap_ms]) {
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
    if b { "on" } else { "off" }
}

fn main() -> ExitCode {
    let args = match parse() {
        Ok(a) => a,
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
