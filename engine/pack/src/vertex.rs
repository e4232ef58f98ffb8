//! The vertex as a pack stores it and the GPU reads it: 36 bytes, quantised, interleaved (the
//! one encoder and decoder; shaders/octahedral.glsl is the shaders' half of the same code).
//!
//! | bytes | attribute | format | decoded |
//! |---|---|---|---|
//! | 0..12 | position | f32 x3 | as stored (exact: the depth pre-pass and skinning need it bit for bit) |
//! | 12..16 | normal | snorm16 x2 | octahedral unit vector |
//! | 16..20 | tangent | sint16 x2 | octahedral x as snorm16; y and the bitangent's sign as one code (below) |
//! | 20..24 | uv0 | unorm16 x2 | `q * scale + offset` over the LOD's uv0 bounds (`UvRanges`) |
//! | 24..28 | uv1 (lightmap) | unorm16 x2 | the same over the LOD's uv1 bounds |
//! | 28..32 | texcoord1 | unorm16 x2 | the same over the LOD's texcoord1 bounds |
//! | 32..36 | colour | unorm8 x4 | linear RGBA |
//!
//! Why these: a 16-bit octahedral normal is within 0.01° of the original (a 16-bit component
//! per axis would waste a third of its codes on non-unit vectors); texture coordinates over
//! their own bounds keep 16 bits of the range that is used (half floats have 11 bits of
//! mantissa: at u near 1 a step is 1/2048, a quarter texel of a 512² texture); positions stay
//! f32 because animated and skinned positions leave any bounds the cooker could fit.

use crate::manifest::Vertex;
use serde::{Deserialize, Serialize};

pub const VERTEX_STRIDE: usize = 36;

/// What kind of data a vertex attribute holds, so the runtime can pick a Vulkan format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AttributeFormat {
    F32x3,
    Snorm16x2,
    Sint16x2,
    Unorm16x2,
    Unorm8x4,
}

/// (shader location, byte offset, format) of every attribute of the stored vertex.
pub const VERTEX_ATTRIBUTES: [(u32, u32, AttributeFormat); 7] = [
    (0, 0, AttributeFormat::F32x3),
    (1, 12, AttributeFormat::Snorm16x2),
    (2, 16, AttributeFormat::Sint16x2),
    (3, 20, AttributeFormat::Unorm16x2),
    (4, 24, AttributeFormat::Unorm16x2),
    (13, 28, AttributeFormat::Unorm16x2),
    (5, 32, AttributeFormat::Unorm8x4),
];

/// An affine map of 16-bit codes onto one texture coordinate set: `uv = q / 65535 * scale +
/// offset` per axis, as `[scale_u, scale_v, offset_u, offset_v]` (the shaders' vec4).
pub type UvRange = [f32; 4];

/// A LOD's three texture-coordinate ranges (its vertices' bounds of each set).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct UvRanges {
    pub uv0: UvRange,
    pub uv1: UvRange,
    pub texcoord1: UvRange,
}

/// Bounds of the three coordinate sets (uv0, uv1, texcoord1), each `[lo_u, lo_v, hi_u, hi_v]`;
/// `UvBounds::EMPTY` holds nothing. The cooker gives every LOD of a mesh, and every chunk of a
/// split one, the same bounds, so a vertex they share is stored alike in all of them (no seam
/// between chunks, no lightmap shift at a LOD's locked border).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct UvBounds(pub [[f32; 4]; 3]);

impl UvBounds {
    pub const EMPTY: UvBounds = UvBounds([[f32::INFINITY, f32::INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY]; 3]);

    /// The bounds of `vertices`' coordinates. A non-finite coordinate is the cooker's to reject;
    /// here it must not poison the bounds of the others.
    pub fn of(vertices: &[Vertex]) -> UvBounds {
        let mut b = UvBounds::EMPTY;
        for v in vertices {
            for (k, uv) in [v.uv0, v.uv1, v.texcoord1].into_iter().enumerate() {
                for c in 0..2 {
                    if uv[c].is_finite() {
                        b.0[k][c] = b.0[k][c].min(uv[c]);
                        b.0[k][2 + c] = b.0[k][2 + c].max(uv[c]);
                    }
                }
            }
        }
        b
    }

    pub fn union(&self, o: &UvBounds) -> UvBounds {
        UvBounds(std::array::from_fn(|k| std::array::from_fn(|c| if c < 2 { self.0[k][c].min(o.0[k][c]) } else { self.0[k][c].max(o.0[k][c]) })))
    }
}

impl UvRanges {
    /// The ranges of `bounds` (zero for an empty set).
    pub fn from_bounds(bounds: &UvBounds) -> UvRanges {
        let range = |b: [f32; 4]| -> UvRange {
            let axis = |c: usize| if b[c] <= b[2 + c] { (b[2 + c] - b[c], b[c]) } else { (0.0, 0.0) };
            let ((su, ou), (sv, ov)) = (axis(0), axis(1));
            [su, sv, ou, ov]
        };
        UvRanges { uv0: range(bounds.0[0]), uv1: range(bounds.0[1]), texcoord1: range(bounds.0[2]) }
    }

    /// The ranges of `vertices`' own bounds.
    pub fn fit(vertices: &[Vertex]) -> UvRanges {
        UvRanges::from_bounds(&UvBounds::of(vertices))
    }

    pub fn all(&self) -> [UvRange; 3] {
        [self.uv0, self.uv1, self.texcoord1]
    }

    /// The largest error the 16-bit codes can make in each set, per axis: half a step.
    pub fn max_error(&self) -> [f32; 3] {
        self.all().map(|r| r[0].abs().max(r[1].abs()) / 65535.0 * 0.5)
    }
}

fn unorm16(x: f32, scale: f32, offset: f32) -> u16 {
    if !(scale > 0.0) {
        return 0;
    }
    ((x - offset) / scale * 65535.0).round().clamp(0.0, 65535.0) as u16
}

fn from_unorm16(q: u16, scale: f32, offset: f32) -> f32 {
    q as f32 / 65535.0 * scale + offset
}

fn snorm16(x: f32) -> i16 {
    (x.clamp(-1.0, 1.0) * 32767.0).round() as i16
}

fn from_snorm16(q: i16) -> f32 {
    (q as f32 / 32767.0).max(-1.0)
}

/// The octahedral map of a direction onto [-1, 1]² (Cigolle et al. 2014); a zero or non-finite
/// vector maps to +z.
pub fn oct_encode(n: [f32; 3]) -> [f32; 2] {
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    if !(l1 > 0.0) || !l1.is_finite() {
        return [0.0, 0.0];
    }
    let (x, y) = (n[0] / l1, n[1] / l1);
    if n[2] >= 0.0 {
        [x, y]
    } else {
        let s = |v: f32| if v >= 0.0 { 1.0 } else { -1.0 };
        [(1.0 - y.abs()) * s(x), (1.0 - x.abs()) * s(y)]
    }
}

/// The unit vector of an octahedral point.
pub fn oct_decode(e: [f32; 2]) -> [f32; 3] {
    let mut v = [e[0], e[1], 1.0 - e[0].abs() - e[1].abs()];
    let t = (-v[2]).max(0.0);
    v[0] += if v[0] >= 0.0 { -t } else { t };
    v[1] += if v[1] >= 0.0 { -t } else { t };
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|c| c / l)
}

/// A tangent (xyz, w = the bitangent's sign) as two i16: octahedral x as snorm16, and y as
/// `c` in 1..=32767 with y = (c - 16384) / 16383 (15 bits; -1, 0 and 1 exact), negated for a
/// negative w.
fn tangent_code(t: [f32; 4]) -> [i16; 2] {
    let e = oct_encode([t[0], t[1], t[2]]);
    let c = (e[1].clamp(-1.0, 1.0) * 16383.0).round() as i16 + 16384;
    [snorm16(e[0]), if t[3] < 0.0 { -c } else { c }]
}

fn tangent_from_code(q: [i16; 2]) -> [f32; 4] {
    let y = (q[1].unsigned_abs() as f32 - 16384.0) / 16383.0;
    let d = oct_decode([from_snorm16(q[0]), y]);
    [d[0], d[1], d[2], if q[1] < 0 { -1.0 } else { 1.0 }]
}

/// The stored bytes of `vertices` with their coordinates over `ranges`.
pub fn encode_vertices_with(vertices: &[Vertex], ranges: &UvRanges) -> Vec<u8> {
    let mut out = Vec::with_capacity(vertices.len() * VERTEX_STRIDE);
    for v in vertices {
        for c in v.position {
            out.extend_from_slice(&c.to_le_bytes());
        }
        let n = oct_encode(v.normal);
        for q in [snorm16(n[0]), snorm16(n[1])].into_iter().chain(tangent_code(v.tangent)) {
            out.extend_from_slice(&q.to_le_bytes());
        }
        for (uv, r) in [(v.uv0, ranges.uv0), (v.uv1, ranges.uv1), (v.texcoord1, ranges.texcoord1)] {
            for c in 0..2 {
                out.extend_from_slice(&unorm16(uv[c], r[c], r[2 + c]).to_le_bytes());
            }
        }
        out.extend_from_slice(&v.color);
    }
    out
}

/// The stored bytes of `vertices` and the ranges their coordinates are stored over.
pub fn encode_vertices(vertices: &[Vertex]) -> (Vec<u8>, UvRanges) {
    let ranges = UvRanges::fit(vertices);
    (encode_vertices_with(vertices, &ranges), ranges)
}

/// The vertices of `bytes` (`VERTEX_STRIDE` each, any alignment; a partial tail is ignored).
pub fn decode_vertices(bytes: &[u8], ranges: &UvRanges) -> Vec<Vertex> {
    bytes
        .chunks_exact(VERTEX_STRIDE)
        .map(|b| {
            let f = |k: usize| f32::from_le_bytes(b[4 * k..4 * k + 4].try_into().unwrap());
            let h = |at: usize| [b[at], b[at + 1]];
            let i = |at: usize| i16::from_le_bytes(h(at));
            let u = |at: usize| u16::from_le_bytes(h(at));
            let uv = |at: usize, r: UvRange| [from_unorm16(u(at), r[0], r[2]), from_unorm16(u(at + 2), r[1], r[3])];
            Vertex {
                position: [f(0), f(1), f(2)],
                normal: oct_decode([from_snorm16(i(12)), from_snorm16(i(14))]),
                tangent: tangent_from_code([i(16), i(18)]),
                uv0: uv(20, ranges.uv0),
                uv1: uv(24, ranges.uv1),
                texcoord1: uv(28, ranges.texcoord1),
                color: [b[32], b[33], b[34], b[35]],
                _pad: [0; 3],
            }
        })
        .collect()
}

/// The positions alone (the first 12 bytes of each vertex), for bounds, collision and culling.
pub fn decode_positions(bytes: &[u8]) -> Vec<[f32; 3]> {
    bytes.chunks_exact(VERTEX_STRIDE).map(|b| std::array::from_fn(|k| f32::from_le_bytes(b[4 * k..4 * k + 4].try_into().unwrap()))).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn angle_deg(a: [f32; 3], b: [f32; 3]) -> f64 {
        let d: f64 = (0..3).map(|k| a[k] as f64 * b[k] as f64).sum();
        let la: f64 = (0..3).map(|k| (a[k] as f64).powi(2)).sum::<f64>().sqrt();
        let lb: f64 = (0..3).map(|k| (b[k] as f64).powi(2)).sum::<f64>().sqrt();
        (d / la / lb).clamp(-1.0, 1.0).acos().to_degrees()
    }

    /// Directions spread over the sphere (a Fibonacci lattice) plus the axes and octant corners,
    /// where the octahedral fold has its seams.
    fn directions() -> Vec<[f32; 3]> {
        let n = 20_000;
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let mut d: Vec<[f32; 3]> = (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let r = (1.0 - z * z).sqrt();
                let phi = golden * i as f64;
                [(r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32]
            })
            .collect();
        for s in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] {
            d.push(s);
            d.push(s.map(|c: f32| -c));
        }
        for k in 0..8 {
            let s = |b: usize| if k >> b & 1 == 1 { -1.0 } else { 1.0 };
            d.push([s(0) / 3f32.sqrt(), s(1) / 3f32.sqrt(), s(2) / 3f32.sqrt()]);
        }
        d
    }

    #[test]
    fn normals_and_tangents_stay_within_half_a_degree() {
        let dirs = directions();
        let verts: Vec<Vertex> = dirs
            .iter()
            .enumerate()
            .map(|(i, &d)| Vertex { normal: d, tangent: [d[1], d[2], d[0], if i % 2 == 0 { 1.0 } else { -1.0 }], ..Default::default() })
            .collect();
        let (bytes, ranges) = encode_vertices(&verts);
        assert_eq!(bytes.len(), verts.len() * VERTEX_STRIDE);
        let back = decode_vertices(&bytes, &ranges);
        let (mut worst_n, mut worst_t) = (0.0f64, 0.0f64);
        for (a, b) in verts.iter().zip(&back) {
            worst_n = worst_n.max(angle_deg(a.normal, b.normal));
            worst_t = worst_t.max(angle_deg([a.tangent[0], a.tangent[1], a.tangent[2]], [b.tangent[0], b.tangent[1], b.tangent[2]]));
            assert_eq!(a.tangent[3], b.tangent[3], "the bitangent's sign");
        }
        // 16-bit octahedral codes: about 0.005° for the normal, twice that for the tangent's
        // 15-bit y; the bound the issue sets is 0.5°.
        assert!(worst_n < 0.01, "normal error {worst_n}°");
        assert!(worst_t < 0.02, "tangent error {worst_t}°");
    }

    #[test]
    fn positions_and_colours_are_exact_and_uvs_within_half_a_step() {
        let verts: Vec<Vertex> = (0..1000)
            .map(|i| {
                let x = i as f32 * 0.37 - 120.0;
                Vertex {
                    position: [x, x.sin() * 1e4, 1e-7 * x],
                    normal: [0.0, 0.0, 1.0],
                    tangent: [1.0, 0.0, 0.0, 1.0],
                    uv0: [(x * 0.013).sin() * 3.0, x * 0.001 - 2.0],
                    uv1: [i as f32 * 2.047, 2047.0 - i as f32],
                    texcoord1: [0.25, 0.25],
                    color: [i as u8, (i / 4) as u8, 7, 255],
                    _pad: [0; 3],
                }
            })
            .collect();
        let (bytes, ranges) = encode_vertices(&verts);
        let back = decode_vertices(&bytes, &ranges);
        let step = ranges.max_error();
        for (a, b) in verts.iter().zip(&back) {
            assert_eq!(a.position, b.position);
            assert_eq!(a.color, b.color);
            for (k, (x, y)) in [(a.uv0, b.uv0), (a.uv1, b.uv1), (a.texcoord1, b.texcoord1)].into_iter().enumerate() {
                for c in 0..2 {
                    // Half a step, plus f32 rounding of the affine map.
                    let tol = step[k] * 1.001 + 4.0 * f32::EPSILON * (x[c].abs() + 1.0);
                    assert!((x[c] - y[c]).abs() <= tol, "set {k} axis {c}: {} vs {}", x[c], y[c]);
                }
            }
        }
        // A constant set decodes exactly.
        assert!(back.iter().all(|v| v.texcoord1 == [0.25, 0.25]));
        assert_eq!(decode_positions(&bytes)[5], verts[5].position);
        // Decoding and encoding again gives the same coordinate codes (skinning re-encodes what
        // it read).
        let again = encode_vertices_with(&back, &ranges);
        for (x, y) in bytes.chunks_exact(VERTEX_STRIDE).zip(again.chunks_exact(VERTEX_STRIDE)) {
            assert_eq!(x[20..], y[20..]);
        }
    }
}
