//! Step 4 of the LOD stage (`asset_pipeline.lod`, whose docstring is the full story): give a
//! simplified, position-welded level its split vertices and attributes by walking over LOD 0.
//!
//! [`split`] walks each output corner from the LOD 0 face it descends from toward its (moved)
//! position, staying in the region of continuous attributes (across `adjacency` only), and merges
//! corners that reach the same point of LOD 0 into one output vertex; a vertex with no seam among
//! its merged LOD 0 vertices is walked once. The attribute functions then interpolate LOD 0's
//! values at those points: plain barycentric blends, renormalised normals, re-orthonormalised
//! tangents, rounded colours, per-joint blended skin weights.
//!
//! Everything is deterministic (parallel work writes fixed slots; merging runs in corner order).

use crate::measure::{self, FxMap, CHUNK};
use rayon::prelude::*;

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
    }
}
