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
//!   emissive triangle picked in proportion to area x luminance (area sampling moved to solid
//!   angle, notes §7.2), with a shadow ray;
//! - a cosine-weighted continuation ray (pdf cos/pi, so a Lambertian vertex multiplies the
//!   throughput by its albedo, notes §7.1). When it hits an emissive triangle or crosses a rect
//!   light, that emission counts with the power-heuristic MIS weight against the light sample, so
//!   emission is counted exactly once; when it escapes it collects the sky (not NEE-sampled: a
//!   uniform sky is best found by cosine sampling, notes §7.3);
//! - Russian roulette on the throughput from bounce `RR_START`, survivors divided by p (unbiased).
//! A ray hitting a back face ends the path with nothing (it is inside geometry), so texels under
//! walls stay dark.

use super::bvh::{offset_ray, Bvh, Ray};
use super::lights::Light;
use super::sampling::*;
use rayon::prelude::*;
use std::f32::consts::FRAC_1_PI;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Roulette starts after this many bounces (the first bounces carry most of the indirect light).
const RR_START: u32 = 2;
/// Points per parallel work item; cancel is checked and progress reported between items.
const CHUNK: usize = 64;
/// Shadow rays stop this fraction short of a light point that lies on geometry.
const SHADOW_SHORTEN: f32 = 1e-4;

pub struct BakeScene {
    pub(super) bvh: Bvh,
    tris: Vec<[V3; 3]>,
    /// Unit geometric normal (b-a)x(c-a) of each triangle: its front side.
    pub(super) normals: Vec<V3>,
    pub(super) albedo: Vec<V3>,
    pub(super) emission: Vec<V3>,
    /// Emissive triangles and the cumulative distribution that picks them (area x luminance).
    emitters: Vec<u32>,
    emitter_cdf: Vec<f32>,
    /// Per triangle: probability of picking it / its area (the area pdf of emitter sampling).
    emitter_pdf: Vec<f32>,
    pub(super) lights: Vec<Light>,
    pub(super) sky: Option<V3>,
}

fn luminance(c: V3) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

impl BakeScene {
    /// `albedo` and `emission` (nits, front face only) are per triangle; `sky` is a uniform
    /// radiance (nits) or None for no sky.
    pub fn new(
        positions: &[V3],
        triangles: &[[u32; 3]],
        albedo: &[V3],
        emission: &[V3],
        lights: Vec<Light>,
        sky: Option<V3>,
    ) -> Result<BakeScene, String> {
        let m = triangles.len();
        if albedo.len() != m || emission.len() != m {
            return Err(format!("{m} triangles but {} albedo and {} emission rows", albedo.len(), emission.len()));
        }
        if let Some(i) = triangles.iter().position(|t| t.iter().any(|&v| v as usize >= positions.len())) {
            return Err(format!("triangle {i} indexes a vertex past the {} positions", positions.len()));
        }
        let tris: Vec<[V3; 3]> = triangles.iter().map(|t| t.map(|v| positions[v as usize])).collect();
        let mut normals = Vec::with_capacity(m);
        let mut areas = Vec::with_capacity(m);
        for t in &tris {
            let c = cross(sub(t[1], t[0]), sub(t[2], t[0]));
            let l = length(c);
            normals.push(if l > 0.0 { scale(c, 1.0 / l) } else { [0.0; 3] });
            areas.push(0.5 * l);
        }
        let weight = |i: usize| areas[i] * luminance(emission[i]).max(0.0);
        let emitters: Vec<u32> = (0..m).filter(|&i| weight(i) > 0.0 && weight(i).is_finite()).map(|i| i as u32).collect();
        let mut acc = 0.0f64;
        let mut emitter_cdf: Vec<f32> = emitters
            .iter()
            .map(|&i| {
                acc += weight(i as usize) as f64;
                acc as f32
            })
            .collect();
        let total = acc as f32;
        emitter_cdf.iter_mut().for_each(|c| *c /= total);
        let mut emitter_pdf = vec![0.0; m];
        for &i in &emitters {
            let i = i as usize;
            emitter_pdf[i] = weight(i) / total / areas[i];
        }
        let clamp01 = |c: &V3| c.map(|x| if x.is_finite() { x.clamp(0.0, 1.0) } else { 0.0 });
        Ok(BakeScene {
            bvh: Bvh::build(positions, triangles),
            tris,
            normals,
            albedo: albedo.iter().map(clamp01).collect(),
            emission: emission.to_vec(),
            emitters,
            emitter_cdf,
            emitter_pdf,
            lights,
            sky,
        })
    }

    pub fn bvh(&self) -> &Bvh {
        &self.bvh
    }
}

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
        let hit = scene.bvh.closest(&Ray { origin: o, dir: w, tmin: 0.0, tmax: f32::INFINITY });
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
        let prim = h.prim as usize;
        let ng = scene.normals[prim];
        let cos_l = -dot(ng, w);
        if !(cos_l > 0.0) {
            break; // back face (or degenerate): inside geometry, nothing arrives.
        }
        let pick = scene.emitter_pdf[prim];
        if pick > 0.0 {
            let pdf_light = pick * h.t * h.t / cos_l;
            b = add(b, scale(mul(thr, scene.emission[prim]), power_heuristic(pdf_bsdf, pdf_light)));
        }
        if depth == bounces {
            break;
        }
        thr = mul(thr, scene.albedo[prim]);
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
        p = add(o, scale(w, h.t));
        nrm = ng;
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
        if !scene.bvh.any(&Ray { origin: o, dir: s.dir, tmin: 0.0, tmax }) {
            h = add(h, scale(s.h, w));
        }
    }
    if !scene.emitters.is_empty() {
        let (u0, u1, u2) = (rng.next_f32(), rng.next_f32(), rng.next_f32());
        let k = scene.emitter_cdf.partition_point(|&c| c <= u0).min(scene.emitters.len() - 1);
        let prim = scene.emitters[k] as usize;
        let [a, bb, c] = scene.tris[prim];
        let (beta, gamma) = uniform_triangle(u1, u2);
        let q = add(a, add(scale(sub(bb, a), beta), scale(sub(c, a), gamma)));
        let d = sub(q, x);
        let r2 = dot(d, d);
        let r = r2.sqrt();
        let w = scale(d, 1.0 / r);
        let (cos_i, cos_l) = (dot(n, w), -dot(scene.normals[prim], w));
        if cos_i > 0.0 && cos_l > 0.0 && r > 0.0 {
            let pdf_light = scene.emitter_pdf[prim] * r2 / cos_l;
            let mis = power_heuristic(pdf_light, cos_i * FRAC_1_PI);
            *rays += 1;
            if !scene.bvh.any(&Ray { origin: o, dir: w, tmin: 0.0, tmax: r * (1.0 - SHADOW_SHORTEN) }) {
                h = add(h, scale(scene.emission[prim], cos_i / pdf_light * mis));
            }
        }
    }
    h
}
