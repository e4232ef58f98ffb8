//! A seeded generator for the simulations: SplitMix64 (Steele, Lea and Flood 2014).
//!
//! Own code rather than a crate: eight lines, no dependency to pin, and its output is fixed by
//! the algorithm, so a seed in a level file means the same particles on every build. SplitMix64
//! passes BigCrush and every 64-bit seed (including 0) is a good one. `hash` is its finaliser,
//! used where a value must follow from (seed, id, time) without carrying state, e.g. a boid's
//! wander direction, so parallel updates need no shared generator.

use glam::Vec3;

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rng {
    state: u64,
}

const GOLDEN: u64 = 0x9E37_79B9_7F4A_7C15;

/// SplitMix64's output function: a bijective mix of 64 bits.
pub fn hash(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A uniform f32 in [0, 1) from the top 24 bits (every value exactly representable).
pub fn unit_f32(bits: u64) -> f32 {
    (bits >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
}

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng { state: seed }
    }

    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(GOLDEN);
        hash(self.state)
    }

    /// Uniform in [0, 1).
    pub fn f32(&mut self) -> f32 {
        unit_f32(self.next_u64())
    }

    /// Uniform in [lo, hi); exactly `lo` when the range is empty.
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f32()
    }

    /// Uniform on the unit sphere (Archimedes: z uniform in [-1, 1], azimuth uniform).
    pub fn unit_vector(&mut self) -> Vec3 {
        let z = self.range(-1.0, 1.0);
        let phi = self.range(0.0, std::f32::consts::TAU);
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }

    /// Uniform over the spherical cap of half-angle `half_angle` (radians) around unit `axis`:
    /// cos(theta) uniform in [cos(half_angle), 1] makes the density uniform in solid angle. A
    /// zero angle returns `axis` exactly.
    pub fn cone(&mut self, axis: Vec3, half_angle: f32) -> Vec3 {
        let cos_t = self.range(half_angle.cos(), 1.0).min(1.0);
        let phi = self.range(0.0, std::f32::consts::TAU);
        let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
        let (b1, b2) = axis.any_orthonormal_pair();
        axis * cos_t + (b1 * phi.cos() + b2 * phi.sin()) * sin_t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splitmix_reference_values() {
        // The first outputs for seed 0 from the reference implementation (Vigna's splitmix64.c).
        let mut r = Rng::new(0);
        assert_eq!(r.next_u64(), 0xE220_A839_7B1D_CDAF);
        assert_eq!(r.next_u64(), 0x6E78_9E6A_A1B9_65F4);
    }

    #[test]
    fn cone_stays_inside_its_half_angle() {
        let mut r = Rng::new(7);
        let axis = Vec3::new(1.0, 2.0, -0.5).normalize();
        let half = 20f32.to_radians();
        let mut widest = 0.0f32;
        for _ in 0..10_000 {
            let d = r.cone(axis, half);
            assert!((d.length() - 1.0).abs() < 1e-5);
            widest = widest.max(d.dot(axis).clamp(-1.0, 1.0).acos());
        }
        assert!(widest <= half + 1e-3, "widest {widest}");
        assert!(widest > 0.9 * half, "the cone is not filled: widest {widest}");
        assert_eq!(r.cone(axis, 0.0), axis);
    }
}
