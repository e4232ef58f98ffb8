//! The level's simulation built from spawns (engine/src/sim/level.rs): the temple's own spawn
//! lines map onto emitters and flocks with the authored numbers, and replay identically.

use engine::sim::particles::Blend;
use engine::sim::level::{warm_up, world_from_spawns};
use glam::Vec3;
use pack::Spawn;

mod common;
use common::spawn;

/// The temple's boids and particles spawns as authored in content/levels/temple.toml, plus a
/// player spawn the simulation ignores.
fn temple_spawns() -> Vec<Spawn> {
    vec![
        spawn("player", "player", [0.0, 0.0, 18.0], r#"{ "speed": 4.0 }"#),
        spawn("doves", "boids", [0.0, 9.0, 9.0], r#"{ "count": 32, "radius": 8.0, "speed": 3.0 }"#),
        spawn(
            "fountain_spray",
            "particles",
            [0.0, 1.95, 10.0],
            r#"{ "rate_per_s": 200, "lifetime_s": 1.2, "speed": 2.5, "spread_deg": 15, "size": 0.04, "color": [0.7, 0.85, 1.0, 0.6], "gravity": -9.81, "blend": "alpha" }"#,
        ),
        spawn(
            "brazier_sparks_west",
            "particles",
            [-3.6, 1.6, -1.6],
            r#"{ "rate_per_s": 30, "lifetime_s": 2.0, "speed": 0.8, "spread_deg": 25, "size": 0.02, "color": [1.0, 0.6, 0.2, 1.0], "gravity": 0.5, "blend": "additive" }"#,
        ),
    ]
}

const LEVEL_MIN: Vec3 = Vec3::new(-20.0, 0.0, -20.0);
const LEVEL_MAX: Vec3 = Vec3::new(20.0, 12.0, 22.0);

#[test]
fn spawns_become_emitters_and_flocks_with_their_authored_parameters() {
    let w = world_from_spawns(&temple_spawns(), &[], LEVEL_MIN, LEVEL_MAX);
    assert_eq!((w.emitters.len(), w.flocks.len()), (2, 1));
    // The spawn names label the overlay's sections.
    assert_eq!((w.emitter_names.as_slice(), w.flock_names.as_slice()), (["fountain_spray", "brazier_sparks_west"].map(String::from).as_slice(), ["doves".to_string()].as_slice()));
    let spray = &w.emitters[0].params;
    assert_eq!(spray.position, [0.0, 1.95, 10.0]);
    assert_eq!((spray.rate_per_s, spray.cone_half_angle_deg, spray.gravity), (200.0, 15.0, [0.0, -9.81, 0.0]));
    assert!(
        (spray.life_min_s + spray.life_max_s - 2.4).abs() < 1e-5 && (spray.speed_min + spray.speed_max - 5.0).abs() < 1e-5,
        "means as authored: {spray:?}"
    );
    assert_eq!(spray.color.eval(0.0), [0.7, 0.85, 1.0, 0.6]);
    assert_eq!(spray.color.eval(1.0)[3], 0.0, "fades out by the end of its life");
    assert_eq!(spray.blend, Blend::Alpha);
    assert_eq!(spray.ground_y, Some(LEVEL_MIN.y));
    assert_eq!(w.emitters[1].params.blend, Blend::Additive, "sparks add light");
    assert_ne!(spray.seed, w.emitters[1].params.seed);
    let doves = &w.flocks[0];
    assert_eq!(doves.len(), 32);
    let centre = Vec3::new(0.0, 9.0, 9.0);
    for i in 0..doves.len() {
        let d = doves.state().position(i) - centre;
        assert!(d.abs().max_element() <= 8.0 + 1e-4, "dove {i} starts within the spawn radius: {d}");
        assert!((doves.state().velocity(i).length() - 3.0).abs() < 1e-4);
    }
    let b = doves.params.bounds.expect("the level bounds are an obstacle");
    assert_eq!((b.min, b.max[0], b.max[2]), (LEVEL_MIN.to_array(), LEVEL_MAX.x, LEVEL_MAX.z));
    assert!(b.max[1] >= 9.0 + 8.0, "the box clears the flock's spawn volume: {b:?}");
    assert_eq!(doves.params.goal, Some([0.0, 9.0, 9.0]));
}

#[test]
fn the_level_world_warms_up_and_replays_identically() {
    let mut a = world_from_spawns(&temple_spawns(), &[], LEVEL_MIN, LEVEL_MAX);
    let mut b = world_from_spawns(&temple_spawns(), &[], LEVEL_MIN, LEVEL_MAX);
    warm_up(&mut a);
    warm_up(&mut b);
    // About rate × mean life particles alive after 2 s (1.2 s lives: the fountain is steady).
    let spray = a.emitters[0].particles.len();
    assert!((180..=300).contains(&spray), "{spray} spray particles after the warm-up");
    for _ in 0..30 {
        a.update(1.0 / 60.0);
        b.update(1.0 / 60.0);
    }
    for (x, y) in a.emitters.iter().zip(&b.emitters) {
        assert_eq!(x.particles, y.particles);
    }
    let (fa, fb) = (a.flocks[0].state(), b.flocks[0].state());
    assert_eq!((&fa.px, &fa.py, &fa.pz, &fa.roll), (&fb.px, &fb.py, &fb.pz, &fb.roll));
    for i in 0..fa.len() {
        let v = fa.velocity(i).length();
        assert!((1.8 - 1e-3..=4.5 + 1e-3).contains(&v), "dove {i} flies within its speed limits: {v}");
    }
}

/// A portico column of the temple as the cooker records it.
fn column() -> pack::Pillar {
    pack::Pillar {
        name: "portico_columns[2]".into(),
        centre: [-2.0, 3.6],
        radius: 0.45,
        y_min: 0.5,
        y_max: 7.3,
    }
}

/// Inside the pillar's solid (not merely within its avoidance range).
fn inside(p: Vec3, c: &pack::Pillar) -> bool {
    let r = ((p.x - c.centre[0]).powi(2) + (p.z - c.centre[1]).powi(2)).sqrt();
    r < c.radius && p.y > c.y_min && p.y < c.y_max
}

/// A flock of 200 spawned 10 m from the column and sent at a point on its axis for 10 s: returns
/// the boid-steps spent inside the column and the closest any boid came to its axis.
fn fly_at_column(with_pillar: bool, goal_weight: f32) -> (usize, f32) {
    let c = column();
    let spawns = [Spawn {
        name: "swarm".into(),
        kind: "boids".into(),
        position: [c.centre[0], 4.0, c.centre[1] + 10.0],
        rotation: [0.0, 0.0, 0.0, 1.0],
        params: serde_json::from_str(r#"{ "count": 200, "radius": 3.0, "speed": 3.0 }"#).unwrap(),
    }];
    let pillars = if with_pillar { vec![c.clone()] } else { vec![] };
    let mut w = world_from_spawns(&spawns, &pillars, LEVEL_MIN, LEVEL_MAX);
    assert_eq!(w.flocks[0].params.pillars.len(), pillars.len(), "the level's pillars reach the flock");
    w.flocks[0].params.goal = Some([c.centre[0], 4.0, c.centre[1]]);
    w.flocks[0].params.goal_weight = goal_weight;
    let (mut entered, mut closest) = (0, f32::INFINITY);
    for _ in 0..1200 {
        w.flocks[0].step(1.0 / 120.0, engine::sim::boids::NeighbourSearch::Grid);
        let s = w.flocks[0].state();
        for i in 0..s.len() {
            let p = s.position(i);
            entered += inside(p, &c) as usize;
            closest = closest.min(((p.x - c.centre[0]).powi(2) + (p.z - c.centre[1]).powi(2)).sqrt());
        }
    }
    (entered, closest)
}

#[test]
fn boids_aimed_at_a_pillar_never_enter_it() {
    let (entered, closest) = fly_at_column(true, 1.0);
    assert_eq!(entered, 0, "boid-steps inside the column");
    // The goal urge holds them where it balances the repulsion, inside the avoidance range.
    let range = engine::sim::boids::BoidParams::default().avoid_distance;
    assert!(closest < column().radius + range, "the flock reached the column's field (closest axis distance {closest} m)");
    // A goal urge far above the budget changes nothing: the obstacle urge is served first.
    let (entered, closest) = fly_at_column(true, 50.0);
    assert_eq!(entered, 0, "boid-steps inside the column with a strong goal");
    assert!(closest < column().radius + range, "closest axis distance {closest} m");
    let (entered, _) = fly_at_column(false, 1.0);
    assert!(entered > 0, "without the pillar the flock flies through the column");
}

#[test]
fn the_blend_comes_from_the_blend_key_and_is_alpha_without_one_whatever_the_name() {
    let particles = |name: &str, params: &str| Spawn {
        name: name.into(),
        kind: "particles".into(),
        position: [0.0; 3],
        rotation: [0.0, 0.0, 0.0, 1.0],
        params: serde_json::from_str(params).unwrap(),
    };
    let spawns = [
        particles("sparks", r#"{ "blend": "alpha" }"#),
        particles("mist", r#"{ "blend": "additive" }"#),
        particles("sparks_unset", "{}"),
        particles("mist_unset", "{}"),
    ];
    let w = world_from_spawns(&spawns, &[], LEVEL_MIN, LEVEL_MAX);
    let blends: Vec<Blend> = w.emitters.iter().map(|e| e.params.blend).collect();
    assert_eq!(blends, [Blend::Alpha, Blend::Additive, Blend::Alpha, Blend::Alpha]);
}
