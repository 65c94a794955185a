//! What a robot's run tells its output: the start, game events, status lines and the final
//! report (serialized as they are for `strata robot --json`).

use std::sync::atomic::Ordering;

use serde::Serialize;
use strata_rcssmj::compute::ComputeReport;
use strata_rcssmj::platform::FallRecord;
use strata_robot::assembly::RobotModules;
use strata_runtime::HostStats;
use strata_soccer::game::GameDirective;

use super::platform::PlatformCounters;
use super::watch::Watch;
use super::{PlatformKind, RobotOptions};
use crate::links::{LinkCounters, LinkStats};
use crate::matches::LayerRate;

/// A change of the game as the robot sees it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GameEvent {
    pub state: String,
    pub penalized: bool,
    pub first_half: bool,
    pub kicking: String,
    pub score: [u8; 2],
}

impl GameEvent {
    pub(crate) fn of(directive: &GameDirective) -> GameEvent {
        GameEvent {
            state: format!("{:?}", directive.state),
            penalized: directive.penalized,
            first_half: directive.first_half,
            kicking: format!("{:?}", directive.kicking),
            score: directive.score,
        }
    }
}

/// How far the world model's pose is from where the robot really is.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct LocalizationAccuracy {
    /// World states compared.
    pub samples: u64,
    /// Position error, m.
    pub mean_error_m: f64,
    pub max_error_m: f64,
    pub last_error_m: f64,
    /// Heading error, degrees.
    pub mean_heading_error_deg: f64,
    /// Where the robot really was last (team frame: x towards the opponent goal), m.
    pub truth: [f64; 2],
    /// Where the world model put it.
    pub estimate: [f64; 2],
    /// Whether the world model said its pose was lost, last.
    #[serde(skip)]
    pub last_lost: bool,
    /// The world model's ball, last (team frame).
    #[serde(skip)]
    pub last_ball: Option<BallStatus>,
    /// Headings last, degrees (estimate, truth).
    #[serde(skip)]
    pub last_headings_deg: [f64; 2],
    /// The same after the pose first converged (first not lost after a landmark correction):
    /// the error of a robot that knows where it is, without the search before.
    pub converged: Option<ConvergedAccuracy>,
}

/// Position error over the world states since the pose first converged.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ConvergedAccuracy {
    /// World states before the first converged one.
    pub after_samples: u64,
    pub samples: u64,
    /// Of these, how many said the pose was lost.
    pub lost_samples: u64,
    pub mean_error_m: f64,
    pub max_error_m: f64,
}

pub(crate) struct Endpoints {
    pub(crate) game_controller: String,
    pub(crate) team: String,
}

#[derive(Debug, Serialize)]
pub struct StartInfo {
    pub team: u8,
    pub player: u8,
    pub platform: PlatformKind,
    pub platform_name: String,
    pub source: String,
    pub sensor_period_ms: f64,
    pub can_walk: bool,
    /// What drives the robot: `soccer`, the full architecture.
    pub controller: &'static str,
    pub team_config: String,
    pub coordination: bool,
    pub game_controller: String,
    pub team_messages: String,
    pub attack_sign: f64,
    pub attack_source: String,
}

#[derive(Debug, Serialize)]
pub struct Status {
    pub t: f64,
    pub sensor_frames: u64,
    pub camera_frames: u64,
    pub game_state: Option<String>,
    pub penalized: bool,
    pub mission: Option<String>,
    pub role: Option<String>,
    pub teammates: usize,
    pub messages_sent: u64,
    pub messages_received: u64,
    pub gc_packets: u64,
    /// The teammates the planning layer counts on now (heard lately, standing, localized, not
    /// penalized): one missing from here is one whose role the others take over.
    pub available_teammates: Vec<u8>,
    /// The three layers of hybrid control since the previous status line: a program watching
    /// the robot sees its rates change while it runs, not only in the final report.
    pub layers: Vec<LayerNow>,
    /// The newest self-localization against the ground truth (platforms that have one).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pose: Option<PoseStatus>,
    /// The world model's ball (platforms with a ground truth): what goal-covering experiments
    /// compare with the server's ball.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ball: Option<BallStatus>,
}

/// One layer in a status line.
#[derive(Debug, Serialize)]
pub struct LayerNow {
    pub layer: String,
    /// Cycles since the robot started.
    pub cycles: u64,
    /// Cycles per second since the previous status line.
    pub hz: f64,
}

/// Turns the host's cumulative cycle counts into each layer's rate between status lines.
pub(crate) struct LayerMeter {
    /// (layer, module) of the three layers.
    pub(crate) layers: Vec<(String, String)>,
    /// The host's elapsed time and each layer's cycles at the previous reading.
    pub(crate) last: Option<(f64, Vec<u64>)>,
}

impl LayerMeter {
    pub(crate) fn new(layers: Vec<(String, String)>) -> LayerMeter {
        LayerMeter { layers, last: None }
    }

    pub(crate) fn read(&mut self, stats: &HostStats) -> Vec<LayerNow> {
        let cycles: Vec<u64> = self
            .layers
            .iter()
            .map(|(_, module)| stats.module(module).map_or(0, |m| m.cycles))
            .collect();
        let (since, before) = match &self.last {
            Some((t, before)) => (stats.elapsed_s - t, before.clone()),
            None => (stats.elapsed_s, vec![0; cycles.len()]),
        };
        let now = self
            .layers
            .iter()
            .zip(cycles.iter().zip(before))
            .map(|((layer, _), (&n, b))| LayerNow {
                layer: layer.clone(),
                cycles: n,
                hz: if since > 0.0 { n.saturating_sub(b) as f64 / since } else { 0.0 },
            })
            .collect();
        self.last = Some((stats.elapsed_s, cycles));
        now
    }
}

/// Whether the world model knows where the ball is, and where it puts it (team frame, m).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct BallStatus {
    pub known: bool,
    pub confidence: f64,
    /// `None` while the ball is not known.
    pub estimate: Option<[f64; 2]>,
}

/// Where the world model puts the robot and where it is, in the team frame, m.
#[derive(Debug, Serialize)]
pub struct PoseStatus {
    /// x, y (m) and heading (degrees).
    pub estimate: [f64; 3],
    pub truth: [f64; 3],
    pub error_m: f64,
    pub lost: bool,
}

impl Status {
    pub(crate) fn gather(
        t: f64,
        platform: &PlatformCounters,
        watch: &Watch,
        team: &LinkCounters,
        gc: &LinkCounters,
        accuracy: Option<LocalizationAccuracy>,
        layers: Vec<LayerNow>,
    ) -> Status {
        let decision = watch.latest();
        let connected = decision.as_ref().filter(|d| d.directive.connected);
        let planning = decision.as_ref().map(|d| d.stats.clone()).unwrap_or_default();
        Status {
            t,
            sensor_frames: platform.sensor_frames.load(Ordering::Relaxed),
            camera_frames: platform.camera_frames.load(Ordering::Relaxed),
            game_state: connected.map(|d| format!("{:?}", d.directive.state)),
            penalized: connected.is_some_and(|d| d.directive.penalized),
            mission: decision.as_ref().map(|d| d.assignment.mission.name().to_owned()),
            role: decision.as_ref().map(|d| d.assignment.role.name().to_owned()),
            teammates: decision.as_ref().map_or(0, |d| d.teammates.len()),
            messages_sent: team.snapshot().sent,
            messages_received: planning.received,
            gc_packets: gc.snapshot().received,
            available_teammates: decision.as_ref().map_or_else(Vec::new, |d| {
                d.teammates.iter().filter(|t| t.available).map(|t| t.member).collect()
            }),
            layers,
            pose: accuracy.map(|a| PoseStatus {
                estimate: [a.estimate[0], a.estimate[1], a.last_headings_deg[0]],
                truth: [a.truth[0], a.truth[1], a.last_headings_deg[1]],
                error_m: a.last_error_m,
                lost: a.last_lost,
            }),
            ball: accuracy.and_then(|a| a.last_ball),
        }
    }
}

/// Everything one run of a robot produced.
#[derive(Debug, Serialize)]
pub struct Report {
    pub team: u8,
    pub player: u8,
    pub platform: PlatformKind,
    pub wall_s: f64,
    pub ended: String,
    pub sensor_frames: u64,
    pub camera_frames: u64,
    pub detections: u64,
    pub platform_errors: u64,
    /// Every game state the robot followed, in order.
    pub game_states: Vec<String>,
    pub game: Option<GameEvent>,
    pub mission: Option<String>,
    pub role: Option<String>,
    pub planning: strata_robot::control::planning::PlanningStats,
    pub team_link: LinkStats,
    pub game_controller_link: LinkStats,
    /// The three layers of hybrid control (the paper's Table 6).
    pub layers: Vec<LayerRate>,
    /// Every module.
    pub host: HostStats,
    /// Self-localization against the platform's ground truth (rcssservermj only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub localization: Option<LocalizationAccuracy>,
    /// Falls in the server's time: the ground-truth onset and the protective-fall order
    /// (rcssservermj only).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub falls: Vec<FallRecord>,
    /// The server's time of every protective-fall order that no fall followed: false alarms
    /// (rcssservermj only; `strata_rcssmj::falls::FallLog::false_falls`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub false_falls: Vec<f64>,
    /// The robot's compute per server cycle (rcssservermj only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub compute: Option<Compute>,
}

/// The robot's compute per 20 ms server cycle: CPU time measured by the platform at each
/// cycle's boundary (`strata_rcssmj::compute`), and the modules' own wall times for comparison.
#[derive(Debug, Serialize)]
pub struct Compute {
    #[serde(flatten)]
    pub per_cycle: ComputeReport,
    /// Every module's measured compute (wall time of its cycles) summed over the run, per
    /// server cycle, us: the share of `process` the modules account for (wall time also counts
    /// waiting for a core).
    pub modules_wall_mean_us: f64,
}

impl Compute {
    pub(crate) fn new(per_cycle: ComputeReport, host: &HostStats) -> Compute {
        let total_us: f64 =
            host.modules.iter().map(|m| m.compute_time.mean_us * m.compute_time.count as f64).sum();
        let modules_wall_mean_us =
            if per_cycle.cycles > 0 { total_us / per_cycle.cycles as f64 } else { 0.0 };
        Compute { per_cycle, modules_wall_mean_us }
    }
}

impl Report {
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        opts: &RobotOptions,
        wall_s: f64,
        ended: String,
        platform: &PlatformCounters,
        watch: &Watch,
        team_link: LinkStats,
        game_controller_link: LinkStats,
        modules: &RobotModules,
        host: HostStats,
    ) -> Report {
        let state = watch.lock();
        let decision = state.latest.clone();
        Report {
            team: opts.team,
            player: opts.player,
            platform: opts.platform,
            wall_s,
            ended,
            sensor_frames: platform.sensor_frames.load(Ordering::Relaxed),
            camera_frames: platform.camera_frames.load(Ordering::Relaxed),
            detections: platform.detections.load(Ordering::Relaxed),
            platform_errors: platform.errors.load(Ordering::Relaxed),
            game_states: state.history.clone(),
            game: state.last_event.clone(),
            mission: decision.as_ref().map(|d| d.assignment.mission.name().to_owned()),
            role: decision.as_ref().map(|d| d.assignment.role.name().to_owned()),
            planning: decision.map(|d| d.stats).unwrap_or_default(),
            team_link,
            game_controller_link,
            layers: modules
                .layers()
                .iter()
                .filter_map(|(layer, name)| {
                    host.module(name).map(|m| LayerRate {
                        layer: (*layer).to_owned(),
                        cycles: m.cycles,
                        min_hz: m.rate.min_hz,
                        mean_hz: m.rate.mean_hz,
                        max_hz: m.rate.max_hz,
                    })
                })
                .collect(),
            host,
            localization: None,
            falls: Vec::new(),
            false_falls: Vec::new(),
            compute: None,
        }
    }
}
