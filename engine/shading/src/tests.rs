//! The brief's numbers (`../shared/notes/shading.md` §6, §7.1-7.2).

use super::*;

fn close(got: f64, want: f64, tol: f64, what: &str) {
    assert!((got - want).abs() <= tol, "{what}: {got}, expected {want} (±{tol})");
}

/// A view at `deg` from the normal +Z.
fn view(deg: f64) -> DVec3 {
    let t = deg.to_radians();
    DVec3::new(t.sin(), 0.0, t.cos())
}

#[test]
fn ggx_is_normalised_for_any_alpha() {
    // ∫ D(n·h) (n·h) dω_h = 2π ∫₀¹ D(μ) μ dμ = 1. Midpoint rule in μ² (D is peaked at μ = 1).
    for r in [0.1, 0.3, 0.5, 0.8, 1.0] {
        let a = alpha(r);
        let n = 200_000;
        let mut s = 0.0;
        for k in 0..n {
            // u = μ², du = 2μ dμ: ∫ D(μ) μ dμ = ½ ∫ D(√u) du
            let u = (k as f64 + 0.5) / n as f64;
            s += 0.5 * d_ggx(u.sqrt(), a) / n as f64;
        }
        close(2.0 * PI * s, 1.0, 1e-3, &format!("∫D cos at r {r}"));
    }
}

#[test]
fn the_brdf_is_reciprocal() {
    let m = Material { base: DVec3::new(0.8, 0.5, 0.2), metallic: 0.3, roughness: 0.4 };
    let n = DVec3::Z;
    for (a, b) in [(10.0, 60.0), (35.0, -20.0), (70.0, 5.0)] {
        let (v, l) = (view(a), DVec3::new(0.3, 0.4, 0.0).normalize().lerp(view(b), 0.8).normalize());
        let (f, g) = (m.brdf(n, v, l), m.brdf(n, l, v));
        assert!((f - g).abs().max_element() < 1e-12, "f(v,l) {f} != f(l,v) {g}");
    }
}

#[test]
fn white_furnace_matches_the_brief_and_never_gains_energy() {
    // §6a: E(v) = f0 A + B for f0 0.04 and 1 at 0°, 45°, 75°.
    let table = [
        (0.1, [0.0400, 0.0421, 0.2538], [0.9999, 0.9998, 0.9992]),
        (0.3, [0.0396, 0.0427, 0.2010], [0.9907, 0.9854, 0.9345]),
        (0.5, [0.0367, 0.0395, 0.1084], [0.9158, 0.8862, 0.8393]),
        (0.8, [0.0223, 0.0251, 0.0497], [0.5552, 0.5811, 0.7132]),
        (1.0, [0.0123, 0.0159, 0.0336], [0.3069, 0.3768, 0.5906]),
    ];
    for (r, dielectric, metal) in table {
        for (k, deg) in [0.0f64, 45.0, 75.0].into_iter().enumerate() {
            let nv = deg.to_radians().cos();
            let (ed, em) = (specular_albedo(0.04, nv, r), specular_albedo(1.0, nv, r));
            // "within 2%" of the brief's four digits
            close(ed, dielectric[k], 0.02 * dielectric[k], &format!("dielectric r {r} at {deg}°"));
            close(em, metal[k], 0.02 * metal[k], &format!("metal r {r} at {deg}°"));
            assert!(em <= 1.0 + 1e-9, "a white metal returns {em} > 1 at r {r}, {deg}°");
        }
    }
    // Closed form: r = 1, normal view, f0 = 1 reflects 1 − ln 2.
    close(specular_albedo(1.0, 1.0, 1.0), 1.0 - 2f64.ln(), 5e-4, "1 − ln 2");
}

#[test]
fn the_sun_peak_in_nits() {
    // §6b: n = v = l, E⊥ = 100 000 lux: L_spec = f0 E / (4π r⁴).
    let n = DVec3::Z;
    for (r, want) in [(0.5, 5092.96), (0.1, 3_183_099.0), (0.3, 39_297.5), (0.8, 777.1), (1.0, 318.3)] {
        let (_, s) = Material::dielectric(1.0, r).brdf_parts(n, n, n);
        close(s.x * 1e5, want, want * 1e-4, &format!("specular peak at r {r}"));
    }
    // Diffuse at the same point, white base: 0.96 E / π; total 35 650.7 nits at r 0.5.
    let white = Material::dielectric(1.0, 0.5);
    close(white.brdf_parts(n, n, n).0.x * 1e5, 30_557.7, 0.1, "white diffuse");
    close(white.sunlit(n, n, n, 1e5).x, 35_650.7, 0.1, "white total");
    // Sun at 45°, seen in the mirror direction: 7348.96 nits.
    let (v, l) = (view(45.0), view(-45.0));
    close(white.brdf_parts(n, v, l).1.x * 1e5 * (45f64).to_radians().cos(), 7348.96, 0.05, "45° mirror");
}

#[test]
fn dfg_lut_points_and_bounds() {
    // §6c's points (the texel centres of a 32² table at (i + ½)/32), ±2·10⁻³.
    for ((i, j), (a, b)) in [((15, 15), (0.84034, 0.02596)), ((3, 28), (0.75904, 0.03145)), ((7, 3), (0.73748, 0.26102))] {
        let (ga, gb) = dfg((i as f64 + 0.5) / 32.0, (j as f64 + 0.5) / 32.0);
        close(ga, a, 2e-3, &format!("A at §6c point ({i}, {j})"));
        close(gb, b, 2e-3, &format!("B at §6c point ({i}, {j})"));
    }
    // The engine's table spans both ranges end to end: texel (i, j) is (i/31, j/31), and its
    // corner is a white metal at r = 1 seen head-on, 1 − ln 2 in all (§6a).
    let lut = DfgLut::new(32);
    for (i, j) in [(0, 0), (15, 15), (3, 28), (31, 31)] {
        let (a, b) = dfg(i as f64 / 31.0, j as f64 / 31.0);
        let k = 1.0 / (a + b).max(1.0);
        assert_eq!(lut.at(i, j), [(a * k) as f32, (b * k) as f32], "texel ({i}, {j})");
    }
    let [a, b] = lut.at(31, 31);
    close((a + b) as f64, 1.0 - std::f64::consts::LN_2, 2e-3, "A + B at n·v = 1, r = 1");
    // And the table's points away from texel centres.
    for (nv, r, a, b) in [(0.5, 0.5, 0.8349, 0.0223), (0.05, 0.1, 0.2425, 0.7337), (0.25, 1.0, 0.5868, 0.0109), (1.0, 0.75, 0.6268, 0.0)] {
        let (ga, gb) = dfg(nv, r);
        close(ga, a, 2e-3, &format!("A({nv}, {r})"));
        close(gb, b, 2e-3, &format!("B({nv}, {r})"));
    }
    for j in 0..32 {
        for i in 0..32 {
            let [a, b] = lut.at(i, j);
            // (5e-5: the quadrature's error on the sharpest lobes; the table is stored in fp16.)
            assert!(a >= 0.0 && b >= 0.0 && a + b <= 1.0 + 5e-5, "A + B = {} at ({i}, {j})", a + b);
        }
        // At n·v → 1 the albedo falls as the lobe widens.
        if j > 0 {
            assert!(lut.at(31, j)[0] <= lut.at(31, j - 1)[0] + 5e-5, "A not monotone in r at n·v ≈ 1, row {j}");
        }
    }
}

#[test]
fn full_dielectric_exceeds_one_only_at_grazing_view() {
    // §6a: the spec's fresnel_mix with a white base, by quadrature over the hemisphere of l.
    let n = DVec3::Z;
    let albedo = |m: &Material, v: DVec3| {
        let k = 512;
        let mut s = DVec3::ZERO;
        for a in 0..k {
            for b in 0..k {
                // cosine-weighted grid: l = (√u cos φ, √u sin φ, √(1-u)), pdf cos/π
                let (u, phi) = ((a as f64 + 0.5) / k as f64, 2.0 * PI * (b as f64 + 0.5) / k as f64);
                let l = DVec3::new(u.sqrt() * phi.cos(), u.sqrt() * phi.sin(), (1.0 - u).sqrt());
                s += m.brdf(n, v, l) * PI;
            }
        }
        (s / (k * k) as f64).x
    };
    let m = Material::dielectric(1.0, 1.0);
    close(albedo(&m, view(0.0)), 0.9722, 0.01, "r 1 at 0°");
    close(albedo(&m, view(75.0)), 0.9815, 0.01, "r 1 at 75°");
    let half = Material::dielectric(1.0, 0.5);
    close(albedo(&half, view(0.0)), 0.9966, 0.01, "r 0.5 at 0°");
    close(albedo(&half, view(75.0)), 1.0563, 0.015, "r 0.5 at 75°");
}

#[test]
fn the_engines_precomputed_dfg_table_is_the_integral() {
    // dfg_table.rs is generated by examples/dfg_table.rs from DfgLut::new: it must stay that.
    // (1e-6: a libm's last-place differences; the GPU reads the table as fp16, ~5e-4 apart.)
    let (engine, computed) = (DfgLut::engine(), DfgLut::new(DFG_TABLE_SIZE));
    assert_eq!(engine.size, computed.size);
    for (k, (e, c)) in engine.texels.iter().zip(&computed.texels).enumerate() {
        assert!((e[0] - c[0]).abs() <= 1e-6 && (e[1] - c[1]).abs() <= 1e-6,
            "texel {k}: dfg_table.rs has {e:?}, DfgLut::new {c:?}: regenerate it with `cargo run --release -p shading --example dfg_table > engine/shading/src/dfg_table.rs`");
    }
}
