//! Scenes built in code that several GPU test files draw (cubes, screen-filling triangles, a
//! textured mesh).

use glam::{Mat4, Vec3};
use pack::{Material, Pack, PackBuilder, TextureFormat, Vertex};

use super::packs::{node, push_mesh, texture};

/// An axis-aligned unit cube centred on the origin with per-face normals (so lighting tells the
/// faces apart) and each face's uv (0,0) at its top-left corner.
pub fn cube_vertices() -> (Vec<Vertex>, Vec<u32>) {
    let faces: [(Vec3, Vec3, Vec3); 6] = [
        (Vec3::X, Vec3::NEG_Z, Vec3::Y),
        (Vec3::NEG_X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::X, Vec3::NEG_Z),
        (Vec3::NEG_Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (Vec3::NEG_Z, Vec3::NEG_X, Vec3::Y),
    ];
    let mut v = Vec::new();
    let mut idx = Vec::new();
    for (n, u, w) in faces {
        let base = v.len() as u32;
        for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            let p = (n + u * a + w * b) * 0.5;
            v.push(Vertex {
                position: p.to_array(),
                normal: n.to_array(),
                tangent: [u.x, u.y, u.z, 1.0],
                uv0: [(a + 1.0) * 0.5, (1.0 - b) * 0.5],
                color: [255; 4],
                ..Default::default()
            });
        }
        // Counter-clockwise seen from outside (u x w = n).
        idx.extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    (v, idx)
}

/// A pack with one cube mesh placed at each of `placements`, textured with a 2x2 checker of
/// `colors` (sRGB bytes).
pub fn cube_pack(placements: &[Mat4], colors: [[u8; 4]; 4], material: Material) -> Pack {
    cube_builder(placements, colors, material).finish()
}

/// `cube_pack`, still open for more.
pub fn cube_builder(placements: &[Mat4], colors: [[u8; 4]; 4], material: Material) -> PackBuilder {
    let mut b = PackBuilder::new("generated", "test");
    let (verts, idx) = cube_vertices();
    push_mesh(&mut b, "cube", &verts, &idx, None);
    let texels: Vec<u8> = colors.iter().flatten().copied().collect();
    let checker = texture(&mut b, "checker", TextureFormat::Rgba8Srgb, [2, 2], &[&texels]);
    b.manifest.materials.push(Material { base_color_texture: Some(checker), ..material });
    for (i, m) in placements.iter().enumerate() {
        b.manifest.nodes.push(node(&format!("cube{i}"), *m, 0));
    }
    b
}

pub const WHITE4: [[u8; 4]; 4] = [[255; 4]; 4];

/// A pack of one triangle per entry of `depths`, at z = -depth facing +Z, big enough to cover the
/// whole view of a 60 degree camera at the origin with its edges off screen (so no pixel is
/// shaded twice along an interior edge, and no helper invocation lands on screen), in that order.
pub fn screen_triangles_pack(depths: &[f32]) -> Pack {
    let mut b = PackBuilder::new("generated", "test");
    let verts: Vec<Vertex> = [(-1.0f32, -1.0f32), (3.0, -1.0), (-1.0, 3.0)]
        .iter()
        .map(|&(x, y)| Vertex { position: [x, y, 0.0], normal: [0.0, 0.0, 1.0], tangent: [1.0, 0.0, 0.0, 1.0], uv0: [0.5, 0.5], color: [255; 4], ..Default::default() })
        .collect();
    push_mesh(&mut b, "triangle", &verts, &[0, 1, 2], None);
    b.manifest.materials.push(Material::default());
    for (i, d) in depths.iter().enumerate() {
        // Centred on the view axis: the triangle's inscribed centre is at (1/3, 1/3).
        let m = Mat4::from_translation(Vec3::new(0.0, 0.0, -d)) * Mat4::from_scale(Vec3::splat(4.0 * d)) * Mat4::from_translation(Vec3::new(-1.0 / 3.0, -1.0 / 3.0, 0.0));
        b.manifest.nodes.push(node(&format!("t{i}"), m, 0));
    }
    b.finish()
}

/// A pack with one mesh (`verts`, `idx`) at the origin and one texture of `format` with the
/// given levels (level 0 first, tightly packed RGBA8).
pub fn mesh_pack(verts: &[Vertex], idx: &[u32], format: TextureFormat, size: u32, levels: &[Vec<u8>], material: Material) -> Pack {
    let mut b = PackBuilder::new("generated", "test");
    push_mesh(&mut b, "mesh", verts, idx, None);
    let levels: Vec<&[u8]> = levels.iter().map(|l| l.as_slice()).collect();
    let t = texture(&mut b, "tex", format, [size, size], &levels);
    b.manifest.materials.push(Material { base_color_texture: Some(t), ..material });
    b.manifest.nodes.push(node("mesh", Mat4::IDENTITY, 0));
    b.finish()
}
