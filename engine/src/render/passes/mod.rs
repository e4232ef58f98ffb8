//! The renderer's passes, one type per file. A new pass is a file here plus one line in
//! `register`: its place in the list is its place in the frame (see `graph::plan`).

mod boids;
mod depth_view;
mod fxaa;
mod particles;
mod prepass;
mod resolve;
mod shading;
mod shadow_copy;
mod shadow_dynamic;
mod shadow_static;
mod skinning;
mod tonemap;
mod transparent;
mod upscale;

pub use depth_view::DepthView;

use crate::gpu::Gpu;
use crate::render::graph::Pass;
use anyhow::Result;
use ash::vk;

/// Every pass of a frame, in order, for a renderer drawing into `color_format` images.
pub fn register(gpu: &Gpu, color_format: vk::Format, frames_in_flight: usize) -> Result<Vec<Box<dyn Pass>>> {
    // Owned while it grows: a pass that fails to build frees the ones built before it.
    let mut passes = gpu.own(Vec::<Box<dyn Pass>>::new());
    passes.push(Box::new(skinning::Skinning));
    passes.push(Box::new(shadow_static::ShadowStatic));
    passes.push(Box::new(shadow_copy::ShadowCopy));
    passes.push(Box::new(shadow_dynamic::ShadowDynamic));
    passes.push(Box::new(prepass::Prepass));
    passes.push(Box::new(shading::Shading));
    passes.push(Box::new(boids::Boids));
    passes.push(Box::new(transparent::Transparent));
    passes.push(Box::new(particles::Particles));
    passes.push(Box::new(resolve::Resolve));
    passes.push(Box::new(tonemap::ToneMapPass));
    passes.push(Box::new(fxaa::Fxaa::new(gpu, color_format, frames_in_flight)?));
    passes.push(Box::new(upscale::Upscale::new(gpu, color_format, frames_in_flight)?));
    passes.push(Box::new(DepthView::new(gpu, color_format, frames_in_flight)?));
    Ok(passes.keep())
}
