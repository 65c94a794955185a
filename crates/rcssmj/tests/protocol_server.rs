//! The protocol against a real rcssservermj: one T1 connects, beams, and a trainer moves the
//! ball; the agent's camera and the monitor stream must both see the ball where it was put.
//!
//! Needs the server: `scripts/setup-rcssservermj` installs it in `.venv-rcssservermj/`, or
//! `RCSSSERVERMJ` names the binary. Without it the test says so and passes (CI has no Python
//! server).

use std::net::{TcpListener, TcpStream};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::thread;
use std::time::Duration;

use strata_rcssmj::protocol::monitor::{MonitorClient, MonitorCommand};
use strata_rcssmj::protocol::{
    Effector, FrameError, InitRequest, MAX_PERCEPTION_FRAME, Perception, SeenObject,
    decode_perception, encode_effectors, encode_init, read_frame, write_frame,
};

/// Kills the server and removes its working directory when the test ends, however it ends.
struct Server {
    child: Child,
    workdir: PathBuf,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.workdir);
    }
}

fn server_binary() -> Option<PathBuf> {
    if let Some(path) = std::env::var_os("RCSSSERVERMJ") {
        return Some(PathBuf::from(path));
    }
    let venv =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../.venv-rcssservermj/bin/rcssservermj");
    venv.exists().then_some(venv)
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .unwrap_or_else(|e| panic!("no free port: {e}"))
}

/// Waits for the server to listen (it takes a second or two to import MuJoCo).
fn connect_with_retry(port: u16) -> TcpStream {
    for _ in 0..300 {
        if let Ok(stream) = TcpStream::connect(("127.0.0.1", port)) {
            return stream;
        }
        thread::sleep(Duration::from_millis(100));
    }
    panic!("rcssservermj did not listen on port {port} within 30 s");
}

struct Agent {
    stream: TcpStream,
    buffer: Vec<u8>,
    out: Vec<u8>,
}

impl Agent {
    fn perceive(&mut self) -> Perception {
        let payload = read_frame(&mut self.stream, &mut self.buffer, MAX_PERCEPTION_FRAME)
            .unwrap_or_else(|e| panic!("reading a perception: {e}"));
        decode_perception(payload).unwrap_or_else(|e| panic!("decoding a perception: {e}"))
    }

    fn act(&mut self, effectors: &[Effector]) {
        encode_effectors(effectors, &mut self.out).unwrap_or_else(|e| panic!("{e}"));
        write_frame(&mut self.stream, &self.out).unwrap_or_else(|e| panic!("{e}"));
    }
}

#[test]
fn a_placed_ball_is_seen_by_the_camera_and_the_monitor() {
    let Some(binary) = server_binary() else {
        eprintln!("rcssservermj not installed (scripts/setup-rcssservermj); skipping");
        return;
    };
    let (agent_port, monitor_port) = (free_port(), free_port());
    // The server writes console.log and MUJOCO_LOG.TXT into its working directory.
    let workdir = std::env::temp_dir().join(format!("strata-rcssmj-test-{}", std::process::id()));
    std::fs::create_dir_all(&workdir).unwrap_or_else(|e| panic!("{}: {e}", workdir.display()));
    let child = Command::new(&binary)
        .current_dir(&workdir)
        .args(["--no-render", "--sync", "--no-realtime"])
        .args(["--aport", &agent_port.to_string(), "--mport", &monitor_port.to_string()])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start {}: {e}", binary.display()));
    let server = Server { child, workdir };

    // An observer reads the monitor stream on its own thread (an unread monitor stalls the
    // server); a second connection sends the commands.
    drop(connect_with_retry(monitor_port));
    let mut observer = MonitorClient::connect(("127.0.0.1", monitor_port), Duration::from_secs(30))
        .unwrap_or_else(|e| panic!("{e}"));
    let mut trainer = MonitorClient::connect(("127.0.0.1", monitor_port), Duration::from_secs(30))
        .unwrap_or_else(|e| panic!("{e}"));
    // rcsssmj 0.2.1 crashes its simulation thread when an agent joins before the first physics
    // step (audio_engine.a_forward on empty arrays); a monitor message means a step happened.
    observer.next_state().unwrap_or_else(|e| panic!("first monitor message: {e}"));
    let stream = connect_with_retry(agent_port);
    stream.set_read_timeout(Some(Duration::from_secs(30))).unwrap_or_else(|e| panic!("{e}"));
    let mut agent = Agent { stream, buffer: Vec::new(), out: Vec::new() };
    let init = InitRequest { model: "T1".into(), team: "Tester".into(), player: 1 };
    let init = encode_init(&init).unwrap_or_else(|e| panic!("{e}"));
    write_frame(&mut agent.stream, &init).unwrap_or_else(|e| panic!("{e}"));

    let (balls, ball_positions) = mpsc::channel();
    let reader = thread::spawn(move || {
        loop {
            match observer.next_state() {
                Ok(state) => {
                    if balls.send(state.ball_position).is_err() {
                        return;
                    }
                }
                Err(strata_rcssmj::protocol::ProtocolError::Frame(FrameError::Closed)) => return,
                Err(e) => panic!("monitor stream: {e}"),
            }
        }
    });

    let first = agent.perceive();
    assert!(first.game.is_some_and(|g| g.team_left.as_deref() == Some("Tester")));
    agent.act(&[Effector::Beam { x: -1.0, y: 0.0, theta: 0.0 }, Effector::Sync]);

    // Stand at (-1, 0) facing +x; the ball goes 1 m ahead-left of the torso, at (0, 1). The
    // camera is about 0.06 m ahead of the torso and 1.1 m above the ground, so it should see
    // the ball about 0.94 m ahead, 1 m to the left (positive azimuth) and below the horizon.
    let target = [0.0, 1.0, 0.11];
    let mut placed = false;
    let mut seen = None;
    for _ in 0..40 {
        let p = agent.perceive();
        let beamed =
            p.torso_position_truth.is_some_and(|t| (t[0] + 1.0).abs() < 0.01 && t[1].abs() < 0.01);
        if beamed && !placed {
            trainer
                .send(&[MonitorCommand::PlaceBall { position: target, velocity: Some([0.0; 3]) }])
                .unwrap_or_else(|e| panic!("{e}"));
            placed = true;
        }
        let ball = p.vision.iter().flatten().find_map(|o| match o {
            SeenObject::Marker(m) if m.name == "B" => Some(m.polar),
            _ => None,
        });
        if let Some(ball) = ball.filter(|_| placed) {
            let [x, y, _] = ball.to_cartesian();
            if (x - 0.94).abs() < 0.15 && (y - 1.0).abs() < 0.15 {
                seen = Some(ball);
                break;
            }
        }
        agent.act(&[Effector::Sync]);
    }
    let ball = seen.unwrap_or_else(|| panic!("the camera never saw the ball where it was placed"));
    assert!(ball.azimuth > 0.0 && ball.elevation < 0.0, "{ball:?}");

    // Keep the server stepping until the monitor has reported the ball at the target.
    let mut monitor_saw = false;
    for _ in 0..40 {
        agent.act(&[Effector::Sync]);
        agent.perceive();
        while let Ok(position) = ball_positions.try_recv() {
            if position
                .is_some_and(|b| (b[0] - target[0]).abs() < 0.01 && (b[1] - target[1]).abs() < 0.01)
            {
                monitor_saw = true;
            }
        }
        if monitor_saw {
            break;
        }
    }
    assert!(monitor_saw, "the monitor never reported the placed ball");
    drop(ball_positions);
    drop(trainer);
    drop(server);
    let _ = reader.join();
}
