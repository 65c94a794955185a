//! `strata experiment NAME`: the paper's section 4, re-runnable, against baselines.

use std::io::Write as _;
use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use strata_experiments::{self as experiments, EXPERIMENTS, Options};
use strata_games::physics::Engine;

#[derive(Debug, Args)]
pub struct ExperimentArgs {
    /// goal-covering (4.2, Table 5, Fig. 5), rates (4.3, Table 6), fall (4.3, Fig. 6),
    /// team (4.4), referee (games by the referee's whistle and gesture under GameController3's
    /// delays), or all.
    #[arg(value_parser = clap::builder::PossibleValuesParser::new(
        EXPERIMENTS.iter().copied().chain(["all"])
    ))]
    pub name: String,
    /// Runs per condition (default: the scenario's).
    #[arg(long)]
    pub runs: Option<usize>,
    /// Run k of every condition uses seed SEED + k.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output directory [default: results/NAME/; with `all`, DIR/NAME/ for each].
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Print the summary as one JSON object (and no progress bar).
    #[arg(long)]
    pub json: bool,
    /// A scenario TOML file instead of the built-in one (crates/experiments/scenarios/NAME.toml).
    #[arg(long, value_name = "FILE")]
    pub scenario: Option<PathBuf>,
    /// Runs executed at once [default: every core].
    #[arg(long)]
    pub threads: Option<usize>,
    /// Record the first run (first condition, run 0) into this MCAP file: every package, with
    /// the graph, seed and scenario; the team experiment's runs are match logs (docs/logging.md).
    #[arg(long, value_name = "FILE.mcap")]
    pub log: Option<PathBuf>,
    /// Where the experiment runs: the built-in 2D simulator, or Booster T1s in rcssservermj
    /// (docs/rcssservermj.md; output in results/NAME-rcssservermj/ by default).
    #[arg(long, value_enum, default_value = "sim")]
    pub engine: Engine,
}

pub fn run(args: ExperimentArgs) -> Result<()> {
    let mut options = Options {
        runs: args.runs,
        seed: args.seed,
        out: args.out.clone(),
        scenario: args.scenario.clone(),
        progress: !args.json,
        strata_exe: std::env::current_exe().ok(),
        log: args.log.clone(),
        engine: args.engine,
        ..Options::default()
    };
    if args.name == "all" && args.log.is_some() {
        anyhow::bail!("--log records one run of one experiment: name the experiment, not `all`");
    }
    if let Some(threads) = args.threads {
        options.threads = threads.max(1);
    }
    let outcomes = if args.name == "all" {
        experiments::run_all(&options)?
    } else {
        vec![experiments::run(&args.name, &options)?]
    };
    if args.json {
        let value = if args.name == "all" {
            serde_json::Value::Object(
                outcomes.iter().map(|o| (o.experiment.clone(), o.summary.clone())).collect(),
            )
        } else {
            outcomes.first().map(|o| o.summary.clone()).unwrap_or_default()
        };
        // A closed pipe (`| head`) is the reader's choice, not an error worth a panic.
        let mut out = std::io::stdout().lock();
        let _ = writeln!(out, "{}", serde_json::to_string(&value)?);
    } else {
        for o in &outcomes {
            println!("{}: {}", o.experiment, o.out_dir.join("report.md").display());
        }
        if args.name == "all" {
            println!("(experiments: {})", EXPERIMENTS.join(", "));
        }
    }
    Ok(())
}
