//! Instanced drawing for the mesh passes: a draw list becomes batches, runs of instances of one
//! mesh LOD drawn with one instanced call per submesh, their transforms streamed per frame as
//! instance-rate vertex data (with each instance's lightmap region, so placements on different
//! atlas pages share a call). On lavapipe every draw call costs tens of microseconds whatever it
//! draws, so 25 000 visible cubes as 25 000 calls took seconds per frame; as a handful of
//! instanced calls they cost what their triangles cost. A real GPU's driver is spared the same
//! per-call work on the CPU.

use crate::anim::animated::AnimatedScene;
use crate::scene::GpuScene;
use crate::render::visibility::Draw;
use ash::vk;
use glam::{Mat3, Mat4, Vec4};

/// What mesh.vert reads per instance (binding 1): the model matrix (locations 6 to 9), the
/// columns of its normal matrix (xyz, locations 10 to 12; the w of the first is the lightmap
/// page of the instance's region), and the region's uv1 transform (location 14: scale xy,
/// offset xy; zero without a region).
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub struct InstanceData {
    pub model: Mat4,
    pub normal_cols: [Vec4; 3],
    pub lightmap: Vec4,
}

/// Bytes per instance in the instance stream.
pub const INSTANCE_STRIDE: u32 = std::mem::size_of::<InstanceData>() as u32;
const _: () = assert!(INSTANCE_STRIDE == 128);

/// The instance-rate attributes of mesh.vert (binding 1; `InstanceData`). Location 13 is the
/// vertex's texcoord1 (binding 0).
pub fn instance_attributes() -> [vk::VertexInputAttributeDescription; 8] {
    let attribute = |location: u32, offset: usize, format| vk::VertexInputAttributeDescription { location, binding: 1, format, offset: offset as u32 };
    let (vec4, vec3) = (vk::Format::R32G32B32A32_SFLOAT, vk::Format::R32G32B32_SFLOAT);
    let normal = std::mem::offset_of!(InstanceData, normal_cols);
    [
        attribute(6, 0, vec4),
        attribute(7, 16, vec4),
        attribute(8, 32, vec4),
        attribute(9, 48, vec4),
        attribute(10, normal, vec4),
        attribute(11, normal + 16, vec3),
        attribute(12, normal + 32, vec3),
        attribute(14, std::mem::offset_of!(InstanceData, lightmap), vec4),
    ]
}

/// How a draw list becomes batches.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BatchMode {
    /// Draws of one mesh LOD share instanced calls (off: one call per draw, for comparison).
    pub instancing: bool,
    /// The frame reads lightmaps: instances with a lightmap region draw with the LIGHTMAPPED
    /// pipelines, so they batch apart from their mesh's other instances.
    pub lightmaps: bool,
}

/// Normal matrix: inverse-transpose of the 3x3 part (not the cofactor, which flips normals of
/// mirrored instances; pipeline.md §1).
pub fn normal_matrix(model: Mat4) -> Mat3 {
    Mat3::from_mat4(model).inverse().transpose()
}

/// Instances `first_instance..first_instance + count` of the stream, all of scene instance
/// `instance`'s mesh at `lod`, read from `vertices` at `base_vertex`, with one winding, all lit
/// by their lightmaps or none.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Batch {
    /// The first of the batch's scene instances: its mesh gives the submeshes, materials and
    /// lightmap blocks, which all instances of the batch share.
    pub instance: u32,
    pub lod: u8,
    pub first_instance: u32,
    pub count: u32,
    pub vertices: vk::Buffer,
    pub base_vertex: i32,
    pub front: vk::FrontFace,
    /// Lit by the instances' lightmap regions (the submeshes with a lightmap block).
    pub lightmapped: bool,
    /// The instances' material override (every submesh drawn with it).
    pub material: Option<u32>,
}

/// Reused buffers of the batching, so a frame allocates nothing once warm.
#[derive(Default)]
pub struct Batcher {
    /// (mesh, LOD, mirrored, lightmapped, material override (u32::MAX: none), draw), sorted
    /// when instancing.
    order: Vec<(u32, u8, bool, bool, u32, u32)>,
    /// This frame's instance stream so far (copied to the GPU's instance buffer after recording).
    stream: Vec<InstanceData>,
}

impl Batcher {
    /// Start a frame's stream.
    pub fn clear(&mut self) {
        self.stream.clear();
    }

    /// Append `draws` to the stream as batches into `out` (cleared first). With
    /// `mode.instancing`, draws are grouped by mesh, LOD, winding and whether their lightmap
    /// lights them (in draw-list order within a group, so the result does not depend on sort
    /// stability); an animated instance, which draws its own skinned vertices in world space, is
    /// a batch of its own. Without, every draw is a batch, in draw-list order (for comparison).
    pub fn batch(&mut self, scene: &GpuScene, animation: Option<&AnimatedScene>, slot: usize, draws: &[Draw], mode: BatchMode, out: &mut Vec<Batch>) {
        out.clear();
        self.order.clear();
        let skinned = |d: &Draw| animation.and_then(|a| a.vertex_buffer(d.instance, d.lod, slot));
        for (i, d) in draws.iter().enumerate() {
            let inst = &scene.instances[d.instance as usize];
            let mirrored = skinned(d).is_none() && inst.world.determinant() < 0.0;
            let lightmapped = mode.lightmaps && inst.lightmap.is_some();
            self.order.push((inst.mesh, d.lod, mirrored, lightmapped, inst.material.unwrap_or(u32::MAX), i as u32));
        }
        if mode.instancing {
            self.order.sort_unstable();
        }
        for &(mesh, lod, mirrored, lightmapped, _, i) in &self.order {
            let d = draws[i as usize];
            let inst = &scene.instances[d.instance as usize];
            let (vertices, base_vertex, model) = match skinned(&d) {
                Some((b, first)) => (b, first, Mat4::IDENTITY),
                None => (scene.vertex_buffer.buffer, scene.meshes[mesh as usize].lods[lod as usize].base_vertex, inst.world),
            };
            // A mirrored instance (negative determinant) reverses its winding.
            let front = if mirrored { vk::FrontFace::CLOCKWISE } else { vk::FrontFace::COUNTER_CLOCKWISE };
            let n = normal_matrix(model);
            let (page, region) = inst.lightmap.map_or((0.0, Vec4::ZERO), |r| (r.page as f32, Vec4::new(r.scale[0], r.scale[1], r.offset[0], r.offset[1])));
            let first_instance = self.stream.len() as u32;
            self.stream.push(InstanceData { model, normal_cols: [n.x_axis.extend(page), n.y_axis.extend(0.0), n.z_axis.extend(0.0)], lightmap: region });
            let joins = mode.instancing && out.last().is_some_and(|b: &Batch| {
                let prev = &scene.instances[b.instance as usize];
                prev.mesh == mesh && b.lod == lod && b.vertices == vertices && b.base_vertex == base_vertex && b.front == front && b.lightmapped == lightmapped && b.material == inst.material && b.first_instance + b.count == first_instance
            });
            if joins {
                out.last_mut().unwrap().count += 1;
            } else {
                out.push(Batch { instance: d.instance, lod, first_instance, count: 1, vertices, base_vertex, front, lightmapped, material: inst.material });
            }
        }
    }

    /// The stream as bytes, for the instance buffer.
    pub fn stream_bytes(&self) -> &[u8] {
        // SAFETY: InstanceData is repr(C) plain floats.
        bytemuck::cast_slice(&self.stream)
    }
}
