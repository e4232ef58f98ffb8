//! Acceptance tests of issue 8's simulation core: particles (notes §7) and boids (notes §8).
//! Numbers come from ../shared/notes/animation.md; each test says which.

use engine::sim::boids::{BoidParams, Flock, FlockState};
use engine::sim::clock::{ClockParams, FixedClock};
use engine::sim::grid::{brute_force_neighbours, Grid};
use engine::sim::particles::{Attractor, Billboard, BillboardScratch, Blend, EmitterParams, ParticleSystem, Preset};
use engine::sim::rng::Rng;
use engine::sim::World;
use glam::Vec3;

mod sim_common;
use sim_common::{ballistic, busy_params, flock_bits, live_state, pool, G};





// ---- particles ------------------------------------------------------------------------------

#[test]
fn projectile_error_is_the_semi_implicit_bound() {
    // Notes §7 test 1: v0 = 5 up, g = −9.81, T = 1. Semi-implicit Euler lands +½·g·T·h from
    // the parabola (−0.4905 at h = 0.1, −0.04905 at h = 0.01): within |½·g·T·h|, and on the
    // low side.
    for steps_per_s in [10u32, 100, 120] {
        let h = 1.0 / steps_per_s as f32;
        let mut s = ParticleSystem::new(ballistic(1));
        assert!(s.particles.push(Vec3::ZERO, Vec3::new(0.0, 5.0, 0.0), 10.0));
        for _ in 0..steps_per_s {
            s.step(h);
        }
        let exact = 5.0 - 0.5 * G;
        let err = s.particles.py[0] - exact;
        let bound = 0.5 * G * h;
        assert!((err + bound).abs() < 1e-4, "h = {h}: error {err}, expected {}", -bound);
        assert!(err.abs() <= bound + 1e-4);
        assert_eq!((s.particles.px[0], s.particles.pz[0]), (0.0, 0.0));
    }
}

fn spring_energy_band(omega: f32, h: f32, steps: usize) -> (f32, f32) {
    let params = EmitterParams {
        gravity: [0.0; 3],
        attractor: Some(Attractor {
            position: [0.0; 3],
            stiffness_per_s2: omega * omega,
        }),
        ..ballistic(1)
    };
    let mut s = ParticleSystem::new(params);
    s.particles.push(Vec3::new(1.0, 0.0, 0.0), Vec3::ZERO, 1e9);
    let energy = |s: &ParticleSystem| 0.5 * s.particles.velocity(0).length_squared() + 0.5 * omega * omega * s.particles.position(0).length_squared();
    let e0 = energy(&s);
    let (mut lo, mut hi) = (1.0f32, 1.0f32);
    for _ in 0..steps {
        s.step(h);
        let r = energy(&s) / e0;
        (lo, hi) = (lo.min(r), hi.max(r));
    }
    (lo, hi)
}

#[test]
fn spring_energy_stays_within_five_percent_over_1000_steps() {
    // A 1 Hz spring at the default step (ωh = 0.052): symplectic Euler's energy band is about
    // ±ωh/2. Explicit Euler would have grown it 15-fold over these 1000 steps.
    let h = 1.0 / ClockParams::default().steps_per_s as f32;
    let (lo, hi) = spring_energy_band(std::f32::consts::TAU, h, 1000);
    assert!(lo >= 0.95 && hi <= 1.05, "E/E0 in [{lo}, {hi}]");
    // Notes §7 test 2 in the particle code (f32): ω = 1, h = 0.1, T = 100 gives [0.952, 1.053].
    let (lo, hi) = spring_energy_band(1.0, 0.1, 1000);
    assert!((lo - 0.9524).abs() < 1e-3 && (hi - 1.0526).abs() < 1e-3, "E/E0 in [{lo}, {hi}]");
}

#[test]
fn exact_drag_never_overshoots_terminal_velocity() {
    // Notes §7 test 3: at kh = 5 explicit Euler would diverge; the exponential approaches
    // −g/k from above, monotonically.
    let h = 1.0 / 120.0;
    let k = 5.0 / h;
    let mut s = ParticleSystem::new(EmitterParams { drag_per_s: k, ..ballistic(1) });
    s.particles.push(Vec3::ZERO, Vec3::ZERO, 1e9);
    let terminal = -G / k;
    let mut prev = 0.0;
    for _ in 0..50 {
        s.step(h);
        let v = s.particles.vy[0];
        assert!(v < prev + 1e-9 && v >= terminal * (1.0 + 1e-5), "v {v}, terminal {terminal}");
        prev = v;
    }
    assert!((prev - terminal).abs() < 1e-6 * terminal.abs().max(1.0));
}

fn run_frames(params: &EmitterParams, fps: u32, seconds: u32) -> (ParticleSystem, FixedClock) {
    let mut clock = FixedClock::new(ClockParams::default());
    let mut s = ParticleSystem::new(params.clone());
    for _ in 0..fps * seconds {
        for _ in 0..clock.advance(1.0 / fps as f64) {
            s.step(clock.dt());
        }
    }
    (s, clock)
}

#[test]
fn fixed_step_gives_the_same_particles_at_30_and_144_fps() {
    // Notes §7 test 5: bitwise identical after 1 s (a fountain: spawning, drag, ground bounces).
    let params = EmitterParams::preset(Preset::Fountain);
    let (a, ca) = run_frames(&params, 30, 1);
    let (b, cb) = run_frames(&params, 144, 1);
    assert_eq!((ca.steps, cb.steps), (120, 120));
    assert!(a.particles.len() > 1000, "the fountain should be running: {}", a.particles.len());
    assert_eq!(a.counters, b.counters);
    assert!(live_state(&a) == live_state(&b), "30 and 144 fps differ");
}

#[test]
fn world_state_is_the_same_at_30_and_144_fps() {
    // The world's one clock drives emitters and flocks alike: 2 s at either frame rate, same bits.
    let run = |fps: u32| {
        let mut w = World::new(FixedClock::new(ClockParams::default()));
        w.emitters.push(ParticleSystem::new(EmitterParams::preset(Preset::Sparks)));
        w.emitters.push(ParticleSystem::new(EmitterParams::preset(Preset::Smoke)));
        w.flocks
            .push(Flock::new(busy_params(2), FlockState::random(500, Vec3::new(-30.0, 2.0, -30.0), Vec3::new(30.0, 25.0, 30.0), 5.0, 2)));
        let steps: u32 = (0..2 * fps).map(|_| w.update(1.0 / fps as f64)).sum();
        assert_eq!(steps, 240, "{fps} fps");
        (w.emitters.iter().map(live_state).collect::<Vec<_>>(), flock_bits(&w.flocks[0]))
    };
    assert!(run(30) == run(144), "30 and 144 fps worlds differ");
}

#[test]
fn set_params_resizes_storage_and_keeps_live_particles() {
    let mut s = ParticleSystem::new(EmitterParams {
        rate_per_s: 1000.0,
        capacity: 100,
        life_min_s: 10.0,
        life_max_s: 10.0,
        ..ballistic(0)
    });
    for _ in 0..12 {
        s.step(1.0 / 120.0);
    }
    assert_eq!(s.particles.len(), 100);
    let kept = live_state(&s)[..40].to_vec();
    s.set_params(EmitterParams { capacity: 40, ..s.params.clone() });
    assert_eq!((s.particles.len(), s.particles.capacity()), (40, 40));
    assert!(live_state(&s) == kept);
    s.set_params(EmitterParams { capacity: 200, ..s.params.clone() });
    s.step(1.0 / 120.0);
    assert_eq!(s.particles.len(), 48);
}

#[test]
fn emitter_lifecycle_counts() {
    // Notes §7 test 4: rate r for time T spawns floor(r·T); the steady population is r·L ± 1;
    // no particle outlives L; the same seed gives the same state.
    let h = 1.0 / 120.0;
    let params = EmitterParams {
        rate_per_s: 100.0,
        life_min_s: 2.0,
        life_max_s: 2.0,
        capacity: 1000,
        ..ballistic(0)
    };
    let mut s = ParticleSystem::new(params.clone());
    for step in 1..=600 {
        s.step(h);
        let p = &s.particles;
        assert!((0..p.len()).all(|i| p.age[i] < p.life[i]), "a particle outlived its lifetime");
        if step == 120 {
            assert_eq!(s.counters.spawned, 100);
        }
        if step > 300 {
            assert!((p.len() as i64 - 200).abs() <= 1, "population {} at step {step}", p.len());
        }
    }
    assert_eq!(s.counters.spawned, 500);
    assert_eq!(s.counters.died as usize + s.particles.len(), 500);
    for rate in [37.0f32, 0.5, 1234.5] {
        let mut s = ParticleSystem::new(EmitterParams {
            rate_per_s: rate,
            capacity: 10_000,
            life_min_s: 100.0,
            life_max_s: 100.0,
            ..ballistic(0)
        });
        for _ in 0..240 {
            s.step(h);
        }
        assert_eq!(s.counters.spawned, (rate as f64 * 2.0).floor() as u64, "rate {rate}");
    }
    let fountain = EmitterParams::preset(Preset::Fountain);
    let (a, _) = run_frames(&fountain, 60, 1);
    let (b, _) = run_frames(&fountain, 60, 1);
    let (c, _) = run_frames(&EmitterParams { seed: 2, ..fountain }, 60, 1);
    assert!(live_state(&a) == live_state(&b));
    assert!(live_state(&a) != live_state(&c), "the seed changes nothing");
}

#[test]
fn full_emitter_drops_spawns_without_reallocating() {
    let params = EmitterParams {
        rate_per_s: 1000.0,
        capacity: 50,
        life_min_s: 10.0,
        life_max_s: 10.0,
        ..ballistic(0)
    };
    let mut s = ParticleSystem::new(params);
    let before = (s.particles.px.as_ptr(), s.particles.life.as_ptr());
    for _ in 0..120 {
        s.step(1.0 / 120.0);
    }
    assert_eq!(s.particles.len(), 50);
    assert_eq!((s.counters.spawned, s.counters.dropped), (50, 950));
    assert_eq!((s.particles.px.as_ptr(), s.particles.life.as_ptr()), before);
}

#[test]
fn ground_bounce_apex_ratio_is_restitution_squared() {
    // Notes §7 test 6: apex heights shrink by about e² per bounce; the particle never ends a
    // step below the plane.
    let e = 0.6;
    let params = EmitterParams {
        ground_y: Some(0.0),
        restitution: e,
        friction: 0.0,
        ..ballistic(1)
    };
    let mut s = ParticleSystem::new(params);
    s.particles.push(Vec3::new(0.0, 5.0, 0.0), Vec3::new(1.0, 0.0, 0.0), 1e9);
    let mut apexes = vec![5.0f32];
    let mut prev_vy = 0.0f32;
    for _ in 0..(6 * 120) {
        s.step(1.0 / 120.0);
        let (y, vy) = (s.particles.py[0], s.particles.vy[0]);
        assert!(y >= 0.0, "below the ground: {y}");
        if prev_vy > 0.0 && vy <= 0.0 {
            apexes.push(y);
        }
        prev_vy = vy;
    }
    assert!(apexes.len() >= 4, "apexes {apexes:?}");
    // Projection onto the plane loses up to one step of travel per bounce, a relative error of
    // about v·h/height: 3% holds while the apexes are above half a metre at h = 1/120.
    let tall: Vec<f32> = apexes.iter().copied().take_while(|&y| y > 0.5).collect();
    assert!(tall.len() >= 3, "apexes {apexes:?}");
    for w in tall.windows(2) {
        let ratio = w[1] / w[0];
        assert!((ratio / (e * e) - 1.0).abs() < 0.03, "apex ratio {ratio}, e² = {}: {apexes:?}", e * e);
    }
    // No friction: the horizontal velocity survives the bounces.
    assert_eq!(s.particles.vx[0], 1.0);
}

#[test]
fn particle_update_is_the_same_for_one_and_two_threads() {
    let params = EmitterParams {
        rate_per_s: 60_000.0,
        capacity: 100_000,
        ..EmitterParams::preset(Preset::Sparks)
    };
    let run = |threads| pool(threads).install(|| run_frames(&params, 60, 1).0);
    let (a, b) = (run(1), run(2));
    assert!(a.particles.len() > 20_000);
    assert!(live_state(&a) == live_state(&b));
}

#[test]
fn billboards_come_back_to_front_for_alpha_and_in_storage_order_for_additive() {
    let mut s = ParticleSystem::new(EmitterParams {
        rate_per_s: 20_000.0,
        capacity: 20_000,
        ..EmitterParams::preset(Preset::Smoke)
    });
    for _ in 0..60 {
        s.step(1.0 / 120.0);
    }
    let n = s.particles.len();
    assert!(n > 5000);
    let (camera, forward) = (Vec3::new(3.0, 1.0, 4.0), Vec3::new(-0.6, 0.0, -0.8));
    let (mut out, mut scratch) = (Vec::new(), BillboardScratch::default());
    s.fill_billboards(camera, forward, 0.0, &mut out, &mut scratch);
    assert_eq!(out.len(), n);
    let depth = |b: &Billboard| (Vec3::from(b.position) - camera).dot(forward);
    assert!(out.windows(2).all(|w| depth(&w[0]) >= depth(&w[1])), "not back to front");
    // Every particle exactly once.
    let mut xs: Vec<u32> = out.iter().map(|b| b.position[0].to_bits()).collect();
    let mut want: Vec<u32> = s.particles.px[..n].iter().map(|x| x.to_bits()).collect();
    xs.sort_unstable();
    want.sort_unstable();
    assert_eq!(xs, want);

    s.params.blend = Blend::Additive;
    s.fill_billboards(camera, forward, 0.0, &mut out, &mut scratch);
    for i in [0, n / 2, n - 1] {
        let t = s.particles.age[i] / s.particles.life[i];
        assert_eq!(out[i].position, s.particles.position(i).to_array());
        assert_eq!(out[i].size, s.params.size.eval(t));
        assert_eq!(out[i].color, s.params.color.eval(t));
    }
    // Extrapolation moves a billboard along its velocity.
    s.fill_billboards(camera, forward, 0.5, &mut out, &mut scratch);
    let moved = s.particles.position(0) + s.particles.velocity(0) * 0.5;
    assert!((Vec3::from(out[0].position) - moved).length() < 1e-5);
}

#[test]
fn parameters_fill_defaults_from_partial_tables() {
    let e: EmitterParams = serde_json::from_str(r#"{ "rate_per_s": 5.0, "blend": "additive", "ground_y": 1.5 }"#).unwrap();
    assert_eq!((e.rate_per_s, e.blend, e.ground_y), (5.0, Blend::Additive, Some(1.5)));
    assert_eq!(e.capacity, EmitterParams::default().capacity);
    let b: BoidParams = serde_json::from_str(r#"{ "speed_max": 4.0, "pillars": [{ "centre": [1, 2], "radius": 0.5, "y_min": 0, "y_max": 6 }] }"#).unwrap();
    assert_eq!((b.speed_max, b.pillars.len()), (4.0, 1));
    assert_eq!(b.neighbour_radius, BoidParams::default().neighbour_radius);
    let round: BoidParams = serde_json::from_str(&serde_json::to_string(&b).unwrap()).unwrap();
    assert_eq!(round, b);
}

// ---- boids: neighbour search ------------------------------------------------------------------

#[test]
fn grid_neighbours_equal_brute_force() {
    // Notes §8 test 1: 10k random points in [−50, 50]³, plus points exactly on cell borders and
    // pairs exactly R apart; R = cell and R < cell.
    let build_r = 5.0f32;
    let mut rng = Rng::new(11);
    let (mut px, mut py, mut pz) = (Vec::new(), Vec::new(), Vec::new());
    let mut push = |p: Vec3| {
        px.push(p.x);
        py.push(p.y);
        pz.push(p.z);
    };
    for _ in 0..10_000 {
        push(Vec3::new(rng.range(-50.0, 50.0), rng.range(-50.0, 50.0), rng.range(-50.0, 50.0)));
    }
    let cell = {
        let mut g = Grid::new();
        g.build(&[0.0, 50.0], &[0.0, 50.0], &[0.0, 50.0], build_r);
        g.cell_size()
    };
    for k in -10i32..=10 {
        // On borders of the grid's own cells, and on whole multiples of R.
        let b = k as f32 * cell;
        push(Vec3::new(b, 0.3 * k as f32, -b));
        // On the middles of cells, where a query switches which neighbour cell it reads.
        let m = (k as f32 + 0.5) * cell;
        push(Vec3::new(m, -m, 0.5 * cell));
        push(Vec3::new(k as f32 * build_r, k as f32 * build_r, 7.0));
        // A pair exactly R (and exactly 3) apart along each axis, at negative coordinates.
        let base = Vec3::new(-20.0 + k as f32, -13.0, -31.0);
        push(base);
        push(base + Vec3::new(build_r, 0.0, 0.0));
        push(base + Vec3::new(0.0, 3.0, 0.0));
        push(base - Vec3::new(0.0, 0.0, build_r));
    }
    let mut grid = Grid::new();
    grid.build(&px, &py, &pz, build_r);
    assert_eq!(grid.cell_size(), cell);
    let (mut a, mut b) = (Vec::new(), Vec::new());
    let mut total = 0;
    for r in [build_r, 3.0] {
        for i in 0..px.len() {
            let p = Vec3::new(px[i], py[i], pz[i]);
            a.clear();
            b.clear();
            grid.neighbours(p, r, Some(i as u32), &mut a);
            brute_force_neighbours(&px, &py, &pz, p, r, Some(i as u32), &mut b);
            a.sort_unstable();
            assert_eq!(a, b, "point {i} at {p}, r {r}");
            total += a.len();
        }
        // A query point off the points themselves, outside the occupied box.
        a.clear();
        b.clear();
        grid.neighbours(Vec3::new(-54.0, 0.0, 0.0), r, None, &mut a);
        brute_force_neighbours(&px, &py, &pz, Vec3::new(-54.0, 0.0, 0.0), r, None, &mut b);
        a.sort_unstable();
        assert_eq!(a, b);
    }
    assert!(total > 10_000, "too few neighbours to test anything: {total}");
}

// ---- boids: rules -----------------------------------------------------------------------------
