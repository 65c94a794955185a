//! The robot's body: the omnidirectional walk as a cyclic motion (initialization, execution,
//! end), special sequences (kicks, stand-ups, protective falls, dives), unprotected falls, the
//! head joints, and the odometry the walking engine reports.
//!
//! The body knows nothing of the ball or of other robots: the world tells it about pushes and
//! collisions, and it tells the world when a kick's foot or a dive's body can meet the ball.

use std::f64::consts::PI;

use serde::{Deserialize, Serialize};
use strata_robot::platform::{
    BodyMotionState, BodyOrder, CycleStage, FallDirection, HeadAngles, HeadOrder, MotionName,
    SpecialMotion,
};
use strata_robot::{Odometry, Pose, Vector, Velocity};
use strata_runtime::Time;

use crate::config::{DiveSide, RobotConfig};
use crate::noise::NoiseParams;
use crate::random::Stream;
use crate::util::{Rotating, approach, length, sin_cos, smoothstep, wrap_near};

/// The kinds of the simulator's catalogue beside the robot crate's stand-ups and falls: the
/// league's names, which soccer orders them by.
pub(crate) const KICK: MotionName = MotionName::from_static(strata_spl::motions::KICK.name);
pub(crate) const DIVE: MotionName = MotionName::from_static(strata_spl::motions::DIVE.name);

/// Kick `sequence` of the catalogue, as soccer orders it.
pub(crate) const fn kick(sequence: u8) -> SpecialMotion {
    SpecialMotion::new(KICK, sequence, strata_spl::motions::KICK.head)
}

/// Dive `sequence` of the catalogue, as soccer orders it.
pub(crate) const fn dive(sequence: u8) -> SpecialMotion {
    SpecialMotion::new(DIVE, sequence, strata_spl::motions::DIVE.head)
}

/// Why a robot fell.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FallCause {
    /// Two robots ran into each other.
    Collision,
    /// An experiment pushed the robot.
    Push,
    /// The random hazard of walking.
    Hazard,
    /// A kick unbalanced the kicker.
    Kick,
    /// An experiment made it fall.
    Forced,
    /// A stand-up sequence failed.
    StandUpFailed,
    /// The robot itself ordered a protective fall or a dive.
    Ordered,
}

/// A special sequence being executed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SpecialRun {
    pub motion: SpecialMotion,
    pub elapsed: f64,
    pub duration: f64,
    pub kind: SpecialKind,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum SpecialKind {
    Kick { index: usize, contacted: bool },
    StandUp { succeeds: bool, direction: FallDirection, start_tilt: f64 },
    ProtectiveFall { direction: FallDirection, start_tilt: f64 },
    Dive { index: usize },
}

/// What the body is doing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Activity {
    Standing,
    /// `elapsed`: time in the stage (initialization and end), s.
    Walking {
        stage: CycleStage,
        elapsed: f64,
    },
    Special(SpecialRun),
    /// An unprotected fall: the tilt grows like an inverted pendulum's.
    Falling {
        direction: FallDirection,
        elapsed: f64,
        tilt0: f64,
    },
    Fallen {
        direction: FallDirection,
    },
}

/// What happened to the body during one update, for the world to act on.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct BodyEvents {
    /// A kick's foot meets the ball's place now (index into the kick catalogue).
    pub kick_contact: Option<usize>,
    /// A dive's body blocks the ball: side and reach.
    pub dive_block: Option<(DiveSide, f64)>,
    /// The robot hit the ground.
    pub landed: Option<FallDirection>,
    /// It landed from a fall nobody announced with [`Body::start_fall`] (a protective fall or a
    /// dive the robot ordered): how long ago that fall began, s.
    pub ordered_fall: Option<f64>,
    /// A stand-up ended: whether it succeeded.
    pub stand_up: Option<bool>,
    /// A fall started this update (hazard, kick, failed stand-up).
    pub fall_started: Option<(FallDirection, FallCause)>,
}

/// The physical robot.
#[derive(Clone, Debug)]
pub(crate) struct Body {
    /// Set it with [`Body::set_pose`], which keeps `heading` in step.
    pub pose: Pose,
    /// Sine and cosine of the heading.
    heading: Rotating,
    /// The walking engine's velocity after acceleration limits, robot frame.
    pub velocity: Velocity,
    /// Per-step execution error of the legs (multiplies each velocity component).
    slip: [f64; 3],
    /// Velocity given by pushes, field frame; decays.
    pub push: Vector<strata_robot::Global>,
    pub head: HeadAngles,
    /// Sine and cosine of the head yaw.
    pub head_yaw: Rotating,
    head_target: HeadAngles,
    head_speed_limit: f64,
    /// Head angular speed during the last update, rad/s.
    pub head_rate: f64,
    pub order: BodyOrder,
    pending_special: Option<SpecialMotion>,
    pub activity: Activity,
    /// Gait phase in [0, 1).
    pub gait_phase: f64,
    /// Sine and cosine of the gait phase angle (2 pi phase).
    pub gait: Rotating,
    /// Tilt of the whole body from falls, stand-ups and dives, and its direction.
    posture_tilt: f64,
    posture_direction: FallDirection,
    /// True torso angles, rad.
    pub roll: f64,
    pub pitch: f64,
    /// True angular rates (roll, pitch, yaw), rad/s.
    pub gyro: [f64; 3],
    /// (roll, pitch) and [sin roll, cos roll, sin pitch, cos pitch] for them: a lying robot's
    /// angles do not change, so neither do these.
    tilt_trig: ((f64, f64), [f64; 4]),
    /// Specific force scale (below 1 while falling freely).
    pub accel_scale: f64,
    /// Acceleration spike of an impact, shown by the next inertial sample.
    pub impact: f64,
    /// Odometry accumulated since the platform last read it ([`Body::take_odometry`]).
    pub odometry: Odometry,
    /// Sine and cosine of `odometry.dtheta`.
    odometry_turn: Rotating,
    /// Walking time left before the walking hazard makes the robot fall, s (drawn when the
    /// robot walks; NaN until then).
    hazard_left: f64,
    /// The current fall was started by [`Body::start_fall`] (and so already recorded).
    fall_announced: bool,
    /// Distance walked and angle turned since the current step began (odometry error).
    step_walked: [f64; 2],
}

impl Body {
    pub fn new(pose: Pose) -> Body {
        Body {
            pose,
            heading: Rotating::new(pose.theta),
            gait: Rotating::new(0.0),
            velocity: Velocity::ZERO,
            slip: [0.0; 3],
            push: Vector::new(0.0, 0.0),
            head: HeadAngles::default(),
            head_yaw: Rotating::new(0.0),
            head_target: HeadAngles::default(),
            head_speed_limit: 0.0,
            head_rate: 0.0,
            order: BodyOrder::Stand,
            pending_special: None,
            activity: Activity::Standing,
            gait_phase: 0.0,
            posture_tilt: 0.0,
            posture_direction: FallDirection::Front,
            roll: 0.0,
            pitch: 0.0,
            gyro: [0.0; 3],
            tilt_trig: ((0.0, 0.0), [0.0, 1.0, 0.0, 1.0]),
            accel_scale: 1.0,
            impact: 0.0,
            odometry: Odometry::ZERO,
            odometry_turn: Rotating::new(0.0),
            hazard_left: f64::NAN,
            fall_announced: false,
            step_walked: [0.0; 2],
        }
    }

    /// Puts the robot upright and still at `pose` (placement by a referee, a kidnapping).
    pub fn set_pose(&mut self, pose: Pose) {
        self.pose = pose;
        self.heading = Rotating::new(pose.theta);
    }

    /// [sin roll, cos roll, sin pitch, cos pitch] of the torso.
    #[inline(always)]
    pub fn tilt_trig(&mut self) -> [f64; 4] {
        if self.tilt_trig.0 != (self.roll, self.pitch) {
            let (sr, cr) = sin_cos(self.roll);
            let (sp, cp) = sin_cos(self.pitch);
            self.tilt_trig = ((self.roll, self.pitch), [sr, cr, sp, cp]);
        }
        self.tilt_trig.1
    }

    /// Sine and cosine of the heading.
    pub fn heading(&self) -> (f64, f64) {
        (self.heading.sin, self.heading.cos)
    }

    /// The odometry accumulated since the last call.
    pub fn take_odometry(&mut self) -> Odometry {
        self.odometry_turn = Rotating::ZERO;
        std::mem::replace(&mut self.odometry, Odometry::ZERO)
    }

    /// Adds `next`, a motion in the frame where the accumulated odometry ends (`Odometry::then`,
    /// with the accumulated turn's sine and cosine kept instead of computed).
    fn add_odometry(&mut self, next: Odometry) {
        let first = self.odometry;
        let (s, c) = (self.odometry_turn.sin, self.odometry_turn.cos);
        let dtheta = wrap_near(first.dtheta + next.dtheta);
        self.odometry = Odometry {
            dx: first.dx + c * next.dx - s * next.dy,
            dy: first.dy + s * next.dx + c * next.dy,
            dtheta,
        };
        if next.dtheta != 0.0 {
            self.odometry_turn.advance(dtheta, next.dtheta);
        }
    }

    pub fn set_position(&mut self, x: f64, y: f64) {
        self.pose.x = x;
        self.pose.y = y;
    }

    /// A vector of the robot frame in the field frame.
    pub fn to_global(&self, x: f64, y: f64) -> (f64, f64) {
        let (s, c) = (self.heading.sin, self.heading.cos);
        (c * x - s * y, s * x + c * y)
    }

    pub fn place(&mut self, pose: Pose) {
        self.set_pose(pose);
        self.velocity = Velocity::ZERO;
        self.push = Vector::new(0.0, 0.0);
        if !self.is_down() {
            return;
        }
        // A referee puts a fallen robot back on its feet.
        self.activity = Activity::Standing;
        self.posture_tilt = 0.0;
        self.order = BodyOrder::Stand;
    }

    pub fn is_fallen(&self) -> bool {
        matches!(self.activity, Activity::Fallen { .. })
    }

    pub fn is_falling(&self) -> bool {
        matches!(self.activity, Activity::Falling { .. })
            || matches!(
                self.activity,
                Activity::Special(SpecialRun { kind: SpecialKind::ProtectiveFall { .. }, .. })
            )
    }

    /// Falling, lying or getting up: not on its feet.
    pub fn is_down(&self) -> bool {
        match self.activity {
            Activity::Falling { .. } | Activity::Fallen { .. } => true,
            Activity::Special(run) => {
                matches!(run.kind, SpecialKind::StandUp { .. } | SpecialKind::ProtectiveFall { .. })
                    || matches!(run.kind, SpecialKind::Dive { .. } if self.posture_tilt > 0.3)
            }
            _ => false,
        }
    }

    /// Whether the body moves by walking this instant (for collisions and hazards).
    pub fn is_walking(&self) -> bool {
        matches!(self.activity, Activity::Walking { .. })
    }

    pub fn head_settled(&self) -> bool {
        self.head == self.head_target
    }

    /// What the platform reports as the motion state.
    pub fn motion_state(&self) -> BodyMotionState {
        match self.activity {
            // The motion engine does not know the robot is falling: only the IMU shows it.
            Activity::Standing | Activity::Falling { .. } => BodyMotionState::Standing,
            Activity::Walking { stage, .. } => {
                BodyMotionState::Walking { stage, velocity: self.velocity }
            }
            Activity::Special(run) => BodyMotionState::Special {
                motion: run.motion,
                elapsed: run.elapsed,
                duration: run.duration,
            },
            Activity::Fallen { direction } => BodyMotionState::Fallen { direction },
        }
    }

    /// Applies a head order: targets are clamped to the joint limits.
    pub fn order_head(&mut self, order: &HeadOrder, config: &RobotConfig) {
        if self.holds_head() {
            return;
        }
        let limits = &config.head;
        self.head_target = HeadAngles {
            yaw: order.target.yaw.clamp(limits.yaw_limits[0], limits.yaw_limits[1]),
            pitch: order.target.pitch.clamp(limits.pitch_limits[0], limits.pitch_limits[1]),
        };
        self.head_speed_limit = if order.max_speed.is_finite() && order.max_speed > 0.0 {
            order.max_speed.min(limits.max_speed)
        } else {
            limits.max_speed
        };
    }

    /// A whole-body sequence (or a fall) holds the head joints.
    fn holds_head(&self) -> bool {
        match self.activity {
            Activity::Special(run) => run.motion.head,
            Activity::Falling { .. } => true,
            _ => false,
        }
    }

    /// Applies a body order. Refuses (with the reason) a motion the catalogue does not have, and
    /// a sequence that cannot start in the body's state (a kick while lying); the robot's
    /// actuation learns of it as an unsupported order.
    pub fn order_body(&mut self, order: BodyOrder, config: &RobotConfig) -> Result<(), String> {
        match order {
            BodyOrder::Stand | BodyOrder::Walk { .. } => {
                if !matches!(self.activity, Activity::Special(_)) {
                    self.pending_special = None;
                }
                // The engine's limits apply once, when the order arrives.
                self.order = match order {
                    BodyOrder::Walk { velocity } => {
                        BodyOrder::Walk { velocity: clamp_velocity(velocity, config) }
                    }
                    other => other,
                };
                Ok(())
            }
            BodyOrder::Special { motion } => {
                if catalogue_entry(config, motion).is_none() {
                    return Err(format!("{motion} is not in the motion catalogue"));
                }
                self.order_special(motion, config)
            }
        }
    }

    fn order_special(&mut self, motion: SpecialMotion, config: &RobotConfig) -> Result<(), String> {
        let is_fall = motion.is(MotionName::FALL);
        match self.activity {
            Activity::Special(run) => {
                if run.motion == motion {
                    // Already running: orders are held until replaced, so this is a repeat.
                    Ok(())
                } else if is_fall {
                    // A protective fall interrupts anything.
                    self.start_special(motion, config, None);
                    Ok(())
                } else {
                    Err(format!("{} is running; {motion} must wait", run.motion))
                }
            }
            Activity::Falling { .. } => match motion.kind {
                MotionName::FALL => {
                    self.start_special(motion, config, None);
                    Ok(())
                }
                MotionName::STAND_UP => {
                    // Getting up starts once the robot lies on the ground.
                    self.pending_special = Some(motion);
                    Ok(())
                }
                _ => Err(format!("the robot is falling: no {motion}")),
            },
            Activity::Fallen { .. } => match motion.kind {
                MotionName::STAND_UP => {
                    // Whether it will fail is drawn when it starts (in `update`).
                    self.pending_special = Some(motion);
                    self.order = BodyOrder::Special { motion };
                    Ok(())
                }
                // Already down: a short sequence that ends lying, so the order completes.
                MotionName::FALL => {
                    self.start_special(motion, config, None);
                    Ok(())
                }
                _ => Err(format!("the robot is lying on the ground: no {motion}")),
            },
            Activity::Walking { .. } => {
                self.order = BodyOrder::Special { motion };
                if is_fall || motion.is(DIVE) {
                    self.start_special(motion, config, None);
                } else {
                    // The walk ends first: kicking out of a running gait is not possible.
                    self.pending_special = Some(motion);
                }
                Ok(())
            }
            Activity::Standing => {
                self.order = BodyOrder::Special { motion };
                self.pending_special = Some(motion);
                Ok(())
            }
        }
    }

    /// Starts a special sequence now. `rng` draws a stand-up's outcome.
    fn start_special(
        &mut self,
        motion: SpecialMotion,
        config: &RobotConfig,
        outcome: Option<(&mut Stream, f64)>,
    ) {
        // Orders outside the catalogue were refused when they came (`order_body`).
        let Some(entry) = catalogue_entry(config, motion) else { return };
        self.pending_special = None;
        self.order = BodyOrder::Special { motion };
        self.velocity = Velocity::ZERO;
        let (duration, kind) = match entry {
            Entry::Kick(index) => {
                let duration = config.kicks.get(index).map_or(1.0, |k| k.duration);
                (duration, SpecialKind::Kick { index, contacted: false })
            }
            Entry::StandUp(index) => {
                let duration = config.stand_ups.get(index).map_or(4.0, |s| s.duration);
                let succeeds = match outcome {
                    Some((rng, failure)) => !rng.chance(failure),
                    None => true,
                };
                let direction = match self.activity {
                    Activity::Fallen { direction } => direction,
                    _ => self.posture_direction,
                };
                (
                    duration,
                    SpecialKind::StandUp { succeeds, direction, start_tilt: self.posture_tilt },
                )
            }
            Entry::Fall(index) => {
                let duration = config.protective_falls.get(index).map_or(0.6, |s| s.duration);
                let (direction, start_tilt) = match self.activity {
                    Activity::Falling { direction, .. } => (direction, self.posture_tilt),
                    Activity::Special(SpecialRun {
                        kind: SpecialKind::Dive { .. } | SpecialKind::StandUp { .. },
                        ..
                    }) => (self.posture_direction, self.posture_tilt),
                    // Sitting down backwards is the safe way for a standing NAO.
                    _ => (FallDirection::Back, self.posture_tilt),
                };
                // A protective fall from halfway down takes only what is left of it.
                let left = 1.0 - (start_tilt / config.fall.lying_tilt).clamp(0.0, 1.0);
                (duration * left.max(0.2), SpecialKind::ProtectiveFall { direction, start_tilt })
            }
            Entry::Dive(index) => {
                let duration = config.dives.get(index).map_or(1.8, |d| d.duration);
                (duration, SpecialKind::Dive { index })
            }
        };
        self.activity = Activity::Special(SpecialRun { motion, elapsed: 0.0, duration, kind });
    }

    /// Starts an unprotected fall. Returns false when the robot is already falling or down.
    pub fn start_fall(&mut self, direction: FallDirection) -> bool {
        if self.is_falling() || self.is_fallen() {
            return false;
        }
        let tilt0 = self.posture_tilt.max(0.05);
        self.fall_announced = true;
        self.pending_special = None;
        self.posture_direction = direction;
        self.velocity = Velocity::ZERO;
        self.activity = Activity::Falling { direction, elapsed: 0.0, tilt0 };
        true
    }

    /// Advances the body by `dt` seconds.
    pub fn update(
        &mut self,
        dt: f64,
        config: &RobotConfig,
        noise: &NoiseParams,
        rng: &mut Stream,
    ) -> BodyEvents {
        let mut events = BodyEvents::default();
        self.update_head(dt);
        self.update_activity(dt, config, noise, rng, &mut events);

        // The legs: gait phase, per-step execution error, displacement.
        let walking = self.is_walking();
        if walking {
            let before = self.gait_phase;
            let mut phase = self.gait_phase + dt / config.walk.step_period;
            while phase >= 1.0 {
                phase -= 1.0;
            }
            self.gait_phase = phase;
            self.gait.advance(2.0 * PI * phase, 2.0 * PI * dt / config.walk.step_period);
            // A new step starts twice per gait cycle; each step has its own execution error,
            // and the odometry's random error of the step just made is known.
            if (phase >= 0.5) != (before >= 0.5) {
                let sigma = noise.actuation.velocity_sigma;
                self.slip = [rng.gauss(sigma), rng.gauss(sigma), rng.gauss(sigma)];
                self.close_step(noise, rng);
            }
        } else if self.step_walked != [0.0; 2] {
            self.close_step(noise, rng);
        }
        let v = self.velocity;
        let walked = Odometry {
            dx: v.vx * (1.0 + self.slip[0]) * dt,
            dy: v.vy * (1.0 + self.slip[1]) * dt,
            dtheta: v.omega * (1.0 + self.slip[2]) * dt,
        };
        if walked != Odometry::ZERO {
            let (dx, dy) = self.to_global(walked.dx, walked.dy);
            self.pose.x += dx;
            self.pose.y += dy;
            if walked.dtheta != 0.0 {
                self.pose.theta = wrap_near(self.pose.theta + walked.dtheta);
                self.heading.advance(self.pose.theta, walked.dtheta);
            }
            // The systematic error at once, the random one per step (see `close_step`).
            let n = &noise.odometry;
            let measured = Odometry {
                dx: walked.dx * (1.0 + n.scale_x),
                dy: walked.dy * (1.0 + n.scale_y),
                dtheta: walked.dtheta * (1.0 + n.scale_theta),
            };
            self.add_odometry(measured);
            self.step_walked[0] += length(walked.dx, walked.dy);
            self.step_walked[1] += walked.dtheta.abs();
        }
        if self.push.x != 0.0 || self.push.y != 0.0 {
            self.pose.x += self.push.x * dt;
            self.pose.y += self.push.y * dt;
            let decay = (-dt / config.fall.push_decay).exp();
            self.push = self.push * decay;
            if self.push.x.abs() + self.push.y.abs() < 1e-3 {
                self.push = Vector::new(0.0, 0.0);
            }
        }

        // Walking is a fall hazard in itself: falls come at a constant rate per walking time,
        // so the walking time until the next one is drawn at once (exponential).
        if walking {
            if self.hazard_left.is_nan() {
                self.hazard_left = rng.exponential(noise.falls.hazard_per_minute / 60.0);
            }
            self.hazard_left -= dt;
            if self.hazard_left <= 0.0 {
                self.hazard_left = f64::NAN;
                let direction = random_direction(rng);
                if self.start_fall(direction) {
                    events.fall_started = Some((direction, FallCause::Hazard));
                }
            }
        }

        self.update_angles(dt, config, walked.dtheta);
        events
    }

    /// Adds the random odometry error of the step just made: the walking engine's error
    /// arises per foot placement, and drawing it once per step rather than per update costs a
    /// twentieth of the draws. Standard deviations sigma_xy * sqrt(d) and
    /// sigma_theta * sqrt(turn + d) for a step of length d that turned by `turn`.
    fn close_step(&mut self, noise: &NoiseParams, rng: &mut Stream) {
        let [distance, turn] = std::mem::take(&mut self.step_walked);
        let n = &noise.odometry;
        let xy = n.sigma_xy * distance.sqrt();
        let theta = n.sigma_theta * (turn + distance).sqrt();
        if xy > 0.0 || theta > 0.0 {
            let error = Odometry { dx: rng.gauss(xy), dy: rng.gauss(xy), dtheta: rng.gauss(theta) };
            self.add_odometry(error);
        }
    }

    fn update_head(&mut self, dt: f64) {
        let before = self.head;
        if !self.holds_head() && self.head_speed_limit > 0.0 {
            let step = self.head_speed_limit * dt;
            self.head.yaw = approach(self.head.yaw, self.head_target.yaw, step);
            self.head.pitch = approach(self.head.pitch, self.head_target.pitch, step);
        }
        let dyaw = self.head.yaw - before.yaw;
        let dpitch = self.head.pitch - before.pitch;
        if dyaw != 0.0 {
            self.head_yaw.advance(self.head.yaw, dyaw);
        }
        self.head_rate = if dt > 0.0 { length(dyaw, dpitch) / dt } else { 0.0 };
    }

    fn update_activity(
        &mut self,
        dt: f64,
        config: &RobotConfig,
        noise: &NoiseParams,
        rng: &mut Stream,
        events: &mut BodyEvents,
    ) {
        let accel = &config.acceleration;
        let lin = accel.linear * dt;
        let rot = accel.turn * dt;
        self.accel_scale = 1.0;
        match self.activity {
            Activity::Standing => {
                self.velocity = Velocity::ZERO;
                if let Some(motion) = self.pending_special {
                    self.start_special(motion, config, Some((rng, noise.falls.stand_up_failure)));
                } else if matches!(self.order, BodyOrder::Walk { .. }) {
                    self.activity =
                        Activity::Walking { stage: CycleStage::Initialization, elapsed: 0.0 };
                }
            }
            Activity::Walking { stage: CycleStage::Initialization, elapsed } => {
                self.velocity = Velocity::ZERO;
                let elapsed = elapsed + dt;
                let keep_walking =
                    matches!(self.order, BodyOrder::Walk { .. }) && self.pending_special.is_none();
                self.activity = if !keep_walking {
                    Activity::Walking { stage: CycleStage::End, elapsed: 0.0 }
                } else if elapsed >= config.walk.init_duration {
                    Activity::Walking { stage: CycleStage::Execution, elapsed: 0.0 }
                } else {
                    Activity::Walking { stage: CycleStage::Initialization, elapsed }
                };
            }
            Activity::Walking { stage: CycleStage::Execution, elapsed } => {
                match (self.order, self.pending_special) {
                    (BodyOrder::Walk { velocity: target }, None) => {
                        self.velocity = Velocity {
                            vx: approach(self.velocity.vx, target.vx, lin),
                            vy: approach(self.velocity.vy, target.vy, lin),
                            omega: approach(self.velocity.omega, target.omega, rot),
                        };
                        self.activity = Activity::Walking {
                            stage: CycleStage::Execution,
                            elapsed: elapsed + dt,
                        };
                    }
                    _ => {
                        self.activity = Activity::Walking { stage: CycleStage::End, elapsed: 0.0 };
                        self.decelerate(lin, rot);
                    }
                }
            }
            Activity::Walking { stage: CycleStage::End, elapsed } => {
                self.decelerate(lin, rot);
                let stopped = self.velocity == Velocity::ZERO;
                let elapsed = if stopped { elapsed + dt } else { elapsed };
                self.activity = if stopped && elapsed >= config.walk.end_duration {
                    Activity::Standing
                } else {
                    Activity::Walking { stage: CycleStage::End, elapsed }
                };
            }
            Activity::Special(run) => self.update_special(run, dt, config, noise, rng, events),
            Activity::Falling { direction, elapsed, tilt0 } => {
                self.update_falling(direction, elapsed, tilt0, dt, config, events);
            }
            Activity::Fallen { direction } => {
                self.velocity = Velocity::ZERO;
                self.posture_direction = direction;
                self.posture_tilt = config.fall.lying_tilt;
                if let Some(motion) = self.pending_special
                    && motion.is(MotionName::STAND_UP)
                {
                    self.start_special(motion, config, Some((rng, noise.falls.stand_up_failure)));
                }
            }
        }
    }

    /// A special motion's step: its posture, its kick contact or dive block, its end.
    fn update_special(
        &mut self,
        mut run: SpecialRun,
        dt: f64,
        config: &RobotConfig,
        noise: &NoiseParams,
        rng: &mut Stream,
        events: &mut BodyEvents,
    ) {
        self.velocity = Velocity::ZERO;
        let before = run.elapsed;
        run.elapsed += dt;
        let progress = (run.elapsed / run.duration).clamp(0.0, 1.0);
        match &mut run.kind {
            SpecialKind::Kick { index, contacted } => {
                let contact = config.kicks.get(*index).map_or(0.5, |k| k.contact_time);
                if !*contacted && before < contact && run.elapsed >= contact {
                    *contacted = true;
                    events.kick_contact = Some(*index);
                }
                // The kicking leg swings the torso forward and back.
                self.posture_direction = FallDirection::Front;
                self.posture_tilt = 0.06 * (PI * progress).sin();
            }
            SpecialKind::StandUp { succeeds, direction, start_tilt } => {
                self.posture_direction = *direction;
                self.posture_tilt = if *succeeds || progress < 0.6 {
                    *start_tilt * (1.0 - smoothstep(progress))
                } else {
                    // It gets halfway up and falls back.
                    let at_failure = *start_tilt * (1.0 - smoothstep(0.6));
                    let back = smoothstep((progress - 0.6) / 0.2);
                    at_failure + (config.fall.lying_tilt - at_failure) * back
                };
            }
            SpecialKind::ProtectiveFall { direction, start_tilt } => {
                self.posture_direction = *direction;
                let s = progress * progress;
                self.posture_tilt = *start_tilt + (config.fall.lying_tilt - *start_tilt) * s;
                self.accel_scale = 1.0 - 0.5 * s;
            }
            SpecialKind::Dive { index } => {
                if let Some(dive) = config.dives.get(*index) {
                    let down = (run.elapsed / (dive.block_time * 1.5)).min(1.0);
                    match dive.side {
                        DiveSide::Left | DiveSide::Right => {
                            self.posture_direction = if dive.side == DiveSide::Left {
                                FallDirection::Left
                            } else {
                                FallDirection::Right
                            };
                            self.posture_tilt = config.fall.lying_tilt * smoothstep(down);
                        }
                        DiveSide::Both => {
                            // Sits down into a wide stance and gets up again.
                            self.posture_direction = FallDirection::Back;
                            self.posture_tilt = 0.35 * (PI * progress).sin();
                        }
                    }
                    if run.elapsed >= dive.block_time {
                        events.dive_block = Some((dive.side, dive.reach));
                    }
                }
            }
        }
        if run.elapsed >= run.duration {
            self.finish_special(run, config, noise, rng, events);
        } else {
            self.activity = Activity::Special(run);
        }
    }

    /// An unprotected fall's step, until the body lands.
    fn update_falling(
        &mut self,
        direction: FallDirection,
        elapsed: f64,
        tilt0: f64,
        dt: f64,
        config: &RobotConfig,
        events: &mut BodyEvents,
    ) {
        self.velocity = Velocity::ZERO;
        let elapsed = elapsed + dt;
        let lying = config.fall.lying_tilt;
        let duration = config.fall.duration;
        let tau = duration / (lying / tilt0).max(1.0 + 1e-9).acosh();
        let progress = (elapsed / duration).min(1.0);
        self.posture_direction = direction;
        self.posture_tilt = (tilt0 * (elapsed / tau).cosh()).min(lying);
        // Falling is partly free fall: the accelerometer sees less than gravity.
        self.accel_scale = 1.0 - 0.6 * progress * progress;
        if elapsed >= duration {
            self.land(direction, config, events, elapsed);
        } else {
            self.activity = Activity::Falling { direction, elapsed, tilt0 };
        }
    }

    fn finish_special(
        &mut self,
        run: SpecialRun,
        config: &RobotConfig,
        noise: &NoiseParams,
        rng: &mut Stream,
        events: &mut BodyEvents,
    ) {
        // The sequence consumed its order: the body stands (or lies) until told otherwise.
        self.order = BodyOrder::Stand;
        self.activity = Activity::Standing;
        match run.kind {
            SpecialKind::Kick { .. } => {
                self.posture_tilt = 0.0;
                if rng.chance(noise.falls.kick_fall_probability) {
                    let direction =
                        if rng.chance(0.5) { FallDirection::Front } else { FallDirection::Back };
                    if self.start_fall(direction) {
                        events.fall_started = Some((direction, FallCause::Kick));
                    }
                }
            }
            SpecialKind::StandUp { succeeds, direction, .. } => {
                events.stand_up = Some(succeeds);
                if succeeds {
                    self.posture_tilt = 0.0;
                } else {
                    self.posture_tilt = config.fall.lying_tilt;
                    self.activity = Activity::Fallen { direction };
                    events.fall_started = Some((direction, FallCause::StandUpFailed));
                }
            }
            SpecialKind::ProtectiveFall { direction, .. } => {
                self.land(direction, config, events, run.elapsed);
            }
            SpecialKind::Dive { index } => {
                let side = config.dives.get(index).map(|d| d.side);
                match side {
                    Some(DiveSide::Left) => {
                        self.land(FallDirection::Left, config, events, run.elapsed);
                    }
                    Some(DiveSide::Right) => {
                        self.land(FallDirection::Right, config, events, run.elapsed);
                    }
                    _ => self.posture_tilt = 0.0,
                }
            }
        }
    }

    fn land(
        &mut self,
        direction: FallDirection,
        config: &RobotConfig,
        events: &mut BodyEvents,
        since_onset: f64,
    ) {
        if !self.fall_announced {
            events.ordered_fall = Some(since_onset);
        }
        self.fall_announced = false;
        self.posture_direction = direction;
        self.posture_tilt = config.fall.lying_tilt;
        self.activity = Activity::Fallen { direction };
        self.impact = config.fall.impact_accel;
        self.order = BodyOrder::Stand;
        events.landed = Some(direction);
    }

    fn decelerate(&mut self, lin: f64, rot: f64) {
        self.velocity = Velocity {
            vx: approach(self.velocity.vx, 0.0, lin),
            vy: approach(self.velocity.vy, 0.0, lin),
            omega: approach(self.velocity.omega, 0.0, rot),
        };
    }

    /// Torso angles and rates from the posture and the gait's sway.
    fn update_angles(&mut self, dt: f64, config: &RobotConfig, dyaw: f64) {
        let (mut roll, mut pitch) = match self.posture_direction {
            FallDirection::Front => (0.0, self.posture_tilt),
            FallDirection::Back => (0.0, -self.posture_tilt),
            FallDirection::Right => (self.posture_tilt, 0.0),
            FallDirection::Left => (-self.posture_tilt, 0.0),
        };
        if self.is_walking() {
            let (sin, cos) = (self.gait.sin, self.gait.cos);
            roll += config.walk.sway_roll * sin;
            pitch += config.walk.sway_pitch * 2.0 * sin * cos;
        }
        if dt > 0.0 {
            self.gyro = [(roll - self.roll) / dt, (pitch - self.pitch) / dt, dyaw / dt];
        }
        self.roll = roll;
        self.pitch = pitch;
    }
}

/// A sequence of the simulator's catalogue, by the list it is in and its place there.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Entry {
    Kick(usize),
    StandUp(usize),
    Fall(usize),
    Dive(usize),
}

/// The catalogue's sequence `motion` selects; `None` for a kind it has no list of (an
/// application's own motion) or a number beyond its list.
fn catalogue_entry(config: &RobotConfig, motion: SpecialMotion) -> Option<Entry> {
    let index = usize::from(motion.sequence);
    let (entry, count) = match motion.kind {
        KICK => (Entry::Kick(index), config.kicks.len()),
        MotionName::STAND_UP => (Entry::StandUp(index), config.stand_ups.len()),
        MotionName::FALL => (Entry::Fall(index), config.protective_falls.len()),
        DIVE => (Entry::Dive(index), config.dives.len()),
        _ => return None,
    };
    (index < count).then_some(entry)
}

/// Limits a commanded velocity: each component to its own limit, and the three together to an
/// ellipsoid (a NAO cannot walk at full speed and turn at full speed at once).
pub(crate) fn clamp_velocity(v: Velocity, config: &RobotConfig) -> Velocity {
    let limits = &config.max_speed;
    let vx = v.vx.clamp(-limits.backward, limits.forward);
    let vy = v.vy.clamp(-limits.sideways, limits.sideways);
    let omega = v.omega.clamp(-limits.turn, limits.turn);
    let ratio = |value: f64, limit: f64| if limit > 0.0 { value / limit } else { 0.0 };
    let x_limit = if vx >= 0.0 { limits.forward } else { limits.backward };
    let norm = (ratio(vx, x_limit).powi(2)
        + ratio(vy, limits.sideways).powi(2)
        + ratio(omega, limits.turn).powi(2))
    .sqrt();
    if norm > 1.0 {
        Velocity { vx: vx / norm, vy: vy / norm, omega: omega / norm }
    } else {
        Velocity { vx, vy, omega }
    }
}

pub(crate) fn random_direction(rng: &mut Stream) -> FallDirection {
    let u = rng.uniform(0.0, 1.0);
    // NAOs fall forwards and backwards more often than sideways.
    if u < 0.35 {
        FallDirection::Front
    } else if u < 0.7 {
        FallDirection::Back
    } else if u < 0.85 {
        FallDirection::Left
    } else {
        FallDirection::Right
    }
}

/// The direction a robot falls when pushed along `push` (field frame).
pub(crate) fn push_direction(pose: &Pose, push: Vector<strata_robot::Global>) -> FallDirection {
    let local = pose.vector_to_robot(push);
    if local.x.abs() >= local.y.abs() {
        if local.x >= 0.0 { FallDirection::Front } else { FallDirection::Back }
    } else if local.y >= 0.0 {
        FallDirection::Left
    } else {
        FallDirection::Right
    }
}

/// When a fall started, for the ground truth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct FallRecord {
    pub onset: Time,
    pub direction: FallDirection,
    pub cause: FallCause,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::noise::NoiseLevel;
    use crate::random::Stream;

    fn run(body: &mut Body, seconds: f64, config: &RobotConfig) -> Vec<BodyEvents> {
        let noise = NoiseParams::preset(NoiseLevel::None);
        let mut rng = Stream::new(1, "t");
        let steps = (seconds / 0.012).round() as usize;
        (0..steps).map(|_| body.update(0.012, config, &noise, &mut rng)).collect()
    }

    #[test]
    fn walk_goes_through_initialization_execution_and_end() {
        let config = RobotConfig::default();
        let mut body = Body::new(Pose::default());
        body.order_body(BodyOrder::Walk { velocity: Velocity::new(0.2, 0.0, 0.0) }, &config)
            .expect("accepted");
        run(&mut body, 0.1, &config);
        assert!(matches!(
            body.motion_state(),
            BodyMotionState::Walking { stage: CycleStage::Initialization, .. }
        ));
        assert_eq!(body.pose.x, 0.0, "no motion during initialization");
        run(&mut body, 1.5, &config);
        assert!(matches!(
            body.motion_state(),
            BodyMotionState::Walking { stage: CycleStage::Execution, .. }
        ));
        assert!((body.velocity.vx - 0.2).abs() < 1e-9, "reached the commanded speed");
        let x = body.pose.x;
        assert!(x > 0.1);
        body.order_body(BodyOrder::Stand, &config).expect("accepted");
        run(&mut body, 0.05, &config);
        assert!(matches!(
            body.motion_state(),
            BodyMotionState::Walking { stage: CycleStage::End, .. }
        ));
        run(&mut body, 2.0, &config);
        assert_eq!(body.motion_state(), BodyMotionState::Standing);
        // Deceleration is limited: the robot did not stop dead.
        assert!(body.pose.x > x + 0.02);
        assert!((body.odometry.dx - body.pose.x).abs() < 1e-9, "exact odometry without noise");
        let (s, c) = sin_cos(body.pose.theta);
        assert!((body.heading().0 - s).abs() < 1e-14 && (body.heading().1 - c).abs() < 1e-14);
    }

    #[test]
    fn odometry_accumulates_like_composed_increments() {
        let mut body = Body::new(Pose::default());
        let mut exact = Odometry::ZERO;
        for i in 0..400 {
            let t = f64::from(i);
            let next = Odometry { dx: 0.003 * t.cos(), dy: 0.001, dtheta: 0.012 * (t * 0.1).sin() };
            body.add_odometry(next);
            exact = exact.then(next);
            if i == 150 {
                let taken = body.take_odometry();
                assert!((taken.dx - exact.dx).abs() < 1e-12 && (taken.dy - exact.dy).abs() < 1e-12);
                exact = Odometry::ZERO;
            }
        }
        let o = body.odometry;
        assert!((o.dx - exact.dx).abs() < 1e-12 && (o.dy - exact.dy).abs() < 1e-12, "{o:?}");
        assert!((o.dtheta - exact.dtheta).abs() < 1e-12, "{o:?} {exact:?}");
    }

    #[test]
    fn velocity_is_clamped_to_the_limits() {
        let config = RobotConfig::default();
        let v = clamp_velocity(Velocity::new(5.0, 0.0, 0.0), &config);
        assert_eq!(v.vx, config.max_speed.forward);
        let v = clamp_velocity(Velocity::new(5.0, 5.0, 5.0), &config);
        let norm = (v.vx / config.max_speed.forward).powi(2)
            + (v.vy / config.max_speed.sideways).powi(2)
            + (v.omega / config.max_speed.turn).powi(2);
        assert!((norm - 1.0).abs() < 1e-9);
    }

    #[test]
    fn a_fall_develops_then_a_stand_up_takes_seconds() {
        let config = RobotConfig::default();
        let mut body = Body::new(Pose::default());
        assert!(body.start_fall(FallDirection::Front));
        let events = run(&mut body, 0.3, &config);
        assert!(events.iter().all(|e| e.landed.is_none()));
        assert!(body.pitch > 0.05 && body.pitch < config.fall.lying_tilt);
        assert!(body.gyro[1] > 0.0, "the gyroscope shows the fall developing");
        let events = run(&mut body, 0.6, &config);
        assert!(events.iter().any(|e| e.landed == Some(FallDirection::Front)));
        assert!(body.is_fallen());
        // Walking is impossible while lying; a stand-up is.
        body.order_body(BodyOrder::Walk { velocity: Velocity::new(0.2, 0.0, 0.0) }, &config)
            .expect("accepted");
        run(&mut body, 0.5, &config);
        assert!(body.is_fallen());
        let kick = BodyOrder::Special { motion: kick(0) };
        assert!(body.order_body(kick, &config).is_err(), "no kicking while lying");
        body.order_body(BodyOrder::Special { motion: SpecialMotion::stand_up(0) }, &config)
            .expect("accepted");
        run(&mut body, 2.0, &config);
        assert!(matches!(body.motion_state(), BodyMotionState::Special { .. }));
        let events = run(&mut body, 2.0, &config);
        assert!(events.iter().any(|e| e.stand_up == Some(true)));
        assert_eq!(body.motion_state(), BodyMotionState::Standing);
        assert!(body.pitch.abs() < 1e-9);
    }

    #[test]
    fn a_kick_waits_for_the_walk_to_end_and_touches_once() {
        let config = RobotConfig::default();
        let mut body = Body::new(Pose::default());
        body.order_body(BodyOrder::Walk { velocity: Velocity::new(0.2, 0.0, 0.0) }, &config)
            .expect("accepted");
        run(&mut body, 1.0, &config);
        body.order_body(BodyOrder::Special { motion: kick(0) }, &config).expect("accepted");
        run(&mut body, 0.05, &config);
        assert!(matches!(
            body.motion_state(),
            BodyMotionState::Walking { stage: CycleStage::End, .. }
        ));
        let events = run(&mut body, 3.0, &config);
        assert_eq!(events.iter().filter(|e| e.kick_contact == Some(0)).count(), 1);
        assert_eq!(body.motion_state(), BodyMotionState::Standing);
        assert!(body.order_body(BodyOrder::Special { motion: kick(9) }, &config).is_err());
    }

    #[test]
    fn head_moves_at_its_speed_limit_within_joint_limits() {
        let config = RobotConfig::default();
        let mut body = Body::new(Pose::default());
        body.order_head(
            &HeadOrder { target: HeadAngles { yaw: 5.0, pitch: 0.0 }, max_speed: 1.0 },
            &config,
        );
        run(&mut body, 0.48, &config);
        assert!((body.head.yaw - 0.48).abs() < 1e-9);
        assert!((body.head_rate - 1.0).abs() < 1e-9);
        run(&mut body, 3.0, &config);
        assert_eq!(body.head.yaw, config.head.yaw_limits[1]);
        assert!(body.head_settled());
    }
}
