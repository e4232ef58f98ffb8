//! KHR_lights_punctual -> pack lights in world space, in the units the extension already uses:
//! directional lights (suns) in lux, point and spot lights in candela.

use crate::label;
use crate::scene::Flat;
use crate::transform;
use gltf::json::extensions::scene::khr_lights_punctual::{Light, Type};
use gltf::json::validation::Checked;
use pack::LightKind;

/// glTF's directional light is a parallel light with no disk; the sun's angular radius (as a
/// level's default sun) gives its baked shadows the sun's penumbra.
const SUN_ANGULAR_RADIUS: f32 = 0.00465;

/// One pack light per scene node that has a light, in flattened node order: at the node's world
/// position, shining along its world -Z. Lights are baked, so a light on an animated node is
/// imported where the node is at rest, with a warning.
pub(crate) fn cook_lights(doc: &gltf::Document, flat: &Flat, warnings: &mut Vec<String>) -> Result<Vec<pack::Light>, String> {
    let json = doc.as_json();
    let lights: &[Light] = json.extensions.as_ref().and_then(|e| e.khr_lights_punctual.as_ref()).map_or(&[], |k| &k.lights);
    let mut out = Vec::new();
    for (f, &n) in flat.gltf.iter().enumerate() {
        let node_json = &json.nodes[n];
        let Some(index) = node_json.extensions.as_ref().and_then(|e| e.khr_lights_punctual.as_ref()).map(|k| k.light.value()) else { continue };
        let node = label("node", n, node_json.name.as_deref());
        // The crate's validation has checked the index; an error rather than a panic all the same.
        let light = lights.get(index).ok_or_else(|| format!("{node}: light {index} does not exist"))?;
        let what = format!("{} on {node}", label("light", index, light.name.as_deref()));
        let world = &flat.world[f];
        let position = transform::translation(world).map(|x| x as f32);
        let direction = transform::normalize(transform::direction(world, [0.0, 0.0, -1.0])).map(|d| d.map(|x| x as f32));
        let kind = match light.type_ {
            Checked::Valid(Type::Directional) => LightKind::Sun,
            Checked::Valid(Type::Point) => LightKind::Point,
            Checked::Valid(Type::Spot) => LightKind::Spot,
            Checked::Invalid => return Err(format!("{what}: its type is not directional, point or spot")),
        };
        let (inner_cone, outer_cone) = match (&kind, &light.spot) {
            (LightKind::Spot, Some(s)) => (s.inner_cone_angle, s.outer_cone_angle),
            // The extension's defaults.
            (LightKind::Spot, None) => (0.0, std::f32::consts::FRAC_PI_4),
            _ => (0.0, 0.0),
        };
        check(light, &kind, inner_cone, outer_cone).map_err(|e| format!("{what}: {e}"))?;
        if !position.iter().all(|x| x.is_finite()) {
            return Err(format!("{what}: the node's world position is not finite"));
        }
        let direction = match (direction, &kind) {
            (Some(d), _) if d.iter().all(|x| x.is_finite()) => d,
            (_, LightKind::Point) => [0.0, 0.0, -1.0], // a point light shines every way
            _ => return Err(format!("{what}: the node's transform scales its -Z axis to nothing, so the light has no direction")),
        };
        if flat.animated[f] {
            warnings.push(format!("{what}: the node is animated, but lights are baked; imported where the node is at rest"));
        }
        out.push(pack::Light {
            name: light.name.clone().unwrap_or_else(|| flat.nodes[f].name.clone()),
            kind,
            color: light.color,
            intensity: light.intensity,
            position,
            direction,
            // Range means nothing for a sun (the extension says so too).
            range: light.range.filter(|_| kind != LightKind::Sun),
            inner_cone,
            outer_cone,
            size: [0.0; 2],
            angular_radius: if kind == LightKind::Sun { SUN_ANGULAR_RADIUS } else { 0.0 },
        });
    }
    Ok(out)
}

/// The extension's constraints on a light's numbers. Inner and outer cone may be equal (a hard
/// edge; Blender exports a spot without blend so), though the extension asks for inner < outer.
fn check(light: &Light, kind: &LightKind, inner: f32, outer: f32) -> Result<(), String> {
    if !light.color.iter().all(|c| c.is_finite() && *c >= 0.0) {
        return Err(format!("colour {:?} is not finite and non-negative", light.color));
    }
    if !(light.intensity.is_finite() && light.intensity >= 0.0) {
        return Err(format!("intensity {} is not finite and non-negative", light.intensity));
    }
    if let (Some(r), false) = (light.range, *kind == LightKind::Sun) {
        if !(r.is_finite() && r > 0.0) {
            return Err(format!("range {r} is not a positive distance"));
        }
    }
    if *kind == LightKind::Spot && !(inner >= 0.0 && inner <= outer && outer > 0.0 && outer <= std::f32::consts::FRAC_PI_2) {
        return Err(format!("spot cone angles {inner} (inner) and {outer} (outer) are not 0 <= inner <= outer <= pi/2 with outer > 0"));
    }
    Ok(())
}
