//! The cooker's compute core: glTF 2.0 in, `pack::Pack` out.
//!
//! Input is untrusted: every accessor is bounds- and type-checked before it is read (see
//! `accessor`), and every failure is a `CookError` whose message is one line naming the file, the
//! object and the problem. Nothing here panics on file content.

mod accessor;
pub mod anim;
mod camera;
pub mod compress;
mod error;
pub mod bake;
pub mod ir;
mod lights;
mod load;
mod material;
mod mesh;
pub mod mesh_opt;
pub mod measure;
pub mod pack_build;
mod scene;
pub mod tangents;
mod transform;
mod uri;
pub mod uv_raster;
pub mod wire;
pub mod exr_io;
pub mod lightmap_post;
pub mod lightmap_mosaic;
pub mod lod;
pub mod mips;

pub use error::CookError;
pub use load::SUPPORTED_EXTENSIONS;
pub use pack;

use ir::SceneIr;
use pack::{Pack, PackError};
use std::path::{Path, PathBuf};

/// Written into every pack's manifest as provenance.
pub const COOKER: &str = concat!("cook_core ", env!("CARGO_PKG_VERSION"));

/// Cook a .gltf or .glb file into a pack in memory (import with the default options, then
/// write; no other stages).
pub fn cook_gltf(source: &Path, progress: &mut dyn FnMut(&str, f32)) -> Result<Pack, CookError> {
    let imported = import_gltf(source, &ImportOptions::default(), progress)?;
    build_pack(&imported.scene)
}

/// The pack for a scene IR; a failure here is a cooker bug or bad data from a stage, reported
/// against the scene's source file.
pub fn build_pack(scene: &SceneIr) -> Result<Pack, CookError> {
    pack_build::build_pack(scene, COOKER).map_err(|e| CookError::invalid(&scene.source, e))
}

/// Which files a glTF import may read besides the glTF itself.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ImportOptions {
    /// The folder tree external buffers and images must lie in, after symlinks are followed;
    /// `None`: the glTF file's own folder. (A level passes its own folder for its props.)
    pub root: Option<PathBuf>,
    /// Read buffer and image URIs wherever they point: absolute paths, `file:` URIs and `..`
    /// out of the root.
    pub allow_external_uris: bool,
}

/// What a glTF import made, and what it read to make it.
#[derive(Debug, Clone, PartialEq)]
pub struct Imported {
    pub scene: SceneIr,
    /// Every file read, in order, without duplicates: the glTF itself (from `import_gltf`, not
    /// `import_gltf_bytes`), then each external buffer and image file, canonical (symlinks
    /// followed). A cache keyed by their contents knows when to import again.
    pub files: Vec<PathBuf>,
}

/// Import a .gltf or .glb file into the scene IR. `progress` is called with what is being
/// worked on and the fraction done (0..=1).
pub fn import_gltf(source: &Path, options: &ImportOptions, progress: &mut dyn FnMut(&str, f32)) -> Result<Imported, CookError> {
    progress("reading", 0.0);
    let bytes = load::read(source, &source.display().to_string())?;
    let mut imported = import_gltf_bytes(source, &bytes, options, progress)?;
    let me = source.canonicalize().unwrap_or_else(|_| source.to_path_buf());
    imported.files.retain(|f| *f != me);
    imported.files.insert(0, me);
    Ok(imported)
}

/// Import the bytes of a .gltf or .glb file that `source` names: `source` is used in messages,
/// for the scene's name and to resolve relative URIs (the fuzz target's entry point). The
/// files it reports are the external ones it read.
pub fn import_gltf_bytes(source: &Path, bytes: &[u8], options: &ImportOptions, progress: &mut dyn FnMut(&str, f32)) -> Result<Imported, CookError> {
    let file = source.display().to_string();
    let invalid = |problem: String| CookError::invalid(&file, problem);
    let policy = uri::UriPolicy::new(source, options.root.as_deref(), options.allow_external_uris);
    let mut src = load::parse(bytes, &file, &policy)?;
    let doc = &src.document;

    // Progress counts each texture once (a rough total is enough).
    let total = (material::texture_count(doc) + doc.meshes().len() + 2) as f32;
    let mut done = 0usize;
    let mut step = |what: &str| {
        progress(what, done as f32 / total);
        done += 1;
    };

    let mut scene = SceneIr {
        name: source.file_stem().map_or_else(|| "scene".into(), |s| s.to_string_lossy().into_owned()),
        source: file.clone(),
        ..Default::default()
    };
    let mut files = std::mem::take(&mut src.files);
    scene.materials = material::cook_materials(&src, &mut scene.textures, &mut files, &mut step).map_err(invalid)?;
    let default_material = scene.materials.len() as u32;
    let mut budget = mesh::MAX_VERTICES;
    for m in doc.meshes() {
        step(&label("mesh", m.index(), m.name()));
        scene.meshes.push(mesh::cook_mesh(&m, &src.buffers, default_material, &mut scene.warnings, &mut budget).map_err(invalid)?);
    }
    let uses_default = scene.meshes.iter().flat_map(|m| &m.lods[0].materials).any(|&m| m == default_material);
    if uses_default {
        scene.materials.push(pack::Material::default());
    }
    step("nodes");
    let mut flat = scene::flatten(doc).map_err(invalid)?;
    scene.lights = lights::cook_lights(doc, &flat, &mut scene.warnings).map_err(invalid)?;
    scene.spawns.extend(camera::first_camera(doc, &flat, &mut scene.warnings).map_err(invalid)?);
    scene.nodes = std::mem::take(&mut flat.nodes);
    let node_map = flat.map;
    step("animation");
    scene.skins = anim::cook_skins(doc, &src.buffers, &node_map).map_err(invalid)?;
    for n in doc.nodes() {
        let (Some(flat), true) = (node_map[n.index()], n.mesh().is_some()) else { continue };
        let weights = n.weights().map(<[f32]>::to_vec);
        let skin = n.skin().map(|s| s.index() as u32);
        if skin.is_some() || weights.is_some() {
            scene.bindings.push(pack::NodeBinding { node: flat, skin, weights });
        }
    }
    let targets_of = |node: u32| scene.nodes[node as usize].mesh.map_or(0, |m| scene.meshes[m as usize].morph_weights.len());
    scene.clips = anim::cook_clips(doc, &src.buffers, &node_map, &targets_of, &mut scene.warnings).map_err(invalid)?;
    scene.check_animation().map_err(invalid)?;
    progress("done", 1.0);
    Ok(Imported { scene, files })
}

/// The largest texture side the cooker accepts: what Vulkan devices commonly support for 2D
/// images (lavapipe's `maxImageDimension2D`); a bigger image would cook but never load.
pub const MAX_TEXTURE_SIZE: u32 = 16384;

/// Decode image bytes (PNG, JPEG, ...; the format from the bytes) as a texture. The size is read
/// from the header and checked against `MAX_TEXTURE_SIZE` before anything is decoded, so a small
/// file that claims a huge image is refused without allocating it; the decoder may then allocate
/// what the largest texture needs (16-bit RGBA) and no more. (The image crate's default limit,
/// 512 MiB, refused legitimate textures above 8192 px square with a bare "limits exceeded".)
pub fn decode_texture(bytes: &[u8]) -> Result<image::DynamicImage, String> {
    let reader = || image::ImageReader::new(std::io::Cursor::new(bytes)).with_guessed_format().map_err(|e| format!("cannot decode: {e}"));
    let (w, h) = reader()?.into_dimensions().map_err(|e| format!("cannot decode: {e}"))?;
    if w.max(h) > MAX_TEXTURE_SIZE {
        return Err(format!("{w} x {h} texels, larger than the {MAX_TEXTURE_SIZE} per side a texture may have"));
    }
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_TEXTURE_SIZE);
    limits.max_image_height = Some(MAX_TEXTURE_SIZE);
    limits.max_alloc = Some(u64::from(MAX_TEXTURE_SIZE) * u64::from(MAX_TEXTURE_SIZE) * 8);
    let mut decoder = reader()?;
    decoder.limits(limits);
    decoder.decode().map_err(|e| format!("cannot decode: {e}"))
}

/// Decode a PNG or JPEG file to RGBA8: (width, height, texels).
pub fn decode_image(path: &Path) -> Result<(u32, u32, Vec<u8>), CookError> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => CookError::NotFound { file: file.clone() },
        _ => CookError::io(&file, e.to_string()),
    })?;
    let rgba = decode_texture(&bytes).map_err(|e| CookError::invalid(&file, e.replacen("cannot decode", "cannot decode image", 1)))?.to_rgba8();
    let (w, h) = rgba.dimensions();
    Ok((w, h, rgba.into_raw()))
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
/// and no temporary file remains. Returns the pack's size in bytes. Compresses on the current
/// rayon pool's thread count (the bytes do not depend on it).
pub fn write_pack(pack: &Pack, out: &Path) -> Result<u64, CookError> {
    let file = out.display().to_string();
    pack::write_pack_atomic(pack, out, rayon::current_num_threads()).map_err(|e| match e {
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
    pub texture_sizes: Vec<[u32; 2]>,
    /// Mip levels of each texture, in pack order.
    pub texture_mips: Vec<usize>,
    pub nodes: usize,
    /// Lightmap atlas pages, and how many of them are baked.
    pub lightmap_pages: usize,
    pub lightmaps_baked: usize,
    /// Irradiance probes.
    pub probes: u64,
    /// Size of the pack file.
    pub bytes: u64,
}

impl Summary {
    /// Counts over LOD 0 of every mesh (what a full-detail frame draws).
    pub fn of(pack: &Pack, bytes: u64) -> Summary {
        let m = &pack.manifest;
        let lod0 = || m.meshes.iter().map(|x| &x.lods[0]);
        let indices: u64 = lod0().map(|x| x.index_count as u64).sum();
        Summary {
            meshes: m.meshes.len(),
            submeshes: lod0().map(|x| x.submeshes.len()).sum(),
            vertices: lod0().map(|x| x.vertex_count as u64).sum(),
            indices,
            triangles: indices / 3,
            materials: m.materials.len(),
            textures: m.textures.len(),
            texture_sizes: m.textures.iter().map(|t| [t.width, t.height]).collect(),
            texture_mips: m.textures.iter().map(|t| t.mips.len()).collect(),
            nodes: m.nodes.len(),
            lightmap_pages: m.lightmap.as_ref().map_or(0, |l| l.pages.len()),
            lightmaps_baked: m.lightmap.as_ref().map_or(0, |l| l.textures.len()),
            probes: m.probes.as_ref().map_or(0, |p| p.count()),
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
