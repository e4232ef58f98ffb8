//! Boids drawn as instanced meshes (issue 8): a small procedural bird, one instance per boid
//! oriented by `sim::boids::boid_rotation` (heading plus banking roll), frustum-culled with the
//! same test as the scene's instances (their counts go into the frame's cull counters).
//!
//! Drawn in a rendering instance of its own right after the opaque shading pass, depth-tested
//! and depth-writing (so the particle pass after it is hidden behind birds too). The birds are
//! not in the depth pre-pass or the shadow map: they are a few hundred triangles, so the
//! pre-pass would save nothing, and a dove's shadow on the temple floor is a few pixels.

use crate::cull::{Class, CullCounts, Frustum};
use crate::gpu::{opaque, Buffer, Gpu, GraphicsPipeline, SlotBuffers};
use crate::render::graph::{ImageRef, Rec};
use crate::render::mesh_draw::depth_attachment;
use crate::shaders;
use crate::sim::boids::{boid_rotation, Flock};
use crate::tonemap::HDR_FORMAT;
use anyhow::Result;
use ash::vk;
use glam::{Mat4, Vec3};

/// Bounding radius of the bird mesh at scale 1 (its wing tips are the farthest points).
const MESH_RADIUS: f32 = 0.47;

pub struct BoidsDraw {
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    mesh: Buffer,
    vertex_count: u32,
    /// Instance buffers (model matrices) per frame slot, with their capacity in instances.
    instances: SlotBuffers,
    /// Every boid's model matrix this frame (`fill`), and the ones in view (`cull`).
    pub boids: Vec<Mat4>,
    visible: Vec<Mat4>,
    /// Uniform scale of the bird mesh (1: a 0.55 m long dove with a 0.9 m span).
    pub scale: f32,
}

/// The bird, facing +Z with up +Y (what `boid_rotation` expects): a flat-shaded diamond body,
/// two swept wings raised a little at the tips, and a tail fan. Non-indexed (position, normal).
pub fn bird_mesh() -> Vec<[f32; 6]> {
    let v = Vec3::new;
    let (nose, tail, top, bottom, left, right) = (v(0.0, 0.0, 0.3), v(0.0, 0.0, -0.2), v(0.0, 0.06, 0.0), v(0.0, -0.05, 0.0), v(-0.06, 0.0, 0.0), v(0.06, 0.0, 0.0));
    let mut tris = Vec::new();
    for (a, b) in [(right, top), (top, left), (left, bottom), (bottom, right)] {
        tris.push([nose, a, b]);
        tris.push([tail, b, a]);
    }
    // Wings (one triangle each; the shader lights both sides) and the tail fan.
    tris.push([v(0.04, 0.0, 0.1), v(0.45, 0.06, -0.08), v(0.04, 0.0, -0.1)]);
    tris.push([v(-0.04, 0.0, 0.1), v(-0.04, 0.0, -0.1), v(-0.45, 0.06, -0.08)]);
    tris.push([v(0.0, 0.0, -0.15), v(-0.1, 0.0, -0.25), v(0.1, 0.0, -0.25)]);
    let mut out = Vec::new();
    for [a, b, c] in tris {
        let n = (b - a).cross(c - a).normalize_or(Vec3::Y);
        for p in [a, b, c] {
            out.push([p.x, p.y, p.z, n.x, n.y, n.z]);
        }
    }
    out
}

impl BoidsDraw {
    /// `frame_layout` is the renderer's set 0 (view_proj, sun and exposure).
    pub fn new(gpu: &Gpu, frame_layout: vk::DescriptorSetLayout, depth_format: vk::Format, frames_in_flight: usize) -> Result<BoidsDraw> {
        let d = &gpu.device;
        let set_layouts = [frame_layout];
        let layout = unsafe { d.create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts), None)? };
        let pipeline = create_pipeline(gpu, layout, depth_format)?;
        let verts = bird_mesh();
        // SAFETY: plain f32 arrays.
        let bytes: &[u8] = bytemuck::cast_slice(&verts);
        let mesh = Buffer::with_data(gpu, "bird mesh", bytes, vk::BufferUsageFlags::VERTEX_BUFFER)?;
        Ok(BoidsDraw {
            layout,
            pipeline,
            mesh,
            vertex_count: verts.len() as u32,
            instances: SlotBuffers::new("boid instances", vk::BufferUsageFlags::VERTEX_BUFFER, frames_in_flight, 64 * 64),
            boids: Vec::new(),
            visible: Vec::new(),
            scale: 1.0,
        })
    }

    /// Replace this frame's instances with every boid of `flocks`.
    pub fn fill(&mut self, flocks: &[Flock]) {
        self.boids.clear();
        for f in flocks {
            let s = f.state();
            for i in 0..s.len() {
                self.boids
                    .push(Mat4::from_scale_rotation_translation(Vec3::splat(self.scale), boid_rotation(s.velocity(i), s.roll[i]), s.position(i)));
            }
        }
    }

    /// Frustum-cull the boids (bounding spheres, as `cull::cull_spheres` does for the scene);
    /// returns the counts to add to the frame's.
    pub fn cull(&mut self, view_proj: Mat4) -> CullCounts {
        let frustum = Frustum::from_view_proj(view_proj);
        let radius = MESH_RADIUS * self.scale;
        let mut counts = CullCounts {
            tested: self.boids.len() as u32,
            ..Default::default()
        };
        self.visible.clear();
        for m in &self.boids {
            match frustum.classify_sphere(m.w_axis.truncate(), radius) {
                Class::Outside => counts.culled += 1,
                class => {
                    counts.visible += 1;
                    counts.inside += (class == Class::Inside) as u32;
                    self.visible.push(*m);
                }
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
        let needed = self.visible.len();
        if needed == 0 {
            return Ok(());
        }
        // SAFETY: Mat4 is 16 plain f32s, column-major, as the shader reads it.
        let bytes: &[u8] = bytemuck::cast_slice(&self.visible[..needed]);
        self.instances.write(gpu, slot, bytes)
    }

    /// Draw the uploaded visible boids into `hdr` over `depth` (loaded and stored). Call only
    /// with boids in view: lavapipe 22.3 crashes on a depth-writing rendering without draws.
    pub fn record(&self, rec: &Rec, frame_set: vk::DescriptorSet, hdr: ImageRef, depth: ImageRef) {
        let (d, cb) = (&rec.gpu.device, rec.cb);
        let Some(buffer) = self.instances.get(rec.slot) else { return };
        let color_attachment = [vk::RenderingAttachmentInfo::default()
            .image_view(hdr.view)
            .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
            .load_op(vk::AttachmentLoadOp::LOAD)
            .store_op(vk::AttachmentStoreOp::STORE)];
        let depth_attachment = depth_attachment(depth, None, vk::AttachmentStoreOp::STORE);
        let area = vk::Rect2D { offset: vk::Offset2D::default(), extent: hdr.extent };
        let rendering = vk::RenderingInfo::default().render_area(area).layer_count(1).color_attachments(&color_attachment).depth_attachment(&depth_attachment);
        unsafe {
            d.cmd_begin_rendering(cb, &rendering);
            rec.set_viewport(hdr.extent);
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, self.pipeline);
            d.cmd_bind_descriptor_sets(cb, vk::PipelineBindPoint::GRAPHICS, self.layout, 0, &[frame_set], &[]);
            d.cmd_bind_vertex_buffers(cb, 0, &[self.mesh.buffer, buffer.buffer], &[0, 0]);
            d.cmd_draw(cb, self.vertex_count, self.visible.len() as u32, 0, 0);
            d.cmd_end_rendering(cb);
        }
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        self.instances.destroy(gpu);
        self.mesh.destroy(gpu);
        unsafe {
            gpu.device.destroy_pipeline(self.pipeline, None);
            gpu.device.destroy_pipeline_layout(self.layout, None);
        }
    }
}

/// The bird pipeline: mesh vertices (binding 0) and per-instance model matrices (binding 1),
/// no culling (single-triangle wings), reversed-Z depth test and write.
fn create_pipeline(gpu: &Gpu, layout: vk::PipelineLayout, depth_format: vk::Format) -> Result<vk::Pipeline> {
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
    GraphicsPipeline::new("boid", shaders::BOID_VERT)
        .fragment(shaders::BOID_FRAG, None)
        .vertex_input(&bindings, &attributes)
        .depth(depth_format, true, vk::CompareOp::GREATER_OR_EQUAL)
        .color(HDR_FORMAT, opaque())
        .build(gpu, layout)
}
