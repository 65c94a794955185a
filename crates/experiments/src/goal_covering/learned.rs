//! The learned gaze (method `learned` of the goal-covering scenarios): a policy trained with
//! PPO on the gaze environment ([`super::gym`]; python/train_gaze.py) chooses the keeper's gaze
//! at each deliberative decision, from the same observation the environment gives it in
//! training ([`super::gym::observation`]). Between two decisions the choice holds, as an
//! environment step does; through the warm-up the team's own gaze runs, as at an episode's
//! reset.

use std::path::Path;

use strata_soccer::gaze_policy::{GazePolicy, GazePolicyError};

use super::gym::OBS_LEN;

/// `policy = "shipped"` in a scenario's method: the policy shipped with the crate.
pub const SHIPPED_POLICY: &str = "shipped";

/// Trained by python/train_gaze.py (data/README.md says how).
const SHIPPED_WEIGHTS: &[u8] = include_bytes!("../../data/gaze-policy.safetensors");
const SHIPPED_ORIGIN: &str = "the shipped crates/experiments/data/gaze-policy.safetensors";

/// The shipped policy.
pub fn shipped_policy() -> Result<GazePolicy, GazePolicyError> {
    GazePolicy::from_safetensors(SHIPPED_WEIGHTS, SHIPPED_ORIGIN, OBS_LEN)
}

/// A policy file for the environment's observations.
pub fn load_policy(path: &Path) -> Result<GazePolicy, GazePolicyError> {
    GazePolicy::load(path, OBS_LEN)
}

#[cfg(test)]
mod tests {
    use serde::Deserialize;

    use super::*;

    /// Observations with the Python policy's logits and actions (python/train_gaze.py).
    #[derive(Deserialize)]
    struct Fixture {
        observations: Vec<Vec<f32>>,
        logits: Vec<Vec<f32>>,
        actions: Vec<usize>,
    }

    #[test]
    fn the_shipped_policy_matches_python_on_the_fixture() {
        let fixture: Fixture =
            serde_json::from_str(include_str!("../../data/gaze-policy-fixture.json"))
                .expect("the fixture parses");
        let policy = shipped_policy().expect("the shipped policy loads");
        assert_eq!(policy.inputs(), OBS_LEN);
        assert!(!fixture.observations.is_empty());
        assert_eq!(fixture.observations.len(), fixture.logits.len());
        assert_eq!(fixture.observations.len(), fixture.actions.len());
        for (i, observation) in fixture.observations.iter().enumerate() {
            assert_eq!(observation.len(), OBS_LEN);
            let logits = policy.logits(observation);
            for (k, (rust, python)) in logits.iter().zip(&fixture.logits[i]).enumerate() {
                assert!(
                    (rust - python).abs() < 1e-4,
                    "observation {i}, logit {k}: {rust} vs {python}"
                );
            }
            assert_eq!(policy.action(observation), fixture.actions[i], "observation {i}");
        }
    }

    #[test]
    fn a_missing_file_names_it() {
        let path = Path::new("no/such/policy.safetensors");
        let message = load_policy(path).map(|_| ()).expect_err("no file").to_string();
        assert!(message.contains("no/such/policy.safetensors"), "{message}");
    }
}
