//! How a pass uses an image or a buffer, and what that means to Vulkan: the pipeline stages,
//! memory accesses and image layout of the use, and whether it writes or keeps the contents.

use ash::vk;

/// One use of a resource by a pass. Passes declare these; the graph derives every barrier from
/// consecutive uses of a resource.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Access {
    /// Colour attachment whose previous contents are not needed (cleared, or every pixel written).
    ColorWrite,
    /// Colour attachment loaded and drawn (blended) on.
    ColorBlend,
    /// Depth attachment cleared and written.
    DepthWrite,
    /// Depth attachment loaded, tested and written.
    DepthReadWrite,
    /// Depth attachment loaded and tested, not written.
    DepthTest,
    /// Sampled by fragment shaders.
    SampledFragment,
    /// Sampled by compute shaders.
    SampledCompute,
    /// Copied from.
    TransferSrc,
    /// Copied into, previous contents not needed.
    TransferDst,
    /// Resolved from (a multisampled image averaged by vkCmdResolveImage).
    ResolveSrc,
    /// Resolved into, previous contents not needed.
    ResolveDst,
    /// Handed to the presentation engine after the frame.
    Present,
    /// Buffer written by compute shaders (storage).
    StorageWriteCompute,
    /// Buffer read by compute shaders (storage).
    StorageReadCompute,
    /// Buffer written by fragment shaders (storage: counters).
    StorageWriteFragment,
    /// Buffer read as vertex attributes.
    VertexInput,
    /// Buffer written by a copy.
    BufferTransferDst,
    /// Buffer read by the host once the frame's fence has signalled.
    HostRead,
}

/// The stages and accesses of the depth tests.
const DEPTH_TESTS: vk::PipelineStageFlags2 =
    vk::PipelineStageFlags2::from_raw(vk::PipelineStageFlags2::EARLY_FRAGMENT_TESTS.as_raw() | vk::PipelineStageFlags2::LATE_FRAGMENT_TESTS.as_raw());
const DEPTH_RW: vk::AccessFlags2 =
    vk::AccessFlags2::from_raw(vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_READ.as_raw() | vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_WRITE.as_raw());
const COLOR_RW: vk::AccessFlags2 = vk::AccessFlags2::from_raw(vk::AccessFlags2::COLOR_ATTACHMENT_READ.as_raw() | vk::AccessFlags2::COLOR_ATTACHMENT_WRITE.as_raw());

/// What an access means to the barriers around it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Usage {
    pub stages: vk::PipelineStageFlags2,
    /// Every memory access of the use (reads and writes).
    pub access: vk::AccessFlags2,
    /// The layout an image must be in (UNDEFINED for buffers).
    pub layout: vk::ImageLayout,
    /// The use writes the resource.
    pub writes: bool,
    /// The use keeps (loads) the previous contents; false lets the graph discard them.
    pub keeps: bool,
}

impl Access {
    pub fn usage(self) -> Usage {
        use vk::{AccessFlags2 as A, ImageLayout as L, PipelineStageFlags2 as S};
        let u = |stages, access, layout, writes, keeps| Usage { stages, access, layout, writes, keeps };
        match self {
            Access::ColorWrite => u(S::COLOR_ATTACHMENT_OUTPUT, A::COLOR_ATTACHMENT_WRITE, L::COLOR_ATTACHMENT_OPTIMAL, true, false),
            Access::ColorBlend => u(S::COLOR_ATTACHMENT_OUTPUT, COLOR_RW, L::COLOR_ATTACHMENT_OPTIMAL, true, true),
            Access::DepthWrite => u(DEPTH_TESTS, DEPTH_RW, L::DEPTH_ATTACHMENT_OPTIMAL, true, false),
            Access::DepthReadWrite => u(DEPTH_TESTS, DEPTH_RW, L::DEPTH_ATTACHMENT_OPTIMAL, true, true),
            // The attachment layout, not a read-only one: a pass that only tests may still store
            // (lavapipe and most drivers gain nothing from the read-only layout's transition).
            Access::DepthTest => u(DEPTH_TESTS, A::DEPTH_STENCIL_ATTACHMENT_READ, L::DEPTH_ATTACHMENT_OPTIMAL, false, true),
            Access::SampledFragment => u(S::FRAGMENT_SHADER, A::SHADER_SAMPLED_READ, L::SHADER_READ_ONLY_OPTIMAL, false, true),
            Access::SampledCompute => u(S::COMPUTE_SHADER, A::SHADER_SAMPLED_READ, L::SHADER_READ_ONLY_OPTIMAL, false, true),
            Access::TransferSrc => u(S::COPY, A::TRANSFER_READ, L::TRANSFER_SRC_OPTIMAL, false, true),
            Access::TransferDst => u(S::COPY, A::TRANSFER_WRITE, L::TRANSFER_DST_OPTIMAL, true, false),
            Access::ResolveSrc => u(S::RESOLVE, A::TRANSFER_READ, L::TRANSFER_SRC_OPTIMAL, false, true),
            Access::ResolveDst => u(S::RESOLVE, A::TRANSFER_WRITE, L::TRANSFER_DST_OPTIMAL, true, false),
            // Presentation is ordered by the semaphore the submit signals: nothing to wait on here.
            Access::Present => u(S::BOTTOM_OF_PIPE, A::NONE, L::PRESENT_SRC_KHR, false, true),
            Access::StorageWriteCompute => u(S::COMPUTE_SHADER, A::SHADER_STORAGE_WRITE, L::UNDEFINED, true, true),
            Access::StorageReadCompute => u(S::COMPUTE_SHADER, A::SHADER_STORAGE_READ, L::UNDEFINED, false, true),
            Access::StorageWriteFragment => u(S::FRAGMENT_SHADER, A::SHADER_STORAGE_WRITE, L::UNDEFINED, true, true),
            Access::VertexInput => u(S::VERTEX_ATTRIBUTE_INPUT, A::VERTEX_ATTRIBUTE_READ, L::UNDEFINED, false, true),
            Access::BufferTransferDst => u(S::COPY, A::TRANSFER_WRITE, L::UNDEFINED, true, false),
            Access::HostRead => u(S::HOST, A::HOST_READ, L::UNDEFINED, false, true),
        }
    }

    /// The image usage flag an image needs for this access (empty for buffer-only accesses).
    pub fn image_usage(self) -> vk::ImageUsageFlags {
        use vk::ImageUsageFlags as U;
        match self {
            Access::ColorWrite | Access::ColorBlend => U::COLOR_ATTACHMENT,
            Access::DepthWrite | Access::DepthReadWrite | Access::DepthTest => U::DEPTH_STENCIL_ATTACHMENT,
            Access::SampledFragment | Access::SampledCompute => U::SAMPLED,
            Access::TransferSrc | Access::ResolveSrc => U::TRANSFER_SRC,
            Access::TransferDst | Access::ResolveDst => U::TRANSFER_DST,
            _ => U::empty(),
        }
    }

    /// Whether this access applies to images (the rest are buffer accesses).
    pub fn is_image(self) -> bool {
        !matches!(self, Access::StorageWriteCompute | Access::StorageReadCompute | Access::StorageWriteFragment | Access::VertexInput | Access::BufferTransferDst | Access::HostRead)
    }
}

/// The aspect of the view passes attach and sample: depth alone for depth formats (a view of
/// both aspects cannot be sampled).
pub fn view_aspect_of(format: vk::Format) -> vk::ImageAspectFlags {
    let a = aspect_of(format);
    if a.contains(vk::ImageAspectFlags::DEPTH) { vk::ImageAspectFlags::DEPTH } else { a }
}

/// The aspects of an image of `format`: depth formats with a stencil part need both in every
/// barrier (the fallback depth formats D32_SFLOAT_S8_UINT and D24_UNORM_S8_UINT).
pub fn aspect_of(format: vk::Format) -> vk::ImageAspectFlags {
    use vk::Format as F;
    match format {
        F::D16_UNORM | F::D32_SFLOAT | F::X8_D24_UNORM_PACK32 => vk::ImageAspectFlags::DEPTH,
        F::D16_UNORM_S8_UINT | F::D24_UNORM_S8_UINT | F::D32_SFLOAT_S8_UINT => vk::ImageAspectFlags::DEPTH | vk::ImageAspectFlags::STENCIL,
        F::S8_UINT => vk::ImageAspectFlags::STENCIL,
        _ => vk::ImageAspectFlags::COLOR,
    }
}
