//! The binary tree the wide one is made from: an exact surface-area-heuristic build (every split
//! of the centroid order, on every axis, at every node) down to one reference per leaf, in
//! parallel, with early split clipping of long triangles. Which subtrees become leaf blocks and
//! how the wide nodes are filled is decided afterwards ([`super::wide`]), by the SAH again.
//!
//! Exactness at n log n: the references are sorted by centroid once per axis; a node sweeps its
//! three sorted runs (O(n)) and hands each child its part of every run by a stable partition, so
//! nothing is sorted again below the root. Records are moved, not indices, so the sweeps read
//! memory in order. Subtrees of `PAR_MIN` references or more are built on both sides of a
//! `rayon::join`; every node's place in the output is fixed by its reference range (a subtree of
//! n references is 2n - 1 nodes, depth first), so the tree is the same bits on any thread count.

use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// A node of the binary tree, depth first: a node of `count` references at index k covers the
/// references `first..first + count` of [`Binary::ids`]; if `count > 1` its left child (of `l`
/// references, `l` = that child's `count`) is at k + 1 and its right child at k + 2 l.
#[derive(Clone, Copy, Default)]
pub(super) struct Node {
    pub(super) min: [f32; 3],
    pub(super) max: [f32; 3],
    pub(super) first: u32,
    pub(super) count: u32,
}

impl Node {
    /// Half the surface area (what the SAH weighs children by).
    pub(super) fn area(&self) -> f32 {
        Aabb { min: self.min, max: self.max }.area()
    }
}

/// The binary tree and the triangle index of each reference, in leaf order.
pub(super) struct Binary {
    pub(super) nodes: Vec<Node>,
    pub(super) ids: Vec<u32>,
}

/// Subtrees of at least this many references are built in parallel (below, the join costs more
/// than it saves).
const PAR_MIN: usize = 2048;
/// Pre-splitting: references' boxes are halved while longer than this fraction of the scene's
/// largest extent, to at most `PRESPLIT_BUDGET` references per triangle on average.
const PRESPLIT_EXTENT: f32 = 1.0 / 32.0;
const PRESPLIT_BUDGET: usize = 2;
const PRESPLIT_DEPTH: u32 = 12;
/// Below this depth the SAH decides; deeper nodes split by count, so the tree depth (and the
/// traversal stack) stays bounded even for adversarial soups: at most 48 + 32 levels.
const SAH_DEPTH: usize = 48;

#[derive(Clone, Copy)]
pub(super) struct Aabb {
    min: [f32; 3],
    max: [f32; 3],
}

impl Aabb {
    const EMPTY: Aabb = Aabb { min: [f32::INFINITY; 3], max: [f32::NEG_INFINITY; 3] };
    #[inline(always)]
    fn grow(&mut self, p: [f32; 3]) {
        for k in 0..3 {
            self.min[k] = self.min[k].min(p[k]);
            self.max[k] = self.max[k].max(p[k]);
        }
    }
    #[inline(always)]
    fn join(&mut self, b: &Aabb) {
        for k in 0..3 {
            self.min[k] = self.min[k].min(b.min[k]);
            self.max[k] = self.max[k].max(b.max[k]);
        }
    }
    #[inline(always)]
    pub(super) fn area(&self) -> f32 {
        let d = [0, 1, 2].map(|k| self.max[k] - self.min[k]);
        if d[0] < 0.0 {
            return 0.0;
        }
        d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
    }
}

/// A reference: a triangle's box (or a clipped part's) as two 4-lane rows, the fourth lanes
/// holding its index among the references (which the partition flags are kept by) and the
/// triangle's, so the sweeps join boxes with one `min` and one `max` instruction.
#[derive(Clone, Copy)]
#[repr(C, align(16))]
struct Rec {
    lo: [f32; 4],
    hi: [f32; 4],
}

impl Rec {
    fn new(b: &Aabb, index: u32, id: u32) -> Rec {
        Rec { lo: [b.min[0], b.min[1], b.min[2], f32::from_bits(index)], hi: [b.max[0], b.max[1], b.max[2], f32::from_bits(id)] }
    }
    fn index(&self) -> u32 {
        self.lo[3].to_bits()
    }
    fn id(&self) -> u32 {
        self.hi[3].to_bits()
    }
    /// Sort key along `axis`: twice the centroid, mapped to an unsigned integer in the same order
    /// (`f32::total_cmp`'s), then the index: a total order, so the tree is deterministic.
    fn key(&self, axis: usize) -> u64 {
        let bits = (self.lo[axis] + self.hi[axis]).to_bits();
        let ordered = if bits >> 31 == 1 { !bits } else { bits | 1 << 31 };
        (ordered as u64) << 32 | self.index() as u64
    }
}

/// A growing box in the sweeps (SSE on x86_64; the fourth lanes are masked off).
#[derive(Clone, Copy)]
struct Acc {
    #[cfg(target_arch = "x86_64")]
    lo: std::arch::x86_64::__m128,
    #[cfg(target_arch = "x86_64")]
    hi: std::arch::x86_64::__m128,
    #[cfg(not(target_arch = "x86_64"))]
    b: Aabb,
}

#[cfg(target_arch = "x86_64")]
impl Acc {
    #[inline(always)]
    fn empty() -> Acc {
        use std::arch::x86_64::*;
        // SAFETY: SSE is part of x86_64.
        unsafe { Acc { lo: _mm_set1_ps(f32::INFINITY), hi: _mm_set1_ps(f32::NEG_INFINITY) } }
    }
    #[inline(always)]
    fn join(&mut self, r: &Rec) {
        use std::arch::x86_64::*;
        // SAFETY: SSE is part of x86_64; `Rec` is 16-byte aligned. The fourth lanes (index bits)
        // are zeroed before they meet the box, so no denormal or NaN reaches the arithmetic.
        unsafe {
            let mask = _mm_castsi128_ps(_mm_set_epi32(0, -1, -1, -1));
            self.lo = _mm_min_ps(self.lo, _mm_and_ps(_mm_load_ps(r.lo.as_ptr()), mask));
            self.hi = _mm_max_ps(self.hi, _mm_and_ps(_mm_load_ps(r.hi.as_ptr()), mask));
        }
    }
    #[inline(always)]
    fn area(&self) -> f32 {
        use std::arch::x86_64::*;
        // SAFETY: SSE is part of x86_64.
        let d: [f32; 4] = unsafe { std::mem::transmute(_mm_sub_ps(self.hi, self.lo)) };
        d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
    }
    fn aabb(&self) -> Aabb {
        // SAFETY: plain reinterpretation of the lanes.
        let (lo, hi): ([f32; 4], [f32; 4]) = unsafe { (std::mem::transmute(self.lo), std::mem::transmute(self.hi)) };
        Aabb { min: [lo[0], lo[1], lo[2]], max: [hi[0], hi[1], hi[2]] }
    }
}

#[cfg(not(target_arch = "x86_64"))]
impl Acc {
    fn empty() -> Acc {
        Acc { b: Aabb::EMPTY }
    }
    fn join(&mut self, r: &Rec) {
        self.b.grow([r.lo[0], r.lo[1], r.lo[2]]);
        self.b.grow([r.hi[0], r.hi[1], r.hi[2]]);
    }
    fn area(&self) -> f32 {
        let d = [0, 1, 2].map(|k| self.b.max[k] - self.b.min[k]);
        d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
    }
    fn aabb(&self) -> Aabb {
        self.b
    }
}

/// Build over the usable triangles (index in range, finite corners); None if there is none.
pub(super) fn binary(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Option<Binary> {
    let prims: Vec<(Aabb, u32)> = triangles
        .par_iter()
        .enumerate()
        .with_min_len(4096)
        .filter_map(|(i, t)| {
            let c = [positions.get(t[0] as usize)?, positions.get(t[1] as usize)?, positions.get(t[2] as usize)?];
            if c.iter().flat_map(|p| p.iter()).any(|x| !x.is_finite()) {
                return None;
            }
            let mut b = Aabb::EMPTY;
            c.iter().for_each(|p| b.grow(**p));
            Some((b, i as u32))
        })
        .collect();
    if prims.is_empty() {
        return None;
    }
    let prims = presplit(prims, positions, triangles);
    let n = prims.len();
    let base: Vec<Rec> = prims.iter().enumerate().map(|(i, (bounds, id))| Rec::new(bounds, i as u32, *id)).collect();
    // Sorting the 8-byte keys (which hold the index) and gathering moves less than sorting records.
    let sorted = |axis: usize| {
        let mut keys: Vec<u64> = base.iter().map(|r| r.key(axis)).collect();
        keys.par_sort_unstable();
        keys.iter().map(|&k| base[k as u32 as usize]).collect::<Vec<Rec>>()
    };
    let (x, (y, z)) = rayon::join(|| sorted(0), || rayon::join(|| sorted(1), || sorted(2)));
    let mut runs = [x, y, z];
    let mut scratch = vec![Rec::new(&Aabb::EMPTY, 0, 0); n];
    let mut areas = vec![0f32; n];
    let left: Vec<AtomicBool> = (0..n).map(|_| AtomicBool::new(false)).collect();
    let mut nodes = vec![Node::default(); 2 * n - 1];
    {
        let [rx, ry, rz] = &mut runs;
        let job = Job { left: &left };
        job.node([rx, ry, rz], &mut scratch, &mut areas, &mut nodes, 0, 0);
    }
    Some(Binary { nodes, ids: runs[0].iter().map(|r| r.id()).collect() })
}

struct Job<'a> {
    /// Per reference, whether the split being made sends it left.
    left: &'a [AtomicBool],
}

impl Job<'_> {
    /// Builds the subtree over the references in `runs` (the same set, sorted by centroid along
    /// x, y and z), which start at `first` in leaf order, into `nodes` (its 2n - 1 slots).
    fn node(&self, runs: [&mut [Rec]; 3], scratch: &mut [Rec], areas: &mut [f32], nodes: &mut [Node], first: usize, depth: usize) {
        let n = runs[0].len();
        // Bounds, and the best split: (cost, axis, references left).
        let mut bounds = Aabb::EMPTY;
        let mut best: Option<(f32, usize, usize)> = None;
        for axis in 0..3 {
            let run = &runs[axis];
            let mut acc = Acc::empty();
            for i in (1..n).rev() {
                acc.join(&run[i]);
                areas[i] = acc.area();
            }
            if axis == 0 {
                acc.join(&run[0]);
                bounds = acc.aabb();
            }
            if depth >= SAH_DEPTH || n == 1 {
                break;
            }
            let mut l = Acc::empty();
            for i in 1..n {
                l.join(&run[i - 1]);
                let cost = i as f32 * l.area() + (n - i) as f32 * areas[i];
                if best.is_none_or(|b| cost < b.0) {
                    best = Some((cost, axis, i));
                }
            }
        }
        nodes[0] = Node { min: bounds.min, max: bounds.max, first: first as u32, count: n as u32 };
        if n == 1 {
            return;
        }
        // Deep nodes (and costs that overflowed to NaN) split by count: keeps depth logarithmic.
        let (axis, mid) = best.map_or((0, n / 2), |(_, a, m)| (a, m));
        let [rx, ry, rz] = runs;
        let mut runs = [rx, ry, rz];
        for (i, r) in runs[axis].iter().enumerate() {
            self.left[r.index() as usize].store(i < mid, Ordering::Relaxed);
        }
        for (a, run) in runs.iter_mut().enumerate() {
            if a == axis {
                continue;
            }
            // Stable partition through the scratch: each side keeps its sorted order.
            let (mut l, mut r) = (0, mid);
            for rec in run.iter() {
                if self.left[rec.index() as usize].load(Ordering::Relaxed) {
                    scratch[l] = *rec;
                    l += 1;
                } else {
                    scratch[r] = *rec;
                    r += 1;
                }
            }
            debug_assert!(l == mid && r == n);
            run.copy_from_slice(&scratch[..n]);
        }
        let [rx, ry, rz] = runs;
        let ((lx, hx), (ly, hy), (lz, hz)) = (rx.split_at_mut(mid), ry.split_at_mut(mid), rz.split_at_mut(mid));
        let (ls, hs) = scratch.split_at_mut(mid);
        let (la, ha) = areas.split_at_mut(mid);
        let (ln, hn) = nodes[1..].split_at_mut(2 * mid - 1);
        let mut lo = move || self.node([lx, ly, lz], ls, la, ln, first, depth + 1);
        let mut hi = move || self.node([hx, hy, hz], hs, ha, hn, first + mid, depth + 1);
        if n >= PAR_MIN {
            rayon::join(lo, hi);
        } else {
            lo();
            hi();
        }
    }
}

/// Early split clipping (Ernst & Greiner 2007): a triangle whose box is large next to the scene
/// is split into several references, each with the box of the part of the triangle inside a
/// half of its box, so long thin triangles (walls, ground) do not make every box overlap. A
/// triangle may then sit in several leaves; hits are unchanged (the same test, the same t).
/// Triangles are split in order until the budget is spent (the clipping runs in parallel).
fn presplit(prims: Vec<(Aabb, u32)>, positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Vec<(Aabb, u32)> {
    let mut scene = Aabb::EMPTY;
    prims.iter().for_each(|p| scene.join(&p.0));
    let ext = [0, 1, 2].map(|k| scene.max[k] - scene.min[k]);
    let limit = ext[0].max(ext[1]).max(ext[2]) * PRESPLIT_EXTENT;
    if !(limit > 0.0) || !limit.is_finite() {
        return prims;
    }
    let parts: Vec<Option<Vec<Aabb>>> = prims
        .par_iter()
        .with_min_len(1024)
        .map(|&(b, id)| {
            if (0..3).all(|k| b.max[k] - b.min[k] <= limit) {
                return None;
            }
            let tri = triangles[id as usize].map(|v| positions[v as usize]);
            let mut out = Vec::new();
            split_ref(&tri, b, limit, 0, &mut out);
            (!out.is_empty()).then_some(out)
        })
        .collect();
    let budget = prims.len() * PRESPLIT_BUDGET;
    let mut out = prims.clone();
    for (i, p) in parts.into_iter().enumerate() {
        if out.len() >= budget {
            break;
        }
        if let Some(p) = p {
            let id = prims[i].1;
            out[i] = (p[0], id);
            out.extend(p[1..].iter().map(|b| (*b, id)));
        }
    }
    out
}

/// Boxes of the parts of `tri` inside `clip` (halving its longest side until under `limit`).
fn split_ref(tri: &[[f32; 3]; 3], clip: Aabb, limit: f32, depth: u32, out: &mut Vec<Aabb>) {
    let ext = [0, 1, 2].map(|k| clip.max[k] - clip.min[k]);
    let axis = if ext[0] >= ext[1] && ext[0] >= ext[2] {
        0
    } else if ext[1] >= ext[2] {
        1
    } else {
        2
    };
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
    // A triangle clipped by 6 planes has at most 3 + 6 corners (each plane adds at most one).
    const MAX: usize = 9;
    let mut poly = [[0f64; 3]; MAX];
    let mut len = 3;
    for (i, p) in tri.iter().enumerate() {
        poly[i] = p.map(|x| x as f64);
    }
    for k in 0..3 {
        for (side, plane) in [(0, b.min[k] as f64), (1, b.max[k] as f64)] {
            let inside = |p: &[f64; 3]| {
                if side == 0 {
                    p[k] >= plane
                } else {
                    p[k] <= plane
                }
            };
            let mut next = [[0f64; 3]; MAX];
            let mut n = 0;
            for i in 0..len {
                let (p, q) = (poly[i], poly[(i + 1) % len]);
                if inside(&p) {
                    next[n] = p;
                    n += 1;
                }
                if inside(&p) != inside(&q) {
                    let t = (plane - p[k]) / (q[k] - p[k]);
                    let mut x = [0, 1, 2].map(|j| p[j] + t * (q[j] - p[j]));
                    x[k] = plane;
                    next[n] = x;
                    n += 1;
                }
            }
            (poly, len) = (next, n);
            if len == 0 {
                return None;
            }
        }
    }
    let mut out = Aabb::EMPTY;
    for p in &poly[..len] {
        for k in 0..3 {
            let pad = p[k].abs() * 1e-6 + 1e-30;
            out.min[k] = out.min[k].min(((p[k] - pad) as f32).max(b.min[k]));
            out.max[k] = out.max[k].max(((p[k] + pad) as f32).min(b.max[k]));
        }
    }
    Some(out)
}
