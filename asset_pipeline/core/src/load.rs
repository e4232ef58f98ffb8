//! Reading a glTF 2.0 file (.gltf or .glb) and the buffers it refers to.
//!
//! We parse with the gltf crate but load buffers and images ourselves: its `import` indexes
//! slices with unchecked ranges and unwraps on some URIs, and it cannot tell us which buffer or
//! image a failure was about.

use crate::error::{one_line, CookError};
use gltf::Document;
use std::path::{Path, PathBuf};

/// A parsed document with its buffers' bytes, index-aligned with `document.buffers()`.
pub(crate) struct Source {
    pub document: Document,
    pub buffers: Vec<Vec<u8>>,
    /// Directory relative URIs are resolved against.
    pub base: PathBuf,
}

/// The bytes of a .gltf or .glb file.
pub(crate) fn read(path: &Path, file: &str) -> Result<Vec<u8>, CookError> {
    std::fs::read(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => CookError::NotFound { file: file.into() },
        _ => CookError::io(file, format!("cannot read: {e}")),
    })
}

/// Parse the bytes of the .gltf or .glb file at `path` (which resolves relative URIs; `file`
/// names it in messages) and load its buffers.
pub(crate) fn parse(bytes: &[u8], path: &Path, file: &str) -> Result<Source, CookError> {
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
    check_position_indices(&json).map_err(|p| CookError::invalid(file, p))?;
    let document = Document::from_json(json)
        .map_err(|e| CookError::invalid(file, e.to_string().trim_end_matches(';')))?;
    let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut blob = gltf.blob;
    let mut buffers = Vec::new();
    for buffer in document.buffers() {
        let i = buffer.index();
        let data = match buffer.source() {
            gltf::buffer::Source::Bin => blob
                .take()
                .ok_or_else(|| format!("buffer {i} refers to the GLB binary chunk, which is missing")),
            gltf::buffer::Source::Uri(uri) => read_uri(&base, uri).map_err(|e| format!("buffer {i}: {e}")),
        }
        .map_err(|p| CookError::invalid(file, p))?;
        if data.len() < buffer.length() {
            return Err(CookError::invalid(
                file,
                format!("buffer {i} holds {} bytes but declares byteLength {}", data.len(), buffer.length()),
            ));
        }
        buffers.push(data);
    }
    Ok(Source { document, buffers, base })
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

/// Bytes behind a buffer or image URI: a base64 `data:` URI, or a file relative to `base`.
pub(crate) fn read_uri(base: &Path, uri: &str) -> Result<Vec<u8>, String> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (_, payload) = rest
            .split_once(";base64,")
            .ok_or_else(|| "only base64 data: URIs are supported".to_string())?;
        return base64::decode(payload).map_err(|e| format!("bad base64 data: {e}"));
    }
    let path = if let Some(p) = uri.strip_prefix("file://").or_else(|| uri.strip_prefix("file:")) {
        PathBuf::from(percent_decode(p))
    } else if has_scheme(uri) {
        return Err(format!("unsupported URI scheme in '{uri}'"));
    } else {
        base.join(percent_decode(uri))
    };
    // Only regular files: a device (/dev/zero, /dev/stdin) or a pipe never ends or blocks.
    match std::fs::metadata(&path) {
        Ok(m) if !m.is_file() => return Err(format!("cannot read '{}': not a regular file", path.display())),
        _ => {}
    }
    std::fs::read(&path).map_err(|e| format!("cannot read '{}': {e}", path.display()))
}

fn has_scheme(uri: &str) -> bool {
    match uri.find(':') {
        Some(colon) => !uri[..colon].contains('/'),
        None => false,
    }
}

/// glTF URIs are percent-encoded (RFC 3986). Malformed escapes are kept literally.
fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        if b[i] == b'%' && i + 2 < b.len() {
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}
