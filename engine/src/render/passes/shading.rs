//! The shading pass: the camera's draw list into the HDR target, lit by lightmaps or by the
//! probes and the sun (reading the shadow map), after the pre-pass with depth EQUAL or alone
//! with a depth test of its own.

use crate::render::frame::{FrameCx, DEPTH, FRAGMENT_COUNTER, HDR, SHADOW_MAP, SKINNED};
use crate::render::graph::{Access, Io, Pass, Rec, Rendering};
use crate::render::mesh_draw::{DrawSetup, LitPhase};
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
        if cx.settings.count_fragments {
            io.uses(FRAGMENT_COUNTER, Access::StorageWriteFragment);
        }
    }

    fn record(&mut self, cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        let (hdr, depth) = (rec.image(HDR), rec.image(DEPTH));
        let f = cx.frame;
        let prepass = cx.settings.prepass;
        // Alpha 0 marks "no surface" for the tone map: with a sky it puts the sky there (the
        // clear is then zero radiance, what premultiplied compositing over the sky needs);
        // without, it leaves the clear colour as it is (display-referred, not radiance).
        let [r, g, b, _] = CLEAR_COLOR;
        let clear = if f.sky.is_some() { [0.0; 4] } else { [r, g, b, 0.0] };
        let color = Rendering::color(hdr, Some(clear));
        // After a pre-pass depth is only tested (and kept as it is); alone, the pass clears and
        // writes it, and stores it when the boids, particles or the transparent phase test
        // against it next.
        let later = f.draw_particles || f.draw_boids || !f.transparent_batches.is_empty();
        let rendering = match prepass {
            true => color.depth(depth, None, vk::AttachmentStoreOp::NONE),
            false => color.depth(depth, Some(0.0), if later { vk::AttachmentStoreOp::STORE } else { vk::AttachmentStoreOp::DONT_CARE }),
        };
        if f.view_batches.is_empty() {
            // Nothing opaque in view (glass alone): clear with a command inside the rendering.
            // Lavapipe 22.3 crashes (SIGSEGV in its execution thread) when a rendering that
            // draws nothing clears by its load op and a later rendering loads the attachments.
            clear_without_draws(rec, &rendering, clear);
            return Ok(());
        }
        let phase = if prepass { LitPhase::Equal } else { LitPhase::Plain };
        let (mesh, settings) = (cx.mesh, &cx.settings);
        let setup = DrawSetup { frame_set: f.frame_set, batches: &f.view_batches, instances: f.instances, depth_test: prepass || settings.depth_test, cull: true, by_state: true };
        cx.draw_calls += mesh.draw(rec, cx.scene, &rendering, &setup, |mat, lightmapped| (!mat.blend).then(|| mesh.lit(settings.samples, settings.lit_key(phase, mat, lightmapped))));
        Ok(())
    }
}

/// Clear the colour (to `color`) and the depth (to the far plane, 0) of `rendering`'s whole
/// area with vkCmdClearAttachments.
fn clear_without_draws(rec: &Rec, rendering: &Rendering, color: [f32; 4]) {
    let extent = rec.image(HDR).extent;
    let rect = [vk::ClearRect { rect: vk::Rect2D { offset: vk::Offset2D::default(), extent }, base_array_layer: 0, layer_count: 1 }];
    let attachments = [
        vk::ClearAttachment { aspect_mask: vk::ImageAspectFlags::COLOR, color_attachment: 0, clear_value: vk::ClearValue { color: vk::ClearColorValue { float32: color } } },
        vk::ClearAttachment { aspect_mask: vk::ImageAspectFlags::DEPTH, color_attachment: 0, clear_value: vk::ClearValue { depth_stencil: vk::ClearDepthStencilValue { depth: 0.0, stencil: 0 } } },
    ];
    rec.begin_rendering(rendering);
    unsafe { rec.gpu.device.cmd_clear_attachments(rec.cb, &attachments, &rect) };
    rec.end_rendering();
}
