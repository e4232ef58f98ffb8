//! Ray queries against a triangle soup: a binned-SAH BVH with 32-byte flattened nodes.
//!
//! - Build: binned surface-area heuristic (16 bins per axis over centroid bounds). A node becomes
//!   a leaf when splitting does not pay (and it has at most `MAX_LEAF` triangles); when every
//!   centroid falls in one bin (duplicates, degenerate soups) it is split by count instead.
//! - Layout: depth-first; an interior node's left child is the next node, `offset` is the right
//!   child. Leaves hold `count` triangles starting at `offset` in the reordered triangle array.
//! - Traversal: explicit stack; at an interior node both child boxes are tested, the nearer is
//!   visited first and the farther is pushed with its entry distance, so it is skipped once a
//!   closer hit is known (the book's "shrink t1", notes §4.2).
//! - Triangle test: watertight (Woop, Benthin, Wald 2013): a ray through a shared edge or vertex
//!   hits at least one of the triangles, never neither. Edge functions that come out exactly zero
//!   are recomputed in f64, as the paper recommends.
//! - Box test: slabs with the reciprocal direction (IEEE infinities handle zero components; a
//!   NaN from 0*inf is dropped by `max`/`min`, which keeps the box, conservatively), and the far
//!   distance widened by 1+2*gamma(3) (pbrt's robust bound) so rounding never culls a real hit.
//! - [`offset_ray`]: the origin offset of Wächter & Binder ("A Fast and Robust Method for Avoiding
//!   Self-Intersection", Ray Tracing Gems ch. 6): a few ulps along the normal, scaled with the
//!   position's magnitude, instead of a fixed epsilon.

/// Triangles per leaf at most (unless all their centroids coincide: then count splits apply).
const MAX_LEAF: usize = 8;
const BINS: usize = 16;
/// Cost of a box-pair test relative to one triangle test, in the SAH.
const TRAVERSAL_COST: f32 = 1.0;
const STACK: usize = 96;
/// Below this depth the SAH decides; deeper nodes split by count, so the tree depth (and the
/// traversal stack) stays bounded even for adversarial soups: at most 48 + 32 < STACK.
const SAH_DEPTH: usize = 48;

#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct Node {
    pub min: [f32; 3],
    /// Interior: index of the right child (the left one is the next node). Leaf: first triangle.
    pub offset: u32,
    pub max: [f32; 3],
    /// 0 for interior nodes.
    pub count: u16,
    /// Split axis of an interior node.
    pub axis: u16,
}

const _: () = assert!(std::mem::size_of::<Node>() == 32);

#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub origin: [f32; 3],
    /// Need not be unit length; `t` is in multiples of it. Must not be all zero.
    pub dir: [f32; 3],
    pub tmin: f32,
    pub tmax: f32,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    /// Index into the triangle list given to [`Bvh::build`].
    pub prim: u32,
}

pub struct Bvh {
    nodes: Vec<Node>,
    /// Triangle corners in leaf order (no index indirection in the inner loop).
    tris: Vec<[[f32; 3]; 3]>,
    /// Original triangle index of each entry of `tris`.
    ids: Vec<u32>,
}

#[derive(Clone, Copy)]
struct Aabb {
    min: [f32; 3],
    max: [f32; 3],
}

impl Aabb {
    const EMPTY: Aabb = Aabb { min: [f32::INFINITY; 3], max: [f32::NEG_INFINITY; 3] };
    fn grow(&mut self, p: [f32; 3]) {
        for k in 0..3 {
            self.min[k] = self.min[k].min(p[k]);
            self.max[k] = self.max[k].max(p[k]);
        }
    }
    fn join(&mut self, b: &Aabb) {
        self.grow(b.min);
        self.grow(b.max);
    }
    fn area(&self) -> f32 {
        let d = [0, 1, 2].map(|k| self.max[k] - self.min[k]);
        if d[0] < 0.0 {
            return 0.0;
        }
        d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
    }
}

struct Prim {
    bounds: Aabb,
    centroid: [f32; 3],
    id: u32,
}

impl Bvh {
    /// Build over `triangles` (indices into `positions`). Triangles with an index out of range
    /// or a non-finite corner are left out (they can never be hit).
    pub fn build(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Bvh {
        let mut prims: Vec<Prim> = triangles
            .iter()
            .enumerate()
            .filter_map(|(i, t)| {
                let c = [positions.get(t[0] as usize)?, positions.get(t[1] as usize)?, positions.get(t[2] as usize)?];
                if c.iter().flat_map(|p| p.iter()).any(|x| !x.is_finite()) {
                    return None;
                }
                let mut b = Aabb::EMPTY;
                c.iter().for_each(|p| b.grow(**p));
                let centroid = [0, 1, 2].map(|k| 0.5 * (b.min[k] + b.max[k]));
                Some(Prim { bounds: b, centroid, id: i as u32 })
            })
            .collect();
        let mut nodes = Vec::with_capacity(prims.len().max(1));
        if prims.is_empty() {
            // An inverted box that no ray enters.
            nodes.push(Node { min: [f32::INFINITY; 3], offset: 0, max: [f32::NEG_INFINITY; 3], count: 0, axis: 0 });
            return Bvh { nodes, tris: Vec::new(), ids: Vec::new() };
        }
        build_node(&mut prims, 0, 0, &mut nodes);
        let ids: Vec<u32> = prims.iter().map(|p| p.id).collect();
        let tris = ids.iter().map(|&i| triangles[i as usize].map(|v| positions[v as usize])).collect();
        Bvh { nodes, tris, ids }
    }

    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }

    pub fn triangle_count(&self) -> usize {
        self.tris.len()
    }

    /// Closest hit with `tmin < t < tmax`, or None.
    pub fn closest(&self, ray: &Ray) -> Option<Hit> {
        let r = Prepared::new(ray);
        let mut tmax = ray.tmax;
        let mut best = u32::MAX;
        self.traverse(&r, &mut tmax, |tris, tmin, tmax| {
            for (i, tri) in tris {
                if let Some(t) = intersect(&r, tri, tmin, *tmax) {
                    *tmax = t;
                    best = i as u32;
                }
            }
            false
        });
        (best != u32::MAX).then(|| Hit { t: tmax, prim: self.ids[best as usize] })
    }

    /// Closest hits of many rays (t in (0, inf)) in parallel on the current rayon pool:
    /// (t, triangle) per ray, (inf, u32::MAX) on a miss.
    pub fn closest_many(&self, origins: &[[f32; 3]], dirs: &[[f32; 3]]) -> (Vec<f32>, Vec<u32>) {
        use rayon::prelude::*;
        origins
            .par_iter()
            .zip(dirs.par_iter())
            .with_min_len(1024)
            .map(|(o, d)| match self.closest(&Ray { origin: *o, dir: *d, tmin: 0.0, tmax: f32::INFINITY }) {
                Some(h) => (h.t, h.prim),
                None => (f32::INFINITY, u32::MAX),
            })
            .unzip()
    }

    /// Whether anything is hit with `tmin < t < tmax` (shadow rays): stops at the first hit.
    pub fn any(&self, ray: &Ray) -> bool {
        let r = Prepared::new(ray);
        let mut tmax = ray.tmax;
        let mut found = false;
        self.traverse(&r, &mut tmax, |tris, tmin, tmax| {
            found = tris.into_iter().any(|(_, tri)| intersect(&r, tri, tmin, *tmax).is_some());
            found
        });
        found
    }

    /// Depth-first traversal; `leaf(triangles with their leaf-order index, tmin, &mut tmax)`
    /// may shrink tmax and returns true to stop.
    #[inline(always)]
    fn traverse<'a, F>(&'a self, r: &Prepared, tmax: &mut f32, mut leaf: F)
    where
        F: FnMut(std::iter::Zip<std::ops::Range<usize>, std::slice::Iter<'a, [[f32; 3]; 3]>>, f32, &mut f32) -> bool,
    {
        if self.tris.is_empty() {
            return;
        }
        let tmin = r.tmin;
        let mut stack = [(0u32, 0f32); STACK];
        let mut sp = 0usize;
        let root = &self.nodes[0];
        if r.enter(root, *tmax).is_none() {
            return;
        }
        let mut at = 0usize;
        loop {
            let n = &self.nodes[at];
            if n.count > 0 {
                let s = n.offset as usize;
                let e = s + n.count as usize;
                if leaf((s..e).zip(self.tris[s..e].iter()), tmin, tmax) {
                    return;
                }
            } else {
                let (a, b) = (at + 1, n.offset as usize);
                let ta = r.enter(&self.nodes[a], *tmax);
                let tb = r.enter(&self.nodes[b], *tmax);
                match (ta, tb) {
                    (Some(ta), Some(tb)) => {
                        let (near, far, tfar) = if ta <= tb { (a, b, tb) } else { (b, a, ta) };
                        // The depth is bounded by the build (count splits halve); STACK covers it.
                        stack[sp] = (far as u32, tfar);
                        sp += 1;
                        at = near;
                        continue;
                    }
                    (Some(_), None) => {
                        at = a;
                        continue;
                    }
                    (None, Some(_)) => {
                        at = b;
                        continue;
                    }
                    (None, None) => {}
                }
            }
            // Pop the next subtree still in front of the closest hit so far.
            loop {
                if sp == 0 {
                    return;
                }
                sp -= 1;
                let (node, tenter) = stack[sp];
                if tenter <= *tmax {
                    at = node as usize;
                    break;
                }
            }
        }
    }
}

/// Per-ray constants for the box and triangle tests.
struct Prepared {
    org: [f32; 3],
    inv: [f32; 3],
    tmin: f32,
    // Woop et al.: axis permutation and shear that make the ray +z from the origin.
    k: [usize; 3],
    shear: [f32; 3],
}

/// 1 + 2*gamma(3), gamma(n) = n*eps/(1-n*eps) with eps = 2^-24 (pbrt 3 §3.9.2).
const ROBUST: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

impl Prepared {
    fn new(ray: &Ray) -> Prepared {
        let d = ray.dir;
        let inv = d.map(|x| 1.0 / x);
        let a = d.map(f32::abs);
        let kz = if a[0] > a[1] { if a[0] > a[2] { 0 } else { 2 } } else if a[1] > a[2] { 1 } else { 2 };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        // Keep the winding: swapping x and y when the dominant component is negative.
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        Prepared {
            org: ray.origin,
            inv,
            tmin: ray.tmin,
            k: [kx, ky, kz],
            shear: [d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]],
        }
    }

    /// Entry distance of the box if the ray overlaps it within (tmin, tmax).
    #[inline(always)]
    fn enter(&self, n: &Node, tmax: f32) -> Option<f32> {
        let mut lo = self.tmin;
        let mut hi = tmax;
        for k in 0..3 {
            let t0 = (n.min[k] - self.org[k]) * self.inv[k];
            let t1 = (n.max[k] - self.org[k]) * self.inv[k];
            // NaN (origin on the slab plane, direction 0 on this axis) is dropped by max/min.
            lo = lo.max(t0.min(t1));
            hi = hi.min(t0.max(t1) * ROBUST);
        }
        (lo <= hi).then_some(lo)
    }
}

/// Watertight ray-triangle test; the hit distance if `tmin < t < tmax`.
#[inline(always)]
fn intersect(r: &Prepared, tri: &[[f32; 3]; 3], tmin: f32, tmax: f32) -> Option<f32> {
    let [kx, ky, kz] = r.k;
    let [sx, sy, sz] = r.shear;
    let rel = |p: &[f32; 3]| [p[kx] - r.org[kx], p[ky] - r.org[ky], p[kz] - r.org[kz]];
    let (a, b, c) = (rel(&tri[0]), rel(&tri[1]), rel(&tri[2]));
    let (ax, ay) = (a[0] - sx * a[2], a[1] - sy * a[2]);
    let (bx, by) = (b[0] - sx * b[2], b[1] - sy * b[2]);
    let (cx, cy) = (c[0] - sx * c[2], c[1] - sy * c[2]);
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    if u == 0.0 || v == 0.0 || w == 0.0 {
        let f = |p: f32, q: f32, s: f32, t: f32| (p as f64 * q as f64 - s as f64 * t as f64) as f32;
        u = f(cx, by, cy, bx);
        v = f(ax, cy, ay, cx);
        w = f(bx, ay, by, ax);
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    let t_scaled = sz * (u * a[2] + v * b[2] + w * c[2]);
    let (ts, d) = if det < 0.0 { (-t_scaled, -det) } else { (t_scaled, det) };
    if ts <= tmin * d || ts >= tmax * d {
        return None;
    }
    let t = ts / d;
    // The division may round onto the bounds; keep the interval strict.
    (t > tmin && t < tmax).then_some(t)
}

/// Brute-force closest hit over every triangle (the BVH's test oracle and tiny-scene path).
pub fn closest_brute(positions: &[[f32; 3]], triangles: &[[u32; 3]], ray: &Ray) -> Option<Hit> {
    let r = Prepared::new(ray);
    let mut best = None;
    let mut tmax = ray.tmax;
    for (i, t) in triangles.iter().enumerate() {
        let tri = t.map(|v| positions[v as usize]);
        if tri.iter().flat_map(|p| p.iter()).any(|x| !x.is_finite()) {
            continue;
        }
        if let Some(th) = intersect(&r, &tri, ray.tmin, tmax) {
            tmax = th;
            best = Some(Hit { t: th, prim: i as u32 });
        }
    }
    best
}

/// Distance-weighted intersection of a ray with one triangle (for tests and tie checks).
pub fn intersect_triangle(ray: &Ray, tri: &[[f32; 3]; 3]) -> Option<f32> {
    intersect(&Prepared::new(ray), tri, ray.tmin, ray.tmax)
}

fn build_node(prims: &mut [Prim], first: usize, depth: usize, nodes: &mut Vec<Node>) -> usize {
    let me = nodes.len();
    let mut bounds = Aabb::EMPTY;
    let mut cb = Aabb::EMPTY;
    for p in prims.iter() {
        bounds.join(&p.bounds);
        cb.grow(p.centroid);
    }
    let n = prims.len();
    let leaf = |nodes: &mut Vec<Node>| {
        nodes.push(Node { min: bounds.min, offset: first as u32, max: bounds.max, count: n as u16, axis: 0 });
        me
    };
    if n <= 2 {
        return leaf(nodes);
    }
    // Best binned SAH split over the three axes.
    let mut best: Option<(f32, usize, usize)> = None; // (cost, axis, bins on the left)
    for axis in 0..if depth < SAH_DEPTH { 3 } else { 0 } {
        let (lo, hi) = (cb.min[axis], cb.max[axis]);
        if !(hi > lo) {
            continue;
        }
        let scale = BINS as f32 / (hi - lo);
        let bin_of = |c: f32| (((c - lo) * scale) as usize).min(BINS - 1);
        let mut counts = [0usize; BINS];
        let mut boxes = [Aabb::EMPTY; BINS];
        for p in prims.iter() {
            let b = bin_of(p.centroid[axis]);
            counts[b] += 1;
            boxes[b].join(&p.bounds);
        }
        // Sweep from the right for the right-side areas, then from the left.
        let mut right_area = [0f32; BINS];
        let mut acc = Aabb::EMPTY;
        for i in (1..BINS).rev() {
            acc.join(&boxes[i]);
            right_area[i] = acc.area();
        }
        let mut left = Aabb::EMPTY;
        let mut nl = 0;
        for i in 0..BINS - 1 {
            left.join(&boxes[i]);
            nl += counts[i];
            let nr = n - nl;
            if nl == 0 || nr == 0 {
                continue;
            }
            let cost = nl as f32 * left.area() + nr as f32 * right_area[i + 1];
            if best.is_none_or(|b| cost < b.0) {
                best = Some((cost, axis, i + 1));
            }
        }
    }
    let area = bounds.area();
    let (mid, axis) = match best {
        Some((cost, axis, split)) => {
            let leaf_cost = n as f32 * area;
            if n <= MAX_LEAF && leaf_cost <= TRAVERSAL_COST * area + cost {
                return leaf(nodes);
            }
            let (lo, hi) = (cb.min[axis], cb.max[axis]);
            let scale = BINS as f32 / (hi - lo);
            let mid = partition(prims, |p| (((p.centroid[axis] - lo) * scale) as usize).min(BINS - 1) < split);
            (mid, axis)
        }
        None if n <= MAX_LEAF => return leaf(nodes),
        // Every centroid in one point: split by count (keeps depth logarithmic).
        None => (n / 2, 0),
    };
    nodes.push(Node { min: bounds.min, offset: 0, max: bounds.max, count: 0, axis: axis as u16 });
    let (l, r) = prims.split_at_mut(mid);
    build_node(l, first, depth + 1, nodes);
    let right = build_node(r, first + mid, depth + 1, nodes);
    nodes[me].offset = right as u32;
    me
}

fn partition<T>(v: &mut [T], pred: impl Fn(&T) -> bool) -> usize {
    let mut i = 0;
    for j in 0..v.len() {
        if pred(&v[j]) {
            v.swap(i, j);
            i += 1;
        }
    }
    i
}

/// Ray origin just off a surface point `p` on the side the geometric normal `n` points to
/// (pass `-n` to leave through the back). Wächter & Binder, Ray Tracing Gems ch. 6: move by a
/// fixed number of ulps (256 * n per axis, in integer space) so the offset scales with |p|;
/// near the origin, where ulps are tiny, use a small absolute offset instead.
pub fn offset_ray(p: [f32; 3], n: [f32; 3]) -> [f32; 3] {
    const ORIGIN: f32 = 1.0 / 32.0;
    const FLOAT_SCALE: f32 = 1.0 / 65536.0;
    const INT_SCALE: f32 = 256.0;
    [0, 1, 2].map(|k| {
        if p[k].abs() < ORIGIN {
            return p[k] + FLOAT_SCALE * n[k];
        }
        let of = (INT_SCALE * n[k]) as i32;
        let bits = p[k].to_bits() as i32;
        f32::from_bits(if p[k] < 0.0 { bits - of } else { bits + of } as u32)
    })
}
