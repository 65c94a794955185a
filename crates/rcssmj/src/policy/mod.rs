//! The Booster T1's walking policy: Booster Robotics' published locomotion network (booster_gym,
//! Apache-2.0) and the controller around it, as the deployment runs it.
//!
//! Once per 20 ms control step, [`WalkPolicy::step`] takes the measured torso orientation and
//! rate and the leg joints' state ([`LegState`]) with the desired walk ([`WalkCommand`]), and
//! returns a position target and PD gains for each of the 12 leg joints ([`JointTarget`]). The
//! other 11 joints (head, arms, waist) hold their default pose with their deployment gains
//! ([`WalkPolicy::upper_body_targets`]).
//!
//! The shipped network and deployment constants live in `assets/t1/` (see its NOTICE) and are
//! embedded in the binary, so [`WalkPolicy::shipped`] needs no files at run time.

mod config;
mod error;
mod network;
mod observation;
mod walk;

pub use config::{
    ActionConfig, ControlConfig, GaitConfig, JointConfig, ObservationScales, T1Config,
};
pub use error::PolicyError;
pub use network::{ACTION_LEN, HIDDEN_WIDTHS, WalkNetwork};
pub use observation::{
    OBS_ANGULAR_VELOCITY, OBS_COMMAND, OBS_GAIT_PHASE, OBS_GRAVITY, OBS_JOINT_POSITIONS,
    OBS_JOINT_VELOCITIES, OBS_PREVIOUS_ACTION, OBSERVATION_LEN, gravity_in_torso,
};
pub use walk::{JointTarget, LegState, WalkCommand, WalkPolicy};

/// Joints of the T1, in the order of its deployment configuration and of rcssservermj's
/// effectors (`he1 he2 lae1-4 rae1-4 te1 lle1-6 rle1-6`).
pub const T1_JOINT_COUNT: usize = 23;

/// The T1's joint names in that order.
pub const JOINT_NAMES: [&str; T1_JOINT_COUNT] = [
    "head_yaw",
    "head_pitch",
    "left_shoulder_pitch",
    "left_shoulder_roll",
    "left_elbow_pitch",
    "left_elbow_yaw",
    "right_shoulder_pitch",
    "right_shoulder_roll",
    "right_elbow_pitch",
    "right_elbow_yaw",
    "waist_yaw",
    "left_hip_pitch",
    "left_hip_roll",
    "left_hip_yaw",
    "left_knee_pitch",
    "left_ankle_pitch",
    "left_ankle_roll",
    "right_hip_pitch",
    "right_hip_roll",
    "right_hip_yaw",
    "right_knee_pitch",
    "right_ankle_pitch",
    "right_ankle_roll",
];

/// The 12 leg joints the policy drives, as indices into [`JOINT_NAMES`], in the policy's order
/// (left hip pitch, hip roll, hip yaw, knee, ankle pitch, ankle roll, then the right leg).
pub const LEG_JOINTS: [usize; ACTION_LEN] = [11, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22];

/// The 11 joints the policy does not drive (head, arms, waist), as indices into
/// [`JOINT_NAMES`]; the caller holds them at their default pose.
pub const UPPER_BODY_JOINTS: [usize; T1_JOINT_COUNT - ACTION_LEN] =
    [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10];
