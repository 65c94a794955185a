//! `strata chaos`: a real-time game under faults, measured (`strata_experiments::chaos`,
//! docs/reliability.md).

use std::io::Write as _;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context as _, Result, bail};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use strata_experiments::chaos::{self, Options, STEPS};

/// `strata chaos`.
#[derive(Debug, Args)]
pub struct ChaosArgs {
    /// Seconds each phase is measured: the baseline and each fault but the slow client's. The
    /// run takes about eight times this, plus the start, the slow client and the waits for a
    /// takeover and a restart.
    #[arg(long, value_name = "SECS", default_value_t = 20.0)]
    pub duration: f64,
    /// Longest the slow client stays connected, seconds. The server drops it first once the
    /// socket buffers between them are full and a write blocks past the server's write
    /// timeout (about 45 s at a kilobyte a second); the phase ends when it does.
    #[arg(long, value_name = "SECS", default_value_t = 120.0)]
    pub slow_client: f64,
    /// Garbage datagrams sent to each of the two ports (the GameController's, the team's).
    #[arg(long, value_name = "N", default_value_t = 100_000,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub datagrams: u64,
    /// Connections opened that never say hello.
    #[arg(long, value_name = "N", default_value_t = 1000)]
    pub connection_attempts: usize,
    /// Output directory: summary.json, report.md, CSV tables, the robots' logs and output.
    #[arg(long, value_name = "DIR", default_value = "results/chaos")]
    pub out: PathBuf,
    /// Seeds the world, the robots and the garbage.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The robots' --real-time-priority (0: every thread at the default policy, as on a
    /// machine without the permission).
    #[arg(long, value_name = "PRIORITY", default_value_t = 0,
          value_parser = clap::value_parser!(u8).range(0..=99))]
    pub real_time_priority: u8,
    /// Print the report as one JSON object (and no progress bar).
    #[arg(long)]
    pub json: bool,
}

/// Runs the chaos run. A run that completes exits with 0 whatever it found: the table (and
/// `all_met` in the JSON) says which targets were met.
pub fn run(args: ChaosArgs) -> Result<()> {
    if !(args.duration.is_finite() && (1.0..=3600.0).contains(&args.duration)) {
        bail!("--duration must be 1 to 3600 seconds, got {}", args.duration);
    }
    if !(args.slow_client.is_finite() && (1.0..=3600.0).contains(&args.slow_client)) {
        bail!("--slow-client must be 1 to 3600 seconds, got {}", args.slow_client);
    }
    if args.connection_attempts == 0 {
        bail!("--connection-attempts must be at least 1: every fault is injected");
    }
    let options = Options {
        phase: Duration::from_secs_f64(args.duration),
        stop: Duration::from_secs(5),
        slow_client: Duration::from_secs_f64(args.slow_client),
        datagrams: args.datagrams,
        connection_attempts: args.connection_attempts,
        out_dir: args.out.clone(),
        strata_exe: std::env::current_exe().context("finding the strata executable")?,
        seed: args.seed,
        real_time_priority: args.real_time_priority,
    };
    let progress = if args.json {
        ProgressBar::hidden()
    } else {
        let bar = ProgressBar::new(STEPS);
        bar.set_style(
            ProgressStyle::with_template(
                "{spinner} chaos [{elapsed_precise}] {bar:20} {pos}/{len} {msg}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar.enable_steady_tick(Duration::from_millis(250));
        bar
    };
    let report = chaos::run(&options, &progress);
    progress.finish_and_clear();
    let report = report?;
    // A closed pipe (`| head`) is the reader's choice, not an error worth a panic.
    let mut out = std::io::stdout().lock();
    if args.json {
        let _ = writeln!(out, "{}", serde_json::to_string(&report)?);
    } else {
        let _ = write!(out, "{}", chaos::table_text(&report));
        let _ = writeln!(out, "files: {}", args.out.display());
    }
    Ok(())
}
