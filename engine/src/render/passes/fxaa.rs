//! Post-process anti-aliasing (`Renderer::aa` = `AntiAliasing::Fxaa`): the tone map writes a
//! transient display-colour image instead of the output, and this pass filters it into the
//! output along the edges it finds (shaders/fxaa.frag). One full-screen pass: the cheap
//! alternative to multisampling; it blurs texture detail a little where edges are steep.

use crate::gpu::Gpu;
use crate::render::frame::{FrameCx, LDR};
use crate::render::graph::{Access, Io, Pass, Rec, OUTPUT};
use crate::render::fullscreen::FullscreenFilter;
use crate::render::shaders;
use anyhow::Result;
use ash::vk;
use bytemuck::{Pod, Zeroable};
use glam::Vec4;

/// Mirrors the push-constant block of shaders/fxaa.frag.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct FxaaPush {
    params: Vec4,
}

pub struct Fxaa {
    filter: FullscreenFilter,
}

impl Fxaa {
    pub fn new(gpu: &Gpu, color_format: vk::Format, frames_in_flight: usize) -> Result<Fxaa> {
        // Bilinear: the taps along the edge fall between pixels.
        let push = std::mem::size_of::<FxaaPush>() as u32;
        Ok(Fxaa { filter: FullscreenFilter::new(gpu, "fxaa", shaders::FXAA_FRAG, push, color_format, frames_in_flight, vk::Filter::LINEAR)? })
    }
}

impl Pass for Fxaa {
    fn name(&self) -> &'static str {
        "fxaa"
    }

    /// A non-indexed full-screen draw: see `Pass::counts_invocations`.
    fn counts_invocations(&self) -> bool {
        false
    }

    fn declare(&mut self, cx: &FrameCx, io: &mut Io) {
        if cx.settings.fxaa {
            io.uses(LDR, Access::SampledFragment).uses(OUTPUT, Access::ColorWrite);
        }
    }

    fn record(&mut self, _cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        let (input, output) = (rec.image(LDR), rec.image(OUTPUT));
        let e = output.extent;
        let push = FxaaPush { params: Vec4::new(1.0 / e.width as f32, 1.0 / e.height as f32, 0.0, 0.0) };
        self.filter.draw(rec, input.view, output, bytemuck::bytes_of(&push));
        Ok(())
    }

    fn destroy(&mut self, gpu: &Gpu) {
        self.filter.destroy(gpu);
    }
}
