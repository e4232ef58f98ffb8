//! How a boid's urges share its acceleration budget (in priority order, not averaged) and how
//! its speed is held in [min, max], for one boid and for eight at a time (`boids`).

use super::lanes::{self, F, LANES, V3};
use glam::{Quat, Vec3};

/// Hands `budget` out to `urges` in order: each gets min(|u|, remaining) along its own direction.
/// Returns the summed acceleration and the magnitude each urge received.
pub fn allocate<const N: usize>(urges: [Vec3; N], budget: f32) -> (Vec3, [f32; N]) {
    let mut remaining = budget.max(0.0);
    let mut sum = Vec3::ZERO;
    let mut granted = [0.0; N];
    for (k, u) in urges.into_iter().enumerate() {
        let m = u.length();
        if m <= 0.0 || remaining <= 0.0 {
            continue;
        }
        let take = m.min(remaining);
        sum += u * (take / m);
        granted[k] = take;
        remaining -= take;
    }
    (sum, granted)
}

/// `allocate` for eight boids at once, returning the summed accelerations.
pub fn allocate_lanes<const N: usize>(urges: [V3; N], budget: f32) -> V3 {
    let mut remaining = F::splat(budget.max(0.0));
    let mut sum = V3::ZERO;
    for u in urges {
        let m = u.length();
        let skip = m.simd_le(F::ZERO) | remaining.simd_le(F::ZERO);
        let take = m.min(remaining);
        sum = lanes::select(skip, sum, sum + u * (take / m));
        remaining = skip.select(remaining, remaining - take);
    }
    sum
}

/// `limit_speed` for eight boids. Below the minimum speed a lane takes the scalar turn (rare:
/// the budget rarely brakes a boid that far).
pub fn limit_speed_lanes(vel: V3, a: V3, h: f32, min: f32, max: f32) -> V3 {
    let v = vel + a * F::splat(h);
    let speed = v.length();
    let over = speed.simd_gt(F::splat(max));
    let slow = !(over | speed.simd_ge(F::splat(min)));
    let mut out = lanes::select(over, v * (F::splat(max) / speed), v);
    if slow.any() {
        let bits = slow.to_bitmask();
        for k in (0..LANES).filter(|k| bits >> k & 1 == 1) {
            out.set_lane(k, limit_speed(vel.lane(k), a.lane(k), h, min, max));
        }
    }
    out
}

/// v + a·h with the speed held in [min, max]. Above the maximum the velocity is scaled back.
/// Below the minimum (a bird cannot hover) the boid turns instead of slowing: its heading rotates
/// toward `a` at the rate |a|/min that the acceleration allows at that speed, so |Δv| stays
/// within |a|·h; an acceleration straight against the heading turns it to the right. Scaling
/// up instead would keep a boid braking head-on into a wall flying into it at the minimum
/// speed forever. A boid that starts below the minimum is brought up to it along its heading.
pub fn limit_speed(vel: Vec3, a: Vec3, h: f32, min: f32, max: f32) -> Vec3 {
    let v = vel + a * h;
    let speed = v.length();
    if speed > max {
        return v * (max / speed);
    }
    if speed >= min {
        return v;
    }
    let speed0 = vel.length();
    let (Some(f), Some(target)) = (vel.try_normalize(), a.try_normalize()) else {
        return v.try_normalize().or(vel.try_normalize()).unwrap_or(Vec3::Z) * min;
    };
    if speed0 < min {
        return v.try_normalize().unwrap_or(f) * min;
    }
    let cos = f.dot(target).clamp(-1.0, 1.0);
    let axis = f.cross(target).try_normalize().or(f.cross(Vec3::Y).try_normalize()).unwrap_or(f.any_orthonormal_vector());
    let theta = (a.length() * h / min).min(cos.acos());
    Quat::from_axis_angle(axis, theta) * f * min
}
