//! Block-compression encoders compared on the shared glTF samples' textures (issue 24): Intel's
//! ISPC texture compressor (`intel_tex_2`: BC1, BC4, BC5, BC7) against a pure-Rust one
//! (`texpresso`, a port of libsquish: BC1, BC4, BC5), per texture class as the materials use
//! them, on one thread (BC7 at three of its speed settings: basic, fast, ultra fast): quality against the source (colour: PSNR in linear light; normal maps:
//! mean and 99th-percentile angular error with z rebuilt from x, y; single channel: PSNR) and
//! encode time per megatexel. Decoding for the metrics is `bcdec_rs` (an independent decoder).
//!
//!     cargo run --release -p cook_core --example bc_compare [SAMPLES_DIR]
//!
//! (SAMPLES_DIR default: $GLTF_SAMPLES_DIR, else ../shared/gltf-samples.)

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug)]
enum Class {
    Colour,
    /// Metallic-roughness (glTF: roughness in G, metallic in B), linear data.
    Data,
    Normal,
    Occlusion,
}

/// An RGBA8 image padded to whole 4x4 blocks by repeating its last row and column.
struct Texture {
    width: usize,
    height: usize,
    rgba: Vec<u8>,
}

fn padded(w: usize, h: usize, rgba: &[u8]) -> Texture {
    let (pw, ph) = (w.next_multiple_of(4), h.next_multiple_of(4));
    let mut out = vec![0u8; pw * ph * 4];
    for y in 0..ph {
        for x in 0..pw {
            let (sx, sy) = (x.min(w - 1), y.min(h - 1));
            out[(y * pw + x) * 4..][..4].copy_from_slice(&rgba[(sy * w + sx) * 4..][..4]);
        }
    }
    Texture { width: pw, height: ph, rgba: out }
}

/// Every texture of every sample, by the class the materials use it as (first use wins).
fn textures(dir: &Path) -> Vec<(String, Class, Texture)> {
    let mut files: Vec<PathBuf> = walk(dir).into_iter().filter(|p| matches!(p.extension().and_then(|e| e.to_str()), Some("gltf" | "glb"))).collect();
    files.sort();
    let mut out = Vec::new();
    for f in files {
        let Ok((doc, _, images)) = gltf::import(&f) else {
            eprintln!("bc_compare: skipped {} (the gltf crate cannot import it)", f.display());
            continue;
        };
        let mut class: BTreeMap<usize, Class> = BTreeMap::new();
        let tex_image = |t: gltf::Texture| t.source().index();
        for m in doc.materials() {
            let pbr = m.pbr_metallic_roughness();
            for (t, c) in [
                (pbr.base_color_texture().map(|i| tex_image(i.texture())), Class::Colour),
                (m.emissive_texture().map(|i| tex_image(i.texture())), Class::Colour),
                (m.normal_texture().map(|i| tex_image(i.texture())), Class::Normal),
                (pbr.metallic_roughness_texture().map(|i| tex_image(i.texture())), Class::Data),
                (m.occlusion_texture().map(|i| tex_image(i.texture())), Class::Occlusion),
            ] {
                if let Some(t) = t {
                    class.entry(t).or_insert(c);
                }
            }
        }
        for (i, c) in class {
            let img = &images[i];
            let (w, h) = (img.width as usize, img.height as usize);
            let rgba: Vec<u8> = match img.format {
                gltf::image::Format::R8G8B8A8 => img.pixels.clone(),
                gltf::image::Format::R8G8B8 => img.pixels.chunks_exact(3).flat_map(|p| [p[0], p[1], p[2], 255]).collect(),
                other => {
                    eprintln!("bc_compare: skipped image {i} of {} ({other:?})", f.display());
                    continue;
                }
            };
            let name = format!("{} #{i}", f.strip_prefix(dir).unwrap_or(&f).display());
            out.push((name, c, padded(w, h, &rgba)));
        }
    }
    out
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}

fn srgb_to_linear(v: u8) -> f64 {
    let c = v as f64 / 255.0;
    if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
}

/// Decode `blocks` of `format` (bcdec_rs) to RGBA8 (BC4: R; BC5: RG).
fn decode(format: &str, blocks: &[u8], w: usize, h: usize) -> Vec<u8> {
    let block_bytes = if matches!(format, "BC1" | "BC4") { 8 } else { 16 };
    let mut out = vec![0u8; w * h * 4];
    let (bw, bh) = (w / 4, h / 4);
    for by in 0..bh {
        for bx in 0..bw {
            let b = &blocks[(by * bw + bx) * block_bytes..][..block_bytes];
            let mut texels = [[0u8; 4]; 16];
            match format {
                "BC1" => {
                    let mut d = [0u8; 64];
                    bcdec_rs::bc1(b, &mut d, 16);
                    for k in 0..16 {
                        texels[k].copy_from_slice(&d[k * 4..k * 4 + 4]);
                    }
                }
                "BC7" => {
                    let mut d = [0u8; 64];
                    bcdec_rs::bc7(b, &mut d, 16);
                    for k in 0..16 {
                        texels[k].copy_from_slice(&d[k * 4..k * 4 + 4]);
                    }
                }
                "BC4" => {
                    let mut d = [0u8; 16];
                    bcdec_rs::bc4(b, &mut d, 4, false);
                    for k in 0..16 {
                        texels[k] = [d[k], 0, 0, 255];
                    }
                }
                "BC5" => {
                    let mut d = [0u8; 32];
                    bcdec_rs::bc5(b, &mut d, 8, false);
                    for k in 0..16 {
                        texels[k] = [d[2 * k], d[2 * k + 1], 0, 255];
                    }
                }
                _ => unreachable!(),
            }
            for k in 0..16 {
                let (x, y) = (bx * 4 + k % 4, by * 4 + k / 4);
                out[(y * w + x) * 4..][..4].copy_from_slice(&texels[k]);
            }
        }
    }
    out
}

/// (encoder, format) -> blocks, on one thread.
fn encode(encoder: &str, format: &str, t: &Texture) -> Vec<u8> {
    let surface = intel_tex_2::RgbaSurface { width: t.width as u32, height: t.height as u32, stride: t.width as u32 * 4, data: &t.rgba };
    let channel = |c: usize| -> Vec<u8> { t.rgba.iter().skip(c).step_by(4).copied().collect() };
    match (encoder, format) {
        ("intel_tex_2", "BC7") => intel_tex_2::bc7::compress_blocks(&intel_tex_2::bc7::alpha_basic_settings(), &surface),
        ("intel_tex_2 fast", "BC7") => intel_tex_2::bc7::compress_blocks(&intel_tex_2::bc7::alpha_fast_settings(), &surface),
        ("intel_tex_2 ultra fast", "BC7") => intel_tex_2::bc7::compress_blocks(&intel_tex_2::bc7::alpha_ultra_fast_settings(), &surface),
        ("intel_tex_2", "BC1") => intel_tex_2::bc1::compress_blocks(&surface),
        ("intel_tex_2", "BC4") => {
            let r = channel(0);
            intel_tex_2::bc4::compress_blocks(&intel_tex_2::RSurface { width: t.width as u32, height: t.height as u32, stride: t.width as u32, data: &r })
        }
        ("intel_tex_2", "BC5") => {
            let rg: Vec<u8> = t.rgba.chunks_exact(4).flat_map(|p| [p[0], p[1]]).collect();
            intel_tex_2::bc5::compress_blocks(&intel_tex_2::RgSurface { width: t.width as u32, height: t.height as u32, stride: t.width as u32 * 2, data: &rg })
        }
        ("texpresso", f) => {
            let format = match f {
                "BC1" => texpresso::Format::Bc1,
                "BC4" => texpresso::Format::Bc4,
                "BC5" => texpresso::Format::Bc5,
                _ => unreachable!(),
            };
            let mut out = vec![0u8; format.compressed_size(t.width, t.height)];
            format.compress(&t.rgba, t.width, t.height, texpresso::Params::default(), &mut out);
            out
        }
        _ => unreachable!(),
    }
}

/// The quality metric of a class. Colour: PSNR of linear RGB premultiplied by alpha, and alpha
/// (what shows); data: PSNR of G and B (roughness, metallic); normal: mean and p99 angular error
/// in degrees; occlusion: PSNR of R.
fn quality(class: Class, src: &Texture, dec: &[u8]) -> Vec<f64> {
    let n = src.width * src.height;
    match class {
        Class::Colour => {
            let mut se = 0.0;
            for i in 0..n {
                let (a, b) = (src.rgba[i * 4 + 3] as f64 / 255.0, dec[i * 4 + 3] as f64 / 255.0);
                for c in 0..3 {
                    let d = srgb_to_linear(src.rgba[i * 4 + c]) * a - srgb_to_linear(dec[i * 4 + c]) * b;
                    se += d * d;
                }
                se += (a - b) * (a - b);
            }
            vec![10.0 * (1.0 / (se / (4 * n) as f64).max(1e-12)).log10()]
        }
        Class::Data => {
            let se: f64 = (0..n).flat_map(|i| [1, 2].map(|c| ((src.rgba[i * 4 + c] as f64 - dec[i * 4 + c] as f64) / 255.0).powi(2))).sum();
            vec![10.0 * (1.0 / (se / (2 * n) as f64).max(1e-12)).log10()]
        }
        Class::Occlusion => {
            let se: f64 = (0..n).map(|i| ((src.rgba[i * 4] as f64 - dec[i * 4] as f64) / 255.0).powi(2)).sum();
            vec![10.0 * (1.0 / (se / n as f64).max(1e-12)).log10()]
        }
        Class::Normal => {
            let mut angles: Vec<f64> = (0..n)
                .map(|i| {
                    let v = |p: &[u8]| {
                        let (x, y) = (p[0] as f64 / 127.5 - 1.0, p[1] as f64 / 127.5 - 1.0);
                        (x, y, (1.0 - x * x - y * y).max(0.0).sqrt())
                    };
                    let (a, b) = (v(&src.rgba[i * 4..]), v(&dec[i * 4..]));
                    let la = (a.0 * a.0 + a.1 * a.1 + a.2 * a.2).sqrt().max(1e-9);
                    let lb = (b.0 * b.0 + b.1 * b.1 + b.2 * b.2).sqrt().max(1e-9);
                    ((a.0 * b.0 + a.1 * b.1 + a.2 * b.2) / (la * lb)).clamp(-1.0, 1.0).acos().to_degrees()
                })
                .collect();
            let mean = angles.iter().sum::<f64>() / n as f64;
            angles.sort_by(f64::total_cmp);
            vec![mean, angles[(n * 99 / 100).min(n - 1)]]
        }
    }
}

fn main() {
    let dir = std::env::args().nth(1).map(PathBuf::from).or_else(|| std::env::var_os("GLTF_SAMPLES_DIR").map(PathBuf::from)).unwrap_or_else(|| PathBuf::from("../shared/gltf-samples"));
    let textures = textures(&dir);
    if textures.is_empty() {
        eprintln!("bc_compare: no textures under {}", dir.display());
        std::process::exit(1);
    }
    let runs: &[(Class, &str, &str)] = &[
        (Class::Colour, "intel_tex_2", "BC7"),
        (Class::Colour, "intel_tex_2 fast", "BC7"),
        (Class::Colour, "intel_tex_2 ultra fast", "BC7"),
        (Class::Colour, "intel_tex_2", "BC1"),
        (Class::Colour, "texpresso", "BC1"),
        (Class::Data, "intel_tex_2", "BC7"),
        (Class::Data, "intel_tex_2", "BC1"),
        (Class::Data, "texpresso", "BC1"),
        (Class::Normal, "intel_tex_2", "BC5"),
        (Class::Normal, "texpresso", "BC5"),
        (Class::Occlusion, "intel_tex_2", "BC4"),
        (Class::Occlusion, "texpresso", "BC4"),
    ];
    println!("| class | encoder | format | textures | megatexels | ms per megatexel (1 thread) | quality, worst texture | which | quality, texel-weighted mean |");
    println!("|---|---|---|---:|---:|---:|---:|---|---:|");
    for &(class, encoder, format) in runs {
        let mine: Vec<_> = textures.iter().filter(|t| t.1 == class).collect();
        if mine.is_empty() {
            continue;
        }
        let (mut secs, mut texels, mut worst, mut weighted) = (0.0, 0usize, None::<(Vec<f64>, &str)>, vec![0.0; if class == Class::Normal { 2 } else { 1 }]);
        for (name, _, t) in &mine {
            let start = Instant::now();
            let blocks = encode(encoder, format, t);
            secs += start.elapsed().as_secs_f64();
            let q = quality(class, t, &decode(format, &blocks, t.width, t.height));
            let n = t.width * t.height;
            texels += n;
            for (w, v) in weighted.iter_mut().zip(&q) {
                *w += v * n as f64;
            }
            // Worst: lowest PSNR, or largest angular error.
            let worse = |a: &Vec<f64>, b: &Vec<f64>| if class == Class::Normal { a[0] > b[0] } else { a[0] < b[0] };
            if worst.as_ref().is_none_or(|w| worse(&q, &w.0)) {
                worst = Some((q, name.as_str()));
            }
        }
        let mt = texels as f64 / 1e6;
        let fmt = |q: &[f64]| match class {
            Class::Normal => format!("{:.2}° mean, {:.2}° p99", q[0], q[1]),
            _ => format!("{:.2} dB", q[0]),
        };
        let mean: Vec<f64> = weighted.iter().map(|w| w / texels as f64).collect();
        let (worst, which) = worst.unwrap();
        println!("| {class:?} | {encoder} | {format} | {} | {mt:.2} | {:.1} | {} | {which} | {} |", mine.len(), 1e3 * secs / mt, fmt(&worst), fmt(&mean));
    }
}
