//! `strata replay`: re-run modules of one robot from a log and compare their outputs with the
//! logged ones (`docs/logging.md`).

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use strata_log::LogReader;
use strata_log::overrides::Override;
use strata_log::replay::{ModuleRegistry, ReplayOptions, replay};
use strata_runtime::Time;

/// `strata replay FILE --robot ID --module NAME [--set key=value]...`
#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// The log (MCAP) written with `--log`.
    pub file: PathBuf,
    /// The robot whose module is replayed (its modules are logged as `ROBOT/MODULE`).
    #[arg(long)]
    pub robot: Option<String>,
    /// The module to replay; repeat it to replay several together (e.g. a whole layer).
    #[arg(long = "module", value_name = "NAME", required = true)]
    pub modules: Vec<String>,
    /// Changes a parameter of the logged configuration before the module is built: a dotted
    /// key and a value (JSON, or plain text for strings). Repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE", value_parser = parse_override)]
    pub set: Vec<Override>,
    /// Replaces the logged seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Stops at this log time (seconds) instead of the end of the log.
    #[arg(long, value_name = "SECONDS")]
    pub until: Option<f64>,
    /// How many differences to describe.
    #[arg(long, default_value_t = 10)]
    pub max_differences: usize,
    /// Do not compare publication times (values, stamps and sequence numbers still are). On by
    /// itself for a robot's own log, which was recorded in real time.
    #[arg(long)]
    pub ignore_time: bool,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// The exit code of a replay whose outputs differ from the log (1 is any error).
pub const OUTPUTS_DIFFER_EXIT_CODE: u8 = 2;

/// The replay ran, and its outputs differ from the logged ones: the answer scripts check for,
/// told apart from errors by its exit code.
#[derive(Debug)]
pub struct OutputsDiffer {
    pub modules: String,
    pub differences: usize,
}

impl std::fmt::Display for OutputsDiffer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the replay of {} differs from the log in {} packages",
            self.modules, self.differences
        )
    }
}

impl std::error::Error for OutputsDiffer {}

fn parse_override(text: &str) -> Result<Override, String> {
    Override::parse(text).map_err(|e| e.to_string())
}

/// Replays with the module constructors of `registry` (the application's). Fails with
/// [`OutputsDiffer`] (exit code 2) when the outputs differ from the log, so scripts can check
/// determinism.
pub fn run(args: ReplayArgs, registry: &ModuleRegistry) -> Result<()> {
    let reader = LogReader::open(&args.file)?;
    if let Some(recovery) = reader.recovery() {
        eprintln!(
            "note: {} was not finished; replaying the {} messages recovered from it",
            args.file.display(),
            recovery.messages
        );
        if recovery.skipped_chunks > 0 {
            // The inputs of those chunks are missing: what follows them may differ.
            eprintln!(
                "note: {} damaged chunks were skipped: their messages are missing",
                recovery.skipped_chunks
            );
        }
    }
    // `strata robot --log` stores the robot's configuration under `robot`, an experiment the
    // host it ran on; a match runs on the lockstep host.
    let real_time_log = reader.config().ok().flatten().is_some_and(|c| {
        c.get("robot").is_some() || c.get("host").and_then(|h| h.as_str()) == Some("threaded")
    });
    if real_time_log && !args.ignore_time {
        eprintln!(
            "note: the log was recorded in real time: publication times are not compared \
             (values, stamps and sequence numbers are)"
        );
    }
    let options = ReplayOptions {
        robot: args.robot,
        modules: args.modules,
        overrides: args.set,
        seed: args.seed,
        until: args.until.map(Time::from_secs_f64),
        max_differences: args.max_differences,
        ignore_time: args.ignore_time || real_time_log,
    };
    let report = replay(&reader, registry, &options)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{report}");
    }
    if !report.identical() {
        return Err(OutputsDiffer {
            modules: report.modules.join(", "),
            differences: report.total_differences,
        }
        .into());
    }
    Ok(())
}
