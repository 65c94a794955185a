//! Goals and their resources (the patrol's Table 3). Each multiplexer has its own goal type, so
//! a goal cannot be sent to a resource that cannot pursue it.

use serde::{Deserialize, Serialize};
use strata_robot::control::scores::Goal;
use strata_robot::geometry::{Global, Point, Pose};

use crate::primitives::{BodyPrimitive, HeadPrimitive, WholeBodyPrimitive};

/// Goals of the head: the sensing primitives active vision chooses among.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "goal", rename_all = "snake_case")]
pub enum HeadGoal {
    /// Look at point of interest `poi` (index in the floor plan) to localize it.
    InspectPoint {
        poi: u8,
    },
    /// Look at a landmark (world-model name, `corner#2` for an instance) to localize the robot.
    ObserveLandmark {
        name: String,
    },
    ObserveIntruder,
    /// Look at a place on the floor (the alarm's location before anything is seen there).
    LookAt {
        target: Point<Global>,
    },
    /// A fixed head sweep, whatever the situation.
    Scan,
}

impl Goal for HeadGoal {
    type Primitive = HeadPrimitive;

    fn label(&self) -> String {
        match self {
            HeadGoal::InspectPoint { poi } => format!("{INSPECT_PREFIX}{poi}"),
            HeadGoal::ObserveLandmark { name } => format!("{LOCALIZE_PREFIX}{name}"),
            HeadGoal::ObserveIntruder => "observe intruder".into(),
            HeadGoal::LookAt { .. } => "look at".into(),
            HeadGoal::Scan => "scan".into(),
        }
    }
}

const INSPECT_PREFIX: &str = "inspect poi_";
const LOCALIZE_PREFIX: &str = "observe ";

/// What a head goal is for, read back from its label (as the reactive report carries it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GazeKind {
    /// Looking at a point of interest.
    Inspecting,
    /// Looking at a landmark.
    Localizing,
    Other,
}

impl GazeKind {
    pub fn of_label(label: &str) -> GazeKind {
        if label.starts_with(INSPECT_PREFIX) {
            GazeKind::Inspecting
        } else if label.starts_with(LOCALIZE_PREFIX) && label != "observe intruder" {
            GazeKind::Localizing
        } else {
            GazeKind::Other
        }
    }
}

/// Goals of the body.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "goal", rename_all = "snake_case")]
pub enum BodyGoal {
    /// Walk to `pose`. With `stop`, settle there at its heading; without, walk through it at
    /// speed (an intermediate point of a planned path).
    GoToWaypoint {
        pose: Pose,
        stop: bool,
    },
    Stand,
}

impl Goal for BodyGoal {
    type Primitive = BodyPrimitive;

    fn label(&self) -> String {
        match self {
            BodyGoal::GoToWaypoint { stop: true, .. } => "go to position".into(),
            BodyGoal::GoToWaypoint { stop: false, .. } => "go through waypoint".into(),
            BodyGoal::Stand => "stand".into(),
        }
    }
}

/// Goals that need head and body together: a humanoid's reflexes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "goal", rename_all = "snake_case")]
pub enum WholeBodyGoal {
    Fall { sequence: u8 },
    StandUp { sequence: u8 },
}

impl Goal for WholeBodyGoal {
    type Primitive = WholeBodyPrimitive;

    fn label(&self) -> String {
        match self {
            WholeBodyGoal::Fall { .. } => "fall".into(),
            WholeBodyGoal::StandUp { .. } => "stand-up".into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_tell_inspecting_from_localizing() {
        let kind = |g: HeadGoal| GazeKind::of_label(&g.label());
        assert_eq!(kind(HeadGoal::InspectPoint { poi: 2 }), GazeKind::Inspecting);
        assert_eq!(
            kind(HeadGoal::ObserveLandmark { name: "marker_3".into() }),
            GazeKind::Localizing
        );
        assert_eq!(
            kind(HeadGoal::ObserveLandmark { name: "corner#1".into() }),
            GazeKind::Localizing
        );
        assert_eq!(kind(HeadGoal::ObserveIntruder), GazeKind::Other);
        assert_eq!(kind(HeadGoal::Scan), GazeKind::Other);
    }
}
