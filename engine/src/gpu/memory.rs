//! Buffers and images with their memory, and uploads through a staging buffer.

use super::{Gpu, Uploader};
use anyhow::{anyhow, bail, Context, Result};
use std::sync::atomic::Ordering;
use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

pub struct Buffer {
    pub buffer: vk::Buffer,
    pub size: u64,
    allocation: Option<Allocation>,
}

impl Buffer {
    pub fn new(gpu: &Gpu, name: &str, size: u64, usage: vk::BufferUsageFlags, location: MemoryLocation) -> Result<Buffer> {
        let d = &gpu.device;
        let buffer = unsafe { d.create_buffer(&vk::BufferCreateInfo::default().size(size.max(4)).usage(usage), None)? };
        let mut b = gpu.own(Buffer { buffer, size, allocation: None });
        let requirements = unsafe { d.get_buffer_memory_requirements(buffer) };
        let allocation = b.allocation.insert(allocate(gpu, name, requirements, location, true)?);
        // SAFETY: the allocation is bound once and freed only after the buffer is destroyed.
        unsafe { d.bind_buffer_memory(buffer, allocation.memory(), allocation.offset())? };
        Ok(b.keep())
    }

    /// The mapped bytes of a host-visible buffer.
    pub fn mapped(&mut self) -> &mut [u8] {
        let size = self.size as usize;
        let slice = self.allocation.as_mut().and_then(|a| a.mapped_slice_mut()).expect("buffer is not host-visible");
        &mut slice[..size]
    }

    pub fn mapped_ref(&self) -> &[u8] {
        let slice = self.allocation.as_ref().and_then(|a| a.mapped_slice()).expect("buffer is not host-visible");
        &slice[..self.size as usize]
    }

    /// A device-local buffer filled with `bytes` through a staging copy, now (one submit; a
    /// loader of many buffers batches them through an `Uploader`).
    pub fn with_data(gpu: &Gpu, name: &str, bytes: &[u8], usage: vk::BufferUsageFlags) -> Result<Buffer> {
        // The staging buffer is freed when this returns, whichever way.
        let mut up = gpu.own(Uploader::new(bytes.len() as u64));
        let dst = gpu.own(up.buffer(gpu, name, &[bytes], usage)?);
        up.flush(gpu)?;
        Ok(dst.keep())
    }

    /// Free the buffer and its memory (once: later calls do nothing).
    pub fn destroy(&mut self, gpu: &Gpu) {
        unsafe { gpu.device.destroy_buffer(std::mem::take(&mut self.buffer), None) };
        if let Some(a) = self.allocation.take() {
            let _ = gpu.allocator.lock().unwrap().free(a);
        }
    }
}

/// One host-visible buffer per frame in flight for data written every frame (instance
/// transforms, billboards), grown to the next power of two when a frame needs more. A slot's
/// buffer is written only after its previous frame's fence, so no frame reads a buffer that is
/// being rewritten or replaced.
pub struct SlotBuffers {
    name: &'static str,
    usage: vk::BufferUsageFlags,
    min_bytes: usize,
    slots: Vec<Option<Buffer>>,
}

impl SlotBuffers {
    pub fn new(name: &'static str, usage: vk::BufferUsageFlags, frames_in_flight: usize, min_bytes: usize) -> SlotBuffers {
        SlotBuffers { name, usage, min_bytes, slots: (0..frames_in_flight).map(|_| None).collect() }
    }

    /// `slot`'s buffer, at least `bytes` long (a new one, contents undefined, when it grew).
    pub fn reserve(&mut self, gpu: &Gpu, slot: usize, bytes: usize) -> Result<&mut Buffer> {
        let entry = &mut self.slots[slot];
        if entry.as_ref().is_none_or(|b| (b.size as usize) < bytes) {
            if let Some(mut old) = entry.take() {
                old.destroy(gpu);
            }
            let size = bytes.next_power_of_two().max(self.min_bytes);
            *entry = Some(Buffer::new(gpu, self.name, size as u64, self.usage, MemoryLocation::CpuToGpu)?);
        }
        Ok(entry.as_mut().unwrap())
    }

    /// Copy `bytes` to the start of `slot`'s buffer, growing it if needed.
    pub fn write(&mut self, gpu: &Gpu, slot: usize, bytes: &[u8]) -> Result<()> {
        self.reserve(gpu, slot, bytes.len())?.mapped()[..bytes.len()].copy_from_slice(bytes);
        Ok(())
    }

    /// `slot`'s buffer, if one was reserved.
    pub fn get(&self, slot: usize) -> Option<&Buffer> {
        self.slots[slot].as_ref()
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        for mut b in self.slots.iter_mut().filter_map(Option::take) {
            b.destroy(gpu);
        }
    }
}

pub struct Image {
    pub image: vk::Image,
    pub view: vk::ImageView,
    pub format: vk::Format,
    pub extent: vk::Extent2D,
    pub mip_levels: u32,
    /// Array layers (1 unless made by `sampled_array`).
    pub(super) layers: u32,
    allocation: Option<Allocation>,
}

impl Image {
    pub fn new(
        gpu: &Gpu,
        name: &str,
        format: vk::Format,
        extent: vk::Extent2D,
        mip_levels: u32,
        usage: vk::ImageUsageFlags,
        aspect: vk::ImageAspectFlags,
    ) -> Result<Image> {
        Image::with_samples(gpu, name, format, extent, mip_levels, vk::SampleCountFlags::TYPE_1, usage, aspect)
    }

    /// `new` with `samples` samples per texel (a multisampled render target has one level).
    #[allow(clippy::too_many_arguments)]
    pub fn with_samples(
        gpu: &Gpu,
        name: &str,
        format: vk::Format,
        extent: vk::Extent2D,
        mip_levels: u32,
        samples: vk::SampleCountFlags,
        usage: vk::ImageUsageFlags,
        aspect: vk::ImageAspectFlags,
    ) -> Result<Image> {
        let info = vk::ImageCreateInfo::default()
            .format(format)
            .extent(vk::Extent3D { width: extent.width, height: extent.height, depth: 1 })
            .mip_levels(mip_levels)
            .array_layers(1)
            .samples(samples)
            .usage(usage);
        Image::create(gpu, name, &info, vk::ImageViewType::TYPE_2D, aspect)
    }

    /// A 2D image as `info` describes it (type, tiling and initial layout are set here; samples
    /// default to one), in device memory, with a view of `view_type` over all its levels and layers.
    fn create(gpu: &Gpu, name: &str, info: &vk::ImageCreateInfo, view_type: vk::ImageViewType, aspect: vk::ImageAspectFlags) -> Result<Image> {
        let d = &gpu.device;
        let info = info
            .image_type(vk::ImageType::TYPE_2D)
            .samples(if info.samples.is_empty() { vk::SampleCountFlags::TYPE_1 } else { info.samples })
            .tiling(vk::ImageTiling::OPTIMAL)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        let image = unsafe { d.create_image(&info, None)? };
        let extent = vk::Extent2D { width: info.extent.width, height: info.extent.height };
        let mut made = gpu.own(Image { image, view: vk::ImageView::null(), format: info.format, extent, mip_levels: info.mip_levels, layers: info.array_layers, allocation: None });
        let requirements = unsafe { d.get_image_memory_requirements(image) };
        let allocation = made.allocation.insert(allocate(gpu, name, requirements, MemoryLocation::GpuOnly, false)?);
        unsafe { d.bind_image_memory(image, allocation.memory(), allocation.offset())? };
        let range = vk::ImageSubresourceRange { layer_count: info.array_layers, ..full_range(aspect, info.mip_levels) };
        made.view = unsafe { d.create_image_view(&vk::ImageViewCreateInfo::default().image(image).view_type(view_type).format(info.format).subresource_range(range), None)? };
        Ok(made.keep())
    }

    /// Array layers.
    pub fn layers(&self) -> u32 {
        self.layers
    }

    /// A sampled image with every mip level uploaded from `mips` (level 0 first, tightly packed)
    /// through `up`, in SHADER_READ_ONLY_OPTIMAL once `up` has flushed.
    pub fn sampled_with_mips(gpu: &Gpu, up: &mut Uploader, name: &str, format: vk::Format, extent: vk::Extent2D, mips: &[&[u8]]) -> Result<Image> {
        let image = gpu.own(Image::new(gpu, name, format, extent, mips.len() as u32, vk::ImageUsageFlags::SAMPLED | vk::ImageUsageFlags::TRANSFER_DST, vk::ImageAspectFlags::COLOR)?);
        let parts: Vec<(&[u8], u32, u32)> = mips.iter().enumerate().map(|(level, bytes)| (*bytes, level as u32, 0)).collect();
        up.image(gpu, &image, &parts)?;
        Ok(image.keep())
    }

    /// A sampled 2D array image of one level, layer i uploaded from `layers[i]` (tightly
    /// packed) through `up`, seen through a 2D-array view, in SHADER_READ_ONLY_OPTIMAL once `up`
    /// has flushed.
    pub fn sampled_array(gpu: &Gpu, up: &mut Uploader, name: &str, format: vk::Format, extent: vk::Extent2D, layers: &[&[u8]]) -> Result<Image> {
        let info = vk::ImageCreateInfo::default()
            .format(format)
            .extent(vk::Extent3D { width: extent.width, height: extent.height, depth: 1 })
            .mip_levels(1)
            .array_layers(layers.len() as u32)
            .usage(vk::ImageUsageFlags::SAMPLED | vk::ImageUsageFlags::TRANSFER_DST);
        let image = gpu.own(Image::create(gpu, name, &info, vk::ImageViewType::TYPE_2D_ARRAY, vk::ImageAspectFlags::COLOR)?);
        let parts: Vec<(&[u8], u32, u32)> = layers.iter().enumerate().map(|(layer, bytes)| (*bytes, 0, layer as u32)).collect();
        up.image(gpu, &image, &parts)?;
        Ok(image.keep())
    }

    /// Cube maps of `size`² texels a face and `levels` mips as one cube-map array (view
    /// CUBE_ARRAY, `imageCubeArray`), cube i uploaded from `cubes[i]`: [level][face +X, −X, +Y,
    /// −Y, +Z, −Z][row][column], tightly packed (a face of level k `face_bytes(k)` long: texels,
    /// or whole blocks of a compressed format), through `up`. In SHADER_READ_ONLY_OPTIMAL once
    /// `up` has flushed.
    pub fn sampled_cubes(gpu: &Gpu, up: &mut Uploader, name: &str, format: vk::Format, size: u32, levels: u32, face_bytes: impl Fn(u32) -> usize, cubes: &[&[u8]]) -> Result<Image> {
        anyhow::ensure!(gpu.caps.cube_arrays, "{name}: the device cannot sample cube-map arrays (imageCubeArray)");
        let info = vk::ImageCreateInfo::default()
            .flags(vk::ImageCreateFlags::CUBE_COMPATIBLE)
            .format(format)
            .extent(vk::Extent3D { width: size, height: size, depth: 1 })
            .mip_levels(levels)
            .array_layers(6 * cubes.len() as u32)
            .usage(vk::ImageUsageFlags::SAMPLED | vk::ImageUsageFlags::TRANSFER_DST);
        let image = gpu.own(Image::create(gpu, name, &info, vk::ImageViewType::CUBE_ARRAY, vk::ImageAspectFlags::COLOR)?);
        let mut parts = Vec::with_capacity(cubes.len() * 6 * levels as usize);
        for (c, bytes) in cubes.iter().enumerate() {
            let mut at = 0usize;
            for level in 0..levels {
                let face = face_bytes(level);
                for f in 0..6u32 {
                    let part = bytes.get(at..at + face).with_context(|| format!("{name}: cube {c} is shorter than {levels} levels of {size}-texel faces"))?;
                    parts.push((part, level, 6 * c as u32 + f));
                    at += face;
                }
            }
        }
        up.image(gpu, &image, &parts)?;
        Ok(image.keep())
    }

    /// Free the view, the image and its memory (once: later calls do nothing).
    pub fn destroy(&mut self, gpu: &Gpu) {
        unsafe {
            gpu.device.destroy_image_view(std::mem::take(&mut self.view), None);
            gpu.device.destroy_image(std::mem::take(&mut self.image), None);
        }
        if let Some(a) = self.allocation.take() {
            let _ = gpu.allocator.lock().unwrap().free(a);
        }
    }
}

impl Gpu {
    /// Make the `nth` allocation from now fail (1: the next one) as if the device were out of
    /// memory; 0 cancels. For the tests of error paths: every object made before the failure
    /// must be freed by the constructor that fails.
    pub fn fail_allocation(&self, nth: u64) {
        self.allocation_fault.store(nth, Ordering::Relaxed);
    }

    /// The names of the live allocations of buffers and images (the overlay's own allocations
    /// included), sorted: what the error-path tests compare before and after.
    pub fn live_allocations(&self) -> Vec<String> {
        let mut names: Vec<String> = self.allocator.lock().unwrap().generate_report().allocations.into_iter().map(|a| a.name).collect();
        names.sort();
        names
    }

    /// Device memory in bytes: what the live buffers and images hold, and what the allocator's
    /// blocks hold in all (the first's sum, plus free room). The soak compares the first over
    /// thousands of frames: a buffer made per frame and never freed grows it, though it fits in a
    /// block already there.
    pub fn device_memory(&self) -> (u64, u64) {
        let report = self.allocator.lock().unwrap().generate_report();
        (report.total_allocated_bytes, report.total_capacity_bytes)
    }
}

/// Memory for one buffer (`linear`) or optimally tiled image from the shared allocator.
fn allocate(gpu: &Gpu, name: &str, requirements: vk::MemoryRequirements, location: MemoryLocation, linear: bool) -> Result<Allocation> {
    let left = gpu.allocation_fault.load(Ordering::Relaxed);
    if left > 0 {
        gpu.allocation_fault.store(left - 1, Ordering::Relaxed);
        if left == 1 {
            bail!("allocating {} bytes for '{name}': out of device memory (injected by Gpu::fail_allocation)", requirements.size);
        }
    }
    gpu.allocator
        .lock()
        .unwrap()
        .allocate(&AllocationCreateDesc { name, requirements, location, linear, allocation_scheme: AllocationScheme::GpuAllocatorManaged })
        .map_err(|e| anyhow!("allocating {} bytes for '{name}': {e}", requirements.size))
}

pub fn full_range(aspect: vk::ImageAspectFlags, mip_levels: u32) -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange { aspect_mask: aspect, base_mip_level: 0, level_count: mip_levels, base_array_layer: 0, layer_count: 1 }
}

/// The stages that test and write depth.
const DEPTH_TESTS: vk::PipelineStageFlags2 =
    vk::PipelineStageFlags2::from_raw(vk::PipelineStageFlags2::EARLY_FRAGMENT_TESTS.as_raw() | vk::PipelineStageFlags2::LATE_FRAGMENT_TESTS.as_raw());

/// An image layout transition with the stages and accesses on both sides.
#[derive(Clone, Copy)]
pub struct Transition {
    pub old: vk::ImageLayout,
    pub new: vk::ImageLayout,
    pub src_stage: vk::PipelineStageFlags2,
    pub src_access: vk::AccessFlags2,
    pub dst_stage: vk::PipelineStageFlags2,
    pub dst_access: vk::AccessFlags2,
}

impl Transition {
    pub const UNDEFINED_TO_TRANSFER_DST: Transition = Transition {
        old: vk::ImageLayout::UNDEFINED,
        new: vk::ImageLayout::TRANSFER_DST_OPTIMAL,
        src_stage: vk::PipelineStageFlags2::TOP_OF_PIPE,
        src_access: vk::AccessFlags2::NONE,
        dst_stage: vk::PipelineStageFlags2::COPY,
        dst_access: vk::AccessFlags2::TRANSFER_WRITE,
    };
    pub const TRANSFER_DST_TO_SAMPLED: Transition = Transition {
        old: vk::ImageLayout::TRANSFER_DST_OPTIMAL,
        new: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
        src_stage: vk::PipelineStageFlags2::COPY,
        src_access: vk::AccessFlags2::TRANSFER_WRITE,
        dst_stage: vk::PipelineStageFlags2::FRAGMENT_SHADER,
        dst_access: vk::AccessFlags2::SHADER_SAMPLED_READ,
    };
    /// Start of a frame: previous contents are discarded (the pass clears).
    pub const COLOR_ATTACHMENT_DISCARD: Transition = Transition {
        old: vk::ImageLayout::UNDEFINED,
        new: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
        src_stage: vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT,
        src_access: vk::AccessFlags2::NONE,
        dst_stage: vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT,
        dst_access: vk::AccessFlags2::COLOR_ATTACHMENT_WRITE,
    };
    pub const DEPTH_ATTACHMENT_DISCARD: Transition = Transition {
        old: vk::ImageLayout::UNDEFINED,
        new: vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL,
        src_stage: DEPTH_TESTS,
        src_access: vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_WRITE,
        dst_stage: DEPTH_TESTS,
        dst_access: vk::AccessFlags2::from_raw(
            vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_READ.as_raw() | vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_WRITE.as_raw(),
        ),
    };
    /// After the depth pre-pass: its writes become visible to the shading pass's depth tests.
    pub const DEPTH_WRITE_TO_TEST: Transition = Transition {
        old: vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL,
        new: vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL,
        src_stage: DEPTH_TESTS,
        src_access: vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_WRITE,
        dst_stage: DEPTH_TESTS,
        dst_access: vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_READ,
    };
    /// Start of a frame for an attachment the previous frame sampled (the renderer's HDR colour
    /// target): discard, after those reads (a write-after-read across frames in flight).
    pub const SAMPLED_TO_COLOR_ATTACHMENT_DISCARD: Transition = Transition {
        old: vk::ImageLayout::UNDEFINED,
        new: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
        src_stage: vk::PipelineStageFlags2::from_raw(vk::PipelineStageFlags2::FRAGMENT_SHADER.as_raw() | vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT.as_raw()),
        src_access: vk::AccessFlags2::NONE,
        dst_stage: vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT,
        dst_access: vk::AccessFlags2::COLOR_ATTACHMENT_WRITE,
    };
    /// A rendered colour attachment becomes a texture for the next pass.
    pub const COLOR_ATTACHMENT_TO_SAMPLED: Transition = Transition {
        old: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
        new: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
        src_stage: vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT,
        src_access: vk::AccessFlags2::COLOR_ATTACHMENT_WRITE,
        dst_stage: vk::PipelineStageFlags2::FRAGMENT_SHADER,
        dst_access: vk::AccessFlags2::SHADER_SAMPLED_READ,
    };
    /// A depth map the previous frame sampled (the sun's shadow map) is rendered again: discard,
    /// after those reads.
    pub const SAMPLED_TO_DEPTH_ATTACHMENT_DISCARD: Transition = Transition {
        old: vk::ImageLayout::UNDEFINED,
        new: vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL,
        src_stage: vk::PipelineStageFlags2::FRAGMENT_SHADER,
        src_access: vk::AccessFlags2::NONE,
        dst_stage: DEPTH_TESTS,
        dst_access: vk::AccessFlags2::from_raw(
            vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_READ.as_raw() | vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_WRITE.as_raw(),
        ),
    };
    /// A rendered depth map becomes a (comparison) texture for the shading pass.
    pub const DEPTH_ATTACHMENT_TO_SAMPLED: Transition = Transition {
        old: vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL,
        new: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
        src_stage: DEPTH_TESTS,
        src_access: vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_WRITE,
        dst_stage: vk::PipelineStageFlags2::FRAGMENT_SHADER,
        dst_access: vk::AccessFlags2::SHADER_SAMPLED_READ,
    };
    /// A depth map earlier frames copied from (the shadow map's cached static part) is rendered
    /// again: discard, after those copies.
    pub const TRANSFER_SRC_TO_DEPTH_ATTACHMENT_DISCARD: Transition = Transition {
        old: vk::ImageLayout::UNDEFINED,
        new: vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL,
        src_stage: vk::PipelineStageFlags2::COPY,
        src_access: vk::AccessFlags2::NONE,
        dst_stage: DEPTH_TESTS,
        dst_access: vk::AccessFlags2::from_raw(
            vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_READ.as_raw() | vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_WRITE.as_raw(),
        ),
    };
    /// A rendered depth map becomes the source of copies.
    pub const DEPTH_ATTACHMENT_TO_TRANSFER_SRC: Transition = Transition {
        old: vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL,
        new: vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
        src_stage: DEPTH_TESTS,
        src_access: vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_WRITE,
        dst_stage: vk::PipelineStageFlags2::COPY,
        dst_access: vk::AccessFlags2::TRANSFER_READ,
    };
    /// A map the previous frame sampled is overwritten by a copy: discard, after those reads.
    pub const SAMPLED_TO_TRANSFER_DST_DISCARD: Transition = Transition {
        old: vk::ImageLayout::UNDEFINED,
        new: vk::ImageLayout::TRANSFER_DST_OPTIMAL,
        src_stage: vk::PipelineStageFlags2::FRAGMENT_SHADER,
        src_access: vk::AccessFlags2::NONE,
        dst_stage: vk::PipelineStageFlags2::COPY,
        dst_access: vk::AccessFlags2::TRANSFER_WRITE,
    };
    /// Depth rendering continues on top of what a copy wrote.
    pub const TRANSFER_DST_TO_DEPTH_ATTACHMENT: Transition = Transition {
        old: vk::ImageLayout::TRANSFER_DST_OPTIMAL,
        new: vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL,
        src_stage: vk::PipelineStageFlags2::COPY,
        src_access: vk::AccessFlags2::TRANSFER_WRITE,
        dst_stage: DEPTH_TESTS,
        dst_access: vk::AccessFlags2::from_raw(
            vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_READ.as_raw() | vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_WRITE.as_raw(),
        ),
    };
    /// A new image that is only ever sampled until first rendered (no contents yet).
    pub const UNDEFINED_TO_SAMPLED: Transition = Transition {
        old: vk::ImageLayout::UNDEFINED,
        new: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
        src_stage: vk::PipelineStageFlags2::TOP_OF_PIPE,
        src_access: vk::AccessFlags2::NONE,
        dst_stage: vk::PipelineStageFlags2::FRAGMENT_SHADER,
        dst_access: vk::AccessFlags2::SHADER_SAMPLED_READ,
    };
    pub const COLOR_ATTACHMENT_TO_TRANSFER_SRC: Transition = Transition {
        old: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
        new: vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
        src_stage: vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT,
        src_access: vk::AccessFlags2::COLOR_ATTACHMENT_WRITE,
        dst_stage: vk::PipelineStageFlags2::COPY,
        dst_access: vk::AccessFlags2::TRANSFER_READ,
    };
    /// The overlay's pass loads and blends onto what the scene passes wrote.
    pub const COLOR_ATTACHMENT_TO_OVERLAY: Transition = Transition {
        old: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
        new: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
        src_stage: vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT,
        src_access: vk::AccessFlags2::COLOR_ATTACHMENT_WRITE,
        dst_stage: vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT,
        dst_access: vk::AccessFlags2::from_raw(vk::AccessFlags2::COLOR_ATTACHMENT_READ.as_raw() | vk::AccessFlags2::COLOR_ATTACHMENT_WRITE.as_raw()),
    };
    pub const COLOR_ATTACHMENT_TO_PRESENT: Transition = Transition {
        old: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
        new: vk::ImageLayout::PRESENT_SRC_KHR,
        src_stage: vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT,
        src_access: vk::AccessFlags2::COLOR_ATTACHMENT_WRITE,
        dst_stage: vk::PipelineStageFlags2::BOTTOM_OF_PIPE,
        dst_access: vk::AccessFlags2::NONE,
    };
}

pub fn barrier(gpu: &Gpu, cb: vk::CommandBuffer, image: vk::Image, range: vk::ImageSubresourceRange, t: Transition) {
    let b = [vk::ImageMemoryBarrier2::default()
        .image(image)
        .subresource_range(range)
        .old_layout(t.old)
        .new_layout(t.new)
        .src_stage_mask(t.src_stage)
        .src_access_mask(t.src_access)
        .dst_stage_mask(t.dst_stage)
        .dst_access_mask(t.dst_access)];
    unsafe { gpu.device.cmd_pipeline_barrier2(cb, &vk::DependencyInfo::default().image_memory_barriers(&b)) };
}
