//! One robot, assembled: perception, actuation, world modeling and the three layers of hybrid
//! control, connected with the paper's policies (docs/architecture.md, One robot as data):
//!
//! ```text
//! Platform ─sensor frame─▶ Perception ─percepts (Latest)─▶ Reactive ─commands (Queue)─▶ Actuation ─▶ Platform
//!                              ├─percepts (Queue)─▶ World ◀─odometry (Merge)──────────────┘   │
//!                              └─signals (Queue)─▶ Planning (the referee's whistle, gestures)
//!                                                    │       Reactive ◀─messages (Queue)───────┘
//!                                world state (Latest)├──────▶ Reactive, Deliberative, Planning
//!   team ◀─▶ Planning ─decision (Latest)─▶ Deliberative ─score vectors (Latest)─▶ Reactive
//!            Planning ─teammates' estimates, commands (Queue)─▶ World
//! ```
//!
//! Each module runs on its own trigger: perception at the sensor rate, world modeling and the
//! reactive layer on every percept, actuation on every command, the deliberative and planning
//! layers at their own rates. The same graph runs on either host.

use std::time::Duration;

use serde::{Deserialize, Serialize};
use strata_runtime::{GraphBuilder, Policy, ProcessingTime, Trigger};

use crate::actuation::{ActuationConfig, ActuationModule};
use crate::command::{ActuationMessage, MotionCommands};
use crate::control::deliberative::DeliberativePolicy;
use crate::control::modules::{
    DeliberativeModule, DeliberativePorts, ReactiveModule, ReactivePorts,
};
use crate::control::planning::{Planner, PlanningPolicy};
use crate::control::planning_module::{
    PlanningDecision, PlanningModule, PlanningPorts, Referee, TeamCodec,
};
use crate::control::reactive::ReactiveLayer;
use crate::control::scores::Goal;
use crate::geometry::Odometry;
use crate::percept::{Percepts, Signal};
use crate::perception::{PerceptionConfig, PerceptionModule};
use crate::platform::{ExternalLink, MotionFeedback, SharedPlatform, TeamLink};
use crate::world::{ConfigError, WorldModelConfig, WorldState, add_world_module};

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

    fn period(&self, default_hz: f64) -> Duration {
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

    fn processing(&self) -> ProcessingTime {
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

/// Everything one robot is made of.
pub struct RobotParts<H, B, X, D, P, C, F>
where
    P: PlanningPolicy,
    F: Referee,
{
    /// Prefix of the module names (`"blue/3"` gives `"blue/3/reactive"`...).
    pub name: String,
    pub player: u8,
    pub platform: SharedPlatform,
    pub perception: PerceptionConfig,
    pub world: WorldModelConfig,
    pub reactive: ReactiveLayer<H, B, X, WorldState>,
    pub deliberative: D,
    pub planner: Planner<P>,
    pub codec: C,
    pub referee: F,
    pub team_link: Option<Box<dyn TeamLink>>,
    pub external_link: Option<Box<dyn ExternalLink>>,
    /// World-model object names this robot shares with teammates, most important first.
    pub shared_objects: Vec<String>,
    pub actuation: ActuationConfig,
    pub timing: RobotTiming,
    /// Extra computation per deliberative tick (the rates experiment's load).
    pub deliberative_load: Duration,
}

impl<H, B, X, D, P: PlanningPolicy, C, F: Referee> std::fmt::Debug
    for RobotParts<H, B, X, D, P, C, F>
{
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RobotParts")
            .field("name", &self.name)
            .field("player", &self.player)
            .finish_non_exhaustive()
    }
}

/// The names of a robot's modules, for statistics and logs.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RobotModules {
    pub perception: String,
    pub world: String,
    pub reactive: String,
    pub actuation: String,
    pub deliberative: String,
    pub planning: String,
}

impl RobotModules {
    pub fn new(prefix: &str) -> RobotModules {
        RobotModules {
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

/// Adds one robot's modules to `graph`.
pub fn add_robot<H, B, X, D, P, C, F>(
    graph: &mut GraphBuilder,
    parts: RobotParts<H, B, X, D, P, C, F>,
) -> Result<RobotModules, ConfigError>
where
    H: Goal,
    B: Goal,
    X: Goal,
    D: DeliberativePolicy<
            HeadGoal = H,
            BodyGoal = B,
            WholeBodyGoal = X,
            World = WorldState,
            Assignment = PlanningDecision<P::Mission, P::Role, F::Directive>,
        > + 'static,
    P: PlanningPolicy + 'static,
    C: TeamCodec<P::Mission, P::Role> + 'static,
    F: Referee + 'static,
{
    let names = RobotModules::new(&parts.name);
    let timing = parts.timing.resolved();

    let world = add_world_module(graph, &names.world, parts.world)?;
    // The world module's processing time and trigger are set by its constructor; its timing
    // model is applied through the builder below.
    graph.set_processing_time(&names.world, timing.world.processing());
    // The sensor path (perception, world modeling, reactive layer, actuation) runs at the sensor
    // rate whatever the deliberative and planning layers do (paper 3.7, Table 6).
    graph.set_real_time(&names.world);

    let platform = parts.platform.clone();
    let perception_config = parts.perception;
    let (percepts_out, signals_out) = graph.add(&names.perception, |p| {
        p.trigger(Trigger::every(timing.perception.period(83.3)));
        p.real_time();
        p.processing_time(timing.perception.processing());
        let out = p.output::<Percepts>("percepts");
        let signals = p.output::<Signal>("signals");
        (PerceptionModule::new(platform, perception_config, out, signals), (out, signals))
    });

    let actuation_config = parts.actuation;
    let platform = parts.platform;
    let (commands_in, odometry_out, messages_out) = graph.add(&names.actuation, |p| {
        let commands = p.input::<MotionCommands>("commands", Policy::queue(16));
        let odometry = p.output::<Odometry>("odometry");
        let messages = p.output::<ActuationMessage>("messages");
        let feedback = p.output::<MotionFeedback>("feedback");
        p.trigger(Trigger::on_any([commands.into()]));
        p.real_time();
        p.processing_time(timing.actuation.processing());
        let module = ActuationModule::new(
            platform,
            actuation_config,
            commands,
            odometry,
            messages,
            feedback,
        );
        (module, (commands, odometry, messages))
    });

    let layer = parts.reactive;
    let reactive = graph.add(&names.reactive, |p| {
        let ports = ReactivePorts {
            percepts: p.input("percepts", Policy::Latest),
            world: p.input("world", Policy::Latest),
            deliberative: p.input("deliberative", Policy::Latest),
            actuation: p.input("actuation", Policy::queue(64)),
            commands: p.output("commands"),
            report: p.output("report"),
            stability: p.output("stability"),
        };
        p.trigger(Trigger::on_any([ports.percepts.into()]));
        p.real_time();
        p.processing_time(timing.reactive.processing());
        (ReactiveModule::new(layer, ports), ports)
    });

    let policy = parts.deliberative;
    let load = parts.deliberative_load;
    let deliberative = graph.add(&names.deliberative, |p| {
        let ports = DeliberativePorts {
            world: p.input("world", Policy::Latest),
            assignment: p.input("assignment", Policy::Latest),
            stability: p.input("stability", Policy::Latest),
            output: p.output("scores"),
        };
        p.trigger(Trigger::every(timing.deliberative.period(1.6)));
        p.processing_time(timing.deliberative.processing());
        let mut module = DeliberativeModule::new(policy, ports);
        module.artificial_load = load;
        (module, ports)
    });

    let (player, planner, codec, referee) =
        (parts.player, parts.planner, parts.codec, parts.referee);
    let (team_link, external_link, shared) =
        (parts.team_link, parts.external_link, parts.shared_objects);
    let planning = graph.add(&names.planning, |p| {
        let ports = PlanningPorts {
            world: p.input("world", Policy::Latest),
            stability: p.input("stability", Policy::Latest),
            signals: p.input("signals", Policy::queue(32)),
            decision: p.output("decision"),
            team_estimates: p.output("team_estimates"),
            world_commands: p.output("world_commands"),
        };
        p.trigger(Trigger::every(timing.planning.period(10.0)));
        p.processing_time(timing.planning.processing());
        let module = PlanningModule::new(
            player,
            planner,
            codec,
            referee,
            team_link,
            external_link,
            ports,
            shared,
        );
        (module, ports)
    });

    graph.fan_out(percepts_out, [reactive.percepts, world.percepts]);
    graph.fan_out(world.world_state, [reactive.world, deliberative.world, planning.world]);
    graph.connect(reactive.commands, commands_in);
    graph.connect(odometry_out, world.odometry);
    graph.connect(messages_out, reactive.actuation);
    graph.fan_out(reactive.stability, [deliberative.stability, planning.stability]);
    graph.connect(deliberative.output, reactive.deliberative);
    graph.connect(planning.decision, deliberative.assignment);
    graph.connect(planning.team_estimates, world.team);
    graph.connect(planning.world_commands, world.commands);
    graph.connect(signals_out, planning.signals);
    Ok(names)
}
