//! The faults, one function each: it injects the fault into the running game, waits for what
//! the fault should lead to (a takeover, a resumption, a refusal...), and returns the window
//! over which the game is measured and what it saw.

use std::collections::BTreeMap;
use std::io::{ErrorKind, Read as _};
use std::net::{IpAddr, Ipv4Addr, SocketAddr, TcpStream, UdpSocket};
use std::process::Command;
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result};
use nix::sys::signal::Signal;
use rand::{Rng as _, RngExt as _, SeedableRng as _};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use strata_sim::net::protocol::{self, ClientMessage, PROTOCOL, ServerMessage, VERSION};
use strata_sim::net::{ErrorCode, ServerLimits};
use strata_soccer::catalog::Role;
use strata_spl::gamecontroller::{CONTROL_HEADER, CONTROL_VERSION, GameControlData, GameState};
use strata_spl::net::LOOPBACK_BROADCAST;

use super::game::{Game, PLAYERS, RobotKey, SPARE_PLAYER, TEAMS};
use super::measure;

/// When a phase was measured, and which robot its fault hit (left out of "the other robots").
#[derive(Clone, Debug)]
pub(super) struct Window {
    pub name: &'static str,
    pub fault: String,
    pub target: Option<RobotKey>,
    pub start: Instant,
    pub end: Instant,
}

/// How long a fault's consequence is awaited before the run says it did not come.
const PATIENCE: Duration = Duration::from_secs(30);

/// The roles that play the ball: the striker when the team attacks, the active defender when
/// it defends. The robot killed holds one; a teammate takes over when it holds one.
fn plays_the_ball(role: Option<&str>) -> bool {
    role.is_some_and(|r| r == Role::Striker.name() || r == Role::ActiveDefender.name())
}

fn secs(from: Instant, to: Instant) -> f64 {
    to.saturating_duration_since(from).as_secs_f64()
}

/// The baseline: nothing injected.
pub(super) fn baseline(game: &mut Game, phase: Duration) -> Result<Window> {
    let start = Instant::now();
    game.run_for(phase)?;
    Ok(Window {
        name: "baseline",
        fault: "none".to_owned(),
        target: None,
        start,
        end: Instant::now(),
    })
}

/// kill -9 and restart.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Takeover {
    pub robot: Option<RobotKey>,
    /// Its role when it was killed.
    pub role: Option<String>,
    /// Seconds from the kill until a teammate's planning layer stopped counting on it.
    pub noticed_s: Option<f64>,
    /// Seconds from the kill until a teammate played the ball (striker or active defender).
    pub taken_over_s: Option<f64>,
    pub taken_over_by: Option<RobotKey>,
    pub role_taken: Option<String>,
    /// How the killed process ended.
    pub killed_status: String,
    /// Seconds from the restart until the robot played again and a teammate counted on it.
    pub rejoined_s: Option<f64>,
}

/// Kills team 10's ball player with SIGKILL, waits until a teammate takes over its role, then
/// starts it again and waits until it plays with its team again.
pub(super) fn kill_and_restart(game: &mut Game, phase: Duration) -> Result<(Window, Takeover)> {
    let team = TEAMS[0];
    let field_players: Vec<RobotKey> =
        PLAYERS[1..].iter().map(|&player| RobotKey { team, player }).collect();
    let ball_player = |g: &Game| {
        field_players.iter().copied().find(|k| {
            g.robot(*k).is_ok_and(|r| plays_the_ball(r.last().and_then(|s| s.role.as_deref())))
        })
    };
    // Roles change with the game: give one a phase to show.
    game.wait_until(phase, |g| ball_player(g).is_some())?;
    let victim = ball_player(game).unwrap_or(field_players[0]);
    let role = game.robot(victim)?.last().and_then(|s| s.role.clone());
    let start = Instant::now();
    game.kill(victim)?;
    let killed_status = game
        .robot(victim)?
        .process
        .exit_status()
        .map_or_else(|| "still running".to_owned(), |s| s.to_string());
    let teammates: Vec<RobotKey> = PLAYERS
        .iter()
        .filter(|&&p| p != victim.player)
        .map(|&player| RobotKey { team, player })
        .collect();
    let survivors: Vec<RobotKey> = field_players.iter().copied().filter(|k| *k != victim).collect();
    let noticed = |g: &Game| -> Option<Instant> {
        teammates
            .iter()
            .filter_map(|k| g.robot(*k).ok())
            .filter_map(|r| {
                r.samples
                    .iter()
                    .find(|s| s.at > start && !s.available.contains(&victim.player))
                    .map(|s| s.at)
            })
            .min()
    };
    let taken = |g: &Game| -> Option<(Instant, RobotKey, Option<String>)> {
        survivors
            .iter()
            .filter_map(|k| g.robot(*k).ok())
            .filter_map(|r| {
                r.samples
                    .iter()
                    .find(|s| s.at > start && plays_the_ball(s.role.as_deref()))
                    .map(|s| (s.at, r.key, s.role.clone()))
            })
            .min_by_key(|(at, _, _)| *at)
    };
    game.wait_until(PATIENCE, |g| noticed(g).is_some() && taken(g).is_some())?;
    let (noticed_at, taken_over) = (noticed(game), taken(game));

    let restarted = Instant::now();
    game.restart(victim)?;
    let rejoined = |g: &Game| -> Option<Instant> {
        let back = g.robot(victim).ok()?.samples.iter().find(|s| {
            s.at > restarted
                && s.game_state.as_deref() == Some("Playing")
                && !s.available.is_empty()
        })?;
        let counted = teammates
            .iter()
            .filter_map(|k| g.robot(*k).ok())
            .filter_map(|r| {
                r.samples
                    .iter()
                    .find(|s| s.at > restarted && s.available.contains(&victim.player))
                    .map(|s| s.at)
            })
            .min()?;
        Some(back.at.max(counted))
    };
    game.wait_until(PATIENCE, |g| rejoined(g).is_some())?;
    let rejoined_at = rejoined(game);
    let end = (start + phase).max(Instant::now());
    game.run_for(end.saturating_duration_since(Instant::now()))?;
    let takeover = Takeover {
        robot: Some(victim),
        role,
        noticed_s: noticed_at.map(|t| secs(start, t)),
        taken_over_s: taken_over.as_ref().map(|(t, _, _)| secs(start, *t)),
        taken_over_by: taken_over.as_ref().map(|(_, k, _)| *k),
        role_taken: taken_over.and_then(|(_, _, r)| r),
        killed_status,
        rejoined_s: rejoined_at.map(|t| secs(restarted, t)),
    };
    let window = Window {
        name: "kill -9",
        fault: format!("kill -9 robot {victim}, restarted once a teammate took over"),
        target: Some(victim),
        start,
        end: Instant::now(),
    };
    Ok((window, takeover))
}

/// SIGSTOP for a while, then SIGCONT.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Stopped {
    pub robot: Option<RobotKey>,
    pub stopped_s: f64,
    /// Seconds from SIGCONT until it reported new sensor frames.
    pub resumed_s: Option<f64>,
    /// Whether it was still in the server's world after it resumed.
    pub in_game: bool,
}

/// Stops team 20's player 3 for `stop` (SIGSTOP: it neither reads nor sends), then lets it go
/// on.
pub(super) fn stop_and_continue(
    game: &mut Game,
    phase: Duration,
    stop: Duration,
) -> Result<(Window, Stopped)> {
    let key = RobotKey { team: TEAMS[1], player: 3 };
    game.poll();
    let frames = game.robot(key)?.last().map_or(0, |s| s.sensor_frames);
    let start = Instant::now();
    game.robot_mut(key)?.process.signal(Signal::SIGSTOP)?;
    let stopped = game.run_for(stop);
    // Whatever happened meanwhile, the robot must not stay stopped.
    game.robot_mut(key)?.process.signal(Signal::SIGCONT)?;
    stopped?;
    let resumed_at = Instant::now();
    let instance = game.robot(key)?.instance;
    let resumed = |g: &Game| {
        g.robot(key).ok().and_then(|r| {
            r.samples
                .iter()
                .find(|s| s.at > resumed_at && s.instance == instance && s.sensor_frames > frames)
                .map(|s| s.at)
        })
    };
    game.wait_until(PATIENCE, |g| resumed(g).is_some())?;
    let resumed_s = resumed(game).map(|t| secs(resumed_at, t));
    let end = (start + phase).max(resumed_at + Duration::from_secs(2));
    game.run_for(end.saturating_duration_since(Instant::now()))?;
    let figures = Stopped {
        robot: Some(key),
        stopped_s: secs(start, resumed_at),
        resumed_s,
        in_game: game.present(key),
    };
    let window = Window {
        name: "SIGSTOP",
        fault: format!("SIGSTOP robot {key} for {:.0} s, then SIGCONT", stop.as_secs_f64()),
        target: Some(key),
        start,
        end: Instant::now(),
    };
    Ok((window, figures))
}

/// A client that connects as a robot and then hardly reads.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SlowClient {
    /// Whether the server put it into the world.
    pub admitted: bool,
    /// Seconds from its hello until the server dropped it (`None`: not within `--slow-client`).
    pub dropped_after_s: Option<f64>,
    pub bytes_read: u64,
    /// Messages the server dropped meanwhile because a client did not read them.
    pub messages_dropped: u64,
    pub held_s: f64,
}

/// Bytes the slow client reads per second.
const SLOW_READ: usize = 1024;

/// Connects as team 20's spare player, says hello and then reads a kilobyte a second, far
/// less than the server sends a robot (about 100 kB/s), until the server drops it or `hold`
/// has passed; then closes.
pub(super) fn slow_client(game: &mut Game, hold: Duration) -> Result<(Window, SlowClient)> {
    let key = RobotKey { team: TEAMS[1], player: SPARE_PLAYER };
    let before = game.server()?.counters();
    let start = Instant::now();
    let mut stream = TcpStream::connect_timeout(&game.addr, Duration::from_secs(5))
        .context("the slow client connecting")?;
    let hello = ClientMessage::Hello {
        protocol: PROTOCOL.to_owned(),
        version: VERSION,
        team: key.team,
        player: key.player,
    };
    protocol::write_message(&mut stream, &hello).context("the slow client's hello")?;
    stream.set_nonblocking(true).context("the slow client's socket")?;
    let mut admitted = false;
    let mut dropped = None;
    let mut bytes_read = 0u64;
    let mut closed = false;
    let mut next_read = Instant::now();
    let mut buffer = vec![0u8; SLOW_READ];
    game.wait_until(hold, |g| {
        let present = g.present(key);
        admitted |= present;
        if admitted && !present && dropped.is_none() {
            dropped = Some(Instant::now());
        }
        if !closed && Instant::now() >= next_read {
            next_read += Duration::from_secs(1);
            match stream.read(&mut buffer) {
                Ok(0) => closed = true,
                Ok(n) => bytes_read += n as u64,
                Err(e) if e.kind() == ErrorKind::WouldBlock => {}
                Err(_) => closed = true,
            }
        }
        // Dropped by the server: what the client still reads is the kernel's backlog.
        dropped.is_some()
    })?;
    let held_s = secs(start, Instant::now());
    drop(stream);
    let after = game.server()?.counters();
    let window = Window {
        name: "slow client",
        fault: format!("a client says hello as robot {key}, then reads {SLOW_READ} bytes a second"),
        target: None,
        start,
        end: Instant::now(),
    };
    // Its slot is free again before the next fault.
    game.wait_until(Duration::from_secs(10), |g| !g.present(key))?;
    let figures = SlowClient {
        admitted,
        dropped_after_s: dropped.map(|t| secs(start, t)),
        bytes_read,
        messages_dropped: after.dropped.saturating_sub(before.dropped),
        held_s,
    };
    Ok((window, figures))
}

/// Many connections at once.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Connections {
    pub attempts: usize,
    /// Answered `too_many_connections`, then closed.
    pub refused_over_cap: u64,
    /// Held below the cap, answered `handshake_timeout` at the deadline, then closed.
    pub handshake_timeouts: u64,
    /// Any other error code, by code.
    pub other_errors: BTreeMap<String, u64>,
    /// Closed without an error frame, reset, or never answered: refusals that were not clean.
    pub unclean: u64,
    pub unclean_examples: Vec<String>,
    /// Connections the kernel could not even open (the listen backlog full).
    pub connect_failed: u64,
    /// The server's own count of refusals over the phase.
    pub server_refused: u64,
    /// The most connections the server had open at once.
    pub most_open: usize,
    pub seconds: f64,
}

/// Connections kept open at once by the flood (a bound on this process's sockets).
const MAX_PENDING: usize = 256;

/// Opens `attempts` connections that never say hello, as fast as the server accepts them,
/// keeping each open until the server answers: the first fill the server's cap and wait for
/// its handshake deadline, the rest are refused over the cap. Each answer must be an error
/// frame followed by a clean close.
pub(super) fn connection_flood(
    game: &mut Game,
    phase: Duration,
    attempts: usize,
) -> Result<(Window, Connections)> {
    struct Pending {
        stream: TcpStream,
        opened: Instant,
        bytes: Vec<u8>,
    }
    let before = game.server()?.counters();
    // An answer later than the deadline and a margin is no answer.
    let answer_within = ServerLimits::DEFAULT.handshake_deadline + Duration::from_secs(10);
    let start = Instant::now();
    let mut figures = Connections { attempts, ..Connections::default() };
    let mut pending: Vec<Pending> = Vec::new();
    let mut opened = 0;
    let mut buffer = [0u8; 4096];
    let mut last_poll = Instant::now();
    let (mut last_open, mut last_read) = (start, start);
    while opened < attempts || !pending.is_empty() {
        game.check_interrupt()?;
        if last_poll.elapsed() >= Duration::from_millis(100) {
            last_poll = Instant::now();
            game.poll();
            figures.most_open = figures.most_open.max(game.server()?.counters().connections);
        }
        // A thousand attempts a second: far faster than robots connect, and slow enough that
        // the listen backlog never overflows (the kernel would drop the attempts itself
        // before the server could refuse them).
        if opened < attempts
            && pending.len() < MAX_PENDING
            && last_open.elapsed() >= Duration::from_millis(1)
        {
            last_open = Instant::now();
            opened += 1;
            match TcpStream::connect_timeout(&game.addr, Duration::from_secs(2)) {
                Ok(stream) if stream.set_nonblocking(true).is_ok() => {
                    pending.push(Pending { stream, opened: Instant::now(), bytes: Vec::new() });
                }
                _ => figures.connect_failed += 1,
            }
        }
        if last_read.elapsed() < Duration::from_millis(10) {
            std::thread::sleep(Duration::from_micros(200));
            continue;
        }
        last_read = Instant::now();
        let mut i = 0;
        while i < pending.len() {
            let p = &mut pending[i];
            let outcome = match (&p.stream).read(&mut buffer) {
                Ok(0) => Some(answer(&p.bytes)),
                Ok(n) => {
                    p.bytes.extend_from_slice(&buffer[..n]);
                    None
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => {
                    (p.opened.elapsed() > answer_within).then(|| Err("no answer".to_owned()))
                }
                Err(e) => Some(Err(format!("{e} after {} bytes", p.bytes.len()))),
            };
            match outcome {
                None => i += 1,
                Some(Ok(ErrorCode::TooManyConnections)) => {
                    figures.refused_over_cap += 1;
                    pending.swap_remove(i);
                }
                Some(Ok(ErrorCode::HandshakeTimeout)) => {
                    figures.handshake_timeouts += 1;
                    pending.swap_remove(i);
                }
                Some(Ok(code)) => {
                    *figures.other_errors.entry(format!("{code:?}")).or_default() += 1;
                    pending.swap_remove(i);
                }
                Some(Err(why)) => {
                    figures.unclean += 1;
                    if figures.unclean_examples.len() < 5 {
                        figures.unclean_examples.push(why);
                    }
                    pending.swap_remove(i);
                }
            }
        }
    }
    figures.seconds = secs(start, Instant::now());
    figures.server_refused = game.server()?.counters().refused.saturating_sub(before.refused);
    let end = (start + phase).max(Instant::now());
    game.run_for(end.saturating_duration_since(Instant::now()))?;
    let window = Window {
        name: "connections",
        fault: format!("{attempts} connection attempts that never say hello"),
        target: None,
        start,
        end: Instant::now(),
    };
    Ok((window, figures))
}

/// What a refused connection received before the server closed it: one error frame is a clean
/// refusal.
fn answer(bytes: &[u8]) -> Result<ErrorCode, String> {
    let mut reader = bytes;
    match protocol::read_message::<ServerMessage>(&mut reader, protocol::MAX_SERVER_FRAME) {
        Ok(ServerMessage::Error { code, .. }) if reader.is_empty() => Ok(code),
        Ok(ServerMessage::Error { .. }) => {
            Err(format!("{} bytes after the error frame", reader.len()))
        }
        Ok(_) => Err("a message other than an error".to_owned()),
        Err(e) => Err(format!("closed without an error frame ({e}, {} bytes)", bytes.len())),
    }
}

/// Garbage at one robot's GameController port and its team's port.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Garbage {
    pub robot: Option<RobotKey>,
    pub ports: Vec<GarbagePort>,
    /// Seconds the garbage took to send.
    pub seconds: f64,
    /// The longest stretch of the phase in which a robot of the flooded team counted on fewer
    /// than both its teammates (silent, fallen or lost), and which robot, s.
    pub team_gap: Option<(RobotKey, f64)>,
    /// The same for the other team, which no garbage reached: what the game alone does.
    pub other_team_gap: Option<(RobotKey, f64)>,
}

#[derive(Clone, Debug, Default, Serialize)]
pub struct GarbagePort {
    /// "GameController" or "team".
    pub port_kind: String,
    pub port: u16,
    pub sent: u64,
    pub send_errors: u64,
    /// Sockets bound to the port: every one receives each datagram (the team port's are the
    /// whole team's; the garbage is broadcast, as anything on a team port is).
    pub sockets: usize,
    /// Datagrams the kernel dropped on the port's sockets during the phase (full receive
    /// buffers; real packets dropped in the flood count here too).
    pub kernel_dropped: u64,
    /// Datagrams the robots read and threw away, counted (rejected, or ignored: another game's
    /// packets). Filled in at the end, from the robots' reports.
    pub robots_counted: u64,
}

impl GarbagePort {
    /// Every garbage datagram was counted somewhere: read and rejected by a robot, or dropped
    /// by the kernel for want of room (with the real packets the flood crowded out).
    pub fn accounted(&self) -> bool {
        let delivered = self.sent.saturating_sub(self.send_errors) * self.sockets as u64;
        self.robots_counted <= delivered && self.robots_counted + self.kernel_dropped >= delivered
    }
}

/// Sends `count` garbage datagrams to team 20's player 2's GameController port and `count` to
/// team 20's port, spread over the phase; none of them decodes as a packet for that robot (the
/// decoders themselves say so).
pub(super) fn garbage(
    game: &mut Game,
    phase: Duration,
    count: u64,
    seed: u64,
) -> Result<(Window, Garbage)> {
    let key = RobotKey { team: TEAMS[1], player: 2 };
    let gc_port = game.robot(key)?.gc_port;
    let team_port = game.team_ports[1];
    let drops_before = [measure::udp_drops(gc_port), measure::udp_drops(team_port)];
    let socket =
        UdpSocket::bind((Ipv4Addr::UNSPECIFIED, 0)).context("binding the garbage socket")?;
    socket.set_broadcast(true).context("the garbage socket")?;
    let gc_to = SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), gc_port);
    let team_to = SocketAddr::new(IpAddr::V4(LOOPBACK_BROADCAST), team_port);
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6761_7262);
    let valid = {
        let mut data = GameControlData {
            state: GameState::Playing,
            players_per_team: SPARE_PLAYER,
            ..GameControlData::default()
        };
        data.teams[0].team_number = TEAMS[0];
        data.teams[1].team_number = TEAMS[1];
        data.encode().to_vec()
    };
    let mut sent = [0u64; 2];
    let mut errors = [0u64; 2];
    let start = Instant::now();
    let spread = phase.mul_f64(0.8).max(Duration::from_millis(100));
    let mut last_poll = Instant::now();
    while sent[0] < count || sent[1] < count {
        game.check_interrupt()?;
        if last_poll.elapsed() >= Duration::from_millis(100) {
            last_poll = Instant::now();
            game.poll();
        }
        // Keep to the schedule: as many sent as the elapsed share of the spread.
        let due = ((start.elapsed().as_secs_f64() / spread.as_secs_f64()).min(1.0) * count as f64)
            .ceil() as u64;
        if sent[0] >= due && sent[1] >= due {
            std::thread::sleep(Duration::from_millis(1));
            continue;
        }
        for (i, to) in [gc_to, team_to].into_iter().enumerate() {
            if sent[i] < due {
                let bytes = if i == 0 {
                    gc_garbage(&mut rng, &valid, key.team)
                } else {
                    team_garbage(&mut rng)
                };
                if socket.send_to(&bytes, to).is_err() {
                    errors[i] += 1;
                }
                sent[i] += 1;
            }
        }
    }
    let sending = secs(start, Instant::now());
    let end = (start + phase).max(Instant::now() + Duration::from_secs(1));
    game.run_for(end.saturating_duration_since(Instant::now()))?;
    let drops_after = [measure::udp_drops(gc_port), measure::udp_drops(team_port)];
    let ports = [("GameController", gc_port), ("team", team_port)]
        .into_iter()
        .enumerate()
        .map(|(i, (kind, port))| {
            let (sockets, after) = drops_after[i].unwrap_or_default();
            let before = drops_before[i].map_or(0, |(_, d)| d);
            GarbagePort {
                port_kind: kind.to_owned(),
                port,
                sent: sent[i],
                send_errors: errors[i],
                sockets,
                kernel_dropped: after.saturating_sub(before),
                robots_counted: 0,
            }
        })
        .collect();
    let gap = |team: u8| {
        game.robots
            .iter()
            .filter(|r| r.key.team == team)
            .map(|r| {
                (r.key, measure::longest_gap(&r.samples, start, Instant::now(), PLAYERS.len() - 1))
            })
            .max_by(|a, b| a.1.total_cmp(&b.1))
    };
    let (team_gap, other_team_gap) = (gap(key.team), gap(TEAMS[0]));
    let window = Window {
        name: "garbage",
        fault: format!(
            "{count} garbage datagrams at robot {key}'s GameController port and {count} at team {}'s port",
            key.team
        ),
        target: Some(key),
        start,
        end: Instant::now(),
    };
    Ok((window, Garbage { robot: Some(key), ports, seconds: sending, team_gap, other_team_gap }))
}

/// A datagram for a GameController port that is no control packet for `team`: random bytes,
/// the right header with another version, a valid packet cut short or grown, or another
/// game's valid packet (which a robot counts as ignored).
fn gc_garbage(rng: &mut ChaCha8Rng, valid: &[u8], team: u8) -> Vec<u8> {
    loop {
        let bytes = match rng.random_range(0..4u8) {
            0 => random_bytes(rng, 0..=600),
            1 => {
                let mut bytes = random_bytes(rng, 5..=200);
                bytes[..4].copy_from_slice(&CONTROL_HEADER);
                bytes[4] = CONTROL_VERSION.wrapping_add(rng.random_range(1..=255u8));
                bytes
            }
            2 => {
                let mut bytes = valid.to_vec();
                let change: i64 =
                    rng.random_range(1..=20i64) * if rng.random_bool(0.5) { 1 } else { -1 };
                let length = (bytes.len() as i64 + change).max(0) as usize;
                bytes.resize(length, 0);
                rng.fill_bytes(&mut bytes[valid.len().min(length)..]);
                bytes
            }
            _ => {
                let mut data = GameControlData::decode(valid).unwrap_or_default();
                data.teams[0].team_number = rng.random_range(30..=60);
                data.teams[1].team_number = rng.random_range(61..=90);
                data.encode().to_vec()
            }
        };
        if GameControlData::decode(&bytes).map_or(true, |d| d.team(team).is_none()) {
            return bytes;
        }
    }
}

/// A datagram for a team port that is no team message: random bytes, some longer than the
/// 128 bytes a team message may have.
fn team_garbage(rng: &mut ChaCha8Rng) -> Vec<u8> {
    loop {
        let bytes = random_bytes(rng, 0..=300);
        if strata_soccer::message::decode(&bytes).is_err() {
            return bytes;
        }
    }
}

fn random_bytes(rng: &mut ChaCha8Rng, length: std::ops::RangeInclusive<usize>) -> Vec<u8> {
    let mut bytes = vec![0u8; rng.random_range(length)];
    rng.fill_bytes(&mut bytes);
    bytes
}

/// A log written to a file that fills up.
#[derive(Clone, Debug, Default, Serialize)]
pub struct LogFull {
    pub robot: Option<RobotKey>,
    /// The file-size limit set on the robot's process, bytes (its log's size then, plus
    /// [`LOG_ROOM`]).
    pub limit_bytes: u64,
    /// Why the limit could not be set, if it could not.
    pub not_injected: Option<String>,
    /// Seconds from the limit until the robot said its log failed.
    pub reported_s: Option<f64>,
    pub note: Option<String>,
    /// Whether it still played (status lines in Playing with reactive cycles) after saying so.
    pub kept_playing: bool,
}

/// Room left in the "nearly full" file: a few of the log's chunks.
pub const LOG_ROOM: u64 = 64 * 1024;

/// Limits the size of the files team 20's goalkeeper may write (RLIMIT_FSIZE, set from
/// outside with `prlimit`, unprivileged for one's own processes) to its log's size plus
/// [`LOG_ROOM`]: the log's next writes fail as on a full disk.
pub(super) fn fill_log(game: &mut Game, phase: Duration) -> Result<(Window, LogFull)> {
    let key = RobotKey { team: TEAMS[1], player: 1 };
    let (pid, log, instance) = {
        let robot = game.robot(key)?;
        (
            robot.process.pid(),
            robot.log.clone().context("that robot writes no log")?,
            robot.instance,
        )
    };
    let size = std::fs::metadata(&log).map_or(0, |m| m.len());
    let limit = size + LOG_ROOM;
    let start = Instant::now();
    let mut figures = LogFull { robot: Some(key), limit_bytes: limit, ..LogFull::default() };
    // Only the soft limit: the hard one stays, as lowering it cannot be undone.
    let set = Command::new("prlimit")
        .args(["--pid", &pid.to_string(), &format!("--fsize={limit}:")])
        .output();
    match set {
        Ok(output) if output.status.success() => {}
        Ok(output) => {
            figures.not_injected =
                Some(format!("prlimit failed: {}", String::from_utf8_lossy(&output.stderr).trim()))
        }
        Err(e) => figures.not_injected = Some(format!("cannot run prlimit (util-linux): {e}")),
    }
    let reported = |g: &Game| {
        g.robot(key).ok().and_then(|r| {
            r.notes
                .iter()
                .find(|(at, i, text)| {
                    *at > start && *i == instance && text.contains("nothing more is logged")
                })
                .cloned()
        })
    };
    if figures.not_injected.is_none() {
        game.wait_until(PATIENCE, |g| reported(g).is_some())?;
    }
    let note = reported(game);
    let end =
        (start + phase).max(note.as_ref().map_or(start, |(at, _, _)| *at) + Duration::from_secs(2));
    game.run_for(end.saturating_duration_since(Instant::now()))?;
    figures.reported_s = note.as_ref().map(|(at, _, _)| secs(start, *at));
    figures.note = note.as_ref().map(|(_, _, text)| text.clone());
    figures.kept_playing = note.is_some_and(|(at, _, _)| {
        game.robot(key).is_ok_and(|r| {
            let after: Vec<_> =
                r.samples.iter().filter(|s| s.at > at && s.instance == instance).collect();
            after.len() >= 2
                && after.iter().all(|s| s.game_state.as_deref() == Some("Playing"))
                && after.first().and_then(|s| s.reactive_cycles)
                    < after.last().and_then(|s| s.reactive_cycles)
        })
    });
    let window = Window {
        name: "log full",
        fault: format!(
            "robot {key}'s log file limited to {} KiB more than it had",
            LOG_ROOM / 1024
        ),
        target: Some(key),
        start,
        end: Instant::now(),
    };
    Ok((window, figures))
}
