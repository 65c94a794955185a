//! The T1's keyframed get-ups against the real rcssservermj: the trainer lays the robot on the
//! ground face down or face up, the robot lies still, is ordered to stand up, and must end
//! upright and stand on the walking policy for five seconds. Each side with a motion in the
//! shipped catalogue is tried a few times; the test prints the success rate and the time from
//! the order to upright (figures, not timed assertions).
//!
//! Needs the server (`scripts/setup-rcssservermj`). Without it the test says so and passes,
//! unless `STRATA_REQUIRE_RCSSSERVERMJ` is set. `STRATA_GETUP_ATTEMPTS` sets the attempts per
//! side (default 10: the first order from the back succeeds in 35-80 % of attempts, and with
//! 5 attempts none did in one of seven runs). A get-up is a throw: MuJoCo runs are close to but not bit-for-bit
//! repeatable, and a small difference decides whether the hips land over the feet. One order
//! does not always succeed (the architecture orders it again while the robot lies fallen), so
//! the test asserts that the robot stands up from each side, and reports how often the first
//! order did.

mod common;

use common::server;

use std::time::{Duration, Instant};

use strata_rcssmj::platform::{RcssConfig, RcssPlatform};
use strata_rcssmj::protocol::monitor::{MonitorCommand, RobotOrientation, TeamRef};
use strata_rcssmj::server::ServerProcess;
use strata_robot::platform::{
    ActuatorOrders, BodyMotionState, BodyOrder, MotionFeedback, Platform, SpecialMotion,
};
use strata_runtime::Time;

const TEAM: &str = "GetUp";
/// Where the robot lies: its own half, clear of everyone.
const SPOT: [f64; 2] = [-3.0, 0.0];

/// The next cycle's server time and motion feedback.
fn next_cycle(robot: &mut RcssPlatform, last: &mut f64) -> (f64, MotionFeedback) {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        assert!(Instant::now() < deadline, "the server stopped advancing");
        match robot.read_sensors(Time::ZERO) {
            Ok(Some(_)) => {}
            Ok(None) => {
                std::thread::sleep(Duration::from_micros(200));
                continue;
            }
            Err(error) => panic!("the platform failed: {error}"),
        }
        let time = robot.ground_truth().expect("truth").time;
        if time > *last {
            *last = time;
            return (time, robot.read_motion(Time::ZERO).expect("motion"));
        }
    }
}

/// Runs `seconds` of simulation, calling `each` every cycle with the time since the start;
/// stops early when it returns false. Returns the last feedback and its time.
fn run_for(
    robot: &mut RcssPlatform,
    last: &mut f64,
    seconds: f64,
    mut each: impl FnMut(&MotionFeedback, f64) -> bool,
) -> (f64, MotionFeedback) {
    let (start, _) = next_cycle(robot, last);
    loop {
        let (time, motion) = next_cycle(robot, last);
        if !each(&motion, time - start) || time - start >= seconds {
            return (time - start, motion);
        }
    }
}

fn order(robot: &mut RcssPlatform, body: BodyOrder) {
    robot.write(Time::ZERO, &ActuatorOrders { head: None, body: Some(body) }).expect("taken");
}

/// One attempt: the robot is laid down with this torso orientation, lies 2 s, is ordered to
/// stand up; `Ok(seconds from the order to standing)` if it then stands 5 s, else what failed.
fn attempt(
    server: &ServerProcess,
    robot: &mut RcssPlatform,
    last: &mut f64,
    sequence: u8,
    orientation: [f64; 4],
) -> Result<f64, String> {
    server.command(vec![MonitorCommand::PlaceRobot {
        team: TeamRef::Name(TEAM.to_owned()),
        player: 1,
        position: [SPOT[0], SPOT[1], 0.25],
        orientation: RobotOrientation::Quaternion(orientation),
    }]);
    let (_, lying) = run_for(robot, last, 2.0, |_, _| true);
    if !matches!(lying.body, BodyMotionState::Fallen { .. }) {
        return Err(format!("laid down, it is not fallen but {:?}", lying.body));
    }
    order(robot, BodyOrder::Special { motion: SpecialMotion::stand_up(sequence) });
    let (took, ended) = run_for(robot, last, 20.0, |motion, t| {
        t < 0.1 || matches!(motion.body, BodyMotionState::Special { .. })
    });
    if ended.body != BodyMotionState::Standing {
        return Err(format!("the get-up ended {:?} after {took:.2} s", ended.body));
    }
    order(robot, BodyOrder::Stand);
    let mut fell = None;
    run_for(robot, last, 5.0, |motion, t| {
        if !matches!(motion.body, BodyMotionState::Standing) {
            fell = Some((t, motion.body));
        }
        fell.is_none()
    });
    match fell {
        Some((t, body)) => Err(format!("stood up in {took:.2} s, then {body:?} after {t:.2} s")),
        None => Ok(took),
    }
}

#[test]
fn a_t1_laid_on_the_ground_stands_up_and_stands() {
    let Some(server) = server() else { return };
    let attempts: usize = std::env::var("STRATA_GETUP_ATTEMPTS")
        .ok()
        .and_then(|n| n.parse().ok())
        .filter(|&n| n > 0)
        .unwrap_or(10);
    let config =
        RcssConfig { pace: 0.0, beam: Some([SPOT[0], SPOT[1], 0.0]), ..RcssConfig::default() };
    let mut robot =
        RcssPlatform::connect(&server.agent_address(), TEAM, 1, config).expect("a T1 connects");
    let motions = robot.info().motions;
    let mut last = f64::NEG_INFINITY;
    order(&mut robot, BodyOrder::Stand);
    run_for(&mut robot, &mut last, 1.0, |_, _| true);

    // Face down: the torso's x axis (forward) points at the ground, a quarter turn about y.
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let sides =
        [(0, "front (face down)", [h, 0.0, h, 0.0]), (1, "back (face up)", [h, 0.0, -h, 0.0])];
    let mut tried = 0;
    for (sequence, side, orientation) in sides {
        if !motions.iter().any(|m| m.motion == SpecialMotion::stand_up(sequence)) {
            println!("from the {side}: no get-up in the catalogue");
            continue;
        }
        tried += 1;
        let mut times = Vec::new();
        for n in 0..attempts {
            match attempt(&server, &mut robot, &mut last, sequence, orientation) {
                Ok(seconds) => times.push(seconds),
                Err(failure) => println!("from the {side}, attempt {}: {failure}", n + 1),
            }
        }
        let mean = times.iter().sum::<f64>() / times.len().max(1) as f64;
        let longest = times.iter().copied().fold(0.0, f64::max);
        println!(
            "from the {side}: stood up and stood 5 s in {} of {attempts} attempts; from the \
             order to upright {mean:.2} s on average, {longest:.2} s at most",
            times.len()
        );
        assert!(!times.is_empty(), "from the {side}: none of {attempts} get-ups succeeded");
    }
    assert!(tried > 0, "the T1's catalogue has no get-up");
    // Each laying down is one placement at most (none when it lay that way already): a fall or
    // a get-up taken for one would make the robot lost for nothing.
    let placements = robot.stats().placements;
    println!("placements reported: {placements} in {} layings", tried * attempts);
    assert!(placements <= (tried * attempts) as u64, "a fall or get-up taken for a placement");
}
