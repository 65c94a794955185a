//! Every experiment in a seconds-long smoke configuration: it runs, and its report and JSON
//! summary hold every metric the issue names. Scenario errors name the file and the field.

use std::path::{Path, PathBuf};
use std::process::Command;

use strata_experiments::{self as experiments, Options};

fn temp_dir(name: &str) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("strata-experiments-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    dir
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).expect("writable");
    path
}

fn options(out: &Path, scenario: &Path) -> Options {
    Options {
        out: Some(out.to_path_buf()),
        scenario: Some(scenario.to_path_buf()),
        threads: 2,
        strata_exe: Some(PathBuf::from(env!("CARGO_BIN_EXE_strata"))),
        ..Options::default()
    }
}

fn assert_contains_all(what: &str, text: &str, needles: &[&str]) {
    for needle in needles {
        assert!(text.contains(needle), "{what} lacks `{needle}`:\n{text}");
    }
}

fn assert_files(dir: &Path, files: &[&str]) {
    for f in files {
        let path = dir.join(f);
        let len = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
        assert!(len > 0, "{} is missing or empty", path.display());
    }
}

const GOAL_COVERING: &str = r#"
field = "paper2010"
noise = "default"
runs = 1
ball_speed = 0.2
deliberative_hz = [1.0]
reactive_hz = 57.0
warmup = 1.0
settle = 0.5
sample_period = 0.05
keeper_start = [-2.55, 0.0, 0.0]
reference = "value-function"
target_pose_error = 0.10

[[methods]]
name = "value-function"
team = "full"

[[methods]]
name = "always-ball"
team = "always-ball"

[[trajectories]]
name = "across"
waypoints = [[-1.8, 0.2], [-1.8, -0.2]]

[[paper]]
deliberative_hz = 1.0
observe_ball = 0.285
ball_unknown = 0.190
target_ball_unknown = 0.05
"#;

#[test]
fn goal_covering_smoke_through_the_command_line() {
    let dir = temp_dir("goal-covering");
    let scenario = write(&dir, "scenario.toml", GOAL_COVERING);
    let out = dir.join("out");
    let output = Command::new(env!("CARGO_BIN_EXE_strata"))
        .args(["experiment", "goal-covering", "--json", "--seed", "3"])
        .arg("--scenario")
        .arg(&scenario)
        .arg("--out")
        .arg(&out)
        .output()
        .expect("strata runs");
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let stdout = String::from_utf8_lossy(&output.stdout);
    let json: serde_json::Value = serde_json::from_str(stdout.trim()).expect("one JSON object");
    let text = json.to_string();
    assert_contains_all(
        "the JSON summary",
        &text,
        &[
            "\"observe_ball\"",
            "\"ball_unknown\"",
            "\"pose_error_mean\"",
            "\"pose_error_p95\"",
            "\"coverage\"",
            "\"ci95\"",
            "\"targets\"",
            "\"covering_behavior\"",
        ],
    );
    assert_eq!(json["conditions"].as_array().map(Vec::len), Some(2), "two methods x one rate");
    // The reactive layer runs on every percept, at the sensor rate the scenario asks for.
    for condition in json["conditions"].as_array().into_iter().flatten() {
        let hz = condition["reactive_hz"]["mean"].as_f64().expect("a measured reactive rate");
        assert!((hz - 57.0).abs() < 0.5, "reactive layer at {hz} Hz, not the scenario's 57");
    }
    let report = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    assert_contains_all(
        "report.md",
        &report,
        &[
            "Table 5",
            "observe ball",
            "ball unknown",
            "pose error mean",
            "pose error p95",
            "goal coverage",
            "Fig. 5",
            "always-ball",
            "fig5_1hz.png",
            "Targets",
        ],
    );
    assert_files(
        &out,
        &[
            "runs.csv",
            "timeseries.csv",
            "summary.json",
            "fig5_1hz.png",
            "fig5_1hz.svg",
            "ball_unknown.png",
            "fig4_trajectories.svg",
        ],
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn goal_covering_is_deterministic_for_a_seed() {
    let dir = temp_dir("determinism");
    let scenario = write(&dir, "scenario.toml", GOAL_COVERING);
    let a = experiments::run("goal-covering", &options(&dir.join("a"), &scenario)).expect("runs");
    let b = experiments::run("goal-covering", &options(&dir.join("b"), &scenario)).expect("runs");
    assert_eq!(a.summary["conditions"], b.summary["conditions"]);
    let csv = |d: &str| std::fs::read_to_string(dir.join(d).join("runs.csv")).expect("csv");
    assert_eq!(csv("a"), csv("b"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn fall_smoke_on_the_lockstep_host() {
    let dir = temp_dir("fall");
    let scenario = write(
        &dir,
        "fall.toml",
        r#"
field = "paper2010"
noise = "default"
host = "lockstep"
runs = 1
falls_per_run = 2
concurrent = 2
team = "full"
first_fall = [1.5, 1.5]
wait_after_recovery = [0.5, 0.5]
recovery_timeout = 15.0
detection_window = 1.0
position_tolerance = 0.3
heading_tolerance = 0.6
directions = ["front", "back"]
sample_period = 0.01
keeper_start = [-2.55, 0.0, 0.0]
ball_path = [[-1.8, 0.3], [-1.8, -0.3]]
ball_speed = 0.2

[walking]
runs = 1
duration = 3.0
player = 2
team = "full"
start = [-1.5, 0.0, 0.0]
ball_path = [[-1.0, 0.5], [1.0, 0.5]]
ball_speed = 0.3

[paper]
detection_latency_ms = 51.0
back_in_position_s = 5.57
deliberative_period_ms = 600.0
"#,
    );
    let outcome = experiments::run("fall", &options(&dir.join("out"), &scenario)).expect("runs");
    let s = &outcome.summary;
    assert!(s["forced_falls"].as_u64() == Some(2), "{s}");
    assert!(s["detected"].as_u64().unwrap_or(0) >= 2, "every forced fall is detected: {s}");
    // Onset to command includes the simulated fall developing until the sensors show it; the
    // architecture's own share (percepts to command) is a reactive cycle or two.
    let median = s["detection_latency"]["median"].as_f64().expect("a median latency");
    assert!(median > 0.0 && median < 1.0, "latency {median} s");
    let sensing = s["sensing_to_command"]["median"].as_f64().expect("a sensing latency");
    assert!(sensing >= 0.0 && sensing < median, "percepts to command {sensing} s");
    assert_contains_all(
        "the JSON summary",
        &s.to_string(),
        &[
            "\"detection_latency\"",
            "\"median\"",
            "\"p95\"",
            "\"max\"",
            "\"standing_time\"",
            "\"back_in_position_time\"",
            "\"false_positives_per_hour\"",
            "\"false_positives_per_walking_hour\"",
            "\"deliberative_latency\"",
            "\"sensing_to_command\"",
        ],
    );
    let report = std::fs::read_to_string(dir.join("out/report.md")).expect("report.md");
    assert_contains_all(
        "report.md",
        &report,
        &[
            "fall detection latency",
            "onset to standing",
            "onset to proper playing position",
            "false positives",
            "per hour of walking",
            "51",
            "baseline: deliberative layer",
            "percepts taken to Fall command",
        ],
    );
    assert_files(
        &dir.join("out"),
        &["falls.csv", "runs.csv", "latency.png", "latency_cdf.svg", "recovery.png"],
    );
    let _ = std::fs::remove_dir_all(&dir);
}

const RATES: &str = r#"
transport = "TRANSPORT"
field = "spl"
noise = "default"
duration = 3.0
runs = 1
loads = [0.0, 0.05]
team = "full"
ball_reset_period = 2.0
tolerance = 0.5

[[robots]]
role = "goalkeeper"
player = 1
start = [-4.05, 0.0, 0.0]

[[robots]]
role = "striker"
player = 2
start = [-1.0, 0.0, 0.0]

[[paper]]
role = "goalkeeper"
layer = "reactive"
max_hz = 69.0
mean_hz = 54.0
min_hz = 42.0
"#;

fn check_rates(transport: &str) {
    let dir = temp_dir(&format!("rates-{transport}"));
    let scenario = write(&dir, "rates.toml", &RATES.replace("TRANSPORT", transport));
    let outcome = experiments::run("rates", &options(&dir.join("out"), &scenario)).expect("runs");
    let s = &outcome.summary;
    assert_contains_all(
        "the JSON summary",
        &s.to_string(),
        &[
            "\"min_hz\"",
            "\"mean_hz\"",
            "\"max_hz\"",
            "\"compute_p50_ms\"",
            "\"compute_p99_ms\"",
            "\"jitter_p99_ms\"",
            "\"claims\"",
            "\"reactive_rate_kept\"",
        ],
    );
    let layers = s["layers"].as_array().expect("layers");
    let reactive = layers
        .iter()
        .find(|l| l["layer"] == "reactive" && l["role"] == "goalkeeper" && l["load_s"] == 0.0)
        .expect("the keeper's reactive layer");
    let hz = reactive["mean_hz"]["mean"].as_f64().expect("a rate");
    assert!(hz > 20.0, "the reactive layer runs near the sensor rate, got {hz} Hz");
    let report = std::fs::read_to_string(dir.join("out/report.md")).expect("report.md");
    assert_contains_all(
        "report.md",
        &report,
        &[
            "Table 6",
            "max Hz",
            "mean Hz",
            "min Hz",
            "compute p50",
            "jitter",
            "reactive rate does not drop",
        ],
    );
    assert_files(&dir.join("out"), &["runs.csv", "reactive_rate.png", "deliberative_rate.svg"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn rates_smoke_in_process() {
    check_rates("in-process");
}

#[test]
fn rates_smoke_over_tcp_with_robot_processes() {
    check_rates("tcp");
}

#[test]
fn team_smoke() {
    let dir = temp_dir("team");
    let scenario = write(
        &dir,
        "team.toml",
        r#"
field = "spl"
noise = "default"
half_duration = 15.0
runs = 1
players = [2]
reference = "full"
baselines = ["no-coordination"]

[loss]
levels = [0.0, 1.0]
players = [2]
runs = 1
team = "full"
"#,
    );
    let outcome = experiments::run("team", &options(&dir.join("out"), &scenario)).expect("runs");
    let s = &outcome.summary;
    assert_contains_all(
        "the JSON summary",
        &s.to_string(),
        &[
            "\"wins\"",
            "\"draws\"",
            "\"losses\"",
            "\"goal_difference\"",
            "\"strikers_histogram\"",
            "\"double_striker_s\"",
            "\"role_switches_per_minute\"",
            "\"budget_used\"",
            "\"messages_sent\"",
        ],
    );
    assert_eq!(s["loss"].as_array().map(Vec::len), Some(2));
    let report = std::fs::read_to_string(dir.join("out/report.md")).expect("report.md");
    assert_contains_all(
        "report.md",
        &report,
        &["W / D / L", "goal difference", "strikers", "double-striker", "role switches", "budget"],
    );
    assert_files(&dir.join("out"), &["matches.csv", "strikers_histogram.png", "goals.svg"]);
    let _ = std::fs::remove_dir_all(&dir);
}

/// One game of 60-second halves with GameController3's timing and the referee's signals, and
/// its `--no-delay` baseline.
#[test]
fn referee_smoke() {
    let dir = temp_dir("referee");
    let scenario = write(
        &dir,
        "referee.toml",
        r#"
half_duration = 60.0
runs = 1
players = 7
baseline_runs = 1
"#,
    );
    let outcome = experiments::run("referee", &options(&dir.join("out"), &scenario)).expect("runs");
    let s = &outcome.summary;
    // A game has a Ready phase and a kick-off in each half, at least.
    assert!(s["ready"]["phases"].as_u64().unwrap_or(0) >= 2, "{s}");
    assert!(s["kick_offs"]["kick_offs"].as_u64().unwrap_or(0) >= 2, "{s}");
    assert_eq!(s["runs"].as_u64(), Some(1));
    assert_contains_all(
        "the JSON summary",
        &s.to_string(),
        &[
            "\"phase_rate\"",
            "\"robot_rate\"",
            "\"not_before_packets\"",
            "\"median\"",
            "\"p95\"",
            "\"false_whistles_in_set\"",
            "\"episodes\"",
            "\"real_time\"",
            "\"ratio\"",
            "\"targets\"",
        ],
    );
    let report = std::fs::read_to_string(dir.join("out/report.md")).expect("report.md");
    assert_contains_all(
        "report.md",
        &report,
        &[
            "## Targets",
            "## Ready phases",
            "## Kick-off starts",
            "## False starts",
            "## Real-time factor",
            "## Games",
            "Machine load",
            "Command: `strata experiment referee",
            "kick_off_delays.png",
            "--no-delay",
        ],
    );
    let csv = std::fs::read_to_string(dir.join("out/phases.csv")).expect("phases.csv");
    let header = csv.lines().next().unwrap_or_default();
    for column in [
        "mode",
        "seed",
        "kind",
        "half",
        "robots",
        "robots_ok",
        "all_ok",
        "worst",
        "median_delay_s",
        "not_before_packets",
    ] {
        assert!(header.split(',').any(|c| c == column), "phases.csv lacks `{column}`: {header}");
    }
    assert!(csv.lines().any(|l| l.starts_with("signals,0,1,ready,")), "{csv}");
    assert!(csv.lines().any(|l| l.starts_with("signals,0,1,kick_off,")), "{csv}");
    assert!(csv.lines().any(|l| l.starts_with("no-delay,0,1,")), "{csv}");
    assert_files(
        &dir.join("out"),
        &[
            "robots.csv",
            "summary.json",
            "kick_off_delays.png",
            "kick_off_delays.svg",
            "ready_distances.png",
        ],
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_bad_scenario_names_the_file_and_the_field() {
    let dir = temp_dir("bad");
    let run = |text: &str| {
        let path = write(&dir, "bad.toml", text);
        let error = experiments::run("goal-covering", &options(&dir.join("out"), &path))
            .expect_err("a bad scenario");
        (format!("{error:#}"), path.display().to_string())
    };
    let (e, path) = run(&GOAL_COVERING.replace("ball_speed = 0.2", "ball_speed = \"fast\""));
    assert!(e.contains(&path) && e.contains("ball_speed"), "{e}");
    let (e, path) =
        run(&GOAL_COVERING.replace("deliberative_hz = [1.0]", "deliberative_hz = [-1.0]"));
    assert!(e.contains(&path) && e.contains("deliberative_hz[0]") && e.contains("> 0"), "{e}");
    let (e, _) = run(&GOAL_COVERING.replace("runs = 1", "runs = 1\nspeeed = 2.0"));
    assert!(e.contains("speeed"), "{e}");
    let (e, _) = run(&GOAL_COVERING.replace("team = \"always-ball\"", "team = \"nobody\""));
    assert!(e.contains("methods[1].team") && e.contains("nobody"), "{e}");
    let (e, _) = run(&GOAL_COVERING
        .replace("waypoints = [[-1.8, 0.2], [-1.8, -0.2]]", "waypoints = [[-1.8, 0.2]]"));
    assert!(e.contains("trajectories[0].waypoints"), "{e}");
    let missing =
        experiments::run("goal-covering", &options(&dir.join("out"), &dir.join("absent.toml")))
            .expect_err("no such file");
    assert!(format!("{missing:#}").contains("absent.toml"), "{missing:#}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn every_built_in_scenario_loads() {
    for (name, text) in [
        ("goal-covering", experiments::goal_covering::DEFAULT_SCENARIO),
        ("rates", experiments::rates::DEFAULT_SCENARIO),
        ("fall", experiments::fall::DEFAULT_SCENARIO),
        ("team", experiments::team::DEFAULT_SCENARIO),
        ("referee", experiments::referee::DEFAULT_SCENARIO),
    ] {
        let on_disk = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../experiments/scenarios")
                .join(format!("{name}.toml")),
        )
        .expect("shipped");
        assert_eq!(on_disk, text, "{name}: the embedded scenario is the shipped file");
    }
    let error = experiments::run("no-such", &Options::default()).expect_err("unknown experiment");
    assert!(error.to_string().contains("goal-covering"), "{error}");
}

/// `--log`: the first run of an experiment is recorded, complete, with its graph and seed; the
/// team experiment's is a match log (robots, ground truth, game state).
#[test]
fn an_experiments_first_run_can_be_logged() {
    let dir = temp_dir("log");
    let scenario = write(&dir, "scenario.toml", GOAL_COVERING);
    let log = dir.join("goal-covering.mcap");
    let output = Command::new(env!("CARGO_BIN_EXE_strata"))
        .args(["experiment", "goal-covering", "--json", "--seed", "3"])
        .arg("--scenario")
        .arg(&scenario)
        .arg("--out")
        .arg(dir.join("out"))
        .arg("--log")
        .arg(&log)
        .output()
        .expect("strata runs");
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let reader = strata_log::LogReader::open(&log).expect("the log opens");
    assert!(reader.is_complete());
    assert_eq!(reader.run_info().expect("run info").map(|r| r.seed), Some(3));
    let world = reader.topic("home/1/world/world_state").expect("the keeper's world state");
    assert!(world.messages > 0);
    // Each layer's active behavior path, as a match log has it.
    let path = reader.topic("home/1/behavior_path").expect("the keeper's behavior paths");
    assert!(path.messages > 0);
    // The log holds what the keeper was built from: its layers replay exactly (lockstep).
    let registry = strata_games::replay_registry::soccer();
    for module in ["world", "deliberative", "reactive"] {
        let replay = strata_log::replay::ReplayOptions {
            robot: Some("home/1".to_owned()),
            modules: vec![module.to_owned()],
            max_differences: 3,
            ..strata_log::replay::ReplayOptions::default()
        };
        let report = strata_log::replay::replay(&reader, &registry, &replay)
            .unwrap_or_else(|e| panic!("{module} replays: {e}"));
        assert!(report.identical(), "{module}: {report}");
        assert!(report.outputs.iter().all(|o| o.logged > 0), "{module}: {:?}", report.outputs);
    }
    let absent = strata_log::replay::ReplayOptions {
        robot: Some("home/4".to_owned()),
        modules: vec!["world".to_owned()],
        ..strata_log::replay::ReplayOptions::default()
    };
    let error =
        strata_log::replay::replay(&reader, &registry, &absent).err().map(|e| e.to_string());
    assert!(error.as_deref().is_some_and(|e| e.contains("home/4")), "{error:?}");

    let team = write(
        &dir,
        "team.toml",
        r#"
field = "spl"
noise = "default"
half_duration = 5.0
runs = 1
players = [2]
reference = "full"
baselines = ["no-coordination"]

[loss]
levels = []
players = [2]
runs = 1
team = "full"
"#,
    );
    let match_log = dir.join("team.mcap");
    let options = Options { log: Some(match_log.clone()), ..options(&dir.join("team"), &team) };
    experiments::run("team", &options).expect("runs");
    let reader = strata_log::LogReader::open(&match_log).expect("the match log opens");
    assert!(reader.is_complete());
    for topic in ["simulator/ground_truth", "game/state", "away/2/planning/decision"] {
        assert!(reader.topic(topic).is_some_and(|t| t.messages > 0), "{topic}");
    }
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}
