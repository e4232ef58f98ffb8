//! Scene IR -> pack: interleave vertices into the GPU layout, group triangles into submeshes,
//! store indices 16-bit where they fit, and lay out the data blob.

use crate::ir::{LodIr, SceneIr};
use pack::{IndexFormat, Mesh, MeshLod, Pack, PackBuilder, Submesh, UvBounds, UvRanges, Vertex};

/// Build the pack for a scene. Errors name the object that is inconsistent.
pub fn build_pack(scene: &SceneIr, cooker: &str) -> Result<Pack, String> {
    let mut b = PackBuilder::new(&scene.source, cooker);
    for t in &scene.textures {
        let mips = t.mips.iter().map(|m| b.push_bytes(m)).collect();
        b.manifest.textures.push(pack::Texture { name: t.name.clone(), width: t.width, height: t.height, format: t.format, mips, sampler: t.sampler });
    }
    for (i, mesh) in scene.meshes.iter().enumerate() {
        let what = format!("mesh {i} '{}'", mesh.name);
        let Some(base) = mesh.lods.first() else { return Err(format!("{what}: no LODs")) };
        let (bounds_min, bounds_max) = bounds(&base.positions);
        for (l, lod) in mesh.lods.iter().enumerate() {
            lod.validate(&format!("{what} LOD {l}"))?;
        }
        // Every LOD's texture coordinates over one set of ranges (the mesh's, and its whole
        // mesh's for a chunk): a vertex two LODs or two chunks share is stored alike.
        let vertices: Vec<Vec<Vertex>> = mesh.lods.iter().map(lod_vertices).collect();
        let bounds = vertices.iter().fold(mesh.uv_bounds.unwrap_or(UvBounds::EMPTY), |acc, v| acc.union(&UvBounds::of(v)));
        let ranges = UvRanges::from_bounds(&bounds);
        let mut lods = Vec::with_capacity(mesh.lods.len());
        for (l, (lod, v)) in mesh.lods.iter().zip(&vertices).enumerate() {
            lods.push(write_lod(lod, v, &ranges, &mut b).map_err(|e| format!("{what} LOD {l}: {e}"))?);
        }
        b.manifest.meshes.push(Mesh { name: mesh.name.clone(), lods, bounds_min, bounds_max });
        write_deform(i as u32, mesh, &mut b);
    }
    scene.check_animation()?;
    write_animation(scene, &mut b);
    b.manifest.materials = scene.materials.clone();
    b.manifest.nodes = scene.nodes.clone();
    b.manifest.lights = scene.lights.clone();
    b.manifest.spawns = scene.spawns.clone();
    b.manifest.pillars = scene.pillars.clone();
    b.manifest.sky = scene.sky;
    b.manifest.lightmap = scene.lightmap.clone();
    if let Some(p) = &scene.probes {
        let sh: Vec<u8> = p.sh.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
        let vis: Vec<u8> = p.sun_visibility.iter().flat_map(|v| v.to_le_bytes()).collect();
        let (sh, sun_visibility) = (b.push_bytes(&sh), b.push_bytes(&vis));
        b.manifest.probes = Some(pack::ProbeGrid { origin: p.origin, spacing: p.spacing, counts: p.counts, sh, sun_visibility });
    }
    if let Some(rp) = &scene.reflection_probes {
        let probes = rp.probes.iter().map(|(p, bytes)| pack::ReflectionProbe { data: b.push_bytes(bytes), ..p.clone() }).collect();
        b.manifest.reflection_probes = Some(pack::ReflectionProbes { face_size: rp.face_size, levels: rp.levels, format: rp.format, probes });
    }
    let pack = b.finish();
    // The pack crate's own consistency check, so a cooker bug is caught here and not at load.
    pack.manifest.validate(pack.data.len() as u64).map_err(|e| e.to_string())?;
    Ok(pack)
}

fn f32_bytes<'a>(v: impl IntoIterator<Item = &'a f32>) -> Vec<u8> {
    v.into_iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// Joints/weights and morph deltas of a mesh that deforms, in the layouts `pack::DeformLod` names.
fn write_deform(index: u32, mesh: &crate::ir::MeshIr, b: &mut PackBuilder) {
    let deforms = mesh.lods.iter().any(|l| l.joints.is_some() || !l.morph_positions.is_empty());
    if !deforms {
        return;
    }
    let lods = mesh
        .lods
        .iter()
        .map(|lod| {
            let skin = match (&lod.joints, &lod.weights) {
                (Some(j), Some(w)) => {
                    let jb: Vec<u8> = j.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
                    Some(pack::SkinWeights { joints: b.push_bytes(&jb), weights: b.push_bytes(&f32_bytes(w.iter().flatten())) })
                }
                _ => None,
            };
            let morph = (!lod.morph_positions.is_empty()).then(|| pack::MorphTargets {
                positions: b.push_bytes(&f32_bytes(lod.morph_positions.iter().flatten().flatten())),
                normals: (!lod.morph_normals.is_empty()).then(|| b.push_bytes(&f32_bytes(lod.morph_normals.iter().flatten().flatten()))),
            });
            pack::DeformLod { skin, morph }
        })
        .collect();
    b.manifest.animation.meshes.push(pack::DeformMesh { mesh: index, morph_weights: mesh.morph_weights.clone(), lods });
}

/// Skins, node bindings and clips (already checked by `SceneIr::check_animation`).
fn write_animation(scene: &SceneIr, b: &mut PackBuilder) {
    for s in &scene.skins {
        let inverse_bind = b.push_bytes(&f32_bytes(s.inverse_bind.iter().flatten()));
        b.manifest.animation.skins.push(pack::Skin { name: s.name.clone(), joints: s.joints.clone(), inverse_bind });
    }
    b.manifest.animation.nodes = scene.bindings.clone();
    for clip in &scene.clips {
        let channels: Vec<pack::Channel> = clip
            .channels
            .iter()
            .map(|c| pack::Channel {
                node: c.node,
                path: c.path,
                interpolation: c.interpolation,
                key_count: c.times.len() as u32,
                components: c.components,
                times: b.push_bytes(&f32_bytes(&c.times)),
                values: b.push_bytes(&f32_bytes(&c.values)),
            })
            .collect();
        let duration = clip.channels.iter().filter_map(|c| c.times.last().copied()).fold(0.0f32, f32::max);
        b.manifest.animation.clips.push(pack::Clip { name: clip.name.clone(), duration, channels });
    }
}

fn bounds(positions: &[[f32; 3]]) -> ([f32; 3], [f32; 3]) {
    if positions.is_empty() {
        return ([0.0; 3], [0.0; 3]);
    }
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for p in positions {
        for c in 0..3 {
            lo[c] = lo[c].min(p[c]);
            hi[c] = hi[c].max(p[c]);
        }
    }
    (lo, hi)
}

/// A LOD's vertices, decoded form (absent attributes get their defaults).
fn lod_vertices(lod: &LodIr) -> Vec<Vertex> {
    let n = lod.positions.len();
    (0..n)
        .map(|i| Vertex {
            position: lod.positions[i],
            normal: lod.normals.as_ref().map_or([0.0, 0.0, 1.0], |v| v[i]),
            tangent: lod.tangents.as_ref().map_or([1.0, 0.0, 0.0, 1.0], |v| v[i]),
            uv0: lod.uv0.as_ref().map_or([0.0; 2], |v| v[i]),
            uv1: lod.uv1.as_ref().map_or([0.0; 2], |v| v[i]),
            texcoord1: lod.texcoord1.as_ref().map_or([0.0; 2], |v| v[i]),
            color: lod.colors.as_ref().map_or([255; 4], |v| v[i]),
            _pad: [0; 3],
        })
        .collect()
}

fn write_lod(lod: &LodIr, vertices: &[Vertex], ranges: &UvRanges, b: &mut PackBuilder) -> Result<MeshLod, String> {
    let n = vertices.len();
    // One submesh per (material, lightmap block); a stable sort keeps the authored triangle order
    // within each, which keeps the output deterministic.
    let key = |t: usize| (lod.materials[t], lod.lightmap_blocks.as_ref().map(|p| p[t]));
    let mut order: Vec<usize> = (0..lod.triangles.len()).collect();
    order.sort_by_key(|&t| key(t));
    let mut indices: Vec<u32> = Vec::with_capacity(order.len() * 3);
    let mut submeshes: Vec<Submesh> = Vec::new();
    for &t in &order {
        let (material, lightmap_block) = key(t);
        match submeshes.last_mut() {
            Some(s) if s.material == material && s.lightmap_block == lightmap_block => s.index_count += 3,
            _ => submeshes.push(Submesh { first_index: indices.len() as u32, index_count: 3, material, lightmap_block }),
        }
        indices.extend_from_slice(&lod.triangles[t]);
    }
    let too_big = || format!("more than {} vertices or indices", u32::MAX);
    let vertex_count = u32::try_from(n).map_err(|_| too_big())?;
    let index_count = u32::try_from(indices.len()).map_err(|_| too_big())?;
    let index_format = IndexFormat::for_vertices(n);
    Ok(MeshLod {
        vertices: b.push_bytes(&pack::encode_vertices_with(vertices, ranges)),
        uv_ranges: *ranges,
        vertex_count,
        indices: b.push_bytes(&index_format.encode(&indices)),
        index_count,
        index_format,
        submeshes,
        error: lod.error,
    })
}
