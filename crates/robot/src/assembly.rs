//! One robot, assembled: perception, actuation, world modeling and the three layers of hybrid
//! control, connected with the paper's policies (docs/architecture.md, One robot as data):
//!
//! ```text
//! Platform ─▶ sensors ─frames (Queue)─▶ Perception ─percepts (Latest)─▶ Reactive ─commands (Queue)─▶ Actuation ─orders─▶ actuators ─▶ Platform
//!               │                        ├─percepts (Queue)─▶ World ◀─odometry (Merge)─────────────────┤    ▲                │
//!               │                        └─signals (Queue)─▶ Planning (the referee's whistle, gestures)  │    └──refusals──────┘
//!               └─motion feedback (Merge)───────────────────────────────────────────────────────────────▶┤
//!                                world state (Latest)├──────▶ Reactive, Deliberative, Planning          │
//!   links_in ─inbox─▶ Planning ─decision (Latest)─▶ Deliberative ─score vectors (Latest)─▶ Reactive ◀─messages (Queue)
//!                     Planning ─teammates' estimates, commands (Queue)─▶ World
//!                     Planning ─outbox─▶ links_out
//! ```
//!
//! Only the edge touches the platform and the links ([`crate::edge`]): `sensors` and
//! `actuators` (or a module that is the platform of several robots, such as the in-process
//! simulator: [`RobotPlatform::Module`]), `links_in` and `links_out`. Every module between them
//! computes on packages and replays from a log. Each module runs on its own trigger:
//! `sensors` at the sensor rate, perception on every frame, world modeling and the reactive
//! layer on every percept, actuation on every command, the deliberative and planning layers at
//! their own rates. The same graph runs on either host. Each module's ports are declared once
//! (`PerceptionPorts::declare`, ...) and each module is added by one function here
//! ([`add_perception`], ...), which `strata replay` calls too.

use std::time::Duration;

use serde::{Deserialize, Serialize};
use strata_runtime::{GraphBuilder, Message, ProcessingTime, Trigger};

use crate::actuation::{ActuationConfig, ActuationModule, ActuationPorts};
use crate::application::{Application, BodyGoalOf, HeadGoalOf, WholeBodyGoalOf};
use crate::control::deliberative::DeliberativePolicy;
use crate::control::modules::{
    DeliberativeModule, DeliberativePorts, PolicyPorts, ReactiveModule, ReactivePorts,
};
use crate::control::planning::{Planner, PlanningPolicy};
use crate::control::planning_module::{ExternalDevice, PlanningModule, PlanningPorts, TeamCodec};
use crate::control::reactive::ReactiveLayer;
use crate::control::scores::Goal;
use crate::edge::{EdgeModules, RobotLinks, RobotPlatform, add_link_edge};
use crate::perception::{PerceptionConfig, PerceptionModule, PerceptionPorts};
use crate::platform::PlatformInfo;
use crate::world::{CameraNoise, ConfigError, WorldModelConfig, WorldState, add_world_module};

/// How often a layer runs (for periodic layers) and how long its cycles take on the lockstep
/// host. A field left out keeps the layer's default: a configuration file that changes the
/// deliberative rate does not silently zero its processing time.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LayerTiming {
    /// Cycle rate, Hz (periodic layers only; ignored by layers that run on input).
    pub rate_hz: Option<f64>,
    pub processing_time: Option<ProcessingTime>,
}

impl LayerTiming {
    pub fn on_input(processing_time: ProcessingTime) -> LayerTiming {
        LayerTiming { rate_hz: None, processing_time: Some(processing_time) }
    }

    pub fn periodic(rate_hz: f64, processing_time: ProcessingTime) -> LayerTiming {
        LayerTiming { rate_hz: Some(rate_hz), processing_time: Some(processing_time) }
    }

    /// The period of a periodic layer, `default_hz` where no valid rate is set.
    pub fn period(&self, default_hz: f64) -> Duration {
        let hz = self.rate_hz.filter(|hz| hz.is_finite() && *hz > 0.0).unwrap_or(default_hz);
        Duration::from_secs_f64(1.0 / hz)
    }

    fn or(&self, default: &LayerTiming) -> LayerTiming {
        LayerTiming {
            rate_hz: self.rate_hz.or(default.rate_hz),
            processing_time: self
                .processing_time
                .clone()
                .or_else(|| default.processing_time.clone()),
        }
    }

    /// The processing-time model, zero where none is set.
    pub fn processing(&self) -> ProcessingTime {
        self.processing_time.clone().unwrap_or_default()
    }
}

/// The timing of every module of a robot.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RobotTiming {
    pub perception: LayerTiming,
    pub world: LayerTiming,
    pub reactive: LayerTiming,
    pub actuation: LayerTiming,
    pub deliberative: LayerTiming,
    pub planning: LayerTiming,
}

impl Default for RobotTiming {
    /// NAO-like: sensors at 83 Hz; image processing a few milliseconds; the deliberative layer
    /// at 1.6 Hz with cycles of tens of milliseconds (the paper's Table 6).
    fn default() -> Self {
        let ms = |v: u64| Duration::from_millis(v);
        RobotTiming {
            perception: LayerTiming::periodic(
                83.3,
                ProcessingTime::Uniform { min: ms(2), max: ms(6) },
            ),
            world: LayerTiming::on_input(ProcessingTime::Uniform { min: ms(1), max: ms(3) }),
            reactive: LayerTiming::on_input(ProcessingTime::Uniform { min: ms(1), max: ms(4) }),
            actuation: LayerTiming::on_input(ProcessingTime::fixed(ms(1))),
            deliberative: LayerTiming::periodic(
                1.6,
                ProcessingTime::Uniform { min: ms(20), max: ms(80) },
            ),
            planning: LayerTiming::periodic(10.0, ProcessingTime::fixed(ms(2))),
        }
    }
}

impl RobotTiming {
    /// Every layer's unset fields filled from the defaults.
    pub fn resolved(&self) -> RobotTiming {
        let d = RobotTiming::default();
        RobotTiming {
            perception: self.perception.or(&d.perception),
            world: self.world.or(&d.world),
            reactive: self.reactive.or(&d.reactive),
            actuation: self.actuation.or(&d.actuation),
            deliberative: self.deliberative.or(&d.deliberative),
            planning: self.planning.or(&d.planning),
        }
    }
}

/// Everything one robot is made of, for application `A`.
pub struct RobotParts<A: Application> {
    /// Prefix of the module names (`"blue/3"` gives `"blue/3/reactive"`...).
    pub name: String,
    pub member: u8,
    pub platform: RobotPlatform,
    pub perception: PerceptionConfig,
    pub world: WorldModelConfig,
    pub reactive: ReactiveLayer<HeadGoalOf<A>, BodyGoalOf<A>, WholeBodyGoalOf<A>, WorldState>,
    pub deliberative: A::Deliberative,
    pub planner: Planner<A::Planning>,
    pub codec: A::Codec,
    pub device: A::Device,
    /// The team link and the external device's (none for a lone robot: `RobotLinks::default()`).
    pub links: RobotLinks,
    /// World-model object names this robot shares with teammates, most important first.
    pub shared_objects: Vec<String>,
    pub actuation: ActuationConfig,
    pub timing: RobotTiming,
}

impl<A: Application> std::fmt::Debug for RobotParts<A> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RobotParts")
            .field("name", &self.name)
            .field("member", &self.member)
            .finish_non_exhaustive()
    }
}

/// The names of a robot's modules, for statistics and logs.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RobotModules {
    /// The platform's edge: the sensor source and the actuator sink (no such modules when the
    /// platform is a module of its own, as the in-process simulator is).
    #[serde(default)]
    pub sensors: String,
    #[serde(default)]
    pub actuators: String,
    pub perception: String,
    pub world: String,
    pub reactive: String,
    pub actuation: String,
    pub deliberative: String,
    pub planning: String,
}

impl RobotModules {
    pub fn new(prefix: &str) -> RobotModules {
        let edge = EdgeModules::new(prefix);
        RobotModules {
            sensors: edge.sensors,
            actuators: edge.actuators,
            perception: format!("{prefix}/perception"),
            world: format!("{prefix}/world"),
            reactive: format!("{prefix}/reactive"),
            actuation: format!("{prefix}/actuation"),
            deliberative: format!("{prefix}/deliberative"),
            planning: format!("{prefix}/planning"),
        }
    }

    /// The three layers of hybrid control, with the paper's names.
    pub fn layers(&self) -> [(&'static str, &str); 3] {
        [
            ("planning", self.planning.as_str()),
            ("deliberative", self.deliberative.as_str()),
            ("reactive", self.reactive.as_str()),
        ]
    }
}

/// Adds perception (`name`), run on every sensor frame.
pub fn add_perception(
    graph: &mut GraphBuilder,
    name: &str,
    info: PlatformInfo,
    config: PerceptionConfig,
    camera: CameraNoise,
    timing: &LayerTiming,
) -> PerceptionPorts {
    graph.add(name, |p| {
        let ports = PerceptionPorts::declare(p);
        p.real_time();
        p.processing_time(timing.processing());
        (PerceptionModule::new(info, config, camera, ports), ports)
    })
}

/// Adds actuation (`name`), run on every command.
pub fn add_actuation(
    graph: &mut GraphBuilder,
    name: &str,
    config: ActuationConfig,
    timing: &LayerTiming,
) -> ActuationPorts {
    graph.add(name, |p| {
        let ports = ActuationPorts::declare(p);
        p.real_time();
        p.processing_time(timing.processing());
        (ActuationModule::new(config, ports), ports)
    })
}

/// Adds the reactive layer (`name`), run on every percept.
pub fn add_reactive<H, B, X, W>(
    graph: &mut GraphBuilder,
    name: &str,
    layer: ReactiveLayer<H, B, X, W>,
    timing: &LayerTiming,
) -> ReactivePorts<H, B, X, W>
where
    H: Goal,
    B: Goal,
    X: Goal,
    W: Message,
{
    graph.add(name, |p| {
        let ports = ReactivePorts::declare(p);
        p.real_time();
        p.processing_time(timing.processing());
        (ReactiveModule::new(layer, ports), ports)
    })
}

/// Adds the deliberative layer (`name`), ticked at its configured rate (1.6 Hz by default).
pub fn add_deliberative<D>(
    graph: &mut GraphBuilder,
    name: &str,
    policy: D,
    timing: &LayerTiming,
) -> PolicyPorts<D>
where
    D: DeliberativePolicy + 'static,
    D::World: Message,
    D::Assignment: Message,
{
    graph.add(name, |p| {
        let ports = DeliberativePorts::declare(p);
        p.trigger(Trigger::every(timing.period(1.6)));
        p.processing_time(timing.processing());
        (DeliberativeModule::new(policy, ports), ports)
    })
}

/// Adds the planning layer (`name`), run on every inbox of its links (at the layer's rate),
/// built by `module` around its ports.
pub fn add_planning<P, C, F>(
    graph: &mut GraphBuilder,
    name: &str,
    timing: &LayerTiming,
    module: impl FnOnce(PlanningPorts<P::Mission, P::Role, F::Directive>) -> PlanningModule<P, C, F>,
) -> PlanningPorts<P::Mission, P::Role, F::Directive>
where
    P: PlanningPolicy + 'static,
    C: TeamCodec<P::Mission, P::Role> + 'static,
    F: ExternalDevice + 'static,
{
    graph.add(name, |p| {
        let ports = PlanningPorts::declare(p);
        p.processing_time(timing.processing());
        (module(ports), ports)
    })
}

/// Adds one robot's modules to `graph`, with its platform and its links at the edge
/// ([`crate::edge::add_platform_edge`], [`crate::edge::add_link_edge`]).
pub fn add_robot<A: Application>(
    graph: &mut GraphBuilder,
    parts: RobotParts<A>,
) -> Result<RobotModules, ConfigError> {
    let names = RobotModules::new(&parts.name);
    let timing = parts.timing.resolved();

    // One camera model: the noise perception attaches is the noise world modeling predicts.
    let camera = parts.world.camera;
    let world = add_world_module(graph, &names.world, parts.world)?;
    // The world module's processing time and trigger are set by its constructor; its timing
    // model is applied through the builder below.
    graph.set_processing_time(&names.world, timing.world.processing());
    // The sensor path (sensors, perception, world modeling, reactive layer, actuation) runs at
    // the sensor rate whatever the deliberative and planning layers do (paper 3.7, Table 6).
    graph.set_real_time(&names.world);

    let info = parts.platform.info();
    let edge = parts.platform.into_ports(graph, &parts.name, timing.perception.period(83.3));
    let perception = add_perception(
        graph,
        &names.perception,
        info,
        parts.perception,
        camera,
        &timing.perception,
    );
    let actuation = add_actuation(graph, &names.actuation, parts.actuation, &timing.actuation);
    let reactive = add_reactive(graph, &names.reactive, parts.reactive, &timing.reactive);
    let deliberative =
        add_deliberative(graph, &names.deliberative, parts.deliberative, &timing.deliberative);

    let (links_in, links_out) =
        add_link_edge(graph, &parts.name, parts.links, timing.planning.period(10.0));
    let (member, planner, codec, device, shared) =
        (parts.member, parts.planner, parts.codec, parts.device, parts.shared_objects);
    let planning = add_planning(graph, &names.planning, &timing.planning, |ports| {
        PlanningModule::new(member, planner, codec, device, ports, shared)
    });

    graph.connect(links_in.inbox, planning.inbox);
    graph.connect(planning.outbox, links_out.outbox);
    graph.connect(edge.frames, perception.frames);
    graph.connect(edge.motion, actuation.motion);
    graph.connect(actuation.orders, edge.orders);
    graph.connect(edge.refusals, actuation.refusals);
    graph.fan_out(perception.percepts, [reactive.percepts, world.percepts]);
    graph.fan_out(world.world_state, [reactive.world, deliberative.world, planning.world]);
    graph.connect(reactive.commands, actuation.commands);
    graph.connect(actuation.odometry, world.odometry);
    graph.connect(actuation.messages, reactive.actuation);
    graph.fan_out(reactive.stability, [deliberative.stability, planning.stability]);
    graph.connect(deliberative.output, reactive.deliberative);
    graph.connect(planning.decision, deliberative.assignment);
    graph.connect(planning.team_estimates, world.team);
    graph.connect(planning.world_commands, world.commands);
    graph.connect(perception.signals, planning.signals);
    Ok(names)
}
