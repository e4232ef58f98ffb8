//! What every GPU test file shares: the validated device, the no-validation-errors check, and the
//! Khronos samples (skipped with a message where ../shared is absent).
//!
//! Each test file compiles this module on its own and uses part of it.
#![allow(dead_code)]

use engine::gpu::{DevicePreference, Gpu, GpuOptions};
use pack::Pack;
use std::path::{Path, PathBuf};

/// The device tests render on: the validation layer always on; ENGINE_DEVICE can still point
/// them at a real GPU.
pub fn gpu() -> Gpu {
    Gpu::new(&GpuOptions { validation: true, device: DevicePreference::from_env(), surface_extensions: vec![] })
        .expect("a Vulkan 1.3 device with the validation layer (run `make setup`)")
}

/// Any validation error fails the test that caused it.
pub fn assert_clean(gpu: &Gpu) {
    assert_eq!(gpu.validation().error_count(), 0, "validation errors: {:#?}", gpu.validation().errors());
}

/// The Khronos sample models (GLTF_SAMPLES_DIR, default ../shared/gltf-samples), or None with
/// a message saying the test is skipped.
pub fn samples() -> Option<PathBuf> {
    let dir = std::env::var_os("GLTF_SAMPLES_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/gltf-samples"));
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!("skipped: glTF samples not found at {} (set GLTF_SAMPLES_DIR)", dir.display());
        None
    }
}

/// Sample `name` (`dir/name/name.gltf`) cooked by the real cooker.
pub fn cook(dir: &Path, name: &str) -> Pack {
    let path = dir.join(name).join(format!("{name}.gltf"));
    cook_core::cook_gltf(&path, &mut |_, _| {}).unwrap_or_else(|e| panic!("cooking {name}: {e}"))
}
