//! One robot, one process, in real time: the full soccer robot (perception, world modeling,
//! actuation and the three layers of hybrid control) on the threaded host, over one of its
//! platforms — what `strata robot` runs (`docs/robot.md`):
//!
//! - [`PlatformKind::Sim`]: the simulator server over TCP (`strata server`). Sensors and orders
//!   go through the server; so do team messages and the game state, unless `net`.
//! - [`PlatformKind::Nao`]: a NAO v6 through LoLA. Team messages and the game state come from
//!   the field's network (`net` is implied).
//! - [`PlatformKind::Rcssservermj`]: a Booster T1 in the RoboCup simulation league's MuJoCo
//!   server. The game state comes from the server's referee; the server carries no team
//!   messages of Strata's size, so teammates talk over UDP with `net` or `team_udp`, or not at
//!   all.
//!
//! With `net`, the GameController's control packets arrive on UDP (3838), return packets go
//! back to it (3939), and team messages are UDP broadcasts (10000 + team): the protocols of a
//! real SPL field, whatever provides the sensors.
//!
//! [`run`] tells a [`RobotOutput`] what happens (the start, game-state changes, status lines,
//! notes, the final [`Report`]); the command line prints them as text or JSON lines.
//!
//! - [`platform`]: opening the platform and counting its traffic;
//! - [`links`]: the team and GameController links, and the attack direction they tell;
//! - [`watch`]: taps on the robot's packages (game events, localization against the truth);
//! - [`report`]: what the output is told.

mod links;
mod platform;
pub mod report;
mod watch;

use std::net::Ipv4Addr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, bail};
use clap::ValueEnum;
use serde::Serialize;
use strata_log::{
    ConfigFormat, LogCompression, LogSummary, McapTap, McapTapOptions, RunInfo, WhenFull,
};
use strata_rcssmj::referee::penalty_spots;
use strata_robot::assembly::RobotModules;
use strata_robot::control::reactive::FallDetectorConfig;
use strata_robot::edge::{Links, RobotLinks, RobotPlatform};
use strata_robot::geometry::Pose;
use strata_robot::platform::{ExternalLink, TeamLink};
use strata_robot::world::PosePrior;
use strata_runtime::{
    Encoding, GraphBuilder, HostConfig, HostError, HostStats, MonotonicClock, Tap, ThreadedHost,
};
use strata_soccer::behaviors::BehaviorConfig;
use strata_soccer::field::TeamField;
use strata_soccer::primitives::MotionModel;
use strata_soccer::team::{SoccerRobotSpec, TeamConfig, add_soccer_robot, robot_world_config};
use strata_spl::Field;

use crate::links::{LinkCounters, LinkStats};
use crate::logging::{RobotRunConfig, open_run_log};
use crate::scene::live::{self, SceneServer};
use links::{OpenLinks, learn_attack_sign, open_links};
use platform::{OpenPlatform, PlatformCounters, open_platform, sit_down};
use report::LayerMeter;
pub use report::{
    BallStatus, Compute, ConvergedAccuracy, GameEvent, LayerNow, LocalizationAccuracy, PoseStatus,
    Report, StartInfo, Status,
};
use watch::{Accuracy, Watch};

/// What [`run`] tells as the robot runs. Called from the robot's monitor thread and from the
/// thread that called [`run`], one call at a time.
pub trait RobotOutput: Send + Sync {
    /// The robot is built and about to start.
    fn start(&self, info: &StartInfo);
    /// The game changed as the robot sees it, `t` seconds after the start.
    fn game_event(&self, t: f64, event: &GameEvent);
    /// Every `status_interval` seconds.
    fn status(&self, status: &Status);
    /// Something worth a line: a refused real-time priority, a log's summary or failure.
    fn note(&self, text: &str);
    /// The run ended.
    fn report(&self, report: &Report);
}

/// Which hardware the robot runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PlatformKind {
    /// The simulator server over TCP (`strata server`).
    Sim,
    /// A NAO v6 through LoLA.
    Nao,
    /// A Booster T1 in rcssservermj (docs/rcssservermj.md).
    Rcssservermj,
}

/// How one robot runs: `strata robot`'s options, which the command line parses into this
/// struct (its help is these fields' documentation). A program fills it in from
/// [`RobotOptions::new`], which has the same defaults.
#[derive(Clone, Debug, PartialEq, clap::Args)]
pub struct RobotOptions {
    /// Team number, as in GameController packets (the simulator's default teams: 10 and 20).
    #[arg(long)]
    pub team: u8,
    /// Player number (1 is the goalkeeper in the built-in formations).
    #[arg(long)]
    pub player: u8,
    #[arg(long, value_enum, default_value = "sim")]
    pub platform: PlatformKind,
    /// A built-in team (full, no-coordination, no-active-vision, always-ball, fixed-scan,
    /// entropy) or a team TOML file.
    #[arg(long, default_value = "full")]
    pub team_config: String,
    /// The simulator server (platform sim) [default: 127.0.0.1:7500], or rcssservermj's agent
    /// port (platform rcssservermj) [default: 127.0.0.1:60000].
    #[arg(long, value_name = "ADDR")]
    pub server: Option<String>,
    /// LoLA's socket (platform nao).
    #[arg(long, value_name = "PATH", default_value = strata_nao::DEFAULT_SOCKET_PATH)]
    pub socket: PathBuf,
    /// LoLA platform configuration (TOML, docs/nao.md), platform nao.
    #[arg(long, value_name = "FILE")]
    pub lola_config: Option<PathBuf>,
    /// The team's name in rcssservermj (platform rcssservermj) [default: Strata<team>].
    #[arg(long, value_name = "NAME")]
    pub team_name: Option<String>,
    /// rcssservermj platform configuration (TOML, docs/rcssservermj.md): camera model, walk
    /// limits, pacing.
    #[arg(long, value_name = "FILE")]
    pub rcss_config: Option<PathBuf>,
    /// Where the server places the robot before kick-off (platform rcssservermj): x, y in
    /// metres in the team's frame and a heading in degrees, e.g. `--beam=-3,0,0`.
    #[arg(long, value_name = "X,Y,DEG", value_parser = parse_beam, allow_hyphen_values = true)]
    pub beam: Option<[f64; 3]>,
    /// Field preset (spl, paper2010, rcssservermj) or field TOML file; must be the
    /// simulator's [default: rcssservermj on that platform, spl elsewhere].
    #[arg(long)]
    pub field: Option<String>,
    /// Length of a half, s (paces team messages within the budget).
    #[arg(long, default_value_t = 600.0)]
    pub half_duration: f64,
    /// The field direction this team attacks, +1 or -1 [default: from the first GameController
    /// packet — the team listed first attacks +x in the first half — or +1 without one].
    #[arg(long, allow_hyphen_values = true, value_parser = parse_sign)]
    pub attack_sign: Option<f64>,
    /// Seconds to wait for a first GameController packet at start (to learn the attack
    /// direction); 0 to start at once.
    #[arg(long, value_name = "SECS", default_value_t = 2.0)]
    pub gc_wait: f64,

    /// Game state and team messages over UDP, as on a real field (implied on a NAO).
    #[arg(long)]
    pub net: bool,
    /// Team messages over UDP while the platform keeps the game state (rcssservermj: its
    /// referee): the server carries no message of Strata's size. `--team-port`, `--broadcast`
    /// and `--interface` apply.
    #[arg(long, conflicts_with = "net")]
    pub team_udp: bool,
    /// The robot's field interface as ADDRESS/PREFIX (e.g. 10.0.18.15/16): team messages go to
    /// its directed broadcast address instead of 255.255.255.255.
    #[arg(long, value_name = "ADDR/PREFIX", conflicts_with = "broadcast")]
    pub interface: Option<String>,
    /// Where team messages are broadcast (127.255.255.255: several robots on one machine).
    #[arg(long, value_name = "ADDR")]
    pub broadcast: Option<Ipv4Addr>,
    /// UDP port of GameController control packets [default: 3838].
    #[arg(long, value_name = "PORT")]
    pub gc_port: Option<u16>,
    /// UDP port the GameController receives return packets on [default: 3939].
    #[arg(long, value_name = "PORT")]
    pub gc_return_port: Option<u16>,
    /// UDP port of the team's messages [default: 10000 + team].
    #[arg(long, value_name = "PORT")]
    pub team_port: Option<u16>,

    /// Stop after this many seconds (default: until Ctrl-C or the platform goes away).
    #[arg(long, value_name = "SECS")]
    pub duration: Option<f64>,
    /// Seconds between status lines.
    #[arg(long, value_name = "SECS", default_value_t = 2.0)]
    pub status_interval: f64,
    /// Seeds the modules' random numbers [default: 100 x team + player].
    #[arg(long)]
    pub seed: Option<u64>,
    /// Real-time priority (SCHED_FIFO, 1-99) of the sensor path's threads (perception, world
    /// modeling, reactive layer, actuation), so that a long deliberative cycle cannot delay
    /// them when no core is free; 0: the operating system's default policy for every thread.
    /// Without the permission (root or CAP_SYS_NICE) the robot says so and runs with the
    /// default policy.
    #[arg(long, value_name = "PRIORITY", default_value_t = 10,
          value_parser = clap::value_parser!(u8).range(0..=99))]
    pub real_time_priority: u8,
    /// Record every package of this robot into this MCAP file, with its graph, seed and team
    /// configuration (docs/logging.md). A module never waits for the disk: what the writer
    /// cannot keep up with is dropped, counted and reported.
    #[arg(long, value_name = "FILE.mcap")]
    pub log: Option<PathBuf>,
    /// How the log's chunks are compressed: zstd, lz4 or none.
    #[arg(long, value_name = "zstd|lz4|none", default_value = "zstd", requires = "log")]
    pub log_compression: LogCompression,
    /// How package values are encoded: cdr (compact), msgpack or json.
    #[arg(long, value_name = "cdr|msgpack|json", default_value = "cdr", requires = "log")]
    pub log_encoding: Encoding,
    /// Do not sync each chunk of the log to the disk once written. Synced (the default), a
    /// power cut or a crash of the machine loses at most the chunk being gathered (half a
    /// second); unsynced, whatever the operating system had not yet written.
    #[arg(long, requires = "log")]
    pub log_no_sync: bool,
    /// Split the log into files of about this many megabytes: past it, at the end of a chunk,
    /// the file is finished and the log goes on in FILE-1.mcap, FILE-2.mcap..., each file a
    /// whole log (its graph, run and configuration included).
    #[arg(long, value_name = "MB", requires = "log",
          value_parser = clap::value_parser!(u64).range(1..))]
    pub log_max_size: Option<u64>,
    /// Serve the robot's scene live (its own estimates: it has no ground truth) over
    /// Foxglove's WebSocket protocol on this address, for the Foxglove app's 3D panel
    /// (docs/foxglove.md, "Live") [default: 127.0.0.1:8765].
    #[arg(long, value_name = "ADDR", num_args = 0..=1,
          default_missing_value = crate::scene::live::DEFAULT_ADDR)]
    pub foxglove: Option<String>,
}

impl RobotOptions {
    /// Player `player` of team `team` on `platform`, everything else at `strata robot`'s
    /// defaults.
    pub fn new(team: u8, player: u8, platform: PlatformKind) -> RobotOptions {
        RobotOptions {
            team,
            player,
            platform,
            team_config: "full".to_owned(),
            server: None,
            socket: PathBuf::from(strata_nao::DEFAULT_SOCKET_PATH),
            lola_config: None,
            team_name: None,
            rcss_config: None,
            beam: None,
            field: None,
            half_duration: 600.0,
            attack_sign: None,
            gc_wait: 2.0,
            net: false,
            team_udp: false,
            interface: None,
            broadcast: None,
            gc_port: None,
            gc_return_port: None,
            team_port: None,
            duration: None,
            status_interval: 2.0,
            seed: None,
            real_time_priority: 10,
            log: None,
            log_compression: LogCompression::Zstd,
            log_encoding: Encoding::Cdr,
            log_no_sync: false,
            log_max_size: None,
            foxglove: None,
        }
    }
}
/// Where a beam puts the robot, in its team's frame: rcssservermj moves `x` into the own half
/// and turns the right team's heading by half a circle but leaves `y` in the world's frame
/// (docs/rcssservermj-protocol.md), which is the team's frame turned for a team attacking -x.
/// `beam` is as parsed from `--beam`: metres and radians.
fn beam_prior([x, y, theta]: [f64; 3], attack_sign: f64) -> PosePrior {
    PosePrior {
        pose: Pose::new(-x.abs(), attack_sign.signum() * y, theta),
        sigma: [0.1, 0.1, 0.05],
    }
}

/// Runs one robot until Ctrl-C, `opts.duration` or the end of its platform, telling `out` how
/// it goes.
pub fn run(opts: &RobotOptions, out: &Arc<dyn RobotOutput>) -> Result<()> {
    validate(opts)?;
    // Reads links outside the host (before it starts, and links the robot does not use). It
    // starts before the host's own clock, so it reads later than that clock at any moment: the
    // simulator client maps its server's stamps with the smallest offset seen between a
    // reader's clock and the server's, and an earlier clock would corrupt that offset.
    let early_clock = MonotonicClock::start();
    let (config, field) = team_config_and_field(opts)?;

    // The body.
    let mut platform = open_platform(opts)?;
    let info = platform.info.clone();

    // The radio and the referee.
    let OpenLinks {
        team: team_link,
        game_controller: gc_link,
        team_counters,
        gc_counters,
        endpoints,
        unused: unused_sim_links,
    } = open_links(opts, platform.links.take(), early_clock)?;

    // Which way the team attacks, from the first control packet if one comes.
    let (gc_link, attack_sign, attack_source) =
        learn_attack_sign(gc_link, opts.team, opts.attack_sign, opts.gc_wait, &early_clock);
    let team_field = Arc::new(TeamField::new(field, attack_sign));

    let RobotGraph { graph, modules, initial_pose, relocations } =
        robot_graph(opts, &config, &team_field, &platform, team_link, gc_link)?;
    let watch = Arc::new(Watch::new(&modules.planning));
    let seed = opts.seed.unwrap_or(100 * u64::from(opts.team) + u64::from(opts.player));
    let host_config = HostConfig {
        real_time_priority: (opts.real_time_priority > 0).then_some(opts.real_time_priority),
        ..HostConfig::with_seed(seed)
    };
    let run_config = RobotRunConfig {
        robot: format!("t{}/{}", opts.team, opts.player),
        team: config.clone(),
        world: robot_world_config(&config, &team_field, initial_pose, &relocations),
        field: team_field.field.dimensions().clone(),
        attack_sign,
        platform: info.clone(),
    };
    let log = match &opts.log {
        Some(path) => Some(open_log(path, opts, seed, &run_config, &graph)?),
        None => None,
    };
    let mut foxglove = match &opts.foxglove {
        Some(text) => {
            let addr = live::parse_addr(text)?;
            let robots = [run_config.robot.clone()];
            Some(SceneServer::start(addr, run_config.scene(), robots)?)
        }
        None => None,
    };
    let mut host = ThreadedHost::new(graph, host_config);
    host.add_tap(Arc::clone(&watch) as Arc<dyn Tap>);
    let accuracy = platform.truth.clone().map(|truth| {
        Arc::new(Accuracy {
            world: modules.world.clone(),
            truth,
            attack_sign,
            state: Mutex::default(),
        })
    });
    if let Some(accuracy) = &accuracy {
        host.add_tap(Arc::clone(accuracy) as Arc<dyn Tap>);
    }
    if let Some(log) = &log {
        host.add_tap(Arc::clone(log) as Arc<dyn Tap>);
    }
    if let Some(server) = &foxglove {
        host.add_tap(Arc::new(server.tap(None)));
        out.note(&format!("Foxglove: {} (Open connection -> Foxglove WebSocket)", server.url()));
    }

    out.start(&start_info(opts, &platform, &config, endpoints, attack_sign, attack_source));

    let running = host.start().context("starting the robot's module threads")?;
    if let Some(t1) = &platform.t1 {
        // The cycles while the robot was being set up are not its work.
        t1.lock().unwrap_or_else(PoisonError::into_inner).inner.restart_compute();
    }
    for (module, reason) in running.real_time_refusals() {
        out.note(&format!(
            "module {module} runs with the default scheduling policy: real-time priority {} \
             refused ({reason}); --real-time-priority 0 silences this",
            opts.real_time_priority
        ));
    }
    running.stop_on_interrupt().context("installing the Ctrl-C handler")?;
    let stop = running.stop_handle();
    let probe = running.stats_probe();
    let layer_modules: Vec<(String, String)> = modules
        .layers()
        .iter()
        .map(|(layer, module)| ((*layer).to_owned(), (*module).to_owned()))
        .collect();
    let started = Instant::now();
    // The host's `wait` returns when asked to stop or when a module fails; a monitor thread
    // reports progress meanwhile and asks to stop at the end of `--duration` or when the
    // platform is gone.
    let done = Arc::new(AtomicBool::new(false));
    let end = Arc::new(Mutex::new(None::<String>));
    let monitor = Monitor {
        done: Arc::clone(&done),
        end: Arc::clone(&end),
        watch: Arc::clone(&watch),
        out: Arc::clone(out),
        counters: Arc::clone(&platform.counters),
        team_counters: Arc::clone(&team_counters),
        gc_counters: Arc::clone(&gc_counters),
        accuracy: accuracy.clone(),
        log: log.clone(),
        duration: opts.duration.map(|d| Duration::from_secs_f64(d.max(0.0))),
        status_every: Duration::from_secs_f64(opts.status_interval.max(0.1)),
        started,
        rates: LayerMeter::new(layer_modules),
        unused_links: unused_sim_links,
        probe,
        stop,
    };
    let monitor = std::thread::Builder::new()
        .name("robot-monitor".to_owned())
        .spawn(move || monitor.run())
        .context("starting the monitor thread")?;
    let result = running.wait();
    done.store(true, Ordering::Relaxed);
    let _ = monitor.join();
    for event in watch.take_events() {
        out.game_event(started.elapsed().as_secs_f64(), &event);
    }
    if let Some(nao) = &platform.nao {
        sit_down(nao, out.as_ref());
    }
    if let Some(log) = &log {
        match log.finish() {
            Ok(summary) => out.note(&log_note(&summary)),
            Err(error) => out.note(&format!("log: {error}")),
        }
    }
    if let Some(server) = &mut foxglove {
        server.finish();
        if server.dropped() > 0 {
            out.note(&format!(
                "Foxglove: {} packages dropped (the server's worker fell behind)",
                server.dropped()
            ));
        }
    }

    let planned_end = end.lock().unwrap_or_else(PoisonError::into_inner).clone();
    conclude(
        opts,
        result,
        planned_end,
        Ran {
            started,
            platform: &platform,
            watch: &watch,
            modules: &modules,
            accuracy,
            out: out.as_ref(),
        },
        (team_counters.snapshot(), gc_counters.snapshot()),
    )
}

/// One soccer robot's graph, and where it believes it starts.
struct RobotGraph {
    graph: strata_runtime::Graph,
    modules: RobotModules,
    initial_pose: Option<PosePrior>,
    relocations: Vec<PosePrior>,
}

/// The robot: all four modules, all three layers, between its platform and its links.
fn robot_graph(
    opts: &RobotOptions,
    config: &TeamConfig,
    team_field: &Arc<TeamField>,
    platform: &OpenPlatform,
    team_link: Option<Box<dyn TeamLink>>,
    gc_link: Box<dyn ExternalLink>,
) -> Result<RobotGraph> {
    let attack_sign = team_field.attack_sign;
    // A robot that beams itself knows where it starts, as the league's agents do.
    let initial_pose = match opts.platform {
        PlatformKind::Rcssservermj => opts.beam.map(|beam| beam_prior(beam, attack_sign)),
        _ => None,
    };
    // rcssservermj's referee moves robots to the side line without a word; a GameController
    // announces each penalty.
    let relocations = match opts.platform {
        PlatformKind::Rcssservermj => penalty_spots(team_field.field.dimensions()),
        _ => Vec::new(),
    };
    let mut graph = GraphBuilder::new();
    let spec = SoccerRobotSpec {
        // Module names: `t10/3/planning`...
        name: format!("t{}/{}", opts.team, opts.player),
        team_number: opts.team,
        player: opts.player,
        field: Arc::clone(team_field),
        platform: RobotPlatform::Shared(Arc::clone(&platform.shared)),
        links: RobotLinks::Shared(Links::new(team_link, Some(gc_link))),
        half_duration: opts.half_duration,
        initial_pose,
        relocations: relocations.clone(),
    };
    let modules = add_soccer_robot(&mut graph, spec, config)
        .map_err(|e| anyhow::anyhow!("building robot {}/{}: {e}", opts.team, opts.player))?;
    let graph = graph.build().context("wiring the robot's modules")?;
    Ok(RobotGraph { graph, modules, initial_pose, relocations })
}

/// What the start line says: the platform, the team and where its links lead.
fn start_info(
    opts: &RobotOptions,
    platform: &OpenPlatform,
    config: &TeamConfig,
    endpoints: report::Endpoints,
    attack_sign: f64,
    attack_source: String,
) -> StartInfo {
    StartInfo {
        team: opts.team,
        player: opts.player,
        platform: opts.platform,
        platform_name: platform.info.name.clone(),
        source: platform.source.clone(),
        sensor_period_ms: platform.info.sensor_period.as_secs_f64() * 1e3,
        can_walk: platform.info.can_walk,
        controller: "soccer",
        team_config: config.name.clone(),
        coordination: config.coordination,
        game_controller: endpoints.game_controller,
        team_messages: endpoints.team,
        attack_sign,
        attack_source,
    }
}

/// Creates the robot's log and writes what a reader needs besides the packages: the run (seed,
/// command line, the configuration its modules are rebuilt from) and the graph.
fn open_log(
    path: &std::path::Path,
    opts: &RobotOptions,
    seed: u64,
    config: &RobotRunConfig,
    graph: &strata_runtime::Graph,
) -> Result<Arc<McapTap>> {
    let options = McapTapOptions {
        // A real-time host: a module never waits for the disk.
        when_full: WhenFull::Drop,
        compression: opts.log_compression,
        encoding: opts.log_encoding,
        // A robot's run cannot be played again: what it logged must survive a power cut.
        sync_chunks: !opts.log_no_sync,
        max_file_size: opts.log_max_size.map(|mb| mb.saturating_mul(1_000_000)),
        ..McapTapOptions::default()
    };
    let text =
        serde_json::to_string_pretty(config).context("serializing the robot's configuration")?;
    let run = RunInfo::current(seed).with_config(ConfigFormat::Json, text);
    open_run_log(
        path,
        options,
        &run,
        &graph.describe(),
        [config.robot.clone()],
        Some(config.scene()),
    )
}

/// What a finished log holds: `log: robot.mcap (N messages, D dropped, X MB)`, or
/// `log: robot.mcap to robot-3.mcap (4 files, ...)` when it was split at its size cap.
fn log_note(summary: &LogSummary) -> String {
    let counts = format!(
        "{} messages, {} dropped, {:.1} MB",
        summary.messages,
        summary.dropped,
        summary.bytes as f64 / 1e6
    );
    match &summary.files[..] {
        [first, .., last] => format!(
            "log: {} to {} ({} files, {counts})",
            first.display(),
            last.display(),
            summary.files.len()
        ),
        [only] => format!("log: {} ({counts})", only.display()),
        [] => format!("log: ({counts})"),
    }
}

fn parse_beam(text: &str) -> Result<[f64; 3], String> {
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>().map_err(|_| format!("`{v}` is not a number")))
        .collect::<Result<_, _>>()?;
    match values[..] {
        [x, y, degrees] if values.iter().all(|v| v.is_finite()) => Ok([x, y, degrees.to_radians()]),
        _ => Err(format!("expected X,Y,DEG (three numbers), got `{text}`")),
    }
}

fn parse_sign(text: &str) -> Result<f64, String> {
    match text.trim() {
        "1" | "+1" | "+" => Ok(1.0),
        "-1" | "-" => Ok(-1.0),
        other => Err(format!("expected +1 or -1, got `{other}`")),
    }
}

/// Refuses options that contradict each other, naming them as the command line does; [`run`]
/// calls it first.
pub fn validate(opts: &RobotOptions) -> Result<()> {
    if opts.player == 0 {
        bail!("--player must be 1 or more");
    }
    if !(opts.half_duration.is_finite() && opts.half_duration > 0.0) {
        bail!("--half-duration must be > 0, got {}", opts.half_duration);
    }
    if opts.duration.is_some_and(|d| !(d.is_finite() && d >= 0.0)) {
        bail!("--duration must be a number of seconds >= 0");
    }
    if !(opts.gc_wait.is_finite() && opts.gc_wait >= 0.0) {
        bail!("--gc-wait must be >= 0, got {}", opts.gc_wait);
    }
    if let Some(addr) = &opts.foxglove {
        live::parse_addr(addr)?;
    }
    let net_options = [
        ("--interface", opts.interface.is_some()),
        ("--broadcast", opts.broadcast.is_some()),
        ("--gc-port", opts.gc_port.is_some()),
        ("--gc-return-port", opts.gc_return_port.is_some()),
        ("--team-port", opts.team_port.is_some()),
    ];
    match opts.platform {
        PlatformKind::Sim => {
            if let Some((option, _)) = net_options.iter().find(|(_, given)| *given)
                && !opts.net
            {
                bail!("{option} configures the UDP links: add --net");
            }
            if opts.team_udp {
                bail!(
                    "--team-udp is for --platform rcssservermj (the simulator server carries \
                       team messages; --net puts everything on UDP)"
                );
            }
        }
        PlatformKind::Rcssservermj => {
            for (option, given) in net_options {
                let team_option = matches!(option, "--interface" | "--broadcast" | "--team-port");
                if given && !opts.net && !(team_option && opts.team_udp) {
                    bail!(
                        "{option} configures the UDP links: add --net{}",
                        if team_option { " (or --team-udp)" } else { "" }
                    );
                }
            }
        }
        PlatformKind::Nao => {
            if opts.team_udp {
                bail!("--team-udp is for --platform rcssservermj (a NAO has everything on UDP)");
            }
            if opts.server.is_some() {
                bail!("--server is for --platform sim; a NAO reads its sensors through LoLA");
            }
        }
    }
    if opts.platform != PlatformKind::Nao && opts.lola_config.is_some() {
        bail!("--lola-config is for --platform nao");
    }
    if opts.platform != PlatformKind::Rcssservermj
        && (opts.rcss_config.is_some() || opts.beam.is_some() || opts.team_name.is_some())
    {
        bail!("--rcss-config, --beam and --team-name are for --platform rcssservermj");
    }
    Ok(())
}

/// What ran, for the final report.
struct Ran<'a> {
    started: Instant,
    platform: &'a OpenPlatform,
    watch: &'a Watch,
    modules: &'a RobotModules,
    accuracy: Option<Arc<Accuracy>>,
    out: &'a dyn RobotOutput,
}

/// Prints the final report and says how the run ended: an error for a failed module or a
/// server lost mid-game.
fn conclude(
    opts: &RobotOptions,
    result: Result<HostStats, HostError>,
    planned_end: Option<String>,
    ran: Ran<'_>,
    (team_link, gc_link): (LinkStats, LinkStats),
) -> Result<()> {
    let Ran { started, platform, watch, modules, accuracy, out } = ran;
    let (stats, ended, failure) = match result {
        Ok(stats) => (stats, planned_end.unwrap_or_else(|| "interrupted".to_owned()), None),
        Err(error) => {
            let Some(stats) = error.stats().cloned() else {
                return Err(error).context("the robot's host failed");
            };
            // A platform that went away (the simulator server stopped) ends the run; any other
            // failure of a module is an error of this robot.
            match (&error, platform.counters.disconnected()) {
                (HostError::ModuleFailed { .. }, Some(reason)) => {
                    (stats, format!("platform disconnected: {reason}"), None)
                }
                _ => (stats, format!("failed: {error}"), Some(error)),
            }
        }
    };
    let report = Report::new(
        opts,
        started.elapsed().as_secs_f64(),
        ended,
        &platform.counters,
        watch,
        team_link,
        gc_link,
        modules,
        stats,
    );
    let t1 = platform.t1.as_ref().map(|t1| t1.lock().unwrap_or_else(PoisonError::into_inner));
    let falls = t1.as_ref().map(|t1| t1.inner.falls()).unwrap_or_default();
    let false_falls = t1.as_ref().map(|t1| t1.inner.false_falls()).unwrap_or_default();
    let compute = t1.as_ref().map(|t1| Compute::new(t1.inner.compute(), &report.host));
    let lost_server = t1.as_ref().and_then(|t1| t1.inner.lost_mid_game());
    drop(t1);
    let report = Report {
        localization: accuracy.and_then(|a| a.snapshot()),
        falls,
        false_falls,
        compute,
        ..report
    };
    out.report(&report);
    match (failure, lost_server) {
        (Some(error), _) => Err(error).context("a module of the robot failed"),
        // The 2D simulator's server ends a game by closing its connections; rcssservermj does
        // not, so a closed link before its GameOver is a server that stopped or crashed.
        (None, Some(reason)) => bail!(
            "lost the server mid-game: {reason} (it stopped or crashed); the run's report is \
             written{}",
            opts.log
                .as_ref()
                .map(|p| format!(" and its log {} finalized", p.display()))
                .unwrap_or_default()
        ),
        (None, None) => Ok(()),
    }
}

/// Reports progress while the robot runs, on a thread of its own, and asks the host to stop at
/// the end of `--duration` or when the platform is gone.
struct Monitor {
    done: Arc<AtomicBool>,
    end: Arc<Mutex<Option<String>>>,
    watch: Arc<Watch>,
    out: Arc<dyn RobotOutput>,
    counters: Arc<PlatformCounters>,
    team_counters: Arc<LinkCounters>,
    gc_counters: Arc<LinkCounters>,
    accuracy: Option<Arc<Accuracy>>,
    log: Option<Arc<McapTap>>,
    duration: Option<Duration>,
    status_every: Duration,
    started: Instant,
    rates: LayerMeter,
    unused_links: Vec<Box<dyn FnMut() + Send>>,
    probe: strata_runtime::StatsProbe,
    stop: strata_runtime::StopHandle,
}

impl Monitor {
    fn run(mut self) {
        let mut last_status = Instant::now();
        let mut log_failed = false;
        while !self.done.load(Ordering::Relaxed) {
            std::thread::sleep(Duration::from_millis(20));
            // A full disk is said when it happens, not when the robot stops.
            if !log_failed && let Some(error) = self.log.as_ref().and_then(|log| log.error()) {
                log_failed = true;
                self.out.note(&format!("log: {error}; nothing more is logged"));
            }
            let elapsed = self.started.elapsed();
            for event in self.watch.take_events() {
                self.out.game_event(elapsed.as_secs_f64(), &event);
            }
            for drain in &mut self.unused_links {
                drain();
            }
            if last_status.elapsed() >= self.status_every {
                last_status = Instant::now();
                self.out.status(&Status::gather(
                    elapsed.as_secs_f64(),
                    &self.counters,
                    &self.watch,
                    &self.team_counters,
                    &self.gc_counters,
                    self.accuracy.as_deref().and_then(Accuracy::snapshot),
                    self.rates.read(&self.probe.stats()),
                ));
            }
            let reason = if self.duration.is_some_and(|d| elapsed >= d) {
                Some("duration reached".to_owned())
            } else {
                self.counters.disconnected().map(|r| format!("platform disconnected: {r}"))
            };
            if let Some(reason) = reason {
                self.end.lock().unwrap_or_else(PoisonError::into_inner).get_or_insert(reason);
                self.stop.stop();
                return;
            }
        }
    }
}

/// The team configuration and the field, with what the platform needs that the team file
/// leaves at its defaults.
fn team_config_and_field(opts: &RobotOptions) -> Result<(TeamConfig, Field)> {
    let mut config = TeamConfig::resolve(&opts.team_config)
        .with_context(|| format!("team configuration `{}`", opts.team_config))?;
    if opts.platform == PlatformKind::Rcssservermj && config.motion == MotionModel::default() {
        // The team file's primitives assume a NAO unless it says otherwise: a T1's camera is
        // twice as high, its neck pitches further and it kicks from further away.
        config.motion = MotionModel::booster_t1();
    }
    if opts.platform == PlatformKind::Rcssservermj
        && config.fall_detector == FallDetectorConfig::default()
    {
        config.fall_detector = strata_rcssmj::controller::fall_detector();
    }
    let field = resolve_field(opts.field.as_deref().unwrap_or(match opts.platform {
        PlatformKind::Rcssservermj => "rcssservermj",
        PlatformKind::Sim | PlatformKind::Nao => "spl",
    }))?;
    if opts.platform == PlatformKind::Rcssservermj && config.behavior.set_play_distance == 0.0 {
        // The server's referee moves a robot within its centre circle's radius of the ball
        // during the other team's set play off the field.
        config.behavior.set_play_distance = field.dimensions().center_circle_diameter / 2.0 + 0.5;
    }
    if opts.platform == PlatformKind::Rcssservermj {
        // The server's referee gives the other team a free kick when a restart's taker touches
        // the ball again before anyone else has.
        config.behavior.no_second_touch = true;
    }
    if opts.platform == PlatformKind::Rcssservermj
        && config.behavior.dribble_distance == BehaviorConfig::default().dribble_distance
    {
        // The T1 dribbles the ball toward the goal faster than its kicks, which go 3 m in
        // a direction 20-60 degrees off, move it there (docs/rcssservermj.md).
        config.behavior.dribble_distance = field.dimensions().field_length;
    }
    Ok((config, field))
}

fn resolve_field(name: &str) -> Result<Field> {
    let field = if strata_spl::field::PRESETS.contains(&name) {
        Field::preset(name)
    } else {
        Field::load(name)
    };
    field.with_context(|| format!("field `{name}`"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_beam_is_a_pose_in_the_teams_frame() {
        // The left team attacks +x: its frame is the world's, and x goes into the own half.
        let left = beam_prior([3.0, -1.0, 30f64.to_radians()], 1.0).pose;
        assert_eq!((left.x, left.y), (-3.0, -1.0));
        assert!((left.theta - 30f64.to_radians()).abs() < 1e-12);
        // The server put the right team's `(beam 2 -1 30)` at (2, -1) heading 210 degrees in
        // the world: in a frame turned half a circle that is (-2, 1) heading 30 degrees.
        let right = beam_prior([2.0, -1.0, 30f64.to_radians()], -1.0).pose;
        assert_eq!((right.x, right.y), (-2.0, 1.0));
        assert!((right.theta - 30f64.to_radians()).abs() < 1e-12);
    }
}
