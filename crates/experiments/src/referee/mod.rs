//! `strata experiment referee`: the head referee's signals in full games. Under the SPL rules
//! robots must see the Ready gesture and hear the kick-off whistle themselves; GameController3
//! keeps sending Standby for 45 s after the gesture and Set for 15 s after the whistle. Over
//! complete 7 vs 7 games with GameController3's timing this measures whether every robot
//! reaches its kick-off position by the end of each Ready phase, how soon after the kick-off
//! whistle each robot starts playing, how often a false whistle starts a robot in Set, and what
//! the signals cost in speed against the same seeds' games with GameController3's
//! `--no-delay` (instant states, no signals).
//!
//! The metric functions are in `metrics` (re-exported here), `report.md`, the CSV files and
//! the figures in `report`.

mod metrics;
mod report;

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{Result, bail};
use serde::{Deserialize, Serialize};
use strata_runtime::{Tap, TapOutput, TapRecord, Time};
use strata_sim::{GameState, NoiseLevel, Penalty, RobotId, Simulation};
use strata_soccer::field::TeamField;
use strata_soccer::team::TeamConfig;

pub use self::metrics::*;
use self::report::{plot_figures, write_phases_csv, write_report, write_robots_csv};
use super::stats::{Estimate, mean};
use super::{Check, Ctx, ScenarioError, Validate, finish_log, parallel};
use strata_games::logging::{LogSettings, MatchLog};
use strata_games::matches::{Match, MatchConfig};
use strata_games::outputs;

pub const NAME: &str = "referee";
pub const DEFAULT_SCENARIO: &str = include_str!("../../scenarios/referee.toml");

/// How often the experiment looks at the world: the last look before Set is the position a
/// Ready phase is judged by (the referee's placement at Set moves robots).
const OBSERVE_PERIOD: Duration = Duration::from_millis(100);

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    #[serde(default)]
    pub description: String,
    #[serde(default = "default_field")]
    pub field: String,
    #[serde(default = "default_noise")]
    pub noise: String,
    /// Length of a half, s.
    #[serde(default = "default_half_duration")]
    pub half_duration: f64,
    /// Games with GameController3's timing and the signals: seeds seed .. seed + runs - 1.
    #[serde(default = "default_runs")]
    pub runs: usize,
    /// Robots per team.
    #[serde(default = "default_players")]
    pub players: u8,
    /// Both teams: a built-in team or a team file.
    #[serde(default = "default_team")]
    pub team: String,
    /// A robot reached its kick-off position when it is this close to it, m.
    #[serde(default = "default_tolerance")]
    pub tolerance: f64,
    /// A robot started the kick-off in time when its decision shows Playing this soon after
    /// the whistle, s.
    #[serde(default = "default_start_within")]
    pub start_within: f64,
    /// A robot going to Playing in Set is a false start unless a true whistle came this long
    /// before, s.
    #[serde(default = "default_false_start_window")]
    pub false_start_window: f64,
    /// The first games' seeds are also played with GameController3's `--no-delay` (no signals),
    /// the baseline for Ready positions and speed; 0: none.
    #[serde(default = "default_baseline_runs")]
    pub baseline_runs: usize,
    #[serde(default)]
    pub targets: Targets,
    #[serde(skip)]
    resolved_team: Option<TeamConfig>,
    #[serde(skip)]
    noise_level: Option<NoiseLevel>,
}

fn default_field() -> String {
    "spl".to_owned()
}
fn default_noise() -> String {
    "default".to_owned()
}
fn default_half_duration() -> f64 {
    300.0
}
fn default_runs() -> usize {
    10
}
fn default_players() -> u8 {
    7
}
fn default_team() -> String {
    "full".to_owned()
}
fn default_tolerance() -> f64 {
    0.5
}
fn default_start_within() -> f64 {
    1.0
}
fn default_false_start_window() -> f64 {
    1.0
}
fn default_baseline_runs() -> usize {
    2
}

/// What the report sets the figures against.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Targets {
    /// Fraction of Ready phases in which every robot on the field reached its position.
    pub ready_phases: f64,
    /// Fraction of kick-offs at which every robot on the field started in time.
    pub kick_offs: f64,
    /// Mean real-time factor of the games with signals (release build).
    pub real_time_factor: f64,
}

impl Default for Targets {
    fn default() -> Self {
        Targets { ready_phases: 0.95, kick_offs: 0.95, real_time_factor: 200.0 }
    }
}

impl Validate for Scenario {
    fn validate(&mut self, check: &Check<'_>, dir: Option<&Path>) -> Result<(), ScenarioError> {
        self.field = check.field_preset("field", &self.field, dir)?;
        self.noise_level = Some(check.noise("noise", &self.noise)?);
        check.positive("half_duration", self.half_duration)?;
        check.at_least("runs", self.runs, 1)?;
        if !(1..=7).contains(&self.players) {
            return Err(check.fail("players", format!("must be 1 to 7, got {}", self.players)));
        }
        self.resolved_team = Some(check.team("team", &self.team, dir)?);
        check.positive("tolerance", self.tolerance)?;
        check.positive("start_within", self.start_within)?;
        check.non_negative("false_start_window", self.false_start_window)?;
        check.fraction("targets.ready_phases", self.targets.ready_phases)?;
        check.fraction("targets.kick_offs", self.targets.kick_offs)?;
        check.non_negative("targets.real_time_factor", self.targets.real_time_factor)?;
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// Watching a game.

/// Keeps each robot's believed game state at each change, from its planning layer's
/// decisions (published on change; the stamp is the planning cycle's time).
#[derive(Default)]
struct BeliefTap {
    beliefs: Mutex<Beliefs>,
}

impl Tap for BeliefTap {
    fn package(&self, record: &TapRecord<'_>) {
        // Other outputs still come when a logger shares the host.
        let Some(package) = record.package(outputs::DECISION) else { return };
        let Some(robot) = robot_of(record.sent_on.module_name) else { return };
        let state = package.value.directive.state;
        let mut beliefs = self.beliefs.lock().unwrap_or_else(|e| e.into_inner());
        let changes = beliefs.entry(robot).or_default();
        if changes.last().is_none_or(|(_, s)| *s != state) {
            changes.push((package.stamp.as_secs_f64(), state));
        }
    }

    fn wants(&self, output: &TapOutput<'_>) -> bool {
        output.is(outputs::DECISION)
    }
}

/// `home/3/planning` -> team 0, player 3 (the names of
/// [`robot_name`](strata_games::matches::robot_name)).
fn robot_of(module_name: &str) -> Option<RobotId> {
    let mut parts = module_name.split('/');
    let team = match parts.next()? {
        "home" => 0,
        "away" => 1,
        _ => return None,
    };
    let player = parts.next()?.parse().ok()?;
    Some(RobotId::new(team, player))
}

/// The world at one look.
#[derive(Clone, Debug)]
struct Snapshot {
    time: f64,
    state: GameState,
    first_half: bool,
    kicking_team: Option<usize>,
    robots: Vec<RobotSample>,
}

fn observe(sim: &Simulation, ids: &[RobotId]) -> Snapshot {
    let game = sim.game();
    let robots = ids
        .iter()
        .filter_map(|id| sim.robot(*id).ok())
        .map(|r| RobotSample {
            robot: r.id,
            on_field: r.present && r.penalty == Penalty::None,
            fallen: r.fallen || r.falling,
            team_pose: r.team_pose,
        })
        .collect();
    Snapshot {
        time: sim.time().as_secs_f64(),
        state: game.state,
        first_half: game.first_half,
        kicking_team: game.kicking_team,
        robots,
    }
}

#[derive(Clone, Copy, Debug)]
struct Job {
    run: usize,
    seed: u64,
    /// GameController3's `--no-delay`: the baseline.
    baseline: bool,
}

impl Job {
    fn mode(&self) -> &'static str {
        if self.baseline { "no-delay" } else { "signals" }
    }
}

#[derive(Clone, Debug)]
struct GameResult {
    score: [u8; 2],
    finished: bool,
    simulated_s: f64,
    wall_s: f64,
    real_time_factor: f64,
    machine_load: Option<f64>,
    /// After the whistle, when the packets show Playing, s.
    packets_after: f64,
    /// A robot started in time within this, s (the scenario's).
    start_within: f64,
    ready: Vec<ReadyResult>,
    kick_offs: Vec<KickOffResult>,
    false_starts: Vec<FalseStart>,
    false_whistles: usize,
    false_whistles_in_set: usize,
}

/// Simulated time after which a game is stopped whatever its state: each kick-off adds
/// Standby, Ready and Set outside the game clock (60 s with GameController3's timing).
fn limit(scenario: &Scenario) -> f64 {
    2.0 * scenario.half_duration + 1800.0
}

fn play(scenario: &Scenario, job: &Job, log: Option<&Path>) -> Result<GameResult> {
    let team = scenario.resolved_team.clone().unwrap_or_default();
    let config = MatchConfig {
        players: scenario.players,
        seed: job.seed,
        home: team.clone(),
        away: team,
        half_duration: scenario.half_duration,
        limit: Some(limit(scenario)),
        noise: scenario.noise_level.unwrap_or_default(),
        field: scenario.field.clone(),
        packet_loss: 0.0,
        realtime: false,
        sim: None,
        no_delay: job.baseline,
    };
    let mut game = Match::new(config)?;
    let log = match log {
        Some(path) => Some(MatchLog::attach(&mut game, &LogSettings::full(path))?),
        None => None,
    };
    let tap = Arc::new(BeliefTap::default());
    game.add_tap(tap.clone());
    let ids: Vec<RobotId> = game.robots.iter().map(|(id, _)| *id).collect();
    let (field, packets_after) = {
        let sim = game.sim.lock();
        // Only the field's dimensions matter to the kick-off positions (team frame).
        (TeamField::new(sim.field().clone(), 1.0), sim.config().referee.delay_after_playing)
    };
    let mut host = game.lockstep()?;
    let interrupt = strata_runtime::signal::interrupt_flag().map_err(anyhow::Error::msg)?;
    host.set_interrupt(interrupt);
    let wall = Instant::now();
    let end = Time::from_secs_f64(limit(scenario));
    // The last look before each change of the true state (before Set: the robots' positions
    // the Ready phase is judged by; before Playing: who was on the field at the whistle), and
    // every look in Ready (where each robot set off from).
    let mut boundaries: Vec<Snapshot> = Vec::new();
    let mut ready_looks: Vec<Snapshot> = Vec::new();
    let mut previous: Option<Snapshot> = None;
    loop {
        host.run_until(end.min(host.now() + OBSERVE_PERIOD))?;
        let (snapshot, over) = {
            let sim = game.sim.lock();
            (observe(&sim, &ids), sim.game().game_over)
        };
        if let Some(last) = previous.take()
            && last.state != snapshot.state
        {
            boundaries.push(last);
        }
        if snapshot.state == GameState::Ready {
            ready_looks.push(snapshot.clone());
        }
        previous = Some(snapshot);
        if host.interrupted() {
            bail!("interrupted");
        }
        if over || host.now() >= end {
            break;
        }
    }
    host.stop();
    let wall_s = wall.elapsed().as_secs_f64();
    if let Some(log) = &log {
        finish_log(log.tap());
    }
    let beliefs = tap.beliefs.lock().unwrap_or_else(|e| e.into_inner()).clone();
    let sim = game.sim.lock();
    let simulated_s = sim.time().as_secs_f64();
    let events = sim.events();
    let timeline = state_timeline(events);
    let game_truth = sim.game();

    let looks = Looks { boundaries: &boundaries, ready_looks: &ready_looks, beliefs: &beliefs };
    let ready = ready_results(&looks, &timeline, events, &field, scenario.tolerance);
    let whistles = kick_off_whistles(events);
    let kick_offs = kick_off_results(&looks, &whistles, &timeline, simulated_s);
    let whistle_times: Vec<f64> = whistles.iter().map(|k| k.time).collect();
    let detections = false_whistles(events);
    let false_starts =
        false_starts(&beliefs, &timeline, &whistle_times, &detections, scenario.false_start_window);
    let (false_whistles, false_whistles_in_set) =
        (detections.len(), in_set(&detections, &timeline));
    Ok(GameResult {
        score: game_truth.score,
        finished: game_truth.game_over,
        simulated_s,
        wall_s,
        real_time_factor: simulated_s / wall_s.max(1e-9),
        machine_load: super::load_average(),
        packets_after,
        start_within: scenario.start_within,
        ready,
        kick_offs,
        false_starts,
        false_whistles,
        false_whistles_in_set,
    })
}

/// What the experiment saw of a game as it ran: the last look before each change of the true
/// state, every look in Ready, and each robot's beliefs of the game state.
struct Looks<'a> {
    boundaries: &'a [Snapshot],
    ready_looks: &'a [Snapshot],
    beliefs: &'a Beliefs,
}

/// Each Ready phase: where every robot ended it, set off from, and what happened to it.
fn ready_results(
    looks: &Looks<'_>,
    timeline: &[(f64, GameState)],
    events: &[strata_sim::Event],
    field: &TeamField,
    tolerance: f64,
) -> Vec<ReadyResult> {
    ready_phases(timeline)
        .into_iter()
        .filter_map(|phase| {
            let in_phase = |s: &&Snapshot| {
                s.state == GameState::Ready && s.time >= phase.start && s.time < phase.end
            };
            let last = looks.boundaries.iter().rfind(in_phase)?;
            let robots = last
                .robots
                .iter()
                .filter_map(|sample| {
                    let mut r = ready_check(field, last.kicking_team, sample, tolerance)?;
                    (r.fell, r.penalized) = incidents(events, sample.robot, phase.start, phase.end);
                    r.believed_ready = looks.beliefs.get(&sample.robot).and_then(|changes| {
                        first_belief(changes, GameState::Ready, phase.start, phase.end)
                    });
                    let set_off = phase.start + r.believed_ready.unwrap_or(0.0);
                    r.start_distance = looks
                        .ready_looks
                        .iter()
                        .filter(in_phase)
                        .find(|look| look.time >= set_off)
                        .and_then(|look| look.robots.iter().find(|s| s.robot == sample.robot))
                        .map(|s| kick_off_distance(field, last.kicking_team, s.robot, s.team_pose));
                    Some(r)
                })
                .collect();
            Some(ReadyResult {
                phase,
                first_half: last.first_half,
                kicking_team: last.kicking_team,
                robots,
            })
        })
        .collect()
}

/// Each kick-off whistle: when every robot on the field started playing after it.
fn kick_off_results(
    looks: &Looks<'_>,
    whistles: &[KickOffWhistle],
    timeline: &[(f64, GameState)],
    simulated_s: f64,
) -> Vec<KickOffResult> {
    whistles
        .iter()
        .filter_map(|k| {
            let last =
                looks.boundaries.iter().rfind(|s| s.state == GameState::Set && s.time <= k.time)?;
            let until = timeline
                .iter()
                .find(|(t, _)| *t > k.time + SAME_INSTANT)
                .map_or(simulated_s, |(t, _)| *t);
            let robots = last
                .robots
                .iter()
                .filter(|s| s.on_field)
                .map(|s| RobotStart {
                    robot: s.robot,
                    heard: k.heard.contains(&s.robot),
                    delay: looks
                        .beliefs
                        .get(&s.robot)
                        .and_then(|changes| start_delay(changes, k.time, until)),
                })
                .collect();
            Some(KickOffResult {
                kick_off: k.clone(),
                first_half: last.first_half,
                kicking_team: last.kicking_team,
                robots,
            })
        })
        .collect()
}

/// The progress line of a finished game.
fn game_line(job: &Job, r: &GameResult, within: f64, games: usize) -> String {
    let ready = ready_summary(&r.ready);
    let kick = kick_off_summary(&r.kick_offs, within, r.packets_after);
    let median = kick.delay.as_ref().map_or(f64::NAN, |d| d.median);
    format!(
        "{NAME}: game {}/{games} ({}, seed {}): {}-{}{}, Ready {}/{} phases ({} of {} robots), \
         kick-offs {}/{} all within {within} s (median {:.2} s), {} false starts, RTF {:.0}x ({:.1} s)",
        job.run + 1,
        job.mode(),
        job.seed,
        r.score[0],
        r.score[1],
        if r.finished { "" } else { " (not finished)" },
        ready.phases_reached,
        ready.phases,
        ready.robots_reached,
        ready.robots,
        kick.all_within,
        kick.kick_offs,
        median,
        r.false_starts.len(),
        r.real_time_factor,
        r.wall_s,
    )
}

// ---------------------------------------------------------------------------------------------
// The experiment.

#[derive(Clone, Debug, Serialize)]
pub struct FalseStartSummary {
    pub episodes: usize,
    /// Episodes of a robot whose own detector fired; the others followed a teammate's false
    /// whistle, relayed in a team message.
    pub own_whistle: usize,
    /// Robot-seconds in Playing before the kick-off.
    pub seconds: f64,
    pub false_whistles: usize,
    pub false_whistles_in_set: usize,
}

#[derive(Clone, Debug, Serialize)]
pub struct RealTime {
    /// Games with signals.
    pub signals: Estimate,
    pub signals_min: f64,
    /// The same seeds' first games with `--no-delay`.
    pub baseline: Estimate,
    /// Mean real-time factor with signals over the baseline's, on the baseline's seeds.
    pub ratio: f64,
    pub release_build: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct TargetCheck {
    pub what: String,
    pub value: f64,
    pub target: f64,
    pub met: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub experiment: String,
    pub scenario: String,
    pub seed: u64,
    pub runs: usize,
    pub baseline_runs: usize,
    pub players: u8,
    pub half_duration: f64,
    pub tolerance: f64,
    pub start_within: f64,
    pub false_start_window: f64,
    /// Games run at once.
    pub threads: usize,
    pub ready: ReadySummary,
    pub kick_offs: KickOffSummary,
    pub false_starts: FalseStartSummary,
    /// The Ready phases at the start of a half, and after a goal.
    pub ready_half_start: ReadySummary,
    pub ready_after_goal: ReadySummary,
    /// The same figures of the `--no-delay` games (the packets alone).
    pub baseline_ready: ReadySummary,
    pub baseline_ready_half_start: ReadySummary,
    pub baseline_ready_after_goal: ReadySummary,
    pub baseline_kick_offs: KickOffSummary,
    pub real_time: RealTime,
    pub targets: Vec<TargetCheck>,
    pub finished: usize,
    pub wall_s: f64,
    pub machine_load_1min: Vec<f64>,
}

pub fn run(scenario: &Scenario, ctx: &mut Ctx<'_>) -> Result<Summary> {
    let runs = ctx.runs(scenario.runs);
    let baseline_runs = scenario.baseline_runs.min(runs);
    // Each baseline game beside its seed's game with signals: the two run at the same time,
    // on the same machine load.
    let mut jobs = Vec::new();
    for run in 0..runs {
        jobs.push(Job { run, seed: ctx.seed(run), baseline: false });
        if run < baseline_runs {
            jobs.push(Job { run, seed: ctx.seed(run), baseline: true });
        }
    }
    let started = Instant::now();
    let bar = ctx.progress(jobs.len() as u64, "games");
    let log = ctx.options.log.clone();
    let within = scenario.start_within;
    let ctx_progress = ctx.options.progress;
    let results = parallel(&jobs, ctx.options.threads, |i, job| {
        let result = play(scenario, job, log.as_deref().filter(|_| i == 0))?;
        let games = if job.baseline { baseline_runs } else { runs };
        if ctx_progress {
            let line = game_line(job, &result, within, games);
            // indicatif draws nothing when stderr is not a terminal; the lines still matter.
            if bar.is_hidden() {
                eprintln!("{line}");
            } else {
                bar.println(line);
            }
        }
        bar.inc(1);
        Ok(result)
    })?;
    bar.finish_and_clear();
    let wall_s = started.elapsed().as_secs_f64();

    let of =
        |baseline: bool| jobs.iter().zip(&results).filter(move |(j, _)| j.baseline == baseline);
    let packets_after = of(false).map(|(_, r)| r.packets_after).next().unwrap_or(0.0);
    let ready = ready_summary(of(false).flat_map(|(_, r)| &r.ready));
    let kick_offs =
        kick_off_summary(of(false).flat_map(|(_, r)| &r.kick_offs), within, packets_after);
    let baseline_ready = ready_summary(of(true).flat_map(|(_, r)| &r.ready));
    let split = |baseline: bool, after_goal: bool| {
        ready_summary(
            of(baseline).flat_map(|(_, r)| &r.ready).filter(|p| p.phase.after_goal == after_goal),
        )
    };
    let baseline_kick_offs =
        kick_off_summary(of(true).flat_map(|(_, r)| &r.kick_offs), within, 0.0);
    let false_starts = FalseStartSummary {
        episodes: of(false).map(|(_, r)| r.false_starts.len()).sum(),
        own_whistle: of(false).flat_map(|(_, r)| &r.false_starts).filter(|f| f.own_whistle).count(),
        seconds: of(false)
            .flat_map(|(_, r)| &r.false_starts)
            .map(|f| f.duration)
            .filter(|d| d.is_finite())
            // Not `sum`: a float sum of nothing is -0.0, which the report would print.
            .fold(0.0, |total, d| total + d),
        false_whistles: of(false).map(|(_, r)| r.false_whistles).sum(),
        false_whistles_in_set: of(false).map(|(_, r)| r.false_whistles_in_set).sum(),
    };
    let signals_rtf: Vec<f64> = of(false).map(|(_, r)| r.real_time_factor).collect();
    let paired: Vec<f64> =
        of(false).filter(|(j, _)| j.run < baseline_runs).map(|(_, r)| r.real_time_factor).collect();
    let baseline_rtf: Vec<f64> = of(true).map(|(_, r)| r.real_time_factor).collect();
    let real_time = RealTime {
        signals: Estimate::of(&signals_rtf),
        signals_min: signals_rtf.iter().copied().fold(f64::NAN, f64::min),
        baseline: Estimate::of(&baseline_rtf),
        ratio: mean(&paired) / mean(&baseline_rtf),
        release_build: !cfg!(debug_assertions),
    };
    let t = &scenario.targets;
    let targets = vec![
        TargetCheck {
            what: format!(
                "Ready phases in which every robot on the field ended within {} m of its kick-off position",
                scenario.tolerance
            ),
            value: ready.phase_rate,
            target: t.ready_phases,
            met: ready.phase_rate >= t.ready_phases,
        },
        TargetCheck {
            what: format!(
                "kick-offs at which every robot on the field started within {within} s of the whistle"
            ),
            value: kick_offs.phase_rate,
            target: t.kick_offs,
            met: kick_offs.phase_rate >= t.kick_offs,
        },
        TargetCheck {
            what: format!(
                "real-time factor of {0} vs {0} games with signals (mean)",
                scenario.players
            ),
            value: real_time.signals.mean,
            target: t.real_time_factor,
            met: real_time.signals.mean >= t.real_time_factor,
        },
    ];
    let summary = Summary {
        experiment: NAME.to_owned(),
        scenario: ctx.scenario_source.clone(),
        seed: ctx.options.seed,
        runs,
        baseline_runs,
        players: scenario.players,
        half_duration: scenario.half_duration,
        tolerance: scenario.tolerance,
        start_within: within,
        false_start_window: scenario.false_start_window,
        threads: ctx.options.threads.clamp(1, jobs.len().max(1)),
        ready,
        ready_half_start: split(false, false),
        ready_after_goal: split(false, true),
        kick_offs,
        false_starts,
        baseline_ready,
        baseline_ready_half_start: split(true, false),
        baseline_ready_after_goal: split(true, true),
        baseline_kick_offs,
        real_time,
        targets,
        finished: of(false).filter(|(_, r)| r.finished).count(),
        wall_s,
        machine_load_1min: results.iter().filter_map(|r| r.machine_load).collect(),
    };
    write_phases_csv(ctx, &jobs, &results, within)?;
    write_robots_csv(ctx, &jobs, &results)?;
    let figures = plot_figures(scenario, ctx, &jobs, &results)?;
    write_report(scenario, ctx, &summary, &jobs, &results, &figures)?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn home(player: u8) -> RobotId {
        RobotId::new(0, player)
    }

    #[test]
    fn robots_are_named_by_their_modules() {
        assert_eq!(robot_of("home/3/planning"), Some(home(3)));
        assert_eq!(robot_of("away/7/planning"), Some(RobotId::new(1, 7)));
        assert_eq!(robot_of("simulator"), None);
        assert_eq!(robot_of("home/x/planning"), None);
    }

    #[test]
    fn the_built_in_scenario_is_valid_and_bad_values_name_the_field() {
        let mut scenario: Scenario =
            super::super::parse_scenario(DEFAULT_SCENARIO, "built-in").expect("parses");
        scenario.validate(&Check { source_name: "built-in" }, None).expect("valid");
        assert_eq!((scenario.runs, scenario.players, scenario.baseline_runs), (10, 7, 10));
        assert_eq!((scenario.half_duration, scenario.tolerance), (300.0, 0.5));
        // Every key but the ones below has a default.
        let mut minimal: Scenario =
            super::super::parse_scenario("runs = 1", "minimal.toml").expect("parses");
        minimal.validate(&Check { source_name: "minimal.toml" }, None).expect("valid");
        assert_eq!((minimal.tolerance, minimal.baseline_runs), (0.5, 2));
        let bad = |text: &str| {
            let mut s: Scenario = super::super::parse_scenario(text, "bad.toml").expect("parses");
            s.validate(&Check { source_name: "bad.toml" }, None).expect_err("invalid").to_string()
        };
        let e = bad("tolerance = -1.0");
        assert!(e.contains("bad.toml") && e.contains("tolerance"), "{e}");
        let e = bad("players = 8");
        assert!(e.contains("players"), "{e}");
        let e = bad("team = \"nobody\"");
        assert!(e.contains("team") && e.contains("nobody"), "{e}");
        let e = bad("[targets]\nkick_offs = 1.5");
        assert!(e.contains("targets.kick_offs"), "{e}");
        let e = super::super::parse_scenario::<Scenario>("tolerence = 0.5", "bad.toml")
            .expect_err("unknown field")
            .to_string();
        assert!(e.contains("tolerence"), "{e}");
    }
}
