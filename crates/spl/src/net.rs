//! UDP transport of an SPL robot: GameController packets and team messages.
//!
//! Ports: the GameController broadcasts control packets to UDP 3838; robots send return
//! packets to the GameController's address on UDP 3939; a team's robots broadcast team
//! messages to UDP 10000 + team number.
//!
//! Several robots on one machine (simulation, tests): every socket here sets SO_REUSEADDR and
//! SO_REUSEPORT, so all robots can bind 0.0.0.0 on the same port. The kernel then hands a
//! *broadcast* datagram to every one of them, but a unicast datagram to only one, so on a
//! single machine send to the loopback broadcast address [`LOOPBACK_BROADCAST`]
//! (127.255.255.255), e.g. with [`TeamSocket::loopback`]. Robots also receive their own
//! broadcasts; team-message payloads carry the player number to tell them apart.

use std::io;
use std::net::{IpAddr, Ipv4Addr, SocketAddr, UdpSocket};
use std::time::Duration;

use socket2::{Domain, Protocol, Socket, Type};
use thiserror::Error;

use crate::gamecontroller::{DecodeError, GameControlData, ReturnData};

/// The port control packets are broadcast to.
pub const GAMECONTROLLER_DATA_PORT: u16 = 3838;
/// The GameController's port for return packets.
pub const GAMECONTROLLER_RETURN_PORT: u16 = 3939;
/// Team messages go to this port plus the team number.
pub const TEAM_PORT_BASE: u16 = 10000;
/// The largest team message the rules allow (bytes of UDP payload).
pub const MAX_TEAM_MESSAGE_SIZE: usize = 128;
/// Reaches every socket bound to the port on this machine.
pub const LOOPBACK_BROADCAST: Ipv4Addr = Ipv4Addr::new(127, 255, 255, 255);

// Larger than any valid packet, so oversized datagrams are seen as such rather than truncated.
const RECEIVE_BUFFER: usize = 2048;

/// The team-message port of a team.
pub const fn team_port(team_number: u8) -> u16 {
    TEAM_PORT_BASE + team_number as u16
}

/// A network failure, or a datagram that is not what the port carries.
#[derive(Debug, Error)]
pub enum NetError {
    #[error("cannot bind UDP {addr}: {source}")]
    Bind {
        addr: SocketAddr,
        #[source]
        source: io::Error,
    },
    #[error("UDP receive failed: {0}")]
    Receive(#[source] io::Error),
    #[error("UDP send to {to} failed: {source}")]
    Send {
        to: SocketAddr,
        #[source]
        source: io::Error,
    },
    #[error("datagram from {from}: {source}")]
    Decode {
        from: SocketAddr,
        #[source]
        source: DecodeError,
    },
    #[error("refusing to send an invalid packet: {0}")]
    Refused(#[source] DecodeError),
    #[error("team message of {size} bytes exceeds the {MAX_TEAM_MESSAGE_SIZE}-byte limit{}",
        from.map(|a| format!(" (from {a})")).unwrap_or_default())]
    TooLarge { size: usize, from: Option<SocketAddr> },
}

/// A datagram's content and sender.
#[derive(Clone, Debug, PartialEq)]
pub struct Received<T> {
    pub data: T,
    pub from: SocketAddr,
}

/// A blocking UDP socket bound with SO_REUSEADDR, SO_REUSEPORT (Unix) and SO_BROADCAST, so
/// that several processes can share the port and send broadcasts.
pub fn bind_shared(addr: SocketAddr) -> Result<UdpSocket, NetError> {
    let bind = || -> io::Result<UdpSocket> {
        let socket = Socket::new(Domain::for_address(addr), Type::DGRAM, Some(Protocol::UDP))?;
        socket.set_reuse_address(true)?;
        #[cfg(unix)]
        socket.set_reuse_port(true)?;
        socket.set_broadcast(true)?;
        socket.bind(&addr.into())?;
        Ok(socket.into())
    };
    bind().map_err(|source| NetError::Bind { addr, source })
}

fn bind_nonblocking(addr: SocketAddr) -> Result<UdpSocket, NetError> {
    let socket = bind_shared(addr)?;
    socket.set_nonblocking(true).map_err(|source| NetError::Bind { addr, source })?;
    Ok(socket)
}

/// Receives one datagram, waiting as the socket is set to: `None` when none came.
fn receive_raw(socket: &UdpSocket) -> Result<Option<(Vec<u8>, SocketAddr)>, NetError> {
    let mut buffer = [0u8; RECEIVE_BUFFER];
    match socket.recv_from(&mut buffer) {
        Ok((size, from)) => Ok(Some((buffer[..size].to_vec(), from))),
        // A read timeout shows as either, depending on the platform.
        Err(e) if matches!(e.kind(), io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut) => {
            Ok(None)
        }
        Err(e) => Err(NetError::Receive(e)),
    }
}

/// `None`: calls return at once (the sockets' default). `Some(wait)`: a receive waits up to
/// `wait` for a datagram and a send up to `wait` for room, for a thread of its own that
/// drains the socket without spinning.
fn set_wait(socket: &UdpSocket, wait: Option<Duration>) -> io::Result<()> {
    match wait {
        None => socket.set_nonblocking(true),
        Some(wait) => {
            // A zero timeout would mean "wait forever" to the OS.
            let wait = wait.max(Duration::from_millis(1));
            socket.set_read_timeout(Some(wait))?;
            socket.set_write_timeout(Some(wait))?;
            socket.set_nonblocking(false)
        }
    }
}

/// A robot's link to the GameController: receives control packets, sends return packets.
#[derive(Debug)]
pub struct GameControllerSocket {
    socket: UdpSocket,
}

impl GameControllerSocket {
    /// Binds 0.0.0.0:3838.
    pub fn bind_default() -> Result<GameControllerSocket, NetError> {
        let any = SocketAddr::new(IpAddr::V4(Ipv4Addr::UNSPECIFIED), GAMECONTROLLER_DATA_PORT);
        GameControllerSocket::bind(any)
    }

    /// Binds a non-blocking, shareable socket (tests bind port 0).
    pub fn bind(addr: SocketAddr) -> Result<GameControllerSocket, NetError> {
        Ok(GameControllerSocket { socket: bind_nonblocking(addr)? })
    }

    /// The bound address (the actual port when bound to 0).
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.socket.local_addr()
    }

    /// How long `receive` and sends wait (see [`TeamSocket::set_wait`]).
    pub fn set_wait(&self, wait: Option<Duration>) -> io::Result<()> {
        set_wait(&self.socket, wait)
    }

    /// One control packet, if one is waiting. Call until `Ok(None)` to drain the queue; a
    /// datagram that is not a valid control packet is an error naming its sender.
    pub fn receive(&self) -> Result<Option<Received<GameControlData>>, NetError> {
        let Some((bytes, from)) = receive_raw(&self.socket)? else { return Ok(None) };
        let data =
            GameControlData::decode(&bytes).map_err(|source| NetError::Decode { from, source })?;
        Ok(Some(Received { data, from }))
    }

    /// Sends a return packet to the GameController at `game_controller` (port 3939).
    pub fn send_return(&self, data: &ReturnData, game_controller: IpAddr) -> Result<(), NetError> {
        self.send_return_to(data, SocketAddr::new(game_controller, GAMECONTROLLER_RETURN_PORT))
    }

    /// Sends a return packet to an explicit address; invalid data is refused unsent.
    pub fn send_return_to(&self, data: &ReturnData, to: SocketAddr) -> Result<(), NetError> {
        let bytes = data.encode().map_err(NetError::Refused)?;
        self.socket.send_to(&bytes, to).map_err(|source| NetError::Send { to, source })?;
        Ok(())
    }
}

/// Team messages: broadcast sends, non-blocking receives, the 128-byte limit.
#[derive(Debug)]
pub struct TeamSocket {
    socket: UdpSocket,
    destinations: Vec<SocketAddr>,
}

impl TeamSocket {
    /// On a real field: binds 0.0.0.0:(10000 + team) and broadcasts to 255.255.255.255.
    pub fn for_team(team_number: u8) -> Result<TeamSocket, NetError> {
        let port = team_port(team_number);
        TeamSocket::bind(any_port(port), vec![SocketAddr::new(Ipv4Addr::BROADCAST.into(), port)])
    }

    /// On one machine: binds 0.0.0.0:port and broadcasts to 127.255.255.255:port, which reaches
    /// every robot bound to the port here.
    pub fn loopback(port: u16) -> Result<TeamSocket, NetError> {
        TeamSocket::bind(any_port(port), vec![SocketAddr::new(LOOPBACK_BROADCAST.into(), port)])
    }

    /// Binds `addr` (shareable, non-blocking) and sends every message to each destination.
    pub fn bind(addr: SocketAddr, destinations: Vec<SocketAddr>) -> Result<TeamSocket, NetError> {
        Ok(TeamSocket { socket: bind_nonblocking(addr)?, destinations })
    }

    /// The bound address (the actual port when bound to 0).
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.socket.local_addr()
    }

    /// Where `send` sends.
    pub fn destinations(&self) -> &[SocketAddr] {
        &self.destinations
    }

    /// How long `receive` and `send` wait: `None` (the default) returns at once; `Some(wait)`
    /// waits up to `wait`, for a thread of its own that drains the socket without spinning.
    pub fn set_wait(&self, wait: Option<Duration>) -> io::Result<()> {
        set_wait(&self.socket, wait)
    }

    /// Sends one team message to every destination. The socket does not count messages: the
    /// robot's planning layer keeps within the game's budget (`MessageBudget` in
    /// `strata_robot::control::planning`).
    pub fn send(&self, payload: &[u8]) -> Result<(), NetError> {
        if payload.len() > MAX_TEAM_MESSAGE_SIZE {
            return Err(NetError::TooLarge { size: payload.len(), from: None });
        }
        for &to in &self.destinations {
            self.socket.send_to(payload, to).map_err(|source| NetError::Send { to, source })?;
        }
        Ok(())
    }

    /// One team message, if one is waiting (this robot's own broadcasts included). An
    /// oversized datagram is an error naming its sender.
    pub fn receive(&self) -> Result<Option<Received<Vec<u8>>>, NetError> {
        let Some((data, from)) = receive_raw(&self.socket)? else { return Ok(None) };
        if data.len() > MAX_TEAM_MESSAGE_SIZE {
            return Err(NetError::TooLarge { size: data.len(), from: Some(from) });
        }
        Ok(Some(Received { data, from }))
    }
}

fn any_port(port: u16) -> SocketAddr {
    SocketAddr::new(IpAddr::V4(Ipv4Addr::UNSPECIFIED), port)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gamecontroller::{GameState, RETURN_PACKET_SIZE};
    use std::time::{Duration, Instant};

    /// Polls a non-blocking receive; the deadline only bounds a failing test.
    fn wait<T>(mut receive: impl FnMut() -> Result<Option<T>, NetError>) -> Result<T, String> {
        let deadline = Instant::now() + Duration::from_secs(5);
        while Instant::now() < deadline {
            match receive() {
                Ok(Some(value)) => return Ok(value),
                Ok(None) => std::thread::sleep(Duration::from_millis(2)),
                Err(e) => return Err(e.to_string()),
            }
        }
        Err("nothing received".into())
    }

    fn broadcast_forbidden(e: &NetError) -> bool {
        matches!(e, NetError::Send { source, .. } if source.kind() == io::ErrorKind::PermissionDenied)
    }

    #[test]
    fn ports() {
        assert_eq!(team_port(0), 10000);
        assert_eq!(team_port(12), 10012);
        assert_eq!(team_port(255), 10255);
    }

    #[test]
    fn team_messages_reach_every_robot_on_the_port() -> Result<(), String> {
        let first = TeamSocket::bind(any_port(0), Vec::new()).map_err(|e| e.to_string())?;
        let port = first.local_addr().map_err(|e| e.to_string())?.port();
        let second = TeamSocket::loopback(port).map_err(|e| e.to_string())?;
        let sender = TeamSocket::loopback(port).map_err(|e| e.to_string())?;
        match sender.send(b"striker: ball at 1.2, -0.4") {
            Err(e) if broadcast_forbidden(&e) => {
                eprintln!("note: this sandbox forbids UDP broadcast; skipping ({e})");
                return Ok(());
            }
            other => other.map_err(|e| e.to_string())?,
        }
        for socket in [&first, &second, &sender] {
            let got = wait(|| socket.receive())?;
            assert_eq!(got.data, b"striker: ball at 1.2, -0.4");
        }
        Ok(())
    }

    #[test]
    fn team_message_size_limit() -> Result<(), String> {
        let socket = TeamSocket::bind(any_port(0), Vec::new()).map_err(|e| e.to_string())?;
        let port = socket.local_addr().map_err(|e| e.to_string())?.port();
        let sender =
            TeamSocket::bind(any_port(0), vec![SocketAddr::new(Ipv4Addr::LOCALHOST.into(), port)])
                .map_err(|e| e.to_string())?;
        assert!(sender.send(&[7; MAX_TEAM_MESSAGE_SIZE]).is_ok());
        let error = sender.send(&[7; MAX_TEAM_MESSAGE_SIZE + 1]).map_err(|e| e.to_string());
        assert_eq!(error, Err("team message of 129 bytes exceeds the 128-byte limit".into()));
        assert_eq!(wait(|| socket.receive())?.data.len(), MAX_TEAM_MESSAGE_SIZE);

        // Someone else's oversized datagram is reported, with its sender.
        let raw = UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).map_err(|e| e.to_string())?;
        raw.send_to(&[1; 200], (Ipv4Addr::LOCALHOST, port)).map_err(|e| e.to_string())?;
        let error = wait(|| socket.receive()).err().unwrap_or_default();
        assert!(error.starts_with("team message of 200 bytes exceeds"), "{error}");
        assert!(error.contains("from 127.0.0.1:"), "{error}");
        assert!(socket.receive().is_ok_and(|r| r.is_none()));
        Ok(())
    }

    #[test]
    fn control_and_return_packets_over_loopback() -> Result<(), String> {
        let robot = GameControllerSocket::bind(any_port(0)).map_err(|e| e.to_string())?;
        let port = robot.local_addr().map_err(|e| e.to_string())?.port();
        let gc = UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).map_err(|e| e.to_string())?;
        let gc_addr = gc.local_addr().map_err(|e| e.to_string())?;

        let data =
            GameControlData { state: GameState::Ready, packet_number: 9, ..Default::default() };
        gc.send_to(&data.encode(), (Ipv4Addr::LOCALHOST, port)).map_err(|e| e.to_string())?;
        let got = wait(|| robot.receive())?;
        assert_eq!(got.data, data);
        assert_eq!(got.from, gc_addr);

        gc.send_to(b"RGme garbage", (Ipv4Addr::LOCALHOST, port)).map_err(|e| e.to_string())?;
        let error = wait(|| robot.receive()).err().unwrap_or_default();
        assert_eq!(
            error,
            format!(
                "datagram from {gc_addr}: control packet: wrong length: expected 118 bytes, got 12"
            )
        );

        let reply = ReturnData {
            player_number: 2,
            team_number: 7,
            fallen: false,
            pose: [100.0, 200.0, 0.5],
            ball_age: ReturnData::BALL_NEVER_SEEN,
            ball: [0.0, 0.0],
        };
        robot.send_return_to(&reply, gc_addr).map_err(|e| e.to_string())?;
        let mut buffer = [0u8; 64];
        gc.set_read_timeout(Some(Duration::from_secs(5))).map_err(|e| e.to_string())?;
        let (size, _) = gc.recv_from(&mut buffer).map_err(|e| e.to_string())?;
        assert_eq!(size, RETURN_PACKET_SIZE);
        assert_eq!(ReturnData::decode(&buffer[..size]), Ok(reply));

        let invalid = ReturnData { player_number: 0, ..reply };
        assert!(matches!(robot.send_return_to(&invalid, gc_addr), Err(NetError::Refused(_))));
        Ok(())
    }
}
