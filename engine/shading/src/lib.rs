//! The material model (glTF 2.0 metallic-roughness, `../shared/notes/shading.md` §2.2) on the
//! CPU, in f64: one definition that the engine's shaders are tested against and that the
//! cooker bakes tables from.
//!
//! - `D`: Trowbridge-Reitz (GGX), `α = r²`, `r` clamped to `MIN_ROUGHNESS`.
//! - `Vis`: height-correlated Smith, `G / (4 |n·l| |n·v|)`.
//! - `F`: Schlick, `f0 = mix(0.04, base, metallic)`.
//! - diffuse `(1 − m)(1 − F_d(v·h)) base / π`, the spec's `fresnel_mix` after glTF PR #2392.

use glam::DVec3;
use std::f64::consts::PI;

mod dfg;
mod dfg_table;
pub mod sh;
pub use dfg::{dfg, specular_albedo, DfgLut, DFG_TABLE_SIZE};

/// Filament's fp16-safe floor on perceptual roughness (α ≥ 0.002): α = 0 is singular.
pub const MIN_ROUGHNESS: f64 = 0.045;
/// Normal-incidence reflectance of a dielectric of index 1.5.
pub const DIELECTRIC_F0: f64 = 0.04;

/// `α` of a perceptual roughness, clamped as the shaders clamp it.
pub fn alpha(roughness: f64) -> f64 {
    let r = roughness.clamp(MIN_ROUGHNESS, 1.0);
    r * r
}

/// GGX normal distribution at `n·h` (zero below the horizon).
pub fn d_ggx(n_h: f64, alpha: f64) -> f64 {
    if n_h <= 0.0 {
        return 0.0;
    }
    let a2 = alpha * alpha;
    let d = n_h * n_h * (a2 - 1.0) + 1.0;
    a2 / (PI * d * d)
}

/// Height-correlated Smith visibility `G / (4 |n·l| |n·v|)`.
pub fn vis_smith(n_l: f64, n_v: f64, alpha: f64) -> f64 {
    let a2 = alpha * alpha;
    let (nl, nv) = (n_l.abs(), n_v.abs());
    let gv = nl * (a2 + (1.0 - a2) * nv * nv).sqrt();
    let gl = nv * (a2 + (1.0 - a2) * nl * nl).sqrt();
    let s = gv + gl;
    if s > 0.0 {
        0.5 / s
    } else {
        0.0
    }
}

/// Schlick's Fresnel weight `(1 − |v·h|)^5`: F = f0 + (1 − f0) w.
pub fn schlick_weight(v_h: f64) -> f64 {
    (1.0 - v_h.abs()).clamp(0.0, 1.0).powi(5)
}

/// A surface as glTF describes it: linear base colour, metallic, perceptual roughness.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    pub base: DVec3,
    pub metallic: f64,
    pub roughness: f64,
}

impl Material {
    pub fn dielectric(base: f64, roughness: f64) -> Material {
        Material { base: DVec3::splat(base), metallic: 0.0, roughness }
    }

    pub fn metal(base: f64, roughness: f64) -> Material {
        Material { base: DVec3::splat(base), metallic: 1.0, roughness }
    }

    pub fn f0(&self) -> DVec3 {
        DVec3::splat(DIELECTRIC_F0).lerp(self.base, self.metallic.clamp(0.0, 1.0))
    }

    /// The BRDF split in its two parts, per channel, in sr⁻¹; unit `n`, `v`, `l` pointing away
    /// from the surface. Zero when either direction is below the surface.
    pub fn brdf_parts(&self, n: DVec3, v: DVec3, l: DVec3) -> (DVec3, DVec3) {
        let (n_l, n_v) = (n.dot(l), n.dot(v));
        if n_l <= 0.0 || n_v <= 0.0 {
            return (DVec3::ZERO, DVec3::ZERO);
        }
        let h = (v + l).normalize();
        let a = alpha(self.roughness);
        let w = schlick_weight(v.dot(h));
        let f = self.f0() + (DVec3::ONE - self.f0()) * w;
        let specular = f * d_ggx(n.dot(h), a) * vis_smith(n_l, n_v, a);
        let f_d = DIELECTRIC_F0 + (1.0 - DIELECTRIC_F0) * w;
        let diffuse = self.base * ((1.0 - self.metallic) * (1.0 - f_d) / PI);
        (diffuse, specular)
    }

    /// The whole BRDF, sr⁻¹.
    pub fn brdf(&self, n: DVec3, v: DVec3, l: DVec3) -> DVec3 {
        let (d, s) = self.brdf_parts(n, v, l);
        d + s
    }

    /// Radiance (nits) reflected toward `v` from a sun of perpendicular illuminance `lux`
    /// arriving from `l`.
    pub fn sunlit(&self, n: DVec3, v: DVec3, l: DVec3, lux: f64) -> DVec3 {
        self.brdf(n, v, l) * lux * n.dot(l).max(0.0)
    }
}

/// The i-th of n points of the Hammersley set in [0, 1)²: a deterministic low-discrepancy
/// quadrature (the tables are cooked, not sampled at random).
pub fn hammersley(i: u32, n: u32) -> (f64, f64) {
    ((i as f64 + 0.5) / n as f64, i.reverse_bits() as f64 / 4_294_967_296.0)
}

/// A GGX half vector about +Z for the point `xi` (pdf `D(n·h)(n·h)` over solid angle).
pub fn sample_ggx_half(xi: (f64, f64), alpha: f64) -> DVec3 {
    let a2 = alpha * alpha;
    let cos_t = ((1.0 - xi.0) / (1.0 + (a2 - 1.0) * xi.0)).sqrt();
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let phi = 2.0 * PI * xi.1;
    DVec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
}

#[cfg(test)]
mod tests;
