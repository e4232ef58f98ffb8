//! MikkTSpace tangents for normal-mapped meshes that come without a TANGENT attribute (glTF:
//! "When tangents are not specified, client implementations SHOULD calculate tangents using
//! default MikkTSpace algorithms"), so a normal map baked by a DCC tool decodes to the normals
//! it was baked from.
//!
//! The algorithm is `bevy_mikktspace` (a port of Morten Mikkelsen's reference implementation;
//! our tests compare it with the reference C code itself). It yields a tangent per triangle
//! corner; corners of one vertex whose tangents differ (a UV seam, a mirrored half) get
//! vertices of their own, as exporters do.

use pack::Vertex;
use std::collections::HashMap;

/// Tangents (xyz unit, w = ±1 the bitangent's sign: B = cross(N, T) * w) for the triangles
/// `idx` over `vertices`, from the UV set `uv_set` (0: `uv0`, 1: `texcoord1`) of the normal
/// map. Returns the vertices (tangents filled, split where corners disagree), the new triangle
/// list, and for each returned vertex the input vertex it copies.
pub fn mikktspace(vertices: &[Vertex], idx: &[u32], uv_set: u32) -> (Vec<Vertex>, Vec<u32>, Vec<u32>) {
    let mut geometry = Corners { vertices, idx, uv_set, tangents: vec![None; idx.len()] };
    // An error means no face had usable geometry: every corner keeps the fallback below.
    let _ = bevy_mikktspace::generate_tangents(&mut geometry);

    let mut out: Vec<Vertex> = vertices.to_vec();
    let mut remap: Vec<u32> = (0..vertices.len() as u32).collect();
    // The tangent each input vertex was given first, and its copies by tangent bits.
    let mut first: Vec<Option<[f32; 4]>> = vec![None; vertices.len()];
    let mut copies: HashMap<(u32, [u32; 4]), u32> = HashMap::new();
    let mut new_idx = Vec::with_capacity(idx.len());
    for (corner, &v) in idx.iter().enumerate() {
        let t = geometry.tangents[corner].unwrap_or_else(|| fallback(vertices[v as usize].normal));
        let slot = match first[v as usize] {
            None => {
                first[v as usize] = Some(t);
                out[v as usize].tangent = t;
                v
            }
            Some(f) if f == t => v,
            Some(_) => *copies.entry((v, t.map(f32::to_bits))).or_insert_with(|| {
                out.push(Vertex { tangent: t, ..vertices[v as usize] });
                remap.push(v);
                (out.len() - 1) as u32
            }),
        };
        new_idx.push(slot);
    }
    // Vertices no triangle uses still get a frame.
    for (v, f) in first.iter().enumerate() {
        if f.is_none() {
            out[v].tangent = fallback(vertices[v].normal);
        }
    }
    (out, new_idx, remap)
}

/// A unit tangent perpendicular to `n`, for corners MikkTSpace leaves without one (degenerate
/// UVs or triangles): the normal map then tilts in some frame rather than none.
pub fn fallback(n: [f32; 3]) -> [f32; 4] {
    // Project the axis least aligned with n, so the difference never vanishes.
    let axis = if n[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let d = n[0] * axis[0] + n[1] * axis[1] + n[2] * axis[2];
    let t = [axis[0] - n[0] * d, axis[1] - n[1] * d, axis[2] - n[2] * d];
    let len = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
    if len > 0.0 && len.is_finite() {
        [t[0] / len, t[1] / len, t[2] / len, 1.0]
    } else {
        [1.0, 0.0, 0.0, 1.0]
    }
}

struct Corners<'a> {
    vertices: &'a [Vertex],
    idx: &'a [u32],
    uv_set: u32,
    tangents: Vec<Option<[f32; 4]>>,
}

impl Corners<'_> {
    fn vertex(&self, face: usize, vert: usize) -> &Vertex {
        &self.vertices[self.idx[face * 3 + vert] as usize]
    }
}

impl bevy_mikktspace::Geometry for Corners<'_> {
    fn num_faces(&self) -> usize {
        self.idx.len() / 3
    }

    fn num_vertices_of_face(&self, _face: usize) -> usize {
        3
    }

    fn position(&self, face: usize, vert: usize) -> [f32; 3] {
        self.vertex(face, vert).position
    }

    fn normal(&self, face: usize, vert: usize) -> [f32; 3] {
        self.vertex(face, vert).normal
    }

    /// glTF's v points down the image while a normal map's green points up it: MikkTSpace is
    /// given (u, 1 - v), so its bitangent is the map's +Y and its sign is glTF's w as it is.
    fn tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
        let v = self.vertex(face, vert);
        let uv = if self.uv_set == 1 { v.texcoord1 } else { v.uv0 };
        [uv[0], 1.0 - uv[1]]
    }

    fn set_tangent(&mut self, tangent_space: Option<bevy_mikktspace::TangentSpace>, face: usize, vert: usize) {
        self.tangents[face * 3 + vert] = tangent_space.map(|s| s.tangent_encoded());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vertex(p: [f32; 3], uv: [f32; 2]) -> Vertex {
        Vertex { position: p, normal: [0.0, 0.0, 1.0], uv0: uv, ..Default::default() }
    }

    /// Two quads side by side in the XY plane facing +Z, the right one's texture mirrored in u
    /// (u runs 0 -> 1 -> 0 from left to right): the seam's two vertices are shared by both.
    /// glTF v points down the image, so v = 0 is the top row (y = 1).
    fn mirrored_strip() -> (Vec<Vertex>, Vec<u32>) {
        let v = vec![
            vertex([0.0, 1.0, 0.0], [0.0, 0.0]),
            vertex([1.0, 1.0, 0.0], [1.0, 0.0]),
            vertex([2.0, 1.0, 0.0], [0.0, 0.0]),
            vertex([0.0, 0.0, 0.0], [0.0, 1.0]),
            vertex([1.0, 0.0, 0.0], [1.0, 1.0]),
            vertex([2.0, 0.0, 0.0], [0.0, 1.0]),
        ];
        // Counter-clockwise seen from +Z.
        let idx = vec![3, 4, 1, 3, 1, 0, 4, 5, 2, 4, 2, 1];
        (v, idx)
    }

    /// The reference implementation (Mikkelsen's C code) on the same corners, fed the same
    /// (u, 1 - v).
    struct Reference<'a> {
        vertices: &'a [Vertex],
        idx: &'a [u32],
        out: Vec<[f32; 4]>,
    }

    impl mikktspace_sys::MikkTSpaceInterface for Reference<'_> {
        fn get_num_faces(&self) -> usize {
            self.idx.len() / 3
        }
        fn get_num_vertices_of_face(&self, _face: usize) -> usize {
            3
        }
        fn get_position(&self, face: usize, vert: usize) -> [f32; 3] {
            self.vertices[self.idx[face * 3 + vert] as usize].position
        }
        fn get_normal(&self, face: usize, vert: usize) -> [f32; 3] {
            self.vertices[self.idx[face * 3 + vert] as usize].normal
        }
        fn get_tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
            let uv = self.vertices[self.idx[face * 3 + vert] as usize].uv0;
            [uv[0], 1.0 - uv[1]]
        }
        fn set_tspace_basic(&mut self, tangent: [f32; 3], sign: f32, face: usize, vert: usize) {
            self.out[face * 3 + vert] = [tangent[0], tangent[1], tangent[2], sign];
        }
    }

    fn reference(vertices: &[Vertex], idx: &[u32]) -> Vec<[f32; 4]> {
        let mut r = Reference { vertices, idx, out: vec![[f32::NAN; 4]; idx.len()] };
        assert!(mikktspace_sys::gen_tang_space_default(&mut r), "the reference implementation failed");
        r.out
    }

    /// Every corner's tangent as the reference gives it, within float rounding.
    fn assert_matches_reference(vertices: &[Vertex], idx: &[u32]) {
        let (out, new_idx, remap) = mikktspace(vertices, idx, 0);
        let expected = reference(vertices, idx);
        for (corner, (&v, e)) in new_idx.iter().zip(&expected).enumerate() {
            let t = out[v as usize].tangent;
            assert_eq!(remap[v as usize], idx[corner], "corner {corner} moved to a copy of another vertex");
            let d = (0..3).map(|k| (t[k] - e[k]).abs()).fold(0.0, f32::max);
            assert!(d < 1e-5 && t[3] == e[3], "corner {corner}: {t:?}, reference {e:?}");
        }
    }

    #[test]
    fn mirrored_uvs_split_the_seam_and_flip_w() {
        let (v, idx) = mirrored_strip();
        let (out, new_idx, remap) = mikktspace(&v, &idx, 0);
        // The seam's two vertices are copied for the mirrored side: 8 vertices.
        assert_eq!(out.len(), 8);
        assert_eq!(&remap[6..], &[4, 1]);
        for (corner, &i) in new_idx.iter().enumerate() {
            let t = out[i as usize].tangent;
            // Left quad: u grows along +X, the bitangent (image up) is +Y = cross(+Z, +X): w = +1.
            // Right quad: u grows along -X, and cross(+Z, -X) = -Y is image down: w = -1.
            let expect = if corner < 6 { [1.0, 0.0, 0.0, 1.0] } else { [-1.0, 0.0, 0.0, -1.0] };
            let d = (0..4).map(|k| (t[k] - expect[k]).abs()).fold(0.0, f32::max);
            assert!(d < 1e-6, "corner {corner}: {t:?}, expected {expect:?}");
        }
        assert_matches_reference(&v, &idx);
    }

    #[test]
    fn a_normal_map_green_tilts_toward_image_up() {
        // shading.md 6e: a quad facing +Z with UV (0,0) at its top-left corner. B = cross(N, T) w
        // must point up the image (+Y) so that a green > 0.5 tilts the normal toward +Y.
        let (v, idx) = mirrored_strip();
        let (out, new_idx, _) = mikktspace(&v, &idx[..6], 0);
        for &i in &new_idx {
            let [tx, ty, tz, w] = out[i as usize].tangent;
            let n = out[i as usize].normal;
            let b = [(n[1] * tz - n[2] * ty) * w, (n[2] * tx - n[0] * tz) * w, (n[0] * ty - n[1] * tx) * w];
            assert!((b[1] - 1.0).abs() < 1e-6, "bitangent {b:?}");
        }
    }

    #[test]
    fn a_curved_mesh_with_seams_matches_the_reference() {
        // A UV sphere (shared vertices except along the u seam and the poles), mirrored in u on
        // its back half: smooth normals, tangents averaged across triangles, split at the
        // mirror line.
        let (rings, segments) = (9, 16);
        let mut v = Vec::new();
        for r in 0..=rings {
            let theta = std::f32::consts::PI * r as f32 / rings as f32;
            for s in 0..=segments {
                let phi = 2.0 * std::f32::consts::PI * s as f32 / segments as f32;
                let n = [theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin()];
                let u = s as f32 / segments as f32;
                let u = if u > 0.5 { 1.0 - u } else { u } * 2.0;
                v.push(Vertex { position: n, normal: n, uv0: [u, r as f32 / rings as f32], ..Default::default() });
            }
        }
        let mut idx = Vec::new();
        let at = |r: u32, s: u32| r * (segments + 1) + s;
        for r in 0..rings {
            for s in 0..segments {
                idx.extend([at(r, s), at(r + 1, s), at(r + 1, s + 1), at(r, s), at(r + 1, s + 1), at(r, s + 1)]);
            }
        }
        assert_matches_reference(&v, &idx);
        let (out, new_idx, _) = mikktspace(&v, &idx, 0);
        assert!(out.len() > v.len(), "the mirror line splits vertices");
        // (The pole rows are degenerate triangles, which borrow their neighbours' frames.)
        let area = |t: &[u32]| {
            let [a, b, c] = [0, 1, 2].map(|k| out[t[k] as usize].position);
            let (e, f) = ([b[0] - a[0], b[1] - a[1], b[2] - a[2]], [c[0] - a[0], c[1] - a[1], c[2] - a[2]]);
            let n = [e[1] * f[2] - e[2] * f[1], e[2] * f[0] - e[0] * f[2], e[0] * f[1] - e[1] * f[0]];
            (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
        };
        for t in new_idx.chunks(3).filter(|t| area(t) > 1e-6) {
            let w: Vec<f32> = t.iter().map(|&i| out[i as usize].tangent[3]).collect();
            assert!(w.iter().all(|&x| x == w[0]), "w changes within a triangle: {w:?}");
        }
    }

    #[test]
    fn degenerate_uvs_get_a_perpendicular_frame() {
        let mut v = mirrored_strip().0;
        for x in &mut v {
            x.uv0 = [0.5, 0.5];
        }
        let idx = [3, 4, 1];
        let (out, new_idx, _) = mikktspace(&v, &idx, 0);
        for &i in &new_idx {
            let t = out[i as usize].tangent;
            let n = out[i as usize].normal;
            let len = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
            assert!((len - 1.0).abs() < 1e-5 && (t[0] * n[0] + t[1] * n[1] + t[2] * n[2]).abs() < 1e-5 && t[3].abs() == 1.0, "{t:?}");
        }
    }
}
