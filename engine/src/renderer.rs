//! The forward renderer (dynamic rendering, reversed-Z depth): per frame the sun's shadow map
//! (`shadow`), a depth pre-pass, the shading pass into an HDR target, and the tone map into any
//! colour + depth attachment pair (`tonemap`). Used by the headless target and the window.

use crate::animated::AnimatedScene;
use crate::camera::Camera;
use crate::batches::{instance_attributes, Batch, BatchMode, Batcher, INSTANCE_STRIDE};
use crate::gpu::{barrier, full_range, opaque, Buffer, Gpu, GraphicsPipeline, SlotBuffers, Transition};
use crate::boids_draw::BoidsDraw;
use crate::particles_pass::ParticlePass;
use crate::scene::{GpuMaterial, GpuScene, SceneLayouts};
use crate::shaders;
use crate::shadow::{SunShadow, DEFAULT_SHADOW_MAP_SIZE, DEPTH_BIAS_CONSTANT, DEPTH_BIAS_SLOPE};
use crate::tonemap::{ToneMap, HDR_FORMAT};
use crate::visibility::Visibility;
use anyhow::Result;
use ash::vk;
use glam::{Mat4, Vec3, Vec4};
use gpu_allocator::MemoryLocation;

/// Mirrors `Frame` in shaders/frame.glsl (std140).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct FrameUniforms {
    pub view_proj: Mat4,
    /// World -> the sun's shadow map (`shadow::sun_view_proj`).
    pub sun_view_proj: Mat4,
    pub camera_pos: Vec4,
    pub sun_dir: Vec4,
    pub sun_color: Vec4,
    pub ambient: Vec4,
    /// x: exposure; y: 1 when lighting is physical (baked lightmaps, probes, sun in lux) and
    /// tone-mapped, 0 for the stand-in lighting (already display-referred). Read by the
    /// tone-map pass; the shading pass only tells the two lighting paths apart by y.
    pub exposure: Vec4,
    /// x: 1 when this frame drew the shadow map (dynamic objects read it; otherwise the probes'
    /// sun visibility); y: one map texel in metres; z: 1 / map size in texels.
    pub shadow: Vec4,
}

/// Mirrors the push-constant block of shaders/mesh_draw.glsl: what a submesh gives its
/// vertices and fragments (the transforms and lightmap regions are per instance, in the
/// instance stream).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
struct DrawPush {
    /// x: alpha-test cutoff (or -1); y: material index (its constants); z: the submesh's
    /// lightmap block (added to the instance's page).
    material: Vec4,
    base_color: Vec4,
}
const _: () = assert!(std::mem::size_of::<DrawPush>() == 32);

/// Lighting that stands in until lightmaps and probes land.
#[derive(Debug, Clone, Copy)]
pub struct Lighting {
    pub sun_dir: Vec3,
    pub sun_color: Vec3,
    pub ambient: Vec3,
}

impl Default for Lighting {
    fn default() -> Self {
        Lighting { sun_dir: Vec3::new(0.35, 0.8, 0.45).normalize(), sun_color: Vec3::splat(0.85), ambient: Vec3::splat(0.22) }
    }
}

impl Lighting {
    /// The stand-in lighting for a pack: its first sun's direction and tint when it has one.
    pub fn for_pack(manifest: &pack::Manifest) -> Lighting {
        let mut l = Lighting::default();
        if let Some(sun) = manifest.lights.iter().find(|l| l.kind == pack::LightKind::Sun) {
            let towards_sun = -Vec3::from(sun.direction);
            if towards_sun.length_squared() > 0.0 {
                l.sun_dir = towards_sun.normalize();
            }
            let tint = Vec3::from(sun.color);
            l.sun_color = tint / tint.max_element().max(1e-6) * l.sun_color.x;
        }
        l
    }
}

pub const CLEAR_COLOR: [f32; 4] = [0.32, 0.42, 0.55, 1.0];

/// The attachments one frame renders into: the display colour image (an `_SRGB` format: the
/// tone-map pass writes linear values and the hardware encodes them) and the depth buffer.
pub struct FrameTarget {
    pub color_image: vk::Image,
    pub color_view: vk::ImageView,
    pub depth_image: vk::Image,
    pub depth_view: vk::ImageView,
    pub extent: vk::Extent2D,
}

pub struct Renderer {
    /// The display target's format (what the tone-map pass writes); shading renders to `HDR_FORMAT`.
    pub color_format: vk::Format,
    pub depth_format: vk::Format,
    pub material_layout: vk::DescriptorSetLayout,
    pub scene_layout: vk::DescriptorSetLayout,
    frame_layout: vk::DescriptorSetLayout,
    pipeline_layout: vk::PipelineLayout,
    pipelines: Pipelines,
    pool: vk::DescriptorPool,
    /// Pipeline statistics (vertex and fragment shader invocations) of the pre-pass and the
    /// shading pass, two queries per frame slot; None when the device cannot count.
    stats_pool: Option<vk::QueryPool>,
    /// Whether the frame recorded in each slot ran the pre-pass (its query was begun).
    slot_prepass: Vec<bool>,
    /// GPU timestamps per frame slot (`TIMESTAMPS_PER_FRAME`): before the shadow pass, then after
    /// each of the shadow, pre-pass, shading, particle and tone-map passes.
    timestamps: Option<vk::QueryPool>,
    /// The HDR target and the pass that tone-maps it to the display target.
    pub tonemap: ToneMap,
    /// The sun's shadow map for dynamic objects.
    pub shadow: SunShadow,
    /// Blended billboards after the shading pass; the caller fills its queue before `record`.
    pub particles: ParticlePass,
    /// Instanced boid meshes after the shading pass; the caller fills them before `record`.
    pub boids: BoidsDraw,
    /// Casters the last recorded frame drew into the shadow map (0 when it skipped the pass).
    pub shadow_casters: u32,
    /// Instances of one mesh LOD drawn with one call (on by default; off, one call per draw, for
    /// comparison).
    pub instancing: bool,
    /// Draw calls the mesh passes (shadow, pre-pass, shading) of the last recorded frame made.
    pub draw_calls: u32,
    /// Each slot's instance stream (transforms per instance, binding 1 of the mesh pipelines).
    instance_buffers: SlotBuffers,
    batcher: Batcher,
    /// This frame's batches of the camera's draw list (the pre-pass and shading pass share them).
    view_batches: Vec<Batch>,
    /// Depth pre-pass, then shading with depth EQUAL (on by default; off for comparison).
    pub prepass: bool,
    /// Count the fragments the shading pass shades (`fragment_count`); costs an atomic each.
    pub count_fragments: bool,
    /// Depth testing in the shading pass without a pre-pass (off only to count raw fragments).
    pub depth_test: bool,
    /// Instances with a lightmap region read their baked lightmap (on by default); off, they are
    /// lit like dynamic geometry, by the probes and the sun, to compare the two.
    pub lightmaps: bool,
    counters: Vec<Buffer>,
    /// One uniform buffer and descriptor set per frame in flight.
    frame_ubos: Vec<Buffer>,
    frame_sets: Vec<vk::DescriptorSet>,
    /// Culling and LOD state and settings; `visibility.counts` are the last frame's counters.
    pub visibility: Visibility,
    /// Skinned and morphed instances (`animated`): advanced by `animate`, skinned in `record`
    /// and drawn from their skinned output. Set by the owner of the scene; destroyed here.
    pub animation: Option<AnimatedScene>,
}

/// The graphics pipelines of the mesh passes (all share one layout and the vertex shader).
struct Pipelines {
    /// The shading pipelines of dynamic objects (probes and sun) and of lightmapped static
    /// geometry: two variants of one shader (LIGHTMAPPED, mesh_shading.glsl), so neither runs
    /// the other's lighting code.
    shade: [Shading; 2],
    /// Pre-pass: depth only, no fragment shader; and with the alpha-test discard.
    depth: vk::Pipeline,
    depth_masked: vk::Pipeline,
    /// The shadow pass: the same two into the shadow map's format, standard depth (0 nearest the
    /// sun), no culling, with depth bias.
    shadow: vk::Pipeline,
    shadow_masked: vk::Pipeline,
}

/// The shading pass's pipelines for one lighting path.
struct Shading {
    /// Without a pre-pass: depth test and write, alpha test in the shader.
    plain: vk::Pipeline,
    /// After the pre-pass: depth EQUAL, no writes, early fragment tests.
    equal: vk::Pipeline,
    /// Both again, counting fragments (when the device lets fragment shaders write buffers).
    counting: Option<(vk::Pipeline, vk::Pipeline)>,
}

impl Shading {
    fn new(make: impl Fn(bool, bool) -> Result<vk::Pipeline>, counting: bool) -> Result<Shading> {
        Ok(Shading { plain: make(false, false)?, equal: make(true, false)?, counting: if counting { Some((make(false, true)?, make(true, true)?)) } else { None } })
    }

    fn pick(&self, prepass: bool, count: bool) -> vk::Pipeline {
        match (count, self.counting) {
            (true, Some((plain, equal))) => if prepass { equal } else { plain },
            _ => if prepass { self.equal } else { self.plain },
        }
    }

    fn all(&self) -> impl Iterator<Item = vk::Pipeline> {
        [self.plain, self.equal].into_iter().chain(self.counting.into_iter().flat_map(|(a, b)| [a, b]))
    }
}

/// Specialisation constants of the mesh fragment shaders (mesh_shading.glsl).
#[derive(Debug, Clone, Copy, Default)]
struct Variant {
    /// COUNT_FRAGMENTS: each shaded fragment adds one to the frame's counter.
    count_fragments: bool,
    /// LIGHTMAPPED: lit by the instance's lightmap region, not by the probes and the sun.
    lightmapped: bool,
}

/// The stages that read the mesh passes' push constants and material constants: the vertex
/// shader transforms the texture coordinates and picks the lightmap layer.
const MESH_STAGES: vk::ShaderStageFlags = vk::ShaderStageFlags::from_raw(vk::ShaderStageFlags::VERTEX.as_raw() | vk::ShaderStageFlags::FRAGMENT.as_raw());

/// Timestamps written per frame slot: 0..=5 around the passes, 6 and 7 around skinning.
const TIMESTAMPS_PER_FRAME: u32 = 8;

/// GPU milliseconds of each pass of one frame (0 for a pass the frame skipped).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PassTimes {
    /// The skinning compute pass (0 without animated instances in the frame).
    pub skinning_ms: f64,
    pub shadow_ms: f64,
    pub prepass_ms: f64,
    pub shading_ms: f64,
    pub particles_ms: f64,
    pub tonemap_ms: f64,
}

impl PassTimes {
    /// GPU time of all the renderer's passes.
    pub fn total(&self) -> f64 {
        self.skinning_ms + self.shadow_ms + self.prepass_ms + self.shading_ms + self.particles_ms + self.tonemap_ms
    }
}

/// Shader invocations counted by the pipeline statistics queries.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ShaderInvocations {
    pub vertex: u64,
    pub fragment: u64,
}

/// The last frame's counts per pass (`prepass` is None when it did not run).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PassStats {
    pub prepass: Option<ShaderInvocations>,
    pub shading: ShaderInvocations,
}

impl Renderer {
    pub fn new(gpu: &Gpu, color_format: vk::Format, frames_in_flight: usize) -> Result<Renderer> {
        let d = &gpu.device;
        let depth_format = gpu.caps.depth_format;
        let frame_binding = [
            vk::DescriptorSetLayoutBinding::default()
                .binding(0)
                .descriptor_type(vk::DescriptorType::UNIFORM_BUFFER)
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT),
            vk::DescriptorSetLayoutBinding::default()
                .binding(1)
                .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::FRAGMENT),
            vk::DescriptorSetLayoutBinding::default()
                .binding(2)
                .descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER)
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::FRAGMENT),
        ];
        // Set 1: the material's base colour (0) and emissive (1) textures.
        let material_binding = [0, 1].map(|binding| {
            vk::DescriptorSetLayoutBinding::default()
                .binding(binding)
                .descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER)
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::FRAGMENT)
        });
        let frame_layout = unsafe {
            d.create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(&frame_binding), None)?
        };
        let material_layout = unsafe {
            d.create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(&material_binding), None)?
        };
        // Set 2: the lightmap array, the probes, and the material constants (their UV
        // transforms are applied per vertex).
        let scene_bindings = [
            vk::DescriptorSetLayoutBinding::default().binding(0).descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER).descriptor_count(1).stage_flags(vk::ShaderStageFlags::FRAGMENT),
            vk::DescriptorSetLayoutBinding::default().binding(1).descriptor_type(vk::DescriptorType::STORAGE_BUFFER).descriptor_count(1).stage_flags(vk::ShaderStageFlags::FRAGMENT),
            vk::DescriptorSetLayoutBinding::default().binding(2).descriptor_type(vk::DescriptorType::STORAGE_BUFFER).descriptor_count(1).stage_flags(MESH_STAGES),
        ];
        let scene_layout = unsafe { d.create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(&scene_bindings), None)? };
        let set_layouts = [frame_layout, material_layout, scene_layout];
        let push = [vk::PushConstantRange::default().stage_flags(MESH_STAGES).size(std::mem::size_of::<DrawPush>() as u32)];
        let pipeline_layout = unsafe {
            d.create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts).push_constant_ranges(&push), None)?
        };
        let reversed_z_nearer = vk::CompareOp::GREATER_OR_EQUAL;
        let shading = |lightmapped| {
            let make = |equal: bool, count_fragments| {
                let variant = Variant { count_fragments, lightmapped };
                match equal {
                    false => create_mesh_pipeline(gpu, pipeline_layout, Some(HDR_FORMAT), depth_format, Some(shaders::MESH_FRAG), true, reversed_z_nearer, variant, None),
                    true => create_mesh_pipeline(gpu, pipeline_layout, Some(HDR_FORMAT), depth_format, Some(shaders::MESH_EQUAL_FRAG), false, vk::CompareOp::EQUAL, variant, None),
                }
            };
            Shading::new(make, gpu.caps.fragment_atomics)
        };
        let plain = Variant::default();
        let shadow = SunShadow::new(gpu, frame_layout, std::mem::size_of::<FrameUniforms>() as u64, frames_in_flight, DEFAULT_SHADOW_MAP_SIZE)?;
        let bias = Some((DEPTH_BIAS_CONSTANT, DEPTH_BIAS_SLOPE));
        let pipelines = Pipelines {
            shade: [shading(false)?, shading(true)?],
            depth: create_mesh_pipeline(gpu, pipeline_layout, None, depth_format, None, true, reversed_z_nearer, plain, None)?,
            depth_masked: create_mesh_pipeline(gpu, pipeline_layout, None, depth_format, Some(shaders::DEPTH_MASKED_FRAG), true, reversed_z_nearer, plain, None)?,
            shadow: create_mesh_pipeline(gpu, pipeline_layout, None, shadow.format, None, true, vk::CompareOp::LESS_OR_EQUAL, plain, bias)?,
            shadow_masked: create_mesh_pipeline(gpu, pipeline_layout, None, shadow.format, Some(shaders::DEPTH_MASKED_FRAG), true, vk::CompareOp::LESS_OR_EQUAL, plain, bias)?,
        };
        let timestamps = if gpu.caps.timestamps {
            let info = vk::QueryPoolCreateInfo::default().query_type(vk::QueryType::TIMESTAMP).query_count(TIMESTAMPS_PER_FRAME * frames_in_flight as u32);
            Some(unsafe { d.create_query_pool(&info, None)? })
        } else {
            None
        };
        let stats_pool = if gpu.caps.pipeline_statistics {
            let info = vk::QueryPoolCreateInfo::default()
                .query_type(vk::QueryType::PIPELINE_STATISTICS)
                .query_count(2 * frames_in_flight as u32)
                .pipeline_statistics(vk::QueryPipelineStatisticFlags::VERTEX_SHADER_INVOCATIONS | vk::QueryPipelineStatisticFlags::FRAGMENT_SHADER_INVOCATIONS);
            Some(unsafe { d.create_query_pool(&info, None)? })
        } else {
            None
        };

        let n = frames_in_flight as u32;
        let pool_sizes = [
            vk::DescriptorPoolSize { ty: vk::DescriptorType::UNIFORM_BUFFER, descriptor_count: n },
            vk::DescriptorPoolSize { ty: vk::DescriptorType::STORAGE_BUFFER, descriptor_count: n },
            vk::DescriptorPoolSize { ty: vk::DescriptorType::COMBINED_IMAGE_SAMPLER, descriptor_count: n },
        ];
        let pool = unsafe {
            d.create_descriptor_pool(&vk::DescriptorPoolCreateInfo::default().max_sets(n).pool_sizes(&pool_sizes), None)?
        };
        let mut frame_ubos = Vec::new();
        let mut counters = Vec::new();
        let mut frame_sets = Vec::new();
        for _ in 0..frames_in_flight {
            let ubo = Buffer::new(
                gpu,
                "frame uniforms",
                std::mem::size_of::<FrameUniforms>() as u64,
                vk::BufferUsageFlags::UNIFORM_BUFFER,
                MemoryLocation::CpuToGpu,
            )?;
            let counter = Buffer::new(gpu, "fragment counter", 16, vk::BufferUsageFlags::STORAGE_BUFFER, MemoryLocation::GpuToCpu)?;
            let layouts = [frame_layout];
            let set = unsafe { d.allocate_descriptor_sets(&vk::DescriptorSetAllocateInfo::default().descriptor_pool(pool).set_layouts(&layouts))?[0] };
            let ubo_info = [vk::DescriptorBufferInfo { buffer: ubo.buffer, offset: 0, range: vk::WHOLE_SIZE }];
            let counter_info = [vk::DescriptorBufferInfo { buffer: counter.buffer, offset: 0, range: vk::WHOLE_SIZE }];
            let writes = [
                vk::WriteDescriptorSet::default().dst_set(set).dst_binding(0).descriptor_type(vk::DescriptorType::UNIFORM_BUFFER).buffer_info(&ubo_info),
                vk::WriteDescriptorSet::default().dst_set(set).dst_binding(1).descriptor_type(vk::DescriptorType::STORAGE_BUFFER).buffer_info(&counter_info),
            ];
            unsafe { d.update_descriptor_sets(&writes, &[]) };
            write_shadow_map_descriptor(gpu, set, &shadow);
            // The shadow pass's set 0 gets the same bindings 1 and 2: its pipelines do not read
            // them, but lavapipe 22.3 crashes binding a set with unwritten descriptors.
            let shadow_set = shadow.sets[frame_sets.len()];
            let counter_write = vk::WriteDescriptorSet::default().dst_set(shadow_set).dst_binding(1).descriptor_type(vk::DescriptorType::STORAGE_BUFFER).buffer_info(&counter_info);
            unsafe { d.update_descriptor_sets(&[counter_write], &[]) };
            write_shadow_map_descriptor(gpu, shadow_set, &shadow);
            frame_ubos.push(ubo);
            counters.push(counter);
            frame_sets.push(set);
        }
        Ok(Renderer {
            color_format,
            depth_format,
            material_layout,
            scene_layout,
            frame_layout,
            pipeline_layout,
            pipelines,
            pool,
            stats_pool,
            slot_prepass: vec![false; frames_in_flight],
            timestamps,
            tonemap: ToneMap::new(gpu, color_format)?,
            particles: ParticlePass::new(gpu, frame_layout, depth_format, frames_in_flight)?,
            boids: BoidsDraw::new(gpu, frame_layout, depth_format, frames_in_flight)?,
            shadow,
            shadow_casters: 0,
            instancing: true,
            draw_calls: 0,
            instance_buffers: SlotBuffers::new("mesh instances", vk::BufferUsageFlags::VERTEX_BUFFER, frames_in_flight, 256 * INSTANCE_STRIDE as usize),
            batcher: Batcher::default(),
            view_batches: Vec::new(),
            prepass: true,
            lightmaps: true,
            count_fragments: false,
            depth_test: true,
            counters,
            frame_ubos,
            frame_sets,
            visibility: Visibility::default(),
            animation: None,
        })
    }

    /// The layouts `GpuScene::upload` makes its descriptor sets for.
    pub fn layouts(&self) -> SceneLayouts {
        SceneLayouts { material: self.material_layout, scene: self.scene_layout }
    }

    /// Advance the animated instances by `dt` seconds and move their culling spheres; call once
    /// per frame before `record`.
    pub fn animate(&mut self, scene: &mut GpuScene, dt: f32) {
        if let Some(a) = &mut self.animation {
            a.advance(scene, dt);
        }
    }

    /// Record one frame: cull and pick LODs for `camera` (`self.visibility`); skinning of the
    /// animated instances drawn or casting (`self.animation`); the sun's shadow map when dynamic
    /// objects in view need it; depth pre-pass; shading into the HDR target;
    /// tone map into `target`'s colour image. Attachments go from UNDEFINED to attachment
    /// layouts; the colour image is left in COLOR_ATTACHMENT_OPTIMAL for the caller to present
    /// or copy. `slot` selects the per-frame uniform buffer, which must not be in use by the GPU.
    /// Fails only when the HDR target cannot be (re)made for a new size.
    #[allow(clippy::too_many_arguments)]
    pub fn record(&mut self, gpu: &Gpu, cb: vk::CommandBuffer, slot: usize, scene: &GpuScene, camera: &Camera, lighting: &Lighting, target: &FrameTarget) -> Result<()> {
        let d = &gpu.device;
        let aspect = target.extent.width as f32 / target.extent.height as f32;
        let view_proj = camera.view_proj(aspect);
        self.visibility.update(scene, view_proj, camera.position, camera.fov_y, target.extent.height as f32);
        // Skipped when empty: nothing to blend, and the depth need not be stored for it.
        let draw_particles = !self.particles.is_empty();
        self.visibility.counts.particles = self.particles.len() as u32;
        self.particles.upload(gpu, slot)?;
        // Boids are instances culled with the scene: their counts join the frame's.
        let boids = self.boids.cull(view_proj);
        let c = &mut self.visibility.counts;
        c.cull.tested += boids.tested;
        c.cull.culled += boids.culled;
        c.cull.visible += boids.visible;
        c.cull.inside += boids.inside;
        c.boids = boids.visible;
        let draw_boids = boids.visible > 0;
        self.boids.upload(gpu, slot)?;
        let (hdr_image, hdr_view) = self.tonemap.hdr_target(gpu, target.extent)?;
        // The shadow map serves dynamic objects lit by a physical sun: skip it when none is in
        // view (and lavapipe 22.3 crashes on a depth-only rendering without draws).
        let sun = scene.baked.filter(|b| b.sun_lux.max_element() > 0.0);
        let dynamic_in_view = self.visibility.draws.iter().any(|dr| !scene.instances[dr.instance as usize].is_static);
        let draw_shadow = match sun {
            Some(b) if dynamic_in_view && !scene.instances.is_empty() => {
                self.shadow.prepare(scene, b.sun_dir);
                true
            }
            _ => false,
        };
        self.shadow_casters = if draw_shadow { self.shadow.casters.len() as u32 } else { 0 };
        // The camera's draw list as instanced batches, shared by the pre-pass and the shading
        // pass; the shadow pass batches its casters as it draws them. The slot's instance buffer
        // holds both: at most every caster plus every draw.
        let mut batcher = std::mem::take(&mut self.batcher);
        let mut view_batches = std::mem::take(&mut self.view_batches);
        batcher.clear();
        // Lightmaps are read when there are baked pages and they are switched on.
        let mode = BatchMode { instancing: self.instancing, lightmaps: self.lightmaps && scene.baked.is_some() };
        batcher.batch(scene, self.animation.as_ref(), slot, &self.visibility.draws, mode, &mut view_batches);
        let stream_capacity = (self.shadow_casters as usize + self.visibility.draws.len()) * INSTANCE_STRIDE as usize;
        let instances = self.instance_buffers.reserve(gpu, slot, stream_capacity)?.buffer;
        let mut draw_calls = 0;
        let shadow_params = Vec4::new(draw_shadow as u32 as f32, self.shadow.texel_m, 1.0 / self.shadow.size as f32, 0.0);
        // A baked scene is lit by its lightmaps, probes and sun in physical units, exposed and
        // tone-mapped; otherwise the stand-in `lighting`.
        let uniforms = match scene.baked {
            Some(b) => FrameUniforms {
                view_proj,
                sun_view_proj: self.shadow.view_proj,
                camera_pos: camera.position.extend(1.0),
                sun_dir: b.sun_dir.extend(0.0),
                sun_color: b.sun_lux.extend(0.0),
                ambient: Vec4::ZERO,
                exposure: Vec4::new(b.exposure, 1.0, 0.0, 0.0),
                shadow: shadow_params,
            },
            None => FrameUniforms {
                view_proj,
                sun_view_proj: self.shadow.view_proj,
                camera_pos: camera.position.extend(1.0),
                sun_dir: lighting.sun_dir.normalize().extend(0.0),
                sun_color: lighting.sun_color.extend(0.0),
                ambient: lighting.ambient.extend(0.0),
                exposure: Vec4::new(1.0, 0.0, 0.0, 0.0),
                shadow: shadow_params,
            },
        };
        self.frame_ubos[slot].mapped()[..std::mem::size_of::<FrameUniforms>()].copy_from_slice(uniform_bytes(&uniforms));
        if draw_shadow {
            // The shadow pass runs mesh.vert with the sun's transform as its view_proj.
            self.shadow.write_uniforms(slot, uniform_bytes(&FrameUniforms { view_proj: self.shadow.view_proj, ..uniforms }));
        }

        barrier(gpu, cb, target.color_image, full_range(vk::ImageAspectFlags::COLOR, 1), Transition::COLOR_ATTACHMENT_DISCARD);
        barrier(gpu, cb, hdr_image, full_range(vk::ImageAspectFlags::COLOR, 1), Transition::SAMPLED_TO_COLOR_ATTACHMENT_DISCARD);
        barrier(gpu, cb, target.depth_image, full_range(vk::ImageAspectFlags::DEPTH, 1), Transition::DEPTH_ATTACHMENT_DISCARD);
        let area = vk::Rect2D { offset: vk::Offset2D::default(), extent: target.extent };
        let (query_a, query_b) = (2 * slot as u32, 2 * slot as u32 + 1);
        if let Some(pool) = self.stats_pool {
            unsafe { d.cmd_reset_query_pool(cb, pool, query_a, 2) };
        }
        let first_stamp = TIMESTAMPS_PER_FRAME * slot as u32;
        let stamp = |i: u32| {
            if let Some(pool) = self.timestamps {
                unsafe { d.cmd_write_timestamp2(cb, vk::PipelineStageFlags2::ALL_COMMANDS, pool, first_stamp + i) };
            }
        };
        if let Some(pool) = self.timestamps {
            unsafe { d.cmd_reset_query_pool(cb, pool, first_stamp, TIMESTAMPS_PER_FRAME) };
        }
        // Skinning once per frame, before every pass that reads its output.
        stamp(6);
        if let Some(a) = &mut self.animation {
            a.record(gpu, cb, slot, &self.visibility.draws, if draw_shadow { &self.shadow.casters } else { &[] });
        }
        stamp(7);
        stamp(0);
        if draw_shadow {
            let p = &self.pipelines;
            let mut batches = Vec::new();
            // Depth only: lightmapped or not, the casters of one mesh share a call.
            let casters_mode = BatchMode { lightmaps: false, ..mode };
            self.shadow.record(gpu, cb, |view, load_op, casters| {
                batcher.batch(scene, self.animation.as_ref(), slot, casters, casters_mode, &mut batches);
                let depth_attachment = vk::RenderingAttachmentInfo::default()
                    .image_view(view)
                    .image_layout(vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL)
                    .load_op(load_op)
                    .store_op(vk::AttachmentStoreOp::STORE)
                    .clear_value(vk::ClearValue { depth_stencil: vk::ClearDepthStencilValue { depth: 1.0, stencil: 0 } });
                let rendering = vk::RenderingInfo::default().render_area(self.shadow.area()).layer_count(1).depth_attachment(&depth_attachment);
                let pass = PassSetup { frame_set: self.shadow.sets[slot], batches: &batches, instances, query: None, depth_test: true, cull: false };
                draw_calls += self.pass(gpu, cb, scene, &rendering, &pass, |mat, _| if mat.alpha_cutoff >= 0.0 { p.shadow_masked } else { p.shadow });
            });
        }
        stamp(1);
        // With nothing to draw there is nothing to pre-pass (and lavapipe 22.3 crashes executing a
        // depth-only rendering that has no draws).
        let prepass = self.prepass && !self.visibility.draws.is_empty();
        self.slot_prepass[slot] = prepass;
        // Reversed-Z: the far plane is depth 0.
        let depth_clear = vk::ClearValue { depth_stencil: vk::ClearDepthStencilValue { depth: 0.0, stencil: 0 } };
        let frame_set = self.frame_sets[slot];
        if prepass {
            let depth_attachment = vk::RenderingAttachmentInfo::default()
                .image_view(target.depth_view)
                .image_layout(vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL)
                .load_op(vk::AttachmentLoadOp::CLEAR)
                .store_op(vk::AttachmentStoreOp::STORE)
                .clear_value(depth_clear);
            let rendering = vk::RenderingInfo::default().render_area(area).layer_count(1).depth_attachment(&depth_attachment);
            let pass = PassSetup { frame_set, batches: &view_batches, instances, query: Some(query_a), depth_test: true, cull: true };
            draw_calls += self.pass(gpu, cb, scene, &rendering, &pass, |mat, _| if mat.alpha_cutoff >= 0.0 { self.pipelines.depth_masked } else { self.pipelines.depth });
            // The shading pass tests against what the pre-pass wrote.
            barrier(gpu, cb, target.depth_image, full_range(vk::ImageAspectFlags::DEPTH, 1), Transition::DEPTH_WRITE_TO_TEST);
        }
        stamp(2);
        // Alpha 0 marks the clear colour as "no surface" for the tone map, which leaves it as it
        // is: it is display-referred, not radiance.
        let [r, g, b, _] = CLEAR_COLOR;
        let color_attachment = [vk::RenderingAttachmentInfo::default()
            .image_view(hdr_view)
            .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::STORE)
            .clear_value(vk::ClearValue { color: vk::ClearColorValue { float32: [r, g, b, 0.0] } })];
        let depth_attachment = vk::RenderingAttachmentInfo::default()
            .image_view(target.depth_view)
            .image_layout(vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL)
            .load_op(if prepass { vk::AttachmentLoadOp::LOAD } else { vk::AttachmentLoadOp::CLEAR })
            .store_op(if draw_particles || draw_boids { vk::AttachmentStoreOp::STORE } else { vk::AttachmentStoreOp::DONT_CARE })
            .clear_value(depth_clear);
        let rendering = vk::RenderingInfo::default().render_area(area).layer_count(1).color_attachments(&color_attachment).depth_attachment(&depth_attachment);
        let shade = [0, 1].map(|lightmapped| self.pipelines.shade[lightmapped].pick(prepass, self.count_fragments));
        self.counters[slot].mapped()[..4].copy_from_slice(&0u32.to_le_bytes());
        let pass = PassSetup { frame_set, batches: &view_batches, instances, query: Some(query_b), depth_test: prepass || self.depth_test, cull: true };
        draw_calls += self.pass(gpu, cb, scene, &rendering, &pass, |_, lightmapped| shade[lightmapped as usize]);
        // Every pass is recorded: the instance stream is complete.
        let stream = batcher.stream_bytes();
        assert!(stream.len() <= stream_capacity, "instance stream overran its reservation");
        self.instance_buffers.write(gpu, slot, stream)?;
        self.draw_calls = draw_calls;
        self.batcher = batcher;
        self.view_batches = view_batches;
        if draw_boids {
            self.boids.record(gpu, cb, slot, frame_set, (hdr_image, hdr_view), (target.depth_image, target.depth_view), target.extent);
        }
        stamp(3);
        if draw_particles {
            let up = camera.right().cross(camera.forward());
            self.particles.record(gpu, cb, slot, frame_set, (hdr_image, hdr_view), (target.depth_image, target.depth_view), target.extent, camera.right(), up);
        }
        stamp(4);
        self.tonemap.record(gpu, cb, target.color_view, target.extent, uniforms.exposure.x, scene.baked.is_some());
        stamp(5);
        Ok(())
    }

    /// GPU milliseconds per pass of the frame last recorded in `slot`, once the GPU has finished
    /// it; None without timestamps.
    pub fn pass_times_ms(&self, gpu: &Gpu, slot: usize) -> Option<PassTimes> {
        let pool = self.timestamps?;
        let mut t = [0u64; TIMESTAMPS_PER_FRAME as usize];
        unsafe { gpu.device.get_query_pool_results(pool, TIMESTAMPS_PER_FRAME * slot as u32, &mut t, vk::QueryResultFlags::TYPE_64) }.ok()?;
        let ms = |a: u64, b: u64| b.saturating_sub(a) as f64 * gpu.caps.timestamp_period_ns as f64 * 1e-6;
        Some(PassTimes { skinning_ms: ms(t[6], t[7]), shadow_ms: ms(t[0], t[1]), prepass_ms: ms(t[1], t[2]), shading_ms: ms(t[2], t[3]), particles_ms: ms(t[3], t[4]), tonemap_ms: ms(t[4], t[5]) })
    }

    /// Make the sun's shadow map `size` texels square (default `shadow::DEFAULT_SHADOW_MAP_SIZE`).
    /// Waits for the device: frames in flight may be reading the old map.
    pub fn set_shadow_map_size(&mut self, gpu: &Gpu, size: u32) -> Result<()> {
        if size == self.shadow.size {
            return Ok(());
        }
        let max = unsafe { gpu.instance.get_physical_device_properties(gpu.physical_device) }.limits.max_image_dimension2_d;
        if size == 0 || size > max {
            anyhow::bail!("shadow map size {size} is out of range (1..={max} on {})", gpu.caps.device_name);
        }
        gpu.wait_idle();
        self.shadow.resize(gpu, size)?;
        for &set in self.frame_sets.iter().chain(&self.shadow.sets) {
            write_shadow_map_descriptor(gpu, set, &self.shadow);
        }
        Ok(())
    }

    /// One rendering instance drawing `setup.batches`, each submesh with the pipeline
    /// `pipeline_for(material, lightmapped)` gives, counted by the pipeline-statistics query `setup.query`.
    /// Returns the draw calls it made.
    fn pass(&self, gpu: &Gpu, cb: vk::CommandBuffer, scene: &GpuScene, rendering: &vk::RenderingInfo, setup: &PassSetup, pipeline_for: impl Fn(&GpuMaterial, bool) -> vk::Pipeline) -> u32 {
        let d = &gpu.device;
        let extent = rendering.render_area.extent;
        let query = setup.query.and_then(|q| self.stats_pool.map(|pool| (pool, q)));
        let mut calls = 0;
        unsafe {
            if let Some((pool, q)) = query {
                d.cmd_begin_query(cb, pool, q, vk::QueryControlFlags::empty());
            }
            d.cmd_begin_rendering(cb, rendering);
            d.cmd_set_viewport(cb, 0, &[vk::Viewport { x: 0.0, y: 0.0, width: extent.width as f32, height: extent.height as f32, min_depth: 0.0, max_depth: 1.0 }]);
            d.cmd_set_scissor(cb, 0, &[rendering.render_area]);
            d.cmd_set_depth_test_enable(cb, setup.depth_test);
            d.cmd_bind_descriptor_sets(cb, vk::PipelineBindPoint::GRAPHICS, self.pipeline_layout, 0, &[setup.frame_set], &[]);
            d.cmd_bind_descriptor_sets(cb, vk::PipelineBindPoint::GRAPHICS, self.pipeline_layout, 2, &[scene.scene_set], &[]);
            d.cmd_bind_vertex_buffers(cb, 0, &[scene.vertex_buffer.buffer, setup.instances], &[0, 0]);
            d.cmd_bind_index_buffer(cb, scene.index_buffer.buffer, 0, vk::IndexType::UINT32);
            let mut bound = vk::Pipeline::null();
            let mut bound_vertices = scene.vertex_buffer.buffer;
            for batch in setup.batches {
                let mesh = &scene.meshes[scene.instances[batch.instance as usize].mesh as usize];
                let lod = &mesh.lods[batch.lod as usize];
                // An animated instance draws its skinned vertices: already in world space, from
                // vertex 0 of its own buffer; every pass reads the same buffer, so the pre-pass
                // and the EQUAL shading pass see identical positions.
                if batch.vertices != bound_vertices {
                    d.cmd_bind_vertex_buffers(cb, 0, &[batch.vertices], &[0]);
                    bound_vertices = batch.vertices;
                }
                d.cmd_set_front_face(cb, batch.front);
                for sm in &lod.submeshes {
                    let mat = &scene.materials[sm.material as usize];
                    // Instances with a lightmap region read it where the submesh has a block;
                    // the rest the probes and the sun.
                    let pipeline = pipeline_for(mat, batch.lightmapped && sm.lightmap_block.is_some());
                    if pipeline != bound {
                        d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, pipeline);
                        bound = pipeline;
                    }
                    let push = DrawPush {
                        material: Vec4::new(mat.alpha_cutoff, sm.material as f32, sm.lightmap_block.unwrap_or(0) as f32, 0.0),
                        base_color: Vec4::from(mat.base_color),
                    };
                    let push_bytes = std::slice::from_raw_parts(&push as *const _ as *const u8, std::mem::size_of::<DrawPush>());
                    d.cmd_push_constants(cb, self.pipeline_layout, MESH_STAGES, 0, push_bytes);
                    let cull = if setup.cull && !mat.double_sided { vk::CullModeFlags::BACK } else { vk::CullModeFlags::NONE };
                    d.cmd_set_cull_mode(cb, cull);
                    d.cmd_bind_descriptor_sets(cb, vk::PipelineBindPoint::GRAPHICS, self.pipeline_layout, 1, &[mat.descriptor_set], &[]);
                    d.cmd_draw_indexed(cb, sm.index_count, batch.count, lod.first_index + sm.first_index, batch.base_vertex, batch.first_instance);
                    calls += 1;
                }
            }
            d.cmd_end_rendering(cb);
            if let Some((pool, q)) = query {
                d.cmd_end_query(cb, pool, q);
            }
        }
        calls
    }

    /// Fragments the shading pass of the frame last recorded in `slot` shaded, once the GPU has
    /// finished it; None unless `count_fragments` was on and the device can count.
    pub fn fragment_count(&self, slot: usize) -> Option<u32> {
        (self.count_fragments && self.pipelines.shade[0].counting.is_some()).then(|| u32::from_le_bytes(self.counters[slot].mapped_ref()[..4].try_into().unwrap()))
    }

    /// Shader invocations of the frame last recorded in `slot`, once the GPU has finished it
    /// (the caller waits for its fence first). None when the device cannot count.
    pub fn pass_stats(&self, gpu: &Gpu, slot: usize) -> Option<PassStats> {
        let pool = self.stats_pool?;
        let read = |q: u32| -> Option<ShaderInvocations> {
            let mut v = [[0u64; 2]; 1];
            unsafe { gpu.device.get_query_pool_results(pool, q, &mut v, vk::QueryResultFlags::TYPE_64) }.ok()?;
            Some(ShaderInvocations { vertex: v[0][0], fragment: v[0][1] })
        };
        let prepass = if self.slot_prepass[slot] { Some(read(2 * slot as u32)?) } else { None };
        Some(PassStats { prepass, shading: read(2 * slot as u32 + 1)? })
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        let d = &gpu.device;
        for b in self.frame_ubos.iter_mut().chain(self.counters.iter_mut()) {
            b.destroy(gpu);
        }
        self.tonemap.destroy(gpu);
        self.particles.destroy(gpu);
        self.boids.destroy(gpu);
        self.instance_buffers.destroy(gpu);
        self.shadow.destroy(gpu);
        if let Some(a) = &mut self.animation {
            a.destroy(gpu);
        }
        unsafe {
            d.destroy_descriptor_pool(self.pool, None);
            let p = &self.pipelines;
            for pipeline in [p.depth, p.depth_masked, p.shadow, p.shadow_masked].into_iter().chain(p.shade.iter().flat_map(Shading::all)) {
                d.destroy_pipeline(pipeline, None);
            }
            for pool in self.stats_pool.into_iter().chain(self.timestamps) {
                d.destroy_query_pool(pool, None);
            }
            d.destroy_pipeline_layout(self.pipeline_layout, None);
            d.destroy_descriptor_set_layout(self.frame_layout, None);
            d.destroy_descriptor_set_layout(self.material_layout, None);
            d.destroy_descriptor_set_layout(self.scene_layout, None);
        }
    }
}

/// What one mesh pass draws and how: the set 0 it binds (the camera's or the sun's uniforms),
/// the draw list, its statistics query, depth testing, and back-face culling (off for shadow
/// casters: a single-sided occluder blocks the sun whichever side faces it).
struct PassSetup<'a> {
    frame_set: vk::DescriptorSet,
    batches: &'a [Batch],
    /// The frame slot's instance stream the batches index.
    instances: vk::Buffer,
    query: Option<u32>,
    depth_test: bool,
    cull: bool,
}

fn uniform_bytes(u: &FrameUniforms) -> &[u8] {
    // SAFETY: FrameUniforms is repr(C) plain floats.
    unsafe { std::slice::from_raw_parts(u as *const _ as *const u8, std::mem::size_of::<FrameUniforms>()) }
}

/// Point binding 2 of a frame set (set 0) at the sun's shadow map.
fn write_shadow_map_descriptor(gpu: &Gpu, set: vk::DescriptorSet, shadow: &SunShadow) {
    let info = [vk::DescriptorImageInfo { sampler: shadow.sampler, image_view: shadow.view(), image_layout: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL }];
    let write = vk::WriteDescriptorSet::default().dst_set(set).dst_binding(2).descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER).image_info(&info);
    unsafe { gpu.device.update_descriptor_sets(&[write], &[]) };
}

fn attribute_format(f: pack::AttributeFormat) -> vk::Format {
    match f {
        pack::AttributeFormat::F32x2 => vk::Format::R32G32_SFLOAT,
        pack::AttributeFormat::F32x3 => vk::Format::R32G32B32_SFLOAT,
        pack::AttributeFormat::F32x4 => vk::Format::R32G32B32A32_SFLOAT,
        pack::AttributeFormat::Unorm8x4 => vk::Format::R8G8B8A8_UNORM,
    }
}

/// A mesh pipeline: `mesh.vert` plus `frag` (None: depth only), rendering into `color_format`
/// (None: no colour attachment) and `depth_format` with the given depth write and compare, and
/// a rasteriser depth bias (constant, slope factor) when given; `variant` specialises the
/// fragment shader.
#[allow(clippy::too_many_arguments)]
fn create_mesh_pipeline(
    gpu: &Gpu,
    layout: vk::PipelineLayout,
    color_format: Option<vk::Format>,
    depth_format: vk::Format,
    frag: Option<&[u8]>,
    depth_write: bool,
    compare: vk::CompareOp,
    variant: Variant,
    depth_bias: Option<(f32, f32)>,
) -> Result<vk::Pipeline> {
    // Specialisation constants 0 and 1: COUNT_FRAGMENTS and LIGHTMAPPED (mesh_shading.glsl).
    let values = [variant.count_fragments, variant.lightmapped].map(|b| vk::Bool32::from(b).to_le_bytes());
    let bytes = values.concat();
    let entries = [vk::SpecializationMapEntry { constant_id: 0, offset: 0, size: 4 }, vk::SpecializationMapEntry { constant_id: 1, offset: 4, size: 4 }];
    let spec = vk::SpecializationInfo::default().map_entries(&entries).data(&bytes);
    // The vertex layout comes from the pack crate: one definition of the format. Only the
    // attributes this shader reads are declared (tangent arrives with normal mapping).
    const MESH_SHADER_INPUTS: [u32; 6] = [0, 1, 3, 4, 5, 13];
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
        .collect();
    // Cull mode, front face and depth testing are dynamic (core 1.3): double-sided materials,
    // mirrored instances and the raw fragment count (`depth_test` off) change them per draw or
    // pass without a second pipeline.
    let dynamic = [vk::DynamicState::CULL_MODE, vk::DynamicState::FRONT_FACE, vk::DynamicState::DEPTH_TEST_ENABLE];
    let mut pipeline = GraphicsPipeline::new("mesh", shaders::MESH_VERT)
        .vertex_input(&bindings, &attributes)
        .cull_back()
        .depth_bias(depth_bias)
        .depth(depth_format, depth_write, compare)
        .dynamic(&dynamic);
    if let Some(f) = frag {
        pipeline = pipeline.fragment(f, Some(spec));
    }
    if let Some(format) = color_format {
        pipeline = pipeline.color(format, opaque());
    }
    pipeline.build(&gpu.device, layout)
}
