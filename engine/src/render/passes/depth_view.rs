//! A debug pass: the camera's depth buffer, as grey, in place of the shaded frame (the
//! overlay's "depth view" switch, `Renderer::depth_view`). It overwrites the output, so the
//! graph drops the passes only the shaded frame needed (tone map, and shading after a pre-pass).

use crate::gpu::Gpu;
use crate::render::frame::{FrameCx, DEPTH};
use crate::render::graph::{Access, Io, Pass, Rec, OUTPUT};
use crate::render::sampled_input::SampledInput;
use crate::render::shaders;
use crate::render::tonemap::{draw_fullscreen, fullscreen_pipeline};
use anyhow::Result;
use ash::vk;
use bytemuck::{Pod, Zeroable};
use glam::Vec4;

/// Mirrors the push-constant block of shaders/depth_view.frag.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct DepthViewPush {
    params: Vec4,
}

pub struct DepthView {
    input: SampledInput,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
}

impl DepthView {
    pub fn new(gpu: &Gpu, color_format: vk::Format, frames_in_flight: usize) -> Result<DepthView> {
        let input = gpu.own(SampledInput::new(gpu, frames_in_flight, vk::Filter::NEAREST)?);
        let (layout, pipeline) = fullscreen_pipeline(gpu, "depth view", input.layout, std::mem::size_of::<DepthViewPush>() as u32, shaders::DEPTH_VIEW_FRAG, color_format)?;
        Ok(DepthView { input: input.keep(), layout, pipeline })
    }
}

impl Pass for DepthView {
    fn name(&self) -> &'static str {
        "depth view"
    }

    /// A non-indexed full-screen draw: see `Pass::counts_invocations`.
    fn counts_invocations(&self) -> bool {
        false
    }

    fn declare(&mut self, cx: &FrameCx, io: &mut Io) {
        if cx.settings.depth_view {
            io.uses(DEPTH, Access::SampledFragment).uses(OUTPUT, Access::ColorWrite);
        }
    }

    fn record(&mut self, _cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        let set = self.input.set(rec.gpu, rec.slot, rec.image(DEPTH).view);
        let push = DepthViewPush { params: Vec4::new(1.0, 0.0, 0.0, 0.0) };
        draw_fullscreen(rec, rec.image(OUTPUT), true, self.pipeline, self.layout, set, bytemuck::bytes_of(&push));
        Ok(())
    }

    fn destroy(&mut self, gpu: &Gpu) {
        self.input.destroy(gpu);
        unsafe {
            gpu.device.destroy_pipeline(self.pipeline, None);
            gpu.device.destroy_pipeline_layout(self.layout, None);
        }
    }
}
