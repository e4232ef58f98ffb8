//! The scene: a cooked pack on the GPU (`assets` loads it: one vertex and one index buffer for
//! all meshes, textures, material descriptor sets, the baked lightmap pages as one array texture)
//! and its instances behind handles (`spawn`, `set_transform`, `despawn`; `instances` keeps their
//! culling spheres and the scene's bounds). `camera` and `walk` are how a game looks and moves
//! around in it.

pub mod camera;
pub mod instances;
pub mod walk;

pub use crate::scene::instances::{Instance, InstanceError, InstanceId, Instances, LocalBounds};
use crate::gpu::{Buffer, Gpu, Image};
use crate::render::samplers::SamplerCache;
use anyhow::Result;
use ash::vk;
use glam::{Mat4, Vec3};

/// A scene upload's submits (each one fence wait) and bytes (`gpu::Uploader`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct UploadStats {
    pub submits: u32,
    pub bytes: u64,
}

/// Where one level of detail of a mesh lives inside the shared buffers.
#[derive(Debug, Clone)]
pub struct GpuLod {
    pub base_vertex: i32,
    /// In indices of `index_type`, from the start of the index buffer's region of that width
    /// (`GpuScene::index_offset_16` for 16-bit).
    pub first_index: u32,
    pub index_type: vk::IndexType,
    pub submeshes: Vec<pack::Submesh>,
    /// What its vertices' 16-bit texture coordinates map onto (`pack::vertex`); the draws push
    /// them for the vertex shader.
    pub uv_ranges: pack::UvRanges,
    /// Geometric error to LOD 0, metres in object space (0 for LOD 0).
    pub error: f32,
    pub triangles: u32,
    /// This LOD's box in the mesh's space (a coarse LOD's vertices can lie outside LOD 0's,
    /// which `GpuMesh::bounds_min/max` are).
    pub bounds: LocalBounds,
    /// Its triangles on the CPU, for occlusion culling (`render::occlusion`): LODs of up to
    /// `occlusion::MAX_OCCLUDER_TRIANGLES` triangles.
    pub occluder: Option<std::sync::Arc<crate::render::occlusion::OccluderMesh>>,
}

#[derive(Debug, Clone)]
pub struct GpuMesh {
    pub name: String,
    /// Full detail first.
    pub lods: Vec<GpuLod>,
    pub bounds_min: Vec3,
    pub bounds_max: Vec3,
    /// `lods[i].error` for every LOD (what LOD selection reads, without gathering it per draw).
    pub errors: Vec<f32>,
}

impl GpuMesh {
    /// The mesh's box in its own space.
    pub fn local_bounds(&self) -> LocalBounds {
        LocalBounds { min: self.bounds_min, max: self.bounds_max }
    }
}

#[derive(Debug, Clone, Copy)]
pub struct GpuMaterial {
    pub base_color: [f32; 4],
    /// Alpha-test threshold, or a negative value for "no alpha test".
    pub alpha_cutoff: f32,
    pub double_sided: bool,
    /// glTF BLEND: drawn in the transparent phase (sorted, over, no depth writes), not in the
    /// opaque passes or the shadow map.
    pub blend: bool,
    /// The texture slots its fragments sample: the renderer draws it with pipelines made for them.
    pub slots: TextureSlots,
    /// Reflection probes show on it (`GpuMaterial::reflects_probes`).
    pub glossy: bool,
    pub descriptor_set: vk::DescriptorSet,
}

impl GpuMaterial {
    /// Roughness from which a dielectric takes its specular environment from the baked diffuse
    /// light (the lightmap's or probes' B toward the lobe's dominant direction) instead of the
    /// reflection probes: at r 0.6 (α 0.36) the GGX lobe is within a factor of two as wide as
    /// the cosine lobe B is convolved with, and a dielectric reflects 4 % of it head-on. On
    /// lavapipe the probes' cube lookups cost a third of the frame (measured on the demo
    /// flythrough, `bench` variant reflections_off), and rough stone is most of the screen.
    pub const GLOSSY_ROUGHNESS: f32 = 0.6;

    /// Whether a material reflects the probes: any metal (a metal's look is its environment),
    /// or a dielectric whose roughness factor is below `GLOSSY_ROUGHNESS` (a roughness texture
    /// multiplies the factor, so no texel is rougher than it).
    pub fn reflects_probes(m: &pack::Material) -> bool {
        m.metallic > 0.0 || m.roughness < Self::GLOSSY_ROUGHNESS
    }
}

/// A set of a material's texture slots, as the shading shaders' SLOTS specialisation constant
/// (mesh_shading.glsl). Shaders run on lavapipe execute a branch masked, the lookup costing the
/// same whether taken or not; so rather than branch on a material's flags, each material draws
/// with a pipeline whose SLOTS leave out what it lacks (the material permutations of other
/// engines' shader keywords, made per scene: `MeshKit::prepare_lit`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TextureSlots(pub u32);

impl TextureSlots {
    pub const BASE_COLOR: TextureSlots = TextureSlots(1);
    pub const EMISSIVE: TextureSlots = TextureSlots(2);
    pub const NORMAL: TextureSlots = TextureSlots(4);
    pub const METALLIC_ROUGHNESS: TextureSlots = TextureSlots(8);
    /// An occlusion texture of its own (a packed ORM's occlusion comes with METALLIC_ROUGHNESS).
    pub const OCCLUSION: TextureSlots = TextureSlots(16);
    /// Every slot: the shaders' default, which leaves it to the material's flags at run time.
    pub const ALL: TextureSlots = TextureSlots(31);

    /// The slots `material` samples: those with a texture that can change its shading (not a
    /// normal map of scale 0, an emissive texture times a zero factor, an occlusion texture of
    /// strength 0, nor one that is the metallic-roughness texture read at the same coordinates:
    /// a packed ORM's occlusion comes with that sample).
    pub fn of(material: &pack::Material) -> TextureSlots {
        let m = material;
        [
            (m.base_color_texture.is_some(), TextureSlots::BASE_COLOR),
            (m.emissive_texture.is_some() && m.emissive.iter().any(|&e| e != 0.0), TextureSlots::EMISSIVE),
            (m.normal_texture.is_some() && m.normal_scale != 0.0, TextureSlots::NORMAL),
            (m.metallic_roughness_texture.is_some(), TextureSlots::METALLIC_ROUGHNESS),
            (m.occlusion_texture.is_some() && m.occlusion_strength != 0.0 && !TextureSlots::packed_occlusion(m), TextureSlots::OCCLUSION),
        ]
        .into_iter()
        .filter(|(has, _)| *has)
        .fold(TextureSlots(0), |all, (_, slot)| TextureSlots(all.0 | slot.0))
    }

    /// Whether `material`'s occlusion is the red of its metallic-roughness texture read at the
    /// same coordinates (glTF's packed ORM): the shader takes it from that sample.
    pub fn packed_occlusion(material: &pack::Material) -> bool {
        let m = material;
        m.occlusion_texture.is_some() && m.occlusion_texture == m.metallic_roughness_texture && m.occlusion_uv == m.metallic_roughness_uv
    }

    /// These slots less what the renderer's switches leave out: without material maps, only
    /// the base colour.
    pub fn with_maps(self, maps: bool) -> TextureSlots {
        if maps { self } else { TextureSlots(self.0 & TextureSlots::BASE_COLOR.0) }
    }
}

/// What `GpuScene::spawn` places.
#[derive(Debug, Clone, Copy)]
pub struct Spawn {
    pub mesh: u32,
    pub world: Mat4,
    pub is_static: bool,
    pub lightmap: Option<pack::LightmapRegion>,
    /// Drawn with this material instead of the mesh's own.
    pub material: Option<u32>,
}

impl Spawn {
    /// A dynamic instance of `mesh` at `world` with the mesh's materials.
    pub fn dynamic(mesh: u32, world: Mat4) -> Spawn {
        Spawn { mesh, world, is_static: false, lightmap: None, material: None }
    }
}

/// Baked light the renderer reads (pack lightmaps and probes), in physical units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BakedLighting {
    /// Unit vector towards the sun, and its illuminance (lux, linear RGB); zero without a sun.
    pub sun_dir: Vec3,
    pub sun_lux: Vec3,
    /// The sun's angular radius (radians) as the baker's soft shadows used it; 0 for a point.
    pub sun_angular_radius: f32,
    /// The sky's uniform radiance (nits, linear RGB) the level was baked under; zero without.
    pub sky: Vec3,
    /// Exposure that maps the lightmaps' log-average luminance (times a typical albedo of 0.5)
    /// to the key 0.18 (textures.md §5.4), before the Reinhard operator.
    pub exposure: f32,
}

pub struct GpuScene {
    /// Unique per upload in this process, so caches of derived data (the shadow map's static
    /// part) can tell one scene from the next even where Vulkan reuses handles.
    pub id: u64,
    pub meshes: Vec<GpuMesh>,
    pub materials: Vec<GpuMaterial>,
    /// The placed meshes, behind handles (`spawn`, `set_transform`, `despawn`), with their
    /// culling spheres.
    pub instances: Instances,
    /// What loading it took: submits through the staging ring and bytes copied.
    pub upload: UploadStats,
    pub vertex_buffer: Buffer,
    /// Every LOD's indices: the 32-bit ones from 0, the 16-bit ones from `index_offset_16`.
    pub index_buffer: Buffer,
    pub index_offset_16: vk::DeviceSize,
    /// The pack's textures by index; None for the baked lightmap pages, which live in `lightmaps`.
    pub(crate) textures: Vec<Option<Image>>,
    pub(crate) white: Image,
    /// Every baked lightmap page as one layer of a 2D array (pages have one size), so instances
    /// on different pages still draw in one instanced call; one black layer without a bake.
    pub(crate) lightmaps: Image,
    /// With directional lightmaps, each page's direction texture as the same layer of a second
    /// array (`lightmaps` then holds b0 and the sun's visibility); one grey layer without.
    pub(crate) lightmap_directions: Image,
    /// The lightmaps are directional (pack `LightmapLayout::directions`): lightmapped surfaces
    /// evaluate them for the shading normal and take the sun at run time.
    pub directional_lightmaps: bool,
    /// The specular lobe's (A, B) table the mesh shaders read (`shading::DfgLut`).
    pub(crate) dfg_lut: Image,
    /// The reflection probes' prefiltered cubes as one cube-map array (one black cube without
    /// probes), and the probes the shaders walk (boxes, capture points; `assets`).
    pub(crate) reflection_cubes: Image,
    pub(crate) reflection_probes: Buffer,
    /// How many reflection probes the scene has (0: the lit pipelines leave them out).
    pub reflection_probe_count: u32,
    pub(crate) samplers: SamplerCache,
    pub(crate) pool: vk::DescriptorPool,
    /// Set 2, bound once per pass: the lightmap array, the probe grid and every material's
    /// constants.
    pub scene_set: vk::DescriptorSet,
    pub(crate) probes: Buffer,
    pub(crate) material_constants: Buffer,
    /// Present when the pack has baked lightmaps: the renderer then shades in physical units.
    pub baked: Option<BakedLighting>,
    /// The meshes the pack's boids spawns name, by mesh index, as the boids pass draws them.
    pub flock_meshes: Vec<(u32, FlockMesh)>,
}

/// A mesh drawn as the birds of a flock: its full detail as a compact stream of (position,
/// normal) per triangle corner, each submesh a run in its material's base colour. Thousands of
/// instances of a few dozen triangles: lavapipe fetches 24-byte vertices without an index
/// buffer measurably faster than the 80-byte shared ones (the `boids-10k` bench).
pub struct FlockMesh {
    pub vertices: Buffer,
    /// (first vertex, vertex count, linear RGBA base colour) per submesh.
    pub parts: Vec<(u32, u32, [f32; 4])>,
    /// The farthest vertex from the mesh's origin: the bounding sphere of a bird, which is
    /// placed by rotation and translation only.
    pub radius: f32,
}

impl GpuScene {
    /// The flock mesh of mesh `mesh`, if a boids spawn of the pack names it.
    pub fn flock_mesh(&self, mesh: u32) -> Option<&FlockMesh> {
        self.flock_meshes.iter().find(|(m, _)| *m == mesh).map(|(_, f)| f)
    }
}

/// The descriptor set layouts a scene's sets are made for (the renderer's).
#[derive(Debug, Clone, Copy)]
pub struct SceneLayouts {
    /// Set 1: the base colour and emissive textures.
    pub material: vk::DescriptorSetLayout,
    /// Set 2: lightmap array, probe grid, material constants.
    pub scene: vk::DescriptorSetLayout,
}

/// Largest axis scale of a transform's 3x3 part.
pub fn max_scale(m: Mat4) -> f32 {
    let m3 = glam::Mat3::from_mat4(m);
    m3.x_axis.length().max(m3.y_axis.length()).max(m3.z_axis.length())
}

/// World transforms of every node (parents precede children, as the pack guarantees).
pub fn world_transforms(nodes: &[pack::Node]) -> Vec<Mat4> {
    let mut world: Vec<Mat4> = Vec::with_capacity(nodes.len());
    for n in nodes {
        let local = Mat4::from_cols_array(&n.local);
        let w = match n.parent {
            Some(p) => world[p as usize] * local,
            None => local,
        };
        world.push(w);
    }
    world
}

/// World-space bounds of a box under a transform (the box of the transformed corners).
pub fn transform_bounds(m: Mat4, min: Vec3, max: Vec3) -> (Vec3, Vec3) {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for i in 0..8 {
        let c = Vec3::new(
            if i & 1 == 0 { min.x } else { max.x },
            if i & 2 == 0 { min.y } else { max.y },
            if i & 4 == 0 { min.z } else { max.z },
        );
        let p = m.transform_point3(c);
        lo = lo.min(p);
        hi = hi.max(p);
    }
    (lo, hi)
}

impl GpuScene {
    /// World-space bounds of every instance together (framing the camera, fitting the shadow
    /// map): static instances' boxes (cached until a static change) and dynamic instances'
    /// current spheres (an animated character's follow its pose).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.instances.world_bounds(|mesh| self.meshes[mesh as usize].local_bounds()).unwrap_or((Vec3::splat(-1.0), Vec3::splat(1.0)))
    }

    /// Place an instance (static: lightmapped when it has a region, and its shadow cached;
    /// dynamic: lit by the probes and the sun; a material override draws every submesh with
    /// that material). Culling and the shadow map see it from the next frame.
    pub fn spawn(&mut self, s: Spawn) -> Result<InstanceId, InstanceError> {
        let bounds = self.meshes.get(s.mesh as usize).ok_or(InstanceError::NoMesh { mesh: s.mesh, meshes: self.meshes.len() })?.local_bounds();
        if let Some(material) = s.material.filter(|&m| m as usize >= self.materials.len()) {
            return Err(InstanceError::NoMaterial { material, materials: self.materials.len() });
        }
        Ok(self.instances.spawn(Instance { mesh: s.mesh, world: s.world, scale: max_scale(s.world), is_static: s.is_static, lightmap: s.lightmap, material: s.material }, bounds))
    }

    /// Move an instance (its culling sphere and the scene's bounds follow).
    pub fn set_transform(&mut self, id: InstanceId, world: Mat4) -> Result<(), InstanceError> {
        let mesh = self.instances.get(id)?.mesh;
        self.instances.set_transform(id, world, self.meshes[mesh as usize].local_bounds())
    }

    /// Remove an instance; other handles stay valid.
    pub fn despawn(&mut self, id: InstanceId) -> Result<(), InstanceError> {
        self.instances.despawn(id)
    }

    /// Triangles of every instance at full detail.
    pub fn triangle_count(&self) -> u64 {
        self.instances.iter().map(|i| self.meshes[i.mesh as usize].lods[0].triangles as u64).sum()
    }

    /// The placed instances of `old`, the same pack's scene on a lost device: what the game
    /// spawned, moved and removed through the scene API stays as it was.
    pub fn carry_on_from(&mut self, old: &mut GpuScene) {
        std::mem::swap(&mut self.instances, &mut old.instances);
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        unsafe { gpu.device.destroy_descriptor_pool(self.pool, None) };
        self.samplers.destroy(gpu);
        for t in self.textures.iter_mut().flatten() {
            t.destroy(gpu);
        }
        self.white.destroy(gpu);
        self.lightmaps.destroy(gpu);
        self.lightmap_directions.destroy(gpu);
        self.dfg_lut.destroy(gpu);
        self.reflection_cubes.destroy(gpu);
        self.reflection_probes.destroy(gpu);
        self.probes.destroy(gpu);
        self.material_constants.destroy(gpu);
        self.vertex_buffer.destroy(gpu);
        self.index_buffer.destroy(gpu);
        for (_, f) in &mut self.flock_meshes {
            f.vertices.destroy(gpu);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::TextureSlots;
    use pack::{Material, TextureTransform};

    #[test]
    fn a_materials_slots_are_the_textures_that_change_it() {
        let none = Material::default();
        assert_eq!(TextureSlots::of(&none), TextureSlots(0));
        let textured = Material {
            base_color_texture: Some(0),
            emissive_texture: Some(1),
            emissive: [1.0, 0.5, 0.0],
            normal_texture: Some(2),
            normal_scale: 1.0,
            metallic_roughness_texture: Some(3),
            occlusion_texture: Some(4),
            occlusion_strength: 1.0,
            ..Default::default()
        };
        assert_eq!(TextureSlots::of(&textured), TextureSlots::ALL);
        // Textures that cannot change the result are not sampled.
        let inert = Material { emissive: [0.0; 3], normal_scale: 0.0, occlusion_strength: 0.0, ..textured.clone() };
        assert_eq!(TextureSlots::of(&inert), TextureSlots(TextureSlots::BASE_COLOR.0 | TextureSlots::METALLIC_ROUGHNESS.0));
        // A packed ORM: occlusion comes with the metallic-roughness sample, unless it is read
        // at other coordinates.
        let orm = Material { occlusion_texture: Some(3), ..textured.clone() };
        assert_eq!(TextureSlots::of(&orm).0, TextureSlots::ALL.0 & !TextureSlots::OCCLUSION.0);
        let moved = TextureTransform { offset: [0.5, 0.0], ..Default::default() };
        let orm_elsewhere = Material { occlusion_uv: moved, ..orm.clone() };
        assert_eq!(TextureSlots::of(&orm_elsewhere), TextureSlots::ALL);
        // Without material maps, the base colour alone.
        assert_eq!(TextureSlots::ALL.with_maps(false), TextureSlots::BASE_COLOR);
        assert_eq!(TextureSlots::of(&inert).with_maps(true), TextureSlots::of(&inert));
    }
}
