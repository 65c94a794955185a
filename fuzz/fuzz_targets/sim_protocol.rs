//! Any bytes: the simulator server's and client's decoders (crates/sim/src/net/protocol.rs)
//! return an error or a message, never panic; an accepted message re-encodes to a frame that
//! decodes to the same message.
//!
//! The same bytes also go through the frame reader as a stream of length-prefixed frames (with
//! the server's handshake limit), as they would arrive from a socket.
#![no_main]

use libfuzzer_sys::fuzz_target;
use strata_sim::net::protocol::{decode, encode, read_frame};
use strata_sim::net::{ClientMessage, ServerMessage};

fn round_trip<T>(bytes: &[u8])
where
    T: serde::Serialize + serde::de::DeserializeOwned + PartialEq + std::fmt::Debug,
{
    let Ok(message) = decode::<T>(bytes) else { return };
    let frame = encode(&message);
    let again: T = decode(&frame[4..]).expect("a re-encoded message decodes");
    assert_eq!(again, message);
}

fuzz_target!(|bytes: &[u8]| {
    round_trip::<ClientMessage>(bytes);
    round_trip::<ServerMessage>(bytes);
    let mut reader = bytes;
    while let Ok(payload) = read_frame(&mut reader, 64 * 1024) {
        let _ = decode::<ClientMessage>(&payload);
    }
});
