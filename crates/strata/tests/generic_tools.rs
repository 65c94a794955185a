//! A match log read by generic tools: Foxglove's own libraries (`@mcap/core` for the file,
//! `@foxglove/omgidl-parser` and `@foxglove/omgidl-serialization` for the CDR messages and
//! their OMG IDL schemas, `fzstd` for the chunks) decode every message of every channel
//! (packages, ground truth, game state, behavior paths), and read the values Strata's reader
//! reads.
//!
//! Needs Node.js and the packages of `tests/foxglove` (`./scripts/test` installs them with
//! `npm ci`). Without them the test says so and passes, unless `STRATA_REQUIRE_FOXGLOVE` is set
//! (the test script sets it once they are installed), in which case it fails.

mod view_support;

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;
use strata_games::logging::LogSettings;
use strata_log::LogReader;
use view_support::{record_match, required_tool, scratch};

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
    let output = Command::new("node").arg(&script).arg(&path).output().expect("node runs");
    assert!(
        output.status.success(),
        "the reader failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let report: Value = serde_json::from_slice(&output.stdout).expect("one JSON line");
    assert_eq!(report["errors"], serde_json::json!([]), "errors: {}", report["errors"]);
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
    // Every channel of a default log has an IDL schema: none is left to a self-describing
    // encoding that Foxglove has no decoder for.
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
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}
