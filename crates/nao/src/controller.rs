//! What happens in one LoLA cycle, without sockets or threads: orders in, one actuator packet
//! out per sensor packet. The platform runs this on its LoLA thread; tests run it directly.
//!
//! Body modes: limp (motors off, the state at start), playing a key-frame sequence (stand, sit,
//! a special motion), holding the last pose of a sequence, walking (a gait engine drives the
//! legs). Head orders are interpolated towards their target at their speed limit every 12 ms,
//! unless a sequence that names the head joints is playing.

use serde::{Deserialize, Serialize};
use strata_robot::geometry::{Odometry, Velocity};
use strata_robot::platform::{
    ActuatorOrders, BodyMotionState, BodyOrder, CycleStage, FallDirection, HeadAngles, HeadOrder,
    MotionName, MotionSpec, PlatformError, SpecialMotion,
};

use crate::codec::{ActuatorPacket, Leds, SensorPacket};
use crate::gait::{GaitEngine, GaitStep};
use crate::joints::{JOINT_COUNT, Joint, JointArray, head_pitch_limits};
use crate::keyframe::{MotionLibrary, Player, SIT, STAND};

/// The stand-up numbering is the architecture's (`strata_robot::control::primitives::StandUp`,
/// the simulator's catalogue): 0 from the front or a side, 1 from the back. 0 plays the front or
/// the back sequence by the torso pitch (the NAO has no side stand-up: a robot on its side rolls
/// onto the side its pitch leans to); 2 is the front sequence itself.
const STAND_UP_BACK: u8 = 1;
const STAND_UP_FRONT: u8 = 2;

/// LoLA's cycle, s: every sensor packet advances motions by this much.
pub const CYCLE: f64 = 0.012;

/// Tuning of the platform's own motion control.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MotionConfig {
    /// Stiffness of the head joints while they follow head orders (0..1).
    pub head_stiffness: f64,
    /// Upper bound on any head order's speed, rad/s.
    pub max_head_speed: f64,
    /// Head orders count as reached when the encoders are this close to the target, rad.
    pub head_settled_tolerance: f64,
    /// Torso roll or pitch beyond this means lying on the ground, rad.
    pub fallen_angle: f64,
    /// Consecutive cycles beyond `fallen_angle` before the robot counts as fallen (a stumble
    /// is not a fall).
    pub fallen_cycles: u32,
    /// A body whose every joint is commanded below this stiffness is reported limp.
    pub limp_stiffness: f64,
    /// Whether the sonar emitters are on.
    pub sonar: bool,
}

impl Default for MotionConfig {
    fn default() -> Self {
        MotionConfig {
            head_stiffness: 0.7,
            max_head_speed: 5.0,
            head_settled_tolerance: 0.05,
            fallen_angle: 0.9,
            fallen_cycles: 5,
            limp_stiffness: 0.05,
            sonar: true,
        }
    }
}

/// Why a sequence is playing, and so how it is reported.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Purpose {
    Stand,
    Sit,
    Special(SpecialMotion),
}

#[derive(Clone, Debug)]
enum BodyMode {
    Limp,
    Playing { purpose: Purpose, player: Box<Player> },
    Holding { purpose: Purpose },
    Walking,
}

/// The platform's motion control for one robot.
#[derive(Debug)]
pub struct MotionController {
    config: MotionConfig,
    library: MotionLibrary,
    gait: Box<dyn GaitEngine>,
    body: BodyMode,
    head_order: Option<HeadOrder>,
    /// The interpolated head command; `None` restarts interpolation from the encoders.
    head_command: Option<HeadAngles>,
    targets: JointArray<f64>,
    stiffness: JointArray<f64>,
    measured: Option<JointArray<f64>>,
    angles: [f64; 2],
    lying_cycles: u32,
    leds: Leds,
    gait_step: Option<GaitStep>,
    odometry: Odometry,
}

impl MotionController {
    pub fn new(config: MotionConfig, library: MotionLibrary, gait: Box<dyn GaitEngine>) -> Self {
        MotionController {
            config,
            library,
            gait,
            body: BodyMode::Limp,
            head_order: None,
            head_command: None,
            targets: [0.0; JOINT_COUNT],
            stiffness: [0.0; JOINT_COUNT],
            measured: None,
            angles: [0.0; 2],
            lying_cycles: 0,
            leds: Leds::default(),
            gait_step: None,
            odometry: Odometry::ZERO,
        }
    }

    pub fn config(&self) -> &MotionConfig {
        &self.config
    }

    pub fn gait(&self) -> &dyn GaitEngine {
        self.gait.as_ref()
    }

    pub fn library(&self) -> &MotionLibrary {
        &self.library
    }

    /// The special motions this robot can play: every tagged sequence, plus stand-up 0
    /// (front or back chosen by how the robot lies) when both stand-ups exist.
    pub fn catalogue(&self) -> Vec<MotionSpec> {
        let mut specs = self.library.catalogue();
        let front = self.library.for_motion(SpecialMotion::stand_up(STAND_UP_FRONT));
        let back = self.library.for_motion(SpecialMotion::stand_up(STAND_UP_BACK));
        if let (Some(front), Some(back), None) =
            (front, back, self.library.for_motion(SpecialMotion::stand_up(0)))
        {
            specs.insert(
                0,
                MotionSpec {
                    motion: SpecialMotion::stand_up(0),
                    name: "stand_up (front or back, by how the robot lies)".to_owned(),
                    duration: std::time::Duration::from_secs_f64(
                        front.duration().max(back.duration()),
                    ),
                },
            );
        }
        specs
    }

    pub fn set_leds(&mut self, leds: Leds) {
        self.leds = leds;
    }

    /// Applies every part of `orders` it can; an unsupported body order is reported after the
    /// head order was taken, so a NAO asked to walk still moves its head.
    pub fn apply(&mut self, orders: &ActuatorOrders) -> Result<(), PlatformError> {
        if let Some(head) = orders.head {
            if !(head.target.yaw.is_finite() && head.target.pitch.is_finite()) {
                return Err(PlatformError::Unsupported(format!(
                    "head orders with non-finite targets ({:?})",
                    head.target
                )));
            }
            self.head_order = Some(head);
        }
        match orders.body {
            None => Ok(()),
            Some(BodyOrder::Stand) => {
                self.stand();
                Ok(())
            }
            Some(BodyOrder::Walk { velocity }) => self.walk(velocity),
            Some(BodyOrder::Special { motion }) => self.start_special(motion),
        }
    }

    fn stand(&mut self) {
        match &self.body {
            BodyMode::Walking => self.gait.stop(),
            BodyMode::Playing { purpose: Purpose::Special(_), .. } => {
                tracing::debug!("stand order ignored while a special motion plays");
            }
            BodyMode::Playing { purpose: Purpose::Stand, .. }
            | BodyMode::Holding { purpose: Purpose::Stand }
            | BodyMode::Holding {
                purpose: Purpose::Special(SpecialMotion { kind: MotionName::STAND_UP, .. }),
            } => {}
            _ => self.play(Purpose::Stand, STAND),
        }
    }

    fn walk(&mut self, velocity: Velocity) -> Result<(), PlatformError> {
        if !velocity.is_finite() {
            return Err(PlatformError::Unsupported(format!(
                "walking at a non-finite velocity ({velocity:?})"
            )));
        }
        if matches!(self.body, BodyMode::Playing { purpose: Purpose::Special(_), .. }) {
            tracing::debug!("walk order ignored while a special motion plays");
            return Ok(());
        }
        self.gait.walk(velocity).map_err(|e| PlatformError::Unsupported(e.to_string()))?;
        self.body = BodyMode::Walking;
        Ok(())
    }

    fn start_special(&mut self, motion: SpecialMotion) -> Result<(), PlatformError> {
        if let BodyMode::Playing { purpose: Purpose::Special(current), .. } = self.body {
            // Actuation repeats the order until it sees the motion running; a protective fall
            // is the only thing that interrupts another special motion.
            if current == motion || !motion.is(MotionName::FALL) {
                return Ok(());
            }
        }
        let name = match self.library.for_motion(motion) {
            Some(sequence) => sequence.name.clone(),
            None if motion.same_sequence(&SpecialMotion::stand_up(0)) => self.auto_stand_up()?,
            None => return Err(PlatformError::Unsupported(self.missing(motion))),
        };
        if matches!(self.body, BodyMode::Walking) {
            self.gait.abort();
        }
        self.play(Purpose::Special(motion), &name);
        Ok(())
    }

    /// Stand-up 0: the front or back stand-up by the sign of the torso pitch, or the stand
    /// posture when the robot is not lying at all.
    fn auto_stand_up(&self) -> Result<String, PlatformError> {
        let [roll, pitch] = self.angles;
        let lying = pitch.abs() > self.config.fallen_angle || roll.abs() > self.config.fallen_angle;
        let motion = match (lying, pitch >= 0.0) {
            (false, _) => return Ok(STAND.to_owned()),
            (true, true) => SpecialMotion::stand_up(STAND_UP_FRONT),
            (true, false) => SpecialMotion::stand_up(STAND_UP_BACK),
        };
        self.library
            .for_motion(motion)
            .map(|s| s.name.clone())
            .ok_or_else(|| PlatformError::Unsupported(self.missing(motion)))
    }

    /// Why `motion` cannot be played: the built-in library has stand-ups and a protective fall;
    /// anything else (a kick needs balance control) is a motion file the team adds.
    fn missing(&self, motion: SpecialMotion) -> String {
        let available: Vec<String> =
            self.catalogue().iter().map(|s| s.motion.to_string()).collect();
        let SpecialMotion { kind, sequence, .. } = motion;
        format!(
            "{kind} {sequence}: not in the NAO motion library (add a sequence tagged \
             motion = {{ kind = \"{kind}\", sequence = {sequence} }}); available: {}",
            available.join(", ")
        )
    }

    /// Sits down and goes limp (shutdown, long pauses). Interrupts anything, walking included.
    pub fn sit_down(&mut self) -> f64 {
        if matches!(self.body, BodyMode::Walking) {
            self.gait.abort();
        }
        self.play(Purpose::Sit, SIT);
        self.library.get(SIT).map_or(0.0, |s| s.duration())
    }

    /// Switches every motor off at once.
    pub fn relax(&mut self) {
        if matches!(self.body, BodyMode::Walking) {
            self.gait.abort();
        }
        self.body = BodyMode::Limp;
        self.head_order = None;
        self.head_command = None;
    }

    /// Whether a sequence or the gait is still moving the body.
    pub fn busy(&self) -> bool {
        matches!(self.body, BodyMode::Playing { .. } | BodyMode::Walking)
    }

    fn play(&mut self, purpose: Purpose, name: &str) {
        let Some(sequence) = self.library.get(name).cloned() else {
            // The library checks for its required sequences when it is built.
            tracing::error!(name, "key-frame sequence missing from the motion library");
            return;
        };
        let start = self.start_pose();
        self.body = BodyMode::Playing { purpose, player: Box::new(Player::new(sequence, start)) };
    }

    /// Where a new sequence starts: the held target of every stiff joint, the measured angle of
    /// every limp one (interpolating from a target the joint never reached would jerk it).
    fn start_pose(&self) -> JointArray<f64> {
        let mut pose = self.targets;
        if let Some(measured) = &self.measured {
            for j in 0..JOINT_COUNT {
                if self.stiffness[j] < self.config.limp_stiffness {
                    pose[j] = measured[j];
                }
            }
        }
        pose
    }

    /// One LoLA cycle: reads the sensor packet and returns the actuator packet to send.
    pub fn step(&mut self, sensors: &SensorPacket) -> ActuatorPacket {
        let measured: JointArray<f64> = sensors.position.map(f64::from);
        let measured_valid = measured.iter().all(|v| v.is_finite());
        if measured_valid {
            self.measured = Some(measured);
        }
        let angles = [f64::from(sensors.angles[0]), f64::from(sensors.angles[1])];
        if angles.iter().all(|a| a.is_finite()) {
            self.angles = angles;
            let lying = angles.iter().any(|a| a.abs() > self.config.fallen_angle);
            self.lying_cycles = if lying { self.lying_cycles.saturating_add(1) } else { 0 };
        }

        self.step_body(sensors);
        self.step_head();

        // Limp joints follow the encoders so that stiffening them later starts where they are.
        let measured = self.measured.unwrap_or(self.targets);
        let mut position = [0.0f32; JOINT_COUNT];
        let mut stiffness = [0.0f32; JOINT_COUNT];
        for joint in Joint::ALL {
            let j = joint.index();
            if !(self.targets[j].is_finite() && self.stiffness[j].is_finite()) {
                self.targets[j] = measured[j];
                self.stiffness[j] = 0.0;
            }
            if self.stiffness[j] < self.config.limp_stiffness {
                self.targets[j] = measured[j];
            }
            let limits = if joint == Joint::HeadPitch {
                head_pitch_limits(self.targets[Joint::HeadYaw.index()])
            } else {
                joint.limits()
            };
            self.targets[j] = limits.clamp(self.targets[j]);
            position[j] = self.targets[j] as f32;
            stiffness[j] = self.stiffness[j] as f32;
        }
        ActuatorPacket::new(position, stiffness, &self.leds, self.config.sonar)
    }

    fn step_body(&mut self, sensors: &SensorPacket) {
        match &mut self.body {
            BodyMode::Limp => {
                for joint in Joint::ALL.into_iter().filter(|j| !j.is_head()) {
                    self.stiffness[joint.index()] = 0.0;
                }
            }
            BodyMode::Playing { purpose, player } => {
                let purpose = *purpose;
                let output = player.advance(CYCLE);
                let drives_head = drives_head(purpose, player);
                for joint in Joint::ALL {
                    if player.sequence().moves(joint) && (drives_head || !joint.is_head()) {
                        self.targets[joint.index()] = output.targets[joint.index()];
                        self.stiffness[joint.index()] = output.stiffness[joint.index()];
                    }
                }
                if output.finished {
                    if drives_head {
                        // Head orders resume from where the sequence left the head.
                        self.head_command = None;
                    }
                    self.body = BodyMode::Holding { purpose };
                }
            }
            BodyMode::Holding { .. } => {}
            BodyMode::Walking => {
                let step = self.gait.step(CYCLE, sensors, &mut self.targets, &mut self.stiffness);
                self.odometry = self.odometry.then(step.odometry);
                self.gait_step = Some(step);
                if !self.gait.is_active() {
                    self.gait_step = None;
                    self.play(Purpose::Stand, STAND);
                }
            }
        }
    }

    fn head_driven_by_sequence(&self) -> bool {
        match &self.body {
            BodyMode::Playing { purpose, player } => drives_head(*purpose, player),
            _ => false,
        }
    }

    fn step_head(&mut self) {
        if self.head_driven_by_sequence() {
            return;
        }
        let (yaw, pitch) = (Joint::HeadYaw.index(), Joint::HeadPitch.index());
        let Some(order) = self.head_order else {
            self.stiffness[yaw] = 0.0;
            self.stiffness[pitch] = 0.0;
            return;
        };
        let encoders = self.measured.map(|m| HeadAngles { yaw: m[yaw], pitch: m[pitch] });
        let current = self.head_command.or(encoders).unwrap_or_default();
        let target = clamp_head(order.target);
        let speed = if order.max_speed.is_finite() && order.max_speed > 0.0 {
            order.max_speed.min(self.config.max_head_speed)
        } else {
            self.config.max_head_speed
        };
        let (dy, dp) = (target.yaw - current.yaw, target.pitch - current.pitch);
        let distance = dy.hypot(dp);
        let reach = speed * CYCLE;
        // Both joints move along the straight line to the target, so they arrive together.
        let next = if distance <= reach {
            target
        } else {
            HeadAngles {
                yaw: current.yaw + dy * reach / distance,
                pitch: current.pitch + dp * reach / distance,
            }
        };
        self.head_command = Some(next);
        self.targets[yaw] = next.yaw;
        self.targets[pitch] = next.pitch;
        self.stiffness[yaw] = self.config.head_stiffness;
        self.stiffness[pitch] = self.config.head_stiffness;
    }

    /// Head angles from the encoders.
    pub fn head(&self) -> HeadAngles {
        self.measured
            .map(|m| HeadAngles {
                yaw: m[Joint::HeadYaw.index()],
                pitch: m[Joint::HeadPitch.index()],
            })
            .unwrap_or_default()
    }

    /// Whether the head reached its last ordered target (clamped to the joint limits): the
    /// interpolation is done and the encoders agree.
    pub fn head_settled(&self) -> bool {
        let Some(order) = self.head_order else { return true };
        let target = clamp_head(order.target);
        let done = self.head_command.is_some_and(|c| c == target);
        let head = self.head();
        let error = (head.yaw - target.yaw).abs().max((head.pitch - target.pitch).abs());
        done && error <= self.config.head_settled_tolerance
    }

    fn fallen(&self) -> Option<FallDirection> {
        if self.lying_cycles < self.config.fallen_cycles.max(1) {
            return None;
        }
        let [roll, pitch] = self.angles;
        Some(if pitch.abs() >= roll.abs() {
            if pitch > 0.0 { FallDirection::Front } else { FallDirection::Back }
        } else if roll > 0.0 {
            FallDirection::Right
        } else {
            FallDirection::Left
        })
    }

    /// What the body is doing: a special motion in progress, else lying, else limp, walking
    /// or standing.
    pub fn body_state(&self) -> BodyMotionState {
        if let BodyMode::Playing { purpose: Purpose::Special(motion), player } = &self.body {
            return BodyMotionState::Special {
                motion: *motion,
                elapsed: player.elapsed(),
                duration: player.duration(),
            };
        }
        if let Some(direction) = self.fallen() {
            return BodyMotionState::Fallen { direction };
        }
        let body_stiff = Joint::ALL
            .into_iter()
            .filter(|j| !j.is_head())
            .any(|j| self.stiffness[j.index()] >= self.config.limp_stiffness);
        match &self.body {
            BodyMode::Limp | BodyMode::Playing { purpose: Purpose::Sit, .. } => {
                BodyMotionState::Limp
            }
            BodyMode::Walking => {
                let step = self.gait_step;
                BodyMotionState::Walking {
                    stage: step.and_then(|s| s.stage).unwrap_or(CycleStage::Initialization),
                    velocity: step.map_or(Velocity::ZERO, |s| s.velocity),
                }
            }
            _ if !body_stiff => BodyMotionState::Limp,
            _ => BodyMotionState::Standing,
        }
    }

    /// Odometry accumulated since the last call (zero without a gait engine).
    pub fn take_odometry(&mut self) -> Odometry {
        std::mem::replace(&mut self.odometry, Odometry::ZERO)
    }

    /// The commands of the last cycle again, without advancing anything (the answer to a
    /// garbled sensor packet).
    pub fn hold(&self) -> ActuatorPacket {
        ActuatorPacket::new(
            self.targets.map(|t| t as f32),
            self.stiffness.map(|s| s as f32),
            &self.leds,
            self.config.sonar,
        )
    }

    /// The targets and stiffnesses of the last cycle, LoLA order.
    pub fn commanded(&self) -> (&JointArray<f64>, &JointArray<f64>) {
        (&self.targets, &self.stiffness)
    }
}

/// A sequence drives the head if it names the head joints, except a motion ordered for the
/// body only (a kick: the head stays with head orders, paper 3.5.1).
fn drives_head(purpose: Purpose, player: &Player) -> bool {
    let names_head =
        player.sequence().moves(Joint::HeadYaw) || player.sequence().moves(Joint::HeadPitch);
    names_head && !matches!(purpose, Purpose::Special(motion) if !motion.head)
}

/// Keeps a head target within the yaw range and the yaw-dependent pitch range.
fn clamp_head(target: HeadAngles) -> HeadAngles {
    let yaw = Joint::HeadYaw.limits().clamp(target.yaw);
    HeadAngles { yaw, pitch: head_pitch_limits(yaw).clamp(target.pitch) }
}

#[cfg(test)]
// A panic is how a test reports failure.
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::codec::tests::standing_packet;
    use crate::gait::NoGait;

    fn controller() -> MotionController {
        MotionController::new(
            MotionConfig::default(),
            MotionLibrary::builtin().unwrap(),
            Box::new(NoGait),
        )
    }

    fn run(c: &mut MotionController, packet: &SensorPacket, cycles: usize) -> ActuatorPacket {
        let mut out = c.step(packet);
        for _ in 1..cycles {
            out = c.step(packet);
        }
        out
    }

    #[test]
    fn starts_limp_following_the_encoders() {
        let mut c = controller();
        let packet = standing_packet();
        let out = c.step(&packet);
        assert_eq!(out.stiffness, [0.0; JOINT_COUNT]);
        assert_eq!(out.position, packet.position);
        assert_eq!(c.body_state(), BodyMotionState::Limp);
        assert!(c.head_settled());
    }

    #[test]
    fn head_moves_at_its_speed_limit_and_settles() {
        let mut c = controller();
        let mut packet = standing_packet();
        let order = HeadOrder { target: HeadAngles { yaw: 0.6, pitch: 0.0 }, max_speed: 1.0 };
        c.apply(&ActuatorOrders { head: Some(order), body: None }).unwrap();
        let out = c.step(&packet);
        let yaw = Joint::HeadYaw.index();
        assert!((f64::from(out.position[yaw]) - 0.012).abs() < 1e-6);
        assert_eq!(out.stiffness[yaw], 0.7);
        assert!(!c.head_settled());
        // 0.6 rad at 1 rad/s: 50 cycles.
        let out = run(&mut c, &packet, 49);
        assert!((f64::from(out.position[yaw]) - 0.6).abs() < 1e-6);
        assert!(!c.head_settled(), "the encoders have not followed yet");
        packet.position[yaw] = 0.59;
        c.step(&packet);
        assert!(c.head_settled());
        assert!((c.head().yaw - 0.59).abs() < 1e-6);
    }

    #[test]
    fn head_targets_are_clamped_to_the_shoulder_safe_range() {
        let mut c = controller();
        let order = HeadOrder { target: HeadAngles { yaw: 3.0, pitch: 0.5 }, max_speed: 100.0 };
        c.apply(&ActuatorOrders { head: Some(order), body: None }).unwrap();
        let out = run(&mut c, &standing_packet(), 200);
        let yaw = f64::from(out.position[Joint::HeadYaw.index()]);
        let pitch = f64::from(out.position[Joint::HeadPitch.index()]);
        assert!((yaw - Joint::HeadYaw.limits().max).abs() < 1e-6);
        assert!(pitch <= head_pitch_limits(yaw).max + 1e-6);
        let bad = HeadOrder { target: HeadAngles { yaw: f64::NAN, pitch: 0.0 }, max_speed: 1.0 };
        assert!(c.apply(&ActuatorOrders { head: Some(bad), body: None }).is_err());
    }

    #[test]
    fn walking_is_unsupported_but_the_head_order_still_applies() {
        let mut c = controller();
        let head = HeadOrder { target: HeadAngles { yaw: 0.3, pitch: 0.0 }, max_speed: 2.0 };
        let walk = BodyOrder::Walk { velocity: Velocity::new(0.2, 0.0, 0.0) };
        let error = c.apply(&ActuatorOrders { head: Some(head), body: Some(walk) }).unwrap_err();
        let PlatformError::Unsupported(reason) = &error else { panic!("{error}") };
        assert!(reason.starts_with("walking: no gait engine"), "{reason}");
        assert!(error.to_string().starts_with("the platform does not support walking"));
        let out = c.step(&standing_packet());
        assert!(out.position[Joint::HeadYaw.index()] > 0.0);
        assert_eq!(c.body_state(), BodyMotionState::Limp);
    }

    #[test]
    fn kicks_and_dives_are_unsupported() {
        let mut c = controller();
        let named = |kind: &str, sequence, head| {
            SpecialMotion::new(MotionName::new(kind).unwrap(), sequence, head)
        };
        let (kick, dive) = (named("kick", 0, false), named("dive", 1, true));
        for motion in [kick, dive, SpecialMotion::stand_up(7)] {
            let orders = ActuatorOrders { head: None, body: Some(BodyOrder::Special { motion }) };
            let Err(PlatformError::Unsupported(reason)) = c.apply(&orders) else { panic!() };
            assert!(reason.starts_with(&format!("{motion}: not in the NAO motion library")));
            assert!(reason.contains("available: stand_up 0, "), "{reason}");
        }
        assert!(c.catalogue().iter().all(|s| !s.motion.is(kick.kind)));
    }

    #[test]
    fn stand_plays_the_stand_sequence_then_holds_it() {
        let mut c = controller();
        let packet = standing_packet();
        c.step(&packet);
        c.apply(&ActuatorOrders { head: None, body: Some(BodyOrder::Stand) }).unwrap();
        assert!(c.busy());
        let out = c.step(&packet);
        assert_eq!(out.stiffness[Joint::LKneePitch.index()], 0.7);
        assert_eq!(out.stiffness[Joint::HeadYaw.index()], 0.0, "the head is not the stand's");
        assert_eq!(c.body_state(), BodyMotionState::Standing);
        let out = run(&mut c, &packet, 120);
        assert!(!c.busy());
        assert!(
            (f64::from(out.position[Joint::LKneePitch.index()]) - 46f64.to_radians()).abs() < 1e-6
        );
        // A second stand order while standing changes nothing.
        c.apply(&ActuatorOrders { head: None, body: Some(BodyOrder::Stand) }).unwrap();
        assert!(!c.busy());
    }

    #[test]
    fn lying_for_a_few_cycles_is_fallen_with_a_direction() {
        let mut c = controller();
        let mut packet = standing_packet();
        packet.angles = [0.1, -1.4];
        run(&mut c, &packet, 4);
        assert_eq!(c.body_state(), BodyMotionState::Limp, "not yet: a stumble is not a fall");
        c.step(&packet);
        assert_eq!(c.body_state(), BodyMotionState::Fallen { direction: FallDirection::Back });
        packet.angles = [-1.5, 0.2];
        run(&mut c, &packet, 5);
        assert_eq!(c.body_state(), BodyMotionState::Fallen { direction: FallDirection::Left });
    }

    #[test]
    fn stand_up_zero_picks_the_sequence_by_how_the_robot_lies() {
        for (pitch, expected) in [(1.4, "stand_up_front"), (-1.4, "stand_up_back")] {
            let mut c = controller();
            let mut packet = standing_packet();
            packet.angles = [0.0, pitch];
            run(&mut c, &packet, 6);
            let motion = SpecialMotion::stand_up(0);
            c.apply(&ActuatorOrders { head: None, body: Some(BodyOrder::Special { motion }) })
                .unwrap();
            let BodyMode::Playing { player, .. } = &c.body else { panic!() };
            assert_eq!(player.sequence().name, expected);
            c.step(&packet);
            let BodyMotionState::Special { motion: m, elapsed, duration } = c.body_state() else {
                panic!("{:?}", c.body_state())
            };
            assert_eq!(m, motion);
            assert!(elapsed > 0.0 && duration > 3.0);
            // Stand-ups name the head joints: head orders wait until the sequence ends.
            let head = HeadOrder { target: HeadAngles { yaw: 1.0, pitch: 0.0 }, max_speed: 5.0 };
            c.apply(&ActuatorOrders { head: Some(head), body: None }).unwrap();
            let out = c.step(&packet);
            assert!(out.position[Joint::HeadYaw.index()].abs() < 0.01);
            run(&mut c, &packet, 400);
            assert!(matches!(c.body_state(), BodyMotionState::Fallen { .. }), "still lying");
            packet.angles = [0.0, 0.0];
            let out = c.step(&packet);
            assert_eq!(c.body_state(), BodyMotionState::Standing);
            assert!(out.position[Joint::HeadYaw.index()] > 0.0, "head orders resume");
        }
    }

    #[test]
    fn the_architectures_stand_up_plays_the_sequence_for_how_the_robot_lies() {
        use strata_robot::control::primitives::StandUp;
        let cases = [
            (FallDirection::Back, [0.0, -1.4], "stand_up_back"),
            (FallDirection::Front, [0.0, 1.4], "stand_up_front"),
            (FallDirection::Left, [-1.5, 0.3], "stand_up_front"),
            (FallDirection::Right, [1.5, -0.3], "stand_up_back"),
        ];
        for (direction, angles, expected) in cases {
            let mut c = controller();
            let mut packet = standing_packet();
            packet.angles = angles;
            run(&mut c, &packet, 6);
            let motion = SpecialMotion::stand_up(StandUp::sequence_for(direction));
            c.apply(&ActuatorOrders { head: None, body: Some(BodyOrder::Special { motion }) })
                .unwrap();
            let BodyMode::Playing { player, .. } = &c.body else { panic!("{direction:?}") };
            assert_eq!(player.sequence().name, expected, "lying {direction:?}");
        }
    }

    #[test]
    fn a_protective_fall_preempts_a_stand_up() {
        let mut c = controller();
        let mut packet = standing_packet();
        packet.angles = [0.0, 1.4];
        run(&mut c, &packet, 6);
        let special =
            |motion| ActuatorOrders { head: None, body: Some(BodyOrder::Special { motion }) };
        c.apply(&special(SpecialMotion::stand_up(STAND_UP_FRONT))).unwrap();
        c.step(&packet);
        c.apply(&special(SpecialMotion::stand_up(STAND_UP_BACK))).unwrap();
        let front = SpecialMotion::stand_up(STAND_UP_FRONT);
        assert!(matches!(
            c.body_state(),
            BodyMotionState::Special { motion, .. } if motion == front
        ));
        c.apply(&special(SpecialMotion::fall(0))).unwrap();
        let out = c.step(&packet);
        assert!(matches!(
            c.body_state(),
            BodyMotionState::Special { motion, .. } if motion == SpecialMotion::fall(0)
        ));
        assert!(out.stiffness[Joint::LKneePitch.index()] <= 0.3);
        run(&mut c, &packet, 60);
        assert_eq!(c.body_state(), BodyMotionState::Fallen { direction: FallDirection::Front });
    }

    #[test]
    fn sitting_down_ends_limp() {
        let mut c = controller();
        let packet = standing_packet();
        c.apply(&ActuatorOrders { head: None, body: Some(BodyOrder::Stand) }).unwrap();
        run(&mut c, &packet, 150);
        assert_eq!(c.body_state(), BodyMotionState::Standing);
        let duration = c.sit_down();
        assert!(duration > 1.0);
        assert_eq!(c.body_state(), BodyMotionState::Limp);
        let out = run(&mut c, &packet, 200);
        assert!(!c.busy());
        assert_eq!(c.body_state(), BodyMotionState::Limp);
        assert!(out.stiffness.iter().all(|s| *s == 0.0));
        c.relax();
        assert_eq!(c.body_state(), BodyMotionState::Limp);
    }

    #[test]
    fn non_finite_sensor_values_never_reach_the_motors() {
        let mut c = controller();
        let mut packet = standing_packet();
        c.apply(&ActuatorOrders { head: None, body: Some(BodyOrder::Stand) }).unwrap();
        c.step(&packet);
        packet.position[3] = f32::NAN;
        packet.angles = [f32::INFINITY, 0.0];
        let out = run(&mut c, &packet, 10);
        assert!(out.position.iter().all(|p| p.is_finite()));
        assert!(out.stiffness.iter().all(|s| s.is_finite()));
        assert_eq!(c.take_odometry(), Odometry::ZERO);
    }
}
