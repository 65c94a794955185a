//! The agent and monitor protocols of rcssservermj (PyPI `rcsssmj` 0.2.1), the RoboCup soccer
//! simulation league's MuJoCo server: framing, S-expressions, perceptions in SI units, effector
//! and trainer-command encoding. docs/rcssservermj-protocol.md describes the protocol.

mod base64;
mod effector;
mod frame;
mod game;
pub mod monitor;
mod perception;
pub mod sexp;

use thiserror::Error;

pub use effector::{
    Effector, InitRequest, JointCommand, MAX_SAY_BYTES, T1_SPEAKER, encode_effectors, encode_init,
};
pub use frame::{FrameError, MAX_MONITOR_FRAME, MAX_PERCEPTION_FRAME, read_frame, write_frame};
pub use game::{FieldSide, PlayMode};
pub use perception::{
    GameStatePerceptor, HeardMessage, JointPerceptor, Perception, Polar, SeenMarker, SeenObject,
    SeenRobot, decode_perception,
};
pub use sexp::SexpError;

/// Why a message could not be decoded, encoded or exchanged.
#[derive(Debug, Error)]
pub enum ProtocolError {
    /// The text is not a sequence of S-expressions.
    #[error("malformed S-expression: {0}")]
    Syntax(#[from] SexpError),
    /// A known perceptor does not have the expected shape.
    #[error("malformed {perceptor} perceptor: {reason}")]
    Perceptor {
        /// The perceptor's name (`GS`, `HJ`, `See`…).
        perceptor: &'static str,
        /// What was wrong.
        reason: String,
    },
    /// The server sent `(error)`: it failed to encode this cycle's perception.
    #[error("the server sent (error) instead of a perception")]
    ServerError,
    /// An effector or command cannot be encoded so that the server reads it as meant.
    #[error("invalid {effector}: {reason}")]
    Effector {
        /// The effector's or command's name.
        effector: &'static str,
        /// What was wrong.
        reason: String,
    },
    /// A monitor message does not have the expected shape.
    #[error("malformed monitor message: {reason}")]
    Monitor {
        /// What was wrong.
        reason: String,
    },
    /// Reading or writing a frame failed.
    #[error(transparent)]
    Frame(#[from] FrameError),
    /// Connecting to the server failed.
    #[error("cannot connect to rcssservermj at {address}: {source}")]
    Connect {
        /// The address tried last.
        address: String,
        /// Why.
        #[source]
        source: std::io::Error,
    },
}
