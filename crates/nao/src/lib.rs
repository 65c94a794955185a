//! The NAO v6 platform: LoLA's msgpack codec, key-frame motions, and [`LolaPlatform`], a
//! Strata [`strata_robot::platform::Platform`] over LoLA's Unix socket (`/tmp/robocup`).
//!
//! - [`codec`]: sensor and actuator maps, decoded with errors that name the key, and a stream
//!   framer that survives truncated and garbled packets.
//! - [`keyframe`]: key-frame sequences as TOML data (`crates/nao/motions/`), validated against
//!   the joint limits, and their interpolating player.
//! - [`controller`]: one LoLA cycle of motion control (head interpolation, sequences, fall
//!   detection), pure and testable without a robot.
//! - [`gait`]: the [`GaitEngine`] trait a walking engine implements; [`NoGait`] until then.
//! - [`platform`]: the socket thread and the `Platform` implementation.
//!
//! Deployment notes are in `docs/nao.md`.

pub mod codec;
pub mod controller;
pub mod gait;
pub mod joints;
pub mod keyframe;
pub mod platform;

pub use codec::{
    ActuatorPacket, CodecError, DEFAULT_SOCKET_PATH, KeyProblem, Leds, PacketFramer, Rgb,
    RobotConfig, SENSOR_PACKET_SIZE, SensorPacket, value_len,
};
pub use controller::{CYCLE, MotionConfig, MotionController};
pub use gait::{GaitEngine, GaitError, GaitStep, NoGait};
pub use joints::{JOINT_COUNT, Joint, JointArray};
pub use keyframe::{KeyFrameSequence, MotionError, MotionLibrary, Player};
pub use platform::{LolaConfig, LolaError, LolaPlatform, LolaStats, buttons, sensor_frame};
