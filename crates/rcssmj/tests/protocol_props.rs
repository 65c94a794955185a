//! Property tests of the rcssservermj protocol: what the encoders write is what the server's
//! parser reads (checked by parsing it back the way the server does), perceptions written in
//! the server's format decode to the values in SI units, and no input makes a decoder panic.

use std::io::Cursor;

use proptest::prelude::*;
use strata_rcssmj::protocol::monitor::{
    MonitorCommand, MonitorDecoder, RobotOrientation, TeamRef, encode_monitor_commands,
};
use strata_rcssmj::protocol::sexp::{self, Sexp};
use strata_rcssmj::protocol::{
    Effector, FieldSide, JointCommand, MAX_SAY_BYTES, ProtocolError, SeenObject, decode_perception,
    encode_effectors, read_frame, write_frame,
};

const FIXTURE: &[u8] = include_bytes!("data/perception_see_robot.sexp");
const MONITOR_FULL: &[u8] = include_bytes!("data/monitor_full.sexp");

/// Parses an encoded message the way the server does: a sequence of lists of atoms.
fn server_view(bytes: &[u8]) -> Vec<Vec<String>> {
    let parsed = sexp::parse(bytes, 4).unwrap_or_else(|e| panic!("unparsable {e}"));
    parsed
        .iter()
        .map(|item| {
            item.as_list()
                .unwrap_or_else(|| panic!("not a list"))
                .iter()
                .map(|atom| match atom {
                    Sexp::Atom(text) => (*text).to_owned(),
                    Sexp::List(l) => format!("{l:?}"),
                })
                .collect()
        })
        .collect()
}

fn float(text: &str) -> f64 {
    text.parse().unwrap_or_else(|_| panic!("{text:?} is not a number"))
}

fn same(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * a.abs().max(b.abs()).max(1.0)
}

fn name() -> impl Strategy<Value = String> {
    "[a-z][a-z0-9_]{0,8}"
}

fn value() -> impl Strategy<Value = f64> {
    -1e4..1e4f64
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, rng_seed: proptest::test_runner::RngSeed::Fixed(0x5c0c), ..ProptestConfig::default() })]

    #[test]
    fn joint_commands_reach_the_server_in_degrees_and_raw_gains(
        joint in name(), q in value(), dq in value(), kp in value(), kd in value(), tau in value(),
    ) {
        prop_assume!(!["beam", "syn", "SPK"].contains(&joint.as_str()));
        let mut out = Vec::new();
        let command = JointCommand { name: joint.clone(), position: q, velocity: dq, kp, kd, torque: tau };
        encode_effectors(&[Effector::Joint(command), Effector::Sync], &mut out)?;
        let view = server_view(&out);
        prop_assert_eq!(view.len(), 2);
        prop_assert_eq!(&view[0][0], &joint);
        // The server applies radians() to q and dq, nothing to the gains and the torque.
        prop_assert!(same(float(&view[0][1]).to_radians(), q));
        prop_assert!(same(float(&view[0][2]).to_radians(), dq));
        prop_assert!(float(&view[0][3]) == kp && float(&view[0][4]) == kd && float(&view[0][5]) == tau);
        prop_assert_eq!(&view[1], &vec!["syn".to_owned()]);
    }

    #[test]
    fn beams_reach_the_server_in_degrees(x in value(), y in value(), theta in -7.0..7.0f64) {
        let mut out = Vec::new();
        encode_effectors(&[Effector::Beam { x, y, theta }], &mut out)?;
        let view = server_view(&out);
        prop_assert_eq!(&view[0][0], "beam");
        prop_assert!(float(&view[0][1]) == x && float(&view[0][2]) == y);
        prop_assert!(same(float(&view[0][3]).to_radians(), theta));
    }

    #[test]
    fn spoken_messages_come_back_as_heard(payload in proptest::collection::vec(any::<u8>(), 1..=MAX_SAY_BYTES), volume in 0.0..=1.0f64) {
        let mut out = Vec::new();
        encode_effectors(&[Effector::Say { volume, payload: payload.clone() }], &mut out)?;
        let view = server_view(&out);
        prop_assert_eq!(&view[0][..2], &["SPK".to_owned(), "say".to_owned()]);
        prop_assert!(same(float(&view[0][2]) / 100.0, volume));
        // What the server broadcasts is the decoded payload, base64-encoded again in MIC.
        let mic = format!("(MIC hear (12 {}))", view[0][3]);
        let heard = decode_perception(mic.as_bytes())?.heard;
        prop_assert_eq!(heard.len(), 1);
        prop_assert_eq!(&heard[0].payload, &payload);
    }

    #[test]
    fn too_long_messages_are_refused(payload in proptest::collection::vec(any::<u8>(), MAX_SAY_BYTES + 1..64)) {
        let mut out = Vec::new();
        let result = encode_effectors(&[Effector::Say { volume: 1.0, payload }], &mut out);
        prop_assert!(matches!(result, Err(ProtocolError::Effector { effector: "say", .. })), "{:?}", result);
        prop_assert!(out.is_empty());
    }

    #[test]
    fn place_commands_reach_the_server_as_written(
        position in proptest::array::uniform3(value()),
        velocity in proptest::option::of(proptest::array::uniform3(value())),
        player in 1u8..=99, yaw in -7.0..7.0f64, team in name(), left in any::<bool>(),
    ) {
        let team_ref = if left { TeamRef::Side(FieldSide::Left) } else { TeamRef::Name(team.clone()) };
        let commands = [
            MonitorCommand::PlaceBall { position, velocity },
            MonitorCommand::PlaceRobot { team: team_ref, player, position, orientation: RobotOrientation::Yaw(yaw) },
        ];
        let mut out = Vec::new();
        encode_monitor_commands(&commands, &mut out)?;
        let parsed = sexp::parse(&out, 4).map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(parsed.len(), 2);
        let field = |item: &Sexp<'_>, key: &str| -> Vec<f64> {
            item.as_list().into_iter().flatten()
                .filter_map(Sexp::as_list)
                .find(|l| l.first().and_then(Sexp::as_atom) == Some(key))
                .map(|l| l[1..].iter().filter_map(Sexp::as_atom).map(float).collect())
                .unwrap_or_default()
        };
        prop_assert_eq!(parsed[0].head(), Some("ball"));
        prop_assert_eq!(field(&parsed[0], "pos"), position.to_vec());
        prop_assert_eq!(field(&parsed[0], "vel"), velocity.map(|v| v.to_vec()).unwrap_or_default());
        prop_assert_eq!(parsed[1].head(), Some("agent"));
        prop_assert_eq!(field(&parsed[1], "unum"), vec![f64::from(player)]);
        let moved = field(&parsed[1], "move");
        prop_assert_eq!(&moved[..3], &position[..]);
        prop_assert!(same(moved[3].to_radians(), yaw));
        let team_atom = parsed[1].as_list().into_iter().flatten().filter_map(Sexp::as_list)
            .find(|l| l.first().and_then(Sexp::as_atom) == Some("team"))
            .and_then(|l| l.get(1)?.as_atom());
        prop_assert_eq!(team_atom, Some(if left { "Left" } else { team.as_str() }));
    }

    #[test]
    fn perceptions_in_the_server_format_decode_to_si(
        now in 0.0..1e4f64, q in proptest::array::uniform4(-1.0..1.0f64),
        gyro in proptest::array::uniform3(-2000.0..2000.0f64),
        joints in proptest::collection::vec((name(), -180.0..180.0f64, -1e3..1e3f64), 0..30),
        markers in proptest::collection::vec((name(), 0.0..100.0f64, -60.0..60.0f64, -60.0..60.0f64), 0..40),
        team in name(), id in 1u32..100,
    ) {
        // Written the way rcsssmj's to_sexp() methods write them (Python's repr of floats is
        // the shortest round-trip form, as Rust's Display).
        let mut text = format!("(time (now {now}))(quat (n torso_quat) (q {} {} {} {}))(GYR (n torso_gyro) (rt {} {} {}))",
            q[0], q[1], q[2], q[3], gyro[0], gyro[1], gyro[2]);
        for (n, ax, vx) in &joints {
            text += &format!("(HJ (n {n})(ax {ax})(vx {vx}))");
        }
        text += "(See ";
        for (n, d, a, e) in &markers {
            text += &format!("({n} (pol {d} {a} {e}))");
        }
        text += &format!("(P (team {team})(id {id})(head (pol 1 2 3))))");
        let p = decode_perception(text.as_bytes())?;
        prop_assert_eq!(p.time, Some(now));
        prop_assert_eq!(p.torso_orientation, Some(q));
        let g = p.gyro.unwrap_or_default();
        prop_assert!((0..3).all(|i| same(g[i], gyro[i].to_radians())));
        prop_assert_eq!(p.joints.len(), joints.len());
        for (decoded, (n, ax, vx)) in p.joints.iter().zip(&joints) {
            prop_assert_eq!(&decoded.name, n);
            prop_assert!(same(decoded.angle, ax.to_radians()) && same(decoded.velocity, vx.to_radians()));
        }
        let vision = p.vision.unwrap_or_default();
        prop_assert_eq!(vision.len(), markers.len() + 1);
        for (seen, (n, d, a, e)) in vision.iter().zip(&markers) {
            let SeenObject::Marker(m) = seen else { return Err(TestCaseError::fail("a robot where a marker was written")) };
            prop_assert_eq!(&m.name, n);
            prop_assert!(m.polar.distance == *d && same(m.polar.azimuth, a.to_radians()) && same(m.polar.elevation, e.to_radians()));
        }
        let robot = matches!(vision.last(), Some(SeenObject::Robot(r)) if r.team == team && r.player == id && r.parts.len() == 1);
        prop_assert!(robot);
    }

    #[test]
    fn frames_round_trip(payloads in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..300), 0..8)) {
        let mut wire = Vec::new();
        for payload in &payloads {
            write_frame(&mut wire, payload)?;
        }
        let mut reader = Cursor::new(wire);
        let mut buffer = Vec::new();
        for payload in &payloads {
            prop_assert_eq!(read_frame(&mut reader, &mut buffer, 300)?, &payload[..]);
        }
        prop_assert!(matches!(read_frame(&mut reader, &mut buffer, 300), Err(strata_rcssmj::protocol::FrameError::Closed)));
    }

    #[test]
    fn any_cut_of_a_frame_stream_is_a_truncation_error(cut in 1usize..FIXTURE.len() + 3) {
        let mut wire = Vec::new();
        write_frame(&mut wire, FIXTURE)?;
        wire.truncate(cut);
        let mut buffer = Vec::new();
        let result = read_frame(&mut Cursor::new(wire), &mut buffer, 1 << 16);
        let truncated = matches!(result, Err(strata_rcssmj::protocol::FrameError::TruncatedLength { .. } | strata_rcssmj::protocol::FrameError::TruncatedPayload { .. }));
        prop_assert!(truncated);
    }

    #[test]
    fn garbage_and_mutated_messages_never_panic(
        garbage in proptest::collection::vec(any::<u8>(), 0..512),
        flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
    ) {
        let _ = decode_perception(&garbage);
        let mut decoder = MonitorDecoder::new();
        let _ = decoder.decode(&garbage);
        let mut mutated = FIXTURE.to_vec();
        let mut monitor = MONITOR_FULL.to_vec();
        for (index, byte) in &flips {
            mutated[index.index(FIXTURE.len())] = *byte;
            monitor[index.index(MONITOR_FULL.len())] = *byte;
        }
        let _ = decode_perception(&mutated);
        let _ = decoder.decode(&monitor);
    }
}
