//! The cooker's compute core: glTF 2.0 in, `pack::Pack` out.
//!
//! Input is untrusted: every accessor is bounds- and type-checked before it is read (see
//! `accessor`), and every failure is a `CookError` whose message is one line naming the file, the
//! object and the problem. Nothing here panics on file content.

mod accessor;
mod error;
mod load;
mod material;
mod mesh;
mod scene;

pub use error::CookError;
pub use pack;

use pack::{Pack, PackBuilder, PackError};
use std::collections::HashSet;
use std::path::Path;

/// Written into every pack's manifest as provenance.
pub const COOKER: &str = concat!("cook_core ", env!("CARGO_PKG_VERSION"));

/// Cook a .gltf or .glb file into a pack in memory. `progress` is called with what is being
/// worked on and the fraction done (0..=1).
pub fn cook_gltf(source: &Path, progress: &mut dyn FnMut(&str, f32)) -> Result<Pack, CookError> {
    let file = source.display().to_string();
    let invalid = |problem: String| CookError::invalid(&file, problem);
    progress("reading", 0.0);
    let src = load::open(source, &file)?;
    let doc = &src.document;

    let images: HashSet<usize> = doc
        .materials()
        .filter_map(|m| m.pbr_metallic_roughness().base_color_texture())
        .map(|info| info.texture().source().index())
        .collect();
    let total = (images.len() + doc.meshes().len() + 1) as f32;
    let mut done = 0usize;
    let mut step = |what: &str| {
        progress(what, done as f32 / total);
        done += 1;
    };

    let mut b = PackBuilder::new(&file, COOKER);
    b.manifest.materials = material::cook_materials(&src, &mut b, &mut step).map_err(invalid)?;
    let default_material = b.manifest.materials.len() as u32;
    for m in doc.meshes() {
        step(&label("mesh", m.index(), m.name()));
        let cooked = mesh::cook_mesh(&m, &src.buffers, default_material, &mut b).map_err(invalid)?;
        b.manifest.meshes.push(cooked);
    }
    let uses_default = b.manifest.meshes.iter().flat_map(|m| &m.submeshes).any(|s| s.material == default_material);
    if uses_default {
        b.manifest.materials.push(pack::Material::default());
    }
    step("nodes");
    b.manifest.nodes = scene::flatten(doc).map_err(invalid)?;
    progress("done", 1.0);
    Ok(b.finish())
}

/// Fail early, before any cooking, when `out` cannot be written or would overwrite `source`.
pub fn check_output(out: &Path, source: &Path) -> Result<(), CookError> {
    let file = out.display().to_string();
    if out.file_name().is_none() {
        return Err(CookError::io(&file, "not a file path"));
    }
    let dir = match out.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        return Err(CookError::io(&file, format!("output directory '{}' does not exist", dir.display())));
    }
    if out.is_dir() {
        return Err(CookError::io(&file, "is a directory"));
    }
    let same = |a: &Path, b: &Path| matches!((a.canonicalize(), b.canonicalize()), (Ok(a), Ok(b)) if a == b);
    if same(out, source) {
        return Err(CookError::io(&file, "is the source file; choose another output path"));
    }
    Ok(())
}

/// Write `pack` to `out` atomically (temporary file + rename): on failure `out` is untouched
/// and no temporary file remains. Returns the pack's size in bytes.
pub fn write_pack(pack: &Pack, out: &Path) -> Result<u64, CookError> {
    let file = out.display().to_string();
    pack::write_pack_atomic(pack, out).map_err(|e| match e {
        // The pack crate's I/O message already starts with the path.
        PackError::Io(m) => CookError::io(&file, m.strip_prefix(&format!("{file}: ")).unwrap_or(&m)),
        e => CookError::BadPack { file: file.clone(), reason: format!("cooker produced a malformed pack: {e}") },
    })?;
    std::fs::metadata(out).map(|m| m.len()).map_err(|e| CookError::io(&file, e.to_string()))
}

/// Read and fully validate a pack file.
pub fn read_pack(path: &Path) -> Result<Pack, CookError> {
    let file = path.display().to_string();
    if !path.exists() {
        return Err(CookError::NotFound { file });
    }
    Pack::read_file(path).map_err(|e| match e {
        PackError::Io(m) => CookError::io(&file, format!("cannot read: {m}")),
        e => CookError::BadPack { file, reason: e.to_string() },
    })
}

/// Counts for a one-line report and for tests.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Summary {
    pub meshes: usize,
    pub submeshes: usize,
    pub vertices: u64,
    pub indices: u64,
    pub triangles: u64,
    pub materials: usize,
    pub textures: usize,
    /// (width, height) of each texture, in pack order.
    pub texture_sizes: Vec<(u32, u32)>,
    pub nodes: usize,
    /// Size of the pack file.
    pub bytes: u64,
}

impl Summary {
    pub fn of(pack: &Pack, bytes: u64) -> Summary {
        let m = &pack.manifest;
        let indices: u64 = m.meshes.iter().map(|x| x.index_count as u64).sum();
        Summary {
            meshes: m.meshes.len(),
            submeshes: m.meshes.iter().map(|x| x.submeshes.len()).sum(),
            vertices: m.meshes.iter().map(|x| x.vertex_count as u64).sum(),
            indices,
            triangles: indices / 3,
            materials: m.materials.len(),
            textures: m.textures.len(),
            texture_sizes: m.textures.iter().map(|t| (t.width, t.height)).collect(),
            nodes: m.nodes.len(),
            bytes,
        }
    }
}

/// How messages name an object: `mesh 0 'Box'`, or `mesh 0` when it has no name.
pub(crate) fn label(kind: &str, index: usize, name: Option<&str>) -> String {
    match name {
        Some(n) if !n.is_empty() => format!("{kind} {index} '{n}'"),
        _ => format!("{kind} {index}"),
    }
}

#[cfg(test)]
mod tests;
