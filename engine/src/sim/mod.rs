//! CPU simulation of particles and boids (issue 8; ../shared/notes/animation.md §7–8).
//!
//! - `clock`: the fixed simulation step behind an accumulator, so state depends on simulated time
//!   only, never on the frame rate.
//! - `rng`: a small seeded generator, so a level replays identically.
//! - `curve`: piecewise-linear curves and colour gradients over a particle's life.
//! - `integrate`: the reference integrators of the notes' table, whose pinned numbers justify the
//!   choice of semi-implicit Euler for the simulations.
//! - `particles`: emitters and structure-of-arrays particle storage, updated in parallel chunks.
//! - `grid`: the uniform grid (counting sort) for neighbour queries.
//! - `boids`: flocking with priority allocation of the acceleration budget, double-buffered.
//!
//! Parameters are plain structs with serde defaults: the level file and the overlay set them.

pub mod boids;
pub mod obstacles;
pub mod clock;
pub mod curve;
pub mod grid;
pub mod level;
pub mod integrate;
pub mod lanes;
pub mod particles;
pub mod rng;
pub mod urges;

use boids::{Flock, NeighbourSearch};
use clock::FixedClock;
use particles::ParticleSystem;

/// Everything the simulation steps, behind one fixed clock: what a level's runtime owns and
/// advances once per frame, before culling.
#[derive(Debug, Clone)]
pub struct World {
    pub clock: FixedClock,
    pub emitters: Vec<ParticleSystem>,
    pub flocks: Vec<Flock>,
    /// The spawn each emitter and flock came from, by index, where known (the overlay's labels).
    pub emitter_names: Vec<String>,
    pub flock_names: Vec<String>,
    /// The scene mesh each flock's birds are drawn with, by index (a boids spawn's `mesh`, which
    /// the cooker sets from its `asset`); None: simulated but not drawn.
    pub flock_meshes: Vec<Option<u32>>,
}

impl World {
    pub fn new(clock: FixedClock) -> World {
        World {
            clock,
            emitters: Vec::new(),
            flocks: Vec::new(),
            emitter_names: Vec::new(),
            flock_names: Vec::new(),
            flock_meshes: Vec::new(),
        }
    }

    /// Advances by a frame's duration; returns the fixed steps taken.
    pub fn update(&mut self, frame_s: f64) -> u32 {
        let steps = self.clock.advance(frame_s);
        let h = self.clock.dt();
        for _ in 0..steps {
            for e in &mut self.emitters {
                e.step(h);
            }
            for f in &mut self.flocks {
                f.step(h, NeighbourSearch::Grid);
            }
        }
        steps
    }
}
