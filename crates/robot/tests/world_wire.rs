//! A world state is written as what the world model decided (the pose, each object's
//! confidence and filter estimate) with a reference to its layout, and read back by working
//! the rest out again (`world/wire.rs`). Read back, it must be the published state bit for
//! bit — localized, lost, after a kidnap, with obstacles and a moving ball — in the log's
//! encoding (CDR, the layout stored once) and in JSON (the layout inline).

mod world_support;

use strata_robot::geometry::Pose;
use strata_robot::world::{PosePrior, WorldState};
use strata_runtime::Encoding;
use strata_runtime::shared::{self, Recorder};
use world_support::{kidnapped_patrol, state_text};

/// Every state published during a [`kidnapped_patrol`].
fn states(initial: Option<PosePrior>, seed: u64, frames: usize) -> Vec<WorldState> {
    let mut states = Vec::new();
    kidnapped_patrol(initial, seed, frames, |_, world| states.push(world.publish()));
    states
}

fn round_trips(states: &[WorldState]) {
    let objects = || states.iter().flat_map(|s| s.objects.iter());
    assert!(objects().any(|o| o.tracked && o.velocity.is_some()), "a moving object tracked");
    assert!(objects().any(|o| o.tracked && o.velocity.is_none()), "a landmark tracked");
    assert!(objects().any(|o| !o.tracked), "untracked objects");
    // As a log writes them: the recorder stores the layout once, packages refer to it.
    let previous = Recorder::default().install();
    let mut encoded = Vec::new();
    let mut records = Vec::new();
    for state in states {
        let mut bytes = Vec::new();
        Encoding::Cdr.encode(state, &mut bytes).expect("encodes");
        encoded.push(bytes);
        records.extend(Recorder::take_new());
    }
    Recorder::uninstall();
    if let Some(previous) = previous {
        previous.install();
    }
    assert_eq!(records.len(), 1, "one layout, stored once");
    for record in &records {
        shared::register(record.id, record.encoding, &record.bytes);
    }
    for (state, bytes) in states.iter().zip(&encoded) {
        let back: WorldState = Encoding::Cdr.decode(bytes).expect("decodes");
        assert_eq!(state_text(&back), state_text(state), "CDR");
        // The objects by name, as the model's own state finds them.
        assert_eq!(back.object("ball").map(|o| o.id), state.object("ball").map(|o| o.id));
    }
    // Self-contained (no recorder): the layout inline.
    for state in states.iter().step_by(17) {
        let json = serde_json::to_vec(state).expect("json");
        let back: WorldState = serde_json::from_slice(&json).expect("from json");
        assert_eq!(state_text(&back), state_text(state), "JSON");
    }
    // Small: the layout and the derived estimates are not in the package.
    let inline = {
        let mut bytes = Vec::new();
        Encoding::Cdr.encode(&states[0], &mut bytes).expect("encodes");
        bytes.len()
    };
    assert!(encoded[0].len() * 2 < inline, "{} against {inline} inline", encoded[0].len());
}

#[test]
fn world_states_read_back_bit_for_bit_localized() {
    let prior = PosePrior { pose: Pose::new(-1.0, 0.5, 0.3), sigma: [0.05, 0.05, 0.02] };
    round_trips(&states(Some(prior), 7, 240));
}

#[test]
fn world_states_read_back_bit_for_bit_lost() {
    // No prior: lost until recovery; untracked objects share the unknown estimate.
    round_trips(&states(None, 11, 180));
}

#[test]
fn a_world_state_whose_objects_do_not_fit_its_layout_is_refused() {
    let state = states(None, 3, 2).pop().expect("a state");
    let mut json = serde_json::to_value(&state).expect("json");
    json["objects"].as_array_mut().expect("objects").pop();
    let error = serde_json::from_value::<WorldState>(json).expect_err("one object short");
    assert!(error.to_string().contains("objects for a layout of"), "{error}");
}
