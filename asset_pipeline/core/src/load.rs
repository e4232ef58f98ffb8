//! Reading a glTF 2.0 file (.gltf or .glb) and the buffers it refers to.
//!
//! We parse with the gltf crate but load buffers and images ourselves: its `import` indexes
//! slices with unchecked ranges and unwraps on some URIs, and it cannot tell us which buffer or
//! image a failure was about.

use crate::error::{one_line, CookError};
use crate::uri::{self, UriPolicy};
use gltf::Document;
use std::path::{Path, PathBuf};

/// The extensions the importer implements; a file that requires any other is refused (one it
/// only uses is read without it, as glTF allows).
pub const SUPPORTED_EXTENSIONS: [&str; 3] = ["KHR_lights_punctual", "KHR_materials_emissive_strength", "KHR_texture_transform"];

/// A parsed document with its buffers' bytes, index-aligned with `document.buffers()`.
pub(crate) struct Source {
    pub document: Document,
    pub buffers: Vec<Vec<u8>>,
    /// Per image: the file its URI names, resolved and checked against the root folder (`None`
    /// for a data: URI, a buffer view or no source at all). Read only when a material uses it.
    pub image_files: Vec<Option<PathBuf>>,
    /// Per material: the KHR_texture_transform JSON of its normal and occlusion textures, which
    /// gltf-json 1.4 does not model (it reads the extension on `textureInfo` only; its
    /// `extensions` feature would keep them, but it also makes light and transform `extras`
    /// fail to parse).
    pub normal_occlusion_transforms: Vec<[Option<serde_json::Value>; 2]>,
    /// The external files read so far (buffers), canonical, in order, without duplicates.
    pub files: Vec<PathBuf>,
}

/// The bytes of a .gltf or .glb file.
pub(crate) fn read(path: &Path, file: &str) -> Result<Vec<u8>, CookError> {
    std::fs::read(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => CookError::NotFound { file: file.into() },
        _ => CookError::io(file, format!("cannot read: {e}")),
    })
}

/// Parse the bytes of a .gltf or .glb file (`file` names it in messages) and load its buffers.
/// Every buffer and image URI is resolved and checked against `policy` (made for the file's
/// path) before any of them is read.
pub(crate) fn parse(bytes: &[u8], file: &str, policy: &UriPolicy) -> Result<Source, CookError> {
    let not_gltf = |reason: String| CookError::NotGltf { file: file.into(), reason: one_line(&reason) };
    if bytes.starts_with(b"glTF") {
        check_glb_header(bytes).map_err(not_gltf)?;
    }
    let gltf = gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| not_gltf(e.to_string()))?;
    let json = gltf.document.into_json();
    if !json.asset.version.starts_with("2.") {
        return Err(not_gltf(format!("asset version is {:?}", json.asset.version)));
    }
    // It parsed as glTF, so from here on failures mean broken content, not a foreign file.
    let invalid = |p: String| CookError::invalid(file, p);
    // Before the crate validates: its message for this ("Unsupported extension") does not say
    // what the cooker can read instead.
    check_required_extensions(&json).map_err(invalid)?;
    check_position_indices(&json).map_err(invalid)?;
    let document = Document::from_json(json)
        .map_err(|e| CookError::invalid(file, e.to_string().trim_end_matches(';')))?;
    let normal_occlusion_transforms = normal_occlusion_transforms(&document, bytes).map_err(invalid)?;

    let resolve = |what: String, uri: &str| policy.resolve(uri).map_err(|e| invalid(format!("invalid glTF: {what}: {e}")));
    let mut buffer_files = Vec::new();
    for buffer in document.buffers() {
        buffer_files.push(match buffer.source() {
            gltf::buffer::Source::Uri(u) if !uri::is_data(u) => Some(resolve(format!("buffer {}", buffer.index()), u)?),
            _ => None,
        });
    }
    let mut image_files = Vec::new();
    for (i, image) in document.as_json().images.iter().enumerate() {
        image_files.push(match (&image.buffer_view, &image.uri) {
            (None, Some(u)) if !uri::is_data(u) => Some(resolve(crate::label("image", i, image.name.as_deref()), u)?),
            _ => None,
        });
    }

    let mut blob = gltf.blob;
    let mut buffers = Vec::new();
    let mut files: Vec<PathBuf> = Vec::new();
    for (buffer, resolved) in document.buffers().zip(buffer_files) {
        let i = buffer.index();
        let data = match (buffer.source(), resolved) {
            (gltf::buffer::Source::Bin, _) => blob
                .take()
                .ok_or_else(|| format!("buffer {i} refers to the GLB binary chunk, which is missing")),
            (_, Some(path)) => {
                let data = uri::read_file(&path).map_err(|e| format!("buffer {i}: {e}"));
                if !files.contains(&path) {
                    files.push(path);
                }
                data
            }
            (gltf::buffer::Source::Uri(u), None) => uri::decode_data(u).map_err(|e| format!("buffer {i}: {e}")),
        }
        .map_err(invalid)?;
        if data.len() < buffer.length() {
            return Err(CookError::invalid(
                file,
                format!("buffer {i} holds {} bytes but declares byteLength {}", data.len(), buffer.length()),
            ));
        }
        buffers.push(data);
    }
    Ok(Source { document, buffers, image_files, normal_occlusion_transforms, files })
}

/// Refuse a file that requires an extension the importer does not implement: read without it,
/// the file would cook into something other than what it describes.
fn check_required_extensions(json: &gltf::json::Root) -> Result<(), String> {
    let missing: Vec<String> = json
        .extensions_required
        .iter()
        .filter(|e| !SUPPORTED_EXTENSIONS.contains(&e.as_str()))
        .map(|e| format!("'{e}'"))
        .collect();
    match missing.len() {
        0 => Ok(()),
        n => Err(format!(
            "requires extension{} {}, which the cooker does not support (supported: {})",
            if n == 1 { "" } else { "s" },
            missing.join(", "),
            SUPPORTED_EXTENSIONS.join(", ")
        )),
    }
}

/// The raw KHR_texture_transform of every material's normal and occlusion textures (see
/// `Source::normal_occlusion_transforms`), read from the JSON a second time, and only when some
/// material has either texture.
fn normal_occlusion_transforms(document: &Document, bytes: &[u8]) -> Result<Vec<[Option<serde_json::Value>; 2]>, String> {
    #[derive(serde::Deserialize)]
    struct Root {
        #[serde(default)]
        materials: Vec<Material>,
    }
    #[derive(serde::Deserialize)]
    #[serde(rename_all = "camelCase")]
    struct Material {
        normal_texture: Option<Slot>,
        occlusion_texture: Option<Slot>,
    }
    #[derive(serde::Deserialize)]
    struct Slot {
        extensions: Option<Extensions>,
    }
    #[derive(serde::Deserialize)]
    struct Extensions {
        #[serde(rename = "KHR_texture_transform")]
        transform: Option<serde_json::Value>,
    }
    let materials = &document.as_json().materials;
    if !materials.iter().any(|m| m.normal_texture.is_some() || m.occlusion_texture.is_some()) {
        return Ok(vec![[None, None]; materials.len()]);
    }
    let text: std::borrow::Cow<[u8]> = match bytes.starts_with(b"glTF") {
        true => gltf::binary::Glb::from_slice(bytes).map_err(|e| format!("GLB: {e}"))?.json,
        false => bytes.into(),
    };
    let root: Root = serde_json::from_slice(&text).map_err(|e| format!("invalid glTF: materials: {e}"))?;
    let transform = |s: Option<Slot>| s.and_then(|s| s.extensions).and_then(|e| e.transform);
    let mut out: Vec<_> = root.materials.into_iter().map(|m| [transform(m.normal_texture), transform(m.occlusion_texture)]).collect();
    out.resize(materials.len(), [None, None]);
    Ok(out)
}

/// What gltf-json 1.4 does not validate but the gltf crate relies on. It validates a primitive by
/// indexing `accessors` with its POSITION index before that index is checked, and panics when it
/// is out of range; check it first.
fn check_position_indices(json: &gltf::json::Root) -> Result<(), String> {
    use gltf::json::{mesh::Semantic, validation::Checked};
    for (m, mesh) in json.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            if let Some(i) = prim.attributes.get(&Checked::Valid(Semantic::Positions)) {
                if i.value() >= json.accessors.len() {
                    return Err(format!("invalid glTF: meshes[{m}].primitives[{p}].attributes.POSITION: Index out of bounds"));
                }
            }
        }
    }
    // Its validation of an animation checks samplers but not channel targets, and the gltf
    // crate unwraps both the target node and the target path.
    for (a, anim) in json.animations.iter().enumerate() {
        for (c, ch) in anim.channels.iter().enumerate() {
            let at = format!("invalid glTF: animations[{a}].channels[{c}].target");
            if ch.target.node.value() >= json.nodes.len() {
                return Err(format!("{at}.node: Index out of bounds"));
            }
            if !matches!(ch.target.path, Checked::Valid(_)) {
                return Err(format!("{at}.path: Invalid value"));
            }
        }
    }
    Ok(())
}

/// The gltf crate subtracts before it compares on a GLB header; reject what would underflow.
/// Lengths that run past the end of the file are reported here too, with the numbers (the
/// crate's own message for them is "could not completely read the object").
fn check_glb_header(bytes: &[u8]) -> Result<(), String> {
    let word = |at: u64| bytes.get(at as usize..at as usize + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    match (word(4), word(8)) {
        (Some(2), Some(len)) if len < 12 => Err(format!("GLB header declares a length of {len} bytes")),
        (Some(2), Some(len)) if len as usize > bytes.len() => {
            Err(format!("GLB header declares a length of {len} bytes but the file has {} (cut short?)", bytes.len()))
        }
        (Some(2), Some(len)) => {
            let (len, mut at) = (len as u64, 12u64);
            for chunk in 0.. {
                if at >= len {
                    break;
                }
                let (Some(size), Some(kind)) = (word(at).filter(|_| at + 8 <= len), word(at + 4)) else {
                    return Err(format!("GLB chunk {chunk} header at byte {at} is cut short"));
                };
                let name = match kind {
                    0x4E4F_534A => "JSON".to_string(),
                    0x004E_4942 => "BIN".to_string(),
                    k => format!("type {k:#010x}"),
                };
                if at + 8 + size as u64 > len {
                    return Err(format!("GLB chunk {chunk} ({name}) declares {size} bytes but only {} follow", len - at - 8));
                }
                at += 8 + size as u64;
            }
            Ok(())
        }
        (Some(v), Some(_)) => Err(format!("GLB container version {v}, expected 2")),
        _ => Err("GLB header is cut short".into()),
    }
}
