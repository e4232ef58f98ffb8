//! `Pack::from_bytes` on arbitrary bytes: any input gives a pack or an error, never a panic or an
//! allocation sized by a length field rather than by the input.
#![no_main]

use libfuzzer_sys::fuzz_target;

mod common;

fuzz_target!(|data: &[u8]| {
    let read = pack::Pack::from_bytes(data);
    // A file read whole (`read_file`) keeps its data in place: the same pack or the same error.
    assert_eq!(pack::Pack::from_vec(data.to_vec()), read);
    if let Ok(pack) = read {
        common::exercise(&pack);
    }
});
