//! Robot soccer on the Strata architecture: the missions and roles, deliberative behaviors,
//! goals and primitive behaviors of the paper's Tables 1 to 4, the value functions of active
//! vision, and the team message of Fig. 2.

pub mod activation;
pub mod behaviors;
pub mod catalog;
pub mod field;
pub mod game;
pub mod gaze_override;
pub mod gaze_policy;
pub mod goals;
pub mod message;
pub mod motions;
pub mod planning;
pub mod predicted_motion;
pub mod primitives;
pub mod situation;
pub mod team;
pub mod value;
pub mod world_config;
