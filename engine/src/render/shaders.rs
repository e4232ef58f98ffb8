//! SPIR-V compiled from ../shaders by build.rs (glslc), embedded in the binary; and, for
//! `demo --watch`, the same sources compiled again at run time ([`reload`]): from then on each
//! [`Shader::spv`] is the new module, and the renderer's pipelines are made again from them
//! (`Renderer::reload_shaders`).

use anyhow::Result;
use ash::vk;
use std::collections::HashMap;
use std::path::Path;
use std::sync::{OnceLock, RwLock};

/// One shader module: its SPIR-V file's name and the bytes build.rs compiled.
#[derive(Clone, Copy, Debug)]
pub struct Shader {
    pub file: &'static str,
    embedded: &'static [u8],
}

macro_rules! shader {
    ($file:literal) => {
        Shader { file: $file, embedded: include_bytes!(concat!(env!("OUT_DIR"), "/", $file)) }
    };
}

pub const MESH_VERT: Shader = shader!("mesh.vert.spv");
/// mesh.vert for the depth-only pipelines: the position alone (`DEPTH_ONLY`).
pub const MESH_DEPTH_VERT: Shader = shader!("mesh_depth.vert.spv");
pub const MESH_FRAG: Shader = shader!("mesh.frag.spv");
pub const MESH_EQUAL_FRAG: Shader = shader!("mesh_equal.frag.spv");
/// The two above with each shaded fragment counted (`COUNT_FRAGMENTS`, mesh_shading.glsl).
pub const MESH_COUNTED_FRAG: Shader = shader!("mesh_counted.frag.spv");
pub const MESH_EQUAL_COUNTED_FRAG: Shader = shader!("mesh_equal_counted.frag.spv");
pub const MESH_BLEND_FRAG: Shader = shader!("mesh_blend.frag.spv");
pub const DEPTH_MASKED_FRAG: Shader = shader!("depth_masked.frag.spv");
pub const FULLSCREEN_VERT: Shader = shader!("fullscreen.vert.spv");
pub const TONEMAP_FRAG: Shader = shader!("tonemap.frag.spv");
pub const FXAA_FRAG: Shader = shader!("fxaa.frag.spv");
pub const UPSCALE_FRAG: Shader = shader!("upscale.frag.spv");
pub const PARTICLE_VERT: Shader = shader!("particle.vert.spv");
pub const PARTICLE_FRAG: Shader = shader!("particle.frag.spv");
pub const BOID_VERT: Shader = shader!("boid.vert.spv");
pub const BOID_FRAG: Shader = shader!("boid.frag.spv");
pub const SKIN_COMP: Shader = shader!("skin.comp.spv");
pub const DEPTH_VIEW_FRAG: Shader = shader!("depth_view.frag.spv");

pub fn module(device: &ash::Device, spv: &[u8]) -> Result<vk::ShaderModule> {
    let words = ash::util::read_spv(&mut std::io::Cursor::new(spv))?;
    Ok(unsafe { device.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)? })
}

/// Every module the renderer uses (what [`reload`] looks for among the recompiled ones).
pub const ALL: [Shader; 18] = [MESH_VERT, MESH_DEPTH_VERT, MESH_FRAG, MESH_EQUAL_FRAG, MESH_COUNTED_FRAG, MESH_EQUAL_COUNTED_FRAG, MESH_BLEND_FRAG, DEPTH_MASKED_FRAG, FULLSCREEN_VERT, TONEMAP_FRAG, FXAA_FRAG, UPSCALE_FRAG, PARTICLE_VERT, PARTICLE_FRAG, BOID_VERT, BOID_FRAG, SKIN_COMP, DEPTH_VIEW_FRAG];

/// Modules compiled at run time, by file name. Their bytes are leaked: pipelines made from a
/// module may outlive any handle to it, and a reload changes only the modules whose sources (or
/// includes) changed, a few tens of KB each, so a long session of edits leaks little.
fn reloaded() -> &'static RwLock<HashMap<&'static str, &'static [u8]>> {
    static MAP: OnceLock<RwLock<HashMap<&'static str, &'static [u8]>>> = OnceLock::new();
    MAP.get_or_init(Default::default)
}

impl Shader {
    /// The module's SPIR-V: the last one [`reload`] compiled, or the embedded one.
    pub fn spv(self) -> &'static [u8] {
        reloaded().read().map(|m| m.get(self.file).copied()).ok().flatten().unwrap_or(self.embedded)
    }
}

/// Compile every shader in `sources` (a copy of the project's ../shaders) with `glslc`, as the
/// build does, and make the modules that changed the ones [`Shader::spv`] returns. Returns the
/// files of those modules; on any compile error nothing changes and the error is glslc's, one
/// message per failing file (its path first).
pub fn reload(glslc: &str, sources: &Path) -> Result<Vec<&'static str>, Vec<String>> {
    static RUN: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = RUN.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let out = std::env::temp_dir().join(format!("engine-shaders-{}-{n}", std::process::id()));
    std::fs::create_dir_all(&out).map_err(|e| vec![format!("{}: {e}", out.display())])?;
    let compiled = shader_compile::compile_all(glslc, sources, &out);
    let result = compiled.and_then(|_| {
        let mut fresh = Vec::new();
        for s in ALL {
            let bytes = std::fs::read(out.join(s.file)).map_err(|e| vec![format!("{}: {e} (not among the compiled shaders)", s.file)])?;
            if bytes != s.spv() {
                fresh.push((s.file, bytes));
            }
        }
        Ok(fresh)
    });
    let _ = std::fs::remove_dir_all(&out);
    let fresh = result?;
    let mut map = reloaded().write().map_err(|_| vec!["the shader table was poisoned".to_string()])?;
    Ok(fresh.into_iter().map(|(file, bytes)| {
        map.insert(file, Box::leak(bytes.into_boxed_slice()));
        file
    }).collect())
}

/// The shader sources to reload from (`demo --watch`): `ENGINE_SHADERS` if set, else the
/// project's ../shaders as the binary was built from, if it is still there.
pub fn sources() -> Option<std::path::PathBuf> {
    let dir = std::env::var_os("ENGINE_SHADERS").map(std::path::PathBuf::from).unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shaders"));
    dir.is_dir().then_some(dir)
}

/// The glslc to compile with: `GLSLC` if set (as the build), else the one on the PATH.
pub fn glslc() -> String {
    std::env::var("GLSLC").unwrap_or_else(|_| "glslc".into())
}

/// A folder of shader sources watched by the stat of its files (a few tens of calls a frame).
pub struct SourceWatch {
    dir: std::path::PathBuf,
    seen: Vec<(std::ffi::OsString, u64, Option<std::time::SystemTime>)>,
}

impl SourceWatch {
    pub fn new(dir: &Path) -> SourceWatch {
        SourceWatch { dir: dir.to_path_buf(), seen: listing(dir) }
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Whether a file was added, removed or rewritten since the last call (or `new`).
    pub fn changed(&mut self) -> bool {
        let now = listing(&self.dir);
        if now == self.seen {
            return false;
        }
        self.seen = now;
        true
    }
}

fn listing(dir: &Path) -> Vec<(std::ffi::OsString, u64, Option<std::time::SystemTime>)> {
    let mut out: Vec<_> = std::fs::read_dir(dir)
        .map(|d| d.filter_map(|e| e.ok()).filter_map(|e| e.metadata().ok().map(|m| (e.file_name(), m.len(), m.modified().ok()))).collect())
        .unwrap_or_default();
    out.sort();
    out
}

#[path = "../../build/shader_compile.rs"]
#[allow(dead_code)]
mod shader_compile;

#[cfg(test)]
mod tests {
    use super::shader_compile::compile_all;

    #[test]
    fn a_shader_error_names_the_file_and_carries_glslcs_message() {
        let dir = std::env::temp_dir().join(format!("shader-test-{}", std::process::id()));
        let out = dir.join("out");
        std::fs::create_dir_all(&out).unwrap();
        std::fs::write(dir.join("good.frag"), "#version 450\nlayout(location=0) out vec4 c;\nvoid main() { c = vec4(1.0); }\n").unwrap();
        std::fs::write(dir.join("broken.vert"), "#version 450\nvoid main() { gl_Position = undefined_thing; }\n").unwrap();
        let failures = compile_all("glslc", &dir, &out).unwrap_err();
        assert_eq!(failures.len(), 1, "{failures:?}");
        let msg = &failures[0];
        assert!(msg.contains("broken.vert"), "{msg}");
        assert!(msg.contains("undefined_thing") && msg.contains("error"), "glslc's diagnostic is missing: {msg}");
        assert!(out.join("good.frag.spv").exists(), "the good shader should still compile");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_variant_line_compiles_one_more_module_with_its_define() {
        let dir = std::env::temp_dir().join(format!("shader-variant-{}", std::process::id()));
        let out = dir.join("out");
        std::fs::create_dir_all(&out).unwrap();
        // The two modules differ only by the define.
        let src = "#version 450\n//! variant loud LOUD\nlayout(location=0) out vec4 c;\n#ifdef LOUD\nvoid main() { c = vec4(1.0); }\n#else\nvoid main() { c = vec4(0.0); }\n#endif\n";
        std::fs::write(dir.join("v.frag"), src).unwrap();
        compile_all("glslc", &dir, &out).unwrap();
        let (plain, loud) = (std::fs::read(out.join("v.frag.spv")).unwrap(), std::fs::read(out.join("v_loud.frag.spv")).unwrap());
        assert_ne!(plain, loud, "the variant must be compiled with its define");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_project_shaders_compile() {
        let shaders = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shaders");
        let out = std::env::temp_dir().join(format!("shader-ok-{}", std::process::id()));
        std::fs::create_dir_all(&out).unwrap();
        let compiled = compile_all("glslc", &shaders, &out).unwrap();
        assert!(compiled.len() >= 2);
        std::fs::remove_dir_all(&out).unwrap();
    }
}
