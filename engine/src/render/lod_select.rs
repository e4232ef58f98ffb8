//! LOD selection from the cooked geometric error (metres, per LOD, non-decreasing) projected to
//! pixels: error_px = error * (H / 2) * cot(fov_y / 2) / distance (pipeline.md T8.3). The coarsest
//! LOD whose projected error stays under the threshold is drawn.
//!
//! Hysteresis, so an instance hovering at a switch distance does not flicker: going coarser needs
//! the coarser LOD's error under threshold x (1 - band); going finer happens only when the current
//! LOD's error passes threshold x (1 + band). The two switch distances differ by that band.

/// Pixels per metre at unit distance for a viewport `height_px` high with vertical FOV `fov_y`.
pub fn pixels_per_metre_at_unit_distance(height_px: f32, fov_y: f32) -> f32 {
    0.5 * height_px / (0.5 * fov_y).tan()
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LodPolicy {
    /// Largest acceptable projected error, in pixels.
    pub threshold_px: f32,
    /// Hysteresis band as a fraction of the threshold.
    pub band: f32,
}

impl Default for LodPolicy {
    fn default() -> Self {
        LodPolicy { threshold_px: 1.0, band: 0.15 }
    }
}

impl LodPolicy {
    /// The LOD to draw: `errors` per LOD in metres (LOD 0 first), `distance` from the camera to
    /// the instance's bounds (metres, clamped away from 0), `px_per_m` from
    /// `pixels_per_metre_at_unit_distance` (scaled by the instance's world scale if any), and
    /// the LOD drawn last frame.
    pub fn select(&self, errors: &[f32], distance: f32, px_per_m: f32, previous: Option<usize>) -> usize {
        if errors.len() <= 1 {
            return 0;
        }
        let scale = px_per_m / distance.max(1e-6);
        let projected = |i: usize| errors[i] * scale;
        let coarsest_under = |t: f32| (0..errors.len()).rev().find(|&i| projected(i) <= t).unwrap_or(0);
        match previous.filter(|&p| p < errors.len()) {
            None => coarsest_under(self.threshold_px),
            Some(p) if projected(p) > self.threshold_px * (1.0 + self.band) => coarsest_under(self.threshold_px),
            Some(p) => p.max(coarsest_under(self.threshold_px * (1.0 - self.band))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn t8_3_projected_radius() {
        // r = 1, H = 1080, 60 degrees, 10 m: 93.5 px.
        let px = 1.0 * pixels_per_metre_at_unit_distance(1080.0, 60f32.to_radians()) / 10.0;
        assert!((px - 93.53).abs() < 0.01, "{px}");
    }

    #[test]
    fn t8_3_sweep_out_and_back_is_monotonic_with_a_band() {
        let errors = [0.0, 0.002, 0.005, 0.012, 0.03, 0.08];
        let policy = LodPolicy { threshold_px: 1.0, band: 0.15 };
        let ppm = pixels_per_metre_at_unit_distance(1080.0, 60f32.to_radians());
        let steps: Vec<f32> = (0..=2000).map(|i| 1.0 * 1000f32.powf(i as f32 / 2000.0)).collect();
        let mut lod = None;
        let mut out_switch = vec![f32::NAN; errors.len()];
        for &d in &steps {
            let l = policy.select(&errors, d, ppm, lod);
            if let Some(p) = lod {
                assert!(l >= p, "went finer moving away at {d} m");
                if l > p {
                    out_switch[l] = d;
                }
            }
            lod = Some(l);
        }
        assert_eq!(lod, Some(errors.len() - 1), "the coarsest LOD at 1 km");
        let mut back_switch = vec![f32::NAN; errors.len()];
        for &d in steps.iter().rev() {
            let l = policy.select(&errors, d, ppm, lod);
            let p = lod.unwrap();
            assert!(l <= p, "went coarser moving closer at {d} m");
            if l < p {
                back_switch[p] = d;
            }
            lod = Some(l);
        }
        assert_eq!(lod, Some(0));
        for i in 1..errors.len() {
            // Going out, LOD i is taken where e_i px <= t (1 - band); coming back it is left where
            // e_i px > t (1 + band): the distances differ by the ratio of the two.
            let ratio = out_switch[i] / back_switch[i];
            assert!((ratio - 1.15 / 0.85).abs() < 0.02, "LOD {i}: out at {} m, back at {} m", out_switch[i], back_switch[i]);
        }
        // No flicker: hovering at a switch distance keeps the LOD.
        let d = out_switch[3] * 1.0001;
        let mut l = policy.select(&errors, d, ppm, Some(2));
        for k in 0..100 {
            let jitter = d * (1.0 + if k % 2 == 0 { 1e-3 } else { -1e-3 });
            let next = policy.select(&errors, jitter, ppm, Some(l));
            assert_eq!(next, l, "flicker at {jitter}");
            l = next;
        }
    }

    #[test]
    fn a_single_lod_is_always_lod_0() {
        assert_eq!(LodPolicy::default().select(&[0.0], 100.0, 900.0, None), 0);
        assert_eq!(LodPolicy::default().select(&[], 100.0, 900.0, Some(3)), 0);
    }
}
