//! Reflection probes (`../shared/notes/shading.md` §3): from a point in the level, the radiance
//! arriving from every direction as a cube map, path-traced with the lightmap integrator, then
//! prefiltered per roughness into its mip chain for the runtime's split-sum specular.
//!
//! - **Capture** (`capture`): per face texel, `samples` directions jittered over the texel; each
//!   brings back what a camera at the probe would see: a rect light's face where the ray crosses
//!   it, the sky where it escapes (the **sun's disc left out**: the runtime draws the sun
//!   analytically, and a 0.53° disc at 10⁵ lux is ~1.5·10⁹ nits, past half floats), and on a
//!   surface its emission plus albedo × B there, B estimated by the lightmap integrator's own
//!   path (so the sun's light on surfaces is in). A single-sided back face is black, as in the
//!   lightmaps. Materials are the baker's (diffuse: a metal's reflection is not in the capture).
//! - **Prefilter** (`prefilter`): level k of M holds roughness `r_k = k / (M − 1)` (level 0 the
//!   mirror, the capture itself); each texel direction N, with v = n = N, averages the source
//!   over GGX half-vector samples (Hammersley points), weighted by n·l, reading the source's own
//!   box-filtered mip chain at the sample's footprint (filtered importance sampling,
//!   Colbert-Křivánek, `lod = ½ log₂(Ω_s / Ω_p)`, without their +1 bias: see
//!   `PREFILTER_SAMPLES`), so a small bright source cannot alias into speckles.
//! - **Faces**: Vulkan's cube layer order +X, −X, +Y, −Y, +Z, −Z and its face table (§1.4): a
//!   texel (column i, row j from the top) of an n×n face has a = 2(i + ½)/n − 1, b = 2(j + ½)/n − 1
//!   and direction `face_direction(face, a, b)`; the cooker writes faces in world space so no
//!   flips are needed at run time.
//!
//! Deterministic like the lightmaps: texel streams are keyed by (seed, probe id, texel, sample).

use super::bvh::Ray;
use super::integrator::{par_update, Cancelled};
use super::probes::leaving;
use super::sampling::*;
use super::scene::BakeScene;
use rayon::prelude::*;
use std::f32::consts::PI;
use std::ops::Range;
use std::sync::atomic::AtomicBool;

/// Keys the reflection probes' random streams apart from the texels' and irradiance probes'.
const REFLECTION_STREAM: u64 = 0x5245_464C_0000_0000;
/// GGX samples per prefiltered texel, and the bias added to the filtered-importance-sampling
/// lod. Measured against `convolve_exact` (the test's lopsided cube, 5 roughness levels x 6
/// texels x 3 channels, worst): 64 samples with Colbert-Křivánek's +1 bias (§3.2) 4.0 % off
/// (the mips blur what the lobe would not), 128 / +1 2.3 %, 512 unbiased 1.55 %, 1024 unbiased
/// 0.87 %. 512 cost well under a second a probe.
pub const PREFILTER_SAMPLES: u32 = 512;
const LOD_BIAS: f32 = 0.0;

/// The unnormalised direction through face coordinates a, b ∈ [−1, 1] (§1.4's inverse table).
pub fn face_direction(face: usize, a: f32, b: f32) -> V3 {
    match face {
        0 => [1.0, -b, -a],
        1 => [-1.0, -b, a],
        2 => [a, 1.0, b],
        3 => [a, -1.0, -b],
        4 => [a, -b, 1.0],
        _ => [-a, -b, -1.0],
    }
}

/// The face a direction selects and its (s, t) ∈ [0, 1] (Vulkan's face selection, §1.4).
pub fn face_coords(d: V3) -> (usize, f32, f32) {
    let [x, y, z] = d;
    let (ax, ay, az) = (x.abs(), y.abs(), z.abs());
    let (face, sc, tc, ma) = if ax >= ay && ax >= az {
        if x > 0.0 { (0, -z, -y, ax) } else { (1, z, -y, ax) }
    } else if ay >= az {
        if y > 0.0 { (2, x, z, ay) } else { (3, x, -z, ay) }
    } else if z > 0.0 {
        (4, x, -y, az)
    } else {
        (5, -x, -y, az)
    };
    (face, 0.5 * (sc / ma + 1.0), 0.5 * (tc / ma + 1.0))
}

/// A cube map of RGB radiance: `size`² texels per face, faces in layer order, rows from the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Cube {
    pub size: usize,
    pub texels: Vec<V3>,
}

impl Cube {
    pub fn new(size: usize, f: impl Fn(V3) -> V3 + Sync) -> Cube {
        let texels = (0..6 * size * size).into_par_iter().map(|i| f(normalize(Cube::direction_of(size, i)))).collect();
        Cube { size, texels }
    }

    /// The (unnormalised) direction through the centre of texel `i`.
    pub fn direction_of(size: usize, i: usize) -> V3 {
        let (face, j, col) = (i / (size * size), (i / size) % size, i % size);
        let n = size as f32;
        face_direction(face, 2.0 * (col as f32 + 0.5) / n - 1.0, 2.0 * (j as f32 + 0.5) / n - 1.0)
    }

    /// The solid angle of texel `i` (they sum to 4π).
    pub fn solid_angle_of(size: usize, i: usize) -> f32 {
        let d = Cube::direction_of(size, i);
        let l2 = dot(d, d);
        (2.0 / size as f32).powi(2) / (l2 * l2.sqrt())
    }

    /// Half the size, each texel the mean of the 2×2 below it (per face: no texel straddles two).
    fn half(&self) -> Cube {
        let (n, h) = (self.size, self.size / 2);
        let mut texels = Vec::with_capacity(6 * h * h);
        for face in 0..6 {
            for j in 0..h {
                for i in 0..h {
                    let at = |jj: usize, ii: usize| self.texels[face * n * n + jj * n + ii];
                    let s = add(add(at(2 * j, 2 * i), at(2 * j, 2 * i + 1)), add(at(2 * j + 1, 2 * i), at(2 * j + 1, 2 * i + 1)));
                    texels.push(scale(s, 0.25));
                }
            }
        }
        Cube { size: h, texels }
    }

    /// Bilinear lookup toward `d`, seamless like Vulkan's cube sampling: a tap past the face's
    /// edge reads the neighbouring face's texel in that direction (clamping at the edge instead
    /// put 2-3 % errors into rough levels near corners, where coarse mips are read).
    pub fn sample(&self, d: V3) -> V3 {
        let (face, s, t) = face_coords(d);
        let n = self.size;
        let (x, y) = (s * n as f32 - 0.5, t * n as f32 - 0.5);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let tap = |ii: i64, jj: i64| -> V3 {
            if (0..n as i64).contains(&ii) && (0..n as i64).contains(&jj) {
                return self.texels[face * n * n + jj as usize * n + ii as usize];
            }
            let a = 2.0 * (ii as f32 + 0.5) / n as f32 - 1.0;
            let b = 2.0 * (jj as f32 + 0.5) / n as f32 - 1.0;
            let (f2, s2, t2) = face_coords(face_direction(face, a, b));
            let (i2, j2) = (((s2 * n as f32) as usize).min(n - 1), ((t2 * n as f32) as usize).min(n - 1));
            self.texels[f2 * n * n + j2 * n + i2]
        };
        let top = add(scale(tap(x0, y0), 1.0 - fx), scale(tap(x0 + 1, y0), fx));
        let bottom = add(scale(tap(x0, y0 + 1), 1.0 - fx), scale(tap(x0 + 1, y0 + 1), fx));
        add(scale(top, 1.0 - fy), scale(bottom, fy))
    }
}

/// What the camera at `x` sees along unit `w` (module doc); a surface as the irradiance probes
/// see it (`probes::leaving`, with `bounces`).
fn radiance(scene: &BakeScene, x: V3, w: V3, bounces: u32, rng: &mut Rng, rays: &mut u64) -> V3 {
    *rays += 1;
    let hit = scene.closest(&Ray { origin: x, dir: w, tmin: 0.0, tmax: f32::INFINITY });
    let t_hit = hit.as_ref().map_or(f32::INFINITY, |h| h.t);
    // Rect lights are not geometry: their emitting face shows where the ray crosses it first.
    let mut l = [0.0; 3];
    for light in scene.lights.rects() {
        if let Some((t, lum, _)) = light.hit_rect(x, w) {
            if t < t_hit {
                l = add(l, lum);
            }
        }
    }
    match hit {
        None => add(l, scene.sky.unwrap_or([0.0; 3])),
        Some(h) => add(l, leaving(scene, x, w, &h, bounces, rng, rays).unwrap_or([0.0; 3])),
    }
}

/// The radiance cube seen from `x` (`size`² texels a face, `samples` jittered rays a texel,
/// `bounces` as the lightmaps'), its streams keyed by (`seed`, `id`). Returns it and the rays.
#[allow(clippy::too_many_arguments)]
pub fn capture(
    scene: &BakeScene,
    x: V3,
    id: u64,
    size: usize,
    samples: u32,
    bounces: u32,
    seed: u64,
    progress: &(dyn Fn(u64, u64) + Sync),
    cancel: &AtomicBool,
) -> Result<(Cube, u64), Cancelled> {
    let mut sums = vec![[0.0f64; 3]; 6 * size * size];
    let rays = add_capture_samples(scene, x, id, size, 0..samples.max(1), bounces, seed, &mut sums, progress, cancel)?;
    Ok((finish_capture(&sums, size, samples), rays))
}

/// The capture samples `samples` (indices) of every texel of the cube seen from `x`, added to
/// its running sums (`6 size²` of them, face by face, row by row): as the lightmaps' samples
/// (`integrator::add_point_samples`), sums over 0..a then a..b are the bits of sums over 0..b.
#[allow(clippy::too_many_arguments)]
pub fn add_capture_samples(
    scene: &BakeScene,
    x: V3,
    id: u64,
    size: usize,
    samples: Range<u32>,
    bounces: u32,
    seed: u64,
    sums: &mut [[f64; 3]],
    progress: &(dyn Fn(u64, u64) + Sync),
    cancel: &AtomicBool,
) -> Result<u64, Cancelled> {
    assert_eq!(sums.len(), 6 * size * size, "one sum per cube texel");
    // Texel indices stay below 2^24 (a 2048² face): the id sits above them.
    let stream = REFLECTION_STREAM ^ (id << 24);
    par_update(sums, 64, None, progress, cancel, |i, _, sum, cast| {
        let (face, j, col) = (i / (size * size), (i / size) % size, i % size);
        for k in samples.clone() {
            let mut rng = Rng::for_sample(seed, stream ^ i as u64, k as u64);
            let (u, v) = (rng.next_f32(), rng.next_f32());
            let a = 2.0 * (col as f32 + u) / size as f32 - 1.0;
            let b = 2.0 * (j as f32 + v) / size as f32 - 1.0;
            let l = radiance(scene, x, normalize(face_direction(face, a, b)), bounces, &mut rng, cast);
            for c in 0..3 {
                sum[c] += l[c] as f64;
            }
        }
    })
}

/// The radiance cube from its texels' sums of `samples` samples.
pub fn finish_capture(sums: &[[f64; 3]], size: usize, samples: u32) -> Cube {
    let n = samples.max(1) as f64;
    Cube { size, texels: sums.iter().map(|s| s.map(|v| (v / n) as f32)).collect() }
}

/// The i-th of n Hammersley points in [0, 1)².
fn hammersley(i: u32, n: u32) -> (f32, f32) {
    (i as f32 / n as f32, i.reverse_bits() as f32 * (1.0 / 4_294_967_296.0))
}

/// GGX normal distribution D(n·h) for α = roughness².
pub fn d_ggx(nh: f32, alpha: f32) -> f32 {
    let a2 = alpha * alpha;
    let d = nh * nh * (a2 - 1.0) + 1.0;
    a2 / (PI * d * d)
}

/// The roughness level k of `levels` holds (§3.2).
pub fn level_roughness(k: usize, levels: usize) -> f32 {
    if levels <= 1 { 0.0 } else { k as f32 / (levels - 1) as f32 }
}

/// The mip chain of `base` for the runtime: `levels` cubes, level k of size `base.size >> k`
/// prefiltered for roughness `level_roughness(k, levels)` with `samples` GGX samples a texel;
/// level 0 is `base` itself.
pub fn prefilter(base: &Cube, levels: usize, samples: u32) -> Vec<Cube> {
    // The source's box-filtered chain, down to 1×1, for filtered importance sampling.
    let mut chain = vec![base.clone()];
    while chain.last().unwrap().size > 1 {
        let next = chain.last().unwrap().half();
        chain.push(next);
    }
    let omega_p = 4.0 * PI / (6.0 * (base.size * base.size) as f32);
    let mut out = vec![base.clone()];
    for k in 1..levels {
        let size = (base.size >> k).max(1);
        let alpha = level_roughness(k, levels).powi(2);
        out.push(Cube::new(size, |n| prefiltered(&chain, n, alpha, samples, omega_p)));
    }
    out
}

/// One prefiltered direction: Σ L(l) n·l / Σ n·l over GGX samples of h around n = v = `n`.
fn prefiltered(chain: &[Cube], n: V3, alpha: f32, samples: u32, omega_p: f32) -> V3 {
    let (t, b) = frame(n);
    let (mut sum, mut weight) = ([0.0f32; 3], 0.0f32);
    let max_lod = (chain.len() - 1) as f32;
    for i in 0..samples {
        let (u1, u2) = hammersley(i, samples);
        let cos_h = ((1.0 - u1) / (1.0 + (alpha * alpha - 1.0) * u1)).sqrt();
        let sin_h = (1.0 - cos_h * cos_h).max(0.0).sqrt();
        let phi = 2.0 * PI * u2;
        let h = add(add(scale(t, sin_h * phi.cos()), scale(b, sin_h * phi.sin())), scale(n, cos_h));
        // v = n: l = 2 (v·h) h − v, and n·l = 2 cos_h² − 1.
        let nl = 2.0 * cos_h * cos_h - 1.0;
        if nl <= 0.0 {
            continue;
        }
        let l = sub(scale(h, 2.0 * cos_h), n);
        // pdf of l = D (n·h) / (4 v·h) = D / 4 here; the sample stands for 1/(N pdf) sr.
        let omega_s = 4.0 / (samples as f32 * d_ggx(cos_h, alpha));
        let lod = (0.5 * (omega_s / omega_p).log2() + LOD_BIAS).clamp(0.0, max_lod);
        let (lo, f) = (lod.floor() as usize, lod.fract());
        let mut c = chain[lo].sample(l);
        if f > 0.0 && lo + 1 < chain.len() {
            c = add(scale(c, 1.0 - f), scale(chain[lo + 1].sample(l), f));
        }
        sum = add(sum, scale(c, nl));
        weight += nl;
    }
    if weight > 0.0 { scale(sum, 1.0 / weight) } else { chain[0].sample(n) }
}

/// The ground truth `prefilter` approximates, by brute force over every texel of `cube`:
/// ∫ L(l) (n·l)₊ D(h) dl / ∫ (n·l)₊ D(h) dl with v = n (for tests).
pub fn convolve_exact(cube: &Cube, n: V3, roughness: f32) -> V3 {
    let n = normalize(n);
    let alpha = roughness * roughness;
    let (mut sum, mut weight) = ([0.0f64; 3], 0.0f64);
    for (i, l) in cube.texels.iter().enumerate() {
        let d = normalize(Cube::direction_of(cube.size, i));
        let nl = dot(n, d);
        if nl <= 0.0 {
            continue;
        }
        let h = normalize(add(n, d));
        let w = (nl * d_ggx(dot(n, h), alpha) * Cube::solid_angle_of(cube.size, i)) as f64;
        for c in 0..3 {
            sum[c] += l[c] as f64 * w;
        }
        weight += w;
    }
    sum.map(|s| (s / weight) as f32)
}
