//! The baked scene's exposure (textures.md eq. 21.1): k / L with k = 0.18 and L the log-average
//! luminance of the lightmaps' covered texels times an albedo of 0.5. One place for the sum, so
//! the cooker (which stores it in `LightmapLayout::log_average`, from the pages as baked) and
//! the runtime (for a pack without it) agree. Computed before block compression: BC7's noise in
//! a direction's bytes biases |t| upward, which moved the demo level's exposure by about 5 %.

/// Rec. 709 luminance weights.
const LUMINANCE: [f32; 3] = [0.2126, 0.7152, 0.0722];

/// The key value the log-average maps to (middle grey).
pub const KEY: f32 = 0.18;

fn luminance(c: [f32; 3]) -> f32 {
    c[0] * LUMINANCE[0] + c[1] * LUMINANCE[1] + c[2] * LUMINANCE[2]
}

/// The scene's sun as the exposure sees it: the unit direction toward it and its illuminance
/// (colour times lux).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sun {
    pub toward: [f32; 3],
    pub lux: [f32; 3],
}

/// Sum of ln(1e-4 + 0.5 B) over the covered texels (B > 0) of lightmap pages, and their count.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LogAverage {
    pub sum: f64,
    pub count: u64,
}

impl LogAverage {
    /// Add one page: `page` half-float RGBA texels (B, or b0 of a directional page), and for a
    /// directional page its direction texture's RGBA8 texels (128 + 127 t, the sun's visibility
    /// in alpha). A directional texel's B is estimated toward its light's direction, which is near
    /// its surface's normal: b0 (1 + 2 |t|) plus the sun's E cos / pi times its visibility, the
    /// cosine taken to that direction (the pack does not hold the surface normal).
    pub fn add_page(&mut self, page: &[u8], direction: Option<&[u8]>, sun: Option<Sun>) {
        let sun = sun.unwrap_or(Sun { toward: [0.0, 1.0, 0.0], lux: [0.0; 3] });
        let sun_luminance = luminance(sun.lux);
        for (i, px) in page.chunks_exact(8).enumerate() {
            let c: [f32; 3] = std::array::from_fn(|k| half::f16::from_le_bytes([px[2 * k], px[2 * k + 1]]).to_f32());
            let mut lum = luminance(c);
            if let Some(d) = direction.and_then(|d| d.get(4 * i..4 * i + 4)) {
                let t: [f32; 3] = std::array::from_fn(|k| (d[k] as f32 - 128.0) / 127.0);
                let len = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
                let cos = if len > 0.0 { (t[0] * sun.toward[0] + t[1] * sun.toward[1] + t[2] * sun.toward[2]) / len } else { 0.0 };
                let visibility = d[3] as f32 / 255.0;
                lum = lum * (1.0 + 2.0 * len.min(1.0)) + visibility * sun_luminance * cos.max(0.0) / std::f32::consts::PI;
            }
            if lum > 0.0 {
                self.sum += (1e-4 + 0.5 * lum as f64).ln();
                self.count += 1;
            }
        }
    }

    /// L, the log-average (1 when no texel is covered).
    pub fn value(&self) -> f32 {
        if self.count > 0 { (self.sum / self.count as f64).exp() as f32 } else { 1.0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn half_page(values: &[[f32; 3]]) -> Vec<u8> {
        values.iter().flat_map(|c| [c[0], c[1], c[2], 1.0]).flat_map(|v| half::f16::from_f32(v).to_le_bytes()).collect()
    }

    /// Two covered texels of B = 2 and 8 nits and a black one: L = exp(mean ln(1e-4 + 0.5 B)).
    #[test]
    fn irradiance_pages_average_the_logs_of_covered_texels() {
        let mut a = LogAverage::default();
        a.add_page(&half_page(&[[2.0; 3], [8.0; 3], [0.0; 3]]), None, None);
        assert_eq!(a.count, 2);
        let want = (((1e-4f64 + 1.0).ln() + (1e-4f64 + 4.0).ln()) / 2.0).exp() as f32;
        assert!((a.value() - want).abs() < 1e-6, "{} vs {want}", a.value());
    }

    /// A directional texel facing the sun, fully visible: b0 (1 + 2 |t|) + E cos / pi.
    #[test]
    fn directional_texels_add_the_visible_sun_toward_their_direction() {
        let mut a = LogAverage::default();
        let dir = [128u8, 255, 128, 255]; // t = (0, 1, 0), visibility 1
        let sun = Sun { toward: [0.0, 1.0, 0.0], lux: [1000.0; 3] };
        a.add_page(&half_page(&[[1.0; 3]]), Some(&dir), Some(sun));
        let b = 1.0 * 3.0 + 1000.0 / std::f32::consts::PI;
        assert!((a.value() - (1e-4 + 0.5 * b)).abs() < 1e-2, "{}", a.value());
        // In shadow (visibility 0) only b0 (1 + 2 |t|) is left.
        let mut s = LogAverage::default();
        s.add_page(&half_page(&[[1.0; 3]]), Some(&[128, 255, 128, 0]), Some(sun));
        assert!((s.value() - (1e-4 + 1.5)).abs() < 1e-4, "{}", s.value());
    }
}
