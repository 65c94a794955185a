//! Deliberative behaviors of the patrol (paper 3.4), organised as a hierarchical state machine
//! whose states are single behaviors or behavior trees:
//!
//! ```text
//! Patrolling: Patrol (walk the beat) → Inspect (tree: approach viewpoint / observe / record)
//!             → Return (back to the route) → Patrol ...
//! Responding (tree: watch the intruder when on site / go to the alarm)
//! Localizing (the pose is lost)    Recovering (fallen or falling: the reflexes act)
//! ```
//!
//! Every behavior sets a goal for each resource: the body's directly (along a path planned on
//! the floor plan's roadmap), the head's through its value function and active vision (3.6):
//! while walking the gaze serves the route (landmarks), while inspecting it trades looking at
//! the point of interest against looking at landmarks by "inspection quality".

use std::collections::BTreeSet;
use std::sync::Arc;
use std::time::Duration;

use serde::{Deserialize, Serialize};
use strata_robot::control::active_vision::{
    ActiveVision, ActiveVisionConfig, Criterion, GazeCandidate, ValueFunction,
};
use strata_robot::control::bt::{
    Status, Tree, action, condition, reactive_selector, reactive_sequence, sequence, timeout,
};
use strata_robot::control::deliberative::{
    DeliberativeInput, DeliberativeOutput, DeliberativePolicy,
};
use strata_robot::control::hsm::{BuildError, State, StateMachine};
use strata_robot::control::planning_module::PlanningDecision;
use strata_robot::control::reactive::Stability;
use strata_robot::control::scores::{GoalScore, ScoreVector};
use strata_robot::geometry::{Global, Point, Pose};
use strata_robot::world::{ObjectId, WorldState};
use strata_runtime::Time;

use crate::building::{FloorPlan, Waypoint};
use crate::console::{OperatorDirective, max_sigma};
use crate::goals::{BodyGoal, HeadGoal, WholeBodyGoal};
use crate::planning::{Mission, Role};
use crate::value::{InspectionQuality, RouteValue};
use crate::world_config::{INTRUDER, landmark_groups, poi_name};

/// What the planning layer sends the patrol's deliberative layer.
pub type Decision = PlanningDecision<Mission, Role, OperatorDirective>;
pub type Output = DeliberativeOutput<HeadGoal, BodyGoal, WholeBodyGoal>;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BehaviorConfig {
    /// A waypoint is reached within this distance, m.
    pub arrival: f64,
    /// An inspection is complete when the point's field position is known this well (the
    /// larger standard deviation, pose uncertainty included), m ...
    pub inspection_sigma: f64,
    /// ... after looking for at least this long, s.
    pub min_observation: f64,
    /// Give up on an inspection after this long observing, s, or approaching, s.
    pub observation_timeout: f64,
    pub approach_timeout: f64,
    /// The responder is on site within this distance of the alarm, m.
    pub on_site: f64,
    /// Landmarks farther than this are no gaze candidates, m.
    pub gaze_range: f64,
}

impl Default for BehaviorConfig {
    fn default() -> Self {
        BehaviorConfig {
            arrival: 0.3,
            inspection_sigma: 0.1,
            min_observation: 4.0,
            observation_timeout: 25.0,
            approach_timeout: 60.0,
            on_site: 0.9,
            gaze_range: 6.0,
        }
    }
}

/// The context the state machine and its trees run on.
pub struct Ctx {
    now: Time,
    world: Option<WorldState>,
    decision: Option<Decision>,
    stability: Stability,
    plan: Arc<FloorPlan>,
    beat: Vec<Waypoint>,
    config: BehaviorConfig,
    /// The waypoint of the beat being walked to.
    next: usize,
    /// Points of interest inspected in the current lap of the beat.
    lap_inspected: BTreeSet<usize>,
    /// The point of interest to inspect now.
    pending: Option<usize>,
    observing_since: Option<Time>,
    landmark_groups: Vec<String>,
    vision: ActiveVision,
    out: Output,
}

impl std::fmt::Debug for Ctx {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ctx")
            .field("now", &self.now)
            .field("next", &self.next)
            .field("pending", &self.pending)
            .finish_non_exhaustive()
    }
}

impl Ctx {
    fn pose(&self) -> Option<Pose> {
        self.world.as_ref().filter(|w| !w.pose.lost).map(|w| w.pose.pose)
    }

    fn lost(&self) -> bool {
        self.world.as_ref().is_some_and(|w| w.pose.lost)
    }

    fn alarm_point(&self) -> Option<Point<Global>> {
        self.decision.as_ref()?.directive.alarm.map(|a| a.point)
    }

    /// Whether this robot answers the alarm: the planning layer made it the responder, or it
    /// hears no teammate to share the work with.
    fn responding(&self) -> bool {
        self.decision.as_ref().is_some_and(|d| {
            d.directive.alarm.is_some()
                && (d.assignment.role == Role::Responder || d.assignment.alone)
        })
    }

    fn set_body(&mut self, goal: BodyGoal) {
        self.out.body = ScoreVector::single(goal);
    }

    fn object_id(&self, name: &str) -> Option<ObjectId> {
        self.world.as_ref()?.object(name).map(|o| o.id)
    }

    fn arrived(&self, target: Point<Global>) -> bool {
        self.pose().is_some_and(|p| p.position().distance(target) < self.config.arrival)
    }

    /// Walks toward `target` along the roadmap: the body's goal is the next point of the path.
    /// `heading` is the final heading when `stop`.
    fn go_to(&mut self, target: Point<Global>, heading: Option<f64>, stop: bool) {
        let Some(pose) = self.pose() else {
            self.set_body(BodyGoal::Stand);
            return;
        };
        let here = pose.position();
        let path = self.plan.route(here, target).unwrap_or_else(|| vec![target]);
        let goal = match path.as_slice() {
            [next, after, ..] => BodyGoal::GoToWaypoint {
                pose: Pose::new(next.x, next.y, (*after - *next).angle()),
                stop: false,
            },
            _ => {
                let theta = heading.unwrap_or_else(|| {
                    if here.distance(target) > 0.3 { (target - here).angle() } else { pose.theta }
                });
                BodyGoal::GoToWaypoint { pose: Pose::new(target.x, target.y, theta), stop }
            }
        };
        self.set_body(goal);
    }

    /// The head's score vector: landmarks in sight and the given objects, scored by the value
    /// function's active-vision evaluation. An object not seen yet cannot be evaluated (there
    /// is no estimate to improve): looking where the plan puts it gets the top score.
    fn gaze(
        &mut self,
        value: &dyn ValueFunction,
        criterion: Criterion,
        targets: &[(ObjectId, HeadGoal)],
    ) {
        let Some(world) = self.world.take() else {
            self.out.head = ScoreVector::single(HeadGoal::Scan);
            return;
        };
        let mut candidates: Vec<(GazeCandidate, HeadGoal, String)> = Vec::new();
        let mut unseen = Vec::new();
        for (id, goal) in targets {
            match world.get(*id) {
                Some(o) if o.tracked => candidates.push((
                    GazeCandidate {
                        label: o.name.to_string(),
                        direction: o.position.bearing(),
                        footprint: None,
                    },
                    goal.clone(),
                    o.name.to_string(),
                )),
                Some(o) => unseen.push(GoalScore::new(goal.clone(), 1.0).about(o.name.to_string())),
                None => {}
            }
        }
        if !world.pose.lost {
            let here = world.pose.pose.position();
            for group in &self.landmark_groups {
                for o in world.group(group) {
                    let at = o.map_position.unwrap_or(o.global_position);
                    // Only what the camera could see from here: in range, not behind a wall,
                    // within the neck's reach.
                    if here.distance(at) > self.config.gaze_range
                        || o.position.bearing().abs() > 2.2
                        || !self.plan.line_of_sight(here, at)
                    {
                        continue;
                    }
                    candidates.push((
                        GazeCandidate {
                            label: o.name.to_string(),
                            direction: o.position.bearing(),
                            footprint: None,
                        },
                        HeadGoal::ObserveLandmark { name: o.name.to_string() },
                        o.name.to_string(),
                    ));
                }
            }
        }
        let gazes: Vec<GazeCandidate> = candidates.iter().map(|(c, _, _)| c.clone()).collect();
        self.vision.config.criterion = criterion;
        let report = self.vision.evaluate(&world, value, &gazes);
        let mut head = ScoreVector::default();
        let scale = if unseen.is_empty() { 1.0 } else { 0.5 };
        for ((_, goal, name), evaluation) in candidates.into_iter().zip(&report.candidates) {
            head.push(GoalScore::new(goal, scale * evaluation.score).about(name));
        }
        for goal in unseen {
            head.push(goal);
        }
        // Something to do when no look is worth anything.
        head.push(GoalScore::new(HeadGoal::Scan, 0.05));
        self.out.head = head;
        self.world = Some(world);
    }

    fn route_gaze(&mut self, target: Point<Global>) {
        let value = RouteValue { target };
        self.gaze(&value, Criterion::MinExpectedValueVariance, &[]);
    }

    fn inspection_gaze(&mut self, poi: usize) {
        let Some(id) = self.object_id(&poi_name(poi)) else { return };
        let value = InspectionQuality {
            poi: id,
            nominal: self.plan.points_of_interest[poi].nominal,
            scale: 0.3,
        };
        let goal = HeadGoal::InspectPoint { poi: u8::try_from(poi).unwrap_or(u8::MAX) };
        self.gaze(&value, Criterion::MaxExpectedTaskValue, &[(id, goal)]);
    }
}

// ---------------------------------------------------------------------------------------------
// Behaviors

/// Patrol: walk the beat; a waypoint with a point of interest not inspected in this lap sends
/// the robot to inspect it.
fn patrol(ctx: &mut Ctx) -> Status {
    if ctx.pose().is_none() {
        ctx.set_body(BodyGoal::Stand);
        ctx.out.head = ScoreVector::single(HeadGoal::Scan);
        return Status::Running;
    }
    let waypoint = ctx.beat[ctx.next];
    if ctx.arrived(waypoint.position) {
        if let Some(k) = waypoint.inspect
            && !ctx.lap_inspected.contains(&k)
        {
            ctx.pending = Some(k);
            ctx.set_body(BodyGoal::Stand);
            return Status::Success;
        }
        ctx.next = (ctx.next + 1) % ctx.beat.len();
        if ctx.next == 0 {
            ctx.lap_inspected.clear();
        }
    }
    let target = ctx.beat[ctx.next].position;
    ctx.go_to(target, None, false);
    ctx.route_gaze(target);
    Status::Running
}

/// Approach viewpoint: walk to where the point is inspected from, facing it.
fn approach(ctx: &mut Ctx, now: Time) -> Status {
    let Some(k) = ctx.pending else { return Status::Failure };
    let viewpoint = ctx.plan.points_of_interest[k].viewpoint;
    ctx.go_to(viewpoint.position(), Some(viewpoint.theta), true);
    ctx.inspection_gaze(k);
    let facing = ctx.pose().is_some_and(|p| {
        p.position().distance(viewpoint.position()) < 0.15
            && strata_robot::normalize_angle(p.theta - viewpoint.theta).abs() < 0.25
    });
    if facing {
        ctx.observing_since = Some(now);
        return Status::Success;
    }
    Status::Running
}

/// Observe: stand and let active vision share the head between the point and the landmarks
/// until the point's field position is known well enough.
fn observe(ctx: &mut Ctx, now: Time) -> Status {
    let Some(k) = ctx.pending else { return Status::Failure };
    ctx.set_body(BodyGoal::Stand);
    ctx.inspection_gaze(k);
    let long_enough =
        ctx.observing_since.is_some_and(|t| (now - t).as_secs_f64() >= ctx.config.min_observation);
    let sharp = ctx.world.as_ref().is_some_and(|w| {
        !w.pose.lost
            && w.object(&poi_name(k)).is_some_and(|o| {
                o.known
                    && o.last_seen.is_some_and(|t| (w.stamp - t).as_secs_f64() < 1.0)
                    && max_sigma(&o.global_covariance) < ctx.config.inspection_sigma
            })
    });
    if long_enough && sharp { Status::Success } else { Status::Running }
}

/// Record: the inspection is done for this lap (the estimate itself goes to the operator in
/// the planning layer's status packets).
fn record(ctx: &mut Ctx) -> Status {
    if let Some(k) = ctx.pending {
        ctx.lap_inspected.insert(k);
    }
    Status::Success
}

/// Return: back to the route, at the waypoint the inspection (or the alarm, or the fall) took
/// the robot from.
fn return_to_route(ctx: &mut Ctx) -> Status {
    let target = ctx.beat[ctx.next].position;
    if ctx.arrived(target) {
        ctx.set_body(BodyGoal::Stand);
        return Status::Success;
    }
    ctx.go_to(target, None, false);
    ctx.route_gaze(target);
    Status::Running
}

fn on_site(ctx: &Ctx) -> bool {
    match (ctx.alarm_point(), ctx.pose()) {
        (Some(point), Some(pose)) => pose.position().distance(point) < ctx.config.on_site,
        _ => false,
    }
}

/// Go to alarm: along the roadmap, looking where the route needs.
fn go_to_alarm(ctx: &mut Ctx) -> Status {
    let Some(point) = ctx.alarm_point() else { return Status::Failure };
    ctx.go_to(point, None, true);
    ctx.route_gaze(point);
    if let Some(intruder) = ctx.world.as_ref().and_then(|w| w.object(INTRUDER)).filter(|o| o.known)
    {
        ctx.out
            .head
            .push(GoalScore::new(HeadGoal::ObserveIntruder, 0.6).about(intruder.name.clone()));
    }
    Status::Running
}

/// Watch: on site, face and follow whoever is there; look at the spot until someone is seen.
fn watch(ctx: &mut Ctx) -> Status {
    let Some(point) = ctx.alarm_point() else { return Status::Failure };
    let intruder = ctx
        .world
        .as_ref()
        .and_then(|w| w.object(INTRUDER))
        .filter(|o| o.known)
        .map(|o| o.global_position);
    match (intruder, ctx.pose()) {
        (Some(person), Some(pose)) => {
            let here = pose.position();
            ctx.set_body(BodyGoal::GoToWaypoint {
                pose: Pose::new(here.x, here.y, (person - here).angle()),
                stop: true,
            });
            ctx.out.head = ScoreVector::single(HeadGoal::ObserveIntruder)
                .with(GoalScore::new(HeadGoal::Scan, 0.1));
        }
        _ => {
            ctx.set_body(BodyGoal::Stand);
            ctx.out.head = ScoreVector::default()
                .with(GoalScore::new(HeadGoal::ObserveIntruder, 0.8).about(INTRUDER))
                .with(GoalScore::new(HeadGoal::LookAt { target: point }, 0.7))
                .with(GoalScore::new(HeadGoal::Scan, 0.4));
        }
    }
    Status::Running
}

/// Localizing (the pose is lost): stand and sweep the head for landmarks.
fn localizing(ctx: &mut Ctx) -> Status {
    ctx.set_body(BodyGoal::Stand);
    ctx.out.head = ScoreVector::single(HeadGoal::Scan);
    Status::Running
}

/// Recovering: the reflexes of the head+body multiplexer act; the deliberative layer asks for
/// nothing.
fn recovering(ctx: &mut Ctx) -> Status {
    ctx.set_body(BodyGoal::Stand);
    ctx.out.head = ScoreVector::single(HeadGoal::Scan);
    Status::Running
}

// ---------------------------------------------------------------------------------------------
// The machine

/// The states of the machine.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum S {
    Patrolling,
    Patrol,
    Inspect,
    Return,
    Responding,
    Localizing,
    Recovering,
}

fn unstable(ctx: &Ctx, _: Status) -> bool {
    !ctx.stability.is_stable()
}

fn lost(ctx: &Ctx, _: Status) -> bool {
    ctx.lost()
}

fn build_machine(config: &BehaviorConfig) -> Result<StateMachine<S, Ctx>, BuildError<S>> {
    let approach_limit = Duration::from_secs_f64(config.approach_timeout);
    let observe_limit = Duration::from_secs_f64(config.observation_timeout);
    StateMachine::builder()
        .initial(S::Patrolling)
        .state(
            State::new(S::Patrolling)
                .initial_child(S::Patrol)
                .transition(unstable, S::Recovering)
                .transition(lost, S::Localizing)
                .transition(|ctx: &Ctx, _| ctx.responding(), S::Responding),
        )
        .state(
            State::new(S::Patrol)
                .parent(S::Patrolling)
                .behavior(|ctx: &mut Ctx, _| patrol(ctx))
                .transition(|ctx: &Ctx, _| ctx.pending.is_some(), S::Inspect),
        )
        .state(
            State::new(S::Inspect)
                .parent(S::Patrolling)
                .tree(Tree::new(sequence(
                    "inspect",
                    [
                        timeout(approach_limit, action("approach viewpoint", approach))
                            .named("approach viewpoint"),
                        timeout(observe_limit, action("observe", observe)).named("observe"),
                        action("record", |ctx: &mut Ctx, _| record(ctx)),
                    ],
                )))
                .on_exit(|ctx: &mut Ctx, _| {
                    // Done or given up: either way not again in this lap.
                    if let Some(k) = ctx.pending.take() {
                        ctx.lap_inspected.insert(k);
                    }
                    ctx.observing_since = None;
                })
                .transition(|_, status| status.is_finished(), S::Return),
        )
        .state(
            State::new(S::Return)
                .parent(S::Patrolling)
                .behavior(|ctx: &mut Ctx, _| return_to_route(ctx))
                .transition(|_, status| status == Status::Success, S::Patrol),
        )
        .state(
            State::new(S::Responding)
                .tree(Tree::new(reactive_selector(
                    "respond",
                    [
                        // Re-checked every tick: a robot pushed or re-localized away from the
                        // alarm goes back instead of watching from the wrong place.
                        reactive_sequence(
                            "on site",
                            [
                                condition("at the alarm", on_site),
                                action("watch", |ctx: &mut Ctx, _| watch(ctx)),
                            ],
                        ),
                        action("go to alarm", |ctx: &mut Ctx, _| go_to_alarm(ctx)),
                    ],
                )))
                .transition(unstable, S::Recovering)
                .transition(lost, S::Localizing)
                .transition(|ctx: &Ctx, _| !ctx.responding(), S::Return),
        )
        .state(
            State::new(S::Localizing)
                .behavior(|ctx: &mut Ctx, _| localizing(ctx))
                .transition(unstable, S::Recovering)
                .transition(|ctx: &Ctx, _| !ctx.lost(), S::Return),
        )
        .state(
            State::new(S::Recovering)
                .behavior(|ctx: &mut Ctx, _| recovering(ctx))
                .transition(|ctx: &Ctx, _| ctx.stability.is_stable(), S::Return),
        )
        .build()
}

/// The patrol's deliberative layer.
pub struct PatrolBehavior {
    machine: StateMachine<S, Ctx>,
    ctx: Ctx,
}

impl std::fmt::Debug for PatrolBehavior {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PatrolBehavior")
            .field("path", &self.machine.active_path())
            .finish_non_exhaustive()
    }
}

impl PatrolBehavior {
    pub fn new(
        player: u8,
        plan: Arc<FloorPlan>,
        config: BehaviorConfig,
        vision: ActiveVisionConfig,
    ) -> Result<PatrolBehavior, BuildError<S>> {
        let machine = build_machine(&config)?;
        let beat = plan.beat(player).to_vec();
        let groups = landmark_groups(&plan);
        Ok(PatrolBehavior {
            machine,
            ctx: Ctx {
                now: Time::ZERO,
                world: None,
                decision: None,
                stability: Stability::Stable,
                plan,
                beat,
                config,
                next: 0,
                lap_inspected: BTreeSet::new(),
                pending: None,
                observing_since: None,
                landmark_groups: groups,
                vision: ActiveVision::new(vision),
                out: Output::default(),
            },
        })
    }

    pub fn active_path(&self) -> String {
        self.machine.active_path()
    }
}

/// The waypoint a behavior path names (`"... [waypoint 3]"`), if any.
pub fn waypoint_of_path(path: &str) -> Option<usize> {
    let start = path.rfind("[waypoint ")? + "[waypoint ".len();
    path[start..].strip_suffix(']')?.parse().ok()
}

impl DeliberativePolicy for PatrolBehavior {
    type HeadGoal = HeadGoal;
    type BodyGoal = BodyGoal;
    type WholeBodyGoal = WholeBodyGoal;
    type World = WorldState;
    type Assignment = Decision;

    fn tick(&mut self, input: &DeliberativeInput<'_, WorldState, Decision>) -> Output {
        let ctx = &mut self.ctx;
        ctx.now = input.now;
        ctx.world = input.world.cloned();
        ctx.decision = input.assignment.cloned();
        ctx.stability = input.stability;
        ctx.out = Output::default();
        self.machine.tick(&mut self.ctx, input.now);
        let mut out = std::mem::take(&mut self.ctx.out);
        // The waypoint being walked to is part of the path: the log shows the beat's order.
        out.behavior_path = format!("{} [waypoint {}]", self.machine.active_path(), self.ctx.next);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_machine_builds_and_paths_name_their_waypoint() {
        assert!(build_machine(&BehaviorConfig::default()).is_ok());
        assert_eq!(waypoint_of_path("Patrolling/Patrol [waypoint 3]"), Some(3));
        assert_eq!(waypoint_of_path("Patrolling/Patrol"), None);
    }

    #[test]
    fn without_a_world_the_robot_stands_and_scans() {
        let plan = Arc::new(FloorPlan::office());
        let mut behavior =
            PatrolBehavior::new(1, plan, BehaviorConfig::default(), ActiveVisionConfig::default())
                .expect("machine");
        let out = behavior.tick(&DeliberativeInput {
            now: Time::ZERO,
            world: None,
            assignment: None,
            stability: Stability::Stable,
        });
        assert_eq!(out.body, ScoreVector::single(BodyGoal::Stand));
        assert_eq!(out.behavior_path, "Patrolling/Patrol [waypoint 0]");
    }
}
