//! The tone map: the HDR target into the output (`tonemap`), or into the FXAA pass's input.

use crate::render::frame::{FrameCx, HDR, LDR};
use crate::render::graph::{Access, ImageDesc, Io, Pass, Rec, ResourceId, Size, OUTPUT};
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
        if cx.settings.fxaa {
            io.create(LDR, ImageDesc { format: cx.tonemap.display_format, size: Size::Output });
        }
        io.uses(HDR, Access::SampledFragment).uses(target(cx), Access::ColorWrite);
    }

    fn record(&mut self, cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        let f = cx.frame;
        let out = rec.image(target(cx));
        cx.tonemap.record(rec, rec.image(HDR), out, f.exposure, f.tone_map);
        Ok(())
    }
}

/// Where the tone map writes: the output, or FXAA's input.
fn target(cx: &FrameCx) -> ResourceId {
    if cx.settings.fxaa {
        LDR
    } else {
        OUTPUT
    }
}
