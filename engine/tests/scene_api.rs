//! The scene API while rendering: spawn, move and despawn instances through handles, with the
//! culling counters exact after each step and the picture following.

use engine::scene::camera::Camera;
use engine::scene::instances::InstanceError;
use engine::render::renderer::Lighting;
use engine::scene::Spawn;
use glam::{Mat4, Vec3};

mod common;
use common::frames::{looking_down_neg_z, pixel, screen_pixel, Rig};
use common::{assert_clean, gpu, square_pack};

#[test]
fn instances_spawned_moved_and_despawned_while_rendering_are_culled_and_drawn_exactly() {
    let gpu = gpu();
    let (w, h) = (64u32, 48u32);
    // One 0.5 m quad at the origin (mesh 0, dynamic, white), seen from 6 m away along +Z; the
    // pack also has a red material (1) for overrides.
    let mut pack = square_pack("quad", 0.25, 0.0, pack::Material::default());
    pack.manifest.materials.push(pack::Material { base_color: [1.0, 0.0, 0.0, 1.0], ..Default::default() });
    let mut rig = Rig::new(&gpu, &pack, w, h);
    let cam: Camera = looking_down_neg_z(6.0);
    let placed = rig.scene.instances.id_at(0);
    let frame = |rig: &mut Rig| {
        rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
        let c = rig.renderer.visibility.counts.cull;
        (c.tested, c.visible, c.culled, rig.target.pixels().to_vec())
    };
    let lit = |px: &[u8], p: Vec3| {
        let (x, y) = screen_pixel(&cam, w, h, p);
        pixel(px, w, x, y) != pixel(px, w, 1, 1)
    };
    let (t, v, c, px) = frame(&mut rig);
    assert_eq!((t, v, c), (1, 1, 0));
    assert!(lit(&px, Vec3::ZERO));

    // Spawn one in view (left) and one behind the camera.
    let left = Vec3::new(-1.5, 0.0, 0.0);
    let a = rig.scene.spawn(Spawn::dynamic(0, Mat4::from_translation(left))).unwrap();
    let behind = rig.scene.spawn(Spawn::dynamic(0, Mat4::from_translation(Vec3::new(0.0, 0.0, 10.0)))).unwrap();
    let (t, v, c, px) = frame(&mut rig);
    assert_eq!((t, v, c), (3, 2, 1));
    assert!(lit(&px, left));

    // Move the one behind into view (right), and the left one out of view.
    let right = Vec3::new(1.5, 0.0, 0.0);
    rig.scene.set_transform(behind, Mat4::from_translation(right)).unwrap();
    rig.scene.set_transform(a, Mat4::from_translation(Vec3::new(-40.0, 0.0, 0.0))).unwrap();
    let (t, v, c, px) = frame(&mut rig);
    assert_eq!((t, v, c), (3, 2, 1));
    assert!(lit(&px, right) && !lit(&px, left));

    // Despawn the first placed one: the others keep their handles.
    rig.scene.despawn(placed).unwrap();
    let (t, v, c, px) = frame(&mut rig);
    assert_eq!((t, v, c), (2, 1, 1));
    assert!(!lit(&px, Vec3::ZERO) && lit(&px, right));
    assert_eq!(rig.scene.set_transform(placed, Mat4::IDENTITY), Err(InstanceError::Stale(placed)));
    assert_eq!(rig.scene.spawn(Spawn::dynamic(7, Mat4::IDENTITY)), Err(InstanceError::NoMesh { mesh: 7, meshes: 1 }));
    assert_eq!(rig.scene.spawn(Spawn { material: Some(2), ..Spawn::dynamic(0, Mat4::IDENTITY) }), Err(InstanceError::NoMaterial { material: 2, materials: 2 }));
    // The same mesh with a material override: drawn red where the plain one is white, each in a
    // call of its own (instances batch only with their own material).
    let red = rig.scene.spawn(Spawn { material: Some(1), ..Spawn::dynamic(0, Mat4::from_translation(left)) }).unwrap();
    let (t, v, _, px) = frame(&mut rig);
    assert_eq!((t, v), (3, 2));
    let (at_left, at_right) = (pixel(&px, w, screen_pixel(&cam, w, h, left).0, screen_pixel(&cam, w, h, left).1), pixel(&px, w, screen_pixel(&cam, w, h, right).0, screen_pixel(&cam, w, h, right).1));
    assert!(at_left[0] > 100 && at_left[1] < 10 && at_left[2] < 10, "the override is red: {at_left:?}");
    assert!(at_right[1] > 100, "the plain instance keeps its white material: {at_right:?}");
    assert_eq!(rig.renderer.draw_calls, 4, "two instances, two materials: a pre-pass and a shading call each");
    for id in [a, behind, red] {
        rig.scene.despawn(id).unwrap();
    }
    let (t, v, c, _) = frame(&mut rig);
    assert_eq!((t, v, c), (0, 0, 0));
    rig.destroy(&gpu);
    assert_clean(&gpu);
}
