//! Skinned and morphed meshes through the renderer (lavapipe in CI, validation on): the image of
//! an animated instance at time t equals the image of a static copy of the pack whose vertices
//! are the CPU reference's skinning of the same pose; the depth pre-pass with EQUAL shading
//! still covers every pixel (both passes read the same skinned buffer); and time moves the
//! image. Sample models are cooked in-process ($GLTF_SAMPLES_DIR, default ../shared/gltf-samples).

use engine::anim::skin_cpu::{skin_cpu, DeformData};
use engine::anim::route::Route;
use engine::anim::{joint_count, node_joint_matrices, Rig};
use engine::anim::animated::AnimatedScene;
use engine::scene::camera::Camera;
use engine::gpu::Gpu;
use engine::app::headless::{Offscreen, OFFSCREEN_FORMAT};
use engine::render::renderer::{Lighting, Renderer, CLEAR_COLOR};
use engine::render::visibility::LOD_BUCKETS;
use engine::scene::{world_transforms, GpuScene};
use glam::{Mat4, Vec3};
use pack::{Pack, Vertex};

mod common;
use common::{assert_clean, cook, gpu, samples};

const W: u32 = 96;
const H: u32 = 72;

/// The pack with clip 0 at `time` baked in: every deforming node's LODs replaced by the CPU
/// reference's skinned (world-space) vertices, the node placed at the identity, its bounds
/// refitted, and no animation section left, so the renderer draws it as ordinary static data.
fn baked(pack: &Pack, time: f32) -> Pack {
    let mut out = pack.clone();
    let rig = Rig::from_pack(pack);
    let mut pose = rig.new_pose();
    rig.sample(0, time, true, &mut pose);
    rig.update_globals(&mut pose);
    let world = world_transforms(&pack.manifest.nodes);
    for node in 0..pack.manifest.nodes.len() {
        if !engine::anim::animated::animated_node(pack, node) {
            continue;
        }
        let mesh = pack.manifest.nodes[node].mesh.unwrap() as usize;
        let mut joints = vec![Mat4::IDENTITY; joint_count(pack, node)];
        node_joint_matrices(pack, &rig, node, &pose, &mut joints);
        let weights = rig.node_weights(node, &pose).to_vec();
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for lod in 0..pack.manifest.meshes[mesh].lods.len() {
            let data = DeformData::for_node(pack, node, lod).unwrap();
            let mut v = data.vertices.clone();
            skin_cpu(&data, &weights, &joints, &mut v);
            for p in &v {
                lo = lo.min(Vec3::from(p.position));
                hi = hi.max(Vec3::from(p.position));
            }
            let l = &pack.manifest.meshes[mesh].lods[lod];
            let r = l.vertices;
            out.data[r.offset as usize..(r.offset + r.len) as usize].copy_from_slice(&pack::encode_vertices_with(&v, &l.uv_ranges));
        }
        out.manifest.meshes[mesh].bounds_min = lo.to_array();
        out.manifest.meshes[mesh].bounds_max = hi.to_array();
        // World = parent world x local = identity: the vertices are already in world space.
        let parent = pack.manifest.nodes[node].parent.map_or(Mat4::IDENTITY, |p| world[p as usize]);
        out.manifest.nodes[node].local = parent.inverse().to_cols_array();
    }
    out.manifest.animation = Default::default();
    out
}

struct Frame {
    pixels: Vec<u8>,
    /// Pixels not showing the clear colour.
    covered: usize,
    /// Instances drawn per LOD (the renderer's histogram).
    lods: [u32; LOD_BUCKETS],
}

fn clear_bytes() -> [u8; 3] {
    let enc = |l: f32| {
        let c = if l <= 0.0031308 { l * 12.92 } else { 1.055 * l.powf(1.0 / 2.4) - 0.055 };
        (c.clamp(0.0, 1.0) * 255.0).round() as i32
    };
    [enc(CLEAR_COLOR[0]) as u8, enc(CLEAR_COLOR[1]) as u8, enc(CLEAR_COLOR[2]) as u8]
}

fn frame(pixels: Vec<u8>) -> Frame {
    let clear = clear_bytes();
    let covered = pixels.chunks_exact(4).filter(|p| (0..3).any(|c| (p[c] as i32 - clear[c] as i32).abs() > 1)).count();
    Frame { pixels, covered, lods: [0; LOD_BUCKETS] }
}

/// Render `pack` once; with `time`, its animated instances play clip 0 from that time (advanced
/// by 0 s), otherwise the pack is drawn as it is.
fn render(gpu: &Gpu, pack: &Pack, camera: &Camera, time: Option<f32>, prepass: bool) -> Frame {
    let mut target = Offscreen::new(gpu, W, H).unwrap();
    let mut renderer = Renderer::new(gpu, OFFSCREEN_FORMAT, 1).unwrap();
    renderer.prepass = prepass;
    let mut scene = GpuScene::upload(gpu, pack, renderer.layouts()).unwrap();
    if let Some(t) = time {
        let mut anim = AnimatedScene::new(gpu, pack, &scene, 1).unwrap().expect("the pack has animated instances");
        for i in 0..anim.instances.len() {
            anim.play(i, 0, t, 1.0);
        }
        renderer.animation = Some(anim);
        renderer.animate(&mut scene, 0.0);
    }
    target.render(gpu, &mut renderer, &scene, camera, &Lighting::default(), true).unwrap();
    if time.is_some() {
        let a = renderer.animation.as_ref().unwrap();
        assert!(a.dispatches > 0, "no skinning dispatch was recorded");
    }
    let px = target.pixels().to_vec();
    let lods = renderer.visibility.counts.lod_histogram;
    scene.destroy(gpu);
    renderer.destroy(gpu);
    target.destroy(gpu);
    Frame { lods, ..frame(px) }
}

/// A camera framing the baked pose's bounds.
fn camera_for(gpu: &Gpu, pack: &Pack) -> Camera {
    let renderer = Renderer::new(gpu, OFFSCREEN_FORMAT, 1).unwrap();
    let mut scene = GpuScene::upload(gpu, pack, renderer.layouts()).unwrap();
    let (lo, hi) = scene.bounds();
    scene.destroy(gpu);
    let mut r = renderer;
    r.destroy(gpu);
    Camera::framing(lo, hi)
}

fn max_channel_difference(a: &[u8], b: &[u8]) -> (i32, usize) {
    let mut worst = (0, 0);
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        let d = (*x as i32 - *y as i32).abs();
        if d > worst.0 {
            worst = (d, i / 4);
        }
    }
    worst
}

#[test]
fn an_animated_instance_renders_like_its_pose_baked_into_a_static_mesh() {
    let Some(dir) = samples() else { return };
    let gpu = gpu();
    // (model, time): times inside each clip, away from its keys, where the pose is deformed.
    for (name, time) in [("SimpleSkin", 1.3f32), ("RiggedSimple", 0.9), ("SimpleMorph", 0.7)] {
        let pack = cook(&dir, name);
        let reference_pack = baked(&pack, time);
        let camera = camera_for(&gpu, &reference_pack);
        let reference = render(&gpu, &reference_pack, &camera, None, true);
        let animated = render(&gpu, &pack, &camera, Some(time), true);
        assert!(reference.covered > (W * H / 50) as usize, "{name}: the baked pose covers only {} pixels", reference.covered);
        let (worst, at) = max_channel_difference(&reference.pixels, &animated.pixels);
        println!(
            "{name} at {time} s: {} pixels covered (baked {}), largest channel difference {worst} at pixel {at}",
            animated.covered, reference.covered
        );
        assert_eq!(animated.covered, reference.covered, "{name}: the silhouettes differ");
        assert!(worst <= 1, "{name}: pixel {} differs by {worst} steps from the CPU-skinned static mesh", at);
        // The pose must show: the pack drawn undeformed (bind pose, no skinning) looks different.
        let bind = render(&gpu, &pack, &camera, None, true);
        assert!(bind.pixels != reference.pixels, "{name}: the pose at {time} s renders like the bind pose");
    }
    assert_clean(&gpu);
}

#[test]
fn the_prepass_and_equal_shading_see_identical_skinned_positions() {
    // If the pre-pass and the shading pass read different positions, depth EQUAL would reject
    // fragments and leave holes of clear colour; the image must equal one without a pre-pass.
    let Some(dir) = samples() else { return };
    let gpu = gpu();
    let pack = cook(&dir, "RiggedSimple");
    let camera = camera_for(&gpu, &baked(&pack, 0.9));
    let with = render(&gpu, &pack, &camera, Some(0.9), true);
    let without = render(&gpu, &pack, &camera, Some(0.9), false);
    assert!(with.covered > 0);
    assert_eq!(with.covered, without.covered, "the pre-pass changed the coverage");
    assert!(with.pixels == without.pixels, "the pre-pass changed the image");
    assert_clean(&gpu);
}

#[test]
fn an_animated_instance_changes_between_two_times() {
    let Some(dir) = samples() else { return };
    let gpu = gpu();
    let pack = cook(&dir, "RiggedSimple");
    let camera = camera_for(&gpu, &baked(&pack, 0.9));
    let a = render(&gpu, &pack, &camera, Some(0.3), true);
    let b = render(&gpu, &pack, &camera, Some(1.7), true);
    let changed = a.pixels.chunks_exact(4).zip(b.pixels.chunks_exact(4)).filter(|(x, y)| x != y).count();
    println!("{changed} pixels changed between 0.3 s and 1.7 s");
    assert!(changed > (W * H / 100) as usize, "only {changed} pixels changed");
    assert_clean(&gpu);
}

#[test]
fn the_culling_sphere_of_an_animated_instance_holds_every_skinned_vertex() {
    // The sphere comes from the joints plus a bind-pose margin; check it against the CPU
    // reference's vertices over the whole clip, so a sphere that is too small (culling a visible
    // character) fails here.
    let Some(dir) = samples() else { return };
    let gpu = gpu();
    for name in ["SimpleSkin", "RiggedSimple", "SimpleMorph"] {
        let pack = cook(&dir, name);
        let renderer = Renderer::new(&gpu, OFFSCREEN_FORMAT, 1).unwrap();
        let mut scene = GpuScene::upload(&gpu, &pack, renderer.layouts()).unwrap();
        let mut anim = AnimatedScene::new(&gpu, &pack, &scene, 1).unwrap().unwrap();
        let duration = anim.rig.clips[0].duration;
        let mut worst = f32::INFINITY;
        for step in 0..24 {
            let t = duration * step as f32 / 23.0;
            for i in 0..anim.instances.len() {
                anim.play(i, 0, t, 1.0);
            }
            anim.advance(&mut scene, 0.0);
            let rig = Rig::from_pack(&pack);
            let mut pose = rig.new_pose();
            rig.sample(0, t, true, &mut pose);
            rig.update_globals(&mut pose);
            for a in &anim.instances {
                let node = a.node as usize;
                let data = DeformData::for_node(&pack, node, 0).unwrap();
                let mut joints = vec![Mat4::IDENTITY; joint_count(&pack, node)];
                node_joint_matrices(&pack, &rig, node, &pose, &mut joints);
                let mut v = data.vertices.clone();
                skin_cpu(&data, rig.node_weights(node, &pose), &joints, &mut v);
                let s = scene.instances.spheres();
                let i = a.instance as usize;
                let (c, r) = (Vec3::new(s.x[i], s.y[i], s.z[i]), s.r[i]);
                for p in &v {
                    let slack = r - (Vec3::from(p.position) - c).length();
                    worst = worst.min(slack / r);
                    assert!(slack >= -1e-4 * r, "{name} at {t} s: a vertex lies {} outside the culling sphere (radius {r})", -slack);
                }
            }
        }
        // Conservative but not absurd: the tightest vertex comes within half the radius of the edge.
        println!("{name}: smallest slack {:.3} of the radius", worst);
        assert!(worst < 0.5, "{name}: the sphere is more than twice as large as needed");
        let mut r = renderer;
        anim.destroy(&gpu);
        scene.destroy(&gpu);
        r.destroy(&gpu);
    }
    assert_clean(&gpu);
}

/// A 2 x 2 m double-sided sheet in the XY plane with two LODs of their own vertices (a 9 x 9 and
/// a 5 x 5 grid: different vertex counts, as the cooker's LOD stage makes them) and one morph
/// target, each LOD's deltas a smooth field sampled at its own vertices (the sheet's sides bend
/// down and it shears and bows out of its plane), held at weight 1 by a constant clip. Both
/// LODs' errors are 0, so LOD selection always draws the coarser one, LOD 1.
fn morph_lods_pack() -> Pack {
    use pack::{Channel, ChannelPath, Clip, DeformLod, DeformMesh, Interpolation, Material, Mesh, MeshLod, MorphTargets, Node, PackBuilder, Submesh};
    let field = |p: [f32; 3]| [0.2 * p[0] * p[1], 0.35 * (1.0 - p[0] * p[0]), 0.3 * p[0] * p[1]];
    let bytes = |v: &[f32]| -> Vec<u8> { v.iter().flat_map(|x| x.to_le_bytes()).collect() };
    let mut b = PackBuilder::new("generated", "test");
    let (mut lods, mut deform) = (Vec::new(), Vec::new());
    for n in [8u32, 4] {
        let verts: Vec<Vertex> = (0..=n)
            .flat_map(|j| (0..=n).map(move |i| (i, j)))
            .map(|(i, j)| {
                let (x, y) = (2.0 * i as f32 / n as f32 - 1.0, 2.0 * j as f32 / n as f32 - 1.0);
                Vertex { position: [x, y, 0.0], normal: [0.0, 0.0, 1.0], tangent: [1.0, 0.0, 0.0, 1.0], color: [255; 4], ..Default::default() }
            })
            .collect();
        let mut idx: Vec<u32> = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let a = j * (n + 1) + i;
                idx.extend([a, a + 1, a + n + 2, a, a + n + 2, a + n + 1]);
            }
        }
        let deltas: Vec<f32> = verts.iter().flat_map(|v| field(v.position)).collect();
        let index_format = pack::IndexFormat::for_vertices(verts.len());
        let index_bytes = index_format.encode(&idx);
        lods.push(MeshLod {
            vertices: b.push_vertices(&verts).0, uv_ranges: pack::UvRanges::fit(&verts),
            vertex_count: verts.len() as u32,
            indices: b.push_bytes(&index_bytes),
            index_count: idx.len() as u32,
            index_format,
            submeshes: vec![Submesh { first_index: 0, index_count: idx.len() as u32, material: 0, lightmap_block: None }],
            error: 0.0,
        });
        deform.push(DeformLod { skin: None, morph: Some(MorphTargets { positions: b.push_bytes(&bytes(&deltas)), normals: None }) });
    }
    b.manifest.materials.push(Material { double_sided: true, ..Default::default() });
    b.manifest.meshes.push(Mesh { name: "sheet".into(), lods, bounds_min: [-1.0, -1.0, 0.0], bounds_max: [1.0, 1.0, 0.0] });
    b.manifest.nodes.push(Node { name: "sheet".into(), mesh: Some(0), local: Mat4::IDENTITY.to_cols_array(), ..Default::default() });
    let (times, values) = (b.push_bytes(&bytes(&[0.0, 1.0])), b.push_bytes(&bytes(&[1.0, 1.0])));
    b.manifest.animation.meshes.push(DeformMesh { mesh: 0, morph_weights: vec![0.0], lods: deform });
    let channel = Channel { node: 0, path: ChannelPath::Weights, interpolation: Interpolation::Linear, key_count: 2, components: 1, times, values };
    b.manifest.animation.clips.push(Clip { name: "hold".into(), duration: 1.0, channels: vec![channel] });
    b.finish()
}

#[test]
fn a_morphed_lod_1_deforms_with_its_own_deltas() {
    // The sheet drawn at LOD 1 with the target at weight 1 must look like LOD 1's own vertices
    // plus LOD 1's own deltas (the CPU reference, baked into a static copy); LOD 0's deltas are
    // for other vertices (81, not 25), so any mix-up shows. The culling sphere holds every LOD's
    // morphed vertices.
    let gpu = gpu();
    let pack = morph_lods_pack();
    let reference_pack = baked(&pack, 0.5);
    let camera = camera_for(&gpu, &reference_pack);
    let reference = render(&gpu, &reference_pack, &camera, None, true);
    let animated = render(&gpu, &pack, &camera, Some(0.5), true);
    assert_eq!(animated.lods[..2], [0, 1], "the animated sheet is not drawn at LOD 1: {:?}", animated.lods);
    assert_eq!(reference.lods[..2], [0, 1], "the baked sheet is not drawn at LOD 1: {:?}", reference.lods);
    assert!(reference.covered > (W * H / 10) as usize, "the morphed sheet covers only {} pixels", reference.covered);
    let (worst, at) = max_channel_difference(&reference.pixels, &animated.pixels);
    println!("morphed LOD 1: {} pixels covered (baked {}), largest channel difference {worst} at pixel {at}", animated.covered, reference.covered);
    assert_eq!(animated.covered, reference.covered, "the silhouettes differ");
    assert!(worst <= 1, "pixel {at} differs by {worst} steps from LOD 1 morphed by its own deltas on the CPU");
    // The morph shows: the flat sheet (no animation) looks different.
    let flat = render(&gpu, &pack, &camera, None, true);
    assert_eq!(flat.lods[..2], [0, 1]);
    let changed = flat.pixels.chunks_exact(4).zip(reference.pixels.chunks_exact(4)).filter(|(x, y)| x != y).count();
    assert!(changed > reference.covered / 5, "the morph changed only {changed} of {} pixels", reference.covered);

    let renderer = Renderer::new(&gpu, OFFSCREEN_FORMAT, 1).unwrap();
    let mut scene = GpuScene::upload(&gpu, &pack, renderer.layouts()).unwrap();
    let mut anim = AnimatedScene::new(&gpu, &pack, &scene, 1).unwrap().unwrap();
    anim.play(0, 0, 0.5, 1.0);
    anim.advance(&mut scene, 0.0);
    let s = scene.instances.spheres();
    let i = anim.instances[0].instance as usize;
    let (c, r) = (Vec3::new(s.x[i], s.y[i], s.z[i]), s.r[i]);
    for lod in 0..2 {
        let data = DeformData::for_node(&pack, 0, lod).unwrap();
        let mut v = data.vertices.clone();
        skin_cpu(&data, &[1.0], &[Mat4::IDENTITY], &mut v);
        let outside = v.iter().map(|p| (Vec3::from(p.position) - c).length() - r).fold(f32::NEG_INFINITY, f32::max);
        assert!(outside <= 1e-4 * r, "LOD {lod}: a morphed vertex lies {outside} outside the culling sphere (radius {r})");
    }
    let mut r = renderer;
    anim.destroy(&gpu);
    scene.destroy(&gpu);
    r.destroy(&gpu);
    assert_clean(&gpu);
}

/// RiggedSimple as a level character: its nodes renamed "walker/..." (as the level cooker names a
/// spawn's nodes) and a character spawn walking `route` at 2 m/s.
fn walker_pack(dir: &std::path::Path, route: serde_json::Value) -> Pack {
    let mut pack = cook(dir, "RiggedSimple");
    for n in &mut pack.manifest.nodes {
        n.name = format!("walker/{}", n.name);
    }
    pack.manifest.spawns.push(pack::Spawn {
        name: "walker".into(),
        kind: "character".into(),
        position: [0.0; 3],
        rotation: [0.0, 0.0, 0.0, 1.0],
        params: serde_json::json!({ "route": route, "walk_speed": 2.0 }),
    });
    pack
}

#[test]
fn a_character_with_a_route_walks_it_facing_where_it_goes() {
    // RiggedSimple as a level character: its nodes renamed "walker/..." (as the level cooker
    // names a spawn's nodes) and a spawn with a route. The route replaces the spawn's placement:
    // after 1 s at 2 m/s the character has moved 2 m towards the first waypoint (+X) and turned
    // to face it, and the joint matrices (what the skinning pass uses) moved with it.
    let Some(dir) = samples() else { return };
    let gpu = gpu();
    let pack = walker_pack(&dir, serde_json::json!([[10.0, 0.0, 0.0], [10.0, 0.0, 10.0]]));
    let mut renderer = Renderer::new(&gpu, OFFSCREEN_FORMAT, 1).unwrap();
    let mut scene = GpuScene::upload(&gpu, &pack, renderer.layouts()).unwrap();
    let mut anim = AnimatedScene::new(&gpu, &pack, &scene, 1).unwrap().unwrap();
    let centre = |scene: &GpuScene, i: usize| {
        let s = scene.instances.spheres();
        Vec3::new(s.x[i], s.y[i], s.z[i])
    };
    let i = anim.instances[0].instance as usize;
    anim.play(0, 0, 0.0, 0.0); // a frozen pose: only the route moves the character
    anim.advance(&mut scene, 0.0);
    let (c0, j0) = (centre(&scene, i), anim.instances[0].joint_matrices()[0]);
    anim.advance(&mut scene, 1.0);
    let (c1, j1) = (centre(&scene, i), anim.instances[0].joint_matrices()[0]);
    // At its start the character stands on a corner of the loop (the last leg comes back to the
    // spawn), facing halfway between the two legs; 2 m on, it faces along the first leg, +X:
    // a quarter turn about +Y from +Z. So j1 = T(2, 0, 0) R_y(90 degrees) start^-1 j0.
    let start = Route::new(Vec3::ZERO, &[Vec3::new(10.0, 0.0, 0.0), Vec3::new(10.0, 0.0, 10.0)], 2.0).unwrap().placement();
    let expected = Mat4::from_translation(Vec3::new(2.0, 0.0, 0.0)) * Mat4::from_rotation_y(std::f32::consts::FRAC_PI_2) * start.inverse() * j0;
    assert!(j1.abs_diff_eq(expected, 1e-4), "joint 0 after 1 s:\n{j1}\nexpected\n{expected}");
    let moved = c1 - (Mat4::from_rotation_y(std::f32::consts::FRAC_PI_2) * start.inverse()).transform_point3(c0);
    assert!((moved - Vec3::new(2.0, 0.0, 0.0)).length() < 1e-3, "culling sphere moved by {moved}");
    anim.destroy(&gpu);
    scene.destroy(&gpu);
    renderer.destroy(&gpu);
    assert_clean(&gpu);
}

#[test]
fn a_walking_character_stays_inside_the_shadow_maps_window_along_its_route() {
    // A small static floor (2 m) and RiggedSimple walking a 10 m square route around it: the
    // scene's bounds, which the sun's map is fitted to, must follow the walker (its culling
    // sphere, from its pose), or it walks out of the map and loses its shadow. At every step the
    // whole sphere projects inside the map's window and depth range.
    let Some(dir) = samples() else { return };
    let gpu = gpu();
    let pack = walker_pack(&dir, serde_json::json!([[10.0, 0.0, 0.0], [10.0, 0.0, 10.0], [0.0, 0.0, 10.0]]));
    let mut renderer = Renderer::new(&gpu, OFFSCREEN_FORMAT, 1).unwrap();
    let mut scene = GpuScene::upload(&gpu, &pack, renderer.layouts()).unwrap();
    let mut anim = AnimatedScene::new(&gpu, &pack, &scene, 1).unwrap().unwrap();
    // The floor: the character's own mesh as a static instance, shrunk to about 2 m at the origin.
    let mesh = scene.instances[anim.instances[0].instance as usize].mesh;
    scene.spawn(engine::scene::Spawn { is_static: true, ..engine::scene::Spawn::dynamic(mesh, Mat4::from_scale(Vec3::splat(0.3))) }).unwrap();
    let walker = anim.instances[0].instance as usize;
    let towards_sun = Vec3::new(0.3, 1.0, 0.2).normalize();
    let mut worst = f32::NEG_INFINITY;
    for step in 0..40 {
        anim.advance(&mut scene, 0.5);
        renderer.shadow.prepare(&scene, towards_sun);
        let s = scene.instances.spheres();
        let (c, r) = (Vec3::new(s.x[walker], s.y[walker], s.z[walker]), s.r[walker]);
        for corner in 0..8 {
            let d = Vec3::new([-r, r][corner & 1], [-r, r][(corner >> 1) & 1], [-r, r][(corner >> 2) & 1]);
            let p = renderer.shadow.view_proj.project_point3(c + d);
            worst = worst.max(p.x.abs()).max(p.y.abs());
            assert!(p.x.abs() <= 1.0 && p.y.abs() <= 1.0 && (0.0..=1.0).contains(&p.z), "step {step}: the walker at {c} (r {r}) leaves the map: {p}");
        }
    }
    println!("walker's furthest corner in the map: {worst:.3} of the half-width");
    anim.destroy(&gpu);
    scene.destroy(&gpu);
    renderer.destroy(&gpu);
    assert_clean(&gpu);
}
