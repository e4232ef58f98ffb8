//! Blended particle billboards into the HDR target, depth tested against the scene's.

use crate::render::frame::{FrameCx, DEPTH, HDR};
use crate::render::graph::{Access, Io, Pass, Rec};
use anyhow::Result;

pub struct Particles;

impl Pass for Particles {
    fn name(&self) -> &'static str {
        "particles"
    }

    /// Non-indexed instanced draws: see `Pass::counts_invocations`.
    fn counts_invocations(&self) -> bool {
        false
    }

    fn declare(&mut self, cx: &FrameCx, io: &mut Io) {
        if cx.frame.draw_particles {
            io.uses(HDR, Access::ColorBlend).uses(DEPTH, Access::DepthTest);
        }
    }

    fn record(&mut self, cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        let f = cx.frame;
        cx.particles.record(rec, f.frame_set, rec.image(HDR), rec.image(DEPTH), cx.settings.samples, f.camera_right, f.camera_up);
        Ok(())
    }
}
