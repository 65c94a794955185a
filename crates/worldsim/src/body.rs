//! One walking body: an omnidirectional gait with acceleration limits and an initialization and
//! end stage, a head that turns at a limited speed, and the special sequences a biped needs —
//! a protective fall and a stand-up from either side — that take their time and tilt the body.
//! A slip is an unprotected fall the walking engine does not know about: only the IMU shows it.
//!
//! The body is kinematic and knows nothing of walls or noise: the simulator moves it
//! ([`crate::WorldSim`]) and decides where its steps really take it.

use strata_robot::geometry::{Odometry, Pose, Velocity};
use strata_robot::platform::{
    ActuatorOrders, BodyMotionState, BodyOrder, CycleStage, FallDirection, FootContact, HeadAngles,
    InertialData, MotionFeedback, MotionName, PlatformError, SensorFrame, SpecialMotion,
};
use strata_runtime::Time;

use crate::config::BodyConfig;

/// Tilt of a body lying on the floor, rad.
const LYING_TILT: f64 = 1.45;
/// Tilt at which an unprotected fall starts toppling, rad.
const FALL_TILT0: f64 = 0.05;
/// Below this tilt the feet still carry the body.
const FEET_TILT: f64 = 0.5;
/// Shortest rest of a fall a protective sequence can take over, s.
const MIN_PROTECTIVE_REST: f64 = 0.1;
const GRAVITY: f64 = 9.81;
/// Foot pressure of a body standing on both feet, kg per foot.
const FOOT_LOAD: f64 = 2.5;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Activity {
    Standing,
    Walking {
        stage: CycleStage,
        elapsed: f64,
    },
    /// Slipping, unprotected.
    Falling {
        elapsed: f64,
    },
    Special {
        motion: SpecialMotion,
        elapsed: f64,
        duration: f64,
        start_tilt: f64,
    },
    Fallen,
}

/// What a body's own motion ended in during one step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Landing {
    OnTheFloor,
    OnItsFeet,
}

/// A walking body's state.
#[derive(Clone, Debug, PartialEq)]
pub struct Body {
    pose: Pose,
    velocity: Velocity,
    target: Velocity,
    activity: Activity,
    head: HeadAngles,
    head_target: HeadAngles,
    head_speed: f64,
    tilt: f64,
    tilt_rate: f64,
    direction: FallDirection,
    /// What the walking engine believes it moved since the feedback was last read.
    odometry: Odometry,
    /// True motion = scale * believed motion (+ noise), per axis.
    scale: [f64; 3],
}

fn approach(value: f64, target: f64, step: f64) -> f64 {
    value + (target - value).clamp(-step, step)
}

impl Body {
    pub(crate) fn new(pose: Pose, scale: [f64; 3], head_speed: f64) -> Body {
        Body {
            pose,
            velocity: Velocity::ZERO,
            target: Velocity::ZERO,
            activity: Activity::Standing,
            head: HeadAngles::default(),
            head_target: HeadAngles::default(),
            head_speed,
            tilt: 0.0,
            tilt_rate: 0.0,
            direction: FallDirection::Front,
            odometry: Odometry::ZERO,
            scale,
        }
    }

    /// Where the body really is.
    pub fn pose(&self) -> Pose {
        self.pose
    }

    pub(crate) fn set_pose(&mut self, pose: Pose) {
        self.pose = pose;
    }

    /// Its true walking velocity, in its own frame.
    pub fn velocity(&self) -> Velocity {
        self.velocity
    }

    pub fn head(&self) -> HeadAngles {
        self.head
    }

    /// How far the torso leans from upright, rad.
    pub fn tilt(&self) -> f64 {
        self.tilt
    }

    /// The systematic scale error of its odometry, per axis (x, y, heading).
    pub fn odometry_scale(&self) -> [f64; 3] {
        self.scale
    }

    /// Whether the body lies on the floor.
    pub fn is_fallen(&self) -> bool {
        self.activity == Activity::Fallen
    }

    /// What the walking engine reports: a slip looks like standing to it.
    pub fn motion_state(&self) -> BodyMotionState {
        match self.activity {
            Activity::Standing | Activity::Falling { .. } => BodyMotionState::Standing,
            Activity::Walking { stage, .. } => {
                BodyMotionState::Walking { stage, velocity: self.velocity }
            }
            Activity::Special { motion, elapsed, duration, .. } => {
                BodyMotionState::Special { motion, elapsed, duration }
            }
            Activity::Fallen => BodyMotionState::Fallen { direction: self.direction },
        }
    }

    /// Whether a fall or a sequence holds the head, so head orders are ignored.
    fn holds_head(&self) -> bool {
        match self.activity {
            Activity::Falling { .. } | Activity::Fallen => true,
            Activity::Special { motion, .. } => motion.head,
            _ => false,
        }
    }

    /// Whether the camera can take a usable image: upright and on its feet's own motion.
    pub(crate) fn can_see(&self, max_tilt: f64) -> bool {
        self.tilt < max_tilt
            && matches!(self.activity, Activity::Standing | Activity::Walking { .. })
    }

    /// Starts an unprotected forward fall; false if the body is not on its feet.
    pub(crate) fn slip(&mut self) -> bool {
        if !matches!(self.activity, Activity::Standing | Activity::Walking { .. }) {
            return false;
        }
        self.activity = Activity::Falling { elapsed: 0.0 };
        self.direction = FallDirection::Front;
        self.target = Velocity::ZERO;
        true
    }

    /// Takes orders; they act from the next step. A sequence the body's state does not fit (a
    /// stand-up while standing) is ignored; one the body cannot do is refused.
    pub(crate) fn apply(
        &mut self,
        orders: &ActuatorOrders,
        config: &BodyConfig,
    ) -> Result<(), PlatformError> {
        let max = config.max_velocity;
        let max_head = config.max_head_speed;
        if let Some(head) = orders.head
            && !self.holds_head()
        {
            let (yaw, pitch) = (config.head_yaw_limits, config.head_pitch_limits);
            self.head_target = HeadAngles {
                yaw: head.target.yaw.clamp(yaw.0, yaw.1),
                pitch: head.target.pitch.clamp(pitch.0, pitch.1),
            };
            self.head_speed =
                if head.max_speed > 0.0 { head.max_speed.min(max_head) } else { max_head };
        }
        match orders.body {
            None => {}
            Some(BodyOrder::Stand) => {
                self.target = Velocity::ZERO;
                if let Activity::Walking {
                    stage: CycleStage::Initialization | CycleStage::Execution,
                    ..
                } = self.activity
                {
                    self.activity = Activity::Walking { stage: CycleStage::End, elapsed: 0.0 };
                }
            }
            Some(BodyOrder::Walk { velocity }) => {
                self.target = Velocity::new(
                    velocity.vx.clamp(-max.vx, max.vx),
                    velocity.vy.clamp(-max.vy, max.vy),
                    velocity.omega.clamp(-max.omega, max.omega),
                );
                self.activity = match self.activity {
                    Activity::Standing => {
                        Activity::Walking { stage: CycleStage::Initialization, elapsed: 0.0 }
                    }
                    // A new walk during the end stage resumes the gait.
                    Activity::Walking { stage: CycleStage::End, .. } => {
                        Activity::Walking { stage: CycleStage::Execution, elapsed: 0.0 }
                    }
                    other => other,
                };
            }
            Some(BodyOrder::Special { motion }) => {
                self.activity = self.start_special(motion, config)?;
                self.target = Velocity::ZERO;
            }
        }
        Ok(())
    }

    fn start_special(
        &mut self,
        motion: SpecialMotion,
        config: &BodyConfig,
    ) -> Result<Activity, PlatformError> {
        let start_tilt = self.tilt;
        let special =
            |duration: f64| Activity::Special { motion, elapsed: 0.0, duration, start_tilt };
        Ok(match (motion.kind, self.activity) {
            // Protecting a fall already under way takes what is left of it.
            (MotionName::FALL, Activity::Falling { elapsed }) => {
                special((config.fall_time - elapsed).max(MIN_PROTECTIVE_REST))
            }
            (MotionName::FALL, Activity::Standing | Activity::Walking { .. }) => {
                // Sitting down backwards is the safe way for a standing humanoid.
                self.direction = FallDirection::Back;
                special(config.protective_fall_time)
            }
            (MotionName::STAND_UP, Activity::Fallen) => special(config.stand_up_time),
            // The state does not fit: actuation sees no special state and releases it.
            (MotionName::FALL | MotionName::STAND_UP, other) => other,
            _ => return Err(PlatformError::Unsupported(format!("special motion {motion}"))),
        })
    }

    /// Moves the body's own state on by `dt`: its gait, sequences, falls, velocity and head.
    pub(crate) fn advance(&mut self, dt: f64, config: &BodyConfig) -> Option<Landing> {
        let previous_tilt = self.tilt;
        let mut landing = None;
        self.activity = match self.activity {
            Activity::Standing => Activity::Standing,
            Activity::Walking { stage, elapsed } => {
                let elapsed = elapsed + dt;
                match stage {
                    CycleStage::Initialization if elapsed >= config.walk_start => {
                        Activity::Walking { stage: CycleStage::Execution, elapsed: 0.0 }
                    }
                    CycleStage::End if elapsed >= config.walk_stop => {
                        self.velocity = Velocity::ZERO;
                        Activity::Standing
                    }
                    _ => Activity::Walking { stage, elapsed },
                }
            }
            Activity::Falling { elapsed } => {
                let elapsed = elapsed + dt;
                // An inverted pendulum: the tilt grows as cosh, reaching the floor at fall_time.
                let tau = config.fall_time / (LYING_TILT / FALL_TILT0).acosh();
                self.tilt = (FALL_TILT0 * (elapsed / tau).cosh()).min(LYING_TILT);
                if elapsed >= config.fall_time {
                    landing = Some(Landing::OnTheFloor);
                    Activity::Fallen
                } else {
                    Activity::Falling { elapsed }
                }
            }
            Activity::Special { motion, elapsed, duration, start_tilt } => {
                let elapsed = elapsed + dt;
                let progress = (elapsed / duration).min(1.0);
                let going_on = Activity::Special { motion, elapsed, duration, start_tilt };
                if motion.kind == MotionName::STAND_UP {
                    self.tilt = start_tilt * (1.0 - progress);
                    if progress >= 1.0 {
                        landing = Some(Landing::OnItsFeet);
                        Activity::Standing
                    } else {
                        going_on
                    }
                } else {
                    // A protective fall lowers the body on purpose, faster and softer.
                    self.tilt = start_tilt + (LYING_TILT - start_tilt) * progress * progress;
                    if progress >= 1.0 {
                        landing = Some(Landing::OnTheFloor);
                        Activity::Fallen
                    } else {
                        going_on
                    }
                }
            }
            Activity::Fallen => {
                self.tilt = LYING_TILT;
                Activity::Fallen
            }
        };
        let walking =
            matches!(self.activity, Activity::Walking { stage: CycleStage::Execution, .. });
        let target = if walking { self.target } else { Velocity::ZERO };
        let (lin, rot) = (config.acceleration * dt, config.angular_acceleration * dt);
        self.velocity = Velocity::new(
            approach(self.velocity.vx, target.vx, lin),
            approach(self.velocity.vy, target.vy, lin),
            approach(self.velocity.omega, target.omega, rot),
        );
        if !matches!(self.activity, Activity::Walking { .. }) {
            self.velocity = Velocity::ZERO;
        }
        self.tilt_rate = (self.tilt - previous_tilt) / dt;
        if !self.holds_head() {
            let step = self.head_speed * dt;
            self.head = HeadAngles {
                yaw: approach(self.head.yaw, self.head_target.yaw, step),
                pitch: approach(self.head.pitch, self.head_target.pitch, step),
            };
        }
        landing
    }

    /// What the walking engine believes one step of `dt` moved the body (it adds this to its
    /// odometry), or `None` when the body stands still.
    pub(crate) fn believed_step(&mut self, dt: f64) -> Option<Odometry> {
        let v = self.velocity;
        if v.is_zero() {
            return None;
        }
        let believed = Odometry { dx: v.vx * dt, dy: v.vy * dt, dtheta: v.omega * dt };
        self.odometry = self.odometry.then(believed);
        Some(believed)
    }

    /// The motion feedback, handing over the odometry accumulated since the last call.
    pub(crate) fn take_feedback(&mut self, stamp: Time) -> MotionFeedback {
        MotionFeedback {
            stamp,
            body: self.motion_state(),
            head: self.head,
            head_settled: self.head == self.head_target,
            odometry: std::mem::take(&mut self.odometry),
        }
    }

    /// The IMU, joints and feet, without a camera image.
    pub(crate) fn sensor_frame(&self, stamp: Time) -> SensorFrame {
        let lean = |value: f64| match self.direction {
            FallDirection::Front => (value, 0.0),
            FallDirection::Back => (-value, 0.0),
            FallDirection::Left => (0.0, -value),
            FallDirection::Right => (0.0, value),
        };
        let (pitch, roll) = lean(self.tilt);
        let (pitch_rate, roll_rate) = lean(self.tilt_rate);
        SensorFrame {
            stamp,
            inertial: InertialData {
                accelerometer: [
                    GRAVITY * pitch.sin(),
                    -GRAVITY * roll.sin(),
                    GRAVITY * self.tilt.cos(),
                ],
                gyroscope: [roll_rate, pitch_rate, self.velocity.omega],
                body_angles: [roll, pitch],
            },
            head: self.head,
            foot_contact: if self.tilt < FEET_TILT {
                FootContact { left: FOOT_LOAD, right: FOOT_LOAD }
            } else {
                FootContact::default()
            },
            battery: Some(1.0),
            ..SensorFrame::default()
        }
    }
}
