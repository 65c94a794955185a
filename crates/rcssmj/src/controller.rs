//! What happens in one server cycle, without sockets or threads: the newest orders and the
//! measured body in, one command per joint out. The platform runs this on its connection
//! thread, once per 20 ms server cycle; tests run it directly.
//!
//! The body resource is Booster's walking policy (see [`crate::policy`]): standing is the
//! policy with a zero command, walking the policy with the ordered velocity. A protective fall
//! softens every joint; a robot lying on the ground is reported fallen and held soft until a
//! stand-up order runs its keyframed get-up ([`crate::getup`]) or it is put upright. The head
//! resource is the neck, driven towards head orders at their speed limit.

use serde::{Deserialize, Serialize};
use strata_robot::control::reactive::FallDetectorConfig;
use strata_robot::geometry::{Odometry, Velocity};
use strata_robot::platform::{
    ActuatorOrders, BodyMotionState, BodyOrder, CycleStage, FallDirection, HeadAngles, HeadOrder,
    MotionName, MotionSpec, PlatformError, SpecialMotion,
};

use crate::getup::GetUpMotions;
use crate::joints::{
    FIRST_LEG, HEAD_PITCH, HEAD_PITCH_LIMITS, HEAD_YAW, HEAD_YAW_LIMITS, JOINT_COUNT, JointArray,
    LEG_COUNT,
};
use crate::kick::{self, KickCycle, KickRun, KickSpec};
use crate::kinematics::Quaternion;
use crate::policy::{LegState, WalkCommand, WalkPolicy};

/// The T1's kicks, by the league's name, which soccer orders them by.
pub const KICK: MotionName = MotionName::from_static(strata_spl::motions::KICK.name);

/// Kick `sequence` of the catalogue ([`MotionConfig::kicks`]).
pub const fn kick_motion(sequence: u8) -> SpecialMotion {
    SpecialMotion::new(KICK, sequence, strata_spl::motions::KICK.head)
}

/// The server's agent cycle, s: every perception advances the controller by this much.
pub const CYCLE: f64 = 0.02;

/// The T1's fall detector: the architecture's prediction (tilt 0.1 s ahead by the gyroscope past
/// 0.5 rad) and a lean past 20 degrees. In six 3 vs 3 games with 300-second halves (72
/// robot-halves, 2026-11-27) the torso passed 17 degrees from upright 27 times and the T1 fell
/// within 2 s every time, while the prediction passed 0.40 rad 4 times and 0.45 rad once
/// without a fall: a T1 leaning 20 degrees will fall, however slowly it starts, and waiting
/// for the lean to speed up (a push from rest: 45 to 305 ms) only delays the protective fall.
pub fn fall_detector() -> FallDetectorConfig {
    FallDetectorConfig { falling_tilt: Some(0.35), ..FallDetectorConfig::default() }
}

/// A heading change between two perceptions beyond this is a placement, not a turn, rad
/// (15 rad/s; the policy turns at 1 rad/s at most). So is any change of the torso's
/// orientation beyond it, which catches a robot lying too long that the server's referee puts
/// back upright: a toppling T1 turns at about 5 rad/s, and no fall or get-up of the get-up
/// test was taken for a placement (`tests/getup.rs`).
const MAX_TURN_PER_CYCLE: f64 = 0.3;

/// Perceptions after the platform's own beam ([`T1Controller::restart`]) in which a placement
/// is that beam's (its perception arrives one or two cycles later): world modeling starts from
/// the beam's pose already, so it is not reported.
const OWN_BEAM_CYCLES: u32 = 10;

/// How long a protective fall keeps the joints soft, s.
const FALL_DURATION: f64 = 0.6;

/// Tuning of the platform's own motion control.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MotionConfig {
    /// The fastest walk the platform accepts (forward, sideways m/s, turning rad/s); faster
    /// orders are clamped. Booster trained the policy for about these.
    pub max_velocity: Velocity,
    /// Upper bound on any head order's speed, rad/s.
    pub max_head_speed: f64,
    /// Head orders count as reached when the joints are this close to the target, rad.
    pub head_settled_tolerance: f64,
    /// Head joint gains, N m/rad and N m s/rad.
    pub head_stiffness: f64,
    pub head_damping: f64,
    /// Torso tilt beyond this means lying on the ground, rad.
    pub fallen_angle: f64,
    /// Consecutive cycles beyond `fallen_angle` before the robot counts as fallen.
    pub fallen_cycles: u32,
    /// Consecutive upright cycles before a fallen robot counts as standing again.
    pub upright_cycles: u32,
    /// Gains of a soft body (protective fall, lying), as a share of the policy's.
    pub soft_gain: f64,
    /// The walk the body really makes for a commanded one, per axis (forward, sideways,
    /// turning): odometry reports commanded x factor. Measured on this policy in the server
    /// (docs/rcssservermj.md).
    pub odometry_scale: [f64; 3],
    /// The kicks, by sequence number (`Kick(n)` is the n-th): [`crate::kick`].
    pub kicks: Vec<KickSpec>,
}

impl Default for MotionConfig {
    fn default() -> Self {
        MotionConfig {
            max_velocity: Velocity::new(0.6, 0.3, 1.0),
            max_head_speed: 4.0,
            head_settled_tolerance: 0.05,
            head_stiffness: 20.0,
            head_damping: 0.2,
            fallen_angle: 1.0,
            fallen_cycles: 5,
            upright_cycles: 25,
            soft_gain: 0.1,
            odometry_scale: [0.92, 0.85, 1.0],
            kicks: kick::catalogue(),
        }
    }
}

/// The body as measured in one cycle.
#[derive(Clone, Debug, PartialEq)]
pub struct MeasuredBody {
    /// The torso's orientation in the world (the IMU's filter output).
    pub orientation: Quaternion,
    /// Torso angular velocity in the torso frame, rad/s.
    pub gyro: [f64; 3],
    /// Joint angles, rad, and velocities, rad/s, in [`crate::joints::JOINTS`] order.
    pub joint_positions: JointArray<f64>,
    pub joint_velocities: JointArray<f64>,
}

/// One joint's command: a PD target with feed-forward torque, SI units.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct JointCommand {
    /// rad
    pub q: f64,
    /// rad/s
    pub dq: f64,
    /// N m/rad
    pub kp: f64,
    /// N m s/rad
    pub kd: f64,
    /// N m
    pub tau: f64,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum BodyMode {
    Standing,
    Walking(Velocity),
    /// A protective fall: soft joints for a while.
    Falling {
        elapsed: f64,
    },
    Fallen(FallDirection),
    Kicking(KickRun),
    /// A keyframed get-up, `StandUp(sequence)`, from the joint angles at its start.
    GettingUp {
        sequence: u8,
        elapsed: f64,
        start: JointArray<f64>,
    },
}

/// The T1's motion control.
#[derive(Debug)]
pub struct T1Controller {
    config: MotionConfig,
    policy: WalkPolicy,
    body: BodyMode,
    head_order: Option<HeadOrder>,
    /// Where the head is being driven this cycle (moves towards the order's target).
    head_command: Option<HeadAngles>,
    measured: Option<MeasuredBody>,
    odometry: Odometry,
    tilted_cycles: u32,
    upright_cycles: u32,
    getup: GetUpMotions,
    /// A placement seen since [`T1Controller::take_placement`] was last called.
    placed: bool,
    /// Perceptions left in which a placement is the platform's own beam.
    own_beam_cycles: u32,
    /// The heading at the last cycle whose odometry was integrated, and whether that was the
    /// previous cycle. A fall and a stand-up integrate none, and turn the robot (rolling
    /// over, by up to half a turn): the net turn counts when odometry resumes, or world
    /// modeling keeps the old heading and, on a symmetric field, settles on the mirror pose.
    upright_yaw: Option<f64>,
    integrated_last_cycle: bool,
}

impl T1Controller {
    pub fn new(config: MotionConfig, policy: WalkPolicy) -> T1Controller {
        T1Controller {
            config,
            policy,
            body: BodyMode::Standing,
            head_order: None,
            head_command: None,
            measured: None,
            odometry: Odometry::ZERO,
            tilted_cycles: 0,
            upright_cycles: 0,
            getup: GetUpMotions::default(),
            placed: false,
            own_beam_cycles: 0,
            upright_yaw: None,
            integrated_last_cycle: false,
        }
    }

    /// This controller with these get-up motions (`new` has none: a fallen robot waits to be
    /// put upright).
    pub fn with_getup(mut self, getup: GetUpMotions) -> T1Controller {
        self.getup = getup;
        self
    }

    pub fn config(&self) -> &MotionConfig {
        &self.config
    }

    /// The special motions this body can make.
    pub fn catalogue(&self) -> Vec<MotionSpec> {
        let mut catalogue = vec![MotionSpec {
            motion: SpecialMotion::fall(0),
            name: "protective fall: every joint soft".to_owned(),
            duration: std::time::Duration::from_secs_f64(FALL_DURATION),
        }];
        catalogue.extend(self.config.kicks.iter().zip(0u8..).map(|(spec, n)| MotionSpec {
            motion: kick_motion(n),
            name: format!("kick {}", spec.name),
            duration: std::time::Duration::from_secs_f64(spec.duration()),
        }));
        for (sequence, side) in [(0, "front (face down)"), (1, "back (face up)")] {
            if let Some(motion) = self.getup.motion(sequence) {
                catalogue.push(MotionSpec {
                    motion: SpecialMotion::stand_up(sequence),
                    name: format!("keyframed get-up from the {side}"),
                    duration: std::time::Duration::from_secs_f64(motion.duration()),
                });
            }
        }
        catalogue
    }

    /// Starts over after the server put the robot somewhere with every joint at zero (the
    /// platform's own beam): the policy forgets its previous actions, the body stands, the head
    /// is driven from where it is. The placement the next perceptions show is the beam's and is
    /// not reported ([`T1Controller::take_placement`]): the robot knows where it put itself.
    pub fn restart(&mut self) {
        self.policy.reset();
        self.body = BodyMode::Standing;
        self.head_command = None;
        self.measured = None;
        self.tilted_cycles = 0;
        self.upright_cycles = 0;
        self.own_beam_cycles = OWN_BEAM_CYCLES;
    }

    /// Takes new orders; a `None` part keeps the previous one.
    pub fn apply(&mut self, orders: &ActuatorOrders) -> Result<(), PlatformError> {
        if let Some(head) = orders.head {
            if !(head.target.yaw.is_finite() && head.target.pitch.is_finite()) {
                return Err(PlatformError::Unsupported(format!(
                    "a head order to {:?}",
                    head.target
                )));
            }
            self.head_order = Some(head);
        }
        let Some(body) = orders.body else { return Ok(()) };
        match (body, self.body) {
            // Lying, or falling, the body takes no walking orders: only a stand-up would help.
            (
                BodyOrder::Stand | BodyOrder::Walk { .. },
                BodyMode::Fallen(_) | BodyMode::Falling { .. } | BodyMode::GettingUp { .. },
            ) => Ok(()),
            // A kick runs to its end: walking orders meanwhile are dropped (actuation holds the
            // body until the kick reports its end).
            (BodyOrder::Stand | BodyOrder::Walk { .. }, BodyMode::Kicking(_)) => Ok(()),
            (BodyOrder::Stand, _) => {
                self.body = BodyMode::Standing;
                Ok(())
            }
            (BodyOrder::Walk { velocity }, _) => {
                if !velocity.is_finite() {
                    return Err(PlatformError::Unsupported(format!("walking at {velocity:?}")));
                }
                let max = self.config.max_velocity;
                let v = Velocity::new(
                    velocity.vx.clamp(-max.vx, max.vx),
                    velocity.vy.clamp(-max.vy, max.vy),
                    velocity.omega.clamp(-max.omega, max.omega),
                );
                self.body = if v.is_zero() { BodyMode::Standing } else { BodyMode::Walking(v) };
                Ok(())
            }
            (
                BodyOrder::Special { motion: SpecialMotion { kind: MotionName::FALL, .. } },
                BodyMode::Fallen(_) | BodyMode::GettingUp { .. },
            ) => Ok(()),
            (
                BodyOrder::Special { motion: SpecialMotion { kind: MotionName::FALL, .. } },
                BodyMode::Falling { .. },
            ) => Ok(()),
            (BodyOrder::Special { motion: SpecialMotion { kind: MotionName::FALL, .. } }, _) => {
                self.body = BodyMode::Falling { elapsed: 0.0 };
                Ok(())
            }
            (
                BodyOrder::Special { motion: SpecialMotion { kind: KICK, .. } },
                BodyMode::Kicking(_),
            ) => Ok(()),
            (
                BodyOrder::Special { motion: SpecialMotion { kind: KICK, sequence: n, .. } },
                BodyMode::Standing | BodyMode::Walking(_),
            ) if let Some(spec) = self.config.kicks.get(usize::from(n)) => {
                self.body = BodyMode::Kicking(KickRun::new(n, spec, self.policy.is_walking()));
                Ok(())
            }
            (BodyOrder::Special { motion: SpecialMotion { kind: KICK, .. } }, _)
                if matches!(
                    self.body,
                    BodyMode::Fallen(_) | BodyMode::Falling { .. } | BodyMode::GettingUp { .. }
                ) =>
            {
                Err(PlatformError::Unsupported(
                    "a kick while falling, fallen or getting up".to_owned(),
                ))
            }
            (
                BodyOrder::Special {
                    motion: SpecialMotion { kind: MotionName::STAND_UP, sequence, .. },
                },
                BodyMode::Fallen(_),
            ) if self.getup.motion(sequence).is_some() => {
                let start = self.measured.as_ref().map_or_else(
                    || self.policy.config().default_targets().map(|t| t.q),
                    |m| m.joint_positions,
                );
                self.body = BodyMode::GettingUp { sequence, elapsed: 0.0, start };
                Ok(())
            }
            (
                BodyOrder::Special { motion: SpecialMotion { kind: MotionName::STAND_UP, .. } },
                BodyMode::GettingUp { .. },
            ) => Ok(()),
            // Refused rather than ignored, so actuation frees the body: ordered again once the
            // robot lies still.
            (
                BodyOrder::Special { motion: SpecialMotion { kind: MotionName::STAND_UP, .. } },
                mode,
            ) if !matches!(mode, BodyMode::Fallen(_)) => Err(PlatformError::Unsupported(format!(
                "a stand-up while the T1 is not lying on the ground ({mode:?})"
            ))),
            (BodyOrder::Special { motion }, _) => Err(PlatformError::Unsupported(format!(
                "special motion {motion} on the T1 (its catalogue: {})",
                self.catalogue()
                    .iter()
                    .map(|m| m.motion.to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))),
        }
    }

    /// One server cycle: updates the body's state from the measurement and returns every
    /// joint's command.
    pub fn step(&mut self, measured: MeasuredBody) -> JointArray<JointCommand> {
        let previous_yaw = self.measured.as_ref().map(|m| m.orientation.yaw());
        let placed = self.track_placement(&measured);
        if placed {
            // The server's move is no turn of the robot's, lying or not.
            self.upright_yaw = Some(measured.orientation.yaw());
        }
        // Odometry resuming after a stretch without: it turns by the whole stretch's turn.
        let previous_yaw = if self.integrated_last_cycle { previous_yaw } else { self.upright_yaw };
        let resumed = !self.integrated_last_cycle && self.upright_yaw.is_some();
        self.integrated_last_cycle = false;
        self.track_fall(&measured);
        let mut commands = self.hold_default_pose();
        let soft = self.config.soft_gain;
        match &mut self.body {
            BodyMode::Standing | BodyMode::Walking(_) | BodyMode::Kicking(_) => {
                let cycle = self.walk_cycle();
                let state = leg_state(&measured);
                let targets =
                    self.policy.step_smoothed_by(&state, cycle.command, cycle.smoothing_step);
                for (i, target) in targets.iter().enumerate() {
                    commands[FIRST_LEG + i] = JointCommand {
                        q: target.q + cycle.offsets[i],
                        dq: 0.0,
                        kp: target.kp,
                        kd: target.kd,
                        tau: 0.0,
                    };
                }
                self.integrate_odometry(previous_yaw, &measured, placed, resumed);
            }
            BodyMode::Falling { elapsed } => {
                *elapsed += CYCLE;
                for command in &mut commands {
                    command.kp *= soft;
                    command.kd *= soft;
                }
                if *elapsed >= FALL_DURATION && self.tilted_cycles == 0 {
                    // A protective fall that ended upright (a false alarm, a stumble caught).
                    self.body = BodyMode::Standing;
                    self.policy.reset();
                }
            }
            BodyMode::Fallen(_) => {
                for command in &mut commands {
                    command.kp *= soft;
                    command.kd *= soft;
                }
            }
            BodyMode::GettingUp { sequence, elapsed, start } => {
                if let Some(motion) = self.getup.motion(*sequence) {
                    let gains = self.policy.config().default_targets();
                    commands = motion.commands(*elapsed, start, &gains);
                    *elapsed += CYCLE;
                    if *elapsed >= motion.duration() + CYCLE / 2.0 {
                        self.body = self.getup_ended(&measured);
                    }
                }
            }
        }
        self.step_head(&measured, &mut commands);
        self.measured = Some(measured);
        commands
    }

    /// The policy's command this cycle (and a kick's leg offsets); a kick that ends here leaves
    /// the body standing.
    fn walk_cycle(&mut self) -> KickCycle {
        let smoothing_step = self.policy.config().control.command_smoothing_step;
        let walk = |v: Velocity| KickCycle {
            command: WalkCommand { vx: v.vx, vy: v.vy, yaw_rate: v.omega },
            smoothing_step,
            restart_gait: false,
            offsets: [0.0; LEG_COUNT],
        };
        match &mut self.body {
            BodyMode::Walking(v) => walk(*v),
            BodyMode::Kicking(run) => match self.config.kicks.get(usize::from(run.sequence)) {
                Some(spec) => {
                    let cycle = run.step(spec, self.policy.phase(), CYCLE);
                    if cycle.restart_gait {
                        self.policy.restart_gait();
                    }
                    if run.finished(spec) {
                        self.body = BodyMode::Standing;
                    }
                    cycle
                }
                None => {
                    self.body = BodyMode::Standing;
                    walk(Velocity::ZERO)
                }
            },
            _ => walk(Velocity::ZERO),
        }
    }

    /// Every joint at the deployment's default pose with its gains: what arms and waist do
    /// always, and the legs' start before the policy overrides them.
    fn hold_default_pose(&self) -> JointArray<JointCommand> {
        self.policy.config().default_targets().map(|target| JointCommand {
            q: target.q,
            dq: 0.0,
            kp: target.kp,
            kd: target.kd,
            tau: 0.0,
        })
    }

    /// Standing if the get-up ended upright (the policy starts over from here), else still
    /// fallen: the stand-up may be ordered again.
    fn getup_ended(&mut self, measured: &MeasuredBody) -> BodyMode {
        let [roll, pitch] = measured.orientation.roll_pitch();
        if roll.abs().max(pitch.abs()) < self.getup.upright_angle() {
            self.policy.reset();
            BodyMode::Standing
        } else {
            BodyMode::Fallen(fall_direction(roll, pitch))
        }
    }

    fn track_fall(&mut self, measured: &MeasuredBody) {
        let [roll, pitch] = measured.orientation.roll_pitch();
        let tilted = roll.abs().max(pitch.abs()) > self.config.fallen_angle;
        if tilted {
            self.tilted_cycles += 1;
            self.upright_cycles = 0;
        } else {
            self.tilted_cycles = 0;
            self.upright_cycles += 1;
        }
        match self.body {
            BodyMode::Fallen(_) if self.upright_cycles >= self.config.upright_cycles => {
                // Put back on its feet (a referee's or a trainer's beam).
                self.body = BodyMode::Standing;
                self.policy.reset();
            }
            // Lying, the side it lies on now: it may have rolled over, or been laid down again.
            BodyMode::Fallen(_) if tilted => {
                self.body = BodyMode::Fallen(fall_direction(roll, pitch))
            }
            // A get-up tilts the torso on purpose; its end decides.
            BodyMode::Fallen(_) | BodyMode::GettingUp { .. } => {}
            _ if self.tilted_cycles >= self.config.fallen_cycles => {
                self.body = BodyMode::Fallen(fall_direction(roll, pitch));
            }
            _ => {}
        }
    }

    /// Whether the server placed the robot between the previous perception and this one (the
    /// torso turned faster than any motion turns it); reported unless it was the platform's own
    /// beam.
    fn track_placement(&mut self, measured: &MeasuredBody) -> bool {
        let placed = self
            .measured
            .as_ref()
            .is_some_and(|m| m.orientation.angle_to(&measured.orientation) > MAX_TURN_PER_CYCLE);
        if placed && self.own_beam_cycles > 0 {
            self.own_beam_cycles = 0;
        } else if placed {
            self.placed = true;
        } else {
            self.own_beam_cycles = self.own_beam_cycles.saturating_sub(1);
        }
        placed
    }

    fn integrate_odometry(
        &mut self,
        previous_yaw: Option<f64>,
        measured: &MeasuredBody,
        placed: bool,
        resumed: bool,
    ) {
        let [sx, sy, st] = self.config.odometry_scale;
        let v = self.policy.smoothed_command();
        // Turning comes from the IMU's heading (what a real T1 integrates from its gyro); a
        // first cycle has no previous heading and contributes only the commanded turn.
        let commanded = st * v.yaw_rate * CYCLE;
        let dtheta = match previous_yaw {
            Some(yaw) => {
                let turned =
                    strata_robot::geometry::normalize_angle(measured.orientation.yaw() - yaw);
                // No step turns the body this fast: the server placed the robot (a beam, or a
                // referee's move, whose perception can arrive a cycle after the restart).
                // After a fall or a stand-up the turn is the motion's, whatever its size.
                let stepped = resumed || turned.abs() <= MAX_TURN_PER_CYCLE;
                if placed || !stepped { commanded } else { turned }
            }
            None => commanded,
        };
        let step = Odometry { dx: sx * v.vx * CYCLE, dy: sy * v.vy * CYCLE, dtheta };
        self.odometry = self.odometry.then(step);
        self.upright_yaw = Some(measured.orientation.yaw());
        self.integrated_last_cycle = true;
    }

    fn step_head(&mut self, measured: &MeasuredBody, commands: &mut JointArray<JointCommand>) {
        let encoders = HeadAngles {
            yaw: measured.joint_positions[HEAD_YAW],
            pitch: measured.joint_positions[HEAD_PITCH],
        };
        let current = self.head_command.unwrap_or(encoders);
        let next = match self.head_order {
            Some(order) => {
                let target = clamp_head(order.target);
                let speed = if order.max_speed.is_finite() && order.max_speed > 0.0 {
                    order.max_speed.min(self.config.max_head_speed)
                } else {
                    self.config.max_head_speed
                };
                let (dy, dp) = (target.yaw - current.yaw, target.pitch - current.pitch);
                let distance = dy.hypot(dp);
                let reach = speed * CYCLE;
                if distance <= reach {
                    target
                } else {
                    let t = reach / distance;
                    HeadAngles { yaw: current.yaw + dy * t, pitch: current.pitch + dp * t }
                }
            }
            None => current,
        };
        self.head_command = Some(next);
        let falling = matches!(self.body, BodyMode::Falling { .. } | BodyMode::Fallen(_));
        let gain = if falling { self.config.soft_gain } else { 1.0 };
        for (joint, q) in [(HEAD_YAW, next.yaw), (HEAD_PITCH, next.pitch)] {
            commands[joint] = JointCommand {
                q,
                dq: 0.0,
                kp: gain * self.config.head_stiffness,
                kd: gain * self.config.head_damping,
                tau: 0.0,
            };
        }
    }

    /// The head's measured angles.
    pub fn head(&self) -> HeadAngles {
        self.measured
            .as_ref()
            .map(|m| HeadAngles {
                yaw: m.joint_positions[HEAD_YAW],
                pitch: m.joint_positions[HEAD_PITCH],
            })
            .unwrap_or_default()
    }

    /// Whether the head reached its last ordered target.
    pub fn head_settled(&self) -> bool {
        let Some(order) = self.head_order else { return true };
        let target = clamp_head(order.target);
        let head = self.head();
        (head.yaw - target.yaw).abs() <= self.config.head_settled_tolerance
            && (head.pitch - target.pitch).abs() <= self.config.head_settled_tolerance
    }

    /// What the body is doing, as actuation reads it.
    pub fn body_state(&self) -> BodyMotionState {
        match self.body {
            BodyMode::Standing => BodyMotionState::Standing,
            BodyMode::Walking(velocity) => {
                // The policy's gait has no start or stop phase: any cycle may take a new
                // command (the deployment smooths it), so walking is always in execution.
                BodyMotionState::Walking { stage: CycleStage::Execution, velocity }
            }
            BodyMode::Falling { elapsed } => BodyMotionState::Special {
                motion: SpecialMotion::fall(0),
                elapsed,
                duration: FALL_DURATION,
            },
            BodyMode::Fallen(direction) => BodyMotionState::Fallen { direction },
            BodyMode::Kicking(run) => BodyMotionState::Special {
                motion: kick_motion(run.sequence),
                elapsed: run.elapsed,
                duration: self
                    .config
                    .kicks
                    .get(usize::from(run.sequence))
                    .map_or(0.0, |k| run.duration(k)),
            },
            BodyMode::GettingUp { sequence, elapsed, .. } => BodyMotionState::Special {
                motion: SpecialMotion::stand_up(sequence),
                elapsed,
                duration: self.getup.motion(sequence).map_or(0.0, |m| m.duration()),
            },
        }
    }

    /// The motion since the last call.
    pub fn take_odometry(&mut self) -> Odometry {
        std::mem::replace(&mut self.odometry, Odometry::ZERO)
    }

    /// Whether the server placed the robot since the last call (a referee's move, a trainer's
    /// through the monitor port; not the platform's own beam): something other than its own
    /// motion moved it, to where it cannot know. Only a placement that turns the torso shows:
    /// the IMU cannot see a move that keeps the orientation.
    pub fn take_placement(&mut self) -> bool {
        std::mem::take(&mut self.placed)
    }
}

fn leg_state(measured: &MeasuredBody) -> LegState {
    let legs = FIRST_LEG..FIRST_LEG + LEG_COUNT;
    let mut positions = [0.0; LEG_COUNT];
    let mut velocities = [0.0; LEG_COUNT];
    positions.copy_from_slice(&measured.joint_positions[legs.clone()]);
    velocities.copy_from_slice(&measured.joint_velocities[legs]);
    let q = measured.orientation;
    LegState {
        torso_orientation: [q.w, q.x, q.y, q.z],
        torso_angular_velocity: measured.gyro,
        joint_positions: positions,
        joint_velocities: velocities,
    }
}

fn fall_direction(roll: f64, pitch: f64) -> FallDirection {
    if pitch.abs() >= roll.abs() {
        if pitch > 0.0 { FallDirection::Front } else { FallDirection::Back }
    } else if roll > 0.0 {
        FallDirection::Right
    } else {
        FallDirection::Left
    }
}

fn clamp_head(target: HeadAngles) -> HeadAngles {
    HeadAngles {
        yaw: target.yaw.clamp(HEAD_YAW_LIMITS.0, HEAD_YAW_LIMITS.1),
        pitch: target.pitch.clamp(HEAD_PITCH_LIMITS.0, HEAD_PITCH_LIMITS.1),
    }
}

const _: () = assert!(JOINT_COUNT == FIRST_LEG + LEG_COUNT);

#[cfg(test)]
mod tests {
    use super::*;
    use strata_robot::platform::HeadOrder;

    fn controller() -> T1Controller {
        let policy = WalkPolicy::shipped().expect("the shipped policy loads");
        T1Controller::new(MotionConfig::default(), policy)
    }

    fn upright() -> MeasuredBody {
        MeasuredBody {
            orientation: Quaternion::IDENTITY,
            gyro: [0.0; 3],
            joint_positions: [0.0; JOINT_COUNT],
            joint_velocities: [0.0; JOINT_COUNT],
        }
    }

    fn pitched(angle: f64) -> MeasuredBody {
        MeasuredBody {
            orientation: Quaternion {
                w: (angle / 2.0).cos(),
                x: 0.0,
                y: (angle / 2.0).sin(),
                z: 0.0,
            },
            ..upright()
        }
    }

    fn body(order: BodyOrder) -> ActuatorOrders {
        ActuatorOrders { head: None, body: Some(order) }
    }

    #[test]
    fn walk_orders_are_clamped_and_a_zero_walk_is_standing() {
        let mut c = controller();
        c.apply(&body(BodyOrder::Walk { velocity: Velocity::new(3.0, -2.0, 0.5) })).expect("taken");
        match c.body_state() {
            BodyMotionState::Walking { velocity, .. } => {
                assert_eq!((velocity.vx, velocity.vy, velocity.omega), (0.6, -0.3, 0.5));
            }
            other => panic!("walking expected, got {other:?}"),
        }
        c.apply(&body(BodyOrder::Walk { velocity: Velocity::ZERO })).expect("taken");
        assert_eq!(c.body_state(), BodyMotionState::Standing);
        let nan = Velocity::new(f64::NAN, 0.0, 0.0);
        assert!(c.apply(&body(BodyOrder::Walk { velocity: nan })).is_err());
        let side_kick = BodyOrder::Special { motion: kick_motion(2) };
        assert!(matches!(c.apply(&body(side_kick)), Err(PlatformError::Unsupported(_))));
    }

    fn kick(n: u8) -> ActuatorOrders {
        body(BodyOrder::Special { motion: kick_motion(n) })
    }

    #[test]
    fn the_catalogue_lists_the_kicks_with_their_durations() {
        let c = controller();
        let catalogue = c.catalogue();
        for (n, spec) in c.config().kicks.iter().enumerate() {
            let entry = catalogue
                .iter()
                .find(|m| m.motion == kick_motion(n as u8))
                .expect("each kick is in the catalogue");
            assert_eq!(entry.duration.as_secs_f64(), spec.duration());
            assert!(entry.name.contains(&spec.name));
        }
        assert!(catalogue.iter().any(|m| m.motion == SpecialMotion::fall(0)));
    }

    #[test]
    fn a_kick_from_a_walk_runs_its_duration_ignoring_walks_then_stands() {
        let mut c = controller();
        c.apply(&body(BodyOrder::Walk { velocity: Velocity::new(0.2, 0.0, 0.0) })).expect("ok");
        c.step(upright());
        c.apply(&kick(1)).expect("a pass is taken while walking");
        // From a walk the kick stands first.
        let spec = &c.config().kicks[1];
        let duration = spec.stop + spec.duration();
        let cycles = (duration / CYCLE).round() as usize;
        for i in 0..cycles {
            match c.body_state() {
                BodyMotionState::Special { motion, elapsed, duration: d }
                    if motion == kick_motion(1) =>
                {
                    assert!((elapsed - i as f64 * CYCLE).abs() < 1e-9);
                    assert_eq!(d, duration);
                }
                other => panic!("kicking expected at cycle {i}, got {other:?}"),
            }
            // Walks and kicks ordered meanwhile change nothing.
            c.apply(&body(BodyOrder::Walk { velocity: Velocity::new(0.0, 0.3, 0.0) })).expect("ok");
            c.apply(&kick(0)).expect("ok");
            c.step(upright());
        }
        assert_eq!(c.body_state(), BodyMotionState::Standing);
        // The burst walked forward.
        assert!(c.take_odometry().dx > 0.1);
    }

    #[test]
    fn a_kick_is_refused_on_the_ground_and_a_fall_interrupts_it() {
        let mut c = controller();
        c.apply(&kick(0)).expect("a kick is taken while standing");
        c.step(upright());
        c.apply(&body(BodyOrder::Special { motion: SpecialMotion::fall(0) })).expect("taken");
        assert!(matches!(
            c.body_state(),
            BodyMotionState::Special { motion, .. } if motion == SpecialMotion::fall(0)
        ));
        for _ in 0..MotionConfig::default().fallen_cycles {
            c.step(pitched(1.4));
        }
        assert!(matches!(c.body_state(), BodyMotionState::Fallen { .. }));
        assert!(matches!(c.apply(&kick(0)), Err(PlatformError::Unsupported(_))));
        assert!(matches!(c.body_state(), BodyMotionState::Fallen { .. }));
    }

    #[test]
    fn a_kick_falling_over_is_fallen() {
        let mut c = controller();
        c.apply(&kick(0)).expect("taken");
        for _ in 0..MotionConfig::default().fallen_cycles {
            c.step(pitched(-1.4));
        }
        assert_eq!(c.body_state(), BodyMotionState::Fallen { direction: FallDirection::Back });
    }

    #[test]
    fn the_policy_drives_the_legs_and_the_rest_holds_the_default_pose() {
        let mut c = controller();
        let commands = c.step(upright());
        let defaults = c.policy.config().default_targets();
        for i in 2..FIRST_LEG {
            assert_eq!(commands[i].q, defaults[i].q, "joint {i}");
            assert!(commands[i].kp > 0.0);
        }
        // Legs at zero are far from the default pose: the policy moves them, within its clip.
        assert!(commands[FIRST_LEG..].iter().all(|c| c.q.is_finite() && c.kp > 0.0));
    }

    #[test]
    fn lying_for_a_few_cycles_is_fallen_and_upright_again_is_standing() {
        let mut c = controller();
        for _ in 0..4 {
            c.step(pitched(1.3));
        }
        assert_eq!(c.body_state(), BodyMotionState::Standing, "a stumble is not a fall");
        c.step(pitched(1.3));
        assert_eq!(c.body_state(), BodyMotionState::Fallen { direction: FallDirection::Front });
        let soft = c.step(pitched(-1.5));
        assert!(soft[FIRST_LEG].kp < 0.2 * c.policy.config().default_targets()[FIRST_LEG].kp);
        // Walking orders do nothing to a robot on the ground.
        c.apply(&body(BodyOrder::Walk { velocity: Velocity::new(0.3, 0.0, 0.0) })).expect("ok");
        assert!(matches!(c.body_state(), BodyMotionState::Fallen { .. }));
        for _ in 0..MotionConfig::default().upright_cycles {
            c.step(upright());
        }
        assert_eq!(c.body_state(), BodyMotionState::Standing);
    }

    #[test]
    fn a_protective_fall_softens_every_joint_for_its_duration() {
        let mut c = controller();
        c.apply(&body(BodyOrder::Special { motion: SpecialMotion::fall(0) })).expect("taken");
        let commands = c.step(upright());
        assert!(matches!(c.body_state(), BodyMotionState::Special { .. }));
        let defaults = c.policy.config().default_targets();
        for (command, default) in commands.iter().zip(defaults).skip(2) {
            assert!(command.kp <= 0.1 * default.kp + 1e-12);
        }
        for _ in 0..(FALL_DURATION / CYCLE).ceil() as usize {
            c.step(upright());
        }
        assert_eq!(c.body_state(), BodyMotionState::Standing, "caught upright: standing again");
    }

    /// A controller with a two-keyframe get-up from the front only, 0.2 s + 0.3 s.
    fn with_front_getup() -> T1Controller {
        let getup = GetUpMotions::from_toml_str(
            "upright_angle = 0.5\n\
             [[front]]\nduration = 0.2\ngain = 2.0\ntargets = { knee_pitch = 2.0 }\n\
             [[front]]\nduration = 0.3\ntargets = { knee_pitch = 0.4 }\n",
            "test",
        )
        .expect("a valid get-up");
        controller().with_getup(getup)
    }

    fn lie_down(c: &mut T1Controller) {
        for _ in 0..MotionConfig::default().fallen_cycles {
            c.step(pitched(1.5));
        }
        assert_eq!(c.body_state(), BodyMotionState::Fallen { direction: FallDirection::Front });
    }

    fn stand_up(sequence: u8) -> ActuatorOrders {
        body(BodyOrder::Special { motion: SpecialMotion::stand_up(sequence) })
    }

    #[test]
    fn the_catalogue_lists_the_get_ups_it_has_with_their_durations() {
        let c = with_front_getup();
        let stand_ups = |c: &T1Controller| -> Vec<MotionSpec> {
            c.catalogue().into_iter().filter(|m| m.motion.is(MotionName::STAND_UP)).collect()
        };
        let catalogue = stand_ups(&c);
        assert_eq!(catalogue.len(), 1);
        assert_eq!(catalogue[0].motion, SpecialMotion::stand_up(0));
        assert_eq!(catalogue[0].duration, std::time::Duration::from_millis(500));
        assert!(stand_ups(&controller()).is_empty(), "no get-up without motions");
    }

    #[test]
    fn a_stand_up_runs_its_keyframes_and_ends_standing_when_upright() {
        let mut c = with_front_getup();
        lie_down(&mut c);
        // Ordered standing, or a side this body has no motion for, it stays on the ground.
        c.apply(&body(BodyOrder::Stand)).expect("ignored");
        assert!(matches!(c.apply(&stand_up(1)), Err(PlatformError::Unsupported(_))));
        assert!(matches!(c.body_state(), BodyMotionState::Fallen { .. }));

        c.apply(&stand_up(0)).expect("taken");
        let knee = FIRST_LEG + 3;
        let kp = c.policy.config().default_targets()[knee].kp;
        let first = c.step(pitched(1.5));
        assert_eq!(first[knee].kp, 2.0 * kp, "the keyframe's gain");
        let mut last = first;
        for _ in 0..10 {
            last = c.step(pitched(1.0));
        }
        assert!((last[knee].q - 2.0).abs() < 0.1, "near the first keyframe: {}", last[knee].q);
        match c.body_state() {
            BodyMotionState::Special { motion, elapsed, duration } => {
                assert_eq!(motion, SpecialMotion::stand_up(0));
                assert!((elapsed - 0.22).abs() < 1e-9 && duration == 0.5, "{elapsed} {duration}");
            }
            other => panic!("getting up expected, got {other:?}"),
        }
        // Tilted on purpose while getting up: neither a fall nor a new order interrupts it.
        c.apply(&body(BodyOrder::Special { motion: SpecialMotion::fall(0) })).expect("ignored");
        c.apply(&body(BodyOrder::Walk { velocity: Velocity::new(0.3, 0.0, 0.0) })).expect("ok");
        c.apply(&stand_up(0)).expect("already getting up");
        for _ in 0..14 {
            c.step(pitched(0.2));
        }
        assert!(matches!(c.body_state(), BodyMotionState::Special { .. }));
        c.step(pitched(0.2));
        assert_eq!(c.body_state(), BodyMotionState::Standing, "upright at the end");
        // The walking policy has the legs again.
        let next = c.step(upright());
        assert_eq!(next[knee].kp, kp);
    }

    #[test]
    fn a_stand_up_that_ends_tilted_is_still_fallen_and_may_try_again() {
        let mut c = with_front_getup();
        lie_down(&mut c);
        c.apply(&stand_up(0)).expect("taken");
        for _ in 0..26 {
            c.step(pitched(1.2));
        }
        assert_eq!(c.body_state(), BodyMotionState::Fallen { direction: FallDirection::Front });
        c.apply(&stand_up(0)).expect("a second try");
        c.step(pitched(1.2));
        assert!(
            matches!(c.body_state(), BodyMotionState::Special { elapsed, .. } if elapsed > 0.0)
        );
    }

    #[test]
    fn a_robot_lying_reports_the_side_it_lies_on_now() {
        let mut c = with_front_getup();
        lie_down(&mut c);
        // Rolled over, or laid down again on its back: the back's get-up is the one to order.
        c.step(pitched(-1.5));
        assert_eq!(c.body_state(), BodyMotionState::Fallen { direction: FallDirection::Back });
    }

    #[test]
    fn a_stand_up_while_on_its_feet_is_refused() {
        let mut c = with_front_getup();
        assert!(matches!(c.apply(&stand_up(0)), Err(PlatformError::Unsupported(_))));
        c.step(upright());
        assert_eq!(c.body_state(), BodyMotionState::Standing);
    }

    #[test]
    fn the_head_moves_at_its_speed_limit_and_settles() {
        let mut c = controller();
        let order = HeadOrder { target: HeadAngles { yaw: 1.0, pitch: 0.3 }, max_speed: 2.0 };
        c.apply(&ActuatorOrders { head: Some(order), body: None }).expect("taken");
        let first = c.step(upright());
        let moved = first[HEAD_YAW].q.hypot(first[HEAD_PITCH].q);
        assert!((moved - 2.0 * CYCLE).abs() < 1e-9, "moved {moved}");
        assert!(!c.head_settled());
        let mut at_target = upright();
        at_target.joint_positions[HEAD_YAW] = 1.0;
        at_target.joint_positions[HEAD_PITCH] = 0.3;
        c.step(at_target);
        assert!(c.head_settled());
        // Beyond the neck's range the order is clamped.
        let far = HeadOrder { target: HeadAngles { yaw: 3.0, pitch: -1.0 }, max_speed: 100.0 };
        c.apply(&ActuatorOrders { head: Some(far), body: None }).expect("taken");
        let mut last = c.step(upright());
        for _ in 0..50 {
            last = c.step(upright());
        }
        assert_eq!(
            (last[HEAD_YAW].q, last[HEAD_PITCH].q),
            (HEAD_YAW_LIMITS.1, HEAD_PITCH_LIMITS.0)
        );
    }

    #[test]
    fn odometry_turns_with_the_imu_and_moves_with_the_command() {
        let mut c = controller();
        c.apply(&body(BodyOrder::Walk { velocity: Velocity::new(0.5, 0.0, 0.0) })).expect("ok");
        for _ in 0..100 {
            c.step(upright());
        }
        let odometry = c.take_odometry();
        assert!(odometry.dx > 0.0 && odometry.dtheta.abs() < 1e-12, "{odometry:?}");
        assert_eq!(c.take_odometry(), Odometry::ZERO);
        let yawed = MeasuredBody {
            orientation: Quaternion { w: (0.05f64).cos(), x: 0.0, y: 0.0, z: (0.05f64).sin() },
            ..upright()
        };
        c.step(yawed);
        assert!((c.take_odometry().dtheta - 0.1).abs() < 1e-9);
        // Placed facing elsewhere by the server: no turn.
        let placed = MeasuredBody {
            orientation: Quaternion { w: (1.0f64).cos(), x: 0.0, y: 0.0, z: (1.0f64).sin() },
            ..upright()
        };
        c.step(placed);
        assert!(c.take_odometry().dtheta.abs() < 1e-12);
    }

    fn yawed(yaw: f64) -> MeasuredBody {
        MeasuredBody {
            orientation: Quaternion { w: (yaw / 2.0).cos(), x: 0.0, y: 0.0, z: (yaw / 2.0).sin() },
            ..upright()
        }
    }

    #[test]
    fn a_heading_jump_is_reported_as_a_placement_and_a_turn_is_not() {
        let mut c = controller();
        c.apply(&body(BodyOrder::Walk { velocity: Velocity::new(0.3, 0.0, 1.0) })).expect("ok");
        // Turning at the policy's fastest, 1 rad/s, and four times that: a turn, whole.
        let mut yaw = 0.0;
        for _ in 0..100 {
            yaw += 4.0 * CYCLE;
            c.step(yawed(yaw));
            assert!(!c.take_placement(), "a turn at 4 rad/s is no placement");
        }
        // The first cycle, without a previous heading, counts the commanded turn (< 0.02).
        let turned = c.take_odometry().dtheta;
        assert!(normalize(turned - 4.0 * CYCLE * 99.0).abs() < 0.021, "turned {turned}");
        // The referee's move: facing into the field (the robot faced along the line).
        c.step(yawed(yaw + std::f64::consts::FRAC_PI_2));
        assert!(c.take_placement(), "a quarter turn in one cycle is a placement");
        assert!(!c.take_placement(), "reported once");
        let turned = c.take_odometry().dtheta;
        assert!(turned.abs() <= 1.0 * CYCLE + 1e-12, "not a turn: the commanded one, {turned}");
    }

    fn normalize(angle: f64) -> f64 {
        strata_robot::geometry::normalize_angle(angle)
    }

    #[test]
    fn a_fall_and_a_stand_up_that_turn_the_robot_turn_its_odometry() {
        // Lying on its back long enough to be fallen, then upright again: turned by the
        // stand-up rolling it over, or put at the side line by the referee.
        let fall_and_rise = |rise: &[MeasuredBody]| {
            let mut c = controller();
            for _ in 0..10 {
                c.step(yawed(0.0));
            }
            c.take_odometry();
            for _ in 0..20 {
                c.step(pitched(-1.5));
            }
            assert!(matches!(c.body_state(), BodyMotionState::Fallen { .. }));
            c.take_placement();
            for body in rise {
                c.step(body.clone());
            }
            for _ in 0..MotionConfig::default().upright_cycles + 2 {
                c.step(rise.last().cloned().unwrap_or_else(upright));
            }
            assert_eq!(c.body_state(), BodyMotionState::Standing);
            (c.take_odometry().dtheta, c.take_placement())
        };
        // Rolled over: sitting up from the back and turning, a little every cycle.
        let posed = |yaw: f64, pitch: f64| {
            let (sy, cy) = (yaw / 2.0).sin_cos();
            let (sp, cp) = (pitch / 2.0).sin_cos();
            MeasuredBody {
                orientation: Quaternion { w: cy * cp, x: -sy * sp, y: cy * sp, z: sy * cp },
                ..upright()
            }
        };
        let rolling: Vec<MeasuredBody> = (0..=30)
            .map(|i| f64::from(i) / 30.0)
            .map(|t| posed(2.8 * t, -1.5 * (1.0 - t)))
            .collect();
        let (turned, placed) = fall_and_rise(&rolling);
        assert!(!placed);
        assert!(normalize(turned - 2.8).abs() < 1e-9, "turned {turned}");
        // The referee's move: a jump, reported as a placement and no turn.
        let (turned, placed) = fall_and_rise(&[yawed(std::f64::consts::FRAC_PI_2)]);
        assert!(placed);
        assert!(turned.abs() < 0.05, "a placement is no turn: {turned}");
    }

    #[test]
    fn a_lying_robot_put_upright_is_placed_and_a_fall_is_not() {
        let mut c = controller();
        c.step(upright());
        // Falling forward at 6 rad/s, then lying.
        let mut angle = 0.0;
        while angle < 1.5 {
            angle += 6.0 * CYCLE;
            c.step(pitched(angle));
            assert!(!c.take_placement(), "a fall at {angle:.2} rad is no placement");
        }
        for _ in 0..50 {
            c.step(pitched(1.5));
        }
        assert!(matches!(c.body_state(), BodyMotionState::Fallen { .. }));
        assert!(!c.take_placement());
        // Down too long: the server's referee puts it at the side line, upright.
        c.step(yawed(std::f64::consts::FRAC_PI_2));
        assert!(c.take_placement());
    }

    #[test]
    fn the_platforms_own_beam_is_not_reported_and_later_moves_are() {
        let mut c = controller();
        // Spawned at the side line facing into the field, then beamed facing along x: the
        // beam's perception arrives a cycle after the beam order.
        c.step(yawed(-std::f64::consts::FRAC_PI_2));
        c.restart();
        c.step(yawed(-std::f64::consts::FRAC_PI_2));
        c.step(yawed(0.0));
        assert!(!c.take_placement(), "the robot knows where it beamed itself");
        c.step(yawed(0.0));
        c.step(yawed(2.0));
        assert!(c.take_placement(), "a move after the beam is the referee's");
        // A beam that keeps the heading shows nothing; a move well after it is reported.
        c.restart();
        for _ in 0..=OWN_BEAM_CYCLES {
            c.step(yawed(2.0));
        }
        c.step(yawed(0.5));
        assert!(c.take_placement(), "the beam's window is over");
    }
}
