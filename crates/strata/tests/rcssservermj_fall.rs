//! `strata experiment fall --engine rcssservermj` against the real server, in a small scenario:
//! two pushes of one T1 and a short walk, the command as a user runs it.
//!
//! Needs the server (`scripts/setup-rcssservermj`). Without it the test says so and passes,
//! unless `STRATA_REQUIRE_RCSSSERVERMJ` is set (as `scripts/test` does after installing it).
//! MuJoCo in another process and the robots' threaded hosts make runs close to but not
//! bit-for-bit repeatable: the test asserts that falls were caused, detected and measured, not
//! how fast.

mod common;

use common::cli::{physics_experiment, rcssservermj_installed};

/// Two pushes (front, back) of one robot, then one robot chasing the ball for 15 s; the 2D
/// experiment is not run (its figures come from the docs).
const SCENARIO: &str = r#"
description = "CI: two pushes and a short walk"
team = "full"

[pushes]
runs = 1
pushes_per_run = 2
player = 2
beam = [-3.0, 1.0, 0.0]
ready = 6.0
method = "tilt"
ball_speed = 30.0
ball_height = 0.75
ball_distance = 0.6
tilt_degrees = 25.0
directions = ["front", "back"]
chase_distance = 2.5
settle = [1.0, 1.5]
fall_window = 1.5
recovery_timeout = 20.0

[walking]
runs = 1
robots = 1
duration = 15.0
ready = 4.0
ball_every = 5.0
ball_area = [[-6.0, -2.0], [-3.0, 3.0]]

[targets]
onset_to_command_ms = 51.0
percept_to_command_ms = 40.0
walking_minutes = 10.0

[sim2d]
run = false
documented_onset_to_command_ms = 465.0
documented_percepts_to_command_ms = 10.0
documented_standing_s = 4.59
documented_source = "docs/experiments.md"
"#;

fn figure(value: &serde_json::Value, pointer: &str) -> f64 {
    value
        .pointer(pointer)
        .and_then(serde_json::Value::as_f64)
        .unwrap_or_else(|| panic!("no number at {pointer} in {value}"))
}

#[test]
fn pushed_t1s_fall_are_caught_by_the_reactive_layer_and_the_report_says_so() {
    if !rcssservermj_installed() {
        return;
    }
    let (out, summary) = physics_experiment("fall", SCENARIO, &[]);
    println!("{}", serde_json::to_string_pretty(&summary).unwrap_or_default());

    assert_eq!(summary["engine"], "rcssservermj");
    assert_eq!(figure(&summary, "/pushes"), 2.0);
    // A T1 placed 25 degrees off the vertical, its joints reset, always falls.
    assert!(figure(&summary, "/pushes_with_fall") >= 1.0, "no push made the robot fall");
    assert!(figure(&summary, "/falls_pushed") >= 1.0, "the robot's report holds no pushed fall");
    assert!(figure(&summary, "/detected") >= 1.0, "no fall was given a Fall order");
    for measure in ["onset_to_command", "percept_to_command", "reaction"] {
        let n = figure(&summary, &format!("/{measure}/n"));
        let median = figure(&summary, &format!("/{measure}/median"));
        assert!(n >= 1.0 && median.is_finite(), "{measure}: n {n}, median {median}");
        // Bounds a broken measurement, not a speed: the protective fall lasts 0.6 s.
        assert!(median.abs() < 2.0, "{measure}: median {median} s");
    }
    for target in ["target_onset_to_command_ms", "target_percept_to_command_ms"] {
        assert!(summary[target]["met"].is_boolean(), "{target}: {}", summary[target]);
        assert!(figure(&summary, &format!("/{target}/measured")).is_finite(), "{target}");
    }
    assert!(figure(&summary, "/playing_robot_minutes") > 0.0, "the walking robot never stood");
    assert!(summary["false_positives_walking"].is_u64());
    assert_eq!(summary["sim2d"].as_array().map(Vec::len), Some(1), "the documented 2D figures");

    for file in [
        "report.md",
        "falls.csv",
        "pushes.csv",
        "runs.csv",
        "latency_histogram.png",
        "latency_cdf.png",
        "summary.json",
    ] {
        let path = out.join(file);
        let len = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
        assert!(len > 0, "{} is missing or empty", path.display());
    }
    let report = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    for needle in ["## Targets", "51 ms", "40 ms", "false positives", "--engine rcssservermj"] {
        assert!(report.contains(needle), "report.md lacks `{needle}`:\n{report}");
    }
    let falls = std::fs::read_to_string(out.join("falls.csv")).expect("falls.csv");
    assert!(falls.lines().any(|l| l.contains("push front") || l.contains("push back")), "{falls}");
    let _ = std::fs::remove_dir_all(out.parent().unwrap_or(&out));
}
