//! Loading a cooked pack onto the device: every mesh's vertices and indices into one vertex and
//! one index buffer, textures (with the sampler state each material slot asks for), material
//! descriptor sets, the baked lightmap pages as one array texture, the probe grid, and the
//! instances from the node hierarchy, and each small LOD's triangles kept on the CPU for
//! occlusion culling. What it makes is a `scene::GpuScene`. [`reload`]: a pack replaced while
//! the program runs.

use crate::gpu::{Gpu, Image, Uploader};
use crate::render::occlusion::{OccluderMesh, MAX_OCCLUDER_TRIANGLES};
use crate::render::samplers::SamplerCache;
use crate::scene::{max_scale, world_transforms, BakedLighting, FlockMesh, GpuLod, GpuMaterial, GpuMesh, GpuScene, Instance, Instances, LocalBounds, SceneLayouts, TextureSlots, UploadStats};
use anyhow::{Context, Result};
use ash::vk;
use glam::Vec3;
use pack::{Pack, TextureFormat, TextureTransform};
use std::sync::Arc;

pub mod reload;

/// What the mesh shaders read per material (set 2 binding 2, std430; `MaterialConstants` in
/// shaders/mesh_draw.glsl): the emission and the UV transforms of the slots they sample.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct MaterialConstants {
    /// rgb: emitted radiance factor (multiplies the emissive texture).
    emission: [f32; 4],
    /// metallic, roughness, normalTexture.scale (0 without a normal map), occlusion strength.
    pbr: [f32; 4],
    base_color_uv: [[f32; 4]; 2],
    emissive_uv: [[f32; 4]; 2],
    normal_uv: [[f32; 4]; 2],
    metallic_roughness_uv: [[f32; 4]; 2],
    occlusion_uv: [[f32; 4]; 2],
}

/// The staging ring scenes upload through (`gpu::Uploader`): the demo level (25 MB) goes in
/// one submit; bigger packs take one more per 32 MiB.
const UPLOAD_RING_BYTES: u64 = 32 << 20;

/// Texture slots of a material's descriptor set (set 1), in binding order.
const MATERIAL_SLOTS: u32 = 5;

/// Size of the (A, B) table: 32 x 32 texels over (n.v, roughness), as the brief's tests.
const DFG_LUT_SIZE: u32 = shading::DFG_TABLE_SIZE;

/// The table as R16G16_SFLOAT texels, converted once a process (it is the same for every
/// scene; computed ahead of time, `shading::DfgLut::engine`).
fn dfg_lut_texels() -> &'static [u8] {
    static TEXELS: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
    TEXELS.get_or_init(|| {
        let lut = shading::DfgLut::engine();
        lut.texels.iter().flat_map(|t| t.map(half::f16::from_f32)).flat_map(|h| h.to_le_bytes()).collect()
    })
}

/// A slot's transform as two rows `(a, b, c, tex_coord)`, `(d, e, f, has)`: `uv' = (a u + b v +
/// c, d u + e v + f)` of the vertex's uv0 (tex_coord 0) or texcoord1 (1); `has` is 1 when the
/// slot has a texture (the shader samples only then: on lavapipe every sample costs).
fn uv_rows(t: &TextureTransform, texture: Option<u32>) -> [[f32; 4]; 2] {
    let [r0, r1] = t.matrix();
    [[r0[0], r0[1], r0[2], t.tex_coord as f32], [r1[0], r1[1], r1[2], texture.is_some() as u32 as f32]]
}

/// The occlusion slot's rows; their flag is 2 when occlusion is the red channel of the
/// metallic-roughness texture read at the same coordinates (glTF's packed ORM, as the level's
/// procedural materials and most exported assets have it): the shader then takes it from that
/// sample instead of sampling the same texel again.
fn occlusion_rows(mt: &pack::Material) -> [[f32; 4]; 2] {
    let mut rows = uv_rows(&mt.occlusion_uv, mt.occlusion_texture);
    if TextureSlots::packed_occlusion(mt) {
        rows[1][3] = 2.0;
    }
    rows
}

fn vk_format(f: TextureFormat) -> vk::Format {
    match f {
        TextureFormat::Rgba8Srgb => vk::Format::R8G8B8A8_SRGB,
        TextureFormat::Rgba8Unorm => vk::Format::R8G8B8A8_UNORM,
        TextureFormat::Rgba16Float => vk::Format::R16G16B16A16_SFLOAT,
        TextureFormat::Rgba16Unorm => vk::Format::R16G16B16A16_UNORM,
        TextureFormat::Bc7Srgb => vk::Format::BC7_SRGB_BLOCK,
        TextureFormat::Bc7Unorm => vk::Format::BC7_UNORM_BLOCK,
        TextureFormat::Bc5Unorm => vk::Format::BC5_UNORM_BLOCK,
        TextureFormat::Bc4Unorm => vk::Format::BC4_UNORM_BLOCK,
        TextureFormat::Bc6hUfloat => vk::Format::BC6H_UFLOAT_BLOCK,
    }
}

/// The plain format a block-compressed one decodes to (`pack::bc::decode`'s layout): every one
/// of them is sampled with linear filtering on every Vulkan device.
fn decoded_vk_format(f: TextureFormat) -> vk::Format {
    match f {
        TextureFormat::Bc7Srgb => vk::Format::R8G8B8A8_SRGB,
        TextureFormat::Bc7Unorm => vk::Format::R8G8B8A8_UNORM,
        TextureFormat::Bc5Unorm => vk::Format::R8G8_UNORM,
        TextureFormat::Bc4Unorm => vk::Format::R8_UNORM,
        TextureFormat::Bc6hUfloat => vk::Format::R16G16B16A16_SFLOAT,
        plain => vk_format(plain),
    }
}

/// Whether block-compressed textures are sampled as they are (`true`) or decoded at load.
/// GPUs sample them natively (a quarter to an eighth of the memory and bandwidth); CPU devices
/// get them decoded, since lavapipe decodes every texel it filters: sampling BC7 made the demo
/// flythrough's shading pass 5.9x slower (8.3 -> 49.1 ms, README "Texture formats").
/// `ENGINE_BC=native` or `=decode` forces either. A device without the format (or without
/// linear filtering of it) always gets the decoded texels.
fn native_bc(gpu: &Gpu, format: TextureFormat) -> bool {
    let wanted = match std::env::var("ENGINE_BC").as_deref() {
        Ok("native") => true,
        Ok("decode") => false,
        _ => gpu.caps.device_type != vk::PhysicalDeviceType::CPU,
    };
    wanted && can_filter(gpu, vk_format(format))
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

/// One texture's levels as they go to the device: the format, and each level's bytes (the
/// pack's own, or converted).
type Texels<'a> = (vk::Format, Vec<std::borrow::Cow<'a, [u8]>>);

/// Every texture's levels in the format the device samples (material textures, and the
/// lightmap pages and direction textures, which go into array textures). Block-compressed
/// textures the device does not sample natively (`native_bc`) are decoded here, in parallel over
/// every level of every texture; 16-bit UNORM normal maps become half floats where the device
/// cannot filter them.
fn device_texels<'a>(gpu: &Gpu, pack: &'a Pack) -> Result<Vec<Texels<'a>>> {
    use rayon::prelude::*;
    let m = &pack.manifest;
    let plans: Vec<(vk::Format, bool)> = m
        .textures
        .iter()
        .map(|t| {
            if t.format.is_compressed() && !native_bc(gpu, t.format) {
                (decoded_vk_format(t.format), true)
            } else if t.format == TextureFormat::Rgba16Unorm && !can_filter(gpu, vk_format(t.format)) {
                (vk::Format::R16G16B16A16_SFLOAT, true)
            } else {
                (vk_format(t.format), false)
            }
        })
        .collect();
    // (texture, level) pairs that need converting: a big texture's levels spread over threads.
    let jobs: Vec<(usize, usize)> = plans
        .iter()
        .enumerate()
        .filter(|(_, p)| p.1)
        .flat_map(|(i, _)| (0..m.textures[i].mips.len()).map(move |l| (i, l)))
        .collect();
    let converted: Vec<Result<Vec<u8>>> = jobs
        .par_iter()
        .map(|&(i, l)| {
            let t = &m.textures[i];
            let bytes = pack.bytes(t.mips[l]);
            if t.format == TextureFormat::Rgba16Unorm {
                return Ok(unorm16_to_half(bytes));
            }
            let (w, h) = ((t.width >> l).max(1), (t.height >> l).max(1));
            pack::bc::decode(t.format, w, h, bytes).with_context(|| format!("texture '{}' level {l}: blocks do not decode", t.name))
        })
        .collect();
    let mut converted = jobs.into_iter().zip(converted).peekable();
    let mut out = Vec::with_capacity(plans.len());
    for (i, (format, convert)) in plans.into_iter().enumerate() {
        let t = &m.textures[i];
        let mips = if convert {
            let mut mips = Vec::with_capacity(t.mips.len());
            while let Some(((_, _), bytes)) = converted.next_if(|((j, _), _)| *j == i) {
                mips.push(std::borrow::Cow::Owned(bytes?));
            }
            mips
        } else {
            t.mips.iter().map(|r| std::borrow::Cow::Borrowed(pack.bytes(*r))).collect()
        };
        out.push((format, mips));
    }
    Ok(out)
}

impl GpuScene {
    pub fn upload(gpu: &Gpu, pack: &Pack, layouts: SceneLayouts) -> Result<GpuScene> {
        let material_layout = layouts.material;
        let m = &pack.manifest;
        // Every upload below goes through one staging ring, flushed at the end: a few submits
        // for the whole scene. Everything made is owned until the scene is whole: an error
        // frees what was made.
        // (No bigger than the pack's data, plus what decoding textures adds and room for what
        // the loader makes itself: a small pack gets a small ring.)
        let pages: &[u32] = m.lightmap.as_ref().map_or(&[], |l| &l.textures);
        let directions: &[u32] = m.lightmap.as_ref().map_or(&[], |l| &l.directions);
        let texels = device_texels(gpu, pack)?;
        let grown: u64 = m.textures.iter().zip(&texels).map(|(t, x)| {
            let stored: u64 = t.mips.iter().map(|r| r.len).sum();
            x.1.iter().map(|b| b.len() as u64).sum::<u64>().saturating_sub(stored)
        }).sum();
        let mut up = gpu.own(Uploader::new(UPLOAD_RING_BYTES.min(pack.data.len() as u64 + grown + (1 << 20))));
        // Every mesh's vertices and indices, in the order they are laid out: one vertex buffer
        // for the whole scene, one index buffer holding the 32-bit LODs' indices and then the
        // 16-bit ones (draws bind it at the region of their LOD's width).
        let mut vertex_parts: Vec<&[u8]> = Vec::new();
        let mut index_parts: Vec<&[u8]> = Vec::new();
        let mut index_parts_16: Vec<&[u8]> = Vec::new();
        let (mut vertices, mut indices, mut indices_16) = (0usize, 0usize, 0usize);
        let mut meshes = Vec::with_capacity(m.meshes.len());
        for mesh in &m.meshes {
            let mut lods = Vec::with_capacity(mesh.lods.len());
            for lod in &mesh.lods {
                let (bounds, occluder) = lod_geometry(pack, lod, mesh);
                let (parts, count, index_type) = match lod.index_format {
                    pack::IndexFormat::U16 => (&mut index_parts_16, &mut indices_16, vk::IndexType::UINT16),
                    pack::IndexFormat::U32 => (&mut index_parts, &mut indices, vk::IndexType::UINT32),
                };
                let first_index = *count as u32;
                *count += lod.index_count as usize;
                parts.push(pack.bytes(lod.indices));
                lods.push(GpuLod {
                    base_vertex: vertices as i32,
                    first_index,
                    index_type,
                    submeshes: lod.submeshes.clone(),
                    uv_ranges: lod.uv_ranges,
                    error: lod.error,
                    triangles: lod.index_count / 3,
                    bounds,
                    occluder,
                });
                vertices += lod.vertex_count as usize;
                vertex_parts.push(pack.bytes(lod.vertices));
            }
            meshes.push(GpuMesh {
                name: mesh.name.clone(),
                lods,
                bounds_min: Vec3::from(mesh.bounds_min),
                bounds_max: Vec3::from(mesh.bounds_max),
                errors: mesh.lods.iter().map(|l| l.error).collect(),
            });
        }
        let vertex_buffer = gpu.own(up.buffer(gpu, "vertices", &vertex_parts, vk::BufferUsageFlags::VERTEX_BUFFER)?);
        // The 32-bit region's length is a multiple of 4, so the 16-bit region starts aligned.
        let index_offset_16 = (indices * 4) as vk::DeviceSize;
        index_parts.extend(index_parts_16);
        if indices + indices_16 == 0 {
            index_parts.push(&[0; 4]); // a buffer cannot be empty
        }
        let index_buffer = gpu.own(up.buffer(gpu, "indices", &index_parts, vk::BufferUsageFlags::INDEX_BUFFER)?);

        // The lightmap pages (and their direction textures) go into array textures below, not
        // into images of their own.
        let mut textures = gpu.own(Vec::with_capacity(m.textures.len()));
        for (i, (t, (format, mips))) in m.textures.iter().zip(&texels).enumerate() {
            if pages.contains(&(i as u32)) || directions.contains(&(i as u32)) {
                textures.push(None);
                continue;
            }
            let mips: Vec<&[u8]> = mips.iter().map(|m| m.as_ref()).collect();
            let extent = vk::Extent2D { width: t.width, height: t.height };
            textures.push(Some(
                Image::sampled_with_mips(gpu, &mut up, &t.name, *format, extent, &mips)
                    .with_context(|| format!("uploading texture '{}'", t.name))?,
            ));
        }
        // Empty texture slots hold this (the pipelines made for a material's `TextureSlots`
        // do not sample them; those for every slot read white, which changes nothing).
        let white = gpu.own(Image::sampled_with_mips(gpu, &mut up, "white", vk::Format::R8G8B8A8_UNORM, vk::Extent2D { width: 1, height: 1 }, &[&[255; 4]])?);
        // Each set in one format (the pack checks it): the layers' level 0 as the device takes them.
        let layers = |ids: &[u32]| -> (vk::Format, Vec<&[u8]>) { (texels[ids[0] as usize].0, ids.iter().map(|&t| texels[t as usize].1[0].as_ref()).collect()) };
        let lightmaps = gpu.own(match m.lightmap.as_ref().filter(|l| !l.textures.is_empty()) {
            Some(l) => {
                let (format, layers) = layers(pages);
                let [width, height] = l.pages[0];
                Image::sampled_array(gpu, &mut up, "lightmaps", format, vk::Extent2D { width, height }, &layers)
                    .with_context(|| format!("uploading {} lightmap pages of {width}x{height}", layers.len()))?
            }
            None => Image::sampled_array(gpu, &mut up, "no lightmap", vk::Format::R16G16B16A16_SFLOAT, vk::Extent2D { width: 1, height: 1 }, &[&[0; 8]])?,
        });
        let lightmap_directions = gpu.own(match m.lightmap.as_ref().filter(|l| !l.directions.is_empty()) {
            Some(l) => {
                let (format, layers) = layers(directions);
                let [width, height] = l.pages[0];
                Image::sampled_array(gpu, &mut up, "lightmap directions", format, vk::Extent2D { width, height }, &layers)
                    .with_context(|| format!("uploading {} lightmap direction pages of {width}x{height}", layers.len()))?
            }
            None => Image::sampled_array(gpu, &mut up, "no lightmap directions", vk::Format::R8G8B8A8_UNORM, vk::Extent2D { width: 1, height: 1 }, &[&[128, 128, 128, 255]])?,
        });
        let reflection_cubes = gpu.own(reflection_cubes(gpu, &mut up, pack)?);
        let reflection_bytes = reflection_probe_bytes(pack);
        let reflection_probes = gpu.own(up.buffer(gpu, "reflection probes", &[&reflection_bytes], vk::BufferUsageFlags::STORAGE_BUFFER)?);
        let mut samplers = gpu.own(SamplerCache::default());

        let material_count = m.materials.len() as u32;
        let pool_sizes = [
            vk::DescriptorPoolSize { ty: vk::DescriptorType::COMBINED_IMAGE_SAMPLER, descriptor_count: MATERIAL_SLOTS * material_count + 4 },
            vk::DescriptorPoolSize { ty: vk::DescriptorType::STORAGE_BUFFER, descriptor_count: 3 },
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
            // Binding order: base colour, emissive, normal, metallic-roughness, occlusion.
            let infos = [mat.base_color_texture, mat.emissive_texture, mat.normal_texture, mat.metallic_roughness_texture, mat.occlusion_texture].map(&mut slot);
            let infos = infos.into_iter().collect::<Result<Vec<_>>>()?;
            let writes: Vec<_> = infos
                .iter()
                .enumerate()
                .map(|(binding, info)| vk::WriteDescriptorSet::default().dst_set(set).dst_binding(binding as u32).descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER).image_info(info))
                .collect();
            unsafe { gpu.device.update_descriptor_sets(&writes, &[]) };
            materials.push(GpuMaterial {
                base_color: mat.base_color,
                alpha_cutoff: if mat.alpha_mode == pack::AlphaMode::Mask { mat.alpha_cutoff } else { -1.0 },
                double_sided: mat.double_sided,
                blend: mat.alpha_mode == pack::AlphaMode::Blend,
                slots: TextureSlots::of(mat),
                glossy: GpuMaterial::reflects_probes(mat),
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
        let probes = gpu.own(up.buffer(gpu, "probes", &[&probe_bytes], vk::BufferUsageFlags::STORAGE_BUFFER)?);
        let mut constants: Vec<MaterialConstants> = m
            .materials
            .iter()
            .map(|mt| MaterialConstants {
                emission: [mt.emissive[0], mt.emissive[1], mt.emissive[2], 0.0],
                // Scale 0 leaves the normal alone where the slot samples the white stand-in.
                pbr: [mt.metallic, mt.roughness, if mt.normal_texture.is_some() { mt.normal_scale } else { 0.0 }, mt.occlusion_strength],
                base_color_uv: uv_rows(&mt.base_color_uv, mt.base_color_texture),
                emissive_uv: uv_rows(&mt.emissive_uv, mt.emissive_texture),
                normal_uv: uv_rows(&mt.normal_uv, mt.normal_texture),
                metallic_roughness_uv: uv_rows(&mt.metallic_roughness_uv, mt.metallic_roughness_texture),
                occlusion_uv: occlusion_rows(mt),
            })
            .collect();
        if constants.is_empty() {
            // A buffer cannot be empty.
            constants.push(MaterialConstants::default());
        }
        let constant_bytes: &[u8] = bytemuck::cast_slice(&constants);
        let material_constants = gpu.own(up.buffer(gpu, "material constants", &[constant_bytes], vk::BufferUsageFlags::STORAGE_BUFFER)?);
        // Lightmaps are read between their texels, never past the page's edge.
        let clamped = pack::Sampler { wrap_s: pack::Wrap::Clamp, wrap_t: pack::Wrap::Clamp, mipmap_filter: None, ..Default::default() };
        let lightmap_sampler = samplers.get(gpu, clamped, false)?;
        let scene_layout = [layouts.scene];
        let scene_set = unsafe { gpu.device.allocate_descriptor_sets(&vk::DescriptorSetAllocateInfo::default().descriptor_pool(*pool).set_layouts(&scene_layout))?[0] };
        let image_info = [vk::DescriptorImageInfo { sampler: lightmap_sampler, image_view: lightmaps.view, image_layout: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL }];
        let direction_info = [vk::DescriptorImageInfo { sampler: lightmap_sampler, image_view: lightmap_directions.view, image_layout: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL }];
        let lut_extent = vk::Extent2D { width: DFG_LUT_SIZE, height: DFG_LUT_SIZE };
        let dfg_lut = gpu.own(Image::sampled_with_mips(gpu, &mut up, "dfg lut", vk::Format::R16G16_SFLOAT, lut_extent, &[dfg_lut_texels()])?);
        let lut_info = [vk::DescriptorImageInfo { sampler: lightmap_sampler, image_view: dfg_lut.view, image_layout: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL }];
        let probe_info = [vk::DescriptorBufferInfo { buffer: probes.buffer, offset: 0, range: vk::WHOLE_SIZE }];
        // Trilinear between the roughness levels; cube sampling is seamless across faces.
        let trilinear = pack::Sampler { wrap_s: pack::Wrap::Clamp, wrap_t: pack::Wrap::Clamp, mipmap_filter: Some(pack::Filter::Linear), ..Default::default() };
        let cube_info = [vk::DescriptorImageInfo { sampler: samplers.get(gpu, trilinear, false)?, image_view: reflection_cubes.view, image_layout: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL }];
        let reflection_info = [vk::DescriptorBufferInfo { buffer: reflection_probes.buffer, offset: 0, range: vk::WHOLE_SIZE }];
        let constants_info = [vk::DescriptorBufferInfo { buffer: material_constants.buffer, offset: 0, range: vk::WHOLE_SIZE }];
        let writes = [
            vk::WriteDescriptorSet::default().dst_set(scene_set).dst_binding(0).descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER).image_info(&image_info),
            vk::WriteDescriptorSet::default().dst_set(scene_set).dst_binding(1).descriptor_type(vk::DescriptorType::STORAGE_BUFFER).buffer_info(&probe_info),
            vk::WriteDescriptorSet::default().dst_set(scene_set).dst_binding(2).descriptor_type(vk::DescriptorType::STORAGE_BUFFER).buffer_info(&constants_info),
            vk::WriteDescriptorSet::default().dst_set(scene_set).dst_binding(3).descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER).image_info(&lut_info),
            vk::WriteDescriptorSet::default().dst_set(scene_set).dst_binding(4).descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER).image_info(&direction_info),
            vk::WriteDescriptorSet::default().dst_set(scene_set).dst_binding(5).descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER).image_info(&cube_info),
            vk::WriteDescriptorSet::default().dst_set(scene_set).dst_binding(6).descriptor_type(vk::DescriptorType::STORAGE_BUFFER).buffer_info(&reflection_info),
        ];
        unsafe { gpu.device.update_descriptor_sets(&writes, &[]) };
        let baked = (!pages.is_empty()).then(|| baked_lighting(pack, &texels)).transpose()?;
        let mut flock_meshes = gpu.own(Vec::new());
        for mesh in m.spawns.iter().filter(|s| s.kind == "boids").filter_map(|s| s.params.get("mesh")?.as_u64()) {
            let mesh = mesh as u32; // the pack checked it names one of its meshes
            if !flock_meshes.iter().any(|(m, _)| *m == mesh) {
                let f = flock_mesh(gpu, &mut up, pack, mesh)?;
                flock_meshes.push((mesh, f));
            }
        }

        // The copies run: the scene is ready once this returns.
        up.flush(gpu)?;
        let upload = UploadStats { submits: up.submits, bytes: up.bytes };
        up.destroy(gpu);

        static NEXT_ID: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
        Ok(GpuScene {
            upload,
            id: NEXT_ID.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
            meshes,
            materials,
            instances,
            vertex_buffer: vertex_buffer.keep(),
            index_buffer: index_buffer.keep(),
            index_offset_16,
            textures: textures.keep(),
            white: white.keep(),
            lightmaps: lightmaps.keep(),
            lightmap_directions: lightmap_directions.keep(),
            directional_lightmaps: !directions.is_empty(),
            dfg_lut: dfg_lut.keep(),
            reflection_cubes: reflection_cubes.keep(),
            reflection_probes: reflection_probes.keep(),
            reflection_probe_count: m.reflection_probes.as_ref().map_or(0, |r| r.probes.len() as u32),
            samplers: samplers.keep(),
            pool: pool.keep(),
            scene_set,
            probes: probes.keep(),
            material_constants: material_constants.keep(),
            baked,
            flock_meshes: flock_meshes.keep(),
        })
    }
}

/// A LOD's box in the mesh's space (the mesh's own where it has no vertices) and, for a LOD of
/// up to `occlusion::MAX_OCCLUDER_TRIANGLES` triangles, its triangles for occlusion culling.
fn lod_geometry(pack: &Pack, lod: &pack::MeshLod, mesh: &pack::Mesh) -> (LocalBounds, Option<Arc<OccluderMesh>>) {
    let positions: Vec<Vec3> = pack::vertex::decode_positions(pack.bytes(lod.vertices)).into_iter().map(Vec3::from).collect();
    let bounds = match positions.iter().copied().reduce(Vec3::min).zip(positions.iter().copied().reduce(Vec3::max)) {
        Some((min, max)) => LocalBounds { min, max },
        None => LocalBounds { min: Vec3::from(mesh.bounds_min), max: Vec3::from(mesh.bounds_max) },
    };
    let occluder = (lod.index_count as usize / 3 <= MAX_OCCLUDER_TRIANGLES && lod.index_count >= 3).then(|| {
        let indices = pack.indices(lod);
        let submeshes: Vec<(u32, u32)> = lod.submeshes.iter().map(|s| (s.first_index, s.index_count)).collect();
        Arc::new(OccluderMesh::new(&positions, &indices, &submeshes))
    });
    (bounds, occluder)
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

/// The reflection probes' cubes as one cube-map array (half RGBA), in the pack's probe order;
/// one black 1-texel cube when there are none (the binding must hold a view).
fn reflection_cubes(gpu: &Gpu, up: &mut Uploader, pack: &Pack) -> Result<Image> {
    let half = vk::Format::R16G16B16A16_SFLOAT;
    let texels = |size: u32| move |k: u32| ((size >> k).max(1) as usize).pow(2) * 8;
    match pack.manifest.reflection_probes.as_ref().filter(|r| !r.probes.is_empty()) {
        Some(r) if r.format.is_compressed() && !native_bc(gpu, r.format) => {
            // Decoded like the material textures (a CPU device, or no BC6H): every face of
            // every level of every probe in parallel, into the half-float layout.
            use rayon::prelude::*;
            let decoded: Vec<Vec<u8>> = r
                .probes
                .par_iter()
                .map(|p| decode_cube(r, pack.bytes(p.data)).with_context(|| format!("reflection probe '{}': blocks do not decode", p.name)))
                .collect::<Result<_>>()?;
            let cubes: Vec<&[u8]> = decoded.iter().map(|c| c.as_slice()).collect();
            Image::sampled_cubes(gpu, up, "reflection probes", half, r.face_size, r.levels, texels(r.face_size), &cubes)
                .with_context(|| format!("uploading {} reflection probes of {} texels a face", cubes.len(), r.face_size))
        }
        Some(r) => {
            let cubes: Vec<&[u8]> = r.probes.iter().map(|p| pack.bytes(p.data)).collect();
            Image::sampled_cubes(gpu, up, "reflection probes", vk_format(r.format), r.face_size, r.levels, |k| r.face_bytes(k) as usize, &cubes)
                .with_context(|| format!("uploading {} reflection probes of {} texels a face", cubes.len(), r.face_size))
        }
        None => Image::sampled_cubes(gpu, up, "no reflection probes", half, 1, 1, texels(1), &[&[0u8; 6 * 8]]),
    }
}

/// One probe's BC6H cube (`data`) as half-float RGBA in the same [level][face] order.
fn decode_cube(r: &pack::ReflectionProbes, data: &[u8]) -> Option<Vec<u8>> {
    let mut out = Vec::new();
    let mut at = 0usize;
    for k in 0..r.levels {
        let s = (r.face_size >> k).max(1);
        let n = r.face_bytes(k) as usize;
        for _ in 0..6 {
            out.extend(pack::bc::decode(r.format, s, s, data.get(at..at + n)?)?);
            at += n;
        }
    }
    Some(out)
}

/// The reflection probes as the shaders walk them (std430, `ReflectionProbes` in
/// mesh_shading.glsl): (count, levels, 0, 0), then per probe three vec4s, the box's min with
/// the blend distance, its max with the probe's layer in the cube array, the capture point.
/// Smaller boxes come first: a room's probe stays on top of the courtyard's that contains it,
/// each taking its weight of what the ones before left (shading.md §3.6).
fn reflection_probe_bytes(pack: &Pack) -> Vec<u8> {
    let r = pack.manifest.reflection_probes.as_ref();
    let probes: &[pack::ReflectionProbe] = r.map_or(&[], |r| &r.probes);
    let volume = |p: &pack::ReflectionProbe| (0..3).map(|i| p.box_max[i] - p.box_min[i]).product::<f32>();
    let mut order: Vec<usize> = (0..probes.len()).collect();
    order.sort_by(|&a, &b| volume(&probes[a]).total_cmp(&volume(&probes[b])));
    let mut floats = vec![f32::from_bits(probes.len() as u32), f32::from_bits(r.map_or(1, |r| r.levels)), 0.0, 0.0];
    for i in order {
        let p = &probes[i];
        floats.extend([p.box_min[0], p.box_min[1], p.box_min[2], p.blend_distance]);
        floats.extend([p.box_max[0], p.box_max[1], p.box_max[2], i as f32]);
        floats.extend([p.position[0], p.position[1], p.position[2], 0.0]);
    }
    if probes.is_empty() {
        floats.extend([0.0; 12]);
    }
    bytemuck::cast_slice(&floats).to_vec()
}

/// Sun and exposure for a baked pack: exposure k / L (`pack::exposure`), L as the cooker
/// stored it (`LightmapLayout::log_average`, from the pages as baked), or for a pack without it
/// computed here from the texels as the device got them, decoding a page the device samples
/// block-compressed.
fn baked_lighting(pack: &Pack, texels: &[Texels]) -> Result<BakedLighting> {
    let m = &pack.manifest;
    let (sun_dir, sun_lux, sun_angular_radius) = match m.lights.iter().find(|l| l.kind == pack::LightKind::Sun) {
        Some(sun) => ((-Vec3::from(sun.direction)).normalize_or_zero(), Vec3::from(sun.color) * sun.intensity, sun.angular_radius),
        None => (Vec3::Y, Vec3::ZERO, 0.0),
    };
    let log_average = match m.lightmap.as_ref().and_then(|l| l.log_average) {
        Some(l) => l,
        None => {
            // Level 0 of texture t in its plain layout (RGBA16F pages, RGBA8 directions).
            let plain = |t: u32| -> Result<std::borrow::Cow<[u8]>> {
                let tex = &m.textures[t as usize];
                let (format, mips) = &texels[t as usize];
                Ok(if tex.format.is_compressed() && *format == vk_format(tex.format) {
                    std::borrow::Cow::Owned(pack::bc::decode(tex.format, tex.width, tex.height, &mips[0]).with_context(|| format!("texture '{}': blocks do not decode", tex.name))?)
                } else {
                    std::borrow::Cow::Borrowed(mips[0].as_ref())
                })
            };
            let sun = pack::exposure::Sun { toward: sun_dir.into(), lux: sun_lux.into() };
            let (pages, directions) = m.lightmap.as_ref().map_or((&[][..], &[][..]), |l| (&l.textures[..], &l.directions[..]));
            let mut sum = pack::exposure::LogAverage::default();
            for (p, &t) in pages.iter().enumerate() {
                let direction = directions.get(p).map(|&d| plain(d)).transpose()?;
                sum.add_page(&plain(t)?, direction.as_deref(), Some(sun));
            }
            sum.value()
        }
    };
    let sky = m.sky.map_or(Vec3::ZERO, |s| Vec3::from(s.color) * s.intensity);
    Ok(BakedLighting { sun_dir, sun_lux, sun_angular_radius, sky, exposure: pack::exposure::KEY / log_average })
}

/// Mesh `mesh`'s full detail as a flock mesh (see `scene::FlockMesh`).
fn flock_mesh(gpu: &Gpu, up: &mut Uploader, pack: &Pack, mesh: u32) -> Result<FlockMesh> {
    let m = &pack.manifest;
    let lod = &m.meshes[mesh as usize].lods[0];
    let vertices = pack::decode_vertices(pack.bytes(lod.vertices), &lod.uv_ranges);
    let indices = pack.indices(lod);
    let mut corners: Vec<[f32; 6]> = Vec::with_capacity(indices.len());
    let mut parts = Vec::new();
    for sub in &lod.submeshes {
        let first = corners.len() as u32;
        for &i in &indices[sub.first_index as usize..(sub.first_index + sub.index_count) as usize] {
            let v = &vertices[i as usize];
            corners.push([v.position[0], v.position[1], v.position[2], v.normal[0], v.normal[1], v.normal[2]]);
        }
        parts.push((first, sub.index_count, m.materials[sub.material as usize].base_color));
    }
    let radius = vertices.iter().map(|v| Vec3::from(v.position).length()).fold(0.0, f32::max);
    let name = format!("flock mesh '{}'", m.meshes[mesh as usize].name);
    let vertices = up.buffer(gpu, &name, &[bytemuck::cast_slice(&corners)], vk::BufferUsageFlags::VERTEX_BUFFER)?;
    Ok(FlockMesh { vertices, parts, radius })
}
