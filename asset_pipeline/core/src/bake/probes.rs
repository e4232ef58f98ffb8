//! Irradiance probes for dynamic objects: at points in the level's open space, the light arriving
//! from every direction, as order-2 spherical harmonics (9 coefficients per colour channel).
//!
//! What a probe holds, and what it leaves to the runtime:
//! - **SH of B(n) = E(n)/pi** (nits), already convolved with the clamped cosine (Ramamoorthi &
//!   Hanrahan 2001: band factors pi, 2pi/3, pi/4, divided by pi), so the runtime evaluates
//!   `B(n) = sum_i c_i Y_i(n)` and shades a diffuse surface `albedo * B(n)`, exactly as it shades
//!   a lightmapped one with the lightmap's B. The basis: real SH, order Y00, Y1-1 (y), Y10 (z),
//!   Y11 (x), Y2-2 (xy), Y2-1 (yz), Y20 (3z^2-1), Y21 (xz), Y22 (x^2-y^2), in world axes.
//! - everything but the **sun's direct light**: the sky, emissive surfaces, point, spot and rect
//!   lights (next-event estimation: each light sampled from the probe and added as a directional
//!   delta, with a shadow ray), and all indirect light including the sun's bounce (uniform
//!   sphere rays: the radiance each brings back is the emission it hits plus albedo x B there,
//!   estimated by the lightmap integrator's own path). The sun's direct light is left to the
//!   runtime, which has the surface's own normal and adds it sharply, scaled by the probe's
//!   **sun visibility** (the fraction of shadow rays to the sun's disk that escape; 1 with no sun).
//! - the **back-face fraction**: the share of probe rays whose first hit is the back face of a
//!   single-sided material (a double-sided one's back is a surface like its front). A probe
//!   inside a wall sees mostly back faces; the cooker replaces such probes by their neighbours.
//!
//! Deterministic like the lightmaps: probe i's random streams are keyed by (seed, `ids[i]`, sample).

use super::bvh::{Hit, Ray};
use super::integrator::{direct, par_bake, sample_path, BakeSettings, Cancelled};
use super::light_set::{light_numbers, LightSet};
use super::lights::Light;
use super::sampling::*;
use super::scene::BakeScene;
use std::f32::consts::{FRAC_1_PI, PI};
use std::sync::atomic::AtomicBool;

/// Shadow rays stop this fraction short of a light point (as the integrator's).
const SHADOW_SHORTEN: f32 = 1e-4;
/// Keys the probes' random streams apart from the lightmap texels' (which use the same seed).
const PROBE_STREAM: u64 = 0x5052_4F42_4500_0000;

/// The 9 real SH basis functions at unit direction d (order in the module doc).
pub fn sh9(d: V3) -> [f32; 9] {
    let [x, y, z] = d;
    [
        0.282_094_8,
        0.488_602_5 * y,
        0.488_602_5 * z,
        0.488_602_5 * x,
        1.092_548_4 * x * y,
        1.092_548_4 * y * z,
        0.315_391_57 * (3.0 * z * z - 1.0),
        1.092_548_4 * x * z,
        0.546_274_2 * (x * x - y * y),
    ]
}

/// Clamped-cosine convolution per coefficient, divided by pi: B = E/pi from radiance SH.
const BAND: [f32; 9] = [1.0, 2.0 / 3.0, 2.0 / 3.0, 2.0 / 3.0, 0.25, 0.25, 0.25, 0.25, 0.25];

/// Evaluate stored probe coefficients (B SH) at unit direction n.
pub fn eval_sh9(c: &[V3; 9], n: V3) -> V3 {
    let y = sh9(n);
    let mut out = [0.0; 3];
    for i in 0..9 {
        out = add(out, scale(c[i], y[i]));
    }
    out
}

#[derive(Clone, Debug, Default, PartialEq)]
pub struct Probe {
    /// SH coefficients of B(n) = E(n)/pi, RGB, without the sun's direct light.
    pub sh: [V3; 9],
    /// Fraction of the sun's disk visible (1 when the scene has no sun).
    pub sun_visibility: f32,
    /// Fraction of probe rays that first hit a back face (inside geometry when large).
    pub backface: f32,
}

/// Bake a probe at every point, with `settings.probe_samples` sphere rays each (and as many light
/// samples per light). Runs on the current rayon pool; progress and cancel as `bake_points`.
pub fn bake_probes(
    scene: &BakeScene,
    points: &[V3],
    ids: Option<&[u64]>,
    settings: &BakeSettings,
    progress: &(dyn Fn(u64, u64) + Sync),
    cancel: &AtomicBool,
) -> Result<(Vec<Probe>, u64), Cancelled> {
    // Probes are slow (hundreds of rays each): small chunks keep progress and cancel prompt.
    par_bake(points.len(), 4, ids, progress, cancel, |i, id, cast| bake_probe(scene, points[i], PROBE_STREAM ^ id, settings, cast))
}

fn bake_probe(scene: &BakeScene, x: V3, id: u64, s: &BakeSettings, rays: &mut u64) -> Probe {
    let n = s.probe_samples.max(1);
    let mut sh = [[0.0f64; 3]; 9];
    let mut backface = 0u32;
    let (mut sun_seen, mut sun_tried) = (0u32, 0u32);
    let add_delta = |sh: &mut [[f64; 3]; 9], w: V3, l: V3, weight: f32| {
        let y = sh9(w);
        for i in 0..9 {
            for c in 0..3 {
                sh[i][c] += (l[c] * y[i] * weight) as f64;
            }
        }
    };
    for k in 0..n {
        let mut rng = Rng::for_sample(s.seed, id, k as u64);
        // Analytic lights: one sample each, a delta of its irradiance at normal incidence.
        let key = LightSet::key(&mut rng);
        scene.lights.near(x, |i, light| {
            let (u1, u2) = light_numbers(key, i);
            let toward = match *light {
                Light::Sun { dir, .. } => scale(dir, -1.0),
                Light::Point { pos, .. } | Light::Spot { pos, .. } => normalize(sub(pos, x)),
                Light::Rect { c, .. } => normalize(sub(c, x)),
            };
            let Some(ls) = light.sample(x, toward, u1, u2) else { return };
            let tmax = if ls.dist.is_finite() { ls.dist * (1.0 - SHADOW_SHORTEN) } else { f32::INFINITY };
            *rays += 1;
            let visible = !scene.occluded(&Ray { origin: x, dir: ls.dir, tmin: 0.0, tmax });
            if let Light::Sun { .. } = light {
                sun_tried += 1;
                sun_seen += visible as u32;
            } else if visible {
                // sample() scaled the light's irradiance by cos(toward, dir): undo it.
                add_delta(&mut sh, ls.dir, ls.h, 1.0 / dot(toward, ls.dir) / n as f32);
            }
        });
        // One uniform sphere ray: the radiance coming back along it (Monte Carlo weight 4 pi / N).
        let w = uniform_cone(rng.next_f32(), rng.next_f32(), -1.0);
        let (l, back) = incoming(scene, x, w, s.bounces, &mut rng, rays);
        backface += back as u32;
        add_delta(&mut sh, w, l, 4.0 * PI / n as f32);
    }
    Probe {
        sh: std::array::from_fn(|i| sh[i].map(|v| (v * BAND[i] as f64) as f32)),
        sun_visibility: if sun_tried > 0 { sun_seen as f32 / sun_tried as f32 } else { 1.0 },
        backface: backface as f32 / n as f32,
    }
}

/// Radiance arriving at x from direction w (travelling along -w), leaving out analytic lights
/// (sampled separately): the sky on a miss; on a surface (a front face, or either face of a
/// double-sided material) its emission plus albedo x B there (B with `bounces - 1` further
/// bounces, or direct light only at 0). Also: was it a single-sided back face.
fn incoming(scene: &BakeScene, x: V3, w: V3, bounces: u32, rng: &mut Rng, rays: &mut u64) -> (V3, bool) {
    *rays += 1;
    let Some(h) = scene.closest(&Ray { origin: x, dir: w, tmin: 0.0, tmax: f32::INFINITY }) else {
        return (scene.sky.unwrap_or([0.0; 3]), false);
    };
    match leaving(scene, x, w, &h, bounces, rng, rays) {
        Some(l) => (l, false),
        None => ([0.0; 3], true),
    }
}

/// The radiance leaving the surface that the ray from x along unit w reached at `h`, back
/// toward x: its emission plus albedo x B there (B with `bounces - 1` further bounces, or
/// direct light only at 0). None on a single-sided material's back face (opaque and black).
/// Shared with the reflection probes' capture.
pub(super) fn leaving(scene: &BakeScene, x: V3, w: V3, h: &Hit, bounces: u32, rng: &mut Rng, rays: &mut u64) -> Option<V3> {
    let s = scene.surface(x, w, h)?;
    let b = if bounces == 0 { scale(direct(scene, s.p, s.n, rng, rays, None), FRAC_1_PI) } else { sample_path(scene, s.p, s.n, bounces - 1, rng, rays, None) };
    let shade = scene.surfaces.shade(s.prim, s.bary);
    Some(add(shade.emission, mul(shade.albedo, b)))
}
