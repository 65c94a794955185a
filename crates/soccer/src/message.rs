//! The team message of Fig. 2 on the wire: at most 128 bytes (the SPL limit), little-endian,
//! the same bytes in the simulator and over UDP.
//!
//! ```text
//! offset size  field
//!  0     2     magic "ST" (rejects other teams' messages on a shared network)
//!  2     1     version (2)
//!  3     1     sender player number (1-20)
//!  4     1     mission code
//!  5     1     role code
//!  6     1     flags: bits 0-1 standing status (0 stable, 1 unstable, 2 fallen),
//!              bit 2 penalized, bit 3 localized, bit 4 data received, bit 5 role conflict,
//!              bits 6-7 referee signal (0 none, 1 Ready gesture seen, 2 kick-off whistle
//!              heard; [`crate::game::SIGNAL_READY`], [`crate::game::SIGNAL_WHISTLE`])
//!  7     2     time since the sender last received, 0.1 s (0xFFFF: never)
//!  9     2     role utility, hundredths, i16 (saturating)
//! 11     2     pose x, mm, i16
//! 13     2     pose y, mm, i16
//! 15     2     pose theta, 1e-4 rad, i16
//! 17     1     pose confidence, /255
//! 18     1     number of shared objects n (at most 12)
//! 19     1     referee signal's age, 0.1 s (255 = 25.5 s or more; 0 without a signal)
//! 20     9n    objects: code u8, x i16 mm, y i16 mm, sigma u16 mm, confidence u8 (/255),
//!              age u8 (0.1 s, 255 = 25.5 s or more)
//! ```
//!
//! 20 + 12 x 9 = 128 bytes. Integers instead of floats: no NaN can arrive, and 1 mm / 1e-4 rad
//! is finer than any estimate worth sharing.

use strata_robot::control::planning::{SharedObject, SharedSignal, StandingStatus, TeamMessage};
use strata_robot::geometry::{Point, Pose};

use crate::catalog::{Mission, Role};

pub const MAGIC: [u8; 2] = *b"ST";
pub const VERSION: u8 = 2;
pub const MAX_SIZE: usize = 128;
const HEADER: usize = 20;
/// The largest referee signal code the flags carry.
const MAX_SIGNAL: u8 = 3;
const OBJECT: usize = 9;
pub const MAX_OBJECTS: usize = (MAX_SIZE - HEADER) / OBJECT;
/// The wire heading nearest to pi: round(pi x 1e4).
const HALF_TURN: u16 = 31416;

/// Shared objects by wire code.
pub const SHARED_OBJECTS: [&str; 2] = ["ball", "obstacle"];

pub type SoccerMessage = TeamMessage<Mission, Role>;

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MessageError {
    #[error("team message too short: {len} bytes, the header alone is {HEADER}")]
    TooShort { len: usize },
    #[error("team message too long: {len} bytes, the limit is {MAX_SIZE}")]
    TooLong { len: usize },
    #[error(
        "not a Strata team message (magic {found:02x?}, expected \"ST\"): another team's code?"
    )]
    Foreign { found: [u8; 2] },
    #[error("team message version {found}, this robot speaks {VERSION}")]
    Version { found: u8 },
    #[error("{field} has invalid value {value}")]
    InvalidValue { field: &'static str, value: u32 },
    #[error("team message declares {objects} objects ({expected} bytes) but has {len} bytes")]
    Length { objects: usize, expected: usize, len: usize },
    #[error("cannot encode: {0}")]
    Encode(String),
}

fn mm(v: f64) -> i16 {
    (v * 1000.0).round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}

fn unit(v: f64) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Seconds in 0.1 s, saturating at 25.5 s (and there for what is not a number).
fn tenths(age: f64) -> u8 {
    if age.is_finite() { (age * 10.0).round().clamp(0.0, 255.0) as u8 } else { 255 }
}

/// Encodes a message; objects beyond what fits are dropped (the first ones are kept: the
/// caller orders them by importance).
pub fn encode(message: &SoccerMessage) -> Result<Vec<u8>, MessageError> {
    if !(1..=20).contains(&message.sender) {
        return Err(MessageError::Encode(format!(
            "sender {} is not a player number 1-20",
            message.sender
        )));
    }
    if !message.pose.is_finite() {
        return Err(MessageError::Encode("pose is not finite".into()));
    }
    let (signal, signal_age) = match message.signal {
        None => (0, 0),
        Some(SharedSignal { code, age }) if (1..=MAX_SIGNAL).contains(&code) => (code, tenths(age)),
        Some(SharedSignal { code, .. }) => {
            return Err(MessageError::Encode(format!(
                "referee signal {code} is not a code 1-{MAX_SIGNAL}"
            )));
        }
    };
    let mut out = Vec::with_capacity(MAX_SIZE);
    out.extend_from_slice(&MAGIC);
    out.push(VERSION);
    out.push(message.sender);
    out.push(message.mission.code());
    out.push(message.role.code());
    let status = match message.status {
        StandingStatus::Stable => 0,
        StandingStatus::Unstable => 1,
        StandingStatus::Fallen => 2,
    };
    let flags = status
        | (u8::from(message.penalized) << 2)
        | (u8::from(message.localized) << 3)
        | (u8::from(message.data_received) << 4)
        | (u8::from(message.conflict) << 5)
        | (signal << 6);
    out.push(flags);
    let since = if message.since_last_received.is_finite() {
        (message.since_last_received * 10.0).round().clamp(0.0, 65534.0) as u16
    } else {
        u16::MAX
    };
    out.extend_from_slice(&since.to_le_bytes());
    let utility = if message.utility.is_finite() {
        (message.utility * 100.0).round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
    } else {
        i16::MIN
    };
    out.extend_from_slice(&utility.to_le_bytes());
    out.extend_from_slice(&mm(message.pose.x).to_le_bytes());
    out.extend_from_slice(&mm(message.pose.y).to_le_bytes());
    out.extend_from_slice(&((message.pose.theta * 1e4).round() as i16).to_le_bytes());
    out.push(unit(message.pose_confidence));
    let objects: Vec<(u8, &SharedObject)> = message
        .objects
        .iter()
        .filter(|o| o.position.is_finite())
        .filter_map(|o| SHARED_OBJECTS.iter().position(|n| *n == o.name).map(|c| (c as u8, o)))
        .take(MAX_OBJECTS)
        .collect();
    out.push(objects.len() as u8);
    out.push(signal_age);
    for (code, o) in objects {
        out.push(code);
        out.extend_from_slice(&mm(o.position.x).to_le_bytes());
        out.extend_from_slice(&mm(o.position.y).to_le_bytes());
        let sigma = if o.sigma.is_finite() {
            (o.sigma * 1000.0).round().clamp(0.0, 65535.0) as u16
        } else {
            u16::MAX
        };
        out.extend_from_slice(&sigma.to_le_bytes());
        out.push(unit(o.confidence));
        out.push(tenths(o.age));
    }
    debug_assert!(out.len() <= MAX_SIZE);
    Ok(out)
}

fn i16_at(bytes: &[u8], at: usize) -> i16 {
    i16::from_le_bytes([bytes[at], bytes[at + 1]])
}

fn u16_at(bytes: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([bytes[at], bytes[at + 1]])
}

/// Decodes a message, rejecting anything malformed or foreign with the reason. Never panics.
pub fn decode(bytes: &[u8]) -> Result<SoccerMessage, MessageError> {
    if bytes.len() > MAX_SIZE {
        return Err(MessageError::TooLong { len: bytes.len() });
    }
    if bytes.len() < 2 || bytes[..2] != MAGIC {
        let mut found = [0; 2];
        for (f, b) in found.iter_mut().zip(bytes) {
            *f = *b;
        }
        if bytes.len() < 2 {
            return Err(MessageError::TooShort { len: bytes.len() });
        }
        return Err(MessageError::Foreign { found });
    }
    if bytes.len() < HEADER {
        return Err(MessageError::TooShort { len: bytes.len() });
    }
    if bytes[2] != VERSION {
        return Err(MessageError::Version { found: bytes[2] });
    }
    let sender = bytes[3];
    if !(1..=20).contains(&sender) {
        return Err(MessageError::InvalidValue { field: "sender", value: u32::from(sender) });
    }
    let mission = Mission::from_code(bytes[4])
        .ok_or(MessageError::InvalidValue { field: "mission", value: u32::from(bytes[4]) })?;
    let role = Role::from_code(bytes[5])
        .ok_or(MessageError::InvalidValue { field: "role", value: u32::from(bytes[5]) })?;
    let flags = bytes[6];
    let status = match flags & 0b11 {
        0 => StandingStatus::Stable,
        1 => StandingStatus::Unstable,
        2 => StandingStatus::Fallen,
        other => {
            return Err(MessageError::InvalidValue {
                field: "standing status",
                value: u32::from(other),
            });
        }
    };
    let since = u16_at(bytes, 7);
    let count = usize::from(bytes[18]);
    if count > MAX_OBJECTS {
        return Err(MessageError::InvalidValue { field: "object count", value: count as u32 });
    }
    let expected = HEADER + count * OBJECT;
    if bytes.len() != expected {
        return Err(MessageError::Length { objects: count, expected, len: bytes.len() });
    }
    let mut objects = Vec::with_capacity(count);
    for i in 0..count {
        let at = HEADER + i * OBJECT;
        let code = usize::from(bytes[at]);
        let name = SHARED_OBJECTS
            .get(code)
            .ok_or(MessageError::InvalidValue { field: "object code", value: code as u32 })?;
        objects.push(SharedObject {
            name: (*name).to_owned(),
            position: Point::new(
                f64::from(i16_at(bytes, at + 1)) / 1000.0,
                f64::from(i16_at(bytes, at + 3)) / 1000.0,
            ),
            sigma: f64::from(u16_at(bytes, at + 5)) / 1000.0,
            confidence: f64::from(bytes[at + 7]) / 255.0,
            age: f64::from(bytes[at + 8]) / 10.0,
        });
    }
    let theta_wire = i16_at(bytes, 15);
    let theta = f64::from(theta_wire) / 1e4;
    if theta.abs() > std::f64::consts::PI + 1e-3 {
        return Err(MessageError::InvalidValue {
            field: "pose theta",
            value: theta_wire as u16 as u32,
        });
    }
    // ±31416 is the grid point nearest to ±pi (where `encode` puts a heading of pi), but lies
    // just beyond it: `Pose::new` would wrap 3.1416 to -3.14159, which encodes as -31416, which
    // wraps back to +3.14159, so a relayed heading would flip between the two forever. Reading
    // both as pi makes decode and encode agree (found by the `team_message` fuzz target).
    let theta = if theta_wire.unsigned_abs() == HALF_TURN { std::f64::consts::PI } else { theta };
    Ok(TeamMessage {
        sender,
        mission,
        role,
        status,
        penalized: flags & 0b100 != 0,
        localized: flags & 0b1000 != 0,
        since_last_received: if since == u16::MAX {
            f64::INFINITY
        } else {
            f64::from(since) / 10.0
        },
        data_received: flags & 0b1_0000 != 0,
        conflict: flags & 0b10_0000 != 0,
        utility: f64::from(i16_at(bytes, 9)) / 100.0,
        pose: Pose::new(
            f64::from(i16_at(bytes, 11)) / 1000.0,
            f64::from(i16_at(bytes, 13)) / 1000.0,
            theta,
        ),
        pose_confidence: f64::from(bytes[17]) / 255.0,
        objects,
        signal: match flags >> 6 {
            0 => None,
            code => Some(SharedSignal { code, age: f64::from(bytes[19]) / 10.0 }),
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn sample() -> SoccerMessage {
        TeamMessage {
            sender: 3,
            mission: Mission::Attack,
            role: Role::StrikerCover,
            status: StandingStatus::Fallen,
            penalized: false,
            localized: true,
            since_last_received: 1.3,
            data_received: true,
            utility: -2.25,
            conflict: true,
            pose: Pose::new(-1.234, 2.5, 1.5),
            pose_confidence: 0.8,
            objects: vec![SharedObject {
                name: "ball".into(),
                position: Point::new(0.5, -0.25),
                sigma: 0.12,
                confidence: 0.6,
                age: 0.4,
            }],
            signal: Some(SharedSignal { code: 2, age: 0.7 }),
        }
    }

    #[test]
    fn the_layout_is_as_documented() {
        let bytes = encode(&sample()).expect("encodes");
        assert_eq!(bytes.len(), 20 + 9);
        assert_eq!(&bytes[..7], &[b'S', b'T', 2, 3, 1, 2, 0b1011_1010]);
        assert_eq!(u16_at(&bytes, 7), 13);
        assert_eq!(i16_at(&bytes, 9), -225);
        assert_eq!(i16_at(&bytes, 11), -1234);
        assert_eq!(i16_at(&bytes, 13), 2500);
        assert_eq!(i16_at(&bytes, 15), 15000);
        assert_eq!(bytes[18], 1);
        assert_eq!(bytes[19], 7);
        assert_eq!(&bytes[20..], &[0, 244, 1, 6, 255, 120, 0, 153, 4]);
    }

    #[test]
    fn round_trip() {
        let message = sample();
        let decoded = decode(&encode(&message).expect("encodes")).expect("decodes");
        assert_eq!(decoded.sender, 3);
        assert_eq!(decoded.role, Role::StrikerCover);
        assert_eq!(decoded.status, StandingStatus::Fallen);
        assert!(decoded.conflict && decoded.localized && !decoded.penalized);
        assert!((decoded.pose.x + 1.234).abs() < 1e-9);
        assert!((decoded.objects[0].position.y + 0.25).abs() < 1e-9);
        assert_eq!(decoded.signal, Some(SharedSignal { code: 2, age: 0.7 }));
        let silent = SoccerMessage { signal: None, ..message };
        let bytes = encode(&silent).expect("encodes");
        assert_eq!((bytes[6] >> 6, bytes[19]), (0, 0));
        assert_eq!(decode(&bytes).expect("decodes").signal, None);
        let unknown = SoccerMessage { signal: Some(SharedSignal { code: 4, age: 0.0 }), ..silent };
        assert!(encode(&unknown).is_err(), "a code the flags cannot carry");
    }

    #[test]
    fn the_largest_message_fits_the_spl_limit() {
        let mut message = sample();
        message.objects = (0..20).map(|_| message.objects[0].clone()).collect();
        let bytes = encode(&message).expect("encodes");
        assert!(bytes.len() <= MAX_SIZE);
        assert_eq!(decode(&bytes).expect("decodes").objects.len(), MAX_OBJECTS);
    }

    #[test]
    fn malformed_and_foreign_messages_are_rejected_with_the_reason() {
        let good = encode(&sample()).expect("encodes");
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (vec![], "too short"),
            (b"XY and more bytes than a header".to_vec(), "not a Strata team message"),
            (good[..10].to_vec(), "too short"),
            (
                {
                    let mut b = good.clone();
                    b[2] = 9;
                    b
                },
                "version 9",
            ),
            (
                {
                    let mut b = good.clone();
                    b[3] = 0;
                    b
                },
                "sender has invalid value 0",
            ),
            (
                {
                    let mut b = good.clone();
                    b[5] = 17;
                    b
                },
                "role has invalid value 17",
            ),
            (
                {
                    let mut b = good.clone();
                    b[6] = 0b11;
                    b
                },
                "standing status",
            ),
            (
                {
                    let mut b = good.clone();
                    b[18] = 2;
                    b
                },
                "declares 2 objects",
            ),
            (
                {
                    let mut b = good.clone();
                    b[20] = 7;
                    b
                },
                "object code",
            ),
            (vec![b'S'; 200], "too long"),
        ];
        for (bytes, expected) in cases {
            let error = decode(&bytes).expect_err("must be rejected").to_string();
            assert!(error.contains(expected), "{error:?} should mention {expected:?}");
        }
    }

    /// Regression (found by the `team_message` fuzz target): a heading of pi is sent as 31416,
    /// just beyond pi; decoding wrapped it to -3.14159, re-encoding sent -31416, and a relayed
    /// message flipped between +31416 and -31416 without ever settling.
    #[test]
    fn a_heading_of_pi_survives_relaying() {
        let mut message = sample();
        message.pose = Pose::new(0.0, 0.0, std::f64::consts::PI);
        let bytes = encode(&message).expect("encodes");
        assert_eq!(i16_at(&bytes, 15), 31416);
        for wire in [31416i16, -31416] {
            let mut b = bytes.clone();
            b[15..17].copy_from_slice(&wire.to_le_bytes());
            let decoded = decode(&b).expect("decodes");
            assert_eq!(decoded.pose.theta, std::f64::consts::PI);
            assert_eq!(decode(&encode(&decoded).expect("encodes")).expect("decodes"), decoded);
        }
    }

    proptest! {
        /// Every accepted heading settles after one re-encoding: headings beyond ±pi are wrapped
        /// off the 1e-4 grid by the decoder, so the first round may move them (by less than half
        /// a step), the second must not.
        #[test]
        fn decoded_headings_are_a_fixed_point_after_one_relay(wire in -31425i16..=31425) {
            let mut bytes = encode(&sample()).expect("encodes");
            bytes[15..17].copy_from_slice(&wire.to_le_bytes());
            let first = decode(&bytes).expect("decodes");
            let second = decode(&encode(&first).expect("encodes")).expect("decodes");
            let third = decode(&encode(&second).expect("encodes")).expect("decodes");
            prop_assert_eq!(&third, &second);
            let moved = (second.pose.theta - first.pose.theta).rem_euclid(std::f64::consts::TAU);
            prop_assert!(moved.min(std::f64::consts::TAU - moved) <= 0.5e-4 + 1e-9);
        }

        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..160)) {
            let _ = decode(&bytes);
        }

        #[test]
        fn valid_messages_round_trip(sender in 1u8..=20, x in -4.5f64..4.5, y in -3.0f64..3.0, theta in -3.1f64..3.1, n in 0usize..15) {
            let mut message = sample();
            message.sender = sender;
            message.pose = Pose::new(x, y, theta);
            message.objects = (0..n).map(|_| message.objects[0].clone()).collect();
            let decoded = decode(&encode(&message).expect("encodes")).expect("decodes");
            prop_assert_eq!(decoded.sender, sender);
            prop_assert!((decoded.pose.x - x).abs() <= 0.0005 + 1e-9);
            prop_assert!((decoded.pose.theta - theta).abs() <= 0.00005 + 1e-9);
            prop_assert_eq!(decoded.objects.len(), n.min(MAX_OBJECTS));
        }
    }
}
