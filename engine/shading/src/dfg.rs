//! The specular term's directional albedo split by Schlick (`shading.md` §3.1, §3.3):
//! `A = ∫(1 − w) D Vis (n·l) dl`, `B = ∫ w D Vis (n·l) dl`, so that a specular lobe of any f0
//! reflects `f0 A + B` of a uniform environment. Integrated by GGX importance sampling of the
//! half vector over a Hammersley set.

use crate::{alpha, hammersley, sample_ggx_half, schlick_weight, vis_smith};
use glam::DVec3;
use rayon::prelude::*;

/// Half vectors per (n·v, r) point: the brief's numbers hold to their tolerances (tests.rs) and
/// the engine's 32² table costs a fraction of a second at start-up (16 384 took 1.5 s).
const SAMPLES: u32 = 1 << 12;

/// `(A, B)` at `n_v` (cosine of the view angle) and perceptual roughness `r`.
pub fn dfg(n_v: f64, r: f64) -> (f64, f64) {
    dfg_with(n_v, r, SAMPLES)
}

fn dfg_with(n_v: f64, r: f64, samples: u32) -> (f64, f64) {
    let n_v = n_v.clamp(1e-4, 1.0);
    let v = DVec3::new((1.0 - n_v * n_v).sqrt(), 0.0, n_v);
    let a = alpha(r);
    let (mut sa, mut sb) = (0.0, 0.0);
    for i in 0..samples {
        let h = sample_ggx_half(hammersley(i, samples), a);
        let v_h = v.dot(h);
        let l = 2.0 * v_h * h - v;
        let (n_l, n_h) = (l.z, h.z);
        if n_l <= 0.0 || v_h <= 0.0 {
            continue;
        }
        // D Vis (n·l) / pdf_l with pdf_l = D (n·h) / (4 v·h).
        let g = vis_smith(n_l, n_v, a) * n_l * 4.0 * v_h / n_h;
        let w = schlick_weight(v_h);
        sa += (1.0 - w) * g;
        sb += w * g;
    }
    (sa / samples as f64, sb / samples as f64)
}

/// What a uniform environment of radiance 1 returns off the specular lobe alone, per f0.
pub fn specular_albedo(f0: f64, n_v: f64, r: f64) -> f64 {
    let (a, b) = dfg(n_v, r);
    f0 * a + b
}

/// A cooked table of `(A, B)`: texel (i, j) holds n·v = i/(size − 1), r = j/(size − 1) (x is
/// n·v, y is roughness), so its first and last texels are the ends of both ranges: a lookup at
/// n·v = 1 or r = 1 (a metal seen head-on, the roughest material) reads the value there, not
/// the one half a texel in (at (i + ½)/size the table's corner is r = 0.984, where a white
/// metal's A + B is 6 % above its 1 − ln 2 at r = 1). The shaders map x to (x (size − 1) + ½)
/// / size for their clamped linear sampler.
#[derive(Debug, Clone, PartialEq)]
pub struct DfgLut {
    pub size: u32,
    /// Row-major, `size * size` pairs.
    pub texels: Vec<[f32; 2]>,
}

impl DfgLut {
    pub fn new(size: u32) -> DfgLut {
        // Texels in parallel: the table is built once a process, at the first scene upload.
        let texels = (0..size * size)
            .into_par_iter()
            .map(|k| {
                let (i, j) = (k % size, k / size);
                let last = (size - 1).max(1) as f64;
                let (a, b) = dfg(i as f64 / last, j as f64 / last);
                // No lobe reflects more than it receives; the quadrature overshoots by up to
                // 0.3 % on sharp lobes at grazing view (column 0 is n·v = 0, taken as 1e-4).
                let k = 1.0 / (a + b).max(1.0);
                [(a * k) as f32, (b * k) as f32]
            })
            .collect();
        DfgLut { size, texels }
    }

    pub fn at(&self, i: u32, j: u32) -> [f32; 2] {
        self.texels[(j * self.size + i) as usize]
    }
}
