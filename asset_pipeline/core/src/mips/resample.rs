//! The separable f32 downsample (FCG ch.9.4.3, L5769): every needed source row is filtered
//! horizontally, then output rows are weighted sums of those. Work goes in bands of output rows,
//! one band per task, so the horizontal results stay in cache and the source is read row by
//! row (level 0 never exists as a whole f32 image).

use super::filter::{Edge, Filter, Taps};
use rayon::prelude::*;

/// Premultiplied linear RGBA (or whatever 4 channels the usage puts there).
pub type Texel = [f32; 4];

/// A float image, rows top to bottom.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub texels: Vec<Texel>,
}

impl Image {
    pub fn row(&self, y: usize) -> &[Texel] {
        &self.texels[y * self.width..(y + 1) * self.width]
    }
}

/// Output rows per task: larger bands filter fewer source rows twice (a band of B output rows
/// at 2:1 with an 8-tap kernel reads 2B + 6 rows), smaller ones keep a band's horizontally
/// filtered rows in L2 (38 rows of a 2048-texel level: 1.2 MB) and spread better over threads.
const BAND: usize = 16;

/// Downsample a `width` x `height` image whose rows `load_row(y, row)` fills, to
/// `out_w` x `out_h`. Deterministic: every sum runs in a fixed order whatever the thread count.
/// `edges`: along the width, then the height.
pub fn downsample<L>(width: usize, height: usize, load_row: L, out_w: usize, out_h: usize, filter: Filter, edges: [Edge; 2]) -> Image
where
    L: Fn(usize, &mut [Texel]) + Sync,
{
    let xt = Taps::downsample(width, out_w, filter, edges[0]);
    let yt = Taps::downsample(height, out_h, filter, edges[1]);
    let (pad_lo, pad_hi) = xt.padding();
    let (xt, yt) = (&xt, &yt);
    let mut texels = vec![[0.0f32; 4]; out_w * out_h];
    // Keep at least a few bands per thread on small levels.
    let band = BAND.min(out_h.div_ceil(4 * rayon::current_num_threads()).max(1));
    texels.par_chunks_mut(out_w * band).enumerate().for_each(|(b, out)| {
        let y0 = b * band;
        let rows = out.len() / out_w;
        let mut needed: Vec<usize> = (y0..y0 + rows).flat_map(|y| (0..yt.count).map(move |k| yt.first[y] + k as isize)).map(|j| yt.source(j)).collect();
        needed.sort_unstable();
        needed.dedup();
        // The source row with its edges extended, so every output's taps are consecutive.
        let mut padded = vec![[0.0f32; 4]; pad_lo + width + pad_hi];
        let mut filtered = vec![[0.0f32; 4]; needed.len() * out_w];
        for (k, &y) in needed.iter().enumerate() {
            load_row(y, &mut padded[pad_lo..pad_lo + width]);
            if xt.edge != Edge::Clamp {
                for p in 0..pad_lo {
                    padded[p] = padded[pad_lo + xt.source(p as isize - pad_lo as isize)];
                }
                for p in 0..pad_hi {
                    padded[pad_lo + width + p] = padded[pad_lo + xt.source((width + p) as isize)];
                }
            } // Clamp: the pads keep zeros, with weight 0.
            filter_row(&padded, pad_lo, &xt, &mut filtered[k * out_w..(k + 1) * out_w]);
        }
        let slot = |y: usize| needed.binary_search(&y).expect("every tap's row was filtered");
        for (r, out_row) in out.chunks_exact_mut(out_w).enumerate() {
            let y = y0 + r;
            let rows: Vec<&[Texel]> = (0..yt.count).map(|k| slot(yt.source(yt.first[y] + k as isize))).map(|s| &filtered[s * out_w..(s + 1) * out_w]).collect();
            sum_rows(&rows, &yt.weight[y * yt.count..(y + 1) * yt.count], out_row);
        }
    });
    Image { width: out_w, height: out_h, texels }
}

/// Calls `$f::<K>` for the tap count at hand, so the inner loops have a constant length the
/// compiler unrolls; counts outside the list (huge ratios) take the dynamic loop.
macro_rules! by_count {
    ($count:expr, $f:ident, $dynamic:ident, ($($arg:expr),*)) => {
        match $count {
            1 => $f::<1>($($arg),*),
            2 => $f::<2>($($arg),*),
            3 => $f::<3>($($arg),*),
            4 => $f::<4>($($arg),*),
            5 => $f::<5>($($arg),*),
            6 => $f::<6>($($arg),*),
            7 => $f::<7>($($arg),*),
            8 => $f::<8>($($arg),*),
            9 => $f::<9>($($arg),*),
            10 => $f::<10>($($arg),*),
            11 => $f::<11>($($arg),*),
            12 => $f::<12>($($arg),*),
            13 => $f::<13>($($arg),*),
            _ => $dynamic($($arg),*),
        }
    };
}

/// One padded row (`pad` texels before position 0) through the horizontal taps.
fn filter_row(padded: &[Texel], pad: usize, taps: &Taps, out: &mut [Texel]) {
    by_count!(taps.count, filter_row_k, filter_row_dyn, (padded, pad, taps, out))
}

fn filter_row_k<const K: usize>(padded: &[Texel], pad: usize, taps: &Taps, out: &mut [Texel]) {
    for ((o, &first), w) in out.iter_mut().zip(&taps.first).zip(taps.weight.chunks_exact(K)) {
        let s0 = (first + pad as isize) as usize;
        let src: &[Texel; K] = padded[s0..s0 + K].try_into().unwrap();
        let w: &[f32; K] = w.try_into().unwrap();
        let mut acc = [0.0f32; 4];
        for k in 0..K {
            for c in 0..4 {
                acc[c] += w[k] * src[k][c];
            }
        }
        *o = acc;
    }
}

fn filter_row_dyn(padded: &[Texel], pad: usize, taps: &Taps, out: &mut [Texel]) {
    let n = taps.count;
    for ((o, &first), w) in out.iter_mut().zip(&taps.first).zip(taps.weight.chunks_exact(n)) {
        let s0 = (first + pad as isize) as usize;
        let mut acc = [0.0f32; 4];
        for (s, &w) in padded[s0..s0 + n].iter().zip(w) {
            for c in 0..4 {
                acc[c] += w * s[c];
            }
        }
        *o = acc;
    }
}

/// `out = sum_k weights[k] * rows[k]`, texel by texel.
fn sum_rows(rows: &[&[Texel]], weights: &[f32], out: &mut [Texel]) {
    by_count!(rows.len(), sum_rows_k, sum_rows_dyn, (rows, weights, out))
}

fn sum_rows_k<const K: usize>(rows: &[&[Texel]], weights: &[f32], out: &mut [Texel]) {
    let rows: &[&[Texel]; K] = rows.try_into().unwrap();
    let w: &[f32; K] = weights.try_into().unwrap();
    let n = out.len();
    let rows: [&[Texel]; K] = std::array::from_fn(|k| &rows[k][..n]);
    for (x, o) in out.iter_mut().enumerate() {
        let mut acc = [0.0f32; 4];
        for k in 0..K {
            for c in 0..4 {
                acc[c] += w[k] * rows[k][x][c];
            }
        }
        *o = acc;
    }
}

fn sum_rows_dyn(rows: &[&[Texel]], weights: &[f32], out: &mut [Texel]) {
    out.fill([0.0; 4]);
    for (row, &w) in rows.iter().zip(weights) {
        for (o, s) in out.iter_mut().zip(row.iter()) {
            for c in 0..4 {
                o[c] += w * s[c];
            }
        }
    }
}
