//! Animation on the CPU side: clip sampling (`sample`), poses and skeletons (`pose`), characters walking routes (`route`), the CPU
//! reference of skinning and morphing (`skin_cpu`), the GPU skinning pass (`skin_gpu`) and the
//! pose dump for tools (`dump`). The renderer drives them through `crate::anim::animated`.

pub mod dump;
pub mod pose;
pub mod route;
pub mod sample;
pub mod skin_cpu;
pub mod skin_gpu;
pub mod animated;

use glam::Mat4;
use pack::Pack;
pub use pose::{Animator, Pose, Rig};

/// Little-endian f32s of a pack range, copied out at load so rigs and meshes do not borrow the pack.
pub(crate) fn f32s(pack: &Pack, r: pack::BufferRange) -> Vec<f32> {
    pack.bytes(r).chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
}

/// How many joint matrices the mesh on node `node` takes: its skin's joint count, or 1 (the
/// node's own world matrix) when it is not skinned.
pub fn joint_count(pack: &Pack, node: usize) -> usize {
    let anim = &pack.manifest.animation;
    anim.binding(node as u32).and_then(|b| b.skin).map_or(1, |s| anim.skins[s as usize].joints.len())
}

/// The joint matrices that place the mesh on node `node` in world space: global x inverse bind
/// for a skinned mesh (glTF ignores the mesh node's own transform then), otherwise the node's
/// world matrix. `out` has `joint_count(pack, node)` entries.
pub fn node_joint_matrices(pack: &Pack, rig: &Rig, node: usize, pose: &Pose, out: &mut [Mat4]) {
    match pack.manifest.animation.binding(node as u32).and_then(|b| b.skin) {
        Some(s) => rig.joint_matrices(s as usize, pose, out),
        None => out[0] = pose.global[node],
    }
}
