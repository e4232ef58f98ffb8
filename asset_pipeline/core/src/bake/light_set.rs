//! The scene's analytic lights, indexed by where they can reach.
//!
//! Next-event estimation tries every light that can light a point. A level of many rooms has a
//! light or more per room, each with a `range` beyond which glTF's window makes it exactly zero;
//! walking all of them at every path vertex made the bake's cost per texel grow with the level
//! (35 % of a 100k-triangle level's bake went to `Light::sample` of lights out of range). So the
//! lights with a range are binned in a uniform grid over their spheres of influence, and a query
//! tries only the lights of the point's cell; the others (the sun, rect lights, lights without
//! a range) are tried everywhere. Skipping a light whose window is zero changes no estimate.
//! (A tree of the spheres came first: its walk, at every bounce vertex, was 9 % of the
//! 1M-triangle benchmark level's bake. The grid answers in one cell; the lights keep the tree's
//! order, a recursive median split, so the bake's sums and picks are the same bits.)
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
    /// Ranged lights in visiting order: (index, centre, range squared).
    ranged: Vec<(u32, V3, f32)>,
    grid: Grid,
}

/// A uniform grid over the ranged lights' spheres: cell c holds the positions in `ranged` of
/// the lights whose (slightly padded) sphere box overlaps it, ascending, at
/// `items[start[c]..start[c + 1]]`.
#[derive(Default)]
struct Grid {
    lo: V3,
    inv_cell: f32,
    dims: [u32; 3],
    start: Vec<u32>,
    items: Vec<u32>,
}

/// Grid cells per ranged light, about: a room's light then covers a few cells and a cell holds
/// the few lights around it.
const CELLS_PER_LIGHT: f32 = 8.0;
/// The most cell entries (light x cell) and cells the grid may hold; coarser cells beyond.
const MAX_ENTRIES: usize = 1 << 24;
const MAX_CELLS: usize = 1 << 22;

impl Grid {
    fn new(ranged: &[(u32, V3, f32)]) -> Grid {
        if ranged.is_empty() {
            return Grid::default();
        }
        // Boxes padded by a millionth of their size: a point strictly inside a sphere lands in
        // one of its cells whatever the rounding of c - r and c + r.
        let boxes: Vec<(V3, V3)> = ranged
            .iter()
            .map(|&(_, c, r2)| {
                let r = r2.sqrt();
                let pad = 1e-6 * (r + c.iter().fold(0.0f32, |m, v| m.max(v.abs())));
                (c.map(|v| v - r - pad), c.map(|v| v + r + pad))
            })
            .collect();
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for (a, b) in &boxes {
            for k in 0..3 {
                (lo[k], hi[k]) = (lo[k].min(a[k]), hi[k].max(b[k]));
            }
        }
        let ext = sub(hi, lo).map(|e| e.max(1e-6));
        let mut cell = (ext[0] * ext[1] * ext[2] / (CELLS_PER_LIGHT * ranged.len() as f32)).cbrt().max(ext[0].max(ext[1]).max(ext[2]) / 1024.0);
        loop {
            let inv_cell = 1.0 / cell;
            let dims = ext.map(|e| ((e * inv_cell).ceil() as u32).clamp(1, 1024));
            let grid = Grid { lo, inv_cell, dims, start: Vec::new(), items: Vec::new() };
            let spans: Vec<[(u32, u32); 3]> = boxes.iter().map(|(a, b)| std::array::from_fn(|k| (grid.coord(a, k), grid.coord(b, k)))).collect();
            let entries: usize = spans.iter().map(|s| s.iter().map(|&(a, b)| (b - a + 1) as usize).product::<usize>()).sum();
            let cells: usize = dims.iter().map(|&d| d as usize).product();
            // (One cell holds every light once: the coarsest grid, taken whatever its size.)
            if (entries > MAX_ENTRIES || cells > MAX_CELLS) && dims != [1, 1, 1] {
                cell *= 2.0;
                continue;
            }
            return grid.fill(&spans);
        }
    }

    /// The cell coordinate of `p` on axis k, clamped into the grid.
    fn coord(&self, p: &V3, k: usize) -> u32 {
        (((p[k] - self.lo[k]) * self.inv_cell).max(0.0) as u32).min(self.dims[k] - 1)
    }

    fn cell(&self, p: &V3) -> usize {
        let [x, y, z] = [0, 1, 2].map(|k| self.coord(p, k) as usize);
        (z * self.dims[1] as usize + y) * self.dims[0] as usize + x
    }

    /// Counting sort of (cell, light position) pairs: each cell's lights ascending.
    fn fill(mut self, spans: &[[(u32, u32); 3]]) -> Grid {
        let cells = self.dims.iter().map(|&d| d as usize).product::<usize>();
        let each = |f: &mut dyn FnMut(usize, u32)| {
            for (j, s) in spans.iter().enumerate() {
                for z in s[2].0..=s[2].1 {
                    for y in s[1].0..=s[1].1 {
                        for x in s[0].0..=s[0].1 {
                            f((z as usize * self.dims[1] as usize + y as usize) * self.dims[0] as usize + x as usize, j as u32);
                        }
                    }
                }
            }
        };
        let mut count = vec![0u32; cells + 1];
        each(&mut |c, _| count[c + 1] += 1);
        for c in 0..cells {
            count[c + 1] += count[c];
        }
        let mut items = vec![0u32; count[cells] as usize];
        let mut next = count.clone();
        each(&mut |c, j| {
            items[next[c] as usize] = j;
            next[c] += 1;
        });
        self.start = count;
        self.items = items;
        self
    }

    /// The positions in `ranged` of the lights that may reach `p`, ascending.
    fn at(&self, p: &V3) -> &[u32] {
        if self.items.is_empty() {
            return &[];
        }
        let c = self.cell(p);
        &self.items[self.start[c] as usize..self.start[c + 1] as usize]
    }
}

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
        median_order(&mut ranged);
        let grid = Grid::new(&ranged);
        LightSet { lights, everywhere, rects, ranged, grid }
    }

    pub fn all(&self) -> &[Light] {
        &self.lights
    }

    /// The rect lights (a ray may cross them), in index order.
    pub fn rects(&self) -> impl Iterator<Item = &Light> {
        self.rects.iter().map(|&i| &self.lights[i as usize])
    }

    /// `f(index, light)` for every light that may light `x`: those that reach everywhere, in
    /// index order, then the ranged ones whose sphere holds `x`, in `median_order` (fixed by the
    /// lights, so sums over them are the same on every run).
    pub fn near(&self, x: V3, mut f: impl FnMut(usize, &Light)) {
        for &i in &self.everywhere {
            f(i as usize, &self.lights[i as usize]);
        }
        for &j in self.grid.at(&x) {
            let (i, c, r2) = self.ranged[j as usize];
            let d = sub(x, c);
            if dot(d, d) < r2 {
                f(i as usize, &self.lights[i as usize]);
            }
        }
    }

    /// The key a point's stream gives for its light samples (one draw pair, whatever is near).
    pub fn key(rng: &mut Rng) -> u64 {
        ((rng.next_u32() as u64) << 32) | rng.next_u32() as u64
    }
}

/// The order ranged lights are visited in: a recursive median split on the widest axis of
/// their centres, lower half first (ties by index: the order depends on the lights alone). Kept
/// from the tree the lights were once walked in, so bakes stay the same bits.
fn median_order(run: &mut [(u32, V3, f32)]) {
    if run.len() <= 2 {
        return;
    }
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for &(_, c, _) in run.iter() {
        for a in 0..3 {
            (lo[a], hi[a]) = (lo[a].min(c[a]), hi[a].max(c[a]));
        }
    }
    let axis = (0..3).max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b]))).unwrap();
    run.sort_by(|x, y| x.1[axis].total_cmp(&y.1[axis]).then(x.0.cmp(&y.0)));
    let mid = run.len() / 2;
    let (a, b) = run.split_at_mut(mid);
    median_order(a);
    median_order(b);
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
    /// ranged ones strictly inside their range), each once, in one fixed order (the unranged in
    /// index order, then the ranged in `median_order`): points in and out of the grid, on cell
    /// edges, in a light with a range as big as the level and in tiny ones.
    #[test]
    fn near_visits_the_lights_in_range_and_no_others() {
        let mut rng = Rng::for_sample(7, 0, 0);
        let mut u = || rng.next_f32();
        let mut lights = vec![Light::Sun { dir: [0.0, -1.0, 0.0], e: [1.0; 3], cos_max: 0.99 }];
        for k in 0..300 {
            let pos = [100.0 * u(), 10.0 * u(), 100.0 * u()];
            let range = match k % 10 {
                0 => None,
                1 => Some(0.01 + 0.1 * u()),
                _ => Some(1.0 + 9.0 * u()),
            };
            lights.push(point(pos, range));
        }
        lights.push(point([50.0, 5.0, 50.0], Some(80.0)));
        lights.push(Light::Rect { c: [0.0; 3], n: [0.0, -1.0, 0.0], hu: [1.0, 0.0, 0.0], hv: [0.0, 0.0, 1.0], l: [1.0; 3] });
        let set = LightSet::new(lights.clone());
        assert_eq!(set.rects().count(), 1);
        // Brute force in the documented order.
        let order: Vec<usize> = set.everywhere.iter().map(|&i| i as usize).chain(set.ranged.iter().map(|r| r.0 as usize)).collect();
        let mut sorted = order.clone();
        sorted.sort();
        assert_eq!(sorted, (0..lights.len()).collect::<Vec<_>>(), "every light once");
        let in_range = |i: usize, x: V3| match lights[i] {
            Light::Point { pos, range: Some(r), .. } => dot(sub(x, pos), sub(x, pos)) < r * r,
            _ => true,
        };
        let mut points: Vec<V3> = (0..3000).map(|_| [160.0 * u() - 30.0, 40.0 * u() - 15.0, 160.0 * u() - 30.0]).collect();
        // Near the tiny lights, on the grid's cell edges, far outside.
        for i in 0..lights.len() {
            if let Light::Point { pos, range: Some(r), .. } = lights[i] {
                points.push(add(pos, [0.9 * r, 0.0, 0.0]));
                points.push(add(pos, [0.0, -0.99 * r, 0.0]));
            }
        }
        let g = &set.grid;
        points.extend((0..50).map(|k| [g.lo[0] + k as f32 / g.inv_cell, g.lo[1] + 1.0 / g.inv_cell, g.lo[2] + 2.0 / g.inv_cell]));
        points.extend([[1e6, 0.0, 0.0], [-1e6, -1e6, -1e6], [f32::MAX, 0.0, f32::MIN]]);
        let (mut visited_ranged, mut visited_tiny) = (0, 0);
        for &x in &points {
            let mut got = Vec::new();
            set.near(x, |i, _| got.push(i));
            let want: Vec<usize> = order.iter().copied().filter(|&i| in_range(i, x)).collect();
            assert_eq!(got, want, "at {x:?}");
            visited_ranged += got.len() - 31;
            visited_tiny += got.iter().filter(|&&i| matches!(lights[i], Light::Point { range: Some(r), .. } if r < 0.2)).count();
        }
        assert!(visited_ranged > 5000 && visited_tiny >= 60, "the test points fall in some ranges: {visited_ranged}, {visited_tiny}");
        // The grid holds the big light in every cell and the others in a few.
        assert!(g.items.len() < 20 * g.start.len(), "{} entries in {} cells", g.items.len(), g.start.len());
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
