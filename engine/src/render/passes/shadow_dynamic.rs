//! The sun's shadow map for dynamic objects: every caster when none is static, otherwise the
//! dynamic casters on top of the copied static depth.

use super::shadow_static::draw_casters;
use crate::render::frame::{FrameCx, SHADOW_MAP, SKINNED};
use crate::render::graph::{Access, Io, Pass, Rec};
use anyhow::Result;

pub struct ShadowDynamic;

impl Pass for ShadowDynamic {
    fn name(&self) -> &'static str {
        "shadow"
    }

    fn declare(&mut self, cx: &FrameCx, io: &mut Io) {
        let s = cx.shadow;
        if !cx.frame.draw_shadow {
            return;
        }
        let access = match (s.static_casters.is_empty(), s.dynamic_casters.is_empty()) {
            (true, _) => Access::DepthWrite,
            (false, false) => Access::DepthReadWrite,
            (false, true) => return,
        };
        io.import(SHADOW_MAP, s.map_ref()).uses(SHADOW_MAP, access);
        if cx.animation.is_some() {
            io.uses(SKINNED, Access::VertexInput);
        }
    }

    fn record(&mut self, cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        let f = cx.frame;
        let (clear, batches) = if cx.shadow.static_casters.is_empty() { (Some(1.0), &f.shadow.all) } else { (None, &f.shadow.dynamics) };
        cx.draw_calls += draw_casters(cx, rec, SHADOW_MAP, clear, batches);
        Ok(())
    }
}
