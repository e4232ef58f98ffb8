//! glTF meshes -> IR meshes: one LOD 0 per mesh with every primitive's triangles, each tagged
//! with its material.

use crate::accessor::{self, check, Checked};
use crate::ir::{LodIr, MeshIr};
use crate::label;
use gltf::mesh::{Mode, Semantic};
use pack::Vertex;

/// Per-vertex data beyond `Vertex` that deformation needs, parallel to a primitive's vertices.
#[derive(Default)]
struct Deform {
    /// JOINTS_0/JOINTS_1 and WEIGHTS_0/WEIGHTS_1 side by side (zeros where a set is absent).
    influences: Option<(Vec<[u16; 8]>, Vec<[f32; 8]>)>,
    morph_positions: Vec<Vec<[f32; 3]>>,
    morph_normals: Vec<Vec<[f32; 3]>>,
}

/// Import one glTF mesh. Primitives without a material use `default_material`. Fixes the import
/// made on its own (influences reduced to four) are pushed to `warnings`.
pub(crate) fn cook_mesh(mesh: &gltf::Mesh, buffers: &[Vec<u8>], default_material: u32, warnings: &mut Vec<String>, budget: &mut u64) -> Result<MeshIr, String> {
    let what = label("mesh", mesh.index(), mesh.name());
    let mut vertices: Vec<Vertex> = Vec::new();
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    let mut materials: Vec<u32> = Vec::new();
    let mut has_uv1 = false;
    let mut deform: Option<Deform> = None;
    for p in mesh.primitives() {
        let (v, i, d) = primitive(&p, buffers, budget).map_err(|e| format!("{what} primitive {}: {e}", p.index()))?;
        let all = deform.get_or_insert_with(|| Deform {
            influences: d.influences.as_ref().map(|_| (Vec::new(), Vec::new())),
            morph_positions: vec![Vec::new(); d.morph_positions.len()],
            morph_normals: vec![Vec::new(); d.morph_normals.len()],
        });
        if all.influences.is_some() != d.influences.is_some() || all.morph_positions.len() != d.morph_positions.len() || all.morph_normals.len() != d.morph_normals.len() {
            return Err(format!("{what} primitive {}: its skinning attributes or morph targets differ from the mesh's first primitive", p.index()));
        }
        if let (Some((aj, aw)), Some((j, w))) = (&mut all.influences, d.influences) {
            aj.extend(j);
            aw.extend(w);
        }
        for (a, m) in all.morph_positions.iter_mut().zip(d.morph_positions).chain(all.morph_normals.iter_mut().zip(d.morph_normals)) {
            a.extend(m);
        }
        has_uv1 |= p.get(&Semantic::TexCoords(1)).is_some();
        let base = u32::try_from(vertices.len())
            .ok()
            .filter(|b| b.checked_add(v.len() as u32).is_some() && v.len() <= u32::MAX as usize)
            .ok_or_else(|| format!("{what}: more than {} vertices", u32::MAX))?;
        let material = p.material().index().map_or(default_material, |m| m as u32);
        vertices.extend(v);
        for t in i.chunks_exact(3) {
            triangles.push([t[0] + base, t[1] + base, t[2] + base]);
            materials.push(material);
        }
    }
    let deform = deform.unwrap_or_default();
    let (joints, weights) = match deform.influences {
        None => (None, None),
        Some((j, w)) => {
            let (j, w, reduced) = crate::anim::reduce_influences(&j, &w).map_err(|e| format!("{what}: {e}"))?;
            if reduced > 0 {
                warnings.push(format!("{what}: {reduced} vertices had more than 4 joint influences; kept the 4 largest and renormalised"));
            }
            (Some(j), Some(w))
        }
    };
    let targets = deform.morph_positions.len();
    let morph_weights = match mesh.weights() {
        Some(w) if w.len() == targets => w.to_vec(),
        Some(w) => return Err(format!("{what}: {} default morph weights for {targets} morph targets", w.len())),
        None => vec![0.0; targets],
    };
    let lod = LodIr {
        positions: vertices.iter().map(|v| v.position).collect(),
        normals: Some(vertices.iter().map(|v| v.normal).collect()),
        tangents: Some(vertices.iter().map(|v| v.tangent).collect()),
        uv0: Some(vertices.iter().map(|v| v.uv0).collect()),
        texcoord1: has_uv1.then(|| vertices.iter().map(|v| v.texcoord1).collect()),
        colors: Some(vertices.iter().map(|v| v.color).collect()),
        joints,
        weights,
        triangles,
        materials,
        morph_positions: deform.morph_positions,
        morph_normals: deform.morph_normals,
        ..Default::default()
    };
    Ok(MeshIr { name: mesh.name().map_or_else(|| format!("mesh{}", mesh.index()), str::to_string), lods: vec![lod], morph_weights, uv_bounds: None })
}

/// An upper bound on the vertices one import may produce (counting each morph target's deltas as
/// vertices too). Accessors are bounded one by one (`accessor::MAX_ELEMENTS`), but a small file
/// can refer to one big accessor from thousands of primitives or morph targets, and a sparse
/// accessor declares its count freely; this keeps such a file from becoming a multi-gigabyte
/// allocation. 16M vertices are 1 GB as pack vertices. `cook_mesh` draws on it per primitive,
/// after the primitive's accessors are checked and before any of them is read.
pub(crate) const MAX_VERTICES: u64 = 1 << 24;

/// One primitive as vertices and a triangle list indexing them.
fn primitive(p: &gltf::Primitive, buffers: &[Vec<u8>], budget: &mut u64) -> Result<(Vec<Vertex>, Vec<u32>, Deform), String> {
    let mode = p.mode();
    if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
        return Err(format!("mode {mode:?} is not supported (only triangles, triangle strips and fans)"));
    }
    // Check every accessor before reading any of them.
    let pos_acc = p.get(&Semantic::Positions).ok_or("has no POSITION attribute")?;
    let pos = check(&pos_acc, buffers, "POSITION", &accessor::VEC3_F32)?;
    let n = pos.count;
    let attribute = |sem: Semantic, role: &str, expect| -> Result<Option<Checked>, String> {
        let Some(acc) = p.get(&sem) else { return Ok(None) };
        let c = check(&acc, buffers, role, expect)?;
        if c.count != n {
            return Err(format!("accessor {} ({role}) has {} elements but POSITION has {n}", acc.index(), c.count));
        }
        Ok(Some(c))
    };
    let normals = attribute(Semantic::Normals, "NORMAL", &accessor::VEC3_F32)?;
    let tangents = attribute(Semantic::Tangents, "TANGENT", &accessor::VEC4_F32)?;
    let uv0 = attribute(Semantic::TexCoords(0), "TEXCOORD_0", &accessor::TEXCOORD)?;
    let uv1 = attribute(Semantic::TexCoords(1), "TEXCOORD_1", &accessor::TEXCOORD)?;
    let colors = attribute(Semantic::Colors(0), "COLOR_0", &accessor::COLOR)?;
    let joints = [attribute(Semantic::Joints(0), "JOINTS_0", &accessor::JOINTS)?, attribute(Semantic::Joints(1), "JOINTS_1", &accessor::JOINTS)?];
    let weights = [attribute(Semantic::Weights(0), "WEIGHTS_0", &accessor::WEIGHTS)?, attribute(Semantic::Weights(1), "WEIGHTS_1", &accessor::WEIGHTS)?];
    for set in 0..2 {
        if joints[set].is_some() != weights[set].is_some() {
            return Err(format!("has only one of JOINTS_{set} and WEIGHTS_{set}"));
        }
    }
    let index_acc = p.indices();
    let checked_indices = match &index_acc {
        Some(acc) => Some(check(acc, buffers, "indices", &accessor::INDICES)?),
        None => None,
    };
    // Without normals the primitive is unwelded, a vertex per index.
    let corners = checked_indices.as_ref().map_or(n, |c| c.count).max(n) as u64;
    let need = corners.saturating_mul(1 + p.morph_targets().len() as u64);
    if need > *budget {
        let used = MAX_VERTICES - *budget;
        return Err(format!(
            "the meshes so far need {} vertices (each morph target's deltas counted as vertices), more than the cooker's limit of {MAX_VERTICES}",
            used.saturating_add(need)
        ));
    }
    *budget -= need;
    let mut morph_checked = Vec::new();
    for (t, target) in p.morph_targets().enumerate() {
        let get = |acc: Option<gltf::Accessor>, role: &str| -> Result<Option<Vec<[f32; 3]>>, String> {
            let Some(acc) = acc else { return Ok(None) };
            let c = check(&acc, buffers, &format!("morph target {t} {role}"), &accessor::VEC3_F32)?;
            if c.count != n {
                return Err(format!("morph target {t}: accessor {} ({role}) has {} elements but POSITION has {n}", acc.index(), c.count));
            }
            let d = c.vecs::<3>(0.0);
            if let Some(i) = d.iter().position(|d| !d.iter().all(|x| x.is_finite())) {
                return Err(format!("morph target {t}: {role} delta {i} is not a finite number"));
            }
            Ok(Some(d))
        };
        morph_checked.push((get(target.positions(), "POSITION")?, get(target.normals(), "NORMAL")?));
    }

    let positions = pos.vecs::<3>(0.0);
    if let Some(i) = positions.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(format!("accessor {} (POSITION) element {i} is not a finite number", pos_acc.index()));
    }
    let mut idx = match (&checked_indices, &index_acc) {
        (Some(c), Some(acc)) => {
            let idx = c.uints();
            if let Some(k) = idx.iter().position(|&i| i as usize >= n) {
                return Err(format!(
                    "accessor {} (indices) element {k} is {}, but there are only {n} vertices",
                    acc.index(),
                    idx[k]
                ));
            }
            idx
        }
        _ => (0..n as u32).collect(),
    };
    idx = triangle_list(mode, idx)?;

    let read = |c: &Option<Checked>, pad| c.as_ref().map(|c| c.vecs::<4>(pad));
    let (nrm, tan, col) = (normals.as_ref().map(|c| c.vecs::<3>(0.0)), read(&tangents, 0.0), read(&colors, 1.0));
    let (t0, t1) = (uv0.as_ref().map(|c| c.vecs::<2>(0.0)), uv1.as_ref().map(|c| c.vecs::<2>(0.0)));
    // NaN or infinity in any attribute would reach the LOD, lightmap UV and bake stages and the GPU.
    let finite = |role: &str, sem: Semantic, values: Option<Vec<&[f32]>>| -> Result<(), String> {
        let Some(values) = values else { return Ok(()) };
        match values.iter().position(|v| !v.iter().all(|x| x.is_finite())) {
            Some(i) => Err(format!("accessor {} ({role}) element {i} is not a finite number", p.get(&sem).map_or(0, |a| a.index()))),
            None => Ok(()),
        }
    };
    finite("NORMAL", Semantic::Normals, nrm.as_ref().map(|v| v.iter().map(|x| &x[..]).collect()))?;
    finite("TANGENT", Semantic::Tangents, tan.as_ref().map(|v| v.iter().map(|x| &x[..]).collect()))?;
    finite("TEXCOORD_0", Semantic::TexCoords(0), t0.as_ref().map(|v| v.iter().map(|x| &x[..]).collect()))?;
    finite("TEXCOORD_1", Semantic::TexCoords(1), t1.as_ref().map(|v| v.iter().map(|x| &x[..]).collect()))?;
    let mut vertices: Vec<Vertex> = (0..n)
        .map(|i| Vertex {
            position: positions[i],
            normal: nrm.as_ref().map_or([0.0, 0.0, 1.0], |v| v[i]),
            tangent: tan.as_ref().map_or([0.0; 4], |v| v[i]),
            uv0: t0.as_ref().map_or([0.0; 2], |v| v[i]),
            texcoord1: t1.as_ref().map_or([0.0; 2], |v| v[i]),
            color: col.as_ref().map_or([255; 4], |v| unorm8(v[i])),
            ..Default::default()
        })
        .collect();
    let influences = joints[0].as_ref().map(|_| {
        let sets: Vec<(Vec<[f32; 4]>, Vec<[f32; 4]>)> =
            joints.iter().zip(&weights).filter_map(|(j, w)| Some((j.as_ref()?.vecs::<4>(0.0), w.as_ref()?.vecs::<4>(0.0)))).collect();
        let mut jj = vec![[0u16; 8]; n];
        let mut ww = vec![[0f32; 8]; n];
        for (s, (j, w)) in sets.iter().enumerate() {
            for v in 0..n {
                for c in 0..4 {
                    jj[v][s * 4 + c] = j[v][c] as u16;
                    ww[v][s * 4 + c] = w[v][c];
                }
            }
        }
        (jj, ww)
    });
    // Without base normals there is nothing for normal deltas to move (normals are made flat).
    let any_normals = normals.is_some() && morph_checked.iter().any(|(_, nrm)| nrm.is_some());
    let mut deform = Deform {
        influences,
        morph_positions: morph_checked.iter().map(|(pos, _)| pos.clone().unwrap_or_else(|| vec![[0.0; 3]; n])).collect(),
        morph_normals: if any_normals { morph_checked.into_iter().map(|(_, nrm)| nrm.unwrap_or_else(|| vec![[0.0; 3]; n])).collect() } else { Vec::new() },
    };
    if normals.is_none() {
        let remap;
        (vertices, idx, remap) = flat_normals(&vertices, &idx);
        deform.follow(&remap);
    }
    if tangents.is_none() {
        match p.material().normal_texture() {
            // Normal-mapped: the tangents the map was baked against (split at UV seams).
            Some(t) => {
                let remap;
                (vertices, idx, remap) = crate::tangents::mikktspace(&vertices, &idx, t.tex_coord().min(1));
                deform.follow(&remap);
            }
            // Nothing reads them; any frame will do.
            None => {
                for v in &mut vertices {
                    v.tangent = crate::tangents::fallback(v.normal);
                }
            }
        }
    }
    Ok((vertices, idx, deform))
}

impl Deform {
    /// The deformation data of vertices that were copied: `remap[i]` is the vertex the new
    /// vertex `i` copies.
    fn follow(&mut self, remap: &[u32]) {
        if let Some((j, w)) = &mut self.influences {
            *j = remap.iter().map(|&i| j[i as usize]).collect();
            *w = remap.iter().map(|&i| w[i as usize]).collect();
        }
        for d in self.morph_positions.iter_mut().chain(&mut self.morph_normals) {
            *d = remap.iter().map(|&i| d[i as usize]).collect();
        }
    }
}

/// Strips and fans as the equivalent list, with the winding glTF specifies.
fn triangle_list(mode: Mode, idx: Vec<u32>) -> Result<Vec<u32>, String> {
    let n = idx.len();
    Ok(match mode {
        Mode::TriangleStrip => (0..n.saturating_sub(2))
            .flat_map(|i| if i % 2 == 0 { [idx[i], idx[i + 1], idx[i + 2]] } else { [idx[i + 1], idx[i], idx[i + 2]] })
            .collect(),
        Mode::TriangleFan => (1..n.saturating_sub(1)).flat_map(|i| [idx[i], idx[i + 1], idx[0]]).collect(),
        _ if n % 3 != 0 => return Err(format!("{n} indices do not make whole triangles")),
        _ => idx,
    })
}

/// glTF: "When normals are not specified, client implementations MUST calculate flat normals."
/// Flat shading needs a vertex per triangle corner, so the primitive is unwelded.
/// Also returns, per output vertex, the input vertex it copies.
fn flat_normals(vertices: &[Vertex], idx: &[u32]) -> (Vec<Vertex>, Vec<u32>, Vec<u32>) {
    let mut out = Vec::with_capacity(idx.len());
    for t in idx.chunks_exact(3) {
        let [a, b, c] = [0, 1, 2].map(|k| vertices[t[k] as usize].position);
        let n = normalize(cross(sub(b, a), sub(c, a))).unwrap_or([0.0, 0.0, 1.0]);
        out.extend(t.iter().map(|&i| Vertex { normal: n, ..vertices[i as usize] }));
    }
    let remap = idx[..out.len()].to_vec();
    let idx = (0..out.len() as u32).collect();
    (out, idx, remap)
}

/// glTF vertex colours are linear already; only the storage changes.
fn unorm8(c: [f32; 4]) -> [u8; 4] {
    c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
fn normalize(v: [f32; 3]) -> Option<[f32; 3]> {
    let len = dot(v, v).sqrt();
    (len > 1e-12 && len.is_finite()).then(|| v.map(|c| c / len))
}
