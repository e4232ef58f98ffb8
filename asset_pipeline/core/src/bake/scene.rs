//! The scene the integrator traces: world-space triangles with their materials ([`Surfaces`]),
//! the emissive triangles and the distribution that picks them for light sampling, analytic
//! lights and the sky; and ray queries that see the surfaces as their materials make them
//! (points an alpha test cuts out are passed through, in the BVH walk itself).

use super::bvh::{Bvh, Hit, Ray};
use super::light_set::LightSet;
use super::lights::Light;
use super::material::{Material, Surfaces, VertexAttributes};
use super::sampling::*;
use super::textures::{Footprint, Texture};
use std::collections::BTreeMap;

/// The triangles of a scene and what their materials read, borrowed.
pub struct Geometry<'a> {
    /// World space.
    pub positions: &'a [V3],
    pub triangles: &'a [[u32; 3]],
    /// Index into the materials, per triangle.
    pub materials: &'a [u32],
    pub attributes: VertexAttributes<'a>,
}

pub struct BakeScene {
    bvh: Bvh,
    pub(super) tris: Vec<[V3; 3]>,
    /// Unit geometric normal (b-a)x(c-a) of each triangle: its front side.
    pub(super) normals: Vec<V3>,
    pub(super) surfaces: Surfaces,
    /// Emissive triangles and the cumulative distribution that picks them (area x emitted
    /// luminance, see `Surfaces::emitter_weight`).
    emitters: Vec<u32>,
    emitter_cdf: Vec<f32>,
    /// Per triangle: probability of picking it / its area (the area pdf of emitter sampling);
    /// 0 for triangles that are not emitters.
    emitter_pdf: Vec<f32>,
    pub(super) lights: LightSet,
    pub(super) sky: Option<V3>,
    /// Some triangle may let rays through: queries go through the hit filter.
    filtered: bool,
}

/// A surface point a ray reached, as the side it reached sees it.
pub struct SurfaceHit {
    pub prim: usize,
    pub p: V3,
    /// Barycentric weights of the triangle's corners at `p`: where its material is read.
    pub bary: V3,
    /// Unit normal on the side the ray came from.
    pub n: V3,
    /// Cosine between `n` and the way back along the ray.
    pub cos: f32,
}

impl BakeScene {
    /// `sky` is a uniform radiance (nits) or None for no sky.
    pub fn new(geometry: Geometry, materials: Vec<Material>, textures: Vec<Texture>, lights: Vec<Light>, sky: Option<V3>) -> Result<BakeScene, String> {
        let Geometry { positions, triangles, materials: triangle_materials, attributes } = geometry;
        let m = triangles.len();
        if let Some(i) = triangles.iter().position(|t| t.iter().any(|&v| v as usize >= positions.len())) {
            return Err(format!("triangle {i} indexes a vertex past the {} positions", positions.len()));
        }
        let surfaces = Surfaces::new(triangles, positions.len(), triangle_materials, attributes, materials, textures)?;
        let tris: Vec<[V3; 3]> = triangles.iter().map(|t| t.map(|v| positions[v as usize])).collect();
        let mut normals = Vec::with_capacity(m);
        let mut areas = Vec::with_capacity(m);
        for t in &tris {
            let c = cross(sub(t[1], t[0]), sub(t[2], t[0]));
            let l = length(c);
            normals.push(if l > 0.0 { scale(c, 1.0 / l) } else { [0.0; 3] });
            areas.push(0.5 * l);
        }
        // Light sampling picks a triangle by area x how much it emits (a texture's mean over the
        // triangle's footprint), then a uniform point on it, whose real emission is evaluated:
        // unbiased as long as every triangle that emits somewhere can be picked.
        let mut weight = vec![0.0f64; m];
        let mut textured: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
        for (i, w) in weight.iter_mut().enumerate() {
            match surfaces.emissive_texture(i) {
                Some(t) => textured.entry(t).or_default().push(i),
                None => *w = areas[i] as f64 * surfaces.emitter_weight(i, None),
            }
        }
        // One footprint table at a time: only one is ever held.
        for (t, prims) in textured {
            let table = Footprint::new(&surfaces.textures[t]);
            for i in prims {
                weight[i] = areas[i] as f64 * surfaces.emitter_weight(i, Some(&table));
            }
        }
        let emitters: Vec<u32> = (0..m).filter(|&i| weight[i] > 0.0 && weight[i].is_finite() && areas[i] > 0.0).map(|i| i as u32).collect();
        let total: f64 = emitters.iter().map(|&i| weight[i as usize]).sum();
        let mut acc = 0.0f64;
        let emitter_cdf: Vec<f32> = emitters
            .iter()
            .map(|&i| {
                acc += weight[i as usize];
                (acc / total) as f32
            })
            .collect();
        let mut emitter_pdf = vec![0.0; m];
        for &i in &emitters {
            let i = i as usize;
            emitter_pdf[i] = (weight[i] / total / areas[i] as f64) as f32;
        }
        let flagged: Vec<bool> = (0..m).map(|i| surfaces.maybe_transparent(i)).collect();
        let filtered = flagged.iter().any(|&f| f);
        Ok(BakeScene {
            bvh: Bvh::build_flagged(positions, triangles, filtered.then_some(&flagged[..])),
            tris,
            normals,
            surfaces,
            emitters,
            emitter_cdf,
            emitter_pdf,
            lights: LightSet::new(lights),
            sky,
            filtered,
        })
    }

    pub fn bvh(&self) -> &Bvh {
        &self.bvh
    }

    /// Whether the hit at distance `t` along `ray` on triangle `prim` is a surface point (not
    /// cut out by its material's alpha test).
    fn kept(&self, ray: &Ray, prim: u32, t: f32) -> bool {
        let p = add(ray.origin, scale(ray.dir, t));
        let prim = prim as usize;
        self.surfaces.present(prim, p, self.barycentrics(prim, p))
    }

    /// Closest surface hit with `tmin < t < tmax`, through alpha-tested cut-outs.
    pub fn closest(&self, ray: &Ray) -> Option<Hit> {
        if self.filtered {
            self.bvh.closest_filtered(ray, |prim, t| self.kept(ray, prim, t))
        } else {
            self.bvh.closest(ray)
        }
    }

    /// Whether a surface blocks `ray` within `tmin < t < tmax` (shadow rays), through cut-outs.
    pub fn occluded(&self, ray: &Ray) -> bool {
        if self.filtered {
            self.bvh.any_filtered(ray, |prim, t| self.kept(ray, prim, t))
        } else {
            self.bvh.any(ray)
        }
    }

    /// Barycentric weights of the triangle's corners at point `p` (on or next to its plane),
    /// clamped into the triangle: where a material is read.
    pub fn barycentrics(&self, prim: usize, p: V3) -> V3 {
        let [a, b, c] = self.tris[prim];
        let (e1, e2, d) = (sub(b, a), sub(c, a), sub(p, a));
        let (d11, d12, d22) = (dot(e1, e1), dot(e1, e2), dot(e2, e2));
        let (dp1, dp2) = (dot(d, e1), dot(d, e2));
        let den = d11 * d22 - d12 * d12;
        if den.is_nan() || den <= 0.0 {
            return [1.0, 0.0, 0.0];
        }
        let beta = ((d22 * dp1 - d12 * dp2) / den).clamp(0.0, 1.0);
        let gamma = ((d11 * dp2 - d12 * dp1) / den).clamp(0.0, 1.0 - beta);
        [1.0 - beta - gamma, beta, gamma]
    }

    /// The surface a ray along unit `w` reached at its hit `h` (origin `o`), or None where the
    /// path ends there: a single-sided material's back face (opaque and black, notes in
    /// `integrator`) or a degenerate triangle.
    pub fn surface(&self, o: V3, w: V3, h: &Hit) -> Option<SurfaceHit> {
        let prim = h.prim as usize;
        let ng = self.normals[prim];
        let c = -dot(ng, w);
        let (n, cos) = if c > 0.0 {
            (ng, c)
        } else if c < 0.0 && self.surfaces.material(prim).double_sided {
            (scale(ng, -1.0), -c)
        } else {
            return None;
        };
        let p = add(o, scale(w, h.t));
        Some(SurfaceHit { prim, p, bary: self.barycentrics(prim, p), n, cos })
    }

    pub fn has_emitters(&self) -> bool {
        !self.emitters.is_empty()
    }

    /// The emissive triangle that `u` in [0, 1) picks.
    pub fn pick_emitter(&self, u: f32) -> usize {
        let k = self.emitter_cdf.partition_point(|&c| c <= u).min(self.emitters.len() - 1);
        self.emitters[k] as usize
    }

    /// Area pdf of light sampling picking a point on triangle `prim` (0: never picked).
    #[inline]
    pub fn emitter_pdf(&self, prim: usize) -> f32 {
        self.emitter_pdf[prim]
    }
}
