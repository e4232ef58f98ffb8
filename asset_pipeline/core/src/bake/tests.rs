//! Baker tests: BVH against brute force (random and degenerate soups), and the integrator
//! against the closed-form scenes of notes §10.

use super::bvh::*;
use super::integrator::*;
use super::lights::Light;
use super::probes::*;
use super::sampling::*;
use std::f32::consts::PI;
use std::sync::atomic::AtomicBool;

pub(super) fn rand3(r: &mut Rng, lo: f32, hi: f32) -> V3 {
    [0, 1, 2].map(|_| lo + (hi - lo) * r.next_f32())
}

/// Closest-hit equals brute force (same t; a different prim only on a tie), and any-hit with a
/// random tmax agrees with closest-hit.
fn check_against_brute(pos: &[V3], tris: &[[u32; 3]], rays: &[Ray]) {
    let bvh = Bvh::build(pos, tris);
    bvh.assert_boxes_nested();
    let mut hits = 0;
    for (i, ray) in rays.iter().enumerate() {
        let a = bvh.closest(ray);
        let b = closest_brute(pos, tris, ray);
        match (a, b) {
            (None, None) => {}
            (Some(a), Some(b)) => {
                hits += 1;
                assert_eq!(a.t, b.t, "ray {i}: {ray:?}");
                if a.prim != b.prim {
                    let tri = tris[a.prim as usize].map(|v| pos[v as usize]);
                    assert_eq!(intersect_triangle(&Ray { tmax: f32::INFINITY, ..*ray }, &tri), Some(a.t), "ray {i}: tie");
                }
            }
            _ => panic!("ray {i}: bvh {a:?} brute {b:?} ({ray:?})"),
        }
        let t = a.map_or(f32::INFINITY, |h| h.t);
        assert_eq!(bvh.any(ray), t < ray.tmax, "ray {i}");
        // Shadow query with a cut: hit within tmax iff the closest t is below it.
        let cut = Ray { tmax: if t.is_finite() { t * 1.0001 } else { 10.0 }, ..*ray };
        assert_eq!(bvh.any(&cut), a.is_some(), "ray {i} cut");
        let short = Ray { tmax: if t.is_finite() { t * 0.999 } else { 10.0 }, ..*ray };
        let expect = bvh.closest(&short).is_some();
        assert_eq!(bvh.any(&short), expect, "ray {i} short");
    }
    assert!(hits > 0);
}

pub(super) fn random_rays(r: &mut Rng, n: usize, lo: f32, hi: f32) -> Vec<Ray> {
    (0..n)
        .map(|_| {
            let mut dir = sub(rand3(r, -1.0, 1.0), [0.0; 3]);
            if r.next_f32() < 0.1 {
                // Axis-aligned, with signed zeros: the slab test's IEEE cases (T4).
                let k = (r.next_u32() % 3) as usize;
                dir = [if r.next_f32() < 0.5 { 0.0 } else { -0.0 }; 3];
                dir[k] = if r.next_f32() < 0.5 { 1.0 } else { -1.0 };
            }
            Ray { origin: rand3(r, lo, hi), dir, tmin: 0.0, tmax: f32::INFINITY }
        })
        .collect()
}

#[test]
fn bvh_matches_brute_force_on_random_soup() {
    let mut r = Rng::for_sample(1, 0, 0);
    let mut pos = Vec::new();
    let mut tris = Vec::new();
    for i in 0..3000u32 {
        let c = rand3(&mut r, -10.0, 10.0);
        for _ in 0..3 {
            pos.push(add(c, rand3(&mut r, -1.0, 1.0)));
        }
        tris.push([3 * i, 3 * i + 1, 3 * i + 2]);
    }
    let rays = random_rays(&mut r, 20000, -12.0, 12.0);
    check_against_brute(&pos, &tris, &rays);
}

#[test]
fn bvh_matches_brute_force_on_degenerate_soups() {
    let mut r = Rng::for_sample(2, 0, 0);
    // Axis-aligned coplanar sheet (grid in z = 0 sharing edges), duplicated triangles,
    // zero-area triangles (collinear and single-point), at huge and tiny scales.
    for s in [1e-6f32, 1.0, 1e6] {
        let mut pos = Vec::new();
        let mut tris = Vec::new();
        let g = 20u32;
        for y in 0..=g {
            for x in 0..=g {
                pos.push([x as f32 * s, y as f32 * s, 0.0]);
            }
        }
        for y in 0..g {
            for x in 0..g {
                let i = y * (g + 1) + x;
                tris.push([i, i + 1, i + g + 2]);
                tris.push([i, i + g + 2, i + g + 1]);
            }
        }
        let dup = tris.clone();
        tris.extend(dup.iter().take(100));
        for _ in 0..200 {
            let a = rand3(&mut r, 0.0, 20.0 * s);
            let b = rand3(&mut r, 0.0, 20.0 * s);
            let base = pos.len() as u32;
            pos.extend([a, b, add(a, scale(sub(b, a), 0.5))]); // collinear
            pos.push(a); // a point
            tris.push([base, base + 1, base + 2]);
            tris.push([base + 3, base + 3, base + 3]);
        }
        // Rays from random points, from points on the sheet (tmin 0), and in the sheet's plane.
        let mut rays = random_rays(&mut r, 4000, -2.0 * s, 22.0 * s);
        for _ in 0..4000 {
            let mut o = rand3(&mut r, 0.0, 20.0 * s);
            o[2] = 0.0;
            let mut d = rand3(&mut r, -1.0, 1.0);
            if r.next_f32() < 0.3 {
                d[2] = 0.0;
            }
            rays.push(Ray { origin: o, dir: d, tmin: 0.0, tmax: f32::INFINITY });
        }
        // Rays aimed exactly at shared grid vertices and edge midpoints: must never slip through.
        let bvh = Bvh::build(&pos, &tris);
        for k in 0..2000 {
            let x = (k % 19 + 1) as f32 * s;
            let y = ((k / 19) % 19 + 1) as f32 * s + if k % 2 == 0 { 0.0 } else { 0.5 * s };
            let o = [x + (r.next_f32() - 0.5) * 3.0 * s, y + (r.next_f32() - 0.5) * 3.0 * s, 5.0 * s];
            let ray = Ray { origin: o, dir: sub([x, y, 0.0], o), tmin: 0.0, tmax: f32::INFINITY };
            assert!(bvh.closest(&ray).is_some(), "ray through a shared vertex/edge slipped through: {ray:?}");
            rays.push(ray);
        }
        check_against_brute(&pos, &tris, &rays);
    }
}

#[test]
fn bvh_matches_brute_force_on_long_thin_triangles() {
    // Slivers spanning the scene in every direction (pre-split into many references), a big
    // ground quad and a fan sharing one vertex: the same closest t as brute force.
    let mut r = Rng::for_sample(3, 0, 0);
    let mut pos = vec![[-30.0, 0.0, -30.0], [30.0, 0.0, -30.0], [30.0, 0.0, 30.0], [-30.0, 0.0, 30.0]];
    let mut tris = vec![[0, 1, 2], [0, 2, 3]];
    for _ in 0..400 {
        let a = rand3(&mut r, -25.0, 25.0);
        let b = rand3(&mut r, -25.0, 25.0);
        let c = add(a, rand3(&mut r, -0.05, 0.05));
        let base = pos.len() as u32;
        pos.extend([a, b, c]);
        tris.push([base, base + 1, base + 2]);
    }
    let hub = pos.len() as u32;
    pos.push([0.0, 5.0, 0.0]);
    for i in 0..64 {
        let (s0, c0) = (i as f32 * 0.1).sin_cos();
        let (s1, c1) = ((i + 1) as f32 * 0.1).sin_cos();
        let base = pos.len() as u32;
        pos.extend([[28.0 * c0, 5.0, 28.0 * s0], [28.0 * c1, 5.0, 28.0 * s1]]);
        tris.push([hub, base, base + 1]);
    }
    let rays = random_rays(&mut r, 20000, -28.0, 28.0);
    check_against_brute(&pos, &tris, &rays);
}

#[test]
fn empty_and_tiny_bvh() {
    let bvh = Bvh::build(&[], &[]);
    let ray = Ray { origin: [0.0; 3], dir: [0.0, 0.0, 1.0], tmin: 0.0, tmax: f32::INFINITY };
    assert!(bvh.closest(&ray).is_none() && !bvh.any(&ray));
    // T2: ray (1,1,1) + t(-1,-1,-1) hits the triangle (1,0,0),(0,1,0),(0,0,1) at t = 2/3.
    let pos = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let bvh = Bvh::build(&pos, &[[0, 1, 2]]);
    let h = bvh.closest(&Ray { origin: [1.0; 3], dir: [-1.0; 3], tmin: 0.0, tmax: f32::INFINITY }).unwrap();
    assert!((h.t - 2.0 / 3.0).abs() < 1e-6);
}

// ---- integrator --------------------------------------------------------------------------

struct Soup {
    pos: Vec<V3>,
    tris: Vec<[u32; 3]>,
    albedo: Vec<V3>,
    emission: Vec<V3>,
}

impl Soup {
    fn new() -> Soup {
        Soup { pos: vec![], tris: vec![], albedo: vec![], emission: vec![] }
    }
    /// Quad centred at c with half-extents u, v; front face along u x v.
    fn quad(&mut self, c: V3, u: V3, v: V3, albedo: f32, emission: f32) {
        let b = self.pos.len() as u32;
        self.pos.extend([sub(sub(c, u), v), sub(add(c, u), v), add(add(c, u), v), add(sub(c, u), v)]);
        self.tris.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
        self.albedo.extend([[albedo; 3]; 2]);
        self.emission.extend([[emission; 3]; 2]);
    }
    /// Axis-aligned box with faces pointing out (or in).
    fn cube(&mut self, c: V3, h: V3, inward: bool, albedo: f32, emission: f32) {
        for k in 0..3 {
            for s in [-1.0f32, 1.0] {
                let mut n = [0.0; 3];
                n[k] = s;
                let (a, b) = ((k + 1) % 3, (k + 2) % 3);
                let mut u = [0.0; 3];
                u[a] = h[a];
                let mut v = [0.0; 3];
                v[b] = h[b];
                // u x v points along +k; flip to get the wanted side.
                let out = s > 0.0;
                let v = if out != inward { v } else { scale(v, -1.0) };
                self.quad(add(c, scale(n, h[k])), u, v, albedo, emission);
            }
        }
    }
    fn scene(&self, lights: Vec<Light>, sky: Option<V3>) -> BakeScene {
        BakeScene::new(&self.pos, &self.tris, &self.albedo, &self.emission, lights, sky).unwrap()
    }
}

fn bake(scene: &BakeScene, pts: &[V3], nrm: &[V3], s: &BakeSettings) -> Baked {
    bake_points(scene, pts, nrm, None, s, &|_, _| {}, &AtomicBool::new(false)).unwrap()
}

fn settings(samples: u32, bounces: u32, seed: u64) -> BakeSettings {
    BakeSettings { samples, bounces, probe_samples: samples, seed }
}

fn lights(json: &str) -> Vec<Light> {
    Light::from_ir_json(json).unwrap()
}

/// Mean over points and its standard error (points are independent estimates).
fn mean_se(v: &[V3]) -> (f64, f64) {
    let m = mean(v);
    let var = v.iter().map(|x| (x[0] as f64 - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64;
    (m, (var / v.len() as f64).sqrt())
}

fn mean(v: &[V3]) -> f64 {
    v.iter().map(|x| x[0] as f64).sum::<f64>() / v.len() as f64
}

/// Irradiance at x (normal n) from a Lambertian polygon of radiance 1 (notes T12, Lambert's
/// formula): H = (1/2) |sum_i Theta_i (n . g_i)|.
fn polygon_irradiance(x: V3, n: V3, poly: &[V3]) -> f64 {
    let r: Vec<V3> = poly.iter().map(|p| normalize(sub(*p, x))).collect();
    let mut s = 0.0f64;
    for i in 0..r.len() {
        let (a, b) = (r[i], r[(i + 1) % r.len()]);
        let theta = (dot(a, b) as f64).clamp(-1.0, 1.0).acos();
        s += theta * dot(n, normalize(cross(a, b))) as f64;
    }
    0.5 * s.abs()
}

#[test]
fn t10_uniform_sky_gives_b_equal_l_exactly_even_far_and_tilted() {
    let sky = [0.3, 0.7, 1.9];
    for (c, tilt) in [([0.0f32; 3], 0.0f32), ([1.0e4, -2.0e4, 3.0e4], 0.4)] {
        let mut s = Soup::new();
        let (u, v) = ([1.0, 0.0, 0.0], normalize([0.0, tilt.cos(), tilt.sin()]));
        s.quad(c, scale(u, 5.0), scale(v, 5.0), 0.8, 0.0);
        let n = cross(u, v);
        let scene = s.scene(vec![], Some(sky));
        let mut r = Rng::for_sample(9, 0, 0);
        let pts: Vec<V3> = (0..64).map(|_| add(c, add(scale(u, 8.0 * r.next_f32() - 4.0), scale(v, 8.0 * r.next_f32() - 4.0)))).collect();
        let out = bake(&scene, &pts, &vec![n; pts.len()], &settings(64, 3, 1));
        for b in &out.b {
            for k in 0..3 {
                assert!((b[k] - sky[k]).abs() <= 1e-6 * sky[k], "{b:?} vs {sky:?} at {c:?}");
            }
        }
    }
}

#[test]
fn t15_closed_furnace() {
    // Every wall emits Le = 0.25 and reflects R = 0.5: L = Le/(1-R) = 0.5 everywhere; B = L.
    let mut s = Soup::new();
    s.cube([0.0; 3], [1.0, 1.5, 2.0], true, 0.5, 0.25);
    let scene = s.scene(vec![], None);
    let pts = vec![[0.3, -1.5, 0.2]; 64];
    let out = bake(&scene, &vec![[0.3, -1.5, 0.2]; 256], &vec![[0.0, 1.0, 0.0]; 256], &settings(512, 1000, 3));
    let (m, se) = mean_se(&out.b);
    assert!((m - 0.5).abs() < 0.005 && (m - 0.5).abs() < 4.0 * se, "furnace B = {m} (se {se}), want 0.5");
    // Depth-capped: k bounces keep Le (1 - R^(k+1)) / (1 - R) (0.25, 0.375, 0.4375).
    for (k, want) in [(0u32, 0.25f64), (1, 0.375), (2, 0.4375)] {
        let m = mean(&bake(&scene, &pts, &vec![[0.0, 1.0, 0.0]; 64], &settings(64, k, 4)).b);
        assert!((m - want).abs() < 0.01 * want, "{k} bounces: {m} want {want}");
    }
}

fn square_light_scene(as_triangles: bool, l: f32, h: f32, half: f32) -> (BakeScene, f64) {
    let mut s = Soup::new();
    s.quad([0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 0.0, -10.0], 0.0, 0.0); // floor, facing +y
    let json;
    let light = if as_triangles {
        s.quad([0.0, h, 0.0], [half, 0.0, 0.0], [0.0, 0.0, half], 0.0, l); // facing -y
        vec![]
    } else {
        json = format!(r#"[{{"name":"r","kind":"rect","intensity":{l},"position":[0,{h},0],"direction":[0,-1,0],"size":[{},{}]}}]"#, 2.0 * half, 2.0 * half);
        lights(&json)
    };
    let poly = [[-half, h, -half], [half, h, -half], [half, h, half], [-half, h, half]];
    let expect_b = l as f64 * polygon_irradiance([0.0; 3], [0.0, 1.0, 0.0], &poly) / PI as f64;
    (s.scene(light, None), expect_b)
}

#[test]
fn t11_on_axis_square_light_rect_and_emissive_triangles() {
    for tri in [false, true] {
        let (scene, want) = square_light_scene(tri, 2.0, 1.5, 1.0);
        let pts = vec![[0.0; 3]; 64];
        let out = bake(&scene, &pts, &vec![[0.0, 1.0, 0.0]; 64], &settings(512, 0, 5));
        let m = mean(&out.b);
        assert!((m / want - 1.0).abs() < 0.01, "triangles={tri}: {m} want {want}");
    }
}

#[test]
fn t20_error_falls_like_one_over_sqrt_n() {
    let (scene, want) = square_light_scene(false, 1.0, 1.0, 1.0);
    let rms = |n: u32| {
        let pts = vec![[0.0; 3]; 400];
        let out = bake(&scene, &pts, &vec![[0.0, 1.0, 0.0]; 400], &settings(n, 0, 6 + n as u64));
        (out.b.iter().map(|b| (b[0] as f64 - want).powi(2)).sum::<f64>() / 400.0).sqrt()
    };
    let (a, b) = (rms(4), rms(64));
    let ratio = a / b; // 16x the samples: 4x less error.
    assert!((3.0..5.3).contains(&ratio), "rms {a} -> {b}: ratio {ratio}");
}

#[test]
fn point_spot_and_sun_closed_forms() {
    let mut s = Soup::new();
    s.quad([0.0; 3], [10.0, 0.0, 0.0], [0.0, 0.0, -10.0], 0.0, 0.0);
    let n = [0.0, 1.0, 0.0];
    let x = [1.0, 0.0, 0.5];
    let check = |json: &str, want: f64| {
        let scene = s.scene(lights(json), None);
        let b = bake(&scene, &[x], &[n], &settings(1024, 2, 1)).b[0][0] as f64;
        assert!((b - want).abs() <= 2e-4 * want.max(1e-3), "{json}: {b} want {want}");
    };
    // Point, 100 cd at (0,2,0): H = I cos / r^2.
    let d = sub([0.0, 2.0, 0.0], x);
    let r2 = dot(d, d) as f64;
    let cos = 2.0 / r2.sqrt();
    check(r#"[{"name":"p","kind":"point","intensity":100,"position":[0,2,0]}]"#, 100.0 * cos / r2 / PI as f64);
    // Spot pointing down: x is at angle acos(cos) from the axis.
    let ang = cos.acos() as f32;
    let spot = |inner: f32, outer: f32| format!(r#"[{{"name":"s","kind":"spot","intensity":100,"position":[0,2,0],"direction":[0,-1,0],"inner_cone":{inner},"outer_cone":{outer}}}]"#);
    check(&spot(ang + 0.1, ang + 0.2), 100.0 * cos / r2 / PI as f64);
    check(&spot(ang - 0.2, ang - 0.1), 0.0);
    let (ci, co) = (((ang - 0.1) as f64).cos(), ((ang + 0.1) as f64).cos());
    let t = (cos - co) / (ci - co);
    check(&spot(ang - 0.1, ang + 0.1), 100.0 * cos / r2 / PI as f64 * t * t * (3.0 - 2.0 * t));
    // Sun, 1000 lux at 60 degrees from the normal: H = lux cos (cone of the real sun's size).
    let dir = [0.0, -0.5, -(3f32.sqrt() / 2.0)];
    check(&format!(r#"[{{"name":"sun","kind":"sun","intensity":1000,"direction":[{},{},{}]}}]"#, dir[0], dir[1], dir[2]), 1000.0 * 0.5 / PI as f64);
}

#[test]
fn no_light_leaks_under_a_wall() {
    let mut s = Soup::new();
    s.quad([0.0; 3], [10.0, 0.0, 0.0], [0.0, 0.0, -10.0], 0.8, 0.0);
    s.cube([0.0, 1.0, 0.0], [0.1, 1.0, 5.0], false, 0.0, 0.0); // a thin dark wall standing on the floor
    let json = r#"[{"name":"sun","kind":"sun","intensity":1000,"direction":[-0.6,-0.8,0]}]"#;
    let scene = s.scene(lights(json), Some([1.0; 3]));
    let n = [0.0, 1.0, 0.0];
    let under: Vec<V3> = (0..50).map(|i| [-0.099 + 0.198 * (i as f32 / 49.0), 0.0, -4.0 + 0.16 * i as f32]).collect();
    let out = bake(&scene, &under, &vec![n; under.len()], &settings(64, 3, 2));
    assert!(out.b.iter().all(|b| *b == [0.0; 3]), "{:?}", out.b);
    // Just outside the wall: lit (sky, plus the sun on the +x side, the side it comes from).
    let out = bake(&scene, &[[0.11, 0.0, 0.0], [-0.11, 0.0, 0.0]], &[n; 2], &settings(64, 3, 2));
    assert!(out.b[1][0] > 0.1 && out.b[0][0] > 1000.0 * 0.8 / PI * 0.9, "{:?}", out.b);
}

#[test]
fn same_seed_same_result_on_one_and_two_threads_and_pinned_ray_count() {
    let mut s = Soup::new();
    s.quad([0.0; 3], [10.0, 0.0, 0.0], [0.0, 0.0, -10.0], 0.8, 0.0);
    s.cube([0.0, 1.0, 0.0], [0.5, 1.0, 0.5], false, 0.5, 0.0);
    s.quad([2.0, 1.0, 0.0], [0.2, 0.0, 0.0], [0.0, 0.0, 0.2], 0.0, 5.0);
    let json = r#"[{"name":"sun","kind":"sun","intensity":1000,"direction":[-0.6,-0.8,0]},
                   {"name":"p","kind":"point","intensity":50,"position":[1,2,1]},
                   {"name":"r","kind":"rect","intensity":3,"position":[-2,2,0],"direction":[0,-1,0]}]"#;
    let scene = s.scene(lights(json), Some([0.2, 0.3, 0.5]));
    let pts: Vec<V3> = (0..300).map(|i| [-3.0 + 0.02 * i as f32, 0.0, 0.7]).collect();
    let nrm = vec![[0.0, 1.0, 0.0]; pts.len()];
    let st = BakeSettings::preset("draft", 42).unwrap();
    let run = |t| rayon::ThreadPoolBuilder::new().num_threads(t).build().unwrap().install(|| bake(&scene, &pts, &nrm, &st));
    let (a, b) = (run(1), run(2));
    assert_eq!(a, b);
    let c = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap().install(|| bake(&scene, &pts, &nrm, &BakeSettings { seed: 43, ..st.clone() }));
    assert_ne!(a.b, c.b);

    // Pinned ray count: a plane under sun and sky, draft (32 samples): per sample one sun
    // shadow ray and one hemisphere ray that escapes.
    let mut s = Soup::new();
    s.quad([0.0; 3], [10.0, 0.0, 0.0], [0.0, 0.0, -10.0], 0.8, 0.0);
    let scene = s.scene(lights(r#"[{"name":"sun","kind":"sun","intensity":1000}]"#), Some([1.0; 3]));
    let out = bake(&scene, &pts[..10], &nrm[..10], &st);
    assert_eq!(out.rays, 10 * 32 * 2);
}

#[test]
fn cancel_stops_the_bake() {
    let mut s = Soup::new();
    s.quad([0.0; 3], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0], 0.8, 0.0);
    let scene = s.scene(vec![], Some([1.0; 3]));
    let r = bake_points(&scene, &[[0.0; 3]; 10], &[[0.0, 1.0, 0.0]; 10], None, &settings(4, 1, 1), &|_, _| {}, &AtomicBool::new(true));
    assert_eq!(r, Err(Cancelled));
}

fn probes(scene: &BakeScene, pts: &[V3], s: &BakeSettings) -> Vec<Probe> {
    bake_probes(scene, pts, None, s, &|_, _| {}, &AtomicBool::new(false)).unwrap().0
}

const AXES: [V3; 6] = [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]];

#[test]
fn probe_under_a_uniform_sky_sees_b_equal_l() {
    // Nothing but sky: the DC term is exact (4 pi Y00^2 = 1); the higher bands are Monte Carlo
    // noise around 0.
    let mut s = Soup::new();
    s.quad([0.0, -1e6, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0], 0.5, 0.0); // far away, tiny
    let scene = s.scene(vec![], Some([0.5, 1.0, 2.0]));
    let p = &probes(&scene, &[[0.0; 3]], &settings(4096, 2, 1))[0];
    assert!((p.sh[0][1] * 0.282_094_8 - 1.0).abs() < 1e-4, "{:?}", p.sh[0]);
    for n in AXES {
        let b = eval_sh9(&p.sh, n);
        assert!((b[1] - 1.0).abs() < 0.05 && (b[2] / b[1] - 2.0).abs() < 1e-4, "B({n:?}) = {b:?}");
    }
    assert_eq!((p.sun_visibility, p.backface), (1.0, 0.0));
}

#[test]
fn probe_point_light_closed_form_and_sun_visibility() {
    // A point light is one exact sample per ray: its L2 irradiance at the light's direction is
    // E/pi x sum_l A_l (2l+1)/(4 pi) = 1.0625 E/pi, and 0.0625 E/pi straight away from it.
    let mut s = Soup::new();
    s.quad([0.0, 5.0, 0.0], [3.0, 0.0, 0.0], [0.0, 0.0, 3.0], 0.0, 0.0); // a black roof, facing down
    let json = r#"[{"name":"p","kind":"point","intensity":100,"position":[2,0,0]},
                   {"name":"sun","kind":"sun","intensity":1000,"direction":[0,-1,0]}]"#;
    let scene = s.scene(lights(json), None);
    let e = 100.0 / 4.0 / PI;
    let under = &probes(&scene, &[[0.0; 3]], &settings(64, 1, 2))[0];
    let toward = eval_sh9(&under.sh, [1.0, 0.0, 0.0])[0];
    let away = eval_sh9(&under.sh, [-1.0, 0.0, 0.0])[0];
    assert!((toward / (1.0625 * e) - 1.0).abs() < 1e-4 && (away / (0.0625 * e) - 1.0).abs() < 1e-3, "{toward} {away} (E/pi = {e})");
    assert_eq!(under.sun_visibility, 0.0, "under the roof");
    let beside = &probes(&scene, &[[10.0, 0.0, 0.0]], &settings(64, 1, 2))[0];
    assert_eq!(beside.sun_visibility, 1.0);
    assert!(eval_sh9(&beside.sh, [0.0, 1.0, 0.0])[0] < 1.0, "the sun's direct light is not in the SH");
}

#[test]
fn probe_inside_a_solid_sees_back_faces_and_bakes_deterministically() {
    let mut s = Soup::new();
    s.quad([0.0; 3], [10.0, 0.0, 0.0], [0.0, 0.0, -10.0], 0.8, 0.0);
    s.cube([0.0, 1.0, 0.0], [0.5, 1.0, 0.5], false, 0.5, 0.0);
    let json = r#"[{"name":"sun","kind":"sun","intensity":1000,"direction":[-0.6,-0.8,0]}, {"name":"p","kind":"point","intensity":50,"position":[1,2,1]}]"#;
    let scene = s.scene(lights(json), Some([0.2, 0.3, 0.5]));
    let st = BakeSettings::preset("draft", 7).unwrap();
    let pts: Vec<V3> = (0..40).map(|i| [-1.95 + 0.1 * i as f32, 1.0, 0.2]).collect(); // none on a wall
    let run = |t| rayon::ThreadPoolBuilder::new().num_threads(t).build().unwrap().install(|| probes(&scene, &pts, &st));
    let (a, b) = (run(1), run(2));
    assert_eq!(a, b);
    for (p, x) in a.iter().zip(&pts) {
        let inside = x[0].abs() < 0.5;
        assert_eq!(p.backface == 1.0, inside, "{x:?}: {}", p.backface);
        if !inside {
            // Some light from the floor below. (L2 SH ringing can push B(up) below zero next to
            // a strong lobe, such as the sunlit box side; the runtime clamps it.)
            assert!(p.backface < 0.5 && eval_sh9(&p.sh, [0.0, -1.0, 0.0])[0] > 0.0, "{x:?}: {p:?}");
        }
    }
    // Far out on the sunlit floor: its radiance, 0.8 x (800 lux / pi + sky), comes from below.
    let far = &probes(&scene, &[[6.0, 1.0, 0.2]], &BakeSettings { probe_samples: 2048, ..st })[0];
    let (up, down) = (eval_sh9(&far.sh, [0.0, 1.0, 0.0])[0], eval_sh9(&far.sh, [0.0, -1.0, 0.0])[0]);
    assert!(down > 150.0 && down > 10.0 * up.max(0.0), "{far:?}");
}

/// Benchmark on a raw scene (tools/bench_bvh.py --write-raw): `BVH_RAW=/tmp/temple.bin cargo
/// test --release -p cook_core bvh_raw_bench -- --ignored --nocapture`. Prints rays/s on one
/// thread and the box/triangle tests per ray (the lanes tested, used or not).
#[test]
#[ignore]
fn bvh_raw_bench() {
    let Ok(path) = std::env::var("BVH_RAW") else { return };
    let buf = std::fs::read(path).unwrap();
    let u = |i: usize| u32::from_le_bytes(buf[4 * i..4 * i + 4].try_into().unwrap());
    let f = |i: usize| f32::from_le_bytes(buf[4 * i..4 * i + 4].try_into().unwrap());
    let (nv, nt, nr) = (u(0) as usize, u(1) as usize, u(2) as usize);
    let mut w = 3;
    let pos: Vec<V3> = (0..nv).map(|i| [f(w + 3 * i), f(w + 3 * i + 1), f(w + 3 * i + 2)]).collect();
    w += 3 * nv;
    let tris: Vec<[u32; 3]> = (0..nt).map(|i| [u(w + 3 * i), u(w + 3 * i + 1), u(w + 3 * i + 2)]).collect();
    w += 3 * nt;
    let org: Vec<V3> = (0..nr).map(|i| [f(w + 3 * i), f(w + 3 * i + 1), f(w + 3 * i + 2)]).collect();
    w += 3 * nr;
    let dir: Vec<V3> = (0..nr).map(|i| [f(w + 3 * i), f(w + 3 * i + 1), f(w + 3 * i + 2)]).collect();
    let t0 = std::time::Instant::now();
    let bvh = Bvh::build(&pos, &tris);
    println!("build {:.1} ms, {} nodes", t0.elapsed().as_secs_f64() * 1e3, bvh.node_count());
    let n = std::env::var("BVH_RAYS").ok().and_then(|s| s.parse().ok()).unwrap_or(nr).min(nr);
    let rays: Vec<Ray> = (0..n).map(|i| Ray { origin: org[i], dir: dir[i], tmin: 0.0, tmax: f32::INFINITY }).collect();
    let mut best = f64::INFINITY;
    let mut hits = 0;
    for _ in 0..3 {
        let t0 = std::time::Instant::now();
        hits = rays.iter().filter(|r| bvh.closest(r).is_some()).count();
        best = best.min(t0.elapsed().as_secs_f64());
    }
    let (boxes, prims) = stats::take();
    println!(
        "{n} rays, hit {:.4}, {:.2} Mrays/s, per ray: {:.1} box tests (8 per node), {:.1} triangle tests (8 per leaf)",
        hits as f64 / n as f64,
        n as f64 / best / 1e6,
        boxes as f64 / (3 * n) as f64,
        prims as f64 / (3 * n) as f64
    );
}

