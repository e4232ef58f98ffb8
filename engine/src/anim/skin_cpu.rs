//! The deformable mesh data of a pack, and the CPU reference of the skinning pass: morph
//! deltas first, then linear blend skinning of positions (and of normals and tangents, by the
//! inverse transpose of the blended matrix). `skin.comp` computes the same thing on the GPU.

use glam::{Mat3, Mat4, Vec3, Vec4};
use pack::{Pack, Vertex};

/// One mesh LOD ready to deform: bind-pose vertices, joints/weights and morph deltas.
pub struct DeformData {
    /// Decoded (the pack stores them quantised).
    pub vertices: Vec<Vertex>,
    /// The LOD's texture-coordinate ranges: the GPU pass re-encodes `vertices` over them, so
    /// its output's codes mean what the LOD's draws push.
    pub uv_ranges: pack::UvRanges,
    /// `None`: not skinned; every vertex follows joint matrix 0 (the node's own world matrix).
    pub joints: Option<Vec<[u16; 4]>>,
    pub weights: Option<Vec<[f32; 4]>>,
    pub targets: usize,
    /// [target][vertex][3].
    pub morph_positions: Vec<f32>,
    /// [target][vertex][3]; empty when no target moves normals.
    pub morph_normals: Vec<f32>,
}

impl DeformData {
    /// The data of the mesh on node `node`, as that node deforms it: joints and weights only
    /// when the node is bound to a skin (a mesh can also be placed unskinned elsewhere).
    pub fn for_node(pack: &Pack, node: usize, lod: usize) -> Option<DeformData> {
        let mesh = pack.manifest.nodes.get(node)?.mesh? as usize;
        let mut d = DeformData::from_pack(pack, mesh, lod);
        if pack.manifest.animation.binding(node as u32).and_then(|b| b.skin).is_none() {
            d.joints = None;
            d.weights = None;
        }
        Some(d)
    }

    pub fn from_pack(pack: &Pack, mesh: usize, lod: usize) -> DeformData {
        let m = &pack.manifest.meshes[mesh].lods[lod];
        let bytes = pack.bytes(m.vertices);
        // The range was validated to hold vertex_count vertices.
        let vertices = pack::decode_vertices(bytes, &m.uv_ranges);
        let deform = pack.manifest.animation.deform(mesh as u32);
        let d = deform.map(|d| d.lods[lod]).unwrap_or_default();
        let skin = d.skin;
        DeformData {
            vertices,
            uv_ranges: m.uv_ranges,
            joints: skin.map(|s| {
                pack.bytes(s.joints)
                    .chunks_exact(8)
                    .map(|b| std::array::from_fn(|k| u16::from_le_bytes([b[2 * k], b[2 * k + 1]])))
                    .collect()
            }),
            weights: skin.map(|s| super::f32s(pack, s.weights).chunks_exact(4).map(|w| [w[0], w[1], w[2], w[3]]).collect()),
            targets: d.morph.map_or(0, |_| deform.map_or(0, |d| d.morph_weights.len())),
            morph_positions: d.morph.map_or_else(Vec::new, |mt| super::f32s(pack, mt.positions)),
            morph_normals: d.morph.and_then(|mt| mt.normals).map_or_else(Vec::new, |r| super::f32s(pack, r)),
        }
    }
}

/// Deform every vertex into `out` (same length as `data.vertices`; attributes other than
/// position, normal and tangent are copied). `joint_matrices` are global x inverse bind; a
/// joint index past them is clamped to the last (the cooker rejects such data; this keeps a
/// damaged pack from reading out of bounds, as the shader does).
pub fn skin_cpu(data: &DeformData, morph_weights: &[f32], joint_matrices: &[Mat4], out: &mut [Vertex]) {
    let n = data.vertices.len();
    for (v, (src, dst)) in data.vertices.iter().zip(out.iter_mut()).enumerate() {
        let mut p = Vec3::from(src.position);
        let mut nrm = Vec3::from(src.normal);
        for (t, &w) in morph_weights.iter().enumerate().take(data.targets) {
            if w != 0.0 {
                let at = (t * n + v) * 3;
                p += w * Vec3::from_slice(&data.morph_positions[at..at + 3]);
                if !data.morph_normals.is_empty() {
                    nrm += w * Vec3::from_slice(&data.morph_normals[at..at + 3]);
                }
            }
        }
        let m = match (&data.joints, &data.weights) {
            (Some(j), Some(w)) => {
                let mut m = Mat4::ZERO;
                for k in 0..4 {
                    if w[v][k] != 0.0 {
                        m += joint_matrices[(j[v][k] as usize).min(joint_matrices.len() - 1)] * w[v][k];
                    }
                }
                m
            }
            _ => joint_matrices[0],
        };
        let m3 = Mat3::from_mat4(m);
        let normal_matrix = m3.inverse().transpose();
        *dst = *src;
        dst.position = (m * p.extend(1.0)).truncate().to_array();
        dst.normal = (normal_matrix * nrm).normalize_or_zero().to_array();
        let t = Vec4::from(src.tangent);
        dst.tangent = (m3 * t.truncate()).normalize_or_zero().extend(t.w).to_array();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Quat;

    fn vertex(p: [f32; 3], n: [f32; 3]) -> Vertex {
        Vertex {
            position: p,
            normal: n,
            tangent: [1.0, 0.0, 0.0, 1.0],
            ..Default::default()
        }
    }

    fn data(vertices: Vec<Vertex>, joints: Vec<[u16; 4]>, weights: Vec<[f32; 4]>) -> DeformData {
        DeformData {
            uv_ranges: pack::UvRanges::fit(&vertices),
            vertices,
            joints: Some(joints),
            weights: Some(weights),
            targets: 0,
            morph_positions: vec![],
            morph_normals: vec![],
        }
    }

    #[test]
    fn bind_pose_joint_matrices_return_the_bind_vertices_exactly() {
        // At the bind pose every joint matrix is global x inverse bind = identity.
        let verts = vec![vertex([0.3, -1.2, 5.0], [0.0, 0.6, 0.8]), vertex([2.0, 0.5, -0.25], [1.0, 0.0, 0.0])];
        let d = data(verts.clone(), vec![[0, 1, 0, 0], [1, 0, 0, 0]], vec![[0.25, 0.75, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]]);
        let mut out = verts.clone();
        skin_cpu(&d, &[], &[Mat4::IDENTITY; 2], &mut out);
        assert_eq!(out, verts);
    }

    #[test]
    fn candy_wrapper_collapse_of_linear_blend_skinning() {
        // Half/half between an untwisted joint and one twisted 180 degrees about x collapses a
        // ring vertex at radius 1 onto the axis; at 90 degrees its radius is cos(45).
        for (angle, radius) in [(std::f32::consts::PI, 0.0), (std::f32::consts::FRAC_PI_2, std::f32::consts::FRAC_1_SQRT_2)] {
            let d = data(vec![vertex([0.5, 1.0, 0.0], [0.0, 1.0, 0.0])], vec![[0, 1, 0, 0]], vec![[0.5, 0.5, 0.0, 0.0]]);
            let mut out = d.vertices.clone();
            skin_cpu(&d, &[], &[Mat4::IDENTITY, Mat4::from_quat(Quat::from_rotation_x(angle))], &mut out);
            let r = out[0].position[1].hypot(out[0].position[2]);
            assert!((r - radius).abs() < 1e-6, "angle {angle}: radius {r}");
        }
    }

    #[test]
    fn morph_is_applied_before_skinning() {
        let mut d = data(vec![vertex([1.0, 0.0, 0.0], [0.0, 0.0, 1.0])], vec![[0, 0, 0, 0]], vec![[1.0, 0.0, 0.0, 0.0]]);
        d.targets = 1;
        d.morph_positions = vec![0.0, 1.0, 0.0];
        let j = Mat4::from_scale(Vec3::splat(2.0));
        let mut out = d.vertices.clone();
        skin_cpu(&d, &[1.0], &[j], &mut out);
        assert_eq!(out[0].position, [2.0, 2.0, 0.0]); // J (P0 + dP), not J P0 + dP
    }

    #[test]
    fn normals_stay_perpendicular_under_non_uniform_scale() {
        let d = data(vec![vertex([0.0; 3], [1.0, 1.0, 0.0])], vec![[0, 0, 0, 0]], vec![[1.0, 0.0, 0.0, 0.0]]);
        let j = Mat4::from_scale(Vec3::new(3.0, 1.0, 1.0));
        let mut out = d.vertices.clone();
        skin_cpu(&d, &[], &[j], &mut out);
        // The surface tangent (1, -1, 0) maps to (3, -1, 0); the normal must stay perpendicular.
        let n = Vec3::from(out[0].normal);
        assert!(n.dot(Vec3::new(3.0, -1.0, 0.0)).abs() < 1e-5, "{n}");
    }
}
