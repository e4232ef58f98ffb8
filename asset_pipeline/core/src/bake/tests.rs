//! Baker tests: BVH against brute force (random and degenerate soups), and the integrator
//! against the closed-form scenes of notes §10.

use super::bvh::*;
use super::integrator::*;
use super::lights::Light;
use super::material::*;
use super::probes::*;
use super::sampling::*;
use super::scene::*;
use super::textures::*;
use pack::{Filter, Sampler, TextureTransform, Wrap};
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
                // Ties go to the highest triangle index in both, so the hits are the same.
                assert_eq!(a, b, "ray {i}: {ray:?}");
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

/// A test scene built quad by quad, each with its own material.
struct Soup {
    pos: Vec<V3>,
    tris: Vec<[u32; 3]>,
    mats: Vec<u32>,
    materials: Vec<Material>,
    textures: Vec<Texture>,
    uv0: Vec<[f32; 2]>,
    colors: Vec<[u8; 4]>,
}

impl Soup {
    fn new() -> Soup {
        Soup { pos: vec![], tris: vec![], mats: vec![], materials: vec![], textures: vec![], uv0: vec![], colors: vec![] }
    }
    /// Quad centred at c with half-extents u, v; front face along u x v.
    fn quad(&mut self, c: V3, u: V3, v: V3, albedo: f32, emission: f32) {
        self.quad_with(c, u, v, Material { base_color: [albedo, albedo, albedo, 1.0], emissive: [emission; 3], ..Material::default() });
    }
    /// Quad with its own material; uv0 (0, 0) at c - u - v, (1, 0) at c + u - v, (1, 1) at
    /// c + u + v; white vertex colours. Returns its first vertex.
    fn quad_with(&mut self, c: V3, u: V3, v: V3, material: Material) -> usize {
        let b = self.pos.len() as u32;
        self.pos.extend([sub(sub(c, u), v), sub(add(c, u), v), add(add(c, u), v), add(sub(c, u), v)]);
        self.uv0.extend([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]);
        self.colors.extend([[255; 4]; 4]);
        self.tris.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
        self.mats.extend([self.materials.len() as u32; 2]);
        self.materials.push(material);
        b as usize
    }
    fn texture(&mut self, t: Texture) -> u32 {
        self.textures.push(t);
        self.textures.len() as u32 - 1
    }
    /// Axis-aligned box with faces pointing out (or in).
    fn cube(&mut self, c: V3, h: V3, inward: bool, albedo: f32, emission: f32) {
        self.cube_with(c, h, inward, Material { base_color: [albedo, albedo, albedo, 1.0], emissive: [emission; 3], ..Material::default() });
    }
    fn cube_with(&mut self, c: V3, h: V3, inward: bool, material: Material) {
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
                self.quad_with(add(c, scale(n, h[k])), u, v, material.clone());
            }
        }
    }
    fn scene(&self, lights: Vec<Light>, sky: Option<V3>) -> BakeScene {
        let geometry = Geometry {
            positions: &self.pos,
            triangles: &self.tris,
            materials: &self.mats,
            attributes: VertexAttributes { uv0: Some(&self.uv0), texcoord1: None, color: Some(&self.colors) },
        };
        BakeScene::new(geometry, self.materials.clone(), self.textures.clone(), lights, sky).unwrap()
    }
}

/// A texture of `w` x `h` RGBA texels (rows top to bottom), sRGB unless `linear`.
fn texture(w: usize, h: usize, texels: &[[u8; 4]], filter: Filter, wrap: Wrap) -> Texture {
    Texture::new(w, h, texels.to_vec(), true, Sampler { wrap_s: wrap, wrap_t: wrap, mag_filter: filter, min_filter: filter, mipmap_filter: None }).unwrap()
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

/// Lights out of range of every point change nothing: the lightmap is bit-identical with 200
/// ranged lights far away added after the scene's own, though each adds to the lights a bake
/// walks past (they are skipped by the light tree, and the near lights' numbers do not depend on
/// the others).
#[test]
fn lights_out_of_range_change_no_texel() {
    let mut s = Soup::new();
    s.quad([0.0; 3], [4.0, 0.0, 0.0], [0.0, 0.0, -4.0], 0.5, 0.0);
    s.cube([0.0, 1.0, 0.0], [0.5; 3], false, 0.7, 0.0);
    let own = r#"{"name":"p","kind":"point","intensity":100,"position":[2,2,0],"range":8},{"name":"sun","kind":"sun","intensity":1000,"direction":[0.3,-1,0.2]}"#;
    let far: Vec<String> = (0..200).map(|k| format!(r#"{{"name":"f{k}","kind":"point","intensity":100,"position":[{},3,{}],"range":5}}"#, 20 + k, -30 - k)).collect();
    let pts: Vec<V3> = (0..64).map(|k| [-3.5 + 0.11 * k as f32, 0.0, 3.0 - 0.09 * k as f32]).collect();
    let nrm = vec![[0.0, 1.0, 0.0]; pts.len()];
    let st = settings(16, 2, 3);
    let alone = bake(&s.scene(lights(&format!("[{own}]")), Some([0.1; 3])), &pts, &nrm, &st);
    let crowded = bake(&s.scene(lights(&format!("[{own},{}]", far.join(","))), Some([0.1; 3])), &pts, &nrm, &st);
    assert_eq!(alone.b, crowded.b);
    assert_eq!(alone.rays, crowded.rays);
    assert!(alone.b.iter().all(|b| b[0] > 0.0));
}

/// Of several point lights in view, next-event estimation casts one shadow ray, to a light picked
/// in proportion to its irradiance, and the estimate is exact per sample (H = sum I cos / r^2, in
/// the sum of the channels): the pick adds no noise there. A light hidden behind a box drops out on average (the samples that
/// pick it see nothing) and only there.
#[test]
fn one_point_light_is_picked_and_all_in_view_bake_exactly() {
    let mut s = Soup::new();
    s.quad([0.0; 3], [10.0, 0.0, 0.0], [0.0, 0.0, -10.0], 0.0, 0.0);
    let json = r#"[{"name":"a","kind":"point","intensity":100,"position":[0,2,0],"range":20},
                   {"name":"b","kind":"point","intensity":150,"color":[1,0.5,0.2],"position":[3,1,-1]},
                   {"name":"c","kind":"spot","intensity":60,"position":[-2,3,1],"direction":[0.5,-1,0],"outer_cone":1.2}]"#;
    let all = lights(json);
    let x = [0.5, 0.0, 0.3];
    let n = [0.0, 1.0, 0.0];
    let want: V3 = all.iter().fold([0.0; 3], |h, l| add(h, l.sample(x, n, 0.0, 0.0).unwrap().h));
    let samples = 64;
    let out = bake(&s.scene(all, None), &[x], &[n], &settings(samples, 0, 5));
    // Exact in the sum of the channels (what the pick weighs); light b's colour differs from
    // the others', so single channels are exact on average only (checked below).
    let (b, w) = (out.b[0].iter().map(|&v| v as f64).sum::<f64>(), want.iter().map(|&v| v as f64).sum::<f64>() / PI as f64);
    assert!((b - w).abs() <= 1e-5 * w, "channel sum: {b} want {w}");
    // Per sample the continuation ray (which sees the black void), and one shadow ray per
    // light the first time it is picked (from a texel that stays put a delta light's shadow ray
    // is the same ray every sample: see `SeenFrom`).
    assert_eq!(out.rays, samples as u64 + 3);
    // A box between x and light b: B loses b's share, on average.
    s.cube([1.75, 0.5, -0.35], [0.2, 0.2, 0.2], false, 0.0, 0.0);
    let lit = lights(json);
    let without_b: V3 = [&lit[0], &lit[2]].iter().fold([0.0; 3], |h, l| add(h, l.sample(x, n, 0.0, 0.0).unwrap().h));
    let scene = s.scene(lit, None);
    let pts = vec![x; 400];
    let ids: Vec<u64> = (0..400).collect();
    let est = bake_points(&scene, &pts, &vec![n; 400], Some(&ids), &settings(16, 0, 9), &|_, _| {}, &AtomicBool::new(false)).unwrap();
    for c in 0..3 {
        let v: Vec<V3> = est.b.iter().map(|b| [b[c]; 3]).collect();
        let (m, se) = mean_se(&v);
        let w = without_b[c] as f64 / PI as f64;
        assert!((m - w).abs() < 4.0 * se && se < 0.02 * w, "channel {c}: {m} +- {se}, want {w}");
    }
}

#[test]
fn a_texel_asks_once_whether_it_sees_a_point_light_and_bakes_the_same_bits() {
    // A floor, boxes casting shadows, five point and spot lights (some hidden from some points):
    // the bake (which remembers per point what its samples learnt of each delta light) against
    // the same samples each asking again (`sample_path` without `SeenFrom`): the same bits, and
    // fewer rays by exactly one per sample that picked a light already asked about.
    let mut s = Soup::new();
    s.quad([-5.0, 0.0, 5.0], [10.0, 0.0, 0.0], [0.0, 0.0, -10.0], 0.0, 0.0);
    s.cube([1.0, 0.6, 0.0], [0.3, 0.6, 0.3], false, 0.0, 0.0);
    s.cube([-1.5, 0.4, 1.0], [0.5, 0.4, 0.2], false, 0.0, 0.0);
    let json = r#"[{"name":"a","kind":"point","intensity":40,"position":[2,1,0],"range":8},
                   {"name":"b","kind":"point","intensity":60,"color":[1,0.6,0.3],"position":[-2,1.5,2]},
                   {"name":"c","kind":"spot","intensity":80,"position":[0,3,0],"direction":[0,-1,0],"outer_cone":0.9},
                   {"name":"d","kind":"point","intensity":30,"position":[-1.5,0.3,0.5],"range":3},
                   {"name":"e","kind":"point","intensity":20,"position":[3,0.5,-2]}]"#;
    let scene = s.scene(lights(json), Some([0.2, 0.3, 0.5]));
    let pts: Vec<V3> = (0..40).map(|i| [-4.0 + 0.2 * i as f32, 0.0, 0.35 * (i % 7) as f32 - 1.0]).collect();
    let nrm = vec![[0.0, 1.0, 0.0]; pts.len()];
    let st = settings(32, 2, 11);
    let out = bake(&scene, &pts, &nrm, &st);
    let mut asked = 0u64;
    for (i, (&x, &n)) in pts.iter().zip(&nrm).enumerate() {
        let mut sum = [0.0f64; 3];
        for k in 0..st.samples {
            let mut rng = Rng::for_sample(st.seed, i as u64, k as u64);
            let v = sample_path(&scene, x, n, st.bounces, &mut rng, &mut asked, None);
            for c in 0..3 {
                sum[c] += v[c] as f64;
            }
        }
        let want = sum.map(|v| (v / st.samples as f64) as f32);
        assert_eq!(out.b[i].map(f32::to_bits), want.map(f32::to_bits), "point {i}");
    }
    assert!(out.rays < asked, "{} rays remembering, {asked} asking every time", out.rays);
    // At least one point sees each of a, b, c; each sample at most one delta shadow ray saved.
    assert!(asked - out.rays <= (pts.len() * st.samples as usize) as u64);
    assert!(asked - out.rays >= (pts.len() * (st.samples as usize - 5)) as u64 / 2, "{asked} -> {}", out.rays);
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
    // Between the cones: KHR_lights_punctual's falloff, the square of the cosine's linear ramp.
    for (inner, outer) in [(ang - 0.1, ang + 0.1), (ang - 0.3, ang + 0.05), (0.0, ang + 0.2)] {
        let (ci, co) = ((inner as f64).cos(), (outer as f64).cos());
        let t = (cos - co) / (ci - co);
        check(&spot(inner, outer), 100.0 * cos / r2 / PI as f64 * t * t);
    }
    // Inner = outer: a hard edge.
    check(&spot(ang + 0.01, ang + 0.01), 100.0 * cos / r2 / PI as f64);
    check(&spot(ang - 0.01, ang - 0.01), 0.0);
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
    // Materials read at the hit: a textured emitter, a hashed-alpha pane, a masked double-sided leaf.
    let t = s.texture(texture(2, 2, &[[255, 0, 0, 255], [0, 0, 0, 0], [20, 200, 90, 200], [255; 4]], Filter::Linear, Wrap::Repeat));
    s.quad_with([-1.5, 1.2, 0.5], [0.3, 0.0, 0.0], [0.0, 0.0, 0.3], Material { emissive: [4.0; 3], emissive_texture: Some(Slot::plain(t)), ..Material::default() });
    s.quad_with([1.0, 1.5, 1.0], [0.6, 0.0, 0.0], [0.0, 0.0, 0.6], Material { base_color: [0.2, 0.5, 0.9, 0.4], alpha: Alpha::Blend, ..Material::default() });
    let leaf = Material { base_color_texture: Some(Slot::plain(t)), alpha: Alpha::Mask(0.5), double_sided: true, ..Material::default() };
    s.quad_with([-1.0, 1.8, -0.5], [0.5, 0.0, 0.0], [0.0, 0.3, 0.3], leaf);
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

// ---- materials at the hit point ------------------------------------------------------------

/// A 1000 lux sun straight down.
const SUN_LUX: f64 = 1000.0;
fn sun_down() -> Vec<Light> {
    lights(r#"[{"name":"sun","kind":"sun","intensity":1000,"direction":[0,-1,0]}]"#)
}

/// Channel k's mean over points.
fn channel_mean(v: &[V3], k: usize) -> f64 {
    v.iter().map(|x| x[k] as f64).sum::<f64>() / v.len() as f64
}

/// 64 points `h` above the floor within 0.1 m of (x, 0), facing down: under a sun straight down
/// each sees the floor around it, so B there is the floor's radiance: albedo x E/pi.
fn looking_down_at(x: f32, h: f32) -> (Vec<V3>, Vec<V3>) {
    let pts = (0..64).map(|i| [x - 0.1 + 0.2 * (i % 8) as f32 / 7.0, h, -0.1 + 0.2 * (i / 8) as f32 / 7.0]).collect();
    (pts, vec![[0.0, -1.0, 0.0]; 64])
}

fn srgb_to_linear(byte: u8) -> f64 {
    let c = byte as f64 / 255.0;
    if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
}

#[test]
fn texture_sampling_decodes_srgb_filters_in_linear_light_and_wraps() {
    let px = |t: &Texture, u: f32, v: f32| t.sample([u, v]);
    // 2 x 1, black | white: bilinear halfway is 0.5 in linear light (not the sRGB midpoint).
    let t = texture(2, 1, &[[0, 0, 0, 255], [255, 255, 255, 51]], Filter::Linear, Wrap::Clamp);
    assert_eq!(px(&t, 0.5, 0.5), [0.5, 0.5, 0.5, 0.6]);
    assert_eq!(px(&t, 0.1, 0.5)[0], 0.0, "clamped at the edge");
    let grey = texture(1, 1, &[[188, 188, 188, 255]], Filter::Linear, Wrap::Repeat);
    assert!((px(&grey, 0.3, 0.7)[0] as f64 - srgb_to_linear(188)).abs() < 1e-6 && (srgb_to_linear(188) - 0.5029).abs() < 1e-4);
    // 4 x 1, texels 0..3 by their red channel; nearest reads floor(u * 4) wrapped.
    let ramp: Vec<[u8; 4]> = (0..4).map(|i| [[0, 90, 160, 255][i], 0, 0, 255]).collect();
    let red = |wrap: Wrap, u: f32| {
        let t = Texture::new(4, 1, ramp.clone(), false, Sampler { wrap_s: wrap, wrap_t: wrap, mag_filter: Filter::Nearest, min_filter: Filter::Nearest, mipmap_filter: None }).unwrap();
        (t.sample([u, 0.5])[0] * 255.0).round() as u8
    };
    assert_eq!([1.1, -0.1, 2.6].map(|u| red(Wrap::Repeat, u)), [0, 255, 160]);
    assert_eq!([1.1, -0.1, 2.6].map(|u| red(Wrap::Clamp, u)), [255, 0, 255]);
    // Mirrored repeat: 1.1 reads texel 3 (its mirror image of 0.9), -0.1 texel 0, 1.6 texel 1.
    assert_eq!([1.1, -0.1, 1.6].map(|u| red(Wrap::Mirror, u)), [255, 0, 90]);
}

#[test]
fn materials_read_their_slot_uv_set_through_its_transform_and_the_vertex_colour() {
    // One triangle; texcoord1 differs from uv0; a 2 x 2 nearest texture A B / C D.
    let (a, b, c, d) = ([255, 0, 0, 255], [0, 255, 0, 255], [0, 0, 255, 255], [188, 188, 188, 255]);
    let tex = texture(2, 2, &[a, b, c, d], Filter::Nearest, Wrap::Repeat);
    let uv0 = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
    let uv1 = [[0.25, 0.25], [0.75, 0.25], [0.25, 0.75]];
    let colors = [[255, 255, 255, 255], [128, 255, 255, 255], [255, 255, 255, 0]];
    let surfaces = |slot: Slot| {
        let m = Material { base_color: [1.0, 1.0, 1.0, 0.5], base_color_texture: Some(slot), emissive: [3.0; 3], emissive_texture: Some(slot), ..Material::default() };
        let attributes = VertexAttributes { uv0: Some(&uv0), texcoord1: Some(&uv1), color: Some(&colors) };
        Surfaces::new(&[[0, 1, 2]], 3, &[0], attributes, vec![m], vec![tex.clone()]).unwrap()
    };
    let corner = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    // texcoord1 moved by offset (0.5, 0): the first corner reads (0.75, 0.25) = B, the last (0.75, 0.75) = D.
    let offset = TextureTransform { tex_coord: 1, offset: [0.5, 0.0], ..TextureTransform::default() };
    let s = surfaces(Slot { texture: 0, set: 1, matrix: offset.matrix() });
    assert_eq!(s.shade(0, corner[0]).albedo, [0.0, 1.0, 0.0]);
    let grey = srgb_to_linear(188) as f32;
    assert_eq!(s.shade(0, corner[2]), Shade { albedo: [grey; 3], emission: [3.0 * grey; 3] });
    // The second corner reads (1.25, 0.25), repeated: A. The vertex colour (red 128/255 there)
    // multiplies the albedo, not the emission.
    let second = s.shade(0, corner[1]);
    assert_eq!((second.albedo, second.emission), ([128.0 / 255.0, 0.0, 0.0], [3.0, 0.0, 0.0]));
    // Alpha: factor 0.5 x texture 1 x vertex alpha (0 at the last corner, 0.5 halfway to it).
    assert_eq!((s.alpha(0, corner[0]), s.alpha(0, corner[2]), s.alpha(0, [0.5, 0.0, 0.5])), (0.5, 0.0, 0.25));
    // A quarter turn (KHR_texture_transform's T R S), (u, v) -> (v, -u): uv0 (0.25, 0.125) ->
    // (0.125, -0.25) reads C (the identity would read A), uv0 (0.75, 0.125) -> (0.125, -0.75)
    // reads A (the identity: B).
    let turn = TextureTransform { rotation: std::f32::consts::FRAC_PI_2, ..TextureTransform::default() };
    let s = surfaces(Slot { texture: 0, set: 0, matrix: turn.matrix() });
    assert_eq!(s.shade(0, [0.625, 0.25, 0.125]).albedo, [0.0, 0.0, 1.0]);
    // (Red x the vertex colour there: 0.125 + 0.75 x 128/255 + 0.125.)
    assert_eq!(s.shade(0, [0.125, 0.75, 0.125]).albedo, [159.75 / 255.0, 0.0, 0.0]);
    // Without texcoord1 in the vertices, set 1 reads (0, 0) through its transform: A.
    let m = Material { base_color_texture: Some(Slot { texture: 0, set: 1, matrix: offset.matrix() }), ..Material::default() };
    let s = Surfaces::new(&[[0, 1, 2]], 3, &[0], VertexAttributes { uv0: Some(&uv0), ..Default::default() }, vec![m], vec![tex.clone()]).unwrap();
    assert_eq!(s.shade(0, corner[2]).albedo, [0.0, 1.0, 0.0], "(0, 0) + (0.5, 0) reads B");
}

#[test]
fn emitter_footprints_cover_every_texel_a_read_can_reach() {
    // Unbiased light sampling needs a positive weight wherever a read can return light: random
    // sparse textures (one big enough to be summed in blocks), random UV boxes (beyond [0, 1],
    // huge, tiny), every wrap mode and filter; the mean is zero only if every read is black.
    let mut r = Rng::for_sample(21, 0, 0);
    for (w, h) in [(7usize, 5usize), (1, 1), (2048, 1030)] {
        for wrap in [Wrap::Repeat, Wrap::Clamp, Wrap::Mirror] {
            for filter in [Filter::Linear, Filter::Nearest] {
                let mut texels = vec![[0u8, 0, 0, 255]; w * h];
                for _ in 0..(w * h / 40).clamp(1, 3) {
                    texels[(r.next_u32() as usize) % (w * h)] = [0, 0, 40, 255];
                }
                let tex = Texture::new(w, h, texels, true, Sampler { wrap_s: wrap, wrap_t: wrap, mag_filter: filter, min_filter: filter, mipmap_filter: None }).unwrap();
                let textures = [tex];
                let fp = Footprint::new(&textures[0]);
                let (mut lit, mut dark) = (0, 0);
                for _ in 0..300 {
                    let size = [0.001f32, 0.05, 0.3, 3.0][(r.next_u32() % 4) as usize];
                    let lo = [(r.next_f32() - 0.5) * 6.0, (r.next_f32() - 0.5) * 6.0];
                    let hi = [lo[0] + size * r.next_f32(), lo[1] + size * r.next_f32()];
                    let mean = fp.mean(&textures[0], lo, hi);
                    let reads = (0..400).any(|_| {
                        let uv = [lo[0] + (hi[0] - lo[0]) * r.next_f32(), lo[1] + (hi[1] - lo[1]) * r.next_f32()];
                        textures[0].sample(uv)[2] > 0.0
                    });
                    assert!(!reads || mean > 0.0, "{w}x{h} {wrap:?} {filter:?}: box {lo:?}..{hi:?} reads light but weighs {mean}");
                    if mean > 0.0 { lit += 1 } else { dark += 1 }
                }
                assert!(w * h < 40 || dark > 0, "{w}x{h} {wrap:?}: some boxes should miss the few lit texels ({lit} lit)");
            }
        }
    }
}

#[test]
fn albedo_comes_from_the_texture_at_the_hit_point() {
    // A floor whose texture is red on its left half and sRGB 188 grey on its right, as one quad
    // (two triangles, each spanning both halves): the bounce light above each half has the
    // colour of the texels under it, sRGB decoded (188 -> 0.5029), not a per-triangle mean.
    let mut s = Soup::new();
    let (red, grey) = ([255, 0, 0, 255], [188, 188, 188, 255]);
    let t = s.texture(texture(8, 1, &[red, red, red, red, grey, grey, grey, grey], Filter::Linear, Wrap::Repeat));
    s.quad_with([0.0; 3], [10.0, 0.0, 0.0], [0.0, 0.0, -10.0], Material { base_color_texture: Some(Slot::plain(t)), ..Material::default() });
    let scene = s.scene(sun_down(), None);
    let e = SUN_LUX / PI as f64;
    let g = srgb_to_linear(188);
    for (x, want) in [(-5.0, [1.0, 0.0, 0.0]), (5.0, [g, g, g])] {
        let (pts, nrm) = looking_down_at(x, 0.02);
        let out = bake(&scene, &pts, &nrm, &settings(64, 1, 11));
        for (k, want) in want.iter().enumerate() {
            let m = channel_mean(&out.b, k);
            assert!((m - want * e).abs() <= 0.01 * e, "x = {x} channel {k}: B = {m}, want {}", want * e);
        }
    }
}

#[test]
fn vertex_colour_multiplies_the_albedo_where_the_ray_hits() {
    // The floor's green channel runs linearly from 0 at x = -10 to 1 at x = 10 (vertex colours):
    // above x = -5 and x = 5 (symmetric neighbourhoods of a linear function) B's green is a
    // quarter and three quarters of the white floor's.
    let mut s = Soup::new();
    let b = s.quad_with([0.0; 3], [10.0, 0.0, 0.0], [0.0, 0.0, -10.0], Material::default());
    for corner in [b, b + 3] {
        s.colors[corner] = [255, 0, 255, 255]; // the x = -10 side
    }
    let scene = s.scene(sun_down(), None);
    let e = SUN_LUX / PI as f64;
    for (x, green) in [(-5.0, 0.25), (5.0, 0.75)] {
        let (pts, nrm) = looking_down_at(x, 0.02);
        let out = bake(&scene, &pts, &nrm, &settings(64, 1, 12));
        let (r, g) = (channel_mean(&out.b, 0), channel_mean(&out.b, 1));
        assert!((r / e - 1.0).abs() < 0.01 && (g / e - green).abs() < 0.01, "x = {x}: B = ({r}, {g}), want ({e}, {})", green * e);
    }
}

/// An emissive quad (radiance 2 x texture) 1.5 above the origin facing down, its texture white
/// on the half over x < 0 and black on the other, over a black floor; and B at the origin that
/// the white half alone gives (Lambert's polygon formula).
fn half_white_emitter(filter: Filter, wrap: Wrap) -> (BakeScene, f64) {
    let mut s = Soup::new();
    s.quad([0.0; 3], [10.0, 0.0, 0.0], [0.0, 0.0, -10.0], 0.0, 0.0);
    let t = s.texture(texture(2, 1, &[[255; 4], [0, 0, 0, 255]], filter, wrap));
    s.quad_with([0.0, 1.5, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], Material { base_color: [0.0, 0.0, 0.0, 1.0], emissive: [2.0; 3], emissive_texture: Some(Slot::plain(t)), ..Material::default() });
    // Far off, an emitter whose transform reads only the black texel: never worth sampling.
    let black = Slot { texture: t, set: 0, matrix: [[0.0, 0.0, 0.75], [0.0, 0.0, 0.5]] };
    s.quad_with([30.0, 1.5, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], Material { emissive: [5.0; 3], emissive_texture: Some(black), ..Material::default() });
    let white_half = [[-1.0, 1.5, -1.0], [0.0, 1.5, -1.0], [0.0, 1.5, 1.0], [-1.0, 1.5, 1.0]];
    (s.scene(vec![], None), 2.0 * polygon_irradiance([0.0; 3], [0.0, 1.0, 0.0], &white_half) / PI as f64)
}

#[test]
fn textured_emission_matches_the_polygon_irradiance_of_its_lit_half() {
    // Nearest: the emitting half is exactly x < 0. Bilinear (clamped): the ramp between the two
    // texel centres is antisymmetric about x = 0, as is nothing else, and the point's view is
    // symmetric: the same irradiance. Light sampling picks the quad by its texture's mean and
    // evaluates the texture at each sampled point; MIS with the hits as before.
    for (filter, wrap) in [(Filter::Nearest, Wrap::Repeat), (Filter::Linear, Wrap::Clamp)] {
        let (scene, want) = half_white_emitter(filter, wrap);
        let out = bake(&scene, &[[0.0; 3]; 64], &[[0.0, 1.0, 0.0]; 64], &settings(4096, 0, 13));
        let (m, se) = mean_se(&out.b);
        assert!((m / want - 1.0).abs() < 0.01, "{filter:?} {wrap:?}: B = {m} (se {se}), want {want} (the whole quad would give about twice)");
        if wrap == Wrap::Clamp {
            // The far quad reads black everywhere (clamped), so it is no emitter at all.
            assert!(scene.emitter_pdf(4) == 0.0 && scene.emitter_pdf(5) == 0.0 && scene.emitter_pdf(2) > 0.0);
        }
    }
}

#[test]
fn alpha_mask_cuts_a_hard_edged_hole_for_shadow_and_closest_hit_rays() {
    // A black quad 1 m above the floor whose alpha runs from 1 (x = -0.5) to 0 (x = 0.5),
    // bilinear, masked at 0.5: it is there for x <= 0 only.
    let masked = |s: &mut Soup| {
        let t = s.texture(texture(2, 1, &[[0, 0, 0, 255], [0, 0, 0, 0]], Filter::Linear, Wrap::Clamp));
        s.quad_with([0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], Material { base_color_texture: Some(Slot::plain(t)), alpha: Alpha::Mask(0.5), ..Material::default() });
    };
    // Under a sun straight down (its disk makes a penumbra ~5 mm wide here): shadow exactly
    // under the opaque half, full sun 2 cm away on the other side of x = 0.
    let mut s = Soup::new();
    s.quad([0.0; 3], [10.0, 0.0, 0.0], [0.0, 0.0, -10.0], 0.5, 0.0);
    masked(&mut s);
    let scene = s.scene(sun_down(), None);
    let xs = [-0.9f32, -0.5, -0.05, -0.02, 0.02, 0.05, 0.5, 0.9];
    let pts: Vec<V3> = xs.iter().map(|&x| [x, 0.0, 0.3]).collect();
    let out = bake(&scene, &pts, &[[0.0, 1.0, 0.0]; 8], &settings(64, 0, 14));
    let e = (SUN_LUX / PI as f64) as f32;
    for (x, b) in xs.iter().zip(&out.b) {
        if *x < 0.0 {
            assert_eq!(b[0], 0.0, "x = {x}: under the opaque half");
        } else {
            assert!((b[0] / e - 1.0).abs() < 2e-4, "x = {x}: B = {} under the cut-out half, want {e}", b[0]);
        }
    }
    // Under a uniform sky (radiance 1) and no sun: hemisphere rays pass through the cut-out, so
    // B = 1 - (irradiance the opaque half would send) / pi.
    let mut s = Soup::new();
    s.quad([0.0; 3], [10.0, 0.0, 0.0], [0.0, 0.0, -10.0], 0.0, 0.0);
    masked(&mut s);
    let scene = s.scene(vec![], Some([1.0; 3]));
    let opaque_half = [[-1.0, 1.0, -1.0], [0.0, 1.0, -1.0], [0.0, 1.0, 1.0], [-1.0, 1.0, 1.0]];
    let want = 1.0 - polygon_irradiance([0.0; 3], [0.0, 1.0, 0.0], &opaque_half) / PI as f64;
    let out = bake(&scene, &[[0.0; 3]; 64], &[[0.0, 1.0, 0.0]; 64], &settings(256, 0, 15));
    let (m, se) = mean_se(&out.b);
    assert!((m - want).abs() < 4.0 * se && (m - want).abs() < 0.01, "sky through the hole: B = {m} (se {se}), want {want}");
}

#[test]
fn hashed_alpha_lets_one_minus_alpha_through_and_opaque_ignores_alpha() {
    // A pane of alpha 0.3 1 m above the floor under a sun straight down.
    let pane = |alpha: Alpha| {
        let mut s = Soup::new();
        s.quad([0.0; 3], [10.0, 0.0, 0.0], [0.0, 0.0, -10.0], 0.5, 0.0);
        s.quad_with([0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], Material { base_color: [0.2, 0.6, 0.9, 0.3], alpha, ..Material::default() });
        s.scene(sun_down(), None)
    };
    let pts: Vec<V3> = (0..256).map(|i| [-0.8 + 1.6 * (i % 16) as f32 / 15.0, 0.0, -0.8 + 1.6 * (i / 16) as f32 / 15.0]).collect();
    let nrm = vec![[0.0, 1.0, 0.0]; pts.len()];
    let e = SUN_LUX / PI as f64;
    // Blend: each shadow ray passes where alpha < a hash of the point it crosses.
    let out = bake(&pane(Alpha::Blend), &pts, &nrm, &settings(64, 0, 16));
    let (m, se) = mean_se(&out.b);
    let (m, se) = (m / e, se / e);
    assert!((m - 0.7).abs() < 4.0 * se && se < 0.01, "transmittance {m} (se {se}), want 0.7");
    // Opaque ignores alpha: full shadow. Mask at 0.5 with alpha 0.3 everywhere: no shadow.
    assert!(bake(&pane(Alpha::Opaque), &pts, &nrm, &settings(8, 0, 16)).b.iter().all(|b| b[0] == 0.0));
    let m = mean(&bake(&pane(Alpha::Mask(0.5)), &pts, &nrm, &settings(8, 0, 16)).b);
    assert!((m / e - 1.0).abs() < 2e-4, "{m}");
}

#[test]
fn single_sided_back_faces_are_black_double_sided_ones_reflect() {
    // A 4 x 4 m quad of albedo 0.8 1 m above a black floor, a point light between them: floor
    // points get the light directly plus what the quad's underside reflects. The underside is
    // the front of a quad facing down, the back of one facing up: black if single-sided (B is
    // then the direct light alone, exactly), the same surface if double-sided.
    let light = lights(r#"[{"name":"p","kind":"point","intensity":100,"position":[0.5,0.5,0]}]"#);
    let pts: Vec<V3> = (0..64).map(|i| [-0.7 + 0.2 * (i % 8) as f32, 0.0, -0.7 + 0.2 * (i / 8) as f32]).collect();
    let nrm = vec![[0.0, 1.0, 0.0]; pts.len()];
    let run = |facing_up: bool, double_sided: bool| {
        let mut s = Soup::new();
        s.quad([0.0; 3], [10.0, 0.0, 0.0], [0.0, 0.0, -10.0], 0.0, 0.0);
        let v = if facing_up { [0.0, 0.0, -2.0] } else { [0.0, 0.0, 2.0] };
        s.quad_with([0.0, 1.0, 0.0], [2.0, 0.0, 0.0], v, Material { base_color: [0.8, 0.8, 0.8, 1.0], double_sided, ..Material::default() });
        bake(&s.scene(light.clone(), None), &pts, &nrm, &settings(256, 1, 17)).b
    };
    let (down, up, up_double) = (run(false, false), run(true, false), run(true, true));
    for (x, b) in pts.iter().zip(&up) {
        let d = sub([0.5, 0.5, 0.0], *x);
        let direct = 100.0 * d[1] / length(d) / dot(d, d) / PI;
        assert!((b[0] / direct - 1.0).abs() < 1e-5, "{x:?}: {} want the direct light {direct}", b[0]);
    }
    // Point by point (the direct light varies over the points): the underside's reflection,
    // down - up, is large against its noise; down and double-sided up agree within theirs.
    let diff = |a: &[V3], b: &[V3]| -> Vec<V3> { a.iter().zip(b).map(|(x, y)| [x[0] - y[0]; 3]).collect() };
    let ((reflected, se_r), (delta, se_d)) = (mean_se(&diff(&down, &up)), mean_se(&diff(&down, &up_double)));
    assert!(reflected > 20.0 * se_r && reflected > 0.2 * mean(&up), "the underside's reflection {reflected} (se {se_r}), direct {}", mean(&up));
    assert!(delta.abs() < 4.0 * se_d, "facing down vs double-sided facing up: {delta} (se {se_d})");
}

#[test]
fn double_sided_emitters_emit_and_are_sampled_from_both_sides() {
    // T11's square light as emissive triangles, facing away from the point: nothing if
    // single-sided, the full closed form if double-sided (light samples and MIS from the back).
    for (down, double_sided, lit) in [(true, false, true), (false, false, false), (false, true, true)] {
        let mut s = Soup::new();
        s.quad([0.0; 3], [10.0, 0.0, 0.0], [0.0, 0.0, -10.0], 0.0, 0.0);
        let v = if down { [0.0, 0.0, 1.0] } else { [0.0, 0.0, -1.0] };
        s.quad_with([0.0, 1.5, 0.0], [1.0, 0.0, 0.0], v, Material { base_color: [0.0, 0.0, 0.0, 1.0], emissive: [2.0; 3], double_sided, ..Material::default() });
        let poly = [[-1.0, 1.5, -1.0], [1.0, 1.5, -1.0], [1.0, 1.5, 1.0], [-1.0, 1.5, 1.0]];
        let want = if lit { 2.0 * polygon_irradiance([0.0; 3], [0.0, 1.0, 0.0], &poly) / PI as f64 } else { 0.0 };
        let m = mean(&bake(&s.scene(vec![], None), &[[0.0; 3]; 64], &[[0.0, 1.0, 0.0]; 64], &settings(512, 0, 18)).b);
        assert!((m - want).abs() <= 0.01 * want, "facing down {down}, double-sided {double_sided}: {m} want {want}");
    }
}

#[test]
fn probes_count_only_single_sided_back_faces_as_inside() {
    // A probe inside a closed box (faces outward) with a point light: single-sided, it sees only
    // back faces (inside geometry) and the light's direct delta; double-sided, the walls' inner
    // sides are surfaces that reflect the light back to it.
    let probe = |double_sided: bool| {
        let mut s = Soup::new();
        s.cube_with([0.0; 3], [1.0; 3], false, Material { base_color: [0.5, 0.5, 0.5, 1.0], double_sided, ..Material::default() });
        let scene = s.scene(lights(r#"[{"name":"p","kind":"point","intensity":10,"position":[0.3,0.2,0.1]}]"#), Some([1.0; 3]));
        probes(&scene, &[[0.0; 3]], &settings(256, 1, 19))[0].clone()
    };
    let (single, double) = (probe(false), probe(true));
    assert_eq!((single.backface, double.backface), (1.0, 0.0));
    assert!(double.sh[0][0] > 1.1 * single.sh[0][0], "the walls' reflection: {:?} vs {:?}", double.sh[0], single.sh[0]);
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
    let (blocks, used) = bvh.block_fill();
    println!("build {:.1} ms, {} nodes, {blocks} leaf blocks holding {:.2} triangles each", t0.elapsed().as_secs_f64() * 1e3, bvh.node_count(), used as f64 / blocks as f64);
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
    // Shadow rays: the same rays as any-hit queries.
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let t0 = std::time::Instant::now();
        hits = rays.iter().filter(|r| bvh.any(r)).count();
        best = best.min(t0.elapsed().as_secs_f64());
    }
    stats::take();
    println!("any-hit: hit {:.4}, {:.2} Mrays/s", hits as f64 / n as f64, n as f64 / best / 1e6);
    // The filtered walk (alpha-tested surfaces): every 16th triangle flagged, a filter that keeps
    // every hit (so the answers are the unfiltered ones): what asking the filter costs.
    let flagged: Vec<bool> = (0..tris.len()).map(|i| i % 16 == 0).collect();
    let fbvh = Bvh::build_flagged(&pos, &tris, Some(&flagged));
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let t0 = std::time::Instant::now();
        hits = rays.iter().filter(|r| fbvh.closest_filtered(r, |p, t| p != u32::MAX && t >= 0.0).is_some()).count();
        best = best.min(t0.elapsed().as_secs_f64());
    }
    stats::take();
    println!("filtered closest (1/16 of triangles flagged): hit {:.4}, {:.2} Mrays/s", hits as f64 / n as f64, n as f64 / best / 1e6);
}


// ---- directional lightmaps (shading.md §4) ---------------------------------------------

fn bake_directional(scene: &BakeScene, pts: &[V3], nrm: &[V3], s: &BakeSettings) -> BakedDirectional {
    bake_points_directional(scene, pts, nrm, None, s, &|_, _| {}, &AtomicBool::new(false)).unwrap()
}

/// Mean over texels of channel 0's b0 and b1, and the standard error of b0.
fn mean_l1(t: &[DirectionalTexel]) -> (f64, [f64; 3], f64) {
    let n = t.len() as f64;
    let b0 = t.iter().map(|t| t.b0[0] as f64).sum::<f64>() / n;
    let b1 = [0, 1, 2].map(|a| t.iter().map(|t| t.b1[0][a] as f64).sum::<f64>() / n);
    let var = t.iter().map(|t| (t.b0[0] as f64 - b0).powi(2)).sum::<f64>() / (n - 1.0);
    (b0, b1, (var / n).sqrt())
}

#[test]
fn directional_texel_under_a_uniform_sky_is_half_l_and_half_l_up() {
    // shading.md §4.1: b0 = L/2, b1 = (L/2) n_g, so B(n) = L (1 + n.n_g)/2 for every normal.
    let l = 1000.0f32;
    let mut s = Soup::new();
    s.quad([0.0; 3], [50.0, 0.0, 0.0], [0.0, 0.0, -50.0], 0.0, 0.0);
    let scene = s.scene(vec![], Some([l; 3]));
    let pts = vec![[0.0; 3]; 256];
    let out = bake_directional(&scene, &pts, &vec![[0.0, 1.0, 0.0]; 256], &settings(64, 1, 7));
    let (b0, b1, se) = mean_l1(&out.texels);
    eprintln!("uniform sky: b0 {b0:.2} (se {se:.2}), b1 {b1:.2?}");
    assert!((b0 - 500.0).abs() < 4.0 * se.max(0.1) && (b0 - 500.0).abs() < 5.0, "b0 {b0}");
    // b1's standard errors per axis: its sideways parts are as noisy as its upward one.
    let n = out.texels.len() as f64;
    let se1 = [0, 1, 2].map(|a| (out.texels.iter().map(|t| (t.b1[0][a] as f64 - b1[a]).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt());
    eprintln!("b1 standard errors {se1:.2?}");
    let want = [0.0, 500.0, 0.0];
    assert!((0..3).all(|a| (b1[a] - want[a]).abs() < 4.0 * se1[a] && se1[a] < 8.0), "b1 {b1:?}, se {se1:?}");
    assert!(out.texels.iter().all(|t| t.sun_visibility == 1.0 && t.b0[0] == t.b0[1]));
}

#[test]
fn directional_texel_of_a_point_light_is_its_delta() {
    // A point light seen from x: each sample's next-event estimate is exact, so b0 = E/4 pi and
    // b1 = E d / 2 pi, E = I / r^2 its perpendicular illuminance, to float precision.
    let mut s = Soup::new();
    s.quad([0.0; 3], [10.0, 0.0, 0.0], [0.0, 0.0, -10.0], 0.0, 0.0);
    let scene = s.scene(lights(r#"[{"name":"p","kind":"point","intensity":100,"position":[0,2,0]}]"#), None);
    let x = [1.0, 0.0, 0.5];
    let t = bake_directional(&scene, &[x], &[[0.0, 1.0, 0.0]], &settings(16, 0, 1)).texels[0];
    let d = sub([0.0, 2.0, 0.0], x);
    let r2 = dot(d, d);
    let e = 100.0 / r2;
    let want_b1 = scale(normalize(d), e / (2.0 * PI));
    assert!((t.b0[0] - e / (4.0 * PI)).abs() < 1e-5 * e, "b0 {} want {}", t.b0[0], e / (4.0 * PI));
    for a in 0..3 {
        assert!((t.b1[0][a] - want_b1[a]).abs() < 1e-5 * e, "b1 {:?} want {want_b1:?}", t.b1[0]);
    }
}

#[test]
fn directional_texel_of_a_square_light_matches_its_solid_angle_and_irradiance() {
    // On the axis of a square of radiance L (half side a, height h): b0 = L Omega / 4 pi with
    // Omega = 4 asin(a^2 / (a^2 + h^2)), and b1 = L P / 2 pi along the axis, P the polygon's
    // irradiance factor (Lambert's formula): as a rect light and as emissive triangles, both
    // MIS-weighted against the continuation rays.
    for tri in [false, true] {
        let (l, h, a) = (2.0f32, 1.5f32, 1.0f32);
        let (scene, want_b) = square_light_scene(tri, l, h, a);
        let omega = 4.0 * ((a * a) as f64 / (a * a + h * h) as f64).asin();
        let want_b0 = l as f64 * omega / (4.0 * PI as f64);
        // B(n_g) = H / pi = L P / pi, so b1 = B pi / 2 pi = B / 2.
        let want_b1 = want_b / 2.0;
        let out = bake_directional(&scene, &vec![[0.0; 3]; 64], &vec![[0.0, 1.0, 0.0]; 64], &settings(512, 0, 5));
        let (b0, b1, _) = mean_l1(&out.texels);
        eprintln!("square light (triangles {tri}): b0 {b0:.4} want {want_b0:.4}, b1 {b1:.4?} want (0, {want_b1:.4}, 0)");
        assert!((b0 / want_b0 - 1.0).abs() < 0.01, "triangles={tri}: b0 {b0} want {want_b0}");
        assert!((b1[1] / want_b1 - 1.0).abs() < 0.01 && b1[0].abs() < 0.01 * want_b1 && b1[2].abs() < 0.01 * want_b1, "triangles={tri}: b1 {b1:?} want {want_b1}");
    }
}

#[test]
fn directional_texels_leave_the_sun_to_the_runtime_with_its_visibility() {
    // Sun and sky over a black floor with a black wall: the L1 is the sky's alone, the same
    // as the scene's without the sun (within the estimates' error: their random streams
    // differ); the visibility is 0 in the wall's shadow and 1 in the open.
    let mut s = Soup::new();
    s.quad([0.0; 3], [10.0, 0.0, 0.0], [0.0, 0.0, -10.0], 0.0, 0.0);
    s.cube([0.0, 1.0, 0.0], [0.1, 1.0, 5.0], false, 0.0, 0.0);
    let sun = r#"[{"name":"sun","kind":"sun","intensity":1000,"direction":[-0.6,-0.8,0]}]"#;
    let n = [0.0, 1.0, 0.0];
    // The sun comes from +x: x = -0.5 is in the wall's shadow (the wall is 2 high, the shadow
    // 1.5 long), x = 3 in the open.
    let (shade, open) = ([-0.5, 0.0, 0.0], [3.0, 0.0, 0.0]);
    let pts: Vec<V3> = [shade, open].iter().flat_map(|p| std::iter::repeat_n(*p, 64)).collect();
    let with_sun = bake_directional(&s.scene(lights(sun), Some([10.0; 3])), &pts, &vec![n; 128], &settings(128, 2, 3));
    let without = bake_directional(&s.scene(vec![], Some([10.0; 3])), &pts, &vec![n; 128], &settings(128, 2, 4));
    for (k, place) in ["shadow", "open"].into_iter().enumerate() {
        let texels = |b: &BakedDirectional| b.texels[64 * k..64 * (k + 1)].to_vec();
        let ((b0, b1, se), (b0_ref, b1_ref, se_ref)) = (mean_l1(&texels(&with_sun)), mean_l1(&texels(&without)));
        let vis: Vec<f32> = texels(&with_sun).iter().map(|t| t.sun_visibility).collect();
        eprintln!("{place}: vis {:?}, b0 {b0:.3} (without the sun {b0_ref:.3}, se {se:.3}), b1 {b1:.3?} ({b1_ref:.3?})", vis[0]);
        assert!(vis.iter().all(|&v| v == if k == 0 { 0.0 } else { 1.0 }), "{place}: visibility {vis:?}");
        let tol = 4.0 * (se * se + se_ref * se_ref).sqrt();
        assert!((b0 - b0_ref).abs() < tol && (b1[1] - b1_ref[1]).abs() < 2.0 * tol, "{place}: b0 {b0} b1 {b1:?} vs without the sun {b0_ref} {b1_ref:?} (tol {tol})");
    }
}

#[test]
fn directional_sunlit_texels_runtime_light_for_tilted_normals_is_the_bakers_for_tilted_geometry() {
    // Issue 22's acceptance on the CPU: a sun (60 000 lux, 30 degrees from the zenith) and a
    // sky of 2000 nits over a black floor. For normals tilted up to 60 degrees, the runtime's
    // reconstruction, clamped L1 + E vis max(0, n.l) / pi, is within 3% of B baked at the
    // tilted normal itself.
    let mut s = Soup::new();
    s.quad([0.0; 3], [50.0, 0.0, 0.0], [0.0, 0.0, -50.0], 0.0, 0.0);
    let sun_dir = normalize([-0.5, -(3f32.sqrt() / 2.0), 0.0]);
    let json = format!(r#"[{{"name":"sun","kind":"sun","intensity":60000,"direction":[{},{},{}]}}]"#, sun_dir[0], sun_dir[1], sun_dir[2]);
    let scene = s.scene(lights(&json), Some([2000.0; 3]));
    let pts = vec![[0.0; 3]; 64];
    let l1 = bake_directional(&scene, &pts, &vec![[0.0, 1.0, 0.0]; 64], &settings(256, 1, 11));
    let (b0, b1, _) = mean_l1(&l1.texels);
    let vis = l1.texels.iter().map(|t| t.sun_visibility as f64).sum::<f64>() / 64.0;
    let towards_sun = scale(sun_dir, -1.0);
    for deg in [0.0f32, 15.0, 30.0, 45.0, 60.0] {
        for side in [1.0f32, -1.0] {
            let t = (deg * side).to_radians();
            let n = [t.sin(), t.cos(), 0.0];
            let runtime = (b0 + b1[0] * n[0] as f64 + b1[1] * n[1] as f64 + b1[2] * n[2] as f64).max(0.0) + 60_000.0 * vis * (dot(n, towards_sun).max(0.0) as f64) / PI as f64;
            let baked = mean(&bake(&scene, &pts, &vec![n; 64], &settings(256, 1, 12)).b);
            eprintln!("tilt {:+}: runtime {runtime:.1} nits, baked {baked:.1}", deg * side);
            assert!((runtime / baked - 1.0).abs() < 0.03, "tilt {}: runtime {runtime} vs baked {baked}", deg * side);
        }
    }
}

// ---- reflection probes (shading.md §3) --------------------------------------------------------

use super::reflection::*;

#[test]
fn cube_faces_follow_vulkans_table() {
    // §6f: (1, 0.5, -0.5) is on +X at (s, t) = (0.75, 0.25); straight up is layer 2.
    let (face, s, t) = face_coords([1.0, 0.5, -0.5]);
    assert_eq!((face, s, t), (0, 0.75, 0.25));
    assert_eq!(face_coords([0.0, 1.0, 0.0]).0, 2);
    // Every texel's direction selects its own face at its own centre, and the texels' solid
    // angles cover the sphere.
    for size in [1usize, 4, 7, 32] {
        let mut total = 0.0f64;
        for i in 0..6 * size * size {
            let (face, s, t) = face_coords(Cube::direction_of(size, i));
            let (j, col) = ((i / size) % size, i % size);
            assert_eq!(face, i / (size * size), "size {size} texel {i}");
            assert!((s - (col as f32 + 0.5) / size as f32).abs() < 1e-6 && (t - (j as f32 + 0.5) / size as f32).abs() < 1e-6, "size {size} texel {i}: ({s}, {t})");
            total += Cube::solid_angle_of(size, i) as f64;
        }
        // The midpoint rule over a face, exact as the size grows.
        if size >= 7 {
            assert!((total / (4.0 * std::f64::consts::PI) - 1.0).abs() < 0.5 / (size * size) as f64, "size {size}: {total}");
        }
    }
}

/// Smooth but lopsided radiance: a sharp-ish red lobe toward a cube corner (across three faces'
/// seams), a broad green one from below, a blue gradient.
fn structured(d: V3) -> V3 {
    let a = normalize([1.0, 0.6, 0.3]);
    let b = [0.0, -1.0, 0.0];
    [0.2 + 5.0 * dot(d, a).max(0.0).powi(16), 0.3 + 3.0 * dot(d, b).max(0.0).powi(4), 0.1 + 0.5 * (1.0 + d[1])]
}

#[test]
fn prefiltering_keeps_a_constant_cube_constant_and_matches_brute_force_ggx() {
    // A constant radiance stays itself at every level (§7.3: ±0.5 %).
    let constant = Cube::new(32, |_| [2.0, 1.0, 0.5]);
    for (k, level) in prefilter(&constant, 4, PREFILTER_SAMPLES).iter().enumerate() {
        assert_eq!(level.size, 32 >> k);
        for t in &level.texels {
            assert!((t[0] / 2.0 - 1.0).abs() < 5e-3 && (t[1] - 1.0).abs() < 5e-3 && (t[2] / 0.5 - 1.0).abs() < 5e-3, "level {k}: {t:?}");
        }
    }
    // The acceptance: each level's texels against the brute-force GGX convolution of the same
    // 128² cube (every source texel weighted by (n·l) D(h) dω), within 2 %, for several texels
    // (in the red lobe, on its flank, at a seam and a corner, away from it) and every roughness.
    let base = Cube::new(128, structured);
    let levels = prefilter(&base, 6, PREFILTER_SAMPLES);
    let probes: [V3; 6] = [normalize([1.0, 0.6, 0.3]), normalize([1.0, 0.3, 0.6]), [1.0, 1.0, 1.0], [1.0, 0.02, 0.0], [0.0, -1.0, 0.3], [-0.4, 0.2, -1.0]];
    let mut worst = 0.0f32;
    for (k, level) in levels.iter().enumerate().skip(1) {
        let r = level_roughness(k, 6);
        for d in probes {
            // The texel whose centre is nearest d, compared at its own centre direction.
            let (face, s, t) = face_coords(d);
            let n = level.size;
            let i = face * n * n + ((t * n as f32) as usize).min(n - 1) * n + ((s * n as f32) as usize).min(n - 1);
            let got = level.texels[i];
            let want = convolve_exact(&base, Cube::direction_of(n, i), r);
            for c in 0..3 {
                let e = (got[c] / want[c] - 1.0).abs();
                worst = worst.max(e);
                assert!(e < 0.02, "r {r} toward {d:?} channel {c}: prefiltered {} exact {} ({:.2} %)", got[c], want[c], 100.0 * e);
            }
        }
    }
    eprintln!("prefilter vs brute-force GGX: worst {:.2} % over 5 roughness levels x 6 texels x 3 channels", 100.0 * worst);
}

#[test]
fn a_bright_texel_spreads_wider_as_roughness_grows() {
    let bright = normalize([0.3, 1.0, -0.2]);
    let base = Cube::new(64, |d| if dot(d, bright) > 0.9995 { [1000.0; 3] } else { [0.0; 3] });
    let levels = prefilter(&base, 5, PREFILTER_SAMPLES);
    // Energy-weighted mean angle from the bright direction, per level.
    let spread: Vec<f32> = levels
        .iter()
        .map(|c| {
            let (mut s, mut w) = (0.0f64, 0.0f64);
            for (i, t) in c.texels.iter().enumerate() {
                let e = (t[0] * Cube::solid_angle_of(c.size, i)) as f64;
                s += e * dot(normalize(Cube::direction_of(c.size, i)), bright).clamp(-1.0, 1.0).acos() as f64;
                w += e;
            }
            (s / w) as f32
        })
        .collect();
    assert!(spread.windows(2).all(|p| p[1] > p[0]), "spread per level {spread:?}");
}

/// A closed box of black walls (albedo 0) each emitting its own colour, seen from inside.
fn coloured_box(h: f32) -> (BakeScene, [V3; 6]) {
    let colours: [V3; 6] = [[10.0, 0.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, 10.0], [10.0, 10.0, 0.0], [0.0, 10.0, 10.0], [10.0, 0.0, 10.0]];
    let mut soup = Soup::new();
    for k in 0..3 {
        for (side, s) in [1.0f32, -1.0].iter().enumerate() {
            let mut n = [0.0; 3];
            n[k] = *s;
            let (a, b) = ((k + 1) % 3, (k + 2) % 3);
            let (mut u, mut v) = ([0.0; 3], [0.0; 3]);
            u[a] = h;
            v[b] = h;
            // u x v points along +k: flip v for the +k wall so it faces in.
            let v = if *s > 0.0 { scale(v, -1.0) } else { v };
            soup.quad_with(scale(n, h), u, v, Material { base_color: [0.0, 0.0, 0.0, 1.0], emissive: colours[2 * k + side], ..Material::default() });
        }
    }
    // Layer order +X, -X, +Y, -Y, +Z, -Z matches (k, side) order.
    (soup.scene(vec![], None), colours)
}

#[test]
fn capture_sees_each_wall_in_its_face_and_the_sky_without_the_sun() {
    let cancel = AtomicBool::new(false);
    let (scene, colours) = coloured_box(3.0);
    let (cube, rays) = capture(&scene, [0.5, -0.4, 0.2], 0, 8, 4, 1, 7, &|_, _| {}, &cancel).unwrap();
    assert!(rays >= 6 * 64 * 4, "{rays} rays");
    for (i, t) in cube.texels.iter().enumerate() {
        // Each face's middle texels look at its wall whatever the probe's offset inside.
        let (j, col) = ((i / 8) % 8, i % 8);
        if (3..5).contains(&j) && (3..5).contains(&col) {
            assert_eq!(*t, colours[i / 64], "texel {i}");
        }
    }
    // Open sky over a black floor, with a sun: the sky exactly above (no disc), black below.
    let mut soup = Soup::new();
    soup.quad([0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [0.0, 0.0, -100.0], 0.0, 0.0);
    let scene = soup.scene(lights(r#"[{"name":"sun","kind":"sun","intensity":100000,"direction":[0,-1,0],"angular_radius":0.1}]"#), Some([500.0, 600.0, 700.0]));
    let (cube, _) = capture(&scene, [0.0, 1.0, 0.0], 3, 8, 2, 2, 7, &|_, _| {}, &cancel).unwrap();
    assert!(cube.texels[2 * 64..3 * 64].iter().all(|t| *t == [500.0, 600.0, 700.0]), "+Y face");
    assert!(cube.texels[3 * 64..4 * 64].iter().all(|t| *t == [0.0; 3]), "-Y face");
}

#[test]
fn capture_is_the_same_on_one_and_two_threads() {
    let mut soup = Soup::new();
    soup.cube([0.0, 0.0, 0.0], [4.0, 3.0, 5.0], true, 0.7, 0.0);
    soup.quad([0.0, 2.9, 0.0], [0.5, 0.0, 0.0], [0.0, 0.0, 0.5], 0.0, 200.0);
    let scene = soup.scene(vec![], None);
    let cancel = AtomicBool::new(false);
    let run = |threads| super::with_threads(Some(threads), || capture(&scene, [1.0, 0.5, -1.0], 2, 8, 8, 2, 11, &|_, _| {}, &cancel).unwrap()).unwrap();
    let (a, b) = (run(1), run(2));
    assert_eq!(a, b);
    assert!(a.0.texels.iter().all(|t| t.iter().all(|c| c.is_finite() && *c >= 0.0)));
    // Another probe id draws other random numbers.
    let c = capture(&scene, [1.0, 0.5, -1.0], 3, 8, 8, 2, 11, &|_, _| {}, &cancel).unwrap();
    assert_ne!(a.0, c.0);
}

// ---- refinement: samples added in steps end where one pass ends (cook --watch) ------------

/// A lit room with a sun through an opening, a point light, a sky and a bounce: every kind of
/// sample the lightmaps and the reflection capture draw.
fn refinement_scene() -> BakeScene {
    let mut soup = Soup::new();
    soup.cube([0.0, 0.0, 0.0], [4.0, 3.0, 5.0], true, 0.7, 0.0);
    soup.quad([0.0, 2.9, 0.0], [0.5, 0.0, 0.0], [0.0, 0.0, 0.5], 0.0, 200.0);
    soup.scene(
        lights(r#"[{"name":"sun","kind":"sun","intensity":50000,"direction":[0.3,-1,0.2],"angular_radius":0.02},
                  {"name":"lamp","kind":"point","intensity":40,"position":[1,2,1],"range":0}]"#),
        Some([300.0, 400.0, 500.0]),
    )
}

#[test]
fn samples_added_in_steps_finish_to_the_bits_of_one_pass() {
    let scene = refinement_scene();
    let cancel = AtomicBool::new(false);
    let quiet = |_: u64, _: u64| {};
    // Points on the floor and walls, one without a usable normal (it bakes as nothing).
    let pts: Vec<V3> = (0..40).map(|i| [-1.5 + 0.07 * i as f32, -1.49, -2.0 + 0.1 * i as f32]).chain([[0.0, 0.0, 0.0]]).collect();
    let mut nrm = vec![[0.0, 1.0, 0.0]; 40];
    nrm.push([0.0, 0.0, 0.0]);
    let ids: Vec<u64> = (0..pts.len() as u64).map(|i| 1000 + 7 * i).collect();
    let s = settings(12, 2, 5);
    for steps in [vec![0, 12], vec![0, 1, 4, 12], vec![0, 5, 6, 12]] {
        let mut sums = vec![[0.0f64; 3]; pts.len()];
        let mut dsums = vec![TexelSums::default(); pts.len()];
        for w in steps.windows(2) {
            add_point_samples(&scene, &pts, &nrm, Some(&ids), &s, w[0]..w[1], &mut sums, &quiet, &cancel).unwrap();
            add_texel_samples(&scene, &pts, &nrm, Some(&ids), &s, w[0]..w[1], &mut dsums, &quiet, &cancel).unwrap();
        }
        let one = bake_points(&scene, &pts, &nrm, Some(&ids), &s, &quiet, &cancel).unwrap();
        let stepped: Vec<V3> = sums.iter().map(|v| finish_point(v, 12)).collect();
        assert_eq!(stepped, one.b, "irradiance, steps {steps:?}");
        let one = bake_points_directional(&scene, &pts, &nrm, Some(&ids), &s, &quiet, &cancel).unwrap();
        let stepped: Vec<DirectionalTexel> = dsums.iter().zip(pts.iter().zip(&nrm)).map(|(v, (&x, &n))| finish_texel(&scene, v, 12, x, n)).collect();
        assert_eq!(stepped, one.texels, "directional, steps {steps:?}");
    }
    // An intermediate step is the one-pass bake of that many samples.
    let mut sums = vec![[0.0f64; 3]; pts.len()];
    add_point_samples(&scene, &pts, &nrm, Some(&ids), &s, 0..4, &mut sums, &quiet, &cancel).unwrap();
    let four = bake_points(&scene, &pts, &nrm, Some(&ids), &settings(4, 2, 5), &quiet, &cancel).unwrap();
    assert_eq!(sums.iter().map(|v| finish_point(v, 4)).collect::<Vec<_>>(), four.b);
    assert!(four.b[..40].iter().any(|b| b.iter().any(|&c| c > 0.0)), "the room is lit");

    // Reflection capture likewise.
    let one = capture(&scene, [0.5, 0.0, 0.3], 1, 8, 6, 2, 9, &quiet, &cancel).unwrap().0;
    let mut sums = vec![[0.0f64; 3]; 6 * 64];
    for w in [0, 2, 3, 6].windows(2) {
        add_capture_samples(&scene, [0.5, 0.0, 0.3], 1, 8, w[0]..w[1], 2, 9, &mut sums, &quiet, &cancel).unwrap();
    }
    assert_eq!(finish_capture(&sums, 8, 6), one);
}
