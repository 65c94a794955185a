//! The seat of a walking engine. No gait ships with this crate: [`NoGait`] reports walking as
//! unsupported, and a future engine implements [`GaitEngine`] and is handed to
//! [`crate::LolaPlatform::connect_with_gait`] without any other change to the platform.

use std::fmt;

use strata_robot::geometry::{Odometry, Velocity};
use strata_robot::platform::CycleStage;

use crate::codec::SensorPacket;
use crate::joints::JointArray;

/// Why a gait engine refused a request.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GaitError {
    /// The engine cannot do this at all; the message completes "the platform does not
    /// support ...".
    #[error("{0}")]
    Unsupported(String),
    /// The request is valid in general but not now (e.g. a velocity beyond the limits).
    #[error("walk request rejected: {0}")]
    Rejected(String),
}

/// What the engine did in one LoLA cycle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaitStep {
    /// Stage of the step cycle (paper 3.5.1); `None` once the engine stands still.
    pub stage: Option<CycleStage>,
    /// The velocity the engine is executing now (it ramps towards the request).
    pub velocity: Velocity,
    /// Motion of the robot during this cycle, in the robot frame at the cycle's start.
    pub odometry: Odometry,
}

/// A walking engine driven by the platform's 12 ms LoLA cycle.
///
/// The platform owns the engine and calls it under its own lock: `walk` and `stop` from the
/// caller's thread when orders arrive, `step` from the LoLA thread once per sensor packet.
/// While [`GaitEngine::is_active`] is true the engine owns the leg and arm joints (the head
/// stays with head orders); when it returns false the platform takes the legs back and holds
/// the stand posture.
pub trait GaitEngine: Send + fmt::Debug {
    /// Shown in logs and in the platform's name.
    fn name(&self) -> &str;

    /// The fastest the engine walks; `None` if it cannot walk.
    fn max_velocity(&self) -> Option<Velocity>;

    /// Starts walking at `velocity`, or changes the velocity of a walk in progress.
    fn walk(&mut self, velocity: Velocity) -> Result<(), GaitError>;

    /// Finishes the current step and stands still.
    fn stop(&mut self);

    /// Stops at once and releases the joints (a fall, or the motors going off): the platform
    /// takes every joint over in the same cycle.
    fn abort(&mut self) {
        self.stop();
    }

    /// Whether the engine is moving the legs.
    fn is_active(&self) -> bool;

    /// One LoLA cycle: writes the joint targets and stiffnesses of the joints it drives (leave
    /// the head alone) and reports the step.
    fn step(
        &mut self,
        dt: f64,
        sensors: &SensorPacket,
        targets: &mut JointArray<f64>,
        stiffness: &mut JointArray<f64>,
    ) -> GaitStep;
}

/// The engine a NAO has until a real one is written: it refuses to walk.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoGait;

impl GaitEngine for NoGait {
    fn name(&self) -> &str {
        "none"
    }

    fn max_velocity(&self) -> Option<Velocity> {
        None
    }

    fn walk(&mut self, _velocity: Velocity) -> Result<(), GaitError> {
        Err(GaitError::Unsupported(
            "walking: no gait engine is installed on this NAO (strata-nao ships none yet; \
             implement strata_nao::GaitEngine and pass it to LolaPlatform::connect_with_gait)"
                .to_owned(),
        ))
    }

    fn stop(&mut self) {}

    fn is_active(&self) -> bool {
        false
    }

    fn step(
        &mut self,
        _dt: f64,
        _sensors: &SensorPacket,
        _targets: &mut JointArray<f64>,
        _stiffness: &mut JointArray<f64>,
    ) -> GaitStep {
        GaitStep { stage: None, velocity: Velocity::ZERO, odometry: Odometry::ZERO }
    }
}

#[cfg(test)]
// A panic is how a test reports failure.
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn no_gait_refuses_with_a_clear_message() {
        let mut gait = NoGait;
        let error = gait.walk(Velocity::new(0.1, 0.0, 0.0)).unwrap_err();
        assert!(error.to_string().starts_with("walking: no gait engine"), "{error}");
        assert!(!gait.is_active());
        assert_eq!(gait.max_velocity(), None);
    }
}
