//! The fixed simulation step behind an accumulator (notes §7, "timestep policy").
//!
//! Frames hand in their wall-clock duration; the clock answers how many fixed steps to take. The
//! simulation then only ever sees h = 1/steps_per_s, so its state after a given simulated time is
//! the same at any frame rate, and its stability bounds (h·ω < 2, h·k_drag < 1) are set once by
//! the parameters rather than by the slowest frame. A cap on steps per frame keeps one long
//! stall (a debugger, a window drag) from turning into a burst of catch-up work: the excess time
//! is dropped. `alpha` is how far the frame sits between the last step and the next, for a
//! renderer that extrapolates positions.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ClockParams {
    pub steps_per_s: u32,
    pub max_steps_per_frame: u32,
}

impl Default for ClockParams {
    fn default() -> Self {
        // 1/120 s keeps h·ω ≲ 0.5 for springs up to ω = 60 rad/s (notes).
        ClockParams {
            steps_per_s: 120,
            max_steps_per_frame: 8,
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct FixedClock {
    pub params: ClockParams,
    /// Simulated time not yet stepped, in seconds (f64: summing thousands of frames in f32
    /// would drift by whole steps).
    accumulator_s: f64,
    /// Steps taken since creation.
    pub steps: u64,
    /// Frame time dropped by the per-frame cap, in seconds.
    pub dropped_s: f64,
}

/// A frame within this fraction of a step of the next step boundary takes that step. Frame
/// durations are sums of rounded values (1/144 s is not a binary fraction), so one second of
/// frames can add up to a hair under 1 s; without the tolerance 30 fps and 144 fps would take
/// 120 and 119 steps for the same second.
const STEP_TOLERANCE: f64 = 1e-6;

impl FixedClock {
    pub fn new(params: ClockParams) -> FixedClock {
        FixedClock {
            params,
            accumulator_s: 0.0,
            steps: 0,
            dropped_s: 0.0,
        }
    }

    pub fn dt(&self) -> f32 {
        1.0 / self.params.steps_per_s.max(1) as f32
    }

    fn dt_f64(&self) -> f64 {
        1.0 / self.params.steps_per_s.max(1) as f64
    }

    /// Adds a frame's duration and returns how many fixed steps to run now.
    pub fn advance(&mut self, frame_s: f64) -> u32 {
        let h = self.dt_f64();
        self.accumulator_s += frame_s.max(0.0);
        let mut n = 0;
        while self.accumulator_s >= h * (1.0 - STEP_TOLERANCE) {
            if n == self.params.max_steps_per_frame {
                self.dropped_s += self.accumulator_s;
                self.accumulator_s = 0.0;
                break;
            }
            self.accumulator_s -= h;
            n += 1;
        }
        self.steps += n as u64;
        n
    }

    /// Fraction of a step between the last step and the frame time, in [0, 1).
    pub fn alpha(&self) -> f32 {
        (self.accumulator_s / self.dt_f64()).clamp(0.0, 1.0) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_second_is_the_same_number_of_steps_at_any_frame_rate() {
        for fps in [24u32, 30, 60, 75, 144, 165, 240] {
            let mut c = FixedClock::new(ClockParams::default());
            let taken: u32 = (0..fps).map(|_| c.advance(1.0 / fps as f64)).sum();
            assert_eq!(taken, 120, "{fps} fps");
            assert_eq!(c.steps, 120);
        }
    }

    #[test]
    fn a_stall_is_capped_and_the_excess_dropped() {
        let mut c = FixedClock::new(ClockParams {
            steps_per_s: 100,
            max_steps_per_frame: 4,
        });
        assert_eq!(c.advance(1.0), 4);
        assert!((c.dropped_s - 0.96).abs() < 1e-9, "{}", c.dropped_s);
        assert_eq!(c.advance(0.015), 1);
        assert!((c.alpha() - 0.5).abs() < 1e-5);
    }
}
