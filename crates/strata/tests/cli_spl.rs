//! `strata spl listen` on the GameController's return port: every datagram gets GameController3's
//! verdict, whatever its first bytes, since GameController3 judges everything arriving there.

mod common;

use std::net::{Ipv4Addr, UdpSocket};

use common::Process;
use common::cli::strata;

#[test]
fn every_datagram_on_the_return_port_gets_game_controller3s_verdict() {
    // Killed when dropped; the count only bounds a run that goes wrong. Robots elsewhere on
    // this machine may send their return packets here too: only ours are judged below.
    let mut listener = Process::spawn(
        "strata spl listen",
        &mut strata(&["spl", "listen", "--port", "3939", "--bind", "127.0.0.1", "--count", "1000"]),
    );
    listener.wait_for("the listener to bind", |p| p.stderr().contains("listening").then_some(()));
    let socket = UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).expect("binds");
    let from = socket.local_addr().expect("an address").to_string();
    // A return packet's length with the header in the wrong case, and a datagram too short.
    let mut wrong_header = b"rgrt".to_vec();
    wrong_header.extend([4, 3, 12, 0]);
    wrong_header.resize(32, 0);
    let datagrams: [&[u8]; 2] = [&wrong_header, b"hello"];
    let mut sent = 0;
    // Sent again until the listener has shown both: another process sharing the port (robots
    // bind it shared) may be handed some of them.
    let lines = listener.wait_for("both datagrams", |p| {
        let _ = socket.send_to(datagrams[sent % 2], ("127.0.0.1", 3939));
        sent += 1;
        let ours: Vec<_> = p.json_lines().into_iter().filter(|l| l["from"] == from).collect();
        let lengths = |n: u64| ours.iter().any(|l| l["length"] == n);
        (lengths(32) && lengths(5)).then_some(ours)
    });
    for line in lines {
        let expected = match line["length"].as_u64() {
            Some(32) => "drops it: wrong header",
            _ => "drops it: wrong length",
        };
        assert_eq!(line["kind"], "return", "{line}");
        assert_eq!(line["game_controller3"], expected, "{line}");
    }
}
