//! Any bytes: the return-packet decoder returns an error or a packet, never panics, and a
//! packet it accepts encodes back to exactly its first 32 bytes (the rest of a longer datagram
//! is ignored, as GameController3 ignores it).
#![no_main]

use libfuzzer_sys::fuzz_target;
use strata_spl::gamecontroller::{RETURN_PACKET_SIZE, ReturnData};

fuzz_target!(|bytes: &[u8]| {
    if let Ok(data) = ReturnData::decode(bytes) {
        let encoded = data.encode();
        assert_eq!(encoded.as_ref().map(|b| b.as_slice()), Ok(&bytes[..RETURN_PACKET_SIZE]));
    }
});
