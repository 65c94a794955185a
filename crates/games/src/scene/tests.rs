use std::time::Duration as StdDuration;

use strata_sim::{SimConfig, Simulation};

use super::*;

fn config(field: &Field) -> SceneConfig {
    SceneConfig {
        field: field.dimensions().clone(),
        camera_fov: 1.0,
        camera_range: 3.0,
        attack_sign: [1.0, -1.0],
        period: 0.1,
    }
}

fn spl() -> Field {
    Field::preset("spl").expect("the SPL field")
}

/// Equal but for the scene's rounding (a tenth of a millimetre; about 2e-4 rad for angles).
fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 3e-4
}

#[test]
fn the_field_holds_every_line_the_circle_and_both_goals() {
    let field = spl();
    let update = field_update(&field, Timestamp::from_secs_f64(2.0));
    assert_eq!(update.entities.len(), 1);
    let entity = &update.entities[0];
    assert_eq!((entity.frame_id.as_str(), entity.id.as_str()), (FIELD_FRAME, "field"));
    // Shown until replaced.
    assert_eq!(entity.lifetime, Duration::default());
    let lines = &entity.lines[0];
    assert_eq!(lines.kind, LineType::List);
    assert_eq!(lines.points.len(), 2 * field.lines().len());
    let first = field.lines()[0];
    assert!(close(lines.points[0].x, first.start.x) && close(lines.points[1].y, first.end.y));
    // The centre circle passes through (radius, 0).
    let radius = field.centre_circle().radius;
    assert!(close(entity.lines[1].points[0].x, radius) && entity.lines[1].kind == LineType::Loop);
    // Four posts, at the goals' posts; two goal areas behind the goal lines.
    assert_eq!(entity.cylinders.len(), 4);
    let own = field.goal(Side::Own);
    assert!(close(entity.cylinders[0].pose.position.x, own.left_post.x));
    assert!(close(entity.cylinders[0].pose.position.y, own.left_post.y));
    assert_eq!(entity.lines.len(), 4);
}

fn robot(name: &str, x: f64, y: f64, theta: f64) -> RobotState {
    let mut state = RobotState::new(name);
    state.truth = Some(TrueRobot {
        x,
        y,
        theta,
        head_yaw: 0.3,
        head_pitch: 0.2,
        present: true,
        fallen: false,
        penalized: false,
    });
    state
}

#[test]
fn robots_are_drawn_at_their_true_poses_with_their_estimates_and_views() {
    let field = spl();
    let mut home = robot("home/3", 1.0, -2.0, 0.5);
    home.role = Some("striker".to_owned());
    home.estimate = Some(Estimate {
        x: 1.1,
        y: -2.1,
        theta: 0.4,
        confidence: 0.9,
        lost: false,
        ball: Some(BallEstimate {
            x: 2.0,
            y: 0.0,
            covariance: [[0.04, 0.0], [0.0, 0.01]],
            known: true,
            confidence: 0.8,
        }),
        team_ball: Some((1.9, 0.1)),
    });
    let away = robot("away/1", -3.0, 0.0, -2.0);
    let update = objects_update(
        &[home, away],
        Some((0.5, 0.25)),
        &config(&field),
        Timestamp::from_secs_f64(1.0),
    );
    let ids: Vec<&str> = update.entities.iter().map(|e| e.id.as_str()).collect();
    assert_eq!(
        ids,
        ["ball", "home/3/truth", "home/3/estimate", "home/3/view", "away/1/truth", "away/1/view"]
    );
    let ball = &update.entities[0].spheres[0].pose.position;
    assert!(close(ball.x, 0.5) && close(ball.y, 0.25));
    let truth = &update.entities[1];
    let body = &truth.cubes[0].pose;
    assert!(close(body.position.x, 1.0) && close(body.position.y, -2.0));
    assert!(close(body.orientation.yaw(), 0.5));
    assert_eq!(truth.texts[0].text, "home/3 striker");
    let estimate = &update.entities[2];
    assert!(close(estimate.arrows[0].pose.position.x, 1.1));
    assert!(close(estimate.arrows[0].pose.orientation.yaw(), 0.4));
    // The 2-sigma ellipse of a covariance of 0.04 along x and 0.01 along y: 0.4 by 0.2.
    let ellipse = &estimate.lines[0].points;
    let extent = |f: fn(&Point3) -> f64| ellipse.iter().map(f).fold(0.0f64, f64::max);
    assert!(close(extent(|p| p.x), 2.4), "{}", extent(|p| p.x));
    assert!((extent(|p| p.y) - 0.2).abs() < 1e-2, "{}", extent(|p| p.y));
    let ring = &estimate.cylinders[0].pose.position;
    assert!(close(ring.x, 1.9) && close(ring.y, 0.1), "the team ball");
    // The view is drawn in the head frame, which follows the robot.
    let view = &update.entities[3];
    assert_eq!(view.frame_id, "home/3/head");
    assert!(view.frame_locked);
    let left = view.lines[0].points[1];
    assert!(close(left.x.hypot(left.y), 3.0) && close(left.y.atan2(left.x), 0.5));
    // The teams' colours differ.
    assert_ne!(truth.cubes[0].color, update.entities[4].cubes[0].color);
}

#[test]
fn a_rotated_covariance_gives_a_rotated_ellipse() {
    // Variance 1 along the diagonal (1, 1)/sqrt(2), 0.25 across it.
    let (major, minor): (f64, f64) = (1.0, 0.25);
    let mean = (major + minor) / 2.0;
    let half = (major - minor) / 2.0;
    let points = covariance_ellipse(0.0, 0.0, [[mean, half], [half, mean]], 1.0);
    let longest = points.iter().map(|p| p.x.hypot(p.y)).fold(0.0f64, f64::max);
    let shortest = points.iter().map(|p| p.x.hypot(p.y)).fold(f64::MAX, f64::min);
    assert!(close(longest, 1.0) && (shortest - 0.5).abs() < 0.02, "{longest} {shortest}");
    assert!(close(points[0].x, points[0].y), "the major axis along the diagonal");
}

#[test]
fn frames_chain_from_the_field_to_each_camera() {
    let mut home = robot("home/3", 1.0, -2.0, 0.5);
    home.estimate = Some(Estimate {
        x: 1.0,
        y: -2.0,
        theta: 0.5,
        confidence: 1.0,
        lost: false,
        ball: None,
        team_ball: None,
    });
    let tf = transforms(&[home], Timestamp::from_secs_f64(4.0));
    let chain: Vec<(&str, &str)> = tf
        .transforms
        .iter()
        .map(|t| (t.parent_frame_id.as_str(), t.child_frame_id.as_str()))
        .collect();
    assert_eq!(
        chain,
        [
            ("field", "home/3"),
            ("home/3", "home/3/head"),
            ("home/3/head", "home/3/camera"),
            ("field", "home/3/estimate")
        ]
    );
    assert!(close(tf.transforms[0].translation.x, 1.0));
    assert!(close(tf.transforms[0].rotation.yaw(), 0.5));
    assert!(close(tf.transforms[1].rotation.yaw(), 0.3));
    assert!(close(tf.transforms[1].translation.z, HEAD_HEIGHT));
    assert_eq!(tf.transforms[3].timestamp, Timestamp { sec: 4, nsec: 0 });
}

#[test]
fn a_robot_off_the_field_is_not_drawn_and_has_no_frames() {
    let mut gone = robot("home/2", 0.0, 0.0, 0.0);
    if let Some(truth) = gone.truth.as_mut() {
        truth.present = false;
    }
    let field = spl();
    let update = objects_update(&[gone.clone()], None, &config(&field), Timestamp::default());
    assert!(update.entities.is_empty());
    assert!(transforms(&[gone], Timestamp::default()).transforms.is_empty());
}

#[test]
fn events_become_log_lines() {
    let at = Time::from_secs_f64(12.5);
    let goal = Event {
        time: at,
        kind: EventKind::Goal { team: 1, score: [0, 1], scorer: Some(RobotId::new(1, 4)) },
    };
    let line = event_log(&goal).expect("a goal is logged");
    assert_eq!(line.message, "goal for away (0:1), scored by away/4");
    assert_eq!((line.level, line.timestamp), (LogLevel::Warning, Timestamp::from_secs_f64(12.5)));
    let kick_off = Event { time: at, kind: EventKind::SetPlayOver };
    assert_eq!(event_log(&kick_off), None);
    let role = role_log("home/3", at, "striker", Some("goalie"));
    assert_eq!(
        (role.name.as_str(), role.message.as_str()),
        ("home/3", "home/3 role striker (was goalie)")
    );
}

#[test]
fn the_recorder_writes_the_field_once_and_the_objects_every_period() {
    let sim = Simulation::new(SimConfig::default()).expect("the default world");
    let field = sim.field().clone();
    let mut truth = sim.ground_truth();
    assert!(!truth.robots.is_empty());
    let mut recorder = SceneRecorder::new(config(&field), Vec::new());
    let mut updates = 0;
    let mut fields = 0;
    for k in 0..25u64 {
        let time = Time::ZERO + StdDuration::from_millis(20 * k);
        truth.robots[0].pose.x = k as f64 * 0.1;
        let out = recorder.truth(time, &truth);
        fields += usize::from(out.field.is_some());
        if let Some(objects) = out.objects {
            updates += 1;
            let id = format!("{}/truth", robot_name(truth.robots[0].id));
            let first = objects.entities.iter().find(|e| e.id == id).expect("the first robot");
            assert!(close(first.cubes[0].pose.position.x, k as f64 * 0.1));
            assert!(out.transforms.is_some());
        }
    }
    // At 0, 0.1, 0.2, 0.3 and 0.4 s (every fifth package, 20 ms apart).
    assert_eq!((fields, updates), (1, 5));
    // Packages a little more than a period apart still give one update per period.
    let mut recorder = SceneRecorder::new(config(&field), Vec::new());
    let updates = (0..30u64)
        .filter(|k| {
            let time = Time::from_nanos(k * 33_333_333);
            recorder.truth(time, &truth).objects.is_some()
        })
        .count();
    assert_eq!(updates, 10, "in a second of packages at 30 Hz");
    assert_eq!(recorder.robots().len(), truth.robots.len());
    let same = recorder.role("home/1", Time::ZERO, "goalie");
    assert_eq!(same.logs.len(), 1);
    assert!(recorder.role("home/1", Time::ZERO, "goalie").logs.is_empty());
    recorder.restart();
    let again = recorder.truth(Time::from_secs_f64(0.5), &truth);
    assert!(again.field.is_some() && again.objects.is_some());
}

#[test]
fn the_shipped_layout_shows_the_scene_topics() {
    let layout: serde_json::Value =
        serde_json::from_str(include_str!("../../../../docs/foxglove-layout.json")).expect("JSON");
    let three_d = &layout["configById"]["3D!strata-field"];
    assert_eq!(three_d["followTf"], FIELD_FRAME);
    for topic in [FIELD_TOPIC, OBJECTS_TOPIC] {
        assert_eq!(three_d["topics"][topic]["visible"], true, "{topic}");
    }
    assert_eq!(layout["configById"]["RosOut!strata-events"]["topicToRender"], EVENTS_TOPIC);
    let rates = layout["configById"]["Plot!strata-rates"]["paths"].as_array().expect("paths");
    for layer in ["reactive", "deliberative", "planning"] {
        assert!(
            rates.iter().any(|p| p["value"].as_str().is_some_and(|v| {
                v.starts_with(plot::PLOT_TOPIC) && v.ends_with(&format!(".rates.{layer}"))
            })),
            "a plot of the {layer} layer's rate"
        );
    }
}

#[test]
fn a_team_frame_estimate_turns_half_a_turn_for_the_team_attacking_minus_x() {
    let team_frame = Estimate {
        x: -3.0,
        y: 2.0,
        theta: 0.5,
        confidence: 0.7,
        lost: false,
        ball: Some(BallEstimate {
            x: 1.0,
            y: -1.0,
            covariance: [[0.04, 0.01], [0.01, 0.02]],
            known: true,
            confidence: 0.9,
        }),
        team_ball: Some((0.5, 0.25)),
    };
    assert_eq!(team_frame.to_field(1.0), team_frame);
    let field = team_frame.to_field(-1.0);
    assert!(close(field.x, 3.0) && close(field.y, -2.0));
    assert!(close(field.theta, 0.5 - std::f64::consts::PI));
    let ball = field.ball.unwrap_or_else(|| panic!("the ball"));
    assert!(close(ball.x, -1.0) && close(ball.y, 1.0));
    assert_eq!(ball.covariance, [[0.04, 0.01], [0.01, 0.02]], "unchanged by half a turn");
    assert_eq!(field.team_ball, Some((-0.5, -0.25)));
    assert_eq!((field.confidence, field.lost), (0.7, false));
}

#[test]
fn the_recorder_plots_each_robots_layer_rates_with_the_objects() {
    let sim = Simulation::new(SimConfig::default()).expect("the default world");
    let field = sim.field().clone();
    let truth = sim.ground_truth();
    let mut recorder = SceneRecorder::new(config(&field), Vec::new());
    let mut plots = Vec::new();
    // Two seconds: the reactive layer of home/1 every 10 ms, its deliberative layer every
    // 500 ms, the ground truth every 20 ms.
    for k in 0..200u64 {
        let time = Time::from_nanos(k * 10_000_000);
        recorder.layer("home/1", time, plot::LayerKind::Reactive);
        if k % 50 == 0 {
            recorder.layer("home/1", time, plot::LayerKind::Deliberative);
        }
        if k % 2 == 0
            && let Some(plot) = recorder.truth(time, &truth).plot
        {
            plots.push(plot);
        }
    }
    assert_eq!(plots.len(), 20, "one plot with each objects update, ten a second");
    let last = plots.last().expect("plots");
    assert_eq!(last.robots.len(), 1, "only the robot whose layers were heard from");
    let rates = last.robots[0].rates;
    assert_eq!((rates.reactive, rates.deliberative, rates.planning), (100.0, 2.0, 0.0));
}
