//! `strata experiment rates` (paper 4.3, Table 6): a goalkeeper and a striker play in real time
//! and every layer's frequency, cycle compute time and period jitter are measured; then again
//! with an artificial load in every deliberative cycle (200 ms of computation by default). The
//! paper's central claim is that the reactive layer keeps its rate whatever the deliberative
//! layer does.
//!
//! Transport `tcp` (the default, the paper's HL-SIM setup): the simulator server runs in this
//! process, each robot is its own `strata robot` process connected over TCP, and reports its
//! host statistics as JSON when it ends. Transport `in-process`: both robots on one threaded
//! host in this process, with the simulator module.

use std::io::{BufRead as _, BufReader};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, anyhow, bail};
use rand::{RngExt as _, SeedableRng as _};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use strata_robot::assembly::RobotModules;
use strata_robot::geometry::{Point, Pose, Vector};
use strata_runtime::{HostStats, ModuleStats, Scheduling};
use strata_sim::net::{Server, ServerOptions};
use strata_sim::{GameState, NoiseLevel, RobotId, SimConfig, SimHandle, Simulation};
use strata_soccer::field::TeamField;
use strata_soccer::team::TeamConfig;

use strata_games::children::Child;

use super::plot::Bars;
use super::report::{Markdown, num, verdict, write_csv};
use super::stats::Estimate;
use super::{Check, Ctx, ExperimentLog, HostKind, ScenarioError, Scene, SceneRobot, Validate};

pub const NAME: &str = "rates";
pub const DEFAULT_SCENARIO: &str = include_str!("../scenarios/rates.toml");

/// How the robots reach the simulated world.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Transport {
    /// The simulator server in this process, one `strata robot` process per robot.
    Tcp,
    /// Both robots on one threaded host in this process.
    InProcess,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    #[serde(default)]
    pub description: String,
    pub transport: Transport,
    pub field: String,
    pub noise: String,
    /// Seconds of real time per run and condition.
    pub duration: f64,
    /// Runs per condition (conditions run one after another: they would share the cores).
    pub runs: usize,
    /// Extra computation per deliberative cycle, s, one condition each.
    pub loads: Vec<f64>,
    /// The team the robots play with: a built-in team or a team file.
    pub team: String,
    /// The ball is put at a new random place this often, s (and when it leaves the field).
    pub ball_reset_period: f64,
    /// The reactive layer's rate under load may not fall below this fraction of its rate
    /// without load.
    pub tolerance: f64,
    /// Real-time priority (SCHED_FIFO, 1-99) the robot processes give their sensor path
    /// (`strata robot --real-time-priority`); 0: every thread at the default policy. The
    /// in-process transport always uses the default policy.
    #[serde(default = "default_real_time_priority")]
    pub real_time_priority: u8,
    pub robots: Vec<RobotSpec>,
    /// The paper's Table 6.
    #[serde(default)]
    pub paper: Vec<PaperRow>,
    #[serde(skip)]
    resolved: Option<TeamConfig>,
    #[serde(skip)]
    noise_level: Option<NoiseLevel>,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSpec {
    /// Label in the tables (Table 6's "Mission/role").
    pub role: String,
    pub player: u8,
    /// Start pose, team frame [x, y, theta].
    pub start: [f64; 3],
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PaperRow {
    pub role: String,
    pub layer: String,
    pub max_hz: f64,
    pub mean_hz: f64,
    pub min_hz: f64,
}

impl Validate for Scenario {
    fn validate(&mut self, check: &Check<'_>, dir: Option<&Path>) -> Result<(), ScenarioError> {
        self.field = check.field_preset("field", &self.field, dir)?;
        self.noise_level = Some(check.noise("noise", &self.noise)?);
        check.positive("duration", self.duration)?;
        check.at_least("runs", self.runs, 1)?;
        check.not_empty("loads", &self.loads)?;
        for (i, load) in self.loads.iter().enumerate() {
            check.non_negative(&format!("loads[{i}]"), *load)?;
        }
        self.resolved = Some(check.team("team", &self.team, dir)?);
        check.positive("ball_reset_period", self.ball_reset_period)?;
        check.fraction("tolerance", self.tolerance)?;
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
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// Metric functions.

/// One layer of one robot in one run: Table 6's columns and more.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct LayerFigures {
    pub cycles: u64,
    pub min_hz: f64,
    pub mean_hz: f64,
    pub max_hz: f64,
    pub compute_p50_ms: f64,
    pub compute_p99_ms: f64,
    pub compute_max_ms: f64,
    pub period_p50_ms: f64,
    pub period_p99_ms: f64,
    pub period_max_ms: f64,
    /// Period p99 minus median: how late a cycle can be.
    pub jitter_p99_ms: f64,
}

impl LayerFigures {
    /// The columns of `runs.csv` after the run's and robot's (2D and physics alike).
    pub(crate) fn csv_fields(&self) -> [String; 11] {
        [
            self.cycles.to_string(),
            num(self.min_hz),
            num(self.mean_hz),
            num(self.max_hz),
            num(self.compute_p50_ms),
            num(self.compute_p99_ms),
            num(self.compute_max_ms),
            num(self.period_p50_ms),
            num(self.period_p99_ms),
            num(self.period_max_ms),
            num(self.jitter_p99_ms),
        ]
    }
}

pub fn layer_figures(m: &ModuleStats) -> LayerFigures {
    LayerFigures {
        cycles: m.cycles,
        min_hz: m.rate.min_hz,
        mean_hz: m.rate.mean_hz,
        max_hz: m.rate.max_hz,
        compute_p50_ms: m.compute_time.p50_us / 1000.0,
        compute_p99_ms: m.compute_time.p99_us / 1000.0,
        compute_max_ms: m.compute_time.max_us / 1000.0,
        period_p50_ms: m.period.p50_us / 1000.0,
        period_p99_ms: m.period.p99_us / 1000.0,
        period_max_ms: m.period.max_us / 1000.0,
        jitter_p99_ms: (m.period.p99_us - m.period.p50_us) / 1000.0,
    }
}

/// The reactive layer "does not drop": its mean rate under load keeps `tolerance` of the rate
/// without load.
pub fn keeps_rate(unloaded_hz: f64, loaded_hz: f64, tolerance: f64) -> bool {
    loaded_hz >= tolerance * unloaded_hz
}

pub(crate) const LAYERS: [&str; 5] =
    ["reactive", "deliberative", "planning", "perception", "world"];

fn module_of<'a>(modules: &'a RobotModules, layer: &str) -> &'a str {
    match layer {
        "reactive" => &modules.reactive,
        "deliberative" => &modules.deliberative,
        "planning" => &modules.planning,
        "perception" => &modules.perception,
        "world" => &modules.world,
        _ => &modules.actuation,
    }
}

// ---------------------------------------------------------------------------------------------
// One run of one condition: every robot at once.

#[derive(Clone, Debug)]
struct RunResult {
    load: f64,
    run: usize,
    seed: u64,
    /// Per robot (scenario order), per layer.
    robots: Vec<Vec<(String, LayerFigures)>>,
    /// How each robot's sensor-path threads were scheduled.
    scheduling: Vec<String>,
    wall_s: f64,
    /// The machine's 1-minute load average when the run ended.
    machine_load: Option<f64>,
}

/// What one run of one condition measured, per robot in scenario order.
struct RunOutcome {
    /// Per layer.
    robots: Vec<Vec<(String, LayerFigures)>>,
    /// How the robot's sensor-path threads were scheduled.
    scheduling: Vec<String>,
}

fn default_real_time_priority() -> u8 {
    10
}

/// How a robot's sensor-path threads were scheduled, in a few words for the report.
fn scheduling_note(stats: &HostStats, modules: &RobotModules) -> String {
    let sensor_path = [
        &modules.sensors,
        &modules.perception,
        &modules.world,
        &modules.reactive,
        &modules.actuation,
        &modules.actuators,
    ];
    let mut notes: Vec<String> = sensor_path
        .iter()
        .filter_map(|name| stats.module(name))
        .map(|m| match &m.scheduling {
            Scheduling::Default => "default policy".to_owned(),
            Scheduling::RealTime { priority } => format!("SCHED_FIFO {priority}"),
            Scheduling::RealTimeRefused { priority, reason } => {
                format!("default policy (SCHED_FIFO {priority} refused: {reason})")
            }
        })
        .collect();
    notes.sort();
    notes.dedup();
    notes.join("; ")
}

fn team_with_load(scenario: &Scenario, load: f64) -> TeamConfig {
    let mut team = scenario.resolved.clone().unwrap_or_default();
    team.deliberative_load = load;
    team
}

fn sim_config(scenario: &Scenario, seed: u64) -> Result<SimConfig> {
    let players = scenario.robots.iter().map(|r| r.player).max().unwrap_or(1);
    let mut config = SimConfig { seed, field: scenario.field.clone(), ..SimConfig::default() };
    config.noise.preset = scenario.noise_level.unwrap_or_default();
    config.referee.auto = false;
    config.referee.players_per_team = players;
    config.validate("rates experiment").context("simulator configuration")?;
    Ok(config)
}

/// Keeps the game going: the ball goes to a new random place now and then, and when it leaves
/// the field or enters a goal, so the striker keeps walking and kicking (the chaos run's game
/// too).
pub(crate) struct BallKeeper {
    rng: ChaCha8Rng,
    last: Instant,
    period: Duration,
}

impl BallKeeper {
    pub(crate) fn new(seed: u64, period: f64) -> BallKeeper {
        BallKeeper {
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x7261_7465),
            last: Instant::now(),
            period: Duration::from_secs_f64(period),
        }
    }

    pub(crate) fn tend(&mut self, sim: &SimHandle) -> Result<()> {
        let mut sim = sim.lock();
        let (hl, hw) = (sim.field().half_length(), sim.field().half_width());
        let ball = sim.ball().position;
        let out = ball.x.abs() > hl - 0.05 || ball.y.abs() > hw - 0.05;
        if out || self.last.elapsed() >= self.period {
            self.last = Instant::now();
            let x = self.rng.random_range(-0.7 * hl..0.7 * hl);
            let y = self.rng.random_range(-0.7 * hw..0.7 * hw);
            sim.place_ball(Point::new(x, y), Vector::new(0.0, 0.0)).map_err(|e| anyhow!("{e}"))?;
        }
        Ok(())
    }
}

fn run_in_process(
    scenario: &Scenario,
    load: f64,
    seed: u64,
    log: Option<ExperimentLog>,
    tick: &dyn Fn(u64),
) -> Result<RunOutcome> {
    let team = team_with_load(scenario, load);
    let robots: Vec<SceneRobot> = scenario
        .robots
        .iter()
        .map(|r| SceneRobot {
            player: r.player,
            team: team.clone(),
            start: Pose::new(r.start[0], r.start[1], r.start[2]),
            gaze: None,
        })
        .collect();
    let mut scene =
        Scene::new(&scenario.field, scenario.noise_level.unwrap_or_default(), seed, &robots)?;
    scene.log = log;
    let modules: Vec<RobotModules> = scene.robots.iter().map(|(_, m)| m.clone()).collect();
    let tap: Arc<dyn strata_runtime::Tap> = Arc::new(NoTap);
    let mut host = scene.host(HostKind::Threaded, seed, tap)?;
    let mut keeper = BallKeeper::new(seed, scenario.ball_reset_period);
    let started = Instant::now();
    let mut ticked = 0u64;
    while started.elapsed().as_secs_f64() < scenario.duration {
        host.advance(Duration::from_millis(100))?;
        keeper.tend(&scene.sim)?;
        let whole = started.elapsed().as_secs();
        if whole > ticked {
            tick(whole - ticked);
            ticked = whole;
        }
    }
    let stats = host.finish()?;
    Ok(RunOutcome {
        robots: modules.iter().map(|m| figures(&stats, m)).collect(),
        scheduling: modules.iter().map(|m| scheduling_note(&stats, m)).collect(),
    })
}

struct NoTap;

impl strata_runtime::Tap for NoTap {
    fn package(&self, _: &strata_runtime::TapRecord<'_>) {}
}

pub(crate) fn figures(stats: &HostStats, modules: &RobotModules) -> Vec<(String, LayerFigures)> {
    LAYERS
        .iter()
        .filter_map(|layer| {
            stats.module(module_of(modules, layer)).map(|m| ((*layer).to_owned(), layer_figures(m)))
        })
        .collect()
}

fn run_tcp(
    scenario: &Scenario,
    ctx_dir: &Path,
    exe: &Path,
    load: f64,
    seed: u64,
    tick: &dyn Fn(u64),
) -> Result<RunOutcome> {
    let config = sim_config(scenario, seed)?;
    let simulation = Simulation::new(config).context("building the simulated world")?;
    let team_number = simulation.team_number(0);
    let attack_sign = simulation.game().attack_sign[0];
    let team_field = TeamField::new(simulation.field().clone(), attack_sign);
    let sim = SimHandle::new(simulation);
    let server = Server::bind("127.0.0.1:0", sim.clone(), ServerOptions::default())
        .context("starting the simulator server")?
        .spawn()
        .context("starting the simulator server")?;
    let addr = server.local_addr().to_string();
    sim.lock().set_game_state(GameState::Playing);

    // The team file the robot processes read: the scenario's team with this condition's load.
    let team = team_with_load(scenario, load);
    let team_file = ctx_dir.join(format!("team-load-{load}.toml"));
    let text = toml::to_string(&team).context("writing the robots' team configuration")?;
    std::fs::write(&team_file, text).with_context(|| format!("writing {}", team_file.display()))?;

    let mut processes = Vec::new();
    for robot in &scenario.robots {
        let mut command = Command::new(exe);
        command
            .args(["robot", "--platform", "sim", "--server", &addr])
            .args(["--team", &team_number.to_string(), "--player", &robot.player.to_string()])
            .arg("--team-config")
            .arg(&team_file)
            .args(["--field", &scenario.field])
            .args(["--attack-sign", if attack_sign > 0.0 { "1" } else { "-1" }])
            .args(["--gc-wait", "0", "--json", "--status-interval", "3600"])
            .args(["--duration", &scenario.duration.to_string()])
            .args(["--seed", &(seed * 10 + u64::from(robot.player)).to_string()])
            .args(["--real-time-priority", &scenario.real_time_priority.to_string()]);
        let name = format!("`{} robot` (player {})", exe.display(), robot.player);
        processes.push((robot.player, Child::spawn(&name, &mut command)?));
    }
    // Place each robot where its role starts once its process has joined the world.
    let mut placed = vec![false; scenario.robots.len()];
    let mut keeper = BallKeeper::new(seed, scenario.ball_reset_period);
    let started = Instant::now();
    let deadline = scenario.duration + 30.0;
    let mut ticked = 0u64;
    loop {
        std::thread::sleep(Duration::from_millis(50));
        for (i, robot) in scenario.robots.iter().enumerate() {
            let id = RobotId::new(0, robot.player);
            if !placed[i] && sim.lock().is_present(id) {
                let [x, y, theta] = robot.start;
                sim.lock()
                    .teleport(id, team_field.pose_to_field(Pose::new(x, y, theta)))
                    .map_err(|e| anyhow!("{e}"))?;
                placed[i] = true;
            }
        }
        keeper.tend(&sim)?;
        let whole = started.elapsed().as_secs().min(scenario.duration as u64);
        if whole > ticked {
            tick(whole - ticked);
            ticked = whole;
        }
        let mut running = 0;
        for (_, p) in &mut processes {
            if p.try_wait()?.is_none() {
                running += 1;
            }
        }
        if running == 0 {
            break;
        }
        if started.elapsed().as_secs_f64() > deadline {
            bail!("robot processes still running {deadline} s after the start: killed");
        }
    }
    let _ = server.stop();
    let mut out = Vec::new();
    let mut scheduling = Vec::new();
    for (player, mut p) in processes {
        let status = p.wait()?;
        let (stdout, stderr) = (p.stdout(), p.stderr());
        let report = BufReader::new(stdout.as_bytes())
            .lines()
            .map_while(Result::ok)
            .filter_map(|line| serde_json::from_str::<serde_json::Value>(&line).ok())
            .find(|v| v.get("type").and_then(|t| t.as_str()) == Some("report"));
        let Some(report) = report else {
            bail!(
                "robot {player} ({status}) printed no report; its stderr ends with: {}",
                stderr
                    .lines()
                    .rev()
                    .take(5)
                    .collect::<Vec<_>>()
                    .into_iter()
                    .rev()
                    .collect::<Vec<_>>()
                    .join(" | ")
            );
        };
        let host: HostStats =
            serde_json::from_value(report.get("host").cloned().unwrap_or_default())
                .with_context(|| format!("robot {player}: reading its host statistics"))?;
        let prefix = format!("t{team_number}/{player}");
        out.push(figures(&host, &RobotModules::new(&prefix)));
        scheduling.push(scheduling_note(&host, &RobotModules::new(&prefix)));
    }
    Ok(RunOutcome { robots: out, scheduling })
}

// ---------------------------------------------------------------------------------------------
// The experiment.

/// Mean and 95% CI over runs of one layer's figures.
#[derive(Clone, Debug, Serialize)]
pub struct LayerSummary {
    pub role: String,
    pub layer: String,
    pub load_s: f64,
    pub runs: usize,
    pub min_hz: Estimate,
    pub mean_hz: Estimate,
    pub max_hz: Estimate,
    pub compute_p50_ms: Estimate,
    pub compute_p99_ms: Estimate,
    pub period_p50_ms: Estimate,
    pub period_p99_ms: Estimate,
    pub jitter_p99_ms: Estimate,
}

impl LayerSummary {
    /// One layer's figures over runs (the 2D and the physics experiments).
    pub(crate) fn of(role: &str, layer: &str, load_s: f64, figures: &[&LayerFigures]) -> Self {
        let e = |f: &dyn Fn(&LayerFigures) -> f64| {
            Estimate::of(&figures.iter().map(|x| f(x)).collect::<Vec<_>>())
        };
        LayerSummary {
            role: role.to_owned(),
            layer: layer.to_owned(),
            load_s,
            runs: figures.len(),
            min_hz: e(&|x| x.min_hz),
            mean_hz: e(&|x| x.mean_hz),
            max_hz: e(&|x| x.max_hz),
            compute_p50_ms: e(&|x| x.compute_p50_ms),
            compute_p99_ms: e(&|x| x.compute_p99_ms),
            period_p50_ms: e(&|x| x.period_p50_ms),
            period_p99_ms: e(&|x| x.period_p99_ms),
            jitter_p99_ms: e(&|x| x.jitter_p99_ms),
        }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct Claim {
    pub role: String,
    pub load_s: f64,
    pub unloaded_reactive_hz: f64,
    pub loaded_reactive_hz: f64,
    pub ratio: f64,
    pub reactive_rate_kept: bool,
    /// The load really ran: the deliberative cycle's median compute time is at least the load.
    pub load_applied: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub experiment: String,
    pub scenario: String,
    pub transport: Transport,
    pub seed: u64,
    pub runs: usize,
    pub duration_s: f64,
    pub layers: Vec<LayerSummary>,
    pub claims: Vec<Claim>,
    pub reactive_rate_kept: bool,
    /// The machine's 1-minute load average at the end of each run (empty where unknown).
    pub machine_load_1min: Vec<f64>,
    /// How the robots' sensor-path threads were scheduled, each distinct way once.
    pub sensor_path_scheduling: Vec<String>,
}

pub fn run(scenario: &Scenario, ctx: &mut Ctx<'_>) -> Result<Summary> {
    let runs = ctx.runs(scenario.runs);
    let exe: Option<PathBuf> = ctx.options.strata_exe.clone();
    if scenario.transport == Transport::Tcp && exe.is_none() {
        bail!(
            "{}: transport `tcp` starts `strata robot` processes, but the strata executable is unknown (run through `strata experiment`, or use transport `in-process`)",
            ctx.scenario_source
        );
    }
    let total = (scenario.duration * (runs * scenario.loads.len()) as f64).ceil() as u64;
    let bar = ctx.progress(total, "real s");
    let mut results = Vec::new();
    let mut log = ExperimentLog::for_job(ctx, 0);
    if log.is_some() && scenario.transport == Transport::Tcp && exe.is_some() {
        eprintln!(
            "note: --log records in-process runs; over TCP each robot is a `strata robot` \
             process, which takes --log itself"
        );
    }
    // One condition at a time: real-time runs side by side would compete for the cores and
    // measure the machine, not the architecture.
    for run in 0..runs {
        for load in &scenario.loads {
            let seed = ctx.seed(run);
            let started = Instant::now();
            let RunOutcome { robots, scheduling } = match (scenario.transport, &exe) {
                (Transport::Tcp, Some(exe)) => {
                    run_tcp(scenario, &ctx.out_dir, exe, *load, seed, &|n| bar.inc(n))?
                }
                _ => run_in_process(scenario, *load, seed, log.take(), &|n| bar.inc(n))?,
            };
            results.push(RunResult {
                load: *load,
                run,
                seed,
                robots,
                scheduling,
                wall_s: started.elapsed().as_secs_f64(),
                machine_load: super::load_average(),
            });
        }
    }
    bar.finish_and_clear();
    for load in &scenario.loads {
        let _ = std::fs::remove_file(ctx.out_dir.join(format!("team-load-{load}.toml")));
    }

    let mut layers = Vec::new();
    for load in &scenario.loads {
        for (r, robot) in scenario.robots.iter().enumerate() {
            for layer in LAYERS {
                let figures: Vec<&LayerFigures> = results
                    .iter()
                    .filter(|x| x.load == *load)
                    .filter_map(|x| x.robots.get(r))
                    .filter_map(|layers| layers.iter().find(|(l, _)| l == layer).map(|(_, f)| f))
                    .collect();
                if figures.is_empty() {
                    continue;
                }
                layers.push(LayerSummary::of(&robot.role, layer, *load, &figures));
            }
        }
    }
    let find = |role: &str, layer: &str, load: f64| {
        layers
            .iter()
            .find(|l| l.role == role && l.layer == layer && (l.load_s - load).abs() < 1e-12)
    };
    let base_load = scenario.loads.iter().copied().fold(f64::INFINITY, f64::min);
    let mut claims = Vec::new();
    for robot in &scenario.robots {
        for load in scenario.loads.iter().filter(|l| **l > base_load) {
            let (Some(unloaded), Some(loaded), Some(delib)) = (
                find(&robot.role, "reactive", base_load),
                find(&robot.role, "reactive", *load),
                find(&robot.role, "deliberative", *load),
            ) else {
                continue;
            };
            claims.push(Claim {
                role: robot.role.clone(),
                load_s: *load,
                unloaded_reactive_hz: unloaded.mean_hz.mean,
                loaded_reactive_hz: loaded.mean_hz.mean,
                ratio: loaded.mean_hz.mean / unloaded.mean_hz.mean,
                reactive_rate_kept: keeps_rate(
                    unloaded.mean_hz.mean,
                    loaded.mean_hz.mean,
                    scenario.tolerance,
                ),
                load_applied: delib.compute_p50_ms.mean >= 0.95 * load * 1000.0,
            });
        }
    }
    let summary = Summary {
        experiment: NAME.to_owned(),
        scenario: ctx.scenario_source.clone(),
        transport: scenario.transport,
        seed: ctx.options.seed,
        runs,
        duration_s: scenario.duration,
        reactive_rate_kept: claims.iter().all(|c| c.reactive_rate_kept),
        layers,
        claims,
        machine_load_1min: results.iter().filter_map(|r| r.machine_load).collect(),
        sensor_path_scheduling: {
            let mut notes: Vec<String> =
                results.iter().flat_map(|r| r.scheduling.iter().cloned()).collect();
            notes.sort();
            notes.dedup();
            notes
        },
    };
    write_outputs(scenario, ctx, &results, &summary, runs)?;
    Ok(summary)
}

/// Writes every output file: the raw data, the figures and the report.
fn write_outputs(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    results: &[RunResult],
    s: &Summary,
    runs: usize,
) -> Result<()> {
    write_runs_csv(scenario, ctx, results)?;
    let (reactive_png, deliberative_png) = plot_rates(scenario, ctx, s)?;
    write_report(scenario, ctx, s, runs, reactive_png, deliberative_png)
}

/// How a load per deliberative cycle is named in figures and tables.
pub(crate) fn load_label(l: f64) -> String {
    if l == 0.0 { "no load".to_owned() } else { format!("+{:.0} ms load", l * 1000.0) }
}

/// `runs.csv`: one row per run, load, robot and layer.
fn write_runs_csv(scenario: &Scenario, ctx: &mut Ctx<'_>, results: &[RunResult]) -> Result<()> {
    let mut rows = Vec::new();
    for r in results {
        for (i, robot) in r.robots.iter().enumerate() {
            for (layer, f) in robot {
                let mut row = vec![
                    num(r.load),
                    r.run.to_string(),
                    r.seed.to_string(),
                    scenario.robots.get(i).map_or(String::new(), |x| x.role.clone()),
                    layer.clone(),
                ];
                row.extend(f.csv_fields());
                row.extend([num(r.wall_s), r.machine_load.map_or(String::new(), num)]);
                rows.push(row);
            }
        }
    }
    let csv = ctx.path("runs.csv");
    write_csv(
        &csv,
        &[
            "load_s",
            "run",
            "seed",
            "role",
            "layer",
            "cycles",
            "min_hz",
            "mean_hz",
            "max_hz",
            "compute_p50_ms",
            "compute_p99_ms",
            "compute_max_ms",
            "period_p50_ms",
            "period_p99_ms",
            "period_max_ms",
            "jitter_p99_ms",
            "wall_s",
            "machine_load_1min",
        ],
        &rows,
    )
}

/// The figures: each layer's mean rate per robot and load, beside the paper's.
fn plot_rates(scenario: &Scenario, ctx: &mut Ctx<'_>, s: &Summary) -> Result<(String, String)> {
    let mut groups = Vec::new();
    let mut reactive = Vec::new();
    let mut deliberative = Vec::new();
    let mut paper_reactive = Vec::new();
    for robot in &scenario.robots {
        for load in &scenario.loads {
            groups.push(format!("{}, {}", robot.role, load_label(*load)));
            let get = |layer: &str| {
                s.layers
                    .iter()
                    .find(|l| {
                        l.role == robot.role && l.layer == layer && (l.load_s - load).abs() < 1e-12
                    })
                    .map(|l| l.mean_hz)
                    .unwrap_or_default()
            };
            reactive.push(get("reactive"));
            deliberative.push(get("deliberative"));
            paper_reactive.push(
                scenario
                    .paper
                    .iter()
                    .find(|p| p.role == robot.role && p.layer == "reactive")
                    .map(|p| p.mean_hz),
            );
        }
    }
    let reactive_png = ctx.plot(
        &Bars {
            title: "Reactive layer: mean frequency, without and with deliberative load".into(),
            y_label: "Hz".into(),
            groups: groups.clone(),
            series: vec![("ours".into(), reactive)],
            reference: Some(("paper (Table 6, mean)".into(), paper_reactive)),
            targets: None,
        },
        "reactive_rate",
    )?;
    let deliberative_png = ctx.plot(
        &Bars {
            title: "Deliberative layer: mean frequency, without and with load".into(),
            y_label: "Hz".into(),
            groups,
            series: vec![("ours".into(), deliberative)],
            reference: Some((
                "paper (Table 6, mean)".into(),
                scenario
                    .robots
                    .iter()
                    .flat_map(|r| {
                        let v = scenario
                            .paper
                            .iter()
                            .find(|p| p.role == r.role && p.layer == "deliberative")
                            .map(|p| p.mean_hz);
                        scenario.loads.iter().map(move |_| v)
                    })
                    .collect(),
            )),
            targets: None,
        },
        "deliberative_rate",
    )?;
    Ok((reactive_png, deliberative_png))
}

/// `report.md`: the setup, Table 6 beside the paper's, every layer, the claim and the
/// figures.
fn write_report(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    s: &Summary,
    runs: usize,
    reactive_png: String,
    deliberative_png: String,
) -> Result<()> {
    let mut md = Markdown::new("Layer frequencies in real time (paper 4.3, Table 6)");
    ctx.report_head(
        NAME,
        "A goalkeeper and a striker play in real time; every layer's frequency, compute time per \
         cycle and period jitter are measured, without and with an artificial computation in \
         every deliberative cycle. The paper's claim: the reactive layer keeps its rate whatever \
         the deliberative layer does.",
        &mut md,
        runs,
    );
    report_setup(scenario, s, runs, &mut md);
    report_table6(scenario, s, &mut md);
    report_layers(&s.layers, &mut md);
    report_claim(scenario, s, &mut md);
    md.heading("Figures");
    md.image("Reactive rate", &reactive_png);
    md.image("Deliberative rate", &deliberative_png);
    ctx.finish_report(
        md,
        &[
            "`runs.csv`: one row per run, load, robot and layer (rates, compute-time and period percentiles)",
        ],
    )
}

/// What was run.
fn report_setup(scenario: &Scenario, s: &Summary, runs: usize, md: &mut Markdown) {
    md.bullets(&[
        match scenario.transport {
            Transport::Tcp => "Transport: the simulator server (real time, in the experiment's process) and one `strata robot` process per robot over TCP, as HL-SIM in the paper".to_owned(),
            Transport::InProcess => "Transport: in-process, both robots and the simulator module on one threaded host (not the paper's one process per robot)".to_owned(),
        },
        format!(
            "{} s per run and condition, {} runs, conditions one after another (never side by side); loads per deliberative cycle: {}",
            scenario.duration,
            runs,
            scenario.loads.iter().map(|l| format!("{:.0} ms", l * 1000.0)).collect::<Vec<_>>().join(", ")
        ),
        format!("Field `{}`, noise `{}`, team `{}`; the ball is moved to a random place every {} s and when it leaves the field", scenario.field, scenario.noise, scenario.team, scenario.ball_reset_period),
        format!("Machine: {} logical cores; the paper's robot: a 500 MHz AMD Geode", std::thread::available_parallelism().map_or(1, |n| n.get())),
        format!(
            "Machine load: {}",
            super::describe_load(&s.machine_load_1min)
        ),
        format!(
            "Scheduling of the sensor path (perception, world modeling, reactive layer, actuation): {}; the deliberative and planning layers: default policy",
            if s.sensor_path_scheduling.is_empty() { "unknown".to_owned() } else { s.sensor_path_scheduling.join(" | ") }
        ),
        "Min and max frequencies are over 1 s windows; jitter is the cycle period's 99th percentile minus its median".to_owned(),
    ]);
}

/// Table 6: each robot's layers without load, beside the paper's.
fn report_table6(scenario: &Scenario, s: &Summary, md: &mut Markdown) {
    md.heading("Table 6, beside the paper's");
    let mut rows = Vec::new();
    for robot in &scenario.robots {
        for layer in ["reactive", "deliberative"] {
            let paper = scenario.paper.iter().find(|p| p.role == robot.role && p.layer == layer);
            let ours = s
                .layers
                .iter()
                .find(|l| l.role == robot.role && l.layer == layer && l.load_s == 0.0);
            rows.push(vec![
                robot.role.clone(),
                layer.to_owned(),
                paper.map_or("n/a".into(), |p| {
                    format!("{} / {} / {}", p.max_hz, p.mean_hz, p.min_hz)
                }),
                ours.map_or("n/a".into(), |l| {
                    format!(
                        "{} / {} / {}",
                        l.max_hz.show(1.0, 2),
                        l.mean_hz.show(1.0, 2),
                        l.min_hz.show(1.0, 2)
                    )
                }),
            ]);
        }
    }
    md.table(
        &[
            "mission / role",
            "layer",
            "paper: max / mean / min Hz",
            "ours, no load: max / mean / min Hz",
        ],
        &rows,
    );
}

/// Every layer under every load (the 2D and the physics reports).
pub(crate) fn report_layers(layers: &[LayerSummary], md: &mut Markdown) {
    md.heading("Every layer");
    let rows: Vec<Vec<String>> = layers
        .iter()
        .map(|l| {
            vec![
                l.role.clone(),
                l.layer.clone(),
                load_label(l.load_s),
                l.max_hz.show(1.0, 2),
                l.mean_hz.show(1.0, 2),
                l.min_hz.show(1.0, 2),
                l.compute_p50_ms.show(1.0, 2),
                l.compute_p99_ms.show(1.0, 2),
                l.period_p50_ms.show(1.0, 1),
                l.period_p99_ms.show(1.0, 1),
                l.jitter_p99_ms.show(1.0, 1),
            ]
        })
        .collect();
    md.table(
        &[
            "role",
            "layer",
            "condition",
            "max Hz",
            "mean Hz",
            "min Hz",
            "compute p50 (ms)",
            "compute p99 (ms)",
            "period p50 (ms)",
            "period p99 (ms)",
            "jitter p99 (ms)",
        ],
        &rows,
    );
}

/// The claim: the reactive rate does not drop under deliberative load.
fn report_claim(scenario: &Scenario, s: &Summary, md: &mut Markdown) {
    md.heading("The claim: the reactive rate does not drop under deliberative load");
    let rows: Vec<Vec<String>> = s
        .claims
        .iter()
        .map(|c| {
            vec![
                c.role.clone(),
                format!("{:.0} ms", c.load_s * 1000.0),
                format!("{:.2}", c.unloaded_reactive_hz),
                format!("{:.2}", c.loaded_reactive_hz),
                format!("{:.1}%", c.ratio * 100.0),
                verdict(c.load_applied),
                verdict(c.reactive_rate_kept),
            ]
        })
        .collect();
    md.table(
        &[
            "role",
            "load per deliberative cycle",
            "reactive Hz, no load",
            "reactive Hz, load",
            "ratio",
            "load applied",
            "rate kept",
        ],
        &rows,
    );
    md.paragraph(&format!(
        "Rate kept: the reactive layer's mean rate under load is at least {:.0}% of its rate without load. {}",
        scenario.tolerance * 100.0,
        if s.reactive_rate_kept { "It is, for every role and load." } else { "**It is not for every role and load: see the table.**" }
    ));
}

#[cfg(test)]
mod tests {
    use super::*;
    use strata_runtime::{RateStats, Summary as Durations};

    #[test]
    fn layer_figures_convert_units_and_compute_jitter() {
        let m = ModuleStats {
            name: "r".into(),
            cycles: 100,
            errors: 0,
            rate: RateStats { min_hz: 40.0, mean_hz: 55.0, max_hz: 70.0 },
            compute_time: Durations {
                count: 100,
                mean_us: 900.0,
                min_us: 100.0,
                p50_us: 800.0,
                p90_us: 1500.0,
                p99_us: 3000.0,
                max_us: 5000.0,
            },
            latency: Durations::default(),
            period: Durations {
                count: 99,
                mean_us: 18000.0,
                min_us: 10000.0,
                p50_us: 18000.0,
                p90_us: 20000.0,
                p99_us: 30000.0,
                max_us: 45000.0,
            },
            inputs: Vec::new(),
            scheduling: Default::default(),
        };
        let f = layer_figures(&m);
        assert_eq!((f.min_hz, f.mean_hz, f.max_hz), (40.0, 55.0, 70.0));
        assert!((f.compute_p50_ms - 0.8).abs() < 1e-12);
        assert!((f.jitter_p99_ms - 12.0).abs() < 1e-12);
        assert!((f.period_max_ms - 45.0).abs() < 1e-12);
    }

    #[test]
    fn the_rate_is_kept_within_the_tolerance() {
        assert!(keeps_rate(56.0, 55.0, 0.95));
        assert!(!keeps_rate(56.0, 50.0, 0.95));
        assert!(keeps_rate(56.0, 60.0, 0.95));
    }

    #[test]
    fn the_built_in_scenario_is_valid_and_its_team_file_round_trips() {
        let mut scenario: Scenario =
            super::super::parse_scenario(DEFAULT_SCENARIO, "built-in").expect("parses");
        scenario.validate(&Check { source_name: "built-in" }, None).expect("valid");
        assert_eq!(scenario.transport, Transport::Tcp);
        let team = team_with_load(&scenario, 0.2);
        let text = toml::to_string(&team).expect("a team serializes to TOML");
        let back = TeamConfig::from_toml_str(&text, "written").expect("and reads back");
        assert_eq!(back, team);
    }
}
