//! `strata robot`: one robot, one process, in real time — the full soccer robot (perception,
//! world modeling, actuation and the three layers of hybrid control) on the threaded host, over
//! one of its platforms:
//!
//! - `--platform sim`: the simulator server over TCP (`strata server`). Sensors and orders go
//!   through the server; so do team messages and the game state, unless `--net`.
//! - `--platform nao`: a NAO v6 through LoLA. Team messages and the game state come from the
//!   field's network (`--net` is implied).
//! - `--platform rcssservermj`: a Booster T1 in the RoboCup simulation league's MuJoCo server.
//!   The game state comes from the server's referee; the server carries no team messages of
//!   Strata's size, so teammates talk over UDP with `--net` or not at all.
//!
//! With `--net`, the GameController's control packets arrive on UDP (3838), return packets go
//! back to it (3939), and team messages are UDP broadcasts (10000 + team): the protocols of a
//! real SPL field, whatever provides the sensors. `docs/robot.md` has the commands.
//!
//! `--controller test` runs the simulator's trivial test controller instead of the soccer
//! robot (simulator server only).

use std::net::Ipv4Addr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, bail};
use clap::{Args, ValueEnum};
use serde::Serialize;
use strata_games::links::{self, Counted, LinkCounters, LinkStats, NetConfig, Prefetched};
use strata_games::logging::{RobotRunConfig, open_run_log};
use strata_games::matches::LayerRate;
use strata_log::{
    ConfigFormat, LogCompression, LogSummary, McapTap, McapTapOptions, RunInfo, WhenFull,
};
use strata_nao::{DEFAULT_SOCKET_PATH, LolaConfig, LolaPlatform};
use strata_rcssmj::compute::ComputeReport;
use strata_rcssmj::platform::{FALL_ONSET_TILT, FallRecord, RcssConfig, RcssPlatform, TruthSource};
use strata_rcssmj::referee::{TeamNumbers, penalty_spots};
use strata_robot::assembly::RobotModules;
use strata_robot::control::reactive::FallDetectorConfig;
use strata_robot::edge::RobotPlatform;
use strata_robot::geometry::{Pose, normalize_angle};
use strata_robot::platform::{
    ActuatorOrders, ExternalLink, MotionFeedback, Platform, PlatformError, PlatformInfo,
    ReceivedPacket, SensorFrame, SharedPlatform, TeamLink,
};
use strata_robot::world::{PosePrior, WorldState};
use strata_runtime::{
    Clock, Encoding, GraphBuilder, HostConfig, HostError, HostStats, MonotonicClock, Package, Tap,
    TapRecord, ThreadedHost, Time,
};
use strata_soccer::behaviors::{BehaviorConfig, Decision};
use strata_soccer::field::TeamField;
use strata_soccer::game::GameDirective;
use strata_soccer::primitives::MotionModel;
use strata_soccer::team::{SoccerRobotSpec, TeamConfig, add_soccer_robot, robot_world_config};
use strata_soccer::world_config::BALL;
use strata_spl::Field;
use strata_spl::gamecontroller::GameControlData;

use crate::sim_cmd;

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

/// What drives the robot.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ControllerKind {
    /// The full architecture: four modules, three layers of hybrid control.
    Soccer,
    /// The simulator's trivial test controller (walk to the ball, kick, look around).
    Test,
}

/// `strata robot`.
#[derive(Debug, Args)]
pub struct RobotArgs {
    /// Team number, as in GameController packets (the simulator's default teams: 10 and 20).
    #[arg(long)]
    pub team: u8,
    /// Player number (1 is the goalkeeper in the built-in formations).
    #[arg(long)]
    pub player: u8,
    #[arg(long, value_enum, default_value = "sim")]
    pub platform: PlatformKind,
    #[arg(long, value_enum, default_value = "soccer")]
    pub controller: ControllerKind,
    /// A built-in team (full, no-coordination, no-active-vision, always-ball, fixed-scan,
    /// entropy) or a team TOML file.
    #[arg(long, default_value = "full")]
    pub team_config: String,
    /// The simulator server (platform sim) [default: 127.0.0.1:7500], or rcssservermj's agent
    /// port (platform rcssservermj) [default: 127.0.0.1:60000].
    #[arg(long, value_name = "ADDR")]
    pub server: Option<String>,
    /// LoLA's socket (platform nao).
    #[arg(long, value_name = "PATH", default_value = DEFAULT_SOCKET_PATH)]
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
    /// Print JSON lines (start, game-state changes, status, final report) instead of text.
    #[arg(long)]
    pub json: bool,
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

/// Runs one robot until Ctrl-C, `--duration` or the end of its platform.
pub fn run(args: RobotArgs) -> Result<()> {
    validate(&args)?;
    if args.controller == ControllerKind::Test {
        return run_test_controller(&args);
    }
    // Reads links outside the host (before it starts, and links the robot does not use). It
    // starts before the host's own clock, so it reads later than that clock at any moment: the
    // simulator client maps its server's stamps with the smallest offset seen between a
    // reader's clock and the server's, and an earlier clock would corrupt that offset.
    let early_clock = MonotonicClock::start();
    let (config, field) = team_config_and_field(&args)?;
    let out = Output { json: args.json, name: format!("robot {}/{}", args.team, args.player) };

    // The body.
    let mut platform = open_platform(&args)?;
    let info = platform.info.clone();

    // The radio and the referee.
    let RobotLinks {
        team: team_link,
        game_controller: gc_link,
        team_counters,
        gc_counters,
        endpoints,
        unused: unused_sim_links,
    } = open_links(&args, platform.links.take(), early_clock)?;

    // Which way the team attacks, from the first control packet if one comes.
    let (gc_link, attack_sign, attack_source) =
        learn_attack_sign(gc_link, args.team, args.attack_sign, args.gc_wait, &early_clock);
    let team_field = Arc::new(TeamField::new(field, attack_sign));

    // A robot that beams itself knows where it starts, as the league's agents do.
    let initial_pose = match args.platform {
        PlatformKind::Rcssservermj => args.beam.map(|beam| beam_prior(beam, attack_sign)),
        _ => None,
    };
    // rcssservermj's referee moves robots to the side line without a word; a GameController
    // announces each penalty.
    let relocations = match args.platform {
        PlatformKind::Rcssservermj => penalty_spots(team_field.field.dimensions()),
        _ => Vec::new(),
    };
    // The robot: all four modules, all three layers.
    let mut graph = GraphBuilder::new();
    let spec = SoccerRobotSpec {
        // Module names: `t10/3/planning`...
        name: format!("t{}/{}", args.team, args.player),
        team_number: args.team,
        player: args.player,
        field: Arc::clone(&team_field),
        platform: RobotPlatform::Shared(Arc::clone(&platform.shared)),
        team_link,
        game_controller: Some(gc_link),
        half_duration: args.half_duration,
        initial_pose,
        relocations: relocations.clone(),
    };
    let modules = add_soccer_robot(&mut graph, spec, &config)
        .map_err(|e| anyhow::anyhow!("building robot {}/{}: {e}", args.team, args.player))?;
    let graph = graph.build().context("wiring the robot's modules")?;
    let watch = Arc::new(Watch::new(&modules.planning));
    let seed = args.seed.unwrap_or(100 * u64::from(args.team) + u64::from(args.player));
    let host_config = HostConfig {
        real_time_priority: (args.real_time_priority > 0).then_some(args.real_time_priority),
        ..HostConfig::with_seed(seed)
    };
    let log = match &args.log {
        Some(path) => {
            let run_config = RobotRunConfig {
                robot: format!("t{}/{}", args.team, args.player),
                team: config.clone(),
                world: robot_world_config(&team_field, initial_pose, &relocations),
                field: team_field.field.dimensions().clone(),
                attack_sign,
                platform: info.clone(),
            };
            Some(open_log(path, &args, seed, &run_config, &graph)?)
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

    out.start(&StartInfo {
        team: args.team,
        player: args.player,
        platform: args.platform,
        platform_name: info.name.clone(),
        source: platform.source.clone(),
        sensor_period_ms: info.sensor_period.as_secs_f64() * 1e3,
        can_walk: info.can_walk,
        controller: args.controller,
        team_config: config.name.clone(),
        coordination: config.coordination,
        game_controller: endpoints.game_controller,
        team_messages: endpoints.team,
        attack_sign,
        attack_source,
    });

    let running = host.start().context("starting the robot's module threads")?;
    if let Some(t1) = &platform.t1 {
        // The cycles while the robot was being set up are not its work.
        t1.lock().unwrap_or_else(PoisonError::into_inner).inner.restart_compute();
    }
    for (module, reason) in running.real_time_refusals() {
        out.note(&format!(
            "module {module} runs with the default scheduling policy: real-time priority {} \
             refused ({reason}); --real-time-priority 0 silences this",
            args.real_time_priority
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
        out: out.clone(),
        counters: Arc::clone(&platform.counters),
        team_counters: Arc::clone(&team_counters),
        gc_counters: Arc::clone(&gc_counters),
        accuracy: accuracy.clone(),
        log: log.clone(),
        duration: args.duration.map(|d| Duration::from_secs_f64(d.max(0.0))),
        status_every: Duration::from_secs_f64(args.status_interval.max(0.1)),
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
        sit_down(nao, &out);
    }
    if let Some(log) = &log {
        match log.finish() {
            Ok(summary) => out.note(&log_note(&summary)),
            Err(error) => out.note(&format!("log: {error}")),
        }
    }

    let planned_end = end.lock().unwrap_or_else(PoisonError::into_inner).clone();
    conclude(
        &args,
        result,
        planned_end,
        Ran { started, platform: &platform, watch: &watch, modules: &modules, accuracy, out: &out },
        (team_counters.snapshot(), gc_counters.snapshot()),
    )
}

/// Creates the robot's log and writes what a reader needs besides the packages: the run (seed,
/// command line, the configuration its modules are rebuilt from) and the graph.
fn open_log(
    path: &std::path::Path,
    args: &RobotArgs,
    seed: u64,
    config: &RobotRunConfig,
    graph: &strata_runtime::Graph,
) -> Result<Arc<McapTap>> {
    let options = McapTapOptions {
        // A real-time host: a module never waits for the disk.
        when_full: WhenFull::Drop,
        compression: args.log_compression,
        encoding: args.log_encoding,
        // A robot's run cannot be played again: what it logged must survive a power cut.
        sync_chunks: !args.log_no_sync,
        max_file_size: args.log_max_size.map(|mb| mb.saturating_mul(1_000_000)),
        ..McapTapOptions::default()
    };
    let text =
        serde_json::to_string_pretty(config).context("serializing the robot's configuration")?;
    let run = RunInfo::current(seed).with_config(ConfigFormat::Json, text);
    open_run_log(path, options, &run, &graph.describe(), [config.robot.clone()])
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

fn validate(args: &RobotArgs) -> Result<()> {
    if args.player == 0 {
        bail!("--player must be 1 or more");
    }
    if !(args.half_duration.is_finite() && args.half_duration > 0.0) {
        bail!("--half-duration must be > 0, got {}", args.half_duration);
    }
    if args.duration.is_some_and(|d| !(d.is_finite() && d >= 0.0)) {
        bail!("--duration must be a number of seconds >= 0");
    }
    if !(args.gc_wait.is_finite() && args.gc_wait >= 0.0) {
        bail!("--gc-wait must be >= 0, got {}", args.gc_wait);
    }
    let net_options = [
        ("--interface", args.interface.is_some()),
        ("--broadcast", args.broadcast.is_some()),
        ("--gc-port", args.gc_port.is_some()),
        ("--gc-return-port", args.gc_return_port.is_some()),
        ("--team-port", args.team_port.is_some()),
    ];
    match args.platform {
        PlatformKind::Sim => {
            if let Some((option, _)) = net_options.iter().find(|(_, given)| *given)
                && !args.net
            {
                bail!("{option} configures the UDP links: add --net");
            }
            if args.team_udp {
                bail!(
                    "--team-udp is for --platform rcssservermj (the simulator server carries \
                       team messages; --net puts everything on UDP)"
                );
            }
        }
        PlatformKind::Rcssservermj => {
            if args.controller == ControllerKind::Test {
                bail!("--controller test runs against the simulator server only");
            }
            for (option, given) in net_options {
                let team_option = matches!(option, "--interface" | "--broadcast" | "--team-port");
                if given && !args.net && !(team_option && args.team_udp) {
                    bail!(
                        "{option} configures the UDP links: add --net{}",
                        if team_option { " (or --team-udp)" } else { "" }
                    );
                }
            }
        }
        PlatformKind::Nao => {
            if args.team_udp {
                bail!("--team-udp is for --platform rcssservermj (a NAO has everything on UDP)");
            }
            if args.server.is_some() {
                bail!("--server is for --platform sim; a NAO reads its sensors through LoLA");
            }
            if args.controller == ControllerKind::Test {
                bail!("--controller test runs against the simulator server only");
            }
        }
    }
    if args.controller == ControllerKind::Test && args.log.is_some() {
        bail!("--log records the modules of the full architecture: not with --controller test");
    }
    if args.platform != PlatformKind::Nao && args.lola_config.is_some() {
        bail!("--lola-config is for --platform nao");
    }
    if args.platform != PlatformKind::Rcssservermj
        && (args.rcss_config.is_some() || args.beam.is_some() || args.team_name.is_some())
    {
        bail!("--rcss-config, --beam and --team-name are for --platform rcssservermj");
    }
    if args.controller == ControllerKind::Test && args.net {
        bail!(
            "--controller test reads the game state from the simulator server; run it without --net"
        );
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
    out: &'a Output,
}

/// Prints the final report and says how the run ended: an error for a failed module or a
/// server lost mid-game.
fn conclude(
    args: &RobotArgs,
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
        args,
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
            args.log
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
    out: Output,
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
fn team_config_and_field(args: &RobotArgs) -> Result<(TeamConfig, Field)> {
    let mut config = TeamConfig::resolve(&args.team_config)
        .with_context(|| format!("team configuration `{}`", args.team_config))?;
    if args.platform == PlatformKind::Rcssservermj && config.motion == MotionModel::default() {
        // The team file's primitives assume a NAO unless it says otherwise: a T1's camera is
        // twice as high, its neck pitches further and it kicks from further away.
        config.motion = MotionModel::booster_t1();
    }
    if args.platform == PlatformKind::Rcssservermj
        && config.fall_detector == FallDetectorConfig::default()
    {
        config.fall_detector = strata_rcssmj::controller::fall_detector();
    }
    let field = resolve_field(args.field.as_deref().unwrap_or(match args.platform {
        PlatformKind::Rcssservermj => "rcssservermj",
        PlatformKind::Sim | PlatformKind::Nao => "spl",
    }))?;
    if args.platform == PlatformKind::Rcssservermj && config.behavior.set_play_distance == 0.0 {
        // The server's referee moves a robot within its centre circle's radius of the ball
        // during the other team's set play off the field.
        config.behavior.set_play_distance = field.dimensions().center_circle_diameter / 2.0 + 0.5;
    }
    if args.platform == PlatformKind::Rcssservermj {
        // The server's referee gives the other team a free kick when a restart's taker touches
        // the ball again before anyone else has.
        config.behavior.no_second_touch = true;
    }
    if args.platform == PlatformKind::Rcssservermj
        && config.behavior.dribble_distance == BehaviorConfig::default().dribble_distance
    {
        // The T1 dribbles the ball toward the goal faster than its kicks, which go 3 m in
        // a direction 20-60 degrees off, move it there (docs/rcssservermj.md).
        config.behavior.dribble_distance = field.dimensions().field_length;
    }
    Ok((config, field))
}

/// A robot's links and what the start line and the report say of them.
struct RobotLinks {
    team: Option<Box<dyn TeamLink>>,
    game_controller: Box<dyn ExternalLink>,
    team_counters: Arc<LinkCounters>,
    gc_counters: Arc<LinkCounters>,
    endpoints: Endpoints,
    /// Links the platform carries that the robot does not use: drained now and then so they
    /// do not pile up.
    unused: Vec<Box<dyn FnMut() + Send>>,
}

/// The team and GameController links: UDP on a field (`--net`, always on a NAO), or the ones
/// the platform carries (with `--team-udp`, the team's over UDP).
fn open_links(
    args: &RobotArgs,
    platform_links: Option<PlatformLinks>,
    early_clock: MonotonicClock,
) -> Result<RobotLinks> {
    let net = args.net || args.platform == PlatformKind::Nao;
    let mut unused_sim_links: Vec<Box<dyn FnMut() + Send>> = Vec::new();
    let (team, game_controller, team_counters, gc_counters, endpoints) = if net {
        let net_config = net_config(args)?;
        let (team, gc) = net_config.bind().with_context(|| {
            format!(
                "binding UDP ports {} (GameController) and {} (team)",
                net_config.gc_port, net_config.team_port
            )
        })?;
        let endpoints = Endpoints {
            game_controller: format!(
                "UDP :{} (return packets to the sender's :{})",
                net_config.gc_port, net_config.gc_return_port
            ),
            team: format!(
                "UDP :{} -> {}:{}",
                net_config.team_port, net_config.broadcast, net_config.team_port
            ),
        };
        let (team_counters, gc_counters) = (team.counters(), gc.counters());
        if let Some(links) = platform_links {
            // The server still forwards its referee's packets and teammates' messages; drain
            // them so they do not pile up in the client.
            let PlatformLinks { mut team_link, mut game_controller, .. } = links;
            let clock = early_clock;
            unused_sim_links.push(Box::new(move || {
                if let Some(team_link) = &mut team_link {
                    let _ = team_link.receive(clock.now());
                }
                let _ = game_controller.receive(clock.now());
            }));
        }
        let team: Box<dyn TeamLink> = Box::new(team);
        let gc: Box<dyn ExternalLink> = Box::new(gc);
        (Some(team), gc, team_counters, gc_counters, endpoints)
    } else {
        let Some(PlatformLinks { team_link, game_controller, label }) = platform_links else {
            bail!("without --net the simulator server must carry team messages and game state");
        };
        let gc_counters = Arc::<LinkCounters>::default();
        let (team, team_counters, team_label): (Option<Box<dyn TeamLink>>, _, _) = if args.team_udp
        {
            let net_config = net_config(args)?;
            let udp = links::UdpTeamLink::bind(net_config.team_port, net_config.broadcast)
                .with_context(|| format!("binding UDP port {} (team)", net_config.team_port))?;
            let counters = udp.counters();
            let label = format!(
                "UDP :{} -> {}:{}",
                net_config.team_port, net_config.broadcast, net_config.team_port
            );
            (Some(Box::new(udp)), counters, label)
        } else {
            let counters = Arc::<LinkCounters>::default();
            let link = team_link.map(|link| {
                Box::new(Counted::new(link, Arc::clone(&counters))) as Box<dyn TeamLink>
            });
            let label = match link {
                Some(_) => label.to_owned(),
                None => "none (the platform carries no team messages; --team-udp or --net \
                             for UDP)"
                    .to_owned(),
            };
            (link, counters, label)
        };
        let gc: Box<dyn ExternalLink> =
            Box::new(Counted::new(game_controller, Arc::clone(&gc_counters)));
        let endpoints = Endpoints { game_controller: label.to_owned(), team: team_label };
        (team, gc, team_counters, gc_counters, endpoints)
    };
    Ok(RobotLinks {
        team,
        game_controller,
        team_counters,
        gc_counters,
        endpoints,
        unused: unused_sim_links,
    })
}

fn net_config(args: &RobotArgs) -> Result<NetConfig> {
    let mut config = NetConfig::field(args.team);
    if let Some(interface) = &args.interface {
        config.broadcast = links::directed_broadcast(interface).map_err(anyhow::Error::msg)?;
    }
    if let Some(broadcast) = args.broadcast {
        config.broadcast = broadcast;
    }
    if let Some(port) = args.gc_port {
        config.gc_port = port;
    }
    if let Some(port) = args.gc_return_port {
        config.gc_return_port = port;
    }
    if let Some(port) = args.team_port {
        config.team_port = port;
    }
    Ok(config)
}

/// rcssservermj's default agent port.
const RCSS_DEFAULT_ADDR: &str = "127.0.0.1:60000";

fn rcss_team_name(args: &RobotArgs) -> String {
    args.team_name.clone().unwrap_or_else(|| format!("Strata{}", args.team))
}

fn resolve_field(name: &str) -> Result<Field> {
    let field = if strata_spl::field::PRESETS.contains(&name) {
        Field::preset(name)
    } else {
        Field::load(name)
    };
    field.with_context(|| format!("field `{name}`"))
}

/// The simulator's test controller, through the simulator server.
fn run_test_controller(args: &RobotArgs) -> Result<()> {
    if args.json {
        bail!("--json is not available with --controller test");
    }
    sim_cmd::run_robot_test_controller(sim_cmd::RobotArgs {
        server: args.server.clone().unwrap_or_else(|| sim_cmd::DEFAULT_ADDR.to_owned()),
        team: args.team,
        player: args.player,
        duration: args.duration,
        status_interval: args.status_interval,
    })
}

// ---------------------------------------------------------------------------------------------
// The platform, observed.

/// What the platform delivered.
#[derive(Debug, Default)]
struct PlatformCounters {
    sensor_frames: AtomicU64,
    camera_frames: AtomicU64,
    detections: AtomicU64,
    errors: AtomicU64,
    disconnected: Mutex<Option<String>>,
}

impl PlatformCounters {
    fn disconnected(&self) -> Option<String> {
        self.disconnected.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }

    fn note<T>(&self, result: &Result<T, PlatformError>) {
        match result {
            Ok(_) => {}
            Err(PlatformError::Disconnected(reason)) => {
                self.errors.fetch_add(1, Ordering::Relaxed);
                self.disconnected
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .get_or_insert_with(|| reason.clone());
            }
            Err(_) => {
                self.errors.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

/// A platform whose traffic is counted for the robot's report.
struct Observed<P> {
    inner: P,
    counters: Arc<PlatformCounters>,
}

impl<P: Platform> Platform for Observed<P> {
    fn info(&self) -> PlatformInfo {
        self.inner.info()
    }

    fn read_sensors(&mut self, now: Time) -> Result<Option<SensorFrame>, PlatformError> {
        let result = self.inner.read_sensors(now);
        self.counters.note(&result);
        if let Ok(Some(frame)) = &result {
            self.counters.sensor_frames.fetch_add(1, Ordering::Relaxed);
            if let Some(camera) = &frame.camera {
                self.counters.camera_frames.fetch_add(1, Ordering::Relaxed);
                self.counters
                    .detections
                    .fetch_add(camera.detections.len() as u64, Ordering::Relaxed);
            }
        }
        result
    }

    fn read_motion(&mut self, now: Time) -> Result<MotionFeedback, PlatformError> {
        let result = self.inner.read_motion(now);
        self.counters.note(&result);
        result
    }

    fn write(&mut self, now: Time, orders: &ActuatorOrders) -> Result<(), PlatformError> {
        let result = self.inner.write(now, orders);
        // An order the body cannot execute (a NAO asked to walk) is the reactive layer's
        // business, not a platform failure.
        if !matches!(result, Err(PlatformError::Unsupported(_))) {
            self.counters.note(&result);
        }
        result
    }
}

/// The team and game-controller links a platform carries itself.
struct PlatformLinks {
    team_link: Option<Box<dyn TeamLink>>,
    game_controller: Box<dyn ExternalLink>,
    /// Where the links lead, for the start line.
    label: &'static str,
}

struct OpenPlatform {
    shared: SharedPlatform,
    info: PlatformInfo,
    counters: Arc<PlatformCounters>,
    /// Where the sensors come from, for the start line.
    source: String,
    links: Option<PlatformLinks>,
    nao: Option<Arc<Mutex<Observed<LolaPlatform>>>>,
    /// Where the robot really is, on platforms that know it (for the accuracy report only).
    truth: Option<TruthSource>,
    t1: Option<Arc<Mutex<Observed<RcssPlatform>>>>,
}

fn open_platform(args: &RobotArgs) -> Result<OpenPlatform> {
    let counters = Arc::<PlatformCounters>::default();
    match args.platform {
        PlatformKind::Sim => {
            let server = args.server.clone().unwrap_or_else(|| sim_cmd::DEFAULT_ADDR.to_owned());
            let robot = strata_sim::net::connect(
                server.as_str(),
                args.team,
                args.player,
                Duration::from_secs(5),
            )
            .with_context(|| format!("connecting to the simulator server at {server}"))?;
            let info = robot.welcome.info.clone();
            let shared: SharedPlatform = Arc::new(Mutex::new(Observed {
                inner: robot.platform,
                counters: Arc::clone(&counters),
            }));
            Ok(OpenPlatform {
                shared,
                info,
                counters,
                source: format!("simulator server {server}"),
                links: Some(PlatformLinks {
                    team_link: Some(Box::new(robot.team_link)),
                    game_controller: Box::new(robot.game_controller),
                    label: "simulator server",
                }),
                nao: None,
                truth: None,
                t1: None,
            })
        }
        PlatformKind::Nao => {
            let config = match &args.lola_config {
                Some(path) => {
                    let text = std::fs::read_to_string(path)
                        .with_context(|| format!("reading {}", path.display()))?;
                    toml::from_str::<LolaConfig>(&text)
                        .with_context(|| format!("LoLA configuration {}", path.display()))?
                }
                None => LolaConfig::default(),
            };
            let lola = LolaPlatform::connect(&args.socket, config)
                .with_context(|| format!("connecting to LoLA at {}", args.socket.display()))?;
            let info = lola.info();
            let nao =
                Arc::new(Mutex::new(Observed { inner: lola, counters: Arc::clone(&counters) }));
            let shared: SharedPlatform = nao.clone();
            Ok(OpenPlatform {
                shared,
                info,
                counters,
                source: format!("LoLA {}", args.socket.display()),
                links: None,
                nao: Some(nao),
                truth: None,
                t1: None,
            })
        }
        PlatformKind::Rcssservermj => {
            let mut config = match &args.rcss_config {
                Some(path) => {
                    let text = std::fs::read_to_string(path)
                        .with_context(|| format!("reading {}", path.display()))?;
                    toml::from_str::<RcssConfig>(&text)
                        .with_context(|| format!("rcssservermj configuration {}", path.display()))?
                }
                None => RcssConfig::default(),
            };
            if args.beam.is_some() {
                config.beam = args.beam;
            }
            config.camera_seed = args
                .seed
                .unwrap_or(100 * u64::from(args.team) + u64::from(args.player))
                .wrapping_add(1);
            let server = args.server.clone().unwrap_or_else(|| RCSS_DEFAULT_ADDR.to_owned());
            let team_name = rcss_team_name(args);
            let t1 = RcssPlatform::connect(&server, &team_name, args.player, config)
                .with_context(|| format!("connecting a T1 to rcssservermj at {server}"))?;
            let info = t1.info();
            let referee = t1.referee_link(TeamNumbers::new(args.team));
            let truth = t1.truth_source();
            let t1 = Arc::new(Mutex::new(Observed { inner: t1, counters: Arc::clone(&counters) }));
            let shared: SharedPlatform = t1.clone();
            Ok(OpenPlatform {
                shared,
                info,
                counters,
                source: format!("rcssservermj {server} as {team_name} #{}", args.player),
                links: Some(PlatformLinks {
                    team_link: None,
                    game_controller: Box::new(referee),
                    label: "rcssservermj's referee",
                }),
                nao: None,
                truth: Some(truth),
                t1: Some(t1),
            })
        }
    }
}

/// Ends a NAO's run sitting, motors soft: a robot left standing without commands falls.
fn sit_down(nao: &Arc<Mutex<Observed<LolaPlatform>>>, out: &Output) {
    let lock = || nao.lock().unwrap_or_else(PoisonError::into_inner);
    // Bound first: a guard in the `match` scrutinee would live through the arms and the
    // `busy` polls below would deadlock on it.
    let sitting = lock().inner.sit_down();
    match sitting {
        Ok(expected) => {
            let deadline = Instant::now() + expected + Duration::from_secs(5);
            while lock().inner.busy() && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(20));
            }
            // Seated, the motors go soft; a few LoLA cycles carry that out before we exit.
            lock().inner.relax();
            std::thread::sleep(Duration::from_millis(60));
        }
        Err(error) => out.note(&format!("could not sit down: {error}")),
    }
}

/// Reads the GameController link for up to `wait` seconds for a control packet of this team;
/// every packet read is handed to the robot afterwards.
fn learn_attack_sign(
    mut link: Box<dyn ExternalLink>,
    team: u8,
    given: Option<f64>,
    wait: f64,
    clock: &MonotonicClock,
) -> (Box<dyn ExternalLink>, f64, String) {
    if let Some(sign) = given {
        return (link, sign, "--attack-sign".to_owned());
    }
    let deadline = Instant::now() + Duration::from_secs_f64(wait);
    let mut read: Vec<ReceivedPacket> = Vec::new();
    let mut found = None;
    loop {
        if let Ok(packets) = link.receive(clock.now()) {
            found = packets.iter().filter_map(|p| GameControlData::decode(&p.bytes).ok()).find_map(
                |data| links::attack_sign(&data, team).map(|sign| (sign, data.first_half)),
            );
            read.extend(packets);
        }
        if found.is_some() || Instant::now() >= deadline {
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let link: Box<dyn ExternalLink> =
        if read.is_empty() { link } else { Box::new(Prefetched::new(read, link)) };
    match found {
        Some((sign, first_half)) => (
            link,
            sign,
            format!("GameController ({} half)", if first_half { "first" } else { "second" }),
        ),
        None => (link, 1.0, "default: no GameController packet for this team yet".to_owned()),
    }
}

// ---------------------------------------------------------------------------------------------
// Watching the planning layer's decisions.

/// A change of the game as the robot sees it.
#[derive(Clone, Debug, PartialEq, Serialize)]
struct GameEvent {
    state: String,
    penalized: bool,
    first_half: bool,
    kicking: String,
    score: [u8; 2],
}

impl GameEvent {
    fn of(directive: &GameDirective) -> GameEvent {
        GameEvent {
            state: format!("{:?}", directive.state),
            penalized: directive.penalized,
            first_half: directive.first_half,
            kicking: format!("{:?}", directive.kicking),
            score: directive.score,
        }
    }
}

/// Sees every package of the robot and keeps what the reports need from the planning layer.
/// Runs on the planning thread: it only copies under a short lock.
struct Watch {
    planning: String,
    state: Mutex<WatchState>,
}

#[derive(Default)]
struct WatchState {
    latest: Option<Decision>,
    events: Vec<GameEvent>,
    last_event: Option<GameEvent>,
    /// Every distinct game state seen, in order.
    history: Vec<String>,
}

impl Watch {
    fn new(planning: &str) -> Watch {
        Watch { planning: planning.to_owned(), state: Mutex::default() }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, WatchState> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn take_events(&self) -> Vec<GameEvent> {
        std::mem::take(&mut self.lock().events)
    }

    fn latest(&self) -> Option<Decision> {
        self.lock().latest.clone()
    }
}

impl Tap for Watch {
    fn package(&self, record: &TapRecord<'_>) {
        if record.sent_on.output != "decision" || record.sent_on.module_name != self.planning {
            return;
        }
        let Some(package) = record.package.as_any().downcast_ref::<Package<Decision>>() else {
            return;
        };
        let decision = &package.value;
        let mut state = self.lock();
        // Before the first control packet the directive is a default, not the game's.
        if decision.directive.connected {
            let event = GameEvent::of(&decision.directive);
            if state.last_event.as_ref() != Some(&event) {
                if state.history.last() != Some(&event.state) {
                    state.history.push(event.state.clone());
                }
                state.last_event = Some(event.clone());
                state.events.push(event);
            }
        }
        state.latest = Some(decision.clone());
    }
}

// ---------------------------------------------------------------------------------------------
// Self-localization against the ground truth (platforms that have one).

/// How far the world model's pose is from where the robot really is.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
struct LocalizationAccuracy {
    /// World states compared.
    samples: u64,
    /// Position error, m.
    mean_error_m: f64,
    max_error_m: f64,
    last_error_m: f64,
    /// Heading error, degrees.
    mean_heading_error_deg: f64,
    /// Where the robot really was last (team frame: x towards the opponent goal), m.
    truth: [f64; 2],
    /// Where the world model put it.
    estimate: [f64; 2],
    /// Whether the world model said its pose was lost, last.
    #[serde(skip)]
    last_lost: bool,
    /// The world model's ball, last (team frame).
    #[serde(skip)]
    last_ball: Option<BallStatus>,
    /// Headings last, degrees (estimate, truth).
    #[serde(skip)]
    last_headings_deg: [f64; 2],
    /// The same after the pose first converged (first not lost after a landmark correction):
    /// the error of a robot that knows where it is, without the search before.
    converged: Option<ConvergedAccuracy>,
}

/// Position error over the world states since the pose first converged.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
struct ConvergedAccuracy {
    /// World states before the first converged one.
    after_samples: u64,
    samples: u64,
    /// Of these, how many said the pose was lost.
    lost_samples: u64,
    mean_error_m: f64,
    max_error_m: f64,
}

/// Compares each of the world module's states with the platform's ground truth.
struct Accuracy {
    world: String,
    truth: TruthSource,
    attack_sign: f64,
    state: Mutex<(LocalizationAccuracy, f64)>,
}

impl Accuracy {
    fn snapshot(&self) -> Option<LocalizationAccuracy> {
        let (accuracy, _) = *self.state.lock().unwrap_or_else(PoisonError::into_inner);
        (accuracy.samples > 0).then_some(accuracy)
    }
}

impl Tap for Accuracy {
    fn package(&self, record: &TapRecord<'_>) {
        if record.sent_on.output != "world_state" || record.sent_on.module_name != self.world {
            return;
        }
        let Some(package) = record.package.as_any().downcast_ref::<Package<WorldState>>() else {
            return;
        };
        let Some(truth) = self.truth.get() else { return };
        let estimate = &package.value.pose;
        let pose = estimate.pose;
        // The team frame is the server's world frame turned half a circle for a team that
        // attacks towards -x.
        let s = self.attack_sign;
        let (tx, ty) = (s * truth.position[0], s * truth.position[1]);
        let heading = if s < 0.0 { truth.heading + std::f64::consts::PI } else { truth.heading };
        let error = (pose.x - tx).hypot(pose.y - ty);
        let heading_error = normalize_angle(pose.theta - heading).abs().to_degrees();
        let mut state = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        let (accuracy, heading_sum) = &mut *state;
        accuracy.samples += 1;
        let n = accuracy.samples as f64;
        accuracy.mean_error_m += (error - accuracy.mean_error_m) / n;
        *heading_sum += heading_error;
        accuracy.mean_heading_error_deg = *heading_sum / n;
        accuracy.max_error_m = accuracy.max_error_m.max(error);
        accuracy.last_error_m = error;
        if accuracy.converged.is_none() && !estimate.lost && estimate.last_correction.is_some() {
            accuracy.converged =
                Some(ConvergedAccuracy { after_samples: n as u64 - 1, ..Default::default() });
        }
        if let Some(converged) = &mut accuracy.converged {
            converged.samples += 1;
            converged.lost_samples += u64::from(estimate.lost);
            let m = converged.samples as f64;
            converged.mean_error_m += (error - converged.mean_error_m) / m;
            converged.max_error_m = converged.max_error_m.max(error);
        }
        accuracy.truth = [tx, ty];
        accuracy.estimate = [pose.x, pose.y];
        accuracy.last_lost = estimate.lost;
        accuracy.last_ball = package.value.object(BALL).map(|b| BallStatus {
            known: b.known,
            confidence: b.confidence,
            estimate: b.known.then_some([b.field_position.x, b.field_position.y]),
        });
        accuracy.last_headings_deg =
            [pose.theta.to_degrees(), normalize_angle(heading).to_degrees()];
    }
}

// ---------------------------------------------------------------------------------------------
// Output.

struct Endpoints {
    game_controller: String,
    team: String,
}

#[derive(Debug, Serialize)]
struct StartInfo {
    team: u8,
    player: u8,
    platform: PlatformKind,
    platform_name: String,
    source: String,
    sensor_period_ms: f64,
    can_walk: bool,
    controller: ControllerKind,
    team_config: String,
    coordination: bool,
    game_controller: String,
    team_messages: String,
    attack_sign: f64,
    attack_source: String,
}

#[derive(Debug, Serialize)]
struct Status {
    t: f64,
    sensor_frames: u64,
    camera_frames: u64,
    game_state: Option<String>,
    penalized: bool,
    mission: Option<String>,
    role: Option<String>,
    teammates: usize,
    messages_sent: u64,
    messages_received: u64,
    gc_packets: u64,
    /// The teammates the planning layer counts on now (heard lately, standing, localized, not
    /// penalized): one missing from here is one whose role the others take over.
    available_teammates: Vec<u8>,
    /// The three layers of hybrid control since the previous status line: a program watching
    /// the robot sees its rates change while it runs, not only in the final report.
    layers: Vec<LayerNow>,
    /// The newest self-localization against the ground truth (platforms that have one).
    #[serde(skip_serializing_if = "Option::is_none")]
    pose: Option<PoseStatus>,
    /// The world model's ball (platforms with a ground truth): what goal-covering experiments
    /// compare with the server's ball.
    #[serde(skip_serializing_if = "Option::is_none")]
    ball: Option<BallStatus>,
}

/// One layer in a status line.
#[derive(Debug, Serialize)]
struct LayerNow {
    layer: String,
    /// Cycles since the robot started.
    cycles: u64,
    /// Cycles per second since the previous status line.
    hz: f64,
}

/// Turns the host's cumulative cycle counts into each layer's rate between status lines.
struct LayerMeter {
    /// (layer, module) of the three layers.
    layers: Vec<(String, String)>,
    /// The host's elapsed time and each layer's cycles at the previous reading.
    last: Option<(f64, Vec<u64>)>,
}

impl LayerMeter {
    fn new(layers: Vec<(String, String)>) -> LayerMeter {
        LayerMeter { layers, last: None }
    }

    fn read(&mut self, stats: &HostStats) -> Vec<LayerNow> {
        let cycles: Vec<u64> = self
            .layers
            .iter()
            .map(|(_, module)| stats.module(module).map_or(0, |m| m.cycles))
            .collect();
        let (since, before) = match &self.last {
            Some((t, before)) => (stats.elapsed_s - t, before.clone()),
            None => (stats.elapsed_s, vec![0; cycles.len()]),
        };
        let now = self
            .layers
            .iter()
            .zip(cycles.iter().zip(before))
            .map(|((layer, _), (&n, b))| LayerNow {
                layer: layer.clone(),
                cycles: n,
                hz: if since > 0.0 { n.saturating_sub(b) as f64 / since } else { 0.0 },
            })
            .collect();
        self.last = Some((stats.elapsed_s, cycles));
        now
    }
}

/// Whether the world model knows where the ball is, and where it puts it (team frame, m).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
struct BallStatus {
    known: bool,
    confidence: f64,
    /// `None` while the ball is not known.
    estimate: Option<[f64; 2]>,
}

/// Where the world model puts the robot and where it is, in the team frame, m.
#[derive(Debug, Serialize)]
struct PoseStatus {
    /// x, y (m) and heading (degrees).
    estimate: [f64; 3],
    truth: [f64; 3],
    error_m: f64,
    lost: bool,
}

impl Status {
    fn gather(
        t: f64,
        platform: &PlatformCounters,
        watch: &Watch,
        team: &LinkCounters,
        gc: &LinkCounters,
        accuracy: Option<LocalizationAccuracy>,
        layers: Vec<LayerNow>,
    ) -> Status {
        let decision = watch.latest();
        let connected = decision.as_ref().filter(|d| d.directive.connected);
        let planning = decision.as_ref().map(|d| d.stats.clone()).unwrap_or_default();
        Status {
            t,
            sensor_frames: platform.sensor_frames.load(Ordering::Relaxed),
            camera_frames: platform.camera_frames.load(Ordering::Relaxed),
            game_state: connected.map(|d| format!("{:?}", d.directive.state)),
            penalized: connected.is_some_and(|d| d.directive.penalized),
            mission: decision.as_ref().map(|d| d.assignment.mission.name().to_owned()),
            role: decision.as_ref().map(|d| d.assignment.role.name().to_owned()),
            teammates: decision.as_ref().map_or(0, |d| d.teammates.len()),
            messages_sent: team.snapshot().sent,
            messages_received: planning.received,
            gc_packets: gc.snapshot().received,
            available_teammates: decision.as_ref().map_or_else(Vec::new, |d| {
                d.teammates.iter().filter(|t| t.available).map(|t| t.player).collect()
            }),
            layers,
            pose: accuracy.map(|a| PoseStatus {
                estimate: [a.estimate[0], a.estimate[1], a.last_headings_deg[0]],
                truth: [a.truth[0], a.truth[1], a.last_headings_deg[1]],
                error_m: a.last_error_m,
                lost: a.last_lost,
            }),
            ball: accuracy.and_then(|a| a.last_ball),
        }
    }
}

/// Everything one run of a robot produced.
#[derive(Debug, Serialize)]
struct Report {
    team: u8,
    player: u8,
    platform: PlatformKind,
    wall_s: f64,
    ended: String,
    sensor_frames: u64,
    camera_frames: u64,
    detections: u64,
    platform_errors: u64,
    /// Every game state the robot followed, in order.
    game_states: Vec<String>,
    game: Option<GameEvent>,
    mission: Option<String>,
    role: Option<String>,
    planning: strata_robot::control::planning::PlanningStats,
    team_link: LinkStats,
    game_controller_link: LinkStats,
    /// The three layers of hybrid control (the paper's Table 6).
    layers: Vec<LayerRate>,
    /// Every module.
    host: HostStats,
    /// Self-localization against the platform's ground truth (rcssservermj only).
    #[serde(skip_serializing_if = "Option::is_none")]
    localization: Option<LocalizationAccuracy>,
    /// Falls in the server's time: the ground-truth onset and the protective-fall order
    /// (rcssservermj only).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    falls: Vec<FallRecord>,
    /// The server's time of every protective-fall order that no fall followed: false alarms
    /// (rcssservermj only; `strata_rcssmj::falls::FallLog::false_falls`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    false_falls: Vec<f64>,
    /// The robot's compute per server cycle (rcssservermj only).
    #[serde(skip_serializing_if = "Option::is_none")]
    compute: Option<Compute>,
}

/// The robot's compute per 20 ms server cycle: CPU time measured by the platform at each
/// cycle's boundary (`strata_rcssmj::compute`), and the modules' own wall times for comparison.
#[derive(Debug, Serialize)]
struct Compute {
    #[serde(flatten)]
    per_cycle: ComputeReport,
    /// Every module's measured compute (wall time of its cycles) summed over the run, per
    /// server cycle, us: the share of `process` the modules account for (wall time also counts
    /// waiting for a core).
    modules_wall_mean_us: f64,
}

impl Compute {
    fn new(per_cycle: ComputeReport, host: &HostStats) -> Compute {
        let total_us: f64 =
            host.modules.iter().map(|m| m.compute_time.mean_us * m.compute_time.count as f64).sum();
        let modules_wall_mean_us =
            if per_cycle.cycles > 0 { total_us / per_cycle.cycles as f64 } else { 0.0 };
        Compute { per_cycle, modules_wall_mean_us }
    }
}

impl Report {
    #[allow(clippy::too_many_arguments)]
    fn new(
        args: &RobotArgs,
        wall_s: f64,
        ended: String,
        platform: &PlatformCounters,
        watch: &Watch,
        team_link: LinkStats,
        game_controller_link: LinkStats,
        modules: &RobotModules,
        host: HostStats,
    ) -> Report {
        let state = watch.lock();
        let decision = state.latest.clone();
        Report {
            team: args.team,
            player: args.player,
            platform: args.platform,
            wall_s,
            ended,
            sensor_frames: platform.sensor_frames.load(Ordering::Relaxed),
            camera_frames: platform.camera_frames.load(Ordering::Relaxed),
            detections: platform.detections.load(Ordering::Relaxed),
            platform_errors: platform.errors.load(Ordering::Relaxed),
            game_states: state.history.clone(),
            game: state.last_event.clone(),
            mission: decision.as_ref().map(|d| d.assignment.mission.name().to_owned()),
            role: decision.as_ref().map(|d| d.assignment.role.name().to_owned()),
            planning: decision.map(|d| d.stats).unwrap_or_default(),
            team_link,
            game_controller_link,
            layers: modules
                .layers()
                .iter()
                .filter_map(|(layer, name)| {
                    host.module(name).map(|m| LayerRate {
                        layer: (*layer).to_owned(),
                        cycles: m.cycles,
                        min_hz: m.rate.min_hz,
                        mean_hz: m.rate.mean_hz,
                        max_hz: m.rate.max_hz,
                    })
                })
                .collect(),
            host,
            localization: None,
            falls: Vec::new(),
            false_falls: Vec::new(),
            compute: None,
        }
    }
}

/// Text for people, or JSON lines (`{"type": ...}`) for programs.
#[derive(Clone, Debug)]
struct Output {
    json: bool,
    name: String,
}

impl Output {
    fn json_line(&self, kind: &str, value: &impl Serialize) {
        // Our own types always serialize; a failure would be a bug, reported rather than
        // hidden.
        match serde_json::to_value(value) {
            Ok(serde_json::Value::Object(mut map)) => {
                map.insert("type".to_owned(), serde_json::Value::String(kind.to_owned()));
                println!("{}", serde_json::Value::Object(map));
            }
            Ok(other) => println!("{}", serde_json::json!({ "type": kind, "value": other })),
            Err(error) => eprintln!("{}: cannot serialize {kind}: {error}", self.name),
        }
    }

    fn start(&self, info: &StartInfo) {
        if self.json {
            return self.json_line("start", info);
        }
        println!(
            "{}: {} ({}, sensors every {:.0} ms{}), {} controller, team `{}`{}",
            self.name,
            info.platform_name,
            info.source,
            info.sensor_period_ms,
            if info.can_walk { "" } else { ", cannot walk" },
            match info.controller {
                ControllerKind::Soccer => "soccer",
                ControllerKind::Test => "test",
            },
            info.team_config,
            if info.coordination { "" } else { " (no team messages)" },
        );
        println!(
            "{}: GameController: {}; team messages: {}; attacks {}x ({})   (Ctrl-C stops)",
            self.name,
            info.game_controller,
            info.team_messages,
            if info.attack_sign > 0.0 { "+" } else { "-" },
            info.attack_source
        );
    }

    fn game_event(&self, t: f64, event: &GameEvent) {
        if self.json {
            #[derive(Serialize)]
            struct Line<'a> {
                t: f64,
                #[serde(flatten)]
                event: &'a GameEvent,
            }
            return self.json_line("game_state", &Line { t, event });
        }
        println!(
            "{}: t={t:7.1} s  game {}{}  ({} half, kick-off/set play: {}, score {}:{})",
            self.name,
            event.state,
            if event.penalized { " (penalized)" } else { "" },
            if event.first_half { "1st" } else { "2nd" },
            event.kicking.to_lowercase(),
            event.score[0],
            event.score[1],
        );
    }

    fn status(&self, status: &Status) {
        if self.json {
            return self.json_line("status", status);
        }
        println!(
            "{}: t={:7.1} s  frames {:6}  images {:5}  game {}{}  {} / {}  teammates {}  messages sent {} heard {}  gc packets {}",
            self.name,
            status.t,
            status.sensor_frames,
            status.camera_frames,
            status.game_state.as_deref().unwrap_or("(no GameController yet)"),
            if status.penalized { " (penalized)" } else { "" },
            status.mission.as_deref().unwrap_or("-"),
            status.role.as_deref().unwrap_or("-"),
            status.teammates,
            status.messages_sent,
            status.messages_received,
            status.gc_packets,
        );
    }

    fn note(&self, text: &str) {
        if self.json {
            return self.json_line("note", &serde_json::json!({ "text": text }));
        }
        println!("{}: {text}", self.name);
    }

    fn report(&self, report: &Report) {
        if self.json {
            return self.json_line("report", report);
        }
        println!(
            "{}: stopped after {:.1} s ({}): {} sensor frames, {} images, {} detections, {} platform errors",
            self.name,
            report.wall_s,
            report.ended,
            report.sensor_frames,
            report.camera_frames,
            report.detections,
            report.platform_errors
        );
        if let Some(l) = &report.localization {
            println!(
                "{}: self-localization against the ground truth: mean error {:.2} m (max {:.2}, last {:.2}), heading {:.1} degrees, over {} world states; last at ({:.2}, {:.2}), estimated ({:.2}, {:.2})",
                self.name,
                l.mean_error_m,
                l.max_error_m,
                l.last_error_m,
                l.mean_heading_error_deg,
                l.samples,
                l.truth[0],
                l.truth[1],
                l.estimate[0],
                l.estimate[1]
            );
            if let Some(c) = &l.converged {
                println!(
                    "{}: after the pose first converged ({} world states in): mean error {:.2} m (max {:.2}) over {} world states, {} of them lost",
                    self.name,
                    c.after_samples,
                    c.mean_error_m,
                    c.max_error_m,
                    c.samples,
                    c.lost_samples
                );
            }
        }
        for fall in &report.falls {
            match fall.latency {
                Some(latency) => println!(
                    "{}: fall at {:.2} s (server time): protective fall ordered {:.0} ms after the onset",
                    self.name,
                    fall.onset,
                    latency * 1e3
                ),
                None => println!(
                    "{}: tilt past {:.0} degrees at {:.2} s (server time): no protective fall ordered",
                    self.name,
                    FALL_ONSET_TILT.to_degrees(),
                    fall.onset
                ),
            }
            if let Some(upright) = fall.upright {
                println!(
                    "{}: standing again {:.2} s after the fall at {:.2} s",
                    self.name,
                    upright - fall.onset,
                    fall.onset
                );
            }
        }
        for t in &report.false_falls {
            println!(
                "{}: protective fall ordered at {t:.2} s (server time) with no fall",
                self.name
            );
        }
        if let Some(c) = &report.compute {
            let p = &c.per_cycle;
            println!(
                "{}: compute per {:.0} ms server cycle over {} cycles (CPU time, us): process p50 {:.0} p99 {:.0} max {:.0} ({:.1} % / {:.1} % / {:.1} % of the cycle), mean {:.0}; connection thread p50 {:.0} p99 {:.0}; walking policy p50 {:.0} p99 {:.0}; modules' wall time mean {:.0}",
                self.name,
                p.cycle_ms,
                p.cycles,
                p.process.p50_us,
                p.process.p99_us,
                p.process.max_us,
                100.0 * p.share_of_cycle.p50,
                100.0 * p.share_of_cycle.p99,
                100.0 * p.share_of_cycle.max,
                p.process.mean_us,
                p.connection.p50_us,
                p.connection.p99_us,
                p.policy.p50_us,
                p.policy.p99_us,
                c.modules_wall_mean_us,
            );
        }
        println!(
            "{}: game states followed: {}",
            self.name,
            if report.game_states.is_empty() {
                "none (no GameController packet)".to_owned()
            } else {
                report.game_states.join(" -> ")
            }
        );
        let p = &report.planning;
        println!(
            "{}: team messages: sent {} periodic + {} instant, heard {}, rejected {}, withheld {} (budget); link: {} sent (largest {} B), {} received, {} dropped, {} errors",
            self.name,
            p.sent_periodic,
            p.sent_instant,
            p.received,
            p.rejected,
            p.withheld,
            report.team_link.sent,
            report.team_link.largest_sent,
            report.team_link.received,
            report.team_link.rejected,
            report.team_link.errors,
        );
        println!(
            "{}: GameController: {} packets received, {} dropped, {} return packets sent",
            self.name,
            report.game_controller_link.received,
            report.game_controller_link.rejected,
            report.game_controller_link.sent,
        );
        println!(
            "\n{:<14} {:>8} {:>9} {:>9} {:>9}",
            "layer", "cycles", "min Hz", "mean Hz", "max Hz"
        );
        for layer in &report.layers {
            println!(
                "{:<14} {:>8} {:>9.2} {:>9.2} {:>9.2}",
                layer.layer, layer.cycles, layer.min_hz, layer.mean_hz, layer.max_hz
            );
        }
        println!("\n{}", report.host.table());
    }
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
