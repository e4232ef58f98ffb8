//! The lightmap integrator: per surface point, a path-traced estimate of
//!
//!   **B = H / pi**  (nits; H is the irradiance from the hemisphere around the point's normal)
//!
//! — the one quantity the baker stores (notes §1.3): the outgoing radiance a white Lambertian
//! surface would have there, so the runtime shades `L_out = L_e + albedo * B`. Under a uniform
//! sky of radiance L, B = L exactly.
//!
//! Per sample path, at the point and at every bounce vertex:
//! - next-event estimation for the sun and each rect light, for one of the point and spot lights
//!   in range picked in proportion to its unoccluded irradiance (`direct_each`), and for one
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
use super::light_set::{light_numbers, LightSet};
use super::lights::{Light, LightSample};
use super::sampling::*;
use super::scene::BakeScene;
use rayon::prelude::*;
use std::f32::consts::FRAC_1_PI;
use std::ops::Range;
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
    let mut sums = vec![[0.0f64; 3]; points.len()];
    let rays = add_point_samples(scene, points, normals, ids, settings, 0..settings.samples, &mut sums, progress, cancel)?;
    Ok(Baked { b: sums.iter().map(|s| finish_point(s, settings.samples)).collect(), rays })
}

/// The samples `samples` (indices, of `settings.samples` in all) of every point, added to its
/// running sums (`bake_points` is this over 0..settings.samples, then [`finish_point`]). Sample
/// k of a point is the same whichever call draws it (its streams are keyed by (seed, id, k)), and
/// each point's sums take its samples in index order: sums made over 0..a and then a..b are the
/// bits of sums made over 0..b, so a bake can be refined (`cook --watch`) and end exactly where
/// a one-shot bake of b samples does. Returns the rays cast.
#[allow(clippy::too_many_arguments)]
pub fn add_point_samples(
    scene: &BakeScene,
    points: &[V3],
    normals: &[V3],
    ids: Option<&[u64]>,
    settings: &BakeSettings,
    samples: Range<u32>,
    sums: &mut [[f64; 3]],
    progress: &(dyn Fn(u64, u64) + Sync),
    cancel: &AtomicBool,
) -> Result<u64, Cancelled> {
    assert_eq!(points.len(), normals.len(), "one normal per point");
    assert_eq!(points.len(), sums.len(), "one sum per point");
    par_update(sums, CHUNK, ids, progress, cancel, |i, id, sum, cast| add_point(scene, points[i], normals[i], id, settings, samples.clone(), sum, cast))
}

/// B from a point's sums of `samples` samples (0 for a point the baker cannot place).
pub fn finish_point(sum: &[f64; 3], samples: u32) -> V3 {
    sum.map(|v| (v / samples.max(1) as f64) as f32)
}

/// A texel of a directional lightmap (shading.md §4): each channel's L1 irradiance in lightmap
/// units, `B(n) = b0 + b1·n`, of all the light but the sun's direct light, and the fraction of
/// the sun's disc the point sees. The runtime lights the texel with the sun itself, for the
/// shading normal: L1 holds one direction poorly (a quarter of it misplaced, §6d), and the sun
/// is most of the light outdoors; its bounces are in the L1.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DirectionalTexel {
    /// b0 per channel (nits): the mean radiance over the sphere.
    pub b0: V3,
    /// b1 per channel, each an (x, y, z) vector (nits).
    pub b1: [V3; 3],
    /// Of the sun's samples, the fraction that reached the point unoccluded and above its
    /// horizon (1 without a sun, which then lights nothing).
    pub sun_visibility: f32,
}

#[derive(Debug, Clone, PartialEq)]
pub struct BakedDirectional {
    pub texels: Vec<DirectionalTexel>,
    /// Every ray cast (closest-hit and shadow).
    pub rays: u64,
}

/// `bake_points` for a directional lightmap: per point, `settings.samples` samples, each one
/// light sample per light (the sun's only counted for its visibility), one emissive triangle
/// and one continuation ray drawn from `mixture_hemisphere`, MIS-weighted against each other.
/// The sun is `scene.lights`' first sun, the one the runtime draws.
#[allow(clippy::too_many_arguments)]
pub fn bake_points_directional(
    scene: &BakeScene,
    points: &[V3],
    normals: &[V3],
    ids: Option<&[u64]>,
    settings: &BakeSettings,
    progress: &(dyn Fn(u64, u64) + Sync),
    cancel: &AtomicBool,
) -> Result<BakedDirectional, Cancelled> {
    let mut sums = vec![TexelSums::default(); points.len()];
    let rays = add_texel_samples(scene, points, normals, ids, settings, 0..settings.samples, &mut sums, progress, cancel)?;
    let texels = sums.iter().zip(points.iter().zip(normals)).map(|(s, (&x, &n))| finish_texel(scene, s, settings.samples, x, n)).collect();
    Ok(BakedDirectional { texels, rays })
}

/// A directional texel's running sums (see [`add_texel_samples`]): of L/p (radiance over the
/// density it was drawn with) and of L w / p per channel, and how many sun samples saw the sun.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TexelSums {
    pub l: [f64; 3],
    pub lw: [[f64; 3]; 3],
    pub sun_seen: u32,
}

/// [`add_point_samples`] for a directional lightmap's texels (`bake_points_directional` is
/// this over 0..settings.samples, then [`finish_texel`]).
#[allow(clippy::too_many_arguments)]
pub fn add_texel_samples(
    scene: &BakeScene,
    points: &[V3],
    normals: &[V3],
    ids: Option<&[u64]>,
    settings: &BakeSettings,
    samples: Range<u32>,
    sums: &mut [TexelSums],
    progress: &(dyn Fn(u64, u64) + Sync),
    cancel: &AtomicBool,
) -> Result<u64, Cancelled> {
    assert_eq!(points.len(), normals.len(), "one normal per point");
    assert_eq!(points.len(), sums.len(), "one sum per point");
    let sun = first_sun(scene);
    par_update(sums, CHUNK, ids, progress, cancel, |i, id, acc, cast| add_texel(scene, points[i], normals[i], id, sun, settings, samples.clone(), acc, cast))
}

/// The scene's first sun, the one the runtime draws.
fn first_sun(scene: &BakeScene) -> Option<usize> {
    scene.lights.all().iter().position(|l| matches!(l, Light::Sun { .. }))
}

/// A directional texel from its sums of `samples` samples at point `x` with normal `n` (a point
/// the baker cannot place is all zero).
pub fn finish_texel(scene: &BakeScene, acc: &TexelSums, samples: u32, x: V3, n: V3) -> DirectionalTexel {
    if unit_normal(x, n).is_none() {
        return DirectionalTexel::default();
    }
    // b0 = mean(L/p) / 4 pi, b1 = mean(L w / p) / 2 pi.
    let samples = samples.max(1);
    let k = 1.0 / samples as f64;
    DirectionalTexel {
        b0: acc.l.map(|v| (v * k / (4.0 * std::f64::consts::PI)) as f32),
        b1: acc.lw.map(|c| c.map(|v| (v * k / (2.0 * std::f64::consts::PI)) as f32)),
        sun_visibility: if first_sun(scene).is_some() { acc.sun_seen as f32 / samples as f32 } else { 1.0 },
    }
}

#[allow(clippy::too_many_arguments)]
fn add_texel(scene: &BakeScene, x: V3, n: V3, index: u64, sun: Option<usize>, s: &BakeSettings, samples: Range<u32>, acc: &mut TexelSums, rays: &mut u64) {
    let Some(n) = unit_normal(x, n) else { return };
    let TexelSums { l: l_sum, lw: lw_sum, sun_seen } = acc;
    let mut add_sample = |l_over_pdf: V3, w: V3| {
        for c in 0..3 {
            l_sum[c] += l_over_pdf[c] as f64;
            for a in 0..3 {
                lw_sum[c][a] += (l_over_pdf[c] * w[a]) as f64;
            }
        }
    };
    // What a texel learns of its lights holds for every sample (the same answers, fewer rays).
    let mut seen = SeenFrom::default();
    for k in samples {
        let mut rng = Rng::for_sample(s.seed, index, k as u64);
        direct_each(scene, x, n, &mut rng, rays, Some(&mut seen), mixture_pdf, |source, w, e, cos| {
            if sun.is_some_and(|i| source == Source::Light(i)) {
                *sun_seen += 1;
            } else if cos > 0.0 {
                // The sample's irradiance is its radiance x cos / pdf: undo the cosine.
                add_sample(scale(e, 1.0 / cos), w);
            }
        });
        let (local, pdf) = mixture_hemisphere(rng.next_f32(), rng.next_f32());
        let w = to_world(local, n);
        let l = trace(scene, [0.0; 3], x, n, w, pdf, s.bounces, &mut rng, rays);
        add_sample(scale(l, 1.0 / pdf), w);
    }
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
    let mut out = vec![T::default(); n];
    let rays = par_update(&mut out, chunk, ids, progress, cancel, |i, id, o, cast| *o = f(i, id, cast))?;
    Ok((out, rays))
}

/// `items` updated in parallel, `chunk` at a time: `f(i, id, item, rays)` updates item i, whose
/// random streams are keyed by `ids[i]` (default i), adding the rays it casts. Progress and
/// cancel as [`par_bake`]; a cancelled call leaves some items updated and others not. Returns the
/// rays.
pub(super) fn par_update<T: Send>(
    items: &mut [T],
    chunk: usize,
    ids: Option<&[u64]>,
    progress: &(dyn Fn(u64, u64) + Sync),
    cancel: &AtomicBool,
    f: impl Fn(usize, u64, &mut T, &mut u64) + Sync,
) -> Result<u64, Cancelled> {
    assert!(ids.is_none_or(|ids| ids.len() == items.len()), "one id per point");
    let (done, rays) = (AtomicU64::new(0), AtomicU64::new(0));
    items.par_chunks_mut(chunk).enumerate().for_each(|(c, dst)| {
        if cancel.load(Ordering::Relaxed) {
            return;
        }
        let mut cast = 0u64;
        for (j, o) in dst.iter_mut().enumerate() {
            let i = c * chunk + j;
            f(i, ids.map_or(i as u64, |ids| ids[i]), o, &mut cast);
        }
        let d = done.fetch_add(dst.len() as u64, Ordering::Relaxed) + dst.len() as u64;
        let r = rays.fetch_add(cast, Ordering::Relaxed) + cast;
        progress(d, r);
    });
    if cancel.load(Ordering::Relaxed) {
        return Err(Cancelled);
    }
    Ok(rays.into_inner())
}

/// `n` made unit, or None for a point the baker cannot place (a zero or NaN normal, a
/// position that is not finite), which bakes as no light.
fn unit_normal(x: V3, n: V3) -> Option<V3> {
    let nl = length(n);
    (nl > 0.0 && x.iter().all(|v| v.is_finite())).then(|| scale(n, 1.0 / nl))
}

#[allow(clippy::too_many_arguments)]
fn add_point(scene: &BakeScene, x: V3, n: V3, index: u64, s: &BakeSettings, samples: Range<u32>, sum: &mut [f64; 3], rays: &mut u64) {
    let Some(n) = unit_normal(x, n) else { return };
    let mut seen = SeenFrom::default();
    for k in samples {
        let mut rng = Rng::for_sample(s.seed, index, k as u64);
        let v = sample_path(scene, x, n, s.bounces, &mut rng, rays, Some(&mut seen));
        for c in 0..3 {
            sum[c] += v[c] as f64;
        }
    }
}

/// One estimate of B at x: (direct irradiance)/pi + radiance along one cosine-sampled ray.
/// `seen`: what x's samples learnt so far of which point and spot lights x sees (see
/// [`SeenFrom`]), when x is the same point in every sample.
pub(super) fn sample_path(scene: &BakeScene, x: V3, n: V3, bounces: u32, rng: &mut Rng, rays: &mut u64, seen: Option<&mut SeenFrom>) -> V3 {
    let b = scale(direct(scene, x, n, rng, rays, seen), FRAC_1_PI);
    let local = cosine_hemisphere(rng.next_f32(), rng.next_f32());
    trace(scene, b, x, n, to_world(local, n), local[2] * FRAC_1_PI, bounces, rng, rays)
}

/// `acc` plus the radiance arriving at (x, n) from the direction `w`, drawn with density `pdf`
/// (per steradian): emission where the ray lands (MIS-weighted against light sampling), the sky
/// if it escapes, and the light reflected there, path-traced through `bounces` more vertices
/// with cosine-sampled continuations and next-event estimation at each.
#[allow(clippy::too_many_arguments)]
fn trace(scene: &BakeScene, acc: V3, x: V3, n: V3, w: V3, pdf: f32, bounces: u32, rng: &mut Rng, rays: &mut u64) -> V3 {
    let mut b = acc;
    let mut thr = [1.0f32; 3];
    let (mut p, mut nrm, mut w, mut pdf_bsdf) = (x, n, w, pdf);
    for depth in 0..=bounces {
        if depth > 0 {
            let local = cosine_hemisphere(rng.next_f32(), rng.next_f32());
            (w, pdf_bsdf) = (to_world(local, nrm), local[2] * FRAC_1_PI);
        }
        let o = offset_ray(p, nrm);
        *rays += 1;
        let hit = scene.closest(&Ray { origin: o, dir: w, tmin: 0.0, tmax: f32::INFINITY });
        let t_hit = hit.map_or(f32::INFINITY, |h| h.t);
        for l in scene.lights.rects() {
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
        b = add(b, scale(mul(thr, direct(scene, p, nrm, rng, rays, None)), FRAC_1_PI));
    }
    b
}

/// Point and spot lights: one direction, their irradiance at a point known without sampling.
fn is_delta(l: &Light) -> bool {
    matches!(l, Light::Point { .. } | Light::Spot { .. })
}

/// How much a delta light's sample weighs in the pick: its irradiance summed over channels,
/// positive whenever it lights the point.
fn pick_weight(h: V3) -> f32 {
    h[0] + h[1] + h[2]
}

/// Where a next-event sample's light came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Source {
    /// `scene.lights[i]`.
    Light(usize),
    /// An emissive triangle.
    Emitter,
}

/// Next-event estimate of the irradiance H at (x, n) from the analytic lights that reach x (the
/// sun and rects each, one point or spot light picked, see `direct_each`) and one emissive
/// triangle, area lights MIS-weighted against cosine sampling. Always draws the same number of
/// random numbers, so later dimensions of a path stay aligned whatever is hit.
pub(super) fn direct(scene: &BakeScene, x: V3, n: V3, rng: &mut Rng, rays: &mut u64, seen: Option<&mut SeenFrom>) -> V3 {
    let mut h = [0.0f32; 3];
    direct_each(scene, x, n, rng, rays, seen, |cos| cos * FRAC_1_PI, |_, _, e, _| h = add(h, e));
    h
}

/// What one fixed point (a lightmap texel's, over its samples) learns of its lights once and
/// keeps: the lights that reach it, in the order [`LightSet::near`] visits them, with each point
/// or spot light's sample (a delta light has one direction: its sample there never changes),
/// and whether it sees each delta light (its shadow ray is the same ray every sample, with the
/// same answer). Asked once, remembered: the bake is bit-identical, with one shadow ray per
/// light in view of the texel instead of one per sample (14 % of the rays of the 100k benchmark
/// level, a point light in every room) and one walk of the light tree per texel. A few lights: those
/// near one point.
#[derive(Default)]
pub(super) struct SeenFrom {
    near: Option<Vec<(usize, Option<LightSample>)>>,
    visible: Vec<(usize, bool)>,
}

impl SeenFrom {
    fn visible_or(&mut self, light: usize, test: impl FnOnce() -> bool) -> bool {
        if let Some(&(_, v)) = self.visible.iter().find(|e| e.0 == light) {
            return v;
        }
        let v = test();
        self.visible.push((light, v));
        v
    }
}

/// `direct`'s samples one by one: `each(source, direction, irradiance, cos)` for every sample
/// that arrives unoccluded, its irradiance (lux, the light's radiance x cos / pdf) already
/// MIS-weighted against continuation rays drawn with density `bsdf_pdf(cos)`.
#[allow(clippy::too_many_arguments)]
pub(super) fn direct_each(scene: &BakeScene, x: V3, n: V3, rng: &mut Rng, rays: &mut u64, seen: Option<&mut SeenFrom>, bsdf_pdf: impl Fn(f32) -> f32, mut each: impl FnMut(Source, V3, V3, f32)) {
    let o = offset_ray(x, n);
    let key = LightSet::key(rng);
    // `seen` only for delta lights: a sun or rect sample's direction changes every time.
    let mut shadow = |i: usize, s: LightSample, weight: f32, rays: &mut u64, seen: Option<&mut SeenFrom>| {
        let cos = dot(n, s.dir);
        let w = s.pdf.map_or(1.0, |pl| power_heuristic(pl, bsdf_pdf(cos)));
        let tmax = if s.dist.is_finite() { s.dist * (1.0 - SHADOW_SHORTEN) } else { f32::INFINITY };
        let mut test = || {
            *rays += 1;
            !scene.occluded(&Ray { origin: o, dir: s.dir, tmin: 0.0, tmax })
        };
        let visible = match seen {
            Some(seen) => seen.visible_or(i, test),
            None => test(),
        };
        if visible {
            each(Source::Light(i), s.dir, scale(s.h, w * weight), cos);
        }
    };
    // The sun and rect lights: one sample each. Point and spot lights: their unoccluded
    // irradiance is known exactly (a delta light has one direction), so one of them is picked in
    // proportion to it, in one pass (weighted reservoir sampling: the light seen with running
    // total T replaces the pick with probability w / T, its own number deciding), and its sample
    // divided by that probability: one shadow ray instead of one per light, and no noise from the
    // choice when they are all in view.
    let (mut total, mut picked) = (0.0f32, None);
    // One light in range: `known` is its sample when it is a delta light whose sample `seen` holds.
    let mut visit = |i: usize, l: &Light, known: Option<LightSample>, rays: &mut u64| {
        let (u1, u2) = light_numbers(key, i);
        let Some(s) = known.or_else(|| l.sample(x, n, u1, u2)) else { return };
        if !is_delta(l) {
            shadow(i, s, 1.0, rays, None);
            return;
        }
        let w = pick_weight(s.h);
        if w > 0.0 {
            total += w;
            if u1 * total < w {
                picked = Some((i, s, w));
            }
        }
    };
    let seen = match seen {
        Some(seen) => {
            let near = seen.near.get_or_insert_with(|| {
                let mut near = Vec::new();
                scene.lights.near(x, |i, l| match is_delta(l) {
                    // A delta light that does not light x (behind it, out of its cone or
                    // range) is skipped every sample: left out.
                    true => near.extend(l.sample(x, n, 0.0, 0.0).map(|s| (i, Some(s)))),
                    false => near.push((i, None)),
                });
                near
            });
            let all = scene.lights.all();
            for &(i, known) in near.iter() {
                visit(i, &all[i], known, rays);
            }
            Some(seen)
        }
        None => {
            scene.lights.near(x, |i, l| visit(i, l, None, rays));
            None
        }
    };
    if let Some((i, s, w)) = picked {
        shadow(i, s, total / w, rays, seen);
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
                let mis = power_heuristic(pdf_light, bsdf_pdf(cos_i));
                *rays += 1;
                if !scene.occluded(&Ray { origin: o, dir: w, tmin: 0.0, tmax: r * (1.0 - SHADOW_SHORTEN) }) {
                    each(Source::Emitter, w, scale(le, cos_i / pdf_light * mis), cos_i);
                }
            }
        }
    }
}
