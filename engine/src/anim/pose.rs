//! Poses: node-local TRS from sampled clips (with cross-fade), global matrices through the
//! hierarchy, and skin joint matrices (global x inverse bind). A `Pose` is allocated once per
//! rig; evaluating a frame writes into it without allocating.
//!
//! A pose evaluates a scope: the nodes some consumer needs (a character's joints and mesh node)
//! and their ancestors, not the whole pack. A level holds many characters and props in one node
//! tree; posing all of it for every character made the per-frame cost grow with the square of
//! the character count.

use super::sample::{clip_time, nlerp, ClipData, Track};
use glam::{Mat4, Quat, Vec3};
use pack::{ChannelPath, Pack};

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trs {
    pub translation: Vec3,
    pub rotation: Quat,
    pub scale: Vec3,
}

impl Trs {
    pub fn matrix(&self) -> Mat4 {
        Mat4::from_scale_rotation_translation(self.scale, self.rotation, self.translation)
    }
}

pub struct SkinData {
    pub name: String,
    pub joints: Vec<u32>,
    pub inverse_bind: Vec<Mat4>,
}

/// Everything about a pack's nodes that animation needs, read once at load.
pub struct Rig {
    pub names: Vec<String>,
    pub parents: Vec<Option<u32>>,
    /// The authored local matrix: used as-is for nodes no channel touches, so an unanimated
    /// node (even one with shear) keeps its exact transform.
    pub rest_matrix: Vec<Mat4>,
    pub rest: Vec<Trs>,
    /// Per node, where its morph weights start in `Pose::weights` and how many there are.
    pub weight_range: Vec<(usize, usize)>,
    /// Default morph weights of every node, laid out as `Pose::weights`.
    pub rest_weights: Vec<f32>,
    pub skins: Vec<SkinData>,
    pub clips: Vec<ClipData>,
}

/// Indexed by node over the whole rig, but only the nodes of `scope` are evaluated; the others
/// keep their rest values and an identity `global`.
pub struct Pose {
    /// The nodes this pose evaluates, ascending, so parents come before children.
    pub scope: Vec<u32>,
    /// Per node, whether it is in `scope` (channels on other nodes are skipped).
    in_scope: Vec<bool>,
    pub local: Vec<Trs>,
    /// Nodes whose `local` came from a channel this frame (the others use the rest matrix).
    pub touched: Vec<bool>,
    pub global: Vec<Mat4>,
    pub weights: Vec<f32>,
}

impl Rig {
    pub fn from_pack(pack: &Pack) -> Rig {
        let m = &pack.manifest;
        let anim = &m.animation;
        let rest_matrix: Vec<Mat4> = m.nodes.iter().map(|n| Mat4::from_cols_array(&n.local)).collect();
        let rest = rest_matrix
            .iter()
            .map(|l| {
                let (scale, rotation, translation) = l.to_scale_rotation_translation();
                Trs { translation, rotation, scale }
            })
            .collect();
        let mut weight_range = Vec::with_capacity(m.nodes.len());
        let mut rest_weights = Vec::new();
        for (i, n) in m.nodes.iter().enumerate() {
            let defaults = n.mesh.and_then(|mesh| anim.deform(mesh)).map_or(&[][..], |d| &d.morph_weights[..]);
            let own = anim.binding(i as u32).and_then(|b| b.weights.as_deref());
            weight_range.push((rest_weights.len(), defaults.len()));
            rest_weights.extend_from_slice(own.unwrap_or(defaults));
        }
        let skins = anim
            .skins
            .iter()
            .map(|s| SkinData {
                name: s.name.clone(),
                joints: s.joints.clone(),
                inverse_bind: super::f32s(pack, s.inverse_bind).chunks_exact(16).map(Mat4::from_cols_slice).collect(),
            })
            .collect();
        let clips = anim
            .clips
            .iter()
            .map(|c| ClipData {
                name: c.name.clone(),
                duration: c.duration,
                tracks: c
                    .channels
                    .iter()
                    .map(|ch| Track {
                        node: ch.node,
                        path: ch.path,
                        interpolation: ch.interpolation,
                        components: ch.components as usize,
                        times: super::f32s(pack, ch.times),
                        values: super::f32s(pack, ch.values),
                    })
                    .collect(),
            })
            .collect();
        Rig {
            names: m.nodes.iter().map(|n| n.name.clone()).collect(),
            parents: m.nodes.iter().map(|n| n.parent).collect(),
            rest_matrix,
            rest,
            weight_range,
            rest_weights,
            skins,
            clips,
        }
    }

    pub fn clip_index(&self, name: &str) -> Option<usize> {
        self.clips.iter().position(|c| c.name == name)
    }

    /// A pose buffer evaluating every node of this rig, at rest.
    pub fn new_pose(&self) -> Pose {
        self.pose_for(&(0..self.parents.len() as u32).collect::<Vec<_>>())
    }

    /// A pose buffer evaluating `needed` and their ancestors, at rest.
    pub fn pose_for(&self, needed: &[u32]) -> Pose {
        let mut in_scope = vec![false; self.parents.len()];
        for &n in needed {
            let mut at = Some(n);
            while let Some(i) = at.filter(|&i| !in_scope[i as usize]) {
                in_scope[i as usize] = true;
                at = self.parents[i as usize];
            }
        }
        let mut p = Pose {
            scope: (0..in_scope.len() as u32).filter(|&i| in_scope[i as usize]).collect(),
            in_scope,
            local: self.rest.clone(),
            touched: vec![false; self.rest.len()],
            global: vec![Mat4::IDENTITY; self.rest.len()],
            weights: self.rest_weights.clone(),
        };
        self.update_globals(&mut p);
        p
    }

    /// Back to the authored (bind) pose.
    pub fn reset(&self, pose: &mut Pose) {
        for &n in &pose.scope {
            let n = n as usize;
            pose.local[n] = self.rest[n];
            pose.touched[n] = false;
            let (start, len) = self.weight_range[n];
            pose.weights[start..start + len].copy_from_slice(&self.rest_weights[start..start + len]);
        }
    }

    /// The rest pose with clip `clip` applied at `time` seconds (wrapped or clamped to the clip).
    /// Globals are not updated; call `update_globals` when the pose is final.
    pub fn sample(&self, clip: usize, time: f32, looping: bool, pose: &mut Pose) {
        self.reset(pose);
        let c = &self.clips[clip];
        let t = clip_time(time, c.duration, looping);
        let mut v = [0f32; 4];
        for track in &c.tracks {
            let n = track.node as usize;
            if !pose.in_scope[n] {
                continue;
            }
            match track.path {
                ChannelPath::Weights => {
                    let (start, len) = self.weight_range[n];
                    track.sample(t, &mut pose.weights[start..start + len]);
                    continue;
                }
                ChannelPath::Translation => {
                    track.sample(t, &mut v);
                    pose.local[n].translation = Vec3::new(v[0], v[1], v[2]);
                }
                ChannelPath::Scale => {
                    track.sample(t, &mut v);
                    pose.local[n].scale = Vec3::new(v[0], v[1], v[2]);
                }
                ChannelPath::Rotation => {
                    track.sample(t, &mut v);
                    pose.local[n].rotation = Quat::from_array(v);
                }
            }
            pose.touched[n] = true;
        }
    }

    /// Cross-fade: `a` becomes (1 - w) a + w b, rotations by shortest-path nlerp. A node either
    /// pose animates counts as animated.
    /// Both poses must have the same scope (an animator's pose and its scratch do).
    pub fn blend(&self, a: &mut Pose, b: &Pose, w: f32) {
        debug_assert_eq!(a.scope, b.scope);
        for &n in &a.scope {
            let i = n as usize;
            let (la, lb) = (&mut a.local[i], &b.local[i]);
            la.translation = la.translation.lerp(lb.translation, w);
            la.scale = la.scale.lerp(lb.scale, w);
            la.rotation = nlerp(la.rotation, lb.rotation, w);
            a.touched[i] |= b.touched[i];
            let (start, len) = self.weight_range[i];
            for (x, y) in a.weights[start..start + len].iter_mut().zip(&b.weights[start..start + len]) {
                *x += (y - *x) * w;
            }
        }
    }

    /// Global matrices from local ones: parents precede children in a pack, so one pass works.
    pub fn update_globals(&self, pose: &mut Pose) {
        for &n in &pose.scope {
            let i = n as usize;
            let local = if pose.touched[i] { pose.local[i].matrix() } else { self.rest_matrix[i] };
            pose.global[i] = match self.parents[i] {
                Some(p) => pose.global[p as usize] * local,
                None => local,
            };
        }
    }

    /// Joint matrices of skin `skin` (global x inverse bind) into `out` (one per joint).
    pub fn joint_matrices(&self, skin: usize, pose: &Pose, out: &mut [Mat4]) {
        let s = &self.skins[skin];
        for ((o, &j), ibm) in out.iter_mut().zip(&s.joints).zip(&s.inverse_bind) {
            *o = pose.global[j as usize] * *ibm;
        }
    }

    /// The morph weights of node `node` in `pose`.
    pub fn node_weights<'a>(&self, node: usize, pose: &'a Pose) -> &'a [f32] {
        let (start, len) = self.weight_range[node];
        &pose.weights[start..start + len]
    }
}

/// Playback of one clip, or a cross-fade between two, at a speed; owns its pose buffers.
pub struct Animator {
    pub clip: usize,
    pub time: f32,
    pub speed: f32,
    pub looping: bool,
    /// Fading towards `(clip, time, weight)`: weight 0 is all `clip`, 1 all the other.
    pub fade: Option<(usize, f32, f32)>,
    pub pose: Pose,
    scratch: Pose,
}

impl Animator {
    /// An animator posing every node of the rig.
    pub fn new(rig: &Rig, clip: usize) -> Animator {
        Animator::for_nodes(rig, clip, &(0..rig.parents.len() as u32).collect::<Vec<_>>())
    }

    /// An animator posing only `needed` and their ancestors (see `Rig::pose_for`).
    pub fn for_nodes(rig: &Rig, clip: usize, needed: &[u32]) -> Animator {
        Animator {
            clip,
            time: 0.0,
            speed: 1.0,
            looping: true,
            fade: None,
            pose: rig.pose_for(needed),
            scratch: rig.pose_for(needed),
        }
    }

    /// Advance by `dt` seconds of game time (scaled by `speed`) and evaluate the pose.
    pub fn advance(&mut self, rig: &Rig, dt: f32) {
        self.time += dt * self.speed;
        if let Some((_, t, _)) = &mut self.fade {
            *t += dt * self.speed;
        }
        rig.sample(self.clip, self.time, self.looping, &mut self.pose);
        if let Some((other, t, w)) = self.fade {
            rig.sample(other, t, self.looping, &mut self.scratch);
            rig.blend(&mut self.pose, &self.scratch, w);
        }
        rig.update_globals(&mut self.pose);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pack::Interpolation;

    fn two_node_rig(tracks_a: Vec<Track>, tracks_b: Vec<Track>) -> Rig {
        let rest = vec![
            Trs {
                translation: Vec3::ZERO,
                rotation: Quat::IDENTITY,
                scale: Vec3::ONE
            };
            2
        ];
        Rig {
            names: vec!["root".into(), "child".into()],
            parents: vec![None, Some(0)],
            rest_matrix: vec![Mat4::IDENTITY, Mat4::from_translation(Vec3::X)],
            rest: vec![rest[0], Trs { translation: Vec3::X, ..rest[1] }],
            weight_range: vec![(0, 0), (0, 0)],
            rest_weights: vec![],
            skins: vec![],
            clips: vec![
                ClipData {
                    name: "a".into(),
                    duration: 1.0,
                    tracks: tracks_a,
                },
                ClipData {
                    name: "b".into(),
                    duration: 1.0,
                    tracks: tracks_b,
                },
            ],
        }
    }

    fn translate(node: u32, x: f32) -> Track {
        Track {
            node,
            path: ChannelPath::Translation,
            interpolation: Interpolation::Step,
            components: 3,
            times: vec![0.0],
            values: vec![x, 0.0, 0.0],
        }
    }

    #[test]
    fn globals_follow_the_hierarchy_and_cross_fade_weights_the_clips() {
        let rig = two_node_rig(vec![translate(0, 2.0)], vec![translate(0, 4.0)]);
        let mut anim = Animator::new(&rig, 0);
        anim.advance(&rig, 0.0);
        assert_eq!(anim.pose.global[1].w_axis.truncate(), Vec3::new(3.0, 0.0, 0.0));
        anim.fade = Some((1, 0.0, 0.25));
        anim.advance(&rig, 0.1);
        assert!((anim.pose.global[1].w_axis.x - (1.0 + 2.5)).abs() < 1e-6);
    }

    #[test]
    fn a_scoped_pose_evaluates_only_its_nodes_and_their_ancestors_and_agrees_with_the_full_pose() {
        // Two characters under one level root: 0 root; 1 -> 2 (a); 3 -> 4 (b).
        let rest = Trs {
            translation: Vec3::X,
            rotation: Quat::from_rotation_z(0.3),
            scale: Vec3::ONE,
        };
        let track = |node: u32, x: f32| Track {
            node,
            path: ChannelPath::Translation,
            interpolation: Interpolation::Linear,
            components: 3,
            times: vec![0.0, 1.0],
            values: vec![0.0, 0.0, 0.0, x, 1.0, 0.0],
        };
        let rig = Rig {
            names: (0..5).map(|i| format!("n{i}")).collect(),
            parents: vec![None, Some(0), Some(1), Some(0), Some(3)],
            rest_matrix: vec![rest.matrix(); 5],
            rest: vec![rest; 5],
            weight_range: vec![(0, 0); 5],
            rest_weights: vec![],
            skins: vec![],
            clips: vec![ClipData {
                name: "both".into(),
                duration: 1.0,
                tracks: vec![track(2, 2.0), track(4, -3.0), track(1, 0.5)],
            }],
        };
        let mut full = Animator::new(&rig, 0);
        let mut scoped = Animator::for_nodes(&rig, 0, &[2]);
        assert_eq!(scoped.pose.scope, vec![0, 1, 2]);
        full.advance(&rig, 0.4);
        scoped.advance(&rig, 0.4);
        for n in 0..3 {
            assert_eq!(scoped.pose.global[n], full.pose.global[n], "node {n}");
        }
        // The other character's nodes were neither sampled nor updated.
        assert!(!scoped.pose.touched[4]);
        assert_eq!(scoped.pose.global[4], Mat4::IDENTITY);
        assert_ne!(full.pose.global[4], Mat4::IDENTITY);
    }

    #[test]
    fn playback_speed_scales_clip_time() {
        let track = Track {
            node: 0,
            path: ChannelPath::Translation,
            interpolation: Interpolation::Linear,
            components: 3,
            times: vec![0.0, 1.0],
            values: vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
        };
        let rig = two_node_rig(vec![track], vec![]);
        let mut anim = Animator::new(&rig, 0);
        anim.speed = 0.5;
        anim.looping = false;
        anim.advance(&rig, 0.5);
        assert!((anim.pose.global[0].w_axis.x - 0.25).abs() < 1e-6);
    }
}
