//! The patrol's part of each multiplexer's activation function (paper 3.5.2): the reactive
//! score S_r refreshed on every percept, and which primitive behavior pursues a goal given the
//! percepts.

use strata_robot::command::Resource;
use strata_robot::control::reactive::{ActivationPolicy, ReactiveInput, Stability};
use strata_robot::control::scores::GoalScore;
use strata_robot::world::WorldState;

use crate::goals::{BodyGoal, HeadGoal, WholeBodyGoal};
use crate::primitives::{BodyPrimitive, HeadPrimitive, WholeBodyPrimitive, head_goal_objects};

type Input<'a> = ReactiveInput<'a, WorldState>;

/// The head. S_r is the need to look: one minus the confidence in the objects concerned, so
/// that an object the world model is losing gets the head back before the slow deliberative
/// layer notices.
#[derive(Debug, Default)]
pub struct HeadActivation;

impl ActivationPolicy<HeadGoal, WorldState> for HeadActivation {
    fn reactive_score(&self, goal: &GoalScore<HeadGoal>, input: &Input<'_>) -> f64 {
        let Some(world) = input.world else { return 1.0 };
        match goal.goal {
            HeadGoal::Scan => 0.5,
            HeadGoal::LookAt { .. } => 1.0 - world.pose.confidence,
            _ => head_goal_objects(world, &goal.goal)
                .iter()
                .map(|o| 1.0 - o.confidence)
                .fold(0.0, f64::max),
        }
    }

    fn primitives_for(&self, goal: &HeadGoal, input: &Input<'_>) -> &'static [HeadPrimitive] {
        let Some(world) = input.world else { return &[HeadPrimitive::Scan] };
        let localized = !world.pose.lost;
        match goal {
            HeadGoal::Scan => &[HeadPrimitive::Scan],
            HeadGoal::LookAt { .. } if localized => &[HeadPrimitive::LookAtTarget],
            HeadGoal::LookAt { .. } => &[HeadPrimitive::Scan],
            _ => {
                let objects = head_goal_objects(world, goal);
                // Tracking needs a position worth pointing at: a known object, or a landmark
                // predicted from a pose that is not lost.
                let trackable =
                    objects.iter().any(|o| o.known || (o.map_position.is_some() && localized));
                if trackable {
                    &[HeadPrimitive::ObjectTracking, HeadPrimitive::Scan]
                } else if matches!(goal, HeadGoal::InspectPoint { .. }) && localized {
                    // Not seen yet (or forgotten): look where the plan puts it.
                    &[HeadPrimitive::LookAtTarget, HeadPrimitive::Scan]
                } else {
                    &[HeadPrimitive::Scan]
                }
            }
        }
    }
}

/// The body: one goal at a time. S_r says how feasible it is right now: walking by a pose that
/// is lost is worth little.
#[derive(Debug, Default)]
pub struct BodyActivation;

impl ActivationPolicy<BodyGoal, WorldState> for BodyActivation {
    fn reactive_score(&self, goal: &GoalScore<BodyGoal>, input: &Input<'_>) -> f64 {
        match (&goal.goal, input.world) {
            (BodyGoal::GoToWaypoint { .. }, Some(world)) if world.pose.lost => 0.2,
            (BodyGoal::GoToWaypoint { .. }, None) => 0.0,
            _ => 1.0,
        }
    }

    fn primitives_for(&self, goal: &BodyGoal, input: &Input<'_>) -> &'static [BodyPrimitive] {
        match goal {
            BodyGoal::GoToWaypoint { .. } if input.world.is_some() => {
                &[BodyPrimitive::GoToWaypoint]
            }
            _ => &[BodyPrimitive::Stand],
        }
    }
}

/// Head and body: the reflexes, offered on every cycle (they must not wait for the slow
/// deliberative layer).
#[derive(Debug, Default)]
pub struct WholeBodyActivation;

impl ActivationPolicy<WholeBodyGoal, WorldState> for WholeBodyActivation {
    fn reactive_score(&self, goal: &GoalScore<WholeBodyGoal>, input: &Input<'_>) -> f64 {
        match goal.goal {
            WholeBodyGoal::Fall { .. } => {
                f64::from(matches!(input.stability, Stability::Unstable(_)))
            }
            WholeBodyGoal::StandUp { .. } => {
                f64::from(matches!(input.stability, Stability::Fallen(_)))
            }
        }
    }

    fn primitives_for(
        &self,
        goal: &WholeBodyGoal,
        input: &Input<'_>,
    ) -> &'static [WholeBodyPrimitive] {
        match goal {
            // A stand-up tilts the robot on purpose: that is not a fall to protect from.
            WholeBodyGoal::Fall { .. }
                if matches!(input.stability, Stability::Unstable(_))
                    && !input.actuation.busy.contains(&Resource::Head) =>
            {
                &[WholeBodyPrimitive::Fall]
            }
            WholeBodyGoal::StandUp { .. } if matches!(input.stability, Stability::Fallen(_)) => {
                &[WholeBodyPrimitive::StandUp]
            }
            _ => &[],
        }
    }
}
