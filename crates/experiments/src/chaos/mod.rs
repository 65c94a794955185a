//! `strata chaos`: a real-time game under faults, measured. The simulator server
//! runs in this process; each of six robots (3 vs 3) is a `strata robot --net` process with its
//! own GameController port and its team's UDP port, as on a field. After a baseline with
//! nothing injected, one fault at a time, with a settling pause between:
//!
//! 1. `kill -9` team 10's ball player; a teammate takes over its role; it is started again and
//!    plays with its team again.
//! 2. `SIGSTOP` a robot of team 20 for 5 s, then `SIGCONT`.
//! 3. A slow client: a connection that says hello as a spare robot and reads a kilobyte a
//!    second, until the server drops it.
//! 4. A thousand connections that never say hello: the server's cap refuses most at once, its
//!    handshake deadline the rest; each refusal must be an error frame and a clean close.
//! 5. A hundred thousand garbage datagrams at one robot's GameController port and as many at
//!    its team's port.
//! 6. A robot's log file limited to a little more than it holds (RLIMIT_FSIZE, SIGXFSZ
//!    ignored): its writes fail as on a full disk.
//!
//! Measured throughout: the server's real-time factor per phase, every robot's reactive rate
//! per phase against its baseline, how long the teammates take to take over the dead robot's
//! role, peak memory after the baseline and at the end, panics, the records a robot's log lost.
//! `docs/reliability.md` has the targets and figures.

mod faults;
mod game;
mod measure;
mod report;

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use anyhow::{Context as _, Result};
use indicatif::ProgressBar;
use strata_log::LogReader;

pub use faults::{
    Connections, Garbage, GarbagePort, LOG_ROOM, LogFull, SlowClient, Stopped, Takeover,
};
pub use game::{Interrupted, RobotKey};
pub use measure::{CpuShare, Memory, RealTime};
pub use report::{
    Check, LogFile, LogRecords, Machine, Phase, ProcessEnd, ProcessMemory, RATE_KEPT,
    REAL_TIME_TOLERANCE, Report, RobotRate, Settings, table_text,
};

use faults::Window;
use game::{Game, PLAYERS, TEAMS};

/// How a chaos run runs.
#[derive(Clone, Debug)]
pub struct Options {
    /// How long each phase is measured (the baseline, each fault).
    pub phase: Duration,
    /// How long the stopped robot stays stopped.
    pub stop: Duration,
    /// How long the slow client stays at most: the server usually drops it first, once the
    /// socket buffers between them are full and a write blocks past its write timeout.
    pub slow_client: Duration,
    /// Garbage datagrams sent to each of the two ports.
    pub datagrams: u64,
    pub connection_attempts: usize,
    pub out_dir: PathBuf,
    /// The `strata` executable the robot processes run.
    pub strata_exe: PathBuf,
    pub seed: u64,
    /// `strata robot --real-time-priority`.
    pub real_time_priority: u8,
}

impl Options {
    /// The pause after each fault before the next: long enough for the game to settle, short
    /// against the phase.
    fn settle(&self) -> Duration {
        self.phase.div_f64(4.0).clamp(Duration::from_secs(1), Duration::from_secs(5))
    }
}

/// The steps a progress bar counts: start, the baseline, six faults, the end.
pub const STEPS: u64 = 9;

/// Runs the chaos run and writes its files into `options.out_dir`. Ctrl-C ends it with
/// [`Interrupted`] after killing every process it started.
pub fn run(options: &Options, progress: &ProgressBar) -> Result<Report> {
    let interrupted = strata_runtime::signal::interrupt_flag().map_err(anyhow::Error::msg)?;
    std::fs::create_dir_all(&options.out_dir)
        .with_context(|| format!("creating {}", options.out_dir.display()))?;
    let panics = PanicCounter::install();
    let date = report::utc(SystemTime::now().duration_since(UNIX_EPOCH).unwrap_or_default());
    let load_start = measure::load_average();
    progress.set_length(STEPS);
    progress.set_message("starting the server and six robots");
    let mut game = Game::start(options, interrupted)?;
    progress.inc(1);
    let outputs = options.out_dir.join("robots");
    let run = run_phases(&mut game, options, progress);
    // The robots' own words, whatever happened: the first place to look when a check fails.
    let saved = game.save_outputs(&outputs);
    let mut found = run.with_context(|| {
        format!("the chaos run failed; the robots' output is in {}", outputs.display())
    })?;
    saved?;
    found.server_panics = panics.count();
    found.date = date;
    found.machine.load_start = load_start;
    found.checks = report::checks(&found);
    found.all_met = found.checks.iter().all(|c| c.met != Some(false));
    report::write(&found, &options.out_dir)?;
    progress.inc(1);
    Ok(found)
}

fn run_phases(game: &mut Game, options: &Options, progress: &ProgressBar) -> Result<Report> {
    let phase = options.phase;
    let mut windows = Vec::new();
    let step = |message: &str| {
        progress.set_message(message.to_owned());
    };
    step("baseline: nothing injected");
    windows.push(faults::baseline(game, phase)?);
    progress.inc(1);
    let memory_before = memory(game);

    step("kill -9 a robot, wait for a teammate to take over, restart it");
    let (window, takeover) = faults::kill_and_restart(game, phase)?;
    windows.push(window);
    progress.inc(1);
    game.run_for(options.settle())?;

    step("SIGSTOP a robot, then SIGCONT");
    let (window, stopped) = faults::stop_and_continue(game, phase, options.stop)?;
    windows.push(window);
    progress.inc(1);
    game.run_for(options.settle())?;

    step("a slow client");
    let (window, slow_client) = faults::slow_client(game, options.slow_client)?;
    windows.push(window);
    progress.inc(1);
    game.run_for(options.settle())?;

    step("connection attempts");
    let (window, connections) = faults::connection_flood(game, phase, options.connection_attempts)?;
    windows.push(window);
    progress.inc(1);
    game.run_for(options.settle())?;

    step("garbage datagrams");
    let (window, mut garbage) = faults::garbage(game, phase, options.datagrams, options.seed)?;
    windows.push(window);
    progress.inc(1);
    game.run_for(options.settle())?;

    step("a log into a nearly full file");
    let (window, log_full) = faults::fill_log(game, phase)?;
    windows.push(window);
    progress.inc(1);

    step("stopping");
    let memory_after = memory(game);
    let running: Vec<(RobotKey, bool)> =
        game.robots.iter_mut().map(|r| (r.key, r.process.is_running())).collect();
    game.silence_gc();
    // What is on its way to the robots reaches them before they stop.
    game.run_for(Duration::from_secs(1))?;
    let (killed, server_stop) = game.stop(Duration::from_secs(20))?;

    let phases = phase_figures(game, &windows);
    count_garbage(game, &mut garbage);
    let processes = process_ends(game, &running, &killed);
    let memory = memory_before
        .into_iter()
        .map(|(process, before)| {
            let after = memory_after.iter().find(|(p, _)| *p == process).and_then(|(_, m)| *m);
            ProcessMemory { process, before, after }
        })
        .chain(
            memory_after
                .iter()
                .filter(|(p, _)| p.contains("restart"))
                .map(|(p, m)| ProcessMemory { process: p.clone(), before: None, after: *m }),
        )
        .collect();
    Ok(Report {
        date: String::new(),
        machine: Machine {
            cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
            load_start: None,
            load_end: measure::load_average(),
        },
        settings: Settings {
            phase_s: phase.as_secs_f64(),
            stop_s: options.stop.as_secs_f64(),
            slow_client_s: options.slow_client.as_secs_f64(),
            datagrams_per_port: options.datagrams,
            connection_attempts: options.connection_attempts,
            seed: options.seed,
            robots: game.robots.len(),
            real_time_priority: options.real_time_priority,
        },
        phases,
        takeover,
        stopped,
        slow_client,
        connections,
        garbage,
        full_log_file: full_log_file(game),
        log_full,
        log: log_records(game),
        memory,
        processes,
        server_panics: 0,
        server_stop_error: server_stop.err(),
        checks: Vec::new(),
        all_met: false,
    })
}

/// The server's (this process's) and every robot process's memory now.
fn memory(game: &Game) -> Vec<(String, Option<Memory>)> {
    let mut all = vec![("server".to_owned(), measure::own_memory())];
    for robot in &game.robots {
        all.push((robot.process.name().to_owned(), measure::memory(robot.process.pid())));
    }
    all
}

fn phase_figures(game: &Game, windows: &[Window]) -> Vec<Phase> {
    let time = game.time_samples();
    let baseline: Vec<(RobotKey, Option<f64>)> = match windows.first() {
        Some(w) => game
            .robots
            .iter()
            .map(|r| (r.key, measure::reactive_rate(&r.samples, w.start, w.end)))
            .collect(),
        None => Vec::new(),
    };
    windows
        .iter()
        .map(|w| {
            let robots: Vec<RobotRate> = game
                .robots
                .iter()
                .map(|r| {
                    let hz = measure::reactive_rate(&r.samples, w.start, w.end);
                    let base = baseline.iter().find(|(k, _)| *k == r.key).and_then(|(_, b)| *b);
                    let share = match (hz, base) {
                        (Some(hz), Some(base)) if base > 0.0 => Some(hz / base),
                        _ => None,
                    };
                    RobotRate { robot: r.key, reactive_hz: hz, share }
                })
                .collect();
            // A robot that gave no rate in a phase it was not hit by counts as none at all.
            let lowest_other = robots
                .iter()
                .filter(|r| Some(r.robot) != w.target)
                .map(|r| (r.robot, r.share.unwrap_or(0.0)))
                .min_by(|a, b| a.1.total_cmp(&b.1));
            Phase {
                name: w.name.to_owned(),
                fault: w.fault.clone(),
                target: w.target,
                start_s: w.start.saturating_duration_since(game.started).as_secs_f64(),
                seconds: w.end.saturating_duration_since(w.start).as_secs_f64(),
                real_time: measure::real_time(&time, w.start, w.end),
                cpu: measure::cpu_share(&game.cpu, w.start, w.end),
                robots,
                lowest_other,
            }
        })
        .collect()
}

/// What the robots counted of the garbage, from their final reports: the target's
/// GameController link (rejected and ignored), and for the team port every robot of the
/// team (datagrams over 128 bytes rejected by the link, the rest by the message decoder, or
/// dropped by the link's queue had more than it holds arrived between two planning cycles).
fn count_garbage(game: &Game, garbage: &mut Garbage) {
    let number = |report: &serde_json::Value, path: &[&str]| {
        path.iter().try_fold(report, |v, key| v.get(key)).and_then(|v| v.as_u64()).unwrap_or(0)
    };
    let Some(target) = garbage.robot else { return };
    for port in &mut garbage.ports {
        let mut counted = 0;
        for robot in &game.robots {
            for (_, report) in &robot.reports {
                if port.port_kind == "GameController" && robot.key == target {
                    counted += number(report, &["game_controller_link", "rejected"])
                        + number(report, &["game_controller_link", "ignored"]);
                } else if port.port_kind == "team" && robot.key.team == target.team {
                    counted += number(report, &["team_link", "rejected"])
                        + number(report, &["team_link", "dropped"])
                        + number(report, &["planning", "rejected"]);
                }
            }
        }
        port.robots_counted = counted;
    }
}

fn process_ends(game: &Game, running: &[(RobotKey, bool)], killed: &[RobotKey]) -> Vec<ProcessEnd> {
    let mut ends = Vec::new();
    for robot in &game.robots {
        for process in &robot.ended {
            ends.push(ProcessEnd {
                process: process.name().to_owned(),
                // Killed by the fault, as intended: it ran until then.
                ran_to_the_end: true,
                status: format!("{} (the fault)", describe_status(process)),
                killed_at_the_end: false,
                panics: measure::panics(&process.stderr()),
            });
        }
        ends.push(ProcessEnd {
            process: robot.process.name().to_owned(),
            ran_to_the_end: running.iter().any(|(k, alive)| *k == robot.key && *alive),
            status: describe_status(&robot.process),
            killed_at_the_end: killed.contains(&robot.key),
            panics: measure::panics(&robot.process.stderr()),
        });
    }
    ends
}

fn describe_status(process: &strata_games::children::Child) -> String {
    process.exit_status().map_or_else(|| "still running".to_owned(), |s| s.to_string())
}

/// Team 10's goalkeeper's log: what the writer says it wrote against what reads back.
fn log_records(game: &Game) -> LogRecords {
    let key = RobotKey { team: TEAMS[0], player: PLAYERS[0] };
    let Some(path) = game.robot(key).ok().and_then(|r| r.log.clone()) else {
        return LogRecords::default();
    };
    let mut records =
        LogRecords { robot: Some(key), file: path.display().to_string(), ..LogRecords::default() };
    match LogReader::open(&path) {
        Ok(reader) => {
            records.finished = reader.is_complete();
            let stats = reader.stats();
            records.written = stats.as_ref().map_or(0, |s| s.messages);
            records.dropped = stats.as_ref().map_or(0, |s| s.dropped);
            let mut unreadable = 0;
            for message in reader.messages() {
                match message {
                    Ok(_) => records.read_back += 1,
                    Err(_) => unreadable += 1,
                }
            }
            records.lost = stats.map(|_| records.written.saturating_sub(records.read_back));
            if unreadable > 0 {
                records.error = Some(format!("{unreadable} records could not be read"));
            } else if !records.finished {
                records.error = Some("the log was not finished".to_owned());
            }
        }
        Err(error) => records.error = Some(error.to_string()),
    }
    records
}

/// What is left of the log that filled its file.
fn full_log_file(game: &Game) -> LogFile {
    let key = RobotKey { team: TEAMS[1], player: PLAYERS[0] };
    let Some(path) = game.robot(key).ok().and_then(|r| r.log.clone()) else {
        return LogFile::default();
    };
    let bytes = std::fs::metadata(&path).map_or(0, |m| m.len());
    match LogReader::open(&path) {
        Ok(reader) => LogFile {
            bytes,
            messages_recovered: reader.messages().filter(Result::is_ok).count() as u64,
            error: None,
        },
        Err(error) => LogFile { bytes, messages_recovered: 0, error: Some(error.to_string()) },
    }
}

/// Counts the panics of this process's threads (the server's among them) while a run lasts,
/// then hands panics back to the hook that was there before.
struct PanicCounter {
    count: Arc<AtomicUsize>,
    previous: Arc<dyn Fn(&std::panic::PanicHookInfo<'_>) + Sync + Send>,
}

impl PanicCounter {
    fn install() -> PanicCounter {
        let count = Arc::new(AtomicUsize::new(0));
        let previous: Arc<dyn Fn(&std::panic::PanicHookInfo<'_>) + Sync + Send> =
            Arc::from(std::panic::take_hook());
        let (counter, chained) = (Arc::clone(&count), Arc::clone(&previous));
        std::panic::set_hook(Box::new(move |info| {
            counter.fetch_add(1, Ordering::Relaxed);
            chained(info);
        }));
        PanicCounter { count, previous }
    }

    fn count(&self) -> usize {
        self.count.load(Ordering::Relaxed)
    }
}

impl Drop for PanicCounter {
    fn drop(&mut self) {
        let previous = Arc::clone(&self.previous);
        std::panic::set_hook(Box::new(move |info| previous(info)));
    }
}
