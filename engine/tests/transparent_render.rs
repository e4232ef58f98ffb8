//! The transparent phase (glTF BLEND, `../shared/notes/shading.md` §2.5, §6f): overlapping glass
//! composites back to front with the premultiplied "over" operator, whichever side it is seen
//! from, and writes no depth. Bytes against the operator in closed form, validation on.

use engine::render::renderer::Lighting;
use engine::scene::camera::Camera;
use glam::{Mat4, Vec3};
use pack::{AlphaMode, Material, Pack, PackBuilder};

mod common;
use common::frames::{assert_bytes_near, auto_exposure, pixel, screen_pixel, tone_mapped_bytes, Rig};
use common::packs::{add_baked_light, node, push_mesh, quad_vertices, sun};
use common::{assert_clean, gpu};

const LIGHTMAP_B: f32 = 100.0;
const SKY_NITS: f32 = 150.0;
const SIZE: u32 = 48;

/// Glass panes (`emission`, alpha) as double-sided BLEND quads 2 m wide facing +Z at the given
/// z, in a baked level whose background is a grey sky of `SKY_NITS` (no sun, no probes: a pane
/// shows its emission alone, over what is behind it).
fn glass_pack(panes: &[([f32; 3], f32, f32)]) -> Pack {
    let mut b = PackBuilder::new("generated", "test");
    let (verts, idx) = quad_vertices();
    add_baked_light(&mut b, LIGHTMAP_B, Vec3::new(0.0, -500.0, 0.0));
    b.manifest.sky = Some(pack::Sky { color: [1.0; 3], intensity: SKY_NITS });
    for (i, &(emission, alpha, z)) in panes.iter().enumerate() {
        b.manifest.materials.push(Material { base_color: [0.0, 0.0, 0.0, alpha], emissive: emission, alpha_mode: AlphaMode::Blend, double_sided: true, ..Material::default() });
        let mesh = push_mesh(&mut b, &format!("pane{i}"), &verts, &idx, None);
        b.manifest.meshes[mesh as usize].lods[0].submeshes[0].material = i as u32 + 1;
        b.manifest.nodes.push(node(&format!("pane{i}"), Mat4::from_translation(Vec3::new(0.0, 0.0, z)) * Mat4::from_scale(Vec3::splat(2.0)), mesh));
    }
    b.finish()
}

/// Porter-Duff over, back to front: `layers` from the nearest to the farthest, then the sky.
fn over(layers: &[([f32; 3], f32)]) -> [f32; 3] {
    let mut l = [SKY_NITS; 3];
    for &(e, a) in layers.iter().rev() {
        l = std::array::from_fn(|c| a * e[c] + (1.0 - a) * l[c]);
    }
    l
}

/// The centre pixel seen from `camera`, which must look at the origin.
fn centre(pack: &Pack, camera: &Camera) -> [u8; 4] {
    let gpu = gpu();
    let mut rig = Rig::new(&gpu, pack, SIZE, SIZE);
    rig.renderer.tonemap.saturation = 1.0;
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, camera, &Lighting::default(), true).unwrap();
    assert_eq!(screen_pixel(camera, SIZE, SIZE, Vec3::ZERO), (SIZE / 2, SIZE / 2));
    let p = pixel(rig.target.pixels(), SIZE, SIZE / 2, SIZE / 2);
    assert!(rig.renderer.passes_run(0).contains(&"transparent"));
    rig.destroy(&gpu);
    assert_clean(&gpu);
    p
}

#[test]
fn overlapping_glass_composites_back_to_front_from_either_side() {
    // §6f: red alpha 0.5 over blue alpha 0.5, in front of the sky. Seen from +Z the red pane
    // (z = 0) is nearer; from -Z the blue one (z = -1).
    let (red, blue) = (([600.0, 0.0, 0.0], 0.5), ([0.0, 0.0, 600.0], 0.5));
    let pack = glass_pack(&[(red.0, red.1, 0.0), (blue.0, blue.1, -1.0)]);
    let exposure = auto_exposure(LIGHTMAP_B);
    let front = Camera { position: Vec3::new(0.0, 0.0, 3.0), yaw: 0.0, pitch: 0.0, fov_y: 60f32.to_radians(), near: 0.1 };
    let back = Camera { position: Vec3::new(0.0, 0.0, -4.0), yaw: std::f32::consts::PI, ..front };
    let from_front = centre(&pack, &front);
    let from_back = centre(&pack, &back);
    let (want_front, want_back) = (tone_mapped_bytes(over(&[red, blue]), exposure, 1.0), tone_mapped_bytes(over(&[blue, red]), exposure, 1.0));
    eprintln!("from the front {from_front:?} (over: {want_front:?}), from the back {from_back:?} (over: {want_back:?})");
    // The wrong order would be far off: red and blue swap weights (0.5 vs 0.25).
    assert!((want_front[0] as i32 - want_back[0] as i32).abs() > 20, "the test needs the orders to differ");
    assert_bytes_near("red over blue, seen from +Z", from_front, want_front, 1);
    assert_bytes_near("blue over red, seen from -Z", from_back, want_back, 1);
}

#[test]
fn glass_writes_no_depth_and_hides_nothing_behind_it() {
    // A nearly opaque pane (alpha 0.9) in front, a fainter one behind (drawn after it would be
    // hidden if the front pane wrote depth; sorting draws the far one first anyway, so this
    // also checks the order is by depth, not by the order of the nodes).
    let near = ([0.0, 800.0, 0.0], 0.9);
    let far = ([800.0, 0.0, 0.0], 0.6);
    let pack = glass_pack(&[(near.0, near.1, 0.0), (far.0, far.1, -2.0)]);
    let cam = Camera { position: Vec3::new(0.0, 0.0, 3.0), yaw: 0.0, pitch: 0.0, fov_y: 60f32.to_radians(), near: 0.1 };
    let got = centre(&pack, &cam);
    let want = tone_mapped_bytes(over(&[near, far]), auto_exposure(LIGHTMAP_B), 1.0);
    assert_bytes_near("green over red", got, want, 1);
}

#[test]
fn glass_casts_no_shadow_and_a_sunlit_pane_alone_renders() {
    // Under a sun, with a dynamic glass pane in view (the map is drawn for dynamic objects in
    // view): the one caster is the level's static quad; the pane casts nothing, and the dynamic
    // part of the map, left without draws, is not rendered.
    let mut pack = glass_pack(&[([0.0, 0.0, 600.0], 0.5, 0.0)]);
    pack.manifest.lights.push(sun(1000.0, Vec3::Y, 0.0));
    let gpu = gpu();
    let mut rig = Rig::new(&gpu, &pack, SIZE, SIZE);
    let cam = Camera { position: Vec3::new(0.0, 0.0, 3.0), yaw: 0.0, pitch: 0.0, fov_y: 60f32.to_radians(), near: 0.1 };
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
    let run = rig.renderer.passes_run(0);
    assert_eq!(rig.renderer.shadow_casters, 1, "only the static quad casts, not the glass");
    assert!(run.contains(&"transparent") && !run.contains(&"shadow") && !run.contains(&"prepass"), "{run:?}");
    rig.destroy(&gpu);
    assert_clean(&gpu);
}
