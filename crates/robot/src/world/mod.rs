//! World modeling (paper 3.1): several Extended Kalman Filters, one per object of interest and
//! one for the robot's own pose.
//!
//! - Every object of interest has its own EKF in the robot's frame ([`ObjectFilter`]),
//!   predicted with odometry (and its uncertainty) and corrected by that object's observations.
//!   Objects are tracked while the robot's pose is uncertain, so it can act on them anyway.
//! - The robot-pose EKF ([`PoseFilter`]) takes the landmark filters' estimates as its
//!   observations against the known map: what each landmark filter gained in a frame, so no
//!   observation counts twice.
//! - The landmark filters also give the odometry's error (even when the pose is lost), the map
//!   accuracy (estimated against known landmark map) and, when the robot is lost or kidnapped,
//!   the hypotheses it relocalizes from.
//! - Each object has a confidence in [0, 1] from its covariance, the time since it was seen and
//!   negative information (not seen where it should have been); below a threshold it is
//!   "unknown".
//! - [`WorldState::expected_update`] simulates the correction stage for active vision (3.6).
//! - Teammates' estimates are fused into team objects (MAWM, 3.3).
//!
//! Application-agnostic: the objects of interest and the map are configuration
//! ([`WorldModelConfig`]). Design notes: `docs/world-model.md`.

mod config;
mod expected;
mod expected_lines;
mod math;
mod model;
mod module;
mod object;
mod odometry_error;
mod pose;
mod published;
mod recovery;
mod state;
mod team;
mod wire;

pub use config::{
    AssociationConfig, CameraNoise, ConfidenceConfig, ConfigError, FieldLinesConfig, MAX_INSTANCES,
    ObjectConfidence, ObjectKind, ObjectOfInterest, OdometryNoise, PoseConfig, PoseFeed, PosePrior,
    Region, SymmetryHint, TeamConfig, WorldModelConfig, validate_hint, validate_pose_prior,
};
pub use expected::{
    ExpectedBelief, ExpectedObject, ExpectedObservation, ObservationPrior, PredictedObservation,
    SensingCandidate, predicted_measurement,
};
pub use expected_lines::ExpectedLineObservation;
pub use math::{Innovation, RangeBearing, chi2_2dof_quantile};
pub use model::{WorldCommand, WorldModel};
pub use module::{PERCEPT_QUEUE, WorldModule, WorldPorts, add_world_module};
pub use object::{
    GainedInformation, MotionModel, ObjectFilter, cartesian_noise_at, posterior_position_covariance,
};
pub use pose::{PoseFilter, pose_posterior_covariance};
pub use state::{
    LostReason, MapAccuracy, ObjectCategory, ObjectEstimate, ObjectId, ObjectIndex, ObjectInfo,
    OdometryErrorEstimate, PoseEstimate, WorldDiagnostics, WorldLayout, WorldState,
};
pub use team::{
    Fused, FusionCandidate, SharedObject, Source, TeamError, TeamFusion, TeamObject,
    TeammateEstimate, fuse,
};
