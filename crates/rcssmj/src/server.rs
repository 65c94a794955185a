//! Starting rcssservermj from the project's environment: headless, in sync mode, on free ports,
//! ended when the handle is dropped. Tests, benchmarks and commands that need a server of their
//! own use this; `scripts/setup-rcssservermj` installs the server.

use std::io;
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex, PoisonError, mpsc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::protocol::monitor::{MonitorClient, MonitorCommand, MonitorState};

/// The project-local virtual environment `scripts/setup-rcssservermj` creates.
pub const VENV_DIR: &str = ".venv-rcssservermj";

/// Why a server could not be started.
#[derive(Debug, thiserror::Error)]
pub enum ServerError {
    #[error(
        "rcssservermj is not installed: run scripts/setup-rcssservermj (it creates {VENV_DIR}/ \
         at the repository root), or set STRATA_RCSSSERVERMJ to the server's executable"
    )]
    NotInstalled,
    #[error("cannot start {}: {source}", program.display())]
    Spawn { program: PathBuf, source: io::Error },
    #[error("no free port on 127.0.0.1: {0}")]
    Port(io::Error),
    #[error("rcssservermj did not accept connections on port {port} within {waited:?}{}", status.as_ref().map(|s| format!(" (it exited: {s})")).unwrap_or_default())]
    NotListening { port: u16, waited: Duration, status: Option<String> },
}

/// How to run the server.
#[derive(Clone, Debug, PartialEq)]
pub struct ServerOptions {
    /// Wait for every agent each cycle (deterministic stepping; the agents pace it).
    pub sync: bool,
    /// Run in real time (only without `sync`).
    pub realtime: bool,
    /// Extra arguments (`--field fifa7vs7`, `--rules ...`).
    pub extra: Vec<String>,
    /// How long to wait for the server to listen.
    pub start_timeout: Duration,
}

impl Default for ServerOptions {
    fn default() -> Self {
        ServerOptions {
            sync: true,
            realtime: false,
            extra: Vec::new(),
            start_timeout: Duration::from_secs(60),
        }
    }
}

/// A running server; dropping it ends the process.
#[derive(Debug)]
pub struct ServerProcess {
    child: Child,
    agent_port: u16,
    monitor_port: u16,
    program: PathBuf,
    workdir: PathBuf,
    monitor: Option<MonitorLink>,
}

/// The server's monitor stream, read without pause on a thread of its own: rcsssmj 0.2.1 sends
/// to monitors from its simulation thread, so an unread monitor stalls the simulation, and a
/// monitor that disconnects while a message is on its way crashes it. One monitor connection
/// for the server's whole life avoids both, and carries the trainer's commands too.
#[derive(Debug)]
struct MonitorLink {
    state: Arc<Mutex<MonitorState>>,
    commands: mpsc::Sender<Vec<MonitorCommand>>,
    thread: JoinHandle<()>,
}

impl ServerProcess {
    /// Starts the server found by [`find_server`] on two free ports and waits until it listens.
    pub fn start(options: &ServerOptions) -> Result<ServerProcess, ServerError> {
        let program = find_server().ok_or(ServerError::NotInstalled)?;
        let (agent_port, monitor_port) = free_ports()?;
        // The server writes console.log and MUJOCO_LOG.TXT into its working directory.
        let workdir = std::env::temp_dir()
            .join(format!("strata-rcssservermj-{}-{agent_port}", std::process::id()));
        std::fs::create_dir_all(&workdir)
            .map_err(|source| ServerError::Spawn { program: workdir.clone(), source })?;
        let mut command = Command::new(&program);
        command
            .current_dir(&workdir)
            .arg("--no-render")
            .args(["--aport", &agent_port.to_string(), "--mport", &monitor_port.to_string()])
            .args(&options.extra)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null());
        if options.sync {
            command.arg("--sync");
        }
        command.arg(if options.realtime { "--realtime" } else { "--no-realtime" });
        let child = command
            .spawn()
            .map_err(|source| ServerError::Spawn { program: program.clone(), source })?;
        let mut server =
            ServerProcess { child, agent_port, monitor_port, program, workdir, monitor: None };
        server.connect_monitor(options.start_timeout)?;
        Ok(server)
    }

    /// Connects the monitor once the server listens, and waits for its first message: the
    /// simulation has stepped (an agent that joins before the first step is never activated;
    /// rcsssmj 0.2.1 drops it).
    fn connect_monitor(&mut self, timeout: Duration) -> Result<(), ServerError> {
        let start = Instant::now();
        let not_listening = |server: &mut ServerProcess| ServerError::NotListening {
            port: server.monitor_port,
            waited: start.elapsed(),
            status: server.child.try_wait().ok().flatten().map(|s| s.to_string()),
        };
        let address = self.monitor_address();
        let mut client = loop {
            match MonitorClient::connect(address.as_str(), Duration::from_secs(1)) {
                Ok(client) => break client,
                Err(_)
                    if start.elapsed() < timeout
                        && self.child.try_wait().ok().flatten().is_none() =>
                {
                    std::thread::sleep(Duration::from_millis(100));
                }
                Err(_) => return Err(not_listening(self)),
            }
        };
        if client.set_read_timeout(Some(timeout)).is_err() || client.next_state().is_err() {
            return Err(not_listening(self));
        }
        // From now on reads block until the server ends (its messages come every 40 ms).
        let _ = client.set_read_timeout(None);
        let state = Arc::new(Mutex::new(client.state().clone()));
        let (commands, orders) = mpsc::channel::<Vec<MonitorCommand>>();
        let shared = Arc::clone(&state);
        let thread = std::thread::Builder::new()
            .name("rcssservermj-monitor".to_owned())
            .spawn(move || {
                while let Ok(latest) = client.next_state() {
                    *shared.lock().unwrap_or_else(PoisonError::into_inner) = latest.clone();
                    while let Ok(batch) = orders.try_recv() {
                        if let Err(error) = client.send(&batch) {
                            tracing::warn!(%error, "a trainer command to rcssservermj failed");
                        }
                    }
                }
            })
            .map_err(|source| ServerError::Spawn { program: self.program.clone(), source })?;
        self.monitor = Some(MonitorLink { state, commands, thread });
        Ok(())
    }

    /// The world as the monitor stream last described it: ground truth of the ball and every
    /// robot, for tests and reports (never for a robot).
    pub fn truth(&self) -> MonitorState {
        self.monitor
            .as_ref()
            .map(|m| m.state.lock().unwrap_or_else(PoisonError::into_inner).clone())
            .unwrap_or_default()
    }

    /// Sends trainer commands (place the ball, move a robot, kick off); the server applies
    /// them after the next monitor message.
    pub fn command(&self, commands: Vec<MonitorCommand>) {
        if let Some(monitor) = &self.monitor {
            // A closed channel means the server is gone: nothing to command.
            let _ = monitor.commands.send(commands);
        }
    }

    /// Where agents connect: `127.0.0.1:PORT`.
    pub fn agent_address(&self) -> String {
        format!("127.0.0.1:{}", self.agent_port)
    }

    /// Where monitors and trainers connect.
    pub fn monitor_address(&self) -> String {
        format!("127.0.0.1:{}", self.monitor_port)
    }

    /// The server's process id (to read its CPU time).
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    pub fn program(&self) -> &Path {
        &self.program
    }

    /// Ends the server now (a test of a server that dies mid-game).
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for ServerProcess {
    fn drop(&mut self) {
        self.kill();
        // The server is gone, so the monitor thread's read ends.
        if let Some(monitor) = self.monitor.take() {
            let _ = monitor.thread.join();
        }
        let _ = std::fs::remove_dir_all(&self.workdir);
    }
}

/// The server's executable: `STRATA_RCSSSERVERMJ` if set, else `.venv-rcssservermj/bin/
/// rcssservermj` in the current directory or one of its ancestors, else in the workspace this
/// crate was built from.
pub fn find_server() -> Option<PathBuf> {
    if let Some(path) = std::env::var_os("STRATA_RCSSSERVERMJ") {
        return Some(PathBuf::from(path));
    }
    let in_venv = |dir: &Path| {
        let candidate = dir.join(VENV_DIR).join("bin").join("rcssservermj");
        candidate.is_file().then_some(candidate)
    };
    if let Ok(cwd) = std::env::current_dir()
        && let Some(found) = cwd.ancestors().find_map(in_venv)
    {
        return Some(found);
    }
    Path::new(env!("CARGO_MANIFEST_DIR")).ancestors().find_map(in_venv)
}

/// Two distinct free ports. Both listeners are held until both are chosen, or the system could
/// hand out the same port twice. The ports are free when the listeners close and the server
/// binds them a moment later; should another process take one in between, the start fails with
/// a clear error rather than a wrong server.
fn free_ports() -> Result<(u16, u16), ServerError> {
    let first = TcpListener::bind(("127.0.0.1", 0)).map_err(ServerError::Port)?;
    let second = TcpListener::bind(("127.0.0.1", 0)).map_err(ServerError::Port)?;
    let port = |l: &TcpListener| l.local_addr().map(|a| a.port()).map_err(ServerError::Port);
    Ok((port(&first)?, port(&second)?))
}
