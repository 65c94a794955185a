//! Decoding of the perception message the server sends an agent every cycle, into SI units.
//!
//! A perception is a sequence of perceptors, e.g. (rcsssmj 0.2.1, one T1):
//! `(time (now 8.55))(GS (t 0.0)(pm BeforeKickOff)(tl Alpha)(tr Beta)(sl 0)(sr 0))(quat (n
//! torso_quat) (q 0.707 0.0 0.0 -0.707))(pos (n torso_pos) (p -3.0 21.0 0.673))(GYR (n
//! torso_gyro) (rt 0.0 0.0 0.0))(ACC (n torso_acc) (a 0.0 -0.0 0.0))(HJ (n q_hj1)(ax 0.0)(vx
//! 0.0))…(See (B (pol 21.12 8.17 -2.68))(P (team Beta)(id 2)(head (pol …))…))(MIC hear (-54
//! aGVsbG8=))`. Angles arrive in degrees and leave in radians.
//!
//! Perceptors this module does not know are skipped (a newer server may add some); a known
//! perceptor that does not have the expected shape is an error naming it.

use super::ProtocolError;
use super::base64;
use super::game::{FieldSide, PlayMode};
use super::sexp::{self, Sexp};

/// Everything one perception message reported. Fields are `None`/empty when the message did
/// not carry that perceptor (vision arrives every second cycle; `hear` only when someone
/// spoke).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Perception {
    /// `time`: the simulation clock (MuJoCo time), seconds. It runs from the server's start,
    /// not from kick-off, and advances 0.02 s per cycle; truncated to 0.01 s by the server.
    pub time: Option<f64>,
    /// `GS`: the game state.
    pub game: Option<GameStatePerceptor>,
    /// `quat` named `torso_quat`: orientation of the torso in the world frame, quaternion
    /// `[w, x, y, z]` (truncated to 0.001). The world frame has x towards the right team's
    /// goal, y to the left seen from the left team's goal, z up.
    pub torso_orientation: Option<[f64; 4]>,
    /// `pos` named `torso_pos`: position of the torso in the world frame, metres (truncated to
    /// 1 mm). Ground truth from the simulator, which a real robot would not have: use it for
    /// tests and evaluation, not in the robot's own estimation.
    pub torso_position_truth: Option<[f64; 3]>,
    /// `GYR` named `torso_gyro`: angular velocity of the torso in the torso frame (x forward,
    /// y left, z up), rad/s (the server sends deg/s truncated to 0.01).
    pub gyro: Option<[f64; 3]>,
    /// `ACC` named `torso_acc`: proper acceleration in the torso frame, m/s² (about `[0, 0,
    /// 9.81]` standing still; truncated to 0.01).
    pub accel: Option<[f64; 3]>,
    /// `HJ`: the joint states, in the order the server sent them (the model's sensor order).
    pub joints: Vec<JointPerceptor>,
    /// `See`: what the camera saw, when this cycle carried vision (every second cycle).
    /// `Some(vec![])` means vision arrived and nothing was in view.
    pub vision: Option<Vec<SeenObject>>,
    /// `MIC`: team messages heard this cycle (from either team, never our own).
    pub heard: Vec<HeardMessage>,
}

/// The `GS` perceptor: `(GS (t 0.0)(pm BeforeKickOff)(tl Alpha)(tr Beta)(sl 0)(sr 0))`.
///
/// The server does not tell an agent its side: compare the team names ([`Self::side_of`]).
#[derive(Debug, Clone, PartialEq)]
pub struct GameStatePerceptor {
    /// `t`: play time, seconds since kick-off of the half (0 before kick-off).
    pub play_time: f64,
    /// `pm`: the play mode as the server wrote it.
    pub play_mode_text: String,
    /// The play mode, when `play_mode_text` is one of rcsssmj 0.2.1's.
    pub play_mode: Option<PlayMode>,
    /// `tl`: the left team's name, once a left team has connected.
    pub team_left: Option<String>,
    /// `tr`: the right team's name, once a right team has connected.
    pub team_right: Option<String>,
    /// `sl`: goals of the left team.
    pub score_left: u32,
    /// `sr`: goals of the right team.
    pub score_right: u32,
}

impl GameStatePerceptor {
    /// The side the team named `team` plays on, when the names tell it unambiguously (the first
    /// team to connect becomes the left team).
    pub fn side_of(&self, team: &str) -> Option<FieldSide> {
        let left = self.team_left.as_deref() == Some(team);
        let right = self.team_right.as_deref() == Some(team);
        match (left, right) {
            (true, false) => Some(FieldSide::Left),
            (false, true) => Some(FieldSide::Right),
            _ => None,
        }
    }
}

/// One `HJ` perceptor: `(HJ (n q_llj4)(ax -0.03)(vx -2.2))`.
#[derive(Debug, Clone, PartialEq)]
pub struct JointPerceptor {
    /// The perceptor name (`q_hj1`, `q_llj1`…; the effector is named differently, `he1`,
    /// `lle1`…).
    pub name: String,
    /// Joint angle, radians (sent in degrees truncated to 0.01).
    pub angle: f64,
    /// Joint velocity, rad/s (sent in deg/s truncated to 0.01).
    pub velocity: f64,
}

/// A direction and range in the camera frame.
///
/// The camera frame is the T1's `camera` site on the head link: x forward (the optical axis),
/// y left, z up. The server's camera is ideal: no noise, no occlusion, everything within ±60°
/// azimuth and ±60° elevation is reported.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Polar {
    /// Distance from the camera, metres (truncated to 0.01).
    pub distance: f64,
    /// Horizontal angle `atan2(y, x)`, radians, positive to the left.
    pub azimuth: f64,
    /// Vertical angle `asin(z / distance)`, radians, positive up.
    pub elevation: f64,
}

impl Polar {
    /// The point in Cartesian camera coordinates `[x, y, z]`, metres.
    pub fn to_cartesian(&self) -> [f64; 3] {
        let horizontal = self.distance * self.elevation.cos();
        [
            horizontal * self.azimuth.cos(),
            horizontal * self.azimuth.sin(),
            self.distance * self.elevation.sin(),
        ]
    }
}

/// A named point the camera saw: a field feature, the ball, or a robot's body part.
///
/// Field features (rcsssmj 0.2.1): `B` the ball centre; `g_lup g_llp g_rup g_rlp` goal posts
/// (left/right goal, upper = +y / lower = -y post, at crossbar height); `l_*` L-junctions (field
/// corners `l_luf l_llf l_ruf l_rlf`, goal-area corners `l_*ga`, penalty-area corners `l_*pa`);
/// `t_*` T-junctions (halfway line `t_cuf t_clf`, goal/penalty-area lines meeting the goal line
/// `t_*ga t_*pa`); `x_cuc x_clc` where the centre circle crosses the halfway line; `p_lpm p_rpm`
/// penalty marks. Robot parts (T1): `head`, `lfoot`, `rfoot`.
#[derive(Debug, Clone, PartialEq)]
pub struct SeenMarker {
    /// The server's name of the point.
    pub name: String,
    /// Where it is, in the camera frame.
    pub polar: Polar,
}

/// A robot in view: `(P (team Beta)(id 2)(head (pol …))(lfoot (pol …))(rfoot (pol …)))`. Only
/// the parts within the field of view are listed; a robot with none is not listed.
#[derive(Debug, Clone, PartialEq)]
pub struct SeenRobot {
    /// Its team's name.
    pub team: String,
    /// Its player number.
    pub player: u32,
    /// Its visible parts.
    pub parts: Vec<SeenMarker>,
}

/// One entry of the `See` perceptor.
#[derive(Debug, Clone, PartialEq)]
pub enum SeenObject {
    /// A field feature or the ball.
    Marker(SeenMarker),
    /// Another robot (or our own feet, which the camera can see too).
    Robot(SeenRobot),
}

/// One message of the `MIC` perceptor: `(MIC hear (-54 aGVsbG8=))`.
#[derive(Debug, Clone, PartialEq)]
pub struct HeardMessage {
    /// Direction of the speaker, `atan2(y, x)` in the microphone frame (head link: x forward,
    /// y left), radians; the server sends whole degrees (truncated).
    pub azimuth: f64,
    /// The message bytes (at most 10: the server drops longer ones).
    pub payload: Vec<u8>,
}

/// Decodes one perception message (the payload of a frame from the agent port).
pub fn decode_perception(message: &[u8]) -> Result<Perception, ProtocolError> {
    let perceptors = sexp::parse(message, sexp::PERCEPTION_MAX_DEPTH)?;
    let mut perception = Perception::default();
    for perceptor in &perceptors {
        let Some(items) = perceptor.as_list() else {
            continue;
        };
        let Some(name) = items.first().and_then(Sexp::as_atom) else {
            continue;
        };
        let fields = &items[1..];
        match name {
            "time" => perception.time = Some(number(fields, "now", "time")?),
            "GS" => perception.game = Some(game_state(fields)?),
            "quat" if sensor_name(fields, "quat")? == "torso_quat" => {
                perception.torso_orientation = Some(numbers::<4>(fields, "q", "quat")?);
            }
            "pos" if sensor_name(fields, "pos")? == "torso_pos" => {
                perception.torso_position_truth = Some(numbers::<3>(fields, "p", "pos")?);
            }
            "GYR" if sensor_name(fields, "GYR")? == "torso_gyro" => {
                perception.gyro = Some(numbers::<3>(fields, "rt", "GYR")?.map(f64::to_radians));
            }
            "ACC" if sensor_name(fields, "ACC")? == "torso_acc" => {
                perception.accel = Some(numbers::<3>(fields, "a", "ACC")?);
            }
            "HJ" => perception.joints.push(JointPerceptor {
                name: sensor_name(fields, "HJ")?.to_owned(),
                angle: number(fields, "ax", "HJ")?.to_radians(),
                velocity: number(fields, "vx", "HJ")?.to_radians(),
            }),
            "See" => perception.vision = Some(vision(fields)?),
            "MIC" => hear(fields, &mut perception.heard)?,
            "error" if fields.is_empty() => return Err(ProtocolError::ServerError),
            _ => {}
        }
    }
    Ok(perception)
}

fn malformed(perceptor: &'static str, reason: impl Into<String>) -> ProtocolError {
    ProtocolError::Perceptor { perceptor, reason: reason.into() }
}

/// The values of the field `(key v…)` among `fields`.
fn field<'s, 'a>(fields: &'s [Sexp<'a>], key: &str) -> Option<&'s [Sexp<'a>]> {
    fields.iter().find_map(|f| {
        let items = f.as_list()?;
        (items.first()?.as_atom()? == key).then(|| &items[1..])
    })
}

fn atom<'a>(
    fields: &[Sexp<'a>],
    key: &str,
    perceptor: &'static str,
) -> Result<&'a str, ProtocolError> {
    match field(fields, key) {
        Some([Sexp::Atom(text)]) => Ok(text),
        Some(_) => Err(malformed(perceptor, format!("({key} …) is not one atom"))),
        None => Err(malformed(perceptor, format!("no ({key} …) field"))),
    }
}

fn sensor_name<'a>(fields: &[Sexp<'a>], perceptor: &'static str) -> Result<&'a str, ProtocolError> {
    atom(fields, "n", perceptor)
}

fn parse_number(text: &str, what: &str, perceptor: &'static str) -> Result<f64, ProtocolError> {
    match text.parse::<f64>() {
        Ok(value) if value.is_finite() => Ok(value),
        _ => Err(malformed(perceptor, format!("{what} is {text:?}, not a finite number"))),
    }
}

fn number(fields: &[Sexp<'_>], key: &str, perceptor: &'static str) -> Result<f64, ProtocolError> {
    parse_number(atom(fields, key, perceptor)?, key, perceptor)
}

fn numbers<const N: usize>(
    fields: &[Sexp<'_>],
    key: &str,
    perceptor: &'static str,
) -> Result<[f64; N], ProtocolError> {
    let Some(values) = field(fields, key) else {
        return Err(malformed(perceptor, format!("no ({key} …) field")));
    };
    if values.len() != N {
        return Err(malformed(
            perceptor,
            format!("({key} …) has {} values, expected {N}", values.len()),
        ));
    }
    let mut out = [0.0; N];
    for (slot, value) in out.iter_mut().zip(values) {
        let Some(text) = value.as_atom() else {
            return Err(malformed(perceptor, format!("({key} …) holds a list")));
        };
        *slot = parse_number(text, key, perceptor)?;
    }
    Ok(out)
}

fn count(fields: &[Sexp<'_>], key: &str, perceptor: &'static str) -> Result<u32, ProtocolError> {
    let text = atom(fields, key, perceptor)?;
    text.parse::<u32>()
        .map_err(|_| malformed(perceptor, format!("{key} is {text:?}, not a non-negative integer")))
}

fn game_state(fields: &[Sexp<'_>]) -> Result<GameStatePerceptor, ProtocolError> {
    let play_mode_text = atom(fields, "pm", "GS")?;
    let team = |key| field(fields, key).and_then(|v| v.first()?.as_atom()).map(str::to_owned);
    Ok(GameStatePerceptor {
        play_time: number(fields, "t", "GS")?,
        play_mode_text: play_mode_text.to_owned(),
        play_mode: PlayMode::from_server_name(play_mode_text),
        team_left: team("tl"),
        team_right: team("tr"),
        score_left: count(fields, "sl", "GS")?,
        score_right: count(fields, "sr", "GS")?,
    })
}

/// `(NAME (pol d a e))` → a marker.
fn seen_marker(entry: &[Sexp<'_>]) -> Result<SeenMarker, ProtocolError> {
    let Some(name) = entry.first().and_then(Sexp::as_atom) else {
        return Err(malformed("See", "an object without a name"));
    };
    let [distance, azimuth, elevation] = numbers::<3>(&entry[1..], "pol", "See")
        .map_err(|e| malformed("See", format!("object {name}: {e}")))?;
    Ok(SeenMarker {
        name: name.to_owned(),
        polar: Polar { distance, azimuth: azimuth.to_radians(), elevation: elevation.to_radians() },
    })
}

fn vision(fields: &[Sexp<'_>]) -> Result<Vec<SeenObject>, ProtocolError> {
    let mut objects = Vec::with_capacity(fields.len());
    for entry in fields {
        let Some(items) = entry.as_list() else {
            return Err(malformed("See", "an atom where an object was expected"));
        };
        if items.first().and_then(Sexp::as_atom) == Some("P") {
            let rest = &items[1..];
            let team = atom(rest, "team", "See")?.to_owned();
            let player = count(rest, "id", "See")?;
            let parts = rest
                .iter()
                .filter_map(Sexp::as_list)
                .filter(|part| !matches!(part.first().and_then(Sexp::as_atom), Some("team" | "id")))
                .map(seen_marker)
                .collect::<Result<Vec<_>, _>>()?;
            objects.push(SeenObject::Robot(SeenRobot { team, player, parts }));
        } else {
            objects.push(SeenObject::Marker(seen_marker(items)?));
        }
    }
    Ok(objects)
}

/// `(MIC hear (AZIMUTH BASE64)…)`: the microphone name, then one list per message.
fn hear(fields: &[Sexp<'_>], heard: &mut Vec<HeardMessage>) -> Result<(), ProtocolError> {
    for entry in fields.iter().filter_map(Sexp::as_list) {
        let [Sexp::Atom(azimuth), Sexp::Atom(payload)] = entry else {
            return Err(malformed("MIC", "a message is not (AZIMUTH BASE64)"));
        };
        let azimuth = parse_number(azimuth, "azimuth", "MIC")?.to_radians();
        let Some(payload) = base64::decode(payload) else {
            return Err(malformed("MIC", format!("{payload:?} is not base64")));
        };
        heard.push(HeardMessage { azimuth, payload });
    }
    Ok(())
}
