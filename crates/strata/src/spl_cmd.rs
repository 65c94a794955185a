//! `strata spl`: look at SPL wire traffic — GameController control and return packets, team
//! messages — as JSON.

use std::io::Read;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::time::{SystemTime, UNIX_EPOCH};

use anyhow::{Context, Result, bail};
use clap::{Subcommand, ValueEnum};
use serde_json::{Value, json};
use strata_spl::gamecontroller::{GameControlData, PacketKind, RETURN_PACKET_SIZE, ReturnData};
use strata_spl::net::{self, MAX_TEAM_MESSAGE_SIZE};

/// The `spl` subcommands.
#[derive(Debug, Subcommand)]
pub enum SplCommand {
    /// Decode one raw packet and print it as JSON; the type is detected by header.
    Decode {
        /// File holding one packet's bytes, or "-" for stdin.
        file: String,
        /// Decode as this type instead of detecting it.
        #[arg(long, value_enum)]
        kind: Option<Kind>,
    },
    /// Print every datagram arriving on a UDP port as a JSON line, until Ctrl-C.
    Listen {
        /// 3838: control packets; 3939: return packets; 10000 + team: team messages.
        #[arg(long, default_value_t = net::GAMECONTROLLER_DATA_PORT)]
        port: u16,
        /// Local address to bind (the port is shared with robots on this machine).
        #[arg(long, default_value_t = IpAddr::V4(Ipv4Addr::UNSPECIFIED))]
        bind: IpAddr,
        /// Decode every datagram as this type. By default the port decides: everything on 3838
        /// is judged as a control packet and everything on 3939 as a return packet, as the
        /// robots and GameController3 judge what arrives there; on other ports the type is
        /// detected by header.
        #[arg(long, value_enum)]
        kind: Option<Kind>,
        /// Stop after this many datagrams.
        #[arg(long)]
        count: Option<u64>,
    },
}

/// A packet type to decode as.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Kind {
    /// RoboCupGameControlData ("RGme", version 18, 118 bytes).
    Control,
    /// RoboCupGameControlReturnData ("RGrt", version 4, 32 bytes), judged as GameController3
    /// judges it.
    Return,
    /// A team message: opaque bytes, at most 128.
    Team,
}

impl Kind {
    /// What a datagram on `port` is taken for whatever its first bytes: GameController3 judges
    /// every datagram on its return port as a return packet (one with a wrong header is dropped
    /// for that), and a robot every datagram on its control port as a control packet.
    fn received_on(port: u16) -> Option<Kind> {
        match port {
            net::GAMECONTROLLER_DATA_PORT => Some(Kind::Control),
            net::GAMECONTROLLER_RETURN_PORT => Some(Kind::Return),
            _ => None,
        }
    }
}

/// Runs an `spl` subcommand.
pub fn run(cmd: SplCommand) -> Result<()> {
    match cmd {
        SplCommand::Decode { file, kind } => {
            let bytes = read_input(&file)?;
            let description = describe(&bytes, kind);
            println!("{}", serde_json::to_string_pretty(&description)?);
            if let Some(error) = description.get("error").and_then(Value::as_str) {
                bail!("{file}: {error}");
            }
            Ok(())
        }
        SplCommand::Listen { port, bind, kind, count } => {
            listen(SocketAddr::new(bind, port), kind.or_else(|| Kind::received_on(port)), count)
        }
    }
}

fn read_input(file: &str) -> Result<Vec<u8>> {
    let mut bytes = Vec::new();
    if file == "-" {
        std::io::stdin().read_to_end(&mut bytes).context("cannot read stdin")?;
    } else {
        bytes = std::fs::read(file).with_context(|| format!("cannot read {file}"))?;
    }
    Ok(bytes)
}

fn listen(addr: SocketAddr, kind: Option<Kind>, count: Option<u64>) -> Result<()> {
    let socket = net::bind_shared(addr)?;
    eprintln!("listening on UDP {addr}");
    let mut buffer = vec![0u8; 65536];
    let mut seen = 0;
    while count.is_none_or(|n| seen < n) {
        let (size, from) = socket.recv_from(&mut buffer).context("UDP receive failed")?;
        let mut line = describe(&buffer[..size], kind);
        if let Value::Object(fields) = &mut line {
            let ms = SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_millis());
            fields.insert("from".into(), json!(from.to_string()));
            fields.insert("unix_ms".into(), json!(ms));
        }
        println!("{line}");
        seen += 1;
    }
    Ok(())
}

/// One datagram as JSON: its type, length, and the decoded packet or the decoder's error.
pub fn describe(bytes: &[u8], kind: Option<Kind>) -> Value {
    let kind = match (kind, PacketKind::detect(bytes)) {
        (Some(kind), _) => kind,
        (None, PacketKind::Control) => Kind::Control,
        (None, PacketKind::Return) => Kind::Return,
        (None, PacketKind::Unknown) => return opaque("unknown", bytes),
    };
    let decoded = match kind {
        Kind::Control => GameControlData::decode(bytes).map(|p| (json!(p), Vec::new())),
        Kind::Return => ReturnData::decode(bytes).map(|p| (json!(p), return_notes(&p, bytes))),
        Kind::Team => return opaque("team", bytes),
    };
    let name = match kind {
        Kind::Control => "control",
        Kind::Return => "return",
        Kind::Team => "team",
    };
    let mut value = match &decoded {
        Ok((packet, _)) => json!({ "kind": name, "length": bytes.len(), "packet": packet }),
        Err(e) => json!({
            "kind": name,
            "length": bytes.len(),
            "error": e.to_string(),
            "hex": hex_dump(bytes),
        }),
    };
    // The return decoder judges as GameController3's receiver does, so its verdict is
    // GameController3's, in GameController3's own words when it drops the packet.
    if kind == Kind::Return {
        value["game_controller3"] = json!(match &decoded {
            Ok(_) => "accepts".to_owned(),
            Err(e) => format!("drops it: {}", e.game_controller3_reason().unwrap_or("invalid")),
        });
    }
    if let Ok((_, notes)) = &decoded
        && !notes.is_empty()
    {
        value["notes"] = json!(notes);
    }
    value
}

/// What JSON and a first look at an accepted return packet would hide.
fn return_notes(data: &ReturnData, bytes: &[u8]) -> Vec<String> {
    let mut notes = Vec::new();
    if let Some(extra) = bytes.len().checked_sub(RETURN_PACKET_SIZE).filter(|&n| n > 0) {
        notes.push(format!(
            "{extra} bytes past the {RETURN_PACKET_SIZE}-byte packet: GameController3 ignores them"
        ));
    }
    let floats = [
        ("pose[0]", data.pose[0]),
        ("pose[1]", data.pose[1]),
        ("pose[2]", data.pose[2]),
        ("ball_age", data.ball_age),
        ("ball[0]", data.ball[0]),
        ("ball[1]", data.ball[1]),
    ];
    for (field, value) in floats.into_iter().filter(|(_, v)| v.is_infinite()) {
        notes.push(format!("{field} is {value} (null in JSON)"));
    }
    notes
}

/// Bytes that are not a GameController packet: on a team port, a team message.
fn opaque(kind: &str, bytes: &[u8]) -> Value {
    let mut value = json!({
        "kind": kind,
        "length": bytes.len(),
        "max_team_message_length": MAX_TEAM_MESSAGE_SIZE,
        "hex": hex_dump(bytes),
    });
    if bytes.len() > MAX_TEAM_MESSAGE_SIZE {
        value["error"] = json!(format!(
            "{} bytes exceed the {MAX_TEAM_MESSAGE_SIZE}-byte team message limit",
            bytes.len()
        ));
    }
    value
}

/// Classic 16-bytes-a-line dump: offset, hex, printable ASCII.
fn hex_dump(bytes: &[u8]) -> Vec<String> {
    bytes
        .chunks(16)
        .enumerate()
        .map(|(i, chunk)| {
            let hex: Vec<String> = chunk.iter().map(|b| format!("{b:02x}")).collect();
            let text: String = chunk
                .iter()
                .map(|&b| if b.is_ascii_graphic() || b == b' ' { char::from(b) } else { '.' })
                .collect();
            format!("{:08x}  {:<47}  |{text}|", i * 16, hex.join(" "))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use strata_spl::gamecontroller::GameState;

    #[test]
    fn detects_and_decodes_control_packets() {
        let data = GameControlData { state: GameState::Set, ..Default::default() };
        let out = describe(&data.encode(), None);
        assert_eq!(out["kind"], "control");
        assert_eq!(out["length"], 118);
        assert_eq!(out["packet"]["state"], "set");
        assert_eq!(out.get("error"), None);
    }

    #[test]
    fn reports_bad_packets_and_team_messages() {
        let out = describe(b"RGrt\x04", None);
        assert_eq!(out["kind"], "return");
        assert_eq!(out["error"], "return packet: too short: expected at least 32 bytes, got 5");
        assert_eq!(out["game_controller3"], "drops it: wrong length");
        let out = describe(b"hello", None);
        assert_eq!(out["kind"], "unknown");
        assert_eq!(
            out["hex"][0],
            "00000000  68 65 6c 6c 6f                                   |hello|"
        );
        assert_eq!(out.get("error"), None);
        let out = describe(&[0; 129], Some(Kind::Team));
        assert_eq!(out["kind"], "team");
        assert_eq!(out["error"], "129 bytes exceed the 128-byte team message limit");
        assert_eq!(out["hex"].as_array().map(Vec::len), Some(9));
    }

    fn return_packet() -> Vec<u8> {
        let data = ReturnData {
            player_number: 3,
            team_number: 12,
            fallen: false,
            pose: [1.0, 2.0, 0.5],
            ball_age: ReturnData::BALL_NEVER_SEEN,
            ball: [0.0, 0.0],
        };
        data.encode().expect("valid").to_vec()
    }

    /// Return packets are judged as GameController3 judges them, and a rejection
    /// says which check of GameController3's fails.
    #[test]
    fn return_packets_get_game_controller3s_verdict() {
        let good = return_packet();
        let out = describe(&good, None);
        assert_eq!((out["game_controller3"].as_str(), out.get("notes")), (Some("accepts"), None));
        assert_eq!(out["packet"]["player_number"], 3);

        let mut fallen = good.clone();
        fallen[7] = 2;
        let out = describe(&fallen, None);
        assert_eq!(out["error"], "return packet: fallen value 2 out of range (valid: 0-1)");
        assert_eq!(out["game_controller3"], "drops it: invalid fallen");

        let mut nan = good.clone();
        nan[20..24].copy_from_slice(&f32::NAN.to_le_bytes());
        let out = describe(&nan, None);
        assert_eq!(out["error"], "return packet: ball_age is NaN");
        assert_eq!(out["game_controller3"], "drops it: invalid ball age");

        // What GameController3 accepts although it looks wrong: said so, not rejected.
        let mut odd = good;
        odd[8..12].copy_from_slice(&f32::NEG_INFINITY.to_le_bytes());
        odd.extend([0; 4]);
        let out = describe(&odd, None);
        assert_eq!(out["game_controller3"], "accepts");
        assert_eq!(out.get("error"), None);
        assert_eq!(
            out["notes"],
            json!([
                "4 bytes past the 32-byte packet: GameController3 ignores them",
                "pose[0] is -inf (null in JSON)"
            ])
        );

        // A control packet on the return port, forced: GameController3's header check.
        let control = GameControlData::default().encode();
        let out = describe(&control, Some(Kind::Return));
        assert_eq!(out["game_controller3"], "drops it: wrong header");
        // Control packets are not GameController3's to judge.
        assert_eq!(describe(&control, None).get("game_controller3"), None);
    }

    /// A control packet with values this version does not know decodes, and shows
    /// them raw.
    #[test]
    fn control_packets_show_unknown_values_raw() {
        let mut bytes = GameControlData::default().encode();
        bytes[8] = 9; // competition type
        bytes[11] = 7; // set play
        let out = describe(&bytes, None);
        assert_eq!(out.get("error"), None);
        assert_eq!(out["packet"]["competition_type"], json!({ "unknown": 9 }));
        assert_eq!(out["packet"]["set_play"], json!({ "unknown": 7 }));
    }
}
