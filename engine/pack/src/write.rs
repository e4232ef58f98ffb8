//! Building a pack in memory and writing it so that no reader ever sees half a file.

use crate::{align_up, BufferRange, Manifest, Pack, PackError, DATA_ALIGN};
use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

/// Makes temporary names unique across threads of one process (the pid covers processes).
static TMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Accumulates the data blob while the cooker adds meshes and textures.
#[derive(Debug, Default)]
pub struct PackBuilder {
    pub manifest: Manifest,
    data: Vec<u8>,
}

impl PackBuilder {
    pub fn new(source: &str, cooker: &str) -> Self {
        PackBuilder {
            manifest: Manifest { source: source.into(), cooker: cooker.into(), ..Default::default() },
            data: Vec::new(),
        }
    }

    /// Append bytes to the data blob at the next aligned offset and return where they went.
    pub fn push_bytes(&mut self, bytes: &[u8]) -> BufferRange {
        let offset = align_up(self.data.len(), DATA_ALIGN);
        self.data.resize(offset, 0);
        self.data.extend_from_slice(bytes);
        BufferRange { offset: offset as u64, len: bytes.len() as u64 }
    }

    /// Append `vertices` quantised (`crate::vertex`): where they went and the ranges their
    /// texture coordinates are stored over (both go into the LOD).
    pub fn push_vertices(&mut self, vertices: &[crate::Vertex]) -> (BufferRange, crate::UvRanges) {
        let (bytes, ranges) = crate::encode_vertices(vertices);
        (self.push_bytes(&bytes), ranges)
    }

    pub fn finish(self) -> Pack {
        Pack { manifest: self.manifest, data: self.data }
    }
}

/// Write `pack` to `path` atomically: the bytes go to a temporary file in the same directory,
/// are flushed to disk, and only then renamed over `path`. On any error the temporary file is
/// removed and `path` is untouched. The blob is compressed on `workers` threads (the bytes do
/// not depend on how many).
pub fn write_pack_atomic(pack: &Pack, path: &Path, workers: usize) -> Result<(), PackError> {
    let bytes = pack.encode(crate::DataEncoding::Zstd, workers)?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let name = path.file_name().ok_or_else(|| PackError::Io(format!("{}: not a file path", path.display())))?;
    let unique = TMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    let tmp = dir.join(format!(".{}.tmp-{}-{unique}", name.to_string_lossy(), std::process::id()));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(&bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        PackError::Io(format!("{}: cannot write: {e}", path.display()))
    })
}
