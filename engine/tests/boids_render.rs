//! Boids drawn as instanced meshes on the real device (lavapipe in CI) with validation on:
//! culled with the scene (their counts join the frame's), drawn where they are in view.

use engine::scene::camera::Camera;
use engine::app::headless::{Offscreen, OFFSCREEN_FORMAT};
use engine::render::renderer::{Lighting, Renderer, CLEAR_COLOR};
use engine::scene::GpuScene;
use engine::sim::boids::{BoidParams, Flock, FlockState};
use glam::{Mat4, Vec3};
use pack::{Material, Pack, PackBuilder};

mod common;
use common::packs::{node, push_mesh, quad_vertices};
use common::scenes::cube_vertices;
use common::{assert_clean, gpu, spawn};

const W: u32 = 64;
const H: u32 = 48;

/// Mesh 0: a 2 m square at z = 50 (behind the camera), the scene's one instance. Mesh 1: the
/// bird, a 0.3 m cube with no node, named by a boids spawn (as the cooker packs a spawn's asset).
fn pack_with_a_bird() -> Pack {
    let mut b = PackBuilder::new("generated", "test");
    b.manifest.materials.push(Material::default());
    let (quad, quad_idx) = quad_vertices();
    let square = push_mesh(&mut b, "quad", &quad, &quad_idx, None);
    b.manifest.nodes.push(node("quad", Mat4::from_scale_rotation_translation(Vec3::splat(2.0), glam::Quat::IDENTITY, Vec3::new(0.0, 0.0, 50.0)), square));
    let (mut cube, cube_idx) = cube_vertices();
    for v in &mut cube {
        v.position = (Vec3::from(v.position) * 0.3).to_array();
    }
    assert_eq!(push_mesh(&mut b, "bird", &cube, &cube_idx, None), BIRD);
    // The flock's spawn names it (the cooker writes `mesh` from the spawn's asset).
    b.manifest.spawns.push(spawn("flock", "boids", [0.0; 3], &format!(r#"{{ "mesh": {BIRD} }}"#)));
    b.finish()
}

const BIRD: u32 = 1;

fn flock(positions: &[Vec3]) -> Flock {
    let mut s = FlockState::default();
    for &p in positions {
        // Flying across the view, so the bird is seen from the side (wings edge-on would be thin).
        s.push(p, Vec3::new(3.0, 0.0, 0.0));
    }
    Flock::new(BoidParams::default(), s)
}

#[test]
fn boids_in_view_are_drawn_and_those_behind_the_camera_are_culled() {
    let gpu = gpu();
    let mut target = Offscreen::new(&gpu, W, H).unwrap();
    let mut renderer = Renderer::new(&gpu, OFFSCREEN_FORMAT, 1).unwrap();
    let scene = GpuScene::upload(&gpu, &pack_with_a_bird(), renderer.layouts()).unwrap();
    let camera = Camera {
        position: Vec3::ZERO,
        yaw: 0.0,
        pitch: 0.0,
        fov_y: 60f32.to_radians(),
        near: 0.1,
    };
    // Five in front (one dead centre, 1.5 m away: a bird ~20 px long), three behind the camera.
    let ahead = [
        Vec3::new(0.0, 0.0, -1.5),
        Vec3::new(-2.0, 1.0, -8.0),
        Vec3::new(2.0, -1.0, -8.0),
        Vec3::new(0.0, 2.0, -12.0),
        Vec3::new(1.0, 0.0, -20.0),
    ];
    let behind = [Vec3::new(0.0, 0.0, 3.0), Vec3::new(2.0, 0.0, 6.0), Vec3::new(-1.0, 1.0, 1.0)];
    let positions: Vec<Vec3> = ahead.iter().chain(&behind).copied().collect();
    renderer.boids.fill(&scene, &[flock(&positions)], &[Some(BIRD)]);
    assert_eq!(renderer.boids.boids.len(), 8);
    target.render(&gpu, &mut renderer, &scene, &camera, &Lighting::default(), true).unwrap();
    let c = renderer.visibility.counts;
    assert_eq!(c.boids, 5, "{c:?}");
    // One scene instance plus eight boids tested; the quad and the three behind culled.
    assert_eq!((c.cull.tested, c.cull.culled, c.cull.visible), (9, 4, 5), "{c:?}");
    let i = ((H / 2 * W + W / 2) * 4) as usize;
    let centre = &target.pixels()[i..i + 3];
    let clear: Vec<u8> = CLEAR_COLOR[..3].iter().map(|&c| (c.powf(1.0 / 2.2) * 255.0) as u8).collect();
    assert!(
        centre.iter().zip(&clear).any(|(a, b)| (*a as i32 - *b as i32).abs() > 20),
        "the centre bird covers the centre pixel: {centre:?} vs clear ~{clear:?}"
    );
    // None in view: the pass is skipped (no draws, no validation error), nothing drawn.
    renderer.boids.fill(&scene, &[flock(&behind)], &[Some(BIRD)]);
    target.render(&gpu, &mut renderer, &scene, &camera, &Lighting::default(), true).unwrap();
    assert_eq!(renderer.visibility.counts.boids, 0);
    assert_eq!(renderer.visibility.counts.cull.culled, 4);
    let centre = target.pixels()[i..i + 3].to_vec();
    assert!(centre.iter().zip(&clear).all(|(a, b)| (*a as i32 - *b as i32).abs() <= 3), "only the clear colour: {centre:?}");
    let mut scene = scene;
    scene.destroy(&gpu);
    renderer.destroy(&gpu);
    target.destroy(&gpu);
    assert_clean(&gpu);
}
