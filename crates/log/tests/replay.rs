//! Replaying logged modules: deterministic modules reproduce their outputs exactly; a changed
//! parameter shows up as listed differences.

mod support;

use std::time::Duration;

use strata_log::overrides::Override;
use strata_log::replay::{ReplayError, ReplayOptions, replay};
use strata_log::{LogReader, McapTapOptions};
use support::{CONFIG, record_demo, registry, scratch};

fn options(modules: &[&str], set: &[&str]) -> ReplayOptions {
    ReplayOptions {
        modules: modules.iter().map(|m| (*m).to_owned()).collect(),
        overrides: set.iter().map(|s| Override::parse(s).expect("override")).collect(),
        max_differences: 5,
        ..ReplayOptions::default()
    }
}

#[test]
fn deterministic_modules_replay_identically() {
    let dir = scratch("replay-equal");
    let path = dir.join("demo.mcap");
    record_demo(&path, 3.0, McapTapOptions::default(), CONFIG);
    let reader = LogReader::open(&path).expect("open");
    let registry = registry();

    // Input-triggered, with a queue, random draws and a random processing time.
    let report = replay(&reader, &registry, &options(&["filter"], &[])).expect("replay");
    assert!(report.identical(), "{report}");
    assert!(report.warnings.is_empty(), "{report}");
    assert_eq!(report.inputs.len(), 1);
    assert_eq!(report.inputs[0].topic.as_deref(), Some("source/reading"));
    assert_eq!(report.inputs[0].packages, 301);
    assert_eq!(report.outputs[0].topic, "filter/estimate");
    assert!(report.outputs[0].equal > 250, "{report}");
    assert_eq!(report.outputs[0].equal, report.outputs[0].logged);

    // Periodic, reading packages sent at the instant of its ticks.
    let report = replay(&reader, &registry, &options(&["monitor"], &[])).expect("replay");
    assert!(report.identical(), "{report}");
    assert_eq!(report.outputs[0].equal, 151);

    // Several modules together: the connection between them is kept, not fed from the log.
    let report = replay(&reader, &registry, &options(&["filter", "monitor"], &[])).expect("replay");
    assert!(report.identical(), "{report}");
    let fed: Vec<&str> = report.inputs.iter().map(|i| i.input.as_str()).collect();
    assert_eq!(fed, ["filter.readings", "monitor.reading"]);

    // Ticks of a reader that runs before its writer at the same instant.
    let early = dir.join("early.mcap");
    record_demo(
        &early,
        1.0,
        McapTapOptions::default(),
        &CONFIG.replace("priority = 10", "priority = -5"),
    );
    let early = LogReader::open(&early).expect("open");
    let report = replay(&early, &registry, &options(&["monitor"], &[])).expect("replay");
    assert!(report.identical(), "{report}");

    // A source has no inputs: it replays from its seed alone.
    let report = replay(&reader, &registry, &options(&["source"], &[])).expect("replay");
    assert!(report.identical(), "{report}");
    assert!(report.to_string().contains("identical"));
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

#[test]
fn a_changed_parameter_lists_differences() {
    let dir = scratch("replay-set");
    let path = dir.join("demo.mcap");
    record_demo(&path, 2.0, McapTapOptions::default(), CONFIG);
    let reader = LogReader::open(&path).expect("open");
    let report =
        replay(&reader, &registry(), &options(&["filter"], &["filter.gain=0.5"])).expect("replay");
    assert!(!report.identical());
    assert_eq!(report.overrides, ["filter.gain=0.5"]);
    assert_eq!(report.differences.len(), 5);
    assert!(report.total_differences > 100, "{report}");
    let first = &report.differences[0];
    assert_eq!(first.topic, "filter/estimate");
    assert_eq!(first.index, 0);
    assert_eq!(first.logged_seq, Some(0));
    assert!(first.details.iter().any(|d| d.starts_with("$.value: ")), "{:?}", first.details);
    // Same timing: only the values changed.
    assert!(report.differences.iter().all(|d| d.details.iter().all(|x| x.starts_with("$.value"))));
    let text = report.to_string();
    assert!(text.contains("differences; the first 5"), "{text}");
    assert!(text.contains("--set filter.gain=0.5"), "{text}");

    // A different seed changes the random draws.
    let mut reseeded = options(&["filter"], &[]);
    reseeded.seed = Some(7);
    let report = replay(&reader, &registry(), &reseeded).expect("replay");
    assert!(!report.identical());
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

#[test]
fn replay_errors_say_what_is_wrong() {
    let dir = scratch("replay-errors");
    let path = dir.join("demo.mcap");
    let small = McapTapOptions { max_chunk_span: Duration::from_millis(50), ..Default::default() };
    record_demo(&path, 0.5, small, CONFIG);
    let reader = LogReader::open(&path).expect("open");
    let registry = registry();

    let error = replay(&reader, &registry, &options(&["filter"], &["filter.gian=1"]))
        .err()
        .map(|e| e.to_string());
    assert_eq!(
        error.as_deref(),
        Some("--set filter.gian: `gian` does not exist in `filter` (it has: gain, jitter)")
    );
    match replay(&reader, &registry, &options(&["planner"], &[])) {
        Err(ReplayError::UnknownModule { name, available }) => {
            assert_eq!(name, "planner");
            assert_eq!(available, ["source", "filter", "monitor"]);
        }
        other => panic!("{other:?}"),
    }
    let mut robot = options(&["filter"], &[]);
    robot.robot = Some("3".to_owned());
    match replay(&reader, &registry, &robot) {
        Err(ReplayError::UnknownModule { name, .. }) => assert_eq!(name, "3/filter"),
        other => panic!("{other:?}"),
    }
    let empty = strata_log::replay::ModuleRegistry::new();
    let error = replay(&reader, &empty, &options(&["filter"], &[])).err().map(|e| e.to_string());
    assert_eq!(
        error.as_deref(),
        Some("no constructor for module kind `filter`; known kinds: none")
    );
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

#[test]
fn a_truncated_log_still_replays_what_it_holds() {
    let dir = scratch("replay-truncated");
    let path = dir.join("demo.mcap");
    let small = McapTapOptions { max_chunk_span: Duration::from_millis(100), ..Default::default() };
    record_demo(&path, 2.0, small, CONFIG);
    let bytes = std::fs::read(&path).expect("read");
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).expect("write");
    let reader = LogReader::open(&cut).expect("open");
    assert!(!reader.is_complete());
    let report = replay(&reader, &registry(), &options(&["filter"], &[])).expect("replay");
    assert!(report.warnings.iter().any(|w| w.contains("not finished")), "{report}");
    // The replay stops at the last recovered message; outputs up to there match.
    assert!(report.identical(), "{report}");

    // Cut before its graph: said so, not that the log was written without one.
    let stub = dir.join("stub.mcap");
    std::fs::write(&stub, &bytes[..64]).expect("write");
    let reader = LogReader::open(&stub).expect("open");
    let error = replay(&reader, &registry(), &options(&["filter"], &[])).expect_err("no graph");
    assert!(matches!(error, ReplayError::GraphCutOff { .. }), "{error}");
    assert!(error.to_string().contains("cut short"), "{error}");
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}
