//! The LOD stage's per-level bookkeeping (`asset_pipeline.lod`, whose docstring is the full
//! story): [`track_collapses`] follows fast-simplification's collapse list to say where every
//! face, vertex and seam of a level went (step 3); [`split`] and the attribute functions give
//! the simplified, position-welded level its split vertices and attributes by walking over
//! LOD 0 (step 4).
//!
//! [`split`] walks each output corner from the LOD 0 face it descends from toward its (moved)
//! position, staying in the region of continuous attributes (across `adjacency` only), and merges
//! corners that reach the same point of LOD 0 into one output vertex; a vertex with no seam among
//! its merged LOD 0 vertices is walked once. The attribute functions then interpolate LOD 0's
//! values at those points: plain barycentric blends, renormalised normals, re-orthonormalised
//! tangents, rounded colours, per-joint blended skin weights, and morph target deltas (blended
//! per target; see [`Morphs::carry`]).
//!
//! Everything is deterministic (parallel work writes fixed slots; merging runs in corner order).

use crate::measure::{self, Bvh, FxMap, CHUNK};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{mpsc, Arc, Condvar, Mutex};
use std::thread::JoinHandle;

/// LOD 0 welded by position (step 1), as simplification starts from it.
pub struct Welded {
    /// The welded vertices (the first split vertex at each position, in order of first use).
    pub points: Vec<[f32; 3]>,
    /// The faces over them, without those with two corners at one position.
    pub faces: Vec<[u32; 3]>,
    /// The LOD 0 face of each face.
    pub face_origin: Vec<u32>,
    /// Per vertex: faces use more than one split copy of it (it is on a seam).
    pub seamy: Vec<bool>,
    /// Edges whose faces use different split vertices at either end: [a, b], a < b.
    pub seams: Vec<[u32; 2]>,
    /// Per vertex: a LOD 0 face around it (the last one), where its first walk starts.
    pub near: Vec<u32>,
    /// Length of the bounding-box diagonal of the vertices faces use.
    pub diagonal: f64,
}

pub fn weld(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Welded {
    let (ids, first) = measure::weld_positions(positions);
    let wf: Vec<[u32; 3]> = triangles.iter().map(|t| t.map(|i| ids[i as usize])).collect();
    let mut used = vec![false; positions.len()];
    let mut near = vec![0u32; first.len()];
    for (f, (t, w)) in triangles.iter().zip(&wf).enumerate() {
        t.iter().for_each(|&i| used[i as usize] = true);
        w.iter().for_each(|&i| near[i as usize] = f as u32);
    }
    let mut copies = vec![0u32; first.len()];
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for (i, _) in used.iter().enumerate().filter(|(_, &u)| u) {
        copies[ids[i] as usize] += 1;
        for k in 0..3 {
            lo[k] = lo[k].min(positions[i][k] as f64);
            hi[k] = hi[k].max(positions[i][k] as f64);
        }
    }
    let face_origin: Vec<u32> = (0..wf.len() as u32).filter(|&f| {
        let t = wf[f as usize];
        t[0] != t[1] && t[1] != t[2] && t[0] != t[2]
    }).collect();
    let faces: Vec<[u32; 3]> = face_origin.iter().map(|&f| wf[f as usize]).collect();
    let split: Vec<[u32; 3]> = face_origin.iter().map(|&f| triangles[f as usize]).collect();
    let seamy: Vec<bool> = copies.iter().map(|&c| c > 1).collect();
    let seams = measure::seam_edges(&faces, &split, &seamy).into_iter().map(|e| [e[0], e[1]]).collect();
    Welded {
        points: first.iter().map(|&i| positions[i as usize]).collect(),
        faces,
        face_origin,
        seamy,
        seams,
        near,
        diagonal: if lo[0] <= hi[0] { norm([hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]]) } else { 0.0 },
    }
}

/// Where a level's faces, vertices and seams went in one simplification (see [`track_collapses`]).
#[derive(Debug, PartialEq)]
pub struct Tracked {
    /// The new level's faces: the surviving real faces, in order, corners renumbered.
    pub faces: Vec<[u32; 3]>,
    /// Index (among the real input faces) of each surviving face.
    pub kept: Vec<u32>,
    /// Per new vertex: its row in the simplifier's output points.
    pub rows: Vec<u32>,
    /// Per new vertex: a seamy input vertex was merged into it.
    pub seamy: Vec<bool>,
    /// The input seams where the collapses took them: sorted pairs, sorted, no duplicates.
    pub seams: Vec<[u32; 2]>,
    /// Per new vertex: the input vertex whose walk end its walk starts from (itself, or for a flap
    /// tip that absorbed real vertices, the first of them).
    pub survivor: Vec<u32>,
}

/// Follow fast-simplification's collapse list. `faces` is what it was given: `real` faces over
/// `seamy.len()` real vertices, then flaps over extra tip vertices; `collapses` its `(i0, i1)`
/// pairs (i1 merged into i0) and `out_faces` its output faces. It never creates triangles: it
/// deletes those that degenerate, keeps the others in order and corner order, and numbers the
/// vertices they use in order, which is checked here (an error if its numbering ever changes).
pub fn track_collapses(faces: &[[u32; 3]], real: usize, collapses: &[[u32; 2]], out_faces: &[[u32; 3]], seamy: &[bool], seams: &[[u32; 2]]) -> Result<Tracked, String> {
    let n = seamy.len();
    let points = faces.iter().flatten().chain(collapses.iter().flatten()).map(|&i| i as usize + 1).max().unwrap_or(0).max(n);
    let mut root: Vec<u32> = (0..points as u32).collect();
    for &[i0, i1] in collapses {
        root[i1 as usize] = i0;
    }
    // Chains i2 -> i1 -> i0: resolve each to its end (with path compression; a cycle is a bug).
    for i in 0..points {
        let mut r = i;
        for _ in 0..=points {
            let next = root[r] as usize;
            if next == r {
                break;
            }
            r = next;
        }
        if root[r] as usize != r {
            return Err("fast_simplification's collapse list has a cycle".into());
        }
        let mut j = i;
        while root[j] as usize != r {
            let next = root[j] as usize;
            root[j] = r as u32;
            j = next;
        }
    }
    let mapped = |t: &[u32; 3]| t.map(|i| root[i as usize]);
    let alive = |t: &[u32; 3]| t[0] != t[1] && t[1] != t[2] && t[0] != t[2];
    // The surviving faces (in order) over their roots, mapped once. Serial: the LOD stage calls
    // this on its calling thread between simplifications, while the other core carries the
    // level before.
    let survivors: Vec<(u32, [u32; 3])> = faces
        .iter()
        .enumerate()
        .filter_map(|(f, t)| {
            let t = mapped(t);
            alive(&t).then_some((f as u32, t))
        })
        .collect();
    let mut used = vec![false; points];
    for (_, t) in &survivors {
        t.iter().for_each(|&i| used[i as usize] = true);
    }
    let mut number = vec![u32::MAX; points];
    let mut k = 0;
    for (i, &u) in used.iter().enumerate() {
        if u {
            number[i] = k;
            k += 1;
        }
    }
    let matches = survivors.len() == out_faces.len() && survivors.iter().zip(out_faces).all(|((_, t), o)| t.map(|i| number[i as usize]) == *o);
    if !matches {
        return Err("fast_simplification's output does not match its collapse list".into());
    }
    // The real faces and the vertices they use (a flap tip that absorbed a real vertex stands in
    // for it, at its position: it is just a vertex).
    let real_survivors = &survivors[..survivors.partition_point(|&(f, _)| (f as usize) < real)];
    let kept: Vec<u32> = real_survivors.iter().map(|&(f, _)| f).collect();
    let mut used_real = vec![false; points];
    for (_, t) in real_survivors {
        t.iter().for_each(|&i| used_real[i as usize] = true);
    }
    let mut renumber = vec![u32::MAX; points];
    let mut roots = Vec::new();
    for (i, &u) in used_real.iter().enumerate() {
        if u {
            renumber[i] = roots.len() as u32;
            roots.push(i as u32);
        }
    }
    let mut new_seamy = vec![false; roots.len()];
    let mut first = vec![u32::MAX; points];
    for i in 0..n {
        let r = root[i] as usize;
        if used_real[r] {
            new_seamy[renumber[r] as usize] |= seamy[i];
            first[r] = first[r].min(i as u32);
        }
    }
    let mut new_seams: Vec<[u32; 2]> = seams
        .iter()
        .filter_map(|&[a, b]| {
            let (ra, rb) = (root[a as usize] as usize, root[b as usize] as usize);
            (ra != rb && used_real[ra] && used_real[rb]).then(|| {
                let (x, y) = (renumber[ra], renumber[rb]);
                [x.min(y), x.max(y)]
            })
        })
        .collect();
    new_seams.sort_unstable();
    new_seams.dedup();
    Ok(Tracked {
        faces: real_survivors.iter().map(|(_, t)| t.map(|i| renumber[i as usize])).collect(),
        kept,
        rows: roots.iter().map(|&r| number[r as usize]).collect(),
        seamy: new_seamy,
        seams: new_seams,
        survivor: roots.iter().map(|&r| if (r as usize) < n { r } else { first[r as usize] }).collect(),
    })
}

/// LOD 0, split by attributes, and its face adjacency (edges crossed by walks).
pub struct Lod0<'a> {
    pub positions: &'a [[f32; 3]],
    pub triangles: &'a [[u32; 3]],
    pub adjacency: &'a [[u32; 3]],
}

/// A simplified level in welded form.
pub struct Level<'a> {
    pub points: &'a [[f32; 3]],
    pub faces: &'a [[u32; 3]],
    /// The LOD 0 face each face descends from (corner j from its corner j).
    pub face_origin: &'a [u32],
    /// Per vertex: a LOD 0 vertex with several split copies was merged into it.
    pub seamy: &'a [bool],
    /// Per vertex: a LOD 0 face near it, where its walk starts (when not seamy).
    pub near: &'a [u32],
}

/// The split level: output vertices and where on LOD 0 each one's attributes come from.
pub struct Split {
    pub triangles: Vec<[u32; 3]>,
    pub positions: Vec<[f32; 3]>,
    /// Per output vertex: the LOD 0 face its point lies on, and the point's barycentric weights.
    pub source: Vec<u32>,
    pub bary: Vec<[f64; 3]>,
    /// Per level vertex: where its walk ended (the next level's walks start there).
    pub near: Vec<u32>,
}

/// Barycentric weights are keyed to 2^-20 when merging corners that reached the same point.
const KEY_SCALE: f64 = (1u64 << 20) as f64;

pub fn split(lod0: &Lod0, level: &Level) -> Split {
    let nv = level.points.len();
    let corners: Vec<u32> = level.faces.iter().flatten().copied().collect();
    // Plain vertices: one output vertex each, walked from their survivor's spot. Corners of seamy
    // vertices: walked one by one from their face's origin.
    let plain: Vec<u32> = (0..nv as u32).filter(|&i| !level.seamy[i as usize]).collect();
    let edge: Vec<u32> = (0..corners.len() as u32).filter(|&c| level.seamy[corners[c as usize] as usize]).collect();
    let starts: Vec<u32> = plain.iter().map(|&i| level.near[i as usize]).chain(edge.iter().map(|&c| level.face_origin[c as usize / 3])).collect();
    let targets: Vec<[f32; 3]> = plain
        .iter()
        .map(|&i| level.points[i as usize])
        .chain(edge.iter().map(|&c| level.points[corners[c as usize] as usize]))
        .collect();
    let walks = measure::walk_closest_many(lod0.positions, lod0.triangles, lod0.adjacency, &starts, &targets);
    let n_plain = plain.len();

    // Merge the seamy corners by (vertex, LOD 0 corners with nonzero weight in id order, weights
    // to 2^-20): canonical, so corners that end on a shared edge or corner of LOD 0 get one key
    // whichever face they stopped in. Output vertices are numbered in order of first corner.
    let mut groups: FxMap<(u32, [(i64, i64); 3]), u32> = Default::default();
    let mut first_walk: Vec<usize> = Vec::new(); // the walk that gives each group its values
    let edge_out: Vec<u32> = edge
        .iter()
        .enumerate()
        .map(|(k, &c)| {
            let (tri, _, bary) = walks[n_plain + k];
            let ids = lod0.triangles[tri as usize];
            let mut key = [0, 1, 2].map(|j| {
                let q = (bary[j] * KEY_SCALE).round_ties_even() as i64;
                if q > 0 {
                    (ids[j] as i64, q)
                } else {
                    (-1, 0)
                }
            });
            key.sort_by_key(|e| e.0); // stable, like the rest of the key: ties keep corner order
            let next = groups.len() as u32;
            let g = *groups.entry((corners[c as usize], key)).or_insert(next);
            if g == next {
                first_walk.push(n_plain + k);
            }
            n_plain as u32 + g
        })
        .collect();

    let mut vertex_out = vec![u32::MAX; nv];
    for (k, &i) in plain.iter().enumerate() {
        vertex_out[i as usize] = k as u32;
    }
    let mut corner_out: Vec<u32> = corners.iter().map(|&v| vertex_out[v as usize]).collect();
    for (&c, &o) in edge.iter().zip(&edge_out) {
        corner_out[c as usize] = o;
    }
    let mut near = level.near.to_vec();
    for (k, &i) in plain.iter().enumerate() {
        near[i as usize] = walks[k].0;
    }
    for (k, &c) in edge.iter().enumerate() {
        near[corners[c as usize] as usize] = walks[n_plain + k].0; // the last corner's
    }
    let picks: Vec<usize> = (0..n_plain).chain(first_walk.iter().copied()).collect();
    let positions = plain
        .iter()
        .map(|&i| level.points[i as usize])
        .chain(first_walk.iter().map(|&w| level.points[corners[edge[w - n_plain] as usize] as usize]))
        .collect();
    Split {
        triangles: corner_out.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
        positions,
        source: picks.iter().map(|&w| walks[w].0).collect(),
        bary: picks.iter().map(|&w| walks[w].2).collect(),
        near,
    }
}

/// Where output vertices take their values from: LOD 0's three corner vertices and weights.
pub struct Sources<'a> {
    pub triangles: &'a [[u32; 3]],
    pub source: &'a [u32],
    pub bary: &'a [[f64; 3]],
}

impl Sources<'_> {
    fn len(&self) -> usize {
        self.source.len()
    }

    fn corners(&self, i: usize) -> [usize; 3] {
        self.triangles[self.source[i] as usize].map(|x| x as usize)
    }

    /// The corner with the largest weight (the first on ties).
    pub fn dominant(&self, i: usize) -> usize {
        let b = self.bary[i];
        let j = if b[1] > b[0] {
            if b[2] > b[1] {
                2
            } else {
                1
            }
        } else if b[2] > b[0] {
            2
        } else {
            0
        };
        self.corners(i)[j]
    }

    /// Each output vertex's `W` values, computed in parallel from its index.
    fn map<T: Send + Copy + Default, const W: usize>(&self, f: impl Fn(usize) -> [T; W] + Sync) -> Vec<[T; W]> {
        let mut out = vec![[T::default(); W]; self.len()];
        out.par_chunks_mut(CHUNK).enumerate().for_each(|(c, dst)| {
            for (j, o) in dst.iter_mut().enumerate() {
                *o = f(c * CHUNK + j);
            }
        });
        out
    }

    fn blend<const W: usize>(&self, values: &[[f32; W]], i: usize) -> [f64; W] {
        let (c, b) = (self.corners(i), self.bary[i]);
        std::array::from_fn(|k| b[0] * values[c[0]][k] as f64 + b[1] * values[c[1]][k] as f64 + b[2] * values[c[2]][k] as f64)
    }

    /// Barycentric blend (UVs and other plain attributes).
    pub fn interpolate<const W: usize>(&self, values: &[[f32; W]]) -> Vec<[f32; W]> {
        self.map(|i| self.blend(values, i).map(|x| x as f32))
    }

    /// Blended normals, renormalised; the dominant corner's where the blend cancels out.
    pub fn normals(&self, normals: &[[f32; 3]]) -> Vec<[f32; 3]> {
        self.map(|i| {
            let n = self.blend(normals, i);
            let n = if norm(n) > 1e-12 { n } else { normals[self.dominant(i)].map(|x| x as f64) };
            let l = norm(n).max(1e-300);
            n.map(|x| (x / l) as f32)
        })
    }

    /// A morph target's normal deltas `deltas` at the points, for output normals made by
    /// [`Sources::normals`] from LOD 0's `normals`: the barycentric blend divided by the length of
    /// the blended normal (the factor the output normal was divided by), so the output's
    /// `n + w dn` is LOD 0's blended `n + w dn` scaled by one positive factor at every weight `w`
    /// (the skinning pass normalises it: the same direction). Where the normal blend cancels out
    /// (the dominant corner's normal was taken), the dominant corner's delta.
    pub fn normal_deltas(&self, deltas: &[[f32; 3]], normals: &[[f32; 3]]) -> Vec<[f32; 3]> {
        self.map(|i| {
            let l = norm(self.blend(normals, i));
            if l > 1e-12 {
                self.blend(deltas, i).map(|x| (x / l) as f32)
            } else {
                deltas[self.dominant(i)]
            }
        })
    }

    /// Blended tangents, Gram-Schmidt against the output `normals`; handedness (w) from the
    /// dominant corner. Where the blend is parallel to the normal, any perpendicular unit vector.
    pub fn tangents(&self, tangents: &[[f32; 4]], normals: &[[f32; 3]]) -> Vec<[f32; 4]> {
        self.map(|i| {
            let b = self.blend(tangents, i);
            let n = normals[i].map(|x| x as f64);
            let d = b[0] * n[0] + b[1] * n[1] + b[2] * n[2];
            let mut t = [b[0] - n[0] * d, b[1] - n[1] * d, b[2] - n[2] * d];
            if norm(t) < 1e-9 {
                // Cross with the axis the normal is least aligned with.
                let a = n.map(f64::abs);
                let k = if a[1] < a[0] {
                    if a[2] < a[1] {
                        2
                    } else {
                        1
                    }
                } else if a[2] < a[0] {
                    2
                } else {
                    0
                };
                let mut axis = [0.0; 3];
                axis[k] = 1.0;
                t = [n[1] * axis[2] - n[2] * axis[1], n[2] * axis[0] - n[0] * axis[2], n[0] * axis[1] - n[1] * axis[0]];
            }
            let l = norm(t);
            let w = if tangents[self.dominant(i)][3] < 0.0 { -1.0 } else { 1.0 };
            [(t[0] / l) as f32, (t[1] / l) as f32, (t[2] / l) as f32, w]
        })
    }

    /// Blended 8-bit colours, rounded (half to even) and clamped.
    pub fn colors(&self, colors: &[[u8; 4]]) -> Vec<[u8; 4]> {
        self.map(|i| {
            let (c, b) = (self.corners(i), self.bary[i]);
            std::array::from_fn(|k| {
                let x = b[0] * colors[c[0]][k] as f64 + b[1] * colors[c[1]][k] as f64 + b[2] * colors[c[2]][k] as f64;
                x.round_ties_even().clamp(0.0, 255.0) as u8
            })
        })
    }

    /// The dominant corner's values (attributes that cannot be blended alone).
    pub fn nearest<T: Send + Sync + Copy + Default, const W: usize>(&self, values: &[[T; W]]) -> Vec<[T; W]> {
        self.map(|i| values[self.dominant(i)])
    }

    /// Skin weights at the point: each corner's weights times its barycentric weight, summed per
    /// joint; the four largest joints kept (ties: first seen) and renormalised to sum 1; unused
    /// slots joint 0, weight 0. Where the corners have no weight at all, the dominant corner's
    /// skin as it is.
    pub fn skin(&self, joints: &[[u16; 4]], weights: &[[f32; 4]]) -> (Vec<[u16; 4]>, Vec<[f32; 4]>) {
        let both: Vec<([u16; 4], [f32; 4])> = self
            .map(|i| {
                let (c, b) = (self.corners(i), self.bary[i]);
                let mut cand: Vec<(u16, f64)> = Vec::with_capacity(12);
                for (k, &v) in c.iter().enumerate() {
                    for s in 0..4 {
                        let (j, w) = (joints[v][s], weights[v][s] as f64 * b[k]);
                        match cand.iter_mut().find(|e| e.0 == j) {
                            Some(e) => e.1 += w,
                            None => cand.push((j, w)),
                        }
                    }
                }
                cand.sort_by(|x, y| y.1.total_cmp(&x.1)); // stable: ties keep first-seen order
                let mut oj = [0u16; 4];
                let mut ow = [0f64; 4];
                for (s, &(j, w)) in cand.iter().take(4).enumerate() {
                    (oj[s], ow[s]) = (j, w.max(0.0));
                }
                let mut sum: f64 = ow.iter().sum();
                if sum <= 0.0 {
                    let d = self.dominant(i);
                    oj = joints[d];
                    ow = weights[d].map(|w| w as f64);
                    sum = ow.iter().sum::<f64>().max(1e-30);
                }
                let ow = ow.map(|w| w / sum);
                let oj = std::array::from_fn(|s| if ow[s] > 0.0 { oj[s] } else { 0 });
                [(oj, ow.map(|w| w as f32))]
            })
            .into_iter()
            .map(|[x]| x)
            .collect();
        both.into_iter().unzip()
    }
}

/// A mesh's attributes other than position (as the IR's `ATTRIBUTES`): LOD 0's, or a level's.
#[derive(Default)]
pub struct Attributes {
    pub normal: Option<Vec<[f32; 3]>>,
    pub tangent: Option<Vec<[f32; 4]>>,
    pub uv0: Option<Vec<[f32; 2]>>,
    pub uv1: Option<Vec<[f32; 2]>>,
    pub color: Option<Vec<[u8; 4]>>,
    pub joints: Option<Vec<[u16; 4]>>,
    pub weights: Option<Vec<[f32; 4]>>,
}

impl Attributes {
    /// Row counts of the attributes present.
    pub fn lens(&self) -> impl Iterator<Item = usize> + '_ {
        let l = [self.normal.as_ref().map(Vec::len), self.tangent.as_ref().map(Vec::len), self.uv0.as_ref().map(Vec::len), self.uv1.as_ref().map(Vec::len)];
        let m = [self.color.as_ref().map(Vec::len), self.joints.as_ref().map(Vec::len), self.weights.as_ref().map(Vec::len)];
        l.into_iter().chain(m).flatten()
    }

    /// These attributes at the points `src` names, each by its rule (see [`Sources`]).
    pub fn carry(&self, src: &Sources) -> Attributes {
        let normal = self.normal.as_deref().map(|a| src.normals(a));
        let tangent = self.tangent.as_deref().map(|t| match &normal {
            Some(n) => src.tangents(t, n),
            None => src.interpolate(t),
        });
        let (joints, weights) = match (&self.joints, &self.weights) {
            (Some(j), Some(w)) => {
                let (j, w) = src.skin(j, w);
                (Some(j), Some(w))
            }
            (j, w) => (j.as_deref().map(|j| src.nearest(j)), w.as_deref().map(|w| src.nearest(w))),
        };
        Attributes {
            normal,
            tangent,
            uv0: self.uv0.as_deref().map(|a| src.interpolate(a)),
            uv1: self.uv1.as_deref().map(|a| src.interpolate(a)),
            color: self.color.as_deref().map(|a| src.colors(a)),
            joints,
            weights,
        }
    }
}

/// A mesh's morph target deltas (as the IR's `morph_positions` / `morph_normals`): LOD 0's, or
/// a level's. Tangents have no deltas (the IR keeps none).
#[derive(Default)]
pub struct Morphs {
    /// Position deltas, [target][vertex]; empty when the mesh has no morph targets.
    pub positions: Vec<Vec<[f32; 3]>>,
    /// Normal deltas, [target][vertex]; empty, or one list per target.
    pub normals: Vec<Vec<[f32; 3]>>,
}

impl Morphs {
    /// These deltas at the points `src` names, per target: position deltas blended
    /// (barycentric, like UVs: a carried vertex moves by LOD 0's displacement at the point its
    /// attributes come from), normal deltas blended and scaled with the normal (see
    /// [`Sources::normal_deltas`]; plain blends when LOD 0 has no normals).
    pub fn carry(&self, src: &Sources, normals0: Option<&[[f32; 3]]>) -> Morphs {
        Morphs {
            positions: self.positions.iter().map(|d| src.interpolate(d)).collect(),
            normals: self
                .normals
                .iter()
                .map(|d| match normals0 {
                    Some(n) => src.normal_deltas(d, n),
                    None => src.interpolate(d),
                })
                .collect(),
        }
    }

    /// `positions` with target `t` at weight 1.
    pub fn morphed(&self, positions: &[[f32; 3]], t: usize) -> Vec<[f32; 3]> {
        positions.iter().zip(&self.positions[t]).map(|(p, d)| [p[0] + d[0], p[1] + d[1], p[2] + d[2]]).collect()
    }
}

/// LOD 0 as the chain needs it: split mesh, a key per face (walks cross only between faces of one
/// key: material and lightmap page), attributes and morph deltas. Indices must be valid (see
/// [`Chain::start`]).
pub struct Lod0Data {
    pub positions: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
    pub keys: Vec<u32>,
    pub attributes: Attributes,
    pub morphs: Morphs,
}

/// One simplified level, welded (see [`Level`]); `survivor[i]` is the vertex of the level before
/// (of LOD 0's welded level for the first) whose walk end vertex i's walk starts from.
pub struct Job {
    pub points: Vec<[f32; 3]>,
    pub faces: Vec<[u32; 3]>,
    pub face_origin: Vec<u32>,
    pub seamy: Vec<bool>,
    pub survivor: Vec<u32>,
}

/// A finished level: its split mesh, attributes and morph deltas, and its measured error (the
/// sampled symmetric Hausdorff distance to LOD 0, in LOD 0's units, the largest of the rest pose
/// and each morph target at weight 1; 0 when not measured).
pub struct Carried {
    pub positions: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
    pub attributes: Attributes,
    pub morphs: Morphs,
    pub error: f64,
}

/// How errors are measured: sample spacing in LOD 0 mean edge lengths, grid subdivisions per
/// edge of a level's triangles (LOD 0's get 2), and a sample budget per direction.
#[derive(Clone, Copy)]
pub struct ErrorSettings {
    pub sample_spacing: f64,
    pub min_subdiv: u32,
    pub max_samples: u64,
}

/// A thread that carries attributes to each level and measures its error while the caller makes
/// the next one. It needs nothing from the caller but the levels: LOD 0's adjacency and BVH are
/// built on the thread, and each level's walks start from where the level before's ended.
pub struct Chain {
    jobs: Option<mpsc::Sender<Job>>,
    worker: Option<JoinHandle<Vec<Carried>>>,
    /// Errors of the levels finished so far, and a signal for each one finished.
    errors: Arc<(Mutex<Vec<f64>>, Condvar)>,
    submitted: AtomicUsize,
    caller_done: Arc<AtomicBool>,
}

impl Chain {
    /// `near0`: per vertex of LOD 0's welded level, a LOD 0 face around it.
    pub fn start(lod0: Lod0Data, near0: Vec<u32>, measure: Option<ErrorSettings>) -> Chain {
        let (tx, rx) = mpsc::channel::<Job>();
        let errors = Arc::new((Mutex::new(Vec::new()), Condvar::new()));
        let report = errors.clone();
        let caller_done = Arc::new(AtomicBool::new(false));
        let done = caller_done.clone();
        let worker = std::thread::spawn(move || {
            // While the caller is still simplifying (one core, busy), leave it a core: levels
            // carried meanwhile use one thread fewer than the machine has; once it waits in
            // `finish`, the rest use them all. Rayon's own count, so RAYON_NUM_THREADS=1 limits
            // this pool too (with `wait`, the benchmark's one-thread comparison).
            let cores = rayon::current_num_threads();
            let beside = rayon::ThreadPoolBuilder::new().num_threads(cores.saturating_sub(1).max(1)).build().ok();
            let in_pool = |f: &mut (dyn FnMut() + Send)| match (&beside, done.load(Ordering::Acquire)) {
                (Some(pool), false) => pool.install(f),
                _ => f(),
            };
            // LOD 0 with each morph target at weight 1 (positions and BVH, None where it cannot
            // be built), where levels are measured with their own deltas, besides the rest pose.
            let (mut adjacency, mut bvh0, mut morphed0, mut spacing) = (Vec::new(), None, Vec::<(Vec<[f32; 3]>, Option<Bvh>)>::new(), 0.0);
            in_pool(&mut || {
                adjacency = measure::face_adjacency(&lod0.triangles, &lod0.keys);
                bvh0 = measure.and_then(|_| Bvh::build(&lod0.positions, &lod0.triangles).ok());
                if measure.is_some() {
                    morphed0 = (0..lod0.morphs.positions.len())
                        .map(|t| {
                            let p = lod0.morphs.morphed(&lod0.positions, t);
                            let bvh = Bvh::build(&p, &lod0.triangles).ok();
                            (p, bvh)
                        })
                        .collect();
                }
                spacing = measure.map_or(0.0, |m| m.sample_spacing * mean_edge(&lod0.positions, &lod0.triangles));
            });
            // LOD 0 is the source of every level's LOD 0 -> level measure (at rest, and with each
            // target at weight 1): prepared once here, not once per level.
            let mut sources0: Vec<Option<measure::Source>> = Vec::new();
            in_pool(&mut || {
                if let Some(m) = measure {
                    sources0 = std::iter::once(&lod0.positions)
                        .chain(morphed0.iter().map(|(p, _)| p))
                        .map(|p| measure::Source::new(p, &lod0.triangles, spacing, 1, m.max_samples).ok())
                        .collect();
                }
            });
            let view = Lod0 { positions: &lod0.positions, triangles: &lod0.triangles, adjacency: &adjacency };
            let (mut near, mut out) = (near0, Vec::new());
            for job in rx {
                in_pool(&mut || {
                    let start: Vec<u32> = job.survivor.iter().map(|&s| near[s as usize]).collect();
                    let level = Level { points: &job.points, faces: &job.faces, face_origin: &job.face_origin, seamy: &job.seamy, near: &start };
                    let sp = split(&view, &level);
                    let src = Sources { triangles: &lod0.triangles, source: &sp.source, bary: &sp.bary };
                    let attributes = lod0.attributes.carry(&src);
                    let morphs = lod0.morphs.carry(&src, lod0.attributes.normal.as_deref());
                    let error = match (measure, &bvh0) {
                        (Some(m), Some(bvh0)) => {
                            // At rest, then with each morph target at weight 1 (LOD 0 and the
                            // level each moved by its own deltas): the largest bounds them all.
                            let rest = level_error(sources0[0].as_ref(), bvh0, &sp.positions, &sp, spacing, m);
                            morphed0.iter().enumerate().fold(rest, |e, (t, (_, b0))| {
                                e.max(b0.as_ref().map_or(f64::INFINITY, |b0| level_error(sources0[t + 1].as_ref(), b0, &morphs.morphed(&sp.positions, t), &sp, spacing, m)))
                            })
                        }
                        _ => 0.0,
                    };
                    report.0.lock().unwrap().push(error);
                    report.1.notify_all();
                    near = sp.near;
                    out.push(Carried { positions: sp.positions, triangles: sp.triangles, attributes, morphs, error });
                });
            }
            out
        });
        Chain { jobs: Some(tx), worker: Some(worker), errors, submitted: AtomicUsize::new(0), caller_done }
    }

    /// Queue the next level (its survivors refer to the level queued before).
    pub fn submit(&self, job: Job) {
        // A send fails only when the worker has died; `finish` reports that.
        self.submitted.fetch_add(1, Ordering::Relaxed);
        let _ = self.jobs.as_ref().map(|tx| tx.send(job));
    }

    /// Block until every level submitted so far is carried and measured (or the worker died):
    /// with it, the caller and the worker take turns, one thread at a time.
    pub fn wait(&self) {
        let want = self.submitted.load(Ordering::Relaxed);
        let (lock, done) = &*self.errors;
        let mut errors = lock.lock().unwrap();
        while errors.len() < want && !self.worker.as_ref().is_none_or(|w| w.is_finished()) {
            errors = done.wait_timeout(errors, std::time::Duration::from_millis(50)).unwrap().0;
        }
    }

    /// Errors of the levels finished so far, in order.
    pub fn errors(&self) -> Vec<f64> {
        self.errors.0.lock().map(|e| e.clone()).unwrap_or_default()
    }

    /// Wait for every queued level.
    pub fn finish(mut self) -> Result<Vec<Carried>, String> {
        self.caller_done.store(true, Ordering::Release);
        drop(self.jobs.take());
        self.worker.take().map_or(Ok(Vec::new()), |w| w.join().map_err(|_| "the LOD worker thread panicked".to_string()))
    }
}

/// Sampled symmetric Hausdorff distance between a split level and LOD 0 (see
/// `Bvh::directed_hausdorff`), both in one pose: LOD 0 prepared as `source0` (None: it could
/// not be, and the error is infinite) at the positions `bvh0` is built over,
/// the level at `positions` (its own at rest, or moved by its morph deltas). LOD 0 is sampled
/// against the level at `spacing` (its small triangles at their corners only), the level's big
/// triangles at `min_subdiv` or more cells per edge against LOD 0 (its vertices' LOD 0 faces as
/// hints); each side's best samples are then refined by local search.
pub fn level_error(source0: Option<&measure::Source>, bvh0: &Bvh, positions: &[[f32; 3]], level: &Split, spacing: f64, m: ErrorSettings) -> f64 {
    let Ok(bvh) = Bvh::build(positions, &level.triangles) else { return f64::INFINITY };
    // LOD 0's triangles shorter than the spacing get no edge midpoints (they used to: 2M samples
    // a level at 1M triangles against 0.5M corners; half of this direction's time). Why that
    // still finds the maximum: over a LOD 0 triangle the distance to one level triangle is
    // convex, so it peaks at a corner; it can peak inside only where the nearest level triangle
    // changes, by at most the LOD 0 triangle's size times the level's bend there, and the local
    // search (pass 3, from the best corners into every triangle around them) climbs to such
    // peaks. Measured: the same maxima on every level of bench_lod's 1M-triangle mesh, and the
    // tests' independent 60k-sample Hausdorff stays under the stored errors.
    let a = source0.map_or(f64::INFINITY, |s0| bvh.directed_hausdorff_from(s0, None).map_or(f64::INFINITY, |d| d.max));
    let b = bvh0.directed_hausdorff(positions, &level.triangles, spacing, m.min_subdiv, m.max_samples, Some(&level.source)).map_or(f64::INFINITY, |d| d.max);
    a.max(b)
}

/// Edge of an equilateral triangle of the mesh's mean (non-zero) triangle area: its sampling
/// scale. 0 for a mesh with no area.
pub fn mean_edge(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> f64 {
    // Fixed chunks summed in order: the same sum whatever the thread count.
    let parts: Vec<(f64, usize)> = triangles
        .par_chunks(4096)
        .map(|chunk| {
            chunk.iter().fold((0.0, 0), |(sum, count), t| {
                let [a, b, c] = t.map(|i| positions[i as usize].map(|x| x as f64));
                let (u, v) = ([b[0] - a[0], b[1] - a[1], b[2] - a[2]], [c[0] - a[0], c[1] - a[1], c[2] - a[2]]);
                let area = 0.5 * norm([u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]);
                (sum + area, count + (area != 0.0) as usize)
            })
        })
        .collect();
    let (sum, count) = parts.iter().fold((0.0, 0), |x, y| (x.0 + y.0, x.1 + y.1));
    if count == 0 { 0.0 } else { (4.0 * sum / (3f64.sqrt() * count as f64)).sqrt() }
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measure::{face_adjacency, NO_FACE};

    /// A unit square of two triangles, split along its diagonal into two UV charts.
    fn square() -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        let p = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        (p, vec![[0, 1, 2], [3, 4, 5]])
    }

    #[test]
    fn split_keeps_each_side_of_a_seam() {
        let (p, t) = square();
        let adj = face_adjacency(&t, &[0, 0]);
        assert!(adj.iter().flatten().all(|&f| f == NO_FACE), "the diagonal is a seam: no crossing");
        let lod0 = Lod0 {
            positions: &p,
            triangles: &t,
            adjacency: &adj,
        };
        // The welded square (0, 1, 2, 3 = the far corner), unchanged; corners 0 and 2 are seamy.
        let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        let faces = [[0, 1, 2], [0, 2, 3]];
        let level = Level {
            points: &pts,
            faces: &faces,
            face_origin: &[0, 1],
            seamy: &[true, false, true, false],
            near: &[0, 0, 0, 1],
        };
        let s = split(&lod0, &level);
        // Plain vertices 1 and 3 first, then a copy of 0 and 2 per side: 6 vertices, like LOD 0.
        assert_eq!(s.positions.len(), 6);
        assert_eq!(s.triangles, vec![[2, 0, 3], [4, 5, 1]]);
        let src = Sources {
            triangles: &t,
            source: &s.source,
            bary: &s.bary,
        };
        let uv: Vec<[f32; 2]> = (0..6).map(|i| [i as f32, 0.0]).collect();
        let out = src.interpolate(&uv);
        // Each copy takes its own face's split vertex: 0 and 2 on face 0, 3 and 4 on face 1.
        assert_eq!(out.iter().map(|u| u[0]).collect::<Vec<_>>(), vec![1.0, 5.0, 0.0, 2.0, 3.0, 4.0]);
        assert_eq!(s.near, vec![1, 0, 1, 1], "vertices 0 and 2: the last corner's face");
    }

    #[test]
    fn collapses_are_followed() {
        // A fan of 4 triangles around vertex 0, plus a flap (4, 1, 5) over real vertices 0..=4.
        let faces = [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1], [4, 1, 5]];
        // 2 -> 1, then 1 -> 3 (a chain), then the flap tip 5 absorbs 4. Faces 0 and 1 degenerate,
        // as does the flap; (0, 3, 4) -> (0, 3, 5) and (0, 4, 1) -> (0, 5, 3) survive.
        let collapses = [[1, 2], [3, 1], [5, 4]];
        let out = [[0, 1, 2], [0, 2, 1]];
        let seamy = [false, true, false, false, true];
        let seams = [[1, 2], [2, 3], [4, 0], [3, 4]];
        let t = track_collapses(&faces, 4, &collapses, &out, &seamy, &seams).unwrap();
        assert_eq!(t.faces, vec![[0, 1, 2], [0, 2, 1]]);
        assert_eq!(t.kept, vec![2, 3]);
        assert_eq!(t.rows, vec![0, 1, 2]);
        assert_eq!(t.seamy, vec![false, true, true], "3 absorbed 1, the tip absorbed 4");
        assert_eq!(t.seams, vec![[0, 2], [1, 2]], "(1, 2) and (2, 3) merged away; (4, 0) -> (0, tip); (3, 4) -> (3, tip)");
        assert_eq!(t.survivor, vec![0, 3, 4], "the tip walks from vertex 4's spot");
        // A numbering fast-simplification did not produce is refused.
        assert!(track_collapses(&faces, 4, &collapses, &[[0, 2, 1], [0, 1, 2]], &seamy, &seams).is_err());
        assert!(track_collapses(&faces, 4, &[[1, 2], [2, 1]], &out, &seamy, &seams).is_err());
    }

    #[test]
    fn attribute_rules() {
        let t = [[0u32, 1, 2]];
        let bary = [[0.5, 0.25, 0.25], [0.0, 1.0, 0.0]];
        let src = Sources {
            triangles: &t,
            source: &[0, 0],
            bary: &bary,
        };
        // Opposite normals cancel at the first point: the dominant corner's normal is used.
        let n = src.normals(&[[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.0, 0.0, -1.0]]);
        assert_eq!(n, vec![[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]);
        // A tangent along the normal gets a perpendicular unit vector (normal x the least aligned
        // axis); w from the dominant corner.
        let tan = src.tangents(&[[0.0, 0.0, 1.0, -1.0], [0.0, 0.0, 1.0, 1.0], [0.0, 0.0, 1.0, 1.0]], &[[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]);
        assert_eq!(tan, vec![[0.0, 1.0, 0.0, -1.0], [0.0, 0.0, 1.0, 1.0]]);
        let c = src.colors(&[[255, 0, 1, 3], [0, 255, 1, 3], [0, 0, 1, 2]]);
        assert_eq!(c[0], [128, 64, 1, 3], "127.5 -> 128 (half to even), 63.75 -> 64, 2.75 -> 3");
        // Skin: joint 7 is on all three corners and wins; weights sum to 1; unused slots are 0.
        let j = [[7, 1, 0, 0], [7, 2, 0, 0], [7, 3, 0, 0]];
        let w = [[0.5, 0.5, 0.0, 0.0], [0.5, 0.5, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]];
        let (sj, sw) = src.skin(&j, &w);
        assert_eq!(sj[0], [7, 1, 2, 0]);
        assert!((sw[0].iter().sum::<f32>() - 1.0).abs() < 1e-6 && sw[0][3] == 0.0);
        assert!((sw[0][0] - 0.625).abs() < 1e-6 && (sw[0][1] - 0.25).abs() < 1e-6);
        assert_eq!((sj[1], sw[1]), ([7, 2, 0, 0], [0.5, 0.5, 0.0, 0.0]));
        // Morph deltas: positions blended; normal deltas blended and scaled like the normal, so
        // n + dn stays parallel to LOD 0's blended n + dn (here (0, 0, 1) blends to length 0.5).
        let morphs = Morphs { positions: vec![vec![[4.0, 0.0, 0.0], [0.0, 8.0, 0.0], [0.0, 0.0, 8.0]]], normals: vec![vec![[2.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]] };
        let normals0 = [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]];
        let out = morphs.carry(&src, Some(&normals0));
        assert_eq!(out.positions, vec![vec![[2.0, 2.0, 2.0], [0.0, 8.0, 0.0]]]);
        assert_eq!(out.normals, vec![vec![[2.0, 0.0, 0.0], [0.0, 0.0, 0.0]]], "(1, 0, 0) / 0.5");
        assert_eq!(src.normals(&normals0)[0], [0.0, 0.0, 1.0]);
        assert_eq!(out.morphed(&[[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]], 0), vec![[3.0, 3.0, 3.0], [0.0, 8.0, 0.0]]);
    }
}
