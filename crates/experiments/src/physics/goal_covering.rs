//! `strata experiment goal-covering --engine rcssservermj` (paper 4.2, Table 5): a Booster T1
//! goalkeeper in rcssservermj covers its goal while the server's monitor port moves the ball
//! along each trajectory; the deliberative layer runs at each of the scenario's rates, and the
//! paper's method (value functions and active vision) is run against the gaze baselines.
//!
//! One server and one keeper per run, runs one after the other (the machine's cores go to the
//! physics). The keeper is a `strata robot` process; its status lines carry the world model's
//! ball (`ball`: known, estimate) and pose against the server's truth (`pose`). Each
//! `placement_period` of simulated time the ball is placed on its path and the newest status
//! line is sampled, so samples are even in the server's time, not the wall's. Measured:
//! - ball unknown: the fraction of samples whose world model does not know the ball (Table 5,
//!   column 3), over all samples and over those with the ball within the camera model's ball
//!   range of the keeper. The paper's ball was always within its robot's sight; scaled to this
//!   field, a trajectory can start beyond the T1's (the diagonal, for its first 4 s), where no
//!   gaze can see it. The targets compare the in-range figure with the paper's;
//! - ball error: distance of the known ball estimate from the server's ball, m (the status
//!   line can be one status interval older than the ball's truth);
//! - pose error: the world model's pose against the server's truth, m.
//!
//! "Observe ball" (Table 5, column 2) needs the head multiplexer's goal, which the status line
//! does not carry: it is not measured here.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, bail};
use serde::{Deserialize, Serialize};
use strata_rcssmj::camera::CameraConfig;
use strata_rcssmj::protocol::FieldSide;
use strata_rcssmj::protocol::monitor::{MonitorCommand, MonitorState};
use strata_rcssmj::server::{ServerOptions, ServerProcess};
use strata_soccer::team::TeamConfig;

use crate::goal_covering::check_methods_and_trajectories;
pub use crate::goal_covering::{Method, Trajectory};
use crate::plot::Bars;
use crate::report::{Markdown, num, pct, verdict, write_csv};
use crate::stats::Estimate;
use crate::{Check, Ctx, ScenarioError, Validate};
use strata_games::physics::robot::{T1Launch, T1Process, strata_exe};

pub const NAME: &str = "goal-covering";
pub const DEFAULT_SCENARIO: &str = include_str!("../../scenarios/rcssservermj/goal-covering.toml");

/// The left team's number and server name: its team frame is the server's world frame.
const TEAM: u8 = 1;
const TEAM_NAME: &str = "Strata1";
const KEEPER: u8 = 1;
/// How long the server's clock may stand still (wall time) before a run fails: a robot
/// process starting on a loaded machine takes a while to join.
const STALL: Duration = Duration::from_secs(180);

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    #[serde(default)]
    pub description: String,
    /// Runs per (method, rate, trajectory).
    pub runs: usize,
    /// Ball speed along every trajectory, m/s.
    pub ball_speed: f64,
    /// Deliberative-layer rates, Hz.
    pub deliberative_hz: Vec<f64>,
    /// Where the server places the keeper: x, y (m, team frame), heading (degrees).
    pub keeper_beam: [f64; 3],
    /// Simulated seconds of Ready after the keeper is on the field, before the kick-off.
    pub ready: f64,
    /// Simulated seconds after the kick-off before the ball starts; not measured.
    pub warmup: f64,
    /// Simulated seconds measured after the ball stops.
    pub settle: f64,
    /// Simulated seconds between ball placements and samples.
    pub placement_period: f64,
    /// Seconds between the robot's status lines.
    pub status_interval: f64,
    /// The method the targets apply to.
    pub reference: String,
    pub methods: Vec<Method>,
    pub trajectories: Vec<Trajectory>,
    #[serde(default)]
    pub paper: Vec<PaperRow>,
    /// The 2D simulator's figures per method, for the report.
    #[serde(default)]
    pub figures_2d: Vec<Figures2d>,
    #[serde(skip)]
    resolved: Vec<TeamConfig>,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PaperRow {
    pub deliberative_hz: f64,
    pub observe_ball: f64,
    pub ball_unknown: f64,
    pub target_ball_unknown: f64,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Figures2d {
    pub method: String,
    /// [deliberative Hz, ball unknown (fraction), mean pose error (m)].
    pub values: Vec<[f64; 3]>,
}

impl Validate for Scenario {
    fn validate(&mut self, check: &Check<'_>, dir: Option<&Path>) -> Result<(), ScenarioError> {
        check.at_least("runs", self.runs, 1)?;
        check.positive("ball_speed", self.ball_speed)?;
        check.not_empty("deliberative_hz", &self.deliberative_hz)?;
        for (i, hz) in self.deliberative_hz.iter().enumerate() {
            check.positive(&format!("deliberative_hz[{i}]"), *hz)?;
        }
        if !self.keeper_beam.iter().all(|v| v.is_finite()) {
            return Err(check.fail("keeper_beam", "must be three finite numbers"));
        }
        check.non_negative("ready", self.ready)?;
        check.non_negative("warmup", self.warmup)?;
        check.non_negative("settle", self.settle)?;
        check.positive("placement_period", self.placement_period)?;
        check.positive("status_interval", self.status_interval)?;
        self.resolved = check_methods_and_trajectories(
            check,
            dir,
            &self.methods,
            &self.reference,
            &self.trajectories,
        )?;
        for (i, row) in self.paper.iter().enumerate() {
            check.fraction(&format!("paper[{i}].ball_unknown"), row.ball_unknown)?;
            check.fraction(&format!("paper[{i}].target_ball_unknown"), row.target_ball_unknown)?;
        }
        Ok(())
    }
}

impl Scenario {
    fn paper_row(&self, hz: f64) -> Option<&PaperRow> {
        self.paper.iter().find(|r| same_hz(r.deliberative_hz, hz))
    }

    /// The 2D figures of `method` at `hz`: (ball unknown, mean pose error m).
    fn figures_2d(&self, method: &str, hz: f64) -> Option<(f64, f64)> {
        self.figures_2d
            .iter()
            .find(|f| f.method == method)?
            .values
            .iter()
            .find(|v| same_hz(v[0], hz))
            .map(|v| (v[1], v[2]))
    }
}

fn same_hz(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

// ---------------------------------------------------------------------------------------------
// One run.

/// What one run measured.
#[derive(Clone, Debug, Serialize)]
pub struct Run {
    pub method: String,
    pub deliberative_hz: f64,
    pub trajectory: String,
    pub run: usize,
    pub seed: u64,
    pub samples: usize,
    /// Fraction of samples with the ball not known.
    pub ball_unknown: f64,
    /// The same over the samples with the ball within the camera's ball range of the keeper
    /// (NaN when there were none).
    pub ball_unknown_in_range: f64,
    /// Fraction of the samples with the ball within that range.
    pub in_range: f64,
    /// Mean distance of the known ball estimate from the server's ball, m (NaN if never known).
    pub ball_error_m: f64,
    /// Mean distance of the pose estimate from the server's truth over the samples, m.
    pub pose_error_m: f64,
    pub falls: usize,
    /// Simulated seconds per wall second over the run.
    pub real_time_factor: f64,
}

/// One sample: the world model's ball and pose as the newest status line gave them.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample {
    pub ball_known: bool,
    pub ball_error: f64,
    pub pose_error: f64,
    /// The server's ball within the camera model's ball range of the keeper's torso.
    pub in_range: bool,
}

/// The camera model's ball range, m: how far the keeper's camera reports a ball at all.
fn ball_range() -> f64 {
    CameraConfig::default().ball.max_range
}

/// Over the samples with the ball in range: (fraction with the ball unknown, fraction of all
/// samples in range).
pub fn in_range_metrics(samples: &[Sample]) -> (f64, f64) {
    let in_range: Vec<&Sample> = samples.iter().filter(|s| s.in_range).collect();
    let share = in_range.len() as f64 / samples.len().max(1) as f64;
    if in_range.is_empty() {
        return (f64::NAN, share);
    }
    let unknown = in_range.iter().filter(|s| !s.ball_known).count() as f64;
    (unknown / in_range.len() as f64, share)
}

/// The run's figures from its samples: (ball unknown, ball error, pose error).
pub fn metrics(samples: &[Sample]) -> (f64, f64, f64) {
    if samples.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    let unknown = samples.iter().filter(|s| !s.ball_known).count() as f64 / samples.len() as f64;
    let finite_mean = |values: Vec<f64>| {
        let values: Vec<f64> = values.into_iter().filter(|v| v.is_finite()).collect();
        if values.is_empty() { f64::NAN } else { values.iter().sum::<f64>() / values.len() as f64 }
    };
    let ball = finite_mean(samples.iter().filter(|s| s.ball_known).map(|s| s.ball_error).collect());
    let pose = finite_mean(samples.iter().map(|s| s.pose_error).collect());
    (unknown, ball, pose)
}

/// Reads one sample from a status line, the server's ball and the keeper's torso (world frame
/// = team frame).
fn sample_of(
    status: &serde_json::Value,
    ball: Option<[f64; 3]>,
    keeper: Option<[f64; 3]>,
) -> Sample {
    let known = status.pointer("/ball/known").and_then(serde_json::Value::as_bool) == Some(true);
    let estimate = status
        .pointer("/ball/estimate")
        .and_then(|e| Some([e.get(0)?.as_f64()?, e.get(1)?.as_f64()?]));
    let ball_error = match (estimate, ball) {
        (Some(e), Some(b)) if known => (e[0] - b[0]).hypot(e[1] - b[1]),
        _ => f64::NAN,
    };
    let pose_error =
        status.pointer("/pose/error_m").and_then(serde_json::Value::as_f64).unwrap_or(f64::NAN);
    let in_range = match (ball, keeper) {
        (Some(b), Some(k)) => (b[0] - k[0]).hypot(b[1] - k[1]) <= ball_range(),
        _ => false,
    };
    Sample { ball_known: known, ball_error, pose_error, in_range }
}

struct Job<'a> {
    method: &'a Method,
    team_file: &'a Path,
    hz: f64,
    trajectory: &'a Trajectory,
    run: usize,
    seed: u64,
    /// The keeper's log (`--log`: the first run only).
    log: Option<PathBuf>,
}

fn run_one(
    scenario: &Scenario,
    exe: &Path,
    job: &Job<'_>,
    progress: &mut dyn FnMut(f64),
) -> Result<Run> {
    strata_games::physics::check_interrupt()?;
    let server =
        ServerProcess::start(&ServerOptions::default()).context("starting rcssservermj")?;
    let wall = Instant::now();
    let launch = T1Launch {
        exe: exe.to_owned(),
        server: server.agent_address(),
        team: TEAM,
        team_name: TEAM_NAME.to_owned(),
        player: KEEPER,
        beam: scenario.keeper_beam,
        team_config: job.team_file.display().to_string(),
        seed: job.seed,
        team_port: None,
        log: job.log.clone(),
        status_interval: scenario.status_interval,
        duration: None,
        extra: Vec::new(),
    };
    let mut keeper = T1Process::spawn(&launch)?;
    let result = follow_run(scenario, &server, &mut keeper, job, progress);
    // Stop the robot before the server so it does not report a lost server.
    keeper.interrupt();
    let (report, _) = keeper.finish(Duration::from_secs(30));
    let (samples, play_s) = result
        .with_context(|| format!("the keeper's stderr, last lines: {}", keeper.stderr_tail(5)))?;
    drop(server);
    let (ball_unknown, ball_error_m, pose_error_m) = metrics(&samples);
    let (ball_unknown_in_range, in_range) = in_range_metrics(&samples);
    let falls = report
        .as_ref()
        .and_then(|r| r.get("falls"))
        .and_then(serde_json::Value::as_array)
        .map_or(0, Vec::len);
    Ok(Run {
        method: job.method.name.clone(),
        deliberative_hz: job.hz,
        trajectory: job.trajectory.name.clone(),
        run: job.run,
        seed: job.seed,
        samples: samples.len(),
        ball_unknown,
        ball_unknown_in_range,
        in_range,
        ball_error_m,
        pose_error_m,
        falls,
        real_time_factor: play_s / wall.elapsed().as_secs_f64().max(1e-9),
    })
}

/// Waits for the server's time to pass `until`, failing when the keeper exits or the server
/// stalls; returns the newest monitor state.
fn wait_for_time(
    server: &ServerProcess,
    keeper: &mut T1Process,
    until: impl Fn(&MonitorState) -> bool,
    what: &str,
) -> Result<MonitorState> {
    let started = Instant::now();
    let mut last_time = None;
    let mut last_change = Instant::now();
    loop {
        strata_games::physics::check_interrupt()?;
        let truth = server.truth();
        if until(&truth) {
            return Ok(truth);
        }
        if let Some(status) = keeper.exited() {
            bail!("the keeper exited ({status}) while waiting for {what}");
        }
        if truth.sim_time != last_time {
            last_time = truth.sim_time;
            last_change = Instant::now();
        } else if last_change.elapsed() > STALL {
            bail!(
                "rcssservermj's clock stood still for {:?} while waiting for {what} ({:?} in all)",
                STALL,
                started.elapsed()
            );
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// The run from the keeper joining to the ball's settling: the samples and the simulated
/// seconds played.
fn follow_run(
    scenario: &Scenario,
    server: &ServerProcess,
    keeper: &mut T1Process,
    job: &Job<'_>,
    progress: &mut dyn FnMut(f64),
) -> Result<(Vec<Sample>, f64)> {
    let on_field = |s: &MonitorState| {
        s.sim_time.is_some()
            && s.robots.iter().any(|r| r.team == TEAM_NAME && r.player == u32::from(KEEPER))
    };
    let joined = wait_for_time(server, keeper, on_field, "the keeper on the field")?;
    let start = joined.sim_time.unwrap_or(0.0);
    let kick_off = start + scenario.ready;
    wait_for_time(server, keeper, |s| s.sim_time.is_some_and(|t| t >= kick_off), "Ready")?;
    server.command(vec![MonitorCommand::KickOff(Some(FieldSide::Left))]);
    let ball_start = kick_off + scenario.warmup;
    let first = job.trajectory.at(0.0).0;
    server.command(vec![place(first, [0.0; 2], 0.0)]);
    wait_for_time(server, keeper, |s| s.sim_time.is_some_and(|t| t >= ball_start), "warm-up")?;
    let moving = job.trajectory.length() / scenario.ball_speed;
    let end = ball_start + moving + scenario.settle;
    let mut samples = Vec::new();
    let mut next = ball_start;
    while next <= end {
        let truth = wait_for_time(
            server,
            keeper,
            |s| s.sim_time.is_some_and(|t| t >= next),
            "the ball's next placement",
        )?;
        let now = truth.sim_time.unwrap_or(next);
        if now > ball_start
            && let Some(status) = keeper.latest("status")
        {
            let keeper = truth
                .robots
                .iter()
                .find(|r| r.team == TEAM_NAME && r.player == u32::from(KEEPER))
                .map(|r| r.position);
            samples.push(sample_of(&status, truth.ball_position, keeper));
        }
        let along = (now - ball_start) * scenario.ball_speed;
        let (position, direction) = job.trajectory.at(along);
        let speed = if along < job.trajectory.length() { scenario.ball_speed } else { 0.0 };
        server.command(vec![place(position, direction, speed)]);
        progress(((now - start) / (end - start)).clamp(0.0, 1.0));
        next += scenario.placement_period;
    }
    Ok((samples, end - start))
}

fn place(position: [f64; 2], direction: [f64; 2], speed: f64) -> MonitorCommand {
    MonitorCommand::PlaceBall {
        position: [position[0], position[1], 0.11],
        velocity: Some([direction[0] * speed, direction[1] * speed, 0.0]),
    }
}

// ---------------------------------------------------------------------------------------------
// The experiment.

/// One (method, rate) over its runs and trajectories.
#[derive(Clone, Debug, Serialize)]
pub struct Condition {
    pub method: String,
    pub deliberative_hz: f64,
    pub runs: usize,
    pub ball_unknown: Estimate,
    /// Over the samples with the ball within the camera's range (the paper's condition).
    pub ball_unknown_in_range: Estimate,
    pub ball_error_m: Estimate,
    pub pose_error_m: Estimate,
    pub falls: usize,
    /// The 2D simulator's ball unknown and mean pose error (docs/experiments.md).
    pub ball_unknown_2d: Option<f64>,
    pub pose_error_2d_m: Option<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Target {
    pub deliberative_hz: f64,
    pub paper_ball_unknown: f64,
    /// Over every sample.
    pub ball_unknown: f64,
    /// Over the samples with the ball within the camera's range: what the target compares.
    pub ball_unknown_in_range: f64,
    /// The reference method loses a ball it could see no more often than the paper's robot.
    pub met: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub experiment: String,
    pub engine: String,
    pub reference: String,
    pub ball_speed: f64,
    pub runs: Vec<Run>,
    pub conditions: Vec<Condition>,
    pub targets: Vec<Target>,
}

pub fn run(scenario: &Scenario, ctx: &mut Ctx<'_>) -> Result<Summary> {
    let runs = ctx.runs(scenario.runs);
    if scenario.resolved.len() != scenario.methods.len() {
        bail!("the scenario was not validated");
    }
    let exe = strata_exe(ctx.options.strata_exe.as_deref())?;
    // A team file per (method, rate): the robots read their teams from files.
    let teams_dir =
        std::env::temp_dir().join(format!("strata-goal-covering-3d-{}", std::process::id()));
    std::fs::create_dir_all(&teams_dir)
        .with_context(|| format!("creating {}", teams_dir.display()))?;
    let mut team_files = Vec::new();
    for (m, method) in scenario.methods.iter().enumerate() {
        for (r, hz) in scenario.deliberative_hz.iter().enumerate() {
            let mut team = scenario.resolved[m].clone();
            team.timing.deliberative.rate_hz = Some(*hz);
            team_files.push(write_team(&teams_dir, &format!("{}-{r}", method.name), &team)?);
        }
    }
    let rates = scenario.deliberative_hz.len();
    let total = scenario.methods.len() * rates * scenario.trajectories.len() * runs;
    let bar = ctx.progress((total * 100) as u64, "keeper runs in physics");
    let mut results = Vec::new();
    let mut index = 0;
    for (m, method) in scenario.methods.iter().enumerate() {
        for (r, hz) in scenario.deliberative_hz.iter().enumerate() {
            for trajectory in &scenario.trajectories {
                for run in 0..runs {
                    let job = Job {
                        method,
                        team_file: &team_files[m * rates + r],
                        hz: *hz,
                        trajectory,
                        run,
                        seed: ctx.seed(run),
                        log: if index == 0 { ctx.options.log.clone() } else { None },
                    };
                    bar.set_message(format!(
                        "run {} of {total}: {} at {hz} Hz, {}",
                        index + 1,
                        method.name,
                        trajectory.name
                    ));
                    let done = index as f64;
                    let outcome = run_one(scenario, &exe, &job, &mut |fraction| {
                        bar.set_position(((done + fraction) * 100.0) as u64);
                    })
                    .with_context(|| {
                        format!(
                            "{} at {hz} Hz on `{}`, run {} (seed {})",
                            method.name, trajectory.name, run, job.seed
                        )
                    })?;
                    results.push(outcome);
                    index += 1;
                }
            }
        }
    }
    bar.finish_and_clear();
    let _ = std::fs::remove_dir_all(&teams_dir);

    let mut conditions = Vec::new();
    for method in &scenario.methods {
        for hz in &scenario.deliberative_hz {
            let of: Vec<&Run> = results
                .iter()
                .filter(|r| r.method == method.name && same_hz(r.deliberative_hz, *hz))
                .collect();
            let e = |f: &dyn Fn(&Run) -> f64| {
                Estimate::of(&of.iter().map(|r| f(r)).collect::<Vec<_>>())
            };
            let figures_2d = scenario.figures_2d(&method.name, *hz);
            conditions.push(Condition {
                method: method.name.clone(),
                deliberative_hz: *hz,
                runs: of.len(),
                ball_unknown: e(&|r| r.ball_unknown),
                ball_unknown_in_range: e(&|r| r.ball_unknown_in_range),
                ball_error_m: e(&|r| r.ball_error_m),
                pose_error_m: e(&|r| r.pose_error_m),
                falls: of.iter().map(|r| r.falls).sum(),
                ball_unknown_2d: figures_2d.map(|f| f.0),
                pose_error_2d_m: figures_2d.map(|f| f.1),
            });
        }
    }
    let targets = scenario
        .deliberative_hz
        .iter()
        .filter_map(|hz| {
            let paper = scenario.paper_row(*hz)?;
            let ours = conditions
                .iter()
                .find(|c| c.method == scenario.reference && same_hz(c.deliberative_hz, *hz))?;
            Some(Target {
                deliberative_hz: *hz,
                paper_ball_unknown: paper.ball_unknown,
                ball_unknown: ours.ball_unknown.mean,
                ball_unknown_in_range: ours.ball_unknown_in_range.mean,
                met: ours.ball_unknown_in_range.mean <= paper.ball_unknown,
            })
        })
        .collect();
    let summary = Summary {
        experiment: NAME.to_owned(),
        engine: "rcssservermj".to_owned(),
        reference: scenario.reference.clone(),
        ball_speed: scenario.ball_speed,
        runs: results,
        conditions,
        targets,
    };
    write_outputs(scenario, &summary, ctx, runs)?;
    Ok(summary)
}

fn write_team(dir: &Path, stem: &str, team: &TeamConfig) -> Result<PathBuf> {
    let path = dir.join(format!("{stem}.toml"));
    let text = toml::to_string(team).context("writing a team configuration")?;
    std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

fn hz_label(hz: f64) -> String {
    format!("{hz} Hz")
}

fn write_outputs(
    scenario: &Scenario,
    summary: &Summary,
    ctx: &mut Ctx<'_>,
    runs: usize,
) -> Result<()> {
    write_runs_csv(summary, ctx)?;
    let image = ctx.plot(&ball_unknown_figure(scenario, summary), "ball-unknown")?;
    let mut md = Markdown::new("Goal covering in physics: a T1 keeper's ball perception");
    ctx.report_head(
        "a Booster T1 goalkeeper in rcssservermj, the ball moved by the monitor port",
        "Paper 4.2, Table 5: the goalkeeper covers its goal while the ball moves; the \
         deliberative layer runs at several rates. Here the keeper is a `strata robot` process \
         on a T1 in the RoboCup simulation league's MuJoCo server, one server and one keeper \
         per run, the 2D trajectories scaled by 4 about the goal and the ball's speed with them.",
        &mut md,
        runs,
    );
    md.paragraph(&format!(
        "Ball speed {} m/s; deliberative layer at {} Hz; ball placed and sampled every {} s of \
         simulated time from the ball's start to {} s after it stops; keeper beamed at {:?}, \
         {} s of Ready, kick-off, {} s before the ball starts. Trajectories: {}.",
        scenario.ball_speed,
        scenario.deliberative_hz.iter().map(|h| h.to_string()).collect::<Vec<_>>().join(", "),
        scenario.placement_period,
        scenario.settle,
        scenario.keeper_beam,
        scenario.ready,
        scenario.warmup,
        scenario
            .trajectories
            .iter()
            .map(|t| format!("`{}` ({:.1} m)", t.name, t.length()))
            .collect::<Vec<_>>()
            .join(", ")
    ));
    report_tables(&mut md, scenario, summary);
    md.image("ball unknown", &image);
    ctx.finish_report(
        md,
        &["`goal-covering.csv`: one row per run (method, rate, trajectory, seed)"],
    )
}

/// `goal-covering.csv`: one row per run.
fn write_runs_csv(summary: &Summary, ctx: &mut Ctx<'_>) -> Result<()> {
    let rows: Vec<Vec<String>> = summary
        .runs
        .iter()
        .map(|r| {
            vec![
                r.method.clone(),
                num(r.deliberative_hz),
                r.trajectory.clone(),
                r.run.to_string(),
                r.seed.to_string(),
                r.samples.to_string(),
                num(r.ball_unknown),
                num(r.ball_unknown_in_range),
                num(r.in_range),
                num(r.ball_error_m),
                num(r.pose_error_m),
                r.falls.to_string(),
                num(r.real_time_factor),
            ]
        })
        .collect();
    let csv = ctx.path("goal-covering.csv");
    write_csv(
        &csv,
        &[
            "method",
            "deliberative_hz",
            "trajectory",
            "run",
            "seed",
            "samples",
            "ball_unknown",
            "ball_unknown_in_range",
            "in_range",
            "ball_error_m",
            "pose_error_m",
            "falls",
            "real_time_factor",
        ],
        &rows,
    )
}

/// The fraction of time the ball is unknown, per method and rate, beside the paper's.
fn ball_unknown_figure(scenario: &Scenario, summary: &Summary) -> Bars {
    let condition = |method: &str, hz: f64| {
        summary.conditions.iter().find(|c| c.method == method && same_hz(c.deliberative_hz, hz))
    };
    Bars {
        title: format!(
            "Ball unknown while in the camera's range, T1 keeper in rcssservermj, ball at {} m/s \
             (mean, 95 % CI)",
            scenario.ball_speed
        ),
        y_label: "fraction of time the ball is unknown".to_owned(),
        groups: scenario.deliberative_hz.iter().map(|h| hz_label(*h)).collect(),
        series: scenario
            .methods
            .iter()
            .map(|m| {
                let values = scenario
                    .deliberative_hz
                    .iter()
                    .map(|hz| {
                        condition(&m.name, *hz).map(|c| c.ball_unknown_in_range).unwrap_or_default()
                    })
                    .collect();
                (m.name.clone(), values)
            })
            .collect(),
        reference: Some((
            "paper (Table 5)".to_owned(),
            scenario
                .deliberative_hz
                .iter()
                .map(|hz| scenario.paper_row(*hz).map(|p| p.ball_unknown))
                .collect(),
        )),
        targets: None,
    }
}

/// The targets and Table 5 in physics, beside the paper and the 2D simulator.
fn report_tables(md: &mut Markdown, scenario: &Scenario, summary: &Summary) {
    md.heading("Targets");
    md.table(
        &[
            "deliberative Hz",
            "paper: ball unknown",
            "measured: ball in range",
            "all samples",
            "at least as good as the paper",
        ],
        &summary
            .targets
            .iter()
            .map(|t| {
                vec![
                    t.deliberative_hz.to_string(),
                    pct(t.paper_ball_unknown),
                    pct(t.ball_unknown_in_range),
                    pct(t.ball_unknown),
                    verdict(t.met),
                ]
            })
            .collect::<Vec<_>>(),
    );
    md.heading("Table 5 in physics, with the paper and the 2D simulator");
    let opt_pct = |v: Option<f64>| v.map_or_else(|| "-".to_owned(), pct);
    let opt_cm = |v: Option<f64>| v.map_or_else(|| "-".to_owned(), |m| format!("{:.1}", m * 100.0));
    md.table(
        &[
            "method",
            "deliberative Hz",
            "runs",
            "ball unknown (physics, ball in range)",
            "all samples",
            "ball unknown (2D)",
            "ball unknown (paper)",
            "ball error, cm",
            "pose error, cm (physics)",
            "pose error, cm (2D)",
            "falls",
        ],
        &summary
            .conditions
            .iter()
            .map(|c| {
                let paper = (c.method == scenario.reference)
                    .then(|| scenario.paper_row(c.deliberative_hz).map(|p| p.ball_unknown))
                    .flatten();
                vec![
                    c.method.clone(),
                    c.deliberative_hz.to_string(),
                    c.runs.to_string(),
                    format!("{}%", c.ball_unknown_in_range.show(100.0, 1)),
                    format!("{}%", c.ball_unknown.show(100.0, 1)),
                    opt_pct(c.ball_unknown_2d),
                    opt_pct(paper),
                    c.ball_error_m.show(100.0, 1),
                    c.pose_error_m.show(100.0, 1),
                    opt_cm(c.pose_error_2d_m),
                    c.falls.to_string(),
                ]
            })
            .collect::<Vec<_>>(),
    );
    md.paragraph(
        "The 2D figures are the scenario's `figures_2d`, measured with `strata experiment \
         goal-covering` on the paper's 6 x 4 m field (docs/experiments.md says when). Ball unknown: the fraction of \
         samples whose world model does not know the ball, over the samples with the server's \
         ball within the camera model's ball range of the keeper (the paper's condition: its \
         ball was always within sight; the targets compare this one) and over all samples; \
         ball error: the known estimate \
         against the server's ball (the status line may be up to one status interval older); \
         pose error: the world model's pose against the server's truth. \"Observe ball\" \
         (Table 5's other column) is not measured in physics: the robot's status line does not \
         carry the head multiplexer's goal. A run does not repeat exactly for a seed: MuJoCo \
         steps in the server's process, the robot runs in real time on threads.",
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ball_moves_along_the_path_and_stops_at_its_end() {
        let path =
            Trajectory { name: "l".into(), waypoints: vec![[0.0, 0.0], [3.0, 0.0], [3.0, 4.0]] };
        assert_eq!(path.length(), 7.0);
        assert_eq!(path.at(1.0), ([1.0, 0.0], [1.0, 0.0]));
        assert_eq!(path.at(5.0), ([3.0, 2.0], [0.0, 1.0]));
        assert_eq!(path.at(9.0), ([3.0, 4.0], [0.0, 1.0]));
    }

    #[test]
    fn a_ball_unknown_a_quarter_of_the_samples_gives_25_percent() {
        let known = Sample { ball_known: true, ball_error: 0.2, pose_error: 0.1, in_range: true };
        let unknown =
            Sample { ball_known: false, ball_error: f64::NAN, pose_error: 0.3, in_range: true };
        let (unknown_share, ball, pose) = metrics(&[known, known, known, unknown]);
        assert_eq!(unknown_share, 0.25);
        assert!((ball - 0.2).abs() < 1e-12);
        assert!((pose - 0.15).abs() < 1e-12);
    }

    /// A ball beyond the camera's range is unknown to any gaze: the in-range figure leaves
    /// those samples out, the all-samples figure keeps them.
    #[test]
    fn samples_beyond_the_camera_range_count_only_in_the_all_samples_figure() {
        let status = |known: bool| serde_json::json!({"ball": {"known": known}});
        let keeper = Some([-27.0, 0.0, 0.7]);
        let far = sample_of(&status(false), Some([-27.0 + ball_range() + 0.5, 0.0, 0.1]), keeper);
        let near_lost = sample_of(&status(false), Some([-22.0, 3.0, 0.1]), keeper);
        let near_seen = sample_of(&status(true), Some([-22.0, -3.0, 0.1]), keeper);
        assert!(!far.in_range && near_lost.in_range && near_seen.in_range);
        let samples = [far, far, near_lost, near_seen];
        assert_eq!(metrics(&samples).0, 0.75);
        assert_eq!(in_range_metrics(&samples), (0.5, 0.5));
        // Without the keeper's truth a sample is not counted as in range.
        assert!(!sample_of(&status(false), Some([-22.0, 3.0, 0.1]), None).in_range);
        assert!(in_range_metrics(&[far]).0.is_nan());
    }

    #[test]
    fn a_status_line_without_a_known_ball_is_a_ball_unknown_sample() {
        let status = serde_json::json!({
            "ball": {"known": false, "confidence": 0.1, "estimate": null},
            "pose": {"error_m": 0.12},
        });
        let sample = sample_of(&status, Some([1.0, 2.0, 0.1]), None);
        assert!(!sample.ball_known);
        assert!(sample.ball_error.is_nan());
        assert_eq!(sample.pose_error, 0.12);
        let status = serde_json::json!({"ball": {"known": true, "estimate": [1.0, 2.5]}});
        let sample = sample_of(&status, Some([1.0, 2.0, 0.1]), None);
        assert!((sample.ball_error - 0.5).abs() < 1e-12);
    }

    #[test]
    fn the_built_in_scenario_is_valid_and_keeps_the_ball_away_from_the_keeper() {
        let scenario: Scenario = toml::from_str(DEFAULT_SCENARIO).expect("the scenario parses");
        assert_eq!(scenario.methods.len(), 4);
        for t in &scenario.trajectories {
            for [x, y] in &t.waypoints {
                // The keeper covers from about (-27, 0); it clears a ball within 1.2 m.
                assert!((x + 27.0).hypot(*y) > 2.5, "{}: ({x}, {y})", t.name);
                assert!(*x > -27.5 && y.abs() < 18.0, "{}: off the field", t.name);
            }
        }
    }
}
