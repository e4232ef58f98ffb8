//! The frame graph on a real device: a debug pass added with one line (`passes::register`)
//! shows the depth buffer, and the graph drops the passes only the shaded frame needed.

use engine::render::renderer::Lighting;

mod common;
use common::frames::{looking_down_neg_z, pixel, srgb_encode, Rig};
use common::{assert_clean, gpu, square_pack};

#[test]
fn the_depth_view_shows_znear_over_distance_and_the_graph_skips_the_shading_it_hides() {
    let gpu = gpu();
    let (w, h) = (48u32, 32u32);
    let cam = looking_down_neg_z(0.0);
    for distance in [2.0f32, 8.0] {
        let pack = square_pack("quad", distance, -distance, pack::Material::default());
        let mut rig = Rig::new(&gpu, &pack, w, h);
        rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
        let ran = rig.renderer.passes_run(0);
        assert_eq!(ran, ["prepass", "shading", "tonemap", "readback"], "the frame without the view");
        let shaded = pixel(rig.target.pixels(), w, w / 2, h / 2);

        rig.renderer.depth_view = true;
        rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
        // Reversed-Z with an infinite far plane stores znear / z: the grey is exactly that.
        let want = srgb_encode(cam.near / distance);
        let got = pixel(rig.target.pixels(), w, w / 2, h / 2);
        assert!(got[..3].iter().all(|&c| (c as i32 - want as i32).abs() <= 1), "quad at {distance} m: {got:?}, want {want}");
        assert_ne!(got, shaded, "the view replaced the shaded frame");
        // Only the depth is needed now: the graph dropped the shading pass (it only tests depth
        // after the pre-pass) and the tone map (its output is overwritten).
        assert_eq!(rig.renderer.passes_run(0), ["prepass", "depth view", "readback"]);

        // Without the pre-pass the shading pass writes the depth, so it runs again.
        rig.renderer.prepass = false;
        rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
        assert_eq!(rig.renderer.passes_run(0), ["shading", "depth view", "readback"]);
        assert_eq!(pixel(rig.target.pixels(), w, w / 2, h / 2), got, "the same depth either way");
        rig.destroy(&gpu);
    }
    assert_clean(&gpu);
}
