//! Material textures as the baker reads them where rays hit: level 0, 8 bits per channel as
//! loaded (a 256-entry table decodes sRGB; no f32 copies, so a scene's textures cost the baker
//! what they cost on disk, decoded), filtered bilinearly (or nearest, if the sampler says so)
//! in linear light, addressed by the sampler's wrap modes, with glTF's UV convention (origin at
//! the image's top-left corner, texel centres at half-integers).
//!
//! Also the mean luminance over a UV footprint, which weights emissive triangles for light
//! sampling ([`Footprint`]).

use pack::{Filter, Sampler, Wrap};
use serde::Deserialize;
use std::sync::LazyLock;

/// sRGB-encoded byte -> linear value (IEC 61966-2-1's piecewise curve).
static SRGB_TO_LINEAR: LazyLock<[f32; 256]> = LazyLock::new(|| {
    std::array::from_fn(|i| {
        let c = i as f64 / 255.0;
        (if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }) as f32
    })
});
/// Linear byte -> value (data textures and every alpha channel).
static UNORM: LazyLock<[f32; 256]> = LazyLock::new(|| std::array::from_fn(|i| i as f32 / 255.0));

#[derive(Clone)]
pub struct Texture {
    width: usize,
    height: usize,
    /// Row 0 at the top (v = 0), as the image is stored.
    texels: Vec<[u8; 4]>,
    /// RGB decoding table: sRGB or linear. Alpha is always linear.
    rgb: &'static [f32; 256],
    wrap: [Wrap; 2],
    /// The magnification filter: level 0 is what a lightmap-texel-sized footprint reads.
    filter: Filter,
    /// Every texel's alpha is 255 (the texture never makes a surface transparent).
    opaque: bool,
}

/// What the bindings pass beside each texture's texels: `ir.Texture`'s format and sampler.
#[derive(Deserialize)]
pub struct TextureInfo {
    #[serde(default)]
    pub name: String,
    pub format: String,
    #[serde(default)]
    pub sampler: Option<Sampler>,
}

impl Texture {
    /// `texels`: `width * height` RGBA bytes, rows top to bottom; `srgb`: the RGB channels are
    /// sRGB-encoded (colour textures) rather than linear.
    pub fn new(width: usize, height: usize, texels: Vec<[u8; 4]>, srgb: bool, sampler: Sampler) -> Result<Texture, String> {
        if width == 0 || height == 0 || texels.len() != width * height {
            return Err(format!("a {width}x{height} texture needs {} texels, got {}", width * height, texels.len()));
        }
        let opaque = texels.iter().all(|t| t[3] == 255);
        let rgb = if srgb { &*SRGB_TO_LINEAR } else { &*UNORM };
        Ok(Texture { width, height, texels, rgb, wrap: [sampler.wrap_s, sampler.wrap_t], filter: sampler.mag_filter, opaque })
    }

    /// From `ir.Texture`'s format ("Rgba8Srgb" or "Rgba8Unorm": the baker reads 8-bit textures;
    /// the Python side converts others) and sampler.
    pub fn from_info(info: &TextureInfo, width: usize, height: usize, texels: Vec<[u8; 4]>) -> Result<Texture, String> {
        let srgb = match info.format.as_str() {
            "Rgba8Srgb" => true,
            "Rgba8Unorm" => false,
            f => return Err(format!("texture '{}': format {f}, the baker reads Rgba8Srgb or Rgba8Unorm", info.name)),
        };
        Texture::new(width, height, texels, srgb, info.sampler.unwrap_or_default()).map_err(|e| format!("texture '{}': {e}", info.name))
    }

    pub fn is_opaque(&self) -> bool {
        self.opaque
    }

    #[inline]
    fn decode(&self, t: [u8; 4]) -> [f32; 4] {
        [self.rgb[t[0] as usize], self.rgb[t[1] as usize], self.rgb[t[2] as usize], UNORM[t[3] as usize]]
    }

    #[inline]
    fn texel(&self, x: i64, y: i64) -> [f32; 4] {
        let (x, y) = (wrap(x, self.width, self.wrap[0]), wrap(y, self.height, self.wrap[1]));
        self.decode(self.texels[y * self.width + x])
    }

    /// Linear RGBA at `uv` (level 0). Non-finite coordinates read as 0.
    pub fn sample(&self, uv: [f32; 2]) -> [f32; 4] {
        let finite = |c: f32| if c.is_finite() { c as f64 } else { 0.0 };
        // f64: a UV of a few thousand repeats still resolves texels exactly.
        let (x, y) = (finite(uv[0]) * self.width as f64, finite(uv[1]) * self.height as f64);
        match self.filter {
            Filter::Nearest => self.texel(x.floor() as i64, y.floor() as i64),
            Filter::Linear => {
                let (x, y) = (x - 0.5, y - 0.5);
                let (x0, y0) = (x.floor(), y.floor());
                let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
                let (x0, y0) = (x0 as i64, y0 as i64);
                let (a, b, c, d) = (self.texel(x0, y0), self.texel(x0 + 1, y0), self.texel(x0, y0 + 1), self.texel(x0 + 1, y0 + 1));
                std::array::from_fn(|k| {
                    let top = a[k] + (b[k] - a[k]) * fx;
                    let bottom = c[k] + (d[k] - c[k]) * fx;
                    top + (bottom - top) * fy
                })
            }
        }
    }
}

/// Texel index `i` on an axis of `n` texels under a wrap mode.
#[inline]
fn wrap(i: i64, n: usize, mode: Wrap) -> usize {
    let n = n as i64;
    (match mode {
        Wrap::Repeat => i.rem_euclid(n),
        Wrap::Clamp => i.clamp(0, n - 1),
        Wrap::Mirror => {
            let m = i.rem_euclid(2 * n);
            if m < n { m } else { 2 * n - 1 - m }
        }
    }) as usize
}

/// A summed-area table of a texture's luminance, for the mean over a UV footprint: what weights
/// an emissive triangle for light sampling. Made while the scene is built, one emissive texture
/// at a time, then dropped. A texture larger than 2^20 texels is summed over blocks of 2^k x 2^k
/// texels (a block's sum is positive if any of its texels is), so a table stays under 8 MB.
pub struct Footprint {
    /// Texels per block along each axis (a power of two).
    block: usize,
    /// Blocks across and down.
    w: usize,
    h: usize,
    /// (h + 1) x (w + 1) prefix sums of the blocks' luminance sums.
    sat: Vec<f64>,
}

const TABLE_TEXELS: usize = 1 << 20;

impl Footprint {
    pub fn new(tex: &Texture) -> Footprint {
        let mut block = 1;
        while tex.width.div_ceil(block) * tex.height.div_ceil(block) > TABLE_TEXELS {
            block *= 2;
        }
        let (w, h) = (tex.width.div_ceil(block), tex.height.div_ceil(block));
        let mut sums = vec![0.0f64; w * h];
        for y in 0..tex.height {
            for x in 0..tex.width {
                let c = tex.decode(tex.texels[y * tex.width + x]);
                sums[(y / block) * w + x / block] += luminance(c) as f64;
            }
        }
        let mut sat = vec![0.0f64; (w + 1) * (h + 1)];
        for y in 0..h {
            let mut row = 0.0;
            for x in 0..w {
                row += sums[y * w + x];
                sat[(y + 1) * (w + 1) + x + 1] = sat[y * (w + 1) + x + 1] + row;
            }
        }
        Footprint { block, w, h, sat }
    }

    /// Mean linear luminance of `tex` (the texture this table was made from) over every texel a
    /// filtered read anywhere in the UV box `lo..hi` can touch (the box widened by a texel for
    /// the bilinear neighbours, then wrapped as the sampler wraps), in blocks for big textures.
    /// Zero only if every such texel is black, which is what keeps light sampling by these
    /// weights unbiased: a triangle that can emit anywhere gets a positive weight.
    pub fn mean(&self, tex: &Texture, lo: [f32; 2], hi: [f32; 2]) -> f64 {
        // Integer texel range [a, b] a read in [lo, hi] can touch: bilinear reads floor(x - 0.5)
        // and the next; nearest reads floor(x), which lies in that range too.
        let range = |lo: f32, hi: f32, n: usize| -> (i64, i64) {
            let f = |c: f32| if c.is_finite() { c as f64 * n as f64 } else { 0.0 };
            // Saturating casts: a huge footprint still spans the whole texture.
            ((f(lo) - 0.5).floor().max(-1e15) as i64, ((f(hi) - 0.5).floor().min(1e15) as i64).saturating_add(1))
        };
        let (ax, bx) = range(lo[0], hi[0], tex.width);
        let (ay, by) = range(lo[1], hi[1], tex.height);
        let xs = covered(ax, bx, tex.width, tex.wrap[0]);
        let ys = covered(ay, by, tex.height, tex.wrap[1]);
        let (mut sum, mut count) = (0.0f64, 0.0f64);
        for &(y0, y1, wy) in &ys {
            for &(x0, x1, wx) in &xs {
                let (s, c) = self.sum(x0, x1, y0, y1);
                sum += wx * wy * s;
                count += wx * wy * c;
            }
        }
        if count > 0.0 { sum / count } else { 0.0 }
    }

    /// (luminance sum, texel count) over texels [x0, x1) x [y0, y1), in whole blocks.
    fn sum(&self, x0: usize, x1: usize, y0: usize, y1: usize) -> (f64, f64) {
        let (bx0, bx1) = (x0 / self.block, x1.div_ceil(self.block).min(self.w));
        let (by0, by1) = (y0 / self.block, y1.div_ceil(self.block).min(self.h));
        let at = |x: usize, y: usize| self.sat[y * (self.w + 1) + x];
        let s = at(bx1, by1) - at(bx0, by1) - at(bx1, by0) + at(bx0, by0);
        (s, ((bx1 - bx0) * (by1 - by0) * self.block * self.block) as f64)
    }
}

pub fn luminance(c: [f32; 4]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

/// The texels of an axis of `n` that indices a..=b reach under a wrap mode, as intervals
/// [start, end) of 0..n, each with how many times it is reached.
fn covered(a: i64, b: i64, n: usize, mode: Wrap) -> Vec<(usize, usize, f64)> {
    let ni = n as i64;
    let len = b - a + 1;
    // Intervals of a periodic axis of `period` indices, folded onto 0..period.
    let periodic = |period: i64| -> Vec<(i64, i64, f64)> {
        let (full, rem, s) = (len / period, len % period, a.rem_euclid(period));
        let mut out = Vec::new();
        if full > 0 {
            out.push((0, period, full as f64));
        }
        if rem > 0 {
            out.push((s, (s + rem).min(period), 1.0));
            if s + rem > period {
                out.push((0, s + rem - period, 1.0));
            }
        }
        out
    };
    let v: Vec<(i64, i64, f64)> = match mode {
        Wrap::Repeat => periodic(ni),
        Wrap::Clamp => {
            let mut out = Vec::new();
            let below = (b.min(-1) - a + 1).max(0);
            let above = (b - a.max(ni) + 1).max(0);
            if below > 0 {
                out.push((0, 1, below as f64));
            }
            if above > 0 {
                out.push((ni - 1, ni, above as f64));
            }
            let (lo, hi) = (a.max(0), b.min(ni - 1));
            if lo <= hi {
                out.push((lo, hi + 1, 1.0));
            }
            out
        }
        // Mirrored repeat: period 2n, the second half read backwards.
        Wrap::Mirror => periodic(2 * ni)
            .into_iter()
            .flat_map(|(s, e, w)| {
                let direct = (s.min(ni), e.min(ni));
                let mirrored = (s.max(ni), e.max(ni));
                [(direct.0, direct.1, w), (2 * ni - mirrored.1, 2 * ni - mirrored.0, w)]
            })
            .filter(|(s, e, _)| s < e)
            .collect(),
    };
    v.into_iter().map(|(s, e, w)| (s as usize, e as usize, w)).collect()
}
