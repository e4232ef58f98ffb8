//! The forward renderer (dynamic rendering, reversed-Z depth). `prepare` does a frame's CPU
//! work (culling and LODs, batching, uploads, uniforms); `record` runs the frame graph
//! (`render::graph`) over the passes in `render::passes`: skinning, the sun's shadow map, a depth
//! pre-pass, shading into an HDR target, boids, particles, the tone map into the output, and
//! whatever passes the caller adds (the overlay, a read-back). Used by the headless target and
//! the window.

use crate::anim::animated::AnimatedScene;
use crate::render::batches::{BatchMode, Batcher, INSTANCE_STRIDE};
use crate::render::boids_draw::BoidsDraw;
use crate::scene::camera::Camera;
use crate::gpu::{Buffer, Gpu, SlotBuffers};
use crate::render::particles_draw::ParticlePass;
use crate::render::frame::{FrameCx, FrameData, Settings, SkyParams, FRAGMENT_COUNTER};
use crate::render::graph::{Access, FrameProfile, Graph, ImageRef, Pass, ResourceId};
use crate::render::mesh_draw::{LitPhase, MeshKit};
use crate::render::passes;
use crate::render::scale::{RenderScale, ScaleController, Upscaler};
use crate::scene::{GpuScene, SceneLayouts};
use crate::render::shadow::{SunShadow, DEFAULT_SHADOW_MAP_SIZE};
use crate::render::tonemap::ToneMap;
use crate::render::visibility::{Draw, Visibility};
use anyhow::Result;
use ash::vk;
use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3, Vec4};
use gpu_allocator::MemoryLocation;

/// Mirrors `Frame` in shaders/frame.glsl (std140).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
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
    /// The shading's switches: x: 1 for specular (`Renderer::specular`). (`material_maps`
    /// picks the pipelines: `MeshKit::lit`.) y: the material textures' mip bias, log2 of the
    /// render scale (texture detail of the output's size in a frame drawn smaller).
    pub features: Vec4,
}

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

/// The image one frame ends in: the display colour image (an `_SRGB` format: the tone-map pass
/// writes linear values and the hardware encodes them), of the renderer's `color_format`.
pub struct FrameTarget {
    pub color_image: vk::Image,
    pub color_view: vk::ImageView,
    pub extent: vk::Extent2D,
}

pub struct Renderer {
    /// The display target's format (what the tone-map pass writes); shading renders to `HDR_FORMAT`.
    pub color_format: vk::Format,
    pub depth_format: vk::Format,
    mesh: MeshKit,
    graph: Graph,
    /// The frame's passes in order (`render::passes::register`).
    passes: Vec<Box<dyn Pass>>,
    pool: vk::DescriptorPool,
    /// One uniform buffer, fragment counter and descriptor set (set 0) per frame in flight.
    frame_ubos: Vec<Buffer>,
    counters: Vec<Buffer>,
    frame_sets: Vec<vk::DescriptorSet>,
    /// The tone-map pass's parameters and pipeline.
    pub tonemap: ToneMap,
    /// The sun's shadow map for dynamic objects.
    pub shadow: SunShadow,
    /// Blended billboards after the shading pass; the caller fills its queue before `prepare`.
    pub particles: ParticlePass,
    /// Instanced boid meshes after the shading pass; the caller fills them before `prepare`.
    pub boids: BoidsDraw,
    /// Casters in the last frame's shadow map (0 when it skipped the pass), whether drawn this
    /// frame or kept from the static casters' cache.
    pub shadow_casters: u32,
    /// Casters the last frame drew into the shadow map or its cache (the cached ones are not).
    pub shadow_casters_drawn: u32,
    /// Instances of one mesh LOD drawn with one call (on by default; off, one call per draw, for
    /// comparison).
    pub instancing: bool,
    /// Draw calls the mesh passes (shadow, pre-pass, shading) of the last recorded frame made.
    pub draw_calls: u32,
    /// Each slot's instance stream (transforms per instance, binding 1 of the mesh pipelines).
    instance_buffers: SlotBuffers,
    batcher: Batcher,
    /// What `prepare` made for `record`.
    frame: FrameData,
    /// The scene and settings `prepare_lit` last made pipelines for (and whether lightmaps were on).
    lit_prepared: Option<(u64, Settings, bool)>,
    /// Depth pre-pass, then shading with depth EQUAL (on by default; off for comparison).
    pub prepass: bool,
    /// Count the fragments the shading pass shades (`fragment_count`); costs an atomic each.
    pub count_fragments: bool,
    /// Depth testing in the shading pass without a pre-pass (off only to count raw fragments).
    pub depth_test: bool,
    /// Instances with a lightmap region read their baked lightmap (on by default); off, they are
    /// lit like dynamic geometry, by the probes and the sun, to compare the two.
    pub lightmaps: bool,
    /// Read lightmaps through a cubic B-spline (four bilinear taps) instead of one bilinear
    /// tap: a baked shadow's edge without the kinks bilinear puts at every texel (the filter
    /// reaches two texels past a chart; the atlas keeps 4 clear). On by default where it pays:
    /// on a GPU four taps are noise; on a CPU device (lavapipe) each lookup of the most-drawn
    /// surfaces costs milliseconds, so it starts off there.
    pub bicubic_lightmaps: bool,
    /// Specular light from the scene's reflection probes (on by default); off, or without
    /// probes, the environment is the lightmap's or irradiance probes' light in the reflected
    /// direction.
    pub reflections: bool,
    /// Show the depth buffer instead of the shaded frame (the `depth view` debug pass).
    pub depth_view: bool,
    /// Draw a baked level's sky and sun disc as the background (on by default; off, the clear
    /// colour, to measure the sky pass).
    pub sky: bool,
    /// Sample the materials' normal, metallic-roughness, occlusion and emissive maps (on by
    /// default; off, their factors alone, to see and measure what the maps add).
    pub material_maps: bool,
    /// Specular reflection, of the sun and of the environment (on by default; off, diffuse
    /// only: the look and the cost before the glTF material model).
    pub specular: bool,
    /// Draw BLEND materials in the transparent phase (on by default; off, they are not drawn,
    /// to see and measure the phase).
    pub transparency: bool,
    /// Anti-aliasing: off, MSAA (multisampled camera targets, `resolve` pass) or FXAA after the
    /// tone map (the `fxaa` pass).
    pub aa: AntiAliasing,
    /// Whether the frame last recorded in each slot counted fragments.
    slot_counted: Vec<bool>,
    /// Culling and LOD state and settings; `visibility.counts` are the last frame's counters.
    pub visibility: Visibility,
    /// The render scale (`scale::RenderScale`): `Fixed(1.0)` unless the owner asks (every frame
    /// at the output's size, deterministic); the demo and the bench make it adaptive.
    pub render_scale: ScaleController,
    /// The upscaler's filter: EASU on GPUs; on CPU devices the Catmull-Rom cubic, which costs
    /// 0.62x of EASU's pass there for the same SSIM to within 0.003 (README, "Frame budget").
    pub upscaler: Upscaler,
    /// The scale each slot's last frame was drawn at (what its GPU time is evidence of).
    slot_scale: Vec<f32>,
    /// `prepare` feeds the GPU time of the slot's finished frame to `render_scale` (on by
    /// default); off, the owner does (the bench keeps a controller per variant it interleaves).
    pub scale_feedback: bool,
    /// Skinned and morphed instances (`animated`): advanced by `animate`, skinned in `record`
    /// and drawn from their skinned output. Set by the owner of the scene; destroyed here.
    pub animation: Option<AnimatedScene>,
}

impl Renderer {
    pub fn new(gpu: &Gpu, color_format: vk::Format, frames_in_flight: usize) -> Result<Renderer> {
        let d = &gpu.device;
        let shadow_format = SunShadow::format_for(gpu)?;
        // Each part is owned until the renderer is whole: an error frees what was made.
        let mesh = gpu.own(MeshKit::new(gpu, shadow_format)?);
        let shadow = gpu.own(SunShadow::new(gpu, mesh.frame_layout, std::mem::size_of::<FrameUniforms>() as u64, frames_in_flight, DEFAULT_SHADOW_MAP_SIZE)?);
        let n = frames_in_flight as u32;
        let pool_sizes = [
            vk::DescriptorPoolSize { ty: vk::DescriptorType::UNIFORM_BUFFER, descriptor_count: n },
            vk::DescriptorPoolSize { ty: vk::DescriptorType::STORAGE_BUFFER, descriptor_count: n },
            vk::DescriptorPoolSize { ty: vk::DescriptorType::COMBINED_IMAGE_SAMPLER, descriptor_count: n },
        ];
        let pool = gpu.own(unsafe { d.create_descriptor_pool(&vk::DescriptorPoolCreateInfo::default().max_sets(n).pool_sizes(&pool_sizes), None)? });
        let mut frame_ubos = gpu.own(Vec::new());
        let mut counters = gpu.own(Vec::new());
        let mut frame_sets = Vec::new();
        for _ in 0..frames_in_flight {
            frame_ubos.push(Buffer::new(gpu, "frame uniforms", std::mem::size_of::<FrameUniforms>() as u64, vk::BufferUsageFlags::UNIFORM_BUFFER, MemoryLocation::CpuToGpu)?);
            counters.push(Buffer::new(gpu, "fragment counter", 16, vk::BufferUsageFlags::STORAGE_BUFFER, MemoryLocation::GpuToCpu)?);
            let (ubo, counter) = (&frame_ubos[frame_sets.len()], &counters[frame_sets.len()]);
            let layouts = [mesh.frame_layout];
            let set = unsafe { d.allocate_descriptor_sets(&vk::DescriptorSetAllocateInfo::default().descriptor_pool(*pool).set_layouts(&layouts))?[0] };
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
            frame_sets.push(set);
        }
        let graph = gpu.own(Graph::new(gpu, frames_in_flight)?);
        let passes = gpu.own(passes::register(gpu, color_format, frames_in_flight)?);
        let tonemap = gpu.own(ToneMap::new(gpu, color_format, frames_in_flight)?);
        let particles = gpu.own(ParticlePass::new(gpu, mesh.frame_layout, gpu.caps.depth_format, frames_in_flight)?);
        let boids = gpu.own(BoidsDraw::new(gpu, mesh.frame_layout, gpu.caps.depth_format, frames_in_flight)?);
        Ok(Renderer {
            color_format,
            depth_format: gpu.caps.depth_format,
            graph: graph.keep(),
            passes: passes.keep(),
            pool: pool.keep(),
            frame_ubos: frame_ubos.keep(),
            counters: counters.keep(),
            frame_sets,
            tonemap: tonemap.keep(),
            particles: particles.keep(),
            boids: boids.keep(),
            mesh: mesh.keep(),
            shadow: shadow.keep(),
            shadow_casters: 0,
            shadow_casters_drawn: 0,
            instancing: true,
            draw_calls: 0,
            instance_buffers: SlotBuffers::new("mesh instances", vk::BufferUsageFlags::VERTEX_BUFFER, frames_in_flight, 256 * INSTANCE_STRIDE as usize),
            batcher: Batcher::default(),
            frame: FrameData::default(),
            lit_prepared: None,
            prepass: true,
            count_fragments: false,
            depth_test: true,
            lightmaps: true,
            bicubic_lightmaps: gpu.caps.device_type != vk::PhysicalDeviceType::CPU,
            reflections: true,
            depth_view: false,
            sky: true,
            material_maps: true,
            specular: true,
            transparency: true,
            aa: AntiAliasing::Off,
            slot_counted: vec![false; frames_in_flight],
            visibility: Visibility::default(),
            render_scale: ScaleController::new(RenderScale::Fixed(1.0)),
            slot_scale: vec![1.0; frames_in_flight],
            scale_feedback: true,
            upscaler: if gpu.caps.device_type == vk::PhysicalDeviceType::CPU { Upscaler::Cubic } else { Upscaler::Easu },
            animation: None,
        })
    }

    /// The layouts `GpuScene::upload` makes its descriptor sets for.
    pub fn layouts(&self) -> SceneLayouts {
        SceneLayouts { material: self.mesh.material_layout, scene: self.mesh.scene_layout }
    }

    /// Advance the animated instances by `dt` seconds and move their culling spheres; call once
    /// per frame before `prepare`.
    pub fn animate(&mut self, scene: &mut GpuScene, dt: f32) {
        if let Some(a) = &mut self.animation {
            a.advance(scene, dt);
        }
    }

    /// A frame's CPU work for `camera` and an output of `extent`, in frame slot `slot` (whose
    /// previous frame the GPU has finished): cull and pick LODs (`self.visibility`), decide
    /// which passes have work, batch the draw lists into the slot's instance stream, upload the
    /// particles and boids, and write the uniforms. `record` follows.
    #[allow(clippy::too_many_arguments)]
    pub fn prepare(&mut self, gpu: &Gpu, slot: usize, scene: &GpuScene, camera: &Camera, lighting: &Lighting, extent: vk::Extent2D) -> Result<()> {
        // The slot's last frame is finished: its GPU time at its scale sets this one's.
        if self.scale_feedback && matches!(self.render_scale.mode, RenderScale::Adaptive { .. }) {
            if let Some(p) = self.graph.profile(gpu, slot) {
                self.render_scale.observe(self.slot_scale[slot], p.total_ms() as f32);
            }
        }
        // The depth view shows the depth buffer as it is, at the output's size.
        let scale = if self.depth_view { 1.0 } else { self.render_scale.scale() };
        self.slot_scale[slot] = scale;
        let render = ScaleController::render_extent(scale, extent);
        (self.frame.scale, self.frame.render) = (scale, render);
        let aspect = extent.width as f32 / extent.height as f32;
        let view_proj = camera.view_proj(aspect);
        // LOD error is measured in the pixels the frame is drawn at (Nanite's choice too): below
        // the output's size, detail finer than a render pixel is lost to the scale anyway, and a
        // character 20 render pixels tall no longer draws four triangles a pixel (skinned-64 at
        // scale 0.5: 0.69x the frame time of LODs picked at the output's size).
        self.visibility.update(scene, view_proj, camera.position, camera.fov_y, render.height as f32);
        let f = &mut self.frame;
        // Skipped when empty: nothing to blend, and the depth need not be stored for it.
        f.draw_particles = !self.particles.is_empty();
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
        f.draw_boids = boids.visible > 0;
        self.boids.upload(gpu, slot)?;
        // The shadow map serves dynamic objects lit by a physical sun: skip it when none is in
        // view (and lavapipe 22.3 crashes on a depth-only rendering without draws).
        let sun = scene.baked.filter(|b| b.sun_lux.max_element() > 0.0);
        let dynamic_in_view = self.visibility.draws.iter().any(|dr| !scene.instances[dr.instance as usize].is_static);
        f.draw_shadow = match sun {
            Some(b) if dynamic_in_view && !scene.instances.is_empty() => {
                self.shadow.prepare(scene, b.sun_dir);
                // Nothing casts (only BLEND surfaces): no map (and no rendering without draws).
                !self.shadow.casters.is_empty()
            }
            _ => false,
        };
        let s = &self.shadow;
        (self.shadow_casters, self.shadow_casters_drawn) = match f.draw_shadow {
            false => (0, 0),
            true if s.static_casters.is_empty() => (s.casters.len() as u32, s.casters.len() as u32),
            true => (s.casters.len() as u32, (s.dynamic_casters.len() + if s.redraw_static { s.static_casters.len() } else { 0 }) as u32),
        };
        // The camera's draw list and the shadow map's as instanced batches, in the slot's
        // instance stream (the pre-pass and the shading pass share the camera's).
        self.batcher.clear();
        // Lightmaps are read when there are baked pages and they are switched on.
        let mode = BatchMode { instancing: self.instancing, lightmaps: self.lightmaps && scene.baked.is_some() };
        let anim = self.animation.as_ref();
        // The opaque phase draws the draws with an opaque submesh; the transparent phase those
        // with a BLEND one, one call each, far to near by the view depth of their bounding
        // sphere's centre. (Only a scene with a BLEND material pays for the split.)
        if scene.materials.iter().any(|m| m.blend) {
            let opaque: Vec<Draw> = self.visibility.draws.iter().filter(|d| has_submesh(scene, d, false)).copied().collect();
            self.batcher.batch(scene, anim, slot, &opaque, mode, &mut f.view_batches);
            if self.transparency {
                let blended = sort_back_to_front(scene, &self.visibility.draws, camera);
                self.batcher.batch(scene, anim, slot, &blended, BatchMode { instancing: false, ..mode }, &mut f.transparent_batches);
            } else {
                f.transparent_batches.clear();
            }
        } else {
            self.batcher.batch(scene, anim, slot, &self.visibility.draws, mode, &mut f.view_batches);
            f.transparent_batches.clear();
        }
        // Depth only: lightmapped or not, the casters of one mesh share a call.
        let casters_mode = BatchMode { lightmaps: false, ..mode };
        let sb = &mut f.shadow;
        for list in [&mut sb.all, &mut sb.statics, &mut sb.dynamics] {
            list.clear();
        }
        if f.draw_shadow {
            if s.static_casters.is_empty() {
                self.batcher.batch(scene, anim, slot, &s.casters, casters_mode, &mut sb.all);
            } else {
                if s.redraw_static {
                    self.batcher.batch(scene, anim, slot, &s.static_casters, casters_mode, &mut sb.statics);
                }
                self.batcher.batch(scene, anim, slot, &s.dynamic_casters, casters_mode, &mut sb.dynamics);
            }
        }
        self.instance_buffers.write(gpu, slot, self.batcher.stream_bytes())?;
        f.instances = self.instance_buffers.get(slot).map_or(vk::Buffer::null(), |b| b.buffer);
        f.frame_set = self.frame_sets[slot];
        f.camera_right = camera.right();
        f.camera_up = camera.right().cross(camera.forward());

        let shadow_params = Vec4::new(f.draw_shadow as u32 as f32, self.shadow.texel_m, 1.0 / self.shadow.size as f32, 0.0);
        // A baked scene is lit by its lightmaps, probes and sun in physical units, exposed and
        // tone-mapped; otherwise the stand-in `lighting`.
        let (sun_dir, sun_color, ambient, exposure) = match scene.baked {
            Some(b) => (b.sun_dir, b.sun_lux, Vec3::ZERO, Vec4::new(b.exposure, 1.0, 0.0, 0.0)),
            None => (lighting.sun_dir.normalize(), lighting.sun_color, lighting.ambient, Vec4::new(1.0, 0.0, 0.0, 0.0)),
        };
        let uniforms = FrameUniforms {
            view_proj,
            sun_view_proj: self.shadow.view_proj,
            camera_pos: camera.position.extend(1.0),
            sun_dir: sun_dir.extend(0.0),
            sun_color: sun_color.extend(0.0),
            ambient: ambient.extend(0.0),
            exposure,
            shadow: shadow_params,
            features: Vec4::new(self.specular as u32 as f32, scale.log2(), 0.0, 0.0),
        };
        (f.exposure, f.tone_map) = (exposure.x, scene.baked.is_some());
        // The tone map that draws the sky runs at the render scale.
        f.sky = scene.baked.filter(|_| self.sky).and_then(|b| SkyParams::of(&b, view_proj, render));
        self.frame_ubos[slot].mapped()[..std::mem::size_of::<FrameUniforms>()].copy_from_slice(bytemuck::bytes_of(&uniforms));
        if f.draw_shadow {
            // The shadow passes run mesh.vert with the sun's transform as its view_proj.
            self.shadow.write_uniforms(slot, bytemuck::bytes_of(&FrameUniforms { view_proj: self.shadow.view_proj, ..uniforms }));
        }
        self.counters[slot].mapped()[..4].copy_from_slice(&0u32.to_le_bytes());
        Ok(())
    }

    /// Record the frame `prepare` made into `cb`, ending in `target`: the frame graph runs the
    /// renderer's passes, then `extra` (the caller's: an overlay, a read-back), then leaves
    /// resources as `finals` asks (the output's `Present`, a read-back buffer's `HostRead`);
    /// without finals the output stays a colour attachment.
    #[allow(clippy::too_many_arguments)]
    pub fn record_prepared(&mut self, gpu: &Gpu, cb: vk::CommandBuffer, slot: usize, scene: &GpuScene, target: &FrameTarget, extra: &mut [&mut dyn Pass], finals: &[(ResourceId, Access)]) -> Result<()> {
        let render = self.frame.render;
        let upscale = render != target.extent;
        // With nothing to draw there is nothing to pre-pass (and lavapipe 22.3 crashes executing a
        // depth-only rendering that has no draws).
        let settings = Settings {
            prepass: self.prepass && !self.frame.view_batches.is_empty(),
            count_fragments: self.count_fragments && self.mesh.can_count(),
            material_maps: self.material_maps,
            directional_lightmaps: scene.directional_lightmaps,
            bicubic_lightmaps: self.bicubic_lightmaps,
            reflection_probes: self.reflections && scene.reflection_probe_count > 0,
            depth_test: self.depth_test,
            depth_view: self.depth_view,
            fxaa: self.aa == AntiAliasing::Fxaa,
            upscale,
            upscaler: self.upscaler,
            samples: self.samples(gpu),
        };
        // A sample count's pipelines are made the first time a frame uses it.
        self.mesh.prepare_samples(gpu, settings.samples)?;
        self.particles.prepare_samples(gpu, settings.samples)?;
        self.boids.prepare_samples(gpu, settings.samples)?;
        self.prepare_lit(gpu, scene, &settings)?;
        let counting = settings.count_fragments;
        self.slot_counted[slot] = counting;
        let mut finals = finals.to_vec();
        if counting {
            finals.push((FRAGMENT_COUNTER, Access::HostRead));
        }
        let mut cx = FrameCx {
            gpu,
            scene,
            slot,
            settings,
            frame: &self.frame,
            draws: &self.visibility.draws,
            mesh: &self.mesh,
            shadow: &self.shadow,
            particles: &self.particles,
            boids: &self.boids,
            tonemap: &mut self.tonemap,
            output: target.extent,
            animation: self.animation.as_mut(),
            draw_calls: 0,
        };
        let output = ImageRef { image: target.color_image, view: target.color_view, format: self.color_format, extent: target.extent };
        let mut passes: Vec<&mut dyn Pass> = self.passes.iter_mut().map(|p| &mut **p as &mut dyn Pass).collect();
        passes.extend(extra.iter_mut().map(|p| &mut **p as &mut dyn Pass));
        self.graph.run(gpu, cb, slot, output, render, &mut cx, &mut passes, &finals)?;
        self.draw_calls = cx.draw_calls;
        Ok(())
    }

    /// Make the lit pipelines every material of `scene` can draw with under `settings` (once
    /// per scene and settings): all of them, not only those in view, so that turning the camera
    /// never stalls a frame on a shader compile.
    fn prepare_lit(&mut self, gpu: &Gpu, scene: &GpuScene, settings: &Settings) -> Result<()> {
        let lightmaps = self.lightmaps && scene.baked.is_some();
        let prepared = (scene.id, *settings, lightmaps);
        if self.lit_prepared == Some(prepared) {
            return Ok(());
        }
        let lightmapped: &[bool] = if lightmaps { &[false, true] } else { &[false] };
        let opaque = if settings.prepass { LitPhase::Equal } else { LitPhase::Plain };
        let keys = scene.materials.iter().flat_map(|m| lightmapped.iter().map(move |&lm| settings.lit_key(if m.blend { LitPhase::Blend } else { opaque }, m, lm)));
        self.mesh.prepare_lit(gpu, settings.samples, keys)?;
        self.lit_prepared = Some(prepared);
        Ok(())
    }

    /// Samples per pixel of the camera's targets: MSAA's where the device has it (1 without). The
    /// depth view shows a single-sampled depth buffer (it samples it as a texture).
    pub fn samples(&self, gpu: &Gpu) -> vk::SampleCountFlags {
        match self.aa {
            AntiAliasing::Msaa if !self.depth_view => gpu.caps.msaa_samples,
            _ => vk::SampleCountFlags::TYPE_1,
        }
    }

    /// `prepare` and `record_prepared` with no passes of the caller's, leaving the output a
    /// colour attachment.
    #[allow(clippy::too_many_arguments)]
    pub fn record(&mut self, gpu: &Gpu, cb: vk::CommandBuffer, slot: usize, scene: &GpuScene, camera: &Camera, lighting: &Lighting, target: &FrameTarget) -> Result<()> {
        self.prepare(gpu, slot, scene, camera, lighting, target.extent)?;
        self.record_prepared(gpu, cb, slot, scene, target, &mut [], &[])
    }

    /// The render scale of the frame last prepared.
    pub fn frame_scale(&self) -> f32 {
        self.frame.scale
    }

    /// The region of the camera's targets the frame last prepared draws (the output's size at
    /// scale 1).
    pub fn render_extent(&self) -> vk::Extent2D {
        self.frame.render
    }

    /// GPU milliseconds and shader invocations of every pass of the frame last recorded in
    /// `slot`, once the GPU has finished it; None when the device can measure neither.
    pub fn profile(&self, gpu: &Gpu, slot: usize) -> Option<FrameProfile> {
        self.graph.profile(gpu, slot)
    }

    /// The renderer's own passes, in frame order (whether or not they run).
    pub fn pass_names(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.passes.iter().map(|p| p.name())
    }

    /// The passes the frame last recorded in `slot` ran, in order.
    pub fn passes_run(&self, slot: usize) -> Vec<&'static str> {
        self.graph.ran(slot)
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

    /// Make every pipeline again from the shaders as they are now (after `shaders::reload`):
    /// the mesh passes' (their layouts kept, so the scene's descriptor sets stay valid), the
    /// particles' and birds', and the post passes (tone map, FXAA, upscale, depth view), made
    /// anew with their own sets. Waits for the device. Skinning's compute pipeline belongs to
    /// the scene's characters (`AnimatedScene`) and keeps its module until they are made again.
    pub fn reload_shaders(&mut self, gpu: &Gpu, frames_in_flight: usize) -> Result<()> {
        gpu.wait_idle();
        let shadow_format = SunShadow::format_for(gpu)?;
        let passes = gpu.own(passes::register(gpu, self.color_format, frames_in_flight)?);
        let mut tonemap = gpu.own(ToneMap::new(gpu, self.color_format, frames_in_flight)?);
        tonemap.saturation = self.tonemap.saturation;
        self.mesh.reload_pipelines(gpu, shadow_format)?;
        self.particles.reload_pipelines(gpu);
        self.boids.reload_pipelines(gpu);
        for p in &mut self.passes {
            p.destroy(gpu);
        }
        self.passes = passes.keep();
        let mut old = std::mem::replace(&mut self.tonemap, tonemap.keep());
        old.destroy(gpu);
        self.lit_prepared = None;
        Ok(())
    }

    /// Fragments the shading pass of the frame last recorded in `slot` shaded, once the GPU has
    /// finished it; None unless that frame counted (`count_fragments` on and the device can).
    pub fn fragment_count(&self, slot: usize) -> Option<u32> {
        self.slot_counted[slot].then(|| u32::from_le_bytes(self.counters[slot].mapped_ref()[..4].try_into().unwrap()))
    }

    /// Take over from `old`, a renderer of a device that was lost, what is not on the device:
    /// its settings, the culling and LOD state (LOD hysteresis), the render scale, this frame's
    /// particles and birds, and the animated characters' playback (when both have them: this
    /// renderer's `animation` is the same pack's, made anew). The shadow map's size needs the
    /// device: `recovery` sets it. The destructuring names every field, so a new one must be
    /// placed on one side or the other here.
    pub fn carry_on_from(&mut self, old: &mut Renderer) {
        let Renderer {
            color_format: _,
            depth_format: _,
            mesh: _,
            graph: _,
            passes: _,
            pool: _,
            frame_ubos: _,
            counters: _,
            frame_sets: _,
            tonemap,
            shadow: _,
            particles,
            boids,
            shadow_casters,
            shadow_casters_drawn,
            instancing,
            draw_calls,
            instance_buffers: _,
            batcher: _,
            frame: _,
            lit_prepared: _,
            prepass,
            count_fragments,
            depth_test,
            lightmaps,
            bicubic_lightmaps,
            reflections,
            depth_view,
            sky,
            material_maps,
            specular,
            transparency,
            aa,
            slot_counted: _,
            visibility,
            render_scale,
            upscaler,
            slot_scale: _,
            scale_feedback,
            animation,
        } = old;
        self.tonemap.saturation = tonemap.saturation;
        self.particles.carry_on_from(particles);
        self.boids.carry_on_from(boids);
        (self.shadow_casters, self.shadow_casters_drawn, self.draw_calls) = (*shadow_casters, *shadow_casters_drawn, *draw_calls);
        (self.instancing, self.prepass, self.count_fragments, self.depth_test) = (*instancing, *prepass, *count_fragments, *depth_test);
        (self.lightmaps, self.bicubic_lightmaps, self.reflections, self.depth_view) = (*lightmaps, *bicubic_lightmaps, *reflections, *depth_view);
        (self.sky, self.material_maps, self.specular, self.transparency) = (*sky, *material_maps, *specular, *transparency);
        (self.aa, self.upscaler, self.scale_feedback) = (*aa, *upscaler, *scale_feedback);
        std::mem::swap(&mut self.visibility, visibility);
        std::mem::swap(&mut self.render_scale, render_scale);
        if let (Some(new), Some(old)) = (self.animation.as_mut(), animation.as_mut()) {
            new.carry_on_from(old);
        }
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        for b in self.frame_ubos.iter_mut().chain(self.counters.iter_mut()) {
            b.destroy(gpu);
        }
        for p in &mut self.passes {
            p.destroy(gpu);
        }
        self.graph.destroy(gpu);
        self.tonemap.destroy(gpu);
        self.particles.destroy(gpu);
        self.boids.destroy(gpu);
        self.instance_buffers.destroy(gpu);
        self.shadow.destroy(gpu);
        self.mesh.destroy(gpu);
        if let Some(a) = &mut self.animation {
            a.destroy(gpu);
        }
        unsafe { gpu.device.destroy_descriptor_pool(self.pool, None) };
    }
}

/// Point binding 2 of a frame set (set 0) at the sun's shadow map.
fn write_shadow_map_descriptor(gpu: &Gpu, set: vk::DescriptorSet, shadow: &SunShadow) {
    let info = [vk::DescriptorImageInfo { sampler: shadow.sampler, image_view: shadow.view(), image_layout: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL }];
    let write = vk::WriteDescriptorSet::default().dst_set(set).dst_binding(2).descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER).image_info(&info);
    unsafe { gpu.device.update_descriptor_sets(&[write], &[]) };
}

/// The draws of `draws` whose mesh has a BLEND material (or whose instance overrides its
/// material with one), far to near along the camera's view direction.
fn sort_back_to_front(scene: &GpuScene, draws: &[Draw], camera: &Camera) -> Vec<Draw> {
    let forward = camera.forward();
    let spheres = scene.instances.spheres();
    let mut out: Vec<(f32, Draw)> = draws.iter().filter(|d| has_submesh(scene, d, true)).map(|d| ((Vec3::new(spheres.x[d.instance as usize], spheres.y[d.instance as usize], spheres.z[d.instance as usize]) - camera.position).dot(forward), *d)).collect();
    out.sort_by(|a, b| b.0.total_cmp(&a.0));
    out.into_iter().map(|(_, d)| d).collect()
}

/// Whether draw `d` has a submesh whose material is BLEND (`blend`) or not.
fn has_submesh(scene: &GpuScene, d: &Draw, blend: bool) -> bool {
    let inst = &scene.instances[d.instance as usize];
    let mesh = &scene.meshes[inst.mesh as usize];
    mesh.lods[d.lod as usize].submeshes.iter().any(|sm| scene.materials[inst.material.unwrap_or(sm.material) as usize].blend == blend)
}

/// How the frame is anti-aliased.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AntiAliasing {
    #[default]
    Off,
    /// 4x MSAA: the camera's passes draw multisampled colour and depth (alpha-tested materials
    /// with alpha-to-coverage), resolved before the tone map.
    Msaa,
    /// Lottes' FXAA on the tone-mapped frame (one full-screen pass).
    Fxaa,
}

impl AntiAliasing {
    pub const ALL: [AntiAliasing; 3] = [AntiAliasing::Off, AntiAliasing::Msaa, AntiAliasing::Fxaa];

    /// The name the command line and the overlay use.
    pub fn name(self) -> &'static str {
        match self {
            AntiAliasing::Off => "off",
            AntiAliasing::Msaa => "msaa",
            AntiAliasing::Fxaa => "fxaa",
        }
    }
}

impl std::str::FromStr for AntiAliasing {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        AntiAliasing::ALL.into_iter().find(|a| a.name() == s).ok_or_else(|| format!("'{s}' is not an anti-aliasing mode (off, msaa, fxaa)"))
    }
}
