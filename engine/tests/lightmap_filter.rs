//! Bicubic lightmap sampling (issue 22; `Renderer::bicubic_lightmaps`), on the real device with
//! validation: across a baked shadow's edge, magnified, the cubic B-spline's largest step
//! between neighbouring pixels is smaller than bilinear's, and neither rings past the levels on
//! either side (no light below the shadow's, none above the lit side's).

use engine::render::renderer::Lighting;
use glam::Mat4;
use pack::{Material, Pack, PackBuilder, TextureFormat};

mod common;
use common::frames::{looking_down_neg_z, pixel, tone_mapped_bytes, Rig};
use common::packs::{half_bits, push_mesh, quad_vertices, static_node, texture};
use common::{assert_clean, gpu};

const SIZE: u32 = 128;
const TEXELS: u32 = 16;
const DARK: f32 = 50.0;
const LIT: f32 = 1000.0;

/// A white static quad facing +Z whose lightmap page (16x16, the quad's whole uv1) is DARK on
/// the left half and LIT on the right: a baked shadow's edge down the middle.
fn edge_pack() -> Pack {
    let mut b = PackBuilder::new("generated", "test");
    let (verts, idx) = quad_vertices();
    let mesh = push_mesh(&mut b, "wall", &verts, &idx, Some(0));
    b.manifest.materials.push(Material { base_color: [1.0; 4], roughness: 1.0, ..Material::default() });
    b.manifest.nodes.push(static_node("wall", Mat4::IDENTITY, mesh, 0));
    let texels: Vec<u8> = (0..TEXELS * TEXELS)
        .flat_map(|i| {
            let v = if i % TEXELS < TEXELS / 2 { DARK } else { LIT };
            [v, v, v, 1.0].map(half_bits)
        })
        .flat_map(u16::to_le_bytes)
        .collect();
    let page = texture(&mut b, "lightmap0", TextureFormat::Rgba16Float, [TEXELS, TEXELS], &[&texels]);
    b.manifest.lightmap = Some(pack::LightmapLayout { texels_per_metre: 16.0, pages: vec![[TEXELS, TEXELS]], padding: 2, textures: vec![page], directions: vec![], log_average: None, samples: None });
    b.finish()
}

/// The middle row's red bytes, the quad filling the frame, and the exposure.
fn middle_row(bicubic: bool) -> (Vec<u8>, f32) {
    let gpu = gpu();
    let pack = edge_pack();
    let mut rig = Rig::new(&gpu, &pack, SIZE, SIZE);
    (rig.renderer.bicubic_lightmaps, rig.renderer.specular, rig.renderer.tonemap.saturation) = (bicubic, false, 1.0);
    // 0.8 from a 60-degree camera the view is 0.92 wide: the unit quad fills it.
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &looking_down_neg_z(0.8), &Lighting::default(), true).unwrap();
    let row = (0..SIZE).map(|x| pixel(rig.target.pixels(), SIZE, x, SIZE / 2)[0]).collect();
    let exposure = rig.scene.baked.unwrap().exposure;
    rig.destroy(&gpu);
    assert_clean(&gpu);
    (row, exposure)
}

#[test]
fn bicubic_lightmaps_soften_a_shadow_edge_without_ringing() {
    let (bilinear, exposure) = middle_row(false);
    let (bicubic, _) = middle_row(true);
    let max_step = |row: &[u8]| row.windows(2).map(|w| (w[1] as i32 - w[0] as i32).abs()).max().unwrap();
    let (dark, lit) = (tone_mapped_bytes([DARK; 3], exposure, 1.0)[0], tone_mapped_bytes([LIT; 3], exposure, 1.0)[0]);
    eprintln!("dark {dark}, lit {lit}; largest step: bilinear {}, bicubic {}", max_step(&bilinear), max_step(&bicubic));
    eprintln!("bilinear {bilinear:?}\nbicubic  {bicubic:?}");
    // Far from the edge both read the flat levels.
    for row in [&bilinear, &bicubic] {
        assert_eq!((row[2], row[SIZE as usize - 3]), (dark, lit));
        // No ringing: nothing darker than the shadow or brighter than the lit side.
        assert!(row.iter().all(|&v| (dark..=lit).contains(&v)), "{row:?} leaves [{dark}, {lit}]");
    }
    assert!(max_step(&bicubic) < max_step(&bilinear), "bicubic's largest step {} is not below bilinear's {}", max_step(&bicubic), max_step(&bilinear));
}
