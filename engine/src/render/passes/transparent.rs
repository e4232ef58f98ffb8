//! The transparent phase: glTF BLEND surfaces after the opaque ones, the sky and the boids,
//! one draw each from far to near (`FrameData::transparent_batches`), lit like opaque surfaces
//! and composited with the premultiplied "over" operator into the HDR target; depth tested
//! against the opaque depth and not written, so glass never hides what is behind it. Surfaces
//! that intersect, or one mesh's own overlapping triangles, stay in draw order (glTF accepts it).

use crate::render::frame::{FrameCx, DEPTH, HDR, SHADOW_MAP, SKINNED};
use crate::render::graph::{Access, Io, Pass, Rec, Rendering};
use crate::render::mesh_draw::{DrawSetup, LitPhase};
use anyhow::Result;
use ash::vk;

pub struct Transparent;

impl Pass for Transparent {
    fn name(&self) -> &'static str {
        "transparent"
    }

    fn declare(&mut self, cx: &FrameCx, io: &mut Io) {
        if cx.frame.transparent_batches.is_empty() {
            return;
        }
        io.uses(HDR, Access::ColorBlend).uses(DEPTH, Access::DepthTest);
        io.import(SHADOW_MAP, cx.shadow.map_ref()).uses(SHADOW_MAP, Access::SampledFragment);
        if cx.animation.is_some() {
            io.uses(SKINNED, Access::VertexInput);
        }
    }

    fn record(&mut self, cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        let f = cx.frame;
        let rendering = Rendering::color(rec.image(HDR), None).depth(rec.image(DEPTH), None, vk::AttachmentStoreOp::NONE);
        let setup = DrawSetup { frame_set: f.frame_set, batches: &f.transparent_batches, instances: f.instances, depth_test: true, cull: true, by_state: false };
        let (mesh, settings) = (cx.mesh, &cx.settings);
        cx.draw_calls += mesh.draw(rec, cx.scene, &rendering, &setup, |mat, lightmapped| mat.blend.then(|| mesh.lit(settings.samples, settings.lit_key(LitPhase::Blend, mat, lightmapped))));
        Ok(())
    }
}
