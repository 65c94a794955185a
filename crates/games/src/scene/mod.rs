//! The scene of a run as Foxglove's 3D panel draws it, computed from logged packages: the
//! field, each robot's true pose and its own estimate, the ball's truth and each robot's
//! estimate of it with its covariance, each robot's camera field of view and role, the
//! frames (field -> robot -> head -> camera), and the events of the game as log lines
//! (`docs/foxglove.md`).
//!
//! One place computes it: pure functions of the packages ([`field_update`],
//! [`objects_update`], [`transforms`], [`event_log`]) and a [`SceneRecorder`] that follows a
//! run's packages and says what to write when, fed by topic ([`feed::SceneFeed`]). The log
//! writer derives the scene channels with it off the match thread (`crate::logging`), and so
//! does the live server of Foxglove's WebSocket protocol ([`live`]); `strata view` can use the
//! same functions.
//!
//! The messages are Foxglove's well-known schemas ([`foxglove`]) in **JSON** with JSON
//! Schemas (message encoding `json`, schema encoding `jsonschema`). Foxglove decodes these
//! schemas in JSON, protobuf, ROS 1/2 and OMG IDL/CDR; JSON is chosen because the schema text
//! is then a plain transcription of Foxglove's published definitions that this crate writes
//! itself (no protobuf descriptor set to generate and embed, no `.proto` toolchain), because
//! serde writes it with no new dependency, and because the scene is a small stream (ten
//! updates per simulated second) beside the packages, which stay in CDR.

pub mod feed;
pub mod foxglove;
pub mod live;
pub mod plot;

use strata_robot::world::WorldState;
use strata_runtime::Time;
use strata_sim::{Event, EventKind, GroundTruth, RobotId};
use strata_spl::field::{Field, FieldDimensions, Side};

use crate::matches::robot_name;
use foxglove::{
    ArrowPrimitive, Color, CubePrimitive, Duration, FrameTransform, FrameTransforms, LinePrimitive,
    LineType, Log, LogLevel, Point3, Pose, Quaternion, SceneEntity, SceneUpdate, SpherePrimitive,
    TextPrimitive, Timestamp, TriangleListPrimitive, Vector3,
};
use plot::{LayerCounter, LayerKind, LayerPlot, RobotPlot};
use strata_robot::control::reactive::MuxReport;

/// The field's lines and goals, written once at the start of each file of a log.
pub const FIELD_TOPIC: &str = "scene/field";
/// Robots, ball, estimates and fields of view, [`SceneConfig::period`] apart.
pub const OBJECTS_TOPIC: &str = "scene/objects";
/// The frames `field` -> `home/3` -> `home/3/head` -> `home/3/camera` (and
/// `field` -> `home/3/estimate`), with the objects.
pub const TRANSFORMS_TOPIC: &str = "scene/tf";
/// Goals, falls, penalties, role and game-state changes, one `foxglove.Log` each.
pub const EVENTS_TOPIC: &str = "scene/events";
/// The root frame: the simulator's field frame (x towards the goal team 0 attacks in the
/// first half, metres).
pub const FIELD_FRAME: &str = "field";

/// Height of a robot's head frame above the ground, m (a NAO's neck).
const HEAD_HEIGHT: f64 = 0.45;
/// The camera in the head frame, m.
const CAMERA_OFFSET: Vector3 = Vector3::new(0.05, 0.0, 0.06);
const BALL_DIAMETER: f64 = 0.1;
const TEAM_BALL_DIAMETER: f64 = 0.25;

const WHITE: Color = Color::rgba(1.0, 1.0, 1.0, 1.0);
const GRASS: Color = Color::rgba(0.13, 0.45, 0.18, 1.0);
const BALL: Color = Color::rgba(1.0, 0.55, 0.0, 1.0);
const GOAL: Color = Color::rgba(0.95, 0.95, 0.3, 1.0);
const TEAMS: [Color; 2] = [Color::rgba(0.2, 0.4, 1.0, 1.0), Color::rgba(0.9, 0.15, 0.15, 1.0)];

/// What the scene needs besides the packages.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneConfig {
    pub field: FieldDimensions,
    /// Camera horizontal field of view, rad, and detection range, m (the platform's).
    pub camera_fov: f64,
    pub camera_range: f64,
    /// +1 when the team (index) attacks +x: turns a robot's team-frame estimates into the
    /// field frame. The ground truth's, where the log has it, overrides it.
    pub attack_sign: [f64; 2],
    /// Seconds of log time between two updates of the objects and frames.
    pub period: f64,
}

impl SceneConfig {
    /// Ten updates per second.
    pub const DEFAULT_PERIOD: f64 = 0.1;
}

/// A robot's true state, from the simulator's ground truth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrueRobot {
    /// Field frame.
    pub x: f64,
    pub y: f64,
    pub theta: f64,
    pub head_yaw: f64,
    pub head_pitch: f64,
    pub present: bool,
    pub fallen: bool,
    pub penalized: bool,
}

/// A robot's ball estimate in the field frame, with its covariance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BallEstimate {
    pub x: f64,
    pub y: f64,
    /// Covariance of (x, y), row by row.
    pub covariance: [[f64; 2]; 2],
    pub known: bool,
    pub confidence: f64,
}

/// A robot's own estimates: in its team frame (own goal at -x) as its world model holds
/// them, or in the field frame after [`Estimate::to_field`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    pub x: f64,
    pub y: f64,
    pub theta: f64,
    pub confidence: f64,
    pub lost: bool,
    pub ball: Option<BallEstimate>,
    /// The team's fused ball (MAWM), where the robot has one.
    pub team_ball: Option<(f64, f64)>,
}

/// A point of a team frame (own goal at -x) in the field frame of a team attacking
/// `attack_sign`: the frames agree for +1 and are half a turn apart for -1.
pub fn team_to_field(x: f64, y: f64, attack_sign: f64) -> (f64, f64) {
    if attack_sign < 0.0 { (-x, -y) } else { (x, y) }
}

impl Estimate {
    /// A world state's pose, ball and team ball as the robot holds them (team frame).
    pub fn team_frame(state: &WorldState) -> Estimate {
        let p = state.pose.pose;
        let ball = state.object("ball").map(|ball| {
            let c = &ball.global_covariance;
            BallEstimate {
                x: ball.global_position.x,
                y: ball.global_position.y,
                covariance: [[c[(0, 0)], c[(0, 1)]], [c[(1, 0)], c[(1, 1)]]],
                known: ball.known,
                confidence: ball.confidence,
            }
        });
        Estimate {
            x: p.x,
            y: p.y,
            theta: p.theta,
            confidence: state.pose.confidence,
            lost: state.pose.lost,
            ball,
            team_ball: state.team_object("ball").map(|b| (b.position.x, b.position.y)),
        }
    }

    /// A team-frame estimate in the field frame of a team attacking `attack_sign`.
    pub fn to_field(self, attack_sign: f64) -> Estimate {
        let turn = attack_sign < 0.0;
        let (x, y) = team_to_field(self.x, self.y, attack_sign);
        let theta = if turn { normalize(self.theta + std::f64::consts::PI) } else { self.theta };
        // Half a turn leaves a covariance as it is.
        let ball = self.ball.map(|b| {
            let (x, y) = team_to_field(b.x, b.y, attack_sign);
            BallEstimate { x, y, ..b }
        });
        let team_ball = self.team_ball.map(|(x, y)| team_to_field(x, y, attack_sign));
        Estimate { x, y, theta, ball, team_ball, ..self }
    }

    /// A world state's estimates in the field frame of a team attacking `attack_sign`.
    pub fn of(state: &WorldState, attack_sign: f64) -> Estimate {
        Estimate::team_frame(state).to_field(attack_sign)
    }
}

impl TrueRobot {
    /// A robot of the simulator's ground truth.
    pub fn of(r: &strata_sim::RobotTruth) -> TrueRobot {
        TrueRobot {
            x: r.pose.x,
            y: r.pose.y,
            theta: r.pose.theta,
            head_yaw: r.head.yaw,
            head_pitch: r.head.pitch,
            present: r.present,
            fallen: r.fallen,
            penalized: r.penalty != strata_sim::Penalty::None,
        }
    }
}

/// What the scene knows of one robot.
#[derive(Clone, Debug, PartialEq)]
pub struct RobotState {
    /// `home/3`, `away/1`, or a robot's own log's `t10/3`.
    pub name: String,
    /// Team index: 1 for `away/...`, otherwise 0.
    pub team: usize,
    pub truth: Option<TrueRobot>,
    pub estimate: Option<Estimate>,
    pub role: Option<String>,
    /// Its layers' outputs and head scores, for the plot channel.
    pub layers: LayerCounter,
}

impl RobotState {
    pub fn new(name: &str) -> RobotState {
        let team = usize::from(name.starts_with("away/"));
        RobotState {
            name: name.to_owned(),
            team,
            truth: None,
            estimate: None,
            role: None,
            layers: LayerCounter::default(),
        }
    }

    /// Where the robot is drawn from: its true pose, or its estimate in a log without truth.
    fn frame_pose(&self) -> Option<(f64, f64, f64, f64, f64)> {
        match (self.truth, self.estimate) {
            (Some(t), _) if t.present => Some((t.x, t.y, t.theta, t.head_yaw, t.head_pitch)),
            (Some(_), _) => None,
            (None, Some(e)) => Some((e.x, e.y, e.theta, 0.0, 0.0)),
            (None, None) => None,
        }
    }
}

fn normalize(angle: f64) -> f64 {
    angle.sin().atan2(angle.cos())
}

fn p3(x: f64, y: f64, z: f64) -> Point3 {
    Vector3::rounded(x, y, z)
}

/// The field's carpet, lines, centre circle, penalty marks and goals, in the field frame,
/// shown until replaced.
pub fn field_update(field: &Field, time: Timestamp) -> SceneUpdate {
    let d = field.dimensions();
    let mut entity = SceneEntity::new(time, FIELD_FRAME, "field", Duration::default());
    entity.meta("name", d.name.clone());
    let (half_length, half_width) = (field.half_length(), field.half_width());
    let border = d.border_strip_width;
    entity.cubes.push(CubePrimitive {
        pose: Pose::planar(0.0, 0.0, -0.006, 0.0),
        size: Vector3::new(2.0 * (half_length + border), 2.0 * (half_width + border), 0.01),
        color: GRASS,
    });
    let segments: Vec<Point3> = field
        .lines()
        .iter()
        .flat_map(|l| [p3(l.start.x, l.start.y, 0.0), p3(l.end.x, l.end.y, 0.0)])
        .collect();
    entity.lines.push(LinePrimitive::new(LineType::List, segments, d.line_width, WHITE));
    let circle = field.centre_circle();
    let circle_points = (0..48)
        .map(|k| {
            let a = f64::from(k) / 48.0 * std::f64::consts::TAU;
            p3(
                circle.centre.x + circle.radius * a.cos(),
                circle.centre.y + circle.radius * a.sin(),
                0.0,
            )
        })
        .collect();
    entity.lines.push(LinePrimitive::new(LineType::Loop, circle_points, d.line_width, WHITE));
    for mark in field.landmarks_of(strata_spl::LandmarkKind::PenaltyMark) {
        let p = mark.position();
        entity.cubes.push(CubePrimitive {
            pose: Pose::planar(p.x, p.y, 0.0, 0.0),
            size: Vector3::new(d.line_width * 2.0, d.line_width * 2.0, 0.005),
            color: WHITE,
        });
    }
    for side in [Side::Own, Side::Opponent] {
        let goal = field.goal(side);
        for post in [goal.left_post, goal.right_post] {
            entity.cylinders.push(foxglove::CylinderPrimitive {
                pose: Pose::planar(post.x, post.y, 0.4, 0.0),
                size: Vector3::new(d.goal_post_diameter, d.goal_post_diameter, 0.8),
                bottom_scale: 1.0,
                top_scale: 1.0,
                color: GOAL,
            });
        }
        let (min, max) = (goal.inside.min, goal.inside.max);
        let inside = vec![
            p3(min.x, min.y, 0.0),
            p3(max.x, min.y, 0.0),
            p3(max.x, max.y, 0.0),
            p3(min.x, max.y, 0.0),
        ];
        entity.lines.push(LinePrimitive::new(LineType::Loop, inside, d.line_width, GOAL));
    }
    SceneUpdate { deletions: Vec::new(), entities: vec![entity] }
}

/// The points of the ellipse `sigmas` standard deviations around `(x, y)` for a covariance
/// (24 points, [rounded](foxglove::round)).
pub fn covariance_ellipse(x: f64, y: f64, covariance: [[f64; 2]; 2], sigmas: f64) -> Vec<Point3> {
    let [[a, b], [_, c]] = covariance;
    let mean = (a + c) / 2.0;
    let spread = (((a - c) / 2.0).powi(2) + b * b).sqrt();
    let (major, minor) = ((mean + spread).max(0.0).sqrt(), (mean - spread).max(0.0).sqrt());
    let angle = 0.5 * (2.0 * b).atan2(a - c);
    let (s, co) = angle.sin_cos();
    (0..24)
        .map(|k| {
            let t = f64::from(k) / 24.0 * std::f64::consts::TAU;
            let (u, v) = (sigmas * major * t.cos(), sigmas * minor * t.sin());
            p3(x + co * u - s * v, y + s * u + co * v, 0.02)
        })
        .collect()
}

/// The robots, the ball and what each robot estimates, at `time`: entities `ball`,
/// `{robot}/truth`, `{robot}/estimate`, `{robot}/view` (its camera's field of view, in its
/// head frame). Each is shown for a few update periods unless replaced, so a robot that
/// leaves the log leaves the picture.
pub fn objects_update(
    robots: &[RobotState],
    ball: Option<(f64, f64)>,
    config: &SceneConfig,
    time: Timestamp,
) -> SceneUpdate {
    let lifetime = Duration::from_secs_f64((3.0 * config.period).max(0.3));
    let mut entities = Vec::with_capacity(1 + 3 * robots.len());
    if let Some((x, y)) = ball {
        let mut entity = SceneEntity::new(time, FIELD_FRAME, "ball", lifetime);
        entity.spheres.push(SpherePrimitive {
            pose: Pose::planar(x, y, BALL_DIAMETER / 2.0, 0.0),
            size: Vector3::new(BALL_DIAMETER, BALL_DIAMETER, BALL_DIAMETER),
            color: BALL,
        });
        entities.push(entity);
    }
    for robot in robots {
        let colour = TEAMS[robot.team.min(1)];
        let label = match &robot.role {
            Some(role) => format!("{} {role}", robot.name),
            None => robot.name.clone(),
        };
        if let Some(t) = robot.truth.filter(|t| t.present) {
            let mut entity =
                SceneEntity::new(time, FIELD_FRAME, &format!("{}/truth", robot.name), lifetime);
            let (height, colour) = match (t.fallen, t.penalized) {
                (_, true) => (0.5, colour.with_alpha(0.3)),
                (true, false) => (0.15, colour),
                (false, false) => (0.5, colour),
            };
            entity.cubes.push(CubePrimitive {
                pose: Pose::planar(t.x, t.y, height / 2.0, t.theta),
                size: Vector3::new(0.2, 0.3, height),
                color: colour,
            });
            entity.arrows.push(ArrowPrimitive {
                pose: Pose::planar(t.x, t.y, 0.05, t.theta),
                shaft_length: 0.25,
                shaft_diameter: 0.04,
                head_length: 0.1,
                head_diameter: 0.1,
                color: colour,
            });
            entity.texts.push(TextPrimitive {
                pose: Pose::planar(t.x, t.y, 0.8, 0.0),
                billboard: true,
                font_size: 14.0,
                scale_invariant: true,
                color: WHITE,
                text: label.clone(),
            });
            entity.meta("robot", robot.name.clone());
            entity.meta("role", robot.role.clone().unwrap_or_default());
            entity.meta("fallen", t.fallen.to_string());
            entity.meta("penalized", t.penalized.to_string());
            entities.push(entity);
        }
        if let Some(e) = robot.estimate {
            let mut entity =
                SceneEntity::new(time, FIELD_FRAME, &format!("{}/estimate", robot.name), lifetime);
            let faint = colour.with_alpha(if e.lost { 0.25 } else { 0.6 });
            entity.arrows.push(ArrowPrimitive {
                pose: Pose::planar(e.x, e.y, 0.02, e.theta),
                shaft_length: 0.3,
                shaft_diameter: 0.03,
                head_length: 0.12,
                head_diameter: 0.08,
                color: faint,
            });
            if robot.truth.is_none() {
                entity.texts.push(TextPrimitive {
                    pose: Pose::planar(e.x, e.y, 0.6, 0.0),
                    billboard: true,
                    font_size: 14.0,
                    scale_invariant: true,
                    color: WHITE,
                    text: label.clone(),
                });
            }
            if let Some(b) = e.ball {
                let alpha = if b.known { 0.8 } else { 0.25 };
                entity.spheres.push(SpherePrimitive {
                    pose: Pose::planar(b.x, b.y, BALL_DIAMETER / 2.0, 0.0),
                    size: Vector3::new(
                        BALL_DIAMETER * 0.8,
                        BALL_DIAMETER * 0.8,
                        BALL_DIAMETER * 0.8,
                    ),
                    color: colour.with_alpha(alpha),
                });
                let ellipse = covariance_ellipse(b.x, b.y, b.covariance, 2.0);
                entity.lines.push(LinePrimitive::new(
                    LineType::Loop,
                    ellipse,
                    0.02,
                    colour.with_alpha(alpha),
                ));
                entity.meta("ball_confidence", format!("{:.3}", b.confidence));
            }
            if let Some((x, y)) = e.team_ball {
                // A flat ring on the grass: the team's fused ball, apart from the robot's own.
                entity.cylinders.push(foxglove::CylinderPrimitive {
                    pose: Pose::planar(x, y, 0.003, 0.0),
                    size: Vector3::new(TEAM_BALL_DIAMETER, TEAM_BALL_DIAMETER, 0.005),
                    bottom_scale: 1.0,
                    top_scale: 1.0,
                    color: colour.with_alpha(0.35),
                });
                entity.meta("team_ball", format!("{x:.3}, {y:.3}"));
            }
            entity.meta("robot", robot.name.clone());
            entity.meta("pose_confidence", format!("{:.3}", e.confidence));
            entity.meta("lost", e.lost.to_string());
            entities.push(entity);
        }
        if robot.frame_pose().is_some() {
            let mut entity = SceneEntity::new(
                time,
                &format!("{}/head", robot.name),
                &format!("{}/view", robot.name),
                lifetime,
            );
            entity.frame_locked = true;
            let (half, range) = (config.camera_fov / 2.0, config.camera_range);
            let corner = |a: f64| p3(range * a.cos(), range * a.sin(), 0.0);
            let (left, right) = (corner(half), corner(-half));
            let apex = p3(0.0, 0.0, 0.0);
            entity.lines.push(LinePrimitive::new(
                LineType::Loop,
                vec![apex, left, right],
                0.02,
                colour.with_alpha(0.8),
            ));
            entity.triangles.push(TriangleListPrimitive {
                pose: Pose::planar(0.0, 0.0, -HEAD_HEIGHT + 0.01, 0.0),
                points: vec![apex, left, right],
                color: colour.with_alpha(0.12),
                colors: Vec::new(),
                indices: Vec::new(),
            });
            entities.push(entity);
        }
    }
    SceneUpdate { deletions: Vec::new(), entities }
}

/// The frames of every robot drawn: `field` -> `{robot}` (its true pose, or its estimate in a
/// log without truth) -> `{robot}/head` (the head's yaw, at neck height) -> `{robot}/camera`
/// (the head's pitch), and `field` -> `{robot}/estimate` where it has one.
pub fn transforms(robots: &[RobotState], time: Timestamp) -> FrameTransforms {
    let mut transforms = Vec::with_capacity(4 * robots.len());
    let transform =
        |parent: &str, child: String, translation: Vector3, rotation: Quaternion| FrameTransform {
            timestamp: time,
            parent_frame_id: parent.to_owned(),
            child_frame_id: child,
            translation,
            rotation,
        };
    for robot in robots {
        if let Some((x, y, theta, yaw, pitch)) = robot.frame_pose() {
            let name = &robot.name;
            transforms.push(transform(
                FIELD_FRAME,
                name.clone(),
                Vector3::rounded(x, y, 0.0),
                Quaternion::about_z(theta),
            ));
            let head = format!("{name}/head");
            transforms.push(transform(
                name,
                head.clone(),
                Vector3::new(0.0, 0.0, HEAD_HEIGHT),
                Quaternion::about_z(yaw),
            ));
            transforms.push(transform(
                &head,
                format!("{name}/camera"),
                CAMERA_OFFSET,
                Quaternion::about_y(pitch),
            ));
        }
        if let Some(e) = robot.estimate {
            transforms.push(transform(
                FIELD_FRAME,
                format!("{}/estimate", robot.name),
                Vector3::rounded(e.x, e.y, 0.0),
                Quaternion::about_z(e.theta),
            ));
        }
    }
    FrameTransforms { transforms }
}

fn team_name(team: usize) -> &'static str {
    if team == 0 { "home" } else { "away" }
}

fn log_line(time: Timestamp, level: LogLevel, name: &str, message: String) -> Log {
    Log { timestamp: time, level, message, name: name.to_owned(), file: String::new(), line: 0 }
}

/// The log line of a simulator event worth one: game-state changes, goals, balls out, falls,
/// stand-ups, penalties. `None` for the others (kicks, collisions, whistles...).
pub fn event_log(event: &Event) -> Option<Log> {
    let time = Timestamp::from_nanos(event.time.as_nanos());
    let robot = |id: &RobotId| robot_name(*id);
    let line = |level, name: &str, message: String| Some(log_line(time, level, name, message));
    match &event.kind {
        EventKind::GameState { state, first_half } => {
            let half = if *first_half { "first" } else { "second" };
            line(LogLevel::Info, "referee", format!("game state {state:?} ({half} half)"))
        }
        EventKind::Goal { team, score, scorer } => {
            let by = scorer.map(|s| format!(", scored by {}", robot(&s))).unwrap_or_default();
            let message = format!("goal for {} ({}:{}){by}", team_name(*team), score[0], score[1]);
            line(LogLevel::Warning, "referee", message)
        }
        EventKind::BallOut { status, team, .. } => {
            let to = team.map(|t| format!(", {} to play", team_name(t))).unwrap_or_default();
            line(LogLevel::Info, "referee", format!("ball out: {status:?}{to}"))
        }
        EventKind::Fall { robot: id, direction, cause, .. } => line(
            LogLevel::Warning,
            &robot(id),
            format!("{} fell {direction:?} ({cause:?})", robot(id)),
        ),
        EventKind::StandUp { robot: id, success } => {
            let how = if *success { "stood up" } else { "failed to stand up" };
            line(LogLevel::Info, &robot(id), format!("{} {how}", robot(id)))
        }
        EventKind::Penalty { robot: id, penalty, duration } => {
            let time = duration.map(|d| format!(" for {d:.0} s")).unwrap_or_default();
            line(
                LogLevel::Warning,
                &robot(id),
                format!("{} penalized: {penalty:?}{time}", robot(id)),
            )
        }
        EventKind::Unpenalized { robot: id } => {
            line(LogLevel::Info, &robot(id), format!("{} unpenalized", robot(id)))
        }
        _ => None,
    }
}

/// The log line of a robot's change of role.
pub fn role_log(robot: &str, time: Time, role: &str, before: Option<&str>) -> Log {
    let message = match before {
        Some(before) => format!("{robot} role {role} (was {before})"),
        None => format!("{robot} role {role}"),
    };
    log_line(Timestamp::from_nanos(time.as_nanos()), LogLevel::Info, robot, message)
}

/// What to write after a package, on the topics above.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SceneOutput {
    pub field: Option<SceneUpdate>,
    pub objects: Option<SceneUpdate>,
    pub transforms: Option<FrameTransforms>,
    pub logs: Vec<Log>,
    /// On [`plot::PLOT_TOPIC`], with the objects.
    pub plot: Option<LayerPlot>,
}

/// Follows a run's packages — the simulator's ground truth, each robot's world states and
/// planning decisions — and says what to write when: the field first, then the objects and
/// frames at the first package in each [`SceneConfig::period`] of log time (on the ground truth, or on the world
/// states in a log without it), and a log line for each event and change of role.
#[derive(Debug)]
pub struct SceneRecorder {
    config: SceneConfig,
    field: Option<Field>,
    robots: Vec<RobotState>,
    ball: Option<(f64, f64)>,
    truth: bool,
    field_written: bool,
    next_update: Option<Time>,
}

impl SceneRecorder {
    /// A recorder of the robots named (more join as the ground truth shows them). A field the
    /// configuration does not describe validly is not drawn.
    pub fn new(config: SceneConfig, robots: impl IntoIterator<Item = String>) -> SceneRecorder {
        let field = Field::new(config.field.clone(), "the logged field").ok();
        SceneRecorder {
            config,
            field,
            robots: robots.into_iter().map(|name| RobotState::new(&name)).collect(),
            ball: None,
            truth: false,
            field_written: false,
            next_update: None,
        }
    }

    pub fn robots(&self) -> &[RobotState] {
        &self.robots
    }

    /// The robot of this name, added when new.
    fn robot(&mut self, name: &str) -> &mut RobotState {
        let index = match self.robots.iter().position(|r| r.name == name) {
            Some(index) => index,
            None => {
                self.robots.push(RobotState::new(name));
                self.robots.len() - 1
            }
        };
        &mut self.robots[index]
    }

    /// The field (first time only), and the objects and frames when an update is due.
    fn updates(&mut self, time: Time, out: &mut SceneOutput) {
        let stamp = Timestamp::from_nanos(time.as_nanos());
        if !self.field_written {
            self.field_written = true;
            out.field = self.field.as_ref().map(|field| field_update(field, stamp));
        }
        if self.next_update.is_some_and(|next| time < next) {
            return;
        }
        // On a grid of the period, so that packages a little more than a period apart (a
        // ground truth at 30 Hz) still give an update per period on average.
        let period = ((self.config.period.max(1e-3)) * 1e9) as u64;
        let next = (time.as_nanos() / period + 1).saturating_mul(period);
        self.next_update = Some(Time::from_nanos(next));
        out.objects = Some(objects_update(&self.robots, self.ball, &self.config, stamp));
        out.transforms = Some(transforms(&self.robots, stamp));
        out.plot = Some(self.layer_plot(time, stamp));
    }

    /// The rates and head scores of every robot whose layers were heard from.
    fn layer_plot(&mut self, time: Time, stamp: Timestamp) -> LayerPlot {
        let robots = self
            .robots
            .iter_mut()
            .filter_map(|robot| {
                let rates = robot.layers.rates(time);
                let heard = rates.reactive + rates.deliberative + rates.planning > 0.0;
                let estimate = robot.estimate;
                (heard || estimate.is_some()).then(|| RobotPlot {
                    robot: robot.name.clone(),
                    rates,
                    head_goal: robot.layers.head_goal().to_owned(),
                    head: robot.layers.head_scores().to_vec(),
                    pose_confidence: estimate.map_or(0.0, |e| foxglove::round(e.confidence)),
                    ball_confidence: estimate
                        .and_then(|e| e.ball)
                        .map_or(0.0, |b| foxglove::round(b.confidence)),
                })
            })
            .collect();
        LayerPlot { timestamp: stamp, robots }
    }

    /// An output of `robot`'s `layer` at `time` (a planning decision, deliberative scores, a
    /// reactive report), counted for its rate.
    pub fn layer(&mut self, robot: &str, time: Time, layer: LayerKind) {
        self.robot(robot).layers.output(layer, time);
    }

    /// `robot`'s head multiplexer in a reactive report at `time`: its score vector, plotted.
    pub fn head(&mut self, robot: &str, time: Time, head: &MuxReport) {
        let period = self.config.period;
        self.robot(robot).layers.head(head, time, period);
    }

    /// A ground-truth package at `time`: true poses, the ball, the attack signs and events.
    pub fn truth(&mut self, time: Time, truth: &GroundTruth) -> SceneOutput {
        self.truth = true;
        self.config.attack_sign = truth.game.attack_sign;
        self.ball = Some((truth.ball.position.x, truth.ball.position.y));
        for r in &truth.robots {
            self.robot(&robot_name(r.id)).truth = Some(TrueRobot::of(r));
        }
        let mut out = SceneOutput {
            logs: truth.events.iter().filter_map(event_log).collect(),
            ..SceneOutput::default()
        };
        self.updates(time, &mut out);
        out
    }

    /// A world state of `robot` at `time`: its estimates (updates are due on it only in a
    /// log without ground truth).
    pub fn world(&mut self, robot: &str, time: Time, state: &WorldState) -> SceneOutput {
        let team = RobotState::new(robot).team;
        let estimate = Estimate::of(state, self.config.attack_sign[team]);
        self.robot(robot).estimate = Some(estimate);
        let mut out = SceneOutput::default();
        if !self.truth {
            self.updates(time, &mut out);
        }
        out
    }

    /// `robot`'s role at `time` (its planning decision): a log line when it changed.
    pub fn role(&mut self, robot: &str, time: Time, role: &str) -> SceneOutput {
        let state = self.robot(robot);
        if state.role.as_deref() == Some(role) {
            return SceneOutput::default();
        }
        let line = role_log(robot, time, role, state.role.as_deref());
        state.role = Some(role.to_owned());
        SceneOutput { logs: vec![line], ..SceneOutput::default() }
    }

    /// A new file of the log: the field and the objects again at the next package.
    pub fn restart(&mut self) {
        self.field_written = false;
        self.next_update = None;
    }
}

#[cfg(test)]
mod tests;
