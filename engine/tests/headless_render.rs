//! Headless rendering on the real Vulkan device (lavapipe in CI) with validation on: every test
//! fails on any validation error. Scenes are built in code so these tests need no cooker.

use engine::scene::camera::Camera;
use engine::render::renderer::{Lighting, CLEAR_COLOR};
use glam::{Mat4, Vec3};
use pack::{LightmapRegion, Material, Node, Pack, PackBuilder, TextureFormat, Vertex};

mod common;
use common::frames::{assert_bytes_near, auto_exposure_of, looking_down_neg_z, pixel, render, screen_pixel, srgb_decode, srgb_encode, tone_mapped_bytes, Rig};
use common::packs::{add_lightmap_page, add_lightmap_pages, node, push_mesh, push_uniform_probes, quad_vertices, static_node};
use common::scenes::{cube_builder, cube_pack, cube_vertices, mesh_pack, screen_triangles_pack, WHITE4};
use common::{assert_clean, gpu};





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
        // Read again, the frame's counts are the same (lavapipe adds a pass's fragment count into
        // its query's result again on each read: the graph reads a frame's queries once).
        assert_eq!(rig.renderer.profile(&gpu, 0).as_ref(), Some(&s1), "a second read of the profile differs");
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


// ---- HDR target, tone map, emission, sun shadow map ------------------------------------------
