//! Costs of the hybrid control's layers on the soccer application, each against a baseline
//! measured in the same run:
//! - one reactive cycle (3 multiplexers, 12 primitive behaviors) against the same three
//!   multiplexers with trivial policies (the architecture's own overhead);
//! - one active-vision evaluation over 8 gaze candidates against one expected update;
//! - one planning evaluation with 6 teammates against decoding their 6 messages.
//!
//! Run: `cargo bench -p strata-soccer --bench layers`

use std::hint::black_box;
use std::sync::Arc;
use std::time::{Duration, Instant};

use strata_robot::command::{HeadCommand, ResourceGroup};
use strata_robot::control::active_vision::{ActiveVision, ActiveVisionConfig, GazeCandidate};
use strata_robot::control::planning::{
    OwnState, Planner, PlanningConfig, SharedObject, StandingStatus,
};
use strata_robot::control::reactive::{
    ActivationPolicy, FallDetectorConfig, Multiplexer, MultiplexerConfig, PrimitiveBehavior,
    ReactiveInput, ReactiveLayer,
};
use strata_robot::control::scores::{Goal, GoalScore, PrimitiveId, ScoreVector};
use strata_robot::geometry::{Point, Pose, Velocity};
use strata_robot::percept::{CameraPercepts, Observation, Percepts, ViewCone};
use strata_robot::platform::{ObjectClass, PlatformInfo};
use strata_robot::world::{PosePrior, WorldCommand, WorldModel, WorldState};
use strata_runtime::Time;
use strata_soccer::catalog::{Mission, Role};
use strata_soccer::field::TeamField;
use strata_soccer::goals::{BodyGoal, HeadGoal, Kick, WholeBodyGoal};
use strata_soccer::message;
use strata_soccer::planning::{SoccerPlanning, SoccerPlanningConfig};
use strata_soccer::team::{TeamConfig, reactive_layer};
use strata_soccer::value::GoalCoveringValue;
use strata_soccer::world_config::{BALL, world_config};
use strata_spl::ObjectKind;

fn info() -> PlatformInfo {
    PlatformInfo {
        name: "bench".into(),
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

/// A goalkeeper's world state after a second of seeing the ball and two goal posts.
fn world(field: &TeamField) -> WorldState {
    let mut model = WorldModel::new(world_config(field)).expect("valid config");
    let pose = Pose::new(-4.0, 0.3, 0.2);
    let _ =
        model.command(WorldCommand::SetPose { prior: PosePrior { pose, sigma: [0.1, 0.1, 0.05] } });
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
    for frame in 0..30u64 {
        let percepts = Percepts {
            stamp: Time::from_nanos(frame * 33_000_000),
            camera: Some(CameraPercepts {
                stamp: Time::from_nanos(frame * 33_000_000),
                view: ViewCone { direction: 0.0, fov: 1.06, range: 6.0, near: 0.0 },
                observations: vec![
                    observe(ObjectKind::Ball, Point::new(-2.0, 0.8)),
                    observe(ObjectKind::GoalPost, Point::new(4.525, 0.8)),
                    observe(ObjectKind::GoalPost, Point::new(4.525, -0.8)),
                ],
            }),
            ..Percepts::default()
        };
        model.process(strata_robot::Odometry::ZERO, &percepts);
    }
    model.state()
}

/// The median time per call of `f`, over `rounds` timed batches.
fn measure(mut f: impl FnMut(), batch: u32, rounds: usize) -> f64 {
    for _ in 0..batch {
        f();
    }
    let mut samples: Vec<f64> = (0..rounds)
        .map(|_| {
            let start = Instant::now();
            for _ in 0..batch {
                f();
            }
            start.elapsed().as_nanos() as f64 / f64::from(batch)
        })
        .collect();
    samples.sort_by(f64::total_cmp);
    samples[samples.len() / 2]
}

/// The multiplexer machinery with policies that do nothing: the baseline. Its one primitive
/// takes the goal type's first id.
struct Null;
impl<G: Goal> ActivationPolicy<G, WorldState> for Null {
    fn reactive_score(&self, _: &GoalScore<G>, _: &ReactiveInput<'_, WorldState>) -> f64 {
        0.5
    }
    fn primitives_for(&self, _: &G, _: &ReactiveInput<'_, WorldState>) -> &'static [G::Primitive] {
        G::Primitive::ALL.get(..1).unwrap_or_default()
    }
}
struct NullPrimitive;
impl<G: Goal, C> PrimitiveBehavior<G, C, WorldState> for NullPrimitive {
    fn id(&self) -> G::Primitive {
        G::Primitive::ALL[0]
    }
    fn step(&mut self, _: &G, _: &ReactiveInput<'_, WorldState>) -> Option<C> {
        None
    }
}

fn main() {
    let quick = !std::env::args().any(|a| a == "--bench");
    let (batch, rounds) = if quick { (10, 3) } else { (2000, 15) };
    let field = Arc::new(TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0));
    let world = world(&field);
    let (reactive, reactive_base) = reactive_cycle(&field, &world, batch, rounds);
    let (evaluation, update_base) = active_vision(&field, &world, batch, rounds);
    let (planning, decode_base) = planning_evaluation(&field, batch, rounds);

    if quick {
        println!("layers: smoke run ok");
        return;
    }
    println!("Hybrid control layers on the soccer application (median per call)");
    println!(
        "  reactive cycle (3 multiplexers, 12 primitives): {:>8.2} us   target <= 10 us   {:.1}x the bare multiplexer machinery ({:.2} us)",
        reactive / 1e3,
        reactive / reactive_base,
        reactive_base / 1e3
    );
    println!(
        "  active vision, 8 candidates:                     {:>8.2} us   target <= 100 us  {:.1}x one expected update ({:.2} us)",
        evaluation / 1e3,
        evaluation / update_base,
        update_base / 1e3
    );
    println!(
        "  planning evaluation, 6 teammates:                {:>8.2} us   target <= 20 us   {:.1}x decoding their 6 messages ({:.2} us)",
        planning / 1e3,
        planning / decode_base,
        decode_base / 1e3
    );
}

/// The soccer reactive cycle, and the bare multiplexer machinery under the same goals (ns).
fn reactive_cycle(
    field: &Arc<TeamField>,
    world: &WorldState,
    batch: u32,
    rounds: usize,
) -> (f64, f64) {
    let percepts = Percepts { stamp: Time::from_secs_f64(1.0), ..Percepts::default() };
    let config = TeamConfig::default();
    let mut soccer = reactive_layer(&config, &info(), field);
    let head_goals = ScoreVector::default()
        .with(GoalScore::new(HeadGoal::ObserveBall, 0.8).about(BALL))
        .with(
            GoalScore::new(HeadGoal::ObserveLandmark { name: "goal_post#0".into() }, 0.5)
                .about("goal_post#0"),
        )
        .with(
            GoalScore::new(HeadGoal::ObserveLandmark { name: "goal_post#1".into() }, 0.4)
                .about("goal_post#1"),
        )
        .with(GoalScore::new(
            HeadGoal::ObserveTogether { objects: vec![BALL.into(), "goal_post#1".into()] },
            0.6,
        ));
    let body_goals = ScoreVector::single(BodyGoal::GoToBallAndKick {
        kick: Kick::Forward,
        target: field.opponent_goal(),
    });
    soccer.head.set_scores(head_goals.clone(), &Default::default(), Time::ZERO);
    soccer.body.set_scores(body_goals.clone(), &Default::default(), Time::ZERO);
    let mut t = 0u64;
    let reactive = measure(
        || {
            t += 12_000_000;
            black_box(soccer.step(Time::from_nanos(t), &percepts, Some(world)));
        },
        batch,
        rounds,
    );
    let mut null: ReactiveLayer<HeadGoal, BodyGoal, WholeBodyGoal, WorldState> = ReactiveLayer::new(
        Multiplexer::new(ResourceGroup::Head, MultiplexerConfig::default(), Box::new(Null))
            .with_primitive(Box::new(NullPrimitive)
                as Box<dyn PrimitiveBehavior<HeadGoal, HeadCommand, WorldState>>),
        Multiplexer::new(ResourceGroup::Body, MultiplexerConfig::default(), Box::new(Null))
            .with_primitive(Box::new(NullPrimitive)),
        Multiplexer::new(ResourceGroup::HeadAndBody, MultiplexerConfig::default(), Box::new(Null))
            .with_primitive(Box::new(NullPrimitive)),
        FallDetectorConfig::default(),
    );
    null.head.set_scores(head_goals, &Default::default(), Time::ZERO);
    null.body.set_scores(body_goals, &Default::default(), Time::ZERO);
    let reactive_base = measure(
        || {
            black_box(null.step(Time::ZERO, &percepts, Some(world)));
        },
        batch,
        rounds,
    );

    (reactive, reactive_base)
}

/// Active vision over 8 candidates, and one expected update (ns).
fn active_vision(
    field: &Arc<TeamField>,
    world: &WorldState,
    batch: u32,
    rounds: usize,
) -> (f64, f64) {
    let ball = world.object(BALL).expect("ball").id;
    let value = GoalCoveringValue { field: Arc::clone(field), ball, reach: 0.3 };
    let mut vision = ActiveVision::new(ActiveVisionConfig::default());
    let candidates: Vec<GazeCandidate> = (0..8)
        .map(|i| GazeCandidate {
            label: format!("c{i}"),
            direction: -1.6 + 0.45 * f64::from(i),
            footprint: None,
        })
        .collect();
    let evaluation = measure(
        || {
            black_box(vision.evaluate(world, &value, &candidates));
        },
        batch / 10 + 1,
        rounds,
    );
    let view = ViewCone { direction: 0.4, fov: 1.06, range: 6.0, near: 0.0 };
    let sensing = world.sensing_candidate(&view, 0.05);
    let update_base = measure(
        || {
            black_box(world.expected_update(&sensing));
        },
        batch,
        rounds,
    );

    (evaluation, update_base)
}

/// Planning with 6 teammates, and decoding their messages (ns).
fn planning_evaluation(field: &Arc<TeamField>, batch: u32, rounds: usize) -> (f64, f64) {
    let mut planner = Planner::new(
        SoccerPlanning::new((**field).clone(), SoccerPlanningConfig::default()),
        PlanningConfig::default(),
    );
    let ball_at = |x: f64| {
        vec![SharedObject {
            name: BALL.into(),
            position: Point::new(x, 0.0),
            sigma: 0.1,
            confidence: 0.9,
            age: 0.2,
        }]
    };
    let own = OwnState {
        id: 2,
        status: StandingStatus::Stable,
        penalized: false,
        localized: true,
        pose: Pose::new(-1.0, 0.5, 0.0),
        pose_confidence: 0.9,
        objects: ball_at(0.5),
    };
    let messages: Vec<Vec<u8>> = (3..=8u8)
        .map(|id| {
            let m = strata_robot::control::planning::TeamMessage {
                sender: id,
                mission: Mission::Attack,
                role: Role::StrikerCover,
                status: StandingStatus::Stable,
                penalized: false,
                localized: true,
                since_last_received: 0.5,
                data_received: true,
                utility: -3.0,
                conflict: false,
                pose: Pose::new(-2.0 + f64::from(id) * 0.3, 1.0, 0.0),
                pose_confidence: 0.8,
                objects: ball_at(0.6),
                signal: None,
            };
            message::encode(&m).expect("encodes")
        })
        .collect();
    for (i, bytes) in messages.iter().enumerate() {
        planner
            .receive(Time::from_secs_f64(0.1 * i as f64), message::decode(bytes).expect("decodes"));
    }
    let mut now = 1.0;
    let planning = measure(
        || {
            now += 0.1;
            black_box(planner.evaluate(Time::from_secs_f64(now), own.clone()));
        },
        batch,
        rounds,
    );
    let decode_base = measure(
        || {
            for bytes in &messages {
                black_box(message::decode(bytes).ok());
            }
        },
        batch,
        rounds,
    );

    (planning, decode_base)
}
