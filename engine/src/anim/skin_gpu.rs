//! The skinning compute pass (`shaders/skin.comp`): bind-pose vertices, joints/weights and morph
//! deltas in storage buffers (uploaded once), joint matrices and morph weights written per frame
//! into mapped memory, and skinned vertices out, in the pack's vertex layout, in a buffer later
//! passes bind as their vertex buffer.
//!
//! One `SkinBatch` holds every deforming (instance, LOD) of a scene as a job: its inputs are
//! ranges of shared buffers (a `source`, shared by the jobs that deform the same data), its
//! joint matrices and morph weights those of its `owner` (an instance: all its LODs pose
//! alike), its output a range of one buffer per frame slot. A frame skins the jobs it draws in
//! one dispatch (`dispatch`): lavapipe wakes its compute threads and waits for them at every
//! dispatch, which at one dispatch per character cost more than the skinning (skinned-64: 64
//! dispatches of about 540 vertices each took several ms; README, "Frame budget").

use super::skin_cpu::DeformData;
use crate::gpu::{Buffer, Gpu};
use crate::render::shaders;
use anyhow::{bail, Result};
use ash::vk;
use glam::Mat4;
use gpu_allocator::MemoryLocation;
use pack::Vertex;

const BINDINGS: u32 = 10;
/// The shader's local size.
const GROUP: u32 = 64;
/// Workgroups per dispatch at most (Vulkan guarantees 65 535 in x).
const MAX_GROUPS: u32 = 65_535;

/// Mirrors `Job` in shaders/skin.comp (std430: twelve words).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct JobParams {
    vertex_count: u32,
    bind_base: u32,
    morph_base: u32,
    target_count: u32,
    morph_normal_base: u32,
    weight_base: u32,
    joint_base: u32,
    joint_count: u32,
    skinned: u32,
    out_base: u32,
    first_group: u32,
    pad: u32,
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
            let push = [vk::PushConstantRange::default().stage_flags(vk::ShaderStageFlags::COMPUTE).size(4)];
            let set_layouts = [*set_layout];
            let layout = gpu.own(d.create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts).push_constant_ranges(&push), None)?);
            let module = gpu.own(shaders::module(d, shaders::SKIN_COMP.spv())?);
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

/// What poses a batch's jobs: an instance's joint matrices (global x inverse bind; for an
/// unskinned mesh one, its node's world matrix) and morph weights.
#[derive(Debug, Clone, Copy)]
pub struct Owner {
    pub joints: usize,
    pub targets: usize,
}

/// One job: `source`'s data deformed by `owner`'s pose.
#[derive(Debug, Clone, Copy)]
pub struct JobSpec {
    pub owner: usize,
    pub source: usize,
}

/// A frame slot's per-frame buffers: written by the CPU for the frame using the slot, so a frame
/// in flight never sees the next frame's writes.
struct Slot {
    joint_matrices: Buffer,
    morph_weights: Buffer,
    /// This frame's jobs (`JobParams`) and, per workgroup, its job.
    jobs: Buffer,
    group_jobs: Buffer,
    /// Skinned vertices (the pack's stored vertex layout), every job's range: bind as a vertex buffer
    /// after the dispatch.
    output: Buffer,
    set: vk::DescriptorSet,
}

pub struct SkinBatch {
    /// Per job, its parameters (`first_group` set per frame).
    jobs: Vec<JobParams>,
    /// Per job, its source's texture-coordinate ranges (what its output's codes refer to).
    job_ranges: Vec<pack::UvRanges>,
    /// Per owner, its first joint matrix and morph weight, and how many of each.
    owners: Vec<(u32, u32, Owner)>,
    inputs: Vec<Buffer>,
    slots: Vec<Slot>,
    pool: vk::DescriptorPool,
}

/// A device-local storage buffer with `bytes`; an empty input gets 16 zero bytes, since unused
/// bindings still need a buffer and copies of zero bytes are invalid.
fn input(gpu: &Gpu, name: &str, bytes: &[u8]) -> Result<Buffer> {
    let pad = [0u8; 16];
    Buffer::with_data(gpu, name, if bytes.is_empty() { &pad } else { bytes }, vk::BufferUsageFlags::STORAGE_BUFFER)
}

/// A u32 offset of an input, or an error naming it when the batch outgrows the shader's indices.
fn offset(n: usize, what: &str) -> Result<u32> {
    u32::try_from(n).map_err(|_| anyhow::anyhow!("skinning: {what} past 2^32 elements"))
}

impl SkinBatch {
    /// A batch of one job (`data` posed by `joint_count` matrices) with one frame slot: tests
    /// and tools.
    pub fn single(gpu: &Gpu, pipe: &SkinPipeline, data: &DeformData, joint_count: usize) -> Result<SkinBatch> {
        SkinBatch::new(gpu, pipe, &[data], &[Owner { joints: joint_count, targets: data.targets }], &[JobSpec { owner: 0, source: 0 }], 1)
    }

    /// Upload `sources` once; `jobs` deform them as their owners pose them; `slots` frame slots
    /// (the renderer's frames in flight).
    pub fn new(gpu: &Gpu, pipe: &SkinPipeline, sources: &[&DeformData], owners: &[Owner], jobs: &[JobSpec], slots: usize) -> Result<SkinBatch> {
        // Inputs: the sources one after another; per source its first vertex and first floats.
        let (mut vertices, mut joints, mut weights, mut morph_p, mut morph_n) = (Vec::<u8>::new(), Vec::<[u16; 4]>::new(), Vec::<[f32; 4]>::new(), Vec::new(), Vec::new());
        let mut bases = Vec::with_capacity(sources.len());
        for data in sources {
            let n = data.vertices.len();
            if n == 0 {
                bail!("a deforming mesh needs at least one vertex");
            }
            let normals = if data.morph_normals.is_empty() { u32::MAX } else { offset(morph_n.len(), "morph normals")? };
            bases.push((offset(vertices.len() / pack::VERTEX_STRIDE, "vertices")?, offset(morph_p.len(), "morph deltas")?, normals));
            vertices.extend(pack::encode_vertices_with(&data.vertices, &data.uv_ranges));
            // Joints and weights run beside the vertices (zeros for an unskinned source).
            joints.extend(data.joints.as_deref().map_or(vec![[0; 4]; n], |j| j.to_vec()));
            weights.extend(data.weights.as_deref().map_or(vec![[0.0; 4]; n], |w| w.to_vec()));
            morph_p.extend_from_slice(&data.morph_positions);
            morph_n.extend_from_slice(&data.morph_normals);
        }
        let mut owner_bases = Vec::with_capacity(owners.len());
        let (mut joint_total, mut weight_total) = (0usize, 0usize);
        for o in owners {
            let o = Owner { joints: o.joints.max(1), targets: o.targets };
            owner_bases.push((offset(joint_total, "joint matrices")?, offset(weight_total, "morph weights")?, o));
            joint_total += o.joints;
            weight_total += o.targets;
        }
        let mut params = Vec::with_capacity(jobs.len());
        let mut job_ranges = Vec::with_capacity(jobs.len());
        let mut out_total = 0usize;
        for j in jobs {
            let (Some(data), Some(&(bind_base, morph_base, morph_normal_base)), Some(&(joint_base, weight_base, owner))) = (sources.get(j.source), bases.get(j.source), owner_bases.get(j.owner)) else {
                bail!("skinning job {j:?} names a source or owner the batch does not have");
            };
            params.push(JobParams {
                vertex_count: data.vertices.len() as u32,
                bind_base,
                morph_base,
                // The owner's weights past its count are not read: a source with more targets
                // than its owner poses moves by the first ones only.
                target_count: data.targets.min(owner.targets) as u32,
                morph_normal_base,
                weight_base,
                joint_base,
                joint_count: owner.joints as u32,
                skinned: data.joints.is_some() as u32,
                out_base: offset(out_total, "skinned vertices")?,
                first_group: 0,
                pad: 0,
            });
            job_ranges.push(data.uv_ranges);
            out_total += data.vertices.len();
        }
        let groups: usize = params.iter().map(|p| p.vertex_count.div_ceil(GROUP) as usize).sum();
        let slots = slots.max(1);
        // Owned until the batch is whole: an error frees what was made before it.
        let mut inputs = gpu.own(Vec::with_capacity(5));
        inputs.push(input(gpu, "skin bind vertices", &vertices)?);
        inputs.push(input(gpu, "skin joints", bytemuck::cast_slice::<_, u8>(&joints))?);
        inputs.push(input(gpu, "skin weights", bytemuck::cast_slice::<_, u8>(&weights))?);
        inputs.push(input(gpu, "morph positions", bytemuck::cast_slice::<_, u8>(&morph_p))?);
        inputs.push(input(gpu, "morph normals", bytemuck::cast_slice::<_, u8>(&morph_n))?);
        let d = &gpu.device;
        let sizes = [vk::DescriptorPoolSize { ty: vk::DescriptorType::STORAGE_BUFFER, descriptor_count: BINDINGS * slots as u32 }];
        let pool = gpu.own(unsafe { d.create_descriptor_pool(&vk::DescriptorPoolCreateInfo::default().max_sets(slots as u32).pool_sizes(&sizes), None)? });
        let mut batch = gpu.own(SkinBatch { jobs: params, job_ranges, owners: owner_bases, inputs: inputs.keep(), slots: Vec::with_capacity(slots), pool: pool.keep() });
        for _ in 0..slots {
            let slot = batch.slot(gpu, pipe, joint_total, weight_total, groups, out_total)?;
            batch.slots.push(slot);
        }
        Ok(batch.keep())
    }

    /// One frame slot's buffers and descriptor set (inputs shared).
    fn slot(&self, gpu: &Gpu, pipe: &SkinPipeline, joints: usize, weights: usize, groups: usize, vertices: usize) -> Result<Slot> {
        let host = |name: &str, size: usize| Buffer::new(gpu, name, size.max(16) as u64, vk::BufferUsageFlags::STORAGE_BUFFER, MemoryLocation::CpuToGpu);
        let mut morph_weights = gpu.own(host("morph weights", weights * 4)?);
        morph_weights.mapped().fill(0);
        let mut joint_matrices = gpu.own(host("joint matrices", joints * 64)?);
        joint_matrices.mapped().copy_from_slice(bytemuck::cast_slice::<_, u8>(&vec![Mat4::IDENTITY; joints][..]));
        let jobs = gpu.own(host("skinning jobs", self.jobs.len() * std::mem::size_of::<JobParams>())?);
        let group_jobs = gpu.own(host("skinning workgroups", groups * 4)?);
        let output = gpu.own(Buffer::new(
            gpu,
            "skinned vertices",
            (vertices * pack::VERTEX_STRIDE) as u64,
            vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::VERTEX_BUFFER | vk::BufferUsageFlags::TRANSFER_SRC,
            MemoryLocation::GpuOnly,
        )?);
        let d = &gpu.device;
        let layouts = [pipe.set_layout];
        let set = unsafe { d.allocate_descriptor_sets(&vk::DescriptorSetAllocateInfo::default().descriptor_pool(self.pool).set_layouts(&layouts))?[0] };
        // In the shader's binding order.
        let all: Vec<vk::Buffer> = self.inputs.iter().map(|b| b.buffer).chain([morph_weights.buffer, joint_matrices.buffer, output.buffer, jobs.buffer, group_jobs.buffer]).collect();
        let infos: Vec<[vk::DescriptorBufferInfo; 1]> = all.iter().map(|&b| [vk::DescriptorBufferInfo { buffer: b, offset: 0, range: vk::WHOLE_SIZE }]).collect();
        let writes: Vec<vk::WriteDescriptorSet> = infos
            .iter()
            .enumerate()
            .map(|(i, info)| vk::WriteDescriptorSet::default().dst_set(set).dst_binding(i as u32).descriptor_type(vk::DescriptorType::STORAGE_BUFFER).buffer_info(info))
            .collect();
        unsafe { d.update_descriptor_sets(&writes, &[]) };
        Ok(Slot { joint_matrices: joint_matrices.keep(), morph_weights: morph_weights.keep(), jobs: jobs.keep(), group_jobs: group_jobs.keep(), output: output.keep(), set })
    }

    /// The skinned vertices of frame slot `slot` (every job's range).
    pub fn output(&self, slot: usize) -> &Buffer {
        &self.slots[slot].output
    }

    /// Job `job`'s first vertex in `output`, and its vertex count.
    pub fn output_range(&self, job: usize) -> (u32, u32) {
        (self.jobs[job].out_base, self.jobs[job].vertex_count)
    }

    /// Owner `owner`'s joint matrices and morph weights for frame slot `slot`, written straight
    /// into mapped memory (no allocation); extra ones are ignored.
    pub fn update(&mut self, slot: usize, owner: usize, joint_matrices: &[Mat4], morph_weights: &[f32]) {
        let (joint_base, weight_base, o) = self.owners[owner];
        let (j, w) = (joint_matrices.len().min(o.joints), morph_weights.len().min(o.targets));
        let s = &mut self.slots[slot];
        let at = joint_base as usize * 64;
        s.joint_matrices.mapped()[at..at + j * 64].copy_from_slice(bytemuck::cast_slice::<_, u8>(&joint_matrices[..j]));
        let at = weight_base as usize * 4;
        s.morph_weights.mapped()[at..at + w * 4].copy_from_slice(bytemuck::cast_slice::<_, u8>(&morph_weights[..w]));
    }

    /// Skin `jobs` (indices, each at most once) in frame slot `slot`: write their parameters and
    /// record one dispatch (more only past `MAX_GROUPS` workgroups). The caller has bound
    /// `pipe.pipeline` and records the barrier after (the frame graph's, for the renderer).
    /// Returns the dispatches recorded and the vertices skinned.
    pub fn dispatch(&mut self, gpu: &Gpu, pipe: &SkinPipeline, cb: vk::CommandBuffer, slot: usize, jobs: &[u32]) -> (u32, u64) {
        if jobs.is_empty() {
            return (0, 0);
        }
        let s = &mut self.slots[slot];
        let (mut groups, mut vertices) = (0u32, 0u64);
        {
            let table: &mut [JobParams] = bytemuck::cast_slice_mut(&mut s.jobs.mapped()[..self.jobs.len() * std::mem::size_of::<JobParams>()]);
            let group_jobs: &mut [u32] = bytemuck::cast_slice_mut(s.group_jobs.mapped());
            for (k, &j) in jobs.iter().enumerate() {
                let mut p = self.jobs[j as usize];
                p.first_group = groups;
                let n = p.vertex_count.div_ceil(GROUP);
                group_jobs[groups as usize..(groups + n) as usize].fill(k as u32);
                table[k] = p;
                groups += n;
                vertices += p.vertex_count as u64;
            }
        }
        let d = &gpu.device;
        unsafe {
            d.cmd_bind_descriptor_sets(cb, vk::PipelineBindPoint::COMPUTE, pipe.layout, 0, &[s.set], &[]);
            let (mut first, mut dispatches) = (0, 0);
            while first < groups {
                let n = (groups - first).min(MAX_GROUPS);
                d.cmd_push_constants(cb, pipe.layout, vk::ShaderStageFlags::COMPUTE, 0, &first.to_ne_bytes());
                d.cmd_dispatch(cb, n, 1, 1);
                first += n;
                dispatches += 1;
            }
            (dispatches, vertices)
        }
    }

    /// Record slot 0's dispatch of every job and a barrier that makes the output readable as
    /// vertices, by compute shaders and by copies (tests and tools).
    pub fn record(&mut self, gpu: &Gpu, pipe: &SkinPipeline, cb: vk::CommandBuffer) {
        let d = &gpu.device;
        let all: Vec<u32> = (0..self.jobs.len() as u32).collect();
        unsafe {
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::COMPUTE, pipe.pipeline);
            self.dispatch(gpu, pipe, cb, 0, &all);
            let barrier = [vk::MemoryBarrier2::default()
                .src_stage_mask(vk::PipelineStageFlags2::COMPUTE_SHADER)
                .src_access_mask(vk::AccessFlags2::SHADER_STORAGE_WRITE)
                .dst_stage_mask(vk::PipelineStageFlags2::VERTEX_ATTRIBUTE_INPUT | vk::PipelineStageFlags2::COMPUTE_SHADER | vk::PipelineStageFlags2::COPY)
                .dst_access_mask(vk::AccessFlags2::VERTEX_ATTRIBUTE_READ | vk::AccessFlags2::SHADER_STORAGE_READ | vk::AccessFlags2::TRANSFER_READ)];
            d.cmd_pipeline_barrier2(cb, &vk::DependencyInfo::default().memory_barriers(&barrier));
        }
    }

    /// Run slot 0's pass over every job once and copy the output back, per job its vertices
    /// (tests and tools; waits for the GPU).
    pub fn run_and_read_back(&mut self, gpu: &Gpu, pipe: &SkinPipeline) -> Result<Vec<Vec<Vertex>>> {
        let size = self.slots[0].output.size;
        let mut readback = Buffer::new(gpu, "skin readback", size, vk::BufferUsageFlags::TRANSFER_DST, MemoryLocation::GpuToCpu)?;
        let output = self.slots[0].output.buffer;
        let run = gpu.one_shot(|cb| unsafe {
            self.record(gpu, pipe, cb);
            gpu.device.cmd_copy_buffer(cb, output, readback.buffer, &[vk::BufferCopy::default().size(size)]);
            let to_host = [vk::MemoryBarrier2::default()
                .src_stage_mask(vk::PipelineStageFlags2::COPY)
                .src_access_mask(vk::AccessFlags2::TRANSFER_WRITE)
                .dst_stage_mask(vk::PipelineStageFlags2::HOST)
                .dst_access_mask(vk::AccessFlags2::HOST_READ)];
            gpu.device.cmd_pipeline_barrier2(cb, &vk::DependencyInfo::default().memory_barriers(&to_host));
        });
        let out = run.map(|_| {
            let bytes = readback.mapped_ref();
            self.jobs
                .iter()
                .zip(&self.job_ranges)
                .map(|(p, ranges)| {
                    let at = p.out_base as usize * pack::VERTEX_STRIDE;
                    pack::decode_vertices(&bytes[at..at + p.vertex_count as usize * pack::VERTEX_STRIDE], ranges)
                })
                .collect()
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
            for b in [&mut s.morph_weights, &mut s.joint_matrices, &mut s.jobs, &mut s.group_jobs, &mut s.output] {
                b.destroy(gpu);
            }
        }
    }
}
