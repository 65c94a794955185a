//! The in-process connection: a shared handle to the world, and per robot a
//! [`strata_robot::platform::Platform`], a [`TeamLink`] and a GameController [`ExternalLink`]
//! that read and write the world directly. Stepped by the lockstep host, this is deterministic
//! and as fast as the CPU allows.

use std::sync::{Arc, Mutex, MutexGuard};

use strata_robot::platform::{
    ActuatorOrders, ExternalLink, LinkError, MotionFeedback, Platform, PlatformError, PlatformInfo,
    ReceivedPacket, SensorFrame, SharedPlatform, TeamLink,
};
use strata_runtime::Time;

use crate::truth::RobotId;
use crate::world::{SimError, Simulation};

/// A shared handle to the world. Clones refer to the same simulation.
#[derive(Clone)]
pub struct SimHandle(Arc<Mutex<Simulation>>);

impl std::fmt::Debug for SimHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never locks: printing a handle while the world is locked must not deadlock.
        f.debug_struct("SimHandle").finish_non_exhaustive()
    }
}

impl SimHandle {
    pub fn new(simulation: Simulation) -> SimHandle {
        SimHandle(Arc::new(Mutex::new(simulation)))
    }

    /// Locks the world. A panic while it was locked leaves it usable (every step is
    /// self-contained), so poisoning is ignored.
    pub fn lock(&self) -> MutexGuard<'_, Simulation> {
        self.0.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn check(&self, robot: RobotId) -> Result<(), SimError> {
        // `robot()` validates the id.
        self.lock().robot(robot).map(|_| ())
    }

    /// The platform of one robot (create one per robot).
    pub fn platform(&self, robot: RobotId) -> Result<SimPlatform, SimError> {
        self.check(robot)?;
        let info = self.lock().platform_info();
        Ok(SimPlatform { sim: self.clone(), robot, info })
    }

    /// The platform of one robot, as robot modules share it.
    pub fn shared_platform(&self, robot: RobotId) -> Result<SharedPlatform, SimError> {
        Ok(Arc::new(Mutex::new(self.platform(robot)?)))
    }

    /// The team radio of one robot.
    pub fn team_link(&self, robot: RobotId) -> Result<SimTeamLink, SimError> {
        self.check(robot)?;
        Ok(SimTeamLink { sim: self.clone(), robot })
    }

    /// The GameController link of one robot.
    pub fn game_controller_link(&self, robot: RobotId) -> Result<SimGameControllerLink, SimError> {
        self.check(robot)?;
        Ok(SimGameControllerLink { sim: self.clone(), robot })
    }
}

fn unsupported(error: SimError) -> PlatformError {
    PlatformError::Unsupported(error.to_string())
}

/// One simulated robot's hardware.
#[derive(Debug)]
pub struct SimPlatform {
    sim: SimHandle,
    robot: RobotId,
    info: PlatformInfo,
}

impl SimPlatform {
    pub fn robot(&self) -> RobotId {
        self.robot
    }
}

impl Platform for SimPlatform {
    fn info(&self) -> PlatformInfo {
        self.info.clone()
    }

    fn read_sensors(&mut self, _now: Time) -> Result<Option<SensorFrame>, PlatformError> {
        self.sim.lock().take_sensor_frame(self.robot).map_err(unsupported)
    }

    fn read_motion(&mut self, _now: Time) -> Result<MotionFeedback, PlatformError> {
        self.sim.lock().read_motion(self.robot).map_err(unsupported)
    }

    fn write(&mut self, _now: Time, orders: &ActuatorOrders) -> Result<(), PlatformError> {
        self.sim.lock().apply_orders(self.robot, orders)
    }
}

/// One robot's team radio: the simulator forwards its messages to its teammates.
#[derive(Debug)]
pub struct SimTeamLink {
    sim: SimHandle,
    robot: RobotId,
}

impl TeamLink for SimTeamLink {
    fn send(&mut self, _now: Time, payload: &[u8]) -> Result<(), LinkError> {
        self.sim.lock().send_team_message(self.robot, payload)
    }

    fn receive(&mut self, _now: Time) -> Result<Vec<ReceivedPacket>, LinkError> {
        self.sim.lock().take_team_messages(self.robot).map_err(|e| LinkError::Closed(e.to_string()))
    }
}

/// One robot's GameController: receives the referee's `RGme` packets (2 Hz), accepts `RGrt`
/// return packets.
#[derive(Debug)]
pub struct SimGameControllerLink {
    sim: SimHandle,
    robot: RobotId,
}

impl ExternalLink for SimGameControllerLink {
    fn receive(&mut self, _now: Time) -> Result<Vec<ReceivedPacket>, LinkError> {
        self.sim
            .lock()
            .take_control_packets(self.robot)
            .map_err(|e| LinkError::Closed(e.to_string()))
    }

    fn send(&mut self, _now: Time, payload: &[u8]) -> Result<(), LinkError> {
        self.sim
            .lock()
            .receive_return_packet(self.robot, payload)
            .map_err(|e| LinkError::Closed(e.to_string()))
    }
}
