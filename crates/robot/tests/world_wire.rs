//! A world state is written as what the world model decided (the pose, each object's
//! confidence and filter estimate) with a reference to its layout, and read back by working
//! the rest out again (`world/wire.rs`). Read back, it must be the published state bit for
//! bit — localized, lost, after a kidnap, with obstacles and a moving ball — in the log's
//! encoding (CDR, the layout stored once) and in JSON (the layout inline).

mod world_support;

use strata_robot::geometry::{Odometry, Pose};
use strata_robot::platform::ObjectClass;
use strata_robot::world::{
    ObjectKind, ObjectOfInterest, PosePrior, WorldCommand, WorldModel, WorldModelConfig, WorldState,
};
use strata_runtime::Encoding;
use strata_runtime::shared::{self, Recorder};
use world_support::{Sim, config, patrol_step};

fn layout(initial: Option<PosePrior>) -> WorldModelConfig {
    let mut config = config(initial);
    config.objects.push(ObjectOfInterest {
        name: "obstacle".to_owned(),
        class: ObjectClass(30),
        variant: None,
        kind: ObjectKind::Obstacle {
            max_tracks: 3,
            acceleration_noise: 0.5,
            velocity_decay: 1.0,
            max_speed: 0.6,
        },
        confidence: None,
    });
    config
}

/// Debug prints every float with its sign and shortest round-trip digits: equal texts are
/// equal states, bit for bit (NaNs aside).
fn text(state: &WorldState) -> String {
    format!("{state:?}")
}

/// Every state of a patrol (with a kidnap half way), each encoded with `encode` and read back.
fn states(initial: Option<PosePrior>, seed: u64, frames: usize) -> Vec<WorldState> {
    let mut world = WorldModel::new(layout(initial)).expect("valid config");
    let mut sim = Sim::new(seed, Pose::new(-1.0, 0.5, 0.3));
    sim.ball_velocity = nalgebra::Vector2::new(0.4, -0.2);
    let mut states = Vec::new();
    for frame in 0..frames {
        let (odometry, percepts) = sim.frame(patrol_step(&sim));
        world.process(odometry, &percepts);
        if frame == frames / 2 {
            world.command(WorldCommand::Kidnapped).expect("accepted");
        }
        if frame % 37 == 5 {
            world.predict(Odometry { dx: 0.01, dy: 0.0, dtheta: -0.03 });
        }
        states.push(world.publish());
    }
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
        assert_eq!(text(&back), text(state), "CDR");
        // The objects by name, as the model's own state finds them.
        assert_eq!(back.object("ball").map(|o| o.id), state.object("ball").map(|o| o.id));
    }
    // Self-contained (no recorder): the layout inline.
    for state in states.iter().step_by(17) {
        let json = serde_json::to_vec(state).expect("json");
        let back: WorldState = serde_json::from_slice(&json).expect("from json");
        assert_eq!(text(&back), text(state), "JSON");
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
