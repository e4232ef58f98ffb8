//! One sampled image input of a full-screen pass (the tone map's HDR target, the depth view's
//! depth), as a descriptor set per frame slot. A slot's set is rewritten when the image it was
//! last pointed at changes (a resize re-creates transients): the graph's caller has waited for
//! that slot's previous frame, so no frame in flight reads the set being written, and a resize
//! needs no wait for the device.

use crate::gpu::Gpu;
use anyhow::Result;
use ash::vk;

pub struct SampledInput {
    pub layout: vk::DescriptorSetLayout,
    pool: vk::DescriptorPool,
    sets: Vec<vk::DescriptorSet>,
    bound: Vec<vk::ImageView>,
    sampler: vk::Sampler,
}

impl SampledInput {
    /// Sets for `frames_in_flight` slots sampling with `filter`, clamped at the edges.
    pub fn new(gpu: &Gpu, frames_in_flight: usize, filter: vk::Filter) -> Result<SampledInput> {
        let d = &gpu.device;
        let binding = [vk::DescriptorSetLayoutBinding::default()
            .binding(0)
            .descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER)
            .descriptor_count(1)
            .stage_flags(vk::ShaderStageFlags::FRAGMENT)];
        let n = frames_in_flight as u32;
        // Owned until the input is whole: an error frees what was made before it.
        let layout = gpu.own(unsafe { d.create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(&binding), None)? });
        let sizes = [vk::DescriptorPoolSize { ty: vk::DescriptorType::COMBINED_IMAGE_SAMPLER, descriptor_count: n }];
        let pool = gpu.own(unsafe { d.create_descriptor_pool(&vk::DescriptorPoolCreateInfo::default().max_sets(n).pool_sizes(&sizes), None)? });
        let layouts = vec![*layout; frames_in_flight];
        let sets = unsafe { d.allocate_descriptor_sets(&vk::DescriptorSetAllocateInfo::default().descriptor_pool(*pool).set_layouts(&layouts))? };
        let clamp = vk::SamplerAddressMode::CLAMP_TO_EDGE;
        let info = vk::SamplerCreateInfo::default().mag_filter(filter).min_filter(filter).address_mode_u(clamp).address_mode_v(clamp).address_mode_w(clamp);
        let sampler = unsafe { d.create_sampler(&info, None)? };
        Ok(SampledInput { layout: layout.keep(), pool: pool.keep(), sets, bound: vec![vk::ImageView::null(); frames_in_flight], sampler })
    }

    /// Slot `slot`'s set, pointing at `view` (in SHADER_READ_ONLY_OPTIMAL).
    pub fn set(&mut self, gpu: &Gpu, slot: usize, view: vk::ImageView) -> vk::DescriptorSet {
        if self.bound[slot] != view {
            let info = [vk::DescriptorImageInfo { sampler: self.sampler, image_view: view, image_layout: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL }];
            let write = vk::WriteDescriptorSet::default().dst_set(self.sets[slot]).dst_binding(0).descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER).image_info(&info);
            unsafe { gpu.device.update_descriptor_sets(&[write], &[]) };
            self.bound[slot] = view;
        }
        self.sets[slot]
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        unsafe {
            gpu.device.destroy_sampler(self.sampler, None);
            gpu.device.destroy_descriptor_pool(self.pool, None);
            gpu.device.destroy_descriptor_set_layout(self.layout, None);
        }
    }
}
