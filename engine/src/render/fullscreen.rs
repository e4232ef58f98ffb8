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
    /// One pipeline per variant (`new_variants`), or the one.
    pipelines: Vec<vk::Pipeline>,
}

impl FullscreenFilter {
    /// `frag` writing `format`, reading its input with `filter` (clamped at the edges), with
    /// `push` bytes of fragment push constants.
    pub fn new(gpu: &Gpu, name: &str, frag: &[u8], push: u32, format: vk::Format, frames_in_flight: usize, filter: vk::Filter) -> Result<FullscreenFilter> {
        Self::new_variants(gpu, name, frag, push, format, frames_in_flight, filter, &[])
    }

    /// `new` with a pipeline for each of `variants`, the values of the shader's specialisation
    /// constant 0 (`draw_variant` picks one by index): a variant carries only its own code,
    /// where a push-constant branch would run both sides masked on a CPU device.
    #[allow(clippy::too_many_arguments)]
    pub fn new_variants(gpu: &Gpu, name: &str, frag: &[u8], push: u32, format: vk::Format, frames_in_flight: usize, filter: vk::Filter, variants: &[u32]) -> Result<FullscreenFilter> {
        let d = &gpu.device;
        // Owned until the filter is whole: an error frees what was made before it.
        let input = gpu.own(SampledInput::new(gpu, frames_in_flight, filter)?);
        let ranges = [vk::PushConstantRange::default().stage_flags(vk::ShaderStageFlags::FRAGMENT).size(push)];
        let set_layouts = [input.layout];
        let layout = gpu.own(unsafe { d.create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts).push_constant_ranges(&ranges), None)? });
        let mut pipelines = gpu.own(Vec::new());
        let entries = [vk::SpecializationMapEntry { constant_id: 0, offset: 0, size: 4 }];
        for value in variants.iter().map(Some).chain(variants.is_empty().then_some(None)) {
            let bytes = value.map(|v| v.to_le_bytes());
            let spec = bytes.as_ref().map(|b| vk::SpecializationInfo::default().map_entries(&entries).data(b));
            pipelines.push(GraphicsPipeline::new(name, shaders::FULLSCREEN_VERT.spv()).fragment(frag, spec).color(format, opaque()).build(gpu, *layout)?);
        }
        Ok(FullscreenFilter { input: input.keep(), layout: layout.keep(), pipelines: pipelines.keep() })
    }

    /// One full-screen triangle into `target` (every pixel written, the old contents not
    /// loaded), sampling `input` through this frame slot's set.
    pub fn draw(&mut self, rec: &Rec, input: vk::ImageView, target: ImageRef, push: &[u8]) {
        self.draw_variant(rec, input, target, push, 0);
    }

    /// `draw` with the pipeline of `new_variants`'s variant `variant` (an index).
    pub fn draw_variant(&mut self, rec: &Rec, input: vk::ImageView, target: ImageRef, push: &[u8], variant: usize) {
        let set = self.input.set(rec.gpu, rec.slot, input);
        let (d, cb) = (&rec.gpu.device, rec.cb);
        rec.begin_rendering(&Rendering::color_overwritten(target));
        unsafe {
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, self.pipelines[variant]);
            d.cmd_bind_descriptor_sets(cb, vk::PipelineBindPoint::GRAPHICS, self.layout, 0, &[set], &[]);
            d.cmd_push_constants(cb, self.layout, vk::ShaderStageFlags::FRAGMENT, 0, push);
            d.cmd_draw(cb, 3, 1, 0, 0);
        }
        rec.end_rendering();
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        self.input.destroy(gpu);
        unsafe {
            for &p in &self.pipelines {
                gpu.device.destroy_pipeline(p, None);
            }
            gpu.device.destroy_pipeline_layout(self.layout, None);
        }
    }
}
