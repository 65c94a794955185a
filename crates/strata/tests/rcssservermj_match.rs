//! `strata match --engine rcssservermj` as a user runs it: a short game of T1s against the real
//! server, both halves, and the same report as a 2D match with the physics section.
//!
//! Needs the server (`scripts/setup-rcssservermj`); without it the game test says so and
//! passes, unless `STRATA_REQUIRE_RCSSSERVERMJ` is set (as `scripts/test` does). The physics is
//! not bit-for-bit repeatable: the test asserts what any game must show, not a score.

mod common;

use common::cli::{physics_experiment, rcssservermj_installed, run, stderr, strata};

#[test]
fn a_short_game_plays_both_halves_and_reports_like_a_2d_match() {
    if !rcssservermj_installed() {
        return;
    }
    let output = run(&mut strata(&[
        "match",
        "--engine",
        "rcssservermj",
        "--players",
        "1",
        "--half",
        "12",
        "--seed",
        "3",
        "--json",
    ]));
    assert!(output.status.success(), "the game failed: {}", stderr(&output));
    let report: serde_json::Value =
        serde_json::from_slice(&output.stdout).expect("--json prints one JSON object");
    println!("{report:#}");
    assert_eq!(report["finished"], true, "the referee ended both halves");
    let physics = &report["physics"];
    let halves = physics["halves"].as_array().expect("halves");
    assert_eq!(halves.len(), 2);
    // The teams change ends: each is on the server's left for one half.
    let lefts: Vec<&str> = halves.iter().filter_map(|h| h["left"].as_str()).collect();
    assert_eq!(lefts, ["full (home)", "full (away)"]);
    for half in halves {
        assert!(half["play_s"].as_f64().is_some_and(|s| s >= 11.0), "{half}");
    }
    let kick_offs = report["events"]
        .as_array()
        .expect("events")
        .iter()
        .filter(|e| e["kind"] == "kick-off")
        .count();
    assert_eq!(kick_offs, 2, "one kick-off per half");

    let robots = report["robots"].as_array().expect("robots");
    assert_eq!(robots.len(), 2);
    for robot in robots {
        for layer in ["planning", "deliberative", "reactive"] {
            let rate = robot["layers"]
                .as_array()
                .and_then(|ls| ls.iter().find(|l| l["layer"] == layer))
                .unwrap_or_else(|| panic!("{layer} layer of {}", robot["name"]));
            assert!(rate["cycles"].as_u64().is_some_and(|c| c > 0), "{rate}");
            assert!(rate["mean_hz"].as_f64().is_some_and(|hz| hz > 0.0), "{rate}");
        }
        assert!(robot["roles"]["goalie"].as_f64().is_some_and(|share| share > 0.9), "{robot}");
    }
    for robot in physics["robots"].as_array().expect("physics robots") {
        assert!(robot["cpu_s"].as_f64().is_some_and(|s| s > 0.0), "{robot}");
        // Each half's process knew where it stood, whichever end its team defended: believing
        // itself at the other end would be about 9 m off. The bound leaves room for what the
        // real-time server does not repeat: a keeper that fell in a 12-second half averaged
        // 1.2-1.3 m in 2 of 3 runs on a loaded 2-core machine (2026-11-28).
        let errors = robot["localization_mean_m"].as_array().expect("localization");
        assert_eq!(errors.len(), 2, "{robot}");
        for error in errors {
            assert!(error.as_f64().is_some_and(|m| m < 2.0), "{robot}");
        }
        assert!(robot["ended"].as_array().is_some_and(|e| e.len() == 2), "{robot}");
    }
    let cpu = &physics["cpu"];
    assert!(cpu["server_s"].as_f64().is_some_and(|s| s > 0.0), "{cpu}");
    assert!(cpu["strata_share"].as_f64().is_some_and(|s| s > 0.0 && s < 1.0), "{cpu}");
    assert!(report["team_messages"]["sent"].as_u64().is_some_and(|n| n > 0));
}

#[test]
fn options_of_the_built_in_simulator_are_refused_with_the_option_named() {
    for (args, needle) in [
        (&["--noise", "high"][..], "--noise"),
        (&["--view"][..], "--view"),
        (&["--players", "8"][..], "--players"),
        (&["--half", "400"][..], "--half"),
    ] {
        let mut all = vec!["match", "--engine", "rcssservermj"];
        all.extend_from_slice(args);
        let output = run(&mut strata(&all));
        assert!(!output.status.success(), "{args:?} was accepted");
        let text = stderr(&output);
        assert!(text.contains(needle), "{args:?}: {text}");
    }
}

#[test]
fn the_team_experiment_plays_its_games_in_physics_beside_the_2d_ones() {
    if !rcssservermj_installed() {
        return;
    }
    let (out, summary) = physics_experiment(
        "team",
        "players = 1\nhalf = 8.0\nruns = 1\nreference = \"full\"\n\
         baseline = \"no-coordination\"\nfield_2d = \"spl\"\n",
        &[],
    );
    println!("{summary:#}");
    let games = summary["games"].as_array().expect("games");
    assert_eq!(games.len(), 1);
    assert_eq!(games[0]["finished"], true);
    assert!(games[0]["goals_2d"].as_array().is_some_and(|g| g.len() == 2));
    assert_eq!(summary["targets"]["games_finished"], true);
    for file in ["report.md", "games.csv", "goal-difference.png", "summary.json"] {
        assert!(out.join(file).is_file(), "{file} written");
    }
    let report = std::fs::read_to_string(out.join("report.md")).expect("the report");
    assert!(report.contains("--engine rcssservermj"), "the report's command names the engine");
}

#[test]
fn a_physics_scenario_with_a_bad_value_names_the_file_and_the_field() {
    let dir = common::cli::temp_dir("team-3d-bad");
    let scenario = dir.join("team.toml");
    std::fs::write(
        &scenario,
        "players = 9\nhalf = 8.0\nruns = 1\nreference = \"full\"\n\
         baseline = \"no-coordination\"\nfield_2d = \"spl\"\n",
    )
    .expect("a scenario file");
    let output = run(&mut strata(&[
        "experiment",
        "team",
        "--engine",
        "rcssservermj",
        "--scenario",
        scenario.to_str().expect("a UTF-8 path"),
        "--out",
        dir.join("out").to_str().expect("a UTF-8 path"),
    ]));
    assert!(!output.status.success());
    let text = stderr(&output);
    assert!(text.contains("team.toml") && text.contains("players"), "{text}");
}

#[test]
fn team_messages_over_udp_alone_are_for_the_physics_platform() {
    for (args, needle) in [
        (&["--platform", "sim", "--team-udp"][..], "--team-udp"),
        (&["--platform", "nao", "--team-udp"][..], "--team-udp"),
        // The GameController's ports mean nothing while the server's referee rules.
        (&["--platform", "rcssservermj", "--team-udp", "--gc-port", "4000"][..], "--gc-port"),
        (&["--platform", "rcssservermj", "--team-port", "12000"][..], "--team-udp"),
    ] {
        let mut all = vec!["robot", "--team", "1", "--player", "2"];
        all.extend_from_slice(args);
        let output = run(&mut strata(&all));
        assert!(!output.status.success(), "{args:?} was accepted");
        let text = stderr(&output);
        assert!(text.contains(needle), "{args:?}: {text}");
    }
}

/// The processes whose parent is `parent`, from /proc.
fn children_of(parent: u32) -> Vec<u32> {
    let Ok(entries) = std::fs::read_dir("/proc") else { return Vec::new() };
    entries
        .filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok())
        .filter(|pid| {
            std::fs::read_to_string(format!("/proc/{pid}/stat")).ok().is_some_and(|stat| {
                // The fields after the command name, which is in parentheses: state, ppid, ...
                let after = stat.rsplit_once(')').map_or("", |(_, rest)| rest);
                after.split_whitespace().nth(1) == Some(&parent.to_string())
            })
        })
        .collect()
}

/// Running: neither gone nor a zombie waiting to be reaped.
fn running(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat")).ok().is_some_and(|stat| {
        let after = stat.rsplit_once(')').map_or("", |(_, rest)| rest);
        after.split_whitespace().next().is_some_and(|state| state != "Z" && state != "X")
    })
}

#[test]
fn sigterm_stops_a_physics_game_with_its_server_and_robots() {
    if !rcssservermj_installed() {
        return;
    }
    let game = strata(&["match", "--engine", "rcssservermj", "--players", "1", "--half", "60"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("strata starts");
    // The server and both robots.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
    let children = loop {
        let children = children_of(game.id());
        if children.len() >= 3 || std::time::Instant::now() > deadline {
            break children;
        }
        std::thread::sleep(std::time::Duration::from_millis(200));
    };
    assert!(children.len() >= 3, "the server and two robots started: {children:?}");
    let pid = nix::unistd::Pid::from_raw(i32::try_from(game.id()).expect("a pid"));
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).expect("SIGTERM sent");
    let output = game.wait_with_output().expect("strata ends");
    let text = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "an interrupted game is not a finished one: {text}");
    assert!(text.contains("interrupted"), "the error says why: {text}");
    let left: Vec<u32> = children.into_iter().filter(|&c| running(c)).collect();
    assert!(left.is_empty(), "processes left running: {left:?}");
}
