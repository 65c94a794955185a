//! `strata robot`: one robot, one process, in real time — the full soccer robot
//! (`strata_games::robot`) over the simulator server, a NAO or a T1 in rcssservermj, or the
//! simulator's test controller. This file parses the options and prints what the robot tells:
//! text for people, JSON lines for programs. `docs/robot.md` has the commands.

use std::net::Ipv4Addr;
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{Result, bail};
use clap::{Args, ValueEnum};
use serde::Serialize;
use strata_games::robot::{
    self, GameEvent, PlatformKind, Report, RobotOptions, RobotOutput, StartInfo, Status,
};
use strata_log::LogCompression;
use strata_nao::DEFAULT_SOCKET_PATH;
use strata_rcssmj::platform::FALL_ONSET_TILT;
use strata_runtime::Encoding;

use crate::sim_cmd;

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

impl RobotArgs {
    /// The library's options: the same fields, without the command line's own.
    pub fn options(&self) -> RobotOptions {
        RobotOptions {
            team: self.team,
            player: self.player,
            platform: self.platform,
            team_config: self.team_config.clone(),
            server: self.server.clone(),
            socket: self.socket.clone(),
            lola_config: self.lola_config.clone(),
            team_name: self.team_name.clone(),
            rcss_config: self.rcss_config.clone(),
            beam: self.beam,
            field: self.field.clone(),
            half_duration: self.half_duration,
            attack_sign: self.attack_sign,
            gc_wait: self.gc_wait,
            net: self.net,
            team_udp: self.team_udp,
            interface: self.interface.clone(),
            broadcast: self.broadcast,
            gc_port: self.gc_port,
            gc_return_port: self.gc_return_port,
            team_port: self.team_port,
            duration: self.duration,
            status_interval: self.status_interval,
            seed: self.seed,
            real_time_priority: self.real_time_priority,
            log: self.log.clone(),
            log_compression: self.log_compression,
            log_encoding: self.log_encoding,
            log_no_sync: self.log_no_sync,
            log_max_size: self.log_max_size,
        }
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
    let options = args.options();
    robot::validate(&options)?;
    if args.controller == ControllerKind::Test {
        return run_test_controller(&args);
    }
    let out: Arc<dyn RobotOutput> =
        Arc::new(Output { json: args.json, name: format!("robot {}/{}", args.team, args.player) });
    robot::run(&options, &out)
}

/// The simulator's test controller, through the simulator server.
fn run_test_controller(args: &RobotArgs) -> Result<()> {
    if args.platform != PlatformKind::Sim {
        bail!("--controller test runs against the simulator server only");
    }
    if args.log.is_some() {
        bail!("--log records the modules of the full architecture: not with --controller test");
    }
    if args.net {
        bail!(
            "--controller test reads the game state from the simulator server; run it without --net"
        );
    }
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
}

impl RobotOutput for Output {
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
            info.controller,
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
