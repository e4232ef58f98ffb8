//! Block-compressed texture levels (BC4, BC5, BC6H, BC7): their sizes, and decoding them to the plain
//! texel layouts a device without the format (or a CPU rasteriser, where sampling them costs)
//! reads instead. One place for both, so the runtime's fallback and the cooker's quality check
//! decode the same way (`bcdec_rs`, an independent decoder of the formats' specification).

use crate::TextureFormat;

/// Texels a block is wide and high (every BC format).
pub const BLOCK: u32 = 4;

/// The layout `decode` gives a compressed format's texels in, tightly packed rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decoded {
    /// BC7: RGBA, as the format's sRGB or linear flavour says.
    Rgba8,
    /// BC5: RG (a normal map's x and y; z is rebuilt by the shader).
    Rg8,
    /// BC4: R.
    R8,
    /// BC6H: RGBA half floats (little-endian), alpha 1 (a device samples RGBA16F everywhere;
    /// three-channel half formats are optional).
    Rgba16F,
}

impl Decoded {
    pub fn channels(self) -> usize {
        match self {
            Decoded::Rgba8 | Decoded::Rgba16F => 4,
            Decoded::Rg8 => 2,
            Decoded::R8 => 1,
        }
    }

    pub fn bytes_per_texel(self) -> usize {
        match self {
            Decoded::Rgba16F => 8,
            other => other.channels(),
        }
    }
}

impl TextureFormat {
    /// Bytes of a 4x4 block for a block-compressed format; `None` for a plain one.
    pub fn block_bytes(self) -> Option<u64> {
        match self {
            TextureFormat::Bc4Unorm => Some(8),
            TextureFormat::Bc5Unorm | TextureFormat::Bc7Srgb | TextureFormat::Bc7Unorm | TextureFormat::Bc6hUfloat => Some(16),
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
            TextureFormat::Bc6hUfloat => Some(Decoded::Rgba16F),
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

/// 1.0 as a half float's bits.
const HALF_ONE: u16 = 0x3C00;

/// Four halves as their little-endian bytes (the pack's byte order).
fn half_bytes(h: &[u16; 4]) -> [u8; 8] {
    let mut b = [0u8; 8];
    for (k, v) in h.iter().enumerate() {
        b[2 * k..2 * k + 2].copy_from_slice(&v.to_le_bytes());
    }
    b
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
    let (w, h, texel) = (width as usize, height as usize, layout.bytes_per_texel());
    let bw = w.div_ceil(4);
    let mut out = vec![0u8; w * h * texel];
    let pitch = 4 * texel;
    let mut block = [0u8; 128];
    let mut rgb_half = [0u16; 4 * 4 * 3];
    for (i, b) in blocks.chunks_exact(block_bytes).enumerate() {
        let (bx, by) = (i % bw * 4, i / bw * 4);
        match format {
            TextureFormat::Bc7Srgb | TextureFormat::Bc7Unorm => bcdec_rs::bc7(b, &mut block, pitch),
            TextureFormat::Bc5Unorm => bcdec_rs::bc5(b, &mut block, pitch, false),
            TextureFormat::Bc4Unorm => bcdec_rs::bc4(b, &mut block, pitch, false),
            TextureFormat::Bc6hUfloat => {
                // bcdec gives RGB halves (pitch in halves); the layout adds alpha = 1.0.
                bcdec_rs::bc6h_half(b, &mut rgb_half, 4 * 3, false);
                for (t, rgb) in rgb_half.chunks_exact(3).enumerate() {
                    let texel = [rgb[0], rgb[1], rgb[2], HALF_ONE];
                    block[t * 8..t * 8 + 8].copy_from_slice(half_bytes(&texel).as_slice());
                }
            }
            _ => unreachable!("decoded() is Some only for compressed formats"),
        }
        // Blocks at the right and bottom edges may hang over the level: copy what is inside.
        for y in 0..4.min(h - by) {
            let n = 4.min(w - bx) * texel;
            out[((by + y) * w + bx) * texel..][..n].copy_from_slice(&block[y * pitch..][..n]);
        }
    }
    Some(out)
}
