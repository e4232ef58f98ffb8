//! Directional lightmaps' L1 spherical harmonics (`../shared/notes/shading.md` §4), in the
//! engine's lightmap units: `B(n) = E(n)/π = b0 + b1·n` (nits), where
//! `b0 = (1/4π)∮L dω` (the mean radiance over the sphere) and `b1 = (1/2π)∮L ω dω` (x, y, z).
//! One definition for the baker (estimating b0 and b1 from samples), the runtime's shaders
//! (tested against it) and the tests.
//!
//! Reconstruction: `linear` (may go negative behind a single strong direction), `clamped`
//! (the brief's recommendation when the sun is not in the lightmap: exact for a hemisphere sky)
//! and `geomerics` (never negative, mean b0, exact at the peak of a single direction).

use glam::DVec3;
use std::f64::consts::PI;

/// `Y₀₀ = 1/(2√π)`.
pub const Y00: f64 = 0.282_094_791_773_878_1;
/// `Y₁ₘ = √(3/4π)·{y, z, x}`.
pub const Y1: f64 = 0.488_602_511_902_919_9;

/// One channel's L1 irradiance (or luminance's), `B(n) = b0 + b1·n`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct L1 {
    pub b0: f64,
    pub b1: DVec3,
}

impl L1 {
    /// A delta light (a sun) of perpendicular illuminance `e` (lux) from the unit direction
    /// `d`: `E/4π` into b0, `E d/2π` into b1.
    pub fn delta(e: f64, d: DVec3) -> L1 {
        L1 { b0: e / (4.0 * PI), b1: d * (e / (2.0 * PI)) }
    }

    /// From radiance SH coefficients `[L₀₀, L₁,₋₁, L₁,₀, L₁,₁]` (`L_lm = ∮L Y_lm dω`): the
    /// cosine lobe's convolution (Â₀ = π, Â₁ = 2π/3) divided by π.
    pub fn from_radiance_sh(l: [f64; 4]) -> L1 {
        L1 { b0: Y00 * l[0], b1: DVec3::new(l[3], l[1], l[2]) * (2.0 / 3.0 * Y1) }
    }

    /// Radiance SH `[L₀₀, L₁,₋₁, L₁,₀, L₁,₁]` of a delta light of illuminance `e` from `d`.
    pub fn radiance_sh_of_delta(e: f64, d: DVec3) -> [f64; 4] {
        [e * Y00, e * Y1 * d.y, e * Y1 * d.z, e * Y1 * d.x]
    }

    /// One sample's share of a Monte Carlo estimate: radiance `l` arriving from the unit
    /// direction `w`, drawn with density `pdf` (per steradian), out of `n` samples.
    pub fn sample(l: f64, w: DVec3, pdf: f64, n: f64) -> L1 {
        let k = l / (pdf * n);
        L1 { b0: k / (4.0 * PI), b1: w * (k / (2.0 * PI)) }
    }

    pub fn add(self, o: L1) -> L1 {
        L1 { b0: self.b0 + o.b0, b1: self.b1 + o.b1 }
    }

    /// `b0 + b1·n`: negative behind a strong single direction (δ > ½).
    pub fn linear(&self, n: DVec3) -> f64 {
        self.b0 + self.b1.dot(n)
    }

    /// `max(0, b0 + b1·n)`.
    pub fn clamped(&self, n: DVec3) -> f64 {
        self.linear(n).max(0.0)
    }

    /// Directionality `δ = |b1| / (2 b0)`: 0 uniform, ½ a uniform hemisphere, 1 one direction
    /// (non-negative radiance keeps it within [0, 1]).
    pub fn directionality(&self) -> f64 {
        if self.b0 > 0.0 {
            self.b1.length() / (2.0 * self.b0)
        } else {
            0.0
        }
    }

    /// Geomerics' non-linear reconstruction (Hazel 2017): never negative, its mean over the
    /// sphere is b0, and for one direction (δ = 1) it is exact at the peak.
    pub fn geomerics(&self, n: DVec3) -> f64 {
        if self.b0 <= 0.0 {
            return 0.0;
        }
        let delta = self.directionality().min(1.0);
        if delta < 1e-6 {
            return self.b0;
        }
        let q = ((1.0 + n.dot(self.b1.normalize())) * 0.5).clamp(0.0, 1.0);
        let p = 1.0 + 2.0 * delta;
        let a = (1.0 - delta) / (1.0 + delta);
        self.b0 * (a + (1.0 - a) * (p + 1.0) * q.powf(p))
    }

    /// The light as an ambient part plus one direction, whose SH is exactly (b0, b1): the unit
    /// direction, its perpendicular illuminance `2π|b1|` (lux) and the ambient `b0 − |b1|/2`
    /// (nits). None without a direction.
    pub fn dominant(&self) -> Option<(DVec3, f64, f64)> {
        let len = self.b1.length();
        (len > 0.0).then(|| (self.b1 / len, 2.0 * PI * len, self.b0 - 0.5 * len))
    }
}

/// Luminance weights of linear Rec. 709 RGB (`textures.md` §4.2).
pub const LUMINANCE: DVec3 = DVec3::new(0.2126, 0.7152, 0.0722);

/// "MonoSH": an RGB b0 and one direction shared by the channels, the luminance's
/// `t = b1_Y / (2 b0_Y)` (|t| ≤ 1), so `B_c(n) = b0_c (1 + 2 t·n)`. What the runtime stores and
/// evaluates (clamped at 0): half the memory of RGB L1, losing only colour that differs by
/// direction.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MonoSh {
    pub b0: DVec3,
    pub t: DVec3,
}

impl MonoSh {
    /// From the three channels' L1.
    pub fn from_rgb(c: [L1; 3]) -> MonoSh {
        let b0 = DVec3::new(c[0].b0, c[1].b0, c[2].b0);
        let b0_y = b0.dot(LUMINANCE);
        let b1_y = c[0].b1 * LUMINANCE.x + c[1].b1 * LUMINANCE.y + c[2].b1 * LUMINANCE.z;
        let t = if b0_y > 0.0 { b1_y / (2.0 * b0_y) } else { DVec3::ZERO };
        // Non-negative radiance keeps |t| ≤ 1; noise may not.
        let len = t.length();
        MonoSh { b0, t: if len > 1.0 { t / len } else { t } }
    }

    /// `max(0, b0_c (1 + 2 t·n))` per channel.
    pub fn eval(&self, n: DVec3) -> DVec3 {
        self.b0 * (1.0 + 2.0 * self.t.dot(n)).max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(got: f64, want: f64, tol: f64, what: &str) {
        assert!((got - want).abs() <= tol, "{what}: got {got}, want {want} ± {tol}");
    }

    /// The unit normal tilted by `deg` from +Y toward +X.
    fn tilted(deg: f64) -> DVec3 {
        let t = deg.to_radians();
        DVec3::new(t.sin(), t.cos(), 0.0)
    }

    /// Points spread evenly over the unit sphere (a Fibonacci lattice), each standing for 4π/n sr.
    fn sphere(n: usize) -> impl Iterator<Item = DVec3> {
        let golden = PI * (3.0 - 5f64.sqrt());
        (0..n).map(move |i| {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - y * y).sqrt();
            let phi = golden * i as f64;
            DVec3::new(r * phi.cos(), y, r * phi.sin())
        })
    }

    const THETAS: [f64; 6] = [0.0, 30.0, 60.0, 90.0, 120.0, 180.0];

    #[test]
    fn a_suns_l1_is_the_briefs() {
        // shading.md §6d: E = 100 000 lux from +Y.
        let e = 100_000.0;
        let sh = L1::radiance_sh_of_delta(e, DVec3::Y);
        close(sh[0], 28_209.48, 0.01, "L00");
        close(sh[1], 48_860.25, 0.01, "L1-1");
        assert_eq!((sh[2], sh[3]), (0.0, 0.0));
        let l1 = L1::from_radiance_sh(sh);
        assert!((l1.b0 - L1::delta(e, DVec3::Y).b0).abs() < 1e-9 && (l1.b1 - L1::delta(e, DVec3::Y).b1).length() < 1e-9);
        close(l1.b0, 7957.75, 0.005, "b0");
        close(l1.b1.y, 15_915.49, 0.005, "b1.y");
        close(l1.directionality(), 1.0, 1e-12, "delta");
        // Irradiance (lux, = pi B) at normals tilted by theta: the table's columns.
        let linear = [75_000.0, 68_301.0, 50_000.0, 25_000.0, 0.0, -25_000.0];
        let geomerics = [100_000.0, 81_220.0, 42_188.0, 12_500.0, 1_563.0, 0.0];
        for (k, deg) in THETAS.into_iter().enumerate() {
            let n = tilted(deg);
            close(PI * l1.linear(n), linear[k], 0.5, &format!("linear at {deg}"));
            close(PI * l1.clamped(n), linear[k].max(0.0), 0.5, &format!("clamped at {deg}"));
            close(PI * l1.geomerics(n), geomerics[k], 0.6, &format!("geomerics at {deg}"));
        }
        let (d, e_dir, _) = l1.dominant().unwrap();
        close(e_dir, e, 1e-6, "E_dir");
        assert!((d - DVec3::Y).length() < 1e-12);
    }

    #[test]
    fn a_uniform_hemisphere_is_exact_when_clamped_linear() {
        // L = 1000 nits over the upper hemisphere: b0 = 500, b1 = (0, 500, 0), integrated
        // numerically (1e6 points of the sphere, each 4 pi / n sr).
        let n = 1_000_000;
        let l1 = sphere(n).filter(|w| w.y > 0.0).fold(L1::default(), |acc, w| acc.add(L1::sample(1000.0, w, 1.0 / (4.0 * PI), n as f64)));
        close(l1.b0, 500.0, 0.05, "b0");
        close(l1.b1.y, 500.0, 0.05, "b1.y");
        assert!(l1.b1.x.abs() < 0.05 && l1.b1.z.abs() < 0.05, "b1 {:?}", l1.b1);
        let exact = L1 { b0: 500.0, b1: DVec3::new(0.0, 500.0, 0.0) };
        let linear = [1000.0, 933.01, 750.0, 500.0, 250.0, 0.0];
        let geomerics = [1166.67, 1037.18, 729.17, 416.67, 229.17, 166.67];
        for (k, deg) in THETAS.into_iter().enumerate() {
            let n = tilted(deg);
            close(exact.clamped(n), linear[k], 0.005, &format!("clamped at {deg}"));
            // The exact irradiance of the hemisphere, L (1 + cos)/2.
            close(exact.clamped(n), 1000.0 * (1.0 + deg.to_radians().cos()) / 2.0, 1e-9, "closed form");
            close(exact.geomerics(n), geomerics[k], 0.005, &format!("geomerics at {deg}"));
        }
        close(exact.directionality(), 0.5, 1e-12, "delta");
        let (d, e_dir, ambient) = exact.dominant().unwrap();
        close(e_dir, 3141.59, 0.005, "E_dir");
        close(ambient, 250.0, 1e-9, "ambient");
        assert_eq!(d, DVec3::Y);
    }

    #[test]
    fn the_axes_are_in_x_y_z_order() {
        // §6d's ordering test: a sun from (1, 2, 2)/3.
        let d = DVec3::new(1.0, 2.0, 2.0) / 3.0;
        let sh = L1::radiance_sh_of_delta(100_000.0, d);
        close(sh[1], 32_573.50, 0.01, "L1-1");
        close(sh[2], 32_573.50, 0.01, "L10");
        close(sh[3], 16_286.75, 0.01, "L11");
        let l1 = L1::from_radiance_sh(sh);
        close(l1.b1.x, 5305.16, 0.01, "b1.x");
        close(l1.b1.y, 10_610.33, 0.01, "b1.y");
        close(l1.b1.z, 10_610.33, 0.01, "b1.z");
        close(l1.linear(DVec3::Y), 18_568.08, 0.01, "B(+Y)");
    }

    #[test]
    fn geomerics_is_never_negative_and_keeps_the_mean() {
        for delta in [0.0, 0.1, 0.25, 0.5, 0.75, 0.9, 1.0] {
            let l1 = L1 { b0: 3.0, b1: DVec3::new(1.0, -2.0, 0.5).normalize() * (2.0 * 3.0 * delta) };
            let n = 200_000;
            let (mut mean, mut min_g, mut min_c) = (0.0, f64::INFINITY, f64::INFINITY);
            for w in sphere(n) {
                let g = l1.geomerics(w);
                mean += g / n as f64;
                min_g = min_g.min(g);
                min_c = min_c.min(l1.clamped(w));
            }
            assert!(min_g >= 0.0 && min_c >= 0.0, "delta {delta}: negative ({min_g}, {min_c})");
            close(mean, 3.0, 3e-3, &format!("geomerics' mean at delta {delta}"));
        }
    }

    #[test]
    fn mono_sh_keeps_rgb_b0_and_the_luminance_direction() {
        // A grey hemisphere sky and a red sun from +X: each channel's b0 is kept; the direction
        // is the luminance's.
        let sky = L1 { b0: 500.0, b1: DVec3::new(0.0, 500.0, 0.0) };
        let sun = L1::delta(1000.0, DVec3::X);
        let rgb = [sky.add(sun), sky, sky];
        let m = MonoSh::from_rgb(rgb);
        assert_eq!(m.b0, DVec3::new(rgb[0].b0, 500.0, 500.0));
        let b0_y = m.b0.dot(LUMINANCE);
        let b1_y = rgb[0].b1 * LUMINANCE.x + sky.b1 * (LUMINANCE.y + LUMINANCE.z);
        assert!((m.t - b1_y / (2.0 * b0_y)).length() < 1e-12);
        // A grey input is reproduced exactly.
        let grey = MonoSh::from_rgb([sky; 3]);
        for deg in THETAS {
            let n = tilted(deg);
            assert!((grey.eval(n) - DVec3::splat(sky.clamped(n))).abs().max_element() < 1e-9, "at {deg}");
        }
        // Never negative, |t| <= 1 even from noisy input.
        let noisy = MonoSh::from_rgb([L1 { b0: 1.0, b1: DVec3::new(0.0, 5.0, 0.0) }; 3]);
        assert!(noisy.t.length() <= 1.0 + 1e-12 && noisy.eval(-DVec3::Y).min_element() >= 0.0);
    }
}
