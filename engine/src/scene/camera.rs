//! Camera and projection. The one place that knows Vulkan's clip conventions: right-handed
//! view space looking down -Z, reversed-Z depth (near -> 1, infinitely far -> 0) and NDC +Y
//! pointing down, so that counter-clockwise triangles (glTF's front faces) stay counter-clockwise
//! on screen (../shared/notes/pipeline.md §2).

use glam::{Mat4, Vec3, Vec4};

/// Perspective projection with reversed-Z, an infinite far plane and Y flipped for Vulkan.
/// `fov_y` in radians, `near` in metres. Depth = near / distance.
pub fn perspective_reverse_z(fov_y: f32, aspect: f32, near: f32) -> Mat4 {
    let f = 1.0 / (fov_y * 0.5).tan();
    Mat4::from_cols(
        Vec4::new(f / aspect, 0.0, 0.0, 0.0),
        Vec4::new(0.0, -f, 0.0, 0.0),
        Vec4::new(0.0, 0.0, 0.0, -1.0),
        Vec4::new(0.0, 0.0, near, 0.0),
    )
}

/// A standing person's eye height above the ground (player spawns stand on the floor).
pub const EYE_HEIGHT_M: f32 = 1.7;
/// The field of view (radians) and near plane of a camera at a spawn that does not give its own.
const SPAWN_FOV_Y: f32 = 70f32.to_radians();
const SPAWN_NEAR_M: f32 = 0.05;

/// A fly camera: position plus yaw (about +Y, 0 looks down -Z) and pitch, in radians.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub position: Vec3,
    pub yaw: f32,
    pub pitch: f32,
    pub fov_y: f32,
    pub near: f32,
}

impl Camera {
    pub fn forward(&self) -> Vec3 {
        let (sy, cy) = self.yaw.sin_cos();
        let (sp, cp) = self.pitch.sin_cos();
        Vec3::new(-sy * cp, sp, -cy * cp)
    }

    pub fn right(&self) -> Vec3 {
        self.forward().cross(Vec3::Y).normalize_or(Vec3::X)
    }

    pub fn view(&self) -> Mat4 {
        Mat4::look_to_rh(self.position, self.forward(), Vec3::Y)
    }

    pub fn view_proj(&self, aspect: f32) -> Mat4 {
        perspective_reverse_z(self.fov_y, aspect, self.near) * self.view()
    }

    /// A camera looking at the centre of a bounding box from a fixed direction (front, above,
    /// to the right), far enough back that the bounding sphere fills the vertical field of view.
    pub fn framing(min: Vec3, max: Vec3) -> Camera {
        let fov_y = 50f32.to_radians();
        let centre = (min + max) * 0.5;
        let radius = ((max - min).length() * 0.5).max(0.01);
        let dir = Vec3::new(0.55, 0.45, 0.7).normalize(); // from the target towards the camera
        let distance = radius / (fov_y * 0.5).sin() * 1.05;
        let forward = -dir;
        Camera {
            position: centre + dir * distance,
            yaw: (-forward.x).atan2(-forward.z),
            pitch: forward.y.asin(),
            fov_y,
            near: (distance - radius).clamp(0.01, 0.1),
        }
    }

    /// The camera a pack asks for: at its `player` spawn (eye height above it, looking along
    /// the spawn's rotation); else at its first `camera` spawn (`camera_spawn`); else framing
    /// the scene's bounds.
    pub fn for_pack(manifest: &pack::Manifest, min: Vec3, max: Vec3) -> Camera {
        let first = |kind: &str| manifest.spawns.iter().find(|s| s.kind == kind);
        if let Some(player) = first("player") {
            return Camera::looking_along(Vec3::from(player.position) + Vec3::Y * EYE_HEIGHT_M, player.rotation, SPAWN_FOV_Y, SPAWN_NEAR_M);
        }
        match first("camera") {
            Some(camera) => Camera::camera_spawn(camera),
            None => Camera::framing(min, max),
        }
    }

    /// A `camera` spawn (the cooker writes one from a glTF scene's first camera): exactly at its
    /// position, looking along its rotation's -Z, with its vertical field of view `yfov`
    /// (radians) and near plane `znear` (metres) where it gives usable ones. Its far plane does
    /// not matter (the projection's is infinite), nor does its roll (the camera keeps +Y up).
    fn camera_spawn(spawn: &pack::Spawn) -> Camera {
        let param = |key: &str| spawn.params.get(key).and_then(|v| v.as_f64()).map(|v| v as f32);
        let fov_y = param("yfov").filter(|f| *f > 0.0 && *f < std::f32::consts::PI).unwrap_or(SPAWN_FOV_Y);
        let near = param("znear").filter(|n| *n > 0.0 && n.is_finite()).unwrap_or(SPAWN_NEAR_M);
        Camera::looking_along(Vec3::from(spawn.position), spawn.rotation, fov_y, near)
    }

    /// A camera at `position` looking along the quaternion (xyzw) `rotation` applied to -Z.
    fn looking_along(position: Vec3, rotation: [f32; 4], fov_y: f32, near: f32) -> Camera {
        let forward = glam::Quat::from_array(rotation).normalize() * Vec3::NEG_Z;
        Camera { position, yaw: (-forward.x).atan2(-forward.z), pitch: forward.y.clamp(-1.0, 1.0).asin(), fov_y, near }
    }

    /// Walking: `local` (right, -, forward) metres as a move in the ground plane, whatever the
    /// pitch (`walk::WalkMesh::step` takes it from there).
    pub fn walk_delta(&self, local: Vec3) -> Vec3 {
        let forward = Vec3::new(self.forward().x, 0.0, self.forward().z).normalize_or_zero();
        let right = Vec3::new(self.right().x, 0.0, self.right().z).normalize_or_zero();
        right * local.x + forward * local.z
    }

    /// Move relative to the view: `local` is (right, up, forward) in metres.
    pub fn translate_local(&mut self, local: Vec3) {
        self.position += self.right() * local.x + Vec3::Y * local.y + self.forward() * local.z;
    }

    pub fn rotate(&mut self, d_yaw: f32, d_pitch: f32) {
        self.yaw += d_yaw;
        self.pitch = (self.pitch + d_pitch).clamp(-1.55, 1.55);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ndc(m: Mat4, p: Vec3) -> Vec3 {
        let c = m * p.extend(1.0);
        assert!(c.w > 0.0, "clip w must be positive in front of the camera");
        c.truncate() / c.w
    }

    #[test]
    fn walking_moves_level_whatever_the_pitch() {
        let mut c = Camera { position: Vec3::new(0.0, 5.0, 0.0), yaw: 0.0, pitch: -1.2, fov_y: 1.0, near: 0.1 };
        let d = c.walk_delta(Vec3::new(0.0, 7.0, 2.0)); // 2 m forward (-Z at yaw 0); the up component is ignored
        assert!((d - Vec3::new(0.0, 0.0, -2.0)).length() < 1e-5, "{d}");
        c.yaw = std::f32::consts::FRAC_PI_2; // looking down -X
        let d = c.walk_delta(Vec3::new(1.0, 0.0, 0.0)); // 1 m to the right: -Z
        assert!((d - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-5, "{d}");
    }

    #[test]
    fn reverse_z_maps_near_to_one_and_far_towards_zero() {
        let p = perspective_reverse_z(60f32.to_radians(), 16.0 / 9.0, 0.1);
        assert!((ndc(p, Vec3::new(0.0, 0.0, -0.1)).z - 1.0).abs() < 1e-6);
        assert!((ndc(p, Vec3::new(0.0, 0.0, -1000.0)).z - 1e-4).abs() < 1e-9);
        // Depth strictly decreases with distance.
        let mut last = f32::INFINITY;
        for d in [0.1f32, 0.5, 1.0, 10.0, 100.0] {
            let z = ndc(p, Vec3::new(0.0, 0.0, -d)).z;
            assert!(z < last);
            last = z;
        }
    }

    #[test]
    fn top_of_frustum_is_top_of_screen() {
        // pipeline.md T2.2: (0, d tan(fov/2), -d) -> NDC y = -1 (Vulkan rows grow downward).
        let fov = 60f32.to_radians();
        let p = perspective_reverse_z(fov, 16.0 / 9.0, 0.1);
        for d in [1.0f32, 5.0, 50.0] {
            let y = ndc(p, Vec3::new(0.0, d * (fov * 0.5).tan(), -d)).y;
            assert!((y + 1.0).abs() < 1e-5, "{y}");
            let x = ndc(p, Vec3::new(16.0 / 9.0 * d * (fov * 0.5).tan(), 0.0, -d)).x;
            assert!((x - 1.0).abs() < 1e-5, "{x}");
        }
    }

    #[test]
    fn view_looks_down_forward() {
        let c = Camera { position: Vec3::new(0.0, 0.0, 5.0), yaw: 0.0, pitch: 0.0, fov_y: 1.0, near: 0.1 };
        // pipeline.md T2.1: e=(0,0,5) looking at the origin sends the origin to (0,0,-5).
        let o = c.view().transform_point3(Vec3::ZERO);
        assert!((o - Vec3::new(0.0, 0.0, -5.0)).length() < 1e-6);
    }

    #[test]
    fn player_spawn_places_the_camera_at_eye_height_looking_along_its_rotation() {
        let mut m = pack::Manifest::default();
        assert_eq!(Camera::for_pack(&m, Vec3::ZERO, Vec3::ONE), Camera::framing(Vec3::ZERO, Vec3::ONE));
        // Rotated 90 degrees about +Y: -Z turns into -X.
        let q = glam::Quat::from_rotation_y(std::f32::consts::FRAC_PI_2);
        m.spawns.push(pack::Spawn { name: "p".into(), kind: "player".into(), position: [1.0, 0.0, 2.0], rotation: q.to_array(), params: Default::default() });
        let c = Camera::for_pack(&m, Vec3::ZERO, Vec3::ONE);
        assert!((c.position - Vec3::new(1.0, 1.7, 2.0)).length() < 1e-6);
        assert!((c.forward() - Vec3::NEG_X).length() < 1e-5, "{}", c.forward());
    }

    #[test]
    fn a_camera_spawn_places_the_camera_exactly_with_its_own_lens_unless_a_player_spawn_exists() {
        let mut m = pack::Manifest::default();
        // Rotated -90 degrees about +Y, then tilted 30 degrees down about its own x: -Z turns
        // into +X, looking down.
        let q = glam::Quat::from_rotation_y(-std::f32::consts::FRAC_PI_2) * glam::Quat::from_rotation_x(-30f32.to_radians());
        let params = serde_json::json!({ "yfov": 0.4, "znear": 0.25 });
        m.spawns.push(pack::Spawn { name: "Camera".into(), kind: "camera".into(), position: [1.0, 2.0, 3.0], rotation: q.to_array(), params });
        let c = Camera::for_pack(&m, Vec3::ZERO, Vec3::ONE);
        assert_eq!(c.position, Vec3::new(1.0, 2.0, 3.0), "no eye height above a camera spawn");
        let down = -30f32.to_radians();
        assert!((c.forward() - Vec3::new(down.cos(), down.sin(), 0.0)).length() < 1e-5, "{}", c.forward());
        assert_eq!((c.fov_y, c.near), (0.4, 0.25));
        // Unusable lens parameters fall back to the spawn defaults.
        m.spawns[0].params = serde_json::json!({ "yfov": 4.0, "znear": -1.0 });
        let c = Camera::for_pack(&m, Vec3::ZERO, Vec3::ONE);
        assert_eq!((c.fov_y, c.near), (SPAWN_FOV_Y, SPAWN_NEAR_M));
        // The player's spawn comes first, wherever it is listed.
        m.spawns.push(pack::Spawn { name: "p".into(), kind: "player".into(), position: [5.0, 0.0, 0.0], rotation: [0.0, 0.0, 0.0, 1.0], params: Default::default() });
        assert_eq!(Camera::for_pack(&m, Vec3::ZERO, Vec3::ONE).position, Vec3::new(5.0, EYE_HEIGHT_M, 0.0));
    }

    #[test]
    fn framing_sees_the_whole_box() {
        let (min, max) = (Vec3::splat(-1.0), Vec3::new(3.0, 1.0, 1.0));
        let c = Camera::framing(min, max);
        let vp = c.view_proj(1.0);
        for i in 0..8 {
            let corner = Vec3::new(
                if i & 1 == 0 { min.x } else { max.x },
                if i & 2 == 0 { min.y } else { max.y },
                if i & 4 == 0 { min.z } else { max.z },
            );
            let n = ndc(vp, corner);
            assert!(n.x.abs() <= 1.0 && n.y.abs() <= 1.0 && n.z > 0.0 && n.z <= 1.0, "corner {corner} -> {n}");
        }
    }
}
