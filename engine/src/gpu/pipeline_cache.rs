//! A `VkPipelineCache` kept on disk between runs (`GpuOptions::pipeline_cache`): shader
//! compilation is most of a cold start, and the driver can skip it for pipelines it has seen.
//! The driver checks the data's header (vendor, device, driver UUID) itself and ignores data
//! from another device or driver, so a stale or foreign file only costs the cold start. The file
//! is written atomically (temporary file, then rename) when the `Gpu` is dropped.

use ash::vk;
use std::path::{Path, PathBuf};

pub(super) struct DiskCache {
    pub cache: vk::PipelineCache,
    path: Option<PathBuf>,
}

impl DiskCache {
    /// A cache primed from `path` when it holds data (an unreadable or rejected file starts empty).
    pub fn open(device: &ash::Device, path: Option<&Path>) -> Result<DiskCache, vk::Result> {
        let data = path.and_then(|p| std::fs::read(p).ok()).unwrap_or_default();
        let create = |bytes: &[u8]| unsafe { device.create_pipeline_cache(&vk::PipelineCacheCreateInfo::default().initial_data(bytes), None) };
        let cache = match create(&data) {
            Ok(c) => c,
            Err(_) if !data.is_empty() => create(&[])?,
            Err(e) => return Err(e),
        };
        Ok(DiskCache { cache, path: path.map(Path::to_path_buf) })
    }

    /// Write the cache's data to its file (if it has one) and destroy it.
    pub fn close(&mut self, device: &ash::Device) {
        if let Some(path) = &self.path {
            if let Ok(data) = unsafe { device.get_pipeline_cache_data(self.cache) } {
                if let Err(e) = write_atomically(path, &data) {
                    eprintln!("warning: pipeline cache not saved to {}: {e}", path.display());
                }
            }
        }
        unsafe { device.destroy_pipeline_cache(self.cache, None) };
        self.cache = vk::PipelineCache::null();
    }
}

fn write_atomically(path: &Path, data: &[u8]) -> std::io::Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    let tmp = path.with_extension(format!("tmp-{}", std::process::id()));
    std::fs::write(&tmp, data)?;
    std::fs::rename(&tmp, path)
}
