//! The sun's shadow map for dynamic objects. Static geometry has the sun baked into its
//! lightmaps (shadows included); dynamic objects need to know whether the sun reaches them at
//! their current place, which the probes' sun visibility only approximates on a coarse grid.
//!
//! Drawn by the shadow passes (`render/passes/shadow_*.rs`). One depth-only rendering from the sun: an orthographic projection fitted to the bounding sphere of
//! the scene (a sphere does not change size as the sun turns), with the window snapped to whole
//! texels in a light basis that depends on the sun direction only, so that a moving object does
//! not make the shadow edges of everything else crawl. It draws every opaque instance, static and
//! dynamic, with culling off (single-sided occluders such as a roof quad cast from either side)
//! and a slope-scaled depth bias. The shading pass reads it through a comparison sampler (PCF).
//!
//! The static casters (the level, most of the triangles) are drawn into a map of their own that
//! is kept between frames; each frame copies it into the map and draws only the dynamic casters
//! on top. It is drawn again only when something it depends on changes: the scene, the map's
//! window or size, or a static caster's transform or LOD (`prepare` hashes them all).

use crate::gpu::{Buffer, Gpu, Image};
use crate::render::graph::ImageRef;
use crate::scene::GpuScene;
use crate::render::visibility::Draw;
use anyhow::Result;
use ash::vk;
use glam::{Mat3, Mat4, Vec3, Vec4};
use gpu_allocator::MemoryLocation;
use std::hash::{Hash, Hasher};

/// Shadow map width and height in texels unless set otherwise (`Renderer::set_shadow_map_size`).
pub const DEFAULT_SHADOW_MAP_SIZE: u32 = 2048;

/// Rasteriser depth bias of the shadow pass: a constant (in units of the depth format's
/// resolution) and a factor of the depth slope per texel. The shading samples up to ~2 texels
/// away from the lookup point (3x3 taps of a 2x2 filter), so a surface's own depth must clear the
/// map by about two texels' worth of its slope; the normal offset in the shader does the rest.
pub const DEPTH_BIAS_CONSTANT: f32 = 2.0;
pub const DEPTH_BIAS_SLOPE: f32 = 2.0;

/// Orthographic world -> shadow-map transform for a sun in direction `towards_sun` (unit, from
/// the scene to the sun) and a scene inside the box `lo..hi`: x, y in [-1, 1] across the map,
/// depth z in [0, 1] with 0 nearest the sun. Returns it with the size of one texel in metres.
pub fn sun_view_proj(towards_sun: Vec3, lo: Vec3, hi: Vec3, size: u32) -> (Mat4, f32) {
    let w = towards_sun.normalize();
    // Light basis: a rotation from the sun direction alone (never the scene's position), so a
    // translated window moves the texel grid by whole texels after snapping.
    let up = if w.y.abs() > 0.99 { Vec3::X } else { Vec3::Y };
    let u = up.cross(w).normalize();
    let v = w.cross(u);
    let light = Mat3::from_cols(u, v, w).transpose();
    let centre = light * ((lo + hi) * 0.5);
    // The radius is rounded up to steps of 2^(1/8) (9%), so dynamic objects moving about the
    // scene change the texel size rarely rather than every frame.
    let r = ((hi - lo).length() * 0.5).max(1e-3);
    let r = 2f32.powf((r.log2() * 8.0).ceil() / 8.0);
    let texel = 2.0 * r / size as f32;
    let cx = (centre.x / texel).round() * texel;
    let cy = (centre.y / texel).round() * texel;
    // Light space looks down -w: larger z is nearer the sun. depth = (near_z - z) / 2r.
    let near_z = centre.z + r;
    let proj = Mat4::from_cols(
        Vec4::new(1.0 / r, 0.0, 0.0, 0.0),
        Vec4::new(0.0, 1.0 / r, 0.0, 0.0),
        Vec4::new(0.0, 0.0, -0.5 / r, 0.0),
        Vec4::new(-cx / r, -cy / r, near_z * 0.5 / r, 1.0),
    );
    (proj * Mat4::from_mat3(light), texel)
}

/// The coarsest LOD whose error (object-space `errors`, world metres through `scale`) stays
/// within one shadow-map texel: finer detail would not change the map.
pub fn shadow_lod(errors: &[f32], scale: f32, texel_m: f32) -> usize {
    errors.iter().rposition(|&e| e * scale <= texel_m).unwrap_or(0)
}

pub struct SunShadow {
    /// Width and height of the map in texels.
    pub size: u32,
    pub format: vk::Format,
    image: Image,
    /// Comparison sampler (LESS_OR_EQUAL: lit where the point is no farther than the map's
    /// depth), linear where the format allows (hardware 2x2 PCF), white border (lit outside).
    pub sampler: vk::Sampler,
    /// This frame's world -> map transform and texel size in metres.
    pub view_proj: Mat4,
    pub texel_m: f32,
    /// This frame's casters: every instance at its shadow LOD.
    pub casters: Vec<Draw>,
    /// The same split: static instances (`Instance::is_static`), and the rest.
    pub static_casters: Vec<Draw>,
    pub dynamic_casters: Vec<Draw>,
    /// The static casters' depth alone, copied into `image` every frame.
    static_image: Image,
    /// Hash of what `static_image` was drawn from (None: never drawn, or stale after a resize).
    static_key: Option<u64>,
    /// Whether this frame draws `static_image` again (`prepare` decides).
    pub redraw_static: bool,
    /// Times `static_image` has been drawn.
    pub static_draws: u64,
    /// Per frame slot: uniforms whose `view_proj` is the sun's (what mesh.vert transforms by),
    /// and the set 0 that binds them for the shadow pass.
    ubos: Vec<Buffer>,
    pub sets: Vec<vk::DescriptorSet>,
    pool: vk::DescriptorPool,
}

impl SunShadow {
    /// A `size`-square map; `frame_layout` is the renderer's set 0 layout (its binding 0 is the
    /// uniform buffer of `ubo_size` bytes, the only binding the depth-only pipelines read; this
    /// writes binding 0 of `sets`, the renderer the others).
    pub fn new(gpu: &Gpu, frame_layout: vk::DescriptorSetLayout, ubo_size: u64, frames_in_flight: usize, size: u32) -> Result<SunShadow> {
        let d = &gpu.device;
        let (format, linear) = pick_format(gpu)?;
        // Owned until the shadow is whole: an error frees what was made before it.
        let image = gpu.own(create_map(gpu, format, size)?);
        let static_image = gpu.own(create_static_map(gpu, format, size)?);
        let filter = if linear { vk::Filter::LINEAR } else { vk::Filter::NEAREST };
        let sampler = gpu.own(unsafe {
            d.create_sampler(
                &vk::SamplerCreateInfo::default()
                    .mag_filter(filter)
                    .min_filter(filter)
                    .mipmap_mode(vk::SamplerMipmapMode::NEAREST)
                    .address_mode_u(vk::SamplerAddressMode::CLAMP_TO_BORDER)
                    .address_mode_v(vk::SamplerAddressMode::CLAMP_TO_BORDER)
                    .address_mode_w(vk::SamplerAddressMode::CLAMP_TO_BORDER)
                    .border_color(vk::BorderColor::FLOAT_OPAQUE_WHITE)
                    .compare_enable(true)
                    .compare_op(vk::CompareOp::LESS_OR_EQUAL),
                None,
            )?
        });
        let n = frames_in_flight as u32;
        // The renderer's set 0 layout: uniforms, the fragment counter, the shadow map.
        let sizes = [
            vk::DescriptorPoolSize {
                ty: vk::DescriptorType::UNIFORM_BUFFER,
                descriptor_count: n,
            },
            vk::DescriptorPoolSize {
                ty: vk::DescriptorType::STORAGE_BUFFER,
                descriptor_count: n,
            },
            vk::DescriptorPoolSize {
                ty: vk::DescriptorType::COMBINED_IMAGE_SAMPLER,
                descriptor_count: n,
            },
        ];
        let pool = gpu.own(unsafe { d.create_descriptor_pool(&vk::DescriptorPoolCreateInfo::default().max_sets(n).pool_sizes(&sizes), None)? });
        let mut ubos = gpu.own(Vec::new());
        let mut sets = Vec::new();
        for _ in 0..frames_in_flight {
            ubos.push(Buffer::new(gpu, "sun shadow uniforms", ubo_size, vk::BufferUsageFlags::UNIFORM_BUFFER, MemoryLocation::CpuToGpu)?);
            let ubo = ubos.last().unwrap();
            let layouts = [frame_layout];
            let set = unsafe { d.allocate_descriptor_sets(&vk::DescriptorSetAllocateInfo::default().descriptor_pool(*pool).set_layouts(&layouts))?[0] };
            let info = [vk::DescriptorBufferInfo {
                buffer: ubo.buffer,
                offset: 0,
                range: vk::WHOLE_SIZE,
            }];
            let write = vk::WriteDescriptorSet::default()
                .dst_set(set)
                .dst_binding(0)
                .descriptor_type(vk::DescriptorType::UNIFORM_BUFFER)
                .buffer_info(&info);
            unsafe { d.update_descriptor_sets(&[write], &[]) };
            sets.push(set);
        }
        Ok(SunShadow {
            size,
            format,
            image: image.keep(),
            sampler: sampler.keep(),
            view_proj: Mat4::IDENTITY,
            texel_m: 1.0,
            casters: Vec::new(),
            static_casters: Vec::new(),
            dynamic_casters: Vec::new(),
            static_image: static_image.keep(),
            static_key: None,
            redraw_static: false,
            static_draws: 0,
            ubos: ubos.keep(),
            sets,
            pool: pool.keep(),
        })
    }

    /// The depth format maps are made in on this device.
    pub fn format_for(gpu: &Gpu) -> Result<vk::Format> {
        pick_format(gpu).map(|(format, _)| format)
    }

    pub fn view(&self) -> vk::ImageView {
        self.image.view
    }

    /// A new map of `size` texels square. The caller makes sure no frame in flight uses the old
    /// one and points its descriptors at `view()` again.
    pub fn resize(&mut self, gpu: &Gpu, size: u32) -> Result<()> {
        let image = gpu.own(create_map(gpu, self.format, size)?);
        let static_image = create_static_map(gpu, self.format, size)?;
        let image = image.keep();
        self.image.destroy(gpu);
        self.static_image.destroy(gpu);
        (self.image, self.static_image, self.static_key) = (image, static_image, None);
        self.size = size;
        Ok(())
    }

    /// Fit the map to the scene for a sun towards `towards_sun` and list the casters: every
    /// instance at its shadow LOD, split into static and dynamic; and decide whether the static
    /// part must be drawn again. The static list is rebuilt only when it would change (the
    /// scene, its static version, the map's window or size), so a frame costs O(dynamic) here.
    pub fn prepare(&mut self, scene: &GpuScene, towards_sun: Vec3) {
        let (lo, hi) = scene.bounds();
        (self.view_proj, self.texel_m) = sun_view_proj(towards_sun, lo, hi, self.size);
        let mut key = std::collections::hash_map::DefaultHasher::new();
        (scene.id, scene.instances.static_version(), self.size, self.view_proj.to_cols_array().map(f32::to_bits)).hash(&mut key);
        let key = Some(key.finish());
        let caster = |i: u32| {
            let inst = &scene.instances[i as usize];
            Draw { instance: i, lod: shadow_lod(&scene.meshes[inst.mesh as usize].errors, inst.scale, self.texel_m) as u8 }
        };
        // BLEND surfaces cast no shadow (a glass pane would cast a full one): an instance with
        // nothing else is no caster, and no depth-only rendering is left without draws.
        let casts = |i: &u32| {
            let inst = &scene.instances[*i as usize];
            scene.meshes[inst.mesh as usize].lods[0].submeshes.iter().any(|sm| !scene.materials[inst.material.unwrap_or(sm.material) as usize].blend)
        };
        let statics_changed = key != self.static_key;
        if statics_changed {
            self.static_casters.clear();
            self.static_casters.extend((0..scene.instances.len() as u32).filter(|&i| scene.instances[i as usize].is_static).filter(casts).map(caster));
        }
        self.dynamic_casters.clear();
        self.dynamic_casters.extend(scene.instances.dynamic().iter().copied().filter(casts).map(caster));
        self.casters.clear();
        self.casters.extend_from_slice(&self.static_casters);
        self.casters.extend_from_slice(&self.dynamic_casters);
        self.redraw_static = !self.static_casters.is_empty() && statics_changed;
        if statics_changed {
            self.static_key = key;
        }
        if self.redraw_static {
            self.static_draws += 1;
        }
    }

    /// The shadow pass's uniforms for frame slot `slot` (bytes of the renderer's `FrameUniforms`).
    pub fn write_uniforms(&mut self, slot: usize, bytes: &[u8]) {
        self.ubos[slot].mapped()[..bytes.len()].copy_from_slice(bytes);
    }

    /// The map, as the frame graph imports it (the shadow passes draw it, the shading pass samples it).
    pub fn map_ref(&self) -> ImageRef {
        image_ref(&self.image)
    }

    /// The static casters' cached depth, as the frame graph imports it.
    pub fn cache_ref(&self) -> ImageRef {
        image_ref(&self.static_image)
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        for b in &mut self.ubos {
            b.destroy(gpu);
        }
        self.image.destroy(gpu);
        self.static_image.destroy(gpu);
        unsafe {
            gpu.device.destroy_descriptor_pool(self.pool, None);
            gpu.device.destroy_sampler(self.sampler, None);
        }
    }
}

/// A depth format the map can be rendered into and sampled from with a comparison: 32-bit float
/// first (the sun's depth range spans the whole scene), D16 (which every device must offer for
/// both) otherwise. Also whether it filters linearly (hardware PCF).
fn pick_format(gpu: &Gpu) -> Result<(vk::Format, bool)> {
    let need = vk::FormatFeatureFlags::DEPTH_STENCIL_ATTACHMENT
        | vk::FormatFeatureFlags::SAMPLED_IMAGE
        | vk::FormatFeatureFlags::TRANSFER_SRC
        | vk::FormatFeatureFlags::TRANSFER_DST;
    for f in [vk::Format::D32_SFLOAT, vk::Format::D16_UNORM] {
        let p = unsafe { gpu.instance.get_physical_device_format_properties(gpu.physical_device, f) };
        if p.optimal_tiling_features.contains(need) {
            return Ok((f, p.optimal_tiling_features.contains(vk::FormatFeatureFlags::SAMPLED_IMAGE_FILTER_LINEAR)));
        }
    }
    anyhow::bail!("the device has no depth format that can be sampled (for the shadow map)")
}

/// The map image. The shading pass's descriptor points at it in every frame, also in frames that
/// do not draw it (the shader then does not read it): the graph keeps it readable.
fn create_map(gpu: &Gpu, format: vk::Format, size: u32) -> Result<Image> {
    Image::new(
        gpu,
        "sun shadow map",
        format,
        vk::Extent2D { width: size, height: size },
        1,
        vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT | vk::ImageUsageFlags::SAMPLED | vk::ImageUsageFlags::TRANSFER_DST,
        vk::ImageAspectFlags::DEPTH,
    )
}

fn image_ref(i: &Image) -> ImageRef {
    ImageRef { image: i.image, view: i.view, format: i.format, extent: i.extent }
}

/// The static casters' map: rendered, then copied from; never sampled.
fn create_static_map(gpu: &Gpu, format: vk::Format, size: u32) -> Result<Image> {
    Image::new(
        gpu,
        "sun shadow map, static casters",
        format,
        vk::Extent2D { width: size, height: size },
        1,
        vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC,
        vk::ImageAspectFlags::DEPTH,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map_coords(m: Mat4, p: Vec3) -> Vec3 {
        let c = m * p.extend(1.0);
        c.truncate() / c.w
    }

    #[test]
    fn the_scene_box_fits_inside_the_map_and_depth_grows_away_from_the_sun() {
        let sun = Vec3::new(0.3, 0.8, 0.5).normalize();
        let (lo, hi) = (Vec3::new(-10.0, 0.0, -4.0), Vec3::new(6.0, 5.0, 8.0));
        let (m, texel) = sun_view_proj(sun, lo, hi, 1024);
        for i in 0..8 {
            let p = Vec3::new(if i & 1 == 0 { lo.x } else { hi.x }, if i & 2 == 0 { lo.y } else { hi.y }, if i & 4 == 0 { lo.z } else { hi.z });
            let s = map_coords(m, p);
            assert!(s.x.abs() <= 1.0 && s.y.abs() <= 1.0 && (0.0..=1.0).contains(&s.z), "corner {p} -> {s}");
        }
        let centre = (lo + hi) * 0.5;
        let (a, b) = (map_coords(m, centre + sun), map_coords(m, centre - sun));
        assert!(a.z < b.z, "the point nearer the sun must have the smaller depth: {} vs {}", a.z, b.z);
        // Points along the sun direction share a texel; one texel across it is 2/size in NDC.
        assert!((a.truncate() - b.truncate()).abs().max_element() < 1e-5);
        let across = sun.cross(Vec3::Y).normalize() * texel;
        let step = (map_coords(m, centre + across) - map_coords(m, centre)).truncate().length();
        assert!((step - 2.0 / 1024.0).abs() < 1e-5, "one texel is {step} in NDC");
    }

    #[test]
    fn moving_the_scene_moves_the_texel_grid_by_whole_texels() {
        // Stabilisation: a fixed world point keeps its position within its texel when the fitted
        // box slides by less than a texel (and by several), so static shadow edges do not crawl.
        let sun = Vec3::new(-0.4, 0.7, 0.2).normalize();
        let size = 512;
        let (lo, hi) = (Vec3::new(-5.0, 0.0, -5.0), Vec3::new(5.0, 3.0, 5.0));
        let (m0, _) = sun_view_proj(sun, lo, hi, size);
        let p = Vec3::new(1.234, 0.5, -2.345);
        let texel_pos = |m: Mat4| (map_coords(m, p).truncate() * 0.5 + 0.5) * size as f32;
        let frac = |v: glam::Vec2| v - v.round();
        let f0 = frac(texel_pos(m0));
        let mut moved_whole_texels = false;
        for shift in [Vec3::new(0.003, 0.0, 0.001), Vec3::new(0.37, 0.0, -0.21), Vec3::new(2.5, 0.0, 1.75)] {
            let (m, _) = sun_view_proj(sun, lo + shift, hi + shift, size);
            let f = frac(texel_pos(m));
            assert!((f - f0).abs().max_element() < 2e-3, "shift {shift}: texel phase {f} vs {f0}");
            moved_whole_texels |= (texel_pos(m) - texel_pos(m0)).abs().max_element() > 0.5;
        }
        assert!(moved_whole_texels, "the window should follow the scene");
    }

    #[test]
    fn casters_use_the_coarsest_lod_within_a_texel() {
        let errors = [0.0, 0.01, 0.05, 0.3];
        assert_eq!(shadow_lod(&errors, 1.0, 0.02), 1);
        assert_eq!(shadow_lod(&errors, 1.0, 0.06), 2);
        assert_eq!(shadow_lod(&errors, 10.0, 0.06), 0);
        assert_eq!(shadow_lod(&errors, 1.0, 1.0), 3);
    }
}
