//! Any bytes: the learned gaze's weight loader (crates/soccer/src/gaze_policy.rs) returns an
//! error or a policy, never panics (nor allocates without bound), and a policy it accepts gives
//! one logit per gaze choice and an action among them for any observation.
#![no_main]

use libfuzzer_sys::fuzz_target;
use strata_soccer::gaze_override::GazeChoice;
use strata_soccer::gaze_policy::GazePolicy;

/// The gaze environment's observation length (`strata_experiments::goal_covering::gym::OBS_LEN`,
/// a crate this workspace does not build): the shipped policy's seed loads with it.
const OBS_LEN: usize = 54;

fuzz_target!(|bytes: &[u8]| {
    let Ok(policy) = GazePolicy::from_safetensors(bytes, "fuzz input", OBS_LEN) else { return };
    assert_eq!(policy.inputs(), OBS_LEN);
    for observation in [[0.0f32; OBS_LEN], [100.0; OBS_LEN], [f32::NAN; OBS_LEN]] {
        assert_eq!(policy.logits(&observation).len(), GazeChoice::COUNT);
        assert!(policy.action(&observation) < GazeChoice::COUNT);
    }
    // Short observations are padded with zeros, long ones cut: neither panics.
    assert!(policy.action(&[1.0; 3]) < GazeChoice::COUNT);
});
