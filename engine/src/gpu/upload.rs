//! Load-time uploads through one staging ring: data is copied into a host-visible ring as it
//! comes, the copies into device buffers and images are recorded as pending, and they run in
//! one submit when the ring is full or at `flush`. A scene of many buffers, textures and mip
//! levels costs a few submits and fence waits (its bytes over the ring's size, plus one),
//! instead of one each.

use super::memory::{barrier, full_range, Transition};
use super::{Buffer, Gpu, Image};
use anyhow::Result;
use ash::vk;
use gpu_allocator::MemoryLocation;

/// Where a part starts in the ring: every texel block size and the 4 bytes buffer copies want.
const ALIGN: u64 = 16;

/// A copy waiting for the next submit.
enum Copy {
    Buffer { src: vk::Buffer, dst: vk::Buffer, region: vk::BufferCopy },
    Image { src: vk::Buffer, image: vk::Image, range: vk::ImageSubresourceRange, regions: Vec<vk::BufferImageCopy> },
}

pub struct Uploader {
    capacity: u64,
    ring: Option<Buffer>,
    used: u64,
    pending: Vec<Copy>,
    /// Staging buffers of single uploads larger than the ring, freed at the next flush.
    oversize: Vec<Buffer>,
    /// Submits made so far (each one fence wait).
    pub submits: u32,
    /// Bytes uploaded so far.
    pub bytes: u64,
}

impl Uploader {
    /// An uploader whose ring holds `capacity` bytes (made at the first upload).
    pub fn new(capacity: u64) -> Uploader {
        Uploader { capacity: capacity.max(ALIGN), ring: None, used: 0, pending: Vec::new(), oversize: Vec::new(), submits: 0, bytes: 0 }
    }

    /// Room for `len` bytes: the staging buffer, the offset in it, and the bytes to fill.
    fn reserve(&mut self, gpu: &Gpu, len: u64) -> Result<(vk::Buffer, u64, &mut [u8])> {
        self.bytes += len;
        if len > self.capacity {
            // Larger than the ring: a staging buffer of its own, freed after the next submit.
            let b = Buffer::new(gpu, "upload staging (oversize)", len, vk::BufferUsageFlags::TRANSFER_SRC, MemoryLocation::CpuToGpu)?;
            self.oversize.push(b);
            let b = self.oversize.last_mut().unwrap();
            return Ok((b.buffer, 0, &mut b.mapped()[..len as usize]));
        }
        let at = self.used.next_multiple_of(ALIGN);
        if at + len > self.capacity {
            self.flush(gpu)?;
        }
        let at = self.used.next_multiple_of(ALIGN);
        if self.ring.is_none() {
            self.ring = Some(Buffer::new(gpu, "upload ring", self.capacity, vk::BufferUsageFlags::TRANSFER_SRC, MemoryLocation::CpuToGpu)?);
        }
        self.used = at + len;
        let ring = self.ring.as_mut().unwrap();
        Ok((ring.buffer, at, &mut ring.mapped()[at as usize..(at + len) as usize]))
    }

    /// A device-local buffer that will hold `parts`, one after another, once the copy has run
    /// (at the next flush): a scene's vertices go from the pack's LODs straight into the ring,
    /// with no concatenated copy on the way.
    pub fn buffer(&mut self, gpu: &Gpu, name: &str, parts: &[&[u8]], usage: vk::BufferUsageFlags) -> Result<Buffer> {
        let len: usize = parts.iter().map(|p| p.len()).sum();
        let dst = gpu.own(Buffer::new(gpu, name, len as u64, usage | vk::BufferUsageFlags::TRANSFER_DST, MemoryLocation::GpuOnly)?);
        // An empty buffer (an empty pack's): nothing to copy (a copy of 0 bytes is invalid).
        if len > 0 {
            let (src, at, staged) = self.reserve(gpu, len as u64)?;
            let mut k = 0;
            for p in parts {
                staged[k..k + p.len()].copy_from_slice(p);
                k += p.len();
            }
            let region = vk::BufferCopy::default().src_offset(at).size(len as u64);
            self.pending.push(Copy::Buffer { src, dst: dst.buffer, region });
        }
        Ok(dst.keep())
    }

    /// Copy `parts` (texels, mip level, array layer) into `image`, a new colour image, and leave
    /// every level and layer in SHADER_READ_ONLY_OPTIMAL once the copy has run.
    pub fn image(&mut self, gpu: &Gpu, image: &Image, parts: &[(&[u8], u32, u32)]) -> Result<()> {
        // The parts are laid out in one reservation, each at an aligned offset.
        let mut offsets = Vec::with_capacity(parts.len());
        let mut total = 0u64;
        for (bytes, _, _) in parts {
            total = total.next_multiple_of(ALIGN);
            offsets.push(total);
            total += bytes.len() as u64;
        }
        let (src, at, staged) = self.reserve(gpu, total)?;
        let mut regions = Vec::with_capacity(parts.len());
        for (&(bytes, level, layer), &off) in parts.iter().zip(&offsets) {
            staged[off as usize..off as usize + bytes.len()].copy_from_slice(bytes);
            regions.push(
                vk::BufferImageCopy::default()
                    .buffer_offset(at + off)
                    .image_subresource(vk::ImageSubresourceLayers { aspect_mask: vk::ImageAspectFlags::COLOR, mip_level: level, base_array_layer: layer, layer_count: 1 })
                    .image_extent(vk::Extent3D { width: (image.extent.width >> level).max(1), height: (image.extent.height >> level).max(1), depth: 1 }),
            );
        }
        let range = vk::ImageSubresourceRange { layer_count: image.layers(), ..full_range(vk::ImageAspectFlags::COLOR, image.mip_levels) };
        self.pending.push(Copy::Image { src, image: image.image, range, regions });
        Ok(())
    }

    /// Run the pending copies (one submit, waited for) and start the ring over.
    pub fn flush(&mut self, gpu: &Gpu) -> Result<()> {
        if !self.pending.is_empty() {
            let pending = std::mem::take(&mut self.pending);
            gpu.one_shot(|cb| unsafe {
                for copy in &pending {
                    match copy {
                        Copy::Buffer { src, dst, region } => gpu.device.cmd_copy_buffer(cb, *src, *dst, std::slice::from_ref(region)),
                        Copy::Image { src, image, range, regions } => {
                            barrier(gpu, cb, *image, *range, Transition::UNDEFINED_TO_TRANSFER_DST);
                            gpu.device.cmd_copy_buffer_to_image(cb, *src, *image, vk::ImageLayout::TRANSFER_DST_OPTIMAL, regions);
                            barrier(gpu, cb, *image, *range, Transition::TRANSFER_DST_TO_SAMPLED);
                        }
                    }
                }
            })?;
            self.submits += 1;
        }
        self.used = 0;
        for mut b in self.oversize.drain(..) {
            b.destroy(gpu);
        }
        Ok(())
    }

    /// Free the ring and any staging buffers (copies not flushed are dropped).
    pub fn destroy(&mut self, gpu: &Gpu) {
        self.pending.clear();
        for mut b in self.ring.take().into_iter().chain(self.oversize.drain(..)) {
            b.destroy(gpu);
        }
    }
}
