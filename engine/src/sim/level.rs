//! The level's simulation (issue 8): a `sim::World` built from a pack's `[[spawns]]` (boids and
//! particles kinds; the parameters level.py's SPAWN_PARAMS validates), and the per-frame hand-off
//! of its state to the renderer's particle and boid passes.
//!
//! Everything is seeded from the spawn's name, and the clock is fixed-step, so a level replays
//! identically for the same sequence of frame times (the reference-image test relies on it).

use crate::scene::camera::Camera;
use crate::render::renderer::Renderer;
use crate::scene::GpuScene;
use crate::sim::boids::{Aabb, BoidParams, Flock, FlockState, Pillar};
use crate::sim::clock::{ClockParams, FixedClock};
use crate::sim::curve::{Curve, Gradient};
use crate::sim::particles::{steady_state_capacity, Blend, EmitterParams, ParticleSystem};
use crate::sim::World;
use glam::{Quat, Vec3};

/// Simulated time run at load, at `WARM_UP_STEP_S` a step, so emitters start in their steady
/// state (a fountain already flowing) rather than empty.
pub const WARM_UP_S: f64 = 2.0;
pub const WARM_UP_STEP_S: f64 = 1.0 / 60.0;

/// FNV-1a of the spawn's name: a stable seed per spawn.
fn seed_of(name: &str) -> u64 {
    name.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ b as u64).wrapping_mul(0x100_0000_01b3))
}

/// The spawn's numeric parameter `key` (the params are JSON, whose type this crate does not
/// name: serde_json is only a dependency of the pack crate).
fn num(spawn: &pack::Spawn, key: &str, default: f32) -> f32 {
    spawn.params.get(key).and_then(|v| v.as_f64()).map_or(default, |v| v as f32)
}

/// A particles spawn's blend: its `blend` parameter ("alpha" or "additive", which the cooker
/// validates), alpha when absent. Content decides, not the emitter's name. A value the cooker
/// would reject (a hand-edited pack) is treated as absent rather than failing the level.
pub fn blend_of(spawn: &pack::Spawn) -> Blend {
    match spawn.params.get("blend").and_then(|v| v.as_str()) {
        Some("additive") => Blend::Additive,
        _ => Blend::Alpha,
    }
}

/// A particles spawn's emitter. The level gives means; lifetimes and speeds vary ±20% around them
/// so a stream does not pulse. Colour holds then fades out over the last 30% of a life; size
/// shrinks to half.
pub fn emitter_for(spawn: &pack::Spawn, ground_y: f32) -> EmitterParams {
    let p = spawn;
    let life = num(p, "lifetime_s", 1.0).max(0.05);
    let speed = num(p, "speed", 1.0);
    let rate = num(p, "rate_per_s", 50.0).max(0.0);
    let size = num(p, "size", 0.05);
    let color: [f32; 4] = match spawn.params.get("color").and_then(|v| v.as_array()) {
        Some(a) if a.len() >= 3 => {
            let c = |i: usize, d: f32| a.get(i).and_then(|v| v.as_f64()).map_or(d, |v| v as f32);
            [c(0, 1.0), c(1, 1.0), c(2, 1.0), c(3, 1.0)]
        }
        _ => [1.0; 4],
    };
    let faded = [color[0], color[1], color[2], 0.0];
    let rotation = Quat::from_array(spawn.rotation);
    let direction = if rotation.length_squared() > 0.0 { rotation.normalize() * Vec3::Y } else { Vec3::Y };
    let life_max = life * 1.2;
    EmitterParams {
        position: spawn.position,
        spawn_radius: 0.02,
        direction: direction.to_array(),
        cone_half_angle_deg: num(p, "spread_deg", 10.0),
        speed_min: speed * 0.8,
        speed_max: speed * 1.2,
        rate_per_s: rate,
        life_min_s: life * 0.8,
        life_max_s: life_max,
        capacity: steady_state_capacity(rate, life_max),
        gravity: [0.0, num(p, "gravity", -9.81), 0.0],
        ground_y: Some(ground_y),
        restitution: 0.2,
        friction: 0.5,
        size: Curve::linear(size, size * 0.5),
        color: Gradient {
            keys: vec![(0.0, color), (0.7, color), (1.0, faded)],
        },
        blend: blend_of(spawn),
        seed: seed_of(&spawn.name),
        ..EmitterParams::default()
    }
}

/// A boids spawn's mesh: the `mesh` parameter the cooker writes (the pack checks it names one
/// of its meshes), None when absent.
pub fn mesh_of(spawn: &pack::Spawn) -> Option<u32> {
    spawn.params.get("mesh").and_then(|v| v.as_u64()).and_then(|m| u32::try_from(m).ok())
}

/// The pack's pillars (the cooker reads them from the level's vertical cylinder brushes) as the
/// flocks' obstacles.
pub fn pillars_of(pillars: &[pack::Pillar]) -> Vec<Pillar> {
    pillars
        .iter()
        .map(|p| Pillar {
            centre: p.centre,
            radius: p.radius,
            y_min: p.y_min,
            y_max: p.y_max,
        })
        .collect()
}

/// A boids spawn's flock: `count` birds at random in a cube of half-size `radius` around the
/// spawn, flying at `speed`, drawn back to the spawn by the goal urge, kept inside `bounds` and
/// out of `pillars`.
pub fn flock_for(spawn: &pack::Spawn, bounds: Aabb, pillars: Vec<Pillar>) -> Flock {
    let p = spawn;
    let count = spawn.params.get("count").and_then(|v| v.as_u64()).unwrap_or(16) as usize;
    let radius = num(p, "radius", 5.0);
    let speed = num(p, "speed", 3.0).max(0.1);
    let centre = Vec3::from(spawn.position);
    let seed = seed_of(&spawn.name);
    let params = BoidParams {
        goal: Some(spawn.position),
        speed_min: speed * 0.6,
        speed_max: speed * 1.5,
        // The separation and neighbour radii scale with the flock's size (defaults: 3 and 5 m
        // for a 5 m flock), so a small flock of doves still reads as a flock.
        separation_radius: (radius * 0.25).clamp(0.5, 3.0),
        neighbour_radius: (radius * 0.6).clamp(1.0, 5.0),
        bounds: Some(bounds),
        pillars,
        seed,
        ..BoidParams::default()
    };
    let state = FlockState::random(count, centre - Vec3::splat(radius), centre + Vec3::splat(radius), speed, seed);
    Flock::new(params, state)
}

/// The level's world from its spawns. `level_min`/`level_max` are the scene's bounds: the
/// flocks' obstacle box (raised to clear each flock's spawn volume, since birds fly above the
/// roofs) and the particles' ground plane (its floor). Every flock avoids every pillar.
pub fn world_from_spawns(spawns: &[pack::Spawn], pillars: &[pack::Pillar], level_min: Vec3, level_max: Vec3) -> World {
    let pillars = pillars_of(pillars);
    let mut world = World::new(FixedClock::new(ClockParams::default()));
    for s in spawns {
        match s.kind.as_str() {
            "particles" => {
                world.emitters.push(ParticleSystem::new(emitter_for(s, level_min.y)));
                world.emitter_names.push(s.name.clone());
            }
            "boids" => {
                let r = num(s, "radius", 5.0);
                let top = level_max.y.max(s.position[1] + 2.0 * r);
                let bounds = Aabb {
                    min: level_min.to_array(),
                    max: [level_max.x, top, level_max.z],
                };
                world.flocks.push(flock_for(s, bounds, pillars.clone()));
                world.flock_names.push(s.name.clone());
                world.flock_meshes.push(mesh_of(s));
            }
            _ => {}
        }
    }
    world
}

/// Run `WARM_UP_S` of simulated time in frame-sized steps (the clock caps steps per frame).
pub fn warm_up(world: &mut World) {
    let frames = (WARM_UP_S / WARM_UP_STEP_S).round() as u32;
    for _ in 0..frames {
        world.update(WARM_UP_STEP_S);
    }
}

/// Hand the world's current state to the renderer's particle and boid passes for `camera`;
/// call after `World::update` and before `Renderer::record`. Particles are extrapolated by the
/// clock's leftover fraction of a step, so they move smoothly between fixed steps.
pub fn prepare_frame(world: &World, renderer: &mut Renderer, scene: &GpuScene, camera: &Camera) {
    let extrapolate_s = world.clock.alpha() * world.clock.dt();
    renderer.particles.fill(&world.emitters, camera.position, camera.forward(), extrapolate_s);
    renderer.boids.fill(scene, &world.flocks, &world.flock_meshes);
}
