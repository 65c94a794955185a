//! Active vision's fast paths give the answers of the plain ones: the sensing candidate and the
//! expected update of a view made in one pass, from priors that keep what does not depend on
//! the view, against one prediction per object followed by the expected update; an
//! evaluation into a used report against a fresh one; and the task value after a predicted
//! motion against the pose filter's own prediction.

mod world_support;

use nalgebra::Matrix3;
use strata_robot::control::active_vision::{
    ActiveVision, ActiveVisionConfig, ActiveVisionReport, Criterion, GazeCandidate,
    PredictedMotion, ValueFunction, ValueState,
};
use strata_robot::geometry::{Odometry, Point, Pose};
use strata_robot::percept::ViewCone;
use strata_robot::world::{
    ExpectedBelief, ObjectId, ObservationPrior, PoseFilter, PosePrior, SensingCandidate,
    WorldModel, WorldState,
};
use world_support::{Sim, config, config_with_lines, patrol_step, plain_sensing_candidate};

/// World states along a patrol: landmarks tracked and untracked, a ball, the pose localized;
/// the last one also with the pose lost. Then the same with the painted lines seen and fused.
fn states() -> Vec<WorldState> {
    let mut out = patrol(false);
    out.extend(patrol(true));
    assert!(out.iter().any(|w| w.expects_lines()));
    out
}

fn patrol(lines: bool) -> Vec<WorldState> {
    let start = Pose::new(-1.0, 0.5, 0.3);
    let prior = PosePrior { pose: start, sigma: [0.1, 0.1, 0.05] };
    let config = if lines { config_with_lines(Some(prior)) } else { config(Some(prior)) };
    let mut world = WorldModel::new(config).expect("valid config");
    let mut sim = Sim::new(7, start);
    sim.see_lines = lines;
    let mut out = Vec::new();
    for frame in 1..=240 {
        let (odometry, percepts) = sim.frame(patrol_step(&sim));
        world.process(odometry, &percepts);
        if frame % 60 == 0 {
            out.push(world.state());
        }
    }
    let mut lost = out[out.len() - 1].clone();
    lost.pose.lost = true;
    out.push(lost);
    out
}

fn check(world: &WorldState, priors: &mut [ObservationPrior], view: &ViewCone, min: f64) {
    let expected = plain_sensing_candidate(world, view, min);
    let belief = world.expected_update(&expected);
    let mut sensing = SensingCandidate::default();
    let mut fast = ExpectedBelief::default();
    world.expected_view_update_into(priors, view, min, &mut sensing, &mut fast);
    assert_eq!(sensing, expected, "{view:?} {min}");
    // Bit for bit, signs of zeros included.
    assert_eq!(format!("{fast:?}"), format!("{belief:?}"), "{view:?} {min}");
}

#[test]
fn the_one_pass_view_update_equals_the_prediction_and_the_expected_update() {
    let states = states();
    assert!(states.iter().any(|w| w.objects.iter().filter(|o| o.tracked).count() > 3));
    for world in &states {
        // Priors made for the views' range, for another range, and without one; each kept
        // across all the views, as active vision keeps them across its candidates.
        let mut within = Vec::new();
        world.observation_priors_within_into(6.0, &mut within);
        let mut other = Vec::new();
        world.observation_priors_within_into(4.0, &mut other);
        let mut bare = Vec::new();
        world.observation_priors_into(&mut bare);
        for step in -80..=80 {
            let direction = f64::from(step) * 0.025;
            for (fov, range, min) in
                [(1.06, 6.0, 0.05), (0.5, 6.0, 0.0), (2.0, 6.0, 0.6), (1.06, 6.0, 1e-13)]
            {
                let view = ViewCone { direction, fov, range, near: 0.0 };
                check(world, &mut within, &view, min);
                check(world, &mut other, &view, min);
                check(world, &mut bare, &view, min);
            }
        }
    }
}

#[test]
fn priors_left_out_for_a_range_are_those_no_view_of_it_observes() {
    for world in &states() {
        for (range, min) in [(6.0, 0.05), (4.0, 0.05), (2.5, 0.3), (6.0, 0.6), (6.0, 1e-13)] {
            let mut reaching = Vec::new();
            world.observation_priors_reaching_into(range, min, &mut reaching);
            let mut within = Vec::new();
            world.observation_priors_within_into(range, &mut within);
            // The same priors, a subset of them.
            let mut kept = reaching.iter().peekable();
            let mut left_out = Vec::new();
            for prior in &within {
                if kept.peek().is_some_and(|k| k.object == prior.object) {
                    let k = kept.next().expect("peeked");
                    assert_eq!(format!("{k:?}"), format!("{prior:?}"));
                } else {
                    left_out.push(*prior);
                }
            }
            assert!(kept.next().is_none());
            if range < 5.0 {
                assert!(!left_out.is_empty(), "{range} {min}");
            }
            for step in -80..=80 {
                let direction = f64::from(step) * 0.025;
                for fov in [1.06, 0.5, 2.0] {
                    let view = ViewCone { direction, fov, range, near: 0.0 };
                    // Those left out are observed by no view of that range...
                    let mut sensing = SensingCandidate::default();
                    world.sensing_candidate_into(&left_out, &view, min, &mut sensing);
                    assert!(sensing.observations.is_empty(), "{view:?} {min}");
                    // ...and the views' updates from the others are the plain ones.
                    check(world, &mut reaching, &view, min);
                }
            }
        }
    }
}

/// The update of a reader of some objects: the full update's pose, and its entries for them.
fn check_only(
    world: &WorldState,
    priors: &mut [ObservationPrior],
    view: &ViewCone,
    ids: &[ObjectId],
) {
    let mut sensing = SensingCandidate::default();
    let mut full = ExpectedBelief::default();
    world.expected_view_update_into(priors, view, 0.05, &mut sensing, &mut full);
    let mut only_sensing = SensingCandidate::default();
    let mut only = ExpectedBelief::default();
    world.expected_view_update_of_into(priors, view, 0.05, ids, &mut only_sensing, &mut only);
    assert_eq!(only_sensing, sensing);
    assert_eq!(format!("{:?}", only.pose), format!("{:?}", full.pose), "{view:?}");
    for id in ids {
        assert_eq!(format!("{:?}", only.object(*id)), format!("{:?}", full.object(*id)));
    }
}

#[test]
fn an_update_for_some_objects_has_the_full_updates_pose_and_their_covariances() {
    for world in &states() {
        let tracked: Vec<ObjectId> =
            world.objects.iter().filter(|o| o.tracked).map(|o| o.id).collect();
        let sets: [Vec<ObjectId>; 4] = [
            Vec::new(),
            vec![ObjectId(0)],
            tracked.iter().copied().step_by(3).collect(),
            vec![ObjectId(u16::MAX), tracked[tracked.len() / 2]],
        ];
        let mut priors = Vec::new();
        world.observation_priors_reaching_into(6.0, 0.05, &mut priors);
        let mut twice: Vec<ObservationPrior> =
            priors.iter().chain(priors.iter()).copied().collect();
        for step in -40..=40 {
            let view =
                ViewCone { direction: f64::from(step) * 0.05, fov: 1.06, range: 6.0, near: 0.0 };
            for ids in &sets {
                check_only(world, &mut priors, &view, ids);
                check_only(world, &mut twice, &view, ids);
            }
        }
    }
}

#[test]
fn an_object_listed_twice_builds_on_its_first_observation_as_in_the_expected_update() {
    let world = &states()[2];
    let mut priors = Vec::new();
    world.observation_priors_within_into(6.0, &mut priors);
    let twice: Vec<ObservationPrior> = priors.iter().chain(priors.iter()).copied().collect();
    for direction in [-1.5, -0.4, 0.0, 0.9, 2.0] {
        let view = ViewCone { direction, fov: 1.06, range: 6.0, near: 0.0 };
        let mut sensing = SensingCandidate::default();
        world.sensing_candidate_into(&twice, &view, 0.05, &mut sensing);
        let belief = world.expected_update(&sensing);
        let mut fast_sensing = SensingCandidate::default();
        let mut fast = ExpectedBelief::default();
        let mut kept = twice.clone();
        for _ in 0..2 {
            world.expected_view_update_into(&mut kept, &view, 0.05, &mut fast_sensing, &mut fast);
            assert_eq!(fast_sensing, sensing);
            assert_eq!(format!("{fast:?}"), format!("{belief:?}"));
        }
    }
}

/// V: closeness of the ball and of the pose to fixed points (smooth, depends on both blocks).
struct Closeness;

impl ValueFunction for Closeness {
    fn name(&self) -> &str {
        "closeness"
    }

    fn objects(&self) -> Vec<ObjectId> {
        vec![ObjectId(0)]
    }

    fn value(&self, state: &ValueState<'_>) -> f64 {
        let ball = state.object(ObjectId(0)).map_or(0.0, |b| (-b.range()).exp());
        ball + (-state.pose.position().distance(Point::new(1.0, 0.5))).exp()
    }
}

#[test]
fn an_evaluation_into_a_used_report_is_a_fresh_evaluation() {
    let states = states();
    let candidates = |n: usize, tag: &str| -> Vec<GazeCandidate> {
        (0..n)
            .map(|i| GazeCandidate {
                label: format!("{tag}{i}"),
                direction: -2.2 + 4.4 * i as f64 / n as f64,
                footprint: None,
            })
            .collect()
    };
    let mut vision = ActiveVision::new(ActiveVisionConfig::default());
    let mut report = ActiveVisionReport::default();
    // A larger evaluation first, then smaller and larger ones, each into the same report.
    for (world, n) in states.iter().zip([13, 4, 9, 1, 17]) {
        let gazes = candidates(n, if n % 2 == 0 { "a much longer label " } else { "c" });
        vision.evaluate_into(world, &Closeness, &gazes, &mut report);
        let fresh =
            ActiveVision::new(ActiveVisionConfig::default()).evaluate(world, &Closeness, &gazes);
        assert_eq!(format!("{report:?}"), format!("{fresh:?}"));
        assert!(report.candidates.iter().any(|c| !c.observed.is_empty()));
    }
}

#[test]
fn candidates_looked_at_from_the_same_limit_are_evaluated_as_each_alone() {
    let states = states();
    let directions = [-3.0, 0.3, -2.5, 2.4, -2.0, 3.1, 0.3, 2.0, 1.0];
    let gazes: Vec<GazeCandidate> = directions
        .iter()
        .enumerate()
        .map(|(i, d)| GazeCandidate { label: format!("g{i}"), direction: *d, footprint: None })
        .collect();
    let mut vision = ActiveVision::new(ActiveVisionConfig::default());
    for world in &states {
        let report = vision.evaluate(world, &Closeness, &gazes);
        for (gaze, evaluation) in gazes.iter().zip(&report.candidates) {
            let alone = ActiveVision::new(ActiveVisionConfig::default()).evaluate(
                world,
                &Closeness,
                std::slice::from_ref(gaze),
            );
            let alone = &alone.candidates[0];
            assert_eq!(evaluation.label, alone.label);
            assert_eq!(evaluation.direction.to_bits(), alone.direction.to_bits());
            assert_eq!(evaluation.observed, alone.observed);
            assert_eq!(evaluation.value_variance.to_bits(), alone.value_variance.to_bits());
            assert_eq!(evaluation.expected_value.to_bits(), alone.expected_value.to_bits());
            assert_eq!(evaluation.improvement.to_bits(), alone.improvement.to_bits());
        }
    }
}

/// V: how near the robot is to the line y = 0.5 (quadratic: its expectation is exact to
/// second order).
struct Lateral;

impl ValueFunction for Lateral {
    fn name(&self) -> &str {
        "lateral"
    }

    fn objects(&self) -> Vec<ObjectId> {
        Vec::new()
    }

    fn value(&self, state: &ValueState<'_>) -> f64 {
        -(state.pose.y - 0.5).powi(2)
    }
}

fn task_value() -> ActiveVision {
    ActiveVision::new(ActiveVisionConfig {
        criterion: Criterion::MaxExpectedTaskValue,
        ..ActiveVisionConfig::default()
    })
}

#[test]
fn no_motion_leaves_the_task_value_as_it_was() {
    let gazes: Vec<GazeCandidate> = (0..9)
        .map(|i| GazeCandidate {
            label: format!("g{i}"),
            direction: -2.0 + 0.5 * f64::from(i),
            footprint: None,
        })
        .collect();
    let still = PredictedMotion { odometry: Odometry::ZERO, noise: Matrix3::zeros() };
    for world in &states() {
        let plain = task_value().evaluate(world, &Closeness, &gazes);
        let mut after = ActiveVisionReport::default();
        task_value().evaluate_after_into(world, &Closeness, &gazes, Some(&still), &mut after);
        assert_eq!(format!("{after:?}"), format!("{plain:?}"));
    }
}

/// After a walk, E[V] = V(x') + tr(H P') / 2 with P' the pose filter's prediction: the
/// heading's uncertainty has become lateral uncertainty along the walk, and costs value.
#[test]
fn the_task_value_after_a_walk_is_the_value_under_the_pose_filters_prediction() {
    let walk = Odometry { dx: 2.0, dy: 0.3, dtheta: 0.4 };
    let noise = Matrix3::from_diagonal(&nalgebra::Vector3::new(0.01, 0.01, 0.002));
    let motion = PredictedMotion { odometry: walk, noise };
    let gazes = vec![GazeCandidate { label: "ahead".into(), direction: 0.0, footprint: None }];
    for world in &states() {
        let mut report = ActiveVisionReport::default();
        task_value().evaluate_after_into(world, &Lateral, &gazes, Some(&motion), &mut report);
        let mut filter = PoseFilter::new(world.pose.pose, world.pose.covariance);
        filter.predict(&walk, &noise);
        let moved = filter.pose();
        let expected = -(moved.y - 0.5).powi(2) - filter.covariance()[(1, 1)];
        assert!(
            (report.prior_expected_value - expected).abs() < 1e-6,
            "{} against {expected}",
            report.prior_expected_value
        );
        // Without the walk, the value is taken where the robot stands.
        let here = task_value().evaluate(world, &Lateral, &gazes);
        let standing = -(world.pose.pose.y - 0.5).powi(2) - world.pose.covariance[(1, 1)];
        assert!((here.prior_expected_value - standing).abs() < 1e-6);
    }
}
