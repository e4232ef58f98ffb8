//! The shading pass: the camera's draw list into the HDR target, lit by lightmaps or by the
//! probes and the sun (reading the shadow map), after the pre-pass with depth EQUAL or alone
//! with a depth test of its own.

use crate::render::frame::{FrameCx, DEPTH, FRAGMENT_COUNTER, HDR, SHADOW_MAP, SKINNED};
use crate::render::graph::{Access, Io, Pass, Rec, Rendering};
use crate::render::mesh_draw::DrawSetup;
use crate::render::renderer::CLEAR_COLOR;
use anyhow::Result;
use ash::vk;

pub struct Shading;

impl Pass for Shading {
    fn name(&self) -> &'static str {
        "shading"
    }

    fn declare(&mut self, cx: &FrameCx, io: &mut Io) {
        io.create(HDR, cx.settings.hdr_desc()).uses(HDR, Access::ColorWrite);
        io.create(DEPTH, cx.settings.depth_desc(cx.gpu));
        io.uses(DEPTH, if cx.settings.prepass { Access::DepthTest } else { Access::DepthWrite });
        // Bound in set 0 whether or not this frame drew it.
        io.import(SHADOW_MAP, cx.shadow.map_ref()).uses(SHADOW_MAP, Access::SampledFragment);
        if cx.animation.is_some() {
            io.uses(SKINNED, Access::VertexInput);
        }
        if counts(cx) {
            io.uses(FRAGMENT_COUNTER, Access::StorageWriteFragment);
        }
    }

    fn record(&mut self, cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        let (hdr, depth) = (rec.image(HDR), rec.image(DEPTH));
        let f = cx.frame;
        let prepass = cx.settings.prepass;
        // Alpha 0 marks the clear colour as "no surface" for the tone map, which leaves it as it
        // is: it is display-referred, not radiance.
        let [r, g, b, _] = CLEAR_COLOR;
        let color = Rendering::color(hdr, Some([r, g, b, 0.0]));
        // After a pre-pass depth is only tested (and kept as it is); alone, the pass clears and
        // writes it, and stores it when the sky, boids, particles or the transparent phase test
        // against it next.
        let later = f.draw_particles || f.draw_boids || f.sky.is_some() || !f.transparent_batches.is_empty();
        let rendering = match prepass {
            true => color.depth(depth, None, vk::AttachmentStoreOp::NONE),
            false => color.depth(depth, Some(0.0), if later { vk::AttachmentStoreOp::STORE } else { vk::AttachmentStoreOp::DONT_CARE }),
        };
        let count = counts(cx);
        let shade = [0, 1].map(|lightmapped| cx.mesh.camera(cx.settings.samples).shade[lightmapped].pick(prepass, count));
        let setup = DrawSetup { frame_set: f.frame_set, batches: &f.view_batches, instances: f.instances, depth_test: prepass || cx.settings.depth_test, cull: true };
        cx.draw_calls += cx.mesh.draw(rec, cx.scene, &rendering, &setup, |mat, lightmapped| (!mat.blend).then_some(shade[lightmapped as usize]));
        Ok(())
    }
}

/// Whether this frame counts the fragments it shades.
fn counts(cx: &FrameCx) -> bool {
    cx.settings.count_fragments && cx.mesh.can_count()
}
