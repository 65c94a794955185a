//! The soccer robot's modules for `strata replay`: how to rebuild each replayable module of a
//! logged match, robot or experiment from the run's configuration (`logging::RunConfig` of a
//! match, `logging::RobotRunConfig` of `strata robot --log`, one per robot in
//! `experiments::ExperimentRunConfig`; stored in the log, with the `--set` overrides applied).
//!
//! | module | replayable | why |
//! |---|---|---|
//! | `perception` | yes | reads only packages (the platform's sensor frames); deterministic |
//! | `world` | yes | reads only packages (percepts, odometry, teammates' estimates, commands); deterministic |
//! | `reactive` | yes | reads only packages (percepts, world state, score vectors, actuation messages) |
//! | `deliberative` | yes | reads only packages (world state, planning decision, stability) |
//! | `actuation` | yes | reads only packages (commands, the platform's motion feedback, refused orders) |
//! | `planning` | yes, from a match's log | reads only packages (what the links received, world state, stability, signals); a robot's or an experiment's log lacks its team number and half duration |
//! | `sensors`, `actuators`, `links_in`, `links_out` | no | the platform and the links themselves (the edge of the graph) |
//!
//! Each module is added by the same function the robot's assembly uses
//! (`strata_robot::assembly::add_perception`, ...), so its ports, policies and trigger are
//! declared once. The modules that read the world state replay exactly only from a log with
//! every world-state package (`--log-world-hz 0`, the default); the world model itself needs
//! the world-state packages only for the comparison.

use std::sync::Arc;

use serde::de::DeserializeOwned;
use serde_json::Value;
use strata_log::replay::{BuildError, ModuleRegistry, ModuleSpec};
use strata_robot::actuation::ActuationConfig;
use strata_robot::assembly::{
    RobotTiming, add_actuation, add_deliberative, add_perception, add_planning, add_reactive,
};
use strata_robot::control::planning_module::PlanningModule;
use strata_robot::platform::PlatformInfo;
use strata_robot::world::{WorldModelConfig, add_world_module};
use strata_soccer::field::TeamField;
use strata_soccer::planning::SoccerCodec;
use strata_soccer::team::{
    TeamConfig, deliberative_behavior, perception_config, planning_parts, reactive_layer,
    shared_objects,
};
use strata_spl::field::{Field, FieldDimensions};

use crate::logging::RunConfig;

/// Module kinds of a soccer robot that cannot be replayed, and why.
const NOT_REPLAYABLE: [(&str, &str); 4] = [
    (
        "sensors",
        "`sensors` is the platform itself (the edge of the graph): replay perception or actuation, which read what it published",
    ),
    (
        "actuators",
        "`actuators` is the platform itself (the edge of the graph): replay actuation, whose orders it wrote",
    ),
    (
        "links_in",
        "`links_in` is the robot's links themselves (the edge of the graph): replay planning, which read what it published",
    ),
    (
        "links_out",
        "`links_out` is the robot's links themselves (the edge of the graph): replay planning, whose messages it sent",
    ),
];

/// The registry of the soccer robot of `strata match`: `perception`, `world`, `reactive`,
/// `deliberative` and `actuation` of any robot (`--robot home/3`).
pub fn soccer() -> ModuleRegistry {
    let mut registry = ModuleRegistry::new();
    registry.register("perception", |graph, spec| {
        let robot = Robot::of(spec)?;
        let team = robot.team_config()?;
        let info: PlatformInfo = robot.get(&["platform"])?;
        let timing = team.timing.resolved();
        let camera = robot.world_config()?.camera;
        add_perception(
            graph,
            spec.name,
            info,
            perception_config(&team),
            camera,
            &timing.perception,
        );
        Ok(())
    });
    registry.register("world", |graph, spec| {
        let robot = Robot::of(spec)?;
        let world = robot.world_config()?;
        let timing = robot.timing()?;
        add_world_module(graph, spec.name, world)?;
        graph.set_processing_time(spec.name, timing.world.processing());
        Ok(())
    });
    registry.register("reactive", |graph, spec| {
        let robot = Robot::of(spec)?;
        let team = robot.team_config()?;
        let info: PlatformInfo = robot.get(&["platform"])?;
        let field = robot.team_field()?;
        let layer = reactive_layer(&team, &info, &field);
        let timing = team.timing.resolved();
        add_reactive(graph, spec.name, layer, &timing.reactive);
        Ok(())
    });
    registry.register("deliberative", |graph, spec| {
        let robot = Robot::of(spec)?;
        let team = robot.team_config()?;
        let info: PlatformInfo = robot.get(&["platform"])?;
        let field = robot.team_field()?;
        let policy = deliberative_behavior(&team, &info, &field, robot.player)?;
        let timing = team.timing.resolved();
        add_deliberative(graph, spec.name, policy, &timing.deliberative);
        Ok(())
    });
    registry.register("planning", |graph, spec| {
        let robot = Robot::of(spec)?;
        let team = robot.team_config()?;
        let field = robot.team_field()?;
        let (team_number, half_duration) = robot.game()?;
        let (planner, referee) =
            planning_parts(&team, &field, robot.player, team_number, half_duration);
        let timing = team.timing.resolved();
        add_planning(graph, spec.name, &timing.planning, |ports| {
            PlanningModule::new(
                robot.player,
                planner,
                SoccerCodec,
                referee,
                ports,
                shared_objects(),
            )
        });
        Ok(())
    });
    registry.register("actuation", |graph, spec| {
        let robot = Robot::of(spec)?;
        let team = robot.team_config()?;
        let config: ActuationConfig = team.actuation.clone();
        let timing = team.timing.resolved();
        add_actuation(graph, spec.name, config, &timing.actuation);
        Ok(())
    });
    for (kind, why) in NOT_REPLAYABLE {
        registry
            .register(kind, move |_, _| Err(format!("`{kind}` cannot be replayed: {why}").into()));
    }
    registry
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

    /// The robot's team number and the half's length, s: a match's log holds them, a robot's
    /// own log does not.
    fn game(&self) -> Result<(u8, f64), BuildError> {
        match self.layout {
            Layout::Match { team } => {
                let numbers: [u8; 2] = self.get(&["team_numbers"])?;
                let number = if team == "home" { numbers[0] } else { numbers[1] };
                Ok((number, self.get(&["half_duration"])?))
            }
            Layout::Robot => Err(format!(
                "robot `{}`: the planning layer replays from a match's log only (a robot's or an \
                 experiment's log does not hold its team number and the half's length)",
                self.name
            )
            .into()),
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
