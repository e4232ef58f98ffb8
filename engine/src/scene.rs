//! A cooked pack on the GPU: one vertex and one index buffer for all meshes, textures, material
//! descriptor sets, the baked lightmap pages as one array texture, and instances (mesh, world
//! transform, lightmap region) from the node hierarchy.

pub use crate::instances::{Instance, InstanceError, InstanceId, Instances, LocalBounds};
use crate::gpu::{Buffer, Gpu, Image};
use crate::samplers::SamplerCache;
use anyhow::{Context, Result};
use ash::vk;
use glam::{Mat4, Vec3};
use pack::{Pack, TextureFormat, TextureTransform};

/// Where one level of detail of a mesh lives inside the shared buffers.
#[derive(Debug, Clone)]
pub struct GpuLod {
    pub base_vertex: i32,
    pub first_index: u32,
    pub submeshes: Vec<pack::Submesh>,
    /// Geometric error to LOD 0, metres in object space (0 for LOD 0).
    pub error: f32,
    pub triangles: u32,
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
    /// The farthest any full-detail vertex lies from the mesh's origin: the bounding sphere of
    /// an instance placed by rotation and translation only (the boids' birds).
    pub origin_radius: f32,
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
    pub descriptor_set: vk::DescriptorSet,
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
    pub vertex_buffer: Buffer,
    pub index_buffer: Buffer,
    /// The pack's textures by index; None for the baked lightmap pages, which live in `lightmaps`.
    textures: Vec<Option<Image>>,
    white: Image,
    /// Every baked lightmap page as one layer of a 2D array (pages have one size), so instances
    /// on different pages still draw in one instanced call; one black layer without a bake.
    lightmaps: Image,
    samplers: SamplerCache,
    pool: vk::DescriptorPool,
    /// Set 2, bound once per pass: the lightmap array, the probe grid and every material's
    /// constants.
    pub scene_set: vk::DescriptorSet,
    probes: Buffer,
    material_constants: Buffer,
    /// Present when the pack has baked lightmaps: the renderer then shades in physical units.
    pub baked: Option<BakedLighting>,
}

/// The descriptor set layouts a scene's sets are made for (the renderer's).
#[derive(Debug, Clone, Copy)]
pub struct SceneLayouts {
    /// Set 1: the base colour and emissive textures.
    pub material: vk::DescriptorSetLayout,
    /// Set 2: lightmap array, probe grid, material constants.
    pub scene: vk::DescriptorSetLayout,
}

/// What the mesh shaders read per material (set 2 binding 2, std430; `MaterialConstants` in
/// shaders/mesh_draw.glsl): the emission and the UV transforms of the slots they sample.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct MaterialConstants {
    /// rgb: emitted radiance factor (multiplies the emissive texture).
    emission: [f32; 4],
    base_color_uv: [[f32; 4]; 2],
    emissive_uv: [[f32; 4]; 2],
}

/// A slot's transform as two rows `(a, b, c, tex_coord)`, `(d, e, f, 0)`: `uv' = (a u + b v + c,
/// d u + e v + f)` of the vertex's uv0 (tex_coord 0) or texcoord1 (1).
fn uv_rows(t: &TextureTransform) -> [[f32; 4]; 2] {
    let [r0, r1] = t.matrix();
    [[r0[0], r0[1], r0[2], t.tex_coord as f32], [r1[0], r1[1], r1[2], 0.0]]
}

fn vk_format(f: TextureFormat) -> vk::Format {
    match f {
        TextureFormat::Rgba8Srgb => vk::Format::R8G8B8A8_SRGB,
        TextureFormat::Rgba8Unorm => vk::Format::R8G8B8A8_UNORM,
        TextureFormat::Rgba16Float => vk::Format::R16G16B16A16_SFLOAT,
        TextureFormat::Rgba16Unorm => vk::Format::R16G16B16A16_UNORM,
    }
}

/// Whether the device can sample `format` with linear filtering (every format the pack uses is
/// guaranteed by Vulkan except 16-bit UNORM).
fn can_filter(gpu: &Gpu, format: vk::Format) -> bool {
    let props = unsafe { gpu.instance.get_physical_device_format_properties(gpu.physical_device, format) };
    props.optimal_tiling_features.contains(vk::FormatFeatureFlags::SAMPLED_IMAGE | vk::FormatFeatureFlags::SAMPLED_IMAGE_FILTER_LINEAR)
}

/// 16-bit UNORM texels as half floats, for devices that cannot filter R16G16B16A16_UNORM
/// (half float is mandatory). Values in [0, 1] keep 11 significant bits: a cooked unit normal
/// stays within 1e-3 of unit length.
pub fn unorm16_to_half(bytes: &[u8]) -> Vec<u8> {
    bytes.chunks_exact(2).flat_map(|b| half::f16::from_f32(u16::from_le_bytes([b[0], b[1]]) as f32 / 65535.0).to_le_bytes()).collect()
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
    pub fn upload(gpu: &Gpu, pack: &Pack, layouts: SceneLayouts) -> Result<GpuScene> {
        let material_layout = layouts.material;
        let m = &pack.manifest;
        // Concatenate every mesh's vertices and indices: one bind for the whole scene.
        let mut vertex_bytes = Vec::new();
        let mut index_bytes = Vec::new();
        let mut meshes = Vec::with_capacity(m.meshes.len());
        for mesh in &m.meshes {
            let mut lods = Vec::with_capacity(mesh.lods.len());
            for lod in &mesh.lods {
                lods.push(GpuLod {
                    base_vertex: (vertex_bytes.len() / pack::VERTEX_STRIDE) as i32,
                    first_index: (index_bytes.len() / 4) as u32,
                    submeshes: lod.submeshes.clone(),
                    error: lod.error,
                    triangles: lod.index_count / 3,
                });
                vertex_bytes.extend_from_slice(pack.bytes(lod.vertices));
                index_bytes.extend_from_slice(pack.bytes(lod.indices));
            }
            let origin_radius = mesh.lods.first().map_or(0.0, |lod| {
                pack.bytes(lod.vertices).chunks_exact(pack::VERTEX_STRIDE).map(|v| Vec3::from(bytemuck::pod_read_unaligned::<[f32; 3]>(&v[..12])).length()).fold(0.0, f32::max)
            });
            meshes.push(GpuMesh {
                name: mesh.name.clone(),
                origin_radius,
                lods,
                bounds_min: Vec3::from(mesh.bounds_min),
                bounds_max: Vec3::from(mesh.bounds_max),
                errors: mesh.lods.iter().map(|l| l.error).collect(),
            });
        }
        // Everything made below is owned until the scene is whole: an error frees what was made.
        let vertex_buffer = gpu.own(Buffer::with_data(gpu, "vertices", &vertex_bytes, vk::BufferUsageFlags::VERTEX_BUFFER)?);
        let index_buffer = gpu.own(Buffer::with_data(gpu, "indices", &index_bytes, vk::BufferUsageFlags::INDEX_BUFFER)?);

        // The lightmap pages go into one array texture below, not into images of their own.
        let pages: &[u32] = m.lightmap.as_ref().map_or(&[], |l| &l.textures);
        let mut textures = gpu.own(Vec::with_capacity(m.textures.len()));
        for (i, t) in m.textures.iter().enumerate() {
            if pages.contains(&(i as u32)) {
                textures.push(None);
                continue;
            }
            let mut format = vk_format(t.format);
            let mut mips: Vec<std::borrow::Cow<[u8]>> = t.mips.iter().map(|r| pack.bytes(*r).into()).collect();
            if t.format == TextureFormat::Rgba16Unorm && !can_filter(gpu, format) {
                format = vk::Format::R16G16B16A16_SFLOAT;
                mips = mips.iter().map(|m| unorm16_to_half(m).into()).collect();
            }
            let mips: Vec<&[u8]> = mips.iter().map(|m| m.as_ref()).collect();
            let extent = vk::Extent2D { width: t.width, height: t.height };
            textures.push(Some(
                Image::sampled_with_mips(gpu, &t.name, format, extent, &mips)
                    .with_context(|| format!("uploading texture '{}'", t.name))?,
            ));
        }
        // Empty texture slots sample this instead: no shader variants.
        let white = gpu.own(Image::sampled_with_mips(gpu, "white", vk::Format::R8G8B8A8_UNORM, vk::Extent2D { width: 1, height: 1 }, &[&[255; 4]])?);
        let lightmaps = gpu.own(match m.lightmap.as_ref().filter(|l| !l.textures.is_empty()) {
            Some(l) => {
                let layers: Vec<&[u8]> = pages.iter().map(|&t| pack.bytes(m.textures[t as usize].mips[0])).collect();
                let [width, height] = l.pages[0];
                Image::sampled_array(gpu, "lightmaps", vk::Format::R16G16B16A16_SFLOAT, vk::Extent2D { width, height }, &layers)
                    .with_context(|| format!("uploading {} lightmap pages of {width}x{height}", layers.len()))?
            }
            None => Image::sampled_array(gpu, "no lightmap", vk::Format::R16G16B16A16_SFLOAT, vk::Extent2D { width: 1, height: 1 }, &[&[0; 8]])?,
        });
        let mut samplers = gpu.own(SamplerCache::default());

        let material_count = m.materials.len() as u32;
        let pool_sizes = [
            vk::DescriptorPoolSize { ty: vk::DescriptorType::COMBINED_IMAGE_SAMPLER, descriptor_count: 2 * material_count + 1 },
            vk::DescriptorPoolSize { ty: vk::DescriptorType::STORAGE_BUFFER, descriptor_count: 2 },
        ];
        let pool = gpu.own(unsafe {
            gpu.device.create_descriptor_pool(
                &vk::DescriptorPoolCreateInfo::default().max_sets(material_count + 1).pool_sizes(&pool_sizes),
                None,
            )?
        });
        let mut materials = Vec::with_capacity(m.materials.len());
        for mat in &m.materials {
            let layouts = [material_layout];
            let set = unsafe {
                gpu.device.allocate_descriptor_sets(&vk::DescriptorSetAllocateInfo::default().descriptor_pool(*pool).set_layouts(&layouts))?[0]
            };
            // Each slot's texture with its own sampler state; white for an empty slot.
            let mut slot = |texture: Option<u32>| -> Result<[vk::DescriptorImageInfo; 1]> {
                let (image, state) = texture
                    .and_then(|t| Some((textures[t as usize].as_ref()?, m.textures[t as usize].sampler)))
                    .unwrap_or((&*white, pack::Sampler::default()));
                let sampler = samplers.for_texture(gpu, state, image.mip_levels)?;
                Ok([vk::DescriptorImageInfo { sampler, image_view: image.view, image_layout: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL }])
            };
            let (base_color, emissive) = (slot(mat.base_color_texture)?, slot(mat.emissive_texture)?);
            let write = |binding: u32, info| vk::WriteDescriptorSet::default().dst_set(set).dst_binding(binding).descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER).image_info(info);
            unsafe { gpu.device.update_descriptor_sets(&[write(0, &base_color), write(1, &emissive)], &[]) };
            materials.push(GpuMaterial {
                base_color: mat.base_color,
                alpha_cutoff: if mat.alpha_mode == pack::AlphaMode::Mask { mat.alpha_cutoff } else { -1.0 },
                double_sided: mat.double_sided,
                descriptor_set: set,
            });
        }

        let world = world_transforms(&m.nodes);
        let mut instances = Instances::default();
        for (n, w) in m.nodes.iter().zip(&world) {
            if let Some(mesh) = n.mesh {
                let bounds = meshes[mesh as usize].local_bounds();
                instances.spawn(Instance { mesh, world: *w, scale: max_scale(*w), is_static: n.is_static, lightmap: n.lightmap, material: None }, bounds);
            }
        }

        // Set 2: one for the whole scene.
        let probe_bytes = probe_buffer_bytes(pack);
        let probes = gpu.own(Buffer::with_data(gpu, "probes", &probe_bytes, vk::BufferUsageFlags::STORAGE_BUFFER)?);
        let mut constants: Vec<MaterialConstants> = m
            .materials
            .iter()
            .map(|mt| MaterialConstants {
                emission: [mt.emissive[0], mt.emissive[1], mt.emissive[2], 0.0],
                base_color_uv: uv_rows(&mt.base_color_uv),
                emissive_uv: uv_rows(&mt.emissive_uv),
            })
            .collect();
        if constants.is_empty() {
            // A buffer cannot be empty.
            constants.push(MaterialConstants::default());
        }
        let constant_bytes: &[u8] = bytemuck::cast_slice(&constants);
        let material_constants = gpu.own(Buffer::with_data(gpu, "material constants", constant_bytes, vk::BufferUsageFlags::STORAGE_BUFFER)?);
        // Lightmaps are read between their texels, never past the page's edge.
        let clamped = pack::Sampler { wrap_s: pack::Wrap::Clamp, wrap_t: pack::Wrap::Clamp, mipmap_filter: None, ..Default::default() };
        let lightmap_sampler = samplers.get(gpu, clamped, false)?;
        let scene_layout = [layouts.scene];
        let scene_set = unsafe { gpu.device.allocate_descriptor_sets(&vk::DescriptorSetAllocateInfo::default().descriptor_pool(*pool).set_layouts(&scene_layout))?[0] };
        let image_info = [vk::DescriptorImageInfo { sampler: lightmap_sampler, image_view: lightmaps.view, image_layout: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL }];
        let probe_info = [vk::DescriptorBufferInfo { buffer: probes.buffer, offset: 0, range: vk::WHOLE_SIZE }];
        let constants_info = [vk::DescriptorBufferInfo { buffer: material_constants.buffer, offset: 0, range: vk::WHOLE_SIZE }];
        let writes = [
            vk::WriteDescriptorSet::default().dst_set(scene_set).dst_binding(0).descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER).image_info(&image_info),
            vk::WriteDescriptorSet::default().dst_set(scene_set).dst_binding(1).descriptor_type(vk::DescriptorType::STORAGE_BUFFER).buffer_info(&probe_info),
            vk::WriteDescriptorSet::default().dst_set(scene_set).dst_binding(2).descriptor_type(vk::DescriptorType::STORAGE_BUFFER).buffer_info(&constants_info),
        ];
        unsafe { gpu.device.update_descriptor_sets(&writes, &[]) };
        let baked = (!pages.is_empty()).then(|| baked_lighting(pack));

        static NEXT_ID: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
        Ok(GpuScene {
            id: NEXT_ID.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
            meshes,
            materials,
            instances,
            vertex_buffer: vertex_buffer.keep(),
            index_buffer: index_buffer.keep(),
            textures: textures.keep(),
            white: white.keep(),
            lightmaps: lightmaps.keep(),
            samplers: samplers.keep(),
            pool: pool.keep(),
            scene_set,
            probes: probes.keep(),
            material_constants: material_constants.keep(),
            baked,
        })
    }

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

    pub fn destroy(&mut self, gpu: &Gpu) {
        unsafe { gpu.device.destroy_descriptor_pool(self.pool, None) };
        self.samplers.destroy(gpu);
        for t in self.textures.iter_mut().flatten() {
            t.destroy(gpu);
        }
        self.white.destroy(gpu);
        self.lightmaps.destroy(gpu);
        self.probes.destroy(gpu);
        self.material_constants.destroy(gpu);
        self.vertex_buffer.destroy(gpu);
        self.index_buffer.destroy(gpu);
    }
}

/// The probe grid as the shaders read it (std430): origin, spacing (vec4s), counts (uvec4),
/// then per probe 27 SH floats (9 x rgb) and the sun visibility. An empty grid (counts 0) when
/// the pack has no probes: dynamic objects then get the sun only.
fn probe_buffer_bytes(pack: &Pack) -> Vec<u8> {
    let mut out = Vec::new();
    let Some(g) = &pack.manifest.probes else {
        out.extend(std::iter::repeat_n(0u8, 48 + 28 * 4));
        return out;
    };
    for v in [g.origin, g.spacing] {
        out.extend([v[0], v[1], v[2], 0.0].iter().flat_map(|x| x.to_le_bytes()));
    }
    out.extend([g.counts[0], g.counts[1], g.counts[2], 0].iter().flat_map(|x| x.to_le_bytes()));
    let (sh, vis) = (pack.bytes(g.sh), pack.bytes(g.sun_visibility));
    for i in 0..g.count() as usize {
        out.extend_from_slice(&sh[i * 108..(i + 1) * 108]);
        out.extend_from_slice(&vis[i * 4..(i + 1) * 4]);
    }
    out
}

/// Sun and exposure for a baked pack: exposure k / L with k = 0.18 and L the log-average
/// luminance (textures.md eq. 21.1) of the lightmaps' covered texels times an albedo of 0.5.
fn baked_lighting(pack: &Pack) -> BakedLighting {
    let m = &pack.manifest;
    let (mut sum, mut count) = (0.0f64, 0u64);
    for &t in m.lightmap.as_ref().map_or(&[][..], |l| &l.textures[..]) {
        let tex = &m.textures[t as usize];
        for px in pack.bytes(tex.mips[0]).chunks_exact(8) {
            let c: [f32; 3] = std::array::from_fn(|k| half::f16::from_le_bytes([px[2 * k], px[2 * k + 1]]).to_f32());
            let lum = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
            if lum > 0.0 {
                sum += (1e-4 + 0.5 * lum as f64).ln();
                count += 1;
            }
        }
    }
    let log_average = if count > 0 { (sum / count as f64).exp() as f32 } else { 1.0 };
    let (sun_dir, sun_lux) = match m.lights.iter().find(|l| l.kind == pack::LightKind::Sun) {
        Some(sun) => ((-Vec3::from(sun.direction)).normalize_or_zero(), Vec3::from(sun.color) * sun.intensity),
        None => (Vec3::Y, Vec3::ZERO),
    };
    BakedLighting { sun_dir, sun_lux, exposure: 0.18 / log_average }
}
