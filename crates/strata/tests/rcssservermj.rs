//! The full architecture on a Booster T1 against the real rcssservermj (sync mode, paced to
//! real time by the platform): `strata robot --platform rcssservermj` as a user runs it, its
//! JSON lines read by the test, the server's monitor port as the trainer (placing the ball,
//! kicking off) and as the ground truth.
//!
//! Needs the server (`scripts/setup-rcssservermj`). Without it each test says so and passes,
//! unless `STRATA_REQUIRE_RCSSSERVERMJ` is set (as `scripts/test` does after installing it).
//! MuJoCo's physics in another process and the threaded host make runs close to but not
//! bit-for-bit repeatable: the thresholds leave room for that, and each test prints what it
//! measured (`--nocapture`). The scripts follow the simulation's clock, never the wall's.

mod common;

use std::cell::Cell;
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

use common::{Process, strata};
use strata_rcssmj::protocol::FieldSide;
use strata_rcssmj::protocol::monitor::{MonitorCommand, RobotTruth};
use strata_rcssmj::server::{ServerError, ServerOptions, ServerProcess};

/// The server and the robot take most of the machine's two cores: one test at a time.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// The first team to connect is the server's left team: it defends x < 0 and, listed first
/// in the referee's packets, attacks +x, so its team frame is the server's world frame.
const TEAM: u8 = 1;
const TEAM_NAME: &str = "Strata1";

fn server() -> Option<ServerProcess> {
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

/// `strata robot` on the T1: the full soccer robot, JSON lines, stopping by itself.
fn robot(server: &ServerProcess, player: u8, beam: [f64; 3], seconds: f64, seed: u64) -> Process {
    let [x, y, degrees] = beam;
    Process::spawn(
        &format!("robot {TEAM}/{player}"),
        strata().args([
            "robot".to_owned(),
            "--platform".to_owned(),
            "rcssservermj".to_owned(),
            "--server".to_owned(),
            server.agent_address(),
            "--team".to_owned(),
            TEAM.to_string(),
            "--player".to_owned(),
            player.to_string(),
            format!("--beam={x},{y},{degrees}"),
            "--duration".to_owned(),
            seconds.to_string(),
            "--seed".to_owned(),
            seed.to_string(),
            "--status-interval".to_owned(),
            "1".to_owned(),
            "--json".to_owned(),
            "--real-time-priority".to_owned(),
            "0".to_owned(),
        ]),
    )
}

/// The robot's ground truth from the monitor stream, with the simulation time.
fn truth_of(server: &ServerProcess, player: u8) -> Option<(f64, RobotTruth)> {
    let state = server.truth();
    let robot =
        state.robots.into_iter().find(|r| r.team == TEAM_NAME && r.player == u32::from(player))?;
    Some((state.sim_time?, robot))
}

/// Waits until the robot is in the simulation (it has answered and the monitor shows it).
fn wait_in_simulation(server: &ServerProcess, robot: &mut Process, player: u8) -> f64 {
    robot.wait_for("the robot in the simulation", |_| truth_of(server, player).map(|(t, _)| t))
}

/// Follows the simulation until `until` simulated seconds after `from`, calling `each` with
/// every new ground truth of the robot; fails if the robot exits first.
fn follow(
    server: &ServerProcess,
    robot: &mut Process,
    player: u8,
    until: f64,
    mut each: impl FnMut(f64, &RobotTruth),
) {
    let mut last = f64::NEG_INFINITY;
    robot.wait_for(&format!("{until:.1} s of simulation"), |_| {
        let (t, truth) = truth_of(server, player)?;
        if t > last {
            last = t;
            each(t, &truth);
        }
        (t >= until).then_some(())
    });
}

fn ball(x: f64, y: f64) -> MonitorCommand {
    MonitorCommand::PlaceBall { position: [x, y, 0.11], velocity: Some([0.0; 3]) }
}

/// The last JSON line, the report, once the robot has stopped by itself.
fn report(robot: &mut Process) -> serde_json::Value {
    let status = robot.wait_exit();
    assert!(status.success(), "{} exited with {status}\n{}", robot.name, robot.stderr());
    let lines = robot.json_lines();
    let last = lines.last().cloned().unwrap_or_default();
    assert_eq!(last["type"], "report", "the last line is the report: {last}");
    last
}

fn figure(value: &serde_json::Value, pointer: &str) -> f64 {
    value
        .pointer(pointer)
        .and_then(serde_json::Value::as_f64)
        .unwrap_or_else(|| panic!("no number at {pointer} in {value}"))
}

#[test]
fn self_localization_holds_while_the_t1_walks() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(PoisonError::into_inner);
    let Some(server) = server() else { return };
    // Player 3 beamed 5 m from its kick-off position (-1.2, 1.5): in BeforeKickOff (the
    // game's Ready) it walks there. Then the game starts and it chases a ball the trainer
    // moves around a loop.
    let player = 3;
    let mut robot = robot(&server, player, [-5.0, -2.0, 30.0], 52.0, 7);
    let start = wait_in_simulation(&server, &mut robot, player);
    // The distance walked by the ground truth.
    let walked = Cell::new(0.0);
    let mut previous: Option<[f64; 2]> = None;
    let mut track = |_: f64, truth: &RobotTruth| {
        let p = [truth.position[0], truth.position[1]];
        // A jump of a metre between two monitor states is the beam, not a step.
        if let Some(q) = previous
            && (p[0] - q[0]).hypot(p[1] - q[1]) < 1.0
        {
            walked.set(walked.get() + (p[0] - q[0]).hypot(p[1] - q[1]));
        }
        previous = Some(p);
    };
    follow(&server, &mut robot, player, start + 16.0, &mut track);
    let ready_path = walked.get();
    let ready_end = truth_of(&server, player).map(|(_, r)| [r.position[0], r.position[1]]);
    server.command(vec![MonitorCommand::KickOff(Some(FieldSide::Left))]);
    let corners = [(-2.0, 2.5), (-5.0, 2.5), (-5.0, -1.5), (-2.0, -1.5)];
    for (k, (x, y)) in corners.into_iter().enumerate() {
        follow(&server, &mut robot, player, start + 17.0 + 7.0 * k as f64, &mut track);
        server.command(vec![ball(x, y)]);
    }
    let report = report(&mut robot);
    let path = walked.get();
    let localization = &report["localization"];
    println!(
        "walked {path:.2} m by the ground truth ({ready_path:.2} m in Ready, ending at {:?}); \
         localization: {localization}",
        ready_end.map(|[x, y]| format!("({x:.2}, {y:.2})"))
    );
    let mut missions: Vec<String> = Vec::new();
    for status in robot.json_of("status") {
        let seen = format!("{} {}", status["game_state"], status["mission"]);
        if missions.last() != Some(&seen) {
            missions.push(seen);
        }
    }
    println!("game states and missions: {}", missions.join(" -> "));
    let mean = figure(localization, "/converged/mean_error_m");
    let max = figure(localization, "/converged/max_error_m");
    println!(
        "after convergence: mean error {mean:.3} m, max {max:.3} m over {} world states",
        localization["converged"]["samples"]
    );
    assert!(path > 3.0, "the robot walked only {path:.2} m");
    assert!(mean < 0.3, "mean localization error {mean:.3} m while walking");
}

#[test]
fn the_goalkeeper_covers_its_goal_from_where_the_ball_is() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(PoisonError::into_inner);
    let Some(server) = server() else { return };
    let player = 1;
    // Beamed facing its own goal 5 m away, it localizes on the goal's posts and walks back to
    // its kick-off position in the game's Ready.
    let mut robot = robot(&server, player, [-22.0, 0.0, 180.0], 64.0, 11);
    let start = wait_in_simulation(&server, &mut robot, player);
    follow(&server, &mut robot, player, start + 10.0, |_, _| {});
    if let Some((_, keeper)) = truth_of(&server, player) {
        println!(
            "at kick-off the keeper is at ({:.2}, {:.2})",
            keeper.position[0], keeper.position[1]
        );
    }
    server.command(vec![MonitorCommand::KickOff(Some(FieldSide::Left))]);
    // The ball in the keeper's half, to one side then the other: the covering position is on
    // the bisector of the goal's angle from the ball, 0.45 m in front of the goal line.
    let placements = [(-24.0, 5.0), (-24.0, -5.0), (-25.0, 4.0)];
    let mut settled = Vec::new();
    let mut at = start + 11.0;
    for (x, y) in placements {
        follow(&server, &mut robot, player, at, |_, _| {});
        server.command(vec![ball(x, y)]);
        // The T1 covers about 1.5 m sideways in 10 s.
        at += 16.0;
        // Where the keeper stands over the last 3 s of each placement.
        let mut sum = [0.0; 2];
        let mut n = 0.0;
        follow(&server, &mut robot, player, at, |t, truth| {
            if t >= at - 3.0 {
                sum[0] += truth.position[0];
                sum[1] += truth.position[1];
                n += 1.0;
            }
        });
        let keeper = [sum[0] / n, sum[1] / n];
        let ball = server.truth().ball_position.unwrap_or_default();
        println!(
            "ball placed at ({x:.1}, {y:.1}), now at ({:.2}, {:.2}): keeper at ({:.2}, {:.2})",
            ball[0], ball[1], keeper[0], keeper[1]
        );
        settled.push(((x, y), keeper));
    }
    let report = report(&mut robot);
    println!("game states: {}; localization: {}", report["game_states"], report["localization"]);
    for status in robot.json_of("status").iter().step_by(5) {
        println!(
            "{:5.1} s {} {}: pose {}",
            figure(status, "/t"),
            status["game_state"],
            status["mission"],
            status["pose"]
        );
    }
    for ((_, y), keeper) in &settled {
        assert!(keeper[0] < -25.5, "the keeper left its goal: {keeper:?}");
        assert!(y * keeper[1] > 0.0, "the keeper is not on the ball's side ({y}): {keeper:?}");
    }
    let [(_, left), (_, right), _] = settled[..] else { unreachable!("three placements") };
    assert!(left[1] - right[1] > 0.4, "the keeper moved {:.2} m across", left[1] - right[1]);
    let mean = figure(&report["localization"], "/converged/mean_error_m");
    assert!(mean < 0.3, "the keeper's mean localization error {mean:.3} m");
}

#[test]
fn a_killed_server_ends_the_robot_with_a_clear_error() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(PoisonError::into_inner);
    let Some(mut server) = server() else { return };
    let player = 2;
    let mut robot = robot(&server, player, [-3.0, 0.0, 0.0], 120.0, 5);
    robot.wait_for("sensor frames", |p| {
        p.json_of("status")
            .into_iter()
            .find(|s| s["sensor_frames"].as_u64().unwrap_or(0) > 100)
            .map(|_| ())
    });
    server.kill();
    let killed = Instant::now();
    let status = robot.wait_exit();
    let took = killed.elapsed();
    let lines = robot.json_lines();
    let last = lines.last().cloned().unwrap_or_default();
    let ended = last["ended"].as_str().unwrap_or_default().to_owned();
    println!("the robot stopped {took:.1?} after the server was killed ({status}): {ended}");
    assert!(!robot.stderr().contains("panicked"), "{}", robot.stderr());
    assert_eq!(last["type"], "report", "a report after the lost server: {last}");
    assert!(
        ended.contains("platform disconnected") && ended.contains("rcssservermj"),
        "the report names the lost server: {ended}"
    );
    assert!(status.success(), "{status}\n{}", robot.stderr());
    // Bounds a hang, not a speed: the platform notices a silent server within its stall
    // timeout (2 s).
    assert!(took < Duration::from_secs(20), "the robot took {took:?} to stop");
}
