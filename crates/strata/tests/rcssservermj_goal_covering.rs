//! `strata experiment goal-covering --engine rcssservermj` as a user runs it: a T1 keeper in the
//! real server, the ball moved along a short trajectory by the monitor port, the report, CSV,
//! plot and JSON summary.
//!
//! Needs the server (`scripts/setup-rcssservermj`); without it the test says so and passes,
//! unless `STRATA_REQUIRE_RCSSSERVERMJ` is set (as `scripts/test` does). The physics is not
//! bit-for-bit repeatable: the test asserts what any run must show, not a fraction.

mod common;

use common::cli::{physics_experiment, rcssservermj_installed, run, strata, temp_dir};

/// One method, one rate, one 2.4 m trajectory: about 12 s of play.
const SCENARIO: &str = r#"
runs = 1
ball_speed = 0.8
deliberative_hz = [2.0]
keeper_beam = [-27.2, 0.0, 0.0]
ready = 5.0
warmup = 3.0
settle = 1.0
placement_period = 0.1
status_interval = 0.1
reference = "value-function"

[[methods]]
name = "value-function"
team = "full"

[[trajectories]]
name = "short"
waypoints = [[-22.7, 1.2], [-22.7, -1.2]]

[[paper]]
deliberative_hz = 2.0
observe_ball = 0.315
ball_unknown = 0.109
target_ball_unknown = 0.03
"#;

#[test]
fn the_keeper_runs_in_physics_and_its_ball_perception_is_reported() {
    if !rcssservermj_installed() {
        return;
    }
    let log = temp_dir("goal-covering-rcssservermj-log").join("keeper.mcap");
    let log_arg = log.to_str().expect("a UTF-8 path");
    let (out, summary) = physics_experiment("goal-covering", SCENARIO, &["--log", log_arg]);
    println!("{summary:#}");
    let runs = summary["runs"].as_array().expect("runs");
    assert_eq!(runs.len(), 1);
    let one = &runs[0];
    // 4 s of ball moving and settling, a sample each 0.1 s of simulated time.
    let samples = one["samples"].as_u64().expect("samples");
    assert!(samples >= 30, "{samples} samples");
    let unknown = one["ball_unknown"].as_f64().expect("a ball-unknown fraction");
    assert!((0.0..=1.0).contains(&unknown), "ball unknown {unknown}");
    // The short path passes 4.5 m from the keeper, well within the camera's 10 m: every sample
    // is in range, so both figures are the same.
    assert_eq!(one["in_range"].as_f64(), Some(1.0), "{one}");
    assert_eq!(one["ball_unknown_in_range"].as_f64(), Some(unknown), "{one}");
    let pose = one["pose_error_m"].as_f64().expect("a pose error");
    assert!(pose.is_finite() && pose >= 0.0, "pose error {pose}");
    let conditions = summary["conditions"].as_array().expect("conditions");
    assert_eq!(conditions.len(), 1);
    assert_eq!(conditions[0]["method"], "value-function");
    let targets = summary["targets"].as_array().expect("targets");
    assert_eq!(targets.len(), 1, "the paper's row at 2 Hz gives a target");
    for file in ["report.md", "goal-covering.csv", "ball-unknown.png", "summary.json"] {
        assert!(out.join(file).is_file(), "{file} written");
    }
    let report = std::fs::read_to_string(out.join("report.md")).expect("the report");
    assert!(report.contains("--engine rcssservermj"), "the report's command names the engine");
    assert!(report.contains("Table 5"), "the report places the paper's table");
    let csv = std::fs::read_to_string(out.join("goal-covering.csv")).expect("the CSV");
    assert_eq!(csv.lines().count(), 2, "a header and one run: {csv}");
    // `--log` records the first run's keeper, whose modules replay from it.
    let info = run(&mut strata(&["log", "info", log_arg]));
    assert!(info.status.success(), "the keeper's log opens");
    let text = String::from_utf8_lossy(&info.stdout);
    assert!(text.contains("world/world_state"), "the keeper's world model is logged: {text}");
}
