//! `strata chaos` in its short form, as CI runs it: a 3 vs 3 real-time game of robot processes
//! with every fault injected once (fewer garbage datagrams and connection attempts than the
//! full run, shorter phases). It asserts what the faults must lead to — no panic, every
//! process alive at the end but the killed one (which was restarted and rejoined), its role
//! taken over, every refusal clean, every garbage datagram counted, the full log reported and
//! the robot playing on, no log record lost — never a timing figure: real-time rates and the
//! real-time factor depend on the machine, and the report says whether they met their
//! targets.

mod common;

use common::cli::{run, stderr, strata, temp_dir};
use serde_json::Value;

const DATAGRAMS: u64 = 10_000;
const ATTEMPTS: u64 = 200;

fn number(value: &Value, what: &str) -> u64 {
    value.as_u64().unwrap_or_else(|| panic!("{what}: {value} is no count"))
}

#[test]
fn a_game_survives_every_fault_of_the_chaos_run() {
    let out = temp_dir("chaos");
    let output = run(&mut strata(&[
        "-q",
        "chaos",
        "--duration",
        "4",
        "--slow-client",
        "4",
        "--datagrams",
        &DATAGRAMS.to_string(),
        "--connection-attempts",
        &ATTEMPTS.to_string(),
        "--out",
        out.to_str().expect("a UTF-8 path"),
        "--json",
    ]));
    assert!(output.status.success(), "the chaos run failed: {}", stderr(&output));
    let report: Value = serde_json::from_slice(&output.stdout).expect("--json prints one object");
    // Shown when the test fails (or with --nocapture).
    eprintln!("{report:#}");
    for file in ["summary.json", "report.md", "phases.csv", "checks.csv", "memory.csv"] {
        assert!(out.join(file).is_file(), "{file} is written");
    }

    // No panic anywhere, and every robot process ran until the end and stopped on Ctrl-C, but
    // the killed one, which was started again.
    assert_eq!(report["server_panics"], 0);
    assert!(report["server_stop_error"].is_null(), "{}", report["server_stop_error"]);
    let processes = report["processes"].as_array().expect("processes");
    assert_eq!(processes.len(), 7, "six robots and the restarted one");
    for p in processes {
        assert_eq!(p["panics"], 0, "{p}");
        assert_eq!(p["ran_to_the_end"], true, "{p}");
        assert_eq!(p["killed_at_the_end"], false, "{p}");
    }
    assert_eq!(
        processes
            .iter()
            .filter(|p| p["process"].as_str().is_some_and(|n| n.contains("restart")))
            .count(),
        1
    );
    assert!(
        processes.iter().any(|p| p["status"]
            .as_str()
            .is_some_and(|s| s.contains("SIGKILL") || s.contains("signal: 9"))),
        "one process was killed by the fault: {processes:?}"
    );

    // kill -9: a teammate noticed, took over the ball-playing role, and the robot came back.
    let takeover = &report["takeover"];
    assert!(takeover["noticed_s"].is_number(), "{takeover}");
    assert!(takeover["taken_over_s"].is_number(), "{takeover}");
    assert!(takeover["rejoined_s"].is_number(), "{takeover}");
    assert_ne!(takeover["taken_over_by"], takeover["robot"], "{takeover}");

    // SIGSTOP: the robot went on, still in the game.
    let stopped = &report["stopped"];
    assert!(stopped["resumed_s"].is_number(), "{stopped}");
    assert_eq!(stopped["in_game"], true, "{stopped}");

    // The slow client was let in (and the game went on: the checks below).
    assert_eq!(report["slow_client"]["admitted"], true, "{}", report["slow_client"]);

    // Connection attempts: most refused over the cap at once, the rest at the handshake
    // deadline, each with an error frame and a clean close, each counted by the server.
    let c = &report["connections"];
    let over_cap = number(&c["refused_over_cap"], "refused over the cap");
    let timeouts = number(&c["handshake_timeouts"], "handshake timeouts");
    assert_eq!(over_cap + timeouts, ATTEMPTS, "{c}");
    assert!(over_cap > timeouts, "most attempts are refused by the cap: {c}");
    assert_eq!(c["unclean"], 0, "{c}");
    assert_eq!(c["connect_failed"], 0, "{c}");
    assert_eq!(number(&c["server_refused"], "server refusals"), ATTEMPTS, "{c}");

    // Garbage: all sent, every datagram counted by a robot or dropped (and counted) by the
    // kernel; the GameController port is one robot's, the team port the team's three.
    let ports = report["garbage"]["ports"].as_array().expect("garbage ports");
    assert_eq!(ports.len(), 2);
    for (port, sockets) in ports.iter().zip([1, 3]) {
        assert_eq!(number(&port["sent"], "sent"), DATAGRAMS, "{port}");
        assert_eq!(port["send_errors"], 0, "{port}");
        assert_eq!(port["sockets"], sockets, "{port}");
        let delivered = DATAGRAMS * sockets;
        let counted = number(&port["robots_counted"], "counted");
        let dropped = number(&port["kernel_dropped"], "dropped");
        assert!(counted > 0, "the robots read some of it: {port}");
        assert!(counted <= delivered && counted + dropped >= delivered, "{port}");
    }

    // The log into a nearly full file: the robot said so at once and played on; what was
    // written before reads back.
    let full = &report["log_full"];
    assert!(full["not_injected"].is_null(), "{full}");
    assert!(full["reported_s"].is_number(), "{full}");
    assert!(full["note"].as_str().is_some_and(|n| n.contains("nothing more is logged")), "{full}");
    assert_eq!(full["kept_playing"], true, "{full}");
    assert!(number(&report["full_log_file"]["messages_recovered"], "recovered") > 0);
    assert!(
        number(&report["full_log_file"]["bytes"], "bytes") <= number(&full["limit_bytes"], "limit"),
        "the file stayed within its limit"
    );

    // The log written as usual lost nothing: what the writer wrote reads back.
    let log = &report["log"];
    assert!(log["error"].is_null(), "{log}");
    assert_eq!(log["finished"], true, "{log}");
    assert_eq!(log["lost"], 0, "{log}");
    assert!(number(&log["written"], "written") > 0, "{log}");

    // Every phase was measured (the figures themselves are the report's to judge).
    let phases = report["phases"].as_array().expect("phases");
    let names: Vec<&str> = phases.iter().filter_map(|p| p["name"].as_str()).collect();
    assert_eq!(
        names,
        ["baseline", "kill -9", "SIGSTOP", "slow client", "connections", "garbage", "log full"]
    );
    for phase in phases {
        assert!(phase["real_time"]["factor"].is_number(), "{phase}");
        let rates = phase["robots"].as_array().expect("robots");
        assert_eq!(rates.len(), 6, "{phase}");
    }
    let checks = report["checks"].as_array().expect("checks");
    assert!(checks.iter().all(|c| c["met"].is_boolean() || c["met"].is_null()));
    let _ = std::fs::remove_dir_all(&out);
}
