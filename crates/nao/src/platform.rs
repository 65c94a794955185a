//! [`LolaPlatform`]: a NAO v6 as a Strata [`Platform`], over LoLA's Unix socket.
//!
//! A thread of its own does all socket I/O: it reads LoLA's stream, cuts it into sensor
//! packets, runs one cycle of the [`MotionController`] per packet and answers each with one
//! actuator packet. The [`Platform`] calls only exchange data with that thread under a mutex
//! held for microseconds, so none of them blocks past the cycle.

use std::io::{self, Read, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};
use strata_robot::geometry::Velocity;
use strata_robot::platform::{
    ActuatorOrders, Buttons, FootContact, HeadAngles, InertialData, MotionFeedback,
    PendingProblems, Platform, PlatformError, PlatformInfo, SensorFrame, stamp_at,
};
use strata_runtime::Time;

use crate::codec::{
    ActuatorPacket, CodecError, Leds, PacketFramer, RobotConfig, SensorPacket, touch,
};
use crate::controller::{CYCLE, MotionConfig, MotionController};
use crate::gait::{GaitEngine, NoGait};
use crate::joints::{Joint, head_pitch_limits};
use crate::keyframe::{MotionError, MotionLibrary};

/// The NAO's bits in [`Buttons::pressed`].
pub mod buttons {
    /// The chest button.
    pub const CHEST: u32 = 1;
    /// Any of the three head touch sensors.
    pub const HEAD: u32 = 1 << 1;
}

/// The NAO v6 camera's horizontal field of view (56.3°), rad.
pub const NAO_CAMERA_FOV: f64 = 0.9826;

/// Pending problems kept for `read_sensors` beyond which only a count is kept.
const MAX_PENDING: usize = 8;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LolaConfig {
    /// How long `connect` keeps retrying while LoLA's socket is not there yet, s.
    #[serde(with = "strata_runtime::serde_duration")]
    pub connect_timeout: Duration,
    /// How long `connect` waits for the first valid sensor packet, s.
    #[serde(with = "strata_runtime::serde_duration")]
    pub first_packet_timeout: Duration,
    /// Silence after which LoLA counts as stalled: reported once as an I/O error, and a packet
    /// left half-received is reported truncated, s.
    #[serde(with = "strata_runtime::serde_duration")]
    pub stall_timeout: Duration,
    /// Longest a write of one actuator packet may block, s.
    #[serde(with = "strata_runtime::serde_duration")]
    pub write_timeout: Duration,
    /// A directory of key-frame files replacing or adding to the built-in ones.
    pub motions_dir: Option<PathBuf>,
    pub motion: MotionConfig,
}

impl Default for LolaConfig {
    fn default() -> Self {
        LolaConfig {
            connect_timeout: Duration::from_secs(10),
            first_packet_timeout: Duration::from_secs(2),
            stall_timeout: Duration::from_millis(500),
            write_timeout: Duration::from_millis(100),
            motions_dir: None,
            motion: MotionConfig::default(),
        }
    }
}

/// Why the platform could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum LolaError {
    #[error("cannot connect to LoLA at {path} (tried for {waited:?}; is LoLA running?): {source}")]
    Connect { path: PathBuf, waited: Duration, source: io::Error },
    #[error("LoLA at {path} sent no valid sensor packet within {waited:?}{}", last_error.as_ref().map(|e| format!(" (last problem: {e})")).unwrap_or_default())]
    NoFirstPacket { path: PathBuf, waited: Duration, last_error: Option<String> },
    #[error(transparent)]
    Motions(#[from] MotionError),
    #[error("LoLA socket {path}: {source}")]
    Socket { path: PathBuf, source: io::Error },
}

/// Counters of the LoLA link since `connect`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct LolaStats {
    /// Sensor packets decoded.
    pub packets: u64,
    /// Stretches of the stream that were not a valid packet.
    pub malformed: u64,
    /// Actuator packets sent.
    pub replies: u64,
    /// Actuator packets that could not be sent in time.
    pub send_failures: u64,
}

#[derive(Debug)]
enum Pending {
    Malformed(String),
    Io(String),
}

impl Pending {
    fn text(&self) -> &str {
        match self {
            Pending::Malformed(text) | Pending::Io(text) => text,
        }
    }
}

#[derive(Debug)]
struct Received {
    packet: SensorPacket,
    at: Instant,
}

#[derive(Debug)]
struct Shared {
    controller: MotionController,
    /// The newest packet `read_sensors` has not returned yet.
    unread: Option<Received>,
    /// The newest packet, kept for feedback stamps and diagnostics.
    last: Option<Received>,
    pending: PendingProblems<Pending>,
    disconnected: Option<String>,
    stats: LolaStats,
}

impl Shared {
    fn report(&mut self, problem: Pending) {
        self.pending.push(problem);
    }
}

type SharedState = Arc<(Mutex<Shared>, Condvar)>;

fn lock(shared: &SharedState) -> MutexGuard<'_, Shared> {
    // The LoLA thread never panics while holding the lock in normal operation; if a panic did
    // poison it, the data is still the newest the robot has.
    shared.0.lock().unwrap_or_else(PoisonError::into_inner)
}

/// A NAO v6 over LoLA.
#[derive(Debug)]
pub struct LolaPlatform {
    path: PathBuf,
    shared: SharedState,
    info: PlatformInfo,
    stop: Arc<AtomicBool>,
    socket: UnixStream,
    thread: Option<JoinHandle<()>>,
}

impl LolaPlatform {
    /// Connects to LoLA at `path` (normally [`crate::DEFAULT_SOCKET_PATH`]) without a gait
    /// engine, and waits for the first valid sensor packet.
    pub fn connect(path: impl AsRef<Path>, config: LolaConfig) -> Result<LolaPlatform, LolaError> {
        LolaPlatform::connect_with_gait(path, config, Box::new(NoGait))
    }

    /// Connects with a walking engine.
    pub fn connect_with_gait(
        path: impl AsRef<Path>,
        config: LolaConfig,
        gait: Box<dyn GaitEngine>,
    ) -> Result<LolaPlatform, LolaError> {
        let path = path.as_ref().to_owned();
        let library = match &config.motions_dir {
            Some(dir) => MotionLibrary::with_overrides(dir)?,
            None => MotionLibrary::builtin()?,
        };
        let stream = connect_retrying(&path, config.connect_timeout)?;
        let socket_error = |source| LolaError::Socket { path: path.clone(), source };
        stream
            .set_read_timeout(Some(config.stall_timeout.max(Duration::from_millis(1))))
            .map_err(socket_error)?;
        stream
            .set_write_timeout(Some(config.write_timeout.max(Duration::from_millis(1))))
            .map_err(socket_error)?;
        let socket = stream.try_clone().map_err(socket_error)?;

        let controller = MotionController::new(config.motion.clone(), library, gait);
        let shared: SharedState = Arc::new((
            Mutex::new(Shared {
                controller,
                unread: None,
                last: None,
                pending: PendingProblems::new(MAX_PENDING),
                disconnected: None,
                stats: LolaStats::default(),
            }),
            Condvar::new(),
        ));
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let shared = Arc::clone(&shared);
            let stop = Arc::clone(&stop);
            let stall = config.stall_timeout;
            std::thread::Builder::new()
                .name("lola".to_owned())
                .spawn(move || io_loop(stream, &shared, &stop, stall))
                .map_err(socket_error)?
        };
        let mut platform = LolaPlatform {
            path: path.clone(),
            shared,
            info: PlatformInfo {
                name: String::new(),
                sensor_period: Duration::from_secs_f64(CYCLE),
                camera_fov: NAO_CAMERA_FOV,
                camera_range: 0.0,
                head_yaw_limits: (Joint::HeadYaw.limits().min, Joint::HeadYaw.limits().max),
                head_pitch_limits: (head_pitch_limits(0.0).min, head_pitch_limits(0.0).max),
                max_head_speed: config.motion.max_head_speed,
                max_velocity: Velocity::ZERO,
                motions: Vec::new(),
                can_walk: false,
            },
            stop,
            socket,
            thread: Some(thread),
        };
        platform.wait_for_first_packet(config.first_packet_timeout)?;
        let guard = lock(&platform.shared);
        let robot = guard.last.as_ref().map(|r| r.packet.robot_config.clone()).unwrap_or_default();
        let gait = guard.controller.gait();
        platform.info.name = format!(
            "NAO v6 (LoLA) head {} body {}, gait: {}",
            robot.head_id,
            robot.body_id,
            gait.name()
        );
        platform.info.can_walk = gait.max_velocity().is_some();
        platform.info.max_velocity = gait.max_velocity().unwrap_or(Velocity::ZERO);
        platform.info.motions = guard.controller.catalogue();
        drop(guard);
        tracing::info!(path = %path.display(), name = %platform.info.name, "connected to LoLA");
        Ok(platform)
    }

    fn wait_for_first_packet(&self, timeout: Duration) -> Result<(), LolaError> {
        let deadline = Instant::now() + timeout;
        let mut guard = lock(&self.shared);
        loop {
            if guard.stats.packets > 0 {
                return Ok(());
            }
            let now = Instant::now();
            if guard.disconnected.is_some() || now >= deadline {
                let last_error = guard
                    .disconnected
                    .clone()
                    .or_else(|| guard.pending.iter().last().map(|p| p.text().to_owned()));
                return Err(LolaError::NoFirstPacket {
                    path: self.path.clone(),
                    waited: timeout,
                    last_error,
                });
            }
            guard = self
                .shared
                .1
                .wait_timeout(guard, deadline - now)
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
    }

    /// Sets every LED; applied from the next LoLA cycle on.
    pub fn set_leds(&mut self, leds: Leds) {
        lock(&self.shared).controller.set_leds(leds);
    }

    /// Sits down and goes limp; returns how long that takes. For shutdown: call it, wait the
    /// returned time (or until [`LolaPlatform::busy`] is false), then drop the platform.
    pub fn sit_down(&mut self) -> Result<Duration, PlatformError> {
        let mut shared = lock(&self.shared);
        if let Some(reason) = &shared.disconnected {
            return Err(PlatformError::Disconnected(reason.clone()));
        }
        Ok(Duration::from_secs_f64(shared.controller.sit_down()))
    }

    /// Switches every motor off now.
    pub fn relax(&mut self) {
        lock(&self.shared).controller.relax();
    }

    /// Whether a key-frame sequence or the gait is still moving the body.
    pub fn busy(&self) -> bool {
        lock(&self.shared).controller.busy()
    }

    /// The newest sensor packet as LoLA sent it: joint temperatures and statuses, battery
    /// details, sonar, everything [`SensorFrame`] leaves out.
    pub fn latest_packet(&self) -> Option<SensorPacket> {
        lock(&self.shared).last.as_ref().map(|r| r.packet.clone())
    }

    pub fn robot_config(&self) -> Option<RobotConfig> {
        lock(&self.shared).last.as_ref().map(|r| r.packet.robot_config.clone())
    }

    pub fn stats(&self) -> LolaStats {
        lock(&self.shared).stats
    }

    pub fn socket_path(&self) -> &Path {
        &self.path
    }
}

impl Drop for LolaPlatform {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        // Unblocks the LoLA thread's read; an error only means the socket is already closed.
        let _ = self.socket.shutdown(std::net::Shutdown::Both);
        if let Some(thread) = self.thread.take()
            && thread.join().is_err()
        {
            tracing::error!("the LoLA thread panicked");
        }
    }
}

impl Platform for LolaPlatform {
    fn info(&self) -> PlatformInfo {
        self.info.clone()
    }

    fn read_sensors(&mut self, now: Time) -> Result<Option<SensorFrame>, PlatformError> {
        let mut shared = lock(&self.shared);
        let malformed = shared.pending.iter().any(|p| matches!(p, Pending::Malformed(_)));
        if let Some(text) = shared.pending.take_text(Pending::text) {
            return Err(if malformed {
                PlatformError::Malformed(text)
            } else {
                PlatformError::Io(text)
            });
        }
        match shared.unread.take() {
            Some(received) => sensor_frame(&received.packet, stamp_at(now, received.at)).map(Some),
            None => match &shared.disconnected {
                Some(reason) => Err(PlatformError::Disconnected(reason.clone())),
                None => Ok(None),
            },
        }
    }

    fn read_motion(&mut self, now: Time) -> Result<MotionFeedback, PlatformError> {
        let mut shared = lock(&self.shared);
        if let Some(reason) = &shared.disconnected {
            return Err(PlatformError::Disconnected(reason.clone()));
        }
        let stamp = shared.last.as_ref().map_or(now, |r| stamp_at(now, r.at));
        let controller = &mut shared.controller;
        Ok(MotionFeedback {
            stamp,
            body: controller.body_state(),
            head: controller.head(),
            head_settled: controller.head_settled(),
            odometry: controller.take_odometry(),
        })
    }

    fn write(&mut self, _now: Time, orders: &ActuatorOrders) -> Result<(), PlatformError> {
        let mut shared = lock(&self.shared);
        if let Some(reason) = &shared.disconnected {
            return Err(PlatformError::Disconnected(reason.clone()));
        }
        shared.controller.apply(orders)
    }
}

/// Converts a LoLA packet to Strata's conventions.
///
/// - Accelerometer: LoLA reports the acceleration with the opposite sign to the usual
///   specific-force convention (upright reads z ≈ −9.81); Strata's [`InertialData`] reads
///   +9.81 upright, so all three axes are negated.
/// - Gyroscope and torso angles: LoLA's axes are already right-handed in the torso frame
///   (x forward, y left, z up), with pitch positive leaning forward, as Strata's.
/// - Head: LoLA's `HeadYaw` is left-positive and `HeadPitch` down-positive, as [`HeadAngles`].
/// - Foot contact: the four FSRs of each foot summed (kg); a non-finite cell counts zero.
/// - Buttons: the chest button ([`buttons::CHEST`]), and any of the three head touch sensors
///   ([`buttons::HEAD`]).
///
/// A non-finite inertial value or head angle makes the frame malformed: a filter fed a NaN
/// is lost for good.
pub fn sensor_frame(packet: &SensorPacket, stamp: Time) -> Result<SensorFrame, PlatformError> {
    fn finite<const N: usize>(key: &str, values: [f32; N]) -> Result<[f64; N], PlatformError> {
        let mut out = [0.0; N];
        for (i, (slot, value)) in out.iter_mut().zip(values).enumerate() {
            if !value.is_finite() {
                return Err(PlatformError::Malformed(format!("{key}[{i}] is {value}")));
            }
            *slot = f64::from(value);
        }
        Ok(out)
    }
    let accelerometer = finite("Accelerometer", packet.accelerometer)?.map(|a| -a);
    let gyroscope = finite("Gyroscope", packet.gyroscope)?;
    let body_angles = finite("Angles", packet.angles)?;
    let [yaw, pitch] = finite(
        "Position (head)",
        [packet.position[Joint::HeadYaw.index()], packet.position[Joint::HeadPitch.index()]],
    )?;
    let pressure = |cells: &[f32]| -> f64 {
        cells.iter().filter(|c| c.is_finite()).map(|&c| f64::from(c).max(0.0)).sum()
    };
    let pressed = |index: usize| packet.touch[index] >= 0.5;
    let charge = packet.battery.charge();
    Ok(SensorFrame {
        stamp,
        inertial: InertialData { accelerometer, gyroscope, body_angles },
        head: HeadAngles { yaw, pitch },
        foot_contact: FootContact {
            left: pressure(&packet.fsr[..4]),
            right: pressure(&packet.fsr[4..]),
        },
        buttons: Buttons {
            pressed: [
                (buttons::CHEST, pressed(touch::CHEST_BUTTON)),
                (
                    buttons::HEAD,
                    pressed(touch::HEAD_FRONT)
                        || pressed(touch::HEAD_MIDDLE)
                        || pressed(touch::HEAD_REAR),
                ),
            ]
            .into_iter()
            .filter(|(_, down)| *down)
            .fold(0, |mask, (bit, _)| mask | bit),
        },
        battery: charge.is_finite().then(|| f64::from(charge).clamp(0.0, 1.0)),
        camera: None,
        // LoLA cannot tell: a carried NAO shows through its feet (`pose.kidnap_on_lift`).
        placed: false,
        // LoLA carries no audio; a whistle detector reads the microphones through ALSA.
        whistle: None,
    })
}

fn connect_retrying(path: &Path, timeout: Duration) -> Result<UnixStream, LolaError> {
    let start = Instant::now();
    loop {
        match UnixStream::connect(path) {
            Ok(stream) => return Ok(stream),
            // LoLA starts with the robot and may come up after us; anything else is final.
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::NotFound | io::ErrorKind::ConnectionRefused
                ) && start.elapsed() < timeout =>
            {
                std::thread::sleep(Duration::from_millis(50));
            }
            Err(source) => {
                return Err(LolaError::Connect {
                    path: path.to_owned(),
                    waited: start.elapsed(),
                    source,
                });
            }
        }
    }
}

/// The LoLA thread: read, frame, step the controller, answer; until the socket closes or the
/// platform is dropped.
fn io_loop(mut stream: UnixStream, shared: &SharedState, stop: &AtomicBool, stall: Duration) {
    let mut framer = PacketFramer::new();
    let mut buffer = [0u8; 4096];
    let mut stalled = false;
    let reason = loop {
        if stop.load(Ordering::Acquire) {
            break None;
        }
        match stream.read(&mut buffer) {
            Ok(0) => {
                if let Some(error) = framer.flush_partial() {
                    malformed(shared, &error);
                }
                break Some("LoLA closed the connection".to_owned());
            }
            Ok(n) => {
                stalled = false;
                framer.push(&buffer[..n]);
                while let Some(result) = framer.next_packet() {
                    let reply = match result {
                        Ok(packet) => {
                            let mut guard = lock(shared);
                            let reply = guard.controller.step(&packet);
                            guard.stats.packets += 1;
                            let at = Instant::now();
                            guard.last = Some(Received { packet: packet.clone(), at });
                            guard.unread = Some(Received { packet, at });
                            shared.1.notify_all();
                            reply
                        }
                        Err(error) => {
                            malformed(shared, &error);
                            // LoLA expects one answer per packet; a garbled one gets the
                            // commands of the last cycle again, without advancing any motion.
                            lock(shared).controller.hold()
                        }
                    };
                    // After a failed send the next read tells whether the socket is gone.
                    if send(&mut stream, shared, &reply).is_err() {
                        break;
                    }
                }
            }
            Err(e) if matches!(e.kind(), io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut) => {
                if let Some(error) = framer.flush_partial() {
                    malformed(shared, &error);
                }
                if !stalled {
                    stalled = true;
                    let mut guard = lock(shared);
                    guard.report(Pending::Io(format!("no data from LoLA for {stall:?}")));
                }
            }
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => break Some(format!("reading the LoLA socket failed: {e}")),
        }
    };
    let mut guard = lock(shared);
    if let Some(reason) = reason
        && !stop.load(Ordering::Acquire)
    {
        tracing::warn!(%reason, "LoLA link lost");
        guard.disconnected = Some(reason);
    }
    shared.1.notify_all();
}

fn malformed(shared: &SharedState, error: &CodecError) {
    tracing::debug!(%error, "malformed LoLA data");
    let mut guard = lock(shared);
    guard.stats.malformed += 1;
    guard.report(Pending::Malformed(format!("LoLA sensor packet: {error}")));
}

fn send(
    stream: &mut UnixStream,
    shared: &SharedState,
    packet: &ActuatorPacket,
) -> Result<(), String> {
    let result = packet.encode().map_err(|e| e.to_string()).and_then(|bytes| {
        stream.write_all(&bytes).map_err(|e| format!("sending an actuator packet failed: {e}"))
    });
    let mut guard = lock(shared);
    match &result {
        Ok(()) => guard.stats.replies += 1,
        Err(reason) => {
            guard.stats.send_failures += 1;
            guard.report(Pending::Io(reason.clone()));
        }
    }
    result
}
