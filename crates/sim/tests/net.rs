//! The simulator over TCP: handshake, sensor frames and game state reaching robot processes,
//! orders and team messages reaching the world, team broadcasts forwarded with loss, malformed
//! frames, disconnection and reconnection, the server's limits and the client's write timeout.
//! Waits poll with generous deadlines; nothing asserts how long anything took.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use strata_robot::Velocity;
use strata_robot::platform::{
    ActuatorOrders, BodyOrder, ExternalLink, Platform, SensorFrame, TeamLink,
};
use strata_runtime::Time;
use strata_sim::net::protocol::{self, ClientMessage, ErrorCode, ServerMessage};
use strata_sim::net::{
    ClientOptions, ConnectError, RunningServer, Server, ServerLimits, ServerOptions, TcpRobot,
    connect, connect_with,
};
use strata_sim::{GameState, RobotId, SimConfig, SimHandle, Simulation};
use strata_spl::gamecontroller::GameControlData;

const PATIENCE: Duration = Duration::from_secs(20);

fn server() -> RunningServer {
    server_with(|_| {})
}

fn server_with(adjust: impl FnOnce(&mut SimConfig)) -> RunningServer {
    limited_server(adjust, ServerLimits::default())
}

fn limited_server(adjust: impl FnOnce(&mut SimConfig), limits: ServerLimits) -> RunningServer {
    let mut config = SimConfig::default().without_noise();
    config.referee.auto = false;
    adjust(&mut config);
    let sim = SimHandle::new(Simulation::new(config).expect("valid config"));
    sim.lock().set_game_state(GameState::Playing);
    let options = ServerOptions { limits, ..ServerOptions::default() };
    let server = Server::bind("127.0.0.1:0", sim, options).expect("binds");
    server.spawn().expect("runs")
}

fn join(addr: SocketAddr, team: u8, player: u8) -> TcpRobot {
    connect(addr, team, player, Duration::from_secs(5)).expect("the server accepts the robot")
}

fn until<T>(what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + PATIENCE;
    loop {
        if let Some(value) = f() {
            return value;
        }
        assert!(Instant::now() < deadline, "gave up waiting for {what}");
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn now() -> Time {
    Time::from_nanos(1_000_000_000)
}

fn a_frame(robot: &mut TcpRobot) -> SensorFrame {
    until("a sensor frame", || robot.platform.read_sensors(now()).expect("connected"))
}

#[test]
fn robots_receive_sensor_frames_and_game_state_and_their_orders_move_them() {
    let server = server();
    let addr = server.local_addr();
    let mut first = join(addr, 10, 1);
    let mut second = join(addr, 10, 2);
    assert_eq!(first.welcome.team_index, 0);
    assert_eq!(first.platform.info(), server.sim().lock().platform_info());
    for robot in [&mut first, &mut second] {
        let frame = a_frame(robot);
        assert!((frame.inertial.accelerometer[2] - 9.81).abs() < 1e-9);
        let packet = until("a control packet", || {
            let packets = robot.game_controller.receive(now()).expect("connected");
            packets.into_iter().find_map(|p| GameControlData::decode(&p.bytes).ok())
        });
        assert_eq!(packet.state, GameState::Playing);
        assert_eq!(packet.teams[0].team_number, 10);
    }
    // A camera image arrives within a few frames.
    until("a camera image", || a_frame(&mut first).camera);

    let start = server.sim().lock().robot(RobotId::new(0, 1)).expect("present").pose;
    let walk = ActuatorOrders {
        head: None,
        body: Some(BodyOrder::Walk { velocity: Velocity::new(0.25, 0.0, 0.0) }),
    };
    first.platform.write(now(), &walk).expect("sent");
    until("the robot to walk", || {
        let pose = server.sim().lock().robot(RobotId::new(0, 1)).expect("present").pose;
        (pose.position().distance(start.position()) > 0.05).then_some(())
    });
    let odometry = until("odometry", || {
        let feedback = first.platform.read_motion(now()).expect("connected");
        (feedback.odometry.dx > 0.0).then_some(feedback.odometry)
    });
    assert!(odometry.dx > 0.0);

    // A team message goes through the server to the teammate.
    first.team_link.send(now(), b"pass to me").expect("within the limit");
    let message = until("a team message", || {
        second.team_link.receive(now()).expect("connected").into_iter().next()
    });
    assert_eq!(message.bytes, b"pass to me");
    assert!(matches!(
        first.team_link.send(now(), &[0u8; 129]),
        Err(strata_robot::platform::LinkError::TooLarge { size: 129, limit: 128 })
    ));
    // A return packet is accepted by the referee.
    let ret = strata_spl::gamecontroller::ReturnData {
        player_number: 1,
        team_number: 10,
        fallen: false,
        pose: [0.0; 3],
        ball_age: -1.0,
        ball: [0.0; 2],
    };
    first.game_controller.send(now(), &ret.encode().expect("valid")).expect("sent");
    until("the return packet", || {
        server.sim().lock().last_return_packet(RobotId::new(0, 1)).filter(|r| *r == ret)
    });
    server.stop().expect("stops cleanly");
}

/// Sends raw bytes as a client and returns the error the server answers with.
fn refused(addr: SocketAddr, bytes: &[u8]) -> (ErrorCode, Vec<u8>) {
    let mut stream = TcpStream::connect(addr).expect("connects");
    stream.set_read_timeout(Some(PATIENCE)).expect("timeout");
    stream.write_all(bytes).expect("sends");
    let code = loop {
        match protocol::read_message::<ServerMessage>(&mut stream, protocol::MAX_SERVER_FRAME) {
            Ok(ServerMessage::Error { code, .. }) => break code,
            Ok(_) => {}
            Err(error) => panic!("no error frame: {error}"),
        }
    };
    // The server closes the connection after the error.
    let mut rest = Vec::new();
    let _ = stream.read_to_end(&mut rest);
    (code, rest)
}

fn frame(json: &str) -> Vec<u8> {
    let mut bytes = (json.len() as u32).to_le_bytes().to_vec();
    bytes.extend_from_slice(json.as_bytes());
    bytes
}

#[test]
fn malformed_frames_get_an_error_and_the_server_keeps_serving_everyone_else() {
    let server = server();
    let addr = server.local_addr();
    let mut robot = join(addr, 20, 3);
    a_frame(&mut robot);

    assert_eq!(refused(addr, &frame("{not json")).0, ErrorCode::MalformedFrame);
    assert_eq!(refused(addr, &frame(r#"{"type":"teleport_me"}"#)).0, ErrorCode::MalformedFrame);
    let mut huge = (10_000_000u32).to_le_bytes().to_vec();
    huge.extend_from_slice(&[b'x'; 1000]);
    assert_eq!(refused(addr, &huge).0, ErrorCode::FrameTooLarge);
    let orders = ClientMessage::Orders { orders: ActuatorOrders::default() };
    assert_eq!(refused(addr, &protocol::encode(&orders)).0, ErrorCode::UnexpectedMessage);
    let hello = |protocol: &str, version: u32, team: u8, player: u8| {
        protocol::encode(&ClientMessage::Hello {
            protocol: protocol.to_owned(),
            version,
            team,
            player,
        })
    };
    assert_eq!(refused(addr, &hello("strata-sim", 99, 10, 1)).0, ErrorCode::UnsupportedVersion);
    assert_eq!(refused(addr, &hello("hl-sim", 1, 10, 1)).0, ErrorCode::UnsupportedVersion);
    assert_eq!(refused(addr, &hello("strata-sim", 1, 99, 1)).0, ErrorCode::UnknownRobot);
    assert_eq!(refused(addr, &hello("strata-sim", 1, 10, 8)).0, ErrorCode::UnknownRobot);
    assert_eq!(refused(addr, &hello("strata-sim", 1, 20, 3)).0, ErrorCode::SlotTaken);
    assert!(matches!(
        connect(addr, 20, 3, Duration::from_secs(5)),
        Err(ConnectError::Refused { code: ErrorCode::SlotTaken, .. })
    ));
    // A connected robot that sends garbage is dropped and removed from the world.
    let mut bad = TcpStream::connect(addr).expect("connects");
    bad.write_all(&hello("strata-sim", 1, 10, 5)).expect("sends");
    until("the robot to join", || server.sim().lock().is_present(RobotId::new(0, 5)).then_some(()));
    bad.write_all(&frame("[1, 2, 3]")).expect("sends");
    until("the robot to leave", || {
        (!server.sim().lock().is_present(RobotId::new(0, 5))).then_some(())
    });

    // The well-behaved robot never noticed.
    let before = robot.platform.received();
    until("more frames", || (robot.platform.received() > before + 10).then_some(()));
    assert_eq!(robot.platform.closed(), None);
    server.stop().expect("stops cleanly");
}

#[test]
fn a_robot_that_disconnects_mid_game_is_removed_and_may_reconnect() {
    let server = server();
    let addr = server.local_addr();
    let id = RobotId::new(1, 4);
    let mut robot = join(addr, 20, 4);
    a_frame(&mut robot);
    assert!(server.sim().lock().is_present(id));
    drop(robot);
    until("the robot to leave", || (!server.sim().lock().is_present(id)).then_some(()));
    let mut again = join(addr, 20, 4);
    a_frame(&mut again);
    assert!(server.sim().lock().is_present(id));
    // The server stopping ends the robot's connection with an error it can read.
    server.stop().expect("stops cleanly");
    let reason = until("the connection to close", || again.platform.closed());
    assert!(reason.contains("ServerShutdown"), "{reason}");
    assert!(again.platform.read_motion(now()).is_err());
}

#[test]
fn the_server_forwards_team_messages_to_teammates_only_and_loses_the_configured_fraction() {
    // Plenty of budget and message rate for a burst of 400: neither is what this test is about.
    let limits = ServerLimits { max_messages_per_second: 100_000, ..ServerLimits::default() };
    let server = limited_server(
        |c| {
            c.broadcast.loss = 0.5;
            c.referee.message_budget = 10_000;
        },
        limits,
    );
    let addr = server.local_addr();
    let mut sender = join(addr, 10, 1);
    let mut teammate = join(addr, 10, 2);
    let mut opponent = join(addr, 20, 1);
    for robot in [&mut sender, &mut teammate, &mut opponent] {
        a_frame(robot);
    }
    const SENT: u64 = 400;
    for i in 0..SENT {
        let payload = format!("message {i}");
        sender.team_link.send(now(), payload.as_bytes()).expect("within the limit");
    }
    // One present teammate: every message is either forwarded to it or lost on the way.
    let stats = until("every message to be forwarded or lost", || {
        let stats = server.sim().lock().comms_stats().clone();
        (stats.sent == SENT && stats.delivered + stats.lost == SENT).then_some(stats)
    });
    assert!(
        (140..=260).contains(&stats.lost),
        "{} of {SENT} lost at 50 % loss (binomial sd 10)",
        stats.lost
    );
    let mut received = Vec::new();
    until("the forwarded messages", || {
        received.extend(teammate.team_link.receive(now()).expect("connected"));
        (received.len() as u64 == stats.delivered).then_some(())
    });
    // Untouched, each at most once (jitter may reorder a burst).
    let mut numbers: Vec<u64> = received
        .iter()
        .map(|m| {
            let text = std::str::from_utf8(&m.bytes).expect("the bytes sent");
            text.trim_start_matches("message ").parse().expect("the bytes sent")
        })
        .collect();
    numbers.sort_unstable();
    numbers.dedup();
    assert_eq!(numbers.len() as u64, stats.delivered);
    assert!(numbers.iter().all(|&n| n < SENT));
    // Nothing to the opponent or back to the sender, even after the teammate got everything.
    assert!(opponent.team_link.receive(now()).expect("connected").is_empty());
    assert!(sender.team_link.receive(now()).expect("connected").is_empty());
    server.stop().expect("stops cleanly");
}

fn hello_frame(team: u8, player: u8) -> Vec<u8> {
    protocol::encode(&ClientMessage::Hello {
        protocol: "strata-sim".to_owned(),
        version: 1,
        team,
        player,
    })
}

/// Sends `bytes` on a new connection and returns the server's first message.
fn first_reply(addr: SocketAddr, bytes: &[u8]) -> ServerMessage {
    let mut stream = TcpStream::connect(addr).expect("connects");
    stream.set_read_timeout(Some(PATIENCE)).expect("timeout");
    stream.write_all(bytes).expect("sends");
    protocol::read_message::<ServerMessage>(&mut stream, protocol::MAX_SERVER_FRAME)
        .expect("a message from the server")
}

#[test]
fn connections_over_the_cap_are_refused_with_the_reason_while_robots_still_join_and_play() {
    let limits = ServerLimits {
        max_connections: 3,
        // Long enough that the idle connections stay for the whole test.
        handshake_deadline: Duration::from_secs(120),
        ..ServerLimits::default()
    };
    let server = limited_server(|_| {}, limits);
    let addr = server.local_addr();
    let mut robot = join(addr, 10, 1);
    a_frame(&mut robot);
    let idle: Vec<TcpStream> =
        (0..2).map(|_| TcpStream::connect(addr).expect("connects")).collect();
    until("the idle connections to be open", || (server.counters().connections == 3).then_some(()));

    match first_reply(addr, &hello_frame(10, 2)) {
        ServerMessage::Error { code: ErrorCode::TooManyConnections, message } => {
            assert!(message.contains("3 connections open"), "{message}");
        }
        other => panic!("expected too_many_connections, got {other:?}"),
    }
    assert!(matches!(
        connect(addr, 10, 2, Duration::from_secs(5)),
        Err(ConnectError::Refused { code: ErrorCode::TooManyConnections, .. })
    ));
    assert!(!server.sim().lock().is_present(RobotId::new(0, 2)));
    assert_eq!(server.counters().refused, 2);

    // The robot already playing never noticed.
    let before = robot.platform.received();
    until("more frames", || (robot.platform.received() > before + 10).then_some(()));
    assert_eq!(robot.platform.closed(), None);

    // The cap counts open connections: once one closes, a robot joins again.
    drop(idle);
    until("the idle connections to close", || (server.counters().connections == 1).then_some(()));
    let mut second = join(addr, 10, 2);
    a_frame(&mut second);
    server.stop().expect("stops cleanly");
}

#[test]
fn a_client_that_trickles_its_hello_is_dropped_at_the_handshake_deadline() {
    let limits =
        ServerLimits { handshake_deadline: Duration::from_secs(1), ..ServerLimits::default() };
    let server = limited_server(|_| {}, limits);
    let hello = hello_frame(10, 1);
    let mut stream = TcpStream::connect(server.local_addr()).expect("connects");
    stream.set_read_timeout(Some(PATIENCE)).expect("timeout");
    let sent = Arc::new(AtomicUsize::new(0));
    let stop = Arc::new(AtomicBool::new(false));
    let trickle = {
        let (mut writer, sent, stop) =
            (stream.try_clone().expect("clones"), Arc::clone(&sent), Arc::clone(&stop));
        let hello = hello.clone();
        // Each byte well within the deadline of the previous one: only a deadline over the
        // whole handshake ends this.
        std::thread::spawn(move || {
            for byte in hello {
                if stop.load(Ordering::SeqCst) || writer.write_all(&[byte]).is_err() {
                    return;
                }
                sent.fetch_add(1, Ordering::SeqCst);
                std::thread::sleep(Duration::from_millis(200));
            }
        })
    };
    let reply = protocol::read_message::<ServerMessage>(&mut stream, protocol::MAX_SERVER_FRAME);
    let sent_at_reply = sent.load(Ordering::SeqCst);
    stop.store(true, Ordering::SeqCst);
    let _ = trickle.join();
    match reply {
        Ok(ServerMessage::Error { code: ErrorCode::HandshakeTimeout, message }) => {
            assert!(message.contains("1 s"), "{message}");
        }
        other => panic!("expected handshake_timeout, got {other:?}"),
    }
    assert!(
        sent_at_reply < hello.len(),
        "the server waited for the whole trickled hello ({sent_at_reply} bytes)"
    );
    assert!(!server.sim().lock().is_present(RobotId::new(0, 1)));
    assert_eq!(server.counters().refused, 1);
    server.stop().expect("stops cleanly");
}

#[test]
fn a_robot_sending_above_the_message_rate_has_the_excess_dropped_and_others_keep_playing() {
    const RATE: u32 = 50;
    const SENT: u64 = 5000;
    let limits = ServerLimits { max_messages_per_second: RATE, ..ServerLimits::default() };
    let server = limited_server(|_| {}, limits);
    let addr = server.local_addr();
    let mut other = join(addr, 20, 1);
    a_frame(&mut other);

    let mut flood = TcpStream::connect(addr).expect("connects");
    flood.write_all(&hello_frame(10, 1)).expect("sends");
    let mut replies = flood.try_clone().expect("clones");
    assert!(matches!(
        protocol::read_message::<ServerMessage>(&mut replies, protocol::MAX_SERVER_FRAME),
        Ok(ServerMessage::Welcome { .. })
    ));
    // Read what the server sends, so that only the orders are at stake.
    let drain = std::thread::spawn(move || {
        while protocol::read_message::<ServerMessage>(&mut replies, protocol::MAX_SERVER_FRAME)
            .is_ok()
        {}
    });
    let walk = ActuatorOrders {
        head: None,
        body: Some(BodyOrder::Walk { velocity: Velocity::new(0.1, 0.0, 0.0) }),
    };
    let orders = protocol::encode(&ClientMessage::Orders { orders: walk });
    let burst: Vec<u8> = (0..SENT).flat_map(|_| orders.iter().copied()).collect();
    let frames_before = other.platform.received();
    let start = Instant::now();
    flood.write_all(&burst).expect("sends");
    until("the server to read every order", || (server.counters().messages >= SENT).then_some(()));
    let elapsed = start.elapsed().as_secs_f64();
    let counters = server.counters();
    let applied = SENT - counters.throttled;
    // A tenth of a second's worth, at least 10, may pass at once; then the rate.
    let allowed = 10.0 + f64::from(RATE) * elapsed;
    assert!(
        (applied as f64) <= allowed + 1.0,
        "{applied} of {SENT} orders applied in {elapsed:.2} s at {RATE} per second"
    );
    assert!(applied >= 1, "orders within the rate are applied");
    // The flooding robot stays (its excess is only dropped), and the other one keeps playing.
    assert!(server.sim().lock().is_present(RobotId::new(0, 1)));
    until("the other robot's frames", || {
        (other.platform.received() > frames_before + 20).then_some(())
    });
    assert_eq!(other.platform.closed(), None);
    drop(flood);
    server.stop().expect("stops cleanly");
    let _ = drain.join();
}

/// A server that welcomes one robot and then never reads from it again.
fn stalled_server() -> (SocketAddr, std::sync::mpsc::Sender<()>) {
    let listener = TcpListener::bind("127.0.0.1:0").expect("binds");
    let addr = listener.local_addr().expect("an address");
    let info = Simulation::new(SimConfig::default()).expect("valid config").platform_info();
    let (release, released) = std::sync::mpsc::channel::<()>();
    std::thread::spawn(move || {
        let (mut stream, _) = listener.accept().expect("a robot connects");
        let hello =
            protocol::read_message::<ClientMessage>(&mut stream, protocol::MAX_CLIENT_FRAME);
        assert!(matches!(hello, Ok(ClientMessage::Hello { .. })));
        let welcome = ServerMessage::Welcome {
            version: protocol::VERSION,
            team: 10,
            player: 1,
            team_index: 0,
            info,
            max_team_message: 128,
            time: Time::ZERO,
        };
        protocol::write_message(&mut stream, &welcome).expect("welcomes");
        // Holds the connection open, reading nothing.
        let _ = released.recv();
        drop(stream);
    });
    (addr, release)
}

#[test]
fn a_robot_whose_server_stops_reading_gets_a_write_timeout_error_and_drops_promptly() {
    let (addr, release) = stalled_server();
    let options = ClientOptions {
        timeout: Duration::from_secs(5),
        write_timeout: Duration::from_millis(300),
    };
    let robot = connect_with(addr, 10, 1, options).expect("welcomed");
    let (result_tx, result) = std::sync::mpsc::channel();
    // On another thread, so that a send or drop that never returns fails the test instead of
    // hanging it.
    std::thread::spawn(move || {
        let mut robot = robot;
        let walk = ActuatorOrders {
            head: None,
            body: Some(BodyOrder::Walk { velocity: Velocity::new(0.1, 0.0, 0.0) }),
        };
        // Fills the socket's buffers until a send blocks for the write timeout.
        let error = loop {
            if let Err(error) = robot.platform.write(now(), &walk) {
                break error;
            }
        };
        let _ = result_tx.send(Some(error.to_string()));
        drop(robot);
        let _ = result_tx.send(None);
    });
    let error = result.recv_timeout(PATIENCE);
    let dropped = error.is_ok() && result.recv_timeout(PATIENCE).is_ok();
    let _ = release.send(());
    let error = error.expect("a send to the stalled server returns").expect("an error");
    assert!(error.contains("write timeout"), "{error}");
    assert!(dropped, "dropping the robot did not return");
}

/// A server that reads `hello` and then sends its welcome one byte every 100 ms: each read
/// gets a byte well within any timeout, so only a deadline for the whole handshake ends it.
fn trickling_server() -> SocketAddr {
    let listener = TcpListener::bind("127.0.0.1:0").expect("binds");
    let addr = listener.local_addr().expect("an address");
    let info = Simulation::new(SimConfig::default()).expect("valid config").platform_info();
    std::thread::spawn(move || {
        let (mut stream, _) = listener.accept().expect("a robot connects");
        let hello =
            protocol::read_message::<ClientMessage>(&mut stream, protocol::MAX_CLIENT_FRAME);
        assert!(matches!(hello, Ok(ClientMessage::Hello { .. })));
        let welcome = ServerMessage::Welcome {
            version: protocol::VERSION,
            team: 10,
            player: 1,
            team_index: 0,
            info,
            max_team_message: 128,
            time: Time::ZERO,
        };
        for byte in protocol::encode(&welcome) {
            // Ends when the robot gives up and closes the connection.
            if stream.write_all(&[byte]).is_err() {
                return;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    });
    addr
}

#[test]
fn a_server_that_trickles_its_welcome_fails_the_connect_at_the_timeout() {
    let addr = trickling_server();
    let options = ClientOptions {
        timeout: Duration::from_millis(500),
        write_timeout: Duration::from_secs(2),
    };
    let (result_tx, result) = std::sync::mpsc::channel();
    // On another thread, so that a connect that never returns fails the test instead of
    // hanging it.
    std::thread::spawn(move || {
        let _ = result_tx.send(connect_with(addr, 10, 1, options).map(|_| ()));
    });
    // The welcome would take minutes at this pace; the whole handshake gets half a second.
    let outcome = result.recv_timeout(Duration::from_secs(10));
    match outcome {
        Ok(Err(ConnectError::Handshake { error, .. })) => {
            assert!(error.to_string().contains("0.5 s"), "the error names the timeout: {error}");
        }
        Ok(other) => panic!("expected a handshake timeout, got {other:?}"),
        Err(_) => panic!("connect still waiting after 10 s with a 0.5 s timeout"),
    }
}

/// A zero limit is a mistake, never a setting: a zero write timeout means "no timeout" to the
/// OS, which would take the bound off every write (and off stopping the server) without a word,
/// and a server that admits no connection, hello or message serves nobody.
#[test]
fn limits_that_would_switch_themselves_off_are_refused_by_name() {
    let zero = Duration::ZERO;
    let cases = [
        (ServerLimits { write_timeout: zero, ..ServerLimits::DEFAULT }, "write_timeout"),
        (ServerLimits { handshake_deadline: zero, ..ServerLimits::DEFAULT }, "handshake_deadline"),
        (ServerLimits { max_connections: 0, ..ServerLimits::DEFAULT }, "max_connections"),
        (
            ServerLimits { max_messages_per_second: 0, ..ServerLimits::DEFAULT },
            "max_messages_per_second",
        ),
    ];
    for (limits, field) in cases {
        let sim = SimHandle::new(Simulation::new(SimConfig::default()).expect("valid config"));
        let options = ServerOptions { limits, ..ServerOptions::default() };
        match Server::bind("127.0.0.1:0", sim, options) {
            Ok(_) => panic!("a server with {field} = 0 was started"),
            Err(error) => assert!(error.to_string().contains(field), "{field}: {error}"),
        }
    }
}
