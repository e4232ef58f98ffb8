//! The sky pass: the level's sky (a uniform radiance in nits, the one the baker lit the level
//! with) and the sun's disc, drawn where the shading pass left the far plane, before boids,
//! particles and the tone map, so the background goes through the same exposure and operator
//! as every surface. Runs only for a baked level with a sky or a sun (`FrameData::sky`).

use crate::gpu::{opaque, Gpu, GraphicsPipeline, PerSamples};
use crate::render::frame::{FrameCx, SkyParams, DEPTH, HDR};
use crate::render::graph::{Access, Io, Pass, Rec, Rendering};
use crate::render::shaders;
use crate::render::tonemap::HDR_FORMAT;
use anyhow::Result;
use ash::vk;

pub struct Sky {
    layout: vk::PipelineLayout,
    /// Made for a sample count when a frame first draws the sky with it.
    pipelines: PerSamples<vk::Pipeline>,
}

impl Sky {
    pub fn new(gpu: &Gpu) -> Result<Sky> {
        let d = &gpu.device;
        let ranges = [vk::PushConstantRange::default().stage_flags(vk::ShaderStageFlags::FRAGMENT).size(std::mem::size_of::<SkyParams>() as u32)];
        let layout = unsafe { d.create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default().push_constant_ranges(&ranges), None)? };
        Ok(Sky { layout, pipelines: PerSamples::default() })
    }
}

/// The sky's pipeline for targets of `samples` samples. The full-screen triangle lies at depth
/// 0, the reverse-Z far plane the depth buffer is cleared to: EQUAL passes exactly the pixels
/// (or samples) no surface covered.
fn pipeline(gpu: &Gpu, layout: vk::PipelineLayout, samples: vk::SampleCountFlags) -> Result<vk::Pipeline> {
    GraphicsPipeline::new("sky", shaders::FULLSCREEN_VERT)
        .fragment(shaders::SKY_FRAG, None)
        .depth(gpu.caps.depth_format, false, vk::CompareOp::EQUAL)
        .color(HDR_FORMAT, opaque())
        .multisample(samples)
        .build(gpu, layout)
}

impl Pass for Sky {
    fn name(&self) -> &'static str {
        "sky"
    }

    /// A non-indexed full-screen draw: see `Pass::counts_invocations`.
    fn counts_invocations(&self) -> bool {
        false
    }

    fn declare(&mut self, cx: &FrameCx, io: &mut Io) {
        if cx.frame.sky.is_some() {
            // Loaded and drawn on: only the pixels no surface covered change.
            io.uses(HDR, Access::ColorBlend).uses(DEPTH, Access::DepthTest);
        }
    }

    fn record(&mut self, cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        let Some(params) = cx.frame.sky else { return Ok(()) };
        let (d, cb) = (&rec.gpu.device, rec.cb);
        let layout = self.layout;
        let pipeline = *self.pipelines.ensure(cx.settings.samples, |s| pipeline(rec.gpu, layout, s))?;
        let rendering = Rendering::color(rec.image(HDR), None).depth(rec.image(DEPTH), None, vk::AttachmentStoreOp::NONE);
        rec.begin_rendering(&rendering);
        unsafe {
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, pipeline);
            d.cmd_push_constants(cb, self.layout, vk::ShaderStageFlags::FRAGMENT, 0, bytemuck::bytes_of(&params));
            d.cmd_draw(cb, 3, 1, 0, 0);
        }
        rec.end_rendering();
        Ok(())
    }

    fn destroy(&mut self, gpu: &Gpu) {
        unsafe {
            for pipeline in self.pipelines.drain() {
                gpu.device.destroy_pipeline(pipeline, None);
            }
            gpu.device.destroy_pipeline_layout(self.layout, None);
        }
    }
}
