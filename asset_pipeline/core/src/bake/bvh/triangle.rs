//! Per-ray constants and the watertight ray-triangle test.

use super::{Hit, Ray};

/// Per-ray constants of the triangle test.
pub(super) struct Prepared {
    pub(super) org: [f32; 3],
    pub(super) tmin: f32,
    /// Woop et al.: axis permutation and shear that make the ray +z from the origin.
    pub(super) k: [usize; 3],
    pub(super) shear: [f32; 3],
}

/// 1 + 2*gamma(3), gamma(n) = n*eps/(1-n*eps) with eps = 2^-24 (pbrt 3 §3.9.2): widens far
/// bounds so rounding never culls a real hit.
pub(super) const ROBUST: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

impl Prepared {
    pub(super) fn new(ray: &Ray) -> Prepared {
        let d = ray.dir;
        let a = [d[0].abs(), d[1].abs(), d[2].abs()];
        let kz = if a[0] > a[1] { if a[0] > a[2] { 0 } else { 2 } } else if a[1] > a[2] { 1 } else { 2 };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        // Keep the winding: swapping x and y when the dominant component is negative.
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        Prepared { org: ray.origin, tmin: ray.tmin, k: [kx, ky, kz], shear: [d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]] }
    }
}

/// Watertight ray-triangle test; the hit distance if `tmin < t < tmax`.
#[inline(always)]
pub(super) fn intersect(r: &Prepared, tri: &[[f32; 3]; 3], tmin: f32, tmax: f32) -> Option<f32> {
    let [kx, ky, kz] = r.k;
    let [sx, sy, sz] = r.shear;
    // SAFETY: kx, ky, kz are a permutation of 0..3 (Prepared::new).
    let at = |p: &[f32; 3], k: usize| unsafe { *p.get_unchecked(k) };
    let rel = |p: &[f32; 3]| [at(p, kx) - at(&r.org, kx), at(p, ky) - at(&r.org, ky), at(p, kz) - at(&r.org, kz)];
    let (a, b, c) = (rel(&tri[0]), rel(&tri[1]), rel(&tri[2]));
    let (ax, ay) = (a[0] - sx * a[2], a[1] - sy * a[2]);
    let (bx, by) = (b[0] - sx * b[2], b[1] - sy * b[2]);
    let (cx, cy) = (c[0] - sx * c[2], c[1] - sy * c[2]);
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    if u == 0.0 || v == 0.0 || w == 0.0 {
        let f = |p: f32, q: f32, s: f32, t: f32| (p as f64 * q as f64 - s as f64 * t as f64) as f32;
        u = f(cx, by, cy, bx);
        v = f(ax, cy, ay, cx);
        w = f(bx, ay, by, ax);
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    let t_scaled = sz * (u * a[2] + v * b[2] + w * c[2]);
    let (ts, d) = if det < 0.0 { (-t_scaled, -det) } else { (t_scaled, det) };
    // Cheap rejection before the division; the far bound is widened (conservative) so the
    // exact `t < tmax` below decides, and a hit is kept or not whatever tmax earlier triangles
    // left (otherwise a hit a rounding under tmax could be lost, making the closest hit depend
    // on the order triangles are tested in).
    if ts <= tmin * d || ts > tmax * d * ROBUST {
        return None;
    }
    let t = ts / d;
    // The division may round onto the bounds; keep the interval strict.
    (t > tmin && t < tmax).then_some(t)
}

/// Brute-force closest hit over every triangle (the BVH's test oracle and tiny-scene path); of
/// hits at the same distance, the highest triangle index wins, as in the BVH.
pub fn closest_brute(positions: &[[f32; 3]], triangles: &[[u32; 3]], ray: &Ray) -> Option<Hit> {
    let r = Prepared::new(ray);
    let mut best = None;
    let mut tmax = ray.tmax;
    for (i, t) in triangles.iter().enumerate() {
        let tri = t.map(|v| positions[v as usize]);
        if tri.iter().flat_map(|p| p.iter()).any(|x| !x.is_finite()) {
            continue;
        }
        // Once a hit is found, a later triangle at the same t replaces it.
        let bound = if best.is_some() { tmax.next_up() } else { tmax };
        if let Some(th) = intersect(&r, &tri, ray.tmin, bound) {
            tmax = th;
            best = Some(Hit { t: th, prim: i as u32 });
        }
    }
    best
}

/// Distance-weighted intersection of a ray with one triangle (for tests and tie checks).
pub fn intersect_triangle(ray: &Ray, tri: &[[f32; 3]; 3]) -> Option<f32> {
    intersect(&Prepared::new(ray), tri, ray.tmin, ray.tmax)
}
