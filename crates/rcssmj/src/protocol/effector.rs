//! Encoding of what an agent sends the server: the `init` message, then each cycle one message
//! of effectors (joint commands, beam, speech) ending with `(syn)`.
//!
//! The typed API takes SI units; the wire takes degrees for angles (rcsssmj 0.2.1
//! `server/action_parser.py` converts `q`, `dq` and the beam angle with `radians()`), while the
//! PD gains pass through unconverted into MuJoCo actuators whose control is in radians: `kp` is
//! N·m/rad and `kd` N·m·s/rad on the wire as in the typed API.

use std::fmt::Write as _;

use super::ProtocolError;
use super::base64;

/// The longest team message the server delivers, in bytes (rcsssmj 0.2.1 `simulation.py`
/// drops longer ones silently: `len(msg) <= 10`).
pub const MAX_SAY_BYTES: usize = 10;

/// The T1's speaker effector name (its `say_a-speaker` site).
pub const T1_SPEAKER: &str = "say";

/// The first message on a new agent connection: `(init T1 TEAM N)`. It must be alone in its
/// frame: the server reads only the first expression and disconnects on anything else.
#[derive(Debug, Clone, PartialEq)]
pub struct InitRequest {
    /// Robot model (`T1`, `K1`).
    pub model: String,
    /// Team name (no spaces or parentheses). The first team to connect plays on the left.
    pub team: String,
    /// Player number, 1 to 99 (the server takes `abs(n) % 100`).
    pub player: u8,
}

/// One effector of a cycle's action message.
#[derive(Debug, Clone, PartialEq)]
pub enum Effector {
    /// `(NAME q dq kp kd tau)`: the joint's actuator applies the torque
    /// `kp (q - q_now) + kd (dq - dq_now) + tau`, clamped to the joint's torque range, at every
    /// physics step until the next command.
    Joint(JointCommand),
    /// `(beam x y theta)`: place the robot standing at `x, y` with heading `theta` and every
    /// joint at zero. Honoured only in `BeforeKickOff` and after a goal. `x` and `theta` are in
    /// the team's own frame: the server forces `x` into the own half (`-|x|` for the left team,
    /// `+|x|` for the right) and adds π to the right team's heading, but leaves `y` as given.
    Beam {
        /// Metres, see above.
        x: f64,
        /// Metres, world frame.
        y: f64,
        /// Heading, radians (sent in degrees).
        theta: f64,
    },
    /// `(SPK say VOLUME BASE64)`: broadcast a team message, heard in the next cycle by every
    /// other robot (both teams) within earshot.
    Say {
        /// Gain 0 to 1 (sent as percent; 0 is silent). Loudness falls 6 dB per doubling of
        /// distance beyond 1 m; a listener always hears the three loudest messages.
        volume: f64,
        /// At most [`MAX_SAY_BYTES`] bytes.
        payload: Vec<u8>,
    },
    /// `(syn)`: ends the cycle's message. In sync mode the server waits for one message per
    /// agent per cycle; any message counts, `(syn)` alone is the empty answer.
    Sync,
}

/// A PD-plus-feedforward joint command, SI units.
#[derive(Debug, Clone, PartialEq)]
pub struct JointCommand {
    /// Effector name (`he1`, `lle4`…; the joint's perceptor is `q_hj1`, `q_llj4`…).
    pub name: String,
    /// Target angle, radians.
    pub position: f64,
    /// Target velocity, rad/s.
    pub velocity: f64,
    /// Stiffness, N·m/rad.
    pub kp: f64,
    /// Damping, N·m·s/rad.
    pub kd: f64,
    /// Feed-forward torque, N·m.
    pub torque: f64,
}

fn invalid(effector: &'static str, reason: impl Into<String>) -> ProtocolError {
    ProtocolError::Effector { effector, reason: reason.into() }
}

/// An atom the server can read back as one token.
fn check_atom(text: &str, what: &str, effector: &'static str) -> Result<(), ProtocolError> {
    if text.is_empty() || text.bytes().any(|b| b.is_ascii_whitespace() || b == b'(' || b == b')') {
        return Err(invalid(
            effector,
            format!("{what} {text:?} is empty or holds whitespace or parentheses"),
        ));
    }
    Ok(())
}

fn check_finite(values: &[f64], effector: &'static str) -> Result<(), ProtocolError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(invalid(effector, format!("a value is not finite: {values:?}")))
    }
}

/// Encodes the `init` message.
pub fn encode_init(init: &InitRequest) -> Result<Vec<u8>, ProtocolError> {
    check_atom(&init.model, "model", "init")?;
    check_atom(&init.team, "team", "init")?;
    if !(1..=99).contains(&init.player) {
        return Err(invalid("init", format!("player number {} is outside 1..=99", init.player)));
    }
    Ok(format!("(init {} {} {})", init.model, init.team, init.player).into_bytes())
}

/// Appends the effectors' encoding to `out` (cleared first). Checks everything before writing
/// a byte, so an error leaves `out` empty. Numbers are written in Rust's shortest round-trip
/// form, which Python's `float()` reads exactly.
pub fn encode_effectors(effectors: &[Effector], out: &mut Vec<u8>) -> Result<(), ProtocolError> {
    out.clear();
    let mut text = String::new();
    for effector in effectors {
        // `write!` into a String cannot fail.
        let _ = match effector {
            Effector::Joint(c) => {
                check_atom(&c.name, "joint name", "joint")?;
                check_finite(&[c.position, c.velocity, c.kp, c.kd, c.torque], "joint")?;
                if c.name == "beam" || c.name == "syn" || c.name == "SPK" {
                    return Err(invalid("joint", format!("{:?} is not a joint", c.name)));
                }
                write!(
                    text,
                    "({} {} {} {} {} {})",
                    c.name,
                    c.position.to_degrees(),
                    c.velocity.to_degrees(),
                    c.kp,
                    c.kd,
                    c.torque
                )
            }
            Effector::Beam { x, y, theta } => {
                check_finite(&[*x, *y, *theta], "beam")?;
                write!(text, "(beam {x} {y} {})", theta.to_degrees())
            }
            Effector::Say { volume, payload } => {
                if !(0.0..=1.0).contains(volume) {
                    return Err(invalid("say", format!("volume {volume} is outside 0..=1")));
                }
                if payload.len() > MAX_SAY_BYTES {
                    return Err(invalid(
                        "say",
                        format!(
                            "a message of {} bytes is over the server's limit of {MAX_SAY_BYTES}",
                            payload.len()
                        ),
                    ));
                }
                if payload.is_empty() {
                    return Err(invalid("say", "an empty message is never delivered"));
                }
                write!(text, "(SPK {T1_SPEAKER} {} {})", volume * 100.0, base64::encode(payload))
            }
            Effector::Sync => write!(text, "(syn)"),
        };
    }
    out.extend_from_slice(text.as_bytes());
    Ok(())
}
