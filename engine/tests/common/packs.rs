//! Building packs in code: meshes, instances (dynamic, or static with a lightmap region),
//! textures, lightmap pages and probe grids, as the cooker would write them.

use glam::{Mat4, Vec3};
use pack::{LightmapRegion, Mesh, MeshLod, Node, PackBuilder, Submesh, Texture, TextureFormat, Vertex};

/// Append a one-LOD mesh of `verts` and `idx` (one submesh, material 0, in `lightmap_block`)
/// with bounds from its vertices; returns its mesh index.
pub fn push_mesh(b: &mut PackBuilder, name: &str, verts: &[Vertex], idx: &[u32], lightmap_block: Option<u32>) -> u32 {
    let (vertices, uv_ranges) = b.push_vertices(verts);
    let index_format = pack::IndexFormat::for_vertices(verts.len());
    let indices = b.push_bytes(&index_format.encode(idx));
    let (lo, hi) = verts.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), v| (lo.min(Vec3::from(v.position)), hi.max(Vec3::from(v.position))));
    let count = idx.len() as u32;
    b.manifest.meshes.push(Mesh {
        name: name.into(),
        lods: vec![MeshLod { vertices, uv_ranges, vertex_count: verts.len() as u32, indices, index_count: count, index_format, submeshes: vec![Submesh { first_index: 0, index_count: count, material: 0, lightmap_block }], error: 0.0 }],
        bounds_min: lo.to_array(),
        bounds_max: hi.to_array(),
    });
    b.manifest.meshes.len() as u32 - 1
}

/// A dynamic instance of `mesh` placed by `local`.
pub fn node(name: &str, local: Mat4, mesh: u32) -> Node {
    Node { name: name.into(), local: local.to_cols_array(), mesh: Some(mesh), ..Default::default() }
}

/// A static instance of `mesh` placed by `local` whose lightmap region is the whole of page
/// `page` (the mesh's uv1 as they are).
pub fn static_node(name: &str, local: Mat4, mesh: u32, page: u32) -> Node {
    Node { is_static: true, lightmap: Some(LightmapRegion { page, scale: [1.0; 2], offset: [0.0; 2] }), ..node(name, local, mesh) }
}

/// A texture of `format` with the given levels (level 0 first), repeating and trilinear.
pub fn texture(b: &mut PackBuilder, name: &str, format: TextureFormat, [width, height]: [u32; 2], levels: &[&[u8]]) -> u32 {
    let mips = levels.iter().map(|l| b.push_bytes(l)).collect();
    b.manifest.textures.push(Texture { name: name.into(), width, height, format, mips, sampler: Default::default() });
    b.manifest.textures.len() as u32 - 1
}

/// f32 -> IEEE half bits (the `half` crate, as the cooker's pages are written).
pub fn half_bits(v: f32) -> u16 {
    half::f16::from_f32(v).to_bits()
}

/// A 2x2x2 probe grid over [-2, 2]^3 whose every probe sees the constant `radiance` (SH band 0
/// only: L0 = radiance / Y00) and the sun with visibility `sun_visibility`.
pub fn push_uniform_probes(b: &mut PackBuilder, radiance: f32, sun_visibility: f32) {
    let mut sh = Vec::new();
    for _ in 0..8 {
        let mut probe = [0.0f32; 27];
        probe[..3].copy_from_slice(&[radiance / 0.282_094_8; 3]);
        sh.extend(probe.iter().flat_map(|v| v.to_le_bytes()));
    }
    let sh = b.push_bytes(&sh);
    let vis = b.push_bytes(&[sun_visibility; 8].iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>());
    b.manifest.probes = Some(pack::ProbeGrid { origin: [-2.0; 3], spacing: [4.0; 3], counts: [2, 2, 2], sh, sun_visibility: vis });
}

/// A unit quad in the z = 0 plane facing +Z (counter-clockwise seen from +Z), uv1 over [0, 1].
pub fn quad_vertices() -> (Vec<Vertex>, Vec<u32>) {
    let v = [(-0.5f32, -0.5f32), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)]
        .iter()
        .map(|&(x, y)| Vertex { position: [x, y, 0.0], normal: [0.0, 0.0, 1.0], tangent: [1.0, 0.0, 0.0, 1.0], uv0: [0.5, 0.5], uv1: [x + 0.5, 0.5 - y], color: [255; 4], ..Default::default() })
        .collect();
    (v, vec![0, 1, 2, 0, 2, 3])
}

/// A uniform 4x4 lightmap page of B = `b` nits as the pack's only page: the pack is then baked
/// (physical lighting, tone-mapped) with auto exposure 0.18 / (1e-4 + 0.5 b).
pub fn add_lightmap_page(bld: &mut PackBuilder, b: f32) {
    add_lightmap_pages(bld, &[[[b; 4]; 4]]);
}

/// 4x4 lightmap pages of B (nits, grey; rows top to bottom) as the pack's pages.
pub fn add_lightmap_pages(bld: &mut PackBuilder, pages: &[[[f32; 4]; 4]]) {
    let mut textures = Vec::new();
    for (p, page) in pages.iter().enumerate() {
        let texels: Vec<u8> = page.iter().flatten().flat_map(|&b| [half_bits(b), half_bits(b), half_bits(b), half_bits(1.0)]).flat_map(u16::to_le_bytes).collect();
        textures.push(texture(bld, &format!("lightmap{p}"), TextureFormat::Rgba16Float, [4, 4], &[&texels]));
    }
    bld.manifest.lightmap = Some(pack::LightmapLayout { texels_per_metre: 2.0, pages: vec![[4, 4]; pages.len()], padding: 2, textures, directions: vec![], log_average: None, samples: None });
}

/// A sun of `lux` (perpendicular illuminance, white) shining toward -`towards_sun`, with
/// `angular_radius` (radians; 0: a point).
pub fn sun(lux: f32, towards_sun: Vec3, angular_radius: f32) -> pack::Light {
    pack::Light {
        name: "sun".into(),
        kind: pack::LightKind::Sun,
        color: [1.0; 3],
        intensity: lux,
        position: [0.0; 3],
        direction: (-towards_sun.normalize()).to_array(),
        range: None,
        inner_cone: 0.0,
        outer_cone: 0.0,
        size: [0.0; 2],
        angular_radius,
    }
}

/// Make the pack baked (physical lighting, exposure 0.18 / (1e-4 + 0.5 b)): a uniform lightmap
/// page of B = `b` on a static quad at `at`, out of the way, in a default material of its own.
pub fn add_baked_light(bld: &mut PackBuilder, b: f32, at: Vec3) {
    let (verts, idx) = quad_vertices();
    let material = bld.manifest.materials.len() as u32;
    bld.manifest.materials.push(pack::Material::default());
    let quad = push_mesh(bld, "lightmapped", &verts, &idx, Some(0));
    bld.manifest.meshes[quad as usize].lods[0].submeshes[0].material = material;
    add_lightmap_page(bld, b);
    bld.manifest.nodes.push(static_node("lightmapped", Mat4::from_translation(at), quad, 0));
}
