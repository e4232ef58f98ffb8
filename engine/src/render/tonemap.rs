//! The HDR colour target's format, and the full-screen tone-map pass that
//! turns it into the display target: exposure, then Reinhard's operator on luminance with the
//! colour restored (textures.md §5.7; the formula is in shaders/tonemap.frag), written to an
//! `_SRGB` image so the hardware does the sRGB encode. The one place tone mapping happens.

use crate::gpu::{opaque, Gpu, GraphicsPipeline};
use crate::render::graph::{ImageRef, Rec, Rendering};
use crate::render::sampled_input::SampledInput;
use bytemuck::{Pod, Zeroable};
use crate::render::shaders;
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
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct ToneMapPush {
    /// x: exposure; y: 1 = tone map, 0 = pass through; z: saturation exponent.
    params: Vec4,
}

pub struct ToneMap {
    /// The saturation exponent `s` (see `DEFAULT_SATURATION`).
    pub saturation: f32,
    /// The display format it writes (the output's; also the FXAA input's).
    pub display_format: vk::Format,
    /// The HDR target, per frame slot (the shader reads texels with texelFetch: the sampler only
    /// has to exist).
    input: SampledInput,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
}

impl ToneMap {
    /// A tone-map pass writing `display_format` (the swapchain's or the offscreen target's).
    pub fn new(gpu: &Gpu, display_format: vk::Format, frames_in_flight: usize) -> Result<ToneMap> {
        let input = gpu.own(SampledInput::new(gpu, frames_in_flight, vk::Filter::NEAREST)?);
        let (layout, pipeline) = fullscreen_pipeline(gpu, "tone-map", input.layout, std::mem::size_of::<ToneMapPush>() as u32, shaders::TONEMAP_FRAG, display_format)?;
        Ok(ToneMap { saturation: DEFAULT_SATURATION, display_format, input: input.keep(), layout, pipeline })
    }

    /// Record the pass: `hdr` is sampled, every pixel of `target` written. `tone_map` false
    /// passes the values through (display-referred input: the stand-in lighting).
    pub fn record(&mut self, rec: &Rec, hdr: ImageRef, target: ImageRef, exposure: f32, tone_map: bool) {
        let set = self.input.set(rec.gpu, rec.slot, hdr.view);
        let push = ToneMapPush { params: Vec4::new(exposure, tone_map as u32 as f32, self.saturation, 0.0) };
        draw_fullscreen(rec, target, true, self.pipeline, self.layout, set, bytemuck::bytes_of(&push));
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        self.input.destroy(gpu);
        unsafe {
            gpu.device.destroy_pipeline(self.pipeline, None);
            gpu.device.destroy_pipeline_layout(self.layout, None);
        }
    }
}

/// A full-screen pipeline (`fullscreen.vert` + `frag`) with one sampled input set and `push`
/// bytes of fragment push constants, into one colour attachment of `format`.
pub fn fullscreen_pipeline(gpu: &Gpu, name: &str, set_layout: vk::DescriptorSetLayout, push: u32, frag: &[u8], format: vk::Format) -> Result<(vk::PipelineLayout, vk::Pipeline)> {
    let d = &gpu.device;
    let ranges = [vk::PushConstantRange::default().stage_flags(vk::ShaderStageFlags::FRAGMENT).size(push)];
    let set_layouts = [set_layout];
    let layout = gpu.own(unsafe { d.create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts).push_constant_ranges(&ranges), None)? });
    let pipeline = GraphicsPipeline::new(name, shaders::FULLSCREEN_VERT).fragment(frag, None).color(format, opaque()).build(gpu, *layout)?;
    Ok((layout.keep(), pipeline))
}

/// One full-screen triangle into `target` with `pipeline`, its input `set` and `push` bytes;
/// `overwrite`: every pixel is written, so the old contents are not loaded.
pub fn draw_fullscreen(rec: &Rec, target: ImageRef, overwrite: bool, pipeline: vk::Pipeline, layout: vk::PipelineLayout, set: vk::DescriptorSet, push: &[u8]) {
    let (d, cb) = (&rec.gpu.device, rec.cb);
    rec.begin_rendering(&if overwrite { Rendering::color_overwritten(target) } else { Rendering::color(target, None) });
    unsafe {
        d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, pipeline);
        d.cmd_bind_descriptor_sets(cb, vk::PipelineBindPoint::GRAPHICS, layout, 0, &[set], &[]);
        d.cmd_push_constants(cb, layout, vk::ShaderStageFlags::FRAGMENT, 0, push);
        d.cmd_draw(cb, 3, 1, 0, 0);
    }
    rec.end_rendering();
}
