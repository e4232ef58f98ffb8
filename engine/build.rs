//! Compiles every GLSL shader in ../shaders to SPIR-V with glslc. A shader error fails the build
//! with glslc's own message, which names the file and line.

use std::path::PathBuf;
use std::process::Command;

fn main() {
    let shader_dir = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap()).join("../shaders");
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").unwrap());
    println!("cargo:rerun-if-changed={}", shader_dir.display());
    let glslc = std::env::var("GLSLC").unwrap_or_else(|_| "glslc".into());
    let mut entries: Vec<_> = std::fs::read_dir(&shader_dir)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", shader_dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    let mut failures = Vec::new();
    for src in entries {
        let ext = src.extension().and_then(|e| e.to_str()).unwrap_or("");
        if !matches!(ext, "vert" | "frag" | "comp") {
            continue; // .glsl files are includes
        }
        println!("cargo:rerun-if-changed={}", src.display());
        let name = src.file_name().unwrap().to_string_lossy();
        let out = out_dir.join(format!("{name}.spv"));
        let result = Command::new(&glslc)
            .args(["--target-env=vulkan1.3", "-O", "-Werror", "-I"])
            .arg(&shader_dir)
            .arg(&src)
            .arg("-o")
            .arg(&out)
            .output();
        match result {
            Ok(o) if o.status.success() => {}
            Ok(o) => failures.push(format!("{}:\n{}", src.display(), String::from_utf8_lossy(&o.stderr))),
            Err(e) => failures.push(format!(
                "cannot run '{glslc}' for {}: {e} (install Debian's glslc, or run `make setup`)",
                src.display()
            )),
        }
    }
    if !failures.is_empty() {
        eprintln!("shader compilation failed:\n{}", failures.join("\n"));
        panic!("shader compilation failed:\n{}", failures.join("\n"));
    }
}
