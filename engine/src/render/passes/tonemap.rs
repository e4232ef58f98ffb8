//! The tone map: the HDR target into the output (`tonemap`), or into the FXAA pass's input, or,
//! below the output's size, into the upscaler's input (gamma 2, the render scale's size).

use crate::render::frame::{FrameCx, LDR, LDR_LOW, LOW_FORMAT};
use crate::render::graph::{Access, ImageDesc, Io, Pass, Rec, ResourceId, OUTPUT};
use anyhow::Result;

pub struct ToneMapPass;

impl Pass for ToneMapPass {
    fn name(&self) -> &'static str {
        "tonemap"
    }

    /// A non-indexed full-screen draw: see `Pass::counts_invocations`.
    fn counts_invocations(&self) -> bool {
        false
    }

    fn declare(&mut self, cx: &FrameCx, io: &mut Io) {
        if cx.settings.upscale {
            io.create(LDR_LOW, ImageDesc::render(LOW_FORMAT));
        } else if cx.settings.fxaa {
            io.create(LDR, ImageDesc::output(cx.tonemap.display_format));
        }
        io.uses(cx.settings.tone_map_input(), Access::SampledFragment).uses(target(cx), Access::ColorWrite);
    }

    fn record(&mut self, cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        let f = cx.frame;
        let out = rec.image(target(cx));
        cx.tonemap.record(rec, rec.image(cx.settings.tone_map_input()), out, f.exposure, f.tone_map, f.sky);
        Ok(())
    }
}

/// Where the tone map writes: the output, FXAA's input or the upscaler's.
fn target(cx: &FrameCx) -> ResourceId {
    if cx.settings.upscale {
        LDR_LOW
    } else if cx.settings.fxaa {
        LDR
    } else {
        OUTPUT
    }
}
