//! The boids scenario's bird: the demo's dove (content/birds/make_dove.py) as a mesh built here,
//! so the scenario needs no cooked content and draws the same 11 flat-shaded triangles per boid
//! as the demo level's flock.

use glam::Vec3;
use pack::{Material, Mesh, MeshLod, PackBuilder, Submesh, Vertex};

/// Append the bird (facing +Z, up +Y, 0.55 m long, 0.9 m span; no node: the flock draws it),
/// its material and a boids spawn naming it (as the cooker writes them) to `b`; returns its
/// mesh index.
pub fn push_bird(b: &mut PackBuilder) -> u32 {
    let v = Vec3::new;
    let (nose, tail, top, bottom, left, right) = (v(0.0, 0.0, 0.3), v(0.0, 0.0, -0.2), v(0.0, 0.06, 0.0), v(0.0, -0.05, 0.0), v(-0.06, 0.0, 0.0), v(0.06, 0.0, 0.0));
    let mut tris = Vec::new();
    for (a, c) in [(right, top), (top, left), (left, bottom), (bottom, right)] {
        tris.push([nose, a, c]);
        tris.push([tail, c, a]);
    }
    tris.push([v(0.04, 0.0, 0.1), v(0.45, 0.06, -0.08), v(0.04, 0.0, -0.1)]);
    tris.push([v(-0.04, 0.0, 0.1), v(-0.04, 0.0, -0.1), v(-0.45, 0.06, -0.08)]);
    tris.push([v(0.0, 0.0, -0.15), v(-0.1, 0.0, -0.25), v(0.1, 0.0, -0.25)]);
    let mut verts = Vec::new();
    let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
    for [a, c, d] in tris {
        let n = (c - a).cross(d - a).normalize_or(Vec3::Y);
        for p in [a, c, d] {
            (lo, hi) = (lo.min(p), hi.max(p));
            verts.push(Vertex { position: p.to_array(), normal: n.to_array(), tangent: [1.0, 0.0, 0.0, 1.0], color: [255; 4], ..Default::default() });
        }
    }
    let count = verts.len() as u32;
    let idx: Vec<u32> = (0..count).collect();
    let (vertices, uv_ranges) = b.push_vertices(&verts);
    let index_format = pack::IndexFormat::for_vertices(verts.len());
    let indices = b.push_bytes(&index_format.encode(&idx));
    let material = b.manifest.materials.len() as u32;
    b.manifest.materials.push(Material { name: "dove feathers".into(), base_color: [0.85, 0.85, 0.82, 1.0], double_sided: true, ..Default::default() });
    b.manifest.meshes.push(Mesh {
        name: "dove".into(),
        lods: vec![MeshLod { vertices, uv_ranges, vertex_count: count, indices, index_count: count, index_format, submeshes: vec![Submesh { first_index: 0, index_count: count, material, lightmap_block: None }], error: 0.0 }],
        bounds_min: lo.to_array(),
        bounds_max: hi.to_array(),
    });
    let mesh = b.manifest.meshes.len() as u32 - 1;
    b.manifest.spawns.push(pack::Spawn { name: "flock".into(), kind: "boids".into(), position: [0.0; 3], rotation: [0.0, 0.0, 0.0, 1.0], params: serde_json::json!({ "mesh": mesh }) });
    mesh
}
