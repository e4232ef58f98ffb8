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
/// at 2:1 with an 8-tap kernel reads 2B + 6 rows), smaller ones spread better over threads.
const BAND: usize = 32;

/// Downsample a `width` x `height` image whose rows `load_row(y, row)` fills, to
/// `out_w` x `out_h`. Deterministic: every sum runs in a fixed order whatever the thread count.
pub fn downsample<L>(width: usize, height: usize, load_row: L, out_w: usize, out_h: usize, filter: Filter, edge: Edge) -> Image
where
    L: Fn(usize, &mut [Texel]) + Sync,
{
    let xt = Taps::downsample(width, out_w, filter, edge);
    let yt = Taps::downsample(height, out_h, filter, edge);
    let mut texels = vec![[0.0f32; 4]; out_w * out_h];
    // Keep at least a few bands per thread on small levels.
    let band = BAND.min(out_h.div_ceil(4 * rayon::current_num_threads()).max(1));
    texels.par_chunks_mut(out_w * band).enumerate().for_each(|(b, out)| {
        let y0 = b * band;
        let rows = out.len() / out_w;
        let mut needed: Vec<u32> = (y0..y0 + rows).flat_map(|y| yt.index[yt.start[y]..yt.start[y + 1]].iter().copied()).collect();
        needed.sort_unstable();
        needed.dedup();
        let mut src = vec![[0.0f32; 4]; width];
        let mut filtered = vec![[0.0f32; 4]; needed.len() * out_w];
        for (k, &y) in needed.iter().enumerate() {
            load_row(y as usize, &mut src);
            filter_row(&src, &xt, &mut filtered[k * out_w..(k + 1) * out_w]);
        }
        for (r, out_row) in out.chunks_exact_mut(out_w).enumerate() {
            for (y, w) in yt.of(y0 + r) {
                let k = needed.binary_search(&(y as u32)).expect("every tap's row was filtered");
                add_scaled(out_row, w, &filtered[k * out_w..(k + 1) * out_w]);
            }
        }
    });
    Image { width: out_w, height: out_h, texels }
}

/// One row through the horizontal taps.
fn filter_row(src: &[Texel], taps: &Taps, out: &mut [Texel]) {
    for (i, o) in out.iter_mut().enumerate() {
        let mut acc = [0.0f32; 4];
        for (j, w) in taps.of(i) {
            let s = src[j];
            for c in 0..4 {
                acc[c] += w * s[c];
            }
        }
        *o = acc;
    }
}

/// `out += w * row`, texel by texel.
fn add_scaled(out: &mut [Texel], w: f32, row: &[Texel]) {
    for (o, s) in out.iter_mut().zip(row) {
        for c in 0..4 {
            o[c] += w * s[c];
        }
    }
}
