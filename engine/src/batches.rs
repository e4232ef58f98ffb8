//! Instanced drawing for the mesh passes: a draw list becomes batches, runs of instances of one
//! mesh LOD drawn with one instanced call per submesh, their transforms streamed per frame as
//! instance-rate vertex data. On lavapipe every draw call costs tens of microseconds whatever it
//! draws, so 25 000 visible cubes as 25 000 calls took seconds per frame; as a handful of
//! instanced calls they cost what their triangles cost. A real GPU's driver is spared the same
//! per-call work on the CPU.

use crate::animated::AnimatedScene;
use crate::scene::GpuScene;
use crate::visibility::Draw;
use ash::vk;
use glam::{Mat3, Mat4, Vec4};

/// What mesh.vert reads per instance (binding 1, locations 6 to 12): the model matrix and the
/// columns of its normal matrix (xyz; w unused).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct InstanceData {
    pub model: Mat4,
    pub normal_cols: [Vec4; 3],
}

/// Bytes per instance in the instance stream.
pub const INSTANCE_STRIDE: u32 = std::mem::size_of::<InstanceData>() as u32;
const _: () = assert!(INSTANCE_STRIDE == 112);

/// The instance-rate attributes of mesh.vert: binding 1, model columns at locations 6 to 9,
/// normal-matrix columns at 10 to 12.
pub fn instance_attributes() -> [vk::VertexInputAttributeDescription; 7] {
    std::array::from_fn(|i| vk::VertexInputAttributeDescription {
        location: 6 + i as u32,
        binding: 1,
        format: if i < 4 { vk::Format::R32G32B32A32_SFLOAT } else { vk::Format::R32G32B32_SFLOAT },
        offset: 16 * i as u32,
    })
}

/// Normal matrix: inverse-transpose of the 3x3 part (not the cofactor, which flips normals of
/// mirrored instances; pipeline.md §1).
pub fn normal_matrix(model: Mat4) -> Mat3 {
    Mat3::from_mat4(model).inverse().transpose()
}

/// Instances `first_instance..first_instance + count` of the stream, all of scene instance
/// `instance`'s mesh at `lod`, read from `vertices` at `base_vertex`, with one winding.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Batch {
    /// The first of the batch's scene instances: its mesh gives the submeshes, materials and
    /// lightmap pages, which all instances of the batch share.
    pub instance: u32,
    pub lod: u8,
    pub first_instance: u32,
    pub count: u32,
    pub vertices: vk::Buffer,
    pub base_vertex: i32,
    pub front: vk::FrontFace,
}

/// Reused buffers of the batching, so a frame allocates nothing once warm.
#[derive(Default)]
pub struct Batcher {
    order: Vec<(u32, u8, bool, u32)>,
    /// This frame's instance stream so far (copied to the GPU's instance buffer after recording).
    stream: Vec<InstanceData>,
}

impl Batcher {
    /// Start a frame's stream.
    pub fn clear(&mut self) {
        self.stream.clear();
    }

    /// Append `draws` to the stream as batches into `out` (cleared first). With `instancing`,
    /// draws are grouped by mesh, LOD and winding (in draw-list order within a group, so the
    /// result does not depend on sort stability); an animated instance, which draws its own
    /// skinned vertices in world space, is a batch of its own. Without, every draw is a batch,
    /// in draw-list order (for comparison).
    pub fn batch(&mut self, scene: &GpuScene, animation: Option<&AnimatedScene>, slot: usize, draws: &[Draw], instancing: bool, out: &mut Vec<Batch>) {
        out.clear();
        self.order.clear();
        let skinned = |d: &Draw| animation.and_then(|a| a.vertex_buffer(d.instance, d.lod, slot));
        for (i, d) in draws.iter().enumerate() {
            let inst = &scene.instances[d.instance as usize];
            let mirrored = skinned(d).is_none() && inst.world.determinant() < 0.0;
            self.order.push((inst.mesh, d.lod, mirrored, i as u32));
        }
        if instancing {
            self.order.sort_unstable();
        }
        for &(mesh, lod, mirrored, i) in &self.order {
            let d = draws[i as usize];
            let (vertices, base_vertex, model) = match skinned(&d) {
                Some(b) => (b, 0, Mat4::IDENTITY),
                None => (scene.vertex_buffer.buffer, scene.meshes[mesh as usize].lods[lod as usize].base_vertex, scene.instances[d.instance as usize].world),
            };
            // A mirrored instance (negative determinant) reverses its winding.
            let front = if mirrored { vk::FrontFace::CLOCKWISE } else { vk::FrontFace::COUNTER_CLOCKWISE };
            let n = normal_matrix(model);
            let first_instance = self.stream.len() as u32;
            self.stream.push(InstanceData { model, normal_cols: [n.x_axis.extend(0.0), n.y_axis.extend(0.0), n.z_axis.extend(0.0)] });
            let joins = instancing && out.last().is_some_and(|b: &Batch| {
                let prev = &scene.instances[b.instance as usize];
                prev.mesh == mesh && b.lod == lod && b.vertices == vertices && b.base_vertex == base_vertex && b.front == front && b.first_instance + b.count == first_instance
            });
            if joins {
                out.last_mut().unwrap().count += 1;
            } else {
                out.push(Batch { instance: d.instance, lod, first_instance, count: 1, vertices, base_vertex, front });
            }
        }
    }

    /// The stream as bytes, for the instance buffer.
    pub fn stream_bytes(&self) -> &[u8] {
        // SAFETY: InstanceData is repr(C) plain floats.
        unsafe { std::slice::from_raw_parts(self.stream.as_ptr() as *const u8, self.stream.len() * INSTANCE_STRIDE as usize) }
    }
}
