//! What a chaos run found: every figure, each target and whether it was met, as a table for
//! the terminal, `report.md`, CSV files and `summary.json`.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Result;
use serde::Serialize;

use crate::report::{Markdown, num, write_csv};

use super::faults::{Connections, Garbage, LogFull, SlowClient, Stopped, Takeover};
use super::game::RobotKey;
use super::measure::{CpuShare, Memory, RealTime};

/// The server's real-time factor may stray this far from 1.
pub const REAL_TIME_TOLERANCE: f64 = 0.05;
/// The other robots' reactive rates keep this share of their baseline rates.
pub const RATE_KEPT: f64 = 0.95;

/// Everything a chaos run measured.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// When the run started, UTC.
    pub date: String,
    pub machine: Machine,
    pub settings: Settings,
    pub phases: Vec<Phase>,
    pub takeover: Takeover,
    pub stopped: Stopped,
    pub slow_client: SlowClient,
    pub connections: Connections,
    pub garbage: Garbage,
    pub log_full: LogFull,
    pub full_log_file: LogFile,
    pub log: LogRecords,
    pub memory: Vec<ProcessMemory>,
    pub processes: Vec<ProcessEnd>,
    /// Panics of this process (the server's threads among them).
    pub server_panics: usize,
    /// How the server stopped: `None` cleanly, or why not.
    pub server_stop_error: Option<String>,
    pub checks: Vec<Check>,
    /// Every target with a pass/fail was met.
    pub all_met: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct Machine {
    pub cores: usize,
    /// 1-minute load averages at the start and at the end.
    pub load_start: Option<f64>,
    pub load_end: Option<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Settings {
    pub phase_s: f64,
    pub stop_s: f64,
    pub slow_client_s: f64,
    pub datagrams_per_port: u64,
    pub connection_attempts: usize,
    pub seed: u64,
    pub robots: usize,
    pub real_time_priority: u8,
}

/// One phase: the baseline or a fault, and how the game ran meanwhile.
#[derive(Clone, Debug, Serialize)]
pub struct Phase {
    pub name: String,
    pub fault: String,
    /// The robot the fault hit, left out of `lowest_other`.
    pub target: Option<RobotKey>,
    /// Seconds from the start of the run.
    pub start_s: f64,
    pub seconds: f64,
    pub real_time: Option<RealTime>,
    /// Where the machine's CPU time went meanwhile.
    pub cpu: Option<CpuShare>,
    pub robots: Vec<RobotRate>,
    /// The other robots' lowest reactive rate as a share of its baseline, and whose.
    pub lowest_other: Option<(RobotKey, f64)>,
}

#[derive(Clone, Debug, Serialize)]
pub struct RobotRate {
    pub robot: RobotKey,
    pub reactive_hz: Option<f64>,
    /// Of its baseline rate.
    pub share: Option<f64>,
}

/// The log of a robot that logs as usual (team 10's goalkeeper).
#[derive(Clone, Debug, Default, Serialize)]
pub struct LogRecords {
    pub robot: Option<RobotKey>,
    pub file: String,
    /// The file has its summary and footer: the robot finished it.
    pub finished: bool,
    /// Records the writer says it wrote, and dropped (the bounded queue full: counted).
    pub written: u64,
    pub dropped: u64,
    /// Records read back from the file.
    pub read_back: u64,
    /// Written but not in the file.
    pub lost: Option<u64>,
    pub error: Option<String>,
}

/// What is in the log that filled its file.
#[derive(Clone, Debug, Default, Serialize)]
pub struct LogFile {
    pub bytes: u64,
    pub messages_recovered: u64,
    pub error: Option<String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct ProcessMemory {
    pub process: String,
    pub before: Option<Memory>,
    pub after: Option<Memory>,
}

/// How a robot process ended.
#[derive(Clone, Debug, Serialize)]
pub struct ProcessEnd {
    pub process: String,
    /// Running until the run stopped it (or, for the killed one, until the fault).
    pub ran_to_the_end: bool,
    pub status: String,
    /// Killed because it did not stop within the grace after Ctrl-C.
    pub killed_at_the_end: bool,
    pub panics: usize,
}

/// One target, what was measured and whether it was met (`None`: reported, no target).
#[derive(Clone, Debug, Serialize)]
pub struct Check {
    pub measurement: String,
    pub target: String,
    pub measured: String,
    pub met: Option<bool>,
}

fn check(measurement: &str, target: &str, measured: String, met: Option<bool>) -> Check {
    Check { measurement: measurement.to_owned(), target: target.to_owned(), measured, met }
}

fn seconds(value: Option<f64>) -> String {
    value.map_or_else(|| "not seen".to_owned(), |s| format!("{s:.1} s"))
}

/// The chaos run's targets, each with what was measured.
pub fn checks(r: &Report) -> Vec<Check> {
    let mut checks = Vec::new();
    pace_checks(r, &mut checks);
    fault_checks(r, &mut checks);
    network_checks(r, &mut checks);
    log_checks(r, &mut checks);
    process_checks(r, &mut checks);
    checks
}

/// The server's real-time factor and the robots' reactive rates, phase by phase.
fn pace_checks(r: &Report, checks: &mut Vec<Check>) {
    let rtf: Vec<String> = r
        .phases
        .iter()
        .map(|p| {
            p.real_time.map_or_else(
                || format!("{}: n/a", p.name),
                |rt| format!("{}: {:.3} (worst 1 s {:.2})", p.name, rt.factor, rt.lowest_1s),
            )
        })
        .collect();
    checks.push(check(
        "server real-time factor, per phase",
        "within 5 % of 1.0",
        rtf.join("; "),
        Some(
            r.phases.iter().all(|p| {
                p.real_time.is_some_and(|rt| (rt.factor - 1.0).abs() <= REAL_TIME_TOLERANCE)
            }),
        ),
    ));
    let rates: Vec<String> = r
        .phases
        .iter()
        .skip(1)
        .map(|p| {
            p.lowest_other.map_or_else(
                || format!("{}: n/a", p.name),
                |(k, share)| format!("{}: {:.1} % ({k})", p.name, 100.0 * share),
            )
        })
        .collect();
    checks.push(check(
        "other robots' reactive rate, lowest, of baseline",
        ">= 95 %",
        rates.join("; "),
        Some(r.phases.iter().skip(1).all(|p| p.lowest_other.is_some_and(|(_, s)| s >= RATE_KEPT))),
    ));
}

/// The killed robot's role taken over, its restart, the stopped robot, the slow client.
fn fault_checks(r: &Report, checks: &mut Vec<Check>) {
    let t = &r.takeover;
    checks.push(check(
        "kill -9: a teammate takes over the dead robot's role",
        "taken over",
        format!(
            "{} ({}) killed; noticed after {}, {} held by {} after {}",
            t.robot.map_or("-".to_owned(), |k| k.to_string()),
            t.role.as_deref().unwrap_or("no role"),
            seconds(t.noticed_s),
            t.role_taken.as_deref().unwrap_or("the ball-playing role"),
            t.taken_over_by.map_or("nobody".to_owned(), |k| k.to_string()),
            seconds(t.taken_over_s),
        ),
        Some(t.taken_over_s.is_some()),
    ));
    checks.push(check(
        "kill -9: the restarted robot plays with its team again",
        "rejoins",
        format!("after {}", seconds(t.rejoined_s)),
        Some(t.rejoined_s.is_some()),
    ));
    let s = &r.stopped;
    checks.push(check(
        "SIGSTOP: the stopped robot resumes",
        "resumes, still in the game",
        format!(
            "stopped {:.1} s, sensor frames again {} after SIGCONT, {}",
            s.stopped_s,
            seconds(s.resumed_s),
            if s.in_game { "in the game" } else { "dropped from the game" }
        ),
        Some(s.resumed_s.is_some() && s.in_game),
    ));
    let c = &r.slow_client;
    checks.push(check(
        "slow client",
        "admitted, then dropped by the server (write timeout) or held to the end; the game goes on",
        format!(
            "{}; {} read in {:.0} s; the server dropped {} messages for it; {}",
            if c.admitted { "admitted" } else { "never admitted" },
            bytes(c.bytes_read),
            c.held_s,
            c.messages_dropped,
            c.dropped_after_s.map_or_else(
                || "still connected at the end of the phase".to_owned(),
                |s| format!("disconnected by the server after {s:.1} s")
            )
        ),
        Some(c.admitted),
    ));
}

/// Connection attempts over the cap and garbage datagrams.
fn network_checks(r: &Report, checks: &mut Vec<Check>) {
    let n = &r.connections;
    checks.push(check(
        "connection attempts: every refusal clean",
        "0 unclean",
        format!(
            "{} attempts: {} refused over the cap, {} at the handshake deadline, {} other errors, {} unclean, {} not connected; server counted {} refusals; at most {} open; {:.1} s",
            n.attempts,
            n.refused_over_cap,
            n.handshake_timeouts,
            n.other_errors.values().sum::<u64>(),
            n.unclean,
            n.connect_failed,
            n.server_refused,
            n.most_open,
            n.seconds
        ),
        Some(
            n.unclean == 0
                && n.connect_failed == 0
                && n.other_errors.is_empty()
                && n.refused_over_cap + n.handshake_timeouts == n.attempts as u64
                && n.server_refused == n.attempts as u64,
        ),
    ));
    for port in &r.garbage.ports {
        checks.push(check(
            &format!("garbage at the {} port: every datagram counted", port.port_kind),
            "counted by a robot or dropped by the kernel",
            format!(
                "{} sent to {} socket(s); robots counted {}, the kernel dropped {}",
                port.sent, port.sockets, port.robots_counted, port.kernel_dropped
            ),
            Some(port.accounted()),
        ));
    }
    checks.push(check(
        "garbage: the flooded team's own messages",
        "reported",
        {
            let gap = |g: Option<(RobotKey, f64)>| {
                g.map_or_else(|| "n/a".to_owned(), |(k, s)| format!("{s:.1} s ({k})"))
            };
            format!(
                "longest stretch a robot counted on fewer than both teammates: {} in the flooded team, {} in the other",
                gap(r.garbage.team_gap),
                gap(r.garbage.other_team_gap)
            )
        },
        None,
    ));
}

/// The nearly full log file and the game's own log.
fn log_checks(r: &Report, checks: &mut Vec<Check>) {
    let l = &r.log_full;
    checks.push(check(
        "log into a nearly full file: failure reported, robot plays on",
        "reported, keeps playing",
        match &l.not_injected {
            Some(why) => format!("not injected: {why}"),
            None => format!(
                "limit {}; reported after {}; {}; {} records readable",
                bytes(l.limit_bytes),
                seconds(l.reported_s),
                if l.kept_playing { "kept playing" } else { "did not keep playing" },
                r.full_log_file.messages_recovered
            ),
        },
        Some(l.not_injected.is_none() && l.reported_s.is_some() && l.kept_playing),
    ));
    let g = &r.log;
    checks.push(check(
        "log records lost",
        "0 (dropped ones counted)",
        match &g.error {
            Some(error) => format!("{}: {error}", g.file),
            None => format!(
                "{} written, {} read back, {} lost, {} dropped (counted)",
                g.written,
                g.read_back,
                g.lost.map_or("?".to_owned(), |l| l.to_string()),
                g.dropped
            ),
        },
        Some(g.error.is_none() && g.finished && g.lost == Some(0)),
    ));
}

/// Memory, panics and processes alive at the end.
fn process_checks(r: &Report, checks: &mut Vec<Check>) {
    let memory: Vec<String> = r
        .memory
        .iter()
        .map(|m| {
            let kb = |m: Option<Memory>| {
                m.map_or("-".to_owned(), |m| format!("{:.0}", m.peak_kb as f64 / 1024.0))
            };
            format!("{} {} -> {} MiB", m.process, kb(m.before), kb(m.after))
        })
        .collect();
    checks.push(check(
        "peak memory (VmHWM), after the baseline -> at the end",
        "reported",
        memory.join("; "),
        None,
    ));
    let panics = r.server_panics + r.processes.iter().map(|p| p.panics).sum::<usize>();
    checks.push(check(
        "panics",
        "0",
        format!("{panics} ({} in the server's process)", r.server_panics),
        Some(panics == 0 && r.server_stop_error.is_none()),
    ));
    let ended_early: Vec<&str> = r
        .processes
        .iter()
        .filter(|p| !p.ran_to_the_end || p.killed_at_the_end)
        .map(|p| p.process.as_str())
        .collect();
    checks.push(check(
        "every process alive at the end (the killed one restarted)",
        "all",
        if ended_early.is_empty() {
            format!("{} processes, all ran to the end and stopped on Ctrl-C", r.processes.len())
        } else {
            format!("ended early or had to be killed: {}", ended_early.join(", "))
        },
        Some(ended_early.is_empty()),
    ));
}

fn bytes(n: u64) -> String {
    if n >= 1 << 20 {
        format!("{:.1} MiB", n as f64 / f64::from(1 << 20))
    } else {
        format!("{:.0} KiB", n as f64 / 1024.0)
    }
}

fn met(met: Option<bool>) -> &'static str {
    match met {
        Some(true) => "yes",
        Some(false) => "NO",
        None => "-",
    }
}

/// The phases as rows: name, fault, RTF, worst second, the other robots' lowest share.
fn phase_rows(r: &Report) -> Vec<Vec<String>> {
    r.phases
        .iter()
        .map(|p| {
            vec![
                p.name.clone(),
                format!("{:.0}", p.seconds),
                p.real_time.map_or("n/a".to_owned(), |rt| format!("{:.3}", rt.factor)),
                p.real_time.map_or("n/a".to_owned(), |rt| format!("{:.2}", rt.lowest_1s)),
                p.lowest_other
                    .map_or("n/a".to_owned(), |(k, s)| format!("{:.1} % ({k})", 100.0 * s)),
                p.cpu.as_ref().map_or("n/a".to_owned(), |c| {
                    format!(
                        "{:.2} / {:.2} / {}",
                        c.robots,
                        c.server,
                        c.other.map_or("?".to_owned(), |o| format!("{o:.2}"))
                    )
                }),
                p.fault.clone(),
            ]
        })
        .collect()
}

const PHASE_HEADERS: [&str; 7] = [
    "phase",
    "s",
    "RTF",
    "worst 1 s",
    "others' reactive, lowest",
    "CPU robots / server / rest (cores)",
    "fault",
];

/// The tables for the terminal.
pub fn table_text(r: &Report) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "chaos run {}: {} robots, {:.0} s phases, {} cores, load {} -> {}",
        r.date,
        r.settings.robots,
        r.settings.phase_s,
        r.machine.cores,
        r.machine.load_start.map_or("?".to_owned(), |l| format!("{l:.2}")),
        r.machine.load_end.map_or("?".to_owned(), |l| format!("{l:.2}")),
    );
    out.push('\n');
    out.push_str(&aligned(&PHASE_HEADERS, &phase_rows(r)));
    out.push('\n');
    let rows: Vec<Vec<String>> = r
        .checks
        .iter()
        .map(|c| {
            vec![met(c.met).to_owned(), c.measurement.clone(), c.target.clone(), c.measured.clone()]
        })
        .collect();
    out.push_str(&aligned(&["met", "measurement", "target", "measured"], &rows));
    let _ = writeln!(
        out,
        "\n{}",
        if r.all_met { "every target met" } else { "SOME TARGETS NOT MET (see above)" }
    );
    out
}

/// Columns padded to their widest cell; the last column is not padded.
fn aligned(headers: &[&str], rows: &[Vec<String>]) -> String {
    let mut widths: Vec<usize> = headers.iter().map(|h| h.chars().count()).collect();
    for row in rows {
        for (w, cell) in widths.iter_mut().zip(row) {
            *w = (*w).max(cell.chars().count());
        }
    }
    let line = |cells: Vec<&str>| {
        let last = cells.len().saturating_sub(1);
        let mut text = String::new();
        for (i, (cell, w)) in cells.iter().zip(&widths).enumerate() {
            if i == last {
                text.push_str(cell);
            } else {
                let _ = write!(text, "{cell:<w$}  ");
            }
        }
        text.trim_end().to_owned() + "\n"
    };
    let mut out = line(headers.to_vec());
    for row in rows {
        out.push_str(&line(row.iter().map(String::as_str).collect()));
    }
    out
}

/// Writes `summary.json`, `report.md`, `phases.csv`, `checks.csv` and `memory.csv` into `dir`.
pub fn write(r: &Report, dir: &Path) -> Result<()> {
    let json = serde_json::to_string_pretty(r)?;
    std::fs::write(dir.join("summary.json"), json + "\n")?;
    let mut md = Markdown::new("Chaos run");
    md.paragraph(&format!(
        "{}; {} logical cores; 1-minute load {} at the start, {} at the end; phases of {:.0} s, {} garbage datagrams per port, {} connection attempts, seed {}.",
        r.date,
        r.machine.cores,
        r.machine.load_start.map_or("?".to_owned(), |l| format!("{l:.2}")),
        r.machine.load_end.map_or("?".to_owned(), |l| format!("{l:.2}")),
        r.settings.phase_s,
        r.settings.datagrams_per_port,
        r.settings.connection_attempts,
        r.settings.seed,
    ));
    md.heading("Phases");
    md.table(&PHASE_HEADERS, &phase_rows(r));
    md.heading("Targets");
    let rows: Vec<Vec<String>> = r
        .checks
        .iter()
        .map(|c| {
            vec![c.measurement.clone(), c.target.clone(), c.measured.clone(), met(c.met).to_owned()]
        })
        .collect();
    md.table(&["measurement", "target", "measured", "met"], &rows);
    md.write(&dir.join("report.md"))?;

    let mut rows = Vec::new();
    for p in &r.phases {
        for robot in &p.robots {
            rows.push(vec![
                p.name.clone(),
                num(p.start_s),
                num(p.seconds),
                p.real_time.map_or(String::new(), |rt| num(rt.factor)),
                p.real_time.map_or(String::new(), |rt| num(rt.lowest_1s)),
                robot.robot.to_string(),
                (p.target == Some(robot.robot)).to_string(),
                robot.reactive_hz.map_or(String::new(), num),
                robot.share.map_or(String::new(), num),
                p.cpu.as_ref().map_or(String::new(), |c| {
                    // A restarted robot's processes together.
                    let name = format!("robot {}", robot.robot);
                    let cores: f64 = c
                        .processes
                        .iter()
                        .filter(|(n, _)| *n == name || n.starts_with(&format!("{name} ")))
                        .map(|(_, cores)| cores)
                        .sum();
                    num(cores)
                }),
                p.cpu.as_ref().map_or(String::new(), |c| num(c.server)),
                p.cpu.as_ref().and_then(|c| c.other).map_or(String::new(), num),
            ]);
        }
    }
    write_csv(
        &dir.join("phases.csv"),
        &[
            "phase",
            "start_s",
            "seconds",
            "rtf",
            "rtf_worst_1s",
            "robot",
            "fault_target",
            "reactive_hz",
            "share_of_baseline",
        ],
        &rows,
    )?;
    let rows: Vec<Vec<String>> = r
        .checks
        .iter()
        .map(|c| {
            vec![c.measurement.clone(), c.target.clone(), c.measured.clone(), met(c.met).to_owned()]
        })
        .collect();
    write_csv(&dir.join("checks.csv"), &["measurement", "target", "measured", "met"], &rows)?;
    let kb =
        |m: Option<Memory>, f: fn(Memory) -> u64| m.map_or(String::new(), |m| f(m).to_string());
    let rows: Vec<Vec<String>> = r
        .memory
        .iter()
        .map(|m| {
            vec![
                m.process.clone(),
                kb(m.before, |m| m.peak_kb),
                kb(m.after, |m| m.peak_kb),
                kb(m.before, |m| m.rss_kb),
                kb(m.after, |m| m.rss_kb),
            ]
        })
        .collect();
    write_csv(
        &dir.join("memory.csv"),
        &["process", "peak_kb_before", "peak_kb_after", "rss_kb_before", "rss_kb_after"],
        &rows,
    )?;
    Ok(())
}

/// "2025-11-27 18:31 UTC" for a time since the Unix epoch.
pub fn utc(since_epoch: std::time::Duration) -> String {
    let secs = since_epoch.as_secs();
    let days = (secs / 86_400) as i64;
    let (hour, minute) = ((secs % 86_400) / 3600, (secs % 3600) / 60);
    // Howard Hinnant's days-to-civil.
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02} {hour:02}:{minute:02} UTC")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_are_utc_calendar_dates() {
        assert_eq!(utc(std::time::Duration::ZERO), "1970-01-01 00:00 UTC");
        // 2024-02-29 12:34:56 UTC.
        assert_eq!(utc(std::time::Duration::from_secs(1_709_210_096)), "2024-02-29 12:34 UTC");
    }

    #[test]
    fn tables_align_their_columns() {
        let text = aligned(&["a", "bb"], &[vec!["long".to_owned(), "x".to_owned()]]);
        assert_eq!(text, "a     bb\nlong  x\n");
    }
}
