//! The Booster T1 humanoid in rcssservermj, the RoboCup soccer simulation league's MuJoCo
//! server, as a Strata platform.
//!
//! - [`protocol`]: the server's agent and monitor protocols (framing, S-expressions,
//!   perceptions in SI units, effectors, trainer commands);
//! - [`policy`]: Booster's published T1 walking policy, run in Rust;
//! - [`controller`]: one server cycle of the body and the neck (the body resource is the
//!   policy, the head resource the neck);
//! - [`kick`]: the T1's kicks, walking bursts through the ball on the policy;
//! - [`getup`]: the keyframed get-up motions from the front and the back (`assets/t1/getup.toml`);
//! - [`kinematics`], [`camera`], [`markers`]: from the server's ideal vision to the detections
//!   of a realistic head camera;
//! - [`referee`]: the server's game state as GameController packets;
//! - [`falls`]: falls against the server's ground truth, and the protective fall's latency;
//! - [`platform`]: [`platform::RcssPlatform`], the [`strata_robot::platform::Platform`] over the
//!   agent port;
//! - [`server`]: starting the server from the project's environment;
//! - [`compute`]: what each server cycle costs the robot's process, in CPU time.

pub mod camera;
pub mod compute;
pub mod controller;
pub mod falls;
pub mod getup;
pub mod joints;
pub mod kick;
pub mod kinematics;
pub mod markers;
pub mod platform;
pub mod policy;
pub mod protocol;
pub mod referee;
pub mod server;
