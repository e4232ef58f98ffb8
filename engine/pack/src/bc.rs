//! Block-compressed texture levels (BC4, BC5, BC7): their sizes, and decoding them to the plain
//! texel layouts a device without the format (or a CPU rasteriser, where sampling them costs)
//! reads instead. One place for both, so the runtime's fallback and the cooker's quality check
//! decode the same way (`bcdec_rs`, an independent decoder of the formats' specification).

use crate::TextureFormat;

/// Texels a block is wide and high (every BC format).
pub const BLOCK: u32 = 4;

/// The layout `decode` gives a compressed format's texels in: 8-bit channels, tightly packed rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decoded {
    /// BC7: RGBA, as the format's sRGB or linear flavour says.
    Rgba8,
    /// BC5: RG (a normal map's x and y; z is rebuilt by the shader).
    Rg8,
    /// BC4: R.
    R8,
}

impl Decoded {
    pub fn channels(self) -> usize {
        match self {
            Decoded::Rgba8 => 4,
            Decoded::Rg8 => 2,
            Decoded::R8 => 1,
        }
    }
}

impl TextureFormat {
    /// Bytes of a 4x4 block for a block-compressed format; `None` for a plain one.
    pub fn block_bytes(self) -> Option<u64> {
        match self {
            TextureFormat::Bc4Unorm => Some(8),
            TextureFormat::Bc5Unorm | TextureFormat::Bc7Srgb | TextureFormat::Bc7Unorm => Some(16),
            TextureFormat::Rgba8Srgb | TextureFormat::Rgba8Unorm | TextureFormat::Rgba16Float | TextureFormat::Rgba16Unorm => None,
        }
    }

    pub fn is_compressed(self) -> bool {
        self.block_bytes().is_some()
    }

    /// What `decode` turns a compressed format into (`None` for a plain format).
    pub fn decoded(self) -> Option<Decoded> {
        match self {
            TextureFormat::Bc7Srgb | TextureFormat::Bc7Unorm => Some(Decoded::Rgba8),
            TextureFormat::Bc5Unorm => Some(Decoded::Rg8),
            TextureFormat::Bc4Unorm => Some(Decoded::R8),
            _ => None,
        }
    }

    /// Bytes of one `width` x `height` level: whole blocks for a compressed format (a level
    /// smaller than a block still takes one), texels otherwise. `None` on overflow.
    pub fn level_bytes(self, width: u32, height: u32) -> Option<u64> {
        let (w, h) = (width as u64, height as u64);
        match (self.block_bytes(), self.bytes_per_texel()) {
            (Some(b), _) => (w.div_ceil(BLOCK as u64) * h.div_ceil(BLOCK as u64)).checked_mul(b),
            (None, Some(t)) => (w * h).checked_mul(t),
            (None, None) => unreachable!("a format is plain or compressed"),
        }
    }
}

/// Decode one `width` x `height` level of a compressed `format` (`blocks`: row-major blocks,
/// `level_bytes` long) to tightly packed texels in `format.decoded()`'s layout. `None` when the
/// format is not compressed or `blocks` has the wrong length.
pub fn decode(format: TextureFormat, width: u32, height: u32, blocks: &[u8]) -> Option<Vec<u8>> {
    let layout = format.decoded()?;
    let block_bytes = format.block_bytes()? as usize;
    if blocks.len() as u64 != format.level_bytes(width, height)? {
        return None;
    }
    let (w, h, c) = (width as usize, height as usize, layout.channels());
    let bw = w.div_ceil(4);
    let mut out = vec![0u8; w * h * c];
    let mut block = [0u8; 64];
    for (i, b) in blocks.chunks_exact(block_bytes).enumerate() {
        let (bx, by) = (i % bw * 4, i / bw * 4);
        let pitch = 4 * c;
        match format {
            TextureFormat::Bc7Srgb | TextureFormat::Bc7Unorm => bcdec_rs::bc7(b, &mut block, pitch),
            TextureFormat::Bc5Unorm => bcdec_rs::bc5(b, &mut block, pitch, false),
            TextureFormat::Bc4Unorm => bcdec_rs::bc4(b, &mut block, pitch, false),
            _ => unreachable!("decoded() is Some only for compressed formats"),
        }
        // Blocks at the right and bottom edges may hang over the level: copy what is inside.
        for y in 0..4.min(h - by) {
            let n = 4.min(w - bx) * c;
            out[((by + y) * w + bx) * c..][..n].copy_from_slice(&block[y * pitch..][..n]);
        }
    }
    Some(out)
}
