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
