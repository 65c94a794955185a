//! What an application brings to a robot, named once: its planning policy (missions and
//! roles), its external device, its team messages' wire format and its deliberative layer,
//! whose goal types name the reactive layer's. [`crate::assembly::RobotParts`] and
//! [`crate::assembly::add_robot`] take one [`Application`] instead of a type parameter for each.
//!
//! A robot that works alone writes no team planning, codec or device: [`Alone`],
//! [`NoCodec`] and [`NoDevice`] stand in for them.

use crate::control::deliberative::DeliberativePolicy;
use crate::control::modules::{PolicyPorts, ReactivePorts};
use crate::control::planning::PlanningPolicy;
pub use crate::control::planning::{Alone, Solo};
pub use crate::control::planning_module::{ExternalDevice, NoCodec, NoDevice, TeamCodec};
use crate::control::planning_module::{PlanningDecision, PlanningPorts};
use crate::world::WorldState;

/// One application's types. Soccer's is `strata_soccer::team::Soccer`; `examples/patrol`
/// has `Patrol`.
pub trait Application: 'static {
    /// MAMS and ARS: the application's missions and roles ([`Alone`] for a lone robot).
    type Planning: PlanningPolicy + 'static;
    /// The device that directs the robot, a GameController in soccer ([`NoDevice`] for none).
    type Device: ExternalDevice + 'static;
    /// Team messages as bytes ([`NoCodec`] for a robot without teammates).
    type Codec: TeamCodec<MissionOf<Self>, RoleOf<Self>> + 'static;
    /// The deliberative layer, handed the planning layer's assignment; its goal types are the
    /// reactive layer's.
    type Deliberative: DeliberativePolicy<World = WorldState, Assignment = AssignmentOf<Self>>
        + 'static;
}

/// An application's missions.
pub type MissionOf<A> = <<A as Application>::Planning as PlanningPolicy>::Mission;
/// An application's roles.
pub type RoleOf<A> = <<A as Application>::Planning as PlanningPolicy>::Role;
/// What an application's device tells the deliberative layer.
pub type DirectiveOf<A> = <<A as Application>::Device as ExternalDevice>::Directive;
/// What the planning layer hands an application's deliberative layer.
pub type AssignmentOf<A> = PlanningDecision<MissionOf<A>, RoleOf<A>, DirectiveOf<A>>;
/// An application's head goals (the head multiplexer's).
pub type HeadGoalOf<A> = <<A as Application>::Deliberative as DeliberativePolicy>::HeadGoal;
/// An application's body goals (the body multiplexer's).
pub type BodyGoalOf<A> = <<A as Application>::Deliberative as DeliberativePolicy>::BodyGoal;
/// An application's head-and-body goals (the whole-body multiplexer's).
pub type WholeBodyGoalOf<A> =
    <<A as Application>::Deliberative as DeliberativePolicy>::WholeBodyGoal;

/// The ports of an application's reactive layer: `ReactivePortsOf::<Soccer>::REPORT` names the
/// output a tap finds the soccer robot's reactive reports on.
pub type ReactivePortsOf<A> =
    ReactivePorts<HeadGoalOf<A>, BodyGoalOf<A>, WholeBodyGoalOf<A>, WorldState>;
/// The ports of an application's deliberative layer.
pub type DeliberativePortsOf<A> = PolicyPorts<<A as Application>::Deliberative>;
/// The ports of an application's planning layer.
pub type PlanningPortsOf<A> = PlanningPorts<MissionOf<A>, RoleOf<A>, DirectiveOf<A>>;
