//! What to draw this frame: frustum culling of every instance (`cull`), a LOD per visible
//! instance from its projected error (`lod_select`, with last frame's choice for hysteresis),
//! then occlusion culling of the visible ones (`occlusion`: the largest static ones, at the LODs
//! just chosen, are rasterised on the CPU and hide the rest where they cover them). The result
//! is a draw list plus exact counters (tests and the overlay pin them).

use crate::render::cull::{cull_spheres, Class, CullCounts, Frustum};
use crate::render::lod_select::{pixels_per_metre_at_unit_distance, LodPolicy};
use crate::render::occlusion::OcclusionCuller;
use crate::scene::GpuScene;
use glam::{Mat4, Vec3};

/// LOD histogram buckets (LODs past the last share it).
pub const LOD_BUCKETS: usize = 8;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Draw {
    pub instance: u32,
    pub lod: u8,
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FrameCounts {
    pub cull: CullCounts,
    /// Triangles submitted (visible instances at their chosen LOD).
    pub triangles: u64,
    pub lod_histogram: [u32; LOD_BUCKETS],
    /// Particle billboards the particle pass drew (set by the renderer, not by `update`).
    pub particles: u32,
    /// Boid instances drawn (also counted in `cull`; set by the renderer).
    pub boids: u32,
}

/// The per-view state: settings, last frame's LODs, this frame's draw list.
pub struct Visibility {
    pub policy: LodPolicy,
    /// Off: every instance is drawn (for comparison; occlusion culling is off with it).
    pub culling: bool,
    /// Occlusion culling after frustum culling (on by default; off, for comparison). The shadow
    /// map keeps its own culling: what the camera cannot see still casts shadows.
    pub occlusion: bool,
    /// Off: every instance draws LOD 0.
    pub lod_selection: bool,
    /// On: instances keep the LOD they were last drawn with (ones never drawn still pick), so
    /// the choices made from one viewpoint can be inspected from another.
    pub freeze_lod: bool,
    /// The occlusion pass: its budget (`settings`) and what it did last frame (`stats`).
    pub occlusion_culler: OcclusionCuller,
    previous: Vec<Option<u8>>,
    visible: Vec<u32>,
    /// The frustum's survivors at their LODs, before occlusion culling.
    candidates: Vec<Draw>,
    hidden: Vec<bool>,
    pub draws: Vec<Draw>,
    pub counts: FrameCounts,
}

impl Default for Visibility {
    fn default() -> Self {
        Visibility {
            policy: LodPolicy::default(),
            culling: true,
            occlusion: true,
            lod_selection: true,
            freeze_lod: false,
            occlusion_culler: OcclusionCuller::default(),
            previous: Vec::new(),
            visible: Vec::new(),
            candidates: Vec::new(),
            hidden: Vec::new(),
            draws: Vec::new(),
            counts: FrameCounts::default(),
        }
    }
}

impl Visibility {
    /// Recompute the draw list for a camera at `eye` with `view_proj`, vertical FOV `fov_y`
    /// (radians) and a viewport `height_px` pixels high.
    pub fn update(&mut self, scene: &GpuScene, view_proj: Mat4, eye: Vec3, fov_y: f32, height_px: f32) {
        self.previous.resize(scene.instances.len(), None);
        self.visible.clear();
        let frustum = Frustum::from_view_proj(view_proj);
        let mut cull = if self.culling {
            cull_spheres(&frustum, scene.instances.spheres(), &mut self.visible)
        } else {
            self.visible.extend(0..scene.instances.len() as u32);
            let n = scene.instances.len() as u32;
            CullCounts { visible: n, ..Default::default() }
        };
        let ppm = pixels_per_metre_at_unit_distance(height_px, fov_y);
        self.candidates.clear();
        for &i in &self.visible {
            let inst = &scene.instances[i as usize];
            let mesh = &scene.meshes[inst.mesh as usize];
            let lod = if let Some(frozen) = self.previous[i as usize].filter(|_| self.freeze_lod) {
                usize::from(frozen).min(mesh.lods.len() - 1)
            } else if self.lod_selection && mesh.lods.len() > 1 {
                // Distance to the nearest point of the bounding sphere: an object the camera is
                // inside or touching is at full detail.
                let s = scene.instances.spheres();
                let c = Vec3::new(s.x[i as usize], s.y[i as usize], s.z[i as usize]);
                let distance = ((c - eye).length() - s.r[i as usize]).max(1e-3);
                // Object-space errors become world metres through the instance's scale.
                self.policy.select(&mesh.errors, distance, ppm * inst.scale, self.previous[i as usize].map(usize::from))
            } else {
                0
            };
            self.candidates.push(Draw { instance: i, lod: lod as u8 });
        }
        self.hidden.clear();
        if self.culling && self.occlusion {
            let o = self.occlusion_culler.cull(scene, view_proj, eye, fov_y, &self.candidates, &mut self.hidden);
            cull.occlusion_tested = o.tested;
            cull.occlusion_culled = o.culled;
            cull.culled += o.culled;
            cull.visible -= o.culled;
        } else {
            self.occlusion_culler.stats = Default::default();
        }
        let mut counts = FrameCounts { cull, ..Default::default() };
        self.draws.clear();
        for (k, &d) in self.candidates.iter().enumerate() {
            let i = d.instance as usize;
            if self.hidden.get(k).copied().unwrap_or(false) {
                // Hidden: it keeps last frame's LOD for hysteresis, as one out of view does.
                let s = scene.instances.spheres();
                if frustum.classify_sphere(Vec3::new(s.x[i], s.y[i], s.z[i]), s.r[i]) == Class::Inside {
                    counts.cull.inside -= 1;
                }
                continue;
            }
            let mesh = &scene.meshes[scene.instances[i].mesh as usize];
            self.previous[i] = Some(d.lod);
            counts.triangles += mesh.lods[d.lod as usize].triangles as u64;
            counts.lod_histogram[usize::from(d.lod).min(LOD_BUCKETS - 1)] += 1;
            self.draws.push(d);
        }
        self.counts = counts;
    }
}
