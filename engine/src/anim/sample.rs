//! Keyframe sampling as the glTF spec defines it (Animations, Appendix C): STEP holds, LINEAR
//! lerps (rotations: shortest-path slerp), CUBICSPLINE is a Hermite curve whose per-second
//! tangents are scaled by the key interval. Sampling writes into caller-provided slices and
//! never allocates.

use glam::{Quat, Vec4};
use pack::{ChannelPath, Interpolation};

/// One channel of a clip, with its keys copied out of the pack at load time.
#[derive(Debug, Clone)]
pub struct Track {
    pub node: u32,
    pub path: ChannelPath,
    pub interpolation: Interpolation,
    /// Floats per value: 3, 4 or the morph target count.
    pub components: usize,
    pub times: Vec<f32>,
    /// [key][components], or [key][in, value, out][components] for cubic splines.
    pub values: Vec<f32>,
}

#[derive(Debug, Clone)]
pub struct ClipData {
    pub name: String,
    pub duration: f32,
    pub tracks: Vec<Track>,
}

/// Where clip time `t` lands for a clip of `duration` seconds: wrapped when looping, clamped
/// to [0, duration] otherwise.
pub fn clip_time(t: f32, duration: f32, looping: bool) -> f32 {
    if duration <= 0.0 || !t.is_finite() {
        return 0.0;
    }
    if looping {
        t.rem_euclid(duration)
    } else {
        t.clamp(0.0, duration)
    }
}

impl Track {
    fn stride(&self) -> usize {
        self.components * if self.interpolation == Interpolation::Cubicspline { 3 } else { 1 }
    }

    /// The value block of key `k` (the middle block for cubic splines).
    fn value(&self, k: usize) -> &[f32] {
        let c = self.components;
        let at = k * self.stride() + if self.interpolation == Interpolation::Cubicspline { c } else { 0 };
        &self.values[at..at + c]
    }

    /// Sample at `t` seconds into `out` (`components` floats). Before the first key and after the
    /// last, the end values hold; exactly on a key, that key's value is returned as stored.
    pub fn sample(&self, t: f32, out: &mut [f32]) {
        let n = self.times.len();
        let c = self.components;
        let out = &mut out[..c];
        if n == 1 || t <= self.times[0] {
            out.copy_from_slice(self.value(0));
            return;
        }
        if t >= self.times[n - 1] {
            out.copy_from_slice(self.value(n - 1));
            return;
        }
        // times[k] <= t < times[k + 1]
        let k = self.times.partition_point(|&x| x <= t) - 1;
        let (t0, t1) = (self.times[k], self.times[k + 1]);
        let td = t1 - t0;
        let u = (t - t0) / td;
        if u <= 0.0 || self.interpolation == Interpolation::Step {
            out.copy_from_slice(self.value(k));
            return;
        }
        let (a, b) = (self.value(k), self.value(k + 1));
        match self.interpolation {
            Interpolation::Step => unreachable!(),
            Interpolation::Linear if self.path == ChannelPath::Rotation => {
                let q = slerp(quat(a), quat(b), u);
                out.copy_from_slice(&q.to_array());
            }
            Interpolation::Linear => {
                for i in 0..c {
                    out[i] = (1.0 - u) * a[i] + u * b[i];
                }
            }
            Interpolation::Cubicspline => {
                let s = self.stride();
                let out_tangent = &self.values[k * s + 2 * c..k * s + 3 * c];
                let in_tangent = &self.values[(k + 1) * s..(k + 1) * s + c];
                let (u2, u3) = (u * u, u * u * u);
                let h00 = 2.0 * u3 - 3.0 * u2 + 1.0;
                let h10 = u3 - 2.0 * u2 + u;
                let h01 = -2.0 * u3 + 3.0 * u2;
                let h11 = u3 - u2;
                for i in 0..c {
                    out[i] = h00 * a[i] + h10 * td * out_tangent[i] + h01 * b[i] + h11 * td * in_tangent[i];
                }
                if self.path == ChannelPath::Rotation {
                    let q = Vec4::from_slice(out).normalize_or(Vec4::W);
                    out.copy_from_slice(&q.to_array());
                }
            }
        }
    }
}

fn quat(v: &[f32]) -> Quat {
    Quat::from_xyzw(v[0], v[1], v[2], v[3])
}

/// glTF's shortest-path slerp: the path never exceeds 180 degrees whatever the keys' signs
/// (q and -q are one rotation); nearly equal keys fall back to a normalised lerp, where the
/// slerp formula divides by sin(angle) -> 0.
pub fn slerp(q0: Quat, q1: Quat, u: f32) -> Quat {
    let d = q0.dot(q1);
    let s = if d < 0.0 { -1.0 } else { 1.0 };
    let cos = d.abs().min(1.0) as f64;
    let (a, b) = (Vec4::from(q0), Vec4::from(q1) * s);
    if cos > 0.9995 {
        return Quat::from_vec4((a + (b - a) * u).normalize());
    }
    let angle = cos.acos();
    let sin = angle.sin();
    let w0 = ((angle * (1.0 - u as f64)).sin() / sin) as f32;
    let w1 = ((angle * u as f64).sin() / sin) as f32;
    Quat::from_vec4((a * w0 + b * w1).normalize())
}

/// Normalised lerp along the shortest path, for blending poses (cheap, exact at both ends).
pub fn nlerp(q0: Quat, q1: Quat, u: f32) -> Quat {
    let b = if q0.dot(q1) < 0.0 { -Vec4::from(q1) } else { Vec4::from(q1) };
    let a = Vec4::from(q0);
    Quat::from_vec4((a + (b - a) * u).normalize_or(Vec4::W))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn track(path: ChannelPath, interpolation: Interpolation, components: usize, times: &[f32], values: &[f32]) -> Track {
        Track {
            node: 0,
            path,
            interpolation,
            components,
            times: times.to_vec(),
            values: values.to_vec(),
        }
    }

    fn at(t: &Track, time: f32) -> Vec<f32> {
        let mut out = vec![0.0; t.components];
        t.sample(time, &mut out);
        out
    }

    #[test]
    fn slerp_halfway_identity_to_90_degrees_about_z() {
        let q = slerp(Quat::IDENTITY, Quat::from_rotation_z(std::f32::consts::FRAC_PI_2), 0.5);
        let want = [0.0, 0.0, 0.382_683_43, 0.923_879_5];
        for (a, b) in q.to_array().iter().zip(want) {
            assert!((a - b).abs() < 1e-6, "{q:?} != {want:?}");
        }
    }

    #[test]
    fn negated_key_takes_the_short_path() {
        // -R_z(90) is the same rotation; halfway must turn +x to (0.7071, 0.7071, 0), where a
        // slerp without the sign flip goes the long way round to (-0.7071, -0.7071, 0).
        let q1 = -Quat::from_rotation_z(std::f32::consts::FRAC_PI_2);
        let t = track(ChannelPath::Rotation, Interpolation::Linear, 4, &[0.0, 1.0], &[0.0, 0.0, 0.0, 1.0, q1.x, q1.y, q1.z, q1.w]);
        let q = quat(&at(&t, 0.5));
        let x = q * Vec3::X;
        assert!((x - Vec3::new(0.70710677, 0.70710677, 0.0)).length() < 1e-5, "{x}");
    }

    #[test]
    fn step_and_linear_follow_the_notes_examples() {
        let s = track(ChannelPath::Translation, Interpolation::Step, 1, &[0.0, 1.0], &[0.0, 10.0]);
        assert_eq!([at(&s, 0.999)[0], at(&s, 1.0)[0], at(&s, -5.0)[0], at(&s, 7.0)[0]], [0.0, 10.0, 0.0, 10.0]);
        let l = track(ChannelPath::Translation, Interpolation::Linear, 1, &[0.0, 1.0, 3.0], &[0.0, 10.0, 30.0]);
        assert_eq!(at(&l, 2.0)[0], 20.0);
        assert_eq!(at(&l, 0.5)[0], 5.0);
    }

    #[test]
    fn cubic_reproduces_a_line_on_uneven_keys() {
        // v_k = 2 + 3 t_k with every tangent 3: the Hermite curve is the line itself.
        let times = [0.0, 0.3, 1.7, 2.0];
        let values: Vec<f32> = times.iter().flat_map(|&t| [3.0, 2.0 + 3.0 * t, 3.0]).collect();
        let c = track(ChannelPath::Translation, Interpolation::Cubicspline, 1, &times, &values);
        for i in 0..50 {
            let t = i as f32 * 2.0 / 49.0;
            assert!((at(&c, t)[0] - (2.0 + 3.0 * t)).abs() < 1e-5, "t {t}");
        }
        // Zero tangents ease: the midpoint is the average.
        let e = track(ChannelPath::Translation, Interpolation::Cubicspline, 1, &[0.0, 2.0], &[0.0, 1.0, 0.0, 0.0, 5.0, 0.0]);
        assert!((at(&e, 1.0)[0] - 3.0).abs() < 1e-6);
    }

    #[test]
    fn looping_wraps_and_clamping_holds() {
        assert!((clip_time(2.5, 2.0, true) - 0.5).abs() < 1e-6);
        assert!((clip_time(-0.5, 2.0, true) - 1.5).abs() < 1e-6);
        assert_eq!(clip_time(2.5, 2.0, false), 2.0);
        assert_eq!(clip_time(-1.0, 2.0, false), 0.0);
    }
}
