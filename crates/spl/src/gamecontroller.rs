//! GameController packets, byte-exact: the control packet `RoboCupGameControlData` (header
//! "RGme", version 18, 118 bytes) the GameController broadcasts, and the return packet
//! `RoboCupGameControlReturnData` ("RGrt", version 4, 32 bytes) each robot sends back.
//!
//! Layout and constants follow `RoboCupGameControlData.h` of the RoboCup-SPL GameController3
//! (`game_controller_msgs/headers`, read at commit 36353e4, v5.0.0-7): packed, little-endian.
//! Decoders never panic and reject no more than they must:
//!
//! - [`ReturnData::decode`] accepts exactly what GameController3 accepts from a robot (its
//!   `game_controller_net/src/status_message_receiver.rs`, `game_controller_runtime/src/lib.rs`
//!   and `game_controller_msgs/src/status_message.rs`), so a check here is never a surprise on
//!   the field, in either direction.
//! - [`GameControlData::decode`] rejects a packet only for what the robot cannot follow the
//!   game without: length, header, version, the game state and the first-half flag. A value it
//!   does not know in any other enumerated field (a newer GameController's competition type,
//!   set play or penalty) is kept as `Unknown(raw)`, so the robot keeps following the game and
//!   the packet still encodes back to the same bytes.

use std::fmt;

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// `GAMECONTROLLER_STRUCT_HEADER`.
pub const CONTROL_HEADER: [u8; 4] = *b"RGme";
/// `GAMECONTROLLER_STRUCT_VERSION`.
pub const CONTROL_VERSION: u8 = 18;
/// `sizeof(RoboCupGameControlData)`.
pub const CONTROL_PACKET_SIZE: usize = 118;
/// `GAMECONTROLLER_RETURN_STRUCT_HEADER`.
pub const RETURN_HEADER: [u8; 4] = *b"RGrt";
/// `GAMECONTROLLER_RETURN_STRUCT_VERSION`.
pub const RETURN_VERSION: u8 = 4;
/// `sizeof(RoboCupGameControlReturnData)`.
pub const RETURN_PACKET_SIZE: usize = 32;
/// `MAX_NUM_PLAYERS`: the size of each team's player array.
pub const MAX_NUM_PLAYERS: usize = 20;
/// `KICKING_TEAM_NONE`.
pub const KICKING_TEAM_NONE: u8 = 255;

const TEAM_INFO_SIZE: usize = 10 + 2 * MAX_NUM_PLAYERS;
// The header's fixed part (18 bytes) and two teams fill the packet exactly.
const _: () = assert!(18 + 2 * TEAM_INFO_SIZE == CONTROL_PACKET_SIZE);

/// A byte that is not one of the values an enumeration defines.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
#[error("{what} value {value} out of range (valid: {})", list(allowed))]
pub struct UnknownValue {
    pub what: &'static str,
    pub value: u8,
    pub allowed: &'static [u8],
}

fn list(values: &[u8]) -> String {
    values.iter().map(u8::to_string).collect::<Vec<_>>().join(", ")
}

macro_rules! wire_enum {
    // A closed enumeration: a byte outside it is an error ([`UnknownValue`]). Only for fields
    // the robot cannot act on without knowing the value.
    ($(#[$meta:meta])* closed $name:ident, $what:literal {
        $($(#[$vmeta:meta])* $variant:ident = $value:literal,)+
    }) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
        #[serde(rename_all = "snake_case")]
        #[repr(u8)]
        pub enum $name {
            $($(#[$vmeta])* $variant = $value,)+
        }

        impl $name {
            /// Every wire value, ascending.
            pub const VALUES: &'static [u8] = &[$($value),+];
        }

        impl From<$name> for u8 {
            fn from(value: $name) -> u8 {
                value as u8
            }
        }

        impl TryFrom<u8> for $name {
            type Error = UnknownValue;

            fn try_from(value: u8) -> Result<Self, UnknownValue> {
                match value {
                    $($value => Ok($name::$variant),)+
                    _ => Err(UnknownValue { what: $what, value, allowed: $name::VALUES }),
                }
            }
        }
    };
    // An open enumeration: every byte converts, one this version does not define to
    // `Unknown(byte)`, which encodes back to the same byte.
    ($(#[$meta:meta])* open $name:ident {
        $($(#[$vmeta:meta])* $variant:ident = $value:literal,)+
    }) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
        #[serde(rename_all = "snake_case")]
        pub enum $name {
            $($(#[$vmeta])* $variant,)+
            /// A value this version does not define (a newer GameController's), as sent.
            /// `From<u8>` gives it only for such values.
            Unknown(u8),
        }

        impl $name {
            /// Every defined wire value, ascending.
            pub const VALUES: &'static [u8] = &[$($value),+];

            /// Whether the value is one this version defines.
            pub fn is_known(self) -> bool {
                Self::VALUES.contains(&u8::from(self))
            }
        }

        impl From<$name> for u8 {
            fn from(value: $name) -> u8 {
                match value {
                    $($name::$variant => $value,)+
                    $name::Unknown(raw) => raw,
                }
            }
        }

        impl From<u8> for $name {
            fn from(value: u8) -> Self {
                match value {
                    $($value => $name::$variant,)+
                    raw => $name::Unknown(raw),
                }
            }
        }
    };
}

wire_enum! {
    /// `TEAM_*`: jersey colours.
    open TeamColour {
        Blue = 0,
        Red = 1,
        Yellow = 2,
        Black = 3,
        White = 4,
        Green = 5,
        Orange = 6,
        Purple = 7,
        Brown = 8,
        Gray = 9,
    }
}

wire_enum! {
    /// `COMPETITION_PHASE_*`.
    open CompetitionPhase {
        RoundRobin = 0,
        Playoff = 1,
    }
}

wire_enum! {
    /// `COMPETITION_TYPE_*`.
    open CompetitionType {
        Normal = 0,
        /// The Most Passes Leaderboard challenge (GameController3's
        /// `config/most_passes_leaderboard`).
        MostPasses = 1,
    }
}

wire_enum! {
    /// `GAME_PHASE_*`. The robot only asks whether it is a penalty shoot-out, so a phase it
    /// does not know is not one.
    open GamePhase {
        Normal = 0,
        PenaltyShoot = 1,
        Overtime = 2,
        Timeout = 3,
    }
}

wire_enum! {
    /// `STATE_*`: the game state. Closed: a robot cannot follow a state it does not know, so
    /// such a packet is rejected and the robot keeps the last state it understood.
    closed GameState, "state" {
        Initial = 0,
        Ready = 1,
        Set = 2,
        Playing = 3,
        Finished = 4,
        Standby = 5,
    }
}

wire_enum! {
    /// `SET_PLAY_*`. A set play the robot does not know is still a set play (not `None`).
    open SetPlay {
        None = 0,
        GoalKick = 1,
        PushingFreeKick = 2,
        CornerKick = 3,
        KickIn = 4,
        PenaltyKick = 5,
    }
}

wire_enum! {
    /// `PENALTY_*`. A penalty the robot does not know is still a penalty (not `None`).
    /// (GameController3's header defines `Manual`, but GameController3 never sends it.)
    open Penalty {
        None = 0,
        IllegalBallContact = 1,
        PlayerPushing = 2,
        IllegalMotionInSet = 3,
        InactivePlayer = 4,
        IllegalPosition = 5,
        LeavingTheField = 6,
        RequestForPickup = 7,
        LocalGameStuck = 8,
        IllegalPositionInSet = 9,
        PlayerStance = 10,
        IllegalMotionInStandby = 11,
        Substitute = 14,
        Manual = 15,
    }
}

/// Which of the two packets a decoder was reading.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PacketType {
    Control,
    Return,
}

impl fmt::Display for PacketType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            PacketType::Control => "control packet",
            PacketType::Return => "return packet",
        })
    }
}

/// Why bytes are not a valid packet.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum DecodeError {
    #[error("{packet}: wrong length: expected {expected} bytes, got {actual}")]
    Length { packet: PacketType, expected: usize, actual: usize },
    #[error("{packet}: too short: expected at least {minimum} bytes, got {actual}")]
    TooShort { packet: PacketType, minimum: usize, actual: usize },
    #[error("{packet}: bad header \"{}\" (expected \"{}\")", found.escape_ascii(), expected.escape_ascii())]
    Header { packet: PacketType, expected: [u8; 4], found: [u8; 4] },
    #[error("{packet}: version {found} is not {expected}")]
    Version { packet: PacketType, expected: u8, found: u8 },
    #[error("{packet}: {field} value {value} out of range (valid: {valid})")]
    OutOfRange { packet: PacketType, field: String, value: u8, valid: String },
    #[error("{packet}: {field} is NaN")]
    NotANumber { packet: PacketType, field: &'static str },
}

impl DecodeError {
    fn out_of_range(packet: PacketType, field: impl Into<String>, e: UnknownValue) -> DecodeError {
        DecodeError::OutOfRange {
            packet,
            field: field.into(),
            value: e.value,
            valid: list(e.allowed),
        }
    }

    fn range(packet: PacketType, field: impl Into<String>, value: u8, valid: &str) -> DecodeError {
        DecodeError::OutOfRange { packet, field: field.into(), value, valid: valid.to_owned() }
    }

    /// For a return packet, the reason GameController3 gives itself when it drops the packet
    /// (the `bail!` text of `StatusMessage::try_from`; it logs the packet but shows no reason).
    /// `None` for a control packet, which GameController3 only sends.
    pub fn game_controller3_reason(&self) -> Option<&'static str> {
        let return_packet = |packet: &PacketType| *packet == PacketType::Return;
        Some(match self {
            DecodeError::Length { packet, .. } | DecodeError::TooShort { packet, .. }
                if return_packet(packet) =>
            {
                "wrong length"
            }
            DecodeError::Header { packet, .. } if return_packet(packet) => "wrong header",
            DecodeError::Version { packet, .. } if return_packet(packet) => "wrong version",
            DecodeError::OutOfRange { packet, field, .. } if return_packet(packet) => {
                match field.as_str() {
                    "player_number" => "invalid player number",
                    "fallen" => "invalid fallen",
                    _ => return None,
                }
            }
            DecodeError::NotANumber { packet, field } if return_packet(packet) => {
                match field.split('[').next() {
                    Some("pose") => "invalid pose",
                    Some("ball_age") => "invalid ball age",
                    Some("ball") => "invalid ball",
                    _ => return None,
                }
            }
            _ => return None,
        })
    }
}

/// The packet types a datagram can be recognised as, by its header.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PacketKind {
    Control,
    Return,
    /// Anything else; on the team port, a team message.
    Unknown,
}

impl PacketKind {
    /// Recognises a datagram by its first four bytes (the length is checked by the decoder).
    pub fn detect(bytes: &[u8]) -> PacketKind {
        match bytes.first_chunk::<4>() {
            Some(&CONTROL_HEADER) => PacketKind::Control,
            Some(&RETURN_HEADER) => PacketKind::Return,
            _ => PacketKind::Unknown,
        }
    }
}

/// `RobotInfo`: one player slot of a team.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RobotInfo {
    pub penalty: Penalty,
    /// Estimated seconds until the penalty ends.
    pub secs_till_unpenalised: u8,
}

impl Default for RobotInfo {
    fn default() -> Self {
        RobotInfo { penalty: Penalty::None, secs_till_unpenalised: 0 }
    }
}

/// `TeamInfo`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TeamInfo {
    pub team_number: u8,
    pub field_player_colour: TeamColour,
    pub goalkeeper_colour: TeamColour,
    /// Player number of the goalkeeper, 1..=20; 0 when there is none (as sent: not checked).
    pub goalkeeper: u8,
    pub score: u8,
    /// Penalty shot counter (outside a penalty shoot-out: the fallback-mode flag).
    pub penalty_shot: u8,
    /// One bit per penalty shot: success.
    pub single_shots: u16,
    /// Team messages the team may still send in this game.
    pub message_budget: u16,
    /// Index 0 is player number 1.
    pub players: [RobotInfo; MAX_NUM_PLAYERS],
}

impl TeamInfo {
    /// The slot of a player number (1-based), if in range.
    pub fn player(&self, player_number: u8) -> Option<&RobotInfo> {
        self.players.get(usize::from(player_number).checked_sub(1)?)
    }
}

/// `RoboCupGameControlData`, typed. Header and version are implied.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct GameControlData {
    /// Incremented with each packet sent (wraps).
    pub packet_number: u8,
    /// Players on a team; [`MAX_NUM_PLAYERS`] at most in any real game, but not checked.
    pub players_per_team: u8,
    pub competition_phase: CompetitionPhase,
    pub competition_type: CompetitionType,
    pub game_phase: GamePhase,
    pub state: GameState,
    pub set_play: SetPlay,
    pub first_half: bool,
    /// Team number of the team taking the next kick-off or set play; `None` on the wire is 255,
    /// so `Some(255)` cannot be represented.
    pub kicking_team: Option<u8>,
    /// Estimated seconds left in the half.
    pub secs_remaining: i16,
    /// Seconds shown as secondary time (remaining ready time, until free ball, ...).
    pub secondary_time: i16,
    pub teams: [TeamInfo; 2],
}

struct Reader<'a> {
    bytes: &'a [u8],
    packet: PacketType,
    expected: usize,
    actual: usize,
}

impl<'a> Reader<'a> {
    fn new(bytes: &'a [u8], packet: PacketType, expected: usize) -> Result<Self, DecodeError> {
        let reader = Reader { bytes, packet, expected, actual: bytes.len() };
        if bytes.len() == expected { Ok(reader) } else { Err(reader.short()) }
    }

    fn short(&self) -> DecodeError {
        DecodeError::Length { packet: self.packet, expected: self.expected, actual: self.actual }
    }

    fn take<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        let (head, rest) = self.bytes.split_first_chunk::<N>().ok_or_else(|| self.short())?;
        self.bytes = rest;
        Ok(*head)
    }

    fn u8(&mut self) -> Result<u8, DecodeError> {
        self.take::<1>().map(|[b]| b)
    }

    fn u16(&mut self) -> Result<u16, DecodeError> {
        self.take().map(u16::from_le_bytes)
    }

    fn i16(&mut self) -> Result<i16, DecodeError> {
        self.take().map(i16::from_le_bytes)
    }

    /// A float that is not NaN: ±inf passes, as GameController3 lets it pass.
    fn f32(&mut self, field: &'static str) -> Result<f32, DecodeError> {
        let value = self.take().map(f32::from_le_bytes)?;
        if value.is_nan() {
            Err(DecodeError::NotANumber { packet: self.packet, field })
        } else {
            Ok(value)
        }
    }

    fn header(&mut self, expected: [u8; 4], version: u8) -> Result<(), DecodeError> {
        let packet = self.packet;
        let found = self.take::<4>()?;
        if found != expected {
            return Err(DecodeError::Header { packet, expected, found });
        }
        let found = self.u8()?;
        if found != version {
            return Err(DecodeError::Version { packet, expected: version, found });
        }
        Ok(())
    }

    /// A value of an open enumeration: never an error.
    fn open<T: From<u8>>(&mut self) -> Result<T, DecodeError> {
        self.u8().map(T::from)
    }

    fn wire<T: TryFrom<u8, Error = UnknownValue>>(
        &mut self,
        field: impl FnOnce() -> String,
    ) -> Result<T, DecodeError> {
        let packet = self.packet;
        T::try_from(self.u8()?).map_err(|e| DecodeError::out_of_range(packet, field(), e))
    }

    fn bounded(
        &mut self,
        field: impl FnOnce() -> String,
        min: u8,
        max: u8,
    ) -> Result<u8, DecodeError> {
        let value = self.u8()?;
        if (min..=max).contains(&value) {
            Ok(value)
        } else {
            Err(DecodeError::range(self.packet, field(), value, &format!("{min}-{max}")))
        }
    }
}

/// Writes fields in order into a fixed-size packet.
struct Writer<const N: usize> {
    bytes: [u8; N],
    at: usize,
}

impl<const N: usize> Writer<N> {
    fn new() -> Self {
        Writer { bytes: [0; N], at: 0 }
    }

    fn put(&mut self, data: &[u8]) {
        // The layouts are constants checked by tests, so running past the end is a bug here.
        self.bytes[self.at..self.at + data.len()].copy_from_slice(data);
        self.at += data.len();
    }

    fn finish(self) -> [u8; N] {
        debug_assert_eq!(self.at, N, "packet layout does not fill the packet");
        self.bytes
    }
}

impl GameControlData {
    /// Parses a control packet. Rejects only what a robot cannot follow the game without: a
    /// length other than 118, a header other than `RGme`, a version other than 18, a state it
    /// does not know and a first-half flag other than 0 or 1 (GameController3 writes only
    /// those; anything else is not a packet to act on). Every other byte is kept as it is:
    /// unknown enumerated values as `Unknown(raw)`, counts and player numbers (`players_per_team`,
    /// `goalkeeper`) unchecked, since GameController3 does not bound them either and the robot
    /// does not need them to be in range.
    pub fn decode(bytes: &[u8]) -> Result<GameControlData, DecodeError> {
        let packet = PacketType::Control;
        let mut r = Reader::new(bytes, packet, CONTROL_PACKET_SIZE)?;
        r.header(CONTROL_HEADER, CONTROL_VERSION)?;
        let packet_number = r.u8()?;
        let players_per_team = r.u8()?;
        let competition_phase = r.open()?;
        let competition_type = r.open()?;
        let game_phase = r.open()?;
        let state = r.wire(|| "state".into())?;
        let set_play = r.open()?;
        let first_half = r.bounded(|| "first_half".into(), 0, 1)? == 1;
        let kicking_team = Some(r.u8()?).filter(|&team| team != KICKING_TEAM_NONE);
        let secs_remaining = r.i16()?;
        let secondary_time = r.i16()?;
        let mut teams = [TeamInfo::default(); 2];
        for team in &mut teams {
            team.team_number = r.u8()?;
            team.field_player_colour = r.open()?;
            team.goalkeeper_colour = r.open()?;
            team.goalkeeper = r.u8()?;
            team.score = r.u8()?;
            team.penalty_shot = r.u8()?;
            team.single_shots = r.u16()?;
            team.message_budget = r.u16()?;
            for player in &mut team.players {
                player.penalty = r.open()?;
                player.secs_till_unpenalised = r.u8()?;
            }
        }
        Ok(GameControlData {
            packet_number,
            players_per_team,
            competition_phase,
            competition_type,
            game_phase,
            state,
            set_play,
            first_half,
            kicking_team,
            secs_remaining,
            secondary_time,
            teams,
        })
    }

    /// The wire bytes. `kicking_team == Some(255)`, which the wire cannot carry as meant, is
    /// written as 255 and decodes as `None`.
    pub fn encode(&self) -> [u8; CONTROL_PACKET_SIZE] {
        let mut w = Writer::<CONTROL_PACKET_SIZE>::new();
        w.put(&CONTROL_HEADER);
        w.put(&[
            CONTROL_VERSION,
            self.packet_number,
            self.players_per_team,
            self.competition_phase.into(),
            self.competition_type.into(),
            self.game_phase.into(),
            self.state.into(),
            self.set_play.into(),
            u8::from(self.first_half),
            self.kicking_team.unwrap_or(KICKING_TEAM_NONE),
        ]);
        w.put(&self.secs_remaining.to_le_bytes());
        w.put(&self.secondary_time.to_le_bytes());
        for team in &self.teams {
            w.put(&[
                team.team_number,
                team.field_player_colour.into(),
                team.goalkeeper_colour.into(),
                team.goalkeeper,
                team.score,
                team.penalty_shot,
            ]);
            w.put(&team.single_shots.to_le_bytes());
            w.put(&team.message_budget.to_le_bytes());
            for player in &team.players {
                w.put(&[player.penalty.into(), player.secs_till_unpenalised]);
            }
        }
        w.finish()
    }

    /// The team with this team number, if it plays in this game.
    pub fn team(&self, team_number: u8) -> Option<&TeamInfo> {
        self.teams.iter().find(|team| team.team_number == team_number)
    }

    /// Seconds left in the game (both halves) for halves of `half_secs`; an estimate that
    /// ignores overtime and penalty shoot-outs, which is what budget pacing needs.
    pub fn game_secs_remaining(&self, half_secs: u32) -> u32 {
        let this_half = u32::try_from(self.secs_remaining).unwrap_or(0);
        if self.first_half && self.game_phase == GamePhase::Normal {
            this_half + half_secs
        } else {
            this_half
        }
    }
}

impl Default for TeamInfo {
    fn default() -> Self {
        TeamInfo {
            team_number: 0,
            field_player_colour: TeamColour::Blue,
            goalkeeper_colour: TeamColour::Blue,
            goalkeeper: 0,
            score: 0,
            penalty_shot: 0,
            single_shots: 0,
            message_budget: 0,
            players: [RobotInfo::default(); MAX_NUM_PLAYERS],
        }
    }
}

impl Default for GameControlData {
    /// An Initial-state packet of the first half with two blank teams.
    fn default() -> Self {
        GameControlData {
            packet_number: 0,
            players_per_team: 0,
            competition_phase: CompetitionPhase::RoundRobin,
            competition_type: CompetitionType::Normal,
            game_phase: GamePhase::Normal,
            state: GameState::Initial,
            set_play: SetPlay::None,
            first_half: true,
            kicking_team: None,
            secs_remaining: 0,
            secondary_time: 0,
            teams: [TeamInfo::default(); 2],
        }
    }
}

/// `RoboCupGameControlReturnData`, typed. Header and version are implied.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReturnData {
    /// 1..=20.
    pub player_number: u8,
    pub team_number: u8,
    /// The wire's 1 (0 is `false`); GameController3 drops a packet with any other value, so
    /// nothing is lost.
    pub fallen: bool,
    /// x, y (millimetres, field frame, x towards the goal the robot attacks), theta (radians).
    /// Never NaN in a valid packet, but possibly infinite (as are `ball_age` and `ball`).
    pub pose: [f32; 3],
    /// Seconds since the ball was last seen; -1 if never.
    pub ball_age: f32,
    /// Ball position relative to the robot (millimetres, x forward, y left).
    pub ball: [f32; 2],
}

impl ReturnData {
    /// `ball_age` for a robot that has not seen the ball.
    pub const BALL_NEVER_SEEN: f32 = -1.0;

    /// Judges a received datagram as GameController3 does, accepting exactly what it accepts:
    /// at least 32 bytes, of which the first 32 are the packet, with header `RGrt`, version 4,
    /// a player number of 1 to 20, `fallen` 0 or 1 and no NaN among the floats. Team numbers,
    /// and infinite or absurd floats, pass: GameController3 does not check them.
    pub fn decode(bytes: &[u8]) -> Result<ReturnData, DecodeError> {
        let packet = PacketType::Return;
        // GameController3 receives into a buffer one byte larger than the packet and hands on
        // the first 32 bytes with a `too_long` flag that its runtime ignores for return packets
        // (`status_message_receiver.rs`; `game_controller_runtime/src/lib.rs`,
        // `Event::StatusMessage { host, data, .. }`): a longer datagram counts as its first 32
        // bytes, a shorter one fails `StatusMessage::try_from`'s length check.
        let Some(bytes) = bytes.get(..RETURN_PACKET_SIZE) else {
            return Err(DecodeError::TooShort {
                packet,
                minimum: RETURN_PACKET_SIZE,
                actual: bytes.len(),
            });
        };
        // The rest is `StatusMessage::try_from` (`game_controller_msgs/src/status_message.rs`),
        // check for check and in its order, so the first error here is the one it stops at.
        let mut r = Reader::new(bytes, packet, RETURN_PACKET_SIZE)?;
        r.header(RETURN_HEADER, RETURN_VERSION)?;
        let player_number = r.bounded(|| "player_number".into(), 1, MAX_NUM_PLAYERS as u8)?;
        // Not checked against the game's teams here: GameController3 accepts any team number
        // and then counts the packet only if the team plays in its game.
        let team_number = r.u8()?;
        let fallen = r.bounded(|| "fallen".into(), 0, 1)? == 1;
        // `is_nan` per float there, so ±inf passes here too.
        let pose = [r.f32("pose[0]")?, r.f32("pose[1]")?, r.f32("pose[2]")?];
        let ball_age = r.f32("ball_age")?;
        let ball = [r.f32("ball[0]")?, r.f32("ball[1]")?];
        Ok(ReturnData { player_number, team_number, fallen, pose, ball_age, ball })
    }

    /// The wire bytes, refused when the GameController would drop the packet.
    pub fn encode(&self) -> Result<[u8; RETURN_PACKET_SIZE], DecodeError> {
        let mut w = Writer::<RETURN_PACKET_SIZE>::new();
        w.put(&RETURN_HEADER);
        w.put(&[RETURN_VERSION, self.player_number, self.team_number, u8::from(self.fallen)]);
        for value in self.pose.iter().chain([&self.ball_age]).chain(&self.ball) {
            w.put(&value.to_le_bytes());
        }
        let bytes = w.finish();
        // Validating the encoded bytes keeps one set of rules for both directions.
        ReturnData::decode(&bytes).map(|_| bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn sample() -> GameControlData {
        let mut data = GameControlData {
            packet_number: 42,
            players_per_team: 7,
            competition_phase: CompetitionPhase::Playoff,
            competition_type: CompetitionType::Normal,
            game_phase: GamePhase::Normal,
            state: GameState::Playing,
            set_play: SetPlay::KickIn,
            first_half: false,
            kicking_team: Some(12),
            secs_remaining: 300,
            secondary_time: -5,
            teams: [TeamInfo::default(); 2],
        };
        data.teams[0].team_number = 12;
        data.teams[0].field_player_colour = TeamColour::Red;
        data.teams[0].goalkeeper_colour = TeamColour::Purple;
        data.teams[0].goalkeeper = 1;
        data.teams[0].score = 3;
        data.teams[0].single_shots = 0x0102;
        data.teams[0].message_budget = 1200;
        data.teams[0].players[2] =
            RobotInfo { penalty: Penalty::PlayerPushing, secs_till_unpenalised: 45 };
        data.teams[1].team_number = 5;
        data.teams[1].field_player_colour = TeamColour::Gray;
        data.teams[1].goalkeeper_colour = TeamColour::Green;
        data.teams[1].goalkeeper = 20;
        data.teams[1].penalty_shot = 2;
        data.teams[1].message_budget = 0xBEEF;
        data.teams[1].players[19] =
            RobotInfo { penalty: Penalty::Manual, secs_till_unpenalised: 255 };
        data
    }

    /// The sample, written byte by byte from the C header's layout.
    fn sample_bytes() -> Vec<u8> {
        let mut b = b"RGme".to_vec();
        b.extend([18, 42, 7, 1, 0, 0, 3, 4, 0, 12]);
        b.extend([0x2C, 0x01]); // secsRemaining 300
        b.extend([0xFB, 0xFF]); // secondaryTime -5
        // teams[0]
        b.extend([12, 1, 7, 1, 3, 0]);
        b.extend([0x02, 0x01]); // singleShots
        b.extend([0xB0, 0x04]); // messageBudget 1200
        for p in 0..20 {
            b.extend(if p == 2 { [2, 45] } else { [0, 0] });
        }
        // teams[1]
        b.extend([5, 9, 5, 20, 0, 2]);
        b.extend([0, 0]);
        b.extend([0xEF, 0xBE]);
        for p in 0..20 {
            b.extend(if p == 19 { [15, 255] } else { [0, 0] });
        }
        b
    }

    fn decode_err(bytes: &[u8]) -> String {
        match GameControlData::decode(bytes) {
            Ok(data) => panic!("decoded {data:?}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn control_packet_is_byte_exact() {
        let bytes = sample_bytes();
        assert_eq!(bytes.len(), CONTROL_PACKET_SIZE);
        assert_eq!(sample().encode().to_vec(), bytes);
        assert_eq!(GameControlData::decode(&bytes), Ok(sample()));
        assert_eq!(TEAM_INFO_SIZE, 50);
    }

    #[test]
    fn kicking_team_none_is_255() {
        let mut data = sample();
        data.kicking_team = None;
        let bytes = data.encode();
        assert_eq!(bytes[13], 255);
        assert_eq!(GameControlData::decode(&bytes).map(|d| d.kicking_team), Ok(None));
    }

    #[test]
    fn control_packet_rejections_say_what_is_wrong() {
        let good = sample_bytes();
        assert_eq!(
            decode_err(&good[..117]),
            "control packet: wrong length: expected 118 bytes, got 117"
        );
        let mut long = good.clone();
        long.push(0);
        assert_eq!(decode_err(&long), "control packet: wrong length: expected 118 bytes, got 119");
        assert_eq!(decode_err(&[]), "control packet: wrong length: expected 118 bytes, got 0");

        // Only what the robot cannot follow the game without.
        let cases: &[(usize, u8, &str)] = &[
            (0, b'X', "control packet: bad header \"XGme\" (expected \"RGme\")"),
            (3, 0, "control packet: bad header \"RGm\\x00\" (expected \"RGme\")"),
            (4, 17, "control packet: version 17 is not 18"),
            (4, 19, "control packet: version 19 is not 18"),
            (10, 6, "control packet: state value 6 out of range (valid: 0, 1, 2, 3, 4, 5)"),
            (10, 255, "control packet: state value 255 out of range (valid: 0, 1, 2, 3, 4, 5)"),
            (12, 2, "control packet: first_half value 2 out of range (valid: 0-1)"),
        ];
        for &(offset, value, expected) in cases {
            let mut bytes = good.clone();
            bytes[offset] = value;
            assert_eq!(decode_err(&bytes), expected, "byte {offset} = {value}");
        }
    }

    /// Values the robot does not know, in fields it does not act on (or acts on only
    /// as "not none"), used to make the whole packet undecodable, and the robot deaf.
    #[test]
    fn control_packet_keeps_values_it_does_not_know_and_still_decodes() {
        let good = sample_bytes();
        let mut bytes = good.clone();
        bytes[6] = 21; // players_per_team above MAX_NUM_PLAYERS: GameController3 does not bound it
        bytes[7] = 2; // competition_phase
        bytes[8] = 7; // competition_type
        bytes[9] = 4; // game_phase
        bytes[11] = 6; // set_play
        bytes[18 + 1] = 10; // teams[0].field_player_colour
        bytes[18 + 50 + 2] = 255; // teams[1].goalkeeper_colour
        bytes[18 + 3] = 21; // teams[0].goalkeeper
        bytes[18 + 10 + 2 * 3] = 12; // teams[0].players[3].penalty
        bytes[18 + 50 + 10 + 2 * 19] = 13; // teams[1].players[19].penalty
        let data = GameControlData::decode(&bytes).expect("a robot must keep following the game");
        assert_eq!(data.state, GameState::Playing);
        assert_eq!(data.players_per_team, 21);
        assert_eq!(data.competition_phase, CompetitionPhase::Unknown(2));
        assert_eq!(data.competition_type, CompetitionType::Unknown(7));
        assert_eq!(data.game_phase, GamePhase::Unknown(4));
        assert_eq!(data.set_play, SetPlay::Unknown(6));
        assert_ne!(data.set_play, SetPlay::None, "an unknown set play is a set play");
        assert_eq!(data.teams[0].field_player_colour, TeamColour::Unknown(10));
        assert_eq!(data.teams[1].goalkeeper_colour, TeamColour::Unknown(255));
        assert_eq!(data.teams[0].goalkeeper, 21);
        assert_eq!(data.teams[0].players[3].penalty, Penalty::Unknown(12));
        assert_eq!(data.teams[1].players[19].penalty, Penalty::Unknown(13));
        // The rest is the sample, and the packet encodes back to the very bytes received (the
        // robot's link hands its canonical encoding on).
        assert_eq!(data.teams[0].players[2], sample().teams[0].players[2]);
        assert_eq!(data.encode().to_vec(), bytes);

        // The Most Passes Leaderboard challenge: GameController3 sends competition type 1.
        let mut bytes = good;
        bytes[8] = 1;
        let data = GameControlData::decode(&bytes).map(|d| d.competition_type);
        assert_eq!(data, Ok(CompetitionType::MostPasses));
    }

    /// Every control packet GameController3 can send decodes: each value its
    /// `control_message.rs` writes, in every field.
    #[test]
    fn every_value_game_controller3_sends_is_known() {
        let known = |values: &[u8], sent: &[u8]| sent.iter().all(|v| values.contains(v));
        assert!(known(CompetitionPhase::VALUES, &[0, 1]));
        assert!(known(CompetitionType::VALUES, &[0, 1]));
        assert!(known(GamePhase::VALUES, &[0, 1, 3]));
        assert!(known(GameState::VALUES, &[0, 1, 2, 3, 4, 5]));
        assert!(known(SetPlay::VALUES, &[0, 1, 2, 3, 4, 5]));
        assert!(known(TeamColour::VALUES, &[0, 1, 2, 3, 4, 5, 6, 7, 8, 9]));
        assert!(known(Penalty::VALUES, &[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 14]));
    }

    fn return_bytes() -> Vec<u8> {
        let mut b = b"RGrt".to_vec();
        b.extend([4, 3, 12, 1]);
        for value in [1500.0f32, -750.5, 1.25, 2.5, 320.0, -40.0] {
            b.extend(value.to_le_bytes());
        }
        b
    }

    fn return_sample() -> ReturnData {
        ReturnData {
            player_number: 3,
            team_number: 12,
            fallen: true,
            pose: [1500.0, -750.5, 1.25],
            ball_age: 2.5,
            ball: [320.0, -40.0],
        }
    }

    #[test]
    fn return_packet_is_byte_exact() {
        let bytes = return_bytes();
        assert_eq!(bytes.len(), RETURN_PACKET_SIZE);
        assert_eq!(return_sample().encode().map(|b| b.to_vec()), Ok(bytes.clone()));
        assert_eq!(ReturnData::decode(&bytes), Ok(return_sample()));
        // Hand-checked: 1500.0f32 is 0x44BB8000.
        assert_eq!(bytes[8..12], [0x00, 0x80, 0xBB, 0x44]);
    }

    /// What GameController3 rejects (`StatusMessage::try_from`), rejected with the field, the
    /// value and GameController3's own reason.
    #[test]
    fn return_packet_rejections_say_what_is_wrong() {
        let good = return_bytes();
        let err = |bytes: &[u8]| match ReturnData::decode(bytes) {
            Ok(data) => panic!("decoded {data:?}"),
            Err(e) => (e.to_string(), e.game_controller3_reason()),
        };
        assert_eq!(
            err(&good[..31]),
            (
                "return packet: too short: expected at least 32 bytes, got 31".into(),
                Some("wrong length")
            )
        );
        assert_eq!(err(&[]).1, Some("wrong length"));
        // A control packet sent to the return port: long enough, but not a return packet.
        assert_eq!(
            err(&sample_bytes()),
            ("return packet: bad header \"RGme\" (expected \"RGrt\")".into(), Some("wrong header"))
        );
        let cases: &[(usize, u8, &str, &str)] = &[
            (1, b'X', "return packet: bad header \"RXrt\" (expected \"RGrt\")", "wrong header"),
            (4, 3, "return packet: version 3 is not 4", "wrong version"),
            (4, 5, "return packet: version 5 is not 4", "wrong version"),
            (
                5,
                0,
                "return packet: player_number value 0 out of range (valid: 1-20)",
                "invalid player number",
            ),
            (
                5,
                21,
                "return packet: player_number value 21 out of range (valid: 1-20)",
                "invalid player number",
            ),
            (7, 2, "return packet: fallen value 2 out of range (valid: 0-1)", "invalid fallen"),
            (7, 255, "return packet: fallen value 255 out of range (valid: 0-1)", "invalid fallen"),
        ];
        for &(offset, value, expected, reason) in cases {
            let mut bytes = good.clone();
            bytes[offset] = value;
            assert_eq!(err(&bytes), (expected.to_owned(), Some(reason)), "byte {offset} = {value}");
        }
        let floats = [
            ("pose[0]", "invalid pose"),
            ("pose[1]", "invalid pose"),
            ("pose[2]", "invalid pose"),
            ("ball_age", "invalid ball age"),
            ("ball[0]", "invalid ball"),
            ("ball[1]", "invalid ball"),
        ];
        for (i, (field, reason)) in floats.into_iter().enumerate() {
            // Any NaN, whatever its sign and payload.
            for nan in [f32::NAN, -f32::NAN, f32::from_bits(0x7F80_0001)] {
                let mut bytes = good.clone();
                bytes[8 + 4 * i..12 + 4 * i].copy_from_slice(&nan.to_le_bytes());
                assert_eq!(err(&bytes), (format!("return packet: {field} is NaN"), Some(reason)));
            }
        }
        // The first failing check is the one GameController3 stops at.
        let mut bytes = good.clone();
        bytes[5] = 0;
        bytes[7] = 9;
        assert_eq!(err(&bytes).1, Some("invalid player number"));
    }

    /// What GameController3 accepts and the decoder used to reject.
    #[test]
    fn return_packets_game_controller3_accepts_are_accepted() {
        let good = return_bytes();
        // Infinite floats: GameController3 checks only `is_nan`.
        let floats = ["pose[0]", "pose[1]", "pose[2]", "ball_age", "ball[0]", "ball[1]"];
        for (i, field) in floats.iter().enumerate() {
            for inf in [f32::INFINITY, f32::NEG_INFINITY] {
                let mut bytes = good.clone();
                bytes[8 + 4 * i..12 + 4 * i].copy_from_slice(&inf.to_le_bytes());
                let data = ReturnData::decode(&bytes);
                assert!(data.is_ok(), "{field} = {inf}: {data:?}");
                let encoded = data.map(|d| d.encode().map(|b| b.to_vec()));
                assert_eq!(encoded, Ok(Ok(bytes)), "{field} = {inf}");
            }
        }
        // Longer datagrams: GameController3 reads the first 32 bytes and ignores the rest.
        for extra in [1, 2, 100, 65_000] {
            let mut bytes = good.clone();
            bytes.resize(RETURN_PACKET_SIZE + extra, 0xAB);
            assert_eq!(ReturnData::decode(&bytes), Ok(return_sample()), "{extra} bytes more");
        }
        // Any team number, and absurd but finite values.
        let mut bytes = good;
        bytes[6] = 255;
        bytes[8..12].copy_from_slice(&f32::MAX.to_le_bytes());
        bytes[20..24].copy_from_slice(&(-1e30f32).to_le_bytes());
        let data = ReturnData::decode(&bytes).expect("GameController3 accepts it");
        assert_eq!((data.team_number, data.pose[0], data.ball_age), (255, f32::MAX, -1e30));
    }

    #[test]
    fn return_encode_refuses_what_the_gamecontroller_would_drop() {
        let mut data = return_sample();
        data.pose[2] = f32::NAN;
        assert!(matches!(data.encode(), Err(DecodeError::NotANumber { field: "pose[2]", .. })));
        let mut data = return_sample();
        data.player_number = 0;
        assert!(matches!(data.encode(), Err(DecodeError::OutOfRange { .. })));
        // What it would not drop is sent.
        let data = ReturnData { ball_age: f32::INFINITY, ..return_sample() };
        assert!(data.encode().is_ok());
    }

    #[test]
    fn control_errors_have_no_game_controller3_reason() {
        let error = GameControlData::decode(&return_bytes()).expect_err("a return packet");
        assert_eq!(error.game_controller3_reason(), None);
    }

    #[test]
    fn closed_enums_round_trip_and_reject_unknown_values() {
        for value in 0..=255u8 {
            if let Ok(state) = GameState::try_from(value) {
                assert_eq!(u8::from(state), value);
            } else {
                assert!(!GameState::VALUES.contains(&value));
            }
        }
        assert_eq!(GameState::try_from(5), Ok(GameState::Standby));
        assert_eq!(
            GameState::try_from(6).map_err(|e| e.to_string()),
            Err("state value 6 out of range (valid: 0, 1, 2, 3, 4, 5)".into())
        );
    }

    #[test]
    fn open_enums_keep_every_byte() {
        fn check<T: From<u8> + Into<u8> + Copy + fmt::Debug + PartialEq>(
            values: &[u8],
            unknown: fn(u8) -> T,
        ) {
            for value in 0..=255u8 {
                let typed = T::from(value);
                assert_eq!(typed.into(), value);
                assert_eq!(typed == unknown(value), !values.contains(&value), "{value}");
            }
        }
        check(TeamColour::VALUES, TeamColour::Unknown);
        check(CompetitionPhase::VALUES, CompetitionPhase::Unknown);
        check(CompetitionType::VALUES, CompetitionType::Unknown);
        check(GamePhase::VALUES, GamePhase::Unknown);
        check(SetPlay::VALUES, SetPlay::Unknown);
        check(Penalty::VALUES, Penalty::Unknown);
        assert_eq!(Penalty::from(14), Penalty::Substitute);
        assert_eq!(SetPlay::from(5), SetPlay::PenaltyKick);
        assert_eq!(TeamColour::VALUES.len(), 10);
        assert!(Penalty::Manual.is_known());
        assert!(!Penalty::Unknown(12).is_known());
    }

    #[test]
    fn detect_by_header() {
        assert_eq!(PacketKind::detect(&sample_bytes()), PacketKind::Control);
        assert_eq!(PacketKind::detect(&return_bytes()), PacketKind::Return);
        assert_eq!(PacketKind::detect(b"RGm"), PacketKind::Unknown);
        assert_eq!(PacketKind::detect(b"hello team"), PacketKind::Unknown);
    }

    #[test]
    fn helpers() {
        let data = sample();
        assert_eq!(data.team(5).map(|t| t.goalkeeper), Some(20));
        assert_eq!(data.team(6), None);
        let team = &data.teams[0];
        assert_eq!(team.player(3).map(|p| p.penalty), Some(Penalty::PlayerPushing));
        assert_eq!(team.player(0), None);
        assert_eq!(team.player(21), None);
        assert_eq!(data.game_secs_remaining(600), 300);
        let first = GameControlData { first_half: true, ..data };
        assert_eq!(first.game_secs_remaining(600), 900);
    }

    fn wire_value<T: TryFrom<u8> + fmt::Debug>(values: &'static [u8]) -> impl Strategy<Value = T> {
        proptest::sample::select(values).prop_filter_map("defined", |v| T::try_from(v).ok())
    }

    /// Any byte of an open enumeration, known or not.
    fn open_value<T: From<u8> + fmt::Debug>() -> impl Strategy<Value = T> {
        any::<u8>().prop_map(T::from)
    }

    fn robot_info() -> impl Strategy<Value = RobotInfo> {
        (open_value(), any::<u8>()).prop_map(|(penalty, secs_till_unpenalised)| RobotInfo {
            penalty,
            secs_till_unpenalised,
        })
    }

    fn team_info() -> impl Strategy<Value = TeamInfo> {
        (
            (any::<u8>(), open_value(), open_value(), any::<u8>()),
            (any::<u8>(), any::<u8>(), any::<u16>(), any::<u16>()),
            proptest::array::uniform20(robot_info()),
        )
            .prop_map(
                |((team_number, fp, gk, goalkeeper), (score, shot, shots, budget), players)| {
                    TeamInfo {
                        team_number,
                        field_player_colour: fp,
                        goalkeeper_colour: gk,
                        goalkeeper,
                        score,
                        penalty_shot: shot,
                        single_shots: shots,
                        message_budget: budget,
                        players,
                    }
                },
            )
    }

    fn control() -> impl Strategy<Value = GameControlData> {
        (
            (any::<u8>(), any::<u8>(), open_value(), open_value()),
            (open_value(), wire_value(GameState::VALUES), open_value()),
            (any::<bool>(), proptest::option::of(0..255u8), any::<i16>(), any::<i16>()),
            [team_info(), team_info()],
        )
            .prop_map(
                |((number, players, cphase, ctype), (gphase, state, set_play), rest, teams)| {
                    let (first_half, kicking_team, secs_remaining, secondary_time) = rest;
                    GameControlData {
                        packet_number: number,
                        players_per_team: players,
                        competition_phase: cphase,
                        competition_type: ctype,
                        game_phase: gphase,
                        state,
                        set_play,
                        first_half,
                        kicking_team,
                        secs_remaining,
                        secondary_time,
                        teams,
                    }
                },
            )
    }

    /// Any float GameController3 accepts: everything but NaN, infinities included.
    fn not_nan() -> impl Strategy<Value = f32> {
        prop_oneof![
            any::<f32>().prop_filter("not NaN", |v| !v.is_nan()),
            Just(f32::INFINITY),
            Just(f32::NEG_INFINITY),
        ]
    }

    fn return_data() -> impl Strategy<Value = ReturnData> {
        (
            1..=20u8,
            any::<u8>(),
            any::<bool>(),
            [not_nan(), not_nan(), not_nan()],
            not_nan(),
            [not_nan(), not_nan()],
        )
            .prop_map(|(player_number, team_number, fallen, pose, ball_age, ball)| {
                ReturnData { player_number, team_number, fallen, pose, ball_age, ball }
            })
    }

    proptest! {
        #[test]
        fn control_round_trip(data in control()) {
            prop_assert_eq!(GameControlData::decode(&data.encode()), Ok(data));
        }

        #[test]
        fn return_round_trip(data in return_data()) {
            let bytes = data.encode();
            prop_assert!(bytes.is_ok(), "{:?}", bytes);
            let decoded = bytes.map(|b| ReturnData::decode(&b));
            // Compare bit patterns: -0.0 and 0.0 must survive as themselves.
            let bits = |d: &ReturnData| (d.pose.map(f32::to_bits), d.ball_age.to_bits(), d.ball.map(f32::to_bits));
            match decoded {
                Ok(Ok(back)) => {
                    prop_assert_eq!(bits(&back), bits(&data));
                    prop_assert_eq!((back.player_number, back.team_number, back.fallen),
                        (data.player_number, data.team_number, data.fallen));
                }
                other => prop_assert!(false, "{:?}", other),
            }
        }

        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
            let _ = GameControlData::decode(&bytes);
            let _ = ReturnData::decode(&bytes);
            let _ = PacketKind::detect(&bytes);
        }

        #[test]
        fn valid_headers_with_arbitrary_bodies_never_panic(
            body in proptest::collection::vec(any::<u8>(), 114),
            ret in proptest::collection::vec(any::<u8>(), 28..40),
        ) {
            let mut control = CONTROL_HEADER.to_vec();
            control.extend(&body);
            control[4] = CONTROL_VERSION;
            if let Ok(data) = GameControlData::decode(&control) {
                prop_assert_eq!(data.encode().to_vec(), control);
            }
            let mut bytes = RETURN_HEADER.to_vec();
            bytes.extend(&ret);
            bytes[4] = RETURN_VERSION;
            if let Ok(data) = ReturnData::decode(&bytes) {
                // Only the first 32 bytes are the packet.
                prop_assert_eq!(data.encode().map(|b| b.to_vec()), Ok(bytes[..32].to_vec()));
            }
        }
    }
}
