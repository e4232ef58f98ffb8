//! A pack replaced while the program runs (`demo --watch`, with `cook --watch` rewriting it):
//! noticing the new file, and swapping the scene for the new one only once the new one is whole
//! on the device, so a pack that cannot be read or uploaded leaves the old scene drawn. And the
//! shader sources edited while it runs ([`reload_shaders`]).

use crate::anim::animated::AnimatedScene;
use crate::gpu::Gpu;
use crate::render::renderer::Renderer;
use crate::render::shaders::{self, SourceWatch};
use crate::scene::GpuScene;
use anyhow::Result;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

/// What the file system says of a file's current contents. Packs are written whole and renamed
/// into place (`pack::write_pack_atomic`), so a new pack is a new inode with a new mtime; a
/// reader never sees half of one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Stamp {
    len: u64,
    modified: Option<SystemTime>,
    inode: u64,
}

fn stamp(path: &Path) -> Option<Stamp> {
    let m = std::fs::metadata(path).ok()?;
    #[cfg(unix)]
    let inode = std::os::unix::fs::MetadataExt::ino(&m);
    #[cfg(not(unix))]
    let inode = 0;
    Some(Stamp { len: m.len(), modified: m.modified().ok(), inode })
}

/// A pack file watched for replacement, by its stat (one call a frame: microseconds).
pub struct PackWatch {
    path: PathBuf,
    seen: Option<Stamp>,
}

impl PackWatch {
    /// Watch `path`, as it is now.
    pub fn new(path: &Path) -> PackWatch {
        PackWatch { path: path.to_path_buf(), seen: stamp(path) }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Whether the file was replaced since `new` or the last true answer. A file that is gone
    /// (being replaced) is no change yet: its replacement will be.
    pub fn changed(&mut self) -> bool {
        match stamp(&self.path) {
            Some(now) if Some(now) != self.seen => {
                self.seen = Some(now);
                true
            }
            _ => false,
        }
    }
}

/// Replace `scene` and the renderer's animated characters with `pack`'s. Both new ones are made
/// before the old ones go: if either cannot be, the old scene stays as it was and the error is
/// returned. Waits for the device before freeing the old scene (frames in flight read it).
pub fn replace_scene(gpu: &Gpu, renderer: &mut Renderer, scene: &mut GpuScene, pack: &pack::Pack, frames_in_flight: usize) -> Result<()> {
    let mut fresh = GpuScene::upload(gpu, pack, renderer.layouts())?;
    let animation = match AnimatedScene::new(gpu, pack, &fresh, frames_in_flight) {
        Ok(a) => a,
        Err(e) => {
            gpu.wait_idle();
            fresh.destroy(gpu);
            return Err(e);
        }
    };
    gpu.wait_idle();
    if let Some(mut a) = renderer.animation.take() {
        a.destroy(gpu);
    }
    let mut old = std::mem::replace(scene, fresh);
    old.destroy(gpu);
    renderer.animation = animation;
    Ok(())
}

/// What a look at the shader sources found.
#[derive(Debug)]
pub enum ShaderReload {
    /// No source changed since the last look.
    Unchanged,
    /// Compiled; these modules changed and the renderer's pipelines were made again from them
    /// (none: the edit did not change the SPIR-V, a comment, say).
    Reloaded(Vec<&'static str>),
    /// A shader did not compile: glslc's messages. The pipelines are as they were.
    Refused(String),
}

/// If a file under `watch` changed, compile every shader again (`shaders::reload`) and, if any
/// module changed, make the renderer's pipelines again (`Renderer::reload_shaders`).
pub fn reload_shaders(watch: &mut SourceWatch, gpu: &Gpu, renderer: &mut Renderer, frames_in_flight: usize) -> Result<ShaderReload> {
    if !watch.changed() {
        return Ok(ShaderReload::Unchanged);
    }
    match shaders::reload(&shaders::glslc(), watch.dir()) {
        Ok(changed) => {
            if !changed.is_empty() {
                renderer.reload_shaders(gpu, frames_in_flight)?;
            }
            Ok(ShaderReload::Reloaded(changed))
        }
        Err(messages) => Ok(ShaderReload::Refused(messages.join("\n"))),
    }
}

/// What the overlay says of the pack on show: where it is, when it was written (its file's
/// mtime: when the cook finished), its bake's samples per texel, and the last reload's error.
#[derive(Clone, Debug, Default)]
pub struct PackInfo {
    pub path: PathBuf,
    pub written: Option<SystemTime>,
    /// Lightmap paths per texel (`LightmapLayout::samples`): grows while `cook --watch` refines.
    pub samples: Option<u32>,
    pub reloads: u32,
    /// Why the last replacement was refused (the pack on show is then the one before it).
    pub error: Option<String>,
    /// Shader reloads (`--watch` with the shader sources present), and why the last was refused.
    pub shader_reloads: u32,
    pub shader_error: Option<String>,
}

impl PackInfo {
    pub fn new(path: &Path, pack: &pack::Pack) -> PackInfo {
        let mut info = PackInfo { path: path.to_path_buf(), ..Default::default() };
        info.shown(pack);
        info
    }

    /// `pack` (read from `path`) is on show now.
    pub fn shown(&mut self, pack: &pack::Pack) {
        self.written = std::fs::metadata(&self.path).and_then(|m| m.modified()).ok();
        self.samples = pack.manifest.lightmap.as_ref().and_then(|l| l.samples);
        self.error = None;
    }

    /// The overlay's lines: (label, value).
    pub fn rows(&self, now: SystemTime) -> Vec<(&'static str, String)> {
        let name = self.path.file_name().map_or_else(|| self.path.display().to_string(), |n| n.to_string_lossy().into_owned());
        let mut rows = vec![("pack", name)];
        if let Some(w) = self.written {
            let ago = now.duration_since(w).map(|d| d.as_secs()).unwrap_or(0);
            rows.push(("cooked", format!("{} ({ago} s ago)", clock(w))));
        }
        rows.push(("bake", self.samples.map_or_else(|| "not recorded".into(), |s| format!("{s} samples per texel"))));
        rows.push(("reloads", self.reloads.to_string()));
        if let Some(e) = &self.error {
            rows.push(("reload refused", e.clone()));
        }
        if self.shader_reloads > 0 {
            rows.push(("shader reloads", self.shader_reloads.to_string()));
        }
        if let Some(e) = &self.shader_error {
            rows.push(("shaders refused", e.clone()));
        }
        rows
    }
}

/// Wall-clock time of day (UTC) as hh:mm:ss.
fn clock(t: SystemTime) -> String {
    let s = t.duration_since(SystemTime::UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0) % 86_400;
    format!("{:02}:{:02}:{:02} UTC", s / 3600, s / 60 % 60, s % 60)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_renamed_replacement_is_a_change_and_a_missing_file_is_not() {
        let dir = std::env::temp_dir().join(format!("pack_watch_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.pack");
        std::fs::write(&path, b"one").unwrap();
        let mut w = PackWatch::new(&path);
        assert!(!w.changed());
        // Written beside and renamed over, as packs are: a new inode, whatever the size and mtime.
        let tmp = dir.join(".a.pack.tmp");
        std::fs::write(&tmp, b"two").unwrap();
        std::fs::rename(&tmp, &path).unwrap();
        assert!(w.changed());
        assert!(!w.changed(), "one change is told once");
        std::fs::remove_file(&path).unwrap();
        assert!(!w.changed(), "gone is not a change");
        std::fs::write(&path, b"three!").unwrap();
        assert!(w.changed());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn rows_say_the_samples_and_a_refused_reload() {
        let mut info = PackInfo { path: PathBuf::from("build/level.pack"), samples: Some(32), reloads: 2, ..Default::default() };
        info.written = Some(SystemTime::UNIX_EPOCH + std::time::Duration::from_secs(3600 * 25 + 61));
        let rows = info.rows(SystemTime::UNIX_EPOCH + std::time::Duration::from_secs(3600 * 25 + 71));
        assert_eq!(rows[0], ("pack", "level.pack".to_string()));
        assert_eq!(rows[1], ("cooked", "01:01:01 UTC (10 s ago)".to_string()));
        assert_eq!(rows[2], ("bake", "32 samples per texel".to_string()));
        info.error = Some("level.pack: not a pack".into());
        assert_eq!(info.rows(SystemTime::UNIX_EPOCH).last().unwrap().0, "reload refused");
    }
}
