//! The HDR colour target the shading pass renders into, and the full-screen tone-map pass that
//! turns it into the display target: exposure, then Reinhard's operator on luminance with the
//! colour restored (textures.md §5.7; the formula is in shaders/tonemap.frag), written to an
//! `_SRGB` image so the hardware does the sRGB encode. The one place tone mapping happens.

use crate::gpu::{barrier, full_range, opaque, Gpu, GraphicsPipeline, Image, Transition};
use crate::shaders;
use anyhow::Result;
use ash::vk;
use glam::Vec4;

/// Half float: radiance in nits spans far more than 0..1 and must not be clamped before the
/// tone map (textures.md §4.1: values above 1 need float storage; half is the real-time choice).
pub const HDR_FORMAT: vk::Format = vk::Format::R16G16B16A16_SFLOAT;

/// The saturation exponent `s` of the colour restore, `(L_c / Y)^s * L_d` (textures.md §5.5,
/// §5.7: "s ≈ 0.7 to 1"; 1 keeps the ratios but often looks oversaturated).
pub const DEFAULT_SATURATION: f32 = 0.8;

/// Mirrors the push-constant block of shaders/tonemap.frag.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
struct ToneMapPush {
    /// x: exposure; y: 1 = tone map, 0 = pass through; z: saturation exponent.
    params: Vec4,
}

pub struct ToneMap {
    /// The saturation exponent `s` (see `DEFAULT_SATURATION`).
    pub saturation: f32,
    set_layout: vk::DescriptorSetLayout,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    pool: vk::DescriptorPool,
    set: vk::DescriptorSet,
    sampler: vk::Sampler,
    /// Sized to the last target; None until the first frame.
    hdr: Option<Image>,
}

impl ToneMap {
    /// A tone-map pass writing `display_format` (the swapchain's or the offscreen target's).
    pub fn new(gpu: &Gpu, display_format: vk::Format) -> Result<ToneMap> {
        let d = &gpu.device;
        let binding = [vk::DescriptorSetLayoutBinding::default()
            .binding(0)
            .descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER)
            .descriptor_count(1)
            .stage_flags(vk::ShaderStageFlags::FRAGMENT)];
        let set_layout = unsafe { d.create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(&binding), None)? };
        let push = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::FRAGMENT)
            .size(std::mem::size_of::<ToneMapPush>() as u32)];
        let set_layouts = [set_layout];
        let layout = unsafe { d.create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts).push_constant_ranges(&push), None)? };
        let pipeline = create_pipeline(gpu, layout, display_format)?;
        let sizes = [vk::DescriptorPoolSize {
            ty: vk::DescriptorType::COMBINED_IMAGE_SAMPLER,
            descriptor_count: 1,
        }];
        let pool = unsafe { d.create_descriptor_pool(&vk::DescriptorPoolCreateInfo::default().max_sets(1).pool_sizes(&sizes), None)? };
        let set = unsafe { d.allocate_descriptor_sets(&vk::DescriptorSetAllocateInfo::default().descriptor_pool(pool).set_layouts(&set_layouts))?[0] };
        // The shader reads texels with texelFetch: the sampler only has to exist.
        let sampler = unsafe {
            d.create_sampler(
                &vk::SamplerCreateInfo::default()
                    .mag_filter(vk::Filter::NEAREST)
                    .min_filter(vk::Filter::NEAREST)
                    .address_mode_u(vk::SamplerAddressMode::CLAMP_TO_EDGE)
                    .address_mode_v(vk::SamplerAddressMode::CLAMP_TO_EDGE)
                    .address_mode_w(vk::SamplerAddressMode::CLAMP_TO_EDGE),
                None,
            )?
        };
        Ok(ToneMap {
            saturation: DEFAULT_SATURATION,
            set_layout,
            layout,
            pipeline,
            pool,
            set,
            sampler,
            hdr: None,
        })
    }

    /// The HDR target for a frame of `extent`, (re)made when the size changes (first frame,
    /// window resize). The old image may still be in use by a frame in flight, so a resize waits
    /// for the device; resizes are rare.
    pub fn hdr_target(&mut self, gpu: &Gpu, extent: vk::Extent2D) -> Result<(vk::Image, vk::ImageView)> {
        if self.hdr.as_ref().map(|i| i.extent) != Some(extent) {
            if let Some(mut old) = self.hdr.take() {
                gpu.wait_idle();
                old.destroy(gpu);
            }
            let image = Image::new(
                gpu,
                "HDR colour",
                HDR_FORMAT,
                extent,
                1,
                vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::SAMPLED,
                vk::ImageAspectFlags::COLOR,
            )?;
            let info = [vk::DescriptorImageInfo {
                sampler: self.sampler,
                image_view: image.view,
                image_layout: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
            }];
            let write = vk::WriteDescriptorSet::default()
                .dst_set(self.set)
                .dst_binding(0)
                .descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER)
                .image_info(&info);
            unsafe { gpu.device.update_descriptor_sets(&[write], &[]) };
            self.hdr = Some(image);
        }
        let hdr = self.hdr.as_ref().unwrap();
        Ok((hdr.image, hdr.view))
    }

    /// Record the pass: the HDR target (rendered as a colour attachment) is read, and every pixel
    /// of `target_view` (COLOR_ATTACHMENT_OPTIMAL) written. `tone_map` false passes the values
    /// through (display-referred input: the stand-in lighting).
    pub fn record(&self, gpu: &Gpu, cb: vk::CommandBuffer, target_view: vk::ImageView, extent: vk::Extent2D, exposure: f32, tone_map: bool) {
        let d = &gpu.device;
        let hdr = self.hdr.as_ref().expect("hdr_target() before record()");
        barrier(gpu, cb, hdr.image, full_range(vk::ImageAspectFlags::COLOR, 1), Transition::COLOR_ATTACHMENT_TO_SAMPLED);
        let area = vk::Rect2D {
            offset: vk::Offset2D::default(),
            extent,
        };
        // Every pixel is written: nothing to load.
        let color = [vk::RenderingAttachmentInfo::default()
            .image_view(target_view)
            .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
            .load_op(vk::AttachmentLoadOp::DONT_CARE)
            .store_op(vk::AttachmentStoreOp::STORE)];
        let rendering = vk::RenderingInfo::default().render_area(area).layer_count(1).color_attachments(&color);
        let push = ToneMapPush {
            params: Vec4::new(exposure, tone_map as u32 as f32, self.saturation, 0.0),
        };
        unsafe {
            d.cmd_begin_rendering(cb, &rendering);
            d.cmd_set_viewport(
                cb,
                0,
                &[vk::Viewport {
                    x: 0.0,
                    y: 0.0,
                    width: extent.width as f32,
                    height: extent.height as f32,
                    min_depth: 0.0,
                    max_depth: 1.0,
                }],
            );
            d.cmd_set_scissor(cb, 0, &[area]);
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, self.pipeline);
            d.cmd_bind_descriptor_sets(cb, vk::PipelineBindPoint::GRAPHICS, self.layout, 0, &[self.set], &[]);
            let bytes = std::slice::from_raw_parts(&push as *const _ as *const u8, std::mem::size_of::<ToneMapPush>());
            d.cmd_push_constants(cb, self.layout, vk::ShaderStageFlags::FRAGMENT, 0, bytes);
            d.cmd_draw(cb, 3, 1, 0, 0);
            d.cmd_end_rendering(cb);
        }
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        if let Some(mut hdr) = self.hdr.take() {
            hdr.destroy(gpu);
        }
        let d = &gpu.device;
        unsafe {
            d.destroy_sampler(self.sampler, None);
            d.destroy_descriptor_pool(self.pool, None);
            d.destroy_pipeline(self.pipeline, None);
            d.destroy_pipeline_layout(self.layout, None);
            d.destroy_descriptor_set_layout(self.set_layout, None);
        }
    }
}

/// `fullscreen.vert` + `tonemap.frag` into one colour attachment of `format`; no depth, no
/// vertex input, no culling.
fn create_pipeline(gpu: &Gpu, layout: vk::PipelineLayout, format: vk::Format) -> Result<vk::Pipeline> {
    GraphicsPipeline::new("tone-map", shaders::FULLSCREEN_VERT)
        .fragment(shaders::TONEMAP_FRAG, None)
        .color(format, opaque())
        .build(&gpu.device, layout)
}
