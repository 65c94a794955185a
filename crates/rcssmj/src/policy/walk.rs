//! The walking controller around the network: command smoothing, gait phase, observation,
//! action clipping and joint targets, one call per policy step. Pure: no I/O and no clock (time
//! advances by one policy period per step).

use super::observation::{self, ObservationInputs};
use super::{
    ACTION_LEN, LEG_JOINTS, OBSERVATION_LEN, PolicyError, T1Config, UPPER_BODY_JOINTS, WalkNetwork,
};

/// The desired walk, in the torso's heading frame.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct WalkCommand {
    /// Forward velocity, m/s.
    pub vx: f64,
    /// Leftward velocity, m/s.
    pub vy: f64,
    /// Turning rate, rad/s, counter-clockwise seen from above.
    pub yaw_rate: f64,
}

impl WalkCommand {
    /// Stand in place.
    pub const STAND: Self = Self { vx: 0.0, vy: 0.0, yaw_rate: 0.0 };

    fn as_array(self) -> [f64; 3] {
        [self.vx, self.vy, self.yaw_rate]
    }

    fn from_array([vx, vy, yaw_rate]: [f64; 3]) -> Self {
        Self { vx, vy, yaw_rate }
    }
}

/// What the walking policy measures each step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LegState {
    /// Torso orientation in the world as a quaternion (w, x, y, z), z up.
    pub torso_orientation: [f64; 4],
    /// Torso angular velocity in the torso frame, rad/s (a gyroscope's reading).
    pub torso_angular_velocity: [f64; 3],
    /// Leg joint positions, rad, in [`LEG_JOINTS`](super::LEG_JOINTS) order.
    pub joint_positions: [f64; ACTION_LEN],
    /// Leg joint velocities, rad/s, in the same order.
    pub joint_velocities: [f64; ACTION_LEN],
}

/// A joint's position target and the PD gains to reach it:
/// torque = kp (q - q_measured) - kd dq_measured.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct JointTarget {
    /// rad
    pub q: f64,
    /// N m/rad
    pub kp: f64,
    /// N m s/rad
    pub kd: f64,
}

/// Booster's T1 walking policy as its deployment runs it.
#[derive(Debug, Clone)]
pub struct WalkPolicy {
    config: T1Config,
    network: WalkNetwork,
    /// Each leg joint's default position and gains, in policy order.
    legs: [JointTarget; ACTION_LEN],
    smoothed_command: [f64; 3],
    /// Gait phase in [0, 1). It advances by one period times the frequency per walking step
    /// and holds while standing, as in training; the deployment instead takes its clock time
    /// times the frequency, which is the same from a reset but jumps when a walk resumes.
    phase: f64,
    walking: bool,
    previous_action: [f32; ACTION_LEN],
    observation: [f32; OBSERVATION_LEN],
}

impl WalkPolicy {
    /// A policy with this configuration and network, standing, at gait phase zero.
    pub fn new(config: T1Config, network: WalkNetwork) -> Result<Self, PolicyError> {
        config.validate("the walk policy's configuration")?;
        let defaults = config.default_targets();
        Ok(Self {
            legs: LEG_JOINTS.map(|index| defaults[index]),
            config,
            network,
            smoothed_command: [0.0; 3],
            phase: 0.0,
            walking: false,
            previous_action: [0.0; ACTION_LEN],
            observation: [0.0; OBSERVATION_LEN],
        })
    }

    /// The shipped configuration and network.
    pub fn shipped() -> Result<Self, PolicyError> {
        Self::new(T1Config::shipped()?, WalkNetwork::shipped()?)
    }

    /// Forgets the smoothed command, the gait phase and the previous action, as when the
    /// deployment starts: call after a fall, a beam, or any pause in stepping.
    pub fn reset(&mut self) {
        self.smoothed_command = [0.0; 3];
        self.phase = 0.0;
        self.walking = false;
        self.previous_action = [0.0; ACTION_LEN];
        self.observation = [0.0; OBSERVATION_LEN];
    }

    /// Starts the next walk at gait phase zero, as after a reset, without forgetting the
    /// previous action: a motion that needs a known first step (a kick: the left leg swings
    /// first) calls it. Only while standing, so a gait in progress never jumps.
    pub fn restart_gait(&mut self) {
        if !self.walking && smoothed_norm(self.smoothed_command) == 0.0 {
            self.phase = 0.0;
        }
    }

    /// One policy step (every [`T1Config::policy_period`], 20 ms): the leg joint targets, in
    /// [`LEG_JOINTS`](super::LEG_JOINTS) order, that walk toward `command`.
    pub fn step(&mut self, state: &LegState, command: WalkCommand) -> [JointTarget; ACTION_LEN] {
        let step = self.config.control.command_smoothing_step;
        self.step_smoothed_by(state, command, step)
    }

    /// One policy step whose command moves toward `command` by at most `smoothing_step` per
    /// component (m/s, rad/s) instead of the deployment's: a motion that needs its walk sooner
    /// (a kick's burst) accepts a harder start.
    pub fn step_smoothed_by(
        &mut self,
        state: &LegState,
        command: WalkCommand,
        smoothing_step: f64,
    ) -> [JointTarget; ACTION_LEN] {
        self.smooth(command, smoothing_step);
        self.walking = smoothed_norm(self.smoothed_command)
            >= self.config.gait.standing_command_norm
            && self.config.gait.frequency > 0.0;

        let joint_offsets =
            std::array::from_fn(|leg| state.joint_positions[leg] - self.legs[leg].q);
        let inputs = ObservationInputs {
            gravity: observation::gravity_in_torso(state.torso_orientation),
            angular_velocity: state.torso_angular_velocity,
            command: self.walking.then_some(self.smoothed_command),
            phase: self.walking.then_some(self.phase),
            joint_offsets,
            joint_velocities: state.joint_velocities,
            previous_action: &self.previous_action,
        };
        self.observation = observation::build(&inputs, &self.config.observation_scales);

        let clip = self.config.action.clip as f32;
        // A non-finite output would otherwise come back every step as the previous action.
        self.previous_action = self
            .network
            .forward(&self.observation)
            .map(|a| if a.is_finite() { a.clamp(-clip, clip) } else { 0.0 });

        if self.walking {
            let advance = self.config.policy_period() * self.config.gait.frequency;
            self.phase = (self.phase + advance).rem_euclid(1.0);
        }

        let scale = self.config.action.scale;
        std::array::from_fn(|leg| JointTarget {
            q: self.legs[leg].q + scale * f64::from(self.previous_action[leg]),
            ..self.legs[leg]
        })
    }

    /// Moves each smoothed command component toward the desired one by at most the smoothing
    /// step, as the deployment does, so a sudden command never jolts the gait.
    fn smooth(&mut self, command: WalkCommand, step: f64) {
        let step = if step.is_finite() && step > 0.0 {
            step
        } else {
            self.config.control.command_smoothing_step
        };
        for (smoothed, desired) in self.smoothed_command.iter_mut().zip(command.as_array()) {
            if desired.is_finite() {
                *smoothed += (desired - *smoothed).clamp(-step, step);
            }
        }
    }

    /// The head, arm and waist joints held at their default pose with their deployment gains,
    /// in [`UPPER_BODY_JOINTS`] order.
    pub fn upper_body_targets(&self) -> [JointTarget; UPPER_BODY_JOINTS.len()] {
        let defaults = self.config.default_targets();
        UPPER_BODY_JOINTS.map(|index| defaults[index])
    }

    pub fn config(&self) -> &T1Config {
        &self.config
    }

    pub fn network(&self) -> &WalkNetwork {
        &self.network
    }

    /// The command the last step walked with, after smoothing.
    pub fn smoothed_command(&self) -> WalkCommand {
        WalkCommand::from_array(self.smoothed_command)
    }

    /// The gait phase in [0, 1) the next walking step will use.
    pub fn phase(&self) -> f64 {
        self.phase
    }

    /// Whether the last step walked (smoothed command not zero) or stood.
    pub fn is_walking(&self) -> bool {
        self.walking
    }

    /// The observation the last step fed the network.
    pub fn observation(&self) -> &[f32; OBSERVATION_LEN] {
        &self.observation
    }

    /// The last step's clipped action, fed back in the next observation.
    pub fn previous_action(&self) -> &[f32; ACTION_LEN] {
        &self.previous_action
    }
}

fn smoothed_norm(command: [f64; 3]) -> f64 {
    command.iter().map(|c| c * c).sum::<f64>().sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::policy::{OBS_COMMAND, OBS_GAIT_PHASE};

    fn policy() -> Result<WalkPolicy, PolicyError> {
        WalkPolicy::shipped()
    }

    fn standing_state(policy: &WalkPolicy) -> LegState {
        let defaults = policy.config().default_targets();
        LegState {
            torso_orientation: [1.0, 0.0, 0.0, 0.0],
            torso_angular_velocity: [0.0; 3],
            joint_positions: LEG_JOINTS.map(|i| defaults[i].q),
            joint_velocities: [0.0; ACTION_LEN],
        }
    }

    fn approx(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn command_moves_at_most_one_smoothing_step_per_step() -> Result<(), PolicyError> {
        let mut policy = policy()?;
        let state = standing_state(&policy);
        let command = WalkCommand { vx: 0.5, vy: -0.03, yaw_rate: 0.01 };
        policy.step(&state, command);
        let first = policy.smoothed_command();
        assert!(approx(first.vx, 0.02) && approx(first.vy, -0.02) && approx(first.yaw_rate, 0.01));
        policy.step(&state, command);
        let second = policy.smoothed_command();
        assert!(approx(second.vx, 0.04) && approx(second.vy, -0.03));
        for _ in 0..30 {
            policy.step(&state, command);
        }
        assert!(approx(policy.smoothed_command().vx, 0.5));
        // Back down just as gradually.
        policy.step(&state, WalkCommand::STAND);
        assert!(approx(policy.smoothed_command().vx, 0.48));
        Ok(())
    }

    #[test]
    fn observation_carries_the_smoothed_command_not_the_desired_one() -> Result<(), PolicyError> {
        let mut policy = policy()?;
        let state = standing_state(&policy);
        policy.step(&state, WalkCommand { vx: 1.0, ..WalkCommand::STAND });
        assert_eq!(policy.observation()[OBS_COMMAND], [0.02, 0.0, 0.0]);
        Ok(())
    }

    #[test]
    fn standing_until_the_command_leaves_zero() -> Result<(), PolicyError> {
        let mut policy = policy()?;
        let state = standing_state(&policy);
        for _ in 0..5 {
            policy.step(&state, WalkCommand::STAND);
            assert!(!policy.is_walking());
            assert_eq!(policy.observation()[OBS_GAIT_PHASE], [0.0, 0.0]);
            assert_eq!(policy.observation()[OBS_COMMAND], [0.0; 3]);
            assert_eq!(policy.phase(), 0.0, "the phase holds while standing");
        }
        policy.step(&state, WalkCommand { yaw_rate: 0.3, ..WalkCommand::STAND });
        assert!(policy.is_walking());
        // The first walking step is at phase zero: cos 1, sin 0.
        assert_eq!(policy.observation()[OBS_GAIT_PHASE], [1.0, 0.0]);
        Ok(())
    }

    #[test]
    fn phase_advances_by_period_times_frequency_and_wraps() -> Result<(), PolicyError> {
        let mut policy = policy()?;
        let state = standing_state(&policy);
        let walk = WalkCommand { vx: 0.3, ..WalkCommand::STAND };
        policy.step(&state, walk);
        assert!(approx(policy.phase(), 0.02));
        for _ in 0..12 {
            policy.step(&state, walk);
        }
        // 13 steps of 20 ms at 1 Hz; the observation used the phase before the last advance.
        assert!(approx(policy.phase(), 0.26));
        let angle = std::f64::consts::TAU * 0.24;
        let features = &policy.observation()[OBS_GAIT_PHASE];
        assert!((f64::from(features[0]) - angle.cos()).abs() < 1e-6);
        assert!((f64::from(features[1]) - angle.sin()).abs() < 1e-6);
        for _ in 0..37 {
            policy.step(&state, walk);
        }
        assert!(policy.phase() < 1e-9 || policy.phase() > 1.0 - 1e-9, "{}", policy.phase());
        // The phase holds once the smoothed command has come back to zero.
        for _ in 0..20 {
            policy.step(&state, WalkCommand::STAND);
        }
        let held = policy.phase();
        policy.step(&state, WalkCommand::STAND);
        assert!(!policy.is_walking());
        assert_eq!(policy.phase(), held);
        Ok(())
    }

    #[test]
    fn restart_gait_zeroes_a_held_phase_only_while_standing() -> Result<(), PolicyError> {
        let mut policy = policy()?;
        let state = standing_state(&policy);
        for _ in 0..10 {
            policy.step(&state, WalkCommand { vx: 0.1, ..WalkCommand::STAND });
        }
        let walking = policy.phase();
        policy.restart_gait();
        assert_eq!(policy.phase(), walking, "a gait in progress keeps its phase");
        for _ in 0..10 {
            policy.step(&state, WalkCommand::STAND);
        }
        assert!(!policy.is_walking() && policy.phase() > 0.0);
        policy.restart_gait();
        assert_eq!(policy.phase(), 0.0);
        Ok(())
    }

    #[test]
    fn reset_forgets_command_phase_and_action() -> Result<(), PolicyError> {
        let mut policy = policy()?;
        let state = standing_state(&policy);
        for _ in 0..10 {
            policy.step(&state, WalkCommand { vx: 0.5, ..WalkCommand::STAND });
        }
        policy.reset();
        assert_eq!(policy.smoothed_command(), WalkCommand::STAND);
        assert_eq!(policy.phase(), 0.0);
        assert_eq!(policy.previous_action(), &[0.0; ACTION_LEN]);
        assert!(!policy.is_walking());
        Ok(())
    }

    #[test]
    fn non_finite_command_keeps_the_smoothed_one() -> Result<(), PolicyError> {
        let mut policy = policy()?;
        let state = standing_state(&policy);
        policy.step(&state, WalkCommand { vx: 0.2, ..WalkCommand::STAND });
        policy.step(&state, WalkCommand { vx: f64::NAN, ..WalkCommand::STAND });
        assert!(approx(policy.smoothed_command().vx, 0.02));
        Ok(())
    }

    #[test]
    fn targets_stay_within_the_clip_of_the_default_pose() -> Result<(), PolicyError> {
        let mut policy = policy()?;
        let defaults = policy.config().default_targets();
        // A wild state: tumbling, joints far off, fast.
        let state = LegState {
            torso_orientation: [0.3, 0.8, -0.4, 0.3],
            torso_angular_velocity: [6.0, -5.0, 4.0],
            joint_positions: std::array::from_fn(|i| if i % 2 == 0 { 2.0 } else { -2.0 }),
            joint_velocities: [20.0; ACTION_LEN],
        };
        for _ in 0..20 {
            let targets = policy.step(&state, WalkCommand { vx: 1.0, ..WalkCommand::STAND });
            for (target, &index) in targets.iter().zip(&LEG_JOINTS) {
                assert!((target.q - defaults[index].q).abs() <= 1.0 + 1e-9, "{target:?}");
                assert_eq!((target.kp, target.kd), (defaults[index].kp, defaults[index].kd));
            }
        }
        Ok(())
    }

    #[test]
    fn non_finite_state_gives_finite_targets() -> Result<(), PolicyError> {
        let mut policy = policy()?;
        let mut state = standing_state(&policy);
        state.torso_orientation = [f64::NAN; 4];
        state.joint_positions[3] = f64::NAN;
        state.joint_velocities[7] = f64::INFINITY;
        for _ in 0..3 {
            let targets = policy.step(&state, WalkCommand::STAND);
            assert!(targets.iter().all(|t| t.q.is_finite()), "{targets:?}");
        }
        assert!(policy.previous_action().iter().all(|a| a.is_finite()));
        Ok(())
    }

    #[test]
    fn gains_are_the_deployment_ones_in_si() -> Result<(), PolicyError> {
        let mut policy = policy()?;
        let state = standing_state(&policy);
        let targets = policy.step(&state, WalkCommand::STAND);
        // Left hip pitch and left ankle pitch, N m/rad and N m s/rad.
        assert_eq!((targets[0].kp, targets[0].kd), (200.0, 5.0));
        assert_eq!((targets[4].kp, targets[4].kd), (50.0, 3.0));
        let upper = policy.upper_body_targets();
        assert_eq!(upper[0], JointTarget { q: 0.0, kp: 20.0, kd: 0.2 });
        // Left shoulder roll holds the arm down at -1.35 rad; the waist is stiff.
        assert_eq!(upper[3].q, -1.35);
        assert_eq!((upper[10].kp, upper[10].kd), (200.0, 5.0));
        Ok(())
    }

    #[test]
    fn an_invalid_config_is_refused() -> Result<(), PolicyError> {
        let mut config = T1Config::shipped()?;
        config.joints.pop();
        let message = WalkPolicy::new(config, WalkNetwork::shipped()?)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(message.contains("`joints`"), "{message}");
        Ok(())
    }
}
