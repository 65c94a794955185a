//! The wire protocol between the simulator server and robot processes (version 1), documented in
//! `docs/sim-protocol.md`.
//!
//! A connection is a stream of frames: a 4-byte little-endian payload length, then that many
//! bytes of one JSON message. The client opens with `hello`; the server answers `welcome` or
//! `error` and closes. Byte payloads (team messages, GameController packets) are hex strings.

use std::io::{self, Read, Write};
use std::net::TcpStream;
use std::time::Instant;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use strata_robot::platform::{ActuatorOrders, MotionFeedback, PlatformInfo, SensorFrame};
use strata_runtime::Time;

/// The protocol's name in the handshake.
pub const PROTOCOL: &str = "strata-sim";
/// The protocol version this build speaks.
pub const VERSION: u32 = 1;
/// Where `strata server` listens and `strata robot --platform sim` connects unless told.
pub const DEFAULT_ADDR: &str = "127.0.0.1:7500";
/// The largest frame a server accepts from a robot.
pub const MAX_CLIENT_FRAME: usize = 64 * 1024;
/// The largest frame a robot accepts from the server.
pub const MAX_SERVER_FRAME: usize = 1024 * 1024;

/// Bytes carried as a lowercase hex string.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Bytes(pub Vec<u8>);

impl Serialize for Bytes {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        const DIGITS: &[u8; 16] = b"0123456789abcdef";
        let mut text = String::with_capacity(self.0.len() * 2);
        for byte in &self.0 {
            text.push(char::from(DIGITS[usize::from(byte >> 4)]));
            text.push(char::from(DIGITS[usize::from(byte & 0x0f)]));
        }
        serializer.serialize_str(&text)
    }
}

impl<'de> Deserialize<'de> for Bytes {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Bytes, D::Error> {
        let text = <std::borrow::Cow<'de, str>>::deserialize(deserializer)?;
        decode_hex(&text).map(Bytes).map_err(serde::de::Error::custom)
    }
}

fn decode_hex(text: &str) -> Result<Vec<u8>, String> {
    if !text.len().is_multiple_of(2) {
        return Err(format!("hex payload has an odd length ({})", text.len()));
    }
    let digit = |c: u8| match c {
        b'0'..=b'9' => Ok(c - b'0'),
        b'a'..=b'f' => Ok(c - b'a' + 10),
        b'A'..=b'F' => Ok(c - b'A' + 10),
        _ => Err(format!("{:?} is not a hex digit", char::from(c))),
    };
    text.as_bytes().chunks(2).map(|pair| Ok(digit(pair[0])? << 4 | digit(pair[1])?)).collect()
}

/// What a robot process sends.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ClientMessage {
    /// The first message: which protocol, and which robot this process drives.
    Hello {
        protocol: String,
        version: u32,
        /// The team number (as in GameController packets), not the team's index.
        team: u8,
        player: u8,
    },
    /// Actuator orders, applied when they arrive.
    Orders { orders: ActuatorOrders },
    /// A team message to forward to the teammates (at most 128 bytes).
    TeamMessage { payload: Bytes },
    /// A GameController return packet (`RGrt`).
    ReturnPacket { payload: Bytes },
    /// The robot leaves; the server removes it from the world.
    Goodbye,
}

/// What the server sends.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ServerMessage {
    /// The handshake succeeded: the robot is in the world.
    Welcome {
        version: u32,
        team: u8,
        player: u8,
        /// The team's index in the simulation (0 or 1).
        team_index: usize,
        info: PlatformInfo,
        /// The largest team message the server forwards.
        max_team_message: usize,
        /// The server's simulated time.
        time: Time,
    },
    /// A sensor frame (every sensor period; with a camera image when one was taken).
    Sensors { frame: SensorFrame },
    /// The motion state, with the odometry since the previous `motion` message.
    Motion { feedback: MotionFeedback },
    /// A teammate's message, with the server time it was delivered.
    TeamMessage { received: Time, payload: Bytes },
    /// A GameController control packet (`RGme`).
    ControlPacket { received: Time, payload: Bytes },
    /// Something went wrong; the server closes the connection after sending it.
    Error { code: ErrorCode, message: String },
}

/// Why the server refused or closed a connection.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ErrorCode {
    /// A frame was not a valid message.
    MalformedFrame,
    /// A frame's length was above the limit.
    FrameTooLarge,
    /// `hello` named another protocol or version.
    UnsupportedVersion,
    /// `hello` named a team or player that is not in the game.
    UnknownRobot,
    /// Another process already drives that robot.
    SlotTaken,
    /// A message that is not valid at this point (orders before `hello`, a second `hello`).
    UnexpectedMessage,
    /// No complete `hello` within the server's handshake deadline.
    HandshakeTimeout,
    /// The server is stopping.
    ServerShutdown,
    /// The server has as many connections open as its limit allows.
    TooManyConnections,
}

/// Why a frame could not be read.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    #[error("the connection closed")]
    Closed,
    #[error("frame of {size} bytes exceeds the limit of {limit}")]
    TooLarge { size: usize, limit: usize },
    #[error("I/O error: {0}")]
    Io(#[from] io::Error),
    #[error("malformed message: {0}")]
    Malformed(String),
}

/// Encodes one message as a frame.
pub fn encode<T: Serialize>(message: &T) -> Vec<u8> {
    let mut frame = vec![0u8; 4];
    // Serializing these types to a Vec cannot fail: no maps with non-string keys, no I/O.
    if serde_json::to_writer(&mut frame, message).is_err() {
        frame.truncate(4);
    }
    let length = u32::try_from(frame.len() - 4).unwrap_or(u32::MAX);
    frame[..4].copy_from_slice(&length.to_le_bytes());
    frame
}

/// Writes one message as a frame.
pub fn write_message<T: Serialize>(writer: &mut impl Write, message: &T) -> io::Result<()> {
    writer.write_all(&encode(message))?;
    writer.flush()
}

/// Reads one frame's payload, refusing frames longer than `limit`.
pub fn read_frame(reader: &mut impl Read, limit: usize) -> Result<Vec<u8>, FrameError> {
    let mut header = [0u8; 4];
    match reader.read_exact(&mut header) {
        Ok(()) => {}
        Err(error) if error.kind() == io::ErrorKind::UnexpectedEof => {
            return Err(FrameError::Closed);
        }
        Err(error) => return Err(FrameError::Io(error)),
    }
    let size = u32::from_le_bytes(header) as usize;
    if size > limit {
        return Err(FrameError::TooLarge { size, limit });
    }
    let mut payload = vec![0u8; size];
    reader.read_exact(&mut payload).map_err(|error| {
        if error.kind() == io::ErrorKind::UnexpectedEof {
            FrameError::Malformed(format!("the connection closed inside a {size}-byte frame"))
        } else {
            FrameError::Io(error)
        }
    })?;
    Ok(payload)
}

/// Reads from a stream until a deadline over all reads together: each read may wait only for
/// what is left, so a peer that sends a byte now and then cannot stretch a handshake past it as
/// it could a timeout per read.
pub(crate) struct Deadline<'a> {
    stream: &'a TcpStream,
    deadline: Instant,
}

impl<'a> Deadline<'a> {
    pub(crate) fn new(stream: &'a TcpStream, deadline: Instant) -> Deadline<'a> {
        Deadline { stream, deadline }
    }
}

impl Read for Deadline<'_> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let left = self.deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(io::ErrorKind::TimedOut.into());
        }
        self.stream.set_read_timeout(Some(left))?;
        let mut stream = self.stream;
        stream.read(buf)
    }
}

/// Decodes a frame's payload.
pub fn decode<T: DeserializeOwned>(payload: &[u8]) -> Result<T, FrameError> {
    serde_json::from_slice(payload).map_err(|e| FrameError::Malformed(e.to_string()))
}

/// Reads and decodes one message.
pub fn read_message<T: DeserializeOwned>(
    reader: &mut impl Read,
    limit: usize,
) -> Result<T, FrameError> {
    decode(&read_frame(reader, limit)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_round_trip_and_limits_hold() {
        let message = ClientMessage::TeamMessage { payload: Bytes(vec![0, 1, 0xab, 0xff]) };
        let frame = encode(&message);
        let text = std::str::from_utf8(&frame[4..]).expect("utf-8");
        assert_eq!(text, r#"{"type":"team_message","payload":"0001abff"}"#);
        let back: ClientMessage = read_message(&mut &frame[..], 1024).expect("decodes");
        assert_eq!(back, message);
        assert!(matches!(
            read_frame(&mut &frame[..], 3),
            Err(FrameError::TooLarge { size, limit: 3 }) if size == frame.len() - 4
        ));
        assert!(matches!(read_frame(&mut &[][..], 10), Err(FrameError::Closed)));
        assert!(matches!(read_frame(&mut &frame[..10], 1024), Err(FrameError::Malformed(_))));
        let odd = br#"{"type":"team_message","payload":"abc"}"#;
        assert!(matches!(decode::<ClientMessage>(odd), Err(FrameError::Malformed(_))));
        let unknown = br#"{"type":"teleport_me"}"#;
        assert!(matches!(decode::<ClientMessage>(unknown), Err(FrameError::Malformed(_))));
    }

    #[test]
    fn the_documented_examples_decode() {
        // docs/sim-protocol.md shows these; they must stay valid.
        let examples = [
            r#"{"type":"hello","protocol":"strata-sim","version":1,"team":10,"player":1}"#,
            r#"{"type":"orders","orders":{"head":{"target":{"yaw":0.3,"pitch":0.2},"max_speed":2.0},
 "body":{"order":"walk","velocity":{"vx":0.2,"vy":0.0,"omega":0.1}}}}"#,
            r#"{"type":"orders","orders":{"head":null,"body":{"order":"special","motion":{"kind":"kick","sequence":0}}}}"#,
            r#"{"type":"team_message","payload":"0a0b0c"}"#,
        ];
        for example in examples {
            decode::<ClientMessage>(example.as_bytes()).expect(example);
        }
        let error = r#"{"type":"error","code":"frame_too_large","message":"too large"}"#;
        decode::<ServerMessage>(error.as_bytes()).expect("an error message");
    }
}
