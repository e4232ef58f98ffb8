//! Particle systems (Reeves 1983; notes §7): emitters, structure-of-arrays storage, a fixed-step
//! parallel update, and the billboard instances a renderer draws.
//!
//! - Storage is one array per component, allocated once at the emitter's capacity: the update
//!   streams through memory in parallel chunks, nothing is allocated per particle, and a spawn
//!   beyond capacity is dropped and counted rather than growing the arrays mid-frame.
//! - Each step, in the notes' order: forces and motion for every live particle, death of those
//!   past their lifetime (swap-remove: the arrays stay dense), then spawning at the emitter's
//!   rate. Spawns are a running fraction, so rate r over time T gives floor(r·T) particles at
//!   any step size.
//! - Motion is semi-implicit Euler (`integrate` has the evidence) with linear drag toward the wind
//!   velocity integrated exactly: v' = e^{-kh}·v + (1 − e^{-kh})/k · (g + k·w − k_s·(x − c)),
//!   then x' = x + h·v'. With k = 0 this is plain symplectic Euler; for any k it never
//!   overshoots the terminal velocity, however large kh is.
//! - The ground is a plane y = ground_y: a particle that crossed it is projected back onto it,
//!   its normal velocity reflected and scaled by the restitution e and its tangential velocity
//!   scaled by (1 − friction). A bounce apex is therefore about e² of the previous one.
//! - Particles are independent, so the parallel update gives the same bits for any thread count;
//!   the only random draws are at spawn, from a generator per particle seeded by the emitter's
//!   seed and the particle's spawn number.

use super::curve::{Curve, Gradient};
use super::rng::{hash, Rng};
use glam::Vec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// How the billboards combine with what is behind them. Alpha blending needs back-to-front
/// order; additive blending commutes and is drawn unsorted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Blend {
    #[default]
    Alpha,
    Additive,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Preset {
    Fountain,
    Fire,
    Smoke,
    Sparks,
}

/// A spring pulling particles toward a point: a = −stiffness·(x − position). The notes' force
/// patterns (attractors) in their linear form; it is also the oscillator the energy test runs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Attractor {
    pub position: [f32; 3],
    pub stiffness_per_s2: f32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct EmitterParams {
    pub position: [f32; 3],
    /// Particles start uniformly inside a sphere of this radius around `position`.
    pub spawn_radius: f32,
    /// Centre of the cone of initial directions (need not be unit length).
    pub direction: [f32; 3],
    pub cone_half_angle_deg: f32,
    pub speed_min: f32,
    pub speed_max: f32,
    pub rate_per_s: f32,
    pub life_min_s: f32,
    pub life_max_s: f32,
    pub capacity: u32,
    /// Acceleration, m/s² (buoyant fire and smoke point it up).
    pub gravity: [f32; 3],
    /// Linear drag rate k, 1/s: velocity relaxes toward `wind` + gravity/k.
    pub drag_per_s: f32,
    /// Velocity of the air, m/s.
    pub wind: [f32; 3],
    /// Height of the ground plane; `None` lets particles fall through.
    pub ground_y: Option<f32>,
    pub restitution: f32,
    pub friction: f32,
    pub attractor: Option<Attractor>,
    /// Billboard size (metres) over normalised age.
    pub size: Curve,
    /// Linear RGBA over normalised age.
    pub color: Gradient,
    pub blend: Blend,
    pub seed: u64,
}

impl Default for EmitterParams {
    fn default() -> Self {
        EmitterParams::preset(Preset::Fountain)
    }
}

impl EmitterParams {
    pub fn preset(preset: Preset) -> EmitterParams {
        let base = EmitterParams {
            position: [0.0; 3],
            spawn_radius: 0.0,
            direction: [0.0, 1.0, 0.0],
            cone_half_angle_deg: 10.0,
            speed_min: 1.0,
            speed_max: 1.0,
            rate_per_s: 100.0,
            life_min_s: 1.0,
            life_max_s: 1.0,
            capacity: 4096,
            gravity: [0.0, -9.81, 0.0],
            drag_per_s: 0.0,
            wind: [0.0; 3],
            ground_y: None,
            restitution: 0.0,
            friction: 0.0,
            attractor: None,
            size: Curve::constant(0.1),
            color: Gradient::constant([1.0; 4]),
            blend: Blend::Alpha,
            seed: 1,
        };
        match preset {
            // A jet of water: narrow, fast, falls back and splashes a little.
            Preset::Fountain => EmitterParams {
                spawn_radius: 0.05,
                cone_half_angle_deg: 8.0,
                speed_min: 6.0,
                speed_max: 7.0,
                rate_per_s: 1500.0,
                life_min_s: 1.8,
                life_max_s: 2.2,
                capacity: 5000,
                drag_per_s: 0.1,
                ground_y: Some(0.0),
                restitution: 0.25,
                friction: 0.5,
                size: Curve::linear(0.05, 0.1),
                color: Gradient {
                    keys: vec![(0.0, [0.7, 0.85, 1.0, 0.8]), (0.8, [0.6, 0.8, 1.0, 0.5]), (1.0, [0.6, 0.8, 1.0, 0.0])],
                },
                ..base
            },
            // Buoyant, strongly damped flames; HDR colours fading from yellow to dark red.
            Preset::Fire => EmitterParams {
                spawn_radius: 0.25,
                cone_half_angle_deg: 20.0,
                speed_min: 0.3,
                speed_max: 1.0,
                rate_per_s: 600.0,
                life_min_s: 0.6,
                life_max_s: 1.1,
                capacity: 1024,
                gravity: [0.0, 3.0, 0.0],
                drag_per_s: 2.0,
                size: Curve {
                    keys: vec![[0.0, 0.35], [0.3, 0.45], [1.0, 0.1]],
                },
                color: Gradient {
                    keys: vec![(0.0, [4.0, 2.0, 0.5, 1.0]), (0.4, [3.0, 0.8, 0.1, 0.8]), (1.0, [0.4, 0.05, 0.0, 0.0])],
                },
                blend: Blend::Additive,
                ..base
            },
            // Slow, growing, drifting with the wind; fades in and out.
            Preset::Smoke => EmitterParams {
                spawn_radius: 0.2,
                cone_half_angle_deg: 12.0,
                speed_min: 0.5,
                speed_max: 1.0,
                rate_per_s: 60.0,
                life_min_s: 3.0,
                life_max_s: 5.0,
                capacity: 512,
                gravity: [0.0, 0.6, 0.0],
                drag_per_s: 0.5,
                wind: [0.8, 0.0, 0.2],
                size: Curve::linear(0.3, 1.8),
                color: Gradient {
                    keys: vec![(0.0, [0.3, 0.3, 0.3, 0.0]), (0.15, [0.35, 0.35, 0.35, 0.45]), (1.0, [0.5, 0.5, 0.5, 0.0])],
                },
                ..base
            },
            // Fast, wide, short-lived, bouncing off the floor.
            Preset::Sparks => EmitterParams {
                cone_half_angle_deg: 50.0,
                speed_min: 3.0,
                speed_max: 8.0,
                rate_per_s: 300.0,
                life_min_s: 0.6,
                life_max_s: 1.4,
                capacity: 1024,
                drag_per_s: 0.3,
                ground_y: Some(0.0),
                restitution: 0.5,
                friction: 0.2,
                size: Curve::linear(0.03, 0.01),
                color: Gradient {
                    keys: vec![(0.0, [8.0, 4.0, 1.2, 1.0]), (1.0, [2.0, 0.3, 0.05, 0.0])],
                },
                blend: Blend::Additive,
                ..base
            },
        }
    }
}

/// A capacity that holds an emitter's steady state: rate × the longest life particles are alive
/// at once, with a quarter more and a few extra for the spawn rounding, so none is dropped.
pub fn steady_state_capacity(rate_per_s: f32, life_max_s: f32) -> u32 {
    (rate_per_s.max(0.0) * life_max_s.max(0.0) * 1.25).ceil() as u32 + 16
}

/// Live particles, one array per component, each allocated at capacity once.
#[derive(Debug, Clone, PartialEq)]
pub struct Particles {
    pub px: Vec<f32>,
    pub py: Vec<f32>,
    pub pz: Vec<f32>,
    pub vx: Vec<f32>,
    pub vy: Vec<f32>,
    pub vz: Vec<f32>,
    pub age: Vec<f32>,
    pub life: Vec<f32>,
    len: usize,
}

impl Particles {
    pub fn with_capacity(capacity: usize) -> Particles {
        let z = || vec![0.0f32; capacity];
        Particles {
            px: z(),
            py: z(),
            pz: z(),
            vx: z(),
            vy: z(),
            vz: z(),
            age: z(),
            life: z(),
            len: 0,
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn capacity(&self) -> usize {
        self.px.len()
    }

    /// Adds a particle of age 0; false (and nothing added) when full.
    pub fn push(&mut self, p: Vec3, v: Vec3, life_s: f32) -> bool {
        let i = self.len;
        if i == self.capacity() {
            return false;
        }
        (self.px[i], self.py[i], self.pz[i]) = (p.x, p.y, p.z);
        (self.vx[i], self.vy[i], self.vz[i]) = (v.x, v.y, v.z);
        (self.age[i], self.life[i]) = (0.0, life_s);
        self.len += 1;
        true
    }

    pub fn position(&self, i: usize) -> Vec3 {
        Vec3::new(self.px[i], self.py[i], self.pz[i])
    }

    pub fn velocity(&self, i: usize) -> Vec3 {
        Vec3::new(self.vx[i], self.vy[i], self.vz[i])
    }

    /// Changes the capacity, dropping the particles past it.
    pub fn resize(&mut self, capacity: usize) {
        for a in [&mut self.px, &mut self.py, &mut self.pz, &mut self.vx, &mut self.vy, &mut self.vz, &mut self.age, &mut self.life] {
            a.resize(capacity, 0.0);
            a.shrink_to_fit();
        }
        self.len = self.len.min(capacity);
    }

    /// Moves the last live particle into slot `i` (order is not kept; the arrays stay dense).
    fn swap_remove(&mut self, i: usize) {
        let last = self.len - 1;
        for a in [&mut self.px, &mut self.py, &mut self.pz, &mut self.vx, &mut self.vy, &mut self.vz, &mut self.age, &mut self.life] {
            a[i] = a[last];
        }
        self.len = last;
    }
}

/// Exact totals since the emitter started (tests and the overlay read them).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ParticleCounters {
    pub steps: u64,
    pub spawned: u64,
    pub died: u64,
    /// Spawns refused because the emitter was at capacity.
    pub dropped: u64,
}

/// One camera-facing quad: what the particle pass instances. 32 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Billboard {
    pub position: [f32; 3],
    pub size: f32,
    pub color: [f32; 4],
}

/// Particles per parallel work item: big enough to amortise scheduling (a few µs of work).
const CHUNK: usize = 4096;

#[derive(Debug, Clone)]
pub struct ParticleSystem {
    pub params: EmitterParams,
    pub particles: Particles,
    pub counters: ParticleCounters,
    /// Spawns so far, dropped ones included: the next particle's generator seed.
    spawn_index: u64,
    /// Fractional spawns carried to the next step.
    spawn_carry: f64,
}

/// A spawn that falls within this much of a whole particle happens now: the running sum of
/// rate·h over a second rounds to a hair under the integer it should be.
const SPAWN_TOLERANCE: f64 = 1e-6;

impl ParticleSystem {
    pub fn new(params: EmitterParams) -> ParticleSystem {
        let particles = Particles::with_capacity(params.capacity as usize);
        ParticleSystem {
            spawn_index: 0,
            params,
            particles,
            counters: ParticleCounters::default(),
            spawn_carry: 0.0,
        }
    }

    /// Replaces the parameters (the overlay editing an emitter live). The live particles carry
    /// on; a new capacity reallocates the storage once, keeping the first particles that fit.
    pub fn set_params(&mut self, params: EmitterParams) {
        if params.capacity != self.params.capacity {
            self.particles.resize(params.capacity as usize);
        }
        self.params = params;
    }

    /// One fixed step of `h` seconds: move, kill, spawn.
    pub fn step(&mut self, h: f32) {
        // On a rayon worker, so the parallel loops inside queue work instead of each waking a
        // worker and waiting for it (as `Flock::step`).
        rayon::scope(|_| {
            self.integrate(h);
            self.kill();
            self.spawn(h);
        });
        self.counters.steps += 1;
    }

    fn integrate(&mut self, h: f32) {
        let p = &self.params;
        let k = p.drag_per_s.max(0.0);
        // Exact drag: the velocity decays by c1 and the constant forces act through c2 (h when
        // there is no drag, its limit).
        let c1 = (-k * h).exp();
        let step = Motion {
            h,
            c1,
            c2: if k * h > 1e-6 { (1.0 - c1) / k } else { h },
            g: Vec3::from(p.gravity) + k * Vec3::from(p.wind),
            spring: p.attractor.map_or(0.0, |a| a.stiffness_per_s2),
            centre: p.attractor.map_or(Vec3::ZERO, |a| Vec3::from(a.position)),
            // No ground is a ground at −∞: the loop has no branch on it.
            ground: p.ground_y.unwrap_or(f32::NEG_INFINITY),
            restitution: p.restitution,
            keep_tangent: 1.0 - p.friction.clamp(0.0, 1.0),
        };
        let n = self.particles.len;
        let s = &mut self.particles;
        (
            s.px[..n].par_chunks_mut(CHUNK),
            s.py[..n].par_chunks_mut(CHUNK),
            s.pz[..n].par_chunks_mut(CHUNK),
            s.vx[..n].par_chunks_mut(CHUNK),
            s.vy[..n].par_chunks_mut(CHUNK),
            s.vz[..n].par_chunks_mut(CHUNK),
            s.age[..n].par_chunks_mut(CHUNK),
        )
            .into_par_iter()
            .for_each(|(px, py, pz, vx, vy, vz, age)| step.run(px, py, pz, vx, vy, vz, age));
    }

    /// Swap-removes every particle that reached its lifetime: after a step, age < life for all.
    fn kill(&mut self) {
        let s = &mut self.particles;
        let mut i = 0;
        while i < s.len {
            if s.age[i] >= s.life[i] {
                // The particle moved in from the end is checked on the next pass of the loop.
                s.swap_remove(i);
                self.counters.died += 1;
            } else {
                i += 1;
            }
        }
    }

    fn spawn(&mut self, h: f32) {
        let p = &self.params;
        self.spawn_carry += p.rate_per_s.max(0.0) as f64 * h as f64;
        let n = (self.spawn_carry + SPAWN_TOLERANCE).floor() as u64;
        self.spawn_carry -= n as f64;
        let s = &mut self.particles;
        let (start, room) = (s.len, s.capacity() - s.len);
        let take = (n as usize).min(room);
        let first = self.spawn_index;
        // Dropped spawns use up their numbers too, so the particles after a full spell are the
        // same whether or not it happened.
        self.spawn_index += n;
        self.counters.spawned += take as u64;
        self.counters.dropped += n - take as u64;
        let axis = Vec3::from(p.direction).try_normalize().unwrap_or(Vec3::Y);
        let half = p.cone_half_angle_deg.to_radians();
        let origin = Vec3::from(p.position);
        let seed = hash(p.seed);
        let end = start + take;
        // Each new particle draws from its own generator, seeded by its spawn number: the draws
        // run in parallel and come out the same for any thread count.
        (
            s.px[start..end].par_chunks_mut(CHUNK),
            s.py[start..end].par_chunks_mut(CHUNK),
            s.pz[start..end].par_chunks_mut(CHUNK),
            s.vx[start..end].par_chunks_mut(CHUNK),
            s.vy[start..end].par_chunks_mut(CHUNK),
            s.vz[start..end].par_chunks_mut(CHUNK),
            s.age[start..end].par_chunks_mut(CHUNK),
            s.life[start..end].par_chunks_mut(CHUNK),
        )
            .into_par_iter()
            .enumerate()
            .for_each(|(c, (px, py, pz, vx, vy, vz, age, life))| {
                for k in 0..px.len() {
                    let mut rng = Rng::new(hash(seed ^ (first + (c * CHUNK + k) as u64)));
                    let offset = if p.spawn_radius > 0.0 {
                        rng.unit_vector() * (p.spawn_radius * rng.f32().cbrt())
                    } else {
                        Vec3::ZERO
                    };
                    let pos = origin + offset;
                    let v = rng.cone(axis, half) * rng.range(p.speed_min, p.speed_max);
                    (px[k], py[k], pz[k]) = (pos.x, pos.y, pos.z);
                    (vx[k], vy[k], vz[k]) = (v.x, v.y, v.z);
                    (age[k], life[k]) = (0.0, rng.range(p.life_min_s, p.life_max_s));
                }
            });
        s.len = end;
    }

    /// Fills `out` with one billboard per live particle: size and colour from the curves at the
    /// particle's normalised age, position moved on by `extrapolate_s` of its velocity (the
    /// clock's alpha times the step, so motion is smooth between steps). Alpha-blended emitters
    /// come out back to front along `view_forward` from `camera` (ties broken by storage index,
    /// so the order is deterministic); additive ones in storage order. `out` and `scratch` keep
    /// their allocations between frames.
    pub fn fill_billboards(&self, camera: Vec3, view_forward: Vec3, extrapolate_s: f32, out: &mut Vec<Billboard>, scratch: &mut BillboardScratch) {
        let s = &self.particles;
        let p = &self.params;
        let fill = |dst: &mut Vec<Billboard>| {
            dst.clear();
            dst.resize(s.len, Billboard::default());
            dst.par_chunks_mut(CHUNK).enumerate().for_each(|(c, chunk)| {
                for (j, b) in chunk.iter_mut().enumerate() {
                    let i = c * CHUNK + j;
                    let t = s.age[i] / s.life[i];
                    let at = s.position(i) + s.velocity(i) * extrapolate_s;
                    *b = Billboard {
                        position: at.to_array(),
                        size: p.size.eval(t),
                        color: p.color.eval(t),
                    };
                }
            });
        };
        // On a rayon worker, as `step`: four parallel loops, one wake-up.
        rayon::scope(|_| match p.blend {
            Blend::Additive => fill(out),
            Blend::Alpha => {
                // Build in storage order (streaming through the particle arrays), sort 8-byte
                // keys, then move each 32-byte billboard once: gathering straight from the eight
                // particle arrays in sorted order would miss the cache eight times per particle.
                let src = &mut scratch.unsorted;
                fill(src);
                // Key: depth descending in the high half (farthest first), index in the low.
                let keys = &mut scratch.keys;
                keys.clear();
                keys.par_extend(src.par_iter().enumerate().with_min_len(CHUNK).map(|(i, b)| {
                    let depth = (Vec3::from(b.position) - camera).dot(view_forward);
                    ((!ordered_bits(depth) as u64) << 32) | i as u64
                }));
                keys.par_sort_unstable();
                out.clear();
                out.par_extend(keys.par_iter().with_min_len(CHUNK).map(|&k| src[k as u32 as usize]));
            }
        });
    }
}

/// One step of motion for a chunk of particles, the constants of `integrate` folded in.
struct Motion {
    h: f32,
    c1: f32,
    c2: f32,
    g: Vec3,
    spring: f32,
    centre: Vec3,
    ground: f32,
    restitution: f32,
    keep_tangent: f32,
}

impl Motion {
    /// A function of its own so the slices arrive as distinct `&mut` arguments: the compiler
    /// then knows they do not alias and vectorises the loop (inlined into the closure, it did
    /// not). The lengths are stated once, so the loop has no bounds checks.
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    fn run(&self, px: &mut [f32], py: &mut [f32], pz: &mut [f32], vx: &mut [f32], vy: &mut [f32], vz: &mut [f32], age: &mut [f32]) {
        let m = px.len();
        let (py, pz, vx, vy, vz, age) = (&mut py[..m], &mut pz[..m], &mut vx[..m], &mut vy[..m], &mut vz[..m], &mut age[..m]);
        let (h, c1, c2, g, ks, c) = (self.h, self.c1, self.c2, self.g, self.spring, self.centre);
        for i in 0..m {
            age[i] += h;
            let mut v = [
                c1 * vx[i] + c2 * (g.x - ks * (px[i] - c.x)),
                c1 * vy[i] + c2 * (g.y - ks * (py[i] - c.y)),
                c1 * vz[i] + c2 * (g.z - ks * (pz[i] - c.z)),
            ];
            let mut y = py[i] + h * v[1];
            // Selects rather than branches (`&`, not `&&`), for the same reason.
            let hit = y < self.ground;
            let keep = if hit { self.keep_tangent } else { 1.0 };
            v[1] = if hit & (v[1] < 0.0) { -self.restitution * v[1] } else { v[1] };
            y = if hit { self.ground } else { y };
            px[i] += h * v[0];
            pz[i] += h * v[2];
            py[i] = y;
            vx[i] = v[0] * keep;
            vy[i] = v[1];
            vz[i] = v[2] * keep;
        }
    }
}

/// Reusable buffers for `fill_billboards`'s sort.
#[derive(Debug, Clone, Default)]
pub struct BillboardScratch {
    keys: Vec<u64>,
    unsorted: Vec<Billboard>,
}

/// An f32's bits mapped so unsigned order is numeric order (negatives flipped whole, positives
/// with the sign bit set).
fn ordered_bits(f: f32) -> u32 {
    let b = f.to_bits();
    if b >> 31 == 1 {
        !b
    } else {
        b | 0x8000_0000
    }
}
