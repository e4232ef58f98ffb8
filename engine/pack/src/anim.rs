//! The animation section of a pack (format version 3): skins, keyframe clips and the per-vertex
//! data of meshes that deform (joints/weights, morph target deltas). It is its own section so
//! that static content (meshes, nodes) keeps the shape it had; big arrays live in the data blob
//! in the layout the runtime samples and the skinning pass reads, without conversion.

use crate::{BufferRange, Manifest, PackError};
use serde::{Deserialize, Serialize};

/// The most joints a skin may have. The skinning pass reads joint matrices from a storage buffer
/// of any length; this only bounds what a malformed pack can make the runtime allocate.
pub const MAX_JOINTS: usize = 65536;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Animation {
    pub skins: Vec<Skin>,
    pub clips: Vec<Clip>,
    /// Meshes that deform, at most one entry per mesh.
    pub meshes: Vec<DeformMesh>,
    /// Mesh nodes bound to a skin and/or carrying their own morph weights.
    pub nodes: Vec<NodeBinding>,
}

/// A skeleton: joint nodes and their inverse bind matrices. The joint matrix of joint j is
/// `global(joints[j]) * inverse_bind[j]` (glTF); the skinned mesh node's own transform is ignored.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Skin {
    pub name: String,
    /// Node indices, one per joint; the joint indices of `SkinWeights` index this list.
    pub joints: Vec<u32>,
    /// f32 [joint][16], column-major 4x4 per joint.
    pub inverse_bind: BufferRange,
}

/// Which node property a channel animates. Values have 3 (translation, scale), 4 (rotation,
/// unit quaternion xyzw) or the node's morph target count (weights) components.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ChannelPath {
    Translation,
    Rotation,
    Scale,
    Weights,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Interpolation {
    Step,
    Linear,
    Cubicspline,
}

/// One animated property of one node, as a glTF sampler: key times and values. Cubic splines keep
/// [in tangent, value, out tangent] per key, tangents per second.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Channel {
    pub node: u32,
    pub path: ChannelPath,
    pub interpolation: Interpolation,
    pub key_count: u32,
    pub components: u32,
    /// f32 [key]: seconds, finite and strictly increasing (the cooker rejects anything else).
    pub times: BufferRange,
    /// f32 [key][components], or f32 [key][3][components] for `Cubicspline`.
    pub values: BufferRange,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Clip {
    pub name: String,
    /// Seconds: the last key time over all channels.
    pub duration: f32,
    pub channels: Vec<Channel>,
}

/// The deformation data of one mesh, per LOD (parallel to that LOD's vertices).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeformMesh {
    pub mesh: u32,
    /// Default morph weights (glTF `mesh.weights`, zeros when absent); one per morph target.
    pub morph_weights: Vec<f32>,
    /// One per LOD of the mesh.
    pub lods: Vec<DeformLod>,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct DeformLod {
    /// u16 [vertex][4] joint indices and f32 [vertex][4] weights summing to 1 (cooker-normalised).
    pub skin: Option<SkinWeights>,
    /// f32 [target][vertex][3] position deltas, and normal deltas when any target has them,
    /// over this LOD's own vertices (the cooker carries LOD 0's deltas to each level). Every LOD
    /// of a mesh has them or none does, and normal deltas likewise.
    pub morph: Option<MorphTargets>,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SkinWeights {
    pub joints: BufferRange,
    pub weights: BufferRange,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MorphTargets {
    pub positions: BufferRange,
    pub normals: Option<BufferRange>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NodeBinding {
    pub node: u32,
    pub skin: Option<u32>,
    /// Morph weights of this instance (glTF `node.weights`), overriding the mesh's defaults.
    pub weights: Option<Vec<f32>>,
}

impl Animation {
    /// The deformation entry of mesh `mesh`, if it deforms.
    pub fn deform(&self, mesh: u32) -> Option<&DeformMesh> {
        self.meshes.iter().find(|d| d.mesh == mesh)
    }

    /// The binding of node `node`, if any.
    pub fn binding(&self, node: u32) -> Option<&NodeBinding> {
        self.nodes.iter().find(|b| b.node == node)
    }

    /// Every index and range points at something that exists and has the size its counts imply.
    pub(crate) fn validate(&self, m: &Manifest, in_data: &dyn Fn(&str, BufferRange, u64) -> Result<(), PackError>) -> Result<(), PackError> {
        let bad = |what: String| Err(PackError::Malformed(what));
        for (i, s) in self.skins.iter().enumerate() {
            if s.joints.is_empty() || s.joints.len() > MAX_JOINTS {
                return bad(format!("skin {i} '{}': {} joints (1..={MAX_JOINTS} supported)", s.name, s.joints.len()));
            }
            if let Some(j) = s.joints.iter().find(|&&j| j as usize >= m.nodes.len()) {
                return bad(format!("skin {i} '{}': joint node {j} does not exist", s.name));
            }
            in_data(&format!("skin {i} '{}' inverse bind matrices", s.name), s.inverse_bind, s.joints.len() as u64 * 64)?;
        }
        let mut seen = vec![false; m.meshes.len()];
        for d in &self.meshes {
            let Some(mesh) = m.meshes.get(d.mesh as usize) else {
                return bad(format!("animation: deforming mesh {} does not exist", d.mesh));
            };
            if std::mem::replace(&mut seen[d.mesh as usize], true) {
                return bad(format!("animation: mesh {} '{}' has two deformation entries", d.mesh, mesh.name));
            }
            if d.lods.len() != mesh.lods.len() {
                return bad(format!("mesh {} '{}': deformation data for {} LODs, the mesh has {}", d.mesh, mesh.name, d.lods.len(), mesh.lods.len()));
            }
            let targets = d.morph_weights.len() as u64;
            // What a LOD's morph deltas hold: none, positions, or positions and normals.
            let kind = |dl: &DeformLod| match dl.morph {
                None => "none",
                Some(MorphTargets { normals: None, .. }) => "positions",
                Some(_) => "positions and normals",
            };
            for (l, (dl, lod)) in d.lods.iter().zip(&mesh.lods).enumerate() {
                let what = format!("mesh {} '{}' LOD {l}", d.mesh, mesh.name);
                let n = lod.vertex_count as u64;
                if kind(dl) != kind(&d.lods[0]) {
                    return bad(format!("{what}: morph deltas of {}, LOD 0's of {} (every LOD morphs alike)", kind(dl), kind(&d.lods[0])));
                }
                if let Some(s) = dl.skin {
                    in_data(&format!("{what} joints"), s.joints, n * 8)?;
                    in_data(&format!("{what} weights"), s.weights, n * 16)?;
                }
                if let Some(mt) = dl.morph {
                    if targets == 0 {
                        return bad(format!("{what}: morph deltas but no morph targets"));
                    }
                    in_data(&format!("{what} morph positions"), mt.positions, targets * n * 12)?;
                    if let Some(r) = mt.normals {
                        in_data(&format!("{what} morph normals"), r, targets * n * 12)?;
                    }
                }
            }
        }
        let targets_of = |node: usize| -> usize { m.nodes[node].mesh.and_then(|mesh| self.deform(mesh)).map_or(0, |d| d.morph_weights.len()) };
        for b in &self.nodes {
            let Some(node) = m.nodes.get(b.node as usize) else {
                return bad(format!("animation: bound node {} does not exist", b.node));
            };
            let what = format!("node {} '{}'", b.node, node.name);
            if let Some(s) = b.skin {
                let skinned = node.mesh.and_then(|mesh| self.deform(mesh)).is_some_and(|d| d.lods.iter().all(|l| l.skin.is_some()));
                if s as usize >= self.skins.len() || !skinned {
                    return bad(format!("{what}: skin {s} does not exist or the node's mesh has no joints and weights"));
                }
            }
            if let Some(w) = b.weights.as_ref().filter(|w| w.len() != targets_of(b.node as usize)) {
                return bad(format!("{what}: {} morph weights for {} morph targets", w.len(), targets_of(b.node as usize)));
            }
        }
        for (c, clip) in self.clips.iter().enumerate() {
            if !(clip.duration >= 0.0 && clip.duration.is_finite()) {
                return bad(format!("clip {c} '{}': duration {} is not a finite non-negative time", clip.name, clip.duration));
            }
            for (k, ch) in clip.channels.iter().enumerate() {
                let what = format!("clip {c} '{}' channel {k} ({:?})", clip.name, ch.path);
                if ch.node as usize >= m.nodes.len() {
                    return bad(format!("{what}: node {} does not exist", ch.node));
                }
                let want = match ch.path {
                    ChannelPath::Translation | ChannelPath::Scale => 3,
                    ChannelPath::Rotation => 4,
                    ChannelPath::Weights => targets_of(ch.node as usize) as u32,
                };
                if ch.components != want || want == 0 {
                    return bad(format!("{what}: {} components, node {} needs {want}", ch.components, ch.node));
                }
                let cubic = ch.interpolation == Interpolation::Cubicspline;
                if ch.key_count == 0 || (cubic && ch.key_count < 2) {
                    return bad(format!("{what}: {} keys is too few for {:?}", ch.key_count, ch.interpolation));
                }
                let keys = ch.key_count as u64;
                in_data(&format!("{what} times"), ch.times, keys * 4)?;
                in_data(&format!("{what} values"), ch.values, keys * ch.components as u64 * if cubic { 3 } else { 1 } * 4)?;
            }
        }
        Ok(())
    }
}
