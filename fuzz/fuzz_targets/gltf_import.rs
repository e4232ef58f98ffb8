//! glTF import from arbitrary bytes (.gltf JSON with data: URIs, or .glb): any input gives a scene
//! or an error, never a panic; a scene that imports builds a pack the runtime can read.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

mod common;

fuzz_target!(|data: &[u8]| {
    // Relative URIs resolve against a directory that does not exist, and the default options
    // refuse any URI out of it: the target reads no files.
    let source = Path::new("/nonexistent-fuzz-input/input.gltf");
    let options = cook_core::ImportOptions::default();
    let Ok(imported) = cook_core::import_gltf_bytes(source, data, &options, &mut |_, _| {}) else { return };
    if let Ok(pack) = cook_core::build_pack(&imported.scene) {
        common::exercise(&pack);
    }
});
