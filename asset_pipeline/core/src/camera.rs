//! The scene's first camera -> a `camera` spawn: where the game's view starts.

use crate::label;
use crate::scene::Flat;
use crate::transform;
use gltf::json::camera::Type;
use gltf::json::validation::Checked;
use serde_json::json;

/// The camera of the first node (in flattened order) that has one, as a spawn at the node's world
/// position and rotation (scale removed) with its projection in `params`: `yfov` (radians) and
/// `znear` (metres) for a perspective camera, `xmag`, `ymag` and `znear` for an orthographic one,
/// which also gets a warning (the runtime shows every camera in perspective). Later cameras are
/// not imported: a spawn is one starting view.
pub(crate) fn first_camera(doc: &gltf::Document, flat: &Flat, warnings: &mut Vec<String>) -> Result<Option<pack::Spawn>, String> {
    let json = doc.as_json();
    let Some((f, n, index)) = flat.gltf.iter().enumerate().find_map(|(f, &n)| json.nodes[n].camera.map(|c| (f, n, c.value()))) else {
        return Ok(None);
    };
    let node = label("node", n, json.nodes[n].name.as_deref());
    // The crate's validation has checked the index; an error rather than a panic all the same.
    let camera = json.cameras.get(index).ok_or_else(|| format!("{node}: camera {index} does not exist"))?;
    let what = format!("{} on {node}", label("camera", index, camera.name.as_deref()));
    let positive = |name: &str, x: f32| match x.is_finite() && x > 0.0 {
        true => Ok(f64::from(x)),
        false => Err(format!("{what}: {name} {x} is not a positive number")),
    };
    // Read the type and its values together: the crate's `projection()` unwraps the values of
    // the declared type, which its validation does not check are there.
    let params = match (&camera.type_, &camera.perspective, &camera.orthographic) {
        (Checked::Valid(Type::Perspective), Some(p), _) => json!({"yfov": positive("yfov", p.yfov)?, "znear": positive("znear", p.znear)?}),
        (Checked::Valid(Type::Orthographic), _, Some(o)) => {
            // glTF allows a zero near plane for orthographic cameras (not a negative one), and
            // any magnification but zero.
            if !(o.znear.is_finite() && o.znear >= 0.0) {
                return Err(format!("{what}: znear {} is not a distance", o.znear));
            }
            if let Some((name, x)) = [("xmag", o.xmag), ("ymag", o.ymag)].into_iter().find(|(_, x)| !x.is_finite() || *x == 0.0) {
                return Err(format!("{what}: {name} {x} is not a non-zero number"));
            }
            warnings.push(format!("{what}: orthographic; the runtime shows it in perspective"));
            json!({"xmag": f64::from(o.xmag), "ymag": f64::from(o.ymag), "znear": f64::from(o.znear)})
        }
        (Checked::Valid(Type::Perspective), None, _) => return Err(format!("{what}: its type is perspective but it has no perspective values")),
        (Checked::Valid(Type::Orthographic), _, None) => return Err(format!("{what}: its type is orthographic but it has no orthographic values")),
        (Checked::Invalid, _, _) => return Err(format!("{what}: its type is not perspective or orthographic")),
    };
    let world = &flat.world[f];
    let position = transform::translation(world).map(|x| x as f32);
    let rotation = transform::rotation(world).map(|q| q.map(|x| x as f32));
    let Some(rotation) = rotation.filter(|_| position.iter().all(|x| x.is_finite())) else {
        return Err(format!("{what}: the node's world transform is degenerate (not finite, or scaled to nothing)"));
    };
    Ok(Some(pack::Spawn {
        name: camera.name.clone().unwrap_or_else(|| flat.nodes[f].name.clone()),
        kind: "camera".into(),
        position,
        rotation,
        params,
    }))
}
