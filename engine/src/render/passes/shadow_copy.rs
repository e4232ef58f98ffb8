//! Each frame's shadow map starts as a copy of the static casters' cached depth.

use crate::render::frame::{FrameCx, SHADOW_CACHE, SHADOW_MAP};
use crate::render::graph::{Access, Io, Pass, Rec};
use anyhow::Result;
use ash::vk;

pub struct ShadowCopy;

impl Pass for ShadowCopy {
    fn name(&self) -> &'static str {
        "shadow copy"
    }

    /// No draws: no vertex or fragment shader invocations to count (and a statistics query on
    /// lavapipe is not free).
    fn counts_invocations(&self) -> bool {
        false
    }

    fn declare(&mut self, cx: &FrameCx, io: &mut Io) {
        let s = cx.shadow;
        if cx.frame.draw_shadow && !s.static_casters.is_empty() {
            io.import(SHADOW_CACHE, s.cache_ref()).import(SHADOW_MAP, s.map_ref());
            io.uses(SHADOW_CACHE, Access::TransferSrc).uses(SHADOW_MAP, Access::TransferDst);
        }
    }

    fn record(&mut self, cx: &mut FrameCx, rec: &Rec) -> Result<()> {
        let (cache, map) = (rec.image(SHADOW_CACHE), rec.image(SHADOW_MAP));
        let layers = vk::ImageSubresourceLayers { aspect_mask: vk::ImageAspectFlags::DEPTH, mip_level: 0, base_array_layer: 0, layer_count: 1 };
        let size = cx.shadow.size;
        let region = vk::ImageCopy { src_subresource: layers, dst_subresource: layers, extent: vk::Extent3D { width: size, height: size, depth: 1 }, ..Default::default() };
        unsafe { rec.gpu.device.cmd_copy_image(rec.cb, cache.image, vk::ImageLayout::TRANSFER_SRC_OPTIMAL, map.image, vk::ImageLayout::TRANSFER_DST_OPTIMAL, &[region]) };
        Ok(())
    }
}
