//! Directional lightmaps at run time (issue 22; `../shared/notes/shading.md` §4), on the real
//! device with validation. A sun over a plane, baked by the cooker's own path tracer: the
//! runtime's diffuse light for normals tilted by a normal map is within 3% of the irradiance the
//! baker computes for the tilted normal itself (the acceptance), and equals the reconstruction
//! `b0 (1 + 2 t·n) + E vis max(0, n·l) / π` it is meant to evaluate (to a byte).

use cook_core::bake::integrator::{bake_points, bake_points_directional, BakeSettings};
use cook_core::bake::lights::Light;
use cook_core::bake::material::{Material as BakeMaterial, VertexAttributes};
use cook_core::bake::scene::{BakeScene, Geometry};
use engine::render::renderer::Lighting;
use glam::{Mat4, Vec3};
use pack::{Material, Pack, PackBuilder, TextureFormat};
use std::sync::atomic::AtomicBool;

mod common;
use common::frames::{looking_down_neg_z, pixel, tone_mapped_bytes, Rig};
use common::packs::{half_bits, push_mesh, quad_vertices, static_node, sun, texture};
use common::{assert_clean, gpu};

const SIZE: u32 = 32;
const SUN_LUX: f32 = 60_000.0;
const SKY_NITS: f32 = 2000.0;
/// Toward the sun, 30 degrees from the zenith toward +X (the baker's +Y up).
fn towards_sun() -> Vec3 {
    Vec3::new(0.5, 3f32.sqrt() / 2.0, 0.0)
}

/// A black floor facing +Y under the sky and the sun, as the baker traces it.
fn bake_scene() -> BakeScene {
    let h = 50.0f32;
    let positions = [[-h, 0.0, h], [h, 0.0, h], [h, 0.0, -h], [-h, 0.0, -h]];
    let triangles = [[0u32, 1, 2], [0, 2, 3]];
    let geometry = Geometry { positions: &positions, triangles: &triangles, materials: &[0, 0], attributes: VertexAttributes { uv0: None, texcoord1: None, color: None } };
    let black = BakeMaterial { base_color: [0.0, 0.0, 0.0, 1.0], ..BakeMaterial::default() };
    let d = -towards_sun();
    let lights = Light::from_ir_json(&format!(r#"[{{"name":"sun","kind":"sun","intensity":{SUN_LUX},"direction":[{},{},{}]}}]"#, d.x, d.y, d.z)).unwrap();
    BakeScene::new(geometry, vec![black], vec![], lights, Some([SKY_NITS; 3])).unwrap()
}

/// The baker's view of the texel at the origin: the mean over 64 estimates of its directional
/// texel (b0 grey, b1 of the luminance, the sun's visibility), and of B for each of `normals`.
fn baked(normals: &[Vec3]) -> ((f32, Vec3, f32), Vec<f32>) {
    let scene = bake_scene();
    let settings = BakeSettings { samples: 256, bounces: 1, probe_samples: 0, seed: 21 };
    let points = vec![[0.0f32; 3]; 64];
    let cancel = AtomicBool::new(false);
    let texels = bake_points_directional(&scene, &points, &vec![[0.0, 1.0, 0.0]; 64], None, &settings, &|_, _| {}, &cancel).unwrap().texels;
    let n = texels.len() as f32;
    let b0 = texels.iter().map(|t| t.b0[1]).sum::<f32>() / n;
    let b1 = texels.iter().map(|t| Vec3::from(t.b1[1])).sum::<Vec3>() / n;
    let vis = texels.iter().map(|t| t.sun_visibility).sum::<f32>() / n;
    let tilted = normals
        .iter()
        .map(|nrm| {
            let b = bake_points(&scene, &points, &vec![nrm.to_array(); 64], None, &BakeSettings { seed: 22, ..settings.clone() }, &|_, _| {}, &cancel).unwrap().b;
            b.iter().map(|v| v[1]).sum::<f32>() / n
        })
        .collect();
    ((b0, b1, vis), tilted)
}

/// Baker space (+Y up) to the test's frame, where the floor is the quad facing +Z: a quarter
/// turn about X (+Y -> +Z, +Z -> -Y).
fn to_quad(v: Vec3) -> Vec3 {
    Vec3::new(v.x, -v.z, v.y)
}

/// A static white quad facing +Z, rough, with a 1x1 normal map holding `normal_ts`, lit by a
/// uniform directional lightmap page (`b0` grey, direction `t` in the quad's frame, the sun's
/// visibility `vis`) and the sun.
fn quad_pack(normal_ts: Vec3, b0: f32, t: Vec3, vis: f32) -> Pack {
    let mut b = PackBuilder::new("generated", "test");
    let (verts, idx) = quad_vertices();
    let mesh = push_mesh(&mut b, "floor", &verts, &idx, Some(0));
    let texel: Vec<u8> = [normal_ts.x * 0.5 + 0.5, normal_ts.y * 0.5 + 0.5, normal_ts.z * 0.5 + 0.5, 1.0].iter().flat_map(|c| ((c * 65535.0).round() as u16).to_le_bytes()).collect();
    let normal = texture(&mut b, "normal", TextureFormat::Rgba16Unorm, [1, 1], &[&texel]);
    b.manifest.materials.push(Material { base_color: [1.0; 4], metallic: 0.0, roughness: 1.0, normal_texture: Some(normal), normal_scale: 1.0, ..Material::default() });
    b.manifest.nodes.push(static_node("floor", Mat4::IDENTITY, mesh, 0));
    let page: Vec<u8> = [b0, b0, b0, 1.0].map(half_bits).iter().flat_map(|h| h.to_le_bytes()).collect::<Vec<u8>>().repeat(16);
    let lightmap = texture(&mut b, "lightmap0", TextureFormat::Rgba16Float, [4, 4], &[&page]);
    // The direction's bytes 128 + 127 t, and the sun's visibility as alpha.
    let dir: Vec<u8> = [t.x, t.y, t.z].map(|c| (128.0 + (127.0 * c).round()) as u8).into_iter().chain([(vis * 255.0).round() as u8]).collect::<Vec<u8>>().repeat(16);
    let direction = texture(&mut b, "lightmap0 direction", TextureFormat::Rgba8Unorm, [4, 4], &[&dir]);
    b.manifest.lightmap = Some(pack::LightmapLayout { texels_per_metre: 2.0, pages: vec![[4, 4]], padding: 2, textures: vec![lightmap], directions: vec![direction], log_average: None, samples: None });
    b.manifest.lights.push(sun(SUN_LUX, to_quad(towards_sun()), 0.0));
    b.finish()
}

#[test]
fn a_normal_mapped_plane_under_a_baked_sun_shades_as_the_baker_lights_tilted_normals() {
    // Normal-map tilts toward +X (the sun's side) and away from it, in the baker's frame.
    let tilts = [-60.0f32, -30.0, 0.0, 30.0, 60.0];
    let normals: Vec<Vec3> = tilts.iter().map(|d| Vec3::new(d.to_radians().sin(), d.to_radians().cos(), 0.0)).collect();
    let ((b0, b1, vis), tilted) = baked(&normals);
    let t = to_quad(b1 / (2.0 * b0));
    eprintln!("baked texel: b0 {b0:.1} nits, b1 {b1:.1?}, |t| {:.3}, sun visibility {vis}", t.length());
    assert_eq!(vis, 1.0, "nothing shades the floor");
    let gpu = gpu();
    for ((deg, n), want_b) in tilts.iter().zip(&normals).zip(&tilted) {
        let n_quad = to_quad(*n);
        // The quad's tangent is +X and its normal +Z: a tangent-space normal (sin, 0, cos).
        let n_ts = Vec3::new(n_quad.x, 0.0, n_quad.z);
        let pack = quad_pack(n_ts, b0, t, vis);
        let mut rig = Rig::new(&gpu, &pack, SIZE, SIZE);
        assert!(rig.scene.directional_lightmaps);
        // Diffuse only: the white dielectric's specular would add the sun's highlight.
        (rig.renderer.specular, rig.renderer.tonemap.saturation) = (false, 1.0);
        rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &looking_down_neg_z(3.0), &Lighting::default(), true).unwrap();
        let got = pixel(rig.target.pixels(), SIZE, SIZE / 2, SIZE / 2);
        let exposure = rig.scene.baked.unwrap().exposure;
        rig.destroy(&gpu);
        // What the shader evaluates: clamped MonoSH plus the sun (white albedo: radiance = B).
        let q = |c: f32| (128.0 + (127.0 * c).round() - 128.0) / 127.0;
        let t_stored = Vec3::new(q(t.x), q(t.y), q(t.z));
        let runtime_b = b0 * (1.0 + 2.0 * t_stored.dot(n_quad)).max(0.0) + SUN_LUX * vis * n_quad.dot(to_quad(towards_sun())).max(0.0) / std::f32::consts::PI;
        let bytes = |b: f32| tone_mapped_bytes([b; 3], exposure, 1.0);
        eprintln!("tilt {deg:+}: pixel {:?}; runtime B {runtime_b:.1} -> {:?}; baked for the tilted normal {want_b:.1} nits ({:+.2}%) -> {:?}", &got[..3], bytes(runtime_b), (runtime_b / want_b - 1.0) * 100.0, bytes(*want_b));
        // The reconstruction, to a byte; and it within 3% of the baker's own B for the normal.
        for c in 0..3 {
            assert!((got[c] as i32 - bytes(runtime_b)[c] as i32).abs() <= 1, "tilt {deg}: pixel {got:?} vs the reconstruction's {:?}", bytes(runtime_b));
            assert!(got[c] >= bytes(0.97 * want_b)[c] && got[c] <= bytes(1.03 * want_b)[c], "tilt {deg}: pixel {got:?} not within 3% of the baker's {want_b} nits ({:?}..{:?})", bytes(0.97 * want_b), bytes(1.03 * want_b));
        }
    }
    assert_clean(&gpu);
}

/// The exposure (pack::exposure): from the log-average the cooker stored when the pack has one
/// (taken before block compression), else computed at load from the pages, the sun's
/// visibility read from the direction texture's alpha.
#[test]
fn the_exposure_comes_from_the_stored_log_average_or_the_pages() {
    let gpu = gpu();
    let (b0, t, vis) = (500.0, Vec3::new(0.0, 0.0, 0.5), 0.6);
    let mut pack = quad_pack(Vec3::Z, b0, t, vis);
    let exposure = |pack: &Pack| {
        let rig = Rig::new(&gpu, pack, 4, 4);
        let e = rig.scene.baked.unwrap().exposure;
        rig.destroy(&gpu);
        e
    };
    // Computed: every texel alike, B = b0 (1 + 2 |t|) + visibility E cos / pi toward t.
    let towards = to_quad(towards_sun());
    let q = |c: f32| ((128.0 + (127.0 * c).round()) - 128.0) / 127.0;
    let t_stored = Vec3::new(q(t.x), q(t.y), q(t.z));
    let v_stored = (vis * 255.0f32).round() / 255.0;
    let b = b0 * (1.0 + 2.0 * t_stored.length()) + v_stored * SUN_LUX * towards.dot(t_stored.normalize()).max(0.0) / std::f32::consts::PI;
    let computed = exposure(&pack);
    let want = pack::exposure::KEY / (1e-4 + 0.5 * b);
    assert!((computed / want - 1.0).abs() < 1e-3, "computed exposure {computed} vs {want}");
    // Stored: taken as it is.
    pack.manifest.lightmap.as_mut().unwrap().log_average = Some(1234.0);
    let stored = exposure(&pack);
    assert!((stored - pack::exposure::KEY / 1234.0).abs() < 1e-9, "{stored}");
    assert_clean(&gpu);
}
