//! `strata experiment rates --engine rcssservermj` (paper 4.3, Table 6, in physics): walking
//! Booster T1s under the full architecture, every layer's frequency, compute time and period
//! measured, and every fall counted, without and with an artificial computation in every
//! deliberative cycle (200 ms by default).
//!
//! On the 2D simulator no gait depends on the reactive layer; here it does: the reactive layer
//! drives the T1's walking policy every 20 ms server cycle, so "deliberation does not disturb
//! the reactivity a biped's gait needs" shows in two numbers: the reactive layer's rate under
//! load against its rate without, and falls per walking minute under load against without.
//!
//! Each run of a condition: a server of its own (sync mode, paced to real time by the robots),
//! one `strata robot --platform rcssservermj` process per robot with the condition's team file,
//! the trainer ([`trainer`]) kicking off and moving the ball, the ground truth measuring how
//! long each robot walked ([`walking`]); the robots are stopped with SIGINT after `duration`
//! simulated seconds from the kick-off, and their reports give the rates and the falls.
//! Conditions alternate within a run (never side by side: they would share the cores). With
//! `[sim]`, the 2D rates experiment runs in the same command for the 2D figures beside these.

mod report;
mod trainer;
mod walking;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, anyhow, bail};
use serde::{Deserialize, Serialize};
use strata_rcssmj::protocol::monitor::MonitorState;
use strata_rcssmj::server::{ServerOptions, ServerProcess};
use strata_robot::assembly::RobotModules;
use strata_runtime::HostStats;
use strata_soccer::team::TeamConfig;

use crate::counts::{RateEstimate, RateRatio, rate_ratio};
use crate::rates::{
    self as rates2d, Claim, LAYERS, LayerFigures, LayerSummary, PaperRow, figures, keeps_rate,
};
use crate::stats::Estimate;
use crate::{Check, Ctx, Options, ScenarioError, Validate, load_average};
use strata_games::physics::Engine;
use strata_games::physics::robot::{T1Launch, T1Process, free_udp_ports, strata_exe};

use trainer::{Trainer, TrainerPlan};
use walking::WalkTracker;

pub const DEFAULT_SCENARIO: &str = include_str!("../../scenarios/rcssservermj/rates.toml");

/// The robots' team: the server's left team (the first to connect), which defends x < 0 and
/// whose team frame is the server's world frame.
const TEAM: u8 = 1;
const TEAM_NAME: &str = "Strata1";

/// The server's field: 55 x 36 m (FIFA 7 vs 7).
const HALF_LENGTH: f64 = 27.5;
const HALF_WIDTH: f64 = 18.0;

/// How long the robots may take to join the simulation, and the simulation to stand still,
/// before a run fails: these bound a hang, they do not measure anything.
const JOIN_PATIENCE: Duration = Duration::from_secs(120);
const STALL_PATIENCE: Duration = Duration::from_secs(60);
/// How long a robot may take to write its report after SIGINT.
const STOP_PATIENCE: Duration = Duration::from_secs(20);

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    #[serde(default)]
    pub description: String,
    /// Simulated seconds per run and condition, from the kick-off.
    pub duration: f64,
    /// Simulated seconds of the game's Ready before the trainer kicks off.
    pub ready: f64,
    /// Runs per condition.
    pub runs: usize,
    /// Extra computation per deliberative cycle, s, one condition each.
    pub loads: Vec<f64>,
    /// A built-in team or a team file.
    pub team: String,
    /// Team messages over UDP between the robots.
    #[serde(default = "yes")]
    pub team_messages: bool,
    /// Simulated seconds between ball placements.
    pub ball_period: f64,
    /// Where the ball is placed: x_min, x_max, y_min, y_max, m, the server's world frame.
    pub ball_area: [f64; 4],
    /// The reactive layer's rate under load may not fall below this fraction of its rate
    /// without load.
    pub tolerance: f64,
    /// Torso speed over a 1 s window, upright, from which a robot walks, m/s.
    pub walking_speed: f64,
    /// Turning rate over a 1 s window, upright, from which a robot walks (turns in place),
    /// rad/s.
    #[serde(default = "default_turning_speed")]
    pub turning_speed: f64,
    /// The 2D rates experiment run by the same command, for comparison.
    #[serde(default)]
    pub sim: SimComparison,
    pub robots: Vec<RobotSpec>,
    /// The paper's Table 6.
    #[serde(default)]
    pub paper: Vec<PaperRow>,
    #[serde(skip)]
    resolved: Option<TeamConfig>,
}

fn default_turning_speed() -> f64 {
    0.2
}

fn yes() -> bool {
    true
}

/// The 2D rates experiment's built-in scenario, shortened, run before the report is written.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SimComparison {
    /// Seconds of real time per condition; 0: not run.
    #[serde(default)]
    pub duration: f64,
    #[serde(default = "one")]
    pub runs: usize,
}

fn one() -> usize {
    1
}

impl Default for SimComparison {
    fn default() -> Self {
        SimComparison { duration: 0.0, runs: 1 }
    }
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSpec {
    /// Label in the tables (Table 6's "Mission/role"); the 2D figures of the same label are
    /// placed beside it.
    pub role: String,
    /// Player number; 1 is the goalkeeper.
    pub player: u8,
    /// Where the server places the robot before the kick-off: x, y (m, the team's frame) and
    /// heading (degrees).
    pub beam: [f64; 3],
}

impl Validate for Scenario {
    fn validate(&mut self, check: &Check<'_>, dir: Option<&Path>) -> Result<(), ScenarioError> {
        check.positive("duration", self.duration)?;
        check.non_negative("ready", self.ready)?;
        check.at_least("runs", self.runs, 1)?;
        check.not_empty("loads", &self.loads)?;
        for (i, load) in self.loads.iter().enumerate() {
            check.non_negative(&format!("loads[{i}]"), *load)?;
        }
        self.resolved = Some(check.team("team", &self.team, dir)?);
        check.positive("ball_period", self.ball_period)?;
        let [x0, x1, y0, y1] = self.ball_area;
        let inside = |v: f64, half: f64| v.is_finite() && v.abs() < half;
        if !(inside(x0, HALF_LENGTH) && inside(x1, HALF_LENGTH) && x0 <= x1) {
            return Err(check.fail(
                "ball_area",
                format!("x_min <= x_max, both inside +-{HALF_LENGTH} m; got {x0}, {x1}"),
            ));
        }
        if !(inside(y0, HALF_WIDTH) && inside(y1, HALF_WIDTH) && y0 <= y1) {
            return Err(check.fail(
                "ball_area",
                format!("y_min <= y_max, both inside +-{HALF_WIDTH} m; got {y0}, {y1}"),
            ));
        }
        check.fraction("tolerance", self.tolerance)?;
        check.positive("walking_speed", self.walking_speed)?;
        check.positive("turning_speed", self.turning_speed)?;
        check.non_negative("sim.duration", self.sim.duration)?;
        check.at_least("sim.runs", self.sim.runs, 1)?;
        check.not_empty("robots", &self.robots)?;
        for (i, r) in self.robots.iter().enumerate() {
            if !(1..=7).contains(&r.player) {
                return Err(check.fail(&format!("robots[{i}].player"), "must be 1 to 7"));
            }
            if self.robots[..i].iter().any(|o| o.player == r.player) {
                return Err(
                    check.fail(&format!("robots[{i}].player"), "two robots with one number")
                );
            }
            if !r.beam.iter().all(|v| v.is_finite()) {
                return Err(check.fail(&format!("robots[{i}].beam"), "must be finite numbers"));
            }
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// What one run measured.

/// One robot in one run of one condition.
#[derive(Clone, Debug)]
struct RobotRun {
    /// Per layer (`LAYERS` order, those the robot reported).
    layers: Vec<(String, LayerFigures)>,
    /// The role its planning layer assigned last.
    role: Option<String>,
    /// Server cycles the robot perceived.
    sensor_frames: u64,
    /// Server cycles it perceived per second of its own clock from the kick-off to the stop
    /// (its status lines then): the run's pace without the start and the Ready.
    window_frames_hz: f64,
    /// Simulated seconds, from the kick-off to the end of the run.
    walking_s: f64,
    upright_s: f64,
    observed_s: f64,
    path_m: f64,
    /// Falls whose ground-truth onset was in the run's window, and of those the ones for which
    /// the reactive layer ordered the protective fall.
    falls: u64,
    falls_caught: u64,
    /// CPU time of the robot's process per server cycle, us, and its share of the 20 ms cycle.
    compute_p50_us: f64,
    compute_p99_us: f64,
    cycle_share_p50: f64,
    ended: String,
}

#[derive(Clone, Debug)]
struct RunResult {
    load: f64,
    run: usize,
    seed: u64,
    /// Scenario order.
    robots: Vec<RobotRun>,
    /// From the kick-off to the stop: simulated and wall-clock seconds.
    sim_s: f64,
    wall_s: f64,
    machine_load: Option<f64>,
    placements: usize,
    restarts: usize,
}

impl RunResult {
    fn real_time_factor(&self) -> f64 {
        if self.wall_s > 0.0 { self.sim_s / self.wall_s } else { f64::NAN }
    }
}

// ---------------------------------------------------------------------------------------------
// The summary (`--json`).

/// One robot under one condition, over the runs.
#[derive(Clone, Debug, Serialize)]
pub struct RobotSummary {
    pub role: String,
    pub load_s: f64,
    /// The roles its planning layer ended the runs with.
    pub assigned_roles: Vec<String>,
    /// Reactive cycles per perceived server cycle: 1 when the reactive layer acts on every
    /// sensor frame, whatever the machine does to the server's pace.
    pub reactive_per_frame: Estimate,
    /// Server cycles perceived per second from the kick-off to the stop (the run's pace
    /// without the start and the Ready), and times `reactive_per_frame`: the reactive layer's
    /// rate over that window.
    pub window_frames_hz: Estimate,
    pub window_reactive_hz: Estimate,
    pub walking_min: f64,
    pub upright_min: f64,
    pub path_m: Estimate,
    pub falls: u64,
    pub falls_caught: u64,
    pub compute_p50_us: Estimate,
    pub compute_p99_us: Estimate,
    pub cycle_share_p50: Estimate,
}

/// One condition, every robot and run together.
#[derive(Clone, Debug, Serialize)]
pub struct ConditionSummary {
    pub load_s: f64,
    /// Falls per minute of walking (ground truth), with the exact 95% interval.
    pub falls_per_walking_min: RateEstimate,
    /// Falls per minute upright (standing or walking).
    pub falls_per_upright_min: RateEstimate,
    /// Simulated over wall-clock seconds from the kick-off to the stop, per run.
    pub real_time_factor: Estimate,
    pub ball_placements: usize,
    pub restarts: usize,
}

/// The falls target under one load: not more falls per walking minute than without.
#[derive(Clone, Debug, Serialize)]
pub struct FallComparison {
    pub load_s: f64,
    pub unloaded: RateEstimate,
    pub loaded: RateEstimate,
    /// Loaded over unloaded; `None` with no falls in either (or no walking in one).
    pub ratio: Option<RateRatio>,
    /// Both conditions walked: the comparison means something.
    pub measured: bool,
    /// Measured, and the ratio's 95% interval reaches 1 or below (not more falls under load
    /// than chance allows).
    pub not_higher: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub experiment: String,
    pub engine: Engine,
    pub scenario: String,
    pub seed: u64,
    pub runs: usize,
    pub duration_s: f64,
    pub tolerance: f64,
    /// Per role, layer and load (Table 6's columns and more).
    pub layers: Vec<LayerSummary>,
    pub robots: Vec<RobotSummary>,
    pub conditions: Vec<ConditionSummary>,
    /// The reactive target per role and load.
    pub reactive: Vec<Claim>,
    pub reactive_rate_kept: bool,
    pub falls: Vec<FallComparison>,
    pub falls_not_higher: bool,
    pub machine_load_1min: Vec<f64>,
    /// The 2D rates experiment run by the same command, and how to run it again.
    pub sim_2d: Option<rates2d::Summary>,
    pub sim_2d_command: Option<String>,
}

// ---------------------------------------------------------------------------------------------
// The experiment.

pub fn run(scenario: &Scenario, ctx: &mut Ctx<'_>) -> Result<Summary> {
    let runs = ctx.runs(scenario.runs);
    let exe = strata_exe(ctx.options.strata_exe.as_deref())?;
    let total = (scenario.duration * (runs * scenario.loads.len()) as f64).ceil() as u64;
    let bar = ctx.progress(total, "simulated s");
    let mut team_files = Vec::new();
    for load in &scenario.loads {
        let mut team = scenario.resolved.clone().unwrap_or_default();
        team.deliberative_load = *load;
        let path = ctx.out_dir.join(format!("team-load-{load}.toml"));
        let text = toml::to_string(&team).context("writing the robots' team configuration")?;
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
        team_files.push(path);
    }
    // `--log` records the first robot of the first run (each robot is a process of its own).
    let mut log = ctx.options.log.clone();
    let mut all_runs = || -> Result<Vec<RunResult>> {
        let mut results = Vec::new();
        for run in 0..runs {
            for (load, team_file) in scenario.loads.iter().zip(&team_files) {
                let seed = ctx.seed(run);
                bar.set_message(format!("run {}/{runs}, load {:.0} ms", run + 1, load * 1000.0));
                let input = RunInput { scenario, exe: &exe, team_file, load: *load, seed };
                let result = run_once(&input, log.take(), &|n| bar.inc(n))
                    .with_context(|| format!("run {run}, load {load} s"))?;
                results.push(RunResult { run, ..result });
            }
        }
        Ok(results)
    };
    let results = all_runs();
    bar.finish_and_clear();
    // The team files go whether the runs succeeded or not.
    for path in &team_files {
        let _ = std::fs::remove_file(path);
    }
    let results = results?;
    let sim = run_sim_comparison(scenario, ctx)?;
    let summary = summarize(scenario, ctx, runs, &results, sim);
    report::write_outputs(scenario, ctx, &results, &summary)?;
    Ok(summary)
}

struct RunInput<'a> {
    scenario: &'a Scenario,
    exe: &'a Path,
    team_file: &'a Path,
    load: f64,
    seed: u64,
}

/// One run of one condition: a server, the robots, the trainer, until `duration` simulated
/// seconds after the kick-off.
fn run_once(input: &RunInput<'_>, log: Option<PathBuf>, tick: &dyn Fn(u64)) -> Result<RunResult> {
    let scenario = input.scenario;
    strata_games::physics::check_interrupt()?;
    let server =
        ServerProcess::start(&ServerOptions::default()).context("starting rcssservermj")?;
    let team_port = if scenario.team_messages { Some(free_udp_ports::<1>()?[0]) } else { None };
    let mut log = log;
    let mut robots = Vec::new();
    for spec in &scenario.robots {
        let launch = T1Launch {
            exe: input.exe.to_owned(),
            server: server.agent_address(),
            team: TEAM,
            team_name: TEAM_NAME.to_owned(),
            player: spec.player,
            beam: spec.beam,
            team_config: input.team_file.display().to_string(),
            seed: input.seed.wrapping_mul(10).wrapping_add(u64::from(spec.player)),
            team_port,
            log: log.take(),
            status_interval: 1.0,
            duration: None,
            extra: Vec::new(),
        };
        robots.push(T1Process::spawn(&launch)?);
    }
    let plan = TrainerPlan {
        ready: scenario.ready,
        ball_period: scenario.ball_period,
        ball_area: scenario.ball_area,
    };
    let mut trainer = Trainer::new(plan, input.seed);
    let mut walks: Vec<WalkTracker> = scenario
        .robots
        .iter()
        .map(|_| WalkTracker::new(scenario.walking_speed, scenario.turning_speed))
        .collect();
    let started = Instant::now();
    let mut last_t = f64::NEG_INFINITY;
    let mut last_advance = Instant::now();
    let mut window: Option<(f64, Instant)> = None;
    // Each robot's newest status line (its clock, its perceived server cycles) at the kick-off.
    let mut at_kick_off: Vec<Option<(f64, f64)>> = Vec::new();
    let mut ticked = 0u64;
    loop {
        std::thread::sleep(Duration::from_millis(20));
        strata_games::physics::check_interrupt()?;
        for robot in &mut robots {
            if let Some(status) = robot.exited() {
                bail!(
                    "robot {}/{} ended before the run did ({status}); its stderr ends with: {}",
                    robot.team,
                    robot.player,
                    robot.stderr_tail(5)
                );
            }
        }
        let state = server.truth();
        let Some(t) = state.sim_time else { continue };
        if t > last_t {
            last_t = t;
            last_advance = Instant::now();
        } else if last_advance.elapsed() > STALL_PATIENCE {
            bail!("the simulation stood still for {STALL_PATIENCE:?} at {t:.2} s");
        }
        let truths: Vec<_> = scenario.robots.iter().map(|r| truth_of(&state, r.player)).collect();
        let all_arrived = truths.iter().all(Option::is_some);
        if !all_arrived && window.is_none() && started.elapsed() > JOIN_PATIENCE {
            bail!(
                "the robots did not all join the simulation within {JOIN_PATIENCE:?} (players \
                 missing: {})",
                scenario
                    .robots
                    .iter()
                    .zip(&truths)
                    .filter(|(_, t)| t.is_none())
                    .map(|(r, _)| r.player.to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        let mode = state.game.as_ref().and_then(|g| g.play_mode);
        let commands = trainer.step(t, mode, all_arrived);
        if !commands.is_empty() {
            server.command(commands);
        }
        let Some(kick_off) = trainer.kicked_off() else { continue };
        let (kick_off, _) = *window.get_or_insert_with(|| {
            at_kick_off = robots.iter().map(status_frames).collect();
            (kick_off, Instant::now())
        });
        for (walk, truth) in walks.iter_mut().zip(&truths) {
            if let Some(truth) = truth {
                walk.sample(t, truth.position, truth.orientation);
            }
        }
        let whole = ((t - kick_off).max(0.0) as u64).min(scenario.duration as u64);
        if whole > ticked {
            tick(whole - ticked);
            ticked = whole;
        }
        if t - kick_off >= scenario.duration {
            break;
        }
    }
    let (kick_off, wall_start) = window.ok_or_else(|| anyhow!("the run ended before kick-off"))?;
    let sim_s = last_t - kick_off;
    let wall_s = wall_start.elapsed().as_secs_f64();
    let machine_load = load_average();
    let at_stop: Vec<Option<(f64, f64)>> = robots.iter().map(status_frames).collect();
    for robot in &mut robots {
        robot.interrupt();
    }
    let mut out = Vec::new();
    for (i, ((robot, spec), walk)) in
        robots.iter_mut().zip(&scenario.robots).zip(&walks).enumerate()
    {
        let (report, status) = robot.finish(STOP_PATIENCE);
        let Some(report) = report else {
            bail!(
                "robot {TEAM}/{} ({}) printed no report; its stderr ends with: {}",
                spec.player,
                status.map_or("killed".to_owned(), |s| s.to_string()),
                robot.stderr_tail(5)
            );
        };
        let mut run = robot_run(&report, spec.player, (kick_off, last_t), walk)?;
        if let (Some(Some((t0, f0))), Some(Some((t1, f1)))) = (at_kick_off.get(i), at_stop.get(i))
            && t1 > t0
        {
            run.window_frames_hz = (f1 - f0) / (t1 - t0);
        }
        out.push(run);
    }
    drop(server);
    Ok(RunResult {
        load: input.load,
        run: 0,
        seed: input.seed,
        robots: out,
        sim_s,
        wall_s,
        machine_load,
        placements: trainer.placements,
        restarts: trainer.restarts,
    })
}

/// The robot's clock and perceived server cycles in its newest status line.
fn status_frames(robot: &T1Process) -> Option<(f64, f64)> {
    let status = robot.latest("status")?;
    Some((status.get("t")?.as_f64()?, status.get("sensor_frames")?.as_f64()?))
}

fn truth_of(
    state: &MonitorState,
    player: u8,
) -> Option<strata_rcssmj::protocol::monitor::RobotTruth> {
    state.robots.iter().find(|r| r.team == TEAM_NAME && r.player == u32::from(player)).cloned()
}

/// What a robot's final report (`strata robot --json`) and the ground truth say about it.
fn robot_run(
    report: &serde_json::Value,
    player: u8,
    (from, to): (f64, f64),
    walk: &WalkTracker,
) -> Result<RobotRun> {
    let host: HostStats =
        serde_json::from_value(report.get("host").cloned().unwrap_or_default())
            .with_context(|| format!("robot {TEAM}/{player}: reading its host statistics"))?;
    let modules = RobotModules::new(&format!("t{TEAM}/{player}"));
    let falls: Vec<&serde_json::Value> = report
        .get("falls")
        .and_then(serde_json::Value::as_array)
        .map(|falls| {
            falls
                .iter()
                .filter(|f| {
                    f.get("onset")
                        .and_then(serde_json::Value::as_f64)
                        .is_some_and(|onset| (from..=to).contains(&onset))
                })
                .collect()
        })
        .unwrap_or_default();
    let number = |pointer: &str| report.pointer(pointer).and_then(serde_json::Value::as_f64);
    Ok(RobotRun {
        layers: figures(&host, &modules),
        role: report.get("role").and_then(serde_json::Value::as_str).map(str::to_owned),
        sensor_frames: report.get("sensor_frames").and_then(serde_json::Value::as_u64).unwrap_or(0),
        window_frames_hz: f64::NAN,
        walking_s: walk.walking_s(),
        upright_s: walk.upright_s(),
        observed_s: walk.observed_s(),
        path_m: walk.path_m(),
        falls: falls.len() as u64,
        falls_caught: falls.iter().filter(|f| !f["ordered"].is_null()).count() as u64,
        compute_p50_us: number("/compute/process/p50_us").unwrap_or(f64::NAN),
        compute_p99_us: number("/compute/process/p99_us").unwrap_or(f64::NAN),
        cycle_share_p50: number("/compute/share_of_cycle/p50").unwrap_or(f64::NAN),
        ended: report.get("ended").and_then(serde_json::Value::as_str).unwrap_or("").to_owned(),
    })
}

/// The 2D rates experiment's built-in scenario with the physics scenario's `[sim]` duration and
/// runs, run into `OUT/sim/`: the 2D figures of the same machine and hour, beside these.
fn run_sim_comparison(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
) -> Result<Option<(rates2d::Summary, String)>> {
    if scenario.sim.duration <= 0.0 {
        return Ok(None);
    }
    let dir = ctx.out_dir.join("sim");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut table: toml::Table =
        toml::from_str(rates2d::DEFAULT_SCENARIO).context("the built-in 2D rates scenario")?;
    table.insert("duration".to_owned(), toml::Value::Float(scenario.sim.duration));
    let runs = i64::try_from(scenario.sim.runs).context("sim.runs")?;
    table.insert("runs".to_owned(), toml::Value::Integer(runs));
    let path = dir.join("scenario.toml");
    let text = toml::to_string(&table).context("writing the 2D scenario")?;
    std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    let options = Options {
        runs: None,
        out: Some(dir.clone()),
        scenario: Some(path.clone()),
        log: None,
        engine: Engine::Sim,
        ..ctx.options.clone()
    };
    let mut sim_ctx = Ctx::new(rates2d::NAME, &options, dir.clone());
    let sim_scenario = sim_ctx.scenario::<rates2d::Scenario>(rates2d::DEFAULT_SCENARIO)?;
    let summary = rates2d::run(&sim_scenario, &mut sim_ctx).context("the 2D comparison")?;
    ctx.files.append(&mut sim_ctx.files);
    let command = format!(
        "strata experiment rates --scenario {} --seed {} --out {}",
        path.display(),
        ctx.options.seed,
        dir.display()
    );
    Ok(Some((summary, command)))
}

// ---------------------------------------------------------------------------------------------
// From runs to the summary.

fn summarize(
    scenario: &Scenario,
    ctx: &Ctx<'_>,
    runs: usize,
    results: &[RunResult],
    sim: Option<(rates2d::Summary, String)>,
) -> Summary {
    let of_load = |load: f64| results.iter().filter(move |r| r.load == load);
    let mut layers = Vec::new();
    let mut robots = Vec::new();
    for load in &scenario.loads {
        for (i, spec) in scenario.robots.iter().enumerate() {
            let runs_of: Vec<&RobotRun> = of_load(*load).filter_map(|r| r.robots.get(i)).collect();
            for layer in LAYERS {
                let figures: Vec<&LayerFigures> = runs_of
                    .iter()
                    .filter_map(|r| r.layers.iter().find(|(l, _)| l == layer).map(|(_, f)| f))
                    .collect();
                if figures.is_empty() {
                    continue;
                }
                layers.push(LayerSummary::of(&spec.role, layer, *load, &figures));
            }
            robots.push(robot_summary(spec, *load, &runs_of));
        }
    }
    let conditions: Vec<ConditionSummary> = scenario
        .loads
        .iter()
        .map(|load| {
            let runs_of: Vec<&RunResult> = of_load(*load).collect();
            let all: Vec<&RobotRun> = runs_of.iter().flat_map(|r| &r.robots).collect();
            let falls = all.iter().map(|r| r.falls).sum();
            ConditionSummary {
                load_s: *load,
                falls_per_walking_min: RateEstimate::of(
                    falls,
                    all.iter().map(|r| r.walking_s).sum::<f64>() / 60.0,
                ),
                falls_per_upright_min: RateEstimate::of(
                    falls,
                    all.iter().map(|r| r.upright_s).sum::<f64>() / 60.0,
                ),
                real_time_factor: Estimate::of(
                    &runs_of.iter().map(|r| r.real_time_factor()).collect::<Vec<_>>(),
                ),
                ball_placements: runs_of.iter().map(|r| r.placements).sum(),
                restarts: runs_of.iter().map(|r| r.restarts).sum(),
            }
        })
        .collect();
    let base = scenario.loads.iter().copied().fold(f64::INFINITY, f64::min);
    let reactive = reactive_claims(scenario, &layers, base);
    let falls = fall_comparisons(&conditions, base);
    let (sim_2d, sim_2d_command) = match sim {
        Some((summary, command)) => (Some(summary), Some(command)),
        None => (None, None),
    };
    Summary {
        experiment: rates2d::NAME.to_owned(),
        engine: Engine::Rcssservermj,
        scenario: ctx.scenario_source.clone(),
        seed: ctx.options.seed,
        runs,
        duration_s: scenario.duration,
        tolerance: scenario.tolerance,
        reactive_rate_kept: !reactive.is_empty() && reactive.iter().all(|c| c.reactive_rate_kept),
        falls_not_higher: !falls.is_empty() && falls.iter().all(|f| f.not_higher),
        layers,
        robots,
        conditions,
        reactive,
        falls,
        machine_load_1min: results.iter().filter_map(|r| r.machine_load).collect(),
        sim_2d,
        sim_2d_command,
    }
}

fn robot_summary(spec: &RobotSpec, load: f64, runs: &[&RobotRun]) -> RobotSummary {
    let e =
        |f: &dyn Fn(&RobotRun) -> f64| Estimate::of(&runs.iter().map(|r| f(r)).collect::<Vec<_>>());
    let mut assigned: Vec<String> = runs.iter().filter_map(|r| r.role.clone()).collect();
    assigned.sort();
    assigned.dedup();
    let per_frame = |r: &RobotRun| {
        let cycles = r.layers.iter().find(|(l, _)| l == "reactive").map_or(0, |(_, f)| f.cycles);
        if r.sensor_frames > 0 { cycles as f64 / r.sensor_frames as f64 } else { f64::NAN }
    };
    RobotSummary {
        role: spec.role.clone(),
        load_s: load,
        assigned_roles: assigned,
        reactive_per_frame: e(&per_frame),
        window_frames_hz: e(&|r| r.window_frames_hz),
        window_reactive_hz: e(&|r| r.window_frames_hz * per_frame(r)),
        walking_min: runs.iter().map(|r| r.walking_s).sum::<f64>() / 60.0,
        upright_min: runs.iter().map(|r| r.upright_s).sum::<f64>() / 60.0,
        path_m: e(&|r| r.path_m),
        falls: runs.iter().map(|r| r.falls).sum(),
        falls_caught: runs.iter().map(|r| r.falls_caught).sum(),
        compute_p50_us: e(&|r| r.compute_p50_us),
        compute_p99_us: e(&|r| r.compute_p99_us),
        cycle_share_p50: e(&|r| r.cycle_share_p50),
    }
}

/// The reactive target per role and load above the lowest: its mean rate keeps `tolerance` of
/// the rate without load; and whether the load really ran (the deliberative cycle's median
/// compute time is at least 95% of it).
fn reactive_claims(scenario: &Scenario, layers: &[LayerSummary], base: f64) -> Vec<Claim> {
    let find = |role: &str, layer: &str, load: f64| {
        layers.iter().find(|l| l.role == role && l.layer == layer && l.load_s == load)
    };
    let mut claims = Vec::new();
    for robot in &scenario.robots {
        for load in scenario.loads.iter().filter(|l| **l > base) {
            let (Some(unloaded), Some(loaded), Some(deliberative)) = (
                find(&robot.role, "reactive", base),
                find(&robot.role, "reactive", *load),
                find(&robot.role, "deliberative", *load),
            ) else {
                continue;
            };
            let (before, after) = (unloaded.mean_hz.mean, loaded.mean_hz.mean);
            claims.push(Claim {
                role: robot.role.clone(),
                load_s: *load,
                unloaded_reactive_hz: before,
                loaded_reactive_hz: after,
                ratio: after / before,
                reactive_rate_kept: keeps_rate(before, after, scenario.tolerance),
                load_applied: deliberative.compute_p50_ms.mean >= 0.95 * load * 1000.0,
            });
        }
    }
    claims
}

/// The falls target per load above the lowest.
fn fall_comparisons(conditions: &[ConditionSummary], base: f64) -> Vec<FallComparison> {
    let Some(unloaded) = conditions.iter().find(|c| c.load_s == base) else {
        return Vec::new();
    };
    conditions
        .iter()
        .filter(|c| c.load_s > base)
        .map(|c| compare_falls(c.load_s, unloaded.falls_per_walking_min, c.falls_per_walking_min))
        .collect()
}

/// Not more falls per walking minute under load: the loaded-over-unloaded ratio's exact 95%
/// interval reaches 1 (no falls at all passes; no walking in a condition cannot pass).
pub fn compare_falls(load_s: f64, unloaded: RateEstimate, loaded: RateEstimate) -> FallComparison {
    let measured = unloaded.exposure > 0.0 && loaded.exposure > 0.0;
    let ratio = rate_ratio(&loaded, &unloaded);
    let not_higher = measured && ratio.is_none_or(|r| r.low <= 1.0);
    FallComparison { load_s, unloaded, loaded, ratio, measured, not_higher }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parse_scenario;

    fn parsed(text: &str) -> Result<Scenario, ScenarioError> {
        let mut scenario: Scenario = parse_scenario(text, "test.toml")?;
        scenario.validate(&Check { source_name: "test.toml" }, None)?;
        Ok(scenario)
    }

    #[test]
    fn the_built_in_scenario_is_valid() {
        let scenario = parsed(DEFAULT_SCENARIO).expect("valid");
        assert_eq!(scenario.loads, vec![0.0, 0.2]);
        assert_eq!(scenario.tolerance, 0.98);
        assert!(scenario.robots.iter().any(|r| r.player == 1));
        assert!(scenario.sim.duration > 0.0);
    }

    #[test]
    fn a_ball_area_off_the_field_is_named_in_the_error() {
        let text = DEFAULT_SCENARIO.replace("ball_area = [-22.0,", "ball_area = [-30.0,");
        let error = parsed(&text).expect_err("off the field");
        assert_eq!(error.field.as_deref(), Some("ball_area"), "{error}");
        let text = DEFAULT_SCENARIO.replace("player = 2", "player = 1");
        let error = parsed(&text).expect_err("two keepers");
        assert_eq!(error.field.as_deref(), Some("robots[1].player"), "{error}");
        let text = DEFAULT_SCENARIO.replace("walking_speed = 0.1", "walking_speed = 0.0");
        assert_eq!(parsed(&text).expect_err("no speed").field.as_deref(), Some("walking_speed"));
    }

    #[test]
    fn falls_under_load_pass_unless_clearly_more_frequent() {
        let none = compare_falls(0.2, RateEstimate::of(0, 5.0), RateEstimate::of(0, 5.0));
        assert!(none.measured && none.not_higher && none.ratio.is_none());
        let similar = compare_falls(0.2, RateEstimate::of(2, 5.0), RateEstimate::of(3, 5.0));
        assert!(similar.not_higher, "{similar:?}");
        let worse = compare_falls(0.2, RateEstimate::of(0, 5.0), RateEstimate::of(15, 5.0));
        assert!(!worse.not_higher, "{worse:?}");
        let unwalked = compare_falls(0.2, RateEstimate::of(0, 0.0), RateEstimate::of(0, 5.0));
        assert!(!unwalked.measured && !unwalked.not_higher);
    }
}
