//! Mip chains for the textures stage: decode to linear f32, premultiply alpha, filter,
//! un-premultiply, encode, round once (notes/textures.md §1.7).
//!
//! Each level is filtered from the previous level's f32 result (the book's recursive pyramid,
//! L6743) with the filter scaled to the level's spacing; nothing is quantised between levels.
//! Level sizes are `max(1, n >> k)` down to 1x1, as Vulkan and the pack expect. What a texel
//! means decides how it is filtered (`Usage`).

pub mod filter;
pub mod resample;
pub mod srgb;

pub use filter::{Edge, Filter, Taps};
pub use resample::{downsample, Image, Texel};

use rayon::prelude::*;

/// What a texture's texels are, which decides how its levels are made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Usage {
    /// sRGB-encoded colour with straight alpha (base colour): filtered in linear light,
    /// premultiplied.
    Color,
    /// Linear 8-bit data (roughness, metalness, occlusion, masks): each channel on its own.
    Data,
    /// Tangent-space normals in rgb (UNORM, 0..1 -> -1..1): the vectors are averaged and
    /// renormalised; alpha is data. Every level, level 0 included, is stored as 16-bit UNORM:
    /// 8 bits cannot hold a unit vector closer than ~5e-3 to unit length, 16 bits hold it
    /// within 3e-5 (the notes' gate is 1e-3).
    Normal,
    /// Linear half-float HDR (lightmaps, emission): never clamped, non-negative kernels only.
    Hdr,
}

impl Usage {
    /// What a texture of `format` is when nothing says otherwise.
    pub fn of_format(format: pack::TextureFormat) -> Usage {
        match format {
            pack::TextureFormat::Rgba8Srgb | pack::TextureFormat::Bc7Srgb => Usage::Color,
            pack::TextureFormat::Rgba8Unorm | pack::TextureFormat::Bc7Unorm | pack::TextureFormat::Bc4Unorm => Usage::Data,
            pack::TextureFormat::Rgba16Float | pack::TextureFormat::Bc6hUfloat => Usage::Hdr,
            pack::TextureFormat::Rgba16Unorm | pack::TextureFormat::Bc5Unorm => Usage::Normal,
        }
    }

    /// Colour is stored sRGB, data UNORM, normals UNORM (8-bit as authored, 16-bit once
    /// cooked), HDR as half floats; or block-compressed by the compress stage (colour BC7 sRGB,
    /// data BC7 or BC4, normals BC5, HDR BC6H).
    pub fn check_format(self, format: pack::TextureFormat) -> Result<(), String> {
        use pack::TextureFormat as F;
        let ok = match self {
            Usage::Color => matches!(format, F::Rgba8Srgb | F::Bc7Srgb),
            Usage::Data => matches!(format, F::Rgba8Unorm | F::Bc7Unorm | F::Bc4Unorm),
            Usage::Normal => matches!(format, F::Rgba8Unorm | F::Rgba16Unorm | F::Bc5Unorm),
            Usage::Hdr => matches!(format, F::Rgba16Float | F::Bc6hUfloat),
        };
        if !ok {
            let want = match self {
                Usage::Color => "Rgba8Srgb or Bc7Srgb",
                Usage::Data => "Rgba8Unorm, Bc7Unorm or Bc4Unorm",
                Usage::Normal => "Rgba8Unorm, Rgba16Unorm or Bc5Unorm",
                Usage::Hdr => "Rgba16Float or Bc6hUfloat",
            };
            return Err(format!("usage {} needs format {want}, not {format:?}", self.name()));
        }
        Ok(())
    }

    pub fn name(self) -> &'static str {
        match self {
            Usage::Color => "color",
            Usage::Data => "data",
            Usage::Normal => "normal",
            Usage::Hdr => "hdr",
        }
    }

    pub fn parse(name: &str) -> Result<Usage, String> {
        match name {
            "color" => Ok(Usage::Color),
            "data" => Ok(Usage::Data),
            "normal" => Ok(Usage::Normal),
            "hdr" => Ok(Usage::Hdr),
            _ => Err(format!("unknown texture usage '{name}' (expected color, data, normal or hdr)")),
        }
    }

    /// Mitchell-Netravali for 8-bit content: in the notes' zone plate it passes the alias gate
    /// (RMS 0.033 <= 0.05) with little blur (passband error 0.021 <= 0.06); Catmull-Rom sits on
    /// the gate (0.050) and Lanczos3 aliases more (0.045) with larger lobes. HDR gets the tent:
    /// non-negative (a 1e4 texel cannot ring below zero) and sharper than the B-spline.
    pub fn default_filter(self) -> Filter {
        match self {
            Usage::Hdr => Filter::Tent,
            _ => Filter::Mitchell,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MipSettings {
    pub usage: Usage,
    pub filter: Filter,
    /// Along the width, then the height (glTF's wrapS, wrapT).
    pub edges: [Edge; 2],
    /// Alpha-tested colour: keep the fraction of texels with alpha >= cutoff at every level
    /// equal to level 0's (the shader discards below the cutoff).
    pub alpha_cutoff: Option<f32>,
}

impl MipSettings {
    pub fn new(usage: Usage) -> MipSettings {
        MipSettings { usage, filter: usage.default_filter(), edges: [Edge::Wrap; 2], alpha_cutoff: None }
    }

    pub fn check(&self) -> Result<(), String> {
        if self.usage == Usage::Hdr && !self.filter.is_non_negative() {
            return Err(format!("filter '{}' has negative lobes; hdr textures need box, tent or bspline (bright texels would ring below zero)", self.filter.name()));
        }
        if let Some(c) = self.alpha_cutoff {
            if self.usage != Usage::Color || !(c > 0.0 && c <= 1.0) {
                return Err(format!("alpha cutoff {c}: needs a color texture and a cutoff in (0, 1]"));
            }
        }
        Ok(())
    }
}

/// How many levels a `width` x `height` texture has down to 1x1.
pub fn level_count(width: u32, height: u32) -> u32 {
    32 - width.max(height).max(1).leading_zeros()
}

pub fn level_size(width: u32, height: u32, level: u32) -> (u32, u32) {
    ((width >> level).max(1), (height >> level).max(1))
}

/// Levels 1.. of an 8-bit RGBA texture (`texels`: level 0, tightly packed), each tightly packed.
/// Usage Color or Data (normal maps: `normal_levels`).
pub fn mips_rgba8(width: u32, height: u32, texels: &[u8], s: &MipSettings) -> Result<Vec<Vec<u8>>, String> {
    s.check()?;
    check_size(width, height, texels.len(), 4)?;
    match s.usage {
        Usage::Hdr => return Err("an hdr texture must be half float, not 8-bit".into()),
        Usage::Normal => return Err("a normal map's levels are 16-bit (normal_levels), not 8-bit".into()),
        Usage::Color | Usage::Data => {}
    }
    let (w, h) = (width as usize, height as usize);
    let level0 = |y: usize, row: &mut [Texel]| decode_row(s.usage, &texels[y * w * 4..(y + 1) * w * 4], row);
    let coverage = s.alpha_cutoff.map(|c| {
        let kept = texels.par_chunks_exact(4).filter(|t| alpha_kept(t[3], c)).count();
        (c, kept as f64 / (w * h) as f64)
    });
    let mut out = Vec::new();
    chain(width, height, level0, s, |img| {
        let mut bytes = encode(s.usage, img);
        if let Some((cutoff, target)) = coverage {
            keep_coverage(img, &mut bytes, cutoff, target);
        }
        out.push(bytes);
    });
    Ok(out)
}

/// A normal map's level 0 as authored: 8-bit (PNG) or 16-bit UNORM texels, tightly packed RGBA.
#[derive(Debug, Clone, Copy)]
pub enum NormalTexels<'a> {
    Unorm8(&'a [u8]),
    Unorm16(&'a [u16]),
}

impl NormalTexels<'_> {
    fn len(&self) -> usize {
        match self {
            NormalTexels::Unorm8(t) => t.len(),
            NormalTexels::Unorm16(t) => t.len(),
        }
    }

    /// Row `y` decoded to vectors in [-1, 1] (rgb) and alpha in [0, 1].
    fn decode_row(&self, w: usize, y: usize, row: &mut [Texel]) {
        fn snorm(v: f32) -> f32 {
            v * 2.0 - 1.0
        }
        match self {
            NormalTexels::Unorm8(t) => decode_row(Usage::Normal, &t[y * w * 4..(y + 1) * w * 4], row),
            NormalTexels::Unorm16(t) => {
                for (o, t) in row.iter_mut().zip(t[y * w * 4..(y + 1) * w * 4].chunks_exact(4)) {
                    let f: [f32; 4] = std::array::from_fn(|c| t[c] as f32 / 65535.0);
                    *o = [snorm(f[0]), snorm(f[1]), snorm(f[2]), f[3]];
                }
            }
        }
    }
}

/// Every level of a normal map, level 0 included, as 16-bit UNORM RGBA (`pack::TextureFormat::
/// Rgba16Unorm`). Level 0 is renormalised too: authored 8-bit vectors are only unit length to
/// within their quantisation, and the shader should see one consistent encoding at every level.
pub fn normal_levels(width: u32, height: u32, level0: NormalTexels<'_>, s: &MipSettings) -> Result<Vec<Vec<u16>>, String> {
    s.check()?;
    check_size(width, height, level0.len(), 4)?;
    if s.usage != Usage::Normal {
        return Err(format!("normal_levels needs usage normal, not {}", s.usage.name()));
    }
    let (w, h) = (width as usize, height as usize);
    let mut first = Image { width: w, height: h, texels: vec![[0.0; 4]; w * h] };
    first.texels.par_chunks_mut(w).enumerate().for_each(|(y, row)| level0.decode_row(w, y, row));
    let mut out = vec![encode_normal16(&first)];
    // Levels 1.. filter the decoded, not-yet-renormalised level 0 (renormalising first would
    // weight steep texels the same as flat ones and lose the averaging the notes ask for).
    chain(width, height, |y, row| row.copy_from_slice(first.row(y)), s, |img| out.push(encode_normal16(img)));
    Ok(out)
}

fn unorm16(v: f32) -> u16 {
    (v.clamp(0.0, 1.0) * 65535.0 + 0.5) as u16
}

fn encode_normal16(img: &Image) -> Vec<u16> {
    img.texels
        .par_iter()
        .flat_map_iter(|&t| {
            let f = finish_texel(Usage::Normal, t);
            [unorm16(f[0] * 0.5 + 0.5), unorm16(f[1] * 0.5 + 0.5), unorm16(f[2] * 0.5 + 0.5), unorm16(f[3])]
        })
        .collect()
}

/// Levels 1.. of a half-float RGBA texture (`texels`: level 0 as f16 bits). Usage Hdr.
pub fn mips_rgba16f(width: u32, height: u32, texels: &[u16], s: &MipSettings) -> Result<Vec<Vec<u16>>, String> {
    s.check()?;
    check_size(width, height, texels.len(), 4)?;
    if s.usage != Usage::Hdr {
        return Err("a half-float texture must have usage hdr".into());
    }
    let w = width as usize;
    if let Some(i) = texels.iter().position(|&b| !half::f16::from_bits(b).is_finite()) {
        let t = i / 4;
        return Err(format!("texel ({}, {}) is not finite", t % w, t / w));
    }
    let level0 = |y: usize, row: &mut [Texel]| {
        for (o, t) in row.iter_mut().zip(texels[y * w * 4..(y + 1) * w * 4].chunks_exact(4)) {
            *o = std::array::from_fn(|c| half::f16::from_bits(t[c]).to_f32());
        }
    };
    let mut out = Vec::new();
    chain(width, height, level0, s, |img| {
        // Never clamped to 1: only to what a half can hold.
        out.push(img.texels.par_iter().flat_map_iter(|t| t.map(|v| half::f16::from_f32(v.clamp(-65504.0, 65504.0)).to_bits())).collect());
    });
    Ok(out)
}

fn check_size(width: u32, height: u32, len: usize, channels: usize) -> Result<(), String> {
    if width == 0 || height == 0 {
        return Err(format!("size {width}x{height} is empty"));
    }
    let want = width as u64 * height as u64 * channels as u64;
    if len as u64 != want {
        return Err(format!("{len} values for {width}x{height} RGBA (expected {want})"));
    }
    Ok(())
}

/// Make levels 1.. from level 0 (read a row at a time by `level0`) and hand each level's f32
/// texels to `emit`, level 1 first.
pub fn chain<L>(width: u32, height: u32, level0: L, s: &MipSettings, mut emit: impl FnMut(&Image))
where
    L: Fn(usize, &mut [Texel]) + Sync,
{
    let levels = level_count(width, height);
    if levels < 2 {
        return;
    }
    let (w1, h1) = level_size(width, height, 1);
    let mut img = downsample(width as usize, height as usize, level0, w1 as usize, h1 as usize, s.filter, s.edges);
    emit(&img);
    for level in 2..levels {
        let (w, h) = level_size(width, height, level);
        let prev = &img;
        // From the previous level's unclamped f32 texels: the chain stays one linear filter of
        // level 0, and nothing is rounded until the encode.
        let next = downsample(prev.width, prev.height, |y, row| row.copy_from_slice(prev.row(y)), w as usize, h as usize, s.filter, s.edges);
        img = next;
        emit(&img);
    }
}

/// One row of 8-bit texels to the f32 form the filter works on.
fn decode_row(usage: Usage, bytes: &[u8], row: &mut [Texel]) {
    let lut = srgb::decode_table();
    for (o, t) in row.iter_mut().zip(bytes.chunks_exact(4)) {
        let a = t[3] as f32 / 255.0;
        *o = match usage {
            // Premultiplied: colour counts in proportion to the area it covers, and the rgb of
            // transparent texels (often garbage) gets weight 0 instead of bleeding as a fringe.
            Usage::Color => [lut[t[0] as usize] * a, lut[t[1] as usize] * a, lut[t[2] as usize] * a, a],
            Usage::Normal => [unorm_to_snorm(t[0]), unorm_to_snorm(t[1]), unorm_to_snorm(t[2]), a],
            Usage::Data | Usage::Hdr => [t[0] as f32 / 255.0, t[1] as f32 / 255.0, t[2] as f32 / 255.0, a],
        };
    }
}

fn unorm_to_snorm(b: u8) -> f32 {
    b as f32 / 127.5 - 1.0
}

fn unorm8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// The f32 texels a level's bytes stand for, before rounding: un-premultiplied colour clamped to
/// [0, 1] (negative lobes overshoot), unit normals. Tests check these; `encode` rounds them.
pub fn finish_texel(usage: Usage, t: Texel) -> Texel {
    match usage {
        Usage::Color => {
            let a = t[3].clamp(0.0, 1.0);
            // Below one 16-bit step of coverage the colour is noise: call it black.
            if a <= 1.0 / 65536.0 {
                return [0.0, 0.0, 0.0, a];
            }
            let inv = 1.0 / t[3];
            [(t[0] * inv).clamp(0.0, 1.0), (t[1] * inv).clamp(0.0, 1.0), (t[2] * inv).clamp(0.0, 1.0), a]
        }
        Usage::Normal => {
            let n = [t[0], t[1], t[2]];
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            // Opposite normals can cancel exactly; the surface is then on average flat.
            if len < 1e-6 {
                return [0.0, 0.0, 1.0, t[3].clamp(0.0, 1.0)];
            }
            [n[0] / len, n[1] / len, n[2] / len, t[3].clamp(0.0, 1.0)]
        }
        Usage::Data => t.map(|v| v.clamp(0.0, 1.0)),
        Usage::Hdr => t,
    }
}

/// A level's bytes: the one rounding.
fn encode(usage: Usage, img: &Image) -> Vec<u8> {
    let mut out = vec![0u8; img.texels.len() * 4];
    out.par_chunks_mut(4 * 1024).zip(img.texels.par_chunks(1024)).for_each(|(o, ts)| {
        for (o, &t) in o.chunks_exact_mut(4).zip(ts) {
            let f = finish_texel(usage, t);
            let rgb: [u8; 3] = match usage {
                Usage::Color => std::array::from_fn(|c| srgb::encode_byte(f[c])),
                Usage::Data => std::array::from_fn(|c| unorm8(f[c])),
                // mips_rgba8 turns these away: normals are 16-bit, HDR half float.
                Usage::Normal | Usage::Hdr => unreachable!("8-bit encode of {usage:?}"),
            };
            o.copy_from_slice(&[rgb[0], rgb[1], rgb[2], unorm8(f[3])]);
        }
    });
    out
}

/// What the shader keeps: `alpha >= cutoff` (mesh.frag discards below).
pub fn alpha_kept(alpha: u8, cutoff: f32) -> bool {
    alpha as f32 / 255.0 >= cutoff
}

/// Alpha-tested textures thin out (or fill in) with distance because filtering moves alpha
/// toward the mean. Rescale this level's stored alpha so the fraction of texels the shader
/// keeps matches level 0's (Castaño's coverage-preserving mips): choose a scale that keeps
/// exactly the `target` share of texels, 1 when that already holds. Only the stored alpha
/// changes; the next level is still filtered from the unscaled one.
fn keep_coverage(img: &Image, bytes: &mut [u8], cutoff: f32, target: f64) {
    let n = img.texels.len();
    let keep = ((target * n as f64).round() as usize).min(n);
    // The smallest byte the shader keeps, and the alpha from which rounding reaches it.
    let first_kept = (0..=255u8).find(|&b| alpha_kept(b, cutoff)).unwrap_or(255);
    let edge = (first_kept as f32 - 0.5) / 255.0;
    let mut alphas: Vec<f32> = img.texels.iter().map(|t| t[3].clamp(0.0, 1.0)).collect();
    // Scales in [lo, hi) keep exactly the `keep` largest alphas.
    let (lo, hi) = if keep == 0 {
        (0.0, edge / alphas.iter().copied().fold(0.0, f32::max))
    } else {
        let (below, &mut q, _) = alphas.select_nth_unstable_by(n - keep, |a, b| a.total_cmp(b));
        if q <= 0.0 {
            return; // fewer than `keep` texels have any alpha: no scale reaches the target
        }
        let next = below.iter().copied().fold(0.0, f32::max);
        (edge / q, if next > 0.0 { edge / next } else { f32::INFINITY })
    };
    let scale = if (lo..hi).contains(&1.0) {
        1.0
    } else if hi.is_finite() {
        0.5 * (lo + hi) // away from both ends, so rounding does not move a texel across
    } else {
        lo * 1.000_001 // just past the edge, so the quantile texel rounds to a kept byte
    };
    for (t, o) in img.texels.iter().zip(bytes.chunks_exact_mut(4)) {
        o[3] = unorm8(t[3].clamp(0.0, 1.0) * scale);
    }
}

#[cfg(test)]
mod tests;
