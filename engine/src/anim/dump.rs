//! `demo --dump-pose PACK --clip NAME --time T`: the evaluated pose of every node of a cooked
//! pack as JSON on stdout, so a rig can be checked against an independent implementation.
//!
//! MODEL is a cooked pack path (one model per glTF file, so the pack is the model). The clip is
//! sampled at T seconds, clamped to the clip (no looping). Output:
//! `{"clip", "time", "duration", "nodes": [{"name", "world": [16 floats, column-major]}],
//!   "skins": [{"name", "joints": [node index], "joint_matrices": [[16]]}],
//!   "meshes": [{"node", "mesh", "morph_weights": [..], "positions": [[x,y,z]], "normals": [[x,y,z]]}]}`
//! Mesh positions and normals are LOD 0 after morphing and skinning, in world space.

use super::skin_cpu::{skin_cpu, DeformData};
use super::{joint_count, node_joint_matrices, Rig};
use glam::Mat4;
use pack::Pack;
use std::fmt::Write;
use std::path::Path;
use std::process::ExitCode;

fn num(out: &mut String, x: f32) {
    if x.is_finite() {
        let _ = write!(out, "{x}");
    } else {
        out.push_str("null");
    }
}

fn list(out: &mut String, xs: impl IntoIterator<Item = f32>) {
    out.push('[');
    for (i, x) in xs.into_iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        num(out, x);
    }
    out.push(']');
}

fn string(out: &mut String, s: &str) {
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if (c as u32) < 0x20 => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
}

/// The JSON document for clip `clip` at `time` seconds. Errors name the clip and list the
/// clips the pack has.
pub fn dump_pose(pack: &Pack, clip: &str, time: f32) -> Result<String, String> {
    let rig = Rig::from_pack(pack);
    let Some(c) = rig.clip_index(clip) else {
        let names: Vec<&str> = rig.clips.iter().map(|c| c.name.as_str()).collect();
        return Err(format!("no clip named '{clip}' (clips: {})", if names.is_empty() { "none".to_string() } else { names.join(", ") }));
    };
    let mut pose = rig.new_pose();
    rig.sample(c, time, false, &mut pose);
    rig.update_globals(&mut pose);
    let mut out = String::new();
    out.push_str("{\"clip\":");
    string(&mut out, clip);
    out.push_str(",\"time\":");
    num(&mut out, time);
    out.push_str(",\"duration\":");
    num(&mut out, rig.clips[c].duration);
    out.push_str(",\"nodes\":[");
    for (i, g) in pose.global.iter().enumerate() {
        out.push_str(if i > 0 { ",{\"name\":" } else { "{\"name\":" });
        string(&mut out, &rig.names[i]);
        out.push_str(",\"world\":");
        list(&mut out, g.to_cols_array());
        out.push('}');
    }
    out.push_str("],\"skins\":[");
    for (s, skin) in rig.skins.iter().enumerate() {
        let mut m = vec![Mat4::IDENTITY; skin.joints.len()];
        rig.joint_matrices(s, &pose, &mut m);
        out.push_str(if s > 0 { ",{\"name\":" } else { "{\"name\":" });
        string(&mut out, &skin.name);
        out.push_str(",\"joints\":");
        list(&mut out, skin.joints.iter().map(|&j| j as f32));
        out.push_str(",\"joint_matrices\":[");
        for (k, j) in m.iter().enumerate() {
            if k > 0 {
                out.push(',');
            }
            list(&mut out, j.to_cols_array());
        }
        out.push_str("]}");
    }
    out.push_str("],\"meshes\":[");
    let mut first = true;
    for (i, node) in pack.manifest.nodes.iter().enumerate() {
        let (Some(mesh), Some(data)) = (node.mesh, DeformData::for_node(pack, i, 0)) else { continue };
        let mut joints = vec![Mat4::IDENTITY; joint_count(pack, i)];
        node_joint_matrices(pack, &rig, i, &pose, &mut joints);
        let weights = rig.node_weights(i, &pose);
        let mut skinned = data.vertices.clone();
        skin_cpu(&data, weights, &joints, &mut skinned);
        let _ = write!(out, "{}{{\"node\":{i},\"mesh\":{mesh},\"morph_weights\":", if first { "" } else { "," });
        first = false;
        list(&mut out, weights.iter().copied());
        for (key, pick) in [("positions", 0usize), ("normals", 1)] {
            let _ = write!(out, ",\"{key}\":[");
            for (k, v) in skinned.iter().enumerate() {
                if k > 0 {
                    out.push(',');
                }
                list(&mut out, if pick == 0 { v.position } else { v.normal });
            }
            out.push(']');
        }
        out.push('}');
    }
    out.push_str("]}");
    Ok(out)
}

/// The `--dump-pose` command: prints the JSON, or one error line; 0 ok, 2 bad pack or clip.
pub fn run(model: &Path, clip: &str, time: f32) -> ExitCode {
    let pack = match Pack::read_file(model) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("demo: error: {}: {e}", model.display());
            return ExitCode::from(2);
        }
    };
    match dump_pose(&pack, clip, time) {
        Ok(json) => {
            println!("{json}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("demo: error: {}: {e}", model.display());
            ExitCode::from(2)
        }
    }
}
