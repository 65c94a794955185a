//! The reactive layer's shortcuts on soccer's activation policies give the plain answers: the
//! head policy's noted objects against lookups by name, and cycles that reuse answers on one
//! world state against cycles that ask every time.

use std::sync::Arc;
use std::time::Duration;

use strata_robot::command::{ActuationMessage, Resource};
use strata_robot::control::reactive::{
    ActivationPolicy, ActivationShortcuts, ActuationStatus, GoalNotes, ReactiveInput, Stability,
};
use strata_robot::control::scores::{GoalScore, ScoreVector};
use strata_robot::geometry::{Point, Pose, Velocity};
use strata_robot::percept::{CameraPercepts, Observation, Percepts, ViewCone};
use strata_robot::platform::{ObjectClass, PlatformInfo};
use strata_robot::world::{ObjectEstimate, PosePrior, WorldCommand, WorldModel, WorldState};
use strata_runtime::Time;
use strata_soccer::activation::HeadActivation;
use strata_soccer::field::TeamField;
use strata_soccer::goals::{BodyGoal, GoalSide, HeadGoal, Kick, WholeBodyGoal};
use strata_soccer::team::{TeamConfig, reactive_layer};
use strata_soccer::world_config::{BALL, world_config};
use strata_spl::ObjectKind;

fn field() -> Arc<TeamField> {
    Arc::new(TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0))
}

fn info() -> PlatformInfo {
    PlatformInfo {
        name: "test".into(),
        sensor_period: Duration::from_millis(12),
        camera_fov: 1.06,
        camera_range: 6.0,
        head_yaw_limits: (-2.0, 2.0),
        head_pitch_limits: (-0.6, 0.5),
        max_head_speed: 4.0,
        max_velocity: Velocity::new(0.25, 0.15, 1.2),
        motions: Vec::new(),
        can_walk: true,
    }
}

/// Consecutive world states of one model (one layout): the ball rolls across the view, two
/// goal posts and a robot are seen, then nothing for a while (confidence fades).
fn states(field: &TeamField) -> Vec<WorldState> {
    let mut model = WorldModel::new(world_config(field)).expect("valid config");
    let pose = Pose::new(2.0, 0.3, 0.2);
    let _ =
        model.command(WorldCommand::SetPose { prior: PosePrior { pose, sigma: [0.1, 0.1, 0.05] } });
    let mut states = Vec::new();
    for frame in 0..60u64 {
        let observe = |class: ObjectKind, p: Point<strata_robot::Global>| {
            let r = pose.to_robot(p);
            Observation {
                class: ObjectClass(class.code()),
                variant: None,
                range: r.range(),
                bearing: r.bearing(),
                orientation: None,
                range_sigma: 0.1,
                bearing_sigma: 0.03,
            }
        };
        let ball = Point::new(3.0, -1.5 + 0.05 * frame as f64);
        let observations = if frame < 40 {
            vec![
                observe(ObjectKind::Ball, ball),
                observe(ObjectKind::GoalPost, Point::new(4.525, 0.8)),
                observe(ObjectKind::GoalPost, Point::new(4.525, -0.8)),
                observe(ObjectKind::Robot, Point::new(3.0, 0.3)),
            ]
        } else {
            Vec::new()
        };
        let stamp = Time::from_nanos(frame * 33_000_000);
        let view = ViewCone { direction: 0.0, fov: 1.06, range: 6.0, near: 0.0 };
        let camera = Some(CameraPercepts { stamp, view, observations });
        model.process(
            strata_robot::Odometry::ZERO,
            &Percepts { stamp, camera, ..Percepts::default() },
        );
        if frame % 4 == 3 {
            states.push(model.state());
        }
    }
    states
}

/// The same objects as `world` in another order, and read back without the name index.
fn replaced(world: &WorldState) -> [WorldState; 2] {
    let mut reversed = world.clone();
    reversed.objects = world.objects.iter().rev().cloned().collect::<Vec<ObjectEstimate>>().into();
    let mut bare = world.clone();
    bare.index = Default::default();
    [reversed, bare]
}

fn head_goals(world: &WorldState) -> Vec<HeadGoal> {
    let names: Vec<String> = world.objects.iter().map(|o| o.name.to_string()).collect();
    let groups: Vec<String> = world.objects.iter().map(|o| o.group.to_string()).collect();
    let mut goals = vec![
        HeadGoal::ObserveBall,
        HeadGoal::Scan,
        HeadGoal::ObserveGoal { side: GoalSide::Own },
        HeadGoal::ObserveGoal { side: GoalSide::Opponent },
        HeadGoal::ObserveFieldLine { line: 1 },
        HeadGoal::ObserveRival { player: 0 },
        HeadGoal::ObserveLandmark { name: "nothing".into() },
        HeadGoal::ObserveTogether { objects: vec![BALL.into(), "nothing".into()] },
        HeadGoal::ObserveTogether { objects: vec![] },
    ];
    for (name, group) in names.iter().zip(&groups) {
        goals.push(HeadGoal::ObserveLandmark { name: name.clone() });
        goals.push(HeadGoal::ObserveLandmark { name: group.clone() });
        goals.push(HeadGoal::ObserveTogether { objects: vec![BALL.into(), name.clone()] });
        goals.push(HeadGoal::ObserveTogether { objects: vec![BALL.into(), group.clone()] });
    }
    goals
}

#[test]
fn noted_head_objects_give_the_answers_of_lookups_by_name() {
    let field = field();
    let states = states(&field);
    let goals: Vec<GoalScore<HeadGoal>> =
        head_goals(&states[0]).into_iter().map(|g| GoalScore::new(g, 0.6)).collect();
    let head = HeadActivation { fov: 1.06 };
    let percepts = Percepts::default();
    let actuation = ActuationStatus::default();
    // Notes kept across states of one layout, states of another order or without an index,
    // and back.
    let mut sequence: Vec<WorldState> = states.clone();
    sequence.extend(replaced(&states[5]));
    sequence.push(states[6].clone());
    sequence.extend(replaced(&states[7]));
    sequence.push(states[3].clone());
    let mut lost = states[8].clone();
    lost.pose.lost = true;
    sequence.push(lost);
    let mut notes: Vec<GoalNotes> = goals.iter().map(|_| GoalNotes::default()).collect();
    for (i, world) in sequence.iter().enumerate() {
        let input = ReactiveInput {
            now: Time::ZERO,
            percepts: &percepts,
            world: Some(world),
            actuation: &actuation,
            stability: Stability::Stable,
        };
        for (goal, notes) in goals.iter().zip(&mut notes) {
            let split = head.split_noted(goal, notes, &input);
            assert_eq!(split, head.split(goal, &input), "state {i}: {:?}", goal.goal);
            let (score, primitives) = head.assess_noted(goal, notes, &input);
            let (plain_score, plain_primitives) = head.assess(goal, &input);
            assert_eq!(score.to_bits(), plain_score.to_bits(), "state {i}: {:?}", goal.goal);
            assert_eq!(primitives, plain_primitives, "state {i}: {:?}", goal.goal);
        }
    }
}

#[test]
fn cycles_on_numbered_world_states_decide_as_cycles_that_ask_every_time() {
    let field = field();
    let states = states(&field);
    let config = TeamConfig::default();
    let mut plain = reactive_layer(&config, &info(), &field);
    let mut numbered = reactive_layer(&config, &info(), &field);
    let names: Vec<String> = states[0].objects.iter().map(|o| o.name.to_string()).collect();
    let vectors = [
        ScoreVector::default()
            .with(GoalScore::new(HeadGoal::ObserveBall, 0.8).about(BALL))
            .with(
                GoalScore::new(HeadGoal::ObserveLandmark { name: names[3].clone() }, 0.5)
                    .about(names[3].clone()),
            )
            .with(GoalScore::new(
                HeadGoal::ObserveTogether { objects: vec![BALL.into(), names[4].clone()] },
                0.6,
            )),
        ScoreVector::default()
            .with(GoalScore::new(HeadGoal::ObserveGoal { side: GoalSide::Opponent }, 0.7))
            .with(GoalScore::new(
                HeadGoal::ObserveTogether { objects: vec![BALL.into(), names[5].clone()] },
                0.9,
            ))
            .with(GoalScore::new(HeadGoal::ObserveBall, 0.3).about(BALL)),
    ];
    let body = [
        ScoreVector::single(BodyGoal::GoToBallAndKick {
            kick: Kick::Forward,
            target: field.opponent_goal(),
        }),
        ScoreVector::single(BodyGoal::GoToPosition { pose: Pose::new(0.0, 0.0, 0.0) }),
    ];
    let whole =
        ScoreVector::single(WholeBodyGoal::GoToBallAndDribble { target: field.opponent_goal() });
    let mut upright = Percepts::default();
    upright.inertial.accelerometer = [0.0, 0.0, 9.81];
    let mut tipping = upright.clone();
    tipping.inertial.body_angles = [0.0, 0.4];
    tipping.inertial.gyroscope = [0.0, 2.0, 0.0];
    let mut lying = upright.clone();
    lying.inertial.body_angles = [0.0, 1.4];
    for cycle in 0..(3 * states.len()) {
        if cycle % 13 == 0 {
            let k = cycle / 13;
            for layer in [&mut plain, &mut numbered] {
                layer.head.set_scores(vectors[k % 2].clone(), &Default::default(), Time::ZERO);
                layer.body.set_scores(body[k % 2].clone(), &Default::default(), Time::ZERO);
                layer.whole_body.set_scores(whole.clone(), &Default::default(), Time::ZERO);
            }
        }
        let message = match cycle {
            10 => Some(ActuationMessage::ResourceBusy { resource: Resource::Head }),
            16 => Some(ActuationMessage::ResourceReleased { resource: Resource::Head }),
            _ => None,
        };
        if let Some(message) = message {
            plain.actuation_message(&message);
            numbered.actuation_message(&message);
        }
        let percepts = match cycle {
            12 | 13 => &tipping,
            14..=17 => &lying,
            _ => &upright,
        };
        // A new world state every third cycle.
        let revision = cycle / 3;
        let world = &states[revision];
        let now = Time::from_nanos(cycle as u64 * 12_000_000);
        let expected = plain.step(now, percepts, Some(world));
        let got = numbered.step_on_revision(now, percepts, Some(world), revision as u64);
        assert_eq!(got, expected, "cycle {cycle}");
    }
}
