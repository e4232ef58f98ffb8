//! The depth pre-pass: the camera's draw list depth only (alpha-tested where masked), so the
//! shading pass shades each pixel once (depth EQUAL).

use crate::render::frame::{FrameCx, DEPTH, SKINNED};
use crate::render::graph::{Access, Io, Pass, Rec, Rendering};
use crate::render::mesh_draw::DrawSetup;
use anyhow::Result;
use ash::vk;

pub struct Prepass;

impl Pass for Prepass {
    fn name(&self) -> &'static str {
        "prepass"
    }

    fn declare(&mut self, cx: &FrameCx, io: &mut Io) {
        if cx.settings.prepass {
            io.create(DEPTH, cx.settings.depth_desc(cx.gpu)).uses(DEPTH, Access::DepthWrite);
            if cx.animation.is_some() {
                io.uses(SKINNED, Access::VertexInput);
            }
        }
    }

    fn record(&mut self, cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        let depth = rec.image(DEPTH);
        // Reversed-Z: the far plane is depth 0.
        let rendering = Rendering::depth_only(depth, Some(0.0), vk::AttachmentStoreOp::STORE);
        let f = cx.frame;
        let setup = DrawSetup { frame_set: f.frame_set, batches: &f.view_batches, instances: f.instances, depth_test: true, cull: true, by_state: true };
        cx.draw_calls += cx.mesh.draw(rec, cx.scene, &rendering, &setup, |mat, _| cx.mesh.depth_for(mat, Some(cx.settings.samples)));
        Ok(())
    }
}
