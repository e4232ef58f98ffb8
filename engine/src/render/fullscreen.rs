//! A full-screen filter: one fragment shader over one full-screen triangle that samples one
//! image (a descriptor set per frame slot) and writes every pixel of another, with push
//! constants. The tone map, FXAA and the depth view are each one of these.

use crate::gpu::{opaque, Gpu, GraphicsPipeline};
use crate::render::graph::{ImageRef, Rec, Rendering};
use crate::render::sampled_input::SampledInput;
use crate::render::shaders;
use anyhow::Result;
use ash::vk;

pub struct FullscreenFilter {
    input: SampledInput,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
}

impl FullscreenFilter {
    /// `frag` writing `format`, reading its input with `filter` (clamped at the edges), with
    /// `push` bytes of fragment push constants.
    pub fn new(gpu: &Gpu, name: &str, frag: &[u8], push: u32, format: vk::Format, frames_in_flight: usize, filter: vk::Filter) -> Result<FullscreenFilter> {
        let d = &gpu.device;
        // Owned until the filter is whole: an error frees what was made before it.
        let input = gpu.own(SampledInput::new(gpu, frames_in_flight, filter)?);
        let ranges = [vk::PushConstantRange::default().stage_flags(vk::ShaderStageFlags::FRAGMENT).size(push)];
        let set_layouts = [input.layout];
        let layout = gpu.own(unsafe { d.create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts).push_constant_ranges(&ranges), None)? });
        let pipeline = GraphicsPipeline::new(name, shaders::FULLSCREEN_VERT).fragment(frag, None).color(format, opaque()).build(gpu, *layout)?;
        Ok(FullscreenFilter { input: input.keep(), layout: layout.keep(), pipeline })
    }

    /// One full-screen triangle into `target` (every pixel written, the old contents not
    /// loaded), sampling `input` through this frame slot's set.
    pub fn draw(&mut self, rec: &Rec, input: vk::ImageView, target: ImageRef, push: &[u8]) {
        let set = self.input.set(rec.gpu, rec.slot, input);
        let (d, cb) = (&rec.gpu.device, rec.cb);
        rec.begin_rendering(&Rendering::color_overwritten(target));
        unsafe {
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, self.pipeline);
            d.cmd_bind_descriptor_sets(cb, vk::PipelineBindPoint::GRAPHICS, self.layout, 0, &[set], &[]);
            d.cmd_push_constants(cb, self.layout, vk::ShaderStageFlags::FRAGMENT, 0, push);
            d.cmd_draw(cb, 3, 1, 0, 0);
        }
        rec.end_rendering();
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        self.input.destroy(gpu);
        unsafe {
            gpu.device.destroy_pipeline(self.pipeline, None);
            gpu.device.destroy_pipeline_layout(self.layout, None);
        }
    }
}
