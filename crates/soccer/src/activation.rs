//! The soccer part of each multiplexer's activation function (paper 3.5.2): how goals split
//! when they cannot be executed together, the reactive score S_r refreshed on every percept,
//! and which primitive behavior pursues a goal given the percepts.

use std::sync::Arc;

use strata_robot::control::active_vision::GazeCandidate;
use strata_robot::control::reactive::{
    ActivationPolicy, ActivationShortcuts, GoalNotes, ReactiveInput, Stability,
};
use strata_robot::control::scores::GoalScore;
use strata_robot::platform::FallDirection;
use strata_robot::world::{ObjectEstimate, WorldState};

use crate::field::TeamField;
use crate::goals::{BodyGoal, HeadGoal, WholeBodyGoal};
use crate::primitives::{
    BodyPrimitive, HeadPrimitive, MotionModel, WholeBodyPrimitive, ball_crossing, kickable,
};
use crate::situation::{GoalObjects, ball, head_goal_objects, obstacle_ahead};

type Input<'a> = ReactiveInput<'a, WorldState>;

/// The head: observe goals. S_r is the need to look: one minus the confidence in the objects
/// concerned (the paper: "the higher the confidence of an object, the lower its associated
/// score").
#[derive(Debug)]
pub struct HeadActivation {
    pub fov: f64,
}

impl HeadActivation {
    /// Stage 1 on the goal's objects, found by `find`.
    fn split_with<'a>(
        &self,
        goal: &'a GoalScore<HeadGoal>,
        input: &Input<'a>,
        find: impl FnOnce(&'a WorldState, &'a HeadGoal) -> GoalObjects<'a>,
    ) -> Option<Vec<GoalScore<HeadGoal>>> {
        let HeadGoal::ObserveTogether { objects } = &goal.goal else { return None };
        let world = input.world?;
        let found = find(world, &goal.goal);
        let together = found.len() == objects.len()
            && GazeCandidate::covering_direction(world, found.iter().map(|o| o.id), self.fov * 0.8)
                .is_some();
        if together {
            return None;
        }
        // Not in one gaze from here: one goal per object, each with the deliberative score.
        let split = objects
            .iter()
            .map(|name| {
                let single = if name == crate::world_config::BALL {
                    HeadGoal::ObserveBall
                } else {
                    HeadGoal::ObserveLandmark { name: name.clone() }
                };
                GoalScore {
                    goal: single,
                    deliberative: goal.deliberative,
                    objects: vec![name.clone()],
                }
            })
            .collect();
        Some(split)
    }

    /// S_r and the primitives on the goal's objects, found (if needed) by `find`.
    fn assess_with<'a>(
        &self,
        goal: &'a GoalScore<HeadGoal>,
        input: &Input<'a>,
        find: impl FnOnce(&'a WorldState, &'a HeadGoal) -> GoalObjects<'a>,
    ) -> (f64, &'static [HeadPrimitive]) {
        let Some(world) = input.world else { return (1.0, &[HeadPrimitive::SearchObjectEllipse]) };
        if goal.goal == HeadGoal::Scan {
            return (0.5, &[HeadPrimitive::SearchObjectEllipse]);
        }
        let objects = find(world, &goal.goal);
        let need = need_to_look(&goal.goal, world, &objects);
        (need, head_primitives(&goal.goal, world, || objects))
    }
}

impl ActivationPolicy<HeadGoal, WorldState> for HeadActivation {
    fn split(
        &self,
        goal: &GoalScore<HeadGoal>,
        input: &Input<'_>,
    ) -> Option<Vec<GoalScore<HeadGoal>>> {
        self.split_with(goal, input, head_goal_objects)
    }

    fn reactive_score(&self, goal: &GoalScore<HeadGoal>, input: &Input<'_>) -> f64 {
        let Some(world) = input.world else { return 1.0 };
        if goal.goal == HeadGoal::Scan {
            return 0.5;
        }
        need_to_look(&goal.goal, world, &head_goal_objects(world, &goal.goal))
    }

    fn primitives_for(&self, goal: &HeadGoal, input: &Input<'_>) -> &'static [HeadPrimitive] {
        let Some(world) = input.world else { return &[HeadPrimitive::SearchObjectEllipse] };
        head_primitives(goal, world, || head_goal_objects(world, goal))
    }
}

impl ActivationShortcuts<HeadGoal, WorldState> for HeadActivation {
    /// Both answers from one look-up of the goal's objects.
    fn assess(
        &self,
        goal: &GoalScore<HeadGoal>,
        input: &Input<'_>,
    ) -> (f64, &'static [HeadPrimitive]) {
        self.assess_with(goal, input, head_goal_objects)
    }

    /// The goal's objects found where its notes say, not by name.
    fn split_noted(
        &self,
        goal: &GoalScore<HeadGoal>,
        notes: &mut GoalNotes,
        input: &Input<'_>,
    ) -> Option<Vec<GoalScore<HeadGoal>>> {
        // Only goals about several objects are split: the others need no notes for it.
        self.split_with(goal, input, |world, goal| {
            notes.get_or_insert_with(FoundObjects::default).objects(world, goal)
        })
    }

    /// The goal's objects found where its notes say, not by name.
    fn assess_noted(
        &self,
        goal: &GoalScore<HeadGoal>,
        notes: &mut GoalNotes,
        input: &Input<'_>,
    ) -> (f64, &'static [HeadPrimitive]) {
        let found = notes.get_or_insert_with(FoundObjects::default);
        self.assess_with(goal, input, |world, goal| found.objects(world, goal))
    }

    /// Every answer reads the world state alone (the goal's objects, the pose).
    fn reuse_key(&self, _: &Input<'_>) -> Option<u64> {
        Some(0)
    }
}

/// Where a head goal's objects were found by name: the ball and landmark instances a head goal
/// names are looked for by name (a hash of the name) several times per world state; found once,
/// they are found again by place.
#[derive(Debug, Default)]
struct FoundObjects {
    /// The objects of the world state they were found in: kept, so that their names' very
    /// texts identify the layout.
    noted: Option<Arc<[ObjectEstimate]>>,
    /// Each object's place in [`WorldState::objects`].
    places: Vec<usize>,
}

impl FoundObjects {
    /// [`head_goal_objects`] for `goal`: from the places noted, if `world` is a state of the
    /// layout they were noted in, otherwise by name (noting the places for next time).
    fn objects<'a>(&mut self, world: &'a WorldState, goal: &'a HeadGoal) -> GoalObjects<'a> {
        if let Some(objects) = self.at_places(world) {
            return objects;
        }
        let objects = head_goal_objects(world, goal);
        self.note(world, goal, &objects);
        objects
    }

    /// The objects at the places noted, if `world` holds at each the very name noted there (the
    /// same shared text) in a list as long: the layout they were noted in, by the test the
    /// world state's name index makes before it answers.
    fn at_places<'a>(&self, world: &'a WorldState) -> Option<GoalObjects<'a>> {
        let noted = self.noted.as_ref().filter(|n| n.len() == world.objects.len())?;
        let at = |place: usize| {
            let name = noted.get(place)?.name.as_str();
            world.objects.get(place).filter(|o| std::ptr::eq(o.name.as_str(), name))
        };
        if let [one] = self.places.as_slice() {
            return at(*one).map(|o| GoalObjects::One(Some(o)));
        }
        let mut missing = false;
        let objects = GoalObjects::collect(self.places.iter().map_while(|place| {
            let object = at(*place);
            missing |= object.is_none();
            object
        }));
        (!missing).then_some(objects)
    }

    /// Notes where `objects`, found by name for `goal`, are — if each is the object of that
    /// very name (a group's best instance changes with the estimates, and a missing object
    /// has no place).
    fn note(&mut self, world: &WorldState, goal: &HeadGoal, objects: &[&ObjectEstimate]) {
        self.places.clear();
        self.noted = None;
        let named = match goal {
            HeadGoal::ObserveBall => {
                objects.len() == 1 && self.note_place(world, crate::world_config::BALL, objects[0])
            }
            HeadGoal::ObserveLandmark { name } => {
                objects.len() == 1 && self.note_place(world, name, objects[0])
            }
            HeadGoal::ObserveTogether { objects: names } => {
                names.len() == objects.len()
                    && names.iter().zip(objects).all(|(name, o)| self.note_place(world, name, o))
            }
            _ => false,
        };
        if named {
            self.noted = Some(world.objects.clone());
        } else {
            self.places.clear();
        }
    }

    /// Notes the place of `object` if it is the object named `name`, where its id says.
    fn note_place(&mut self, world: &WorldState, name: &str, object: &ObjectEstimate) -> bool {
        let place = object.id.index();
        let at_place = world.objects.get(place).is_some_and(|o| std::ptr::eq(o, object));
        if object.name != name || !at_place {
            return false;
        }
        self.places.push(place);
        true
    }
}

/// S_r of a head goal (not a scan) about `objects`.
fn need_to_look(goal: &HeadGoal, world: &WorldState, objects: &[&ObjectEstimate]) -> f64 {
    if objects.is_empty() {
        return match goal {
            HeadGoal::ObservePartner { .. } | HeadGoal::ObserveFieldLine { .. } => {
                1.0 - world.pose.confidence
            }
            // The gesture is not in the world model: the need lasts as long as the goal.
            _ => 1.0,
        };
    }
    objects.iter().map(|o| 1.0 - o.confidence).fold(0.0, f64::max)
}

/// The head primitives that can pursue `goal`; `objects` gives the goal's objects when the
/// choice depends on them.
fn head_primitives<'a>(
    goal: &HeadGoal,
    world: &'a WorldState,
    objects: impl FnOnce() -> GoalObjects<'a>,
) -> &'static [HeadPrimitive] {
    match goal {
        HeadGoal::ObserveTogether { .. } => {
            &[HeadPrimitive::LookAtTarget, HeadPrimitive::SearchObjectEllipse]
        }
        HeadGoal::Scan => &[HeadPrimitive::SearchObjectEllipse],
        // A goal is looked at between its posts, which tracking one post would not do.
        HeadGoal::ObservePartner { .. }
        | HeadGoal::ObserveFieldLine { .. }
        | HeadGoal::ObserveReferee { .. }
        | HeadGoal::ObserveGoal { .. }
            if !world.pose.lost =>
        {
            &[HeadPrimitive::LookAtTarget]
        }
        HeadGoal::ObservePartner { .. }
        | HeadGoal::ObserveFieldLine { .. }
        | HeadGoal::ObserveReferee { .. }
        | HeadGoal::ObserveGoal { .. } => &[HeadPrimitive::SearchObjectEllipse],
        _ => {
            // Tracking needs a position worth pointing at: a tracked object, or a landmark
            // predicted from a pose that is not lost. A track not yet confident enough to be
            // known counts: seen once at the edge of a search (a far ball, a few frames), it
            // is confirmed by looking at it, or dropped when looking shows nothing, where the
            // search would sweep past it and let it fade.
            let trackable = objects()
                .iter()
                .any(|o| o.tracked || (o.map_position.is_some() && !world.pose.lost));
            if trackable {
                &[HeadPrimitive::ObjectTracking, HeadPrimitive::SearchObjectEllipse]
            } else {
                &[HeadPrimitive::SearchObjectEllipse]
            }
        }
    }
}

/// The body: one goal at a time, usually; S_r says how feasible it is right now.
#[derive(Debug)]
pub struct BodyActivation {
    pub model: Arc<MotionModel>,
}

impl ActivationPolicy<BodyGoal, WorldState> for BodyActivation {
    fn reactive_score(&self, goal: &GoalScore<BodyGoal>, input: &Input<'_>) -> f64 {
        match (&goal.goal, input.world) {
            (BodyGoal::GoToBallAndKick { .. }, Some(world)) => match ball(world) {
                Some(b) if b.known => 1.0,
                Some(_) => 0.3,
                None => 0.0,
            },
            _ => 1.0,
        }
    }

    fn primitives_for(&self, goal: &BodyGoal, input: &Input<'_>) -> &'static [BodyPrimitive] {
        if goal == &BodyGoal::Stand {
            return &[BodyPrimitive::Stand];
        }
        let Some(world) = input.world else { return &[BodyPrimitive::Stand] };
        let blocked = obstacle_ahead(world, self.model.collision_distance, 0.6).is_some();
        match goal {
            BodyGoal::GoToBallAndKick { kick, target } => {
                if kickable(&self.model, world, *kick, *target) {
                    // Kick or go-to-ball is decided from percepts; the kick id is the
                    // deliberative layer's parameter.
                    &[BodyPrimitive::KickBall, BodyPrimitive::GoToBall]
                } else if blocked && ball(world).is_none_or(|b| b.robot.range() > 0.5) {
                    &[BodyPrimitive::AvoidCollision, BodyPrimitive::GoToBall]
                } else if ball(world).is_some() {
                    &[BodyPrimitive::GoToBall]
                } else {
                    &[]
                }
            }
            BodyGoal::GoToPosition { .. } if blocked => {
                &[BodyPrimitive::AvoidCollision, BodyPrimitive::GoToPosition]
            }
            BodyGoal::GoToPosition { .. } | BodyGoal::ObserveTarget { .. } => {
                &[BodyPrimitive::GoToPosition]
            }
            BodyGoal::Stand => &[BodyPrimitive::Stand],
        }
    }
}

impl ActivationShortcuts<BodyGoal, WorldState> for BodyActivation {
    /// Every answer reads the world state alone (the ball, the obstacles).
    fn reuse_key(&self, _: &Input<'_>) -> Option<u64> {
        Some(0)
    }
}

/// Head and body: the reflexes (fall, stand-up), the dive, dribbling.
#[derive(Debug)]
pub struct WholeBodyActivation {
    /// A ball crossing the keeper's line within this time triggers the dive, s.
    pub dive_horizon: f64,
    /// ... and within this lateral distance, m.
    pub dive_reach: f64,
    pub field: Arc<TeamField>,
}

impl ActivationPolicy<WholeBodyGoal, WorldState> for WholeBodyActivation {
    fn reactive_score(&self, goal: &GoalScore<WholeBodyGoal>, input: &Input<'_>) -> f64 {
        match &goal.goal {
            WholeBodyGoal::Fall { .. } => {
                f64::from(matches!(input.stability, Stability::Unstable(_)))
            }
            WholeBodyGoal::StandUp { .. } => {
                f64::from(matches!(input.stability, Stability::Fallen(_)))
            }
            WholeBodyGoal::Dive { .. } => input
                .world
                .and_then(ball_crossing)
                .map_or(0.0, |(_, t)| (1.0 - t / self.dive_horizon).clamp(0.0, 1.0)),
            WholeBodyGoal::GoToBallAndDribble { .. } => match input.world.and_then(ball) {
                Some(b) if b.known && b.robot.range() < 1.0 => 1.0,
                Some(b) if b.known => 0.6,
                _ => 0.0,
            },
        }
    }

    fn primitives_for(
        &self,
        goal: &WholeBodyGoal,
        input: &Input<'_>,
    ) -> &'static [WholeBodyPrimitive] {
        match goal {
            // A whole-body sequence of our own (a stand-up sweeping the torso up from the
            // ground, a dive) tilts the robot on purpose: that is not a fall to protect from.
            WholeBodyGoal::Fall { .. }
                if matches!(input.stability, Stability::Unstable(_))
                    && !input.actuation.busy.contains(&strata_robot::command::Resource::Head) =>
            {
                &[WholeBodyPrimitive::Fall]
            }
            WholeBodyGoal::StandUp { .. } if matches!(input.stability, Stability::Fallen(_)) => {
                &[WholeBodyPrimitive::StandUp]
            }
            WholeBodyGoal::Dive { .. } if input.stability.is_stable() => {
                let dive = input.world.and_then(ball_crossing).is_some_and(|(y, t)| {
                    t < self.dive_horizon && y.abs() < self.dive_reach && t > 0.05
                });
                if dive { &[WholeBodyPrimitive::Dive] } else { &[] }
            }
            WholeBodyGoal::GoToBallAndDribble { .. } if input.stability.is_stable() => {
                if input.world.and_then(ball).is_some_and(|b| b.known) {
                    &[WholeBodyPrimitive::Dribbling]
                } else {
                    &[]
                }
            }
            _ => &[],
        }
    }
}

impl ActivationShortcuts<WholeBodyGoal, WorldState> for WholeBodyActivation {
    /// The answers read the world state, the stability and whether the head is busy.
    fn reuse_key(&self, input: &Input<'_>) -> Option<u64> {
        let direction = |d: FallDirection| match d {
            FallDirection::Front => 0,
            FallDirection::Back => 1,
            FallDirection::Left => 2,
            FallDirection::Right => 3,
        };
        let stability = match input.stability {
            Stability::Stable => 0,
            Stability::Unstable(d) => 1 + direction(d),
            Stability::Fallen(d) => 5 + direction(d),
        };
        let head_busy = input.actuation.busy.contains(&strata_robot::command::Resource::Head);
        Some(stability | u64::from(head_busy) << 4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use strata_robot::control::reactive::{ActuationStatus, Stability};
    use strata_robot::percept::Percepts;
    use strata_robot::world::WorldModel;
    use strata_runtime::Time;

    use crate::goals::GoalSide;
    use crate::world_config::{BALL, world_config};

    /// The head's combined assessment answers as its two separate questions do.
    #[test]
    fn head_assessment_is_its_score_and_primitives() {
        let field = TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0);
        let model = WorldModel::new(world_config(&field)).expect("valid world config");
        let mut world = model.state();
        let names: Vec<String> = world.objects.iter().map(|o| o.name.to_string()).collect();
        let mut goals = vec![
            HeadGoal::ObserveBall,
            HeadGoal::Scan,
            HeadGoal::ObserveGoal { side: GoalSide::Own },
            HeadGoal::ObserveGoal { side: GoalSide::Opponent },
            HeadGoal::ObserveFieldLine { line: 1 },
            HeadGoal::ObserveRival { player: 0 },
            HeadGoal::ObserveLandmark { name: "nothing".into() },
            HeadGoal::ObserveTogether { objects: vec![BALL.into(), names[3].clone()] },
        ];
        goals.extend(names.iter().map(|n| HeadGoal::ObserveLandmark { name: n.clone() }));
        let head = HeadActivation { fov: 1.0 };
        let percepts = Percepts::default();
        let actuation = ActuationStatus::default();
        for lost in [false, true] {
            world.pose.lost = lost;
            for world in [Some(&world), None] {
                let input = ReactiveInput {
                    now: Time::ZERO,
                    percepts: &percepts,
                    world,
                    actuation: &actuation,
                    stability: Stability::Stable,
                };
                for goal in &goals {
                    let scored = GoalScore::new(goal.clone(), 0.7);
                    let (score, primitives) = head.assess(&scored, &input);
                    assert_eq!(score.to_bits(), head.reactive_score(&scored, &input).to_bits());
                    assert_eq!(primitives, head.primitives_for(goal, &input), "{goal:?}");
                }
            }
        }
    }
}
