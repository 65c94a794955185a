//! Value functions of soccer's deliberative behaviors (paper 3.4): V(x) grows with how
//! convenient the world state is for the behavior. Active vision ([`strata_robot::control::
//! active_vision`]) differentiates them numerically, so they are written smooth.

use std::sync::Arc;

use strata_robot::control::active_vision::{ValueFunction, ValueState};
use strata_robot::geometry::{Global as FieldFrame, Point, Segment, normalize_angle};
use strata_robot::world::ObjectId;

use crate::field::TeamField;

/// How much of the goal's angle, seen from the ball, the keeper's body covers.
///
/// The goal spans the angles from the ball to its two posts; the keeper blocks the angles
/// within its reach of the line from the ball to its centre. Coverage is computed with a soft
/// edge (a logistic of width `edge`) over samples of the goal's angle, so V is smooth in the
/// keeper's pose and the ball's position.
pub fn goal_coverage(
    field: &TeamField,
    ball: Point<FieldFrame>,
    keeper: Point<FieldFrame>,
    reach: f64,
    edge: f64,
) -> f64 {
    let [left, right] = field.posts(strata_spl::field::Side::Own);
    let a_left = (left - ball).angle();
    let a_right = (right - ball).angle();
    let span = normalize_angle(a_left - a_right);
    if span.abs() < 1e-6 {
        return 0.0;
    }
    let to_keeper = keeper - ball;
    let distance = to_keeper.norm().max(1e-3);
    let centre = to_keeper.angle();
    let half = (reach / distance).min(1.0).asin();
    const SAMPLES: usize = 24;
    let mut covered = 0.0;
    for i in 0..SAMPLES {
        let t = (i as f64 + 0.5) / SAMPLES as f64;
        let angle = a_right + span * t;
        let off = normalize_angle(angle - centre).abs();
        covered += 1.0 / (1.0 + ((off - half) / edge).exp());
    }
    covered / SAMPLES as f64
}

/// V of goal covering: the fraction of the own goal's angle from the ball the keeper covers.
#[derive(Debug, Clone)]
pub struct GoalCoveringValue {
    pub field: Arc<TeamField>,
    pub ball: ObjectId,
    /// Half the width the keeper blocks, m.
    pub reach: f64,
}

impl ValueFunction for GoalCoveringValue {
    fn name(&self) -> &str {
        "goal covering"
    }

    fn objects(&self) -> Vec<ObjectId> {
        vec![self.ball]
    }

    fn value(&self, state: &ValueState<'_>) -> f64 {
        let Some(ball) = state.object_field(self.ball) else { return 0.0 };
        goal_coverage(&self.field, ball, state.pose.position(), self.reach, 0.03)
    }
}

/// V of go to ball: a striker wants to be close to the ball, on the side away from the goal it
/// attacks, facing it. With the ball seen relative to the robot, the pose matters through the
/// direction of the goal: aiming needs localization.
#[derive(Debug, Clone)]
pub struct GoToBallValue {
    pub field: Arc<TeamField>,
    pub ball: ObjectId,
}

impl ValueFunction for GoToBallValue {
    fn name(&self) -> &str {
        "go to ball"
    }

    fn objects(&self) -> Vec<ObjectId> {
        vec![self.ball]
    }

    fn value(&self, state: &ValueState<'_>) -> f64 {
        let Some(ball) = state.object_field(self.ball) else { return 0.0 };
        let robot = state.pose.position();
        let shot = (self.field.opponent_goal() - ball).angle();
        let approach = (ball - robot).angle();
        let distance = (ball - robot).norm();
        // Close and coming from behind the ball along the shot: high value.
        let alignment = normalize_angle(shot - approach);
        (-0.5 * distance).exp() * (0.5 + 0.5 * alignment.cos())
    }
}

/// V of going to a field position: closeness to it, which only localization improves.
#[derive(Debug, Clone)]
pub struct PositionValue {
    pub target: Point<FieldFrame>,
}

impl ValueFunction for PositionValue {
    fn name(&self) -> &str {
        "going to field position"
    }

    fn objects(&self) -> Vec<ObjectId> {
        Vec::new()
    }

    fn value(&self, state: &ValueState<'_>) -> f64 {
        (-0.5 * state.pose.position().distance(self.target)).exp()
    }
}

/// V of avoiding an obstacle: reaching the waypoint beside the rival in the way, with room to
/// pass it. The waypoint is a field position and the rival is seen relative to the robot, so
/// both the pose and the rival's estimate matter: a look at the rival tells how much room
/// there is, a look at a landmark or a line where the waypoint is.
#[derive(Debug, Clone)]
pub struct AvoidingValue {
    pub waypoint: Point<FieldFrame>,
    pub rival: ObjectId,
    /// The room wanted between the path and the rival, m.
    pub clearance: f64,
}

impl ValueFunction for AvoidingValue {
    fn name(&self) -> &str {
        "avoiding obstacle"
    }

    fn objects(&self) -> Vec<ObjectId> {
        vec![self.rival]
    }

    fn value(&self, state: &ValueState<'_>) -> f64 {
        let Some(rival) = state.object_field(self.rival) else { return 0.0 };
        let robot = state.pose.position();
        let reach = (-0.5 * robot.distance(self.waypoint)).exp();
        let room = Segment::new(robot, self.waypoint).distance_to(rival) / self.clearance.max(1e-3);
        // Smooth, so that the rival's uncertainty has a gradient to act on.
        reach * (1.0 - (-0.5 * room * room).exp())
    }
}

/// V of waiting for the referee's Ready gesture (Standby): how centred the referee would be
/// in the image with the head turned to `gaze`, where the robot believes the referee stands.
/// A gesture detector is surest near the image's centre and blind beyond its edge; a heading
/// or position error moves the referee toward the edge, so V falls with the pose's
/// uncertainty: E[V] is what looking at the referee is worth now, and what localizing first
/// would add.
#[derive(Debug, Clone)]
pub struct RefereeVisibilityValue {
    /// Where the referee stands (team frame).
    pub referee: Point<FieldFrame>,
    /// The gaze direction in the body frame, rad: toward the referee from the believed pose,
    /// within the head's reach.
    pub gaze: f64,
    /// The camera's horizontal field of view, rad.
    pub fov: f64,
    /// How far the gesture can be seen, m.
    pub range: f64,
}

impl ValueFunction for RefereeVisibilityValue {
    fn name(&self) -> &str {
        "watching the referee"
    }

    fn objects(&self) -> Vec<ObjectId> {
        Vec::new()
    }

    fn value(&self, state: &ValueState<'_>) -> f64 {
        let seen = state.pose.to_robot(self.referee);
        let off = normalize_angle(seen.bearing() - self.gaze);
        // Gaussian, not a step: its curvature at the centre is what makes E[V] fall with the
        // heading's variance (a flat top would hide the risk from a second-order estimate).
        let half = (self.fov / 2.0).max(1e-3);
        let centred = (-0.5 * (off / half).powi(2)).exp();
        let near = 1.0 / (1.0 + ((seen.range() - self.range) / 0.3).exp());
        centred * near
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field() -> TeamField {
        TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0)
    }

    #[test]
    fn a_keeper_on_the_line_from_ball_to_goal_covers_more_than_one_beside_it() {
        let f = field();
        let ball = Point::new(-2.5, 0.0);
        let centred = goal_coverage(&f, ball, Point::new(-4.2, 0.0), 0.3, 0.02);
        let beside = goal_coverage(&f, ball, Point::new(-4.2, 0.6), 0.3, 0.02);
        let near_ball = goal_coverage(&f, ball, Point::new(-3.0, 0.0), 0.3, 0.02);
        assert!(centred > beside, "{centred} {beside}");
        // Closer to the ball, the same body hides more of the goal.
        assert!(near_ball > centred, "{near_ball} {centred}");
        assert!((0.0..=1.0).contains(&centred));
        // Hand check: from 1.7 m the keeper's 0.3 m half-width hides asin(0.3/1.7) ~ 0.177 rad
        // each side; the goal spans 2 atan(0.75/2.0) ~ 0.72 rad: about 49%.
        assert!((centred - 0.49).abs() < 0.05, "{centred}");
    }

    /// Passing a rival is worth more the farther it stands from the path to the waypoint.
    #[test]
    fn a_rival_on_the_path_costs_value_and_one_aside_does_not() {
        use strata_robot::geometry::Pose;
        use strata_robot::world::WorldModel;
        let f = field();
        let mut world =
            WorldModel::new(crate::world_config::world_config(&f)).expect("valid").state();
        world.pose.pose = Pose::new(0.0, 0.0, 0.0);
        let rival = world.group(crate::world_config::OBSTACLE).next().expect("a track").id;
        let v = |world: &mut strata_robot::world::WorldState, y: f64| {
            let mut objects = world.objects.to_vec();
            objects[rival.index()].position = Point::new(0.8, y);
            world.objects = objects.into();
            let vf = AvoidingValue { waypoint: Point::new(1.6, 0.0), rival, clearance: 0.4 };
            vf.value(&ValueState::of(world))
        };
        let on_path = v(&mut world, 0.0);
        let near = v(&mut world, 0.3);
        let aside = v(&mut world, 1.5);
        assert!(on_path < 1e-9, "{on_path}");
        assert!(on_path < near && near < aside, "{on_path} {near} {aside}");
        // Far aside, only the distance to the waypoint counts: exp(-0.5 * 1.6).
        assert!((aside - (-0.8f64).exp()).abs() < 1e-3, "{aside}");
    }

    #[test]
    fn the_referee_is_worth_most_centred_and_within_range() {
        use strata_robot::geometry::Pose;
        use strata_robot::world::{WorldModel, WorldState};
        let f = field();
        let referee = f.referee(0.6);
        let state_at = |pose: Pose| -> WorldState {
            let mut world =
                WorldModel::new(crate::world_config::world_config(&f)).expect("valid").state();
            world.pose.pose = pose;
            world
        };
        // On the side line at x = -3, facing the field (+y), the referee behind-left.
        let pose = Pose::new(-3.0, 3.0, std::f64::consts::FRAC_PI_2);
        let gaze = pose.to_robot(referee).bearing();
        let v = |pose: Pose, range: f64| {
            let vf = RefereeVisibilityValue { referee, gaze, fov: 1.06, range };
            vf.value(&ValueState::of(&state_at(pose)))
        };
        let here = v(pose, 10.0);
        assert!(here > 0.9, "{here}");
        let turned = v(Pose::new(-3.0, 3.0, std::f64::consts::FRAC_PI_2 + 0.4), 10.0);
        assert!(turned < here * 0.8, "a heading error moves it off centre: {turned}");
        // 7.3 m away: beyond a 5 m gesture range it is not seen at all.
        assert!(v(pose, 5.0) < 0.01);
    }
}
