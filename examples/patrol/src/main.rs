//! `cargo run -p patrol -- [--seed N] [--seconds S] [--threaded]`: runs the demonstration
//! patrol (on the lockstep host unless `--threaded`) and prints a summary.

use std::process::ExitCode;

const USAGE: &str = "usage: patrol [--seed N] [--seconds S] [--threaded]";

fn main() -> ExitCode {
    let mut seed = 7;
    let mut seconds = 180.0;
    let mut threaded = false;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--seed" => match args.next().and_then(|v| v.parse().ok()) {
                Some(v) => seed = v,
                None => return usage(),
            },
            "--seconds" => match args.next().and_then(|v| v.parse().ok()) {
                Some(v) => seconds = v,
                None => return usage(),
            },
            "--threaded" => threaded = true,
            _ => return usage(),
        }
    }
    let outcome = patrol::PatrolRun::demo(seed).and_then(|run| {
        if threaded { run.run_threaded(seconds) } else { run.run_lockstep(seconds) }
    });
    match outcome {
        Ok(outcome) => {
            print!("{}", outcome.summary());
            ExitCode::SUCCESS
        }
        Err(error) => {
            eprintln!("patrol: {error}");
            ExitCode::FAILURE
        }
    }
}

fn usage() -> ExitCode {
    eprintln!("{USAGE}");
    ExitCode::FAILURE
}
