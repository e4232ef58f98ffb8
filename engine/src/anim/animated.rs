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
use crate::anim::skin_gpu::{SkinPipeline, SkinnedMesh};
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
    lods: Vec<SkinnedMesh>,
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
    /// CPU milliseconds the last `advance` took (sampling, globals, joint matrices, bounds).
    pub cpu_ms: f64,
    /// Skinning jobs (instance LODs) the last recorded frame dispatched, and their vertices.
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
            cpu_ms: 0.0,
            dispatches: 0,
            skinned_vertices: 0,
        });
        for (i, &node) in instance_nodes.iter().enumerate() {
            if !animated_node(pack, node) {
                continue;
            }
            let inst = out
                .instance(gpu, pack, scene, i, node, frames_in_flight)
                .with_context(|| format!("animating node '{}'", pack.manifest.nodes[node].name))?;
            out.lookup[i] = Some(out.instances.len() as u32);
            out.instances.push(inst);
        }
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

    fn instance(&self, gpu: &Gpu, pack: &Pack, scene: &GpuScene, index: usize, node: usize, slots: usize) -> Result<AnimatedInstance> {
        let mesh = &scene.meshes[scene.instances[index].mesh as usize];
        let joints = vec![Mat4::IDENTITY; joint_count(pack, node)];
        let mut lods = gpu.own(Vec::with_capacity(mesh.lods.len()));
        // Every LOD's own data (vertices, skin, morph deltas): each is skinned and morphed from
        // its own, and the culling margins below hold whichever LOD is drawn.
        let mut all: Vec<DeformData> = Vec::with_capacity(mesh.lods.len());
        for lod in 0..mesh.lods.len() {
            let data = DeformData::for_node(pack, node, lod).context("an animated node without a mesh")?;
            lods.push(SkinnedMesh::with_slots(gpu, &self.pipe, &data, joints.len(), slots)?);
            all.push(data);
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
        Ok(AnimatedInstance {
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
            lods: lods.keep(),
        })
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
    /// (instance, LOD) that `draws` or `casters` use into frame slot `slot`'s buffers, dispatch
    /// each once (the frame graph makes the outputs readable as vertex attributes: the skinning
    /// pass writes `render::frame::SKINNED`).
    pub fn record(&mut self, gpu: &Gpu, cb: vk::CommandBuffer, slot: usize, draws: &[Draw], casters: &[Draw]) {
        for a in &mut self.instances {
            a.wanted.fill(false);
        }
        for d in draws.iter().chain(casters) {
            if let Some(i) = self.index_of(d.instance) {
                self.instances[i].wanted[d.lod as usize] = true;
            }
        }
        self.dispatches = 0;
        self.skinned_vertices = 0;
        let dev = &gpu.device;
        for a in &mut self.instances {
            let weights = self.rig.node_weights(a.node as usize, &a.animator.pose);
            for (lod, job) in a.lods.iter_mut().enumerate() {
                if !a.wanted[lod] {
                    continue;
                }
                job.update_slot(slot, &a.joints, weights);
                if self.dispatches == 0 {
                    unsafe { dev.cmd_bind_pipeline(cb, vk::PipelineBindPoint::COMPUTE, self.pipe.pipeline) };
                }
                job.dispatch(gpu, &self.pipe, cb, slot);
                self.dispatches += 1;
                self.skinned_vertices += job.output(slot).size / pack::VERTEX_STRIDE as u64;
            }
        }
    }

    /// The skinned vertex buffer of scene instance `instance` at `lod` in frame slot `slot`
    /// (world space, indexed by the mesh's own indices from vertex 0), if it is animated.
    pub fn vertex_buffer(&self, instance: u32, lod: u8, slot: usize) -> Option<vk::Buffer> {
        let a = &self.instances[self.index_of(instance)?];
        Some(a.lods[lod as usize].output(slot).buffer)
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        for a in &mut self.instances {
            for job in &mut a.lods {
                job.destroy(gpu);
            }
        }
        self.pipe.destroy(gpu);
    }
}
