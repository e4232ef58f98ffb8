//! `Pack::from_bytes` past the checksum: the input's header gets the right file length and CRC
//! before it is read, so mutations reach the metadata JSON and `Manifest::validate` instead of
//! stopping at the checksum (which random damage almost never gets past).
#![no_main]

use libfuzzer_sys::fuzz_target;

mod common;

fuzz_target!(|data: &[u8]| {
    let mut bytes = data.to_vec();
    if bytes.len() >= pack::HEADER_LEN {
        let len = bytes.len() as u64;
        bytes[16..24].copy_from_slice(&len.to_le_bytes());
        bytes[56..60].fill(0);
        let crc = crc32fast::hash(&bytes);
        bytes[56..60].copy_from_slice(&crc.to_le_bytes());
    }
    if let Ok(pack) = pack::Pack::from_bytes(&bytes) {
        common::exercise(&pack);
    }
});
