//! The simulator server: the world in real time, one TCP connection per robot process
//! (HL-SIM's architecture, paper 4.1). Commands are applied when they arrive, so a robot's
//! processing time counts. Team messages go through the server, which forwards them to the
//! sender's teammates.
//!
//! Threads: one steps the world and hands each connected robot its messages; one accepts
//! connections; per connection, one reads (and applies what arrives) and, once the robot said
//! `hello`, one writes. A slow or broken client never blocks the world: its queue overflows (and
//! is counted) or it is dropped. [`ServerLimits`] bounds what any one peer can cost: how many
//! connections are open, how long a handshake may take, how often a robot may take the
//! simulation's lock, how long a write may block.

use std::io::Read;
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, Sender, TrySendError};
use strata_runtime::Time;
use strata_spl::gamecontroller::GameState;

use super::protocol::{
    self, Bytes, ClientMessage, Deadline, ErrorCode, FrameError, MAX_CLIENT_FRAME, PROTOCOL,
    ServerMessage, VERSION,
};
use crate::platform::SimHandle;
use crate::truth::RobotId;

/// Why the server could not start or stopped.
#[derive(Debug, thiserror::Error)]
pub enum ServerError {
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        addr: String,
        #[source]
        source: std::io::Error,
    },
    #[error("server I/O error: {0}")]
    Io(#[from] std::io::Error),
    #[error("cannot start a server thread: {0}")]
    Spawn(std::io::Error),
    #[error("invalid server limit: {0}")]
    Limits(String),
}

/// How the server runs.
#[derive(Clone, Debug)]
pub struct ServerOptions {
    /// World step; `None`: the simulation's sensor period.
    pub tick: Option<Duration>,
    /// How often `run` reports its status.
    pub status_interval: Duration,
    /// Messages queued per robot before new ones are dropped.
    pub queue: usize,
    /// Robots are in the world only while a process drives them.
    pub robots_need_clients: bool,
    /// What one peer may cost the server.
    pub limits: ServerLimits,
}

impl Default for ServerOptions {
    fn default() -> Self {
        ServerOptions {
            tick: None,
            status_interval: Duration::from_secs(5),
            queue: 1024,
            robots_need_clients: true,
            limits: ServerLimits::DEFAULT,
        }
    }
}

/// Caps and deadlines that keep one peer (a stuck robot, a port scanner, a flood) from taking
/// the server's threads, memory or simulation from everyone else. Documented with their
/// defaults in `docs/sim-protocol.md`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ServerLimits {
    /// Connections open at once, robots and handshakes together. One more is answered with
    /// `too_many_connections` and closed.
    pub max_connections: usize,
    /// From accepting a connection to having read its whole `hello`: a peer that sends its hello
    /// a byte at a time cannot hold a connection longer than this.
    pub handshake_deadline: Duration,
    /// Messages (orders, team messages, return packets) a robot may send per second, each of
    /// which takes the simulation's lock; bursts of a tenth of a second's worth (at least 10)
    /// pass. Messages above the rate are dropped and counted (`throttled`).
    pub max_messages_per_second: u32,
    /// How long a write to one peer may block before the server gives up on that peer.
    pub write_timeout: Duration,
}

impl ServerLimits {
    /// A robot sends orders about once per sensor period (83 Hz); a team of 7 plus spare
    /// connections for reconnects and tools fits the connection cap many times over.
    pub const DEFAULT: ServerLimits = ServerLimits {
        max_connections: 64,
        handshake_deadline: Duration::from_secs(5),
        max_messages_per_second: 500,
        write_timeout: Duration::from_secs(2),
    };

    /// Refuses a zero limit, naming it. The OS takes a zero write timeout for none at all, so a
    /// zero there would lift the bound on every write silently; a zero elsewhere refuses every
    /// peer.
    pub fn validate(&self) -> Result<(), String> {
        let zero = if self.max_connections == 0 {
            Some("max_connections")
        } else if self.handshake_deadline.is_zero() {
            Some("handshake_deadline")
        } else if self.max_messages_per_second == 0 {
            Some("max_messages_per_second")
        } else if self.write_timeout.is_zero() {
            Some("write_timeout")
        } else {
            None
        };
        match zero {
            Some(field) => Err(format!("{field} is 0; it must be positive")),
            None => Ok(()),
        }
    }
}

impl Default for ServerLimits {
    fn default() -> Self {
        ServerLimits::DEFAULT
    }
}

/// What the server's limits did so far, and how many connections are open.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ServerCounters {
    /// Connections open now (robots and handshakes).
    pub connections: usize,
    /// Messages read from robots after their `hello`, throttled ones included.
    pub messages: u64,
    /// Messages dropped because a robot sent above `max_messages_per_second`.
    pub throttled: u64,
    /// Connections closed by a limit before `hello`: over `max_connections`, or past the
    /// handshake deadline.
    pub refused: u64,
    /// Messages dropped because a robot did not read fast enough.
    pub dropped: u64,
}

/// A status report of a running server.
#[derive(Clone, Debug, PartialEq)]
pub struct ServerStatus {
    pub sim_time: Time,
    pub wall: Duration,
    pub clients: usize,
    pub state: GameState,
    pub first_half: bool,
    pub score: [u8; 2],
    pub secs_remaining: f64,
    /// Simulated seconds per wall second since the last report.
    pub real_time_factor: f64,
    /// Messages dropped because a client did not read fast enough.
    pub dropped: u64,
    /// Messages dropped because a robot sent above the message rate.
    pub throttled: u64,
    /// Connections closed by a limit before `hello`.
    pub refused: u64,
    /// Steps that started late by more than one tick.
    pub late_steps: u64,
}

impl std::fmt::Display for ServerStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "t={:8.2} s  robots={:2}  {:?}{}  score {}:{}  clock {:4.0} s  x{:.2} real time",
            self.sim_time.as_secs_f64(),
            self.clients,
            self.state,
            if self.first_half { " (1st half)" } else { " (2nd half)" },
            self.score[0],
            self.score[1],
            self.secs_remaining,
            self.real_time_factor,
        )?;
        if self.dropped > 0 || self.late_steps > 0 {
            write!(f, "  dropped={} late={}", self.dropped, self.late_steps)?;
        }
        if self.throttled > 0 || self.refused > 0 {
            write!(f, "  throttled={} refused={}", self.throttled, self.refused)?;
        }
        Ok(())
    }
}

enum Outgoing {
    Message(ServerMessage),
    /// Send this, then close the connection.
    Close(ServerMessage),
}

struct Client {
    connection: u64,
    robot: RobotId,
    sender: Sender<Outgoing>,
}

#[derive(Default)]
struct Registry {
    /// Per robot slot, the process driving it.
    clients: Vec<Option<Client>>,
    /// Every open connection (for shutdown).
    streams: Vec<(u64, TcpStream)>,
}

struct Shared {
    sim: SimHandle,
    registry: Mutex<Registry>,
    stop: Arc<AtomicBool>,
    dropped: AtomicU64,
    throttled: AtomicU64,
    refused: AtomicU64,
    messages: AtomicU64,
    /// Connections whose thread is running.
    open: AtomicUsize,
    next_connection: AtomicU64,
    options: ServerOptions,
    players: u8,
}

impl Shared {
    fn registry(&self) -> MutexGuard<'_, Registry> {
        self.registry.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn limits(&self) -> &ServerLimits {
        &self.options.limits
    }

    fn counters(&self) -> ServerCounters {
        ServerCounters {
            connections: self.open.load(Ordering::Relaxed),
            messages: self.messages.load(Ordering::Relaxed),
            throttled: self.throttled.load(Ordering::Relaxed),
            refused: self.refused.load(Ordering::Relaxed),
            dropped: self.dropped.load(Ordering::Relaxed),
        }
    }

    fn slot(&self, robot: RobotId) -> usize {
        robot.team * usize::from(self.players) + usize::from(robot.player) - 1
    }
}

/// A bound server, ready to run.
pub struct Server {
    listener: TcpListener,
    shared: Arc<Shared>,
    addr: SocketAddr,
}

impl std::fmt::Debug for Server {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Server").field("addr", &self.addr).finish_non_exhaustive()
    }
}

impl Server {
    /// Binds the listening socket. With `robots_need_clients`, every robot leaves the world
    /// until a process connects for it.
    pub fn bind(
        addr: impl ToSocketAddrs + std::fmt::Display,
        sim: SimHandle,
        options: ServerOptions,
    ) -> Result<Server, ServerError> {
        options.limits.validate().map_err(ServerError::Limits)?;
        let listener = TcpListener::bind(&addr)
            .map_err(|source| ServerError::Bind { addr: addr.to_string(), source })?;
        let local = listener.local_addr()?;
        listener.set_nonblocking(true)?;
        let players = {
            let mut world = sim.lock();
            if options.robots_need_clients {
                let ids: Vec<RobotId> = world.robot_ids().collect();
                for id in ids {
                    // Every id comes from the world itself.
                    let _ = world.remove_robot(id);
                }
            }
            world.config().referee.players_per_team
        };
        let slots = 2 * usize::from(players);
        let registry =
            Registry { clients: (0..slots).map(|_| None).collect(), streams: Vec::new() };
        Ok(Server {
            listener,
            addr: local,
            shared: Arc::new(Shared {
                sim,
                registry: Mutex::new(registry),
                stop: Arc::new(AtomicBool::new(false)),
                dropped: AtomicU64::new(0),
                throttled: AtomicU64::new(0),
                refused: AtomicU64::new(0),
                messages: AtomicU64::new(0),
                open: AtomicUsize::new(0),
                next_connection: AtomicU64::new(1),
                options,
                players,
            }),
        })
    }

    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    pub fn sim(&self) -> SimHandle {
        self.shared.sim.clone()
    }

    pub fn counters(&self) -> ServerCounters {
        self.shared.counters()
    }

    /// Runs the world in real time until `stop` becomes true, calling `on_status` every
    /// `status_interval`. Closes every connection before returning.
    pub fn run(
        self,
        stop: Arc<AtomicBool>,
        mut on_status: impl FnMut(&ServerStatus),
    ) -> Result<(), ServerError> {
        let shared = Arc::clone(&self.shared);
        let accept_shared = Arc::clone(&shared);
        let listener = self.listener;
        let acceptor = std::thread::Builder::new()
            .name("sim-accept".to_owned())
            .spawn(move || accept_loop(listener, accept_shared))
            .map_err(ServerError::Spawn)?;

        let tick = shared.options.tick.unwrap_or_else(|| {
            let seconds = shared.sim.lock().config().timing.sensor_period;
            Duration::from_nanos((seconds * 1e9).round().max(1.0) as u64)
        });
        let start = Instant::now();
        let mut next = start;
        let mut late_steps = 0;
        let mut last_status = (start, shared.sim.lock().time());
        let mut batches: Vec<(Sender<Outgoing>, Vec<ServerMessage>)> = Vec::new();
        while !stop.load(Ordering::Relaxed) && !shared.stop.load(Ordering::Relaxed) {
            next += tick;
            let now = Instant::now();
            if next > now {
                std::thread::sleep(next - now);
            } else if now - next > tick {
                late_steps += 1;
                if now - next > 10 * tick {
                    // Far behind (a suspended process): skip ahead rather than run a burst.
                    next = now;
                }
            }
            step_and_collect(&shared, tick, &mut batches);
            for (sender, messages) in batches.drain(..) {
                for message in messages {
                    if let Err(TrySendError::Full(_)) = sender.try_send(Outgoing::Message(message))
                    {
                        shared.dropped.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
            let wall = Instant::now();
            if wall - last_status.0 >= shared.options.status_interval {
                let status = status(&shared, start, last_status, late_steps);
                last_status = (wall, status.sim_time);
                on_status(&status);
            }
        }
        // Tell every client first; only then does the acceptor stop and close every
        // connection, and each connection's writer sends what is queued before it ends.
        for client in shared.registry().clients.iter().flatten() {
            let _ = client.sender.try_send(Outgoing::Close(ServerMessage::Error {
                code: ErrorCode::ServerShutdown,
                message: "the simulator server is stopping".to_owned(),
            }));
        }
        shared.stop.store(true, Ordering::Relaxed);
        let _ = acceptor.join();
        Ok(())
    }

    /// Runs the server on its own thread (tests, embedding).
    pub fn spawn(self) -> Result<RunningServer, ServerError> {
        let stop = Arc::new(AtomicBool::new(false));
        let addr = self.addr;
        let sim = self.sim();
        let shared = Arc::clone(&self.shared);
        let thread_stop = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name("sim-server".to_owned())
            .spawn(move || self.run(thread_stop, |_| {}))
            .map_err(ServerError::Spawn)?;
        Ok(RunningServer { addr, sim, shared, stop, thread: Some(thread) })
    }
}

/// A server running on its own thread; stops when dropped.
pub struct RunningServer {
    addr: SocketAddr,
    sim: SimHandle,
    shared: Arc<Shared>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<Result<(), ServerError>>>,
}

impl std::fmt::Debug for RunningServer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RunningServer").field("addr", &self.addr).finish_non_exhaustive()
    }
}

impl RunningServer {
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    pub fn sim(&self) -> SimHandle {
        self.sim.clone()
    }

    pub fn counters(&self) -> ServerCounters {
        self.shared.counters()
    }

    /// Stops the server and waits for it.
    pub fn stop(mut self) -> Result<(), ServerError> {
        self.shutdown()
    }

    fn shutdown(&mut self) -> Result<(), ServerError> {
        self.stop.store(true, Ordering::Relaxed);
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(result)) => result,
            Some(Err(_)) => {
                Err(ServerError::Io(std::io::Error::other("the server thread panicked")))
            }
            None => Ok(()),
        }
    }
}

impl Drop for RunningServer {
    fn drop(&mut self) {
        let _ = self.shutdown();
    }
}

fn status(
    shared: &Shared,
    start: Instant,
    (last_wall, last_sim): (Instant, Time),
    late_steps: u64,
) -> ServerStatus {
    let clients = shared.registry().clients.iter().flatten().count();
    let sim = shared.sim.lock();
    let game = sim.game();
    let now = Instant::now();
    let sim_time = sim.time();
    let wall = now - last_wall;
    ServerStatus {
        sim_time,
        wall: now - start,
        clients,
        state: game.state,
        first_half: game.first_half,
        score: game.score,
        secs_remaining: game.secs_remaining,
        real_time_factor: (sim_time - last_sim).as_secs_f64() / wall.as_secs_f64().max(1e-9),
        dropped: shared.dropped.load(Ordering::Relaxed),
        throttled: shared.throttled.load(Ordering::Relaxed),
        refused: shared.refused.load(Ordering::Relaxed),
        late_steps,
    }
}

/// Steps the world once and gathers every connected robot's messages.
fn step_and_collect(
    shared: &Shared,
    tick: Duration,
    batches: &mut Vec<(Sender<Outgoing>, Vec<ServerMessage>)>,
) {
    let clients: Vec<(RobotId, Sender<Outgoing>)> =
        shared.registry().clients.iter().flatten().map(|c| (c.robot, c.sender.clone())).collect();
    let mut sim = shared.sim.lock();
    sim.step(tick);
    for (robot, sender) in clients {
        let mut messages = Vec::new();
        if let Ok(packets) = sim.take_control_packets(robot) {
            messages.extend(packets.into_iter().map(|p| ServerMessage::ControlPacket {
                received: p.received,
                payload: Bytes(p.bytes),
            }));
        }
        if let Ok(packets) = sim.take_team_messages(robot) {
            messages.extend(packets.into_iter().map(|p| ServerMessage::TeamMessage {
                received: p.received,
                payload: Bytes(p.bytes),
            }));
        }
        if let Ok(Some(frame)) = sim.take_sensor_frame(robot) {
            messages.push(ServerMessage::Sensors { frame });
            if let Ok(feedback) = sim.read_motion(robot) {
                messages.push(ServerMessage::Motion { feedback });
            }
        }
        batches.push((sender, messages));
    }
}

/// How long a refused connection stays open so its peer can read why: closing a socket with
/// unread input makes the kernel reset it, which could destroy the error frame on its way.
const LINGER: Duration = Duration::from_secs(1);
/// Refused connections lingering at once; under a flood the oldest are closed early.
const MAX_LINGERING: usize = 64;
/// At most one warning about refused connections per this interval (a flood would fill the log).
const REFUSAL_WARNING_INTERVAL: Duration = Duration::from_secs(5);

/// A connection refused by the acceptor, read and discarded until its peer closes or `until`.
struct Lingering {
    stream: TcpStream,
    until: Instant,
}

/// Refusals since the last warning.
#[derive(Default)]
struct RefusalLog {
    last_warning: Option<Instant>,
    since: u64,
}

/// Counts a connection as open until its thread ends, however it ends.
struct OpenConnection(Arc<Shared>);

impl Drop for OpenConnection {
    fn drop(&mut self) {
        self.0.open.fetch_sub(1, Ordering::Relaxed);
    }
}

fn accept_loop(listener: TcpListener, shared: Arc<Shared>) {
    let mut threads: Vec<JoinHandle<()>> = Vec::new();
    let mut lingering: Vec<Lingering> = Vec::new();
    let mut refusals = RefusalLog::default();
    while !shared.stop.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((stream, peer)) => {
                // Only this thread opens connections, so the count cannot pass the cap between
                // the check and the increment.
                if shared.open.load(Ordering::Relaxed) >= shared.limits().max_connections {
                    refuse_over_cap(stream, peer, &shared, &mut lingering, &mut refusals);
                } else if let Some(thread) = spawn_connection(stream, peer, &shared) {
                    threads.push(thread);
                }
                threads.retain(|t| !t.is_finished());
            }
            Err(error) if error.kind() == std::io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(20));
            }
            Err(error) => {
                tracing::warn!(%error, "accept failed");
                std::thread::sleep(Duration::from_millis(20));
            }
        }
        drain(&mut lingering);
    }
    // Wake connection threads still reading, then wait for them.
    for (_, stream) in &shared.registry().streams {
        let _ = stream.shutdown(Shutdown::Read);
    }
    for thread in threads {
        let _ = thread.join();
    }
}

fn spawn_connection(
    stream: TcpStream,
    peer: SocketAddr,
    shared: &Arc<Shared>,
) -> Option<JoinHandle<()>> {
    let connection = shared.next_connection.fetch_add(1, Ordering::Relaxed);
    shared.open.fetch_add(1, Ordering::Relaxed);
    let thread_shared = Arc::clone(shared);
    let spawned =
        std::thread::Builder::new().name(format!("sim-conn-{connection}")).spawn(move || {
            let open = OpenConnection(thread_shared);
            serve(stream, peer, connection, &open.0);
        });
    match spawned {
        Ok(thread) => Some(thread),
        Err(error) => {
            shared.open.fetch_sub(1, Ordering::Relaxed);
            tracing::warn!(%peer, %error, "cannot serve a connection");
            None
        }
    }
}

/// Answers a connection over `max_connections` from the acceptor itself: no thread, no queue.
fn refuse_over_cap(
    stream: TcpStream,
    peer: SocketAddr,
    shared: &Shared,
    lingering: &mut Vec<Lingering>,
    refusals: &mut RefusalLog,
) {
    shared.refused.fetch_add(1, Ordering::Relaxed);
    let limit = shared.limits().max_connections;
    refusals.since += 1;
    let now = Instant::now();
    if refusals.last_warning.is_none_or(|last| now - last >= REFUSAL_WARNING_INTERVAL) {
        tracing::warn!(
            %peer,
            refused = refusals.since,
            "refusing connections: {limit} are open, the server's limit (max_connections)"
        );
        refusals.last_warning = Some(now);
        refusals.since = 0;
    }
    let message = error(
        ErrorCode::TooManyConnections,
        format!("the server already has {limit} connections open, its limit; try again later"),
    );
    // Non-blocking: the acceptor must never wait for a peer. A fresh socket's send buffer takes
    // one small frame at once; if it does not, the peer only misses the reason.
    if stream.set_nonblocking(true).is_err() {
        return;
    }
    let mut writer = &stream;
    let _ = std::io::Write::write_all(&mut writer, &protocol::encode(&message));
    let _ = stream.shutdown(Shutdown::Write);
    if lingering.len() >= MAX_LINGERING {
        lingering.remove(0);
    }
    lingering.push(Lingering { stream, until: now + LINGER });
}

/// Reads and discards what refused peers still send; closes each at its end or deadline.
fn drain(lingering: &mut Vec<Lingering>) {
    let now = Instant::now();
    let mut sink = [0u8; 4096];
    lingering.retain(|l| {
        if now >= l.until {
            return false;
        }
        // Bounded, so a peer that keeps sending cannot hold the acceptor.
        for _ in 0..16 {
            match (&l.stream).read(&mut sink) {
                Ok(0) => return false,
                Ok(_) => {}
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return true,
                Err(_) => return false,
            }
        }
        true
    });
}

fn error(code: ErrorCode, message: impl Into<String>) -> ServerMessage {
    ServerMessage::Error { code, message: message.into() }
}

/// One connection: handshake, then apply what the robot sends until it leaves.
fn serve(stream: TcpStream, peer: SocketAddr, connection: u64, shared: &Shared) {
    let _ = stream.set_nodelay(true);
    let _ = stream.set_write_timeout(Some(shared.limits().write_timeout));
    let Ok(registered) = stream.try_clone() else {
        return;
    };
    shared.registry().streams.push((connection, registered));
    let mut reader = stream;
    // Before hello a connection costs this thread only: its queue and writer exist once the
    // peer has shown it speaks the protocol.
    match read_hello(&reader, shared) {
        Ok((team, player)) => serve_robot(&mut reader, peer, connection, shared, team, player),
        Err(refusal) => {
            tracing::warn!(%peer, ?refusal, "connection refused");
            refuse(&mut reader, &refusal);
        }
    }
    let _ = reader.shutdown(Shutdown::Both);
    shared.registry().streams.retain(|(c, _)| *c != connection);
}

/// A robot that said hello: its writer, then admission, then what it sends until it leaves.
fn serve_robot(
    reader: &mut TcpStream,
    peer: SocketAddr,
    connection: u64,
    shared: &Shared,
    team: u8,
    player: u8,
) {
    let Ok(writer_stream) = reader.try_clone() else {
        return;
    };
    let (sender, receiver) = crossbeam_channel::bounded(shared.options.queue.max(16));
    let write_timeout = shared.limits().write_timeout;
    let writer = std::thread::Builder::new()
        .name(format!("sim-write-{connection}"))
        .spawn(move || write_loop(writer_stream, receiver, write_timeout));
    let writer = match writer {
        Ok(writer) => writer,
        Err(error) => {
            tracing::warn!(%peer, %error, "cannot start a robot's writer thread");
            return;
        }
    };
    match admit(shared, connection, team, player, &sender) {
        Ok(robot) => play(reader, peer, connection, shared, robot, &sender),
        Err(refusal) => {
            tracing::warn!(%peer, ?refusal, "connection refused");
            close_with(reader, &sender, *refusal, write_timeout);
        }
    }
    drop(sender);
    let _ = writer.join();
}

fn play(
    reader: &mut TcpStream,
    peer: SocketAddr,
    connection: u64,
    shared: &Shared,
    robot: RobotId,
    sender: &Sender<Outgoing>,
) {
    tracing::info!(%peer, %robot, "robot connected");
    if let Some(refusal) = read_loop(reader, shared, peer, robot) {
        tracing::info!(%peer, %robot, ?refusal, "robot disconnected by the server");
        close_with(reader, sender, refusal, shared.limits().write_timeout);
    } else {
        tracing::info!(%peer, %robot, "robot disconnected");
    }
    let mut registry = shared.registry();
    let slot = shared.slot(robot);
    if registry.clients[slot].as_ref().is_some_and(|c| c.connection == connection) {
        registry.clients[slot] = None;
        drop(registry);
        let _ = shared.sim.lock().remove_robot(robot);
    }
}

/// Sends a last error through the robot's writer, then lingers.
fn close_with(
    reader: &mut TcpStream,
    sender: &Sender<Outgoing>,
    message: ServerMessage,
    write_timeout: Duration,
) {
    // The queue may be full of frames the robot is slow to read; the writer empties it within
    // its write timeouts or gives up on the robot.
    let _ = sender.send_timeout(Outgoing::Close(message), write_timeout);
    linger(reader);
}

/// Sends a last error on a connection that has no writer yet (the stream's write timeout bounds
/// it), then lingers.
fn refuse(reader: &mut TcpStream, message: &ServerMessage) {
    let _ = protocol::write_message(reader, message);
    let _ = reader.shutdown(Shutdown::Write);
    linger(reader);
}

/// Waits briefly for the peer to close after a last error: closing a socket with unread input
/// makes the kernel reset it, which could destroy the error frame on its way.
fn linger(reader: &mut TcpStream) {
    let _ = reader.set_read_timeout(Some(Duration::from_millis(500)));
    let mut sink = [0u8; 4096];
    let deadline = Instant::now() + LINGER;
    while Instant::now() < deadline {
        match reader.read(&mut sink) {
            Ok(0) | Err(_) => break,
            Ok(_) => {}
        }
    }
}

/// Reads `hello` within the handshake deadline, counted once from now: a peer that trickles its
/// bytes cannot hold the connection longer.
fn read_hello(reader: &TcpStream, shared: &Shared) -> Result<(u8, u8), Box<ServerMessage>> {
    let limit = shared.limits().handshake_deadline;
    let mut deadline = Deadline::new(reader, Instant::now() + limit);
    let hello = protocol::read_message::<ClientMessage>(&mut deadline, MAX_CLIENT_FRAME);
    let _ = reader.set_read_timeout(None);
    match hello {
        Ok(ClientMessage::Hello { protocol, version, team, player }) => {
            if protocol != PROTOCOL || version != VERSION {
                return Err(Box::new(error(
                    ErrorCode::UnsupportedVersion,
                    format!(
                        "this server speaks {PROTOCOL} version {VERSION}, not {protocol} version {version}"
                    ),
                )));
            }
            Ok((team, player))
        }
        Ok(other) => Err(Box::new(error(
            ErrorCode::UnexpectedMessage,
            format!("the first message must be hello, not {}", message_name(&other)),
        ))),
        Err(FrameError::Io(e))
            if matches!(
                e.kind(),
                std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
            ) =>
        {
            shared.refused.fetch_add(1, Ordering::Relaxed);
            Err(Box::new(error(
                ErrorCode::HandshakeTimeout,
                format!(
                    "no complete hello within {} s, the server's handshake deadline",
                    limit.as_secs_f64()
                ),
            )))
        }
        Err(e) => Err(Box::new(frame_error(e))),
    }
}

/// Puts the robot named in `hello` in the world, unless it is unknown or already driven.
fn admit(
    shared: &Shared,
    connection: u64,
    team: u8,
    player: u8,
    sender: &Sender<Outgoing>,
) -> Result<RobotId, Box<ServerMessage>> {
    let mut sim = shared.sim.lock();
    let team_index = sim
        .team_index(team)
        .map_err(|e| Box::new(error(ErrorCode::UnknownRobot, e.to_string())))?;
    let robot = RobotId::new(team_index, player);
    sim.robot(robot).map_err(|e| Box::new(error(ErrorCode::UnknownRobot, e.to_string())))?;
    let mut registry = shared.registry();
    let slot = shared.slot(robot);
    if registry.clients[slot].is_some() {
        return Err(Box::new(error(
            ErrorCode::SlotTaken,
            format!("another process already drives team {team} player {player}"),
        )));
    }
    // The welcome is queued before the client is registered: once registered, the simulation
    // loop may queue sensor frames for it, and the robot must see the welcome first.
    let welcome = ServerMessage::Welcome {
        version: VERSION,
        team,
        player,
        team_index,
        info: sim.platform_info(),
        max_team_message: sim.config().broadcast.max_message_size,
        time: sim.time(),
    };
    let _ = sender.send(Outgoing::Message(welcome));
    registry.clients[slot] = Some(Client { connection, robot, sender: sender.clone() });
    drop(registry);
    let _ = sim.add_robot(robot);
    drop(sim);
    Ok(robot)
}

fn message_name(message: &ClientMessage) -> &'static str {
    match message {
        ClientMessage::Hello { .. } => "hello",
        ClientMessage::Orders { .. } => "orders",
        ClientMessage::TeamMessage { .. } => "team_message",
        ClientMessage::ReturnPacket { .. } => "return_packet",
        ClientMessage::Goodbye => "goodbye",
    }
}

fn frame_error(e: FrameError) -> ServerMessage {
    match e {
        FrameError::TooLarge { size, limit } => error(
            ErrorCode::FrameTooLarge,
            format!("frame of {size} bytes exceeds the limit of {limit}"),
        ),
        other => error(ErrorCode::MalformedFrame, other.to_string()),
    }
}

/// A token bucket: `rate` messages per second on average, bursts of up to `capacity`.
struct Allowance {
    rate: f64,
    capacity: f64,
    tokens: f64,
    last: Instant,
}

impl Allowance {
    fn new(per_second: u32) -> Allowance {
        let rate = f64::from(per_second.max(1));
        let capacity = (rate / 10.0).max(10.0);
        Allowance { rate, capacity, tokens: capacity, last: Instant::now() }
    }

    fn take(&mut self) -> bool {
        let now = Instant::now();
        let earned = self.rate * (now - self.last).as_secs_f64();
        self.tokens = (self.tokens + earned).min(self.capacity);
        self.last = now;
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

/// Applies what the robot sends, at most at the message rate: every message applied takes the
/// simulation's lock, which the world's step needs too. Returns the error to send when the
/// server closes the connection, `None` when the client left.
fn read_loop(
    reader: &mut TcpStream,
    shared: &Shared,
    peer: SocketAddr,
    robot: RobotId,
) -> Option<ServerMessage> {
    let limit = shared.limits().max_messages_per_second;
    let mut allowance = Allowance::new(limit);
    let mut warned = false;
    loop {
        let message = match protocol::read_message::<ClientMessage>(reader, MAX_CLIENT_FRAME) {
            Ok(message) => message,
            Err(FrameError::Closed | FrameError::Io(_)) => return None,
            Err(e) => return Some(frame_error(e)),
        };
        if shared.stop.load(Ordering::Relaxed) {
            return None;
        }
        shared.messages.fetch_add(1, Ordering::Relaxed);
        match message {
            ClientMessage::Goodbye => return None,
            ClientMessage::Hello { .. } => {
                return Some(error(ErrorCode::UnexpectedMessage, "hello was already received"));
            }
            _ if !allowance.take() => {
                shared.throttled.fetch_add(1, Ordering::Relaxed);
                if !warned {
                    warned = true;
                    tracing::warn!(
                        %peer,
                        %robot,
                        "robot sends more than {limit} messages per second, the server's limit \
                         (max_messages_per_second); the excess is dropped"
                    );
                }
            }
            message => apply(shared, robot, message),
        }
    }
}

fn apply(shared: &Shared, robot: RobotId, message: ClientMessage) {
    match message {
        ClientMessage::Orders { orders } => {
            // A sequence the body cannot start in its state (a kick while lying) is refused
            // by the motion engine; over the network that is not an error of the protocol.
            if let Err(refusal) = shared.sim.lock().apply_orders(robot, &orders) {
                tracing::debug!(%robot, %refusal, "order refused");
            }
        }
        ClientMessage::TeamMessage { payload } => {
            // Oversized messages are rejected and counted by the world, like lost ones.
            let _ = shared.sim.lock().send_team_message(robot, &payload.0);
        }
        ClientMessage::ReturnPacket { payload } => {
            let _ = shared.sim.lock().receive_return_packet(robot, &payload.0);
        }
        // `read_loop` answers these itself.
        ClientMessage::Hello { .. } | ClientMessage::Goodbye => {}
    }
}

fn write_loop(mut stream: TcpStream, receiver: Receiver<Outgoing>, timeout: Duration) {
    let _ = stream.set_write_timeout(Some(timeout));
    for outgoing in receiver {
        match outgoing {
            Outgoing::Message(message) => {
                if protocol::write_message(&mut stream, &message).is_err() {
                    // A dead client, or one that read nothing for the write timeout: unblock its
                    // reader so the connection is cleaned up.
                    let _ = stream.shutdown(Shutdown::Both);
                    return;
                }
            }
            Outgoing::Close(message) => {
                let _ = protocol::write_message(&mut stream, &message);
                let _ = stream.shutdown(Shutdown::Write);
                return;
            }
        }
    }
}
