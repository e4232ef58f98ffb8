//! Compiles every GLSL shader in ../shaders to SPIR-V with glslc (see build/shader_compile.rs).
//! A shader error fails the build with glslc's message, which names the file and line.

#[path = "build/shader_compile.rs"]
mod shader_compile;

use std::path::PathBuf;

fn main() {
    let shader_dir = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap()).join("../shaders");
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").unwrap());
    let glslc = std::env::var("GLSLC").unwrap_or_else(|_| "glslc".into());
    println!("cargo:rerun-if-changed={}", shader_dir.display());
    println!("cargo:rerun-if-env-changed=GLSLC");
    if let Ok(entries) = std::fs::read_dir(&shader_dir) {
        for e in entries.flatten() {
            println!("cargo:rerun-if-changed={}", e.path().display());
        }
    }
    if let Err(failures) = shader_compile::compile_all(&glslc, &shader_dir, &out_dir) {
        panic!("shader compilation failed:\n{}", failures.join("\n"));
    }
}
