//! Confidence, short-term memory, negative information, the odometry-error estimate and the
//! configuration checks.

mod world_support;

use strata_robot::geometry::{Odometry, Point, Pose};
use strata_robot::percept::{CameraPercepts, Observation, Percepts, ViewCone};
use strata_robot::world::{ObjectKind, PosePrior, WorldModel, WorldModelConfig};
use strata_runtime::Time;
use world_support::{BALL, DT, Sim, config, patrol_step, pose_error};

fn frame(t: f64, direction: f64, ball: Option<Point<strata_robot::geometry::Robot>>) -> Percepts {
    let stamp = Time::from_secs_f64(t);
    let observations = ball
        .map(|p| Observation {
            class: BALL,
            variant: None,
            range: p.range(),
            bearing: p.bearing(),
            orientation: None,
            range_sigma: 0.1,
            bearing_sigma: 0.03,
        })
        .into_iter()
        .collect();
    Percepts {
        stamp,
        camera: Some(CameraPercepts {
            stamp,
            view: ViewCone { direction, fov: 1.0, range: 6.0, near: 0.0 },
            observations,
        }),
        ..Percepts::default()
    }
}

fn world_with_ball() -> (WorldModel, f64) {
    let prior = PosePrior { pose: Pose::new(0.0, 0.0, 0.0), sigma: [0.05, 0.05, 0.02] };
    let mut world = WorldModel::new(config(Some(prior))).expect("valid config");
    let mut t = 0.0;
    for _ in 0..15 {
        t += DT;
        world.process(Odometry::ZERO, &frame(t, 0.0, Some(Point::new(2.0, 0.1))));
    }
    (world, t)
}

#[test]
fn a_ball_not_seen_where_it_should_be_becomes_unknown_quickly() {
    let (mut world, mut t) = world_with_ball();
    let ball = world.object_id("ball").expect("configured");
    let start = world.object_confidence(ball);
    assert!(start > 0.8, "a ball seen in 15 images: {start}");
    let mut frames = 0;
    while world.state().get(ball).is_some_and(|b| b.known) {
        t += DT;
        frames += 1;
        world.process(Odometry::ZERO, &frame(t, 0.0, None));
        assert!(frames < 30, "still known after a second of looking at an empty spot");
    }
    println!("looking at an empty spot: unknown after {frames} images");
    assert!(frames >= 2, "one missed detection is not enough");
}

#[test]
fn a_ball_out_of_sight_is_remembered_with_growing_uncertainty() {
    let (mut world, mut t) = world_with_ball();
    let ball = world.object_id("ball").expect("configured");
    let mut previous = world.state().get(ball).expect("configured").covariance.trace();
    // Looking the other way: no evidence against the ball.
    for k in 0..30 {
        t += DT;
        world.process(Odometry::ZERO, &frame(t, std::f64::consts::PI, None));
        let b = world.state().get(ball).expect("configured").clone();
        assert!(b.known, "forgotten after {k} images");
        let trace = b.covariance.trace();
        assert!(trace > previous, "uncertainty must grow while unseen");
        previous = trace;
    }
    // The age factor halves the confidence every half-life (3 s for mobile objects).
    let c1 = world.object_confidence(ball);
    for _ in 0..90 {
        t += DT;
        world.process(Odometry::ZERO, &frame(t, std::f64::consts::PI, None));
    }
    let c2 = world.object_confidence(ball);
    assert!(c2 < c1 * 0.5, "{c1} -> {c2}");
    assert!((0.0..=1.0).contains(&c2));
    // Long enough, and it is unknown, then forgotten.
    for _ in 0..600 {
        t += DT;
        world.process(Odometry::ZERO, &frame(t, std::f64::consts::PI, None));
    }
    let b = world.state().get(ball).expect("configured").clone();
    assert!(!b.known && !b.tracked && b.confidence == 0.0);
    assert!(b.last_seen.is_none());
}

#[test]
fn the_odometry_error_is_estimated_from_the_landmarks_and_corrected() {
    let run = |correct: bool| {
        let start = Pose::new(-2.0, 0.5, 0.0);
        let mut sim = Sim::new(21, start);
        // Odometry reports 15% more forward motion than the robot makes.
        sim.forward_bias = 0.15;
        let mut cfg = config(Some(PosePrior { pose: start, sigma: [0.05, 0.05, 0.02] }));
        cfg.pose.correct_odometry = correct;
        let mut world = WorldModel::new(cfg).expect("valid config");
        let mut errors = 0.0;
        let frames = (40.0 / DT) as usize;
        for _ in 0..frames {
            let (odometry, percepts) = sim.frame(patrol_step(&sim));
            world.process(odometry, &percepts);
            errors += pose_error(&world.state().pose.pose, &sim.truth).xy().norm();
        }
        (world.state().odometry_error, errors / frames as f64)
    };
    let (estimate, error_without) = run(false);
    let truth = 1.0 / 1.15 - 1.0;
    println!(
        "relative forward error {:.3} +- {:.3} (truth {truth:.3}), {} samples",
        estimate.relative_error[0], estimate.relative_error_sigma[0], estimate.samples
    );
    assert!((estimate.relative_error[0] - truth).abs() < 0.06, "{estimate:?}");
    assert!(estimate.relative_error[2].abs() < 0.1, "{estimate:?}");
    let (corrected, error_with) = run(true);
    assert!(corrected.applied);
    println!("mean pose error {error_without:.3} m uncorrected, {error_with:.3} m corrected");
    assert!(error_with < error_without);
}

#[test]
fn configuration_errors_name_the_field() {
    let check = |edit: &dyn Fn(&mut WorldModelConfig), field: &str| {
        let mut cfg = config(None);
        edit(&mut cfg);
        let error = WorldModel::new(cfg).expect_err("invalid");
        assert_eq!(error.field, field, "{error}");
        assert!(error.to_string().contains(field));
    };
    check(&|c| c.objects[1].name = "ball".into(), "objects[1].name");
    check(&|c| c.objects[2].name = "post#1".into(), "objects[2].name");
    check(
        &|c| {
            if let ObjectKind::Mobile { friction, .. } = &mut c.objects[0].kind {
                *friction = -1.0;
            }
        },
        "objects[0].kind.friction",
    );
    check(
        &|c| {
            if let ObjectKind::Landmark { positions, .. } = &mut c.objects[1].kind {
                positions[2] = Point::new(f64::INFINITY, 0.0);
            }
        },
        "objects[1].kind.positions[2]",
    );
    check(
        &|c| {
            if let ObjectKind::Landmark { positions, .. } = &mut c.objects[1].kind {
                positions.clear();
            }
        },
        "objects[1].kind.positions",
    );
    check(&|c| c.camera.bearing_sigma = 0.0, "camera.bearing_sigma");
    check(
        &|c| c.odometry.rotation_variance_per_metre = f64::NAN,
        "odometry.rotation_variance_per_metre",
    );
    check(&|c| c.confidence.forget_threshold = 0.5, "confidence.forget_threshold");
    check(&|c| c.association.reinit_observations = 0, "association.reinit_observations");
    check(&|c| c.pose.recovery_min_landmarks = 1, "pose.recovery_min_landmarks");
    check(&|c| c.team.gate_probability = 1.0, "team.gate_probability");
    assert!(WorldModel::new(WorldModelConfig::default()).is_ok(), "no objects is valid");
}

#[test]
fn instances_get_stable_ids_and_names() {
    let world = WorldModel::new(config(None)).expect("valid config");
    let state = world.state();
    for (i, o) in state.objects.iter().enumerate() {
        assert_eq!(o.id.index(), i);
        assert_eq!(world.object_id(&o.name), Some(o.id));
    }
    assert_eq!(world.instances("goal_post").len(), 4);
    assert!(state.object("goal_post#3").is_some());
    assert!(state.object("centre_circle").is_some(), "a single instance keeps the plain name");
    assert_eq!(state.objects_of_class(world_support::POST).count(), 4);
    assert!(state.best_of_class(BALL).is_none(), "nothing known yet");
}
