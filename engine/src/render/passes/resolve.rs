//! The MSAA resolve: with a multisampled camera target, each pixel's samples averaged into the
//! single-sampled image the tone map reads (`HDR_RESOLVED`), after the last pass that draws
//! into the target. The average is of radiance, before the tone map, as Godot, Unity's URP and
//! Bevy resolve.

use crate::render::frame::{FrameCx, HDR, HDR_RESOLVED};
use crate::render::graph::{Access, ImageDesc, Io, Pass, Rec};
use crate::render::tonemap::HDR_FORMAT;
use anyhow::Result;
use ash::vk;

pub struct Resolve;

impl Pass for Resolve {
    fn name(&self) -> &'static str {
        "resolve"
    }

    fn declare(&mut self, cx: &FrameCx, io: &mut Io) {
        if cx.settings.multisampled() {
            io.create(HDR_RESOLVED, ImageDesc::render(HDR_FORMAT));
            io.uses(HDR, Access::ResolveSrc).uses(HDR_RESOLVED, Access::ResolveDst);
        }
    }

    fn record(&mut self, _cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        let (src, dst) = (rec.image(HDR), rec.image(HDR_RESOLVED));
        let layers = vk::ImageSubresourceLayers { aspect_mask: vk::ImageAspectFlags::COLOR, mip_level: 0, base_array_layer: 0, layer_count: 1 };
        let region = vk::ImageResolve {
            src_subresource: layers,
            dst_subresource: layers,
            extent: vk::Extent3D { width: src.extent.width, height: src.extent.height, depth: 1 },
            ..Default::default()
        };
        unsafe { rec.gpu.device.cmd_resolve_image(rec.cb, src.image, vk::ImageLayout::TRANSFER_SRC_OPTIMAL, dst.image, vk::ImageLayout::TRANSFER_DST_OPTIMAL, &[region]) };
        Ok(())
    }
}
