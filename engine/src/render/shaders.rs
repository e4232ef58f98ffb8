//! SPIR-V compiled from ../shaders by build.rs (glslc), embedded in the binary.

use anyhow::Result;
use ash::vk;

pub const MESH_VERT: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/mesh.vert.spv"));
/// mesh.vert for the depth-only pipelines: the position alone (`DEPTH_ONLY`).
pub const MESH_DEPTH_VERT: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/mesh_depth.vert.spv"));
pub const MESH_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/mesh.frag.spv"));
pub const MESH_EQUAL_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/mesh_equal.frag.spv"));
/// The two above with each shaded fragment counted (`COUNT_FRAGMENTS`, mesh_shading.glsl).
pub const MESH_COUNTED_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/mesh_counted.frag.spv"));
pub const MESH_EQUAL_COUNTED_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/mesh_equal_counted.frag.spv"));
pub const MESH_BLEND_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/mesh_blend.frag.spv"));
pub const DEPTH_MASKED_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/depth_masked.frag.spv"));
pub const FULLSCREEN_VERT: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fullscreen.vert.spv"));
pub const TONEMAP_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/tonemap.frag.spv"));
pub const FXAA_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fxaa.frag.spv"));
pub const UPSCALE_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/upscale.frag.spv"));
pub const PARTICLE_VERT: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/particle.vert.spv"));
pub const PARTICLE_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/particle.frag.spv"));
pub const BOID_VERT: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/boid.vert.spv"));
pub const BOID_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/boid.frag.spv"));
pub const SKIN_COMP: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/skin.comp.spv"));
pub const DEPTH_VIEW_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/depth_view.frag.spv"));

pub fn module(device: &ash::Device, spv: &[u8]) -> Result<vk::ShaderModule> {
    let words = ash::util::read_spv(&mut std::io::Cursor::new(spv))?;
    Ok(unsafe { device.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)? })
}

#[cfg(test)]
#[path = "../../build/shader_compile.rs"]
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
