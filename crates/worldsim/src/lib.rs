//! A small generic world simulator for Strata applications that are not soccer: a flat floor
//! with walls, markers the camera recognises, walking bodies with a head camera, and the
//! platform edge that serves them to the robots' graphs. An application describes its world
//! (walls and markers), scripts what happens in it (a [`Script`]: objects that come and go,
//! robots that slip) and keeps its own links; the simulator does the rest.
//!
//! - [`World`]: walls (segments that block sight and movement) and [`Marker`]s (anything a
//!   camera reports: a class, an optional variant, a position the application may change).
//! - [`WorldSim`]: the bodies (omnidirectional gait with acceleration limits and start and stop
//!   stages, a head with speed and joint limits, odometry with a scale error and noise, walls
//!   that stop them, unprotected falls, protective falls and stand-ups that take their time and
//!   tilt the body) and their sensors (IMU, joints, feet, a head camera with field of view,
//!   range, occlusion by walls, misses and range and bearing noise). One seed, one run.
//! - [`add_world_sim`]: the simulator as a module of the graph and the platform of the robots
//!   it serves: their frames and motion feedback leave through its ports and their orders come
//!   back through them ([`WorldSimPorts::platform`], given to `add_robot` as
//!   `RobotPlatform::Module`), so the world moves before its robots look at it because its
//!   step triggers their perception, on either host.
//! - [`Truth`]: what really happened (trajectories, falls, stand-ups, bumps), never for robots.
//!
//! ```
//! use std::time::Duration;
//! use strata_robot::geometry::{Point, Pose, Segment};
//! use strata_robot::platform::ObjectClass;
//! use strata_runtime::{GraphBuilder, HostConfig, LockstepHost};
//! use strata_worldsim::{
//!     Marker, Simulation, World, WorldHandle, WorldSim, WorldSimConfig, add_world_sim,
//! };
//!
//! let mut world = World::new(vec![Segment::new(Point::new(3.0, -2.0), Point::new(3.0, 2.0))]);
//! world.add_marker(Marker::at("door", ObjectClass(1), Some(0), Point::new(2.98, 0.0)));
//! let sim = WorldSim::new(WorldSimConfig::default(), world, &[Pose::new(0.0, 0.0, 0.0)], 7)?;
//! let handle = WorldHandle::new(Simulation::new(sim, ()));
//!
//! let mut graph = GraphBuilder::new();
//! let served = add_world_sim(&mut graph, "world", handle.clone(), &[0])?;
//! let platform = served.platform(0).expect("robot 0 is served");
//! // A robot's `add_robot` takes `RobotPlatform::Module(platform)`; here the orders port is
//! // left to the outside.
//! graph.external(platform.orders);
//! let mut host = LockstepHost::new(graph.build()?, HostConfig::with_seed(7));
//! host.run_for(Duration::from_secs(1))?;
//! assert_eq!(handle.lock().sim.time().as_secs_f64(), 1.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod body;
mod camera;
pub mod config;
mod handle;
mod module;
mod sim;
mod truth;
mod world;

pub use body::Body;
pub use config::{BodyConfig, CameraConfig, ConfigError, WorldSimConfig};
pub use handle::{Simulation, WorldHandle};
pub use module::{WorldSimModule, WorldSimPorts, add_world_sim, robot_port_prefix};
pub use sim::{BodyEvent, Script, WorldSim, WorldSimError};
pub use truth::{Truth, pose_at};
pub use world::{Marker, MarkerId, World};
