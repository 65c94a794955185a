//! The 47-value observation the walking network reads, laid out as booster_gym's deployment
//! builds it.

use std::ops::Range;

use super::{ACTION_LEN, ObservationScales};

pub const OBSERVATION_LEN: usize = 47;

/// Gravity (0, 0, -1) rotated into the torso frame.
pub const OBS_GRAVITY: Range<usize> = 0..3;
/// Torso angular velocity, rad/s.
pub const OBS_ANGULAR_VELOCITY: Range<usize> = 3..6;
/// Smoothed command vx, vy (m/s), yaw rate (rad/s); zero while standing.
pub const OBS_COMMAND: Range<usize> = 6..9;
/// cos and sin of 2 pi times the gait phase; zero while standing.
pub const OBS_GAIT_PHASE: Range<usize> = 9..11;
/// Leg joint positions minus the default pose, rad.
pub const OBS_JOINT_POSITIONS: Range<usize> = 11..23;
/// Leg joint velocities, rad/s, scaled.
pub const OBS_JOINT_VELOCITIES: Range<usize> = 23..35;
/// The previous step's clipped action.
pub const OBS_PREVIOUS_ACTION: Range<usize> = 35..47;

/// The unit gravity direction (0, 0, -1) of the world, seen from a torso whose orientation in
/// the world is the quaternion `(w, x, y, z)`: the third row of the torso-to-world rotation,
/// negated. The quaternion need not be normalized; a zero or non-finite one gives upright
/// (0, 0, -1), so a missing orientation reading cannot poison the network with NaN.
pub fn gravity_in_torso([w, x, y, z]: [f64; 4]) -> [f64; 3] {
    let norm_sq = w * w + x * x + y * y + z * z;
    if !(norm_sq.is_finite() && norm_sq > 1e-12) {
        return [0.0, 0.0, -1.0];
    }
    // Dividing the quadratic terms by |q|^2 normalizes the rotation they form.
    let s = 2.0 / norm_sq;
    [-s * (x * z - w * y), -s * (y * z + w * x), -(1.0 - s * (x * x + y * y))]
}

/// What one observation is made of, already in SI units and the policy's leg order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ObservationInputs<'a> {
    pub gravity: [f64; 3],
    pub angular_velocity: [f64; 3],
    /// The smoothed command; `None` while standing.
    pub command: Option<[f64; 3]>,
    /// The gait phase in [0, 1); `None` while standing.
    pub phase: Option<f64>,
    pub joint_offsets: [f64; ACTION_LEN],
    pub joint_velocities: [f64; ACTION_LEN],
    pub previous_action: &'a [f32; ACTION_LEN],
}

/// Builds the observation; a value that is not finite (a sensor dropout) becomes zero, the
/// value the network sees for "nothing unusual" in every slot.
pub(crate) fn build(
    inputs: &ObservationInputs<'_>,
    scales: &ObservationScales,
) -> [f32; OBSERVATION_LEN] {
    let mut obs = [0.0f64; OBSERVATION_LEN];
    for (slot, g) in obs[OBS_GRAVITY].iter_mut().zip(inputs.gravity) {
        *slot = g * scales.gravity;
    }
    for (slot, w) in obs[OBS_ANGULAR_VELOCITY].iter_mut().zip(inputs.angular_velocity) {
        *slot = w * scales.ang_vel;
    }
    if let Some([vx, vy, yaw_rate]) = inputs.command {
        obs[OBS_COMMAND].copy_from_slice(&[
            vx * scales.lin_vel,
            vy * scales.lin_vel,
            yaw_rate * scales.ang_vel,
        ]);
    }
    if let Some(phase) = inputs.phase {
        let angle = std::f64::consts::TAU * phase;
        obs[OBS_GAIT_PHASE].copy_from_slice(&[angle.cos(), angle.sin()]);
    }
    for (slot, q) in obs[OBS_JOINT_POSITIONS].iter_mut().zip(inputs.joint_offsets) {
        *slot = q * scales.dof_pos;
    }
    for (slot, dq) in obs[OBS_JOINT_VELOCITIES].iter_mut().zip(inputs.joint_velocities) {
        *slot = dq * scales.dof_vel;
    }
    for (slot, &a) in obs[OBS_PREVIOUS_ACTION].iter_mut().zip(inputs.previous_action) {
        *slot = f64::from(a);
    }
    obs.map(|v| if v.is_finite() { v as f32 } else { 0.0 })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_scales() -> ObservationScales {
        ObservationScales { gravity: 1.0, lin_vel: 1.0, ang_vel: 1.0, dof_pos: 1.0, dof_vel: 0.1 }
    }

    fn close(a: [f64; 3], b: [f64; 3]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12)
    }

    #[test]
    fn upright_torso_sees_gravity_straight_down() {
        assert_eq!(gravity_in_torso([1.0, 0.0, 0.0, 0.0]), [0.0, 0.0, -1.0]);
        // Yaw does not change which way is down.
        let half = 0.7_f64 / 2.0;
        let yawed = gravity_in_torso([half.cos(), 0.0, 0.0, half.sin()]);
        assert!(close(yawed, [0.0, 0.0, -1.0]), "{yawed:?}");
    }

    #[test]
    fn pitched_forward_torso_sees_gravity_ahead() {
        // Pitch +30 degrees about y (nose down in a z-up, x-forward world): the torso's x axis
        // points partly down, so gravity has a positive x component in the torso frame.
        let angle = 30f64.to_radians();
        let q = [(angle / 2.0).cos(), 0.0, (angle / 2.0).sin(), 0.0];
        let g = gravity_in_torso(q);
        assert!(close(g, [angle.sin(), 0.0, -angle.cos()]), "{g:?}");
    }

    #[test]
    fn rolled_torso_sees_gravity_sideways() {
        // Roll +90 degrees about x: the torso's y axis points up, so gravity is along -y.
        let half = std::f64::consts::FRAC_PI_4;
        let g = gravity_in_torso([half.cos(), half.sin(), 0.0, 0.0]);
        assert!(close(g, [0.0, -1.0, 0.0]), "{g:?}");
    }

    #[test]
    fn upside_down_and_unnormalized_quaternions() {
        assert!(close(gravity_in_torso([0.0, 1.0, 0.0, 0.0]), [0.0, 0.0, 1.0]));
        let angle = 30f64.to_radians();
        let scaled = [2.0 * (angle / 2.0).cos(), 0.0, 2.0 * (angle / 2.0).sin(), 0.0];
        assert!(close(gravity_in_torso(scaled), [angle.sin(), 0.0, -angle.cos()]));
    }

    #[test]
    fn missing_orientation_reads_as_upright() {
        assert_eq!(gravity_in_torso([0.0; 4]), [0.0, 0.0, -1.0]);
        assert_eq!(gravity_in_torso([f64::NAN, 0.0, 0.0, 0.0]), [0.0, 0.0, -1.0]);
    }

    fn walking_inputs(previous: &[f32; ACTION_LEN]) -> ObservationInputs<'_> {
        ObservationInputs {
            gravity: [0.1, -0.2, -0.97],
            angular_velocity: [0.3, -0.4, 0.5],
            command: Some([0.6, -0.1, 0.2]),
            phase: Some(0.25),
            joint_offsets: std::array::from_fn(|i| 0.01 * i as f64),
            joint_velocities: std::array::from_fn(|i| i as f64 - 6.0),
            previous_action: previous,
        }
    }

    #[test]
    fn each_slice_holds_its_part() {
        let previous: [f32; ACTION_LEN] = std::array::from_fn(|i| i as f32 / 12.0 - 0.5);
        let obs = build(&walking_inputs(&previous), &unit_scales());
        assert_eq!(obs[OBS_GRAVITY], [0.1, -0.2, -0.97]);
        assert_eq!(obs[OBS_ANGULAR_VELOCITY], [0.3, -0.4, 0.5]);
        assert_eq!(obs[OBS_COMMAND], [0.6, -0.1, 0.2]);
        // Phase a quarter: cos 0, sin 1.
        assert!(obs[OBS_GAIT_PHASE][0].abs() < 1e-7);
        assert_eq!(obs[OBS_GAIT_PHASE][1], 1.0);
        let positions: Vec<f32> = (0..ACTION_LEN).map(|i| (0.01 * i as f64) as f32).collect();
        assert_eq!(obs[OBS_JOINT_POSITIONS], positions[..]);
        // Velocities are scaled by dof_vel = 0.1.
        let velocities: Vec<f32> =
            (0..ACTION_LEN).map(|i| ((i as f64 - 6.0) * 0.1) as f32).collect();
        assert_eq!(obs[OBS_JOINT_VELOCITIES], velocities[..]);
        assert_eq!(obs[OBS_PREVIOUS_ACTION], previous);
    }

    #[test]
    fn standing_zeroes_command_and_phase_only() {
        let previous = [0.25f32; ACTION_LEN];
        let inputs = ObservationInputs { command: None, phase: None, ..walking_inputs(&previous) };
        let obs = build(&inputs, &unit_scales());
        assert_eq!(obs[OBS_COMMAND], [0.0; 3]);
        assert_eq!(obs[OBS_GAIT_PHASE], [0.0; 2]);
        assert_eq!(obs[OBS_GRAVITY], [0.1, -0.2, -0.97]);
        assert_eq!(obs[OBS_PREVIOUS_ACTION], previous);
    }

    #[test]
    fn scales_apply_per_part() {
        let previous = [0.0f32; ACTION_LEN];
        let scales = ObservationScales {
            gravity: 2.0,
            lin_vel: 3.0,
            ang_vel: 0.5,
            dof_pos: 4.0,
            dof_vel: 0.1,
        };
        let obs = build(&walking_inputs(&previous), &scales);
        assert_eq!(obs[OBS_GRAVITY][0], 0.2);
        assert_eq!(obs[OBS_ANGULAR_VELOCITY][0], 0.15);
        // vx and vy by lin_vel, the yaw rate by ang_vel.
        assert_eq!(obs[OBS_COMMAND], [1.8, -0.3, 0.1]);
        assert_eq!(obs[OBS_JOINT_POSITIONS][1], 0.04);
    }

    #[test]
    fn non_finite_readings_become_zero() {
        let previous = [0.0f32; ACTION_LEN];
        let mut inputs = walking_inputs(&previous);
        inputs.angular_velocity[1] = f64::NAN;
        inputs.joint_velocities[3] = f64::INFINITY;
        let obs = build(&inputs, &unit_scales());
        assert_eq!(obs[OBS_ANGULAR_VELOCITY], [0.3, 0.0, 0.5]);
        assert_eq!(obs[OBS_JOINT_VELOCITIES][3], 0.0);
        assert!(obs.iter().all(|v| v.is_finite()));
    }
}
