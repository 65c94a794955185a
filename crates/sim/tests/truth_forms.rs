//! Ground truth in its two forms: text (experiment data, the simulator's JSON protocol), where
//! an event's fields sit beside its time, tagged by `event`; and binary (logs), where CDR
//! describes it positionally so that generic tools read it with an IDL schema.

mod common;

use common::*;
use strata_robot::{Pose, Vector};
use strata_runtime::{Encoding, cdr};
use strata_sim::{Event, EventKind, GameState, GroundTruth};

/// A world that has something of each sort to tell: a game state change, a teleport, a push.
fn eventful_truth() -> GroundTruth {
    let mut sim = quiet(|_| {});
    sim.set_game_state(GameState::Playing);
    sim.teleport(A1, Pose::new(-1.0, 0.5, 0.3)).expect("a robot of the world");
    sim.push(A2, Vector::new(0.4, 0.0)).expect("a robot of the world");
    steps(&mut sim, 1.0);
    sim.ground_truth()
}

#[test]
fn an_event_reads_as_its_time_beside_its_tagged_fields_in_text() {
    let truth = eventful_truth();
    let teleport = truth
        .events
        .iter()
        .find(|e| matches!(e.kind, EventKind::Teleported { .. }))
        .expect("the teleport is an event");
    let json = serde_json::to_value(teleport).expect("json");
    assert_eq!(json["event"], "teleported");
    assert_eq!(json["robot"]["player"], 1);
    assert!(json["time"].is_number() || json["time"].is_object(), "{json}");
    assert!(json.get("kind").is_none(), "no nesting in text: {json}");
    let back: Event = serde_json::from_value(json).expect("back from text");
    assert_eq!(&back, teleport);
}

#[test]
fn ground_truth_round_trips_in_every_log_encoding_and_cdr_describes_it() {
    let truth = eventful_truth();
    assert!(truth.events.len() >= 3, "{:?}", truth.events);
    for encoding in [Encoding::Cdr, Encoding::MessagePack, Encoding::Json] {
        let mut bytes = Vec::new();
        encoding.encode(&truth, &mut bytes).expect("encoded");
        let back: GroundTruth = encoding.decode(&bytes).expect("decoded");
        assert_eq!(back, truth, "{encoding:?}");
    }
    let format = cdr::trace::<GroundTruth>().expect("CDR describes the ground truth");
    cdr::idl_schema(&format, "GroundTruth").expect("an IDL schema for generic tools");
}
