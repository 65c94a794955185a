//! Robot processes on rcssservermj: `strata robot --platform rcssservermj --json` started
//! with the options a game or an experiment needs, its JSON lines read as they come (start,
//! game-state changes, status, the final report), stopped with SIGINT as a person stops it
//! with Ctrl-C, so it writes its report and closes its log.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result};

use super::cpu::process_cpu_seconds;

/// How to start one T1.
#[derive(Clone, Debug)]
pub struct T1Launch {
    /// The `strata` executable.
    pub exe: PathBuf,
    /// The server's agent port, `127.0.0.1:PORT`.
    pub server: String,
    /// Team number in the game-controller packets the robot makes from the server's referee.
    pub team: u8,
    /// The team's name in the server (robots of one team share it).
    pub team_name: String,
    pub player: u8,
    /// Where the server places the robot: metres in the team's frame, heading in degrees.
    pub beam: [f64; 3],
    /// A built-in team or a team TOML file (`--team-config`).
    pub team_config: String,
    pub seed: u64,
    /// Team messages over UDP on this port, broadcast on the loopback network; `None`: no
    /// team messages.
    pub team_port: Option<u16>,
    /// Record the robot's packages into this MCAP file.
    pub log: Option<PathBuf>,
    /// Seconds between status lines.
    pub status_interval: f64,
    /// Stop by itself after this many seconds.
    pub duration: Option<f64>,
    /// More options, passed as they are.
    pub extra: Vec<String>,
}

impl T1Launch {
    /// The command line, for reports and for people who want to run one robot by hand.
    pub fn command(&self) -> Command {
        let [x, y, degrees] = self.beam;
        let mut command = Command::new(&self.exe);
        command
            .args(["robot", "--platform", "rcssservermj", "--json"])
            .args(["--server", &self.server])
            .args(["--team", &self.team.to_string(), "--player", &self.player.to_string()])
            .args(["--team-name", &self.team_name])
            .arg(format!("--beam={x},{y},{degrees}"))
            .args(["--team-config", &self.team_config])
            .args(["--seed", &self.seed.to_string()])
            .args(["--status-interval", &self.status_interval.to_string()])
            // The robots of one machine share its two cores with the server: SCHED_FIFO
            // threads would starve the physics the robots wait for.
            .args(["--real-time-priority", "0"]);
        if let Some(port) = self.team_port {
            command.args(["--team-udp", "--broadcast", "127.255.255.255"]);
            command.args(["--team-port", &port.to_string()]);
        }
        if let Some(log) = &self.log {
            command.arg("--log").arg(log);
        }
        if let Some(duration) = self.duration {
            command.args(["--duration", &duration.to_string()]);
        }
        command.args(&self.extra);
        command
    }
}

/// A running robot process. Dropping it kills the process if it still runs: a failed game
/// must not leave robots behind.
#[derive(Debug)]
pub struct T1Process {
    pub team: u8,
    pub player: u8,
    child: Child,
    lines: Arc<Mutex<Vec<serde_json::Value>>>,
    stderr: Arc<Mutex<Vec<String>>>,
    readers: Vec<JoinHandle<()>>,
    /// The newest reading of the process's CPU time, s (kept once the process is gone).
    cpu_seconds: f64,
    status: Option<ExitStatus>,
}

impl T1Process {
    pub fn spawn(launch: &T1Launch) -> Result<T1Process> {
        let mut child = launch
            .command()
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .with_context(|| format!("starting `{} robot`", launch.exe.display()))?;
        let lines = Arc::new(Mutex::new(Vec::new()));
        let stderr = Arc::new(Mutex::new(Vec::new()));
        let mut readers = Vec::new();
        if let Some(out) = child.stdout.take() {
            let sink = Arc::clone(&lines);
            readers.push(read_lines(out, move |line| {
                // Lines that are not JSON (none are expected with --json) are not data.
                if let Ok(value) = serde_json::from_str::<serde_json::Value>(&line) {
                    sink.lock().unwrap_or_else(PoisonError::into_inner).push(value);
                }
            }));
        }
        if let Some(err) = child.stderr.take() {
            let sink = Arc::clone(&stderr);
            readers.push(read_lines(err, move |line| {
                sink.lock().unwrap_or_else(PoisonError::into_inner).push(line);
            }));
        }
        Ok(T1Process {
            team: launch.team,
            player: launch.player,
            child,
            lines,
            stderr,
            readers,
            cpu_seconds: 0.0,
            status: None,
        })
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Every JSON line of `kind` (`start`, `game`, `status`, `report`, `note`) so far.
    pub fn json_of(&self, kind: &str) -> Vec<serde_json::Value> {
        self.lines
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
            .filter(|v| v.get("type").and_then(|t| t.as_str()) == Some(kind))
            .cloned()
            .collect()
    }

    /// The newest line of `kind`.
    pub fn latest(&self, kind: &str) -> Option<serde_json::Value> {
        self.lines
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
            .rev()
            .find(|v| v.get("type").and_then(|t| t.as_str()) == Some(kind))
            .cloned()
    }

    /// The last lines the process wrote to stderr, for error messages.
    pub fn stderr_tail(&self, lines: usize) -> String {
        let stderr = self.stderr.lock().unwrap_or_else(PoisonError::into_inner);
        let start = stderr.len().saturating_sub(lines);
        stderr[start..].join(" | ")
    }

    /// Reads the process's CPU time while it runs; returns the newest reading.
    pub fn sample_cpu(&mut self) -> f64 {
        if self.status.is_none()
            && let Some(seconds) = process_cpu_seconds(self.child.id())
        {
            self.cpu_seconds = seconds;
        }
        self.cpu_seconds
    }

    /// Whether the process has ended (and how); once it has, every line it wrote is read.
    pub fn exited(&mut self) -> Option<ExitStatus> {
        if self.status.is_none() {
            self.sample_cpu();
            self.status = self.child.try_wait().ok().flatten();
            if self.status.is_some() {
                for reader in self.readers.drain(..) {
                    let _ = reader.join();
                }
            }
        }
        self.status
    }

    /// Asks the robot to stop, as Ctrl-C does: it finishes its log and prints its report.
    pub fn interrupt(&mut self) {
        if self.exited().is_none()
            && let Ok(pid) = i32::try_from(self.child.id())
        {
            let _ = nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(pid),
                nix::sys::signal::Signal::SIGINT,
            );
        }
    }

    /// Waits up to `patience` for the process to end, then kills it; returns its final report
    /// (`None` if it printed none) and how it ended.
    pub fn finish(
        &mut self,
        patience: Duration,
    ) -> (Option<serde_json::Value>, Option<ExitStatus>) {
        let deadline = Instant::now() + patience;
        while self.exited().is_none() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
        }
        if self.exited().is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
            for reader in self.readers.drain(..) {
                let _ = reader.join();
            }
        }
        (self.latest("report"), self.status)
    }
}

impl Drop for T1Process {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

fn read_lines(
    stream: impl Read + Send + 'static,
    mut sink: impl FnMut(String) + Send + 'static,
) -> JoinHandle<()> {
    std::thread::spawn(move || {
        for line in BufReader::new(stream).lines() {
            let Ok(line) = line else { break };
            sink(line);
        }
    })
}

/// `N` distinct UDP ports no process of this machine uses right now, one per team's messages:
/// robots bind them shared (SO_REUSEPORT), so the short gap before they bind cannot make them
/// fail, and two games on one machine do not hear each other. Every socket is held until all
/// are chosen, or the system could hand out one port twice.
pub fn free_udp_ports<const N: usize>() -> Result<[u16; N]> {
    let mut sockets = Vec::with_capacity(N);
    let mut ports = [0u16; N];
    for port in &mut ports {
        let socket =
            std::net::UdpSocket::bind(("127.0.0.1", 0)).context("finding a free UDP port")?;
        *port = socket.local_addr().context("finding a free UDP port")?.port();
        sockets.push(socket);
    }
    Ok(ports)
}

/// The `strata` executable for robot processes: `exe` if given, else this process's own
/// executable when it is `strata`.
pub fn strata_exe(exe: Option<&Path>) -> Result<PathBuf> {
    match exe {
        Some(exe) => Ok(exe.to_owned()),
        None => std::env::current_exe().context("finding the strata executable for the robots"),
    }
}
