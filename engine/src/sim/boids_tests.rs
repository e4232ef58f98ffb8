//! Tests of `boids` (a file of their own to keep the module readable).

use super::*;

/// The rules one boid at a time in scalar glam, as they were before the lanes: the
/// reference `StepContext::rules` must agree with to the bit.
mod reference {
    use super::super::*;

    /// Repulsion from a surface at signed distance `d` (negative inside) with outward normal `n`:
    /// zero beyond `range`, rising linearly to `strength` at contact, `strength` inside.
    fn repel(d: f32, n: Vec3, range: f32, strength: f32) -> Vec3 {
        if d >= range {
            return Vec3::ZERO;
        }
        n * (strength * ((range - d) / range).min(1.0))
    }

    /// Signed distance from `p` to a box and the outward normal there.
    fn box_distance(p: Vec3, b: &Aabb) -> (f32, Vec3) {
        let (lo, hi) = (Vec3::from(b.min), Vec3::from(b.max));
        let q = p.clamp(lo, hi);
        let out = p - q;
        let d = out.length();
        if d > 0.0 {
            return (d, out / d);
        }
        // Inside: the nearest face.
        let mut best = (f32::INFINITY, Vec3::ZERO);
        for a in 0..3 {
            let mut n = Vec3::ZERO;
            for (depth, sign) in [(p[a] - lo[a], -1.0), (hi[a] - p[a], 1.0)] {
                if depth < best.0 {
                    n[a] = sign;
                    best = (depth, n);
                    n[a] = 0.0;
                }
            }
        }
        (-best.0, best.1)
    }

    /// Signed distance from `p` to a capped vertical cylinder and the outward normal there.
    fn pillar_distance(p: Vec3, c: &Pillar) -> (f32, Vec3) {
        let radial = glam::Vec2::new(p.x - c.centre[0], p.z - c.centre[1]);
        let r = radial.length();
        let dir = if r > 0.0 { radial / r } else { glam::Vec2::X };
        let side = (r - c.radius, Vec3::new(dir.x, 0.0, dir.y));
        let (below, above) = (c.y_min - p.y, p.y - c.y_max);
        let cap = if above > below { (above, Vec3::Y) } else { (below, Vec3::NEG_Y) };
        if side.0 > 0.0 && cap.0 > 0.0 {
            // Past the rim: distance to the circular edge.
            let off = side.1 * side.0 + cap.1 * cap.0;
            let d = off.length();
            return (d, off / d);
        }
        if side.0 > cap.0 {
            side
        } else {
            cap
        }
    }

    /// atan within about 1e-7 of libm's (Abramowitz & Stegun 4.4.49, |ε| ≤ 2·10⁻⁸ on [0, 1], and
    /// atan x = π/2 − atan(1/x) beyond): a polynomial instead of a libm call per boid and step.
    fn atan(x: f32) -> f32 {
        let a = x.abs();
        let big = a > 1.0;
        let t = if big { 1.0 / a } else { a };
        let t2 = t * t;
        let poly = -0.333_331_45
            + t2 * (0.199_935_51 + t2 * (-0.142_088_99 + t2 * (0.106_562_64 + t2 * (-0.075_289_64 + t2 * (0.042_909_61 + t2 * (-0.016_165_737 + t2 * 0.002_866_225_7))))));
        let r = t + t * t2 * poly;
        let r = if big { std::f32::consts::FRAC_PI_2 - r } else { r };
        r.copysign(x)
    }

    fn obstacles(p: &BoidParams, pos: Vec3) -> Vec3 {
        let (range, strength) = (p.avoid_distance.max(1e-3), p.obstacle_weight * p.accel_max);
        let mut u = Vec3::ZERO;
        if let Some(b) = &p.bounds {
            for a in 0..3 {
                let mut n = Vec3::ZERO;
                n[a] = 1.0;
                u += repel(pos[a] - b.min[a], n, range, strength);
                u += repel(b.max[a] - pos[a], -n, range, strength);
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

    fn goal(p: &BoidParams, t: f32, i: usize, pos: Vec3, vel: Vec3) -> Vec3 {
        if let Some(g) = p.goal {
            let desired = (Vec3::from(g) - pos).try_normalize().unwrap_or(Vec3::ZERO) * p.speed_max;
            return (desired - vel) * p.goal_weight;
        }
        if p.wander_weight == 0.0 {
            return Vec3::ZERO;
        }
        let phase = t / p.wander_period_s.max(1e-3);
        let k = phase.floor();
        let w = phase - k;
        let smooth = w * w * (3.0 - 2.0 * w);
        let heading = |period: u64| wander_heading(p.seed, i, period);
        let dir = heading(k as u64).lerp(heading(k as u64 + 1), smooth).try_normalize().unwrap_or(Vec3::X);
        (dir * p.speed_max - vel) * p.wander_weight
    }

    /// Lane `l` of `StepContext::rules`.
    pub fn rules(ctx: &StepContext, g: &Group, l: usize) -> (Vec3, Vec3, f32) {
        let p = ctx.p;
        let (i, pos, vel) = (g.index[l], g.pos[l], g.vel[l]);
        let urges = [
            obstacles(p, pos),
            g.sep[l] * p.separation_weight,
            g.alignment[l] * p.alignment_weight,
            g.cohesion[l] * p.cohesion_weight,
            goal(p, ctx.t, i, pos, vel),
        ];
        let (a, _) = allocate(urges, p.accel_max);
        let v = limit_speed(vel, a, ctx.h, p.speed_min, p.speed_max);
        let applied = (v - vel) / ctx.h;
        let right = v.cross(Vec3::Y).try_normalize();
        let target = right.map_or(0.0, |r| atan(applied.dot(r) / GRAVITY).clamp(-ctx.max_bank, ctx.max_bank));
        (pos + v * ctx.h, v, g.roll[l] + (target - g.roll[l]) * ctx.bank_follow)
    }

    pub fn atan_scalar(x: f32) -> f32 {
        atan(x)
    }
}

#[test]
fn polynomial_atan_matches_libm_and_the_lanes_match_the_scalar_bits() {
    let mut xs: Vec<f32> = (-200_000..=200_000).map(|k| k as f32 * 1e-4).collect();
    xs.extend([1e-30f32, 1e6, -1e6, f32::MAX, f32::INFINITY, f32::NEG_INFINITY, 0.0, -0.0]);
    let mut worst = 0f32;
    for x in xs.chunks(LANES) {
        let lane: [f32; LANES] = std::array::from_fn(|k| x[k.min(x.len() - 1)]);
        let got = atan(F::new(lane)).to_array();
        for k in 0..LANES {
            worst = worst.max((got[k] - lane[k].atan()).abs());
            assert_eq!(got[k].to_bits(), reference::atan_scalar(lane[k]).to_bits(), "atan({})", lane[k]);
        }
    }
    assert!(worst < 5e-7, "worst error {worst}");
}

/// A flock strewn through and around two boxes and two pillars, near the bounds, at every
/// speed from standing still to past the limit (so the slow-turn and clamp paths run).
fn awkward_flock(n: usize) -> (BoidParams, FlockState) {
    let params = BoidParams {
        bounds: Some(Aabb { min: [-20.0, 0.0, -20.0], max: [20.0, 15.0, 20.0] }),
        boxes: vec![Aabb { min: [-6.0, 0.0, -6.0], max: [-1.0, 6.0, -1.0] }, Aabb { min: [4.0, 2.0, 4.0], max: [9.0, 4.0, 12.0] }],
        pillars: vec![Pillar { centre: [8.0, -8.0], radius: 1.5, y_min: 0.0, y_max: 9.0 }, Pillar { centre: [-10.0, 10.0], radius: 3.0, y_min: 2.0, y_max: 5.0 }],
        ..BoidParams::default()
    };
    let mut rng = crate::sim::rng::Rng::new(5);
    let mut s = FlockState::random(n, Vec3::new(-22.0, -2.0, -22.0), Vec3::new(22.0, 17.0, 22.0), 5.0, 3);
    for i in 0..n {
        let v = match i % 9 {
            0 => Vec3::ZERO,
            1 => Vec3::Y * 0.5,
            2 => rng.unit_vector() * 1.9,
            3 => rng.unit_vector() * 14.0,
            _ => rng.unit_vector() * rng.range(0.0, 11.0),
        };
        (s.vx[i], s.vy[i], s.vz[i]) = (v.x, v.y, v.z);
        s.roll[i] = rng.range(-1.0, 1.0);
    }
    (s.px[0], s.py[0], s.pz[0]) = (8.0, 4.0, -8.0); // on a pillar's axis
    (s.px[1], s.py[1], s.pz[1]) = (-3.5, 3.0, -3.5); // at a box's centre
    (params, s)
}

#[test]
fn the_rules_in_lanes_give_the_scalar_rules_bits() {
    let grid = Grid::new();
    let (base, state) = awkward_flock(203);
    let goal = BoidParams { goal: Some([3.0, 7.0, -2.0]), ..base.clone() };
    let still = BoidParams { wander_weight: 0.0, ..base.clone() };
    let mut compared = 0;
    for (p, t) in [(&base, 0.0), (&base, 5.3), (&goal, 1.0), (&still, 2.0)] {
        let ctx = StepContext { p, cur: &state, grid: &grid, search: NeighbourSearch::BruteForce, radius: 5.0, h: 1.0 / 60.0, t, max_bank: 1.0, bank_follow: 0.1 };
        let mut buf = Vec::new();
        for start in (0..state.len()).step_by(LANES) {
            let mut g = Group::default();
            for l in 0..LANES {
                let i = (start + l).min(state.len() - 1);
                ctx.neighbourhood(i, i, &mut buf, &mut StepCounters::default(), &mut g, l);
            }
            let (pos, vel, roll) = ctx.rules(&g);
            for l in 0..LANES {
                let (rp, rv, rr) = reference::rules(&ctx, &g, l);
                let bits = |v: Vec3| v.to_array().map(f32::to_bits);
                let i = g.index[l];
                assert_eq!(bits(pos.lane(l)), bits(rp), "boid {i} position: {:?} vs {rp:?}", pos.lane(l));
                assert_eq!(bits(vel.lane(l)), bits(rv), "boid {i} velocity: {:?} vs {rv:?}", vel.lane(l));
                assert_eq!(roll.as_array()[l].to_bits(), rr.to_bits(), "boid {i} roll");
                compared += 1;
            }
        }
    }
    assert_eq!(compared, 4 * 26 * LANES);
}
