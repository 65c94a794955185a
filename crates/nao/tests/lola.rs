//! The platform against a fake LoLA server: sensor packets in, one actuator packet out per
//! sensor packet, errors for truncated and malformed packets, disconnection.

mod common;

use std::time::Duration;

use common::{FakeLola, HEAD_ID, recorded_packet};
use strata_nao::codec::touch;
use strata_nao::{Joint, Leds, LolaConfig, LolaError, LolaPlatform, Rgb, SENSOR_PACKET_SIZE};
use strata_robot::geometry::Velocity;
use strata_robot::platform::{
    ActuatorOrders, BodyMotionState, BodyOrder, FallDirection, HeadAngles, HeadOrder, MotionName,
    Platform, PlatformError, SpecialMotion,
};
use strata_runtime::Time;

/// Stall detection far beyond anything a loaded test machine causes, so no test depends on
/// timing.
fn config() -> LolaConfig {
    LolaConfig { stall_timeout: Duration::from_secs(30), ..LolaConfig::default() }
}

/// Starts a fake LoLA, queues the first packet and connects to it.
fn connected() -> (FakeLola, LolaPlatform) {
    let mut lola = FakeLola::start();
    lola.send_recorded();
    let platform = LolaPlatform::connect(lola.path(), config()).expect("connect to the fake LoLA");
    let first = lola.reply();
    assert_eq!(first.stiffness, [0.0; 25], "the robot starts limp");
    (lola, platform)
}

fn now() -> Time {
    Time::from_secs_f64(100.0)
}

#[test]
fn sensors_arrive_in_strata_conventions() {
    let (mut lola, mut platform) = connected();
    let info = platform.info();
    assert!(info.name.contains(HEAD_ID), "{}", info.name);
    assert!(!info.can_walk);
    assert_eq!(info.sensor_period, Duration::from_millis(12));
    let motions: Vec<SpecialMotion> = info.motions.iter().map(|m| m.motion).collect();
    for expected in [SpecialMotion::stand_up(0), SpecialMotion::stand_up(1), SpecialMotion::fall(0)]
    {
        assert!(motions.contains(&expected), "{motions:?}");
    }

    let first = platform.read_sensors(now()).expect("read").expect("the first packet");
    assert!(first.stamp <= now());
    assert_eq!(platform.read_sensors(now()).expect("read"), None, "nothing new yet");

    let mut packet = recorded_packet(1);
    packet.touch[touch::CHEST_BUTTON] = 1.0;
    packet.touch[touch::HEAD_REAR] = 1.0;
    packet.position[Joint::HeadYaw.index()] = 0.25;
    packet.position[Joint::HeadPitch.index()] = -0.1;
    lola.exchange_with(&packet);
    let frame = platform.read_sensors(now()).expect("read").expect("a frame");
    assert!((frame.inertial.accelerometer[2] - 9.79).abs() < 1e-5, "upright reads +g on z");
    assert!((frame.inertial.accelerometer[0] + f64::from(packet.accelerometer[0])).abs() < 1e-6);
    assert_eq!(frame.inertial.gyroscope[1], f64::from(packet.gyroscope[1]));
    assert_eq!(frame.inertial.body_angles[1], f64::from(packet.angles[1]));
    assert!((frame.foot_contact.left - 2.16).abs() < 1e-5);
    assert!((frame.foot_contact.right - 2.14).abs() < 1e-5);
    assert!(frame.buttons.all(strata_nao::buttons::CHEST | strata_nao::buttons::HEAD));
    assert!((frame.head.yaw - 0.25).abs() < 1e-6 && (frame.head.pitch + 0.1).abs() < 1e-6);
    assert!((frame.battery.expect("battery") - 0.9).abs() < 1e-3);
    assert!(frame.camera.is_none());

    // Only the newest of several packets is delivered.
    for cycle in 2..5 {
        lola.exchange_with(&recorded_packet(cycle));
    }
    let frame = platform.read_sensors(now()).expect("read").expect("a frame");
    assert_eq!(frame.inertial.body_angles[0], f64::from(recorded_packet(4).angles[0]));
    // Counted before the answer goes out, so exact once the answer has arrived.
    assert_eq!(platform.stats().packets, 5);
    assert_eq!(platform.latest_packet().expect("raw packet").status[10], 1);
}

#[test]
fn head_orders_are_interpolated_each_cycle() {
    let (mut lola, mut platform) = connected();
    let order = HeadOrder { target: HeadAngles { yaw: 0.5, pitch: 0.0 }, max_speed: 2.0 };
    platform.write(now(), &ActuatorOrders { head: Some(order), body: None }).expect("head order");
    let yaw = Joint::HeadYaw.index();
    // Interpolation starts from the encoders of the packet that carries the first step.
    let mut previous = f64::from(recorded_packet(1).position[yaw]);
    let mut reached = false;
    for _ in 0..40 {
        let reply = lola.exchange();
        let command = f64::from(reply.position[yaw]);
        assert!(reply.stiffness[yaw] > 0.5);
        // 2 rad/s over one 12 ms cycle.
        assert!(command - previous <= 0.024 + 1e-5, "{previous} -> {command}");
        assert!(command >= previous - 1e-6, "moves towards the target");
        previous = command;
        if (command - 0.5).abs() < 1e-6 {
            reached = true;
            break;
        }
    }
    assert!(reached, "the head reached its target");
    let feedback = platform.read_motion(now()).expect("feedback");
    assert!(!feedback.head_settled, "the fake robot's encoders did not move");
    assert_eq!(feedback.body, BodyMotionState::Limp);
}

#[test]
fn stand_and_leds_reach_the_actuator_packets() {
    let (mut lola, mut platform) = connected();
    platform
        .write(now(), &ActuatorOrders { head: None, body: Some(BodyOrder::Stand) })
        .expect("stand");
    let mut leds = Leds { chest: Rgb::BLUE, ..Leds::default() };
    leds.set_eyes(Rgb::GREEN);
    platform.set_leds(leds);
    let knee = Joint::LKneePitch.index();
    let reply = lola.exchange();
    assert_eq!(reply.stiffness[knee], 0.7);
    assert_eq!(reply.chest, [0.0, 0.0, 1.0]);
    assert_eq!(reply.left_eye[8..16], [1.0; 8], "green channel of the left eye");
    assert_eq!(platform.read_motion(now()).expect("feedback").body, BodyMotionState::Standing);
    assert!(platform.busy());
    let mut last = reply;
    for _ in 0..110 {
        last = lola.exchange();
    }
    assert!(!platform.busy());
    assert!((f64::from(last.position[knee]) - 46f64.to_radians()).abs() < 1e-5);
}

#[test]
fn walking_is_reported_unsupported() {
    let (mut lola, mut platform) = connected();
    let head = HeadOrder { target: HeadAngles { yaw: -0.3, pitch: 0.1 }, max_speed: 4.0 };
    let walk = BodyOrder::Walk { velocity: Velocity::new(0.2, 0.0, 0.1) };
    let error = platform
        .write(now(), &ActuatorOrders { head: Some(head), body: Some(walk) })
        .expect_err("no gait engine");
    let PlatformError::Unsupported(reason) = &error else { panic!("{error}") };
    assert!(reason.starts_with("walking: no gait engine"), "{reason}");
    // The head part of the same orders was applied.
    let reply = lola.exchange();
    assert!(reply.position[Joint::HeadYaw.index()] < 0.0);

    // A motion the application names and the library lacks is refused, by name.
    let kick = SpecialMotion::new(MotionName::from_static("kick"), 0, false);
    let error = platform
        .write(
            now(),
            &ActuatorOrders { head: None, body: Some(BodyOrder::Special { motion: kick }) },
        )
        .expect_err("no kick");
    assert!(error.to_string().contains("kick 0: not in the NAO motion library"), "{error}");
}

#[test]
fn a_fallen_robot_is_detected_and_stands_up() {
    let (mut lola, mut platform) = connected();
    let mut lying = recorded_packet(0);
    lying.angles = [0.05, -1.45];
    lying.accelerometer = [-9.7, 0.1, -0.5];
    for _ in 0..6 {
        lola.exchange_with(&lying);
    }
    let feedback = platform.read_motion(now()).expect("feedback");
    assert_eq!(feedback.body, BodyMotionState::Fallen { direction: FallDirection::Back });
    let stand_up = BodyOrder::Special { motion: SpecialMotion::stand_up(0) };
    platform.write(now(), &ActuatorOrders { head: None, body: Some(stand_up) }).expect("stand up");
    let reply = lola.exchange_with(&lying);
    assert_eq!(reply.stiffness[Joint::LShoulderPitch.index()], 0.8, "first frame of stand_up_back");
    let BodyMotionState::Special { motion, duration, .. } =
        platform.read_motion(now()).expect("feedback").body
    else {
        panic!("not playing the stand-up")
    };
    assert_eq!(motion, SpecialMotion::stand_up(0));
    assert!(duration > 3.0);
}

#[test]
fn a_truncated_packet_is_an_error_and_the_stream_recovers() {
    let (mut lola, mut platform) = connected();
    let _ = platform.read_sensors(now());
    let whole = recorded_packet(1).encode().expect("encode");
    assert_eq!(whole.len(), SENSOR_PACKET_SIZE);
    lola.send_raw(whole[..400].to_vec());
    let mut next = recorded_packet(2);
    next.angles = [0.3, 0.2];
    lola.send(&next);
    // One answer per packet LoLA sent, the cut one included.
    lola.reply();
    lola.reply();
    let error = platform.read_sensors(now()).expect_err("the truncation is reported");
    let PlatformError::Malformed(reason) = &error else { panic!("{error}") };
    assert!(reason.contains("truncated packet: got 400 bytes of a 896-byte packet"), "{reason}");
    let frame = platform.read_sensors(now()).expect("read").expect("the next packet");
    assert_eq!(frame.inertial.body_angles, [f64::from(0.3f32), f64::from(0.2f32)]);
    assert_eq!(platform.stats().malformed, 1);
    // The link is healthy afterwards.
    lola.exchange();
    assert!(platform.read_sensors(now()).expect("read").is_some());
}

#[test]
fn a_malformed_packet_names_the_key_and_costs_only_itself() {
    let (mut lola, mut platform) = connected();
    let _ = platform.read_sensors(now());
    // A map without "Accelerometer": re-encode the packet with that key renamed.
    let mut bytes = recorded_packet(1).encode().expect("encode");
    let at = bytes.windows(13).position(|w| w == b"Accelerometer").expect("key present");
    bytes[at..at + 13].copy_from_slice(b"Acceleromxter");
    lola.send_raw(bytes);
    let hold = lola.reply();
    assert_eq!(hold.stiffness, [0.0; 25], "a garbled packet is answered with the last commands");
    let error = platform.read_sensors(now()).expect_err("malformed");
    assert_eq!(
        error,
        PlatformError::Malformed("LoLA sensor packet: key \"Accelerometer\" is missing".to_owned())
    );
    // Garbage that is not msgpack at all, then a good packet.
    lola.send_raw(vec![0xc1; 37]);
    lola.reply();
    lola.exchange();
    let error = platform.read_sensors(now()).expect_err("garbage reported");
    assert!(
        matches!(error, PlatformError::Malformed(ref r) if r.contains("malformed msgpack")),
        "{error}"
    );
    assert!(platform.read_sensors(now()).expect("read").is_some());
}

#[test]
fn a_packet_cut_by_a_closed_socket_then_disconnection() {
    let (mut lola, mut platform) = connected();
    let _ = platform.read_sensors(now());
    let whole = recorded_packet(1).encode().expect("encode");
    lola.send_raw(whole[..300].to_vec());
    lola.close();
    // The platform notices the closed socket on its own thread; wait for it without timing.
    let mut seen_truncation = false;
    let deadline = std::time::Instant::now() + common::GUARD;
    let disconnected = loop {
        match platform.read_sensors(now()) {
            Err(PlatformError::Malformed(reason)) => {
                assert!(reason.contains("got 300 bytes"), "{reason}");
                seen_truncation = true;
            }
            Err(PlatformError::Disconnected(reason)) => break reason,
            Ok(None) => std::thread::sleep(Duration::from_millis(5)),
            other => panic!("{other:?}"),
        }
        assert!(std::time::Instant::now() < deadline, "disconnection not noticed");
    };
    assert!(seen_truncation);
    assert!(disconnected.contains("closed"), "{disconnected}");
    assert!(matches!(platform.read_motion(now()), Err(PlatformError::Disconnected(_))));
    let stand = ActuatorOrders { head: None, body: Some(BodyOrder::Stand) };
    assert!(matches!(platform.write(now(), &stand), Err(PlatformError::Disconnected(_))));
    assert!(matches!(platform.sit_down(), Err(PlatformError::Disconnected(_))));
}

#[test]
fn connecting_without_lola_fails_clearly() {
    let path = common::socket_path();
    let config = LolaConfig { connect_timeout: Duration::from_millis(100), ..config() };
    let error = LolaPlatform::connect(&path, config).expect_err("nothing listens");
    assert!(matches!(error, LolaError::Connect { .. }));
    let text = error.to_string();
    assert!(
        text.contains(&path.display().to_string()) && text.contains("is LoLA running"),
        "{text}"
    );
}

#[test]
fn a_server_sending_only_garbage_never_yields_a_platform() {
    let mut lola = FakeLola::start();
    lola.send_raw(vec![0x93, 1, 2, 3]);
    lola.close();
    let error = LolaPlatform::connect(lola.path(), config()).expect_err("no valid packet");
    let text = error.to_string();
    assert!(text.contains("sent no valid sensor packet"), "{text}");
    assert!(text.contains("closed"), "{text}");
}

#[test]
fn sitting_down_for_shutdown() {
    let (mut lola, mut platform) = connected();
    platform
        .write(now(), &ActuatorOrders { head: None, body: Some(BodyOrder::Stand) })
        .expect("stand");
    for _ in 0..110 {
        lola.exchange();
    }
    let duration = platform.sit_down().expect("sit");
    assert!(duration > Duration::from_secs(1));
    let mut last = lola.exchange();
    assert!(last.stiffness[Joint::LKneePitch.index()] > 0.5);
    while platform.busy() {
        last = lola.exchange();
    }
    assert_eq!(last.stiffness, [0.0; 25]);
    assert_eq!(platform.read_motion(now()).expect("feedback").body, BodyMotionState::Limp);
}
