//! Sensor simulation: noise statistics over many seeded samples, detection rates, the camera's
//! field of view, range, vertical coverage and occlusion, line features.

mod common;

use common::*;
use strata_robot::Vector;
use strata_robot::platform::{Detection, SensorFrame};
use strata_sim::{RobotId, SimConfig, Simulation};
use strata_spl::ObjectKind;

fn frames(sim: &mut Simulation, robot: RobotId, seconds: f64) -> Vec<SensorFrame> {
    let mut out = Vec::new();
    let steps = (seconds / 0.012).round() as usize;
    for _ in 0..steps {
        sim.run_for(std::time::Duration::from_millis(12));
        if let Some(frame) = sim.take_sensor_frame(robot).expect("known robot") {
            out.push(frame);
        }
    }
    out
}

fn of(detections: &[Detection], kind: ObjectKind) -> Vec<Detection> {
    detections.iter().filter(|d| d.class.0 == kind.code()).copied().collect()
}

fn mean_std(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, var.sqrt())
}

/// A world with default noise, a manual referee, one robot at the origin facing +x.
fn noisy(adjust: impl FnOnce(&mut SimConfig)) -> Simulation {
    let mut sim = quiet(|c| {
        c.noise = SimConfig::default().noise;
        adjust(c);
    });
    only(&mut sim, &[A1]);
    place(&mut sim, A1, 0.0, 0.0, 0.0);
    sim
}

#[test]
fn imu_encoder_and_foot_noise_have_the_configured_deviation() {
    let mut sim = noisy(|_| {});
    let noise = sim.noise().imu.clone();
    let samples = frames(&mut sim, A1, 60.0);
    assert_eq!(samples.len(), 5000, "83 Hz for 60 s");
    let check = |name: &str, values: Vec<f64>, truth: f64, sigma: f64| {
        let (mean, std) = mean_std(&values);
        assert!(
            (mean - truth).abs() < 4.0 * sigma / (values.len() as f64).sqrt(),
            "{name}: mean {mean}"
        );
        assert!((std / sigma - 1.0).abs() < 0.05, "{name}: std {std}, configured {sigma}");
    };
    check(
        "accel x",
        samples.iter().map(|f| f.inertial.accelerometer[0]).collect(),
        0.0,
        noise.accel_sigma,
    );
    check(
        "accel z",
        samples.iter().map(|f| f.inertial.accelerometer[2]).collect(),
        9.81,
        noise.accel_sigma,
    );
    check(
        "gyro y",
        samples.iter().map(|f| f.inertial.gyroscope[1]).collect(),
        0.0,
        noise.gyro_sigma,
    );
    check(
        "roll",
        samples.iter().map(|f| f.inertial.body_angles[0]).collect(),
        0.0,
        noise.angle_sigma,
    );
    check("head yaw", samples.iter().map(|f| f.head.yaw).collect(), 0.0, noise.joint_sigma);
    let half = sim.config().robot.mass / 2.0;
    check(
        "left foot",
        samples.iter().map(|f| f.foot_contact.left).collect(),
        half,
        noise.foot_sigma,
    );
    // Camera images arrive at 30 Hz, attached to sensor frames.
    let images = samples.iter().filter(|f| f.camera.is_some()).count();
    assert!((1795..=1805).contains(&images), "{images} images in 60 s");
}

#[test]
fn range_and_bearing_noise_grow_with_distance_and_detections_thin_out() {
    for distance in [1.5, 4.5] {
        // False positives would pollute the statistics of the real ball.
        let mut sim = noisy(|c| c.noise.camera.false_positive_rate = Some(0.0));
        sim.place_ball(point(distance, 0.0), Vector::new(0.0, 0.0)).expect("valid ball");
        look(&mut sim, A1, 0.0, 0.3);
        let camera = sim.noise().camera.clone();
        let range = sim.config().robot.camera.range;
        let images: Vec<_> =
            frames(&mut sim, A1, 200.0).into_iter().filter_map(|f| f.camera).collect();
        let balls: Vec<Detection> = images
            .iter()
            .filter_map(|c| {
                of(&c.detections, ObjectKind::Ball)
                    .into_iter()
                    .find(|d| d.range < 8.0 && d.bearing.abs() < 0.3)
            })
            .collect();
        let rate = balls.len() as f64 / images.len() as f64;
        let expected = camera.detection_near
            + (camera.detection_far - camera.detection_near) * distance / range;
        assert!(
            (rate - expected).abs() < 0.03,
            "at {distance} m: rate {rate}, expected {expected}"
        );
        let (mean, std) = mean_std(&balls.iter().map(|d| d.range).collect::<Vec<_>>());
        let sigma = camera.range_sigma + camera.range_sigma_per_metre * distance;
        assert!((mean - distance).abs() < 0.02, "range mean {mean}");
        assert!((std / sigma - 1.0).abs() < 0.08, "range std {std}, configured {sigma}");
        let (mean, std) = mean_std(&balls.iter().map(|d| d.bearing).collect::<Vec<_>>());
        let sigma = camera.bearing_sigma + camera.bearing_sigma_per_metre * distance;
        assert!(mean.abs() < 0.005, "bearing mean {mean}");
        assert!((std / sigma - 1.0).abs() < 0.08, "bearing std {std}, configured {sigma}");
    }
}

#[test]
fn a_moving_head_blurs_detections_away() {
    let detection_rate = |moving: bool| {
        let mut sim = noisy(|c| c.noise.camera.false_positive_rate = Some(0.0));
        sim.place_ball(point(2.0, 0.0), Vector::new(0.0, 0.0)).expect("valid ball");
        let mut images = 0;
        let mut seen = 0;
        let mut target = 0.15;
        let steps = (120.0 / 0.012) as usize;
        for _ in 0..steps {
            if moving {
                let head = sim.robot(A1).expect("a").head;
                if (head.yaw - target).abs() < 1e-9 {
                    target = -target;
                }
                let orders = strata_robot::platform::ActuatorOrders {
                    head: Some(strata_robot::platform::HeadOrder {
                        target: strata_robot::platform::HeadAngles { yaw: target, pitch: 0.3 },
                        max_speed: 2.0,
                    }),
                    body: None,
                };
                sim.apply_orders(A1, &orders).expect("valid");
            } else {
                look(&mut sim, A1, 0.0, 0.3);
            }
            sim.run_for(std::time::Duration::from_millis(12));
            if let Some(camera) = sim.take_sensor_frame(A1).expect("known").and_then(|f| f.camera) {
                images += 1;
                seen += usize::from(
                    of(&camera.detections, ObjectKind::Ball)
                        .iter()
                        .any(|d| (d.range - 2.0).abs() < 1.0),
                );
            }
        }
        seen as f64 / images as f64
    };
    let still = detection_rate(false);
    let moving = detection_rate(true);
    // 2 rad/s at 0.12 per rad/s: 76 % of the still rate (a little more: the head slows to turn).
    let ratio = moving / still;
    assert!((0.74..0.84).contains(&ratio), "still {still}, moving {moving}");
}

#[test]
fn false_positives_appear_at_the_configured_rate() {
    let mut sim = quiet(|c| c.noise.camera.false_positive_rate = Some(0.25));
    only(&mut sim, &[A1]);
    // At a corner of the carpet, looking out: nothing real to see.
    place(&mut sim, A1, -5.0, -3.5, -2.4);
    let images: Vec<_> = frames(&mut sim, A1, 100.0).into_iter().filter_map(|f| f.camera).collect();
    let ghosts: usize = images.iter().map(|c| c.detections.len()).sum();
    let rate = ghosts as f64 / images.len() as f64;
    assert!((rate - 0.25).abs() < 0.03, "{rate}");
    assert!(images.iter().all(|c| c.detections.len() <= 1));
}

fn one_image(sim: &mut Simulation) -> Vec<Detection> {
    for _ in 0..10 {
        sim.run_for(std::time::Duration::from_millis(12));
        if let Some(camera) = sim.take_sensor_frame(A1).expect("known").and_then(|f| f.camera) {
            return camera.detections;
        }
    }
    Vec::new()
}

#[test]
fn only_what_is_in_the_field_of_view_and_range_is_seen() {
    let mut sim = quiet(|_| {});
    only(&mut sim, &[A1]);
    place(&mut sim, A1, -2.0, 0.0, 0.0);
    look(&mut sim, A1, 0.0, 0.0);
    sim.place_ball(point(0.0, 0.5), Vector::new(0.0, 0.0)).expect("valid ball");
    steps(&mut sim, 0.5);
    let ball = of(&one_image(&mut sim), ObjectKind::Ball);
    assert_eq!(ball.len(), 1);
    assert!((ball[0].range - 2.0f64.hypot(0.5)).abs() < 1e-12);
    assert!((ball[0].bearing - 0.5f64.atan2(2.0)).abs() < 1e-12);
    // 45 degrees to the left is outside a 61-degree view ...
    sim.place_ball(point(0.0, 2.0), Vector::new(0.0, 0.0)).expect("valid ball");
    assert!(of(&one_image(&mut sim), ObjectKind::Ball).is_empty());
    // ... until the head turns: bearings are relative to the camera axis.
    look(&mut sim, A1, 0.8, 0.0);
    steps(&mut sim, 0.5);
    let ball = of(&one_image(&mut sim), ObjectKind::Ball);
    assert_eq!(ball.len(), 1);
    assert!((ball[0].bearing - (std::f64::consts::FRAC_PI_4 - 0.8)).abs() < 1e-12);
    // Beyond the range, and behind, nothing.
    look(&mut sim, A1, 0.0, 0.0);
    steps(&mut sim, 0.5);
    sim.place_ball(point(4.1, 0.0), Vector::new(0.0, 0.0)).expect("valid ball");
    assert!(of(&one_image(&mut sim), ObjectKind::Ball).is_empty(), "6.1 m away");
    sim.place_ball(point(-3.0, 0.0), Vector::new(0.0, 0.0)).expect("valid ball");
    assert!(of(&one_image(&mut sim), ObjectKind::Ball).is_empty(), "behind");
    // Looking down (to the pitch limit, 0.515 rad) shortens the view on the ground to 4.3 m,
    // not for goal posts.
    place(&mut sim, A1, -0.5, 0.0, 0.0);
    sim.place_ball(point(4.0, 0.0), Vector::new(0.0, 0.0)).expect("valid ball");
    look(&mut sim, A1, 0.0, 0.6);
    steps(&mut sim, 0.5);
    let image = one_image(&mut sim);
    assert!(of(&image, ObjectKind::Ball).is_empty(), "4.5 m is beyond the ground the camera sees");
    assert_eq!(of(&image, ObjectKind::GoalPost).len(), 2, "{image:?}");
}

#[test]
fn robots_hide_what_is_behind_them() {
    let mut sim = quiet(|_| {});
    only(&mut sim, &[A1, B1]);
    place(&mut sim, A1, 0.0, 0.0, 0.0);
    place(&mut sim, B1, 1.0, 0.0, std::f64::consts::PI);
    look(&mut sim, A1, 0.0, 0.2);
    sim.place_ball(point(2.0, 0.0), Vector::new(0.0, 0.0)).expect("valid ball");
    steps(&mut sim, 0.5);
    let image = one_image(&mut sim);
    assert!(of(&image, ObjectKind::Ball).is_empty(), "hidden by the robot");
    let robots = of(&image, ObjectKind::Robot);
    assert_eq!(robots.len(), 1);
    assert!((robots[0].range - 1.0).abs() < 1e-12);
    let jersey = u16::from(u8::from(sim.config().referee.teams[1].goalkeeper_colour));
    assert_eq!(robots[0].variant, Some(jersey), "player 1 wears the goalkeeper colour");
    place(&mut sim, B1, 1.0, 0.5, std::f64::consts::PI);
    let image = one_image(&mut sim);
    assert_eq!(of(&image, ObjectKind::Ball).len(), 1, "in sight again");
}

#[test]
fn line_features_and_crossings_are_reported_with_their_orientation() {
    let mut sim = quiet(|_| {});
    only(&mut sim, &[A1]);
    // Facing the left side line from 3 m, the T where the halfway line meets it to the right.
    place(&mut sim, A1, -1.0, 0.0, std::f64::consts::FRAC_PI_2);
    look(&mut sim, A1, 0.0, 0.2);
    sim.place_ball(point(-4.0, -2.0), Vector::new(0.0, 0.0)).expect("valid ball");
    steps(&mut sim, 0.5);
    let image = one_image(&mut sim);
    let lines = of(&image, ObjectKind::FieldLine);
    let side = lines.iter().find(|d| (d.range - 3.0).abs() < 1e-9).expect("the side line");
    assert!(side.bearing.abs() < 1e-12);
    let orientation = side.orientation.expect("lines have a direction");
    assert!((orientation.abs() - std::f64::consts::FRAC_PI_2).abs() < 1e-12, "{orientation}");
    let t = of(&image, ObjectKind::TCrossing);
    assert_eq!(t.len(), 1, "{image:?}");
    assert!((t[0].range - 10f64.sqrt()).abs() < 1e-12);
    assert!((t[0].bearing + (1.0f64).atan2(3.0)).abs() < 1e-12);
    // The T's stem points into the field (-y), i.e. back towards the robot: pi from the axis.
    let stem = t[0].orientation.expect("crossings have an orientation");
    assert!((stem.abs() - std::f64::consts::PI).abs() < 1e-12, "{stem}");
}

#[test]
fn odometry_errors_have_the_configured_bias_and_deviation() {
    // Exact legs, odometry with a 10 % forward bias and sigma_xy = 0.05 per sqrt(m).
    let mut sim = quiet(|c| {
        c.noise.odometry.scale_x = Some(0.1);
        c.noise.odometry.sigma_xy = Some(0.05);
    });
    only(&mut sim, &[A1]);
    let mut errors = Vec::new();
    for run in 0..300 {
        // Every run walks about 1 m straight ahead from the same place.
        place(&mut sim, A1, -2.0, 0.0, 0.0);
        walk(&mut sim, A1, 0.0, 0.0, 0.0);
        steps(&mut sim, 1.0);
        let _ = sim.read_motion(A1);
        let start = sim.robot(A1).expect("a").pose;
        walk(&mut sim, A1, 0.25, 0.0, 0.0);
        steps(&mut sim, 4.3 + 0.001 * f64::from(run % 3));
        walk(&mut sim, A1, 0.0, 0.0, 0.0);
        steps(&mut sim, 1.5);
        let odometry = sim.read_motion(A1).expect("motion").odometry;
        let truth = start.odometry_to(&sim.robot(A1).expect("a").pose);
        errors.push(((odometry.dx - 1.1 * truth.dx) / truth.dx.sqrt(), truth.dx));
    }
    let walked = errors.iter().map(|e| e.1).sum::<f64>() / errors.len() as f64;
    assert!((0.8..1.2).contains(&walked), "walked {walked} m per run");
    let (mean, std) = mean_std(&errors.iter().map(|e| e.0).collect::<Vec<_>>());
    assert!(mean.abs() < 0.01, "random error mean {mean}");
    assert!((std / 0.05 - 1.0).abs() < 0.12, "random error per sqrt(m) {std}, configured 0.05");
}

#[test]
fn the_paper_field_has_beacons_and_coloured_goals() {
    let mut sim = quiet(|c| c.field = "paper2010".to_owned());
    only(&mut sim, &[A1]);
    place(&mut sim, A1, 0.0, 0.0, std::f64::consts::FRAC_PI_2);
    look(&mut sim, A1, 0.0, 0.0);
    steps(&mut sim, 0.5);
    let beacons = of(&one_image(&mut sim), ObjectKind::Beacon);
    assert_eq!(beacons.len(), 1);
    assert_eq!(beacons[0].variant, Some(0), "the left beacon (index 0)");
    assert!((beacons[0].range - 2.4).abs() < 1e-12);
    place(&mut sim, A1, 0.0, 0.0, 0.0);
    steps(&mut sim, 0.1);
    let posts = of(&one_image(&mut sim), ObjectKind::GoalPost);
    assert_eq!(posts.len(), 2);
    let yellow = strata_spl::field::Colour::Yellow.code();
    assert!(posts.iter().all(|p| p.variant == Some(yellow)), "{posts:?}");
}
