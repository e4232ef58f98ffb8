//! What to draw this frame: frustum culling of every instance (`cull`), then a LOD per visible
//! instance from its projected error (`lod_select`, with last frame's choice for hysteresis).
//! The result is a draw list plus exact counters (tests and the overlay pin them).

use crate::render::cull::{cull_spheres, CullCounts, Frustum};
use crate::render::lod_select::{pixels_per_metre_at_unit_distance, LodPolicy};
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
    /// Off: every instance is drawn (for comparison).
    pub culling: bool,
    /// Off: every instance draws LOD 0.
    pub lod_selection: bool,
    /// On: instances keep the LOD they were last drawn with (ones never drawn still pick), so
    /// the choices made from one viewpoint can be inspected from another.
    pub freeze_lod: bool,
    previous: Vec<Option<u8>>,
    visible: Vec<u32>,
    pub draws: Vec<Draw>,
    pub counts: FrameCounts,
}

impl Default for Visibility {
    fn default() -> Self {
        Visibility {
            policy: LodPolicy::default(),
            culling: true,
            lod_selection: true,
            freeze_lod: false,
            previous: Vec::new(),
            visible: Vec::new(),
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
        let cull = if self.culling {
            cull_spheres(&Frustum::from_view_proj(view_proj), scene.instances.spheres(), &mut self.visible)
        } else {
            self.visible.extend(0..scene.instances.len() as u32);
            let n = scene.instances.len() as u32;
            CullCounts { tested: 0, culled: 0, visible: n, inside: 0 }
        };
        let ppm = pixels_per_metre_at_unit_distance(height_px, fov_y);
        let mut counts = FrameCounts { cull, ..Default::default() };
        self.draws.clear();
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
            self.previous[i as usize] = Some(lod as u8);
            counts.triangles += mesh.lods[lod].triangles as u64;
            counts.lod_histogram[lod.min(LOD_BUCKETS - 1)] += 1;
            self.draws.push(Draw { instance: i, lod: lod as u8 });
        }
        self.counts = counts;
    }
}
