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
pub mod clock;
pub mod curve;
pub mod grid;
pub mod integrate;
pub mod particles;
pub mod rng;
