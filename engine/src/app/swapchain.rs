//! The window's swapchain (images, views, a "rendered" semaphore each) and the per-frame-in-flight
//! command buffers, fences and "acquired" semaphores.

use super::FRAMES_IN_FLIGHT;
use crate::gpu::{full_range, Gpu};
use anyhow::{anyhow, Result};
use ash::vk;
use winit::dpi::PhysicalSize;

/// Per-frame-in-flight command buffers and synchronisation.
pub(crate) struct Frames {
    pub pool: vk::CommandPool,
    pub cbs: Vec<vk::CommandBuffer>,
    pub fences: Vec<vk::Fence>,
    pub acquired: Vec<vk::Semaphore>,
}

impl Frames {
    pub fn new(gpu: &Gpu) -> Result<Frames> {
        let d = &gpu.device;
        // Owned until the frames are whole: an error frees what was made before it.
        unsafe {
            let pool = gpu.own(d.create_command_pool(
                &vk::CommandPoolCreateInfo::default()
                    .queue_family_index(gpu.queue_family)
                    .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER),
                None,
            )?);
            let cbs = d.allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default().command_pool(*pool).command_buffer_count(FRAMES_IN_FLIGHT as u32),
            )?;
            let mut fences = gpu.own(Vec::new());
            let mut acquired = gpu.own(Vec::new());
            for _ in 0..FRAMES_IN_FLIGHT {
                fences.push(d.create_fence(&vk::FenceCreateInfo::default().flags(vk::FenceCreateFlags::SIGNALED), None)?);
                acquired.push(d.create_semaphore(&vk::SemaphoreCreateInfo::default(), None)?);
            }
            Ok(Frames { pool: pool.keep(), cbs, fences: fences.keep(), acquired: acquired.keep() })
        }
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        unsafe {
            for &f in &self.fences {
                gpu.device.destroy_fence(f, None);
            }
            for &s in &self.acquired {
                gpu.device.destroy_semaphore(s, None);
            }
            gpu.device.destroy_command_pool(self.pool, None);
        }
    }
}

pub(crate) struct Swapchain {
    pub surface_loader: ash::khr::surface::Instance,
    pub loader: ash::khr::swapchain::Device,
    pub surface: vk::SurfaceKHR,
    pub swapchain: vk::SwapchainKHR,
    pub format: vk::Format,
    pub color_space: vk::ColorSpaceKHR,
    pub extent: vk::Extent2D,
    pub images: Vec<vk::Image>,
    pub views: Vec<vk::ImageView>,
    /// One "rendering finished" semaphore per swapchain image: presentation holds it until that
    /// image is acquired again, so it cannot be shared across frames in flight.
    pub rendered: Vec<vk::Semaphore>,
}

impl Swapchain {
    pub fn new(gpu: &Gpu, surface: vk::SurfaceKHR, size: PhysicalSize<u32>) -> Result<Swapchain> {
        let surface_loader = ash::khr::surface::Instance::new(&gpu.entry, &gpu.instance);
        let supported = unsafe { surface_loader.get_physical_device_surface_support(gpu.physical_device, gpu.queue_family, surface)? };
        if !supported {
            return Err(anyhow!("{} cannot present to this window's surface", gpu.caps.device_name));
        }
        let formats = unsafe { surface_loader.get_physical_device_surface_formats(gpu.physical_device, surface)? };
        let format = formats
            .iter()
            .find(|f| {
                matches!(f.format, vk::Format::B8G8R8A8_SRGB | vk::Format::R8G8B8A8_SRGB)
                    && f.color_space == vk::ColorSpaceKHR::SRGB_NONLINEAR
            })
            .or(formats.first())
            .copied()
            .ok_or_else(|| anyhow!("the surface offers no formats"))?;
        let loader = ash::khr::swapchain::Device::new(&gpu.instance, &gpu.device);
        // Owned (with the surface) until it is built: a failed build frees what it made.
        let mut sc = gpu.own(Swapchain {
            surface_loader,
            loader,
            surface,
            swapchain: vk::SwapchainKHR::null(),
            format: format.format,
            color_space: format.color_space,
            extent: vk::Extent2D::default(),
            images: vec![],
            views: vec![],
            rendered: vec![],
        });
        sc.build(gpu, size)?;
        Ok(sc.keep())
    }

    fn build(&mut self, gpu: &Gpu, size: PhysicalSize<u32>) -> Result<()> {
        let caps = unsafe { self.surface_loader.get_physical_device_surface_capabilities(gpu.physical_device, self.surface)? };
        self.extent = if caps.current_extent.width != u32::MAX {
            caps.current_extent
        } else {
            vk::Extent2D {
                width: size.width.clamp(caps.min_image_extent.width, caps.max_image_extent.width),
                height: size.height.clamp(caps.min_image_extent.height, caps.max_image_extent.height),
            }
        };
        if self.extent.width == 0 || self.extent.height == 0 {
            return Ok(());
        }
        let mut count = caps.min_image_count + 1;
        if caps.max_image_count > 0 {
            count = count.min(caps.max_image_count);
        }
        let old = self.swapchain;
        let info = vk::SwapchainCreateInfoKHR::default()
            .surface(self.surface)
            .min_image_count(count)
            .image_format(self.format)
            .image_color_space(self.color_space)
            .image_extent(self.extent)
            .image_array_layers(1)
            .image_usage(vk::ImageUsageFlags::COLOR_ATTACHMENT)
            .image_sharing_mode(vk::SharingMode::EXCLUSIVE)
            .pre_transform(caps.current_transform)
            .composite_alpha(vk::CompositeAlphaFlagsKHR::OPAQUE)
            .present_mode(vk::PresentModeKHR::FIFO)
            .clipped(true)
            .old_swapchain(old);
        self.swapchain = unsafe { self.loader.create_swapchain(&info, None)? };
        self.destroy_images(gpu);
        if old != vk::SwapchainKHR::null() {
            unsafe { self.loader.destroy_swapchain(old, None) };
        }
        self.images = unsafe { self.loader.get_swapchain_images(self.swapchain)? };
        for &image in &self.images {
            let view = unsafe {
                gpu.device.create_image_view(
                    &vk::ImageViewCreateInfo::default()
                        .image(image)
                        .view_type(vk::ImageViewType::TYPE_2D)
                        .format(self.format)
                        .subresource_range(full_range(vk::ImageAspectFlags::COLOR, 1)),
                    None,
                )?
            };
            self.views.push(view);
            self.rendered.push(unsafe { gpu.device.create_semaphore(&vk::SemaphoreCreateInfo::default(), None)? });
        }
        Ok(())
    }

    pub fn recreate(&mut self, gpu: &Gpu, size: PhysicalSize<u32>) -> Result<()> {
        gpu.wait_idle();
        self.build(gpu, size)
    }

    fn destroy_images(&mut self, gpu: &Gpu) {
        unsafe {
            for v in self.views.drain(..) {
                gpu.device.destroy_image_view(v, None);
            }
            for s in self.rendered.drain(..) {
                gpu.device.destroy_semaphore(s, None);
            }
        }
        self.images.clear();
    }

    /// Frees the swapchain and the surface; a second call does nothing (the handles are null
    /// after the first: a recovery destroys the lost device's before the window's teardown).
    pub fn destroy(&mut self, gpu: &Gpu) {
        self.destroy_images(gpu);
        unsafe {
            self.loader.destroy_swapchain(std::mem::take(&mut self.swapchain), None);
            self.surface_loader.destroy_surface(std::mem::take(&mut self.surface), None);
        }
    }
}
