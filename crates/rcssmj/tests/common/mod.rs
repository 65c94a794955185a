//! What the T1's tests against the real server share: starting the server (or skipping when it
//! is not installed) and following a robot through simulation time.

#![allow(dead_code)] // each test binary uses its own part

use std::time::{Duration, Instant};

use strata_rcssmj::platform::{GroundTruth, RcssPlatform};
use strata_rcssmj::server::{ServerError, ServerOptions, ServerProcess};
use strata_robot::platform::{MotionFeedback, Platform};
use strata_runtime::Time;

/// The server, or `None` (the test says so and passes) when it is not installed, unless
/// `STRATA_REQUIRE_RCSSSERVERMJ` is set (as `scripts/test` does after installing it).
pub fn server() -> Option<ServerProcess> {
    match ServerProcess::start(&ServerOptions::default()) {
        Ok(server) => Some(server),
        Err(ServerError::NotInstalled)
            if std::env::var_os("STRATA_REQUIRE_RCSSSERVERMJ").is_none() =>
        {
            eprintln!("rcssservermj is not installed (scripts/setup-rcssservermj): test skipped");
            None
        }
        Err(error) => panic!("starting rcssservermj: {error}"),
    }
}

/// Runs the robot for `seconds` of simulation time, calling `each` every cycle with the newest
/// ground truth, feedback and time since the start; stops early when `each` says so. Returns
/// the last truth.
pub fn run_for(
    robot: &mut RcssPlatform,
    seconds: f64,
    mut each: impl FnMut(&GroundTruth, &MotionFeedback, f64) -> bool,
) -> GroundTruth {
    let start = robot.ground_truth().expect("a first perception").time;
    let deadline = Instant::now() + Duration::from_secs_f64(seconds * 2.0 + 30.0);
    let mut last_time = start;
    loop {
        assert!(Instant::now() < deadline, "the server did not advance {seconds} s in time");
        match robot.read_sensors(Time::ZERO) {
            Ok(Some(_)) => {}
            Ok(None) => {
                std::thread::sleep(Duration::from_micros(200));
                continue;
            }
            Err(error) => panic!("the platform failed: {error}"),
        }
        let truth = robot.ground_truth().expect("truth");
        if truth.time <= last_time {
            continue;
        }
        last_time = truth.time;
        let motion = robot.read_motion(Time::ZERO).expect("motion");
        if !each(&truth, &motion, truth.time - start) || truth.time - start >= seconds {
            return truth;
        }
    }
}
