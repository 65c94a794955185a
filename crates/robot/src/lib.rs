//! The architecture of one robot (Testart et al. 2011, section 3), application-agnostic.
//!
//! Four parallel modules — perception, actuation, world modeling and hybrid control (planning,
//! deliberative and reactive layers) — over an abstract [`platform::Platform`]. Nothing here
//! names a ball, a goal or a soccer role: an application provides its objects of interest,
//! missions, roles, goals, behaviors and value functions.

pub mod actuation;
pub mod application;
pub mod assembly;
pub mod command;
pub mod control;
pub mod edge;
pub mod geometry;
pub mod percept;
pub mod perception;
pub mod platform;
pub mod weights;
pub mod world;

pub use geometry::{Global, Odometry, Point, Pose, Robot, Vector, Velocity, normalize_angle};
