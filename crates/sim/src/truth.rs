//! Ground truth: what really happened, for experiments, logs and viewers — never for robots.

use serde::{Deserialize, Serialize};
use strata_robot::platform::{BodyMotionState, FallDirection, HeadAngles, SpecialMotion};
use strata_robot::{Global as FieldFrame, Point, Pose, Vector};
use strata_runtime::Time;
use strata_spl::field::BallStatus;
use strata_spl::gamecontroller::{GameState, Penalty, SetPlay};

use crate::body::FallCause;

/// A robot slot: team index (0 or 1, the order of `referee.teams`) and player number (1..=N).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct RobotId {
    /// Index of the team in the configuration (0 or 1), not its team number.
    pub team: usize,
    /// Player number, 1..=players_per_team.
    pub player: u8,
}

impl RobotId {
    pub const fn new(team: usize, player: u8) -> RobotId {
        RobotId { team, player }
    }
}

impl std::fmt::Display for RobotId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "team {} player {}", self.team, self.player)
    }
}

/// One robot's true state.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RobotTruth {
    pub id: RobotId,
    pub team_number: u8,
    /// On the field or held by the referee (false: not in the world at all).
    pub present: bool,
    /// Field frame of the simulator (x towards the goal team 0 attacks in the first half).
    pub pose: Pose,
    /// The same pose in the robot's own team frame (own goal at -x), as its localization should
    /// estimate it.
    pub team_pose: Pose,
    /// Walking velocity, robot frame.
    pub velocity: strata_robot::Velocity,
    pub head: HeadAngles,
    /// What the platform reports as the body's motion.
    pub body: BodyMotionState,
    pub falling: bool,
    pub fallen: bool,
    /// Onset, direction and cause of the current or most recent fall.
    pub fall_onset: Option<Time>,
    pub fall_direction: Option<FallDirection>,
    pub fall_cause: Option<FallCause>,
    pub penalty: Penalty,
    pub penalty_remaining: Option<f64>,
}

/// The ball's true state.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BallTruth {
    pub position: Point<FieldFrame>,
    pub velocity: Vector<FieldFrame>,
    /// Moving along a scripted path, ignoring physics.
    pub scripted: bool,
    /// The team (index) that touched it last.
    pub last_touch: Option<usize>,
}

/// The game as the referee sees it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GameTruth {
    pub state: GameState,
    pub set_play: SetPlay,
    pub first_half: bool,
    /// Team index taking the kick-off or set play.
    pub kicking_team: Option<usize>,
    pub secs_remaining: f64,
    /// Goals per team index.
    pub score: [u8; 2],
    pub team_numbers: [u8; 2],
    /// +1 when the team attacks the goal at +x.
    pub attack_sign: [f64; 2],
    pub message_budget: [u16; 2],
    pub game_over: bool,
}

/// Counters of the team broadcast emulation and the GameController links.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct CommsStats {
    /// Team messages accepted for forwarding.
    pub sent: u64,
    /// Copies delivered to teammates.
    pub delivered: u64,
    /// Copies lost on the way.
    pub lost: u64,
    /// Messages over the size limit, rejected.
    pub rejected_oversize: u64,
    /// Messages sent with the team's budget spent.
    pub over_budget: u64,
    /// Control packets published (each reaching every robot but the lost copies).
    pub control_packets: u64,
    pub control_packets_lost: u64,
    /// Return packets received and accepted.
    pub return_packets: u64,
    /// Return packets that were not valid `RGrt` packets.
    pub return_packets_rejected: u64,
}

/// Something that happened, with the time it happened. In text (experiment data, the
/// simulator's protocol) the kind's fields sit beside the time (`{"time": ..., "event":
/// "goal", "team": 0, ...}`); in binary encodings (logs, whose CDR has no fields found by name)
/// the kind is a field of its own.
#[derive(Clone, Debug, PartialEq)]
pub struct Event {
    pub time: Time,
    pub kind: EventKind,
}

#[derive(Serialize, Deserialize)]
#[serde(remote = "Event")]
struct EventText {
    time: Time,
    #[serde(flatten)]
    kind: EventKind,
}

#[derive(Serialize, Deserialize)]
#[serde(remote = "Event")]
struct EventBinary {
    time: Time,
    kind: EventKind,
}

strata_runtime::text_and_binary_forms!(Event, EventText, EventBinary);

strata_runtime::text_and_binary_enum! {
    /// What happened, with its details. Tagged by `event` in text, externally in binary
    /// encodings.
    #[derive(Clone, Debug, PartialEq)]
    pub enum EventKind {
        GameState {
            state: GameState,
            first_half: bool,
        },
        Goal {
            /// Team index that scored.
            team: usize,
            score: [u8; 2],
            /// The robot that touched the ball last.
            scorer: Option<RobotId>,
        },
        BallOut {
            status: BallStatus,
            set_play: SetPlay,
            /// The team awarded the set play.
            team: Option<usize>,
            /// Where the ball was when it went out.
            at: Point<FieldFrame>,
            /// Where the referee placed it (automatic referee).
            placed: Option<Point<FieldFrame>>,
        },
        SetPlayOver,
        Fall {
            robot: RobotId,
            onset: Time,
            direction: FallDirection,
            cause: FallCause,
        },
        /// The robot hit the ground.
        Landed {
            robot: RobotId,
            direction: FallDirection,
        },
        StandUp {
            robot: RobotId,
            success: bool,
        },
        Kick {
            robot: RobotId,
            motion: SpecialMotion,
            /// Whether the foot met the ball.
            hit: bool,
        },
        Penalty {
            robot: RobotId,
            penalty: Penalty,
            duration: Option<f64>,
        },
        Unpenalized {
            robot: RobotId,
        },
        Collision {
            a: RobotId,
            b: RobotId,
            speed: f64,
        },
        RobotAdded {
            robot: RobotId,
        },
        RobotRemoved {
            robot: RobotId,
        },
        Teleported {
            robot: RobotId,
            pose: Pose,
        },
        Pushed {
            robot: RobotId,
            velocity: Vector<FieldFrame>,
        },
        BallPlaced {
            position: Point<FieldFrame>,
        },
        BallScripted {
            waypoints: Vec<Point<FieldFrame>>,
            speed: f64,
        },
        PacketLoss {
            loss: f64,
        },
        IllegalCommunication {
            team: usize,
        },
        /// The head referee whistled (the kick-off, or a goal): these robots hear it, in their
        /// next sensor frame (`referee.signals`); the others were out of range or missed it.
        Whistle {
            robots: Vec<RobotId>,
        },
        /// A robot's whistle detector fired with no whistle.
        FalseWhistle {
            robot: RobotId,
        },
    }
    text: #[serde(tag = "event", rename_all = "snake_case")]
    binary: #[serde(rename_all = "snake_case")]
}

/// Everything true about the world at one instant.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroundTruth {
    pub time: Time,
    pub robots: Vec<RobotTruth>,
    pub ball: BallTruth,
    pub game: GameTruth,
    pub comms: CommsStats,
    /// Events (all of them from [`crate::Simulation::ground_truth`]; those since the previous
    /// publication on the simulator module's output).
    pub events: Vec<Event>,
}
