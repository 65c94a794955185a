//! `strata match --log` end to end, in process: a short match is recorded and read back (the
//! same packages), cut short (the complete chunks are recovered), replayed (every module between
//! the platform's and the links' edges reproduces its outputs; a changed parameter lists
//! differences), and served by the viewer's data endpoints (they say what the log says).

mod view_support;

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use serde_json::Value;
use strata_games::logging::{BEHAVIOR_PATH_TOPIC, GAME_STATE_TOPIC, LogSettings};
use strata_games::replay_registry;
use strata_games::scene::plot::PLOT_TOPIC;
use strata_log::LogReader;
use strata_log::overrides::Override;
use strata_log::replay::{ReplayOptions, replay};
use strata_runtime::shared::Recorder;
use strata_runtime::{ErasedPackage, Tap, TapRecord};
use view_support::{get, get_json, record_match, scratch};

/// A delivered package: (topic, sequence, delivery time ns, stamp ns, the package).
type Delivered = (String, u64, u64, u64, Box<dyn ErasedPackage>);

/// Every package the host delivered, as the log should hold it.
#[derive(Default)]
struct Collect {
    packages: Mutex<Vec<Delivered>>,
}

impl Tap for Collect {
    fn package(&self, record: &TapRecord<'_>) {
        self.packages.lock().unwrap_or_else(PoisonError::into_inner).push((
            format!("{}/{}", record.sent_on.module_name, record.sent_on.output),
            record.package.seq(),
            record.time.as_nanos(),
            record.package.stamp().as_nanos(),
            record.package.clone_boxed(),
        ));
    }
}

fn is_record_topic(topic: &str) -> bool {
    topic == GAME_STATE_TOPIC
        || topic.ends_with(BEHAVIOR_PATH_TOPIC)
        || topic.starts_with("scene/")
        || topic == PLOT_TOPIC
}

#[test]
fn a_match_log_holds_every_package_and_survives_truncation() {
    let dir = scratch("match-log-roundtrip");
    let path = dir.join("match.mcap");
    let collect = Arc::new(Collect::default());
    record_match(&LogSettings::full(&path), 2, 5.0, 11, Some(collect.clone()));

    let reader = LogReader::open(&path).expect("open");
    assert!(reader.is_complete());
    assert_eq!(reader.stats().map(|s| s.dropped), Some(0));
    let mut logged = Vec::new();
    let mut records: BTreeMap<String, usize> = BTreeMap::new();
    let mut shared = 0;
    for message in reader.messages() {
        let m = message.expect("message");
        if is_record_topic(&m.topic) {
            *records.entry(m.topic.to_string()).or_default() += 1;
            continue;
        }
        if m.topic.starts_with("shared/") {
            shared += 1;
            continue;
        }
        logged.push(m);
    }
    // The world model's layout (one per team) and the multiplexers' goal lists.
    assert!(shared >= 2, "{shared} shared values");
    let mut sent =
        std::mem::take(&mut *collect.packages.lock().unwrap_or_else(PoisonError::into_inner));
    // The file is in the order the writer received the packages; compare per topic.
    sent.sort_by(|a, b| (&a.0, a.1).cmp(&(&b.0, b.1)));
    logged.sort_by(|a, b| (&*a.topic, a.seq).cmp(&(&*b.topic, b.seq)));
    assert_eq!(sent.len(), logged.len());
    // Each package encoded as the log did (in its channel's encoding, the shared values the
    // log holds as references) is the logged message, byte for byte.
    let previous = Recorder::knowing(strata_runtime::shared::registered_ids()).install();
    for (sent, logged) in sent.iter().zip(&logged) {
        let mut ours = Vec::new();
        sent.4.encode(logged.encoding, &mut ours).expect("serializable");
        let header = (sent.0.as_str(), sent.1, sent.2, sent.3);
        let theirs =
            (&*logged.topic, logged.seq, logged.log_time.as_nanos(), logged.stamp.as_nanos());
        assert_eq!(header, theirs);
        assert!(
            ours == logged.data,
            "{} #{}: the log differs from what the host delivered",
            sent.0,
            sent.1
        );
    }
    Recorder::uninstall();
    if let Some(previous) = previous {
        previous.install();
    }
    for topic in [
        "simulator/ground_truth",
        "home/1/world/world_state",
        "away/2/reactive/report",
        "home/2/deliberative/scores",
        "away/1/planning/decision",
    ] {
        assert!(logged.iter().any(|m| &*m.topic == topic), "nothing on {topic}");
    }
    // The game state and the behavior paths of every robot.
    assert!(records.get(GAME_STATE_TOPIC).is_some_and(|n| *n >= 2), "{records:?}");
    for robot in ["home/1", "home/2", "away/1", "away/2"] {
        assert!(records.contains_key(&format!("{robot}/{BEHAVIOR_PATH_TOPIC}")), "{records:?}");
    }
    // The scene Foxglove draws (docs/foxglove.md; checked with Foxglove's own schemas in
    // generic_tools.rs): the field once, the objects and frames ten times a second.
    assert_eq!(records.get("scene/field"), Some(&1), "{records:?}");
    let objects = records.get("scene/objects").copied().unwrap_or_default();
    assert!((45..=52).contains(&objects), "{objects} scene updates in 5 s");
    assert_eq!(records.get("scene/tf"), Some(&objects));
    let config = reader.config().expect("config").expect("a configuration");
    assert_eq!(config["players"], 2);
    assert!(config["world"]["home"]["objects"].is_array());

    // A killed process: the file cut in the middle keeps every complete chunk before the cut.
    let bytes = std::fs::read(&path).expect("read");
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 3 / 5]).expect("write");
    let cut = LogReader::open(&cut).expect("a truncated log opens");
    let recovery = cut.recovery().expect("recovered, not complete").clone();
    assert!(recovery.messages > 1000, "{recovery:?}");
    let full: Vec<_> = reader.messages().map(|m| m.expect("message")).collect();
    let recovered: Vec<_> = cut.messages().map(|m| m.expect("message")).collect();
    assert_eq!(recovered.len() as u64, recovery.messages);
    assert!(recovered.len() < full.len());
    assert!(
        recovered == full[..recovered.len()],
        "the recovered messages are the log's first ones"
    );
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

#[test]
fn logged_robots_can_be_chosen_and_the_world_state_decimated() {
    let dir = scratch("match-log-choice");
    let path = dir.join("choice.mcap");
    let settings = LogSettings {
        path: path.clone(),
        robots: vec!["home/2".to_owned()],
        world_state_hz: Some(5.0),
        ..LogSettings::full(&path)
    };
    record_match(&settings, 2, 4.0, 3, None);
    let reader = LogReader::open(&path).expect("open");
    let topics: Vec<&str> = reader.topics().iter().map(|t| t.name.as_str()).collect();
    assert!(
        topics.iter().all(|t| t.starts_with("home/2/")
            || t.starts_with("shared/")
            || *t == "simulator/ground_truth"
            || t.starts_with("simulator/home_2/")
            || t.starts_with("scene/")
            || *t == PLOT_TOPIC
            || *t == GAME_STATE_TOPIC),
        "{topics:?}"
    );
    // The chosen robot's platform is in, so its perception replays from this log.
    assert!(topics.contains(&"simulator/home_2/frames"), "{topics:?}");
    let world = reader.topic("home/2/world/world_state").expect("world state").messages;
    // 4 s at 5 Hz, give or take the first and last.
    assert!((14..=21).contains(&world), "{world} world states");
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

fn options(robot: &str, modules: &[&str], set: &[&str]) -> ReplayOptions {
    ReplayOptions {
        robot: Some(robot.to_owned()),
        modules: modules.iter().map(|m| (*m).to_owned()).collect(),
        overrides: set.iter().map(|s| Override::parse(s).expect("override")).collect(),
        max_differences: 5,
        ..ReplayOptions::default()
    }
}

#[test]
fn logged_modules_replay_identically_and_parameters_can_be_changed() {
    let dir = scratch("match-log-replay");
    let path = dir.join("replay.mcap");
    record_match(&LogSettings::full(&path), 2, 6.0, 5, None);
    let reader = LogReader::open(&path).expect("open");
    let registry = replay_registry::soccer();

    let report = replay(&reader, &registry, &options("home/2", &["world"], &[])).expect("replay");
    assert!(report.identical(), "{report}");
    assert!(report.warnings.is_empty(), "{report}");
    assert!(report.outputs[0].equal > 100, "{report}");
    assert_eq!(report.outputs[0].equal, report.outputs[0].logged);

    // Every module between the edges replays from what the log holds, each output it sent in
    // these 6 s but the referee's signals and placements.
    let quiet = ["perception/signals", "planning/world_commands"];
    for module in ["perception", "reactive", "deliberative", "actuation", "planning"] {
        let report =
            replay(&reader, &registry, &options("away/1", &[module], &[])).expect("replay");
        assert!(report.identical(), "{report}");
        for output in &report.outputs {
            let quiet = quiet.iter().any(|q| output.topic.ends_with(q));
            assert!(quiet || output.logged > 0, "{report}");
        }
    }

    // A noisier odometry model: the covariances the world model publishes change (the robot's
    // pose and every object predicted with the odometry).
    let set = ["world.home.odometry.translation_variance_per_metre=0.5"];
    let report = replay(&reader, &registry, &options("home/2", &["world"], &set)).expect("replay");
    assert!(!report.identical());
    assert_eq!(report.overrides, set);
    let details: Vec<&String> = report.differences.iter().flat_map(|d| &d.details).collect();
    assert!(details.iter().any(|d| d.contains("covariance")), "{report}");

    // What cannot be replayed says why; a mistyped key names what exists.
    let error = replay(&reader, &registry, &options("home/2", &["links_in"], &[]))
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(error.contains("cannot be replayed") && error.contains("edge"), "{error}");
    let error =
        replay(&reader, &registry, &options("home/2", &["world"], &["world.home.odometri.x=1"]))
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
    assert!(error.contains("odometri") && error.contains("odometry"), "{error}");
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

/// The newest ground truth at or before `t` in the log.
fn truth_at(path: &Path, t: f64) -> Value {
    let reader = LogReader::open(path).expect("open");
    let mut best = None;
    for m in reader.messages_on(["simulator/ground_truth"]) {
        let m = m.expect("message");
        if m.log_time.as_secs_f64() <= t + 1e-9 {
            best = Some(m.json().expect("json"));
        }
    }
    best.expect("ground truth before t")
}

#[test]
fn the_viewer_endpoints_say_what_the_log_says() {
    let dir = scratch("match-log-view");
    let path = dir.join("view.mcap");
    record_match(&LogSettings::full(&path), 2, 6.0, 9, None);
    let data = strata_view::load_log(&path).expect("load");
    assert!(strata_view::wait_loaded(&data, Duration::from_secs(120)), "the log was not read");
    let server = strata_view::ViewServer::start(data, 0).expect("serve");
    let base = server.url();

    let info = get_json(&format!("{base}api/info"));
    assert_eq!(info["source"], "log");
    assert_eq!(info["growing"], false);
    assert_eq!(info["robots"], serde_json::json!(["home/1", "home/2", "away/1", "away/2"]));
    assert_eq!(info["field"]["length"], 9.0);
    assert!(info["end"].as_f64().is_some_and(|end| end > 5.5));

    let t = 4.0;
    let frame = get_json(&format!("{base}api/frame?t={t}"));
    let truth = truth_at(&path, t);
    assert_eq!(frame["ball"]["x"], truth["ball"]["position"]["x"]);
    assert_eq!(frame["ball"]["y"], truth["ball"]["position"]["y"]);
    for robot in truth["robots"].as_array().expect("robots") {
        let name = format!(
            "{}/{}",
            if robot["id"]["team"] == 0 { "home" } else { "away" },
            robot["id"]["player"]
        );
        let shown = frame["robots"]
            .as_array()
            .and_then(|r| r.iter().find(|r| r["name"] == name.as_str()))
            .unwrap_or_else(|| panic!("{name} is not in the frame"));
        assert_eq!(shown["pose"], robot["pose"], "{name}");
        assert_eq!(shown["head_yaw"], robot["head"]["yaw"], "{name}");
        // Estimates, behaviors and roles are there once the robots have run a while.
        assert!(shown["estimate"].is_object(), "{name}: {shown}");
        assert!(shown["reactive_path"].as_str().is_some_and(|p| p.contains("head:")), "{shown}");
        assert!(shown["role"].is_string(), "{shown}");
    }

    let series = get_json(&format!("{base}api/series?robot=home%2F1&from=1&to=5&points=50"));
    assert_eq!(series["robot"], "home/1");
    let goals = series["goals"].as_array().expect("goals");
    assert!(goals.iter().any(|g| g["goal"] == "observe ball"), "{series}");
    for g in goals {
        let n = g["t"].as_array().map(Vec::len).unwrap_or(0);
        assert!(n > 0 && n <= 50);
        for key in ["deliberative", "reactive", "final"] {
            assert_eq!(g[key].as_array().map(Vec::len), Some(n));
        }
        assert!(
            g["t"]
                .as_array()
                .into_iter()
                .flatten()
                .all(|t| t.as_f64().is_some_and(|t| (1.0..=5.0).contains(&t)))
        );
    }
    let confidence = series["ball_confidence"].as_array().expect("confidence");
    assert!(!confidence.is_empty());
    assert!(confidence.iter().all(|c| c[1].as_f64().is_some_and(|v| (0.0..=1.0).contains(&v))));

    // The page and its errors.
    let (status, page) = get(&base.to_string());
    assert_eq!(status, 200);
    assert!(page.contains("viewer.js"));
    assert_eq!(get(&format!("{base}viewer.js")).0, 200);
    assert_eq!(get(&format!("{base}api/frame?t=soon")).0, 400);
    assert_eq!(get(&format!("{base}api/series")).0, 400);
    assert_eq!(get(&format!("{base}api/series?robot=home/9")).0, 404);
    assert_eq!(get(&format!("{base}nothing-here")).0, 404);
    drop(server);
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}
