//! What every GPU test file shares: the validated device, the no-validation-errors check, and the
//! Khronos samples (skipped with a message where ../shared is absent).
//!
//! Each test file compiles this module on its own and uses part of it.
#![allow(dead_code)]

pub mod frames;
pub mod packs;
pub mod scenes;

use engine::gpu::{DevicePreference, Gpu, GpuOptions};
use pack::Pack;
use std::path::{Path, PathBuf};

/// The device tests render on: the validation layer always on; ENGINE_DEVICE can still point
/// them at a real GPU.
pub fn gpu() -> Gpu {
    Gpu::new(&GpuOptions { validation: true, device: DevicePreference::from_env(), surface_extensions: vec![], pipeline_cache: None })
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

/// One dynamic square mesh named `name`, 2 `half` metres on a side, facing +Z (counter-clockwise
/// seen from +Z), placed with its centre at (0, 0, z), in `material`.
pub fn square_pack(name: &str, half: f32, z: f32, material: pack::Material) -> Pack {
    use glam::{Mat4, Vec3};
    use pack::{Mesh, MeshLod, Node, PackBuilder, Submesh, Vertex};
    let mut b = PackBuilder::new("generated", "test");
    let verts: Vec<Vertex> = [(-half, -half), (half, -half), (half, half), (-half, half)]
        .iter()
        .map(|&(x, y)| Vertex { position: [x, y, 0.0], normal: [0.0, 0.0, 1.0], tangent: [1.0, 0.0, 0.0, 1.0], color: [255; 4], ..Default::default() })
        .collect();
    let idx: Vec<u32> = vec![0, 1, 2, 0, 2, 3];
    let (vertices, uv_ranges) = b.push_vertices(&verts);
    let indices = b.push_bytes(&idx.iter().flat_map(|i| i.to_le_bytes()).collect::<Vec<u8>>());
    b.manifest.meshes.push(Mesh {
        name: name.into(),
        lods: vec![MeshLod {
            vertices,
            uv_ranges,
            vertex_count: 4,
            indices,
            index_count: 6,
            index_format: pack::IndexFormat::U32,
            submeshes: vec![Submesh { first_index: 0, index_count: 6, material: 0, lightmap_block: None }],
            error: 0.0,
        }],
        bounds_min: [-half, -half, 0.0],
        bounds_max: [half, half, 0.0],
    });
    b.manifest.materials.push(material);
    b.manifest.nodes.push(Node { name: name.into(), local: Mat4::from_translation(Vec3::new(0.0, 0.0, z)).to_cols_array(), mesh: Some(0), ..Default::default() });
    b.finish()
}

/// A level spawn as the cooker writes it: unrotated, `params` given as JSON text.
pub fn spawn(name: &str, kind: &str, position: [f32; 3], params: &str) -> pack::Spawn {
    pack::Spawn { name: name.into(), kind: kind.into(), position, rotation: [0.0, 0.0, 0.0, 1.0], params: serde_json::from_str(params).unwrap() }
}
