//! Ray queries against a triangle soup: a binned-SAH BVH with 32-byte flattened nodes.
//!
//! - Build: binned surface-area heuristic (16 bins per axis over centroid bounds). A node becomes
//!   a leaf when splitting does not pay (and it has at most `MAX_LEAF` triangles); when every
//!   centroid falls in one bin (duplicates, degenerate soups) it is split by count instead.
//! - Pre-splitting ([`presplit`], early split clipping): triangles much longer than the scene's
//!   size / 32 are given several references with the boxes of their clipped parts, up to 2x as
//!   many references as triangles in all; a triangle can then be tested in several leaves.
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
/// Pre-splitting: references' boxes are halved while longer than this fraction of the scene's
/// largest extent, to at most `PRESPLIT_BUDGET` references per triangle on average.
const PRESPLIT_EXTENT: f32 = 1.0 / 32.0;
const PRESPLIT_BUDGET: usize = 2;
const PRESPLIT_DEPTH: u32 = 12;
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

/// Box and triangle test counters of the current thread (test builds only), for the benchmark.
#[cfg(test)]
pub mod stats {
    use std::cell::Cell;
    thread_local!(static C: Cell<(u64, u64)> = const { Cell::new((0, 0)) });
    pub fn add(boxes: u64, prims: u64) {
        C.with(|c| {
            let (a, b) = c.get();
            c.set((a + boxes, b + prims))
        });
    }
    /// (box tests, triangle tests) since the last call.
    pub fn take() -> (u64, u64) {
        C.with(|c| c.replace((0, 0)))
    }
}
#[cfg(not(test))]
mod stats {
    #[inline(always)]
    pub fn add(_: u64, _: u64) {}
}

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
        presplit(&mut prims, positions, triangles);
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
        // SAFETY (the unchecked loads below): the build makes every child index and leaf range
        // valid (children follow their parent in `nodes`, leaves index into `tris`).
        let node = |i: usize| unsafe { self.nodes.get_unchecked(i) };
        if r.enter(root, *tmax).is_none() {
            return;
        }
        let mut at = 0usize;
        loop {
            let n = node(at);
            if n.count > 0 {
                let s = n.offset as usize;
                let e = s + n.count as usize;
                stats::add(0, (e - s) as u64);
                if leaf((s..e).zip(unsafe { self.tris.get_unchecked(s..e) }.iter()), tmin, tmax) {
                    return;
                }
            } else {
                let (a, b) = (at + 1, n.offset as usize);
                stats::add(2, 0);
                let ta = r.enter(node(a), *tmax);
                let tb = r.enter(node(b), *tmax);
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
    /// Direction sign bits (near plane is the box's max on negative axes).
    neg: [bool; 3],
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
            neg: d.map(|x| x.is_sign_negative()),
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
            // Near and far planes by the direction's sign (sign bit, so -0 counts as negative).
            let (pn, pf) = if self.neg[k] { (n.max[k], n.min[k]) } else { (n.min[k], n.max[k]) };
            let t0 = (pn - self.org[k]) * self.inv[k];
            let t1 = (pf - self.org[k]) * self.inv[k] * ROBUST;
            // NaN (origin on the slab plane, direction 0 on this axis) fails the comparison and
            // leaves the bound as it was: conservative.
            lo = if t0 > lo { t0 } else { lo };
            hi = if t1 < hi { t1 } else { hi };
        }
        (lo <= hi).then_some(lo)
    }
}

/// Watertight ray-triangle test; the hit distance if `tmin < t < tmax`.
#[inline(always)]
fn intersect(r: &Prepared, tri: &[[f32; 3]; 3], tmin: f32, tmax: f32) -> Option<f32> {
    let [kx, ky, kz] = r.k;
    let [sx, sy, sz] = r.shear;
    // SAFETY: kx, ky, kz are a permutation of 0..3 (Prepared::new).
    let at = |p: &[f32; 3], k: usize| unsafe { *p.get_unchecked(k) };
    let rel = |p: &[f32; 3]| [at(p, kx) - at(&r.org, kx), at(p, ky) - at(&r.org, ky), at(p, kz) - at(&r.org, kz)];
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
    // Cheap rejection before the division; the far bound is widened (conservative) so the
    // exact `t < tmax` below decides, and a hit is kept or not whatever tmax earlier triangles
    // left (otherwise a hit a rounding under tmax could be lost, making the closest hit depend
    // on the order triangles are tested in).
    if ts <= tmin * d || ts > tmax * d * ROBUST {
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

/// Early split clipping (Ernst & Greiner 2007): a triangle whose box is large next to the scene
/// is split into several references, each with the box of the part of the triangle inside a
/// half of its box, so long thin triangles (walls, ground) do not make every box overlap. A
/// triangle may then sit in several leaves; hits are unchanged (the same test, the same t).
fn presplit(prims: &mut Vec<Prim>, positions: &[[f32; 3]], triangles: &[[u32; 3]]) {
    let mut scene = Aabb::EMPTY;
    prims.iter().for_each(|p| scene.join(&p.bounds));
    let ext = [0, 1, 2].map(|k| scene.max[k] - scene.min[k]);
    let limit = ext[0].max(ext[1]).max(ext[2]) * PRESPLIT_EXTENT;
    if !(limit > 0.0) || !limit.is_finite() {
        return;
    }
    let budget = prims.len() * PRESPLIT_BUDGET;
    let n = prims.len();
    for i in 0..n {
        if prims.len() >= budget {
            break;
        }
        let b = prims[i].bounds;
        if (0..3).all(|k| b.max[k] - b.min[k] <= limit) {
            continue;
        }
        let id = prims[i].id;
        let tri = triangles[id as usize].map(|v| positions[v as usize]);
        let mut out = Vec::new();
        split_ref(&tri, b, limit, 0, &mut out);
        if out.is_empty() {
            continue;
        }
        let mk = |bounds: Aabb| Prim { bounds, centroid: [0, 1, 2].map(|k| 0.5 * (bounds.min[k] + bounds.max[k])), id };
        prims[i] = mk(out[0]);
        prims.extend(out[1..].iter().map(|b| mk(*b)));
    }
}

/// Boxes of the parts of `tri` inside `clip` (halving its longest side until under `limit`).
fn split_ref(tri: &[[f32; 3]; 3], clip: Aabb, limit: f32, depth: u32, out: &mut Vec<Aabb>) {
    let ext = [0, 1, 2].map(|k| clip.max[k] - clip.min[k]);
    let axis = if ext[0] >= ext[1] && ext[0] >= ext[2] { 0 } else if ext[1] >= ext[2] { 1 } else { 2 };
    if ext[axis] <= limit || depth >= PRESPLIT_DEPTH {
        out.push(clip);
        return;
    }
    let mid = 0.5 * (clip.min[axis] + clip.max[axis]);
    for side in 0..2 {
        let mut half = clip;
        if side == 0 {
            half.max[axis] = mid;
        } else {
            half.min[axis] = mid;
        }
        if let Some(b) = clipped_bounds(tri, &half) {
            split_ref(tri, b, limit, depth + 1, out);
        }
    }
}

/// Bounds of the triangle clipped to the box `b` (Sutherland-Hodgman in f64), widened by a few
/// ulps and cut to `b` (so a hit inside `b` is always inside); None if nothing is left.
fn clipped_bounds(tri: &[[f32; 3]; 3], b: &Aabb) -> Option<Aabb> {
    let mut poly: Vec<[f64; 3]> = tri.iter().map(|p| p.map(|x| x as f64)).collect();
    for k in 0..3 {
        for (side, plane) in [(0, b.min[k] as f64), (1, b.max[k] as f64)] {
            let inside = |p: &[f64; 3]| if side == 0 { p[k] >= plane } else { p[k] <= plane };
            let mut next = Vec::with_capacity(poly.len() + 2);
            for i in 0..poly.len() {
                let (p, q) = (poly[i], poly[(i + 1) % poly.len()]);
                if inside(&p) {
                    next.push(p);
                }
                if inside(&p) != inside(&q) {
                    let t = (plane - p[k]) / (q[k] - p[k]);
                    let mut x = [0, 1, 2].map(|j| p[j] + t * (q[j] - p[j]));
                    x[k] = plane;
                    next.push(x);
                }
            }
            poly = next;
            if poly.is_empty() {
                return None;
            }
        }
    }
    let mut out = Aabb::EMPTY;
    for p in &poly {
        for k in 0..3 {
            let pad = p[k].abs() * 1e-6 + 1e-30;
            out.min[k] = out.min[k].min(((p[k] - pad) as f32).max(b.min[k]));
            out.max[k] = out.max[k].max(((p[k] + pad) as f32).min(b.max[k]));
        }
    }
    Some(out)
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
