//! [`RcssPlatform`]: a Booster T1 in rcssservermj as a Strata [`Platform`], over the server's
//! agent port.
//!
//! A thread of its own does all socket I/O: it reads the server's perception messages, runs one
//! cycle of the [`T1Controller`] per message (the walking policy must answer every 20 ms cycle
//! whatever the architecture's layers are doing, as a real robot's motion board does) and
//! answers each with the joints' commands and `(syn)`. In the server's sync mode the
//! simulation waits for that answer; the thread paces it to real time (or `pace` times real
//! time), so the architecture's modules, which run on the host's clock, see a world that moves
//! at the speed it would on a field. The [`Platform`] calls only exchange data with that thread
//! under a mutex held for microseconds.

use std::io;
use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};
use strata_robot::platform::{
    ActuatorOrders, BodyMotionState, BodyOrder, CameraFrame, FootContact, HeadAngles, InertialData,
    MotionFeedback, MotionName, PendingProblems, Platform, PlatformError, PlatformInfo,
    SensorFrame, stamp_at,
};
use strata_runtime::Time;

use crate::camera::{CameraConfig, CameraModel, DetectorKind, Sighting};
use crate::compute::{ComputeMeter, ComputeReport, thread_cpu_time};
use crate::controller::{CYCLE, JointCommand, MeasuredBody, MotionConfig, T1Controller};
use crate::falls::FallLog;
pub use crate::falls::{FALL_ONSET_TILT, FallRecord};
use crate::getup::{GetUpError, GetUpMotions};
use crate::joints::{
    HEAD_PITCH, HEAD_PITCH_LIMITS, HEAD_YAW, HEAD_YAW_LIMITS, JOINTS, by_perceptor,
};
use crate::kinematics::{CameraPose, NeckGeometry, Quaternion};
use crate::markers;
use crate::policy::{PolicyError, WalkPolicy};
use crate::protocol::{
    self, Effector, FrameError, GameStatePerceptor, InitRequest, MAX_PERCEPTION_FRAME, Perception,
    PlayMode, SeenObject, SeenRobot,
};
use crate::referee::{RefereeLink, RefereeRules, SharedGame, TeamNumbers};

/// Pending problems kept for `read_sensors` beyond which only a count is kept.
const MAX_PENDING: usize = 8;

/// How the platform connects and behaves.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RcssConfig {
    /// How long `connect` keeps retrying while the server is not listening yet, s.
    #[serde(with = "strata_runtime::serde_duration")]
    pub connect_timeout: Duration,
    /// How long `connect` waits for the first perception, s.
    #[serde(with = "strata_runtime::serde_duration")]
    pub first_perception_timeout: Duration,
    /// Silence after which the server counts as stalled (a warning, not an error), s.
    #[serde(with = "strata_runtime::serde_duration")]
    pub stall_timeout: Duration,
    /// Longest a write of one cycle's answer may block, s.
    #[serde(with = "strata_runtime::serde_duration")]
    pub write_timeout: Duration,
    /// In sync mode, the simulation's speed as a multiple of real time: each answer waits
    /// until its cycle's time has come. 0 answers at once (the server then runs as fast as it
    /// can, and the architecture sees a world faster than real time).
    pub pace: f64,
    /// Where the robot is placed when the game allows it (before kick-off): x, y in metres in
    /// the team's frame (the server moves x into the own half), heading in rad.
    pub beam: Option<[f64; 3]>,
    /// The height of the torso origin above the ground while standing, m (ground projection of
    /// what the camera sees).
    pub torso_height: f64,
    pub camera: CameraConfig,
    /// Seeds the camera model's random numbers.
    pub camera_seed: u64,
    pub motion: MotionConfig,
    /// A get-up keyframe file in the format of the shipped `assets/t1/getup.toml`, to tune the
    /// get-up without a build; none: the shipped motions.
    pub getup: Option<PathBuf>,
    /// The length of a half in the server's rule book, play seconds (`ssim` rules: 300): the
    /// referee's packets give the half and the seconds left in it from the server's play time.
    pub half_time: f64,
    /// Team messages per team and game that the referee's packets announce (the SPL's 1200).
    pub message_budget: u16,
    /// Robots per team in the referee's packets (`ssim` rules: at most 7): a robot's share of
    /// the message budget.
    pub players_per_team: u8,
}

impl Default for RcssConfig {
    fn default() -> Self {
        RcssConfig {
            connect_timeout: Duration::from_secs(10),
            first_perception_timeout: Duration::from_secs(10),
            stall_timeout: Duration::from_secs(2),
            write_timeout: Duration::from_secs(1),
            pace: 1.0,
            beam: None,
            torso_height: 0.66,
            camera: CameraConfig::default(),
            camera_seed: 1,
            motion: MotionConfig::default(),
            getup: None,
            half_time: RefereeRules::default().half_time,
            message_budget: RefereeRules::default().message_budget,
            players_per_team: 7,
        }
    }
}

impl RcssConfig {
    /// Checks every value; the error names the field.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.pace.is_finite() && self.pace >= 0.0) {
            return Err(format!("pace must be a number >= 0, got {}", self.pace));
        }
        if self.players_per_team == 0 {
            return Err("players_per_team must be at least 1".to_owned());
        }
        if !(self.half_time.is_finite() && self.half_time > 0.0) {
            return Err(format!("half_time must be > 0 s, got {}", self.half_time));
        }
        if !(self.torso_height.is_finite() && self.torso_height > 0.0) {
            return Err(format!("torso_height must be > 0, got {}", self.torso_height));
        }
        if let Some(beam) = self.beam
            && !beam.iter().all(|v| v.is_finite())
        {
            return Err(format!("beam must be three finite numbers, got {beam:?}"));
        }
        for kick in &self.motion.kicks {
            kick.validate().map_err(|e| format!("motion.kicks: {e}"))?;
        }
        self.camera.validate()
    }
}

/// Why the platform could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum RcssError {
    #[error("invalid platform configuration: {0}")]
    Config(String),
    #[error("cannot resolve the server address {0}")]
    Address(String),
    #[error(
        "cannot connect to rcssservermj at {address} (tried for {waited:?}; is it running?): {source}"
    )]
    Connect { address: String, waited: Duration, source: io::Error },
    #[error("rcssservermj at {address}: {source}")]
    Socket { address: String, source: io::Error },
    #[error("rcssservermj at {address}: {source}")]
    Protocol { address: String, source: protocol::ProtocolError },
    #[error("rcssservermj at {address}: {source}")]
    Frame { address: String, source: FrameError },
    #[error("rcssservermj at {address} sent no valid perception within {waited:?}{}", last_error.as_ref().map(|e| format!(" (last problem: {e})")).unwrap_or_default())]
    NoFirstPerception {
        address: String,
        waited: Duration,
        last_error: Option<String>,
        /// Whether the server closed the connection (rather than staying silent).
        closed: bool,
    },
    #[error("the walking policy: {0}")]
    Policy(#[from] PolicyError),
    #[error("the get-up motions: {0}")]
    GetUp(#[from] GetUpError),
}

/// Counters of the server link since `connect`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RcssStats {
    /// Perception messages decoded.
    pub perceptions: u64,
    /// Of which with a camera image.
    pub images: u64,
    /// Messages that could not be decoded.
    pub malformed: u64,
    /// Answers sent.
    pub answers: u64,
    /// Placements by the server reported to world modeling (not the platform's own beam).
    #[serde(default)]
    pub placements: u64,
}

/// The server's view of the robot, for reports of accuracy only: the robot itself never uses
/// it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroundTruth {
    /// The server's simulation time, s.
    pub time: f64,
    /// The torso's position in the world, m.
    pub position: [f64; 3],
    /// The torso's heading in the world, rad.
    pub heading: f64,
}

/// The newest ground truth, shared with whoever reports accuracy.
#[derive(Clone, Debug, Default)]
pub struct TruthSource(Arc<Mutex<Option<GroundTruth>>>);

impl TruthSource {
    pub fn get(&self) -> Option<GroundTruth> {
        *self.0.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn set(&self, truth: GroundTruth) {
        *self.0.lock().unwrap_or_else(PoisonError::into_inner) = Some(truth);
    }
}

#[derive(Debug)]
struct Shared {
    controller: T1Controller,
    /// The server's time of the newest perception.
    sim_time: Option<f64>,
    falls: FallLog,
    unread: Option<SensorFrame>,
    last_at: Option<Instant>,
    pending: PendingProblems<String>,
    disconnected: Option<String>,
    /// Whether the link was lost before the game was over (the server stopped or crashed).
    lost_mid_game: bool,
    stats: RcssStats,
    compute: ComputeMeter,
}

type SharedState = Arc<(Mutex<Shared>, Condvar)>;

fn lock(shared: &SharedState) -> MutexGuard<'_, Shared> {
    // The connection thread never panics while holding the lock in normal operation; if a
    // panic did poison it, the data is still the newest the robot has.
    shared.0.lock().unwrap_or_else(PoisonError::into_inner)
}

impl Shared {
    fn report(&mut self, problem: String) {
        self.pending.push(problem);
    }
}

/// A Booster T1 in rcssservermj.
#[derive(Debug)]
pub struct RcssPlatform {
    address: String,
    team: String,
    game: SharedGame,
    truth: TruthSource,
    shared: SharedState,
    info: PlatformInfo,
    stop: Arc<AtomicBool>,
    socket: TcpStream,
    thread: Option<JoinHandle<()>>,
    stall_timeout: Duration,
    stall_reported: bool,
    rules: RefereeRules,
    players: u8,
}

/// What the connection thread needs besides the socket.
struct Session {
    address: String,
    team: String,
    game: SharedGame,
    truth: TruthSource,
    player: u8,
    config: RcssConfig,
    camera: CameraModel,
}

impl RcssPlatform {
    /// Connects a T1 of `team` with number `player` to the server's agent port and waits for
    /// the first perception.
    pub fn connect(
        address: &str,
        team: &str,
        player: u8,
        config: RcssConfig,
    ) -> Result<RcssPlatform, RcssError> {
        config.validate().map_err(RcssError::Config)?;
        let resolved: Vec<SocketAddr> = address
            .to_socket_addrs()
            .map_err(|_| RcssError::Address(address.to_owned()))?
            .collect();
        if resolved.is_empty() {
            return Err(RcssError::Address(address.to_owned()));
        }
        let start = Instant::now();
        loop {
            match RcssPlatform::connect_once(address, &resolved, team, player, config.clone()) {
                // A server that drops an agent before its first perception is still starting
                // (rcsssmj 0.2.1 never activates an agent that joins before its first step):
                // join again while the connect timeout lasts.
                Err(RcssError::NoFirstPerception { closed: true, .. })
                    if start.elapsed() < config.connect_timeout =>
                {
                    std::thread::sleep(Duration::from_millis(200));
                }
                result => return result,
            }
        }
    }

    fn connect_once(
        address: &str,
        resolved: &[SocketAddr],
        team: &str,
        player: u8,
        config: RcssConfig,
    ) -> Result<RcssPlatform, RcssError> {
        let policy = WalkPolicy::shipped()?;
        let getup = match &config.getup {
            Some(path) => GetUpMotions::load(path)?,
            None => GetUpMotions::shipped()?,
        };
        let mut stream = connect_retrying(address, resolved, config.connect_timeout)?;
        let socket_error = |source| RcssError::Socket { address: address.to_owned(), source };
        stream.set_nodelay(true).map_err(socket_error)?;
        stream
            .set_write_timeout(Some(config.write_timeout.max(Duration::from_millis(1))))
            .map_err(socket_error)?;
        let init = protocol::encode_init(&InitRequest {
            model: "T1".to_owned(),
            team: team.to_owned(),
            player,
        })
        .map_err(|source| RcssError::Protocol { address: address.to_owned(), source })?;
        protocol::write_frame(&mut stream, &init)
            .map_err(|source| RcssError::Frame { address: address.to_owned(), source })?;
        let socket = stream.try_clone().map_err(socket_error)?;

        let controller = T1Controller::new(config.motion.clone(), policy).with_getup(getup);
        let catalogue = controller.catalogue();
        let max_velocity = controller.config().max_velocity;
        let max_head_speed = controller.config().max_head_speed;
        let shared: SharedState = Arc::new((
            Mutex::new(Shared {
                controller,
                sim_time: None,
                falls: FallLog::default(),
                unread: None,
                last_at: None,
                pending: PendingProblems::new(MAX_PENDING),
                disconnected: None,
                lost_mid_game: false,
                stats: RcssStats::default(),
                compute: ComputeMeter::default(),
            }),
            Condvar::new(),
        ));
        let camera = CameraModel::new(config.camera.clone(), config.camera_seed);
        let info = PlatformInfo {
            name: format!("Booster T1 in rcssservermj ({team} #{player})"),
            sensor_period: Duration::from_secs_f64(CYCLE),
            camera_fov: camera.horizontal_fov(),
            camera_range: camera.max_range(),
            head_yaw_limits: HEAD_YAW_LIMITS,
            head_pitch_limits: HEAD_PITCH_LIMITS,
            max_head_speed,
            max_velocity,
            motions: catalogue,
            can_walk: true,
        };
        let stop = Arc::new(AtomicBool::new(false));
        let first_timeout = config.first_perception_timeout;
        let stall_timeout = config.stall_timeout;
        let rules = RefereeRules {
            half_time: config.half_time,
            message_budget: config.message_budget,
            ..RefereeRules::default()
        };
        let players_per_team = config.players_per_team;
        let game: SharedGame = Arc::default();
        let truth = TruthSource::default();
        let session = Session {
            address: address.to_owned(),
            team: team.to_owned(),
            game: Arc::clone(&game),
            truth: truth.clone(),
            player,
            config,
            camera,
        };
        let thread = {
            let shared = Arc::clone(&shared);
            let stop = Arc::clone(&stop);
            std::thread::Builder::new()
                .name("rcssservermj".to_owned())
                .spawn(move || io_loop(stream, session, &shared, &stop))
                .map_err(socket_error)?
        };
        let platform = RcssPlatform {
            address: address.to_owned(),
            team: team.to_owned(),
            game,
            truth,
            shared,
            info,
            stop,
            socket,
            thread: Some(thread),
            stall_timeout,
            stall_reported: false,
            rules,
            players: players_per_team,
        };
        platform.wait_for_first_perception(first_timeout)?;
        tracing::info!(address, team, player, "connected to rcssservermj");
        Ok(platform)
    }

    fn wait_for_first_perception(&self, timeout: Duration) -> Result<(), RcssError> {
        let deadline = Instant::now() + timeout;
        let mut guard = lock(&self.shared);
        loop {
            if guard.stats.perceptions > 0 {
                return Ok(());
            }
            let now = Instant::now();
            if guard.disconnected.is_some() || now >= deadline {
                let problems: Vec<String> =
                    guard.pending.iter().cloned().chain(guard.disconnected.clone()).collect();
                let last_error = (!problems.is_empty()).then(|| problems.join("; "));
                return Err(RcssError::NoFirstPerception {
                    address: self.address.clone(),
                    waited: timeout,
                    last_error,
                    closed: guard.disconnected.is_some(),
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

    /// The game as the server reported it last.
    pub fn game_state(&self) -> Option<GameStatePerceptor> {
        self.game.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }

    /// A GameController link that follows the server's referee, for the robot's planning
    /// layer (see [`crate::referee`]).
    pub fn referee_link(&self, numbers: TeamNumbers) -> RefereeLink {
        RefereeLink::new(Arc::clone(&self.game), &self.team, numbers, self.players, self.rules)
    }

    /// The server's ground truth of the torso (for accuracy reports only).
    pub fn ground_truth(&self) -> Option<GroundTruth> {
        self.truth.get()
    }

    /// A handle on the ground truth that other threads can read without the platform.
    pub fn truth_source(&self) -> TruthSource {
        self.truth.clone()
    }

    pub fn stats(&self) -> RcssStats {
        lock(&self.shared).stats
    }

    /// Every fall since `connect`, with the protective-fall order's latency.
    pub fn falls(&self) -> Vec<FallRecord> {
        lock(&self.shared).falls.falls().to_vec()
    }

    /// The server's time of every protective-fall order that no fall followed (false alarms,
    /// see [`crate::falls::FallLog::false_falls`]).
    pub fn false_falls(&self) -> Vec<f64> {
        lock(&self.shared).falls.false_falls().to_vec()
    }

    /// The robot's compute per server cycle since `connect` or the last
    /// [`RcssPlatform::restart_compute`] (see [`crate::compute`]).
    pub fn compute(&self) -> ComputeReport {
        lock(&self.shared).compute.report()
    }

    /// Starts the compute figures over: the cycles before (the robot's set-up) are left out.
    pub fn restart_compute(&self) {
        lock(&self.shared).compute.restart();
    }

    /// Why the link to the server was lost before the game was over, if it was: the server
    /// stopped or crashed mid-game (not the end of a game).
    pub fn lost_mid_game(&self) -> Option<String> {
        let shared = lock(&self.shared);
        if shared.lost_mid_game { shared.disconnected.clone() } else { None }
    }

    pub fn address(&self) -> &str {
        &self.address
    }
}

impl Drop for RcssPlatform {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        // Unblocks the connection thread's read; an error only means the socket is closed.
        let _ = self.socket.shutdown(std::net::Shutdown::Both);
        if let Some(thread) = self.thread.take()
            && thread.join().is_err()
        {
            tracing::error!("the rcssservermj connection thread panicked");
        }
    }
}

impl Platform for RcssPlatform {
    fn info(&self) -> PlatformInfo {
        self.info.clone()
    }

    fn read_sensors(&mut self, now: Time) -> Result<Option<SensorFrame>, PlatformError> {
        let mut shared = lock(&self.shared);
        if let Some(text) = shared.pending.take_text(String::as_str) {
            return Err(PlatformError::Malformed(text));
        }
        if let Some(mut frame) = shared.unread.take() {
            // The frame was stamped with the instant it arrived; the host's clock is `now`.
            let at = shared.last_at.unwrap_or_else(Instant::now);
            frame.stamp = stamp_at(now, at);
            if let Some(camera) = &mut frame.camera {
                camera.stamp = frame.stamp;
            }
            self.stall_reported = false;
            return Ok(Some(frame));
        }
        if let Some(reason) = &shared.disconnected {
            return Err(PlatformError::Disconnected(reason.clone()));
        }
        // A silent server is not fatal (in sync mode it waits for its slowest agent): said
        // once per silence, and the robot goes on when the server does.
        let silent = shared.last_at.is_some_and(|at| at.elapsed() > self.stall_timeout);
        if silent && !self.stall_reported {
            tracing::warn!(
                address = %self.address,
                seconds = self.stall_timeout.as_secs_f64(),
                "no perception from rcssservermj for longer than the stall timeout"
            );
        }
        self.stall_reported = silent;
        Ok(None)
    }

    fn read_motion(&mut self, now: Time) -> Result<MotionFeedback, PlatformError> {
        let mut shared = lock(&self.shared);
        if let Some(reason) = &shared.disconnected {
            return Err(PlatformError::Disconnected(reason.clone()));
        }
        let stamp = shared.last_at.map_or(now, |at| stamp_at(now, at));
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
        let fall_ordered = match orders.body {
            Some(BodyOrder::Special { motion }) => motion.is(MotionName::FALL),
            _ => false,
        };
        if fall_ordered {
            let time = shared.sim_time;
            shared.falls.order(time, Instant::now());
        }
        shared.controller.apply(orders)
    }
}

fn connect_retrying(
    address: &str,
    resolved: &[SocketAddr],
    timeout: Duration,
) -> Result<TcpStream, RcssError> {
    let start = Instant::now();
    loop {
        let mut last = None;
        for addr in resolved {
            match TcpStream::connect_timeout(addr, Duration::from_secs(1)) {
                Ok(stream) => return Ok(stream),
                Err(e) => last = Some(e),
            }
        }
        let error = last.unwrap_or_else(|| io::Error::other("no address"));
        // The server may come up after us; anything but a refusal is final.
        if error.kind() == io::ErrorKind::ConnectionRefused && start.elapsed() < timeout {
            std::thread::sleep(Duration::from_millis(100));
            continue;
        }
        return Err(RcssError::Connect {
            address: address.to_owned(),
            waited: start.elapsed(),
            source: error,
        });
    }
}

/// The connection thread: read a perception, step the controller, answer; until the server
/// closes the connection or the platform is dropped.
fn io_loop(mut stream: TcpStream, mut session: Session, shared: &SharedState, stop: &AtomicBool) {
    let mut buffer = Vec::with_capacity(16 * 1024);
    let mut answer = Vec::with_capacity(4 * 1024);
    let mut beamed = session.config.beam.is_none();
    let mut last_answer: Option<Instant> = None;
    let reason = loop {
        if stop.load(Ordering::Acquire) {
            break None;
        }
        let message = match protocol::read_frame(&mut stream, &mut buffer, MAX_PERCEPTION_FRAME) {
            Ok(message) => message,
            Err(FrameError::Closed) => {
                break Some(format!("rcssservermj at {} closed the connection", session.address));
            }
            Err(FrameError::Io(e)) if e.kind() == io::ErrorKind::Interrupted => continue,
            // A broken frame leaves no way to find the next one: the link is lost.
            Err(error) => {
                break Some(format!(
                    "reading from rcssservermj at {} failed: {error}",
                    session.address
                ));
            }
        };
        let arrived = Instant::now();
        lock(shared).compute.arrival();
        let mut effectors: Vec<Effector> = Vec::with_capacity(JOINTS.len() + 2);
        match protocol::decode_perception(message) {
            Ok(perception) => {
                let beam_now = !beamed
                    && perception
                        .game
                        .as_ref()
                        .and_then(|g| g.play_mode)
                        .is_some_and(|m| m.allows_beam());
                match cycle(&mut session, shared, &perception, arrived) {
                    Ok(commands) => effectors.extend(joint_effectors(&commands)),
                    Err(problem) => {
                        let mut guard = lock(shared);
                        guard.stats.malformed += 1;
                        guard.report(problem);
                    }
                }
                if beam_now && let Some([x, y, theta]) = session.config.beam {
                    effectors.push(Effector::Beam { x, y, theta });
                    beamed = true;
                    // The beam puts every joint at zero: the policy starts over.
                    lock(shared).controller.restart();
                }
            }
            Err(error) => {
                let mut guard = lock(shared);
                guard.stats.malformed += 1;
                guard.report(format!("rcssservermj perception: {error}"));
            }
        }
        effectors.push(Effector::Sync);
        answer.clear();
        if let Err(error) = protocol::encode_effectors(&effectors, &mut answer) {
            // Our own commands failed to encode (a non-finite value): answer with (syn) alone,
            // so the simulation goes on and the joints keep their last commands.
            lock(shared).report(format!("this cycle's commands: {error}"));
            answer.clear();
            if let Err(error) = protocol::encode_effectors(&[Effector::Sync], &mut answer) {
                break Some(format!("encoding (syn) failed: {error}"));
            }
        }
        if session.config.pace > 0.0 {
            // One cycle's time after the previous answer; a server that fell behind is not
            // made to catch up in a burst (the schedule restarts from now).
            let period = Duration::from_secs_f64(CYCLE / session.config.pace);
            let due = last_answer.map_or(arrived, |at| at + period);
            let now = Instant::now();
            if due > now {
                std::thread::sleep(due - now);
            }
            last_answer = Some(due.max(now));
        }
        if let Err(error) = protocol::write_frame(&mut stream, &answer) {
            break Some(format!("sending to rcssservermj at {} failed: {error}", session.address));
        }
        lock(shared).stats.answers += 1;
    };
    let game_over = session
        .game
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .as_ref()
        .is_some_and(|game| game.play_mode == Some(PlayMode::GameOver));
    let mut guard = lock(shared);
    if let Some(reason) = reason
        && !stop.load(Ordering::Acquire)
    {
        if game_over {
            tracing::info!(%reason, "rcssservermj link closed after the game");
            guard.disconnected = Some(format!("{reason} after the game was over"));
        } else {
            tracing::warn!(%reason, "rcssservermj link lost");
            guard.disconnected = Some(reason);
            guard.lost_mid_game = true;
        }
    }
    shared.1.notify_all();
}

/// One cycle of a decoded perception: the controller's joint commands, and the sensor frame
/// handed to perception.
fn cycle(
    session: &mut Session,
    shared: &SharedState,
    perception: &Perception,
    arrived: Instant,
) -> Result<[JointCommand; JOINTS.len()], String> {
    let measured = measured_body(perception)?;
    let orientation = measured.orientation;
    let head = HeadAngles {
        yaw: measured.joint_positions[HEAD_YAW],
        pitch: measured.joint_positions[HEAD_PITCH],
    };
    let camera = perception.vision.as_ref().map(|seen| {
        let pose = CameraPose::new(
            NeckGeometry::T1,
            head.yaw,
            head.pitch,
            orientation,
            session.config.torso_height,
        );
        let sightings = sightings(seen, &session.team, session.player);
        CameraFrame {
            stamp: Time::ZERO,
            head,
            detections: session.camera.detect(&pose, head.yaw, &sightings),
            footprint: Some(session.camera.footprint(&pose)),
        }
    });
    let mut frame = SensorFrame {
        stamp: Time::ZERO,
        inertial: InertialData {
            accelerometer: perception.accel.unwrap_or([0.0; 3]),
            gyroscope: measured.gyro,
            body_angles: orientation.roll_pitch(),
        },
        head,
        // The server's T1 has no foot pressure sensors.
        foot_contact: FootContact::default(),
        buttons: Default::default(),
        battery: None,
        camera,
        placed: false,
        // rcssservermj has no sound.
        whistle: None,
    };
    if let Some(game) = &perception.game {
        *session.game.lock().unwrap_or_else(PoisonError::into_inner) = Some(game.clone());
    }
    let [roll, pitch] = orientation.roll_pitch();
    let mut guard = lock(shared);
    if let Some(time) = perception.time {
        guard.sim_time = Some(time);
    }
    let protecting = matches!(
        guard.controller.body_state(),
        BodyMotionState::Special { .. } | BodyMotionState::Fallen { .. }
    );
    guard.falls.perception(perception.time, roll.hypot(pitch), protecting, arrived);
    let before = thread_cpu_time();
    let commands = guard.controller.step(measured);
    if let (Some(before), Some(after)) = (before, thread_cpu_time()) {
        guard.compute.policy_step(after.saturating_sub(before));
    }
    guard.stats.perceptions += 1;
    if frame.camera.is_some() {
        guard.stats.images += 1;
    }
    if guard.controller.take_placement() {
        guard.stats.placements += 1;
        tracing::info!(time = ?perception.time, "the server placed the robot (reported)");
        frame.placed = true;
    }
    // A frame perception has not read yet is replaced: its placement must not go with it.
    frame.placed |= guard.unread.as_ref().is_some_and(|f| f.placed);
    guard.unread = Some(frame);
    guard.last_at = Some(arrived);
    if let (Some(time), Some(position)) = (perception.time, perception.torso_position_truth) {
        session.truth.set(GroundTruth { time, position, heading: orientation.yaw() });
    }
    shared.1.notify_all();
    Ok(commands)
}

/// The measured body; a perception without orientation or with a missing or non-finite joint
/// is malformed (a policy fed a NaN would command nonsense).
fn measured_body(perception: &Perception) -> Result<MeasuredBody, String> {
    let [w, x, y, z] =
        perception.torso_orientation.ok_or("the perception has no torso orientation (quat)")?;
    let orientation = Quaternion { w, x, y, z }
        .normalized()
        .ok_or_else(|| format!("the torso orientation {:?} is not a rotation", [w, x, y, z]))?;
    let gyro = perception.gyro.ok_or("the perception has no gyroscope (GYR)")?;
    if !gyro.iter().all(|v| v.is_finite()) {
        return Err(format!("the gyroscope reads {gyro:?}"));
    }
    let mut positions = [f64::NAN; JOINTS.len()];
    let mut velocities = [f64::NAN; JOINTS.len()];
    for joint in &perception.joints {
        if let Some(i) = by_perceptor(&joint.name) {
            positions[i] = joint.angle;
            velocities[i] = joint.velocity;
        }
    }
    if let Some(i) =
        (0..JOINTS.len()).find(|&i| !(positions[i].is_finite() && velocities[i].is_finite()))
    {
        return Err(format!("joint {} is missing or not finite", JOINTS[i].perceptor));
    }
    Ok(MeasuredBody { orientation, gyro, joint_positions: positions, joint_velocities: velocities })
}

/// The server's detections as the camera model takes them: world markers by kind, each robot
/// once (where its feet are, or its head when no foot is in view), this robot left out.
fn sightings(seen: &[SeenObject], team: &str, player: u8) -> Vec<Sighting> {
    let mut out = Vec::with_capacity(seen.len());
    for object in seen {
        match object {
            SeenObject::Marker(marker) => {
                if let Some((class, detector)) = markers::classify(&marker.name) {
                    out.push(Sighting {
                        class,
                        variant: None,
                        detector,
                        distance: marker.polar.distance,
                        azimuth: marker.polar.azimuth,
                        elevation: marker.polar.elevation,
                    });
                }
            }
            SeenObject::Robot(robot) => {
                if robot.team == team && robot.player == u32::from(player) {
                    continue;
                }
                if let Some(sighting) = robot_sighting(robot) {
                    out.push(sighting);
                }
            }
        }
    }
    out
}

fn robot_sighting(robot: &SeenRobot) -> Option<Sighting> {
    let feet: Vec<[f64; 3]> = robot
        .parts
        .iter()
        .filter(|p| p.name.ends_with("foot"))
        .map(|p| p.polar.to_cartesian())
        .collect();
    let point = if feet.is_empty() {
        robot.parts.first()?.polar.to_cartesian()
    } else {
        let n = feet.len() as f64;
        let sum = feet.iter().fold([0.0; 3], |a, f| [a[0] + f[0], a[1] + f[1], a[2] + f[2]]);
        [sum[0] / n, sum[1] / n, sum[2] / n]
    };
    let distance = (point[0] * point[0] + point[1] * point[1] + point[2] * point[2]).sqrt();
    if !(distance.is_finite() && distance > 0.0) {
        return None;
    }
    Some(Sighting {
        class: markers::robot_class(),
        variant: None,
        detector: DetectorKind::Robot,
        distance,
        azimuth: point[1].atan2(point[0]),
        elevation: (point[2] / distance).asin(),
    })
}

fn joint_effectors(commands: &[JointCommand; JOINTS.len()]) -> impl Iterator<Item = Effector> + '_ {
    JOINTS.iter().zip(commands).map(|(joint, c)| {
        Effector::Joint(protocol::JointCommand {
            name: joint.effector.to_owned(),
            position: c.q,
            velocity: c.dq,
            kp: c.kp,
            kd: c.kd,
            torque: c.tau,
        })
    })
}
