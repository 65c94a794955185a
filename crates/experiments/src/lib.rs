//! `strata experiment`: the validation of the paper's section 4 as commands anyone can re-run,
//! each set against baselines in the same run.
//!
//! | experiment | paper | what |
//! |---|---|---|
//! | `goal-covering` | 4.2, Fig. 4, Fig. 5, Table 5 | active vision while covering the goal, deliberative layer at 0.5 / 1 / 2 Hz, against always-ball, fixed-scan and entropy gaze |
//! | `rates` | 4.3, Table 6 | layer frequencies of a goalkeeper and a striker in real time, with and without an artificial deliberative load |
//! | `fall` | 4.3, Fig. 6 | fall-detection latency, stand-up time, false positives while walking, in real time |
//! | `team` | 4.4 | matches of the full architecture against no coordination and no active vision; role statistics under team-message loss |
//! | `referee` | - | the referee's signals in full games with GameController3's timing: Ready positions, kick-off starts after the whistle, false starts, speed against `--no-delay` |
//!
//! Every experiment reads a scenario (TOML; the shipped ones are in `crates/experiments/scenarios/`
//! and embedded in the binary), runs its runs in parallel, and writes `report.md`, PNG and SVG
//! plots, the raw per-run data as CSV and `summary.json` to its output directory.
//! Lockstep experiments are deterministic for a seed: run `k` of a condition uses seed
//! `seed + k`, the same for every method compared.

pub mod chaos;
pub mod counts;
pub mod fall;
pub mod goal_covering;
pub mod physics;
pub mod plot;
pub mod rates;
pub mod records;
pub mod referee;
pub mod report;
pub mod stats;
pub mod team;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, anyhow, bail};
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use serde::de::DeserializeOwned;
use strata_robot::assembly::RobotModules;
use strata_robot::geometry::Pose;
use strata_runtime::{
    Graph, GraphBuilder, HostConfig, HostStats, LockstepHost, RunningHost, Tap, Taps, ThreadedHost,
};
use strata_sim::{GameState, NoiseLevel, RobotId, SimConfig, SimHandle, Simulation, add_simulator};
use strata_soccer::field::TeamField;
use strata_soccer::gaze_override::GazeOverride;
use strata_soccer::team::team_world_config;
use strata_soccer::team::{SoccerRobotSpec, TeamConfig, add_soccer_robot_with_gaze};

use strata_games::logging::{RobotRunConfig, open_run_log};
use strata_games::matches::{robot_name, served_links, served_platform};
use strata_games::physics::Engine;
use strata_log::{ConfigFormat, McapTap, McapTapOptions, RunInfo, WhenFull};

/// Every experiment, in the order `strata experiment all` runs them.
pub const EXPERIMENTS: [&str; 5] =
    [goal_covering::NAME, rates::NAME, fall::NAME, team::NAME, referee::NAME];

/// How to run an experiment (the command line).
#[derive(Clone, Debug)]
pub struct Options {
    /// Runs per condition; `None`: the scenario's.
    pub runs: Option<usize>,
    /// Run `k` of every condition uses seed `seed + k`.
    pub seed: u64,
    /// Output directory; `None`: `results/NAME/`.
    pub out: Option<PathBuf>,
    /// A scenario file instead of the built-in one.
    pub scenario: Option<PathBuf>,
    /// Draw a progress bar (on stderr).
    pub progress: bool,
    /// Runs executed at once (lockstep experiments); real-time experiments limit themselves.
    pub threads: usize,
    /// The `strata` executable, for experiments that start robot processes (`rates` over TCP).
    pub strata_exe: Option<PathBuf>,
    /// Record the experiment's first run (first condition, run 0) into this MCAP file.
    pub log: Option<PathBuf>,
    /// The built-in simulator or T1s in rcssservermj (`crate::physics`).
    pub engine: Engine,
    /// Run only some jobs into a records directory, or merge the records there (`records`).
    pub records: Option<records::Records>,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            runs: None,
            seed: 1,
            out: None,
            scenario: None,
            progress: false,
            log: None,
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
            strata_exe: None,
            engine: Engine::Sim,
            records: None,
        }
    }
}

/// The experiments whose jobs can be recorded and merged (`Options::records`): the lockstep
/// ones, deterministic for a seed.
pub const RECORDABLE: [&str; 2] = [goal_covering::NAME, team::NAME];

/// What an experiment produced.
#[derive(Clone, Debug, Serialize)]
pub struct Outcome {
    pub experiment: String,
    pub out_dir: PathBuf,
    pub files: Vec<PathBuf>,
    /// The summary `--json` prints (also in `summary.json`).
    pub summary: serde_json::Value,
}

/// Runs one experiment by name.
pub fn run(name: &str, options: &Options) -> Result<Outcome> {
    if !EXPERIMENTS.contains(&name) {
        bail!("no experiment `{name}` (try: {}, all)", EXPERIMENTS.join(", "));
    }
    if options.engine == Engine::Rcssservermj && name == referee::NAME {
        bail!("`{name}` runs on the built-in simulator only (its referee emulates the signals)");
    }
    if let Some(records) = &options.records {
        check_recordable(name, options.engine)?;
        if records.mode != records::RecordMode::Merge {
            return run_records(name, options, records);
        }
    }
    let out_dir = options.out.clone().unwrap_or_else(|| match options.engine {
        Engine::Sim => Path::new("results").join(name),
        Engine::Rcssservermj => Path::new("results").join(format!("{name}-rcssservermj")),
    });
    std::fs::create_dir_all(&out_dir)
        .with_context(|| format!("creating the output directory {}", out_dir.display()))?;
    let mut ctx = Ctx::new(name, options, out_dir.clone());
    let summary = match (options.engine, name) {
        (Engine::Rcssservermj, _) => crate::physics::run(name, &mut ctx)?,
        (Engine::Sim, name) => run_2d(name, &mut ctx)?,
    };
    let summary_path = out_dir.join("summary.json");
    std::fs::write(&summary_path, serde_json::to_string_pretty(&summary)?)
        .with_context(|| format!("writing {}", summary_path.display()))?;
    ctx.files.push(summary_path);
    Ok(Outcome { experiment: name.to_owned(), out_dir, files: ctx.files, summary })
}

/// Refuses record mode where splitting the runs changes what they measure.
pub fn check_recordable(name: &str, engine: Engine) -> Result<()> {
    if engine != Engine::Sim {
        bail!(
            "`{name}` on {engine:?} cannot be split into job records: only the built-in \
             simulator's lockstep runs are deterministic for a seed"
        );
    }
    if name == rates::NAME || name == fall::NAME {
        bail!(
            "`{name}` measures in real time on this machine: its runs cannot be split across \
             workers or machines (run it in one process)"
        );
    }
    if !RECORDABLE.contains(&name) {
        bail!(
            "`{name}` cannot be split into job records yet (recordable: {})",
            RECORDABLE.join(", ")
        );
    }
    Ok(())
}

/// Plans or runs jobs into a records directory: the experiment stops at `Ctx::run_jobs`, before
/// its report, with what it did.
fn run_records(name: &str, options: &Options, records: &records::Records) -> Result<Outcome> {
    let mut ctx = Ctx::new(name, options, records.dir.clone());
    let stop = match run_2d(name, &mut ctx) {
        Ok(_) => bail!("`{name}` ran without going through its job records"),
        Err(e) => e.downcast::<records::Stop>()?,
    };
    let (summary, files) = match stop {
        records::Stop::Planned { jobs } => (serde_json::json!({ "jobs": jobs }), Vec::new()),
        records::Stop::Ran { jobs, written, skipped } => {
            let files = written.iter().map(|i| records::record_path(&records.dir, *i)).collect();
            (serde_json::json!({ "jobs": jobs, "written": written, "skipped": skipped }), files)
        }
    };
    Ok(Outcome { experiment: name.to_owned(), out_dir: records.dir.clone(), files, summary })
}

/// The number of jobs experiment `name` runs with `options`; writes the records manifest into
/// `dir` (or checks the one there is this sweep's).
pub fn plan(name: &str, options: &Options, dir: &Path) -> Result<usize> {
    let options = Options {
        records: Some(records::Records { dir: dir.to_path_buf(), mode: records::RecordMode::Plan }),
        progress: false,
        ..options.clone()
    };
    let outcome = run(name, &options)?;
    outcome.summary["jobs"]
        .as_u64()
        .map(|n| n as usize)
        .ok_or_else(|| anyhow!("`{name}`: the plan has no job count"))
}

fn run_2d(name: &str, ctx: &mut Ctx<'_>) -> Result<serde_json::Value> {
    Ok(match name {
        goal_covering::NAME => {
            let scenario =
                ctx.scenario::<goal_covering::Scenario>(goal_covering::DEFAULT_SCENARIO)?;
            to_json(&goal_covering::run(&scenario, ctx)?)?
        }
        rates::NAME => {
            let scenario = ctx.scenario::<rates::Scenario>(rates::DEFAULT_SCENARIO)?;
            to_json(&rates::run(&scenario, ctx)?)?
        }
        fall::NAME => {
            let scenario = ctx.scenario::<fall::Scenario>(fall::DEFAULT_SCENARIO)?;
            to_json(&fall::run(&scenario, ctx)?)?
        }
        team::NAME => {
            let scenario = ctx.scenario::<team::Scenario>(team::DEFAULT_SCENARIO)?;
            to_json(&team::run(&scenario, ctx)?)?
        }
        referee::NAME => {
            let scenario = ctx.scenario::<referee::Scenario>(referee::DEFAULT_SCENARIO)?;
            to_json(&referee::run(&scenario, ctx)?)?
        }
        other => bail!("no experiment `{other}` (try: {}, all)", EXPERIMENTS.join(", ")),
    })
}

/// Runs every experiment; with `--out DIR`, each writes to `DIR/NAME/`. A scenario file cannot
/// apply to all of them.
pub fn run_all(options: &Options) -> Result<Vec<Outcome>> {
    if options.scenario.is_some() {
        bail!("--scenario names one experiment's scenario; it cannot be used with `all`");
    }
    EXPERIMENTS
        .iter()
        // The referee's signals are the built-in simulator's.
        .filter(|name| options.engine == Engine::Sim || **name != referee::NAME)
        .map(|name| {
            let options =
                Options { out: options.out.as_ref().map(|out| out.join(name)), ..options.clone() };
            run(name, &options)
        })
        .collect()
}

/// The machine's 1-minute load average (Linux only): real-time figures depend on what else the
/// machine runs, so their reports state it.
pub fn load_average() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/loadavg").ok()?;
    text.split_whitespace().next()?.parse().ok()
}

/// "1.2 to 3.4 (1-minute load average, N logical cores)", or "unknown".
pub fn describe_load(loads: &[f64]) -> String {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let finite: Vec<f64> = loads.iter().copied().filter(|l| l.is_finite()).collect();
    if finite.is_empty() {
        return format!("unknown ({cores} logical cores)");
    }
    let lo = finite.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = finite.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let busy = if hi > cores as f64 {
        "; above the core count: other processes competed for the cores, so real-time figures \
         measure the machine as well as the architecture"
    } else {
        ""
    };
    format!(
        "{lo:.1} to {hi:.1} (1-minute load average at the end of each run, {cores} logical cores){busy}"
    )
}

fn to_json(value: &impl Serialize) -> Result<serde_json::Value> {
    serde_json::to_value(value).context("serializing the summary")
}

/// A scenario that cannot be used: names the file and the field.
#[derive(Debug)]
pub struct ScenarioError {
    pub source_name: String,
    pub field: Option<String>,
    pub message: String,
}

impl std::fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.field {
            Some(field) => write!(f, "{}: field `{field}`: {}", self.source_name, self.message),
            None => write!(f, "{}: {}", self.source_name, self.message),
        }
    }
}

impl std::error::Error for ScenarioError {}

impl ScenarioError {
    pub fn invalid(source_name: &str, field: &str, message: impl Into<String>) -> ScenarioError {
        ScenarioError {
            source_name: source_name.to_owned(),
            field: Some(field.to_owned()),
            message: message.into(),
        }
    }
}

/// Parses a scenario; errors name `source_name` and the field's path (`trajectories[1].speed`).
pub fn parse_scenario<T: DeserializeOwned>(
    text: &str,
    source_name: &str,
) -> Result<T, ScenarioError> {
    let deserializer = toml::Deserializer::parse(text).map_err(|e| ScenarioError {
        source_name: source_name.to_owned(),
        field: None,
        message: e.to_string().trim_end().to_owned(),
    })?;
    serde_path_to_error::deserialize(deserializer).map_err(|e| {
        let path = e.path().to_string();
        ScenarioError {
            source_name: source_name.to_owned(),
            field: (!path.is_empty() && path != ".").then_some(path),
            message: e.into_inner().to_string().trim_end().to_owned(),
        }
    })
}

/// Checks of a scenario's values, with the source name for errors.
#[derive(Debug)]
pub struct Check<'a> {
    pub source_name: &'a str,
}

impl Check<'_> {
    pub fn positive(&self, field: &str, value: f64) -> Result<(), ScenarioError> {
        if value.is_finite() && value > 0.0 {
            Ok(())
        } else {
            Err(ScenarioError::invalid(
                self.source_name,
                field,
                format!("must be > 0, got {value}"),
            ))
        }
    }

    pub fn non_negative(&self, field: &str, value: f64) -> Result<(), ScenarioError> {
        if value.is_finite() && value >= 0.0 {
            Ok(())
        } else {
            Err(ScenarioError::invalid(
                self.source_name,
                field,
                format!("must be >= 0, got {value}"),
            ))
        }
    }

    pub fn fraction(&self, field: &str, value: f64) -> Result<(), ScenarioError> {
        if (0.0..=1.0).contains(&value) {
            Ok(())
        } else {
            Err(ScenarioError::invalid(
                self.source_name,
                field,
                format!("must be in [0, 1], got {value}"),
            ))
        }
    }

    pub fn not_empty<T>(&self, field: &str, values: &[T]) -> Result<(), ScenarioError> {
        if values.is_empty() {
            Err(ScenarioError::invalid(self.source_name, field, "must not be empty"))
        } else {
            Ok(())
        }
    }

    pub fn at_least(&self, field: &str, value: usize, min: usize) -> Result<(), ScenarioError> {
        if value >= min {
            Ok(())
        } else {
            Err(ScenarioError::invalid(
                self.source_name,
                field,
                format!("must be at least {min}, got {value}"),
            ))
        }
    }

    pub fn fail(&self, field: &str, message: impl Into<String>) -> ScenarioError {
        ScenarioError::invalid(self.source_name, field, message)
    }

    pub fn team(
        &self,
        field: &str,
        team: &str,
        base: Option<&Path>,
    ) -> Result<TeamConfig, ScenarioError> {
        resolve_team(team, base).map_err(|e| self.fail(field, e))
    }

    pub fn noise(&self, field: &str, noise: &str) -> Result<NoiseLevel, ScenarioError> {
        match noise {
            "none" => Ok(NoiseLevel::None),
            "default" => Ok(NoiseLevel::Default),
            "high" => Ok(NoiseLevel::High),
            other => {
                Err(self
                    .fail(field, format!("unknown noise preset `{other}` (none, default, high)")))
            }
        }
    }

    pub fn field_preset(
        &self,
        field: &str,
        name: &str,
        base: Option<&Path>,
    ) -> Result<String, ScenarioError> {
        if strata_spl::field::PRESETS.contains(&name) {
            return Ok(name.to_owned());
        }
        let path = base.map_or_else(|| PathBuf::from(name), |b| b.join(name));
        if path.exists() {
            Ok(path.display().to_string())
        } else {
            Err(self.fail(
                field,
                format!(
                    "no field preset or file `{name}` (presets: {})",
                    strata_spl::field::PRESETS.join(", ")
                ),
            ))
        }
    }
}

/// A built-in team or a team file (relative to the scenario file's directory).
fn resolve_team(team: &str, base: Option<&Path>) -> Result<TeamConfig, String> {
    let is_file = Path::new(team).extension().is_some_and(|e| e == "toml");
    if is_file {
        let path = base.map_or_else(|| PathBuf::from(team), |b| b.join(team));
        TeamConfig::load(&path).map_err(|e| e.to_string())
    } else {
        TeamConfig::preset(team).map_err(|e| e.to_string())
    }
}

/// What an experiment's run needs from the runner.
pub struct Ctx<'a> {
    pub name: &'a str,
    pub options: &'a Options,
    pub out_dir: PathBuf,
    /// Where the scenario came from (a path, or the built-in file's name).
    pub scenario_source: String,
    pub scenario_text: String,
    /// The scenario file's directory: relative paths in it are resolved from there.
    pub scenario_dir: Option<PathBuf>,
    pub files: Vec<PathBuf>,
}

impl std::fmt::Debug for Ctx<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ctx").field("name", &self.name).field("out_dir", &self.out_dir).finish()
    }
}

impl<'a> Ctx<'a> {
    pub(crate) fn new(name: &'a str, options: &'a Options, out_dir: PathBuf) -> Ctx<'a> {
        Ctx {
            name,
            options,
            out_dir,
            scenario_source: String::new(),
            scenario_text: String::new(),
            scenario_dir: None,
            files: Vec::new(),
        }
    }

    /// Loads `--scenario` or the built-in scenario.
    pub(crate) fn scenario<T: DeserializeOwned + Validate>(&mut self, built_in: &str) -> Result<T> {
        let (text, source, dir) = match &self.options.scenario {
            Some(path) => {
                let text = std::fs::read_to_string(path)
                    .with_context(|| format!("cannot read scenario {}", path.display()))?;
                (text, path.display().to_string(), path.parent().map(Path::to_path_buf))
            }
            None => (
                built_in.to_owned(),
                format!(
                    "built-in scenario crates/experiments/scenarios/{}{}.toml",
                    match self.options.engine {
                        Engine::Sim => "",
                        Engine::Rcssservermj => "rcssservermj/",
                    },
                    self.name
                ),
                None,
            ),
        };
        let mut scenario: T = parse_scenario(&text, &source)?;
        scenario.validate(&Check { source_name: &source }, dir.as_deref())?;
        self.scenario_text = text;
        self.scenario_source = source;
        self.scenario_dir = dir;
        Ok(scenario)
    }

    /// Runs per condition: `--runs` or the scenario's.
    pub fn runs(&self, scenario_runs: usize) -> usize {
        self.options.runs.unwrap_or(scenario_runs).max(1)
    }

    pub fn seed(&self, run: usize) -> u64 {
        self.options.seed.wrapping_add(run as u64)
    }

    /// A progress bar over `total` units (simulated or real seconds).
    pub fn progress(&self, total: u64, what: &str) -> ProgressBar {
        if !self.options.progress {
            return ProgressBar::hidden();
        }
        let bar = ProgressBar::new(total.max(1));
        bar.set_style(
            ProgressStyle::with_template(
                "{spinner} {prefix} [{elapsed_precise}] {bar:40} {percent:>3}% eta {eta} {msg}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar.set_prefix(format!("{}: {what}", self.name));
        bar.enable_steady_tick(Duration::from_millis(250));
        bar
    }

    pub fn path(&mut self, file: &str) -> PathBuf {
        let path = self.out_dir.join(file);
        self.files.push(path.clone());
        path
    }

    pub fn plot(&mut self, figure: &impl plot::Figure, stem: &str) -> Result<String> {
        let files = plot::save(figure, &self.out_dir, stem)?;
        self.files.extend(files);
        Ok(format!("{stem}.png"))
    }

    /// The common head of every report: what ran, how to run it again, the scenario.
    pub fn report_head(&self, title: &str, paper: &str, md: &mut report::Markdown, runs: usize) {
        md.paragraph(paper);
        md.heading("What was run");
        let scenario_arg = match &self.options.scenario {
            Some(p) => format!(" --scenario {}", p.display()),
            None => String::new(),
        };
        let engine_arg = match self.options.engine {
            Engine::Sim => "",
            Engine::Rcssservermj => " --engine rcssservermj",
        };
        md.bullets(&[
            format!(
                "Command: `strata experiment {}{engine_arg} --runs {runs} --seed {}{scenario_arg}`",
                self.name, self.options.seed
            ),
            format!("Scenario: {}", self.scenario_source),
            format!("Runs per condition: {runs}; run k uses seed {} + k", self.options.seed),
            format!("Experiment: {title}"),
            format!("strata {}", env!("CARGO_PKG_VERSION")),
        ]);
    }

    /// Ends a report the same way for every experiment — where the raw data is (the files
    /// `raw_data` describes, then the summary), the scenario that was run — and writes it as
    /// `report.md`.
    pub fn finish_report(&mut self, mut md: report::Markdown, raw_data: &[&str]) -> Result<()> {
        md.heading("Raw data");
        let mut bullets = raw_data.to_vec();
        bullets.push("`summary.json`: the summary `--json` prints");
        md.bullets(&bullets);
        md.heading("Scenario");
        md.code("toml", &self.scenario_text);
        let report = self.path("report.md");
        md.write(&report)
    }
}

/// A scenario's own checks, after parsing.
pub trait Validate {
    fn validate(&mut self, check: &Check<'_>, dir: Option<&Path>) -> Result<(), ScenarioError>;
}

impl Ctx<'_> {
    /// Runs the experiment's jobs: all of them in this process (`parallel`), or, with
    /// `Options::records`, only some into the records directory (then stops the experiment
    /// before its report) or none, loading every job's result from the records.
    pub fn run_jobs<J: Sync, R: Send + Serialize + DeserializeOwned>(
        &self,
        jobs: &[J],
        f: impl Fn(usize, &J) -> Result<R> + Sync,
    ) -> Result<Vec<R>> {
        use records::{Manifest, RecordMode, Stop};
        let Some(records) = &self.options.records else {
            return parallel(jobs, self.options.threads, f);
        };
        let dir = &records.dir;
        let manifest = Manifest::new(self.name, &self.scenario_text, self.options.seed, jobs.len());
        match &records.mode {
            RecordMode::Plan => {
                manifest.write_or_check(dir)?;
                Err(Stop::Planned { jobs: jobs.len() }.into())
            }
            RecordMode::Run { only } => {
                manifest.write_or_check(dir)?;
                let mut wanted: Vec<usize> = match only {
                    Some(only) => only.clone(),
                    None => (0..jobs.len()).collect(),
                };
                wanted.sort_unstable();
                wanted.dedup();
                if let Some(bad) = wanted.iter().find(|i| **i >= jobs.len()) {
                    bail!(
                        "no job {bad}: `{}` has {} jobs (0 to {})",
                        self.name,
                        jobs.len(),
                        jobs.len().saturating_sub(1)
                    );
                }
                // A record present is a finished job (records appear whole): resume skips it.
                let (skipped, todo): (Vec<usize>, Vec<usize>) =
                    wanted.into_iter().partition(|i| records::record_path(dir, *i).exists());
                let written = parallel(&todo, self.options.threads, |_, i| {
                    let result = f(*i, &jobs[*i]).with_context(|| format!("job {i}"))?;
                    records::write(dir, *i, &result)?;
                    Ok(*i)
                })?;
                Err(Stop::Ran { jobs: jobs.len(), written, skipped }.into())
            }
            RecordMode::Merge => {
                manifest.check(dir)?;
                (0..jobs.len()).map(|i| records::read(dir, i, jobs.len())).collect()
            }
        }
    }
}

/// Runs `f` on every job, `threads` at a time, in job order of the results; stops at the first
/// error (the one of the lowest job index is returned).
pub fn parallel<J: Sync, R: Send>(
    jobs: &[J],
    threads: usize,
    f: impl Fn(usize, &J) -> Result<R> + Sync,
) -> Result<Vec<R>> {
    let next = AtomicUsize::new(0);
    let failed = AtomicBool::new(false);
    let results: Mutex<Vec<Option<Result<R>>>> =
        Mutex::new((0..jobs.len()).map(|_| None).collect());
    std::thread::scope(|scope| {
        for _ in 0..threads.clamp(1, jobs.len().max(1)) {
            scope.spawn(|| {
                loop {
                    if failed.load(Ordering::Relaxed) {
                        break;
                    }
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(job) = jobs.get(i) else { break };
                    let result = f(i, job);
                    if result.is_err() {
                        failed.store(true, Ordering::Relaxed);
                    }
                    results.lock().unwrap_or_else(|e| e.into_inner())[i] = Some(result);
                }
            });
        }
    });
    let results = results.into_inner().unwrap_or_else(|e| e.into_inner());
    let mut out = Vec::with_capacity(jobs.len());
    for (i, result) in results.into_iter().enumerate() {
        match result {
            Some(Ok(r)) => out.push(r),
            Some(Err(e)) => return Err(e.context(format!("run {i}"))),
            None => return Err(anyhow!("run {i} did not run (an earlier run failed)")),
        }
    }
    Ok(out)
}

/// A robot of a one-team scene.
#[derive(Clone, Debug)]
pub struct SceneRobot {
    pub player: u8,
    pub team: TeamConfig,
    /// Where it starts, team frame (own goal at -x).
    pub start: Pose,
    /// Its head's goal chosen from outside (the gaze environment, `goal_covering::gym`).
    pub gaze: Option<Arc<GazeOverride>>,
}

/// A world with some robots of one team, set to Playing, the referee manual (nothing moves
/// unless the experiment moves it): the stage of the goal-covering and fall experiments.
pub struct Scene {
    pub sim: SimHandle,
    pub graph: Option<Graph>,
    pub robots: Vec<(RobotId, RobotModules)>,
    pub field: Arc<TeamField>,
    /// Where to record the run, if it is the one `--log` asked for.
    pub log: Option<ExperimentLog>,
    /// What each robot was built from, by name: stored in the log for replay.
    robot_configs: BTreeMap<String, RobotRunConfig>,
}

/// `--log` of an experiment: the file, and the scenario (TOML) stored with the run.
#[derive(Clone, Debug)]
pub struct ExperimentLog {
    pub path: PathBuf,
    pub scenario_text: String,
}

/// The configuration an experiment's log holds (JSON): the scenario as it was given, and what
/// each robot's modules were built from, so that `strata replay` can rebuild them.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct ExperimentRunConfig {
    /// The scenario file's text (TOML).
    pub scenario: String,
    /// The host the run was on: a threaded run's publication times are the CPU's.
    pub host: HostKind,
    /// By robot name (`home/1`).
    pub robots: BTreeMap<String, RobotRunConfig>,
}

impl ExperimentLog {
    /// The log for job `index` of a run of `ctx`: only the first job is recorded.
    pub fn for_job(ctx: &Ctx<'_>, index: usize) -> Option<ExperimentLog> {
        let path = ctx.options.log.as_ref().filter(|_| index == 0)?;
        Some(ExperimentLog { path: path.clone(), scenario_text: ctx.scenario_text.clone() })
    }

    /// Creates the file with the run (seed, command line, scenario and robots) and the graph.
    fn create(
        &self,
        graph: &Graph,
        kind: HostKind,
        seed: u64,
        robots: &BTreeMap<String, RobotRunConfig>,
    ) -> Result<Arc<McapTap>> {
        let options = McapTapOptions {
            // Simulated time waits for the disk (a complete log); real time never does.
            when_full: match kind {
                HostKind::Lockstep => WhenFull::Wait,
                HostKind::Threaded => WhenFull::Drop,
            },
            ..McapTapOptions::default()
        };
        let config = ExperimentRunConfig {
            scenario: self.scenario_text.clone(),
            host: kind,
            robots: robots.clone(),
        };
        let config = serde_json::to_string_pretty(&config)
            .context("serializing the experiment's configuration")?;
        let run = RunInfo::current(seed).with_config(ConfigFormat::Json, config);
        // The scene is drawn on the first robot's field; the ground truth, where the run has
        // it, says which way each team attacks.
        let scene = robots.values().next().map(|first| {
            let mut scene = first.scene();
            for (name, robot) in robots {
                let team = usize::from(name.starts_with("away/"));
                scene.attack_sign[team] = robot.attack_sign;
            }
            scene
        });
        open_run_log(&self.path, options, &run, &graph.describe(), robots.keys().cloned(), scene)
    }
}

/// Finishes an experiment's log and says so on stderr (the report goes to its own files).
pub fn finish_log(log: &McapTap) {
    match log.finish() {
        Ok(summary) => eprintln!(
            "log: {} ({} messages, {} dropped, {:.1} MB)",
            log.path().display(),
            summary.messages,
            summary.dropped,
            summary.bytes as f64 / 1e6
        ),
        Err(error) => eprintln!("log: {error:#}"),
    }
}

impl std::fmt::Debug for Scene {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Scene").field("robots", &self.robots).finish_non_exhaustive()
    }
}

impl Scene {
    pub fn new(field: &str, noise: NoiseLevel, seed: u64, robots: &[SceneRobot]) -> Result<Scene> {
        let players = robots.iter().map(|r| r.player).max().unwrap_or(1).max(1);
        let mut config = SimConfig { seed, field: field.to_owned(), ..SimConfig::default() };
        config.noise.preset = noise;
        config.referee.auto = false;
        config.referee.players_per_team = players;
        // Perception runs on every frame its platform sends: robots that ask for another sensor
        // rate than the simulator's (goal covering: the paper's 57 Hz) get a simulator that
        // sends frames at it (the first robot's; its physics keeps steps of at most
        // `max_substep`). A rate within 1 % is the simulator's own (the default 83.3 Hz is its
        // 12 ms).
        if let Some(hz) = robots.iter().find_map(|r| r.team.timing.perception.rate_hz) {
            let period = 1.0 / hz;
            if (period - config.timing.sensor_period).abs() > 0.01 * config.timing.sensor_period {
                config.timing.sensor_period = period;
            }
        }
        config.validate("experiment scene").context("simulator configuration")?;
        let mut simulation = Simulation::new(config).context("building the simulated world")?;
        let keep: Vec<RobotId> = robots.iter().map(|r| RobotId::new(0, r.player)).collect();
        let all: Vec<RobotId> = simulation.robot_ids().collect();
        for id in all.into_iter().filter(|id| !keep.contains(id)) {
            simulation.remove_robot(id).context("removing a robot")?;
        }
        let attack_sign = simulation.game().attack_sign[0];
        let team_number = simulation.team_number(0);
        let team_field = Arc::new(TeamField::new(simulation.field().clone(), attack_sign));
        for robot in robots {
            simulation
                .teleport(RobotId::new(0, robot.player), team_field.pose_to_field(robot.start))
                .context("placing a robot")?;
        }
        simulation.set_game_state(GameState::Playing);
        let sim = SimHandle::new(simulation);
        let mut graph = GraphBuilder::new();
        let ids: Vec<RobotId> = robots.iter().map(|r| RobotId::new(0, r.player)).collect();
        let served = add_simulator(&mut graph, sim.clone(), &ids);
        let mut added = Vec::new();
        let mut robot_configs = BTreeMap::new();
        let platform = sim.lock().platform_info();
        for robot in robots {
            let id = RobotId::new(0, robot.player);
            robot_configs.insert(
                robot_name(id),
                RobotRunConfig {
                    robot: robot_name(id),
                    team: robot.team.clone(),
                    world: team_world_config(&robot.team, &team_field),
                    field: team_field.field.dimensions().clone(),
                    attack_sign,
                    platform: platform.clone(),
                },
            );
            let spec = SoccerRobotSpec {
                name: robot_name(id),
                team_number,
                player: robot.player,
                field: Arc::clone(&team_field),
                platform: served_platform(&served, id)?,
                links: served_links(&served, id)?,
                half_duration: 600.0,
                initial_pose: None,
                relocations: Vec::new(),
            };
            let modules =
                add_soccer_robot_with_gaze(&mut graph, spec, &robot.team, robot.gaze.clone())
                    .map_err(|e| anyhow!("robot {}: {e}", robot_name(id)))?;
            added.push((id, modules));
        }
        let graph = graph.build().context("wiring the experiment")?;
        Ok(Scene {
            sim,
            graph: Some(graph),
            robots: added,
            field: team_field,
            log: None,
            robot_configs,
        })
    }

    /// Starts a host over the scene's graph.
    pub fn host(&mut self, kind: HostKind, seed: u64, tap: Arc<dyn Tap>) -> Result<Host> {
        let graph = self.graph.take().context("the scene's graph was already taken")?;
        let log = match &self.log {
            Some(log) => Some(log.create(&graph, kind, seed, &self.robot_configs)?),
            None => None,
        };
        let tap: Arc<dyn Tap> = match &log {
            Some(log) => Arc::new(Taps(vec![tap, Arc::clone(log) as Arc<dyn Tap>])),
            None => tap,
        };
        let mut host = Host::start(graph, kind, seed, tap)?;
        host.log = log;
        Ok(host)
    }
}

/// Which host runs an experiment's graph.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum HostKind {
    /// Real time, one thread per module (the paper's setting).
    Threaded,
    /// Simulated time, deterministic, faster than real time.
    Lockstep,
}

/// A running host the experiment drives in steps, and its log if the run is recorded.
#[derive(Debug)]
pub struct Host {
    running: Running,
    log: Option<Arc<McapTap>>,
}

enum Running {
    Lockstep(Box<LockstepHost>),
    Threaded { host: RunningHost, started: Instant, elapsed: Duration },
}

impl std::fmt::Debug for Running {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Running::Lockstep(_) => "Lockstep",
            Running::Threaded { .. } => "Threaded",
        })
    }
}

impl Host {
    pub fn start(graph: Graph, kind: HostKind, seed: u64, tap: Arc<dyn Tap>) -> Result<Host> {
        let running = match kind {
            HostKind::Lockstep => {
                let mut host = LockstepHost::new(graph, HostConfig::with_seed(seed));
                host.set_tap(tap);
                Running::Lockstep(Box::new(host))
            }
            HostKind::Threaded => {
                let mut host = ThreadedHost::new(graph, HostConfig::with_seed(seed));
                host.set_tap(tap);
                let host = host.start().context("starting the module threads")?;
                Running::Threaded { host, started: Instant::now(), elapsed: Duration::ZERO }
            }
        };
        Ok(Host { running, log: None })
    }

    /// Lets `dt` of host time pass: simulated on the lockstep host, real (on a fixed schedule,
    /// so sampling does not drift) on the threaded one.
    pub fn advance(&mut self, dt: Duration) -> Result<()> {
        match &mut self.running {
            Running::Lockstep(host) => host.run_for(dt).map_err(|e| anyhow!("{e}")),
            Running::Threaded { started, elapsed, .. } => {
                *elapsed += dt;
                let target = *started + *elapsed;
                let now = Instant::now();
                if target > now {
                    std::thread::sleep(target - now);
                }
                Ok(())
            }
        }
    }

    pub fn finish(self) -> Result<HostStats> {
        let stats = match self.running {
            Running::Lockstep(mut host) => {
                host.stop();
                Ok(host.stats())
            }
            Running::Threaded { host, .. } => host.stop().map_err(|e| anyhow!("{e}")),
        };
        if let Some(log) = &self.log {
            finish_log(log);
        }
        stats
    }
}
