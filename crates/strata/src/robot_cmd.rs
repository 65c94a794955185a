//! `strata robot`: one robot, one process, in real time — the full soccer robot
//! (`strata_games::robot`) over the simulator server, a NAO or a T1 in rcssservermj, or the
//! simulator's test controller. This file parses the options and prints what the robot tells:
//! text for people, JSON lines for programs. `docs/robot.md` has the commands.

use std::sync::Arc;

use anyhow::{Result, bail};
use clap::{Args, ValueEnum};
use serde::Serialize;
use strata_games::robot::{
    self, GameEvent, PlatformKind, Report, RobotOptions, RobotOutput, StartInfo, Status,
};
use strata_rcssmj::platform::FALL_ONSET_TILT;

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
    /// Everything the library runs a robot with.
    #[command(flatten)]
    pub options: RobotOptions,
    #[arg(long, value_enum, default_value = "soccer")]
    pub controller: ControllerKind,
    /// Print JSON lines (start, game-state changes, status, final report) instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Runs one robot until Ctrl-C, `--duration` or the end of its platform.
pub fn run(args: RobotArgs) -> Result<()> {
    let options = &args.options;
    robot::validate(options)?;
    if args.controller == ControllerKind::Test {
        return run_test_controller(&args);
    }
    let out: Arc<dyn RobotOutput> = Arc::new(Output {
        json: args.json,
        name: format!("robot {}/{}", options.team, options.player),
    });
    robot::run(options, &out)
}

/// The simulator's test controller, through the simulator server.
fn run_test_controller(args: &RobotArgs) -> Result<()> {
    let options = &args.options;
    if options.platform != PlatformKind::Sim {
        bail!("--controller test runs against the simulator server only");
    }
    if options.log.is_some() {
        bail!("--log records the modules of the full architecture: not with --controller test");
    }
    if options.foxglove.is_some() {
        bail!("--foxglove serves the full architecture's scene: not with --controller test");
    }
    if options.net {
        bail!(
            "--controller test reads the game state from the simulator server; run it without --net"
        );
    }
    if args.json {
        bail!("--json is not available with --controller test");
    }
    sim_cmd::run_robot_test_controller(sim_cmd::RobotArgs {
        server: options.server.clone().unwrap_or_else(|| sim_cmd::DEFAULT_ADDR.to_owned()),
        team: options.team,
        player: options.player,
        duration: options.duration,
        status_interval: options.status_interval,
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
