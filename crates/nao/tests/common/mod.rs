//! A stand-in for LoLA: a Unix socket in a temp dir that sends recorded-style sensor packets,
//! paced at LoLA's 12 ms, and decodes every actuator packet it gets back.
//!
//! Tests drive it step by step (`send`, then `reply`), so they assert on content and order,
//! never on timing; the generous receive guard only turns a hang into a failure.

#![allow(dead_code)]

use std::io::{Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::time::Duration;

use strata_nao::codec::{Battery, touch};
use strata_nao::{ActuatorPacket, CodecError, JOINT_COUNT, Joint, RobotConfig, SensorPacket};

/// Only a guard against hangs; tests never assert that anything happens within it.
pub const GUARD: Duration = Duration::from_secs(20);

pub const HEAD_ID: &str = "P0000073A07S9AB00123";
pub const BODY_ID: &str = "P0000074A05S94300042";

/// A sensor packet like the ones a NAO v6 standing still sends, varying a little from cycle to
/// cycle the way a recording does (sensor noise, a draining battery).
pub fn recorded_packet(cycle: u32) -> SensorPacket {
    let c = cycle as f32;
    let wobble = |phase: f32, amplitude: f32| amplitude * (0.37 * c + phase).sin();
    let mut position = [0.0f32; JOINT_COUNT];
    for (joint, angle) in [
        (Joint::HeadYaw, 0.0),
        (Joint::HeadPitch, 0.1),
        (Joint::LShoulderPitch, 1.57),
        (Joint::LShoulderRoll, 0.14),
        (Joint::LElbowYaw, -1.22),
        (Joint::LElbowRoll, -0.44),
        (Joint::RShoulderPitch, 1.57),
        (Joint::RShoulderRoll, -0.14),
        (Joint::RElbowYaw, 1.22),
        (Joint::RElbowRoll, 0.44),
        (Joint::LHipPitch, -0.4),
        (Joint::LKneePitch, 0.8),
        (Joint::LAnklePitch, -0.4),
        (Joint::RHipPitch, -0.4),
        (Joint::RKneePitch, 0.8),
        (Joint::RAnklePitch, -0.4),
    ] {
        position[joint.index()] = angle + wobble(joint.index() as f32, 0.002);
    }
    SensorPacket {
        stiffness: [0.0; JOINT_COUNT],
        position,
        temperature: std::array::from_fn(|i| 30.0 + (i % 7) as f32),
        current: std::array::from_fn(|i| 0.05 * (i % 3) as f32),
        battery: Battery([0.9 - 1e-5 * c, 0.0, -1.4, 33.0]),
        accelerometer: [0.12 + wobble(0.0, 0.05), -0.03 + wobble(1.0, 0.05), -9.79],
        gyroscope: [wobble(2.0, 0.004), wobble(3.0, 0.004), wobble(4.0, 0.002)],
        angles: [0.012 + wobble(5.0, 0.002), 0.021 + wobble(6.0, 0.002)],
        sonar: [1.84, 2.51],
        fsr: [0.61, 0.55, 0.48, 0.52, 0.57, 0.6, 0.5, 0.47],
        touch: [0.0; touch::COUNT],
        status: std::array::from_fn(|i| i32::from(i == 10)),
        robot_config: RobotConfig {
            body_id: BODY_ID.into(),
            body_version: "6.0.0".into(),
            head_id: HEAD_ID.into(),
            head_version: "6.0.0".into(),
        },
    }
}

/// A unique socket path in the temp dir (never `/tmp/robocup`).
pub fn socket_path() -> PathBuf {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    std::env::temp_dir().join(format!("strata-nao-{}-{n}-{nanos}.sock", std::process::id()))
}

enum Item {
    Bytes(Vec<u8>),
    Close,
}

/// What the fake server saw back from the platform.
pub type Reply = Result<ActuatorPacket, CodecError>;

pub struct FakeLola {
    path: PathBuf,
    items: Sender<Item>,
    replies: Receiver<Reply>,
    sent: u32,
}

impl FakeLola {
    /// Listens on a fresh socket; the connection is accepted when the platform connects.
    pub fn start() -> FakeLola {
        let path = socket_path();
        let listener = UnixListener::bind(&path).expect("bind the fake LoLA socket");
        let (items, item_rx) = mpsc::channel::<Item>();
        let (reply_tx, replies) = mpsc::channel::<Reply>();
        std::thread::spawn(move || {
            let Ok((stream, _)) = listener.accept() else { return };
            let Ok(reader) = stream.try_clone() else { return };
            std::thread::spawn(move || read_replies(reader, reply_tx));
            write_items(stream, item_rx);
        });
        FakeLola { path, items, replies, sent: 0 }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Queues one sensor packet (sent 12 ms after the previous item).
    pub fn send(&mut self, packet: &SensorPacket) {
        self.send_raw(packet.encode().expect("encode a sensor packet"));
    }

    /// Queues the next recorded packet.
    pub fn send_recorded(&mut self) {
        let packet = recorded_packet(self.sent);
        self.send(&packet);
    }

    /// Queues arbitrary bytes (a truncated or malformed packet).
    pub fn send_raw(&mut self, bytes: Vec<u8>) {
        self.sent += 1;
        let _ = self.items.send(Item::Bytes(bytes));
    }

    /// Closes the connection after everything queued so far.
    pub fn close(&mut self) {
        let _ = self.items.send(Item::Close);
    }

    /// The next actuator packet the platform sent back.
    pub fn reply(&self) -> ActuatorPacket {
        match self.replies.recv_timeout(GUARD) {
            Ok(Ok(packet)) => packet,
            Ok(Err(error)) => panic!("the platform sent a malformed actuator packet: {error}"),
            Err(RecvTimeoutError::Timeout) => panic!("no actuator packet from the platform"),
            Err(RecvTimeoutError::Disconnected) => panic!("the platform closed the connection"),
        }
    }

    /// Sends a recorded packet and returns the platform's answer to it.
    pub fn exchange(&mut self) -> ActuatorPacket {
        self.send_recorded();
        self.reply()
    }

    /// Sends `packet` and returns the answer.
    pub fn exchange_with(&mut self, packet: &SensorPacket) -> ActuatorPacket {
        self.send(packet);
        self.reply()
    }
}

impl Drop for FakeLola {
    fn drop(&mut self) {
        let _ = self.items.send(Item::Close);
        let _ = std::fs::remove_file(&self.path);
    }
}

fn write_items(mut stream: UnixStream, items: Receiver<Item>) {
    while let Ok(item) = items.recv() {
        match item {
            Item::Bytes(bytes) => {
                if stream.write_all(&bytes).is_err() {
                    return;
                }
                // LoLA's pace; only the order of packets matters to the tests.
                std::thread::sleep(Duration::from_millis(12));
            }
            Item::Close => {
                let _ = stream.shutdown(std::net::Shutdown::Both);
                return;
            }
        }
    }
}

fn read_replies(mut stream: UnixStream, replies: Sender<Reply>) {
    let mut buffer = Vec::new();
    let mut chunk = [0u8; 4096];
    loop {
        match stream.read(&mut chunk) {
            Ok(0) | Err(_) => return,
            Ok(n) => buffer.extend_from_slice(&chunk[..n]),
        }
        loop {
            match strata_nao::value_len(&buffer) {
                Ok(Some(len)) => {
                    let reply = ActuatorPacket::decode(&buffer[..len]);
                    buffer.drain(..len);
                    if replies.send(reply).is_err() {
                        return;
                    }
                }
                Ok(None) => break,
                Err(error) => {
                    let _ = replies.send(Err(error));
                    return;
                }
            }
        }
    }
}
