//! The graph's pure part: from the passes' declared uses, which passes a frame runs and the
//! barriers before each. No Vulkan calls here, so the rules are unit-tested without a device.
//!
//! Order: passes run in the order they were registered, which is the order of their writes to
//! each resource (as in program order: a pass reads what the passes registered before it wrote).
//! From the uses the graph derives the dependencies (read after write, write after read, write
//! after write) and drops every pass that nothing needs: a pass runs when it writes something
//! the frame exports (the output, a buffer the host reads) or that a running pass reads, or when
//! it is marked as having effects of its own.
//!
//! Barriers: each resource carries its state across passes and across frames (so the first write
//! of a frame waits for the reads of the frame before, which may still be in flight). A use gets
//! a barrier when its layout differs, when it writes after any access (write after write, write
//! after read), or when it reads what was written and not yet made visible to its stages. A use
//! that does not keep the contents transitions from UNDEFINED, which lets the driver discard them.

use super::access::{Access, Usage};
use ash::vk;
use std::collections::HashMap;

/// A resource by name: images and buffers share the name space.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ResourceId(pub &'static str);

/// One declared use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Use {
    pub resource: ResourceId,
    pub access: Access,
}

/// One pass's declarations for a frame.
#[derive(Clone, Debug, Default)]
pub struct PassUses {
    pub name: &'static str,
    pub uses: Vec<Use>,
    /// The pass has effects outside the graph's resources (it always runs when declared).
    pub side_effects: bool,
}

impl PassUses {
    /// Declares nothing: the pass is skipped this frame.
    pub fn is_empty(&self) -> bool {
        self.uses.is_empty() && !self.side_effects
    }
}

/// A resource's synchronisation state between uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct State {
    pub layout: vk::ImageLayout,
    /// The last write not followed by a barrier that covers every later reader: its stages and
    /// accesses (empty when there is none).
    pub write_stages: vk::PipelineStageFlags2,
    pub write_access: vk::AccessFlags2,
    /// Stages that read since the last write (a later write waits for them).
    pub read_stages: vk::PipelineStageFlags2,
    /// Stages and accesses the last write has been made visible to.
    pub visible_stages: vk::PipelineStageFlags2,
    pub visible_access: vk::AccessFlags2,
}

impl Default for State {
    fn default() -> State {
        State {
            layout: vk::ImageLayout::UNDEFINED,
            write_stages: vk::PipelineStageFlags2::NONE,
            write_access: vk::AccessFlags2::NONE,
            read_stages: vk::PipelineStageFlags2::NONE,
            visible_stages: vk::PipelineStageFlags2::NONE,
            visible_access: vk::AccessFlags2::NONE,
        }
    }
}

/// One barrier: for an image (`old`/`new` layouts) or a buffer (a memory barrier).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Barrier {
    pub resource: ResourceId,
    pub image: bool,
    pub old: vk::ImageLayout,
    pub new: vk::ImageLayout,
    pub src_stages: vk::PipelineStageFlags2,
    pub src_access: vk::AccessFlags2,
    pub dst_stages: vk::PipelineStageFlags2,
    pub dst_access: vk::AccessFlags2,
}

/// The barrier (if any) `access` needs after `state`, and the state after the use.
///
/// A write after reads waits only for the readers: each read was ordered after the last write
/// by a barrier that also made that write available, so the chain orders the writes too. A use
/// that reads the contents and has not yet been shown the last write gets it made visible.
pub fn transition(resource: ResourceId, state: State, access: Access) -> (Option<Barrier>, State) {
    let u: Usage = access.usage();
    let image = access.is_image();
    let layout_changes = image && state.layout != u.layout;
    let has_write = !state.write_stages.is_empty();
    let has_reads = !state.read_stages.is_empty();
    let reads = u.access & READS;
    let unseen = u.keeps && !reads.is_empty() && has_write && (!state.visible_stages.contains(u.stages) || !state.visible_access.contains(reads));
    let needed = layout_changes || (u.writes && (has_write || has_reads)) || unseen;
    let barrier = needed.then(|| {
        // The last write must be waited for and made available unless readers already chained
        // it (then they are what a new write waits for); a use that needs its contents also
        // waits for it, and contents not kept need no memory made visible at all.
        let wait_write = has_write && (unseen || !has_reads || (layout_changes && u.keeps));
        let src_stages = state.read_stages | if wait_write { state.write_stages } else { vk::PipelineStageFlags2::NONE };
        let src_access = if wait_write && u.keeps { state.write_access } else { vk::AccessFlags2::NONE };
        Barrier {
            resource,
            image,
            old: if u.keeps { state.layout } else { vk::ImageLayout::UNDEFINED },
            new: if image { u.layout } else { vk::ImageLayout::UNDEFINED },
            // A first use has nothing to wait for; the barrier still orders the layout change.
            src_stages,
            src_access,
            dst_stages: u.stages,
            dst_access: u.access,
        }
    });
    let mut next = state;
    if image {
        next.layout = u.layout;
    }
    if u.writes {
        // Nothing has seen this write yet: the next pass that reads it gets a barrier.
        next = State { layout: next.layout, write_stages: u.stages, write_access: u.access & WRITES, ..State::default() };
    } else {
        next.read_stages |= u.stages;
        if barrier.is_some() {
            next.visible_stages |= u.stages;
            next.visible_access |= reads;
        }
    }
    (barrier, next)
}

const WRITES: vk::AccessFlags2 = vk::AccessFlags2::from_raw(
    vk::AccessFlags2::COLOR_ATTACHMENT_WRITE.as_raw()
        | vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_WRITE.as_raw()
        | vk::AccessFlags2::TRANSFER_WRITE.as_raw()
        | vk::AccessFlags2::SHADER_STORAGE_WRITE.as_raw()
        | vk::AccessFlags2::HOST_WRITE.as_raw(),
);
const READS: vk::AccessFlags2 = vk::AccessFlags2::from_raw(!WRITES.as_raw());

/// Which of `passes` run: walking back from the end, a pass runs when it has side effects or
/// writes something still needed (an export, or what a later running pass reads or keeps); a
/// running pass that overwrites a resource without keeping it ends the need for earlier writes.
/// Returns one flag per pass.
pub fn live_passes(passes: &[PassUses], exports: &[ResourceId]) -> Vec<bool> {
    let mut live = vec![false; passes.len()];
    let mut needed: Vec<ResourceId> = exports.to_vec();
    for (i, p) in passes.iter().enumerate().rev() {
        let writes_needed = p.uses.iter().any(|u| u.access.usage().writes && needed.contains(&u.resource));
        if p.side_effects || writes_needed {
            live[i] = true;
            // What this pass overwrites without keeping, earlier passes need not produce...
            needed.retain(|r| !p.uses.iter().any(|u| u.resource == *r && u.access.usage().writes && !u.access.usage().keeps));
            // ...and what it keeps or reads, they must.
            for u in &p.uses {
                // Everything a live pass touches must be produced before it: a blended or
                // loaded attachment needs its earlier writer as much as a sampled image does.
                if u.access.usage().keeps && !needed.contains(&u.resource) {
                    needed.push(u.resource);
                }
            }
        }
    }
    live
}

/// Where each resource stands; kept by the graph from frame to frame.
#[derive(Default, Debug)]
pub struct States(pub HashMap<ResourceId, State>);

impl States {
    /// The barriers `uses` need (in declaration order, one per resource), updating the states.
    /// Declaring one resource twice in a pass is an error of the pass (caught in debug builds).
    pub fn plan(&mut self, uses: &[Use]) -> Vec<Barrier> {
        debug_assert!(
            uses.iter().enumerate().all(|(i, u)| uses[..i].iter().all(|v| v.resource != u.resource)),
            "a pass declared one resource twice: {uses:?}"
        );
        let mut out = Vec::new();
        for u in uses {
            let s = self.0.get(&u.resource).copied().unwrap_or_default();
            let (b, next) = transition(u.resource, s, u.access);
            out.extend(b);
            self.0.insert(u.resource, next);
        }
        out
    }

    /// Forget a resource's state (its image was replaced: the new one starts UNDEFINED).
    pub fn forget(&mut self, r: ResourceId) {
        self.0.remove(&r);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vk::{AccessFlags2 as A, ImageLayout as L, PipelineStageFlags2 as S};

    const HDR: ResourceId = ResourceId("hdr");
    const DEPTH: ResourceId = ResourceId("depth");

    fn run(states: &mut States, uses: &[(ResourceId, Access)]) -> Vec<Barrier> {
        states.plan(&uses.iter().map(|&(resource, access)| Use { resource, access }).collect::<Vec<_>>())
    }

    #[test]
    fn a_cleared_target_starts_undefined_and_waits_for_the_last_frames_reads() {
        let mut s = States::default();
        // Frame 1: write, then sample.
        let b = run(&mut s, &[(HDR, Access::ColorWrite)]);
        assert_eq!(b.len(), 1);
        assert_eq!((b[0].old, b[0].new, b[0].src_stages), (L::UNDEFINED, L::COLOR_ATTACHMENT_OPTIMAL, S::NONE));
        let b = run(&mut s, &[(HDR, Access::SampledFragment)]);
        assert_eq!((b[0].old, b[0].new), (L::COLOR_ATTACHMENT_OPTIMAL, L::SHADER_READ_ONLY_OPTIMAL));
        assert_eq!((b[0].src_stages, b[0].src_access), (S::COLOR_ATTACHMENT_OUTPUT, A::COLOR_ATTACHMENT_WRITE));
        assert_eq!((b[0].dst_stages, b[0].dst_access), (S::FRAGMENT_SHADER, A::SHADER_SAMPLED_READ));
        // Frame 2: the clear discards (UNDEFINED) after the sampling of frame 1 (write after read).
        let b = run(&mut s, &[(HDR, Access::ColorWrite)]);
        assert_eq!((b[0].old, b[0].src_stages, b[0].src_access), (L::UNDEFINED, S::FRAGMENT_SHADER, A::NONE));
    }

    #[test]
    fn depth_prepass_then_equal_test_then_blend_passes() {
        let mut s = States::default();
        run(&mut s, &[(DEPTH, Access::DepthWrite)]);
        // The shading pass's EQUAL test reads the pre-pass's writes: same layout, one barrier.
        let b = run(&mut s, &[(DEPTH, Access::DepthTest), (HDR, Access::ColorWrite)]);
        let depth = b.iter().find(|b| b.resource == DEPTH).unwrap();
        assert_eq!((depth.old, depth.new), (L::DEPTH_ATTACHMENT_OPTIMAL, L::DEPTH_ATTACHMENT_OPTIMAL));
        assert!(depth.src_access.contains(A::DEPTH_STENCIL_ATTACHMENT_WRITE));
        // A second test-only pass needs nothing more for depth; the blend after a write does.
        let b = run(&mut s, &[(DEPTH, Access::DepthTest), (HDR, Access::ColorBlend)]);
        assert_eq!(b.iter().map(|b| b.resource).collect::<Vec<_>>(), vec![HDR]);
        assert_eq!(b[0].old, L::COLOR_ATTACHMENT_OPTIMAL, "a blend keeps the contents");
        assert!(b[0].src_access.contains(A::COLOR_ATTACHMENT_WRITE));
        // A depth write after reads waits for them (write after read, execution only).
        let b = run(&mut s, &[(DEPTH, Access::DepthReadWrite)]);
        assert_eq!(b.len(), 1);
        assert!(b[0].src_stages.contains(S::EARLY_FRAGMENT_TESTS));
    }

    #[test]
    fn buffers_get_memory_barriers_and_host_reads_are_made_visible() {
        let counter = ResourceId("counter");
        let mut s = States::default();
        assert!(run(&mut s, &[(counter, Access::StorageWriteFragment)]).is_empty(), "a first write needs nothing");
        let b = run(&mut s, &[(counter, Access::HostRead)]);
        assert_eq!(b.len(), 1);
        assert!(!b[0].image);
        assert_eq!((b[0].src_stages, b[0].src_access, b[0].dst_stages, b[0].dst_access), (S::FRAGMENT_SHADER, A::SHADER_STORAGE_WRITE, S::HOST, A::HOST_READ));
        let skinned = ResourceId("skinned");
        run(&mut s, &[(skinned, Access::StorageWriteCompute)]);
        let b = run(&mut s, &[(skinned, Access::VertexInput)]);
        assert_eq!((b[0].dst_stages, b[0].dst_access), (S::VERTEX_ATTRIBUTE_INPUT, A::VERTEX_ATTRIBUTE_READ));
        assert!(run(&mut s, &[(skinned, Access::VertexInput)]).is_empty(), "already visible to vertex input");
        // Next frame's write waits for the vertex reads.
        let b = run(&mut s, &[(skinned, Access::StorageWriteCompute)]);
        assert_eq!((b[0].src_stages, b[0].src_access), (S::VERTEX_ATTRIBUTE_INPUT, A::NONE));
    }

    #[test]
    fn reads_in_new_stages_after_a_write_get_their_own_barrier() {
        let map = ResourceId("map");
        let mut s = States::default();
        run(&mut s, &[(map, Access::TransferDst)]);
        run(&mut s, &[(map, Access::SampledFragment)]);
        let b = run(&mut s, &[(map, Access::SampledCompute)]);
        assert_eq!(b.len(), 1, "the write was made visible to fragment shaders only");
        assert_eq!((b[0].old, b[0].new), (L::SHADER_READ_ONLY_OPTIMAL, L::SHADER_READ_ONLY_OPTIMAL));
        assert!(run(&mut s, &[(map, Access::SampledFragment)]).is_empty());
    }

    #[test]
    fn passes_nothing_needs_are_dropped() {
        let out = ResourceId("output");
        let debug = ResourceId("debug");
        let p = |name, uses: &[(ResourceId, Access)], side_effects| PassUses { name, uses: uses.iter().map(|&(resource, access)| Use { resource, access }).collect(), side_effects };
        let passes = [
            p("prepass", &[(DEPTH, Access::DepthWrite)], false),
            p("shading", &[(DEPTH, Access::DepthTest), (HDR, Access::ColorWrite)], false),
            p("debug", &[(DEPTH, Access::SampledFragment), (debug, Access::ColorWrite)], false),
            p("tonemap", &[(HDR, Access::SampledFragment), (out, Access::ColorWrite)], false),
            p("stats", &[], true),
        ];
        assert_eq!(live_passes(&passes, &[out]), vec![true, true, false, true, true]);
        assert_eq!(live_passes(&passes, &[out, debug]), vec![true; 5]);
        assert_eq!(live_passes(&passes, &[]), vec![false, false, false, false, true]);
        // A debug view that overwrites the output with the depth: the tone map and the shading
        // (which only tests depth after the pre-pass) are not needed.
        let mut with_view = passes.to_vec();
        with_view.insert(4, p("depth view", &[(DEPTH, Access::SampledFragment), (out, Access::ColorWrite)], false));
        assert_eq!(live_passes(&with_view, &[out]), vec![true, false, false, false, true, true]);
    }
}
