//! Boids drawn as instanced meshes (issue 8): every bird of a flock is one instance of the mesh
//! its spawn names (the cooker packs the boids spawn's `asset` and sets its `mesh`), oriented by
//! `sim::boids::boid_rotation` (heading plus banking roll), frustum-culled with the same test as
//! the scene's instances (their counts go into the frame's cull counters).
//!
//! Drawn in a rendering instance of its own right after the opaque shading pass, depth-tested
//! and depth-writing (so the particle pass after it is hidden behind birds too), from the
//! scene's flock mesh of the bird (`scene::FlockMesh`: full detail, a bird covers a few pixels),
//! each submesh in its material's base colour. The birds are not in the depth pre-pass or the shadow
//! map: they are a few hundred triangles, so the pre-pass would save nothing, and a bird's shadow
//! on the ground is a few pixels.

use crate::render::cull::{Class, CullCounts, Frustum};
use crate::gpu::{opaque, Gpu, GraphicsPipeline, PerSamples, SlotBuffers};
use crate::render::graph::{ImageRef, Rec, Rendering};
use crate::scene::GpuScene;
use crate::render::shaders;
use crate::sim::boids::{boid_rotation, Flock};
use crate::render::tonemap::HDR_FORMAT;
use anyhow::Result;
use ash::vk;
use glam::Mat4;

/// One flock's birds in the instance list: drawn with scene mesh `mesh`.
#[derive(Debug, Clone, Copy)]
struct Group {
    mesh: u32,
    first: u32,
    count: u32,
}

pub struct BoidsDraw {
    layout: vk::PipelineLayout,
    depth_format: vk::Format,
    /// The bird pipeline per sample count of the camera's targets.
    pipelines: PerSamples<vk::Pipeline>,
    /// Instance buffers (model matrices) per frame slot, with their capacity in instances.
    instances: SlotBuffers,
    /// Every drawn boid's model matrix this frame (`fill`), and the ones in view (`cull`).
    pub boids: Vec<Mat4>,
    /// The flock each of `boids` belongs to, as runs (a flock's birds are consecutive), and the
    /// bounding radius of its mesh.
    groups: Vec<(Group, f32)>,
    visible: Vec<Mat4>,
    visible_groups: Vec<Group>,
}

impl BoidsDraw {
    /// `frame_layout` is the renderer's set 0 (view_proj, sun and exposure).
    pub fn new(gpu: &Gpu, frame_layout: vk::DescriptorSetLayout, depth_format: vk::Format, frames_in_flight: usize) -> Result<BoidsDraw> {
        let d = &gpu.device;
        let set_layouts = [frame_layout];
        // The submesh's base colour (linear RGBA) for the fragment shader.
        let push = [vk::PushConstantRange::default().stage_flags(vk::ShaderStageFlags::FRAGMENT).size(16)];
        let layout = unsafe { d.create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts).push_constant_ranges(&push), None)? };
        Ok(BoidsDraw {
            layout,
            depth_format,
            pipelines: PerSamples::default(),
            instances: SlotBuffers::new("boid instances", vk::BufferUsageFlags::VERTEX_BUFFER, frames_in_flight, 64 * 64),
            boids: Vec::new(),
            groups: Vec::new(),
            visible: Vec::new(),
            visible_groups: Vec::new(),
        })
    }

    /// Replace this frame's instances with every boid of `flocks`, flock `i` drawn with
    /// `scene`'s mesh `meshes[i]`. A flock without a mesh (None, or one no boids spawn of the
    /// scene's pack names, so it has no flock mesh) is simulated but not drawn.
    pub fn fill(&mut self, scene: &GpuScene, flocks: &[Flock], meshes: &[Option<u32>]) {
        self.boids.clear();
        self.groups.clear();
        for (f, mesh) in flocks.iter().zip(meshes) {
            let Some((mesh, m)) = mesh.and_then(|i| Some((i, scene.flock_mesh(i)?))) else { continue };
            let radius = m.radius;
            let s = f.state();
            let first = self.boids.len() as u32;
            for i in 0..s.len() {
                self.boids.push(Mat4::from_rotation_translation(boid_rotation(s.velocity(i), s.roll[i]), s.position(i)));
            }
            self.groups.push((Group { mesh, first, count: s.len() as u32 }, radius));
        }
    }

    /// Frustum-cull the boids (bounding spheres, as `cull::cull_spheres` does for the scene);
    /// returns the counts to add to the frame's.
    pub fn cull(&mut self, view_proj: Mat4) -> CullCounts {
        let frustum = Frustum::from_view_proj(view_proj);
        let mut counts = CullCounts {
            tested: self.boids.len() as u32,
            ..Default::default()
        };
        self.visible.clear();
        self.visible_groups.clear();
        for &(g, radius) in &self.groups {
            let first = self.visible.len() as u32;
            for m in &self.boids[g.first as usize..(g.first + g.count) as usize] {
                match frustum.classify_sphere(m.w_axis.truncate(), radius) {
                    Class::Outside => counts.culled += 1,
                    class => {
                        counts.visible += 1;
                        counts.inside += (class == Class::Inside) as u32;
                        self.visible.push(*m);
                    }
                }
            }
            let count = self.visible.len() as u32 - first;
            if count > 0 {
                self.visible_groups.push(Group { mesh: g.mesh, first, count });
            }
        }
        counts
    }

    /// Boids in view after the last `cull`: the instances the next `record` draws.
    pub fn visible_count(&self) -> usize {
        self.visible.len()
    }

    /// Copy the visible boids into `slot`'s instance buffer; the GPU must be done with that slot.
    pub fn upload(&mut self, gpu: &Gpu, slot: usize) -> Result<()> {
        if self.visible.is_empty() {
            return Ok(());
        }
        // Mat4 is 16 plain f32s, column-major, as the shader reads it.
        self.instances.write(gpu, slot, bytemuck::cast_slice(&self.visible))
    }

    /// Make the pipeline for targets of `samples` samples if no frame has used it yet.
    pub fn prepare_samples(&mut self, gpu: &Gpu, samples: vk::SampleCountFlags) -> Result<()> {
        let (layout, depth_format) = (self.layout, self.depth_format);
        self.pipelines.ensure(samples, |samples| create_pipeline(gpu, layout, depth_format, samples))?;
        Ok(())
    }

    /// Draw the uploaded visible boids with `scene`'s flock meshes into `hdr` over `depth` (loaded
    /// and stored; both of `samples` samples, which `prepare_samples` made a pipeline for). Call
    /// only with boids in view: lavapipe 22.3 crashes on a depth-writing rendering without draws.
    pub fn record(&self, rec: &Rec, scene: &GpuScene, frame_set: vk::DescriptorSet, hdr: ImageRef, depth: ImageRef, samples: vk::SampleCountFlags) {
        let (d, cb) = (&rec.gpu.device, rec.cb);
        let pipeline = *self.pipelines.get(samples);
        let Some(buffer) = self.instances.get(rec.slot) else { return };
        rec.begin_rendering(&Rendering::color(hdr, None).depth(depth, None, vk::AttachmentStoreOp::STORE));
        unsafe {
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, pipeline);
            d.cmd_bind_descriptor_sets(cb, vk::PipelineBindPoint::GRAPHICS, self.layout, 0, &[frame_set], &[]);
            for g in &self.visible_groups {
                let Some(mesh) = scene.flock_mesh(g.mesh) else { continue };
                d.cmd_bind_vertex_buffers(cb, 0, &[mesh.vertices.buffer, buffer.buffer], &[0, 0]);
                for &(first, count, colour) in &mesh.parts {
                    d.cmd_push_constants(cb, self.layout, vk::ShaderStageFlags::FRAGMENT, 0, bytemuck::bytes_of(&colour));
                    d.cmd_draw(cb, count, g.count, first, g.first);
                }
            }
        }
        rec.end_rendering();
    }

    /// Drop the pipelines (the shaders were reloaded): `prepare_samples` makes them again from
    /// the new modules.
    pub fn reload_pipelines(&mut self, gpu: &Gpu) {
        unsafe {
            for pipeline in self.pipelines.drain() {
                gpu.device.destroy_pipeline(pipeline, None);
            }
        }
    }

    /// This frame's birds, from the pass of a lost device (`Renderer::carry_on_from`).
    pub fn carry_on_from(&mut self, old: &mut BoidsDraw) {
        std::mem::swap(&mut self.boids, &mut old.boids);
        std::mem::swap(&mut self.groups, &mut old.groups);
        std::mem::swap(&mut self.visible, &mut old.visible);
        std::mem::swap(&mut self.visible_groups, &mut old.visible_groups);
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        self.instances.destroy(gpu);
        unsafe {
            for pipeline in self.pipelines.drain() {
                gpu.device.destroy_pipeline(pipeline, None);
            }
            gpu.device.destroy_pipeline_layout(self.layout, None);
        }
    }
}

/// The bird pipeline: the flock mesh's (position, normal) corners (binding 0) and per-instance
/// model matrices (binding 1), no culling (single-triangle wings), reversed-Z depth test and
/// write.
fn create_pipeline(gpu: &Gpu, layout: vk::PipelineLayout, depth_format: vk::Format, samples: vk::SampleCountFlags) -> Result<vk::Pipeline> {
    let bindings = [
        vk::VertexInputBindingDescription {
            binding: 0,
            stride: 24,
            input_rate: vk::VertexInputRate::VERTEX,
        },
        vk::VertexInputBindingDescription {
            binding: 1,
            stride: 64,
            input_rate: vk::VertexInputRate::INSTANCE,
        },
    ];
    let f3 = vk::Format::R32G32B32_SFLOAT;
    let f4 = vk::Format::R32G32B32A32_SFLOAT;
    let attributes = [
        vk::VertexInputAttributeDescription {
            location: 0,
            binding: 0,
            format: f3,
            offset: 0,
        },
        vk::VertexInputAttributeDescription {
            location: 1,
            binding: 0,
            format: f3,
            offset: 12,
        },
        vk::VertexInputAttributeDescription {
            location: 2,
            binding: 1,
            format: f4,
            offset: 0,
        },
        vk::VertexInputAttributeDescription {
            location: 3,
            binding: 1,
            format: f4,
            offset: 16,
        },
        vk::VertexInputAttributeDescription {
            location: 4,
            binding: 1,
            format: f4,
            offset: 32,
        },
        vk::VertexInputAttributeDescription {
            location: 5,
            binding: 1,
            format: f4,
            offset: 48,
        },
    ];
    GraphicsPipeline::new("boid", shaders::BOID_VERT.spv())
        .fragment(shaders::BOID_FRAG.spv(), None)
        .vertex_input(&bindings, &attributes)
        .depth(depth_format, true, vk::CompareOp::GREATER_OR_EQUAL)
        .color(HDR_FORMAT, opaque())
        .multisample(samples)
        .build(gpu, layout)
}
