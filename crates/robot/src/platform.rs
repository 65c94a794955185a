//! The abstract hardware layer (paper 3.7): everything perception and actuation need from a
//! robot, and nothing else. Instances: the in-process simulator, the simulator over TCP, a NAO
//! v6 through LoLA. Simulation swaps the platform, never the robot code (docs/architecture.md,
//! Principles, 7).

use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde::{Deserialize, Serialize};
use strata_runtime::Time;

use crate::geometry::{Odometry, Velocity};

/// A class of object a camera can report. The codes are the application's (and its
/// platforms'): the architecture only compares them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct ObjectClass(pub u16);

/// Inertial measurements in the robot's torso frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct InertialData {
    /// m/s^2; standing upright reads about (0, 0, +9.81).
    pub accelerometer: [f64; 3],
    /// rad/s around x (roll), y (pitch), z (yaw).
    pub gyroscope: [f64; 3],
    /// Torso roll and pitch from the IMU's own filter, rad (0 when upright; pitch > 0 leaning
    /// forward).
    pub body_angles: [f64; 2],
}

/// Head joint angles (encoders, or targets).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct HeadAngles {
    /// Left positive, rad.
    pub yaw: f64,
    /// Down positive, rad.
    pub pitch: f64,
}

/// Foot pressure, the stability signal of the feet.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FootContact {
    /// Total pressure under each foot, kg.
    pub left: f64,
    pub right: f64,
}

impl FootContact {
    /// Whether any foot carries weight (a lifted or fallen robot has none).
    pub fn on_ground(&self, threshold: f64) -> bool {
        self.left + self.right > threshold
    }
}

/// The robot's buttons and touch sensors, pressed or not: bit `i` is the platform's button `i`,
/// which the platform names (`strata_nao::buttons::CHEST`); the robot crate knows no body's
/// buttons.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Buttons {
    pub pressed: u32,
}

impl Buttons {
    /// Whether every button of `mask` is pressed.
    pub fn all(self, mask: u32) -> bool {
        self.pressed & mask == mask
    }

    /// Whether any button of `mask` is pressed.
    pub fn any(self, mask: u32) -> bool {
        self.pressed & mask != 0
    }
}

/// One object reported by the camera.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Detection {
    pub class: ObjectClass,
    /// Distinguishes objects of one class when the camera can (a goal's colour, a beacon's
    /// pattern, a robot's jersey); `None` when it cannot (a white goal post).
    pub variant: Option<u16>,
    /// Ground distance from the robot, m.
    pub range: f64,
    /// Angle from the camera's optical axis, left positive, rad.
    pub bearing: f64,
    /// The feature's own orientation relative to the camera axis (line crossings), rad.
    pub orientation: Option<f64>,
}

/// What the camera delivered in one image.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CameraFrame {
    /// When the image was taken.
    pub stamp: Time,
    /// Head joint angles when the image was taken (bearings are relative to this gaze).
    pub head: HeadAngles,
    pub detections: Vec<Detection>,
    /// The stretch of ground the image covered along its axis, for platforms whose camera
    /// looks down at the ground (a tall robot cannot see its own feet while it looks far, nor
    /// far while it looks at its feet); `None` when the platform does not model it.
    #[serde(default)]
    pub footprint: Option<Footprint>,
}

/// Ground distances from the robot between which an image could show an object, m.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Footprint {
    pub near: f64,
    pub far: f64,
}

/// Everything the platform measured in one sensor cycle.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SensorFrame {
    /// When the data was measured, on the host's clock.
    pub stamp: Time,
    pub inertial: InertialData,
    pub head: HeadAngles,
    pub foot_contact: FootContact,
    pub buttons: Buttons,
    /// Battery charge in [0, 1], if the platform knows it.
    pub battery: Option<f64>,
    /// A camera image's detections, when one was completed since the last frame (cameras run
    /// slower than the inertial sensors).
    pub camera: Option<CameraFrame>,
    /// The platform saw the robot moved by something other than its own motion since the last
    /// frame: put somewhere by a referee or a trainer (rcssservermj's referee turns it in one
    /// cycle), not a placement the robot knows the destination of (its own beam). World
    /// modeling takes it as a kidnap. False when the platform cannot tell.
    #[serde(default)]
    pub placed: bool,
    /// The platform's whistle detector fired since the last frame, with this confidence in
    /// [0, 1]; `None` when it did not (or the platform has no microphone).
    #[serde(default)]
    pub whistle: Option<f64>,
}

/// The name of a kind of special motion: `"stand_up"`, `"fall"`, or one the application
/// names (soccer's `"kick"` and `"dive"`). Held inline, so a motion is `Copy` and passing one
/// along never allocates, whether it was named by a constant or read from a protocol or a log.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct MotionName {
    len: u8,
    bytes: [u8; MotionName::CAPACITY],
}

/// A motion name that is empty or longer than [`MotionName::CAPACITY`] bytes.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("a motion name has 1 to {} bytes, not {len} ({name:?})", MotionName::CAPACITY)]
pub struct InvalidMotionName {
    /// The name's first characters: enough to find it, never a whole message a peer sent.
    pub name: String,
    pub len: usize,
}

impl MotionName {
    /// The longest name, in bytes.
    pub const CAPACITY: usize = 31;
    /// The robot's getting up from the ground ([`crate::control::primitives::StandUp`]).
    pub const STAND_UP: MotionName = MotionName::from_static("stand_up");
    /// The protective fall the fall detector calls for.
    pub const FALL: MotionName = MotionName::from_static("fall");

    /// A name known when the program is built. Evaluated in a `const`, an empty or too long
    /// name fails the build; elsewhere it panics, so names read at run time go through
    /// [`MotionName::new`].
    pub const fn from_static(name: &'static str) -> MotionName {
        match MotionName::checked(name) {
            Some(name) => name,
            None => panic!("a motion name has 1 to MotionName::CAPACITY bytes"),
        }
    }

    /// A name read at run time (a motion file, a protocol).
    pub fn new(name: &str) -> Result<MotionName, InvalidMotionName> {
        MotionName::checked(name).ok_or_else(|| InvalidMotionName {
            name: name.chars().take(2 * MotionName::CAPACITY).collect(),
            len: name.len(),
        })
    }

    const fn checked(name: &str) -> Option<MotionName> {
        let source = name.as_bytes();
        if source.is_empty() || source.len() > MotionName::CAPACITY {
            return None;
        }
        let mut bytes = [0; MotionName::CAPACITY];
        let mut i = 0;
        while i < source.len() {
            bytes[i] = source[i];
            i += 1;
        }
        // The unused bytes stay zero, so equal names have equal bytes (derived `Eq`, `Hash`).
        Some(MotionName { len: source.len() as u8, bytes })
    }

    pub fn as_str(&self) -> &str {
        // Copied whole from a `str`, never cut: always UTF-8.
        std::str::from_utf8(&self.bytes[..usize::from(self.len)]).unwrap_or_default()
    }
}

impl std::fmt::Debug for MotionName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        std::fmt::Debug::fmt(self.as_str(), f)
    }
}

impl std::fmt::Display for MotionName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl Serialize for MotionName {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.as_str())
    }
}

impl<'de> Deserialize<'de> for MotionName {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Name;
        impl serde::de::Visitor<'_> for Name {
            type Value = MotionName;

            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                write!(f, "a motion name of 1 to {} bytes", MotionName::CAPACITY)
            }

            fn visit_str<E: serde::de::Error>(self, name: &str) -> Result<MotionName, E> {
                // A CDR trace reads an empty placeholder where a name would be.
                if name.is_empty() && strata_runtime::cdr::is_tracing() {
                    return Ok(MotionName::STAND_UP);
                }
                MotionName::new(name).map_err(E::custom)
            }
        }
        deserializer.deserialize_str(Name)
    }
}

/// A non-parametric movement sequence (paper 3.5.1, the special policy): a kind the
/// application names, and a number that selects one sequence of that kind in the platform's
/// motion catalogue ([`PlatformInfo::motions`]). The robot crate names the two every biped
/// needs ([`SpecialMotion::stand_up`], [`SpecialMotion::fall`]); an application names its own
/// (soccer: `strata_soccer::motions::kick`). A platform runs the kinds in its catalogue and
/// refuses the others ([`PlatformError::Unsupported`]), which actuation reports.
///
/// In text (a motion file, the simulator's JSON protocol) `{ kind = "stand_up", sequence = 2 }`,
/// with `head = false` for a motion that leaves the head free (left out where text written
/// before applications named their motions implied it: `{ kind = "kick", sequence = 0 }`). In
/// binary encodings (logs) the four kinds the robot crate once named itself are a variant and a
/// number, the same bytes as then; any other motion is a fifth variant with the kind, the
/// number and the head use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SpecialMotion {
    pub kind: MotionName,
    pub sequence: u8,
    /// Whether the sequence moves the head as well as the body: while it runs, head commands
    /// are refused. A kick leaves the head to keep the ball in view; getting up does not.
    pub head: bool,
}

impl SpecialMotion {
    pub const fn new(kind: MotionName, sequence: u8, head: bool) -> SpecialMotion {
        SpecialMotion { kind, sequence, head }
    }

    /// Getting up from the ground: stand-up `sequence` of the catalogue. Head and body.
    pub const fn stand_up(sequence: u8) -> SpecialMotion {
        SpecialMotion::new(MotionName::STAND_UP, sequence, true)
    }

    /// Protective fall: minimise joint torque once instability is detected. Head and body.
    pub const fn fall(sequence: u8) -> SpecialMotion {
        SpecialMotion::new(MotionName::FALL, sequence, true)
    }

    /// Whether this is a motion of kind `kind`.
    pub fn is(&self, kind: MotionName) -> bool {
        self.kind == kind
    }

    /// Whether `other` selects the same sequence of a catalogue: the kind and the number (the
    /// head use is the caller's claim, not part of the sequence).
    pub fn same_sequence(&self, other: &SpecialMotion) -> bool {
        self.kind == other.kind && self.sequence == other.sequence
    }
}

/// The head use a text form leaves out: the whole robot, except for the kinds the robot crate
/// named before applications named their own, which keep the head use they had then (so motion
/// files and protocol messages written then read the same).
fn usual_head(kind: MotionName) -> bool {
    LEGACY_KINDS.iter().find(|(name, _)| *name == kind).is_none_or(|(_, head)| *head)
}

impl std::fmt::Display for SpecialMotion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} {}", self.kind, self.sequence)?;
        if self.head != usual_head(self.kind) {
            write!(f, " ({} the head)", if self.head { "with" } else { "without" })?;
        }
        Ok(())
    }
}

/// The kinds the robot crate named itself until applications named their own, in the order of
/// that enum's variants (a log's variant index) and with the head use each had. Only for the
/// forms written then, which stay as they were: the robot crate runs no kick and no dive.
const LEGACY_KINDS: [(MotionName, bool); 4] = [
    (MotionName::from_static("kick"), false),
    (MotionName::STAND_UP, true),
    (MotionName::FALL, true),
    (MotionName::from_static("dive"), true),
];

mod special_motion_forms {
    use super::{LEGACY_KINDS, MotionName, SpecialMotion, usual_head};
    use serde::{Deserialize, Serialize};

    #[derive(Serialize, Deserialize)]
    #[serde(rename = "SpecialMotion", deny_unknown_fields)]
    struct Text {
        kind: MotionName,
        sequence: u8,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        head: Option<bool>,
    }

    /// Positional. The first four variants are the enum logs held before applications named
    /// their motions (CDR writes a variant's index, MessagePack its name); any other kind, or
    /// one of those four with another head use, is `Named`.
    #[derive(Serialize, Deserialize)]
    #[serde(rename = "SpecialMotion", rename_all = "snake_case")]
    enum Binary {
        Kick(u8),
        StandUp(u8),
        Fall(u8),
        Dive(u8),
        Named { kind: MotionName, sequence: u8, head: bool },
    }

    impl Serialize for SpecialMotion {
        fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
            let SpecialMotion { kind, sequence, head } = *self;
            if serializer.is_human_readable() {
                let head = (head != usual_head(kind)).then_some(head);
                Text { kind, sequence, head }.serialize(serializer)
            } else {
                // The four kinds logs held as variants keep their bytes, so logs of the same
                // run are the same and older ones replay without differences.
                let [kick, stand_up, fall, dive] = LEGACY_KINDS;
                let binary = match (kind, head) {
                    legacy if legacy == kick => Binary::Kick(sequence),
                    legacy if legacy == stand_up => Binary::StandUp(sequence),
                    legacy if legacy == fall => Binary::Fall(sequence),
                    legacy if legacy == dive => Binary::Dive(sequence),
                    _ => Binary::Named { kind, sequence, head },
                };
                binary.serialize(serializer)
            }
        }
    }

    impl<'de> Deserialize<'de> for SpecialMotion {
        fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
            if deserializer.is_human_readable() {
                let Text { kind, sequence, head } = Text::deserialize(deserializer)?;
                let head = head.unwrap_or_else(|| usual_head(kind));
                return Ok(SpecialMotion { kind, sequence, head });
            }
            let [kick, stand_up, fall, dive] = LEGACY_KINDS;
            let ((kind, head), sequence) = match Binary::deserialize(deserializer)? {
                Binary::Kick(sequence) => (kick, sequence),
                Binary::StandUp(sequence) => (stand_up, sequence),
                Binary::Fall(sequence) => (fall, sequence),
                Binary::Dive(sequence) => (dive, sequence),
                Binary::Named { kind, sequence, head } => ((kind, head), sequence),
            };
            Ok(SpecialMotion { kind, sequence, head })
        }
    }
}

/// A catalogue entry: what a platform can execute and for how long.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MotionSpec {
    pub motion: SpecialMotion,
    pub name: String,
    #[serde(with = "strata_runtime::serde_duration")]
    pub duration: Duration,
}

/// The stage of a cyclic movement (paper 3.5.1): the execution stage is the one a new command
/// can change without disturbing the robot.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CycleStage {
    Initialization,
    Execution,
    End,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FallDirection {
    Front,
    Back,
    Left,
    Right,
}

strata_runtime::text_and_binary_enum! {
    /// What the body is doing, as the platform reports it. Tagged by `state` in text (the
    /// simulator's protocol), externally in binary encodings (logs).
    #[derive(Clone, Copy, Debug, PartialEq)]
    pub enum BodyMotionState {
        Standing,
        Walking {
            stage: CycleStage,
            velocity: Velocity,
        },
        Special {
            motion: SpecialMotion,
            elapsed: f64,
            duration: f64,
        },
        /// Lying on the ground; only a stand-up sequence helps.
        Fallen {
            direction: FallDirection,
        },
        /// Motors off or unsupported: the platform does nothing with body orders.
        Limp,
    }
    text: #[serde(tag = "state", rename_all = "snake_case")]
    binary: #[serde(rename_all = "snake_case")]
}

/// What actuation reads back from the platform every cycle.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MotionFeedback {
    pub stamp: Time,
    pub body: BodyMotionState,
    pub head: HeadAngles,
    /// The head reached its last ordered target.
    pub head_settled: bool,
    /// Motion since the previous feedback, from the walking engine's model (with its errors).
    pub odometry: Odometry,
}

/// A head order: move the joints to these angles, no faster than `max_speed`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HeadOrder {
    pub target: HeadAngles,
    /// rad/s.
    pub max_speed: f64,
}

strata_runtime::text_and_binary_enum! {
    /// A body order, held until replaced. Tagged by `order` in text (the simulator's protocol),
    /// externally in binary encodings (logs, whose positional encoding has no internal tags).
    #[derive(Clone, Copy, Debug, PartialEq)]
    pub enum BodyOrder {
        Stand,
        Walk { velocity: Velocity },
        Special { motion: SpecialMotion },
    }
    text: #[serde(tag = "order", rename_all = "snake_case")]
    binary: #[serde(rename_all = "snake_case")]
}

/// What actuation sends to the platform. `None` keeps the previous order.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ActuatorOrders {
    pub head: Option<HeadOrder>,
    pub body: Option<BodyOrder>,
}

/// What a platform is and can do.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlatformInfo {
    pub name: String,
    /// Inertial sensor period (NAO v6: 12 ms, 83 Hz).
    #[serde(with = "strata_runtime::serde_duration")]
    pub sensor_period: Duration,
    /// Camera horizontal field of view, rad.
    pub camera_fov: f64,
    /// Maximum detection range, m.
    pub camera_range: f64,
    pub head_yaw_limits: (f64, f64),
    pub head_pitch_limits: (f64, f64),
    pub max_head_speed: f64,
    pub max_velocity: Velocity,
    pub motions: Vec<MotionSpec>,
    /// Whether the platform can walk (a NAO without a gait engine cannot).
    pub can_walk: bool,
}

impl PlatformInfo {
    /// The catalogue entry of `motion`'s sequence (its kind and number).
    pub fn motion(&self, motion: SpecialMotion) -> Option<&MotionSpec> {
        self.motions.iter().find(|m| m.motion.same_sequence(&motion))
    }
}

/// Why a platform call failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlatformError {
    #[error("platform disconnected: {0}")]
    Disconnected(String),
    #[error("malformed data from the platform: {0}")]
    Malformed(String),
    #[error("the platform does not support {0}")]
    Unsupported(String),
    #[error("platform I/O error: {0}")]
    Io(String),
}

/// The hardware of one robot. Calls never block past the current cycle: a platform that talks
/// to hardware or a network does its I/O on its own thread and hands over the newest data.
pub trait Platform: Send {
    fn info(&self) -> PlatformInfo;

    /// The newest sensor frame since the last call, stamped on the host clock (`now` is the
    /// host's current time, for platforms that stamp data on arrival).
    fn read_sensors(&mut self, now: Time) -> Result<Option<SensorFrame>, PlatformError>;

    /// The motion state and the odometry accumulated since the last call.
    fn read_motion(&mut self, now: Time) -> Result<MotionFeedback, PlatformError>;

    fn write(&mut self, now: Time, orders: &ActuatorOrders) -> Result<(), PlatformError>;
}

/// Maps an instant on this machine to the host's clock, for platforms that stamp data on
/// arrival: `now` is the host's present, so data received `age` ago was measured at
/// `now - age`.
pub fn stamp_at(now: Time, at: std::time::Instant) -> Time {
    let age = u64::try_from(at.elapsed().as_nanos()).unwrap_or(u64::MAX);
    Time::from_nanos(now.as_nanos().saturating_sub(age))
}

/// Problems a platform's I/O thread met since the robot last read its sensors, held for the
/// next `read_sensors` to report: bounded, so a peer sending garbage every cycle cannot grow
/// it, and counting what did not fit.
#[derive(Clone, Debug, PartialEq)]
pub struct PendingProblems<T> {
    problems: Vec<T>,
    dropped: usize,
    capacity: usize,
}

impl<T> PendingProblems<T> {
    pub fn new(capacity: usize) -> PendingProblems<T> {
        PendingProblems { problems: Vec::new(), dropped: 0, capacity }
    }

    /// Holds a problem, or counts it when the queue is full.
    pub fn push(&mut self, problem: T) {
        if self.problems.len() < self.capacity {
            self.problems.push(problem);
        } else {
            self.dropped += 1;
        }
    }

    pub fn is_empty(&self) -> bool {
        self.problems.is_empty()
    }

    pub fn iter(&self) -> impl Iterator<Item = &T> {
        self.problems.iter()
    }

    /// Empties the queue: the problems held and how many more did not fit.
    pub fn take(&mut self) -> (Vec<T>, usize) {
        (std::mem::take(&mut self.problems), std::mem::take(&mut self.dropped))
    }

    /// Empties the queue into one line: the problems' texts and how many more there were.
    pub fn take_text(&mut self, text: impl Fn(&T) -> &str) -> Option<String> {
        if self.problems.is_empty() {
            return None;
        }
        let (problems, dropped) = self.take();
        let mut line = problems.iter().map(text).collect::<Vec<_>>().join("; ");
        if dropped > 0 {
            line.push_str(&format!("; and {dropped} more"));
        }
        Some(line)
    }
}

/// A platform shared by the perception and actuation modules of one robot.
pub type SharedPlatform = Arc<Mutex<dyn Platform>>;

/// Locks a shared platform; a module that panicked while holding it leaves the platform's own
/// state consistent enough to keep reading sensors, so poisoning is not fatal.
pub fn lock_platform(
    platform: &SharedPlatform,
) -> std::sync::MutexGuard<'_, dyn Platform + 'static> {
    platform.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// A packet received from a teammate or an external device.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReceivedPacket {
    pub received: Time,
    pub bytes: Vec<u8>,
}

/// Why a communication link failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LinkError {
    #[error("message of {size} bytes exceeds the limit of {limit}")]
    TooLarge { size: usize, limit: usize },
    #[error("link closed: {0}")]
    Closed(String),
    #[error("link I/O error: {0}")]
    Io(String),
}

/// The robot's radio to its teammates (UDP broadcast on a field, the simulator's forwarding in
/// simulation). Used only by the planning layer (paper 3.3).
pub trait TeamLink: Send {
    fn send(&mut self, now: Time, payload: &[u8]) -> Result<(), LinkError>;
    /// Every packet received since the last call, oldest first; never blocks.
    fn receive(&mut self, now: Time) -> Result<Vec<ReceivedPacket>, LinkError>;
}

/// An external device that directs the robot (a game controller in soccer).
pub trait ExternalLink: Send {
    /// Every packet received since the last call; never blocks.
    fn receive(&mut self, now: Time) -> Result<Vec<ReceivedPacket>, LinkError>;
    /// Sends a status packet back to the device.
    fn send(&mut self, now: Time, payload: &[u8]) -> Result<(), LinkError>;
}

impl<L: TeamLink + ?Sized> TeamLink for Box<L> {
    fn send(&mut self, now: Time, payload: &[u8]) -> Result<(), LinkError> {
        (**self).send(now, payload)
    }

    fn receive(&mut self, now: Time) -> Result<Vec<ReceivedPacket>, LinkError> {
        (**self).receive(now)
    }
}

impl<L: ExternalLink + ?Sized> ExternalLink for Box<L> {
    fn receive(&mut self, now: Time) -> Result<Vec<ReceivedPacket>, LinkError> {
        (**self).receive(now)
    }

    fn send(&mut self, now: Time, payload: &[u8]) -> Result<(), LinkError> {
        (**self).send(now, payload)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pending_problems_are_bounded_and_reported_in_one_line() {
        let mut pending = PendingProblems::new(2);
        assert_eq!(pending.take_text(|p: &String| p), None);
        for problem in ["a", "b", "c", "d"] {
            pending.push(problem.to_owned());
        }
        assert_eq!(pending.take_text(|p| p).as_deref(), Some("a; b; and 2 more"));
        assert!(pending.is_empty());
        assert_eq!(pending.take(), (Vec::new(), 0));
    }
}
