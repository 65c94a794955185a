//! Writes the committed seed corpus, `fuzz/seeds/<target>/`, from the crates' own encoders (and
//! the captured rcssservermj messages of crates/rcssmj/tests/data). Deterministic: running it
//! again rewrites the same bytes, so `git status` after a run shows only what an encoder change
//! moved.
//!
//! ```sh
//! cd fuzz && cargo run --example seeds          # replaces fuzz/seeds/
//! ```
//!
//! Without seeds libFuzzer rarely gets past a magic (`b"ST"`, `RGme`, an MCAP header) in a short
//! run; each target gets a few valid inputs and a few near misses (truncated, one byte off).

use std::collections::BTreeMap;
use std::f32::consts::FRAC_PI_2;
use std::path::{Path, PathBuf};

use strata_log::{LogCompression, LogReader, McapTap, McapTapOptions, RunInfo};
use strata_nao::SensorPacket;
use strata_robot::control::planning::{SharedObject, StandingStatus, TeamMessage};
use strata_robot::geometry::{Odometry, Point, Pose};
use strata_robot::percept::Percepts;
use strata_robot::platform::{
    BodyMotionState, HeadAngles, MotionFeedback, MotionName, SpecialMotion,
};
use strata_runtime::Time;
use strata_soccer::catalog::{Mission, Role};
use strata_spl::gamecontroller::{
    GameControlData, GamePhase, GameState, Penalty, ReturnData, RobotInfo, SetPlay, TeamColour,
};

type Seeds = BTreeMap<String, Vec<u8>>;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let fuzz_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let root = fuzz_dir.join("seeds");
    let targets: [(&str, Seeds); 11] = [
        ("control_packet", control_packets()),
        ("return_packet", return_packets()?),
        ("team_message", team_messages()?),
        ("lola_sensor", sensor_packets()?),
        ("rcss_perception", rcss_messages(&fuzz_dir.join("../crates/rcssmj/tests/data"))?),
        ("sim_protocol", sim_messages()),
        ("log_reader", logs()?),
        ("cdr", cdr_payloads()?),
        ("view_request", view_requests()),
        ("gaze_policy", gaze_policies(&fuzz_dir.join("../crates/experiments/data"))?),
        ("walk_policy", walk_policies(&fuzz_dir.join("../crates/rcssmj/assets/t1"))?),
    ];
    for (target, seeds) in targets {
        let dir = root.join(target);
        // Replaced whole, so a seed renamed or dropped here does not linger.
        if dir.exists() {
            std::fs::remove_dir_all(&dir)?;
        }
        std::fs::create_dir_all(&dir)?;
        let bytes: usize = seeds.values().map(Vec::len).sum();
        for (name, data) in &seeds {
            std::fs::write(dir.join(name), data)?;
        }
        println!("{target}: {} seeds, {bytes} bytes", seeds.len());
    }
    Ok(())
}

/// The valid seeds under their names, plus the near misses every binary format shares: empty,
/// the first valid seed cut in half and without its last byte.
fn with_near_misses(valid: Seeds) -> Seeds {
    let mut seeds = valid.clone();
    seeds.insert("edge-empty".into(), Vec::new());
    if let Some((_, first)) = valid.iter().next() {
        seeds.insert("edge-half".into(), first[..first.len() / 2].to_vec());
        seeds.insert("edge-short-by-one".into(), first[..first.len().saturating_sub(1)].to_vec());
    }
    seeds
}

/// The shipped learned gaze (its tensors' names and shapes are what the loader checks), and its
/// near misses.
fn gaze_policies(data: &Path) -> Result<Seeds, Box<dyn std::error::Error>> {
    let shipped = std::fs::read(data.join("gaze-policy.safetensors"))?;
    Ok(with_near_misses(Seeds::from([("shipped".into(), shipped)])))
}

/// The shipped T1 walking network and its near misses.
fn walk_policies(assets: &Path) -> Result<Seeds, Box<dyn std::error::Error>> {
    let shipped = std::fs::read(assets.join("t1.safetensors"))?;
    Ok(with_near_misses(Seeds::from([("shipped".into(), shipped)])))
}

fn control_packets() -> Seeds {
    let initial = GameControlData::default();
    let mut playing = GameControlData {
        packet_number: 42,
        players_per_team: 7,
        state: GameState::Playing,
        set_play: SetPlay::KickIn,
        first_half: false,
        kicking_team: Some(12),
        secs_remaining: 300,
        secondary_time: -5,
        ..GameControlData::default()
    };
    playing.teams[0].team_number = 12;
    playing.teams[0].field_player_colour = TeamColour::Red;
    playing.teams[0].goalkeeper = 1;
    playing.teams[0].score = 3;
    playing.teams[0].message_budget = 1200;
    playing.teams[0].players[2] =
        RobotInfo { penalty: Penalty::PlayerPushing, secs_till_unpenalised: 45 };
    playing.teams[1].team_number = 5;
    playing.teams[1].field_player_colour = TeamColour::Gray;
    playing.teams[1].goalkeeper = 20;
    playing.teams[1].players[19] =
        RobotInfo { penalty: Penalty::Manual, secs_till_unpenalised: 255 };
    let shootout = GameControlData {
        game_phase: GamePhase::PenaltyShoot,
        state: GameState::Set,
        set_play: SetPlay::None,
        kicking_team: Some(5),
        ..playing
    };
    let mut seeds = with_near_misses(Seeds::from([
        ("initial".into(), initial.encode().to_vec()),
        ("playing-kick-in".into(), playing.encode().to_vec()),
        ("penalty-shoot-out".into(), shootout.encode().to_vec()),
    ]));
    // A version the decoder refuses: the header is right, the version byte is not 18.
    let mut old = playing.encode().to_vec();
    old[4] = 17;
    seeds.insert("edge-version-17".into(), old);
    seeds
}

fn return_packets() -> Result<Seeds, Box<dyn std::error::Error>> {
    let standing = ReturnData {
        player_number: 3,
        team_number: 12,
        fallen: false,
        pose: [-1500.0, 250.0, FRAC_PI_2],
        ball_age: 0.4,
        ball: [800.0, -120.0],
    };
    let fallen = ReturnData {
        player_number: 20,
        fallen: true,
        ball_age: ReturnData::BALL_NEVER_SEEN,
        ball: [0.0, 0.0],
        ..standing
    };
    let mut seeds = with_near_misses(Seeds::from([
        ("fallen-never-saw-ball".into(), fallen.encode()?.to_vec()),
        ("standing".into(), standing.encode()?.to_vec()),
    ]));
    // A NaN ball age: the decoder refuses non-finite floats.
    let mut nan = standing.encode()?.to_vec();
    nan[20..24].copy_from_slice(&f32::NAN.to_le_bytes());
    seeds.insert("edge-nan-ball-age".into(), nan);
    Ok(seeds)
}

fn team_messages() -> Result<Seeds, Box<dyn std::error::Error>> {
    let striker = TeamMessage {
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
        signal: None,
    };
    let goalie = TeamMessage {
        sender: 1,
        mission: Mission::DefendTheGoal,
        role: Role::Goalie,
        status: StandingStatus::Stable,
        conflict: false,
        pose: Pose::new(-4.5, 0.0, 0.0),
        objects: Vec::new(),
        ..striker.clone()
    };
    // Headings at the edge of ±pi are where the wrap (see the target) shows.
    let turned = TeamMessage {
        sender: 20,
        pose: Pose::new(0.0, 0.0, std::f64::consts::PI),
        objects: vec![
            striker.objects[0].clone(),
            SharedObject {
                name: "obstacle".into(),
                position: Point::new(-1.0, 1.0),
                sigma: 0.3,
                confidence: 0.2,
                age: 2.0,
            },
        ],
        ..striker.clone()
    };
    let encode = strata_soccer::message::encode;
    Ok(with_near_misses(Seeds::from([
        ("goalie".into(), encode(&goalie)?),
        ("striker-cover-with-ball".into(), encode(&striker)?),
        ("turned-pi-two-objects".into(), encode(&turned)?),
    ])))
}

fn sensor_packets() -> Result<Seeds, Box<dyn std::error::Error>> {
    let zero = SensorPacket::default();
    let mut standing = SensorPacket::default();
    for (i, position) in standing.position.iter_mut().enumerate() {
        *position = 0.05 * i as f32 - 0.5;
    }
    standing.stiffness = [1.0; strata_nao::JOINT_COUNT];
    standing.temperature = [35.0; strata_nao::JOINT_COUNT];
    standing.battery.0 = [0.8, 128.0, -0.5, 27.0];
    standing.accelerometer = [0.1, -0.2, -9.81];
    standing.gyroscope = [0.0, 0.01, -0.02];
    standing.angles = [0.02, -0.01];
    standing.sonar = [0.8, 5.0];
    standing.fsr = [0.5; 8];
    standing.robot_config.body_id = "P0000073A07S93D00019".into();
    standing.robot_config.body_version = "6.0.0".into();
    standing.robot_config.head_id = "P0000074A05S93R00072".into();
    standing.robot_config.head_version = "6.0.0".into();
    let mut seeds = with_near_misses(Seeds::from([
        ("standing".into(), standing.encode()?),
        ("zero".into(), zero.encode()?),
    ]));
    // One byte after a complete map: refused as trailing bytes.
    let mut trailing = zero.encode()?;
    trailing.push(0xc0);
    seeds.insert("edge-trailing-nil".into(), trailing);
    Ok(seeds)
}

/// The captured server messages as they are (the target reads each input both as one message and
/// as a length-prefixed stream, which `perception_stream.bin` is).
fn rcss_messages(data: &Path) -> Result<Seeds, Box<dyn std::error::Error>> {
    let mut seeds = Seeds::new();
    let mut names: Vec<PathBuf> =
        std::fs::read_dir(data)?.map(|entry| entry.map(|e| e.path())).collect::<Result<_, _>>()?;
    names.sort();
    for path in names {
        let Some(name) = path.file_name().and_then(|n| n.to_str()) else { continue };
        if name.ends_with(".sexp") || name.ends_with(".bin") {
            seeds.insert(name.to_owned(), std::fs::read(&path)?);
        }
    }
    if seeds.is_empty() {
        return Err(format!("no captured messages in {}", data.display()).into());
    }
    seeds.insert(
        "edge-unbalanced".into(),
        b"((time (now 1.0)) (GS (t 0.00) (pm BeforeKickOff))".to_vec(),
    );
    seeds.insert("edge-deep".into(), [b"(".repeat(5000), b")".repeat(5000)].concat());
    Ok(seeds)
}

/// The examples of docs/sim-protocol.md, as bare messages and as one length-prefixed stream.
fn sim_messages() -> Seeds {
    let messages = [
        ("hello", r#"{"type":"hello","protocol":"strata-sim","version":1,"team":10,"player":1}"#),
        (
            "orders-walk",
            r#"{"type":"orders","orders":{"head":{"target":{"yaw":0.3,"pitch":0.2},"max_speed":2.0},"body":{"order":"walk","velocity":{"vx":0.2,"vy":0.0,"omega":0.1}}}}"#,
        ),
        (
            "orders-kick",
            r#"{"type":"orders","orders":{"head":null,"body":{"order":"special","motion":{"kind":"kick","sequence":0}}}}"#,
        ),
        (
            "orders-application-motion",
            r#"{"type":"orders","orders":{"head":null,"body":{"order":"special","motion":{"kind":"wave","sequence":2,"head":false}}}}"#,
        ),
        ("team-message", r#"{"type":"team_message","payload":"0a0b0c"}"#),
        ("goodbye", r#"{"type":"goodbye"}"#),
        (
            "error",
            r#"{"type":"error","code":"frame_too_large","message":"frame of 10000000 bytes exceeds the limit of 65536"}"#,
        ),
        (
            "server-team-message",
            r#"{"type":"team_message","received":1234000000,"payload":"5354"}"#,
        ),
    ];
    let mut seeds = Seeds::new();
    let mut stream = Vec::new();
    for (name, text) in messages {
        seeds.insert(name.into(), text.as_bytes().to_vec());
        stream.extend_from_slice(&(text.len() as u32).to_le_bytes());
        stream.extend_from_slice(text.as_bytes());
    }
    seeds.insert("stream-all".into(), stream);
    seeds.insert("edge-odd-hex".into(), br#"{"type":"team_message","payload":"abc"}"#.to_vec());
    seeds.insert("edge-frame-too-large".into(), [0xff, 0xff, 0xff, 0xff, b'{'].to_vec());
    seeds
}

/// A tiny log (run info, a CDR record, a MessagePack record), uncompressed and lz4, plus the
/// uncompressed one cut short (the reader recovers up to its last complete chunk).
fn logs() -> Result<Seeds, Box<dyn std::error::Error>> {
    let dir = std::env::temp_dir().join(format!("strata-fuzz-seeds-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let mut seeds = Seeds::new();
    for (name, compression) in [("tiny", LogCompression::None), ("tiny-lz4", LogCompression::Lz4)] {
        let path = dir.join(format!("{name}.mcap"));
        let log = McapTap::create(&path, McapTapOptions { compression, ..Default::default() })?;
        // Not RunInfo::current: the command line and build profile would make the seed depend
        // on how the generator ran.
        log.write_run_info(&RunInfo {
            seed: 7,
            command_line: vec!["strata".into(), "sim".into()],
            version: "strata 0.1.0 (seed)".into(),
            config: None,
        })?;
        for step in 1..=3u64 {
            let t = Time::from_nanos(step * 100_000_000);
            let odometry = Odometry { dx: 0.01 * step as f64, dy: 0.0, dtheta: -0.02 };
            log.record_value("motion/odometry", t, &odometry);
            let truth = serde_json::json!({ "ball": { "x": step as f64 * 0.01, "y": 0.0 } });
            log.record("sim/ground_truth", "demo::GroundTruth", t, &truth);
        }
        log.finish()?;
        seeds.insert(name.into(), std::fs::read(&path)?);
    }
    std::fs::remove_dir_all(&dir)?;
    let tiny = seeds["tiny"].clone();
    // The writer must have produced something the reader opens, or the seeds are useless.
    let check = std::env::temp_dir().join(format!("strata-fuzz-seeds-{}.mcap", std::process::id()));
    std::fs::write(&check, &tiny)?;
    let opened = LogReader::open(&check).map(|r| r.message_count());
    std::fs::remove_file(&check)?;
    if opened? != 6 {
        return Err("the tiny log does not read back 6 messages".into());
    }
    let cut = tiny[..tiny.len() * 2 / 3].to_vec();
    seeds.insert("edge-truncated".into(), cut);
    seeds.insert("edge-magic-only".into(), tiny[..8].to_vec());
    Ok(seeds)
}

/// CDR payloads of logged representations; the target reads each against every format.
fn cdr_payloads() -> Result<Seeds, Box<dyn std::error::Error>> {
    fn cdr<T: serde::Serialize>(value: &T) -> Result<Vec<u8>, strata_runtime::cdr::CdrError> {
        let mut out = Vec::new();
        strata_runtime::cdr::encode(value, &mut out)?;
        Ok(out)
    }
    let feedback = MotionFeedback {
        stamp: Time::from_nanos(1_234_000_000),
        body: BodyMotionState::Standing,
        head: HeadAngles { yaw: 0.3, pitch: 0.2 },
        head_settled: true,
        odometry: Odometry { dx: 0.01, dy: -0.002, dtheta: 0.03 },
    };
    let odometry = cdr(&feedback.odometry)?;
    // Soccer's kick is written as the robot crate's enum wrote it; a motion of an
    // application's own carries its name, the one text in the feedback.
    let special = |motion| MotionFeedback {
        body: BodyMotionState::Special { motion, elapsed: 0.25, duration: 1.5 },
        ..feedback
    };
    let kicking = special(strata_soccer::motions::kick(1));
    let waving = special(SpecialMotion::new(MotionName::from_static("wave"), 2, false));
    let mut seeds = with_near_misses(Seeds::from([
        ("motion-feedback".into(), cdr(&feedback)?),
        ("motion-feedback-kicking".into(), cdr(&kicking)?),
        ("motion-feedback-named".into(), cdr(&waving)?),
        ("odometry".into(), odometry),
        ("percepts-default".into(), cdr(&Percepts::default())?),
    ]));
    // A sequence length far beyond the bytes: must be refused without allocating it.
    let mut huge = cdr(&Percepts::default())?;
    huge.extend_from_slice(&u32::MAX.to_le_bytes());
    seeds.insert("edge-huge-length".into(), huge);
    Ok(seeds)
}

fn view_requests() -> Seeds {
    let requests: [(&str, &[u8]); 8] = [
        ("get-root", b"GET / HTTP/1.1\r\nHost: localhost:8080\r\n\r\n"),
        (
            "get-state-query",
            b"GET /state?t=12.5&robot=blue%2F3 HTTP/1.1\r\nHost: 127.0.0.1:8080\r\nUser-Agent: x\r\n\r\n",
        ),
        ("head-ipv6", b"HEAD /index.html HTTP/1.1\r\nHost: [::1]:8080\r\n\r\n"),
        ("http10-no-host", b"GET /events HTTP/1.0\r\n\r\n"),
        ("edge-foreign-host", b"GET / HTTP/1.1\r\nHost: evil.example:8080\r\n\r\n"),
        ("edge-post", b"POST /state HTTP/1.1\r\nHost: localhost\r\nContent-Length: 2\r\n\r\nhi"),
        ("edge-no-blank-line", b"GET / HTTP/1.1\r\nHost: localhost\r\n"),
        ("edge-invalid-utf8", b"GET /\xff\xfe?t=\xc3 HTTP/1.1\r\nHost: localhost\r\n\r\n"),
    ];
    requests.into_iter().map(|(name, bytes)| (name.to_owned(), bytes.to_vec())).collect()
}
