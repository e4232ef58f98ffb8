//! Flocking (Reynolds 1987; the book's 16.7 and notes §8).
//!
//! - Each boid sees its neighbours within `neighbour_radius` and forms five urges, as
//!   accelerations: obstacle avoidance (limited-range repulsion fields around the level's boxes,
//!   pillars and bounds), separation Σ (p_i − p_j)/d² within `separation_radius`, alignment
//!   mean(v_j) − v_i, cohesion mean(p_j) − p_i, and a goal (seek a point) or wander urge.
//! - The urges are not averaged (equal and opposite urges would cancel and leave the boid going
//!   nowhere, the book's failure mode): `allocate` hands a fixed acceleration budget out in
//!   priority order, obstacles first, and once it is spent the later urges wait for a later step.
//! - Then v += a·h with |v| held in [speed_min, speed_max] (`limit_speed`), and x += v·h
//!   (semi-implicit Euler, as the particles). The budget bounds |a|, and the clamp to the
//!   speed_max ball cannot add to the change (projection onto a convex set is non-expansive), so
//!   |Δv| ≤ accel_max·h with no speed_min. At speed_min a boid turns rather than slows.
//! - State is double-buffered: every boid reads the previous step and writes the next, so the
//!   result does not depend on the order boids are updated in. Each boid's neighbour list is
//!   sorted by (distance, index) before use and capped to the nearest `max_neighbours`, so the
//!   sums run in the same order however the neighbours were found: the grid and the brute-force
//!   scan give the same bits, for any number of threads. Nearest first, because in a dense
//!   cluster the neighbour that matters for separation is the closest one.
//! - Banking: a boid rolls into a turn by atan(a_lateral / g) (a coordinated turn), smoothed with
//!   a time constant, and `boid_rotation` turns velocity and roll into the instance rotation.

use super::grid::Grid;
use super::lanes::{self, F, LANES, V3};
pub use super::obstacles::{Aabb, Pillar};
pub use super::urges::{allocate, allocate_lanes, limit_speed, limit_speed_lanes};
use super::obstacles::{box_distance, pillar_distance, repel};
use super::rng::hash;
use glam::{Mat3, Quat, Vec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct BoidParams {
    /// Alignment and cohesion see neighbours closer than this (metres).
    pub neighbour_radius: f32,
    /// Separation acts on neighbours closer than this (at most `neighbour_radius`).
    pub separation_radius: f32,
    /// 0: every neighbour; otherwise the nearest ones, bounding the cost in dense flocks.
    pub max_neighbours: u32,
    pub separation_weight: f32,
    pub alignment_weight: f32,
    pub cohesion_weight: f32,
    /// Repulsion at contact with an obstacle, as a multiple of `accel_max`.
    pub obstacle_weight: f32,
    /// Range of the obstacle repulsion fields (metres).
    pub avoid_distance: f32,
    pub goal: Option<[f32; 3]>,
    pub goal_weight: f32,
    /// Strength of a slowly turning random heading when there is no goal.
    pub wander_weight: f32,
    /// Time between the random headings wander blends between.
    pub wander_period_s: f32,
    pub speed_min: f32,
    pub speed_max: f32,
    /// The acceleration budget the urges share (m/s²).
    pub accel_max: f32,
    /// Space the flock stays inside (`None`: unbounded).
    pub bounds: Option<Aabb>,
    pub boxes: Vec<Aabb>,
    pub pillars: Vec<Pillar>,
    pub bank_max_deg: f32,
    /// Time constant of the roll following its target.
    pub bank_response_s: f32,
    pub seed: u64,
}

impl Default for BoidParams {
    fn default() -> Self {
        // Rule distances as CIS 565's (5 / 3 / 5, anchors §6), speeds of a bird, and an
        // avoidance range longer than the braking distance v²/(2a) = 2.5 m.
        BoidParams {
            neighbour_radius: 5.0,
            separation_radius: 3.0,
            max_neighbours: 32,
            separation_weight: 20.0,
            alignment_weight: 2.0,
            cohesion_weight: 0.5,
            obstacle_weight: 4.0,
            avoid_distance: 5.0,
            goal: None,
            goal_weight: 1.0,
            wander_weight: 2.0,
            wander_period_s: 4.0,
            speed_min: 2.0,
            speed_max: 10.0,
            accel_max: 20.0,
            bounds: Some(Aabb { min: [-100.0; 3], max: [100.0; 3] }),
            boxes: Vec::new(),
            pillars: Vec::new(),
            bank_max_deg: 60.0,
            bank_response_s: 0.2,
            seed: 1,
        }
    }
}

/// Boid state, one array per component.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FlockState {
    pub px: Vec<f32>,
    pub py: Vec<f32>,
    pub pz: Vec<f32>,
    pub vx: Vec<f32>,
    pub vy: Vec<f32>,
    pub vz: Vec<f32>,
    /// Bank angle (radians, positive rolls toward the boid's right).
    pub roll: Vec<f32>,
}

impl FlockState {
    pub fn len(&self) -> usize {
        self.px.len()
    }

    pub fn is_empty(&self) -> bool {
        self.px.is_empty()
    }

    pub fn push(&mut self, p: Vec3, v: Vec3) {
        self.px.push(p.x);
        self.py.push(p.y);
        self.pz.push(p.z);
        self.vx.push(v.x);
        self.vy.push(v.y);
        self.vz.push(v.z);
        self.roll.push(0.0);
    }

    pub fn position(&self, i: usize) -> Vec3 {
        Vec3::new(self.px[i], self.py[i], self.pz[i])
    }

    pub fn velocity(&self, i: usize) -> Vec3 {
        Vec3::new(self.vx[i], self.vy[i], self.vz[i])
    }

    /// `n` boids uniformly in the box, headed in random directions at `speed`.
    pub fn random(n: usize, min: Vec3, max: Vec3, speed: f32, seed: u64) -> FlockState {
        let mut rng = super::rng::Rng::new(seed);
        let mut s = FlockState::default();
        for _ in 0..n {
            let p = Vec3::new(rng.range(min.x, max.x), rng.range(min.y, max.y), rng.range(min.z, max.z));
            s.push(p, rng.unit_vector() * speed);
        }
        s
    }

    /// The seven arrays in parallel chunks of `size` boids, a chunk of each together.
    fn par_chunks_mut(&mut self, size: usize) -> impl IndexedParallelIterator<Item = ChunkMut<'_>> {
        let s = self;
        (
            s.px.par_chunks_mut(size),
            s.py.par_chunks_mut(size),
            s.pz.par_chunks_mut(size),
            s.vx.par_chunks_mut(size),
            s.vy.par_chunks_mut(size),
            s.vz.par_chunks_mut(size),
            s.roll.par_chunks_mut(size),
        )
            .into_par_iter()
    }

    fn resize_like(&mut self, other: &FlockState) {
        let n = other.len();
        for a in [&mut self.px, &mut self.py, &mut self.pz, &mut self.vx, &mut self.vy, &mut self.vz, &mut self.roll] {
            a.resize(n, 0.0);
        }
    }
}

/// One range of boids in each of `FlockState`'s arrays: px, py, pz, vx, vy, vz, roll.
type ChunkMut<'a> = (&'a mut [f32], &'a mut [f32], &'a mut [f32], &'a mut [f32], &'a mut [f32], &'a mut [f32], &'a mut [f32]);

/// How a step finds neighbours: the grid, or the O(N²) scan (tests and the bench).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NeighbourSearch {
    Grid,
    BruteForce,
}

/// Exact totals of the last step.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StepCounters {
    /// Points the neighbour search looked at (the grid's cost; N per boid for brute force).
    pub examined: u64,
    /// Neighbours used after the cap.
    pub neighbours: u64,
}

#[derive(Debug, Clone)]
pub struct Flock {
    pub params: BoidParams,
    cur: FlockState,
    next: FlockState,
    /// The next state in the grid's cell order, before it is gathered into `next`.
    sorted: FlockState,
    grid: Grid,
    pub steps: u64,
    pub last: StepCounters,
}

/// Boids per parallel work item.
const CHUNK: usize = 256;
/// Boids per work item of the gather back to index order.
const GATHER: usize = 4096;

/// Rotation of a boid model (facing +Z, up +Y, as glTF) flying along `v`, rolled by `roll`
/// about its heading.
pub fn boid_rotation(v: Vec3, roll: f32) -> Quat {
    let f = v.try_normalize().unwrap_or(Vec3::Z);
    // Straight up or down: any horizontal side will do.
    let x = Vec3::Y.cross(f).try_normalize().unwrap_or(Vec3::X);
    let y = f.cross(x);
    Quat::from_axis_angle(f, roll) * Quat::from_mat3(&Mat3::from_cols(x, y, f))
}

const GRAVITY: f32 = 9.81;

/// atan within about 1e-7 of libm's (Abramowitz & Stegun 4.4.49, |ε| ≤ 2·10⁻⁸ on [0, 1], and
/// atan x = π/2 − atan(1/x) beyond): a polynomial, in lanes, instead of a libm call per boid.
fn atan(x: F) -> F {
    let a = x.abs();
    let big = a.simd_gt(F::ONE);
    let t = big.select(F::ONE / a, a);
    let t2 = t * t;
    let c = F::splat;
    let poly = c(-0.333_331_45)
        + t2 * (c(0.199_935_51) + t2 * (c(-0.142_088_99) + t2 * (c(0.106_562_64) + t2 * (c(-0.075_289_64) + t2 * (c(0.042_909_61) + t2 * (c(-0.016_165_737) + t2 * c(0.002_866_225_7)))))));
    let r = t + t * t2 * poly;
    big.select(c(std::f32::consts::FRAC_PI_2) - r, r).copysign(x)
}

impl Flock {
    pub fn new(params: BoidParams, state: FlockState) -> Flock {
        Flock {
            params,
            next: FlockState::default(),
            sorted: FlockState::default(),
            cur: state,
            grid: Grid::new(),
            steps: 0,
            last: StepCounters::default(),
        }
    }

    pub fn state(&self) -> &FlockState {
        &self.cur
    }

    pub fn len(&self) -> usize {
        self.cur.len()
    }

    pub fn is_empty(&self) -> bool {
        self.cur.is_empty()
    }

    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// One fixed step of `h` seconds.
    pub fn step(&mut self, h: f32, search: NeighbourSearch) {
        // The whole step on one of rayon's worker threads: each parallel loop started from
        // outside the pool wakes a worker and puts this thread to sleep until it is done, a
        // round trip per loop (10k boids on 2 cores: 2.0 ms a step that way, 1.35 ms this way).
        rayon::scope(|_| self.step_in_pool(h, search));
    }

    fn step_in_pool(&mut self, h: f32, search: NeighbourSearch) {
        let p = &self.params;
        let radius = p.neighbour_radius.max(p.separation_radius);
        if search == NeighbourSearch::Grid && !self.cur.is_empty() {
            self.grid.build(&self.cur.px, &self.cur.py, &self.cur.pz, radius);
        }
        self.next.resize_like(&self.cur);
        self.sorted.resize_like(&self.cur);
        let t = self.steps as f32 * h;
        let max_bank = p.bank_max_deg.to_radians();
        let bank_follow = if p.bank_response_s > 0.0 { 1.0 - (-h / p.bank_response_s).exp() } else { 1.0 };
        // With the grid, boids are updated in cell order (neighbouring boids share cells, so
        // their queries hit the same cache lines) into `sorted`, then gathered back.
        let order = (search == NeighbourSearch::Grid).then(|| self.grid.order());
        let ctx = StepContext {
            p,
            cur: &self.cur,
            grid: &self.grid,
            search,
            radius,
            h,
            t,
            max_bank,
            bank_follow,
        };
        let n = if order.is_some() { &mut self.sorted } else { &mut self.next };
        let counters = n
            .par_chunks_mut(CHUNK)
            .enumerate()
            .map_init(
                || Vec::with_capacity(64),
                |buf, (c, (px, py, pz, vx, vy, vz, roll))| {
                    let mut counts = StepCounters::default();
                    let len = px.len();
                    // Eight boids at a time: each one's neighbourhood sums (scalar: the query and
                    // the sorted neighbour list), then the rules for all eight in SIMD lanes. A
                    // short last group repeats its last boid, whose copies are not written.
                    for g in (0..len).step_by(LANES) {
                        let mut group = Group::default();
                        for l in 0..LANES {
                            let k = (g + l).min(len - 1);
                            let at = c * CHUNK + k;
                            let i = order.map_or(at, |o| o[at] as usize);
                            let mut ignored = StepCounters::default();
                            ctx.neighbourhood(i, at, buf, if g + l < len { &mut counts } else { &mut ignored }, &mut group, l);
                        }
                        let (pos, vel, r) = ctx.rules(&group);
                        for l in 0..LANES.min(len - g) {
                            let k = g + l;
                            (px[k], py[k], pz[k]) = (pos.x.as_array()[l], pos.y.as_array()[l], pos.z.as_array()[l]);
                            (vx[k], vy[k], vz[k]) = (vel.x.as_array()[l], vel.y.as_array()[l], vel.z.as_array()[l]);
                            roll[k] = r.as_array()[l];
                        }
                    }
                    counts
                },
            )
            .reduce(StepCounters::default, |a, b| StepCounters {
                examined: a.examined + b.examined,
                neighbours: a.neighbours + b.neighbours,
            });
        self.last = counters;
        if order.is_some() {
            // Back to index order, in one parallel pass over all seven arrays.
            let (rank, src, dst) = (self.grid.rank(), &self.sorted, &mut self.next);
            dst.par_chunks_mut(GATHER).zip(rank.par_chunks(GATHER)).for_each(|((px, py, pz, vx, vy, vz, roll), rank)| {
                    for (k, &r) in rank.iter().enumerate() {
                        let r = r as usize;
                        (px[k], py[k], pz[k]) = (src.px[r], src.py[r], src.pz[r]);
                        (vx[k], vy[k], vz[k]) = (src.vx[r], src.vy[r], src.vz[r]);
                        roll[k] = src.roll[r];
                    }
                });
        }
        std::mem::swap(&mut self.cur, &mut self.next);
        self.steps += 1;
    }
}

/// What one step reads: the previous state only.
struct StepContext<'a> {
    p: &'a BoidParams,
    cur: &'a FlockState,
    grid: &'a Grid,
    search: NeighbourSearch,
    radius: f32,
    h: f32,
    /// Simulated time at the start of the step.
    t: f32,
    max_bank: f32,
    /// Fraction of the way the roll moves to its target in one step.
    bank_follow: f32,
}

/// Eight boids' inputs to the rules, one lane each: their state and their neighbourhood sums.
#[derive(Debug, Default, Clone)]
struct Group {
    index: [usize; LANES],
    pos: [Vec3; LANES],
    vel: [Vec3; LANES],
    roll: [f32; LANES],
    sep: [Vec3; LANES],
    alignment: [Vec3; LANES],
    cohesion: [Vec3; LANES],
}

impl StepContext<'_> {
    /// Boid `i`'s state and its separation, alignment and cohesion sums into lane `l` of `g`.
    /// `at`: its position in the grid's order (with the grid).
    fn neighbourhood(&self, i: usize, at: usize, buf: &mut Vec<u64>, counts: &mut StepCounters, g: &mut Group, l: usize) {
        let (p, s) = (self.p, self.cur);
        let (pos, vel) = (s.position(i), s.velocity(i));

        let keys: &mut [u64] = match self.search {
            NeighbourSearch::Grid => {
                let (found, examined) = self.grid.sorted_point_neighbour_keys(at, self.radius, buf);
                counts.examined += examined as u64;
                &mut buf[..found]
            }
            NeighbourSearch::BruteForce => {
                let keys = buf;
                keys.clear();
                // Key: squared distance (non-negative, so its bits order as the numbers) above the
                // index, with the grid's arithmetic.
                let r2 = self.radius * self.radius;
                for j in 0..s.len() {
                    let (dx, dy, dz) = (s.px[j] - pos.x, s.py[j] - pos.y, s.pz[j] - pos.z);
                    let d2 = dx * dx + dy * dy + dz * dz;
                    if d2 < r2 && j != i {
                        keys.push((d2.to_bits() as u64) << 32 | j as u64);
                    }
                }
                counts.examined += s.len() as u64;
                &mut keys[..]
            }
        };
        // The nearest `max_neighbours` by (distance, index), ascending. Keys are unique (the index
        // is in them), so selecting before sorting gives the same list as sorting everything.
        let cap = p.max_neighbours as usize;
        let keys: &[u64] = if cap > 0 && keys.len() > cap {
            keys.select_nth_unstable(cap - 1);
            let kept = &mut keys[..cap];
            kept.sort_unstable();
            kept
        } else {
            keys.sort_unstable();
            keys
        };
        counts.neighbours += keys.len() as u64;

        let (r2, sep2) = (p.neighbour_radius * p.neighbour_radius, p.separation_radius * p.separation_radius);
        let (mut sep, mut sum_v, mut sum_p, mut count) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, 0u32);
        for &key in keys.iter() {
            let j = key as u32 as usize;
            let d = pos - s.position(j);
            let d2 = f32::from_bits((key >> 32) as u32);
            if d2 < sep2 && d2 > 0.0 {
                sep += d / d2;
            }
            if d2 < r2 {
                sum_v += s.velocity(j);
                sum_p += s.position(j);
                count += 1;
            }
        }
        let (alignment, cohesion) = if count > 0 {
            let inv = 1.0 / count as f32;
            (sum_v * inv - vel, sum_p * inv - pos)
        } else {
            (Vec3::ZERO, Vec3::ZERO)
        };
        (g.index[l], g.pos[l], g.vel[l], g.roll[l]) = (i, pos, vel, s.roll[i]);
        (g.sep[l], g.alignment[l], g.cohesion[l]) = (sep, alignment, cohesion);
    }

    /// The next positions, velocities and rolls of the eight boids of `g`.
    fn rules(&self, g: &Group) -> (V3, V3, F) {
        let p = self.p;
        let (pos, vel) = (V3::from_lanes(&g.pos), V3::from_lanes(&g.vel));
        let urges = [
            self.obstacles(pos),
            V3::from_lanes(&g.sep) * F::splat(p.separation_weight),
            V3::from_lanes(&g.alignment) * F::splat(p.alignment_weight),
            V3::from_lanes(&g.cohesion) * F::splat(p.cohesion_weight),
            self.goal(&g.index, pos, vel),
        ];
        let a = allocate_lanes(urges, p.accel_max);

        let h = F::splat(self.h);
        let v = limit_speed_lanes(vel, a, self.h, p.speed_min, p.speed_max);
        let next_pos = pos + v * h;

        // Bank into the turn: the lateral part of the acceleration actually applied.
        let applied = (v - vel) / h;
        let (right, has_right) = v.cross(V3::splat(Vec3::Y)).try_normalize();
        let target = atan(applied.dot(right) / F::splat(GRAVITY)).max(F::splat(-self.max_bank)).min(F::splat(self.max_bank));
        let target = has_right.select(target, F::ZERO);
        let roll = F::new(g.roll);
        (next_pos, v, roll + (target - roll) * F::splat(self.bank_follow))
    }

    fn obstacles(&self, pos: V3) -> V3 {
        let p = self.p;
        let (range, strength) = (p.avoid_distance.max(1e-3), p.obstacle_weight * p.accel_max);
        let mut u = V3::ZERO;
        if let Some(b) = &p.bounds {
            // Inside the bounds is free space: each wall pushes inward.
            for (a, pa) in [pos.x, pos.y, pos.z].into_iter().enumerate() {
                let mut n = Vec3::ZERO;
                n[a] = 1.0;
                u += repel(pa - F::splat(b.min[a]), V3::splat(n), range, strength);
                u += repel(F::splat(b.max[a]) - pa, V3::splat(-n), range, strength);
            }
        }
        for b in &p.boxes {
            let (d, n) = box_distance(pos, b);
            u += repel(d, n, range, strength);
        }
        for c in &p.pillars {
            let (d, n) = pillar_distance(pos, c);
            u += repel(d, n, range, strength);
        }
        u
    }

    /// Seek the goal, or wander: steer toward speed_max along a heading that blends between
    /// random directions drawn from (seed, boid, period), so no generator state is shared. The
    /// directions are normalised points of a cube, not uniform on the sphere (a little more
    /// often diagonal): no trigonometry per boid, and a wander needs no better.
    fn goal(&self, index: &[usize; LANES], pos: V3, vel: V3) -> V3 {
        let p = self.p;
        let speed_max = F::splat(p.speed_max);
        if let Some(g) = p.goal {
            let (dir, ok) = (V3::splat(Vec3::from(g)) - pos).try_normalize();
            return (lanes::select(ok, dir, V3::ZERO) * speed_max - vel) * F::splat(p.goal_weight);
        }
        if p.wander_weight == 0.0 {
            return V3::ZERO;
        }
        let phase = self.t / p.wander_period_s.max(1e-3);
        let k = phase.floor();
        let w = phase - k;
        let smooth = w * w * (3.0 - 2.0 * w);
        let headings = |period: u64| V3::from_lanes(&index.map(|i| wander_heading(p.seed, i, period)));
        let (dir, ok) = headings(k as u64).lerp(headings(k as u64 + 1), F::splat(smooth)).try_normalize();
        (lanes::select(ok, dir, V3::splat(Vec3::X)) * speed_max - vel) * F::splat(p.wander_weight)
    }
}

/// The random heading of boid `i` in wander period `period`: three 21-bit coordinates of one
/// hash, in [-1, 1).
fn wander_heading(seed: u64, i: usize, period: u64) -> Vec3 {
    let bits = hash(seed ^ hash((i as u64) << 32 ^ period));
    let c = |shift: u32| ((bits >> shift) & 0x1F_FFFF) as f32 * (2.0 / (1u32 << 21) as f32) - 1.0;
    Vec3::new(c(0), c(21), c(42))
}

#[cfg(test)]
#[path = "boids_tests.rs"]
mod tests;
