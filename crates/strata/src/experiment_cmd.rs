//! `strata experiment NAME`: the paper's section 4, re-runnable, against baselines.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use anyhow::{Context as _, Result, bail};
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
    /// Run the runs as Ray tasks (`strata.sweep`, docs/python.md): on the cluster at ADDRESS
    /// (`ray start --head` prints it), or on a local Ray instance without it. Records go to
    /// OUT/records/; running the same command again resumes without redoing finished runs.
    #[arg(long, value_name = "ADDRESS", num_args = 0..=1, default_missing_value = "")]
    pub ray: Option<String>,
}

pub fn run(args: ExperimentArgs) -> Result<()> {
    if let Some(address) = &args.ray {
        return run_on_ray(&args, address);
    }
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

/// The interpreter that has the `strata` package: `$STRATA_PYTHON`, the repository's
/// `.venv-python` (scripts/setup-python), or `python3`.
fn python() -> PathBuf {
    if let Some(python) = std::env::var_os("STRATA_PYTHON").filter(|p| !p.is_empty()) {
        return PathBuf::from(python);
    }
    let venv = Path::new(".venv-python/bin/python");
    if venv.is_file() {
        return venv.to_path_buf();
    }
    PathBuf::from("python3")
}

/// `--ray`: the sweep is Python's (Ray's client is a Python library): runs `python -m
/// strata.sweep` with the same options.
fn run_on_ray(args: &ExperimentArgs, address: &str) -> Result<()> {
    if args.name == "all" {
        bail!("--ray runs one experiment: name it, not `all`");
    }
    if args.log.is_some() {
        bail!("--log records a run in this process; it cannot be used with --ray");
    }
    experiments::check_recordable(&args.name, args.engine)?;
    let python = python();
    let setup = "install the Python package: ./scripts/setup-python (or set STRATA_PYTHON to an \
                 interpreter that has strata and ray)";
    let check = Command::new(&python)
        .args(["-c", "import strata.sweep, ray"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status();
    match check {
        Ok(status) if status.success() => {}
        Ok(_) => bail!("{} cannot import strata and ray: {setup}", python.display()),
        Err(e) => bail!("cannot run {}: {e}; {setup}", python.display()),
    }
    let mut command = Command::new(&python);
    command.args(["-m", "strata.sweep", &args.name, "--seed", &args.seed.to_string()]);
    if !address.is_empty() {
        command.args(["--address", address]);
    }
    if let Some(runs) = args.runs {
        command.args(["--runs", &runs.to_string()]);
    }
    if let Some(out) = &args.out {
        command.arg("--out").arg(out);
    }
    if let Some(scenario) = &args.scenario {
        command.arg("--scenario").arg(scenario);
    }
    if let Some(threads) = args.threads {
        // On a local instance, the workers are the cores it may use.
        command.args(["--num-workers", &threads.max(1).to_string()]);
    }
    if args.json {
        command.arg("--json");
    }
    let status = command
        .status()
        .with_context(|| format!("running {} -m strata.sweep", python.display()))?;
    if !status.success() {
        bail!("the sweep failed ({status})");
    }
    Ok(())
}
