//! Post-process anti-aliasing (`Renderer::aa` = `AntiAliasing::Fxaa`): the tone map writes a
//! transient display-colour image instead of the output, and this pass filters it into the
//! output along the edges it finds (shaders/fxaa.frag). One full-screen pass: the cheap
//! alternative to multisampling; it blurs texture detail a little where edges are steep. Below
//! the output's size it filters the upscaler's input at the render scale instead (`LDR_LOW` into
//! `LDR_LOW_AA`, gamma 2): the frame's pixels are anti-aliased where they are drawn, and only
//! the upscaler touches every output pixel.

use crate::gpu::Gpu;
use crate::render::frame::{FrameCx, LDR, LDR_LOW, LDR_LOW_AA, LOW_FORMAT};
use crate::render::graph::{Access, ImageDesc, Io, Pass, Rec, OUTPUT};
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
    /// At the render scale: GAMMA2 (specialisation constant 0), into `LOW_FORMAT`.
    low: FullscreenFilter,
}

impl Fxaa {
    pub fn new(gpu: &Gpu, color_format: vk::Format, frames_in_flight: usize) -> Result<Fxaa> {
        // Bilinear: the taps along the edge fall between pixels.
        let push = std::mem::size_of::<FxaaPush>() as u32;
        let filter = gpu.own(FullscreenFilter::new_variants(gpu, "fxaa", shaders::FXAA_FRAG.spv(), push, color_format, frames_in_flight, vk::Filter::LINEAR, &[0])?);
        let low = FullscreenFilter::new_variants(gpu, "fxaa (render scale)", shaders::FXAA_FRAG.spv(), push, LOW_FORMAT, frames_in_flight, vk::Filter::LINEAR, &[1])?;
        Ok(Fxaa { filter: filter.keep(), low })
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
        if cx.settings.fxaa && cx.settings.upscale {
            io.create(LDR_LOW_AA, ImageDesc::render(LOW_FORMAT));
            io.uses(LDR_LOW, Access::SampledFragment).uses(LDR_LOW_AA, Access::ColorWrite);
        } else if cx.settings.fxaa {
            io.uses(LDR, Access::SampledFragment).uses(OUTPUT, Access::ColorWrite);
        }
    }

    fn record(&mut self, cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        if cx.settings.upscale {
            let (input, output) = (rec.image(LDR_LOW), rec.image(LDR_LOW_AA));
            // The image is the output's size; the drawn region is the render scale's.
            let full = cx.output;
            let (w, h) = (full.width as f32, full.height as f32);
            let push = FxaaPush { params: Vec4::new(1.0 / w, 1.0 / h, input.extent.width as f32 / w, input.extent.height as f32 / h) };
            self.low.draw(rec, input.view, output, bytemuck::bytes_of(&push));
            return Ok(());
        }
        let (input, output) = (rec.image(LDR), rec.image(OUTPUT));
        let e = output.extent;
        let push = FxaaPush { params: Vec4::new(1.0 / e.width as f32, 1.0 / e.height as f32, 0.0, 0.0) };
        self.filter.draw(rec, input.view, output, bytemuck::bytes_of(&push));
        Ok(())
    }

    fn destroy(&mut self, gpu: &Gpu) {
        self.filter.destroy(gpu);
        self.low.destroy(gpu);
    }
}
