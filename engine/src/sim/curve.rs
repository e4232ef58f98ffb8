//! Values over a particle's normalised age t in [0, 1]: piecewise-linear curves (size) and
//! colour gradients (linear RGBA), the notes' "appearance over age".
//!
//! Keys are few (two to five), so evaluation is a linear scan; it runs once per particle per
//! rendered frame. Outside the keys the end values hold. An empty curve is a constant 1 (and an
//! empty gradient opaque white), so a missing table in a level file changes nothing.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Curve {
    /// (t, value), t ascending.
    pub keys: Vec<[f32; 2]>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Gradient {
    /// (t, [r, g, b, a]) in linear colour, t ascending.
    pub keys: Vec<(f32, [f32; 4])>,
}

/// The keys `(a, b)` around `t` (`a == b` before the first key, after the last, or on a single
/// key), from the keys' times in ascending order.
fn segment(ts: impl Iterator<Item = f32>, t: f32) -> (usize, usize) {
    let mut last = 0;
    for (i, ti) in ts.enumerate() {
        if t < ti {
            return if i == 0 { (0, 0) } else { (i - 1, i) };
        }
        last = i;
    }
    (last, last)
}

impl Curve {
    pub fn constant(v: f32) -> Curve {
        Curve { keys: vec![[0.0, v]] }
    }

    pub fn linear(from: f32, to: f32) -> Curve {
        Curve { keys: vec![[0.0, from], [1.0, to]] }
    }

    pub fn eval(&self, t: f32) -> f32 {
        let k = &self.keys;
        if k.is_empty() {
            return 1.0;
        }
        let (a, b) = segment(k.iter().map(|k| k[0]), t);
        if a == b {
            return k[a][1];
        }
        let w = (t - k[a][0]) / (k[b][0] - k[a][0]);
        k[a][1] + (k[b][1] - k[a][1]) * w
    }
}

impl Gradient {
    pub fn constant(c: [f32; 4]) -> Gradient {
        Gradient { keys: vec![(0.0, c)] }
    }

    pub fn eval(&self, t: f32) -> [f32; 4] {
        let k = &self.keys;
        if k.is_empty() {
            return [1.0; 4];
        }
        let (a, b) = segment(k.iter().map(|k| k.0), t);
        if a == b {
            return k[a].1;
        }
        let w = (t - k[a].0) / (k[b].0 - k[a].0);
        let (ca, cb) = (k[a].1, k[b].1);
        std::array::from_fn(|i| ca[i] + (cb[i] - ca[i]) * w)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curves_interpolate_between_keys_and_hold_outside() {
        let c = Curve {
            keys: vec![[0.0, 1.0], [0.5, 3.0], [1.0, 0.0]],
        };
        assert_eq!(c.eval(-1.0), 1.0);
        assert_eq!(c.eval(0.0), 1.0);
        assert_eq!(c.eval(0.25), 2.0);
        assert_eq!(c.eval(0.5), 3.0);
        assert_eq!(c.eval(0.75), 1.5);
        assert_eq!(c.eval(2.0), 0.0);
        assert_eq!(Curve { keys: vec![] }.eval(0.3), 1.0);
        let g = Gradient {
            keys: vec![(0.0, [1.0, 0.0, 0.0, 1.0]), (1.0, [0.0, 0.0, 1.0, 0.0])],
        };
        assert_eq!(g.eval(0.5), [0.5, 0.0, 0.5, 0.5]);
        assert_eq!(g.eval(1.0), [0.0, 0.0, 1.0, 0.0]);
    }
}
