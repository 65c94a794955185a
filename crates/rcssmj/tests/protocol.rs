//! The agent and monitor protocols on messages captured from rcssservermj 0.2.1 (two T1s,
//! `Alpha` 1 on the left and `Beta` 2 on the right, beamed to (-1.5, 0.5, 0°) and (2, -1, 30°);
//! see tests/data/README.md).

use std::f64::consts::PI;
use std::io::Cursor;

use strata_rcssmj::protocol::monitor::MonitorDecoder;
use strata_rcssmj::protocol::{
    FieldSide, FrameError, MAX_PERCEPTION_FRAME, PlayMode, ProtocolError, SeenObject, SexpError,
    decode_perception, read_frame, write_frame,
};

const FIRST_CYCLE: &[u8] = include_bytes!("data/perception_first_cycle_see.sexp");
const NO_SEE: &[u8] = include_bytes!("data/perception_no_see.sexp");
const SEE_ROBOT: &[u8] = include_bytes!("data/perception_see_robot.sexp");
const MIC_EMPTY: &[u8] = include_bytes!("data/perception_mic_empty.sexp");
const HEAR: &[u8] = include_bytes!("data/perception_hear.sexp");
const KICKOFF: &[u8] = include_bytes!("data/perception_kickoff_left.sexp");
const RIGHT_TEAM: &[u8] = include_bytes!("data/perception_right_team.sexp");
const STREAM: &[u8] = include_bytes!("data/perception_stream.bin");
const MONITOR_FULL: &[u8] = include_bytes!("data/monitor_full.sexp");
const MONITOR_DIFF: &[u8] = include_bytes!("data/monitor_diff_first.sexp");
const MONITOR_BALL_MOVED: &[u8] = include_bytes!("data/monitor_diff_ball_moved.sexp");
const MONITOR_AFTER_KICKOFF: &[u8] = include_bytes!("data/monitor_diff_after_kickoff.sexp");

fn close(a: f64, b: f64, tolerance: f64) -> bool {
    (a - b).abs() <= tolerance
}

#[test]
fn first_cycle_decodes_every_perceptor_in_si_units() -> Result<(), ProtocolError> {
    let p = decode_perception(FIRST_CYCLE)?;
    assert_eq!(p.time, Some(8.55));
    let Some(game) = p.game.as_ref() else { panic!("no GS perceptor") };
    assert_eq!(game.play_mode, Some(PlayMode::BeforeKickOff));
    assert_eq!(game.play_mode_text, "BeforeKickOff");
    assert_eq!(game.team_left.as_deref(), Some("Alpha"));
    assert_eq!(game.team_right.as_deref(), Some("Beta"));
    assert_eq!((game.score_left, game.score_right), (0, 0));
    assert_eq!(game.side_of("Alpha"), Some(FieldSide::Left));
    assert_eq!(game.side_of("Beta"), Some(FieldSide::Right));
    assert_eq!(game.side_of("Gamma"), None);
    assert_eq!(p.torso_orientation, Some([0.707, 0.0, 0.0, -0.707]));
    assert_eq!(p.torso_position_truth, Some([-3.0, 21.0, 0.673]));
    assert_eq!(p.gyro, Some([0.0, 0.0, 0.0]));
    assert_eq!(p.accel, Some([0.0, 0.0, 0.0]));
    let names: Vec<&str> = p.joints.iter().map(|j| j.name.as_str()).collect();
    assert_eq!(names.len(), 23);
    assert_eq!(&names[..3], ["q_hj1", "q_hj2", "q_laj1"]);
    assert_eq!(&names[17..], ["q_rlj1", "q_rlj2", "q_rlj3", "q_rlj4", "q_rlj5", "q_rlj6"]);
    let vision = p.vision.as_ref().map(Vec::len);
    assert_eq!(vision, Some(22));
    assert!(p.heard.is_empty());
    Ok(())
}

#[test]
fn angles_and_rates_are_converted_from_degrees() -> Result<(), ProtocolError> {
    let p = decode_perception(NO_SEE)?;
    // (HJ (n q_laj2)(ax -0.0)(vx -0.03)) and the ball in the first cycle (B (pol 21.12 8.17 -2.68)).
    let laj2 = p.joints.iter().find(|j| j.name == "q_laj2");
    assert!(laj2.is_some_and(|j| close(j.velocity, -0.03 * PI / 180.0, 1e-12)));
    assert_eq!(p.vision, None, "vision arrives every second cycle only");
    let first = decode_perception(FIRST_CYCLE)?;
    let ball = first.vision.iter().flatten().find_map(|o| match o {
        SeenObject::Marker(m) if m.name == "B" => Some(m.polar),
        _ => None,
    });
    assert!(ball.is_some_and(|b| b.distance == 21.12
        && close(b.azimuth, 8.17_f64.to_radians(), 1e-12)
        && close(b.elevation, (-2.68_f64).to_radians(), 1e-12)));
    let moving = decode_perception(KICKOFF)?;
    // (GYR (n torso_gyro) (rt 0.08 -217.64 -0.14)) in deg/s.
    assert!(moving.gyro.is_some_and(|g| close(g[1], (-217.64_f64).to_radians(), 1e-12)));
    Ok(())
}

#[test]
fn robots_in_view_are_listed_with_their_parts() -> Result<(), ProtocolError> {
    let p = decode_perception(SEE_ROBOT)?;
    let robots: Vec<_> = p
        .vision
        .iter()
        .flatten()
        .filter_map(|o| match o {
            SeenObject::Robot(r) => Some(r),
            SeenObject::Marker(_) => None,
        })
        .collect();
    assert_eq!(robots.len(), 1);
    assert_eq!((robots[0].team.as_str(), robots[0].player), ("Beta", 2));
    let parts: Vec<&str> = robots[0].parts.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(parts, ["head", "lfoot", "rfoot"]);
    // Alpha stands at (-1.5, 0.5) facing +x, Beta at (2, -1): ahead and to the right, so a
    // negative azimuth (positive is to the left) about 3.6 m away.
    let head = robots[0].parts[0].polar;
    assert!(head.azimuth < 0.0 && close(head.distance, 3.66, 1e-9));
    let [x, y, _] = head.to_cartesian();
    assert!(close(x, 3.4, 0.15) && close(y, -1.5, 0.15), "{x} {y}");
    Ok(())
}

#[test]
fn right_team_perceives_its_beam_turned_by_half_a_turn() -> Result<(), ProtocolError> {
    let p = decode_perception(RIGHT_TEAM)?;
    // (beam 2 -1 30) by the right team: x stays on its own (positive) half, y as given, and
    // the heading is 30° + 180° in the world frame.
    assert_eq!(p.torso_position_truth, Some([1.999, -1.0, 0.667]));
    let q = p.torso_orientation.unwrap_or_default();
    let yaw = 2.0 * q[3].atan2(q[0]);
    assert!(close(yaw.to_degrees().rem_euclid(360.0), 210.0, 0.2), "{}", yaw.to_degrees());
    Ok(())
}

#[test]
fn team_messages_are_heard_and_an_empty_microphone_is_no_message() -> Result<(), ProtocolError> {
    assert!(decode_perception(MIC_EMPTY)?.heard.is_empty());
    let p = decode_perception(HEAR)?;
    assert_eq!(p.heard.len(), 1);
    assert_eq!(p.heard[0].payload, b"hello");
    assert!(close(p.heard[0].azimuth, (-54.0_f64).to_radians(), 1e-12));
    Ok(())
}

#[test]
fn play_mode_text_and_play_time_follow_the_kick_off() -> Result<(), ProtocolError> {
    let game = decode_perception(KICKOFF)?.game;
    assert!(game.as_ref().is_some_and(|g| g.play_mode == Some(PlayMode::KickOffLeft)
        && g.play_mode_text == "KickOff_Left"
        && g.play_time == 0.04));
    assert_eq!(decode_perception(KICKOFF)?.vision, Some(vec![]));
    Ok(())
}

#[test]
fn every_play_mode_round_trips_through_its_name_and_index() {
    for (index, mode) in PlayMode::ALL.into_iter().enumerate() {
        assert_eq!(PlayMode::from_server_name(mode.as_str()), Some(mode));
        assert_eq!(PlayMode::from_index(index), Some(mode));
    }
    assert_eq!(PlayMode::from_server_name("playon"), None);
    assert_eq!(PlayMode::from_index(23), None);
}

#[test]
fn unknown_perceptors_are_skipped() -> Result<(), ProtocolError> {
    let p = decode_perception(
        b"(time (now 1.5))(TCH n lf val 1)(FRP (n lf) (c 0 0 0) (f 0 0 1))(syn)(quat (n head_quat) (q 1 0 0 0))",
    )?;
    assert_eq!(p.time, Some(1.5));
    assert_eq!(p.torso_orientation, None, "only the torso quaternion is the torso's");
    Ok(())
}

#[test]
fn malformed_known_perceptors_are_errors_naming_them() {
    let cases: [(&[u8], &str); 8] = [
        (b"(time (now abc))", "time"),
        (b"(time)", "time"),
        (b"(GS (t 0)(sl 0)(sr 0))", "GS"),
        (b"(GS (t 0)(pm PlayOn)(sl -1)(sr 0))", "GS"),
        (b"(quat (n torso_quat) (q 1 0 0))", "quat"),
        (b"(HJ (n q_hj1)(ax 1)(vx nan))", "HJ"),
        (b"(See (B (pol 1 2)))", "See"),
        (b"(MIC hear (10 !!!!))", "MIC"),
    ];
    for (input, perceptor) in cases {
        match decode_perception(input) {
            Err(ProtocolError::Perceptor { perceptor: p, .. }) => assert_eq!(p, perceptor),
            other => panic!("{:?} gave {other:?}", String::from_utf8_lossy(input)),
        }
    }
    assert!(matches!(decode_perception(b"(error)"), Err(ProtocolError::ServerError)));
}

#[test]
fn syntax_errors_say_what_and_where() {
    let cases: [(&[u8], SexpError); 5] = [
        (b"(time (now 1)", SexpError::Unclosed { offset: 0 }),
        (b"(time (now 1)))", SexpError::UnexpectedClose { offset: 14 }),
        (b"(time) now", SexpError::TopLevelAtom { offset: 7 }),
        (b"(a \xff)", SexpError::InvalidUtf8 { offset: 3 }),
        (&[b'('; 100], SexpError::TooDeep { offset: 16, max: 16 }),
    ];
    for (input, expected) in cases {
        match decode_perception(input) {
            Err(ProtocolError::Syntax(e)) => assert_eq!(e, expected),
            other => panic!("{:?} gave {other:?}", String::from_utf8_lossy(input)),
        }
    }
    let message = decode_perception(b"(a))").err().map(|e| e.to_string());
    assert_eq!(message.as_deref(), Some("malformed S-expression: unexpected ')' at byte 3"));
}

#[test]
fn a_hostile_nesting_is_refused_without_recursion() {
    let deep = vec![b'('; 10_000_000];
    assert!(matches!(
        decode_perception(&deep),
        Err(ProtocolError::Syntax(SexpError::TooDeep { .. }))
    ));
}

#[test]
fn frames_of_a_captured_stream_read_back_and_end_cleanly() -> Result<(), ProtocolError> {
    let mut reader = Cursor::new(STREAM);
    let mut buffer = Vec::new();
    let mut count = 0;
    loop {
        match read_frame(&mut reader, &mut buffer, MAX_PERCEPTION_FRAME) {
            Ok(payload) => {
                decode_perception(payload)?;
                count += 1;
            }
            Err(FrameError::Closed) => break,
            Err(e) => return Err(e.into()),
        }
    }
    assert_eq!(count, 6);
    Ok(())
}

#[test]
fn written_frames_read_back() -> Result<(), FrameError> {
    let mut wire = Vec::new();
    write_frame(&mut wire, b"(syn)")?;
    write_frame(&mut wire, b"")?;
    assert_eq!(&wire[..9], b"\0\0\0\x05(syn)");
    let mut reader = Cursor::new(wire);
    let mut buffer = Vec::new();
    assert_eq!(read_frame(&mut reader, &mut buffer, 16)?, b"(syn)");
    assert_eq!(read_frame(&mut reader, &mut buffer, 16)?, b"");
    assert!(matches!(read_frame(&mut reader, &mut buffer, 16), Err(FrameError::Closed)));
    Ok(())
}

#[test]
fn truncated_and_oversized_frames_are_distinct_errors() {
    let mut buffer = Vec::new();
    let mut read = |bytes: &[u8], max| {
        read_frame(&mut Cursor::new(bytes.to_vec()), &mut buffer, max).map(<[u8]>::to_vec)
    };
    assert!(matches!(read(b"\0\0", 16), Err(FrameError::TruncatedLength { got: 2 })));
    assert!(matches!(
        read(b"\0\0\0\x05(sy", 16),
        Err(FrameError::TruncatedPayload { got: 3, expected: 5 })
    ));
    assert!(matches!(
        read(b"\xff\xff\xff\xff", 1024),
        Err(FrameError::Oversized { length: 4_294_967_295, max: 1024 })
    ));
    assert!(matches!(read(b"", 16), Err(FrameError::Closed)));
    let message = read(b"\0\0\0\x09abc", 16).err().map(|e| e.to_string());
    assert_eq!(
        message.as_deref(),
        Some("the stream ended inside a frame: 3 of 9 payload bytes arrived")
    );
}

#[test]
fn monitor_stream_gives_ball_and_robot_ground_truth() -> Result<(), ProtocolError> {
    let mut decoder = MonitorDecoder::new();
    let state = decoder.decode(MONITOR_FULL)?;
    assert_eq!(state.sim_time, Some(8.60));
    let ball = state.ball_position.unwrap_or_default();
    assert!(close(ball[0], 0.0, 1e-9) && close(ball[1], 0.0, 1e-9) && close(ball[2], 0.1099, 1e-9));
    let game = state.game.clone().unwrap_or_default();
    assert_eq!(game.play_mode, Some(PlayMode::BeforeKickOff));
    assert_eq!(game.team_left.as_deref(), Some("Alpha"));
    assert_eq!(game.half, 1);
    assert_eq!(state.robots.len(), 2);
    let alpha = &state.robots[0];
    assert_eq!((alpha.team.as_str(), alpha.player), ("Alpha", 1));
    // Before their beams the robots stand where the server put them on connecting, facing -y:
    // the agent's first perception says (p -3.0 21.0 0.673), (q 0.707 0 0 -0.707).
    assert!(close(alpha.position[0], -3.0, 0.01) && close(alpha.position[1], 21.0, 0.01));
    assert!(close(alpha.orientation[0], 0.707, 0.01) && close(alpha.orientation[3], -0.707, 0.01));

    // The first diff carries the beams; the robots' transforms update in place.
    let state = decoder.decode(MONITOR_DIFF)?;
    assert_eq!(state.game.as_ref().and_then(|g| g.team_right.as_deref()), Some("Beta"));
    let alpha = &state.robots[0];
    assert_eq!(alpha.position, [-1.5, 0.5, 0.6671]);
    assert!(close(alpha.orientation[0], 1.0, 1e-6));
    let beta = &state.robots[1];
    assert_eq!(beta.position, [2.0, -1.0, 0.6671]);
    let yaw = 2.0 * beta.orientation[3].atan2(beta.orientation[0]);
    assert!(close(yaw.to_degrees().rem_euclid(360.0), 210.0, 0.1), "{}", yaw.to_degrees());

    // After (ball (pos 1.0 0.5 0.11) (vel 0 0 0)), then after (kickOff Left) puts it back.
    let ball = decoder.decode(MONITOR_BALL_MOVED)?.ball_position.unwrap_or_default();
    assert!(close(ball[0], 1.0, 1e-9) && close(ball[1], 0.5, 1e-9), "{ball:?}");
    let state = decoder.decode(MONITOR_AFTER_KICKOFF)?;
    let ball = state.ball_position.unwrap_or_default();
    assert!(close(ball[0], 0.0, 1e-9) && close(ball[1], 0.0, 1e-9), "{ball:?}");
    assert_eq!(state.game.as_ref().and_then(|g| g.play_mode), Some(PlayMode::KickOffLeft));
    Ok(())
}

#[test]
fn a_diff_that_does_not_match_the_full_graph_is_an_error() -> Result<(), ProtocolError> {
    let mut decoder = MonitorDecoder::new();
    decoder.decode(MONITOR_FULL)?;
    let result = decoder.decode(b"((RSMP 1 0)((sg 1 0)diff(nd)))");
    assert!(matches!(result, Err(ProtocolError::Monitor { .. })), "{result:?}");
    Ok(())
}
