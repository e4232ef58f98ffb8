//! Anti-aliasing (`Renderer::aa`): FXAA turns a sloped edge's hard step into a ramp and leaves
//! the flat areas on either side alone. Validation on; the scene is a quad turned 20 degrees
//! (black, stand-in lighting) over the clear colour.

use engine::render::renderer::{AntiAliasing, Lighting};
use glam::{Mat4, Quat, Vec3};
use pack::Material;

mod common;
use common::frames::{looking_down_neg_z, Rig};
use common::scenes::{cube_pack, WHITE4};
use common::{assert_clean, gpu};

const W: u32 = 96;
const H: u32 = 64;

/// The frame's green channel, row by row (a black quad over the clear colour: 0 against 173),
/// and the passes that ran.
fn frame(aa: AntiAliasing) -> (Vec<u8>, Vec<&'static str>) {
    let gpu = gpu();
    let turned = Mat4::from_quat(Quat::from_rotation_z(20f32.to_radians())) * Mat4::from_scale(Vec3::new(1.2, 1.2, 0.05));
    let pack = cube_pack(&[turned], WHITE4, Material { base_color: [0.0, 0.0, 0.0, 1.0], ..Material::default() });
    let mut rig = Rig::new(&gpu, &pack, W, H);
    rig.renderer.aa = aa;
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &looking_down_neg_z(3.0), &Lighting::default(), true).unwrap();
    let px: Vec<u8> = rig.target.pixels().chunks_exact(4).map(|p| p[1]).collect();
    let ran = rig.renderer.passes_run(0);
    rig.destroy(&gpu);
    assert_clean(&gpu);
    (px, ran)
}

#[test]
fn fxaa_ramps_a_sloped_edge_and_keeps_flat_areas() {
    let (off, ran_off) = frame(AntiAliasing::Off);
    let (on, ran_on) = frame(AntiAliasing::Fxaa);
    assert!(!ran_off.contains(&"fxaa") && ran_on.contains(&"fxaa"), "{ran_off:?} / {ran_on:?}");
    let (lo, hi) = (*off.iter().min().unwrap() as i32, *off.iter().max().unwrap() as i32);
    assert!(hi - lo > 60, "the test needs contrast: {lo}..{hi}");
    // Without anti-aliasing coverage is all or nothing: an edge pixel is background or quad.
    let between = |v: u8| (v as i32) > lo + (hi - lo) / 8 && (v as i32) < hi - (hi - lo) / 8;
    let intermediate = |img: &[u8]| img.iter().filter(|&&v| between(v)).count();
    let (n_off, n_on) = (intermediate(&off), intermediate(&on));
    // Along the edges FXAA blends: many more in-between pixels (the quad's four edges cross ~150).
    eprintln!("in-between pixels: {n_off} without, {n_on} with FXAA");
    assert!(n_on >= n_off + 60, "FXAA made {n_on} in-between pixels, {n_off} without");
    // Flat areas (every pixel of a 5x5 neighbourhood equal) are untouched.
    let mut flat = 0;
    for y in 2..H - 2 {
        for x in 2..W - 2 {
            let v = off[(y * W + x) as usize];
            if (0..25).all(|k| off[((y + k / 5 - 2) * W + x + k % 5 - 2) as usize] == v) {
                flat += 1;
                assert_eq!(on[(y * W + x) as usize], v, "FXAA changed a flat pixel at ({x}, {y})");
            }
        }
    }
    assert!(flat > (W * H / 2) as usize, "only {flat} flat pixels");
}
