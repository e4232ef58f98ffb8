//! The cooked pack format: one file per cooked level, written by the cooker and read by the runtime.
//!
//! This crate is the only place that knows the bytes of the format. The layout is
//!
//! ```text
//! offset 0   header (64 bytes, little endian)
//!              magic       [u8; 8]  = b"GAMEPACK"
//!              version     u32      = FORMAT_VERSION
//!              header_len  u32      = 64
//!              file_len    u64      total length of the file in bytes
//!              meta_off    u64      JSON metadata (the `Manifest`), UTF-8
//!              meta_len    u64
//!              data_off    u64      binary blob, 16-byte aligned; `BufferRange`s point into it
//!              data_len    u64      its length as stored
//!              checksum    u32      CRC-32 of the whole file with this field read as zero
//!              encoding    u32      how the blob is stored: 0 as it is, 1 one zstd frame
//!                                   (`DataEncoding`); `BufferRange`s are into the decoded blob
//! 64         metadata
//! data_off   data
//! ```
//!
//! Version 3 added the `animation` section (skins, clips, joints/weights, morph targets).
//! Version 4: 80-byte vertices with TEXCOORD_1; lightmaps per static instance (`Node::lightmap`
//! regions, `Submesh::lightmap_block`, pages of one size) and `Node::is_static` instead of
//! `Mesh::is_static`; texture slot transforms (`Material::*_uv`) and samplers (`Texture::sampler`).
//! Version 5: directional lightmaps (`LightmapLayout::directions`; with them a page's texture
//! holds b0 and the sun's visibility instead of B).
//! Version 6: reflection probes (`Manifest::reflection_probes`).
//! Version 7: 16-bit indices where a LOD has at most 65 536 vertices (`MeshLod::index_format`);
//! LODs in vertex cache and fetch order (the cooker's mesh_opt stage).
//! Version 8: block-compressed material textures (`TextureFormat::Bc7Srgb`, `Bc7Unorm`,
//! `Bc5Unorm`, `Bc4Unorm`; levels are whole 4x4 blocks, `TextureFormat::level_bytes`).
//! Version 9: baked light block-compressed: lightmap pages and reflection cubes may be
//! `Bc6hUfloat` (`ReflectionProbes::format`), direction textures `Bc7Unorm`; a directional
//! page's sun visibility moved from its alpha to the direction texture's.
//! Version 10: quantised 36-byte vertices (`vertex`, `MeshLod::uv_ranges`).
//! Version 11: the data blob may be stored zstd-compressed (the header's encoding word).
//!
//! Small, structured things (meshes, materials, textures, nodes) are JSON so that a pack can be
//! inspected with ordinary tools; big arrays (vertices, indices, texels) live in the data blob,
//! already in the layout the GPU consumes, so the runtime uploads them with one copy and no
//! per-vertex parsing.

mod anim;
pub mod bc;
mod error;
pub mod exposure;
mod manifest;
pub mod vertex;
mod write;

pub use anim::*;
pub use error::PackError;
pub use manifest::*;
pub use vertex::{decode_vertices, encode_vertices, encode_vertices_with, AttributeFormat, UvBounds, UvRanges, VERTEX_ATTRIBUTES, VERTEX_STRIDE};
pub use write::{write_pack_atomic, PackBuilder};

/// The first eight bytes of every pack.
pub const MAGIC: [u8; 8] = *b"GAMEPACK";
/// The version this build writes and reads. Bump on any incompatible change.
pub const FORMAT_VERSION: u32 = 11;
/// Size of the fixed header in bytes.
pub const HEADER_LEN: usize = 64;
/// Every buffer in the data blob starts at a multiple of this (vertex, index and texel uploads
/// want at least 4; 16 keeps room for vec4 storage-buffer views).
pub const DATA_ALIGN: usize = 16;

/// How a pack's data blob is stored (the header's encoding word).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataEncoding {
    /// As the GPU takes it: what tests that edit a pack's bytes in place write.
    Raw,
    /// One zstd frame (level `zstd_level`): lossless, what the cooker writes. The demo level's
    /// blob is 2.5x smaller (11.5 -> 4.6 MB), the golem's 4.9x, PalmTree's 6.1x (its lightmap
    /// atlas is mostly empty); decoding runs once, when the pack is read.
    Zstd,
}

/// The cooker's zstd level for a blob of up to `ZSTD_BEST_MAX` bytes, the highest of the normal
/// ones: against level 12 it stores the demo level's blob in 4.58 MB instead of 4.86 (6 % less;
/// Terrain's 2.77 instead of 2.91, the golem's 20 % less) for about 7x the encoding time (2-3 MB/s
/// a core) and decoding at about 600 MB/s instead of 1 GB/s (`zstd -b12 -e19`).
pub const ZSTD_LEVEL: i32 = 19;
/// Above this many bytes a blob is stored at `ZSTD_LEVEL_LARGE`: level 19 would take minutes
/// (the 1M-triangle benchmark level's 114 MB blob: 37 s on one core, 26 s on two) to save a
/// tenth (38.7 MB against 43.0 at level 9, which takes 1.6 s on two cores; level 12: 42.9 MB,
/// 3.7 s; level 16: 40.7 MB, 14 s; `zstd -b9 -e19 -T2` on that blob). At 32 MiB level 19 costs
/// about 10 s on one core.
pub const ZSTD_BEST_MAX: usize = 32 << 20;
/// The zstd level of a blob bigger than `ZSTD_BEST_MAX`.
pub const ZSTD_LEVEL_LARGE: i32 = 9;

/// The zstd level the cooker stores a blob of `len` bytes at.
pub fn zstd_level(len: usize) -> i32 {
    if len <= ZSTD_BEST_MAX { ZSTD_LEVEL } else { ZSTD_LEVEL_LARGE }
}

/// The blob as one zstd frame at `zstd_level`, its jobs on `workers` threads (at least one:
/// zstd's multithreaded frames are the same bytes for any number of workers, unlike the
/// single-threaded encoder's, so the pack does not depend on the cook's thread count).
fn zstd_frame(data: &[u8], workers: usize) -> Result<Vec<u8>, PackError> {
    let err = |e: std::io::Error| PackError::Io(format!("zstd: {e}"));
    let mut c = zstd::bulk::Compressor::new(zstd_level(data.len())).map_err(err)?;
    c.set_parameter(zstd::zstd_safe::CParameter::NbWorkers(workers.clamp(1, 64) as u32)).map_err(err)?;
    c.compress(data).map_err(err)
}

/// The largest data blob a pack may decode to (a damaged or forged frame header must not make
/// the reader allocate without bound).
pub const MAX_DATA_BYTES: u64 = 1 << 36;

/// A parsed pack: the manifest plus the data blob it points into.
#[derive(Debug, Clone, PartialEq)]
pub struct Pack {
    pub manifest: Manifest,
    pub data: Vec<u8>,
}

/// The fixed-size header, decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Header {
    version: u32,
    file_len: u64,
    meta_off: u64,
    meta_len: u64,
    data_off: u64,
    data_len: u64,
    checksum: u32,
    encoding: u32,
}

impl Header {
    fn encode(&self) -> [u8; HEADER_LEN] {
        let mut h = [0u8; HEADER_LEN];
        h[0..8].copy_from_slice(&MAGIC);
        h[8..12].copy_from_slice(&self.version.to_le_bytes());
        h[12..16].copy_from_slice(&(HEADER_LEN as u32).to_le_bytes());
        h[16..24].copy_from_slice(&self.file_len.to_le_bytes());
        h[24..32].copy_from_slice(&self.meta_off.to_le_bytes());
        h[32..40].copy_from_slice(&self.meta_len.to_le_bytes());
        h[40..48].copy_from_slice(&self.data_off.to_le_bytes());
        h[48..56].copy_from_slice(&self.data_len.to_le_bytes());
        h[56..60].copy_from_slice(&self.checksum.to_le_bytes());
        h[60..64].copy_from_slice(&self.encoding.to_le_bytes());
        h
    }
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}
fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}

impl Pack {
    /// Read and fully validate a pack file.
    pub fn read_file(path: &std::path::Path) -> Result<Pack, PackError> {
        let bytes = std::fs::read(path).map_err(|e| PackError::Io(e.to_string()))?;
        Pack::from_vec(bytes)
    }

    /// `from_bytes` for a file read whole: the data blob stays in the same allocation (moved to
    /// its front) instead of being copied into a new one, so loading reads the file once and
    /// touches no second copy of its pages.
    pub fn from_vec(mut bytes: Vec<u8>) -> Result<Pack, PackError> {
        match Pack::parse(&bytes)? {
            (manifest, Data::Stored(data)) => {
                bytes.truncate(data.end);
                bytes.drain(..data.start);
                Ok(Pack { manifest, data: bytes })
            }
            (manifest, Data::Decoded(data)) => Ok(Pack { manifest, data }),
        }
    }

    /// Decode a pack from memory. The checks run from the outside in, so each kind of damage
    /// gets its own error: not a pack at all, a pack from another version, a pack cut short,
    /// a pack whose bytes changed, and finally a pack whose contents do not make sense.
    pub fn from_bytes(bytes: &[u8]) -> Result<Pack, PackError> {
        match Pack::parse(bytes)? {
            (manifest, Data::Stored(data)) => Ok(Pack { manifest, data: bytes[data].to_vec() }),
            (manifest, Data::Decoded(data)) => Ok(Pack { manifest, data }),
        }
    }

    /// Check a whole file and decode its manifest; returns the data blob: its byte range in
    /// the file when stored as it is, else decoded.
    fn parse(bytes: &[u8]) -> Result<(Manifest, Data), PackError> {
        if bytes.len() < MAGIC.len() || bytes[..MAGIC.len()] != MAGIC {
            return Err(PackError::NotAPack);
        }
        if bytes.len() < 12 {
            return Err(PackError::Truncated { expected: HEADER_LEN as u64, actual: bytes.len() as u64 });
        }
        let version = u32_at(bytes, 8);
        if version != FORMAT_VERSION {
            return Err(PackError::WrongVersion { found: version, supported: FORMAT_VERSION });
        }
        if bytes.len() < HEADER_LEN {
            return Err(PackError::Truncated { expected: HEADER_LEN as u64, actual: bytes.len() as u64 });
        }
        let header = Header {
            version,
            file_len: u64_at(bytes, 16),
            meta_off: u64_at(bytes, 24),
            meta_len: u64_at(bytes, 32),
            data_off: u64_at(bytes, 40),
            data_len: u64_at(bytes, 48),
            checksum: u32_at(bytes, 56),
            encoding: u32_at(bytes, 60),
        };
        let actual = bytes.len() as u64;
        if actual < header.file_len {
            return Err(PackError::Truncated { expected: header.file_len, actual });
        }
        if actual > header.file_len {
            return Err(PackError::Corrupt(format!(
                "{} unexpected trailing bytes after the declared end at {}",
                actual - header.file_len,
                header.file_len
            )));
        }
        if u32_at(bytes, 12) as usize != HEADER_LEN {
            return Err(PackError::Corrupt(format!("header length {} is not {HEADER_LEN}", u32_at(bytes, 12))));
        }
        let crc = checksum(bytes);
        if crc != header.checksum {
            return Err(PackError::ChecksumMismatch { stored: header.checksum, computed: crc });
        }
        // The checksum matched, so what follows can only fail for a pack written wrongly (or
        // forged with a matching checksum): report it as malformed, naming the part.
        let section = |name: &str, off: u64, len: u64| -> Result<std::ops::Range<usize>, PackError> {
            let end = off.checked_add(len).filter(|&e| e <= actual && off >= HEADER_LEN as u64);
            match end {
                Some(end) => Ok(off as usize..end as usize),
                None => Err(PackError::Malformed(format!(
                    "{name} section {off}..+{len} lies outside the file ({actual} bytes)"
                ))),
            }
        };
        let meta = section("metadata", header.meta_off, header.meta_len)?;
        let stored = section("data", header.data_off, header.data_len)?;
        let manifest: Manifest = serde_json::from_slice(&bytes[meta])
            .map_err(|e| PackError::Malformed(format!("metadata: {e}")))?;
        let data = match header.encoding {
            0 => Data::Stored(stored),
            1 => Data::Decoded(unzstd(&bytes[stored])?),
            e => return Err(PackError::Malformed(format!("data encoding {e} is unknown (0: raw, 1: zstd)"))),
        };
        let blob = match &data {
            Data::Stored(r) => &bytes[r.clone()],
            Data::Decoded(v) => &v[..],
        };
        manifest.validate(blob.len() as u64)?;
        manifest.validate_indices(blob)?;
        Ok((manifest, data))
    }

    /// Encode to bytes (header, metadata, data zstd-compressed). `Pack::from_bytes` inverts
    /// this exactly.
    pub fn to_bytes(&self) -> Result<Vec<u8>, PackError> {
        self.to_bytes_with(DataEncoding::Zstd)
    }

    /// Encode to bytes (header, metadata, data stored as `encoding` says), compressing on one
    /// worker thread.
    pub fn to_bytes_with(&self, encoding: DataEncoding) -> Result<Vec<u8>, PackError> {
        self.encode(encoding, 1)
    }

    /// Encode to bytes, compressing on `workers` threads: the same bytes for any number.
    pub fn encode(&self, encoding: DataEncoding, workers: usize) -> Result<Vec<u8>, PackError> {
        self.manifest.validate(self.data.len() as u64)?;
        self.manifest.validate_indices(&self.data)?;
        let meta = serde_json::to_vec(&self.manifest)
            .map_err(|e| PackError::Malformed(format!("metadata: {e}")))?;
        let meta_off = HEADER_LEN as u64;
        let data_off = align_up(meta_off as usize + meta.len(), DATA_ALIGN) as u64;
        let zstd;
        let data: &[u8] = match encoding {
            DataEncoding::Raw => &self.data,
            DataEncoding::Zstd => {
                zstd = zstd_frame(&self.data, workers)?;
                &zstd
            }
        };
        let file_len = data_off + data.len() as u64;
        let mut out = Vec::with_capacity(file_len as usize);
        out.extend_from_slice(&[0u8; HEADER_LEN]);
        out.extend_from_slice(&meta);
        out.resize(data_off as usize, 0);
        out.extend_from_slice(data);
        let header = Header {
            version: FORMAT_VERSION,
            file_len,
            meta_off,
            meta_len: meta.len() as u64,
            data_off,
            data_len: data.len() as u64,
            checksum: 0,
            encoding: match encoding {
                DataEncoding::Raw => 0,
                DataEncoding::Zstd => 1,
            },
        };
        out[..HEADER_LEN].copy_from_slice(&header.encode());
        let crc = checksum(&out);
        out[CHECKSUM_AT..CHECKSUM_AT + 4].copy_from_slice(&crc.to_le_bytes());
        Ok(out)
    }

    /// The bytes a `BufferRange` refers to (validated on read, so this cannot go out of bounds
    /// for a pack that came from `from_bytes`).
    pub fn bytes(&self, r: BufferRange) -> &[u8] {
        &self.data[r.offset as usize..(r.offset + r.len) as usize]
    }

    /// A LOD's indices, whatever their stored width, as u32.
    pub fn indices(&self, lod: &MeshLod) -> Vec<u32> {
        lod.index_format.decode(self.bytes(lod.indices)).collect()
    }
}

const CHECKSUM_AT: usize = 56;

/// A parsed pack's data blob: where it lies in the file, or decoded from it.
enum Data {
    Stored(std::ops::Range<usize>),
    Decoded(Vec<u8>),
}

/// The blob of one zstd frame that states its size (the writer's do), at most
/// `MAX_DATA_BYTES`; any other frame is malformed.
fn unzstd(frame: &[u8]) -> Result<Vec<u8>, PackError> {
    let bad = |why: String| PackError::Malformed(format!("data: {why}"));
    let size = match zstd::zstd_safe::get_frame_content_size(frame) {
        Ok(Some(n)) if n <= MAX_DATA_BYTES => n as usize,
        Ok(Some(n)) => return Err(bad(format!("decodes to {n} bytes, more than {MAX_DATA_BYTES}"))),
        Ok(None) => return Err(bad("its zstd frame does not state its size".into())),
        Err(_) => return Err(bad("not a zstd frame".into())),
    };
    // The stated size is the frame's word, not a fact: a forged 50 KB frame can claim 60 GiB.
    // Allocating it up front (zstd's bulk API does) aborted the process when the allocation
    // failed (the pack_manifest fuzzer found it). So the output grows with what the frame really
    // decodes to, each reservation fallible: a frame that decodes to less is malformed, and one
    // that really needs more memory than there is, an error too.
    let mut decoder = zstd::stream::read::Decoder::with_buffer(frame).map_err(|e| bad(format!("zstd: {e}")))?;
    let mut out: Vec<u8> = Vec::new();
    let cannot = |_| bad(format!("decodes to {size} bytes, more memory than can be had"));
    // Packs' blobs shrink a few times under zstd: reserve for that at once, grow past it.
    out.try_reserve_exact(size.min(frame.len().saturating_mul(16).saturating_add(1 << 20))).map_err(cannot)?;
    let mut chunk = vec![0u8; 1 << 20];
    loop {
        let n = std::io::Read::read(&mut decoder, &mut chunk).map_err(|e| bad(format!("zstd: {e}")))?;
        if n == 0 {
            break;
        }
        if out.len() + n > size {
            return Err(bad(format!("decodes to more bytes than its frame says ({size})")));
        }
        if out.capacity() - out.len() < n {
            let grow = out.capacity().max(n).min(size - out.len());
            out.try_reserve_exact(grow).map_err(cannot)?;
        }
        out.extend_from_slice(&chunk[..n]);
    }
    if out.len() != size {
        return Err(bad(format!("decoded {} bytes, its frame says {size}", out.len())));
    }
    Ok(out)
}

/// CRC-32 of the whole file, reading the checksum field itself as zero, so that damage to the
/// header is caught as surely as damage to the body.
fn checksum(file: &[u8]) -> u32 {
    let mut h = crc32fast::Hasher::new();
    h.update(&file[..CHECKSUM_AT]);
    h.update(&[0u8; 4]);
    h.update(&file[CHECKSUM_AT + 4..]);
    h.finalize()
}

pub(crate) fn align_up(n: usize, a: usize) -> usize {
    n.div_ceil(a) * a
}

#[cfg(test)]
mod tests;
