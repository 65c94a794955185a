//! The game the faults are injected into: the simulator server in this process (real time),
//! a GameController over UDP, and every robot a `strata robot --net` process whose status
//! lines are read as they come.

use std::collections::BTreeMap;
use std::net::{IpAddr, Ipv4Addr, SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, bail};
use serde::Serialize;
use strata_sim::net::{RunningServer, Server, ServerOptions};
use strata_sim::{GameState, RobotId, SimConfig, SimHandle, Simulation};
use strata_spl::gamecontroller::GameControlData;
use strata_spl::net::LOOPBACK_BROADCAST;

use crate::rates::BallKeeper;
use strata_games::children::Child;

use super::Options;
use super::measure::{self, CpuReading};

/// The teams, as the simulator's default configuration numbers them.
pub(super) const TEAMS: [u8; 2] = [10, 20];
/// Each team's robots: a goalkeeper and two field players, the smallest team in which a field
/// player's role has someone to pass to when its holder dies.
pub(super) const PLAYERS: [u8; 3] = [1, 2, 3];
/// The slot the slow client takes: the world has one player more per team than robots.
pub(super) const SPARE_PLAYER: u8 = 4;
/// Seconds between a robot's status lines: the resolution of the takeover time.
const STATUS_INTERVAL: f64 = 0.5;
/// How often the GameController sends its control packet (a real one sends two a second).
const GC_PERIOD: Duration = Duration::from_millis(500);
/// How often the server's real-time factor is sampled.
const SAMPLE_PERIOD: Duration = Duration::from_millis(200);

/// A robot of the game: `10/2` is team 10's player 2.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
pub struct RobotKey {
    pub team: u8,
    pub player: u8,
}

impl std::fmt::Display for RobotKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.team, self.player)
    }
}

/// One status line of a robot, stamped with when it was read.
#[derive(Clone, Debug)]
pub(super) struct Sample {
    pub at: Instant,
    /// Which process of the robot wrote it (0, then 1 after a restart).
    pub instance: usize,
    /// The robot's own seconds since it started.
    pub t: f64,
    pub game_state: Option<String>,
    pub role: Option<String>,
    pub available: Vec<u8>,
    pub reactive_cycles: Option<u64>,
    pub sensor_frames: u64,
}

/// A robot and the processes that played it.
#[derive(Debug)]
pub(super) struct Robot {
    pub key: RobotKey,
    pub gc_port: u16,
    pub log: Option<PathBuf>,
    /// Started with SIGXFSZ ignored: past a file-size limit its log's writes fail (as on a full
    /// disk) instead of the kernel killing it.
    pub file_limit: bool,
    pub process: Child,
    /// Processes of this robot that were ended on purpose (kill -9), kept for their output.
    pub ended: Vec<Child>,
    pub instance: usize,
    /// Stdout lines of the current process read so far.
    read: usize,
    pub samples: Vec<Sample>,
    /// The robot's notes (`{"type": "note"}`), e.g. its log failing.
    pub notes: Vec<(Instant, usize, String)>,
    /// The final report of each process that wrote one, by instance.
    pub reports: Vec<(usize, serde_json::Value)>,
}

impl Robot {
    pub fn last(&self) -> Option<&Sample> {
        self.samples.last()
    }

    /// Every process of the robot, the ended ones first.
    pub fn processes(&self) -> impl Iterator<Item = &Child> {
        self.ended.iter().chain(std::iter::once(&self.process))
    }

    /// Reads the lines the current process wrote since the last call.
    fn poll(&mut self) {
        let lines = self.process.lines_from(self.read);
        self.read += lines.len();
        for line in lines {
            let Ok(value) = serde_json::from_str::<serde_json::Value>(&line.text) else {
                continue;
            };
            match value.get("type").and_then(|t| t.as_str()) {
                Some("status") => self.samples.push(sample(&value, line.at, self.instance)),
                Some("note") => {
                    let text = value.get("text").and_then(|t| t.as_str()).unwrap_or_default();
                    self.notes.push((line.at, self.instance, text.to_owned()));
                }
                Some("report") => self.reports.push((self.instance, value)),
                _ => {}
            }
        }
    }
}

fn sample(value: &serde_json::Value, at: Instant, instance: usize) -> Sample {
    let text = |key: &str| value.get(key).and_then(|v| v.as_str()).map(str::to_owned);
    let reactive_cycles = value.get("layers").and_then(|l| l.as_array()).and_then(|layers| {
        layers
            .iter()
            .find(|l| l.get("layer").and_then(|n| n.as_str()) == Some("reactive"))
            .and_then(|l| l.get("cycles"))
            .and_then(|c| c.as_u64())
    });
    Sample {
        at,
        instance,
        t: value.get("t").and_then(|t| t.as_f64()).unwrap_or_default(),
        game_state: text("game_state"),
        role: text("role"),
        available: value
            .get("available_teammates")
            .and_then(|a| a.as_array())
            .map(|a| {
                a.iter().filter_map(|p| p.as_u64()).filter_map(|p| u8::try_from(p).ok()).collect()
            })
            .unwrap_or_default(),
        reactive_cycles,
        sensor_frames: value.get("sensor_frames").and_then(|f| f.as_u64()).unwrap_or_default(),
    }
}

/// The GameController's side of the game: control packets to every robot's port. The robots'
/// return packets come back to its socket; nothing here needs them (the kernel drops what
/// nobody reads).
struct GameController {
    data: Arc<Mutex<GameControlData>>,
    sending: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    return_port: u16,
}

impl GameController {
    fn start(ports: Vec<u16>, players_per_team: u8) -> Result<GameController> {
        let mut data = GameControlData {
            state: GameState::Initial,
            players_per_team,
            first_half: true,
            kicking_team: Some(TEAMS[0]),
            secs_remaining: 600,
            ..GameControlData::default()
        };
        for (info, number) in data.teams.iter_mut().zip(TEAMS) {
            info.team_number = number;
            info.message_budget = 1200;
        }
        // The robots learn where to send their return packets from where control packets
        // come from: one socket does both.
        let socket = UdpSocket::bind((Ipv4Addr::UNSPECIFIED, 0))
            .context("binding the GameController's socket")?;
        socket.set_nonblocking(true).context("the GameController's socket")?;
        let return_port = socket.local_addr().context("the GameController's socket")?.port();
        let data = Arc::new(Mutex::new(data));
        let sending = Arc::new(AtomicBool::new(true));
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let data = Arc::clone(&data);
            let (sending, stop) = (Arc::clone(&sending), Arc::clone(&stop));
            std::thread::Builder::new()
                .name("chaos-gc".to_owned())
                .spawn(move || {
                    let mut next = Instant::now();
                    while !stop.load(Ordering::Relaxed) {
                        if Instant::now() >= next && sending.load(Ordering::Relaxed) {
                            next += GC_PERIOD;
                            let bytes = {
                                let mut data = lock(&data);
                                data.packet_number = data.packet_number.wrapping_add(1);
                                data.encode()
                            };
                            for &port in &ports {
                                let to = SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), port);
                                // A lost packet is one of many: the next comes in half a second.
                                let _ = socket.send_to(&bytes, to);
                            }
                        }
                        std::thread::sleep(Duration::from_millis(10));
                    }
                })
                .context("starting the GameController thread")?
        };
        Ok(GameController { data, sending, stop, thread: Some(thread), return_port })
    }

    fn set_state(&self, state: GameState) {
        lock(&self.data).state = state;
    }
}

impl Drop for GameController {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// Samples the simulated time against the wall clock, and keeps the ball in play.
struct Keeper {
    samples: Arc<Mutex<Vec<(Instant, f64)>>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Keeper {
    fn start(sim: SimHandle, seed: u64) -> Result<Keeper> {
        let samples = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (samples, stop) = (Arc::clone(&samples), Arc::clone(&stop));
            std::thread::Builder::new()
                .name("chaos-keeper".to_owned())
                .spawn(move || {
                    // The ball goes back into play when it leaves the field (nothing else puts
                    // it back: the referee is manual) and every 20 s, so the robots keep
                    // walking and kicking.
                    let mut ball = BallKeeper::new(seed, 20.0);
                    let mut next = Instant::now();
                    while !stop.load(Ordering::Relaxed) {
                        let time = sim.lock().time().as_secs_f64();
                        lock(&samples).push((Instant::now(), time));
                        let _ = ball.tend(&sim);
                        next += SAMPLE_PERIOD;
                        std::thread::sleep(next.saturating_duration_since(Instant::now()));
                    }
                })
                .context("starting the sampling thread")?
        };
        Ok(Keeper { samples, stop, thread: Some(thread) })
    }
}

impl Drop for Keeper {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// The running game.
pub(super) struct Game {
    exe: PathBuf,
    pub started: Instant,
    server: Option<RunningServer>,
    pub sim: SimHandle,
    pub addr: SocketAddr,
    pub team_ports: [u16; 2],
    attack_signs: [f64; 2],
    gc: GameController,
    keeper: Keeper,
    pub robots: Vec<Robot>,
    /// CPU time of every process, read about once a second.
    pub cpu: Vec<CpuReading>,
    interrupted: Arc<AtomicBool>,
    seed: u64,
    real_time_priority: u8,
}

impl std::fmt::Debug for Game {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Game").field("addr", &self.addr).finish_non_exhaustive()
    }
}

/// Ended by Ctrl-C or SIGTERM: every process is killed on the way out.
#[derive(Debug)]
pub struct Interrupted;

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("interrupted (Ctrl-C or SIGTERM): every robot process was killed")
    }
}

impl std::error::Error for Interrupted {}

impl Game {
    /// Starts the server, the GameController and every robot, and waits until each robot
    /// plays and hears its teammates.
    pub fn start(options: &Options, interrupted: Arc<AtomicBool>) -> Result<Game> {
        let mut config = SimConfig { seed: options.seed, ..SimConfig::default() };
        // The game state is this command's to set: no kick-off, no half time, no robot moved
        // by a referee in the middle of a measurement.
        config.referee.auto = false;
        config.referee.players_per_team = SPARE_PLAYER;
        config.validate("chaos run").context("simulator configuration")?;
        let simulation = Simulation::new(config).context("building the simulated world")?;
        let numbers = [simulation.team_number(0), simulation.team_number(1)];
        if numbers != TEAMS {
            bail!("the simulator's teams are {numbers:?}, not {TEAMS:?}");
        }
        let attack_signs = simulation.game().attack_sign;
        let sim = SimHandle::new(simulation);
        let server = Server::bind("127.0.0.1:0", sim.clone(), ServerOptions::default())
            .context("starting the simulator server")?
            .spawn()
            .context("starting the simulator server")?;
        let addr = server.local_addr();

        // Ports nobody uses, so that another game on this machine (an experiment, a second
        // chaos run) neither hears these robots nor floods them.
        let team_ports = [free_udp_port()?, free_udp_port()?];
        let mut gc_ports = BTreeMap::new();
        for team in TEAMS {
            for player in PLAYERS {
                gc_ports.insert(RobotKey { team, player }, free_udp_port()?);
            }
        }
        // Three players a team: the spare slot is the slow client's, not a player's, and the
        // robots share the team's message budget by this number.
        let gc = GameController::start(gc_ports.values().copied().collect(), PLAYERS.len() as u8)?;
        let keeper = Keeper::start(sim.clone(), options.seed)?;
        let logs = options.out_dir.join("logs");
        std::fs::create_dir_all(&logs).with_context(|| format!("creating {}", logs.display()))?;
        let mut game = Game {
            exe: options.strata_exe.clone(),
            started: Instant::now(),
            server: Some(server),
            sim,
            addr,
            team_ports,
            attack_signs,
            gc,
            keeper,
            robots: Vec::new(),
            cpu: Vec::new(),
            interrupted,
            seed: options.seed,
            real_time_priority: options.real_time_priority,
        };
        for (key, gc_port) in gc_ports {
            // Team 10's goalkeeper logs as a robot does (the records lost are counted); team
            // 20's logs into the file that fills up.
            let (log, file_limit) = match (key.team, key.player) {
                (10, 1) => (Some(logs.join("t10-1.mcap")), false),
                (20, 1) => (Some(logs.join("t20-1-full.mcap")), true),
                _ => (None, false),
            };
            let process = game.spawn(key, gc_port, log.as_deref(), file_limit, 0)?;
            game.robots.push(Robot {
                key,
                gc_port,
                log,
                file_limit,
                process,
                ended: Vec::new(),
                instance: 0,
                read: 0,
                samples: Vec::new(),
                notes: Vec::new(),
                reports: Vec::new(),
            });
        }
        let keys: Vec<RobotKey> = game.robots.iter().map(|r| r.key).collect();
        let joined =
            game.wait_until(Duration::from_secs(90), |g| keys.iter().all(|k| g.present(*k)))?;
        if !joined {
            bail!("not every robot joined the server within 90 s{}", game.stderr_tails());
        }
        // Everyone stands at its kick-off place (the world put it there in Initial): play.
        game.sim.lock().set_game_state(GameState::Playing);
        game.gc.set_state(GameState::Playing);
        let playing = game.wait_until(Duration::from_secs(90), |g| {
            g.robots.iter().all(|r| {
                r.last().is_some_and(|s| {
                    s.game_state.as_deref() == Some("Playing")
                        && s.available.len() == PLAYERS.len() - 1
                })
            })
        })?;
        if !playing {
            bail!(
                "not every robot was playing with both teammates within 90 s{}",
                game.stderr_tails()
            );
        }
        Ok(game)
    }

    /// Starts one process of a robot.
    pub fn spawn(
        &self,
        key: RobotKey,
        gc_port: u16,
        log: Option<&Path>,
        file_limit: bool,
        instance: usize,
    ) -> Result<Child> {
        let team_index = usize::from(key.team != TEAMS[0]);
        let mut args: Vec<String> = [
            "robot",
            "--platform",
            "sim",
            "--server",
            &self.addr.to_string(),
            "--team",
            &key.team.to_string(),
            "--player",
            &key.player.to_string(),
            "--net",
            "--broadcast",
            &LOOPBACK_BROADCAST.to_string(),
            "--gc-port",
            &gc_port.to_string(),
            "--gc-return-port",
            &self.gc.return_port.to_string(),
            "--team-port",
            &self.team_ports[team_index].to_string(),
            "--attack-sign",
            if self.attack_signs[team_index] > 0.0 { "1" } else { "-1" },
            "--gc-wait",
            "0",
            "--json",
            "--status-interval",
            &STATUS_INTERVAL.to_string(),
            "--seed",
            &(self.seed * 1000 + 10 * u64::from(key.team) + u64::from(key.player)).to_string(),
            "--real-time-priority",
            &self.real_time_priority.to_string(),
        ]
        .map(str::to_owned)
        .into();
        if let Some(log) = log {
            args.push("--log".to_owned());
            args.push(log.display().to_string());
        }
        let name = format!(
            "robot {key}{}",
            if instance > 0 { format!(" (restart {instance})") } else { String::new() }
        );
        let mut command = if file_limit {
            // An ignored signal stays ignored through exec: the robot gets EFBIG from its
            // writes past the limit. `exec` leaves no shell behind.
            let mut command = Command::new("sh");
            command.args(["-c", "trap '' XFSZ; exec \"$0\" \"$@\""]).arg(&self.exe).args(&args);
            command
        } else {
            let mut command = Command::new(&self.exe);
            command.args(&args);
            command
        };
        Child::spawn(&name, &mut command)
    }

    /// Kills the robot's process (SIGKILL, no warning), keeps it for its output, and returns
    /// when the kernel has reaped it.
    pub fn kill(&mut self, key: RobotKey) -> Result<()> {
        let robot = self.robot_mut(key)?;
        robot.process.signal(nix::sys::signal::Signal::SIGKILL)?;
        robot.process.wait()?;
        Ok(())
    }

    /// Starts the robot again (after [`Game::kill`]).
    pub fn restart(&mut self, key: RobotKey) -> Result<()> {
        let (gc_port, log, file_limit, instance) = {
            let robot = self.robot(key)?;
            (robot.gc_port, robot.log.clone(), robot.file_limit, robot.instance + 1)
        };
        let process = self.spawn(key, gc_port, log.as_deref(), file_limit, instance)?;
        let robot = self.robot_mut(key)?;
        robot.poll();
        let old = std::mem::replace(&mut robot.process, process);
        robot.ended.push(old);
        robot.instance = instance;
        robot.read = 0;
        Ok(())
    }

    pub fn robot(&self, key: RobotKey) -> Result<&Robot> {
        self.robots.iter().find(|r| r.key == key).with_context(|| format!("no robot {key}"))
    }

    pub fn robot_mut(&mut self, key: RobotKey) -> Result<&mut Robot> {
        self.robots.iter_mut().find(|r| r.key == key).with_context(|| format!("no robot {key}"))
    }

    /// Whether the robot is in the server's world (a process drives it).
    pub fn present(&self, key: RobotKey) -> bool {
        let team = usize::from(key.team != TEAMS[0]);
        self.sim.lock().is_present(RobotId::new(team, key.player))
    }

    pub fn server(&self) -> Result<&RunningServer> {
        self.server.as_ref().context("the server has stopped")
    }

    /// Reads every robot's new lines, and the CPU times once a second.
    pub fn poll(&mut self) {
        for robot in &mut self.robots {
            robot.poll();
        }
        if self.cpu.last().is_none_or(|r| r.at.elapsed() >= Duration::from_secs(1)) {
            let mut processes: Vec<(String, u64)> = self
                .robots
                .iter()
                .filter_map(|r| {
                    measure::cpu_ticks(r.process.pid()).map(|t| (r.process.name().to_owned(), t))
                })
                .collect();
            if let Some(own) = measure::own_cpu_ticks() {
                processes.push((measure::SERVER.to_owned(), own));
            }
            self.cpu.push(CpuReading {
                at: Instant::now(),
                processes,
                machine: measure::machine_ticks(),
            });
        }
    }

    /// Fails with [`Interrupted`] once Ctrl-C was pressed.
    pub fn check_interrupt(&self) -> Result<()> {
        if self.interrupted.load(Ordering::Relaxed) {
            return Err(Interrupted.into());
        }
        Ok(())
    }

    /// Polls until `done` holds (true) or `within` has passed (false); Ctrl-C ends it with an
    /// error.
    pub fn wait_until(
        &mut self,
        within: Duration,
        mut done: impl FnMut(&Game) -> bool,
    ) -> Result<bool> {
        let deadline = Instant::now() + within;
        loop {
            self.check_interrupt()?;
            self.poll();
            if done(self) {
                return Ok(true);
            }
            if Instant::now() >= deadline {
                return Ok(false);
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Lets the game run for `duration`, reading the robots' lines meanwhile.
    pub fn run_for(&mut self, duration: Duration) -> Result<()> {
        self.wait_until(duration, |_| false).map(|_| ())
    }

    /// The (wall, simulated seconds) samples so far.
    pub fn time_samples(&self) -> Vec<(Instant, f64)> {
        lock(&self.keeper.samples).clone()
    }

    /// The GameController stops sending (before the end: the robots read what is on its way
    /// before their final counts).
    pub fn silence_gc(&self) {
        self.gc.sending.store(false, Ordering::Relaxed);
    }

    /// Stops every robot as Ctrl-C would (each writes its report and finishes its log), killing
    /// those still running after `grace`; then the server. Returns the robots that had to be
    /// killed and whether the server stopped cleanly.
    pub fn stop(&mut self, grace: Duration) -> Result<(Vec<RobotKey>, Result<(), String>)> {
        for robot in &mut self.robots {
            let _ = robot.process.signal(nix::sys::signal::Signal::SIGINT);
        }
        let deadline = Instant::now() + grace;
        let mut killed = Vec::new();
        for robot in &mut self.robots {
            let left = deadline.saturating_duration_since(Instant::now());
            if robot.process.wait_for(left)?.is_none() {
                robot.process.kill()?;
                killed.push(robot.key);
            }
            robot.process.wait()?;
            robot.poll();
        }
        let server = match self.server.take() {
            Some(server) => server.stop().map_err(|e| e.to_string()),
            None => Ok(()),
        };
        Ok((killed, server))
    }

    /// The last lines of every robot's stderr, for an error message.
    pub fn stderr_tails(&self) -> String {
        let mut text = String::new();
        for robot in &self.robots {
            for process in robot.processes() {
                let stderr = process.stderr();
                let tail: Vec<&str> = stderr.lines().rev().take(5).collect();
                if !tail.is_empty() {
                    text.push_str(&format!(
                        "\n{}: {}",
                        process.name(),
                        tail.into_iter().rev().collect::<Vec<_>>().join(" | ")
                    ));
                }
            }
        }
        text
    }

    /// Writes every robot process's stdout and stderr into `dir`.
    pub fn save_outputs(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        for robot in &self.robots {
            for (instance, process) in robot.processes().enumerate() {
                let base = format!("t{}-{}-{instance}", robot.key.team, robot.key.player);
                for (ext, text) in [("out", process.stdout()), ("err", process.stderr())] {
                    let path = dir.join(format!("{base}.{ext}"));
                    std::fs::write(&path, text)
                        .with_context(|| format!("writing {}", path.display()))?;
                }
            }
        }
        Ok(())
    }
}

fn free_udp_port() -> Result<u16> {
    UdpSocket::bind((Ipv4Addr::LOCALHOST, 0))
        .and_then(|s| s.local_addr())
        .map(|a| a.port())
        .context("asking the OS for a free UDP port")
}

fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}
