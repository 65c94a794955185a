//! Primitive behaviors (paper Table 4): short-term policies that turn a goal and the newest
//! percepts into one command for their resource. They know nothing of the consequences of their
//! actions; the multiplexers choose among them.

use std::f64::consts::FRAC_PI_2;
use std::sync::Arc;

use serde::{Deserialize, Serialize};
use strata_robot::command::{BodyCommand, BodyMotion, HeadCommand, HeadMotion, WholeBodyCommand};
use strata_robot::control::active_vision::GazeCandidate;
pub use strata_robot::control::primitives::{HeadSender, Stand, StandUp, WalkSender};
use strata_robot::control::primitives::{StandPrimitive, StandUpPrimitive, names};
use strata_robot::control::reactive::{PrimitiveBehavior, ReactiveInput};
use strata_robot::geometry::{Point, Pose, Robot, Velocity, normalize_angle};
use strata_robot::platform::{Footprint, HeadAngles, SpecialMotion};
use strata_robot::world::WorldState;
use strata_runtime::Time;

use crate::field::TeamField;
use crate::goals::{BodyGoal, HeadGoal, Kick, WholeBodyGoal};
use crate::motions;
use crate::situation::{ball, head_goal_objects, obstacle_ahead, obstacles};

strata_robot::primitive_ids! {
    /// The head's primitive behaviors (Table 4), as activation policies name them.
    pub enum HeadPrimitive {
        SearchObjectEllipse => "search object ellipse",
        ObjectTracking => "object tracking",
        LookAtTarget => "look at target",
    }
}

strata_robot::primitive_ids! {
    /// The body's primitive behaviors (Table 4), as activation policies name them and the
    /// deliberative layer deactivates them.
    pub enum BodyPrimitive {
        GoToPosition => "go to position",
        GoToBall => "go to ball",
        KickBall => "kick ball",
        AvoidCollision => "avoid collision",
        Stand => names::STAND,
    }
}

strata_robot::primitive_ids! {
    /// The primitive behaviors that drive head and body together (Table 4).
    pub enum WholeBodyPrimitive {
        Dribbling => "dribbling",
        StandUp => names::STAND_UP,
        Fall => "fall",
        Dive => "dive",
    }
}

impl StandPrimitive for BodyPrimitive {
    const STAND: BodyPrimitive = BodyPrimitive::Stand;
}

impl StandUpPrimitive for WholeBodyPrimitive {
    const STAND_UP: WholeBodyPrimitive = WholeBodyPrimitive::StandUp;
}

/// The robot's motion abilities as the primitives assume them (NAO-like defaults, matching the
/// simulator's).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MotionModel {
    pub max_forward: f64,
    pub max_sideways: f64,
    pub max_turn: f64,
    pub head_speed: f64,
    pub camera_height: f64,
    /// The ball must be in this box (robot frame) for a kick to hit it.
    pub kick_reach_x: [f64; 2],
    pub kick_reach_y: [f64; 2],
    /// Alignment needed between the kick direction and the target, rad.
    pub kick_alignment: f64,
    /// Where the forward kick and the pass send the ball, left of where [`Kick::direction`]
    /// says, rad: the approach turns the robot so the ball goes to the target anyway.
    pub kick_deviation: [f64; 2],
    /// Distance behind the ball the approach aims at, m.
    pub approach_distance: f64,
    /// The fastest forward walk at the kicking pose, m/s: faster, a walking foot reaches the
    /// ball before the kick does. Within the approach's last 0.8 m the limit rises by
    /// `approach_speed_gain` for every metre still to walk to the kicking pose.
    pub approach_speed: f64,
    /// 1/s.
    pub approach_speed_gain: f64,
    /// How far behind the ball the torso lines up before dribbling walks through it, m; 0:
    /// dribbling walks straight at a point beyond the ball from wherever the robot is (a 2D
    /// ball rolls off whatever touches it). A biped that walks into the ball from the side
    /// pushes it off the line, so the T1 lines up first: [`dribble_walk`].
    pub dribble_behind: f64,
    /// While dribbling, the head looks up toward the target for `[1]` s of every `[0]` s, so
    /// that landmarks keep the pose (world modeling tracks the ball through the glance); 0:
    /// it watches the ball throughout (a camera that sees the ball and the landmarks at once).
    pub dribble_glance: [f64; 2],
    /// How far a dribble turns from its target to pass a robot in its way, rad
    /// ([`dodge_target`]); 0: it dribbles straight at the target whoever is there.
    pub dribble_dodge: f64,
    /// An obstacle closer than this, straight ahead, must be avoided, m.
    pub collision_distance: f64,
    /// How long each walk command lasts if no newer one replaces it, s.
    pub walk_command_duration: f64,
    /// Objects nearer than this are looked at from above, m: farther ones with the head level.
    pub near_gaze_range: f64,
    /// How far above a near object's direction the gaze points, rad (it then sits in the
    /// image's lower part, and more of the ground beyond it in view).
    pub near_gaze_offset: f64,
    /// The head pitch the primitives order, rad: [up, down].
    pub head_pitch_limits: [f64; 2],
    /// The ball search's head pitch, rad: [centre, amplitude] of its ellipse (a taller robot
    /// looks further down to see the ground at its feet).
    pub ball_search_pitch: [f64; 2],
    /// The camera's vertical field of view, rad, less a margin at each edge where objects are
    /// often missed: with the camera height and the gaze's pitch it says which stretch of
    /// ground a gaze shows ([`MotionModel::footprint`]). 0: not modelled (the 2D simulator's
    /// camera sees everything within its range).
    pub vertical_fov: f64,
}

impl Default for MotionModel {
    fn default() -> Self {
        MotionModel {
            max_forward: 0.25,
            max_sideways: 0.15,
            max_turn: 1.2,
            head_speed: 3.0,
            camera_height: 0.5,
            kick_reach_x: [0.08, 0.24],
            kick_reach_y: [-0.1, 0.1],
            kick_alignment: 0.25,
            kick_deviation: [0.0, 0.0],
            approach_distance: 0.16,
            approach_speed: 0.15,
            approach_speed_gain: 0.0,
            dribble_behind: 0.0,
            dribble_glance: [0.0, 0.0],
            dribble_dodge: 0.0,
            collision_distance: 0.45,
            walk_command_duration: 0.4,
            near_gaze_range: 0.6,
            near_gaze_offset: 0.6,
            head_pitch_limits: [-0.6, 0.5],
            ball_search_pitch: [0.15, 0.2],
            vertical_fov: 0.0,
        }
    }
}

impl MotionModel {
    /// The Booster T1's (`crates/soccer/bodies/booster-t1.toml`), for rcssservermj.
    pub fn booster_t1() -> MotionModel {
        // Embedded and checked by a test: it cannot fail at run time.
        toml::from_str(BOOSTER_T1).unwrap_or_default()
    }
}

impl MotionModel {
    /// Where `kick` sends the ball, relative to the robot's heading, rad.
    pub fn kick_direction(&self, kick: Kick) -> f64 {
        let deviation = match kick {
            Kick::Forward => self.kick_deviation[0],
            Kick::Pass => self.kick_deviation[1],
            Kick::SideLeft | Kick::SideRight => 0.0,
        };
        kick.direction() + deviation
    }

    /// The stretch of ground a gaze at something `range` metres away shows (from the camera's
    /// foot, ignoring the torso's lean), for active vision to predict what each gaze would
    /// see. `None` when the vertical field of view is not modelled.
    pub fn footprint(&self, range: f64) -> Option<Footprint> {
        if self.vertical_fov <= 0.0 {
            return None;
        }
        let pitch = gaze_pitch(self, range);
        let half = self.vertical_fov / 2.0;
        // Where an edge of the image meets the ground, by its angle below the horizon; an
        // edge at or above the horizon never does (f64::MAX: a finite "beyond any range").
        let ground = |depression: f64| {
            if depression >= FRAC_PI_2 {
                0.0
            } else if depression > 0.0 {
                self.camera_height / depression.tan()
            } else {
                f64::MAX
            }
        };
        let far = ground(pitch - half);
        Some(Footprint { near: ground(pitch + half).min(far), far })
    }
}

const BOOSTER_T1: &str = include_str!("../bodies/booster-t1.toml");

type Input<'a, 'b> = ReactiveInput<'a, WorldState>;

fn limit(v: f64, max: f64) -> f64 {
    v.clamp(-max, max)
}

/// An omnidirectional walking controller: turn toward far targets, side-step near ones, and
/// settle at the final heading (`heading`, relative to the robot).
pub fn walk_velocity(model: &MotionModel, target: Point<Robot>, heading: f64) -> Velocity {
    let distance = target.range();
    let bearing = target.bearing();
    if distance > 0.5 {
        let turn = limit(2.0 * bearing, model.max_turn);
        // Walk forward only once roughly facing the target.
        let forward = model.max_forward * (1.0 - (bearing.abs() / 1.0)).clamp(0.0, 1.0);
        Velocity::new(forward, limit(0.3 * target.y, model.max_sideways), turn)
    } else {
        let k = 1.5;
        Velocity::new(
            limit(k * target.x, model.max_forward),
            limit(k * target.y, model.max_sideways),
            limit(2.0 * heading, model.max_turn),
        )
    }
}

/// Head angles that put a robot-frame point in the middle of the image.
fn gaze_at(model: &MotionModel, point: Point<Robot>) -> HeadAngles {
    HeadAngles { yaw: point.bearing().clamp(-2.0, 2.0), pitch: gaze_pitch(model, point.range()) }
}

/// The head pitch that keeps an object `range` metres away in view.
fn gaze_pitch(model: &MotionModel, range: f64) -> f64 {
    let range = range.max(0.05);
    // Look down at near objects so they stay above the lower edge of the image.
    let pitch = if range < model.near_gaze_range {
        (model.camera_height / range).atan() - model.near_gaze_offset
    } else {
        0.0
    };
    let [up, down] = model.head_pitch_limits;
    pitch.clamp(up, down)
}

fn head_command(model: &MotionModel, target: HeadAngles) -> HeadCommand {
    HeadCommand::NonQueue(HeadMotion { target, max_speed: model.head_speed })
}

// ---------------------------------------------------------------------------------------------
// Head

/// Search object ellipse: a predefined head path whose shape depends on the object, followed
/// with the queue policy (the next point is queued when actuation announces the current one is
/// about to be reached).
#[derive(Debug)]
pub struct SearchObjectEllipse {
    model: Arc<MotionModel>,
    phase: usize,
    started: bool,
}

impl SearchObjectEllipse {
    pub fn new(model: Arc<MotionModel>) -> Self {
        SearchObjectEllipse { model, phase: 0, started: false }
    }

    const POINTS: usize = 8;

    fn point(model: &MotionModel, goal: &HeadGoal, phase: usize) -> HeadAngles {
        // The ball lies on the ground near the robot: a low, wide ellipse. Landmarks stand at
        // the field's edges: a flatter, wider one.
        let [ball_centre, ball_amplitude] = model.ball_search_pitch;
        let (yaw_amplitude, pitch_centre, pitch_amplitude) = match goal {
            HeadGoal::ObserveBall => (1.6, ball_centre, ball_amplitude),
            _ => (1.9, 0.0, 0.08),
        };
        let angle = phase as f64 / Self::POINTS as f64 * std::f64::consts::TAU;
        HeadAngles {
            yaw: yaw_amplitude * angle.sin(),
            pitch: pitch_centre + pitch_amplitude * angle.cos(),
        }
    }
}

impl PrimitiveBehavior<HeadGoal, HeadCommand, WorldState> for SearchObjectEllipse {
    fn id(&self) -> HeadPrimitive {
        HeadPrimitive::SearchObjectEllipse
    }

    fn activate(&mut self, _: &HeadGoal, input: &Input<'_, '_>) {
        // Start the ellipse where the head already is, not at a fixed corner.
        let yaw = input.percepts.head.yaw;
        self.phase = (0..Self::POINTS)
            .min_by(|a, b| {
                let pa = Self::point(&self.model, &HeadGoal::ObserveBall, *a).yaw;
                let pb = Self::point(&self.model, &HeadGoal::ObserveBall, *b).yaw;
                (pa - yaw).abs().total_cmp(&(pb - yaw).abs())
            })
            .unwrap_or(0);
        self.started = false;
    }

    fn step(&mut self, goal: &HeadGoal, input: &Input<'_, '_>) -> Option<HeadCommand> {
        let due = !self.started
            || input.actuation.finishing.contains(&strata_robot::command::Resource::Head);
        if !due {
            return None;
        }
        self.started = true;
        self.phase = (self.phase + 1) % Self::POINTS;
        Some(HeadCommand::Queue(HeadMotion {
            target: Self::point(&self.model, goal, self.phase),
            max_speed: self.model.head_speed * 0.6,
        }))
    }
}

/// Object tracking: keep the goal's object in the middle of the image, predicting a moving
/// object a little ahead.
#[derive(Debug)]
pub struct ObjectTracking {
    model: Arc<MotionModel>,
    sender: HeadSender,
}

impl ObjectTracking {
    pub fn new(model: Arc<MotionModel>) -> Self {
        ObjectTracking { model, sender: HeadSender::default() }
    }
}

impl PrimitiveBehavior<HeadGoal, HeadCommand, WorldState> for ObjectTracking {
    fn id(&self) -> HeadPrimitive {
        HeadPrimitive::ObjectTracking
    }

    fn activate(&mut self, _: &HeadGoal, _: &Input<'_, '_>) {
        self.sender.reset();
    }

    fn step(&mut self, goal: &HeadGoal, input: &Input<'_, '_>) -> Option<HeadCommand> {
        let world = input.world?;
        let object = *head_goal_objects(world, goal).first()?;
        let lookahead = 0.15;
        let target = match object.velocity {
            Some(v) => object.position + v * lookahead,
            None => object.position,
        };
        self.sender.send(gaze_at(&self.model, target), self.model.head_speed)
    }
}

/// Look at target: a direction chosen by the goal — the point from which several objects are
/// seen together, a partner's reported position, the nearest point of a field line.
#[derive(Debug)]
pub struct LookAtTarget {
    model: Arc<MotionModel>,
    field: Arc<TeamField>,
    sender: HeadSender,
}

impl LookAtTarget {
    pub fn new(model: Arc<MotionModel>, field: Arc<TeamField>) -> Self {
        LookAtTarget { model, field, sender: HeadSender::default() }
    }
}

/// How far along its direction a gaze at several objects together aims, m (it sets the
/// head's pitch).
pub const TOGETHER_RANGE: f64 = 2.0;

/// The point of the field's line `line` (index in [`strata_spl::Field::lines`]) nearest a robot
/// at `pose` (team frame), in the robot frame: where a look at the line aims.
pub fn nearest_point_of_line(field: &TeamField, line: usize, pose: Pose) -> Option<Point<Robot>> {
    let segment = field.field.lines().get(line)?;
    let a = field.to_team(segment.start.x, segment.start.y);
    let b = field.to_team(segment.end.x, segment.end.y);
    let closest = strata_robot::geometry::Segment::new(a, b).closest_point(pose.position());
    Some(pose.to_robot(closest))
}

/// Where a head goal that is about a place rather than a tracked object looks.
pub fn look_target(
    field: &TeamField,
    world: &WorldState,
    goal: &HeadGoal,
    fov: f64,
) -> Option<Point<Robot>> {
    let pose = world.pose.pose;
    match goal {
        HeadGoal::ObserveTogether { objects } => {
            let ids: Vec<_> = head_goal_objects(world, goal).iter().map(|o| o.id).collect();
            if ids.len() != objects.len() {
                return None;
            }
            let candidate = GazeCandidate::covering(world, &ids, fov * 0.8, "together")?;
            Some(Point::from_polar(TOGETHER_RANGE, candidate.direction))
        }
        HeadGoal::ObservePartner { position, .. } | HeadGoal::ObserveReferee { position } => {
            Some(pose.to_robot(*position))
        }
        HeadGoal::ObserveFieldLine { line } => {
            nearest_point_of_line(field, usize::from(*line), pose)
        }
        HeadGoal::ObserveGoal { .. } => {
            let posts = head_goal_objects(world, goal);
            let n = posts.len() as f64;
            let (x, y) =
                posts.iter().fold((0.0, 0.0), |(x, y), o| (x + o.position.x, y + o.position.y));
            let middle = (n > 0.0).then(|| Point::<Robot>::new(x / n, y / n))?;
            // Centred on the posts' bearings where they fit in one image (as the gaze
            // candidate was judged), else between them.
            let direction =
                GazeCandidate::covering_direction(world, posts.iter().map(|o| o.id), fov * 0.8)
                    .unwrap_or_else(|| middle.bearing());
            Some(Point::from_polar(middle.range(), direction))
        }
        _ => head_goal_objects(world, goal).first().map(|o| o.position),
    }
}

impl PrimitiveBehavior<HeadGoal, HeadCommand, WorldState> for LookAtTarget {
    fn id(&self) -> HeadPrimitive {
        HeadPrimitive::LookAtTarget
    }

    fn activate(&mut self, _: &HeadGoal, _: &Input<'_, '_>) {
        self.sender.reset();
    }

    fn step(&mut self, goal: &HeadGoal, input: &Input<'_, '_>) -> Option<HeadCommand> {
        let world = input.world?;
        let target = look_target(&self.field, world, goal, 1.06)?;
        self.sender.send(gaze_at(&self.model, target), self.model.head_speed)
    }
}

// ---------------------------------------------------------------------------------------------
// Body

/// Go to position: walk to a field pose (or turn in place toward a target).
#[derive(Debug)]
pub struct GoToPosition {
    model: Arc<MotionModel>,
    sender: WalkSender,
}

impl GoToPosition {
    pub fn new(model: Arc<MotionModel>) -> Self {
        GoToPosition { model, sender: WalkSender::default() }
    }
}

/// The pose a body goal walks to, relative to the robot, with its final heading.
pub fn body_target(world: &WorldState, goal: &BodyGoal) -> Option<(Point<Robot>, f64)> {
    let pose = world.pose.pose;
    match goal {
        BodyGoal::GoToPosition { pose: target } => {
            Some((pose.to_robot(target.position()), normalize_angle(target.theta - pose.theta)))
        }
        BodyGoal::ObserveTarget { target } => {
            Some((Point::new(0.0, 0.0), pose.to_robot(*target).bearing()))
        }
        _ => None,
    }
}

impl PrimitiveBehavior<BodyGoal, BodyCommand, WorldState> for GoToPosition {
    fn id(&self) -> BodyPrimitive {
        BodyPrimitive::GoToPosition
    }

    fn activate(&mut self, _: &BodyGoal, _: &Input<'_, '_>) {
        self.sender.reset();
    }

    fn step(&mut self, goal: &BodyGoal, input: &Input<'_, '_>) -> Option<BodyCommand> {
        let (target, heading) = body_target(input.world?, goal)?;
        let arrived = target.range() < 0.08 && heading.abs() < 0.15;
        let velocity =
            if arrived { Velocity::ZERO } else { walk_velocity(&self.model, target, heading) };
        if arrived {
            return self
                .sender
                .send(input.now, velocity, self.model.walk_command_duration)
                .map(|_| BodyCommand::NonQueue(BodyMotion::Stand));
        }
        self.sender.send(input.now, velocity, self.model.walk_command_duration)
    }
}

/// Where to stand to kick the ball toward `target` with `kick`: behind the ball, so the kick's
/// direction points at the target.
pub fn approach_pose(
    model: &MotionModel,
    world: &WorldState,
    kick: Kick,
    target: Point<strata_robot::Global>,
) -> Option<(Point<Robot>, f64)> {
    let ball = ball(world)?;
    let pose = world.pose.pose;
    let target_robot = pose.to_robot(target);
    let shot = (target_robot - ball.robot).angle();
    // The robot's heading such that the kick direction points along the shot.
    let heading = normalize_angle(shot - model.kick_direction(kick));
    let behind =
        Point::<Robot>::from_polar(model.approach_distance + 0.04, heading + std::f64::consts::PI);
    // Sideways, the ball ends in the middle of the kick's reach (the T1's is off-centre).
    let lateral = (model.kick_reach_y[0] + model.kick_reach_y[1]) / 2.0;
    let (sin, cos) = heading.sin_cos();
    let stand = Point::new(
        ball.robot.x + behind.x + sin * lateral,
        ball.robot.y + behind.y - cos * lateral,
    );
    Some((stand, heading))
}

/// Whether the ball is where `kick` hits it, with the kick pointing at the target.
pub fn kickable(
    model: &MotionModel,
    world: &WorldState,
    kick: Kick,
    target: Point<strata_robot::Global>,
) -> bool {
    let Some(ball) = ball(world).filter(|b| b.known && !b.from_team) else { return false };
    let in_reach = (model.kick_reach_x[0]..=model.kick_reach_x[1]).contains(&ball.robot.x)
        && (model.kick_reach_y[0]..=model.kick_reach_y[1]).contains(&ball.robot.y);
    let target_robot = world.pose.pose.to_robot(target);
    let shot = (target_robot - ball.robot).angle();
    in_reach && normalize_angle(shot - model.kick_direction(kick)).abs() < model.kick_alignment
}

/// Go to ball: like go to position, but ends where the ball can be kicked toward the target.
#[derive(Debug)]
pub struct GoToBall {
    model: Arc<MotionModel>,
    sender: WalkSender,
}

impl GoToBall {
    pub fn new(model: Arc<MotionModel>) -> Self {
        GoToBall { model, sender: WalkSender::default() }
    }
}

impl PrimitiveBehavior<BodyGoal, BodyCommand, WorldState> for GoToBall {
    fn id(&self) -> BodyPrimitive {
        BodyPrimitive::GoToBall
    }

    fn activate(&mut self, _: &BodyGoal, _: &Input<'_, '_>) {
        self.sender.reset();
    }

    fn step(&mut self, goal: &BodyGoal, input: &Input<'_, '_>) -> Option<BodyCommand> {
        let BodyGoal::GoToBallAndKick { kick, target } = goal else { return None };
        let world = input.world?;
        let ball = ball(world)?;
        let (stand, heading) = approach_pose(&self.model, world, *kick, *target)?;
        // Far away: head straight for the ball; near: circle to the kicking pose without
        // touching the ball.
        let velocity = if ball.robot.range() > 0.8 {
            walk_velocity(&self.model, ball.robot, ball.robot.bearing())
        } else {
            let mut v = walk_velocity(&self.model, stand, heading);
            let limit = self.model.approach_speed + self.model.approach_speed_gain * stand.range();
            v.vx = v.vx.min(limit);
            v
        };
        self.sender.send(input.now, velocity, self.model.walk_command_duration)
    }
}

/// Kick ball: the kick sequence chosen by the deliberative layer's parameter.
#[derive(Debug, Default)]
pub struct KickBall;

impl PrimitiveBehavior<BodyGoal, BodyCommand, WorldState> for KickBall {
    fn id(&self) -> BodyPrimitive {
        BodyPrimitive::KickBall
    }

    fn step(&mut self, goal: &BodyGoal, input: &Input<'_, '_>) -> Option<BodyCommand> {
        let BodyGoal::GoToBallAndKick { kick, .. } = goal else { return None };
        if input.actuation.is_busy(strata_robot::command::ResourceGroup::Body) {
            return None;
        }
        Some(BodyCommand::Special(motions::kick(kick.sequence())))
    }
}

/// Avoid collision: step aside from a robot right in front.
#[derive(Debug)]
pub struct AvoidCollision {
    model: Arc<MotionModel>,
    sender: WalkSender,
}

impl AvoidCollision {
    pub fn new(model: Arc<MotionModel>) -> Self {
        AvoidCollision { model, sender: WalkSender::default() }
    }
}

impl PrimitiveBehavior<BodyGoal, BodyCommand, WorldState> for AvoidCollision {
    fn id(&self) -> BodyPrimitive {
        BodyPrimitive::AvoidCollision
    }

    fn activate(&mut self, _: &BodyGoal, _: &Input<'_, '_>) {
        self.sender.reset();
    }

    fn step(&mut self, _: &BodyGoal, input: &Input<'_, '_>) -> Option<BodyCommand> {
        let obstacle = obstacle_ahead(input.world?, self.model.collision_distance, 0.7)?;
        let away = if obstacle.y > 0.0 { -1.0 } else { 1.0 };
        let velocity = Velocity::new(-0.05, away * self.model.max_sideways, 0.0);
        self.sender.send(input.now, velocity, self.model.walk_command_duration)
    }
}

// ---------------------------------------------------------------------------------------------
// Head and body

/// Dribbling: walk the ball toward the target while the head keeps it in view.
#[derive(Debug)]
pub struct Dribbling {
    model: Arc<MotionModel>,
    walk: WalkSender,
    head: HeadSender,
    /// The last step walked through the ball (lined up behind it): staying lined up takes less
    /// than lining up.
    through: bool,
    /// When this dribble started: the glances' clock.
    since: Option<Time>,
    /// The side (+1 left, -1 right) the dribble passes a robot in its way on, while it does.
    dodge: Option<f64>,
}

impl Dribbling {
    pub fn new(model: Arc<MotionModel>) -> Self {
        Dribbling {
            model,
            walk: WalkSender::default(),
            head: HeadSender::default(),
            through: false,
            since: None,
            dodge: None,
        }
    }
}

/// A robot within this of the ball, m, along the line to the target (from a little behind the
/// ball) and within `DODGE_ACROSS` of it is in the dribble's way.
const DODGE_AHEAD: f64 = 1.5;
const DODGE_ACROSS: f64 = 0.7;
/// Where a dribble aims (robot frame) with robots (`others`, robot frame) about: `angle` off
/// the line to `target` past the nearest one in the way, on the side it was passed on before
/// (`side`) or else the side away from it; straight at `target` when none is. Two T1s walking
/// through the ball from either side push it between them and fall over each other.
pub fn dodge_target(
    ball: Point<Robot>,
    target: Point<Robot>,
    others: impl Iterator<Item = Point<Robot>>,
    side: Option<f64>,
    angle: f64,
) -> (Point<Robot>, Option<f64>) {
    if angle <= 0.0 {
        return (target, None);
    }
    let line = (target - ball).normalized();
    let in_the_way = others
        .map(|o| o - ball)
        .filter(|d| {
            let along = d.dot(line);
            along > -0.2 && along < DODGE_AHEAD && line.cross(*d).abs() < DODGE_ACROSS
        })
        .min_by(|a, b| a.dot(line).total_cmp(&b.dot(line)));
    let Some(d) = in_the_way else { return (target, None) };
    let side = side.unwrap_or(if line.cross(d) > 0.0 { -1.0 } else { 1.0 });
    let aim = ball + line.rotated(side * angle) * (target - ball).norm();
    (aim, Some(side))
}

/// Where a lined-up dribble keeps the ball: ahead of the torso by at most `reach`, m, within
/// `across` of its centre line, m, with the target within `turn` of the heading, rad. Lining
/// up takes the tight one, staying lined up the loose one: the ball rolls ahead and sideways
/// with each step, and a robot that stopped to line up again at every push would hardly move
/// it. Tuned on the T1 (crates/rcssmj/tests/dribble.rs).
struct Corridor {
    reach: f64,
    across: f64,
    turn: f64,
}

const LINE_UP: Corridor = Corridor { reach: 0.6, across: 0.12, turn: 0.5 };
const STAY_LINED_UP: Corridor = Corridor { reach: 1.0, across: 0.25, turn: 0.8 };

/// How far beside the ball a robot on the wrong side of it walks around it, m (the T1's feet
/// are 0.2 m apart).
const ROUND_BALL: f64 = 0.45;

/// The walk that dribbles the ball (robot frame) toward `target` (robot frame) with a body
/// that lines up first (`model.dribble_behind` > 0), and whether it walks through the ball:
/// lined up, it walks at full speed along the line to the target, side-stepping to keep the
/// ball in front and slowing the farther it is off; otherwise it goes to the spot behind the
/// ball on that line, as the approach to a kick does.
pub fn dribble_walk(
    model: &MotionModel,
    ball: Point<Robot>,
    target: Point<Robot>,
    through: bool,
) -> (Velocity, bool) {
    let line = (target - ball).normalized();
    let heading = line.angle();
    let corridor = if through { STAY_LINED_UP } else { LINE_UP };
    let lined_up = ball.x > 0.05
        && ball.x < corridor.reach
        && ball.y.abs() < corridor.across
        && heading.abs() < corridor.turn;
    if lined_up {
        let slow = (1.0 - ball.y.abs() / (STAY_LINED_UP.across + 0.1)).max(0.0)
            * (1.0 - heading.abs() / STAY_LINED_UP.turn).max(0.0);
        let velocity = Velocity::new(
            model.max_forward * slow,
            limit(1.5 * ball.y, model.max_sideways),
            limit(2.0 * heading, model.max_turn),
        );
        return (velocity, true);
    }
    // The robot's place relative to the ball: how far along the line toward the target, and
    // on which side of it.
    let robot = Point::<Robot>::ORIGIN - ball;
    let along = robot.dot(line);
    let velocity = if along > -model.dribble_behind / 2.0 && ball.range() < 1.5 {
        // Between the ball and the target or beside the ball: round it, a step to the side of
        // the line the robot is on, so the walk does not push the ball back.
        let side = if line.cross(robot) >= 0.0 { 1.0 } else { -1.0 };
        let perpendicular = line.rotated(FRAC_PI_2) * side;
        let waypoint = ball + perpendicular * ROUND_BALL - line * model.dribble_behind;
        walk_velocity(model, waypoint, heading)
    } else if ball.range() > 0.8 {
        walk_velocity(model, ball, ball.bearing())
    } else {
        walk_velocity(model, ball - line * model.dribble_behind, heading)
    };
    (velocity, false)
}

impl PrimitiveBehavior<WholeBodyGoal, WholeBodyCommand, WorldState> for Dribbling {
    fn id(&self) -> WholeBodyPrimitive {
        WholeBodyPrimitive::Dribbling
    }

    fn activate(&mut self, _: &WholeBodyGoal, input: &Input<'_, '_>) {
        self.walk.reset();
        self.head.reset();
        self.through = false;
        self.since = Some(input.now);
        self.dodge = None;
    }

    fn step(&mut self, goal: &WholeBodyGoal, input: &Input<'_, '_>) -> Option<WholeBodyCommand> {
        let WholeBodyGoal::GoToBallAndDribble { target } = goal else { return None };
        let world = input.world?;
        let ball = ball(world)?;
        let target_robot = world.pose.pose.to_robot(*target);
        let others = obstacles(world).map(|o| o.position);
        let dodge_angle = self.model.dribble_dodge;
        let (target_robot, dodge) =
            dodge_target(ball.robot, target_robot, others, self.dodge, dodge_angle);
        self.dodge = dodge;
        let velocity = if self.model.dribble_behind > 0.0 {
            let (velocity, through) =
                dribble_walk(&self.model, ball.robot, target_robot, self.through);
            self.through = through;
            velocity
        } else {
            let through = (target_robot - ball.robot).normalized();
            // Aim a little behind the ball on the line to the target: walking there pushes it.
            let aim = ball.robot + through * 0.1;
            walk_velocity(&self.model, aim, through.angle())
        };
        let duration = self.model.walk_command_duration;
        let [period, glance] = self.model.dribble_glance;
        let into = self.since.map_or(0.0, |t| (input.now - t).as_secs_f64());
        let gaze = if period > 0.0 && into % period >= period - glance {
            // Level, toward the target: the goal and the lines beyond the ball.
            HeadAngles { yaw: target_robot.bearing().clamp(-2.0, 2.0), pitch: 0.0 }
        } else {
            gaze_at(&self.model, ball.robot)
        };
        let head_moved = self.head.send(gaze, self.model.head_speed).is_some();
        // A coordinated command carries both resources: when only the head has to move, the
        // walk goes with it unchanged (within the walk sender's tolerance) rather than the
        // head waiting for the walk to change.
        let body = match self.walk.send(input.now, velocity, duration) {
            Some(body) => body,
            None if head_moved => BodyCommand::NonQueue(BodyMotion::Walk { velocity, duration }),
            None => return None,
        };
        Some(WholeBodyCommand::Coordinated { head: head_command(&self.model, gaze), body })
    }
}

/// Fall: relax the joints and protect the robot once instability is detected.
#[derive(Debug, Default)]
pub struct Fall;

impl PrimitiveBehavior<WholeBodyGoal, WholeBodyCommand, WorldState> for Fall {
    fn id(&self) -> WholeBodyPrimitive {
        WholeBodyPrimitive::Fall
    }

    fn step(&mut self, goal: &WholeBodyGoal, _: &Input<'_, '_>) -> Option<WholeBodyCommand> {
        let sequence = match goal {
            WholeBodyGoal::Fall { sequence } => *sequence,
            _ => 0,
        };
        Some(WholeBodyCommand::Special { motion: SpecialMotion::fall(sequence) })
    }
}

/// Dive: the goalkeeper throws itself to the side the ball will cross.
#[derive(Debug, Default)]
pub struct Dive;

/// Where a moving ball will cross the robot's lateral axis (y at x = 0) and when, if it comes
/// toward the robot.
pub fn ball_crossing(world: &WorldState) -> Option<(f64, f64)> {
    let b = ball(world)?;
    let v = b.velocity?;
    if v.x >= -0.1 || b.robot.x <= 0.0 {
        return None;
    }
    let t = -b.robot.x / v.x;
    Some((b.robot.y + v.y * t, t))
}

impl PrimitiveBehavior<WholeBodyGoal, WholeBodyCommand, WorldState> for Dive {
    fn id(&self) -> WholeBodyPrimitive {
        WholeBodyPrimitive::Dive
    }

    fn step(&mut self, _: &WholeBodyGoal, input: &Input<'_, '_>) -> Option<WholeBodyCommand> {
        let (y, _) = ball_crossing(input.world?)?;
        // Catalogue: 0 left, 1 right, 2 block (both sides, for balls straight at the keeper).
        let sequence = if y.abs() < 0.15 {
            2
        } else if y > 0.0 {
            0
        } else {
            1
        };
        Some(WholeBodyCommand::Special { motion: motions::dive(sequence) })
    }
}

/// Pose helper for behaviors: facing a point from a position.
pub fn facing(from: Point<strata_robot::Global>, toward: Point<strata_robot::Global>) -> Pose {
    Pose::new(from.x, from.y, (toward - from).angle())
}

#[cfg(test)]
mod tests {
    use super::*;
    use strata_robot::control::reactive::{ActuationStatus, Stability};
    use strata_robot::percept::Percepts;
    use strata_robot::world::{PosePrior, WorldCommand, WorldModel};
    use strata_runtime::Time;

    use crate::world_config::{BALL, world_config};

    #[test]
    fn a_t1_gaze_shows_near_or_far_ground_and_a_nao_gaze_all_of_it() {
        let t1 = MotionModel::booster_t1();
        // Looking at the ball at its feet: the ball is in the image, the field beyond 3 m not.
        let Some(down) = t1.footprint(0.25) else { panic!("the T1 models its camera") };
        assert!(down.near < 0.25 && down.far > 0.5 && down.far < 3.0, "{down:?}");
        // Looking at a far landmark: the head is level and nothing within 1.5 m is seen.
        let Some(level) = t1.footprint(10.0) else { panic!("the T1 models its camera") };
        assert!(level.near > 1.5 && level.far == f64::MAX, "{level:?}");
        // Looking at two objects together: in between.
        let Some(together) = t1.footprint(TOGETHER_RANGE) else { panic!("modelled") };
        assert!(together.near > down.near && together.near < level.near, "{together:?}");
        assert_eq!(MotionModel::default().footprint(0.25), None);
    }

    #[test]
    fn the_t1_looks_down_at_a_ball_at_its_feet_and_the_nao_as_before() {
        let t1: MotionModel = toml::from_str(BOOSTER_T1).expect("the shipped T1 body parses");
        assert_eq!(MotionModel::booster_t1(), t1);
        assert!(t1.camera_height > 1.0 && t1.kick_reach_x[0] > 0.1);
        // A ball 0.25 m ahead: the T1 pitches its head far down, the NAO as it always did.
        let at_feet = Point::new(0.25, 0.0);
        let t1_pitch = gaze_at(&t1, at_feet).pitch;
        let nao = MotionModel::default();
        assert!(t1_pitch > 0.9, "{t1_pitch}");
        let nao_expected = ((0.5f64 / 0.25).atan() - 0.6).min(0.5);
        assert!((gaze_at(&nao, at_feet).pitch - nao_expected).abs() < 1e-12);
        assert_eq!(gaze_at(&nao, Point::new(2.0, 0.0)).pitch, 0.0);
        // The T1's ball search reaches down to its feet: the lowest point plus half the image
        // (29 degrees) sees the ground 0.3 m ahead of a 1.1 m camera.
        let lowest = (0..SearchObjectEllipse::POINTS)
            .map(|k| SearchObjectEllipse::point(&t1, &HeadGoal::ObserveBall, k).pitch)
            .fold(f64::NEG_INFINITY, f64::max);
        assert!((t1.camera_height / (lowest + 0.506).tan()) < 0.3, "{lowest}");
    }

    /// The approach ends with the ball inside the kick's reach, well clear of its edges (the
    /// T1's approach once ended 1 cm beyond it, where the walk barely moves the robot).
    #[test]
    fn the_approach_ends_with_the_ball_within_reach() {
        for model in [MotionModel::default(), MotionModel::booster_t1()] {
            let world = world_with_ball(Point::new(1.0, 0.0));
            let target = world.pose.pose.to_global(Point::new(5.0, 0.0));
            let Some((stand, heading)) = approach_pose(&model, &world, Kick::Forward, target)
            else {
                panic!("the ball is known")
            };
            let ball_from_stand = (Point::<Robot>::new(1.0, 0.0) - stand).rotated(-heading);
            let [near, far] = model.kick_reach_x;
            let margin = (far - near) / 5.0;
            assert!(
                ball_from_stand.x > near + margin && ball_from_stand.x < far - margin,
                "ball {ball_from_stand:?} ahead, reach {:?}",
                model.kick_reach_x
            );
            let [right, left] = model.kick_reach_y;
            let middle = (right + left) / 2.0;
            assert!((ball_from_stand.y - middle).abs() < 1e-9, "ball {ball_from_stand:?}");
        }
    }

    /// A robot at the centre facing +x that knows the ball at `ball` (robot frame).
    fn world_with_ball(ball: Point<Robot>) -> WorldState {
        let field = TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0);
        let mut model = WorldModel::new(world_config(&field)).expect("valid config");
        let prior = PosePrior { pose: Pose::new(0.0, 0.0, 0.0), sigma: [0.1, 0.1, 0.05] };
        model.command(WorldCommand::SetPose { prior }).expect("pose set");
        let mut world = model.state();
        let mut objects = world.objects.to_vec();
        let estimate = objects.iter_mut().find(|o| o.name.as_str() == BALL).expect("a ball");
        estimate.known = true;
        estimate.position = ball;
        estimate.global_position = world.pose.pose.to_global(ball);
        world.objects = objects.into();
        world
    }

    /// The reactive input of a stable robot with `world`, `at` seconds.
    fn with_input<R>(world: &WorldState, at: f64, f: impl FnOnce(&Input<'_, '_>) -> R) -> R {
        let percepts = Percepts::default();
        let actuation = ActuationStatus::default();
        f(&Input {
            now: Time::from_secs_f64(at),
            percepts: &percepts,
            world: Some(world),
            actuation: &actuation,
            stability: Stability::Stable,
        })
    }

    const DRIBBLE_TO: WholeBodyGoal =
        WholeBodyGoal::GoToBallAndDribble { target: Point::new(4.5, 0.0) };

    fn dribble(dribbling: &mut Dribbling, world: &WorldState, at: f64) -> Option<WholeBodyCommand> {
        with_input(world, at, |input| dribbling.step(&DRIBBLE_TO, input))
    }

    fn head_target(command: Option<WholeBodyCommand>) -> Option<HeadAngles> {
        match command {
            Some(WholeBodyCommand::Coordinated {
                head: HeadCommand::NonQueue(HeadMotion { target, .. }),
                ..
            }) => Some(target),
            _ => None,
        }
    }

    #[test]
    fn a_t1_lined_up_behind_the_ball_walks_through_it_at_full_speed() {
        let model = MotionModel::booster_t1();
        let target = Point::new(10.0, 0.0);
        let (v, through) = dribble_walk(&model, Point::new(0.3, 0.0), target, false);
        assert!(through);
        assert!((v.vx - model.max_forward).abs() < 1e-9, "{v:?}");
        // Off to the left: it side-steps left and slows.
        let (v, through) = dribble_walk(&model, Point::new(0.3, 0.1), target, false);
        assert!(through && v.vy > 0.0 && v.vx < model.max_forward, "{v:?}");
    }

    #[test]
    fn a_t1_lines_up_before_walking_through_and_stays_lined_up_more_loosely() {
        let model = MotionModel::booster_t1();
        let target = Point::new(10.0, 0.0);
        // 0.2 m to the side: too far to start walking through, near enough to go on.
        let ball = Point::new(0.3, 0.2);
        assert!(!dribble_walk(&model, ball, target, false).1);
        assert!(dribble_walk(&model, ball, target, true).1);
        // The target behind the robot: it never walks through the ball away from it.
        let (v, through) = dribble_walk(&model, Point::new(0.3, 0.0), Point::new(-10.0, 0.0), true);
        assert!(!through);
        assert!(v.vx < model.max_forward * 0.5, "{v:?}");
        // The ball behind the robot: it walks back around it, not through it.
        let (_, through) = dribble_walk(&model, Point::new(-0.3, 0.0), target, true);
        assert!(!through);
    }

    #[test]
    fn a_t1_beside_the_ball_goes_behind_it_on_the_line_to_the_target() {
        let model = MotionModel::booster_t1();
        // Ball 0.5 m to the left, target far ahead: the spot is 0.25 m behind the ball.
        let (v, through) = dribble_walk(&model, Point::new(0.0, 0.5), Point::new(10.0, 0.5), false);
        assert!(!through);
        assert!(v.vx < 0.0 && v.vy > 0.0, "back and left to the spot: {v:?}");
    }

    #[test]
    fn a_dribble_passes_a_robot_in_its_way_on_the_far_side_and_keeps_to_that_side() {
        let angle = MotionModel::booster_t1().dribble_dodge;
        assert!(angle > 0.0);
        let ball = Point::new(0.3, 0.0);
        let target = Point::new(10.0, 0.0);
        let dodge = |others: &[Point<Robot>], side| {
            dodge_target(ball, target, others.iter().copied(), side, angle)
        };
        // Nobody about, or only beside the robot and behind the ball: straight at the target.
        assert_eq!(dodge(&[], None), (target, None));
        assert_eq!(dodge(&[Point::new(0.0, 1.5), Point::new(-1.0, 0.2)], None), (target, None));
        // A robot 0.8 m past the ball, a little to the left: aim right of it.
        let (aim, side) = dodge(&[Point::new(1.1, 0.2)], None);
        assert_eq!(side, Some(-1.0));
        let turn = (aim - ball).angle();
        assert!((turn + angle).abs() < 1e-9, "{turn}");
        // It steps right across the line: the dribble keeps passing on the right.
        let right = [Point::new(1.1, -0.1)];
        assert_eq!(dodge(&right, side).1, Some(-1.0));
        assert_eq!(dodge(&right, None).1, Some(1.0));
        // Past it: straight at the target again. A NAO does not dodge.
        assert_eq!(dodge(&[Point::new(0.0, 0.6)], side), (target, None));
        let nao = MotionModel::default().dribble_dodge;
        let never = dodge_target(ball, target, right.into_iter(), None, nao);
        assert_eq!(never, (target, None));
    }

    #[test]
    fn a_t1_dribbling_glances_up_toward_the_target_and_back_at_the_ball() {
        let model = MotionModel::booster_t1();
        let [period, glance] = model.dribble_glance;
        let mut dribbling = Dribbling::new(Arc::new(model.clone()));
        let world = world_with_ball(Point::new(0.35, 0.0));
        with_input(&world, 0.0, |input| dribbling.activate(&DRIBBLE_TO, input));
        let mut head_at = |at: f64| {
            let command = dribble(&mut dribbling, &world, at);
            head_target(command).map(|h| h.pitch)
        };
        let down = head_at(0.0).expect("the first command");
        assert!(down > 0.5, "at the ball at its feet: pitch {down}");
        let up = head_at(period - glance / 2.0).expect("the glance");
        assert!(up.abs() < 1e-9, "level: {up}");
        let back = head_at(period + 0.1).expect("back at the ball");
        assert!((back - down).abs() < 1e-9);
    }

    #[test]
    fn dribbling_follows_the_ball_with_the_head_while_the_walk_repeats() {
        let mut dribbling = Dribbling::new(Arc::new(MotionModel::default()));
        let first = world_with_ball(Point::new(0.3, 0.15));
        let first_head = head_target(dribble(&mut dribbling, &first, 0.0)).expect("a command");
        // The ball moved sideways in the image: the walk toward it is the same (both
        // saturated), the head must turn to keep it in view.
        let moved = world_with_ball(Point::new(0.3, 0.2));
        let head = head_target(dribble(&mut dribbling, &moved, 0.01)).expect("the head follows");
        assert!(head.yaw - first_head.yaw > 0.1, "{first_head:?} -> {head:?}");
        // Neither moved: nothing to say.
        assert_eq!(dribble(&mut dribbling, &moved, 0.02), None);
    }
}
