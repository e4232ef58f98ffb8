//! The renderer's side of animation: one animator per instance whose node has a skin or morph
//! weights, advanced on the CPU each frame without allocating, and the skinning compute pass
//! recorded once per frame for the (instance, LOD) pairs the frame draws. The skinned output is
//! world space, so the mesh passes draw those instances from it with an identity model matrix.
//!
//! Culling bounds of an animated instance come from its joints: the sphere around the joints'
//! world positions, grown by the farthest any vertex of any LOD sits from a joint that moves it
//! (measured once in the bind pose) plus the current morph displacement (each LOD is skinned and
//! morphed from its own vertices, weights and deltas). Linear blend skinning puts a
//! vertex in the convex hull of its joints' rigid images, each that far from its joint, so the
//! sphere holds every skinned vertex while the joints stay rigid (scale is accounted for by
//! the largest joint scale).

use crate::anim::skin_cpu::DeformData;
use crate::anim::skin_gpu::{JobSpec, Owner, SkinBatch, SkinPipeline};
use crate::anim::route::Route;
use crate::anim::{joint_count, Animator, Rig};
use crate::render::cull::world_sphere;
use crate::gpu::Gpu;
use crate::scene::{max_scale, GpuScene};
use crate::render::visibility::Draw;
use anyhow::{Context, Result};
use ash::vk;
use glam::{Mat4, Vec3};
use pack::Pack;
use std::time::Instant;

/// One animated instance: its animator, this frame's joint matrices, and per LOD one skinning
/// job with a slot per frame in flight (each slot has its own matrices and output, so a frame in
/// flight never sees the next frame's writes; the inputs are shared).
pub struct AnimatedInstance {
    /// Index into `GpuScene::instances`.
    pub instance: u32,
    pub node: u32,
    pub animator: Animator,
    /// Extra world transform applied after the pose (a character walking its route).
    pub root: Mat4,
    /// The route the character walks, and the inverse of its spawn placement (the pose already
    /// holds the placement; `root` replaces it with the route's).
    pub route: Option<(Route, Mat4)>,
    /// The skin the node is bound to (None: morph only, placed by the node's own matrix).
    skin: Option<usize>,
    joints: Vec<Mat4>,
    /// Bind-pose distance from any vertex of any LOD to the farthest joint that moves it (0
    /// unskinned).
    margin: f32,
    /// Per morph target, the longest position delta of any LOD.
    morph_reach: Vec<f32>,
    /// Bind bounds of the mesh as a sphere (unskinned, morph-only instances).
    bind_sphere: (Vec3, f32),
    /// Per LOD, its job in the scene's `SkinBatch`.
    jobs: Vec<u32>,
    /// This frame's (LOD) jobs wanted, reset every frame.
    wanted: Vec<bool>,
}

impl AnimatedInstance {
    /// This frame's joint matrices as the skinning pass gets them (world space).
    pub fn joint_matrices(&self) -> &[Mat4] {
        &self.joints
    }
}

/// Every animated instance of a scene, the skinning pipeline and the timings of the last frame.
pub struct AnimatedScene {
    pub rig: Rig,
    pub instances: Vec<AnimatedInstance>,
    /// Scene instance -> index into `instances`.
    lookup: Vec<Option<u32>>,
    pipe: SkinPipeline,
    /// Every instance's LODs as jobs of one batch (None only while `new` builds the instances).
    batch: Option<SkinBatch>,
    /// This frame's wanted jobs (reused).
    frame_jobs: Vec<u32>,
    /// CPU milliseconds the last `advance` took (sampling, globals, joint matrices, bounds).
    pub cpu_ms: f64,
    /// Skinning jobs (instance LODs) the last recorded frame skinned, the dispatches they took
    /// (one, unless past 65 535 workgroups), and their vertices.
    pub jobs: u32,
    pub dispatches: u32,
    pub skinned_vertices: u64,
}

/// The route of a character spawn from its params: `route` (a list of [x, y, z] waypoints in
/// level space; the cooker validated it) and `walk_speed` (m/s, default 1.2).
fn spawn_route(spawn: &pack::Spawn) -> Option<Route> {
    let waypoints: Vec<Vec3> = spawn
        .params
        .get("route")?
        .as_array()?
        .iter()
        .filter_map(|p| {
            let p = p.as_array()?;
            Some(Vec3::new(p.first()?.as_f64()? as f32, p.get(1)?.as_f64()? as f32, p.get(2)?.as_f64()? as f32))
        })
        .collect();
    let speed = spawn.params.get("walk_speed").and_then(|v| v.as_f64()).unwrap_or(1.2) as f32;
    Route::new(Vec3::from(spawn.position), &waypoints, speed)
}

/// Nodes whose mesh deforms: bound to a skin, or showing a mesh with morph targets.
pub fn animated_node(pack: &Pack, node: usize) -> bool {
    let anim = &pack.manifest.animation;
    let Some(mesh) = pack.manifest.nodes[node].mesh else { return false };
    anim.binding(node as u32).is_some_and(|b| b.skin.is_some()) || anim.deform(mesh).is_some_and(|d| d.lods.iter().any(|l| l.morph.is_some()))
}

impl AnimatedScene {
    /// None when nothing in the pack deforms. Every animator starts on clip 0 (if any) at time 0;
    /// `play` changes that.
    pub fn new(gpu: &Gpu, pack: &Pack, scene: &GpuScene, frames_in_flight: usize) -> Result<Option<AnimatedScene>> {
        // Instances are the nodes with a mesh, in node order (`GpuScene::upload`).
        let instance_nodes: Vec<usize> = pack.manifest.nodes.iter().enumerate().filter(|(_, n)| n.mesh.is_some()).map(|(i, _)| i).collect();
        debug_assert_eq!(instance_nodes.len(), scene.instances.len());
        if !instance_nodes.iter().any(|&n| animated_node(pack, n)) {
            return Ok(None);
        }
        let rig = Rig::from_pack(pack);
        // Owned until every instance is made: an error frees the ones made before it.
        let pipe = SkinPipeline::new(gpu)?;
        let mut out = gpu.own(AnimatedScene {
            rig,
            instances: Vec::new(),
            lookup: vec![None; scene.instances.len()],
            pipe,
            batch: None,
            frame_jobs: Vec::new(),
            cpu_ms: 0.0,
            jobs: 0,
            dispatches: 0,
            skinned_vertices: 0,
        });
        // The skinning jobs: per instance and LOD, the deform data of (mesh, LOD, skinned or
        // not), uploaded once however many instances show it.
        let mut sources: Vec<((u32, usize, bool), DeformData)> = Vec::new();
        let (mut owners, mut jobs) = (Vec::new(), Vec::new());
        for (i, &node) in instance_nodes.iter().enumerate() {
            if !animated_node(pack, node) {
                continue;
            }
            let (mut inst, data) = out.instance(pack, scene, i, node).with_context(|| format!("animating node '{}'", pack.manifest.nodes[node].name))?;
            let mesh = scene.instances[i].mesh;
            owners.push(Owner { joints: inst.joints.len(), targets: inst.morph_reach.len() });
            for (lod, d) in data.into_iter().enumerate() {
                let key = (mesh, lod, d.joints.is_some());
                let source = match sources.iter().position(|(k, _)| *k == key) {
                    Some(k) => k,
                    None => {
                        sources.push((key, d));
                        sources.len() - 1
                    }
                };
                inst.jobs.push(jobs.len() as u32);
                jobs.push(JobSpec { owner: owners.len() - 1, source });
            }
            out.lookup[i] = Some(out.instances.len() as u32);
            out.instances.push(inst);
        }
        let sources: Vec<&DeformData> = sources.iter().map(|(_, d)| d).collect();
        out.batch = Some(SkinBatch::new(gpu, &out.pipe, &sources, &owners, &jobs, frames_in_flight)?);
        // Room for every job: recording allocates nothing.
        out.frame_jobs = Vec::with_capacity(jobs.len());
        out.start_characters(pack);
        Ok(Some(out.keep()))
    }

    /// One animator per character spawn: the instances under the spawn's root node (the level
    /// cooker names them "<spawn>/...") play "<spawn>/<animation>" at the spawn's `speed`, from a
    /// phase set by the spawn's index (golden-ratio steps through the clip), so two characters
    /// playing one clip are not in lockstep. A spawn with a `route` (waypoints, level space)
    /// walks it as a loop from its position at `walk_speed` m/s.
    fn start_characters(&mut self, pack: &Pack) {
        for spawn in pack.manifest.spawns.iter().filter(|s| s.kind == "character") {
            let Some(route) = spawn_route(spawn) else { continue };
            let placement = Mat4::from_rotation_translation(glam::Quat::from_array(spawn.rotation).normalize(), Vec3::from(spawn.position));
            let prefix = format!("{}/", spawn.name);
            for a in &mut self.instances {
                if pack.manifest.nodes[a.node as usize].name.starts_with(&prefix) {
                    a.route = Some((route.clone(), placement.inverse()));
                    a.root = route.placement() * placement.inverse();
                }
            }
        }
        for (k, spawn) in pack.manifest.spawns.iter().enumerate().filter(|(_, s)| s.kind == "character") {
            let Some(animation) = spawn.params.get("animation").and_then(|a| a.as_str()) else { continue };
            let Some(clip) = self.rig.clip_index(&format!("{}/{animation}", spawn.name)) else { continue };
            let speed = spawn.params.get("speed").and_then(|v| v.as_f64()).unwrap_or(1.0) as f32;
            let phase = (k as f32 * 0.618_034).fract() * self.rig.clips[clip].duration;
            let prefix = format!("{}/", spawn.name);
            for i in 0..self.instances.len() {
                if pack.manifest.nodes[self.instances[i].node as usize].name.starts_with(&prefix) {
                    self.play(i, clip, phase, speed);
                }
            }
        }
    }

    /// Animated instance `index` (on node `node`), and per LOD the data its skinning job deforms
    /// (the caller makes the jobs).
    fn instance(&self, pack: &Pack, scene: &GpuScene, index: usize, node: usize) -> Result<(AnimatedInstance, Vec<DeformData>)> {
        let mesh = &scene.meshes[scene.instances[index].mesh as usize];
        let joints = vec![Mat4::IDENTITY; joint_count(pack, node)];
        // Every LOD's own data (vertices, skin, morph deltas): each is skinned and morphed from
        // its own, and the culling margins below hold whichever LOD is drawn.
        let mut all: Vec<DeformData> = Vec::with_capacity(mesh.lods.len());
        for lod in 0..mesh.lods.len() {
            all.push(DeformData::for_node(pack, node, lod).context("an animated node without a mesh")?);
        }
        if all.is_empty() {
            anyhow::bail!("a mesh without LODs");
        }
        let skin = pack.manifest.animation.binding(node as u32).and_then(|b| b.skin);
        let bind_pos: Vec<Vec3> = skin.map_or(vec![], |s| self.rig.skins[s as usize].inverse_bind.iter().map(|ibm| ibm.inverse().w_axis.truncate()).collect());
        let mut margin = 0.0f32;
        let mut morph_reach = vec![0.0f32; all.iter().map(|d| d.targets).max().unwrap_or(0)];
        for data in &all {
            if let (false, Some(js), Some(ws)) = (bind_pos.is_empty(), &data.joints, &data.weights) {
                for ((v, j), w) in data.vertices.iter().zip(js).zip(ws) {
                    for k in 0..4 {
                        if w[k] != 0.0 {
                            let p = bind_pos[(j[k] as usize).min(bind_pos.len() - 1)];
                            margin = margin.max((Vec3::from(v.position) - p).length());
                        }
                    }
                }
            }
            let n = data.vertices.len();
            for (t, reach) in morph_reach.iter_mut().enumerate().take(data.targets) {
                let longest = data.morph_positions[t * n * 3..(t + 1) * n * 3].chunks_exact(3).map(|d| Vec3::new(d[0], d[1], d[2]).length()).fold(0.0, f32::max);
                *reach = reach.max(longest);
            }
        }
        // Pose only this character's skeleton (and the node itself), not the whole level.
        let mut needed = skin.map_or(vec![], |s| self.rig.skins[s as usize].joints.clone());
        needed.push(node as u32);
        let mut animator = Animator::for_nodes(&self.rig, 0, &needed);
        if self.rig.clips.is_empty() {
            // Nothing to play: the animator holds the rest pose (`advance` skips sampling).
            animator.speed = 0.0;
        }
        let instance = AnimatedInstance {
            instance: index as u32,
            node: node as u32,
            animator,
            root: Mat4::IDENTITY,
            route: None,
            skin: skin.map(|s| s as usize),
            joints,
            margin,
            morph_reach,
            bind_sphere: ((mesh.bounds_min + mesh.bounds_max) * 0.5, (mesh.bounds_max - mesh.bounds_min).length() * 0.5),
            wanted: vec![false; mesh.lods.len()],
            jobs: Vec::with_capacity(mesh.lods.len()),
        };
        Ok((instance, all))
    }

    /// The animated instance drawing scene instance `instance`, if it is animated.
    pub fn index_of(&self, instance: u32) -> Option<usize> {
        self.lookup.get(instance as usize).copied().flatten().map(|i| i as usize)
    }

    /// Play clip `clip` on animated instance `i` from `time` seconds at `speed`.
    pub fn play(&mut self, i: usize, clip: usize, time: f32, speed: f32) {
        let a = &mut self.instances[i].animator;
        a.clip = clip;
        a.time = time;
        a.speed = speed;
        a.fade = None;
    }

    /// Advance every animator by `dt` seconds, evaluate its pose and joint matrices, and move its
    /// culling sphere in `scene.instances`. Allocates nothing.
    pub fn advance(&mut self, scene: &mut GpuScene, dt: f32) {
        let start = Instant::now();
        let rig = &self.rig;
        for a in &mut self.instances {
            if let Some((route, unplace)) = &mut a.route {
                route.advance(dt);
                a.root = route.placement() * *unplace;
            }
            if rig.clips.is_empty() {
                rig.update_globals(&mut a.animator.pose);
            } else {
                a.animator.advance(rig, dt);
            }
            let node = a.node as usize;
            let weights = rig.node_weights(node, &a.animator.pose);
            let morph: f32 = weights.iter().zip(&a.morph_reach).map(|(w, r)| w.abs() * r).sum();
            let (centre, radius) = if let Some(s) = a.skin {
                rig.joint_matrices(s, &a.animator.pose, &mut a.joints);
                let skin = &rig.skins[s];
                let (mut lo, mut hi, mut scale) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY), 0.0f32);
                for (m, &j) in a.joints.iter_mut().zip(&skin.joints) {
                    let global = a.root * a.animator.pose.global[j as usize];
                    let p = global.w_axis.truncate();
                    lo = lo.min(p);
                    hi = hi.max(p);
                    scale = scale.max(max_scale(global));
                    *m = a.root * *m;
                }
                ((lo + hi) * 0.5, (hi - lo).length() * 0.5 + (a.margin + morph) * scale)
            } else {
                let global = a.root * a.animator.pose.global[node];
                a.joints[0] = global;
                world_sphere(global, a.bind_sphere.0, a.bind_sphere.1 + morph)
            };
            scene.instances.set_sphere(a.instance as usize, centre, radius);
        }
        self.cpu_ms = start.elapsed().as_secs_f64() * 1e3;
    }

    /// Record this frame's skinning: write the joint matrices and morph weights of every
    /// instance that `draws` or `casters` use into frame slot `slot`'s buffers, and skin each
    /// (instance, LOD) they use once, all in one dispatch (the frame graph makes the output
    /// readable as vertex attributes: the skinning pass writes `render::frame::SKINNED`).
    pub fn record(&mut self, gpu: &Gpu, cb: vk::CommandBuffer, slot: usize, draws: &[Draw], casters: &[Draw]) {
        for a in &mut self.instances {
            a.wanted.fill(false);
        }
        for d in draws.iter().chain(casters) {
            if let Some(i) = self.index_of(d.instance) {
                self.instances[i].wanted[d.lod as usize] = true;
            }
        }
        let Some(batch) = self.batch.as_mut() else { return };
        self.frame_jobs.clear();
        for (owner, a) in self.instances.iter().enumerate() {
            if !a.wanted.contains(&true) {
                continue;
            }
            batch.update(slot, owner, &a.joints, self.rig.node_weights(a.node as usize, &a.animator.pose));
            self.frame_jobs.extend(a.jobs.iter().zip(&a.wanted).filter(|(_, &w)| w).map(|(&j, _)| j));
        }
        self.jobs = self.frame_jobs.len() as u32;
        (self.dispatches, self.skinned_vertices) = (0, 0);
        if !self.frame_jobs.is_empty() {
            unsafe { gpu.device.cmd_bind_pipeline(cb, vk::PipelineBindPoint::COMPUTE, self.pipe.pipeline) };
            (self.dispatches, self.skinned_vertices) = batch.dispatch(gpu, &self.pipe, cb, slot, &self.frame_jobs);
        }
    }

    /// The skinned vertices of scene instance `instance` at `lod` in frame slot `slot` (world
    /// space, indexed by the mesh's own indices from the returned base vertex), if it is
    /// animated.
    pub fn vertex_buffer(&self, instance: u32, lod: u8, slot: usize) -> Option<(vk::Buffer, i32)> {
        let a = &self.instances[self.index_of(instance)?];
        let batch = self.batch.as_ref()?;
        let (first, _) = batch.output_range(a.jobs[lod as usize] as usize);
        Some((batch.output(slot).buffer, first as i32))
    }

    /// The playback of `old`, the same pack's characters on a lost device: each instance's
    /// animator (clip, time, fade, pose), its place on its route and its joint matrices, so the
    /// characters go on from where they were instead of from their first frame.
    pub fn carry_on_from(&mut self, old: &mut AnimatedScene) {
        for (new, old) in self.instances.iter_mut().zip(old.instances.iter_mut()).filter(|(n, o)| n.instance == o.instance) {
            std::mem::swap(&mut new.animator, &mut old.animator);
            std::mem::swap(&mut new.route, &mut old.route);
            std::mem::swap(&mut new.joints, &mut old.joints);
            new.root = old.root;
        }
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        if let Some(b) = &mut self.batch {
            b.destroy(gpu);
        }
        self.pipe.destroy(gpu);
    }
}
