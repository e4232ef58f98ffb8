//! Eight boids at a time: 3-vectors whose components are `f32x8` lanes, for the per-boid rule
//! arithmetic in `boids` (obstacle fields, wander, the budget, the speed limits, banking).
//!
//! - Each operation is the one glam's scalar `Vec3` does, in the same order (a dot product is
//!   (x·x + y·y) + z·z, a normalisation multiplies by 1/|v|), and +, −, ×, ÷ and √ are exactly
//!   rounded in every lane. So a lane gives the same bits as the scalar code on one boid, which
//!   the tests in `boids` check: the scalar functions stay as the reference.
//! - Branches become masks: both sides are computed and `select` keeps one per lane.
//! - `wide` compiles to SSE2 on any x86-64 (two 4-wide halves), AVX where the build enables it
//!   and NEON on ARM, so no CPU detection is needed and every build agrees with itself.

use glam::Vec3;
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub};
pub use wide::f32x8 as F;

pub const LANES: usize = 8;

/// One 3-vector per lane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct V3 {
    pub x: F,
    pub y: F,
    pub z: F,
}

impl V3 {
    pub const ZERO: V3 = V3 { x: F::ZERO, y: F::ZERO, z: F::ZERO };

    /// The same vector in every lane.
    pub fn splat(v: Vec3) -> V3 {
        V3 { x: F::splat(v.x), y: F::splat(v.y), z: F::splat(v.z) }
    }

    pub fn from_lanes(v: &[Vec3; LANES]) -> V3 {
        V3 { x: F::new(v.map(|v| v.x)), y: F::new(v.map(|v| v.y)), z: F::new(v.map(|v| v.z)) }
    }

    pub fn from_arrays(x: [f32; LANES], y: [f32; LANES], z: [f32; LANES]) -> V3 {
        V3 { x: F::new(x), y: F::new(y), z: F::new(z) }
    }

    pub fn lane(self, k: usize) -> Vec3 {
        Vec3::new(self.x.as_array()[k], self.y.as_array()[k], self.z.as_array()[k])
    }

    pub fn set_lane(&mut self, k: usize, v: Vec3) {
        self.x.as_mut_array()[k] = v.x;
        self.y.as_mut_array()[k] = v.y;
        self.z.as_mut_array()[k] = v.z;
    }

    pub fn dot(self, o: V3) -> F {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    pub fn cross(self, o: V3) -> V3 {
        V3 { x: self.y * o.z - o.y * self.z, y: self.z * o.x - o.z * self.x, z: self.x * o.y - o.x * self.y }
    }

    pub fn length(self) -> F {
        self.dot(self).sqrt()
    }

    /// glam's `try_normalize` per lane: the unit vector, and the mask of the lanes where it is
    /// defined (1/|v| finite and positive). Other lanes hold garbage.
    pub fn try_normalize(self) -> (V3, F) {
        let rcp = F::ONE / self.length();
        (self * rcp, rcp.is_finite() & rcp.simd_gt(F::ZERO))
    }

    /// glam's `clamp` (max, then min), per component.
    pub fn clamp(self, lo: V3, hi: V3) -> V3 {
        V3 { x: self.x.max(lo.x).min(hi.x), y: self.y.max(lo.y).min(hi.y), z: self.z.max(lo.z).min(hi.z) }
    }

    /// glam's `lerp`: self·(1 − s) + o·s.
    pub fn lerp(self, o: V3, s: F) -> V3 {
        self * (F::ONE - s) + o * s
    }
}

/// Per lane, `a` where `mask` is set and `b` elsewhere.
pub fn select(mask: F, a: V3, b: V3) -> V3 {
    V3 { x: mask.select(a.x, b.x), y: mask.select(a.y, b.y), z: mask.select(a.z, b.z) }
}

impl Add for V3 {
    type Output = V3;
    fn add(self, o: V3) -> V3 {
        V3 { x: self.x + o.x, y: self.y + o.y, z: self.z + o.z }
    }
}

impl AddAssign for V3 {
    fn add_assign(&mut self, o: V3) {
        *self = *self + o;
    }
}

impl Sub for V3 {
    type Output = V3;
    fn sub(self, o: V3) -> V3 {
        V3 { x: self.x - o.x, y: self.y - o.y, z: self.z - o.z }
    }
}

impl Neg for V3 {
    type Output = V3;
    fn neg(self) -> V3 {
        V3 { x: -self.x, y: -self.y, z: -self.z }
    }
}

impl Mul<F> for V3 {
    type Output = V3;
    fn mul(self, s: F) -> V3 {
        V3 { x: self.x * s, y: self.y * s, z: self.z * s }
    }
}

impl Div<F> for V3 {
    type Output = V3;
    fn div(self, s: F) -> V3 {
        V3 { x: self.x / s, y: self.y / s, z: self.z / s }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Vectors with zero, tiny, huge and negative components, so the masks' edge cases show.
    fn samples() -> Vec<Vec3> {
        let mut rng = crate::sim::rng::Rng::new(7);
        let mut v: Vec<Vec3> = (0..64).map(|_| rng.unit_vector() * rng.range(0.0, 30.0)).collect();
        v.extend([Vec3::ZERO, Vec3::X * 1e-30, Vec3::new(-0.0, 3.0, 0.0), Vec3::splat(1e20), Vec3::new(0.0, 0.0, -2.5)]);
        v
    }

    #[test]
    fn lane_operations_give_glams_bits() {
        let s = samples();
        for w in s.windows(LANES + 1) {
            let a: [Vec3; LANES] = std::array::from_fn(|k| w[k]);
            let b: [Vec3; LANES] = std::array::from_fn(|k| w[k + 1]);
            let (va, vb) = (V3::from_lanes(&a), V3::from_lanes(&b));
            let t = F::new(std::array::from_fn(|k| (k as f32) / 7.0));
            let (n, ok) = va.try_normalize();
            for k in 0..LANES {
                let bits = |v: Vec3| v.to_array().map(f32::to_bits);
                assert_eq!(va.dot(vb).as_array()[k].to_bits(), a[k].dot(b[k]).to_bits());
                assert_eq!(bits(va.cross(vb).lane(k)), bits(a[k].cross(b[k])));
                assert_eq!(va.length().as_array()[k].to_bits(), a[k].length().to_bits());
                assert_eq!(bits(va.lerp(vb, t).lane(k)), bits(a[k].lerp(b[k], t.as_array()[k])));
                assert_eq!(bits(va.clamp(-V3::splat(Vec3::ONE), vb.clamp(V3::splat(Vec3::ONE), V3::splat(Vec3::splat(f32::MAX)))).lane(k)), bits(a[k].clamp(-Vec3::ONE, b[k].max(Vec3::ONE))));
                match a[k].try_normalize() {
                    Some(u) => {
                        assert_eq!(ok.as_array()[k].to_bits(), u32::MAX, "lane {k}: {:?}", a[k]);
                        assert_eq!(bits(n.lane(k)), bits(u));
                    }
                    None => assert_eq!(ok.as_array()[k].to_bits(), 0, "lane {k}: {:?}", a[k]),
                }
            }
        }
    }
}
