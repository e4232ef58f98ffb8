//! The particle pass on the real device (lavapipe in CI) with validation on: depth testing
//! against the pre-pass depth, the two blend modes' closed-form pixels, and an empty queue.
//! Stand-in lighting (no baked data), so the tone map passes the HDR values through and a pixel
//! is the sRGB encoding of the blend equation's result.

use engine::scene::camera::Camera;
use engine::gpu::Gpu;
use engine::app::headless::{Offscreen, OFFSCREEN_FORMAT};
use engine::render::renderer::{Lighting, Renderer, CLEAR_COLOR};
use engine::scene::GpuScene;
use engine::sim::particles::{Billboard, Blend};
use glam::Vec3;
use pack::{Material, Pack};

mod common;
use common::{assert_clean, gpu, square_pack};

/// A grey 8 m square facing +Z, centred on (0, 0, z).
fn wall_pack(z: f32) -> Pack {
    square_pack("wall", 4.0, z, Material { base_color: [0.5, 0.5, 0.5, 1.0], ..Material::default() })
}

const W: u32 = 64;
const H: u32 = 48;

fn camera() -> Camera {
    Camera {
        position: Vec3::ZERO,
        yaw: 0.0,
        pitch: 0.0,
        fov_y: 60f32.to_radians(),
        near: 0.1,
    }
}

struct Rig {
    target: Offscreen,
    renderer: Renderer,
    scene: GpuScene,
}

impl Rig {
    fn new(gpu: &Gpu, pack: &Pack) -> Rig {
        let target = Offscreen::new(gpu, W, H).unwrap();
        let renderer = Renderer::new(gpu, OFFSCREEN_FORMAT, 1).unwrap();
        let scene = GpuScene::upload(gpu, pack, renderer.layouts()).unwrap();
        Rig { target, renderer, scene }
    }

    /// Render one frame with `billboards` queued (one batch each) and return the centre pixel.
    fn centre_with(&mut self, gpu: &Gpu, batches: &[(Blend, Billboard)]) -> [u8; 4] {
        self.renderer.particles.clear();
        for (blend, b) in batches {
            self.renderer.particles.push(*blend, std::slice::from_ref(b));
        }
        self.target.render(gpu, &mut self.renderer, &self.scene, &camera(), &Lighting::default(), true).unwrap();
        let i = ((H / 2 * W + W / 2) * 4) as usize;
        self.target.pixels()[i..i + 4].try_into().unwrap()
    }

    fn destroy(mut self, gpu: &Gpu) {
        self.scene.destroy(gpu);
        self.renderer.destroy(gpu);
        self.target.destroy(gpu);
    }
}

fn srgb_encode(linear: f32) -> u8 {
    let c = if linear <= 0.0031308 { linear * 12.92 } else { 1.055 * linear.powf(1.0 / 2.4) - 0.055 };
    (c.clamp(0.0, 1.0) * 255.0).round() as u8
}

fn srgb_decode(byte: u8) -> f32 {
    let v = byte as f32 / 255.0;
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

fn assert_near(got: [u8; 4], want: [f32; 3], what: &str) {
    let want = want.map(srgb_encode);
    for c in 0..3 {
        assert!((got[c] as i32 - want[c] as i32).abs() <= 1, "{what}: got {got:?}, want {want:?}");
    }
}

/// A 4 m particle 3 m in front of the camera covers the centre pixel with falloff ~1 there
/// (0.5 px off-centre of a ~28 px half-size quad: 1 - r^2 > 0.999).
fn particle(z: f32, color: [f32; 4]) -> Billboard {
    Billboard {
        position: [0.0, 0.0, z],
        size: 4.0,
        color,
    }
}

#[test]
fn alpha_and_additive_blending_give_the_closed_form_pixels() {
    let gpu = gpu();
    // The wall is behind the camera: the centre shows the clear colour (passed through).
    let mut rig = Rig::new(&gpu, &wall_pack(10.0));
    let bg = [CLEAR_COLOR[0], CLEAR_COLOR[1], CLEAR_COLOR[2]];
    let c = [0.8f32, 0.3, 0.1];
    let a = 0.4f32;
    let none = rig.centre_with(&gpu, &[]);
    assert_near(none, bg, "no particles");
    let alpha = rig.centre_with(&gpu, &[(Blend::Alpha, particle(-3.0, [c[0], c[1], c[2], a]))]);
    assert_near(alpha, [0, 1, 2].map(|i| c[i] * a + bg[i] * (1.0 - a)), "alpha blend");
    let additive = rig.centre_with(&gpu, &[(Blend::Additive, particle(-3.0, [c[0], c[1], c[2], a]))]);
    assert_near(additive, [0, 1, 2].map(|i| bg[i] + c[i] * a), "additive blend");
    // Two alpha layers, far then near: the "over" operator applied twice in that order.
    let (c2, a2) = ([0.1f32, 0.2, 0.9], 0.5f32);
    let two = rig.centre_with(
        &gpu,
        &[(Blend::Alpha, particle(-4.0, [c[0], c[1], c[2], a])), (Blend::Alpha, particle(-3.0, [c2[0], c2[1], c2[2], a2]))],
    );
    assert_near(two, [0, 1, 2].map(|i| c2[i] * a2 + (c[i] * a + bg[i] * (1.0 - a)) * (1.0 - a2)), "two alpha layers");
    assert_eq!(rig.renderer.visibility.counts.particles, 2);
    let t = rig.renderer.profile(&gpu, 0);
    println!("pass times with 2 particles: {t:?}");
    if let Some(t) = t {
        assert!(t.ms("particles") > 0.0, "the particle pass ran between its timestamps: {t:?}");
    }
    rig.destroy(&gpu);
    assert_clean(&gpu);
}

#[test]
fn a_particle_in_front_of_a_wall_shows_and_one_behind_it_is_hidden() {
    let gpu = gpu();
    let mut rig = Rig::new(&gpu, &wall_pack(-5.0));
    let wall = rig.centre_with(&gpu, &[]);
    assert_ne!(&wall[..3], &CLEAR_COLOR[..3].iter().map(|&c| srgb_encode(c)).collect::<Vec<u8>>()[..], "the wall covers the centre");
    let (c, a) = ([1.0f32, 0.2, 0.0], 0.5f32);
    let wall_lin = [0, 1, 2].map(|i| srgb_decode(wall[i]));
    let front = rig.centre_with(&gpu, &[(Blend::Alpha, particle(-3.0, [c[0], c[1], c[2], a]))]);
    assert_near(front, [0, 1, 2].map(|i| c[i] * a + wall_lin[i] * (1.0 - a)), "in front of the wall");
    // Behind the wall: the pre-pass depth rejects every fragment, additive or not.
    for blend in [Blend::Alpha, Blend::Additive] {
        let behind = rig.centre_with(&gpu, &[(blend, particle(-7.0, [c[0], c[1], c[2], a]))]);
        assert_eq!(behind, wall, "{blend:?} particle behind the wall");
    }
    rig.destroy(&gpu);
    assert_clean(&gpu);
}

#[test]
fn no_particles_skips_the_pass_and_leaves_the_frame_unchanged() {
    let gpu = gpu();
    let mut rig = Rig::new(&gpu, &wall_pack(-5.0));
    let before = rig.centre_with(&gpu, &[]);
    assert_eq!(rig.renderer.visibility.counts.particles, 0);
    // A frame with particles, then an empty queue again: nothing stale is drawn.
    let with = rig.centre_with(&gpu, &[(Blend::Additive, particle(-3.0, [1.0, 1.0, 1.0, 1.0]))]);
    assert_ne!(with, before, "the particle brightens the wall");
    let after = rig.centre_with(&gpu, &[]);
    assert_eq!(after, before);
    assert_eq!(rig.renderer.visibility.counts.particles, 0);
    rig.destroy(&gpu);
    // Nothing in view either (the wall is culled, so no pre-pass): the pass is skipped, not
    // recorded empty. (An empty pack is not used: uploading it copies zero-sized buffers.)
    let mut empty = Rig::new(&gpu, &wall_pack(10.0));
    assert_near(empty.centre_with(&gpu, &[]), [CLEAR_COLOR[0], CLEAR_COLOR[1], CLEAR_COLOR[2]], "nothing in view");
    assert_eq!(empty.renderer.visibility.counts.cull.visible, 0);
    empty.destroy(&gpu);
    assert_clean(&gpu);
}
