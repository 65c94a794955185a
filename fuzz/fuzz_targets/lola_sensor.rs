//! Any bytes: the LoLA sensor-packet decoder returns an error or a packet, never panics (nor
//! allocates what a hostile length field asks for), and a packet it accepts encodes.
//!
//! The decoder accepts any msgpack number encoding, extra keys and any key order, so the input
//! bytes are not what the packet encodes back to; the encoder's output (float32 values, keys in
//! LoLA's order) is canonical and must come back unchanged. The check compares bytes, not
//! packets: a NaN in the input is a legal float and would make `PartialEq` fail.
#![no_main]

use libfuzzer_sys::fuzz_target;
use strata_nao::SensorPacket;

fuzz_target!(|bytes: &[u8]| {
    let Ok(packet) = SensorPacket::decode(bytes) else { return };
    let canonical = packet.encode().expect("a decoded packet encodes");
    let again = SensorPacket::decode(&canonical).expect("an encoded packet decodes");
    assert_eq!(again.encode().expect("encodes"), canonical);
});
