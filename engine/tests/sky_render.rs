//! The sky: a baked level's sky radiance and the sun's disc as the background, put behind the
//! frame by the tone map, through the same exposure and operator as the surfaces (closed-form
//! bytes, validation on).

use engine::render::renderer::Lighting;
use engine::scene::camera::Camera;
use glam::Vec3;
use pack::{Pack, PackBuilder};

mod common;
use common::frames::{assert_bytes_near, auto_exposure, pixel, screen_pixel, srgb_encode, tone_mapped_bytes, Rig};
use common::packs::{add_baked_light, sun};
use common::{assert_clean, gpu};

const LIGHTMAP_B: f32 = 100.0;
const SKY: [f32; 3] = [0.4, 0.6, 1.0];
const SKY_NITS: f32 = 300.0;

/// A baked level with nothing in view: a lightmapped quad far below (it sets the exposure), a
/// sky of `SKY` x `SKY_NITS`, and a sun of `lux` toward `towards_sun` with `angular_radius`.
fn sky_pack(lux: f32, towards_sun: Vec3, angular_radius: f32) -> Pack {
    let mut b = PackBuilder::new("generated", "test");
    add_baked_light(&mut b, LIGHTMAP_B, Vec3::new(0.0, -500.0, 0.0));
    b.manifest.sky = Some(pack::Sky { color: SKY, intensity: SKY_NITS });
    b.manifest.lights.push(sun(lux, towards_sun, angular_radius));
    b.finish()
}

#[test]
fn the_background_is_the_skys_radiance_and_the_suns_disc_exposed_and_tone_mapped() {
    // Looking down -Z with the sun straight ahead: the centre pixel is in the disc (radius 5
    // degrees: E / (2 pi (1 - cos 5 deg)) = 41.8 E nits on top of the sky); a pixel 15 degrees
    // up is sky alone.
    let gpu = gpu();
    let (w, h) = (64u32, 64u32);
    let (lux, radius) = (20.0f32, 5f32.to_radians());
    let pack = sky_pack(lux, -Vec3::Z, radius);
    let mut rig = Rig::new(&gpu, &pack, w, h);
    rig.renderer.tonemap.saturation = 1.0;
    let cam = Camera { position: Vec3::ZERO, yaw: 0.0, pitch: 0.0, fov_y: 60f32.to_radians(), near: 0.1 };
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
    let exposure = auto_exposure(LIGHTMAP_B);
    let sky = SKY.map(|c| c * SKY_NITS);
    let disc = lux / (2.0 * std::f32::consts::PI * (1.0 - radius.cos()));
    let centre = pixel(rig.target.pixels(), w, w / 2, h / 2);
    let (ux, uy) = screen_pixel(&cam, w, h, Vec3::new(0.0, 15f32.to_radians().tan(), -1.0));
    let up = pixel(rig.target.pixels(), w, ux, uy);
    eprintln!("sun disc {disc:.1} nits: centre {centre:?}, sky {up:?}");
    assert_bytes_near("the sky", up, tone_mapped_bytes(sky, exposure, 1.0), 1);
    assert_bytes_near("the sun's disc", centre, tone_mapped_bytes(sky.map(|c| c + disc), exposure, 1.0), 1);
    // The tone map draws the background; there is no sky pass.
    assert!(!rig.renderer.pass_names().any(|n| n == "sky"));
    rig.destroy(&gpu);
    assert_clean(&gpu);
}

#[test]
fn a_level_without_baked_light_keeps_the_clear_colour() {
    // No lightmaps: the stand-in lighting, display-referred; the clear colour stays, as it is.
    let gpu = gpu();
    let mut b = PackBuilder::new("generated", "test");
    b.manifest.sky = Some(pack::Sky { color: SKY, intensity: SKY_NITS });
    let pack = b.finish();
    let mut rig = Rig::new(&gpu, &pack, 32, 32);
    let cam = Camera { position: Vec3::ZERO, yaw: 0.0, pitch: 0.0, fov_y: 60f32.to_radians(), near: 0.1 };
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
    let [r, g, b, _] = engine::render::renderer::CLEAR_COLOR;
    assert_bytes_near("the clear colour", pixel(rig.target.pixels(), 32, 16, 16), [r, g, b].map(srgb_encode), 1);
    rig.destroy(&gpu);
    assert_clean(&gpu);
}
