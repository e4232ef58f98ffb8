//! Materials evaluated where rays hit: the glTF metallic-roughness model reduced to what a
//! diffuse light bake needs, at the hit's barycentrics rather than once per triangle.
//!
//! - **albedo** = base colour factor x base colour texture (bilinear at the slot's UV: `uv0` or
//!   `texcoord1` by its `tex_coord`, through its KHR_texture_transform, wrapped as its sampler
//!   says; sRGB decoded to linear) x vertex colour (rgb), clamped to [0, 1] so no surface
//!   reflects more than it receives;
//! - **emission** (nits) = emissive factor (already x KHR_materials_emissive_strength) x emissive
//!   texture (at its own slot's UV);
//! - **alpha** = factor.a x texture.a x vertex colour.a: Opaque ignores it; Mask keeps the
//!   surface where alpha >= cutoff; Blend keeps it where alpha >= a hash of the point (hashed
//!   alpha testing: a pane of alpha a stops a fraction a of the rays crossing it, at random
//!   points, but the same rays every bake);
//! - **sides**: a single-sided material's back face is opaque and black; a double-sided one is
//!   the same surface from both sides (see `integrator`).

use super::sampling::{mix, V3};
use super::textures::{luminance, Footprint, Texture};
use pack::TextureTransform;
use serde::Deserialize;

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Alpha {
    Opaque,
    /// Kept where alpha >= the cutoff.
    Mask(f32),
    /// Kept where alpha >= a hash of the point (stochastic transparency, deterministic).
    Blend,
}

/// A texture slot: which texture, which vertex UV set (0: uv0, 1: texcoord1), and the 2x3
/// transform applied to it (`pack::TextureTransform::matrix`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Slot {
    pub texture: u32,
    pub set: usize,
    pub matrix: [[f32; 3]; 2],
}

impl Slot {
    /// `texture` read at `uv0` through the identity.
    pub fn plain(texture: u32) -> Slot {
        Slot { texture, set: 0, matrix: TextureTransform::default().matrix() }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Linear RGBA factor.
    pub base_color: [f32; 4],
    pub base_color_texture: Option<Slot>,
    /// Nits (linear RGB factor x strength).
    pub emissive: V3,
    pub emissive_texture: Option<Slot>,
    pub alpha: Alpha,
    pub double_sided: bool,
}

impl Default for Material {
    fn default() -> Self {
        Material { base_color: [1.0; 4], base_color_texture: None, emissive: [0.0; 3], emissive_texture: None, alpha: Alpha::Opaque, double_sided: false }
    }
}

/// `ir.Material` as the bindings send it (the fields the bake reads; texture indices into the
/// texture list given beside it).
#[derive(Deserialize)]
struct IrMaterial {
    #[serde(default)]
    name: String,
    #[serde(default = "white")]
    base_color: [f32; 4],
    #[serde(default)]
    base_color_texture: Option<u32>,
    #[serde(default)]
    base_color_uv: Option<TextureTransform>,
    #[serde(default)]
    emissive: [f32; 3],
    #[serde(default)]
    emissive_texture: Option<u32>,
    #[serde(default)]
    emissive_uv: Option<TextureTransform>,
    #[serde(default = "opaque")]
    alpha_mode: String,
    #[serde(default = "half")]
    alpha_cutoff: f32,
    #[serde(default)]
    double_sided: bool,
}
fn white() -> [f32; 4] {
    [1.0; 4]
}
fn opaque() -> String {
    "Opaque".into()
}
fn half() -> f32 {
    0.5
}

impl Material {
    /// Parse a JSON list of `ir.Material` dicts; texture indices must be below `textures`.
    pub fn from_ir_json(text: &str, textures: usize) -> Result<Vec<Material>, String> {
        let list: Vec<IrMaterial> = serde_json::from_str(text).map_err(|e| format!("materials JSON: {e}"))?;
        list.into_iter()
            .enumerate()
            .map(|(k, m)| {
                let what = format!("material {k} '{}'", m.name);
                let slot = |tex: Option<u32>, uv: Option<TextureTransform>, name: &str| -> Result<Option<Slot>, String> {
                    let Some(texture) = tex else { return Ok(None) };
                    if texture as usize >= textures {
                        return Err(format!("{what}: {name} texture {texture} does not exist ({textures} textures)"));
                    }
                    let uv = uv.unwrap_or_default();
                    if uv.tex_coord > 1 {
                        return Err(format!("{what}: {name} reads TEXCOORD_{}; vertices carry TEXCOORD_0 and _1", uv.tex_coord));
                    }
                    Ok(Some(Slot { texture, set: uv.tex_coord as usize, matrix: uv.matrix() }))
                };
                let numbers = m.base_color.iter().chain(&m.emissive).chain([&m.alpha_cutoff]);
                if numbers.clone().any(|x| !x.is_finite()) {
                    return Err(format!("{what}: factors must be finite"));
                }
                Ok(Material {
                    base_color: m.base_color,
                    base_color_texture: slot(m.base_color_texture, m.base_color_uv, "base colour")?,
                    emissive: m.emissive.map(|x| x.max(0.0)),
                    emissive_texture: slot(m.emissive_texture, m.emissive_uv, "emissive")?,
                    alpha: match m.alpha_mode.as_str() {
                        "Opaque" => Alpha::Opaque,
                        "Mask" => Alpha::Mask(m.alpha_cutoff),
                        "Blend" => Alpha::Blend,
                        a => return Err(format!("{what}: unknown alpha mode '{a}' (Opaque, Mask, Blend)")),
                    },
                    double_sided: m.double_sided,
                })
            })
            .collect()
    }
}

/// What the surfaces are made of: materials, textures, and the per-vertex attributes they read.
pub struct Surfaces {
    pub(super) materials: Vec<Material>,
    pub(super) textures: Vec<Texture>,
    /// Material of each triangle, and its vertex indices (into the attributes).
    material: Vec<u32>,
    triangles: Vec<[u32; 3]>,
    /// uv0 and texcoord1 per vertex (None: absent, reads (0, 0) as the runtime's vertices do).
    uv: [Option<Vec<[f32; 2]>>; 2],
    /// Linear RGBA per vertex (None: white).
    color: Option<Vec<[u8; 4]>>,
}

/// Per-vertex attributes the materials read, each one row per vertex when present.
#[derive(Default)]
pub struct VertexAttributes<'a> {
    pub uv0: Option<&'a [[f32; 2]]>,
    pub texcoord1: Option<&'a [[f32; 2]]>,
    pub color: Option<&'a [[u8; 4]]>,
}

/// An albedo and an emission: a surface point as the integrator sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shade {
    pub albedo: V3,
    pub emission: V3,
}

impl Surfaces {
    pub fn new(
        triangles: &[[u32; 3]],
        vertices: usize,
        material: &[u32],
        attributes: VertexAttributes,
        materials: Vec<Material>,
        textures: Vec<Texture>,
    ) -> Result<Surfaces, String> {
        if material.len() != triangles.len() {
            return Err(format!("{} triangles but {} triangle materials", triangles.len(), material.len()));
        }
        if let Some(i) = material.iter().position(|&m| m as usize >= materials.len()) {
            return Err(format!("triangle {i} has material {} of {}", material[i], materials.len()));
        }
        for (name, n) in [("uv0", attributes.uv0.map(<[_]>::len)), ("texcoord1", attributes.texcoord1.map(<[_]>::len)), ("color", attributes.color.map(<[_]>::len))] {
            if n.is_some_and(|n| n != vertices) {
                return Err(format!("{} {name} rows for {vertices} vertices", n.unwrap_or(0)));
            }
        }
        for (k, m) in materials.iter().enumerate() {
            if [m.base_color_texture, m.emissive_texture].iter().flatten().any(|s| s.texture as usize >= textures.len()) {
                return Err(format!("material {k} reads a texture past the {} given", textures.len()));
            }
        }
        Ok(Surfaces {
            materials,
            textures,
            material: material.to_vec(),
            triangles: triangles.to_vec(),
            uv: [attributes.uv0.map(<[_]>::to_vec), attributes.texcoord1.map(<[_]>::to_vec)],
            color: attributes.color.map(<[_]>::to_vec),
        })
    }

    #[inline]
    pub fn material(&self, prim: usize) -> &Material {
        &self.materials[self.material[prim] as usize]
    }

    /// Vertex colour at barycentrics `b` (weights of the triangle's three corners).
    fn color(&self, prim: usize, b: V3) -> [f32; 4] {
        let Some(c) = &self.color else { return [1.0; 4] };
        let t = self.triangles[prim];
        std::array::from_fn(|k| (b[0] * c[t[0] as usize][k] as f32 + b[1] * c[t[1] as usize][k] as f32 + b[2] * c[t[2] as usize][k] as f32) / 255.0)
    }

    /// A slot's texture coordinates at barycentrics `b`: its UV set interpolated, transformed.
    fn slot_uv(&self, prim: usize, slot: &Slot, b: V3) -> [f32; 2] {
        let uv = match &self.uv[slot.set] {
            Some(uv) => {
                let t = self.triangles[prim];
                let (p, q, r) = (uv[t[0] as usize], uv[t[1] as usize], uv[t[2] as usize]);
                [b[0] * p[0] + b[1] * q[0] + b[2] * r[0], b[0] * p[1] + b[1] * q[1] + b[2] * r[1]]
            }
            None => [0.0; 2],
        };
        let m = &slot.matrix;
        [m[0][0] * uv[0] + m[0][1] * uv[1] + m[0][2], m[1][0] * uv[0] + m[1][1] * uv[1] + m[1][2]]
    }

    /// Linear RGBA of a texture slot at barycentrics `b`.
    fn read(&self, prim: usize, slot: &Slot, b: V3) -> [f32; 4] {
        self.textures[slot.texture as usize].sample(self.slot_uv(prim, slot, b))
    }

    /// Alpha at barycentrics `b`: factor x texture x vertex colour.
    pub fn alpha(&self, prim: usize, b: V3) -> f32 {
        let m = self.material(prim);
        let tex = m.base_color_texture.map_or(1.0, |s| self.read(prim, &s, b)[3]);
        m.base_color[3] * tex * self.color(prim, b)[3]
    }

    /// Whether a ray can pass through triangle `prim` somewhere: its material tests alpha and
    /// its alpha can fall below the test's threshold. Only these go through the hit filter.
    pub fn maybe_transparent(&self, prim: usize) -> bool {
        let m = self.material(prim);
        let threshold = match m.alpha {
            Alpha::Opaque => return false,
            Alpha::Mask(cutoff) => cutoff,
            // The hash reaches up to (not including) 1: anything under 1 can be passed.
            Alpha::Blend => 1.0,
        };
        if m.base_color_texture.is_some_and(|s| !self.textures[s.texture as usize].is_opaque()) {
            return true;
        }
        // Alpha is linear in the barycentrics: its least is at a corner.
        let least = match &self.color {
            Some(c) => self.triangles[prim].iter().map(|&v| c[v as usize][3]).min().unwrap_or(255) as f32 / 255.0,
            None => 1.0,
        };
        m.base_color[3] * least < threshold
    }

    /// Whether the surface is there at point `p` (barycentrics `b`) of triangle `prim`: false
    /// where its alpha test lets rays through. The same answer for the same point every time.
    pub fn present(&self, prim: usize, p: V3, b: V3) -> bool {
        match self.material(prim).alpha {
            Alpha::Opaque => true,
            Alpha::Mask(cutoff) => self.alpha(prim, b) >= cutoff,
            Alpha::Blend => self.alpha(prim, b) >= hashed_threshold(prim as u32, p),
        }
    }

    /// Albedo and emission at barycentrics `b` of triangle `prim`.
    pub fn shade(&self, prim: usize, b: V3) -> Shade {
        let m = self.material(prim);
        let tex = m.base_color_texture.map_or([1.0; 4], |s| self.read(prim, &s, b));
        let vc = self.color(prim, b);
        let albedo = std::array::from_fn(|k| {
            let a = m.base_color[k] * tex[k] * vc[k];
            if a.is_finite() { a.clamp(0.0, 1.0) } else { 0.0 }
        });
        Shade { albedo, emission: self.emission(prim, b) }
    }

    /// Emitted radiance (nits) at barycentrics `b` of triangle `prim`.
    pub fn emission(&self, prim: usize, b: V3) -> V3 {
        let m = self.material(prim);
        if m.emissive == [0.0; 3] {
            return [0.0; 3];
        }
        match m.emissive_texture {
            Some(s) => {
                let t = self.read(prim, &s, b);
                [m.emissive[0] * t[0], m.emissive[1] * t[1], m.emissive[2] * t[2]]
            }
            None => m.emissive,
        }
    }

    /// The texture triangle `prim`'s emission reads, if it emits through one.
    pub fn emissive_texture(&self, prim: usize) -> Option<usize> {
        let m = self.material(prim);
        m.emissive_texture.filter(|_| m.emissive != [0.0; 3]).map(|s| s.texture as usize)
    }

    /// How much triangle `prim` emits per unit area, roughly: the luminance of its emissive
    /// factor x the mean of its emissive texture over the triangle's UV footprint (`footprint`:
    /// the table of the texture `emissive_texture(prim)` names). Positive wherever the triangle
    /// emits anywhere (what keeps light sampling unbiased).
    pub fn emitter_weight(&self, prim: usize, footprint: Option<&Footprint>) -> f64 {
        let m = self.material(prim);
        let factor = luminance([m.emissive[0], m.emissive[1], m.emissive[2], 0.0]) as f64;
        if factor.is_nan() || factor <= 0.0 {
            return 0.0;
        }
        let Some(s) = m.emissive_texture else { return factor };
        let footprint = footprint.expect("the emissive texture's footprint table");
        let corners = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]].map(|b| self.slot_uv(prim, &s, b));
        // The transform is affine, so the triangle's UV image is the triangle of its corners'.
        let lo = [0, 1].map(|k| corners.iter().map(|c| c[k]).fold(f32::INFINITY, f32::min));
        let hi = [0, 1].map(|k| corners.iter().map(|c| c[k]).fold(f32::NEG_INFINITY, f32::max));
        factor * footprint.mean(&self.textures[s.texture as usize], lo, hi)
    }
}

/// Hashed alpha's threshold at point `p` of triangle `prim`: uniform in [0, 1), a function of
/// the point's bits (so a ray and a light sample reaching the same point agree, and a bake is
/// reproducible), uncorrelated between nearby points.
pub fn hashed_threshold(prim: u32, p: V3) -> f32 {
    let [x, y, z] = p.map(|c| c.to_bits() as u64);
    let h = mix(mix(mix(prim as u64 ^ 0x414C_5048_4100_0000) ^ x) ^ (y << 32 | z));
    (h >> 40) as f32 * (1.0 / 16_777_216.0)
}
