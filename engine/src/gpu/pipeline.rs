//! One place that builds graphics pipelines. Every pass (meshes, shadows, particles, boids, tone
//! map) differs only in its shaders, vertex layout, topology, depth state, blending, attachment
//! formats and sample count; the rest (dynamic rendering, dynamic viewport and scissor, fill
//! mode, shader module lifetime) is the same and lives here once.

use crate::render::shaders;
use anyhow::{Context, Result};
use ash::vk;
use super::Gpu;

/// A graphics pipeline's description. Start from [`GraphicsPipeline::new`] and set what the
/// pass needs; the defaults are a triangle list with no vertex input, no culling, no depth
/// attachment and no colour attachment.
pub struct GraphicsPipeline<'a> {
    /// What the pipeline is for, named in the error when creation fails.
    name: &'a str,
    vert: &'a [u8],
    frag: Option<&'a [u8]>,
    /// Specialisation constants of the fragment shader.
    frag_specialization: Option<vk::SpecializationInfo<'a>>,
    bindings: &'a [vk::VertexInputBindingDescription],
    attributes: &'a [vk::VertexInputAttributeDescription],
    topology: vk::PrimitiveTopology,
    cull: vk::CullModeFlags,
    /// Rasteriser depth bias: (constant factor, slope factor).
    depth_bias: Option<(f32, f32)>,
    /// Depth attachment format, depth write and compare op.
    depth: Option<(vk::Format, bool, vk::CompareOp)>,
    /// Colour attachment format and its blending.
    color: Option<(vk::Format, vk::PipelineColorBlendAttachmentState)>,
    /// Dynamic state beyond viewport and scissor (which every pipeline has dynamic).
    extra_dynamic: &'a [vk::DynamicState],
    /// Rasterisation samples (the attachments').
    samples: vk::SampleCountFlags,
}

/// Writes all four channels, no blending.
pub fn opaque() -> vk::PipelineColorBlendAttachmentState {
    vk::PipelineColorBlendAttachmentState::default().color_write_mask(vk::ColorComponentFlags::RGBA)
}

/// Porter-Duff "over" for premultiplied colour, alpha likewise: dst = src + (1 - src.a) dst.
pub fn premultiplied_over() -> vk::PipelineColorBlendAttachmentState {
    vk::PipelineColorBlendAttachmentState::default()
        .blend_enable(true)
        .src_color_blend_factor(vk::BlendFactor::ONE)
        .dst_color_blend_factor(vk::BlendFactor::ONE_MINUS_SRC_ALPHA)
        .color_blend_op(vk::BlendOp::ADD)
        .src_alpha_blend_factor(vk::BlendFactor::ONE)
        .dst_alpha_blend_factor(vk::BlendFactor::ONE_MINUS_SRC_ALPHA)
        .alpha_blend_op(vk::BlendOp::ADD)
        .color_write_mask(vk::ColorComponentFlags::RGBA)
}

impl<'a> GraphicsPipeline<'a> {
    pub fn new(name: &'a str, vert: &'a [u8]) -> Self {
        Self {
            name,
            vert,
            frag: None,
            frag_specialization: None,
            bindings: &[],
            attributes: &[],
            topology: vk::PrimitiveTopology::TRIANGLE_LIST,
            cull: vk::CullModeFlags::NONE,
            depth_bias: None,
            depth: None,
            color: None,
            extra_dynamic: &[],
            samples: vk::SampleCountFlags::TYPE_1,
        }
    }

    /// Render into attachments of `samples` samples.
    pub fn multisample(mut self, samples: vk::SampleCountFlags) -> Self {
        self.samples = samples;
        self
    }

    /// The fragment shader (none: a depth-only pass).
    pub fn fragment(mut self, spv: &'a [u8], specialization: Option<vk::SpecializationInfo<'a>>) -> Self {
        self.frag = Some(spv);
        self.frag_specialization = specialization;
        self
    }

    pub fn vertex_input(mut self, bindings: &'a [vk::VertexInputBindingDescription], attributes: &'a [vk::VertexInputAttributeDescription]) -> Self {
        self.bindings = bindings;
        self.attributes = attributes;
        self
    }

    pub fn topology(mut self, topology: vk::PrimitiveTopology) -> Self {
        self.topology = topology;
        self
    }

    /// Back-face culling with counter-clockwise front faces (meshes may still change both per
    /// draw when they are dynamic state).
    pub fn cull_back(mut self) -> Self {
        self.cull = vk::CullModeFlags::BACK;
        self
    }

    pub fn depth_bias(mut self, bias: Option<(f32, f32)>) -> Self {
        self.depth_bias = bias;
        self
    }

    /// A depth attachment of `format`, tested with `compare` and written when `write`.
    pub fn depth(mut self, format: vk::Format, write: bool, compare: vk::CompareOp) -> Self {
        self.depth = Some((format, write, compare));
        self
    }

    /// One colour attachment of `format`, blended by `blend` (see [`opaque`]).
    pub fn color(mut self, format: vk::Format, blend: vk::PipelineColorBlendAttachmentState) -> Self {
        self.color = Some((format, blend));
        self
    }

    pub fn dynamic(mut self, states: &'a [vk::DynamicState]) -> Self {
        self.extra_dynamic = states;
        self
    }

    /// Create the pipeline through the device's pipeline cache.
    pub fn build(&self, gpu: &Gpu, layout: vk::PipelineLayout) -> Result<vk::Pipeline> {
        let device = &gpu.device;
        // The modules are only needed while the pipeline is created: owned, so freed on return.
        let vert = gpu.own(shaders::module(device, self.vert).with_context(|| format!("the {} pipeline's vertex shader", self.name))?);
        let frag = gpu.own(self.frag.map(|f| shaders::module(device, f)).transpose().with_context(|| format!("the {} pipeline's fragment shader", self.name))?);
        let mut stages = vec![vk::PipelineShaderStageCreateInfo::default().stage(vk::ShaderStageFlags::VERTEX).module(*vert).name(c"main")];
        if let Some(f) = *frag {
            let mut stage = vk::PipelineShaderStageCreateInfo::default().stage(vk::ShaderStageFlags::FRAGMENT).module(f).name(c"main");
            if let Some(spec) = &self.frag_specialization {
                stage = stage.specialization_info(spec);
            }
            stages.push(stage);
        }
        let vertex_input = vk::PipelineVertexInputStateCreateInfo::default().vertex_binding_descriptions(self.bindings).vertex_attribute_descriptions(self.attributes);
        let input_assembly = vk::PipelineInputAssemblyStateCreateInfo::default().topology(self.topology);
        let viewport = vk::PipelineViewportStateCreateInfo::default().viewport_count(1).scissor_count(1);
        let mut raster = vk::PipelineRasterizationStateCreateInfo::default()
            .polygon_mode(vk::PolygonMode::FILL)
            .cull_mode(self.cull)
            .front_face(vk::FrontFace::COUNTER_CLOCKWISE)
            .line_width(1.0);
        if let Some((constant, slope)) = self.depth_bias {
            raster = raster.depth_bias_enable(true).depth_bias_constant_factor(constant).depth_bias_slope_factor(slope);
        }
        let multisample = vk::PipelineMultisampleStateCreateInfo::default().rasterization_samples(self.samples);
        let depth_stencil = self
            .depth
            .map(|(_, write, compare)| vk::PipelineDepthStencilStateCreateInfo::default().depth_test_enable(true).depth_write_enable(write).depth_compare_op(compare));
        let blend_attachments: Vec<_> = self.color.iter().map(|&(_, blend)| blend).collect();
        let blend = vk::PipelineColorBlendStateCreateInfo::default().attachments(&blend_attachments);
        let mut dynamic_states = vec![vk::DynamicState::VIEWPORT, vk::DynamicState::SCISSOR];
        dynamic_states.extend_from_slice(self.extra_dynamic);
        let dynamic = vk::PipelineDynamicStateCreateInfo::default().dynamic_states(&dynamic_states);
        let color_formats: Vec<_> = self.color.iter().map(|&(format, _)| format).collect();
        let mut rendering = vk::PipelineRenderingCreateInfo::default().color_attachment_formats(&color_formats);
        if let Some((format, _, _)) = self.depth {
            rendering = rendering.depth_attachment_format(format);
        }
        let mut info = vk::GraphicsPipelineCreateInfo::default()
            .stages(&stages)
            .vertex_input_state(&vertex_input)
            .input_assembly_state(&input_assembly)
            .viewport_state(&viewport)
            .rasterization_state(&raster)
            .multisample_state(&multisample)
            .color_blend_state(&blend)
            .dynamic_state(&dynamic)
            .layout(layout)
            .push_next(&mut rendering);
        if let Some(ds) = &depth_stencil {
            info = info.depth_stencil_state(ds);
        }
        let result = unsafe { device.create_graphics_pipelines(gpu.pipeline_cache, &[info], None) };
        let pipelines = result.map_err(|(_, e)| anyhow::anyhow!("creating the {} pipeline: {e}", self.name))?;
        Ok(pipelines[0])
    }
}

/// Pipelines a pass builds once per sample count of the camera's targets, the first time a
/// frame uses it: switching MSAA on builds the multisampled set without waiting for the device
/// (frames in flight keep theirs), switching back reuses the single-sampled one.
pub struct PerSamples<T> {
    sets: Vec<(vk::SampleCountFlags, T)>,
}

impl<T> Default for PerSamples<T> {
    fn default() -> Self {
        PerSamples { sets: Vec::new() }
    }
}

impl<T> PerSamples<T> {
    /// The set for `samples`, made by `make` if this is its first use.
    pub fn ensure(&mut self, samples: vk::SampleCountFlags, make: impl FnOnce(vk::SampleCountFlags) -> Result<T>) -> Result<&mut T> {
        let i = match self.sets.iter().position(|s| s.0 == samples) {
            Some(i) => i,
            None => {
                self.sets.push((samples, make(samples)?));
                self.sets.len() - 1
            }
        };
        Ok(&mut self.sets[i].1)
    }

    /// The set for `samples` (`ensure` made it before the frame).
    pub fn get(&self, samples: vk::SampleCountFlags) -> &T {
        self.sets.iter().find(|s| s.0 == samples).map(|s| &s.1).unwrap_or_else(|| panic!("no pipelines were made for {samples:?} samples"))
    }

    /// Every set made so far.
    pub fn iter(&self) -> impl Iterator<Item = &T> + '_ {
        self.sets.iter().map(|s| &s.1)
    }

    /// Every set made, emptied out (to destroy them).
    pub fn drain(&mut self) -> impl Iterator<Item = T> + '_ {
        self.sets.drain(..).map(|s| s.1)
    }
}
