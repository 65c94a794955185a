//! The keeper's gaze as a reinforcement-learning environment (the Python package's
//! `strata.gym.GazeEnv` wraps it): one goal-covering run of [`super::run`] on the lockstep host,
//! with the head's goal chosen by an agent at every deliberative decision.
//!
//! - **step**: one deliberative period (`1 / deliberative_hz` of simulated time); the chosen
//!   gaze is what the next deliberative tick sends the head multiplexer, and holds until the
//!   agent chooses again.
//! - **action**: an index into [`GazeChoice`]: the ball, the k-th nearest landmark, or the ball
//!   together with it (the candidates the value-function gaze scores, so a learned gaze is
//!   compared with it on the same looks).
//! - **observation**: [`OBS_LEN`] numbers summarizing the world model the deliberative layer
//!   sees ([`observation`]).
//! - **reward**: the goal coverage of the step's samples, less `unknown_penalty` for each
//!   sample with the ball unknown and `pose_penalty` per metre of pose error beyond
//!   `pose_tolerance`, averaged over the step.
//! - **episode**: one ball path of the scenario, from the end of its warm-up (which the
//!   method's own gaze runs) until the ball has stopped for `settle` s. `reset(seed)` picks the
//!   path `seed % paths` and seeds the simulator with `seed`: the same seed gives the same
//!   episode.

use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use anyhow::{Context as _, Result, anyhow, bail};
use serde::{Deserialize, Serialize};
use strata_robot::world::{ObjectCategory, WorldState};
use strata_runtime::{Tap, TapRecord};
use strata_sim::{BallScript, RobotId};
use strata_soccer::behaviors::GazeStrategy;
use strata_soccer::gaze_override::{GazeChoice, GazeOverride, RANKED_LANDMARKS};
use strata_soccer::situation::best_instance;
use strata_soccer::world_config::landmark_groups;

use super::*;
use crate::{Check, Host, HostKind, Validate, parse_scenario};

/// Numbers per landmark: seen (0/1), position (robot frame, m), covariance (xx, xy, yy).
const PER_LANDMARK: usize = 6;
/// Ball (6), pose (10), head (2), then the ranked landmarks.
pub const OBS_LEN: usize = 6 + 10 + 2 + PER_LANDMARK * RANKED_LANDMARKS;
/// Every observation is clipped to this magnitude (an unknown object's covariance is huge).
pub const OBS_LIMIT: f32 = 100.0;
/// Covariance entries reported for an object the world model does not have, m².
const UNSEEN_VARIANCE: f64 = 25.0;

/// How the environment is set up; the defaults are the paper's method at 1 Hz.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct GazeEnvConfig {
    /// The scenario's TOML text; empty: the built-in goal-covering scenario.
    pub scenario: String,
    /// The method whose team plays the keeper (one with a value-function or entropy gaze,
    /// whose candidates the actions name); empty: the scenario's reference.
    pub method: String,
    /// Deliberative decisions per simulated second: one step each.
    pub deliberative_hz: f64,
    /// Always this path of the scenario (index) instead of `seed % paths`.
    pub path: Option<usize>,
    /// Subtracted per sample with the ball unknown.
    pub unknown_penalty: f64,
    /// Subtracted per sample and metre of pose error beyond `pose_tolerance`.
    pub pose_penalty: f64,
    /// m; `None`: the scenario's `target_pose_error`.
    pub pose_tolerance: Option<f64>,
}

impl Default for GazeEnvConfig {
    fn default() -> Self {
        GazeEnvConfig {
            scenario: String::new(),
            method: String::new(),
            deliberative_hz: 1.0,
            path: None,
            unknown_penalty: 0.5,
            pose_penalty: 1.0,
            pose_tolerance: None,
        }
    }
}

/// What a step measured, beside the reward.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct StepInfo {
    /// Simulated time at the end of the step, s.
    pub time: f64,
    pub path: usize,
    /// Means over the step's samples.
    pub coverage: f64,
    pub ball_unknown: f64,
    pub pose_error: f64,
}

/// One step's result, as Gymnasium's `step` returns it.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    pub observation: Vec<f32>,
    pub reward: f64,
    pub terminated: bool,
    pub truncated: bool,
    pub info: StepInfo,
}

/// The newest world state of the keeper.
struct WorldTap {
    world: String,
    latest: Mutex<Option<WorldState>>,
}

impl Tap for WorldTap {
    fn package(&self, record: &TapRecord<'_>) {
        if let Some(world) = record.value_from(&self.world, outputs::WORLD_STATE) {
            *self.latest.lock().unwrap_or_else(PoisonError::into_inner) = Some(world.clone());
        }
    }
}

/// A running episode.
struct Episode {
    scene: Scene,
    host: Host,
    tap: Arc<WorldTap>,
    keeper: RobotId,
    path: usize,
    end: f64,
}

/// The environment: [`GazeEnv::reset`], then [`GazeEnv::step`] until `terminated`.
pub struct GazeEnv {
    scenario: Scenario,
    team: TeamConfig,
    config: GazeEnvConfig,
    pose_tolerance: f64,
    choice: Arc<GazeOverride>,
    episode: Option<Episode>,
}

impl std::fmt::Debug for GazeEnv {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GazeEnv").field("config", &self.config).finish_non_exhaustive()
    }
}

impl GazeEnv {
    pub fn new(config: GazeEnvConfig) -> Result<GazeEnv> {
        let (text, source) = if config.scenario.trim().is_empty() {
            (DEFAULT_SCENARIO, "built-in scenario goal-covering")
        } else {
            (config.scenario.as_str(), "the environment's scenario")
        };
        let mut scenario: Scenario = parse_scenario(text, source)?;
        scenario.validate(&Check { source_name: source }, None)?;
        let check = Check { source_name: "the environment's configuration" };
        check.positive("deliberative_hz", config.deliberative_hz)?;
        check.non_negative("unknown_penalty", config.unknown_penalty)?;
        check.non_negative("pose_penalty", config.pose_penalty)?;
        if let Some(tolerance) = config.pose_tolerance {
            check.non_negative("pose_tolerance", tolerance)?;
        }
        if let Some(path) = config.path
            && path >= scenario.paths.len()
        {
            return Err(check
                .fail("path", format!("the scenario has {} paths", scenario.paths.len()))
                .into());
        }
        let method = if config.method.is_empty() { &scenario.reference } else { &config.method };
        let Some(index) = scenario.methods.iter().position(|m| &m.name == method) else {
            return Err(check
                .fail("method", format!("`{method}` is not a method of the scenario"))
                .into());
        };
        let mut team = scenario.resolved[index].clone();
        if matches!(team.behavior.gaze, GazeStrategy::AlwaysBall | GazeStrategy::FixedScan) {
            return Err(check
                .fail("method", format!("`{method}` makes no gaze candidates to choose from"))
                .into());
        }
        team.timing.deliberative.rate_hz = Some(config.deliberative_hz);
        team.timing.perception.rate_hz = Some(scenario.reactive_hz);
        let pose_tolerance = config.pose_tolerance.unwrap_or(scenario.target_pose_error);
        Ok(GazeEnv {
            scenario,
            team,
            config,
            pose_tolerance,
            choice: GazeOverride::new(),
            episode: None,
        })
    }

    /// Paths an episode can follow.
    pub fn paths(&self) -> usize {
        self.scenario.paths.len()
    }

    /// Simulated seconds one step covers.
    pub fn step_seconds(&self) -> f64 {
        1.0 / self.config.deliberative_hz
    }

    /// Starts the episode of `seed`: the keeper placed, the method's own gaze through the
    /// warm-up, the ball set moving; the first observation.
    pub fn reset(&mut self, seed: u64) -> Result<Vec<f32>> {
        self.episode = None;
        self.choice.set(None);
        let paths = self.scenario.paths.len() as u64;
        let path = self.config.path.unwrap_or((seed % paths.max(1)) as usize);
        let ball_path = self.scenario.paths.get(path).context("the scenario has no paths")?;
        let [x, y, theta] = self.scenario.keeper_start;
        let mut scene = Scene::new(
            &self.scenario.field,
            self.scenario.noise_level.unwrap_or_default(),
            seed,
            &[SceneRobot {
                player: 1,
                team: self.team.clone(),
                start: Pose::new(x, y, theta),
                gaze: Some(Arc::clone(&self.choice)),
            }],
        )?;
        let (keeper, modules) = scene.robots[0].clone();
        let waypoints: Vec<Point<FieldFrame>> = ball_path
            .trajectory
            .waypoints
            .iter()
            .map(|[x, y]| scene.field.to_team(*x, *y))
            .collect();
        let first = *waypoints.first().context("a ball path without waypoints")?;
        scene
            .sim
            .lock()
            .place_ball(first, strata_robot::geometry::Vector::new(0.0, 0.0))
            .map_err(|e| anyhow!("{e}"))?;
        let tap = Arc::new(WorldTap { world: modules.world.clone(), latest: Mutex::new(None) });
        let mut host = scene.host(HostKind::Lockstep, seed, tap.clone())?;
        host.advance(Duration::from_secs_f64(self.scenario.warmup))?;
        scene
            .sim
            .lock()
            .script_ball(BallScript::new(waypoints, ball_path.speed))
            .map_err(|e| anyhow!("{e}"))?;
        let end = self.scenario.warmup
            + ball_path.trajectory.length() / ball_path.speed
            + self.scenario.settle;
        let episode = Episode { scene, host, tap, keeper, path, end };
        let observation = observe(&episode)?;
        self.episode = Some(episode);
        Ok(observation)
    }

    /// Looks as `action` says ([`GazeChoice::from_index`]) for one deliberative period.
    pub fn step(&mut self, action: usize) -> Result<Step> {
        let Some(choice) = GazeChoice::from_index(action) else {
            bail!("action {action} is not one of the {} gazes", GazeChoice::COUNT);
        };
        let Some(episode) = self.episode.as_mut() else {
            bail!("step before reset (or after the episode ended)");
        };
        self.choice.set(Some(choice));
        let period = Duration::from_secs_f64(self.scenario.sample_period);
        let step = 1.0 / self.config.deliberative_hz;
        let samples = (step / self.scenario.sample_period).round().max(1.0) as usize;
        let reach = self.team.behavior.keeper_reach;
        let (mut coverage, mut unknown, mut pose_error, mut taken) = (0.0, 0.0, 0.0, 0usize);
        let mut now = 0.0;
        for _ in 0..samples {
            episode.host.advance(period)?;
            let (time, truth, ball) = {
                let sim = episode.scene.sim.lock();
                (
                    sim.time().as_secs_f64(),
                    sim.robot(episode.keeper).map_err(|e| anyhow!("{e}"))?,
                    sim.ball(),
                )
            };
            now = time;
            let field = &episode.scene.field;
            let ball = team_point(field, ball.position);
            let latest = episode.tap.latest.lock().unwrap_or_else(PoisonError::into_inner);
            let known = latest.as_ref().and_then(|w| w.object(BALL)).is_some_and(|b| b.known);
            // No estimate yet counts as a metre off: a keeper that does not know where it is.
            let error = latest
                .as_ref()
                .map_or(1.0, |w| w.pose.pose.position().distance(truth.team_pose.position()));
            drop(latest);
            coverage += goal_coverage(field, ball, truth.team_pose.position(), reach, 1e-3);
            unknown += f64::from(u8::from(!known));
            pose_error += error;
            taken += 1;
            if now > episode.end {
                break;
            }
        }
        let n = taken.max(1) as f64;
        let (coverage, unknown, pose_error) = (coverage / n, unknown / n, pose_error / n);
        let reward = coverage
            - self.config.unknown_penalty * unknown
            - self.config.pose_penalty * (pose_error - self.pose_tolerance).max(0.0);
        let observation = observe(episode)?;
        let terminated = now > episode.end;
        let info =
            StepInfo { time: now, path: episode.path, coverage, ball_unknown: unknown, pose_error };
        if terminated {
            if let Some(episode) = self.episode.take() {
                episode.host.finish()?;
            }
            self.choice.set(None);
        }
        Ok(Step { observation, reward, terminated, truncated: false, info })
    }
}

/// The observation of a running episode: the keeper's newest world state and its head.
fn observe(episode: &Episode) -> Result<Vec<f32>> {
    let head = episode.scene.sim.lock().robot(episode.keeper).map_err(|e| anyhow!("{e}"))?.head;
    let latest = episode.tap.latest.lock().unwrap_or_else(PoisonError::into_inner);
    Ok(observation(latest.as_ref(), &episode.scene.field, [head.yaw, head.pitch]))
}

/// The fixed-size summary of a world state ([`OBS_LEN`] numbers, clipped to [`OBS_LIMIT`]):
/// - ball: known (0/1), position (robot frame, m), covariance (xx, xy, yy);
/// - pose: x, y (team frame, m), cos and sin of the heading, covariance of (x, y, theta)
///   (upper triangle, row by row);
/// - head: yaw and pitch, rad;
/// - landmarks: the best instance of each landmark group, nearest first, as many as actions
///   name ([`RANKED_LANDMARKS`]): seen (0/1), position (robot frame), covariance; zeros and a
///   large variance for missing ones. Slot k is the landmark action k names.
pub fn observation(world: Option<&WorldState>, field: &TeamField, head: [f64; 2]) -> Vec<f32> {
    let mut out = Vec::with_capacity(OBS_LEN);
    let unseen = [0.0, 0.0, 0.0, UNSEEN_VARIANCE, 0.0, UNSEEN_VARIANCE];
    match world.and_then(|w| w.object(BALL)) {
        Some(b) => out.extend([
            f64::from(u8::from(b.known)),
            b.position.x,
            b.position.y,
            b.covariance[(0, 0)],
            b.covariance[(0, 1)],
            b.covariance[(1, 1)],
        ]),
        None => out.extend(unseen),
    }
    match world {
        Some(w) => {
            let (p, c) = (w.pose.pose, &w.pose.covariance);
            out.extend([p.x, p.y, p.theta.cos(), p.theta.sin()]);
            out.extend([c[(0, 0)], c[(0, 1)], c[(0, 2)], c[(1, 1)], c[(1, 2)], c[(2, 2)]]);
        }
        None => out.extend([0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 1.0]),
    }
    out.extend(head);
    let groups = landmark_groups(field);
    let mut landmarks: Vec<_> = match world {
        Some(w) => groups
            .iter()
            .filter_map(|g| best_instance(w, g))
            .filter(|o| o.category == ObjectCategory::Landmark)
            .collect(),
        None => Vec::new(),
    };
    landmarks.sort_by(|a, b| a.position.range().total_cmp(&b.position.range()));
    for k in 0..RANKED_LANDMARKS {
        match landmarks.get(k) {
            Some(o) => out.extend([
                1.0,
                o.position.x,
                o.position.y,
                o.covariance[(0, 0)],
                o.covariance[(0, 1)],
                o.covariance[(1, 1)],
            ]),
            None => out.extend(unseen),
        }
    }
    debug_assert_eq!(out.len(), OBS_LEN);
    out.iter().map(|v| (*v as f32).clamp(-OBS_LIMIT, OBS_LIMIT)).collect()
}

#[cfg(test)]
mod tests;
