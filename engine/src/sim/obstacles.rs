//! The level's obstacles as flocks see them (boxes, vertical pillars): signed distances with
//! their outward normals, eight boids at a time, and the limited-range repulsion fields built
//! from them (`boids`).

use super::lanes::{self, F, V3};
use glam::Vec3;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Aabb {
    pub min: [f32; 3],
    pub max: [f32; 3],
}

/// A vertical cylinder: axis at (x, z) = `centre`, from `y_min` to `y_max`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pillar {
    pub centre: [f32; 2],
    pub radius: f32,
    pub y_min: f32,
    pub y_max: f32,
}

/// Repulsion from a surface at signed distance `d` (negative inside) with outward normal `n`:
/// zero beyond `range`, rising linearly to `strength` at contact, `strength` inside.
pub(super) fn repel(d: F, n: V3, range: f32, strength: f32) -> V3 {
    let range = F::splat(range);
    let f = F::splat(strength) * ((range - d) / range).min(F::ONE);
    lanes::select(d.simd_ge(range), V3::ZERO, n * f)
}

/// Signed distance from `p` to a box and the outward normal there.
pub(super) fn box_distance(p: V3, b: &Aabb) -> (F, V3) {
    let (lo, hi) = (Vec3::from(b.min), Vec3::from(b.max));
    let out = p - p.clamp(V3::splat(lo), V3::splat(hi));
    let d = out.length();
    // Inside: the nearest face (the first of equals, as the axes and sides are visited).
    let (mut best, mut normal) = (F::splat(f32::INFINITY), V3::ZERO);
    let axes = [(p.x, lo.x, hi.x), (p.y, lo.y, hi.y), (p.z, lo.z, hi.z)];
    for (a, (pa, lo, hi)) in axes.into_iter().enumerate() {
        for (depth, sign) in [(pa - F::splat(lo), -1.0), (F::splat(hi) - pa, 1.0)] {
            let mut n = Vec3::ZERO;
            n[a] = sign;
            let nearer = depth.simd_lt(best);
            best = nearer.select(depth, best);
            normal = lanes::select(nearer, V3::splat(n), normal);
        }
    }
    let outside = d.simd_gt(F::ZERO);
    (outside.select(d, -best), lanes::select(outside, out / d, normal))
}

/// Signed distance from `p` to a capped vertical cylinder and the outward normal there.
pub(super) fn pillar_distance(p: V3, c: &Pillar) -> (F, V3) {
    let (rx, rz) = (p.x - F::splat(c.centre[0]), p.z - F::splat(c.centre[1]));
    let r = (rx * rx + rz * rz).sqrt();
    let off_axis = r.simd_gt(F::ZERO);
    let side_n = V3 { x: off_axis.select(rx / r, F::ONE), y: F::ZERO, z: off_axis.select(rz / r, F::ZERO) };
    let side_d = r - F::splat(c.radius);
    let (below, above) = (F::splat(c.y_min) - p.y, p.y - F::splat(c.y_max));
    let up = above.simd_gt(below);
    let (cap_d, cap_n) = (up.select(above, below), lanes::select(up, V3::splat(Vec3::Y), V3::splat(Vec3::NEG_Y)));
    // Past the rim: distance to the circular edge.
    let off = side_n * side_d + cap_n * cap_d;
    let rim_d = off.length();
    let rim = side_d.simd_gt(F::ZERO) & cap_d.simd_gt(F::ZERO);
    let sideways = side_d.simd_gt(cap_d);
    let (d, n) = (sideways.select(side_d, cap_d), lanes::select(sideways, side_n, cap_n));
    (rim.select(rim_d, d), lanes::select(rim, off / rim_d, n))
}
