//! The shared samples' material maps reach the image (issue 21): every sample whose materials
//! use a normal, metallic-roughness, occlusion or emissive texture renders differently with
//! that map removed, over the pixels the model covers (GolfBall's dimples are its normal map).
//! With the renderer's material-maps switch off, each renders as with all those maps removed.
//! Each sample is cooked in-process, lit physically (a lightmap page out of view for the
//! exposure, uniform probes for the indirect light, a sun) and framed whole. Samples from
//! $GLTF_SAMPLES_DIR (default ../shared/gltf-samples); skipped with a message when absent.

use engine::render::renderer::Lighting;
use engine::scene::camera::Camera;
use glam::Vec3;
use pack::{Material, Pack, PackBuilder};
use std::path::Path;

mod common;
use common::frames::Rig;
use common::packs::{add_baked_light, push_uniform_probes, sun};
use common::{assert_clean, gpu, samples};

const SIZE: u32 = 96;

/// The sample's pack with physical light added: a lightmapped quad far below (B = 200 nits, the
/// exposure), probes of B = 300 nits over the level, and a sun of 20 000 lux from above-front.
/// `dark`: a night instead (B = 1 nit for the exposure, no probes, no sun), where an emissive
/// factor of 1 (1 nit, glTF's unit) is what shows: in daylight it is invisible, as it should be.
fn lit(mut pack: Pack, dark: bool) -> Pack {
    // Append the extras through a builder that owns a copy of the sample's data.
    let mut b = PackBuilder::new("generated", "test");
    b.manifest = pack.manifest.clone();
    b.push_bytes(&pack.data);
    add_baked_light(&mut b, if dark { 1.0 } else { 200.0 }, Vec3::new(0.0, -1.0e4, 0.0));
    b.manifest.lights.retain(|l| l.kind != pack::LightKind::Sun);
    if dark {
        return b.finish();
    }
    push_uniform_probes(&mut b, 300.0, 1.0);
    b.manifest.lights.push(sun(20_000.0, Vec3::new(0.3, 1.0, 0.6), 0.0));
    pack = b.finish();
    pack
}

/// The frame of `pack` with the model's bounds in view from the front (+Z) and above, 96x96.
fn render(gpu: &engine::gpu::Gpu, pack: &Pack) -> Vec<u8> {
    render_maps(gpu, pack, true)
}

/// `render` with the renderer's material-maps switch as given.
fn render_maps(gpu: &engine::gpu::Gpu, pack: &Pack, maps: bool) -> Vec<u8> {
    let mut rig = Rig::new(gpu, pack, SIZE, SIZE);
    rig.renderer.material_maps = maps;
    // The model's bounds: every instance except the quad far below.
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for i in 0..rig.scene.instances.len() {
        let s = rig.scene.instances.spheres();
        let (c, r) = (Vec3::new(s.x[i], s.y[i], s.z[i]), s.r[i]);
        if c.y > -1.0e3 {
            lo = lo.min(c - r);
            hi = hi.max(c + r);
        }
    }
    let (centre, radius) = ((lo + hi) * 0.5, ((hi - lo) * 0.5).length().max(1e-3));
    // From the front and 30 degrees above, so horizontal parts (PalmTree's water) show.
    let pitch = 30f32.to_radians();
    let camera = Camera { position: centre + Vec3::new(0.0, pitch.sin(), pitch.cos()) * radius * 2.2, yaw: 0.0, pitch: -pitch, fov_y: 60f32.to_radians(), near: radius * 0.01 };
    rig.target.render(gpu, &mut rig.renderer, &rig.scene, &camera, &Lighting::default(), true).unwrap();
    let px = rig.target.pixels().to_vec();
    rig.destroy(gpu);
    px
}

/// Fraction of pixels whose colour differs by more than 2/255 in some channel.
fn changed(a: &[u8], b: &[u8]) -> f64 {
    let n = a.chunks_exact(4).zip(b.chunks_exact(4)).filter(|(p, q)| (0..3).any(|c| (p[c] as i32 - q[c] as i32).abs() > 2)).count();
    n as f64 / (a.len() / 4) as f64
}

type Slot = (&'static str, fn(&mut Material));

const SLOTS: [Slot; 4] = [
    ("normal", |m| m.normal_texture = None),
    ("metallic-roughness", |m| m.metallic_roughness_texture = None),
    ("occlusion", |m| m.occlusion_texture = None),
    ("emissive", |m| m.emissive_texture = None),
];

fn has(m: &Material, slot: &str) -> bool {
    match slot {
        "normal" => m.normal_texture.is_some(),
        "metallic-roughness" => m.metallic_roughness_texture.is_some(),
        "occlusion" => m.occlusion_texture.is_some(),
        _ => m.emissive_texture.is_some() && m.emissive.iter().any(|&e| e > 0.0),
    }
}

fn sample_files(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .flat_map(|d| std::fs::read_dir(d.unwrap().path()).into_iter().flatten())
        .map(|f| f.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "gltf" || e == "glb"))
        .collect();
    files.sort();
    files
}

#[test]
fn every_samples_material_maps_change_its_image() {
    let Some(dir) = samples() else { return };
    let gpu = gpu();
    let mut checked = Vec::new();
    for file in sample_files(&dir) {
        let Ok(cooked) = cook_core::cook_gltf(&file, &mut |_, _| {}) else { continue };
        let name = file.file_name().unwrap().to_string_lossy().into_owned();
        for (slot, remove) in SLOTS {
            if !cooked.manifest.materials.iter().any(|m| has(m, slot)) {
                continue;
            }
            let dark = slot == "emissive";
            let with = render(&gpu, &lit(cooked.clone(), dark));
            let mut without = cooked.clone();
            without.manifest.materials.iter_mut().for_each(remove);
            let without = render(&gpu, &lit(without, dark));
            let fraction = changed(&with, &without);
            eprintln!("{name}: without its {slot} map, {:.2}% of the pixels change", fraction * 100.0);
            // At least 0.1% of the frame (9 pixels): a map the shader never read changes none.
            // (Terrain's metallic-roughness map only moves a rough dielectric's faint specular.)
            assert!(fraction >= 0.001, "{name}: removing the {slot} map changes only {:.3}% of the image", fraction * 100.0);
            checked.push(format!("{name} {slot}"));
        }
        // The renderer's switch: its material-maps-off frame is the frame of the sample with
        // every such map removed (the pipelines then sample the base colour alone), exactly.
        if SLOTS.iter().any(|(slot, _)| cooked.manifest.materials.iter().any(|m| has(m, slot))) {
            let switched_off = render_maps(&gpu, &lit(cooked.clone(), false), false);
            let mut bare = cooked.clone();
            bare.manifest.materials.iter_mut().for_each(|m| SLOTS.iter().for_each(|(_, remove)| remove(m)));
            let bare = render(&gpu, &lit(bare, false));
            assert!(switched_off == bare, "{name}: with material maps off, {:.3}% of the pixels differ from the sample without its maps", changed(&switched_off, &bare) * 100.0);
        }
    }
    eprintln!("checked: {checked:?}");
    assert!(checked.iter().any(|c| c.starts_with("GolfBall") && c.ends_with("normal")), "GolfBall's normal map was not checked: {checked:?}");
    assert_clean(&gpu);
}
