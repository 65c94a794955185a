//! The protocol against a real rcssservermj: one T1 connects, beams, and a trainer moves the
//! ball; the agent's camera and the monitor stream must both see the ball where it was put.
//!
//! Needs the server: `scripts/setup-rcssservermj` installs it in `.venv-rcssservermj/`, or
//! `STRATA_RCSSSERVERMJ` names the binary. Without it the test says so and passes, unless
//! `STRATA_REQUIRE_RCSSSERVERMJ` is set (as `scripts/test` does after installing it).

use std::net::TcpStream;
use std::time::Duration;

use strata_rcssmj::protocol::monitor::MonitorCommand;
use strata_rcssmj::protocol::{
    Effector, InitRequest, MAX_PERCEPTION_FRAME, Perception, SeenObject, decode_perception,
    encode_effectors, encode_init, read_frame, write_frame,
};
use strata_rcssmj::server::{ServerError, ServerOptions, ServerProcess};

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
    let server = match ServerProcess::start(&ServerOptions::default()) {
        Ok(server) => server,
        Err(ServerError::NotInstalled)
            if std::env::var_os("STRATA_REQUIRE_RCSSSERVERMJ").is_none() =>
        {
            eprintln!("rcssservermj not installed (scripts/setup-rcssservermj); skipping");
            return;
        }
        Err(e) => panic!("starting rcssservermj: {e}"),
    };
    let stream = TcpStream::connect(server.agent_address()).unwrap_or_else(|e| panic!("{e}"));
    stream.set_read_timeout(Some(Duration::from_secs(30))).unwrap_or_else(|e| panic!("{e}"));
    let mut agent = Agent { stream, buffer: Vec::new(), out: Vec::new() };
    let init = InitRequest { model: "T1".into(), team: "Tester".into(), player: 1 };
    let init = encode_init(&init).unwrap_or_else(|e| panic!("{e}"));
    write_frame(&mut agent.stream, &init).unwrap_or_else(|e| panic!("{e}"));

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
            server.command(vec![MonitorCommand::PlaceBall {
                position: target,
                velocity: Some([0.0; 3]),
            }]);
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
        if server
            .truth()
            .ball_position
            .is_some_and(|b| (b[0] - target[0]).abs() < 0.01 && (b[1] - target[1]).abs() < 0.01)
        {
            monitor_saw = true;
        }
        if monitor_saw {
            break;
        }
    }
    assert!(monitor_saw, "the monitor never reported the placed ball");
}
