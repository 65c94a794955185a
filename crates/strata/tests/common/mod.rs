//! Running `strata` processes from tests: start them, read their output as it comes, stop them
//! with Ctrl-C (SIGINT) as a person would, and never leave one behind when a test fails.
//!
//! Every wait polls with a generous deadline that only bounds a failing test: nothing here
//! asserts how long anything took.

#![allow(dead_code)] // each test file uses a different part

pub mod cli;

use std::io::{BufRead, BufReader};
use std::net::{Ipv4Addr, UdpSocket};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long a test waits for anything before giving up (a loaded machine with two cores runs
/// several robots of six threads each: be patient).
pub const PATIENCE: Duration = Duration::from_secs(120);

pub fn strata() -> Command {
    Command::new(env!("CARGO_BIN_EXE_strata"))
}

/// A port nobody on this machine uses right now: the OS picks it. Robots bind their ports
/// shared (SO_REUSEPORT), so the short gap before they bind it cannot make them fail.
pub fn free_udp_port() -> u16 {
    UdpSocket::bind((Ipv4Addr::LOCALHOST, 0))
        .and_then(|s| s.local_addr())
        .map(|a| a.port())
        .expect("the OS gives a free UDP port")
}

/// Polls `f` until it gives something.
pub fn until<T>(what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + PATIENCE;
    loop {
        if let Some(value) = f() {
            return value;
        }
        assert!(Instant::now() < deadline, "gave up waiting for {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A child process whose output lines are collected as they come; killed if still running
/// when dropped (a failed assertion must not leave processes behind).
pub struct Process {
    pub name: String,
    child: Child,
    lines: Arc<Mutex<Vec<String>>>,
    errors: Arc<Mutex<Vec<String>>>,
    readers: Vec<JoinHandle<()>>,
}

impl Process {
    pub fn spawn(name: &str, command: &mut Command) -> Process {
        let mut child = command
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {name}: {e}"));
        let lines = Arc::new(Mutex::new(Vec::new()));
        let errors = Arc::new(Mutex::new(Vec::new()));
        let mut readers = Vec::new();
        for (stream, sink) in [
            (child.stdout.take().map(|s| Box::new(s) as Box<dyn std::io::Read + Send>), &lines),
            (child.stderr.take().map(|s| Box::new(s) as Box<dyn std::io::Read + Send>), &errors),
        ] {
            let Some(stream) = stream else { continue };
            let sink = Arc::clone(sink);
            readers.push(std::thread::spawn(move || {
                for line in BufReader::new(stream).lines() {
                    let Ok(line) = line else { break };
                    sink.lock().unwrap_or_else(PoisonError::into_inner).push(line);
                }
            }));
        }
        Process { name: name.to_owned(), child, lines, errors, readers }
    }

    /// Every stdout line so far.
    pub fn lines(&self) -> Vec<String> {
        self.lines.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }

    pub fn stderr(&self) -> String {
        self.errors.lock().unwrap_or_else(PoisonError::into_inner).join("\n")
    }

    /// Every stdout line that is a JSON object, parsed.
    pub fn json_lines(&self) -> Vec<serde_json::Value> {
        self.lines().iter().filter_map(|l| serde_json::from_str(l).ok()).collect()
    }

    /// The JSON lines of one `type`.
    pub fn json_of(&self, kind: &str) -> Vec<serde_json::Value> {
        self.json_lines().into_iter().filter(|v| v["type"] == kind).collect()
    }

    /// Whether the process has exited; once it has, every line it wrote has been read.
    fn exited(&mut self) -> Option<ExitStatus> {
        let status = self.child.try_wait().ok().flatten()?;
        // The pipes close with the process: the readers end after its last line.
        for reader in self.readers.drain(..) {
            let _ = reader.join();
        }
        Some(status)
    }

    fn output(&self) -> String {
        format!("stdout:\n{}\nstderr:\n{}", self.lines().join("\n"), self.stderr())
    }

    /// Waits for output `f` accepts; fails if the process exits without writing it.
    pub fn wait_for<T>(&mut self, what: &str, mut f: impl FnMut(&Process) -> Option<T>) -> T {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let exited = self.exited();
            if let Some(value) = f(self) {
                return value;
            }
            if let Some(status) = exited {
                panic!("{} exited ({status}) before {what}\n{}", self.name, self.output());
            }
            assert!(
                Instant::now() < deadline,
                "gave up waiting for {what} from {}\n{}",
                self.name,
                self.output()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Waits for the process to end on its own.
    pub fn wait_exit(&mut self) -> ExitStatus {
        let deadline = Instant::now() + PATIENCE;
        loop {
            if let Some(status) = self.exited() {
                return status;
            }
            assert!(Instant::now() < deadline, "{} did not stop\n{}", self.name, self.output());
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Ctrl-C, then waits for the process to end on its own.
    pub fn interrupt(&mut self) -> ExitStatus {
        let status = Command::new("kill")
            .args(["-INT", &self.child.id().to_string()])
            .status()
            .expect("kill runs");
        assert!(status.success(), "cannot interrupt {}", self.name);
        self.wait_exit()
    }
}

impl Drop for Process {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// Starts `strata server` on a free port and returns it with its address.
pub fn start_server(extra: &[&str]) -> (Process, String) {
    let mut server = Process::spawn(
        "strata server",
        strata().args(["server", "--addr", "127.0.0.1:0", "--status-interval", "1"]).args(extra),
    );
    let addr = server.wait_for("the listening address", |p| {
        p.lines().iter().find_map(|l| {
            let rest = l.strip_prefix("strata server listening on ")?;
            Some(rest.split(':').take(2).collect::<Vec<_>>().join(":"))
        })
    });
    (server, addr)
}
