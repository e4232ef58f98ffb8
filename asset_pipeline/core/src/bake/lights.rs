//! Analytic lights in the physical units of `ir.Light`, and their next-event samples.
//!
//! Units (photometric, tinted by a linear `color`): sun in lux (illuminance at normal incidence),
//! point and spot in candela, rect in nits (luminance of the emitting face). The baker's sky is in
//! nits too, so irradiance comes out in lux and the stored B = H/pi in nits.

use super::sampling::*;
use serde::Deserialize;

#[derive(Clone, Debug)]
pub enum Light {
    /// A disk of the sky: illuminance `e` (lux) at normal incidence; light travels along `dir`.
    /// Sampled uniformly in its cone of half-angle acos(cos_max), so its shadows are soft.
    Sun { dir: V3, e: V3, cos_max: f32 },
    /// Intensity `i` (candela); inverse-square falloff, windowed to zero at `range` if given.
    Point { pos: V3, i: V3, range: Option<f32> },
    /// A point light whose intensity falls from full inside `cos_inner` to zero at `cos_outer`:
    /// KHR_lights_punctual's recommended falloff, the square of the cosine's linear ramp between
    /// them (a hard edge when they are equal), so spots bake as glTF viewers show them.
    Spot { pos: V3, dir: V3, i: V3, cos_inner: f32, cos_outer: f32, range: Option<f32> },
    /// One-sided rectangle: centre, emitting normal `n` (the way light travels), half-extent
    /// vectors `hu`, `hv`, luminance `l` (nits). It lights the scene but does not occlude.
    Rect { c: V3, n: V3, hu: V3, hv: V3, l: V3 },
}

/// A next-event sample: unit direction to the light, distance (inf for the sun), the irradiance
/// this sample contributes if unoccluded (lux, already divided by the pdf), and for area lights
/// the solid-angle pdf of the sample (for MIS against cosine sampling).
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    pub dir: V3,
    pub dist: f32,
    pub h: V3,
    pub pdf: Option<f32>,
}

#[derive(Deserialize)]
struct IrLight {
    #[serde(default)]
    name: String,
    kind: String,
    #[serde(default = "one3")]
    color: [f32; 3],
    #[serde(default = "one")]
    intensity: f32,
    #[serde(default)]
    position: [f32; 3],
    #[serde(default = "down")]
    direction: [f32; 3],
    #[serde(default)]
    range: Option<f32>,
    #[serde(default)]
    inner_cone: f32,
    #[serde(default = "quarter_pi")]
    outer_cone: f32,
    #[serde(default = "one2")]
    size: [f32; 2],
    #[serde(default = "sun_radius")]
    angular_radius: f32,
}
fn one() -> f32 {
    1.0
}
fn one2() -> [f32; 2] {
    [1.0; 2]
}
fn one3() -> [f32; 3] {
    [1.0; 3]
}
fn down() -> [f32; 3] {
    [0.0, -1.0, 0.0]
}
fn quarter_pi() -> f32 {
    std::f32::consts::FRAC_PI_4
}
fn sun_radius() -> f32 {
    0.00465
}

/// Tangent axes of a rect light with emitting normal `n`: width along a horizontal axis
/// (cross(+Y, n)), height along cross(n, width); for a light facing straight up or down, width
/// is +X. (ir.Light has no roll; this is the convention.)
pub fn rect_axes(n: V3) -> (V3, V3) {
    let u = if n[1].abs() > 0.999 { [1.0, 0.0, 0.0] } else { normalize(cross([0.0, 1.0, 0.0], n)) };
    (u, normalize(cross(n, u)))
}

impl Light {
    /// Parse a JSON list of `ir.Light` dicts (dataclasses.asdict form).
    pub fn from_ir_json(text: &str) -> Result<Vec<Light>, String> {
        let list: Vec<IrLight> = serde_json::from_str(text).map_err(|e| format!("lights JSON: {e}"))?;
        list.into_iter()
            .enumerate()
            .map(|(k, l)| {
                let what = format!("light {k} '{}'", l.name);
                let c = scale(l.color, l.intensity);
                let dn = length(l.direction);
                if !(dn > 0.0) || c.iter().any(|x| !x.is_finite()) {
                    return Err(format!("{what}: direction must be non-zero and colour*intensity finite"));
                }
                let dir = scale(l.direction, 1.0 / dn);
                let range = l.range.filter(|r| *r > 0.0);
                Ok(match l.kind.as_str() {
                    "sun" => Light::Sun { dir, e: c, cos_max: l.angular_radius.clamp(0.0, 1.5).cos() },
                    "point" => Light::Point { pos: l.position, i: c, range },
                    "spot" => Light::Spot {
                        pos: l.position,
                        dir,
                        i: c,
                        cos_inner: l.inner_cone.cos(),
                        cos_outer: l.outer_cone.cos(),
                        range,
                    },
                    "rect" => {
                        let (u, v) = rect_axes(dir);
                        Light::Rect { c: l.position, n: dir, hu: scale(u, 0.5 * l.size[0]), hv: scale(v, 0.5 * l.size[1]), l: c }
                    }
                    k => return Err(format!("{what}: unknown kind '{k}' (sun, point, spot, rect)")),
                })
            })
            .collect()
    }

    /// Next-event sample from a surface point `x` with unit normal `n`; None when it cannot
    /// contribute (behind the surface, outside the cone or range).
    pub fn sample(&self, x: V3, n: V3, u1: f32, u2: f32) -> Option<LightSample> {
        match *self {
            Light::Sun { dir, e, cos_max } => {
                let w = to_world(uniform_cone(u1, u2, cos_max), scale(dir, -1.0));
                let cos = dot(n, w);
                (cos > 0.0).then(|| LightSample { dir: w, dist: f32::INFINITY, h: scale(e, cos), pdf: None })
            }
            Light::Point { pos, i, range } => point(x, n, pos, i, range, |_| 1.0),
            // w points from the light to x.
            Light::Spot { pos, dir, i, cos_inner, cos_outer, range } => point(x, n, pos, i, range, |w| spot_falloff(dot(w, dir), cos_inner, cos_outer)),
            Light::Rect { c, n: ln, hu, hv, l } => {
                let p = add(c, add(scale(hu, 2.0 * u1 - 1.0), scale(hv, 2.0 * u2 - 1.0)));
                let d = sub(p, x);
                let r2 = dot(d, d);
                let r = r2.sqrt();
                let w = scale(d, 1.0 / r);
                let (cos_i, cos_l) = (dot(n, w), -dot(ln, w));
                if !(cos_i > 0.0 && cos_l > 0.0) {
                    return None;
                }
                let area = 4.0 * length(cross(hu, hv));
                // Area pdf 1/A moved to solid angle (notes §7.2, eq. 23.7).
                let pdf = r2 / (area * cos_l);
                Some(LightSample { dir: w, dist: r, h: scale(l, cos_i / pdf), pdf: Some(pdf) })
            }
        }
    }

    /// A rect light crossed by the ray `o + t w` (unit w) from its emitting side: (t, its
    /// luminance, solid-angle pdf of light sampling that direction).
    pub fn hit_rect(&self, o: V3, w: V3) -> Option<(f32, V3, f32)> {
        let Light::Rect { c, n, hu, hv, l } = *self else { return None };
        let dn = dot(w, n);
        if !(dn < 0.0) {
            return None;
        }
        let t = dot(sub(c, o), n) / dn;
        if !(t > 0.0) {
            return None;
        }
        let q = sub(add(o, scale(w, t)), c);
        let (a, b) = (dot(q, hu) / dot(hu, hu), dot(q, hv) / dot(hv, hv));
        if a.abs() > 1.0 || b.abs() > 1.0 {
            return None;
        }
        let area = 4.0 * length(cross(hu, hv));
        Some((t, l, t * t / (area * -dn)))
    }
}

/// KHR_lights_punctual's spot attenuation at cosine `c` from the axis:
/// clamp((c - cos outer) / (cos inner - cos outer), 0, 1)^2; a hard edge at the outer cone when
/// the inner is not inside it.
pub fn spot_falloff(c: f32, cos_inner: f32, cos_outer: f32) -> f32 {
    if cos_inner <= cos_outer {
        return if c >= cos_outer { 1.0 } else { 0.0 };
    }
    let s = ((c - cos_outer) / (cos_inner - cos_outer)).clamp(0.0, 1.0);
    s * s
}

fn point(x: V3, n: V3, pos: V3, i: V3, range: Option<f32>, falloff: impl Fn(V3) -> f32) -> Option<LightSample> {
    let d = sub(pos, x);
    let r2 = dot(d, d);
    let r = r2.sqrt();
    let w = scale(d, 1.0 / r);
    let cos = dot(n, w);
    // glTF's recommended window: (clamp(1 - (r/range)^4, 0, 1))^2, so lights end smoothly.
    let window = range.map_or(1.0, |rg| (1.0 - (r / rg).powi(4)).clamp(0.0, 1.0).powi(2));
    let f = falloff(scale(w, -1.0)) * window * cos / r2;
    (cos > 0.0 && f > 0.0 && r > 0.0).then(|| LightSample { dir: w, dist: r, h: scale(i, f), pdf: None })
}
