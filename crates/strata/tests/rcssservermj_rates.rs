//! `strata experiment rates --engine rcssservermj` against the real server, as a user runs it:
//! a goalkeeper and a striker walk under the full architecture without and with a deliberative
//! load, and the command writes its summary, report, CSV and plots.
//!
//! Needs the server (`scripts/setup-rcssservermj`). Without it the test says so and passes,
//! unless `STRATA_REQUIRE_RCSSSERVERMJ` is set (as `scripts/test` does after installing it).
//! It asserts what the experiment measures, never how fast: real-time rates depend on the
//! machine. The load here (0.8 s) is longer than the deliberative layer's period (0.625 s),
//! so the load shows in the layer's rate as well as in its compute time.

mod common;

use std::collections::BTreeSet;

use common::cli::{physics_experiment, rcssservermj_installed};

const SCENARIO: &str = r#"
description = "a short rates run for the tests"
duration = 10.0
ready = 3.0
runs = 1
loads = [0.0, 0.8]
team = "full"
team_messages = true
ball_period = 5.0
ball_area = [-7.0, -2.0, -2.0, 2.0]
tolerance = 0.98
walking_speed = 0.1

[[robots]]
role = "goalkeeper"
player = 1
beam = [-24.0, 0.0, 0.0]

[[robots]]
role = "striker"
player = 2
beam = [-3.0, 0.0, 0.0]
"#;

const LAYERS: [&str; 5] = ["reactive", "deliberative", "planning", "perception", "world"];

fn number(value: &serde_json::Value, pointer: &str) -> f64 {
    value
        .pointer(pointer)
        .and_then(serde_json::Value::as_f64)
        .unwrap_or_else(|| panic!("no number at {pointer} in {value}"))
}

/// The summary's entry for a role, layer and load.
fn layer<'a>(
    summary: &'a serde_json::Value,
    role: &str,
    name: &str,
    load: f64,
) -> &'a serde_json::Value {
    summary["layers"]
        .as_array()
        .and_then(|layers| {
            layers.iter().find(|l| {
                l["role"] == role && l["layer"] == name && l["load_s"].as_f64() == Some(load)
            })
        })
        .unwrap_or_else(|| panic!("no {role} {name} at load {load}: {}", summary["layers"]))
}

#[test]
fn rates_in_physics_measure_every_layer_of_every_robot_under_both_conditions() {
    if !rcssservermj_installed() {
        return;
    }
    let (out, summary) = physics_experiment("rates", SCENARIO, &["--runs", "1"]);
    println!("{summary:#}");
    assert_eq!(summary["engine"], "rcssservermj");

    // Every layer of every robot ran in both conditions, with finite rates.
    for role in ["goalkeeper", "striker"] {
        for load in [0.0, 0.8] {
            for name in LAYERS {
                let l = layer(&summary, role, name, load);
                for field in ["min_hz", "mean_hz", "max_hz"] {
                    let hz = number(l, &format!("/{field}/mean"));
                    assert!(hz.is_finite() && hz > 0.0, "{role} {name} {load}: {field} {hz}");
                }
                assert!(number(l, "/min_hz/mean") <= number(l, "/max_hz/mean"), "{l}");
            }
        }
    }
    let csv = std::fs::read_to_string(out.join("runs.csv")).expect("runs.csv");
    let mut header = csv.lines().next().unwrap_or_default().split(',');
    let cycles_at = header.position(|h| h == "cycles").expect("a cycles column");
    let mut seen = BTreeSet::new();
    for line in csv.lines().skip(1) {
        let cells: Vec<&str> = line.split(',').collect();
        let cycles: u64 = cells[cycles_at].parse().expect("a cycle count");
        assert!(cycles > 0, "a layer that never ran: {line}");
        seen.insert((cells[0].to_owned(), cells[3].to_owned(), cells[5].to_owned()));
    }
    assert_eq!(seen.len(), 2 * 2 * LAYERS.len(), "every load, robot and layer: {seen:?}");

    // The load made each robot's deliberative cycle longer, and with it the layer slower.
    for role in ["goalkeeper", "striker"] {
        let (free, loaded) = (
            layer(&summary, role, "deliberative", 0.0),
            layer(&summary, role, "deliberative", 0.8),
        );
        let compute = number(loaded, "/compute_p50_ms/mean");
        assert!(compute >= 760.0, "{role}: deliberative compute p50 {compute} ms under 0.8 s");
        assert!(compute > number(free, "/compute_p50_ms/mean"));
        assert!(
            number(loaded, "/mean_hz/mean") < number(free, "/mean_hz/mean"),
            "{role}: the loaded deliberative layer is not slower: {loaded} vs {free}"
        );
    }

    // Both conditions' falls and walking were measured, and each target has a verdict.
    let conditions = summary["conditions"].as_array().expect("conditions");
    let loads: Vec<f64> = conditions.iter().map(|c| number(c, "/load_s")).collect();
    assert_eq!(loads, vec![0.0, 0.8]);
    for c in conditions {
        assert!(number(c, "/real_time_factor/mean") > 0.0, "{c}");
        assert!(c["falls_per_walking_min"]["events"].is_u64(), "{c}");
    }
    assert_eq!(summary["reactive"].as_array().map(Vec::len), Some(2));
    assert_eq!(summary["falls"].as_array().map(Vec::len), Some(1));
    assert!(summary["reactive_rate_kept"].is_boolean() && summary["falls_not_higher"].is_boolean());
    let walked: f64 = summary["robots"]
        .as_array()
        .expect("robots")
        .iter()
        .map(|r| number(r, "/path_m/mean"))
        .sum();
    assert!(walked > 0.5, "the robots hardly moved: {walked:.2} m in all");
    for robot in summary["robots"].as_array().expect("robots") {
        let pace = number(robot, "/window_frames_hz/mean");
        assert!(pace.is_finite() && pace > 0.0, "no server cycles measured: {robot}");
    }

    for file in [
        "report.md",
        "runs.csv",
        "robots.csv",
        "summary.json",
        "reactive_rate.png",
        "deliberative_rate.svg",
        "planning_rate.png",
    ] {
        assert!(out.join(file).is_file(), "{file} was not written");
    }
    let report = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    assert!(report.contains("## Targets") && report.contains("--engine rcssservermj"), "{report}");
    assert!(!out.join("team-load-0.8.toml").exists(), "the team files are cleaned up");
    let _ = std::fs::remove_dir_all(out.parent().unwrap_or(&out));
}
