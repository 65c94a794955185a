//! Object and pose filters against hand-computed values, and the expected update of active
//! vision against real updates.

mod world_support;

use approx::assert_relative_eq;
use nalgebra::{Matrix2, Matrix3, Vector3};
use strata_robot::geometry::{Odometry, Point, Pose, Vector};
use strata_robot::percept::{CameraPercepts, Observation, ViewCone};
use strata_robot::world::{
    ExpectedObservation, GainedInformation, MotionModel, ObjectFilter, PoseFilter, PosePrior,
    RangeBearing, SensingCandidate, WorldModel,
};
use strata_runtime::Time;
use world_support::{BALL, LINE, POST, config, config_with_lines};

#[test]
fn object_prediction_with_a_turn_matches_hand_computation() {
    // A landmark 2 m ahead; the robot turns 90 degrees left: it now appears 2 m to the right.
    let mut f = ObjectFilter::new(
        Point::new(2.0, 0.0),
        Matrix2::new(0.01, 0.0, 0.0, 0.04),
        Vector::new(0.0, 0.0),
        Matrix2::zeros(),
        MotionModel::Static { position_noise: 0.0 },
    );
    let turn = Odometry { dx: 0.0, dy: 0.0, dtheta: std::f64::consts::FRAC_PI_2 };
    let q = Matrix3::from_diagonal(&Vector3::new(0.0, 0.0, 0.0025));
    f.predict_odometry(&turn, &q);
    assert_relative_eq!(f.position().x, 0.0, epsilon = 1e-12);
    assert_relative_eq!(f.position().y, -2.0, epsilon = 1e-12);
    // The axes swap: x variance 0.04, y variance 0.01; heading noise adds r^2 * 0.0025 = 0.01
    // across the line of sight (now the x axis).
    let p = f.position_covariance();
    assert_relative_eq!(p[(0, 0)], 0.04 + 0.01, epsilon = 1e-12);
    assert_relative_eq!(p[(1, 1)], 0.01, epsilon = 1e-12);
    assert_relative_eq!(p[(0, 1)], 0.0, epsilon = 1e-12);
}

#[test]
fn pose_update_with_a_landmark_to_the_left_matches_hand_computation() {
    // Robot at (1, 1) facing +y (theta = pi/2), covariance diag(0.09, 0.04, 0). The landmark at
    // (1, 4) is straight ahead at 3 m; it is measured at 3.2 m with variance 0.09 along the
    // robot's x axis (the field's y axis): field y corrects by 0.04 / 0.13 * (-0.2).
    let p0 = Matrix3::from_diagonal(&Vector3::new(0.09, 0.04, 0.0));
    let mut f = PoseFilter::new(Pose::new(1.0, 1.0, std::f64::consts::FRAC_PI_2), p0);
    let measured = GainedInformation {
        position: nalgebra::Vector2::new(3.2, 0.0),
        covariance: Matrix2::new(0.09, 0.0, 0.0, 0.09),
    };
    f.update_landmark(Point::new(1.0, 4.0), &measured).expect("regular update");
    assert_relative_eq!(f.pose().y, 1.0 - 0.2 * 0.04 / 0.13, epsilon = 1e-12);
    assert_relative_eq!(f.pose().x, 1.0, epsilon = 1e-12);
    assert_relative_eq!(f.covariance()[(1, 1)], 0.04 * 0.09 / 0.13, epsilon = 1e-12);
    // Field x is the robot's lateral axis: variance 0.09 with measurement variance 0.09 halves.
    assert_relative_eq!(f.covariance()[(0, 0)], 0.045, epsilon = 1e-12);
}

fn frame(stamp: Time, direction: f64, observations: Vec<Observation>) -> CameraPercepts {
    CameraPercepts {
        stamp,
        view: ViewCone { direction, fov: 1.0, range: 6.0, near: 0.0 },
        observations,
    }
}

fn observation(
    class: strata_robot::platform::ObjectClass,
    p: Point<strata_robot::geometry::Robot>,
) -> Observation {
    Observation {
        class,
        variant: None,
        range: p.range(),
        bearing: p.bearing(),
        orientation: None,
        range_sigma: 0.05 + 0.08 * p.range(),
        bearing_sigma: 0.035,
    }
}

/// A localized robot that has seen the ball and one goal post.
fn tracked_world() -> (WorldModel, Pose) {
    let truth = Pose::new(2.0, 0.3, 0.1);
    let prior = PosePrior { pose: truth, sigma: [0.15, 0.15, 0.08] };
    let mut world = WorldModel::new(config(Some(prior))).expect("valid config");
    let post = truth.to_robot(Point::new(4.5, 0.8));
    let ball = Point::new(1.2, -0.2);
    world.update(&frame(
        Time::from_secs_f64(1.0),
        0.0,
        vec![observation(POST, post), observation(BALL, ball)],
    ));
    // Walk a little so that the filters are no longer exactly the observations.
    world.predict(Odometry { dx: 0.1, dy: 0.0, dtheta: 0.05 });
    world.advance_to(Time::from_secs_f64(1.1));
    (world, truth)
}

#[test]
fn expected_update_equals_the_real_update_when_the_measurement_arrives() {
    let (world, _) = tracked_world();
    let ball = world.object_id("ball").expect("configured");
    let post = world.object_id("goal_post#0").expect("configured");
    let post_filter = world.filter(post).expect("the post is tracked").clone();
    let ball_filter = world.filter(ball).expect("the ball is tracked").clone();
    // The measurements arrive where the filters predict them, with the predicted noise.
    let sigmas = |p: Point<strata_robot::geometry::Robot>| (0.05 + 0.08 * p.range(), 0.035);
    let (post_rs, post_bs) = sigmas(post_filter.position());
    let (ball_rs, ball_bs) = sigmas(ball_filter.position());
    let candidate = SensingCandidate {
        observations: vec![
            ExpectedObservation {
                object: post,
                range_sigma: post_rs,
                bearing_sigma: post_bs,
                detection_probability: 1.0,
            },
            ExpectedObservation {
                object: ball,
                range_sigma: ball_rs,
                bearing_sigma: ball_bs,
                detection_probability: 1.0,
            },
        ],
        lines: Vec::new(),
    };
    let before = world.state();
    let expected = world.expected_update(&candidate);
    let from_state = before.expected_update(&candidate);
    // Nothing changed, and the published state predicts the same.
    assert_eq!(world.state(), before);
    assert_eq!(expected, from_state);

    let mut real = world.clone();
    let obs = |p: Point<strata_robot::geometry::Robot>, class, rs, bs| Observation {
        class,
        variant: None,
        range: p.range(),
        bearing: p.bearing(),
        orientation: None,
        range_sigma: rs,
        bearing_sigma: bs,
    };
    real.update(&frame(
        Time::from_secs_f64(1.1),
        0.0,
        vec![
            obs(post_filter.position(), POST, post_rs, post_bs),
            obs(ball_filter.position(), BALL, ball_rs, ball_bs),
        ],
    ));
    let post_after = real.filter(post).expect("tracked").position_covariance();
    let ball_after = real.filter(ball).expect("tracked").position_covariance();
    assert_relative_eq!(*expected.object(post).expect("simulated"), post_after, epsilon = 1e-12);
    assert_relative_eq!(*expected.object(ball).expect("simulated"), ball_after, epsilon = 1e-12);
    let pose_after = real.pose_filter().expect("localized").covariance();
    assert_relative_eq!(expected.pose, pose_after, epsilon = 1e-12);
    assert!(expected.pose.trace() < before.pose.covariance.trace());
}

/// A line the view would show corrects the pose's covariance as the world model's own
/// correction with that observation does, weighed by the detection probability; a world model
/// that has never fused a line expects none.
#[test]
fn the_expected_line_update_is_the_real_one() {
    let truth = Pose::new(-2.6, 0.4, 0.2);
    let prior = PosePrior { pose: truth, sigma: [0.2, 0.2, 0.1] };
    let mut world = WorldModel::new(config_with_lines(Some(prior))).expect("valid config");
    let view = ViewCone { direction: 0.0, fov: 1.0, range: 6.0, near: 0.0 };
    let camera = world.state().camera;
    let line = |p: Point<strata_robot::geometry::Robot>, direction: f64| {
        let (range_sigma, bearing_sigma) = camera.sigmas(p.range());
        Observation {
            class: LINE,
            variant: None,
            range: p.range(),
            bearing: p.bearing(),
            orientation: Some(direction),
            range_sigma,
            bearing_sigma,
        }
    };
    assert!(world.state().sensing_candidate(&view, 0.05).lines.is_empty(), "none fused yet");
    // The halfway line (x = 0), seen at the foot of the perpendicular from the robot.
    let foot = truth.to_robot(Point::new(0.0, truth.y));
    let across = std::f64::consts::FRAC_PI_2 - truth.theta;
    world.update(&frame(Time::from_secs_f64(0.1), 0.0, vec![line(foot, across)]));
    let state = world.state();
    assert_eq!(state.diagnostics.line_corrections, 1);
    let predicted = state.sensing_candidate(&view, 0.05).lines;
    let halfway = predicted.iter().find(|l| l.line == 4).copied().expect("the halfway line");
    assert!(predicted.iter().all(|l| l.line == 4), "only the halfway line: {predicted:?}");

    let mut sure = halfway;
    sure.detection_probability = 1.0;
    let expected =
        state.expected_update(&SensingCandidate { observations: Vec::new(), lines: vec![sure] });
    let mut real = world.clone();
    real.update(&frame(
        Time::from_secs_f64(0.1),
        0.0,
        vec![line(halfway.point, halfway.direction)],
    ));
    assert_eq!(real.state().diagnostics.line_corrections, 2);
    let after = real.pose_filter().expect("localized").covariance();
    assert_relative_eq!(expected.pose, after, epsilon = 1e-12);
    assert!(after[(0, 0)] < state.pose.covariance[(0, 0)], "across the line: narrower");

    let pd = halfway.detection_probability;
    assert!(pd > 0.0 && pd < 1.0, "{pd}");
    let weighed =
        state.expected_update(&SensingCandidate { observations: Vec::new(), lines: vec![halfway] });
    assert_relative_eq!(
        weighed.pose,
        after * pd + state.pose.covariance * (1.0 - pd),
        epsilon = 1e-12
    );
}

#[test]
fn expected_update_weighs_the_detection_probability() {
    let (world, _) = tracked_world();
    let ball = world.object_id("ball").expect("configured");
    let prior = world.filter(ball).expect("tracked").position_covariance();
    let candidate = |p: f64| SensingCandidate {
        observations: vec![ExpectedObservation {
            object: ball,
            range_sigma: 0.1,
            bearing_sigma: 0.035,
            detection_probability: p,
        }],
        lines: Vec::new(),
    };
    let never = world.expected_update(&candidate(0.0));
    assert_relative_eq!(*never.object(ball).expect("simulated"), prior, epsilon = 1e-15);
    let sure = *world.expected_update(&candidate(1.0)).object(ball).expect("simulated");
    let half = *world.expected_update(&candidate(0.5)).object(ball).expect("simulated");
    assert_relative_eq!(half, (sure + prior) * 0.5, epsilon = 1e-12);
}

#[test]
fn predicted_observation_and_sensing_candidate_follow_the_view() {
    let (world, _) = tracked_world();
    let state = world.state();
    let ball = world.object_id("ball").expect("configured");
    let ahead = ViewCone { direction: 0.0, fov: 1.0, range: 6.0, near: 0.0 };
    let behind = ViewCone { direction: std::f64::consts::PI, fov: 1.0, range: 9.0, near: 0.0 };
    let seen = state.predicted_observation(ball, &ahead).expect("the ball is tracked");
    assert!(seen.in_view && seen.visibility > 0.8, "{seen:?}");
    let unseen = state.predicted_observation(ball, &behind).expect("the ball is tracked");
    assert!(!unseen.in_view && unseen.visibility < 0.01, "{unseen:?}");
    let candidate = state.sensing_candidate(&ahead, 0.1);
    assert!(candidate.observations.iter().any(|o| o.object == ball));
    // An untracked goal post of the far goal lies behind: not part of looking ahead.
    let far_post = world.object_id("goal_post#2").expect("configured");
    assert!(!candidate.observations.iter().any(|o| o.object == far_post));
    let candidate = state.sensing_candidate(&behind, 0.1);
    assert!(candidate.observations.iter().any(|o| o.object == far_post));
    // Looking at it would start its filter and correct the pose.
    let belief = state.expected_update(&candidate);
    assert!(belief.pose.trace() < state.pose.covariance.trace());
}

#[test]
fn observation_noise_comes_from_the_percepts() {
    let z = RangeBearing { range: 2.0, bearing: 0.0, range_sigma: 0.2, bearing_sigma: 0.01 };
    let f = ObjectFilter::from_observation(&z, 1.0, MotionModel::Static { position_noise: 0.0 });
    assert_relative_eq!(
        f.position_covariance(),
        Matrix2::new(0.04, 0.0, 0.0, 0.0004),
        epsilon = 1e-12
    );
    // A static object has no velocity uncertainty, whatever was asked.
    assert_relative_eq!(f.velocity_covariance(), Matrix2::zeros());
}
