//! The lightmap integrator: per surface point, a path-traced estimate of
//!
//!   **B = H / pi**  (nits; H is the irradiance from the hemisphere around the point's normal)
//!
//! — the one quantity the baker stores (notes §1.3): the outgoing radiance a white Lambertian
//! surface would have there, so the runtime shades `L_out = L_e + albedo * B`. Under a uniform
//! sky of radiance L, B = L exactly.
//!
//! Per sample path, at the point and at every bounce vertex:
//! - next-event estimation for each analytic light (sun cone, point, spot, rect) and for one
//!   emissive triangle picked in proportion to area x emitted luminance (its emissive texture's
//!   mean over the triangle), at a uniform point whose real emission is then evaluated (area
//!   sampling moved to solid angle, notes §7.2), with a shadow ray;
//! - a cosine-weighted continuation ray (pdf cos/pi, so a Lambertian vertex multiplies the
//!   throughput by its albedo, notes §7.1). When it hits an emissive triangle or crosses a rect
//!   light, that emission counts with the power-heuristic MIS weight against the light sample, so
//!   emission is counted exactly once; when it escapes it collects the sky (not NEE-sampled: a
//!   uniform sky is best found by cosine sampling, notes §7.3);
//! - Russian roulette on the throughput from bounce `RR_START`, survivors divided by p (unbiased).
//!
//! Materials are read where rays hit (`material`): albedo and emission at the hit point's
//! barycentrics (textures, vertex colours); alpha-tested points (Mask below the cutoff, Blend by
//! hashed alpha) are not there at all: closest-hit and shadow rays pass through them in the BVH
//! walk, and a light sample landing on one contributes nothing.
//!
//! Sides: a ray reaching the **back face of a single-sided material** ends the path with
//! nothing. Such a face is opaque and black: it blocks light (a single-sided wall still casts
//! its shadow), reflects and emits nothing, so the insides of closed meshes stay dark and texels
//! under walls get no light through them. A **double-sided** material's back face is the same
//! surface with the normal flipped: it reflects with its albedo and emits from both sides, and
//! light sampling picks points on it from either side.

use super::bvh::{offset_ray, Ray};
use super::sampling::*;
use super::scene::BakeScene;
use rayon::prelude::*;
use std::f32::consts::FRAC_1_PI;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Roulette starts after this many bounces (the first bounces carry most of the indirect light).
const RR_START: u32 = 2;
/// Points per parallel work item; cancel is checked and progress reported between items.
const CHUNK: usize = 64;
/// Shadow rays stop this fraction short of a light point that lies on geometry.
const SHADOW_SHORTEN: f32 = 1e-4;

#[derive(Clone, Debug, PartialEq)]
pub struct BakeSettings {
    /// Sample paths per point.
    pub samples: u32,
    /// Indirect bounces at most (0: direct light, sky and emitters seen from the point only).
    pub bounces: u32,
    /// Sphere rays per irradiance probe (see `probes`).
    pub probe_samples: u32,
    pub seed: u64,
}

impl BakeSettings {
    /// draft | medium | high. Sample counts follow Godot's low/medium/high rays per texel (32,
    /// 128, 512) and per probe (64, 256, 512; anchors §1.1); bounces 2/3/4 (Godot's default is
    /// 3, Unity's 2).
    pub fn preset(name: &str, seed: u64) -> Option<BakeSettings> {
        let (samples, probe_samples, bounces) = match name {
            "draft" => (32, 64, 2),
            "medium" => (128, 256, 3),
            "high" => (512, 512, 4),
            _ => return None,
        };
        Some(BakeSettings { samples, bounces, probe_samples, seed })
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Baked {
    /// B = H/pi per point (nits, linear RGB).
    pub b: Vec<V3>,
    /// Every ray cast (closest-hit and shadow).
    pub rays: u64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cancelled;

/// Bake B = H/pi at every (point, unit normal). Point i's random streams are keyed by
/// `ids[i]` (default: i), so a point gets the same value whichever batch it is baked in.
/// `progress(points_done, rays_cast)` is called after each chunk of points (from worker threads);
/// setting `cancel` stops the bake between chunks. Runs on the current rayon pool; the result
/// does not depend on its thread count.
#[allow(clippy::too_many_arguments)]
pub fn bake_points(
    scene: &BakeScene,
    points: &[V3],
    normals: &[V3],
    ids: Option<&[u64]>,
    settings: &BakeSettings,
    progress: &(dyn Fn(u64, u64) + Sync),
    cancel: &AtomicBool,
) -> Result<Baked, Cancelled> {
    assert_eq!(points.len(), normals.len(), "one normal per point");
    let (b, rays) = par_bake(points.len(), CHUNK, ids, progress, cancel, |i, id, cast| bake_point(scene, points[i], normals[i], id, settings, cast))?;
    Ok(Baked { b, rays })
}

/// `n` items baked in parallel, `chunk` at a time: `f(i, id, rays)` makes item i, whose random
/// streams are keyed by `ids[i]` (default i), adding the rays it casts. `progress(items done,
/// rays cast)` after each chunk; `cancel` stops between chunks. Returns the items and the rays.
pub(super) fn par_bake<T: Clone + Default + Send>(
    n: usize,
    chunk: usize,
    ids: Option<&[u64]>,
    progress: &(dyn Fn(u64, u64) + Sync),
    cancel: &AtomicBool,
    f: impl Fn(usize, u64, &mut u64) -> T + Sync,
) -> Result<(Vec<T>, u64), Cancelled> {
    assert!(ids.is_none_or(|ids| ids.len() == n), "one id per point");
    let (done, rays) = (AtomicU64::new(0), AtomicU64::new(0));
    let mut out = vec![T::default(); n];
    out.par_chunks_mut(chunk).enumerate().for_each(|(c, dst)| {
        if cancel.load(Ordering::Relaxed) {
            return;
        }
        let mut cast = 0u64;
        for (j, o) in dst.iter_mut().enumerate() {
            let i = c * chunk + j;
            *o = f(i, ids.map_or(i as u64, |ids| ids[i]), &mut cast);
        }
        let d = done.fetch_add(dst.len() as u64, Ordering::Relaxed) + dst.len() as u64;
        let r = rays.fetch_add(cast, Ordering::Relaxed) + cast;
        progress(d, r);
    });
    if cancel.load(Ordering::Relaxed) {
        return Err(Cancelled);
    }
    Ok((out, rays.into_inner()))
}

fn bake_point(scene: &BakeScene, x: V3, n: V3, index: u64, s: &BakeSettings, rays: &mut u64) -> V3 {
    let nl = length(n);
    if !(nl > 0.0) || x.iter().any(|v| !v.is_finite()) {
        return [0.0; 3];
    }
    let n = scale(n, 1.0 / nl);
    let mut sum = [0.0f64; 3];
    for k in 0..s.samples {
        let mut rng = Rng::for_sample(s.seed, index, k as u64);
        let v = sample_path(scene, x, n, s.bounces, &mut rng, rays);
        for c in 0..3 {
            sum[c] += v[c] as f64;
        }
    }
    sum.map(|v| (v / s.samples.max(1) as f64) as f32)
}

/// One estimate of B at x: (direct irradiance)/pi + radiance along one cosine-sampled ray.
pub(super) fn sample_path(scene: &BakeScene, x: V3, n: V3, bounces: u32, rng: &mut Rng, rays: &mut u64) -> V3 {
    let mut b = scale(direct(scene, x, n, rng, rays), FRAC_1_PI);
    let mut thr = [1.0f32; 3];
    let (mut p, mut nrm) = (x, n);
    for depth in 0..=bounces {
        let local = cosine_hemisphere(rng.next_f32(), rng.next_f32());
        let w = to_world(local, nrm);
        let pdf_bsdf = local[2] * FRAC_1_PI;
        let o = offset_ray(p, nrm);
        *rays += 1;
        let hit = scene.closest(&Ray { origin: o, dir: w, tmin: 0.0, tmax: f32::INFINITY });
        let t_hit = hit.map_or(f32::INFINITY, |h| h.t);
        for l in &scene.lights {
            if let Some((t, le, pdf_light)) = l.hit_rect(o, w) {
                if t < t_hit {
                    b = add(b, scale(mul(thr, le), power_heuristic(pdf_bsdf, pdf_light)));
                }
            }
        }
        let Some(h) = hit else {
            if let Some(sky) = scene.sky {
                b = add(b, mul(thr, sky));
            }
            break;
        };
        // A single-sided back face (or a degenerate triangle): nothing arrives, see the module doc.
        let Some(s) = scene.surface(o, w, &h) else { break };
        let pick = scene.emitter_pdf(s.prim);
        if pick > 0.0 {
            let pdf_light = pick * h.t * h.t / s.cos;
            b = add(b, scale(mul(thr, scene.surfaces.emission(s.prim, s.bary)), power_heuristic(pdf_bsdf, pdf_light)));
        }
        if depth == bounces {
            break;
        }
        thr = mul(thr, scene.surfaces.shade(s.prim, s.bary).albedo);
        if depth + 1 >= RR_START {
            let q = thr[0].max(thr[1]).max(thr[2]).clamp(0.05, 0.95);
            if rng.next_f32() >= q {
                break;
            }
            thr = scale(thr, 1.0 / q);
        }
        if thr == [0.0; 3] {
            break;
        }
        (p, nrm) = (s.p, s.n);
        b = add(b, scale(mul(thr, direct(scene, p, nrm, rng, rays)), FRAC_1_PI));
    }
    b
}

/// Next-event estimate of the irradiance H at (x, n) from every analytic light and one emissive
/// triangle, area lights MIS-weighted against cosine sampling. Always draws the same number of
/// random numbers, so later dimensions of a path stay aligned whatever is hit.
pub(super) fn direct(scene: &BakeScene, x: V3, n: V3, rng: &mut Rng, rays: &mut u64) -> V3 {
    let o = offset_ray(x, n);
    let mut h = [0.0f32; 3];
    for l in &scene.lights {
        let (u1, u2) = (rng.next_f32(), rng.next_f32());
        let Some(s) = l.sample(x, n, u1, u2) else { continue };
        let w = s.pdf.map_or(1.0, |pl| power_heuristic(pl, dot(n, s.dir) * FRAC_1_PI));
        *rays += 1;
        let tmax = if s.dist.is_finite() { s.dist * (1.0 - SHADOW_SHORTEN) } else { f32::INFINITY };
        if !scene.occluded(&Ray { origin: o, dir: s.dir, tmin: 0.0, tmax }) {
            h = add(h, scale(s.h, w));
        }
    }
    if scene.has_emitters() {
        let (u0, u1, u2) = (rng.next_f32(), rng.next_f32(), rng.next_f32());
        let prim = scene.pick_emitter(u0);
        let [a, bb, c] = scene.tris[prim];
        let (beta, gamma) = uniform_triangle(u1, u2);
        let q = add(a, add(scale(sub(bb, a), beta), scale(sub(c, a), gamma)));
        let d = sub(q, x);
        let r2 = dot(d, d);
        let r = r2.sqrt();
        let w = scale(d, 1.0 / r);
        let cos_i = dot(n, w);
        // The emitting side faces x: the front, or either side of a double-sided material.
        let cos_front = -dot(scene.normals[prim], w);
        let cos_l = if scene.surfaces.material(prim).double_sided { cos_front.abs() } else { cos_front };
        if cos_i > 0.0 && cos_l > 0.0 && r > 0.0 {
            let bary = [1.0 - beta - gamma, beta, gamma];
            let le = scene.surfaces.emission(prim, bary);
            // A black texel or a cut-out point sends nothing: no shadow ray needed.
            if le != [0.0; 3] && scene.surfaces.present(prim, q, bary) {
                let pdf_light = scene.emitter_pdf(prim) * r2 / cos_l;
                let mis = power_heuristic(pdf_light, cos_i * FRAC_1_PI);
                *rays += 1;
                if !scene.occluded(&Ray { origin: o, dir: w, tmin: 0.0, tmax: r * (1.0 - SHADOW_SHORTEN) }) {
                    h = add(h, scale(le, cos_i / pdf_light * mis));
                }
            }
        }
    }
    h
}
