//! The forward renderer: one graphics pipeline (dynamic rendering, reversed-Z depth) that draws a
//! `GpuScene` into any colour + depth attachment pair. Used by the headless target and the window.

use crate::camera::Camera;
use crate::gpu::{barrier, full_range, Buffer, Gpu, Transition};
use crate::scene::GpuScene;
use crate::shaders;
use crate::visibility::Visibility;
use anyhow::Result;
use ash::vk;
use glam::{Mat3, Mat4, Vec3, Vec4};
use gpu_allocator::MemoryLocation;

/// Mirrors `Frame` in shaders/frame.glsl (std140).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct FrameUniforms {
    pub view_proj: Mat4,
    pub camera_pos: Vec4,
    pub sun_dir: Vec4,
    pub sun_color: Vec4,
    pub ambient: Vec4,
}

/// Mirrors the push-constant block of shaders/mesh.vert (128 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
struct DrawPush {
    model: Mat4,
    /// Columns of the normal matrix; `.w` of column 0 carries the alpha-test cutoff.
    normal_cols: [Vec4; 3],
    base_color: Vec4,
}
const _: () = assert!(std::mem::size_of::<DrawPush>() == 128);

/// Lighting that stands in until lightmaps and probes land.
#[derive(Debug, Clone, Copy)]
pub struct Lighting {
    pub sun_dir: Vec3,
    pub sun_color: Vec3,
    pub ambient: Vec3,
}

impl Default for Lighting {
    fn default() -> Self {
        Lighting { sun_dir: Vec3::new(0.35, 0.8, 0.45).normalize(), sun_color: Vec3::splat(0.85), ambient: Vec3::splat(0.22) }
    }
}

impl Lighting {
    /// The stand-in lighting for a pack: its first sun's direction and tint when it has one.
    pub fn for_pack(manifest: &pack::Manifest) -> Lighting {
        let mut l = Lighting::default();
        if let Some(sun) = manifest.lights.iter().find(|l| l.kind == pack::LightKind::Sun) {
            let towards_sun = -Vec3::from(sun.direction);
            if towards_sun.length_squared() > 0.0 {
                l.sun_dir = towards_sun.normalize();
            }
            let tint = Vec3::from(sun.color);
            l.sun_color = tint / tint.max_element().max(1e-6) * l.sun_color.x;
        }
        l
    }
}

pub const CLEAR_COLOR: [f32; 4] = [0.32, 0.42, 0.55, 1.0];

/// The attachments one frame renders into.
pub struct FrameTarget {
    pub color_image: vk::Image,
    pub color_view: vk::ImageView,
    pub depth_image: vk::Image,
    pub depth_view: vk::ImageView,
    pub extent: vk::Extent2D,
}

pub struct Renderer {
    pub color_format: vk::Format,
    pub depth_format: vk::Format,
    pub material_layout: vk::DescriptorSetLayout,
    frame_layout: vk::DescriptorSetLayout,
    pipeline_layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    pool: vk::DescriptorPool,
    /// One uniform buffer and descriptor set per frame in flight.
    frame_ubos: Vec<Buffer>,
    frame_sets: Vec<vk::DescriptorSet>,
    /// Culling and LOD state and settings; `visibility.counts` are the last frame's counters.
    pub visibility: Visibility,
}

/// Normal matrix: inverse-transpose of the 3x3 part (not the cofactor, which flips normals of
/// mirrored instances; pipeline.md §1).
pub fn normal_matrix(model: Mat4) -> Mat3 {
    Mat3::from_mat4(model).inverse().transpose()
}

impl Renderer {
    pub fn new(gpu: &Gpu, color_format: vk::Format, frames_in_flight: usize) -> Result<Renderer> {
        let d = &gpu.device;
        let depth_format = gpu.caps.depth_format;
        let frame_binding = [vk::DescriptorSetLayoutBinding::default()
            .binding(0)
            .descriptor_type(vk::DescriptorType::UNIFORM_BUFFER)
            .descriptor_count(1)
            .stage_flags(vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT)];
        let material_binding = [vk::DescriptorSetLayoutBinding::default()
            .binding(0)
            .descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER)
            .descriptor_count(1)
            .stage_flags(vk::ShaderStageFlags::FRAGMENT)];
        let frame_layout = unsafe {
            d.create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(&frame_binding), None)?
        };
        let material_layout = unsafe {
            d.create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(&material_binding), None)?
        };
        let set_layouts = [frame_layout, material_layout];
        let push = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT)
            .size(std::mem::size_of::<DrawPush>() as u32)];
        let pipeline_layout = unsafe {
            d.create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts).push_constant_ranges(&push), None)?
        };
        let pipeline = create_mesh_pipeline(gpu, pipeline_layout, color_format, depth_format)?;

        let n = frames_in_flight as u32;
        let pool_sizes = [vk::DescriptorPoolSize { ty: vk::DescriptorType::UNIFORM_BUFFER, descriptor_count: n }];
        let pool = unsafe {
            d.create_descriptor_pool(&vk::DescriptorPoolCreateInfo::default().max_sets(n).pool_sizes(&pool_sizes), None)?
        };
        let mut frame_ubos = Vec::new();
        let mut frame_sets = Vec::new();
        for _ in 0..frames_in_flight {
            let ubo = Buffer::new(
                gpu,
                "frame uniforms",
                std::mem::size_of::<FrameUniforms>() as u64,
                vk::BufferUsageFlags::UNIFORM_BUFFER,
                MemoryLocation::CpuToGpu,
            )?;
            let layouts = [frame_layout];
            let set = unsafe { d.allocate_descriptor_sets(&vk::DescriptorSetAllocateInfo::default().descriptor_pool(pool).set_layouts(&layouts))?[0] };
            let info = [vk::DescriptorBufferInfo { buffer: ubo.buffer, offset: 0, range: vk::WHOLE_SIZE }];
            let write = vk::WriteDescriptorSet::default()
                .dst_set(set)
                .dst_binding(0)
                .descriptor_type(vk::DescriptorType::UNIFORM_BUFFER)
                .buffer_info(&info);
            unsafe { d.update_descriptor_sets(&[write], &[]) };
            frame_ubos.push(ubo);
            frame_sets.push(set);
        }
        Ok(Renderer {
            color_format,
            depth_format,
            material_layout,
            frame_layout,
            pipeline_layout,
            pipeline,
            pool,
            frame_ubos,
            frame_sets,
            visibility: Visibility::default(),
        })
    }

    /// Record one frame: cull and pick LODs for `camera` (`self.visibility`), attachments from
    /// UNDEFINED to attachment layouts, clear, draw what is visible. The colour image is left in
    /// COLOR_ATTACHMENT_OPTIMAL for the caller to present or copy. `slot` selects the per-frame
    /// uniform buffer, which must not be in use by the GPU.
    #[allow(clippy::too_many_arguments)]
    pub fn record(&mut self, gpu: &Gpu, cb: vk::CommandBuffer, slot: usize, scene: &GpuScene, camera: &Camera, lighting: &Lighting, target: &FrameTarget) {
        let d = &gpu.device;
        let aspect = target.extent.width as f32 / target.extent.height as f32;
        let view_proj = camera.view_proj(aspect);
        self.visibility.update(scene, view_proj, camera.position, camera.fov_y, target.extent.height as f32);
        let uniforms = FrameUniforms {
            view_proj,
            camera_pos: camera.position.extend(1.0),
            sun_dir: lighting.sun_dir.normalize().extend(0.0),
            sun_color: lighting.sun_color.extend(0.0),
            ambient: lighting.ambient.extend(0.0),
        };
        // SAFETY: FrameUniforms is repr(C) plain floats.
        let bytes = unsafe {
            std::slice::from_raw_parts(&uniforms as *const _ as *const u8, std::mem::size_of::<FrameUniforms>())
        };
        self.frame_ubos[slot].mapped()[..bytes.len()].copy_from_slice(bytes);

        barrier(gpu, cb, target.color_image, full_range(vk::ImageAspectFlags::COLOR, 1), Transition::COLOR_ATTACHMENT_DISCARD);
        barrier(gpu, cb, target.depth_image, full_range(vk::ImageAspectFlags::DEPTH, 1), Transition::DEPTH_ATTACHMENT_DISCARD);
        let color_attachment = [vk::RenderingAttachmentInfo::default()
            .image_view(target.color_view)
            .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::STORE)
            .clear_value(vk::ClearValue { color: vk::ClearColorValue { float32: CLEAR_COLOR } })];
        // Reversed-Z: the far plane is depth 0.
        let depth_attachment = vk::RenderingAttachmentInfo::default()
            .image_view(target.depth_view)
            .image_layout(vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::DONT_CARE)
            .clear_value(vk::ClearValue { depth_stencil: vk::ClearDepthStencilValue { depth: 0.0, stencil: 0 } });
        let area = vk::Rect2D { offset: vk::Offset2D::default(), extent: target.extent };
        let rendering = vk::RenderingInfo::default()
            .render_area(area)
            .layer_count(1)
            .color_attachments(&color_attachment)
            .depth_attachment(&depth_attachment);
        unsafe {
            d.cmd_begin_rendering(cb, &rendering);
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, self.pipeline);
            d.cmd_set_viewport(
                cb,
                0,
                &[vk::Viewport {
                    x: 0.0,
                    y: 0.0,
                    width: target.extent.width as f32,
                    height: target.extent.height as f32,
                    min_depth: 0.0,
                    max_depth: 1.0,
                }],
            );
            d.cmd_set_scissor(cb, 0, &[area]);
            d.cmd_bind_descriptor_sets(cb, vk::PipelineBindPoint::GRAPHICS, self.pipeline_layout, 0, &[self.frame_sets[slot]], &[]);
            d.cmd_bind_vertex_buffers(cb, 0, &[scene.vertex_buffer.buffer], &[0]);
            d.cmd_bind_index_buffer(cb, scene.index_buffer.buffer, 0, vk::IndexType::UINT32);
            for draw in &self.visibility.draws {
                let inst = &scene.instances[draw.instance as usize];
                let mesh = &scene.meshes[inst.mesh as usize];
                let lod = &mesh.lods[draw.lod as usize];
                let n = normal_matrix(inst.world);
                // A mirrored instance (negative determinant) reverses its winding.
                let front = if inst.world.determinant() < 0.0 { vk::FrontFace::CLOCKWISE } else { vk::FrontFace::COUNTER_CLOCKWISE };
                d.cmd_set_front_face(cb, front);
                for sm in &lod.submeshes {
                    let mat = &scene.materials[sm.material as usize];
                    let push = DrawPush {
                        model: inst.world,
                        normal_cols: [n.x_axis.extend(mat.alpha_cutoff), n.y_axis.extend(0.0), n.z_axis.extend(0.0)],
                        base_color: Vec4::from(mat.base_color),
                    };
                    let push_bytes = std::slice::from_raw_parts(&push as *const _ as *const u8, std::mem::size_of::<DrawPush>());
                    d.cmd_push_constants(
                        cb,
                        self.pipeline_layout,
                        vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT,
                        0,
                        push_bytes,
                    );
                    d.cmd_set_cull_mode(cb, if mat.double_sided { vk::CullModeFlags::NONE } else { vk::CullModeFlags::BACK });
                    d.cmd_bind_descriptor_sets(cb, vk::PipelineBindPoint::GRAPHICS, self.pipeline_layout, 1, &[mat.descriptor_set], &[]);
                    d.cmd_draw_indexed(cb, sm.index_count, 1, lod.first_index + sm.first_index, lod.base_vertex, 0);
                }
            }
            d.cmd_end_rendering(cb);
        }
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        let d = &gpu.device;
        for b in &mut self.frame_ubos {
            b.destroy(gpu);
        }
        unsafe {
            d.destroy_descriptor_pool(self.pool, None);
            d.destroy_pipeline(self.pipeline, None);
            d.destroy_pipeline_layout(self.pipeline_layout, None);
            d.destroy_descriptor_set_layout(self.frame_layout, None);
            d.destroy_descriptor_set_layout(self.material_layout, None);
        }
    }
}

fn attribute_format(f: pack::AttributeFormat) -> vk::Format {
    match f {
        pack::AttributeFormat::F32x2 => vk::Format::R32G32_SFLOAT,
        pack::AttributeFormat::F32x3 => vk::Format::R32G32B32_SFLOAT,
        pack::AttributeFormat::F32x4 => vk::Format::R32G32B32A32_SFLOAT,
        pack::AttributeFormat::Unorm8x4 => vk::Format::R8G8B8A8_UNORM,
    }
}

fn create_mesh_pipeline(gpu: &Gpu, layout: vk::PipelineLayout, color_format: vk::Format, depth_format: vk::Format) -> Result<vk::Pipeline> {
    let d = &gpu.device;
    let vert = shaders::module(d, shaders::MESH_VERT)?;
    let frag = shaders::module(d, shaders::MESH_FRAG)?;
    let stages = [
        vk::PipelineShaderStageCreateInfo::default().stage(vk::ShaderStageFlags::VERTEX).module(vert).name(c"main"),
        vk::PipelineShaderStageCreateInfo::default().stage(vk::ShaderStageFlags::FRAGMENT).module(frag).name(c"main"),
    ];
    // The vertex layout comes from the pack crate: one definition of the format. Only the
    // attributes this shader reads are declared (tangent and lightmap UV arrive with normal
    // mapping and lightmaps).
    const MESH_SHADER_INPUTS: [u32; 4] = [0, 1, 3, 5];
    let bindings = [vk::VertexInputBindingDescription { binding: 0, stride: pack::VERTEX_STRIDE as u32, input_rate: vk::VertexInputRate::VERTEX }];
    let attributes: Vec<_> = pack::VERTEX_ATTRIBUTES
        .iter()
        .filter(|a| MESH_SHADER_INPUTS.contains(&a.0))
        .map(|&(location, offset, f)| vk::VertexInputAttributeDescription { location, binding: 0, format: attribute_format(f), offset })
        .collect();
    let vertex_input = vk::PipelineVertexInputStateCreateInfo::default()
        .vertex_binding_descriptions(&bindings)
        .vertex_attribute_descriptions(&attributes);
    let input_assembly = vk::PipelineInputAssemblyStateCreateInfo::default().topology(vk::PrimitiveTopology::TRIANGLE_LIST);
    let viewport = vk::PipelineViewportStateCreateInfo::default().viewport_count(1).scissor_count(1);
    // Cull mode and front face are dynamic (core 1.3): double-sided materials and mirrored
    // instances change them per draw without a second pipeline.
    let raster = vk::PipelineRasterizationStateCreateInfo::default()
        .polygon_mode(vk::PolygonMode::FILL)
        .cull_mode(vk::CullModeFlags::BACK)
        .front_face(vk::FrontFace::COUNTER_CLOCKWISE)
        .line_width(1.0);
    let multisample = vk::PipelineMultisampleStateCreateInfo::default().rasterization_samples(vk::SampleCountFlags::TYPE_1);
    let depth = vk::PipelineDepthStencilStateCreateInfo::default()
        .depth_test_enable(true)
        .depth_write_enable(true)
        .depth_compare_op(vk::CompareOp::GREATER_OR_EQUAL);
    let blend_attachment = [vk::PipelineColorBlendAttachmentState::default().color_write_mask(vk::ColorComponentFlags::RGBA)];
    let blend = vk::PipelineColorBlendStateCreateInfo::default().attachments(&blend_attachment);
    let dynamic_states = [vk::DynamicState::VIEWPORT, vk::DynamicState::SCISSOR, vk::DynamicState::CULL_MODE, vk::DynamicState::FRONT_FACE];
    let dynamic = vk::PipelineDynamicStateCreateInfo::default().dynamic_states(&dynamic_states);
    let color_formats = [color_format];
    let mut rendering = vk::PipelineRenderingCreateInfo::default().color_attachment_formats(&color_formats).depth_attachment_format(depth_format);
    let info = vk::GraphicsPipelineCreateInfo::default()
        .stages(&stages)
        .vertex_input_state(&vertex_input)
        .input_assembly_state(&input_assembly)
        .viewport_state(&viewport)
        .rasterization_state(&raster)
        .multisample_state(&multisample)
        .depth_stencil_state(&depth)
        .color_blend_state(&blend)
        .dynamic_state(&dynamic)
        .layout(layout)
        .push_next(&mut rendering);
    let result = unsafe { d.create_graphics_pipelines(vk::PipelineCache::null(), &[info], None) };
    unsafe {
        d.destroy_shader_module(vert, None);
        d.destroy_shader_module(frag, None);
    }
    let pipelines = result.map_err(|(_, e)| anyhow::anyhow!("creating the mesh pipeline: {e}"))?;
    Ok(pipelines[0])
}
