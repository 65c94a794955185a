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
use strata_runtime::{Tap, TapRecord};
use strata_sim::{BallScript, NoiseLevel};
use strata_soccer::behaviors::covering_pose;
use strata_soccer::field::TeamField;
use strata_soccer::goals::HeadGoal;
use strata_soccer::team::TeamConfig;
use strata_soccer::value::goal_coverage;
use strata_soccer::world_config::BALL;

use super::plot::{Bars, FieldPaths, Panel, Series, Stack, Tradeoff, TradeoffPoint};
use super::report::{Markdown, num, pct, verdict, write_csv};
use super::stats::{Estimate, fraction_true, mean, percentile};
use super::{
    Check, Ctx, ExperimentLog, HostKind, ScenarioError, Scene, SceneRobot, Validate, parallel,
};

pub const NAME: &str = "goal-covering";
pub const DEFAULT_SCENARIO: &str = include_str!("../scenarios/goal-covering.toml");

/// The scenario (`scenarios/goal-covering.toml`).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    #[serde(default)]
    pub description: String,
    /// Field preset or field file.
    pub field: String,
    /// Simulator noise preset: none, default, high.
    pub noise: String,
    /// Runs per (method, rate, trajectory).
    pub runs: usize,
    /// Ball speed along every fixed trajectory, m/s (needed when there are any).
    #[serde(default)]
    pub ball_speed: Option<f64>,
    /// Deliberative-layer rates, Hz.
    pub deliberative_hz: Vec<f64>,
    /// Sensor rate, Hz: the reactive layer runs on every percept.
    pub reactive_hz: f64,
    /// Seconds before the ball starts moving (the keeper localizes); not measured.
    pub warmup: f64,
    /// Seconds measured after the ball stops.
    pub settle: f64,
    /// Sampling period of the metrics, s of simulated time.
    pub sample_period: f64,
    /// Keeper's start pose, team frame [x, y, theta].
    pub keeper_start: [f64; 3],
    /// The method the targets apply to and the baselines are compared with.
    pub reference: String,
    /// Mean pose error the reference method must stay under, m.
    pub target_pose_error: f64,
    pub methods: Vec<Method>,
    /// Fixed trajectories, run at `ball_speed`.
    #[serde(default)]
    pub trajectories: Vec<Trajectory>,
    /// Seeded random paths at speeds drawn from a range, run after the fixed trajectories.
    #[serde(default)]
    pub random: Option<RandomPaths>,
    /// How the time to re-cover is measured.
    #[serde(default)]
    pub recover: Recover,
    /// The paper's Table 5, and the targets per rate.
    #[serde(default)]
    pub paper: Vec<PaperRow>,
    #[serde(skip)]
    resolved: Vec<TeamConfig>,
    #[serde(skip)]
    noise_level: Option<NoiseLevel>,
    /// The fixed trajectories, then the random paths: what the runs follow.
    #[serde(skip)]
    pub paths: Vec<BallPath>,
    /// The report's speed bands, m/s [low, high].
    #[serde(skip)]
    pub speed_bands: Vec<[f64; 2]>,
}

/// Seeded random ball paths: the method is measured on paths nobody drew by hand.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RandomPaths {
    /// How many paths.
    pub paths: usize,
    /// The paths and their speeds are drawn from this seed alone, not from `--seed`: every run
    /// of every method follows the same paths.
    pub seed: u64,
    /// Range of the ball's speed [min, max], m/s; each path's constant speed is drawn uniformly.
    pub speed: [f64; 2],
    /// Range of the number of straight segments of a path [min, max].
    pub segments: [usize; 2],
    /// Shortest segment, m.
    pub min_segment: f64,
    /// Where waypoints are drawn, keeper's team frame [[x_min, y_min], [x_max, y_max]], m;
    /// segments that enter the own penalty area (0.1 m margin) are drawn again, since there the
    /// keeper leaves its goal to clear the ball.
    pub region: [[f64; 2]; 2],
    /// The report splits `speed` into this many equal bands.
    pub speed_bands: usize,
}

/// The definition of the time to re-cover.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Recover {
    /// A change of the ball's direction: its velocity has turned by more than this since the
    /// previous change (or since it started moving), degrees.
    pub turn: f64,
    /// Covered again: the keeper's coverage is at least the covering pose's minus this.
    pub tolerance: f64,
    /// ... for this long without interruption, s: a keeper sweeping through the right place is
    /// not covering.
    pub hold: f64,
}

impl Default for Recover {
    fn default() -> Self {
        Recover { turn: 40.0, tolerance: 0.05, hold: 0.5 }
    }
}

/// A path the ball follows in a run, at a constant speed.
#[derive(Clone, Debug, Serialize)]
pub struct BallPath {
    pub trajectory: Trajectory,
    /// m/s.
    pub speed: f64,
    /// Drawn from `[random]`.
    pub random: bool,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Method {
    pub name: String,
    /// A built-in team (full, always-ball, fixed-scan, entropy, ...) or a team TOML file.
    pub team: String,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Trajectory {
    pub name: String,
    /// Polyline in the keeper's team frame (own goal at -x), m.
    pub waypoints: Vec<[f64; 2]>,
}

impl Trajectory {
    pub fn length(&self) -> f64 {
        self.waypoints
            .windows(2)
            .map(|w| ((w[1][0] - w[0][0]).powi(2) + (w[1][1] - w[0][1]).powi(2)).sqrt())
            .sum()
    }

    /// Where the ball is `s` metres along the path, and its direction there (unit vector).
    pub fn at(&self, s: f64) -> ([f64; 2], [f64; 2]) {
        let mut left = s.max(0.0);
        let mut last = ([0.0; 2], [0.0; 2]);
        for w in self.waypoints.windows(2) {
            let (d, e) = (w[1][0] - w[0][0], w[1][1] - w[0][1]);
            let length = d.hypot(e);
            if length <= 0.0 {
                continue;
            }
            let direction = [d / length, e / length];
            if left <= length {
                return ([w[0][0] + direction[0] * left, w[0][1] + direction[1] * left], direction);
            }
            left -= length;
            last = (w[1], direction);
        }
        last
    }
}

/// The checks both goal-covering scenarios (2D and physics) make of their methods, reference
/// and trajectories; the methods' teams, resolved.
pub(crate) fn check_methods_and_trajectories(
    check: &Check<'_>,
    dir: Option<&Path>,
    methods: &[Method],
    reference: &str,
    trajectories: &[Trajectory],
) -> Result<Vec<TeamConfig>, ScenarioError> {
    let resolved = check_methods(check, dir, methods, reference)?;
    check_trajectories(check, trajectories, false)?;
    Ok(resolved)
}

/// The methods' teams, resolved; the reference is one of them.
fn check_methods(
    check: &Check<'_>,
    dir: Option<&Path>,
    methods: &[Method],
    reference: &str,
) -> Result<Vec<TeamConfig>, ScenarioError> {
    check.not_empty("methods", methods)?;
    let mut resolved = Vec::with_capacity(methods.len());
    for (i, m) in methods.iter().enumerate() {
        resolved.push(check.team(&format!("methods[{i}].team"), &m.team, dir)?);
    }
    if !methods.iter().any(|m| m.name == reference) {
        return Err(check.fail("reference", format!("`{reference}` is not one of the methods")));
    }
    Ok(resolved)
}

/// Fixed trajectories: at least one unless random paths are drawn; each a finite polyline.
fn check_trajectories(
    check: &Check<'_>,
    trajectories: &[Trajectory],
    random_paths: bool,
) -> Result<(), ScenarioError> {
    if !random_paths {
        check.not_empty("trajectories", trajectories)?;
    }
    for (i, t) in trajectories.iter().enumerate() {
        if t.waypoints.len() < 2 {
            return Err(
                check.fail(&format!("trajectories[{i}].waypoints"), "needs at least two points")
            );
        }
        if t.waypoints.iter().flatten().any(|v| !v.is_finite()) {
            return Err(check.fail(&format!("trajectories[{i}].waypoints"), "must be finite"));
        }
    }
    Ok(())
}

impl RandomPaths {
    /// The section's own checks; the region must lie on the field.
    fn check(&self, check: &Check<'_>, field: &TeamField) -> Result<(), ScenarioError> {
        check.at_least("random.paths", self.paths, 1)?;
        let [low, high] = self.speed;
        check.positive("random.speed[0]", low)?;
        check.positive("random.speed[1]", high)?;
        if low > high {
            return Err(check.fail("random.speed", format!("[{low}, {high}]: min above max")));
        }
        let [fewest, most] = self.segments;
        check.at_least("random.segments[0]", fewest, 1)?;
        if fewest > most {
            return Err(check.fail("random.segments", format!("[{fewest}, {most}]: min above max")));
        }
        check.positive("random.min_segment", self.min_segment)?;
        let [[x0, y0], [x1, y1]] = self.region;
        if ![x0, y0, x1, y1].iter().all(|v| v.is_finite()) || x0 >= x1 || y0 >= y1 {
            return Err(check.fail(
                "random.region",
                "must be [[x_min, y_min], [x_max, y_max]] with finite x_min < x_max, y_min < y_max",
            ));
        }
        if !field.is_inside(Point::new(x0, y0), 0.0) || !field.is_inside(Point::new(x1, y1), 0.0) {
            return Err(check.fail(
                "random.region",
                format!(
                    "must lie on the field (|x| <= {}, |y| <= {})",
                    field.half_length, field.half_width
                ),
            ));
        }
        check.at_least("random.speed_bands", self.speed_bands, 1)?;
        Ok(())
    }
}

/// Attempts at drawing one waypoint before the region is declared unusable.
const WAYPOINT_ATTEMPTS: usize = 10_000;

/// The random paths of `random`, drawn from its seed alone: the same on every machine and for
/// every `--seed`. A segment is drawn again when it is shorter than `min_segment` or passes
/// within 0.1 m of the own penalty area.
pub fn random_paths(random: &RandomPaths, field: &TeamField) -> Result<Vec<BallPath>, String> {
    use rand::{RngExt as _, SeedableRng as _};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(random.seed);
    let [[x0, y0], [x1, y1]] = random.region;
    let clear = |a: Point<FieldFrame>, b: Point<FieldFrame>| {
        let steps = (a.distance(b) / 0.05).ceil().max(1.0) as usize;
        (0..=steps).all(|k| !field.in_own_penalty_area(a.lerp(b, k as f64 / steps as f64), 0.1))
    };
    let mut paths = Vec::with_capacity(random.paths);
    for i in 0..random.paths {
        let speed = rng.random_range(random.speed[0]..=random.speed[1]);
        let segments = rng.random_range(random.segments[0]..=random.segments[1]);
        let mut waypoints: Vec<Point<FieldFrame>> = Vec::with_capacity(segments + 1);
        while waypoints.len() <= segments {
            let drawn = (0..WAYPOINT_ATTEMPTS).find_map(|_| {
                let p = Point::new(rng.random_range(x0..=x1), rng.random_range(y0..=y1));
                let fits = match waypoints.last() {
                    None => clear(p, p),
                    Some(&last) => last.distance(p) >= random.min_segment && clear(last, p),
                };
                fits.then_some(p)
            });
            let Some(p) = drawn else {
                return Err(format!(
                    "no segment of at least {} m outside the own penalty area found in \
                     {WAYPOINT_ATTEMPTS} draws for path {i}",
                    random.min_segment
                ));
            };
            waypoints.push(p);
        }
        paths.push(BallPath {
            trajectory: Trajectory {
                name: format!("random-{i}"),
                waypoints: waypoints.iter().map(|p| [p.x, p.y]).collect(),
            },
            speed,
            random: true,
        });
    }
    Ok(paths)
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PaperRow {
    pub deliberative_hz: f64,
    /// Table 5: fraction of time the robot decides to observe the ball.
    pub observe_ball: f64,
    /// Table 5: fraction of time the ball position is unknown.
    pub ball_unknown: f64,
    /// The target for the reference method's ball-unknown fraction.
    pub target_ball_unknown: f64,
}

impl Validate for Scenario {
    fn validate(&mut self, check: &Check<'_>, dir: Option<&Path>) -> Result<(), ScenarioError> {
        self.field = check.field_preset("field", &self.field, dir)?;
        self.noise_level = Some(check.noise("noise", &self.noise)?);
        check.at_least("runs", self.runs, 1)?;
        if let Some(speed) = self.ball_speed {
            check.positive("ball_speed", speed)?;
        }
        check.not_empty("deliberative_hz", &self.deliberative_hz)?;
        for (i, hz) in self.deliberative_hz.iter().enumerate() {
            check.positive(&format!("deliberative_hz[{i}]"), *hz)?;
        }
        check.positive("reactive_hz", self.reactive_hz)?;
        check.non_negative("warmup", self.warmup)?;
        check.non_negative("settle", self.settle)?;
        check.positive("sample_period", self.sample_period)?;
        check.positive("target_pose_error", self.target_pose_error)?;
        if !self.keeper_start.iter().all(|v| v.is_finite()) {
            return Err(check.fail("keeper_start", "must be three finite numbers"));
        }
        self.resolved = check_methods(check, dir, &self.methods, &self.reference)?;
        check_trajectories(check, &self.trajectories, self.random.is_some())?;
        check.positive("recover.turn", self.recover.turn)?;
        if self.recover.turn >= 180.0 {
            return Err(check.fail("recover.turn", "must be under 180 degrees"));
        }
        check.fraction("recover.tolerance", self.recover.tolerance)?;
        check.non_negative("recover.hold", self.recover.hold)?;
        self.paths = Vec::new();
        if !self.trajectories.is_empty() {
            let Some(speed) = self.ball_speed else {
                return Err(check.fail("ball_speed", "is needed by the fixed `trajectories`"));
            };
            self.paths.extend(self.trajectories.iter().map(|t| BallPath {
                trajectory: t.clone(),
                speed,
                random: false,
            }));
        }
        self.speed_bands = Vec::new();
        if let Some(random) = &self.random {
            let field = strata_spl::Field::preset(&self.field)
                .or_else(|_| strata_spl::Field::load(&self.field))
                .map_err(|e| check.fail("field", e.to_string()))?;
            let field = TeamField::new(field, 1.0);
            random.check(check, &field)?;
            self.paths
                .extend(random_paths(random, &field).map_err(|e| check.fail("random.region", e))?);
            let [low, high] = random.speed;
            let width = (high - low) / random.speed_bands as f64;
            self.speed_bands = (0..random.speed_bands)
                .map(|i| [low + width * i as f64, low + width * (i + 1) as f64])
                .collect();
        }
        for path in &self.paths {
            if self.speed_band(path.speed).is_none() {
                self.speed_bands.push([path.speed, path.speed]);
            }
        }
        for (i, row) in self.paper.iter().enumerate() {
            check.fraction(&format!("paper[{i}].observe_ball"), row.observe_ball)?;
            check.fraction(&format!("paper[{i}].ball_unknown"), row.ball_unknown)?;
            check.fraction(&format!("paper[{i}].target_ball_unknown"), row.target_ball_unknown)?;
        }
        Ok(())
    }
}

impl Scenario {
    fn paper_row(&self, hz: f64) -> Option<&PaperRow> {
        self.paper.iter().find(|r| (r.deliberative_hz - hz).abs() < 1e-9)
    }

    /// The speed band `speed` falls in (bands include both ends; the first that fits).
    pub fn speed_band(&self, speed: f64) -> Option<usize> {
        let slack = 1e-9;
        self.speed_bands
            .iter()
            .position(|[low, high]| speed >= low - slack && speed <= high + slack)
    }
}

/// "0.1-0.2 m/s", or "0.2 m/s" for a single speed.
fn band_label(band: [f64; 2]) -> String {
    if (band[1] - band[0]).abs() < 1e-9 {
        format!("{} m/s", num_short(band[0]))
    } else {
        format!("{}-{} m/s", num_short(band[0]), num_short(band[1]))
    }
}

fn num_short(v: f64) -> String {
    let s = format!("{v:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_owned()
}

// ---------------------------------------------------------------------------------------------
// Metrics of one run, from its trace.

/// One sample of a run.
/// One object's head multiplexer scores: (object, S_d, S_r, final).
pub type ObjectScores = (String, f64, f64, f64);

#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Sample {
    pub t: f64,
    /// The head multiplexer's selected goal is the ball alone (Table 5's "observe ball").
    pub observe_ball: bool,
    /// The selected goal is the ball together with other objects (a landmark).
    pub joint_gaze: bool,
    pub ball_known: bool,
    pub ball_confidence: f64,
    /// Distance of the pose estimate from the true pose, m (NaN before the first estimate).
    pub pose_error: f64,
    /// Distance of the ball estimate from the true ball when known, m.
    pub ball_error: f64,
    pub coverage: f64,
    pub ideal_coverage: f64,
    /// Head multiplexer scores per single object: (object, S_d, S_r, final).
    pub scores: Vec<ObjectScores>,
    pub keeper: (f64, f64),
    pub ball: (f64, f64),
    /// True head (yaw, pitch), rad: shows where the camera looked when the ball was lost.
    pub head: (f64, f64),
    /// True heading of the keeper, rad (team frame).
    pub keeper_heading: f64,
    /// The deliberative layer was in the cover behavior.
    pub covering: bool,
    /// The deliberative layer's active behavior path and the reactive layer's (run 0 only).
    pub behavior: String,
    pub reactive_path: String,
}

/// The metrics of one run (the columns of `runs.csv`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunMetrics {
    pub samples: usize,
    pub observe_ball: f64,
    /// Fraction of the time the head looked at the ball together with other objects.
    pub joint_gaze: f64,
    pub ball_unknown: f64,
    pub pose_error_mean: f64,
    pub pose_error_p95: f64,
    pub ball_error_mean: f64,
    pub coverage: f64,
    pub ideal_coverage: f64,
    /// Gaze changes between the ball and anything else, per minute.
    pub gaze_switches_per_min: f64,
    /// Fraction of the time the deliberative layer was in the cover behavior (not searching
    /// for the ball, not localizing).
    pub covering_behavior: f64,
    /// Changes of the ball's direction ([`recover_times`]).
    pub direction_changes: usize,
    /// Mean time to re-cover after those the keeper re-covered from, s (NaN: none).
    pub recover_time_mean: f64,
    /// Fraction of the changes the keeper did not re-cover from before the next or the end.
    pub not_recovered: f64,
}

/// Where the head multiplexer's selected goal looks, in Table 5's terms.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Gaze {
    /// At the ball alone: the paper's "observe ball".
    Ball,
    /// At the ball together with other objects in one gaze.
    BallWithOthers,
    /// At something else, or at nothing.
    #[default]
    Other,
}

/// The gaze of the head multiplexer's decision. The baselines send the plain observe-ball goal
/// without objects; the value functions name the objects of every goal.
pub fn gaze(head: &MuxReport) -> Gaze {
    let Some(label) = &head.selected_goal else { return Gaze::Other };
    let observe_ball = HeadGoal::ObserveBall.label();
    match head.goals.iter().find(|g| &g.goal == label) {
        Some(goal) => {
            let ball = goal.objects.iter().any(|o| o == BALL);
            match (ball, goal.objects.len()) {
                (true, 1) => Gaze::Ball,
                (true, _) => Gaze::BallWithOthers,
                (false, 0) if **label == *observe_ball => Gaze::Ball,
                _ => Gaze::Other,
            }
        }
        None if **label == *observe_ball => Gaze::Ball,
        None => Gaze::Other,
    }
}

/// The time to re-cover after each change of the ball's direction, in order; `None` where the
/// keeper did not re-cover before the next change or the end of the trace.
///
/// A change: the direction of the true ball's displacement between consecutive samples has
/// turned by more than `recover.turn` degrees from the direction at the previous change (or
/// where the ball started moving), so a gradual curve counts once per `turn` degrees. Samples
/// where the ball moved less than 0.1 mm have no direction. Re-covered: from some sample on,
/// `coverage >= ideal_coverage - recover.tolerance` for `recover.hold` s; the time is from the
/// change to that sample.
pub fn recover_times(trace: &[Sample], recover: &Recover) -> Vec<Option<f64>> {
    let turn = recover.turn.to_radians();
    let mut changes = Vec::new();
    let mut reference: Option<f64> = None;
    for (i, w) in trace.windows(2).enumerate() {
        let (dx, dy) = (w[1].ball.0 - w[0].ball.0, w[1].ball.1 - w[0].ball.1);
        if dx.hypot(dy) < 1e-4 {
            continue;
        }
        let heading = dy.atan2(dx);
        match reference {
            None => reference = Some(heading),
            Some(r) => {
                let turned = (heading - r + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                    - std::f64::consts::PI;
                if turned.abs() > turn {
                    changes.push(i + 1);
                    reference = Some(heading);
                }
            }
        }
    }
    let covered: Vec<bool> =
        trace.iter().map(|s| s.coverage >= s.ideal_coverage - recover.tolerance).collect();
    changes
        .iter()
        .enumerate()
        .map(|(k, &start)| {
            let until = changes.get(k + 1).copied().unwrap_or(trace.len());
            (start..until)
                .find(|&j| {
                    let held = trace[j].t + recover.hold;
                    trace.last().is_some_and(|last| last.t >= held - 1e-9)
                        && trace[j..]
                            .iter()
                            .zip(&covered[j..])
                            .take_while(|(s, _)| s.t <= held + 1e-9)
                            .all(|(_, c)| *c)
                })
                .map(|j| trace[j].t - trace[start].t)
        })
        .collect()
}

/// The metrics of a trace sampled at a constant period.
pub fn metrics(trace: &[Sample], recover: &Recover) -> RunMetrics {
    let pose: Vec<f64> = trace.iter().map(|s| s.pose_error).filter(|e| e.is_finite()).collect();
    let ball: Vec<f64> = trace.iter().filter(|s| s.ball_known).map(|s| s.ball_error).collect();
    // A switch is between a gaze that includes the ball and one that does not.
    let with_ball = |s: &Sample| s.observe_ball || s.joint_gaze;
    let switches = trace.windows(2).filter(|w| with_ball(&w[0]) != with_ball(&w[1])).count();
    let recovered = recover_times(trace, recover);
    let times: Vec<f64> = recovered.iter().flatten().copied().collect();
    let minutes = match (trace.first(), trace.last()) {
        (Some(a), Some(b)) if b.t > a.t => (b.t - a.t) / 60.0,
        _ => f64::NAN,
    };
    RunMetrics {
        samples: trace.len(),
        observe_ball: fraction_true(trace.iter().map(|s| s.observe_ball)),
        joint_gaze: fraction_true(trace.iter().map(|s| s.joint_gaze)),
        ball_unknown: fraction_true(trace.iter().map(|s| !s.ball_known)),
        pose_error_mean: mean(&pose),
        pose_error_p95: percentile(&pose, 0.95),
        ball_error_mean: mean(&ball),
        coverage: mean(&trace.iter().map(|s| s.coverage).collect::<Vec<_>>()),
        ideal_coverage: mean(&trace.iter().map(|s| s.ideal_coverage).collect::<Vec<_>>()),
        gaze_switches_per_min: switches as f64 / minutes,
        covering_behavior: fraction_true(trace.iter().map(|s| s.covering)),
        direction_changes: recovered.len(),
        recover_time_mean: mean(&times),
        not_recovered: fraction_true(recovered.iter().map(Option::is_none)),
    }
}

// ---------------------------------------------------------------------------------------------
// Watching the keeper.

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

#[derive(Clone, Debug)]
struct RunResult {
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
    let mut scene = Scene::new(
        &scenario.field,
        scenario.noise_level.unwrap_or_default(),
        job.seed,
        &[SceneRobot { player: 1, team: team.clone(), start: Pose::new(x, y, theta) }],
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
    });
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

// ---------------------------------------------------------------------------------------------
// The experiment.

/// Aggregated metrics of one (method, rate).
#[derive(Clone, Debug, Serialize)]
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
    let results = parallel(&jobs, ctx.options.threads, |i, job| {
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
            targets.push(Target {
                what: format!(
                    "ball unknown at {hz} Hz: {} vs {}",
                    scenario.reference, baseline.name
                ),
                required: "at least as low".into(),
                measured: format!(
                    "{} vs {} %",
                    reference.ball_unknown.show(100.0, 1),
                    b.ball_unknown.show(100.0, 1)
                ),
                met: reference.ball_unknown.mean <= b.ball_unknown.mean,
            });
            targets.push(Target {
                what: format!("pose error at {hz} Hz: {} vs {}", scenario.reference, baseline.name),
                required: "at least as low".into(),
                measured: format!(
                    "{} vs {} cm",
                    reference.pose_error_mean.show(100.0, 1),
                    b.pose_error_mean.show(100.0, 1)
                ),
                met: reference.pose_error_mean.mean <= b.pose_error_mean.mean,
            });
            let dominated = b.ball_unknown.mean < reference.ball_unknown.mean
                && b.pose_error_mean.mean < reference.pose_error_mean.mean;
            targets.push(Target {
                what: format!(
                    "{} better on both ball unknown and pose error than {} at {hz} Hz",
                    baseline.name, scenario.reference
                ),
                required: "no".into(),
                measured: if dominated { "yes".into() } else { "no".into() },
                met: !dominated,
            });
            targets.push(Target {
                what: format!(
                    "goal coverage at {hz} Hz: {} vs {}",
                    scenario.reference, baseline.name
                ),
                required: "at least as high (the baseline's mean within the reference's CI or \
                           below)"
                    .into(),
                measured: format!(
                    "{} vs {} %",
                    reference.coverage.show(100.0, 1),
                    b.coverage.show(100.0, 1)
                ),
                met: reference.coverage.high() >= b.coverage.mean,
            });
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

/// Writes every output file: the raw data, the figures and the report.
#[allow(clippy::too_many_arguments)]
fn write_outputs(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    jobs: &[Job],
    results: &[RunResult],
    conditions: &[Condition],
    bands: &[BandCondition],
    targets: &[Target],
    runs: usize,
) -> Result<()> {
    write_runs_csv(scenario, ctx, jobs, results)?;
    write_timeseries_csv(scenario, ctx, jobs, results)?;
    let (unknown_png, observe_png, pose_png, coverage_png) =
        plot_per_rate(scenario, ctx, conditions)?;
    let fig5 = plot_fig5(scenario, ctx, jobs, results)?;
    let confidence_plots = plot_confidence(scenario, ctx, jobs, results)?;
    let fig4 = plot_fig4(scenario, ctx, jobs, results)?;
    let pareto = plot_pareto(scenario, ctx, conditions)?;
    let figures = Figures {
        unknown_png,
        observe_png,
        pose_png,
        coverage_png,
        pareto,
        fig5,
        confidence_plots,
        fig4,
    };
    write_report(scenario, ctx, conditions, bands, targets, runs, figures)
}

/// The figures the report shows, as [`Ctx::plot`] names them.
struct Figures {
    unknown_png: String,
    observe_png: String,
    pose_png: String,
    coverage_png: String,
    pareto: Vec<(f64, String)>,
    fig5: Vec<(f64, String)>,
    confidence_plots: Vec<String>,
    fig4: String,
}

/// The index of the reference method (the first when it is not among the methods).
fn reference_index(scenario: &Scenario) -> usize {
    scenario.methods.iter().position(|m| m.name == scenario.reference).unwrap_or(0)
}

/// `runs.csv`: one row per run with every metric.
fn write_runs_csv(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    jobs: &[Job],
    results: &[RunResult],
) -> Result<()> {
    let rows: Vec<Vec<String>> = jobs
        .iter()
        .zip(results)
        .map(|(j, r)| {
            let m = &r.metrics;
            vec![
                scenario.methods[j.method].name.clone(),
                num(scenario.deliberative_hz[j.rate]),
                scenario.paths[j.trajectory].trajectory.name.clone(),
                num(scenario.paths[j.trajectory].speed),
                j.run.to_string(),
                j.seed.to_string(),
                m.samples.to_string(),
                num(m.observe_ball),
                num(m.joint_gaze),
                num(m.ball_unknown),
                num(m.pose_error_mean),
                num(m.pose_error_p95),
                num(m.ball_error_mean),
                num(m.coverage),
                num(m.ideal_coverage),
                num(m.gaze_switches_per_min),
                num(m.covering_behavior),
                m.direction_changes.to_string(),
                num(m.recover_time_mean),
                num(m.not_recovered),
                num(r.reactive_hz),
                num(r.deliberative_hz),
            ]
        })
        .collect();
    let runs_csv = ctx.path("runs.csv");
    write_csv(
        &runs_csv,
        &[
            "method",
            "deliberative_hz",
            "trajectory",
            "ball_speed",
            "run",
            "seed",
            "samples",
            "observe_ball",
            "joint_gaze",
            "ball_unknown",
            "pose_error_mean_m",
            "pose_error_p95_m",
            "ball_error_mean_m",
            "coverage",
            "ideal_coverage",
            "gaze_switches_per_min",
            "covering_behavior",
            "direction_changes",
            "recover_time_mean_s",
            "not_recovered",
            "reactive_hz",
            "deliberative_hz_measured",
        ],
        &rows,
    )
}

/// `timeseries.csv`: every traced sample, with the head multiplexer's scores per object.
fn write_timeseries_csv(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    jobs: &[Job],
    results: &[RunResult],
) -> Result<()> {
    let mut ts_rows = Vec::new();
    for (j, r) in jobs.iter().zip(results) {
        let Some(trace) = &r.trace else { continue };
        for s in trace {
            let mut row = vec![
                scenario.methods[j.method].name.clone(),
                num(scenario.deliberative_hz[j.rate]),
                scenario.paths[j.trajectory].trajectory.name.clone(),
                format!("{:.3}", s.t),
                u8::from(s.observe_ball).to_string(),
                u8::from(s.joint_gaze).to_string(),
                u8::from(s.ball_known).to_string(),
                num(s.ball_confidence),
                num(s.pose_error),
                num(s.coverage),
                num(s.keeper.0),
                num(s.keeper.1),
                num(s.keeper_heading),
                num(s.ball.0),
                num(s.ball.1),
                num(s.head.0),
                num(s.head.1),
            ];
            row.push(s.behavior.clone());
            row.push(s.reactive_path.clone());
            row.push(
                s.scores
                    .iter()
                    .map(|(o, d, r, f)| format!("{o}:{d:.3}/{r:.3}/{f:.3}"))
                    .collect::<Vec<_>>()
                    .join(" "),
            );
            ts_rows.push(row);
        }
    }
    let ts_csv = ctx.path("timeseries.csv");
    write_csv(
        &ts_csv,
        &[
            "method",
            "deliberative_hz",
            "trajectory",
            "t",
            "observe_ball",
            "joint_gaze",
            "ball_known",
            "ball_confidence",
            "pose_error_m",
            "coverage",
            "keeper_x",
            "keeper_y",
            "keeper_theta",
            "ball_x",
            "ball_y",
            "head_yaw",
            "head_pitch",
            "behavior_path",
            "reactive_path",
            "head_scores (object:S_d/S_r/final)",
        ],
        &ts_rows,
    )
}

/// The bar charts per rate and method: ball unknown, observe ball, pose error, coverage.
fn plot_per_rate(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    conditions: &[Condition],
) -> Result<(String, String, String, String)> {
    let groups: Vec<String> = scenario.deliberative_hz.iter().map(|h| hz_label(*h)).collect();
    let series = |f: &dyn Fn(&Condition) -> Estimate, scale: f64| -> Vec<(String, Vec<Estimate>)> {
        scenario
            .methods
            .iter()
            .map(|m| {
                let values = scenario
                    .deliberative_hz
                    .iter()
                    .map(|hz| {
                        conditions
                            .iter()
                            .find(|c| c.method == m.name && (c.deliberative_hz - hz).abs() < 1e-9)
                            .map(|c| {
                                let e = f(c);
                                Estimate { mean: e.mean * scale, ci95: e.ci95 * scale, n: e.n }
                            })
                            .unwrap_or_default()
                    })
                    .collect();
                (m.name.clone(), values)
            })
            .collect()
    };
    let paper = |f: &dyn Fn(&PaperRow) -> f64| -> Vec<Option<f64>> {
        scenario
            .deliberative_hz
            .iter()
            .map(|hz| scenario.paper_row(*hz).map(|r| 100.0 * f(r)))
            .collect()
    };
    let unknown_png = ctx.plot(
        &Bars {
            title: "Ball position unknown (Table 5, column 3)".into(),
            y_label: "% of time".into(),
            groups: groups.clone(),
            series: series(&|c| c.ball_unknown, 100.0),
            reference: Some(("paper (Table 5)".into(), paper(&|r| r.ball_unknown))),
            targets: Some(("target".into(), paper(&|r| r.target_ball_unknown))),
        },
        "ball_unknown",
    )?;
    let observe_png = ctx.plot(
        &Bars {
            title: "Robot decides to observe the ball (Table 5, column 2)".into(),
            y_label: "% of time".into(),
            groups: groups.clone(),
            series: series(&|c| c.observe_ball, 100.0),
            reference: Some(("paper (Table 5)".into(), paper(&|r| r.observe_ball))),
            targets: None,
        },
        "observe_ball",
    )?;
    let pose_png = ctx.plot(
        &Bars {
            title: "Self-localization error (mean)".into(),
            y_label: "cm".into(),
            groups: groups.clone(),
            series: series(&|c| c.pose_error_mean, 100.0),
            reference: None,
            targets: Some((
                "target".into(),
                scenario
                    .deliberative_hz
                    .iter()
                    .map(|_| Some(100.0 * scenario.target_pose_error))
                    .collect(),
            )),
        },
        "pose_error",
    )?;
    let coverage_png = ctx.plot(
        &Bars {
            title: "Goal covered by the keeper (fraction of the goal's angle seen from the ball)"
                .into(),
            y_label: "%".into(),
            groups: groups.clone(),
            series: series(&|c| c.coverage, 100.0),
            reference: None,
            targets: None,
        },
        "coverage",
    )?;
    Ok((unknown_png, observe_png, pose_png, coverage_png))
}

/// Fig. 5: the reference method's scores and ball confidence over time, per rate.
fn plot_fig5(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    jobs: &[Job],
    results: &[RunResult],
) -> Result<Vec<(f64, String)>> {
    let reference_index = reference_index(scenario);
    let mut fig5 = Vec::new();
    for (r, hz) in scenario.deliberative_hz.iter().enumerate() {
        let Some(trace) = jobs
            .iter()
            .zip(results)
            .find(|(j, _)| {
                j.method == reference_index && j.rate == r && j.trajectory == 0 && j.run == 0
            })
            .and_then(|(_, res)| res.trace.as_ref())
        else {
            continue;
        };
        let objects = plotted_objects(trace);
        let score_series = |pick: &dyn Fn(&ObjectScores) -> f64| -> Vec<Series> {
            objects
                .iter()
                .enumerate()
                .map(|(i, object)| Series {
                    name: object.clone(),
                    points: trace
                        .iter()
                        .filter_map(|s| {
                            s.scores.iter().find(|x| &x.0 == object).map(|x| (s.t, pick(x)))
                        })
                        .collect(),
                    colour: i,
                })
                .collect()
        };
        let stack = Stack {
            title: format!(
                "Goal covering, deliberative layer at {hz} Hz, reactive at {} Hz ({}, trajectory `{}`)",
                scenario.reactive_hz, scenario.reference, scenario.paths[0].trajectory.name
            ),
            x_label: "t (s)".into(),
            panels: vec![
                Panel {
                    title: "Final score for gaze direction selection".into(),
                    y_label: "score".into(),
                    y_range: Some((0.0, 1.05)),
                    series: score_series(&|x| x.3),
                },
                Panel {
                    title: "Evolution of the ball confidence".into(),
                    y_label: "confidence".into(),
                    y_range: Some((0.0, 1.05)),
                    series: vec![Series {
                        name: "ball".into(),
                        points: trace.iter().map(|s| (s.t, s.ball_confidence)).collect(),
                        colour: 0,
                    }],
                },
                Panel {
                    title: "Score calculated by the deliberative layer".into(),
                    y_label: "S_d".into(),
                    y_range: Some((0.0, 1.05)),
                    series: score_series(&|x| x.1),
                },
                Panel {
                    title: "Score calculated by the reactive layer".into(),
                    y_label: "S_r".into(),
                    y_range: Some((0.0, 1.05)),
                    series: score_series(&|x| x.2),
                },
            ],
        };
        let stem = format!("fig5_{}hz", hz).replace('.', "_");
        fig5.push((*hz, ctx.plot(&stack, &stem)?));
    }
    Ok(fig5)
}

/// Ball confidence of every method at each rate (same seed, first trajectory).
fn plot_confidence(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    jobs: &[Job],
    results: &[RunResult],
) -> Result<Vec<String>> {
    let mut confidence_plots = Vec::new();
    for (r, hz) in scenario.deliberative_hz.iter().enumerate() {
        let series: Vec<Series> = scenario
            .methods
            .iter()
            .enumerate()
            .filter_map(|(m, method)| {
                let trace = jobs
                    .iter()
                    .zip(results)
                    .find(|(j, _)| j.method == m && j.rate == r && j.trajectory == 0 && j.run == 0)
                    .and_then(|(_, res)| res.trace.as_ref())?;
                Some(Series {
                    name: method.name.clone(),
                    points: trace.iter().map(|s| (s.t, s.ball_confidence)).collect(),
                    colour: m,
                })
            })
            .collect();
        let stack = Stack {
            title: format!("Ball confidence, every method, deliberative layer at {hz} Hz"),
            x_label: "t (s)".into(),
            panels: vec![Panel {
                title: format!("trajectory `{}`, run 0", scenario.paths[0].trajectory.name),
                y_label: "confidence".into(),
                y_range: Some((0.0, 1.05)),
                series,
            }],
        };
        let stem = format!("confidence_{}hz", hz).replace('.', "_");
        confidence_plots.push(ctx.plot(&stack, &stem)?);
    }
    Ok(confidence_plots)
}

/// The trade-off per rate: ball unknown against mean pose error, one point per method with
/// its confidence intervals, goal coverage as the point's size.
fn plot_pareto(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    conditions: &[Condition],
) -> Result<Vec<(f64, String)>> {
    let mut figures = Vec::new();
    for hz in &scenario.deliberative_hz {
        let scaled = |e: Estimate| Estimate { mean: e.mean * 100.0, ci95: e.ci95 * 100.0, n: e.n };
        let points = scenario
            .methods
            .iter()
            .enumerate()
            .filter_map(|(m, method)| {
                let c = conditions
                    .iter()
                    .find(|c| c.method == method.name && (c.deliberative_hz - hz).abs() < 1e-9)?;
                Some(TradeoffPoint {
                    name: method.name.clone(),
                    x: scaled(c.ball_unknown),
                    y: scaled(c.pose_error_mean),
                    size: c.coverage.mean,
                    colour: m,
                })
            })
            .collect();
        let figure = Tradeoff {
            title: format!(
                "Ball unknown against pose error at {hz} Hz (size: goal coverage; lower left is better)"
            ),
            x_label: "ball unknown (% of time)".into(),
            y_label: "mean pose error (cm)".into(),
            size_label: "coverage".into(),
            size_unit: (100.0, " %".into()),
            points,
        };
        let stem = format!("pareto_{hz}hz").replace('.', "_");
        figures.push((*hz, ctx.plot(&figure, &stem)?));
    }
    Ok(figures)
}

/// Paths drawn in Fig. 4: more make its legend longer than the field.
const FIG4_PATHS: usize = 6;

/// Fig. 4: the trajectories (the first [`FIG4_PATHS`]), and where the keeper went.
fn plot_fig4(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    jobs: &[Job],
    results: &[RunResult],
) -> Result<String> {
    let reference_index = reference_index(scenario);
    let field = TeamField::new(
        strata_spl::Field::preset(&scenario.field)
            .or_else(|_| strata_spl::Field::load(&scenario.field))
            .map_err(|e| anyhow!("field {}: {e}", scenario.field))?,
        1.0,
    );
    let mid_rate = scenario.deliberative_hz.len() / 2;
    let mut paths = Vec::new();
    for (t, trajectory) in scenario.paths.iter().map(|p| &p.trajectory).enumerate().take(FIG4_PATHS)
    {
        paths.push(Series {
            name: format!("ball: {}", trajectory.name),
            points: trajectory.waypoints.iter().map(|[x, y]| (*x, *y)).collect(),
            colour: t,
        });
        if let Some(trace) = jobs
            .iter()
            .zip(results)
            .find(|(j, _)| {
                j.method == reference_index && j.rate == mid_rate && j.trajectory == t && j.run == 0
            })
            .and_then(|(_, res)| res.trace.as_ref())
        {
            paths.push(Series {
                name: format!(
                    "keeper ({}, {} Hz)",
                    trajectory.name, scenario.deliberative_hz[mid_rate]
                ),
                points: trace.iter().map(|s| s.keeper).collect(),
                colour: t + 4,
            });
        }
    }
    ctx.plot(
        &FieldPaths {
            title: if scenario.paths.len() > FIG4_PATHS {
                format!(
                    "Ball trajectories (Fig. 4; the first {FIG4_PATHS} of {}) and the keeper's true path",
                    scenario.paths.len()
                )
            } else {
                "Ball trajectories (Fig. 4) and the keeper's true path".into()
            },
            outline: field_outline(&field),
            paths,
            half_extent: (field.half_length + 0.8, field.half_width + 0.8),
        },
        "fig4_trajectories",
    )
}

/// `report.md`: what was run, Table 5 beside the paper's, every method, the targets and the
/// figures.
fn write_report(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    conditions: &[Condition],
    bands: &[BandCondition],
    targets: &[Target],
    runs: usize,
    figures: Figures,
) -> Result<()> {
    let mut md =
        Markdown::new("Goal covering with active vision (paper 4.2, Table 5, Fig. 4, Fig. 5)");
    ctx.report_head(
        NAME,
        "The goalkeeper covers its goal while the ball moves along trajectories at constant \
         speed; the deliberative layer runs at several rates and the reactive layer at the sensor \
         rate. The paper's method (value functions with active vision, the head multiplexer \
         averaging S_d and S_r) is compared with gaze baselines on the same seeds.",
        &mut md,
        runs,
    );
    report_setup(scenario, runs, &mut md);
    report_table5(scenario, conditions, &mut md);
    report_methods(conditions, &mut md);
    report_bands(bands, &mut md);
    report_targets(targets, &mut md);
    report_figures(figures, &mut md);
    ctx.finish_report(
        md,
        &[
            "`runs.csv`: one row per run (method, rate, trajectory, ball speed, seed) with every metric",
            "`timeseries.csv`: every sample of run 0 of each (method, rate) on the first three trajectories, with the head multiplexer's S_d / S_r / final score per object",
        ],
    )
}

/// The report's setup and definitions.
fn report_setup(scenario: &Scenario, runs: usize, md: &mut Markdown) {
    let mut paths = Vec::new();
    if let (false, Some(speed)) = (scenario.trajectories.is_empty(), scenario.ball_speed) {
        paths.push(format!(
            "Ball at {speed} m/s along {} fixed trajectories: {}",
            scenario.trajectories.len(),
            scenario
                .trajectories
                .iter()
                .map(|t| format!("`{}` ({:.1} m)", t.name, t.length()))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    if let Some(random) = &scenario.random {
        let [[x0, y0], [x1, y1]] = random.region;
        paths.push(format!(
            "{} random paths drawn from seed {} (the same for every `--seed`): {} to {} straight \
             segments of at least {} m between waypoints in x {x0}..{x1}, y {y0}..{y1} (team \
             frame), outside the own penalty area; each path at a constant speed drawn from \
             {}-{} m/s",
            random.paths,
            random.seed,
            random.segments[0],
            random.segments[1],
            random.min_segment,
            random.speed[0],
            random.speed[1]
        ));
    }
    let mut setup = vec![format!(
        "Field `{}`, noise `{}`, lockstep host (deterministic)",
        scenario.field, scenario.noise
    )];
    setup.extend(paths);
    setup.extend([
        format!(
            "Speed bands of the breakdown: {}",
            scenario.speed_bands.iter().map(|b| band_label(*b)).collect::<Vec<_>>().join(", ")
        ),
        format!(
            "Deliberative layer at {} Hz; reactive layer on every percept at {} Hz (the paper's mean: 57 Hz)",
            scenario.deliberative_hz.iter().map(|h| h.to_string()).collect::<Vec<_>>().join(", "),
            scenario.reactive_hz
        ),
        format!(
            "Methods: {}; reference: `{}`",
            scenario.methods.iter().map(|m| format!("`{}` (team `{}`)", m.name, m.team)).collect::<Vec<_>>().join(", "),
            scenario.reference
        ),
        format!(
            "Metrics sampled every {} s of simulated time after a {} s warm-up, until {} s after the ball stops; \
             each condition averages {} runs x {} trajectories; ± is the 95% confidence interval (Student t)",
            scenario.sample_period,
            scenario.warmup,
            scenario.settle,
            runs,
            scenario.paths.len()
        ),
    ]);
    md.bullets(&setup);
    md.heading("Definitions");
    md.bullets(&[
        "observe ball: the head multiplexer's selected goal is the ball alone (the paper's Table 5: its head looks at one object at a time)".to_owned(),
        "joint gaze: the selected goal is the ball together with other objects (a landmark) in one gaze; not counted as observe ball".to_owned(),
        "ball unknown: the world model's ball estimate is not `known` (confidence under the unknown threshold, or never seen)".to_owned(),
        "pose error: distance between the self-localization estimate and the simulator's true pose; p95 is the 95th percentile within a run".to_owned(),
        "goal coverage: the fraction of the goal's angle, seen from the true ball, that the keeper (true position, half-width `keeper_reach`) covers; ideal: the same for the covering pose the behavior aims at".to_owned(),
        format!(
            "time to re-cover: a change of the ball's direction is a turn of its true velocity by more than {} degrees since the previous change (or since it started moving); the time runs from that sample until the first sample from which the keeper's coverage stays within {} points of the ideal coverage for {} s. Per run the mean over the changes re-covered from; changes not re-covered from before the next change or the end are counted apart (not re-covered)",
            scenario.recover.turn,
            100.0 * scenario.recover.tolerance,
            scenario.recover.hold
        ),
        "time in cover behavior: the deliberative layer's behavior path ends in `cover` (the goal-covering tree's branch with the value function), not `searching for object` or `localizing`".to_owned(),
    ]);
}

/// Table 5: the reference method per rate, beside the paper's.
fn report_table5(scenario: &Scenario, conditions: &[Condition], md: &mut Markdown) {
    md.heading("Table 5, beside the paper's");
    let mut rows = Vec::new();
    for hz in &scenario.deliberative_hz {
        let Some(c) = conditions
            .iter()
            .find(|c| c.method == scenario.reference && (c.deliberative_hz - hz).abs() < 1e-9)
        else {
            continue;
        };
        let row = scenario.paper_row(*hz);
        rows.push(vec![
            hz.to_string(),
            row.map_or("n/a".into(), |r| pct(r.observe_ball)),
            c.observe_ball.show(100.0, 1) + " %",
            c.joint_gaze.show(100.0, 1) + " %",
            row.map_or("n/a".into(), |r| pct(r.ball_unknown)),
            c.ball_unknown.show(100.0, 1) + " %",
            row.map_or("n/a".into(), |r| format!("<= {}", pct(r.target_ball_unknown))),
        ]);
    }
    md.table(
        &[
            "deliberative Hz",
            "observe ball, paper",
            "observe ball, ours",
            "joint ball+landmark gaze, ours",
            "ball unknown, paper",
            "ball unknown, ours",
            "target",
        ],
        &rows,
    );
}

/// Every method at every rate.
fn report_methods(conditions: &[Condition], md: &mut Markdown) {
    md.heading("Every method");
    let rows: Vec<Vec<String>> = conditions
        .iter()
        .map(|c| {
            vec![
                c.method.clone(),
                c.deliberative_hz.to_string(),
                c.observe_ball.show(100.0, 1),
                c.joint_gaze.show(100.0, 1),
                c.ball_unknown.show(100.0, 1),
                c.pose_error_mean.show(100.0, 1),
                c.pose_error_p95.show(100.0, 1),
                c.ball_error_mean.show(100.0, 1),
                c.coverage.show(100.0, 1),
                c.ideal_coverage.show(100.0, 1),
                c.recover_time.show(1.0, 2),
                c.not_recovered.show(100.0, 1),
                c.gaze_switches_per_min.show(1.0, 1),
                c.covering_behavior.show(100.0, 1),
                c.reactive_hz.show(1.0, 1),
                c.deliberative_hz_measured.show(1.0, 2),
            ]
        })
        .collect();
    md.table(
        &[
            "method",
            "deliberative Hz",
            "observe ball %",
            "joint gaze %",
            "ball unknown %",
            "pose error mean (cm)",
            "pose error p95 (cm)",
            "ball error (cm)",
            "goal coverage %",
            "ideal coverage %",
            "time to re-cover (s)",
            "not re-covered %",
            "ball/other gaze switches per min",
            "time in cover behavior %",
            "reactive Hz (measured)",
            "deliberative Hz (measured)",
        ],
        &rows,
    );
}

/// Every method at every rate, per speed band.
fn report_bands(bands: &[BandCondition], md: &mut Markdown) {
    md.heading("By ball speed");
    let rows: Vec<Vec<String>> = bands
        .iter()
        .map(|c| {
            vec![
                band_label(c.speed_band),
                c.method.clone(),
                c.deliberative_hz.to_string(),
                c.runs.to_string(),
                c.observe_ball.show(100.0, 1),
                c.joint_gaze.show(100.0, 1),
                c.ball_unknown.show(100.0, 1),
                c.pose_error_mean.show(100.0, 1),
                c.coverage.show(100.0, 1),
                c.recover_time.show(1.0, 2),
            ]
        })
        .collect();
    md.table(
        &[
            "ball speed",
            "method",
            "deliberative Hz",
            "runs",
            "observe ball %",
            "joint gaze %",
            "ball unknown %",
            "pose error mean (cm)",
            "goal coverage %",
            "time to re-cover (s)",
        ],
        &rows,
    );
}

/// The targets, and which are missed.
fn report_targets(targets: &[Target], md: &mut Markdown) {
    md.heading("Targets");
    let rows: Vec<Vec<String>> = targets
        .iter()
        .map(|t| vec![t.what.clone(), t.required.clone(), t.measured.clone(), verdict(t.met)])
        .collect();
    md.table(&["target", "required", "measured", "met"], &rows);
    let missed: Vec<&Target> = targets.iter().filter(|t| !t.met).collect();
    if missed.is_empty() {
        md.paragraph("Every target is met.");
    } else {
        md.paragraph(&format!(
            "**{} of {} targets are not met.** This is reported as measured: a negative result is \
             kept, not tuned away. Where the value-function method loses to a baseline, the \
             confidence intervals in the table above show whether the difference is larger than \
             the run-to-run spread.",
            missed.len(),
            targets.len()
        ));
    }
}

/// The figures.
fn report_figures(figures: Figures, md: &mut Markdown) {
    let Figures {
        unknown_png,
        observe_png,
        pose_png,
        coverage_png,
        pareto,
        fig5,
        confidence_plots,
        fig4,
    } = figures;
    md.heading("Figures");
    md.subheading(
        "Ball unknown against pose error per rate (lower left is better; point size: goal coverage)",
    );
    for (hz, png) in &pareto {
        md.image(&format!("Ball unknown against pose error at {hz} Hz"), png);
    }
    md.image("Ball unknown per rate and method, with the paper's Table 5", &unknown_png);
    md.image("Observe ball per rate and method, with the paper's Table 5", &observe_png);
    md.image("Mean pose error per rate and method", &pose_png);
    md.image("Goal coverage per rate and method", &coverage_png);
    md.subheading(
        "Fig. 5, ours (the paper's Fig. 5 shows the same four panels for 0.5, 1 and 2 Hz)",
    );
    for (hz, png) in &fig5 {
        md.image(&format!("Scores and ball confidence at {hz} Hz"), png);
    }
    md.subheading("Ball confidence of every method");
    for png in &confidence_plots {
        md.image("Ball confidence of every method", png);
    }
    md.subheading("Fig. 4, ours");
    md.image("Ball trajectories and the keeper's path", &fig4);
}

/// The objects of Fig. 5: the ball and the two landmarks the head multiplexer ranked highest
/// on average (the paper shows the ball and two beacons).
fn plotted_objects(trace: &[Sample]) -> Vec<String> {
    let mut totals: BTreeMap<String, (f64, usize)> = BTreeMap::new();
    for s in trace {
        for (object, _, _, final_score) in &s.scores {
            let e = totals.entry(object.clone()).or_default();
            e.0 += final_score;
            e.1 += 1;
        }
    }
    let mut landmarks: Vec<(String, f64)> = totals
        .into_iter()
        .filter(|(o, _)| o != BALL)
        .map(|(o, (sum, n))| (o, sum / trace.len().max(n).max(1) as f64))
        .collect();
    landmarks.sort_by(|a, b| b.1.total_cmp(&a.1));
    std::iter::once(BALL.to_owned()).chain(landmarks.into_iter().take(2).map(|(o, _)| o)).collect()
}

/// The field's lines and goals as polylines (team frame).
fn field_outline(field: &TeamField) -> Vec<Vec<(f64, f64)>> {
    let (hl, hw) = (field.half_length, field.half_width);
    let (pl, pw) = (field.penalty_area_length, field.penalty_area_half_width);
    let gw = field.goal_half_width;
    let depth = field.field.dimensions().goal_depth;
    let r = field.center_circle_radius;
    let mut lines = vec![
        vec![(-hl, -hw), (hl, -hw), (hl, hw), (-hl, hw), (-hl, -hw)],
        vec![(0.0, -hw), (0.0, hw)],
        vec![(-hl, -pw), (-hl + pl, -pw), (-hl + pl, pw), (-hl, pw)],
        vec![(hl, -pw), (hl - pl, -pw), (hl - pl, pw), (hl, pw)],
        vec![(-hl, -gw), (-hl - depth, -gw), (-hl - depth, gw), (-hl, gw)],
        vec![(hl, -gw), (hl + depth, -gw), (hl + depth, gw), (hl, gw)],
    ];
    lines.push(
        (0..=48)
            .map(|i| {
                let a = f64::from(i) / 48.0 * std::f64::consts::TAU;
                (r * a.cos(), r * a.sin())
            })
            .collect(),
    );
    lines
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t: f64, observe_ball: bool, ball_known: bool, pose_error: f64) -> Sample {
        Sample {
            t,
            observe_ball,
            ball_known,
            pose_error,
            coverage: 0.5,
            ideal_coverage: 0.6,
            covering: ball_known,
            ..Sample::default()
        }
    }

    #[test]
    fn a_ball_unknown_a_quarter_of_the_time_gives_25_percent() {
        let trace: Vec<Sample> =
            (0..100).map(|i| sample(f64::from(i) * 0.02, i % 2 == 0, i % 4 != 0, 0.1)).collect();
        let m = metrics(&trace, &Recover::default());
        assert_eq!(m.samples, 100);
        assert!((m.ball_unknown - 0.25).abs() < 1e-12, "{m:?}");
        assert!((m.observe_ball - 0.5).abs() < 1e-12);
        assert!((m.coverage - 0.5).abs() < 1e-12 && (m.ideal_coverage - 0.6).abs() < 1e-12);
        assert!((m.covering_behavior - 0.75).abs() < 1e-12);
        // Alternating every sample: 99 switches in 1.98 s.
        assert!((m.gaze_switches_per_min - 99.0 / (1.98 / 60.0)).abs() < 1e-6);
    }

    #[test]
    fn pose_error_statistics_skip_samples_without_an_estimate() {
        let mut trace: Vec<Sample> =
            (1..=20).map(|i| sample(f64::from(i), true, true, f64::from(i) / 100.0)).collect();
        trace.push(sample(21.0, true, true, f64::NAN));
        let m = metrics(&trace, &Recover::default());
        assert!((m.pose_error_mean - 0.105).abs() < 1e-12, "{m:?}");
        // 95th percentile of 0.01..0.20: position 18.05 -> 0.1905.
        assert!((m.pose_error_p95 - 0.1905).abs() < 1e-9, "{m:?}");
    }

    #[test]
    fn the_built_in_scenario_is_valid_and_its_trajectories_stay_out_of_the_penalty_area() {
        let mut scenario: Scenario =
            super::super::parse_scenario(DEFAULT_SCENARIO, "built-in").expect("parses");
        scenario.validate(&Check { source_name: "built-in" }, None).expect("valid");
        let field =
            TeamField::new(strata_spl::Field::preset(&scenario.field).expect("preset"), 1.0);
        assert_eq!(scenario.paths.len(), scenario.trajectories.len());
        assert_eq!(scenario.speed_bands, vec![[0.2, 0.2]]);
        for t in scenario.paths.iter().map(|p| &p.trajectory) {
            for [x, y] in &t.waypoints {
                let p = Point::new(*x, *y);
                assert!(field.is_inside(p, 0.0), "{}: {p:?}", t.name);
                assert!(!field.in_own_penalty_area(p, 0.1), "{}: {p:?}", t.name);
            }
        }
        assert_eq!(scenario.paper.len(), 3);
    }

    fn head(selected: &str, goals: &[(&str, &[&str])]) -> MuxReport {
        use strata_robot::control::reactive::GoalReport;
        let goals: Vec<GoalReport> = goals
            .iter()
            .map(|(goal, objects)| GoalReport {
                goal: (*goal).into(),
                objects: objects.iter().map(|o| (*o).to_owned()).collect(),
                deliberative: 0.5,
                reactive: 0.5,
                final_score: 0.5,
                applicable: true,
            })
            .collect();
        MuxReport {
            goals: goals.into(),
            selected_goal: Some(selected.into()),
            ..MuxReport::default()
        }
    }

    #[test]
    fn observe_ball_is_the_ball_alone_and_a_joint_gaze_is_counted_apart() {
        let goals: &[(&str, &[&str])] = &[
            ("observe ball", &[BALL]),
            ("observe ball+left", &[BALL, "left"]),
            ("observe left", &["left"]),
        ];
        assert_eq!(gaze(&head("observe ball", goals)), Gaze::Ball);
        assert_eq!(gaze(&head("observe ball+left", goals)), Gaze::BallWithOthers);
        assert_eq!(gaze(&head("observe left", goals)), Gaze::Other);
        // The baselines' plain goal names no object.
        assert_eq!(gaze(&head("observe ball", &[("observe ball", &[])])), Gaze::Ball);
        assert_eq!(gaze(&head("scan", &[("scan", &[])])), Gaze::Other);
        assert_eq!(gaze(&MuxReport::default()), Gaze::Other);

        // A quarter of the time the ball alone, a quarter jointly with a landmark.
        let trace: Vec<Sample> = (0..100)
            .map(|i| {
                let g = [Gaze::Ball, Gaze::BallWithOthers, Gaze::Other, Gaze::Other][i % 4];
                Sample {
                    t: i as f64 * 0.02,
                    observe_ball: g == Gaze::Ball,
                    joint_gaze: g == Gaze::BallWithOthers,
                    ..sample(i as f64 * 0.02, false, true, 0.1)
                }
            })
            .collect();
        let m = metrics(&trace, &Recover::default());
        assert!((m.observe_ball - 0.25).abs() < 1e-12, "{m:?}");
        assert!((m.joint_gaze - 0.25).abs() < 1e-12, "{m:?}");
        // Ball alone to joint is no switch away from the ball; joint to other and other to ball
        // are: 49 switches in 1.98 s.
        assert!((m.gaze_switches_per_min - 49.0 / (1.98 / 60.0)).abs() < 1e-6, "{m:?}");
    }

    /// The ball along +x until `turn_at`, then along +y, at 0.2 m/s, sampled every 0.02 s; the
    /// keeper covers as well as the ideal pose from `covered_from` on.
    fn turning_trace(turn_at: f64, covered_from: f64, end: f64) -> Vec<Sample> {
        (0..=(end / 0.02).round() as usize)
            .map(|i| {
                let t = i as f64 * 0.02;
                let ball = if t <= turn_at {
                    (0.2 * t, 0.0)
                } else {
                    (0.2 * turn_at, 0.2 * (t - turn_at))
                };
                Sample {
                    t,
                    ball,
                    coverage: if t >= covered_from - 1e-9 { 0.58 } else { 0.3 },
                    ideal_coverage: 0.6,
                    ..Sample::default()
                }
            })
            .collect()
    }

    #[test]
    fn the_time_to_re_cover_runs_from_the_turn_until_the_keeper_covers_for_the_hold_time() {
        let recover = Recover { turn: 40.0, tolerance: 0.05, hold: 0.5 };
        let times = recover_times(&turning_trace(1.0, 1.6, 4.0), &recover);
        assert_eq!(times.len(), 1, "{times:?}");
        let time = times[0].expect("re-covered");
        // The turn shows in the displacement ending at the first sample after t = 1.
        assert!((time - 0.58).abs() < 1e-9, "{time}");
        // Covered, but not for the hold time before the trace ends: not re-covered.
        assert_eq!(recover_times(&turning_trace(1.0, 3.8, 4.0), &recover), vec![None]);
        let m = metrics(&turning_trace(1.0, 3.8, 4.0), &recover);
        assert_eq!((m.direction_changes, m.not_recovered), (1, 1.0));
        assert!(m.recover_time_mean.is_nan());
        // A turn smaller than the threshold is no change of direction.
        let shallow = Recover { turn: 95.0, ..recover };
        assert!(recover_times(&turning_trace(1.0, 1.6, 4.0), &shallow).is_empty());
    }

    #[test]
    fn a_gradual_curve_changes_direction_once_per_turn_threshold() {
        // A quarter circle of radius 1 m at 0.2 m/s: 90 degrees of turning.
        let trace: Vec<Sample> = (0..=400)
            .map(|i| {
                let t = f64::from(i) * 0.02;
                let a = (0.2 * t).min(std::f64::consts::FRAC_PI_2);
                Sample {
                    t,
                    ball: (a.sin(), 1.0 - a.cos()),
                    coverage: 0.6,
                    ideal_coverage: 0.6,
                    ..Sample::default()
                }
            })
            .collect();
        let times = recover_times(&trace, &Recover { turn: 40.0, tolerance: 0.05, hold: 0.5 });
        // At 40 and 80 degrees; covered all along, so at once.
        assert_eq!(times, vec![Some(0.0), Some(0.0)]);
    }

    fn random_section() -> RandomPaths {
        RandomPaths {
            paths: 30,
            seed: 7,
            speed: [0.1, 0.5],
            segments: [2, 4],
            min_segment: 0.5,
            region: [[-2.2, -1.7], [0.0, 1.7]],
            speed_bands: 4,
        }
    }

    fn paper_field() -> TeamField {
        TeamField::new(strata_spl::Field::preset("paper2010").expect("preset"), 1.0)
    }

    #[test]
    fn random_paths_are_the_same_for_a_seed_and_respect_the_section() {
        let field = paper_field();
        let random = random_section();
        let a = random_paths(&random, &field).expect("drawn");
        let b = random_paths(&random, &field).expect("drawn");
        let as_data = |p: &[BallPath]| {
            p.iter().map(|p| (p.trajectory.waypoints.clone(), p.speed)).collect::<Vec<_>>()
        };
        assert_eq!(as_data(&a), as_data(&b));
        let other =
            random_paths(&RandomPaths { seed: 8, ..random_section() }, &field).expect("drawn");
        assert_ne!(as_data(&a), as_data(&other));
        assert_eq!(a.len(), 30);
        let [[x0, y0], [x1, y1]] = random.region;
        for path in &a {
            assert!(path.random);
            assert!((0.1..=0.5).contains(&path.speed), "{}: {}", path.trajectory.name, path.speed);
            let w = &path.trajectory.waypoints;
            assert!((3..=5).contains(&w.len()), "{}: {} waypoints", path.trajectory.name, w.len());
            for [x, y] in w {
                assert!((x0..=x1).contains(x) && (y0..=y1).contains(y), "{x}, {y}");
            }
            for s in w.windows(2) {
                let (a, b) = (Point::new(s[0][0], s[0][1]), Point::new(s[1][0], s[1][1]));
                assert!(a.distance(b) >= 0.5, "{}: {a:?} {b:?}", path.trajectory.name);
                for k in 0..=100 {
                    let p = a.lerp(b, f64::from(k) / 100.0);
                    assert!(!field.in_own_penalty_area(p, 0.05), "{}: {p:?}", path.trajectory.name);
                }
            }
        }
        // The speeds spread over the range.
        let slowest = a.iter().map(|p| p.speed).fold(f64::INFINITY, f64::min);
        let fastest = a.iter().map(|p| p.speed).fold(0.0, f64::max);
        assert!(slowest < 0.2 && fastest > 0.4, "{slowest}..{fastest}");
        // A region inside the penalty area has no segment to offer: refused, not looped on.
        let inside = RandomPaths { region: [[-3.0, -0.5], [-2.5, 0.5]], ..random_section() };
        assert!(random_paths(&inside, &field).is_err());
    }

    fn validated(text: &str) -> Result<Scenario, ScenarioError> {
        let mut scenario: Scenario = super::super::parse_scenario(text, "bad.toml")?;
        scenario.validate(&Check { source_name: "bad.toml" }, None)?;
        Ok(scenario)
    }

    const RANDOM_SCENARIO: &str = include_str!("../scenarios/goal-covering-random.toml");

    #[test]
    fn the_shipped_random_scenario_draws_its_paths_into_four_speed_bands() {
        let scenario = validated(RANDOM_SCENARIO).expect("valid");
        assert_eq!(scenario.paths.len(), 40);
        assert!(scenario.trajectories.is_empty() && scenario.ball_speed.is_none());
        assert_eq!(scenario.speed_bands.len(), 4);
        for path in &scenario.paths {
            assert!(scenario.speed_band(path.speed).is_some(), "{}", path.speed);
        }
        let again = validated(RANDOM_SCENARIO).expect("valid");
        assert_eq!(
            scenario.paths.iter().map(|p| p.speed).collect::<Vec<_>>(),
            again.paths.iter().map(|p| p.speed).collect::<Vec<_>>()
        );
    }

    #[test]
    fn a_bad_random_or_recover_value_names_the_file_and_the_field() {
        let bad = |from: &str, to: &str, field: &str| {
            assert!(RANDOM_SCENARIO.contains(from), "{from}");
            let error = validated(&RANDOM_SCENARIO.replace(from, to)).map(|_| ()).expect_err(to);
            let text = error.to_string();
            assert!(text.contains("bad.toml") && text.contains(&format!("`{field}`")), "{text}");
        };
        bad("speed = [0.1, 0.5]", "speed = [0.5, 0.1]", "random.speed");
        bad("speed = [0.1, 0.5]", "speed = [0.0, 0.5]", "random.speed[0]");
        bad("speed = [0.1, 0.5]", "speed = [0.1]", "random.speed");
        bad("paths = 40", "paths = 0", "random.paths");
        bad("segments = [2, 4]", "segments = [3, 2]", "random.segments");
        bad("min_segment = 0.5", "min_segment = -1.0", "random.min_segment");
        bad("[[-2.2, -1.7], [0.0, 1.7]]", "[[-2.2, -1.7], [0.0, 2.7]]", "random.region");
        bad("[[-2.2, -1.7], [0.0, 1.7]]", "[[-2.2, -1.7], [-2.2, 1.7]]", "random.region");
        bad("[[-2.2, -1.7], [0.0, 1.7]]", "[[-3.0, -0.5], [-2.5, 0.5]]", "random.region");
        bad("speed_bands = 4", "speed_bands = 0", "random.speed_bands");
        bad("turn = 40.0", "turn = 180.0", "recover.turn");
        bad("tolerance = 0.05", "tolerance = 1.5", "recover.tolerance");
        // Fixed trajectories need the speed they are run at.
        bad(
            "[random]",
            "[[trajectories]]\nname = \"t\"\nwaypoints = [[-1.8, 0.2], [-1.8, -0.2]]\n\n[random]",
            "ball_speed",
        );
        // Neither fixed trajectories nor random paths.
        let start = RANDOM_SCENARIO.find("[random]").expect("section");
        let end = RANDOM_SCENARIO.find("# How the time").expect("next section");
        let none = format!("{}{}", &RANDOM_SCENARIO[..start], &RANDOM_SCENARIO[end..]);
        let error = validated(&none).map(|_| ()).expect_err("no paths");
        assert!(error.to_string().contains("`trajectories`"), "{error}");
    }
}
