//! Tests on glTF files written by the tests themselves: a textured quad, then broken variants.

use super::*;
use serde_json::{json, Value};
use std::path::PathBuf;

/// A fresh directory per use (tests run in parallel), removed when dropped.
struct TempDir(PathBuf);
impl TempDir {
    fn new(name: &str) -> TempDir {
        static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let d = std::env::temp_dir().join(format!("cook-core-{}-{name}-{n}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        TempDir(d)
    }
    fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
    fn files(&self) -> Vec<String> {
        let mut v: Vec<String> =
            std::fs::read_dir(&self.0).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into()).collect();
        v.sort();
        v
    }
}
impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn f32s(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn png(w: u32, h: u32) -> Vec<u8> {
    let img = image::RgbaImage::from_fn(w, h, |x, y| image::Rgba([x as u8 * 100, y as u8 * 100, 7, 255]));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

/// A unit quad in z=0: u16 indices (view 0), positions (1), normals (2), uvs (3); a 2x2 PNG base
/// colour; node "root" with child "child" holding the mesh.
fn quad() -> (Value, Vec<u8>) {
    let mut bin: Vec<u8> = [0u16, 1, 2, 2, 1, 3].iter().flat_map(|i| i.to_le_bytes()).collect();
    bin.extend(f32s(&[0., 0., 0., 1., 0., 0., 0., 1., 0., 1., 1., 0.]));
    bin.extend(f32s(&[0., 0., 1., 0., 0., 1., 0., 0., 1., 0., 0., 1.]));
    bin.extend(f32s(&[0., 0., 1., 0., 0., 1., 1., 1.]));
    let j = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [
            {"name": "root", "children": [1], "translation": [1.0, 2.0, 3.0]},
            {"name": "child", "mesh": 0}
        ],
        "meshes": [{"name": "Quad", "primitives": [{
            "attributes": {"POSITION": 1, "NORMAL": 2, "TEXCOORD_0": 3},
            "indices": 0, "material": 0
        }]}],
        "materials": [{
            "name": "mat",
            "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0.25, "roughnessFactor": 0.75},
            "emissiveFactor": [1.0, 0.5, 0.0],
            "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}},
            "alphaMode": "MASK", "alphaCutoff": 0.3, "doubleSided": true
        }],
        "textures": [{"source": 0}],
        "images": [{"uri": format!("data:image/png;base64,{}", base64::encode(png(2, 2)))}],
        "accessors": [
            {"bufferView": 0, "componentType": 5123, "count": 6, "type": "SCALAR"},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC3"},
            {"bufferView": 3, "componentType": 5126, "count": 4, "type": "VEC2"}
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 12},
            {"buffer": 0, "byteOffset": 12, "byteLength": 48},
            {"buffer": 0, "byteOffset": 60, "byteLength": 48},
            {"buffer": 0, "byteOffset": 108, "byteLength": 32}
        ],
        "buffers": [{"byteLength": 140}]
    });
    (j, bin)
}

/// Write `j` with `bin` embedded as a data: URI.
fn write_gltf(dir: &TempDir, name: &str, mut j: Value, bin: &[u8]) -> PathBuf {
    j["buffers"][0]["uri"] = json!(format!("data:application/octet-stream;base64,{}", base64::encode(bin)));
    let p = dir.path(name);
    std::fs::write(&p, serde_json::to_vec(&j).unwrap()).unwrap();
    p
}

fn cook(p: &Path) -> Result<Pack, CookError> {
    cook_gltf(p, &mut |_, _| {})
}

fn cook_err(j: Value, bin: &[u8]) -> String {
    let dir = TempDir::new("err");
    let p = write_gltf(&dir, "broken.gltf", j, bin);
    let e = cook(&p).expect_err("cook should fail").to_string();
    let prefix = format!("{}: ", p.display());
    assert!(e.starts_with(&prefix), "{e}");
    assert!(!e.contains('\n'), "{e}");
    e[prefix.len()..].to_string()
}

fn vertices(p: &Pack, mesh: usize) -> Vec<pack::Vertex> {
    let lod = &p.manifest.meshes[mesh].lods[0];
    pack::decode_vertices(p.bytes(lod.vertices), &lod.uv_ranges)
}

fn indices(p: &Pack, mesh: usize) -> Vec<u32> {
    p.indices(&p.manifest.meshes[mesh].lods[0])
}

#[test]
fn textured_quad_cooks_completely() {
    let dir = TempDir::new("quad");
    let (j, bin) = quad();
    let path = write_gltf(&dir, "quad.gltf", j, &bin);
    let mut calls = Vec::new();
    let p = cook_gltf(&path, &mut |what, f| calls.push((what.to_string(), f))).unwrap();
    let m = &p.manifest;

    assert_eq!(m.meshes.len(), 1);
    let mesh = &m.meshes[0];
    assert_eq!((mesh.name.as_str(), mesh.lods[0].vertex_count, mesh.lods[0].index_count), ("Quad", 4, 6));
    assert_eq!(indices(&p, 0), [0, 1, 2, 2, 1, 3], "u16 indices widened to u32");
    assert_eq!(mesh.lods[0].submeshes, [pack::Submesh { first_index: 0, index_count: 6, material: 0, lightmap_block: None }]);
    assert_eq!((mesh.bounds_min, mesh.bounds_max), ([0.0; 3], [1.0, 1.0, 0.0]));
    let v = vertices(&p, 0);
    assert_eq!(v[3].position, [1.0, 1.0, 0.0]);
    assert_eq!(v[3].normal, [0.0, 0.0, 1.0]);
    assert_eq!(v[3].uv0, [1.0, 1.0]);
    assert_eq!(v[3].uv1, [0.0, 0.0]);
    assert_eq!(v[3].color, [255; 4], "no COLOR_0: white");
    assert_eq!(v[3].tangent, [1.0, 0.0, 0.0, 1.0], "default tangent is perpendicular to the normal");

    assert_eq!(m.materials.len(), 1, "no default material when every primitive has one");
    let mat = &m.materials[0];
    assert_eq!((mat.base_color_texture, mat.metallic, mat.roughness), (Some(0), 0.25, 0.75));
    assert_eq!(mat.emissive, [4.0, 2.0, 0.0], "emissive times KHR_materials_emissive_strength");
    assert_eq!((mat.alpha_mode, mat.alpha_cutoff, mat.double_sided), (pack::AlphaMode::Mask, 0.3, true));

    assert_eq!(m.textures.len(), 1);
    let t = &m.textures[0];
    assert_eq!((t.width, t.height, t.format, t.mips.len()), (2, 2, pack::TextureFormat::Rgba8Srgb, 1));
    assert_eq!(&p.bytes(t.mips[0])[4..8], &[100, 0, 7, 255], "texel (1, 0)");

    let names: Vec<_> = m.nodes.iter().map(|n| (n.name.as_str(), n.parent, n.mesh)).collect();
    assert_eq!(names, [("root", None, None), ("child", Some(0), Some(0))]);
    assert_eq!(&m.nodes[0].local[12..15], &[1.0, 2.0, 3.0], "translation in the last column");

    assert_eq!(calls.first().map(|c| c.1), Some(0.0));
    assert_eq!(calls.last().map(|c| c.1), Some(1.0));
    assert!(calls.windows(2).all(|w| w[0].1 <= w[1].1), "progress only grows: {calls:?}");

    // It writes, reads back identically, and leaves nothing else behind.
    let out = dir.path("quad.pack");
    check_output(&out, &path).unwrap();
    let bytes = write_pack(&p, &out).unwrap();
    let back = read_pack(&out).unwrap();
    assert_eq!(back, p);
    let s = Summary::of(&back, bytes);
    assert_eq!((s.meshes, s.vertices, s.indices, s.triangles, s.textures, s.nodes), (1, 4, 6, 2, 1, 2));
    assert_eq!(dir.files(), ["quad.gltf", "quad.pack"]);
}

/// `j` and `bin` as a GLB file's bytes (JSON chunk, then the buffer as the BIN chunk).
fn glb(j: &Value, bin: &[u8]) -> Vec<u8> {
    let mut bin = bin.to_vec();
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let mut j = j.clone();
    j["buffers"] = json!([{"byteLength": bin.len()}]);
    let mut text = serde_json::to_vec(&j).unwrap();
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    let mut glb = Vec::new();
    glb.extend(b"glTF");
    glb.extend(2u32.to_le_bytes());
    glb.extend(((12 + 8 + text.len() + 8 + bin.len()) as u32).to_le_bytes());
    glb.extend((text.len() as u32).to_le_bytes());
    glb.extend(b"JSON");
    glb.extend(&text);
    glb.extend((bin.len() as u32).to_le_bytes());
    glb.extend(b"BIN\0");
    glb.extend(&bin);
    glb
}

#[test]
fn glb_with_image_in_a_buffer_view_cooks() {
    let (mut j, mut bin) = quad();
    let image = png(3, 1);
    j["bufferViews"].as_array_mut().unwrap().push(json!({"buffer": 0, "byteOffset": 140, "byteLength": image.len()}));
    j["images"] = json!([{"bufferView": 4, "mimeType": "image/png"}]);
    bin.extend(&image);
    let mut glb = glb(&j, &bin);
    let dir = TempDir::new("glb");
    let p = dir.path("quad.glb");
    std::fs::write(&p, &glb).unwrap();
    let pack = cook(&p).unwrap();
    assert_eq!(pack.manifest.meshes[0].lods[0].index_count, 6);
    assert_eq!((pack.manifest.textures[0].width, pack.manifest.textures[0].height), (3, 1));

    // A GLB whose header length would underflow is refused, not parsed.
    glb[8..12].copy_from_slice(&4u32.to_le_bytes());
    std::fs::write(&p, &glb).unwrap();
    let e = cook(&p).unwrap_err().to_string();
    assert!(e.contains("not a glTF 2.0 file: GLB header declares a length of 4 bytes"), "{e}");
}

#[test]
fn missing_and_foreign_files_say_so() {
    let dir = TempDir::new("foreign");
    let missing = dir.path("x.gltf");
    assert_eq!(cook(&missing).unwrap_err().to_string(), format!("{}: no such file", missing.display()));
    for (name, bytes) in [("text.gltf", &b"hello, world\n"[..]), ("png.glb", &png(1, 1)[..]), ("empty.gltf", b"")] {
        let p = dir.path(name);
        std::fs::write(&p, bytes).unwrap();
        let e = cook(&p).unwrap_err();
        assert!(matches!(e, CookError::NotGltf { .. }), "{name}: {e}");
        assert!(e.to_string().starts_with(&format!("{}: not a glTF 2.0 file: ", p.display())), "{e}");
    }
}

#[test]
fn accessor_past_its_buffer_view_is_named() {
    let (mut j, bin) = quad();
    j["bufferViews"][2]["byteLength"] = json!(24);
    j["bufferViews"][3]["byteOffset"] = json!(84);
    assert_eq!(cook_err(j, &bin), "mesh 0 'Quad' primitive 0: accessor 2 (NORMAL) needs 48 bytes but buffer view 2 holds 24");

    let (mut j, bin) = quad();
    j["accessors"][3]["count"] = json!(5);
    j["accessors"][1]["count"] = json!(5);
    assert_eq!(cook_err(j, &bin), "mesh 0 'Quad' primitive 0: accessor 1 (POSITION) needs 60 bytes but buffer view 1 holds 48");

    let (mut j, bin) = quad();
    j["accessors"][2]["byteOffset"] = json!(8);
    assert_eq!(cook_err(j, &bin), "mesh 0 'Quad' primitive 0: accessor 2 (NORMAL) needs 56 bytes but buffer view 2 holds 48");
}

#[test]
fn buffer_view_past_its_buffer_is_named() {
    let (mut j, bin) = quad();
    j["bufferViews"][3]["byteLength"] = json!(64);
    assert_eq!(
        cook_err(j, &bin),
        "mesh 0 'Quad' primitive 0: buffer view 3 (bytes 108..172) does not fit in buffer 0 (140 bytes)"
    );
    let (mut j, bin) = quad();
    j["buffers"][0]["byteLength"] = json!(400);
    assert_eq!(cook_err(j, &bin), "buffer 0 holds 140 bytes but declares byteLength 400");
}

#[test]
fn index_out_of_range_is_named() {
    let (j, mut bin) = quad();
    bin[10..12].copy_from_slice(&4u16.to_le_bytes());
    assert_eq!(
        cook_err(j, &bin),
        "mesh 0 'Quad' primitive 0: accessor 0 (indices) element 5 is 4, but there are only 4 vertices"
    );
}

#[test]
fn inconsistent_or_mistyped_attributes_are_refused() {
    let (mut j, bin) = quad();
    j["accessors"][3]["count"] = json!(3);
    assert_eq!(cook_err(j, &bin), "mesh 0 'Quad' primitive 0: accessor 3 (TEXCOORD_0) has 3 elements but POSITION has 4");

    let (mut j, bin) = quad();
    j["accessors"][2]["type"] = json!("VEC2");
    assert_eq!(cook_err(j, &bin), "mesh 0 'Quad' primitive 0: accessor 2 (NORMAL) is VEC2 of F32, expected VEC3 of [F32]");

    let (mut j, bin) = quad();
    j["accessors"][0]["count"] = json!(5);
    assert_eq!(cook_err(j, &bin), "mesh 0 'Quad' primitive 0: 5 indices do not make whole triangles");

    let (mut j, bin) = quad();
    j["meshes"][0]["primitives"][0]["mode"] = json!(1);
    assert_eq!(cook_err(j, &bin), "mesh 0 'Quad' primitive 0: mode Lines is not supported (only triangles, triangle strips and fans)");

    let (mut j, bin) = quad();
    j["accessors"][2].as_object_mut().unwrap().remove("bufferView");
    // The gltf crate's own validation catches this one, naming the JSON path.
    assert_eq!(cook_err(j, &bin), "invalid glTF: accessors[2].bufferView: Missing data");

    let (mut j, bin) = quad();
    j["accessors"][1]["bufferView"] = json!(9);
    assert!(cook_err(j, &bin).starts_with("invalid glTF: "));
}

#[test]
fn bad_image_is_named() {
    let (mut j, bin) = quad();
    j["images"][0]["uri"] = json!(format!("data:image/png;base64,{}", base64::encode(b"not a png at all")));
    let e = cook_err(j, &bin);
    assert!(e.starts_with("image 0 (base colour of material 0 'mat'): cannot decode: "), "{e}");

    let (mut j, bin) = quad();
    j["images"][0]["uri"] = json!("missing%20file.png");
    let e = cook_err(j, &bin);
    assert!(e.contains("cannot read '") && e.contains("missing file.png"), "{e}");
}

#[test]
fn unindexed_primitive_without_normals_gets_indices_and_flat_normals() {
    let (mut j, bin) = quad();
    let prim = &mut j["meshes"][0]["primitives"][0];
    prim.as_object_mut().unwrap().remove("indices");
    prim.as_object_mut().unwrap().remove("material");
    prim["attributes"] = json!({"POSITION": 1});
    j["accessors"][1]["count"] = json!(3);
    let dir = TempDir::new("flat");
    let p = cook(&write_gltf(&dir, "t.gltf", j, &bin)).unwrap();
    assert_eq!(indices(&p, 0), [0, 1, 2]);
    let v = vertices(&p, 0);
    assert!(v.iter().all(|v| v.normal == [0.0, 0.0, 1.0] && v.uv0 == [0.0, 0.0]));
    assert_eq!(p.manifest.materials.len(), 2, "a default material is appended");
    assert_eq!(p.manifest.meshes[0].lods[0].submeshes[0].material, 1);
    assert_eq!(p.manifest.materials[1], pack::Material::default());
}

#[test]
fn triangle_strip_becomes_a_list_with_alternating_winding() {
    let (mut j, bin) = quad();
    j["meshes"][0]["primitives"][0]["mode"] = json!(5);
    j["accessors"][0]["count"] = json!(4); // strip 0 1 2 2 -> (0 1 2) (2 1 2)
    let dir = TempDir::new("strip");
    let p = cook(&write_gltf(&dir, "t.gltf", j, &bin)).unwrap();
    assert_eq!(indices(&p, 0), [0, 1, 2, 2, 1, 2]);
}

#[test]
fn sparse_accessor_overrides_base_values() {
    let (mut j, mut bin) = quad();
    bin.extend(3u16.to_le_bytes());
    bin.extend([0, 0]);
    bin.extend(f32s(&[5.0, 6.0, 7.0]));
    j["bufferViews"].as_array_mut().unwrap().extend([
        json!({"buffer": 0, "byteOffset": 140, "byteLength": 2}),
        json!({"buffer": 0, "byteOffset": 144, "byteLength": 12}),
    ]);
    j["buffers"][0]["byteLength"] = json!(bin.len());
    j["accessors"][1]["sparse"] = json!({"count": 1, "indices": {"bufferView": 4, "componentType": 5123}, "values": {"bufferView": 5}});
    let dir = TempDir::new("sparse");
    let p = cook(&write_gltf(&dir, "t.gltf", j.clone(), &bin)).unwrap();
    let v = vertices(&p, 0);
    assert_eq!((v[2].position, v[3].position), ([0.0, 1.0, 0.0], [5.0, 6.0, 7.0]));
    assert_eq!(p.manifest.meshes[0].bounds_max, [5.0, 6.0, 7.0]);

    bin[140..142].copy_from_slice(&9u16.to_le_bytes());
    assert_eq!(
        cook_err(j, &bin),
        "mesh 0 'Quad' primitive 0: accessor 1 (POSITION): sparse index 0 is 9, past the accessor's 4 elements"
    );
}

#[test]
fn node_cycles_are_refused() {
    let (mut j, bin) = quad();
    j["nodes"][1]["children"] = json!([0]);
    assert_eq!(cook_err(j, &bin), "node 0 'root' is reached twice in the scene (a cycle, or a node with two parents)");
}

#[test]
fn output_checks_name_the_path_and_leave_nothing() {
    let dir = TempDir::new("out");
    let (j, bin) = quad();
    let src = write_gltf(&dir, "quad.gltf", j, &bin);
    let out = dir.path("missing/quad.pack");
    let e = check_output(&out, &src).unwrap_err().to_string();
    assert_eq!(e, format!("{}: output directory '{}' does not exist", out.display(), dir.path("missing").display()));
    let e = write_pack(&cook(&src).unwrap(), &out).unwrap_err().to_string();
    assert!(e.starts_with(&format!("{}: cannot write: ", out.display())), "{e}");
    assert!(check_output(&src, &src).is_err(), "refuses to overwrite the source");
    assert_eq!(dir.files(), ["quad.gltf"]);
    let e = read_pack(&src).unwrap_err().to_string();
    assert!(e.contains("not a pack file"), "{e}");
}

#[test]
fn position_index_out_of_range_is_refused_not_a_panic() {
    // gltf-json's own validation would index out of bounds here (see load::check_position_indices).
    let (mut j, bin) = quad();
    j["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(17);
    assert_eq!(cook_err(j, &bin), "invalid glTF: meshes[0].primitives[0].attributes.POSITION: Index out of bounds");
}

#[test]
fn hostile_numbers_anywhere_give_errors_not_panics() {
    let fields: &[(&str, usize, &str)] = &[
        ("accessors", 0, "count"),
        ("accessors", 0, "byteOffset"),
        ("accessors", 0, "componentType"),
        ("accessors", 1, "count"),
        ("accessors", 1, "byteOffset"),
        ("accessors", 1, "componentType"),
        ("accessors", 3, "componentType"),
        ("accessors", 2, "bufferView"),
        ("bufferViews", 1, "byteOffset"),
        ("bufferViews", 1, "byteLength"),
        ("bufferViews", 1, "byteStride"),
        ("bufferViews", 0, "buffer"),
        ("buffers", 0, "byteLength"),
        ("meshes", 0, "primitives"),
        ("nodes", 0, "children"),
        ("nodes", 1, "mesh"),
        ("textures", 0, "source"),
        ("materials", 0, "alphaCutoff"),
    ];
    let values = [json!(0), json!(1), json!(3), json!(5121), json!(5125), json!(1u64 << 31), json!(u32::MAX as u64 + 1), json!(u64::MAX), json!(-1), json!([]), json!(null)];
    let dir = TempDir::new("hostile");
    for (array, i, key) in fields {
        for v in &values {
            let (mut j, bin) = quad();
            j[*array][*i][*key] = v.clone();
            let p = write_gltf(&dir, "h.gltf", j, &bin);
            if let Err(e) = cook(&p) {
                assert!(!e.to_string().contains('\n'), "{e}");
            }
        }
    }
}

#[test]
fn image_without_a_source_is_refused_not_a_panic() {
    let (mut j, bin) = quad();
    j["images"] = json!([{"name": "nothing"}]);
    assert_eq!(cook_err(j, &bin), "image 0 'nothing' (base colour of material 0 'mat'): has neither a uri nor a bufferView");
    let (mut j, bin) = quad();
    j["images"] = json!([{"bufferView": 0}]); // no mimeType: the gltf crate would unwrap
    assert!(cook_err(j, &bin).contains("cannot decode"));
}

#[test]
fn scene_ir_survives_the_wire_both_ways() {
    let dir = TempDir::new("wire");
    let (j, bin) = quad();
    let path = write_gltf(&dir, "quad.gltf", j, &bin);
    let mut scene = crate::import_gltf(&path, &ImportOptions::default(), &mut |_, _| {}).unwrap().scene;
    // Exercise the optional parts too: a second LOD, lightmap blocks and a static instance's
    // region, TEXCOORD_1, a sampler, skin attributes, lights.
    let mut lod1 = scene.meshes[0].lods[0].clone();
    lod1.triangles.truncate(1);
    lod1.materials.truncate(1);
    lod1.error = 0.25;
    lod1.joints = Some(vec![[0, 1, 0, 0]; lod1.positions.len()]);
    lod1.weights = Some(vec![[0.5, 0.5, 0.0, 0.0]; lod1.positions.len()]);
    lod1.lightmap_blocks = Some(vec![0]);
    lod1.texcoord1 = Some(vec![[0.5, 0.25]; lod1.positions.len()]);
    scene.meshes[0].lods.push(lod1);
    scene.nodes[1].is_static = true;
    scene.nodes[1].lightmap = Some(pack::LightmapRegion { page: 0, scale: [0.5, 0.5], offset: [0.25, 0.0] });
    scene.textures.push(crate::ir::TextureIr {
        name: "clamped".into(),
        width: 1,
        height: 1,
        format: pack::TextureFormat::Rgba8Unorm,
        usage: crate::mips::Usage::Data,
        mips: vec![vec![1, 2, 3, 4]],
        sampler: pack::Sampler { wrap_s: pack::Wrap::Clamp, min_filter: pack::Filter::Nearest, mipmap_filter: None, ..Default::default() },
    });
    scene.lightmap = Some(pack::LightmapLayout { texels_per_metre: 8.0, pages: vec![[64, 32]], padding: 2, textures: vec![], directions: vec![], log_average: None, samples: None });
    scene.probes = Some(crate::ir::ProbesIr { origin: [1.0, 2.0, 3.0], spacing: [2.0; 3], counts: [2, 1, 1], sh: vec![[0.5; 27], [0.25; 27]], sun_visibility: vec![1.0, 0.0] });
    scene.sky = Some(pack::Sky { color: [0.1, 0.2, 0.3], intensity: 2.0 });
    let (json, arrays) = crate::wire::to_wire(&scene);
    let back = crate::wire::from_wire(&json, &arrays).unwrap();
    assert_eq!(back, scene);
    let pack = crate::build_pack(&back).unwrap();
    assert_eq!(pack.manifest.meshes[0].lods.len(), 2);
    assert_eq!(pack.manifest.meshes[0].lods[1].submeshes[0].lightmap_block, Some(0));
    assert_eq!(pack.manifest.nodes[1].lightmap, scene.nodes[1].lightmap);
    assert_eq!(pack.manifest.textures.last().unwrap().sampler, scene.textures.last().unwrap().sampler);
    assert_eq!(pack.manifest.meshes[0].lods[1].error, 0.25);
    let g = pack.manifest.probes.as_ref().unwrap();
    assert_eq!((g.counts, g.sh.len, g.sun_visibility.len), ([2, 1, 1], 2 * 27 * 4, 8));
    assert_eq!(&pack.bytes(g.sun_visibility)[4..], &0.0f32.to_le_bytes());
}

#[test]
fn wire_arrays_of_the_wrong_type_or_shape_are_named() {
    let dir = TempDir::new("wire");
    let (j, bin) = quad();
    let scene = crate::import_gltf(&write_gltf(&dir, "quad.gltf", j, &bin), &ImportOptions::default(), &mut |_, _| {}).unwrap().scene;
    let (json, arrays) = crate::wire::to_wire(&scene);
    let position = arrays.iter().position(|a| a.shape == vec![4, 3] && a.dtype == "<f4").unwrap();
    let mut bad = arrays.clone();
    bad[position].dtype = "<f8".into();
    let e = crate::wire::from_wire(&json, &bad).unwrap_err();
    assert!(e.contains("LOD 0 position") && e.contains("<f8"), "{e}");
    let mut bad = arrays.clone();
    let tri = bad.iter().position(|a| a.dtype == "<u4" && a.shape.len() == 2).unwrap();
    bad[tri].bytes[0] = 200; // index 200 in a 4-vertex mesh
    let e = crate::wire::from_wire(&json, &bad).unwrap_err();
    assert!(e.contains("out of range"), "{e}");
}

#[test]
fn a_texture_larger_than_the_image_crates_default_memory_limit_decodes() {
    // 16384 x 8448 RGBA8 is 553 MB decoded: over the image crate's default 512 MiB allocation
    // limit, which refused it with "limits exceeded", and within the cooker's 16384 per side.
    let (w, h) = (crate::MAX_TEXTURE_SIZE, 8448);
    let mut png = Vec::new();
    let encoder = image::codecs::png::PngEncoder::new_with_quality(&mut png, image::codecs::png::CompressionType::Fast, image::codecs::png::FilterType::NoFilter);
    image::ImageEncoder::write_image(encoder, &vec![0u8; (w * h * 4) as usize], w, h, image::ExtendedColorType::Rgba8).unwrap();
    let decoded = crate::decode_texture(&png).unwrap();
    assert_eq!((decoded.width(), decoded.height()), (w, h));
    // One more row than a texture may have is refused from the header, before decoding.
    let err = crate::decode_texture(&self::png(1, crate::MAX_TEXTURE_SIZE + 1)).unwrap_err();
    assert!(err.contains("1 x 16385 texels, larger than the 16384"), "{err}");
}

/// Import `p` with `options`; panics on failure.
fn import_with(p: &Path, options: &ImportOptions) -> Imported {
    import_gltf(p, options, &mut |_, _| {}).unwrap_or_else(|e| panic!("{e}"))
}

fn import_err_with(p: &Path, options: &ImportOptions) -> String {
    let e = import_gltf(p, options, &mut |_, _| {}).expect_err("import should fail").to_string();
    assert!(!e.contains('\n'), "{e}");
    e
}

#[test]
fn required_extensions_the_cooker_does_not_implement_are_refused_by_name() {
    let (mut j, bin) = quad();
    j["extensionsRequired"] = json!(["KHR_texture_transform", "KHR_draco_mesh_compression"]);
    j["extensionsUsed"] = json!(["KHR_texture_transform", "KHR_draco_mesh_compression"]);
    assert_eq!(
        cook_err(j, &bin),
        "requires extension 'KHR_draco_mesh_compression', which the cooker does not support \
         (supported: KHR_lights_punctual, KHR_materials_emissive_strength, KHR_texture_transform)"
    );
    // Every one we implement may be required; one that is only used is ignored.
    let (mut j, bin) = quad();
    j["extensionsRequired"] = json!(["KHR_lights_punctual", "KHR_materials_emissive_strength", "KHR_texture_transform"]);
    j["extensionsUsed"] = json!(["KHR_lights_punctual", "KHR_materials_emissive_strength", "KHR_texture_transform", "EXT_meshopt_compression"]);
    let dir = TempDir::new("required");
    cook(&write_gltf(&dir, "q.gltf", j, &bin)).unwrap();
}

#[test]
fn texture_slots_carry_their_uv_set_and_khr_texture_transform() {
    let (mut j, bin) = quad();
    let transform = |t: Value| json!({"KHR_texture_transform": t});
    j["extensionsUsed"] = json!(["KHR_texture_transform"]);
    let m = &mut j["materials"][0];
    m["pbrMetallicRoughness"]["baseColorTexture"] =
        json!({"index": 0, "texCoord": 1, "extensions": transform(json!({"offset": [0.5, 0.25], "rotation": 0.3, "scale": [2.0, 3.0]}))});
    m["pbrMetallicRoughness"]["metallicRoughnessTexture"] = json!({"index": 0, "texCoord": 1});
    m["normalTexture"] = json!({"index": 0, "scale": 0.5, "extensions": transform(json!({"texCoord": 1, "scale": [4.0, 4.0]}))});
    // The transform's texCoord overrides the slot's.
    m["occlusionTexture"] = json!({"index": 0, "texCoord": 1, "extensions": transform(json!({"offset": [1.0, 0.0], "texCoord": 0}))});
    m["emissiveTexture"] = json!({"index": 0});
    let check = |p: &Pack| {
        let mat = &p.manifest.materials[0];
        let t = |tex_coord, offset, rotation, scale| pack::TextureTransform { tex_coord, offset, rotation, scale };
        assert_eq!(mat.base_color_uv, t(1, [0.5, 0.25], 0.3, [2.0, 3.0]));
        assert_eq!(mat.metallic_roughness_uv, t(1, [0.0; 2], 0.0, [1.0; 2]));
        assert_eq!(mat.normal_uv, t(1, [0.0; 2], 0.0, [4.0, 4.0]));
        assert_eq!(mat.occlusion_uv, t(0, [1.0, 0.0], 0.0, [1.0; 2]));
        assert_eq!(mat.emissive_uv, pack::TextureTransform::default());
        assert_eq!(mat.normal_scale, 0.5);
    };
    let dir = TempDir::new("uv");
    check(&cook(&write_gltf(&dir, "t.gltf", j.clone(), &bin)).unwrap());
    // The same from a GLB, whose normal and occlusion transforms come from its JSON chunk.
    let p = dir.path("t.glb");
    std::fs::write(&p, glb(&j, &bin)).unwrap();
    check(&cook(&p).unwrap());

    let mut bad = j.clone();
    bad["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["texCoord"] = json!(2);
    bad["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"] = json!({});
    assert_eq!(cook_err(bad, &bin), "material 0 'mat' base colour: texCoord 2 is not supported (vertices carry TEXCOORD_0 and TEXCOORD_1)");
    let mut bad = j.clone();
    bad["materials"][0]["normalTexture"]["extensions"]["KHR_texture_transform"]["texCoord"] = json!(3);
    assert_eq!(cook_err(bad, &bin), "material 0 'mat' normal map: texCoord 3 is not supported (vertices carry TEXCOORD_0 and TEXCOORD_1)");
    let mut bad = j.clone();
    bad["materials"][0]["occlusionTexture"]["extensions"]["KHR_texture_transform"]["offset"] = json!("up");
    let e = cook_err(bad, &bin);
    assert!(e.starts_with("material 0 'mat' occlusion: KHR_texture_transform: invalid type"), "{e}");
    let mut bad = j;
    bad["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"]["KHR_texture_transform"]["rotation"] = json!(1e39);
    let e = cook_err(bad, &bin);
    assert!(e.starts_with("material 0 'mat' base colour: KHR_texture_transform has a number that is not finite"), "{e}");
}

#[test]
fn samplers_come_through_and_one_image_under_two_samplers_is_two_textures() {
    let (mut j, bin) = quad();
    j["samplers"] = json!([{"wrapS": 33071, "wrapT": 33648, "magFilter": 9728, "minFilter": 9984}, {}]);
    j["textures"] = json!([{"source": 0, "sampler": 0}, {"source": 0, "sampler": 1}, {"source": 0}]);
    j["materials"][0]["emissiveTexture"] = json!({"index": 1});
    j["materials"].as_array_mut().unwrap().push(json!({"name": "plain", "pbrMetallicRoughness": {"baseColorTexture": {"index": 2}}}));
    let dir = TempDir::new("sampler");
    let p = cook(&write_gltf(&dir, "t.gltf", j.clone(), &bin)).unwrap();
    let m = &p.manifest;
    assert_eq!(m.textures.len(), 2, "sampler 1 (all defaults) and no sampler sample alike: one texture");
    use pack::{Filter, Sampler, Wrap};
    let clamped = Sampler { wrap_s: Wrap::Clamp, wrap_t: Wrap::Mirror, mag_filter: Filter::Nearest, min_filter: Filter::Nearest, mipmap_filter: Some(Filter::Nearest) };
    assert_eq!((m.textures[0].sampler, m.textures[1].sampler), (clamped, Sampler::default()));
    assert_eq!((m.materials[0].base_color_texture, m.materials[0].emissive_texture, m.materials[1].base_color_texture), (Some(0), Some(1), Some(1)));

    // Every minification filter, and the other wrap and magnification values.
    for (min, filter, mips) in [
        (9728, Filter::Nearest, None),
        (9729, Filter::Linear, None),
        (9984, Filter::Nearest, Some(Filter::Nearest)),
        (9985, Filter::Linear, Some(Filter::Nearest)),
        (9986, Filter::Nearest, Some(Filter::Linear)),
        (9987, Filter::Linear, Some(Filter::Linear)),
    ] {
        j["samplers"][0] = json!({"wrapS": 10497, "wrapT": 33071, "magFilter": 9729, "minFilter": min});
        let p = cook(&write_gltf(&dir, "t.gltf", j.clone(), &bin)).unwrap();
        let want = Sampler { wrap_s: Wrap::Repeat, wrap_t: Wrap::Clamp, mag_filter: Filter::Linear, min_filter: filter, mipmap_filter: mips };
        assert_eq!(p.manifest.textures[0].sampler, want, "minFilter {min}");
    }
}

/// The quad scene with deformation and motion: a skinned mesh (1), a mesh with a morph target
/// (2), an animation moving nodes 3 and 6, and extras marking nodes static or not. Nodes, in
/// flattened order: 0 plain, 1 skinned, 2 morphed, 3 mover (animated, no mesh), 4 rider (under
/// mover), 5 door (extras static false), 6 insist (extras static true, animated), 7 joint,
/// 8 empty, 9 marked (extras static true).
fn rig() -> (Value, Vec<u8>) {
    let (mut j, mut bin) = quad();
    bin.extend([0u8; 16]); // joints, view 4
    bin.extend(f32s(&[1., 0., 0., 0.].repeat(4))); // weights, view 5
    bin.extend(f32s(&[0., 1.])); // key times, view 6
    bin.extend(f32s(&[0., 0., 0., 0., 1., 0.])); // translations, view 7
    j["buffers"][0]["byteLength"] = json!(bin.len());
    j["bufferViews"].as_array_mut().unwrap().extend([
        json!({"buffer": 0, "byteOffset": 140, "byteLength": 16}),
        json!({"buffer": 0, "byteOffset": 156, "byteLength": 64}),
        json!({"buffer": 0, "byteOffset": 220, "byteLength": 8}),
        json!({"buffer": 0, "byteOffset": 228, "byteLength": 24}),
    ]);
    j["accessors"].as_array_mut().unwrap().extend([
        json!({"bufferView": 4, "componentType": 5121, "count": 4, "type": "VEC4"}),
        json!({"bufferView": 5, "componentType": 5126, "count": 4, "type": "VEC4"}),
        json!({"bufferView": 6, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0.0], "max": [1.0]}),
        json!({"bufferView": 7, "componentType": 5126, "count": 2, "type": "VEC3"}),
    ]);
    j["meshes"].as_array_mut().unwrap().extend([
        json!({"name": "Skinned", "primitives": [{"attributes": {"POSITION": 1, "NORMAL": 2, "JOINTS_0": 4, "WEIGHTS_0": 5}, "indices": 0}]}),
        // The normals serve as the target's position deltas.
        json!({"name": "Morphed", "primitives": [{"attributes": {"POSITION": 1, "NORMAL": 2}, "indices": 0, "targets": [{"POSITION": 2}]}]}),
    ]);
    j["skins"] = json!([{"joints": [7]}]);
    j["nodes"] = json!([
        {"name": "plain", "mesh": 0},
        {"name": "skinned", "mesh": 1, "skin": 0},
        {"name": "morphed", "mesh": 2},
        {"name": "mover", "children": [4]},
        {"name": "rider", "mesh": 0},
        {"name": "door", "mesh": 0, "extras": {"static": false}},
        {"name": "insist", "mesh": 0, "extras": {"static": true}},
        {"name": "joint"},
        {"name": "empty"},
        {"name": "marked", "mesh": 0, "extras": {"static": true, "note": "kept"}}
    ]);
    j["scenes"] = json!([{"nodes": [0, 1, 2, 3, 5, 6, 7, 8, 9]}]);
    j["animations"] = json!([{"name": "move", "samplers": [{"input": 6, "output": 7}], "channels": [
        {"sampler": 0, "target": {"node": 3, "path": "translation"}},
        {"sampler": 0, "target": {"node": 6, "path": "translation"}}
    ]}]);
    (j, bin)
}

#[test]
fn a_mesh_node_is_static_unless_it_deforms_moves_or_says_otherwise() {
    let dir = TempDir::new("static");
    let (j, bin) = rig();
    let p = cook(&write_gltf(&dir, "rig.gltf", j.clone(), &bin)).unwrap();
    let flags: Vec<(&str, bool)> = p.manifest.nodes.iter().map(|n| (n.name.as_str(), n.is_static)).collect();
    assert_eq!(
        flags,
        [
            ("plain", true),
            ("skinned", false),
            ("morphed", false),
            ("mover", false),
            ("rider", false),
            ("door", false),
            ("insist", false),
            ("joint", false),
            ("empty", false),
            ("marked", true)
        ]
    );
    let mut bad = j;
    bad["nodes"][5]["extras"] = json!({"static": "no"});
    assert_eq!(cook_err(bad, &bin), "node 5 'door': extras \"static\" is \"no\", expected true or false");
}

fn close(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5)
}

#[test]
fn punctual_lights_come_in_world_space_with_their_units() {
    let (mut j, bin) = quad();
    let h = std::f32::consts::FRAC_1_SQRT_2;
    j["extensionsUsed"] = json!(["KHR_lights_punctual"]);
    j["extensions"] = json!({"KHR_lights_punctual": {"lights": [
        {"name": "Sun", "type": "directional", "color": [1.0, 0.9, 0.8], "intensity": 3.0, "range": 7.0},
        {"type": "point", "intensity": 100.0, "range": 5.0},
        {"name": "Spot", "type": "spot", "intensity": 50.0, "spot": {"innerConeAngle": 0.1}}
    ]}});
    // root: at (1, 2, 3), turned 90 degrees about +Y (so -Z becomes -X).
    j["nodes"] = json!([
        {"name": "root", "children": [1, 2, 4], "translation": [1.0, 2.0, 3.0], "rotation": [0.0, h, 0.0, h]},
        {"name": "child", "mesh": 0},
        {"name": "lamp", "translation": [0.0, 0.0, 2.0], "extensions": {"KHR_lights_punctual": {"light": 1}}},
        {"name": "sky", "rotation": [-h, 0.0, 0.0, h], "extensions": {"KHR_lights_punctual": {"light": 0}}},
        {"name": "spot holder", "scale": [3.0, 3.0, 3.0], "extensions": {"KHR_lights_punctual": {"light": 2}}}
    ]);
    j["scenes"] = json!([{"nodes": [0, 3]}]);
    let dir = TempDir::new("lights");
    let imported = import_with(&write_gltf(&dir, "l.gltf", j.clone(), &bin), &ImportOptions::default());
    let lights = &imported.scene.lights;
    let names: Vec<(&str, pack::LightKind)> = lights.iter().map(|l| (l.name.as_str(), l.kind)).collect();
    use pack::LightKind::{Point, Spot, Sun};
    assert_eq!(names, [("lamp", Point), ("Spot", Spot), ("Sun", Sun)], "flattened node order; a light without a name takes its node's");
    let (lamp, spot, sun) = (&lights[0], &lights[1], &lights[2]);
    assert!(close(&lamp.position, &[3.0, 2.0, 3.0]), "{:?}", lamp.position);
    assert_eq!((lamp.intensity, lamp.range, lamp.color), (100.0, Some(5.0), [1.0; 3]));
    assert!(close(&spot.position, &[1.0, 2.0, 3.0]) && close(&spot.direction, &[-1.0, 0.0, 0.0]), "{spot:?}");
    assert_eq!((spot.inner_cone, spot.outer_cone, spot.range), (0.1, std::f32::consts::FRAC_PI_4, None), "outer cone defaults to pi/4");
    assert!(close(&sun.direction, &[0.0, -1.0, 0.0]), "{:?}", sun.direction);
    assert_eq!((sun.intensity, sun.color, sun.range), (3.0, [1.0, 0.9, 0.8], None), "lux and tint apart; no range for a sun");
    assert!(imported.scene.warnings.is_empty(), "{:?}", imported.scene.warnings);
    let p = build_pack(&imported.scene).unwrap();
    assert_eq!(p.manifest.lights, *lights);

    let mut bad = j.clone();
    bad["extensions"]["KHR_lights_punctual"]["lights"][2]["spot"] = json!({"innerConeAngle": 0.9, "outerConeAngle": 0.5});
    assert_eq!(
        cook_err(bad, &bin),
        "light 2 'Spot' on node 4 'spot holder': spot cone angles 0.9 (inner) and 0.5 (outer) are not 0 <= inner <= outer <= pi/2 with outer > 0"
    );
    let mut bad = j;
    bad["extensions"]["KHR_lights_punctual"]["lights"][1]["range"] = json!(0.0);
    assert_eq!(cook_err(bad, &bin), "light 1 on node 2 'lamp': range 0 is not a positive distance");

    // A light on an animated node is baked where the node rests, and the import says so.
    let (mut j, bin) = rig();
    j["extensionsUsed"] = json!(["KHR_lights_punctual"]);
    j["extensions"] = json!({"KHR_lights_punctual": {"lights": [{"type": "point"}]}});
    j["nodes"][4]["extensions"] = json!({"KHR_lights_punctual": {"light": 0}});
    let imported = import_with(&write_gltf(&dir, "rig.gltf", j, &bin), &ImportOptions::default());
    assert_eq!(imported.scene.lights.len(), 1);
    assert_eq!(
        imported.scene.warnings,
        ["light 0 on node 4 'rider': the node is animated, but lights are baked; imported where the node is at rest"]
    );
}

#[test]
fn the_first_camera_becomes_the_camera_spawn() {
    let (mut j, bin) = quad();
    let h = std::f32::consts::FRAC_1_SQRT_2;
    j["cameras"] = json!([
        {"name": "Wide", "type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1, "zfar": 100.0}},
        {"type": "orthographic", "orthographic": {"xmag": 2.0, "ymag": 1.0, "znear": 0.0, "zfar": 10.0}}
    ]);
    // The eye sits 1 m along +Z of root, which is at (1, 2, 3), scaled by 2 and turned 90
    // degrees about +Y: 2 m along +X of (1, 2, 3).
    j["nodes"] = json!([
        {"name": "root", "children": [1, 2], "translation": [1.0, 2.0, 3.0], "rotation": [0.0, h, 0.0, h], "scale": [2.0, 2.0, 2.0]},
        {"name": "child", "mesh": 0},
        {"name": "eye", "translation": [0.0, 0.0, 1.0], "camera": 0},
        {"name": "topdown", "camera": 1}
    ]);
    j["scenes"] = json!([{"nodes": [0, 3]}]);
    let dir = TempDir::new("camera");
    let scene = import_with(&write_gltf(&dir, "c.gltf", j.clone(), &bin), &ImportOptions::default()).scene;
    assert_eq!(scene.spawns.len(), 1, "only the first camera");
    let s = &scene.spawns[0];
    assert_eq!((s.name.as_str(), s.kind.as_str()), ("Wide", "camera"));
    assert!(close(&s.position, &[3.0, 2.0, 3.0]), "{:?}", s.position);
    assert!(close(&s.rotation, &[0.0, h, 0.0, h]), "scale removed, unit length: {:?}", s.rotation);
    assert_eq!(s.params, json!({"yfov": f64::from(0.8f32), "znear": f64::from(0.1f32)}));
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    assert_eq!(build_pack(&scene).unwrap().manifest.spawns, scene.spawns);

    // Without the eye's camera, the orthographic one is first: its magnifications, and a warning.
    let mut ortho = j.clone();
    ortho["nodes"][2].as_object_mut().unwrap().remove("camera");
    let scene = import_with(&write_gltf(&dir, "c.gltf", ortho, &bin), &ImportOptions::default()).scene;
    let s = &scene.spawns[0];
    assert_eq!((s.name.as_str(), &s.position, &s.rotation), ("topdown", &[0.0; 3], &[0.0, 0.0, 0.0, 1.0]), "unnamed: the node's name");
    assert_eq!(s.params, json!({"xmag": 2.0, "ymag": 1.0, "znear": 0.0}));
    assert_eq!(scene.warnings, ["camera 1 on node 3 'topdown': orthographic; the runtime shows it in perspective"]);

    // A type without its values is an error, not the gltf crate's panic.
    let mut bad = j.clone();
    bad["cameras"][0] = json!({"type": "perspective", "orthographic": {"xmag": 1.0, "ymag": 1.0, "znear": 0.0, "zfar": 1.0}});
    assert_eq!(cook_err(bad, &bin), "camera 0 on node 2 'eye': its type is perspective but it has no perspective values");
    let mut bad = j;
    bad["cameras"][0]["perspective"]["yfov"] = json!(0.0);
    assert_eq!(cook_err(bad, &bin), "camera 0 'Wide' on node 2 'eye': yfov 0 is not a positive number");
}

#[test]
fn buffers_and_images_must_stay_inside_the_assets_folder() {
    let dir = TempDir::new("uris");
    let (mut j, bin) = quad();
    for sub in ["asset/tex", "shared"] {
        std::fs::create_dir_all(dir.path(sub)).unwrap();
    }
    std::fs::write(dir.path("asset/quad.bin"), &bin).unwrap();
    std::fs::write(dir.path("secret.bin"), &bin).unwrap();
    std::fs::write(dir.path("asset/tex/t.png"), png(2, 2)).unwrap();
    std::fs::write(dir.path("shared/t.png"), png(2, 2)).unwrap();
    let canonical = |p: &str| dir.path(p).canonicalize().unwrap();
    let gltf = dir.path("asset/scene.gltf");
    // The image serves two usages (colour and data): read twice, listed once.
    j["materials"][0]["pbrMetallicRoughness"]["metallicRoughnessTexture"] = json!({"index": 0});
    let write = |buffer: &str, image: &str| {
        let mut j = j.clone();
        j["buffers"][0]["uri"] = json!(buffer);
        j["images"][0]["uri"] = json!(image);
        std::fs::write(&gltf, serde_json::to_vec(&j).unwrap()).unwrap();
    };
    let defaults = ImportOptions::default();

    write("quad.bin", "tex/t.png");
    let imported = import_with(&gltf, &defaults);
    assert_eq!(imported.files, [canonical("asset/scene.gltf"), canonical("asset/quad.bin"), canonical("asset/tex/t.png")]);
    assert_eq!(imported.scene.textures.len(), 2);

    let outside = |object: &str, uri: &str| {
        format!(
            "{}: invalid glTF: {object}: URI '{uri}' reaches outside the asset's folder '{}' (pass --allow-external-uris to allow it)",
            gltf.display(),
            canonical("asset").display()
        )
    };
    let secret = canonical("secret.bin");
    let file_uri = format!("file://{}", secret.display());
    let absolute = secret.display().to_string();
    for uri in ["../secret.bin", "%2E%2E/secret.bin", "tex/../../secret.bin", absolute.as_str(), file_uri.as_str()] {
        write(uri, "tex/t.png");
        assert_eq!(import_err_with(&gltf, &defaults), outside("buffer 0", uri));
        // Allowed, the old behaviour: the file is read (and reported).
        let imported = import_with(&gltf, &ImportOptions { allow_external_uris: true, ..Default::default() });
        assert_eq!(imported.files[1], secret, "{uri}");
    }
    // An absolute path inside the folder is inside.
    write(&canonical("asset/quad.bin").display().to_string(), "tex/t.png");
    import_with(&gltf, &defaults);

    // A symlink in the folder that leads out of it counts as leaving.
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(&secret, dir.path("asset/link.bin")).unwrap();
        write("link.bin", "tex/t.png");
        assert_eq!(import_err_with(&gltf, &defaults), outside("buffer 0", "link.bin"));
    }

    // Images too, checked before anything is read; a wider root (a level's folder) lets a
    // prop share its textures.
    write("quad.bin", "../shared/t.png");
    assert_eq!(import_err_with(&gltf, &defaults), outside("image 0", "../shared/t.png"));
    let imported = import_with(&gltf, &ImportOptions { root: Some(dir.0.clone()), ..Default::default() });
    assert_eq!(imported.files, [canonical("asset/scene.gltf"), canonical("asset/quad.bin"), canonical("shared/t.png")]);
    write("../secret.bin", "tex/t.png");
    import_with(&gltf, &ImportOptions { root: Some(dir.0.clone()), ..Default::default() });
}

#[test]
fn broken_lights_and_cameras_give_errors_not_panics() {
    let base = || {
        let (mut j, bin) = quad();
        j["extensions"] = json!({"KHR_lights_punctual": {"lights": [{"type": "spot", "spot": {}}]}});
        j["cameras"] = json!([{"type": "perspective", "perspective": {"yfov": 1.0, "znear": 0.1}}]);
        j["nodes"][1]["extensions"] = json!({"KHR_lights_punctual": {"light": 0}});
        j["nodes"][1]["camera"] = json!(0);
        (j, bin)
    };
    let dir = TempDir::new("broken-lights");
    let (j, bin) = base();
    cook(&write_gltf(&dir, "ok.gltf", j, &bin)).unwrap();
    type Change = Box<dyn Fn(&mut Value)>;
    let cases: Vec<(&str, Change)> = vec![
        ("light index", Box::new(|j| j["nodes"][1]["extensions"]["KHR_lights_punctual"]["light"] = json!(5))),
        ("light type", Box::new(|j| j["extensions"]["KHR_lights_punctual"]["lights"][0]["type"] = json!("area"))),
        ("spot without spot", Box::new(|j| j["extensions"]["KHR_lights_punctual"]["lights"][0] = json!({"type": "spot"}))),
        ("no lights", Box::new(|j| j["extensions"] = json!({}))),
        ("intensity", Box::new(|j| j["extensions"]["KHR_lights_punctual"]["lights"][0]["intensity"] = json!(-1.0))),
        ("colour", Box::new(|j| j["extensions"]["KHR_lights_punctual"]["lights"][0]["color"] = json!([1e39, 0.0, 0.0]))),
        ("camera index", Box::new(|j| j["nodes"][1]["camera"] = json!(3))),
        ("camera type", Box::new(|j| j["cameras"][0]["type"] = json!("fisheye"))),
        ("camera values", Box::new(|j| j["cameras"][0] = json!({"type": "orthographic", "perspective": {"yfov": 1.0, "znear": 0.1}}))),
        ("flat node", Box::new(|j| j["nodes"][1]["scale"] = json!([0.0, 0.0, 0.0]))),
        ("huge node", Box::new(|j| j["nodes"][1]["translation"] = json!([1e39, 0.0, 0.0]))),
    ];
    for (what, change) in cases {
        let (mut j, bin) = base();
        change(&mut j);
        let p = write_gltf(&dir, "h.gltf", j, &bin);
        let e = cook(&p).expect_err(what).to_string();
        assert!(!e.contains('\n'), "{what}: {e}");
    }
}
