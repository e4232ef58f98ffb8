//! Instanced boid meshes into the HDR target, depth tested and written against the scene's.

use crate::render::frame::{FrameCx, DEPTH, HDR};
use crate::render::graph::{Access, Io, Pass, Rec};
use anyhow::Result;

pub struct Boids;

impl Pass for Boids {
    fn name(&self) -> &'static str {
        "boids"
    }

    /// Non-indexed instanced draws: see `Pass::counts_invocations`.
    fn counts_invocations(&self) -> bool {
        false
    }

    fn declare(&mut self, cx: &FrameCx, io: &mut Io) {
        // Only with boids in view: lavapipe 22.3 crashes on a depth-writing rendering without draws.
        if cx.frame.draw_boids {
            io.uses(HDR, Access::ColorBlend).uses(DEPTH, Access::DepthReadWrite);
        }
    }

    fn record(&mut self, cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        cx.boids.record(rec, cx.scene, cx.frame.frame_set, rec.image(HDR), rec.image(DEPTH), cx.settings.samples);
        Ok(())
    }
}
