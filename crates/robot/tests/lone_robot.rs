//! A robot that works alone, assembled by `add_robot` like any other: it writes no team
//! planning, codec or device (`Alone`, `NoCodec`, `NoDevice`), gives the reactive layer only
//! the multiplexer it uses (`ReactiveLayer::empty` + `with_body`), and walks when its
//! deliberative layer asks.

use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use serde::{Deserialize, Serialize};
use strata_robot::actuation::ActuationConfig;
use strata_robot::application::{Alone, Application, AssignmentOf, NoCodec, NoDevice};
use strata_robot::assembly::{RobotParts, RobotTiming, add_robot};
use strata_robot::command::{BodyCommand, BodyMotion, ResourceGroup};
use strata_robot::control::deliberative::{
    DeliberativeInput, DeliberativeOutput, DeliberativePolicy,
};
use strata_robot::control::planning::{Planner, PlanningConfig};
use strata_robot::control::reactive::{
    ActivationPolicy, FallDetectorConfig, Multiplexer, MultiplexerConfig, PrimitiveBehavior,
    ReactiveInput, ReactiveLayer,
};
use strata_robot::control::scores::{Goal, GoalScore, NoGoal, ScoreVector};
use strata_robot::edge::{RobotLinks, RobotPlatform};
use strata_robot::geometry::{Odometry, Velocity};
use strata_robot::perception::PerceptionConfig;
use strata_robot::platform::{
    ActuatorOrders, BodyMotionState, BodyOrder, FootContact, HeadAngles, MotionFeedback, Platform,
    PlatformError, PlatformInfo, SensorFrame,
};
use strata_robot::world::{WorldModelConfig, WorldState};
use strata_runtime::{GraphBuilder, HostConfig, LockstepHost, Time};

strata_robot::primitive_ids! {
    enum StrollPrimitive {
        Stroll => "stroll",
    }
}

/// The only goal this robot has: walk slowly forward.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
enum Stroll {
    Forward,
}

impl Goal for Stroll {
    type Primitive = StrollPrimitive;

    fn label(&self) -> String {
        "stroll".into()
    }
}

const PACE: f64 = 0.1;

struct Strolling;

impl PrimitiveBehavior<Stroll, BodyCommand, WorldState> for Strolling {
    fn id(&self) -> StrollPrimitive {
        StrollPrimitive::Stroll
    }

    fn step(&mut self, _: &Stroll, _: &ReactiveInput<'_, WorldState>) -> Option<BodyCommand> {
        Some(BodyCommand::NonQueue(BodyMotion::Walk {
            velocity: Velocity::new(PACE, 0.0, 0.0),
            duration: 1.0,
        }))
    }
}

struct AlwaysStroll;

impl ActivationPolicy<Stroll, WorldState> for AlwaysStroll {
    fn reactive_score(&self, _: &GoalScore<Stroll>, _: &ReactiveInput<'_, WorldState>) -> f64 {
        1.0
    }

    fn primitives_for(
        &self,
        _: &Stroll,
        _: &ReactiveInput<'_, WorldState>,
    ) -> &'static [StrollPrimitive] {
        &[StrollPrimitive::Stroll]
    }
}

struct Stroller;

impl DeliberativePolicy for Stroller {
    type HeadGoal = NoGoal;
    type BodyGoal = Stroll;
    type WholeBodyGoal = NoGoal;
    type World = WorldState;
    type Assignment = AssignmentOf<Lone>;

    fn tick(
        &mut self,
        _: &DeliberativeInput<'_, WorldState, AssignmentOf<Lone>>,
    ) -> DeliberativeOutput<NoGoal, Stroll, NoGoal> {
        DeliberativeOutput {
            body: ScoreVector::single(Stroll::Forward),
            behavior_path: "strolling".into(),
            ..DeliberativeOutput::default()
        }
    }
}

struct Lone;

impl Application for Lone {
    type Planning = Alone;
    type Device = NoDevice;
    type Codec = NoCodec;
    type Deliberative = Stroller;
}

/// A body that stands on both feet and keeps every order it is given.
struct Body {
    orders: Arc<Mutex<Vec<ActuatorOrders>>>,
}

impl Platform for Body {
    fn info(&self) -> PlatformInfo {
        PlatformInfo {
            name: "lone body".into(),
            sensor_period: Duration::from_millis(10),
            camera_fov: 1.0,
            camera_range: 4.0,
            head_yaw_limits: (-1.5, 1.5),
            head_pitch_limits: (-0.5, 0.5),
            max_head_speed: 3.0,
            max_velocity: Velocity::new(0.3, 0.1, 1.0),
            motions: Vec::new(),
            can_walk: true,
        }
    }

    fn read_sensors(&mut self, now: Time) -> Result<Option<SensorFrame>, PlatformError> {
        Ok(Some(SensorFrame {
            stamp: now,
            foot_contact: FootContact { left: 2.0, right: 2.0 },
            ..SensorFrame::default()
        }))
    }

    fn read_motion(&mut self, now: Time) -> Result<MotionFeedback, PlatformError> {
        Ok(MotionFeedback {
            stamp: now,
            body: BodyMotionState::Standing,
            head: HeadAngles::default(),
            head_settled: true,
            odometry: Odometry::ZERO,
        })
    }

    fn write(&mut self, _: Time, orders: &ActuatorOrders) -> Result<(), PlatformError> {
        self.orders.lock().unwrap_or_else(PoisonError::into_inner).push(*orders);
        Ok(())
    }
}

#[test]
fn a_lone_robot_needs_no_team_planning_codec_device_or_unused_multiplexer() {
    let orders = Arc::new(Mutex::new(Vec::new()));
    let body: Arc<Mutex<dyn Platform>> = Arc::new(Mutex::new(Body { orders: orders.clone() }));
    let strolling =
        Multiplexer::new(ResourceGroup::Body, MultiplexerConfig::default(), Box::new(AlwaysStroll))
            .with_primitive(Box::new(Strolling));
    let reactive = ReactiveLayer::empty(FallDetectorConfig::default()).with_body(strolling);
    assert!(reactive.unregistered().is_empty(), "{:?}", reactive.unregistered());
    let parts = RobotParts::<Lone> {
        name: "lone".into(),
        member: 1,
        platform: RobotPlatform::Shared(body),
        perception: PerceptionConfig::default(),
        world: WorldModelConfig::default(),
        reactive,
        deliberative: Stroller,
        planner: Planner::new(Alone::default(), PlanningConfig::default()),
        codec: NoCodec,
        device: NoDevice,
        links: RobotLinks::default(),
        shared_objects: Vec::new(),
        actuation: ActuationConfig::default(),
        timing: RobotTiming::default(),
    };
    let mut graph = GraphBuilder::new();
    let modules = add_robot(&mut graph, parts).expect("a valid robot");
    assert_eq!(modules.deliberative, "lone/deliberative");
    let mut host =
        LockstepHost::new(graph.build().expect("a valid graph"), HostConfig::with_seed(1));
    host.run_for(Duration::from_secs(3)).expect("runs");

    let orders = orders.lock().unwrap_or_else(PoisonError::into_inner);
    let walking = orders
        .iter()
        .filter(|o| {
            matches!(o.body, Some(BodyOrder::Walk { velocity }) if velocity == Velocity::new(PACE, 0.0, 0.0))
        })
        .count();
    assert!(walking > 0, "the deliberative layer's stroll reaches the body: {orders:?}");
    // No head goal, no head-and-body goal: the unused multiplexers never order the head.
    assert!(orders.iter().all(|o| o.head.is_none()), "{orders:?}");
}
