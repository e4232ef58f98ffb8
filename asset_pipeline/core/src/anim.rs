//! glTF skins and animations -> IR skins and clips, and the per-vertex influence clean-up.
//!
//! Every channel is checked before it reaches the pack: key times finite and strictly
//! increasing, values finite, output counts matching the sampler. Errors name the animation and
//! the channel, so a broken export can be traced to the curve that is wrong.

use crate::accessor::{self, check};
use crate::ir::{ChannelIr, ClipIr, SkinIr};
use crate::label;
use gltf::animation::{Interpolation as GltfInterpolation, Property};
use pack::{ChannelPath, Interpolation};

/// Skins, with joints as indices into the flattened node list (`node_map[gltf index]`).
pub(crate) fn cook_skins(doc: &gltf::Document, buffers: &[Vec<u8>], node_map: &[Option<u32>]) -> Result<Vec<SkinIr>, String> {
    let mut out = Vec::new();
    for skin in doc.skins() {
        let what = label("skin", skin.index(), skin.name());
        let mut joints = Vec::new();
        for j in skin.joints() {
            let mapped = node_map[j.index()].ok_or_else(|| format!("{what}: joint {} is not in the scene", label("node", j.index(), j.name())))?;
            joints.push(mapped);
        }
        let inverse_bind = match skin.inverse_bind_matrices() {
            // glTF: without the accessor every inverse bind matrix is the identity.
            None => vec![IDENTITY; joints.len()],
            Some(acc) => {
                let c = check(&acc, buffers, "inverseBindMatrices", &accessor::MAT4_F32).map_err(|e| format!("{what}: {e}"))?;
                if c.count != joints.len() {
                    return Err(format!("{what}: {} inverse bind matrices for {} joints", c.count, joints.len()));
                }
                let m = c.vecs::<16>(0.0);
                if let Some(i) = m.iter().position(|m| !m.iter().all(|x| x.is_finite())) {
                    return Err(format!("{what}: inverse bind matrix {i} is not finite"));
                }
                m
            }
        };
        if joints.len() > pack::MAX_JOINTS {
            return Err(format!("{what}: {} joints, more than the supported {}", joints.len(), pack::MAX_JOINTS));
        }
        out.push(SkinIr {
            name: skin.name().map_or_else(|| format!("skin{}", skin.index()), str::to_string),
            joints,
            inverse_bind,
        });
    }
    Ok(out)
}

const IDENTITY: [f32; 16] = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];

/// Clips, one per glTF animation. `targets_of(node)` is the morph target count of the mesh on a
/// (flattened) node. Channels on nodes outside the scene are dropped with a warning.
pub(crate) fn cook_clips(doc: &gltf::Document, buffers: &[Vec<u8>], node_map: &[Option<u32>], targets_of: &dyn Fn(u32) -> usize, warnings: &mut Vec<String>) -> Result<Vec<ClipIr>, String> {
    let mut clips = Vec::new();
    for anim in doc.animations() {
        let clip = label("animation", anim.index(), anim.name());
        let mut channels = Vec::new();
        for (k, ch) in anim.channels().enumerate() {
            let target = ch.target();
            let node = target.node();
            let path = match target.property() {
                Property::Translation => ChannelPath::Translation,
                Property::Rotation => ChannelPath::Rotation,
                Property::Scale => ChannelPath::Scale,
                Property::MorphTargetWeights => ChannelPath::Weights,
            };
            let what = format!("{clip} channel {k} ({} of {})", path_name(path), label("node", node.index(), node.name()));
            let Some(flat) = node_map[node.index()] else {
                warnings.push(format!("{what}: the node is not in the scene; channel dropped"));
                continue;
            };
            let sampler = ch.sampler();
            let interpolation = match sampler.interpolation() {
                GltfInterpolation::Step => Interpolation::Step,
                GltfInterpolation::Linear => Interpolation::Linear,
                GltfInterpolation::CubicSpline => Interpolation::Cubicspline,
            };
            let components = match path {
                ChannelPath::Translation | ChannelPath::Scale => 3,
                ChannelPath::Rotation => 4,
                ChannelPath::Weights => match targets_of(flat) {
                    0 => return Err(format!("{what}: animates morph weights but the node's mesh has no morph targets")),
                    n => n,
                },
            };
            let times = check(&sampler.input(), buffers, "sampler input", &accessor::KEY_TIMES).map_err(|e| format!("{what}: {e}"))?;
            let times: Vec<f32> = times.vecs::<1>(0.0).into_iter().map(|t| t[0]).collect();
            let expect = match path {
                ChannelPath::Translation | ChannelPath::Scale => &accessor::VEC3_F32,
                ChannelPath::Rotation => &accessor::ROTATIONS,
                ChannelPath::Weights => &accessor::MORPH_WEIGHTS,
            };
            let output = check(&sampler.output(), buffers, "sampler output", expect).map_err(|e| format!("{what}: {e}"))?;
            let values: Vec<f32> = match path {
                ChannelPath::Translation | ChannelPath::Scale => output.vecs::<3>(0.0).into_iter().flatten().collect(),
                ChannelPath::Rotation => output.vecs::<4>(0.0).into_iter().flatten().collect(),
                ChannelPath::Weights => output.vecs::<1>(0.0).into_iter().flatten().collect(),
            };
            let channel = ChannelIr {
                node: flat,
                path,
                interpolation,
                components: components as u32,
                times,
                values,
            };
            channels.push(validate_channel(channel).map_err(|e| format!("{what}: {e}"))?);
        }
        let name = anim.name().map_or_else(|| format!("animation{}", anim.index()), str::to_string);
        clips.push(ClipIr { name, channels });
    }
    Ok(clips)
}

fn path_name(p: ChannelPath) -> &'static str {
    match p {
        ChannelPath::Translation => "translation",
        ChannelPath::Rotation => "rotation",
        ChannelPath::Scale => "scale",
        ChannelPath::Weights => "weights",
    }
}

/// Check a channel's keys and values (the IR from Python crosses this too) and normalise its
/// rotation keys. The message names the problem; callers prefix the clip and channel.
pub fn validate_channel(mut ch: ChannelIr) -> Result<ChannelIr, String> {
    let keys = ch.times.len();
    let cubic = ch.interpolation == Interpolation::Cubicspline;
    if keys == 0 || (cubic && keys < 2) {
        return Err(format!("{keys} key(s) is too few for {:?} interpolation", ch.interpolation));
    }
    if let Some(i) = ch.times.iter().position(|t| !t.is_finite()) {
        return Err(format!("key time {i} is {} (not a finite number)", ch.times[i]));
    }
    if let Some(i) = ch.times.windows(2).position(|w| w[1] <= w[0]) {
        return Err(format!("key times are not strictly increasing: time {} is {} after {}", i + 1, ch.times[i + 1], ch.times[i]));
    }
    let per_key = ch.components as usize * if cubic { 3 } else { 1 };
    if ch.values.len() != keys * per_key {
        return Err(format!(
            "{} output values for {keys} keys, expected {} ({} per key for {:?})",
            ch.values.len() / ch.components.max(1) as usize,
            keys * per_key / ch.components.max(1) as usize,
            per_key / ch.components.max(1) as usize,
            ch.interpolation
        ));
    }
    if let Some(i) = ch.values.iter().position(|v| !v.is_finite()) {
        return Err(format!("output value {} of key {} is {} (not a finite number)", i % per_key, i / per_key, ch.values[i]));
    }
    if ch.path == ChannelPath::Rotation {
        // Quaternion keys (not cubic tangents) must be unit length for slerp and for the cubic
        // curve to start and end on rotations.
        let value_block = if cubic { 1 } else { 0 };
        for k in 0..keys {
            let at = k * per_key + value_block * 4;
            let q = &mut ch.values[at..at + 4];
            let len = q.iter().map(|x| x * x).sum::<f32>().sqrt();
            if len < 1e-6 {
                return Err(format!("rotation key {k} is a zero quaternion"));
            }
            q.iter_mut().for_each(|x| *x /= len);
        }
    }
    Ok(ch)
}

/// Up to eight (joint, weight) influences per vertex (JOINTS_0/1, WEIGHTS_0/1) -> the four
/// largest, renormalised to sum 1. Returns joints, weights and how many vertices had more than
/// four non-zero influences. A vertex whose weights are negative, not finite or all zero is an
/// error naming it.
pub(crate) fn reduce_influences(joints: &[[u16; 8]], weights: &[[f32; 8]]) -> Result<(Vec<[u16; 4]>, Vec<[f32; 4]>, usize), String> {
    let mut out_j = Vec::with_capacity(joints.len());
    let mut out_w = Vec::with_capacity(joints.len());
    let mut reduced = 0;
    for (v, (j, w)) in joints.iter().zip(weights).enumerate() {
        if let Some(x) = w.iter().find(|x| !x.is_finite() || **x < 0.0) {
            return Err(format!("vertex {v} has skin weight {x} (weights must be finite and non-negative)"));
        }
        let mut order: [usize; 8] = std::array::from_fn(|i| i);
        // Largest first; ties keep the authored order, so the result is deterministic.
        order.sort_by(|&a, &b| w[b].total_cmp(&w[a]));
        if w.iter().filter(|&&x| x > 0.0).count() > 4 {
            reduced += 1;
        }
        let sum: f32 = order[..4].iter().map(|&i| w[i]).sum();
        if sum <= 0.0 {
            return Err(format!("vertex {v} has no non-zero skin weight"));
        }
        let mut jj = [0u16; 4];
        let mut ww = [0f32; 4];
        for (k, &i) in order[..4].iter().enumerate() {
            if w[i] > 0.0 {
                jj[k] = j[i];
                ww[k] = w[i] / sum;
            }
        }
        out_j.push(jj);
        out_w.push(ww);
    }
    Ok((out_j, out_w, reduced))
}
