//! Inputs the fuzz targets (fuzz/, `make fuzz`) found to crash glTF import, minimised by hand and
//! kept under tests/fuzz/: each must now be refused with an error naming the problem.

use cook_core::ImportOptions;
use std::path::{Path, PathBuf};

fn input(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz").join(name)
}

/// Import the file from memory (as the fuzz target does) and from disk; both must fail the same way.
fn import_err(name: &str) -> String {
    import_err_with(name, &ImportOptions::default())
}

fn import_err_with(name: &str, options: &ImportOptions) -> String {
    let path = input(name);
    let bytes = std::fs::read(&path).unwrap();
    let from_bytes = cook_core::import_gltf_bytes(&path, &bytes, options, &mut |_, _| {}).expect_err("the input is refused");
    let from_file = cook_core::import_gltf(&path, options, &mut |_, _| {}).expect_err("the input is refused");
    assert_eq!(from_bytes, from_file);
    let message = from_file.to_string();
    assert!(!message.contains('\n'), "{message}");
    message
}

#[test]
fn fuzz_animation_channel_target_node_out_of_range() {
    // gltf 1.4 unwrapped the missing node in `Target::node` (gltf-json does not validate channel targets).
    let e = import_err("channel_target_node_out_of_range.gltf");
    assert!(e.ends_with("invalid glTF: animations[0].channels[0].target.node: Index out of bounds"), "{e}");
}

#[test]
fn fuzz_animation_channel_target_path_invalid() {
    // gltf 1.4 unwrapped the unknown path in `Target::property`.
    let e = import_err("channel_target_path_invalid.gltf");
    assert!(e.ends_with("invalid glTF: animations[0].channels[0].target.path: Invalid value"), "{e}");
}

#[test]
fn buffer_uri_naming_a_device_is_refused_not_read_forever() {
    // Found by review beside the fuzz target (which resolves URIs against a missing directory):
    // an absolute URI such as /dev/zero was read until memory ran out.
    // Now an absolute path out of the asset's folder is refused before anything is read; where
    // external URIs are allowed, a device is still refused as not a regular file.
    let e = import_err("buffer_uri_is_a_device.gltf");
    assert!(e.contains("invalid glTF: buffer 0: URI '/dev/zero' reaches outside the asset's folder"), "{e}");
    let e = import_err_with("buffer_uri_is_a_device.gltf", &ImportOptions { allow_external_uris: true, ..Default::default() });
    assert!(e.ends_with("buffer 0: cannot read '/dev/zero': not a regular file"), "{e}");
}
