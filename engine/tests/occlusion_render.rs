//! Occlusion culling (issue 23) on real frames: a scene built through the scene API with walls
//! and boxes behind, beside, above and through gaps in them, its exact counters pinned; and every
//! frame drawn with occlusion culling on is byte for byte the frame drawn with it off (the culling
//! is conservative on real content), here and along the demo's camera flight over the temple.

use engine::render::renderer::{AntiAliasing, Lighting};
use engine::render::occlusion::{OcclusionCuller, OcclusionSettings};
use engine::render::visibility::Visibility;
use engine::scene::camera::Camera;
use engine::scene::{InstanceId, Spawn};
use glam::{Mat4, Quat, Vec3};
use std::path::Path;

mod common;
use common::frames::Rig;
use common::scenes::{cube_builder, WHITE4};
use common::{assert_clean, gpu};

/// The demo's scripted flight, the one `bench`'s demo-flythrough flies.
#[path = "../src/bin/demo/flight.rs"]
#[allow(dead_code)]
mod flight;

const W: u32 = 320;
const H: u32 = 180;

fn static_box(mesh: u32, scale: Vec3, at: Vec3) -> Spawn {
    Spawn { is_static: true, ..Spawn::dynamic(mesh, Mat4::from_scale_rotation_translation(scale, Quat::IDENTITY, at)) }
}

/// The frame with occlusion culling on and off (LOD hysteresis off, so both pick the same LODs
/// whatever each drew before), read back.
fn frames(gpu: &engine::gpu::Gpu, rig: &mut Rig, camera: &Camera) -> (Vec<u8>, Vec<u8>) {
    let mut out = Vec::new();
    for on in [true, false] {
        rig.renderer.visibility.occlusion = on;
        rig.target.render(gpu, &mut rig.renderer, &rig.scene, camera, &Lighting::default(), true).unwrap();
        out.push(rig.target.pixels().to_vec());
    }
    rig.renderer.visibility.occlusion = true;
    let off = out.pop().unwrap();
    (out.pop().unwrap(), off)
}

/// Pixels that differ between two frames, for the failure message.
fn differing(a: &[u8], b: &[u8]) -> usize {
    a.chunks_exact(4).zip(b.chunks_exact(4)).filter(|(x, y)| x != y).count()
}

#[test]
fn walls_hide_what_is_behind_them_and_the_frame_does_not_change() {
    let gpu = gpu();
    // A unit cube mesh (0) and no placements: everything is spawned. Material 1 is alpha-tested.
    let mut b = cube_builder(&[], WHITE4, pack::Material::default());
    b.manifest.materials.push(pack::Material { alpha_mode: pack::AlphaMode::Mask, alpha_cutoff: 0.5, ..Default::default() });
    let pack = b.finish();
    let mut rig = Rig::new(&gpu, &pack, W, H);
    rig.renderer.visibility.policy.band = 0.0;
    let camera = Camera { position: Vec3::new(0.0, 1.5, 10.0), yaw: 0.0, pitch: 0.0, fov_y: 60f32.to_radians(), near: 0.1 };
    // Where a box's top must be, on its face 14.5 m away, to show `px` pixels above the wall's
    // top edge (y 3 on its face 9.8 m away).
    let px_per_tan = 0.5 * H as f32 / 30f32.to_radians().tan();
    let peeking = |px: f32| 1.5 + ((3.0 - 1.5) / 9.8 + px / px_per_tan) * 14.5;
    let s = &mut rig.scene;
    let mut spawn = |what: &'static str, spawn: Spawn, hidden: bool| -> (&'static str, InstanceId, bool) { (what, s.spawn(spawn).unwrap(), hidden) };
    let instances = [
        spawn("wall", static_box(0, Vec3::new(6.0, 3.0, 0.4), Vec3::new(0.0, 1.5, 0.0)), false),
        spawn("static box behind the wall", static_box(0, Vec3::ONE, Vec3::new(0.0, 1.5, -5.0)), true),
        spawn("dynamic box behind the wall", Spawn::dynamic(0, Mat4::from_translation(Vec3::new(1.0, 1.0, -4.0))), true),
        spawn("box beside the wall", static_box(0, Vec3::ONE, Vec3::new(5.0, 1.0, -4.0)), false),
        spawn("box 2 pixels over the wall's top", static_box(0, Vec3::ONE, Vec3::new(0.5, peeking(2.0) - 0.5, -5.0)), false),
        spawn("box 0.6 pixels over the wall's top", Spawn::dynamic(0, Mat4::from_translation(Vec3::new(-1.5, peeking(0.6) - 0.5, -5.0))), false),
        spawn("box in front of the wall", static_box(0, Vec3::ONE, Vec3::new(-1.0, 1.0, 3.0)), false),
        // Two thin walls 20 m away with a gap of about a pixel between them, and a slat behind
        // the gap seen through it.
        spawn("far wall, left", static_box(0, Vec3::new(3.0, 3.0, 0.05), Vec3::new(5.5, 1.5, -10.0)), false),
        spawn("far wall, right", static_box(0, Vec3::new(2.85, 3.0, 0.05), Vec3::new(8.575, 1.5, -10.0)), false),
        spawn("slat behind the gap", static_box(0, Vec3::new(0.1, 3.0, 0.1), Vec3::new(10.61, 1.5, -20.0)), false),
        spawn("box behind the far wall", static_box(0, Vec3::ONE, Vec3::new(8.0, 1.5, -16.0)), true),
        // An alpha-tested wall occludes nothing (its texels may be cut away).
        spawn("alpha-tested wall", Spawn { material: Some(1), ..static_box(0, Vec3::new(3.0, 3.0, 0.4), Vec3::new(-6.0, 1.5, -6.0)) }, false),
        spawn("box behind the alpha-tested wall", static_box(0, Vec3::ONE, Vec3::new(-6.5, 1.5, -12.0)), false),
        spawn("box behind the camera", static_box(0, Vec3::ONE, Vec3::new(0.0, 1.5, 14.0)), true),
    ];
    for aa in [AntiAliasing::Off, AntiAliasing::Msaa] {
        rig.renderer.aa = aa;
        let (on, off) = frames(&gpu, &mut rig, &camera);
        assert!(on == off, "{aa:?}: {} pixels differ with occlusion culling on", differing(&on, &off));
    }
    // The counters of the last frame drawn with occlusion culling on (`frames` renders it first,
    // then off): render it once more on.
    rig.renderer.aa = AntiAliasing::Off;
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &camera, &Lighting::default(), true).unwrap();
    let v = &rig.renderer.visibility;
    let drawn: Vec<u32> = v.draws.iter().map(|d| d.instance).collect();
    for (what, id, hidden) in instances {
        let i = rig.scene.instances.index_of(id).unwrap();
        assert_eq!(!drawn.contains(&i), hidden, "{what}: {}", if hidden { "drawn" } else { "culled" });
    }
    let c = v.counts.cull;
    let o = v.occlusion_culler.stats;
    eprintln!("synthetic scene: {c:?}; {o:?}");
    // 14 instances: 1 behind the camera (frustum), 13 in view. Occluders, largest first: the
    // walls but the alpha-tested one, the slat and the static boxes no occluder before them
    // hides (beside, over the top, in front): 7 of 12 triangles. Tested: the two static boxes
    // behind walls (before they could be occluders), the box behind the alpha-tested wall (too
    // small to occlude: 3.7 texels), the dynamic boxes and the alpha-tested wall; 3 hidden.
    assert_eq!((c.tested, c.culled, c.visible), (14, 4, 10));
    assert_eq!((c.occlusion_tested, c.occlusion_culled), (6, 3));
    assert_eq!((o.occluders, o.occluder_triangles, o.tested, o.culled), (7, 84, 6, 3));
    // Occlusion off: only the frustum culls.
    rig.renderer.visibility.occlusion = false;
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &camera, &Lighting::default(), true).unwrap();
    let c = rig.renderer.visibility.counts.cull;
    assert_eq!((c.tested, c.culled, c.visible, c.occlusion_tested, c.occlusion_culled), (14, 1, 13, 0, 0));
    rig.destroy(&gpu);
    assert_clean(&gpu);
}

/// The cooked demo level (`make cook`) along the demo's camera flight: each frame the same with
/// occlusion culling on and off; the counters are printed, not pinned (the level changes), and
/// so is the occlusion pass's CPU cost per frame at 1280x720.
#[test]
fn the_temple_along_the_demo_flight_looks_the_same_with_occlusion_culling() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../build/temple.pack");
    if !path.exists() {
        eprintln!("skipped: {} not found (`make cook` makes it)", path.display());
        return;
    }
    let pack = pack::Pack::read_file(&path).unwrap();
    let gpu = gpu();
    let mut rig = Rig::new(&gpu, &pack, 480, 270);
    rig.renderer.visibility.policy.band = 0.0;
    let (min, max) = rig.scene.bounds();
    let flight = flight::Flight::for_pack(&pack.manifest, min, max, flight::DEFAULT_SECONDS);
    const FRAMES: usize = 8;
    let (mut tested, mut culled) = (0, 0);
    for k in 0..FRAMES {
        let camera = flight.camera(k as f32 / FRAMES as f32 * flight.seconds);
        let (on, off) = frames(&gpu, &mut rig, &camera);
        // `frames` drew it on, then off: the counters of on again.
        rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &camera, &Lighting::default(), false).unwrap();
        let v = &rig.renderer.visibility;
        let (c, o) = (v.counts.cull, v.occlusion_culler.stats);
        eprintln!(
            "temple frame {k} (t {:5.2} s): {} instances, frustum culled {}, occluders {} ({} triangles), occlusion tested {} culled {}, drawn {}, triangles {}",
            k as f32 / FRAMES as f32 * flight.seconds,
            c.tested,
            c.culled - c.occlusion_culled,
            o.occluders,
            o.occluder_triangles,
            c.occlusion_tested,
            c.occlusion_culled,
            c.visible,
            v.counts.triangles
        );
        assert!(on == off, "frame {k}: {} pixels differ with occlusion culling on", differing(&on, &off));
        tested += c.occlusion_tested;
        culled += c.occlusion_culled;
    }
    eprintln!("temple: {culled} of {tested} tested instances occlusion-culled over {FRAMES} frames");

    // CPU cost of the occlusion pass: the whole visibility update (frustum, LOD, occlusion) at
    // 1280x720 with occlusion culling on less the same with it off, along 240 cameras of the
    // flight, the best of 3 passes per camera; for the default and for other buffer sizes and
    // occluder counts, with what each culls over the 240 frames.
    let cameras: Vec<Camera> = (0..240).map(|k| flight.camera(k as f32 / 240.0 * flight.seconds)).collect();
    let time = |culler: Option<OcclusionCuller>| -> (Vec<f64>, u32) {
        let mut v = Visibility::default();
        v.policy.band = 0.0;
        v.occlusion = culler.is_some();
        if let Some(c) = culler {
            v.occlusion_culler = c;
        }
        let mut culled = 0;
        let ms = cameras
            .iter()
            .map(|c| {
                let vp = c.view_proj(1280.0 / 720.0);
                let best = (0..3)
                    .map(|_| {
                        let t = std::time::Instant::now();
                        v.update(&rig.scene, vp, c.position, c.fov_y, 720.0);
                        t.elapsed().as_secs_f64() * 1e3
                    })
                    .fold(f64::INFINITY, f64::min);
                culled += v.counts.cull.occlusion_culled;
                best
            })
            .collect();
        (ms, culled)
    };
    let (without, _) = time(None);
    let defaults = OcclusionSettings::default();
    let variants = [
        ("default", OcclusionCuller::default()),
        ("256x144, 8 occluders", OcclusionCuller::new(defaults, (256, 144))),
        ("256x144, 32 occluders, 8192 triangles", OcclusionCuller::new(OcclusionSettings { max_occluders: 32, triangle_budget: 8192, ..defaults }, (256, 144))),
        ("192x108, 32 occluders, 8192 triangles", OcclusionCuller::new(OcclusionSettings { max_occluders: 32, triangle_budget: 8192, ..defaults }, (192, 108))),
        ("192x108, 4 occluders", OcclusionCuller::new(OcclusionSettings { max_occluders: 4, ..defaults }, (192, 108))),
        ("160x90, 8 occluders", OcclusionCuller::new(defaults, (160, 90))),
    ];
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    eprintln!("temple: visibility update without occlusion culling {:.3} ms a frame (mean over {} cameras)", mean(&without), cameras.len());
    for (what, culler) in variants {
        let (size, settings) = (culler.buffer().size(), culler.settings);
        let (with, culled) = time(Some(culler));
        let mut extra: Vec<f64> = with.iter().zip(&without).map(|(a, b)| a - b).collect();
        extra.sort_by(f64::total_cmp);
        eprintln!(
            "temple: occlusion pass {what} ({}x{}, {} occluders, {} triangles): mean {:.3} ms, p50 {:.3}, p95 {:.3}, max {:.3}; {culled} instances culled over the {} frames",
            size.0,
            size.1,
            settings.max_occluders,
            settings.triangle_budget,
            mean(&extra),
            extra[extra.len() / 2],
            extra[extra.len() * 95 / 100],
            extra[extra.len() - 1],
            cameras.len()
        );
    }
    rig.destroy(&gpu);
    assert_clean(&gpu);
}
