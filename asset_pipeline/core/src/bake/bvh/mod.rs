//! Ray queries against a triangle soup: an exact-SAH BVH cut into 8-wide nodes, traversed with
//! SIMD lanes.
//!
//! - Build ([`build`]): surface-area heuristic, exact (every split of the centroid order, on
//!   every axis, at every node) down to one reference per leaf, at n log n: the references are
//!   sorted once per axis and each node hands its children their parts of the three sorted runs
//!   by stable partition. Subtrees run on both sides of `rayon::join` (the current pool); each
//!   node's place in the output follows from its reference range, so the tree is the same bits
//!   on any thread count.
//!   Pre-splitting (early split clipping): triangles much longer than the scene's size / 32 get
//!   several references with the boxes of their clipped parts, up to 2x as many references as
//!   triangles in all; a triangle can then be tested in several leaves.
//! - Layout ([`wide`]): the binary tree cut into 8-wide nodes and leaf blocks of up to 8
//!   triangles by the SAH again (Ylitie et al. 2017's dynamic programme: each subtree costed as
//!   a block, a wide node, or spread over its parent's slots), which fills the nodes (7.1 of 8
//!   slots on the anchor scene, against 4.2 for greedy collapsing); child boxes stored plane by
//!   plane; a leaf is one block of triangles stored lane by lane, or half of one (a leaf of at
//!   most 4 triangles shares its block with the next such leaf: 26 % fewer blocks, 1.10-1.12x
//!   the rays/s on one thread on the anchor).
//! - Traversal ([`traverse`]): explicit stack; a visit tests the 8 child boxes at once, goes on
//!   with the nearest hit child and pushes the others in entry-distance order, so a subtree is
//!   skipped once a closer hit is known (the book's "shrink t1", notes §4.2); every child the ray
//!   enters is prefetched at once, which overlaps the cache misses of a walk. Of hits at the same
//!   distance the highest triangle index wins, so the closest hit depends on the geometry alone,
//!   not on the tree. Shadow rays stop at the first hit. A leaf's 8 triangles are tested at
//!   once. The lanes ([`lanes`]) are AVX
//!   registers where the CPU has AVX (checked at run time) and plain arrays elsewhere; both give
//!   the same bits. No fused multiply-add, in the box test either (measured: 0-5 % faster on
//!   the anchor, within its noise): a box test rounded differently can disagree with the
//!   triangle test's rounding at the edge of an interval (a grazing hit on a long triangle has a
//!   t with a relative error of 1e-4), so rare hits would depend on the CPU (21 of 1.76 M rays
//!   near their tmin on the demo level; the demo's lightmap changed).
//! - Triangle test ([`triangle`]): watertight (Woop, Benthin, Wald 2013): a ray through a shared
//!   edge or vertex hits at least one of the triangles, never neither. Edge functions that come
//!   out exactly zero are recomputed in f64, as the paper recommends (those lanes are redone one
//!   by one with the scalar test).
//! - Box test: slabs with the reciprocal direction (IEEE infinities handle zero components; a
//!   NaN from 0*inf is dropped by `max`/`min`, which keeps the box, conservatively), and the far
//!   distance widened by 1+2*gamma(3) (pbrt's robust bound) so rounding never culls a real hit.
//!   Both ends of the ray's interval are widened by the cull slack (`traverse::CULL_SLACK`) for
//!   the boxes: a triangle's computed t can lie beyond its box's computed exit.
//! - Hit filters ([`Bvh::closest_filtered`], [`Bvh::any_filtered`]): triangles flagged at build
//!   time (alpha-tested surfaces) can be passed through: the walk asks a closure about each hit
//!   on one and goes on when it says no, so a ray through a cut-out finds what lies behind in the
//!   same walk. Only leaves holding a flagged triangle are marked; the unfiltered queries are a
//!   separate instantiation with the filter compiled out (the opaque path does not pay for it).
//! - [`offset_ray`]: the origin offset of Wächter & Binder ("A Fast and Robust Method for Avoiding
//!   Self-Intersection", Ray Tracing Gems ch. 6): a few ulps along the normal, scaled with the
//!   position's magnitude, instead of a fixed epsilon.

mod build;
mod lanes;
mod offset;
mod traverse;
mod triangle;
mod wide;

pub use offset::offset_ray;
pub use triangle::{closest_brute, intersect_triangle};

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
    /// 8-wide nodes, the root first.
    nodes: Vec<wide::Wide>,
    /// Leaf triangles, a block of 8 per leaf.
    blocks: Vec<wide::Tris>,
    /// Per block, the lanes whose triangle was flagged for the hit filter (empty if none was).
    filter_lanes: Vec<u8>,
    /// The implementation queries run with: the fastest this CPU has.
    kernel: traverse::Kernel,
}

impl Bvh {
    /// Build over `triangles` (indices into `positions`). Triangles with an index out of range
    /// or a non-finite corner are left out (they can never be hit).
    pub fn build(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Bvh {
        Bvh::build_flagged(positions, triangles, None)
    }

    /// As [`Bvh::build`], with `flagged[i]` marking the triangles whose hits the filtered
    /// queries hand to their filter (one flag per triangle).
    pub fn build_flagged(positions: &[[f32; 3]], triangles: &[[u32; 3]], flagged: Option<&[bool]>) -> Bvh {
        assert!(flagged.is_none_or(|f| f.len() == triangles.len()), "one flag per triangle");
        let kernel = *traverse::Kernel::available().last().expect("the portable kernel");
        let Some(bin) = build::binary(positions, triangles) else {
            return Bvh { nodes: vec![wide::Wide::EMPTY], blocks: Vec::new(), filter_lanes: Vec::new(), kernel };
        };
        let w = wide::collapse(&bin, &wide::Soup { positions, triangles, flagged });
        assert!(w.stack < traverse::STACK, "BVH deeper than the traversal stack");
        Bvh { nodes: w.nodes, blocks: w.blocks, filter_lanes: w.filter_lanes, kernel }
    }

    /// Closest hit with `tmin < t < tmax`, or None (of hits at the same t, the one on the
    /// highest triangle index). Every triangle counts, flagged or not.
    pub fn closest(&self, ray: &Ray) -> Option<Hit> {
        traverse::closest(self, ray, &traverse::Opaque)
    }

    /// Closest hit with `tmin < t < tmax` among those kept: a hit on a flagged triangle counts
    /// only if `keep(triangle, t)`. `keep` must depend on nothing else (not on the order it is
    /// asked in), so the answer does not depend on the walk; it may be asked about hits that
    /// turn out to lie behind the closest.
    pub fn closest_filtered(&self, ray: &Ray, keep: impl Fn(u32, f32) -> bool) -> Option<Hit> {
        traverse::closest(self, ray, &traverse::Filtered(keep))
    }

    /// Whether a kept hit lies within `tmin < t < tmax` (shadow rays through alpha-tested
    /// surfaces): stops at the first one. `keep` as in [`Bvh::closest_filtered`].
    pub fn any_filtered(&self, ray: &Ray, keep: impl Fn(u32, f32) -> bool) -> bool {
        traverse::any(self, ray, &traverse::Filtered(keep))
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
    /// Every triangle counts, flagged or not.
    pub fn any(&self, ray: &Ray) -> bool {
        traverse::any(self, ray, &traverse::Opaque)
    }
}

#[cfg(test)]
mod tests;
