//! Any bytes: the team-message decoder returns an error or a message, never panics, and a
//! message it accepts re-encodes within the SPL limit and decodes to the same message.
//!
//! Why the comparison waits for the second round: the wire quantizes (1 mm, 1e-4 rad, ...) and
//! every quantized field decodes to a value that encodes back to the same integer, except the
//! heading. The decoder accepts headings slightly beyond ±pi (|theta| <= pi + 1e-3, tolerance
//! for other encoders) and `Pose::new` wraps them into (-pi, pi], which moves them off the 1e-4
//! grid: wire 31420 decodes to 3.1420 - 2 pi = -3.14118..., which encodes as -31412. So
//! `decode(encode(m1))` may differ from `m1` in `pose.theta` (by less than half a quantum, modulo
//! 2 pi), and from then on the message is a fixed point. The target checks both: after one round
//! only the heading may have moved, and only that little; after two rounds nothing changes.
#![no_main]

use std::f64::consts::{PI, TAU};

use libfuzzer_sys::fuzz_target;
use strata_soccer::message::{decode, encode};
use strata_spl::MAX_TEAM_MESSAGE_SIZE;

fn reencode(message: &strata_soccer::message::SoccerMessage) -> Vec<u8> {
    let bytes = encode(message).expect("a decoded message encodes");
    assert!(
        bytes.len() <= MAX_TEAM_MESSAGE_SIZE,
        "re-encoded to {} bytes, the limit is {MAX_TEAM_MESSAGE_SIZE}",
        bytes.len()
    );
    bytes
}

fuzz_target!(|bytes: &[u8]| {
    let Ok(first) = decode(bytes) else { return };
    let second = decode(&reencode(&first)).expect("a re-encoded message decodes");

    // One round: everything but the heading is exact; the heading moves by at most half a
    // quantum (1e-4 rad), modulo a full turn.
    let mut same_heading = second.clone();
    same_heading.pose.theta = first.pose.theta;
    assert_eq!(same_heading, first, "one round changed more than the heading");
    let moved = (second.pose.theta - first.pose.theta).rem_euclid(TAU);
    let moved = moved.min(TAU - moved);
    assert!(moved <= 0.5e-4 + 1e-9, "heading moved by {moved} rad");
    assert!(second.pose.theta > -PI && second.pose.theta <= PI);

    // Two rounds: a fixed point, in the message and in the bytes.
    let bytes2 = reencode(&second);
    let third = decode(&bytes2).expect("a re-encoded message decodes");
    assert_eq!(third, second, "the second round is not a fixed point");
    assert_eq!(reencode(&third), bytes2);
});
