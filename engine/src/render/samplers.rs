//! Texture samplers from the pack's sampler states (glTF samplers): one Vulkan sampler per
//! distinct state, made on first use and shared by every texture that asks for it.

use crate::gpu::Gpu;
use anyhow::Result;
use ash::vk;
use pack::{Filter, Sampler, Wrap};

/// The anisotropy of mipmapped textures' samplers: up to 16x where the device offers it, none on
/// a CPU device. Lavapipe's (Mesa 22.3) anisotropic sampling can spin for minutes on a single
/// frame: the validation soak stalled at frame 909 of the demo's flight (64x36, 16x), a frame
/// that renders in 0.1 s without it. There it also costs 10-20% of the shading pass.
pub fn max_anisotropy(gpu: &Gpu) -> Option<f32> {
    if gpu.caps.device_type == vk::PhysicalDeviceType::CPU {
        return None;
    }
    gpu.caps.sampler_anisotropy.map(|max| max.min(16.0))
}

/// Whether a mipmapped texture whose sampler asks for linear mipmap filtering (trilinear) gets
/// it: yes on GPUs; on a CPU device the nearer level only (bilinear within it), since lavapipe
/// pays for every texel it filters: the demo flythrough's shading pass took 0.75x the time, the
/// frame 0.88x (README, "Frame budget"; the screens' SSIM against trilinear in
/// tests/test_render.py). `ENGINE_TRILINEAR=1` forces trilinear everywhere, `=0` turns it off.
pub fn trilinear(gpu: &Gpu) -> bool {
    match std::env::var("ENGINE_TRILINEAR").as_deref() {
        Ok("1") => true,
        Ok("0") => false,
        _ => gpu.caps.device_type != vk::PhysicalDeviceType::CPU,
    }
}

/// The samplers made so far, by state and anisotropy. A pack has a handful of distinct states,
/// so a list searched in order is all the lookup needs.
#[derive(Default)]
pub struct SamplerCache {
    made: Vec<(Sampler, bool, vk::Sampler)>,
}

impl SamplerCache {
    /// The sampler for a texture of `mip_levels` levels sampled as `state`. Anisotropic (where
    /// `max_anisotropy` allows) only when there is a mip chain to filter and the state filters
    /// minification linearly: without a chain it makes lavapipe take ~18x longer per frame
    /// (257 ms vs 14 ms on the temple level), and a NEAREST state asks for unfiltered texels.
    /// Linear mipmap filtering only where `trilinear` allows (material textures; the reflection
    /// probes' roughness levels, read through `get`, always blend).
    pub fn for_texture(&mut self, gpu: &Gpu, mut state: Sampler, mip_levels: u32) -> Result<vk::Sampler> {
        if state.mipmap_filter == Some(Filter::Linear) && !trilinear(gpu) {
            state.mipmap_filter = Some(Filter::Nearest);
        }
        let mipmapped = mip_levels > 1 && state.mipmap_filter.is_some();
        let anisotropic = mipmapped && state.min_filter == Filter::Linear && max_anisotropy(gpu).is_some();
        self.get(gpu, state, anisotropic)
    }

    /// The sampler for `state`, anisotropic or not.
    pub fn get(&mut self, gpu: &Gpu, state: Sampler, anisotropic: bool) -> Result<vk::Sampler> {
        if let Some(&(_, _, s)) = self.made.iter().find(|(st, a, _)| *st == state && *a == anisotropic) {
            return Ok(s);
        }
        let mode = |w: Wrap| match w {
            Wrap::Repeat => vk::SamplerAddressMode::REPEAT,
            Wrap::Clamp => vk::SamplerAddressMode::CLAMP_TO_EDGE,
            Wrap::Mirror => vk::SamplerAddressMode::MIRRORED_REPEAT,
        };
        let filter = |f: Filter| match f {
            Filter::Nearest => vk::Filter::NEAREST,
            Filter::Linear => vk::Filter::LINEAR,
        };
        // Without a mipmap filter only level 0 is read (glTF's NEAREST or LINEAR minification).
        let (mipmap_mode, max_lod) = match state.mipmap_filter {
            Some(Filter::Nearest) => (vk::SamplerMipmapMode::NEAREST, vk::LOD_CLAMP_NONE),
            Some(Filter::Linear) => (vk::SamplerMipmapMode::LINEAR, vk::LOD_CLAMP_NONE),
            None => (vk::SamplerMipmapMode::NEAREST, 0.0),
        };
        let mut info = vk::SamplerCreateInfo::default()
            .mag_filter(filter(state.mag_filter))
            .min_filter(filter(state.min_filter))
            .mipmap_mode(mipmap_mode)
            .address_mode_u(mode(state.wrap_s))
            .address_mode_v(mode(state.wrap_t))
            .address_mode_w(mode(state.wrap_s))
            .max_lod(max_lod);
        if let (true, Some(max)) = (anisotropic, max_anisotropy(gpu)) {
            info = info.anisotropy_enable(true).max_anisotropy(max);
        }
        let sampler = unsafe { gpu.device.create_sampler(&info, None)? };
        self.made.push((state, anisotropic, sampler));
        Ok(sampler)
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        for (_, _, s) in self.made.drain(..) {
            unsafe { gpu.device.destroy_sampler(s, None) };
        }
    }
}
