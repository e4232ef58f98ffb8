//! The scene's analytic lights, indexed by where they can reach.
//!
//! Next-event estimation tries every light that can light a point. A level of many rooms has a
//! light or more per room, each with a `range` beyond which glTF's window makes it exactly zero;
//! walking all of them at every path vertex made the bake's cost per texel grow with the level
//! (35 % of a 100k-triangle level's bake went to `Light::sample` of lights out of range). So the
//! lights with a range sit in a small tree of their spheres of influence, and a query visits only
//! the spheres that hold the point; the others (the sun, rect lights, lights without a range)
//! are tried everywhere. Skipping a light whose window is zero changes no estimate.
//!
//! Each light's sample numbers are drawn from a key the point's stream gives once
//! ([`LightSet::key`]), hashed with the light's index ([`light_numbers`]), so a light gets the same
//! numbers whichever others are near, and the stream after the lights stays aligned.

use super::lights::Light;
use super::sampling::*;

pub struct LightSet {
    lights: Vec<Light>,
    /// Indices of the lights that reach everywhere, in order.
    everywhere: Vec<u32>,
    /// Indices of the rect lights: the lights a ray can cross.
    rects: Vec<u32>,
    /// Bounding boxes of the ranged lights' spheres, as a binary tree (root first).
    nodes: Vec<Node>,
    /// Ranged lights in the tree's leaf order: (index, centre, range squared).
    ranged: Vec<(u32, V3, f32)>,
}

/// A box over a run of `ranged` (`count` > 0) or over two children at `first`, `first + 1`.
struct Node {
    lo: V3,
    hi: V3,
    first: u32,
    count: u32,
}

/// Ranged lights per leaf, at most.
const LEAF: usize = 2;

impl LightSet {
    pub fn new(lights: Vec<Light>) -> LightSet {
        let mut everywhere = Vec::new();
        let mut ranged = Vec::new();
        for (i, l) in lights.iter().enumerate() {
            match *l {
                Light::Point { pos, range: Some(r), .. } | Light::Spot { pos, range: Some(r), .. } if r.is_finite() => ranged.push((i as u32, pos, r * r)),
                _ => everywhere.push(i as u32),
            }
        }
        let rects = lights.iter().enumerate().filter(|(_, l)| matches!(l, Light::Rect { .. })).map(|(i, _)| i as u32).collect();
        let mut set = LightSet { lights, everywhere, rects, nodes: Vec::new(), ranged };
        if !set.ranged.is_empty() {
            set.nodes.push(Node { lo: [0.0; 3], hi: [0.0; 3], first: 0, count: 0 });
            set.build(0, 0, set.ranged.len());
        }
        set
    }

    /// Node `at` over `ranged[start..end]`: median split on the widest axis of the centres.
    fn build(&mut self, at: usize, start: usize, end: usize) {
        let run = &mut self.ranged[start..end];
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        let (mut clo, mut chi) = (lo, hi);
        for &(_, c, r2) in run.iter() {
            let r = r2.sqrt();
            for a in 0..3 {
                (lo[a], hi[a]) = (lo[a].min(c[a] - r), hi[a].max(c[a] + r));
                (clo[a], chi[a]) = (clo[a].min(c[a]), chi[a].max(c[a]));
            }
        }
        if run.len() <= LEAF {
            self.nodes[at] = Node { lo, hi, first: start as u32, count: run.len() as u32 };
            return;
        }
        let axis = (0..3).max_by(|&a, &b| (chi[a] - clo[a]).total_cmp(&(chi[b] - clo[b]))).unwrap();
        // Ties broken by index: the tree depends on the lights alone.
        run.sort_by(|x, y| x.1[axis].total_cmp(&y.1[axis]).then(x.0.cmp(&y.0)));
        let mid = start + run.len() / 2;
        let first = self.nodes.len();
        self.nodes[at] = Node { lo, hi, first: first as u32, count: 0 };
        self.nodes.push(Node { lo, hi, first: 0, count: 0 });
        self.nodes.push(Node { lo, hi, first: 0, count: 0 });
        self.build(first, start, mid);
        self.build(first + 1, mid, end);
    }

    pub fn all(&self) -> &[Light] {
        &self.lights
    }

    /// The rect lights (a ray may cross them), in index order.
    pub fn rects(&self) -> impl Iterator<Item = &Light> {
        self.rects.iter().map(|&i| &self.lights[i as usize])
    }

    /// `f(index, light)` for every light that may light `x`: those that reach everywhere, in
    /// index order, then the ranged ones whose sphere holds `x`, in the tree's order (fixed by
    /// the lights, so sums over them are the same on every run).
    pub fn near(&self, x: V3, mut f: impl FnMut(usize, &Light)) {
        for &i in &self.everywhere {
            f(i as usize, &self.lights[i as usize]);
        }
        if self.nodes.is_empty() {
            return;
        }
        let mut stack = [0u32; 64];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = &self.nodes[stack[top] as usize];
            if (0..3).any(|a| x[a] < node.lo[a] || x[a] > node.hi[a]) {
                continue;
            }
            if node.count > 0 {
                for &(i, c, r2) in &self.ranged[node.first as usize..(node.first + node.count) as usize] {
                    let d = sub(x, c);
                    if dot(d, d) < r2 {
                        f(i as usize, &self.lights[i as usize]);
                    }
                }
            } else {
                // Second child pushed first: the walk visits the lower half first.
                stack[top] = node.first + 1;
                stack[top + 1] = node.first;
                top += 2;
            }
        }
    }

    /// The key a point's stream gives for its light samples (one draw pair, whatever is near).
    pub fn key(rng: &mut Rng) -> u64 {
        ((rng.next_u32() as u64) << 32) | rng.next_u32() as u64
    }
}

/// The two sample numbers in [0, 1) of light `i` under `key`.
pub fn light_numbers(key: u64, i: usize) -> (f32, f32) {
    let h = mix(key ^ mix(i as u64));
    ((h >> 40) as f32 * (1.0 / 16_777_216.0), ((h >> 16) & 0xFF_FFFF) as f32 * (1.0 / 16_777_216.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(pos: V3, range: Option<f32>) -> Light {
        Light::Point { pos, i: [1.0; 3], range }
    }

    /// `near` visits exactly the lights whose window is not zero at x (every unranged light, the
    /// ranged ones strictly inside their range), each once; the same order on every query.
    #[test]
    fn near_visits_the_lights_in_range_and_no_others() {
        let mut rng = Rng::for_sample(7, 0, 0);
        let mut u = || rng.next_f32();
        let mut lights = vec![Light::Sun { dir: [0.0, -1.0, 0.0], e: [1.0; 3], cos_max: 0.99 }];
        for k in 0..300 {
            let pos = [100.0 * u(), 10.0 * u(), 100.0 * u()];
            lights.push(point(pos, if k % 10 == 0 { None } else { Some(1.0 + 9.0 * u()) }));
        }
        lights.push(Light::Rect { c: [0.0; 3], n: [0.0, -1.0, 0.0], hu: [1.0, 0.0, 0.0], hv: [0.0, 0.0, 1.0], l: [1.0; 3] });
        let set = LightSet::new(lights.clone());
        assert_eq!(set.rects().count(), 1);
        let mut visited_ranged = 0;
        for _ in 0..2000 {
            let x = [110.0 * u() - 5.0, 14.0 * u() - 2.0, 110.0 * u() - 5.0];
            let mut got = Vec::new();
            set.near(x, |i, _| got.push(i));
            let mut again = Vec::new();
            set.near(x, |i, _| again.push(i));
            assert_eq!(got, again);
            let mut want: Vec<usize> = (0..lights.len())
                .filter(|&i| match lights[i] {
                    Light::Point { pos, range: Some(r), .. } => dot(sub(x, pos), sub(x, pos)) < r * r,
                    _ => true,
                })
                .collect();
            visited_ranged += got.len() - 31;
            got.sort();
            want.sort();
            assert_eq!(got, want, "at {x:?}");
        }
        assert!(visited_ranged > 500, "the test points fall in some ranges: {visited_ranged}");
    }

    #[test]
    fn light_numbers_are_uniform_and_differ_per_light() {
        let n = 100_000;
        let (mut s1, mut s2, mut same) = (0.0f64, 0.0f64, 0);
        for k in 0..n {
            let key = mix(k);
            let (a, b) = light_numbers(key, 3);
            let (c, _) = light_numbers(key, 4);
            assert!((0.0..1.0).contains(&a) && (0.0..1.0).contains(&b));
            (s1, s2) = (s1 + a as f64, s2 + (a as f64 - 0.5) * (b as f64 - 0.5));
            same += (a == c) as u32;
        }
        assert!((s1 / n as f64 - 0.5).abs() < 0.005, "mean {}", s1 / n as f64);
        assert!((s2 / n as f64).abs() < 0.002, "u1, u2 correlated: {}", s2 / n as f64);
        assert!(same < 5);
    }
}
