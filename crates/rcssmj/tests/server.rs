//! The T1 against the real rcssservermj, in sync mode and as fast as the server runs (the
//! platform's `pace` 0): standing, walking to a point, turning, a lost server.
//!
//! Needs the server (`scripts/setup-rcssservermj`). Without it each test says so and passes,
//! unless `STRATA_REQUIRE_RCSSSERVERMJ` is set (as `scripts/test` does after installing it).
//! The physics is MuJoCo's, not ours, and the server steps when our answer arrives, so a run
//! is close to but not bit-for-bit repeatable: the thresholds leave room for that.

mod common;

use common::{run_for, server};

use std::time::{Duration, Instant};

use strata_rcssmj::platform::{RcssConfig, RcssPlatform};
use strata_rcssmj::protocol::monitor::{MonitorCommand, RobotOrientation, TeamRef};
use strata_rcssmj::server::ServerProcess;
use strata_robot::geometry::Velocity;
use strata_robot::platform::{
    ActuatorOrders, BodyMotionState, BodyOrder, MotionFeedback, Platform, PlatformError,
};
use strata_runtime::Time;

fn t1(server: &ServerProcess, team: &str, beam: [f64; 3]) -> RcssPlatform {
    let config = RcssConfig { pace: 0.0, beam: Some(beam), ..RcssConfig::default() };
    RcssPlatform::connect(&server.agent_address(), team, 1, config).expect("a T1 connects")
}

fn fallen(motion: &MotionFeedback) -> bool {
    matches!(motion.body, BodyMotionState::Fallen { .. })
}

fn order(robot: &mut RcssPlatform, body: BodyOrder) {
    robot
        .write(Time::ZERO, &ActuatorOrders { head: None, body: Some(body) })
        .expect("orders are taken");
}

#[test]
fn a_t1_stands_thirty_seconds() {
    let Some(server) = server() else { return };
    let mut robot = t1(&server, "Stand", [-3.0, 0.0, 0.0]);
    order(&mut robot, BodyOrder::Stand);
    let mut lowest = f64::INFINITY;
    let truth = run_for(&mut robot, 30.0, |truth, motion, t| {
        if t > 1.0 {
            lowest = lowest.min(truth.position[2]);
            assert!(!fallen(motion), "fell at {t:.2} s");
        }
        true
    });
    assert!(lowest > 0.55, "the torso sank to {lowest:.3} m");
    println!("stood 30 s: torso at {:.3} m, lowest {lowest:.3} m", truth.position[2]);
}

#[test]
fn a_t1_walks_three_metres_by_odometry_and_stops() {
    let Some(server) = server() else { return };
    let mut robot = t1(&server, "Walker", [-6.0, 0.0, 0.0]);
    order(&mut robot, BodyOrder::Stand);
    let settled = run_for(&mut robot, 2.0, |_, _, _| true);
    let start = [settled.position[0], settled.position[1]];
    // The command is smoothed by 0.02 m/s per 20 ms cycle (1 m/s^2): stopping from 0.5 m/s
    // takes another 0.125 m, so the order to stand goes out that much before the point.
    let speed = 0.5;
    let braking = speed * speed / 2.0;
    order(&mut robot, BodyOrder::Walk { velocity: Velocity::new(speed, 0.0, 0.0) });
    let mut travelled = 0.0;
    let mut cruise = None;
    run_for(&mut robot, 20.0, |truth, motion, t| {
        assert!(!fallen(motion), "fell while walking");
        travelled += motion.odometry.dx;
        // Cruise speed from the ground truth between 2 s and 6 s of walking.
        if t >= 2.0 && cruise.is_none() {
            cruise = Some((t, [truth.position[0], truth.position[1]], 0.0));
        }
        if let Some((t0, p0, speed)) = &mut cruise
            && t <= 6.0
        {
            *speed = (truth.position[0] - p0[0]).hypot(truth.position[1] - p0[1]) / (t - *t0);
        }
        travelled < 3.0 - braking
    });
    order(&mut robot, BodyOrder::Stand);
    let end = run_for(&mut robot, 2.0, |_, motion, _| {
        assert!(!fallen(motion), "fell stopping");
        travelled += motion.odometry.dx;
        true
    });
    let distance = (end.position[0] - start[0]).hypot(end.position[1] - start[1]);
    let cruise_speed = cruise.map_or(0.0, |(_, _, s)| s);
    println!(
        "odometry said {travelled:.2} m; the ground truth moved {distance:.2} m; cruise speed \
         {cruise_speed:.3} m/s for {speed} commanded (tracking error {:+.1} %)",
        (cruise_speed / speed - 1.0) * 100.0
    );
    assert!((distance - 3.0).abs() < 0.3, "walked {distance:.2} m to a point 3 m away");
}

#[test]
fn a_t1_turns_half_a_circle_in_place() {
    let Some(server) = server() else { return };
    let mut robot = t1(&server, "Turn", [-3.0, 3.0, 0.0]);
    order(&mut robot, BodyOrder::Stand);
    let settled = run_for(&mut robot, 2.0, |_, _, _| true);
    // Stopping from 0.6 rad/s at the policy's smoothing of 0.02 rad/s per cycle turns another
    // 0.18 rad: the order to stand goes out that much before half a circle.
    let rate = 0.6;
    order(&mut robot, BodyOrder::Walk { velocity: Velocity::new(0.0, 0.0, rate) });
    let mut turned = 0.0;
    run_for(&mut robot, 20.0, |_, motion, _| {
        assert!(!fallen(motion), "fell while turning");
        turned += motion.odometry.dtheta;
        turned < std::f64::consts::PI - rate * rate / 2.0
    });
    order(&mut robot, BodyOrder::Stand);
    let end = run_for(&mut robot, 2.0, |_, _, _| true);
    let heading = strata_robot::geometry::normalize_angle(end.heading - settled.heading);
    let error = strata_robot::geometry::normalize_angle(heading - std::f64::consts::PI);
    let drift =
        (end.position[0] - settled.position[0]).hypot(end.position[1] - settled.position[1]);
    println!(
        "turned {:.0} degrees by the ground truth ({:+.0} from 180), drifting {drift:.2} m",
        heading.rem_euclid(std::f64::consts::TAU).to_degrees(),
        error.to_degrees()
    );
    assert!(error.abs() < 20f64.to_radians(), "turned {:.0} degrees", heading.to_degrees());
    assert!(drift < 0.5, "drifted {drift:.2} m turning in place");
}

#[test]
fn a_lost_server_ends_the_robot_with_a_clear_error() {
    let Some(mut server) = server() else { return };
    let mut robot = t1(&server, "Lost", [-3.0, -3.0, 0.0]);
    run_for(&mut robot, 0.5, |_, _, _| true);
    server.kill();
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        if let Err(PlatformError::Disconnected(reason)) = robot.read_sensors(Time::ZERO) {
            assert!(reason.contains("rcssservermj"), "{reason}");
            break;
        }
        assert!(Instant::now() < deadline, "the lost server went unnoticed");
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(matches!(robot.read_motion(Time::ZERO), Err(PlatformError::Disconnected(_))));
}

/// Reads the robot's sensor frames for `seconds` of simulation time; returns how many said the
/// robot was placed.
fn placements_within(robot: &mut RcssPlatform, seconds: f64) -> usize {
    let start = robot.ground_truth().expect("a first perception").time;
    let deadline = Instant::now() + Duration::from_secs_f64(seconds * 2.0 + 30.0);
    let mut placed = 0;
    loop {
        assert!(Instant::now() < deadline, "the server did not advance {seconds} s in time");
        match robot.read_sensors(Time::ZERO) {
            Ok(Some(frame)) => placed += usize::from(frame.placed),
            Ok(None) => std::thread::sleep(Duration::from_micros(200)),
            Err(error) => panic!("the platform failed: {error}"),
        }
        robot.read_motion(Time::ZERO).expect("motion");
        if robot.ground_truth().is_some_and(|t| t.time - start >= seconds) {
            return placed;
        }
    }
}

/// The server moving the robot (the referee's `_penalize`; here the monitor port, as a trainer)
/// is reported in the sensor frame, once, for world modeling to declare a kidnap; the platform's
/// own beam at the start is not (the robot starts from the beam's pose). A move that keeps the
/// heading is invisible to the IMU, and so to the platform.
#[test]
fn a_t1_placed_by_the_server_is_reported_and_its_own_beam_is_not() {
    let Some(server) = server() else { return };
    // Spawned at the side line facing into the field, beamed facing along x: a quarter turn.
    let mut robot = t1(&server, "Placed", [-3.0, 0.0, 0.0]);
    order(&mut robot, BodyOrder::Stand);
    assert_eq!(placements_within(&mut robot, 3.0), 0, "the platform's own beam");
    let place = |x: f64, yaw: f64| {
        server.command(vec![MonitorCommand::PlaceRobot {
            team: TeamRef::Name("Placed".to_owned()),
            player: 1,
            position: [x, -5.0, 0.6735],
            orientation: RobotOrientation::Yaw(yaw),
        }]);
    };
    let facing_in = std::f64::consts::FRAC_PI_2;
    place(-2.0, facing_in);
    assert_eq!(placements_within(&mut robot, 3.0), 1, "moved and turned a quarter");
    place(-4.0, facing_in);
    assert_eq!(placements_within(&mut robot, 3.0), 0, "moved 2 m, the heading kept");
    place(-6.0, facing_in + 0.5);
    assert_eq!(placements_within(&mut robot, 3.0), 1, "moved and turned 0.5 rad");
    assert_eq!(robot.stats().placements, 2);
}

/// A fake server on loopback that answers `init` with a script of frames: what a broken or
/// hostile server can send.
fn fake_server(script: Vec<Vec<u8>>) -> (String, std::thread::JoinHandle<()>) {
    use std::io::{Read, Write};
    let listener = std::net::TcpListener::bind("127.0.0.1:0").expect("a loopback port");
    let address = listener.local_addr().expect("bound").to_string();
    let thread = std::thread::spawn(move || {
        let Ok((mut stream, _)) = listener.accept() else { return };
        let mut length = [0u8; 4];
        if stream.read_exact(&mut length).is_err() {
            return;
        }
        let mut init = vec![0u8; u32::from_be_bytes(length) as usize];
        if stream.read_exact(&mut init).is_err() {
            return;
        }
        for frame in script {
            if stream.write_all(&frame).is_err() {
                return;
            }
            // The robot answers each perception; read what it sends so it never blocks.
            let mut answer = [0u8; 65536];
            let _ = stream.set_read_timeout(Some(Duration::from_millis(200)));
            let _ = stream.read(&mut answer);
        }
    });
    (address, thread)
}

fn framed(payload: &[u8]) -> Vec<u8> {
    let mut frame = (payload.len() as u32).to_be_bytes().to_vec();
    frame.extend_from_slice(payload);
    frame
}

#[test]
fn garbage_from_the_server_is_an_error_named_and_never_a_panic() {
    let good = std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/perception_first_cycle_see.sexp"
    ))
    .expect("fixture");
    let script = vec![
        framed(&good),
        framed(b"(time (now 1.0))(quat (n torso_quat) (q nonsense"),
        framed(&[0xff, 0xfe, 0x00, 0x28]),
        framed(&good),
        // A length prefix announcing 3 GB: the link cannot be trusted after that.
        vec![0xb0, 0, 0, 0, b'('],
    ];
    let (address, server) = fake_server(script);
    let config = RcssConfig { pace: 0.0, ..RcssConfig::default() };
    let mut robot = RcssPlatform::connect(&address, "Fake", 1, config).expect("a first perception");
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut frames = 0;
    let mut malformed = Vec::new();
    let disconnected = loop {
        assert!(Instant::now() < deadline, "the broken server went unnoticed");
        match robot.read_sensors(Time::ZERO) {
            Ok(Some(_)) => frames += 1,
            Ok(None) => std::thread::sleep(Duration::from_millis(5)),
            Err(PlatformError::Malformed(reason)) => malformed.push(reason),
            Err(PlatformError::Disconnected(reason)) => break reason,
            Err(other) => panic!("unexpected error: {other}"),
        }
    };
    println!("frames {frames}, malformed {malformed:?}, then: {disconnected}");
    assert!(frames >= 1, "the valid perceptions were lost");
    assert!(
        malformed.iter().any(|m| m.contains("quat") || m.contains("S-expression")),
        "{malformed:?}"
    );
    assert!(disconnected.contains("bytes"), "the oversized frame is named: {disconnected}");
    assert_eq!(robot.stats().malformed, 2);
    server.join().expect("the fake server ends");
}

/// How far the T1 moves for small walk orders: each order for 4 s from standing, forward,
/// sideways, turning and backwards, by the ground truth. A tuning bench for the soccer
/// primitives' approach (2026-11-27: 0.02 m/s forward moved it 0.1 m, since walking on the
/// spot creeps forward; -0.04 m/s backwards did not move it).
#[test]
#[ignore = "a tuning bench: run with --ignored --nocapture"]
fn small_walk_orders() {
    let Some(server) = server() else { return };
    let mut robot = t1(&server, "Small", [-3.0, 0.0, 0.0]);
    let orders: [(f64, f64, f64); 12] = [
        (0.02, 0.0, 0.0),
        (0.04, 0.0, 0.0),
        (0.06, 0.0, 0.0),
        (0.1, 0.0, 0.0),
        (0.0, 0.02, 0.0),
        (0.0, 0.04, 0.0),
        (0.0, 0.08, 0.0),
        (0.0, 0.0, 0.05),
        (0.0, 0.0, 0.1),
        (0.0, 0.0, 0.2),
        (-0.04, 0.0, 0.0),
        (-0.1, 0.0, 0.0),
    ];
    for (vx, vy, omega) in orders {
        order(&mut robot, BodyOrder::Stand);
        let before = run_for(&mut robot, 2.0, |_, _, _| true);
        order(&mut robot, BodyOrder::Walk { velocity: Velocity::new(vx, vy, omega) });
        let after = run_for(&mut robot, 4.0, |_, motion, t| {
            assert!(!fallen(motion), "fell at {t:.2} s walking ({vx}, {vy}, {omega})");
            true
        });
        let (c, s) = (before.heading.cos(), before.heading.sin());
        let dx = after.position[0] - before.position[0];
        let dy = after.position[1] - before.position[1];
        let turned = strata_robot::geometry::normalize_angle(after.heading - before.heading);
        println!(
            "order ({vx:+.2}, {vy:+.2}, {omega:+.2}) for 4 s: forward {:+.3} m, left {:+.3} m, \
             turned {:+.3} rad (commanded {:+.3} m, {:+.3} m, {:+.3} rad)",
            c * dx + s * dy,
            -s * dx + c * dy,
            turned,
            vx * 4.0,
            vy * 4.0,
            omega * 4.0
        );
    }
}
