//! The building operator's console: the patrol's external device (paper 3.3: the planning layer
//! uses "information coming from other robots and eventually external devices"; in soccer a
//! game controller). The console broadcasts a tiny binary alarm packet; each robot answers
//! with a status packet that carries its pose and its estimates of the points of interest it
//! has inspected.
//!
//! Wire formats, little-endian, positions in centimetres:
//!
//! ```text
//! alarm  (11 bytes): "PA" version=1 flags(bit0: alarm active) id:u16 x:i16 y:i16 seq:u8
//! status (10 + 7n):  "PS" version=1 player:u8 flags(bit0 stable, bit1 localized,
//!                    bit2 intruder sighted) x:i16 y:i16 n:u8 { poi:u8 x:i16 y:i16 sigma_mm:u16 }*n
//! ```

use std::sync::{Arc, Mutex};

use serde::{Deserialize, Serialize};
use strata_robot::control::planning::{OwnState, StandingStatus};
use strata_robot::control::planning_module::ExternalDevice;
use strata_robot::geometry::{Global, Point};
use strata_robot::world::WorldState;
use strata_runtime::Time;

use crate::world_config::{INTRUDER, POINT_OF_INTEREST};

/// An alarm raised by the operator.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Alarm {
    pub id: u16,
    /// Where to go.
    pub point: Point<Global>,
}

/// What the console tells the deliberative layer (the planning layer passes it on).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct OperatorDirective {
    pub alarm: Option<Alarm>,
}

/// Why a console packet was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PacketError {
    #[error("packet of {0} bytes is too short")]
    Truncated(usize),
    #[error("not a console packet (header {0:02x?})")]
    Header([u8; 2]),
    #[error("unsupported version {0}")]
    Version(u8),
    #[error("packet length {found} does not match its contents ({expected} bytes)")]
    Length { expected: usize, found: usize },
}

fn cm(v: f64) -> i16 {
    (v * 100.0).round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}

fn from_cm(bytes: [u8; 2]) -> f64 {
    f64::from(i16::from_le_bytes(bytes)) / 100.0
}

fn check(bytes: &[u8], header: &[u8; 2], min: usize) -> Result<(), PacketError> {
    if bytes.len() < min {
        return Err(PacketError::Truncated(bytes.len()));
    }
    if &bytes[..2] != header {
        return Err(PacketError::Header([bytes[0], bytes[1]]));
    }
    if bytes[2] != 1 {
        return Err(PacketError::Version(bytes[2]));
    }
    Ok(())
}

/// The console's broadcast.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AlarmPacket {
    pub alarm: Option<Alarm>,
    /// Counts broadcasts (wraps).
    pub seq: u8,
}

impl AlarmPacket {
    pub const SIZE: usize = 11;

    pub fn encode(&self) -> Vec<u8> {
        let mut out = vec![b'P', b'A', 1];
        let (flags, id, point) = match self.alarm {
            Some(a) => (1u8, a.id, a.point),
            None => (0, 0, Point::ORIGIN),
        };
        out.push(flags);
        out.extend(id.to_le_bytes());
        out.extend(cm(point.x).to_le_bytes());
        out.extend(cm(point.y).to_le_bytes());
        out.push(self.seq);
        out
    }

    pub fn decode(bytes: &[u8]) -> Result<AlarmPacket, PacketError> {
        check(bytes, b"PA", Self::SIZE)?;
        if bytes.len() != Self::SIZE {
            return Err(PacketError::Length { expected: Self::SIZE, found: bytes.len() });
        }
        let alarm = (bytes[3] & 1 == 1).then(|| Alarm {
            id: u16::from_le_bytes([bytes[4], bytes[5]]),
            point: Point::new(from_cm([bytes[6], bytes[7]]), from_cm([bytes[8], bytes[9]])),
        });
        Ok(AlarmPacket { alarm, seq: bytes[10] })
    }
}

/// A point of interest as a robot reports it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoiReport {
    pub poi: u8,
    pub position: Point<Global>,
    /// Standard deviation of the position (the larger axis), m.
    pub sigma: f64,
}

/// A robot's answer to the console.
#[derive(Clone, Debug, PartialEq)]
pub struct StatusPacket {
    pub player: u8,
    pub stable: bool,
    pub localized: bool,
    pub intruder_sighted: bool,
    pub position: Point<Global>,
    pub reports: Vec<PoiReport>,
}

impl StatusPacket {
    const HEADER: usize = 10;
    const REPORT: usize = 7;
    pub const MAX_REPORTS: usize = 8;

    pub fn encode(&self) -> Vec<u8> {
        let mut out = vec![b'P', b'S', 1, self.player];
        out.push(
            u8::from(self.stable)
                | (u8::from(self.localized) << 1)
                | (u8::from(self.intruder_sighted) << 2),
        );
        out.extend(cm(self.position.x).to_le_bytes());
        out.extend(cm(self.position.y).to_le_bytes());
        let reports = &self.reports[..self.reports.len().min(Self::MAX_REPORTS)];
        out.push(reports.len() as u8);
        for r in reports {
            out.push(r.poi);
            out.extend(cm(r.position.x).to_le_bytes());
            out.extend(cm(r.position.y).to_le_bytes());
            out.extend(((r.sigma * 1000.0).round().clamp(0.0, 65535.0) as u16).to_le_bytes());
        }
        out
    }

    pub fn decode(bytes: &[u8]) -> Result<StatusPacket, PacketError> {
        check(bytes, b"PS", Self::HEADER)?;
        let n = usize::from(bytes[9]);
        let expected = Self::HEADER + n * Self::REPORT;
        if bytes.len() != expected || n > Self::MAX_REPORTS {
            return Err(PacketError::Length { expected, found: bytes.len() });
        }
        let reports = bytes[Self::HEADER..]
            .chunks_exact(Self::REPORT)
            .map(|r| PoiReport {
                poi: r[0],
                position: Point::new(from_cm([r[1], r[2]]), from_cm([r[3], r[4]])),
                sigma: f64::from(u16::from_le_bytes([r[5], r[6]])) / 1000.0,
            })
            .collect();
        Ok(StatusPacket {
            player: bytes[3],
            stable: bytes[4] & 1 != 0,
            localized: bytes[4] & 2 != 0,
            intruder_sighted: bytes[4] & 4 != 0,
            position: Point::new(from_cm([bytes[5], bytes[6]]), from_cm([bytes[7], bytes[8]])),
            reports,
        })
    }
}

/// The alarm as this robot last heard it, shared by the console's referee (which writes it
/// when a packet arrives) and the planning policy (which selects the mission from it). Both
/// live in the one planning module and run in the same cycle, referee first, so sharing keeps
/// the planning layer deterministic. (`PlanningPolicy` is not handed the referee's directive.)
pub type AlarmBoard = Arc<Mutex<Option<Alarm>>>;

/// Reads an alarm board, whatever a panicking writer left (an `Option` is always consistent).
pub fn read_board(board: &AlarmBoard) -> Option<Alarm> {
    *board.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The robot's side of the console.
#[derive(Debug)]
pub struct OperatorConsole {
    player: u8,
    board: AlarmBoard,
    /// Seconds between status packets.
    status_period: f64,
    last_status: Option<Time>,
    /// A point of interest is reported once its field position is known this well, m.
    report_sigma: f64,
}

impl OperatorConsole {
    pub fn new(player: u8, board: AlarmBoard) -> OperatorConsole {
        OperatorConsole { player, board, status_period: 1.0, last_status: None, report_sigma: 0.15 }
    }

    fn reports(&self, world: &WorldState) -> Vec<PoiReport> {
        world
            .objects_of_class(POINT_OF_INTEREST)
            .filter(|o| {
                o.known && o.last_seen.is_some_and(|t| (world.stamp - t).as_secs_f64() < 2.0)
            })
            .filter_map(|o| {
                let sigma = max_sigma(&o.global_covariance);
                (sigma < self.report_sigma && !world.pose.lost).then_some(PoiReport {
                    poi: u8::try_from(o.variant?).ok()?,
                    position: o.global_position,
                    sigma,
                })
            })
            .take(StatusPacket::MAX_REPORTS)
            .collect()
    }
}

/// Standard deviation along the larger axis of a 2x2 covariance.
pub fn max_sigma(c: &nalgebra::Matrix2<f64>) -> f64 {
    let half_trace = 0.5 * (c[(0, 0)] + c[(1, 1)]);
    let det = c[(0, 0)] * c[(1, 1)] - c[(0, 1)] * c[(1, 0)];
    (half_trace + (half_trace * half_trace - det).max(0.0).sqrt()).max(0.0).sqrt()
}

impl ExternalDevice for OperatorConsole {
    type Directive = OperatorDirective;

    fn receive(&mut self, _now: Time, packet: &[u8]) -> Result<(), String> {
        let packet = AlarmPacket::decode(packet).map_err(|e| e.to_string())?;
        *self.board.lock().unwrap_or_else(std::sync::PoisonError::into_inner) = packet.alarm;
        Ok(())
    }

    fn directive(&self) -> OperatorDirective {
        OperatorDirective { alarm: read_board(&self.board) }
    }

    fn status_packet(
        &mut self,
        now: Time,
        own: &OwnState,
        world: Option<&WorldState>,
    ) -> Option<Vec<u8>> {
        if self.last_status.is_some_and(|t| (now - t).as_secs_f64() < self.status_period) {
            return None;
        }
        self.last_status = Some(now);
        let packet = StatusPacket {
            player: self.player,
            stable: own.status == StandingStatus::Stable,
            localized: own.localized,
            intruder_sighted: world.and_then(|w| w.object(INTRUDER)).is_some_and(|o| o.known),
            position: own.pose.position(),
            reports: world.map(|w| self.reports(w)).unwrap_or_default(),
        };
        Some(packet.encode())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packets_round_trip_and_garbage_is_refused() {
        let alarm =
            AlarmPacket { alarm: Some(Alarm { id: 7, point: Point::new(-4.25, 2.5) }), seq: 3 };
        assert_eq!(AlarmPacket::decode(&alarm.encode()), Ok(alarm));
        let quiet = AlarmPacket { alarm: None, seq: 4 };
        assert_eq!(AlarmPacket::decode(&quiet.encode()), Ok(quiet));
        let status = StatusPacket {
            player: 2,
            stable: true,
            localized: true,
            intruder_sighted: false,
            position: Point::new(1.5, -2.0),
            reports: vec![PoiReport { poi: 3, position: Point::new(6.93, -1.0), sigma: 0.042 }],
        };
        assert_eq!(StatusPacket::decode(&status.encode()), Ok(status.clone()));
        assert_eq!(AlarmPacket::decode(b"P"), Err(PacketError::Truncated(1)));
        assert!(matches!(AlarmPacket::decode(&status.encode()), Err(PacketError::Header(_))));
        let mut long = status.encode();
        long.push(0);
        assert!(matches!(StatusPacket::decode(&long), Err(PacketError::Length { .. })));
        let mut future = alarm.encode();
        future[2] = 2;
        assert_eq!(AlarmPacket::decode(&future), Err(PacketError::Version(2)));
    }
}
