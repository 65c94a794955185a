//! Data association: symmetric landmarks, false positives, a ball that jumps.

mod world_support;

use nalgebra::Vector2;
use strata_robot::geometry::{Odometry, Point, Pose};
use strata_robot::percept::{CameraPercepts, Observation, Percepts, ViewCone};
use strata_robot::world::{PosePrior, WorldModel};
use strata_runtime::Time;
use world_support::{BALL, DT, POST, Sim, config, patrol_step, pose_error};

struct Outcome {
    pose_error: f64,
    map_error: f64,
    ball_mean: f64,
    ball_p95: f64,
    diagnostics: strata_robot::world::WorldDiagnostics,
}

fn patrol_with_clutter(seed: u64, false_positive_rate: f64) -> Outcome {
    let start = Pose::new(-1.5, 0.5, 0.2);
    let mut sim = Sim::new(seed, start);
    sim.false_positive_rate = false_positive_rate;
    sim.false_classes = vec![POST, BALL];
    sim.ball = Vector2::new(0.0, 0.0);
    let prior = PosePrior { pose: start, sigma: [0.05, 0.05, 0.02] };
    let mut world = WorldModel::new(config(Some(prior))).expect("valid config");
    let mut pose_errors = Vec::new();
    let mut map_errors = Vec::new();
    let mut ball_errors = Vec::new();
    for frame in 0..(20.0 / DT) as usize {
        let (odometry, percepts) = sim.frame(patrol_step(&sim));
        world.process(odometry, &percepts);
        let state = world.state();
        assert!(!state.pose.lost, "seed {seed} frame {frame}: lost");
        if frame > 60 {
            pose_errors.push(pose_error(&state.pose.pose, &sim.truth).xy().norm());
            map_errors.extend(state.map_accuracy.map(|a| a.mean_error));
        }
        if sim.ball_streak >= 3 {
            let ball = state.object("ball").expect("configured");
            let e = Vector2::new(ball.position.x, ball.position.y) - sim.ball_in_robot_frame();
            ball_errors.push(e.norm());
        }
    }
    let state = world.state();
    for post in state.group("goal_post").filter(|p| p.known) {
        let map = post.map_position.expect("a landmark");
        let age = post.last_seen.map_or(f64::INFINITY, |t| (state.stamp - t).as_secs_f64());
        assert!(
            age > 2.0 || post.global_position.distance(map) < 0.5,
            "seed {seed}: {} at {:?}, map {:?}",
            post.name,
            post.global_position,
            map
        );
    }
    ball_errors.sort_by(f64::total_cmp);
    assert!(ball_errors.len() > 30, "seed {seed}: ball seen in {} frames", ball_errors.len());
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    Outcome {
        pose_error: mean(&pose_errors),
        map_error: mean(&map_errors),
        ball_mean: mean(&ball_errors),
        ball_p95: ball_errors[ball_errors.len() * 95 / 100],
        diagnostics: state.diagnostics,
    }
}

#[test]
fn false_positives_do_not_corrupt_the_landmarks_the_pose_or_the_ball() {
    for seed in 100..105 {
        let clean = patrol_with_clutter(seed, 0.0);
        // Nine spurious goal posts and nine spurious balls per second of 30 images.
        let cluttered = patrol_with_clutter(seed, 0.3);
        let d = cluttered.diagnostics;
        println!(
            "seed {seed}: pose {:.3} / {:.3} m, map {:.3} / {:.3} m, ball mean {:.3} / {:.3} m, 95% {:.3} / {:.3} m; {d:?}",
            clean.pose_error,
            cluttered.pose_error,
            clean.map_error,
            cluttered.map_error,
            clean.ball_mean,
            cluttered.ball_mean,
            clean.ball_p95,
            cluttered.ball_p95
        );
        assert!(d.rejected > clean.diagnostics.rejected + 50, "seed {seed}: clutter accepted");
        assert_eq!(d.kidnaps, 0, "seed {seed}");
        assert!(cluttered.pose_error < 0.15, "seed {seed}");
        assert!(cluttered.map_error < 0.25, "seed {seed}");
        assert!(cluttered.ball_mean < 0.15, "seed {seed}");
        assert!(cluttered.ball_p95 < 0.4, "seed {seed}");
    }
}

fn observation(
    class: strata_robot::platform::ObjectClass,
    pose: &Pose,
    at: Point<strata_robot::geometry::Global>,
) -> Observation {
    let p = pose.to_robot(at);
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

fn percepts(t: f64, observations: Vec<Observation>) -> Percepts {
    let stamp = Time::from_secs_f64(t);
    Percepts {
        stamp,
        camera: Some(CameraPercepts {
            stamp,
            view: ViewCone { direction: 0.0, fov: 1.0, range: 6.0, near: 0.0 },
            observations,
        }),
        ..Percepts::default()
    }
}

#[test]
fn identical_goal_posts_are_told_apart_by_the_pose_and_the_map() {
    // Facing the opponent goal, slightly uncertain: the two posts, 1.6 m apart, are associated
    // with the right instances; the posts of the other goal are never touched.
    let truth = Pose::new(1.5, 0.4, -0.05);
    let prior = PosePrior { pose: Pose::new(1.6, 0.3, 0.0), sigma: [0.2, 0.2, 0.1] };
    let mut world = WorldModel::new(config(Some(prior))).expect("valid config");
    for k in 0..30 {
        let obs = vec![
            observation(POST, &truth, Point::new(4.5, -0.8)),
            observation(POST, &truth, Point::new(4.5, 0.8)),
        ];
        world.process(Odometry::ZERO, &percepts(0.1 * f64::from(k), obs));
    }
    let state = world.state();
    let p0 = state.object("goal_post#0").expect("configured");
    let p1 = state.object("goal_post#1").expect("configured");
    assert!(p0.known && p1.known);
    assert!(p0.global_position.distance(Point::new(4.5, 0.8)) < 0.15, "{:?}", p0.global_position);
    assert!(p1.global_position.distance(Point::new(4.5, -0.8)) < 0.15, "{:?}", p1.global_position);
    assert!(!state.object("goal_post#2").expect("configured").tracked);
    assert!(!state.object("goal_post#3").expect("configured").tracked);
    let e = pose_error(&state.pose.pose, &truth);
    assert!(e.xy().norm() < 0.1 && e.z.abs() < 0.03, "pose error {e:?}");
}

#[test]
fn a_wild_ball_detection_is_rejected_but_a_moved_ball_is_followed() {
    let pose = Pose::new(0.0, 0.0, 0.0);
    let prior = PosePrior { pose, sigma: [0.05, 0.05, 0.02] };
    let mut world = WorldModel::new(config(Some(prior))).expect("valid config");
    let ball_at = |x: f64, y: f64| observation(BALL, &pose, Point::new(x, y));
    let mut t = 0.0;
    for _ in 0..20 {
        t += DT;
        world.process(Odometry::ZERO, &percepts(t, vec![ball_at(1.5, 0.2)]));
    }
    // One spurious detection 2 m away, the real ball not seen in that image.
    t += DT;
    world.process(Odometry::ZERO, &percepts(t, vec![ball_at(3.0, -1.2)]));
    let ball = world.state().object("ball").expect("configured").position;
    assert!(ball.distance(Point::new(1.5, 0.2)) < 0.05, "pulled to {ball:?}");
    // The ball really is there now (it was kicked): consistent detections restart the track.
    for _ in 0..3 {
        t += DT;
        world.process(Odometry::ZERO, &percepts(t, vec![ball_at(3.0, -1.2)]));
    }
    let ball = world.state().object("ball").expect("configured").position;
    assert!(ball.distance(Point::new(3.0, -1.2)) < 0.3, "still at {ball:?}");
    assert!(world.diagnostics().reinitialized >= 1);
}

#[test]
fn variants_tell_coloured_goals_apart() {
    use strata_robot::world::{ObjectKind, ObjectOfInterest, WorldModelConfig};
    // The 2010 field: a yellow goal (variant 1) and a blue one (variant 2).
    let goal = |name: &str, variant: u16, x: f64| ObjectOfInterest {
        name: name.to_owned(),
        class: POST,
        variant: Some(variant),
        kind: ObjectKind::Landmark {
            positions: vec![Point::new(x, 0.7), Point::new(x, -0.7)],
            position_noise: 0.0,
        },
        confidence: None,
    };
    let cfg = WorldModelConfig {
        objects: vec![goal("yellow_post", 1, 3.0), goal("blue_post", 2, -3.0)],
        pose: strata_robot::world::PoseConfig {
            bounds: Some(world_support::bounds()),
            ..Default::default()
        },
        ..WorldModelConfig::default()
    };
    let mut world = WorldModel::new(cfg).expect("valid config");
    let pose = Pose::new(1.0, 0.0, std::f64::consts::PI);
    let seen = |variant: u16, at: Point<strata_robot::geometry::Global>| Observation {
        variant: Some(variant),
        ..observation(POST, &pose, at)
    };
    for k in 0..5 {
        let obs = vec![seen(2, Point::new(-3.0, 0.7)), seen(2, Point::new(-3.0, -0.7))];
        world.process(Odometry::ZERO, &percepts(0.1 * f64::from(k), obs));
    }
    let state = world.state();
    assert!(state.group("blue_post").all(|p| p.tracked));
    assert!(state.group("yellow_post").all(|p| !p.tracked));
    // Unknown pose, but two coloured posts fix it: no symmetry to break.
    assert!(!state.pose.lost, "{:?}", state.pose);
    let e = pose_error(&state.pose.pose, &pose);
    assert!(e.xy().norm() < 0.2 && e.z.abs() < 0.1, "{e:?}");
}

#[test]
fn obstacles_are_tracked_in_a_bank_of_filters() {
    use strata_robot::platform::ObjectClass;
    use strata_robot::world::{ObjectKind, ObjectOfInterest, WorldModelConfig};
    const ROBOT: ObjectClass = ObjectClass(2);
    let cfg = WorldModelConfig {
        objects: vec![ObjectOfInterest {
            name: "robot".to_owned(),
            class: ROBOT,
            variant: None,
            kind: ObjectKind::Obstacle {
                max_tracks: 3,
                acceleration_noise: 0.3,
                velocity_decay: 2.0,
                max_speed: 0.6,
            },
            confidence: None,
        }],
        ..WorldModelConfig::default()
    };
    let mut world = WorldModel::new(cfg).expect("valid config");
    let pose = Pose::new(0.0, 0.0, 0.0);
    let mut t = 0.0;
    // One robot standing, one walking across at 0.3 m/s.
    for _ in 0..90 {
        t += DT;
        let walker = Point::new(3.0, -1.0 + 0.3 * t);
        let obs = vec![
            observation(ROBOT, &pose, Point::new(2.0, 0.3)),
            observation(ROBOT, &pose, walker),
        ];
        world.process(Odometry::ZERO, &percepts(t, obs));
    }
    let state = world.state();
    let tracks: Vec<_> = state.group("robot").filter(|o| o.known).collect();
    assert_eq!(tracks.len(), 2, "{:?}", state.group("robot").collect::<Vec<_>>());
    let walker = tracks
        .iter()
        .find(|o| o.position.distance(Point::new(3.0, -1.0 + 0.3 * t)) < 0.3)
        .expect("the walking robot is tracked");
    let v = walker.velocity.expect("obstacles have a velocity");
    assert!((v.y - 0.3).abs() < 0.15 && v.x.abs() < 0.15, "velocity {v:?}");
    // The standing robot leaves; looking at its spot makes it unknown.
    for _ in 0..30 {
        t += DT;
        let walker = Point::new(3.0, -1.0 + 0.3 * t);
        world.process(Odometry::ZERO, &percepts(t, vec![observation(ROBOT, &pose, walker)]));
    }
    let state = world.state();
    assert_eq!(state.group("robot").filter(|o| o.known).count(), 1);
}
