//! Every GPU object a constructor made is freed when a later step fails (issue 20): each
//! construction is made to fail at each of its allocations in turn (`Gpu::fail_allocation`, as if
//! the device ran out of memory) and must return the error with the device's live allocations
//! exactly as they were before it started, validation clean; left to succeed, it must work.

use anyhow::Result;
use engine::anim::animated::AnimatedScene;
use engine::scene::camera::Camera;
use engine::gpu::{Destroy, Gpu};
use engine::app::headless::{Offscreen, OFFSCREEN_FORMAT};
use engine::render::renderer::{Lighting, Renderer};
use engine::scene::GpuScene;
use glam::{Mat4, Vec3};
use pack::Material;

mod common;
use common::packs::{add_lightmap_page, push_uniform_probes};
use common::scenes::{cube_builder, WHITE4};
use common::{assert_clean, cook, gpu, samples};

/// Make `make` fail at its first, second, ... allocation until it succeeds; every failure must
/// leave the live allocations as they were. Returns how many allocations the success made
/// (temporaries included).
fn fail_at_each_allocation<T: Destroy>(gpu: &Gpu, what: &str, make: impl Fn() -> Result<T>) -> u64 {
    let before = gpu.live_allocations();
    for n in 1.. {
        gpu.fail_allocation(n);
        match make() {
            Ok(mut made) => {
                gpu.fail_allocation(0);
                let after = gpu.live_allocations();
                made.destroy(gpu);
                assert_eq!(gpu.live_allocations(), before, "{what}: destroy frees what it made");
                eprintln!("{what}: {} allocations, {} of them live after it", n - 1, after.len() - before.len());
                // Temporaries (staging buffers) are among the allocations, freed on the way.
                assert!(after.len() - before.len() <= n as usize - 1, "{what}: {after:?}");
                return n - 1;
            }
            Err(e) => {
                let e = format!("{e:#}");
                assert!(e.contains("injected by Gpu::fail_allocation"), "{what}, allocation {n}: another error: {e}");
                assert_eq!(gpu.live_allocations(), before, "{what}: failing at allocation {n} ({e}) left allocations behind");
            }
        }
    }
    unreachable!()
}

/// A scene with a texture, a lightmap page and probes: every kind of upload a pack makes.
fn scene_pack() -> pack::Pack {
    let mut b = cube_builder(&[Mat4::IDENTITY, Mat4::from_translation(Vec3::X * 3.0)], WHITE4, Material::default());
    add_lightmap_page(&mut b, 1.0);
    push_uniform_probes(&mut b, 1.0, 1.0);
    b.finish()
}

#[test]
fn every_constructor_frees_what_it_made_when_an_allocation_fails() {
    let gpu = gpu();
    let renderer_allocations = fail_at_each_allocation(&gpu, "Renderer::new", || Renderer::new(&gpu, OFFSCREEN_FORMAT, 2));
    // Per frame slot: uniforms and fragment counter, the shadow's uniforms; the shadow map and
    // its static cache.
    assert!(renderer_allocations >= 8, "{renderer_allocations}");
    let mut renderer = Renderer::new(&gpu, OFFSCREEN_FORMAT, 2).unwrap();
    let pack = scene_pack();
    // Vertices, indices, the texture, white, the lightmap array, probes, material constants;
    // and each upload's staging buffer, freed before it returns.
    assert!(fail_at_each_allocation(&gpu, "GpuScene::upload", || GpuScene::upload(&gpu, &pack, renderer.layouts())) >= 7);
    assert!(fail_at_each_allocation(&gpu, "Offscreen::new", || Offscreen::new(&gpu, 32, 24)) >= 2);
    if let Some(dir) = samples() {
        let skinned = cook(&dir, "RiggedSimple");
        let scene = GpuScene::upload(&gpu, &skinned, renderer.layouts()).unwrap();
        let animated = fail_at_each_allocation(&gpu, "AnimatedScene::new", || {
            AnimatedScene::new(&gpu, &skinned, &scene, 2).map(|a| a.expect("RiggedSimple is skinned"))
        });
        // Five inputs and three buffers per slot, for each LOD of the skinned mesh.
        assert!(animated >= 5 + 3 * 2, "{animated}");
        let mut scene = scene;
        scene.destroy(&gpu);
    }

    // A frame whose transient targets cannot be made fails, and the next one renders.
    let mut scene = GpuScene::upload(&gpu, &pack, renderer.layouts()).unwrap();
    let mut target = Offscreen::new(&gpu, 32, 24).unwrap();
    let camera = Camera { position: Vec3::new(0.0, 0.0, 6.0), yaw: 0.0, pitch: 0.0, fov_y: 60f32.to_radians(), near: 0.1 };
    gpu.fail_allocation(1);
    let e = target.render(&gpu, &mut renderer, &scene, &camera, &Lighting::default(), true).map(|_| ()).unwrap_err();
    assert!(format!("{e:#}").contains("injected"), "{e:#}");
    gpu.fail_allocation(0);
    target.render(&gpu, &mut renderer, &scene, &camera, &Lighting::default(), true).unwrap();
    assert!(renderer.visibility.counts.cull.visible == 2, "{:?}", renderer.visibility.counts);
    scene.destroy(&gpu);
    target.destroy(&gpu);
    renderer.destroy(&gpu);
    assert_clean(&gpu);
}
