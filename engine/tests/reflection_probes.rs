//! Reflection probes at run time (issue 22; `../shared/notes/shading.md` §3), on the real device
//! with validation, with cubes the cooker's own code captures and prefilters:
//! - a mirror floor in a room whose walls glow in different colours shows, at each pixel, the
//!   wall the exact mirror ray reaches (what the box projection predicts), also where the
//!   uncorrected lookup would show another wall;
//! - a rough metal sphere under a uniform sky returns the sky's radiance times its directional
//!   albedo A + B (the furnace) within 2 %, across the sphere.

use cook_core::bake::reflection::{capture, prefilter, Cube, PREFILTER_SAMPLES};
use cook_core::bake::material::{Material as BakeMaterial, VertexAttributes};
use cook_core::bake::scene::{BakeScene, Geometry};
use engine::render::renderer::Lighting;
use engine::scene::camera::Camera;
use glam::{Mat4, Vec3, Vec4Swizzles};
use pack::{Material, PackBuilder, ReflectionProbe, ReflectionProbes, TextureFormat, Vertex};
use std::sync::atomic::AtomicBool;

mod common;
use common::frames::{pixel, screen_pixel, tone_mapped_bytes, Rig};
use common::packs::{add_baked_light, half_bits, node, push_mesh, push_uniform_probes, quad_vertices};
use common::{assert_clean, gpu};

const SIZE: u32 = 96;
/// The lightmap page's B: it makes the pack baked and sets the exposure (0.18 / (0.5 B)).
const LIGHTMAP_B: f32 = 100.0;

/// The room of the brief's §3.5 example: x, z in [-5, 5], y in [0, 4], probe at (0, 2, 0).
const ROOM_MIN: Vec3 = Vec3::new(-5.0, 0.0, -5.0);
const ROOM_MAX: Vec3 = Vec3::new(5.0, 4.0, 5.0);
const PROBE_AT: Vec3 = Vec3::new(0.0, 2.0, 0.0);
/// Each wall's emission (nits), in the cube's layer order: +X, -X, +Y, -Y, +Z, -Z walls (the
/// wall at x = +5 first).
const WALLS: [[f32; 3]; 6] = [[60.0, 0.0, 0.0], [0.0, 60.0, 0.0], [0.0, 30.0, 30.0], [30.0, 30.0, 0.0], [0.0, 0.0, 60.0], [30.0, 0.0, 30.0]];

/// The room as the baker traces it: black walls (albedo 0) glowing in `WALLS`, facing in.
fn room_scene() -> BakeScene {
    let (lo, hi) = (ROOM_MIN.to_array(), ROOM_MAX.to_array());
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    let mut materials = Vec::new();
    let mut walls = Vec::new();
    for k in 0..3 {
        for (side, at) in [hi[k], lo[k]].into_iter().enumerate() {
            let (a, b) = ((k + 1) % 3, (k + 2) % 3);
            let corner = |u: f32, v: f32| {
                let mut p = [0.0; 3];
                p[k] = at;
                p[a] = u;
                p[b] = v;
                p
            };
            let base = positions.len() as u32;
            positions.extend([corner(lo[a], lo[b]), corner(hi[a], lo[b]), corner(hi[a], hi[b]), corner(lo[a], hi[b])]);
            // Counter-clockwise seen from inside: the +k wall's normal is -k.
            let wind = if side == 0 { [[0, 2, 1], [0, 3, 2]] } else { [[0, 1, 2], [0, 2, 3]] };
            triangles.extend(wind.map(|t| t.map(|i| base + i)));
            let m = walls.len() as u32;
            materials.extend([m, m]);
            walls.push(BakeMaterial { base_color: [0.0, 0.0, 0.0, 1.0], emissive: WALLS[2 * k + side], ..BakeMaterial::default() });
        }
    }
    let geometry = Geometry { positions: &positions, triangles: &triangles, materials: &materials, attributes: VertexAttributes { uv0: None, texcoord1: None, color: None } };
    BakeScene::new(geometry, walls, vec![], vec![], None).unwrap()
}

/// A probe's cube levels as the pack stores them: half RGBA, [level][face][row][column].
fn cube_bytes(levels: &[Cube]) -> Vec<u8> {
    levels.iter().flat_map(|c| &c.texels).flat_map(|t| [t[0], t[1], t[2], 1.0].map(half_bits)).flat_map(|h| h.to_le_bytes()).collect()
}

/// Capture and prefilter a probe at `at` in `scene` as the cooker does.
fn baked_probe(scene: &BakeScene, at: Vec3, face: usize, levels: usize) -> Vec<Cube> {
    let (cube, _) = capture(scene, at.to_array(), 0, face, 4, 1, 5, &|_, _| {}, &AtomicBool::new(false)).unwrap();
    prefilter(&cube, levels, PREFILTER_SAMPLES)
}

fn push_probe(b: &mut PackBuilder, levels: &[Cube], position: Vec3, box_min: Vec3, box_max: Vec3, blend_distance: f32) {
    let data = b.push_bytes(&cube_bytes(levels));
    let probe = ReflectionProbe { name: "room".into(), position: position.to_array(), box_min: box_min.to_array(), box_max: box_max.to_array(), blend_distance, data };
    b.manifest.reflection_probes = Some(ReflectionProbes { face_size: levels[0].size as u32, levels: levels.len() as u32, format: TextureFormat::Rgba16Float, probes: vec![probe] });
}

/// The world-space ray through pixel (x, y)'s centre.
fn pixel_ray(camera: &Camera, x: u32, y: u32) -> (Vec3, Vec3) {
    let inv = camera.view_proj(1.0).inverse();
    let ndc = |depth: f32| {
        let p = inv * glam::Vec4::new((x as f32 + 0.5) / SIZE as f32 * 2.0 - 1.0, (y as f32 + 0.5) / SIZE as f32 * 2.0 - 1.0, depth, 1.0);
        p.xyz() / p.w
    };
    let (near, far) = (ndc(1.0), ndc(0.5));
    (near, (far - near).normalize())
}

/// Which wall (layer order) the ray from `o` along `d` reaches inside the room.
fn wall_hit(o: Vec3, d: Vec3) -> usize {
    let far = ((ROOM_MAX - o) / d).max((ROOM_MIN - o) / d);
    let t = far.min_element();
    let k = (0..3).find(|&k| far[k] == t).unwrap();
    2 * k + (d[k] < 0.0) as usize
}

#[test]
fn a_mirror_floor_shows_the_wall_the_box_projection_predicts() {
    let levels = baked_probe(&room_scene(), PROBE_AT, 64, 6);
    // The capture itself: each face's centre is its wall's glow.
    for (f, wall) in WALLS.iter().enumerate() {
        let centre = levels[0].texels[f * 64 * 64 + 32 * 64 + 32];
        assert_eq!(centre, *wall, "face {f}");
    }
    // The runtime: a white mirror (metal, roughness 0) floor filling the room's floor, seen
    // from near a corner, looking down across it; no other light.
    let mut b = PackBuilder::new("generated", "test");
    add_baked_light(&mut b, LIGHTMAP_B, Vec3::new(0.0, -50.0, 0.0));
    let (verts, idx) = quad_vertices();
    let floor = push_mesh(&mut b, "floor", &verts, &idx, None);
    b.manifest.meshes[floor as usize].lods[0].submeshes[0].material = 1;
    b.manifest.materials.push(Material { base_color: [1.0; 4], metallic: 1.0, roughness: 0.0, ..Material::default() });
    let lay_flat = Mat4::from_scale(Vec3::new(10.0, 10.0, 1.0));
    b.manifest.nodes.push(node("floor", Mat4::from_rotation_x(-std::f32::consts::FRAC_PI_2) * lay_flat, floor));
    push_probe(&mut b, &levels, PROBE_AT, ROOM_MIN, ROOM_MAX, 0.0);
    let pack = b.finish();
    let camera = Camera { position: Vec3::new(3.0, 3.0, 3.5), yaw: 0.6, pitch: -0.75, fov_y: 70f32.to_radians(), near: 0.05 };

    let gpu = gpu();
    let mut rig = Rig::new(&gpu, &pack, SIZE, SIZE);
    assert_eq!(rig.scene.reflection_probe_count, 1);
    rig.renderer.tonemap.saturation = 1.0;
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &camera, &Lighting::default(), true).unwrap();
    let px = rig.target.pixels().to_vec();
    let exposure = rig.scene.baked.unwrap().exposure;
    rig.renderer.reflections = false;
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &camera, &Lighting::default(), true).unwrap();
    let without = rig.target.pixels().to_vec();
    rig.destroy(&gpu);
    assert_clean(&gpu);

    let (mut checked, mut corrected) = (0, 0);
    for y in (4..SIZE).step_by(6) {
        for x in (4..SIZE).step_by(6) {
            let (o, d) = pixel_ray(&camera, x, y);
            if d.y >= -0.05 {
                continue;
            }
            let p = o + d * (-o.y / d.y);
            if p.x.abs() > 4.9 || p.z.abs() > 4.9 {
                continue;
            }
            let r = Vec3::new(d.x, -d.y, d.z);
            let truth = wall_hit(p, r);
            // Away from the walls' edges (where trilinear filtering mixes two walls).
            let far = ((ROOM_MAX - p) / r).max((ROOM_MIN - p) / r);
            let hit = p + r * far.min_element();
            let margin = (0..3).filter(|&k| k != truth / 2).map(|k| (hit[k] - ROOM_MIN[k]).min(ROOM_MAX[k] - hit[k])).fold(f32::INFINITY, f32::min);
            if margin < 0.4 {
                continue;
            }
            let naive = wall_hit(PROBE_AT, r);
            // The mirror reflects with F = 1 (white metal): the wall's glow, exposed.
            let want = tone_mapped_bytes(WALLS[truth], exposure, 1.0);
            let got = pixel(&px, SIZE, x, y);
            for c in 0..3 {
                assert!((got[c] as i32 - want[c] as i32).abs() <= 3, "pixel ({x}, {y}): floor {p:.2}, mirror ray reaches wall {truth} (uncorrected lookup: wall {naive}); got {got:?}, want {want:?}");
            }
            checked += 1;
            corrected += (naive != truth) as u32;
        }
    }
    eprintln!("{checked} floor pixels show the wall the box projection predicts; at {corrected} of them the uncorrected lookup would show another wall");
    assert!(checked >= 40 && corrected >= 10, "{checked} pixels checked, {corrected} needing the correction");
    // Off, the floor shows no probe (no other environment here: black).
    let centre = pixel(&without, SIZE, SIZE / 2, SIZE / 2);
    assert!(centre[..3].iter().all(|&c| c < 8), "reflections off: {centre:?}");
}

/// A UV sphere of radius 1: `rings` x `segments` quads, normals exact at the vertices.
fn sphere(rings: u32, segments: u32) -> (Vec<Vertex>, Vec<u32>) {
    let mut v = Vec::new();
    for i in 0..=rings {
        let theta = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..=segments {
            let phi = 2.0 * std::f32::consts::PI * j as f32 / segments as f32;
            let n = [theta.sin() * phi.cos(), theta.cos(), -theta.sin() * phi.sin()];
            v.push(Vertex { position: n, normal: n, tangent: [-phi.sin(), 0.0, -phi.cos(), 1.0], color: [255; 4], ..Default::default() });
        }
    }
    let mut idx = Vec::new();
    let row = segments + 1;
    for i in 0..rings {
        for j in 0..segments {
            let (a, b) = (i * row + j, (i + 1) * row + j);
            idx.extend([a, b, b + 1, a, b + 1, a + 1]);
        }
    }
    (v, idx)
}

#[test]
fn a_rough_metal_sphere_under_a_uniform_sky_returns_the_sky_times_its_albedo() {
    // The probe sees a uniform 80-nit sky (an empty scene); the irradiance probes say 50 nits,
    // so the furnace's 80 (A + B) can only come from the reflection probe.
    let sky = 80.0;
    let empty = BakeScene::new(Geometry { positions: &[], triangles: &[], materials: &[], attributes: VertexAttributes { uv0: None, texcoord1: None, color: None } }, vec![], vec![], vec![], Some([sky; 3])).unwrap();
    let levels = baked_probe(&empty, Vec3::ZERO, 32, 6);
    let roughness = 0.6;
    let mut b = PackBuilder::new("generated", "test");
    add_baked_light(&mut b, LIGHTMAP_B, Vec3::new(0.0, -50.0, 0.0));
    let (verts, idx) = sphere(96, 192);
    let ball = push_mesh(&mut b, "sphere", &verts, &idx, None);
    b.manifest.meshes[ball as usize].lods[0].submeshes[0].material = 1;
    b.manifest.materials.push(Material { base_color: [1.0; 4], metallic: 1.0, roughness, ..Material::default() });
    b.manifest.nodes.push(node("sphere", Mat4::IDENTITY, ball));
    push_uniform_probes(&mut b, 50.0, 0.0);
    push_probe(&mut b, &levels, Vec3::ZERO, Vec3::splat(-10.0), Vec3::splat(10.0), 1.0);
    let pack = b.finish();
    let camera = Camera { position: Vec3::new(0.0, 0.0, 3.0), yaw: 0.0, pitch: 0.0, fov_y: 50f32.to_radians(), near: 0.1 };

    let gpu = gpu();
    let mut rig = Rig::new(&gpu, &pack, SIZE, SIZE);
    rig.renderer.tonemap.saturation = 1.0;
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &camera, &Lighting::default(), true).unwrap();
    let px = rig.target.pixels().to_vec();
    let exposure = rig.scene.baked.unwrap().exposure;
    rig.destroy(&gpu);
    assert_clean(&gpu);

    // Points on the sphere at angles from the view axis; n.v from the camera there.
    for deg in [0.0f32, 20.0, 35.0, 50.0] {
        let n = Vec3::new(deg.to_radians().sin(), 0.0, deg.to_radians().cos());
        let (x, y) = screen_pixel(&camera, SIZE, SIZE, n);
        let nv = n.dot((camera.position - n).normalize());
        let (a, b) = shading::dfg(nv as f64, roughness as f64);
        let want = sky * (a + b) as f32;
        let got = pixel(&px, SIZE, x, y);
        let bytes = |l: f32| tone_mapped_bytes([l; 3], exposure, 1.0);
        eprintln!("n.v {nv:.3} at ({x}, {y}): got {:?}, want {:?} = {sky} x (A + B) = {want:.2} nits", &got[..3], bytes(want));
        for c in 0..3 {
            assert!(got[c] >= bytes(0.98 * want)[c] && got[c] <= bytes(1.02 * want)[c], "n.v {nv}: {got:?} not within 2% of {want} nits ({:?}..{:?})", bytes(0.98 * want), bytes(1.02 * want));
        }
    }
}
