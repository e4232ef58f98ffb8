//! Frustum culling on the CPU (../shared/notes/pipeline.md §3).
//!
//! - Planes come from the view-projection matrix (Gribb–Hartmann): with rows r0..r3 of VP and
//!   Vulkan's clip volume -w <= x, y <= w, 0 <= z <= w, the six half-spaces are r3 ± r0, r3 ± r1,
//!   r2 and r3 - r2, normalised by |xyz| with the inside positive. The same six serve standard,
//!   reversed and infinite depth: under infinite reversed-Z one of them is (0, 0, 0, n), always
//!   satisfied and with no normal to normalise, and it is dropped (never divide by zero).
//! - Instances are tested as world-space spheres (and optionally boxes), stored as structure of
//!   arrays so the loop over 100k instances streams through memory. The test is the book's: a
//!   sphere is outside when its centre is more than r behind a plane (strictly: one that just
//!   touches the frustum is kept); each instance is also classified inside / intersecting.
//! - Large scenes run in parallel over fixed chunks, writing the visible indices in order, so the
//!   result is the same for any thread count.

use glam::{Mat4, Vec3, Vec4};

/// Up to six planes (xyz = inward unit normal, w = offset): inside where dot(n, p) + w >= 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frustum {
    planes: [Vec4; 6],
    count: usize,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Class {
    Outside,
    Intersecting,
    Inside,
}

impl Frustum {
    pub fn from_view_proj(vp: Mat4) -> Frustum {
        let (r0, r1, r2, r3) = (vp.row(0), vp.row(1), vp.row(2), vp.row(3));
        let mut planes = [Vec4::ZERO; 6];
        let mut count = 0;
        for p in [r3 + r0, r3 - r0, r3 + r1, r3 - r1, r2, r3 - r2] {
            let len = p.truncate().length();
            // A plane without a normal (the far plane at infinity) holds everywhere.
            if len > 1e-12 * p.w.abs().max(1.0) && len.is_finite() {
                planes[count] = p / len;
                count += 1;
            }
        }
        Frustum { planes, count }
    }

    pub fn planes(&self) -> &[Vec4] {
        &self.planes[..self.count]
    }

    /// Signed distance of `p` to each plane (positive inside).
    fn distance(plane: Vec4, p: Vec3) -> f32 {
        plane.truncate().dot(p) + plane.w
    }

    pub fn classify_sphere(&self, centre: Vec3, radius: f32) -> Class {
        let mut class = Class::Inside;
        for &p in self.planes() {
            let d = Self::distance(p, centre);
            if d < -radius {
                return Class::Outside;
            }
            if d < radius {
                class = Class::Intersecting;
            }
        }
        class
    }

    /// Box given by centre and half extents (world axes): effective radius sum |n_i| e_i.
    pub fn classify_box(&self, centre: Vec3, half: Vec3) -> Class {
        let mut class = Class::Inside;
        for &p in self.planes() {
            let d = Self::distance(p, centre);
            let r = p.truncate().abs().dot(half);
            if d < -r {
                return Class::Outside;
            }
            if d < r {
                class = Class::Intersecting;
            }
        }
        class
    }
}

/// World-space bounding spheres of instances, structure of arrays.
#[derive(Debug, Clone, Default)]
pub struct Spheres {
    pub x: Vec<f32>,
    pub y: Vec<f32>,
    pub z: Vec<f32>,
    pub r: Vec<f32>,
}

impl Spheres {
    pub fn len(&self) -> usize {
        self.r.len()
    }

    pub fn is_empty(&self) -> bool {
        self.r.is_empty()
    }

    pub fn push(&mut self, centre: Vec3, radius: f32) {
        self.x.push(centre.x);
        self.y.push(centre.y);
        self.z.push(centre.z);
        self.r.push(radius);
    }
}

/// What one culling pass did (exact counts: tests and the overlay pin them). With occlusion
/// culling (`render::occlusion`, run by `Visibility` on the frustum's survivors) `culled` counts
/// both kinds and `visible` what is left, the instances drawn.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CullCounts {
    pub tested: u32,
    pub culled: u32,
    pub visible: u32,
    /// Visible and entirely inside the frustum.
    pub inside: u32,
    /// Frustum-visible instances tested against the occluders (the occluders themselves are not).
    pub occlusion_tested: u32,
    /// Of them, those hidden (also counted in `culled`).
    pub occlusion_culled: u32,
}

/// Instances per parallel work item.
const CHUNK: usize = 4096;

/// Indices (ascending) of the spheres not outside `frustum`, appended to `visible`.
pub fn cull_spheres(frustum: &Frustum, s: &Spheres, visible: &mut Vec<u32>) -> CullCounts {
    let chunk = |start: usize, end: usize, out: &mut Vec<u32>| -> u32 {
        let mut inside = 0;
        for i in start..end {
            let c = Vec3::new(s.x[i], s.y[i], s.z[i]);
            match frustum.classify_sphere(c, s.r[i]) {
                Class::Outside => {}
                class => {
                    out.push(i as u32);
                    inside += (class == Class::Inside) as u32;
                }
            }
        }
        inside
    };
    let n = s.len();
    let before = visible.len();
    let inside = if n <= CHUNK {
        chunk(0, n, visible)
    } else {
        // Fixed chunks on the rayon pool (threads made once, not per frame), concatenated in
        // order: deterministic.
        use rayon::prelude::*;
        let parts: Vec<(Vec<u32>, u32)> = (0..n.div_ceil(CHUNK))
            .into_par_iter()
            .map(|k| {
                let (a, b) = (k * CHUNK, ((k + 1) * CHUNK).min(n));
                let mut out = Vec::with_capacity(b - a);
                let inside = chunk(a, b, &mut out);
                (out, inside)
            })
            .collect();
        let mut inside = 0;
        for (part, k) in parts {
            visible.extend_from_slice(&part);
            inside += k;
        }
        inside
    };
    let shown = (visible.len() - before) as u32;
    CullCounts { tested: n as u32, culled: n as u32 - shown, visible: shown, inside, ..Default::default() }
}

/// A local bounding sphere placed by an affine `model` matrix: centre transformed, radius scaled
/// by the largest column norm of the 3x3 part (conservative under non-uniform scale).
pub fn world_sphere(model: Mat4, centre: Vec3, radius: f32) -> (Vec3, f32) {
    let m = glam::Mat3::from_mat4(model);
    let s = m.x_axis.length().max(m.y_axis.length()).max(m.z_axis.length());
    (model.transform_point3(centre), radius * s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::camera::perspective_reverse_z;

    /// Vulkan [0, 1] depth, finite far, Y flipped (pipeline.md §2).
    fn perspective_finite(fov_y: f32, aspect: f32, n: f32, f: f32) -> Mat4 {
        let d = 1.0 / (fov_y * 0.5).tan();
        Mat4::from_cols(
            Vec4::new(d / aspect, 0.0, 0.0, 0.0),
            Vec4::new(0.0, -d, 0.0, 0.0),
            Vec4::new(0.0, 0.0, f / (n - f), -1.0),
            Vec4::new(0.0, 0.0, n * f / (n - f), 0.0),
        )
    }

    fn grid(radius: f32) -> Spheres {
        let mut s = Spheres::default();
        for x in -10..=10 {
            for z in -10..=10 {
                s.push(Vec3::new(x as f32, 0.0, z as f32), radius);
            }
        }
        s
    }

    #[test]
    fn t3_1_known_scene_counts() {
        // Camera at the origin looking down -z, 90 degrees, aspect 1: 121 drawn (100 inside,
        // 21 straddling), 320 culled; row z = -k keeps |x| <= k. Same with infinite reversed-Z.
        for vp in [perspective_finite(90f32.to_radians(), 1.0, 0.1, 100.0), perspective_reverse_z(90f32.to_radians(), 1.0, 0.1)] {
            let f = Frustum::from_view_proj(vp);
            let s = grid(0.5);
            let mut vis = Vec::new();
            let c = cull_spheres(&f, &s, &mut vis);
            assert_eq!(c, CullCounts { tested: 441, culled: 320, visible: 121, inside: 100, ..Default::default() });
            for &i in &vis {
                let (x, z) = (s.x[i as usize], s.z[i as usize]);
                assert!(z <= 0.0 && x.abs() <= -z, "({x}, {z})");
            }
            // Boxes are larger. At half-extent exactly 0.5 the boxes at x = +-(k + 1) in row
            // z = -k touch a side plane exactly (distance -1/sqrt 2 = -effective radius), so
            // rounding decides each of those 20 ties (the notes count 137; we get 133): pin the
            // counts just off the tie instead, 121 + 20 = 141 and 121.
            let boxes = |h: f32| (0..s.len()).filter(|&i| f.classify_box(Vec3::new(s.x[i], s.y[i], s.z[i]), Vec3::splat(h)) != Class::Outside).count();
            assert_eq!((boxes(0.5001), boxes(0.4999)), (141, 121));
            assert!((121..=141).contains(&boxes(0.5)));
        }
    }

    #[test]
    fn t3_2_touching_a_plane_is_kept() {
        let f = Frustum::from_view_proj(perspective_finite(90f32.to_radians(), 1.0, 1.0, 100.0));
        // Near plane at z = -1: a sphere of r 0.5 at z = -0.5 touches it from the camera side.
        assert_ne!(f.classify_sphere(Vec3::new(0.0, 0.0, -0.5), 0.5), Class::Outside);
        assert_eq!(f.classify_sphere(Vec3::new(0.0, 0.0, -0.499), 0.5), Class::Outside);
        assert_ne!(f.classify_sphere(Vec3::new(0.0, 0.0, -0.501), 0.5), Class::Outside);
        // Side plane x = -z (normal (-1, 0, -1)/sqrt 2): just outside and just inside by 1e-4.
        let z = -5.0f32;
        let r = 0.5f32;
        let on = |d: f32| Vec3::new(-z + (r + d) * std::f32::consts::SQRT_2, 0.0, z);
        assert_eq!(f.classify_sphere(on(1e-4), r), Class::Outside);
        assert_ne!(f.classify_sphere(on(-1e-4), r), Class::Outside);
    }

    #[test]
    fn t3_3_planes_match_unprojected_corners_and_infinite_far_has_five() {
        let vp = perspective_finite(70f32.to_radians(), 1.5, 0.3, 50.0) * Mat4::look_at_rh(Vec3::new(1.0, 2.0, 3.0), Vec3::new(-2.0, 0.5, -4.0), Vec3::Y);
        let f = Frustum::from_view_proj(vp);
        assert_eq!(f.planes().len(), 6);
        let inv = vp.inverse();
        for x in [-1.0f32, 1.0] {
            for y in [-1.0f32, 1.0] {
                for z in [0.0f32, 1.0] {
                    let c = inv.project_point3(Vec3::new(x, y, z));
                    let on = f.planes().iter().filter(|p| (p.truncate().dot(c) + p.w).abs() < 1e-3 * (1.0 + c.length())).count();
                    assert!(on >= 3, "corner {c} lies on {on} planes");
                    assert!(f.planes().iter().all(|p| p.truncate().dot(c) + p.w > -1e-3 * (1.0 + c.length())));
                }
            }
        }
        let inf = Frustum::from_view_proj(perspective_reverse_z(60f32.to_radians(), 1.0, 0.1));
        assert_eq!(inf.planes().len(), 5);
        assert!(inf.planes().iter().all(|p| p.is_finite()));
    }

    #[test]
    fn t3_4_no_false_negatives_on_random_scenes() {
        let mut seed = 0x1234_5678u64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f32 / (1u64 << 53) as f32
        };
        let (mut kept_outside, mut total) = (0, 0);
        for _ in 0..10_000 {
            let eye = Vec3::new(rnd() * 20.0 - 10.0, rnd() * 4.0, rnd() * 20.0 - 10.0);
            let at = eye + Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5).normalize_or(Vec3::NEG_Z);
            let vp = perspective_reverse_z(60f32.to_radians(), 1.3, 0.1) * Mat4::look_at_rh(eye, at, Vec3::Y);
            let f = Frustum::from_view_proj(vp);
            let c = Vec3::new(rnd() * 20.0 - 10.0, rnd() * 4.0, rnd() * 20.0 - 10.0);
            let r = 0.1 + rnd();
            // Brute force: any of a few hundred points of the sphere inside the clip volume.
            let mut any_inside = false;
            for k in 0..256 {
                let (u, v) = ((k % 16) as f32 / 15.0, (k / 16) as f32 / 15.0);
                let (th, ph) = (u * std::f32::consts::PI, v * std::f32::consts::TAU);
                let p = c + r * Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin());
                let q = vp * p.extend(1.0);
                if q.w > 0.0 && q.x.abs() <= q.w && q.y.abs() <= q.w && q.z >= 0.0 && q.z <= q.w {
                    any_inside = true;
                    break;
                }
            }
            let class = f.classify_sphere(c, r);
            if any_inside {
                assert_ne!(class, Class::Outside, "culled a visible sphere {c} r {r}");
            } else if class != Class::Outside {
                kept_outside += 1;
            }
            total += 1;
        }
        assert!(kept_outside < total / 4, "{kept_outside} false positives of {total}");
    }

    #[test]
    fn parallel_culling_matches_serial_and_counts_are_exact() {
        let f = Frustum::from_view_proj(perspective_reverse_z(60f32.to_radians(), 1.0, 0.1));
        let mut s = Spheres::default();
        for i in 0..100_000 {
            let t = i as f32 * 0.618;
            s.push(Vec3::new((t * 7.1).sin() * 300.0, (t * 3.3).cos() * 10.0, (t * 5.7).cos() * 300.0), 1.0 + (i % 5) as f32);
        }
        let mut par = Vec::new();
        let c = cull_spheres(&f, &s, &mut par);
        let serial: Vec<u32> = (0..s.len() as u32).filter(|&i| f.classify_sphere(Vec3::new(s.x[i as usize], s.y[i as usize], s.z[i as usize]), s.r[i as usize]) != Class::Outside).collect();
        assert_eq!(par, serial);
        assert_eq!((c.tested, c.visible, c.culled), (100_000, serial.len() as u32, 100_000 - serial.len() as u32));
    }

    #[test]
    fn world_spheres_are_conservative_under_scale() {
        let m = Mat4::from_scale_rotation_translation(Vec3::new(1.0, 3.0, 0.5), glam::Quat::from_rotation_y(0.7), Vec3::new(1.0, 2.0, 3.0));
        let (c, r) = world_sphere(m, Vec3::new(0.5, 0.0, 0.0), 1.0);
        assert_eq!(r, 3.0);
        assert!((c - m.transform_point3(Vec3::new(0.5, 0.0, 0.0))).length() < 1e-6);
    }
}
