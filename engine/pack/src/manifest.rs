//! The structured part of a pack (serialised as JSON inside it) and its consistency checks.

use crate::PackError;
use serde::{Deserialize, Serialize};

/// A byte range inside the pack's data blob.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub struct BufferRange {
    pub offset: u64,
    pub len: u64,
}

/// A vertex as the cooker makes it and the runtime's CPU code reads it, decoded (all f32).
/// A pack stores it quantised (36 bytes: `crate::vertex`); `_pad` keeps it 80 bytes of plain
/// numbers for bytemuck.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Vertex {
    pub position: [f32; 3],
    pub normal: [f32; 3],
    /// xyz tangent, w = handedness (+1/-1) of the bitangent, as glTF.
    pub tangent: [f32; 4],
    /// glTF TEXCOORD_0.
    pub uv0: [f32; 2],
    /// Lightmap UVs in the mesh's own lightmap space (the cooker's: texels of the page for a
    /// mesh placed once, `[0, 1]` over its largest block for one placed several times); a static
    /// instance maps them onto its atlas page with its `Node::lightmap` region. Zero until the
    /// uv2 stage has run.
    pub uv1: [f32; 2],
    /// glTF TEXCOORD_1, for texture slots whose `tex_coord` is 1 (zero when absent).
    pub texcoord1: [f32; 2],
    /// Linear RGBA vertex colour, 8 bits per channel (UNORM).
    pub color: [u8; 4],
    pub _pad: [u32; 3],
}

impl Vertex {
    /// The raw bytes of decoded vertices (80 each), for tools that read them as records.
    pub fn slice_as_bytes(v: &[Vertex]) -> &[u8] {
        bytemuck::cast_slice(v)
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Manifest {
    /// Free-form provenance: the source file and the cooker version.
    pub source: String,
    pub cooker: String,
    pub meshes: Vec<Mesh>,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    pub nodes: Vec<Node>,
    #[serde(default)]
    pub lights: Vec<Light>,
    #[serde(default)]
    pub spawns: Vec<Spawn>,
    /// Vertical cylinders of the level's solid geometry (columns, basins): the CSG merges them
    /// into one mesh, so the cooker records them from the authored brushes for the flocks to
    /// steer around. Absent in packs cooked before they were recorded.
    #[serde(default)]
    pub pillars: Vec<Pillar>,
    #[serde(default)]
    pub sky: Option<Sky>,
    /// The lightmap atlas the static meshes' uv1 refer to (pages and density); `None` when the
    /// level has no lightmap UVs.
    #[serde(default)]
    pub lightmap: Option<LightmapLayout>,
    /// Baked irradiance probes; `None` when the level was not baked.
    #[serde(default)]
    pub probes: Option<ProbeGrid>,
    /// Baked reflection probes (radiance cubes prefiltered per roughness); `None` when the
    /// level was not baked or has none.
    #[serde(default)]
    pub reflection_probes: Option<ReflectionProbes>,
    /// Skins, clips and deforming meshes (see `anim.rs`); empty for static content.
    #[serde(default)]
    pub animation: crate::Animation,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LightKind {
    Sun,
    Point,
    Spot,
    Rect,
}

/// A light in physical units: sun in lux (illuminance at normal incidence), point and spot in
/// candela, rect in nits (luminance of its emitting face). `color` is a linear tint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Light {
    pub name: String,
    pub kind: LightKind,
    pub color: [f32; 3],
    pub intensity: f32,
    pub position: [f32; 3],
    /// The direction the light travels (unit).
    pub direction: [f32; 3],
    /// Metres; `None` is physically unbounded.
    pub range: Option<f32>,
    pub inner_cone: f32,
    pub outer_cone: f32,
    /// Rect: width and height in metres.
    pub size: [f32; 2],
    /// Sun: angular radius in radians.
    pub angular_radius: f32,
}

/// Where the game places something at start: the player, characters, boid flocks, emitters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Spawn {
    pub name: String,
    pub kind: String,
    pub position: [f32; 3],
    /// Quaternion xyzw.
    pub rotation: [f32; 4],
    /// Kind-specific parameters (asset, count, radius, rate, ...), kept as authored, plus what
    /// the cooker adds: a boids spawn's `mesh` (the index of the mesh its birds are drawn with).
    #[serde(default)]
    pub params: serde_json::Value,
}

/// A vertical cylinder in world space: axis at (x, z) = `centre`, from `y_min` to `y_max`.
/// `name` is the brush's, with the copy's number for a repeated brush (`columns[2]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Pillar {
    pub name: String,
    pub centre: [f32; 2],
    pub radius: f32,
    pub y_min: f32,
    pub y_max: f32,
}

impl Pillar {
    /// Why the pillar cannot be used, if it cannot (non-finite numbers, no radius or height).
    fn problem(&self) -> Option<String> {
        let numbers = [self.centre[0], self.centre[1], self.radius, self.y_min, self.y_max];
        if !numbers.iter().all(|x| x.is_finite()) {
            return Some(format!("non-finite numbers (centre {:?}, radius {}, y {}..{})", self.centre, self.radius, self.y_min, self.y_max));
        }
        if !(self.radius > 0.0) {
            return Some(format!("radius {} is not positive", self.radius));
        }
        if !(self.y_min < self.y_max) {
            return Some(format!("y range {}..{} is empty", self.y_min, self.y_max));
        }
        None
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Sky {
    /// Linear colour.
    pub color: [f32; 3],
    /// Luminance scale in nits.
    pub intensity: f32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LightmapLayout {
    pub texels_per_metre: f32,
    /// (width, height) in texels of each atlas page; every page has the same size (the runtime
    /// holds them as the layers of one array texture).
    pub pages: Vec<[u32; 2]>,
    /// Texels kept free around every chart.
    pub padding: u32,
    /// The baked lightmap of each page: a texture (`Rgba16Float` or `Bc6hUfloat`, the page's
    /// size, one level, every page in one format) holding B = H/pi in nits, linear (runtime:
    /// `L_out = L_e + albedo * B`). Empty until baked.
    #[serde(default)]
    pub textures: Vec<u32>,
    /// Directional lightmaps ("MonoSH", shading.md §4), one texture per page (`Rgba8Unorm` or
    /// `Bc7Unorm`, the page's size, one level, all in one format) holding the luminance's L1
    /// direction t = b1_Y / (2 b0_Y) as the bytes 128 + 127 t (rgb) and the fraction of the sun
    /// the texel sees (a): the runtime lights it with the pack's first sun itself. With them,
    /// `textures` hold b0 (rgb: B(n) = b0 (1 + 2 t·n), clamped at 0, for the shading normal n)
    /// of all the light but the sun's direct light. Empty: irradiance lightmaps, B with the sun
    /// in it.
    #[serde(default)]
    pub directions: Vec<u32>,
    /// The log-average luminance the runtime's exposure is made from (`exposure::LogAverage`),
    /// computed by the cooker from the pages as baked (before block compression changes their
    /// texels); `None`: the runtime computes it from the pages it loads.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub log_average: Option<f32>,
    /// Paths per texel the pages were baked with (`None`: not recorded). The runtime's overlay
    /// shows it, so a designer watching a bake refine (`cook --watch`) sees it grow.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub samples: Option<u32>,
}

/// Irradiance probes for dynamic objects on a regular grid: probe (i, j, k) sits at
/// `origin + (i, j, k) * spacing` and is number `i + counts[0] * (j + counts[1] * k)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProbeGrid {
    pub origin: [f32; 3],
    pub spacing: [f32; 3],
    pub counts: [u32; 3],
    /// f32 [probe][9][rgb]: order-2 SH of B(n) = E(n)/pi in nits, already convolved with the
    /// cosine, so `B(n) = sum_i sh[i] * Y_i(n)` (basis order Y00, Y1-1 (y), Y10 (z), Y11 (x),
    /// Y2-2 (xy), Y2-1 (yz), Y20, Y21 (xz), Y22 in world axes; constants in cook_core::bake::probes).
    /// The sun's direct light is not in it.
    pub sh: BufferRange,
    /// f32 [probe]: fraction of the sun's disk visible from the probe (1 with no sun): the
    /// runtime scales its own sun term by it.
    pub sun_visibility: BufferRange,
}

impl ProbeGrid {
    pub fn count(&self) -> u64 {
        self.counts.iter().map(|&c| c as u64).product()
    }
}

/// Reflection probes (shading.md §3): per probe a cube map of the radiance arriving at its
/// capture point, path-traced by the cooker with the sun's disc left out, prefiltered for GGX
/// into its mip chain (level k holds roughness k / (levels − 1); level 0 is the mirror). Every
/// probe has the same face size and levels (the runtime holds them as one cube-map array).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReflectionProbes {
    /// Texels along a face's edge at level 0 (a power of two).
    pub face_size: u32,
    /// Mip levels, 1 ..= log2(face_size) + 1.
    pub levels: u32,
    /// How every probe's `data` holds its texels: `Rgba16Float`, or `Bc6hUfloat` (each face of
    /// each level whole 4x4 blocks, `TextureFormat::level_bytes`).
    #[serde(default = "half_float")]
    pub format: TextureFormat,
    pub probes: Vec<ReflectionProbe>,
}

fn half_float() -> TextureFormat {
    TextureFormat::Rgba16Float
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReflectionProbe {
    pub name: String,
    /// Where the cube was captured (world space), inside the box.
    pub position: [f32; 3],
    /// The world-space axis-aligned box of the room it reflects: the parallax-correction box
    /// and the probe's influence, whole inside the box (faces included: a room's floor and
    /// walls lie on them) and fading to 0 over `blend_distance` metres outside it.
    pub box_min: [f32; 3],
    pub box_max: [f32; 3],
    pub blend_distance: f32,
    /// Radiance in nits, as `ReflectionProbes::format` says (half-float RGBA, alpha 1; or BC6H
    /// blocks): [level][face +X, −X, +Y, −Y, +Z, −Z (Vulkan's layer order)][row from the
    /// top][column], level k `face_size >> k` texels square.
    pub data: BufferRange,
}

impl ReflectionProbes {
    /// Bytes of one probe's `data`.
    pub fn probe_bytes(&self) -> u64 {
        (0..self.levels).map(|k| 6 * self.face_bytes(k)).sum()
    }

    /// Bytes of one face of level `k`.
    pub fn face_bytes(&self, k: u32) -> u64 {
        let s = (self.face_size >> k).max(1);
        self.format.level_bytes(s, s).unwrap_or(u64::MAX)
    }
}

impl ReflectionProbe {
    fn problem(&self) -> Option<String> {
        let numbers = [&self.position[..], &self.box_min, &self.box_max, &[self.blend_distance]].concat();
        if !numbers.iter().all(|x| x.is_finite()) {
            return Some(format!("non-finite numbers (position {:?}, box {:?}..{:?}, blend {})", self.position, self.box_min, self.box_max, self.blend_distance));
        }
        if !(0..3).all(|i| self.box_min[i] < self.box_max[i]) {
            return Some(format!("box {:?}..{:?} is empty", self.box_min, self.box_max));
        }
        if !(0..3).all(|i| (self.box_min[i]..=self.box_max[i]).contains(&self.position[i])) {
            return Some(format!("position {:?} is outside its box {:?}..{:?}", self.position, self.box_min, self.box_max));
        }
        if self.blend_distance < 0.0 {
            return Some(format!("blend distance {} is negative", self.blend_distance));
        }
        None
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Mesh {
    pub name: String,
    /// Levels of detail, full detail first. Each has its own vertices and indices.
    pub lods: Vec<MeshLod>,
    /// Object-space axis-aligned bounds (of LOD 0, which every LOD stays close to).
    pub bounds_min: [f32; 3],
    pub bounds_max: [f32; 3],
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeshLod {
    /// Stored vertices (`crate::vertex`), `vertex_count * VERTEX_STRIDE` bytes.
    pub vertices: BufferRange,
    pub vertex_count: u32,
    /// What the vertices' 16-bit texture coordinates map onto.
    pub uv_ranges: crate::UvRanges,
    /// Triangle list indices into this LOD's vertices, `index_format` wide.
    pub indices: BufferRange,
    pub index_count: u32,
    pub index_format: IndexFormat,
    /// Ranges of `indices` drawn with one material (and lightmap block) each.
    pub submeshes: Vec<Submesh>,
    /// Geometric error to LOD 0 in metres, object space (an upper bound of the measured
    /// two-sided Hausdorff distance); 0 for LOD 0. Non-decreasing along the chain.
    pub error: f32,
}

/// How wide a LOD's indices are: 16 bits where every index fits (a LOD of at most 65 536
/// vertices: half the index bytes to store, upload and fetch), else 32.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum IndexFormat {
    U16,
    U32,
}

impl IndexFormat {
    /// The narrowest format that can index `vertex_count` vertices.
    pub fn for_vertices(vertex_count: usize) -> IndexFormat {
        if vertex_count <= 1 << 16 { IndexFormat::U16 } else { IndexFormat::U32 }
    }

    /// Bytes per index.
    pub fn size(self) -> usize {
        match self {
            IndexFormat::U16 => 2,
            IndexFormat::U32 => 4,
        }
    }

    /// Little-endian indices of this width, as u32 (a trailing partial index is ignored).
    pub fn decode(self, bytes: &[u8]) -> impl Iterator<Item = u32> + '_ {
        bytes.chunks_exact(self.size()).map(move |b| match self {
            IndexFormat::U16 => u16::from_le_bytes([b[0], b[1]]) as u32,
            IndexFormat::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        })
    }

    /// `indices` in this width, little-endian (each must fit: see `for_vertices`).
    pub fn encode(self, indices: &[u32]) -> Vec<u8> {
        match self {
            IndexFormat::U16 => indices.iter().flat_map(|&i| (i as u16).to_le_bytes()).collect(),
            IndexFormat::U32 => indices.iter().flat_map(|&i| i.to_le_bytes()).collect(),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Submesh {
    pub first_index: u32,
    pub index_count: u32,
    pub material: u32,
    /// The mesh's lightmap block its lightmap UVs (uv1) lie in; `None` when the mesh has none.
    /// A mesh too big for one atlas page is laid out in several blocks; a static instance puts
    /// block `b` on page `region.page + b` (see `Node::lightmap`).
    #[serde(default)]
    pub lightmap_block: Option<u32>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum AlphaMode {
    #[default]
    Opaque,
    Mask,
    Blend,
}

/// A metallic-roughness material, as glTF.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Material {
    pub name: String,
    /// Linear RGBA factor.
    pub base_color: [f32; 4],
    pub base_color_texture: Option<u32>,
    pub metallic: f32,
    pub roughness: f32,
    /// Linear emitted radiance factor (already multiplied by any emissive strength).
    pub emissive: [f32; 3],
    pub alpha_mode: AlphaMode,
    pub alpha_cutoff: f32,
    pub double_sided: bool,
    /// Tangent-space normal map (Rgba16Unorm once cooked: rgb = n * 0.5 + 0.5) and the scale of
    /// its xy (glTF `normalTexture.scale`).
    pub normal_texture: Option<u32>,
    pub normal_scale: f32,
    /// glTF metallic-roughness: roughness in g, metalness in b, linear (Rgba8Unorm); multiplies
    /// `roughness` and `metallic`.
    pub metallic_roughness_texture: Option<u32>,
    /// Ambient occlusion in r, linear (Rgba8Unorm), mixed in by `occlusion_strength`.
    pub occlusion_texture: Option<u32>,
    pub occlusion_strength: f32,
    /// Emission colour (Rgba8Srgb), multiplies `emissive`.
    pub emissive_texture: Option<u32>,
    /// How each slot's texture coordinates are chosen and transformed (glTF `texCoord` and
    /// KHR_texture_transform); the identity on TEXCOORD_0 when absent.
    #[serde(default)]
    pub base_color_uv: TextureTransform,
    #[serde(default)]
    pub normal_uv: TextureTransform,
    #[serde(default)]
    pub metallic_roughness_uv: TextureTransform,
    #[serde(default)]
    pub occlusion_uv: TextureTransform,
    #[serde(default)]
    pub emissive_uv: TextureTransform,
}

/// Which vertex UV set a texture slot reads and how it is transformed before sampling, as glTF
/// `textureInfo.texCoord` and KHR_texture_transform: `uv' = T(offset) R(rotation) S(scale) uv`
/// (`matrix`). `tex_coord` 0 is `Vertex::uv0`, 1 is `Vertex::texcoord1`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TextureTransform {
    #[serde(default)]
    pub tex_coord: u32,
    #[serde(default)]
    pub offset: [f32; 2],
    /// Radians, counter-clockwise in UV space (glTF's convention).
    #[serde(default)]
    pub rotation: f32,
    #[serde(default = "one2")]
    pub scale: [f32; 2],
}

fn one2() -> [f32; 2] {
    [1.0; 2]
}

impl Default for TextureTransform {
    fn default() -> Self {
        TextureTransform { tex_coord: 0, offset: [0.0; 2], rotation: 0.0, scale: [1.0; 2] }
    }
}

impl TextureTransform {
    /// The 2x3 matrix of the transform, rows `[a, b, c]` and `[d, e, f]`:
    /// `u' = a u + b v + c`, `v' = d u + e v + f` (KHR_texture_transform's T * R * S).
    pub fn matrix(&self) -> [[f32; 3]; 2] {
        let (s, c) = self.rotation.sin_cos();
        let [sx, sy] = self.scale;
        [[c * sx, s * sy, self.offset[0]], [-s * sx, c * sy, self.offset[1]]]
    }

    pub fn is_identity(&self) -> bool {
        *self == TextureTransform::default()
    }
}

impl Material {
    /// Every texture slot with the formats it accepts: what readers and tools iterate over.
    pub fn texture_slots(&self) -> [(&'static str, Option<u32>, &'static [TextureFormat]); 5] {
        use TextureFormat::*;
        [
            ("base colour", self.base_color_texture, &[Rgba8Srgb, Rgba8Unorm, Bc7Srgb]),
            ("normal", self.normal_texture, &[Rgba16Unorm, Rgba8Unorm, Bc5Unorm]),
            ("metallic-roughness", self.metallic_roughness_texture, &[Rgba8Unorm, Bc7Unorm]),
            ("occlusion", self.occlusion_texture, &[Rgba8Unorm, Bc7Unorm, Bc4Unorm]),
            ("emissive", self.emissive_texture, &[Rgba8Srgb, Bc7Srgb]),
        ]
    }

    /// The UV transform of each slot, in `texture_slots` order.
    pub fn texture_uvs(&self) -> [&TextureTransform; 5] {
        [&self.base_color_uv, &self.normal_uv, &self.metallic_roughness_uv, &self.occlusion_uv, &self.emissive_uv]
    }
}

impl Default for Material {
    fn default() -> Self {
        Material {
            name: "default".into(),
            base_color: [1.0; 4],
            base_color_texture: None,
            metallic: 0.0,
            roughness: 1.0,
            emissive: [0.0; 3],
            alpha_mode: AlphaMode::Opaque,
            alpha_cutoff: 0.5,
            double_sided: false,
            normal_texture: None,
            normal_scale: 1.0,
            metallic_roughness_texture: None,
            occlusion_texture: None,
            occlusion_strength: 1.0,
            emissive_texture: None,
            base_color_uv: TextureTransform::default(),
            normal_uv: TextureTransform::default(),
            metallic_roughness_uv: TextureTransform::default(),
            occlusion_uv: TextureTransform::default(),
            emissive_uv: TextureTransform::default(),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum TextureFormat {
    /// 8-bit RGBA, sRGB-encoded colour (sampled through an _SRGB format).
    Rgba8Srgb,
    /// 8-bit RGBA, linear data (roughness, masks; normal maps as authored).
    Rgba8Unorm,
    /// Half-float RGBA, linear HDR (lightmaps).
    Rgba16Float,
    /// 16-bit RGBA, linear (cooked normal maps: rgb = n * 0.5 + 0.5, unit length within 3e-5).
    Rgba16Unorm,
    /// BC7, sRGB-encoded colour with alpha (base colour, emission).
    Bc7Srgb,
    /// BC7, linear data (metallic-roughness, packed occlusion).
    Bc7Unorm,
    /// BC5, two linear channels: a normal map's x, y as n * 0.5 + 0.5 (z = sqrt(1 - x² - y²)).
    Bc5Unorm,
    /// BC4, one linear channel in R (occlusion).
    Bc4Unorm,
    /// BC6H, unsigned half-float RGB, linear HDR (lightmap pages, reflection cubes); alpha reads 1.
    Bc6hUfloat,
}

impl TextureFormat {
    /// Bytes of a texel of a plain format; `None` for a block-compressed one (`block_bytes`).
    pub fn bytes_per_texel(self) -> Option<u64> {
        match self {
            TextureFormat::Rgba8Srgb | TextureFormat::Rgba8Unorm => Some(4),
            TextureFormat::Rgba16Float | TextureFormat::Rgba16Unorm => Some(8),
            TextureFormat::Bc4Unorm | TextureFormat::Bc5Unorm | TextureFormat::Bc7Srgb | TextureFormat::Bc7Unorm | TextureFormat::Bc6hUfloat => None,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Texture {
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub format: TextureFormat,
    /// One range per mip level, level 0 first; level i is max(1, w >> i) x max(1, h >> i), tightly packed rows.
    pub mips: Vec<BufferRange>,
    /// How it is sampled (glTF's sampler); repeating, trilinear when absent.
    #[serde(default)]
    pub sampler: Sampler,
}

/// Texture addressing outside [0, 1], per axis (glTF `wrapS` / `wrapT`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Wrap {
    #[default]
    Repeat,
    Clamp,
    Mirror,
}

/// Texel filtering (glTF's NEAREST / LINEAR).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Filter {
    Nearest,
    #[default]
    Linear,
}

/// A glTF sampler: wrap per axis, magnification and minification filters, and how mip levels
/// are blended (`None`: level 0 only, glTF's NEAREST or LINEAR minification).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Sampler {
    #[serde(default)]
    pub wrap_s: Wrap,
    #[serde(default)]
    pub wrap_t: Wrap,
    #[serde(default)]
    pub mag_filter: Filter,
    #[serde(default)]
    pub min_filter: Filter,
    #[serde(default = "linear_mips")]
    pub mipmap_filter: Option<Filter>,
}

fn linear_mips() -> Option<Filter> {
    Some(Filter::Linear)
}

impl Default for Sampler {
    fn default() -> Self {
        Sampler { wrap_s: Wrap::Repeat, wrap_t: Wrap::Repeat, mag_filter: Filter::Linear, min_filter: Filter::Linear, mipmap_filter: Some(Filter::Linear) }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Node {
    pub name: String,
    pub parent: Option<u32>,
    /// Local transform relative to the parent, column-major 4x4 (as glam's `Mat4::to_cols_array`).
    pub local: [f32; 16],
    pub mesh: Option<u32>,
    /// A static instance of its mesh: never moves (not skinned, morphed or animated), so it is
    /// part of the baked scene and its shadow is cached.
    #[serde(default)]
    pub is_static: bool,
    /// Where a baked static instance's lightmap lies in the atlas; `None` when it has none.
    #[serde(default)]
    pub lightmap: Option<LightmapRegion>,
}

/// A static instance's part of the lightmap atlas: its mesh's lightmap UVs (`Vertex::uv1`) map
/// to `uv1 * scale + offset` on page `page + block`,
/// `block` being the submesh's `lightmap_block`. One mesh placed several times keeps one set of
/// vertices; every placement gets texels of its own, sized by its own world scale.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LightmapRegion {
    pub page: u32,
    pub scale: [f32; 2],
    pub offset: [f32; 2],
}

impl Manifest {
    /// Every vertex index in the data must name a vertex of its LOD: the GPU reads vertices by
    /// these without a bounds check. Call after `validate` (which proves the ranges lie in `data`).
    pub fn validate_indices(&self, data: &[u8]) -> Result<(), PackError> {
        for (i, m) in self.meshes.iter().enumerate() {
            for (l, lod) in m.lods.iter().enumerate() {
                let (at, len) = (lod.indices.offset as usize, lod.indices.len as usize);
                let bytes = data.get(at..at.saturating_add(len)).unwrap_or_default();
                if let Some((k, v)) = lod
                    .index_format
                    .decode(bytes)
                    .enumerate()
                    .find(|&(_, v)| v >= lod.vertex_count)
                {
                    return Err(PackError::Malformed(format!(
                        "mesh {i} '{}' LOD {l}: index {k} is {v}, but the LOD has {} vertices",
                        m.name, lod.vertex_count
                    )));
                }
            }
        }
        Ok(())
    }

    /// Every number of the JSON part is finite. JSON has no infinity or NaN: serde_json writes
    /// them as null, which does not read back, and reads a number too large for f32 (1e39) as
    /// infinity; either way the pack would not survive a round trip, and the runtime would
    /// compute with infinities. (LOD errors, clip durations and probe grids are checked with
    /// their other rules.)
    fn validate_floats(&self) -> Result<(), PackError> {
        let check = |what: &dyn Fn() -> String, v: &[f32]| match v.iter().all(|x| x.is_finite()) {
            true => Ok(()),
            false => Err(PackError::Malformed(format!("{}: {v:?} is not finite", what()))),
        };
        for (i, m) in self.meshes.iter().enumerate() {
            check(&|| format!("mesh {i} '{}' bounds", m.name), &[m.bounds_min, m.bounds_max].concat())?;
        }
        for (i, m) in self.materials.iter().enumerate() {
            let v = [&m.base_color[..], &[m.metallic, m.roughness], &m.emissive, &[m.alpha_cutoff, m.normal_scale, m.occlusion_strength]].concat();
            check(&|| format!("material {i} '{}'", m.name), &v)?;
            for (t, (slot, _, _)) in m.texture_uvs().iter().zip(m.texture_slots()) {
                check(&|| format!("material {i} '{}' {slot} transform", m.name), &[t.offset[0], t.offset[1], t.rotation, t.scale[0], t.scale[1]])?;
                if t.tex_coord > 1 {
                    return Err(PackError::Malformed(format!("material {i} '{}': {slot} reads TEXCOORD_{}, but vertices carry TEXCOORD_0 and _1", m.name, t.tex_coord)));
                }
            }
        }
        for (i, l) in self.lights.iter().enumerate() {
            let v = [&l.color[..], &[l.intensity], &l.position, &l.direction, l.range.as_slice(), &[l.inner_cone, l.outer_cone], &l.size, &[l.angular_radius]].concat();
            check(&|| format!("light {i} '{}'", l.name), &v)?;
        }
        for (i, s) in self.spawns.iter().enumerate() {
            check(&|| format!("spawn {i} '{}'", s.name), &[&s.position[..], &s.rotation].concat())?;
        }
        if let Some(s) = &self.sky {
            check(&|| "sky".into(), &[&s.color[..], &[s.intensity]].concat())?;
        }
        if let Some(l) = &self.lightmap {
            check(&|| "lightmap texels_per_metre".into(), &[l.texels_per_metre])?;
        }
        for (i, n) in self.nodes.iter().enumerate() {
            check(&|| format!("node {i} '{}' transform", n.name), &n.local)?;
        }
        for d in &self.animation.meshes {
            check(&|| format!("animation: mesh {} morph weights", d.mesh), &d.morph_weights)?;
        }
        for b in &self.animation.nodes {
            check(&|| format!("animation: node {} morph weights", b.node), b.weights.as_deref().unwrap_or_default())?;
        }
        Ok(())
    }

    /// Every index and range must point at something that exists; a reader that passes this can
    /// index without bounds checks failing.
    pub fn validate(&self, data_len: u64) -> Result<(), PackError> {
        let bad = |what: String| Err(PackError::Malformed(what));
        let in_data = |what: &str, r: BufferRange, want: u64| -> Result<(), PackError> {
            if r.offset % crate::DATA_ALIGN as u64 != 0 {
                return bad(format!("{what}: offset {} is not {}-byte aligned", r.offset, crate::DATA_ALIGN));
            }
            if r.len != want {
                return bad(format!("{what}: {} bytes stored but {want} expected", r.len));
            }
            match r.offset.checked_add(r.len) {
                Some(end) if end <= data_len => Ok(()),
                _ => bad(format!("{what}: range {}..+{} lies outside the data ({data_len} bytes)", r.offset, r.len)),
            }
        };
        self.validate_floats()?;
        let pages = self.lightmap.as_ref().map_or(0, |l| l.pages.len());
        for (i, m) in self.meshes.iter().enumerate() {
            if m.lods.is_empty() {
                return bad(format!("mesh {i} '{}': no LODs", m.name));
            }
            let mut last_error = 0.0f32;
            for (l, lod) in m.lods.iter().enumerate() {
                let what = format!("mesh {i} '{}' LOD {l}", m.name);
                in_data(&format!("{what} vertices"), lod.vertices, lod.vertex_count as u64 * crate::VERTEX_STRIDE as u64)?;
                if !lod.uv_ranges.all().iter().flatten().all(|x| x.is_finite()) {
                    return bad(format!("{what}: a texture coordinate range is not finite"));
                }
                in_data(&format!("{what} indices"), lod.indices, lod.index_count as u64 * lod.index_format.size() as u64)?;
                if !(lod.error >= last_error) || !lod.error.is_finite() {
                    return bad(format!("{what}: error {} is not finite and non-decreasing (previous {last_error})", lod.error));
                }
                last_error = lod.error;
                for (s, sm) in lod.submeshes.iter().enumerate() {
                    let end = sm.first_index as u64 + sm.index_count as u64;
                    if end > lod.index_count as u64 || sm.index_count % 3 != 0 {
                        return bad(format!("{what} submesh {s}: indices {}..{end} do not fit {} indices in whole triangles", sm.first_index, lod.index_count));
                    }
                    if sm.material as usize >= self.materials.len() {
                        return bad(format!("{what} submesh {s}: material {} does not exist", sm.material));
                    }
                    if let Some(block) = sm.lightmap_block {
                        if block as usize >= pages.max(1) {
                            return bad(format!("{what} submesh {s}: lightmap block {block} cannot lie on one of the {pages} pages"));
                        }
                    }
                }
            }
        }
        for (i, s) in self.spawns.iter().enumerate() {
            // The cooker names the mesh a boids spawn's flock is drawn with.
            if let Some(mesh) = s.params.get("mesh") {
                if !mesh.as_u64().is_some_and(|m| (m as usize) < self.meshes.len()) {
                    return bad(format!("spawn {i} '{}': mesh {mesh} is not one of the {} meshes", s.name, self.meshes.len()));
                }
            }
        }
        for (i, m) in self.materials.iter().enumerate() {
            for (slot, t, formats) in m.texture_slots() {
                let Some(t) = t else { continue };
                match self.textures.get(t as usize) {
                    None => return bad(format!("material {i} '{}': {slot} texture {t} does not exist", m.name)),
                    Some(tex) if !formats.contains(&tex.format) => {
                        return bad(format!("material {i} '{}': {slot} texture {t} '{}' is {:?}, expected one of {formats:?}", m.name, tex.name, tex.format));
                    }
                    Some(_) => {}
                }
            }
        }
        for (i, t) in self.textures.iter().enumerate() {
            if t.width == 0 || t.height == 0 || t.mips.is_empty() {
                return bad(format!("texture {i} '{}': empty ({}x{}, {} mips)", t.name, t.width, t.height, t.mips.len()));
            }
            // A full chain ends at 1x1; more levels would shift the size by 32 bits or more.
            let full_chain = 32 - t.width.max(t.height).leading_zeros() as usize;
            if t.mips.len() > full_chain {
                return bad(format!("texture {i} '{}': {} mips, more than the {full_chain} of a full chain for {}x{}", t.name, t.mips.len(), t.width, t.height));
            }
            for (l, r) in t.mips.iter().enumerate() {
                let (w, h) = ((t.width >> l).max(1) as u64, (t.height >> l).max(1) as u64);
                // u32 x u32 fits in u64, times the texel (or block) size need not.
                let Some(bytes) = t.format.level_bytes(w as u32, h as u32) else {
                    return bad(format!("texture {i} '{}': {}x{} is too large", t.name, t.width, t.height));
                };
                in_data(&format!("texture {i} '{}' mip {l}", t.name), *r, bytes)?;
            }
        }
        if let Some(l) = &self.lightmap {
            if let Some(size) = l.pages.iter().find(|p| **p != l.pages[0]) {
                return bad(format!("lightmap: pages of different sizes ({}x{} and {}x{})", l.pages[0][0], l.pages[0][1], size[0], size[1]));
            }
            if !l.textures.is_empty() && l.textures.len() != l.pages.len() {
                return bad(format!("lightmap: {} baked textures for {} pages", l.textures.len(), l.pages.len()));
            }
            if !l.directions.is_empty() && (l.directions.len() != l.pages.len() || l.textures.len() != l.pages.len()) {
                return bad(format!("lightmap: {} direction textures and {} baked textures for {} pages", l.directions.len(), l.textures.len(), l.pages.len()));
            }
            // Every page in one format, every direction texture in one (the runtime holds each
            // set as one array texture): half float or BC6H; RGBA8 or BC7.
            use TextureFormat::*;
            let sets: [(&[u32], &[TextureFormat], &str); 2] = [(&l.textures, &[Rgba16Float, Bc6hUfloat], "texture"), (&l.directions, &[Rgba8Unorm, Bc7Unorm], "direction texture")];
            for (ids, formats, what) in sets {
                let first = ids.first().and_then(|&t| self.textures.get(t as usize)).map(|t| t.format);
                for (p, (&t, size)) in ids.iter().zip(&l.pages).enumerate() {
                    match self.textures.get(t as usize) {
                        Some(tex) if formats.contains(&tex.format) && Some(tex.format) == first && [tex.width, tex.height] == *size && tex.mips.len() == 1 => {}
                        Some(tex) => return bad(format!("lightmap page {p}: {what} {t} '{}' is {}x{} {:?} ({} levels), not {}x{} {} (one level, page 0's format)", tex.name, tex.width, tex.height, tex.format, tex.mips.len(), size[0], size[1], formats.iter().map(|f| format!("{f:?}")).collect::<Vec<_>>().join(" or "))),
                        None => return bad(format!("lightmap page {p}: {what} {t} does not exist")),
                    }
                }
            }
        }
        if let Some(g) = &self.probes {
            let n = g.count();
            if n == 0 || n > 1 << 24 || !g.spacing.iter().chain(&g.origin).all(|x| x.is_finite()) || !g.spacing.iter().all(|&x| x > 0.0) {
                return bad(format!("probes: bad grid (counts {:?}, spacing {:?}, origin {:?})", g.counts, g.spacing, g.origin));
            }
            in_data("probes sh", g.sh, n * 27 * 4)?;
            in_data("probes sun_visibility", g.sun_visibility, n * 4)?;
        }
        if let Some(r) = &self.reflection_probes {
            if !r.face_size.is_power_of_two() || !(1..=2048).contains(&r.face_size) || !(1..=r.face_size.trailing_zeros() + 1).contains(&r.levels) {
                return bad(format!("reflection probes: bad cube ({} texels a face, {} levels)", r.face_size, r.levels));
            }
            if !matches!(r.format, TextureFormat::Rgba16Float | TextureFormat::Bc6hUfloat) {
                return bad(format!("reflection probes: format {:?} is not Rgba16Float or Bc6hUfloat", r.format));
            }
            for (i, p) in r.probes.iter().enumerate() {
                if let Some(problem) = p.problem() {
                    return bad(format!("reflection probe {i} '{}': {problem}", p.name));
                }
                in_data(&format!("reflection probe {i} '{}'", p.name), p.data, r.probe_bytes())?;
            }
        }
        for (i, p) in self.pillars.iter().enumerate() {
            if let Some(problem) = p.problem() {
                return bad(format!("pillar {i} '{}': {problem}", p.name));
            }
        }
        self.animation.validate(self, &in_data)?;
        for (i, n) in self.nodes.iter().enumerate() {
            // Parents come before children, which also rules out cycles.
            if let Some(p) = n.parent {
                if p as usize >= i {
                    return bad(format!("node {i} '{}': parent {p} does not precede it", n.name));
                }
            }
            if let Some(m) = n.mesh {
                if m as usize >= self.meshes.len() {
                    return bad(format!("node {i} '{}': mesh {m} does not exist", n.name));
                }
            }
            if let Some(r) = &n.lightmap {
                let Some(m) = n.mesh else { return bad(format!("node {i} '{}': a lightmap region but no mesh", n.name)) };
                let blocks = self.meshes[m as usize].lods.iter().flat_map(|l| &l.submeshes).filter_map(|s| s.lightmap_block).max().map_or(0, |b| b + 1);
                if r.page as usize + blocks as usize > pages {
                    return bad(format!("node {i} '{}': lightmap pages {}..{} do not exist ({pages} pages)", n.name, r.page, r.page + blocks));
                }
                if !r.scale.iter().chain(&r.offset).all(|x| x.is_finite()) || !r.scale.iter().all(|&x| x > 0.0) {
                    return bad(format!("node {i} '{}': bad lightmap region (scale {:?}, offset {:?})", n.name, r.scale, r.offset));
                }
            }
        }
        Ok(())
    }
}
