//! A character walking a route: a closed loop from its spawn point through the level's
//! waypoints and back, at a constant ground speed, facing where it goes. The animation clip
//! plays on top (the walk cycle); the route only moves and turns the whole character.
//!
//! Headings turn smoothly: over the last `TURN` metres before a waypoint the yaw blends from
//! one leg's direction into the next one's (smoothstep), so a character never snaps around a
//! corner. Characters face +Z in their own space (glTF's convention for an asset's front).

use glam::{Mat4, Quat, Vec3};

/// Distance before a waypoint over which the heading turns (capped at half the leg).
const TURN: f32 = 0.8;

#[derive(Debug, Clone, PartialEq)]
pub struct Route {
    /// Loop points: the spawn position first, then the waypoints; the last leg returns to the first.
    points: Vec<Vec3>,
    /// Distance along the loop at which each point is reached (`cumulative[0]` is 0).
    cumulative: Vec<f32>,
    length: f32,
    /// Metres per second along the loop.
    pub speed: f32,
    /// Distance walked so far, in [0, length).
    pub distance: f32,
}

impl Route {
    /// None when the loop has no length (every point the same): the character stands still.
    pub fn new(start: Vec3, waypoints: &[Vec3], speed: f32) -> Option<Route> {
        let mut points = vec![start];
        points.extend_from_slice(waypoints);
        let mut cumulative = Vec::with_capacity(points.len());
        let mut length = 0.0;
        for i in 0..points.len() {
            cumulative.push(length);
            length += points[i].distance(points[(i + 1) % points.len()]);
        }
        (length > 1e-4 && speed.is_finite()).then_some(Route { points, cumulative, length, speed, distance: 0.0 })
    }

    pub fn length(&self) -> f32 {
        self.length
    }

    /// Walk `dt` seconds further along the loop.
    pub fn advance(&mut self, dt: f32) {
        self.distance = (self.distance + dt * self.speed).rem_euclid(self.length);
    }

    /// Yaw (radians about +Y) that turns +Z towards `d`; `fallback` for a vertical or empty `d`.
    fn yaw(d: Vec3, fallback: f32) -> f32 {
        if d.x * d.x + d.z * d.z < 1e-12 {
            fallback
        } else {
            d.x.atan2(d.z)
        }
    }

    /// Position and yaw at the current distance.
    pub fn at(&self) -> (Vec3, f32) {
        let n = self.points.len();
        let s = self.distance;
        let leg = self.cumulative.partition_point(|&c| c <= s).saturating_sub(1);
        let (a, b) = (self.points[leg], self.points[(leg + 1) % n]);
        let leg_len = a.distance(b).max(1e-6);
        let along = s - self.cumulative[leg];
        let position = a.lerp(b, (along / leg_len).clamp(0.0, 1.0));
        let here = Route::yaw(b - a, 0.0);
        // Blend into the next leg's heading over the end of this leg.
        let next = Route::yaw(self.points[(leg + 2) % n] - b, here);
        let turn = TURN.min(0.5 * leg_len);
        let x = ((along - (leg_len - turn)) / turn).clamp(0.0, 1.0);
        let w = 0.5 * (x * x * (3.0 - 2.0 * x));
        // Half the blend here, half at the start of the next leg: the heading is continuous at
        // the waypoint, where both legs give the mid-angle.
        let prev = Route::yaw(a - self.points[(leg + n - 1) % n], here);
        let y = (along / turn).clamp(0.0, 1.0);
        let into = 0.5 * (1.0 - y * y * (3.0 - 2.0 * y));
        let yaw = here + w * wrap(next - here) + into * wrap(prev - here);
        (position, yaw)
    }

    /// The character's world placement now: at the route's position, facing along it.
    pub fn placement(&self) -> Mat4 {
        let (p, yaw) = self.at();
        Mat4::from_rotation_translation(Quat::from_rotation_y(yaw), p)
    }
}

/// An angle difference wrapped into [-pi, pi), so blends turn the short way.
fn wrap(a: f32) -> f32 {
    (a + std::f32::consts::PI).rem_euclid(std::f32::consts::TAU) - std::f32::consts::PI
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> Route {
        // Spawn at the origin, then (4,0,0), (4,0,4), (0,0,4): a 16 m loop.
        Route::new(Vec3::ZERO, &[Vec3::new(4.0, 0.0, 0.0), Vec3::new(4.0, 0.0, 4.0), Vec3::new(0.0, 0.0, 4.0)], 2.0).unwrap()
    }

    #[test]
    fn walks_the_loop_at_its_speed_and_wraps() {
        let mut r = square();
        assert_eq!(r.length(), 16.0);
        r.advance(1.0); // 2 m along the first leg
        let (p, yaw) = r.at();
        assert!((p - Vec3::new(2.0, 0.0, 0.0)).length() < 1e-5, "{p}");
        // Mid-leg the character faces along +X: +Z turned by +90 degrees about Y.
        assert!((yaw - std::f32::consts::FRAC_PI_2).abs() < 1e-5, "{yaw}");
        let facing = r.placement().transform_vector3(Vec3::Z);
        assert!((facing - Vec3::X).length() < 1e-5, "{facing}");
        r.advance(3.5); // 9 m: 1 m along the third leg, from (4,0,4) towards (0,0,4)
        assert!((r.at().0 - Vec3::new(3.0, 0.0, 4.0)).length() < 1e-5);
        r.advance(4.0); // 17 m = 1 m into the next lap
        assert!((r.at().0 - Vec3::new(1.0, 0.0, 0.0)).length() < 1e-5, "{}", r.at().0);
    }

    #[test]
    fn the_heading_turns_smoothly_through_a_corner() {
        let mut r = square();
        let mut last = r.at().1;
        let mut biggest = 0.0f32;
        // 16 m in 1 cm steps: no jump in heading anywhere (a snap would be a quarter turn).
        for _ in 0..1600 {
            r.advance(0.005);
            let yaw = r.at().1;
            biggest = biggest.max(wrap(yaw - last).abs());
            last = yaw;
        }
        assert!(biggest < 0.05, "largest heading step per cm: {biggest} rad");
        // At the corner (4,0,0) the heading is halfway between +X (pi/2) and +Z (0).
        r.distance = 4.0;
        assert!((r.at().1 - std::f32::consts::FRAC_PI_4).abs() < 1e-4, "{}", r.at().1);
    }

    #[test]
    fn a_route_without_length_is_none() {
        assert!(Route::new(Vec3::ONE, &[Vec3::ONE], 1.0).is_none());
        assert!(Route::new(Vec3::ONE, &[], 1.0).is_none());
    }
}
