//! Clean-up of a baked lightmap page: gutter dilation and UV2 seam stitching.
//!
//! Conventions are `uv_raster`'s: a page is `width x height` texels, row-major, texel `(x, y)` the
//! square `[x, x+1] x [y, y+1]` in texel units with its centre at `(x+0.5, y+0.5)`; a UV in
//! `[0, 1]` is at `(u * width, v * height)` texel units. Images are flat `height * width * 3` f32
//! (numpy's (h, w, 3)); the chart map is `height * width` u32 with [`NONE`] for empty texels.
//! Bilinear lookups are the runtime sampler's: centres at half texels, CLAMP_TO_EDGE.
//!
//! **Dilation** ([`dilate`]) grows every chart outward ring by ring (8-neighbourhood, so `rings`
//! rings fill every empty texel within Chebyshev distance `rings` of a chart and nothing else).
//! An empty texel takes one chart only: the nearest (distance accumulated along the growth, 1 per
//! side step, sqrt 2 per diagonal step), ties broken by the lower chart id, and the plain average
//! of that chart's already-filled neighbours. No gutter texel ever mixes two charts, and the
//! result does not depend on the thread count.
//!
//! **Seams** ([`find_seams`], [`stitch_seams`]): a seam is a 3D edge shared by two triangles whose
//! UV2 differ along it (two charts, or two sides of one chart). Both sides are sampled bilinearly
//! at matching points along the edge and the texels under those footprints are adjusted by a
//! least-squares solve (after Iwanicki, "Lighting Technology of The Last of Us", and
//! ands/seamoptimizer): minimise `sum (A(p) - B(p))^2 + lambda^2 sum (x - x0)^2` over the
//! footprint texels, by conjugate gradients per channel and per group of linked texels. Stitch after dilation: the footprints
//! at a chart's edge reach into its 1-texel ring.

use crate::uv_raster::NONE;
use rayon::prelude::*;
use std::collections::HashMap;

fn check_image(len: usize, channels: usize, width: usize, height: usize) -> Result<(), String> {
    if width == 0 || height == 0 || channels == 0 {
        return Err(format!("empty page ({width} x {height} x {channels})"));
    }
    if len != width * height * channels {
        return Err(format!("image has {len} floats, expected {} for {width} x {height} x {channels}", width * height * channels));
    }
    Ok(())
}

fn check_page(rgb_len: usize, chart_len: Option<usize>, width: usize, height: usize) -> Result<(), String> {
    if width == 0 || height == 0 {
        return Err(format!("empty page ({width} x {height})"));
    }
    if rgb_len != width * height * 3 {
        return Err(format!("image has {rgb_len} floats, expected {} for {width} x {height} x 3", width * height * 3));
    }
    if let Some(n) = chart_len {
        if n != width * height {
            return Err(format!("chart map has {n} texels, expected {} for {width} x {height}", width * height));
        }
    }
    Ok(())
}

// ---- dilation ------------------------------------------------------------------------------------

const NEIGHBOURS: [(isize, isize, f32); 8] = [
    (-1, 0, 1.0),
    (1, 0, 1.0),
    (0, -1, 1.0),
    (0, 1, 1.0),
    (-1, -1, std::f32::consts::SQRT_2),
    (1, -1, std::f32::consts::SQRT_2),
    (-1, 1, std::f32::consts::SQRT_2),
    (1, 1, std::f32::consts::SQRT_2),
];

/// What [`dilate`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct Dilation {
    /// Gutter texels filled, per ring (ring 1 first).
    pub filled_per_ring: Vec<usize>,
}

/// Fill up to `rings` rings of empty texels around every chart, in place: `rgb` gets the values,
/// `chart` the chart each filled texel was filled from (so it no longer reads [`NONE`] there).
/// Covered texels (chart != NONE) are never changed.
pub fn dilate(rgb: &mut [f32], chart: &mut [u32], width: usize, height: usize, rings: usize) -> Result<Dilation, String> {
    check_page(rgb.len(), Some(chart.len()), width, height)?;
    let mut dist: Vec<f32> = chart.iter().map(|&c| if c == NONE { f32::INFINITY } else { 0.0 }).collect();
    let mut filled_per_ring = Vec::new();
    for _ in 0..rings {
        // Every update of this ring reads only the state before it.
        let updates: Vec<(usize, u32, f32, [f32; 3])> = (0..height)
            .into_par_iter()
            .flat_map_iter(|y| {
                let (rgb, chart, dist) = (&*rgb, &*chart, &dist);
                (0..width).filter_map(move |x| {
                    let i = y * width + x;
                    if chart[i] != NONE {
                        return None;
                    }
                    // Nearest chart among the filled neighbours, ties to the lower id.
                    let mut best: Option<(f32, u32)> = None;
                    for &(dx, dy, step) in &NEIGHBOURS {
                        let (nx, ny) = (x as isize + dx, y as isize + dy);
                        if nx < 0 || ny < 0 || nx >= width as isize || ny >= height as isize {
                            continue;
                        }
                        let j = ny as usize * width + nx as usize;
                        let c = chart[j];
                        if c == NONE {
                            continue;
                        }
                        let d = dist[j] + step;
                        let better = match best {
                            None => true,
                            Some((bd, bc)) => d < bd - 1e-4 || (d <= bd + 1e-4 && c < bc),
                        };
                        if better {
                            best = Some((d, c));
                        }
                    }
                    let (d, c) = best?;
                    let mut sum = [0f32; 3];
                    let mut n = 0f32;
                    for &(dx, dy, _) in &NEIGHBOURS {
                        let (nx, ny) = (x as isize + dx, y as isize + dy);
                        if nx < 0 || ny < 0 || nx >= width as isize || ny >= height as isize {
                            continue;
                        }
                        let j = ny as usize * width + nx as usize;
                        if chart[j] == c {
                            for k in 0..3 {
                                sum[k] += rgb[j * 3 + k];
                            }
                            n += 1.0;
                        }
                    }
                    Some((i, c, d, [sum[0] / n, sum[1] / n, sum[2] / n]))
                })
            })
            .collect();
        if updates.is_empty() {
            break;
        }
        filled_per_ring.push(updates.len());
        for (i, c, d, v) in updates {
            chart[i] = c;
            dist[i] = d;
            rgb[i * 3..i * 3 + 3].copy_from_slice(&v);
        }
    }
    Ok(Dilation { filled_per_ring })
}

// ---- bilinear sampling ---------------------------------------------------------------------------

/// The four texels (flat index) and weights a bilinear lookup at texel-unit point `p` reads
/// (CLAMP_TO_EDGE).
pub fn bilinear_footprint(p: [f64; 2], width: usize, height: usize) -> [(usize, f64); 4] {
    let fx = p[0] - 0.5;
    let fy = p[1] - 0.5;
    let x0 = fx.floor();
    let y0 = fy.floor();
    let (tx, ty) = (fx - x0, fy - y0);
    let clamp = |v: f64, n: usize| (v.max(0.0) as usize).min(n - 1);
    let (xa, xb) = (clamp(x0, width), clamp(x0 + 1.0, width));
    let (ya, yb) = (clamp(y0, height), clamp(y0 + 1.0, height));
    [
        (ya * width + xa, (1.0 - tx) * (1.0 - ty)),
        (ya * width + xb, tx * (1.0 - ty)),
        (yb * width + xa, (1.0 - tx) * ty),
        (yb * width + xb, tx * ty),
    ]
}

/// Bilinear lookup of `rgb` at texel-unit point `p`.
pub fn bilinear(rgb: &[f32], width: usize, height: usize, p: [f64; 2]) -> [f64; 3] {
    let mut out = [0f64; 3];
    for (i, w) in bilinear_footprint(p, width, height) {
        for k in 0..3 {
            out[k] += w * rgb[i * 3 + k] as f64;
        }
    }
    out
}

// ---- seams ---------------------------------------------------------------------------------------

/// The triangles of every mesh on one page, as numpy hands them over.
#[derive(Clone, Copy, Debug)]
pub struct SeamMesh<'a> {
    /// `2 * n` floats: UV2 per vertex in [0, 1] of the page.
    pub uv: &'a [f32],
    /// `3 * m` vertex indices.
    pub triangles: &'a [u32],
    /// `3 * n` floats; vertices closer than the weld tolerance are the same 3D point.
    pub positions: &'a [f32],
    /// Optional `3 * n` shading normals; else each triangle's geometric normal is used.
    pub normals: Option<&'a [f32]>,
    /// Optional `m` mesh ids: edges are only matched within one mesh (positions in object space
    /// of different meshes may coincide without touching in the world).
    pub mesh: Option<&'a [u32]>,
}

/// One seam edge: its two endpoints in texel units on side A and on side B (endpoint k of A is
/// the same 3D point as endpoint k of B).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Seam {
    pub a: [[f64; 2]; 2],
    pub b: [[f64; 2]; 2],
}

/// Seam finding options.
#[derive(Clone, Copy, Debug)]
pub struct SeamOptions {
    /// Positions within this distance (per axis, same units as the positions) are welded.
    pub weld_eps: f32,
    /// Two sides are stitched only if their normals at both endpoints (shading normals if given,
    /// else the triangles' geometric normals) have a cosine at least this: hard edges (a wall
    /// meeting the floor) legitimately differ in light and are left alone.
    pub min_normal_cos: f32,
    /// UVs closer than this (in texels) on both endpoints are the same UV: not a seam.
    pub uv_eps_texels: f64,
}

impl Default for SeamOptions {
    fn default() -> Self {
        SeamOptions { weld_eps: 1e-5, min_normal_cos: 0.9, uv_eps_texels: 1e-3 }
    }
}

fn v3(a: &[f32], i: usize) -> [f64; 3] {
    [a[i * 3] as f64, a[i * 3 + 1] as f64, a[i * 3 + 2] as f64]
}

fn normalise(v: [f64; 3]) -> [f64; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if l > 0.0 {
        [v[0] / l, v[1] / l, v[2] / l]
    } else {
        [0.0; 3]
    }
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Every UV2 seam of a page's triangles, in a deterministic order (by the first triangle's index,
/// then its edge). Edges shared by more than two triangles (non-manifold) are skipped.
pub fn find_seams(m: &SeamMesh, width: usize, height: usize, opt: &SeamOptions) -> Result<Vec<Seam>, String> {
    let n = m.uv.len() / 2;
    if m.uv.len() % 2 != 0 || m.triangles.len() % 3 != 0 {
        return Err("uv must be (n, 2) and triangles (m, 3)".into());
    }
    if m.positions.len() != n * 3 {
        return Err(format!("{} positions for {n} uv vertices", m.positions.len() / 3));
    }
    if let Some(nr) = m.normals {
        if nr.len() != n * 3 {
            return Err(format!("{} normals for {n} uv vertices", nr.len() / 3));
        }
    }
    let tri_count = m.triangles.len() / 3;
    if let Some(me) = m.mesh {
        if me.len() != tri_count {
            return Err(format!("{} mesh ids for {tri_count} triangles", me.len()));
        }
    }
    if let Some(&bad) = m.triangles.iter().find(|&&v| v as usize >= n) {
        return Err(format!("triangle vertex {bad} out of range ({n} vertices)"));
    }
    if !(opt.weld_eps > 0.0) {
        return Err("weld_eps must be > 0".into());
    }
    // Weld by quantised position (per mesh).
    let mut weld_ids: HashMap<(u32, [i64; 3]), u32> = HashMap::new();
    let mut weld = vec![0u32; n];
    let mut vmesh = vec![0u32; n];
    if let Some(me) = m.mesh {
        for t in 0..tri_count {
            for k in 0..3 {
                vmesh[m.triangles[t * 3 + k] as usize] = me[t];
            }
        }
    }
    for v in 0..n {
        let p = v3(m.positions, v);
        let q = [0, 1, 2].map(|k| (p[k] / opt.weld_eps as f64).round() as i64);
        let next = weld_ids.len() as u32;
        weld[v] = *weld_ids.entry((vmesh[v], q)).or_insert(next);
    }
    let face_normal = |t: usize| {
        let [a, b, c] = [0, 1, 2].map(|k| v3(m.positions, m.triangles[t * 3 + k] as usize));
        let (e1, e2) = ([b[0] - a[0], b[1] - a[1], b[2] - a[2]], [c[0] - a[0], c[1] - a[1], c[2] - a[2]]);
        normalise([e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]])
    };
    let normal_at = |t: usize, v: usize| match m.normals {
        Some(nr) => normalise(v3(nr, v)),
        None => face_normal(t),
    };
    // Shared 3D edges: (mesh, welded a < welded b) -> (triangle, vertex at a, vertex at b).
    let mut edges: HashMap<(u32, u32, u32), Vec<(usize, usize, usize)>> = HashMap::new();
    for t in 0..tri_count {
        for k in 0..3 {
            let (va, vb) = (m.triangles[t * 3 + k] as usize, m.triangles[t * 3 + (k + 1) % 3] as usize);
            let (wa, wb) = (weld[va], weld[vb]);
            if wa == wb {
                continue;
            }
            let key = if wa < wb { (vmesh[va], wa, wb) } else { (vmesh[va], wb, wa) };
            let (lo, hi) = if wa < wb { (va, vb) } else { (vb, va) };
            edges.entry(key).or_default().push((t, lo, hi));
        }
    }
    let texel = |v: usize| [m.uv[v * 2] as f64 * width as f64, m.uv[v * 2 + 1] as f64 * height as f64];
    let close = |p: [f64; 2], q: [f64; 2]| (p[0] - q[0]).abs() <= opt.uv_eps_texels && (p[1] - q[1]).abs() <= opt.uv_eps_texels;
    let mut found: Vec<(usize, usize, Seam)> = Vec::new();
    for list in edges.values() {
        if list.len() != 2 {
            continue;
        }
        let ((ta, a0, a1), (tb, b0, b1)) = (list[0], list[1]);
        if ta == tb {
            continue;
        }
        let s = Seam { a: [texel(a0), texel(a1)], b: [texel(b0), texel(b1)] };
        if close(s.a[0], s.b[0]) && close(s.a[1], s.b[1]) {
            continue; // the same UVs on both sides: no seam
        }
        let smooth = [(a0, b0), (a1, b1)].iter().all(|&(va, vb)| dot(normal_at(ta, va), normal_at(tb, vb)) >= opt.min_normal_cos as f64);
        if !smooth {
            continue;
        }
        let (first, s) = if ta < tb { (ta, s) } else { (tb, Seam { a: s.b, b: s.a }) };
        found.push((first, ta.max(tb), s));
    }
    found.sort_by(|x, y| (x.0, x.1).cmp(&(y.0, y.1)).then(x.2.a[0][0].total_cmp(&y.2.a[0][0])).then(x.2.a[0][1].total_cmp(&y.2.a[0][1])));
    Ok(found.into_iter().map(|f| f.2).collect())
}

fn lerp(p: [[f64; 2]; 2], t: f64) -> [f64; 2] {
    [p[0][0] + (p[1][0] - p[0][0]) * t, p[0][1] + (p[1][1] - p[0][1]) * t]
}

fn length(p: [[f64; 2]; 2]) -> f64 {
    ((p[1][0] - p[0][0]).powi(2) + (p[1][1] - p[0][1]).powi(2)).sqrt()
}

/// The matching sample points `(side A, side B)` along a seam: `samples_per_texel` per texel of
/// the longer side, endpoints included (at least 2).
pub fn seam_points(s: &Seam, samples_per_texel: f64) -> Vec<([f64; 2], [f64; 2])> {
    let len = length(s.a).max(length(s.b));
    let count = ((len * samples_per_texel).ceil() as usize + 1).clamp(2, 1 << 16);
    (0..count)
        .map(|k| {
            let t = k as f64 / (count - 1) as f64;
            (lerp(s.a, t), lerp(s.b, t))
        })
        .collect()
}

/// Largest and mean absolute difference (over samples and channels) between the two sides'
/// bilinear lookups along the seams, for an RGB page.
pub fn seam_mismatch(rgb: &[f32], width: usize, height: usize, seams: &[Seam], samples_per_texel: f64) -> Result<(f64, f64), String> {
    seam_mismatch_channels(rgb, 3, width, height, seams, samples_per_texel)
}

/// [`seam_mismatch`] for a page of `channels` floats a texel.
pub fn seam_mismatch_channels(img: &[f32], channels: usize, width: usize, height: usize, seams: &[Seam], samples_per_texel: f64) -> Result<(f64, f64), String> {
    check_image(img.len(), channels, width, height)?;
    let (mut max, mut sum, mut n) = (0f64, 0f64, 0usize);
    for s in seams {
        for (pa, pb) in seam_points(s, samples_per_texel) {
            let (fa, fb) = (bilinear_footprint(pa, width, height), bilinear_footprint(pb, width, height));
            for k in 0..channels {
                let at = |fp: &[(usize, f64); 4]| fp.iter().map(|&(i, w)| w * img[i * channels + k] as f64).sum::<f64>();
                let d = (at(&fa) - at(&fb)).abs();
                max = max.max(d);
                sum += d;
                n += 1;
            }
        }
    }
    Ok((max, if n > 0 { sum / n as f64 } else { 0.0 }))
}

/// Stitching options.
#[derive(Clone, Copy, Debug)]
pub struct StitchOptions {
    /// Sample points per texel of seam length.
    pub samples_per_texel: f64,
    /// Weight of "stay close to the baked value" against "both sides agree". seamoptimizer uses
    /// 0.1, which leaves ~2% of a seam's step; 0.03 leaves ~0.2% and still moves only the
    /// footprint texels.
    pub lambda: f64,
    /// Conjugate-gradient iterations at most (per channel).
    pub max_iterations: usize,
}

impl Default for StitchOptions {
    fn default() -> Self {
        StitchOptions { samples_per_texel: 2.0, lambda: 0.03, max_iterations: 1000 }
    }
}

/// What [`stitch_seams`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct Stitch {
    pub seams: usize,
    pub constraints: usize,
    /// Groups of texels no constraint links, each solved on its own.
    pub groups: usize,
    pub texels_changed: usize,
    pub mismatch_before: (f64, f64),
    pub mismatch_after: (f64, f64),
    pub iterations: usize,
}

/// Make both sides of every seam interpolate to (nearly) the same value, in place, on an RGB
/// page. Only texels under the seams' bilinear footprints change; results are clamped to >= 0.
pub fn stitch_seams(rgb: &mut [f32], width: usize, height: usize, seams: &[Seam], opt: &StitchOptions) -> Result<Stitch, String> {
    stitch_seams_channels(rgb, 3, width, height, seams, opt)
}

/// [`stitch_seams`] for a page of `channels` floats a texel: the system is built once and
/// solved for every channel (a directional page's images stitched in one call).
///
/// The texels under the footprints fall into groups no constraint links (a seam of a small
/// chart touches only its own few dozen texels): each group is solved on its own, in parallel,
/// and converges in the iterations it needs rather than the slowest group's (on a level's page:
/// thousands of groups, most of a few texels; one solve for the whole page took ~800 conjugate
/// gradient iterations over all of its 40k texels). Each group's solve is sequential, so the
/// result does not depend on the thread count.
pub fn stitch_seams_channels(img: &mut [f32], channels: usize, width: usize, height: usize, seams: &[Seam], opt: &StitchOptions) -> Result<Stitch, String> {
    check_image(img.len(), channels, width, height)?;
    if !(opt.samples_per_texel > 0.0 && opt.lambda > 0.0) {
        return Err("samples_per_texel and lambda must be > 0".into());
    }
    let before = seam_mismatch_channels(img, channels, width, height, seams, opt.samples_per_texel)?;
    // Constraint rows over compact unknowns (texels in some footprint, numbered in first-seen order).
    let mut var_of: HashMap<usize, usize> = HashMap::new();
    let mut texels: Vec<usize> = Vec::new();
    let mut rows: Vec<Vec<(usize, f64)>> = Vec::new();
    for s in seams {
        for (pa, pb) in seam_points(s, opt.samples_per_texel) {
            let mut row: Vec<(usize, f64)> = Vec::with_capacity(8);
            for (fp, sign) in [(bilinear_footprint(pa, width, height), 1.0), (bilinear_footprint(pb, width, height), -1.0)] {
                for (t, w) in fp {
                    if w == 0.0 {
                        continue;
                    }
                    let v = *var_of.entry(t).or_insert_with(|| {
                        texels.push(t);
                        texels.len() - 1
                    });
                    match row.iter_mut().find(|e| e.0 == v) {
                        Some(e) => e.1 += sign * w,
                        None => row.push((v, sign * w)),
                    }
                }
            }
            row.retain(|e| e.1.abs() > 1e-12);
            if !row.is_empty() {
                rows.push(row);
            }
        }
    }
    let nv = texels.len();
    // Groups: unknowns linked by some row (union-find), each group's rows and unknowns in
    // first-seen order, renumbered locally.
    let mut parent: Vec<usize> = (0..nv).collect();
    fn root(parent: &mut [usize], mut v: usize) -> usize {
        while parent[v] != v {
            parent[v] = parent[parent[v]];
            v = parent[v];
        }
        v
    }
    for row in &rows {
        for &(v, _) in &row[1..] {
            let (a, b) = (root(&mut parent, row[0].0), root(&mut parent, v));
            if a != b {
                parent[a.max(b)] = a.min(b);
            }
        }
    }
    let mut group_of = vec![usize::MAX; nv];
    let mut groups: Vec<(Vec<usize>, Vec<Vec<(usize, f64)>>)> = Vec::new(); // (unknowns, rows)
    let mut local = vec![0usize; nv];
    for v in 0..nv {
        let r = root(&mut parent, v);
        if group_of[r] == usize::MAX {
            group_of[r] = groups.len();
            groups.push((Vec::new(), Vec::new()));
        }
        let g = group_of[r];
        group_of[v] = g;
        local[v] = groups[g].0.len();
        groups[g].0.push(v);
    }
    for row in rows.iter() {
        let g = group_of[row[0].0];
        groups[g].1.push(row.iter().map(|&(v, w)| (local[v], w)).collect());
    }
    let l2 = opt.lambda * opt.lambda;
    // Per group: the solved values per channel, and its iterations (the most over channels).
    let solved: Vec<(Vec<f32>, usize)> = groups
        .par_iter()
        .map(|(vars, grows)| {
            let n = vars.len();
            // y = (R^T R + lambda^2 I) x
            let apply = |x: &[f64], y: &mut [f64]| {
                for (yi, xi) in y.iter_mut().zip(x) {
                    *yi = l2 * xi;
                }
                for row in grows {
                    let r: f64 = row.iter().map(|&(v, w)| w * x[v]).sum();
                    for &(v, w) in row {
                        y[v] += w * r;
                    }
                }
            };
            let mut out = vec![0f32; n * channels];
            let mut iterations = 0;
            for k in 0..channels {
                let x0: Vec<f64> = vars.iter().map(|&v| img[texels[v] * channels + k] as f64).collect();
                // Solve for the change d = x - x0: (R^T R + l2 I) d = -R^T R x0.
                let mut ax0 = vec![0f64; n];
                apply(&x0, &mut ax0);
                let mut r: Vec<f64> = ax0.iter().zip(&x0).map(|(a, x)| -(a - l2 * x)).collect();
                let mut d = vec![0f64; n];
                let mut p = r.clone();
                let mut ap = vec![0f64; n];
                let mut rr: f64 = r.iter().map(|v| v * v).sum();
                let tol = 1e-20 * (1.0 + x0.iter().map(|v| v * v).sum::<f64>());
                let mut it = 0;
                while it < opt.max_iterations && rr > tol {
                    apply(&p, &mut ap);
                    let pap: f64 = p.iter().zip(&ap).map(|(a, b)| a * b).sum();
                    if pap <= 0.0 {
                        break;
                    }
                    let alpha = rr / pap;
                    for i in 0..n {
                        d[i] += alpha * p[i];
                        r[i] -= alpha * ap[i];
                    }
                    let rr_new: f64 = r.iter().map(|v| v * v).sum();
                    let beta = rr_new / rr;
                    rr = rr_new;
                    for i in 0..n {
                        p[i] = r[i] + beta * p[i];
                    }
                    it += 1;
                }
                iterations = iterations.max(it);
                for i in 0..n {
                    out[i * channels + k] = ((x0[i] + d[i]) as f32).max(0.0);
                }
            }
            (out, iterations)
        })
        .collect();
    let (mut changed, mut iterations) = (0, 0);
    for ((vars, _), (vals, it)) in groups.iter().zip(&solved) {
        iterations = iterations.max(*it);
        for (i, &v) in vars.iter().enumerate() {
            let t = texels[v];
            let new = &vals[i * channels..(i + 1) * channels];
            changed += (img[t * channels..(t + 1) * channels] != *new) as usize;
            img[t * channels..(t + 1) * channels].copy_from_slice(new);
        }
    }
    let after = seam_mismatch_channels(img, channels, width, height, seams, opt.samples_per_texel)?;
    Ok(Stitch {
        seams: seams.len(),
        constraints: rows.len(),
        groups: groups.len(),
        texels_changed: changed,
        mismatch_before: before,
        mismatch_after: after,
        iterations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two charts: a 3x3 block of chart 5 at (2..5, 2..5) and one texel of chart 1 at (9, 3).
    fn page() -> (Vec<f32>, Vec<u32>, usize, usize) {
        let (w, h) = (14, 9);
        let mut rgb = vec![0f32; w * h * 3];
        let mut chart = vec![NONE; w * h];
        for y in 2..5 {
            for x in 2..5 {
                chart[y * w + x] = 5;
                rgb[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&[2.0, 3.0, 4.0]);
            }
        }
        chart[3 * w + 9] = 1;
        rgb[(3 * w + 9) * 3..(3 * w + 9) * 3 + 3].copy_from_slice(&[10.0, 20.0, 30.0]);
        (rgb, chart, w, h)
    }

    #[test]
    fn dilation_fills_exactly_the_rings_and_never_mixes_charts() {
        let (mut rgb, mut chart, w, h) = page();
        let orig = chart.clone();
        let info = dilate(&mut rgb, &mut chart, w, h, 2).unwrap();
        assert_eq!(info.filled_per_ring.len(), 2);
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                // Chebyshev distance to the nearest covered texel.
                let d = (0..h * w)
                    .filter(|&j| orig[j] != NONE)
                    .map(|j| ((j % w) as isize - x as isize).abs().max(((j / w) as isize - y as isize).abs()))
                    .min()
                    .unwrap();
                let v = &rgb[i * 3..i * 3 + 3];
                if d == 0 {
                    assert_eq!(chart[i], orig[i]);
                } else if d <= 2 {
                    let expect: &[f32] = if chart[i] == 5 { &[2.0, 3.0, 4.0] } else { &[10.0, 20.0, 30.0] };
                    assert_ne!(chart[i], NONE, "({x},{y})");
                    assert_eq!(v, expect, "({x},{y}) mixes charts");
                } else {
                    assert_eq!(chart[i], NONE);
                    assert_eq!(v, &[0.0, 0.0, 0.0]);
                }
            }
        }
        // Texel (7, 3) is 3 from chart 5 and 2 from chart 1: chart 1 wins; a texel equally near
        // both (none here at ring <= 2 with equal distance) would go to the lower id.
        assert_eq!(chart[3 * w + 7], 1);
    }

    #[test]
    fn dilation_ties_go_to_the_lower_chart_id() {
        let (w, h) = (5, 1);
        let mut rgb = vec![0f32; 15];
        let mut chart = vec![NONE; 5];
        chart[0] = 7;
        chart[2] = 3;
        rgb[0..3].copy_from_slice(&[1.0; 3]);
        rgb[6..9].copy_from_slice(&[9.0; 3]);
        dilate(&mut rgb, &mut chart, w, h, 1).unwrap();
        assert_eq!(chart[1], 3);
        assert_eq!(&rgb[3..6], &[9.0; 3]);
        assert_eq!(chart[3], 3);
        assert_eq!(chart[4], NONE);
    }

    #[test]
    fn bilinear_matches_the_sampler_convention() {
        let (w, h) = (2, 1);
        let rgb = [0.0, 0.0, 0.0, 4.0, 4.0, 4.0];
        assert_eq!(bilinear(&rgb, w, h, [0.5, 0.5])[0], 0.0);
        assert_eq!(bilinear(&rgb, w, h, [1.0, 0.5])[0], 2.0);
        assert_eq!(bilinear(&rgb, w, h, [1.5, 0.5])[0], 4.0);
        assert_eq!(bilinear(&rgb, w, h, [1.9, 0.5])[0], 4.0); // clamp to edge
    }

    /// A unit square in 3D made of two triangles whose shared diagonal is cut into two UV
    /// islands, each with a different constant: one seam.
    #[test]
    fn seams_are_found_and_stitched() {
        let (w, h) = (32usize, 16usize);
        // Triangle A: (0,0,0) (1,0,0) (1,1,0); triangle B: (0,0,0) (1,1,0) (0,1,0).
        let positions: Vec<f32> = vec![0., 0., 0., 1., 0., 0., 1., 1., 0., 0., 0., 0., 1., 1., 0., 0., 1., 0.];
        // Side A in the left half of the page, side B in the right, 8 texels per metre.
        let t = |x: f32, y: f32| [x / w as f32, y / h as f32];
        let uv: Vec<f32> = [t(4., 4.), t(12., 4.), t(12., 12.), t(20., 4.), t(28., 12.), t(20., 12.)].concat();
        let tris = [0u32, 1, 2, 3, 4, 5];
        let m = SeamMesh { uv: &uv, triangles: &tris, positions: &positions, normals: None, mesh: None };
        let seams = find_seams(&m, w, h, &SeamOptions::default()).unwrap();
        assert_eq!(seams.len(), 1);
        let s = seams[0];
        assert_eq!(s.a, [[4.0, 4.0], [12.0, 12.0]]);
        assert_eq!(s.b, [[20.0, 4.0], [28.0, 12.0]]);
        // A gradient on the left, a constant on the right.
        let mut rgb = vec![0f32; w * h * 3];
        for y in 0..h {
            for x in 0..w {
                let v = if x < 16 { 1.0 + 0.1 * x as f32 } else { 3.0 };
                rgb[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&[v, v * 0.5, v * 2.0]);
            }
        }
        let st = stitch_seams(&mut rgb, w, h, &seams, &StitchOptions::default()).unwrap();
        assert!(st.mismatch_before.0 > 1.0, "{st:?}");
        assert!(st.mismatch_after.0 < 0.02 * st.mismatch_before.0, "{st:?}");
        assert!(rgb.iter().all(|&v| v >= 0.0));
        // Far from the seam nothing moved.
        assert_eq!(rgb[(1 * w + 1) * 3], 1.1);
    }

    #[test]
    fn hard_edges_and_shared_uvs_are_not_seams() {
        let (w, h) = (16usize, 16usize);
        // Two triangles folded 90 degrees along x = 1 (a box edge), with split UVs.
        let positions: Vec<f32> = vec![0., 0., 0., 1., 0., 0., 1., 1., 0., 1., 0., 0., 1., 0., 1., 1., 1., 0.];
        let uv: Vec<f32> = vec![0.1, 0.1, 0.4, 0.1, 0.4, 0.4, 0.6, 0.1, 0.9, 0.1, 0.6, 0.4];
        let tris = [0u32, 1, 2, 3, 4, 5];
        let m = SeamMesh { uv: &uv, triangles: &tris, positions: &positions, normals: None, mesh: None };
        assert!(find_seams(&m, w, h, &SeamOptions::default()).unwrap().is_empty());
        // The same quad with shared UVs along its diagonal: no seam.
        let positions: Vec<f32> = vec![0., 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., 0.];
        let uv: Vec<f32> = vec![0.1, 0.1, 0.5, 0.1, 0.5, 0.5, 0.1, 0.5];
        let tris = [0u32, 1, 2, 0, 2, 3];
        let m = SeamMesh { uv: &uv, triangles: &tris, positions: &positions, normals: None, mesh: None };
        assert!(find_seams(&m, w, h, &SeamOptions::default()).unwrap().is_empty());
    }
}
