//! The static casters' depth from the sun, drawn into the shadow map's cache only when they
//! changed (`SunShadow::prepare` decides); `shadow_copy` starts each frame's map from it.

use crate::render::frame::{FrameCx, SHADOW_CACHE, SKINNED};
use crate::render::graph::{Access, Io, Pass, Rec, Rendering};
use crate::render::mesh_draw::DrawSetup;
use anyhow::Result;
use ash::vk;

pub struct ShadowStatic;

impl Pass for ShadowStatic {
    fn name(&self) -> &'static str {
        "shadow static"
    }

    fn declare(&mut self, cx: &FrameCx, io: &mut Io) {
        let s = cx.shadow;
        if cx.frame.draw_shadow && !s.static_casters.is_empty() && s.redraw_static {
            io.import(SHADOW_CACHE, s.cache_ref()).uses(SHADOW_CACHE, Access::DepthWrite);
            if cx.animation.is_some() {
                io.uses(SKINNED, Access::VertexInput);
            }
        }
    }

    fn record(&mut self, cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        cx.draw_calls += draw_casters(cx, rec, SHADOW_CACHE, Some(1.0), &cx.frame.shadow.statics);
        Ok(())
    }
}

/// One depth-only rendering of `batches` from the sun into `target`, cleared to `clear` or on
/// top of what it holds; returns the draw calls. Shared by the three shadow passes' drawing two.
pub(super) fn draw_casters(cx: &FrameCx, rec: &Rec, target: crate::render::graph::ResourceId, clear: Option<f32>, batches: &[crate::render::batches::Batch]) -> u32 {
    let rendering = Rendering::depth_only(rec.image(target), clear, vk::AttachmentStoreOp::STORE);
    let setup = DrawSetup { frame_set: cx.shadow.sets[cx.slot], batches, instances: cx.frame.instances, depth_test: true, cull: false, by_state: true };
    cx.mesh.draw(rec, cx.scene, &rendering, &setup, |mat, _| cx.mesh.depth_for(mat, None))
}
