//! SPIR-V compiled from ../shaders by build.rs (glslc), embedded in the binary.

use anyhow::Result;
use ash::vk;

pub const MESH_VERT: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/mesh.vert.spv"));
pub const MESH_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/mesh.frag.spv"));

pub fn module(device: &ash::Device, spv: &[u8]) -> Result<vk::ShaderModule> {
    let words = ash::util::read_spv(&mut std::io::Cursor::new(spv))?;
    Ok(unsafe { device.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)? })
}
