//! Any bytes: the control-packet decoder returns an error or a packet, never panics, and a
//! packet it accepts encodes back to exactly the same bytes.
#![no_main]

use libfuzzer_sys::fuzz_target;
use strata_spl::gamecontroller::GameControlData;

fuzz_target!(|bytes: &[u8]| {
    if let Ok(data) = GameControlData::decode(bytes) {
        assert_eq!(data.encode().as_slice(), bytes);
    }
});
