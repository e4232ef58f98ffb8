//! Reconstruction/prefilter kernels at their natural scale (FCG 4th ed. ch.9.3.1), and the
//! discrete taps of one axis of a downsample built from them (ch.9.4.3).

/// A 1D kernel, evaluated at its natural scale; `Taps::downsample` scales it to the output
/// spacing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Filter {
    /// The 2x2 average at 2:1. Leaky (its transform is sinc): kept for previews and to show
    /// that the aliasing test can fail.
    Box,
    /// `1 - |x|`: non-negative, so HDR data never rings below zero.
    Tent,
    /// Cubic B-spline: non-negative and the strongest alias suppression here, but soft.
    BSpline,
    /// Mitchell-Netravali, B = C = 1/3: the book's pick, small negative lobes.
    Mitchell,
    /// Catmull-Rom: sharper than Mitchell, larger lobes, more aliasing.
    CatmullRom,
    /// Lanczos a = 3 (not in the book): what most image tools default to.
    Lanczos3,
}

impl Filter {
    pub const ALL: [Filter; 6] = [Filter::Box, Filter::Tent, Filter::BSpline, Filter::Mitchell, Filter::CatmullRom, Filter::Lanczos3];

    pub fn name(self) -> &'static str {
        match self {
            Filter::Box => "box",
            Filter::Tent => "tent",
            Filter::BSpline => "bspline",
            Filter::Mitchell => "mitchell",
            Filter::CatmullRom => "catmull-rom",
            Filter::Lanczos3 => "lanczos3",
        }
    }

    pub fn parse(name: &str) -> Result<Filter, String> {
        Filter::ALL.into_iter().find(|f| f.name() == name).ok_or_else(|| {
            let names: Vec<_> = Filter::ALL.iter().map(|f| f.name()).collect();
            format!("unknown filter '{name}' (expected one of {})", names.join(", "))
        })
    }

    /// Support radius at the natural scale.
    pub fn radius(self) -> f64 {
        match self {
            Filter::Box => 0.5,
            Filter::Tent => 1.0,
            Filter::BSpline | Filter::Mitchell | Filter::CatmullRom => 2.0,
            Filter::Lanczos3 => 3.0,
        }
    }

    /// No negative lobes: a non-negative input gives a non-negative output (HDR needs this).
    pub fn is_non_negative(self) -> bool {
        matches!(self, Filter::Box | Filter::Tent | Filter::BSpline)
    }

    pub fn eval(self, x: f64) -> f64 {
        let a = x.abs();
        match self {
            // Half-open, [-1/2, 1/2), so a tap exactly on the edge counts once.
            Filter::Box => f64::from(-0.5 <= x && x < 0.5),
            Filter::Tent => (1.0 - a).max(0.0),
            Filter::BSpline => bc_cubic(a, 1.0, 0.0),
            Filter::Mitchell => bc_cubic(a, 1.0 / 3.0, 1.0 / 3.0),
            Filter::CatmullRom => bc_cubic(a, 0.0, 0.5),
            Filter::Lanczos3 => {
                if a < 3.0 {
                    sinc(x) * sinc(x / 3.0)
                } else {
                    0.0
                }
            }
        }
    }
}

/// The Mitchell-Netravali family of cubics (B, C); (1,0) is the B-spline, (0,1/2) Catmull-Rom.
fn bc_cubic(a: f64, b: f64, c: f64) -> f64 {
    if a < 1.0 {
        ((12.0 - 9.0 * b - 6.0 * c) * a * a * a + (-18.0 + 12.0 * b + 6.0 * c) * a * a + (6.0 - 2.0 * b)) / 6.0
    } else if a < 2.0 {
        ((-b - 6.0 * c) * a * a * a + (6.0 * b + 30.0 * c) * a * a + (-12.0 * b - 48.0 * c) * a + (8.0 * b + 24.0 * c)) / 6.0
    } else {
        0.0
    }
}

fn sinc(x: f64) -> f64 {
    if x == 0.0 {
        1.0
    } else {
        let p = std::f64::consts::PI * x;
        p.sin() / p
    }
}

/// What to do with taps that fall outside the image: what the runtime's sampler does there, so
/// a level filters across the edge the way the texture is read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Edge {
    /// Wrap around: the texture repeats (the runtime's REPEAT sampler), so its levels tile too
    /// and the mean is preserved exactly.
    Wrap,
    /// Drop outside taps and renormalise what is left (the book's best option, L5758): the
    /// border keeps its intensity. For atlases and clamped textures.
    Clamp,
    /// Reflect at the edge (MIRRORED_REPEAT): the texture repeats mirrored, so the level does
    /// too.
    Mirror,
}

impl Edge {
    pub fn parse(name: &str) -> Result<Edge, String> {
        match name {
            "wrap" => Ok(Edge::Wrap),
            "clamp" => Ok(Edge::Clamp),
            "mirror" => Ok(Edge::Mirror),
            _ => Err(format!("unknown edge mode '{name}' (expected wrap, clamp or mirror)")),
        }
    }

    /// One mode for both axes ("wrap") or one per axis, along the width then the height
    /// ("wrap,clamp": glTF's wrapS and wrapT).
    pub fn parse_axes(text: &str) -> Result<[Edge; 2], String> {
        match text.split_once(',') {
            Some((s, t)) => Ok([Edge::parse(s.trim())?, Edge::parse(t.trim())?]),
            None => Edge::parse(text).map(|e| [e; 2]),
        }
    }
}

/// The taps of one axis of a resample from `n_in` to `n_out` texels. Output i reads the `count`
/// consecutive source positions from `first[i]` with `weight[i * count..][..count]`, which sum to
/// 1. Positions may lie outside `0..n_in`: with `Edge::Wrap` they wrap around, with
/// `Edge::Clamp` their weight is 0. A fixed count and consecutive positions let the inner loops
/// run without index lists (see `resample`).
#[derive(Debug, Clone)]
pub struct Taps {
    pub n_in: usize,
    pub edge: Edge,
    pub first: Vec<isize>,
    pub count: usize,
    pub weight: Vec<f32>,
}

impl Taps {
    /// Downsample taps (n_out <= n_in). Output i is centred at `-0.5 + dx (i + 0.5)` in input
    /// texel coordinates with `dx = n_in / n_out`, so odd sizes keep every texel and the level
    /// lines up with the sampler's texel centres (not `2i + 0.5`, which drifts for odd n). The
    /// filter is scaled by dx (its area stays 1) and each output's taps are renormalised to sum
    /// to 1, so a constant stays exactly constant (eq 9.4); at a clamped edge that is the
    /// book's renormalisation over the taps inside (L5758).
    pub fn downsample(n_in: usize, n_out: usize, filter: Filter, edge: Edge) -> Taps {
        assert!(n_out >= 1 && n_out <= n_in);
        if n_in == n_out {
            // This axis is already as small as it gets (1 texel, or the other axis is longer):
            // a copy, not a blur.
            return Taps { n_in, edge, first: (0..n_in as isize).collect(), count: 1, weight: vec![1.0; n_in] };
        }
        let dx = n_in as f64 / n_out as f64;
        let support = filter.radius() * dx;
        let centre = |i: usize| -0.5 + dx * (i as f64 + 0.5);
        let span = |i: usize| ((centre(i) - support).ceil() as isize, (centre(i) + support).floor() as isize);
        let count = (0..n_out).map(|i| span(i)).map(|(lo, hi)| (hi - lo + 1) as usize).max().unwrap_or(1);
        let mut taps = Taps { n_in, edge, first: Vec::with_capacity(n_out), count, weight: Vec::with_capacity(n_out * count) };
        let mut row = vec![0.0f64; count];
        for i in 0..n_out {
            let (lo, _) = span(i);
            for (k, w) in row.iter_mut().enumerate() {
                let j = lo + k as isize;
                let inside = (0..n_in as isize).contains(&j);
                *w = if edge == Edge::Clamp && !inside { 0.0 } else { filter.eval((j as f64 - centre(i)) / dx) };
            }
            let sum: f64 = row.iter().sum();
            debug_assert!(sum > 0.0, "every output has a positive weight sum");
            taps.first.push(lo);
            taps.weight.extend(row.iter().map(|w| (w / sum) as f32));
        }
        taps
    }

    pub fn len(&self) -> usize {
        self.first.len()
    }

    /// The source index of position `j` (wrapped, mirrored, or clamped where the weight is 0
    /// anyway).
    pub fn source(&self, j: isize) -> usize {
        let n = self.n_in as isize;
        match self.edge {
            Edge::Wrap => j.rem_euclid(n) as usize,
            Edge::Clamp => j.clamp(0, n - 1) as usize,
            Edge::Mirror => {
                let m = j.rem_euclid(2 * n);
                (if m < n { m } else { 2 * n - 1 - m }) as usize
            }
        }
    }

    /// Output i's (source index, weight) pairs with a non-zero weight.
    pub fn of(&self, i: usize) -> impl Iterator<Item = (usize, f32)> + '_ {
        let w = &self.weight[i * self.count..(i + 1) * self.count];
        w.iter().enumerate().filter(|(_, &w)| w != 0.0).map(move |(k, &w)| (self.source(self.first[i] + k as isize), w))
    }

    /// How far positions reach before 0 and past `n_in - 1`.
    pub fn padding(&self) -> (usize, usize) {
        let lo = self.first.iter().map(|&f| (-f).max(0) as usize).max().unwrap_or(0);
        let hi = self.first.iter().map(|&f| (f + self.count as isize - self.n_in as isize).max(0) as usize).max().unwrap_or(0);
        (lo, hi)
    }
}
