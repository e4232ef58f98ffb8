//! Skinning and morphing of the animated instances the frame draws or casts shadows with
//! (compute, `animated`), once, before every pass that reads the skinned vertices.

use crate::render::frame::{FrameCx, SKINNED};
use crate::render::graph::{Access, Io, Pass, Rec};
use anyhow::Result;

pub struct Skinning;

impl Pass for Skinning {
    fn name(&self) -> &'static str {
        "skinning"
    }

    /// No draws: no vertex or fragment shader invocations to count (and a statistics query on
    /// lavapipe is not free).
    fn counts_invocations(&self) -> bool {
        false
    }

    fn declare(&mut self, cx: &FrameCx, io: &mut Io) {
        if cx.animation.is_some() {
            io.uses(SKINNED, Access::StorageWriteCompute);
        }
    }

    fn record(&mut self, cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        let casters = if cx.frame.draw_shadow { &cx.shadow.casters[..] } else { &[] };
        if let Some(a) = cx.animation.as_deref_mut() {
            a.record(rec.gpu, rec.cb, cx.slot, cx.draws, casters);
        }
        Ok(())
    }
}
