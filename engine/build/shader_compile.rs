//! Compiling GLSL to SPIR-V with glslc. Shared by build.rs (which fails the build on error) and
//! a unit test (which checks that errors name the file and carry glslc's message).

use std::path::{Path, PathBuf};
use std::process::Command;

/// Shader stages compiled on their own; other files in the directory (`*.glsl`) are includes.
pub fn is_stage(path: &Path) -> bool {
    matches!(path.extension().and_then(|e| e.to_str()), Some("vert" | "frag" | "comp"))
}

/// Compile every stage in `shader_dir` into `out_dir/<name>.spv`. Returns the compiled sources,
/// or one message per failing file: its path followed by glslc's own diagnostics.
pub fn compile_all(glslc: &str, shader_dir: &Path, out_dir: &Path) -> Result<Vec<PathBuf>, Vec<String>> {
    let mut sources: Vec<PathBuf> = match std::fs::read_dir(shader_dir) {
        Ok(d) => d.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| is_stage(p)).collect(),
        Err(e) => return Err(vec![format!("cannot read {}: {e}", shader_dir.display())]),
    };
    sources.sort();
    let mut failures = Vec::new();
    for src in &sources {
        let name = src.file_name().unwrap().to_string_lossy();
        let out = out_dir.join(format!("{name}.spv"));
        let result = Command::new(glslc)
            .args(["--target-env=vulkan1.3", "-O", "-Werror", "-I"])
            .arg(shader_dir)
            .arg(src)
            .arg("-o")
            .arg(&out)
            .output();
        match result {
            Ok(o) if o.status.success() => {}
            Ok(o) => failures.push(format!("{}:\n{}", src.display(), String::from_utf8_lossy(&o.stderr).trim_end())),
            Err(e) => failures.push(format!(
                "{}: cannot run '{glslc}': {e} (install Debian's glslc, or run `make setup`)",
                src.display()
            )),
        }
    }
    if failures.is_empty() {
        Ok(sources)
    } else {
        Err(failures)
    }
}
