//! A robot's links on a real network (docs/architecture.md, Platforms and the edge): the team
//! radio over SPL team-message UDP broadcasts and the GameController over its UDP control and
//! return packets, as the `robot` crate's [`TeamLink`] and [`ExternalLink`].
//!
//! They live here, in the binary's library, because they join two crates that must not know
//! each other: `spl` (wire formats and sockets, no robot) and `robot` (the architecture, no
//! league). The soccer application does not need them either: it sees the same traits whether
//! packets come from these sockets, the simulator server or the in-process simulator.
//!
//! Both links only move bytes: the planning layer decides when to send within the message
//! budget, and the GameController referee decodes and applies control packets. What the links
//! do enforce is what the network itself demands: the 128-byte team-message limit (on sending,
//! and on receiving from a misbehaving robot), and that only well-formed `RGme` packets reach
//! the referee and only well-formed `RGrt` packets leave.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use serde::{Deserialize, Serialize};
use strata_robot::platform::{ExternalLink, LinkError, ReceivedPacket, TeamLink};
use strata_runtime::Time;
use strata_spl::gamecontroller::{GameControlData, ReturnData};
use strata_spl::net::{
    GAMECONTROLLER_DATA_PORT, GAMECONTROLLER_RETURN_PORT, LOOPBACK_BROADCAST,
    MAX_TEAM_MESSAGE_SIZE, NetError, team_port,
};
use strata_spl::{GameControllerSocket, TeamSocket};

mod receiver;

use receiver::{READ_WAIT, Read, Receiver};

/// Packets a link keeps for the robot between two planning cycles, at most (the default of
/// both links; `set_queue_capacity` changes it). Each link's socket is drained by a thread of
/// its own, which drops garbage and other games' packets as they come (`receiver`), so only
/// packets the link cannot tell from real ones fill this queue: at the 10 Hz planning cycle,
/// more than 10,000 of them a second. Beyond it the oldest go (counted as `dropped`).
pub const RECEIVE_QUEUE_CAPACITY: usize = 1024;

/// Counters of one link, shared between the link (inside the planning module's thread) and
/// whoever reports on it.
#[derive(Debug, Default)]
pub struct LinkCounters {
    sent: AtomicU64,
    received: AtomicU64,
    rejected: AtomicU64,
    ignored: AtomicU64,
    errors: AtomicU64,
    dropped: AtomicU64,
    largest_sent: AtomicU64,
    largest_received: AtomicU64,
}

impl LinkCounters {
    fn sent(&self, size: usize) {
        self.sent.fetch_add(1, Ordering::Relaxed);
        self.largest_sent.fetch_max(size as u64, Ordering::Relaxed);
    }

    fn received(&self, size: usize) {
        self.received.fetch_add(1, Ordering::Relaxed);
        self.largest_received.fetch_max(size as u64, Ordering::Relaxed);
    }

    fn rejected(&self) {
        self.rejected.fetch_add(1, Ordering::Relaxed);
    }

    fn ignored(&self) {
        self.ignored.fetch_add(1, Ordering::Relaxed);
    }

    fn error(&self) {
        self.errors.fetch_add(1, Ordering::Relaxed);
    }

    fn dropped(&self) {
        self.dropped.fetch_add(1, Ordering::Relaxed);
    }

    pub fn snapshot(&self) -> LinkStats {
        LinkStats {
            sent: self.sent.load(Ordering::Relaxed),
            received: self.received.load(Ordering::Relaxed),
            rejected: self.rejected.load(Ordering::Relaxed),
            ignored: self.ignored.load(Ordering::Relaxed),
            errors: self.errors.load(Ordering::Relaxed),
            dropped: self.dropped.load(Ordering::Relaxed),
            largest_sent: self.largest_sent.load(Ordering::Relaxed),
            largest_received: self.largest_received.load(Ordering::Relaxed),
        }
    }
}

/// What a link has done so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct LinkStats {
    /// Datagrams sent.
    pub sent: u64,
    /// Datagrams handed to the robot (a team link also hears its own broadcasts).
    pub received: u64,
    /// Datagrams dropped as malformed (a foreign packet on the port, an oversized message).
    pub rejected: u64,
    /// Valid packets that were not for this robot (another game's control packets).
    pub ignored: u64,
    /// Send or receive failures of the socket.
    pub errors: u64,
    /// Packets for the robot dropped unread because more than the link's queue holds arrived
    /// between two planning cycles (the oldest go first).
    #[serde(default)]
    pub dropped: u64,
    /// Size of the largest datagram sent / received, bytes.
    pub largest_sent: u64,
    pub largest_received: u64,
}

/// Where a robot's UDP links bind and send. The defaults are a real SPL field's.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NetConfig {
    /// Team number: the team-message port is 10000 + team unless overridden.
    pub team_number: u8,
    /// Port the GameController's control packets arrive on (3838).
    pub gc_port: u16,
    /// Port the GameController listens for return packets on (3939), at the address its
    /// control packets came from.
    pub gc_return_port: u16,
    /// Port of the team's messages (10000 + team number).
    pub team_port: u16,
    /// Where team messages are broadcast: 255.255.255.255 on a field (or the interface's
    /// directed broadcast address), 127.255.255.255 for several robots on one machine.
    pub broadcast: Ipv4Addr,
}

impl NetConfig {
    /// The standard ports of an SPL field, limited broadcast.
    pub fn field(team_number: u8) -> NetConfig {
        NetConfig {
            team_number,
            gc_port: GAMECONTROLLER_DATA_PORT,
            gc_return_port: GAMECONTROLLER_RETURN_PORT,
            team_port: team_port(team_number),
            broadcast: Ipv4Addr::BROADCAST,
        }
    }

    /// Several robots on this machine: broadcasts to the loopback network.
    pub fn loopback(team_number: u8) -> NetConfig {
        NetConfig { broadcast: LOOPBACK_BROADCAST, ..NetConfig::field(team_number) }
    }

    /// Binds both links.
    pub fn bind(&self) -> Result<(UdpTeamLink, UdpGameControllerLink), NetError> {
        let team = UdpTeamLink::bind(self.team_port, self.broadcast)?;
        let gc = UdpGameControllerLink::bind(self.team_number, self.gc_port, self.gc_return_port)?;
        Ok((team, gc))
    }
}

/// The directed broadcast address of an interface given as `ADDRESS/PREFIX`
/// (`10.0.18.15/16` gives `10.0.255.255`): a limited broadcast (255.255.255.255) leaves only
/// through the interface of the default route, which on a robot with wired and wireless
/// interfaces may be the wrong one.
pub fn directed_broadcast(interface: &str) -> Result<Ipv4Addr, String> {
    let (address, prefix) = interface.split_once('/').ok_or_else(|| {
        format!("interface `{interface}`: expected ADDRESS/PREFIX, e.g. 10.0.18.15/16")
    })?;
    let address: Ipv4Addr = address
        .trim()
        .parse()
        .map_err(|e| format!("interface `{interface}`: `{address}` is not an IPv4 address: {e}"))?;
    let prefix: u32 = prefix
        .trim()
        .parse()
        .ok()
        .filter(|p| *p <= 32)
        .ok_or_else(|| format!("interface `{interface}`: prefix must be 0 to 32"))?;
    // A /32 has no host bits (a shift by 32 would overflow).
    let host_mask = u32::MAX.checked_shr(prefix).unwrap_or(0);
    Ok(Ipv4Addr::from(u32::from(address) | host_mask))
}

/// The team radio over SPL team-message broadcasts.
#[derive(Debug)]
pub struct UdpTeamLink {
    socket: Arc<TeamSocket>,
    receiver: Receiver<Vec<u8>>,
    counters: Arc<LinkCounters>,
}

impl UdpTeamLink {
    /// Binds 0.0.0.0:`port` (shared with every robot of this machine on the port) and
    /// broadcasts to `broadcast`:`port`.
    pub fn bind(port: u16, broadcast: Ipv4Addr) -> Result<UdpTeamLink, NetError> {
        let any = SocketAddr::new(IpAddr::V4(Ipv4Addr::UNSPECIFIED), port);
        let socket = TeamSocket::bind(any, vec![SocketAddr::new(IpAddr::V4(broadcast), port)])?;
        socket.set_wait(Some(READ_WAIT)).map_err(NetError::Receive)?;
        let socket = Arc::new(socket);
        let counters = Arc::<LinkCounters>::default();
        let reading = Arc::clone(&socket);
        let receiver = Receiver::spawn(
            format!("team-link-{port}"),
            RECEIVE_QUEUE_CAPACITY,
            Arc::clone(&counters),
            move || match reading.receive() {
                Ok(Some(received)) => Read::Packet(received.data),
                Ok(None) => Read::Nothing,
                // Another robot's oversized message costs that message only.
                Err(NetError::TooLarge { size, from }) => {
                    tracing::debug!(size, ?from, "oversized team message dropped");
                    Read::Rejected
                }
                Err(error) => Read::Failed(error.to_string()),
            },
        )
        .map_err(NetError::Receive)?;
        Ok(UdpTeamLink { socket, receiver, counters })
    }

    /// Messages kept between two receives at most ([`RECEIVE_QUEUE_CAPACITY`] by default).
    pub fn queue_capacity(&self) -> usize {
        self.receiver.capacity()
    }

    /// Sets how many messages are kept between two receives at most (at least one).
    pub fn set_queue_capacity(&mut self, capacity: usize) {
        self.receiver.set_capacity(capacity);
    }

    pub fn counters(&self) -> Arc<LinkCounters> {
        Arc::clone(&self.counters)
    }

    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.socket.local_addr().ok()
    }

    pub fn destinations(&self) -> &[SocketAddr] {
        self.socket.destinations()
    }
}

impl TeamLink for UdpTeamLink {
    fn send(&mut self, _now: Time, payload: &[u8]) -> Result<(), LinkError> {
        // Checked here as well as in the socket, so the planning layer gets the typed error.
        if payload.len() > MAX_TEAM_MESSAGE_SIZE {
            self.counters.error();
            return Err(LinkError::TooLarge { size: payload.len(), limit: MAX_TEAM_MESSAGE_SIZE });
        }
        match self.socket.send(payload) {
            Ok(()) => {
                self.counters.sent(payload.len());
                Ok(())
            }
            Err(error) => {
                self.counters.error();
                Err(LinkError::Io(error.to_string()))
            }
        }
    }

    fn receive(&mut self, now: Time) -> Result<Vec<ReceivedPacket>, LinkError> {
        let messages = self.receiver.take().map_err(LinkError::Io)?;
        Ok(messages
            .into_iter()
            .map(|bytes| {
                self.counters.received(bytes.len());
                ReceivedPacket { received: now, bytes }
            })
            .collect())
    }
}

/// The GameController over UDP: control packets in, return packets out to the address the
/// control packets come from.
#[derive(Debug)]
pub struct UdpGameControllerLink {
    socket: Arc<GameControllerSocket>,
    /// The canonical encoding of each control packet for this team, and its sender.
    receiver: Receiver<(Vec<u8>, IpAddr)>,
    return_port: u16,
    /// The GameController's address, learned from the newest valid control packet (a field
    /// may switch to a backup GameController during a game).
    game_controller: Option<IpAddr>,
    counters: Arc<LinkCounters>,
}

impl UdpGameControllerLink {
    /// Binds 0.0.0.0:`port` (shared with every robot of this machine on the port) for the
    /// robot of team `team_number`; return packets go to the GameController's `return_port`.
    pub fn bind(
        team_number: u8,
        port: u16,
        return_port: u16,
    ) -> Result<UdpGameControllerLink, NetError> {
        let socket =
            GameControllerSocket::bind(SocketAddr::new(IpAddr::V4(Ipv4Addr::UNSPECIFIED), port))?;
        socket.set_wait(Some(READ_WAIT)).map_err(NetError::Receive)?;
        let socket = Arc::new(socket);
        let counters = Arc::<LinkCounters>::default();
        let reading = Arc::clone(&socket);
        let receiver = Receiver::spawn(
            format!("gc-link-{port}"),
            RECEIVE_QUEUE_CAPACITY,
            Arc::clone(&counters),
            move || match reading.receive() {
                // Another field's GameController on a shared network: neither its game nor
                // its address are ours.
                Ok(Some(received)) if received.data.team(team_number).is_none() => Read::Ignored,
                // The socket validated the packet; its canonical encoding is what the referee
                // decodes (the same bytes, for a valid packet).
                Ok(Some(received)) => {
                    Read::Packet((received.data.encode().to_vec(), received.from.ip()))
                }
                Ok(None) => Read::Nothing,
                // Anything else on the port (another version's packets, garbage) is skipped:
                // the robot keeps the game state it has.
                Err(NetError::Decode { from, source }) => {
                    tracing::debug!(%from, %source, "datagram on the GameController port dropped");
                    Read::Rejected
                }
                Err(error) => Read::Failed(error.to_string()),
            },
        )
        .map_err(NetError::Receive)?;
        Ok(UdpGameControllerLink { socket, receiver, return_port, game_controller: None, counters })
    }

    /// Control packets kept between two receives at most ([`RECEIVE_QUEUE_CAPACITY`] by
    /// default).
    pub fn queue_capacity(&self) -> usize {
        self.receiver.capacity()
    }

    /// Sets how many control packets are kept between two receives at most (at least one).
    pub fn set_queue_capacity(&mut self, capacity: usize) {
        self.receiver.set_capacity(capacity);
    }

    pub fn counters(&self) -> Arc<LinkCounters> {
        Arc::clone(&self.counters)
    }

    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.socket.local_addr().ok()
    }

    /// The GameController heard last, if any.
    pub fn game_controller(&self) -> Option<IpAddr> {
        self.game_controller
    }
}

impl ExternalLink for UdpGameControllerLink {
    fn receive(&mut self, now: Time) -> Result<Vec<ReceivedPacket>, LinkError> {
        let packets = self.receiver.take().map_err(LinkError::Io)?;
        Ok(packets
            .into_iter()
            .map(|(bytes, from)| {
                self.game_controller = Some(from);
                self.counters.received(bytes.len());
                ReceivedPacket { received: now, bytes }
            })
            .collect())
    }

    fn send(&mut self, _now: Time, payload: &[u8]) -> Result<(), LinkError> {
        let Some(game_controller) = self.game_controller else {
            return Err(LinkError::Closed(
                "no GameController heard yet: its address is unknown".to_owned(),
            ));
        };
        // Decoding checks that the referee's bytes are a valid return packet before they go
        // onto the field's network.
        let data = ReturnData::decode(payload).map_err(|e| {
            self.counters.error();
            LinkError::Io(format!("not a valid return packet: {e}"))
        })?;
        let to = SocketAddr::new(game_controller, self.return_port);
        match self.socket.send_return_to(&data, to) {
            Ok(()) => {
                self.counters.sent(payload.len());
                Ok(())
            }
            Err(error) => {
                self.counters.error();
                Err(LinkError::Io(error.to_string()))
            }
        }
    }
}

/// Any link, counted the way the UDP links count themselves (for the simulator's links, so a
/// robot reports its traffic the same way whatever carries it).
pub struct Counted<L> {
    inner: L,
    counters: Arc<LinkCounters>,
}

impl<L> std::fmt::Debug for Counted<L> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Counted").field("counters", &self.counters.snapshot()).finish()
    }
}

impl<L> Counted<L> {
    pub fn new(inner: L, counters: Arc<LinkCounters>) -> Counted<L> {
        Counted { inner, counters }
    }

    fn count_send(&self, size: usize, result: &Result<(), LinkError>) {
        match result {
            Ok(()) => self.counters.sent(size),
            Err(_) => self.counters.error(),
        }
    }

    fn count_receive(&self, result: &Result<Vec<ReceivedPacket>, LinkError>) {
        match result {
            Ok(packets) => packets.iter().for_each(|p| self.counters.received(p.bytes.len())),
            Err(_) => self.counters.error(),
        }
    }
}

impl<L: TeamLink> TeamLink for Counted<L> {
    fn send(&mut self, now: Time, payload: &[u8]) -> Result<(), LinkError> {
        let result = self.inner.send(now, payload);
        self.count_send(payload.len(), &result);
        result
    }

    fn receive(&mut self, now: Time) -> Result<Vec<ReceivedPacket>, LinkError> {
        let result = self.inner.receive(now);
        self.count_receive(&result);
        result
    }
}

impl<L: ExternalLink> ExternalLink for Counted<L> {
    fn receive(&mut self, now: Time) -> Result<Vec<ReceivedPacket>, LinkError> {
        let result = self.inner.receive(now);
        self.count_receive(&result);
        result
    }

    fn send(&mut self, now: Time, payload: &[u8]) -> Result<(), LinkError> {
        let result = self.inner.send(now, payload);
        self.count_send(payload.len(), &result);
        result
    }
}

/// Packets read from a link before the robot started (to learn the game from the first
/// control packet), handed to the robot first.
pub struct Prefetched {
    pending: Vec<ReceivedPacket>,
    inner: Box<dyn ExternalLink>,
}

impl std::fmt::Debug for Prefetched {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Prefetched").field("pending", &self.pending.len()).finish_non_exhaustive()
    }
}

impl Prefetched {
    pub fn new(pending: Vec<ReceivedPacket>, inner: Box<dyn ExternalLink>) -> Prefetched {
        Prefetched { pending, inner }
    }
}

impl ExternalLink for Prefetched {
    fn receive(&mut self, now: Time) -> Result<Vec<ReceivedPacket>, LinkError> {
        // Stamped when handed to the robot: they were read on another clock.
        let mut packets: Vec<ReceivedPacket> = std::mem::take(&mut self.pending)
            .into_iter()
            .map(|p| ReceivedPacket { received: now, bytes: p.bytes })
            .collect();
        match self.inner.receive(now) {
            Ok(more) => packets.extend(more),
            Err(error) if packets.is_empty() => return Err(error),
            Err(_) => {}
        }
        Ok(packets)
    }

    fn send(&mut self, now: Time, payload: &[u8]) -> Result<(), LinkError> {
        self.inner.send(now, payload)
    }
}

/// Which way a team attacks in the field frame, from a control packet: the team listed first
/// attacks the field's +x in the first half and -x in the second (the simulator's convention;
/// on a real SPL field, whose two halves look the same, this only names the field frame of
/// logs and views: the robot itself works in its team frame, own goal at -x). `None` when the
/// packet is not for this team.
pub fn attack_sign(data: &GameControlData, team_number: u8) -> Option<f64> {
    let index = data.teams.iter().position(|t| t.team_number == team_number)?;
    let first_listed = index == 0;
    Some(if first_listed == data.first_half { 1.0 } else { -1.0 })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{Duration, Instant};
    use strata_spl::gamecontroller::{GameState, RETURN_PACKET_SIZE};

    fn now() -> Time {
        Time::from_nanos(1)
    }

    /// Polls until `f` gives something; the deadline only bounds a failing test.
    fn until<T>(what: &str, mut f: impl FnMut() -> Option<T>) -> Result<T, String> {
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            if let Some(value) = f() {
                return Ok(value);
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        Err(format!("gave up waiting for {what}"))
    }

    /// A port nobody on this machine uses right now (the OS picks it).
    fn free_udp_port() -> Result<u16, String> {
        let socket =
            std::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).map_err(|e| e.to_string())?;
        socket.local_addr().map(|a| a.port()).map_err(|e| e.to_string())
    }

    #[test]
    fn directed_broadcast_addresses() {
        assert_eq!(directed_broadcast("10.0.18.15/16"), Ok(Ipv4Addr::new(10, 0, 255, 255)));
        assert_eq!(directed_broadcast("192.168.1.7/24"), Ok(Ipv4Addr::new(192, 168, 1, 255)));
        assert_eq!(directed_broadcast("10.1.2.3/32"), Ok(Ipv4Addr::new(10, 1, 2, 3)));
        assert_eq!(directed_broadcast("10.1.2.3/0"), Ok(Ipv4Addr::BROADCAST));
        assert!(directed_broadcast("10.0.18.15").is_err_and(|e| e.contains("ADDRESS/PREFIX")));
        assert!(directed_broadcast("10.0.18/16").is_err_and(|e| e.contains("not an IPv4")));
        assert!(directed_broadcast("10.0.18.15/33").is_err_and(|e| e.contains("prefix")));
    }

    #[test]
    fn attack_direction_follows_team_order_and_half() {
        let mut data = GameControlData::default();
        data.teams[0].team_number = 5;
        data.teams[1].team_number = 9;
        data.first_half = true;
        assert_eq!(attack_sign(&data, 5), Some(1.0));
        assert_eq!(attack_sign(&data, 9), Some(-1.0));
        data.first_half = false;
        assert_eq!(attack_sign(&data, 5), Some(-1.0));
        assert_eq!(attack_sign(&data, 9), Some(1.0));
        assert_eq!(attack_sign(&data, 7), None);
    }

    #[test]
    fn team_messages_over_loopback_broadcast_within_the_limit() -> Result<(), String> {
        let port = free_udp_port()?;
        let mut a = UdpTeamLink::bind(port, LOOPBACK_BROADCAST).map_err(|e| e.to_string())?;
        let mut b = UdpTeamLink::bind(port, LOOPBACK_BROADCAST).map_err(|e| e.to_string())?;
        match a.send(now(), &[3; MAX_TEAM_MESSAGE_SIZE]) {
            Err(LinkError::Io(e)) if e.contains("ermission") => {
                eprintln!("note: this sandbox forbids UDP broadcast; skipping ({e})");
                return Ok(());
            }
            other => other.map_err(|e| e.to_string())?,
        }
        // Both robots hear it (the sender too: the payload says who sent it).
        for link in [&mut b, &mut a] {
            let packets =
                until("the team message", || link.receive(now()).ok().filter(|p| !p.is_empty()))?;
            assert_eq!(packets[0].bytes, vec![3; MAX_TEAM_MESSAGE_SIZE]);
        }
        assert_eq!(
            a.send(now(), &[3; MAX_TEAM_MESSAGE_SIZE + 1]),
            Err(LinkError::TooLarge { size: 129, limit: 128 })
        );
        let stats = a.counters().snapshot();
        assert_eq!((stats.sent, stats.largest_sent, stats.errors), (1, 128, 1));

        // Someone else's oversized datagram is dropped and counted, not handed over.
        let raw = std::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).map_err(|e| e.to_string())?;
        raw.send_to(&[1; 300], (Ipv4Addr::LOCALHOST, port)).map_err(|e| e.to_string())?;
        raw.send_to(b"ok", (Ipv4Addr::LOCALHOST, port)).map_err(|e| e.to_string())?;
        // A unicast datagram reaches one of the sockets sharing the port.
        let mut got = Vec::new();
        until("the small datagram", || {
            for link in [&mut a, &mut b] {
                got.extend(link.receive(now()).unwrap_or_default());
            }
            got.iter().any(|p| p.bytes == b"ok").then_some(())
        })?;
        assert!(got.iter().all(|p| p.bytes.len() <= MAX_TEAM_MESSAGE_SIZE));
        until("the rejection to be counted", || {
            let rejected = a.counters().snapshot().rejected + b.counters().snapshot().rejected;
            (rejected == 1).then_some(())
        })
    }

    #[test]
    fn control_packets_in_return_packets_back_to_their_sender() -> Result<(), String> {
        let port = free_udp_port()?;
        let mut robot = UdpGameControllerLink::bind(7, port, 0).map_err(|e| e.to_string())?;
        // The GameController: sends from the port it receives return packets on.
        let gc = std::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).map_err(|e| e.to_string())?;
        let gc_addr = gc.local_addr().map_err(|e| e.to_string())?;
        robot.return_port = gc_addr.port();

        let reply = ReturnData {
            player_number: 2,
            team_number: 7,
            fallen: false,
            pose: [1.0, 2.0, 0.5],
            ball_age: ReturnData::BALL_NEVER_SEEN,
            ball: [0.0, 0.0],
        };
        let bytes = reply.encode().map_err(|e| e.to_string())?;
        assert!(
            matches!(robot.send(now(), &bytes), Err(LinkError::Closed(_))),
            "no GameController heard yet"
        );

        gc.send_to(b"RGme, but not really", (Ipv4Addr::LOCALHOST, port))
            .map_err(|e| e.to_string())?;
        // Another game's packet (teams 0 and 0), then ours.
        let other = GameControlData { state: GameState::Set, ..Default::default() };
        gc.send_to(&other.encode(), (Ipv4Addr::LOCALHOST, port)).map_err(|e| e.to_string())?;
        let mut data =
            GameControlData { state: GameState::Ready, packet_number: 4, ..Default::default() };
        data.teams[1].team_number = 7;
        gc.send_to(&data.encode(), (Ipv4Addr::LOCALHOST, port)).map_err(|e| e.to_string())?;
        let packets =
            until("the control packet", || robot.receive(now()).ok().filter(|p| !p.is_empty()))?;
        assert_eq!(packets.len(), 1, "the garbage and the other game were dropped");
        assert_eq!(GameControlData::decode(&packets[0].bytes), Ok(data));
        assert_eq!(robot.game_controller(), Some(gc_addr.ip()));
        let stats = robot.counters().snapshot();
        assert_eq!((stats.rejected, stats.ignored, stats.received), (1, 1, 1));

        robot.send(now(), &bytes).map_err(|e| e.to_string())?;
        let mut buffer = [0u8; 64];
        gc.set_read_timeout(Some(Duration::from_secs(10))).map_err(|e| e.to_string())?;
        let (size, _) = gc.recv_from(&mut buffer).map_err(|e| e.to_string())?;
        assert_eq!(size, RETURN_PACKET_SIZE);
        assert_eq!(ReturnData::decode(&buffer[..size]), Ok(reply));
        assert!(matches!(robot.send(now(), b"RGrt nonsense"), Err(LinkError::Io(_))));
        Ok(())
    }

    /// A control packet with values the robot does not know in fields it does not
    /// act on reaches the robot as sent; one it cannot follow (an unknown state) is dropped and
    /// counted, and the link goes on listening.
    #[test]
    fn unknown_values_pass_and_a_rejected_packet_does_not_stop_the_link() -> Result<(), String> {
        let port = free_udp_port()?;
        let mut robot = UdpGameControllerLink::bind(7, port, 0).map_err(|e| e.to_string())?;
        let gc = std::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).map_err(|e| e.to_string())?;
        let send = |bytes: &[u8]| {
            gc.send_to(bytes, (Ipv4Addr::LOCALHOST, port)).map(drop).map_err(|e| e.to_string())
        };
        let mut data =
            GameControlData { state: GameState::Playing, packet_number: 1, ..Default::default() };
        data.teams[0].team_number = 7;
        data.teams[1].team_number = 9;
        let mut newer = data.encode();
        newer[8] = 9; // competition type
        newer[11] = 6; // set play
        newer[18 + 10 + 2 * 4] = 12; // a team mate's penalty
        newer[18 + 50 + 10] = 13; // an opponent's penalty
        send(&newer)?;
        let packets =
            until("the control packet", || robot.receive(now()).ok().filter(|p| !p.is_empty()))?;
        let bytes: Vec<&[u8]> = packets.iter().map(|p| p.bytes.as_slice()).collect();
        assert_eq!(bytes, [newer.as_slice()], "handed over as sent");

        // A state the robot does not know: dropped and counted, nothing handed over...
        let mut unknown_state = data.encode();
        unknown_state[10] = 6;
        send(&unknown_state)?;
        let mut handed = Vec::new();
        until("the rejection", || {
            handed.extend(robot.receive(now()).unwrap_or_default());
            (robot.counters().snapshot().rejected == 1).then_some(())
        })?;
        assert_eq!(handed, Vec::new());
        // ...and the next packet is heard.
        let ready = GameControlData { state: GameState::Ready, packet_number: 3, ..data };
        send(&ready.encode())?;
        let packets =
            until("the next packet", || robot.receive(now()).ok().filter(|p| !p.is_empty()))?;
        assert_eq!(packets.len(), 1);
        assert_eq!(GameControlData::decode(&packets[0].bytes), Ok(ready));
        let stats = robot.counters().snapshot();
        assert_eq!((stats.received, stats.rejected, stats.errors), (2, 1, 0));
        Ok(())
    }

    /// Sends `count` datagrams of `payload` to `port` on loopback, in steps the link's thread
    /// keeps up with (`read` counts what it has read), so the kernel drops none.
    fn flood(port: u16, payload: &[u8], count: u64, read: impl Fn() -> u64) -> Result<(), String> {
        let raw = std::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).map_err(|e| e.to_string())?;
        let start = read();
        for sent in 1..=count {
            raw.send_to(payload, (Ipv4Addr::LOCALHOST, port)).map_err(|e| e.to_string())?;
            if sent % 64 == 0 || sent == count {
                until("the link to read the flood", || (read() >= start + sent).then_some(()))?;
            }
        }
        Ok(())
    }

    /// The robot does not read between its planning cycles: thousands of datagrams that are
    /// no packet of its game arriving meanwhile must not cost it one that is.
    #[test]
    fn a_flood_of_garbage_between_two_receives_costs_no_control_packet() -> Result<(), String> {
        let port = free_udp_port()?;
        let mut robot = UdpGameControllerLink::bind(7, port, 0).map_err(|e| e.to_string())?;
        assert_eq!(robot.queue_capacity(), RECEIVE_QUEUE_CAPACITY);
        let counters = robot.counters();
        let read = || {
            let stats = counters.snapshot();
            stats.rejected + stats.ignored
        };
        let gc = std::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).map_err(|e| e.to_string())?;
        let mut ours = GameControlData { state: GameState::Playing, ..Default::default() };
        ours.teams[0].team_number = 7;
        for round in 0..5u8 {
            // Garbage and another game's valid packets, then one of ours.
            flood(port, b"RGme, but not really", 400, read)?;
            flood(port, &GameControlData::default().encode(), 400, read)?;
            ours.packet_number = round;
            gc.send_to(&ours.encode(), (Ipv4Addr::LOCALHOST, port)).map_err(|e| e.to_string())?;
        }
        let mut packets = Vec::new();
        until("our five control packets", || {
            packets.extend(robot.receive(now()).unwrap_or_default());
            (packets.len() >= 5).then_some(())
        })?;
        let numbers: Vec<u8> = packets
            .iter()
            .filter_map(|p| GameControlData::decode(&p.bytes).ok())
            .map(|d| d.packet_number)
            .collect();
        assert_eq!(numbers, [0, 1, 2, 3, 4]);
        let stats = robot.counters().snapshot();
        assert_eq!(
            (stats.rejected, stats.ignored, stats.received, stats.dropped),
            (2000, 2000, 5, 0)
        );
        Ok(())
    }

    /// Only messages the link cannot tell from real ones fill its queue; past its capacity the
    /// oldest go, counted, and the newest are handed over.
    #[test]
    fn a_full_team_queue_keeps_the_newest_messages() -> Result<(), String> {
        let port = free_udp_port()?;
        let mut link = UdpTeamLink::bind(port, LOOPBACK_BROADCAST).map_err(|e| e.to_string())?;
        assert_eq!(link.queue_capacity(), RECEIVE_QUEUE_CAPACITY);
        link.set_queue_capacity(4);
        let counters = link.counters();
        let read = || {
            let stats = counters.snapshot();
            stats.rejected + stats.dropped
        };
        flood(port, &[7; MAX_TEAM_MESSAGE_SIZE + 1], 500, read)?;
        let raw = std::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).map_err(|e| e.to_string())?;
        for n in 0..10u8 {
            raw.send_to(&[n], (Ipv4Addr::LOCALHOST, port)).map_err(|e| e.to_string())?;
        }
        until("six messages dropped", || (counters.snapshot().dropped == 6).then_some(()))?;
        let packets = link.receive(now()).map_err(|e| e.to_string())?;
        let bytes: Vec<&[u8]> = packets.iter().map(|p| p.bytes.as_slice()).collect();
        assert_eq!(bytes, [[6u8].as_slice(), &[7], &[8], &[9]]);
        let stats = link.counters().snapshot();
        assert_eq!((stats.rejected, stats.dropped, stats.received), (500, 6, 4));
        Ok(())
    }

    #[test]
    fn prefetched_packets_come_first() -> Result<(), String> {
        #[derive(Debug)]
        struct Silent;
        impl ExternalLink for Silent {
            fn receive(&mut self, _now: Time) -> Result<Vec<ReceivedPacket>, LinkError> {
                Err(LinkError::Closed("gone".into()))
            }
            fn send(&mut self, _now: Time, _payload: &[u8]) -> Result<(), LinkError> {
                Ok(())
            }
        }
        let first = ReceivedPacket { received: now(), bytes: vec![1] };
        let mut link = Prefetched::new(vec![first.clone()], Box::new(Silent));
        assert_eq!(link.receive(now()), Ok(vec![first]));
        assert!(link.receive(now()).is_err());
        Ok(())
    }
}
