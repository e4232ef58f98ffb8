//! Random numbers and warps for the baker.
//!
//! Every sample path owns its random stream, seeded from a hash of (bake seed, point index,
//! sample index): the numbers a path sees do not depend on which thread runs it or in what order,
//! so a bake is bit-identical for any thread count.

/// PCG32 (O'Neill 2014, XSH-RR output), seeded per sample path.
pub struct Rng {
    state: u64,
    inc: u64,
}

/// SplitMix64 finaliser: a bijective 64-bit mix, so distinct inputs give distinct seeds.
pub(super) fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Rng {
    pub fn for_sample(seed: u64, point: u64, sample: u64) -> Rng {
        let key = mix(mix(mix(seed) ^ point) ^ sample);
        let mut r = Rng { state: 0, inc: (mix(key ^ 0x5851_F42D_4C95_7F2D) << 1) | 1 };
        r.next_u32();
        r.state = r.state.wrapping_add(key);
        r.next_u32();
        r
    }

    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        xorshifted.rotate_right((old >> 59) as u32)
    }

    /// Uniform in [0, 1): 24 random bits, so 1.0 is never returned.
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
    }
}

pub type V3 = [f32; 3];

#[inline]
pub fn dot(a: V3, b: V3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline]
pub fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline]
pub fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
#[inline]
pub fn scale(a: V3, s: f32) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}
#[inline]
pub fn mul(a: V3, b: V3) -> V3 {
    [a[0] * b[0], a[1] * b[1], a[2] * b[2]]
}
#[inline]
pub fn cross(a: V3, b: V3) -> V3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
#[inline]
pub fn length(a: V3) -> f32 {
    dot(a, a).sqrt()
}
#[inline]
pub fn normalize(a: V3) -> V3 {
    scale(a, 1.0 / length(a))
}

/// Orthonormal tangents (t, b) for unit `n` (Duff et al. 2017, branchless, no singularity).
pub fn frame(n: V3) -> (V3, V3) {
    let sign = 1f32.copysign(n[2]);
    let a = -1.0 / (sign + n[2]);
    let b = n[0] * n[1] * a;
    ([1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]], [b, sign + n[1] * n[1] * a, -n[1]])
}

/// `local` (z along `n`) to world.
pub fn to_world(local: V3, n: V3) -> V3 {
    let (t, b) = frame(n);
    add(add(scale(t, local[0]), scale(b, local[1])), scale(n, local[2]))
}

/// Cosine-weighted hemisphere direction, z up; pdf cos(theta)/pi (notes §6, L9130).
pub fn cosine_hemisphere(u1: f32, u2: f32) -> V3 {
    let phi = 2.0 * std::f32::consts::PI * u1;
    let r = u2.sqrt();
    [r * phi.cos(), r * phi.sin(), (1.0 - u2).max(0.0).sqrt()]
}

/// A direction over the hemisphere around z, cosine-weighted half the time and uniform the
/// other half, and its pdf `½ cos/π + ½/(2π)` (`mixture_pdf`). For estimating L1 SH: with
/// cosine sampling alone the 1/cos of b0's and the tangential b1's estimators has infinite
/// variance (shading.md §4.3).
pub fn mixture_hemisphere(u1: f32, u2: f32) -> (V3, f32) {
    let local = if u1 < 0.5 { cosine_hemisphere(2.0 * u1, u2) } else { uniform_cone(2.0 * u1 - 1.0, u2, 0.0) };
    (local, mixture_pdf(local[2]))
}

/// `mixture_hemisphere`'s density at a direction whose cosine to the axis is `cos`.
pub fn mixture_pdf(cos: f32) -> f32 {
    0.5 * cos.max(0.0) * std::f32::consts::FRAC_1_PI + 0.25 * std::f32::consts::FRAC_1_PI
}

/// Uniform direction in the cone cos(theta) >= cos_max around z; pdf 1/(2 pi (1 - cos_max)).
pub fn uniform_cone(u1: f32, u2: f32, cos_max: f32) -> V3 {
    let c = 1.0 - u1 * (1.0 - cos_max);
    let s = (1.0 - c * c).max(0.0).sqrt();
    let phi = 2.0 * std::f32::consts::PI * u2;
    [s * phi.cos(), s * phi.sin(), c]
}

/// Uniform barycentrics (beta, gamma) on a triangle (notes §6, the fixed ex. 14.3 mapping).
pub fn uniform_triangle(u1: f32, u2: f32) -> (f32, f32) {
    let beta = 1.0 - (1.0 - u1).sqrt();
    (beta, (1.0 - beta) * u2)
}

/// Power heuristic (beta = 2) weight for a strategy with pdf `a` against one with pdf `b`.
pub fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 > 0.0 { a2 / (a2 + b2) } else { 0.0 }
}
