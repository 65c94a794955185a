//! What connections that never say `hello` cost the simulator server: one thread each, no
//! writer, and no more than `max_connections` of them. Alone in its test binary, so that the
//! threads counted are this server's only.

#![cfg(target_os = "linux")]

use std::net::TcpStream;
use std::time::{Duration, Instant};

use strata_sim::net::{Server, ServerLimits, ServerOptions};
use strata_sim::{SimConfig, SimHandle, Simulation};

const PATIENCE: Duration = Duration::from_secs(20);

/// How many of this process's threads have a name starting with `prefix`.
fn threads_named(prefix: &str) -> usize {
    std::fs::read_dir("/proc/self/task")
        .expect("a Linux /proc")
        .filter_map(|task| std::fs::read_to_string(task.ok()?.path().join("comm")).ok())
        .filter(|name| name.starts_with(prefix))
        .count()
}

#[test]
fn idle_connections_cost_one_thread_each_and_no_more_than_the_cap() {
    const CAP: usize = 24;
    let limits = ServerLimits {
        max_connections: CAP,
        handshake_deadline: Duration::from_secs(120),
        ..ServerLimits::default()
    };
    let sim = SimHandle::new(Simulation::new(SimConfig::default()).expect("valid config"));
    let options = ServerOptions { limits, ..ServerOptions::default() };
    let server = Server::bind("127.0.0.1:0", sim, options).expect("binds").spawn().expect("runs");
    let addr = server.local_addr();
    let idle: Vec<TcpStream> =
        (0..CAP + 10).map(|_| TcpStream::connect(addr).expect("connects")).collect();
    let deadline = Instant::now() + PATIENCE;
    while server.counters().connections < CAP || server.counters().refused < 10 {
        assert!(Instant::now() < deadline, "gave up waiting: {:?}", server.counters());
        std::thread::sleep(Duration::from_millis(5));
    }
    assert_eq!(server.counters().connections, CAP);
    assert_eq!(threads_named("sim-conn-"), CAP, "one thread per connection, at most the cap");
    assert_eq!(threads_named("sim-write-"), 0, "no writer before hello");
    drop(idle);
    server.stop().expect("stops cleanly");
}
