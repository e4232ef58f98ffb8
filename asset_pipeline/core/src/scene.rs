//! The default scene's node tree, flattened so that every parent precedes its children, with
//! what the later steps need to know about each node: where it is at rest and whether it moves.

use crate::label;
use crate::transform::{self, Mat4};
use pack::Node;

/// The flattened tree. Per-node vectors are index-aligned with `nodes`.
pub(crate) struct Flat {
    pub nodes: Vec<Node>,
    /// Per glTF node index, its index in `nodes` (`None`: not in the scene).
    pub map: Vec<Option<u32>>,
    /// The glTF node each flattened node came from.
    pub gltf: Vec<usize>,
    /// World transform at rest (the node's own transform, not any animation's).
    pub world: Vec<Mat4>,
    /// The node or one of its ancestors is the target of an animation channel.
    pub animated: Vec<bool>,
}

pub(crate) fn flatten(doc: &gltf::Document) -> Result<Flat, String> {
    // No default scene: the first scene; no scenes at all: every node that is nobody's child.
    let roots: Vec<gltf::Node> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(scene) => scene.nodes().collect(),
        None => {
            let mut is_child = vec![false; doc.nodes().len()];
            for c in doc.nodes().flat_map(|n| n.children()) {
                is_child[c.index()] = true;
            }
            doc.nodes().filter(|n| !is_child[n.index()]).collect()
        }
    };
    let mut targeted = vec![false; doc.nodes().len()];
    for ch in doc.animations().flat_map(|a| a.channels()) {
        targeted[ch.target().node().index()] = true;
    }
    let mut seen = vec![false; doc.nodes().len()];
    let mut flat = Flat { nodes: Vec::new(), map: vec![None; doc.nodes().len()], gltf: Vec::new(), world: Vec::new(), animated: Vec::new() };
    // Depth-first with an explicit stack: a deep or cyclic file cannot overflow ours.
    let mut stack: Vec<(gltf::Node, Option<u32>)> = roots.into_iter().rev().map(|n| (n, None)).collect();
    while let Some((node, parent)) = stack.pop() {
        let what = label("node", node.index(), node.name());
        if std::mem::replace(&mut seen[node.index()], true) {
            return Err(format!("{what} is reached twice in the scene (a cycle, or a node with two parents)"));
        }
        let me = flat.nodes.len() as u32;
        flat.map[node.index()] = Some(me);
        let m = node.transform().matrix(); // columns, as glTF and the pack
        if !m.iter().flatten().all(|x| x.is_finite()) {
            return Err(format!("{what}: its transform has a number that is not finite"));
        }
        let (parent_world, parent_animated) = parent.map_or((transform::IDENTITY, false), |p| (flat.world[p as usize], flat.animated[p as usize]));
        let animated = parent_animated || targeted[node.index()];
        let mesh = node.mesh();
        let is_static = match &mesh {
            None => false,
            Some(mesh) => {
                let morphed = mesh.primitives().any(|p| p.morph_targets().len() > 0);
                // `"static": true` in extras cannot make a skinned, morphed or animated node
                // static: it moves at run time whatever the author says, and a baked lightmap
                // and cached shadow of it would be wrong as soon as it did.
                let authored = authored_static(&node).map_err(|e| format!("{what}: {e}"))?;
                node.skin().is_none() && !morphed && !animated && authored != Some(false)
            }
        };
        flat.nodes.push(Node {
            name: node.name().map_or_else(|| format!("node{}", node.index()), str::to_string),
            parent,
            local: std::array::from_fn(|i| m[i / 4][i % 4]),
            mesh: mesh.map(|m| m.index() as u32),
            is_static,
            ..Default::default()
        });
        flat.gltf.push(node.index());
        flat.world.push(transform::mul(&parent_world, &transform::from_f32(m)));
        flat.animated.push(animated);
        stack.extend(node.children().collect::<Vec<_>>().into_iter().rev().map(|c| (c, Some(me))));
    }
    Ok(flat)
}

/// The node's `extras.static`, when it has one: how an author marks a mesh node that would be
/// static as dynamic (a door a script will move). Extras that are not an object, or an object
/// without `static`, say nothing.
fn authored_static(node: &gltf::Node) -> Result<Option<bool>, String> {
    let Some(raw) = node.extras() else { return Ok(None) };
    let extras: serde_json::Value = serde_json::from_str(raw.get()).map_err(|e| format!("extras: {e}"))?;
    match extras.get("static") {
        None => Ok(None),
        Some(serde_json::Value::Bool(b)) => Ok(Some(*b)),
        Some(v) => Err(format!("extras \"static\" is {v}, expected true or false")),
    }
}
