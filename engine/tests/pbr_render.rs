//! The glTF metallic-roughness model in the shading pass against its closed forms
//! (`../shared/notes/shading.md` §6a, §6b, §6e, §7.9), on the real device with validation: the
//! runtime white furnace, the sun's GGX peak in nits, normal maps that tilt the normal like
//! tilted geometry in the handedness glTF gives w, and no inf or NaN from the sharpest lobe. Expected bytes come from the CPU model (`shading`), exposed and tone-mapped by
//! the formula in `common::frames`.

use engine::render::renderer::Lighting;
use glam::{DVec3, Mat4, Quat, Vec3};
use pack::{Material, Pack, PackBuilder, TextureFormat};

mod common;
use common::frames::{assert_bytes_near, auto_exposure, looking_down_neg_z, pixel, tone_mapped_bytes, Rig};
use common::packs::{add_baked_light, node, push_mesh, push_uniform_probes, quad_vertices, sun, texture};
use common::{assert_clean, gpu};

/// The lightmap page's B: it sets the exposure (`auto_exposure`) and makes the pack baked
/// (physical lighting, sun in lux), on a static quad far out of view.
const LIGHTMAP_B: f32 = 100.0;
const SIZE: u32 = 64;

/// One dynamic unit quad at the origin facing +Z (tangent +X with handedness `w`), placed by
/// `place`, drawn with material 1, which the caller pushes; a static lightmapped quad far out
/// of view makes the pack baked (physical lighting, exposure from `LIGHTMAP_B`).
fn quad_builder(w: f32, place: Mat4) -> PackBuilder {
    let mut b = PackBuilder::new("generated", "test");
    let (mut verts, idx) = quad_vertices();
    for v in &mut verts {
        v.tangent = [1.0, 0.0, 0.0, w];
    }
    add_baked_light(&mut b, LIGHTMAP_B, Vec3::new(0.0, -50.0, 0.0));
    let mesh = push_mesh(&mut b, "quad", &verts, &idx, None);
    b.manifest.meshes[mesh as usize].lods[0].submeshes[0].material = 1;
    b.manifest.nodes.push(node("quad", place, mesh));
    b
}

/// `quad_builder`'s quad in `material`; optionally a 1x1 16-bit normal map holding
/// `normal_ts`; a sun of `lux` shining toward -`towards_sun`; no probes (no indirect light).
fn quad_pack(material: Material, normal_ts: Option<Vec3>, w: f32, place: Mat4, lux: f32, towards_sun: Vec3) -> Pack {
    let mut b = quad_builder(w, place);
    let normal_texture = normal_ts.map(|n| {
        let texel: Vec<u8> = [n.x * 0.5 + 0.5, n.y * 0.5 + 0.5, n.z * 0.5 + 0.5, 1.0].iter().flat_map(|c| ((c * 65535.0).round() as u16).to_le_bytes()).collect();
        texture(&mut b, "normal", TextureFormat::Rgba16Unorm, [1, 1], &[&texel])
    });
    b.manifest.materials.push(Material { normal_texture, ..material });
    b.manifest.lights.push(sun(lux, towards_sun, 0.0));
    b.finish()
}

/// `quad_builder`'s quad in `material`, lit by probes alone: every probe sees a uniform sky of
/// `sky` nits, no sun.
fn furnace_pack(material: Material, place: Mat4, sky: f32) -> Pack {
    furnace_builder(material, place, sky).finish()
}

/// `furnace_pack`, still open for more (the quad's material is material 1).
fn furnace_builder(material: Material, place: Mat4, sky: f32) -> PackBuilder {
    let mut b = quad_builder(1.0, place);
    b.manifest.materials.push(material);
    push_uniform_probes(&mut b, sky, 0.0);
    b
}

/// The centre pixel of the frame from (0, 0, 3) looking down -Z (the quad's centre), with
/// tone-map saturation 1.
fn centre_pixel(pack: &Pack) -> [u8; 4] {
    let gpu = gpu();
    let mut rig = Rig::new(&gpu, pack, SIZE, SIZE);
    assert!(rig.scene.baked.is_some());
    rig.renderer.tonemap.saturation = 1.0;
    rig.target.render(&gpu, &mut rig.renderer, &rig.scene, &looking_down_neg_z(3.0), &Lighting::default(), true).unwrap();
    let p = pixel(rig.target.pixels(), SIZE, SIZE / 2, SIZE / 2);
    rig.destroy(&gpu);
    assert_clean(&gpu);
    p
}

/// The bytes the CPU model gives for a sunlit surface of `m` with normal `n`, seen from +Z.
fn expected(m: &shading::Material, n: Vec3, towards_sun: Vec3, lux: f32) -> [u8; 3] {
    let v = DVec3::Z;
    let l = shading::Material::sunlit(m, n.as_dvec3().normalize(), v, towards_sun.as_dvec3().normalize(), lux as f64);
    tone_mapped_bytes([l.x as f32, l.y as f32, l.z as f32], auto_exposure(LIGHTMAP_B), 1.0)
}

fn material(base: f32, roughness: f32) -> (Material, shading::Material) {
    (Material { base_color: [base, base, base, 1.0], metallic: 0.0, roughness, ..Material::default() }, shading::Material::dielectric(base as f64, roughness as f64))
}

#[test]
fn the_suns_ggx_peak_in_nits() {
    // §6b: n = v = l, a black dielectric shows the specular peak alone, f0 E / (4 pi r^4):
    // 0.0509 E at r 0.5, 0.393 E at r 0.3; a white one adds 0.96 E / pi of diffuse.
    let lux = 4000.0;
    for (base, r) in [(0.0, 0.5), (0.0, 0.3), (1.0, 0.5), (0.5, 0.8)] {
        let (m, cpu) = material(base, r);
        let got = centre_pixel(&quad_pack(m, None, 1.0, Mat4::IDENTITY, lux, Vec3::Z));
        let want = expected(&cpu, Vec3::Z, Vec3::Z, lux);
        let nits = cpu.sunlit(DVec3::Z, DVec3::Z, DVec3::Z, lux as f64).x;
        eprintln!("base {base}, r {r}: {nits:.1} nits, got {got:?}, want {want:?}");
        assert_bytes_near(&format!("base {base}, r {r} ({nits:.1} nits)"), got, want, 1);
    }
    // The peak is there: a black r 0.3 surface is far brighter than a black r 0.8 one.
    let dark = |r| centre_pixel(&quad_pack(material(0.0, r).0, None, 1.0, Mat4::IDENTITY, lux, Vec3::Z))[0];
    assert!(dark(0.3) > dark(0.8) + 60);
}

#[test]
fn a_normal_map_tilting_by_t_shades_like_geometry_tilted_by_t() {
    // §6e: n_ts = (sin t, 0, cos t) with T = +X tilts the normal to (sin t, 0, cos t); the sun
    // and the eye on +Z. The same quad without a map, rotated by t about Y, has that normal as
    // its geometry: both pixels within 2/255 of each other and of the closed form.
    let lux = 3000.0;
    let (m, cpu) = material(0.8, 0.5);
    for deg in [30.0f32, 60.0] {
        let t = deg.to_radians();
        let n = Vec3::new(t.sin(), 0.0, t.cos());
        let mapped = centre_pixel(&quad_pack(m.clone(), Some(n), 1.0, Mat4::IDENTITY, lux, Vec3::Z));
        let tilted = centre_pixel(&quad_pack(m.clone(), None, 1.0, Mat4::from_quat(Quat::from_rotation_y(t)), lux, Vec3::Z));
        let want = expected(&cpu, n, Vec3::Z, lux);
        eprintln!("t = {deg}: mapped {mapped:?}, tilted {tilted:?}, closed form {want:?}");
        assert_bytes_near(&format!("normal map at {deg} deg vs tilted geometry"), mapped, [tilted[0], tilted[1], tilted[2]], 2);
        assert_bytes_near(&format!("normal map at {deg} deg vs the closed form"), mapped, want, 2);
    }
    // normalTexture.scale 2 scales xy before normalising: 30 deg becomes atan(2 tan 30 deg).
    let t = 30f32.to_radians();
    let n_ts = Vec3::new(t.sin(), 0.0, t.cos());
    let scaled = centre_pixel(&quad_pack(Material { normal_scale: 2.0, ..m.clone() }, Some(n_ts), 1.0, Mat4::IDENTITY, lux, Vec3::Z));
    let n2 = Vec3::new(2.0 * t.sin(), 0.0, t.cos()).normalize();
    assert_bytes_near("scale 2", scaled, expected(&cpu, n2, Vec3::Z, lux), 2);
}

#[test]
fn the_tangents_w_picks_the_bitangents_side() {
    // §6e handedness: n_ts = (0, sin 30, cos 30), the sun toward (0, cos 45, sin 45). With
    // w = +1 the bitangent is +Y and n = (0, 0.5, 0.866): n.l = 0.966; with w = -1 it is -Y and
    // n = (0, -0.5, 0.866): n.l = 0.259.
    let lux = 3000.0;
    let (m, cpu) = material(0.8, 0.9);
    let towards_sun = Vec3::new(0.0, 1.0, 1.0).normalize();
    let n_ts = Vec3::new(0.0, 0.5, 0.75f32.sqrt());
    let mut got = Vec::new();
    for w in [1.0f32, -1.0] {
        let px = centre_pixel(&quad_pack(m.clone(), Some(n_ts), w, Mat4::IDENTITY, lux, towards_sun));
        let n = Vec3::new(0.0, 0.5 * w, 0.75f32.sqrt());
        assert_bytes_near(&format!("w = {w}"), px, expected(&cpu, n, towards_sun, lux), 2);
        got.push(px[0]);
    }
    assert!(got[0] > got[1] + 40, "w = +1 must face the sun more: {got:?}");
}

#[test]
fn white_furnace_at_runtime() {
    // §6a runtime furnace: a uniform sky of L nits as the only light (probe B = L, environment
    // L in every direction). A white dielectric returns L for every roughness and view: its
    // diffuse weight w_d = 1 - (0.04 A + B) gives up exactly what the specular
    // (0.04 A + B) L takes. A white metal returns L (A + B), its single-scattering loss. The
    // sky is dim for the exposure (50 nits, exposed to 0.18, a mid tone), where one byte is
    // about 2.3 % of radiance: a 1 % error shows within the byte of tolerance.
    let sky = 50.0;
    let exposure = auto_exposure(LIGHTMAP_B);
    let white = tone_mapped_bytes([sky; 3], exposure, 1.0);
    for r in [0.1f32, 0.5, 1.0] {
        for view_deg in [0.0f32, 60.0] {
            let place = Mat4::from_quat(Quat::from_rotation_y(view_deg.to_radians()));
            let dielectric = Material { base_color: [1.0; 4], metallic: 0.0, roughness: r, ..Material::default() };
            let got = centre_pixel(&furnace_pack(dielectric, place, sky));
            eprintln!("dielectric r {r}, view {view_deg} deg: {got:?}, want {white:?} ({sky} nits)");
            assert_bytes_near(&format!("white dielectric r {r} at {view_deg} deg"), got, white, 1);
            let metal = Material { base_color: [1.0; 4], metallic: 1.0, roughness: r, ..Material::default() };
            let (a, b) = shading::dfg((view_deg as f64).to_radians().cos(), r as f64);
            let l = sky * (a + b) as f32;
            let want = tone_mapped_bytes([l; 3], exposure, 1.0);
            let got = centre_pixel(&furnace_pack(metal, place, sky));
            eprintln!("metal r {r}, view {view_deg} deg: {got:?}, want {want:?} ({l:.1} nits)");
            assert_bytes_near(&format!("white metal r {r} at {view_deg} deg"), got, want, 1);
        }
    }
}

#[test]
fn the_sharpest_metal_under_a_strong_sun_stays_finite() {
    // §7.9: an r = 0.045 (the floor) white metal facing a 100 000 lux sun along the view peaks
    // at f0 E / (4 pi alpha^2) = 1.9e9 nits, past half precision: the shading pass clamps it to
    // the HDR target's largest value (65 504) instead of writing inf, and the tone map shows it
    // as white, not as the black an inf or NaN would give.
    let lux = 100_000.0;
    let metal = Material { base_color: [1.0; 4], metallic: 1.0, roughness: 0.0, ..Material::default() };
    let got = centre_pixel(&quad_pack(metal, None, 1.0, Mat4::IDENTITY, lux, Vec3::Z));
    let want = tone_mapped_bytes([65_504.0; 3], auto_exposure(LIGHTMAP_B), 1.0);
    assert_bytes_near("the clamped peak", got, want, 1);
}

#[test]
fn occlusion_darkens_indirect_light_from_a_packed_orm_texture_or_its_own() {
    // In the furnace (a white dielectric returns the sky's L) an occlusion of 0.5 at strength
    // 1 returns L / 2: from the red of a packed occlusion-roughness-metalness texture (one
    // texture in both slots, sampled once) and from an occlusion texture of its own; strength
    // 0.5 returns 3 L / 4.
    let sky = 50.0;
    let exposure = auto_exposure(LIGHTMAP_B);
    let pack_with = |separate: bool, strength: f32| {
        let mut b = furnace_builder(Material { base_color: [1.0; 4], metallic: 0.0, roughness: 0.5, ..Material::default() }, Mat4::IDENTITY, sky);
        let orm = texture(&mut b, "orm", TextureFormat::Rgba8Unorm, [1, 1], &[&[128, 255, 0, 255]]);
        let occlusion = if separate { texture(&mut b, "occlusion", TextureFormat::Rgba8Unorm, [1, 1], &[&[128, 128, 128, 255]]) } else { orm };
        let m = &mut b.manifest.materials[1];
        (m.metallic_roughness_texture, m.occlusion_texture, m.occlusion_strength) = (Some(orm), Some(occlusion), strength);
        b.finish()
    };
    let half = 128.0 / 255.0;
    for (separate, strength) in [(false, 1.0), (true, 1.0), (false, 0.5)] {
        let got = centre_pixel(&pack_with(separate, strength));
        let l = sky * (1.0 + strength * (half - 1.0));
        let want = tone_mapped_bytes([l; 3], exposure, 1.0);
        eprintln!("occlusion {half:.3} at strength {strength} ({}): {got:?}, want {want:?} ({l:.1} nits)", if separate { "own texture" } else { "packed ORM" });
        assert_bytes_near(&format!("occlusion strength {strength}, separate {separate}"), got, want, 1);
    }
}
