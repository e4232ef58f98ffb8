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

mod build;
mod offset;
mod triangle;

pub use offset::offset_ray;
pub use triangle::{closest_brute, intersect_triangle};
use triangle::{intersect, Prepared};

const STACK: usize = 96;

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

impl Bvh {
    /// Build over `triangles` (indices into `positions`). Triangles with an index out of range
    /// or a non-finite corner are left out (they can never be hit).
    pub fn build(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Bvh {
        let mut prims = build::prims(positions, triangles);
        let mut nodes = Vec::with_capacity(prims.len().max(1));
        if prims.is_empty() {
            // An inverted box that no ray enters.
            nodes.push(Node { min: [f32::INFINITY; 3], offset: 0, max: [f32::NEG_INFINITY; 3], count: 0, axis: 0 });
            return Bvh { nodes, tris: Vec::new(), ids: Vec::new() };
        }
        build::build_node(&mut prims, 0, 0, &mut nodes);
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
