//! Any bytes as the CDR payload of a logged message (crates/runtime/src/cdr): reading it
//! against the formats of the representations Strata logs in CDR returns JSON or an error,
//! never panics, and never allocates for lengths the bytes cannot hold.
#![no_main]

use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use strata_robot::command::MotionCommands;
use strata_robot::geometry::Odometry;
use strata_robot::percept::Percepts;
use strata_robot::platform::MotionFeedback;
use strata_robot::world::WorldState;
use strata_runtime::cdr::{Format, format_of, to_json};

fn formats() -> &'static [Format] {
    static FORMATS: OnceLock<Vec<Format>> = OnceLock::new();
    FORMATS.get_or_init(|| {
        [
            format_of::<Odometry>(),
            format_of::<MotionFeedback>(),
            format_of::<MotionCommands>(),
            format_of::<Percepts>(),
            format_of::<WorldState>(),
        ]
        .into_iter()
        .filter_map(Result::ok)
        .collect()
    })
}

fuzz_target!(|bytes: &[u8]| {
    for format in formats() {
        let _ = to_json(format, bytes);
    }
    let _ = strata_runtime::cdr::decode::<WorldState>(bytes);
});
