//! `strata match`: a complete simulated game.

use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::sync::{Arc, PoisonError};

use anyhow::{Context as _, Result, bail};
use clap::{ArgGroup, Args};
use indicatif::{ProgressBar, ProgressStyle};
use strata_games::logging::{LogSettings, MatchLog, parse_robots};
use strata_games::matches::{Match, MatchConfig, MatchReport};
use strata_games::physics::game::{GameConfig, PhysicsReport, RULES_HALF_TIME};
use strata_games::physics::{self, Engine};
use strata_games::scene::live::{self, SceneServer};
use strata_log::LogCompression;
use strata_runtime::Encoding;
use strata_sim::NoiseLevel;
use strata_soccer::team::TeamConfig;
use strata_view::{LiveTap, ViewServer};

#[derive(Debug, Args)]
#[command(group(ArgGroup::new("live").args(["view", "foxglove"]).multiple(true)))]
pub struct MatchArgs {
    /// Where the game is played: the built-in 2D simulator, or Booster T1s in rcssservermj
    /// (docs/rcssservermj.md; `scripts/setup-rcssservermj` installs it).
    #[arg(long, value_enum, default_value = "sim")]
    pub engine: Engine,
    /// Robots per team (7: the SPL Champions Cup; 4: the paper's games) [default: 7; 3 on
    /// rcssservermj].
    #[arg(long)]
    pub players: Option<u8>,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The home team: a built-in team (full, no-coordination, no-active-vision, always-ball,
    /// fixed-scan, entropy) or a team TOML file.
    #[arg(long, default_value = "full")]
    pub home: String,
    /// The away team, as --home.
    #[arg(long, default_value = "full")]
    pub away: String,
    /// Stop after this many simulated seconds (default: the whole game; on rcssservermj, play
    /// seconds).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Length of a half, simulated seconds [default: 600; on rcssservermj 300, its rule
    /// book's half, and at most that].
    #[arg(long)]
    pub half: Option<f64>,
    /// Sensor and actuation noise: none, default or high.
    #[arg(long, default_value = "default")]
    pub noise: String,
    /// Field preset (spl, paper2010) or a field TOML file.
    #[arg(long, default_value = "spl")]
    pub field: String,
    /// Team-message loss in [0, 1].
    #[arg(long, default_value_t = 0.0)]
    pub packet_loss: f64,
    /// The referee sends every state at once, without Standby and without the referee's
    /// whistle and gesture (GameController3's `--no-delay`). By default it keeps
    /// GameController3's delays and the robots act on the signals (docs/spl-protocols.md).
    #[arg(long)]
    pub no_delay: bool,
    /// Play on the threaded host, paced to real time.
    #[arg(long)]
    pub realtime: bool,
    /// Print the report as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Record the match into this MCAP file: every package of the chosen robots, ground truth,
    /// game state and behavior paths, with the configuration replay needs (docs/logging.md).
    /// On rcssservermj each robot process writes its own log beside it:
    /// `STEM-hHALF-home|away-PLAYER.mcap`.
    #[arg(long, value_name = "FILE.mcap")]
    pub log: Option<PathBuf>,
    /// The robots whose packages are logged, e.g. `home/1,away/2` (default: all).
    #[arg(long, value_name = "ROBOTS", requires = "log")]
    pub log_robots: Option<String>,
    /// World-state packages logged per second and robot (0: every one, needed to replay the
    /// modules that read the world state, and the world model's own outputs).
    #[arg(long, value_name = "HZ", default_value_t = 0.0, requires = "log")]
    pub log_world_hz: f64,
    /// How the log's chunks are compressed: zstd (the smallest files), lz4 (a fifth larger,
    /// about as fast) or none (least work for the writer, twice the size; docs/logging.md,
    /// "Figures").
    #[arg(long, value_name = "zstd|lz4|none", default_value = "zstd", requires = "log")]
    pub log_compression: LogCompression,
    /// How package values are encoded: cdr (compact, with OMG IDL schemas Foxglove reads),
    /// msgpack or json (self-describing, larger and slower to write).
    #[arg(long, value_name = "cdr|msgpack|json", default_value = "cdr", requires = "log")]
    pub log_encoding: Encoding,
    /// Leave out the scene channels Foxglove's 3D panel draws (`scene/...`, docs/foxglove.md).
    #[arg(long, requires = "log")]
    pub log_no_scene: bool,
    /// Show the match live in the web viewer (prints its address; docs/viewer.md).
    #[arg(long)]
    pub view: bool,
    /// The viewer's port on 127.0.0.1 (0: any free port).
    #[arg(long, default_value_t = 8080, requires = "view")]
    pub port: u16,
    /// With --view or --foxglove: simulated seconds per real second (0: as fast as
    /// possible) [default: 1 with --view; with --foxglove alone, as fast as possible].
    #[arg(long, requires = "live")]
    pub speed: Option<f64>,
    /// Serve the match's scene live over Foxglove's WebSocket protocol on this address, for
    /// the Foxglove app's 3D panel (docs/foxglove.md, "Live") [default: 127.0.0.1:8765].
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = live::DEFAULT_ADDR)]
    pub foxglove: Option<String>,
    /// With --foxglove: start the match only once a client subscribed to a channel.
    #[arg(long, requires = "foxglove")]
    pub foxglove_wait: bool,
}

impl MatchArgs {
    /// Every option at its default.
    pub fn defaults() -> MatchArgs {
        #[derive(clap::Parser)]
        struct Defaults {
            #[command(flatten)]
            args: MatchArgs,
        }
        <Defaults as clap::Parser>::parse_from(["strata"]).args
    }
}

pub fn parse_noise(name: &str) -> Result<NoiseLevel> {
    Ok(match name {
        "none" => NoiseLevel::None,
        "default" => NoiseLevel::Default,
        "high" => NoiseLevel::High,
        other => bail!("unknown noise preset `{other}` (none, default, high)"),
    })
}

pub fn config(args: &MatchArgs) -> Result<MatchConfig> {
    Ok(MatchConfig {
        players: args.players.unwrap_or(7),
        seed: args.seed,
        home: TeamConfig::resolve(&args.home)?,
        away: TeamConfig::resolve(&args.away)?,
        half_duration: args.half.unwrap_or(600.0),
        limit: args.duration,
        noise: parse_noise(&args.noise)?,
        field: args.field.clone(),
        packet_loss: args.packet_loss,
        realtime: args.realtime,
        sim: None,
        no_delay: args.no_delay,
    })
}

pub fn run(args: MatchArgs) -> Result<()> {
    if args.engine == Engine::Rcssservermj {
        return run_physics(&args);
    }
    let config = config(&args)?;
    let foxglove_addr = args.foxglove.as_deref().map(live::parse_addr).transpose()?;
    let players = config.players;
    let mut game = Match::new(config)?;
    let log = match &args.log {
        Some(path) => {
            let settings = LogSettings {
                path: path.clone(),
                robots: match &args.log_robots {
                    Some(text) => parse_robots(text, players)?,
                    None => Vec::new(),
                },
                world_state_hz: (args.log_world_hz > 0.0).then_some(args.log_world_hz),
                compression: args.log_compression,
                encoding: args.log_encoding,
                scene: !args.log_no_scene,
            };
            Some(MatchLog::attach(&mut game, &settings)?)
        }
        None => None,
    };
    // One tap paces a lockstep match: the viewer's when there is one.
    let speed = args.speed.or(args.view.then_some(1.0)).filter(|s| *s > 0.0 && !args.realtime);
    let viewer = if args.view {
        let (data, tap) = LiveTap::for_match(&game, speed);
        game.add_tap(Arc::new(tap));
        let server = ViewServer::start(Arc::clone(&data), args.port)
            .with_context(|| format!("serving the viewer on 127.0.0.1:{}", args.port))?;
        eprintln!("viewer: {}", server.url());
        Some((data, server))
    } else {
        None
    };
    let mut foxglove = match foxglove_addr {
        Some(addr) => {
            let server = SceneServer::attach(&mut game, addr, speed.filter(|_| !args.view))?;
            eprintln!("Foxglove: {} (Open connection -> Foxglove WebSocket)", server.url());
            if args.foxglove_wait {
                eprintln!("waiting for a Foxglove client to subscribe (Ctrl-C stops)");
                wait_for_subscriber(&server)?;
            }
            Some(server)
        }
        None => None,
    };
    let bar = if args.json { ProgressBar::hidden() } else { ProgressBar::new(1000) };
    bar.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:40} {percent:>3}% {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let report = game.play(&mut |fraction, score| {
        bar.set_position((fraction * 1000.0) as u64);
        bar.set_message(score.to_owned());
    })?;
    bar.finish_and_clear();
    if let Some(server) = &mut foxglove {
        server.finish();
        if server.dropped() > 0 {
            eprintln!(
                "Foxglove: {} packages dropped (the server's worker fell behind)",
                server.dropped()
            );
        }
    }
    // After the last simulated second or Ctrl-C: the lockstep loop stopped at the interrupt
    // flag, so the log is closed properly either way.
    if let Some(log) = &log {
        let summary = log.finish()?;
        eprintln!(
            "log: {} ({} messages, {} dropped, {:.1} MB)",
            log.path().display(),
            summary.messages,
            summary.dropped,
            summary.bytes as f64 / 1e6
        );
    }
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print_report(&report);
    }
    if let Some((data, server)) = viewer {
        data.write().unwrap_or_else(PoisonError::into_inner).set_complete();
        let interrupted = strata_runtime::signal::interrupt_flag()
            .map_err(anyhow::Error::msg)?
            .load(Ordering::Relaxed);
        if !interrupted {
            eprintln!("the match is over; the viewer stays at {} until Ctrl-C", server.url());
            crate::view_cmd::wait_for_interrupt()?;
        }
    }
    Ok(())
}

/// Blocks until a Foxglove client subscribed, or Ctrl-C.
fn wait_for_subscriber(server: &SceneServer) -> Result<()> {
    let interrupted = strata_runtime::signal::interrupt_flag().map_err(anyhow::Error::msg)?;
    while !server.wait_for_subscriber(std::time::Duration::from_millis(200)) {
        if interrupted.load(Ordering::Relaxed) {
            bail!("interrupted while waiting for a Foxglove client");
        }
    }
    Ok(())
}

/// A game of T1s in rcssservermj (`strata_games::physics::game`).
fn run_physics(args: &MatchArgs) -> Result<()> {
    let defaults = MatchArgs::defaults();
    let not_here = [
        ("--noise", args.noise != defaults.noise),
        ("--field", args.field != defaults.field),
        ("--packet-loss", args.packet_loss != defaults.packet_loss),
        ("--realtime", args.realtime),
        ("--no-delay", args.no_delay),
        ("--view", args.view),
        ("--foxglove", args.foxglove.is_some()),
        ("--log-robots", args.log_robots.is_some()),
        ("--log-world-hz", args.log_world_hz != defaults.log_world_hz),
    ];
    if let Some((option, _)) = not_here.iter().find(|(_, given)| *given) {
        bail!(
            "{option} is for the built-in simulator: rcssservermj has its own field, physics and \
             referee (without delays), runs in real time, and each robot logs all of its own \
             packages"
        );
    }
    let config = GameConfig {
        exe: std::env::current_exe().context("finding the strata executable for the robots")?,
        players: args.players.unwrap_or(3),
        seed: args.seed,
        home: args.home.clone(),
        away: args.away.clone(),
        half: args.half.unwrap_or(RULES_HALF_TIME),
        limit: args.duration,
        log: args.log.clone(),
        join_timeout: std::time::Duration::from_secs(120),
        stall_timeout: std::time::Duration::from_secs(60),
    };
    let bar = if args.json { ProgressBar::hidden() } else { ProgressBar::new(1000) };
    bar.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:40} {percent:>3}% {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let report = physics::game::play(&config, &mut |fraction, score| {
        bar.set_position((fraction * 1000.0) as u64);
        bar.set_message(score.to_owned());
    })?;
    bar.finish_and_clear();
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print_report(&report);
    }
    Ok(())
}

pub fn print_report(r: &MatchReport) {
    let [home, away] = &r.teams;
    println!(
        "{} {} - {} {}   ({} vs {}, seed {}, {})",
        home.name,
        r.score[0],
        r.score[1],
        away.name,
        r.players_per_team,
        r.players_per_team,
        r.seed,
        if r.finished { "full time" } else { "stopped early" }
    );
    println!(
        "{:.0} s simulated in {:.1} s wall: {:.*}x real time ({})",
        r.simulated_s,
        r.wall_s,
        if r.real_time_factor < 10.0 { 2 } else { 0 },
        r.real_time_factor,
        if r.physics.is_some() { r.host.clone() } else { format!("{} host", r.host) }
    );
    println!("\nEvents");
    for e in r.events.iter().filter(|e| e.kind == "goal" || e.kind == "penalty") {
        let (m, s) = ((e.time / 60.0).floor(), e.time % 60.0);
        println!("  {m:>3.0}:{s:04.1}  {:<8} {}", e.kind, e.detail);
    }
    println!("\nTeams");
    println!(
        "  {:<18} {:>5} {:>6} {:>9} {:>12} {:>12} {:>11} {:>13}",
        "team",
        "goals",
        "falls",
        "penalties",
        "messages",
        "budget left",
        "1 striker",
        "double s (s)"
    );
    for t in &r.teams {
        println!(
            "  {:<18} {:>5} {:>6} {:>9} {:>12} {:>12} {:>10.1}% {:>13.1}",
            t.name,
            t.goals,
            t.falls,
            t.penalties,
            t.messages_sent,
            t.message_budget_left,
            100.0 * t.roles.one_striker,
            t.roles.double_striker_s
        );
    }
    println!("\nLayer rates per robot (Hz, min / mean / max — the columns of the paper's Table 6)");
    println!(
        "  {:<8} {:>22} {:>22} {:>22}   main roles",
        "robot", "planning", "deliberative", "reactive"
    );
    for robot in &r.robots {
        let rate = |name: &str| {
            robot
                .layers
                .iter()
                .find(|l| l.layer == name)
                .map(|l| format!("{:.1}/{:.1}/{:.1}", l.min_hz, l.mean_hz, l.max_hz))
                .unwrap_or_default()
        };
        let mut roles: Vec<_> = robot.roles.iter().collect();
        roles.sort_by(|a, b| b.1.total_cmp(a.1));
        let roles: Vec<String> =
            roles.iter().take(2).map(|(k, v)| format!("{k} {:.0}%", **v * 100.0)).collect();
        println!(
            "  {:<8} {:>22} {:>22} {:>22}   {}",
            robot.name,
            rate("planning"),
            rate("deliberative"),
            rate("reactive"),
            roles.join(", ")
        );
    }
    println!(
        "\nTeam messages: {} sent, {} delivered, {} lost, {} over budget, {} oversize",
        r.team_messages.sent,
        r.team_messages.delivered,
        r.team_messages.lost,
        r.team_messages.over_budget,
        r.team_messages.rejected_oversize
    );
    if let Some(physics) = &r.physics {
        print_physics(physics);
    }
}

fn print_physics(p: &PhysicsReport) {
    println!("\nHalves ({:.0} play seconds each; the left team kicks off)", p.half_s);
    for h in &p.halves {
        println!(
            "  half {}: {} on the left, goals {}-{}, {:.0} s played, {:.0} s simulated in {:.0} s \
             wall{}; the ball rolled {:.1} m, came {:.1} m from the home goal and {:.1} m from \
             the away goal",
            h.half,
            h.left,
            h.goals[0],
            h.goals[1],
            h.play_s,
            h.simulated_s,
            h.wall_s,
            if h.finished { "" } else { " (stopped early)" },
            h.ball_travel_m,
            h.ball_nearest_goal_m[0],
            h.ball_nearest_goal_m[1]
        );
    }
    println!("\nRobots in physics");
    println!(
        "  {:<8} {:>6} {:>9} {:>22} {:>8} {:>10} {:>16}",
        "robot",
        "falls",
        "stood up",
        "fall -> order (ms)",
        "CPU (s)",
        "CPU share",
        "pose error (m)"
    );
    for robot in &p.robots {
        let latencies: Vec<String> =
            robot.fall_latency_ms.iter().map(|ms| format!("{ms:.0}")).collect();
        let errors: Vec<String> =
            robot.localization_mean_m.iter().map(|m| format!("{m:.2}")).collect();
        println!(
            "  {:<8} {:>6} {:>9} {:>22} {:>8.1} {:>9.1}% {:>16}",
            robot.name,
            robot.falls,
            robot.stood_up,
            latencies.join(" "),
            robot.cpu_s,
            100.0 * robot.cpu_share,
            errors.join(" ")
        );
    }
    let c = &p.cpu;
    println!(
        "\nCPU: server {:.1} s, robots {:.1} s: Strata's share {:.1} %, the largest robot's \
         {:.1} % (target under {:.0} % per robot: {})",
        c.server_s,
        c.robots_s,
        100.0 * c.strata_share,
        100.0 * c.max_robot_share,
        100.0 * c.target_share,
        if c.target_met { "met" } else { "not met" }
    );
    println!("Reproducible from the seed: {}", p.reproducible);
}
