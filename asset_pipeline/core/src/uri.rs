//! Buffer and image URIs -> bytes, under the rule that a cook never reads outside the asset's
//! folder: a file URI resolves against the glTF file's folder and, once canonical (symlinks
//! followed), must lie in the root folder tree (the glTF's folder unless the caller widens it).
//! An asset that names `/etc/passwd`, `file:///home/me/.ssh/id_rsa` or `../../secret.bin` would
//! otherwise have the cooker read, and bake into a pack, any file its user can read.

use std::path::{Component, Path, PathBuf};

/// Where URIs resolve and which files they may reach.
pub(crate) struct UriPolicy {
    /// The glTF file's folder, canonical.
    base: PathBuf,
    /// The folder tree files must lie in, canonical.
    root: PathBuf,
    /// Read files anywhere (absolute paths, `file:` URIs, `..` out of the root).
    allow_external: bool,
}

impl UriPolicy {
    /// The policy for the glTF file at `gltf`: files inside `root` (default: the glTF's folder),
    /// or anywhere with `allow_external`.
    pub fn new(gltf: &Path, root: Option<&Path>, allow_external: bool) -> UriPolicy {
        let base = canonical(gltf.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new(".")));
        let root = root.map_or_else(|| base.clone(), canonical);
        UriPolicy { base, root, allow_external }
    }

    /// The file a (non-`data:`) URI names, canonical when it exists. The error is the problem
    /// with the URI, for the caller to prefix with the buffer or image it belongs to.
    pub fn resolve(&self, uri: &str) -> Result<PathBuf, String> {
        let path = if let Some(p) = uri.strip_prefix("file://").or_else(|| uri.strip_prefix("file:")) {
            self.base.join(percent_decode(p))
        } else if has_scheme(uri) {
            return Err(format!("unsupported URI scheme in '{uri}'"));
        } else {
            // An absolute path replaces the base in `join`.
            self.base.join(percent_decode(uri))
        };
        let path = canonical(&path);
        if !self.allow_external && !path.starts_with(&self.root) {
            return Err(format!(
                "URI '{uri}' reaches outside the asset's folder '{}' (pass --allow-external-uris to allow it)",
                self.root.display()
            ));
        }
        Ok(path)
    }
}

/// `p` with symlinks, `.` and `..` resolved; for a path that does not exist (reading it will
/// fail and say so), absolute with `.` and `..` resolved by their names.
fn canonical(p: &Path) -> PathBuf {
    if let Ok(c) = p.canonicalize() {
        return c;
    }
    let absolute = std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let mut out = PathBuf::new();
    for c in absolute.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            c => out.push(c),
        }
    }
    out
}

pub(crate) fn is_data(uri: &str) -> bool {
    uri.starts_with("data:")
}

/// The bytes of a base64 `data:` URI.
pub(crate) fn decode_data(uri: &str) -> Result<Vec<u8>, String> {
    let rest = uri.strip_prefix("data:").ok_or("not a data: URI")?;
    let (_, payload) = rest.split_once(";base64,").ok_or_else(|| "only base64 data: URIs are supported".to_string())?;
    base64::decode(payload).map_err(|e| format!("bad base64 data: {e}"))
}

/// The bytes of a file a URI resolved to.
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>, String> {
    // Only regular files: a device (/dev/zero, /dev/stdin) or a pipe never ends or blocks.
    match std::fs::metadata(path) {
        Ok(m) if !m.is_file() => return Err(format!("cannot read '{}': not a regular file", path.display())),
        _ => {}
    }
    std::fs::read(path).map_err(|e| format!("cannot read '{}': {e}", path.display()))
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
