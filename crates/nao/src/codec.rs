//! The LoLA wire format: msgpack maps over a Unix stream socket.
//!
//! Every 12 ms LoLA sends one sensor map (896 bytes on a NAO v6: float32 values, positive-fixint
//! joint statuses, 20-character robot ids) and expects one actuator map back. Decoding never
//! panics and never allocates what a hostile length field asks for; every error says which key
//! or which byte count was wrong.
//!
//! Key shapes (indices as LoLA numbers them):
//!
//! | key | values |
//! |---|---|
//! | `Stiffness`, `Position`, `Temperature`, `Current` | 25, [`crate::joints::Joint`] order |
//! | `Battery` | charge (0..1), status (bit 0x80: charging), current (A), temperature (°C) |
//! | `Accelerometer` | x, y, z, m/s² (LoLA's sign: upright reads z ≈ −9.81) |
//! | `Gyroscope` | x, y, z, rad/s, right-handed torso frame |
//! | `Angles` | x (roll, right side down positive), y (pitch, forward positive), rad |
//! | `Sonar` | left, right, m |
//! | `FSR` | left foot front-left, front-right, rear-left, rear-right, then the right foot, kg |
//! | `Touch` | chest button, head front/middle/rear, left foot bumper left/right, left hand back/left/right, right foot bumper left/right, right hand back/left/right |
//! | `Status` | 25 joint temperature statuses (integers) |
//! | `RobotConfig` | body id, body version, head id, head version |
//!
//! Actuator keys: `Position` and `Stiffness` (25 each), `REar` and `LEar` (10), `Chest` (3, RGB),
//! `LEye` and `REye` (24: eight reds, eight greens, eight blues), `LFoot` and `RFoot` (3, RGB),
//! `Skull` (12) and `Sonar` (2 booleans: left and right emitters on).

use std::cell::RefCell;
use std::fmt;
use std::io::Cursor;

use serde::de::{self, DeserializeSeed, IgnoredAny, MapAccess, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};

use crate::joints::{JOINT_COUNT, JointArray};

/// Size of one sensor packet as a NAO v6 sends it.
pub const SENSOR_PACKET_SIZE: usize = 896;

/// Where LoLA listens on a NAO v6.
pub const DEFAULT_SOCKET_PATH: &str = "/tmp/robocup";

/// Buffered bytes beyond which an incomplete msgpack value is declared garbage (several real
/// packets): a corrupt length field must not make the reader wait forever.
pub const MAX_PACKET_SIZE: usize = 8 * SENSOR_PACKET_SIZE;

/// LoLA's maps are one level deep with arrays inside; anything deeper is garbage, and the limit
/// keeps a hostile nesting from exhausting the stack.
const MAX_DEPTH: usize = 8;

/// The keys of a sensor map, in the order LoLA sends them.
pub const SENSOR_KEYS: [&str; 13] = [
    "Stiffness",
    "Position",
    "Temperature",
    "Current",
    "Battery",
    "Accelerometer",
    "Gyroscope",
    "Angles",
    "Sonar",
    "FSR",
    "Touch",
    "Status",
    "RobotConfig",
];

/// Indices into [`SensorPacket::touch`].
pub mod touch {
    pub const CHEST_BUTTON: usize = 0;
    pub const HEAD_FRONT: usize = 1;
    pub const HEAD_MIDDLE: usize = 2;
    pub const HEAD_REAR: usize = 3;
    pub const LEFT_FOOT_BUMPER_LEFT: usize = 4;
    pub const LEFT_FOOT_BUMPER_RIGHT: usize = 5;
    pub const LEFT_HAND_BACK: usize = 6;
    pub const LEFT_HAND_LEFT: usize = 7;
    pub const LEFT_HAND_RIGHT: usize = 8;
    pub const RIGHT_FOOT_BUMPER_LEFT: usize = 9;
    pub const RIGHT_FOOT_BUMPER_RIGHT: usize = 10;
    pub const RIGHT_HAND_BACK: usize = 11;
    pub const RIGHT_HAND_LEFT: usize = 12;
    pub const RIGHT_HAND_RIGHT: usize = 13;
    pub const COUNT: usize = 14;
}

/// What is wrong with one key of a map.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum KeyProblem {
    #[error("is missing")]
    Missing,
    #[error("appears twice")]
    Duplicate,
    #[error("has {found} values, expected {expected}")]
    WrongLength { expected: usize, found: usize },
    #[error("has a wrong value type: {0}")]
    WrongType(String),
}

/// Why a LoLA packet could not be decoded or encoded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CodecError {
    #[error("truncated packet: got {received} bytes of a {expected}-byte packet")]
    Truncated { received: usize, expected: usize },
    #[error("{trailing} bytes follow the {packet}-byte packet")]
    TrailingBytes { packet: usize, trailing: usize },
    #[error("key \"{key}\" {problem}")]
    Key { key: String, problem: KeyProblem },
    #[error("malformed msgpack: {0}")]
    Msgpack(String),
    #[error("cannot encode packet: {0}")]
    Encode(String),
}

impl CodecError {
    fn key(key: &str, problem: KeyProblem) -> CodecError {
        CodecError::Key { key: key.to_owned(), problem }
    }
}

/// Battery readings: `[charge, status, current, temperature]` on the wire.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Battery(pub [f32; 4]);

impl Battery {
    /// State of charge, 0 (empty) .. 1 (full).
    pub fn charge(&self) -> f32 {
        self.0[0]
    }

    /// LoLA's raw status word; bit 0x80 means the charger is connected and charging.
    pub fn status(&self) -> f32 {
        self.0[1]
    }

    /// Amperes; negative while discharging.
    pub fn current(&self) -> f32 {
        self.0[2]
    }

    /// °C.
    pub fn temperature(&self) -> f32 {
        self.0[3]
    }

    pub fn charging(&self) -> bool {
        self.0[1].is_finite() && (self.0[1] as i32) & 0x80 != 0
    }
}

/// The robot's identity as LoLA reports it.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RobotConfig {
    pub body_id: String,
    pub body_version: String,
    pub head_id: String,
    pub head_version: String,
}

/// `RobotConfig` as LoLA sends it: an array of four strings.
struct RobotConfigWire<'a>(&'a RobotConfig);

impl Serialize for RobotConfigWire<'_> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let c = self.0;
        [&c.body_id, &c.body_version, &c.head_id, &c.head_version].serialize(serializer)
    }
}

/// One sensor map from LoLA, values as LoLA reports them (see the module table for units and
/// signs; conversion to Strata's conventions happens in the platform).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SensorPacket {
    pub stiffness: JointArray<f32>,
    pub position: JointArray<f32>,
    pub temperature: JointArray<f32>,
    pub current: JointArray<f32>,
    pub battery: Battery,
    pub accelerometer: [f32; 3],
    pub gyroscope: [f32; 3],
    pub angles: [f32; 2],
    pub sonar: [f32; 2],
    pub fsr: [f32; 8],
    pub touch: [f32; touch::COUNT],
    pub status: JointArray<i32>,
    pub robot_config: RobotConfig,
}

impl Serialize for SensorPacket {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut map = serializer.serialize_map(Some(SENSOR_KEYS.len()))?;
        map.serialize_entry("Stiffness", &self.stiffness)?;
        map.serialize_entry("Position", &self.position)?;
        map.serialize_entry("Temperature", &self.temperature)?;
        map.serialize_entry("Current", &self.current)?;
        map.serialize_entry("Battery", &self.battery)?;
        map.serialize_entry("Accelerometer", &self.accelerometer)?;
        map.serialize_entry("Gyroscope", &self.gyroscope)?;
        map.serialize_entry("Angles", &self.angles)?;
        map.serialize_entry("Sonar", &self.sonar)?;
        map.serialize_entry("FSR", &self.fsr)?;
        map.serialize_entry("Touch", &self.touch)?;
        map.serialize_entry("Status", &self.status)?;
        map.serialize_entry("RobotConfig", &RobotConfigWire(&self.robot_config))?;
        map.end()
    }
}

impl SensorPacket {
    /// Decodes exactly one sensor map; `bytes` must hold nothing else.
    pub fn decode(bytes: &[u8]) -> Result<SensorPacket, CodecError> {
        match measure(bytes) {
            Extent::Incomplete => Err(CodecError::Truncated {
                received: bytes.len(),
                expected: SENSOR_PACKET_SIZE.max(bytes.len() + 1),
            }),
            Extent::Invalid(reason) => Err(CodecError::Msgpack(reason)),
            Extent::Complete(n) if n < bytes.len() => {
                Err(CodecError::TrailingBytes { packet: n, trailing: bytes.len() - n })
            }
            Extent::Complete(_) => decode_sensor_map(bytes),
        }
    }

    /// Encodes the map as LoLA sends it (float32 values, integer statuses).
    pub fn encode(&self) -> Result<Vec<u8>, CodecError> {
        rmp_serde::to_vec(self).map_err(|e| CodecError::Encode(e.to_string()))
    }
}

/// An RGB colour, each channel 0..1.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Rgb {
    pub r: f32,
    pub g: f32,
    pub b: f32,
}

impl Rgb {
    pub const OFF: Rgb = Rgb { r: 0.0, g: 0.0, b: 0.0 };
    pub const WHITE: Rgb = Rgb { r: 1.0, g: 1.0, b: 1.0 };
    pub const RED: Rgb = Rgb { r: 1.0, g: 0.0, b: 0.0 };
    pub const GREEN: Rgb = Rgb { r: 0.0, g: 1.0, b: 0.0 };
    pub const BLUE: Rgb = Rgb { r: 0.0, g: 0.0, b: 1.0 };
    pub const YELLOW: Rgb = Rgb { r: 1.0, g: 1.0, b: 0.0 };

    pub const fn new(r: f32, g: f32, b: f32) -> Rgb {
        Rgb { r, g, b }
    }

    fn clamped(self) -> [f32; 3] {
        [unit(self.r), unit(self.g), unit(self.b)]
    }
}

/// Every LED the NAO v6 exposes through LoLA, with segments in LoLA's own order (so a table
/// in LoLA's documentation maps one to one): left eye segments at 45°, 0°, 315°, 270°, 225°,
/// 180°, 135°, 90°; right eye at 0°, 45°, ..., 315°; left ear at 0°, 36°, ..., 324°; right ear
/// at 324°, 288°, ..., 0°; skull front-left 1, front-left 0, middle-left, rear-left 0..2,
/// rear-right 2..0, middle-right, front-right 0, front-right 1.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Leds {
    pub chest: Rgb,
    pub left_eye: [Rgb; 8],
    pub right_eye: [Rgb; 8],
    pub left_ear: [f32; 10],
    pub right_ear: [f32; 10],
    pub left_foot: Rgb,
    pub right_foot: Rgb,
    pub skull: [f32; 12],
}

impl Leds {
    /// Both eyes in one colour.
    pub fn set_eyes(&mut self, colour: Rgb) {
        self.left_eye = [colour; 8];
        self.right_eye = [colour; 8];
    }
}

/// One actuator map for LoLA, in LoLA's layout.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ActuatorPacket {
    #[serde(rename = "Position")]
    pub position: JointArray<f32>,
    #[serde(rename = "Stiffness")]
    pub stiffness: JointArray<f32>,
    #[serde(rename = "REar")]
    pub right_ear: [f32; 10],
    #[serde(rename = "LEar")]
    pub left_ear: [f32; 10],
    #[serde(rename = "Chest")]
    pub chest: [f32; 3],
    #[serde(rename = "LEye")]
    pub left_eye: [f32; 24],
    #[serde(rename = "REye")]
    pub right_eye: [f32; 24],
    #[serde(rename = "LFoot")]
    pub left_foot: [f32; 3],
    #[serde(rename = "RFoot")]
    pub right_foot: [f32; 3],
    #[serde(rename = "Skull")]
    pub skull: [f32; 12],
    #[serde(rename = "Sonar")]
    pub sonar: [bool; 2],
}

impl Default for ActuatorPacket {
    fn default() -> Self {
        ActuatorPacket {
            position: [0.0; JOINT_COUNT],
            stiffness: [0.0; JOINT_COUNT],
            right_ear: [0.0; 10],
            left_ear: [0.0; 10],
            chest: [0.0; 3],
            left_eye: [0.0; 24],
            right_eye: [0.0; 24],
            left_foot: [0.0; 3],
            right_foot: [0.0; 3],
            skull: [0.0; 12],
            sonar: [true; 2],
        }
    }
}

impl ActuatorPacket {
    /// Joint targets (rad) and stiffnesses (0..1) in LoLA order, plus the LEDs.
    pub fn new(
        position: JointArray<f32>,
        stiffness: JointArray<f32>,
        leds: &Leds,
        sonar: bool,
    ) -> ActuatorPacket {
        fn eye(segments: &[Rgb; 8]) -> [f32; 24] {
            let mut out = [0.0; 24];
            for (i, segment) in segments.iter().enumerate() {
                let [r, g, b] = segment.clamped();
                out[i] = r;
                out[8 + i] = g;
                out[16 + i] = b;
            }
            out
        }
        ActuatorPacket {
            position,
            stiffness: stiffness.map(unit),
            right_ear: leds.right_ear.map(unit),
            left_ear: leds.left_ear.map(unit),
            chest: leds.chest.clamped(),
            left_eye: eye(&leds.left_eye),
            right_eye: eye(&leds.right_eye),
            left_foot: leds.left_foot.clamped(),
            right_foot: leds.right_foot.clamped(),
            skull: leds.skull.map(unit),
            sonar: [sonar; 2],
        }
    }

    /// Encodes as a map with LoLA's key names.
    pub fn encode(&self) -> Result<Vec<u8>, CodecError> {
        rmp_serde::to_vec_named(self).map_err(|e| CodecError::Encode(e.to_string()))
    }

    /// Decodes exactly one actuator map (what a LoLA stand-in receives).
    pub fn decode(bytes: &[u8]) -> Result<ActuatorPacket, CodecError> {
        match measure(bytes) {
            Extent::Incomplete => {
                Err(CodecError::Truncated { received: bytes.len(), expected: bytes.len() + 1 })
            }
            Extent::Invalid(reason) => Err(CodecError::Msgpack(reason)),
            Extent::Complete(n) if n < bytes.len() => {
                Err(CodecError::TrailingBytes { packet: n, trailing: bytes.len() - n })
            }
            Extent::Complete(_) => {
                rmp_serde::from_slice(bytes).map_err(|e| CodecError::Msgpack(e.to_string()))
            }
        }
    }
}

/// LoLA ignores stiffness and LED values outside 0..1 at best; NaN must never reach a motor.
fn unit(value: f32) -> f32 {
    if value.is_finite() { value.clamp(0.0, 1.0) } else { 0.0 }
}

/// How far the msgpack value at the start of a buffer reaches.
#[derive(Debug, Clone, PartialEq)]
enum Extent {
    Complete(usize),
    Incomplete,
    Invalid(String),
}

/// Finds the end of the first msgpack value without building it. Reading from a cursor keeps
/// every length field bounded by the bytes actually present.
fn measure(bytes: &[u8]) -> Extent {
    let mut de = rmp_serde::Deserializer::new(Cursor::new(bytes));
    de.set_max_depth(MAX_DEPTH);
    match IgnoredAny::deserialize(&mut de) {
        Ok(IgnoredAny) => match usize::try_from(de.position()) {
            Ok(n) => Extent::Complete(n),
            Err(_) => Extent::Invalid("position overflow".to_owned()),
        },
        Err(
            rmp_serde::decode::Error::InvalidMarkerRead(e)
            | rmp_serde::decode::Error::InvalidDataRead(e),
        ) if e.kind() == std::io::ErrorKind::UnexpectedEof => Extent::Incomplete,
        Err(e) => Extent::Invalid(e.to_string()),
    }
}

/// The length of the first msgpack value in `bytes`, `Ok(None)` if it needs more bytes. Lets a
/// reader of a msgpack stream (a LoLA stand-in reading actuator packets) find packet ends.
pub fn value_len(bytes: &[u8]) -> Result<Option<usize>, CodecError> {
    match measure(bytes) {
        Extent::Complete(n) => Ok(Some(n)),
        Extent::Incomplete => Ok(None),
        Extent::Invalid(reason) => Err(CodecError::Msgpack(reason)),
    }
}

fn decode_sensor_map(bytes: &[u8]) -> Result<SensorPacket, CodecError> {
    let detail = RefCell::new(None);
    let mut de = rmp_serde::Deserializer::from_read_ref(bytes);
    de.set_max_depth(MAX_DEPTH);
    match (SensorSeed { detail: &detail }).deserialize(&mut de) {
        Ok(packet) => Ok(packet),
        Err(e) => Err(detail.into_inner().unwrap_or_else(|| CodecError::Msgpack(e.to_string()))),
    }
}

/// Decodes a sensor map, recording the first structured problem in `detail` (serde's error
/// type can only carry a string, and callers deserve to match on the key and the problem).
struct SensorSeed<'a> {
    detail: &'a RefCell<Option<CodecError>>,
}

impl SensorSeed<'_> {
    fn fail<E: de::Error>(&self, error: CodecError) -> E {
        let message = error.to_string();
        self.detail.borrow_mut().get_or_insert(error);
        E::custom(message)
    }
}

impl<'de> DeserializeSeed<'de> for SensorSeed<'_> {
    type Value = SensorPacket;

    fn deserialize<D: de::Deserializer<'de>>(
        self,
        deserializer: D,
    ) -> Result<SensorPacket, D::Error> {
        deserializer.deserialize_map(self)
    }
}

#[derive(Default)]
struct Partial {
    stiffness: Option<JointArray<f32>>,
    position: Option<JointArray<f32>>,
    temperature: Option<JointArray<f32>>,
    current: Option<JointArray<f32>>,
    battery: Option<[f32; 4]>,
    accelerometer: Option<[f32; 3]>,
    gyroscope: Option<[f32; 3]>,
    angles: Option<[f32; 2]>,
    sonar: Option<[f32; 2]>,
    fsr: Option<[f32; 8]>,
    touch: Option<[f32; touch::COUNT]>,
    status: Option<JointArray<i32>>,
    robot_config: Option<[String; 4]>,
}

impl<'de> Visitor<'de> for SensorSeed<'_> {
    type Value = SensorPacket;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a LoLA sensor map")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<SensorPacket, A::Error> {
        let mut p = Partial::default();
        while let Some(key) = map.next_key::<KeyName>()? {
            let key = key.0;
            macro_rules! floats {
                ($field:ident, $n:expr) => {{
                    if p.$field.is_some() {
                        return Err(self.fail(CodecError::key(&key, KeyProblem::Duplicate)));
                    }
                    let values = map.next_value_seed(Numbers::<$n> { key: &key, seed: &self })?;
                    p.$field = Some(values.map(|v| v as f32));
                }};
            }
            match key.as_str() {
                "Stiffness" => floats!(stiffness, JOINT_COUNT),
                "Position" => floats!(position, JOINT_COUNT),
                "Temperature" => floats!(temperature, JOINT_COUNT),
                "Current" => floats!(current, JOINT_COUNT),
                "Battery" => floats!(battery, 4),
                "Accelerometer" => floats!(accelerometer, 3),
                "Gyroscope" => floats!(gyroscope, 3),
                "Angles" => floats!(angles, 2),
                "Sonar" => floats!(sonar, 2),
                "FSR" => floats!(fsr, 8),
                "Touch" => floats!(touch, { touch::COUNT }),
                "Status" => {
                    if p.status.is_some() {
                        return Err(self.fail(CodecError::key(&key, KeyProblem::Duplicate)));
                    }
                    let values =
                        map.next_value_seed(Numbers::<JOINT_COUNT> { key: &key, seed: &self })?;
                    // Statuses are small integers; some LoLA versions send them as floats.
                    p.status = Some(values.map(|v| v.round() as i32));
                }
                "RobotConfig" => {
                    if p.robot_config.is_some() {
                        return Err(self.fail(CodecError::key(&key, KeyProblem::Duplicate)));
                    }
                    p.robot_config = Some(map.next_value_seed(Strings { key: &key, seed: &self })?);
                }
                // Newer LoLA versions may add keys; ignoring them keeps old robots and new
                // firmware compatible.
                _ => {
                    map.next_value::<IgnoredAny>()?;
                }
            }
        }
        macro_rules! required {
            ($field:ident, $key:expr) => {
                match p.$field {
                    Some(value) => value,
                    None => return Err(self.fail(CodecError::key($key, KeyProblem::Missing))),
                }
            };
        }
        let [body_id, body_version, head_id, head_version] = required!(robot_config, "RobotConfig");
        Ok(SensorPacket {
            stiffness: required!(stiffness, "Stiffness"),
            position: required!(position, "Position"),
            temperature: required!(temperature, "Temperature"),
            current: required!(current, "Current"),
            battery: Battery(required!(battery, "Battery")),
            accelerometer: required!(accelerometer, "Accelerometer"),
            gyroscope: required!(gyroscope, "Gyroscope"),
            angles: required!(angles, "Angles"),
            sonar: required!(sonar, "Sonar"),
            fsr: required!(fsr, "FSR"),
            touch: required!(touch, "Touch"),
            status: required!(status, "Status"),
            robot_config: RobotConfig { body_id, body_version, head_id, head_version },
        })
    }
}

/// A map key: LoLA's keys are strings; anything else is reported as such.
struct KeyName(String);

impl<'de> Deserialize<'de> for KeyName {
    fn deserialize<D: de::Deserializer<'de>>(deserializer: D) -> Result<KeyName, D::Error> {
        struct KeyVisitor;
        impl Visitor<'_> for KeyVisitor {
            type Value = KeyName;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a string key")
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<KeyName, E> {
                Ok(KeyName(v.to_owned()))
            }
        }
        deserializer.deserialize_str(KeyVisitor)
    }
}

/// Exactly `N` numbers (integers or floats) under `key`.
struct Numbers<'a, const N: usize> {
    key: &'a str,
    seed: &'a SensorSeed<'a>,
}

impl<'de, const N: usize> DeserializeSeed<'de> for Numbers<'_, N> {
    type Value = [f64; N];
    fn deserialize<D: de::Deserializer<'de>>(self, deserializer: D) -> Result<[f64; N], D::Error> {
        deserializer.deserialize_seq(self)
    }
}

impl<'de, const N: usize> Visitor<'de> for Numbers<'_, N> {
    type Value = [f64; N];

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "an array of {N} numbers")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<[f64; N], A::Error> {
        let wrong_length =
            |found| CodecError::key(self.key, KeyProblem::WrongLength { expected: N, found });
        if let Some(found) = seq.size_hint()
            && found != N
        {
            return Err(self.seed.fail(wrong_length(found)));
        }
        let mut out = [0.0; N];
        for (i, slot) in out.iter_mut().enumerate() {
            match seq.next_element::<Number>() {
                Ok(Some(Number(v))) => *slot = v,
                Ok(None) => return Err(self.seed.fail(wrong_length(i))),
                Err(e) => {
                    let problem = KeyProblem::WrongType(format!("value {i}: {e}"));
                    return Err(self.seed.fail(CodecError::key(self.key, problem)));
                }
            }
        }
        if seq.next_element::<IgnoredAny>()?.is_some() {
            return Err(self.seed.fail(wrong_length(N + 1)));
        }
        Ok(out)
    }

    fn visit_map<A: MapAccess<'de>>(self, _: A) -> Result<[f64; N], A::Error> {
        Err(self.seed.fail(CodecError::key(self.key, KeyProblem::WrongType("a map".into()))))
    }

    fn visit_str<E: de::Error>(self, _: &str) -> Result<[f64; N], E> {
        Err(self.seed.fail(CodecError::key(self.key, KeyProblem::WrongType("a string".into()))))
    }

    fn visit_f64<E: de::Error>(self, _: f64) -> Result<[f64; N], E> {
        Err(self.seed.fail(CodecError::key(self.key, KeyProblem::WrongType("a number".into()))))
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<[f64; N], E> {
        self.visit_f64(v as f64)
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<[f64; N], E> {
        self.visit_f64(v as f64)
    }

    fn visit_bool<E: de::Error>(self, _: bool) -> Result<[f64; N], E> {
        Err(self.seed.fail(CodecError::key(self.key, KeyProblem::WrongType("a boolean".into()))))
    }

    fn visit_unit<E: de::Error>(self) -> Result<[f64; N], E> {
        Err(self.seed.fail(CodecError::key(self.key, KeyProblem::WrongType("nil".into()))))
    }

    fn visit_bytes<E: de::Error>(self, _: &[u8]) -> Result<[f64; N], E> {
        Err(self.seed.fail(CodecError::key(self.key, KeyProblem::WrongType("binary".into()))))
    }

    fn visit_newtype_struct<D: de::Deserializer<'de>>(self, _: D) -> Result<[f64; N], D::Error> {
        let problem = KeyProblem::WrongType("an extension value".into());
        Err(self.seed.fail(CodecError::key(self.key, problem)))
    }
}

/// A number in any msgpack encoding.
struct Number(f64);

impl<'de> Deserialize<'de> for Number {
    fn deserialize<D: de::Deserializer<'de>>(deserializer: D) -> Result<Number, D::Error> {
        struct NumberVisitor;
        impl Visitor<'_> for NumberVisitor {
            type Value = Number;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a number")
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<Number, E> {
                Ok(Number(v))
            }
            fn visit_f32<E: de::Error>(self, v: f32) -> Result<Number, E> {
                Ok(Number(f64::from(v)))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Number, E> {
                Ok(Number(v as f64))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Number, E> {
                Ok(Number(v as f64))
            }
        }
        deserializer.deserialize_any(NumberVisitor)
    }
}

/// Exactly four strings (`RobotConfig`).
struct Strings<'a> {
    key: &'a str,
    seed: &'a SensorSeed<'a>,
}

impl<'de> DeserializeSeed<'de> for Strings<'_> {
    type Value = [String; 4];
    fn deserialize<D: de::Deserializer<'de>>(
        self,
        deserializer: D,
    ) -> Result<[String; 4], D::Error> {
        deserializer.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for Strings<'_> {
    type Value = [String; 4];

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("an array of 4 strings")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<[String; 4], A::Error> {
        let wrong_length =
            |found| CodecError::key(self.key, KeyProblem::WrongLength { expected: 4, found });
        if let Some(found) = seq.size_hint()
            && found != 4
        {
            return Err(self.seed.fail(wrong_length(found)));
        }
        let mut out: [String; 4] = Default::default();
        for (i, slot) in out.iter_mut().enumerate() {
            match seq.next_element::<String>() {
                Ok(Some(v)) => *slot = v,
                Ok(None) => return Err(self.seed.fail(wrong_length(i))),
                Err(e) => {
                    let problem = KeyProblem::WrongType(format!("value {i}: {e}"));
                    return Err(self.seed.fail(CodecError::key(self.key, problem)));
                }
            }
        }
        if seq.next_element::<IgnoredAny>()?.is_some() {
            return Err(self.seed.fail(wrong_length(5)));
        }
        Ok(out)
    }
}

/// Cuts LoLA's byte stream into sensor packets.
///
/// Packets are delimited by their msgpack structure rather than by counting 896 bytes, so a
/// robot whose ids have another length still works. After a bad packet the framer skips to the
/// next place a packet starts, so one truncated or garbled packet costs that packet only, not
/// the rest of the stream. LoLA writes its keys in a fixed order, so every packet begins with
/// the same bytes (map header and first key), which the framer learns from the first good
/// packet; that signature cannot occur inside a packet, whereas "a map header byte followed by
/// some key" can (a float ending in 0x8d before the next key), and is only the fallback until
/// a packet has been seen.
#[derive(Debug, Default)]
pub struct PacketFramer {
    buffer: Vec<u8>,
    signature: Option<Vec<u8>>,
}

impl PacketFramer {
    pub fn new() -> PacketFramer {
        PacketFramer { buffer: Vec::with_capacity(2 * SENSOR_PACKET_SIZE), signature: None }
    }

    /// Appends bytes read from the socket.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buffer.extend_from_slice(bytes);
    }

    /// Bytes received that do not form a complete packet yet.
    pub fn buffered(&self) -> usize {
        self.buffer.len()
    }

    /// The next complete packet (or the reason the bytes at the front are not one); `None`
    /// when more bytes are needed.
    pub fn next_packet(&mut self) -> Option<Result<SensorPacket, CodecError>> {
        if self.buffer.is_empty() {
            return None;
        }
        match measure(&self.buffer) {
            Extent::Incomplete if self.buffer.len() <= MAX_PACKET_SIZE => {
                // A cut packet can leave its structure waiting for bytes that the next packet
                // feeds it; once the whole next packet is here, the cut is certain.
                let k = self.next_complete_start()?;
                self.buffer.drain(..k);
                Some(Err(CodecError::Truncated { received: k, expected: SENSOR_PACKET_SIZE }))
            }
            Extent::Incomplete => {
                let buffered = self.buffer.len();
                self.resync(1);
                Some(Err(CodecError::Msgpack(format!(
                    "no complete msgpack value in {buffered} bytes"
                ))))
            }
            Extent::Invalid(reason) => {
                self.resync(1);
                Some(Err(CodecError::Msgpack(reason)))
            }
            Extent::Complete(n) => match decode_sensor_map(&self.buffer[..n]) {
                Ok(packet) => {
                    if self.signature.is_none() {
                        self.signature = signature(&self.buffer[..n]);
                    }
                    self.buffer.drain(..n);
                    Some(Ok(packet))
                }
                Err(error) => {
                    // A packet that was cut short swallows the start of the next one; if a new
                    // packet begins inside this one, truncation is the diagnosis.
                    match self.find_start(&self.buffer[..n], 1) {
                        Some(k) => {
                            self.buffer.drain(..k);
                            Some(Err(CodecError::Truncated {
                                received: k,
                                expected: SENSOR_PACKET_SIZE,
                            }))
                        }
                        None => {
                            self.buffer.drain(..n);
                            Some(Err(error))
                        }
                    }
                }
            },
        }
    }

    /// Called when the stream ended or went silent: a partial packet left behind is reported
    /// as truncated and dropped.
    pub fn flush_partial(&mut self) -> Option<CodecError> {
        if self.buffer.is_empty() {
            return None;
        }
        let received = self.buffer.len();
        self.buffer.clear();
        Some(CodecError::Truncated { received, expected: SENSOR_PACKET_SIZE.max(received + 1) })
    }

    fn resync(&mut self, from: usize) {
        let start = self.find_start(&self.buffer, from).unwrap_or(self.buffer.len());
        self.buffer.drain(..start);
    }

    /// Where a complete, valid packet starting with the learned signature begins after the
    /// first byte, if one does.
    fn next_complete_start(&self) -> Option<usize> {
        let signature = self.signature.as_ref()?;
        let k = (1..self.buffer.len().saturating_sub(signature.len() - 1))
            .find(|&i| self.buffer[i..].starts_with(signature))?;
        match measure(&self.buffer[k..]) {
            Extent::Complete(n) if decode_sensor_map(&self.buffer[k..k + n]).is_ok() => Some(k),
            _ => None,
        }
    }

    /// The first offset at or after `from` where a sensor packet could begin. A candidate cut
    /// off by the end of the buffer counts, so the start of a packet still arriving is kept.
    fn find_start(&self, bytes: &[u8], from: usize) -> Option<usize> {
        (from..bytes.len()).find(|&i| {
            let rest = &bytes[i..];
            match &self.signature {
                Some(signature) => {
                    let n = rest.len().min(signature.len());
                    rest[..n] == signature[..n]
                }
                None => could_start_packet(rest),
            }
        })
    }
}

/// The bytes every packet of this stream starts with: the map header and the first key.
fn signature(packet: &[u8]) -> Option<Vec<u8>> {
    let header = match packet.first()? {
        0x80..=0x8f => 1,
        0xde => 3,
        0xdf => 5,
        _ => return None,
    };
    let marker = *packet.get(header)?;
    if marker & 0xe0 != 0xa0 {
        return None;
    }
    let end = header + 1 + usize::from(marker & 0x1f);
    packet.get(..end).map(<[u8]>::to_vec)
}

fn could_start_packet(bytes: &[u8]) -> bool {
    let header = match bytes.first() {
        Some(0x81..=0x8f) => 1,
        Some(0xde) => 3,
        Some(0xdf) => 5,
        _ => return false,
    };
    let Some(rest) = bytes.get(header..) else { return true };
    let Some(&marker) = rest.first() else { return true };
    if marker & 0xe0 != 0xa0 {
        return false;
    }
    let len = usize::from(marker & 0x1f);
    let available = &rest[1..];
    SENSOR_KEYS.iter().any(|key| {
        key.len() == len && {
            let n = available.len().min(len);
            key.as_bytes()[..n] == available[..n]
        }
    })
}

#[cfg(test)]
// A panic is how a test reports failure.
#[allow(clippy::unwrap_used)]
pub(crate) mod tests {
    use super::*;

    /// A sensor packet like one recorded on a standing NAO v6.
    pub(crate) fn standing_packet() -> SensorPacket {
        use crate::joints::Joint;
        let mut position = [0.0; JOINT_COUNT];
        for (joint, angle) in [
            (Joint::LShoulderPitch, 1.57),
            (Joint::RShoulderPitch, 1.57),
            (Joint::LElbowRoll, -0.44),
            (Joint::RElbowRoll, 0.44),
            (Joint::LHipPitch, -0.4),
            (Joint::RHipPitch, -0.4),
            (Joint::LKneePitch, 0.8),
            (Joint::RKneePitch, 0.8),
            (Joint::LAnklePitch, -0.4),
            (Joint::RAnklePitch, -0.4),
        ] {
            position[joint.index()] = angle;
        }
        SensorPacket {
            stiffness: [0.7; JOINT_COUNT],
            position,
            temperature: [32.0; JOINT_COUNT],
            current: [0.1; JOINT_COUNT],
            battery: Battery([0.86, 130.0, -1.2, 31.0]),
            accelerometer: [0.1, -0.05, -9.81],
            gyroscope: [0.001, -0.002, 0.0],
            angles: [0.01, 0.02],
            sonar: [1.2, 2.5],
            fsr: [0.5, 0.6, 0.4, 0.5, 0.55, 0.5, 0.45, 0.5],
            touch: [0.0; touch::COUNT],
            status: [0; JOINT_COUNT],
            robot_config: RobotConfig {
                body_id: "P0000074A05S94300042".into(),
                body_version: "6.0.0".into(),
                head_id: "P0000073A07S9AB00123".into(),
                head_version: "6.0.0".into(),
            },
        }
    }

    #[test]
    fn a_nao_sized_packet_is_896_bytes_and_round_trips() {
        let packet = standing_packet();
        let bytes = packet.encode().unwrap();
        assert_eq!(bytes.len(), SENSOR_PACKET_SIZE);
        assert_eq!(SensorPacket::decode(&bytes).unwrap(), packet);
    }

    #[test]
    fn truncation_is_reported_with_byte_counts() {
        let bytes = standing_packet().encode().unwrap();
        let err = SensorPacket::decode(&bytes[..500]).unwrap_err();
        assert_eq!(err, CodecError::Truncated { received: 500, expected: SENSOR_PACKET_SIZE });
        assert!(err.to_string().contains("500 bytes of a 896-byte packet"), "{err}");
    }

    #[test]
    fn trailing_bytes_are_rejected() {
        let mut bytes = standing_packet().encode().unwrap();
        bytes.extend_from_slice(&[0xc0, 0xc0]);
        assert_eq!(
            SensorPacket::decode(&bytes).unwrap_err(),
            CodecError::TrailingBytes { packet: SENSOR_PACKET_SIZE, trailing: 2 }
        );
    }

    /// Encodes a map built from `entries` so tests can remove, duplicate or reshape keys.
    fn encode_entries(entries: &[(&str, rmp_value::V)]) -> Vec<u8> {
        let mut out = Vec::new();
        rmp_value::write_map(&mut out, entries);
        out
    }

    /// A tiny msgpack writer for building malformed maps in tests.
    pub(crate) mod rmp_value {
        pub enum V {
            Floats(Vec<f32>),
            Ints(Vec<i64>),
            Strs(Vec<&'static str>),
            Str(&'static str),
        }

        fn write_len(out: &mut Vec<u8>, n: usize, fix: u8, m16: u8) {
            if n < 16 {
                out.push(fix | n as u8);
            } else {
                out.push(m16);
                out.extend_from_slice(&(n as u16).to_be_bytes());
            }
        }

        fn write_str(out: &mut Vec<u8>, s: &str) {
            out.push(0xa0 | s.len() as u8);
            out.extend_from_slice(s.as_bytes());
        }

        pub fn write_map(out: &mut Vec<u8>, entries: &[(&str, V)]) {
            write_len(out, entries.len(), 0x80, 0xde);
            for (key, value) in entries {
                write_str(out, key);
                match value {
                    V::Floats(v) => {
                        write_len(out, v.len(), 0x90, 0xdc);
                        for x in v {
                            out.push(0xca);
                            out.extend_from_slice(&x.to_be_bytes());
                        }
                    }
                    V::Ints(v) => {
                        write_len(out, v.len(), 0x90, 0xdc);
                        for x in v {
                            out.push(0xd3);
                            out.extend_from_slice(&x.to_be_bytes());
                        }
                    }
                    V::Strs(v) => {
                        write_len(out, v.len(), 0x90, 0xdc);
                        for s in v {
                            write_str(out, s);
                        }
                    }
                    V::Str(s) => write_str(out, s),
                }
            }
        }
    }

    fn valid_entries() -> Vec<(&'static str, rmp_value::V)> {
        use rmp_value::V;
        vec![
            ("Stiffness", V::Floats(vec![0.5; 25])),
            ("Position", V::Floats(vec![0.0; 25])),
            ("Temperature", V::Floats(vec![30.0; 25])),
            ("Current", V::Floats(vec![0.0; 25])),
            ("Battery", V::Floats(vec![1.0, 0.0, 0.0, 30.0])),
            ("Accelerometer", V::Floats(vec![0.0, 0.0, -9.81])),
            ("Gyroscope", V::Floats(vec![0.0; 3])),
            ("Angles", V::Floats(vec![0.0; 2])),
            ("Sonar", V::Floats(vec![0.0; 2])),
            ("FSR", V::Floats(vec![0.0; 8])),
            ("Touch", V::Floats(vec![0.0; 14])),
            ("Status", V::Ints(vec![0; 25])),
            ("RobotConfig", V::Strs(vec!["b", "6.0.0", "h", "6.0.0"])),
        ]
    }

    #[test]
    fn integer_values_and_unknown_keys_are_accepted() {
        let mut entries = valid_entries();
        entries[5].1 = rmp_value::V::Ints(vec![0, 0, -10]);
        entries.push(("Future", rmp_value::V::Str("ignored")));
        let packet = SensorPacket::decode(&encode_entries(&entries)).unwrap();
        assert_eq!(packet.accelerometer, [0.0, 0.0, -10.0]);
        assert_eq!(packet.robot_config.head_id, "h");
    }

    #[test]
    fn a_missing_key_is_named() {
        for index in 0..SENSOR_KEYS.len() {
            let mut entries = valid_entries();
            let (key, _) = entries.remove(index);
            let err = SensorPacket::decode(&encode_entries(&entries)).unwrap_err();
            assert_eq!(err, CodecError::key(key, KeyProblem::Missing));
            assert_eq!(err.to_string(), format!("key \"{key}\" is missing"));
        }
    }

    #[test]
    fn a_wrong_length_is_named() {
        let mut entries = valid_entries();
        entries[9].1 = rmp_value::V::Floats(vec![0.0; 7]);
        let err = SensorPacket::decode(&encode_entries(&entries)).unwrap_err();
        assert_eq!(err, CodecError::key("FSR", KeyProblem::WrongLength { expected: 8, found: 7 }));
        assert_eq!(err.to_string(), "key \"FSR\" has 7 values, expected 8");

        let mut entries = valid_entries();
        entries[12].1 = rmp_value::V::Strs(vec!["a", "b", "c"]);
        let err = SensorPacket::decode(&encode_entries(&entries)).unwrap_err();
        assert_eq!(
            err,
            CodecError::key("RobotConfig", KeyProblem::WrongLength { expected: 4, found: 3 })
        );
    }

    #[test]
    fn a_wrong_type_is_named() {
        let mut entries = valid_entries();
        entries[6].1 = rmp_value::V::Str("fast");
        let err = SensorPacket::decode(&encode_entries(&entries)).unwrap_err();
        assert!(
            matches!(&err, CodecError::Key { key, problem: KeyProblem::WrongType(_) } if key == "Gyroscope"),
            "{err}"
        );

        let mut entries = valid_entries();
        entries[1].1 = rmp_value::V::Strs(vec!["x"; 25]);
        let err = SensorPacket::decode(&encode_entries(&entries)).unwrap_err();
        assert!(
            err.to_string().starts_with("key \"Position\" has a wrong value type: value 0"),
            "{err}"
        );
    }

    #[test]
    fn a_duplicate_key_is_named() {
        let mut entries = valid_entries();
        entries.push(("Angles", rmp_value::V::Floats(vec![0.0; 2])));
        let err = SensorPacket::decode(&encode_entries(&entries)).unwrap_err();
        assert_eq!(err, CodecError::key("Angles", KeyProblem::Duplicate));
    }

    #[test]
    fn not_a_map_is_malformed() {
        assert!(matches!(SensorPacket::decode(&[0x93, 1, 2, 3]), Err(CodecError::Msgpack(_))));
        assert!(matches!(SensorPacket::decode(&[0xc1]), Err(CodecError::Msgpack(_))));
        assert!(matches!(SensorPacket::decode(&[]), Err(CodecError::Truncated { .. })));
    }

    #[test]
    fn hostile_lengths_do_not_allocate_or_hang() {
        // array32 and str32 claiming four billion entries, with nothing behind them.
        for bytes in [&[0xdd, 0xff, 0xff, 0xff, 0xff][..], &[0xdb, 0xff, 0xff, 0xff, 0xff][..]] {
            assert!(matches!(SensorPacket::decode(bytes), Err(CodecError::Truncated { .. })));
        }
        // Deep nesting is cut off by the depth limit.
        let deep = vec![0x91; 10_000];
        assert!(SensorPacket::decode(&deep).is_err());
    }

    #[test]
    fn framer_splits_a_stream_and_survives_partial_reads() {
        let a = standing_packet();
        let mut b = standing_packet();
        b.angles = [0.3, -0.2];
        let mut stream = a.encode().unwrap();
        stream.extend(b.encode().unwrap());
        let mut framer = PacketFramer::new();
        let mut out = Vec::new();
        for chunk in stream.chunks(100) {
            framer.push(chunk);
            while let Some(packet) = framer.next_packet() {
                out.push(packet.unwrap());
            }
        }
        assert_eq!(out, vec![a, b]);
        assert_eq!(framer.buffered(), 0);
        assert_eq!(framer.flush_partial(), None);
    }

    #[test]
    fn framer_reports_a_truncated_packet_and_resynchronises() {
        let a = standing_packet();
        let mut b = standing_packet();
        b.angles = [0.5, 0.5];
        let bytes_a = a.encode().unwrap();
        let mut stream = bytes_a[..400].to_vec();
        stream.extend(b.encode().unwrap());
        stream.extend(a.encode().unwrap());
        let mut framer = PacketFramer::new();
        framer.push(&stream);
        assert_eq!(
            framer.next_packet(),
            Some(Err(CodecError::Truncated { received: 400, expected: SENSOR_PACKET_SIZE }))
        );
        assert_eq!(framer.next_packet(), Some(Ok(b)));
        assert_eq!(framer.next_packet(), Some(Ok(a)));
        assert_eq!(framer.next_packet(), None);
    }

    #[test]
    fn framer_does_not_mistake_a_key_inside_a_packet_for_a_new_packet() {
        // A float whose last byte is 0x8d (a map header of 13) right before the "Angles" key.
        let mut good = standing_packet();
        good.gyroscope[2] = f32::from_bits(0x3f80_008d);
        let mut bad = good.encode().unwrap();
        let at = bad.windows(13).position(|w| w == b"Accelerometer").unwrap();
        bad[at + 9] = b'x';
        let mut framer = PacketFramer::new();
        framer.push(&good.encode().unwrap());
        framer.push(&bad);
        framer.push(&good.encode().unwrap());
        assert_eq!(framer.next_packet(), Some(Ok(good.clone())));
        assert_eq!(
            framer.next_packet(),
            Some(Err(CodecError::key("Accelerometer", KeyProblem::Missing)))
        );
        assert_eq!(framer.next_packet(), Some(Ok(good)));
        assert_eq!(framer.next_packet(), None);
    }

    #[test]
    fn framer_detects_a_cut_that_leaves_the_structure_waiting() {
        let a = standing_packet();
        let mut b = standing_packet();
        b.angles = [0.25, 0.5];
        let bytes_a = a.encode().unwrap();
        // Cut right after the header of the 25 temperatures: the next packet alone cannot
        // fill them, so the measured value stays incomplete.
        let cut = bytes_a.windows(11).position(|w| w == b"Temperature").unwrap() + 11 + 3;
        let mut framer = PacketFramer::new();
        framer.push(&bytes_a);
        assert_eq!(framer.next_packet(), Some(Ok(a.clone())));
        framer.push(&bytes_a[..cut]);
        framer.push(&b.encode().unwrap());
        assert_eq!(
            framer.next_packet(),
            Some(Err(CodecError::Truncated { received: cut, expected: SENSOR_PACKET_SIZE }))
        );
        assert_eq!(framer.next_packet(), Some(Ok(b)));
        assert_eq!(framer.next_packet(), None);
    }

    #[test]
    fn framer_skips_garbage_and_reports_a_partial_tail() {
        let a = standing_packet();
        let mut stream = vec![0xc1, 0xff, 0x00, 0x8d];
        stream.extend(a.encode().unwrap());
        let mut framer = PacketFramer::new();
        framer.push(&stream);
        let mut errors = 0;
        let packet = loop {
            match framer.next_packet() {
                Some(Ok(p)) => break p,
                Some(Err(_)) => errors += 1,
                None => panic!("packet lost"),
            }
        };
        assert!(errors >= 1);
        assert_eq!(packet, a);
        framer.push(&a.encode().unwrap()[..10]);
        assert_eq!(framer.next_packet(), None);
        assert_eq!(
            framer.flush_partial(),
            Some(CodecError::Truncated { received: 10, expected: SENSOR_PACKET_SIZE })
        );
    }

    #[test]
    fn actuator_packet_round_trips_with_lola_keys() {
        let mut leds = Leds { chest: Rgb::BLUE, ..Leds::default() };
        leds.left_eye[1] = Rgb::new(0.2, 0.4, 2.0);
        leds.skull[3] = f32::NAN;
        let mut stiffness = [0.5; JOINT_COUNT];
        stiffness[0] = 7.0;
        let packet = ActuatorPacket::new([0.1; JOINT_COUNT], stiffness, &leds, true);
        assert_eq!(packet.chest, [0.0, 0.0, 1.0]);
        assert_eq!(packet.left_eye[1], 0.2);
        assert_eq!(packet.left_eye[9], 0.4);
        assert_eq!(packet.left_eye[17], 1.0);
        assert_eq!(packet.skull[3], 0.0);
        assert_eq!(packet.stiffness[0], 1.0);
        let bytes = packet.encode().unwrap();
        for key in [
            "Position",
            "Stiffness",
            "REar",
            "LEar",
            "Chest",
            "LEye",
            "REye",
            "LFoot",
            "RFoot",
            "Skull",
            "Sonar",
        ] {
            assert!(bytes.windows(key.len()).any(|w| w == key.as_bytes()), "{key}");
        }
        assert_eq!(ActuatorPacket::decode(&bytes).unwrap(), packet);
    }

    #[test]
    fn battery_fields_follow_lola_order() {
        let b = Battery([0.5, 128.0, -2.0, 40.0]);
        assert_eq!(b.charge(), 0.5);
        assert!(b.charging());
        assert_eq!(b.current(), -2.0);
        assert_eq!(b.temperature(), 40.0);
        assert!(!Battery([0.5, 0.0, 1.0, 40.0]).charging());
    }
}
