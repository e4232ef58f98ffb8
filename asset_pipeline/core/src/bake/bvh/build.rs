//! Binned-SAH build of the binary tree, with early split clipping of long triangles.

/// A node of the binary tree, depth-first: an interior node's left child is the next node.
pub(super) struct Node {
    pub(super) min: [f32; 3],
    pub(super) max: [f32; 3],
    /// Interior: index of the right child. Leaf: first reference in [`Binary::ids`].
    pub(super) offset: u32,
    /// References in a leaf; 0 for interior nodes.
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

/// Triangles per leaf at most (unless all their centroids coincide: then count splits apply):
/// one block, tested at once.
const MAX_LEAF: usize = super::wide::BLOCK;
const BINS: usize = 16;
/// Up to this many references the SAH tries every split of the centroid order; above, the
/// splits between 16 bins. Bin boundaries fall wherever they fall against the geometry: on
/// the grid-aligned CSG demo level, 12 or 32 bins instead of 16 changed node visits per ray by
/// -9% and +30%, a lottery that the exact sweep does not play. The sweep sorts at every level
/// (n log^2 n in all), so the top levels of big scenes stay binned: on the demo level a bound
/// of 512 / 4096 / none gave 4.6 / 4.1 / 3.6 node visits per ray, builds of 17 / 18 / 25 ms.
const SWEEP_MAX: usize = 4096;
/// Cost of a box-pair test relative to one leaf (block) test, in the SAH.
const TRAVERSAL_COST: f32 = 1.0;

/// SAH cost of `n` references in leaves: block tests, since a block's triangles cost one test
/// however many of its lanes are used (so a node of up to a block always becomes a leaf).
fn leaf_tests(n: usize) -> f32 {
    n.div_ceil(MAX_LEAF) as f32
}
/// Pre-splitting: references' boxes are halved while longer than this fraction of the scene's
/// largest extent, to at most `PRESPLIT_BUDGET` references per triangle on average.
const PRESPLIT_EXTENT: f32 = 1.0 / 32.0;
const PRESPLIT_BUDGET: usize = 2;
const PRESPLIT_DEPTH: u32 = 12;
/// Below this depth the SAH decides; deeper nodes split by count, so the tree depth (and the
/// traversal stack) stays bounded even for adversarial soups: at most 48 + 32 levels.
const SAH_DEPTH: usize = 48;

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

#[derive(Clone, Copy)]
struct Prim {
    bounds: Aabb,
    centroid: [f32; 3],
    id: u32,
}

/// Build over the usable triangles (index in range, finite corners); None if there is none.
pub(super) fn binary(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Option<Binary> {
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
    if prims.is_empty() {
        return None;
    }
    presplit(&mut prims, positions, triangles);
    let mut nodes = Vec::with_capacity(2 * prims.len());
    build_node(&mut prims, 0, 0, &mut nodes);
    Some(Binary { nodes, ids: prims.iter().map(|p| p.id).collect() })
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
        nodes.push(Node { min: bounds.min, max: bounds.max, offset: first as u32, count: n as u32 });
        me
    };
    if n <= 2 {
        return leaf(nodes);
    }
    // Best SAH split over the three axes.
    let mut best: Option<(f32, usize, Cut)> = None;
    for axis in 0..if depth < SAH_DEPTH { 3 } else { 0 } {
        if !(cb.max[axis] > cb.min[axis]) {
            continue;
        }
        let found = if n <= SWEEP_MAX { sweep(prims, axis) } else { binned(prims, &cb, axis) };
        if let Some((cost, cut)) = found {
            if best.as_ref().is_none_or(|b| cost < b.0) {
                best = Some((cost, axis, cut));
            }
        }
    }
    let area = bounds.area();
    let mid = match best {
        Some((cost, axis, cut)) => {
            let leaf_cost = leaf_tests(n) * area;
            if n <= MAX_LEAF && leaf_cost <= TRAVERSAL_COST * area + cost {
                return leaf(nodes);
            }
            match cut {
                Cut::Bins(split) => {
                    let (lo, hi) = (cb.min[axis], cb.max[axis]);
                    let scale = BINS as f32 / (hi - lo);
                    partition(prims, |p| (((p.centroid[axis] - lo) * scale) as usize).min(BINS - 1) < split)
                }
                Cut::Sorted(order, mid) => {
                    let sorted: Vec<Prim> = order.iter().map(|&i| prims[i as usize]).collect();
                    prims.copy_from_slice(&sorted);
                    mid
                }
            }
        }
        None if n <= MAX_LEAF => return leaf(nodes),
        // Every centroid in one point: split by count (keeps depth logarithmic).
        None => n / 2,
    };
    nodes.push(Node { min: bounds.min, max: bounds.max, offset: 0, count: 0 });
    let (l, r) = prims.split_at_mut(mid);
    build_node(l, first, depth + 1, nodes);
    let right = build_node(r, first + mid, depth + 1, nodes);
    nodes[me].offset = right as u32;
    me
}

/// A split of a node's references: the bins left of a boundary, or the first references of an
/// order (indices into the node's references, by centroid).
enum Cut {
    Bins(usize),
    Sorted(Vec<u32>, usize),
}

/// Every split of the references in centroid order along `axis` (exact SAH).
fn sweep(prims: &[Prim], axis: usize) -> Option<(f32, Cut)> {
    let n = prims.len();
    let mut order: Vec<u32> = (0..n as u32).collect();
    // Ties by position keep the order (and so the tree) deterministic.
    order.sort_by(|&a, &b| prims[a as usize].centroid[axis].total_cmp(&prims[b as usize].centroid[axis]).then(a.cmp(&b)));
    let mut right_area = vec![0f32; n];
    let mut acc = Aabb::EMPTY;
    for i in (1..n).rev() {
        acc.join(&prims[order[i] as usize].bounds);
        right_area[i] = acc.area();
    }
    let mut left = Aabb::EMPTY;
    let mut best: Option<(f32, usize)> = None;
    for i in 1..n {
        left.join(&prims[order[i - 1] as usize].bounds);
        let cost = leaf_tests(i) * left.area() + leaf_tests(n - i) * right_area[i];
        if best.is_none_or(|b| cost < b.0) {
            best = Some((cost, i));
        }
    }
    best.map(|(cost, mid)| (cost, Cut::Sorted(order, mid)))
}

/// The best of the splits between `BINS` equal bins of the centroid bounds along `axis`.
fn binned(prims: &[Prim], cb: &Aabb, axis: usize) -> Option<(f32, Cut)> {
    let n = prims.len();
    let (lo, hi) = (cb.min[axis], cb.max[axis]);
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
    let mut best: Option<(f32, usize)> = None;
    for i in 0..BINS - 1 {
        left.join(&boxes[i]);
        nl += counts[i];
        let nr = n - nl;
        if nl == 0 || nr == 0 {
            continue;
        }
        let cost = leaf_tests(nl) * left.area() + leaf_tests(nr) * right_area[i + 1];
        if best.is_none_or(|b| cost < b.0) {
            best = Some((cost, i + 1));
        }
    }
    best.map(|(cost, split)| (cost, Cut::Bins(split)))
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

