//! The robot process's side of the simulator protocol: a [`TcpSimPlatform`], a [`TcpTeamLink`]
//! and a [`TcpGameControllerLink`] implementing the same traits as the in-process ones, so the
//! same robot code runs against the server.
//!
//! A reader thread keeps the newest sensor frame, the newest camera image, the motion state
//! with the odometry accumulated since the last read, and every team message and control
//! packet. The server stamps data on its simulated clock; the platform maps those stamps to
//! the robot host's clock with the smallest offset seen (transport delay included once).

use std::net::{Shutdown, SocketAddr, TcpStream, ToSocketAddrs};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use strata_robot::Odometry;
use strata_robot::platform::{
    ActuatorOrders, BodyMotionState, BodyOrder, CameraFrame, ExternalLink, HeadAngles, LinkError,
    MotionFeedback, Platform, PlatformError, PlatformInfo, ReceivedPacket, SensorFrame, TeamLink,
};
use strata_runtime::Time;

use super::protocol::{
    self, Bytes, ClientMessage, Deadline, ErrorCode, FrameError, MAX_SERVER_FRAME, PROTOCOL,
    ServerMessage, VERSION,
};

/// Why connecting to the server failed.
#[derive(Debug, thiserror::Error)]
pub enum ConnectError {
    #[error("cannot resolve {0}")]
    Resolve(String),
    #[error("cannot connect to {addr}: {source}")]
    Connect {
        addr: String,
        #[source]
        source: std::io::Error,
    },
    #[error("the server refused the robot ({code:?}): {message}")]
    Refused { code: ErrorCode, message: String },
    #[error("handshake with {addr} failed: {error}")]
    Handshake { addr: SocketAddr, error: FrameError },
    #[error("unexpected first message from the server: {0}")]
    Unexpected(String),
    #[error("cannot start the reader thread: {0}")]
    Spawn(std::io::Error),
}

/// How long the robot waits for the server. [`connect`] uses the default write timeout.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClientOptions {
    /// For connecting, for sending `hello`, and for the whole welcome to arrive.
    pub timeout: Duration,
    /// How long sending one message may block. A server that reads nothing for this long is
    /// taken as gone: the send fails, the connection closes and the platform reports it
    /// disconnected, instead of the robot's module (or dropping the robot) hanging.
    pub write_timeout: Duration,
}

impl ClientOptions {
    /// The write timeout of [`connect`]; the server reads every message as it arrives.
    pub const DEFAULT_WRITE_TIMEOUT: Duration = Duration::from_secs(2);
}

/// What the server said when the robot joined.
#[derive(Clone, Debug, PartialEq)]
pub struct Welcome {
    pub team: u8,
    pub player: u8,
    pub team_index: usize,
    pub info: PlatformInfo,
    pub max_team_message: usize,
    pub server_time: Time,
}

#[derive(Debug, Default)]
struct Inbox {
    sensors: Option<SensorFrame>,
    camera: Option<CameraFrame>,
    body: Option<BodyMotionState>,
    head: HeadAngles,
    head_settled: bool,
    motion_stamp: Time,
    odometry: Odometry,
    team: Vec<ReceivedPacket>,
    control: Vec<ReceivedPacket>,
    closed: Option<String>,
    /// Host time minus server time, the smallest seen (ns).
    offset: Option<i128>,
    received: u64,
}

impl Inbox {
    /// Maps a server stamp to the host clock, learning the offset from `now`.
    fn map(&mut self, server: Time, now: Time) -> Time {
        let offset = i128::from(now.as_nanos()) - i128::from(server.as_nanos());
        let offset = self.offset.map_or(offset, |o| o.min(offset));
        self.offset = Some(offset);
        let mapped = (i128::from(server.as_nanos()) + offset).clamp(0, i128::from(u64::MAX));
        Time::from_nanos(mapped as u64)
    }
}

struct Connection {
    inbox: Mutex<Inbox>,
    writer: Mutex<TcpStream>,
    welcome: Welcome,
    write_timeout: Duration,
}

impl Connection {
    fn inbox(&self) -> MutexGuard<'_, Inbox> {
        self.inbox.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn send(&self, message: &ClientMessage) -> Result<(), String> {
        if let Some(reason) = &self.inbox().closed {
            return Err(reason.clone());
        }
        let mut writer = self.writer.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        protocol::write_message(&mut *writer, message).map_err(|e| {
            let reason = match e.kind() {
                std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut => format!(
                    "the simulator read nothing for {} s, the write timeout; connection closed",
                    self.write_timeout.as_secs_f64()
                ),
                _ => format!("cannot send to the simulator: {e}"),
            };
            // Recorded before the shutdown, which the reader thread would otherwise report
            // first as the simulator closing the connection.
            let reason = self.inbox().closed.get_or_insert(reason).clone();
            // Part of a frame may have gone out: nothing more can be sent on this stream. Closing
            // it ends the reader thread, and the server removes the robot.
            let _ = writer.shutdown(Shutdown::Both);
            reason
        })
    }
}

impl Drop for Connection {
    fn drop(&mut self) {
        let closed = self.inbox().closed.is_some();
        let mut writer = self.writer.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        // The stream's write timeout bounds this when the server has stopped reading.
        if !closed {
            let _ = protocol::write_message(&mut *writer, &ClientMessage::Goodbye);
        }
        // Ends the reader thread too.
        let _ = writer.shutdown(Shutdown::Both);
    }
}

/// A robot connected to the simulator server: its platform and links. Dropping all three
/// leaves the game.
#[derive(Debug)]
pub struct TcpRobot {
    pub platform: TcpSimPlatform,
    pub team_link: TcpTeamLink,
    pub game_controller: TcpGameControllerLink,
    pub welcome: Welcome,
}

/// Connects to the server at `addr` as player `player` of team number `team`, with the default
/// write timeout ([`ClientOptions::DEFAULT_WRITE_TIMEOUT`]).
pub fn connect(
    addr: impl ToSocketAddrs + std::fmt::Display,
    team: u8,
    player: u8,
    timeout: Duration,
) -> Result<TcpRobot, ConnectError> {
    let write_timeout = ClientOptions::DEFAULT_WRITE_TIMEOUT;
    connect_with(addr, team, player, ClientOptions { timeout, write_timeout })
}

/// Connects to the server at `addr` as player `player` of team number `team`.
pub fn connect_with(
    addr: impl ToSocketAddrs + std::fmt::Display,
    team: u8,
    player: u8,
    options: ClientOptions,
) -> Result<TcpRobot, ConnectError> {
    let ClientOptions { timeout, write_timeout } = options;
    let target = addr
        .to_socket_addrs()
        .ok()
        .and_then(|mut addrs| addrs.next())
        .ok_or_else(|| ConnectError::Resolve(addr.to_string()))?;
    let mut stream = TcpStream::connect_timeout(&target, timeout)
        .map_err(|source| ConnectError::Connect { addr: addr.to_string(), source })?;
    let _ = stream.set_nodelay(true);
    let handshake =
        |e: std::io::Error| ConnectError::Handshake { addr: target, error: FrameError::Io(e) };
    stream.set_write_timeout(Some(timeout)).map_err(handshake)?;
    let hello =
        ClientMessage::Hello { protocol: PROTOCOL.to_owned(), version: VERSION, team, player };
    protocol::write_message(&mut stream, &hello).map_err(handshake)?;
    // One deadline for the whole welcome: a server that sends a byte now and then would pass
    // a timeout per read, and keep the robot from starting (or failing) for as long as it likes.
    let mut deadline = Deadline::new(&stream, Instant::now() + timeout);
    let reply = protocol::read_message::<ServerMessage>(&mut deadline, MAX_SERVER_FRAME)
        .map_err(|error| match error {
            FrameError::Io(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                FrameError::Io(std::io::Error::new(
                    std::io::ErrorKind::TimedOut,
                    format!("no complete welcome within {} s, the timeout", timeout.as_secs_f64()),
                ))
            }
            error => error,
        })
        .map_err(|error| ConnectError::Handshake { addr: target, error })?;
    let welcome = match reply {
        ServerMessage::Welcome {
            team, player, team_index, info, max_team_message, time, ..
        } => Welcome { team, player, team_index, info, max_team_message, server_time: time },
        ServerMessage::Error { code, message } => {
            return Err(ConnectError::Refused { code, message });
        }
        other => return Err(ConnectError::Unexpected(format!("{other:?}"))),
    };
    stream.set_read_timeout(None).map_err(handshake)?;
    stream.set_write_timeout(Some(write_timeout)).map_err(handshake)?;
    let reader = stream.try_clone().map_err(handshake)?;
    let connection = Arc::new(Connection {
        inbox: Mutex::new(Inbox::default()),
        writer: Mutex::new(stream),
        welcome: welcome.clone(),
        write_timeout,
    });
    let weak = Arc::downgrade(&connection);
    std::thread::Builder::new()
        .name(format!("sim-client-{team}-{player}"))
        .spawn(move || read_loop(reader, weak))
        .map_err(ConnectError::Spawn)?;
    Ok(TcpRobot {
        platform: TcpSimPlatform { connection: Arc::clone(&connection) },
        team_link: TcpTeamLink { connection: Arc::clone(&connection) },
        game_controller: TcpGameControllerLink { connection },
        welcome,
    })
}

/// Fills the inbox until the connection ends. Holds the connection weakly, so dropping the
/// robot's handles closes it.
fn read_loop(mut reader: TcpStream, connection: std::sync::Weak<Connection>) {
    let reason = loop {
        let message = protocol::read_message::<ServerMessage>(&mut reader, MAX_SERVER_FRAME);
        let Some(connection) = connection.upgrade() else { return };
        let mut inbox = connection.inbox();
        match message {
            Ok(ServerMessage::Sensors { frame }) => {
                inbox.received += 1;
                let SensorFrame { camera, .. } = &frame;
                if let Some(camera) = camera.clone() {
                    inbox.camera = Some(camera);
                }
                inbox.sensors = Some(SensorFrame { camera: None, ..frame });
            }
            Ok(ServerMessage::Motion { feedback }) => {
                inbox.received += 1;
                inbox.body = Some(feedback.body);
                inbox.head = feedback.head;
                inbox.head_settled = feedback.head_settled;
                inbox.motion_stamp = feedback.stamp;
                inbox.odometry = inbox.odometry.then(feedback.odometry);
            }
            Ok(ServerMessage::TeamMessage { received, payload }) => {
                inbox.received += 1;
                inbox.team.push(ReceivedPacket { received, bytes: payload.0 });
            }
            Ok(ServerMessage::ControlPacket { received, payload }) => {
                inbox.received += 1;
                inbox.control.push(ReceivedPacket { received, bytes: payload.0 });
            }
            Ok(ServerMessage::Error { code, message }) => {
                break format!("the simulator closed the connection ({code:?}): {message}");
            }
            Ok(ServerMessage::Welcome { .. }) => {
                break "the simulator sent a second welcome".to_owned();
            }
            Err(FrameError::Closed) => break "the simulator closed the connection".to_owned(),
            Err(error) => break format!("connection to the simulator lost: {error}"),
        }
    };
    if let Some(connection) = connection.upgrade() {
        connection.inbox().closed.get_or_insert(reason);
    }
}

/// The platform of a robot driven through the simulator server.
pub struct TcpSimPlatform {
    connection: Arc<Connection>,
}

impl std::fmt::Debug for TcpSimPlatform {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TcpSimPlatform").field("welcome", &self.connection.welcome).finish()
    }
}

impl TcpSimPlatform {
    /// Why the connection closed, if it did.
    pub fn closed(&self) -> Option<String> {
        self.connection.inbox().closed.clone()
    }

    /// Messages received from the server so far.
    pub fn received(&self) -> u64 {
        self.connection.inbox().received
    }

    fn check(&self, orders: &ActuatorOrders) -> Result<(), PlatformError> {
        let info = &self.connection.welcome.info;
        if let Some(head) = &orders.head
            && !(head.target.yaw.is_finite() && head.target.pitch.is_finite())
        {
            return Err(PlatformError::Unsupported(format!("non-finite head target {head:?}")));
        }
        match orders.body {
            Some(BodyOrder::Walk { velocity }) if !velocity.is_finite() => {
                Err(PlatformError::Unsupported(format!("non-finite walk velocity {velocity:?}")))
            }
            Some(BodyOrder::Special { motion }) if info.motion(motion).is_none() => {
                Err(PlatformError::Unsupported(format!("{motion} is not in the motion catalogue")))
            }
            _ => Ok(()),
        }
    }
}

impl Platform for TcpSimPlatform {
    fn info(&self) -> PlatformInfo {
        self.connection.welcome.info.clone()
    }

    fn read_sensors(&mut self, now: Time) -> Result<Option<SensorFrame>, PlatformError> {
        let mut inbox = self.connection.inbox();
        let Some(mut frame) = inbox.sensors.take() else {
            return match &inbox.closed {
                Some(reason) => Err(PlatformError::Disconnected(reason.clone())),
                None => Ok(None),
            };
        };
        frame.stamp = inbox.map(frame.stamp, now);
        if let Some(mut camera) = inbox.camera.take() {
            camera.stamp = inbox.map(camera.stamp, now);
            frame.camera = Some(camera);
        }
        Ok(Some(frame))
    }

    fn read_motion(&mut self, now: Time) -> Result<MotionFeedback, PlatformError> {
        let mut inbox = self.connection.inbox();
        if let Some(reason) = &inbox.closed {
            return Err(PlatformError::Disconnected(reason.clone()));
        }
        let stamp = match inbox.body {
            Some(_) => {
                let server = inbox.motion_stamp;
                inbox.map(server, now)
            }
            None => now,
        };
        let odometry = std::mem::replace(&mut inbox.odometry, Odometry::ZERO);
        Ok(MotionFeedback {
            stamp,
            body: inbox.body.unwrap_or(BodyMotionState::Standing),
            head: inbox.head,
            head_settled: inbox.head_settled,
            odometry,
        })
    }

    fn write(&mut self, _now: Time, orders: &ActuatorOrders) -> Result<(), PlatformError> {
        self.check(orders)?;
        self.connection
            .send(&ClientMessage::Orders { orders: *orders })
            .map_err(PlatformError::Disconnected)
    }
}

/// The team radio of a robot driven through the simulator server.
pub struct TcpTeamLink {
    connection: Arc<Connection>,
}

impl std::fmt::Debug for TcpTeamLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TcpTeamLink").finish_non_exhaustive()
    }
}

fn map_packets(inbox: &mut Inbox, packets: Vec<ReceivedPacket>, now: Time) -> Vec<ReceivedPacket> {
    packets
        .into_iter()
        .map(|p| ReceivedPacket { received: inbox.map(p.received, now), bytes: p.bytes })
        .collect()
}

impl TeamLink for TcpTeamLink {
    fn send(&mut self, _now: Time, payload: &[u8]) -> Result<(), LinkError> {
        let limit = self.connection.welcome.max_team_message;
        if payload.len() > limit {
            return Err(LinkError::TooLarge { size: payload.len(), limit });
        }
        self.connection
            .send(&ClientMessage::TeamMessage { payload: Bytes(payload.to_vec()) })
            .map_err(LinkError::Closed)
    }

    fn receive(&mut self, now: Time) -> Result<Vec<ReceivedPacket>, LinkError> {
        let mut inbox = self.connection.inbox();
        let packets = std::mem::take(&mut inbox.team);
        if packets.is_empty()
            && let Some(reason) = &inbox.closed
        {
            return Err(LinkError::Closed(reason.clone()));
        }
        Ok(map_packets(&mut inbox, packets, now))
    }
}

/// The GameController link of a robot driven through the simulator server.
pub struct TcpGameControllerLink {
    connection: Arc<Connection>,
}

impl std::fmt::Debug for TcpGameControllerLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TcpGameControllerLink").finish_non_exhaustive()
    }
}

impl ExternalLink for TcpGameControllerLink {
    fn receive(&mut self, now: Time) -> Result<Vec<ReceivedPacket>, LinkError> {
        let mut inbox = self.connection.inbox();
        let packets = std::mem::take(&mut inbox.control);
        if packets.is_empty()
            && let Some(reason) = &inbox.closed
        {
            return Err(LinkError::Closed(reason.clone()));
        }
        Ok(map_packets(&mut inbox, packets, now))
    }

    fn send(&mut self, _now: Time, payload: &[u8]) -> Result<(), LinkError> {
        self.connection
            .send(&ClientMessage::ReturnPacket { payload: Bytes(payload.to_vec()) })
            .map_err(LinkError::Closed)
    }
}
