//! Ray origins off a surface without self-intersection.

/// Ray origin just off a surface point `p` on the side the geometric normal `n` points to
/// (pass `-n` to leave through the back). Wächter & Binder, Ray Tracing Gems ch. 6: move by a
/// fixed number of ulps (256 * n per axis, in integer space) so the offset scales with |p|;
/// near the origin, where ulps are tiny, use a small absolute offset instead.
pub fn offset_ray(p: [f32; 3], n: [f32; 3]) -> [f32; 3] {
    const ORIGIN: f32 = 1.0 / 32.0;
    const FLOAT_SCALE: f32 = 1.0 / 65536.0;
    const INT_SCALE: f32 = 256.0;
    [0, 1, 2].map(|k| {
        if p[k].abs() < ORIGIN {
            return p[k] + FLOAT_SCALE * n[k];
        }
        let of = (INT_SCALE * n[k]) as i32;
        let bits = p[k].to_bits() as i32;
        f32::from_bits(if p[k] < 0.0 { bits - of } else { bits + of } as u32)
    })
}

