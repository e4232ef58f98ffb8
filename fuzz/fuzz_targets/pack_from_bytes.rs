//! `Pack::from_bytes` on arbitrary bytes: any input gives a pack or an error, never a panic or an
//! allocation sized by a length field rather than by the input.
#![no_main]

use libfuzzer_sys::fuzz_target;

mod common;

fuzz_target!(|data: &[u8]| {
    if let Ok(pack) = pack::Pack::from_bytes(data) {
        common::exercise(&pack);
    }
});
