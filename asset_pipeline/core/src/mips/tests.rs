//! The notes' tests (notes/textures.md §1.13) with their thresholds.

use super::*;

/// Every level (1..) of an f32 image as the filter leaves it (before `finish_texel`).
fn levels_f32(img: &Image, s: &MipSettings) -> Vec<Image> {
    let mut out = Vec::new();
    chain(img.width as u32, img.height as u32, |y, row| row.copy_from_slice(img.row(y)), s, |l| out.push(l.clone()));
    out
}

fn image(w: usize, h: usize, mut f: impl FnMut(usize, usize) -> Texel) -> Image {
    let mut texels = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            texels.push(f(x, y));
        }
    }
    Image { width: w, height: h, texels }
}

fn rgba8(w: usize, h: usize, f: impl Fn(usize, usize) -> [u8; 4]) -> Vec<u8> {
    (0..h).flat_map(|y| (0..w).map(move |x| (x, y))).flat_map(|(x, y)| f(x, y)).collect()
}

/// A small deterministic generator (tests must not depend on a seed elsewhere).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((self.0 >> 40) as f32) / (1u64 << 24) as f32
    }
}

fn settings(usage: Usage, filter: Filter, edge: Edge) -> MipSettings {
    MipSettings { usage, filter, edges: [edge; 2], alpha_cutoff: None }
}

#[test]
fn srgb_transfer_matches_the_standard_and_round_trips_every_byte() {
    for b in 0..=255u8 {
        assert_eq!(srgb::encode_byte(srgb::decode_byte(b)), b, "byte {b}");
    }
    assert_eq!(srgb::encode_byte(0.5), 188);
    assert_eq!(srgb::encode_byte(0.18), 118);
    assert!((srgb::decode_byte(128) - 0.2158).abs() < 1e-4);
    // The fast encode agrees with round(255 * encode(c)) on a fine sweep.
    for i in 0..=100_000 {
        let c = i as f32 / 100_000.0;
        let want = (255.0 * srgb::encode(c as f64) + 0.5).floor() as u8;
        assert_eq!(srgb::encode_byte(c), want, "linear {c}");
    }
}

#[test]
fn level_sizes_halve_down_to_one_by_one() {
    assert_eq!(level_count(1024, 1024), 11);
    assert_eq!(level_count(5, 3), 3);
    assert_eq!(level_count(1, 1), 1);
    assert_eq!((0..3).map(|l| level_size(5, 3, l)).collect::<Vec<_>>(), [(5, 3), (2, 1), (1, 1)]);
    let px = rgba8(7, 1, |_, _| [1, 2, 3, 4]);
    let m = mips_rgba8(7, 1, &px, &MipSettings::new(Usage::Data)).unwrap();
    assert_eq!(m.iter().map(Vec::len).collect::<Vec<_>>(), [3 * 4, 4]);
}

#[test]
fn a_constant_image_stays_constant_at_every_level() {
    for (w, h) in [(64, 64), (5, 3), (7, 1), (1, 9), (33, 17)] {
        for filter in Filter::ALL {
            for edge in [Edge::Wrap, Edge::Clamp, Edge::Mirror] {
                let c = [200, 37, 90, 255];
                let px = rgba8(w, h, |_, _| c);
                for usage in [Usage::Color, Usage::Data] {
                    let s = settings(usage, filter, edge);
                    for (l, level) in mips_rgba8(w as u32, h as u32, &px, &s).unwrap().iter().enumerate() {
                        assert!(level.chunks_exact(4).all(|t| t == c), "{w}x{h} {filter:?} {edge:?} {usage:?} level {}: {:?}", l + 1, &level[..4]);
                    }
                }
                // Normals are renormalised: a constant non-unit vector becomes one unit vector,
                // the same at every level as at level 0.
                let levels = normal_levels(w as u32, h as u32, NormalTexels::Unorm8(&px), &settings(Usage::Normal, filter, edge)).unwrap();
                let want = levels[0][..4].to_vec();
                for (l, level) in levels.iter().enumerate() {
                    assert!(level.chunks_exact(4).all(|t| t == want), "{w}x{h} {filter:?} {edge:?} normal level {l}: {:?}", &level[..4]);
                }
                let hdr = half::f16::from_f32(1234.5).to_bits();
                let px = vec![hdr; w * h * 4];
                if filter.is_non_negative() {
                    for level in mips_rgba16f(w as u32, h as u32, &px, &settings(Usage::Hdr, filter, edge)).unwrap() {
                        assert!(level.iter().all(|&v| v == hdr), "hdr {w}x{h} {filter:?} {edge:?}");
                    }
                }
            }
        }
    }
}

#[test]
fn the_mean_is_preserved_with_wrap_and_variance_does_not_grow() {
    let mut rng = Lcg(7);
    let img = image(64, 64, |_, _| [rng.next(), rng.next(), rng.next(), 1.0]);
    for filter in Filter::ALL {
        let mut prev = img.clone();
        for level in levels_f32(&img, &settings(Usage::Data, filter, Edge::Wrap)) {
            for c in 0..3 {
                let mean = |i: &Image| i.texels.iter().map(|t| t[c] as f64).sum::<f64>() / i.texels.len() as f64;
                let var = |i: &Image, m: f64| i.texels.iter().map(|t| (t[c] as f64 - m).powi(2)).sum::<f64>() / i.texels.len() as f64;
                let (m0, m1) = (mean(&prev), mean(&level));
                assert!((m1 - m0).abs() <= 1e-6 * m0.abs().max(1e-3) * 10.0, "{filter:?} {}x{}: mean {m0} -> {m1}", level.width, level.height);
                assert!(var(&level, m1) <= var(&prev, m0) + 1e-9, "{filter:?}: variance grew");
            }
            prev = level;
        }
    }
}

#[test]
fn a_one_pixel_srgb_checker_filters_to_the_linear_light_mean_188() {
    let px = rgba8(16, 16, |x, y| if (x + y) % 2 == 0 { [0, 0, 0, 255] } else { [255, 255, 255, 255] });
    let levels = mips_rgba8(16, 16, &px, &MipSettings::new(Usage::Color)).unwrap();
    for (l, level) in levels.iter().enumerate() {
        // 0.5 linear encodes to 0.73536 = 187.5 -> 188; a gamma-naive filter gives 128.
        assert!(level.chunks_exact(4).all(|t| t == [188, 188, 188, 255]), "level {}: {:?}", l + 1, &level[..8]);
    }
}

/// 1D sinusoid transfer (§1.13 test 3): output amplitude over input amplitude for m cycles over
/// 64 texels, after one 2:1 level with wrap.
fn transfer(filter: Filter, m: usize) -> f32 {
    let n = 64;
    let phase = 0.3f32;
    let img = image(n, 1, |x, _| {
        let v = 0.5 + 0.5 * (2.0 * std::f32::consts::PI * (m * x) as f32 / n as f32 + phase).cos();
        [v, v, v, 1.0]
    });
    let out = &levels_f32(&img, &settings(Usage::Data, filter, Edge::Wrap))[0];
    // Project onto the frequency the input had, sampled at the output centres 2i + 0.5.
    let (mut re, mut im) = (0.0f32, 0.0f32);
    for (i, t) in out.texels.iter().enumerate() {
        let a = 2.0 * std::f32::consts::PI * (m as f32 / n as f32) * (2.0 * i as f32 + 0.5) + phase;
        re += (t[0] - 0.5) * a.cos();
        im += (t[0] - 0.5) * a.sin();
    }
    2.0 * (re * re + im * im).sqrt() / out.width as f32 / 0.5
}

#[test]
fn sinusoid_transfer_matches_the_notes_and_box_leaks_above_nyquist() {
    let alias = transfer(Filter::Mitchell, 24);
    let pass = transfer(Filter::Mitchell, 8);
    assert!((alias - 0.047).abs() < 0.002 && alias <= 0.10, "mitchell H(0.375) = {alias}");
    assert!((pass - 0.843).abs() < 0.002 && pass >= 0.6, "mitchell H(0.125) = {pass}");
    let box_alias = transfer(Filter::Box, 24);
    assert!((box_alias - 0.383).abs() < 0.002 && box_alias > 0.10, "box H(0.375) = {box_alias}");
    assert!((transfer(Filter::Tent, 24) - 0.056).abs() < 0.002);
    assert!((transfer(Filter::BSpline, 24) - 0.007).abs() < 0.002);
}

/// The zone plate of §1.13 test 4 through `level` levels of the chain: (alias RMS, pass RMS).
/// Alias: where the local frequency, in texels of the level before, lies in [0.3, 0.5] (above
/// the new Nyquist limit, so the ideal output is flat 0.5). Pass: where it is <= 0.1.
pub(crate) fn zone_plate(filter: Filter, n: usize, level: usize) -> (f64, f64) {
    let f = |x: f64, y: f64| 0.5 + 0.5 * (std::f64::consts::PI * (x * x + y * y) / (2.0 * n as f64)).cos();
    let img = image(n, n, |x, y| {
        let v = f(x as f64, y as f64) as f32;
        [v, v, v, 1.0]
    });
    let levels = levels_f32(&img, &settings(Usage::Data, filter, Edge::Clamp));
    let out = &levels[level - 1];
    let step = (1usize << level) as f64; // level-0 texels per output texel
    let prev_step = step / 2.0;
    let (mut alias, mut na, mut pass, mut np) = (0.0, 0, 0.0, 0);
    for i in 0..out.height {
        for j in 0..out.width {
            let (x, y) = (step * (j as f64 + 0.5) - 0.5, step * (i as f64 + 0.5) - 0.5);
            let freq = (x * x + y * y).sqrt() / (2.0 * n as f64) * prev_step;
            let v = out.texels[i * out.width + j][0] as f64;
            if (0.3..=0.5).contains(&freq) {
                alias += (v - 0.5).powi(2);
                na += 1;
            } else if freq <= 0.1 {
                pass += (v - f(x, y)).powi(2);
                np += 1;
            }
        }
    }
    ((alias / na as f64).sqrt(), (pass / np as f64).sqrt())
}

#[test]
fn zone_plate_default_filter_passes_the_alias_gate_and_box_fails_it() {
    let default = Usage::Color.default_filter();
    for level in 1..=3 {
        let (alias, pass) = zone_plate(default, 512, level);
        eprintln!("zone plate {} level {level}: alias RMS {alias:.4}, pass RMS {pass:.4}", default.name());
        assert!(alias <= 0.05, "{default:?} level {level}: alias RMS {alias}");
        assert!(pass <= 0.06, "{default:?} level {level}: pass RMS {pass}");
    }
    let (alias, pass) = zone_plate(Filter::Box, 512, 1);
    eprintln!("zone plate box level 1: alias RMS {alias:.4}, pass RMS {pass:.4}");
    assert!(alias > 0.05, "the box filter must fail the alias gate (alias RMS {alias}): the test has teeth");
    for f in Filter::ALL {
        let (a, p) = zone_plate(f, 256, 1);
        eprintln!("zone plate N=256 {:12} alias {a:.4} pass {p:.4}", f.name());
    }
}

#[test]
fn premultiplied_alpha_leaves_no_green_fringe() {
    // Columns 0-2 opaque red, column 3 transparent "garbage" green: the boundary falls inside
    // a 2x2 block.
    let px = rgba8(4, 4, |x, _| if x < 3 { [255, 0, 0, 255] } else { [0, 255, 0, 0] });
    for filter in Filter::ALL {
        let levels = mips_rgba8(4, 4, &px, &settings(Usage::Color, filter, Edge::Clamp)).unwrap();
        for (l, level) in levels.iter().enumerate() {
            for t in level.chunks_exact(4).filter(|t| t[3] > 0) {
                assert_eq!(t[1], 0, "{filter:?} level {}: texel {t:?} has green", l + 1);
                assert_eq!(t[0], 255, "{filter:?} level {}: texel {t:?} is not full red", l + 1);
            }
        }
    }
    // With the box, alpha at the boundary texel is the coverage average 0.5.
    let boxed = mips_rgba8(4, 4, &px, &settings(Usage::Color, Filter::Box, Edge::Clamp)).unwrap();
    assert_eq!(&boxed[0][4..8], &[255, 0, 0, 128]);
}

/// A foliage-like alpha: thin antialiased leaves (about 3 texels wide) on transparency.
fn foliage(n: usize) -> Vec<u8> {
    let mut rng = Lcg(11);
    let leaves: Vec<[f32; 5]> = (0..n * n / 150)
        .map(|_| [rng.next() * n as f32, rng.next() * n as f32, rng.next() * std::f32::consts::PI, 6.0 + 8.0 * rng.next(), 1.2 + 0.8 * rng.next()])
        .collect();
    let mut alpha = vec![0f32; n * n];
    for &[cx, cy, angle, len, wid] in &leaves {
        let (s, c) = angle.sin_cos();
        let r = len.ceil() as i32 + 2;
        for dy in -r..=r {
            for dx in -r..=r {
                let (x, y) = ((cx as i32 + dx).rem_euclid(n as i32) as usize, (cy as i32 + dy).rem_euclid(n as i32) as usize);
                let (px, py) = (dx as f32 + 0.5 - cx.fract(), dy as f32 + 0.5 - cy.fract());
                let (u, v) = (px * c + py * s, -px * s + py * c);
                let d = ((u / len).powi(2) + (v / wid).powi(2)).sqrt(); // 1 on the leaf's outline
                let a = ((1.0 - d) * len.min(wid * 3.0) + 0.5).clamp(0.0, 1.0);
                alpha[y * n + x] = alpha[y * n + x].max(a);
            }
        }
    }
    alpha.iter().flat_map(|&a| [40, 120, 30, (a * 255.0).round() as u8]).collect()
}

fn coverage(level: &[u8], cutoff: f32) -> f64 {
    level.chunks_exact(4).filter(|t| alpha_kept(t[3], cutoff)).count() as f64 / (level.len() / 4) as f64
}

#[test]
fn alpha_tested_coverage_holds_within_two_percent_at_every_level() {
    let n = 256;
    let px = foliage(n);
    let c0 = coverage(&px, 0.5);
    assert!((0.15..0.6).contains(&c0), "level 0 coverage {c0}");
    let mut s = MipSettings::new(Usage::Color);
    let plain = mips_rgba8(n as u32, n as u32, &px, &s).unwrap();
    s.alpha_cutoff = Some(0.5);
    let kept = mips_rgba8(n as u32, n as u32, &px, &s).unwrap();
    let mut worst_plain = 0.0f64;
    for (l, (p, k)) in plain.iter().zip(&kept).enumerate() {
        let texels = k.len() / 4;
        let (cp, ck) = (coverage(p, 0.5), coverage(k, 0.5));
        eprintln!("level {} ({texels} texels): coverage {ck:.4} kept vs {cp:.4} plain, level 0 {c0:.4}", l + 1);
        // Below 50 texels one texel is more than 2%: there the bound is half a texel's share.
        let bound = 0.02f64.max(0.5 / texels as f64);
        assert!((ck - c0).abs() <= bound, "level {}: coverage {ck} vs level 0 {c0}", l + 1);
        if texels >= 64 {
            worst_plain = worst_plain.max((cp - c0).abs());
        }
        // Only alpha changes.
        assert!(p.chunks_exact(4).zip(k.chunks_exact(4)).all(|(a, b)| a[..3] == b[..3]));
    }
    assert!(worst_plain > 0.02, "without the rescale coverage should drift (worst {worst_plain}): the test has teeth");
}

#[test]
fn normal_map_levels_are_unit_vectors() {
    let n = 64;
    // Normals of a bumpy height field, and its 8-bit encoding.
    let h = |x: f32, y: f32| (x * 0.7).sin() * (y * 0.45).cos() * 2.0 + (x * 2.3 + y * 1.7).sin();
    let px = rgba8(n, n, |x, y| {
        let (x, y) = (x as f32, y as f32);
        let (dx, dy) = (h(x + 0.5, y) - h(x - 0.5, y), h(x, y + 0.5) - h(x, y - 0.5));
        let l = (dx * dx + dy * dy + 1.0).sqrt();
        let v = [-dx / l, -dy / l, 1.0 / l];
        [0, 1, 2].map(|c| ((v[c] * 0.5 + 0.5) * 255.0).round() as u8).into_iter().chain([255]).collect::<Vec<_>>().try_into().unwrap()
    });
    let s = MipSettings::new(Usage::Normal);
    let img = image(n, n, |x, y| {
        let t = &px[(y * n + x) * 4..][..4];
        [unorm_to_snorm(t[0]), unorm_to_snorm(t[1]), unorm_to_snorm(t[2]), 1.0]
    });
    let mut worst_f32 = 0.0f32;
    for level in levels_f32(&img, &s) {
        for t in &level.texels {
            let f = finish_texel(Usage::Normal, *t);
            worst_f32 = worst_f32.max(((f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt() - 1.0).abs());
        }
    }
    assert!(worst_f32 <= 1e-3, "f32 level normal length error {worst_f32}");
    // What the pack stores: every texel of every level, level 0 included, 16-bit UNORM.
    let unit_error = |t: &[u16]| {
        let v = [0, 1, 2].map(|c| t[c] as f64 / 65535.0 * 2.0 - 1.0);
        ((v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt() - 1.0).abs()
    };
    let stored = normal_levels(n as u32, n as u32, NormalTexels::Unorm8(&px), &s).unwrap();
    assert_eq!(stored.len(), level_count(n as u32, n as u32) as usize);
    let worst_stored = stored.iter().flat_map(|l| l.chunks_exact(4)).map(unit_error).fold(0.0, f64::max);
    // The 8-bit input itself is not unit length: the re-encode of level 0 is what fixes it.
    let worst_input = px.chunks_exact(4).map(|t| unit_error(&[t[0], t[1], t[2]].map(|b| b as u16 * 257))).fold(0.0, f64::max);
    eprintln!("normal length error: f32 {worst_f32:e}, stored 16-bit {worst_stored:e}, 8-bit input {worst_input:e}");
    assert!(worst_stored <= 1e-3, "stored normal length error {worst_stored}");
    assert!(worst_input > 1e-3, "the 8-bit input should miss the gate ({worst_input}): the test has teeth");
    // 16-bit input takes the same path.
    let px16: Vec<u16> = px.iter().map(|&b| b as u16 * 257).collect();
    assert_eq!(normal_levels(n as u32, n as u32, NormalTexels::Unorm16(&px16), &s).unwrap(), stored);

    // Flat stays exactly flat: (0, 0, 1) encodes to (32768, 32768, 65535) at every level.
    let flat: Vec<u16> = (0..8 * 8).flat_map(|_| [32768, 32768, 65535, 65535]).collect();
    let flat_levels = normal_levels(8, 8, NormalTexels::Unorm16(&flat), &s).unwrap();
    assert!(flat_levels.iter().flatten().collect::<Vec<_>>().chunks_exact(4).all(|t| [*t[0], *t[1], *t[2]] == [32768, 32768, 65535]));
    // Opposite tilts average to flat.
    let tilts = rgba8(8, 8, |x, _| if x % 2 == 0 { [218, 128, 218, 255] } else { [37, 128, 218, 255] });
    let l1 = &normal_levels(8, 8, NormalTexels::Unorm8(&tilts), &settings(Usage::Normal, Filter::Box, Edge::Wrap)).unwrap()[1];
    assert!(l1.chunks_exact(4).all(|t| t[0].abs_diff(32768) <= 300 && t[2] >= 65534), "{:?}", &l1[..4]);
    // 8-bit chains refuse normal maps rather than store them short.
    assert!(mips_rgba8(8, 8, &tilts, &s).unwrap_err().contains("16-bit"));
}

#[test]
fn a_1e4_hdr_texel_never_makes_a_negative_texel_and_flux_is_conserved() {
    let n = 64;
    let zero = half::f16::from_f32(0.0).to_bits();
    let mut px = vec![zero; n * n * 4];
    for c in 0..3 {
        px[(20 * n + 37) * 4 + c] = half::f16::from_f32(1e4).to_bits();
    }
    for filter in [Filter::Tent, Filter::BSpline, Filter::Box] {
        let levels = mips_rgba16f(n as u32, n as u32, &px, &settings(Usage::Hdr, filter, Edge::Wrap)).unwrap();
        let f = |b: &u16| half::f16::from_bits(*b).to_f32();
        let mut prev_flux = 1e4f64;
        for (l, level) in levels.iter().enumerate() {
            let min = level.iter().map(f).fold(f32::INFINITY, f32::min);
            assert!(min >= 0.0, "{filter:?} level {}: texel {min}", l + 1);
            let side = (n >> (l + 1)) as f64;
            let flux = level.chunks_exact(4).map(|t| f(&t[0]) as f64).sum::<f64>() * (n as f64 / side).powi(2);
            assert!((flux - prev_flux).abs() <= 1e-2 * prev_flux, "{filter:?} level {}: flux {flux} vs {prev_flux}", l + 1);
            prev_flux = flux;
        }
        assert!(levels[0].iter().map(f).fold(0.0, f32::max) > 1.0, "clipped to 1");
    }
    let err = mips_rgba16f(n as u32, n as u32, &px, &settings(Usage::Hdr, Filter::Mitchell, Edge::Wrap)).unwrap_err();
    assert!(err.contains("negative lobes"), "{err}");
}

#[test]
fn odd_sizes_place_output_centres_at_the_level_spacing() {
    // A ramp v = x over 65 texels maps to -0.5 + dx (i + 0.5) with dx = 65/32, in the interior.
    let img = image(65, 1, |x, _| [x as f32, 0.0, 0.0, 1.0]);
    let l1 = &levels_f32(&img, &settings(Usage::Hdr, Filter::Mitchell, Edge::Clamp))[0];
    assert_eq!(l1.width, 32);
    for i in 2..30 {
        let want = -0.5 + 65.0 / 32.0 * (i as f32 + 0.5);
        assert!((l1.texels[i][0] - want).abs() < 1e-3, "texel {i}: {} vs {want}", l1.texels[i][0]);
    }
    let taps = Taps::downsample(5, 2, Filter::Box, Edge::Clamp);
    assert_eq!(taps.len(), 2);
    // Box of width 2.5 around 0.75 and 3.25: every input texel contributes.
    let mut used: Vec<usize> = (0..2).flat_map(|i| taps.of(i).map(|(j, _)| j).collect::<Vec<_>>()).collect();
    used.sort();
    used.dedup();
    assert_eq!(used, [0, 1, 2, 3, 4]);
}

#[test]
fn output_does_not_depend_on_the_thread_count() {
    let px = foliage(128);
    let s = MipSettings { alpha_cutoff: Some(0.5), ..MipSettings::new(Usage::Color) };
    let many = mips_rgba8(128, 128, &px, &s).unwrap();
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(|| mips_rgba8(128, 128, &px, &s).unwrap());
    assert_eq!(many, one);
}

#[test]
fn bad_input_is_a_one_line_error() {
    let s = MipSettings::new(Usage::Color);
    assert_eq!(mips_rgba8(4, 4, &[0; 10], &s).unwrap_err(), "10 values for 4x4 RGBA (expected 64)");
    assert!(mips_rgba8(0, 4, &[], &s).unwrap_err().contains("empty"));
    assert!(Usage::parse("albedo").unwrap_err().contains("expected color, data, normal or hdr"));
    assert!(Filter::parse("cubic").unwrap_err().contains("mitchell"));
    let nan = vec![half::f16::NAN.to_bits(); 16];
    assert_eq!(mips_rgba16f(2, 2, &nan, &MipSettings::new(Usage::Hdr)).unwrap_err(), "texel (0, 0) is not finite");
    let cut = MipSettings { alpha_cutoff: Some(1.5), ..s };
    assert!(mips_rgba8(1, 1, &[0; 4], &cut).unwrap_err().contains("alpha cutoff"));
}



#[test]
fn each_axis_filters_across_its_edge_as_the_sampler_reads_it() {
    // A ramp along x, constant along y: level 1 at the left edge reads past texel 0, where a
    // repeating texture continues with the right end, a mirrored one with texel 0 again and a
    // clamped one nothing (renormalised).
    let (w, h) = (8, 8);
    let img = image(w, h, |x, _| [x as f32, 0.0, 0.0, 1.0]);
    let left = |edges: [Edge; 2]| {
        let s = MipSettings { usage: Usage::Data, filter: Filter::Tent, edges, alpha_cutoff: None };
        levels_f32(&img, &s)[0].row(0)[0][0]
    };
    let (wrap, clamp, mirror) = (left([Edge::Wrap, Edge::Clamp]), left([Edge::Clamp, Edge::Wrap]), left([Edge::Mirror, Edge::Clamp]));
    // Tent at 2:1 centred on x = 0.5 reads x = -1..2 with weights 1/8, 3/8, 3/8, 1/8.
    assert!((wrap - (7.0 / 8.0 + 0.0 + 3.0 / 8.0 + 2.0 / 8.0)).abs() < 1e-5, "{wrap}");
    assert!((mirror - (0.0 + 0.0 + 3.0 / 8.0 + 2.0 / 8.0)).abs() < 1e-5, "{mirror}");
    assert!((clamp - (3.0 / 7.0 + 2.0 / 7.0)).abs() < 1e-5, "{clamp}");
    // The other axis is constant whatever its edge.
    assert!(levels_f32(&img, &settings(Usage::Data, Filter::Tent, Edge::Mirror))[0].row(3)[1][0] > 0.0);
    assert_eq!(Edge::parse_axes("wrap,mirror"), Ok([Edge::Wrap, Edge::Mirror]));
    assert_eq!(Edge::parse_axes("clamp"), Ok([Edge::Clamp; 2]));
    assert!(Edge::parse_axes("wrap,bounce").unwrap_err().contains("unknown edge mode 'bounce'"));
}
