//! Team fusion (MAWM): teammates' ball estimates fused with the own one; an outlier teammate
//! cannot pull the team ball away.

mod world_support;

use nalgebra::{Matrix2, Matrix3};
use strata_robot::geometry::{Global, Odometry, Point, Pose};
use strata_robot::percept::{CameraPercepts, Observation, Percepts, ViewCone};
use strata_robot::world::{PosePrior, SharedObject, TeammateEstimate, WorldModel};
use strata_runtime::Time;
use world_support::{BALL, config};

const POSE: Pose = Pose { x: -1.0, y: 0.0, theta: 0.0 };

fn ball_percepts(t: f64, ball: Point<Global>) -> Percepts {
    let p = POSE.to_robot(ball);
    let stamp = Time::from_secs_f64(t);
    Percepts {
        stamp,
        camera: Some(CameraPercepts {
            stamp,
            view: ViewCone { direction: 0.0, fov: 1.0, range: 6.0, near: 0.0 },
            observations: vec![Observation {
                class: BALL,
                variant: None,
                range: p.range(),
                bearing: p.bearing(),
                orientation: None,
                range_sigma: 0.1,
                bearing_sigma: 0.03,
            }],
        }),
        ..Percepts::default()
    }
}

fn teammate(
    player: u8,
    t: f64,
    ball: (f64, f64),
    variance: f64,
    pose_confidence: f64,
) -> TeammateEstimate {
    TeammateEstimate {
        member: player,
        stamp: Time::from_secs_f64(t),
        pose: Pose::new(0.0, 0.0, 0.0),
        pose_covariance: Matrix3::identity() * 0.01,
        pose_confidence,
        objects: vec![SharedObject {
            class: BALL,
            variant: None,
            position: Point::new(ball.0, ball.1),
            velocity: None,
            covariance: Matrix2::identity() * variance,
            confidence: 0.9,
            age: 0.0,
        }],
    }
}

fn world_seeing_ball(ball: Point<Global>) -> WorldModel {
    let prior = PosePrior { pose: POSE, sigma: [0.05, 0.05, 0.02] };
    let mut world = WorldModel::new(config(Some(prior))).expect("valid config");
    for k in 0..10 {
        world.process(Odometry::ZERO, &ball_percepts(0.1 * f64::from(k), ball));
    }
    world
}

#[test]
fn an_outlier_teammate_cannot_pull_the_team_ball() {
    let ball = Point::new(1.0, 0.5);
    let mut world = world_seeing_ball(ball);
    world.add_teammate_estimate(teammate(2, 0.9, (1.05, 0.45), 0.04, 0.9)).expect("valid");
    world.add_teammate_estimate(teammate(3, 0.9, (0.95, 0.55), 0.04, 0.8)).expect("valid");
    // A confident, wildly wrong teammate (mislocalized on the other half).
    world.add_teammate_estimate(teammate(4, 0.9, (-3.0, 2.0), 0.0004, 1.0)).expect("valid");
    world.process(Odometry::ZERO, &ball_percepts(1.0, ball));
    let state = world.state();
    let team = state.team_object("ball").expect("a team ball");
    assert!(team.position.distance(ball) < 0.1, "team ball at {:?}", team.position);
    assert!(team.includes_own);
    assert_eq!(team.teammates, vec![2, 3]);
    assert_eq!(team.rejected, vec![4]);
    let own = state.object("ball").expect("configured");
    assert!(team.covariance.trace() < own.global_covariance.trace(), "fusion adds information");
}

#[test]
fn a_single_wild_teammate_does_not_replace_the_own_estimate_but_two_agreeing_ones_do() {
    let ball = Point::new(1.0, 0.5);
    let mut world = world_seeing_ball(ball);
    world.add_teammate_estimate(teammate(5, 0.9, (3.0, -2.0), 0.0004, 1.0)).expect("valid");
    world.process(Odometry::ZERO, &ball_percepts(1.0, ball));
    let team = world.state().team_object("ball").expect("a team ball").clone();
    assert!(team.position.distance(ball) < 0.1, "{:?}", team.position);
    assert_eq!(team.rejected, vec![5]);
    // Two teammates agree with each other, not with this robot: they outvote it.
    world.add_teammate_estimate(teammate(6, 1.0, (3.02, -1.98), 0.01, 1.0)).expect("valid");
    world.process(Odometry::ZERO, &ball_percepts(1.1, ball));
    let team = world.state().team_object("ball").expect("a team ball").clone();
    assert!(team.position.distance(Point::new(3.0, -2.0)) < 0.1, "{:?}", team.position);
    assert!(!team.includes_own);
}

#[test]
fn pose_confidence_and_age_weigh_the_estimates() {
    // No own ball: two teammates, one sure of its pose, one not.
    let prior = PosePrior { pose: POSE, sigma: [0.05, 0.05, 0.02] };
    let mut world = WorldModel::new(config(Some(prior))).expect("valid config");
    world.add_teammate_estimate(teammate(2, 0.0, (2.0, 0.0), 0.04, 1.0)).expect("valid");
    world.add_teammate_estimate(teammate(3, 0.0, (2.3, 0.0), 0.04, 0.25)).expect("valid");
    world.process(
        Odometry::ZERO,
        &Percepts { stamp: Time::from_secs_f64(0.1), ..Percepts::default() },
    );
    let team = world.state().team_object("ball").expect("a team ball").clone();
    // Weights 1 and 0.25: the fused x is (2.0 * 1 + 2.3 * 0.25) / 1.25 = 2.06 (plus ageing).
    assert!((team.position.x - 2.06).abs() < 0.01, "{:?}", team.position);
    // Estimates older than the configured age are dropped.
    world.process(
        Odometry::ZERO,
        &Percepts { stamp: Time::from_secs_f64(5.0), ..Percepts::default() },
    );
    assert!(world.state().team_object("ball").is_none());
}

#[test]
fn malformed_teammate_estimates_are_refused() {
    let mut world = world_seeing_ball(Point::new(1.0, 0.5));
    let mut bad = teammate(2, 0.9, (1.0, 0.5), 0.04, 0.9);
    bad.objects[0].position = Point::new(f64::NAN, 0.0);
    let error = world.add_teammate_estimate(bad).expect_err("a NaN position");
    assert_eq!(error.field, "objects[0].position");
    let mut bad = teammate(2, 0.9, (1.0, 0.5), 0.04, 1.5);
    bad.pose_confidence = 1.5;
    assert_eq!(
        world.add_teammate_estimate(bad).expect_err("a confidence > 1").field,
        "pose_confidence"
    );
    let mut bad = teammate(2, 0.9, (1.0, 0.5), 0.04, 0.9);
    bad.objects[0].covariance = Matrix2::new(0.04, 0.0, 1.0, 0.04);
    assert!(world.add_teammate_estimate(bad).is_err());
    assert_eq!(world.diagnostics().team_rejected, 3);
}

#[test]
fn shared_estimates_round_trip_between_world_models() {
    let ball = Point::new(1.0, 0.5);
    let sender = world_seeing_ball(ball);
    let shared = sender.state().to_shared(7);
    assert_eq!(shared.objects.len(), 1);
    shared.validate().expect("a valid message");
    let prior = PosePrior { pose: Pose::new(2.0, 2.0, -1.0), sigma: [0.05, 0.05, 0.02] };
    let mut receiver = WorldModel::new(config(Some(prior))).expect("valid config");
    receiver.add_teammate_estimate(shared).expect("valid");
    receiver.process(
        Odometry::ZERO,
        &Percepts { stamp: Time::from_secs_f64(1.0), ..Percepts::default() },
    );
    let team = receiver.state().team_object("ball").expect("a team ball").clone();
    assert!(team.position.distance(ball) < 0.1);
    assert_eq!(team.teammates, vec![7]);
}
