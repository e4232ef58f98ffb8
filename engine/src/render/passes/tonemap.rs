//! The tone map: the HDR target into the output (`tonemap`).

use crate::render::frame::{FrameCx, HDR};
use crate::render::graph::{Access, Io, Pass, Rec, OUTPUT};
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

    fn declare(&mut self, _cx: &FrameCx, io: &mut Io) {
        io.uses(HDR, Access::SampledFragment).uses(OUTPUT, Access::ColorWrite);
    }

    fn record(&mut self, cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        let f = cx.frame;
        cx.tonemap.record(rec, rec.image(HDR), rec.image(OUTPUT), f.exposure, f.tone_map);
        Ok(())
    }
}
