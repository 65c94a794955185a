//! How packages are written: a reactive report with its goals' labels stored once (a shared
//! value) and its selected goal by place; commands and platform states tagged in text (JSON,
//! TOML: what people and the simulator's protocol read) and positional in CDR (logs). Every
//! form reads back as the value written.

use std::sync::Arc;

use strata_robot::command::{
    BodyCommand, BodyMotion, HeadCommand, HeadMotion, MotionCommands, ResourceGroup,
};
use strata_robot::control::reactive::{GoalReport, MuxReport, ReactiveReport, Stability};
use strata_robot::geometry::Velocity;
use strata_robot::platform::{
    BodyMotionState, BodyOrder, CycleStage, FallDirection, HeadAngles, MotionName, SpecialMotion,
};
use strata_runtime::shared::{self, Recorder};
use strata_runtime::{Encoding, Time, cdr};

fn goal(label: &str, objects: &[&str], scores: (f64, f64, f64), applicable: bool) -> GoalReport {
    GoalReport {
        goal: Arc::from(label),
        objects: objects.iter().map(|o| (*o).to_owned()).collect::<Vec<_>>().into(),
        deliberative: scores.0,
        reactive: scores.1,
        final_score: scores.2,
        applicable,
    }
}

fn report(selected: Option<&str>, reactive: f64) -> ReactiveReport {
    let head = MuxReport {
        group: Some(ResourceGroup::Head),
        goals: vec![
            goal("observe ball", &["ball"], (0.8, reactive, 0.5 * (0.8 + reactive)), true),
            goal("observe goal_post#1", &["goal_post#1"], (0.4, 0.1, 0.25), false),
        ]
        .into(),
        selected_goal: selected.map(Arc::from),
        primitive: Some("object tracking".into()),
        inhibited_by: None,
        scores_received: Some(Time::from_secs_f64(1.5)),
    };
    ReactiveReport {
        stamp: Time::from_secs_f64(2.0),
        stability: Stability::Unstable(FallDirection::Back),
        head,
        body: MuxReport {
            group: Some(ResourceGroup::Body),
            inhibited_by: Some(ResourceGroup::HeadAndBody),
            ..MuxReport::default()
        },
        whole_body: MuxReport::default(),
        commands: MotionCommands::PerResource {
            head: Some(HeadCommand::NonQueue(HeadMotion {
                target: HeadAngles { yaw: 0.3, pitch: 0.1 },
                max_speed: 2.0,
            })),
            body: Some(BodyCommand::Queue(BodyMotion::Walk {
                velocity: Velocity { vx: 0.2, vy: 0.0, omega: -0.1 },
                duration: 0.5,
            })),
        },
    }
}

fn text(report: &ReactiveReport) -> String {
    format!("{report:?}")
}

#[test]
fn reactive_reports_store_their_goal_labels_once() {
    // Consecutive reports of one multiplexer share their labels (as a multiplexer's do while
    // its goals stay); the selected goal is one of them, or (made by hand) not.
    let first = report(Some("observe ball"), 0.2);
    let mut second = first.clone();
    second.head.selected_goal = Some(Arc::from("a goal not in the list"));
    let previous = Recorder::default().install();
    let mut encoded = Vec::new();
    let mut records = Vec::new();
    for r in [&first, &second, &first] {
        let mut bytes = Vec::new();
        Encoding::Cdr.encode(r, &mut bytes).expect("encodes");
        encoded.push(bytes);
        records.extend(Recorder::take_new());
    }
    Recorder::uninstall();
    if let Some(previous) = previous {
        previous.install();
    }
    assert_eq!(records.len(), 1, "the head's labels, once");
    for record in &records {
        shared::register(record.id, record.encoding, &record.bytes);
    }
    for (bytes, r) in encoded.iter().zip([&first, &second, &first]) {
        let back: ReactiveReport = Encoding::Cdr.decode(bytes).expect("decodes");
        assert_eq!(text(&back), text(r));
    }
    // The labels are not in the reports: the one that names its goal by place is smaller.
    assert!(encoded[0].len() + "observe ball".len() < encoded[1].len());
    // Self-contained in JSON.
    let json = serde_json::to_string(&first).expect("json");
    let back: ReactiveReport = serde_json::from_str(&json).expect("from json");
    assert_eq!(text(&back), text(&first));
}

#[test]
fn a_selected_goal_beyond_the_goals_is_refused() {
    let r = report(Some("observe ball"), 0.2);
    let mut json = serde_json::to_value(&r).expect("json");
    json["head"]["selected_goal"] = serde_json::json!({ "goal": 7 });
    let error = serde_json::from_value::<ReactiveReport>(json).expect_err("no goal 7");
    assert!(error.to_string().contains("selected goal 7 of 2 goals"), "{error}");
}

#[test]
fn commands_and_platform_states_are_tagged_in_text_and_positional_in_cdr() {
    let kick = SpecialMotion::stand_up(2);
    assert_eq!(
        serde_json::to_value(kick).expect("json"),
        serde_json::json!({ "kind": "stand_up", "sequence": 2 })
    );
    let from_toml: toml::Table =
        toml::from_str("motion = { kind = \"kick\", sequence = 1 }").expect("toml");
    let motion: SpecialMotion =
        from_toml["motion"].clone().try_into().expect("a motion file's form");
    // A kick written before the application named it left the head free, and still does.
    assert_eq!(motion, SpecialMotion::new(MotionName::from_static("kick"), 1, false));
    let walking = BodyMotionState::Walking {
        stage: CycleStage::Execution,
        velocity: Velocity { vx: 0.1, vy: 0.0, omega: 0.0 },
    };
    assert_eq!(serde_json::to_value(walking).expect("json")["state"], "walking");
    for state in [
        walking,
        BodyMotionState::Special { motion: kick, elapsed: 0.5, duration: 2.0 },
        BodyMotionState::Special { motion: WAVE, elapsed: 0.5, duration: 2.0 },
        BodyMotionState::Fallen { direction: FallDirection::Left },
        BodyMotionState::Limp,
    ] {
        let mut bytes = Vec::new();
        cdr::encode(&state, &mut bytes).expect("cdr");
        assert_eq!(cdr::decode::<BodyMotionState>(&bytes).expect("back"), state);
        let json = serde_json::to_string(&state).expect("json");
        assert_eq!(serde_json::from_str::<BodyMotionState>(&json).expect("back"), state);
    }
    // CDR describes every package type of a robot's modules.
    for format in [
        cdr::trace::<ReactiveReport>(),
        cdr::trace::<MotionCommands>(),
        cdr::trace::<strata_robot::platform::MotionFeedback>(),
        cdr::trace::<strata_robot::command::ActuationMessage>(),
        cdr::trace::<strata_robot::world::WorldState>(),
        cdr::trace::<strata_robot::percept::Percepts>(),
        // A serde alias would list a field twice in the trace and break the schema.
        cdr::trace::<strata_robot::world::TeammateEstimate>(),
    ] {
        let format = format.expect("traced");
        cdr::idl_schema(&format, "T").expect("an IDL schema");
    }
}

#[test]
fn symmetry_hints_are_tagged_in_text_and_positional_in_cdr() {
    use strata_robot::world::{PosePrior, Region, SymmetryHint, WorldCommand};
    let prior = PosePrior { pose: strata_robot::Pose::new(-3.0, 0.0, 0.0), sigma: [0.2, 0.2, 0.1] };
    let hints = vec![
        SymmetryHint::Region {
            region: Region { min_x: -4.5, max_x: 0.0, min_y: -3.0, max_y: 3.0 },
        },
        SymmetryHint::Heading { theta: 0.0, sigma: 0.5 },
        SymmetryHint::NearPoses { poses: vec![prior] },
        SymmetryHint::Relocations { poses: vec![prior] },
    ];
    // As a configuration file writes them.
    let from_toml: toml::Table =
        toml::from_str("hint = { type = \"heading\", theta = 0.0, sigma = 0.5 }").expect("toml");
    let hint: SymmetryHint = from_toml["hint"].clone().try_into().expect("a config's form");
    assert_eq!(hint, hints[1]);
    assert_eq!(serde_json::to_value(&hints[0]).expect("json")["type"], "region");
    // As a log writes them, inside the command that carries them.
    let command = WorldCommand::SetHints { hints };
    for encoding in [Encoding::Cdr, Encoding::MessagePack, Encoding::Json] {
        let mut bytes = Vec::new();
        encoding.encode(&command, &mut bytes).expect("encoded");
        assert_eq!(encoding.decode::<WorldCommand>(&bytes).expect("back"), command, "{encoding:?}");
    }
    let format = cdr::trace::<WorldCommand>().expect("CDR describes world commands");
    cdr::idl_schema(&format, "WorldCommand").expect("an IDL schema");
}

/// A motion an application names: one that leaves the head free.
const WAVE: SpecialMotion = SpecialMotion::new(MotionName::from_static("wave"), 3, false);

#[test]
fn an_application_names_its_motions_and_says_when_the_head_stays_free() {
    assert_eq!(
        serde_json::to_value(WAVE).expect("json"),
        serde_json::json!({ "kind": "wave", "sequence": 3, "head": false })
    );
    let with_head = SpecialMotion { head: true, ..WAVE };
    assert_eq!(
        serde_json::to_value(with_head).expect("json"),
        serde_json::json!({ "kind": "wave", "sequence": 3 })
    );
    for motion in [WAVE, with_head, SpecialMotion::fall(0)] {
        let order = BodyOrder::Special { motion };
        for encoding in [Encoding::Cdr, Encoding::MessagePack, Encoding::Json] {
            let mut bytes = Vec::new();
            encoding.encode(&order, &mut bytes).expect("encoded");
            assert_eq!(encoding.decode::<BodyOrder>(&bytes).expect("back"), order, "{encoding:?}");
        }
    }
    // A name is at most MotionName::CAPACITY bytes, and not empty: refused, not cut.
    let long = "w".repeat(MotionName::CAPACITY + 1);
    assert!(MotionName::new(&long).is_err());
    assert!(MotionName::new("").is_err());
    let json = serde_json::json!({ "kind": long, "sequence": 0 });
    let error = serde_json::from_value::<SpecialMotion>(json).expect_err("too long");
    assert!(error.to_string().contains("motion name"), "{error}");
    let json = serde_json::json!({ "kind": "wave", "sequence": 0, "arms": true });
    assert!(serde_json::from_value::<SpecialMotion>(json).is_err(), "unknown fields are refused");
}

/// The enums logs held before applications named their motions, as the robot crate declared
/// them then.
mod before {
    use serde::Serialize;

    #[derive(Serialize)]
    #[serde(rename_all = "snake_case")]
    pub enum SpecialMotion {
        Kick(u8),
        StandUp(u8),
        Fall(u8),
        Dive(u8),
    }

    /// The variants before `special` are there for its index (CDR) only.
    #[allow(dead_code)]
    #[derive(Serialize)]
    #[serde(rename_all = "snake_case")]
    pub enum BodyMotionState {
        Standing,
        Walking { stage: u8, velocity: [f64; 3] },
        Special { motion: SpecialMotion, elapsed: f64, duration: f64 },
    }
}

#[test]
fn logs_written_while_the_robot_crate_named_the_motions_still_read() {
    let named = |kind: &'static str, sequence: u8, head: bool| {
        SpecialMotion::new(MotionName::from_static(kind), sequence, head)
    };
    let cases = [
        (before::SpecialMotion::Kick(1), named("kick", 1, false)),
        (before::SpecialMotion::StandUp(2), SpecialMotion::stand_up(2)),
        (before::SpecialMotion::Fall(0), SpecialMotion::fall(0)),
        (before::SpecialMotion::Dive(3), named("dive", 3, true)),
    ];
    for (old, motion) in cases {
        let old = before::BodyMotionState::Special { motion: old, elapsed: 0.25, duration: 1.5 };
        let now = BodyMotionState::Special { motion, elapsed: 0.25, duration: 1.5 };
        // CDR writes the variant's index, MessagePack its name.
        for encoding in [Encoding::Cdr, Encoding::MessagePack] {
            let mut bytes = Vec::new();
            encoding.encode(&old, &mut bytes).expect("encoded");
            assert_eq!(encoding.decode::<BodyMotionState>(&bytes).expect("read"), now);
            // Written now, the same bytes: a replay of an older log finds no difference.
            let mut again = Vec::new();
            encoding.encode(&now, &mut again).expect("encoded");
            assert_eq!(again, bytes, "{encoding:?} {motion}");
        }
    }
    // A dive that leaves the head free is not the dive those logs knew: it says so.
    let mut bytes = Vec::new();
    let own_dive = named("dive", 3, false);
    Encoding::Cdr.encode(&own_dive, &mut bytes).expect("encoded");
    assert_eq!(Encoding::Cdr.decode::<SpecialMotion>(&bytes).expect("read"), own_dive);
}
