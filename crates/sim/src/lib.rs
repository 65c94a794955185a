//! The Strata simulator: a 2D RoboCup SPL world in the spirit of UChile HL-SIM (Testart et al.
//! 2011, section 4.1), the embedded default on which every match and experiment of Strata runs.
//!
//! - [`Simulation`]: robots (omnidirectional cyclic walk, head, camera, kicks, stand-ups, falls,
//!   an IMU), a rolling ball, a referee that publishes real GameController packets, and team
//!   broadcast emulation — with every noise and error level in one config section and one seed
//!   for everything. `step` is deterministic, bit for bit.
//! - In process: [`add_simulator`] steps the world as a module of the graph and is the
//!   platform and the links of the robots it is given (their frames, motion feedback and
//!   orders, their team messages and GameController packets through its ports); to code that
//!   drives a robot directly, a [`SimHandle`] gives a [`SimPlatform`] (the `robot::Platform`
//!   trait), a [`SimTeamLink`] and a [`SimGameControllerLink`].
//! - Over TCP ([`net`]): a real-time server and one process per robot, with the same traits on
//!   the client side.
//! - Ground truth ([`GroundTruth`]) and experiment controls (kidnap, push, place or script the
//!   ball, set the game state, change packet loss, penalize or remove robots) are for
//!   experiments and logs, never for robots.
//!
//! Models, parameters and noise levels: `docs/simulator.md`; the TCP protocol:
//! `docs/sim-protocol.md`.
//!
//! ```
//! use std::time::Duration;
//! use strata_robot::platform::{ActuatorOrders, BodyOrder, Platform};
//! use strata_robot::Velocity;
//! use strata_runtime::{GraphBuilder, HostConfig, LockstepHost, Time};
//! use strata_sim::{GameState, RobotId, SimConfig, SimHandle, Simulation, add_simulator};
//!
//! let sim = SimHandle::new(Simulation::new(SimConfig::default())?);
//! sim.lock().set_game_state(GameState::Playing);
//! let robot = RobotId::new(0, 1); // team index 0, player 1
//! let mut platform = sim.platform(robot)?;
//! let walk = BodyOrder::Walk { velocity: Velocity::new(0.2, 0.0, 0.0) };
//! platform.write(Time::ZERO, &ActuatorOrders { head: None, body: Some(walk) })?;
//!
//! let mut graph = GraphBuilder::new();
//! add_simulator(&mut graph, sim.clone(), &[]); // `platform` reads the world itself
//! let mut host = LockstepHost::new(graph.build()?, HostConfig::with_seed(1));
//! host.run_for(Duration::from_secs(2))?;
//! let frame = platform.read_sensors(host.now())?.expect("a frame every 12 ms");
//! assert!(frame.inertial.accelerometer[2] > 9.0);
//! assert!(sim.lock().robot(robot)?.velocity.vx > 0.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod body;
mod camera;
mod comms;
pub mod config;
mod module;
pub mod net;
pub mod noise;
mod physics;
mod platform;
mod random;
mod referee;
mod sensors;
pub mod test_controller;
mod truth;
mod util;
mod world;

pub use body::FallCause;
pub use config::{ConfigError, SimConfig};
pub use module::{ServedRobot, SimulatorModule, SimulatorPorts, add_simulator, robot_port_prefix};
pub use noise::{NoiseConfig, NoiseLevel, NoiseParams};
pub use physics::BallScript;
pub use platform::{SimGameControllerLink, SimHandle, SimPlatform, SimTeamLink};
pub use sensors::GRAVITY;
pub use test_controller::{TestController, TestControllerConfig, add_test_controller};
pub use truth::{
    BallTruth, CommsStats, Event, EventKind, GameTruth, GroundTruth, RobotId, RobotTruth,
};
pub use world::{SimError, Simulation};

// The types experiments need to drive the controls, re-exported so they need not name the
// `spl` and `robot` crates for them.
pub use strata_robot::platform::FallDirection;
pub use strata_spl::gamecontroller::{GameState, Penalty, SetPlay};
