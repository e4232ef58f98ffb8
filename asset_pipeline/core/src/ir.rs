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
    pub uv1: Option<Vec<[f32; 2]>>,
    /// Linear RGBA, 8-bit UNORM.
    pub colors: Option<Vec<[u8; 4]>>,
    pub joints: Option<Vec<[u16; 4]>>,
    pub weights: Option<Vec<[f32; 4]>>,
    pub triangles: Vec<[u32; 3]>,
    /// Material index per triangle.
    pub materials: Vec<u32>,
    /// Lightmap atlas page per triangle, once the uv2 stage has run.
    pub lightmap_pages: Option<Vec<u32>>,
    /// Geometric error to LOD 0 in metres (object space).
    pub error: f32,
}

#[derive(Debug, Clone, PartialEq)]
pub struct MeshIr {
    pub name: String,
    pub is_static: bool,
    pub lods: Vec<LodIr>,
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
    pub sky: Option<Sky>,
    pub lightmap: Option<LightmapLayout>,
    pub probes: Option<ProbesIr>,
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
        if let Some(p) = self.lightmap_pages.as_ref().filter(|p| p.len() != m) {
            return Err(format!("{what}: {} lightmap pages for {m} triangles", p.len()));
        }
        if !self.error.is_finite() || self.error < 0.0 {
            return Err(format!("{what}: error {} is not a finite distance", self.error));
        }
        Ok(())
    }
}
