//! Trainer commands for the monitor port (rcsssmj 0.2.1
//! `games/soccer/server/soccer_command_parser.py`). The server applies them after the next
//! physics step and ignores malformed ones silently, so this encoder checks what it can.

use crate::protocol::ProtocolError;
use crate::protocol::game::{FieldSide, PlayMode};

/// Which team a [`MonitorCommand::PlaceRobot`] addresses.
#[derive(Debug, Clone, PartialEq)]
pub enum TeamRef {
    /// By side (`Left` / `Right`).
    Side(FieldSide),
    /// By team name.
    Name(String),
}

/// How a placed robot is oriented.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RobotOrientation {
    /// Keep the current orientation: `(pos x y z)`.
    Keep,
    /// Upright with this heading about the world z axis, radians: `(move x y z degrees)`.
    Yaw(f64),
    /// This torso orientation in the world frame, `[w, x, y, z]`: `(move3d x y z w x y z)`.
    Quaternion([f64; 4]),
}

/// A command a test harness sends on the monitor port. Positions are in the world frame
/// (metres: x towards the right team's goal, z up, origin at the centre spot).
#[derive(Debug, Clone, PartialEq)]
pub enum MonitorCommand {
    /// `(ball (pos x y z) (vel vx vy vz))`: put the ball's centre at `position` (its radius is
    /// 0.11 m, so z = 0.11 rests on the ground) with `velocity` m/s (none: keep its velocity
    /// as the server's `place_at` does).
    PlaceBall {
        /// Centre of the ball, metres.
        position: [f64; 3],
        /// Velocity, m/s.
        velocity: Option<[f64; 3]>,
    },
    /// `(agent (unum N) (team T) (pos|move|move3d …))`: put a robot's torso at `position` and
    /// reset every joint to zero. A T1 torso stands at z ≈ 0.7 m.
    PlaceRobot {
        /// Its team.
        team: TeamRef,
        /// Its player number.
        player: u8,
        /// Torso position, metres.
        position: [f64; 3],
        /// Torso orientation.
        orientation: RobotOrientation,
    },
    /// `(kickOff Left|Right)`, or `(kickOff)` for a random side: the referee grants the kick-off.
    KickOff(Option<FieldSide>),
    /// `(dropBall)`: drop the ball where it is and resume play.
    DropBall,
    /// `(playMode MODE)`. rcsssmj 0.2.1 parses it and only logs it: the play mode does not
    /// change. Use [`MonitorCommand::KickOff`] or [`MonitorCommand::DropBall`] to start play.
    SetPlayMode(PlayMode),
    /// `(killsim)`: shut the server down.
    KillSim,
}

fn invalid(reason: impl Into<String>) -> ProtocolError {
    ProtocolError::Effector { effector: "monitor command", reason: reason.into() }
}

fn check_finite(values: &[f64]) -> Result<(), ProtocolError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(invalid(format!("a value is not finite: {values:?}")))
    }
}

impl MonitorCommand {
    /// This command's text.
    fn text(&self) -> Result<String, ProtocolError> {
        Ok(match self {
            MonitorCommand::PlaceBall { position, velocity } => {
                check_finite(position)?;
                let [x, y, z] = position;
                match velocity {
                    Some([vx, vy, vz]) => {
                        check_finite(&[*vx, *vy, *vz])?;
                        format!("(ball (pos {x} {y} {z}) (vel {vx} {vy} {vz}))")
                    }
                    None => format!("(ball (pos {x} {y} {z}))"),
                }
            }
            MonitorCommand::PlaceRobot { team, player, position, orientation } => {
                check_finite(position)?;
                let team = match team {
                    TeamRef::Side(FieldSide::Left) => "Left",
                    TeamRef::Side(FieldSide::Right) => "Right",
                    TeamRef::Name(name) => {
                        if name.is_empty()
                            || name
                                .bytes()
                                .any(|b| b.is_ascii_whitespace() || b == b'(' || b == b')')
                        {
                            return Err(invalid(format!("team name {name:?} is not one atom")));
                        }
                        name
                    }
                };
                let [x, y, z] = position;
                let pose = match orientation {
                    RobotOrientation::Keep => format!("(pos {x} {y} {z})"),
                    RobotOrientation::Yaw(yaw) => {
                        check_finite(&[*yaw])?;
                        format!("(move {x} {y} {z} {})", yaw.to_degrees())
                    }
                    RobotOrientation::Quaternion(q) => {
                        check_finite(q)?;
                        format!("(move3d {x} {y} {z} {} {} {} {})", q[0], q[1], q[2], q[3])
                    }
                };
                format!("(agent (unum {player}) (team {team}) {pose})")
            }
            MonitorCommand::KickOff(None) => "(kickOff)".to_owned(),
            MonitorCommand::KickOff(Some(FieldSide::Left)) => "(kickOff Left)".to_owned(),
            MonitorCommand::KickOff(Some(FieldSide::Right)) => "(kickOff Right)".to_owned(),
            MonitorCommand::DropBall => "(dropBall)".to_owned(),
            MonitorCommand::SetPlayMode(mode) => format!("(playMode {})", mode.as_str()),
            MonitorCommand::KillSim => "(killsim)".to_owned(),
        })
    }
}

/// Encodes `commands` into `out` (cleared first) as one monitor message; on error `out` is
/// left empty.
pub fn encode_monitor_commands(
    commands: &[MonitorCommand],
    out: &mut Vec<u8>,
) -> Result<(), ProtocolError> {
    out.clear();
    let mut text = String::new();
    for command in commands {
        text += &command.text()?;
    }
    out.extend_from_slice(text.as_bytes());
    Ok(())
}
