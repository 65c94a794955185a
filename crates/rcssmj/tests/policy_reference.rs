//! The shipped T1 walking network against outputs computed from the original T1.pt.
//!
//! The fixture comes from `python3 scripts/t1-policy-reference.py` (numpy, float64, from the
//! original archive's tensors); regenerate it with that command if the shipped weights change.

use serde::Deserialize;
use strata_rcssmj::policy::{ACTION_LEN, OBSERVATION_LEN, WalkNetwork};

#[derive(Deserialize)]
struct Fixture {
    cases: Vec<Case>,
}

#[derive(Deserialize)]
struct Case {
    observation: Vec<f64>,
    action: Vec<f64>,
}

#[test]
fn shipped_network_matches_the_original_within_1e_5() -> Result<(), Box<dyn std::error::Error>> {
    let fixture: Fixture = serde_json::from_str(include_str!("data/policy/t1_reference.json"))?;
    assert_eq!(fixture.cases.len(), 10);
    let network = WalkNetwork::shipped()?;
    let mut worst = 0.0f64;
    for (index, case) in fixture.cases.iter().enumerate() {
        // The observations were drawn as float32, so this conversion is exact.
        let observation: [f32; OBSERVATION_LEN] =
            std::array::from_fn(|i| case.observation[i] as f32);
        assert_eq!(case.action.len(), ACTION_LEN);
        let action = network.forward(&observation);
        for (joint, (&got, &want)) in action.iter().zip(&case.action).enumerate() {
            let error = (f64::from(got) - want).abs();
            worst = worst.max(error);
            assert!(
                error <= 1e-5,
                "case {index}, action {joint}: {got} against {want} (error {error:e})"
            );
        }
    }
    println!("worst absolute error against the original: {worst:e}");
    Ok(())
}
