//! Drawing a pack headless and reading the frame: the rig the renderer tests draw with, pixels,
//! the sRGB transfer functions and the tone map's bytes for a known radiance.

use engine::scene::camera::Camera;
use engine::gpu::Gpu;
use engine::app::headless::{Offscreen, OFFSCREEN_FORMAT};
use engine::render::renderer::{Lighting, Renderer};
use engine::scene::GpuScene;
use glam::Vec3;
use pack::Pack;

/// A headless target, a renderer and an uploaded pack: what the renderer tests draw with.
pub struct Rig {
    pub target: Offscreen,
    pub renderer: Renderer,
    pub scene: GpuScene,
}

impl Rig {
    pub fn new(gpu: &Gpu, pack: &Pack, w: u32, h: u32) -> Rig {
        let target = Offscreen::new(gpu, w, h).unwrap();
        let renderer = Renderer::new(gpu, OFFSCREEN_FORMAT, 1).unwrap();
        let scene = GpuScene::upload(gpu, pack, renderer.layouts()).unwrap();
        Rig { target, renderer, scene }
    }

    /// Draw another pack with the same target and renderer (and its state).
    pub fn reload(&mut self, gpu: &Gpu, pack: &Pack) {
        self.scene.destroy(gpu);
        self.scene = GpuScene::upload(gpu, pack, self.renderer.layouts()).unwrap();
    }

    pub fn destroy(mut self, gpu: &Gpu) {
        self.scene.destroy(gpu);
        self.renderer.destroy(gpu);
        self.target.destroy(gpu);
    }
}

/// One frame of `pack` from `camera` with the stand-in lighting (tone-mapped when baked), read back.
pub fn render(gpu: &Gpu, pack: &Pack, camera: &Camera, w: u32, h: u32) -> Vec<u8> {
    let mut rig = Rig::new(gpu, pack, w, h);
    rig.target.render(gpu, &mut rig.renderer, &rig.scene, camera, &Lighting::default(), true).unwrap();
    let px = rig.target.pixels().to_vec();
    rig.destroy(gpu);
    px
}

/// The RGBA8 pixel at (x, y) of a read-back frame `w` pixels wide (row 0 at the top).
pub fn pixel(px: &[u8], w: u32, x: u32, y: u32) -> [u8; 4] {
    let i = ((y * w + x) * 4) as usize;
    px[i..i + 4].try_into().unwrap()
}

/// Linear [0, 1] to an sRGB byte, as the `_SRGB` attachment encodes.
pub fn srgb_encode(linear: f32) -> u8 {
    let c = if linear <= 0.0031308 { linear * 12.92 } else { 1.055 * linear.powf(1.0 / 2.4) - 0.055 };
    (c.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// A 60 degree camera at (0, 0, z) looking down -Z.
pub fn looking_down_neg_z(z: f32) -> Camera {
    Camera { position: Vec3::new(0.0, 0.0, z), yaw: 0.0, pitch: 0.0, fov_y: 60f32.to_radians(), near: 0.1 }
}

/// An sRGB byte to linear, as an `_SRGB` texture is sampled.
pub fn srgb_decode(byte: u8) -> f32 {
    let v = byte as f32 / 255.0;
    if v <= 0.04045 { v / 12.92 } else { ((v + 0.055) / 1.055).powf(2.4) }
}

/// The exposure `add_lightmap_page(b)` gives (scene.rs: k / log-average, k = 0.18, albedo 0.5).
pub fn auto_exposure(b: f32) -> f32 {
    0.18 / (1e-4 + 0.5 * b)
}

/// The exposure of lightmap pages holding the grey texels `b` (nits): scene.rs's k / L, L the
/// log-average of 1e-4 + 0.5 b over the lit texels.
pub fn auto_exposure_of(b: &[f32]) -> f32 {
    let lit: Vec<f64> = b.iter().filter(|&&b| b > 0.0).map(|&b| (1e-4 + 0.5 * b as f64).ln()).collect();
    0.18 / (lit.iter().sum::<f64>() / lit.len() as f64).exp() as f32
}

/// The tone map's output bytes for linear radiance `l`, computed here from the formula of
/// textures.md §5.7: exposure, Reinhard on luminance, colour restored with exponent `s`, then the
/// sRGB encode.
pub fn tone_mapped_bytes(l: [f32; 3], exposure: f32, s: f32) -> [u8; 3] {
    let ls = l.map(|c| c * exposure);
    let y = 0.2126 * ls[0] + 0.7152 * ls[1] + 0.0722 * ls[2];
    let ld = y / (1.0 + y);
    ls.map(|c| srgb_encode((c / y).powf(s) * ld))
}

/// Every colour channel of `got` within `tolerance` of `want`.
pub fn assert_bytes_near(what: &str, got: [u8; 4], want: [u8; 3], tolerance: i32) {
    for c in 0..3 {
        assert!((got[c] as i32 - want[c] as i32).abs() <= tolerance, "{what}: got {got:?}, want {want:?} (+-{tolerance})");
    }
}

/// The pixel that world point `p` lands in, seen by `camera` in a `w` x `h` frame.
pub fn screen_pixel(camera: &Camera, w: u32, h: u32, p: Vec3) -> (u32, u32) {
    let c = camera.view_proj(w as f32 / h as f32) * p.extend(1.0);
    (((c.x / c.w * 0.5 + 0.5) * w as f32) as u32, ((c.y / c.w * 0.5 + 0.5) * h as f32) as u32)
}
