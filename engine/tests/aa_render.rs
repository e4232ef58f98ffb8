//! Anti-aliasing (`Renderer::aa`): FXAA turns a sloped edge's hard step into a ramp and leaves
//! the flat areas on either side alone; 4x MSAA ramps a sloped geometric edge, and a MASK
//! material's alpha-tested edge through alpha-to-coverage, in quarter steps. Validation on;
//! black surfaces (stand-in lighting) over the clear colour.

use engine::render::renderer::{AntiAliasing, Lighting};
use glam::{Mat4, Quat, Vec3};
use pack::{AlphaMode, Material, Pack};

mod common;
use common::frames::{looking_down_neg_z, srgb_decode, Rig};
use common::scenes::{cube_pack, WHITE4};
use common::{assert_clean, gpu};

const W: u32 = 96;
const H: u32 = 64;

/// The frame's green channel, row by row (a black quad over the clear colour: 0 against 173),
/// and the passes that ran.
fn frame(aa: AntiAliasing) -> (Vec<u8>, Vec<&'static str>) {
    let turned = Mat4::from_quat(Quat::from_rotation_z(20f32.to_radians())) * Mat4::from_scale(Vec3::new(1.2, 1.2, 0.05));
    let pack = cube_pack(&[turned], WHITE4, Material { base_color: [0.0, 0.0, 0.0, 1.0], ..Material::default() });
    render(&pack, aa, true)
}

/// `pack`'s frame's green channel seen from z = 3 with `aa`, and the passes that ran.
fn render(pack: &Pack, aa: AntiAliasing, prepass: bool) -> (Vec<u8>, Vec<&'static str>) {
    let gpu = gpu();
    let mut rig = Rig::new(&gpu, pack, W, H);
    rig.renderer.aa = aa;
    rig.renderer.prepass = prepass;
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

/// The share of each pixel a black surface covers over the clear colour: 1 - L / L_clear in
/// linear light (the resolve averages radiance; the output's sRGB encoding is undone).
fn coverage(green: &[u8]) -> Vec<f32> {
    let clear = srgb_decode(*green.iter().max().unwrap());
    green.iter().map(|&v| 1.0 - srgb_decode(v) / clear).collect()
}

/// The largest change of coverage between neighbours along rows (`along_rows`) or columns,
/// and how many pixels are partly covered (between 0.1 and 0.9).
fn steps(c: &[f32], along_rows: bool) -> (f32, usize) {
    let at = |x: u32, y: u32| c[(y * W + x) as usize];
    let mut max = 0.0f32;
    for y in 0..H {
        for x in 0..W {
            let next = if along_rows { (x + 1 < W).then(|| at(x + 1, y)) } else { (y + 1 < H).then(|| at(x, y + 1)) };
            if let Some(n) = next {
                max = max.max((n - at(x, y)).abs());
            }
        }
    }
    (max, c.iter().filter(|&&v| v > 0.1 && v < 0.9).count())
}

/// The edge's ramp: MSAA's 4 samples sit at 4 different heights (and widths) of the pixel, so an
/// edge 7 degrees off the horizontal crosses them one at a time as a row walks along it (each
/// sample's crossing at least a pixel after the last: 0.25 / tan 7 - 0.5 > 1), a quarter of
/// coverage a pixel at most. Without MSAA a pixel is in or out: a step of 1.
const TILT_DEGREES: f32 = 7.0;
const RAMP_STEP_MAX: f32 = 1.0 / 3.0;

#[test]
fn msaa_ramps_a_sloped_edge() {
    // A black slab filling the frame below a line through its centre turned 7 degrees.
    let slab = Mat4::from_quat(Quat::from_rotation_z(TILT_DEGREES.to_radians())) * Mat4::from_translation(Vec3::new(0.0, -4.0, 0.0)) * Mat4::from_scale(Vec3::new(12.0, 8.0, 0.05));
    let pack = cube_pack(&[slab], WHITE4, Material { base_color: [0.0, 0.0, 0.0, 1.0], ..Material::default() });
    let (off, _) = render(&pack, AntiAliasing::Off, true);
    let (on, ran) = render(&pack, AntiAliasing::Msaa, true);
    assert!(ran.contains(&"resolve"), "{ran:?}");
    let (step_off, partial_off) = steps(&coverage(&off), true);
    let (step_on, partial_on) = steps(&coverage(&on), true);
    eprintln!("along the edge: largest step {step_off:.3} without, {step_on:.3} with MSAA; partly covered pixels {partial_off} / {partial_on}");
    assert!(step_off > 0.95 && partial_off == 0, "without MSAA the edge should be a staircase: step {step_off}, {partial_off} partial pixels");
    assert!(step_on <= RAMP_STEP_MAX, "MSAA left a step of {step_on} along the edge");
    // The edge crosses all 96 columns, partly covering a pixel in each but those where it runs
    // between two samples' heights (a quarter of a pixel's height of the 0.12 it climbs a column).
    assert!(partial_on >= W as usize / 2, "only {partial_on} partly covered pixels");
}

#[test]
fn alpha_to_coverage_ramps_a_mask_edge() {
    // A face filling the frame, black, its alpha 1 on the left texel column and 0 on the right:
    // bilinear filtering makes alpha fall across the face's middle, where the 0.5 cutoff draws
    // an edge, turned 7 degrees off the vertical. The face's own edges are outside the frame;
    // single-sided, so the back face (cut on the other side) does not show through.
    let face = Mat4::from_quat(Quat::from_rotation_z(TILT_DEGREES.to_radians())) * Mat4::from_scale(Vec3::new(8.0, 8.0, 0.05));
    let texels = [[0, 0, 0, 255], [0, 0, 0, 0], [0, 0, 0, 255], [0, 0, 0, 0]];
    let mask = Material { base_color: [0.0, 0.0, 0.0, 1.0], alpha_mode: AlphaMode::Mask, alpha_cutoff: 0.5, ..Material::default() };
    let pack = cube_pack(&[face], texels, mask);
    let (off, _) = render(&pack, AntiAliasing::Off, true);
    let (step_off, partial_off) = steps(&coverage(&off), false);
    assert!(step_off > 0.95 && partial_off == 0, "without MSAA the alpha test should be a staircase: step {step_off}, {partial_off} partial pixels");
    // Through the pre-pass (alpha-to-coverage writing the samples' depth) and without it (in
    // the shading pass).
    for prepass in [true, false] {
        let (on, _) = render(&pack, AntiAliasing::Msaa, prepass);
        let (step_on, partial_on) = steps(&coverage(&on), false);
        eprintln!("pre-pass {prepass}: along the alpha edge: largest step {step_off:.3} without, {step_on:.3} with MSAA; partly covered pixels {partial_on}");
        assert!(step_on <= RAMP_STEP_MAX, "alpha-to-coverage left a step of {step_on} along the edge (pre-pass {prepass})");
        assert!(partial_on >= H as usize / 2, "only {partial_on} partly covered pixels (pre-pass {prepass})");
    }
}

#[test]
fn switching_msaa_back_and_forth_keeps_both_targets_and_drops_the_unused_one() {
    // The graph keeps a transient image per description: frames alternating MSAA on and off
    // (the overlay's buttons, bench's variants) reuse the 4-sample and the 1-sample targets
    // instead of re-creating them at every switch; 16 frames after MSAA is last used its
    // targets go.
    let gpu = gpu();
    let pack = cube_pack(&[Mat4::from_scale(Vec3::splat(0.8))], WHITE4, Material::default());
    let mut rig = Rig::new(&gpu, &pack, W, H);
    let images = |gpu: &engine::gpu::Gpu| gpu.live_allocations().into_iter().filter(|n| n.starts_with("hdr") || n.starts_with("depth")).collect::<Vec<_>>();
    let frame = |rig: &mut Rig, aa| {
        rig.renderer.aa = aa;
        rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &looking_down_neg_z(3.0), &Lighting::default(), false).unwrap();
    };
    frame(&mut rig, AntiAliasing::Off);
    frame(&mut rig, AntiAliasing::Msaa);
    let both = images(&gpu);
    // hdr and depth at 1 sample, hdr and depth at 4, and the resolve target.
    assert_eq!(both, ["depth", "depth", "hdr", "hdr", "hdr resolved"], "{both:?}");
    for k in 0..10 {
        frame(&mut rig, if k % 2 == 0 { AntiAliasing::Off } else { AntiAliasing::Msaa });
        assert_eq!(images(&gpu), both, "frame {k} made or freed a target");
    }
    for _ in 0..20 {
        frame(&mut rig, AntiAliasing::Off);
    }
    assert_eq!(images(&gpu), ["depth", "hdr"], "the multisampled targets outlived their use");
    rig.destroy(&gpu);
    assert_clean(&gpu);
}
