//! The scripted camera flight of the headless demo and of the `demo-flythrough` benchmark: from
//! the player's view straight up, once around the level above its roofs looking down at it, and
//! back down onto the player's view, as a closed Catmull-Rom spline through those keys
//! (positions and look-at points), so it loops without a jolt.
//!
//! Derived from the pack's player spawn and bounds, so any level gets a flight that starts where
//! the player stands (at t = 0 it is exactly `Camera::for_pack`) and sees every side of it. It
//! leaves the ground only vertically and flies above the level's bounds, so it never passes
//! through a wall: the runtime keeps no collision geometry to steer around.

use engine::scene::camera::Camera;
use glam::Vec3;

/// Seconds for the whole loop unless the caller chooses.
pub const DEFAULT_SECONDS: f32 = 24.0;

#[derive(Debug, Clone)]
pub struct Flight {
    /// (camera position, point looked at), in order; the loop closes back to the first.
    keys: Vec<(Vec3, Vec3)>,
    start: Camera,
    pub seconds: f32,
}

impl Flight {
    pub fn for_pack(manifest: &pack::Manifest, min: Vec3, max: Vec3, seconds: f32) -> Flight {
        let start = Camera::for_pack(manifest, min, max);
        let eye = start.position;
        let centre = (min + max) * 0.5;
        let ground = Vec3::new(centre.x, eye.y, centre.z);
        let size = (max - min).truncate().length().max(1.0);
        let ahead = Vec3::new(start.forward().x, 0.0, start.forward().z).normalize_or(Vec3::NEG_Z);
        // Above everything: the flight never needs to know where the walls are.
        let high = (max.y + 0.1 * size).max(min.y + 0.75 * (max.y - min.y).max(4.0) + 0.15 * size);
        let radius = 0.45 * size;
        // Round the level, starting from the side the player is on.
        let (dx, dz) = (eye.x - centre.x, eye.z - centre.z);
        let a0 = if dx * dx + dz * dz > 1e-6 { dz.atan2(dx) } else { 0.0 };
        let around = |k: f32| {
            let a = a0 + k * std::f32::consts::FRAC_PI_2;
            Vec3::new(centre.x + radius * a.cos(), high, centre.z + radius * a.sin())
        };
        let above_eye = Vec3::new(eye.x, high, eye.z);
        let keys = vec![
            (eye, eye + start.forward() * 10.0),
            // Straight up from where the player stands, tilting down towards the level's centre.
            (eye.lerp(above_eye, 0.5), ground),
            (around(0.0), centre),
            (around(1.0), centre),
            (around(2.0), centre),
            (around(3.0), centre),
            // Back over the player, then straight down into the first view.
            (above_eye, eye + ahead * 10.0),
        ];
        Flight {
            keys,
            start,
            seconds: seconds.max(1e-3),
        }
    }

    /// The camera `t` seconds into the flight (looping).
    pub fn camera(&self, t: f32) -> Camera {
        let n = self.keys.len();
        let u = (t / self.seconds).rem_euclid(1.0) * n as f32;
        let i = (u.floor() as usize).min(n - 1);
        let f = u - i as f32;
        if i == 0 && f == 0.0 {
            return self.start;
        }
        let key = |k: usize| self.keys[(i + k + n - 1) % n];
        let (p, q) = (catmull_rom(key(0).0, key(1).0, key(2).0, key(3).0, f), catmull_rom(key(0).1, key(1).1, key(2).1, key(3).1, f));
        let dir = (q - p).normalize_or(self.start.forward());
        Camera {
            position: p,
            yaw: (-dir.x).atan2(-dir.z),
            pitch: dir.y.clamp(-1.0, 1.0).asin(),
            ..self.start
        }
    }
}

/// The uniform Catmull-Rom segment from `b` (f = 0) to `c` (f = 1).
fn catmull_rom(a: Vec3, b: Vec3, c: Vec3, d: Vec3, f: f32) -> Vec3 {
    let (f2, f3) = (f * f, f * f * f);
    0.5 * ((2.0 * b) + (c - a) * f + (2.0 * a - 5.0 * b + 4.0 * c - d) * f2 + (3.0 * b - a - 3.0 * c + d) * f3)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn level() -> pack::Manifest {
        let mut m = pack::PackBuilder::new("generated", "test").manifest;
        m.spawns.push(pack::Spawn {
            name: "player".into(),
            kind: "player".into(),
            position: [0.0, 0.0, 18.0],
            rotation: [0.0, 0.0, 0.0, 1.0],
            params: serde_json::Value::Null,
        });
        m
    }

    #[test]
    fn starts_at_the_players_view_and_loops_smoothly() {
        let (min, max) = (Vec3::new(-20.0, 0.0, -20.0), Vec3::new(20.0, 10.0, 20.0));
        let m = level();
        let flight = Flight::for_pack(&m, min, max, 20.0);
        assert_eq!(flight.camera(0.0), Camera::for_pack(&m, min, max));
        // Continuous: no step of 1/60 s jumps more than a few metres or turns more than a little.
        let (mut last, mut worst_move, mut worst_turn) = (flight.camera(0.0), 0.0f32, 0.0f32);
        for k in 1..=1200 {
            let c = flight.camera(k as f32 / 60.0);
            worst_move = worst_move.max(c.position.distance(last.position));
            worst_turn = worst_turn.max(c.forward().angle_between(last.forward()));
            last = c;
        }
        assert!(worst_move < 0.5, "largest move in one frame: {worst_move} m");
        assert!(worst_turn < 0.1, "largest turn in one frame: {worst_turn} rad");
        // The loop closes on the start (t = 20 s is t = 0) and goes above the level on the way.
        assert!(flight.camera(20.0).position.distance(flight.camera(0.0).position) < 1e-3);
        let top = (0..200).map(|k| flight.camera(k as f32 * 0.1).position.y).fold(f32::MIN, f32::max);
        assert!(top > max.y, "the flight never rises above the level (top {top})");
    }
}
