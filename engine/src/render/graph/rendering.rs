//! What a pass draws into: a dynamic rendering over the whole of its attachments, begun with the
//! viewport and scissor set to it (`Rec::begin_rendering`), so no pass writes that boilerplate.

use super::{ImageRef, Rec};
use ash::vk;

/// A rendering's colour and depth attachments (either may be absent), all of one extent.
pub struct Rendering {
    extent: vk::Extent2D,
    color: Option<vk::RenderingAttachmentInfo<'static>>,
    depth: Option<vk::RenderingAttachmentInfo<'static>>,
}

impl Rendering {
    /// Into colour `image`: cleared to `clear` or loaded, then stored.
    pub fn color(image: ImageRef, clear: Option<[f32; 4]>) -> Rendering {
        let attachment = vk::RenderingAttachmentInfo::default()
            .image_view(image.view)
            .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
            .load_op(if clear.is_some() { vk::AttachmentLoadOp::CLEAR } else { vk::AttachmentLoadOp::LOAD })
            .store_op(vk::AttachmentStoreOp::STORE)
            .clear_value(vk::ClearValue { color: vk::ClearColorValue { float32: clear.unwrap_or_default() } });
        Rendering { extent: image.extent, color: Some(attachment), depth: None }
    }

    /// Colour `image` whose old contents are not read (every pixel is written): DONT_CARE.
    pub fn color_overwritten(image: ImageRef) -> Rendering {
        let mut r = Rendering::color(image, None);
        r.color = r.color.map(|a| a.load_op(vk::AttachmentLoadOp::DONT_CARE));
        r
    }

    /// Into depth `image` only.
    pub fn depth_only(image: ImageRef, clear: Option<f32>, store: vk::AttachmentStoreOp) -> Rendering {
        Rendering { extent: image.extent, color: None, depth: None }.depth(image, clear, store)
    }

    /// With depth `image`: cleared to `clear` or loaded, then `store`d. A pass that only tests
    /// (`Access::DepthTest`) stores with NONE: DONT_CARE and STORE are writes to Vulkan.
    pub fn depth(mut self, image: ImageRef, clear: Option<f32>, store: vk::AttachmentStoreOp) -> Rendering {
        debug_assert_eq!(image.extent, self.extent, "a rendering's attachments have one size");
        self.depth = Some(
            vk::RenderingAttachmentInfo::default()
                .image_view(image.view)
                .image_layout(vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL)
                .load_op(if clear.is_some() { vk::AttachmentLoadOp::CLEAR } else { vk::AttachmentLoadOp::LOAD })
                .store_op(store)
                .clear_value(vk::ClearValue { depth_stencil: vk::ClearDepthStencilValue { depth: clear.unwrap_or(0.0), stencil: 0 } }),
        );
        self
    }

    pub fn extent(&self) -> vk::Extent2D {
        self.extent
    }
}

impl Rec<'_> {
    /// Begin `r` over its whole extent and point the viewport and scissor (dynamic state) at it;
    /// `end_rendering` closes it.
    pub fn begin_rendering(&self, r: &Rendering) {
        let area = vk::Rect2D { offset: vk::Offset2D::default(), extent: r.extent };
        let color: Vec<vk::RenderingAttachmentInfo> = r.color.into_iter().collect();
        let mut info = vk::RenderingInfo::default().render_area(area).layer_count(1).color_attachments(&color);
        if let Some(depth) = &r.depth {
            info = info.depth_attachment(depth);
        }
        let viewport = vk::Viewport { x: 0.0, y: 0.0, width: r.extent.width as f32, height: r.extent.height as f32, min_depth: 0.0, max_depth: 1.0 };
        unsafe {
            self.gpu.device.cmd_begin_rendering(self.cb, &info);
            self.gpu.device.cmd_set_viewport(self.cb, 0, &[viewport]);
            self.gpu.device.cmd_set_scissor(self.cb, 0, &[area]);
        }
    }

    pub fn end_rendering(&self) {
        unsafe { self.gpu.device.cmd_end_rendering(self.cb) };
    }
}
