//! Compiling GLSL to SPIR-V with glslc. Shared by build.rs (which fails the build on error) and
//! a unit test (which checks that errors name the file and carry glslc's message).

use std::path::{Path, PathBuf};
use std::process::Command;

/// A stage's variants: each line `//! variant SUFFIX DEFINE` in its source also compiles it with
/// `-DDEFINE` into `<stem>_SUFFIX.<ext>.spv`. A variant that must differ in what the shader
/// *could* do (not only in what it does) needs its own module: lavapipe decides from the SPIR-V
/// which storage buffers a pipeline writes, branches under a specialisation constant included.
pub fn variants(source: &str) -> Vec<(String, String)> {
    source
        .lines()
        .filter_map(|l| l.trim().strip_prefix("//! variant "))
        .filter_map(|rest| {
            let mut words = rest.split_whitespace();
            Some((words.next()?.to_string(), words.next()?.to_string()))
        })
        .collect()
}

/// `mesh.frag` with suffix `counted`: `mesh_counted.frag`.
pub fn variant_name(name: &str, suffix: &str) -> String {
    match name.rsplit_once('.') {
        Some((stem, ext)) => format!("{stem}_{suffix}.{ext}"),
        None => format!("{name}_{suffix}"),
    }
}

/// Shader stages compiled on their own; other files in the directory (`*.glsl`) are includes.
pub fn is_stage(path: &Path) -> bool {
    matches!(path.extension().and_then(|e| e.to_str()), Some("vert" | "frag" | "comp"))
}

/// Compile every stage in `shader_dir` into `out_dir/<name>.spv` (and its `variants`). Returns the compiled sources,
/// or one message per failing file: its path followed by glslc's own diagnostics.
pub fn compile_all(glslc: &str, shader_dir: &Path, out_dir: &Path) -> Result<Vec<PathBuf>, Vec<String>> {
    let mut sources: Vec<PathBuf> = match std::fs::read_dir(shader_dir) {
        Ok(d) => d.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| is_stage(p)).collect(),
        Err(e) => return Err(vec![format!("cannot read {}: {e}", shader_dir.display())]),
    };
    sources.sort();
    let mut failures = Vec::new();
    for src in &sources {
        let name = src.file_name().unwrap().to_string_lossy().into_owned();
        let text = std::fs::read_to_string(src).unwrap_or_default();
        let mut outputs = vec![(name.clone(), None)];
        outputs.extend(variants(&text).into_iter().map(|(suffix, define)| (variant_name(&name, &suffix), Some(define))));
        for (out_name, define) in outputs {
            let out = out_dir.join(format!("{out_name}.spv"));
            let mut cmd = Command::new(glslc);
            cmd.args(["--target-env=vulkan1.3", "-O", "-Werror", "-I"]).arg(shader_dir);
            if let Some(d) = &define {
                cmd.arg(format!("-D{d}"));
            }
            match cmd.arg(src).arg("-o").arg(&out).output() {
                Ok(o) if o.status.success() => {}
                Ok(o) => failures.push(format!("{}{}:\n{}", src.display(), define.map(|d| format!(" (with {d})")).unwrap_or_default(), String::from_utf8_lossy(&o.stderr).trim_end())),
                Err(e) => failures.push(format!(
                    "{}: cannot run '{glslc}': {e} (install Debian's glslc, or run `make setup`)",
                    src.display()
                )),
            }
        }
    }
    if failures.is_empty() {
        Ok(sources)
    } else {
        Err(failures)
    }
}
