//! The HDR colour target's format, and the full-screen tone-map pass that
//! turns it into the display target: exposure, then Reinhard's operator on luminance with the
//! colour restored (textures.md §5.7; the formula is in shaders/tonemap.frag), written to an
//! `_SRGB` image so the hardware does the sRGB encode. The one place tone mapping happens.

use crate::gpu::Gpu;
use crate::render::fullscreen::FullscreenFilter;
use crate::render::frame::{SkyParams, LOW_FORMAT};
use crate::render::graph::{ImageRef, Rec};
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

/// Mirrors the push-constant block of shaders/tonemap.frag (within 128 bytes, Vulkan's
/// guaranteed push-constant size).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct ToneMapPush {
    /// x: exposure; y: 1 = tone map, 0 = pass through; z: saturation exponent; w: unused
    /// (whether the sky is behind what the frame drew is the pipeline's: SKY).
    params: Vec4,
    sky: SkyParams,
}
const _: () = assert!(std::mem::size_of::<ToneMapPush>() <= 128);

pub struct ToneMap {
    /// The saturation exponent `s` (see `DEFAULT_SATURATION`).
    pub saturation: f32,
    /// The display format it writes (the output's; also the FXAA input's).
    pub display_format: vk::Format,
    /// Reads the HDR target with texelFetch (the sampler only has to exist).
    filter: FullscreenFilter,
    /// The same into the upscaler's input (`frame::LOW_FORMAT`, gamma 2), below the output's size.
    low: FullscreenFilter,
}

impl ToneMap {
    /// A tone-map pass writing `display_format` (the swapchain's or the offscreen target's).
    pub fn new(gpu: &Gpu, display_format: vk::Format, frames_in_flight: usize) -> Result<ToneMap> {
        let push = std::mem::size_of::<ToneMapPush>() as u32;
        // Variants: SKY off (0) and on (1).
        let filter = gpu.own(FullscreenFilter::new_variants(gpu, "tone-map", shaders::TONEMAP_FRAG.spv(), push, display_format, frames_in_flight, vk::Filter::NEAREST, &[0, 1])?);
        // The same two with GAMMA2 (bit 1), for the upscaler's input.
        let low = FullscreenFilter::new_variants(gpu, "tone-map (render scale)", shaders::TONEMAP_FRAG.spv(), push, LOW_FORMAT, frames_in_flight, vk::Filter::NEAREST, &[2, 3])?;
        Ok(ToneMap { saturation: DEFAULT_SATURATION, display_format, filter: filter.keep(), low })
    }

    /// Record the pass: `hdr` is sampled, every pixel of `target` written. `tone_map` false
    /// passes the values through (display-referred input: the stand-in lighting). With `sky`,
    /// the background shows through where the frame's alpha leaves it uncovered.
    /// Into a `LOW_FORMAT` target (the upscaler's input), `target` is written gamma 2 encoded.
    pub fn record(&mut self, rec: &Rec, hdr: ImageRef, target: ImageRef, exposure: f32, tone_map: bool, sky: Option<SkyParams>) {
        let params = Vec4::new(exposure, tone_map as u32 as f32, self.saturation, 0.0);
        let push = ToneMapPush { params, sky: sky.unwrap_or_else(SkyParams::zeroed) };
        let filter = if target.format == LOW_FORMAT && self.display_format != LOW_FORMAT { &mut self.low } else { &mut self.filter };
        filter.draw_variant(rec, hdr.view, target, bytemuck::bytes_of(&push), sky.is_some() as usize);
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        self.filter.destroy(gpu);
        self.low.destroy(gpu);
    }
}
