//! Ownership of GPU objects while they are being made: `Owned` holds an object (a buffer, an
//! image, a pipeline, a vector of them...) and destroys it when dropped, unless `keep` hands it
//! over. Constructors wrap every object they make as they make it, so a `?` anywhere on the way
//! (an allocation that fails, a shader that does not compile) frees what was already made; the
//! finished struct then owns its parts and frees them in its `destroy`.
//!
//! Objects are not freed on drop in general: the device may still be reading them (a frame in
//! flight), which only the owner knows; `destroy` after the right fence is the owner's job.

use super::{Buffer, Gpu, Image, SlotBuffers, Uploader};
use ash::vk;
use std::ops::{Deref, DerefMut};

/// A GPU object (or a collection of them) that can free itself.
pub trait Destroy {
    fn destroy(&mut self, gpu: &Gpu);
}

/// `value`, destroyed on drop unless `keep` took it: see the module's doc.
pub struct Owned<'g, T: Destroy> {
    gpu: &'g Gpu,
    value: Option<T>,
}

impl<'g, T: Destroy> Owned<'g, T> {
    pub fn new(gpu: &'g Gpu, value: T) -> Owned<'g, T> {
        Owned { gpu, value: Some(value) }
    }

    /// The object, no longer destroyed on drop: the caller owns it now.
    pub fn keep(mut self) -> T {
        self.value.take().expect("an Owned value is kept once")
    }
}

impl<T: Destroy> Deref for Owned<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        self.value.as_ref().expect("an Owned value is kept once")
    }
}

impl<T: Destroy> DerefMut for Owned<'_, T> {
    fn deref_mut(&mut self) -> &mut T {
        self.value.as_mut().expect("an Owned value is kept once")
    }
}

impl<T: Destroy> Drop for Owned<'_, T> {
    fn drop(&mut self) {
        // A hung device may still be using the object (the wait that timed out was for
        // work on it): leave it to the process's exit, as `Gpu`'s drop does.
        if let Some(mut v) = self.value.take().filter(|_| !self.gpu.hung()) {
            v.destroy(self.gpu);
        }
    }
}

impl Gpu {
    /// `value` owned until `keep`: freed if the caller returns early.
    pub fn own<T: Destroy>(&self, value: T) -> Owned<'_, T> {
        Owned::new(self, value)
    }
}

/// `Destroy` for the engine's types that free themselves with a `destroy(&mut self, &Gpu)` of
/// their own: listed here, in one place.
macro_rules! destroy_by_method {
    ($($ty:ty),* $(,)?) => {$(
        impl Destroy for $ty {
            fn destroy(&mut self, gpu: &Gpu) {
                <$ty>::destroy(self, gpu)
            }
        }
    )*};
}

destroy_by_method! {
    Buffer,
    Image,
    Uploader,
    SlotBuffers,
    crate::render::samplers::SamplerCache,
    crate::render::mesh_draw::MeshKit,
    crate::render::graph::Graph,
    crate::render::sampled_input::SampledInput,
    crate::render::shadow::SunShadow,
    crate::render::tonemap::ToneMap,
    crate::render::fullscreen::FullscreenFilter,
    crate::render::particles_draw::ParticlePass,
    crate::render::boids_draw::BoidsDraw,
    crate::scene::GpuScene,
    crate::anim::animated::AnimatedScene,
    crate::anim::skin_gpu::SkinPipeline,
    crate::anim::skin_gpu::SkinBatch,
    crate::app::headless::Offscreen,
    crate::render::renderer::Renderer,
    crate::app::swapchain::Swapchain,
    crate::app::swapchain::Frames,
}

impl Destroy for (u32, crate::scene::FlockMesh) {
    fn destroy(&mut self, gpu: &Gpu) {
        self.1.vertices.destroy(gpu)
    }
}

impl Destroy for Box<dyn crate::render::graph::Pass> {
    fn destroy(&mut self, gpu: &Gpu) {
        (**self).destroy(gpu)
    }
}

impl<T: Destroy> Destroy for Vec<T> {
    fn destroy(&mut self, gpu: &Gpu) {
        for v in self.iter_mut() {
            v.destroy(gpu);
        }
        self.clear();
    }
}

impl<T: Destroy> Destroy for Option<T> {
    fn destroy(&mut self, gpu: &Gpu) {
        if let Some(mut v) = self.take() {
            v.destroy(gpu);
        }
    }
}

/// Raw handles destroyed by one device call each (null handles are ignored by Vulkan).
macro_rules! destroy_handle {
    ($($ty:ty => $call:ident),* $(,)?) => {$(
        impl Destroy for $ty {
            fn destroy(&mut self, gpu: &Gpu) {
                // SAFETY: the handle was made on this device, and whoever holds it is done with it.
                unsafe { gpu.device.$call(std::mem::take(self), None) };
            }
        }
    )*};
}

destroy_handle! {
    vk::Pipeline => destroy_pipeline,
    vk::PipelineLayout => destroy_pipeline_layout,
    vk::DescriptorSetLayout => destroy_descriptor_set_layout,
    vk::DescriptorPool => destroy_descriptor_pool,
    vk::Sampler => destroy_sampler,
    vk::ShaderModule => destroy_shader_module,
    vk::QueryPool => destroy_query_pool,
    vk::Fence => destroy_fence,
    vk::Semaphore => destroy_semaphore,
    vk::CommandPool => destroy_command_pool,
    vk::ImageView => destroy_image_view,
}
