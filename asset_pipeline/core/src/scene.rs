//! The default scene's node tree, flattened so that every parent precedes its children.

use crate::label;
use pack::Node;

/// Also returns, per glTF node index, its index in the flattened list (`None`: not in the scene).
pub(crate) fn flatten(doc: &gltf::Document) -> Result<(Vec<Node>, Vec<Option<u32>>), String> {
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
    let mut seen = vec![false; doc.nodes().len()];
    let mut out = Vec::new();
    let mut map = vec![None; doc.nodes().len()];
    // Depth-first with an explicit stack: a deep or cyclic file cannot overflow ours.
    let mut stack: Vec<(gltf::Node, Option<u32>)> = roots.into_iter().rev().map(|n| (n, None)).collect();
    while let Some((node, parent)) = stack.pop() {
        if std::mem::replace(&mut seen[node.index()], true) {
            return Err(format!(
                "{} is reached twice in the scene (a cycle, or a node with two parents)",
                label("node", node.index(), node.name())
            ));
        }
        let me = out.len() as u32;
        map[node.index()] = Some(me);
        let m = node.transform().matrix(); // columns, as glTF and the pack
        out.push(Node {
            name: node.name().map_or_else(|| format!("node{}", node.index()), str::to_string),
            parent,
            local: std::array::from_fn(|i| m[i / 4][i % 4]),
            mesh: node.mesh().map(|m| m.index() as u32),
        });
        stack.extend(node.children().collect::<Vec<_>>().into_iter().rev().map(|c| (c, Some(me))));
    }
    Ok((out, map))
}
