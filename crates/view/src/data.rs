//! What the viewer shows, as compact time series built from logged (or live) packages: ground
//! truth, each robot's estimates, behavior paths and scores.
//!
//! The robots' true states and estimates are the scene's ([`strata_games::scene`]): the same
//! conversion of ground truth and world states, the same team-to-field frames and the same
//! covariance ellipses that the logs' Foxglove channels draw, sampled over time for scrubbing.
//!
//! Packages come from a log (encoded) or from a live match's tap (the packages themselves):
//! world states and reactive reports are read as their Rust types (a log holds them compactly,
//! what they derive is worked out when they are read), the rest as JSON. Only the fields the
//! viewer draws are kept; the large streams (world state, reactive report) are sampled at
//! [`SAMPLE_PERIOD`] per robot before they are read, which bounds both the memory and the cost
//! of a whole match.

use std::collections::BTreeMap;
use std::sync::Arc;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use strata_games::outputs;
use strata_games::scene::{self, Estimate, TrueRobot};
use strata_robot::control::reactive::{MuxReport, ReactiveReport};
use strata_runtime::cdr::{self, Format};
use strata_runtime::{Encoding, ErasedPackage, PortName, Time};
use strata_spl::field::{Field, Side};

/// A package as the viewer gets it.
#[derive(Clone, Copy)]
pub enum Incoming<'a> {
    /// From a log: its bytes, their encoding and, for CDR, the channel's format.
    Logged { encoding: Encoding, format: Option<&'a Format>, bytes: &'a [u8] },
    /// From a live match.
    Live(&'a dyn ErasedPackage),
}

impl std::fmt::Debug for Incoming<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Incoming::Logged { encoding, bytes, .. } => {
                write!(f, "Logged({}, {} bytes)", encoding.mcap_name(), bytes.len())
            }
            Incoming::Live(p) => write!(f, "Live(seq {})", p.seq()),
        }
    }
}

impl Incoming<'_> {
    /// The value as `T` read from its JSON form (the viewer's own views of the values, which
    /// name the fields they read).
    fn json<T: DeserializeOwned>(self) -> Option<T> {
        match self {
            Incoming::Logged { encoding: Encoding::Cdr, format, bytes } => {
                serde_json::from_value(cdr::to_json(format?, bytes).ok()?).ok()
            }
            Incoming::Logged { encoding, bytes, .. } => encoding.decode(bytes).ok(),
            Incoming::Live(package) => {
                let mut json = Vec::new();
                package.write_json(&mut json).ok()?;
                serde_json::from_slice(&json).ok()
            }
        }
    }

    /// The value as the Rust type of `port`, the output it was sent on.
    fn typed<T: strata_runtime::Message>(self, port: PortName<T>) -> Option<T> {
        match self {
            Incoming::Logged { encoding, bytes, .. } => encoding.decode(bytes).ok(),
            Incoming::Live(package) => port.downcast(package).map(|p| p.value.clone()),
        }
    }
}

/// The spacing of the samples kept of the per-cycle streams of each robot.
pub const SAMPLE_PERIOD: f64 = 0.05;

/// What a topic carries, for the viewer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Truth,
    World,
    Report,
    Deliberative,
    Planning,
}

/// The topic's robot (index into [`ViewData::robots`]) and kind; `None` for topics the viewer
/// does not use.
fn classify(topic: &str) -> Option<(Option<&str>, Kind)> {
    let (module, output) = topic.rsplit_once('/')?;
    if module == "simulator" && output == outputs::GROUND_TRUTH.name() {
        return Some((None, Kind::Truth));
    }
    let (robot, module) = split_robot(module)?;
    let kind = match module {
        "world" if output == outputs::WORLD_STATE.name() => Kind::World,
        "reactive" if output == outputs::REPORT.name() => Kind::Report,
        "deliberative" if output == outputs::SCORES.name() => Kind::Deliberative,
        "planning" if output == outputs::DECISION.name() => Kind::Planning,
        _ => return None,
    };
    Some((Some(robot), kind))
}

/// `home/3/world` -> (`home/3`, `world`). A robot's own log (`strata robot --log`) names its
/// modules by team number: `t10/3/world`.
fn split_robot(topic: &str) -> Option<(&str, &str)> {
    let team_end = topic.find('/')?;
    let team = &topic[..team_end];
    let team_number = team.strip_prefix('t').is_some_and(|n| n.parse::<u8>().is_ok());
    if team != "home" && team != "away" && !team_number {
        return None;
    }
    let player_end = team_end + 1 + topic[team_end + 1..].find('/')?;
    topic[team_end + 1..player_end].parse::<u8>().ok()?;
    Some((&topic[..player_end], &topic[player_end + 1..]))
}

// ---- The parts of logged values the viewer reads (everything else is skipped). ----

#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Xy {
    pub x: f64,
    pub y: f64,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub x: f64,
    pub y: f64,
    pub theta: f64,
}

#[derive(Deserialize)]
struct TruthIn {
    robots: Vec<RobotTruthIn>,
    ball: BallIn,
    game: GameIn,
}

#[derive(Deserialize)]
struct RobotIdIn {
    team: usize,
    player: u8,
}

#[derive(Deserialize)]
struct HeadIn {
    yaw: f64,
    #[serde(default)]
    pitch: f64,
}

#[derive(Deserialize)]
struct RobotTruthIn {
    id: RobotIdIn,
    present: bool,
    pose: Pose,
    head: HeadIn,
    #[serde(default)]
    fallen: bool,
    #[serde(default)]
    penalty: Value,
}

#[derive(Deserialize)]
struct BallIn {
    position: Xy,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GameView {
    #[serde(default)]
    pub state: String,
    #[serde(default)]
    pub set_play: String,
    #[serde(default)]
    pub first_half: bool,
    #[serde(default)]
    pub kicking_team: Option<usize>,
    #[serde(default)]
    pub secs_remaining: f64,
    #[serde(default)]
    pub score: [u8; 2],
    #[serde(default)]
    pub attack_sign: [f64; 2],
    #[serde(default)]
    pub game_over: bool,
}

type GameIn = GameView;

#[derive(Deserialize)]
struct WorldIn {
    pose: PoseEstimateIn,
    objects: Vec<ObjectIn>,
    #[serde(default)]
    team: Vec<TeamObjectIn>,
}

#[derive(Deserialize)]
struct PoseEstimateIn {
    pose: Pose,
    confidence: f64,
    lost: bool,
}

#[derive(Deserialize)]
struct ObjectIn {
    name: String,
    #[serde(default)]
    group: String,
    known: bool,
    confidence: f64,
    global_position: Xy,
}

#[derive(Deserialize)]
struct TeamObjectIn {
    name: String,
    position: Xy,
}

#[derive(Deserialize)]
struct ReportIn {
    head: MuxIn,
    body: MuxIn,
    whole_body: MuxIn,
}

#[derive(Deserialize)]
struct MuxIn {
    #[serde(default)]
    goals: Vec<GoalIn>,
    selected_goal: Option<String>,
    primitive: Option<String>,
    inhibited_by: Option<Value>,
}

#[derive(Deserialize)]
struct GoalIn {
    goal: String,
    #[serde(default)]
    objects: Vec<String>,
    deliberative: f64,
    reactive: f64,
    final_score: f64,
}

#[derive(Deserialize)]
struct DeliberativeIn {
    #[serde(default)]
    behavior_path: String,
}

#[derive(Deserialize)]
struct DecisionIn {
    assignment: AssignmentIn,
}

#[derive(Deserialize)]
struct AssignmentIn {
    mission: Value,
    role: Value,
}

fn label(value: &Value) -> String {
    match value {
        Value::String(s) => s.clone(),
        Value::Null => String::new(),
        // An enum variant with fields: its name.
        Value::Object(map) => map.keys().next().cloned().unwrap_or_default(),
        other => other.to_string(),
    }
}

// ---- Samples. ----

#[derive(Clone, Debug)]
struct TruthSample {
    t: f64,
    game: GameView,
    ball: Xy,
    /// By robot name: the scene's true state and the penalty's name.
    robots: Vec<(String, TrueRobot, String)>,
}

#[derive(Clone, Debug)]
struct WorldSample {
    t: f64,
    /// In the robot's team frame (own goal at -x), as the robot estimates it: turned into the
    /// field frame with the attack sign of the instant shown.
    estimate: Estimate,
}

#[derive(Clone, Debug)]
struct ReportSample {
    t: f64,
    /// Shared with the previous sample when unchanged (paths change seldom).
    path: Arc<str>,
    head_goal: Option<Arc<str>>,
    /// Where the selected head goal's objects are estimated (team frame).
    gaze: Vec<Xy>,
    /// Head goals: (goal index into the robot's labels, S_d, S_r, final).
    scores: Vec<(u16, f32, f32, f32)>,
}

#[derive(Clone, Debug)]
struct LayerSample {
    t: f64,
    text: String,
}

#[derive(Clone, Debug)]
struct PlanningSample {
    t: f64,
    mission: String,
    role: String,
}

#[derive(Debug, Default)]
struct RobotSeries {
    name: String,
    team: usize,
    player: u8,
    world: Vec<WorldSample>,
    reports: Vec<ReportSample>,
    deliberative: Vec<LayerSample>,
    planning: Vec<PlanningSample>,
    goal_labels: Vec<String>,
    /// Newest estimated positions of the objects (team frame), to place the gaze target.
    objects: BTreeMap<String, Xy>,
    last_world: Option<f64>,
    last_report: Option<f64>,
}

/// The field, as the page draws it (metres, field frame).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FieldView {
    pub name: String,
    pub length: f64,
    pub width: f64,
    pub border: f64,
    pub line_width: f64,
    /// Segments: [x0, y0, x1, y1].
    pub lines: Vec<[f64; 4]>,
    pub centre_circle: [f64; 3],
    /// Penalty marks and other point landmarks: [x, y].
    pub marks: Vec<[f64; 2]>,
    /// Goal posts: [x, y] of the centres.
    pub posts: Vec<[f64; 2]>,
    pub post_diameter: f64,
    /// The goals' insides: [x0, y0, x1, y1].
    pub goals: Vec<[f64; 4]>,
    pub beacons: Vec<BeaconView>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BeaconView {
    pub name: String,
    pub x: f64,
    pub y: f64,
    pub colours: Vec<String>,
}

impl FieldView {
    pub fn of(field: &Field) -> FieldView {
        let d = field.dimensions();
        let circle = field.centre_circle();
        let goals: Vec<_> = [Side::Own, Side::Opponent].map(|s| field.goal(s)).into();
        FieldView {
            name: d.name.clone(),
            length: d.field_length,
            width: d.field_width,
            border: d.border_strip_width,
            line_width: d.line_width,
            lines: field.lines().iter().map(|l| [l.start.x, l.start.y, l.end.x, l.end.y]).collect(),
            centre_circle: [circle.centre.x, circle.centre.y, circle.radius],
            marks: field
                .landmarks_of(strata_spl::LandmarkKind::PenaltyMark)
                .map(|l| {
                    let p = l.position();
                    [p.x, p.y]
                })
                .collect(),
            posts: goals
                .iter()
                .flat_map(|g| [[g.left_post.x, g.left_post.y], [g.right_post.x, g.right_post.y]])
                .collect(),
            post_diameter: d.goal_post_diameter,
            goals: goals
                .iter()
                .map(|g| [g.inside.min.x, g.inside.min.y, g.inside.max.x, g.inside.max.y])
                .collect(),
            beacons: d
                .beacons
                .iter()
                .map(|b| BeaconView {
                    name: b.name.clone(),
                    x: b.x,
                    y: b.y,
                    colours: b
                        .colours
                        .iter()
                        .map(|c| serde_json::to_value(c).map(|v| label(&v)).unwrap_or_default())
                        .collect(),
                })
                .collect(),
        }
    }
}

/// Static facts about what is shown.
#[derive(Clone, Debug, Serialize)]
pub struct ViewInfo {
    /// `log` or `live`.
    pub source: String,
    /// The log file, for `log`.
    pub file: Option<String>,
    pub field: FieldView,
    pub teams: [String; 2],
    pub robots: Vec<String>,
    /// Camera field of view (rad) and range (m) of the robots.
    pub camera_fov: f64,
    pub camera_range: f64,
    pub seed: Option<u64>,
    /// First and last time with ground truth, s.
    pub start: f64,
    pub end: f64,
    /// Still receiving data (a live match, or a log being read).
    pub growing: bool,
    /// Problems met while reading (unreadable packages are skipped, and counted here).
    pub warnings: Vec<String>,
}

/// One robot at one instant.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RobotFrame {
    pub name: String,
    pub team: usize,
    pub player: u8,
    pub present: bool,
    pub fallen: bool,
    pub penalty: String,
    /// True pose (field frame).
    pub pose: Option<Pose>,
    /// Head yaw relative to the body, rad.
    pub head_yaw: f64,
    /// Estimated pose (field frame), its confidence and whether the robot considers itself lost.
    pub estimate: Option<Pose>,
    pub pose_confidence: Option<f64>,
    pub lost: bool,
    /// The robot's own ball estimate (field frame), with its confidence and whether it is known.
    pub ball: Option<BallEstimate>,
    /// The team's fused ball (field frame).
    pub team_ball: Option<Xy>,
    /// What the head is looking at (field frame) and the head goal selected.
    pub gaze: Vec<Xy>,
    pub head_goal: Option<String>,
    pub mission: Option<String>,
    pub role: Option<String>,
    /// Active behavior path per layer.
    pub planning_path: Option<String>,
    pub deliberative_path: Option<String>,
    pub reactive_path: Option<String>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BallEstimate {
    pub x: f64,
    pub y: f64,
    pub confidence: f64,
    pub known: bool,
    /// The estimate's 2-sigma covariance ellipse (field frame), as the scene draws it.
    pub ellipse: Vec<[f64; 2]>,
}

/// Everything at one instant.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Frame {
    /// The time asked for, s.
    pub t: f64,
    /// The time of the ground truth shown.
    pub truth_t: Option<f64>,
    pub game: Option<GameView>,
    /// True ball (field frame).
    pub ball: Option<Xy>,
    pub robots: Vec<RobotFrame>,
}

/// Scores of one goal over time.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GoalSeries {
    pub goal: String,
    pub t: Vec<f64>,
    /// S_d, S_r and the final score; `null` where the goal was not offered.
    pub deliberative: Vec<Option<f32>>,
    pub reactive: Vec<Option<f32>>,
    #[serde(rename = "final")]
    pub final_score: Vec<Option<f32>>,
}

/// Fig. 5 of the paper for one robot: the head goals' scores and the ball confidence.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Series {
    pub robot: String,
    pub from: f64,
    pub to: f64,
    pub goals: Vec<GoalSeries>,
    pub ball_confidence: Vec<[f64; 2]>,
}

/// The viewer's store.
#[derive(Debug)]
pub struct ViewData {
    info: ViewInfo,
    truth: Vec<TruthSample>,
    robots: Vec<RobotSeries>,
    /// The times of the robots' own packages: the timeline of a log without ground truth (a
    /// robot's own log).
    estimates_span: Option<(f64, f64)>,
    /// Packages that could not be read, by topic.
    unreadable: BTreeMap<String, u64>,
}

impl ViewData {
    pub fn new(source: &str, file: Option<String>, field: &Field) -> ViewData {
        ViewData {
            info: ViewInfo {
                source: source.to_owned(),
                file,
                field: FieldView::of(field),
                teams: ["home".to_owned(), "away".to_owned()],
                robots: Vec::new(),
                camera_fov: 60f64.to_radians(),
                camera_range: 6.0,
                seed: None,
                start: 0.0,
                end: 0.0,
                growing: true,
                warnings: Vec::new(),
            },
            truth: Vec::new(),
            robots: Vec::new(),
            estimates_span: None,
            unreadable: BTreeMap::new(),
        }
    }

    pub fn set_teams(&mut self, teams: [String; 2]) {
        self.info.teams = teams;
    }

    pub fn set_camera(&mut self, fov: f64, range: f64) {
        self.info.camera_fov = fov;
        self.info.camera_range = range;
    }

    pub fn set_seed(&mut self, seed: Option<u64>) {
        self.info.seed = seed;
    }

    pub fn warn(&mut self, warning: String) {
        self.info.warnings.push(warning);
    }

    /// No more data will come.
    pub fn set_complete(&mut self) {
        self.info.growing = false;
    }

    pub fn info(&self) -> ViewInfo {
        let mut info = self.info.clone();
        info.robots = self.robots.iter().map(|r| r.name.clone()).collect();
        for (topic, n) in &self.unreadable {
            info.warnings.push(format!("{n} packages of `{topic}` could not be read"));
        }
        info
    }

    fn robot_index(&mut self, name: &str) -> usize {
        if let Some(i) = self.robots.iter().position(|r| r.name == name) {
            return i;
        }
        let team = usize::from(name.starts_with("away/"));
        let player = name.rsplit('/').next().and_then(|p| p.parse().ok()).unwrap_or(0);
        self.robots.push(RobotSeries {
            name: name.to_owned(),
            team,
            player,
            ..RobotSeries::default()
        });
        // Keep the robots ordered (home before away, by player): the page lists them so.
        self.robots.sort_by_key(|r| (r.team, r.player));
        self.robots.iter().position(|r| r.name == name).unwrap_or(0)
    }

    /// Whether a package of `topic` at time `t` would be kept: the live tap asks before it
    /// pays for serializing the package.
    pub fn wants(&self, topic: &str, t: Time) -> bool {
        let Some((robot, kind)) = classify(topic) else { return false };
        let t = t.as_secs_f64();
        let last = |r: &RobotSeries| match kind {
            Kind::World => r.last_world,
            Kind::Report => r.last_report,
            _ => None,
        };
        match robot {
            None => true,
            Some(name) => self
                .robots
                .iter()
                .find(|r| r.name == name)
                .and_then(last)
                .is_none_or(|last| t >= last + SAMPLE_PERIOD - 1e-9),
        }
    }

    /// Takes one package (its topic, log time and value). Unreadable packages are counted,
    /// never fatal: a viewer shows what it can.
    pub fn ingest(&mut self, topic: &str, time: Time, value: Incoming<'_>) {
        if !self.wants(topic, time) {
            return;
        }
        let Some((robot, kind)) = classify(topic) else { return };
        let t = time.as_secs_f64();
        let ok = match (robot, kind) {
            (None, _) => self.ingest_truth(t, value),
            (Some(robot), kind) => {
                let index = self.robot_index(robot);
                let series = &mut self.robots[index];
                match kind {
                    Kind::World => ingest_world(series, t, value),
                    Kind::Report => ingest_report(series, t, value),
                    Kind::Deliberative => match value.json::<DeliberativeIn>() {
                        Some(d) => {
                            series.deliberative.push(LayerSample { t, text: d.behavior_path });
                            true
                        }
                        None => false,
                    },
                    Kind::Planning => match value.json::<DecisionIn>() {
                        Some(d) => {
                            series.planning.push(PlanningSample {
                                t,
                                mission: label(&d.assignment.mission),
                                role: label(&d.assignment.role),
                            });
                            true
                        }
                        None => false,
                    },
                    Kind::Truth => false,
                }
            }
        };
        if !ok {
            *self.unreadable.entry(topic.to_owned()).or_default() += 1;
        } else if robot.is_some() {
            let (start, end) = self.estimates_span.get_or_insert((t, t));
            (*start, *end) = (start.min(t), end.max(t));
            if self.truth.is_empty() {
                (self.info.start, self.info.end) = (*start, *end);
            }
        }
    }

    fn ingest_truth(&mut self, t: f64, value: Incoming<'_>) -> bool {
        let Some(truth) = truth_of(value) else { return false };
        for (name, _, _) in &truth.robots {
            self.robot_index(name);
        }
        if self.truth.is_empty() {
            self.info.start = t;
            self.info.end = t;
        }
        self.info.end = self.info.end.max(t);
        self.truth.push(TruthSample { t, ..truth });
        true
    }

    fn truth_at(&self, t: f64) -> Option<&TruthSample> {
        let i = self.truth.partition_point(|s| s.t <= t + 1e-9);
        // Before the first sample: show the first one.
        self.truth.get(i.saturating_sub(1))
    }

    /// The state at time `t` (seconds), or at the newest time when `t` is `None`.
    pub fn frame(&self, t: Option<f64>) -> Frame {
        let t = t.unwrap_or(self.info.end);
        let truth = self.truth_at(t);
        let robots = self
            .robots
            .iter()
            .map(|series| {
                let true_state = truth.and_then(|s| {
                    s.robots.iter().find(|(n, _, _)| *n == series.name).map(|(_, r, p)| (r, p))
                });
                let sign = truth.map_or(1.0, |s| {
                    if series.team == 0 { s.game.attack_sign[0] } else { s.game.attack_sign[1] }
                });
                let to_global = |p: Xy| {
                    let (x, y) = scene::team_to_field(p.x, p.y, sign);
                    Xy { x, y }
                };
                let world = latest(&series.world, t, |s| s.t);
                let estimate = world.map(|w| w.estimate.to_field(sign));
                let report = latest(&series.reports, t, |s| s.t);
                let planning = latest(&series.planning, t, |s| s.t);
                let deliberative = latest(&series.deliberative, t, |s| s.t);
                RobotFrame {
                    name: series.name.clone(),
                    team: series.team,
                    player: series.player,
                    present: true_state.is_none_or(|(r, _)| r.present),
                    fallen: true_state.is_some_and(|(r, _)| r.fallen),
                    penalty: true_state.map(|(_, p)| p.clone()).unwrap_or_default(),
                    pose: true_state.map(|(r, _)| Pose { x: r.x, y: r.y, theta: r.theta }),
                    head_yaw: true_state.map_or(0.0, |(r, _)| r.head_yaw),
                    estimate: estimate.map(|e| Pose { x: e.x, y: e.y, theta: e.theta }),
                    pose_confidence: estimate.map(|e| e.confidence),
                    lost: estimate.is_some_and(|e| e.lost),
                    ball: estimate.and_then(|e| e.ball).map(|b| BallEstimate {
                        x: b.x,
                        y: b.y,
                        confidence: b.confidence,
                        known: b.known,
                        ellipse: scene::covariance_ellipse(b.x, b.y, b.covariance, 2.0)
                            .iter()
                            .map(|p| [p.x, p.y])
                            .collect(),
                    }),
                    team_ball: estimate.and_then(|e| e.team_ball).map(|(x, y)| Xy { x, y }),
                    gaze: report
                        .map(|r| r.gaze.iter().map(|p| to_global(*p)).collect())
                        .unwrap_or_default(),
                    head_goal: report.and_then(|r| r.head_goal.as_deref().map(str::to_owned)),
                    mission: planning.map(|p| p.mission.clone()),
                    role: planning.map(|p| p.role.clone()),
                    planning_path: planning.map(|p| format!("{}/{}", p.mission, p.role)),
                    deliberative_path: deliberative.map(|d| d.text.clone()),
                    reactive_path: report.map(|r| r.path.to_string()),
                }
            })
            .collect();
        Frame {
            t,
            truth_t: truth.map(|s| s.t),
            game: truth.map(|s| s.game.clone()),
            ball: truth.map(|s| s.ball),
            robots,
        }
    }

    /// The scores of the head goals and the ball confidence of `robot` between `from` and
    /// `to` (seconds; the whole run by default), at most `max_points` samples per series.
    pub fn series(
        &self,
        robot: &str,
        from: Option<f64>,
        to: Option<f64>,
        max_points: usize,
    ) -> Option<Series> {
        let series = self.robots.iter().find(|r| r.name == robot)?;
        let from = from.unwrap_or(self.info.start);
        let to = to.unwrap_or(self.info.end);
        let window = |samples_t: &[f64]| {
            let a = samples_t.partition_point(|t| *t < from);
            let b = samples_t.partition_point(|t| *t <= to);
            (a, b.max(a))
        };
        let report_t: Vec<f64> = series.reports.iter().map(|r| r.t).collect();
        let (a, b) = window(&report_t);
        let stride = (b - a).div_ceil(max_points.max(1)).max(1);
        let picked: Vec<&ReportSample> = series.reports[a..b].iter().step_by(stride).collect();
        let goals = series
            .goal_labels
            .iter()
            .enumerate()
            .filter_map(|(g, goal)| {
                let g = g as u16;
                if !picked.iter().any(|r| r.scores.iter().any(|s| s.0 == g)) {
                    return None;
                }
                let find = |r: &ReportSample| r.scores.iter().find(|s| s.0 == g).copied();
                Some(GoalSeries {
                    goal: goal.clone(),
                    t: picked.iter().map(|r| r.t).collect(),
                    deliberative: picked.iter().map(|r| find(r).map(|s| s.1)).collect(),
                    reactive: picked.iter().map(|r| find(r).map(|s| s.2)).collect(),
                    final_score: picked.iter().map(|r| find(r).map(|s| s.3)).collect(),
                })
            })
            .collect();
        let world_t: Vec<f64> = series.world.iter().map(|w| w.t).collect();
        let (a, b) = window(&world_t);
        let stride = (b - a).div_ceil(max_points.max(1)).max(1);
        let ball_confidence = series.world[a..b]
            .iter()
            .step_by(stride)
            .map(|w| [w.t, w.estimate.ball.map_or(0.0, |b| b.confidence)])
            .collect();
        Some(Series { robot: robot.to_owned(), from, to, goals, ball_confidence })
    }
}

/// The newest sample at or before `t`.
fn latest<S>(samples: &[S], t: f64, time: impl Fn(&S) -> f64) -> Option<&S> {
    let i = samples.partition_point(|s| time(s) <= t + 1e-9);
    i.checked_sub(1).and_then(|i| samples.get(i))
}

impl WorldIn {
    /// The estimates of a world state read by its fields: the scene's, with no covariance
    /// (a writer other than Strata's need not log one).
    fn estimate(&self) -> Estimate {
        let p = self.pose.pose;
        Estimate {
            x: p.x,
            y: p.y,
            theta: p.theta,
            confidence: self.pose.confidence,
            lost: self.pose.lost,
            ball: self.objects.iter().find(|o| o.group == "ball" || o.name == "ball").map(|o| {
                scene::BallEstimate {
                    x: o.global_position.x,
                    y: o.global_position.y,
                    covariance: [[0.0; 2]; 2],
                    known: o.known,
                    confidence: o.confidence,
                }
            }),
            team_ball: self
                .team
                .iter()
                .find(|o| o.name == "ball")
                .map(|o| (o.position.x, o.position.y)),
        }
    }
}

impl ReportIn {
    fn of(report: &ReactiveReport) -> ReportIn {
        let mux = |m: &MuxReport| MuxIn {
            goals: m
                .goals
                .iter()
                .map(|g| GoalIn {
                    goal: g.goal.to_string(),
                    objects: g.objects.to_vec(),
                    deliberative: g.deliberative,
                    reactive: g.reactive,
                    final_score: g.final_score,
                })
                .collect(),
            selected_goal: m.selected_goal.as_deref().map(str::to_owned),
            primitive: m.primitive.as_deref().map(str::to_owned),
            inhibited_by: m.inhibited_by.and_then(|g| serde_json::to_value(g).ok()),
        };
        ReportIn {
            head: mux(&report.head),
            body: mux(&report.body),
            whole_body: mux(&report.whole_body),
        }
    }
}

/// A world state read: the scene's estimates (team frame) and where each object is estimated.
struct WorldRead {
    estimate: Estimate,
    objects: BTreeMap<String, Xy>,
}

/// A world state: as its Rust type, or (a log of another writer, a test) by its fields.
fn world_of(value: Incoming<'_>) -> Option<WorldRead> {
    if let Some(state) = value.typed(outputs::WORLD_STATE) {
        let objects = state
            .objects
            .iter()
            .map(|o| (o.name.to_string(), Xy { x: o.global_position.x, y: o.global_position.y }))
            .collect();
        return Some(WorldRead { estimate: Estimate::team_frame(&state), objects });
    }
    let world: WorldIn = value.json()?;
    let objects = world.objects.iter().map(|o| (o.name.clone(), o.global_position)).collect();
    Some(WorldRead { estimate: world.estimate(), objects })
}

/// A ground truth: as its Rust type (the scene's true states), or by its fields.
fn truth_of(value: Incoming<'_>) -> Option<TruthSample> {
    let name =
        |team: usize, player: u8| format!("{}/{}", if team == 0 { "home" } else { "away" }, player);
    if let Some(truth) = value.typed(outputs::GROUND_TRUTH) {
        let game =
            serde_json::to_value(&truth.game).ok().and_then(|v| serde_json::from_value(v).ok())?;
        let robots = truth
            .robots
            .iter()
            .map(|r| {
                let penalty =
                    serde_json::to_value(r.penalty).map(|v| label(&v)).unwrap_or_default();
                (name(r.id.team, r.id.player), TrueRobot::of(r), penalty)
            })
            .collect();
        let ball = Xy { x: truth.ball.position.x, y: truth.ball.position.y };
        return Some(TruthSample { t: 0.0, game, ball, robots });
    }
    let truth: TruthIn = value.json()?;
    let robots = truth
        .robots
        .into_iter()
        .map(|r| {
            let penalty = label(&r.penalty);
            let state = TrueRobot {
                x: r.pose.x,
                y: r.pose.y,
                theta: r.pose.theta,
                head_yaw: r.head.yaw,
                head_pitch: r.head.pitch,
                present: r.present,
                fallen: r.fallen,
                penalized: !penalty.is_empty() && penalty != "None",
            };
            (name(r.id.team, r.id.player), state, penalty)
        })
        .collect();
    Some(TruthSample { t: 0.0, game: truth.game, ball: truth.ball.position, robots })
}

fn report_of(value: Incoming<'_>) -> Option<ReportIn> {
    match value.typed(outputs::REPORT) {
        Some(report) => Some(ReportIn::of(&report)),
        None => value.json(),
    }
}

fn ingest_world(series: &mut RobotSeries, t: f64, value: Incoming<'_>) -> bool {
    let Some(world) = world_of(value) else { return false };
    series.objects = world.objects;
    series.last_world = Some(t);
    series.world.push(WorldSample { t, estimate: world.estimate });
    true
}

fn ingest_report(series: &mut RobotSeries, t: f64, value: Incoming<'_>) -> bool {
    let Some(report) = report_of(value) else { return false };
    let head = &report.head;
    let gaze = head
        .selected_goal
        .as_ref()
        .and_then(|selected| head.goals.iter().find(|g| &g.goal == selected))
        .map(|g| g.objects.iter().filter_map(|o| series.objects.get(o).copied()).collect())
        .unwrap_or_default();
    let mut scores = Vec::with_capacity(head.goals.len());
    for goal in &head.goals {
        let index = match series.goal_labels.iter().position(|l| *l == goal.goal) {
            Some(i) => i,
            None => {
                series.goal_labels.push(goal.goal.clone());
                series.goal_labels.len() - 1
            }
        };
        scores.push((
            index as u16,
            goal.deliberative as f32,
            goal.reactive as f32,
            goal.final_score as f32,
        ));
    }
    let part = |name: &str, m: &MuxIn| match (&m.selected_goal, &m.primitive, &m.inhibited_by) {
        (Some(goal), Some(primitive), _) => format!("{name}: {goal} > {primitive}"),
        // As `ReactiveReport::active_path` names the groups.
        (_, _, Some(by)) if !by.is_null() => {
            format!("{name}: inhibited by {}", label(by).replace("head_and_body", "head+body"))
        }
        _ => format!("{name}: idle"),
    };
    series.last_report = Some(t);
    let path = format!(
        "{} | {} | {}",
        part("head+body", &report.whole_body),
        part("head", &report.head),
        part("body", &report.body)
    );
    let previous = series.reports.last();
    let path = match previous {
        Some(p) if *p.path == *path => Arc::clone(&p.path),
        _ => Arc::from(path),
    };
    let head_goal = match (&head.selected_goal, previous.and_then(|p| p.head_goal.as_ref())) {
        (Some(goal), Some(last)) if **last == **goal => Some(Arc::clone(last)),
        (goal, _) => goal.as_deref().map(Arc::from),
    };
    series.reports.push(ReportSample { t, path, head_goal, gaze, scores });
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topics_are_classified() {
        assert_eq!(classify("simulator/ground_truth"), Some((None, Kind::Truth)));
        assert_eq!(classify("home/3/world/world_state"), Some((Some("home/3"), Kind::World)));
        assert_eq!(classify("away/12/reactive/report"), Some((Some("away/12"), Kind::Report)));
        assert_eq!(classify("home/3/reactive/commands"), None);
        assert_eq!(classify("visitors/3/world/world_state"), None);
        assert_eq!(classify("home/x/world/world_state"), None);
        assert_eq!(classify("home"), None);
        assert_eq!(classify("t10/3/world/world_state"), Some((Some("t10/3"), Kind::World)));
        assert_eq!(classify("t/3/world/world_state"), None);
        assert_eq!(classify("tx/3/world/world_state"), None);
    }

    /// A robot's own log has no ground truth: the timeline follows the robot's packages and the
    /// robot is drawn where it believes it is.
    #[test]
    fn a_robot_log_without_ground_truth_is_shown_from_its_estimates() {
        let field = Field::preset("spl").unwrap_or_else(|e| panic!("{e}"));
        let mut data = ViewData::new("log", None, &field);
        for (t, x) in [(2.0, -1.0), (3.5, 0.5)] {
            let world = serde_json::json!({
                "pose": { "pose": { "x": x, "y": 1.0, "theta": 0.0 }, "confidence": 0.8, "lost": false },
                "objects": [{ "name": "ball", "group": "ball", "global_position": { "x": 2.0, "y": 0.0 },
                              "confidence": 0.9, "known": true }],
                "team": [],
            });
            let bytes = serde_json::to_vec(&world).unwrap_or_else(|e| panic!("{e}"));
            let value = Incoming::Logged { encoding: Encoding::Json, format: None, bytes: &bytes };
            data.ingest("t10/3/world/world_state", Time::from_secs_f64(t), value);
        }
        let info = data.info();
        assert!(info.warnings.is_empty(), "{:?}", info.warnings);
        assert_eq!((info.start, info.end), (2.0, 3.5));
        assert_eq!(info.robots, vec!["t10/3".to_owned()]);
        let frame = data.frame(Some(3.0));
        let robot = &frame.robots[0];
        assert!(robot.pose.is_none(), "no ground truth");
        assert_eq!(robot.estimate.map(|p| (p.x, p.y)), Some((-1.0, 1.0)));
        assert_eq!(robot.ball.as_ref().map(|b| (b.x, b.y)), Some((2.0, 0.0)));
        let later = data.frame(None);
        assert_eq!(later.robots[0].estimate.map(|p| p.x), Some(0.5));
    }

    #[test]
    fn bad_packages_are_counted_not_fatal() {
        let field = Field::preset("spl").unwrap_or_else(|e| panic!("{e}"));
        let mut data = ViewData::new("log", None, &field);
        let logged = |encoding, bytes| Incoming::Logged { encoding, format: None, bytes };
        data.ingest("simulator/ground_truth", Time::ZERO, logged(Encoding::Json, b"{not json"));
        data.ingest("home/1/world/world_state", Time::ZERO, logged(Encoding::Json, b"[]"));
        data.ingest("home/1/reactive/report", Time::ZERO, logged(Encoding::MessagePack, b"\xc1"));
        data.ingest("home/1/planning/decision", Time::ZERO, logged(Encoding::Cdr, b"\0\x01\0\0"));
        let info = data.info();
        assert_eq!(info.warnings.len(), 4, "{:?}", info.warnings);
        let frame = data.frame(Some(1.0));
        assert!(frame.ball.is_none());
    }
}
