//! One-shot `strata` commands for the command-line tests: run to the end, read stdout and
//! stderr after.

use std::path::PathBuf;
use std::process::{Command, Output};

/// A fresh directory for one test, in the system's temporary directory.
pub fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("strata-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    dir
}

/// `strata ARGS`, without the caller's `RUST_LOG` (tests set it themselves when they mean to).
pub fn strata(args: &[&str]) -> Command {
    let mut command = super::strata();
    command.args(args).env_remove("RUST_LOG");
    command
}

pub fn run(command: &mut Command) -> Output {
    command.output().expect("strata runs")
}

pub fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// Whether rcssservermj is installed. Without it a physics test says so and passes, unless
/// `STRATA_REQUIRE_RCSSSERVERMJ` is set (as `scripts/test` does after installing it).
pub fn rcssservermj_installed() -> bool {
    let installed = strata_rcssmj::server::find_server().is_some_and(|p| p.is_file());
    if !installed {
        assert!(
            std::env::var_os("STRATA_REQUIRE_RCSSSERVERMJ").is_none(),
            "rcssservermj is required (STRATA_REQUIRE_RCSSSERVERMJ) but not installed"
        );
        eprintln!("rcssservermj is not installed (scripts/setup-rcssservermj): test skipped");
    }
    installed
}

/// `strata experiment NAME --engine rcssservermj` on `scenario` (TOML text) with `extra`
/// options and `--json`, as a user runs it: its output directory and its summary. Fails the
/// test when the command fails.
pub fn physics_experiment(
    name: &str,
    scenario: &str,
    extra: &[&str],
) -> (PathBuf, serde_json::Value) {
    let dir = temp_dir(&format!("{name}-rcssservermj"));
    let file = dir.join(format!("{name}.toml"));
    std::fs::write(&file, scenario).expect("the scenario is written");
    let out = dir.join("out");
    let mut args = vec![
        "experiment",
        name,
        "--engine",
        "rcssservermj",
        "--scenario",
        file.to_str().expect("a UTF-8 path"),
        "--out",
        out.to_str().expect("a UTF-8 path"),
        "--json",
    ];
    args.extend_from_slice(extra);
    let output = run(&mut strata(&args));
    assert!(output.status.success(), "the experiment failed: {}", stderr(&output));
    let summary = serde_json::from_slice(&output.stdout).expect("--json prints one JSON object");
    (out, summary)
}
