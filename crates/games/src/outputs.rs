//! The outputs of a soccer robot's modules and of the simulator that taps read here, in the
//! experiments and in the viewer, by typed name: each is the module's own declaration with the
//! soccer application's types filled in, so a tap follows a renamed port and does not compile
//! against a retyped one.

use strata_robot::application::{DeliberativePortsOf, PlanningPortsOf, ReactivePortsOf};
use strata_robot::command::MotionCommands;
use strata_robot::control::reactive::ReactiveReport;
use strata_robot::world::{WorldPorts, WorldState};
use strata_runtime::PortName;
use strata_sim::{GroundTruth, SimulatorPorts};
use strata_soccer::behaviors::{Decision, Output};
use strata_soccer::team::Soccer;

/// The simulator's ground truth (module `simulator`).
pub const GROUND_TRUTH: PortName<GroundTruth> = SimulatorPorts::GROUND_TRUTH;
/// The world model's state (`home/3/world`).
pub const WORLD_STATE: PortName<WorldState> = WorldPorts::WORLD_STATE;
/// The reactive layer's motion commands, one package per cycle (`home/3/reactive`).
pub const COMMANDS: PortName<MotionCommands> = ReactivePortsOf::<Soccer>::COMMANDS;
/// The reactive layer's report of each cycle.
pub const REPORT: PortName<ReactiveReport> = ReactivePortsOf::<Soccer>::REPORT;
/// The deliberative layer's score vectors (`home/3/deliberative`).
pub const SCORES: PortName<Output> = DeliberativePortsOf::<Soccer>::SCORES;
/// The planning layer's decisions (`home/3/planning`).
pub const DECISION: PortName<Decision> = PlanningPortsOf::<Soccer>::DECISION;
