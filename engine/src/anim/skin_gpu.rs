//! The skinning compute pass (`shaders/skin.comp`): bind-pose vertices, joints/weights, morph
//! deltas and weights, and joint matrices in storage buffers; skinned vertices out, in the pack's
//! vertex layout, in a buffer later passes bind as their vertex buffer. Per frame the caller
//! writes joint matrices and morph weights into mapped memory (`update`, no allocation) and
//! records one dispatch (`record`).

use super::skin_cpu::DeformData;
use crate::gpu::{Buffer, Gpu};
use crate::render::shaders;
use anyhow::{bail, Result};
use ash::vk;
use glam::Mat4;
use gpu_allocator::MemoryLocation;
use pack::Vertex;

const BINDINGS: u32 = 8;
const GROUP: u32 = 64;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    vertex_count: u32,
    target_count: u32,
    skinned: u32,
    morph_normals: u32,
    joint_count: u32,
}

pub struct SkinPipeline {
    pub set_layout: vk::DescriptorSetLayout,
    pub layout: vk::PipelineLayout,
    pub pipeline: vk::Pipeline,
}

impl SkinPipeline {
    pub fn new(gpu: &Gpu) -> Result<SkinPipeline> {
        let d = &gpu.device;
        let bindings: Vec<vk::DescriptorSetLayoutBinding> = (0..BINDINGS)
            .map(|b| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        // Owned until the pipeline is whole (the module until it is made): an error frees them.
        unsafe {
            let set_layout = gpu.own(d.create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings), None)?);
            let push = [vk::PushConstantRange::default().stage_flags(vk::ShaderStageFlags::COMPUTE).size(std::mem::size_of::<Params>() as u32)];
            let set_layouts = [*set_layout];
            let layout = gpu.own(d.create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts).push_constant_ranges(&push), None)?);
            let module = gpu.own(shaders::module(d, shaders::SKIN_COMP)?);
            let stage = vk::PipelineShaderStageCreateInfo::default().stage(vk::ShaderStageFlags::COMPUTE).module(*module).name(c"main");
            let info = [vk::ComputePipelineCreateInfo::default().stage(stage).layout(*layout)];
            let pipeline = d.create_compute_pipelines(gpu.pipeline_cache, &info, None).map_err(|(_, e)| e)?[0];
            Ok(SkinPipeline { set_layout: set_layout.keep(), layout: layout.keep(), pipeline })
        }
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        unsafe {
            gpu.device.destroy_pipeline(self.pipeline, None);
            gpu.device.destroy_pipeline_layout(self.layout, None);
            gpu.device.destroy_descriptor_set_layout(self.set_layout, None);
        }
    }
}

/// One deforming mesh instance on the GPU: its inputs (bind vertices, joints, weights, morph
/// deltas: uploaded once), and per frame slot the parameters the CPU writes that frame and the
/// output, so a frame in flight never sees the next frame's writes.
pub struct SkinnedMesh {
    params: Params,
    joint_capacity: usize,
    inputs: Vec<Buffer>,
    slots: Vec<Slot>,
    pool: vk::DescriptorPool,
}

struct Slot {
    morph_weights: Buffer,
    joint_matrices: Buffer,
    /// Skinned vertices (pack `Vertex` layout): bind as a vertex buffer after the dispatch.
    output: Buffer,
    set: vk::DescriptorSet,
}

/// A device-local storage buffer with `bytes`; an empty input gets 16 zero bytes, since unused
/// bindings still need a buffer and copies of zero bytes are invalid.
fn input(gpu: &Gpu, name: &str, bytes: &[u8]) -> Result<Buffer> {
    let pad = [0u8; 16];
    Buffer::with_data(gpu, name, if bytes.is_empty() { &pad } else { bytes }, vk::BufferUsageFlags::STORAGE_BUFFER)
}

impl SkinnedMesh {
    /// Upload `data`, with one frame slot; `joint_count` joint matrices per frame (1 for a mesh
    /// that is not skinned).
    pub fn new(gpu: &Gpu, pipe: &SkinPipeline, data: &DeformData, joint_count: usize) -> Result<SkinnedMesh> {
        SkinnedMesh::with_slots(gpu, pipe, data, joint_count, 1)
    }

    /// Upload `data` once, with `slots` frame slots (the renderer's frames in flight).
    pub fn with_slots(gpu: &Gpu, pipe: &SkinPipeline, data: &DeformData, joint_count: usize, slots: usize) -> Result<SkinnedMesh> {
        let n = data.vertices.len();
        if n == 0 {
            bail!("a deforming mesh needs at least one vertex");
        }
        let slots = slots.max(1);
        let joint_capacity = joint_count.max(1);
        let joints: Vec<u16> = data.joints.iter().flatten().flatten().copied().collect();
        let weights: Vec<f32> = data.weights.iter().flatten().flatten().copied().collect();
        // Owned until the mesh is whole: an error frees what was made before it.
        let mut inputs = gpu.own(Vec::with_capacity(BINDINGS as usize));
        inputs.push(input(gpu, "skin bind vertices", pack::Vertex::slice_as_bytes(&data.vertices))?);
        inputs.push(input(gpu, "skin joints", bytemuck::cast_slice::<_, u8>(&joints))?);
        inputs.push(input(gpu, "skin weights", bytemuck::cast_slice::<_, u8>(&weights))?);
        inputs.push(input(gpu, "morph positions", bytemuck::cast_slice::<_, u8>(&data.morph_positions))?);
        inputs.push(input(gpu, "morph normals", bytemuck::cast_slice::<_, u8>(&data.morph_normals))?);
        let d = &gpu.device;
        let sizes = [vk::DescriptorPoolSize {
            ty: vk::DescriptorType::STORAGE_BUFFER,
            descriptor_count: BINDINGS * slots as u32,
        }];
        let pool = gpu.own(unsafe { d.create_descriptor_pool(&vk::DescriptorPoolCreateInfo::default().max_sets(slots as u32).pool_sizes(&sizes), None)? });
        let mut mesh = gpu.own(SkinnedMesh {
            params: Params {
                vertex_count: n as u32,
                target_count: data.targets as u32,
                skinned: data.joints.is_some() as u32,
                morph_normals: !data.morph_normals.is_empty() as u32,
                joint_count: joint_capacity as u32,
            },
            joint_capacity,
            inputs: inputs.keep(),
            slots: Vec::with_capacity(slots),
            pool: pool.keep(),
        });
        for _ in 0..slots {
            let slot = mesh.slot(gpu, pipe, data.targets)?;
            mesh.slots.push(slot);
        }
        Ok(mesh.keep())
    }

    /// One frame slot's parameter buffers, output and descriptor set (inputs shared).
    fn slot(&self, gpu: &Gpu, pipe: &SkinPipeline, targets: usize) -> Result<Slot> {
        let n = self.params.vertex_count as usize;
        let host = |name: &str, size: usize| Buffer::new(gpu, name, size.max(16) as u64, vk::BufferUsageFlags::STORAGE_BUFFER, MemoryLocation::CpuToGpu);
        let mut morph_weights = gpu.own(host("morph weights", targets * 4)?);
        morph_weights.mapped().fill(0);
        let mut joint_matrices = gpu.own(host("joint matrices", self.joint_capacity * 64)?);
        joint_matrices.mapped().copy_from_slice(bytemuck::cast_slice::<_, u8>(&vec![Mat4::IDENTITY; self.joint_capacity][..]));
        let output = gpu.own(Buffer::new(
            gpu,
            "skinned vertices",
            (n * pack::VERTEX_STRIDE) as u64,
            vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::VERTEX_BUFFER | vk::BufferUsageFlags::TRANSFER_SRC,
            MemoryLocation::GpuOnly,
        )?);
        let d = &gpu.device;
        let layouts = [pipe.set_layout];
        let set = unsafe { d.allocate_descriptor_sets(&vk::DescriptorSetAllocateInfo::default().descriptor_pool(self.pool).set_layouts(&layouts))?[0] };
        let all: Vec<vk::Buffer> = self.inputs.iter().map(|b| b.buffer).chain([morph_weights.buffer, joint_matrices.buffer, output.buffer]).collect();
        let infos: Vec<[vk::DescriptorBufferInfo; 1]> = all
            .iter()
            .map(|&b| {
                [vk::DescriptorBufferInfo {
                    buffer: b,
                    offset: 0,
                    range: vk::WHOLE_SIZE,
                }]
            })
            .collect();
        let writes: Vec<vk::WriteDescriptorSet> = infos
            .iter()
            .enumerate()
            .map(|(i, info)| {
                vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(i as u32)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .buffer_info(info)
            })
            .collect();
        unsafe { d.update_descriptor_sets(&writes, &[]) };
        Ok(Slot {
            morph_weights: morph_weights.keep(),
            joint_matrices: joint_matrices.keep(),
            output: output.keep(),
            set,
        })
    }

    /// The skinned vertices of frame slot `slot`.
    pub fn output(&self, slot: usize) -> &Buffer {
        &self.slots[slot].output
    }

    /// Joint matrices and morph weights for slot 0 (tests and tools; see `update_slot`).
    pub fn update(&mut self, joint_matrices: &[Mat4], morph_weights: &[f32]) {
        self.update_slot(0, joint_matrices, morph_weights);
    }

    /// This frame's joint matrices (global x inverse bind; for an unskinned mesh, its node's
    /// world matrix) and morph weights for frame slot `slot`, written straight into mapped memory.
    pub fn update_slot(&mut self, slot: usize, joint_matrices: &[Mat4], morph_weights: &[f32]) {
        let (j, w) = (joint_matrices.len().min(self.joint_capacity), morph_weights.len().min(self.params.target_count as usize));
        let s = &mut self.slots[slot];
        s.joint_matrices.mapped()[..j * 64].copy_from_slice(bytemuck::cast_slice::<_, u8>(&joint_matrices[..j]));
        s.morph_weights.mapped()[..w * 4].copy_from_slice(bytemuck::cast_slice::<_, u8>(&morph_weights[..w]));
    }

    /// Record slot 0's dispatch and a barrier that makes the output readable as vertices, by
    /// compute shaders and by copies (tests and tools).
    pub fn record(&self, gpu: &Gpu, pipe: &SkinPipeline, cb: vk::CommandBuffer) {
        let d = &gpu.device;
        unsafe {
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::COMPUTE, pipe.pipeline);
            self.dispatch(gpu, pipe, cb, 0);
            let barrier = [vk::MemoryBarrier2::default()
                .src_stage_mask(vk::PipelineStageFlags2::COMPUTE_SHADER)
                .src_access_mask(vk::AccessFlags2::SHADER_STORAGE_WRITE)
                .dst_stage_mask(vk::PipelineStageFlags2::VERTEX_ATTRIBUTE_INPUT | vk::PipelineStageFlags2::COMPUTE_SHADER | vk::PipelineStageFlags2::COPY)
                .dst_access_mask(vk::AccessFlags2::VERTEX_ATTRIBUTE_READ | vk::AccessFlags2::SHADER_STORAGE_READ | vk::AccessFlags2::TRANSFER_READ)];
            d.cmd_pipeline_barrier2(cb, &vk::DependencyInfo::default().memory_barriers(&barrier));
        }
    }

    /// Only the dispatch: the caller has bound `pipe.pipeline` and records one barrier after
    /// all of a frame's dispatches (`renderer` skins every character, then one barrier).
    pub fn dispatch(&self, gpu: &Gpu, pipe: &SkinPipeline, cb: vk::CommandBuffer, slot: usize) {
        let d = &gpu.device;
        unsafe {
            d.cmd_bind_descriptor_sets(cb, vk::PipelineBindPoint::COMPUTE, pipe.layout, 0, &[self.slots[slot].set], &[]);
            d.cmd_push_constants(cb, pipe.layout, vk::ShaderStageFlags::COMPUTE, 0, bytemuck::bytes_of(&self.params));
            d.cmd_dispatch(cb, self.params.vertex_count.div_ceil(GROUP), 1, 1);
        }
    }

    /// Run slot 0's pass once and copy its output back (tests and tools; waits for the GPU).
    pub fn run_and_read_back(&self, gpu: &Gpu, pipe: &SkinPipeline) -> Result<Vec<Vertex>> {
        let output = &self.slots[0].output;
        let size = output.size;
        let mut readback = Buffer::new(gpu, "skin readback", size, vk::BufferUsageFlags::TRANSFER_DST, MemoryLocation::GpuToCpu)?;
        let run = gpu.one_shot(|cb| unsafe {
            self.record(gpu, pipe, cb);
            gpu.device.cmd_copy_buffer(cb, output.buffer, readback.buffer, &[vk::BufferCopy::default().size(size)]);
            let to_host = [vk::MemoryBarrier2::default()
                .src_stage_mask(vk::PipelineStageFlags2::COPY)
                .src_access_mask(vk::AccessFlags2::TRANSFER_WRITE)
                .dst_stage_mask(vk::PipelineStageFlags2::HOST)
                .dst_access_mask(vk::AccessFlags2::HOST_READ)];
            gpu.device.cmd_pipeline_barrier2(cb, &vk::DependencyInfo::default().memory_barriers(&to_host));
        });
        let out = run.map(|_| {
            // The buffer holds vertex_count vertices written by the shader.
            Vertex::read_all(&readback.mapped_ref()[..self.params.vertex_count as usize * pack::VERTEX_STRIDE])
        });
        readback.destroy(gpu);
        out
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        unsafe { gpu.device.destroy_descriptor_pool(self.pool, None) };
        for b in self.inputs.iter_mut() {
            b.destroy(gpu);
        }
        for s in &mut self.slots {
            for b in [&mut s.morph_weights, &mut s.joint_matrices, &mut s.output] {
                b.destroy(gpu);
            }
        }
    }
}
