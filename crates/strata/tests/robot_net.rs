//! Robots on a real network (on loopback): three `strata robot --net` processes take their
//! sensors from a simulator server but their game state from a GameController written here
//! (the `spl` encoder, broadcast over UDP) and talk to each other by UDP broadcast. The test
//! walks the game through Initial, Ready, Set and Playing, penalizes and un-penalizes a robot,
//! and checks that every robot follows, answers with return packets, and exchanges team
//! messages of at most 128 bytes.
//!
//! Ports are picked free for each run, so concurrent runs do not hear each other. Nothing
//! asserts how long anything took: every step waits for its condition.

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::net::{IpAddr, Ipv4Addr, SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::Duration;

use common::{Process, free_udp_port, start_server, strata, until};
use strata_robot::control::planning_module::TeamCodec;
use strata_soccer::planning::SoccerCodec;
use strata_spl::TeamSocket;
use strata_spl::gamecontroller::{GameControlData, GameState, Penalty, ReturnData};
use strata_spl::net::{LOOPBACK_BROADCAST, MAX_TEAM_MESSAGE_SIZE, bind_shared};

const TEAM: u8 = 10;
const OPPONENT: u8 = 20;
const PLAYERS: [u8; 3] = [1, 2, 3];

/// A GameController for the test: broadcasts the current control packet ten times a second
/// and collects the return packets.
struct GameController {
    data: Arc<Mutex<GameControlData>>,
    /// Return packets received, per player of our team.
    returns: Arc<Mutex<BTreeMap<u8, u64>>>,
    problems: Arc<Mutex<Vec<String>>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    return_port: u16,
}

impl GameController {
    fn start(control_port: u16) -> GameController {
        let mut data = GameControlData {
            state: GameState::Initial,
            players_per_team: PLAYERS.len() as u8,
            first_half: true,
            kicking_team: Some(TEAM),
            secs_remaining: 600,
            ..GameControlData::default()
        };
        data.teams[0].team_number = TEAM;
        data.teams[1].team_number = OPPONENT;
        for team in &mut data.teams {
            team.message_budget = 1200;
        }
        // Bound like a real GameController: its return packets arrive on the port it sends
        // from, which is what the robots learn from its packets.
        let socket = bind_shared(SocketAddr::new(IpAddr::V4(Ipv4Addr::UNSPECIFIED), 0))
            .expect("the GameController binds");
        socket.set_nonblocking(true).expect("non-blocking");
        let return_port = socket.local_addr().expect("bound").port();
        let data = Arc::new(Mutex::new(data));
        let returns = Arc::new(Mutex::new(BTreeMap::new()));
        let problems = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (data, returns, problems, stop) =
                (Arc::clone(&data), Arc::clone(&returns), Arc::clone(&problems), Arc::clone(&stop));
            std::thread::spawn(move || {
                run_game_controller(socket, control_port, &data, &returns, &problems, &stop)
            })
        };
        GameController { data, returns, problems, stop, thread: Some(thread), return_port }
    }

    fn update(&self, change: impl FnOnce(&mut GameControlData)) {
        change(&mut self.data.lock().unwrap_or_else(PoisonError::into_inner));
    }

    fn players_heard(&self) -> BTreeSet<u8> {
        self.returns.lock().unwrap_or_else(PoisonError::into_inner).keys().copied().collect()
    }

    fn problems(&self) -> Vec<String> {
        self.problems.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }
}

impl Drop for GameController {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn run_game_controller(
    socket: UdpSocket,
    control_port: u16,
    data: &Mutex<GameControlData>,
    returns: &Mutex<BTreeMap<u8, u64>>,
    problems: &Mutex<Vec<String>>,
    stop: &AtomicBool,
) {
    let to = SocketAddr::new(IpAddr::V4(LOOPBACK_BROADCAST), control_port);
    let problem = |text: String| problems.lock().unwrap_or_else(PoisonError::into_inner).push(text);
    while !stop.load(Ordering::Relaxed) {
        let bytes = {
            let mut data = data.lock().unwrap_or_else(PoisonError::into_inner);
            data.packet_number = data.packet_number.wrapping_add(1);
            data.encode()
        };
        if let Err(e) = socket.send_to(&bytes, to) {
            problem(format!("control packet not sent: {e}"));
        }
        let mut buffer = [0u8; 256];
        while let Ok((size, from)) = socket.recv_from(&mut buffer) {
            match ReturnData::decode(&buffer[..size]) {
                Ok(ret) if ret.team_number == TEAM => {
                    *returns
                        .lock()
                        .unwrap_or_else(PoisonError::into_inner)
                        .entry(ret.player_number)
                        .or_default() += 1;
                }
                Ok(ret) => problem(format!("return packet of team {}", ret.team_number)),
                Err(e) => problem(format!("bad return packet from {from}: {e}")),
            }
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Listens on the team port like one more robot and decodes what the robots broadcast.
fn team_listener(port: u16, stop: Arc<AtomicBool>) -> JoinHandle<Result<BTreeSet<u8>, String>> {
    let socket = TeamSocket::loopback(port).expect("the listener binds the team port");
    std::thread::spawn(move || {
        let mut senders = BTreeSet::new();
        while !stop.load(Ordering::Relaxed) {
            match socket.receive() {
                Ok(Some(received)) => {
                    // The socket refuses anything over 128 bytes with an error.
                    assert!(received.data.len() <= MAX_TEAM_MESSAGE_SIZE);
                    let message = SoccerCodec
                        .decode(&received.data)
                        .map_err(|e| format!("a robot sent an undecodable team message: {e}"))?;
                    senders.insert(message.sender);
                }
                Ok(None) => std::thread::sleep(Duration::from_millis(5)),
                Err(e) => return Err(format!("team port: {e}")),
            }
        }
        Ok(senders)
    })
}

fn game_events(robot: &Process) -> Vec<serde_json::Value> {
    robot.json_of("game_state")
}

fn has_followed(robot: &Process, state: &str, penalized: bool) -> bool {
    game_events(robot).iter().any(|e| e["state"] == state && e["penalized"] == penalized)
}

#[test]
fn robots_follow_the_game_controller_and_talk_over_udp() {
    let (mut server, addr) = start_server(&[]);
    let control_port = free_udp_port();
    let team_port = free_udp_port();
    let gc = GameController::start(control_port);
    let listening = Arc::new(AtomicBool::new(false));
    let listener = team_listener(team_port, Arc::clone(&listening));

    let mut robots: Vec<Process> = PLAYERS
        .iter()
        .map(|player| {
            Process::spawn(
                &format!("robot {TEAM}/{player}"),
                strata().args(["robot", "--server", &addr, "--net", "--json"]).args([
                    "--team".to_owned(),
                    TEAM.to_string(),
                    "--player".to_owned(),
                    player.to_string(),
                    "--broadcast".to_owned(),
                    LOOPBACK_BROADCAST.to_string(),
                    "--gc-port".to_owned(),
                    control_port.to_string(),
                    "--gc-return-port".to_owned(),
                    gc.return_port.to_string(),
                    "--team-port".to_owned(),
                    team_port.to_string(),
                    "--status-interval".to_owned(),
                    "1".to_owned(),
                    // A safety net if the test itself is killed; it ends them with Ctrl-C.
                    "--duration".to_owned(),
                    "900".to_owned(),
                ]),
            )
        })
        .collect();

    // Each robot learned its attack direction from the GameController: listed first, first
    // half: +x.
    for robot in &mut robots {
        let start = robot.wait_for("the start line", |p| p.json_of("start").into_iter().next());
        assert_eq!(start["attack_sign"], 1.0, "{start}");
        assert!(start["attack_source"].as_str().is_some_and(|s| s.contains("GameController")));
        assert!(start["game_controller"].as_str().is_some_and(|s| s.contains("UDP")), "{start}");
    }

    // The game, step by step: each state is held until every robot has followed.
    for state in [GameState::Initial, GameState::Ready, GameState::Set, GameState::Playing] {
        gc.update(|d| d.state = state);
        let name = format!("{state:?}");
        for robot in &mut robots {
            robot.wait_for(&format!("game state {name}"), |p| {
                has_followed(p, &name, false).then_some(())
            });
        }
    }
    // A penalty for player 2, then back in.
    gc.update(|d| d.teams[0].players[1].penalty = Penalty::Manual);
    robots[1].wait_for("the penalty", |p| has_followed(p, "Playing", true).then_some(()));
    gc.update(|d| d.teams[0].players[1].penalty = Penalty::None);
    robots[1].wait_for("the end of the penalty", |p| {
        game_events(p).last().is_some_and(|e| e["penalized"] == false).then_some(())
    });

    // Team messages: every robot hears a teammate; every robot answers the GameController.
    for robot in &mut robots {
        robot.wait_for("a teammate's message", |p| {
            p.json_of("status")
                .iter()
                .any(|s| s["messages_received"].as_u64().is_some_and(|n| n > 0))
                .then_some(())
        });
    }
    until("return packets from every robot", || {
        (gc.players_heard() == PLAYERS.into_iter().collect()).then_some(())
    });

    let mut reports = Vec::new();
    for robot in &mut robots {
        let status = robot.interrupt();
        let report = robot.json_of("report").pop().unwrap_or_else(|| {
            panic!("{}: no report\n{}\n{}", robot.name, robot.lines().join("\n"), robot.stderr())
        });
        assert!(status.success(), "{} exited with {status}: {}", robot.name, robot.stderr());
        reports.push(report);
    }
    listening.store(true, Ordering::Relaxed);
    let senders = listener.join().expect("the listener thread").expect("valid team messages");
    assert_eq!(server.interrupt().code(), Some(0), "the server stops cleanly on Ctrl-C");

    for report in &reports {
        let who = format!("robot {}/{}", report["team"], report["player"]);
        // Shown when the test fails (or with --nocapture).
        eprintln!("{who}: {report:#}");
        assert_eq!(report["ended"], "interrupted", "{who}");
        assert_eq!(
            report["game_states"],
            serde_json::json!(["Initial", "Ready", "Set", "Playing"]),
            "{who} followed the game in order"
        );
        assert!(report["sensor_frames"].as_u64().is_some_and(|n| n > 0), "{who}: sensors");
        assert!(report["planning"]["received"].as_u64().is_some_and(|n| n > 0), "{who}");
        let team = &report["team_link"];
        assert!(team["sent"].as_u64().is_some_and(|n| n > 0), "{who}: {team}");
        for size in ["largest_sent", "largest_received"] {
            assert!(
                team[size].as_u64().is_some_and(|n| n > 0 && n <= MAX_TEAM_MESSAGE_SIZE as u64),
                "{who}: {team}"
            );
        }
        let gc_link = &report["game_controller_link"];
        assert!(gc_link["received"].as_u64().is_some_and(|n| n > 0), "{who}: {gc_link}");
        assert!(gc_link["sent"].as_u64().is_some_and(|n| n > 0), "{who}: {gc_link}");
        assert_eq!(report["layers"].as_array().map(Vec::len), Some(3), "{who}: three layers");
    }
    assert_eq!(senders, PLAYERS.into_iter().collect(), "every robot broadcast team messages");
    assert_eq!(gc.problems(), Vec::<String>::new());
}

/// A stand-in for LoLA (the `strata-nao` tests' fake server).
#[path = "../../nao/tests/common/mod.rs"]
mod fake_lola;

/// `--platform nao`: sensors from LoLA (a fake one here), the game state and the team from
/// UDP with nothing else to say; the robot follows the GameController and, when stopped, sits
/// down and goes limp before it exits.
#[test]
fn a_nao_follows_the_game_controller_and_sits_down_when_stopped() {
    let control_port = free_udp_port();
    let team_port = free_udp_port();
    let gc = GameController::start(control_port);
    let mut lola = fake_lola::FakeLola::start();
    let path = lola.path().to_owned();
    // LoLA's side: a sensor packet every 12 ms, each answered with an actuator packet, until
    // the robot closes the socket. Keeps the newest answer's largest stiffness.
    let last_stiffness = Arc::new(Mutex::new(None::<f32>));
    let replies = Arc::new(std::sync::atomic::AtomicU64::new(0));
    let feeder = {
        let (last_stiffness, replies) = (Arc::clone(&last_stiffness), Arc::clone(&replies));
        std::thread::spawn(move || {
            // `exchange` panics when the robot closes the socket: that ends this thread.
            loop {
                let reply = lola.exchange();
                let stiffness = reply.stiffness.iter().copied().fold(0.0f32, f32::max);
                *last_stiffness.lock().unwrap_or_else(PoisonError::into_inner) = Some(stiffness);
                replies.fetch_add(1, Ordering::Relaxed);
            }
        })
    };
    let mut robot = Process::spawn(
        "nao robot 10/4",
        strata()
            .args(["robot", "--platform", "nao", "--team", "10", "--player", "4", "--json"])
            .args([
                "--socket".to_owned(),
                path.display().to_string(),
                "--broadcast".to_owned(),
                LOOPBACK_BROADCAST.to_string(),
                "--gc-port".to_owned(),
                control_port.to_string(),
                "--gc-return-port".to_owned(),
                gc.return_port.to_string(),
                "--team-port".to_owned(),
                team_port.to_string(),
                "--status-interval".to_owned(),
                "1".to_owned(),
                "--duration".to_owned(),
                "900".to_owned(),
            ]),
    );
    let start = robot.wait_for("the start line", |p| p.json_of("start").into_iter().next());
    assert_eq!(start["platform"], "nao");
    assert_eq!(start["can_walk"], false, "no gait engine yet");
    assert!(start["game_controller"].as_str().is_some_and(|s| s.contains("UDP")), "{start}");

    gc.update(|d| d.state = GameState::Ready);
    robot.wait_for("game state Ready", |p| has_followed(p, "Ready", false).then_some(()));
    robot.wait_for("sensor frames", |p| {
        p.json_of("status")
            .iter()
            .any(|s| s["sensor_frames"].as_u64().is_some_and(|n| n > 0))
            .then_some(())
    });
    until("a return packet from the NAO", || gc.players_heard().contains(&4).then_some(()));

    let status = robot.interrupt();
    assert!(status.success(), "exited with {status}: {}", robot.stderr());
    let report = robot.json_of("report").pop().expect("a report");
    assert_eq!(report["ended"], "interrupted", "{report}");
    assert_eq!(report["platform_errors"], 0, "{report}");
    assert!(report["game_states"].as_array().is_some_and(|s| s.iter().any(|s| s == "Ready")));
    let _ = feeder.join();
    assert!(replies.load(Ordering::Relaxed) > 0);
    let last = *last_stiffness.lock().unwrap_or_else(PoisonError::into_inner);
    assert!(last.is_some_and(|s| s < 0.1), "the robot ended limp, sitting: {last:?}");
}
