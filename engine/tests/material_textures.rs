//! Material textures on the real Vulkan device (lavapipe in CI) with validation on: a texture
//! slot reads the UV set its `tex_coord` names through its KHR_texture_transform, the emissive
//! texture scales the emission, and every texture is sampled with its own sampler state (wrap,
//! filters, mip levels). Scenes are built in code; pixels are checked against values computed
//! here.

use engine::gpu::Gpu;
use engine::render::renderer::Lighting;
use glam::Vec3;
use pack::{AlphaMode, Filter, Material, Pack, PackBuilder, Sampler, TextureFormat, TextureTransform, Vertex, Wrap};

mod common;
use common::frames::{assert_bytes_near, auto_exposure, looking_down_neg_z, pixel, render, screen_pixel, srgb_decode, srgb_encode, tone_mapped_bytes, Rig};
use common::packs::{add_lightmap_page, node, push_mesh, texture};
use common::{assert_clean, gpu};

const RED: [u8; 4] = [255, 0, 0, 255];
const GREEN: [u8; 4] = [0, 255, 0, 255];

/// Unfiltered, level 0 only, repeating: a pixel shows one texel exactly.
const NEAREST: Sampler = Sampler { wrap_s: Wrap::Repeat, wrap_t: Wrap::Repeat, mag_filter: Filter::Nearest, min_filter: Filter::Nearest, mipmap_filter: None };

/// A pack of unit quads facing +Z at z = 0 side by side along x, 1.1 m apart and centred on
/// x = 0, quad i in material i. Each quad's uv0 run from `u_range[0]` at its left edge to
/// `u_range[1]` at its right, v from 0 at the top to 1 at the bottom; its texcoord1 are
/// (1 - s, v) for s its position from left (0) to right (1), TEXCOORD_1 mirrored.
struct Quads {
    builder: PackBuilder,
    count: usize,
    u_range: [f32; 2],
}

impl Quads {
    fn new(materials: Vec<Material>, u_range: [f32; 2]) -> Quads {
        let mut builder = PackBuilder::new("generated", "test");
        let count = materials.len();
        builder.manifest.materials = materials;
        let verts: Vec<Vertex> = [(0.0f32, 1.0f32), (1.0, 1.0), (1.0, 0.0), (0.0, 0.0)]
            .iter()
            .map(|&(s, v)| Vertex {
                position: [s - 0.5, 0.5 - v, 0.0],
                normal: [0.0, 0.0, 1.0],
                tangent: [1.0, 0.0, 0.0, 1.0],
                uv0: [u_range[0] + s * (u_range[1] - u_range[0]), v],
                texcoord1: [1.0 - s, v],
                color: [255; 4],
                ..Default::default()
            })
            .collect();
        for i in 0..count {
            let mesh = push_mesh(&mut builder, &format!("quad{i}"), &verts, &[0, 1, 2, 0, 2, 3], None);
            builder.manifest.meshes[mesh as usize].lods[0].submeshes[0].material = i as u32;
        }
        let mut quads = Quads { builder, count, u_range };
        for i in 0..count {
            let at = glam::Mat4::from_translation(Vec3::new(quads.centre_x(i), 0.0, 0.0));
            quads.builder.manifest.nodes.push(node(&format!("quad{i}"), at, i as u32));
        }
        quads
    }

    fn centre_x(&self, i: usize) -> f32 {
        (i as f32 - (self.count as f32 - 1.0) * 0.5) * 1.1
    }

    /// The world point of quad `i` where its uv0 are (u, v).
    fn at(&self, i: usize, u: f32, v: f32) -> Vec3 {
        let [u0, u1] = self.u_range;
        Vec3::new(self.centre_x(i) + (u - u0) / (u1 - u0) - 0.5, 0.5 - v, 0.0)
    }

    /// A texture of `format` and `size` with the given levels, sampled with `sampler`.
    fn texture(&mut self, format: TextureFormat, size: [u32; 2], levels: &[&[u8]], sampler: Sampler) -> u32 {
        let t = texture(&mut self.builder, "texture", format, size, levels);
        self.builder.manifest.textures[t as usize].sampler = sampler;
        t
    }

    /// One row of texels, left to right, as an sRGB texture.
    fn row(&mut self, texels: &[[u8; 4]], sampler: Sampler) -> u32 {
        self.texture(TextureFormat::Rgba8Srgb, [texels.len() as u32, 1], &[texels.as_flattened()], sampler)
    }
}

/// What the stand-in lighting makes of a linear albedo on a face towards the camera (+Z):
/// albedo x (ambient + sun n.l), sRGB-encoded.
fn lit(albedo: [f32; 3]) -> [u8; 3] {
    let l = Lighting::default();
    let light = l.ambient.x + l.sun_color.x * l.sun_dir.normalize().dot(Vec3::Z).max(0.0);
    albedo.map(|c| srgb_encode(c * light))
}

/// `lit` of an sRGB texel.
fn lit_texel(texel: [u8; 4]) -> [u8; 3] {
    lit([srgb_decode(texel[0]), srgb_decode(texel[1]), srgb_decode(texel[2])])
}

/// The pixels at world points `points` of `pack` rendered `w` x `h` from (0, 0, z) looking down -Z.
fn pixels_at(gpu: &Gpu, pack: &Pack, z: f32, (w, h): (u32, u32), points: &[Vec3]) -> Vec<[u8; 4]> {
    let cam = looking_down_neg_z(z);
    let px = render(gpu, pack, &cam, w, h);
    points.iter().map(|&p| screen_pixel(&cam, w, h, p)).map(|(x, y)| pixel(&px, w, x, y)).collect()
}

#[test]
fn the_base_colour_reads_its_uv_set_through_its_texture_transform() {
    // A red | green texture, unfiltered, on a quad whose uv0 run left to right (and whose
    // texcoord1 run right to left): the colour at a uv is the texel its transformed uv lands on.
    // Offset 0.5 swaps the halves (the right half wraps round); a quarter turn maps v to u, so
    // the top is red and the bottom green; scale 2 repeats the texture twice across; tex_coord 1
    // reads texcoord1, mirrored. Every pixel is the exact lit texel.
    let gpu = gpu();
    let turn = TextureTransform { rotation: std::f32::consts::FRAC_PI_2, ..Default::default() };
    // (what, the slot's transform, [(u, v, the texel shown there)]).
    type Case = (&'static str, TextureTransform, &'static [(f32, f32, [u8; 4])]);
    let cases: [Case; 5] = [
        ("identity", TextureTransform::default(), &[(0.25, 0.5, RED), (0.75, 0.5, GREEN)]),
        ("offset", TextureTransform { offset: [0.5, 0.0], ..Default::default() }, &[(0.25, 0.5, GREEN), (0.75, 0.5, RED)]),
        ("rotation", turn, &[(0.25, 0.25, RED), (0.75, 0.25, RED), (0.25, 0.75, GREEN), (0.75, 0.75, GREEN)]),
        ("scale", TextureTransform { scale: [2.0, 1.0], ..Default::default() }, &[(0.125, 0.5, RED), (0.375, 0.5, GREEN), (0.625, 0.5, RED), (0.875, 0.5, GREEN)]),
        ("texcoord1", TextureTransform { tex_coord: 1, ..Default::default() }, &[(0.25, 0.5, GREEN), (0.75, 0.5, RED)]),
    ];
    for (what, transform, expected) in cases {
        let mut quads = Quads::new(vec![Material { base_color_uv: transform, ..Default::default() }], [0.0, 1.0]);
        let t = quads.row(&[RED, GREEN], NEAREST);
        quads.builder.manifest.materials[0].base_color_texture = Some(t);
        let points: Vec<Vec3> = expected.iter().map(|&(u, v, _)| quads.at(0, u, v)).collect();
        let got = pixels_at(&gpu, &quads.builder.finish(), 1.2, (128, 128), &points);
        for (p, &(u, v, texel)) in got.into_iter().zip(expected) {
            assert_bytes_near(&format!("{what} at uv ({u}, {v})"), p, lit_texel(texel), 1);
        }
    }
    assert_clean(&gpu);
}

#[test]
fn the_alpha_test_reads_the_base_colours_transformed_uv_with_and_without_the_prepass() {
    // An alpha-tested (MASK) red | transparent texture with offset 0.5: the left half of the quad
    // lands on the transparent texel and is cut away (clear colour), the right half on red. The
    // depth pre-pass does the test when it runs, the shading pass otherwise: both must transform.
    let gpu = gpu();
    let material = Material { alpha_mode: AlphaMode::Mask, alpha_cutoff: 0.5, base_color_uv: TextureTransform { offset: [0.5, 0.0], ..Default::default() }, ..Default::default() };
    let mut quads = Quads::new(vec![material], [0.0, 1.0]);
    let t = quads.row(&[RED, [0, 255, 0, 0]], NEAREST);
    quads.builder.manifest.materials[0].base_color_texture = Some(t);
    let (left, right) = (quads.at(0, 0.25, 0.5), quads.at(0, 0.75, 0.5));
    let (w, h) = (128, 128);
    let cam = looking_down_neg_z(1.2);
    let mut rig = Rig::new(&gpu, &quads.builder.finish(), w, h);
    for prepass in [true, false] {
        rig.renderer.prepass = prepass;
        rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
        let at = |p: Vec3| {
            let (x, y) = screen_pixel(&cam, w, h, p);
            pixel(rig.target.pixels(), w, x, y)
        };
        assert_eq!(at(left), pixel(rig.target.pixels(), w, 0, 0), "pre-pass {prepass}: the left half is cut away");
        assert_bytes_near(&format!("pre-pass {prepass}: right half"), at(right), lit_texel(RED), 1);
    }
    rig.destroy(&gpu);
    assert_clean(&gpu);
}

#[test]
fn the_emissive_texture_times_the_emissive_factor_is_the_emitted_radiance() {
    // A black quad in a baked scene whose emission is the factor E times a two-texel sRGB
    // emissive texture, read through the emissive slot's own transform (offset 0.5: the texels
    // swap sides; the base colour's transform stays the identity). Each half's radiance is E
    // times its texel decoded to linear, exposed and tone-mapped. Without the texture the quad
    // would be E all over; without its transform the halves would be the other way round.
    let gpu = gpu();
    let e = [500.0, 400.0, 300.0];
    let texels = [[255, 128, 0, 255], [64, 255, 128, 255]];
    let material = Material { base_color: [0.0, 0.0, 0.0, 1.0], emissive: e, emissive_uv: TextureTransform { offset: [0.5, 0.0], ..Default::default() }, ..Default::default() };
    let mut quads = Quads::new(vec![material], [0.0, 1.0]);
    let t = quads.row(&texels, NEAREST);
    quads.builder.manifest.materials[0].emissive_texture = Some(t);
    add_lightmap_page(&mut quads.builder, 200.0);
    let (left, right) = (quads.at(0, 0.25, 0.5), quads.at(0, 0.75, 0.5));
    let (w, h) = (128, 128);
    let cam = looking_down_neg_z(1.2);
    let mut rig = Rig::new(&gpu, &quads.builder.finish(), w, h);
    assert!(rig.scene.baked.is_some());
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &cam, &Lighting::default(), true).unwrap();
    let radiance = |texel: [u8; 4]| std::array::from_fn(|c| e[c] * srgb_decode(texel[c]));
    let s = rig.renderer.tonemap.saturation;
    for (what, p, texel) in [("left half", left, texels[1]), ("right half", right, texels[0])] {
        let (x, y) = screen_pixel(&cam, w, h, p);
        assert_bytes_near(what, pixel(rig.target.pixels(), w, x, y), tone_mapped_bytes(radiance(texel), auto_exposure(200.0), s), 1);
    }
    rig.destroy(&gpu);
    assert_clean(&gpu);
}

#[test]
fn each_texture_wraps_outside_zero_to_one_as_its_sampler_says() {
    // Three quads in one scene, each with its own red | green texture (unfiltered) and wrap
    // mode, uv0 running from -1 to 2 across each: repeat, clamp-to-edge and mirrored repeat give
    // different texels at u = -0.25, 1.25 and 1.75.
    let gpu = gpu();
    let wraps = [
        (Wrap::Repeat, [GREEN, RED, GREEN]),
        (Wrap::Clamp, [RED, GREEN, GREEN]),
        (Wrap::Mirror, [RED, GREEN, RED]),
    ];
    let mut quads = Quads::new(vec![Material::default(); wraps.len()], [-1.0, 2.0]);
    for (i, (wrap, _)) in wraps.iter().enumerate() {
        let t = quads.row(&[RED, GREEN], Sampler { wrap_s: *wrap, wrap_t: *wrap, ..NEAREST });
        quads.builder.manifest.materials[i].base_color_texture = Some(t);
    }
    let us = [-0.25, 1.25, 1.75];
    let points: Vec<Vec3> = (0..wraps.len()).flat_map(|i| us.map(|u| quads.at(i, u, 0.5))).collect();
    let got = pixels_at(&gpu, &quads.builder.finish(), 3.0, (192, 128), &points);
    for (i, (wrap, want)) in wraps.iter().enumerate() {
        for (k, u) in us.iter().enumerate() {
            assert_bytes_near(&format!("{wrap:?} at u = {u}"), got[i * us.len() + k], lit_texel(want[k]), 1);
        }
    }
    assert_clean(&gpu);
}

#[test]
fn magnification_is_nearest_or_linear_as_the_sampler_says() {
    // The red | green texture stretched over a quad (clamped), seen at u near 0.4, between the
    // texel centres 0.25 and 0.75: NEAREST shows red alone; LINEAR blends the two in linear
    // light with the weight of green t = 2u - 0.5, u being the pixel centre's own coordinate.
    let gpu = gpu();
    let (w, h) = (192u32, 128u32);
    let z = 3.0;
    let clamped = Sampler { wrap_s: Wrap::Clamp, wrap_t: Wrap::Clamp, ..NEAREST };
    let filters = [Filter::Nearest, Filter::Linear];
    let mut quads = Quads::new(vec![Material::default(); filters.len()], [0.0, 1.0]);
    for (i, f) in filters.iter().enumerate() {
        let t = quads.row(&[RED, GREEN], Sampler { mag_filter: *f, min_filter: *f, ..clamped });
        quads.builder.manifest.materials[i].base_color_texture = Some(t);
    }
    let points = [quads.at(0, 0.4, 0.5), quads.at(1, 0.4, 0.5)];
    let left_edge = quads.centre_x(1) - 0.5;
    let got = pixels_at(&gpu, &quads.builder.finish(), z, (w, h), &points);
    // The pixel centre's u: back from the pixel's NDC x through the 60 degree camera at z.
    let (x, _) = screen_pixel(&looking_down_neg_z(z), w, h, points[1]);
    let ndc = (x as f32 + 0.5) / w as f32 * 2.0 - 1.0;
    let u = ndc * z * 30f32.to_radians().tan() * (w as f32 / h as f32) - left_edge;
    let t = 2.0 * u - 0.5;
    assert_bytes_near("nearest", got[0], lit_texel(RED), 1);
    assert_bytes_near(&format!("linear at u = {u}"), got[1], lit([1.0 - t, t, 0.0]), 2);
    assert_clean(&gpu);
}

#[test]
fn without_a_mipmap_filter_only_level_zero_is_read() {
    // A 256x256 texture whose level k is the grey 20 + 25k, on a quad 32 pixels wide: 8 texels
    // per pixel, so the trilinear default reads level 3; a sampler without a mipmap filter reads
    // level 0 however small the quad (glTF's NEAREST / LINEAR minification).
    let gpu = gpu();
    let size = 256u32;
    let levels: Vec<Vec<u8>> = (0..9).map(|k| [20 + 25 * k as u8, 20 + 25 * k as u8, 20 + 25 * k as u8, 255].repeat(((size >> k) * (size >> k)) as usize)).collect();
    let levels: Vec<&[u8]> = levels.iter().map(|l| l.as_slice()).collect();
    let (w, h) = (128u32, 128u32);
    // A 1 m quad 32 pixels wide: w / (2 z tan 30) = 32.
    let z = w as f32 / (2.0 * 32.0 * 30f32.to_radians().tan());
    let grey = |k: u8| lit([(20.0 + 25.0 * k as f32) / 255.0; 3]);
    for (mipmap_filter, level) in [(Some(Filter::Linear), 3), (None, 0)] {
        let mut quads = Quads::new(vec![Material::default()], [0.0, 1.0]);
        let t = quads.texture(TextureFormat::Rgba8Unorm, [size, size], &levels, Sampler { mipmap_filter, ..Sampler::default() });
        quads.builder.manifest.materials[0].base_color_texture = Some(t);
        let centre = quads.at(0, 0.5, 0.5);
        let got = pixels_at(&gpu, &quads.builder.finish(), z, (w, h), &[centre]);
        assert_bytes_near(&format!("mipmap filter {mipmap_filter:?}"), got[0], grey(level), 1);
    }
    assert_clean(&gpu);
}
