//! The motion a body goal's acting primitive is expected to make before the deliberative layer
//! decides again: what the task-value criterion of active vision (paper 3.6) evaluates a look
//! after. A walk toward the goal's target at the body's speed limits, no farther than the
//! target; a turn toward its heading at the turning limit.

use nalgebra::Matrix3;
use strata_robot::control::active_vision::PredictedMotion;
use strata_robot::geometry::{Odometry, Point, Pose, Robot, normalize_angle};
use strata_robot::world::OdometryNoise;

use crate::goals::BodyGoal;
use crate::primitives::MotionModel;

/// The displacement (robot frame) `goal` is expected to make in `horizon` seconds from `pose`;
/// `ball` is the ball's position relative to the robot, for the goals that walk to it. `None`
/// when the goal stands still.
pub fn predicted_odometry(
    goal: &BodyGoal,
    pose: Pose,
    ball: Option<Point<Robot>>,
    motion: &MotionModel,
    horizon: f64,
) -> Option<Odometry> {
    let (target, heading) = match goal {
        BodyGoal::Stand => return None,
        BodyGoal::ObserveTarget { target } => (None, Some(pose.to_robot(*target).bearing())),
        BodyGoal::GoToPosition { pose: target } => (
            Some(pose.to_robot(target.position())),
            Some(normalize_angle(target.theta - pose.theta)),
        ),
        BodyGoal::GoToBallAndKick { .. } => (ball, ball.map(|b| b.bearing())),
    };
    let horizon = horizon.max(0.0);
    let (mut dx, mut dy) = (0.0, 0.0);
    if let Some(target) = target {
        let distance = target.x.hypot(target.y);
        if distance > 1e-9 {
            // The walk's speed limit along the target's direction (an ellipse of the forward
            // and sideways limits).
            let (ux, uy) = (target.x / distance, target.y / distance);
            let speed = 1.0
                / ((ux / motion.max_forward.max(1e-9)).powi(2)
                    + (uy / motion.max_sideways.max(1e-9)).powi(2))
                .sqrt();
            let step = distance.min(speed * horizon);
            (dx, dy) = (ux * step, uy * step);
        }
    }
    let turn = motion.max_turn.max(0.0) * horizon;
    let dtheta = heading.map_or(0.0, |h| h.clamp(-turn, turn));
    Some(Odometry { dx, dy, dtheta })
}

/// [`predicted_odometry`] with the error a walk of that length adds (`noise`: the world
/// model's odometry noise).
pub fn predicted_motion(
    goal: &BodyGoal,
    pose: Pose,
    ball: Option<Point<Robot>>,
    motion: &MotionModel,
    horizon: f64,
    noise: &OdometryNoise,
) -> Option<PredictedMotion> {
    let odometry = predicted_odometry(goal, pose, ball, motion, horizon)?;
    let noise: Matrix3<f64> = noise.covariance(&odometry);
    Some(PredictedMotion { odometry, noise })
}

#[cfg(test)]
mod tests {
    use super::*;
    use strata_robot::geometry::Global;

    fn model() -> MotionModel {
        MotionModel {
            max_forward: 0.3,
            max_sideways: 0.15,
            max_turn: 1.0,
            ..MotionModel::default()
        }
    }

    #[test]
    fn a_walk_goes_toward_its_target_at_the_speed_limit_and_no_farther() {
        let pose = Pose::new(1.0, 0.0, std::f64::consts::FRAC_PI_2);
        // 2 m ahead (the robot faces +y): 0.3 m in a second.
        let far = BodyGoal::GoToPosition { pose: Pose::new(1.0, 2.0, std::f64::consts::FRAC_PI_2) };
        let step = predicted_odometry(&far, pose, None, &model(), 1.0).expect("a walk");
        assert!((step.dx - 0.3).abs() < 1e-9 && step.dy.abs() < 1e-9, "{step:?}");
        assert!(step.dtheta.abs() < 1e-9);
        // 0.1 m ahead: reached within the horizon.
        let near = BodyGoal::GoToPosition { pose: Pose::new(1.0, 0.1, 0.0) };
        let step = predicted_odometry(&near, pose, None, &model(), 1.0).expect("a walk");
        assert!((step.dx - 0.1).abs() < 1e-9);
        // The turn to the target's heading (-90 degrees) is limited to 1 rad/s.
        assert!((step.dtheta + 1.0).abs() < 1e-9, "{step:?}");
        // Sideways, the slower limit.
        let side =
            BodyGoal::GoToPosition { pose: Pose::new(0.0, 0.0, std::f64::consts::FRAC_PI_2) };
        let step = predicted_odometry(&side, pose, None, &model(), 1.0).expect("a walk");
        assert!((step.dy - 0.15).abs() < 1e-9 && step.dx.abs() < 1e-9, "{step:?}");
    }

    #[test]
    fn standing_makes_no_motion_and_observing_only_turns() {
        let pose = Pose::new(0.0, 0.0, 0.0);
        assert_eq!(predicted_odometry(&BodyGoal::Stand, pose, None, &model(), 1.0), None);
        let look = BodyGoal::ObserveTarget { target: Point::<Global>::new(0.0, 3.0) };
        let step = predicted_odometry(&look, pose, None, &model(), 0.5).expect("a turn");
        assert_eq!((step.dx, step.dy), (0.0, 0.0));
        assert!((step.dtheta - 0.5).abs() < 1e-9, "{step:?}");
        let kick = BodyGoal::GoToBallAndKick {
            kick: crate::goals::Kick::Forward,
            target: Point::<Global>::new(4.5, 0.0),
        };
        let ball = Point::<Robot>::new(0.0, -0.1);
        let step = predicted_odometry(&kick, pose, Some(ball), &model(), 2.0).expect("a walk");
        assert!((step.dy + 0.1).abs() < 1e-9, "to the ball and no farther: {step:?}");
        let noise = OdometryNoise::default();
        let motion =
            predicted_motion(&kick, pose, Some(ball), &model(), 2.0, &noise).expect("a motion");
        assert!(motion.noise[(0, 0)] > 0.0, "a walk adds odometry error");
    }
}
