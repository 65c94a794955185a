//! Exit codes: 0 success, 1 an error (usage errors included), 2 a replay whose outputs differ
//! from the log — so a script can tell "not deterministic" from "could not check".

mod common;

use common::cli::{run, stderr, strata, temp_dir};

#[test]
fn exit_codes_tell_errors_from_differing_replays() {
    let dir = temp_dir("replay");
    let log = dir.join("match.mcap");
    let log_arg = log.to_string_lossy().into_owned();
    // Without GameController3's delays the robots walk to Ready after 2 s: a world model that
    // integrates odometry (standing through Standby it would have none to integrate).
    let output = run(&mut strata(&[
        "match",
        "--no-delay",
        "--players",
        "2",
        "--duration",
        "4",
        "--seed",
        "5",
        "--log",
        &log_arg,
    ]));
    assert!(output.status.success(), "{}", stderr(&output));

    let replay = ["replay", log_arg.as_str(), "--robot", "home/2", "--module", "world"];
    let same = run(&mut strata(&replay));
    assert_eq!(same.status.code(), Some(0), "{}", stderr(&same));

    let noisier = "world.home.odometry.translation_variance_per_metre=0.5";
    let differs = run(strata(&replay).args(["--set", noisier]));
    assert_eq!(differs.status.code(), Some(2), "{}", stderr(&differs));
    assert!(stderr(&differs).contains("differs from the log"), "{}", stderr(&differs));
    assert!(!stderr(&differs).starts_with("error"), "{}", stderr(&differs));

    let missing = dir.join("missing.mcap");
    let missing = run(strata(&["replay", "--module", "world"]).arg(&missing));
    assert_eq!(missing.status.code(), Some(1), "{}", stderr(&missing));
    let unknown = run(&mut strata(&["replay", "--no-such-flag"]));
    assert_eq!(unknown.status.code(), Some(1), "a usage error is an error: {}", stderr(&unknown));
    let help = run(&mut strata(&["--help"]));
    assert_eq!(help.status.code(), Some(0));
    let help = String::from_utf8_lossy(&help.stdout);
    assert!(help.contains("Exit codes") && help.contains("outputs differ"), "{help}");
    let _ = std::fs::remove_dir_all(&dir);
}
