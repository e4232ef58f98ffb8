//! What a frame gives its passes: the scene, the renderer's parts they draw with, and this
//! frame's prepared data (culled draws as batches, the instance stream, which passes have work).
//! Prepared on the CPU by `Renderer::prepare` before the graph runs; passes only record.

use crate::anim::animated::AnimatedScene;
use crate::render::batches::Batch;
use crate::render::boids_draw::BoidsDraw;
use crate::gpu::Gpu;
use crate::render::particles_draw::ParticlePass;
use crate::render::graph::{ImageDesc, ResourceId};
use crate::render::tonemap::HDR_FORMAT;
use crate::render::mesh_draw::{LitKey, LitPhase, MeshKit};
use crate::scene::{BakedLighting, GpuMaterial, GpuScene};
use crate::render::shadow::SunShadow;
use crate::render::tonemap::ToneMap;
use crate::render::visibility::Draw;
use ash::vk;
use glam::{Mat4, Vec3, Vec4};

/// The HDR colour target the camera's passes draw (transient, the output's size; with MSAA,
/// multisampled).
pub const HDR: ResourceId = ResourceId("hdr");
/// With MSAA: HDR with each pixel's samples averaged (the `resolve` pass), what the tone map
/// reads.
pub const HDR_RESOLVED: ResourceId = ResourceId("hdr resolved");
/// The camera's depth buffer (transient, the output's size and HDR's samples).
pub const DEPTH: ResourceId = ResourceId("depth");
/// The sun's shadow map (owned by `SunShadow`, imported).
pub const SHADOW_MAP: ResourceId = ResourceId("shadow map");
/// The static casters' part of the shadow map, kept across frames (owned by `SunShadow`).
pub const SHADOW_CACHE: ResourceId = ResourceId("shadow cache");
/// Every skinned vertex buffer (one logical buffer: a memory barrier covers them all).
pub const SKINNED: ResourceId = ResourceId("skinned vertices");
/// The shading pass's fragment counter, read by the host after the frame.
pub const FRAGMENT_COUNTER: ResourceId = ResourceId("fragment counter");
/// The tone-mapped frame before post-process anti-aliasing (transient, the output's size and
/// format), when FXAA is on.
pub const LDR: ResourceId = ResourceId("ldr");
/// The tone-mapped frame at the render scale, gamma 2 in a UNORM image (`LOW_FORMAT`), which the
/// upscaler resamples to the output: when the frame is drawn below the output's size.
pub const LDR_LOW: ResourceId = ResourceId("ldr (render scale)");
/// `LDR_LOW` after FXAA, when it is on below the output's size (the upscaler's input then).
pub const LDR_LOW_AA: ResourceId = ResourceId("ldr (render scale, fxaa)");
/// `LDR_LOW`'s format: 8 bits of sqrt(colour) (shaders/tonemap.frag GAMMA2).
pub const LOW_FORMAT: vk::Format = vk::Format::R8G8B8A8_UNORM;

/// The renderer's switches, as this frame uses them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Depth pre-pass, then shading with depth EQUAL (only when there is something to draw).
    pub prepass: bool,
    /// Count the fragments the shading pass shades (asked for, and the device can).
    pub count_fragments: bool,
    /// Sample the materials' normal, metallic-roughness, occlusion and emissive maps.
    pub material_maps: bool,
    /// The scene's lightmaps are directional (`GpuScene::directional_lightmaps`).
    pub directional_lightmaps: bool,
    /// Lightmaps read through a cubic B-spline (`Renderer::bicubic_lightmaps`).
    pub bicubic_lightmaps: bool,
    /// The scene has reflection probes and the renderer uses them (`Renderer::reflections`).
    pub reflection_probes: bool,
    /// Depth testing in the shading pass without a pre-pass.
    pub depth_test: bool,
    /// Show the depth buffer instead of the shaded frame (a debug view).
    pub depth_view: bool,
    /// Post-process anti-aliasing after the tone map.
    pub fxaa: bool,
    /// The 3D passes draw below the output's size (`FrameCx::render`) and the upscaler
    /// resamples the tone-mapped frame to the output.
    pub upscale: bool,
    /// Its filter.
    pub upscaler: crate::render::scale::Upscaler,
    /// Samples per pixel of the camera's targets (HDR and DEPTH): 1, or 4 with MSAA.
    pub samples: vk::SampleCountFlags,
}

impl Settings {
    /// The lit pipeline a submesh of `material` draws with in `phase` (lit by a lightmap or not).
    pub fn lit_key(&self, phase: LitPhase, material: &GpuMaterial, lightmapped: bool) -> LitKey {
        LitKey {
            phase,
            lightmapped,
            directional: lightmapped && self.directional_lightmaps,
            bicubic: lightmapped && self.bicubic_lightmaps,
            reflections: self.reflection_probes && material.glossy,
            counting: self.count_fragments && phase != LitPhase::Blend,
            slots: material.slots.with_maps(self.material_maps),
        }
    }

    pub fn multisampled(&self) -> bool {
        self.samples != vk::SampleCountFlags::TYPE_1
    }

    /// The camera's colour target as the passes drawing it describe it.
    pub fn hdr_desc(&self) -> ImageDesc {
        ImageDesc::render(HDR_FORMAT).samples(self.samples)
    }

    /// The camera's depth buffer as the passes drawing it describe it.
    pub fn depth_desc(&self, gpu: &Gpu) -> ImageDesc {
        ImageDesc::render(gpu.caps.depth_format).samples(self.samples)
    }

    /// The single-sampled HDR image the tone map reads: HDR, or its resolve.
    pub fn tone_map_input(&self) -> ResourceId {
        if self.multisampled() {
            HDR_RESOLVED
        } else {
            HDR
        }
    }
}

/// The shadow map's draw lists as batches.
#[derive(Default)]
pub struct ShadowBatches {
    /// Every caster (when there are no static casters to cache).
    pub all: Vec<Batch>,
    pub statics: Vec<Batch>,
    pub dynamics: Vec<Batch>,
}

/// This frame's prepared data.
#[derive(Default)]
pub struct FrameData {
    /// The camera's uniforms and the fragment counter (set 0 of the mesh passes).
    pub frame_set: vk::DescriptorSet,
    /// The slot's instance stream every batch indexes.
    pub instances: vk::Buffer,
    pub view_batches: Vec<Batch>,
    /// The transparent phase: the camera's draws with a BLEND material, one batch each, far to
    /// near (their instances follow the camera's in the stream).
    pub transparent_batches: Vec<Batch>,
    pub shadow: ShadowBatches,
    /// The shadow map is drawn this frame (dynamic objects in view under a physical sun).
    pub draw_shadow: bool,
    pub draw_particles: bool,
    pub draw_boids: bool,
    /// The tone map's exposure, and whether it tone-maps (physical lighting) or passes through.
    pub exposure: f32,
    pub tone_map: bool,
    pub camera_right: Vec3,
    pub camera_up: Vec3,
    /// The background's radiance, which the tone map puts behind the frame (a baked level with
    /// a sky or a sun, `Renderer::sky` on).
    pub sky: Option<SkyParams>,
    /// The render scale this frame draws at, and the region of the camera's targets it gives
    /// (`scale::ScaleController::render_extent` of the output's size).
    pub scale: f32,
    pub render: vk::Extent2D,
}

/// The background: the tone map's sky push constants (mirrors shaders/tonemap.frag).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SkyParams {
    /// The view ray through the pixel at framebuffer coordinates (x, y) (gl_FragCoord's) is
    /// `ray[0] + x ray[1] + y ray[2]` (xyz; a perspective camera's rays are affine in screen
    /// coordinates at unit depth): three multiply-adds a pixel instead of unprojecting two
    /// points. w: unused.
    pub ray: [Vec4; 3],
    /// rgb: the sky's radiance (nits).
    pub sky: Vec4,
    /// xyz: toward the sun; w: the cosine of its angular radius.
    pub sun: Vec4,
    /// rgb: the radiance of the sun's disc (nits).
    pub sun_disc: Vec4,
}

/// What every pass records with.
pub struct FrameCx<'a> {
    pub gpu: &'a Gpu,
    pub scene: &'a GpuScene,
    pub slot: usize,
    pub settings: Settings,
    pub frame: &'a FrameData,
    /// The camera's culled draw list (what the batches came from).
    pub draws: &'a [Draw],
    pub mesh: &'a MeshKit,
    pub shadow: &'a SunShadow,
    pub particles: &'a ParticlePass,
    pub boids: &'a BoidsDraw,
    pub tonemap: &'a mut ToneMap,
    /// The output's size (the images of `Size::Render` are made at it; `frame.render` is the
    /// region of them this frame draws).
    pub output: vk::Extent2D,
    pub animation: Option<&'a mut AnimatedScene>,
    /// Draw calls the mesh passes made (passes add theirs).
    pub draw_calls: u32,
}

/// The Sun's angular radius (0.265 degrees), for a sun the level gives as a point.
pub const SUN_ANGULAR_RADIUS: f32 = 0.004_625;

impl SkyParams {
    /// The background of a baked level seen through `view_proj`:
    /// its sky radiance and the sun's disc, whose radiance spreads the sun's illuminance E over
    /// the disc's solid angle 2 pi (1 - cos r). None for a level with neither.
    /// `extent`: the target's size in pixels.
    pub fn of(baked: &BakedLighting, view_proj: Mat4, extent: vk::Extent2D) -> Option<SkyParams> {
        if baked.sky.max_element() <= 0.0 && baked.sun_lux.max_element() <= 0.0 {
            return None;
        }
        let r = if baked.sun_angular_radius > 0.0 { baked.sun_angular_radius } else { SUN_ANGULAR_RADIUS };
        // 1 - cos r without the cancellation: 2 sin^2(r / 2).
        let solid_angle = 2.0 * std::f32::consts::PI * 2.0 * (r * 0.5).sin().powi(2);
        // Rays through NDC (0, 0), (1, 0) and (0, 1) at unit depth along the centre ray.
        let inv = view_proj.inverse();
        let through = |x: f32, y: f32| {
            // Two points along the ray (reverse Z: 1 is the near plane, 0.5 twice as far).
            let (a, b) = (inv.project_point3(Vec3::new(x, y, 1.0)), inv.project_point3(Vec3::new(x, y, 0.5)));
            (b - a).normalize()
        };
        let forward = through(0.0, 0.0);
        let at_unit_depth = |d: Vec3| d / d.dot(forward);
        let (dx, dy) = (at_unit_depth(through(1.0, 0.0)) - forward, at_unit_depth(through(0.0, 1.0)) - forward);
        // NDC from pixels: x_ndc = 2 x / width - 1 (likewise y).
        let (sx, sy) = (2.0 / extent.width.max(1) as f32, 2.0 / extent.height.max(1) as f32);
        let ray = [forward - dx - dy, dx * sx, dy * sy].map(|v| v.extend(0.0));
        Some(SkyParams {
            ray,
            sky: baked.sky.extend(0.0),
            sun: baked.sun_dir.extend(r.cos()),
            sun_disc: (baked.sun_lux / solid_angle).extend(0.0),
        })
    }
}
