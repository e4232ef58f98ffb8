//! Headless rendering on the real Vulkan device (lavapipe in CI) with validation on: every test
//! fails on any validation error. Scenes are built in code so these tests need no cooker.

use engine::camera::Camera;
use engine::gpu::Gpu;
use engine::headless::{Offscreen, OFFSCREEN_FORMAT};
use engine::overlay::{headless_input, FrameStats, Overlay};
use engine::renderer::{Lighting, CLEAR_COLOR};
use engine::scene::GpuScene;
use glam::{Mat4, Vec3};
use pack::{LightmapRegion, Material, Node, Pack, PackBuilder, TextureFormat, Vertex};

mod common;
use common::frames::{assert_bytes_near, auto_exposure, auto_exposure_of, looking_down_neg_z, pixel, render, screen_pixel, srgb_decode, srgb_encode, tone_mapped_bytes, Rig};
use common::packs::{add_lightmap_page, add_lightmap_pages, node, push_mesh, push_uniform_probes, quad_vertices, static_node, texture};
use common::{assert_clean, gpu};

/// An axis-aligned unit cube centred on the origin with per-face normals (so lighting tells the
/// faces apart) and each face's uv (0,0) at its top-left corner.
fn cube_vertices() -> (Vec<Vertex>, Vec<u32>) {
    let faces: [(Vec3, Vec3, Vec3); 6] = [
        (Vec3::X, Vec3::NEG_Z, Vec3::Y),
        (Vec3::NEG_X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::X, Vec3::NEG_Z),
        (Vec3::NEG_Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (Vec3::NEG_Z, Vec3::NEG_X, Vec3::Y),
    ];
    let mut v = Vec::new();
    let mut idx = Vec::new();
    for (n, u, w) in faces {
        let base = v.len() as u32;
        for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            let p = (n + u * a + w * b) * 0.5;
            v.push(Vertex {
                position: p.to_array(),
                normal: n.to_array(),
                tangent: [u.x, u.y, u.z, 1.0],
                uv0: [(a + 1.0) * 0.5, (1.0 - b) * 0.5],
                color: [255; 4],
                ..Default::default()
            });
        }
        // Counter-clockwise seen from outside (u x w = n).
        idx.extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    (v, idx)
}

/// A pack with one cube mesh placed at each of `placements`, textured with a 2x2 checker of
/// `colors` (sRGB bytes).
fn cube_pack(placements: &[Mat4], colors: [[u8; 4]; 4], material: Material) -> Pack {
    cube_builder(placements, colors, material).finish()
}

/// `cube_pack`, still open for more.
fn cube_builder(placements: &[Mat4], colors: [[u8; 4]; 4], material: Material) -> PackBuilder {
    let mut b = PackBuilder::new("generated", "test");
    let (verts, idx) = cube_vertices();
    push_mesh(&mut b, "cube", &verts, &idx, None);
    let texels: Vec<u8> = colors.iter().flatten().copied().collect();
    let checker = texture(&mut b, "checker", TextureFormat::Rgba8Srgb, [2, 2], &[&texels]);
    b.manifest.materials.push(Material { base_color_texture: Some(checker), ..material });
    for (i, m) in placements.iter().enumerate() {
        b.manifest.nodes.push(node(&format!("cube{i}"), *m, 0));
    }
    b
}

const WHITE4: [[u8; 4]; 4] = [[255; 4]; 4];

#[test]
fn clear_colour_where_nothing_is_drawn() {
    let gpu = gpu();
    let pack = cube_pack(&[Mat4::from_translation(Vec3::new(0.0, 0.0, 10.0))], WHITE4, Material::default()); // behind the camera
    let px = render(&gpu, &pack, &looking_down_neg_z(0.0), 64, 48);
    let expect = [srgb_encode(CLEAR_COLOR[0]), srgb_encode(CLEAR_COLOR[1]), srgb_encode(CLEAR_COLOR[2]), 255];
    for (x, y) in [(0, 0), (32, 24), (63, 47)] {
        let p = pixel(&px, 64, x, y);
        for c in 0..3 {
            assert!((p[c] as i32 - expect[c] as i32).abs() <= 1, "pixel ({x},{y}) = {p:?}, clear = {expect:?}");
        }
    }
    assert_clean(&gpu);
}

#[test]
fn front_face_shades_with_ambient_plus_sun_in_srgb() {
    // The camera looks straight at the +Z face of a white cube: the centre pixel is the white
    // albedo times (ambient + sun * n.l), encoded to sRGB by the attachment.
    let gpu = gpu();
    let pack = cube_pack(&[Mat4::IDENTITY], WHITE4, Material::default());
    let px = render(&gpu, &pack, &looking_down_neg_z(2.0), 64, 64);
    let l = Lighting::default();
    let linear = l.ambient.x + l.sun_color.x * l.sun_dir.normalize().dot(Vec3::Z).max(0.0);
    let p = pixel(&px, 64, 32, 32);
    let want = srgb_encode(linear);
    assert!((p[0] as i32 - want as i32).abs() <= 2, "centre {p:?}, expected {want} per channel");
    assert_clean(&gpu);
}

#[test]
fn texture_is_sampled_as_srgb_and_oriented() {
    // A 2x2 texture with distinct quadrants on the +Z face: with uv (0,0) at the face's top-left,
    // red must show top-left, green top-right, blue bottom-left, white bottom-right.
    let gpu = gpu();
    let red = [255, 0, 0, 255];
    let green = [0, 255, 0, 255];
    let blue = [0, 0, 255, 255];
    let white = [255; 4];
    let mat = Material { double_sided: false, ..Default::default() };
    let pack = cube_pack(&[Mat4::IDENTITY], [red, green, blue, white], mat);
    let px = render(&gpu, &pack, &looking_down_neg_z(1.2), 128, 128);
    let dominant = |p: [u8; 4]| -> usize { (0..3).max_by_key(|&c| p[c]).unwrap() };
    // Quadrant centres well inside the face.
    let tl = pixel(&px, 128, 40, 40);
    let tr = pixel(&px, 128, 88, 40);
    let bl = pixel(&px, 128, 40, 88);
    let br = pixel(&px, 128, 88, 88);
    assert_eq!(dominant(tl), 0, "top-left {tl:?}");
    assert_eq!(dominant(tr), 1, "top-right {tr:?}");
    assert_eq!(dominant(bl), 2, "bottom-left {bl:?}");
    assert!(br[0] > 150 && br[1] > 150 && br[2] > 150, "bottom-right {br:?}");
    assert_clean(&gpu);
}

#[test]
fn object_above_the_camera_is_in_the_top_rows() {
    // pipeline.md T2.7: world +Y appears at the top of the read-back image (row 0 is the top).
    let gpu = gpu();
    let pack = cube_pack(&[Mat4::from_translation(Vec3::new(0.0, 1.2, 0.0))], WHITE4, Material::default());
    let (w, h) = (64, 64);
    let px = render(&gpu, &pack, &looking_down_neg_z(4.0), w, h);
    let clear = pixel(&px, w, 0, h - 1);
    let differs = |y: u32| (0..w).any(|x| pixel(&px, w, x, y) != clear);
    let rows: Vec<u32> = (0..h).filter(|&y| differs(y)).collect();
    assert!(!rows.is_empty(), "cube not visible");
    assert!(*rows.last().unwrap() < h / 2, "cube rows {rows:?} should all be in the top half");
    assert_clean(&gpu);
}

#[test]
fn back_faces_are_culled_unless_double_sided_and_mirrors_keep_their_faces() {
    // Inside a closed cube every face is a back face: single-sided draws nothing, double-sided
    // draws everything. A mirrored (det < 0) cube seen from outside must still show its faces.
    let gpu = gpu();
    let inside = looking_down_neg_z(0.0);
    let clear = |px: &[u8]| pixel(px, 32, 16, 16);
    let single = render(&gpu, &cube_pack(&[Mat4::from_scale(Vec3::splat(4.0))], WHITE4, Material::default()), &inside, 32, 32);
    let double = render(
        &gpu,
        &cube_pack(&[Mat4::from_scale(Vec3::splat(4.0))], WHITE4, Material { double_sided: true, ..Default::default() }),
        &inside,
        32,
        32,
    );
    let empty = render(&gpu, &cube_pack(&[Mat4::from_translation(Vec3::Z * 50.0)], WHITE4, Material::default()), &inside, 32, 32);
    assert_eq!(clear(&single), clear(&empty), "single-sided faces seen from behind must be culled");
    assert_ne!(clear(&double), clear(&empty), "double-sided faces must be drawn from behind");

    let mirrored = Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0));
    let normal = render(&gpu, &cube_pack(&[Mat4::IDENTITY], WHITE4, Material::default()), &looking_down_neg_z(2.0), 32, 32);
    let mirror = render(&gpu, &cube_pack(&[mirrored], WHITE4, Material::default()), &looking_down_neg_z(2.0), 32, 32);
    assert_eq!(pixel(&mirror, 32, 16, 16), pixel(&normal, 32, 16, 16), "a mirrored cube must look the same from the front");
    assert_clean(&gpu);
}

#[test]
fn nearer_cube_hides_farther_one_in_either_draw_order() {
    // Reversed-Z depth test. The far cube is tilted so that its face shades differently from the
    // near cube's; the centre pixel must show the near cube whichever is drawn last.
    let gpu = gpu();
    let near = Mat4::IDENTITY;
    let far = Mat4::from_translation(Vec3::new(0.0, 0.0, -3.0)) * Mat4::from_rotation_x(0.5) * Mat4::from_scale(Vec3::splat(3.0));
    let cam = looking_down_neg_z(3.0);
    let centre = |placements: &[Mat4]| pixel(&render(&gpu, &cube_pack(placements, WHITE4, Material::default()), &cam, 64, 64), 64, 32, 32);
    let near_alone = centre(&[near]);
    let far_alone = centre(&[far]);
    assert_ne!(near_alone, far_alone, "the test needs the two faces to shade differently");
    assert_eq!(centre(&[near, far]), near_alone, "far cube drawn last overwrote the near one");
    assert_eq!(centre(&[far, near]), near_alone);
    assert_clean(&gpu);
}

#[test]
fn validation_errors_are_counted() {
    // The zero-error assertions above mean something only if errors are caught: make one on
    // purpose (a zero-sized buffer is invalid usage) and see it counted.
    use ash::vk;
    let gpu = gpu();
    let result = unsafe { gpu.device.create_buffer(&vk::BufferCreateInfo::default().size(0).usage(vk::BufferUsageFlags::VERTEX_BUFFER), None) };
    if let Ok(b) = result {
        unsafe { gpu.device.destroy_buffer(b, None) };
    }
    assert!(gpu.validation().error_count() >= 1, "the validation layer did not report a zero-sized buffer");
}

#[test]
fn rendering_is_deterministic() {
    let gpu = gpu();
    let pack = cube_pack(
        &[Mat4::from_rotation_y(0.6) * Mat4::from_rotation_x(0.4)],
        [[200, 30, 30, 255], [30, 200, 30, 255], [30, 30, 200, 255], [220, 220, 220, 255]],
        Material::default(),
    );
    let cam = Camera::framing(Vec3::splat(-0.9), Vec3::splat(0.9));
    let a = render(&gpu, &pack, &cam, 320, 180);
    let b = render(&gpu, &pack, &cam, 320, 180);
    assert!(a == b, "two renders of the same scene differ");
    assert_clean(&gpu);
}

#[test]
fn a_camera_spawn_sets_the_view_position_field_of_view_and_near_plane() {
    // A pack with a camera spawn (as the cooker writes a glTF scene's camera) 5 m out on +X,
    // turned to look along -X at a unit cube, with the field of view that makes the cube's near
    // face (4.5 m away, 1 m tall) half the frame's height: `Camera::for_pack` sees the face over
    // exactly the middle 64 of 128 rows and columns. At eye height above the spawn the face
    // would be out of view, with the default 70 degrees a fifth as tall; with the near plane
    // past the face it is clipped and nothing is drawn.
    let gpu = gpu();
    let (w, h) = (128u32, 128u32);
    let yfov = 2.0 * (1.0f32 / 4.5).atan();
    let frame = |znear: f32| {
        let mut pack = cube_pack(&[Mat4::IDENTITY], WHITE4, Material::default());
        let rotation = glam::Quat::from_rotation_y(std::f32::consts::FRAC_PI_2).to_array();
        let params = serde_json::json!({ "yfov": yfov, "znear": znear });
        pack.manifest.spawns.push(pack::Spawn { name: "Camera".into(), kind: "camera".into(), position: [5.0, 0.0, 0.0], rotation, params });
        let mut rig = Rig::new(&gpu, &pack, w, h);
        let (min, max) = rig.scene.bounds();
        let cam = Camera::for_pack(&pack.manifest, min, max);
        rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
        let px = rig.target.pixels().to_vec();
        rig.destroy(&gpu);
        px
    };
    let px = frame(0.1);
    let clear = pixel(&px, w, 0, 0);
    let rows: Vec<u32> = (0..h).filter(|&y| pixel(&px, w, w / 2, y) != clear).collect();
    let columns: Vec<u32> = (0..w).filter(|&x| pixel(&px, w, x, h / 2) != clear).collect();
    assert_eq!((rows.first(), rows.len()), (Some(&32), 64), "rows {rows:?}");
    assert_eq!((columns.first(), columns.len()), (Some(&32), 64), "columns {columns:?}");
    let clipped = frame(4.6);
    assert!(clipped.chunks_exact(4).all(|p| p == clear), "a near plane past the face must clip it");
    assert_clean(&gpu);
}

#[test]
fn renderer_culls_the_notes_known_scene_exactly() {
    // pipeline.md T3.1 through the renderer: 441 cubes whose bounding spheres have radius 0.5
    // (scale 1/sqrt 3) on the integer grid x, z in -10..10, a 90 degree camera at the origin
    // looking down -z: 121 drawn, 320 culled. Culling off draws all 441 to the same image there.
    let gpu = gpu();
    let s = 1.0 / 3f32.sqrt();
    let placements: Vec<Mat4> = (-10..=10)
        .flat_map(|x| (-10..=10).map(move |z| Mat4::from_translation(Vec3::new(x as f32, 0.0, z as f32)) * Mat4::from_scale(Vec3::splat(s))))
        .collect();
    let pack = cube_pack(&placements, WHITE4, Material::default());
    let cam = Camera { position: Vec3::ZERO, yaw: 0.0, pitch: 0.0, fov_y: 90f32.to_radians(), near: 0.1 };
    let mut rig = Rig::new(&gpu, &pack, 64, 64);
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
    let culled = rig.target.pixels().to_vec();
    let c = rig.renderer.visibility.counts;
    assert_eq!((c.cull.tested, c.cull.visible, c.cull.culled, c.cull.inside), (441, 121, 320, 100));
    assert_eq!(c.triangles, 121 * 12);
    rig.renderer.visibility.culling = false;
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
    assert_eq!(rig.renderer.visibility.counts.cull.visible, 441);
    assert!(rig.target.pixels() == culled.as_slice(), "culling changed the image");
    rig.destroy(&gpu);
    assert_clean(&gpu);
}

#[test]
fn instances_of_one_mesh_are_drawn_with_one_call_per_winding_and_pass_and_look_the_same_as_one_call_each() {
    // The known scene again, every other cube mirrored (x scale negative) and every third one
    // stretched: 121 visible cubes of one mesh are two batches (the mirrored ones wind the other
    // way), so the pre-pass and the shading pass make 2 calls each; one call per cube makes 242.
    // The instance stream must give every cube its own transform and normal matrix: the two
    // images are the same bytes.
    let gpu = gpu();
    let s = 1.0 / 3f32.sqrt();
    let placements: Vec<Mat4> = (-10..=10)
        .flat_map(|x| (-10..=10).map(move |z| (x, z)))
        .enumerate()
        .map(|(i, (x, z))| {
            let mirror = if i % 2 == 1 { -1.0 } else { 1.0 };
            let stretch = if i % 3 == 0 { Vec3::new(1.0, 1.6, 0.7) } else { Vec3::ONE };
            Mat4::from_translation(Vec3::new(x as f32, 0.0, z as f32)) * Mat4::from_rotation_y(0.3 * i as f32) * Mat4::from_scale(Vec3::new(mirror, 1.0, 1.0) * stretch * s)
        })
        .collect();
    let pack = cube_pack(&placements, [[200, 30, 30, 255], [30, 200, 30, 255], [30, 30, 200, 255], [220, 220, 220, 255]], Material::default());
    let cam = Camera { position: Vec3::new(0.0, 1.0, 0.0), yaw: 0.0, pitch: -0.3, fov_y: 90f32.to_radians(), near: 0.1 };
    let mut rig = Rig::new(&gpu, &pack, 160, 120);
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
    let instanced = rig.target.pixels().to_vec();
    let visible = rig.renderer.visibility.counts.cull.visible;
    assert!(visible > 50, "the test needs many cubes in view, not {visible}");
    assert_eq!(rig.renderer.draw_calls, 2 * 2, "two windings, two passes");
    rig.renderer.instancing = false;
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
    assert_eq!(rig.renderer.draw_calls, 2 * visible);
    assert!(rig.target.pixels() == instanced.as_slice(), "instancing changed the image");
    rig.destroy(&gpu);
    assert_clean(&gpu);
}

#[test]
fn a_mesh_moving_away_switches_to_coarser_lods_monotonically() {
    // One cube mesh with three LODs (6, 4 and 2 faces of it, errors 0, 5 cm and 30 cm): moving the
    // camera back, the drawn LOD never goes back to a finer one and ends at the coarsest; the
    // triangle counter follows the LOD drawn.
    let gpu = gpu();
    let mut rig = Rig::new(&gpu, &three_lod_cube_pack(), 64, 64);
    let mut last = 0u8;
    let mut seen = vec![];
    for step in 0..40 {
        let distance = 1.5 * 1.25f32.powi(step);
        rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &looking_down_neg_z(distance), &Lighting::default(), false).unwrap();
        let v = &rig.renderer.visibility;
        assert_eq!(v.draws.len(), 1);
        let lod = v.draws[0].lod;
        assert!(lod >= last, "LOD went from {last} to {lod} moving away at {distance} m");
        assert_eq!(v.counts.triangles, [12, 8, 4][lod as usize]);
        if seen.last() != Some(&lod) {
            seen.push(lod);
        }
        last = lod;
    }
    assert_eq!(seen, vec![0, 1, 2]);
    rig.destroy(&gpu);
    assert_clean(&gpu);
}

/// One cube mesh with three LODs: 6, 4 and 2 of its faces, errors 0, 5 cm and 30 cm.
fn three_lod_cube_pack() -> Pack {
    let mut pack = cube_pack(&[Mat4::IDENTITY], WHITE4, Material::default());
    let lod0 = pack.manifest.meshes[0].lods[0].clone();
    for (faces, error) in [(4u32, 0.05f32), (2, 0.3)] {
        let mut l = lod0.clone();
        l.index_count = faces * 6;
        l.submeshes[0].index_count = faces * 6;
        l.error = error;
        pack.manifest.meshes[0].lods.push(l);
    }
    pack
}

#[test]
fn frozen_lods_stay_as_the_camera_moves_away_and_pick_again_when_thawed() {
    let gpu = gpu();
    let mut rig = Rig::new(&gpu, &three_lod_cube_pack(), 64, 64);
    let lod_at = |rig: &mut Rig, distance: f32| {
        rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &looking_down_neg_z(distance), &Lighting::default(), false).unwrap();
        (rig.renderer.visibility.draws[0].lod, rig.renderer.visibility.counts.triangles)
    };
    assert_eq!(lod_at(&mut rig, 1.5), (0, 12));
    rig.renderer.visibility.freeze_lod = true;
    assert_eq!(lod_at(&mut rig, 1000.0), (0, 12), "a frozen LOD does not follow the distance");
    rig.renderer.visibility.freeze_lod = false;
    assert_eq!(lod_at(&mut rig, 1000.0), (2, 4));
    rig.renderer.visibility.freeze_lod = true;
    assert_eq!(lod_at(&mut rig, 1.5), (2, 4), "frozen coarse stays coarse up close");
    rig.destroy(&gpu);
    assert_clean(&gpu);
}

/// A pack of one triangle per entry of `depths`, at z = -depth facing +Z, big enough to cover the
/// whole view of a 60 degree camera at the origin with its edges off screen (so no pixel is
/// shaded twice along an interior edge, and no helper invocation lands on screen), in that order.
fn screen_triangles_pack(depths: &[f32]) -> Pack {
    let mut b = PackBuilder::new("generated", "test");
    let verts: Vec<Vertex> = [(-1.0f32, -1.0f32), (3.0, -1.0), (-1.0, 3.0)]
        .iter()
        .map(|&(x, y)| Vertex { position: [x, y, 0.0], normal: [0.0, 0.0, 1.0], tangent: [1.0, 0.0, 0.0, 1.0], uv0: [0.5, 0.5], color: [255; 4], ..Default::default() })
        .collect();
    push_mesh(&mut b, "triangle", &verts, &[0, 1, 2], None);
    b.manifest.materials.push(Material::default());
    for (i, d) in depths.iter().enumerate() {
        // Centred on the view axis: the triangle's inscribed centre is at (1/3, 1/3).
        let m = Mat4::from_translation(Vec3::new(0.0, 0.0, -d)) * Mat4::from_scale(Vec3::splat(4.0 * d)) * Mat4::from_translation(Vec3::new(-1.0 / 3.0, -1.0 / 3.0, 0.0));
        b.manifest.nodes.push(node(&format!("t{i}"), m, 0));
    }
    b.finish()
}

#[test]
fn depth_prepass_shades_each_pixel_once_and_changes_nothing() {
    // pipeline.md T4.1/T4.3: 8 full-screen layers drawn back to front. Without the pre-pass
    // every layer shades every pixel (8 W H fragments); with it exactly W H, and the same image.
    // Fragments are counted by an atomic in the shading shader (lavapipe's fragment-invocation
    // statistic counts rasterised fragments before the depth test, so it cannot show this);
    // layers are single triangles with their edges off screen.
    let gpu = gpu();
    let (w, h) = (64u32, 48u32);
    let pack = screen_triangles_pack(&[8.0, 7.0, 6.0, 5.0, 4.0, 3.0, 2.0, 1.0]);
    let mut rig = Rig::new(&gpu, &pack, w, h);
    let cam = looking_down_neg_z(0.0);
    rig.renderer.count_fragments = true;
    let mut run = |prepass: bool| {
        rig.renderer.prepass = prepass;
        rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
        (rig.target.pixels().to_vec(), rig.renderer.fragment_count(0).expect("lavapipe can count"), rig.renderer.profile(&gpu, 0))
    };
    let (without, f0, s0) = run(false);
    let (with, f1, s1) = run(true);
    let pixels = w * h;
    assert_eq!((f0, f1), (8 * pixels, pixels));
    assert!(with == without, "the pre-pass changed the image");
    // The pre-pass costs a second transform of every vertex (T4.5): 8 layers x 3 vertices.
    if let (Some(s0), Some(s1)) = (s0, s1) {
        let vertices = |p: &engine::render::graph::FrameProfile, name| p.invocations(name).map(|i| i.vertex);
        assert_eq!((vertices(&s0, "prepass"), vertices(&s0, "shading")), (None, Some(24)));
        assert_eq!((vertices(&s1, "prepass"), vertices(&s1, "shading")), (Some(24), Some(24)));
    }
    rig.destroy(&gpu);
    assert_clean(&gpu);
}

#[test]
fn baked_light_lightmaps_for_static_geometry_probes_for_dynamic() {
    // A static quad with a uniform lightmap page B = 200 nits and a dynamic cube inside a probe
    // grid whose probes all hold B(n) = 200 nits (DC term only) and see no sun. Both are white,
    // so both show L = 200 exposed (auto exposure: 0.18 / (0.5 x 200)) and tone-mapped: grey
    // keeps its channel ratios, so Reinhard on luminance gives 0.36 / 1.36 = 0.2647, sRGB byte 141.
    let gpu = gpu();
    let b_nits = 200.0f32;
    let mut pack = quads_like_lightmapped(b_nits);
    let (w, h) = (64u32, 64u32);
    let mut rig = Rig::new(&gpu, &pack, w, h);
    assert!(rig.scene.baked.is_some());
    let cam = looking_down_neg_z(3.0);
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
    let px = rig.target.pixels().to_vec();
    let want = srgb_encode(0.36 / 1.36);
    let quad = pixel(&px, w, 8, 32); // the static quad fills the left half
    let cube = pixel(&px, w, 48, 32); // the dynamic cube's front face on the right
    for (what, p) in [("lightmapped quad", quad), ("probe-lit cube", cube)] {
        for c in 0..3 {
            assert!((p[c] as i32 - want as i32).abs() <= 2, "{what}: {p:?}, want {want}");
        }
    }
    pack.manifest.probes = None;
    rig.reload(&gpu, &pack);
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
    assert_eq!(pixel(rig.target.pixels(), w, 48, 32)[..3], [0, 0, 0], "without probes or sun a dynamic object is unlit");
    rig.destroy(&gpu);
    assert_clean(&gpu);
}

/// Where `lightmap_regions_pack` puts its four quads along x (z = 0).
const REGION_QUADS_X: [f32; 4] = [-1.8, -0.6, 0.6, 1.8];

/// Four unit quads facing +Z, white, in a baked scene of three 4x4 lightmap pages (B in nits:
/// page 0 is 400 on its left half and 50 on its right, page 1 is 25, page 2 is 200) and probes
/// of B = 100 (no sun). At `REGION_QUADS_X`: two static instances of one mesh (its submesh in
/// block 0) with regions of their own, the left half of page 0 and the whole of page 1; a
/// dynamic instance of the same mesh, without a region; and a static instance of a second mesh
/// whose submesh is in block 1, on page 1 (so it reads page 2). Returns the pack and every
/// lightmap texel's B (for the exposure).
fn lightmap_regions_pack() -> (Pack, Vec<f32>) {
    let mut b = PackBuilder::new("generated", "test");
    b.manifest.materials.push(Material::default());
    let (verts, idx) = quad_vertices();
    let panel = push_mesh(&mut b, "panel", &verts, &idx, Some(0));
    let second = push_mesh(&mut b, "panel in block 1", &verts, &idx, Some(1));
    let pages = [[[400.0, 400.0, 50.0, 50.0]; 4], [[25.0; 4]; 4], [[200.0; 4]; 4]];
    add_lightmap_pages(&mut b, &pages);
    push_uniform_probes(&mut b, 100.0, 0.0);
    let at = |i: usize| Mat4::from_translation(Vec3::new(REGION_QUADS_X[i], 0.0, 0.0));
    let left_half = Some(LightmapRegion { page: 0, scale: [0.5, 1.0], offset: [0.0, 0.0] });
    b.manifest.nodes.push(Node { lightmap: left_half, ..static_node("left half of page 0", at(0), panel, 0) });
    b.manifest.nodes.push(static_node("page 1", at(1), panel, 1));
    b.manifest.nodes.push(node("dynamic", at(2), panel));
    b.manifest.nodes.push(static_node("block 1 on page 1", at(3), second, 1));
    (b.finish(), pages.iter().flatten().flatten().copied().collect())
}

#[test]
fn static_instances_of_one_mesh_read_their_own_lightmap_regions_in_one_instanced_call() {
    // Each quad's centre (uv1 = 0.5, 0.5) shows the B its instance's region and its submesh's
    // block pick, exposed and tone-mapped: the left-half region maps u to 0.25, between two
    // B = 400 texels (the page's own u = 0.5 would blend 400 with 50); the page-1 region reads
    // page 1 (page 0 there is the 225 blend); the dynamic instance the probes; block 1 on page 1
    // page 2. The two static instances of the first mesh share one instanced call per pass, the
    // dynamic one (other pipeline) and the second mesh have one each: 3 calls per pass (pre-pass
    // and shading; no sun, no shadow pass), 4 without instancing, the same image.
    let gpu = gpu();
    let (pack, texels) = lightmap_regions_pack();
    let (w, h) = (96u32, 64u32);
    let mut rig = Rig::new(&gpu, &pack, w, h);
    let cam = looking_down_neg_z(3.0);
    let exposure = auto_exposure_of(&texels);
    let s = rig.renderer.tonemap.saturation;
    let centres = |rig: &mut Rig| {
        rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
        let px: Vec<[u8; 4]> = REGION_QUADS_X.iter().map(|&x| screen_pixel(&cam, w, h, Vec3::new(x, 0.0, 0.0))).map(|(x, y)| pixel(rig.target.pixels(), w, x, y)).collect();
        (px, rig.target.pixels().to_vec(), rig.renderer.draw_calls)
    };
    let (px, image, calls) = centres(&mut rig);
    for (what, p, b) in [("left half of page 0", px[0], 400.0), ("page 1", px[1], 25.0), ("dynamic, probes", px[2], 100.0), ("block 1 on page 1", px[3], 200.0)] {
        assert_bytes_near(what, p, tone_mapped_bytes([b; 3], exposure, s), 1);
    }
    assert_eq!((rig.renderer.visibility.draws.len(), calls), (4, 2 * 3));
    rig.renderer.instancing = false;
    let (_, one_each, calls) = centres(&mut rig);
    assert_eq!(calls, 2 * 4);
    assert!(one_each == image, "instancing changed the image");
    // Lightmaps off: every instance is lit by the probes, and the first mesh's three share a call.
    (rig.renderer.instancing, rig.renderer.lightmaps) = (true, false);
    let (px, _, calls) = centres(&mut rig);
    for p in px {
        assert_bytes_near("lightmaps off", p, tone_mapped_bytes([100.0; 3], exposure, s), 1);
    }
    assert_eq!(calls, 2 * 2);
    rig.destroy(&gpu);
    assert_clean(&gpu);
}

/// The cube pack plus a static quad on the left (lightmap page 0, uniform B) and a 2x2x2 probe
/// grid around the cube whose probes all hold B = `b` (DC only), sun visibility 0.
fn quads_like_lightmapped(b: f32) -> Pack {
    let cube_at = Mat4::from_translation(Vec3::new(0.8, 0.0, 0.0)) * Mat4::from_scale(Vec3::splat(0.6));
    let mut bld = cube_builder(&[cube_at], WHITE4, Material::default());
    let verts: Vec<Vertex> = [(-1.0f32, -1.0f32), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
        .iter()
        .map(|&(x, y)| Vertex { position: [x, y, 0.0], normal: [0.0, 0.0, 1.0], tangent: [1.0, 0.0, 0.0, 1.0], uv0: [0.5, 0.5], uv1: [(x + 1.0) * 0.5, (1.0 - y) * 0.5], color: [255; 4], ..Default::default() })
        .collect();
    let floor = push_mesh(&mut bld, "floor", &verts, &[0, 1, 2, 0, 2, 3], Some(0));
    let quad_at = Mat4::from_translation(Vec3::new(-1.3, 0.0, 0.0)) * Mat4::from_scale(Vec3::new(1.0, 2.0, 1.0));
    bld.manifest.nodes.push(static_node("floor", quad_at, floor, 0));
    add_lightmap_page(&mut bld, b);
    push_uniform_probes(&mut bld, b, 0.0);
    bld.finish()
}

#[test]
fn backface_culling_shades_a_closed_mesh_once_per_pixel_and_twice_without() {
    // pipeline.md T3.6 with the fragment counter: a cube in a generic pose (irrational angles,
    // so no pixel centre lies on a silhouette edge), depth test off. Culling back faces: one
    // fragment per covered pixel; double-sided (culling off): exactly two.
    let gpu = gpu();
    let pose = Mat4::from_rotation_y(0.7137) * Mat4::from_rotation_x(0.4321);
    let count = |double_sided: bool| {
        let pack = cube_pack(&[pose], WHITE4, Material { double_sided, ..Material::default() });
        let mut rig = Rig::new(&gpu, &pack, 64, 64);
        (rig.renderer.count_fragments, rig.renderer.prepass, rig.renderer.depth_test) = (true, false, false);
        rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &looking_down_neg_z(2.5), &Lighting::default(), true).unwrap();
        let clear = pixel(rig.target.pixels(), 64, 0, 0);
        let covered = rig.target.pixels().chunks_exact(4).filter(|p| *p != clear).count() as u32;
        let n = rig.renderer.fragment_count(0).unwrap();
        rig.destroy(&gpu);
        (n, covered)
    };
    let (once, covered) = count(false);
    assert!(covered > 500, "the cube covers {covered} pixels");
    assert_eq!(once, covered);
    let (twice, covered2) = count(true);
    assert_eq!((twice, covered2), (2 * covered, covered));
    assert_clean(&gpu);
}

// ---- mip chains: the level the sampler picks, and no shimmer at grazing angles ----------------

/// A pack with one mesh (`verts`, `idx`) at the origin and one texture of `format` with the
/// given levels (level 0 first, tightly packed RGBA8).
fn mesh_pack(verts: &[Vertex], idx: &[u32], format: TextureFormat, size: u32, levels: &[Vec<u8>], material: Material) -> Pack {
    let mut b = PackBuilder::new("generated", "test");
    push_mesh(&mut b, "mesh", verts, idx, None);
    let levels: Vec<&[u8]> = levels.iter().map(|l| l.as_slice()).collect();
    let t = texture(&mut b, "tex", format, [size, size], &levels);
    b.manifest.materials.push(Material { base_color_texture: Some(t), ..material });
    b.manifest.nodes.push(node("mesh", Mat4::IDENTITY, 0));
    b.finish()
}

#[test]
fn the_sampled_mip_level_follows_texels_per_pixel() {
    // A 256x256 UNORM texture whose level k is the constant grey 28k, on the cube's +Z face seen
    // head-on in a 128-pixel-wide frame: a face 2^-k of the frame's width shows 256 / (128 / 2^k)
    // = 2^(k+1) texels per pixel, so level k+1. The face is fronto-parallel, so the level is the
    // same over the whole face.
    let gpu = gpu();
    let size = 256u32;
    let levels: Vec<Vec<u8>> = (0..9).map(|k| {
        let n = ((size >> k).max(1) * (size >> k).max(1)) as usize;
        [28 * k as u8, 28 * k as u8, 28 * k as u8, 255].repeat(n)
    }).collect();
    let (verts, idx) = cube_vertices();
    let pack = mesh_pack(&verts, &idx, TextureFormat::Rgba8Unorm, size, &levels, Material::default());
    let l = Lighting::default();
    let light = l.ambient.x + l.sun_color.x * l.sun_dir.normalize().dot(Vec3::Z).max(0.0);
    let (w, h) = (128u32, 128u32);
    let tan = (30f32).to_radians().tan();
    for want in [1.0f32, 2.0, 2.5, 3.0, 4.0] {
        // Face width in pixels: w / (2 d tan(fov/2)) = 256 / 2^want.
        let pixels = size as f32 / 2f32.powf(want);
        let d = w as f32 / (2.0 * pixels * tan);
        let px = render(&gpu, &pack, &looking_down_neg_z(0.5 + d), w, h);
        let p = pixel(&px, w, w / 2, h / 2);
        let level = srgb_decode(p[0]) / light * 255.0 / 28.0;
        eprintln!("face {pixels:.1} px wide: pixel {p:?} -> level {level:.3} (expected {want})");
        // Whole levels exactly; between two levels the device may blend (trilinear) or pick one:
        // lavapipe's anisotropic path takes floor(lod) (measured: level 2.0 for 2.25..2.75),
        // while its plain trilinear sampler blends (2.515 at 2.5).
        if want.fract() == 0.0 {
            assert!((level - want).abs() <= 0.1, "{pixels} px face: sampled level {level}, expected {want}");
        } else {
            assert!(level >= want.floor() - 0.1 && level <= want.ceil() + 0.1, "{pixels} px face: sampled level {level}, expected between {} and {}", want.floor(), want.ceil());
        }
    }
    assert_clean(&gpu);
}

/// A floor quad (y = 0, x in [-20, 20], z in [-400, 0]) with uv = (x, z) / 2: a 64x64 texture
/// repeats every 2 m, so one texel is 1/32 m.
fn floor_vertices() -> (Vec<Vertex>, Vec<u32>) {
    let corners = [(-20.0, 0.0), (20.0, 0.0), (20.0, -400.0), (-20.0, -400.0)];
    let v = corners
        .iter()
        .map(|&(x, z)| Vertex {
            position: [x, 0.0, z],
            normal: [0.0, 1.0, 0.0],
            tangent: [1.0, 0.0, 0.0, 1.0],
            uv0: [x / 2.0, z / 2.0],
            color: [255; 4],
            ..Default::default()
        })
        .collect();
    (v, vec![0, 1, 2, 0, 2, 3]) // counter-clockwise seen from above
}

#[test]
fn a_grazing_floor_does_not_shimmer_when_the_camera_moves_one_texel() {
    // Stripes across the view direction, one texel black, one white (sRGB): far away many
    // stripes fall in one pixel and the right answer is their linear-light mean. Moving the
    // camera by one texel (half a stripe period) flips every stripe: with the cooker's mip chain
    // (and trilinear + anisotropic sampling) the far floor stays put; with level 0 alone, as
    // packs had before, it shimmers.
    let gpu = gpu();
    let size = 64usize;
    let level0: Vec<u8> = (0..size * size).flat_map(|i| if (i / size) % 2 == 0 { [0, 0, 0, 255] } else { [255; 4] }).collect();
    let s = cook_core::mips::MipSettings::new(cook_core::mips::Usage::Color);
    let mut chain = vec![level0.clone()];
    chain.extend(cook_core::mips::mips_rgba8(size as u32, size as u32, &level0, &s).unwrap());
    assert_eq!(chain.len(), 7);
    let (verts, idx) = floor_vertices();
    let (w, h) = (160u32, 120u32);
    let texel = 2.0 / size as f32;
    let camera = |z: f32| Camera { position: Vec3::new(0.0, 2.0, z), yaw: 0.0, pitch: -0.2, fov_y: 60f32.to_radians(), near: 0.1 };
    // The far floor: rows where z lies between -8 m and -400 m (from ~9 texels per pixel along
    // the view and ~2 across it, to thousands).
    let row_of = |z: f32| {
        let c = camera(0.0).view_proj(w as f32 / h as f32) * glam::Vec4::new(0.0, 0.0, z, 1.0);
        ((c.y / c.w * 0.5 + 0.5) * h as f32) as u32
    };
    let rows = row_of(-400.0) + 1..row_of(-8.0);
    assert!(rows.len() >= 8, "far rows {rows:?}");
    let shimmer = |levels: &[Vec<u8>]| -> (f32, u8, f32) {
        let pack = mesh_pack(&verts, &idx, TextureFormat::Rgba8Srgb, size as u32, levels, Material::default());
        let a = render(&gpu, &pack, &camera(0.0), w, h);
        let b = render(&gpu, &pack, &camera(-texel), w, h);
        let (mut sum, mut max, mut n, mut lum) = (0.0f32, 0u8, 0, 0.0f32);
        for y in rows.clone() {
            for x in 0..w {
                let (p, q) = (pixel(&a, w, x, y), pixel(&b, w, x, y));
                for c in 0..3 {
                    let d = p[c].abs_diff(q[c]);
                    sum += d as f32;
                    max = max.max(d);
                    lum += p[c] as f32;
                    n += 1;
                }
            }
        }
        (sum / n as f32, max, lum / n as f32)
    };
    let (mean, max, level) = shimmer(&chain);
    let (mean0, max0, level0_mean) = shimmer(&chain[..1]);
    // And it shows the right grey: the stripes' linear-light mean (level 1 is sRGB 188) lit.
    let l = Lighting::default();
    let lit = srgb_encode(srgb_decode(188) * (l.ambient.x + l.sun_color.x * l.sun_dir.normalize().dot(Vec3::Y).max(0.0)));
    assert!((level - lit as f32).abs() <= 1.0, "far floor {level}, expected {lit}");
    eprintln!("far floor rows {rows:?}: frame difference with mips mean {mean:.2} max {max} (floor {level:.1}); level 0 only mean {mean0:.2} max {max0} (floor {level0_mean:.1})");
    // Stated bound: on average under one sRGB code value, and nowhere more than 4.
    assert!(mean <= 1.0 && max <= 4, "the mipmapped floor shimmers: mean {mean}, max {max}");
    assert!(mean0 > 4.0 * mean.max(0.25), "without mips the floor should shimmer (mean {mean0}): the test has teeth");
    assert_clean(&gpu);
}

// ---- HDR target, tone map, emission, sun shadow map ------------------------------------------

/// A baked pack (one lightmap page of B = `lightmap_b`, on a static quad out of view) with one
/// black quad per entry of `emission` (nits), side by side along x at z = 0, 1.1 m apart,
/// centred on x = 0: each quad's pixels are its emission alone.
fn emissive_quads_pack(lightmap_b: f32, emission: &[[f32; 3]]) -> Pack {
    let mut b = PackBuilder::new("generated", "test");
    let (verts, idx) = quad_vertices();
    b.manifest.materials.push(Material::default());
    let lit = push_mesh(&mut b, "lightmapped", &verts, &idx, Some(0));
    add_lightmap_page(&mut b, lightmap_b);
    b.manifest.nodes.push(static_node("lightmapped", Mat4::from_translation(Vec3::new(0.0, 0.0, 50.0)), lit, 0));
    for (i, e) in emission.iter().enumerate() {
        b.manifest.materials.push(Material { base_color: [0.0, 0.0, 0.0, 1.0], emissive: *e, ..Material::default() });
        let mesh = push_mesh(&mut b, &format!("emitter{i}"), &verts, &idx, None);
        b.manifest.meshes[mesh as usize].lods[0].submeshes[0].material = i as u32 + 1;
        let x = (i as f32 - (emission.len() as f32 - 1.0) * 0.5) * 1.1;
        b.manifest.nodes.push(node(&format!("emitter{i}"), Mat4::from_translation(Vec3::new(x, 0.0, 0.0)), mesh));
    }
    b.finish()
}

/// Render `emissive_quads_pack` from z = 3 (96x64, 60 degree FOV) with tone-map saturation `s`
/// and return the centre pixel of each quad.
fn emitter_pixels(gpu: &Gpu, lightmap_b: f32, emission: &[[f32; 3]], s: f32) -> Vec<[u8; 4]> {
    let (w, h) = (96u32, 64u32);
    let pack = emissive_quads_pack(lightmap_b, emission);
    let mut rig = Rig::new(gpu, &pack, w, h);
    assert!(rig.scene.baked.is_some());
    rig.renderer.tonemap.saturation = s;
    let cam = looking_down_neg_z(3.0);
    rig.target.render(gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
    let px = (0..emission.len())
        .map(|i| {
            let x = (i as f32 - (emission.len() as f32 - 1.0) * 0.5) * 1.1;
            let (sx, sy) = screen_pixel(&cam, w, h, Vec3::new(x, 0.0, 0.0));
            pixel(rig.target.pixels(), w, sx, sy)
        })
        .collect();
    rig.destroy(gpu);
    px
}

#[test]
fn tone_map_output_is_the_operators_byte_for_a_known_radiance() {
    // Black emissive quads in a baked scene: each pixel's radiance is exactly its material's
    // emission (so emission reaches the HDR target), exposed, tone-mapped and sRGB-encoded. The
    // expected bytes come from the formula in this file; a grey and a coloured emitter (the
    // coloured one pins the luminance operator and the colour restore: per-channel Reinhard
    // would give different bytes), at two saturation settings.
    let gpu = gpu();
    let lightmap_b = 200.0;
    let exposure = auto_exposure(lightmap_b);
    let emission = [[300.0, 300.0, 300.0], [1200.0, 500.0, 100.0]];
    for s in [0.8, 1.0] {
        let px = emitter_pixels(&gpu, lightmap_b, &emission, s);
        for (e, p) in emission.iter().zip(&px) {
            let want = tone_mapped_bytes(*e, exposure, s);
            eprintln!("emission {e:?}, s {s}: got {p:?}, formula {want:?}");
            assert_bytes_near(&format!("emission {e:?} s {s}"), *p, want, 1);
        }
        // Not per-channel Reinhard (the inline operator this pass replaced).
        let per_channel = emission[1].map(|c| srgb_encode(c * exposure / (1.0 + c * exposure)));
        assert!((0..3).any(|c| (px[1][c] as i32 - per_channel[c] as i32).abs() > 3), "looks per-channel: {:?} vs {per_channel:?}", px[1]);
    }
    assert_clean(&gpu);
}

#[test]
fn hdr_values_above_one_reach_the_tone_map_unclamped() {
    // 3000 and 30000 nits are far above 1 in the HDR target. A float target keeps them, so the
    // tone map gives two different bytes below 255 (the operator's asymptote); a clamping (UNORM)
    // target would store 1.0 for both, which exposes to nearly black and the same byte twice.
    let gpu = gpu();
    let lightmap_b = 200.0;
    let exposure = auto_exposure(lightmap_b);
    let emission = [[3000.0; 3], [30000.0; 3]];
    let px = emitter_pixels(&gpu, lightmap_b, &emission, 0.8);
    let clamped = tone_mapped_bytes([1.0; 3], exposure, 0.8);
    for (e, p) in emission.iter().zip(&px) {
        let want = tone_mapped_bytes(*e, exposure, 0.8);
        assert!(want[0] < 255, "the test needs bytes below saturation: {want:?}");
        assert_bytes_near(&format!("emission {}", e[0]), *p, want, 1);
        assert!(p[0] > clamped[0] + 100, "{p:?} looks clamped to 1 before the tone map ({clamped:?})");
    }
    assert!(px[0][0] < px[1][0], "brighter radiance must give a brighter byte: {px:?}");
    assert_clean(&gpu);
}

/// A baked scene for the sun shadow: a white dynamic unit cube at `cube_x`, a static roof (a
/// 6x6 m quad facing up at y = 1.5 over x, z in [-3, 3]; from below the camera sees its back
/// face, culled), probes that all hold B = `probe_b` with sun visibility 1 (so the probes alone
/// would light the cube), and a sun of `sun_lux` towards `towards_sun`.
fn roof_pack(cube_x: f32, probe_b: f32, sun_lux: f32, towards_sun: Vec3) -> Pack {
    let mut b = PackBuilder::new("generated", "test");
    b.manifest.materials.push(Material::default());
    let (cv, ci) = cube_vertices();
    let cube = push_mesh(&mut b, "cube", &cv, &ci, None);
    let roof_verts: Vec<Vertex> = [(-0.5f32, 0.5f32), (0.5, 0.5), (0.5, -0.5), (-0.5, -0.5)]
        .iter()
        .map(|&(x, z)| Vertex { position: [x, 0.0, z], normal: [0.0, 1.0, 0.0], tangent: [1.0, 0.0, 0.0, 1.0], uv0: [0.5, 0.5], uv1: [x + 0.5, z + 0.5], color: [255; 4], ..Default::default() })
        .collect();
    let roof = push_mesh(&mut b, "roof", &roof_verts, &[0, 1, 2, 0, 2, 3], Some(0));
    add_lightmap_page(&mut b, 100.0);
    let roof_at = Mat4::from_translation(Vec3::new(0.0, 1.5, 0.0)) * Mat4::from_scale(Vec3::new(6.0, 1.0, 6.0));
    b.manifest.nodes.push(static_node("roof", roof_at, roof, 0));
    b.manifest.nodes.push(node("cube", Mat4::from_translation(Vec3::new(cube_x, 0.0, 0.0)), cube));
    push_uniform_probes(&mut b, probe_b, 1.0);
    b.manifest.lights.push(pack::Light {
        name: "sun".into(),
        kind: pack::LightKind::Sun,
        color: [1.0; 3],
        intensity: sun_lux,
        position: [0.0; 3],
        direction: (-towards_sun.normalize()).to_array(),
        range: None,
        inner_cone: 0.0,
        outer_cone: 0.0,
        size: [0.0; 2],
        angular_radius: 0.0,
    });
    b.finish()
}

#[test]
fn a_dynamic_object_under_a_static_roof_gets_no_sun_and_gets_it_moved_out() {
    // The cube's +Z face (n.l = 0.447) seen head-on. Under the roof the sun is blocked: the pixel
    // is the probe light alone, although the probes say the sun is visible (their grid is too
    // coarse to know); moved 8 m out from under the roof, the same face adds the sun,
    // E n.l / pi. Both bytes from the closed form; the roof and the cube are the map's casters.
    let gpu = gpu();
    let (probe_b, sun_lux) = (40.0f32, 2000.0f32);
    let towards_sun = Vec3::new(0.0, 1.0, 0.5).normalize();
    let exposure = auto_exposure(100.0);
    let s = 0.8;
    let shaded = tone_mapped_bytes([probe_b; 3], exposure, s);
    let lit_l = probe_b + sun_lux * towards_sun.dot(Vec3::Z) / std::f32::consts::PI;
    let lit = tone_mapped_bytes([lit_l; 3], exposure, s);
    assert!(lit[0] > shaded[0] + 50, "the test needs the sun to matter: {shaded:?} vs {lit:?}");
    let centre = |cube_x: f32, map_size: u32| {
        let pack = roof_pack(cube_x, probe_b, sun_lux, towards_sun);
        let mut rig = Rig::new(&gpu, &pack, 64, 64);
        rig.renderer.tonemap.saturation = s;
        rig.renderer.set_shadow_map_size(&gpu, map_size).unwrap();
        let cam = Camera { position: Vec3::new(cube_x, 0.0, 3.0), yaw: 0.0, pitch: 0.0, fov_y: 60f32.to_radians(), near: 0.1 };
        rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
        let p = pixel(rig.target.pixels(), 64, 32, 32);
        let casters = rig.renderer.shadow_casters;
        eprintln!("cube at x = {cube_x}, {map_size}^2 map: {:?}", rig.renderer.profile(&gpu, 0));
        // The face's corners are 0.5 m from its centre: a 3x3 block of pixels around the centre
        // must agree (no acne speckles on a face that is fully lit or fully shadowed).
        let block: Vec<[u8; 4]> = (28..=36).step_by(4).flat_map(|y| (28..=36).step_by(4).map(move |x| (x, y))).map(|(x, y)| pixel(rig.target.pixels(), 64, x, y)).collect();
        rig.destroy(&gpu);
        (p, casters, block)
    };
    let (under, casters_under, block_under) = centre(0.0, engine::shadow::DEFAULT_SHADOW_MAP_SIZE);
    let (out, casters_out, block_out) = centre(8.0, engine::shadow::DEFAULT_SHADOW_MAP_SIZE);
    eprintln!("under the roof {under:?} (probe only {shaded:?}); out {out:?} (with sun {lit:?})");
    assert_eq!((casters_under, casters_out), (2, 2), "roof and cube cast");
    assert_bytes_near("under the roof", under, shaded, 1);
    assert_bytes_near("out in the sun", out, lit, 1);
    for (what, block, want) in [("under", block_under, shaded), ("out", block_out, lit)] {
        for p in block {
            assert_bytes_near(what, p, want, 1);
        }
    }
    // The map size is a setting: a small map still shadows the cube (and the frame set points at
    // the new map).
    let (small_under, ..) = centre(0.0, 256);
    assert_bytes_near("under the roof, 256^2 map", small_under, shaded, 1);
    assert_clean(&gpu);
}

#[test]
fn the_static_casters_are_drawn_into_the_shadow_map_once_and_reused_while_the_cube_moves() {
    // The roof (static) goes into the map's cached part once; frames that only move the cube
    // copy that part and draw the cube on top, and must give the pixels of a renderer drawing
    // everything afresh. Moving the roof, resizing the map or loading a scene draws it again.
    let gpu = gpu();
    let mut pack = roof_pack(0.0, 40.0, 2000.0, Vec3::new(0.0, 1.0, 0.5));
    // A static ground under it all (the roof's quad, 24 m wide), so the map's window, fitted to
    // the scene, stays put while the cube moves about inside it.
    let ground_at = Mat4::from_translation(Vec3::new(0.0, -0.6, 0.0)) * Mat4::from_scale(Vec3::new(24.0, 1.0, 24.0));
    let roof_mesh = pack.manifest.nodes[0].mesh.unwrap();
    pack.manifest.nodes.push(static_node("ground", ground_at, roof_mesh, 0));
    // Puts the cube at x and the roof at height y in `scene` (through the scene API: the culling
    // spheres and the shadow cache's key follow).
    let place = |scene: &mut GpuScene, cube_x: f32, roof_y: f32| {
        let [roof, cube] = [0, 1];
        assert!(scene.instances[roof].is_static && !scene.instances[cube].is_static);
        let (roof, cube) = (scene.instances.id_at(roof), scene.instances.id_at(cube));
        scene.set_transform(roof, Mat4::from_translation(Vec3::new(0.0, roof_y, 0.0)) * Mat4::from_scale(Vec3::new(6.0, 1.0, 6.0))).unwrap();
        scene.set_transform(cube, Mat4::from_translation(Vec3::new(cube_x, 0.0, 0.0))).unwrap();
    };
    let cam = |cube_x: f32| Camera { position: Vec3::new(cube_x, 0.0, 3.0), yaw: 0.0, pitch: 0.0, fov_y: 60f32.to_radians(), near: 0.1 };
    let afresh = |cube_x: f32, roof_y: f32, map_size: u32| {
        let mut rig = Rig::new(&gpu, &pack, 48, 48);
        rig.renderer.set_shadow_map_size(&gpu, map_size).unwrap();
        place(&mut rig.scene, cube_x, roof_y);
        rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam(cube_x), &Lighting::default(), true).unwrap();
        assert_eq!(rig.renderer.shadow.static_draws, 1);
        let px = rig.target.pixels().to_vec();
        rig.destroy(&gpu);
        px
    };
    let mut rig = Rig::new(&gpu, &pack, 48, 48);
    let frame = |rig: &mut Rig, cube_x: f32, roof_y: f32| {
        place(&mut rig.scene, cube_x, roof_y);
        rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam(cube_x), &Lighting::default(), true).unwrap();
        (rig.target.pixels().to_vec(), rig.renderer.shadow.static_draws, rig.renderer.shadow_casters)
    };
    let size = engine::shadow::DEFAULT_SHADOW_MAP_SIZE;
    let mut seen = Vec::new();
    for x in [0.0, 8.0, 0.5, 0.0] {
        let (px, static_draws, casters) = frame(&mut rig, x, 1.5);
        assert_eq!((static_draws, casters), (1, 3), "cube at x = {x}: the roof and ground are drawn once, all three cast");
        assert!(px == afresh(x, 1.5, size), "cube at x = {x}: the cached frame differs from a fresh one");
        seen.push(px);
    }
    // Under the roof the face gets the probes alone, out in the sun much more (the roof test
    // above pins both values); a map without the roof, or with nothing, would not tell them apart.
    let (under, out) = (pixel(&seen[0], 48, 24, 24), pixel(&seen[1], 48, 24, 24));
    assert!(out[0] > under[0] + 50, "under the roof {under:?}, out in the sun {out:?}");
    // The roof lowered: drawn again, and the cube (still under it) sees the new roof.
    let (px, static_draws, _) = frame(&mut rig, 0.0, 1.2);
    assert_eq!(static_draws, 2, "a moved static caster draws the static part again");
    assert!(px == afresh(0.0, 1.2, size));
    rig.renderer.set_shadow_map_size(&gpu, 512).unwrap();
    let (px, static_draws, _) = frame(&mut rig, 0.0, 1.2);
    assert_eq!(static_draws, 3, "a new map size draws the static part again");
    assert!(px == afresh(0.0, 1.2, 512));
    rig.reload(&gpu, &pack);
    let (_, static_draws, _) = frame(&mut rig, 0.0, 1.2);
    assert_eq!(static_draws, 4, "a new scene draws the static part again");
    rig.destroy(&gpu);
    assert_clean(&gpu);
}

#[test]
fn a_hung_device_is_an_error_that_says_so_not_a_wait_forever() {
    // A frame that cannot finish within the timeout (here 1 ns) ends in `DeviceLost` naming what
    // was waited for; the Gpu then no longer waits for the device at all, so dropping it returns
    // (lavapipe never reports a hang itself: without the timeout this would wait forever).
    let gpu = gpu();
    let pack = roof_pack(0.0, 40.0, 2000.0, Vec3::new(0.0, 1.0, 0.5));
    let mut rig = Rig::new(&gpu, &pack, 64, 64);
    assert_eq!(gpu.timeout(), engine::gpu::DEFAULT_GPU_TIMEOUT);
    gpu.set_timeout(std::time::Duration::from_nanos(1));
    let cam = Camera { position: Vec3::new(0.0, 0.0, 3.0), yaw: 0.0, pitch: 0.0, fov_y: 60f32.to_radians(), near: 0.1 };
    let err = rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).expect_err("a 1 ns limit");
    let lost = err.downcast_ref::<engine::gpu::DeviceLost>().unwrap_or_else(|| panic!("not a DeviceLost: {err:#}"));
    let text = lost.to_string();
    assert!(text.contains("did not finish in time") && text.contains("a frame"), "{text}");
    assert!(gpu.is_lost());
    // Later waits fail at once, saying the device was already lost.
    let again = rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).expect_err("lost");
    assert!(again.to_string().contains("was lost before"), "{again:#}");
    // The rig's objects may still be in use by the device: left to the process, as the demo
    // does; the Gpu's drop must return without waiting.
    std::mem::forget(rig);
    drop(gpu);
}

#[test]
fn a_cpu_device_samples_textures_without_anisotropy() {
    // Lavapipe's anisotropic sampling can stall a frame for minutes (`samplers::max_anisotropy`): a
    // CPU device gets none, any other its own limit up to 16x.
    let gpu = gpu();
    let got = engine::samplers::max_anisotropy(&gpu);
    if gpu.caps.device_type == ash::vk::PhysicalDeviceType::CPU {
        assert_eq!(got, None, "{} is a CPU device", gpu.caps.device_name);
    } else {
        assert_eq!(got, gpu.caps.sampler_anisotropy.map(|m| m.min(16.0)));
    }
}

#[test]
fn the_shadow_pass_is_skipped_without_a_dynamic_object_in_view() {
    // Static geometry has the sun in its lightmap: with only the (static) roof in view nothing
    // reads the map, so it is not drawn; an unbaked pack (stand-in lighting) never draws it.
    let gpu = gpu();
    let pack = roof_pack(20.0, 40.0, 2000.0, Vec3::new(0.0, 1.0, 0.5));
    let mut rig = Rig::new(&gpu, &pack, 32, 32);
    let away = Camera { position: Vec3::new(0.0, 5.0, 0.0), yaw: 0.0, pitch: -1.5, fov_y: 30f32.to_radians(), near: 0.1 };
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &away, &Lighting::default(), true).unwrap();
    assert!(rig.renderer.visibility.draws.len() == 1, "only the roof should be in view: {:?}", rig.renderer.visibility.draws);
    assert_eq!(rig.renderer.shadow_casters, 0);
    rig.reload(&gpu, &cube_pack(&[Mat4::IDENTITY], WHITE4, Material::default()));
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &looking_down_neg_z(2.0), &Lighting::default(), true).unwrap();
    assert_eq!(rig.renderer.shadow_casters, 0);
    rig.destroy(&gpu);
    assert_clean(&gpu);
}

#[test]
fn one_renderer_draws_targets_of_different_sizes() {
    // The HDR target is the renderer's, sized per target: a second, differently sized target
    // gets a new one (no validation error, same shading).
    let gpu = gpu();
    let pack = cube_pack(&[Mat4::IDENTITY], WHITE4, Material::default());
    let mut rig = Rig::new(&gpu, &pack, 64, 64);
    let cam = looking_down_neg_z(2.0);
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
    let big = pixel(rig.target.pixels(), 64, 32, 32);
    let mut small = Offscreen::new(&gpu, 40, 24).unwrap();
    small.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
    assert_eq!(pixel(small.pixels(), 40, 20, 12), big);
    let times = rig.renderer.profile(&gpu, 0).expect("lavapipe has timestamps");
    assert!(times.ms("shading") > 0.0 && times.ms("tonemap") > 0.0, "{times:?}");
    small.destroy(&gpu);
    rig.destroy(&gpu);
    assert_clean(&gpu);
}

// ---- 16-bit textures (cooked normal maps) -----------------------------------------------------

#[test]
fn sixteen_bit_unorm_textures_sample_like_their_eight_bit_originals() {
    // Cooked normal maps are Rgba16Unorm. The same levels stored 8-bit (g) and 16-bit (g * 257,
    // the same value in [0, 1]) must render the same image: the upload picks the right format
    // (or the half-float fallback) and the sampler reads UNORM, not raw integers.
    let gpu = gpu();
    let size = 16u32;
    let grey = |k: usize| [40 + 50 * k as u8, 200 - 30 * k as u8, 90, 255];
    let levels8: Vec<Vec<u8>> = (0..5).map(|k| grey(k).repeat(((size >> k) * (size >> k)) as usize)).collect();
    let levels16: Vec<Vec<u8>> = levels8.iter().map(|l| l.iter().flat_map(|&b| (b as u16 * 257).to_le_bytes()).collect()).collect();
    let (verts, idx) = cube_vertices();
    let (w, h) = (64u32, 64u32);
    let camera = looking_down_neg_z(3.0);
    let a = render(&gpu, &mesh_pack(&verts, &idx, TextureFormat::Rgba8Unorm, size, &levels8, Material::default()), &camera, w, h);
    let b = render(&gpu, &mesh_pack(&verts, &idx, TextureFormat::Rgba16Unorm, size, &levels16, Material::default()), &camera, w, h);
    let centre = pixel(&a, w, w / 2, h / 2);
    assert!(centre[0] != centre[1], "the face shows the texture: {centre:?}");
    let worst = a.iter().zip(&b).map(|(p, q)| p.abs_diff(*q)).max().unwrap();
    assert!(worst <= 1, "8-bit and 16-bit renders differ by up to {worst}");
    assert_clean(&gpu);
}

#[test]
fn the_half_float_fallback_keeps_cooked_normals_unit_length() {
    // Devices that cannot filter R16G16B16A16_UNORM get the texels as half floats.
    let mut worst = 0.0f64;
    for i in 0..2000 {
        let (a, b) = (i as f64 * 0.7391, i as f64 * 0.0123);
        let n = [a.cos() * b.sin(), a.sin() * b.sin(), b.cos()];
        let texel: Vec<u8> = n.iter().chain([1.0].iter()).flat_map(|&c| (((c * 0.5 + 0.5) * 65535.0).round() as u16).to_le_bytes()).collect();
        let halves = engine::scene::unorm16_to_half(&texel);
        let v: Vec<f64> = halves.chunks_exact(2).take(3).map(|h| half_to_f64(u16::from_le_bytes([h[0], h[1]])) * 2.0 - 1.0).collect();
        worst = worst.max(((v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt() - 1.0).abs());
    }
    assert!(worst <= 1e-3, "half-float normals are {worst} from unit length");
}

/// IEEE half to f64, written out here so the test does not trust the conversion it checks.
fn half_to_f64(h: u16) -> f64 {
    let (e, m) = ((h >> 10) & 0x1f, (h & 0x3ff) as f64);
    assert!(h >> 15 == 0 && e != 0x1f, "unexpected half {h:#x}");
    if e == 0 { m * 2f64.powi(-24) } else { (1.0 + m / 1024.0) * 2f64.powi(e as i32 - 15) }
}

/// One headless frame with the overlay built from `events` and drawn over it (hidden: built and
/// drawn as nothing), captured.
fn render_with_overlay(gpu: &Gpu, rig: &mut Rig, overlay: &mut Overlay, camera: &Camera, frame: u64, events: Vec<egui::Event>) -> Vec<u8> {
    let (w, h) = (rig.target.extent.width, rig.target.extent.height);
    let t = rig
        .target
        .render_with(gpu, &mut rig.renderer, &rig.scene, camera, &Lighting::default(), true, overlay, |overlay, renderer| {
            overlay.build(headless_input(w, h, frame as f64 / 60.0, events), renderer, &mut []);
        })
        .unwrap();
    overlay.push_frame(t.frame_ms, t.gpu_ms, FrameStats::read(gpu, &rig.renderer, 0));
    rig.target.pixels().to_vec()
}

#[test]
fn overlay_draws_inside_its_window_and_leaves_the_rest_of_the_frame_alone() {
    let gpu = gpu();
    let (w, h) = (640u32, 560u32);
    let pack = cube_pack(&[Mat4::from_translation(Vec3::new(0.0, 0.0, -3.0)) * Mat4::from_rotation_y(0.6)], WHITE4, Material::default());
    let mut rig = Rig::new(&gpu, &pack, w, h);
    let cam = looking_down_neg_z(0.0);
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
    let plain = rig.target.pixels().to_vec();
    let mut overlay = Overlay::new(&gpu, OFFSCREEN_FORMAT, 1).unwrap();
    // A few frames, so the history has samples and the window's layout has settled.
    let mut shown = Vec::new();
    for f in 0..3 {
        shown = render_with_overlay(&gpu, &mut rig, &mut overlay, &cam, f, Vec::new());
    }
    assert_eq!(overlay.history.cpu_ms.len(), 3);
    let [x0, y0, x1, y1] = overlay.window_rect_px().expect("the overlay window is shown");
    assert!(x1 - x0 >= 200.0 && y1 - y0 >= 150.0 && x0 >= 0.0 && y0 >= 0.0 && x1 < w as f32 && y1 < h as f32, "window rect {:?}", [x0, y0, x1, y1]);
    // Edges are anti-aliased over about a pixel: allow one pixel of feathering around the rect.
    let inside = |x: u32, y: u32, margin: f32| (x as f32 + 0.5) >= x0 - margin && (x as f32 + 0.5) <= x1 + margin && (y as f32 + 0.5) >= y0 - margin && (y as f32 + 0.5) <= y1 + margin;
    let (mut in_total, mut in_changed) = (0u32, 0u32);
    for y in 0..h {
        for x in 0..w {
            let changed = pixel(&plain, w, x, y) != pixel(&shown, w, x, y);
            if inside(x, y, -1.0) {
                in_total += 1;
                in_changed += changed as u32;
            } else if !inside(x, y, 1.5) {
                assert!(!changed, "pixel ({x},{y}) outside the overlay window changed: {:?} -> {:?}", pixel(&plain, w, x, y), pixel(&shown, w, x, y));
            }
        }
    }
    // The window is filled (nearly opaque), so almost every pixel under it changes.
    assert!(in_changed as f32 > 0.95 * in_total as f32, "{in_changed} of {in_total} pixels under the overlay changed");
    // Hidden (F1), nothing is drawn at all.
    overlay.visible = false;
    let hidden = render_with_overlay(&gpu, &mut rig, &mut overlay, &cam, 3, Vec::new());
    assert!(hidden == plain, "the hidden overlay changed the frame");
    assert_eq!(overlay.window_rect_px(), None);
    overlay.destroy(&gpu);
    rig.destroy(&gpu);
    assert_clean(&gpu);
}

#[test]
fn the_overlays_prepass_switch_changes_the_shaded_fragment_count() {
    // The 8 full-screen layers of the pre-pass test: W H fragments shaded with the pre-pass,
    // 8 W H without. The switch is pressed the way a user would: pointer events on its checkbox.
    let gpu = gpu();
    let (w, h) = (480u32, 600u32);
    let pack = screen_triangles_pack(&[8.0, 7.0, 6.0, 5.0, 4.0, 3.0, 2.0, 1.0]);
    let mut rig = Rig::new(&gpu, &pack, w, h);
    let cam = looking_down_neg_z(0.0);
    rig.renderer.count_fragments = true;
    let mut overlay = Overlay::new(&gpu, OFFSCREEN_FORMAT, 1).unwrap();
    let pixels = w * h;
    let mut frame = 0u64;
    let mut run = |overlay: &mut Overlay, rig: &mut Rig, events: Vec<egui::Event>| {
        render_with_overlay(&gpu, rig, overlay, &cam, frame, events);
        frame += 1;
        rig.renderer.fragment_count(0).expect("lavapipe can count")
    };
    for _ in 0..2 {
        assert_eq!(run(&mut overlay, &mut rig, Vec::new()), pixels);
    }
    assert_eq!(overlay.last.fragments_shaded, Some(pixels), "the overlay shows what the renderer counted");
    let [_, _, _, bottom] = overlay.window_rect_px().unwrap();
    assert!(bottom <= h as f32, "the whole overlay fits the image ({bottom} px tall)");
    let at = overlay.control_centre("depth pre-pass").expect("the pre-pass checkbox was laid out");
    let button = |pressed| egui::Event::PointerButton { pos: at, button: egui::PointerButton::Primary, pressed, modifiers: egui::Modifiers::NONE };
    for expect_prepass in [false, true] {
        // Press in one frame, release in the next: the checkbox flips on release, after that
        // frame was recorded, so the frame after it is the first without (or with) the pre-pass.
        run(&mut overlay, &mut rig, vec![egui::Event::PointerMoved(at), button(true)]);
        assert_eq!(rig.renderer.prepass, !expect_prepass, "a press alone does not toggle");
        assert_eq!(overlay.control_centre("depth pre-pass"), Some(at), "the layout moved under the pointer");
        run(&mut overlay, &mut rig, vec![button(false)]);
        assert_eq!(rig.renderer.prepass, expect_prepass);
        let shaded = run(&mut overlay, &mut rig, vec![egui::Event::PointerGone]);
        assert_eq!(shaded, if expect_prepass { pixels } else { 8 * pixels });
        assert_eq!(overlay.last.passes.as_ref().map(|p| p.invocations("prepass").is_some()), Some(expect_prepass));
    }
    overlay.destroy(&gpu);
    rig.destroy(&gpu);
    assert_clean(&gpu);
}
