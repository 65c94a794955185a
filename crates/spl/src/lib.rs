//! The league: the RoboCup Standard Platform League as pure data and wire formats, no robot.
//!
//! - [`field`]: field dimensions (TOML presets `spl` and `paper2010`), landmarks, lines,
//!   goals and referee helpers, in the field frame.
//! - [`objects`]: what a camera can detect, with stable codes shared by simulator and robot.
//! - [`motions`]: the names of the special motions soccer orders and the simulators run.
//! - [`gamecontroller`]: control packets (`RGme` v18) and return packets (`RGrt` v4).
//! - [`net`]: UDP sockets for GameController packets and team messages.

pub mod field;
pub mod gamecontroller;
pub mod motions;
pub mod net;
pub mod objects;

pub use field::{Field, FieldDimensions, FieldError, Landmark, Point, Side};
pub use gamecontroller::{DecodeError, GameControlData, GameState, PacketKind, ReturnData};
pub use net::{GameControllerSocket, MAX_TEAM_MESSAGE_SIZE, NetError, TeamSocket};
pub use objects::{Gesture, LandmarkKind, ObjectKind};
