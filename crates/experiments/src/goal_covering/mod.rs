//! `strata experiment goal-covering` (paper 4.2, Fig. 4, Fig. 5, Table 5): the goalkeeper covers
//! its goal while the ball moves at constant speed along fixed trajectories (the paper's: 0.2 m/s)
//! and, when the scenario asks for them, along seeded random paths at speeds drawn from a range;
//! the deliberative layer runs at 0.5, 1 and 2 Hz. The paper's method (value functions and active vision, S_d and S_r
//! averaged in the head multiplexer) is run against three gaze baselines with the same seeds:
//! always look at the ball, a fixed head scan, and entropy-based gaze selection.
//!
//! Measured on the lockstep host every `sample_period` of simulated time, after a warm-up:
//! - observe ball: the head multiplexer's selected goal is the ball alone (Table 5, column 2:
//!   the paper's head looks at one object at a time, so a joint ball+landmark gaze is not its
//!   "observe ball"); the joint gaze's share is measured beside it;
//! - ball unknown: the world model's ball estimate is not `known` (Table 5, column 3);
//! - pose error: distance between the pose estimate and the true pose (mean and 95th
//!   percentile per run);
//! - goal coverage: the fraction of the goal's angle seen from the true ball that the keeper's
//!   true position covers ([`strata_soccer::value::goal_coverage`]);
//! - time to re-cover: after the ball's direction of motion has turned by more than
//!   `recover.turn` degrees, the time until the keeper's coverage is within `recover.tolerance`
//!   of the covering pose's and stays there for `recover.hold` s ([`recover_times`]).

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{Result, anyhow};
use serde::{Deserialize, Serialize};
use strata_games::outputs;
use strata_robot::control::reactive::MuxReport;
use strata_robot::control::scores::Goal as _;
use strata_robot::geometry::{Global as FieldFrame, Point, Pose};
use strata_robot::world::WorldState;
use strata_runtime::{Tap, TapRecord};
use strata_sim::{BallScript, NoiseLevel};
use strata_soccer::behaviors::GazeStrategy;
use strata_soccer::behaviors::covering_pose;
use strata_soccer::field::TeamField;
use strata_soccer::gaze_override::GazeOverride;
use strata_soccer::gaze_policy::GazePolicy;
use strata_soccer::goals::HeadGoal;
use strata_soccer::team::TeamConfig;
use strata_soccer::value::goal_coverage;
use strata_soccer::world_config::BALL;

use super::plot::{Bars, FieldPaths, Panel, Series, Stack, Tradeoff, TradeoffPoint};
use super::report::{Markdown, num, pct, verdict, write_csv};
use super::stats::{Estimate, fraction_true, mean, percentile};
use super::{Check, Ctx, ExperimentLog, HostKind, ScenarioError, Scene, SceneRobot, Validate};

pub const NAME: &str = "goal-covering";

mod files;
pub mod gym;
pub mod learned;
mod metrics;
mod plots;
mod report;
mod scenario;

use self::files::*;
use self::learned::SHIPPED_POLICY;
pub use self::metrics::*;
use self::plots::*;
use self::report::*;
pub use self::scenario::*;

#[derive(Clone, Debug, Default)]
struct Latest {
    gaze: Gaze,
    scores: BTreeMap<String, (f64, f64, f64)>,
    ball_known: bool,
    ball_confidence: f64,
    ball_estimate: Option<Point<FieldFrame>>,
    pose: Option<Pose>,
    behavior: String,
    head: String,
}

/// Keeps the newest head decision and world state of the keeper.
struct KeeperTap {
    reactive: String,
    deliberative: String,
    world: String,
    latest: Mutex<Latest>,
    /// The newest world state, kept for a learned gaze's observation only (a copy per percept
    /// would slow the other methods down for nothing).
    world_state: Option<Mutex<Option<WorldState>>>,
}

impl Tap for KeeperTap {
    fn package(&self, record: &TapRecord<'_>) {
        if let Some(report) = record.value_from(&self.reactive, outputs::REPORT) {
            let head = &report.head;
            let gaze = gaze(head);
            let mut scores = BTreeMap::new();
            for g in head.goals.iter().filter(|g| g.objects.len() == 1) {
                let entry =
                    scores.entry(g.objects[0].clone()).or_insert((0.0, 0.0, f64::NEG_INFINITY));
                if g.final_score > entry.2 {
                    *entry = (g.deliberative, g.reactive, g.final_score);
                }
            }
            let mut latest = self.latest.lock().unwrap_or_else(|e| e.into_inner());
            latest.gaze = gaze;
            latest.scores = scores;
            latest.head = report.active_path();
        } else if let Some(scores) = record.value_from(&self.deliberative, outputs::SCORES) {
            self.latest.lock().unwrap_or_else(|e| e.into_inner()).behavior =
                scores.behavior_path.clone();
        } else if let Some(world) = record.value_from(&self.world, outputs::WORLD_STATE) {
            let ball = world.object(BALL);
            let mut latest = self.latest.lock().unwrap_or_else(|e| e.into_inner());
            latest.ball_known = ball.is_some_and(|b| b.known);
            latest.ball_confidence = ball.map_or(0.0, |b| b.confidence);
            latest.ball_estimate = ball.filter(|b| b.known).map(|b| b.global_position);
            latest.pose = Some(world.pose.pose);
            drop(latest);
            if let Some(slot) = &self.world_state {
                *slot.lock().unwrap_or_else(|e| e.into_inner()) = Some(world.clone());
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// One run.

#[derive(Clone, Debug)]
struct Job {
    method: usize,
    rate: usize,
    trajectory: usize,
    run: usize,
    seed: u64,
}

/// Run 0 of the first paths keeps its trace (plots, `timeseries.csv`): every path's would make
/// `timeseries.csv` hundreds of megabytes on a random scenario.
const TRACED_PATHS: usize = 3;

/// One job's result; a job record holds it (`crate::records`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct RunResult {
    metrics: RunMetrics,
    reactive_hz: f64,
    deliberative_hz: f64,
    /// Kept for the first run of each condition (plots, `timeseries.csv`).
    trace: Option<Vec<Sample>>,
}

fn team_point(field: &TeamField, p: Point<FieldFrame>) -> Point<FieldFrame> {
    field.to_team(p.x, p.y)
}

fn run_one(
    scenario: &Scenario,
    job: &Job,
    log: Option<ExperimentLog>,
    tick: &dyn Fn(u64),
) -> Result<RunResult> {
    let mut team = scenario.resolved[job.method].clone();
    team.timing.deliberative.rate_hz = Some(scenario.deliberative_hz[job.rate]);
    team.timing.perception.rate_hz = Some(scenario.reactive_hz);
    let [x, y, theta] = scenario.keeper_start;
    let path = &scenario.paths[job.trajectory];
    let trajectory = &path.trajectory;
    let policy = scenario.policies.get(job.method).cloned().flatten();
    let choice = policy.as_ref().map(|_| GazeOverride::new());
    let mut scene = Scene::new(
        &scenario.field,
        scenario.noise_level.unwrap_or_default(),
        job.seed,
        &[SceneRobot {
            player: 1,
            team: team.clone(),
            start: Pose::new(x, y, theta),
            gaze: choice.clone(),
        }],
    )?;
    scene.log = log;
    let (keeper, modules) = scene.robots[0].clone();
    let field = Arc::clone(&scene.field);
    // The script is in the simulator's field frame; the trajectory in the keeper's team frame.
    let waypoints: Vec<Point<FieldFrame>> =
        trajectory.waypoints.iter().map(|[x, y]| field.to_team(*x, *y)).collect();
    {
        let mut sim = scene.sim.lock();
        sim.place_ball(waypoints[0], strata_robot::geometry::Vector::new(0.0, 0.0))
            .map_err(|e| anyhow!("{e}"))?;
    }
    let tap = Arc::new(KeeperTap {
        reactive: modules.reactive.clone(),
        deliberative: modules.deliberative.clone(),
        world: modules.world.clone(),
        latest: Mutex::new(Latest::default()),
        world_state: policy.as_ref().map(|_| Mutex::new(None)),
    });
    // A learned gaze decides every deliberative period, as one step of the gaze environment.
    let decision_samples = (1.0 / scenario.deliberative_hz[job.rate] / scenario.sample_period)
        .round()
        .max(1.0) as usize;
    let mut since_decision = 0usize;
    let mut host = scene.host(HostKind::Lockstep, job.seed, tap.clone())?;
    let period = Duration::from_secs_f64(scenario.sample_period);
    let moving = trajectory.length() / path.speed;
    let end = scenario.warmup + moving + scenario.settle;
    let keep_trace = job.run == 0 && job.trajectory < TRACED_PATHS;
    let mut trace = Vec::new();
    let mut scripted = false;
    let mut last_whole = 0u64;
    let reach = team.behavior.keeper_reach;
    let depth = team.behavior.keeper_depth;
    loop {
        host.advance(period)?;
        let (now, truth, ball_truth) = {
            let sim = scene.sim.lock();
            (sim.time().as_secs_f64(), sim.robot(keeper).map_err(|e| anyhow!("{e}"))?, sim.ball())
        };
        let whole = now as u64;
        if whole > last_whole {
            tick(whole - last_whole);
            last_whole = whole;
        }
        if !scripted && now >= scenario.warmup {
            scripted = true;
            scene
                .sim
                .lock()
                .script_ball(BallScript::new(waypoints.clone(), path.speed))
                .map_err(|e| anyhow!("{e}"))?;
        }
        if let (Some(policy), Some(choice), true) = (&policy, &choice, scripted) {
            if since_decision.is_multiple_of(decision_samples) {
                let world = tap
                    .world_state
                    .as_ref()
                    .and_then(|w| w.lock().unwrap_or_else(|e| e.into_inner()).clone());
                choice.set(Some(learned_choice(policy, world.as_ref(), &field, &truth)));
            }
            since_decision += 1;
        }
        if now > end {
            break;
        }
        if now < scenario.warmup {
            continue;
        }
        let latest = tap.latest.lock().unwrap_or_else(|e| e.into_inner()).clone();
        let keeper_pose = truth.team_pose;
        let ball = team_point(&field, ball_truth.position);
        let pose_error =
            latest.pose.map_or(f64::NAN, |p| p.position().distance(keeper_pose.position()));
        let ball_error = latest.ball_estimate.map_or(f64::NAN, |b| b.distance(ball));
        let ideal = covering_pose(&field, ball, depth).position();
        let sample = Sample {
            t: now,
            observe_ball: latest.gaze == Gaze::Ball,
            joint_gaze: latest.gaze == Gaze::BallWithOthers,
            ball_known: latest.ball_known,
            ball_confidence: latest.ball_confidence,
            pose_error,
            ball_error,
            coverage: goal_coverage(&field, ball, keeper_pose.position(), reach, 1e-3),
            ideal_coverage: goal_coverage(&field, ball, ideal, reach, 1e-3),
            scores: if keep_trace {
                latest.scores.iter().map(|(k, v)| (k.clone(), v.0, v.1, v.2)).collect()
            } else {
                Vec::new()
            },
            keeper: (keeper_pose.x, keeper_pose.y),
            ball: (ball.x, ball.y),
            head: (truth.head.yaw, truth.head.pitch),
            keeper_heading: keeper_pose.theta,
            covering: latest.behavior.ends_with("/cover"),
            behavior: if keep_trace { latest.behavior.clone() } else { String::new() },
            reactive_path: if keep_trace { latest.head.clone() } else { String::new() },
        };
        trace.push(sample);
    }
    let stats = host.finish()?;
    let rate = |name: &str| stats.module(name).map_or(f64::NAN, |m| m.rate.mean_hz);
    Ok(RunResult {
        metrics: metrics(&trace, &scenario.recover),
        reactive_hz: rate(&modules.reactive),
        deliberative_hz: rate(&modules.deliberative),
        trace: keep_trace.then_some(trace),
    })
}

/// The learned gaze's choice from the keeper's world state and true head angles: what the
/// gaze environment observes at a step's start.
fn learned_choice(
    policy: &GazePolicy,
    world: Option<&WorldState>,
    field: &TeamField,
    truth: &strata_sim::RobotTruth,
) -> strata_soccer::gaze_override::GazeChoice {
    policy.choose(&gym::observation(world, field, [truth.head.yaw, truth.head.pitch]))
}

// ---------------------------------------------------------------------------------------------
// The experiment.

/// Aggregated metrics of one (method, rate).
#[derive(Clone, Debug, Default, Serialize)]
pub struct Condition {
    pub method: String,
    pub deliberative_hz: f64,
    pub runs: usize,
    pub observe_ball: Estimate,
    pub joint_gaze: Estimate,
    pub ball_unknown: Estimate,
    pub pose_error_mean: Estimate,
    pub pose_error_p95: Estimate,
    pub ball_error_mean: Estimate,
    pub coverage: Estimate,
    pub ideal_coverage: Estimate,
    pub gaze_switches_per_min: Estimate,
    pub covering_behavior: Estimate,
    /// Per run, the mean time to re-cover, s (runs without a change of direction left out).
    pub recover_time: Estimate,
    /// Per run, the fraction of direction changes not re-covered from.
    pub not_recovered: Estimate,
    pub reactive_hz: Estimate,
    pub deliberative_hz_measured: Estimate,
}

/// The reference and the baselines per (method, rate, speed band).
#[derive(Clone, Debug, Serialize)]
pub struct BandCondition {
    pub method: String,
    pub deliberative_hz: f64,
    /// m/s [low, high].
    pub speed_band: [f64; 2],
    pub runs: usize,
    pub observe_ball: Estimate,
    pub joint_gaze: Estimate,
    pub ball_unknown: Estimate,
    pub pose_error_mean: Estimate,
    pub coverage: Estimate,
    pub recover_time: Estimate,
}

/// One checked target.
#[derive(Clone, Debug, Serialize)]
pub struct Target {
    pub what: String,
    pub required: String,
    pub measured: String,
    pub met: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub experiment: String,
    pub scenario: String,
    pub seed: u64,
    pub runs: usize,
    pub conditions: Vec<Condition>,
    pub speed_bands: Vec<BandCondition>,
    pub targets: Vec<Target>,
    pub all_targets_met: bool,
}

pub fn run(scenario: &Scenario, ctx: &mut Ctx<'_>) -> Result<Summary> {
    let runs = ctx.runs(scenario.runs);
    let mut jobs = Vec::new();
    for method in 0..scenario.methods.len() {
        for rate in 0..scenario.deliberative_hz.len() {
            for trajectory in 0..scenario.paths.len() {
                for run in 0..runs {
                    // Same seed for every method and rate: the comparison is paired.
                    let seed = ctx.seed(run).wrapping_add(1000 * trajectory as u64);
                    jobs.push(Job { method, rate, trajectory, run, seed });
                }
            }
        }
    }
    let per_job: f64 = scenario
        .paths
        .iter()
        .map(|p| scenario.warmup + p.trajectory.length() / p.speed + scenario.settle)
        .sum::<f64>()
        / scenario.paths.len() as f64;
    let bar = ctx.progress((per_job * jobs.len() as f64).ceil() as u64, "simulated s");
    let log = ExperimentLog::for_job(ctx, 0);
    let results = ctx.run_jobs(&jobs, |i, job| {
        run_one(scenario, job, log.clone().filter(|_| i == 0), &|n| bar.inc(n))
    })?;
    bar.finish_and_clear();

    // Aggregate per (method, rate) over trajectories and runs.
    let mut conditions = Vec::new();
    for (m, method) in scenario.methods.iter().enumerate() {
        for (r, hz) in scenario.deliberative_hz.iter().enumerate() {
            let rs: Vec<&RunResult> = jobs
                .iter()
                .zip(&results)
                .filter(|(j, _)| j.method == m && j.rate == r)
                .map(|(_, res)| res)
                .collect();
            let e = |f: &dyn Fn(&RunResult) -> f64| {
                Estimate::of(&rs.iter().map(|x| f(x)).collect::<Vec<_>>())
            };
            conditions.push(Condition {
                method: method.name.clone(),
                deliberative_hz: *hz,
                runs: rs.len(),
                observe_ball: e(&|x| x.metrics.observe_ball),
                joint_gaze: e(&|x| x.metrics.joint_gaze),
                ball_unknown: e(&|x| x.metrics.ball_unknown),
                pose_error_mean: e(&|x| x.metrics.pose_error_mean),
                pose_error_p95: e(&|x| x.metrics.pose_error_p95),
                ball_error_mean: e(&|x| x.metrics.ball_error_mean),
                coverage: e(&|x| x.metrics.coverage),
                ideal_coverage: e(&|x| x.metrics.ideal_coverage),
                gaze_switches_per_min: e(&|x| x.metrics.gaze_switches_per_min),
                covering_behavior: e(&|x| x.metrics.covering_behavior),
                recover_time: e(&|x| x.metrics.recover_time_mean),
                not_recovered: e(&|x| x.metrics.not_recovered),
                reactive_hz: e(&|x| x.reactive_hz),
                deliberative_hz_measured: e(&|x| x.deliberative_hz),
            });
        }
    }
    let speed_bands = band_conditions(scenario, &jobs, &results);
    let condition = |method: &str, hz: f64| {
        conditions.iter().find(|c| c.method == method && (c.deliberative_hz - hz).abs() < 1e-9)
    };

    // Targets.
    let mut targets = Vec::new();
    for hz in &scenario.deliberative_hz {
        let Some(reference) = condition(&scenario.reference, *hz) else { continue };
        targets.extend(reference_targets(
            scenario,
            *hz,
            "",
            &reference.ball_unknown,
            &reference.pose_error_mean,
        ));
        for baseline in scenario.methods.iter().filter(|m| m.name != scenario.reference) {
            let Some(b) = condition(&baseline.name, *hz) else { continue };
            targets.extend(comparison_targets(&scenario.reference, reference, b));
        }
    }
    targets.extend(band_targets(scenario, &speed_bands));
    targets.extend(observe_ball_direction(scenario, &conditions));
    let all_targets_met = targets.iter().all(|t| t.met);

    write_outputs(scenario, ctx, &jobs, &results, &conditions, &speed_bands, &targets, runs)?;
    Ok(Summary {
        experiment: NAME.to_owned(),
        scenario: ctx.scenario_source.clone(),
        seed: ctx.options.seed,
        runs,
        conditions,
        speed_bands,
        targets,
        all_targets_met,
    })
}

/// The reference method against one baseline at one rate. A baseline is better on a measure
/// only when its mean lies beyond the reference's 95% interval on the better side: a
/// difference inside the interval is not one the runs can tell (the same rule for every
/// measure).
fn comparison_targets(reference_name: &str, reference: &Condition, b: &Condition) -> Vec<Target> {
    let hz = reference.deliberative_hz;
    let (name, baseline) = (reference_name, &b.method);
    let lower = |r: &Estimate, b: &Estimate| b.mean < r.low();
    let ball_better = lower(&reference.ball_unknown, &b.ball_unknown);
    let pose_better = lower(&reference.pose_error_mean, &b.pose_error_mean);
    let dominated = ball_better && pose_better;
    // A measure where lower is better, in `unit` (values scaled by 100).
    let as_low = |measure: &str, r: &Estimate, e: &Estimate, unit: &str, better: bool| Target {
        what: format!("{measure} at {hz} Hz: {name} vs {baseline}"),
        required: "at least as low (the baseline's mean within the reference's CI or above)".into(),
        measured: format!("{} vs {} {unit}", r.show(100.0, 1), e.show(100.0, 1)),
        met: !better,
    };
    vec![
        as_low("ball unknown", &reference.ball_unknown, &b.ball_unknown, "%", ball_better),
        as_low("pose error", &reference.pose_error_mean, &b.pose_error_mean, "cm", pose_better),
        Target {
            what: format!(
                "{baseline} better on both ball unknown and pose error than {name} at {hz} Hz"
            ),
            required: "no (better: the baseline's mean beyond the reference's CI)".into(),
            measured: if dominated { "yes".into() } else { "no".into() },
            met: !dominated,
        },
        Target {
            what: format!("goal coverage at {hz} Hz: {name} vs {baseline}"),
            required: "at least as high (the baseline's mean within the reference's CI or below)"
                .into(),
            measured: format!(
                "{} vs {} %",
                reference.coverage.show(100.0, 1),
                b.coverage.show(100.0, 1)
            ),
            met: reference.coverage.high() >= b.coverage.mean,
        },
    ]
}

/// Every (method, rate, speed band) over the runs of the paths in the band.
fn band_conditions(scenario: &Scenario, jobs: &[Job], results: &[RunResult]) -> Vec<BandCondition> {
    let mut bands = Vec::new();
    for (m, method) in scenario.methods.iter().enumerate() {
        for (r, hz) in scenario.deliberative_hz.iter().enumerate() {
            for (b, band) in scenario.speed_bands.iter().enumerate() {
                let rs: Vec<&RunMetrics> = jobs
                    .iter()
                    .zip(results)
                    .filter(|(j, _)| {
                        j.method == m
                            && j.rate == r
                            && scenario.speed_band(scenario.paths[j.trajectory].speed) == Some(b)
                    })
                    .map(|(_, res)| &res.metrics)
                    .collect();
                if rs.is_empty() {
                    continue;
                }
                let e = |f: &dyn Fn(&RunMetrics) -> f64| {
                    Estimate::of(&rs.iter().map(|x| f(x)).collect::<Vec<_>>())
                };
                bands.push(BandCondition {
                    method: method.name.clone(),
                    deliberative_hz: *hz,
                    speed_band: *band,
                    runs: rs.len(),
                    observe_ball: e(&|x| x.observe_ball),
                    joint_gaze: e(&|x| x.joint_gaze),
                    ball_unknown: e(&|x| x.ball_unknown),
                    pose_error_mean: e(&|x| x.pose_error_mean),
                    coverage: e(&|x| x.coverage),
                    recover_time: e(&|x| x.recover_time_mean),
                });
            }
        }
    }
    bands
}

/// The reference's absolute targets in every speed band, when there are several.
fn band_targets(scenario: &Scenario, bands: &[BandCondition]) -> Vec<Target> {
    if scenario.speed_bands.len() < 2 {
        return Vec::new();
    }
    let mut targets = Vec::new();
    for c in bands.iter().filter(|c| c.method == scenario.reference) {
        let band = format!(", ball at {}", band_label(c.speed_band));
        targets.extend(reference_targets(
            scenario,
            c.deliberative_hz,
            &band,
            &c.ball_unknown,
            &c.pose_error_mean,
        ));
    }
    targets
}

/// The reference method's own targets at one rate (`within` narrows what was measured, e.g.
/// to a speed band): ball unknown against the paper's row, mean pose error against the
/// scenario's.
fn reference_targets(
    scenario: &Scenario,
    hz: f64,
    within: &str,
    ball_unknown: &Estimate,
    pose_error: &Estimate,
) -> Vec<Target> {
    let mut targets = Vec::new();
    if let Some(row) = scenario.paper_row(hz) {
        targets.push(Target {
            what: format!("{} ball unknown at {hz} Hz{within}", scenario.reference),
            required: format!("<= {}", pct(row.target_ball_unknown)),
            measured: ball_unknown.show(100.0, 1) + " %",
            met: ball_unknown.mean <= row.target_ball_unknown,
        });
    }
    targets.push(Target {
        what: format!("{} mean pose error at {hz} Hz{within}", scenario.reference),
        required: format!("<= {:.0} cm", scenario.target_pose_error * 100.0),
        measured: pose_error.show(100.0, 1) + " cm",
        met: pose_error.mean <= scenario.target_pose_error,
    });
    targets
}

/// Observe ball changes between the lowest and the highest rate the way the paper's does.
fn observe_ball_direction(scenario: &Scenario, conditions: &[Condition]) -> Option<Target> {
    let lowest = scenario.deliberative_hz.iter().copied().reduce(f64::min)?;
    let highest = scenario.deliberative_hz.iter().copied().reduce(f64::max)?;
    if highest <= lowest {
        return None;
    }
    let paper =
        scenario.paper_row(highest)?.observe_ball - scenario.paper_row(lowest)?.observe_ball;
    let ours = |hz: f64| {
        conditions
            .iter()
            .find(|c| c.method == scenario.reference && (c.deliberative_hz - hz).abs() < 1e-9)
            .map(|c| c.observe_ball)
    };
    let (low, high) = (ours(lowest)?, ours(highest)?);
    let change = high.mean - low.mean;
    let way = |d: f64| if d < 0.0 { "falls" } else { "rises" };
    Some(Target {
        what: format!(
            "{} observe ball from {lowest} to {highest} Hz, the paper's direction",
            scenario.reference
        ),
        required: format!("{} (paper: {:+.1} points)", way(paper), 100.0 * paper),
        measured: format!(
            "{} -> {} % ({:+.1} points)",
            low.show(100.0, 1),
            high.show(100.0, 1),
            100.0 * change
        ),
        met: change * paper > 0.0,
    })
}

fn hz_label(hz: f64) -> String {
    format!("{hz} Hz")
}

#[cfg(test)]
mod tests;
