//! Vulkan plumbing: context (instance, device, allocator), memory objects, validation.

mod context;
mod memory;
mod validation;

pub use context::{Capabilities, DeviceLost, DevicePreference, Gpu, GpuOptions, DEFAULT_GPU_TIMEOUT};
pub use memory::{barrier, full_range, Buffer, Image, Transition};
pub use validation::ValidationLog;
