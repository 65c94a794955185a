//! Any bytes: the rcssservermj perception decoder and the monitor-stream decoder return an
//! error or a value, never panic, and a hostile nesting does not overflow the stack.
//!
//! The same bytes also go through the frame reader (as a stream of length-prefixed frames with
//! the agent port's maximum), as they would arrive from a socket.
#![no_main]

use std::io::Cursor;

use libfuzzer_sys::fuzz_target;
use strata_rcssmj::protocol::monitor::MonitorDecoder;
use strata_rcssmj::protocol::{MAX_PERCEPTION_FRAME, decode_perception, read_frame};

fuzz_target!(|bytes: &[u8]| {
    if let Ok(perception) = decode_perception(bytes) {
        // Decoded values are finite: the decoder refuses NaN and infinities.
        assert!(perception.time.is_none_or(f64::is_finite));
        assert!(perception.joints.iter().all(|j| j.angle.is_finite() && j.velocity.is_finite()));
    }
    let _ = MonitorDecoder::new().decode(bytes);
    let mut reader = Cursor::new(bytes);
    let mut buffer = Vec::new();
    while let Ok(payload) = read_frame(&mut reader, &mut buffer, MAX_PERCEPTION_FRAME) {
        let _ = decode_perception(payload);
    }
});
