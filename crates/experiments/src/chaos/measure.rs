//! What the chaos run measures, from what it recorded: the server's real-time factor over a
//! window, a robot's reactive rate over a window, a process's memory, a UDP port's kernel
//! drops, panics in a process's stderr.

use std::time::{Duration, Instant};

use serde::Serialize;

use strata_games::physics::cpu::parse_stat_ticks;

use super::game::Sample;

/// The server's real-time factor over a window.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RealTime {
    /// Simulated seconds per wall second over the whole window.
    pub factor: f64,
    /// The lowest over any second of the window.
    pub lowest_1s: f64,
}

/// Simulated seconds per wall second from the (wall, simulated seconds) samples inside
/// `[start, end]`; `None` with fewer than two.
pub fn real_time(samples: &[(Instant, f64)], start: Instant, end: Instant) -> Option<RealTime> {
    let inside: Vec<(Instant, f64)> =
        samples.iter().copied().filter(|(at, _)| *at >= start && *at <= end).collect();
    let ((t0, s0), (t1, s1)) = (*inside.first()?, *inside.last()?);
    let wall = (t1 - t0).as_secs_f64();
    if wall <= 0.0 {
        return None;
    }
    let mut lowest = f64::INFINITY;
    let mut j = 0;
    for (i, &(ti, si)) in inside.iter().enumerate() {
        j = j.max(i);
        while j < inside.len() && inside[j].0 - ti < Duration::from_secs(1) {
            j += 1;
        }
        let Some(&(tj, sj)) = inside.get(j) else { break };
        lowest = lowest.min((sj - si) / (tj - ti).as_secs_f64());
    }
    let factor = (s1 - s0) / wall;
    Some(RealTime { factor, lowest_1s: if lowest.is_finite() { lowest } else { factor } })
}

/// A robot's reactive layer's cycles per second within `[start, end]`, by the robot's own
/// clock, over the longest stretch one process of it covered (a restarted robot's count
/// starts again at zero); `None` without two status lines of one process in the window.
pub fn reactive_rate(samples: &[Sample], start: Instant, end: Instant) -> Option<f64> {
    let inside: Vec<&Sample> = samples
        .iter()
        .filter(|s| s.at >= start && s.at <= end && s.reactive_cycles.is_some())
        .collect();
    let mut best: Option<(f64, f64)> = None;
    let mut instances: Vec<usize> = inside.iter().map(|s| s.instance).collect();
    instances.dedup();
    for instance in instances {
        let of: Vec<&&Sample> = inside.iter().filter(|s| s.instance == instance).collect();
        let (Some(first), Some(last)) = (of.first(), of.last()) else { continue };
        let span = last.t - first.t;
        let cycles =
            last.reactive_cycles.unwrap_or(0).saturating_sub(first.reactive_cycles.unwrap_or(0));
        if span > 0.0 && best.is_none_or(|(s, _)| span > s) {
            best = Some((span, cycles as f64 / span));
        }
    }
    best.map(|(_, rate)| rate)
}

/// The longest stretch within `[start, end]` in which a robot's planning layer counted on
/// fewer than `teammates` teammates, seconds, from its status lines (0 when it never did).
pub fn longest_gap(samples: &[Sample], start: Instant, end: Instant, teammates: usize) -> f64 {
    let mut longest = Duration::ZERO;
    let mut open: Option<Instant> = None;
    let mut last = start;
    for s in samples.iter().filter(|s| s.at >= start && s.at <= end) {
        last = s.at;
        match (open, s.available.len() < teammates) {
            (None, true) => open = Some(s.at),
            (Some(since), false) => {
                longest = longest.max(s.at - since);
                open = None;
            }
            _ => {}
        }
    }
    if let Some(since) = open {
        longest = longest.max(last - since);
    }
    longest.as_secs_f64()
}

/// A process's memory, kB.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Memory {
    /// Peak resident set size (VmHWM).
    pub peak_kb: u64,
    /// Resident set size now (VmRSS).
    pub rss_kb: u64,
}

/// The memory of process `pid` (`None`: the process is gone).
pub fn memory(pid: u32) -> Option<Memory> {
    parse_memory(&std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?)
}

/// The memory of this process (the server's).
pub fn own_memory() -> Option<Memory> {
    parse_memory(&std::fs::read_to_string("/proc/self/status").ok()?)
}

fn parse_memory(status: &str) -> Option<Memory> {
    let field = |name: &str| {
        status
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|rest| rest.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
    };
    Some(Memory { peak_kb: field("VmHWM:")?, rss_kb: field("VmRSS:")? })
}

/// The IPv4 UDP sockets bound to `port` on this machine and the datagrams the kernel dropped
/// on them (a full receive buffer), from `/proc/net/udp`.
pub fn udp_drops(port: u16) -> Option<(usize, u64)> {
    Some(parse_udp_drops(&std::fs::read_to_string("/proc/net/udp").ok()?, port))
}

fn parse_udp_drops(table: &str, port: u16) -> (usize, u64) {
    let mut sockets = 0;
    let mut drops = 0;
    for line in table.lines().skip(1) {
        let fields: Vec<&str> = line.split_whitespace().collect();
        let Some(local) = fields.get(1) else { continue };
        let bound = local.rsplit_once(':').and_then(|(_, p)| u16::from_str_radix(p, 16).ok());
        if bound != Some(port) {
            continue;
        }
        sockets += 1;
        drops += fields.get(12).and_then(|d| d.parse::<u64>().ok()).unwrap_or(0);
    }
    (sockets, drops)
}

/// The kernel's clock ticks per second in `/proc`'s CPU times (USER_HZ, 100 on Linux whatever
/// the kernel's own tick rate).
const TICKS_PER_SECOND: f64 = 100.0;

/// One reading of where the machine's CPU time went.
#[derive(Clone, Debug)]
pub struct CpuReading {
    pub at: Instant,
    /// Every robot process's and this process's CPU time so far, ticks, by process name.
    pub processes: Vec<(String, u64)>,
    /// The machine's busy and total ticks, all cores together.
    pub machine: Option<(u64, u64)>,
}

/// CPU time per phase, in cores (1.0: one core busy the whole phase).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct CpuShare {
    /// Each process (the robots by name, this process as [`SERVER`]).
    pub processes: Vec<(String, f64)>,
    /// Every robot process together.
    pub robots: f64,
    /// The busiest robot process, and its share.
    pub busiest: Option<(String, f64)>,
    /// This process: the server, the GameController, the faults.
    pub server: f64,
    /// Everything else on the machine (other programs, the kernel's own work).
    pub other: Option<f64>,
}

/// User and system CPU time of process `pid` so far, ticks.
pub fn cpu_ticks(pid: u32) -> Option<u64> {
    parse_stat_ticks(&std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?)
}

pub fn own_cpu_ticks() -> Option<u64> {
    parse_stat_ticks(&std::fs::read_to_string("/proc/self/stat").ok()?)
}

/// The machine's busy and total CPU ticks, all cores together.
pub fn machine_ticks() -> Option<(u64, u64)> {
    parse_machine_ticks(&std::fs::read_to_string("/proc/stat").ok()?)
}

fn parse_machine_ticks(stat: &str) -> Option<(u64, u64)> {
    let line = stat.lines().find(|l| l.starts_with("cpu "))?;
    let ticks: Vec<u64> = line.split_whitespace().skip(1).filter_map(|t| t.parse().ok()).collect();
    // user nice system idle iowait irq softirq steal guest guest_nice; guest time is counted
    // in user time already.
    let total: u64 = ticks.iter().take(8).sum();
    let idle = ticks.get(3)? + ticks.get(4).unwrap_or(&0);
    Some((total - idle, total))
}

/// Where the CPU time went between the first and the last reading inside `[start, end]`.
pub fn cpu_share(readings: &[CpuReading], start: Instant, end: Instant) -> Option<CpuShare> {
    let inside: Vec<&CpuReading> =
        readings.iter().filter(|r| r.at >= start && r.at <= end).collect();
    let (first, last) = (inside.first()?, inside.last()?);
    let wall = (last.at - first.at).as_secs_f64();
    if wall <= 0.0 {
        return None;
    }
    let cores = |ticks: u64| ticks as f64 / TICKS_PER_SECOND / wall;
    let mut share = CpuShare::default();
    for (name, ticks) in &last.processes {
        // A process started within the window counts from zero.
        let before = first.processes.iter().find(|(n, _)| n == name).map_or(0, |(_, t)| *t);
        let used = cores(ticks.saturating_sub(before));
        share.processes.push((name.clone(), used));
        if name == SERVER {
            share.server = used;
        } else {
            share.robots += used;
            if share.busiest.as_ref().is_none_or(|(_, b)| used > *b) {
                share.busiest = Some((name.clone(), used));
            }
        }
    }
    if let (Some((b0, t0)), Some((b1, t1))) = (first.machine, last.machine) {
        let cores_total = std::thread::available_parallelism().map_or(1, |n| n.get()) as f64;
        let busy =
            (b1.saturating_sub(b0)) as f64 / (t1.saturating_sub(t0)).max(1) as f64 * cores_total;
        share.other = Some((busy - share.robots - share.server).max(0.0));
    }
    Some(share)
}

/// The name this process has among the CPU readings.
pub const SERVER: &str = "server";

/// Panics a Rust process reported on its stderr.
pub fn panics(stderr: &str) -> usize {
    stderr.lines().filter(|l| l.contains("panicked")).count()
}

/// The machine's 1-minute load average.
pub fn load_average() -> Option<f64> {
    crate::load_average()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(base: Instant, seconds: f64) -> Instant {
        base + Duration::from_secs_f64(seconds)
    }

    #[test]
    fn the_real_time_factor_is_simulated_over_wall_time_and_its_worst_second_is_found() {
        let base = Instant::now();
        // Real time for 2 s, then a second in which only half a second was simulated.
        let samples: Vec<(Instant, f64)> = vec![
            (at(base, 0.0), 10.0),
            (at(base, 1.0), 11.0),
            (at(base, 2.0), 12.0),
            (at(base, 3.0), 12.5),
            (at(base, 4.0), 13.5),
        ];
        let rt = real_time(&samples, base, at(base, 4.0)).expect("enough samples");
        assert!((rt.factor - 3.5 / 4.0).abs() < 1e-9);
        assert!((rt.lowest_1s - 0.5).abs() < 1e-9);
        let first = real_time(&samples, base, at(base, 2.0)).expect("enough samples");
        assert!((first.factor - 1.0).abs() < 1e-9 && (first.lowest_1s - 1.0).abs() < 1e-9);
        assert!(real_time(&samples, at(base, 10.0), at(base, 20.0)).is_none());
    }

    fn status(base: Instant, seconds: f64, instance: usize, t: f64, cycles: u64) -> Sample {
        Sample {
            at: at(base, seconds),
            instance,
            t,
            game_state: Some("Playing".into()),
            role: None,
            available: Vec::new(),
            reactive_cycles: Some(cycles),
            sensor_frames: 0,
        }
    }

    #[test]
    fn the_reactive_rate_uses_the_robots_clock_and_the_longest_stretch_of_one_process() {
        let base = Instant::now();
        let samples = vec![
            status(base, 0.0, 0, 100.0, 8300),
            status(base, 1.0, 0, 101.0, 8383),
            status(base, 2.0, 0, 102.0, 8466),
            // Restarted: its count starts again.
            status(base, 3.5, 1, 0.5, 40),
            status(base, 4.0, 1, 1.0, 80),
        ];
        let rate = reactive_rate(&samples, base, at(base, 5.0)).expect("a rate");
        assert!((rate - 83.0).abs() < 1e-9, "{rate}");
        let restarted = reactive_rate(&samples, at(base, 3.0), at(base, 5.0)).expect("a rate");
        assert!((restarted - 80.0).abs() < 1e-9, "{restarted}");
        assert!(reactive_rate(&samples, at(base, 2.5), at(base, 3.6)).is_none());
    }

    #[test]
    fn the_longest_gap_in_a_robots_team_is_found() {
        let base = Instant::now();
        let with = |seconds: f64, available: Vec<u8>| Sample {
            available,
            ..status(base, seconds, 0, seconds, 0)
        };
        let samples = vec![
            with(0.0, vec![2, 3]),
            with(1.0, vec![2]),
            with(2.0, vec![]),
            with(3.0, vec![2, 3]),
            with(4.0, vec![3]),
            with(4.5, vec![3]),
        ];
        let gap = longest_gap(&samples, base, at(base, 10.0), 2);
        assert!((gap - 2.0).abs() < 1e-9, "{gap}");
        // A gap still open at the end of the window counts up to the last status line.
        let open = longest_gap(&samples, at(base, 3.5), at(base, 10.0), 2);
        assert!((open - 0.5).abs() < 1e-9, "{open}");
        assert_eq!(longest_gap(&samples, base, at(base, 0.5), 2), 0.0);
    }

    #[test]
    fn memory_and_udp_drops_are_read_from_procfs_text() {
        let status = "Name:\tstrata\nVmPeak:\t  900 kB\nVmHWM:\t   38140 kB\nVmRSS:\t   37000 kB\n";
        assert_eq!(parse_memory(status), Some(Memory { peak_kb: 38140, rss_kb: 37000 }));
        assert_eq!(parse_memory("Name:\tx\n"), None);
        let table = "   sl  local_address rem_address   st tx_queue rx_queue tr tm->when retrnsmt   uid  timeout inode ref pointer drops\n\
                     12: 00000000:0EF6 00000000:0000 07 00000000:00000000 00:00000000 00000000     0        0 1234 2 0000000000000000 17\n\
                     13: 00000000:0EF6 00000000:0000 07 00000000:00000000 00:00000000 00000000     0        0 1235 2 0000000000000000 3\n\
                     14: 0100007F:0EF7 00000000:0000 07 00000000:00000000 00:00000000 00000000     0        0 1236 2 0000000000000000 99\n";
        assert_eq!(parse_udp_drops(table, 0x0EF6), (2, 20));
        assert_eq!(parse_udp_drops(table, 1), (0, 0));
        assert!(udp_drops(1).is_some(), "procfs is readable");
        assert!(own_memory().is_some_and(|m| m.peak_kb >= m.rss_kb));
    }

    #[test]
    fn machine_cpu_times_are_read_from_procfs_text_and_shared_out() {
        let machine = "cpu  100 0 50 800 50 0 0 0 0 0\ncpu0 50 0 25 400 25 0 0 0 0 0\n";
        assert_eq!(parse_machine_ticks(machine), Some((150, 1000)));
        assert!(own_cpu_ticks().is_some() && machine_ticks().is_some());

        let base = Instant::now();
        let reading = |seconds: f64, robot: u64, server: u64| CpuReading {
            at: at(base, seconds),
            processes: vec![("robot 10/1".into(), robot), (SERVER.into(), server)],
            machine: None,
        };
        let readings = vec![reading(0.0, 100, 0), reading(2.0, 140, 20)];
        let share = cpu_share(&readings, base, at(base, 2.0)).expect("two readings");
        assert!((share.robots - 0.2).abs() < 1e-9 && (share.server - 0.1).abs() < 1e-9);
        assert_eq!(share.busiest.map(|(n, _)| n), Some("robot 10/1".to_owned()));
        assert_eq!(share.other, None);
    }

    #[test]
    fn panics_are_counted_from_stderr() {
        let stderr = "warn: x\nthread 'main' panicked at src/main.rs:1:1:\nboom\nthread 'w' panicked at a.rs\n";
        assert_eq!(panics(stderr), 2);
        assert_eq!(panics(""), 0);
    }
}
