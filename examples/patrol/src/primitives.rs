//! Primitive behaviors (the patrol's Table 4): short-term policies that turn a goal and the
//! newest percepts into one command for their resource. They know nothing of the consequences
//! of their actions; the multiplexers choose among them.

use std::sync::Arc;

use serde::{Deserialize, Serialize};
use strata_robot::command::{
    BodyCommand, BodyMotion, HeadCommand, HeadMotion, Resource, WholeBodyCommand,
};
pub use strata_robot::control::primitives::{HeadSender, Stand, StandUp, WalkSender};
use strata_robot::control::primitives::{StandPrimitive, StandUpPrimitive, names};
use strata_robot::control::reactive::{PrimitiveBehavior, ReactiveInput};
use strata_robot::geometry::{Point, Robot, Velocity, normalize_angle};
use strata_robot::platform::{HeadAngles, SpecialMotion};
use strata_robot::world::{ObjectEstimate, WorldState};

use crate::building::FloorPlan;
use crate::goals::{BodyGoal, HeadGoal, WholeBodyGoal};
use crate::world_config::{INTRUDER, poi_name};

strata_robot::primitive_ids! {
    /// The head's primitive behaviors, as activation policies name them.
    pub enum HeadPrimitive {
        Scan => "scan",
        ObjectTracking => "object tracking",
        LookAtTarget => "look at target",
    }
}

strata_robot::primitive_ids! {
    /// The body's primitive behaviors.
    pub enum BodyPrimitive {
        GoToWaypoint => "go to waypoint",
        Stand => names::STAND,
    }
}

strata_robot::primitive_ids! {
    /// The primitive behaviors that drive head and body together: the reflexes.
    pub enum WholeBodyPrimitive {
        Fall => "fall",
        StandUp => names::STAND_UP,
    }
}

impl StandPrimitive for BodyPrimitive {
    const STAND: BodyPrimitive = BodyPrimitive::Stand;
}

impl StandUpPrimitive for WholeBodyPrimitive {
    const STAND_UP: WholeBodyPrimitive = WholeBodyPrimitive::StandUp;
}

/// The robot's motion abilities as the primitives assume them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MotionModel {
    pub max_forward: f64,
    pub max_sideways: f64,
    pub max_turn: f64,
    pub head_speed: f64,
    /// How long each walk command lasts if no newer one replaces it, s.
    pub walk_command_duration: f64,
}

impl Default for MotionModel {
    fn default() -> Self {
        MotionModel {
            max_forward: 0.35,
            max_sideways: 0.2,
            max_turn: 1.2,
            head_speed: 3.0,
            walk_command_duration: 0.5,
        }
    }
}

type Input<'a> = ReactiveInput<'a, WorldState>;

/// The world-model objects a head goal is about.
pub fn head_goal_objects<'a>(world: &'a WorldState, goal: &HeadGoal) -> Vec<&'a ObjectEstimate> {
    match goal {
        HeadGoal::InspectPoint { poi } => {
            world.object(&poi_name(usize::from(*poi))).into_iter().collect()
        }
        HeadGoal::ObserveLandmark { name } => world.object(name).into_iter().collect(),
        HeadGoal::ObserveIntruder => world.object(INTRUDER).into_iter().collect(),
        HeadGoal::LookAt { .. } | HeadGoal::Scan => Vec::new(),
    }
}

/// An omnidirectional walk toward `target` (robot frame), ending at `heading` (relative) when
/// `stop`; otherwise passing through at speed.
pub fn walk_velocity(
    model: &MotionModel,
    target: Point<Robot>,
    heading: f64,
    stop: bool,
) -> Velocity {
    let distance = target.range();
    let bearing = target.bearing();
    if !stop || distance > 0.5 {
        let turn = (1.5 * bearing).clamp(-model.max_turn, model.max_turn);
        // Walk forward only once roughly facing the target.
        let forward = model.max_forward * (1.0 - bearing.abs() / 0.9).clamp(0.0, 1.0);
        let sideways = (0.3 * target.y).clamp(-model.max_sideways, model.max_sideways);
        Velocity::new(forward, sideways, turn)
    } else {
        Velocity::new(
            (1.2 * target.x).clamp(-model.max_forward, model.max_forward),
            (1.2 * target.y).clamp(-model.max_sideways, model.max_sideways),
            (1.5 * heading).clamp(-model.max_turn, model.max_turn),
        )
    }
}

/// A level gaze in direction `yaw` (the patrol's landmarks and points of interest are at eye
/// height).
fn head_yaw(yaw: f64) -> HeadAngles {
    HeadAngles { yaw: yaw.clamp(-2.0, 2.0), pitch: 0.0 }
}

// ---------------------------------------------------------------------------------------------
// Head

/// Scan: a fixed sweep of the head, queued point after point (the next is sent when actuation
/// announces the current one is about to be reached).
#[derive(Debug)]
pub struct Scan {
    model: Arc<MotionModel>,
    phase: usize,
    started: bool,
}

impl Scan {
    pub fn new(model: Arc<MotionModel>) -> Self {
        Scan { model, phase: 0, started: false }
    }

    const YAWS: [f64; 8] = [0.0, 0.9, 1.8, 0.9, 0.0, -0.9, -1.8, -0.9];
}

impl PrimitiveBehavior<HeadGoal, HeadCommand, WorldState> for Scan {
    fn id(&self) -> HeadPrimitive {
        HeadPrimitive::Scan
    }

    fn activate(&mut self, _: &HeadGoal, input: &Input<'_>) {
        // Start the sweep where the head already is.
        let yaw = input.percepts.head.yaw;
        self.phase = (0..Self::YAWS.len())
            .min_by(|a, b| (Self::YAWS[*a] - yaw).abs().total_cmp(&(Self::YAWS[*b] - yaw).abs()))
            .unwrap_or(0);
        self.started = false;
    }

    fn step(&mut self, _: &HeadGoal, input: &Input<'_>) -> Option<HeadCommand> {
        if self.started && !input.actuation.finishing.contains(&Resource::Head) {
            return None;
        }
        self.started = true;
        self.phase = (self.phase + 1) % Self::YAWS.len();
        let target = HeadAngles { yaw: Self::YAWS[self.phase], pitch: 0.0 };
        Some(HeadCommand::Queue(HeadMotion { target, max_speed: self.model.head_speed * 0.5 }))
    }
}

/// Object tracking: keep the goal's object in the middle of the image.
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

    fn activate(&mut self, _: &HeadGoal, _: &Input<'_>) {
        self.sender.reset();
    }

    fn step(&mut self, goal: &HeadGoal, input: &Input<'_>) -> Option<HeadCommand> {
        let object = head_goal_objects(input.world?, goal).into_iter().next()?;
        self.sender.send(head_yaw(object.position.bearing()), self.model.head_speed)
    }
}

/// Look at target: a place on the plan, through the pose (a point of interest not seen yet,
/// the alarm's location).
#[derive(Debug)]
pub struct LookAtTarget {
    model: Arc<MotionModel>,
    plan: Arc<FloorPlan>,
    sender: HeadSender,
}

impl LookAtTarget {
    pub fn new(model: Arc<MotionModel>, plan: Arc<FloorPlan>) -> Self {
        LookAtTarget { model, plan, sender: HeadSender::default() }
    }
}

impl PrimitiveBehavior<HeadGoal, HeadCommand, WorldState> for LookAtTarget {
    fn id(&self) -> HeadPrimitive {
        HeadPrimitive::LookAtTarget
    }

    fn activate(&mut self, _: &HeadGoal, _: &Input<'_>) {
        self.sender.reset();
    }

    fn step(&mut self, goal: &HeadGoal, input: &Input<'_>) -> Option<HeadCommand> {
        let world = input.world?;
        let target = match goal {
            HeadGoal::LookAt { target } => *target,
            HeadGoal::InspectPoint { poi } => {
                self.plan.points_of_interest.get(usize::from(*poi))?.nominal
            }
            _ => return None,
        };
        self.sender
            .send(head_yaw(world.pose.pose.to_robot(target).bearing()), self.model.head_speed)
    }
}

// ---------------------------------------------------------------------------------------------
// Body

/// Go to waypoint: walk to a pose on the plan.
#[derive(Debug)]
pub struct GoToWaypoint {
    model: Arc<MotionModel>,
    sender: WalkSender,
    stopped: bool,
}

impl GoToWaypoint {
    pub fn new(model: Arc<MotionModel>) -> Self {
        GoToWaypoint { model, sender: WalkSender::default(), stopped: false }
    }
}

impl PrimitiveBehavior<BodyGoal, BodyCommand, WorldState> for GoToWaypoint {
    fn id(&self) -> BodyPrimitive {
        BodyPrimitive::GoToWaypoint
    }

    fn activate(&mut self, _: &BodyGoal, _: &Input<'_>) {
        self.sender.reset();
        self.stopped = false;
    }

    fn step(&mut self, goal: &BodyGoal, input: &Input<'_>) -> Option<BodyCommand> {
        let BodyGoal::GoToWaypoint { pose: target, stop } = goal else { return None };
        let pose = input.world?.pose.pose;
        let relative = pose.to_robot(target.position());
        let heading = normalize_angle(target.theta - pose.theta);
        // Arrival has hysteresis: a robot that stopped does not shuffle back and forth over
        // centimetres of localization noise.
        let (reach, align) = if self.stopped { (0.12, 0.25) } else { (0.06, 0.1) };
        if *stop && relative.range() < reach && heading.abs() < align {
            if self.stopped {
                return None;
            }
            self.stopped = true;
            self.sender.reset();
            return Some(BodyCommand::NonQueue(BodyMotion::Stand));
        }
        self.stopped = false;
        let velocity = walk_velocity(&self.model, relative, heading, *stop);
        self.sender.send(input.now, velocity, self.model.walk_command_duration)
    }
}

// ---------------------------------------------------------------------------------------------
// Head and body

/// Fall: relax and protect the robot once instability is detected.
#[derive(Debug, Default)]
pub struct Fall;

impl PrimitiveBehavior<WholeBodyGoal, WholeBodyCommand, WorldState> for Fall {
    fn id(&self) -> WholeBodyPrimitive {
        WholeBodyPrimitive::Fall
    }

    fn step(&mut self, goal: &WholeBodyGoal, _: &Input<'_>) -> Option<WholeBodyCommand> {
        let sequence = match goal {
            WholeBodyGoal::Fall { sequence } => *sequence,
            WholeBodyGoal::StandUp { .. } => return None,
        };
        Some(WholeBodyCommand::Special { motion: SpecialMotion::fall(sequence) })
    }
}
