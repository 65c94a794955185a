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
use strata_rcssmj::protocol::monitor::{MonitorCommand, RobotOrientation, RobotTruth, TeamRef};
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
    robot_with(server, player, beam, seconds, seed, &[])
}

/// [`robot`] with more options.
fn robot_with(
    server: &ServerProcess,
    player: u8,
    beam: [f64; 3],
    seconds: f64,
    seed: u64,
    extra: &[&str],
) -> Process {
    let [x, y, degrees] = beam;
    Process::spawn(
        &format!("robot {TEAM}/{player}"),
        strata()
            .args([
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
                "--json".to_owned(),
                "--real-time-priority".to_owned(),
                "0".to_owned(),
            ])
            // A status a second unless the test asks for another interval.
            .args(
                (!extra.contains(&"--status-interval"))
                    .then_some(["--status-interval", "1"])
                    .into_iter()
                    .flatten(),
            )
            .args(extra),
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

/// The keeper covers its goal. Against MuJoCo in another process no two runs are the same (the
/// robot's threads and the server's cycles interleave as the machine's load has them), so a
/// failed run is tried once more with another seed, and a keeper that no longer covers its goal
/// fails both. Two causes of such failures on a loaded machine are fixed, and tested where they
/// are deterministic: a head path that stopped for good (actuation) and a fall that left the
/// pose 1-2 m off and too sure of itself (world modeling).
#[test]
fn the_goalkeeper_covers_its_goal_from_where_the_ball_is() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(PoisonError::into_inner);
    if let Err(first) = keeper_covers_its_goal(11) {
        println!("first run: {first}; running again with another seed");
        if let Err(second) = keeper_covers_its_goal(12) {
            panic!("the keeper failed twice: {first}; then {second}");
        }
    }
}

/// One run of the keeper test (`Ok` without running when the server is not installed).
fn keeper_covers_its_goal(seed: u64) -> Result<(), String> {
    let Some(server) = server() else { return Ok(()) };
    let player = 1;
    // Beamed facing its own goal 5 m away, it localizes on the goal's posts and walks back to
    // its kick-off position in the game's Ready.
    let mut robot = robot(&server, player, [-22.0, 0.0, 180.0], 64.0, seed);
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
            "{:5.1} s {} {}: pose {}, ball {}",
            figure(status, "/t"),
            status["game_state"],
            status["mission"],
            status["pose"],
            status["ball"]
        );
    }
    for ((_, y), keeper) in &settled {
        if keeper[0] >= -25.5 {
            return Err(format!("the keeper left its goal: {keeper:?}"));
        }
        if y * keeper[1] <= 0.0 {
            return Err(format!("the keeper is not on the ball's side ({y}): {keeper:?}"));
        }
    }
    let [(_, left), (_, right), _] = settled[..] else { unreachable!("three placements") };
    if left[1] - right[1] <= 0.4 {
        return Err(format!("the keeper moved {:.2} m across", left[1] - right[1]));
    }
    let mean = figure(&report["localization"], "/converged/mean_error_m");
    if mean >= 0.3 {
        return Err(format!("the keeper's mean localization error {mean:.3} m"));
    }
    Ok(())
}

#[test]
fn a_killed_server_ends_the_robot_with_a_clear_error() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(PoisonError::into_inner);
    let Some(mut server) = server() else { return };
    let player = 2;
    let dir = std::env::temp_dir().join(format!("strata-rcss-lost-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    let log = dir.join("robot.mcap");
    let log_arg = log.to_str().expect("a UTF-8 path");
    let mut robot = robot_with(&server, player, [-3.0, 0.0, 0.0], 120.0, 5, &["--log", log_arg]);
    robot.wait_for("sensor frames", |p| {
        p.json_of("status")
            .into_iter()
            .find(|s| s["sensor_frames"].as_u64().unwrap_or(0) > 100)
            .map(|_| ())
    });
    let address = server.agent_address();
    server.kill();
    let killed = Instant::now();
    let status = robot.wait_exit();
    let took = killed.elapsed();
    let lines = robot.json_lines();
    let last = lines.last().cloned().unwrap_or_default();
    let ended = last["ended"].as_str().unwrap_or_default().to_owned();
    let stderr = robot.stderr();
    println!("the robot stopped {took:.1?} after the server was killed ({status}): {ended}");
    println!("its stderr:\n{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(last["type"], "report", "a report after the lost server: {last}");
    assert!(
        ended.contains("platform disconnected") && ended.contains("rcssservermj"),
        "the report names the lost server: {ended}"
    );
    // A failed run (README: exit codes), with one error naming the server and what happened.
    assert_eq!(status.code(), Some(1), "{stderr}");
    let error = stderr.lines().find(|l| l.starts_with("error: ")).unwrap_or_default();
    assert!(
        error.contains("lost the server mid-game") && error.contains(&address),
        "the error names the server and what happened: {stderr}"
    );
    let reader = strata_log::LogReader::open(&log).expect("the log opens");
    assert!(reader.is_complete(), "the log is finalized");
    let world = format!("t{TEAM}/{player}/world/world_state");
    assert!(reader.topic(&world).is_some_and(|t| t.messages > 0), "{world} logged");
    // Bounds a hang, not a speed: the platform notices a silent server within its stall
    // timeout (2 s).
    assert!(took < Duration::from_secs(20), "the robot took {took:?} to stop");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A unit quaternion `[w, x, y, z]`: heading `yaw` about the world's z axis, then `pitch`
/// about the torso's y axis (positive: leaning forward).
fn yaw_then_pitch(yaw: f64, pitch: f64) -> [f64; 4] {
    let (cy, sy) = ((yaw / 2.0).cos(), (yaw / 2.0).sin());
    let (cp, sp) = ((pitch / 2.0).cos(), (pitch / 2.0).sin());
    [cy * cp, -sy * sp, cy * sp, sy * cp]
}

/// The angle between the torso's z axis and the world's vertical.
fn tilt_of([_, x, y, _]: [f64; 4]) -> f64 {
    (1.0 - 2.0 * (x * x + y * y)).clamp(-1.0, 1.0).acos()
}

fn heading_of([w, x, y, z]: [f64; 4]) -> f64 {
    (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
}

/// The trainer tips a T1 forward past its balance (the server puts it down with every joint
/// at zero): the reactive layer's fall detector sees it fall and orders the protective fall.
/// The latency from the ground-truth onset (the torso's tilt passing the platform's
/// `FALL_ONSET_TILT`, 20 degrees) to the order is printed, not asserted. Tipped 25 degrees,
/// the onset is the first perception after the push; tipped 15 degrees (and dropped a few
/// centimetres, as the server puts it down with straight legs), the detector orders the fall
/// from the first perception's gyroscope, before the torso passes 20 degrees.
#[test]
fn a_t1_tipped_over_is_caught_falling_by_the_reactive_layer() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(PoisonError::into_inner);
    let Some(server) = server() else { return };
    let player = 4;
    let tip = 25f64.to_radians();
    let mut robot = robot(&server, player, [-3.0, 1.0, 0.0], 20.0, 13);
    let start = wait_in_simulation(&server, &mut robot, player);
    // Standing or walking to its Ready position for a while first.
    follow(&server, &mut robot, player, start + 4.0, |_, _| {});
    let (pushed_at, truth) = truth_of(&server, player).expect("the robot's ground truth");
    server.command(vec![MonitorCommand::PlaceRobot {
        team: TeamRef::Name(TEAM_NAME.to_owned()),
        player,
        position: [truth.position[0], truth.position[1], 0.72],
        orientation: RobotOrientation::Quaternion(yaw_then_pitch(
            heading_of(truth.orientation),
            tip,
        )),
    }]);
    let mut lowest = f64::INFINITY;
    let mut tilts = Vec::new();
    follow(&server, &mut robot, player, pushed_at + 4.0, |t, truth| {
        lowest = lowest.min(truth.position[2]);
        tilts.push(format!("{t:.2} s {:.0}", tilt_of(truth.orientation).to_degrees()));
    });
    println!(
        "the torso's tilt (degrees) after the push: {}",
        tilts[..tilts.len().min(30)].join(", ")
    );
    let report = report(&mut robot);
    let falls = report["falls"].as_array().cloned().unwrap_or_default();
    println!("tipped {:.0} degrees at {pushed_at:.2} s; falls: {falls:?}", tip.to_degrees());
    assert!(lowest < 0.4, "the robot did not fall: its torso was never below {lowest:.2} m");
    let fall = falls
        .iter()
        .find(|f| f["onset"].as_f64().is_some_and(|onset| onset >= pushed_at))
        .unwrap_or_else(|| panic!("no fall onset after the push at {pushed_at:.2} s: {falls:?}"));
    assert!(
        !fall["ordered"].is_null(),
        "no protective fall was ordered: {fall}\n{}",
        robot.stderr()
    );
    let (onset, ordered, latency) =
        (figure(fall, "/onset"), figure(fall, "/ordered"), figure(fall, "/latency"));
    println!(
        "fall onset (tilt past 20 degrees) at {onset:.2} s (server time), protective fall \
         ordered at {ordered:.2} s: {:.1} ms {} the onset perception arrived",
        latency.abs() * 1e3,
        if latency < 0.0 { "before (predicted by the gyroscope)" } else { "after" }
    );
    assert!(ordered >= onset && latency >= 0.0, "ordered before the onset: {fall}");
}

/// The robot's compute per 20 ms server cycle while a T1 walks (to its Ready position, then
/// after a ball the trainer moves around a loop), from the report's `compute` section: printed
/// as a table, not asserted (the figures depend on the build and the machine). For the
/// figures of a release build over a longer run: `STRATA_COMPUTE_SECONDS=120 cargo test
/// --release -p strata --test rcssservermj compute -- --nocapture`.
#[test]
fn the_compute_per_server_cycle_is_reported() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(PoisonError::into_inner);
    let Some(server) = server() else { return };
    let seconds: f64 = std::env::var("STRATA_COMPUTE_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .filter(|s: &f64| s.is_finite() && *s >= 12.0)
        .unwrap_or(24.0);
    let player = 3;
    let mut robot = robot(&server, player, [-5.0, -2.0, 30.0], seconds, 17);
    let start = wait_in_simulation(&server, &mut robot, player);
    follow(&server, &mut robot, player, start + 8.0, |_, _| {});
    server.command(vec![MonitorCommand::KickOff(Some(FieldSide::Left))]);
    let corners = [(-2.0, 2.5), (-5.0, 2.5), (-5.0, -1.5), (-2.0, -1.5)];
    let mut at = start + 9.0;
    for (x, y) in corners.into_iter().cycle() {
        // Ends with the robot (after `seconds` of its own clock).
        if at > start + seconds - 4.0 {
            break;
        }
        follow(&server, &mut robot, player, at, |_, _| {});
        server.command(vec![ball(x, y)]);
        at += 6.0;
    }
    let report = report(&mut robot);
    let compute = &report["compute"];
    let row = |name: &str, pointer: &str| {
        println!(
            "{name:<34} {:>9.0} {:>9.0} {:>9.0} {:>9.0}",
            figure(compute, &format!("{pointer}/p50_us")),
            figure(compute, &format!("{pointer}/p99_us")),
            figure(compute, &format!("{pointer}/max_us")),
            figure(compute, &format!("{pointer}/mean_us")),
        );
    };
    let cycles = figure(compute, "/cycles");
    println!(
        "\ncompute per {} ms server cycle, CPU time ({} build), {cycles} cycles, {} cores",
        figure(compute, "/cycle_ms"),
        if cfg!(debug_assertions) { "debug" } else { "release" },
        std::thread::available_parallelism().map_or(0, |n| n.get()),
    );
    println!("{:<34} {:>9} {:>9} {:>9} {:>9}", "us", "p50", "p99", "max", "mean");
    row("the robot's process (every thread)", "/process");
    row("  the platform's connection thread", "/connection");
    row("    the body's control and policy", "/policy");
    println!(
        "{:<34} {:>8.1}% {:>8.1}% {:>8.1}%",
        "process / cycle",
        100.0 * figure(compute, "/share_of_cycle/p50"),
        100.0 * figure(compute, "/share_of_cycle/p99"),
        100.0 * figure(compute, "/share_of_cycle/max"),
    );
    println!(
        "modules' own wall time per cycle, mean: {:.0} us",
        figure(compute, "/modules_wall_mean_us")
    );
    assert!(cycles > 0.0, "no server cycle measured: {compute}");
    assert_eq!(figure(compute, "/process/count"), cycles);
    // Every cycle's process time includes its connection thread's, which includes the policy.
    for stat in ["p50_us", "max_us"] {
        let process = figure(compute, &format!("/process/{stat}"));
        let connection = figure(compute, &format!("/connection/{stat}"));
        assert!(process >= connection, "{stat}: process {process} < connection {connection}");
    }
    assert!(figure(compute, "/policy/count") > 0.0, "{compute}");
}

/// The torso's height at which the server's referee drops a robot (`drop_at`: the model's
/// torso body height; the joints reset to zero, so the T1 lands standing).
const DROP_HEIGHT: f64 = 0.6735;

/// What the robot's status lines said after it was moved.
#[derive(Debug)]
struct Relocalization {
    /// How much the move turned the robot, rad.
    turned: f64,
    /// Simulated seconds from the move to the first status with the pose lost, if any.
    lost_after: Option<f64>,
    /// Simulated seconds from the move to the first status with the pose within 0.5 m and 0.3
    /// rad of the ground truth (not lost), if any.
    found_after: Option<f64>,
    /// Simulated seconds from the move to the first status with the pose near the point mirror
    /// of the ground truth (within 1.5 m), if any.
    mirrored_after: Option<f64>,
    /// The statuses after the move: (simulated seconds since it, error m, heading error rad,
    /// lost).
    trace: Vec<(f64, f64, f64, bool)>,
}

fn pose_status(status: &serde_json::Value) -> Option<([f64; 3], [f64; 3], bool)> {
    let pose = status.get("pose")?;
    let triple = |name: &str| -> Option<[f64; 3]> {
        let v = pose.get(name)?.as_array()?;
        Some([v.first()?.as_f64()?, v.get(1)?.as_f64()?, v.get(2)?.as_f64()?])
    };
    Some((triple("estimate")?, triple("truth")?, pose.get("lost")?.as_bool()?))
}

/// Moves the robot as rcsssmj's `_penalize` does, to `spot` (the left team's frame is the world
/// frame) facing into the field, then reads its statuses for `seconds` of simulation.
fn penalize(
    server: &ServerProcess,
    robot: &mut Process,
    player: u8,
    spot: [f64; 2],
    seconds: f64,
) -> Relocalization {
    let (moved_at, before) = truth_of(server, player).expect("the robot's ground truth");
    let facing = -spot[1].signum() * std::f64::consts::FRAC_PI_2;
    server.command(vec![MonitorCommand::PlaceRobot {
        team: TeamRef::Name(TEAM_NAME.to_owned()),
        player,
        position: [spot[0], spot[1], DROP_HEIGHT],
        orientation: RobotOrientation::Yaw(facing),
    }]);
    // Each status line the robot writes, against the simulation's clock when the test read it.
    let mut seen = robot.lines().len();
    let mut statuses: Vec<(f64, serde_json::Value)> = Vec::new();
    robot.wait_for("the robot's statuses after the move", |p| {
        let (t, _) = truth_of(server, player)?;
        let lines = p.lines();
        for line in &lines[seen.min(lines.len())..] {
            if let Ok(v) = serde_json::from_str::<serde_json::Value>(line)
                && v["type"] == "status"
            {
                statuses.push((t, v));
            }
        }
        seen = lines.len();
        (t >= moved_at + seconds).then_some(())
    });
    let [w, x, y, z] = before.orientation;
    let heading = (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z));
    let turned = strata_robot::geometry::normalize_angle(facing - heading).abs();
    let mut result = Relocalization {
        turned,
        lost_after: None,
        found_after: None,
        mirrored_after: None,
        trace: Vec::new(),
    };
    let mut arrived = false;
    for (t, status) in &statuses {
        let Some((estimate, truth, lost)) = pose_status(status) else { continue };
        // The statuses before the move reached the robot's world model show the old place.
        arrived = arrived || (truth[0] - spot[0]).hypot(truth[1] - spot[1]) < 1.5;
        if !arrived {
            continue;
        }
        let since = t - moved_at;
        let error = (estimate[0] - truth[0]).hypot(estimate[1] - truth[1]);
        let heading =
            strata_robot::geometry::normalize_angle((estimate[2] - truth[2]).to_radians()).abs();
        let mirror = (estimate[0] + truth[0]).hypot(estimate[1] + truth[1]);
        if lost {
            result.lost_after.get_or_insert(since);
        }
        if result.found_after.is_none() && !lost && error < 0.5 && heading < 0.3 {
            result.found_after = Some(since);
        }
        if result.mirrored_after.is_none() && !lost && mirror < 1.5 {
            result.mirrored_after = Some(since);
        }
        result.trace.push((since, error, heading, lost));
    }
    println!(
        "moved at {moved_at:.2} s from ({:.2}, {:.2}) facing {:.0} degrees to ({:.1}, {:.1}) \
         facing {:.0} degrees",
        before.position[0],
        before.position[1],
        heading.to_degrees(),
        spot[0],
        spot[1],
        facing.to_degrees()
    );
    for (since, error, heading, lost) in result.trace.iter().step_by(10) {
        println!(
            "{since:5.1} s after: error {error:6.2} m, heading {:5.1} deg{}",
            heading.to_degrees(),
            if *lost { ", lost" } else { "" }
        );
    }
    println!(
        "lost after {:?} s, found after {:?} s, near the mirror pose after {:?} s",
        result.lost_after, result.found_after, result.mirrored_after
    );
    result
}

/// The server's referee moves a robot to the side line (rcsssmj's `_penalize`: the first free
/// spot of x = -2, -4, ... m in the team's own half, on the side away from the ball, facing
/// into the field) and does not tell it. The move turns the robot (it faced along the field,
/// after the ball), which the platform sees: world modeling declares a kidnap at once. From
/// the one landmark it sees there (the halfway line's end, 3.6 m away) it finds itself at the
/// spot, never at its mirror image. With one landmark the heading it had when put there is what tells the two side lines
/// apart: a robot that turns a lot before it first sees the landmark stays lost instead, and one
/// that walks before is found off by what one landmark cannot correct (1 run in 9 each when
/// measured), so the test allows a second try.
#[test]
fn a_t1_moved_to_the_side_line_by_the_referee_finds_itself_there() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(PoisonError::into_inner);
    let Some(server) = server() else { return };
    let player = 2;
    let field = strata_spl::Field::preset("rcssservermj").expect("the field preset");
    let dimensions = field.dimensions();
    let side_line = dimensions.field_width / 2.0 + dimensions.border_strip_width;
    let each = 20.0;
    let mut robot = robot_with(
        &server,
        player,
        [-6.0, 4.0, 0.0],
        22.0 + 2.0 * each + 16.0,
        23,
        &["--status-interval", "0.1"],
    );
    let start = wait_in_simulation(&server, &mut robot, player);
    follow(&server, &mut robot, player, start + 12.0, |_, _| {});
    server.command(vec![MonitorCommand::KickOff(Some(FieldSide::Left))]);
    follow(&server, &mut robot, player, start + 13.0, |_, _| {});
    // The ball at positive y: the referee puts the robot on the other side line.
    server.command(vec![ball(-4.0, 3.0)]);
    follow(&server, &mut robot, player, start + 22.0, |_, _| {});
    let first = penalize(&server, &mut robot, player, [-2.0, -side_line], each);
    let moves = if first.found_after.is_some_and(|t| t < 10.0) {
        vec![first]
    } else {
        // Again: back in the field, where two landmarks find it, then to the other side.
        let (now, _) = truth_of(&server, player).expect("the robot's ground truth");
        server.command(vec![
            ball(-4.0, -3.0),
            MonitorCommand::PlaceRobot {
                team: TeamRef::Name(TEAM_NAME.to_owned()),
                player,
                position: [-3.0, 1.0, DROP_HEIGHT],
                orientation: RobotOrientation::Yaw(0.0),
            },
        ]);
        follow(&server, &mut robot, player, now + 10.0, |_, _| {});
        let second = penalize(&server, &mut robot, player, [-4.0, side_line], each);
        vec![first, second]
    };
    let report = report(&mut robot);
    println!("localization: {}", report["localization"]);
    for moved in &moves {
        // Whatever happens, never the mirror image (the robot would play the wrong way).
        assert_eq!(moved.mirrored_after, None, "took the mirror pose: {moved:?}");
        let wrong = moved.trace.iter().filter(|(_, error, _, lost)| !lost && *error > 1.5);
        let recovered_wrong = wrong.filter(|(t, ..)| moved.found_after.is_some_and(|f| *t > f));
        assert_eq!(recovered_wrong.count(), 0, "lost the spot after finding it: {moved:?}");
        // A move that turns the robot is seen at once (the statuses come every 0.1 s).
        if moved.turned > 0.5 {
            let lost = moved.lost_after.unwrap_or_else(|| panic!("never lost: {moved:?}"));
            assert!(lost < 0.5, "lost only {lost:.1} s after a move that turned it");
        }
    }
    let last = moves.last().expect("one move at least");
    let found = last.found_after.unwrap_or_else(|| panic!("never found: {last:?}"));
    assert!(found < 10.0, "found only {found:.1} s after the move");
}
