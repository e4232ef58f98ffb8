//! Checks shared by the targets: what a pack that `Pack::from_bytes` accepted must allow.

use pack::{BufferRange, Pack};

/// Every range the manifest names can be sliced (validation promised it), and the pack
/// re-encodes to bytes that decode to the same pack.
pub fn exercise(pack: &Pack) {
    let m = &pack.manifest;
    let mut ranges: Vec<BufferRange> = Vec::new();
    for mesh in &m.meshes {
        for lod in &mesh.lods {
            ranges.extend([lod.vertices, lod.indices]);
            // Either index width reads back whole and in range.
            let indices = pack.indices(lod);
            assert_eq!(indices.len(), lod.index_count as usize);
            assert!(indices.iter().all(|&i| i < lod.vertex_count));
        }
    }
    for t in &m.textures {
        ranges.extend(&t.mips);
    }
    if let Some(p) = &m.probes {
        ranges.extend([p.sh, p.sun_visibility]);
    }
    for s in &m.animation.skins {
        ranges.push(s.inverse_bind);
    }
    for c in &m.animation.clips {
        for ch in &c.channels {
            ranges.extend([ch.times, ch.values]);
        }
    }
    for d in &m.animation.meshes {
        for l in &d.lods {
            if let Some(s) = l.skin {
                ranges.extend([s.joints, s.weights]);
            }
            if let Some(mt) = l.morph {
                ranges.push(mt.positions);
                ranges.extend(mt.normals);
            }
        }
    }
    for r in ranges {
        let _ = pack.bytes(r);
    }
    let bytes = pack.to_bytes().expect("a pack that was read must write");
    let again = Pack::from_bytes(&bytes).expect("a pack that was written must read");
    assert!(again.data == pack.data, "data blob changed in a round trip");
    assert!(format!("{:?}", again.manifest) == format!("{:?}", pack.manifest), "manifest changed in a round trip");
}
