//! Walking the wide tree: 8 child boxes per visit, 8 triangles per test. One generic source,
//! instantiated as the portable kernel (plain arrays) and, on x86_64 CPUs that have it, the AVX
//! kernel; both compute the same bits (see [`super::lanes`]), so results do not depend on it.
//!
//! Hit filters (any-hit programs, for alpha-tested surfaces) are a type parameter too: the
//! unfiltered walk is instantiated with [`Opaque`], whose filter code is compiled out, so it is
//! the walk it was before filters existed; a filtered walk asks the filter only about hits on
//! triangles flagged at build time, in leaves marked `child::FILTER`.

use super::lanes::{Lanes, Scalar};
use super::triangle::{intersect, Prepared, ROBUST};
use super::wide::{child, Tris, Wide, BLOCK, WIDTH};
use super::{stats, Bvh, Hit, Ray};
use std::mem::MaybeUninit;

/// Traversal stack entries. A visit pushes at most WIDTH - 1 and the build bounds the binary
/// depth (so the wide one) to 48 + 32 levels; the build checks its tree's actual need.
pub(super) const STACK: usize = (WIDTH - 1) * 80 + WIDTH;

/// Boxes are culled against the closest hit so far times this. A triangle's computed t can be
/// a few ulps under the true distance (a ray through a shared vertex on a box's corner gets
/// t = 0.9999999 from one triangle, 0.99999994 from its neighbour, box entry 1.0): without the
/// slack, the first found would hide the other and the closest hit would depend on the order
/// of the walk. Boxes entered that little behind the closest hit are rare: the cost is noise.
const CULL_SLACK: f32 = 1.0 + 1.0 / 4096.0;

/// The implementations the queries can run with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Kernel {
    Portable,
    #[cfg(target_arch = "x86_64")]
    Avx,
}

impl Kernel {
    /// Every kernel this CPU can run, the fastest last.
    pub(super) fn available() -> Vec<Kernel> {
        let mut k = vec![Kernel::Portable];
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") && std::arch::is_x86_feature_detected!("popcnt") {
            k.push(Kernel::Avx);
        }
        k
    }
}

/// What a walk does with a hit on a flagged triangle.
pub(super) trait AnyHit {
    /// False: no triangle is ever filtered; the checks are compiled out.
    const ACTIVE: bool;
    /// Whether the hit on triangle `prim` at distance `t` counts (false: the ray goes on).
    fn keep(&self, prim: u32, t: f32) -> bool;
}

/// Every hit counts: the unfiltered walk.
pub(super) struct Opaque;

impl AnyHit for Opaque {
    const ACTIVE: bool = false;
    #[inline(always)]
    fn keep(&self, _: u32, _: f32) -> bool {
        true
    }
}

/// Hits on flagged triangles count where the closure says so.
pub(super) struct Filtered<F>(pub(super) F);

impl<F: Fn(u32, f32) -> bool> AnyHit for Filtered<F> {
    const ACTIVE: bool = true;
    #[inline]
    fn keep(&self, prim: u32, t: f32) -> bool {
        (self.0)(prim, t)
    }
}

pub(super) fn closest<F: AnyHit>(bvh: &Bvh, ray: &Ray, filter: &F) -> Option<Hit> {
    match bvh.kernel {
        Kernel::Portable => walk::<Scalar<WIDTH>, true, F>(bvh, ray, filter),
        // SAFETY: `Bvh` only holds a kernel that `Kernel::available` listed.
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx => unsafe { avx::walk::<true, F>(bvh, ray, filter) },
    }
}

pub(super) fn any<F: AnyHit>(bvh: &Bvh, ray: &Ray, filter: &F) -> bool {
    match bvh.kernel {
        Kernel::Portable => walk::<Scalar<WIDTH>, false, F>(bvh, ray, filter),
        // SAFETY: as in `closest`.
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx => unsafe { avx::walk::<false, F>(bvh, ray, filter) },
    }
    .is_some()
}

#[cfg(target_arch = "x86_64")]
mod avx {
    use super::super::lanes::Avx;
    use super::{AnyHit, Bvh, Hit, Ray};

    /// # Safety
    /// The CPU must have AVX and POPCNT.
    #[target_feature(enable = "avx,popcnt")]
    pub(super) unsafe fn walk<const CLOSEST: bool, F: AnyHit>(bvh: &Bvh, ray: &Ray, filter: &F) -> Option<Hit> {
        super::walk::<Avx, CLOSEST, F>(bvh, ray, filter)
    }
}

/// Per-ray constants of the box test, broadcast to the lanes.
pub(super) struct BoxRay<B> {
    org: [B; 3],
    inv: [B; 3],
    /// `inv` times ROBUST, for the far planes.
    inv_far: [B; 3],
    /// Plane indices (see `Wide::planes`) of the near and far side per axis: the box's max is
    /// the near side where the direction is negative (sign bit, so -0 counts as negative).
    near: [usize; 3],
    far: [usize; 3],
    tmin: B,
}

// No `array::map` or closures over lanes in this file's hot code: those are not inlined into the
// AVX kernel, and an intrinsic outside it becomes a function call per operation.
impl<B: Lanes> BoxRay<B> {
    #[inline(always)]
    pub(super) fn new(ray: &Ray) -> Self {
        let (o, d) = (ray.origin, ray.dir);
        let neg = [d[0].is_sign_negative() as usize, d[1].is_sign_negative() as usize, d[2].is_sign_negative() as usize];
        // IEEE infinities handle zero components.
        let inv = [1.0 / d[0], 1.0 / d[1], 1.0 / d[2]];
        BoxRay {
            org: [B::splat(o[0]), B::splat(o[1]), B::splat(o[2])],
            inv: [B::splat(inv[0]), B::splat(inv[1]), B::splat(inv[2])],
            // The far distance is widened by ROBUST (pbrt's bound: gamma(3) covers the subtraction,
            // the reciprocal and the product), so rounding never culls a real hit. Folding it into
            // the reciprocal rounds once more, which the bound's factor 2 leaves room for.
            inv_far: [B::splat(inv[0] * ROBUST), B::splat(inv[1] * ROBUST), B::splat(inv[2] * ROBUST)],
            near: [neg[0], 2 + neg[1], 4 + neg[2]],
            far: [1 - neg[0], 3 - neg[1], 5 - neg[2]],
            // Lowered by the cull slack, as tmax is raised: a triangle's computed t can lie a few
            // ulps beyond its box's computed exit, so a box left just before tmin can still
            // hold a hit the triangle test puts just after it.
            tmin: B::splat(if ray.tmin > 0.0 { ray.tmin / CULL_SLACK } else { ray.tmin * CULL_SLACK }),
        }
    }

    /// Slab test of the 8 child boxes: (mask of those the ray overlaps within (tmin, tcull),
    /// their entry distances). A NaN (origin on a slab plane, direction 0 on that axis) leaves
    /// the bound as it was, which keeps the box: conservative.
    #[inline(always)]
    pub(super) fn enter(&self, n: &Wide, tcull: f32) -> (u32, B) {
        const { assert!(B::N == WIDTH) };
        let mut lo = self.tmin;
        let mut hi = B::splat(tcull);
        for k in 0..3 {
            // SAFETY: plane indices are below 6, and a plane holds WIDTH = B::N floats.
            let (pn, pf) = unsafe {
                (B::load(n.planes.get_unchecked(self.near[k]).as_ptr()), B::load(n.planes.get_unchecked(self.far[k]).as_ptr()))
            };
            let t0 = pn.sub(self.org[k]).mul(self.inv[k]);
            let t1 = pf.sub(self.org[k]).mul(self.inv_far[k]);
            lo = t0.max(lo);
            hi = t1.min(hi);
        }
        (lo.le(hi).bits(), lo)
    }
}

/// Per-ray constants of the triangle test, broadcast to the lanes.
pub(super) struct TriRay<T> {
    /// Origin and shear in the permuted frame of [`Prepared`].
    org: [T; 3],
    shear: [T; 3],
    tmin: T,
    robust: T,
    /// For the lanes redone in scalar.
    scalar: Prepared,
}

impl<T: Lanes> TriRay<T> {
    #[inline(always)]
    pub(super) fn new(ray: &Ray) -> Self {
        let p = Prepared::new(ray);
        let [kx, ky, kz] = p.k;
        let [sx, sy, sz] = p.shear;
        TriRay {
            org: [T::splat(p.org[kx]), T::splat(p.org[ky]), T::splat(p.org[kz])],
            shear: [T::splat(sx), T::splat(sy), T::splat(sz)],
            tmin: T::splat(p.tmin),
            robust: T::splat(ROBUST),
            scalar: p,
        }
    }

    /// The watertight test of `intersect` on a block of triangles, operation for operation (so the same
    /// t to the bit): (mask of hits with tmin < t < tmax, mask of lanes to redo with
    /// `intersect`, t per lane). The lanes to redo are those where an edge function came out
    /// exactly zero, which `intersect` recomputes in f64; they are left out of the hits.
    #[inline(always)]
    pub(super) fn block(&self, b: &Tris, tmax: f32) -> (u32, u32, T) {
        const { assert!(T::N == BLOCK) };
        let [kx, ky, kz] = self.scalar.k;
        let [ox, oy, oz] = self.org;
        // SAFETY: k is a permutation of 0..3; each axis row holds BLOCK = T::N floats.
        let load = |c: usize, k: usize| unsafe { T::load(b.v[c].get_unchecked(k).as_ptr()) };
        let (a, bb, c) = (
            [load(0, kx).sub(ox), load(0, ky).sub(oy), load(0, kz).sub(oz)],
            [load(1, kx).sub(ox), load(1, ky).sub(oy), load(1, kz).sub(oz)],
            [load(2, kx).sub(ox), load(2, ky).sub(oy), load(2, kz).sub(oz)],
        );
        let [sx, sy, sz] = self.shear;
        let (ax, ay) = (a[0].sub(sx.mul(a[2])), a[1].sub(sy.mul(a[2])));
        let (bx, by) = (bb[0].sub(sx.mul(bb[2])), bb[1].sub(sy.mul(bb[2])));
        let (cx, cy) = (c[0].sub(sx.mul(c[2])), c[1].sub(sy.mul(c[2])));
        let u = cx.mul(by).sub(cy.mul(bx));
        let v = ax.mul(cy).sub(ay.mul(cx));
        let w = bx.mul(ay).sub(by.mul(ax));
        let zero = T::splat(0.0);
        let redo = u.eq(zero).or(v.eq(zero)).or(w.eq(zero));
        // Mixed signs: `intersect`'s any-negative-and-any-positive, as min < 0 < max. They differ
        // only where one of u, v, w is NaN, and such a lane fails below anyway (det and t NaN).
        let outside = u.min(v).min(w).lt(zero).and(u.max(v).max(w).gt(zero));
        let det = u.add(v).add(w);
        let t_scaled = sz.mul(u.mul(a[2]).add(v.mul(bb[2])).add(w.mul(c[2])));
        // Negating both when det < 0 is flipping their sign bits by det's.
        let sign = det.and(T::splat(-0.0));
        let (ts, d) = (t_scaled.xor(sign), det.xor(sign));
        // `intersect`'s early outs (det == 0, ts <= tmin d, ts > tmax d ROBUST), then its final
        // strict interval, as one mask. Most tests of a block find nothing: those return before
        // the division.
        let inside = ts.gt(self.tmin.mul(d)).and(ts.le(T::splat(tmax).mul(d).mul(self.robust)));
        let maybe = inside.and_not(outside).and_not(redo).and_not(det.eq(zero));
        if maybe.bits() | redo.bits() == 0 {
            return (0, 0, zero);
        }
        let t = ts.div(d);
        let hit = maybe.and(t.gt(self.tmin)).and(t.lt(T::splat(tmax)));
        (hit.bits(), redo.bits(), t)
    }
}

/// Depth-first walk. CLOSEST: the closest hit, children visited nearest first and subtrees
/// behind the closest hit so far skipped. Otherwise (shadow rays) the first hit found, in no
/// particular order; `Some` with any t then. Hits on flagged triangles count only where
/// `filter` keeps them (so the closest hit is the closest kept one, whatever the order of the
/// walk, as long as the filter's answer depends only on the triangle and t).
#[inline(always)]
fn walk<L: Lanes, const CLOSEST: bool, F: AnyHit>(bvh: &Bvh, ray: &Ray, filter: &F) -> Option<Hit> {
    let br = BoxRay::<L>::new(ray);
    let tr = TriRay::<L>::new(ray);
    let mut tmax = ray.tmax;
    let mut tcull = tmax * CULL_SLACK;
    let mut best = u32::MAX;
    // Entries (child reference, entry distance). Uninitialised: only slots below `sp` are read.
    let mut stack = [MaybeUninit::<(u32, f32)>::uninit(); STACK];
    let mut sp = 0usize;
    // SAFETY (the unchecked accesses below): the build makes every child reference valid and
    // checks that its tree needs fewer than STACK entries (a visit pushes every hit child but
    // the one it goes on with, momentarily that one too).
    macro_rules! push {
        ($e:expr) => {{
            unsafe { stack.get_unchecked_mut(sp).write($e) };
            sp += 1;
        }};
    }
    let mut cur = 0u32;
    'walk: loop {
        if cur & child::LEAF == 0 {
            let n = unsafe { bvh.nodes.get_unchecked(cur as usize) };
            stats::add(WIDTH as u64, 0);
            let (mut hit, tn) = br.enter(n, tcull);
            // Fetch every child the ray enters at once: a walk is a chain of dependent loads,
            // and the blocks (most of the memory) mostly come from beyond L2; issuing them
            // together overlaps their latencies instead of paying them one after the other.
            let mut m = hit;
            while m != 0 {
                let c = n.child[m.trailing_zeros() as usize];
                m &= m - 1;
                if c & child::LEAF != 0 {
                    prefetch(unsafe { bvh.blocks.as_ptr().add(child::block(c)) });
                } else {
                    prefetch(unsafe { bvh.nodes.as_ptr().add(c as usize) });
                }
            }
            if hit != 0 {
                let i = hit.trailing_zeros() as usize;
                hit &= hit - 1;
                if hit == 0 || !CLOSEST {
                    // One child, or a shadow ray: go on with the first, push the others.
                    while hit != 0 {
                        push!((n.child[hit.trailing_zeros() as usize], 0.0));
                        hit &= hit - 1;
                    }
                    cur = n.child[i];
                    continue;
                }
                let mut t = [0f32; 8];
                tn.store(&mut t);
                let j = hit.trailing_zeros() as usize;
                hit &= hit - 1;
                if hit == 0 {
                    let (near, far) = if t[j] < t[i] { (j, i) } else { (i, j) };
                    push!((n.child[far], t[far]));
                    cur = n.child[near];
                    continue;
                }
                // Three or more: each goes to its rank in distance order, the farthest deepest
                // (ties: the higher lane deeper, as above), so the nearest ends on top. Counting ranks with
                // lane compares needs no branch per entry, unlike sorting them.
                let all = hit | 1 << i | 1 << j;
                let mut m = all;
                while m != 0 {
                    let l = m.trailing_zeros() as usize;
                    m &= m - 1;
                    let tl = L::splat(t[l]);
                    let deeper = tn.gt(tl).bits() | tn.eq(tl).bits() & u32::MAX << l << 1;
                    let rank = (deeper & all).count_ones() as usize;
                    unsafe { stack.get_unchecked_mut(sp + rank).write((n.child[l], t[l])) };
                }
                sp += all.count_ones() as usize - 1;
                cur = unsafe { stack.get_unchecked(sp).assume_init().0 };
                continue;
            }
        } else {
            if leaf::<_, CLOSEST, F>(&tr, ray, bvh, cur, filter, &mut tmax, &mut best) {
                return Some(Hit { t: tmax, prim: best });
            }
            tcull = tmax * CULL_SLACK;
        }
        // Pop the next subtree still in front of the closest hit so far.
        while sp > 0 {
            sp -= 1;
            let (c, tenter) = unsafe { stack.get_unchecked(sp).assume_init() };
            if tenter <= tcull {
                cur = c;
                continue 'walk;
            }
        }
        break;
    }
    (best != u32::MAX).then_some(Hit { t: tmax, prim: best })
}

/// Tests the leaf block `cur`. CLOSEST: lowers `tmax` to the closest hit kept and sets `best`
/// to its triangle; of hits at the same distance, the highest triangle index wins, so the hit
/// is a function of the geometry alone, not of the tree or the order of the walk (coplanar
/// faces, such as a box standing on a floor, give exact ties). Otherwise: true if a hit is kept
/// (its t and triangle then in `tmax` and `best`), and the walk can stop.
#[inline(always)]
fn leaf<T: Lanes, const CLOSEST: bool, F: AnyHit>(tr: &TriRay<T>, ray: &Ray, bvh: &Bvh, cur: u32, filter: &F, tmax: &mut f32, best: &mut u32) -> bool {
    let blk = child::block(cur);
    // SAFETY: the build makes every leaf reference a valid block index.
    let b = unsafe { bvh.blocks.get_unchecked(blk) };
    stats::add(0, BLOCK as u64);
    // Closest: up to and including tmax, for the ties (`next_up`: the tests' bound is strict).
    let bound = if CLOSEST { tmax.next_up() } else { *tmax };
    let (hit, redo, t) = tr.block(b, bound);
    // The other half of a shared block is another leaf's: its lanes are dropped.
    let own = child::lanes(cur);
    let (mut hit, redo) = (hit & own, redo & own);
    if hit | redo == 0 {
        return false;
    }
    let mut ts = [0f32; 8];
    t.store(&mut ts);
    let mut r = redo;
    while r != 0 {
        let lane = r.trailing_zeros() as usize;
        r &= r - 1;
        if let Some(th) = intersect(&tr.scalar, &b.triangle(lane), ray.tmin, bound) {
            ts[lane] = th;
            hit |= 1 << lane;
        }
    }
    // Lanes whose hits the filter decides (none unless F filters and the leaf is marked).
    let flagged = if F::ACTIVE && cur & child::FILTER != 0 { unsafe { *bvh.filter_lanes.get_unchecked(blk) as u32 } } else { 0 };
    if !CLOSEST {
        let mut m = hit & flagged;
        while m != 0 {
            let lane = m.trailing_zeros() as usize;
            m &= m - 1;
            if !filter.keep(b.id[lane], ts[lane]) {
                hit &= !(1 << lane);
            }
        }
        if hit != 0 {
            let lane = hit.trailing_zeros() as usize;
            (*tmax, *best) = (ts[lane], b.id[lane]);
            return true;
        }
        return false;
    }
    // Lowest t, the highest triangle index on a tie (never the ray's own tmax: best is u32::MAX
    // until a hit is kept). A flagged lane is asked only when it would be the closest so far.
    while hit != 0 {
        let lane = hit.trailing_zeros() as usize;
        hit &= hit - 1;
        let id = b.id[lane];
        if (ts[lane] < *tmax || ts[lane] == *tmax && id > *best) && (flagged >> lane & 1 == 0 || filter.keep(id, ts[lane])) {
            *tmax = ts[lane];
            *best = id;
        }
    }
    false
}

/// Asks for every cache line of `*p` (no effect on results; a no-op off x86_64).
#[inline(always)]
fn prefetch<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let bytes = p.cast::<i8>();
        let mut at = 0;
        while at < std::mem::size_of::<T>() {
            // SAFETY: prefetching never faults, whatever the address.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(bytes.wrapping_add(at)) };
            at += 64;
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}
