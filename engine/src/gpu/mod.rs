//! Vulkan plumbing: context (instance, device, allocator), memory objects, graphics pipelines,
//! validation.

mod context;
mod memory;
mod owned;
mod pipeline;
mod pipeline_cache;
mod upload;
mod validation;

pub use context::{Capabilities, DeviceLost, DevicePreference, Gpu, GpuOptions, Loss, DEFAULT_GPU_TIMEOUT};
pub use memory::{barrier, full_range, Buffer, Image, SlotBuffers, Transition};
pub use owned::{Destroy, Owned};
pub use upload::Uploader;
pub use pipeline::{opaque, premultiplied_over, GraphicsPipeline, PerSamples};
pub use validation::ValidationLog;
