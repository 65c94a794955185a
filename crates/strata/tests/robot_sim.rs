//! The simulator over TCP, end to end (the simulator issue's "done when"): `strata server`
//! runs; two `strata robot` processes running the full soccer robot connect to it, receive
//! sensor frames and the game state from its referee, and exchange team messages through it;
//! a third runs the test controller. Everything stops cleanly on Ctrl-C.
//!
//! Nothing asserts how long anything took: every step waits for its condition.

mod common;

use common::{Process, start_server, strata};

fn soccer_robot(addr: &str, team: u8, player: u8) -> Process {
    Process::spawn(
        &format!("robot {team}/{player}"),
        strata().args(["robot", "--server", addr, "--json", "--status-interval", "1"]).args([
            "--team".to_owned(),
            team.to_string(),
            "--player".to_owned(),
            player.to_string(),
            // A safety net if the test itself is killed; it ends them with Ctrl-C.
            "--duration".to_owned(),
            "900".to_owned(),
        ]),
    )
}

fn count(status: &serde_json::Value, key: &str) -> u64 {
    status[key].as_u64().unwrap_or(0)
}

#[test]
fn soccer_robots_run_against_the_simulator_server() {
    let (mut server, addr) = start_server(&[]);
    let mut robots = [soccer_robot(&addr, 10, 1), soccer_robot(&addr, 10, 2)];
    let mut tester = Process::spawn(
        "test controller 20/1",
        strata().args([
            "robot",
            "--controller",
            "test",
            "--server",
            &addr,
            "--team",
            "20",
            "--player",
            "1",
            "--status-interval",
            "1",
            "--duration",
            "900",
        ]),
    );

    for robot in &mut robots {
        let start = robot.wait_for("the start line", |p| p.json_of("start").into_iter().next());
        assert_eq!(start["controller"], "soccer");
        assert_eq!(start["game_controller"], "simulator server");
        // Sensor frames, camera images and the referee's game state arrive; a teammate's
        // message comes through the server.
        robot.wait_for("sensors, game state and a teammate", |p| {
            p.json_of("status")
                .into_iter()
                .find(|s| {
                    count(s, "sensor_frames") > 0
                        && count(s, "camera_frames") > 0
                        && s["game_state"].is_string()
                        && count(s, "messages_received") > 0
                })
                .map(|_| ())
        });
    }
    tester.wait_for("the test controller's frames", |p| {
        p.lines()
            .iter()
            .filter_map(|l| l.split("frames=").nth(1))
            .filter_map(|rest| rest.split_whitespace().next()?.parse::<u64>().ok())
            .any(|frames| frames > 0)
            .then_some(())
    });
    server.wait_for("the server to count three robots", |p| {
        p.lines().iter().any(|l| l.contains("robots= 3")).then_some(())
    });

    for robot in &mut robots {
        let status = robot.interrupt();
        assert!(status.success(), "{} exited with {status}: {}", robot.name, robot.stderr());
        let report = robot.json_of("report").pop().unwrap_or_else(|| {
            panic!("{}: no report\n{}\n{}", robot.name, robot.lines().join("\n"), robot.stderr())
        });
        assert_eq!(report["ended"], "interrupted");
        assert!(count(&report, "sensor_frames") > 0);
        assert!(report["game_states"].as_array().is_some_and(|s| !s.is_empty()), "{report}");
        assert!(count(&report["game_controller_link"], "received") > 0, "{report}");
        assert!(count(&report["game_controller_link"], "sent") > 0, "return packets: {report}");
        assert!(count(&report["planning"], "received") > 0, "{report}");
        let layers: Vec<&str> = report["layers"]
            .as_array()
            .map(|l| l.iter().filter_map(|l| l["layer"].as_str()).collect())
            .unwrap_or_default();
        assert_eq!(layers, ["planning", "deliberative", "reactive"]);
        for layer in report["layers"].as_array().into_iter().flatten() {
            assert!(count(layer, "cycles") > 0, "{layer}");
        }
        // Perception, world modeling and actuation ran too, and the four edge modules (the
        // platform's sensors and actuators, the links' source and sink): ten modules.
        let modules: Vec<&str> = report["host"]["modules"]
            .as_array()
            .map(|m| m.iter().filter_map(|m| m["name"].as_str()).collect())
            .unwrap_or_default();
        assert_eq!(modules.len(), 10, "{report}");
        for edge in ["sensors", "actuators", "links_in", "links_out"] {
            assert!(modules.iter().any(|m| m.ends_with(edge)), "{edge}: {modules:?}");
        }
    }
    assert!(tester.interrupt().success(), "{}", tester.stderr());
    let status = server.interrupt();
    assert_eq!(status.code(), Some(0), "{}", server.stderr());
    assert!(server.lines().iter().any(|l| l == "strata server stopped"));
}

/// A robot whose server goes away ends its run with a report instead of failing.
#[test]
fn a_robot_ends_cleanly_when_the_server_stops() {
    let (mut server, addr) = start_server(&[]);
    let mut robot = soccer_robot(&addr, 20, 3);
    robot.wait_for("sensor frames", |p| {
        p.json_of("status").iter().any(|s| count(s, "sensor_frames") > 0).then_some(())
    });
    assert_eq!(server.interrupt().code(), Some(0));
    let status = robot.wait_exit();
    assert!(status.success(), "{} exited with {status}: {}", robot.name, robot.stderr());
    let report = robot.wait_for("the report", |p| p.json_of("report").pop());
    assert!(
        report["ended"].as_str().is_some_and(|e| e.starts_with("platform disconnected")),
        "{report}"
    );
}

/// `strata robot --log`: Ctrl-C finishes the file, which holds the robot's packages, its graph
/// and its run.
#[test]
fn a_robot_logs_its_packages_and_finishes_the_log_on_ctrl_c() {
    let dir = std::env::temp_dir().join(format!("strata-robot-log-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("robot.mcap");
    let (mut server, addr) = start_server(&[]);
    let mut robot = Process::spawn(
        "robot 10/3 (logging)",
        strata().args(["robot", "--server", &addr, "--json", "--status-interval", "1"]).args([
            "--team",
            "10",
            "--player",
            "3",
            "--seed",
            "77",
            "--duration",
            "900",
            "--log",
            path.to_str().expect("utf-8 path"),
        ]),
    );
    robot.wait_for("camera frames", |p| {
        p.json_of("status").iter().any(|s| count(s, "camera_frames") > 0).then_some(())
    });
    let status = robot.interrupt();
    assert!(status.success(), "{} exited with {status}: {}", robot.name, robot.stderr());
    assert_eq!(server.interrupt().code(), Some(0));
    let note =
        robot.json_of("note").into_iter().find_map(|n| n["text"].as_str().map(str::to_owned));
    assert!(note.as_deref().is_some_and(|n| n.starts_with("log: ")), "{note:?}");

    let reader = strata_log::LogReader::open(&path).expect("the log opens");
    assert!(reader.is_complete(), "Ctrl-C finishes the file");
    for topic in ["t10/3/perception/percepts", "t10/3/world/world_state", "t10/3/reactive/report"] {
        let info = reader.topic(topic).unwrap_or_else(|| panic!("no topic {topic}"));
        assert!(info.messages > 0, "{topic}");
        assert_eq!(info.message_encoding, "cdr");
    }
    let world = reader
        .messages_on(["t10/3/world/world_state"])
        .next()
        .expect("a world state")
        .expect("readable");
    assert!(world.json().expect("decodes")["objects"].is_array());
    // Each layer's active behavior path, derived from the layers' packages as in a match log.
    let behavior = reader
        .messages_on(["t10/3/behavior_path"])
        .next()
        .expect("a behavior path")
        .expect("readable");
    let behavior = behavior.json().expect("decodes");
    assert!(behavior["reactive"].as_str().is_some_and(|p| !p.is_empty()), "{behavior}");
    assert_eq!(reader.run_info().expect("run info").map(|r| r.seed), Some(77));
    let graphs = reader.graphs().expect("graphs");
    assert_eq!(graphs.len(), 1);
    assert_eq!(graphs[0].description.modules.len(), 10);

    // The viewer shows a robot's log too: no ground truth, the robot where it believes it is.
    let view = strata_view::load_log(&path).expect("the viewer opens the log");
    let info = loop {
        let info = view.read().unwrap_or_else(std::sync::PoisonError::into_inner).info();
        if !info.growing {
            break info;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    assert_eq!(info.robots, vec!["t10/3".to_owned()], "{:?}", info.warnings);
    assert!(
        info.warnings.is_empty(),
        "the field and camera come from the log: {:?}",
        info.warnings
    );
    assert!(info.end > info.start, "a timeline: {} .. {}", info.start, info.end);
    assert!(!info.warnings.iter().any(|w| w.contains("could not be read")), "{:?}", info.warnings);
    let frame = view.read().unwrap_or_else(std::sync::PoisonError::into_inner).frame(None);
    assert!(frame.robots[0].estimate.is_some(), "the robot's estimated pose is drawn");

    // Replay rebuilds the robot's world model from the configuration in its log. How cycles
    // batched percepts in real time decides how many packages match, so only that the
    // comparison ran, without publication times, is asserted here.
    let options = strata_log::replay::ReplayOptions {
        robot: Some("t10/3".to_owned()),
        modules: vec!["world".to_owned()],
        max_differences: 5,
        ignore_time: true,
        ..strata_log::replay::ReplayOptions::default()
    };
    let report =
        strata_log::replay::replay(&reader, &strata_games::replay_registry::soccer(), &options)
            .expect("the robot's world model replays from its log");
    let world = &report.outputs[0];
    assert_eq!(world.topic, "t10/3/world/world_state");
    assert!(world.logged > 0 && world.replayed > 0, "{world:?}");
    assert!(
        report.differences.iter().all(|d| d.details.iter().all(|x| !x.starts_with("time:"))),
        "{:?}",
        report.differences
    );
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}
