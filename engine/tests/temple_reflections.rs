//! The demo level's reflection probes (issue 22): the cooked temple (`make cook`, which
//! `make test` runs first) has probes for the hall, the side rooms and the courtyard, and the
//! bronze braziers and the fountain's water show them: turning the renderer's reflections off
//! changes their pixels (to the lightmap's light as the environment), while rough stone, which
//! takes no probe, stays as it was.

use engine::render::renderer::Lighting;
use engine::scene::camera::Camera;
use glam::Vec3;
use std::path::Path;

mod common;
use common::frames::{screen_pixel, Rig};
use common::{assert_clean, gpu};

const W: u32 = 480;
const H: u32 = 270;

/// Pixels of the square of `half` pixels around world point `p` whose colour differs by at
/// least 3 (of 255) between frames `a` and `b`, and the square's size.
fn changed_around(camera: &Camera, a: &[u8], b: &[u8], p: Vec3, half: u32) -> (usize, usize) {
    let (cx, cy) = screen_pixel(camera, W, H, p);
    changed_near(a, b, (cx, cy), half)
}

/// `changed_around` about pixel (cx, cy).
fn changed_near(a: &[u8], b: &[u8], (cx, cy): (u32, u32), half: u32) -> (usize, usize) {
    assert!(cx < W && cy < H, "({cx}, {cy}) is off the frame");
    let (mut changed, mut total) = (0, 0usize);
    for y in cy.saturating_sub(half)..(cy + half).min(H) {
        for x in cx.saturating_sub(half)..(cx + half).min(W) {
            let i = ((y * W + x) * 4) as usize;
            total += 1;
            changed += (0..3).any(|c| (a[i + c] as i32 - b[i + c] as i32).abs() >= 3) as usize;
        }
    }
    (changed, total)
}

#[test]
fn the_temples_bronze_and_water_reflect_its_probes() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../build/temple.pack");
    if !path.exists() {
        eprintln!("skipped: {} not found (`make cook` makes it)", path.display());
        return;
    }
    let pack = pack::Pack::read_file(&path).unwrap();
    let names: Vec<&str> = pack.manifest.reflection_probes.as_ref().map_or(vec![], |r| r.probes.iter().map(|p| p.name.as_str()).collect());
    for want in ["hall", "west_room", "east_room", "courtyard"] {
        assert!(names.contains(&want), "the temple's reflection probes {names:?} lack '{want}'");
    }
    let gpu = gpu();
    let mut rig = Rig::new(&gpu, &pack, W, H);
    // (what, camera, points on it, a pixel of rough stone in the same view)
    let views = [
        // The east brazier's bronze bowl from inside the hall, past a column.
        ("bronze", Camera { position: Vec3::new(0.0, 1.8, -4.5), yaw: -2.25, pitch: -0.13, fov_y: 1.0, near: 0.05 }, vec![Vec3::new(3.4, 1.3, -1.6)], (40, 60)),
        // The fountain's water from the courtyard, the temple front beyond.
        ("water", Camera { position: Vec3::new(0.0, 2.5, 14.5), yaw: 0.0, pitch: -0.45, fov_y: 1.0, near: 0.05 }, vec![Vec3::new(-1.3, 0.55, 9.2), Vec3::new(1.3, 0.55, 9.2)], (30, 255)),
    ];
    for (what, camera, points, stone) in views {
        let mut frames = Vec::new();
        for on in [true, false] {
            rig.renderer.reflections = on;
            rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &camera, &Lighting::default(), true).unwrap();
            frames.push(rig.target.pixels().to_vec());
        }
        for p in points {
            let (changed, total) = changed_around(&camera, &frames[0], &frames[1], p, 6);
            eprintln!("{what} at {p}: {changed} of {total} pixels change with reflections off");
            assert!(total > 0 && changed * 2 >= total, "{what} at {p}: only {changed} of {total} pixels show the probes");
        }
        let (changed, total) = changed_near(&frames[0], &frames[1], stone, 6);
        eprintln!("{what}: rough stone about pixel {stone:?}: {changed} of {total} pixels change");
        assert_eq!(changed, 0, "{what}: rough stone about pixel {stone:?} changed with reflections off");
    }
    rig.destroy(&gpu);
    assert_clean(&gpu);
}
