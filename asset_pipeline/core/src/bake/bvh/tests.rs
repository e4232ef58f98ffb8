//! The wide layout and the kernels: every kernel gives the portable one's hits to the bit, the
//! SIMD lanes compute what plain arrays compute, the 8-triangle test what `intersect` does.
//! (Hits against brute force are checked in `bake::tests`.)

use super::lanes::{Lanes, Scalar};
use super::traverse::{BoxRay, Kernel, TriRay};
use super::triangle::{intersect, Prepared};
use super::wide::{child, Tris, BLOCK};
use super::*;
use crate::bake::sampling::Rng;
use crate::bake::tests::{rand3, random_rays};

/// Box of a node's child slot as (min, max); min > max for an unused slot.
fn child_box(n: &wide::Wide, slot: usize) -> ([f32; 3], [f32; 3]) {
    ([0, 1, 2].map(|k| n.planes[2 * k][slot]), [0, 1, 2].map(|k| n.planes[2 * k + 1][slot]))
}

fn used(n: &wide::Wide, slot: usize) -> bool {
    n.planes[0][slot] <= n.planes[1][slot]
}

impl Bvh {
    /// Asserts that every node's child boxes lie inside the box its parent keeps for it.
    pub(crate) fn assert_boxes_nested(&self) {
        for (i, n) in self.nodes.iter().enumerate() {
            for slot in 0..wide::WIDTH {
                let c = n.child[slot];
                let (lo, hi) = child_box(n, slot);
                if !used(n, slot) || c & child::LEAF != 0 {
                    continue;
                }
                let inner = &self.nodes[c as usize];
                for s in (0..wide::WIDTH).filter(|&s| used(inner, s)) {
                    let (a, b) = child_box(inner, s);
                    assert!((0..3).all(|k| a[k] >= lo[k] && b[k] <= hi[k]), "node {i} slot {slot}: child {c} slot {s}");
                }
            }
        }
    }

    pub(crate) fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// (leaf blocks, triangle slots holding a distinct triangle): how full the leaves are.
    pub(crate) fn block_fill(&self) -> (usize, usize) {
        let used = self.blocks.iter().map(|b| (1..BLOCK).filter(|&l| b.id[l] != b.id[l - 1]).count() + 1).sum();
        (self.blocks.len(), used)
    }

    fn with_kernel(mut self, k: Kernel) -> Bvh {
        assert!(Kernel::available().contains(&k));
        self.kernel = k;
        self
    }
}

fn soup(r: &mut Rng, n: u32, spread: f32, size: f32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut pos = Vec::new();
    for _ in 0..n {
        let c = rand3(r, -spread, spread);
        pos.extend((0..3).map(|_| {
            let d = rand3(r, -size, size);
            [c[0] + d[0], c[1] + d[1], c[2] + d[2]]
        }));
    }
    (pos, (0..n).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect())
}

#[test]
fn every_kernel_gives_the_portable_hits_to_the_bit() {
    let mut r = Rng::for_sample(11, 0, 0);
    // A random soup, plus a grid sheet with shared edges (edge functions of exactly zero, the
    // lanes redone in scalar) crossed by rays aimed at its vertices.
    let (mut pos, mut tris) = soup(&mut r, 2000, 10.0, 1.0);
    let g = 16u32;
    let base = pos.len() as u32;
    pos.extend((0..=g).flat_map(|y| (0..=g).map(move |x| [x as f32 - 8.0, y as f32 - 8.0, 0.0])));
    for y in 0..g {
        for x in 0..g {
            let i = base + y * (g + 1) + x;
            tris.extend([[i, i + 1, i + g + 2], [i, i + g + 2, i + g + 1]]);
        }
    }
    let mut rays = random_rays(&mut r, 20000, -12.0, 12.0);
    rays.extend((0..2000).map(|k| {
        let target = [(k % 15) as f32 - 7.0, ((k / 15) % 15) as f32 - 7.0, 0.0];
        let o = rand3(&mut r, -12.0, 12.0);
        Ray { origin: o, dir: [0, 1, 2].map(|i| target[i] - o[i]), tmin: 0.0, tmax: f32::INFINITY }
    }));
    // Finite tmax and tmin too, to exercise both bounds.
    rays.extend(random_rays(&mut r, 2000, -12.0, 12.0).into_iter().map(|ray| Ray { tmin: 0.5, tmax: 6.0, ..ray }));
    let portable = Bvh::build(&pos, &tris).with_kernel(Kernel::Portable);
    // And bounds a hair either side of each hit, where box and triangle roundings meet.
    let near: Vec<Ray> = rays[..4000]
        .iter()
        .filter_map(|ray| portable.closest(ray).map(|h| (ray, h.t)))
        .flat_map(|(ray, t)| [0.99999f32, 1.0, 1.00001].into_iter().flat_map(move |f| [Ray { tmax: t * f, ..*ray }, Ray { tmin: t * f, ..*ray }]))
        .collect();
    rays.extend(near);
    let want: Vec<_> = rays.iter().map(|ray| (portable.closest(ray), portable.any(ray))).collect();
    assert!(want.iter().filter(|w| w.0.is_some()).count() > rays.len() / 4);
    for k in Kernel::available() {
        let bvh = Bvh::build(&pos, &tris).with_kernel(k);
        for (i, ray) in rays.iter().enumerate() {
            let got = (bvh.closest(ray), bvh.any(ray));
            assert_eq!(got, want[i], "{k:?}, ray {i}: {ray:?}");
            if let Some(h) = got.0 {
                assert_eq!(Some(h.t), closest_brute(&pos, &tris, ray).map(|b| b.t), "{k:?} ray {i}");
            }
        }
    }
}

#[test]
fn wide_tree_holds_every_usable_triangle_and_fits_the_stack() {
    let mut r = Rng::for_sample(12, 0, 0);
    for n in [1u32, 3, 4, 5, 9, 100, 5000] {
        let (pos, mut tris) = soup(&mut r, n, 10.0, 1.0);
        tris.push([0, 1, pos.len() as u32]); // out of range: left out
        let bvh = Bvh::build(&pos, &tris);
        let mut seen = vec![false; tris.len()];
        let mut stack = vec![0u32];
        while let Some(c) = stack.pop() {
            let node = &bvh.nodes[c as usize];
            for slot in (0..wide::WIDTH).filter(|&s| used(node, s)) {
                let c = node.child[slot];
                if c & child::LEAF == 0 {
                    stack.push(c);
                } else {
                    // Only the lanes the leaf owns (a leaf of up to 4 shares its block).
                    let b = &bvh.blocks[child::block(c)];
                    (0..BLOCK).filter(|&l| child::lanes(c) >> l & 1 == 1).for_each(|l| seen[b.id[l] as usize] = true);
                }
            }
        }
        assert!(seen[..n as usize].iter().all(|&s| s) && !seen[n as usize], "{n} triangles");
    }
}

/// Inputs that hit every IEEE case the tests meet: signed zeros, infinities, NaN, tiny and huge.
fn special_values(r: &mut Rng, n: usize) -> Vec<f32> {
    let special = [0.0, -0.0, 1.0, -1.0, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, 1e-30, -1e30, f32::MIN_POSITIVE];
    (0..n).map(|i| if i % 3 == 0 { special[(r.next_u32() as usize) % special.len()] } else { (r.next_f32() - 0.5) * 8.0 }).collect()
}

/// Every operation of lanes `L` against `Scalar<N>` on the same inputs, bit for bit.
fn assert_lanes_match<L: Lanes, const N: usize>() {
    let mut r = Rng::for_sample(13, N as u64, 0);
    for _ in 0..2000 {
        let (a, b) = (special_values(&mut r, N), special_values(&mut r, N));
        let (la, lb) = unsafe { (L::load(a.as_ptr()), L::load(b.as_ptr())) };
        let (sa, sb) = unsafe { (Scalar::<N>::load(a.as_ptr()), Scalar::<N>::load(b.as_ptr())) };
        let out = |x: L| {
            let mut o = [0f32; 8];
            x.store(&mut o);
            o.map(f32::to_bits)[..N].to_vec()
        };
        let want = |x: Scalar<N>| {
            let mut o = [0f32; 8];
            x.store(&mut o);
            o.map(f32::to_bits)[..N].to_vec()
        };
        let ops: [(fn(L, L) -> L, fn(Scalar<N>, Scalar<N>) -> Scalar<N>, &str); 14] = [
            (L::add, Scalar::add, "add"),
            (L::sub, Scalar::sub, "sub"),
            (L::mul, Scalar::mul, "mul"),
            (L::div, Scalar::div, "div"),
            (L::max, Scalar::max, "max"),
            (L::min, Scalar::min, "min"),
            (L::lt, Scalar::lt, "lt"),
            (L::le, Scalar::le, "le"),
            (L::gt, Scalar::gt, "gt"),
            (L::eq, Scalar::eq, "eq"),
            (L::and, Scalar::and, "and"),
            (L::or, Scalar::or, "or"),
            (L::and_not, Scalar::and_not, "and_not"),
            (L::xor, Scalar::xor, "xor"),
        ];
        for (l, s, name) in ops {
            let (got, exp) = (out(l(la, lb)), want(s(sa, sb)));
            // NaN payloads may differ; a NaN must stay a NaN.
            let same = got.iter().zip(&exp).all(|(g, e)| g == e || (f32::from_bits(*g).is_nan() && f32::from_bits(*e).is_nan()));
            assert!(same, "{name}({a:?}, {b:?}): {got:x?} vs {exp:x?}");
        }
        assert_eq!(la.bits(), sa.bits(), "bits of {a:?}");
        assert_eq!(out(L::splat(a[0])), want(Scalar::<N>::splat(a[0])));
    }
}

#[test]
fn simd_lanes_compute_what_plain_arrays_compute() {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx") {
            assert_lanes_match::<super::lanes::Avx, 8>();
        }
    }
    // Elsewhere there is only the portable kernel: nothing to compare.
}

/// The block test against `intersect` on each lane: the same hits and the same t bits.
fn assert_block_matches_intersect<T: Lanes>() {
    let mut r = Rng::for_sample(14, 0, 0);
    let (pos, tris) = soup(&mut r, 4000, 1.0, 1.0);
    let mut hits = 0;
    for (i, ray) in random_rays(&mut r, 4000, -2.0, 2.0).iter().enumerate() {
        let mut b = Tris { v: [[[0.0; BLOCK]; 3]; 3], id: [0; BLOCK] };
        for lane in 0..BLOCK {
            for (c, &v) in tris[(BLOCK * i + lane) % tris.len()].iter().enumerate() {
                (0..3).for_each(|a| b.v[c][a][lane] = pos[v as usize][a]);
            }
        }
        let tmax = if i % 2 == 0 { f32::INFINITY } else { 1.5 };
        let (hit, redo, t) = TriRay::<T>::new(ray).block(&b, tmax);
        let mut ts = [0f32; 8];
        t.store(&mut ts);
        let p = Prepared::new(ray);
        for lane in (0..BLOCK).filter(|l| redo >> l & 1 == 0) {
            let want = intersect(&p, &b.triangle(lane), ray.tmin, tmax);
            assert_eq!((hit >> lane & 1 == 1).then_some(ts[lane]), want, "ray {i} lane {lane}");
            hits += want.is_some() as usize;
        }
    }
    assert!(hits > 100);
}

#[test]
fn block_triangle_test_equals_the_scalar_one() {
    assert_block_matches_intersect::<Scalar<BLOCK>>();
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        assert_block_matches_intersect::<super::lanes::Avx>();
    }
}

/// The filtered walk against brute force: the closest hit among those kept (a flagged
/// triangle's hit counts only where the filter keeps it), any-hit likewise, on every kernel;
/// the unfiltered queries on the flagged tree are those of the unflagged tree.
#[test]
fn filtered_queries_keep_only_what_the_filter_keeps() {
    let mut r = Rng::for_sample(15, 0, 0);
    let (pos, tris) = soup(&mut r, 3000, 5.0, 1.0);
    let flagged: Vec<bool> = (0..tris.len()).map(|i| i % 3 != 0).collect();
    // Keep a hit by a hash of (triangle, t): deterministic, and about half of them.
    let keep = |prim: u32, t: f32| (prim.wrapping_mul(0x9E37_79B9) ^ t.to_bits()).wrapping_mul(0x85EB_CA6B) >> 31 == 0;
    let mut rays = random_rays(&mut r, 20000, -7.0, 7.0);
    rays.extend(random_rays(&mut r, 2000, -7.0, 7.0).into_iter().map(|ray| Ray { tmin: 0.5, tmax: 4.0, ..ray }));
    let plain = Bvh::build(&pos, &tris);
    let (mut filtered_away, mut hits) = (0, 0);
    for k in Kernel::available() {
        let bvh = Bvh::build_flagged(&pos, &tris, Some(&flagged)).with_kernel(k);
        for (i, ray) in rays.iter().enumerate() {
            let mut want: Option<Hit> = None;
            for (p, t) in tris.iter().enumerate() {
                let tri = t.map(|v| pos[v as usize]);
                let Some(th) = intersect_triangle(ray, &tri) else { continue };
                if (!flagged[p] || keep(p as u32, th)) && want.is_none_or(|w| th < w.t) {
                    want = Some(Hit { t: th, prim: p as u32 });
                }
            }
            let got = bvh.closest_filtered(ray, keep);
            assert_eq!(got.map(|h| h.t), want.map(|h| h.t), "{k:?} ray {i}: {ray:?}");
            if let Some(h) = got {
                assert!(!flagged[h.prim as usize] || keep(h.prim, h.t), "{k:?} ray {i}: a filtered hit was returned");
            }
            assert_eq!(bvh.any_filtered(ray, keep), want.is_some(), "{k:?} ray {i}");
            assert_eq!(bvh.closest_filtered(ray, |_, _| true), bvh.closest(ray), "{k:?} ray {i}: keep-all filter");
            assert_eq!((bvh.closest(ray), bvh.any(ray)), (plain.closest(ray), plain.any(ray)), "{k:?} ray {i}: flags change the unfiltered walk");
            filtered_away += (plain.closest(ray).map(|h| h.t) != want.map(|h| h.t)) as usize;
            hits += want.is_some() as usize;
        }
    }
    assert!(hits > rays.len() / 4 && filtered_away > rays.len() / 20, "{hits} hits, {filtered_away} changed by the filter");
}

/// The parallel build gives the same tree, to the bit, on any number of threads (the bakes'
/// determinism across thread counts and executors rests on it); and the planned collapse fills
/// the wide nodes (greedy collapsing left them about half empty: 4.2 of 8 slots on the anchor).
#[test]
fn the_tree_is_the_same_on_any_thread_count_and_its_nodes_are_full() {
    let mut r = Rng::for_sample(15, 0, 0);
    let (pos, tris) = soup(&mut r, 30_000, 40.0, 1.5);
    let on = |t: usize| rayon::ThreadPoolBuilder::new().num_threads(t).build().unwrap().install(|| Bvh::build(&pos, &tris));
    let (a, b) = (on(1), on(3));
    let bits = |bvh: &Bvh| {
        let mut v: Vec<u32> = Vec::new();
        for n in &bvh.nodes {
            v.extend(n.planes.iter().flatten().map(|x| x.to_bits()));
            v.extend(n.child);
        }
        for t in &bvh.blocks {
            v.extend(t.v.iter().flatten().flatten().map(|x| x.to_bits()));
            v.extend(t.id);
        }
        v
    };
    assert!(bits(&a) == bits(&b), "1 and 3 threads built different trees");
    let slots: usize = a.nodes.iter().map(|n| (0..wide::WIDTH).filter(|&s| used(n, s)).count()).sum();
    let per_node = slots as f64 / a.nodes.len() as f64;
    assert!(per_node > 6.5, "{per_node:.2} of 8 slots used per node");
}

/// The slab test never drops a box the ray enters (its exact interval, in f64, is not empty),
/// and drops those it clearly misses, plain and AVX: boxes far from the origin, rays starting
/// on, just inside or just outside a face, tiny direction components.
fn assert_box_test_is_conservative<B: Lanes>() {
    let mut r = Rng::for_sample(21, 0, 0);
    let (mut kept, mut dropped) = (0, 0);
    for case in 0..40_000 {
        let scale = [1.0f32, 1e3, 1e5][case % 3];
        let centre = rand3(&mut r, -scale, scale);
        let mut n = wide::Wide::EMPTY;
        let mut boxes = [([0f32; 3], [0f32; 3]); 8];
        for (slot, b) in boxes.iter_mut().enumerate() {
            let half = rand3(&mut r, 0.0, scale * 0.01 + 0.5);
            let off = rand3(&mut r, -scale * 0.02 - 1.0, scale * 0.02 + 1.0);
            for k in 0..3 {
                b.0[k] = centre[k] + off[k] - half[k];
                b.1[k] = centre[k] + off[k] + half[k];
                n.planes[2 * k][slot] = b.0[k];
                n.planes[2 * k + 1][slot] = b.1[k];
            }
        }
        // The origin on a face of box 0, nudged by a few ulps either way, or anywhere near.
        let b0 = boxes[0];
        let mut o = [0, 1, 2].map(|k| b0.0[k] + (b0.1[k] - b0.0[k]) * r.next_f32());
        if case % 2 == 0 {
            let k = (r.next_u32() % 3) as usize;
            o[k] = if r.next_f32() < 0.5 { b0.0[k] } else { b0.1[k] };
            for _ in 0..r.next_u32() % 4 {
                o[k] = if r.next_f32() < 0.5 { o[k].next_up() } else { o[k].next_down() };
            }
        } else if case % 4 == 1 {
            o = rand3(&mut r, -scale, scale);
        }
        let mut dir = rand3(&mut r, -1.0, 1.0);
        if case % 5 == 0 {
            dir[(r.next_u32() % 3) as usize] *= 1e-6;
        }
        let ray = Ray { origin: o, dir, tmin: if case % 7 == 0 { 0.25 } else { 0.0 }, tmax: f32::INFINITY };
        let tcull = if case % 3 == 0 { 1e30 } else { scale * 0.05 };
        let (mask, _) = BoxRay::<B>::new(&ray).enter(&n, tcull);
        for (slot, b) in boxes.iter().enumerate() {
            let (mut lo, mut hi) = (ray.tmin as f64, tcull as f64);
            for k in 0..3 {
                let (a, c) = ((b.0[k] as f64 - o[k] as f64) / dir[k] as f64, (b.1[k] as f64 - o[k] as f64) / dir[k] as f64);
                lo = lo.max(a.min(c));
                hi = hi.min(a.max(c));
            }
            let got = mask >> slot & 1 == 1;
            if lo <= hi {
                assert!(got, "case {case} slot {slot}: a box the ray enters over [{lo}, {hi}] was dropped: {ray:?} {b:?}");
                kept += 1;
            } else if lo > hi + 1e-3 * (lo.abs() + hi.abs()) {
                assert!(!got, "case {case} slot {slot}: a box the ray misses ([{lo}, {hi}]) was kept: {ray:?} {b:?}");
                dropped += 1;
            }
        }
    }
    assert!(kept > 20_000 && dropped > 100_000, "kept {kept}, dropped {dropped}");
}

#[test]
fn box_test_keeps_every_box_the_ray_enters() {
    assert_box_test_is_conservative::<Scalar<8>>();
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        assert_box_test_is_conservative::<super::lanes::Avx>();
    }
}

/// Rays whose tmin lies a hair before a hit (found among the demo level's rays with tmin
/// moved up to 0.99999 of their hit): the triangle test puts the hit just after tmin, while the
/// box of the (pre-split) long triangle is left just before it. Boxes are culled against tmin
/// lowered by the cull slack, so the walk finds what the brute-force test finds.
#[test]
fn a_hit_just_after_tmin_is_found_as_brute_force_finds_it() {
    // The level's floor (60 m) and a sill (22 m), each flat in one axis: every box of their
    // (pre-split) parts is flat there, so its exit on that axis is where the ray crosses.
    let scenes = [
        (vec![[30.0, 0.0, 32.0], [30.0, 0.0, -28.0], [-30.0, 0.0, -28.0]], [9.28369, -0.07022603, 5.2010283], [-0.771693, 0.5272763, 0.35562572], 0.13318649),
        (vec![[-11.0, 0.3, 5.2], [11.0, -0.1, 5.2], [11.0, 0.3, 5.2]], [6.1339073, 0.0007133907, 5.185656], [0.77647173, 0.5564271, 0.2957711], 0.04849686),
    ];
    for (i, (pos, origin, dir, tmin)) in scenes.into_iter().enumerate() {
        let tris = vec![[0, 1, 2]];
        let ray = Ray { origin, dir, tmin, tmax: f32::INFINITY };
        let want = closest_brute(&pos, &tris, &ray);
        assert!(want.is_some_and(|h| h.t > ray.tmin), "scene {i}: the brute-force test hits after tmin");
        for k in Kernel::available() {
            let bvh = Bvh::build(&pos, &tris).with_kernel(k);
            assert_eq!(bvh.closest(&ray), want, "{k:?} scene {i}");
            assert!(bvh.any(&ray), "{k:?} scene {i}");
        }
    }
}
