//! What the simulation test files share (`sim.rs`, `sim_boids.rs`).
#![allow(dead_code)]

use engine::sim::boids::{Aabb, BoidParams, Flock, Pillar};
use engine::sim::particles::{EmitterParams, ParticleSystem};

pub const G: f32 = 9.81;

pub fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap()
}

/// An emitter that spawns nothing and feels only gravity: particles are placed by hand.
pub fn ballistic(capacity: u32) -> EmitterParams {
    EmitterParams {
        rate_per_s: 0.0,
        capacity,
        drag_per_s: 0.0,
        ground_y: None,
        gravity: [0.0, -G, 0.0],
        ..EmitterParams::default()
    }
}

pub fn live_state(s: &ParticleSystem) -> Vec<[u32; 8]> {
    let p = &s.particles;
    (0..p.len())
        .map(|i| [p.px[i], p.py[i], p.pz[i], p.vx[i], p.vy[i], p.vz[i], p.age[i], p.life[i]].map(f32::to_bits))
        .collect()
}

pub fn flock_bits(f: &Flock) -> Vec<u32> {
    let s = f.state();
    [&s.px, &s.py, &s.pz, &s.vx, &s.vy, &s.vz, &s.roll].iter().flat_map(|a| a.iter().map(|x| x.to_bits())).collect()
}

pub fn busy_params(seed: u64) -> BoidParams {
    BoidParams {
        seed,
        bounds: Some(Aabb {
            min: [-40.0, 0.0, -40.0],
            max: [40.0, 30.0, 40.0],
        }),
        boxes: vec![Aabb {
            min: [-5.0, 0.0, -5.0],
            max: [5.0, 8.0, 5.0],
        }],
        pillars: vec![Pillar {
            centre: [20.0, -10.0],
            radius: 1.5,
            y_min: 0.0,
            y_max: 30.0,
        }],
        ..BoidParams::default()
    }
}
