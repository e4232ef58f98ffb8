//! The spatial upscaler: below the output's size (`Settings::upscale`), the tone-mapped frame
//! (`LDR_LOW`, the render scale's region) resampled to the output by FSR 1's edge-adaptive
//! upsampler (shaders/upscale.frag), or on CPU devices the Catmull-Rom cubic (`Upscaler`). One
//! full-screen pass at the output's size: the only one of
//! the frame when it is on (the tone map runs at the render scale, before it).

use crate::gpu::Gpu;
use crate::render::frame::{FrameCx, LDR_LOW, LDR_LOW_AA};
use crate::render::fullscreen::FullscreenFilter;
use crate::render::graph::{Access, Io, Pass, Rec, OUTPUT};
use crate::render::scale::Upscaler;
use crate::render::shaders;
use anyhow::Result;
use ash::vk;
use bytemuck::{Pod, Zeroable};
use glam::Vec4;

/// Mirrors the push-constant block of shaders/upscale.frag.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct UpscalePush {
    /// xy: input texels per output pixel; zw: the input region's size in texels.
    scale: Vec4,
}

pub struct Upscale {
    filter: FullscreenFilter,
}

impl Upscale {
    pub fn new(gpu: &Gpu, color_format: vk::Format, frames_in_flight: usize) -> Result<Upscale> {
        let push = std::mem::size_of::<UpscalePush>() as u32;
        // Variants by `Upscaler`: EASU (CUBIC off), the Catmull-Rom cubic (on).
        Ok(Upscale { filter: FullscreenFilter::new_variants(gpu, "upscale", shaders::UPSCALE_FRAG.spv(), push, color_format, frames_in_flight, vk::Filter::NEAREST, &[0, 1])? })
    }
}

impl Pass for Upscale {
    fn name(&self) -> &'static str {
        "upscale"
    }

    /// A non-indexed full-screen draw: see `Pass::counts_invocations`.
    fn counts_invocations(&self) -> bool {
        false
    }

    fn declare(&mut self, cx: &FrameCx, io: &mut Io) {
        if cx.settings.upscale {
            io.uses(input(cx), Access::SampledFragment).uses(OUTPUT, Access::ColorWrite);
        }
    }

    fn record(&mut self, cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        let (input, output) = (rec.image(input(cx)), rec.image(OUTPUT));
        let (i, o) = (input.extent, output.extent);
        let push = UpscalePush { scale: Vec4::new(i.width as f32 / o.width as f32, i.height as f32 / o.height as f32, i.width as f32, i.height as f32) };
        let variant = match cx.settings.upscaler {
            Upscaler::Easu => 0,
            Upscaler::Cubic => 1,
        };
        self.filter.draw_variant(rec, input.view, output, bytemuck::bytes_of(&push), variant);
        Ok(())
    }

    fn destroy(&mut self, gpu: &Gpu) {
        self.filter.destroy(gpu);
    }
}

/// The tone-mapped frame at the render scale, after FXAA when it is on.
fn input(cx: &FrameCx) -> crate::render::graph::ResourceId {
    if cx.settings.fxaa {
        LDR_LOW_AA
    } else {
        LDR_LOW
    }
}
