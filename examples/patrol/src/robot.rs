//! One patrol robot, assembled on the architecture's [`add_robot`]: the same four modules and
//! three layers as a soccer player, with the patrol's goals, primitives, activation policies,
//! behaviors, value functions, missions, roles, team codec and console.

use std::sync::Arc;
use std::time::Duration;

use serde::{Deserialize, Serialize};
use strata_robot::actuation::ActuationConfig;
use strata_robot::application::Application;
use strata_robot::assembly::{LayerTiming, RobotModules, RobotParts, RobotTiming, add_robot};
use strata_robot::command::ResourceGroup;
use strata_robot::control::active_vision::ActiveVisionConfig;
use strata_robot::control::planning::{Planner, PlanningConfig};
use strata_robot::control::reactive::{
    FallDetectorConfig, Multiplexer, MultiplexerConfig, ReactiveLayer,
};
use strata_robot::control::scores::{GoalScore, ScoreVector};
use strata_robot::edge::{Links, RobotLinks, RobotPlatform};
use strata_robot::geometry::Pose;
use strata_robot::platform::{ExternalLink, TeamLink};
use strata_robot::world::WorldState;
use strata_runtime::{GraphBuilder, ProcessingTime};

use crate::activation::{BodyActivation, HeadActivation, WholeBodyActivation};
use crate::behaviors::{BehaviorConfig, PatrolBehavior};
use crate::building::FloorPlan;
use crate::console::{AlarmBoard, OperatorConsole};
use crate::goals::{BodyGoal, HeadGoal, WholeBodyGoal};
use crate::planning::{PatrolCodec, PatrolPlanning};
use crate::primitives::{
    Fall, GoToWaypoint, LookAtTarget, MotionModel, ObjectTracking, Scan, Stand, StandUp,
};
use crate::world_config::{INTRUDER, perception_config, world_config};

/// The patrol as an application of the architecture.
#[derive(Clone, Copy, Debug)]
pub struct Patrol;

impl Application for Patrol {
    type Planning = PatrolPlanning;
    type Device = OperatorConsole;
    type Codec = PatrolCodec;
    type Deliberative = PatrolBehavior;
}

/// Everything that makes a patrol robot behave the way it does.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PatrolConfig {
    pub behavior: BehaviorConfig,
    pub multiplexer: MultiplexerConfig,
    pub fall_detector: FallDetectorConfig,
    pub actuation: ActuationConfig,
    pub motion: MotionModel,
    pub planning: PlanningConfig,
    pub timing: RobotTiming,
}

impl Default for PatrolConfig {
    fn default() -> Self {
        let ms = |v: u64| Duration::from_millis(v);
        PatrolConfig {
            behavior: BehaviorConfig::default(),
            multiplexer: MultiplexerConfig::default(),
            fall_detector: FallDetectorConfig::default(),
            actuation: ActuationConfig::default(),
            motion: MotionModel::default(),
            // A building's network is better than a soccer field's: messages every 2 s.
            planning: PlanningConfig { message_interval: 2.0, ..PlanningConfig::default() },
            timing: RobotTiming {
                // The building's sensors run at 50 Hz; the deliberative layer at 2 Hz.
                perception: LayerTiming::periodic(
                    50.0,
                    ProcessingTime::Uniform { min: ms(2), max: ms(5) },
                ),
                deliberative: LayerTiming::periodic(
                    2.0,
                    ProcessingTime::Uniform { min: ms(20), max: ms(60) },
                ),
                ..RobotTiming::default()
            },
        }
    }
}

/// What a patrol robot needs from its surroundings.
pub struct PatrolRobotSpec {
    /// Prefix of the robot's module names.
    pub name: String,
    pub player: u8,
    pub plan: Arc<FloorPlan>,
    /// Where the robot is switched on.
    pub start: Pose,
    /// The robot's platform: the building's module serving it, or any platform object.
    pub platform: RobotPlatform,
    pub team_link: Option<Box<dyn TeamLink>>,
    pub console_link: Option<Box<dyn ExternalLink>>,
}

impl std::fmt::Debug for PatrolRobotSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PatrolRobotSpec")
            .field("name", &self.name)
            .field("player", &self.player)
            .finish_non_exhaustive()
    }
}

/// The patrol's reactive layer: its three multiplexers with their primitive behaviors, the
/// fall and stand-up reflexes, and the fall detector.
pub fn reactive_layer(config: &PatrolConfig, plan: &Arc<FloorPlan>) -> PatrolReactiveLayer {
    let model = Arc::new(config.motion.clone());
    let mux = config.multiplexer.clone();
    let head = Multiplexer::new(ResourceGroup::Head, mux.clone(), Box::new(HeadActivation))
        .with_primitive(Box::new(Scan::new(Arc::clone(&model))))
        .with_primitive(Box::new(ObjectTracking::new(Arc::clone(&model))))
        .with_primitive(Box::new(LookAtTarget::new(Arc::clone(&model), Arc::clone(plan))));
    let body = Multiplexer::new(ResourceGroup::Body, mux.clone(), Box::new(BodyActivation))
        .with_primitive(Box::new(GoToWaypoint::new(Arc::clone(&model))))
        .with_primitive(Box::new(Stand::default()));
    // The reflexes are always offered: a falling robot cannot wait for a 2 Hz layer.
    let reflexes = ScoreVector::default()
        .with(GoalScore::new(WholeBodyGoal::Fall { sequence: 0 }, 1.0))
        .with(GoalScore::new(WholeBodyGoal::StandUp { sequence: 0 }, 1.0));
    let whole = Multiplexer::new(ResourceGroup::HeadAndBody, mux, Box::new(WholeBodyActivation))
        .with_primitive(Box::new(Fall))
        .with_primitive(Box::new(StandUp))
        .with_reflexes(reflexes);
    ReactiveLayer::new(head, body, whole, config.fall_detector.clone())
}

/// The reactive layer type of a patrol robot.
pub type PatrolReactiveLayer = ReactiveLayer<HeadGoal, BodyGoal, WholeBodyGoal, WorldState>;

/// Adds one patrol robot (all four modules, all three layers) to `graph`.
pub fn add_patrol_robot(
    graph: &mut GraphBuilder,
    spec: PatrolRobotSpec,
    config: &PatrolConfig,
) -> Result<RobotModules, String> {
    let info = spec.platform.info();
    let plan = Arc::clone(&spec.plan);
    let reactive = reactive_layer(config, &plan);
    let vision = ActiveVisionConfig {
        fov: info.camera_fov,
        range: info.camera_range,
        yaw_limits: info.head_yaw_limits,
        ..ActiveVisionConfig::default()
    };
    let deliberative =
        PatrolBehavior::new(spec.player, Arc::clone(&plan), config.behavior.clone(), vision)
            .map_err(|e| e.to_string())?;
    let board = AlarmBoard::default();
    let planner = Planner::new(
        PatrolPlanning::new(Arc::clone(&plan), board.clone()),
        config.planning.clone(),
    );
    let parts = RobotParts::<Patrol> {
        name: spec.name,
        member: spec.player,
        platform: spec.platform,
        perception: perception_config(),
        world: world_config(&plan, spec.start),
        reactive,
        deliberative,
        planner,
        codec: PatrolCodec,
        device: OperatorConsole::new(spec.player, board),
        links: RobotLinks::Shared(Links::new(spec.team_link, spec.console_link)),
        shared_objects: vec![INTRUDER.to_owned()],
        actuation: config.actuation.clone(),
        timing: config.timing.clone(),
    };
    add_robot(graph, parts).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every primitive an activation policy can name is registered with its multiplexer: one
    /// left out would make the goals only it pursues inapplicable, silently.
    #[test]
    fn the_reactive_layer_registers_every_primitive() {
        let layer = reactive_layer(&PatrolConfig::default(), &Arc::new(FloorPlan::office()));
        assert_eq!(layer.unregistered(), []);
    }
}
