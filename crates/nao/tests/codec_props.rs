//! Properties of the LoLA codec: no input makes it panic, and what the fake LoLA sends comes
//! back out of encode → decode (and out of the stream framer, however the bytes are split).

mod common;

use proptest::prelude::*;
use strata_nao::codec::{Battery, touch};
use strata_nao::{
    ActuatorPacket, CodecError, JOINT_COUNT, PacketFramer, RobotConfig, SENSOR_PACKET_SIZE,
    SensorPacket, sensor_frame,
};
use strata_runtime::Time;

fn floats<const N: usize>() -> impl Strategy<Value = [f32; N]> {
    proptest::array::uniform(-1000.0f32..1000.0)
}

fn id() -> impl Strategy<Value = String> {
    "[A-Z0-9]{20}"
}

prop_compose! {
    /// A recorded packet with its values perturbed: the kind of data the fake server sends.
    fn fake_server_packet()(
        cycle in 0u32..100_000,
        position in floats::<JOINT_COUNT>(),
        accelerometer in floats::<3>(),
        gyroscope in floats::<3>(),
        angles in floats::<2>(),
        fsr in proptest::array::uniform8(0.0f32..5.0),
        touch in proptest::array::uniform::<_, { touch::COUNT }>(prop_oneof![Just(0.0f32), Just(1.0f32)]),
        status in proptest::array::uniform::<_, JOINT_COUNT>(0i32..4),
        battery in floats::<4>(),
        body_id in id(),
        head_id in id(),
    ) -> SensorPacket {
        let mut packet = common::recorded_packet(cycle);
        packet.position = position;
        packet.accelerometer = accelerometer;
        packet.gyroscope = gyroscope;
        packet.angles = angles;
        packet.fsr = fsr;
        packet.touch = touch;
        packet.status = status;
        packet.battery = Battery(battery);
        packet.robot_config = RobotConfig {
            body_id,
            body_version: "6.0.0".into(),
            head_id,
            head_version: "6.0.0".into(),
        };
        packet
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn arbitrary_bytes_never_panic_the_decoders(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
        let _ = SensorPacket::decode(&bytes);
        let _ = ActuatorPacket::decode(&bytes);
        let _ = strata_nao::value_len(&bytes);
        let mut framer = PacketFramer::new();
        framer.push(&bytes);
        let mut results = 0;
        while framer.next_packet().is_some() {
            results += 1;
            prop_assert!(results <= bytes.len(), "every result consumes bytes");
        }
        let _ = framer.flush_partial();
    }

    #[test]
    fn corrupted_packets_never_panic_and_never_hang(
        packet in fake_server_packet(),
        flips in proptest::collection::vec((0usize..SENSOR_PACKET_SIZE, any::<u8>()), 1..8),
        cut in 0usize..SENSOR_PACKET_SIZE,
    ) {
        let mut bytes = packet.encode().expect("encode");
        for (at, value) in flips {
            if let Some(byte) = bytes.get_mut(at) {
                *byte = value;
            }
        }
        let _ = SensorPacket::decode(&bytes);
        bytes.truncate(cut);
        let mut framer = PacketFramer::new();
        framer.push(&bytes);
        framer.push(&packet.encode().expect("encode"));
        let mut recovered = false;
        let mut steps = 0;
        while let Some(result) = framer.next_packet() {
            steps += 1;
            prop_assert!(steps < 4 * SENSOR_PACKET_SIZE);
            if result.as_ref() == Ok(&packet) {
                recovered = true;
            }
        }
        prop_assert!(recovered || framer.buffered() > 0, "the good packet after the bad one survives");
    }

    #[test]
    fn fake_server_packets_round_trip(packet in fake_server_packet()) {
        let bytes = packet.encode().expect("encode");
        prop_assert_eq!(bytes.len(), SENSOR_PACKET_SIZE, "20-character ids give LoLA's size");
        prop_assert_eq!(SensorPacket::decode(&bytes).expect("decode"), packet.clone());
        // Every prefix is a truncated packet, never something else.
        for cut in [0, 1, 13, 100, SENSOR_PACKET_SIZE / 2, SENSOR_PACKET_SIZE - 1] {
            let truncated = matches!(
                SensorPacket::decode(&bytes[..cut]),
                Err(CodecError::Truncated { received, .. }) if received == cut
            );
            prop_assert!(truncated);
        }
        // Finite values always convert to a frame.
        prop_assert!(sensor_frame(&packet, Time::ZERO).is_ok());
    }

    #[test]
    fn the_framer_reassembles_any_split_of_a_stream(
        packets in proptest::collection::vec(fake_server_packet(), 1..5),
        chunk in 1usize..1200,
    ) {
        let mut stream = Vec::new();
        for packet in &packets {
            stream.extend(packet.encode().expect("encode"));
        }
        let mut framer = PacketFramer::new();
        let mut out = Vec::new();
        for piece in stream.chunks(chunk) {
            framer.push(piece);
            while let Some(result) = framer.next_packet() {
                out.push(result.expect("a valid packet"));
            }
        }
        prop_assert_eq!(out, packets);
        prop_assert_eq!(framer.buffered(), 0);
    }

    #[test]
    fn actuator_packets_round_trip(
        position in floats::<JOINT_COUNT>(),
        stiffness in floats::<JOINT_COUNT>(),
        chest in proptest::array::uniform3(-1.0f32..2.0),
        sonar in any::<bool>(),
    ) {
        let leds = strata_nao::Leds {
            chest: strata_nao::Rgb::new(chest[0], chest[1], chest[2]),
            ..strata_nao::Leds::default()
        };
        let packet = ActuatorPacket::new(position, stiffness, &leds, sonar);
        prop_assert!(packet.stiffness.iter().all(|s| (0.0..=1.0).contains(s)));
        let bytes = packet.encode().expect("encode");
        prop_assert_eq!(strata_nao::value_len(&bytes).expect("msgpack"), Some(bytes.len()));
        prop_assert_eq!(ActuatorPacket::decode(&bytes).expect("decode"), packet);
    }
}
