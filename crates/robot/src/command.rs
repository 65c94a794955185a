//! Commands from the reactive layer to actuation, and actuation's messages back (paper 3.5.1).
//!
//! The robot's resources are its head and its body; stand-up, fall and dive need both. A
//! [`MotionCommands`] value holds at most one command per resource: two primitive behaviors
//! commanding the same resource in one cycle cannot be expressed.

use serde::{Deserialize, Serialize};

use crate::geometry::{Odometry, Velocity};
use crate::platform::{HeadAngles, SpecialMotion};

/// A joint or group of joints that must work together to reach a goal.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Resource {
    Head,
    Body,
}

impl Resource {
    pub const ALL: [Resource; 2] = [Resource::Head, Resource::Body];
}

/// The resources a primitive behavior needs; each group has its own multiplexer.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ResourceGroup {
    Head,
    Body,
    HeadAndBody,
}

impl ResourceGroup {
    pub const ALL: [ResourceGroup; 3] =
        [ResourceGroup::Head, ResourceGroup::Body, ResourceGroup::HeadAndBody];

    pub fn uses(&self, resource: Resource) -> bool {
        matches!(
            (self, resource),
            (ResourceGroup::HeadAndBody, _)
                | (ResourceGroup::Head, Resource::Head)
                | (ResourceGroup::Body, Resource::Body)
        )
    }

    /// Whether two groups share a resource (and so inhibit each other).
    pub fn overlaps(&self, other: ResourceGroup) -> bool {
        Resource::ALL.iter().any(|r| self.uses(*r) && other.uses(*r))
    }

    pub fn name(&self) -> &'static str {
        match self {
            ResourceGroup::Head => "head",
            ResourceGroup::Body => "body",
            ResourceGroup::HeadAndBody => "head+body",
        }
    }
}

/// The three ways a primitive behavior can hand a command to actuation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CommandPolicy {
    /// Appended to the resource's queue: continuous movement without initialization and end
    /// stages between commands (continuous walking, a head scan path).
    Queue,
    /// Replaces everything queued.
    NonQueue,
    /// A non-parametric sequence (kick, stand-up, fall, dive).
    Special,
}

/// Move the head to `target`, no faster than `max_speed` rad/s.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HeadMotion {
    pub target: HeadAngles,
    pub max_speed: f64,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HeadCommand {
    Queue(HeadMotion),
    NonQueue(HeadMotion),
}

impl HeadCommand {
    pub fn motion(&self) -> HeadMotion {
        match self {
            HeadCommand::Queue(m) | HeadCommand::NonQueue(m) => *m,
        }
    }

    pub fn policy(&self) -> CommandPolicy {
        match self {
            HeadCommand::Queue(_) => CommandPolicy::Queue,
            HeadCommand::NonQueue(_) => CommandPolicy::NonQueue,
        }
    }
}

/// A parametric body movement.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BodyMotion {
    Stand,
    /// Walk at `velocity` for `duration` seconds of the execution stage; a queued walk that
    /// follows continues the gait without stopping.
    Walk {
        velocity: Velocity,
        duration: f64,
    },
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BodyCommand {
    Queue(BodyMotion),
    NonQueue(BodyMotion),
    /// A sequence that needs the body only (soccer's kick).
    Special(SpecialMotion),
}

impl BodyCommand {
    pub fn policy(&self) -> CommandPolicy {
        match self {
            BodyCommand::Queue(_) => CommandPolicy::Queue,
            BodyCommand::NonQueue(_) => CommandPolicy::NonQueue,
            BodyCommand::Special(_) => CommandPolicy::Special,
        }
    }
}

/// A command of the head+body multiplexer: both resources serve one goal.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WholeBodyCommand {
    /// A sequence that needs head and body together (stand-up, fall, dive).
    Special { motion: SpecialMotion },
    /// Parametric head and body commands computed together (dribbling: the head keeps the ball
    /// in view while the body walks it forward).
    Coordinated { head: HeadCommand, body: BodyCommand },
}

/// One reactive cycle's commands: at most one per resource, by construction.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MotionCommands {
    PerResource {
        head: Option<HeadCommand>,
        body: Option<BodyCommand>,
    },
    /// The head+body multiplexer holds both resources.
    WholeBody {
        command: WholeBodyCommand,
    },
}

impl Default for MotionCommands {
    fn default() -> Self {
        MotionCommands::PerResource { head: None, body: None }
    }
}

impl MotionCommands {
    pub fn is_empty(&self) -> bool {
        matches!(self, MotionCommands::PerResource { head: None, body: None })
    }
}

/// Actuation's messages to the reactive layer (paper 3.5.1).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActuationMessage {
    /// Odometry of the command being executed.
    CommandOdometry { odometry: Odometry },
    /// The command on `resource` is about to finish and the resource will be released: the
    /// reactive layer is asked for the next action.
    CommandFinishing { resource: Resource, remaining: f64 },
    /// The cyclic command on `resource` is in its execution stage: it can be changed now without
    /// disturbing the robot.
    CommandCyclicPart { resource: Resource },
    /// A command could not be executed (unsupported by the platform, resource busy with a
    /// special sequence).
    CommandRejected { resource: Resource, reason: String },
    /// A special sequence took the resource: commands for it are refused until released.
    ResourceBusy { resource: Resource },
    /// The resource is free again (a special sequence ended).
    ResourceReleased { resource: Resource },
}
