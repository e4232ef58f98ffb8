//! Occlusion culling on the CPU: the frame's best occluders are rasterised into a small depth
//! buffer (`OcclusionBuffer`, 192x108 whatever the render target's size), then every other
//! frustum-visible instance's world box is tested against it and culled only where every texel
//! its screen rectangle covers holds an occluder nearer than the box's nearest point.
//!
//! Conservative, never hiding what the GPU would show (tests compare frames with it on and off):
//!
//! - Depth is the engine's (`scene::camera`): reversed-Z, depth = z/w of Vulkan's clip space,
//!   larger is nearer, 0 is infinitely far (an empty texel hides nothing). Triangles are clipped
//!   in clip space against the near plane (w - z >= 0), the far plane (z >= 0) and a guard band
//!   of twice the screen, so nothing behind the camera is projected and coordinates stay small.
//! - A texel is written only where an occluder's drawn triangles cover all of it (grown by
//!   `EPS` of a texel each side, against rounding and the GPU's sub-pixel snapping). A mesh's
//!   triangles cover the region P they make together; a texel lies inside P if its centre does
//!   (sampled with the usual edge functions) and no edge of P's boundary crosses it. P's
//!   boundary edges are found per frame from the mesh's adjacency (positions welded): an edge
//!   is inside P when exactly two drawn triangles share it, in opposite directions and facing
//!   the same way on screen; every other edge (a silhouette, a border, an edge against a culled
//!   back face, an edge made by clipping) is a boundary edge, and the texels it touches are not
//!   written. A gap between two occluders, a hole in one, a thin silhouette: never written.
//! - The depth written is a lower bound (farthest) of the occluder over the texel: the min over
//!   every triangle that touches the (grown) texel of its plane's depth at the texel's corners,
//!   clamped by the triangle's farthest vertex. Occluders merge by max (each covers the texel).
//! - Triangles are drawn as the GPU draws them: single-sided materials' front faces only (an
//!   instance with a negative determinant winds the other way), double-sided ones both sides,
//!   alpha-tested and blended materials not at all, nearly edge-on triangles not at all. The LOD
//!   rasterised is the one the frame draws (a coarser one can stand in front of the drawn
//!   surface: simplification moves surfaces both ways), so the LOD chosen for distance is the
//!   coarse occluder: the budget counts its triangles.
//! - A box is tested by its 8 corners: all in front of the near plane (else kept), nearest depth
//!   their max z/w (w is affine over the box), screen rectangle their projections' bounds. It is
//!   hidden when that depth is farther than every covered texel's by a margin (`hidden`). A
//!   min-depth pyramid answers most boxes from a texel or four.
//!
//! Deterministic: one thread, occluders in a fixed order (largest projected size first, ties by
//! index), every result a function of the scene and the camera alone.
//!
//! Cost: the texels and rows the occluders' triangles cover. Along the demo flight over the
//! chunked temple (240 cameras at 1280x720, one core of a shared 2-core machine; the test
//! `the_temple_along_the_demo_flight_looks_the_same_with_occlusion_culling` in
//! engine/tests/occlusion_render.rs prints this table), the 8 largest occluders cull nearly all
//! that more would, at half the cost, and 192x108 texels nearly all that 256x144 do:
//!
//! | buffer, occluders, triangles | ms a frame: mean, p95 | instances culled, 240 frames |
//! |---|---|---|
//! | 192x108, 8, 4096 (default) | 0.53, 0.85 | 135 |
//! | 256x144, 8, 4096 | 0.66, 0.90 | 140 |
//! | 256x144, 32, 8192 | 1.33, 1.68 | 142 |
//! | 192x108, 4, 4096 | 0.32, 0.41 | 98 |
//! | 160x90, 8, 4096 | 0.40, 0.55 | 114 |
//!
//! Left as it is: each occluder is its own region, so where two instances meet (the chunks a
//! level's large meshes are cut into) their shared border is a boundary of each and its texels
//! are never written. Welding across instances would close those seams but make one region of
//! the two, whose depth bound is the farther layer's where they overlap.

use crate::render::visibility::Draw;
use crate::scene::{GpuMaterial, GpuScene};
use glam::{Mat4, Vec3, Vec4, Vec4Swizzles};
use std::collections::HashMap;

/// The buffer's default size: 16:9, square texels on a 16:9 target (6.7 pixels at 1280x720).
pub const DEFAULT_SIZE: (usize, usize) = (192, 108);
/// LODs of up to this many triangles keep their triangles on the CPU (`GpuLod::occluder`): the
/// default triangle budget, so any LOD that fits in it can occlude.
pub const MAX_OCCLUDER_TRIANGLES: usize = 4096;
/// How far (texels) a texel is grown each side for coverage and depth: rounding, and the GPU's
/// snapping of vertices to 1/256 pixel (1/32 texel is 0.2 pixels at 1280x720).
const EPS: f32 = 1.0 / 32.0;
/// The guard band: triangles are clipped to twice the screen in x and y.
const GUARD: f32 = 2.0;
/// A triangle with |det(xyw)| below this fraction of the product of its clip vectors' lengths
/// is taken as edge-on and not drawn (whichever way the GPU decides its facing).
const EDGE_ON: f32 = 1e-4;
/// No neighbour across an edge (a border, or shared by more than two triangles).
const NONE: u32 = u32::MAX;

/// How the GPU draws a submesh's triangles into depth.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Faces {
    /// Not at all (blended: no depth writes; alpha-tested: holes).
    None,
    /// Front faces only (single-sided: back faces are culled).
    Front,
    /// Both sides (double-sided).
    Both,
}

impl Faces {
    pub fn of(m: &GpuMaterial) -> Faces {
        if m.blend || m.alpha_cutoff >= 0.0 {
            Faces::None
        } else if m.double_sided {
            Faces::Both
        } else {
            Faces::Front
        }
    }
}

/// One LOD's triangles as an occluder: welded positions, triangles, and across each edge the
/// triangle that shares it in the opposite direction (when exactly one does and nothing else
/// uses the edge).
#[derive(Clone)]
pub struct OccluderMesh {
    positions: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    /// Across edge k of triangle t (corner k to corner k + 1).
    neighbours: Vec<[u32; 3]>,
    /// Each submesh's triangles (the LOD's submesh order).
    submeshes: Vec<std::ops::Range<u32>>,
}

impl std::fmt::Debug for OccluderMesh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "OccluderMesh({} positions, {} triangles)", self.positions.len(), self.triangles.len())
    }
}

impl OccluderMesh {
    /// From a LOD's vertex positions, indices and submeshes (first index, index count).
    /// Triangles with an index out of range or two equal welded corners are left out.
    pub fn new(positions: &[Vec3], indices: &[u32], submeshes: &[(u32, u32)]) -> OccluderMesh {
        // Weld by exact position (-0 as 0): a mesh's vertices are split where normals or UVs
        // differ, but its surface is one.
        let mut weld: HashMap<[u32; 3], u32> = HashMap::new();
        let mut welded_positions = Vec::new();
        let remap: Vec<u32> = positions
            .iter()
            .map(|p| {
                let key = (*p + Vec3::ZERO).to_array().map(f32::to_bits);
                *weld.entry(key).or_insert_with(|| {
                    welded_positions.push(*p);
                    welded_positions.len() as u32 - 1
                })
            })
            .collect();
        let mut triangles = Vec::new();
        let mut ranges = Vec::new();
        for &(first, count) in submeshes {
            let start = triangles.len() as u32;
            let end = (first as usize + count as usize).min(indices.len());
            for t in indices.get(first as usize..end).unwrap_or(&[]).chunks_exact(3) {
                let Some(tri) = t.iter().map(|&i| remap.get(i as usize).copied()).collect::<Option<Vec<u32>>>() else { continue };
                let [a, b, c] = [tri[0], tri[1], tri[2]];
                if a != b && b != c && c != a {
                    triangles.push([a, b, c]);
                }
            }
            ranges.push(start..triangles.len() as u32);
        }
        // Directed edge -> (uses, the last triangle using it).
        let mut edges: HashMap<(u32, u32), (u32, u32)> = HashMap::with_capacity(triangles.len() * 3);
        for (t, tri) in triangles.iter().enumerate() {
            for k in 0..3 {
                let e = edges.entry((tri[k], tri[(k + 1) % 3])).or_insert((0, 0));
                *e = (e.0 + 1, t as u32);
            }
        }
        let neighbours = triangles
            .iter()
            .map(|tri| {
                std::array::from_fn(|k| {
                    let (a, b) = (tri[k], tri[(k + 1) % 3]);
                    match (edges.get(&(a, b)), edges.get(&(b, a))) {
                        (Some(&(1, _)), Some(&(1, other))) => other,
                        _ => NONE,
                    }
                })
            })
            .collect();
        OccluderMesh { positions: welded_positions, triangles, neighbours, submeshes: ranges }
    }

    pub fn triangles(&self) -> usize {
        self.triangles.len()
    }
}

/// A polygon vertex in clip space and whether the edge from it to the next is inside the
/// occluder's region (shared with a drawn neighbour facing the same way).
#[derive(Clone, Copy)]
struct PolyVertex {
    clip: Vec4,
    interior: bool,
}

/// Clip planes (inside where dot >= 0): near and far of Vulkan's 0 <= z <= w, and the guard band.
const PLANES: [Vec4; 6] = [
    Vec4::new(0.0, 0.0, -1.0, 1.0),
    Vec4::new(0.0, 0.0, 1.0, 0.0),
    Vec4::new(-1.0, 0.0, 0.0, GUARD),
    Vec4::new(1.0, 0.0, 0.0, GUARD),
    Vec4::new(0.0, -1.0, 0.0, GUARD),
    Vec4::new(0.0, 1.0, 0.0, GUARD),
];

/// floor and ceil to i32 for texel coordinates, as one add and one truncation (the std ones are
/// library calls on the x86-64 baseline, and `as` saturates): x is clamped to +-4000 (NaN to
/// -4000; buffers are at most 4000 texels a side) and offset to be positive, where truncation is
/// floor. The add rounds to 2^-10: within that of an integer the result may be one too large
/// (floor) or too small (ceil), which every caller takes as a wider span, never a narrower one
/// (the depth bound's spans and the boundary marks), or catches (coverage: a centre that close
/// to an edge is within reach of its marks).
#[inline]
fn floor_i(x: f32) -> i32 {
    const OFFSET: f32 = 4096.0;
    let x = if x > -4000.0 { x } else { -4000.0 };
    let x = if x < 4000.0 { x } else { 4000.0 };
    // SAFETY: x + OFFSET is finite, positive and within i32.
    let t: i32 = unsafe { (x + OFFSET).to_int_unchecked() };
    t - OFFSET as i32
}
#[inline]
fn ceil_i(x: f32) -> i32 {
    -floor_i(-x)
}

/// Whether a texel (or pyramid texel) of depth `occluder` hides a box whose nearest depth is
/// `nearest`: farther by 2^-12 of the depth plus 2^-20 (the GPU's interpolation and rounding of
/// z/w; 2^-20 is a 1e-6 margin on depths that are near / distance).
#[inline]
fn hidden(nearest: f32, occluder: f32) -> bool {
    nearest < occluder - (occluder * (1.0 / 4096.0) + 1.0 / 1_048_576.0)
}

/// The CPU depth buffer and its min-depth pyramid.
pub struct OcclusionBuffer {
    width: usize,
    height: usize,
    view_proj: Mat4,
    /// Sign of det(xyw) of clip coordinates for a front face (counter-clockwise seen from the
    /// eye): minus the sign of the determinant of view_proj's x, y, w rows' 3x3.
    front_sign: f32,
    /// Level 0 is the buffer; each next level the min (farthest) of up to 2x2 texels below.
    levels: Vec<(usize, usize, Vec<f32>)>,
    // Per-mesh scratch: the farthest depth of the triangles touching each texel, and flags
    // (1: a triangle covers its centre, 2: a boundary edge crosses it).
    dmin: Vec<f32>,
    flags: Vec<u8>,
    clip: Vec<Vec4>,
    status: Vec<i8>,
    /// Texels the current mesh touched: x0, y0, x1, y1 (inclusive; empty when x0 > x1).
    rect: [i32; 4],
}

impl OcclusionBuffer {
    pub fn new(width: usize, height: usize) -> OcclusionBuffer {
        assert!((1..=4000).contains(&width) && (1..=4000).contains(&height), "an occlusion buffer is 1 to 4000 texels a side, not {width}x{height}");
        let mut levels = Vec::new();
        let (mut w, mut h) = (width, height);
        loop {
            levels.push((w, h, vec![0.0; w * h]));
            if w == 1 && h == 1 {
                break;
            }
            (w, h) = (w.div_ceil(2), h.div_ceil(2));
        }
        OcclusionBuffer {
            width,
            height,
            view_proj: Mat4::IDENTITY,
            front_sign: -1.0,
            levels,
            dmin: vec![f32::INFINITY; width * height],
            flags: vec![0; width * height],
            clip: Vec::new(),
            status: Vec::new(),
            rect: [i32::MAX, i32::MAX, i32::MIN, i32::MIN],
        }
    }

    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Level 0: each texel's depth (0 where no occluder covers it).
    pub fn depth(&self) -> &[f32] {
        &self.levels[0].2
    }

    /// Clear for a frame seen through `view_proj` (world to Vulkan clip space).
    pub fn begin(&mut self, view_proj: Mat4) {
        self.view_proj = view_proj;
        let a = glam::Mat3::from_cols(view_proj.row(0).xyz(), view_proj.row(1).xyz(), view_proj.row(3).xyz());
        self.front_sign = if a.determinant() >= 0.0 { -1.0 } else { 1.0 };
        self.levels[0].2.fill(0.0);
    }

    /// Rasterise `mesh` placed by `model`, submesh s drawn as `faces(s)`. Returns the triangles
    /// that were drawn (facing and clipping as the GPU would).
    pub fn rasterise(&mut self, mesh: &OccluderMesh, model: Mat4, faces: impl Fn(usize) -> Faces) -> u32 {
        let mvp = self.view_proj * model;
        self.clip.clear();
        self.clip.extend(mesh.positions.iter().map(|p| mvp * p.extend(1.0)));
        // A mirroring placement winds its front faces the other way (the GPU's front face too).
        let front = if glam::Mat3::from_mat4(model).determinant() < 0.0 { -self.front_sign } else { self.front_sign };
        self.status.clear();
        self.status.resize(mesh.triangles.len(), 0);
        for (s, range) in mesh.submeshes.iter().enumerate() {
            let f = faces(s);
            if f == Faces::None {
                continue;
            }
            for t in range.start as usize..range.end as usize {
                let [a, b, c] = mesh.triangles[t].map(|i| {
                    let v = self.clip[i as usize];
                    Vec3::new(v.x, v.y, v.w)
                });
                let det = a.dot(b.cross(c));
                // NaN fails this too.
                let facing = det * det > EDGE_ON * EDGE_ON * a.length_squared() * b.length_squared() * c.length_squared();
                if !facing {
                    continue;
                }
                let sign = det.signum();
                if f == Faces::Front && sign != front {
                    continue;
                }
                self.status[t] = sign as i8;
            }
        }
        self.rect = [i32::MAX, i32::MAX, i32::MIN, i32::MIN];
        let mut drawn = 0;
        let mut poly = [PolyVertex { clip: Vec4::ZERO, interior: false }; 12];
        let mut next = poly;
        for (t, tri) in mesh.triangles.iter().enumerate() {
            let s = self.status[t];
            if s == 0 {
                continue;
            }
            let n = mesh.neighbours[t];
            for k in 0..3 {
                poly[k] = PolyVertex { clip: self.clip[tri[k] as usize], interior: n[k] != NONE && self.status[n[k] as usize] == s };
            }
            let mut count = 3;
            for plane in PLANES {
                let all_in = poly[..count].iter().all(|v| v.clip.dot(plane) >= 0.0);
                if all_in {
                    continue;
                }
                count = clip_polygon(&poly[..count], plane, &mut next);
                std::mem::swap(&mut poly, &mut next);
                if count < 3 {
                    break;
                }
            }
            if count >= 3 {
                drawn += 1;
                self.polygon(&poly[..count]);
            }
        }
        self.merge();
        drawn
    }

    /// Rasterise one clipped convex polygon of the current mesh into the scratch.
    fn polygon(&mut self, poly: &[PolyVertex]) {
        let (w, h) = (self.width as f32, self.height as f32);
        let mut p = [Vec3::ZERO; 12];
        for (i, v) in poly.iter().enumerate() {
            let inv = 1.0 / v.clip.w;
            p[i] = Vec3::new((v.clip.x * inv * 0.5 + 0.5) * w, (v.clip.y * inv * 0.5 + 0.5) * h, v.clip.z * inv);
            if !p[i].is_finite() {
                return;
            }
        }
        let n = poly.len();
        let p = &p[..n];
        // Off the screen (within the guard band): nothing to do.
        let (xmin, xmax) = p.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| (lo.min(v.x), hi.max(v.x)));
        let (ymin, ymax) = p.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| (lo.min(v.y), hi.max(v.y)));
        if xmax < -1.0 || ymax < -1.0 || xmin > w + 1.0 || ymin > h + 1.0 {
            return;
        }
        // Boundary edges first: marked whatever the polygon's area.
        for i in 0..n {
            if !poly[i].interior {
                self.mark_segment(p[i], p[(i + 1) % n]);
            }
        }
        // Twice the signed area, about p[0] (small numbers), and the fan triangle with the
        // largest area for the depth plane.
        let o = p[0];
        let (mut area2, mut best, mut best_i) = (0.0f32, 0.0f32, 0usize);
        for i in 1..n - 1 {
            let (a, b) = (p[i] - o, p[i + 1] - o);
            let cross = a.x * b.y - a.y * b.x;
            area2 += cross;
            if cross.abs() > best {
                (best, best_i) = (cross.abs(), i);
            }
        }
        let has_area = area2.abs() > 0.0;
        if !has_area {
            return;
        }
        let sigma = area2.signum();
        // Each edge (inside >= 0: a x + b y + c about o, (a, b) a unit normal) bounds a row's
        // texel centres x on one side. A texel whose square grown by EPS overlaps the half-plane
        // has a x + b cy + c + reach >= 0, reach = (|a| + |b|) (0.5 + EPS): the depth bound takes
        // this polygon there; one whose centre is inside, a x + b cy + c >= 0: coverage. As
        // x >= m cy + q (a > 0) or x <= m cy + q (a < 0). Dividing by a small a loses the bound's
        // precision, so for the depth bound an edge within 3 degrees of the rows bounds the rows
        // instead, inclusively (a x is at most |a| (w + |o.x|) on screen); for coverage, one
        // within 1e-4 of them (ignoring a x errs by 0.06 texel at most: a boundary edge's marks
        // reach half a texel past it, and past an inside edge the neighbour covers).
        let mut bounds = [[(0.0f32, 0.0f32); 12]; 4];
        let mut counts = [0usize; 4];
        let mut push = |list: usize, m: f32, q: f32| {
            bounds[list][counts[list]] = (m, q);
            counts[list] += 1;
        };
        const OUTER_LO: usize = 0;
        const OUTER_HI: usize = 1;
        const CENTRE_LO: usize = 2;
        const CENTRE_HI: usize = 3;
        // Allowed row centres (about o): for the depth bound, and for coverage.
        let (mut orow0, mut orow1, mut crow0, mut crow1) = (f32::NEG_INFINITY, f32::INFINITY, f32::NEG_INFINITY, f32::INFINITY);
        for i in 0..n {
            let (s, e) = (p[i] - o, p[(i + 1) % n] - o);
            let d = e - s;
            let len = (d.x * d.x + d.y * d.y).sqrt();
            let has_length = len > 1e-6;
            if !has_length {
                continue;
            }
            let (a, b) = (-sigma * d.y / len, sigma * d.x / len);
            let c = -(a * s.x + b * s.y);
            let reach = (a.abs() + b.abs()) * (0.5 + EPS);
            if a.abs() < 0.05 {
                let slack = a.abs() * (w + o.x.abs());
                if b > 0.0 {
                    orow0 = orow0.max(-(c + reach + slack) / b);
                } else {
                    orow1 = orow1.min(-(c + reach + slack) / b);
                }
            } else {
                push(if a > 0.0 { OUTER_LO } else { OUTER_HI }, -b / a, -(c + reach) / a);
            }
            if a.abs() < 1e-4 {
                if b > 0.0 {
                    crow0 = crow0.max(-c / b);
                } else {
                    crow1 = crow1.min(-c / b);
                }
            } else {
                push(if a > 0.0 { CENTRE_LO } else { CENTRE_HI }, -b / a, -c / a);
            }
        }
        let list = |k: usize| &bounds[k][..counts[k]];
        let (outer_lo, outer_hi, centre_lo, centre_hi) = (list(OUTER_LO), list(OUTER_HI), list(CENTRE_LO), list(CENTRE_HI));
        // The depth plane z = alpha x + beta y + gamma (about o), from the largest fan triangle;
        // without a usable one the polygon's farthest vertex alone bounds it.
        let zmin = p.iter().map(|v| v.z).fold(f32::INFINITY, f32::min);
        let (mut alpha, mut beta, mut gamma) = (0.0f32, 0.0f32, zmin);
        if best > 1e-6 {
            let (e1, e2) = (p[best_i] - o, p[best_i + 1] - o);
            let det = e1.x * e2.y - e1.y * e2.x;
            alpha = (e1.z * e2.y - e2.z * e1.y) / det;
            beta = (e2.z * e1.x - e1.z * e2.x) / det;
            gamma = o.z;
        }
        let spread = (alpha.abs() + beta.abs()) * (0.5 + EPS);
        let widen = 4e-3;
        let y0 = ceil_i(ymin - 1.0 - EPS).max(ceil_i(orow0 + o.y - 0.5 - widen)).max(0);
        let y1 = floor_i(ymax + EPS).min(floor_i(orow1 + o.y - 0.5 + widen)).min(self.height as i32 - 1);
        let last = self.width as i32 - 1;
        let (mut tx_min, mut tx_max) = (i32::MAX, i32::MIN);
        let width = self.width;
        let (dmin, flags) = (&mut self.dmin[..], &mut self.flags[..]);
        // (Compares rather than f32::max/min: no NaN to handle, and a third of the time.)
        let most = |l: &[(f32, f32)], cy: f32| l.iter().fold(f32::NEG_INFINITY, |x, &(m, q)| if m * cy + q > x { m * cy + q } else { x });
        let least = |l: &[(f32, f32)], cy: f32| l.iter().fold(f32::INFINITY, |x, &(m, q)| if m * cy + q < x { m * cy + q } else { x });
        for ty in y0..=y1 {
            let cy = ty as f32 + 0.5 - o.y;
            let (olo, ohi) = (most(outer_lo, cy), least(outer_hi, cy));
            // Texel tx's centre is tx + 0.5 - o.x about o.
            let (ox0, ox1) = (ceil_i(olo + o.x - 0.5 - widen).max(0), floor_i(ohi + o.x - 0.5 + widen).min(last));
            if ox0 > ox1 {
                continue;
            }
            let row = ty as usize * width;
            let (a, b) = (row + ox0 as usize, row + ox1 as usize + 1);
            // (Plain compares, not f32::min/max, so the loop vectorises.)
            let start = alpha * (ox0 as f32 + 0.5 - o.x) + beta * cy + gamma - spread;
            for (j, d) in dmin[a..b].iter_mut().enumerate() {
                let z = start + alpha * j as i32 as f32;
                let z = if z > zmin { z } else { zmin };
                *d = if z < *d { z } else { *d };
            }
            (tx_min, tx_max) = (tx_min.min(ox0), tx_max.max(ox1));
            if cy < crow0 || cy > crow1 {
                continue;
            }
            let (clo, chi) = (most(centre_lo, cy), least(centre_hi, cy));
            let (cx0, cx1) = (ceil_i(clo + o.x - 0.5).max(ox0), floor_i(chi + o.x - 0.5).min(ox1));
            if cx0 <= cx1 {
                for f in &mut flags[row + cx0 as usize..=row + cx1 as usize] {
                    *f |= 1;
                }
            }
        }
        if tx_min <= tx_max {
            self.touch(tx_min, y0, tx_max, y1);
        }
    }

    /// Mark every texel whose grown square the segment from `p` to `q` (texels) touches.
    fn mark_segment(&mut self, p: Vec3, q: Vec3) {
        let (p, q) = if p.y <= q.y { (p, q) } else { (q, p) };
        let g = EPS + 1e-3;
        let y0 = ceil_i(p.y - 1.0 - g).max(0);
        let y1 = floor_i(q.y + g).min(self.height as i32 - 1);
        let (xlo, xhi) = (p.x.min(q.x), p.x.max(q.x));
        // Off the screen (the guard band's edges): nothing to mark.
        if xhi < -1.0 || xlo > self.width as f32 + 1.0 || y0 > y1 {
            return;
        }
        let dy = q.y - p.y;
        // Nearly along a row: its whole x extent in each row it meets.
        let slope = if dy > 1e-3 { (q.x - p.x) / dy } else { 0.0 };
        let widen = g + slope.abs() * 1e-4;
        let last = self.width as i32 - 1;
        let (mut tx_min, mut tx_max) = (i32::MAX, i32::MIN);
        for ty in y0..=y1 {
            // The part of the segment in the row's grown band.
            let (x0, x1) = if dy > 1e-3 {
                let ya = (ty as f32 - g).max(p.y);
                let yb = (ty as f32 + 1.0 + g).min(q.y);
                let (xa, xb) = (p.x + (ya - p.y) * slope, p.x + (yb - p.y) * slope);
                (xa.min(xb).max(xlo), xa.max(xb).min(xhi))
            } else {
                (xlo, xhi)
            };
            let a = ceil_i(x0 - 1.0 - widen).max(0);
            let b = floor_i(x1 + widen).min(last);
            if a > b {
                continue;
            }
            let row = ty as usize * self.width;
            self.flags[row + a as usize..=row + b as usize].iter_mut().for_each(|f| *f |= 2);
            (tx_min, tx_max) = (tx_min.min(a), tx_max.max(b));
        }
        if tx_min <= tx_max {
            self.touch(tx_min, y0, tx_max, y1);
        }
    }

    fn touch(&mut self, x0: i32, y0: i32, x1: i32, y1: i32) {
        let r = &mut self.rect;
        *r = [r[0].min(x0), r[1].min(y0), r[2].max(x1), r[3].max(y1)];
    }

    /// Write the current mesh's covered texels into the buffer (nearest wins) and clear the
    /// scratch it touched.
    fn merge(&mut self) {
        let [x0, y0, x1, y1] = self.rect;
        if x0 > x1 || y0 > y1 {
            return;
        }
        let depth = &mut self.levels[0].2;
        for ty in y0 as usize..=y1 as usize {
            let span = ty * self.width + x0 as usize..=ty * self.width + x1 as usize;
            for ((out, d), f) in depth[span.clone()].iter_mut().zip(&mut self.dmin[span.clone()]).zip(&mut self.flags[span]) {
                if *f == 1 && d.is_finite() && *d > *out {
                    *out = *d;
                }
                (*d, *f) = (f32::INFINITY, 0);
            }
        }
    }

    /// Build the min-depth pyramid: call after the last `rasterise` and before testing.
    pub fn finish(&mut self) {
        for l in 1..self.levels.len() {
            let (lower, upper) = self.levels.split_at_mut(l);
            let (sw, sh, src) = (&lower[l - 1].0, &lower[l - 1].1, &lower[l - 1].2);
            let (w, h, dst) = (&upper[0].0, &upper[0].1, &mut upper[0].2);
            for y in 0..*h {
                let (ya, yb) = (2 * y, (2 * y + 1).min(sh - 1));
                for x in 0..*w {
                    let (xa, xb) = (2 * x, (2 * x + 1).min(sw - 1));
                    dst[y * w + x] = src[ya * sw + xa].min(src[ya * sw + xb]).min(src[yb * sw + xa]).min(src[yb * sw + xb]);
                }
            }
        }
    }

    /// The texels (x0, y0, x1, y1, inclusive) the world box `min`..`max` covers on screen and
    /// its nearest depth; None where the test cannot cull it (behind the camera or through the
    /// near plane: the GPU clips it there and it may reach the eye; or off the screen).
    fn project_box(&self, min: Vec3, max: Vec3) -> Option<([usize; 4], f32)> {
        let vp = self.view_proj;
        let base = vp * min.extend(1.0);
        let e = max - min;
        let (ax, ay, az) = (vp.x_axis * e.x, vp.y_axis * e.y, vp.z_axis * e.z);
        let (w, h) = (self.width as f32, self.height as f32);
        let (mut x0, mut y0, mut x1, mut y1, mut nearest) = (f32::INFINITY, f32::INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY);
        for i in 0..8 {
            let mut c = base;
            if i & 1 != 0 {
                c += ax;
            }
            if i & 2 != 0 {
                c += ay;
            }
            if i & 4 != 0 {
                c += az;
            }
            // (NaN fails the test too.)
            if !(c.w > 0.0 && c.z <= c.w) {
                return None;
            }
            let inv = 1.0 / c.w;
            let (sx, sy) = ((c.x * inv * 0.5 + 0.5) * w, (c.y * inv * 0.5 + 0.5) * h);
            (x0, y0, x1, y1) = (x0.min(sx), y0.min(sy), x1.max(sx), y1.max(sy));
            nearest = nearest.max(c.z * inv);
        }
        // Texels whose closed square meets the rectangle, grown a little.
        let tx0 = (x0 - EPS).floor().max(0.0);
        let ty0 = (y0 - EPS).floor().max(0.0);
        let tx1 = (x1 + EPS).floor().min(w - 1.0);
        let ty1 = (y1 + EPS).floor().min(h - 1.0);
        (tx0 <= tx1 && ty0 <= ty1).then_some(([tx0 as usize, ty0 as usize, tx1 as usize, ty1 as usize], nearest))
    }

    /// Whether the world box `min`..`max` is hidden behind what was rasterised (after `finish`).
    pub fn box_hidden(&self, min: Vec3, max: Vec3) -> bool {
        let Some((r, nearest)) = self.project_box(min, max) else { return false };
        // The finest level at which the rectangle spans at most 2x2 texels.
        let mut l = 0;
        while l + 1 < self.levels.len() && ((r[2] >> l) - (r[0] >> l) > 1 || (r[3] >> l) - (r[1] >> l) > 1) {
            l += 1;
        }
        for y in r[1] >> l..=r[3] >> l {
            for x in r[0] >> l..=r[2] >> l {
                if !self.hidden_below(l, x, y, &r, nearest) {
                    return false;
                }
            }
        }
        true
    }

    /// `box_hidden` on level 0 alone, before `finish` (between occluders).
    fn box_hidden_so_far(&self, min: Vec3, max: Vec3) -> bool {
        let Some((r, nearest)) = self.project_box(min, max) else { return false };
        let d = &self.levels[0].2;
        (r[1]..=r[3]).all(|y| d[y * self.width + r[0]..=y * self.width + r[2]].iter().all(|&o| hidden(nearest, o)))
    }

    /// Whether every level-0 texel of rectangle `r` under texel (x, y) of level `l` hides depth
    /// `nearest`: yes at once where the texel's own (farthest) depth does; else its children.
    fn hidden_below(&self, l: usize, x: usize, y: usize, r: &[usize; 4], nearest: f32) -> bool {
        let (w, _, d) = &self.levels[l];
        if hidden(nearest, d[y * w + x]) {
            return true;
        }
        if l == 0 {
            return false;
        }
        let (cw, ch, _) = self.levels[l - 1];
        let k = l - 1;
        let (xa, xb) = ((2 * x).max(r[0] >> k), (2 * x + 1).min(cw - 1).min(r[2] >> k));
        let (ya, yb) = ((2 * y).max(r[1] >> k), (2 * y + 1).min(ch - 1).min(r[3] >> k));
        for cy in ya..=yb {
            for cx in xa..=xb {
                if !self.hidden_below(k, cx, cy, r, nearest) {
                    return false;
                }
            }
        }
        true
    }
}

/// Sutherland-Hodgman against one plane, keeping which edges are the occluder's inside: an edge
/// made by the plane is a boundary. An intersection is computed from the inside end to the
/// outside end whichever way the edge runs, so two triangles sharing an edge get the same point.
fn clip_polygon(poly: &[PolyVertex], plane: Vec4, out: &mut [PolyVertex; 12]) -> usize {
    let mut n = 0;
    let mut push = |v: PolyVertex| {
        if n < out.len() {
            out[n] = v;
            n += 1;
        }
    };
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        let (da, db) = (a.clip.dot(plane), b.clip.dot(plane));
        let cut = |inside: Vec4, di: f32, outside: Vec4, dout: f32| inside + (outside - inside) * (di / (di - dout));
        if da >= 0.0 {
            push(a);
            if db < 0.0 {
                push(PolyVertex { clip: cut(a.clip, da, b.clip, db), interior: false });
            }
        } else if db >= 0.0 {
            push(PolyVertex { clip: cut(b.clip, db, a.clip, da), interior: a.interior });
        }
    }
    n
}

/// What occlusion culling may spend per frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OcclusionSettings {
    /// Triangles rasterised per frame at most (occluders' drawn LODs, whole meshes).
    pub triangle_budget: u32,
    /// Occluders per frame at most.
    pub max_occluders: u32,
    /// Smallest occluder: its bounding sphere's projected radius, in buffer texels.
    pub min_radius_texels: f32,
}

impl Default for OcclusionSettings {
    fn default() -> Self {
        OcclusionSettings { triangle_budget: MAX_OCCLUDER_TRIANGLES as u32, max_occluders: 8, min_radius_texels: 4.0 }
    }
}

/// What the last frame's occlusion pass did (exact).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct OcclusionStats {
    /// Occluders drawn into the buffer (candidates the ones before them hid are not).
    pub occluders: u32,
    /// Triangles of the occluders' drawn LODs (what the budget counts).
    pub occluder_triangles: u32,
    /// Of them, those drawn (facing and clipping as the GPU would).
    pub triangles_drawn: u32,
    pub tested: u32,
    pub culled: u32,
}

/// Chooses the frame's occluders among the frustum-visible instances, rasterises them and tests
/// the rest (`Visibility` runs it after frustum culling and LOD selection).
pub struct OcclusionCuller {
    pub settings: OcclusionSettings,
    pub stats: OcclusionStats,
    buffer: OcclusionBuffer,
    candidates: Vec<(f32, u32)>,
    state: Vec<u8>,
}

impl Default for OcclusionCuller {
    fn default() -> Self {
        OcclusionCuller::new(OcclusionSettings::default(), DEFAULT_SIZE)
    }
}

impl OcclusionCuller {
    /// With a buffer of `width` x `height` texels.
    pub fn new(settings: OcclusionSettings, (width, height): (usize, usize)) -> OcclusionCuller {
        OcclusionCuller { settings, stats: OcclusionStats::default(), buffer: OcclusionBuffer::new(width, height), candidates: Vec::new(), state: Vec::new() }
    }

    /// The last frame's buffer (to look at, or to test more boxes against).
    pub fn buffer(&self) -> &OcclusionBuffer {
        &self.buffer
    }

    /// Set `hidden[k]` for each of `draws` (frustum-visible instances at their chosen LODs) that
    /// the frame's occluders hide, for a camera at `eye` with `view_proj` and vertical FOV
    /// `fov_y` (radians). Occluders are static instances with an opaque submesh whose drawn LOD
    /// keeps its triangles (`GpuLod::occluder`), largest projected bounding sphere first, within
    /// the settings' budget; each is first tested against those before it (one they hide is
    /// culled, not drawn into the buffer), and is not tested after. Dynamic instances are tested
    /// by their culling sphere's box (a pose moves it), static ones by their drawn LOD's box.
    pub fn cull(&mut self, scene: &GpuScene, view_proj: Mat4, eye: Vec3, fov_y: f32, draws: &[Draw], hidden: &mut Vec<bool>) -> OcclusionStats {
        hidden.clear();
        hidden.resize(draws.len(), false);
        // Per draw: 0 to test at the end, 1 an occluder, 2 tested already.
        self.state.clear();
        self.state.resize(draws.len(), 0);
        let set = self.settings;
        let s = scene.instances.spheres();
        let world_box = |d: &Draw| {
            let i = d.instance as usize;
            let inst = &scene.instances[i];
            if inst.is_static {
                let mesh = &scene.meshes[inst.mesh as usize];
                let b = mesh.lods[d.lod as usize].bounds;
                crate::scene::transform_bounds(inst.world, b.min.min(mesh.bounds_min), b.max.max(mesh.bounds_max))
            } else {
                let (c, r) = (Vec3::new(s.x[i], s.y[i], s.z[i]), s.r[i]);
                (c - Vec3::splat(r), c + Vec3::splat(r))
            }
        };
        let texels_per_metre = 0.5 * self.buffer.height as f32 / (0.5 * fov_y).tan();
        self.candidates.clear();
        for (k, d) in draws.iter().enumerate() {
            let i = d.instance as usize;
            let inst = &scene.instances[i];
            if !inst.is_static {
                continue;
            }
            let Some(occ) = &scene.meshes[inst.mesh as usize].lods[d.lod as usize].occluder else { continue };
            if occ.triangles() > set.triangle_budget as usize {
                continue;
            }
            let (c, r) = (Vec3::new(s.x[i], s.y[i], s.z[i]), s.r[i]);
            let distance = (c - eye).length();
            let size = if distance <= r { f32::MAX } else { r / distance * texels_per_metre };
            if size >= set.min_radius_texels {
                self.candidates.push((size, k as u32));
            }
        }
        self.candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        self.buffer.begin(view_proj);
        let mut stats = OcclusionStats::default();
        for &(_, k) in &self.candidates {
            if stats.occluders >= set.max_occluders {
                break;
            }
            let d = draws[k as usize];
            let inst = &scene.instances[d.instance as usize];
            let lod = &scene.meshes[inst.mesh as usize].lods[d.lod as usize];
            let occ = lod.occluder.as_ref().expect("a candidate has its triangles");
            let n = occ.triangles() as u32;
            if stats.occluder_triangles + n > set.triangle_budget {
                continue;
            }
            let faces = |sub: usize| {
                let material = inst.material.unwrap_or(lod.submeshes[sub].material);
                scene.materials.get(material as usize).map_or(Faces::None, Faces::of)
            };
            if (0..lod.submeshes.len()).all(|sub| faces(sub) == Faces::None) {
                continue;
            }
            if stats.occluders > 0 {
                let (min, max) = world_box(&d);
                if self.buffer.box_hidden_so_far(min, max) {
                    (hidden[k as usize], self.state[k as usize]) = (true, 2);
                    stats.tested += 1;
                    stats.culled += 1;
                    continue;
                }
            }
            stats.triangles_drawn += self.buffer.rasterise(occ, inst.world, faces);
            stats.occluders += 1;
            stats.occluder_triangles += n;
            self.state[k as usize] = 1;
        }
        self.buffer.finish();
        for (k, d) in draws.iter().enumerate() {
            if self.state[k] != 0 {
                continue;
            }
            stats.tested += 1;
            if stats.occluders == 0 {
                continue;
            }
            let (min, max) = world_box(d);
            if self.buffer.box_hidden(min, max) {
                hidden[k] = true;
                stats.culled += 1;
            }
        }
        self.stats = stats;
        stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::camera::perspective_reverse_z;

    const W: usize = DEFAULT_SIZE.0;
    const H: usize = DEFAULT_SIZE.1;
    const FOV: f32 = std::f32::consts::FRAC_PI_3; // 60 degrees
    const NEAR: f32 = 0.1;

    /// A unit cube about the origin as the engine's meshes are: four vertices per face (split
    /// normals), counter-clockwise seen from outside.
    fn cube() -> (Vec<Vec3>, Vec<u32>) {
        let faces = [(Vec3::X, Vec3::NEG_Z, Vec3::Y), (Vec3::NEG_X, Vec3::Z, Vec3::Y), (Vec3::Y, Vec3::X, Vec3::NEG_Z), (Vec3::NEG_Y, Vec3::X, Vec3::Z), (Vec3::Z, Vec3::X, Vec3::Y), (Vec3::NEG_Z, Vec3::NEG_X, Vec3::Y)];
        let (mut p, mut idx) = (Vec::new(), Vec::new());
        for (n, u, w) in faces {
            let base = p.len() as u32;
            for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                p.push((n + u * a + w * b) * 0.5);
            }
            idx.extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
        }
        (p, idx)
    }

    fn cube_mesh() -> OccluderMesh {
        let (p, i) = cube();
        OccluderMesh::new(&p, &i, &[(0, 36)])
    }

    /// A unit square in the xy plane facing +Z (two triangles).
    fn quad_mesh() -> OccluderMesh {
        let p = [Vec3::new(-0.5, -0.5, 0.0), Vec3::new(0.5, -0.5, 0.0), Vec3::new(0.5, 0.5, 0.0), Vec3::new(-0.5, 0.5, 0.0)];
        OccluderMesh::new(&p, &[0, 1, 2, 0, 2, 3], &[(0, 6)])
    }

    fn view_proj(eye: Vec3, forward: Vec3) -> Mat4 {
        perspective_reverse_z(FOV, W as f32 / H as f32, NEAR) * Mat4::look_to_rh(eye, forward, Vec3::Y)
    }

    /// The buffer row (fractional, 0 at the top) of a point `y` metres up, `d` metres ahead of
    /// a camera at the origin looking down -Z, and the inverse.
    fn row_of(y: f32, d: f32) -> f32 {
        let f = 1.0 / (0.5 * FOV).tan();
        (-f * y / d * 0.5 + 0.5) * H as f32
    }
    fn y_at_row(row: f32, d: f32) -> f32 {
        let f = 1.0 / (0.5 * FOV).tan();
        (0.5 - row / H as f32) * 2.0 * d / f
    }

    /// The wall: 4 m wide and tall, 0.2 m thick, its front face at z = -4.9, its top at y = 2.
    fn wall() -> Mat4 {
        Mat4::from_scale_rotation_translation(Vec3::new(4.0, 4.0, 0.2), glam::Quat::IDENTITY, Vec3::new(0.0, 0.0, -5.0))
    }

    fn buffer_with(vp: Mat4, occluders: &[(&OccluderMesh, Mat4, Faces)]) -> OcclusionBuffer {
        let mut b = OcclusionBuffer::new(W, H);
        b.begin(vp);
        for (mesh, model, faces) in occluders {
            b.rasterise(mesh, *model, |_| *faces);
        }
        b.finish();
        b
    }

    fn unit_box(centre: Vec3) -> (Vec3, Vec3) {
        (centre - Vec3::splat(0.5), centre + Vec3::splat(0.5))
    }

    #[test]
    fn adjacency_welds_split_vertices() {
        let cube = cube_mesh();
        assert_eq!((cube.positions.len(), cube.triangles()), (8, 12));
        assert!(cube.neighbours.iter().flatten().all(|&n| n != NONE), "a closed cube has a neighbour across every edge");
        let quad = quad_mesh();
        let inner = quad.neighbours.iter().flatten().filter(|&&n| n != NONE).count();
        assert_eq!(inner, 2, "the diagonal, seen from both triangles; the four sides are borders");
    }

    #[test]
    fn a_wall_hides_a_box_behind_it_but_not_one_peeking_over_beside_or_in_front() {
        let vp = view_proj(Vec3::ZERO, Vec3::NEG_Z);
        let mesh = cube_mesh();
        let b = buffer_with(vp, &[(&mesh, wall(), Faces::Front)]);
        // The wall's face: depth near / 4.9 where it covers whole texels, nothing outside.
        let centre = b.depth()[(H / 2) * W + W / 2];
        assert!((centre - NEAR / 4.9).abs() < 1e-6, "{centre}");
        assert_eq!(b.depth()[W + 1], 0.0);
        assert!(b.box_hidden(unit_box(Vec3::new(0.0, 0.0, -10.0)).0, unit_box(Vec3::new(0.0, 0.0, -10.0)).1), "behind the wall");
        // Peeking over the top edge: the box's top one texel above the wall's top row.
        let top = row_of(2.0, 4.9);
        for (rows, hidden) in [(-1.0, false), (0.0, false), (2.0, true)] {
            // The box's nearest face is at 9.5 m: that face's top edge is its highest on screen.
            let y = y_at_row(top + rows, 9.5);
            let (min, max) = (Vec3::new(-0.5, y - 1.0, -10.5), Vec3::new(0.5, y, -9.5));
            assert_eq!(b.box_hidden(min, max), hidden, "box top {rows} texels below the wall's top edge");
        }
        let (min, max) = unit_box(Vec3::new(3.5, 0.0, -10.0));
        assert!(!b.box_hidden(min, max), "beside the wall");
        let (min, max) = unit_box(Vec3::new(0.0, 0.0, -3.0));
        assert!(!b.box_hidden(min, max), "in front of the wall");
        // Touching the wall's back face: just behind, hidden; reaching through it, kept.
        assert!(b.box_hidden(Vec3::new(-0.5, -0.5, -6.0), Vec3::new(0.5, 0.5, -5.1)));
        assert!(!b.box_hidden(Vec3::new(-0.5, -0.5, -6.0), Vec3::new(0.5, 0.5, -4.85)));
        // Behind the camera, and through the near plane: kept.
        assert!(!b.box_hidden(Vec3::new(-0.5, -0.5, 1.0), Vec3::new(0.5, 0.5, 2.0)));
        assert!(!b.box_hidden(Vec3::new(-0.5, -0.5, -20.0), Vec3::new(0.5, 0.5, 0.05)));
    }

    #[test]
    fn single_sided_walls_hide_only_from_the_front_and_masked_or_blended_ones_never() {
        let box_behind = unit_box(Vec3::new(0.0, 0.0, -10.0));
        let quad = quad_mesh();
        let facing = Mat4::from_scale_rotation_translation(Vec3::new(4.0, 4.0, 1.0), glam::Quat::IDENTITY, Vec3::new(0.0, 0.0, -5.0));
        let away = facing * Mat4::from_rotation_y(std::f32::consts::PI);
        let vp = view_proj(Vec3::ZERO, Vec3::NEG_Z);
        for (model, faces, hides) in [(facing, Faces::Front, true), (away, Faces::Front, false), (away, Faces::Both, true), (facing, Faces::None, false)] {
            let b = buffer_with(vp, &[(&quad, model, faces)]);
            assert_eq!(b.box_hidden(box_behind.0, box_behind.1), hides, "{faces:?}");
        }
        // A mirroring placement winds its triangles the other way and the GPU's front face
        // turns with it (`Batcher`): the front stays the side the mesh's normals face.
        let mirror = Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0));
        let b = buffer_with(vp, &[(&quad, facing * mirror, Faces::Front)]);
        assert!(b.box_hidden(box_behind.0, box_behind.1));
        let b = buffer_with(vp, &[(&quad, away * mirror, Faces::Front)]);
        assert!(!b.box_hidden(box_behind.0, box_behind.1));
    }

    #[test]
    fn a_gap_between_two_walls_narrower_than_a_texel_is_never_written() {
        let vp = view_proj(Vec3::ZERO, Vec3::NEG_Z);
        let mesh = cube_mesh();
        // Two halves of the wall 2 cm apart (under half a texel at 4.9 m).
        let half = |x: f32| Mat4::from_scale_rotation_translation(Vec3::new(1.99, 4.0, 0.2), glam::Quat::IDENTITY, Vec3::new(x, 0.0, -5.0));
        let b = buffer_with(vp, &[(&mesh, half(-1.005), Faces::Front), (&mesh, half(1.005), Faces::Front)]);
        let thin = (Vec3::new(-0.004, -0.5, -10.5), Vec3::new(0.004, 0.5, -9.5));
        assert!(!b.box_hidden(thin.0, thin.1), "seen through the gap");
        let (min, max) = unit_box(Vec3::new(-1.0, 0.0, -10.0));
        assert!(b.box_hidden(min, max), "behind one half");
        // The column of texels the gap crosses holds nothing.
        let col = W / 2;
        assert!((0..H).all(|y| b.depth()[y * W + col] == 0.0 || b.depth()[y * W + col - 1] == 0.0));
    }

    #[test]
    fn an_occluder_through_the_near_plane_is_clipped_there() {
        // A wall along the view on the left, from 5 m behind the camera to 50 m ahead, facing +x.
        let vp = view_proj(Vec3::ZERO, Vec3::NEG_Z);
        let mesh = cube_mesh();
        let side = Mat4::from_scale_rotation_translation(Vec3::new(0.2, 10.0, 55.0), glam::Quat::IDENTITY, Vec3::new(-1.1, 0.0, -22.5));
        let b = buffer_with(vp, &[(&mesh, side, Faces::Front)]);
        let (min, max) = unit_box(Vec3::new(-4.0, 0.0, -10.0));
        assert!(b.box_hidden(min, max), "behind the side wall");
        let (min, max) = unit_box(Vec3::new(0.5, 0.0, -10.0));
        assert!(!b.box_hidden(min, max), "in the open to its right");
        // The right half of the view stays empty, the left edge is the wall, nearest at the
        // near plane's edge.
        assert!((0..H).all(|y| b.depth()[y * W + W - 1] == 0.0 && b.depth()[y * W + W / 2 + 10] == 0.0));
        let left = b.depth()[(H / 2) * W];
        assert!(left > 0.0 && left <= 1.0, "{left}");
        // Seen from inside a box (the camera within the occluder): its inside faces are back
        // faces, so nothing is hidden.
        let around = Mat4::from_scale(Vec3::splat(4.0));
        let b = buffer_with(vp, &[(&mesh, around, Faces::Front)]);
        assert!(b.depth().iter().all(|&d| d == 0.0));
        let b = buffer_with(vp, &[(&mesh, around, Faces::Both)]);
        let (min, max) = unit_box(Vec3::new(0.0, 0.0, -10.0));
        assert!(b.box_hidden(min, max), "double-sided: the room's far wall hides what is outside");
    }

    /// Ground truth by ray casting: every written texel is covered at each of a grid of points
    /// over it (corners included) by a drawn occluder triangle at least as near as its depth.
    #[test]
    fn written_texels_are_covered_everywhere_by_an_occluder_at_least_that_near() {
        let (w, h) = (64usize, 36usize);
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        let (cube_p, cube_i) = cube();
        let cube = OccluderMesh::new(&cube_p, &cube_i, &[(0, 36)]);
        let quad = quad_mesh();
        let mut written = 0usize;
        for scene in 0..100 {
            let eye = Vec3::new(rnd() * 4.0 - 2.0, rnd() * 2.0, rnd() * 4.0 - 2.0);
            let forward = if scene % 4 == 0 { Vec3::NEG_Z } else { Vec3::new(rnd() - 0.5, (rnd() - 0.5) * 0.6, -1.0).normalize() };
            let vp = perspective_reverse_z(FOV, w as f32 / h as f32, NEAR) * Mat4::look_to_rh(eye, forward, Vec3::Y);
            let mut b = OcclusionBuffer::new(w, h);
            b.begin(vp);
            // (world triangles, single-sided) of every occluder, for the rays.
            let mut tris: Vec<([Vec3; 3], bool)> = Vec::new();
            for k in 0..6 {
                // A third axis-aligned (edges along the rows and columns), the rest at random.
                let rot = if k % 3 == 1 { glam::Quat::from_rotation_y((rnd() * 4.0).floor() * std::f32::consts::FRAC_PI_2) } else { glam::Quat::from_euler(glam::EulerRot::YXZ, rnd() * 6.3, rnd() * 6.3, rnd() * 6.3) };
                let mut scale = Vec3::new(0.2 + rnd() * 3.0, 0.2 + rnd() * 3.0, 0.05 + rnd() * 2.0);
                if k == 5 {
                    scale.x = -scale.x; // mirrored
                }
                let at = eye + forward * (1.0 + rnd() * 12.0) + Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5) * 6.0;
                // Some reach behind the camera.
                let at = if scene % 7 == 0 && k == 0 { eye + Vec3::new(0.0, 0.0, 0.5) } else { at };
                let model = Mat4::from_scale_rotation_translation(scale, rot, at);
                let (mesh, faces) = if k % 3 == 2 { (&quad, if k == 2 { Faces::Both } else { Faces::Front }) } else { (&cube, Faces::Front) };
                b.rasterise(mesh, model, |_| faces);
                let mirrored = model.determinant() < 0.0;
                for t in &mesh.triangles {
                    let [p0, p1, p2] = t.map(|i| model.transform_point3(mesh.positions[i as usize]));
                    // Wind every triangle counter-clockwise in world space as the GPU sees it.
                    let tri = if mirrored { [p0, p2, p1] } else { [p0, p1, p2] };
                    tris.push((tri, faces == Faces::Front));
                }
            }
            b.finish();
            let inv = vp.inverse();
            for ty in 0..h {
                for tx in 0..w {
                    let d = b.depth()[ty * w + tx];
                    if d == 0.0 {
                        continue;
                    }
                    written += 1;
                    for (sx, sy) in (0..16).map(|k| (tx as f32 + (k % 4) as f32 / 3.0, ty as f32 + (k / 4) as f32 / 3.0)) {
                        let ndc = Vec3::new(sx / w as f32 * 2.0 - 1.0, sy / h as f32 * 2.0 - 1.0, 1.0);
                        let (o, far) = (inv.project_point3(ndc), inv.project_point3(Vec3::new(ndc.x, ndc.y, 0.5)));
                        let dir = far - o;
                        let mut best: Option<f32> = None;
                        for (t, single) in &tris {
                            let [a, bb, c] = *t;
                            let n = (bb - a).cross(c - a);
                            if *single && n.dot(dir) >= 0.0 {
                                continue;
                            }
                            // Moller-Trumbore.
                            let (e1, e2) = (bb - a, c - a);
                            let pv = dir.cross(e2);
                            let det = e1.dot(pv);
                            if det.abs() < 1e-12 {
                                continue;
                            }
                            let s = o - a;
                            let u = s.dot(pv) / det;
                            let qv = s.cross(e1);
                            let v = dir.dot(qv) / det;
                            let t = e2.dot(qv) / det;
                            if u >= -1e-5 && v >= -1e-5 && u + v <= 1.0 + 1e-5 && t >= 0.0 {
                                let hit = vp.project_point3(o + dir * t).z;
                                best = Some(best.map_or(hit, |x: f32| x.max(hit)));
                            }
                        }
                        let hit = best.unwrap_or_else(|| panic!("scene {scene}: texel ({tx}, {ty}) depth {d} but nothing at ({sx}, {sy})"));
                        assert!(hit >= d * (1.0 - 1e-4) - 1e-7, "scene {scene}: texel ({tx}, {ty}) depth {d}, occluder at ({sx}, {sy}) only {hit}");
                    }
                }
            }
        }
        assert!(written > 10_000, "the scenes wrote only {written} texels");
    }

    #[test]
    fn same_input_same_buffer() {
        let vp = view_proj(Vec3::new(0.3, 1.0, 2.0), Vec3::new(0.1, -0.2, -1.0).normalize());
        let mesh = cube_mesh();
        let models: Vec<Mat4> = (0..20).map(|i| Mat4::from_scale_rotation_translation(Vec3::new(2.0, 1.0, 0.3), glam::Quat::from_rotation_y(i as f32), Vec3::new(i as f32 - 10.0, 0.0, -8.0 - i as f32))).collect();
        let occluders: Vec<(&OccluderMesh, Mat4, Faces)> = models.iter().map(|&m| (&mesh, m, Faces::Front)).collect();
        let (a, b) = (buffer_with(vp, &occluders), buffer_with(vp, &occluders));
        assert_eq!(a.depth().iter().map(|d| d.to_bits()).collect::<Vec<_>>(), b.depth().iter().map(|d| d.to_bits()).collect::<Vec<_>>());
        assert!(a.depth().iter().any(|&d| d > 0.0));
    }

    /// Cost on one core: 8 occluders of 512 triangles (4096: the default budget, and the
    /// default count) and 2000 boxes. `cargo test --release -p engine --lib occlusion --
    /// --nocapture` prints it.
    #[test]
    fn cost_of_a_full_budget() {
        // A 32 x 8 grid of quads (512 triangles) as one wall mesh.
        let (mut p, mut idx) = (Vec::new(), Vec::new());
        for y in 0..=8 {
            for x in 0..=32 {
                p.push(Vec3::new(x as f32 / 32.0 - 0.5, y as f32 / 8.0 - 0.5, 0.0));
            }
        }
        for y in 0..8u32 {
            for x in 0..32u32 {
                let (a, b, c, d) = (y * 33 + x, y * 33 + x + 1, (y + 1) * 33 + x + 1, (y + 1) * 33 + x);
                idx.extend_from_slice(&[a, b, c, a, c, d]);
            }
        }
        let mesh = OccluderMesh::new(&p, &idx, &[(0, idx.len() as u32)]);
        assert_eq!(mesh.triangles(), 512);
        let vp = view_proj(Vec3::new(0.0, 1.7, 0.0), Vec3::new(0.0, -0.1, -1.0).normalize());
        let walls: Vec<Mat4> = (0..8).map(|i| Mat4::from_scale_rotation_translation(Vec3::new(6.0, 4.0, 1.0), glam::Quat::from_rotation_y((i as f32 * 0.7).sin() * 0.5), Vec3::new((i % 4) as f32 * 6.0 - 9.0, 2.0, -6.0 - (i / 4) as f32 * 8.0))).collect();
        let boxes: Vec<(Vec3, Vec3)> = (0..2000).map(|i| unit_box(Vec3::new((i % 50) as f32 - 25.0, 0.5, -8.0 - (i / 50) as f32))).collect();
        let mut b = OcclusionBuffer::new(W, H);
        let (mut raster_ms, mut test_ms) = (f64::INFINITY, f64::INFINITY);
        let mut culled = 0;
        for _ in 0..20 {
            let t = std::time::Instant::now();
            b.begin(vp);
            for &m in &walls {
                b.rasterise(&mesh, m, |_| Faces::Front);
            }
            b.finish();
            raster_ms = raster_ms.min(t.elapsed().as_secs_f64() * 1e3);
            let t = std::time::Instant::now();
            culled = boxes.iter().filter(|(min, max)| b.box_hidden(*min, *max)).count();
            test_ms = test_ms.min(t.elapsed().as_secs_f64() * 1e3);
        }
        let covered = b.depth().iter().filter(|&&d| d > 0.0).count();
        eprintln!("occlusion: 8 occluders x 512 triangles ({covered} of {} texels written): {raster_ms:.3} ms; 2000 boxes ({culled} hidden): {test_ms:.3} ms (best of 20)", W * H);
        assert!(culled > 0);
    }
}
