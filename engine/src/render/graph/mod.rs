//! The frame graph: passes declare what they read and write (`Io`), the graph decides which run,
//! owns the transient targets, places every barrier (sync2) and times and counts every pass.
//!
//! A pass (`Pass`) is a type in its own file under `render/passes/`; the renderer registers it
//! with one line (`passes::register`). Each frame the graph asks every registered pass to
//! declare its uses (a pass that declares nothing is skipped), creates or re-creates the
//! transient images they ask for (sized from the output; a replaced image is destroyed once no
//! frame in flight can use it, so a resize never waits for the GPU), then records the running
//! passes in order, each after the barriers its uses need and between a timestamp pair and a
//! pipeline-statistics query of its own. See `plan` for the ordering and barrier rules.

pub mod access;
pub mod plan;
mod profile;
mod rendering;

pub use access::{aspect_of, view_aspect_of, Access};
pub use plan::ResourceId;
pub use profile::{FrameProfile, PassProfile, ShaderInvocations};
pub use rendering::Rendering;

use crate::gpu::{Gpu, Image};
use crate::render::frame::FrameCx;
use anyhow::{bail, Result};
use ash::vk;
use plan::{PassUses, States, Use};
use profile::Profiler;
use std::cell::RefCell;
use std::collections::HashMap;

/// The image every frame ends in: the display (swapchain) or headless colour target, imported
/// each frame.
pub const OUTPUT: ResourceId = ResourceId("output");

/// An image as passes see it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImageRef {
    pub image: vk::Image,
    pub view: vk::ImageView,
    pub format: vk::Format,
    pub extent: vk::Extent2D,
}

/// How big a transient image is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Size {
    /// The output's size.
    Output,
    /// The 3D passes' size (the output's times the render scale, `Graph::run`'s `render`). The
    /// image is made at the output's size and passes see the region they draw (`ImageRef::extent`,
    /// from the top-left corner): a new scale every few frames re-creates nothing.
    Render,
    Fixed(vk::Extent2D),
}

/// A transient image a pass asks the graph for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ImageDesc {
    pub format: vk::Format,
    pub size: Size,
    /// Samples per pixel (TYPE_1 but for multisampled render targets).
    pub samples: vk::SampleCountFlags,
}

impl ImageDesc {
    /// A single-sampled image of the output's size.
    pub fn output(format: vk::Format) -> ImageDesc {
        ImageDesc { format, size: Size::Output, samples: vk::SampleCountFlags::TYPE_1 }
    }

    /// A single-sampled image the 3D passes draw at the render scale (`Size::Render`).
    pub fn render(format: vk::Format) -> ImageDesc {
        ImageDesc { format, size: Size::Render, samples: vk::SampleCountFlags::TYPE_1 }
    }

    pub fn samples(self, samples: vk::SampleCountFlags) -> ImageDesc {
        ImageDesc { samples, ..self }
    }
}

/// What one pass declares for this frame.
#[derive(Default)]
pub struct Io {
    uses: Vec<Use>,
    creates: Vec<(ResourceId, ImageDesc)>,
    imports: Vec<(ResourceId, ImageRef)>,
    side_effects: bool,
}

impl Io {
    /// Use an image (transient, imported, or the output) or a buffer as `access`.
    pub fn uses(&mut self, resource: ResourceId, access: Access) -> &mut Io {
        self.uses.push(Use { resource, access });
        self
    }

    /// Ask for a transient image (every pass that names it must describe it the same way).
    pub fn create(&mut self, resource: ResourceId, desc: ImageDesc) -> &mut Io {
        self.creates.push((resource, desc));
        self
    }

    /// Bring in an image the pass owns (a shadow map): the graph tracks its layout from frame to
    /// frame for as long as the same image is imported.
    pub fn import(&mut self, resource: ResourceId, image: ImageRef) -> &mut Io {
        self.imports.push((resource, image));
        self
    }

    /// The pass has effects the graph cannot see (it runs whenever it declares anything).
    pub fn side_effects(&mut self) -> &mut Io {
        self.side_effects = true;
        self
    }
}

/// What a pass records with: the command buffer, the frame slot and the frame's images.
pub struct Rec<'a> {
    pub gpu: &'a Gpu,
    pub cb: vk::CommandBuffer,
    pub slot: usize,
    images: &'a HashMap<ResourceId, ImageRef>,
}

impl Rec<'_> {
    /// An image this pass declared (or the output).
    pub fn image(&self, id: ResourceId) -> ImageRef {
        *self.images.get(&id).unwrap_or_else(|| panic!("image '{}' was not declared this frame", id.0))
    }
}

/// A render pass on the graph.
pub trait Pass {
    fn name(&self) -> &'static str;
    /// This frame's uses; declaring none skips the pass this frame.
    fn declare(&mut self, cx: &FrameCx, io: &mut Io);
    /// Record the pass (the graph has placed its barriers and begun its queries).
    fn record(&mut self, cx: &mut FrameCx, rec: &Rec) -> Result<()>;
    /// Whether the graph counts the pass's shader invocations (pipeline statistics). Lavapipe
    /// 22.3 crashes (SIGSEGV in its execution thread) on non-indexed draws inside a statistics
    /// query in some frames (the boids, the particles, the full-screen tone map after them), so
    /// the passes that make them opt out; their GPU time is still measured.
    fn counts_invocations(&self) -> bool {
        true
    }

    /// Free what the pass owns (the device is idle).
    fn destroy(&mut self, _gpu: &Gpu) {}
}

struct Transient {
    usage: vk::ImageUsageFlags,
    image: Image,
    /// The last frame that used it.
    used: u64,
}

/// Frames a transient may go unused before it is retired: switching a setting back and forth
/// (MSAA on and off, FXAA's input; the bench cycles through its variants frame by frame) keeps
/// each description's image instead of re-creating it at every switch, and one left behind by
/// a setting switched off goes soon after.
const UNUSED_FRAMES: u64 = 16;

pub struct Graph {
    states: States,
    /// Transient images by name and description (one name may have several: the HDR target
    /// with one sample and with four).
    transients: HashMap<(ResourceId, ImageDesc), Transient>,
    /// Which image each imported or transient resource was last frame (a different one starts
    /// UNDEFINED).
    imported: HashMap<ResourceId, vk::Image>,
    /// Replaced transients and the frame after which no frame in flight can use them.
    retired: Vec<(u64, Image)>,
    frame: u64,
    frames_in_flight: usize,
    profiler: Profiler,
    /// The names of the passes that ran in each slot's last frame, and whether each was counted.
    ran: Vec<Vec<(&'static str, bool)>>,
    /// Each slot's profile once read in full. The queries are read once a frame: lavapipe's
    /// pipeline statistics add the fragment count into the result again on every read (a
    /// second read of a pass's query gave 17x its fragment invocations).
    profiles: RefCell<Vec<Option<FrameProfile>>>,
}

impl Graph {
    pub fn new(gpu: &Gpu, frames_in_flight: usize) -> Result<Graph> {
        Ok(Graph {
            states: States::default(),
            transients: HashMap::new(),
            imported: HashMap::new(),
            retired: Vec::new(),
            frame: 0,
            frames_in_flight,
            profiler: Profiler::new(gpu, frames_in_flight)?,
            ran: vec![Vec::new(); frames_in_flight],
            profiles: RefCell::new(vec![None; frames_in_flight]),
        })
    }

    /// Record one frame into `cb`: `passes` in order, then `finals` (the uses the frame leaves
    /// resources in, such as the output's `Present` or a read-back buffer's `HostRead`). The
    /// output and the resources in `finals` are what the frame is for; a pass that contributes
    /// to none of them does not run. The caller has waited for `slot`'s previous frame.
    /// `render`: the region of `Size::Render` images the frame draws (at most the output's).
    #[allow(clippy::too_many_arguments)]
    pub fn run(&mut self, gpu: &Gpu, cb: vk::CommandBuffer, slot: usize, output: ImageRef, render: vk::Extent2D, cx: &mut FrameCx, passes: &mut [&mut dyn Pass], finals: &[(ResourceId, Access)]) -> Result<()> {
        self.frame += 1;
        self.collect_retired(gpu);
        let mut ios: Vec<Io> = Vec::with_capacity(passes.len());
        for p in passes.iter_mut() {
            let mut io = Io::default();
            p.declare(cx, &mut io);
            ios.push(io);
        }
        let mut images = HashMap::new();
        images.insert(OUTPUT, output);
        if self.imported.insert(OUTPUT, output.image) != Some(output.image) {
            // A new output image (a swapchain's next one): its acquire semaphore is waited on at
            // colour output, so the first use must wait for that stage to chain after it.
            self.states.0.insert(OUTPUT, plan::State { read_stages: vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT, ..plan::State::default() });
        }
        for io in &ios {
            for &(id, image) in &io.imports {
                self.track_import(id, image.image);
                images.insert(id, image);
            }
        }
        self.make_transients(gpu, &ios, output.extent, render, &mut images)?;

        // The declarations move into the plan's form (no copy); the images stay in `ios`.
        let uses: Vec<PassUses> = passes.iter().zip(&mut ios).map(|(p, io)| PassUses { name: p.name(), uses: std::mem::take(&mut io.uses), side_effects: io.side_effects }).collect();
        // The output is always what a frame is for.
        let exports: Vec<ResourceId> = std::iter::once(OUTPUT).chain(finals.iter().map(|f| f.0)).collect();
        let live = plan::live_passes(&uses, &exports);
        let ran = &mut self.ran[slot];
        ran.clear();
        self.profiles.get_mut()[slot] = None;
        self.profiler.begin_frame(gpu, cb, slot);
        for ((pass, decl), live) in passes.iter_mut().zip(&uses).zip(live) {
            if !live || decl.is_empty() {
                continue;
            }
            for u in &decl.uses {
                if !images.contains_key(&u.resource) && u.access.is_image() {
                    bail!("pass '{}' uses image '{}', which no pass creates or imports", pass.name(), u.resource.0);
                }
            }
            let barriers = self.states.plan(&decl.uses);
            emit(gpu, cb, &barriers, &images);
            let query = self.profiler.begin_pass(gpu, cb, slot, ran.len(), pass.counts_invocations());
            pass.record(cx, &Rec { gpu, cb, slot, images: &images })?;
            self.profiler.end_pass(gpu, cb, slot, ran.len(), query);
            ran.push((pass.name(), query.1));
        }
        let finals: Vec<Use> = finals.iter().map(|&(resource, access)| Use { resource, access }).collect();
        let barriers = self.states.plan(&finals);
        emit(gpu, cb, &barriers, &images);
        Ok(())
    }

    /// GPU time and shader invocations of each pass of the frame last recorded in `slot`, once
    /// the GPU has finished it; None when the device has neither timestamps nor statistics.
    pub fn profile(&self, gpu: &Gpu, slot: usize) -> Option<FrameProfile> {
        if let Some(p) = &self.profiles.borrow()[slot] {
            return Some(p.clone());
        }
        let (profile, complete) = self.profiler.read(gpu, slot, &self.ran[slot])?;
        if complete {
            self.profiles.borrow_mut()[slot] = Some(profile.clone());
        }
        Some(profile)
    }

    /// The names of the passes that ran in `slot`'s last frame, in order.
    pub fn ran(&self, slot: usize) -> Vec<&'static str> {
        self.ran[slot].iter().map(|r| r.0).collect()
    }

    fn track_import(&mut self, id: ResourceId, image: vk::Image) {
        if self.imported.insert(id, image) != Some(image) {
            self.states.forget(id);
        }
    }

    fn make_transients(&mut self, gpu: &Gpu, ios: &[Io], output: vk::Extent2D, render: vk::Extent2D, images: &mut HashMap<ResourceId, ImageRef>) -> Result<()> {
        let render = vk::Extent2D { width: render.width.clamp(1, output.width), height: render.height.clamp(1, output.height) };
        let mut wanted: Vec<(ResourceId, ImageDesc, vk::ImageUsageFlags)> = Vec::new();
        for io in ios {
            for &(id, desc) in &io.creates {
                match wanted.iter().find(|w| w.0 == id) {
                    Some(w) if w.1 != desc => bail!("two passes describe transient image '{}' differently: {:?} and {desc:?}", id.0, w.1),
                    Some(_) => {}
                    None => wanted.push((id, desc, vk::ImageUsageFlags::empty())),
                }
            }
        }
        for io in ios {
            for u in &io.uses {
                if let Some(w) = wanted.iter_mut().find(|w| w.0 == u.resource) {
                    w.2 |= u.access.image_usage();
                }
            }
        }
        for (id, desc, usage) in wanted {
            // Made at `extent`; passes see `used` of it.
            let (extent, used) = match desc.size {
                Size::Output => (output, output),
                Size::Render => (output, render),
                Size::Fixed(e) => (e, e),
            };
            let key = (id, desc);
            let keep = self.transients.get(&key).is_some_and(|t| t.image.extent == extent && t.usage.contains(usage));
            if !keep {
                // Usage only grows, so a pass switched on and off does not re-create the image.
                let usage = usage | self.transients.get(&key).map_or(vk::ImageUsageFlags::empty(), |t| t.usage);
                let image = Image::with_samples(gpu, id.0, desc.format, extent, 1, desc.samples, usage, view_aspect_of(desc.format))?;
                if let Some(old) = self.transients.insert(key, Transient { usage, image, used: self.frame }) {
                    self.retired.push((self.frame + self.frames_in_flight as u64, old.image));
                }
            }
            let t = self.transients.get_mut(&key).expect("made above");
            t.used = self.frame;
            let (image, view) = (t.image.image, t.image.view);
            // Another image under this name than last frame: its contents and layout are new.
            self.track_import(id, image);
            images.insert(id, ImageRef { image, view, format: desc.format, extent: used });
        }
        // Images no frame has used for a while go once no frame in flight can use them.
        let (frame, retire_after) = (self.frame, self.frame + self.frames_in_flight as u64);
        let stale: Vec<_> = self.transients.iter().filter(|(_, t)| t.used + UNUSED_FRAMES < frame).map(|(k, _)| *k).collect();
        for key in stale {
            let t = self.transients.remove(&key).expect("listed above");
            self.retired.push((retire_after, t.image));
        }
        Ok(())
    }

    fn collect_retired(&mut self, gpu: &Gpu) {
        let frame = self.frame;
        self.retired.retain_mut(|(after, image)| {
            let done = *after < frame;
            if done {
                image.destroy(gpu);
            }
            !done
        });
    }

    /// Destroy every transient (the caller has waited for the device).
    pub fn destroy(&mut self, gpu: &Gpu) {
        for (_, mut t) in self.transients.drain() {
            t.image.destroy(gpu);
        }
        for (_, mut image) in self.retired.drain(..) {
            image.destroy(gpu);
        }
        self.profiler.destroy(gpu);
    }
}

/// Record `barriers` as one sync2 dependency: image barriers over every level and layer of the
/// image's aspects (depth and stencil for the stencil depth formats), memory barriers for buffers.
fn emit(gpu: &Gpu, cb: vk::CommandBuffer, barriers: &[plan::Barrier], images: &HashMap<ResourceId, ImageRef>) {
    if barriers.is_empty() {
        return;
    }
    let mut image_barriers = Vec::new();
    let mut memory_barriers = Vec::new();
    for b in barriers {
        if b.image {
            let image = images[&b.resource];
            let range = vk::ImageSubresourceRange {
                aspect_mask: aspect_of(image.format),
                base_mip_level: 0,
                level_count: vk::REMAINING_MIP_LEVELS,
                base_array_layer: 0,
                layer_count: vk::REMAINING_ARRAY_LAYERS,
            };
            image_barriers.push(
                vk::ImageMemoryBarrier2::default()
                    .image(image.image)
                    .subresource_range(range)
                    .old_layout(b.old)
                    .new_layout(b.new)
                    .src_stage_mask(b.src_stages)
                    .src_access_mask(b.src_access)
                    .dst_stage_mask(b.dst_stages)
                    .dst_access_mask(b.dst_access),
            );
        } else {
            memory_barriers.push(
                vk::MemoryBarrier2::default().src_stage_mask(b.src_stages).src_access_mask(b.src_access).dst_stage_mask(b.dst_stages).dst_access_mask(b.dst_access),
            );
        }
    }
    let dependency = vk::DependencyInfo::default().image_memory_barriers(&image_barriers).memory_barriers(&memory_barriers);
    unsafe { gpu.device.cmd_pipeline_barrier2(cb, &dependency) };
}
