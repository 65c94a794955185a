//! The soccer robot's modules for `strata replay`: how to rebuild each replayable module of a
//! logged match, robot or experiment from the run's configuration (`logging::RunConfig` of a
//! match, `logging::RobotRunConfig` of `strata robot --log`, one per robot in
//! `experiments::ExperimentRunConfig`; stored in the log, with the `--set` overrides applied).
//!
//! | module | replayable | why |
//! |---|---|---|
//! | `world` | yes | reads only packages (percepts, odometry, teammates' estimates, commands); deterministic |
//! | `reactive` | yes | reads only packages (percepts, world state, score vectors, actuation messages) |
//! | `deliberative` | yes | reads only packages (world state, planning decision, stability) |
//! | `planning` | no | reads its team link and the GameController directly (not packages, not logged) |
//! | `perception` | no | reads the platform's sensor frames (not packages) |
//! | `actuation` | no | writes the platform and reads its motion feedback |
//!
//! The modules that read the world state replay exactly only from a log with every world-state
//! package (`--log-world-hz 0`, the default); the world model itself needs the world-state
//! packages only for the comparison.

use std::sync::Arc;
use std::time::Duration;

use serde::de::DeserializeOwned;
use serde_json::Value;
use strata_log::replay::{BuildError, ModuleRegistry, ModuleSpec};
use strata_robot::assembly::{LayerTiming, RobotTiming};
use strata_robot::control::active_vision::ActiveVisionConfig;
use strata_robot::control::modules::{
    DeliberativeModule, DeliberativePorts, ReactiveModule, ReactivePorts,
};
use strata_robot::platform::PlatformInfo;
use strata_robot::world::{WorldModelConfig, add_world_module};
use strata_runtime::{GraphBuilder, Policy, ProcessingTime, Trigger};
use strata_soccer::behaviors::SoccerBehavior;
use strata_soccer::field::TeamField;
use strata_soccer::team::{TeamConfig, reactive_layer};
use strata_spl::field::{Field, FieldDimensions};

use crate::logging::RunConfig;

/// Module kinds of a soccer robot that cannot be replayed, and why.
const NOT_REPLAYABLE: [(&str, &str); 3] = [
    (
        "planning",
        "the planning layer reads its team link and the GameController directly; what they said is not a package and is not in the log",
    ),
    (
        "perception",
        "perception reads the platform's sensor frames, which are not packages and not in the log",
    ),
    (
        "actuation",
        "actuation writes to the platform and reads its motion feedback, which is not in the log",
    ),
];

/// The registry of the soccer robot of `strata match`: `world`, `reactive` and
/// `deliberative` of any robot (`--robot home/3`).
pub fn soccer() -> ModuleRegistry {
    let mut registry = ModuleRegistry::new();
    registry.register("world", |graph, spec| {
        let robot = Robot::of(spec)?;
        let world = robot.world_config()?;
        let timing = robot.timing()?;
        add_world_module(graph, spec.name, world)?;
        graph.set_processing_time(spec.name, processing(&timing.world));
        Ok(())
    });
    registry.register("reactive", |graph, spec| {
        let robot = Robot::of(spec)?;
        let team = robot.team_config()?;
        let info: PlatformInfo = robot.get(&["platform"])?;
        let field = robot.team_field()?;
        let layer = reactive_layer(&team, &info, &field);
        let timing = team.timing.resolved();
        add_reactive(graph, spec.name, layer, processing(&timing.reactive));
        Ok(())
    });
    registry.register("deliberative", |graph, spec| {
        let robot = Robot::of(spec)?;
        let team = robot.team_config()?;
        let info: PlatformInfo = robot.get(&["platform"])?;
        let field = robot.team_field()?;
        // As `add_soccer_robot` builds it.
        let vision = ActiveVisionConfig {
            fov: info.camera_fov,
            range: info.camera_range,
            yaw_limits: info.head_yaw_limits,
            ..ActiveVisionConfig::default()
        };
        let motion = Arc::new(team.motion.clone());
        let policy =
            SoccerBehavior::new(robot.player, field, team.behavior.clone(), vision, motion)?;
        let timing = team.timing.resolved();
        let load = Duration::try_from_secs_f64(team.deliberative_load).unwrap_or_default();
        graph.add(spec.name, |p| {
            let ports = DeliberativePorts {
                world: p.input("world", Policy::Latest),
                assignment: p.input("assignment", Policy::Latest),
                stability: p.input("stability", Policy::Latest),
                output: p.output("scores"),
            };
            p.trigger(Trigger::every(period(&timing.deliberative, 1.6)));
            p.processing_time(processing(&timing.deliberative));
            let mut module = DeliberativeModule::new(policy, ports);
            module.artificial_load = load;
            (module, ())
        });
        Ok(())
    });
    for (kind, why) in NOT_REPLAYABLE {
        registry
            .register(kind, move |_, _| Err(format!("`{kind}` cannot be replayed: {why}").into()));
    }
    registry
}

/// The reactive layer's module, wired as `strata_robot::assembly::add_robot` wires it.
fn add_reactive(
    graph: &mut GraphBuilder,
    name: &str,
    layer: strata_soccer::team::SoccerReactiveLayer,
    processing_time: ProcessingTime,
) {
    graph.add(name, |p| {
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
        p.processing_time(processing_time);
        (ReactiveModule::new(layer, ports), ())
    });
}

/// A layer's processing-time model, as the assembly resolves it.
fn processing(timing: &LayerTiming) -> ProcessingTime {
    timing.processing_time.clone().unwrap_or_default()
}

/// A periodic layer's period, as the assembly resolves it.
fn period(timing: &LayerTiming, default_hz: f64) -> Duration {
    let hz = timing.rate_hz.filter(|hz| hz.is_finite() && *hz > 0.0).unwrap_or(default_hz);
    Duration::from_secs_f64(1.0 / hz)
}

/// The robot a module belongs to, and the run configuration it is rebuilt from.
struct Robot<'a> {
    name: &'a str,
    layout: Layout,
    player: u8,
    config: &'a Value,
}

/// Where a robot's configuration sits in the logged one.
#[derive(Clone, Copy)]
enum Layout {
    /// A match's log ([`RunConfig`]): per team, `home` or `away`.
    Match { team: &'static str },
    /// A robot's own log ([`crate::logging::RobotRunConfig`]), or one robot's entry in an
    /// experiment's log.
    Robot,
}

impl<'a> Robot<'a> {
    fn of(spec: &ModuleSpec<'a>) -> Result<Robot<'a>, BuildError> {
        const NAMES: &str = "expected home/N or away/N (a match's log) or tT/N (a robot's log)";
        let name = spec.robot.ok_or("give the robot whose module to replay (--robot home/3)")?;
        let player = name
            .rsplit('/')
            .next()
            .and_then(|p| p.parse().ok())
            .ok_or_else(|| format!("robot `{name}`: {NAMES}"))?;
        if spec.config.as_object().is_none_or(|c| c.is_empty()) {
            return Err("the log holds no configuration to rebuild the robot's modules from \
                        (it was not written by `strata match --log` or `strata robot --log`)"
                .into());
        }
        // An experiment's log keeps each robot's configuration under `robots`, laid out as a
        // robot's own log keeps its one.
        if let Some(robots) = spec.config.get("robots").and_then(Value::as_object) {
            let config = robots.get(name).ok_or_else(|| {
                let names: Vec<&str> = robots.keys().map(String::as_str).collect();
                format!(
                    "robot `{name}` is not in this experiment's log; it has {}",
                    names.join(", ")
                )
            })?;
            return Ok(Robot { name, layout: Layout::Robot, player, config });
        }
        let layout = match RunConfig::team_of(name) {
            Some(team) => Layout::Match { team },
            None if name.starts_with('t') => {
                let logged: Option<&str> = spec.config.get("robot").and_then(Value::as_str);
                if logged != Some(name) {
                    return Err(format!(
                        "robot `{name}` is not in this log (it is {})",
                        logged.map_or("a match's log".to_owned(), |r| format!("robot {r}'s log"))
                    )
                    .into());
                }
                Layout::Robot
            }
            None => return Err(format!("robot `{name}`: {NAMES}").into()),
        };
        Ok(Robot { name, layout, player, config: spec.config })
    }

    /// The value at `path` of the run configuration.
    fn get<T: DeserializeOwned>(&self, path: &[&str]) -> Result<T, BuildError> {
        let mut value = self.config;
        for key in path {
            value = value
                .get(key)
                .ok_or_else(|| format!("the logged configuration has no `{}`", path.join(".")))?;
        }
        T::deserialize(value).map_err(|e| {
            format!("the logged configuration's `{}` cannot be used: {e}", path.join(".")).into()
        })
    }

    fn team_config(&self) -> Result<TeamConfig, BuildError> {
        let (path, team) = match self.layout {
            Layout::Match { team } => (team, team),
            Layout::Robot => ("team", "of the robot"),
        };
        let config: TeamConfig = self.get(&[path])?;
        config.validate(&format!("the logged team `{team}` of {}", self.name))?;
        Ok(config)
    }

    fn world_config(&self) -> Result<WorldModelConfig, BuildError> {
        match self.layout {
            Layout::Match { team } => self.get(&["world", team]),
            Layout::Robot => self.get(&["world"]),
        }
    }

    fn timing(&self) -> Result<RobotTiming, BuildError> {
        Ok(self.team_config()?.timing.resolved())
    }

    /// The field as the robot's team saw it at kick-off.
    fn team_field(&self) -> Result<Arc<TeamField>, BuildError> {
        let dimensions: FieldDimensions = self.get(&["field"])?;
        let field = Field::new(dimensions, "the logged field")?;
        let sign = match self.layout {
            Layout::Match { team } => {
                let signs: [f64; 2] = self.get(&["attack_sign"])?;
                if team == "home" { signs[0] } else { signs[1] }
            }
            Layout::Robot => self.get(&["attack_sign"])?,
        };
        Ok(Arc::new(TeamField::new(field, sign)))
    }
}
