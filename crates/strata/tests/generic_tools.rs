//! A match log read by generic tools: Foxglove's own libraries (`@mcap/core` for the file,
//! `@foxglove/omgidl-parser` and `@foxglove/omgidl-serialization` for the CDR messages and
//! their OMG IDL schemas, `fzstd` and `lz4js` for the chunks, `@foxglove/schemas` for the
//! scene channels) decode every message of every channel (packages, ground truth, game state,
//! behavior paths, the scene), and read the values Strata's reader reads; the scene holds the
//! field and every robot where the logged packages put it.
//!
//! Needs Node.js and the packages of `tests/foxglove` (`./scripts/test` installs them with
//! `npm ci`). Without them the test says so and passes, unless `STRATA_REQUIRE_FOXGLOVE` is set
//! (the test script sets it once they are installed), in which case it fails.

mod view_support;

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;
use strata_games::logging::{LogSettings, RunConfig};
use strata_games::matches::robot_name;
use strata_log::{LogCompression, LogReader};
use strata_robot::world::WorldState;
use strata_sim::GroundTruth;
use strata_spl::field::Field;
use view_support::{record_match, required_tool, scratch};

/// The scene is checked at the first update at or after this log time, seconds.
const SCENE_AT: f64 = 2.0;

/// The scene channels and the schema each must have.
const SCENE_CHANNELS: [(&str, &str); 4] = [
    ("scene/field", "foxglove.SceneUpdate"),
    ("scene/objects", "foxglove.SceneUpdate"),
    ("scene/tf", "foxglove.FrameTransforms"),
    ("scene/events", "foxglove.Log"),
];

/// Runs the Foxglove reader on a log: its report.
fn read_with_foxglove(script: &Path, path: &Path) -> Value {
    let output = Command::new("node")
        .arg(script)
        .arg(path)
        .arg(SCENE_AT.to_string())
        .output()
        .expect("node runs");
    assert!(
        output.status.success(),
        "the reader failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let report: Value = serde_json::from_slice(&output.stdout).expect("one JSON line");
    assert_eq!(report["errors"], serde_json::json!([]), "errors: {}", report["errors"]);
    report
}

/// Equal but for the scene's rounding to a tenth of a millimetre.
fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-4
}

/// The same heading, a whole number of turns apart (the scene's quaternions are rounded to
/// 1e-4: about 2e-4 rad).
fn same_angle(a: f64, b: f64) -> bool {
    let d = (a - b).rem_euclid(std::f64::consts::TAU);
    d < 5e-4 || std::f64::consts::TAU - d < 5e-4
}

/// Every scene channel was decoded with Foxglove's schemas, and the scene Foxglove read holds
/// the logged field, every robot at its true pose and its own estimate, and the ball, at the
/// logged ground truth's time.
fn check_scene(report: &Value, reader: &LogReader) {
    for (topic, schema) in SCENE_CHANNELS {
        assert!(report["decoded"][topic].as_u64().is_some_and(|n| n > 0), "{topic}: {report}");
        assert_eq!(report["schemaNames"][topic], schema, "{topic}");
    }
    let config: RunConfig = serde_json::from_value(reader.config().expect("config").expect("one"))
        .expect("the match's configuration");
    let field = Field::new(config.field.clone(), "the log").expect("a field");
    let drawn = &report["scene"]["field"]["field"];
    let lines = drawn["lines"].as_array().expect("lines");
    assert_eq!(lines[0].as_u64(), Some(2 * field.lines().len() as u64), "{drawn}");
    assert_eq!(drawn["cylinders"], 4, "four goal posts");

    let objects = &report["scene"]["objects"];
    let at = objects["logTime"].as_u64().expect("an update at the time asked");
    assert!(at >= (SCENE_AT * 1e9) as u64);
    // The ground truth the update was made of: the package of the same log time.
    let messages: Vec<_> = reader.messages().map(|m| m.expect("readable")).collect();
    let truth: GroundTruth = messages
        .iter()
        .find(|m| &*m.topic == "simulator/ground_truth" && m.log_time.as_nanos() == at)
        .expect("a ground truth at the update's time")
        .decode()
        .expect("ground truth");
    let entities = &objects["entities"];
    let ball = &entities["ball"]["sphere"];
    assert!(close(ball["x"].as_f64().expect("x"), truth.ball.position.x), "{ball}");
    assert!(close(ball["y"].as_f64().expect("y"), truth.ball.position.y), "{ball}");
    let present: Vec<_> = truth.robots.iter().filter(|r| r.present).collect();
    assert_eq!(present.len(), 2 * usize::from(config.players));
    let transforms = &report["scene"]["transforms"];
    assert_eq!(transforms["logTime"].as_u64(), Some(at));
    for robot in present {
        let name = robot_name(robot.id);
        let drawn = &entities[format!("{name}/truth")]["cube"];
        assert!(close(drawn["x"].as_f64().expect("x"), robot.pose.x), "{name}: {drawn}");
        assert!(close(drawn["y"].as_f64().expect("y"), robot.pose.y), "{name}: {drawn}");
        assert!(same_angle(drawn["yaw"].as_f64().expect("yaw"), robot.pose.theta), "{name}");
        assert_eq!(entities[format!("{name}/view")]["frame"], format!("{name}/head"));
        // Its frames: field -> robot at the true pose, robot -> head turned by the head's yaw.
        let frame = |child: &str| {
            transforms["transforms"]
                .as_array()
                .expect("transforms")
                .iter()
                .find(|t| t["child"] == child)
                .unwrap_or_else(|| panic!("no frame {child}"))
                .clone()
        };
        let body = frame(&name);
        assert_eq!(body["parent"], "field");
        assert!(close(body["x"].as_f64().expect("x"), robot.pose.x), "{name}: {body}");
        let head = frame(&format!("{name}/head"));
        assert_eq!(head["parent"], name.as_str());
        assert!(same_angle(head["yaw"].as_f64().expect("yaw"), robot.head.yaw), "{name}");
        assert_eq!(frame(&format!("{name}/camera"))["parent"], format!("{name}/head"));

        // Its own estimate: its newest world state by then, turned into the field frame.
        let world = messages
            .iter()
            .rev()
            .find(|m| {
                *m.topic == *format!("{name}/world/world_state") && m.log_time.as_nanos() <= at
            })
            .expect("a world state")
            .decode::<WorldState>()
            .expect("world state");
        let sign = truth.game.attack_sign[robot.id.team];
        let p = world.pose.pose;
        let (x, y, theta) = if sign < 0.0 {
            (-p.x, -p.y, p.theta + std::f64::consts::PI)
        } else {
            (p.x, p.y, p.theta)
        };
        let estimate = &entities[format!("{name}/estimate")]["arrow"];
        assert!(close(estimate["x"].as_f64().expect("x"), x), "{name}: {estimate}");
        assert!(close(estimate["y"].as_f64().expect("y"), y), "{name}: {estimate}");
        assert!(same_angle(estimate["yaw"].as_f64().expect("yaw"), theta), "{name}");
    }
    // The layer plot of the same instant: every robot's three layers heard from, reactive
    // fastest, and its head multiplexer's score vector.
    let plot = &report["scene"]["plot"];
    assert_eq!(plot["logTime"].as_u64(), Some(at), "{plot}");
    assert_eq!(report["schemaNames"]["plot/layers"], "strata.LayerPlot");
    let robots = plot["robots"].as_array().expect("robots");
    assert_eq!(robots.len(), 2 * usize::from(config.players), "{plot}");
    for robot in robots {
        let rate = |layer: &str| robot["rates"][layer].as_f64().expect("a rate");
        assert!(rate("reactive") > rate("deliberative"), "{robot}");
        assert!(rate("deliberative") > 0.0, "{robot}");
        assert!(!robot["head"].as_array().expect("head scores").is_empty(), "{robot}");
    }
    // The game's start is in the event log.
    let events = report["scene"]["events"].as_array().expect("events");
    assert!(
        events.iter().any(|e| e.as_str().is_some_and(|e| e.contains("game state"))),
        "{events:?}"
    );
}

fn checker() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/foxglove");
    let installed = dir.join("node_modules/@mcap/core").is_dir()
        && Command::new("node").arg("--version").output().is_ok_and(|o| o.status.success());
    installed.then(|| dir.join("read_log.js"))
}

#[test]
fn foxglove_reads_every_package_of_a_match_log() {
    let Some(script) = required_tool(
        checker(),
        "STRATA_REQUIRE_FOXGLOVE",
        "generic_tools",
        "Node.js or the packages of crates/strata/tests/foxglove are missing",
    ) else {
        return;
    };
    let dir = scratch("generic-tools");
    let path = dir.join("match.mcap");
    // The default log: CDR, zstd chunks.
    record_match(&LogSettings::full(&path), 2, 3.0, 5, None);
    let report = read_with_foxglove(&script, &path);
    assert!(report["compressions"]["zstd"].as_u64().is_some_and(|n| n > 0), "{report}");
    let decoded = report["decoded"].as_object().expect("counts");
    for kind in [
        "world/world_state",
        "reactive/report",
        "perception/percepts",
        "actuation/feedback",
        "reactive/commands",
        "deliberative/scores",
        "planning/decision",
        "shared/WorldLayout",
        "shared/GoalLabels",
        "simulator/ground_truth",
        "game/state",
        "behavior_path",
    ] {
        assert!(decoded.get(kind).and_then(Value::as_u64).is_some_and(|n| n > 0), "{kind}");
    }
    // Every channel of a default log has an IDL schema or is one of Foxglove's own (the
    // scene): none is left to a self-describing encoding that Foxglove has no decoder for.
    assert_eq!(report["selfDescribing"], serde_json::json!({}), "{}", report["selfDescribing"]);
    let count = |v: &Value| v.as_object().map_or(0, |m| m.values().filter_map(Value::as_u64).sum());
    let reader = LogReader::open(&path).expect("open");
    assert_eq!(
        count(&report["decoded"]) + count(&report["selfDescribing"]),
        reader.message_count(),
        "every message read"
    );

    // The first world state as Foxglove reads it is the one Strata's reader reads.
    let ours = reader
        .messages()
        .map(|m| m.expect("readable"))
        .find(|m| m.topic.ends_with("world/world_state"))
        .expect("a world state")
        .json()
        .expect("json");
    let theirs = &report["samples"]["world/world_state"];
    // JavaScript prints 10000.0 as 10000: compared as numbers.
    let numbers = |v: &Value| -> Vec<f64> {
        match v {
            Value::Array(items) => items.iter().filter_map(Value::as_f64).collect(),
            other => other.as_f64().into_iter().collect(),
        }
    };
    assert_eq!(numbers(&theirs["stamp"]), numbers(&ours["stamp"]));
    assert_eq!(numbers(&theirs["pose"]["covariance"]), numbers(&ours["pose"]["covariance"]));
    let confidence = |v: &Value| numbers(&v["objects"][0]["confidence"]);
    assert_eq!(confidence(theirs), confidence(&ours));
    check_scene(&report, &reader);
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

/// A log with lz4 chunks reads the same way, scene included.
#[test]
fn foxglove_reads_an_lz4_match_log_and_its_scene() {
    let Some(script) = required_tool(
        checker(),
        "STRATA_REQUIRE_FOXGLOVE",
        "generic_tools",
        "Node.js or the packages of crates/strata/tests/foxglove are missing",
    ) else {
        return;
    };
    let dir = scratch("generic-tools-lz4");
    let path = dir.join("match.mcap");
    let settings = LogSettings { compression: LogCompression::Lz4, ..LogSettings::full(&path) };
    record_match(&settings, 2, 3.0, 9, None);
    let report = read_with_foxglove(&script, &path);
    assert!(report["compressions"]["lz4"].as_u64().is_some_and(|n| n > 0), "{report}");
    assert_eq!(report["compressions"]["zstd"], Value::Null);
    assert_eq!(report["selfDescribing"], serde_json::json!({}), "{}", report["selfDescribing"]);
    let reader = LogReader::open(&path).expect("open");
    let count = |v: &Value| v.as_object().map_or(0, |m| m.values().filter_map(Value::as_u64).sum());
    assert_eq!(count(&report["decoded"]), reader.message_count(), "every message read");
    check_scene(&report, &reader);
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

/// Without the scene channels (`--log-no-scene`) the log has none.
#[test]
fn a_log_without_the_scene_has_no_scene_channels() {
    let dir = scratch("generic-tools-no-scene");
    let path = dir.join("match.mcap");
    let settings = LogSettings { scene: false, ..LogSettings::full(&path) };
    record_match(&settings, 1, 1.0, 3, None);
    let reader = LogReader::open(&path).expect("open");
    assert!(reader.topics().iter().all(|t| !t.name.starts_with("scene/")));
    assert!(reader.topic("simulator/ground_truth").is_some());
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}
