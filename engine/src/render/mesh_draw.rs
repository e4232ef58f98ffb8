//! What the mesh passes (shadow, pre-pass, shading) share: the descriptor set layouts, one
//! pipeline layout, the pipelines (all with mesh.vert), and the draw loop over batches.

use crate::render::batches::{instance_attributes, Batch, INSTANCE_STRIDE};
use crate::gpu::{opaque, premultiplied_over, Gpu, GraphicsPipeline, PerSamples};
use crate::render::graph::{Rec, Rendering};
use crate::scene::{GpuMaterial, GpuScene, TextureSlots};
use std::collections::HashMap;
use crate::render::shaders;
use crate::render::shadow::{DEPTH_BIAS_CONSTANT, DEPTH_BIAS_SLOPE};
use crate::render::tonemap::HDR_FORMAT;
use anyhow::Result;
use ash::vk;
use bytemuck::{Pod, Zeroable};
use glam::Vec4;

/// Mirrors the push-constant block of shaders/mesh_draw.glsl: what a submesh gives its
/// vertices and fragments (the transforms and lightmap regions are per instance, in the
/// instance stream).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
struct DrawPush {
    /// x: alpha-test cutoff (or -1); y: material index (its constants); z: the submesh's
    /// lightmap block (added to the instance's page).
    material: Vec4,
    base_color: Vec4,
    /// The LOD's texture-coordinate ranges (uv0, uv1, texcoord1: `pack::UvRanges`).
    uv_ranges: [Vec4; 3],
}
const _: () = assert!(std::mem::size_of::<DrawPush>() == 80);

/// The stages that read the mesh passes' push constants and material constants: the vertex
/// shader transforms the texture coordinates and picks the lightmap layer.
const MESH_STAGES: vk::ShaderStageFlags = vk::ShaderStageFlags::from_raw(vk::ShaderStageFlags::VERTEX.as_raw() | vk::ShaderStageFlags::FRAGMENT.as_raw());

/// Reversed-Z: nearer is greater.
const NEARER: vk::CompareOp = vk::CompareOp::GREATER_OR_EQUAL;

/// The lit phases' pipelines (shading and transparent), one per key: what mesh_shading.glsl is
/// specialised for. `MeshKit::prepare_lit` makes those a frame's materials need.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct LitKey {
    pub phase: LitPhase,
    /// LIGHTMAPPED: lit by the instance's lightmap region, not by the probes and the sun.
    pub lightmapped: bool,
    /// DIRECTIONAL: the lightmap is directional (b0 and a direction, the sun lit here).
    pub directional: bool,
    /// BICUBIC: the lightmap is read through a cubic B-spline.
    pub bicubic: bool,
    /// REFLECTIONS: the environment comes from the scene's reflection probes.
    pub reflections: bool,
    /// COUNT_FRAGMENTS: each shaded fragment adds one to the frame's counter.
    pub counting: bool,
    /// SLOTS: the material's texture slots (less those the renderer's switches leave out).
    pub slots: TextureSlots,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LitPhase {
    /// The shading pass without a pre-pass: depth test and write, alpha test in the shader.
    Plain,
    /// The shading pass after the pre-pass: depth EQUAL, no writes, early fragment tests.
    Equal,
    /// The transparent phase: premultiplied over, depth tested against the opaque depth, not
    /// written.
    Blend,
}

/// Specialisation constants of the mesh fragment shaders (mesh_shading.glsl): a lit key's
/// (its phase aside, which picks the shader and fixed state) and SAMPLES, the target's samples
/// per pixel; above 1 alpha-tested (MASK) fragments cover as many samples as their alpha says
/// instead of discarding (alpha to coverage). Depth-only pipelines take `Variant::default()`.
#[derive(Debug, Clone, Copy)]
struct Variant {
    key: LitKey,
    samples: u32,
}

impl Default for Variant {
    fn default() -> Self {
        let key = LitKey { phase: LitPhase::Plain, lightmapped: false, directional: false, bicubic: false, reflections: false, counting: false, slots: TextureSlots::ALL };
        Variant { key, samples: 1 }
    }
}

/// The pipelines drawing into the camera's targets, for one sample count.
pub struct CameraPipelines {
    /// Pre-pass: depth only, no fragment shader; and with the alpha test (a discard, or
    /// alpha-to-coverage when multisampled).
    pub depth: vk::Pipeline,
    pub depth_masked: vk::Pipeline,
    /// The shading and transparent phases' pipelines made so far.
    lit: HashMap<LitKey, vk::Pipeline>,
}

impl CameraPipelines {
    fn all(&self) -> impl Iterator<Item = vk::Pipeline> + '_ {
        [self.depth, self.depth_masked].into_iter().chain(self.lit.values().copied())
    }
}

/// Layouts and pipelines of the mesh passes.
pub struct MeshKit {
    pub frame_layout: vk::DescriptorSetLayout,
    pub material_layout: vk::DescriptorSetLayout,
    pub scene_layout: vk::DescriptorSetLayout,
    pub pipeline_layout: vk::PipelineLayout,
    /// The camera's pipelines per sample count (`prepare_samples`, `prepare_lit`).
    camera: PerSamples<CameraPipelines>,
    /// The device lets fragment shaders write buffers: the shading pass can count fragments.
    can_count: bool,
    /// The shadow pass: depth only, and with the alpha-test discard, into the shadow map's
    /// format, standard depth (0 nearest the sun), no culling, with depth bias.
    pub shadow: vk::Pipeline,
    pub shadow_masked: vk::Pipeline,
}

impl MeshKit {
    pub fn new(gpu: &Gpu, shadow_format: vk::Format) -> Result<MeshKit> {
        let d = &gpu.device;
        let binding = |binding: u32, ty, stages| vk::DescriptorSetLayoutBinding::default().binding(binding).descriptor_type(ty).descriptor_count(1).stage_flags(stages);
        let (ubo, storage, sampled) = (vk::DescriptorType::UNIFORM_BUFFER, vk::DescriptorType::STORAGE_BUFFER, vk::DescriptorType::COMBINED_IMAGE_SAMPLER);
        let frag = vk::ShaderStageFlags::FRAGMENT;
        // Set 0: the frame's uniforms, the fragment counter and the sun's shadow map.
        let frame_binding = [binding(0, ubo, MESH_STAGES), binding(1, storage, frag), binding(2, sampled, frag)];
        // Set 1: the material's textures: base colour (0), emissive (1), normal (2),
        // metallic-roughness (3), occlusion (4).
        let material_binding = [0, 1, 2, 3, 4].map(|b| binding(b, sampled, frag));
        // Set 2: the lightmap array, the probes, the material constants (their UV transforms
        // are applied per vertex), the specular (A, B) table, the lightmaps' directions, the
        // reflection probes' cube array and the probes' boxes.
        let scene_bindings = [
            binding(0, sampled, frag),
            binding(1, storage, frag),
            binding(2, storage, MESH_STAGES),
            binding(3, sampled, frag),
            binding(4, sampled, frag),
            binding(5, sampled, frag),
            binding(6, storage, frag),
        ];
        let layout = |b: &[vk::DescriptorSetLayoutBinding]| unsafe { d.create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(b), None) };
        // Everything is owned until the kit is whole: an error frees what was made before it.
        let frame_layout = gpu.own(layout(&frame_binding)?);
        let material_layout = gpu.own(layout(&material_binding)?);
        let scene_layout = gpu.own(layout(&scene_bindings)?);
        let set_layouts = [*frame_layout, *material_layout, *scene_layout];
        let push = [vk::PushConstantRange::default().stage_flags(MESH_STAGES).size(std::mem::size_of::<DrawPush>() as u32)];
        let pipeline_layout = gpu.own(unsafe { d.create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts).push_constant_ranges(&push), None)? });
        let pl = *pipeline_layout;
        let bias = Some((DEPTH_BIAS_CONSTANT, DEPTH_BIAS_SLOPE));
        let one = vk::SampleCountFlags::TYPE_1;
        let shadow = gpu.own(create_mesh_pipeline(gpu, pl, None, shadow_format, None, true, vk::CompareOp::LESS_OR_EQUAL, Variant::default(), bias, one)?);
        let shadow_masked = create_mesh_pipeline(gpu, pl, None, shadow_format, Some(shaders::DEPTH_MASKED_FRAG.spv()), true, vk::CompareOp::LESS_OR_EQUAL, Variant::default(), bias, one)?;
        let mut kit = gpu.own(MeshKit {
            frame_layout: frame_layout.keep(),
            material_layout: material_layout.keep(),
            scene_layout: scene_layout.keep(),
            pipeline_layout: pipeline_layout.keep(),
            camera: PerSamples::default(),
            can_count: gpu.caps.fragment_atomics,
            shadow: shadow.keep(),
            shadow_masked,
        });
        kit.prepare_samples(gpu, one)?;
        Ok(kit.keep())
    }

    /// Make every pipeline again from the shaders as they are now (`shaders::reload`), keeping
    /// the layouts the frame's and the scene's descriptor sets were made for; the camera's lit
    /// pipelines come back as frames ask for them (`prepare_lit`).
    pub fn reload_pipelines(&mut self, gpu: &Gpu, shadow_format: vk::Format) -> Result<()> {
        let pl = self.pipeline_layout;
        let bias = Some((DEPTH_BIAS_CONSTANT, DEPTH_BIAS_SLOPE));
        let one = vk::SampleCountFlags::TYPE_1;
        let shadow = gpu.own(create_mesh_pipeline(gpu, pl, None, shadow_format, None, true, vk::CompareOp::LESS_OR_EQUAL, Variant::default(), bias, one)?);
        let shadow_masked = create_mesh_pipeline(gpu, pl, None, shadow_format, Some(shaders::DEPTH_MASKED_FRAG.spv()), true, vk::CompareOp::LESS_OR_EQUAL, Variant::default(), bias, one)?;
        let d = &gpu.device;
        unsafe {
            for set in self.camera.drain() {
                for pipeline in set.all() {
                    d.destroy_pipeline(pipeline, None);
                }
            }
            d.destroy_pipeline(self.shadow, None);
            d.destroy_pipeline(self.shadow_masked, None);
        }
        (self.shadow, self.shadow_masked) = (shadow.keep(), shadow_masked);
        self.prepare_samples(gpu, one)
    }

    /// Make the camera's depth pipelines for `samples` if no frame has used them yet.
    pub fn prepare_samples(&mut self, gpu: &Gpu, samples: vk::SampleCountFlags) -> Result<()> {
        let pl = self.pipeline_layout;
        self.camera.ensure(samples, |samples| depth_pipelines(gpu, pl, samples))?;
        Ok(())
    }

    /// Make the lit pipelines of `keys` for targets of `samples` samples that are not made yet
    /// (after `prepare_samples`). The renderer asks for every key its scene's materials can draw
    /// with under its settings, so a material coming into view never waits for a compile.
    pub fn prepare_lit(&mut self, gpu: &Gpu, samples: vk::SampleCountFlags, keys: impl IntoIterator<Item = LitKey>) -> Result<()> {
        let pl = self.pipeline_layout;
        let set = self.camera.ensure(samples, |samples| depth_pipelines(gpu, pl, samples))?;
        for key in keys {
            if !set.lit.contains_key(&key) {
                let p = lit_pipeline(gpu, pl, samples, key)?;
                set.lit.insert(key, p);
            }
        }
        Ok(())
    }

    /// The camera's pipelines for `samples` (made by `prepare_samples`).
    pub fn camera(&self, samples: vk::SampleCountFlags) -> &CameraPipelines {
        self.camera.get(samples)
    }

    /// The lit pipeline of `key` for `samples` samples (`prepare_lit` made it).
    pub fn lit(&self, samples: vk::SampleCountFlags, key: LitKey) -> vk::Pipeline {
        *self.camera(samples).lit.get(&key).unwrap_or_else(|| panic!("no pipeline was made for {key:?} at {samples:?} samples"))
    }

    /// Whether the device can count the shading pass's fragments.
    pub fn can_count(&self) -> bool {
        self.can_count
    }

    /// The depth-only pipeline for a material: with the alpha test when it is masked; none for
    /// a BLEND material (it writes no depth and casts no shadow). `samples`: the camera's
    /// (the pre-pass); None: the shadow map.
    pub fn depth_for(&self, mat: &GpuMaterial, samples: Option<vk::SampleCountFlags>) -> Option<vk::Pipeline> {
        if mat.blend {
            return None;
        }
        let masked = mat.alpha_cutoff >= 0.0;
        Some(match samples {
            Some(s) => {
                let c = self.camera(s);
                if masked { c.depth_masked } else { c.depth }
            }
            None => if masked { self.shadow_masked } else { self.shadow },
        })
    }

    /// Whether `pipeline` samples the material's textures (set 1): the depth-only pipelines
    /// without the alpha test do not, and their draws bind no material.
    fn reads_material(&self, pipeline: vk::Pipeline) -> bool {
        pipeline != self.shadow && !self.camera.iter().any(|c| c.depth == pipeline)
    }

    /// One rendering instance drawing `setup.batches`, each submesh with the pipeline
    /// `pipeline_for(material, lightmapped)` gives. Returns the draw calls it made.
    ///
    /// With `setup.by_state` the submeshes are drawn grouped by pipeline and material (in list
    /// order within a group), and each state is recorded only when it changes. On lavapipe a
    /// material bind costs a whole flush and wait: it re-sends every sampler view of the stage,
    /// the sun's shadow map among them, and llvmpipe finishes all rendering before it samples
    /// an image that any of its scenes since the shadow pass still holds as a target (measured:
    /// binding materials once a pass instead of at every change took the flythrough's frame
    /// from 38.9 to 32.4 ms at scale 0.5).
    pub fn draw(&self, rec: &Rec, scene: &GpuScene, rendering: &Rendering, setup: &DrawSetup, pipeline_for: impl Fn(&GpuMaterial, bool) -> Option<vk::Pipeline>) -> u32 {
        struct Item {
            pipeline: vk::Pipeline,
            material: u32,
            batch: u32,
            submesh: u32,
            /// The group's rank: its pipeline's and then its material's first appearance in
            /// the list (not the handles' values, which change from run to run: coplanar
            /// surfaces drawn in another order would give another image).
            rank: (u32, u32),
        }
        let mut items = Vec::new();
        let mut pipelines: Vec<vk::Pipeline> = Vec::new();
        let mut materials: Vec<u32> = Vec::new();
        fn first_seen<T: PartialEq + Copy>(seen: &mut Vec<T>, x: T) -> u32 {
            let i = seen.iter().position(|&s| s == x).unwrap_or_else(|| {
                seen.push(x);
                seen.len() - 1
            });
            i as u32
        }
        let mut rank = |pipeline: vk::Pipeline, material: u32| {
            (first_seen(&mut pipelines, pipeline), if self.reads_material(pipeline) { first_seen(&mut materials, material) } else { 0 })
        };
        for (b, batch) in setup.batches.iter().enumerate() {
            let mesh = &scene.meshes[scene.instances[batch.instance as usize].mesh as usize];
            for (i, sm) in mesh.lods[batch.lod as usize].submeshes.iter().enumerate() {
                let material = batch.material.unwrap_or(sm.material);
                // Instances with a lightmap region read it where the submesh has a block; the
                // rest the probes and the sun. None: the submesh is not this pass's (a BLEND
                // material in an opaque pass).
                if let Some(pipeline) = pipeline_for(&scene.materials[material as usize], batch.lightmapped && sm.lightmap_block.is_some()) {
                    let rank = if setup.by_state { rank(pipeline, material) } else { (0, 0) };
                    items.push(Item { pipeline, material, batch: b as u32, submesh: i as u32, rank });
                }
            }
        }
        // Stable: list order within a group.
        items.sort_by_key(|it| it.rank);
        let (d, cb) = (&rec.gpu.device, rec.cb);
        rec.begin_rendering(rendering);
        unsafe {
            d.cmd_set_depth_test_enable(cb, setup.depth_test);
            d.cmd_bind_descriptor_sets(cb, vk::PipelineBindPoint::GRAPHICS, self.pipeline_layout, 0, &[setup.frame_set], &[]);
            d.cmd_bind_descriptor_sets(cb, vk::PipelineBindPoint::GRAPHICS, self.pipeline_layout, 2, &[scene.scene_set], &[]);
            d.cmd_bind_vertex_buffers(cb, 0, &[scene.vertex_buffer.buffer, setup.instances], &[0, 0]);
            let mut bound_index_type = None;
            let mut bound = vk::Pipeline::null();
            let mut bound_vertices = scene.vertex_buffer.buffer;
            let mut bound_front = None;
            let mut bound_cull = None;
            let mut bound_push = None;
            let mut bound_material = vk::DescriptorSet::null();
            for it in &items {
                let batch = &setup.batches[it.batch as usize];
                let mesh = &scene.meshes[scene.instances[batch.instance as usize].mesh as usize];
                let lod = &mesh.lods[batch.lod as usize];
                let sm = &lod.submeshes[it.submesh as usize];
                let mat = &scene.materials[it.material as usize];
                // An animated instance draws its skinned vertices: already in world space, from
                // vertex 0 of its own buffer; every pass reads the same buffer, so the pre-pass
                // and the EQUAL shading pass see identical positions.
                if batch.vertices != bound_vertices {
                    d.cmd_bind_vertex_buffers(cb, 0, &[batch.vertices], &[0]);
                    bound_vertices = batch.vertices;
                }
                if bound_front != Some(batch.front) {
                    d.cmd_set_front_face(cb, batch.front);
                    bound_front = Some(batch.front);
                }
                if bound_index_type != Some(lod.index_type) {
                    let offset = if lod.index_type == vk::IndexType::UINT16 { scene.index_offset_16 } else { 0 };
                    d.cmd_bind_index_buffer(cb, scene.index_buffer.buffer, offset, lod.index_type);
                    bound_index_type = Some(lod.index_type);
                }
                if it.pipeline != bound {
                    d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, it.pipeline);
                    bound = it.pipeline;
                }
                let push = DrawPush {
                    material: Vec4::new(mat.alpha_cutoff, it.material as f32, sm.lightmap_block.unwrap_or(0) as f32, 0.0),
                    base_color: Vec4::from(mat.base_color),
                    uv_ranges: lod.uv_ranges.all().map(Vec4::from),
                };
                if bound_push != Some(push) {
                    d.cmd_push_constants(cb, self.pipeline_layout, MESH_STAGES, 0, bytemuck::bytes_of(&push));
                    bound_push = Some(push);
                }
                let cull = if setup.cull && !mat.double_sided { vk::CullModeFlags::BACK } else { vk::CullModeFlags::NONE };
                if bound_cull != Some(cull) {
                    d.cmd_set_cull_mode(cb, cull);
                    bound_cull = Some(cull);
                }
                if bound_material != mat.descriptor_set && self.reads_material(it.pipeline) {
                    d.cmd_bind_descriptor_sets(cb, vk::PipelineBindPoint::GRAPHICS, self.pipeline_layout, 1, &[mat.descriptor_set], &[]);
                    bound_material = mat.descriptor_set;
                }
                d.cmd_draw_indexed(cb, sm.index_count, batch.count, lod.first_index + sm.first_index, batch.base_vertex, batch.first_instance);
            }
        }
        rec.end_rendering();
        items.len() as u32
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        let d = &gpu.device;
        unsafe {
            for set in self.camera.drain() {
                for pipeline in set.all() {
                    d.destroy_pipeline(pipeline, None);
                }
            }
            for pipeline in [self.shadow, self.shadow_masked] {
                d.destroy_pipeline(pipeline, None);
            }
            d.destroy_pipeline_layout(self.pipeline_layout, None);
            for l in [self.frame_layout, self.material_layout, self.scene_layout] {
                d.destroy_descriptor_set_layout(l, None);
            }
        }
    }
}

/// What one mesh pass draws and how: the set 0 it binds (the camera's or the sun's uniforms),
/// the draw list, depth testing, and back-face culling (off for shadow casters: a single-sided
/// occluder blocks the sun whichever side faces it).
pub struct DrawSetup<'a> {
    pub frame_set: vk::DescriptorSet,
    pub batches: &'a [Batch],
    /// The frame slot's instance stream the batches index.
    pub instances: vk::Buffer,
    pub depth_test: bool,
    pub cull: bool,
    /// Draw grouped by pipeline and material (`MeshKit::draw`); off where the list's order is
    /// the drawing's (the transparent phase's back to front).
    pub by_state: bool,
}

fn attribute_format(f: pack::AttributeFormat) -> vk::Format {
    match f {
        pack::AttributeFormat::F32x3 => vk::Format::R32G32B32_SFLOAT,
        pack::AttributeFormat::Snorm16x2 => vk::Format::R16G16_SNORM,
        pack::AttributeFormat::Sint16x2 => vk::Format::R16G16_SINT,
        pack::AttributeFormat::Unorm16x2 => vk::Format::R16G16_UNORM,
        pack::AttributeFormat::Unorm8x4 => vk::Format::R8G8B8A8_UNORM,
    }
}

/// The camera's depth pipelines for targets of `samples` samples (the lit ones come with
/// `MeshKit::prepare_lit`). Multisampled, the masked pre-pass turns a MASK material's alpha
/// into coverage (its SAMPLES constant).
fn depth_pipelines(gpu: &Gpu, pl: vk::PipelineLayout, samples: vk::SampleCountFlags) -> Result<CameraPipelines> {
    let depth_format = gpu.caps.depth_format;
    let depth = gpu.own(create_mesh_pipeline(gpu, pl, None, depth_format, None, true, NEARER, Variant::default(), None, samples)?);
    let masked = Variant { samples: samples.as_raw(), ..Variant::default() };
    let depth_masked = create_mesh_pipeline(gpu, pl, None, depth_format, Some(shaders::DEPTH_MASKED_FRAG.spv()), true, NEARER, masked, None, samples)?;
    Ok(CameraPipelines { depth: depth.keep(), depth_masked, lit: HashMap::new() })
}

/// The lit pipeline of `key` into the camera's targets of `samples` samples. Without a
/// pre-pass, multisampled, the shading turns a MASK material's alpha into coverage (SAMPLES);
/// after a pre-pass the EQUAL test already keeps the samples the pre-pass covered.
fn lit_pipeline(gpu: &Gpu, pl: vk::PipelineLayout, samples: vk::SampleCountFlags, key: LitKey) -> Result<vk::Pipeline> {
    let depth_format = gpu.caps.depth_format;
    let variant = Variant { key, samples: 1 };
    match key.phase {
        LitPhase::Plain => {
            let variant = Variant { samples: samples.as_raw(), ..variant };
            let frag = if key.counting { shaders::MESH_COUNTED_FRAG.spv() } else { shaders::MESH_FRAG.spv() };
            create_mesh_pipeline(gpu, pl, Some((HDR_FORMAT, opaque())), depth_format, Some(frag), true, NEARER, variant, None, samples)
        }
        LitPhase::Equal => {
            let frag = if key.counting { shaders::MESH_EQUAL_COUNTED_FRAG.spv() } else { shaders::MESH_EQUAL_FRAG.spv() };
            create_mesh_pipeline(gpu, pl, Some((HDR_FORMAT, opaque())), depth_format, Some(frag), false, vk::CompareOp::EQUAL, variant, None, samples)
        }
        LitPhase::Blend => create_mesh_pipeline(gpu, pl, Some((HDR_FORMAT, premultiplied_over())), depth_format, Some(shaders::MESH_BLEND_FRAG.spv()), false, NEARER, variant, None, samples),
    }
}

/// A mesh pipeline: `mesh.vert` plus `frag` (None: depth only), rendering into `color_format`
/// (None: no colour attachment) and `depth_format` with the given depth write and compare, and
/// a rasteriser depth bias (constant, slope factor) when given, into attachments of `samples`
/// samples; `variant` specialises the fragment shader (and alpha-to-coverage turns on with it).
#[allow(clippy::too_many_arguments)]
fn create_mesh_pipeline(
    gpu: &Gpu,
    layout: vk::PipelineLayout,
    color: Option<(vk::Format, vk::PipelineColorBlendAttachmentState)>,
    depth_format: vk::Format,
    frag: Option<&[u8]>,
    depth_write: bool,
    compare: vk::CompareOp,
    variant: Variant,
    depth_bias: Option<(f32, f32)>,
    samples: vk::SampleCountFlags,
) -> Result<vk::Pipeline> {
    // Specialisation constants 1 to 6: LIGHTMAPPED, SAMPLES, SLOTS, DIRECTIONAL, BICUBIC and
    // REFLECTIONS (mesh_shading.glsl). Counting is a module of its own (`lit_pipeline`).
    let k = &variant.key;
    let values = [
        vk::Bool32::from(k.lightmapped),
        variant.samples.max(1),
        k.slots.0,
        vk::Bool32::from(k.directional),
        vk::Bool32::from(k.bicubic),
        vk::Bool32::from(k.reflections),
    ]
    .map(u32::to_le_bytes);
    let bytes = values.concat();
    let entries: [vk::SpecializationMapEntry; 6] = std::array::from_fn(|i| vk::SpecializationMapEntry { constant_id: i as u32 + 1, offset: 4 * i as u32, size: 4 });
    let spec = vk::SpecializationInfo::default().map_entries(&entries).data(&bytes);
    // Without a fragment shader only the position is needed: lavapipe would otherwise compute
    // every output of the vertex shader for nothing (mesh.vert's DEPTH_ONLY module).
    let depth_only = frag.is_none();
    let vert = if depth_only { shaders::MESH_DEPTH_VERT.spv() } else { shaders::MESH_VERT.spv() };
    // The vertex layout comes from the pack crate: one definition of the format. Only the
    // attributes the shader reads are declared: the position and the model matrix (instance
    // locations 6 to 9) for the depth-only module.
    const MESH_SHADER_INPUTS: [u32; 7] = [0, 1, 2, 3, 4, 5, 13];
    let reads = |location: u32| if depth_only { location == 0 || (6..=9).contains(&location) } else { true };
    // Binding 1: the instance stream (batches.rs).
    let bindings = [
        vk::VertexInputBindingDescription { binding: 0, stride: pack::VERTEX_STRIDE as u32, input_rate: vk::VertexInputRate::VERTEX },
        vk::VertexInputBindingDescription { binding: 1, stride: INSTANCE_STRIDE, input_rate: vk::VertexInputRate::INSTANCE },
    ];
    let attributes: Vec<_> = pack::VERTEX_ATTRIBUTES
        .iter()
        .filter(|a| MESH_SHADER_INPUTS.contains(&a.0))
        .map(|&(location, offset, f)| vk::VertexInputAttributeDescription { location, binding: 0, format: attribute_format(f), offset })
        .chain(instance_attributes())
        .filter(|a| reads(a.location))
        .collect();
    // Cull mode, front face and depth testing are dynamic (core 1.3): double-sided materials,
    // mirrored instances and the raw fragment count (`depth_test` off) change them per draw or
    // pass without a second pipeline.
    let dynamic = [vk::DynamicState::CULL_MODE, vk::DynamicState::FRONT_FACE, vk::DynamicState::DEPTH_TEST_ENABLE];
    let mut pipeline = GraphicsPipeline::new("mesh", vert)
        .vertex_input(&bindings, &attributes)
        .cull_back()
        .depth_bias(depth_bias)
        .depth(depth_format, depth_write, compare)
        .multisample(samples)
        .dynamic(&dynamic);
    if let Some(f) = frag {
        pipeline = pipeline.fragment(f, Some(spec));
    }
    if let Some((format, blend)) = color {
        pipeline = pipeline.color(format, blend);
    }
    pipeline.build(gpu, layout)
}
