//! Goals and their resources (paper Table 3). Each multiplexer has its own goal type, so a goal
//! cannot be sent to a resource that cannot pursue it.

use serde::{Deserialize, Serialize};
use strata_robot::control::scores::Goal;
use strata_robot::geometry::{Global, Point, Pose};

use crate::primitives::{BodyPrimitive, HeadPrimitive, WholeBodyPrimitive};

/// Which goal, from this team's point of view.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GoalSide {
    Own,
    Opponent,
}

/// Goals of the head (Table 3).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HeadGoal {
    ObserveBall,
    ObserveGoal {
        side: GoalSide,
    },
    ObserveFieldLine {
        line: u8,
    },
    /// The deliberative layer passes where the partner last reported itself.
    ObservePartner {
        player: u8,
        position: Point<Global>,
    },
    ObserveRival {
        player: u8,
    },
    /// A landmark of interest by world-model name (a beacon on the paper's field, a goal post):
    /// what active vision asks the head to look at to localize.
    ObserveLandmark {
        name: String,
    },
    /// A fixed head scan, whatever the situation (the baseline many SPL teams use).
    Scan,
    /// The head referee, where the rules put it (team frame): in Standby robots watch it for
    /// the Ready gesture.
    ObserveReferee {
        position: Point<Global>,
    },
    /// Several objects in one gaze; split by the multiplexer when they do not fit (stage 1).
    ObserveTogether {
        objects: Vec<String>,
    },
}

impl Goal for HeadGoal {
    type Primitive = HeadPrimitive;

    fn label(&self) -> String {
        match self {
            HeadGoal::ObserveBall => "observe ball".into(),
            HeadGoal::ObserveGoal { side: GoalSide::Own } => "observe own goal".into(),
            HeadGoal::ObserveGoal { side: GoalSide::Opponent } => "observe opponent goal".into(),
            HeadGoal::ObserveFieldLine { line } => format!("observe field line {line}"),
            HeadGoal::ObservePartner { player, .. } => format!("observe partner {player}"),
            HeadGoal::ObserveRival { player } => format!("observe rival {player}"),
            HeadGoal::ObserveLandmark { name } => format!("observe {name}"),
            HeadGoal::ObserveTogether { objects } => format!("observe {}", objects.join("+")),
            HeadGoal::Scan => "scan".into(),
            HeadGoal::ObserveReferee { .. } => "observe referee".into(),
        }
    }
}

/// Kicks of the simulator's and the robot's motion catalogue.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kick {
    /// A strong kick straight ahead (shots).
    Forward,
    /// A softer kick straight ahead (passes, clearing).
    Pass,
    SideLeft,
    SideRight,
}

impl Kick {
    /// The sequence number in the platform's motion catalogue.
    pub fn sequence(self) -> u8 {
        match self {
            Kick::Forward => 0,
            Kick::Pass => 1,
            Kick::SideLeft => 2,
            Kick::SideRight => 3,
        }
    }

    /// Direction of the ball relative to the robot's heading.
    pub fn direction(self) -> f64 {
        match self {
            Kick::Forward | Kick::Pass => 0.0,
            Kick::SideLeft => std::f64::consts::FRAC_PI_2,
            Kick::SideRight => -std::f64::consts::FRAC_PI_2,
        }
    }
}

/// Goals of the body (Table 3).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BodyGoal {
    /// Turn to face a target while standing.
    ObserveTarget {
        target: Point<Global>,
    },
    GoToPosition {
        pose: Pose,
    },
    /// Go to the ball and kick it toward `target` with `kick`.
    GoToBallAndKick {
        kick: Kick,
        target: Point<Global>,
    },
    /// Stand still (Initial, Set, penalized).
    Stand,
}

impl Goal for BodyGoal {
    type Primitive = BodyPrimitive;

    fn label(&self) -> String {
        match self {
            BodyGoal::ObserveTarget { .. } => "observe target".into(),
            BodyGoal::GoToPosition { .. } => "go to position".into(),
            BodyGoal::GoToBallAndKick { kick, .. } => {
                format!("go to ball and kick ({kick:?})").to_lowercase()
            }
            BodyGoal::Stand => "stand".into(),
        }
    }
}

/// Goals that need head and body together (Table 3).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WholeBodyGoal {
    GoToBallAndDribble { target: Point<Global> },
    StandUp { sequence: u8 },
    Fall { sequence: u8 },
    Dive { sequence: u8 },
}

impl Goal for WholeBodyGoal {
    type Primitive = WholeBodyPrimitive;

    fn label(&self) -> String {
        match self {
            WholeBodyGoal::GoToBallAndDribble { .. } => "go to ball and dribble".into(),
            WholeBodyGoal::StandUp { .. } => "stand-up".into(),
            WholeBodyGoal::Fall { .. } => "fall".into(),
            WholeBodyGoal::Dive { .. } => "dive".into(),
        }
    }
}
