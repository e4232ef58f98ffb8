//! A headless stage made again on a new device (`Stage::recover`, what a device loss leads to)
//! draws, from then on, exactly the frames the old one would have drawn: the renderer's settings,
//! the LOD state, the characters' playback and the scene's instances as the game left them all
//! carry over. The loss itself (`ENGINE_INJECT_DEVICE_LOST`) is process-wide, so the demo's
//! tests inject it (tests/test_render.py); here the stage is made again without one.

mod common;

use common::assert_clean;
use engine::app::headless::{Stage, StageOptions};
use engine::gpu::{DevicePreference, GpuOptions};
use engine::render::renderer::{AntiAliasing, Lighting};
use engine::render::scale::RenderScale;
use engine::scene::camera::Camera;
use std::path::Path;

const W: u32 = 160;
const H: u32 = 90;

fn options() -> StageOptions {
    StageOptions {
        gpu: GpuOptions { validation: true, device: DevicePreference::from_env(), surface_extensions: vec![], pipeline_cache: None },
        width: W,
        height: H,
        shadow_map_size: 512,
        aa: AntiAliasing::Fxaa,
        render_scale: RenderScale::Fixed(1.0),
        upscaler: None,
        overlay: false,
    }
}

/// One frame `dt` seconds of animation on, read back.
fn frame(stage: &mut Stage, camera: &Camera, lighting: &Lighting) -> Vec<u8> {
    stage.renderer.animate(&mut stage.scene, 1.0 / 60.0);
    stage.target.render(&stage.gpu, &mut stage.renderer, &stage.scene, camera, lighting, true).expect("a frame");
    stage.target.pixels().to_vec()
}

#[test]
fn a_stage_made_again_draws_the_frames_the_old_one_would_have() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../build/temple.pack");
    let pack = pack::Pack::read_file(&path).unwrap_or_else(|e| panic!("{}: {e} (made by `make cook`)", path.display()));
    let opts = options();
    let (mut kept, mut remade) = (Stage::new(&opts, &pack, &mut |_| {}).unwrap(), Stage::new(&opts, &pack, &mut |_| {}).unwrap());
    assert!(kept.renderer.animation.is_some(), "the temple has characters: their playback must carry over");
    let (min, max) = kept.scene.bounds();
    let camera = Camera::for_pack(&pack.manifest, min, max);
    let lighting = Lighting::for_pack(&pack.manifest);
    // State the game gave both before the loss: a setting off, an instance removed.
    let removed = kept.scene.instances.id_at(0);
    for s in [&mut kept, &mut remade] {
        s.renderer.sky = false;
        s.scene.instances.despawn(removed).unwrap();
    }
    for f in 0..30 {
        if f == 12 {
            remade.recover(&opts, &pack).expect("the stage made again");
            assert!(!remade.renderer.sky, "a setting was lost");
            assert!(remade.scene.instances.index_of(removed).is_err(), "the removed instance came back");
        }
        let (a, b) = (frame(&mut kept, &camera, &lighting), frame(&mut remade, &camera, &lighting));
        let differ = a.chunks(4).zip(b.chunks(4)).filter(|(p, q)| p != q).count();
        assert_eq!(differ, 0, "frame {f}: {differ} pixels differ from the stage that was not made again");
        assert_eq!(kept.renderer.visibility.counts.lod_histogram, remade.renderer.visibility.counts.lod_histogram, "frame {f}");
    }
    // The characters moved after the recovery (the frames compared are not all one picture).
    let animation = remade.renderer.animation.as_ref().unwrap();
    assert!(animation.instances.iter().all(|a| a.animator.time > 29.0 / 60.0), "the playback started over");
    assert_clean(&kept.gpu);
    assert_clean(&remade.gpu);
    assert_eq!(kept.destroy(), 0);
    assert_eq!(remade.destroy(), 0, "the teardown of both devices of the stage made again is clean");
}
