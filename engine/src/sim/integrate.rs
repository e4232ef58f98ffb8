//! The integrators of the notes' table (§7), in f64 on a linear force law, with the notes'
//! numbers pinned by tests. They are the evidence for the choice the simulations make:
//!
//! - Particles and boids use semi-implicit (symplectic) Euler: v += h·a; x += h·v_new. One force
//!   evaluation per step and no extra state. Its energy error on an oscillator stays bounded
//!   (within 5% at ωh = 0.1, and stable up to ωh < 2), where explicit Euler grows it by
//!   (1 + ω²h²) every step and RK2 slowly drifts upward. Its position error under constant gravity
//!   is +½·g·T·h, 4 cm after 1 s at h = 1/120, invisible in a fountain.
//! - Velocity Verlet is exact under constant gravity but needs the acceleration at the new
//!   position: with velocity-dependent drag that is implicit, and storing the old acceleration
//!   costs 12 more bytes per particle, half again the memory traffic of the update.
//! - Linear drag is integrated exactly (v *= e^{-kh}, `particles`), so no drag coefficient can
//!   make a step overshoot: explicit Euler diverges once kh > 2 (pinned below).
//!
//! The force law here is a = g − ω²·x − k·v, enough for gravity, a spring and linear drag, and
//! linear, so backward Euler has a closed form.

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Integrator {
    ExplicitEuler,
    SemiImplicitEuler,
    Midpoint,
    VelocityVerlet,
    BackwardEuler,
}

/// a(x, v) = g − ω²·x − k·v.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearForce {
    pub g: f64,
    pub omega_sq: f64,
    pub k: f64,
}

impl LinearForce {
    pub fn accel(&self, x: f64, v: f64) -> f64 {
        self.g - self.omega_sq * x - self.k * v
    }
}

/// One step of size `h` from (x, v).
pub fn step(method: Integrator, f: &LinearForce, x: f64, v: f64, h: f64) -> (f64, f64) {
    match method {
        Integrator::ExplicitEuler => (x + h * v, v + h * f.accel(x, v)),
        Integrator::SemiImplicitEuler => {
            let v1 = v + h * f.accel(x, v);
            (x + h * v1, v1)
        }
        Integrator::Midpoint => {
            let (xm, vm) = (x + 0.5 * h * v, v + 0.5 * h * f.accel(x, v));
            (x + h * vm, v + h * f.accel(xm, vm))
        }
        Integrator::VelocityVerlet => {
            // The half-step velocity feeds the drag term of the second evaluation; without drag
            // this is the textbook scheme.
            let a0 = f.accel(x, v);
            let x1 = x + h * v + 0.5 * h * h * a0;
            let a1 = f.accel(x1, v + h * a0);
            (x1, v + 0.5 * h * (a0 + a1))
        }
        Integrator::BackwardEuler => {
            // v1 = v + h·(g − ω²·(x + h·v1) − k·v1), solved for v1; then x1 = x + h·v1.
            let v1 = (v + h * (f.g - f.omega_sq * x)) / (1.0 + h * h * f.omega_sq + h * f.k);
            (x + h * v1, v1)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use Integrator::*;

    const ALL: [Integrator; 5] = [ExplicitEuler, SemiImplicitEuler, Midpoint, VelocityVerlet, BackwardEuler];

    fn run(method: Integrator, f: &LinearForce, x0: f64, v0: f64, h: f64, t: f64, mut each: impl FnMut(f64, f64)) -> (f64, f64) {
        let (mut x, mut v) = (x0, v0);
        for _ in 0..(t / h).round() as usize {
            (x, v) = step(method, f, x, v, h);
            each(x, v);
        }
        (x, v)
    }

    #[test]
    fn projectile_error_against_the_parabola() {
        // Notes §7 test 1: x(T) = v0·T + ½·g·T², g = −9.81, v0 = 5, T = 1.
        let f = LinearForce { g: -9.81, omega_sq: 0.0, k: 0.0 };
        let exact = 5.0 - 0.5 * 9.81;
        for h in [0.1, 0.01] {
            let err = |m| run(m, &f, 0.0, 5.0, h, 1.0, |_, _| {}).0 - exact;
            assert!((err(ExplicitEuler) - 0.5 * 9.81 * h).abs() < 1e-9, "explicit at h={h}: {}", err(ExplicitEuler));
            assert!((err(SemiImplicitEuler) + 0.5 * 9.81 * h).abs() < 1e-9, "semi-implicit at h={h}: {}", err(SemiImplicitEuler));
            assert!(err(Midpoint).abs() < 1e-12);
            assert!(err(VelocityVerlet).abs() < 1e-12);
        }
    }

    #[test]
    fn oscillator_energy_over_a_hundred_seconds() {
        // Notes §7 test 2: ω = 1, x0 = 1, v0 = 0, T = 100; E/E0 at the end and its extremes.
        let f = LinearForce { g: 0.0, omega_sq: 1.0, k: 0.0 };
        let energy = |x: f64, v: f64| 0.5 * v * v + 0.5 * x * x;
        let ratios = |m, h| {
            let (mut lo, mut hi) = (1.0f64, 1.0f64);
            let (x, v) = run(m, &f, 1.0, 0.0, h, 100.0, |x, v| {
                let e = energy(x, v) / 0.5;
                lo = lo.min(e);
                hi = hi.max(e);
            });
            (energy(x, v) / 0.5, lo, hi)
        };
        let close = |a: f64, b: f64| (a / b - 1.0).abs() < 1e-3;
        // Explicit Euler gains (1 + ω²h²) per step: 20959 and 2.718 (notes).
        assert!(close(ratios(ExplicitEuler, 0.1).0, 1.01f64.powi(1000)));
        assert!(close(ratios(ExplicitEuler, 0.01).0, 1.0001f64.powi(10_000)));
        assert!(close(ratios(Midpoint, 0.1).0, 1.0253));
        assert!(close(ratios(BackwardEuler, 0.1).0, 4.771e-5));
        assert!(close(ratios(BackwardEuler, 0.01).0, 0.3679));
        // Symplectic Euler oscillates inside a band and reaches its edges: 1/1.05 and 1/0.95 at
        // h = 0.1.
        let (_, lo, hi) = ratios(SemiImplicitEuler, 0.1);
        assert!((0.952..0.953).contains(&lo) && (1.052..=1.053).contains(&hi), "symplectic h=0.1: [{lo}, {hi}]");
        let (_, lo, hi) = ratios(SemiImplicitEuler, 0.01);
        assert!((0.995..0.9951).contains(&lo) && (1.005..=1.0051).contains(&hi), "symplectic h=0.01: [{lo}, {hi}]");
        let (_, lo, hi) = ratios(VelocityVerlet, 0.1);
        assert!(lo >= 0.9975 && hi <= 1.0 + 1e-12, "verlet h=0.1: [{lo}, {hi}]");
    }

    #[test]
    fn drag_stability_threshold() {
        // Notes §7 test 3: a = −k·v from v0 = 1. Explicit Euler's factor is 1 − kh.
        let k = 1.0;
        let f = LinearForce { g: 0.0, omega_sq: 0.0, k };
        let vs = |m, h| {
            let mut out = vec![1.0];
            run(m, &f, 0.0, 1.0, h, 20.0 * h, |_, v| out.push(v));
            out
        };
        let diverging = vs(ExplicitEuler, 2.5 / k);
        assert!(diverging.last().unwrap().abs() > 1e3, "kh = 2.5 must diverge: {diverging:?}");
        let ringing = vs(ExplicitEuler, 1.5 / k);
        assert!(ringing.windows(2).all(|w| w[0] * w[1] < 0.0 && w[1].abs() < w[0].abs()), "kh = 1.5 oscillates and decays");
        for h in [1.5, 2.5, 10.0] {
            let v = vs(BackwardEuler, h / k);
            assert!(v.windows(2).all(|w| w[1] > 0.0 && w[1] < w[0]), "backward Euler overshot at kh = {h}");
        }
        for m in ALL {
            // Every method agrees with the exponential at a small step.
            let v = vs(m, 1e-3).last().copied().unwrap();
            assert!((v - (-20e-3f64).exp()).abs() < 1e-5, "{m:?}");
        }
    }
}
