//! Seed inputs for the fuzz targets in `fuzz/` (run by `tools/fuzz_seed.sh`, not by hand).
//!
//! usage: fuzz_seeds PACK_DIR GLTF_DIR SAMPLE.gltf...
//!
//! For each glTF sample (self-contained: buffers and images as data: URIs) this writes the file
//! itself and the same scene as a .glb (buffers moved into the binary chunk) to GLTF_DIR, and the
//! pack it cooks to PACK_DIR when that is small. It also writes one small synthetic pack that uses
//! every optional section of the manifest (textures and mips, lightmap layout and baked pages,
//! probes, lights, spawns, sky, animation), so the pack targets start from all of them.

use cook_core::pack::{self, BufferRange, Pack, PackBuilder, TextureFormat};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// Packs bigger than this are left out: mutations of big texel blobs find little.
const MAX_SEED_PACK: usize = 64 * 1024;

fn main() {
    let args: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    if args.len() < 2 {
        eprintln!("usage: fuzz_seeds PACK_DIR GLTF_DIR SAMPLE.gltf...");
        std::process::exit(2);
    }
    let (pack_dir, gltf_dir) = (&args[0], &args[1]);
    for dir in [pack_dir, gltf_dir] {
        std::fs::create_dir_all(dir).unwrap_or_else(|e| fail(dir, e));
    }
    let mut rich_base = None;
    for sample in &args[2..] {
        let stem = sample.file_stem().unwrap_or_default().to_string_lossy().into_owned();
        let bytes = std::fs::read(sample).unwrap_or_else(|e| fail(sample, e));
        write(&gltf_dir.join(format!("{stem}.gltf")), &bytes);
        match to_glb(&bytes) {
            Ok(glb) => write(&gltf_dir.join(format!("{stem}.glb")), &glb),
            Err(e) => eprintln!("{}: no .glb seed: {e}", sample.display()),
        }
        let pack = match cook_core::cook_gltf(sample, &mut |_, _| {}) {
            Ok(p) => p,
            Err(e) => {
                eprintln!("{e} (no pack seed)");
                continue;
            }
        };
        let encoded = pack.to_bytes().expect("a cooked pack encodes");
        if encoded.len() <= MAX_SEED_PACK {
            write(&pack_dir.join(format!("{stem}.pack")), &encoded);
        }
        if !pack.manifest.animation.clips.is_empty() && pack.manifest.textures.is_empty() && rich_base.is_none() {
            rich_base = Some(pack);
        }
    }
    let rich = rich_pack(rich_base.unwrap_or_else(|| PackBuilder::new("synthetic", "fuzz_seeds").finish()));
    write(&pack_dir.join("synthetic-all-sections.pack"), &rich.to_bytes().expect("the synthetic pack is valid"));
}

fn fail(path: &Path, e: impl std::fmt::Display) -> ! {
    eprintln!("{}: {e}", path.display());
    std::process::exit(1);
}

fn write(path: &Path, bytes: &[u8]) {
    std::fs::write(path, bytes).unwrap_or_else(|e| fail(path, e));
}

/// A .gltf whose buffers are all data: URIs, as a .glb with one binary chunk holding them.
fn to_glb(gltf: &[u8]) -> Result<Vec<u8>, String> {
    let mut j: Value = serde_json::from_slice(gltf).map_err(|e| e.to_string())?;
    let mut bin: Vec<u8> = Vec::new();
    let mut starts = Vec::new();
    for b in j["buffers"].as_array().ok_or("no buffers")? {
        let uri = b["uri"].as_str().ok_or("a buffer without a uri")?;
        let (_, payload) = uri.split_once(";base64,").ok_or("a buffer that is not a base64 data: URI")?;
        let data = base64::decode(payload).map_err(|e| e.to_string())?;
        bin.resize(bin.len().div_ceil(4) * 4, 0);
        starts.push(bin.len());
        bin.extend_from_slice(&data);
    }
    bin.resize(bin.len().div_ceil(4) * 4, 0);
    for v in j["bufferViews"].as_array_mut().ok_or("no buffer views")? {
        let b = v["buffer"].as_u64().ok_or("a buffer view without a buffer")? as usize;
        let start = *starts.get(b).ok_or("a buffer view of a missing buffer")?;
        v["byteOffset"] = json!(v["byteOffset"].as_u64().unwrap_or(0) as usize + start);
        v["buffer"] = json!(0);
    }
    j["buffers"] = json!([{ "byteLength": bin.len() }]);
    let mut text = serde_json::to_vec(&j).map_err(|e| e.to_string())?;
    text.resize(text.len().div_ceil(4) * 4, b' ');
    let mut glb = Vec::new();
    glb.extend_from_slice(b"glTF");
    glb.extend_from_slice(&2u32.to_le_bytes());
    glb.extend_from_slice(&((12 + 8 + text.len() + 8 + bin.len()) as u32).to_le_bytes());
    glb.extend_from_slice(&(text.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"JSON");
    glb.extend_from_slice(&text);
    glb.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"BIN\0");
    glb.extend_from_slice(&bin);
    Ok(glb)
}

/// `base` (a cooked pack, ideally animated) plus one of everything else the manifest can hold.
fn rich_pack(base: Pack) -> Pack {
    let mut b = PackBuilder::new("", "");
    b.manifest = base.manifest;
    // Re-home the base's ranges: push its whole blob first so its offsets stay valid.
    let whole = b.push_bytes(&base.data);
    assert_eq!(whole.offset, 0);
    let mips: Vec<BufferRange> = [4u32, 2, 1].iter().map(|&s| b.push_bytes(&vec![200u8; (s * s * 4) as usize])).collect();
    b.manifest.textures.push(pack::Texture {
        name: "checker".into(),
        width: 4,
        height: 4,
        format: TextureFormat::Rgba8Srgb,
        mips,
        sampler: pack::Sampler { wrap_s: pack::Wrap::Mirror, ..Default::default() },
    });
    let page = b.push_bytes(&[0u8; 2 * 2 * 8]);
    b.manifest.textures.push(pack::Texture {
        name: "lightmap0".into(),
        width: 2,
        height: 2,
        format: TextureFormat::Rgba16Float,
        mips: vec![page],
        sampler: pack::Sampler::default(),
    });
    let mut material = pack::Material {
        name: "textured".into(),
        base_color_texture: Some(0),
        base_color_uv: pack::TextureTransform { tex_coord: 1, offset: [0.25, 0.0], rotation: 0.5, scale: [2.0, 2.0] },
        ..Default::default()
    };
    material.emissive = [0.5, 0.25, 0.0];
    b.manifest.materials.push(material);
    b.manifest.lightmap = Some(pack::LightmapLayout {
        texels_per_metre: 8.0,
        pages: vec![[2, 2]],
        padding: 1,
        textures: vec![1],
        directions: vec![],
        log_average: None,
        samples: None,
    });
    if let Some(sm) = b.manifest.meshes.first_mut().and_then(|m| m.lods[0].submeshes.first_mut()) {
        sm.lightmap_block = Some(0);
        if let Some(node) = b.manifest.nodes.iter_mut().find(|n| n.mesh == Some(0)) {
            node.is_static = true;
            node.lightmap = Some(pack::LightmapRegion { page: 0, scale: [0.5, 0.5], offset: [0.25, 0.25] });
        }
    }
    let counts = [2u32, 1, 1];
    let n = 2usize;
    let sh = b.push_bytes(&vec![0u8; n * 27 * 4]);
    let sun_visibility = b.push_bytes(&1f32.to_le_bytes().repeat(n));
    b.manifest.probes = Some(pack::ProbeGrid {
        origin: [0.0; 3],
        spacing: [1.0; 3],
        counts,
        sh,
        sun_visibility,
    });
    b.manifest.lights.push(pack::Light {
        name: "sun".into(),
        kind: pack::LightKind::Sun,
        color: [1.0, 0.9, 0.8],
        intensity: 100000.0,
        position: [0.0; 3],
        direction: [0.0, -1.0, 0.0],
        range: None,
        inner_cone: 0.0,
        outer_cone: 0.0,
        size: [0.0; 2],
        angular_radius: 0.00465,
    });
    b.manifest.lights.push(pack::Light {
        name: "lamp".into(),
        kind: pack::LightKind::Spot,
        color: [1.0; 3],
        intensity: 800.0,
        position: [0.0, 2.0, 0.0],
        direction: [0.0, -1.0, 0.0],
        range: Some(10.0),
        inner_cone: 0.3,
        outer_cone: 0.6,
        size: [0.0; 2],
        angular_radius: 0.0,
    });
    b.manifest.spawns.push(pack::Spawn {
        name: "player".into(),
        kind: "player".into(),
        position: [0.0, 1.7, 4.0],
        rotation: [0.0, 0.0, 0.0, 1.0],
        params: json!({"speed": 3.0}),
    });
    b.manifest.sky = Some(pack::Sky {
        color: [0.5, 0.7, 1.0],
        intensity: 2000.0,
    });
    b.finish()
}
