//! What a user sees when the command line is given bad input: one error naming the file and
//! what is wrong with it, a failing exit status, and no backtrace of this program even when
//! RUST_BACKTRACE is set (as many set it for panics).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("strata-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    dir
}

fn strata(args: &[&str], file: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_strata"))
        .args(args)
        .arg(file)
        .env("RUST_BACKTRACE", "1")
        .output()
        .expect("strata runs")
}

fn assert_clear_error(output: &Output, needles: &[&str]) {
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "should fail: {stderr}");
    assert!(stderr.starts_with("error: "), "{stderr}");
    assert!(!stderr.contains("backtrace"), "{stderr}");
    for needle in needles {
        assert!(stderr.contains(needle), "stderr lacks `{needle}`:\n{stderr}");
    }
}

#[test]
fn a_file_that_is_not_a_log_is_one_error_naming_it() {
    let dir = temp_dir("not-a-log");
    let file = dir.join("notes.mcap");
    std::fs::write(&file, b"these are notes, not a log").expect("written");
    let output = strata(&["log", "info"], &file);
    assert_clear_error(&output, &["notes.mcap", "not an MCAP file"]);
    let missing = strata(&["log", "info"], &dir.join("missing.mcap"));
    assert_clear_error(&missing, &["missing.mcap"]);
    // An error that quotes its cause does not repeat it as a cause.
    let stderr = String::from_utf8_lossy(&missing.stderr);
    assert!(!stderr.contains("caused by"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_team_config_with_an_unknown_field_names_the_file_and_the_field() {
    let dir = temp_dir("team-config");
    let file = dir.join("team.toml");
    std::fs::write(&file, "name = \"ours\"\nbogus_gain = 3\n").expect("written");
    let output = strata(&["match", "--duration", "1", "--home"], &file);
    assert_clear_error(&output, &["team.toml", "bogus_gain"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_foxglove_address_that_cannot_be_served_is_one_error_naming_it() {
    let run = |addr: &str| {
        Command::new(env!("CARGO_BIN_EXE_strata"))
            .args(["match", "--players", "1", "--duration", "1", "--foxglove", addr])
            .env("RUST_BACKTRACE", "1")
            .output()
            .expect("strata runs")
    };
    assert_clear_error(&run("not an address"), &["--foxglove `not an address`", "HOST:PORT"]);
    // A port another program listens on.
    let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("a free port");
    let addr = taken.local_addr().expect("its address").to_string();
    assert_clear_error(&run(&addr), &["Foxglove", &addr]);
}
