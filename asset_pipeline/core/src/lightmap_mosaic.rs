//! Denoising a page's charts in few calls: each chart cut out on its own into a tile (its own
//! texels, scaled to a mean of 1, a margin filled from that chart alone), the tiles packed into a
//! few sheets, each sheet one call of the denoiser, the results cut back and scaled back.
//!
//! Why: OIDN costs ~0.6 ms a call however small the image, plus ~1.35 us a texel, and a level's
//! page holds thousands of charts of a few dozen texels (the 100k-triangle benchmark level: 2 706
//! charts, median 22 texels). One call per chart spent most of the clean-up on call overhead
//! and on the margins (2.4 M texels denoised for 0.7 M covered at an 8-texel margin).
//!
//! Why the tiles do not bleed into each other although they share a sheet:
//! - every tile is scaled by its chart's mean (over texels and channels), so every tile in a sheet
//!   has the same brightness: a bright chart cannot lift a dark one, whatever the contrast on the
//!   page (OIDN's `RTLightmap` is scale-equivariant: denoising `k x` gives `k` times the result,
//!   measured to 2e-6 over 1e-3..1e3, so a chart alone on a sheet gets exactly what it got before);
//! - a tile's chart texels are at least `2 margin` texels from any other tile's (each tile has its
//!   own margin, filled by dilating its chart only, then its mean);
//! - sheet texels outside every tile hold 1.0, the tiles' common mean level.
//! Charts whose texels are all zero are not denoised at all: OIDN turns an all-zero image into a
//! faint non-zero one (0.026 on a 16x16 of zeros), which put light into black charts.
//!
//! Packing: shelves, tiles by decreasing height (ties by chart id), sheets [`SHEET`] wide; a tile
//! wider than that gets a sheet of its own. Everything is in a fixed order: the same sheets for
//! the same page, whatever the thread count.

use crate::lightmap_post::dilate;
use crate::uv_raster::NONE;

/// Width of a sheet, texels (and the most rows a sheet gets before the next starts).
pub const SHEET: usize = 512;

/// One chart's tile: where its bounding box is on the page and where the tile is on its sheet.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tile {
    pub chart: u32,
    /// Bounding box of the chart's texels on the page: origin and size.
    pub y0: usize,
    pub x0: usize,
    pub h: usize,
    pub w: usize,
    /// The tile on its sheet: sheet index, top-left corner of the tile (margin included).
    pub sheet: usize,
    pub sy: usize,
    pub sx: usize,
    /// The chart's mean over its texels and channels (the tile holds texels / scale).
    pub scale: f32,
}

/// The tiles of a page and the size of each sheet.
#[derive(Debug, Clone, PartialEq)]
pub struct Mosaic {
    pub margin: usize,
    pub tiles: Vec<Tile>,
    /// (height, width) per sheet.
    pub sheets: Vec<(usize, usize)>,
}

/// Plan the sheets of an RGB page (`height * width * 3` f32) with its chart map.
pub fn plan(rgb: &[f32], chart: &[u32], width: usize, height: usize, margin: usize) -> Result<Mosaic, String> {
    if rgb.len() != width * height * 3 || chart.len() != width * height {
        return Err(format!("page of {} floats and {} chart texels, expected {} and {} for {width} x {height}", rgb.len(), chart.len(), width * height * 3, width * height));
    }
    // Bounding box, texel count and channel sum per chart, in one pass; charts by id.
    let mut by_chart: std::collections::BTreeMap<u32, (usize, usize, usize, usize, usize, f64)> = Default::default();
    for y in 0..height {
        for x in 0..width {
            let c = chart[y * width + x];
            if c == NONE {
                continue;
            }
            let v: f64 = rgb[(y * width + x) * 3..(y * width + x) * 3 + 3].iter().map(|&v| if v.is_finite() { v.max(0.0) as f64 } else { 0.0 }).sum();
            let e = by_chart.entry(c).or_insert((y, y, x, x, 0, 0.0));
            e.0 = e.0.min(y);
            e.1 = e.1.max(y);
            e.2 = e.2.min(x);
            e.3 = e.3.max(x);
            e.4 += 1;
            e.5 += v;
        }
    }
    let mut tiles: Vec<Tile> = by_chart
        .into_iter()
        .filter(|&(_, (.., sum))| sum > 0.0)
        .map(|(c, (ya, yb, xa, xb, n, sum))| Tile {
            chart: c,
            y0: ya,
            x0: xa,
            h: yb - ya + 1,
            w: xb - xa + 1,
            sheet: 0,
            sy: 0,
            sx: 0,
            scale: (sum / (3 * n) as f64) as f32,
        })
        .collect();
    // Shelves: tallest first (ties by chart id: the sort is stable over id order).
    let mut order: Vec<usize> = (0..tiles.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(tiles[i].h));
    let mut sheets: Vec<(usize, usize)> = Vec::new();
    let (mut x, mut y, mut shelf, mut open) = (0usize, 0usize, 0usize, None::<usize>);
    for i in order {
        let (th, tw) = (tiles[i].h + 2 * margin, tiles[i].w + 2 * margin);
        if tw > SHEET {
            // A sheet of its own.
            tiles[i].sheet = sheets.len();
            (tiles[i].sy, tiles[i].sx) = (0, 0);
            sheets.push((th, tw));
            continue;
        }
        if x + tw > SHEET {
            (x, y, shelf) = (0, y + shelf, 0);
        }
        // A new sheet when none is open or this tile would run past its last row (a tile taller
        // than a sheet, at the top of a new one, makes that sheet taller).
        let s = match open {
            Some(s) if y + th <= SHEET => s,
            _ => {
                sheets.push((0, SHEET));
                (x, y, shelf) = (0, 0, 0);
                sheets.len() - 1
            }
        };
        open = Some(s);
        tiles[i].sheet = s;
        (tiles[i].sy, tiles[i].sx) = (y, x);
        x += tw;
        shelf = shelf.max(th);
        sheets[s].0 = sheets[s].0.max(y + th);
    }
    Ok(Mosaic { margin, tiles, sheets })
}

/// The sheets of one RGB image of the page (`height * width * 3`), each `h * w * 3` f32: every
/// tile's chart texels divided by its scale, its margin dilated from its chart alone and the
/// rest of the tile at the chart's (scaled) mean; texels outside every tile at 1.0.
pub fn gather(m: &Mosaic, rgb: &[f32], chart: &[u32], width: usize) -> Vec<Vec<f32>> {
    let mut sheets: Vec<Vec<f32>> = m.sheets.iter().map(|&(h, w)| vec![1.0f32; h * w * 3]).collect();
    for t in &m.tiles {
        let (th, tw) = (t.h + 2 * m.margin, t.w + 2 * m.margin);
        let mut img = vec![0f32; th * tw * 3];
        let mut own = vec![NONE; th * tw];
        let (mut sum, mut n) = ([0f64; 3], 0usize);
        for y in 0..t.h {
            for x in 0..t.w {
                let p = (t.y0 + y) * width + t.x0 + x;
                if chart[p] != t.chart {
                    continue;
                }
                let q = (y + m.margin) * tw + x + m.margin;
                own[q] = 0;
                for k in 0..3 {
                    let v = rgb[p * 3 + k];
                    let v = if v.is_finite() { v.max(0.0) / t.scale } else { 0.0 };
                    img[q * 3 + k] = v;
                    sum[k] += v as f64;
                }
                n += 1;
            }
        }
        // Sizes are consistent by construction: dilation cannot fail.
        let _ = dilate(&mut img, &mut own, tw, th, m.margin);
        let mean = sum.map(|s| (s / n.max(1) as f64) as f32);
        let (sh, sw) = m.sheets[t.sheet];
        debug_assert!(t.sy + th <= sh && t.sx + tw <= sw);
        let sheet = &mut sheets[t.sheet];
        for y in 0..th {
            for x in 0..tw {
                let q = y * tw + x;
                let v = if own[q] == NONE { mean } else { [img[q * 3], img[q * 3 + 1], img[q * 3 + 2]] };
                let s = ((t.sy + y) * sw + t.sx + x) * 3;
                sheet[s..s + 3].copy_from_slice(&v);
            }
        }
    }
    sheets
}

/// Put the denoised sheets back: each tile's chart texels of `rgb` (in place) take the sheet's
/// value times the tile's scale (negative or non-finite results: 0). Texels of charts with no
/// tile (all zero) and gutter texels are left as they are.
pub fn scatter(m: &Mosaic, sheets: &[&[f32]], rgb: &mut [f32], chart: &[u32], width: usize) -> Result<(), String> {
    if sheets.len() != m.sheets.len() {
        return Err(format!("{} sheets given, {} planned", sheets.len(), m.sheets.len()));
    }
    for (i, (&(h, w), s)) in m.sheets.iter().zip(sheets).enumerate() {
        if s.len() != h * w * 3 {
            return Err(format!("sheet {i} has {} floats, expected {} for {h} x {w} x 3", s.len(), h * w * 3));
        }
    }
    for t in &m.tiles {
        let sw = m.sheets[t.sheet].1;
        let sheet = sheets[t.sheet];
        for y in 0..t.h {
            for x in 0..t.w {
                let p = (t.y0 + y) * width + t.x0 + x;
                if chart[p] != t.chart {
                    continue;
                }
                let s = ((t.sy + y + m.margin) * sw + t.sx + x + m.margin) * 3;
                for k in 0..3 {
                    let v = sheet[s + k] * t.scale;
                    rgb[p * 3 + k] = if v.is_finite() { v.max(0.0) } else { 0.0 };
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A page of `n` square charts of side `side`, 3 texels apart, chart i at value (i + 1) *
    /// 10^(i % 4) (contrasts of 1000 between neighbours), chart 2 all zero.
    fn page(n: usize, side: usize) -> (Vec<f32>, Vec<u32>, usize, usize) {
        let (w, h) = (n * (side + 3), side + 6);
        let mut rgb = vec![0f32; w * h * 3];
        let mut chart = vec![NONE; w * h];
        for i in 0..n {
            for y in 3..3 + side {
                for x in i * (side + 3)..i * (side + 3) + side {
                    chart[y * w + x] = 10 + i as u32;
                    let v = if i == 2 { 0.0 } else { (i + 1) as f32 * 10f32.powi((i % 4) as i32) * (1.0 + 0.1 * (x + y) as f32) };
                    rgb[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&[v, 0.5 * v, 0.25 * v]);
                }
            }
        }
        (rgb, chart, w, h)
    }

    #[test]
    fn tiles_never_overlap_and_keep_their_margins() {
        let (rgb, chart, w, h) = page(300, 7);
        let m = plan(&rgb, &chart, w, h, 2).unwrap();
        assert_eq!(m.tiles.len(), 299, "the all-zero chart gets no tile");
        assert!(m.tiles.iter().all(|t| t.chart != 12));
        let mut used: Vec<Vec<bool>> = m.sheets.iter().map(|&(sh, sw)| vec![false; sh * sw]).collect();
        for t in &m.tiles {
            let (sh, sw) = m.sheets[t.sheet];
            assert!(t.sy + t.h + 4 <= sh && t.sx + t.w + 4 <= sw && sw <= SHEET && sh <= SHEET, "{t:?}");
            for y in t.sy..t.sy + t.h + 4 {
                for x in t.sx..t.sx + t.w + 4 {
                    assert!(!std::mem::replace(&mut used[t.sheet][y * sw + x], true), "tiles overlap at {t:?}");
                }
            }
        }
        // 299 tiles of 11 x 11 fit 46 to a shelf of 512, 46 shelves to a sheet: one sheet.
        assert_eq!(m.sheets.len(), 1);
        // The same plan again (deterministic).
        assert_eq!(plan(&rgb, &chart, w, h, 2).unwrap(), m);
    }

    #[test]
    fn gather_then_scatter_of_the_sheets_unchanged_is_the_identity() {
        let (rgb, chart, w, h) = page(40, 5);
        let m = plan(&rgb, &chart, w, h, 3).unwrap();
        let sheets = gather(&m, &rgb, &chart, w);
        // Every tile is at mean 1 over its chart texels, and a neighbour's value never appears in it.
        for t in &m.tiles {
            let sw = m.sheets[t.sheet].1;
            let (mut sum, mut n) = (0f64, 0);
            for y in 0..t.h + 6 {
                for x in 0..t.w + 6 {
                    let s = ((t.sy + y) * sw + t.sx + x) * 3;
                    let v = &sheets[t.sheet][s..s + 3];
                    assert!(v[0] > 0.3 && v[0] < 3.0, "{t:?}: {v:?} is not this chart's (scaled) light");
                    if (3..t.h + 3).contains(&y) && (3..t.w + 3).contains(&x) {
                        sum += v.iter().map(|&v| v as f64).sum::<f64>() / 3.0;
                        n += 1;
                    }
                }
            }
            assert!((sum / n as f64 - 1.0).abs() < 1e-5, "{t:?}");
        }
        let views: Vec<&[f32]> = sheets.iter().map(|s| s.as_slice()).collect();
        let mut back = vec![7f32; rgb.len()];
        for (i, &c) in chart.iter().enumerate() {
            if c == NONE || c == 12 {
                back[i * 3..i * 3 + 3].copy_from_slice(&rgb[i * 3..i * 3 + 3]);
            }
        }
        scatter(&m, &views, &mut back, &chart, w).unwrap();
        for (a, b) in back.iter().zip(&rgb) {
            assert!((a - b).abs() <= 1e-6 * b.abs().max(1.0), "{a} != {b}");
        }
    }

    #[test]
    fn a_tile_wider_than_a_sheet_gets_its_own() {
        let (w, h) = (SHEET + 10, 4);
        let rgb = vec![1f32; w * h * 3];
        let mut chart = vec![NONE; w * h];
        chart[w..2 * w].fill(1); // one row, SHEET + 10 wide
        chart[3 * w] = 2; // one texel
        let m = plan(&rgb, &chart, w, h, 2).unwrap();
        assert_eq!(m.sheets.len(), 2);
        assert_eq!(m.sheets[m.tiles[0].sheet], (5, SHEET + 14));
        assert_eq!(m.sheets[m.tiles[1].sheet], (5, SHEET));
        assert!(scatter(&m, &[&[0.0; 3]], &mut rgb.clone(), &chart, w).is_err());
    }
}
