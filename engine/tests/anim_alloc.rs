//! Per-frame animation work must not allocate: sampling, cross-fading, global matrices and joint
//! matrices write into buffers made at load. A counting allocator (per thread, so other tests
//! running in parallel do not count) checks it on a cooked sample model.

use engine::anim::{Animator, Rig};
use glam::Mat4;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::PathBuf;

struct Counting;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.with(Cell::get) {
            ALLOCATIONS.with(|a| a.set(a.get() + 1));
        }
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if COUNTING.with(Cell::get) {
            ALLOCATIONS.with(|a| a.set(a.get() + 1));
        }
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

fn allocations_during(f: impl FnOnce()) -> usize {
    ALLOCATIONS.with(|a| a.set(0));
    COUNTING.with(|c| c.set(true));
    f();
    COUNTING.with(|c| c.set(false));
    ALLOCATIONS.with(Cell::get)
}

#[test]
fn the_counter_sees_an_allocation() {
    // Without this the test below could pass with a counter that never counts.
    let n = allocations_during(|| drop(std::hint::black_box(vec![1u8; 64])));
    assert_eq!(n, 1);
}

#[test]
fn sampling_blending_and_joint_matrices_do_not_allocate() {
    let dir = std::env::var_os("GLTF_SAMPLES_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/gltf-samples"));
    let path = dir.join("RiggedSimple/RiggedSimple.gltf");
    if !path.exists() {
        eprintln!("skipped: {} not found (set GLTF_SAMPLES_DIR)", path.display());
        return;
    }
    let pack = cook_core::cook_gltf(&path, &mut |_, _| {}).unwrap();
    let rig = Rig::from_pack(&pack);
    let mut anim = Animator::new(&rig, 0);
    anim.fade = Some((0, 0.3, 0.5)); // the same clip at another phase: exercises the blend path
    anim.speed = 1.5;
    let mut joints = vec![Mat4::IDENTITY; rig.skins[0].joints.len()];
    let n = allocations_during(|| {
        for _ in 0..200 {
            anim.advance(&rig, 1.0 / 60.0);
            rig.joint_matrices(0, &anim.pose, &mut joints);
        }
    });
    assert_eq!(n, 0, "{n} allocations in 200 animation frames");
    assert!(joints.iter().all(|m| m.is_finite()));
}

#[test]
fn the_renderers_per_frame_animation_and_skinning_record_do_not_allocate() {
    use engine::anim::animated::AnimatedScene;
    use engine::gpu::{DevicePreference, Gpu, GpuOptions};
    use engine::render::renderer::Renderer;
    use engine::scene::GpuScene;
    use engine::render::visibility::Draw;
    let dir = std::env::var_os("GLTF_SAMPLES_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/gltf-samples"));
    let path = dir.join("RiggedSimple/RiggedSimple.gltf");
    if !path.exists() {
        eprintln!("skipped: {} not found (set GLTF_SAMPLES_DIR)", path.display());
        return;
    }
    let pack = cook_core::cook_gltf(&path, &mut |_, _| {}).unwrap();
    let gpu = Gpu::new(&GpuOptions { validation: true, device: DevicePreference::from_env(), surface_extensions: vec![], pipeline_cache: None }).expect("a Vulkan 1.3 device");
    let mut renderer = Renderer::new(&gpu, engine::app::headless::OFFSCREEN_FORMAT, 2).unwrap();
    let mut scene = GpuScene::upload(&gpu, &pack, renderer.layouts()).unwrap();
    let mut anim = AnimatedScene::new(&gpu, &pack, &scene, 2).unwrap().expect("RiggedSimple is skinned");
    let draws: Vec<Draw> = (0..scene.instances.len() as u32).map(|instance| Draw { instance, lod: 0 }).collect();
    let n = allocations_during(|| {
        for _ in 0..200 {
            anim.advance(&mut scene, 1.0 / 60.0);
        }
    });
    assert_eq!(n, 0, "{n} allocations in 200 frames of AnimatedScene::advance");
    let recorded = gpu
        .one_shot(|cb| {
            allocations_during(|| {
                for slot in [0, 1] {
                    anim.record(&gpu, cb, slot, &draws, &draws);
                }
            })
        })
        .unwrap();
    assert_eq!(recorded, 0, "{recorded} allocations recording the skinning pass");
    assert!(anim.dispatches > 0);
    anim.destroy(&gpu);
    scene.destroy(&gpu);
    renderer.destroy(&gpu);
    assert_eq!(gpu.validation().error_count(), 0, "validation errors: {:#?}", gpu.validation().errors());
}
