//! Texel rasterisation in lightmap (UV2) space.
//!
//! One atlas page is a grid of `width x height` texels; texel `(x, y)` is the square
//! `[x, x+1] x [y, y+1]` in texel units, its centre `(x+0.5, y+0.5)`. A vertex's UV2 (`uv1` in the
//! scene IR) is in `[0, 1]` of its page, so its texel-unit position is `(u * width, v * height)`:
//! the same mapping the runtime's sampler uses, so everything measured here is what is sampled.
//!
//! Two coverage rules (see [`Coverage`]):
//! - **centre**: a texel belongs to the triangle that contains its centre. Shared edges follow a
//!   fill rule, so a chart's interior texels are claimed once. This is "the chart at the chosen
//!   resolution", used for the overlap test and for utilisation.
//! - **conservative**: a texel belongs to every triangle that overlaps its square with positive
//!   area. These are the texels the baker must bake: bilinear sampling anywhere inside a chart
//!   reads only conservative texels of that chart and their 1-texel ring (filled by dilation).
//!
//! Per texel the raster keeps one triangle (the nearest to the texel centre, lowest index on ties),
//! its chart, whether more than one chart claimed the texel, and the barycentric coordinates of
//! the sample point: the nearest point to the texel centre of the triangle shrunk by
//! [`SAMPLE_INSET`] (the centre itself, away from edges). [`surface`] turns those into world positions and normals for the
//! baker; [`chart_separation`] measures the gap between charts for the padding rule.
//!
//! Work is split into bands of rows processed in parallel (rayon); triangles within a band are
//! visited in index order, so the result does not depend on the thread count.

use rayon::prelude::*;
use std::path::Path;

/// "No triangle / no chart" in [`Raster::triangle`] and [`Raster::chart`].
pub const NONE: u32 = u32::MAX;

/// [`chart_separation`] value for texels no chart covers.
pub const NOT_COVERED: u8 = u8::MAX;

/// Texel squares are shrunk by this much (in texels) on each side before the conservative overlap
/// test, so a chart that merely touches a texel's edge (zero-area contact, or float noise of
/// ~1e-4 texel from storing UVs as f32) does not claim it. Bilinear sampling at such a contact
/// point gives that texel weight <= 1e-3.
pub const CONSERVATIVE_EPS: f64 = 1e-3;

/// Sample points keep this far (in texels) inside their triangle's edges: see `Prepared::sample`.
/// A tenth of a texel moves no sample out of its texel and lifts it a few millimetres clear of
/// the neighbouring surface at any practical density (6 mm at 16 texels per metre).
pub const SAMPLE_INSET: f64 = 0.1;

/// Largest page side accepted (a 16k x 16k page already needs ~2.4 GB of raster state).
pub const MAX_PAGE_SIDE: usize = 16384;

const BAND_ROWS: usize = 16;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coverage {
    /// The triangle contains the texel centre (top-left style fill rule on edges).
    Centre,
    /// The triangle overlaps the texel square with positive area.
    Conservative,
}

/// Triangles in UV2 space for one page: flat arrays, as numpy hands them over.
#[derive(Clone, Copy, Debug)]
pub struct UvTriangles<'a> {
    /// `2 * n` floats: `(u, v)` per vertex in `[0, 1]` of the page.
    pub uv: &'a [f32],
    /// `3 * m` vertex indices.
    pub triangles: &'a [u32],
    /// `m` chart ids (any numbering; only equality matters).
    pub charts: &'a [u32],
}

impl UvTriangles<'_> {
    pub fn vertex_count(&self) -> usize {
        self.uv.len() / 2
    }
    pub fn triangle_count(&self) -> usize {
        self.triangles.len() / 3
    }

    /// Check lengths and index ranges; the message names what is wrong.
    pub fn validate(&self) -> Result<(), String> {
        if self.uv.len() % 2 != 0 {
            return Err(format!("uv has {} floats, not a multiple of 2", self.uv.len()));
        }
        if self.triangles.len() % 3 != 0 {
            return Err(format!("triangles has {} indices, not a multiple of 3", self.triangles.len()));
        }
        if self.charts.len() != self.triangle_count() {
            return Err(format!("{} chart ids for {} triangles", self.charts.len(), self.triangle_count()));
        }
        let n = self.vertex_count();
        if let Some((i, &v)) = self.triangles.iter().enumerate().find(|(_, &v)| v as usize >= n) {
            return Err(format!("triangle {} uses vertex {v}, but there are {n} vertices", i / 3));
        }
        if let Some(i) = self.uv.iter().position(|x| !x.is_finite()) {
            return Err(format!("vertex {} has a non-finite uv", i / 2));
        }
        Ok(())
    }
}

/// The coverage of one page. Every per-texel array is row-major, `width * height` long
/// (`bary` is `3 * width * height`).
#[derive(Clone, Debug, PartialEq)]
pub struct Raster {
    pub width: usize,
    pub height: usize,
    pub coverage: Coverage,
    /// Triangle index per texel, or [`NONE`].
    pub triangle: Vec<u32>,
    /// Chart id of that triangle, or [`NONE`].
    pub chart: Vec<u32>,
    /// How many distinct charts claim the texel: 0, 1, or 2 meaning "two or more" (an overlap).
    pub charts_here: Vec<u8>,
    /// Barycentric coordinates (w.r.t. the triangle's vertices in order) of the sample point.
    pub bary: Vec<f32>,
}

impl Raster {
    pub fn covered(&self) -> usize {
        self.charts_here.iter().filter(|&&c| c > 0).count()
    }
    /// Texels claimed by two or more different charts.
    pub fn overlapping(&self) -> usize {
        self.charts_here.iter().filter(|&&c| c > 1).count()
    }
}

fn check_size(width: usize, height: usize) -> Result<(), String> {
    if width == 0 || height == 0 || width > MAX_PAGE_SIDE || height > MAX_PAGE_SIDE {
        return Err(format!("page size {width}x{height} is outside 1..={MAX_PAGE_SIDE}"));
    }
    Ok(())
}

/// One triangle prepared for rasterising: texel-unit corners (oriented counter-clockwise in
/// the x-right/y-down frame, i.e. positive signed area), edge equations and bounding box.
struct Prepared {
    p: [[f64; 2]; 3],
    /// Which original vertex (0..3) each of `p` is (orientation may swap two).
    order: [usize; 3],
    /// Edge i runs from p[i] to p[(i+1)%3]; `e(q) = a*x + b*y + c`, >= 0 inside.
    edges: [[f64; 3]; 3],
    /// Fill rule: whether a centre exactly on edge i is inside.
    owns_edge: [bool; 3],
    x0: i64,
    x1: i64,
    y0: i64,
    y1: i64,
}

fn prepare(t: UvTriangles, i: usize, width: usize, height: usize) -> Option<Prepared> {
    let (w, h) = (width as f64, height as f64);
    let corner = |k: usize| {
        let v = t.triangles[3 * i + k] as usize;
        [t.uv[2 * v] as f64 * w, t.uv[2 * v + 1] as f64 * h]
    };
    let mut p = [corner(0), corner(1), corner(2)];
    let mut order = [0, 1, 2];
    let cross = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
    let area2 = cross(p[0], p[1], p[2]);
    if area2 == 0.0 || !area2.is_finite() {
        // No area in UV space: nothing to sample, nothing to bake.
        return None;
    }
    if area2 < 0.0 {
        p.swap(1, 2);
        order.swap(1, 2);
    }
    let mut edges = [[0.0; 3]; 3];
    let mut owns_edge = [false; 3];
    for k in 0..3 {
        // Evaluate every edge from its lexicographically smaller end, so the two triangles
        // sharing an edge compute bit-identical (negated) edge values and the fill rule is exact.
        let (a, b) = (p[k], p[(k + 1) % 3]);
        let (s, e, sign) = if (a[0], a[1]) <= (b[0], b[1]) { (a, b, 1.0) } else { (b, a, -1.0) };
        // e(q) = cross(e - s, q - s) = (e-s).x * (q.y - s.y) - (e-s).y * (q.x - s.x)
        let (dx, dy) = (e[0] - s[0], e[1] - s[1]);
        edges[k] = [-dy * sign, dx * sign, (dy * s[0] - dx * s[1]) * sign];
        // Of an edge's two directions exactly one is owned, so a centre on an edge shared by
        // two triangles goes to exactly one of them.
        let (ddx, ddy) = (b[0] - a[0], b[1] - a[1]);
        owns_edge[k] = ddy < 0.0 || (ddy == 0.0 && ddx > 0.0);
    }
    let minx = p.iter().map(|q| q[0]).fold(f64::INFINITY, f64::min);
    let maxx = p.iter().map(|q| q[0]).fold(f64::NEG_INFINITY, f64::max);
    let miny = p.iter().map(|q| q[1]).fold(f64::INFINITY, f64::min);
    let maxy = p.iter().map(|q| q[1]).fold(f64::NEG_INFINITY, f64::max);
    let clamp_x = |v: f64| (v.floor() as i64).clamp(0, width as i64 - 1);
    let clamp_y = |v: f64| (v.floor() as i64).clamp(0, height as i64 - 1);
    if maxx < 0.0 || maxy < 0.0 || minx > w || miny > h {
        return None;
    }
    Some(Prepared { p, order, edges, owns_edge, x0: clamp_x(minx), x1: clamp_x(maxx), y0: clamp_y(miny), y1: clamp_y(maxy) })
}

impl Prepared {
    fn edge(&self, k: usize, q: [f64; 2]) -> f64 {
        let [a, b, c] = self.edges[k];
        a * q[0] + b * q[1] + c
    }

    fn contains_centre(&self, q: [f64; 2]) -> bool {
        (0..3).all(|k| {
            let e = self.edge(k, q);
            e > 0.0 || (e == 0.0 && self.owns_edge[k])
        })
    }

    /// Does the triangle overlap the square `[x+eps, x+1-eps] x [y+eps, y+1-eps]`? Separating axes:
    /// x and y (the bounding box, checked by the caller's loop bounds plus here) and the three
    /// edge normals.
    fn overlaps_texel(&self, x: i64, y: i64) -> bool {
        let lo = [x as f64 + CONSERVATIVE_EPS, y as f64 + CONSERVATIVE_EPS];
        let hi = [x as f64 + 1.0 - CONSERVATIVE_EPS, y as f64 + 1.0 - CONSERVATIVE_EPS];
        for axis in 0..2 {
            let mn = self.p.iter().map(|q| q[axis]).fold(f64::INFINITY, f64::min);
            let mx = self.p.iter().map(|q| q[axis]).fold(f64::NEG_INFINITY, f64::max);
            if mx < lo[axis] || mn > hi[axis] {
                return false;
            }
        }
        let c = [x as f64 + 0.5, y as f64 + 0.5];
        let half = 0.5 - CONSERVATIVE_EPS;
        (0..3).all(|k| {
            let [a, b, _] = self.edges[k];
            self.edge(k, c) + (a.abs() + b.abs()) * half >= 0.0
        })
    }

    /// Nearest point of the (closed) triangle to `q`: squared distance and barycentric
    /// coordinates in `p`'s (counter-clockwise) order.
    fn nearest_ccw(&self, q: [f64; 2]) -> (f64, [f64; 3]) {
        let area2 = self.edge(0, self.p[2]); // e0 at the opposite vertex = twice the area
        let l = [self.edge(1, q) / area2, self.edge(2, q) / area2, self.edge(0, q) / area2];
        let mut best = if l.iter().all(|&v| v >= 0.0) { (0.0, l) } else { (f64::INFINITY, [0.0; 3]) };
        if best.0 > 0.0 {
            for k in 0..3 {
                let (a, b) = (self.p[k], self.p[(k + 1) % 3]);
                let d = [b[0] - a[0], b[1] - a[1]];
                let len2 = d[0] * d[0] + d[1] * d[1];
                let t = if len2 > 0.0 { (((q[0] - a[0]) * d[0] + (q[1] - a[1]) * d[1]) / len2).clamp(0.0, 1.0) } else { 0.0 };
                let r = [a[0] + t * d[0] - q[0], a[1] + t * d[1] - q[1]];
                let dist2 = r[0] * r[0] + r[1] * r[1];
                if dist2 < best.0 {
                    let mut lam = [0.0; 3];
                    lam[k] = 1.0 - t;
                    lam[(k + 1) % 3] = t;
                    best = (dist2, lam);
                }
            }
        }
        best
    }

    /// Squared distance from `q` to the triangle (which of several overlapping triangles a
    /// texel belongs to).
    fn distance2(&self, q: [f64; 2]) -> f64 {
        self.nearest_ccw(q).0
    }

    /// Where the texel at `q` is baked, as barycentric coordinates w.r.t. the original vertex
    /// order: the nearest point to `q` of the triangle shrunk by SAMPLE_INSET texels from each
    /// edge (about its incentre; its incentre if it is thinner than that). A point on the
    /// triangle's edge would be where its surface meets the next one (a floor's edge is the
    /// foot of the wall): rays from it start on that wall's plane and slip behind it, so the
    /// texel bakes the dark (or sunlit) outside. An inside corner came out 11% too dark.
    fn sample(&self, q: [f64; 2]) -> [f64; 3] {
        let side = |i: usize, j: usize| ((self.p[i][0] - self.p[j][0]).powi(2) + (self.p[i][1] - self.p[j][1]).powi(2)).sqrt();
        let lengths = [side(1, 2), side(2, 0), side(0, 1)]; // opposite each vertex
        let perimeter = lengths.iter().sum::<f64>();
        let incentre = lengths.map(|l| l / perimeter);
        let inradius = self.edge(0, self.p[2]) / perimeter;
        let s = ((inradius - SAMPLE_INSET) / inradius).max(0.0);
        let lam = if s > 0.0 {
            // The shrunk triangle is the homothety of factor s about the incentre I, so its
            // nearest point to q is that map of the triangle's nearest point to I + (q - I) / s.
            let centre = [0, 1].map(|c| (0..3).map(|k| incentre[k] * self.p[k][c]).sum::<f64>());
            let far = [0, 1].map(|c| centre[c] + (q[c] - centre[c]) / s);
            let l = self.nearest_ccw(far).1;
            [0, 1, 2].map(|k| s * l[k] + (1.0 - s) * incentre[k])
        } else {
            incentre
        };
        let mut out = [0.0; 3];
        for k in 0..3 {
            out[self.order[k]] = lam[k];
        }
        out
    }
}

/// Rasterise `tris` onto a `width x height` page.
pub fn rasterize(tris: UvTriangles, width: usize, height: usize, coverage: Coverage) -> Result<Raster, String> {
    tris.validate()?;
    check_size(width, height)?;
    let m = tris.triangle_count();
    let prepared: Vec<Option<Prepared>> = (0..m).into_par_iter().map(|i| prepare(tris, i, width, height)).collect();

    // Bin triangles into bands of rows (index order is kept inside each band).
    let bands = height.div_ceil(BAND_ROWS);
    let mut binned: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (i, p) in prepared.iter().enumerate() {
        if let Some(p) = p {
            for band in &mut binned[p.y0 as usize / BAND_ROWS..=p.y1 as usize / BAND_ROWS] {
                band.push(i as u32);
            }
        }
    }

    let n = width * height;
    let mut out = Raster {
        width,
        height,
        coverage,
        triangle: vec![NONE; n],
        chart: vec![NONE; n],
        charts_here: vec![0; n],
        bary: vec![0.0; 3 * n],
    };
    let band_len = BAND_ROWS * width;
    out.triangle
        .par_chunks_mut(band_len)
        .zip(out.chart.par_chunks_mut(band_len))
        .zip(out.charts_here.par_chunks_mut(band_len))
        .zip(out.bary.par_chunks_mut(3 * band_len))
        .enumerate()
        .for_each(|(band, (((tri_out, chart_out), here_out), bary_out))| {
            let row0 = band * BAND_ROWS;
            let rows = tri_out.len() / width;
            let mut dist = vec![f64::INFINITY; tri_out.len()];
            for &i in &binned[band] {
                let p = prepared[i as usize].as_ref().expect("binned triangles are prepared");
                let chart = tris.charts[i as usize];
                let ya = (p.y0 as usize).max(row0);
                let yb = (p.y1 as usize).min(row0 + rows - 1);
                for y in ya..=yb {
                    for x in p.x0 as usize..=p.x1 as usize {
                        let q = [x as f64 + 0.5, y as f64 + 0.5];
                        let hit = match coverage {
                            Coverage::Centre => p.contains_centre(q),
                            Coverage::Conservative => p.overlaps_texel(x as i64, y as i64),
                        };
                        if !hit {
                            continue;
                        }
                        let t = (y - row0) * width + x;
                        match here_out[t] {
                            0 => here_out[t] = 1,
                            1 if chart_out[t] != chart => here_out[t] = 2,
                            _ => {}
                        }
                        let d2 = p.distance2(q);
                        // Nearest triangle wins; on a tie the lower index (visited first) stays.
                        if d2 < dist[t] {
                            let lam = p.sample(q);
                            dist[t] = d2;
                            tri_out[t] = i;
                            chart_out[t] = chart;
                            for k in 0..3 {
                                bary_out[3 * t + k] = lam[k] as f32;
                            }
                        }
                    }
                }
            }
        });
    Ok(out)
}

/// World position and unit normal at every covered texel's sample point, interpolated with the
/// raster's barycentrics (`3 * width * height` floats each; zeros where no chart is). `normals`
/// are per-vertex and interpolated then normalised; without them (or where they cancel out) the
/// triangle's geometric normal is used, oriented by its winding (counter-clockwise = front).
pub fn surface(
    raster: &Raster,
    triangles: &[u32],
    positions: &[f32],
    normals: Option<&[f32]>,
) -> Result<(Vec<f32>, Vec<f32>), String> {
    let n_vertices = positions.len() / 3;
    if positions.len() % 3 != 0 {
        return Err(format!("positions has {} floats, not a multiple of 3", positions.len()));
    }
    if let Some(nrm) = normals {
        if nrm.len() != positions.len() {
            return Err(format!("{} normal floats for {} position floats", nrm.len(), positions.len()));
        }
    }
    let m = triangles.len() / 3;
    if let Some(&t) = raster.triangle.iter().find(|&&t| t != NONE && t as usize >= m) {
        return Err(format!("raster refers to triangle {t}, but there are {m} triangles"));
    }
    if let Some(&v) = triangles.iter().find(|&&v| v as usize >= n_vertices) {
        return Err(format!("a triangle uses vertex {v}, but there are {n_vertices} vertices"));
    }
    let texels = raster.width * raster.height;
    let mut pos = vec![0.0f32; 3 * texels];
    let mut nrm_out = vec![0.0f32; 3 * texels];
    let get = |a: &[f32], v: u32| -> [f64; 3] {
        let v = v as usize;
        [a[3 * v] as f64, a[3 * v + 1] as f64, a[3 * v + 2] as f64]
    };
    pos.par_chunks_mut(3 * raster.width)
        .zip(nrm_out.par_chunks_mut(3 * raster.width))
        .enumerate()
        .for_each(|(y, (prow, nrow))| {
            for x in 0..raster.width {
                let t = y * raster.width + x;
                let tri = raster.triangle[t];
                if tri == NONE {
                    continue;
                }
                let vs = [triangles[3 * tri as usize], triangles[3 * tri as usize + 1], triangles[3 * tri as usize + 2]];
                let lam = [raster.bary[3 * t] as f64, raster.bary[3 * t + 1] as f64, raster.bary[3 * t + 2] as f64];
                let p = vs.map(|v| get(positions, v));
                let mut q = [0.0; 3];
                for k in 0..3 {
                    q[k] = lam[0] * p[0][k] + lam[1] * p[1][k] + lam[2] * p[2][k];
                }
                let mut nv = [0.0; 3];
                if let Some(nrm) = normals {
                    let nn = vs.map(|v| get(nrm, v));
                    for k in 0..3 {
                        nv[k] = lam[0] * nn[0][k] + lam[1] * nn[1][k] + lam[2] * nn[2][k];
                    }
                }
                if normalize(&mut nv).is_none() {
                    let e1 = [p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]];
                    let e2 = [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]];
                    nv = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
                    if normalize(&mut nv).is_none() {
                        nv = [0.0; 3];
                    }
                }
                for k in 0..3 {
                    prow[3 * x + k] = q[k] as f32;
                    nrow[3 * x + k] = nv[k] as f32;
                }
            }
        });
    Ok((pos, nrm_out))
}

fn normalize(v: &mut [f64; 3]) -> Option<()> {
    let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if len > 1e-12 && len.is_finite() {
        v.iter_mut().for_each(|c| *c /= len);
        Some(())
    } else {
        None
    }
}

/// For every covered texel, the Chebyshev distance (in texels) to the nearest texel of another
/// chart: 0 if the texel itself is claimed by two charts, `limit + 1` if none is within `limit`.
/// Texels no chart covers get [`NOT_COVERED`].
///
/// The padding rule "dilating each chart by `padding` texels reaches no other chart" holds
/// exactly when every covered texel has a separation greater than `padding`.
pub fn chart_separation(raster: &Raster, limit: u8) -> Result<Vec<u8>, String> {
    separation(&raster.chart, &raster.charts_here, raster.width, raster.height, limit)
}

/// [`chart_separation`] on bare `chart` / `charts_here` maps (as [`Raster`] holds them).
pub fn separation(chart: &[u32], charts_here: &[u8], width: usize, height: usize, limit: u8) -> Result<Vec<u8>, String> {
    if limit >= NOT_COVERED - 1 {
        return Err(format!("separation limit {limit} must be below {}", NOT_COVERED - 1));
    }
    check_size(width, height)?;
    if chart.len() != width * height || charts_here.len() != width * height {
        return Err(format!("chart maps of {} and {} texels for a {width}x{height} page", chart.len(), charts_here.len()));
    }
    let (w, h) = (width as i64, height as i64);
    let other = |x: i64, y: i64, c: u32| -> bool {
        if x < 0 || y < 0 || x >= w || y >= h {
            return false;
        }
        let t = (y * w + x) as usize;
        charts_here[t] > 1 || (charts_here[t] == 1 && chart[t] != c)
    };
    let mut out = vec![NOT_COVERED; width * height];
    out.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
        let y = y as i64;
        for x in 0..w {
            let t = (y * w + x) as usize;
            row[x as usize] = match charts_here[t] {
                0 => NOT_COVERED,
                2.. => 0,
                _ => {
                    let c = chart[t];
                    let ring = |r: i64| {
                        (-r..=r).any(|d| other(x + d, y - r, c) || other(x + d, y + r, c))
                            || (-r + 1..r).any(|d| other(x - r, y + d, c) || other(x + r, y + d, c))
                    };
                    (1..=limit as i64).find(|&r| ring(r)).unwrap_or(limit as i64 + 1) as u8
                }
            };
        }
    });
    Ok(out)
}

/// Connected components of triangles that share a vertex id: component per triangle, numbered
/// 0.. in order of each component's first triangle. With vertex ids that identify a point of a
/// page (same page and same UV), the components of a lightmap-UV mesh are its charts: xatlas
/// never gives two charts a vertex at the same UV, and padding keeps charts apart.
pub fn triangle_components(triangles: &[u32], vertex_count: usize) -> Result<Vec<u32>, String> {
    if triangles.len() % 3 != 0 {
        return Err(format!("triangles has {} indices, not a multiple of 3", triangles.len()));
    }
    if let Some(&v) = triangles.iter().find(|&&v| v as usize >= vertex_count) {
        return Err(format!("a triangle uses vertex {v}, but there are {vertex_count} vertices"));
    }
    let mut parent: Vec<u32> = (0..vertex_count as u32).collect();
    fn find(parent: &mut [u32], mut v: u32) -> u32 {
        while parent[v as usize] != v {
            let up = parent[parent[v as usize] as usize];
            parent[v as usize] = up;
            v = up;
        }
        v
    }
    for t in triangles.chunks_exact(3) {
        for &v in &t[1..] {
            let (a, b) = (find(&mut parent, t[0]), find(&mut parent, v));
            // Union towards the smaller root.
            if a < b {
                parent[b as usize] = a;
            } else if b < a {
                parent[a as usize] = b;
            }
        }
    }
    let mut label = vec![NONE; vertex_count];
    let mut next = 0u32;
    let mut out = Vec::with_capacity(triangles.len() / 3);
    for t in triangles.chunks_exact(3) {
        let r = find(&mut parent, t[0]) as usize;
        if label[r] == NONE {
            label[r] = next;
            next += 1;
        }
        out.push(label[r]);
    }
    Ok(out)
}

/// Write an RGBA8 image (`4 * width * height` bytes, rows top to bottom) as PNG at `path`,
/// atomically: encoded to a temporary file beside it, then renamed into place, so `path` is
/// either the old file or the complete new one.
pub fn write_png_atomic(path: &Path, width: u32, height: u32, rgba: &[u8]) -> Result<(), String> {
    let file = path.display().to_string();
    if rgba.len() as u64 != 4 * width as u64 * height as u64 {
        return Err(format!("{file}: {} bytes of RGBA for a {width}x{height} image", rgba.len()));
    }
    if width == 0 || height == 0 {
        return Err(format!("{file}: empty image {width}x{height}"));
    }
    let name = path.file_name().ok_or_else(|| format!("{file}: not a file path"))?;
    let tmp = path.with_file_name(format!(".{}.tmp{}", name.to_string_lossy(), std::process::id()));
    let result = (|| -> Result<(), String> {
        let f = std::fs::File::create(&tmp).map_err(|e| e.to_string())?;
        let mut writer = std::io::BufWriter::new(f);
        image::ImageEncoder::write_image(
            image::codecs::png::PngEncoder::new(&mut writer),
            rgba,
            width,
            height,
            image::ExtendedColorType::Rgba8,
        )
        .map_err(|e| e.to_string())?;
        let f = writer.into_inner().map_err(|e| e.to_string())?;
        f.sync_all().map_err(|e| e.to_string())?;
        std::fs::rename(&tmp, path).map_err(|e| e.to_string())
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(format!("{file}: cannot write PNG: {}", e.split_whitespace().collect::<Vec<_>>().join(" ")));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn raster(uv_texels: &[[f64; 2]], tris: &[u32], charts: &[u32], w: usize, h: usize, c: Coverage) -> Raster {
        let uv: Vec<f32> = uv_texels.iter().flat_map(|p| [(p[0] / w as f64) as f32, (p[1] / h as f64) as f32]).collect();
        rasterize(UvTriangles { uv: &uv, triangles: tris, charts }, w, h, c).unwrap()
    }

    fn mask(r: &Raster) -> Vec<String> {
        (0..r.height)
            .map(|y| (0..r.width).map(|x| if r.charts_here[y * r.width + x] > 0 { '#' } else { '.' }).collect())
            .collect()
    }

    /// Right triangle (0,0) (8,0) (0,8) on a 10x10 page: texel centres (x+.5, y+.5) with
    /// x + y + 1 <= 8, i.e. x + y <= 7: 8+7+...+1 = 36 texels, the hypotenuse centres on the edge
    /// (x + y = 7) included by the fill rule for this edge direction or not: count by hand below.
    #[test]
    fn centre_coverage_of_a_known_triangle() {
        let r = raster(&[[0.0, 0.0], [8.0, 0.0], [0.0, 8.0]], &[0, 1, 2], &[0], 10, 10, Coverage::Centre);
        // Centres strictly inside: x + y + 1 < 8 -> x + y <= 6: 7+6+..+1 = 28. Centres exactly on
        // the hypotenuse (x + y = 7): 8 of them, owned by this triangle only if its edge is "owned".
        let on_edge = 8;
        let inside = 28;
        let n = r.covered();
        assert!(n == inside || n == inside + on_edge, "{n}\n{}", mask(&r).join("\n"));
        // Its mirror image across the hypotenuse takes exactly the other ones: together they
        // tile the 8x8 square once.
        let r2 = raster(
            &[[0.0, 0.0], [8.0, 0.0], [0.0, 8.0], [8.0, 8.0]],
            &[0, 1, 2, 2, 1, 3],
            &[0, 0],
            10,
            10,
            Coverage::Centre,
        );
        assert_eq!(r2.covered(), 64, "\n{}", mask(&r2).join("\n"));
        let per_tri0 = r2.triangle.iter().filter(|&&t| t == 0).count();
        let per_tri1 = r2.triangle.iter().filter(|&&t| t == 1).count();
        assert_eq!(per_tri0 + per_tri1, 64);
        assert_eq!(per_tri0, n);
        // A triangle off in a corner with a hand-counted footprint: (1.2,1.2) (5.8,1.2) (1.2,3.9)
        // centres (x+.5,y+.5): rows y=1 (1.5): x+.5 <= 5.8-(1.5-1.2)*4.6/2.7=5.289 -> x=1..4 (4)
        // y=2 (2.5): x+.5 <= 5.8-1.3*4.6/2.7=3.585 -> x=1..3 (3); y=3 (3.5): <= 1.881 -> x=1 (1).
        let r3 = raster(&[[1.2, 1.2], [5.8, 1.2], [1.2, 3.9]], &[0, 1, 2], &[7], 10, 10, Coverage::Centre);
        assert_eq!(r3.covered(), 8, "\n{}", mask(&r3).join("\n"));
        assert!(r3.chart.iter().all(|&c| c == NONE || c == 7));
    }

    #[test]
    fn conservative_coverage_includes_edge_texels() {
        // The same small triangle: every texel its area touches, including those whose centre
        // is outside: rows 1..=3, and in each row the x span of the triangle within the row strip.
        let r = raster(&[[1.2, 1.2], [5.8, 1.2], [1.2, 3.9]], &[0, 1, 2], &[0], 10, 10, Coverage::Conservative);
        // Row y=1 (v in [1.2,2]): x from 1.2 to 5.8 -> texels 1..=5 (5)
        // Row y=2 (v in [2,3]): x up to 5.8-0.8*4.6/2.7=4.437 -> 1..=4 (4)
        // Row y=3 (v in [3,3.9]): x up to 5.8-1.8*4.6/2.7=2.733 -> 1..=2 (2)
        assert_eq!(r.covered(), 11, "\n{}", mask(&r).join("\n"));
        let centre = raster(&[[1.2, 1.2], [5.8, 1.2], [1.2, 3.9]], &[0, 1, 2], &[0], 10, 10, Coverage::Centre);
        for t in 0..100 {
            if centre.charts_here[t] > 0 {
                assert!(r.charts_here[t] > 0, "texel {t} covered by centre but not conservative");
            }
        }
        // An edge texel's sample point is on the triangle (barycentrics >= 0, sum 1).
        let t = 3 * 10 + 2; // (2, 3): centre (2.5, 3.5) is outside
        assert_eq!(r.triangle[t], 0);
        let b = &r.bary[3 * t..3 * t + 3];
        assert!(b.iter().all(|&v| v >= -1e-6) && (b.iter().sum::<f32>() - 1.0).abs() < 1e-5, "{b:?}");
        // Axis-aligned square exactly on texel lines [2,6]x[3,5]: touching neighbours are not claimed.
        let sq = raster(&[[2.0, 3.0], [6.0, 3.0], [2.0, 5.0], [6.0, 5.0]], &[0, 1, 2, 2, 1, 3], &[0, 0], 10, 10, Coverage::Conservative);
        assert_eq!(sq.covered(), 8, "\n{}", mask(&sq).join("\n"));
        // A sliver thinner than a texel, between centres: no centre, but conservative texels.
        let sl = raster(&[[1.0, 2.1], [9.0, 2.1], [1.0, 2.3]], &[0, 1, 2], &[0], 10, 10, Coverage::Centre);
        assert_eq!(sl.covered(), 0);
        let sl = raster(&[[1.0, 2.1], [9.0, 2.1], [1.0, 2.3]], &[0, 1, 2], &[0], 10, 10, Coverage::Conservative);
        assert_eq!(sl.covered(), 8, "\n{}", mask(&sl).join("\n"));
    }

    #[test]
    fn interpolated_position_is_the_barycentric_position() {
        let uv = [[1.0, 1.0], [9.0, 2.0], [3.0, 8.0]];
        let pos: [f32; 9] = [0.0, 0.0, 0.0, 4.0, 0.5, 0.0, 1.0, 3.0, 2.0];
        let r = raster(&uv, &[0, 1, 2], &[0], 10, 10, Coverage::Conservative);
        let (p, n) = surface(&r, &[0, 1, 2], &pos, None).unwrap();
        let e1 = [4.0, 0.5, 0.0];
        let e2 = [1.0, 3.0, 2.0];
        let mut gn = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
        normalize(&mut gn).unwrap();
        let mut inside = 0;
        for y in 0..10 {
            for x in 0..10 {
                let t = y * 10 + x;
                if r.triangle[t] == NONE {
                    assert_eq!(&p[3 * t..3 * t + 3], &[0.0; 3]);
                    continue;
                }
                // Barycentrics of the centre, solved directly in UV space.
                let q = [x as f64 + 0.5, y as f64 + 0.5];
                let (a, b, c_) = (uv[0], uv[1], uv[2]);
                let det = (b[0] - a[0]) * (c_[1] - a[1]) - (c_[0] - a[0]) * (b[1] - a[1]);
                let l1 = ((q[0] - a[0]) * (c_[1] - a[1]) - (c_[0] - a[0]) * (q[1] - a[1])) / det;
                let l2 = ((b[0] - a[0]) * (q[1] - a[1]) - (q[0] - a[0]) * (b[1] - a[1])) / det;
                let l0 = 1.0 - l1 - l2;
                let sample: [f64; 3] = [r.bary[3 * t] as f64, r.bary[3 * t + 1] as f64, r.bary[3 * t + 2] as f64];
                // Distance from each edge, in texels: barycentric times the height over that edge.
                let heights = [0, 1, 2].map(|k| {
                    let (a, b) = (uv[(k + 1) % 3], uv[(k + 2) % 3]);
                    det.abs() / ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt()
                });
                let clear = [l0, l1, l2].iter().zip(heights).all(|(l, h)| l * h >= SAMPLE_INSET);
                if clear {
                    // A centre clear of every edge is its own sample point.
                    inside += 1;
                    for (s, l) in sample.iter().zip([l0, l1, l2]) {
                        assert!((s - l).abs() < 1e-5, "texel ({x},{y}): {sample:?} vs {:?}", [l0, l1, l2]);
                    }
                }
                // Every sample point keeps SAMPLE_INSET inside the edges, and stays in its texel's
                // neighbourhood (the nearest point, moved in by at most that).
                for (l, h) in sample.iter().zip(heights) {
                    assert!(l * h >= SAMPLE_INSET - 1e-5, "texel ({x},{y}): {sample:?} is {} texels from an edge", l * h);
                }
                let at = [0, 1].map(|c| sample[0] * a[c] + sample[1] * b[c] + sample[2] * c_[c]);
                assert!((at[0] - q[0]).abs() < 0.5 + 2.0 * SAMPLE_INSET && (at[1] - q[1]).abs() < 0.5 + 2.0 * SAMPLE_INSET, "texel ({x},{y}) sampled at {at:?}");
                for k in 0..3 {
                    let want = sample[0] * pos[k] as f64 + sample[1] * pos[3 + k] as f64 + sample[2] * pos[6 + k] as f64;
                    assert!((p[3 * t + k] as f64 - want).abs() < 1e-5);
                    assert!((n[3 * t + k] as f64 - gn[k]).abs() < 1e-6);
                }
            }
        }
        assert!(inside > 10);
        // Per-vertex normals are interpolated and normalised.
        let nrm: [f32; 9] = [0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0];
        let (_, n2) = surface(&r, &[0, 1, 2], &pos, Some(&nrm)).unwrap();
        let t = 4 * 10 + 4;
        let b = &r.bary[3 * t..3 * t + 3];
        let len = ((b[1] + b[2]) * (b[1] + b[2]) + b[0] * b[0]).sqrt();
        assert!((n2[3 * t + 1] - (b[1] + b[2]) / len).abs() < 1e-5 && (n2[3 * t + 2] - b[0] / len).abs() < 1e-5);
    }

    #[test]
    fn overlaps_and_separation_between_charts() {
        // Two squares 3 texels apart (2 empty texels between), and a third overlapping the first.
        let uv = [
            [1.0, 1.0], [4.0, 1.0], [1.0, 4.0], [4.0, 4.0], // chart 0: texels 1..=3
            [7.0, 1.0], [10.0, 1.0], [7.0, 4.0], [10.0, 4.0], // chart 1: texels 7..=9, gap 4..=6
        ];
        let tris = [0, 1, 2, 2, 1, 3, 4, 5, 6, 6, 5, 7];
        let r = raster(&uv, &tris, &[0, 0, 1, 1], 12, 6, Coverage::Conservative);
        assert_eq!(r.overlapping(), 0);
        let sep = chart_separation(&r, 8).unwrap();
        let min = sep.iter().filter(|&&s| s != NOT_COVERED).min().copied().unwrap();
        assert_eq!(min, 4); // texel 3 to texel 7
        let sep = chart_separation(&r, 2).unwrap();
        assert!(sep.iter().all(|&s| s == NOT_COVERED || s == 3));
        // Same chart id for both: no separation constraint inside a chart.
        let r_same = raster(&uv, &tris, &[0, 0, 0, 0], 12, 6, Coverage::Conservative);
        assert!(chart_separation(&r_same, 8).unwrap().iter().all(|&s| s == NOT_COVERED || s == 9));
        // Overlap: chart 2 covering texels 3..=5 overlaps chart 0 on texel column 3.
        let mut uv2 = uv.to_vec();
        uv2.extend([[3.2, 1.0], [6.0, 1.0], [3.2, 4.0], [6.0, 4.0]]);
        let mut tris2 = tris.to_vec();
        tris2.extend([8, 9, 10, 10, 9, 11]);
        let r = raster(&uv2, &tris2, &[0, 0, 1, 1, 2, 2], 12, 6, Coverage::Centre);
        assert_eq!(r.overlapping(), 3); // column 3, rows 1..=3
        let sep = chart_separation(&r, 4).unwrap();
        assert_eq!(sep.iter().filter(|&&s| s == 0).count(), 3);
    }

    #[test]
    fn deterministic_and_independent_of_threads() {
        // Many random small triangles in a few charts.
        let mut seed = 12345u64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed % 1_000_000) as f64 / 1_000_000.0
        };
        let mut uv = Vec::new();
        let mut tris = Vec::new();
        let mut charts = Vec::new();
        for i in 0..2000u32 {
            let (cx, cy) = (rnd() * 200.0, rnd() * 150.0);
            for _ in 0..3 {
                uv.push([cx + rnd() * 6.0, cy + rnd() * 6.0]);
            }
            tris.extend([3 * i, 3 * i + 1, 3 * i + 2]);
            charts.push(i % 7);
        }
        let a = raster(&uv, &tris, &charts, 200, 150, Coverage::Conservative);
        let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let b = pool.install(|| raster(&uv, &tris, &charts, 200, 150, Coverage::Conservative));
        assert_eq!(a, b);
    }

    #[test]
    fn components_of_triangles() {
        // Two quads sharing nothing, and a triangle joining the second quad through vertex 7.
        let tris = [0, 1, 2, 2, 1, 3, 4, 5, 6, 6, 5, 7, 8, 9, 7];
        assert_eq!(triangle_components(&tris, 10).unwrap(), vec![0, 0, 1, 1, 1]);
        assert_eq!(triangle_components(&[5, 6, 7, 0, 1, 2, 7, 8, 9, 2, 3, 4], 10).unwrap(), vec![0, 1, 0, 1]);
        assert!(triangle_components(&[0, 1, 2], 2).is_err());
    }

    #[test]
    fn bad_input_is_an_error() {
        let uv = [0.0f32; 6];
        assert!(rasterize(UvTriangles { uv: &uv, triangles: &[0, 1, 3], charts: &[0] }, 4, 4, Coverage::Centre).is_err());
        assert!(rasterize(UvTriangles { uv: &uv, triangles: &[0, 1, 2], charts: &[] }, 4, 4, Coverage::Centre).is_err());
        assert!(rasterize(UvTriangles { uv: &uv, triangles: &[0, 1, 2], charts: &[0] }, 0, 4, Coverage::Centre).is_err());
    }

    #[test]
    fn png_is_written_atomically() {
        let dir = std::env::temp_dir().join(format!("uv-raster-png-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.png");
        let rgba: Vec<u8> = (0..4 * 3 * 2).map(|i| i as u8).collect();
        write_png_atomic(&path, 3, 2, &rgba).unwrap();
        let img = image::open(&path).unwrap().to_rgba8();
        assert_eq!(img.dimensions(), (3, 2));
        assert_eq!(img.into_raw(), rgba);
        assert!(write_png_atomic(&path, 3, 3, &rgba).is_err());
        assert!(write_png_atomic(&dir.join("missing/b.png"), 3, 2, &rgba).is_err());
        let names: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 1, "{names:?}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
