//! Adaptive render resolution: the 3D passes draw at a scale of the output's size that the
//! controller adjusts to hold a target GPU frame time, and the upscaler (passes/upscale.rs)
//! resamples the frame to the output. Off (`RenderScale::Fixed(1.0)`), every pass runs at the
//! output's size exactly as without it.
//!
//! The controller (`ScaleController::observe`, once per finished frame with its GPU time):
//! - Scales are steps of `STEP` between `MIN_SCALE` and 1: a frame's size changes rarely and by
//!   whole steps, never by noise.
//! - Down fast: when the slowest of the last `DOWN_FRAMES` frames is over the target, the scale
//!   drops at once to what the frame's pixel cost says fits (time taken as proportional to the
//!   pixels, scale squared: an over-estimate of the gain, since part of a frame does not shrink
//!   with it, so the next frames correct it downwards again if need be).
//! - Up slowly (hysteresis): only after `UP_FRAMES` frames at a scale, and only when the slowest
//!   of them, grown to the next step's pixels, stays under `UP_HEADROOM` of the target. Down
//!   triggers above the target, up below 85 % of it predicted: the two never chase each other
//!   around one scale (the test `a_steady_load_settles_without_oscillating`).

/// The filter that brings a frame drawn below the output's size back to it (shaders/upscale.frag).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Upscaler {
    /// FSR 1's edge-adaptive upsampler (EASU): the default on GPUs.
    #[default]
    Easu,
    /// The separable Catmull-Rom cubic over the same 12 texels: the default on CPU devices,
    /// where EASU's edge analysis costs more than the cubic's whole pass.
    Cubic,
}

impl Upscaler {
    pub const ALL: [Upscaler; 2] = [Upscaler::Easu, Upscaler::Cubic];

    pub fn name(self) -> &'static str {
        match self {
            Upscaler::Easu => "easu",
            Upscaler::Cubic => "cubic",
        }
    }
}

impl std::str::FromStr for Upscaler {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Upscaler::ALL.into_iter().find(|u| u.name() == s).ok_or_else(|| format!("'{s}' is not an upscaler (easu, cubic)"))
    }
}

/// How the render scale is chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RenderScale {
    /// This scale every frame (1: off; clamped to `MIN_SCALE..=1`).
    Fixed(f32),
    /// The controller's, holding the GPU frame time at `target_ms`.
    Adaptive { target_ms: f32 },
}

impl RenderScale {
    /// From the command line's `--render-scale S` (a fixed scale, 1 = off) and `--target-ms T`
    /// (adaptive, holding T): at most one of them; neither is adaptive at `DEFAULT_TARGET_MS`.
    pub fn from_args(render_scale: Option<&str>, target_ms: Option<&str>) -> Result<RenderScale, String> {
        match (render_scale, target_ms) {
            (Some(_), Some(_)) => Err("--render-scale fixes the scale and --target-ms adapts it: give one of them".into()),
            (Some(v), None) => match v.parse::<f32>() {
                Ok(s) if (MIN_SCALE..=1.0).contains(&s) => Ok(RenderScale::Fixed(s)),
                _ => Err(format!("--render-scale: '{v}' is not a scale from {MIN_SCALE} to 1")),
            },
            (None, Some(v)) => match v.parse::<f32>() {
                Ok(t) if t.is_finite() && t > 0.0 => Ok(RenderScale::Adaptive { target_ms: t }),
                _ => Err(format!("--target-ms: '{v}' is not a frame time in milliseconds")),
            },
            (None, None) => Ok(RenderScale::default()),
        }
    }

    /// For the overlay and the bench: "adaptive (16.7 ms)" or "fixed 0.75".
    pub fn describe(&self) -> String {
        match self {
            RenderScale::Fixed(s) => format!("fixed {s}"),
            RenderScale::Adaptive { target_ms } => format!("adaptive ({target_ms} ms)"),
        }
    }
}

impl Default for RenderScale {
    /// The frame budget of a 60 Hz display.
    fn default() -> Self {
        RenderScale::Adaptive { target_ms: DEFAULT_TARGET_MS }
    }
}

/// 60 frames a second.
pub const DEFAULT_TARGET_MS: f32 = 16.7;
/// Never below half the output's size in each direction (a quarter of its pixels): below that,
/// no spatial upscaler gives back an image worth showing.
pub const MIN_SCALE: f32 = 0.5;
/// Scales are multiples of this.
pub const STEP: f32 = 0.05;
/// Frames over the target (the slowest of them) before the scale drops.
pub const DOWN_FRAMES: usize = 2;
/// Frames at one scale before it may grow.
pub const UP_FRAMES: usize = 30;
/// The scale grows only when the next step is predicted under this share of the target.
pub const UP_HEADROOM: f32 = 0.85;

/// Chooses each frame's render scale.
#[derive(Debug, Clone)]
pub struct ScaleController {
    pub mode: RenderScale,
    /// The adaptive scale (kept while the mode is fixed, so switching back resumes it).
    scale: f32,
    /// GPU times of the frames drawn at `scale` since it was set, newest last (at most
    /// `UP_FRAMES`).
    recent: Vec<f32>,
    /// The adaptive target it was made with, kept when switched to a fixed scale.
    last_target: Option<f32>,
}

impl Default for ScaleController {
    fn default() -> Self {
        ScaleController::new(RenderScale::default())
    }
}

impl ScaleController {
    pub fn new(mode: RenderScale) -> ScaleController {
        let last_target = match mode {
            RenderScale::Adaptive { target_ms } => Some(target_ms),
            RenderScale::Fixed(_) => None,
        };
        ScaleController { mode, scale: 1.0, recent: Vec::with_capacity(UP_FRAMES), last_target }
    }

    /// The frame time the adaptive mode holds (its target, or the last one it had, or 60 fps).
    pub fn target_ms(&self) -> f32 {
        match self.mode {
            RenderScale::Adaptive { target_ms } => target_ms,
            RenderScale::Fixed(_) => self.last_target.unwrap_or(DEFAULT_TARGET_MS),
        }
    }

    /// The scale the next frame draws at.
    pub fn scale(&self) -> f32 {
        match self.mode {
            RenderScale::Fixed(s) => clamp_scale(s),
            RenderScale::Adaptive { .. } => self.scale,
        }
    }

    /// The region of an `output`-sized frame the 3D passes draw at `scale` (each side rounded
    /// to whole pixels, at least 1).
    pub fn render_extent(scale: f32, output: ash::vk::Extent2D) -> ash::vk::Extent2D {
        let side = |n: u32| ((n as f32 * scale).round() as u32).clamp(1, n.max(1));
        ash::vk::Extent2D { width: side(output.width), height: side(output.height) }
    }

    /// A frame drawn at `scale` took `gpu_ms` on the GPU. Returns the scale for the next frame.
    pub fn observe(&mut self, scale: f32, gpu_ms: f32) -> f32 {
        let RenderScale::Adaptive { target_ms } = self.mode else {
            return self.scale();
        };
        // A frame from before the last change (frames in flight) says nothing of this scale.
        if (scale - self.scale).abs() > 1e-6 || !gpu_ms.is_finite() || gpu_ms <= 0.0 {
            return self.scale;
        }
        self.recent.push(gpu_ms);
        if self.recent.len() > UP_FRAMES {
            self.recent.remove(0);
        }
        let n = self.recent.len();
        let slowest_last = |k: usize| self.recent[n.saturating_sub(k)..].iter().copied().fold(0.0f32, f32::max);
        let slow = slowest_last(DOWN_FRAMES);
        if n >= DOWN_FRAMES && slow > target_ms && self.scale > MIN_SCALE {
            // Pixels in proportion to the time: the scale whose frame would take the target.
            let fit = self.scale * (target_ms / slow).sqrt();
            self.set(quantise_down(fit).min(self.scale - STEP));
        } else if n >= UP_FRAMES && self.scale < 1.0 {
            let next = (self.scale + STEP).min(1.0);
            let predicted = slowest_last(UP_FRAMES) * (next / self.scale).powi(2);
            if predicted < UP_HEADROOM * target_ms {
                self.set(next);
            }
        }
        self.scale
    }

    fn set(&mut self, scale: f32) {
        self.scale = clamp_scale(scale);
        self.recent.clear();
    }
}

fn clamp_scale(s: f32) -> f32 {
    if s.is_finite() {
        s.clamp(MIN_SCALE, 1.0)
    } else {
        1.0
    }
}

/// The largest step at or below `s` (with a little slack for rounding).
fn quantise_down(s: f32) -> f32 {
    ((s / STEP + 1e-4).floor() * STEP).clamp(MIN_SCALE, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame of `fixed` ms plus `per_pixel` ms at scale 1, scaled by the pixels.
    fn frame_ms(scale: f32, fixed: f32, full: f32) -> f32 {
        fixed + full * scale * scale
    }

    fn run(c: &mut ScaleController, frames: usize, cost: impl Fn(f32, usize) -> f32) -> Vec<f32> {
        let mut scales = Vec::new();
        let mut s = c.scale();
        for i in 0..frames {
            scales.push(s);
            s = c.observe(s, cost(s, i));
        }
        scales
    }

    #[test]
    fn a_fixed_scale_is_kept_and_clamped() {
        let mut c = ScaleController::new(RenderScale::Fixed(1.0));
        assert_eq!(run(&mut c, 50, |_, _| 100.0), vec![1.0; 50]);
        assert_eq!(ScaleController::new(RenderScale::Fixed(0.2)).scale(), MIN_SCALE);
        assert_eq!(ScaleController::new(RenderScale::Fixed(f32::NAN)).scale(), 1.0);
    }

    #[test]
    fn an_easy_frame_stays_at_full_resolution() {
        let mut c = ScaleController::default();
        assert!(run(&mut c, 200, |s, _| frame_ms(s, 2.0, 8.0)).iter().all(|&s| s == 1.0));
    }

    #[test]
    fn a_heavy_frame_drops_at_once_and_never_below_the_minimum() {
        let mut c = ScaleController::default();
        let scales = run(&mut c, 10, |s, _| frame_ms(s, 5.0, 40.0));
        // 45 ms at 1: sqrt(16.7 / 45) = 0.61 -> 0.6 after two frames over.
        assert_eq!(&scales[..3], &[1.0, 1.0, 0.6]);
        let mut c = ScaleController::default();
        let scales = run(&mut c, 100, |s, _| frame_ms(s, 20.0, 80.0));
        assert!(scales.iter().all(|&s| s >= MIN_SCALE));
        assert_eq!(*scales.last().unwrap(), MIN_SCALE);
    }

    #[test]
    fn a_steady_load_settles_without_oscillating() {
        // 6 ms that do not scale and 24 that do: 16.7 fits at 0.65 (16.1 ms), 0.7 does not.
        let mut c = ScaleController::default();
        let scales = run(&mut c, 2000, |s, i| frame_ms(s, 6.0, 24.0) * (1.0 + 0.03 * ((i * 7919 % 13) as f32 / 13.0 - 0.5)));
        let tail = &scales[200..];
        assert!(tail.iter().all(|&s| (s - tail[0]).abs() < 1e-6), "the scale kept changing: {:?}", &tail[..40]);
        // At the largest step that fits (0.65: 16.1 ms, within the 1.5 % noise of 16.7), not below.
        assert!((tail[0] - 0.65).abs() < 1e-4, "settled at {}", tail[0]);
    }

    #[test]
    fn the_scale_grows_back_when_the_load_goes() {
        let mut c = ScaleController::default();
        let scales = run(&mut c, 1500, |s, i| if i < 100 { frame_ms(s, 5.0, 40.0) } else { frame_ms(s, 2.0, 6.0) });
        assert!(scales[99] < 0.7);
        assert_eq!(*scales.last().unwrap(), 1.0);
        // Whole steps, one at a time, at least UP_FRAMES apart.
        let ups: Vec<usize> = (101..scales.len()).filter(|&i| scales[i] > scales[i - 1]).collect();
        assert!(ups.windows(2).all(|w| w[1] - w[0] >= UP_FRAMES));
        assert!(ups.iter().all(|&i| (scales[i] - scales[i - 1] - STEP).abs() < 1e-4));
    }

    #[test]
    fn the_command_line_gives_one_mode() {
        assert_eq!(RenderScale::from_args(None, None), Ok(RenderScale::Adaptive { target_ms: DEFAULT_TARGET_MS }));
        assert_eq!(RenderScale::from_args(Some("1"), None), Ok(RenderScale::Fixed(1.0)));
        assert_eq!(RenderScale::from_args(None, Some("33.3")), Ok(RenderScale::Adaptive { target_ms: 33.3 }));
        assert_eq!(RenderScale::from_args(Some("0.4"), None).unwrap_err(), "--render-scale: '0.4' is not a scale from 0.5 to 1");
        assert!(RenderScale::from_args(Some("x"), None).is_err());
        assert!(RenderScale::from_args(None, Some("-1")).is_err());
        assert!(RenderScale::from_args(None, Some("inf")).is_err());
        assert!(RenderScale::from_args(Some("1"), Some("16")).is_err());
    }

    #[test]
    fn render_extents_round_and_stay_inside() {
        let out = ash::vk::Extent2D { width: 1280, height: 720 };
        assert_eq!(ScaleController::render_extent(1.0, out), out);
        assert_eq!(ScaleController::render_extent(0.5, out), ash::vk::Extent2D { width: 640, height: 360 });
        assert_eq!(ScaleController::render_extent(0.65, out), ash::vk::Extent2D { width: 832, height: 468 });
        assert_eq!(ScaleController::render_extent(0.5, ash::vk::Extent2D { width: 1, height: 1 }), ash::vk::Extent2D { width: 1, height: 1 });
    }
}
