//! The reactive layer (paper 3.5): primitive behaviors, resource multiplexers and their
//! activation function, inhibition between resources, and fall detection.
//!
//! Every reactive cycle (one per percept):
//! 1. The fall detector classifies the robot's stability from the newest inertial data.
//! 2. Each multiplexer — head+body first — runs its activation function on the score vector the
//!    deliberative layer last sent: stage 1 lets the application split goals that cannot be
//!    executed together now (two objects that do not fit in one gaze); stage 2 computes each
//!    goal's reactive score S_r from the newest percepts and combines it with the deliberative
//!    score S_d (the average, by default). S_d is never changed here: the reactive layer only
//!    rescales, it never changes the goals. A policy whose answers read the world state and
//!    little else ([`ActivationShortcuts::reuse_key`]) is asked again only when a new world state
//!    or score vector has arrived or that little else changed; in between its answers could not
//!    change, and are reused.
//! 3. The goal with the highest final score among those some primitive behavior can pursue now
//!    (chosen from perceptual data, skipping primitives the deliberative layer deactivated) is
//!    selected, and that primitive is activated. The head+body multiplexer's selection inhibits
//!    the head and body multiplexers when its final score is at least theirs; otherwise it
//!    yields and they run independently (their resources are disjoint, so their primitives are
//!    orthogonal).
//! 4. The active primitives compute this cycle's commands: a [`MotionCommands`] value, which
//!    cannot hold two commands for one resource.
//!
//! One file per part: the fall detector (`fall.rs`), what actuation reports
//! (`actuation_status.rs`), the application's policy traits (`policy.rs`), the multiplexer
//! (`multiplexer.rs`) and its activation function (`activation.rs`), the layer that runs them
//! (`layer.rs`), the reports (`report.rs`) and how they are written (`encoding.rs`). The types
//! logs name (the layer's outputs and the goal labels) are defined here, see below.

mod activation;
mod actuation_status;
mod encoding;
mod fall;
mod layer;
mod multiplexer;
mod policy;
mod report;

use serde::{Deserialize, Serialize};
use strata_runtime::Time;

use crate::command::MotionCommands;
use crate::platform::FallDirection;

pub use actuation_status::ActuationStatus;
pub use fall::{FallDetector, FallDetectorConfig};
pub use layer::ReactiveLayer;
pub use multiplexer::{Multiplexer, MultiplexerConfig, Selection};
pub use policy::{
    ActivationPolicy, ActivationShortcuts, GoalNotes, NoActivation, PrimitiveBehavior,
    ReactiveInput,
};
pub use report::{GoalReport, GoalReports, MuxReport};

// The types below are defined here rather than beside their parts (`fall.rs`, `report.rs`):
// a log records the Rust type name, module path included, of every package and shared value it
// holds, and replay refuses a module whose port types' names differ from the logged ones; here
// they keep the path that logs written before the split hold.

/// How stable the robot is, from its inertial sensors (the paper's standing status: stable,
/// unstable or fallen).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stability {
    #[default]
    Stable,
    /// Falling: the tilt will pass the point of no return; protect the robot now.
    Unstable(FallDirection),
    /// Lying on the ground.
    Fallen(FallDirection),
}

impl Stability {
    pub fn is_stable(&self) -> bool {
        matches!(self, Stability::Stable)
    }
}

/// The labels of a multiplexer's scored goals, in order.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GoalLabels(pub Vec<GoalLabel>);

impl std::ops::Deref for GoalLabels {
    type Target = [GoalLabel];

    fn deref(&self) -> &[GoalLabel] {
        &self.0
    }
}

/// What a scored goal is: its label, the objects it concerns and its deliberative score.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GoalLabel {
    pub goal: std::sync::Arc<str>,
    pub objects: std::sync::Arc<[String]>,
    /// S_d
    pub deliberative: f64,
}

impl GoalLabel {
    /// Whether `report` has this label: the same texts (usually the very same shared ones) and
    /// the same deliberative score, bit for bit.
    fn labels(&self, report: &GoalReport) -> bool {
        let same_goal =
            std::sync::Arc::ptr_eq(&self.goal, &report.goal) || self.goal == report.goal;
        let same_objects = std::sync::Arc::ptr_eq(&self.objects, &report.objects)
            || self.objects == report.objects;
        same_goal && same_objects && self.deliberative.to_bits() == report.deliberative.to_bits()
    }
}

/// Everything the reactive layer decided in one cycle.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ReactiveReport {
    pub stamp: Time,
    pub stability: Stability,
    pub head: MuxReport,
    pub body: MuxReport,
    pub whole_body: MuxReport,
    pub commands: MotionCommands,
}

impl ReactiveReport {
    /// "head: observe ball > object tracking | body: go to position > go to position".
    pub fn active_path(&self) -> String {
        let part =
            |name: &str, r: &MuxReport| match (&r.selected_goal, &r.primitive, r.inhibited_by) {
                (Some(goal), Some(primitive), _) => format!("{name}: {goal} > {primitive}"),
                (_, _, Some(by)) => format!("{name}: inhibited by {}", by.name()),
                _ => format!("{name}: idle"),
            };
        format!(
            "{} | {} | {}",
            part("head+body", &self.whole_body),
            part("head", &self.head),
            part("body", &self.body)
        )
    }
}
