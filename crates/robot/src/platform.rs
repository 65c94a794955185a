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

strata_runtime::text_and_binary_enum! {
    /// A non-parametric movement sequence (paper 3.5.1, the special policy). The number selects
    /// a sequence of that kind in the platform's motion catalogue ([`PlatformInfo::motions`]).
    /// In text (a motion file, the simulator's JSON protocol) `{ kind = "stand_up", sequence =
    /// 2 }`; in binary encodings (logs) a variant and a number.
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
    pub enum SpecialMotion {
        /// Uses the body only: the head stays free.
        Kick(u8),
        /// Uses head and body.
        StandUp(u8),
        /// Protective fall: minimise joint torque once instability is detected. Head and body.
        Fall(u8),
        /// Head and body.
        Dive(u8),
    }
    text: #[serde(tag = "kind", content = "sequence", rename_all = "snake_case")]
    binary: #[serde(rename_all = "snake_case")]
}

impl SpecialMotion {
    /// Whether the sequence needs the head as well as the body.
    pub fn uses_head(&self) -> bool {
        !matches!(self, SpecialMotion::Kick(_))
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
    pub fn motion(&self, motion: SpecialMotion) -> Option<&MotionSpec> {
        self.motions.iter().find(|m| m.motion == motion)
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
