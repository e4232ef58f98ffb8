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
    let m = &p.manifest.meshes[mesh];
    p.bytes(m.lods[0].vertices)
        .chunks_exact(pack::VERTEX_STRIDE)
        .map(|c| {
            let f = |at: usize| f32::from_le_bytes(c[at..at + 4].try_into().unwrap());
            pack::Vertex {
                position: [f(0), f(4), f(8)],
                normal: [f(12), f(16), f(20)],
                tangent: [f(24), f(28), f(32), f(36)],
                uv0: [f(40), f(44)],
                uv1: [f(48), f(52)],
                color: c[56..60].try_into().unwrap(),
                _pad: 0,
            }
        })
        .collect()
}

fn indices(p: &Pack, mesh: usize) -> Vec<u32> {
    p.bytes(p.manifest.meshes[mesh].lods[0].indices).chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect()
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
    assert_eq!(mesh.lods[0].submeshes, [pack::Submesh { first_index: 0, index_count: 6, material: 0, lightmap_page: None }]);
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

#[test]
fn glb_with_image_in_a_buffer_view_cooks() {
    let (mut j, mut bin) = quad();
    let image = png(3, 1);
    j["bufferViews"].as_array_mut().unwrap().push(json!({"buffer": 0, "byteOffset": 140, "byteLength": image.len()}));
    j["images"] = json!([{"bufferView": 4, "mimeType": "image/png"}]);
    bin.extend(&image);
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    j["buffers"] = json!([{"byteLength": bin.len()}]);
    let mut text = serde_json::to_vec(&j).unwrap();
    while text.len() % 4 != 0 {
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
    let mut scene = crate::import_gltf(&path, &mut |_, _| {}).unwrap();
    // Exercise the optional parts too: a second LOD, lightmap pages, skin attributes, lights.
    let mut lod1 = scene.meshes[0].lods[0].clone();
    lod1.triangles.truncate(1);
    lod1.materials.truncate(1);
    lod1.error = 0.25;
    lod1.joints = Some(vec![[0, 1, 0, 0]; lod1.positions.len()]);
    lod1.weights = Some(vec![[0.5, 0.5, 0.0, 0.0]; lod1.positions.len()]);
    lod1.lightmap_pages = Some(vec![0]);
    scene.meshes[0].lods.push(lod1);
    scene.lightmap = Some(pack::LightmapLayout { texels_per_metre: 8.0, pages: vec![[64, 32]], padding: 2, textures: vec![] });
    scene.probes = Some(crate::ir::ProbesIr { origin: [1.0, 2.0, 3.0], spacing: [2.0; 3], counts: [2, 1, 1], sh: vec![[0.5; 27], [0.25; 27]], sun_visibility: vec![1.0, 0.0] });
    scene.sky = Some(pack::Sky { color: [0.1, 0.2, 0.3], intensity: 2.0 });
    let (json, arrays) = crate::wire::to_wire(&scene);
    let back = crate::wire::from_wire(&json, &arrays).unwrap();
    assert_eq!(back, scene);
    let pack = crate::build_pack(&back).unwrap();
    assert_eq!(pack.manifest.meshes[0].lods.len(), 2);
    assert_eq!(pack.manifest.meshes[0].lods[1].submeshes[0].lightmap_page, Some(0));
    assert_eq!(pack.manifest.meshes[0].lods[1].error, 0.25);
    let g = pack.manifest.probes.as_ref().unwrap();
    assert_eq!((g.counts, g.sh.len, g.sun_visibility.len), ([2, 1, 1], 2 * 27 * 4, 8));
    assert_eq!(&pack.bytes(g.sun_visibility)[4..], &0.0f32.to_le_bytes());
}

#[test]
fn wire_arrays_of_the_wrong_type_or_shape_are_named() {
    let dir = TempDir::new("wire");
    let (j, bin) = quad();
    let scene = crate::import_gltf(&write_gltf(&dir, "quad.gltf", j, &bin), &mut |_, _| {}).unwrap();
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
