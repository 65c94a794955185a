//! The CPU time a process has used, from `/proc/PID/stat` (Linux): how a game's compute splits
//! between the server's physics and the robots. Read while the process runs; a process that
//! has ended has no entry any more, so callers keep the last reading.

use std::path::Path;

/// User plus system CPU time of process `pid`, seconds; `None` when it cannot be read (the
/// process ended, or not on Linux).
pub fn process_cpu_seconds(pid: u32) -> Option<f64> {
    let text =
        std::fs::read_to_string(Path::new("/proc").join(pid.to_string()).join("stat")).ok()?;
    let ticks = parse_stat_ticks(&text)?;
    Some(ticks as f64 / clock_ticks_per_second())
}

/// `utime + stime` (fields 14 and 15) of a `/proc/PID/stat` line. The command name (field 2)
/// is in parentheses and may contain spaces and parentheses itself, so fields are counted
/// from the last `)`.
pub fn parse_stat_ticks(stat: &str) -> Option<u64> {
    let rest = &stat[stat.rfind(')')? + 1..];
    // After the name: state is field 3, so utime (14) is the 12th from here.
    let mut fields = rest.split_whitespace().skip(11);
    let utime: u64 = fields.next()?.parse().ok()?;
    let stime: u64 = fields.next()?.parse().ok()?;
    Some(utime + stime)
}

fn clock_ticks_per_second() -> f64 {
    // USER_HZ: 100 on every Linux ABI Strata builds for (the kernel fixes it for userspace).
    100.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ticks_are_read_after_the_command_name_whatever_it_contains() {
        let line = "4242 (rcss (mj) x) S 1 4242 4242 0 -1 4194560 9000 0 0 0 1234 567 0 0 20 0 \
                    12 0 100 1000000 2000 18446744073709551615";
        assert_eq!(parse_stat_ticks(line), Some(1234 + 567));
        assert_eq!(parse_stat_ticks("garbage"), None);
        assert_eq!(parse_stat_ticks("1 (x) S 1 2"), None);
    }

    #[test]
    fn this_process_has_used_some_cpu_time() {
        let spent = process_cpu_seconds(std::process::id());
        if cfg!(target_os = "linux") {
            assert!(spent.is_some_and(|s| s >= 0.0), "{spent:?}");
        }
    }
}
