//! The particle pass (issue 8): after the opaque shading pass, camera-facing quads blended into
//! the HDR target, depth-tested against the pre-pass depth without writing it.
//!
//! - One instance per `sim::particles::Billboard` (32 bytes), from a host-visible buffer per frame
//!   in flight, grown on demand (the slot's previous frame has finished when it is refilled).
//! - Batches per emitter: alpha-blended emitters first, farthest emitter first, each already
//!   sorted back to front by `fill_billboards`; additive ones after (order-free).
//! - Particles are emissive (unlit): sparks and spray read as their own colour whatever the
//!   lighting. Their colour is display-referred; under physical lighting the vertex shader
//!   divides out the exposure the tone map applies.
//! - Only RGB is written: the HDR alpha keeps its "0 = background" meaning for the tone map. A
//!   particle over bare background in a physically lit scene therefore is not tone-mapped and
//!   comes out brighter than over a surface; accepted for now (it would need the depth as a
//!   texture to tell the two apart).

use crate::gpu::{Gpu, GraphicsPipeline, PerSamples, SlotBuffers};
use crate::render::graph::{ImageRef, Rec, Rendering};
use crate::render::shaders;
use crate::sim::particles::{Billboard, BillboardScratch, Blend, ParticleSystem};
use crate::render::tonemap::HDR_FORMAT;
use anyhow::Result;
use ash::vk;
use glam::{Vec3, Vec4};

/// Mirrors the push-constant block of shaders/particle.vert.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ParticlePush {
    right: Vec4,
    up: Vec4,
}

/// A run of instances drawn with one blend mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParticleBatch {
    pub blend: Blend,
    pub first: u32,
    pub count: u32,
}

pub struct ParticlePass {
    layout: vk::PipelineLayout,
    depth_format: vk::Format,
    /// The soft-alpha and additive pipelines per sample count of the camera's targets.
    pipelines: PerSamples<[vk::Pipeline; 2]>,
    /// Instance buffers per frame slot, with their capacity in billboards.
    buffers: SlotBuffers,
    /// This frame's billboards and how they split into batches (filled before `record`).
    pub billboards: Vec<Billboard>,
    pub batches: Vec<ParticleBatch>,
    scratch: BillboardScratch,
    one_emitter: Vec<Billboard>,
}

impl ParticlePass {
    /// `frame_layout` is the renderer's set 0 (the particle shader reads view_proj and exposure).
    pub fn new(gpu: &Gpu, frame_layout: vk::DescriptorSetLayout, depth_format: vk::Format, frames_in_flight: usize) -> Result<ParticlePass> {
        let d = &gpu.device;
        let push = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::VERTEX)
            .size(std::mem::size_of::<ParticlePush>() as u32)];
        let set_layouts = [frame_layout];
        let layout = unsafe { d.create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts).push_constant_ranges(&push), None)? };
        Ok(ParticlePass {
            layout,
            depth_format,
            pipelines: PerSamples::default(),
            buffers: SlotBuffers::new("particle instances", vk::BufferUsageFlags::VERTEX_BUFFER, frames_in_flight, 256 * std::mem::size_of::<Billboard>()),
            billboards: Vec::new(),
            batches: Vec::new(),
            scratch: BillboardScratch::default(),
            one_emitter: Vec::new(),
        })
    }

    /// Billboards queued for the next frame.
    pub fn len(&self) -> usize {
        self.billboards.len()
    }

    pub fn is_empty(&self) -> bool {
        self.billboards.is_empty()
    }

    pub fn clear(&mut self) {
        self.billboards.clear();
        self.batches.clear();
    }

    /// Queue one batch (already in draw order).
    pub fn push(&mut self, blend: Blend, billboards: &[Billboard]) {
        if billboards.is_empty() {
            return;
        }
        self.batches.push(ParticleBatch {
            blend,
            first: self.billboards.len() as u32,
            count: billboards.len() as u32,
        });
        self.billboards.extend_from_slice(billboards);
    }

    /// Replace the queue with every emitter's live particles for a camera at `eye` looking
    /// along `forward`, moved on by `extrapolate_s` (see `ParticleSystem::fill_billboards`).
    /// Alpha-blended emitters are ordered farthest first by their emitter position, which is
    /// exact for emitters whose particle clouds do not interleave in depth.
    pub fn fill(&mut self, emitters: &[ParticleSystem], eye: Vec3, forward: Vec3, extrapolate_s: f32) {
        self.clear();
        let depth = |e: &ParticleSystem| (Vec3::from(e.params.position) - eye).dot(forward);
        let mut alpha: Vec<&ParticleSystem> = emitters.iter().filter(|e| e.params.blend == Blend::Alpha).collect();
        alpha.sort_by(|a, b| depth(b).total_cmp(&depth(a)));
        let additive = emitters.iter().filter(|e| e.params.blend == Blend::Additive);
        let mut tmp = std::mem::take(&mut self.one_emitter);
        for e in alpha.into_iter().chain(additive) {
            e.fill_billboards(eye, forward, extrapolate_s, &mut tmp, &mut self.scratch);
            self.push(e.params.blend, &tmp);
        }
        self.one_emitter = tmp;
    }

    /// Copy the queue into `slot`'s instance buffer; the GPU must be done with that slot.
    pub fn upload(&mut self, gpu: &Gpu, slot: usize) -> Result<()> {
        let needed = self.billboards.len();
        if needed == 0 {
            return Ok(());
        }
        // SAFETY: Billboard is repr(C) plain floats.
        let bytes: &[u8] = bytemuck::cast_slice(&self.billboards[..needed]);
        self.buffers.write(gpu, slot, bytes)
    }

    /// Make the pipelines for targets of `samples` samples if no frame has used them yet.
    pub fn prepare_samples(&mut self, gpu: &Gpu, samples: vk::SampleCountFlags) -> Result<()> {
        let (layout, depth_format) = (self.layout, self.depth_format);
        self.pipelines.ensure(samples, |samples| {
            let alpha = gpu.own(create_pipeline(gpu, layout, depth_format, vk::BlendFactor::ONE_MINUS_SRC_ALPHA, samples)?);
            let additive = create_pipeline(gpu, layout, depth_format, vk::BlendFactor::ONE, samples)?;
            Ok([alpha.keep(), additive])
        })?;
        Ok(())
    }

    /// Record the pass into the HDR target `hdr` over the depth `depth` the shading pass left
    /// (both of `samples` samples, which `prepare_samples` made pipelines for). Call only with
    /// a non-empty queue uploaded to the slot (an empty pass is skipped).
    #[allow(clippy::too_many_arguments)]
    pub fn record(&self, rec: &Rec, frame_set: vk::DescriptorSet, hdr: ImageRef, depth: ImageRef, samples: vk::SampleCountFlags, camera_right: Vec3, camera_up: Vec3) {
        let (d, cb) = (&rec.gpu.device, rec.cb);
        let [alpha, additive] = *self.pipelines.get(samples);
        let Some(buffer) = self.buffers.get(rec.slot) else { return };
        let push = ParticlePush { right: camera_right.extend(0.0), up: camera_up.extend(0.0) };
        // Depth tested, not written: kept as it is (store NONE).
        rec.begin_rendering(&Rendering::color(hdr, None).depth(depth, None, vk::AttachmentStoreOp::NONE));
        unsafe {
            d.cmd_bind_descriptor_sets(cb, vk::PipelineBindPoint::GRAPHICS, self.layout, 0, &[frame_set], &[]);
            d.cmd_push_constants(cb, self.layout, vk::ShaderStageFlags::VERTEX, 0, bytemuck::bytes_of(&push));
            d.cmd_bind_vertex_buffers(cb, 0, &[buffer.buffer], &[0]);
            let mut bound = vk::Pipeline::null();
            for b in &self.batches {
                let pipeline = match b.blend {
                    Blend::Alpha => alpha,
                    Blend::Additive => additive,
                };
                if pipeline != bound {
                    d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, pipeline);
                    bound = pipeline;
                }
                d.cmd_draw(cb, 4, b.count, 0, b.first);
            }
        }
        rec.end_rendering();
    }

    /// Drop the pipelines (the shaders were reloaded): `prepare_samples` makes them again from
    /// the new modules.
    pub fn reload_pipelines(&mut self, gpu: &Gpu) {
        unsafe {
            for pipeline in self.pipelines.drain().flatten() {
                gpu.device.destroy_pipeline(pipeline, None);
            }
        }
    }

    /// This frame's billboards, from the pass of a lost device (`Renderer::carry_on_from`).
    pub fn carry_on_from(&mut self, old: &mut ParticlePass) {
        std::mem::swap(&mut self.billboards, &mut old.billboards);
        std::mem::swap(&mut self.batches, &mut old.batches);
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        self.buffers.destroy(gpu);
        unsafe {
            for pipeline in self.pipelines.drain().flatten() {
                gpu.device.destroy_pipeline(pipeline, None);
            }
            gpu.device.destroy_pipeline_layout(self.layout, None);
        }
    }
}

/// A particle pipeline: colour = src * src_alpha + dst * `dst_factor` (ONE_MINUS_SRC_ALPHA for
/// soft alpha, which also accumulates coverage in alpha, ONE for additive); reversed-Z depth
/// test, no depth writes.
fn create_pipeline(gpu: &Gpu, layout: vk::PipelineLayout, depth_format: vk::Format, dst_factor: vk::BlendFactor, samples: vk::SampleCountFlags) -> Result<vk::Pipeline> {
    let bindings = [vk::VertexInputBindingDescription {
        binding: 0,
        stride: std::mem::size_of::<Billboard>() as u32,
        input_rate: vk::VertexInputRate::INSTANCE,
    }];
    let attributes = [
        vk::VertexInputAttributeDescription {
            location: 0,
            binding: 0,
            format: vk::Format::R32G32B32A32_SFLOAT,
            offset: 0,
        },
        vk::VertexInputAttributeDescription {
            location: 1,
            binding: 0,
            format: vk::Format::R32G32B32A32_SFLOAT,
            offset: 16,
        },
    ];
    // Soft particles also cover what is behind them: their alpha accumulates as "over" does
    // (the tone map shows the sky through 1 - alpha); additive ones cover nothing.
    let covers = dst_factor == vk::BlendFactor::ONE_MINUS_SRC_ALPHA;
    let rgb = vk::ColorComponentFlags::R | vk::ColorComponentFlags::G | vk::ColorComponentFlags::B;
    let blend = vk::PipelineColorBlendAttachmentState::default()
        .blend_enable(true)
        .src_color_blend_factor(vk::BlendFactor::SRC_ALPHA)
        .dst_color_blend_factor(dst_factor)
        .color_blend_op(vk::BlendOp::ADD)
        .src_alpha_blend_factor(vk::BlendFactor::ONE)
        .dst_alpha_blend_factor(vk::BlendFactor::ONE_MINUS_SRC_ALPHA)
        .alpha_blend_op(vk::BlendOp::ADD)
        .color_write_mask(if covers { rgb | vk::ColorComponentFlags::A } else { rgb });
    // Reversed-Z: nearer is greater; particles test depth but do not write it.
    GraphicsPipeline::new("particle", shaders::PARTICLE_VERT.spv())
        .fragment(shaders::PARTICLE_FRAG.spv(), None)
        .vertex_input(&bindings, &attributes)
        .topology(vk::PrimitiveTopology::TRIANGLE_STRIP)
        .depth(depth_format, false, vk::CompareOp::GREATER_OR_EQUAL)
        .color(HDR_FORMAT, blend)
        .multisample(samples)
        .build(gpu, layout)
}
