//! The scene IR on the Rust side: what glTF import produces and the pack writer consumes. It
//! mirrors `asset_pipeline/ir.py`; `wire` converts between the two.

use crate::mips::Usage;
use pack::{LightmapLayout, Material, Node, Sky, Spawn, TextureFormat};

/// One level of detail: per-vertex attributes (all the same length) and triangles.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LodIr {
    pub positions: Vec<[f32; 3]>,
    pub normals: Option<Vec<[f32; 3]>>,
    pub tangents: Option<Vec<[f32; 4]>>,
    pub uv0: Option<Vec<[f32; 2]>>,
    /// Lightmap UVs (the uv2 stage's), in the mesh's own lightmap space.
    pub uv1: Option<Vec<[f32; 2]>>,
    /// glTF TEXCOORD_1 (textures whose slot reads set 1).
    pub texcoord1: Option<Vec<[f32; 2]>>,
    /// Linear RGBA, 8-bit UNORM.
    pub colors: Option<Vec<[u8; 4]>>,
    pub joints: Option<Vec<[u16; 4]>>,
    pub weights: Option<Vec<[f32; 4]>>,
    pub triangles: Vec<[u32; 3]>,
    /// Material index per triangle.
    pub materials: Vec<u32>,
    /// Lightmap block per triangle (the mesh's own blocks; a static instance's region puts
    /// block b on its page + b), once the uv2 stage has run.
    pub lightmap_blocks: Option<Vec<u32>>,
    /// Geometric error to LOD 0 in metres (object space).
    pub error: f32,
    /// Morph target position deltas, [target][vertex]; empty when the mesh has none.
    pub morph_positions: Vec<Vec<[f32; 3]>>,
    /// Morph target normal deltas, [target][vertex]; empty when no target moves normals.
    pub morph_normals: Vec<Vec<[f32; 3]>>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct MeshIr {
    pub name: String,
    pub lods: Vec<LodIr>,
    /// Default morph target weights (glTF `mesh.weights`, zeros when absent), one per target.
    pub morph_weights: Vec<f32>,
    /// Bounds its texture coordinates are stored over, besides its own (`pack::UvBounds`): the
    /// chunk stage gives each chunk its whole mesh's, so chunks store a shared vertex alike.
    pub uv_bounds: Option<pack::UvBounds>,
}

/// A skeleton: joint node indices (into `SceneIr::nodes`) and inverse bind matrices (column-major).
#[derive(Debug, Clone, PartialEq)]
pub struct SkinIr {
    pub name: String,
    pub joints: Vec<u32>,
    pub inverse_bind: Vec<[f32; 16]>,
}

/// One animated node property (see `pack::Channel`): `values` holds `times.len()` keys of
/// `components` floats, three times that for cubic splines (in tangent, value, out tangent).
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelIr {
    pub node: u32,
    pub path: pack::ChannelPath,
    pub interpolation: pack::Interpolation,
    pub components: u32,
    pub times: Vec<f32>,
    pub values: Vec<f32>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct ClipIr {
    pub name: String,
    pub channels: Vec<ChannelIr>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct TextureIr {
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub format: TextureFormat,
    /// How its mip levels are made (colour, data, normal map, HDR).
    pub usage: Usage,
    /// Tightly packed texels per mip level, level 0 first.
    pub mips: Vec<Vec<u8>>,
    /// How the runtime samples it (and which edges its mip filter wraps across).
    pub sampler: pack::Sampler,
}

#[derive(Debug, Clone, PartialEq, Default)]
pub struct SceneIr {
    pub name: String,
    pub source: String,
    pub meshes: Vec<MeshIr>,
    pub materials: Vec<Material>,
    pub textures: Vec<TextureIr>,
    pub nodes: Vec<Node>,
    pub lights: Vec<pack::Light>,
    pub spawns: Vec<Spawn>,
    /// Vertical cylinders of the solid geometry (levels only), for the flocks to avoid.
    pub pillars: Vec<pack::Pillar>,
    pub sky: Option<Sky>,
    pub lightmap: Option<LightmapLayout>,
    pub probes: Option<ProbesIr>,
    /// Baked reflection probes (`pack::ReflectionProbes`), their cubes' bytes inline.
    pub reflection_probes: Option<ReflectionProbesIr>,
    pub skins: Vec<SkinIr>,
    pub clips: Vec<ClipIr>,
    /// Mesh nodes bound to a skin or carrying their own morph weights.
    pub bindings: Vec<pack::NodeBinding>,
    /// Problems the import fixed on its own (e.g. influences reduced to 4), one line each.
    pub warnings: Vec<String>,
}

/// Baked reflection probes: the pack's `ReflectionProbes` with each probe's cube (half RGBA or
/// BC6H, `pack::ReflectionProbe::data`'s layout) held here instead of a range of the pack.
#[derive(Debug, Clone, PartialEq)]
pub struct ReflectionProbesIr {
    pub face_size: u32,
    pub levels: u32,
    /// `Rgba16Float` or `Bc6hUfloat` (`pack::ReflectionProbes::format`).
    pub format: pack::TextureFormat,
    /// Each probe with a placeholder `data` range, and its cube's bytes.
    pub probes: Vec<(pack::ReflectionProbe, Vec<u8>)>,
}

/// Baked irradiance probes on a grid (see `pack::ProbeGrid`): per probe 27 SH floats (9 x rgb)
/// and a sun visibility.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ProbesIr {
    pub origin: [f32; 3],
    pub spacing: [f32; 3],
    pub counts: [u32; 3],
    pub sh: Vec<[f32; 27]>,
    pub sun_visibility: Vec<f32>,
}

impl LodIr {
    /// Check that every attribute has one entry per vertex and every index is in range, so the
    /// pack writer can index without failing. `what` names the LOD in the message.
    pub fn validate(&self, what: &str) -> Result<(), String> {
        let n = self.positions.len();
        let lens = [
            ("normal", self.normals.as_ref().map(Vec::len)),
            ("tangent", self.tangents.as_ref().map(Vec::len)),
            ("uv0", self.uv0.as_ref().map(Vec::len)),
            ("uv1", self.uv1.as_ref().map(Vec::len)),
            ("texcoord1", self.texcoord1.as_ref().map(Vec::len)),
            ("color", self.colors.as_ref().map(Vec::len)),
            ("joints", self.joints.as_ref().map(Vec::len)),
            ("weights", self.weights.as_ref().map(Vec::len)),
        ];
        for (name, len) in lens {
            if let Some(len) = len.filter(|&l| l != n) {
                return Err(format!("{what}: attribute '{name}' has {len} entries for {n} vertices"));
            }
        }
        if let Some(i) = self.triangles.iter().flatten().position(|&i| i as usize >= n) {
            return Err(format!("{what}: triangle index {} (corner {i}) is out of range for {n} vertices", self.triangles[i / 3][i % 3]));
        }
        let m = self.triangles.len();
        if self.materials.len() != m {
            return Err(format!("{what}: {} material ids for {m} triangles", self.materials.len()));
        }
        if let Some(p) = self.lightmap_blocks.as_ref().filter(|p| p.len() != m) {
            return Err(format!("{what}: {} lightmap blocks for {m} triangles", p.len()));
        }
        for (t, d) in self.morph_positions.iter().chain(&self.morph_normals).enumerate() {
            if d.len() != n {
                return Err(format!("{what}: morph target {t} has {} deltas for {n} vertices", d.len()));
            }
        }
        if !self.morph_normals.is_empty() && self.morph_normals.len() != self.morph_positions.len() {
            return Err(format!("{what}: {} normal delta sets for {} morph targets", self.morph_normals.len(), self.morph_positions.len()));
        }
        if let Some(w) = &self.weights {
            // The skinning pass blends with these as given: they must be a convex combination.
            if let Some(v) = w.iter().position(|w| !w.iter().all(|x| x.is_finite() && *x >= 0.0) || (w.iter().sum::<f32>() - 1.0).abs() > 1e-4) {
                return Err(format!("{what}: skin weights of vertex {v} ({:?}) are not non-negative with sum 1", w[v]));
            }
        }
        if !self.error.is_finite() || self.error < 0.0 {
            return Err(format!("{what}: error {} is not a finite distance", self.error));
        }
        Ok(())
    }
}

impl SceneIr {
    /// Skins, node bindings and clips refer to things that exist and agree with the meshes: a
    /// skinned node's mesh has joints and weights and uses no joint past its skin's; every clip
    /// channel passes `anim::validate_channel` and has the component count its path needs.
    /// Messages name the clip and channel (or node, mesh and skin).
    pub fn check_animation(&self) -> Result<(), String> {
        let node_name = |i: u32| self.nodes.get(i as usize).map_or_else(|| format!("node {i}"), |n| format!("node {i} '{}'", n.name));
        for (i, s) in self.skins.iter().enumerate() {
            if s.joints.is_empty() || s.joints.len() != s.inverse_bind.len() {
                return Err(format!("skin {i} '{}': {} joints and {} inverse bind matrices", s.name, s.joints.len(), s.inverse_bind.len()));
            }
            if let Some(j) = s.joints.iter().find(|&&j| j as usize >= self.nodes.len()) {
                return Err(format!("skin {i} '{}': joint node {j} does not exist", s.name));
            }
        }
        for b in &self.bindings {
            let Some(node) = self.nodes.get(b.node as usize) else { return Err(format!("binding of node {}: no such node", b.node)) };
            let Some(mesh) = node.mesh.and_then(|m| self.meshes.get(m as usize)) else {
                return Err(format!("{}: has a skin or morph weights but no mesh", node_name(b.node)));
            };
            if let Some(w) = b.weights.as_ref().filter(|w| w.len() != mesh.morph_weights.len()) {
                return Err(format!("{}: {} morph weights for mesh '{}' with {} morph targets", node_name(b.node), w.len(), mesh.name, mesh.morph_weights.len()));
            }
            let Some(s) = b.skin else { continue };
            let skin = self.skins.get(s as usize).ok_or_else(|| format!("{}: skin {s} does not exist", node_name(b.node)))?;
            for (l, lod) in mesh.lods.iter().enumerate() {
                let (Some(j), Some(w)) = (&lod.joints, &lod.weights) else {
                    return Err(format!("{}: skinned by skin {s} '{}' but mesh '{}' LOD {l} has no JOINTS_0/WEIGHTS_0", node_name(b.node), skin.name, mesh.name));
                };
                let n = skin.joints.len();
                let used = j.iter().zip(w).enumerate().find_map(|(v, (j, w))| j.iter().zip(w).find(|(&j, &w)| w > 0.0 && j as usize >= n).map(|(&j, _)| (v, j)));
                if let Some((v, j)) = used {
                    return Err(format!(
                        "{}: mesh '{}' LOD {l} vertex {} uses joint {j}, but skin {s} '{}' has only {} joints (joint index out of range)",
                        node_name(b.node),
                        mesh.name,
                        v,
                        skin.name,
                        n
                    ));
                }
            }
        }
        for (c, clip) in self.clips.iter().enumerate() {
            for (k, ch) in clip.channels.iter().enumerate() {
                let what = format!("clip {c} '{}' channel {k} ({:?} of {})", clip.name, ch.path, node_name(ch.node));
                let node = self.nodes.get(ch.node as usize).ok_or_else(|| format!("{what}: no such node"))?;
                let want = match ch.path {
                    pack::ChannelPath::Translation | pack::ChannelPath::Scale => 3,
                    pack::ChannelPath::Rotation => 4,
                    pack::ChannelPath::Weights => node.mesh.and_then(|m| self.meshes.get(m as usize)).map_or(0, |m| m.morph_weights.len() as u32),
                };
                if want == 0 || ch.components != want {
                    return Err(format!("{what}: {} components per key, the target needs {want}", ch.components));
                }
                crate::anim::validate_channel(ch.clone()).map_err(|e| format!("{what}: {e}"))?;
            }
        }
        Ok(())
    }
}
