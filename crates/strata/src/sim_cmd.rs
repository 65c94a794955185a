//! `strata server`: the simulator over TCP, as in the paper's HL-SIM — the world runs in real
//! time in the server, each robot is its own process (`strata robot`, `robot_cmd.rs`). Also
//! `strata robot --controller test`: the simulator's test controller (walk to the ball, kick,
//! look around) against the server, a check of the server without the architecture.

use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::Args;
use strata_robot::platform::{Platform, PlatformError};
use strata_runtime::{Clock, MonotonicClock};
use strata_sim::net::{Server, ServerLimits, ServerOptions, TcpRobot, connect};
use strata_sim::{SimConfig, SimHandle, Simulation, TestController};

pub use strata_sim::net::DEFAULT_ADDR;

/// `strata server`: the simulated world in real time.
#[derive(Debug, Args)]
pub struct ServerArgs {
    /// Address to listen on.
    #[arg(long, default_value = DEFAULT_ADDR)]
    pub addr: String,
    /// Simulator configuration (TOML, any subset of crates/sim/config/default.toml; keys left
    /// out take the code's defaults). Without it: the defaults with GameController3's timing
    /// and the referee's signals, as that file ships them.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The referee sends every state at once, without Standby or the referee's signals
    /// (GameController3's `--no-delay`).
    #[arg(long)]
    pub no_delay: bool,
    /// Overrides the configuration's seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Seconds between status lines.
    #[arg(long, default_value_t = 5.0)]
    pub status_interval: f64,
    /// Keep every robot on the field even when no process drives it (it stands still).
    #[arg(long)]
    pub keep_idle_robots: bool,
    /// Connections open at once, robots and handshakes together; one more is refused with
    /// `too_many_connections`.
    #[arg(long, value_name = "N", default_value_t = ServerLimits::DEFAULT.max_connections,
          value_parser = parse_count)]
    pub max_connections: usize,
    /// Seconds from accepting a connection to having its whole `hello`.
    #[arg(long, value_name = "SECONDS", value_parser = parse_seconds,
          default_value_t = ServerLimits::DEFAULT.handshake_deadline.as_secs_f64())]
    pub handshake_deadline: f64,
    /// Messages (orders, team messages, return packets) a robot may send per second; the
    /// excess is dropped and counted.
    #[arg(long, value_name = "N", default_value_t = ServerLimits::DEFAULT.max_messages_per_second,
          value_parser = clap::value_parser!(u32).range(1..))]
    pub max_messages_per_second: u32,
    /// Seconds a write to one robot may block before the server drops that robot.
    #[arg(long, value_name = "SECONDS", value_parser = parse_seconds,
          default_value_t = ServerLimits::DEFAULT.write_timeout.as_secs_f64())]
    pub write_timeout: f64,
}

impl ServerArgs {
    fn limits(&self) -> ServerLimits {
        ServerLimits {
            max_connections: self.max_connections,
            handshake_deadline: Duration::from_secs_f64(self.handshake_deadline),
            max_messages_per_second: self.max_messages_per_second,
            write_timeout: Duration::from_secs_f64(self.write_timeout),
        }
    }
}

/// A count of at least 1.
fn parse_count(text: &str) -> Result<usize, String> {
    match text.parse::<usize>() {
        Ok(0) => Err("must be at least 1".to_owned()),
        Ok(count) => Ok(count),
        Err(_) => Err(format!("{text:?} is not a whole number")),
    }
}

/// A duration in seconds, positive and at most a day (a limit, not a way to switch it off).
fn parse_seconds(text: &str) -> Result<f64, String> {
    let seconds: f64 = text.parse().map_err(|_| format!("{text:?} is not a number of seconds"))?;
    if seconds > 0.0 && seconds <= 86_400.0 {
        Ok(seconds)
    } else {
        Err(format!("{seconds} s is outside 0 (exclusive) to 86400 s"))
    }
}

/// Runs the simulator server until Ctrl-C.
pub fn run_server(args: ServerArgs) -> Result<()> {
    let mut config = match &args.config {
        Some(path) => SimConfig::load(path)?,
        None => {
            let mut config = SimConfig::default();
            config.referee = config.referee.game_controller3();
            config
        }
    };
    if args.no_delay {
        config.referee = config.referee.no_delay();
    }
    if let Some(seed) = args.seed {
        config.seed = seed;
    }
    let teams = [config.referee.teams[0].number, config.referee.teams[1].number];
    let players = config.referee.players_per_team;
    let simulation = Simulation::new(config).context("building the simulated world")?;
    let field = simulation.field().to_string();
    let seed = simulation.config().seed;
    let options = ServerOptions {
        status_interval: Duration::from_secs_f64(args.status_interval.max(0.1)),
        robots_need_clients: !args.keep_idle_robots,
        limits: args.limits(),
        ..ServerOptions::default()
    };
    let server = Server::bind(args.addr.as_str(), SimHandle::new(simulation), options)?;
    let addr = server.local_addr();
    println!(
        "strata server listening on {addr}: {field}, teams {} and {}, {players} players each, seed {seed}",
        teams[0], teams[1]
    );
    println!(
        "connect robots with: strata robot --server {addr} --team {} --player 1   (Ctrl-C stops)",
        teams[0]
    );
    let stop = strata_runtime::signal::interrupt_flag().map_err(anyhow::Error::msg)?;
    server.run(stop, |status| println!("{status}"))?;
    println!("strata server stopped");
    Ok(())
}

/// `strata robot --controller test`: one robot process connected to a simulator server.
#[derive(Debug, Args)]
pub struct RobotArgs {
    /// The simulator server's address.
    #[arg(long, default_value = DEFAULT_ADDR)]
    pub server: String,
    /// Team number (as in GameController packets; the default config has 10 and 20).
    #[arg(long)]
    pub team: u8,
    /// Player number, 1 to the number of players per team.
    #[arg(long)]
    pub player: u8,
    /// Stop after this many seconds (default: until Ctrl-C or the server closes).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Seconds between status lines.
    #[arg(long, default_value_t = 2.0)]
    pub status_interval: f64,
}

/// Drives one robot of a simulator server with the test controller.
pub fn run_robot_test_controller(args: RobotArgs) -> Result<()> {
    let TcpRobot { mut platform, mut game_controller, welcome, .. } =
        connect(args.server.as_str(), args.team, args.player, Duration::from_secs(5))
            .with_context(|| format!("connecting to the simulator at {}", args.server))?;
    println!(
        "robot {}/{} connected to {} ({}, sensors every {} ms)",
        welcome.team,
        welcome.player,
        args.server,
        welcome.info.name,
        welcome.info.sensor_period.as_millis()
    );
    let mut controller = TestController::new(platform.info(), args.team, args.player);
    let period = welcome.info.sensor_period.max(Duration::from_millis(1));
    let status_every = Duration::from_secs_f64(args.status_interval.max(0.1));
    let stop = strata_runtime::signal::interrupt_flag().map_err(anyhow::Error::msg)?;
    let clock = MonotonicClock::start();
    let started = Instant::now();
    let mut next = started;
    let mut last_status = started;
    while !stop.load(Ordering::Relaxed) {
        if args.duration.is_some_and(|d| started.elapsed().as_secs_f64() >= d) {
            break;
        }
        let now = clock.now();
        controller.read_game_controller(&mut game_controller, now);
        match controller.step(&mut platform, now) {
            Ok(()) => {}
            Err(PlatformError::Disconnected(reason)) => {
                println!("robot {}/{}: {reason}", args.team, args.player);
                return Ok(());
            }
            Err(error) => return Err(error).context("the test controller failed"),
        }
        if last_status.elapsed() >= status_every {
            last_status = Instant::now();
            let (frames, detections) = controller.counts();
            let game = controller.game();
            println!(
                "robot {}/{}  t={:7.1} s  frames={frames:6}  detections={detections:7}  ball {}  game {}  score {}:{}{}",
                args.team,
                args.player,
                started.elapsed().as_secs_f64(),
                if controller.sees_ball(now) { "seen" } else { "lost" },
                game.state.map_or_else(|| "unknown".to_owned(), |s| format!("{s:?}")),
                game.score[0],
                game.score[1],
                if game.penalized { "  (penalized)" } else { "" },
            );
        }
        next += period;
        let wall = Instant::now();
        if next > wall {
            std::thread::sleep(next - wall);
        } else {
            // Behind (a slow machine): do not try to catch up with a burst of cycles.
            next = wall;
        }
    }
    println!("robot {}/{} stopped", args.team, args.player);
    Ok(())
}
