//! What `strata match --log` costs: the real-time factor of the same seeded match (7 vs 7,
//! lockstep host) without and with a log of every package, as the ratio of the two (the
//! observability issue's target is 0.90). Runs the `strata` binary itself, so the figure is
//! what a user gets, allocator and writer thread included; the two runs alternate, so both
//! sides of a ratio see the same minutes of a shared machine.
//!
//! Run: `cargo bench -p strata --bench log_overhead`
//! (`STRATA_LOG_BENCH_SECONDS` sets the simulated seconds per run, 300 by default, 0 for the
//! whole game; `STRATA_LOG_BENCH_ROUNDS` the number of rounds, 6 by default; and
//! `STRATA_LOG_BENCH_ARGS` adds arguments to the logged run only, e.g. `--log-robots home/1`
//! or `--log-compression none`.)
//!
//! Each run also prints the CPU time the whole process used. A logged match runs two threads;
//! on a virtual machine whose two cores sometimes share one physical core the same work then
//! costs much more CPU time, and that round's ratio says more about the host than about the
//! program (`docs/performance.md`).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

/// One run of `strata match`: its real-time factor, the CPU time it used and, when it logged,
/// the writer's summary line.
struct Run {
    real_time_factor: f64,
    cpu: Option<Duration>,
    log_summary: Option<String>,
}

/// CPU time (user and system) of the children this process has waited for, from Linux's
/// `/proc/self/stat` (fields `cutime` and `cstime`, in the kernel's fixed 100 Hz user ticks).
fn children_cpu_time() -> Option<Duration> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The command name may hold spaces; the fields after it are plain numbers.
    let after_name = &stat[stat.rfind(')')? + 1..];
    let fields: Vec<&str> = after_name.split_whitespace().collect();
    // `cutime` and `cstime` are fields 16 and 17 of the line, 14 and 15 after the name.
    let ticks: u64 = fields.get(13)?.parse::<u64>().ok()? + fields.get(14)?.parse::<u64>().ok()?;
    Some(Duration::from_millis(ticks * 10))
}

fn run_match(seconds: f64, log: Option<(&Path, &[String])>) -> Run {
    let mut command = Command::new(env!("CARGO_BIN_EXE_strata"));
    command.args(["match", "--seed", "1", "--json"]);
    if seconds > 0.0 {
        command.arg("--duration").arg(seconds.to_string());
    }
    if let Some((path, extra)) = log {
        // A log from an earlier run would only be overwritten, but its pages would still be
        // in the page cache the writer is about to fill.
        let _ = std::fs::remove_file(path);
        command.arg("--log").arg(path).args(extra);
    }
    let cpu_before = children_cpu_time();
    let output = command.output().expect("the strata binary runs");
    let cpu =
        children_cpu_time().zip(cpu_before).map(|(after, before)| after.saturating_sub(before));
    assert!(
        output.status.success(),
        "strata match failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let report: serde_json::Value =
        serde_json::from_slice(&output.stdout).expect("strata match --json prints its report");
    let real_time_factor = report["real_time_factor"].as_f64().expect("the report has a factor");
    let log_summary = String::from_utf8_lossy(&output.stderr)
        .lines()
        .find(|line| line.starts_with("log: "))
        .map(str::to_owned);
    Run { real_time_factor, cpu, log_summary }
}

fn describe(run: &Run) -> String {
    match run.cpu {
        Some(cpu) => format!("{:6.1}x ({:.2} s CPU)", run.real_time_factor, cpu.as_secs_f64()),
        None => format!("{:6.1}x", run.real_time_factor),
    }
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    let middle = values.len() / 2;
    if values.len().is_multiple_of(2) {
        (values[middle - 1] + values[middle]) / 2.0
    } else {
        values[middle]
    }
}

fn env_number<T: std::str::FromStr>(name: &str, default: T) -> T {
    match std::env::var(name) {
        Ok(text) => text.parse().unwrap_or_else(|_| panic!("{name}={text} is not a number")),
        Err(_) => default,
    }
}

fn log_path() -> PathBuf {
    std::env::temp_dir().join(format!("strata-log-overhead-{}.mcap", std::process::id()))
}

fn main() {
    let path = log_path();
    let quick = !std::env::args().any(|a| a == "--bench");
    if quick {
        // Both runs work and the log is complete; no figure is judged here.
        let unlogged = run_match(3.0, None);
        let logged = run_match(3.0, Some((&path, &[])));
        let _ = std::fs::remove_file(&path);
        assert!(unlogged.real_time_factor > 0.0 && logged.real_time_factor > 0.0);
        let summary = logged.log_summary.expect("a logged match reports its log");
        assert!(summary.contains(" 0 dropped"), "{summary}");
        println!("log_overhead: smoke run ok ({summary})");
        return;
    }
    let seconds: f64 = env_number("STRATA_LOG_BENCH_SECONDS", 300.0);
    let rounds: usize = env_number("STRATA_LOG_BENCH_ROUNDS", 6);
    let extra: Vec<String> = std::env::var("STRATA_LOG_BENCH_ARGS")
        .map(|text| text.split_whitespace().map(str::to_owned).collect())
        .unwrap_or_default();
    let duration = if seconds > 0.0 { format!("--duration {seconds} ") } else { String::new() };
    println!(
        "strata match {duration}--seed 1 (7 vs 7), without and with --log {}{}, alternately, \
         {rounds} rounds",
        path.display(),
        if extra.is_empty() { String::new() } else { format!(" {}", extra.join(" ")) }
    );
    let mut ratios = Vec::with_capacity(rounds);
    let mut last_summary = None;
    for round in 1..=rounds {
        let unlogged = run_match(seconds, None);
        let logged = run_match(seconds, Some((&path, &extra)));
        let ratio = logged.real_time_factor / unlogged.real_time_factor;
        println!(
            "round {round}/{rounds}: no log {}   --log {}   ratio {ratio:.3}",
            describe(&unlogged),
            describe(&logged)
        );
        ratios.push(ratio);
        last_summary = logged.log_summary;
    }
    let _ = std::fs::remove_file(&path);
    if let Some(summary) = last_summary {
        println!("{summary}");
    }
    let best = ratios.iter().copied().fold(f64::NAN, f64::max);
    println!(
        "real-time factor with --log / without: median {:.3}, best round {best:.3} (target >= 0.90)",
        median(ratios)
    );
}
