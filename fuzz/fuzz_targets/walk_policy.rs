//! Any bytes: the T1 walking network's weight loader (`WalkNetwork::load`, for a network a user
//! trained; crates/rcssmj/src/policy/network.rs) returns an error or a network, never panics
//! (nor allocates without bound), and a network it accepts gives an action for any observation.
#![no_main]

use libfuzzer_sys::fuzz_target;
use strata_rcssmj::policy::{ACTION_LEN, OBSERVATION_LEN, WalkNetwork};

fuzz_target!(|bytes: &[u8]| {
    let Ok(network) = WalkNetwork::from_safetensors(bytes, "fuzz input") else { return };
    for observation in [[0.0f32; OBSERVATION_LEN], [1e30; OBSERVATION_LEN], [f32::NAN; OBSERVATION_LEN]]
    {
        assert_eq!(network.forward(&observation).len(), ACTION_LEN);
    }
});
