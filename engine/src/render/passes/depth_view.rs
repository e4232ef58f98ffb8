//! A debug pass: the camera's depth buffer, as grey, in place of the shaded frame (the
//! overlay's "depth view" switch, `Renderer::depth_view`). It overwrites the output, so the
//! graph drops the passes only the shaded frame needed (tone map, and shading after a pre-pass).

use crate::gpu::Gpu;
use crate::render::frame::{FrameCx, DEPTH};
use crate::render::graph::{Access, Io, Pass, Rec, OUTPUT};
use crate::render::fullscreen::FullscreenFilter;
use crate::render::shaders;
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
    filter: FullscreenFilter,
}

impl DepthView {
    pub fn new(gpu: &Gpu, color_format: vk::Format, frames_in_flight: usize) -> Result<DepthView> {
        let push = std::mem::size_of::<DepthViewPush>() as u32;
        Ok(DepthView { filter: FullscreenFilter::new(gpu, "depth view", shaders::DEPTH_VIEW_FRAG.spv(), push, color_format, frames_in_flight, vk::Filter::NEAREST)? })
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
        let push = DepthViewPush { params: Vec4::new(1.0, 0.0, 0.0, 0.0) };
        self.filter.draw(rec, rec.image(DEPTH).view, rec.image(OUTPUT), bytemuck::bytes_of(&push));
        Ok(())
    }

    fn destroy(&mut self, gpu: &Gpu) {
        self.filter.destroy(gpu);
    }
}
